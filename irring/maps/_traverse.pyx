# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernels of the occupancy grid: its cell walk and its per-sweep update.

docs/mapping.md explains the rules (touch lengths, clipping) and the inverse
sensor model; this is their one implementation:

* :func:`walk` lists every cell a batch of segments visits (``mapping.traverse``);
* :func:`add_beams` adds one batch of readings' log-odds to a grid and clamps the box of
  cells their beams reach (``OccupancyGrid.insert``; ``delta``: the same, unclamped).

One call does a whole batch: a loop per segment and column in C, numpy only allocates.
Units are grid cells from the grid's corner. A segment is clipped to the grid (Liang–Barsky),
then walked column by column along its major axis (|slope| ≤ 1: in each column it is in
slot A's cell and, if it crosses a minor-axis border there, in slot B's after it); a cell it
stays in for less than TOUCH_CELLS (a corner touch) is no visit. Every column is computed
from its number, not from the previous one, so nothing accumulates along a ray. Positions
along a segment are u = t·scale − shift (t: 0…1 over the segment).
"""

from libc.float cimport DBL_MAX
from libc.math cimport INFINITY, NAN, cos, exp, fabs, hypot, isfinite, isnan, sin, sqrt
from libc.string cimport memset

import numpy as np
from ..errors import lengths_differ

# The SHA-256 of this file as built (irring/kernel_build.py defines IRRING_PYX_SHA256; "" when
# built without it): irring.resources.kernel compares it with the file in a checkout.
cdef extern from *:
    """
    #ifndef IRRING_PYX_SHA256
    #define IRRING_PYX_SHA256 ""
    #endif
    """
    const char *IRRING_PYX_SHA256

PYX_SHA256 = IRRING_PYX_SHA256.decode("ascii")

# Crossings closer than this (in cells) are the same point: a ray through a cell corner does
# not visit the two side cells it only touches (nor any cell it stays in for less).
cdef double TOUCH_CELLS = 1e-9
# Clipped segments shorter than this visit just the cell they start in.
cdef double SHORT_CELLS = 4 * TOUCH_CELLS
# A valid beam's columns that end more than this many σ (plus the free margin) in front of its
# end point get exactly l_free: the model there is l_free·Φ(4.5) + l_occ·exp(−4.5²/2), within
# 4e-5 of it, and a constant lets those cells be counted as runs instead of weighed one by one.
cdef double NEAR_SIGMAS = 4.5
# Beams reaching farther than this many cells from the grid's corner are not mapped (their
# numbers would swamp the cell arithmetic; 1e9 cells is 10 000 km at 10 mm).
cdef double FAR_CELLS = 1e9
cdef double SQRT1_2 = 0.70710678118654752440
cdef double INTEGRAL = 4503599627370496.0         # 2^52: doubles this large are integers
# A no-return beam looks for cells where it could stop this many columns at a time (in a
# summed-area table); the columns before the first such chunk go in as runs.
cdef long SAT_COLUMNS = 8


cdef struct Seg:
    # a segment clipped to the grid, split into its major (p) and minor (q) axis
    double p0, dp        # start and extent along the major axis …
    double q0, dq        # … and the minor axis; q0 from q_ref (the floor of the start's minor
    double q_ref         # coordinate), so a touch length (1e-9 cells × slope) stays representable
    double t0, t1        # the part inside the grid, as fractions of the segment
    double length        # of the whole segment
    double t_col         # t per column, 1/|dp|
    double t_col0        # t where the line enters column cs
    double tol_p, tol_q  # a touch length along each axis, signed like dp / dq (0 for short ones)
    double last          # the grid's last cell index along the major axis
    long cs, count       # the first column walked (major-axis cell index) and how many
    long step            # +1 or −1 along the major axis
    bint xmaj            # the major axis is x
    bint short           # inside part shorter than SHORT_CELLS: the start cell only


cdef struct Cols:
    # a segment's columns in u = t·scale − shift: column k spans [u1, u2] + k·uc, clipped to
    # [u_lo, u_hi]; slot A's minor cell is floor(qa + u_in·dq_u), slot B's floor(qb + u_out·dq_u)
    # (a touch length inside the column); minor border b is crossed at b·cross + cross0
    double uc, u1, u2, u_lo, u_hi, dq_u, qa, qb, cross, cross0


cdef inline double dmax(double a, double b) noexcept nogil:
    return a if a >= b else b


cdef inline double dmin(double a, double b) noexcept nogil:
    return a if a <= b else b


cdef inline double ffloor(double x) noexcept nogil:
    # floor without a libm call (the walk needs two per column, the runs two per crossing)
    cdef double t
    if fabs(x) < INTEGRAL:
        t = <double>(<long long>x)
        return t - 1.0 if t > x else t
    return x


cdef inline long lfloor(double x) noexcept nogil:
    # floor of a cell coordinate (well inside the long range), without a libm call
    cdef long t = <long>x
    return t - (t > x)


cdef inline long clampl(long p, long hi) noexcept nogil:
    return 0 if p < 0 else (hi if p > hi else p)


cdef inline bint clip(double x0, double y0, double dx, double dy, long nx, long ny,
                      Seg* s) noexcept nogil:
    """Segment (x0, y0) + t·(dx, dy) clipped to [0, nx) × [0, ny); False if it has no visit.

    The columns walked start and end a touch length inside the clipped part, so a first or
    last column the segment barely enters (it starts or ends on its border) is not walked.
    A segment only touching the grid's border has no visits; a zero-length one inside has one.
    """
    cdef double length = sqrt(dx * dx + dy * dy)
    cdef double t0 = -INFINITY, t1 = INFINITY, tol, p0, q0, dp, dq, cs, ce, last
    cdef double p[4]
    cdef double q[4]
    cdef int i
    if not (isfinite(length) and isfinite(x0) and isfinite(y0)):
        return False
    p[0] = -dx; p[1] = dx; p[2] = -dy; p[3] = dy
    q[0] = x0; q[1] = nx - x0; q[2] = y0; q[3] = ny - y0
    for i in range(4):
        if p[i] < 0:
            t0 = dmax(t0, q[i] / p[i])
        elif p[i] > 0:
            t1 = dmin(t1, q[i] / p[i])
        # parallel to a border and beyond it; cells are half-open [i, i+1), so a segment
        # along the top/right border lies outside
        elif q[i] < 0 or (q[i] == 0 and i % 2 == 1):
            return False
    t0 = dmax(t0, 0.0)
    t1 = dmin(t1, 1.0)
    if not (t0 <= t1 and ((t1 - t0) * length >= TOUCH_CELLS or length < TOUCH_CELLS)):
        return False
    s.xmaj = fabs(dx) >= fabs(dy)
    if s.xmaj:
        p0, q0, dp, dq, last = x0, y0, dx, dy, nx - 1
    else:
        p0, q0, dp, dq, last = y0, x0, dy, dx, ny - 1
    s.q_ref = ffloor(q0)
    s.q0 = q0 - s.q_ref                                   # exact: the fractional part
    s.p0, s.dp, s.dq, s.t0, s.t1, s.length = p0, dp, dq, t0, t1, length
    s.short = (t1 - t0) * length < SHORT_CELLS
    tol = 0.0 if s.short else TOUCH_CELLS / length
    s.t_col = 1.0 / fabs(dp)
    cs = dmin(dmax(ffloor(p0 + t0 * dp + tol * dp), 0.0), last)
    ce = dmin(dmax(ffloor(p0 + t1 * dp - tol * dp), 0.0), last)
    s.step = -1 if dp < 0 else 1
    # the line enters column cs at the border p = cs (forwards) or cs + 1 (backwards)
    s.t_col0 = (cs + (dp < 0) - p0) * (-s.t_col if dp < 0 else s.t_col)
    if s.short:
        ce = cs
        s.t_col = 0.0
        s.t_col0 = 0.0
    s.cs = <long>cs
    s.count = <long>fabs(ce - cs) + 1
    s.tol_p = tol * dp
    s.tol_q = tol * dq
    s.last = last
    return True


cdef inline void columns(const Seg* s, double scale, double shift, Cols* c) noexcept nogil:
    """The walk of ``s`` in u = t·scale − shift (scale > 0)."""
    cdef double q_u0
    c.uc = s.t_col * scale
    c.u1 = s.t_col0 * scale - shift                    # u where column 0 is entered …
    c.u2 = c.u1 + c.uc                                 # … and left
    c.u_lo = s.t0 * scale - shift                      # the clipped part, in u
    c.u_hi = s.t1 * scale - shift
    if s.short:                                        # the start cell only, whole segment
        c.u1, c.u2 = -INFINITY, INFINITY
        c.qa = c.qb = s.q0 + s.t0 * s.dq
        c.dq_u = c.cross = c.cross0 = 0.0
        return
    c.dq_u = s.dq / scale                              # minor coordinate per u
    c.cross = scale / s.dq
    if not isfinite(c.cross):                          # (a segment too flat to cross one)
        c.cross = 0.0
    q_u0 = s.q0 + shift * c.dq_u                       # minor coordinate at u = 0
    c.qa = q_u0 + s.tol_q                              # slot A: a touch length in, …
    c.qb = q_u0 - s.tol_q                              # … slot B: a touch length before the end
    c.cross0 = -(q_u0 * c.cross)


cdef inline bint column(const Cols* c, double k, double* a, double* z, double* u_in,
                        double* u_mid, double* u_out) noexcept nogil:
    """Column k: slot A's minor cell a (from q_ref) entered at u_in and left at u_mid, and if
    it returns True slot B's z, left at u_out."""
    u_in[0] = dmax(c.u1 + k * c.uc, c.u_lo)
    u_out[0] = dmin(c.u2 + k * c.uc, c.u_hi)
    a[0] = ffloor(c.qa + u_in[0] * c.dq_u)
    z[0] = ffloor(c.qb + u_out[0] * c.dq_u)
    if z[0] != a[0]:
        u_mid[0] = dmin(dmax(dmax(a[0], z[0]) * c.cross + c.cross0, u_in[0]), u_out[0])
        return True
    u_mid[0] = u_out[0]
    return False


cdef inline bint cell(const Seg* s, long k, double minor, long x_lo, long x_hi, long y_lo,
                      long y_hi, long* ix, long* iy) noexcept nogil:
    """(ix, iy) of column k's cell at ``minor`` (from q_ref); False outside [x_lo, x_hi] ×
    [y_lo, y_hi]."""
    cdef long major = s.cs + s.step * k
    cdef double m = s.q_ref + minor
    if s.xmaj:
        if not (y_lo <= m <= y_hi) or not (x_lo <= major <= x_hi):
            return False
        ix[0], iy[0] = major, <long>m
    else:
        if not (x_lo <= m <= x_hi) or not (y_lo <= major <= y_hi):
            return False
        ix[0], iy[0] = <long>m, major
    return True


cdef Py_ssize_t _visits(const double[::1] x0, const double[::1] y0, const double[::1] dx,
                        const double[::1] dy, long nx, long ny, Py_ssize_t* ray,
                        Py_ssize_t* vx, Py_ssize_t* vy, double* t_enter,
                        double* t_exit) noexcept nogil:
    """How many cells the segments visit (see :func:`walk`), and if ``ray`` is not NULL the
    visits themselves, written to the five arrays: walk counts them first to size those."""
    cdef Py_ssize_t j, m = 0
    cdef long k, ix, iy
    cdef Seg s
    cdef Cols c
    cdef double a, z, u_in, u_mid, u_out
    cdef bint two
    for j in range(x0.shape[0]):
        if not clip(x0[j], y0[j], dx[j], dy[j], nx, ny, &s):
            continue
        columns(&s, 1.0, 0.0, &c)
        for k in range(s.count):
            two = column(&c, k, &a, &z, &u_in, &u_mid, &u_out)
            if cell(&s, k, a, 0, nx - 1, 0, ny - 1, &ix, &iy):
                if ray != NULL:
                    ray[m], vx[m], vy[m], t_enter[m], t_exit[m] = j, ix, iy, u_in, u_mid
                m += 1
            if two and cell(&s, k, z, 0, nx - 1, 0, ny - 1, &ix, &iy):
                if ray != NULL:
                    ray[m], vx[m], vy[m], t_enter[m], t_exit[m] = j, ix, iy, u_mid, u_out
                m += 1
    return m


def walk(const double[::1] x0, const double[::1] y0, const double[::1] dx,
         const double[::1] dy, long nx, long ny):
    """Every cell each segment (x0, y0) + t·(dx, dy) (cells from the grid's corner) visits in
    [0, nx) × [0, ny): (ray, ix, iy, t_enter, t_exit), ordered by segment, then along it."""
    cdef Py_ssize_t n = x0.shape[0], m
    if y0.shape[0] != n or dx.shape[0] != n or dy.shape[0] != n:
        raise lengths_differ("segment arrays", x0=n, y0=y0.shape[0], dx=dx.shape[0],
                             dy=dy.shape[0])
    with nogil:
        m = _visits(x0, y0, dx, dy, nx, ny, NULL, NULL, NULL, NULL, NULL)
    ray_a = np.empty(m, np.intp)
    ix_a = np.empty(m, np.intp)
    iy_a = np.empty(m, np.intp)
    enter_a = np.empty(m)
    exit_a = np.empty(m)
    cdef Py_ssize_t[::1] ray = ray_a, vx = ix_a, vy = iy_a
    cdef double[::1] t_enter = enter_a, t_exit = exit_a
    if m:
        with nogil:
            _visits(x0, y0, dx, dy, nx, ny, &ray[0], &vx[0], &vy[0], &t_enter[0], &t_exit[0])
    return ray_a, ix_a, iy_a, enter_a, exit_a


cdef inline void add_runs(const Seg* s, double t_end, long long unit, long bx0, long by0,
                          long bw, long bh, long long* rx, long long* ry) noexcept nogil:
    """Count ``unit`` in every cell ``s`` visits from t0 to ``t_end`` (at least SHORT_CELLS
    long), as row runs in a difference array (the same cells as the column walk).

    In every minor-axis row a segment (|slope| ≤ 1) visits one contiguous run of columns:
    +unit at the run's first cell, −unit past its last (moving backwards: at the end and
    past the start); a cumulative sum along the major axis then counts the visits. Runs
    begin and end where the segment crosses minor-axis borders, so the work is per crossing,
    not per cell: the run before crossing i ends at floor(p ∓ tol), the one after begins at
    floor(p ± tol).
    Layouts: x-major runs in ``rx`` (rows y, columns x, one spare column past the box),
    y-major ones in ``ry`` (rows y, one spare row past the box, columns x). Rows off the box (a
    rounding step off the grid) are dropped; run ends stay in the box's major range (a guard:
    exact arithmetic keeps them there).
    """
    cdef bint fwd = s.dp >= 0, up = s.dq > 0
    cdef long long w = unit if fwd else -unit
    cdef long long* arr
    cdef double ce, m_s, m_e, slope, p_cross, lo, hi, step, ip
    cdef long i, k, p, r, r_e, dr, major0, rows, p_hi, p_stride, r_stride
    if s.xmaj:
        arr, major0, p_hi, p_stride, rows, r_stride = rx, bx0, bw, 1, bh, bw + 1
        r = <long>s.q_ref - by0
    else:
        arr, major0, p_hi, p_stride, rows, r_stride = ry, by0, bh, bw, bw, 1
        r = <long>s.q_ref - bx0
    # last column and first / last row (from q_ref), a touch length inside the piece
    ce = dmin(dmax(ffloor(s.p0 + t_end * s.dp - s.tol_p), 0.0), s.last)
    m_s = ffloor(s.q0 + s.t0 * s.dq + s.tol_q)
    m_e = ffloor(s.q0 + t_end * s.dq - s.tol_q)
    k = <long>fabs(m_e - m_s)                          # minor-axis borders crossed
    r_e = r + <long>m_e
    r += <long>m_s
    if 0 <= r < rows:
        p = <long>s.cs + (not fwd) - major0
        arr[clampl(p, p_hi) * p_stride + r * r_stride] += w
    if 0 <= r_e < rows:
        p = <long>ce + fwd - major0
        arr[clampl(p, p_hi) * p_stride + r_e * r_stride] -= w
    if k == 0:
        return
    # crossing i (of border m_s + up ± i) at p = p_cross + i·step
    slope = s.dp / s.dq
    if not isfinite(slope):
        slope = 0.0
    p_cross = s.p0 + (m_s + up - s.q0) * slope
    lo = (p_cross - s.tol_p) + fwd                     # the run before it: past its end / its start
    hi = (p_cross + s.tol_p) + (not fwd)               # the run after it: its start / past its end
    step = slope if up else -slope
    dr = 1 if up else -1
    for i in range(k):
        ip = i * step
        if 0 <= r < rows:
            p = lfloor(lo + ip) - major0
            arr[clampl(p, p_hi) * p_stride + r * r_stride] -= w
        r += dr
        if 0 <= r < rows:
            p = lfloor(hi + ip) - major0
            arr[clampl(p, p_hi) * p_stride + r * r_stride] += w


cdef inline double weight(double z_a, double z_b, double mu, double l_occ, double l_ahead,
                          double l_free) noexcept nogil:
    """Log-odds for a cell a valid beam crosses from z_a to z_b, in σ from its end point (the
    model in docs/mapping.md); ``mu`` = the free margin in σ; ``l_ahead`` the hit's peak in
    a cell wholly in front of the end point (z_b < 0)."""
    cdef double gap, w, y, t
    # occupied: l_occ·exp(−gap²/2), gap = how far the cell's [z_a, z_b] is from 0
    gap = dmax(dmax(z_a, -z_b), 0.0)
    w = (l_ahead if z_b < 0 else l_occ) * exp(-0.5 * gap * gap)
    # free: l_free·Φ(y√2) for y = −(z_b + mu)/√2 > 0 (the whole cell in front of the margin),
    # Φ(y√2) = 1 − erfc(y)/2, erfc(y) = t·(0.3480242 − 0.0958798·t + 0.7478556·t²)·exp(−y²)
    # with t = 1/(1 + 0.47047·y), to 2.5e-5 (Abramowitz & Stegun 7.1.25, as the numpy version
    # had): one exp, where libc's erfc takes three times as long (15 vs 5 ns here)
    y = -(z_b + mu) * SQRT1_2
    if y > 0:
        t = 1.0 / (1.0 + 0.47047 * y)
        w += l_free * (1.0 - 0.5 * (t * (0.3480242 + t * (-0.0958798 + t * 0.7478556))
                                     * exp(-y * y)))
    return w


cdef inline double depth(double z_a, double dz, double tail, double l_occ,
                         double l_depth) noexcept nogil:
    """What the surface's depth adds to a cell entered z_a > 0 σ behind an end point, over
    its hit (l_occ·exp(−z_a²/2) before the tail's end, nothing beyond): up to l_depth,
    Gaussian in the gap to dz σ deep."""
    cdef double gap = dmax(z_a - dz, 0.0)
    cdef double w = l_depth * exp(-0.5 * gap * gap)
    return w - l_occ * exp(-0.5 * z_a * z_a) if z_a < tail else w


cdef inline double ranged(Py_ssize_t i, const double[::1] origin_x,
                         const double[::1] origin_y, const double[::1] x, const double[::1] y,
                         const unsigned char[::1] valid,
                         const unsigned char[::1] no_return) noexcept nogil:
    """Reading i's range for its neighbours' edge test: inf if silent, its end point's
    distance from its emitter if valid, else NaN (no edge)."""
    cdef double vx, vy
    if no_return[i]:
        return INFINITY
    if valid[i] and isfinite(x[i] + y[i]) and isfinite(origin_x[i] + origin_y[i]):
        vx, vy = x[i] - origin_x[i], y[i] - origin_y[i]
        return sqrt(vx * vx + vy * vy)
    return NAN


cdef inline double hit_log_odds(double sigma, double l_occ, double l_occ_min, double occ_sigma,
                                double lone_sigma) noexcept nogil:
    # mapping.hit_weight: the hit at a valid reading's end point, from its (floored) σ
    return dmax(dmin(l_occ_min, l_occ) * dmin(1.0, lone_sigma / sigma),
                l_occ * dmin(1.0, occ_sigma / sigma))


cdef inline double ahead_log_odds(double sigma, double l_hit, double l_occ, double l_occ_min,
                                  double occ_sigma, double lone_sigma,
                                  double ahead_floor) noexcept nogil:
    # mapping.ahead_weight: the hit's peak in the cells wholly in front of the end point
    if sigma > lone_sigma:
        return l_hit
    return dmax(ahead_floor * dmin(l_occ_min, l_occ), l_occ * dmin(1.0, occ_sigma / sigma))


def add_beams(double[:, ::1] log_odds, const double[::1] origin_x, const double[::1] origin_y,
              const double[::1] heading, const double[::1] x, const double[::1] y,
              const double[::1] sigma_m, const unsigned char[::1] valid,
              const unsigned char[::1] no_return, const double[::1] reach_m,
              Py_ssize_t step_stride,
              double max_range_m, double grid_x, double grid_y, double res, params,
              double lo, double hi, unsigned char[:, ::1] ends):
    """Add the log-odds of one batch of readings (flat arrays, metres; ``valid`` and
    ``no_return`` as uint8) to the grid ``log_odds`` (ny, nx; its cell (0, 0) has its corner
    at (grid_x, grid_y)), then clamp the box of cells their beams can reach to [lo, hi]
    (±inf: no clamp). Work and memory scale with the beams, not the grid. Returns whether
    any beam was mapped (if none, nothing is touched). The numpy oracle of this function is
    irring/maps/mapping_numpy.py.

    Valid readings (with finite end point and emitter) are walked from the emitter to
    tail_sigmas·σ behind the end point: the columns up to NEAR_SIGMAS·σ before the point
    where the free evidence stops (constant weight l_free) are counted as row runs, exactly
    (integers), the rest walked cell by cell and weighed with the model; all of it goes into
    the grid unclamped. A sharp one on an occluding edge (reading i's neighbours in its
    sensor's sweep are i ± ``step_stride``, the readings per step) is walked on to its
    surface's depth, whose weights wait until the no-return readings are in. Then no-return
    readings (finite emitter and heading) go along the heading to the max range, or to
    ``reach_m`` where that is finite and shorter (a surface explains the silence; ≤ 0: not
    at all), or to the first cell whose log-odds (the grid's
    plus this batch's valid readings') exceed ``no_return_stop`` (+inf: never) and, with
    ``stop_at_end_cells``, that hold an end point (``ends``, uint8 (ny, nx): the grid's
    record, marked here with this batch's valid end points first), and add
    l_no_return to the cells before it: counted as runs up to the first chunk of SAT_COLUMNS
    columns whose box holds such a cell (a summed-area table of them), walked cell by cell
    from there. Every other reading changes nothing.
    The clamp comes last: the batch's updates are summed before clamping.
    """
    cdef double l_occ = params.l_occ, l_free = params.l_free, l_nr = params.l_no_return
    cdef double tail = params.tail_sigmas, min_sigma = params.min_sigma_m
    cdef double default_sigma = params.default_sigma_m
    cdef double occ_sigma = params.occ_sigma_m, l_occ_min = params.l_occ_min, l_hit
    cdef double ahead_floor = params.ahead_floor, l_ahead
    cdef double margin_m = params.free_margin_cells * res
    cdef double free_sigmas = params.free_sigmas, stop_m
    cdef double stop_at = params.no_return_stop, lone_sigma = params.lone_sigma_m
    cdef bint any_cell = params.stop_at_end_cells == 0   # (0: every cell above the stop stops)
    cdef double hold_sigma = params.hold_sigma_m, l_pass, trust
    cdef double l_depth = min(params.l_occ_min, params.l_occ)
    cdef double depth_m = params.hit_depth_cells * res, jump_m = params.edge_jump_cells * res
    cdef double dz, extra, l_deep
    cdef Py_ssize_t deep_cap = 0, n_deep = 0
    cdef long ny = log_odds.shape[0], nx = log_odds.shape[1]
    cdef Py_ssize_t n = origin_x.shape[0], i, j, nb = 0, nv = 0, kept = 0
    cdef long k, ix, iy, n_far, bx0, by0, bx1, by1, bw, bh
    cdef double inv = 1.0 / res, ox, oy, vx, vy, d, sigma, length, stretch, hx, hy
    cdef double lo_x = INFINITY, lo_y = INFINITY, hi_x = -INFINITY, hi_y = -INFINITY
    cdef double a, z, u_in, u_mid, u_out, mu, far, t_end
    cdef long long run
    cdef int* passes
    cdef int* sat
    cdef long sw, qx0, qx1, qy0, qy1
    cdef bint silent_runs = False, stops = isfinite(stop_at) or stop_at < 0
    cdef double v
    cdef double* e
    cdef double* deep_w
    cdef Py_ssize_t* deep_at
    cdef double* grid
    cdef long long* rx
    cdef long long* ry
    cdef long long* row
    cdef long long* col
    cdef double* out
    cdef unsigned char* held
    cdef Seg s
    cdef Cols c
    cdef bint two, is_valid, again
    cdef int pass_, n_pass
    if not (origin_y.shape[0] == heading.shape[0] == x.shape[0] == y.shape[0]
            == sigma_m.shape[0] == valid.shape[0] == no_return.shape[0]
            == reach_m.shape[0] == n):
        raise lengths_differ("the readings' arrays", origin_x=n, origin_y=origin_y.shape[0],
                             heading=heading.shape[0], x=x.shape[0], y=y.shape[0],
                             sigma_m=sigma_m.shape[0], valid=valid.shape[0],
                             no_return=no_return.shape[0], reach_m=reach_m.shape[0])
    if ends.shape[0] != ny or ends.shape[1] != nx:
        raise ValueError(f"ends has shape ({ends.shape[0]}, {ends.shape[1]}), the grid "
                         f"({ny}, {nx}): one flag per cell")
    if n >= 1 << 31:
        raise ValueError("at most 2^31 − 1 readings per insert (the cell counts are 32-bit)")
    if step_stride < 1:
        raise ValueError(f"step_stride must be ≥ 1, got {step_stride}")
    beams_a = np.empty((max(n, 1), 10))
    cdef double[:, ::1] beams = beams_a
    with nogil:
        # the mapped beams in cells, valid ones first: x0, y0, Δx, Δy, d (m), σ (m), length (m),
        # and for valid ones the end point's cell coordinates (as mapping.cell_of: (x − x_g)/res)
        # and the depth of its surface (m)
        for pass_ in range(2):
            is_valid = pass_ == 0
            for i in range(n):
                ox, oy = origin_x[i], origin_y[i]
                if not isfinite(ox + oy):
                    continue
                e = &beams[nb, 0]
                if is_valid:
                    if not (valid[i] and isfinite(x[i] + y[i])):
                        continue
                    # emitter → end point, continued into the surface: by its hit's depth
                    # (a sharp end point on an occluding edge: the step before or after it,
                    # i ∓ step_stride, reads ≥ jump_m farther or nothing; mapping_numpy's
                    # hit_depths) and tail_sigmas·σ
                    sigma = sigma_m[i] if isfinite(sigma_m[i]) else default_sigma
                    sigma = dmax(sigma, min_sigma)
                    vx, vy = x[i] - ox, y[i] - oy
                    d = sqrt(vx * vx + vy * vy)
                    e[9] = 0.0
                    if depth_m > 0 and sigma <= hold_sigma and (
                            (i >= step_stride and ranged(i - step_stride, origin_x, origin_y,
                                                         x, y, valid, no_return) - d >= jump_m)
                            or (i + step_stride < n and ranged(i + step_stride, origin_x,
                                                               origin_y, x, y, valid,
                                                               no_return) - d >= jump_m)):
                        e[9] = depth_m
                        # cells it can enter behind the end point: 2 per column crossed
                        deep_cap += 2 * (<Py_ssize_t>((depth_m + tail * sigma) * inv) + 3)
                    length = d + e[9] + tail * sigma
                    stretch = length / d
                    if d == 0:                         # an end point on its emitter: along the heading
                        hx, hy = cos(heading[i]), sin(heading[i])
                        vx = hx if isfinite(hx) else 0.0
                        vy = hy if isfinite(hy) else 0.0
                        stretch = length
                    e[2], e[3] = vx * stretch * inv, vy * stretch * inv
                    e[4], e[5], e[6] = d, sigma, length
                    e[7], e[8] = (x[i] - grid_x) / res, (y[i] - grid_y) / res
                else:
                    if valid[i] and isfinite(x[i] + y[i]) or not no_return[i] \
                            or not isfinite(heading[i]):
                        continue
                    # emitter → max range (or its reach) along the heading
                    length = max_range_m
                    if isfinite(reach_m[i]) and reach_m[i] < length:
                        if reach_m[i] <= 0:
                            continue
                        length = reach_m[i]
                    e[2] = cos(heading[i]) * length * inv
                    e[3] = sin(heading[i]) * length * inv
                e[0], e[1] = (ox - grid_x) * inv, (oy - grid_y) * inv
                # overflowed or absurd numbers are not mapped
                if not (fabs(e[0]) < FAR_CELLS and fabs(e[1]) < FAR_CELLS
                        and fabs(e[2]) < FAR_CELLS and fabs(e[3]) < FAR_CELLS):
                    continue
                lo_x = dmin(lo_x, dmin(e[0], e[0] + e[2]))
                lo_y = dmin(lo_y, dmin(e[1], e[1] + e[3]))
                hi_x = dmax(hi_x, dmax(e[0], e[0] + e[2]))
                hi_y = dmax(hi_y, dmax(e[1], e[1] + e[3]))
                nb += 1
                nv += is_valid
    if nb == 0:
        return False
    # the beams' bounding box on the grid, one cell wider on every side (an end point a
    # rounding step from a border may lie in the next cell)
    bx0, by0 = max(<long>ffloor(lo_x) - 1, 0), max(<long>ffloor(lo_y) - 1, 0)
    bx1, by1 = min(<long>ffloor(hi_x) + 1, nx - 1), min(<long>ffloor(hi_y) + 1, ny - 1)
    if bx0 > bx1 or by0 > by1:
        return False
    bw, bh = bx1 - bx0 + 1, by1 - by0 + 1
    # valid beams' clean passes as difference arrays: x-major beams' runs along
    # the rows (bh × (bw + 1)), y-major beams' down the columns ((bh + 1) × bw)
    runs_a = np.zeros(bh * (bw + 1) + (bh + 1) * bw, np.int64)
    cdef long long[::1] runs_v = runs_a
    rx = &runs_v[0]
    ry = rx + bh * (bw + 1)
    # cells of the box holding a sharp end point (σ ≤ hold_sigma): no free evidence from this batch
    held_a = np.zeros(bh * bw, np.uint8)
    cdef unsigned char[::1] held_v = held_a
    held = &held_v[0]
    # what the surface's depth adds (flat grid cell, log-odds), added after the silent beams
    # (it does not stop them)
    cdef Py_ssize_t[::1] deep_at_v
    cdef double[::1] deep_w_v
    deep_at, deep_w = NULL, NULL
    if deep_cap:
        deep_at_v = np.empty(deep_cap, np.intp)
        deep_w_v = np.empty(deep_cap)
        deep_at = &deep_at_v[0]
        deep_w = &deep_w_v[0]
    grid = &log_odds[0, 0]
    # no-return passes per cell of the box
    passes_a = np.zeros(bh * bw, np.intc)
    cdef int[::1] passes_v = passes_a
    passes = &passes_v[0]
    # where no-return beams can stop: a summed-area table of the box's cells above
    # no_return_stop, so a beam whose cells hold none goes in as runs instead of a cell walk
    sw = bw + 1
    sat_a = np.zeros((bh + 1) * sw if nb > nv and stops else 1, np.intc)
    cdef int[::1] sat_v = sat_a
    sat = &sat_v[0]
    with nogil:
        for j in range(nv):
            e = &beams[j, 0]
            if e[5] <= hold_sigma and fabs(e[7]) < FAR_CELLS and fabs(e[8]) < FAR_CELLS:
                ix, iy = lfloor(e[7]) - bx0, lfloor(e[8]) - by0
                if 0 <= ix < bw and 0 <= iy < bh:
                    held[iy * bw + ix] = 1
        # the cells holding an end point (the grid's record, with this batch's): with
        # stop_at_end_cells, the only cells that stop a silent beam
        for j in range(nv):
            e = &beams[j, 0]
            if fabs(e[7]) < FAR_CELLS and fabs(e[8]) < FAR_CELLS:
                ix, iy = lfloor(e[7]), lfloor(e[8])
                if 0 <= ix < nx and 0 <= iy < ny:
                    ends[iy, ix] = 1
        for j in range(nv):                            # valid beams
            e = &beams[j, 0]
            if not clip(e[0], e[1], e[2], e[3], nx, ny, &s):
                continue
            kept += 1
            d, sigma, length = e[4], e[5], e[6]
            # no free evidence within stop_m in front of the end point: the margin, and
            # free_sigmas times the σ beyond the floor (an uncertain reading clears less)
            stop_m = margin_m + free_sigmas * (sigma - min_sigma)
            # the columns entirely before NEAR_SIGMAS·σ in front of stop_m: runs
            # a reading more uncertain than lone_sigma weighs lone_sigma/σ of a hit and of a
            # pass: all its columns are weighed cell by cell (the runs count whole passes)
            trust = dmin(1.0, lone_sigma / sigma)
            n_far = 0
            if trust == 1.0 and not s.short:
                far = ffloor(((d - stop_m - NEAR_SIGMAS * sigma) / length - s.t_col0)
                             / s.t_col)
                far = dmin(dmax(far, 0.0), s.count)
                # (a beam leaving the grid may have only far columns: they end where it leaves)
                t_end = dmin(s.t_col0 + far * s.t_col, s.t1)
                if (t_end - s.t0) * s.length >= SHORT_CELLS:
                    n_far = <long>far
                    add_runs(&s, t_end, 1, bx0, by0, bw, bh, rx, ry)
            # the rest cell by cell, in u = (s − d)/σ: σ from the end point along the beam
            # (added to the grid now, clamped below with the rest)
            columns(&s, length / sigma, d / sigma, &c)
            mu = stop_m / sigma
            # a reading k times as uncertain as occ_sigma spreads 1/k of a hit over k times
            # the length, but adds at least l_occ_min (or l_occ, if that is less)
            l_hit = hit_log_odds(sigma, l_occ, l_occ_min, occ_sigma, lone_sigma)
            l_ahead = ahead_log_odds(sigma, l_hit, l_occ, l_occ_min, occ_sigma, lone_sigma,
                                     ahead_floor)
            if e[9] == 0:
                for k in range(n_far, s.count):
                    two = column(&c, k, &a, &z, &u_in, &u_mid, &u_out)
                    if cell(&s, k, a, bx0, bx1, by0, by1, &ix, &iy):
                        l_pass = 0.0 if held[(iy - by0) * bw + ix - bx0] else l_free * trust
                        log_odds[iy, ix] += weight(u_in, u_mid, mu, l_hit, l_ahead, l_pass)
                    if two and cell(&s, k, z, bx0, bx1, by0, by1, &ix, &iy):
                        l_pass = 0.0 if held[(iy - by0) * bw + ix - bx0] else l_free * trust
                        log_odds[iy, ix] += weight(u_mid, u_out, mu, l_hit, l_ahead, l_pass)
                continue
            # a beam with a depth: the hit and pass up to the tail's end (tail σ behind the end
            # point) as any; a cell entered behind the end point gets at least l_deep
            # (l_occ_min, at most the hit's), Gaussian in its gap to the depth dz (in σ)
            dz = e[9] / sigma
            l_deep = dmin(l_depth, l_hit)
            for k in range(n_far, s.count):
                two = column(&c, k, &a, &z, &u_in, &u_mid, &u_out)
                if cell(&s, k, a, bx0, bx1, by0, by1, &ix, &iy):
                    if u_in < tail:
                        l_pass = 0.0 if held[(iy - by0) * bw + ix - bx0] else l_free * trust
                        log_odds[iy, ix] += weight(u_in, u_mid, mu, l_hit, l_ahead, l_pass)
                    extra = depth(u_in, dz, tail, l_hit, l_deep) if u_in > 0 else 0.0
                    if extra > 0 and n_deep < deep_cap:
                        deep_at[n_deep], deep_w[n_deep] = iy * nx + ix, extra
                        n_deep += 1
                if two and cell(&s, k, z, bx0, bx1, by0, by1, &ix, &iy):
                    if u_mid < tail:
                        l_pass = 0.0 if held[(iy - by0) * bw + ix - bx0] else l_free * trust
                        log_odds[iy, ix] += weight(u_mid, u_out, mu, l_hit, l_ahead, l_pass)
                    extra = depth(u_mid, dz, tail, l_hit, l_deep) if u_mid > 0 else 0.0
                    if extra > 0 and n_deep < deep_cap:
                        deep_at[n_deep], deep_w[n_deep] = iy * nx + ix, extra
                        n_deep += 1
        if kept:
            # the runs' cumulative sums (down the columns, then along each row) count the
            # valid beams' clean passes: add their l_free (none in held cells), unclamped.
            # One pass, row by row: a row's column sums need only the row above; with
            # no-return beams to come it leaves the runs zeroed behind it for them
            again = nb > nv
            for iy in range(bh):
                row = rx + iy * (bw + 1)
                col = ry + iy * bw
                out = &log_odds[by0 + iy, bx0]
                run = 0
                for ix in range(bw):
                    if iy > 0:
                        col[ix] += col[ix - bw]
                        if again:
                            col[ix - bw] = 0
                    run += row[ix]
                    if again:
                        row[ix] = 0
                    if not held[iy * bw + ix]:
                        out[ix] += <double>(run + col[ix]) * l_free
                if again:
                    row[bw] = 0                        # (the spare column past the box)
            if again:                                  # the last row and the spare one
                memset(ry + (bh - 1) * bw, 0, 2 * bw * sizeof(long long))
        if nb > nv and stops:
            for iy in range(bh):
                out = &log_odds[by0 + iy, bx0]
                run = 0
                for ix in range(bw):
                    run += <long long>(out[ix] > stop_at
                                       and (any_cell or ends[by0 + iy, bx0 + ix] != 0))
                    sat[(iy + 1) * sw + ix + 1] = sat[iy * sw + ix + 1] + <int>run
        for j in range(nv, nb):                        # no-return beams
            e = &beams[j, 0]
            if not clip(e[0], e[1], e[2], e[3], nx, ny, &s):
                continue
            kept += 1
            # the columns before the first chunk of SAT_COLUMNS whose box (± one cell) holds
            # a cell above no_return_stop cannot stop the beam: runs, as a valid beam's far part
            n_far = 0
            if not s.short:
                n_far = s.count
                k = 0
                while stops and k < s.count:
                    u_in = dmax(s.t_col0 + k * s.t_col, s.t0)
                    u_out = dmin(s.t_col0 + (k + SAT_COLUMNS) * s.t_col, s.t1)
                    qx0 = clampl(lfloor(e[0] + dmin(u_in * e[2], u_out * e[2])) - 1 - bx0, bw - 1)
                    qx1 = clampl(lfloor(e[0] + dmax(u_in * e[2], u_out * e[2])) + 1 - bx0, bw - 1)
                    qy0 = clampl(lfloor(e[1] + dmin(u_in * e[3], u_out * e[3])) - 1 - by0, bh - 1)
                    qy1 = clampl(lfloor(e[1] + dmax(u_in * e[3], u_out * e[3])) + 1 - by0, bh - 1)
                    if (sat[(qy1 + 1) * sw + qx1 + 1] - sat[qy0 * sw + qx1 + 1]
                            - sat[(qy1 + 1) * sw + qx0] + sat[qy0 * sw + qx0]):
                        n_far = k
                        break
                    k += SAT_COLUMNS
                t_end = dmin(s.t_col0 + n_far * s.t_col, s.t1)
                if n_far > 0 and (t_end - s.t0) * s.length >= SHORT_CELLS:
                    add_runs(&s, t_end, 1, bx0, by0, bw, bh, rx, ry)
                    silent_runs = True
                else:
                    n_far = 0
            # l_no_return on every cell up to the first one the map, with this batch's valid
            # readings, holds occupied (a surface at grazing incidence returns nothing)
            columns(&s, 1.0, 0.0, &c)
            for k in range(n_far, s.count):
                two = column(&c, k, &a, &z, &u_in, &u_mid, &u_out)
                if cell(&s, k, a, bx0, bx1, by0, by1, &ix, &iy):
                    if log_odds[iy, ix] > stop_at and (any_cell or ends[iy, ix] != 0):
                        break
                    passes[(iy - by0) * bw + ix - bx0] += 1
                if two and cell(&s, k, z, bx0, bx1, by0, by1, &ix, &iy):
                    if log_odds[iy, ix] > stop_at and (any_cell or ends[iy, ix] != 0):
                        break
                    passes[(iy - by0) * bw + ix - bx0] += 1
        for j in range(n_deep):                        # the surface's depth
            grid[deep_at[j]] += deep_w[j]
        if kept:
            # the no-return passes' log-odds (none in held cells), then the clamp; the
            # silent runs' counts (cumulative sums as above) join the walked passes first
            for iy in range(bh):
                out = &log_odds[by0 + iy, bx0]
                row = rx + iy * (bw + 1)
                col = ry + iy * bw
                run = 0
                for ix in range(bw):
                    n_pass = passes[iy * bw + ix]
                    if silent_runs:
                        if iy > 0:
                            col[ix] += col[ix - bw]
                        run += row[ix]
                        n_pass += <int>(run + col[ix])
                    v = out[ix]
                    if not held[iy * bw + ix]:
                        v += n_pass * l_nr
                    out[ix] = lo if v < lo else (hi if v > hi else v)
    return kept > 0


def first_material(const double[::1] x0, const double[::1] y0, const double[::1] dx,
                   const double[::1] dy, const short[:, ::1] label, const Py_ssize_t[::1] tx,
                   const Py_ssize_t[::1] ty):
    """Per segment j, the ``label`` (> 0: material) of the first cell it visits, walking as
    :func:`walk` does, that is not within one cell (Chebyshev) of its target cell
    (tx[j], ty[j]); 0 when there is none. The walk stops there: a line-of-sight test over
    many cells without listing every visit (``metrics`` ground truth; its numpy oracle is
    ``metrics._sight_oracle``)."""
    cdef Py_ssize_t n = x0.shape[0], j
    cdef long nx = label.shape[1], ny = label.shape[0], k, ix, iy
    cdef Seg s
    cdef Cols c
    cdef double a, z, u_in, u_mid, u_out
    cdef bint two
    cdef short lab
    if (y0.shape[0] != n or dx.shape[0] != n or dy.shape[0] != n or tx.shape[0] != n
            or ty.shape[0] != n):
        raise lengths_differ("segment arrays", x0=n, y0=y0.shape[0], dx=dx.shape[0],
                             dy=dy.shape[0], tx=tx.shape[0], ty=ty.shape[0])
    out_a = np.zeros(n, np.int16)
    cdef short[::1] out = out_a
    with nogil:
        for j in range(n):
            if not clip(x0[j], y0[j], dx[j], dy[j], nx, ny, &s):
                continue
            columns(&s, 1.0, 0.0, &c)
            for k in range(s.count):
                two = column(&c, k, &a, &z, &u_in, &u_mid, &u_out)
                if cell(&s, k, a, 0, nx - 1, 0, ny - 1, &ix, &iy):
                    lab = label[iy, ix]
                    if lab > 0 and (ix - tx[j] > 1 or tx[j] - ix > 1 or iy - ty[j] > 1
                                    or ty[j] - iy > 1):
                        out[j] = lab
                        break
                if two and cell(&s, k, z, 0, nx - 1, 0, ny - 1, &ix, &iy):
                    lab = label[iy, ix]
                    if lab > 0 and (ix - tx[j] > 1 or tx[j] - ix > 1 or iy - ty[j] > 1
                                    or ty[j] - iy > 1):
                        out[j] = lab
                        break
    return out_a


cdef inline Py_ssize_t lower_bound(const double* keys, Py_ssize_t n, double v) noexcept nogil:
    # the first index whose key is ≥ v (keys ascending)
    cdef Py_ssize_t lo = 0, hi = n, mid
    while lo < hi:
        mid = (lo + hi) >> 1
        if keys[mid] < v:
            lo = mid + 1
        else:
            hi = mid
    return lo


cdef inline Py_ssize_t upper_bound(const double* keys, Py_ssize_t n, double v) noexcept nogil:
    # the first index whose key is > v (keys ascending)
    cdef Py_ssize_t lo = 0, hi = n, mid
    while lo < hi:
        mid = (lo + hi) >> 1
        if keys[mid] <= v:
            lo = mid + 1
        else:
            hi = mid
    return lo


def explained_ranges(const double[::1] origin_x, const double[::1] origin_y,
                     const double[::1] x, const double[::1] y, const double[::1] sigma_m,
                     const unsigned char[::1] valid, double grid_x, double grid_y, double res,
                     long nx, long ny, params):
    """The range (m) each reading is mapped at where a sharper surface explains it, NaN
    elsewhere (flat arrays, metres; ``valid`` as uint8): ``mapping.explained_ranges``, whose
    numpy oracle is ``mapping_numpy.explained_ranges``. The batch's end points inside the
    grid are sorted by cell, then σ (numpy's argsort), so a cell's hits of σ up to s are a
    prefix sum found by binary search; each candidate's beam is walked cell by cell
    (Amanatides–Woo, no visit for a cell it stays in less than TOUCH_CELLS) from
    explain_sigmas·σ before its end point until a cell confirms it or none can."""
    cdef Py_ssize_t n = origin_x.shape[0], i, j, m = 0, nc = 0, lo_i, hi_i
    if not (origin_y.shape[0] == x.shape[0] == y.shape[0] == sigma_m.shape[0]
            == valid.shape[0] == n):
        raise lengths_differ("the readings' arrays", origin_x=n, origin_y=origin_y.shape[0],
                             x=x.shape[0], y=y.shape[0], sigma_m=sigma_m.shape[0],
                             valid=valid.shape[0])
    out_a = np.full(n, np.nan)
    cdef double[::1] out = out_a
    cdef double k_sig = params.explain_sigmas, ratio = params.explain_sharper
    cdef double need = params.explain_log_odds, lone = params.lone_sigma_m
    cdef double min_sigma = params.min_sigma_m, default_sigma = params.default_sigma_m
    cdef double l_occ = params.l_occ, l_occ_min = params.l_occ_min, occ_sigma = params.occ_sigma_m
    if not k_sig > 0 or n == 0:
        return out_a
    keys_a = np.empty(n)
    w_a = np.empty(n)
    cand_a = np.empty(n, np.intp)
    cdef double[::1] keys = keys_a
    cdef double[::1] w = w_a
    cdef Py_ssize_t[::1] cand = cand_a
    cdef double inv = 1.0 / res, s, d, vx, vy, cx, cy
    with nogil:
        for i in range(n):
            if not (valid[i] and isfinite(x[i] + y[i]) and isfinite(origin_x[i] + origin_y[i])):
                continue
            s = sigma_m[i] if isfinite(sigma_m[i]) else default_sigma
            s = dmax(s, min_sigma)
            cx, cy = ffloor((x[i] - grid_x) * inv), ffloor((y[i] - grid_y) * inv)
            if 0 <= cx < nx and 0 <= cy < ny:
                keys[m] = cy * nx + cx + dmin(s, 0.5)
                w[m] = hit_log_odds(s, l_occ, l_occ_min, occ_sigma, lone)
                m += 1
            vx, vy = x[i] - origin_x[i], y[i] - origin_y[i]
            d = sqrt(vx * vx + vy * vy)
            if s >= ratio * min_sigma and s <= lone and d - res > dmax(d - k_sig * s, 0.0):
                cand[nc] = i
                nc += 1
    if nc == 0 or m == 0:
        return out_a
    order = np.argsort(keys_a[:m], kind="stable")
    sorted_a = keys_a[:m][order]
    cum_a = np.zeros(m + 1)
    cum_a[1:] = np.cumsum(w_a[:m][order])
    cdef double[::1] sk = sorted_a
    cdef double[::1] cum = cum_a
    cdef double a, ux, uy, px0, py0, length, t, t_exit, tmx, tmy, tdx, tdy, s_a, s_b, cell
    cdef long ix, iy, stx, sty
    with nogil:
        for j in range(nc):
            i = cand[j]
            s = sigma_m[i] if isfinite(sigma_m[i]) else default_sigma
            s = dmax(s, min_sigma)
            vx, vy = x[i] - origin_x[i], y[i] - origin_y[i]
            d = sqrt(vx * vx + vy * vy)
            ux, uy = vx / d, vy / d
            a = dmax(d - k_sig * s, 0.0)
            # the window's start in cells, and its length in cells
            px0 = (origin_x[i] + ux * a - grid_x) * inv
            py0 = (origin_y[i] + uy * a - grid_y) * inv
            length = (d - a) * inv
            ix, iy = lfloor(px0), lfloor(py0)
            stx = 1 if ux > 0 else -1
            sty = 1 if uy > 0 else -1
            tdx = 1.0 / fabs(ux) if ux != 0 else INFINITY
            tdy = 1.0 / fabs(uy) if uy != 0 else INFINITY
            tmx = ((ix + (ux > 0)) - px0) / ux if ux != 0 else INFINITY
            tmy = ((iy + (uy > 0)) - py0) / uy if uy != 0 else INFINITY
            t = 0.0
            while True:
                t_exit = dmin(dmin(tmx, tmy), length)
                s_a, s_b = a + t * res, a + t_exit * res
                if s_a >= d - res:
                    break
                if t_exit - t >= TOUCH_CELLS and s_b <= d - res and 0 <= ix < nx \
                        and 0 <= iy < ny:
                    cell = <double>(iy * nx + ix)
                    lo_i = lower_bound(&sk[0], m, cell)
                    hi_i = upper_bound(&sk[0], m, cell + dmin(s / ratio, 0.5))
                    if cum[hi_i] - cum[lo_i] >= need:
                        out[i] = 0.5 * (s_a + s_b)
                        break
                if t_exit >= length:
                    break
                if tmx < tmy:
                    ix += stx
                    t = tmx
                    tmx += tdx
                elif tmy < tmx:
                    iy += sty
                    t = tmy
                    tmy += tdy
                else:                                  # through a corner: the diagonal cell
                    ix += stx
                    iy += sty
                    t = tmx
                    tmx += tdx
                    tmy += tdy
    return out_a


def neighbour_ranges(const double[::1] origin_x, const double[::1] origin_y,
                     const double[::1] x, const double[::1] y, const double[::1] sigma_m,
                     const unsigned char[::1] valid, long rows, long cols, params):
    """The range (m) each reading its sensor's neighbouring steps bracket is mapped at, NaN
    elsewhere: ``mapping.neighbour_ranges`` on flat (rows, cols) arrays (row-major; a
    column is a sensor, a row a step), whose numpy oracle is
    ``mapping_numpy.neighbour_ranges``. Each column's valid readings are visited in row
    order, each compared with the valid ones before and after it in that order whose beams
    bracket its own (the beam turns one way from the one before to it and on to the one
    after); one of σ > lone_sigma_m with a neighbour on one side only, with that one."""
    cdef Py_ssize_t n = rows * cols, c, r, i, k, m, prev, nxt
    if not (origin_x.shape[0] == origin_y.shape[0] == x.shape[0] == y.shape[0]
            == sigma_m.shape[0] == valid.shape[0] == n):
        raise lengths_differ(f"the readings' arrays (rows × cols = {n})",
                             origin_x=origin_x.shape[0], origin_y=origin_y.shape[0],
                             x=x.shape[0], y=y.shape[0], sigma_m=sigma_m.shape[0],
                             valid=valid.shape[0])
    out_a = np.full(n, np.nan)
    cdef double[::1] out = out_a
    cdef long steps = <long>params.neighbour_steps
    cdef double k_sig = params.explain_sigmas, lone = params.lone_sigma_m
    cdef double min_sigma = params.min_sigma_m, default_sigma = params.default_sigma_m
    cdef double low = params.explain_sharper * params.min_sigma_m
    if steps == 0 or rows < 3 or n == 0:
        return out_a
    d_a, s_a = np.empty(n), np.empty(n)
    at_a = np.empty(rows, np.intp)
    cdef double[::1] d = d_a
    cdef double[::1] s = s_a
    cdef Py_ssize_t[::1] at = at_a
    cdef double dp, dn, si, turn_p, turn_n
    cdef bint near_p, near_n, has_p, has_n
    with nogil:
        for c in range(cols):
            m = 0                                   # the column's valid readings, in row order
            for r in range(rows):
                i = r * cols + c
                if not (valid[i] and isfinite(x[i] + y[i])
                        and isfinite(origin_x[i] + origin_y[i])):
                    continue
                si = sigma_m[i]
                if isnan(si):
                    si = default_sigma
                elif si == INFINITY:
                    si = DBL_MAX                    # (as numpy's nan_to_num)
                s[i] = si if si > min_sigma else min_sigma
                d[i] = hypot(x[i] - origin_x[i], y[i] - origin_y[i])
                at[m] = r
                m += 1
            for k in range(m):
                r = at[k]
                i = r * cols + c
                if not s[i] >= low:
                    continue
                has_p = k > 0 and r - at[k - 1] <= steps
                has_n = k < m - 1 and at[k + 1] - r <= steps
                if has_p != has_n:
                    # one neighbour only: an uncertain end point is not read behind it
                    # when it is sharper, shorter and within their noise
                    if s[i] <= lone:
                        continue
                    prev = at[k - 1] * cols + c if has_p else at[k + 1] * cols + c
                    if (s[prev] < s[i] and d[prev] < d[i] and hypot(
                            x[prev] - x[i], y[prev] - y[i]) <= k_sig * hypot(s[prev], s[i])):
                        out[i] = d[prev]
                    continue
                if not has_p:
                    continue
                prev, nxt = at[k - 1] * cols + c, at[k + 1] * cols + c
                # rows in any order (a sweep asked for steps 5, -10, 30): beams on one side
                turn_p = ((x[prev] - origin_x[prev]) * (y[i] - origin_y[i])
                          - (y[prev] - origin_y[prev]) * (x[i] - origin_x[i]))
                turn_n = ((x[i] - origin_x[i]) * (y[nxt] - origin_y[nxt])
                          - (y[i] - origin_y[i]) * (x[nxt] - origin_x[nxt]))
                if not ((turn_p > 0 and turn_n > 0) or (turn_p < 0 and turn_n < 0)):
                    continue
                near_p = hypot(x[prev] - x[i], y[prev] - y[i]) <= k_sig * hypot(s[prev], s[i])
                near_n = hypot(x[nxt] - x[i], y[nxt] - y[i]) <= k_sig * hypot(s[nxt], s[i])
                if not (near_p and near_n):
                    continue
                dp, dn = d[prev], d[nxt]
                if dp < d[i] and dn < d[i]:
                    out[i] = dp if dp > dn else dn
                elif dp > d[i] and dn > d[i] and s[i] <= lone:
                    out[i] = dp if dp < dn else dn
    return out_a
