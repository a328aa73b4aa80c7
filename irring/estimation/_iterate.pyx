# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
# distutils: extra_compile_args = -ffp-contract=off
"""Compiled kernels for the iteration of the Table II estimator (docs/estimator.md explains
the algorithm; :func:`irring.estimation.estimate.estimate_detail` runs the loop).

The loop works on one sweep's live readings (~850) and its lines (~30). Written with numpy it
made ~1,500 calls per sweep, bound by per-call overhead; here each phase is one call:

- :class:`Sweep`: the live readings in scan order and their placement at a θ;
- :class:`Grouping`: membership (members, settle_corners, corner_sides, drop_steep, adopt),
  line refits and the plain step θ ← θ_new;
- :class:`Held`: the held iterations, run until they settle, a regroup is due or a
  membership check is needed;
- :meth:`Sweep.finish`: final points, σ (with the θ = 0 fallback's spread) and reasons.

Same answers as the numpy code it replaces, bit for bit: the same operations in the same
order per element; exp and arctan2 are numpy's own, called on contiguous buffers (numpy's
SIMD versions differ from libm's in the last bit, and a last bit can flip a threshold);
cos, sin, hypot, sqrt, floor and rint are libm's, as numpy's are; sums repeat numpy's
pairwise summation (np.add.reduceat and np.mean sum a segment of more than 8 terms with 8
accumulators, not one after another); minima pick the first index as argmin does (the
first NaN if any); groupings by line are stable. The (log a, b) look-ups compute the
calibration's fine-table rows from its nodes, which the calibration checked to equal the
table row by row (:func:`fine_table_is_interp`; else the table is read): in a real run
segmentation evicts the 1 MB table between phases, so reading it was mostly cache misses.
The build must not fuse a·b + c into one rounding (``-ffp-contract=off``; x86-64's
default code has no FMA anyway).

Indexing is unchecked (boundscheck off), so the entry points check what they index
through: :class:`Sweep` the sizes and the scan order, :class:`Grouping` the pieces (no
more pieces than points: the scratch rows hold one entry per live reading), the methods
taking per-reading arrays their length. A label of −1 (no line) is never used as an index.
"""

cimport cython
import numpy as np

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

from libc.math cimport cos, fabs, floor, hypot, isfinite, rint, sin, sqrt

from ..core import Reason
from ..errors import lengths_differ

cdef object _exp = np.exp
cdef object _tan = np.tan
cdef object _log = np.log
cdef object _arctan2 = np.arctan2
cdef object _empty = np.empty
cdef object _intp = np.intp
cdef object _uint8 = np.uint8

cdef double PI = 3.141592653589793      # math.pi
cdef double HALF_PI = PI / 2.0
cdef double INV_PI = 1.0 / PI
cdef double INF = float("inf")
cdef double NAN = float("nan")

cdef unsigned char R_OK = int(Reason.OK)
cdef unsigned char R_NO_RETURN = int(Reason.NO_RETURN)
cdef unsigned char R_OUT_OF_RANGE = int(Reason.OUT_OF_RANGE)
cdef unsigned char R_FOLDOVER = int(Reason.FOLDOVER_AMBIGUOUS)
cdef unsigned char R_SATURATED = int(Reason.SATURATED)
cdef unsigned char R_NOT_CONVERGED = int(Reason.NOT_CONVERGED)
cdef unsigned char R_MISSING = int(Reason.MISSING)

# what Held.run stopped for
LIMIT = 0      # max_iterations reached
CHECK = 1      # a member meets its line past the drop-out angle: check membership first
SETTLED = 2    # no member's θ moved by the tolerance
REGROUP = 3    # θ settled coarsely: group the straightened points again
STEPPED = 4    # one step done (run(..., one_step=True), for the θ history)

# readings × lines re-read at once (settle_corners, adopt): a long sweep's thousands of lines
# would otherwise hold all its edge readings against all of them (8 bytes twice each)
cdef Py_ssize_t REREAD_BLOCK = 1 << 18


# --------------------------------------------------------------------------- helpers


cdef inline double _min(double a, double b) noexcept nogil:
    """np.minimum (a NaN wins)."""
    if a != a or a <= b:
        return a
    return b


cdef inline double _max(double a, double b) noexcept nogil:
    """np.maximum (a NaN wins)."""
    if a != a or a >= b:
        return a
    return b


cdef inline Py_ssize_t _max_n(Py_ssize_t a, Py_ssize_t b) noexcept nogil:
    return a if a >= b else b


cdef inline double _incidence(double hm, double alpha) noexcept nogil:
    """Angle between a beam (heading mod π) and the normal of a line at direction angle α in
    [0, π): with δ = h − α, cos θ = |sin δ|, so θ = |π/2 − |δ||."""
    return fabs(HALF_PI - fabs(hm - alpha))


cdef double _pairwise(const double* a, Py_ssize_t n) noexcept nogil:
    """numpy's pairwise sum of n ≥ 1 doubles: in order below 8 terms, 8 accumulators up to
    128, halves (at a multiple of 8) above."""
    cdef Py_ssize_t i, n2
    cdef double res, r0, r1, r2, r3, r4, r5, r6, r7
    if n < 8:
        res = a[0]          # numpy starts from −0.0, and −0.0 + a[0] is a[0] exactly
        for i in range(1, n):
            res += a[i]
        return res
    if n <= 128:
        r0 = a[0]
        r1 = a[1]
        r2 = a[2]
        r3 = a[3]
        r4 = a[4]
        r5 = a[5]
        r6 = a[6]
        r7 = a[7]
        i = 8
        while i < n - (n % 8):
            r0 += a[i]
            r1 += a[i + 1]
            r2 += a[i + 2]
            r3 += a[i + 3]
            r4 += a[i + 4]
            r5 += a[i + 5]
            r6 += a[i + 6]
            r7 += a[i + 7]
            i += 8
        res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
        while i < n:
            res += a[i]
            i += 1
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return _pairwise(a, n2) + _pairwise(a + n2, n - n2)


cdef inline double _segment_sum(const double* a, Py_ssize_t n) noexcept nogil:
    """np.add.reduceat over one segment of n ≥ 1: the first term plus the rest's pairwise sum."""
    if n == 1:
        return a[0]
    return a[0] + _pairwise(a + 1, n - 1)


cdef inline double _tls(const double* m, Py_ssize_t row, Py_ssize_t c, double cnt,
                        double* p, double* q, double* mx, double* my) noexcept nogil:
    """Total least squares over c ≥ 1 points from their moments (rows x, y, x², y², xy,
    ``row`` apart from ``m`` on; cnt = c as a double), each summed as np.add.reduceat does:
    the mean (mx, my), and p = 2·Sxy, q = Sxx − Syy, whose arctan2(p, q)/2 is the line's
    direction angle. Returns Sxx + Syy (0: the points coincide). The refit and the held
    iterations both fit lines this way; one copy keeps them the same bit for bit."""
    cdef double t0 = _segment_sum(m, c)
    cdef double t1 = _segment_sum(m + row, c)
    cdef double t2 = _segment_sum(m + 2 * row, c)
    cdef double t3 = _segment_sum(m + 3 * row, c)
    cdef double t4 = _segment_sum(m + 4 * row, c)
    cdef double sxy
    mx[0] = t0 / cnt
    my[0] = t1 / cnt
    sxy = t4 - t0 * my[0]
    p[0] = sxy + sxy
    q[0] = (t2 - t0 * mx[0]) - (t3 - t1 * my[0])
    return (t2 - t0 * mx[0]) + (t3 - t1 * my[0])


cdef inline double _sign(double v) noexcept nogil:
    """np.sign: −1, 0 or 1 (NaN stays NaN)."""
    return (1.0 if v > 0 else -1.0 if v < 0 else 0.0) if v == v else v


cdef inline Py_ssize_t _argmin(const double* r, Py_ssize_t n) noexcept nogil:
    """np.argmin of n ≥ 1 values: the first minimum, or the first NaN if there is one."""
    cdef Py_ssize_t j, best = 0
    cdef double v = r[0]
    if v != v:
        return 0
    for j in range(1, n):
        if r[j] < v:
            v = r[j]
            best = j
        elif r[j] != r[j]:
            return j
    return best


cdef int _per_reading(Py_ssize_t n, Py_ssize_t k, str name) except -1:
    """Refuse an array with fewer than one entry per live reading: the kernels index
    without bounds checks."""
    if n < k:
        raise ValueError(f"{name} has {n} entries for {k} live readings")
    return 0


cdef inline double _fine_x(Py_ssize_t c, Py_ssize_t top, double step) noexcept nogil:
    """np.linspace(0, π/2, top + 1)[c]: c·step, the last node π/2 itself."""
    return HALF_PI if c == top else c * step


cdef inline double _interp_at(double x, Py_ssize_t j, const double* xp, const double* fp,
                              const double* slope, Py_ssize_t n) noexcept nogil:
    """np.interp(x, xp, fp) given j, the last of the n nodes xp at or below x (−1: none):
    held at the ends, fp[j] on a node, else slope·(x − xp[j]) + fp[j] with
    slope = (fp[j+1] − fp[j]) / (xp[j+1] − xp[j])."""
    if j < 0:
        return fp[0]
    if j >= n - 1:
        return fp[n - 1]
    if x == xp[j]:
        return fp[j]
    return slope[j] * (x - xp[j]) + fp[j]


cdef void _slopes(const double[::1] xp, const double[::1] fp, double[::1] out) noexcept:
    """Each interval's slope (fp[j+1] − fp[j]) / (xp[j+1] − xp[j]) into out[j], computed once
    as np.interp computes it, for :func:`_interp_at`."""
    cdef Py_ssize_t j
    for j in range(xp.shape[0] - 1):
        out[j] = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])


def fine_table_is_interp(const double[::1] xp, const double[::1] log_a, const double[::1] b,
                         const double[:, ::1] table):
    """Whether the calibration's fine table (rows log a, b at np.linspace(0, π/2, cells + 1),
    by np.interp over the nodes ``xp``) equals, bit for bit at every row, what
    :meth:`Sweep.look` computes from the nodes. Then the estimator computes its look-ups
    instead of reading the 1 MB table, whose rows are mostly cache misses; if not (another
    numpy rounding the interpolation differently), it reads the table."""
    cdef Py_ssize_t n = xp.shape[0], top = table.shape[0] - 1, c, j = -1
    cdef double x, step
    if n < 1 or top < 1:
        return False
    if not (log_a.shape[0] == b.shape[0] == n and table.shape[1] == 2):
        raise ValueError("need log a and b at every node and a (cells + 1, 2) table")
    step = HALF_PI / top
    sa_arr, sb_arr = _empty(max(n - 1, 1)), _empty(max(n - 1, 1))
    cdef double[::1] sa = sa_arr, sb = sb_arr
    _slopes(xp, log_a, sa)
    _slopes(xp, b, sb)
    for c in range(top + 1):
        x = _fine_x(c, top, step)
        while j + 1 < n and xp[j + 1] <= x:
            j += 1
        if (_interp_at(x, j, &xp[0], &log_a[0], &sa[0], n) != table[c, 0]
                or _interp_at(x, j, &xp[0], &b[0], &sb[0], n) != table[c, 1]):
            return False
    return True


def classify(const double[::1] counts, unsigned char[::1] reason, double full, double near,
             double no_return, double margin, double weak, bint falling):
    """Reasons decided by the counts alone (before any distance is computed), into
    ``reason`` (zeros on entry). Assigned from the weakest claim up, so MISSING > SATURATED >
    FOLDOVER_AMBIGUOUS > NO_RETURN: a GP2 (``falling``) reading at or below the noise floor
    (``margin`` counts above the no-return level) is NO_RETURN, one up to ``weak`` counts
    above it OUT_OF_RANGE (too weak to tell from noise), one brighter than the curve's near end
    FOLDOVER_AMBIGUOUS; a linear sensor's (sonar/laser hooks) no return reads as max range
    and it has no fold-over; full scale is SATURATED, NaN MISSING."""
    cdef Py_ssize_t i
    cdef double s
    cdef unsigned char r
    if reason.shape[0] != counts.shape[0]:
        raise lengths_differ("counts and reason", counts=counts.shape[0],
                             reason=reason.shape[0])
    for i in range(counts.shape[0]):
        s = counts[i]
        r = R_OK
        if falling:
            if s <= no_return + weak:
                r = R_OUT_OF_RANGE
            if s <= no_return + margin or s <= 0:
                r = R_NO_RETURN
            if s > near:
                r = R_FOLDOVER
        elif s >= no_return - margin or s <= 0:
            r = R_NO_RETURN
        if s >= full - 0.5:
            r = R_SATURATED
        if not isfinite(s):
            r = R_MISSING
        reason[i] = r


def same(const Py_ssize_t[::1] a, const Py_ssize_t[::1] b):
    """Whether two label arrays are equal (np.array_equal)."""
    cdef Py_ssize_t i
    if a.shape[0] != b.shape[0]:
        return False
    for i in range(a.shape[0]):
        if a[i] != b[i]:
            return False
    return True


# --------------------------------------------------------------------------- the readings


@cython.final
cdef class Sweep:
    """One sweep's live readings in scan order (sensor by sensor, by step), and the
    calibration's curve, for the loop: everything per reading that θ does not change.

    ``index``: flat (S, N) index of each live reading; ``sensor``: its sensor; runs for the
    corner check break at a sensor change or a reading that is not live. ``centre``: the
    emitters' mean (lines are summed about it so small spreads keep their digits).
    :meth:`place` puts the readings at a θ (``d``, ``px``, ``py``, ``sigma``, ``thr``).
    """

    cdef readonly Py_ssize_t k, size
    cdef readonly object index, sensor, centre, log_s
    cdef readonly object d, px, py, sigma, thr
    cdef readonly double cap, reject
    cdef const double[:, ::1] ab_t
    # the calibration's nodes, for computing the fine table's rows (see look)
    cdef bint exact
    cdef Py_ssize_t n_nodes
    cdef double step
    cdef double[::1] xp, fa, fb, sa, sb
    cdef Py_ssize_t[::1] bucket
    cdef double[::1] ls, ox, oy, ux, uy, hm, sig_s
    cdef Py_ssize_t[::1] ix
    cdef unsigned char[::1] run_brk
    cdef double[::1] _d, _px, _py, _sigma, _thr
    cdef unsigned char[::1] usable
    cdef bint all_usable
    cdef double inv_h, cx0, cy0, min_split, split_sigmas, adopt_margin, corner_sigmas
    cdef double corner_reach, corner_share, corner_past, jump_sigmas
    cdef double pinned, floor_m
    cdef Py_ssize_t corner_window, top
    # scratch for the kernels (each uses it within one call): index rows of k + 1, value
    # rows of k, a flag row, and a growing buffer (rr: re-read distances with their θ in
    # rr_th, or finish's quadrature terms; numpy's exp needs an array)
    cdef Py_ssize_t[:, ::1] iscr
    cdef double[:, ::1] dscr
    cdef object dscr_obj
    cdef unsigned char[::1] flag
    cdef object rr_obj
    cdef double[::1] rr_th
    cdef Py_ssize_t[::1] snap

    def __init__(self, cal, opts, const double[::1] counts, const double[::1] origin,
                 const double[::1] heading, const unsigned char[::1] reason,
                 const Py_ssize_t[::1] scan, Py_ssize_t n_sensors, double floor_m,
                 double pinned_rad, const double[::1] cos_h=None,
                 const double[::1] sin_h=None):
        """``counts``, ``heading`` (S·N,), ``origin`` (S·N·2,) flat in (S, N) order,
        ``reason`` the counts' verdicts (live: OK), ``scan`` the flat scan order;
        ``floor_m`` the smallest σ, ``pinned_rad`` (see Grouping.drop_steep); ``cos_h``,
        ``sin_h`` (S·N,): the headings' cos and sin where the caller has them (numpy's,
        which are libm's; else computed here). Raises ValueError unless the sizes agree and
        ``scan`` indexes within them (every kernel indexes unchecked through ``index``)."""
        cdef Py_ssize_t total = scan.shape[0], size = reason.shape[0], p, f, j, k = 0
        cdef Py_ssize_t prev = -2
        cdef double c, h, sigma_counts = cal._levels[3]
        cdef bint trig = cos_h is not None and sin_h is not None
        if not (counts.shape[0] == heading.shape[0] == size == total
                and origin.shape[0] == 2 * size):
            raise ValueError(f"counts, heading, reason, scan ({counts.shape[0]}, "
                             f"{heading.shape[0]}, {size}, {total}) need one entry per "
                             f"reading, origin ({origin.shape[0]}) two")
        if trig and not (cos_h.shape[0] == sin_h.shape[0] == size):
            raise ValueError(f"cos_h, sin_h ({cos_h.shape[0]}, {sin_h.shape[0]}) need one "
                             f"entry per reading ({size})")
        for p in range(total):
            f = scan[p]
            if f < 0 or f >= size:
                raise ValueError(f"scan[{p}] = {f} is not a reading (0 … {size - 1})")
            if reason[f] == R_OK:
                k += 1
        self.k = k
        self.size = size
        ints = _empty((2, k), dtype=_intp)
        self.index, self.sensor = ints[0], ints[1]
        cdef Py_ssize_t[:, ::1] iv = ints
        self.ix = iv[0]
        cdef Py_ssize_t[::1] sn = iv[1]
        self.run_brk = _empty(k, dtype=_uint8)
        rows = _empty((7, k))
        cdef double[:, ::1] rv = rows
        cdef double[::1] cc = rv[0]
        self.ox, self.oy, self.ux, self.uy = rv[1], rv[2], rv[3], rv[4]
        self.hm, self.sig_s = rv[5], rv[6]
        j = 0
        for p in range(total):
            f = scan[p]
            if reason[f] != R_OK:
                continue
            self.ix[j] = f
            sn[j] = f % n_sensors
            self.run_brk[j] = j == 0 or sn[j] != sn[j - 1] or p != prev + 1
            prev = p
            c = counts[f]
            cc[j] = c
            self.sig_s[j] = sigma_counts / c        # σ_d = |b|·d·σ_S/S
            self.ox[j] = origin[2 * f]
            self.oy[j] = origin[2 * f + 1]
            h = heading[f]
            if trig:
                self.ux[j] = cos_h[f]
                self.uy[j] = sin_h[f]
            else:
                self.ux[j] = cos(h)
                self.uy[j] = sin(h)
            self.hm[j] = h - PI * floor(h / PI)     # heading mod π
            j += 1
        self.log_s = _log(rows[0])
        self.ls = self.log_s
        if k:   # numpy's sum (pairwise, in blocks of its buffer size)
            self.centre = (float(rows[1].sum()) / k, float(rows[2].sum()) / k)
        else:
            self.centre = (0.0, 0.0)
        self.cx0, self.cy0 = self.centre
        self.inv_h, ab_t, self.exact = cal._fine
        self.ab_t = ab_t
        self.top = self.ab_t.shape[0] - 1
        self.step = HALF_PI / self.top
        if self.exact:
            self._nodes(cal)
        self.cap = cal.max_incidence_rad
        self.reject = self.cap + opts.incidence_margin_rad
        self.min_split = opts.min_split_m
        self.split_sigmas = opts.split_sigmas
        self.adopt_margin = opts.adopt_margin_m
        self.corner_window = opts.corner_window
        self.corner_sigmas = opts.corner_sigmas
        self.corner_reach = opts.corner_reach_m
        self.corner_share = opts.corner_reach_share
        self.corner_past = opts.corner_past_m
        self.jump_sigmas = opts.jump_sigmas
        self.floor_m = floor_m
        self.pinned = pinned_rad
        self.all_usable = True
        self.iscr = _empty((6, k + 1), dtype=_intp)
        self.dscr_obj = _empty((7, k))
        self.dscr = self.dscr_obj
        self.flag = _empty(k, dtype=_uint8)
        self.rr_obj = _empty(0)
        self.rr_th = _empty(0)
        # Grouping.check's labels from before: it calls kernels that use rows 0-4 in
        # between, so the snapshot needs a row of its own
        self.snap = self.iscr[5]

    cdef void _nodes(self, cal):
        """The calibration's nodes and slopes, and for every 256 rows of the fine table the
        interval their first row falls in."""
        cdef Py_ssize_t n, q, j = -1
        cdef double x
        nodes = _empty((5, cal.theta_rad.shape[0]))
        nodes[0], nodes[1], nodes[2] = cal.theta_rad, cal._log_a, cal.b
        cdef double[:, ::1] nv = nodes
        self.xp, self.fa, self.fb, self.sa, self.sb = nv[0], nv[1], nv[2], nv[3], nv[4]
        n = self.n_nodes = nv.shape[1]
        _slopes(self.xp, self.fa, self.sa)
        _slopes(self.xp, self.fb, self.sb)
        self.bucket = _empty((self.top >> 8) + 1, dtype=_intp)
        for q in range(self.bucket.shape[0]):
            x = _fine_x(q << 8, self.top, self.step)
            while j + 1 < n and self.xp[j + 1] <= x:
                j += 1
            self.bucket[q] = j

    cdef inline void look(self, double theta, double* la, double* b) noexcept nogil:
        """log a(θ), b(θ) at the fine table's node nearest θ (see :meth:`cell`): computed
        from the calibration's nodes exactly as the table was built (np.interp at
        np.linspace nodes; the calibration checked every row, see fine_table_is_interp),
        else read from the table."""
        cdef Py_ssize_t c = self.cell(theta), j, n = self.n_nodes
        cdef double x
        if not self.exact:
            la[0] = self.ab_t[c, 0]
            b[0] = self.ab_t[c, 1]
            return
        x = _fine_x(c, self.top, self.step)
        j = self.bucket[c >> 8]
        while j + 1 < n and self.xp[j + 1] <= x:
            j += 1
        la[0] = _interp_at(x, j, &self.xp[0], &self.fa[0], &self.sa[0], n)
        b[0] = _interp_at(x, j, &self.xp[0], &self.fb[0], &self.sb[0], n)

    cdef void curve(self, double theta, double* la, double* b) noexcept nogil:
        """log a(θ), b(θ) of the calibration (linear in |θ| between its nodes, held at the
        ends): Calibration.log_ab's np.interp, the same computation as :meth:`look` (only
        with ``exact``)."""
        cdef Py_ssize_t j, n = self.n_nodes
        cdef double x = fabs(theta)
        if x != x:
            la[0] = b[0] = x
            return
        j = <Py_ssize_t>_min(x * self.inv_h, <double>self.top) >> 8
        j = self.bucket[j]
        while j >= 0 and self.xp[j] > x:
            j -= 1
        while j + 1 < n and self.xp[j + 1] <= x:
            j += 1
        la[0] = _interp_at(x, j, &self.xp[0], &self.fa[0], &self.sa[0], n)
        b[0] = _interp_at(x, j, &self.xp[0], &self.fb[0], &self.sb[0], n)

    cdef inline Py_ssize_t cell(self, double theta) noexcept nogil:
        """The fine (log a, b) table's node nearest θ ∈ [0, π/2] (θ·cells/(π/2) + 0.5,
        truncated; clamped only so that a NaN cannot index outside the table)."""
        cdef double x = theta * self.inv_h + 0.5
        if x >= 0.0 and x < self.top + 1:
            return <Py_ssize_t>x
        return self.top if x >= 0.0 else 0

    cdef object rr(self, Py_ssize_t n):
        """The re-read buffer's first n entries as an array (grown when needed; ``rr_th``
        grows with it)."""
        if self.rr_obj.shape[0] < n:
            self.rr_obj = _empty(2 * n)
            self.rr_th = _empty(2 * n)
        return self.rr_obj[:n]

    def place(self, const double[::1] theta, double max_use_m):
        """Every live reading at incidence θ: d, end point, σ and split threshold (new arrays
        ``d``, ``px``, ``py``, ``sigma``, ``thr``); readings farther than ``max_use_m`` cannot
        help a line (but stay for the final check). Returns the indices of the rest, or None
        when that is all of them."""
        cdef Py_ssize_t i, k = self.k, n_use = 0
        cdef double dv, s, la
        _per_reading(theta.shape[0], k, "theta")
        rows = _empty((5, k))
        self.d, self.px, self.py, self.sigma, self.thr = rows
        cdef double[:, ::1] rv = rows
        self._d, self._px, self._py, self._sigma, self._thr = rv[0], rv[1], rv[2], rv[3], rv[4]
        self.usable = _empty(k, dtype=_uint8)
        cdef double[::1] b = self.dscr[0]
        for i in range(k):
            self.look(theta[i], &la, &b[i])
            self._d[i] = la + b[i] * self.ls[i]
        _exp(self.d, self.d)
        for i in range(k):
            dv = self._d[i]
            self._px[i] = self.ox[i] + dv * self.ux[i]
            self._py[i] = self.oy[i] + dv * self.uy[i]
            s = _max(fabs(b[i]) * dv * self.sig_s[i], self.floor_m)
            self._sigma[i] = s
            self._thr[i] = _max(self.min_split, self.split_sigmas * s)
            self.usable[i] = dv <= max_use_m
            n_use += self.usable[i]
        self.all_usable = n_use == k
        if self.all_usable:
            return None
        uidx = _empty(n_use, dtype=_intp)
        cdef Py_ssize_t[::1] u = uidx
        n_use = 0
        for i in range(k):
            if self.usable[i]:
                u[n_use] = i
                n_use += 1
        return uidx

    def scatter_theta(self, const double[::1] theta, Held held=None):
        """θ of every live reading into a flat (S·N,) array (0 elsewhere); members of
        ``held`` at its current θ. For ``Estimate.theta_history``."""
        cdef Py_ssize_t i
        _per_reading(theta.shape[0], self.k, "theta")
        out = np.zeros(self.size)
        cdef double[::1] o = out
        for i in range(self.k):
            o[self.ix[i]] = theta[i]
        if held is not None:
            for i in range(held.km):
                o[self.ix[held.perm[i]]] = held.theta[i]
        return out

    def finish(self, const double[::1] theta, const unsigned char[::1] on,
               const Py_ssize_t[::1] last_moving, Py_ssize_t n_its, bint iterate, cal,
               double max_range_m, unsigned char[::1] reason, bint keep_moving=False,
               double range_sigmas=0.0):
        """Final points with the exact curve (Calibration's log a(θ), b(θ): see
        :meth:`curve`; ``cal.log_ab`` where the fine table check failed) and reasons.
        Returns flat (S·N,) arrays x, y, d, θ, σ (NaN where not valid), iterations (int32)
        and valid, and writes each live reading's reason into ``reason`` (flat, S·N; the
        others keep theirs). ``theta``, ``on`` (on a line), ``last_moving``: per live reading.

        With ``iterate`` a reading on no line (``on`` 0) keeps θ = 0 and its σ is widened
        by the RMS error of the θ = 0 distance over the incidences a round surface gives
        (``cal._spread``: log a, b at the quadrature nodes, see
        ``estimate._fallback_nodes``). A reading still moving in the last iteration is
        NOT_CONVERGED (with ``keep_moving``: valid, at its last θ); a distance outside
        [min, max] range or a non-finite point is OUT_OF_RANGE, except that a reading on a
        line stays valid up to ``range_sigmas`` of its σ past the max range (a surface at
        the limit read long by noise: ``estimate.final_estimate`` keeps it only on its
        line, within range)."""
        cdef Py_ssize_t i, j, f, k = self.k, size = self.size
        cdef Py_ssize_t nodes, n_off = 0, o
        cdef double dv, s, px, py
        cdef unsigned char why
        cdef double[::1] d = self.dscr[0], sg = self.dscr[1], e, la, b
        cdef const double[::1] spread_la, spread_b
        if reason.shape[0] != size or min(theta.shape[0], on.shape[0], last_moving.shape[0]) < k:
            raise ValueError(f"finish needs reason per reading ({size}, has "
                             f"{reason.shape[0]}) and theta, on, last_moving per live reading "
                             f"({k}; have {theta.shape[0]}, {on.shape[0]}, "
                             f"{last_moving.shape[0]})")
        spread_la, spread_b = cal._spread
        cdef double min_range_m = cal.min_range_m
        d_arr = self.dscr_obj[0]
        if self.exact:
            la, b = self.dscr[2], self.dscr[3]
            for i in range(k):
                self.curve(theta[i], &la[i], &b[i])
        else:
            la, b = cal.log_ab(np.asarray(theta))
        for i in range(k):
            d[i] = la[i] + b[i] * self.ls[i]
        _exp(d_arr, d_arr)
        for i in range(k):
            sg[i] = _max(fabs(b[i]) * d[i] * self.sig_s[i], self.floor_m)
            if iterate and not on[i]:
                n_off += 1
        nodes = spread_la.shape[0]
        if n_off:
            # fallback readings: σ widened by θ's unknown (the spread over the nodes)
            e_arr = self.rr(n_off * nodes)
            e = e_arr
            o = 0
            for i in range(k):
                if not on[i]:
                    for j in range(nodes):
                        e[o * nodes + j] = spread_la[j] + spread_b[j] * self.ls[i]
                    o += 1
            _exp(e_arr, e_arr)
            o = 0
            for i in range(k):
                if not on[i]:
                    for j in range(nodes):
                        s = e[o * nodes + j] - d[i]
                        e[o * nodes + j] = s * s
                    s = (0.0 + _pairwise(&e[o * nodes], nodes)) / nodes   # np.mean
                    sg[i] = hypot(sg[i], sqrt(s))
                    o += 1
        out = np.full((5, size), NAN)
        it_out = np.full(size, 1 if iterate else 0, dtype=np.int32)
        cdef double[:, ::1] ov = out
        cdef int[::1] io = it_out
        for i in range(k):
            f = self.ix[i]
            dv = d[i]
            px = self.ox[i] + dv * self.ux[i]
            py = self.oy[i] + dv * self.uy[i]
            io[f] = <int>min(last_moving[i] + 2, n_its)
            # (a line member's σ is its noise alone: only fallbacks were widened)
            if (dv - (range_sigmas * sg[i] if iterate and on[i] else 0.0) > max_range_m
                    or dv < min_range_m or not isfinite(dv)):
                why = R_OUT_OF_RANGE
            elif n_its and last_moving[i] == n_its - 1 and not keep_moving:
                why = R_NOT_CONVERGED
            elif not (isfinite(px) and isfinite(py) and isfinite(sg[i])):
                why = R_OUT_OF_RANGE
            else:
                why = R_OK
            reason[f] = why
            if why == R_OK:
                ov[0, f] = px
                ov[1, f] = py
                ov[2, f] = dv
                ov[3, f] = theta[i]
                ov[4, f] = sg[i]
        valid = _empty(size, dtype=np.bool_)
        cdef unsigned char[::1] ok = valid.view(_uint8)
        for f in range(size):
            ok[f] = reason[f] == R_OK
        return out[0], out[1], out[2], out[3], out[4], it_out, valid


# --------------------------------------------------------------------------- membership


@cython.final
cdef class Grouping:
    """The lines of the current iteration and which reading takes θ from which line.

    Built on split-and-merge pieces (``lines.segment``) over the usable readings
    (``uidx``: their live indices; None: all of them). ``label`` (live readings): the line
    each reading takes θ from, or −1. The lines start as the pieces' TLS lines (``cx``,
    ``cy``, direction angle ``alpha`` in [0, π), ``usable``) and are refitted to their
    members by :meth:`refit`. All methods use the readings where the sweep last placed them
    (:meth:`Sweep.place`) and change the grouping in place.
    """

    cdef readonly Sweep sw
    cdef readonly object pieces, uidx, cx, cy, alpha, usable, label
    cdef double[::1] _cx, _cy, _alpha
    cdef unsigned char[::1] _usable
    cdef Py_ssize_t[::1] _label, first, last, owner, starts, ends, _uidx
    cdef Py_ssize_t n_lines
    # the usable lines for re-reading, built when first needed (see _table)
    cdef bint tab_ok
    cdef Py_ssize_t n_use
    cdef Py_ssize_t[::1] t_use, t_col
    cdef double[::1] t_a, t_cx, t_cy, t_dx, t_dy, t_lo, t_hi
    # per-line scratch (refit: p, q → arctan2; members: cos, sin)
    cdef double[:, ::1] lscr
    cdef object p_obj, q_obj

    def __init__(self, Sweep sw, pieces, uidx):
        """The pieces' lines copied into one block (refit moves them in place; the pieces
        stay as segmentation left them, for the next regroup to refine), each piece's first
        and last reading as live indices (the extents :meth:`_table` reads), no labels yet
        (:meth:`members` gives them). Raises ValueError if the pieces do not fit the
        points: every method indexes through them unchecked."""
        cdef Py_ssize_t l, i, n, n_points = sw.k if uidx is None else len(uidx)
        self.sw = sw
        self.pieces = pieces
        self.uidx = uidx
        self.starts = np.asarray(pieces.starts, dtype=_intp)
        self.ends = np.asarray(pieces.ends, dtype=_intp)
        self.owner = np.asarray(pieces.owner, dtype=_intp)
        n = self.starts.shape[0]
        self.n_lines = n
        if not (self.ends.shape[0] == len(pieces.cx) == len(pieces.cy) == len(pieces.alpha)
                == len(pieces.usable) == n <= n_points == self.owner.shape[0] <= sw.k):
            # (no more pieces than points: the scratch rows hold one entry per reading)
            raise ValueError("pieces: one line per piece, one owner per point needed")
        for l in range(n):
            if not 0 <= self.starts[l] <= self.ends[l] < n_points:
                raise ValueError(f"piece {l} ({self.starts[l]} … {self.ends[l]}) is not "
                                 f"within the {n_points} points")
        for i in range(n_points):
            if not 0 <= self.owner[i] < n:
                raise ValueError(f"point {i}'s owner {self.owner[i]} is not a piece")
        # rows: cx, cy, alpha | the re-reading table (7) | per-line scratch (5)
        blk = _empty((15, n))
        self.cx, self.cy, self.alpha = blk[0], blk[1], blk[2]
        cdef double[:, ::1] bv = blk
        self._cx, self._cy, self._alpha = bv[0], bv[1], bv[2]
        self.t_a, self.t_cx, self.t_cy, self.t_dx = bv[3], bv[4], bv[5], bv[6]
        self.t_dy, self.t_lo, self.t_hi = bv[7], bv[8], bv[9]
        self.lscr = bv[10:15]
        self.p_obj, self.q_obj = blk[10], blk[11]
        cdef const double[:] src
        for l, v in enumerate((pieces.cx, pieces.cy, pieces.alpha)):
            src = np.asarray(v, dtype=float)
            for i in range(n):
                bv[l, i] = src[i]
        self.usable = np.array(pieces.usable, dtype=bool)
        self._usable = self.usable.view(_uint8)
        ints = _empty((4, n + 1), dtype=_intp)
        cdef Py_ssize_t[:, ::1] iv = ints
        self.t_use, self.t_col, self.first, self.last = iv[0], iv[1], iv[2], iv[3]
        if uidx is not None:
            self._uidx = uidx
        for l in range(n):
            self.first[l] = self.starts[l] if uidx is None else self._uidx[self.starts[l]]
            self.last[l] = self.ends[l] if uidx is None else self._uidx[self.ends[l]]
        self.label = _empty(sw.k, dtype=_intp)
        self._label = self.label
        for i in range(sw.k):
            self._label[i] = -1
        self.tab_ok = False

    cdef bint _any_usable(self):
        """Whether any line can give θ (re-reading needs one)."""
        cdef Py_ssize_t l
        for l in range(self.n_lines):
            if self._usable[l]:
                return True
        return False

    # ---- re-reading a reading with another line's θ

    cdef void _table(self):
        """The usable lines for re-reading (kept until the lines change): α, centroid,
        direction, extent along the line from its end readings ± adopt_margin_m, and the
        column of each line (−1: not usable)."""
        if self.tab_ok:
            return
        cdef Sweep sw = self.sw
        cdef Py_ssize_t l, f, g, j = 0
        cdef double a, cx, cy, dx, dy, t0, t1, m = sw.adopt_margin
        for l in range(self.n_lines + 1):
            self.t_col[l] = -1
        for l in range(self.n_lines):
            if not self._usable[l]:
                continue
            a, cx, cy = self._alpha[l], self._cx[l], self._cy[l]
            dx, dy = cos(a), sin(a)
            f, g = self.first[l], self.last[l]
            t0 = (sw._px[f] - cx) * dx + (sw._py[f] - cy) * dy
            t1 = (sw._px[g] - cx) * dx + (sw._py[g] - cy) * dy
            self.t_use[j], self.t_col[l] = l, j
            self.t_a[j], self.t_cx[j], self.t_cy[j], self.t_dx[j], self.t_dy[j] = a, cx, cy, dx, dy
            self.t_lo[j] = _min(t0, t1) - m
            self.t_hi[j] = _max(t0, t1) + m
            j += 1
        self.n_use = j
        self.tab_ok = True

    cdef double[::1] _reread(self, Py_ssize_t[::1] idx, Py_ssize_t[::1] cols):
        """Distances of readings ``idx`` re-read with the θ of usable line columns ``cols``
        (None: every usable line, (U, L) row-major); those θ (uncapped) go to ``sw.rr_th``.
        A line the beam meets past the rejection angle cannot take the reading: its
        distance is not needed (set to 1)."""
        cdef Sweep sw = self.sw
        cdef Py_ssize_t U = idx.shape[0], L = self.n_use if cols is None else 1
        cdef Py_ssize_t u, j, i, col
        cdef double hm, ls, t, la, b
        d_arr = sw.rr(U * L)
        cdef double[::1] d = d_arr, th = sw.rr_th
        for u in range(U):
            i = idx[u]
            hm, ls = sw.hm[i], sw.ls[i]
            for j in range(L):
                col = j if cols is None else cols[u]
                t = _incidence(hm, self.t_a[col])
                th[u * L + j] = t
                if t > sw.reject:
                    d[u * L + j] = 0.0
                    continue
                sw.look(_min(t, sw.cap), &la, &b)
                d[u * L + j] = la + b * ls
        _exp(d_arr, d_arr)
        return d

    cdef void _residuals(self, Py_ssize_t i, Py_ssize_t first, Py_ssize_t n,
                         const double* d, const double* th, Py_ssize_t own, double* r) noexcept:
        """|Perpendicular residual| of reading i re-read onto usable line columns
        ``first`` … ``first + n − 1`` (distances ``d``, θ ``th`` from :meth:`_reread`) into
        ``r``: inf unless it lands within adopt_margin_m of the line's extent (its ``own``
        column always counts) and the beam meets the line no steeper than the rejection
        angle."""
        cdef Sweep sw = self.sw
        cdef double ux = sw.ux[i], uy = sw.uy[i], ox = sw.ox[i], oy = sw.oy[i]
        cdef double reject = sw.reject, qx, qy, t, dx, dy
        cdef Py_ssize_t j, col
        for j in range(n):
            col = first + j
            dx, dy = self.t_dx[col], self.t_dy[col]
            qx = d[j] * ux + (ox - self.t_cx[col])
            qy = d[j] * uy + (oy - self.t_cy[col])
            t = qx * dx + qy * dy
            if th[j] > reject or (col != own and (t < self.t_lo[col] or t > self.t_hi[col])):
                r[j] = INF
            else:
                r[j] = fabs(qy * dx - qx * dy)

    # ---- membership

    cdef void members(self):
        """Each reading keeps its own usable line only if it sits on it (within the split
        threshold; the last readings past a corner often do not)."""
        cdef Sweep sw = self.sw
        cdef Py_ssize_t u, i, o
        cdef double r
        cdef bint all_points = self.uidx is None
        cdef double[::1] ca = self.lscr[2], sa = self.lscr[3]
        for o in range(self.n_lines):
            ca[o], sa[o] = cos(self._alpha[o]), sin(self._alpha[o])
        for i in range(sw.k):
            self._label[i] = -1
        for u in range(self.owner.shape[0]):
            o = self.owner[u]
            i = u if all_points else self._uidx[u]
            r = fabs((sw._py[i] - self._cy[o]) * ca[o] - (sw._px[i] - self._cx[o]) * sa[o])
            if r <= sw._thr[i] and self._usable[o]:
                self._label[i] = o

    cdef void settle_corners(self):
        """Readings at the ends of their run go to whichever line explains them best.

        Near a corner both walls' lines pass close to the first readings past it, and a
        reading read with the wrong wall's θ can land on that wall's extension (a
        self-consistent but wrong answer). Each reading within ``corner_window`` readings of
        either end of its run (same line, same sensor, consecutive in the scan) is re-read
        with every usable line's θ and put on the line it then lies closest to (within the
        split threshold; see :meth:`_resid`), if that is clearly better than its own
        (by ``corner_sigmas``·σ: noise alone must not shuffle readings between lines).
        """
        cdef Sweep sw = self.sw
        cdef Py_ssize_t k = sw.k, i, u, j, U = 0, start = 0, end, own, best, L
        if k == 0 or not self._any_usable():
            return
        cdef Py_ssize_t[::1] idx = sw.iscr[0], run_end = sw.iscr[1]
        cdef Py_ssize_t[::1] lab = self._label
        # runs: broken at a sensor change, a reading not live, or a change of line
        end = k - 1
        for i in range(k - 1, -1, -1):
            if i < k - 1 and (sw.run_brk[i + 1] or lab[i + 1] != lab[i]):
                end = i
            run_end[i] = end
        for i in range(k):
            if sw.run_brk[i] or (i > 0 and lab[i] != lab[i - 1]):
                start = i
            if lab[i] >= 0 and min(i - start, run_end[i] - i) < sw.corner_window:
                idx[U] = i
                U += 1
        if U == 0:
            return
        self._table()
        L = self.n_use
        cdef double[::1] d, th, row = sw.dscr[0]
        cdef Py_ssize_t u0, per = _max_n(REREAD_BLOCK // _max_n(L, 1), 1)
        for u0 in range(0, U, per):       # (re-read a block of readings at a time)
            d = self._reread(idx[u0:min(u0 + per, U)], None)
            th = sw.rr_th
            for u in range(min(per, U - u0)):
                i = idx[u0 + u]
                own = self.t_col[lab[i]]
                self._residuals(i, 0, L, &d[u * L], &th[u * L], own, &row[0])
                best = _argmin(&row[0], L)
                if (row[best] <= sw._thr[i]
                        and row[best] < row[own] - sw.corner_sigmas * sw._sigma[i]):
                    lab[i] = self.t_use[best]

    cdef void corner_sides(self):
        """A wall ends at its corner: readings on a line past a corner it makes with another
        line (past the intersection, away from the line's bulk) are not on it.

        Corners: two usable lines meeting at > 30°, adjacent pieces of a polyline or
        meeting within ``corner_reach_m`` (or ``corner_reach_share`` of the corner's distance
        from the ring) of both lines' members. Such a reading goes to the line across if,
        read with that line's θ, it lies on it (split threshold, within ``adopt_margin_m`` of
        its members' extent; at a far corner of the corner too, if that brings it closer by
        more than the split threshold) on its side of the corner; past a corner of adjacent
        pieces by itself, else with its run, if the run's range stays
        continuous with the readings beside it and one of them is on that line (see
        ``estimate_numpy._Grouping.corner_sides``, the statement this compiles).
        """
        cdef Sweep sw = self.sw
        cdef Py_ssize_t n, i, j, o, c, l, q, p, P = 0, k = sw.k, first, best
        cdef double den, ex, ey, s, t, v, X, Y, m = sw.adopt_margin, reach
        cdef double qx, qy, r, side, la, b, th, tx
        cdef bint adjacent
        cdef Py_ssize_t[:, ::1] pv
        cdef double[:, ::1] vv
        if self.n_lines < 2:
            return
        self._table()
        n = self.n_use
        if n < 2:
            return
        cdef Py_ssize_t[::1] lab = self._label
        # the extent of each usable line's members along it
        ext = _empty((2, n))
        cdef double[:, ::1] ev = ext
        cdef double[::1] lo = ev[0], hi = ev[1]
        for c in range(n):
            lo[c] = INF
            hi[c] = -INF
        for i in range(k):
            l = lab[i]
            if l < 0:
                continue
            c = self.t_col[l]
            if c < 0:
                continue
            v = (sw._px[i] - self.t_cx[c]) * self.t_dx[c] + (sw._py[i] - self.t_cy[c]) * self.t_dy[c]
            lo[c] = _min(lo[c], v)
            hi[c] = _max(hi[c], v)
        # each corner: its two lines (columns i < j) and whether they are adjacent pieces
        # (0/1), its intersection (X, Y) and the side of it each line's bulk is on (kept per
        # corner: lines may be thousands)
        cdef Py_ssize_t n_cor = 0, e
        cor_i = _empty((3, n + 1), dtype=_intp)
        cor_v = _empty((4, n + 1))
        cdef Py_ssize_t[:, ::1] ci = cor_i
        cdef double[:, ::1] cv = cor_v
        cdef double[::1] dx = self.t_dx, dy = self.t_dy, cx = self.t_cx, cy = self.t_cy
        for i in range(n):
            for j in range(i + 1, n):
                den = dx[i] * dy[j] - dy[i] * dx[j]
                if not fabs(den) > 0.5:
                    continue
                ex = cx[j] - cx[i]
                ey = cy[j] - cy[i]
                s = (ex * dy[j] - ey * dx[j]) / den
                t = (ex * dy[i] - ey * dx[i]) / den
                adjacent = (self.t_use[j] == self.t_use[i] + 1
                            and self.starts[self.t_use[j]] == self.ends[self.t_use[i]])
                X = cx[i] + s * dx[i]
                Y = cy[i] + s * dy[i]
                # a far corner's drop-out gap is wider: the reach grows with its distance
                reach = _max(sw.corner_reach, sw.corner_share * hypot(X - sw.cx0, Y - sw.cy0))
                if not (adjacent or (s >= lo[i] - reach and s <= hi[i] + reach
                                     and t >= lo[j] - reach and t <= hi[j] + reach)):
                    continue
                if n_cor == ci.shape[1]:       # (grown as needed: few corners a line)
                    cor_i = np.concatenate([cor_i, cor_i], axis=1)
                    cor_v = np.concatenate([cor_v, cor_v], axis=1)
                    ci, cv = cor_i, cor_v
                ci[0, n_cor], ci[1, n_cor], ci[2, n_cor] = i, j, adjacent
                cv[0, n_cor], cv[1, n_cor] = X, Y
                cv[2, n_cor], cv[3, n_cor] = _sign(-s), _sign(-t)
                n_cor += 1
        if n_cor == 0:
            return
        # each line's corners as directed entries (line c, partner o) in column order (the
        # pair loops visit only them): entry 2e is corner e from its first line, 2e + 1
        # from its second; a stable counting sort by line keeps partners in column order
        nbr_arr = np.zeros(n + 1, dtype=_intp)
        ent_arr = _empty(2 * n_cor, dtype=_intp)
        cdef Py_ssize_t[::1] nbr_at = nbr_arr, ent = ent_arr
        cdef Py_ssize_t t_o
        for e in range(n_cor):
            nbr_at[ci[0, e] + 1] += 1
            nbr_at[ci[1, e] + 1] += 1
        for c in range(n):
            nbr_at[c + 1] += nbr_at[c]
        fill_arr = nbr_arr[:n].copy()
        cdef Py_ssize_t[::1] fill = fill_arr
        for e in range(n_cor):
            ent[fill[ci[0, e]]] = 2 * e
            fill[ci[0, e]] += 1
            ent[fill[ci[1, e]]] = 2 * e + 1
            fill[ci[1, e]] += 1
        # (member, line across) pairs, the member beyond the corner: counted, then listed
        for q in range(2):
            if q == 1:
                if P == 0:
                    return
                pairs = _empty((4, P), dtype=_intp)
                vals = _empty((4, P))
                pv = pairs
                vv = vals
                P = 0
            for i in range(k):
                l = lab[i]
                if l < 0:
                    continue
                c = self.t_col[l]
                if c < 0:
                    continue
                for t_o in range(nbr_at[c], nbr_at[c + 1]):
                    e = ent[t_o] >> 1
                    o = ci[1 - (ent[t_o] & 1), e]        # the corner's other line
                    v = ((sw._px[i] - cv[0, e]) * dx[c] + (sw._py[i] - cv[1, e]) * dy[c]
                         ) * cv[2 + (ent[t_o] & 1), e]
                    if not v < 0:
                        continue
                    if q == 1:
                        pv[0, P], pv[1, P], pv[2, P], pv[3, P] = i, o, c, ent[t_o]
                        vv[3, P] = v
                    P += 1
        cdef Py_ssize_t[::1] pm = pv[0], po = pv[1], pc = pv[2], pe = pv[3]
        cdef double[::1] dd = vv[0], rr = vv[1]
        # read with the target's θ the reading must lie on the target line ...
        for p in range(P):
            i, o = pm[p], po[p]
            th = _incidence(sw.hm[i], self.t_a[o])
            vv[2, p] = th
            if th > sw.reject:
                dd[p] = 0.0
                continue
            sw.look(_min(th, sw.cap), &la, &b)
            dd[p] = la + b * sw.ls[i]
        _exp(vals[0], vals[0])
        cdef unsigned char[::1] left = np.zeros(P, dtype=_uint8)
        for p in range(P):
            i, o, c = pm[p], po[p], pc[p]
            if vv[2, p] > sw.reject:
                continue
            qx = dd[p] * sw.ux[i] + (sw.ox[i] - cx[o])
            qy = dd[p] * sw.uy[i] + (sw.oy[i] - cy[o])
            r = fabs(qy * dx[o] - qx * dy[o])
            t = qx * dx[o] + qy * dy[o]
            rr[p] = r
            # a far corner hides the wall's end in the drop-out gap: a reading its target
            # brings closer by more than the split threshold may lie on it up to the corner
            tx = lo[o]
            e = pe[p] >> 1
            if (sw.corner_share * hypot(cv[0, e] - sw.cx0, cv[1, e] - sw.cy0)
                    > sw.corner_reach and dd[p] < sw._d[i] - sw._thr[i]):
                tx = (cv[0, e] - cx[o]) * dx[o] + (cv[1, e] - cy[o]) * dy[o]
            if not (r <= sw._thr[i] and t >= _min(lo[o], tx) - m and t <= _max(hi[o], tx) + m):
                continue
            # ... and on the target's side of the corner
            side = ((sw.ox[i] + dd[p] * sw.ux[i] - cv[0, e]) * dx[o]
                    + (sw.oy[i] + dd[p] * sw.uy[i] - cv[1, e]) * dy[o])
            left[p] = side * cv[3 - (pe[p] & 1), e] >= 0     # the side of o's bulk
        # one target per reading (its pairs are consecutive): of those a neighbouring
        # reading of its sensor is on, the one it fits best (the first of equals); else
        # the one it fits best
        cdef unsigned char[::1] cand = sw.flag
        cdef Py_ssize_t[::1] tgt = sw.iscr[0], win = sw.iscr[1]
        cdef double[::1] d_new = sw.dscr[0], slope = sw.dscr[1]
        cdef Py_ssize_t W = 0, nb
        cdef bint seen, best_seen = False
        for i in range(k):
            cand[i] = 0
            d_new[i] = sw._d[i]      # the distances once every candidate moved
        first = 0
        while first < P:
            i = pm[first]
            q = first
            best = -1
            while q < P and pm[q] == i:
                if left[q]:
                    o = self.t_use[po[q]]
                    seen = ((not sw.run_brk[i] and lab[i - 1] == o)
                            or (i + 1 < k and not sw.run_brk[i + 1] and lab[i + 1] == o))
                    if best < 0 or (seen and not best_seen) or (
                            seen == best_seen and rr[q] < rr[best]):
                        best, best_seen = q, seen
                q += 1
            if best >= 0:
                cand[i] = 1
                tgt[i] = self.t_use[po[best]]
                d_new[i] = dd[best]
                win[W] = best
                W += 1
            first = q
        if W == 0:
            return
        tan_arr = _empty(W)
        cdef double[::1] tv = tan_arr
        for q in range(W):
            tv[q] = _min(vv[2, win[q]], sw.cap)
        _tan(tan_arr, tan_arr)
        for q in range(W):
            slope[pm[win[q]]] = tv[q]
        # next to the corner (within corner_past_m) and not clearly closer to the target
        # line than to its own (by corner_sigmas·σ): such a run moves only between readings
        # on the target line; past the corner of two pieces of one polyline (the trace is
        # continuous there, the target the piece beside it) a reading moves by itself
        cdef unsigned char[::1] near = np.zeros(k, dtype=_uint8)
        cdef Py_ssize_t[::1] moved = sw.iscr[2]    # the labels change once all are decided
        cdef Py_ssize_t oc
        cdef double r_own
        for i in range(k):
            moved[i] = -1
        for q in range(W):
            p = win[q]
            i, o, c = pm[p], po[p], pc[p]
            oc = self.t_col[lab[i]]
            r_own = fabs((sw._py[i] - cy[oc]) * dx[oc] - (sw._px[i] - cx[oc]) * dy[oc])
            near[i] = vv[3, p] >= -sw.corner_past and not (
                rr[p] < r_own - sw.corner_sigmas * sw._sigma[i])
            if ci[2, pe[p] >> 1]:       # adjacent pieces of one polyline
                moved[i] = tgt[i]
                cand[i] = 0
        # runs (consecutive readings of a sensor on one line with one target) move if their
        # range, once moved, is continuous with the readings either side of them and one of
        # those is on the target line
        cdef Py_ssize_t s0, e0
        cdef bint ok_run, on_prev, on_next, any_near
        i = 0
        while i < k:
            if not cand[i]:
                i += 1
                continue
            s0 = e0 = i
            while (e0 + 1 < k and cand[e0 + 1] and not sw.run_brk[e0 + 1]
                   and lab[e0 + 1] == lab[e0] and tgt[e0 + 1] == tgt[e0]):
                e0 += 1
            o = tgt[s0]
            ok_run = True
            on_prev = on_next = any_near = False
            if not sw.run_brk[s0]:
                ok_run = self._same_surface(d_new, s0, s0 - 1, slope[s0])
                on_prev = lab[s0 - 1] == o
            if e0 + 1 < k and not sw.run_brk[e0 + 1]:
                ok_run = ok_run and self._same_surface(d_new, e0, e0 + 1, slope[e0])
                on_next = lab[e0 + 1] == o
            for nb in range(s0, e0 + 1):
                any_near = any_near or near[nb]
            if ok_run and (on_prev or on_next) and (not any_near or (on_prev and on_next)):
                for nb in range(s0, e0 + 1):
                    moved[nb] = o
            i = e0 + 1
        for i in range(k):
            if moved[i] >= 0:
                lab[i] = moved[i]

    cdef bint _same_surface(self, const double[::1] d, Py_ssize_t i, Py_ssize_t j,
                            double slope) noexcept:
        """Whether readings i and j (neighbours of one sensor) at distances ``d`` lie on one
        surface: ranges apart by at most max(d)·sin(turn)·``slope`` (d·tanθ per radian the
        beam turns) + jump_sigmas·(σ_i ⊕ σ_j)."""
        cdef Sweep sw = self.sw
        cdef double di = d[i], dj = d[j], turn, allowed
        turn = fabs(sw.ux[i] * sw.uy[j] - sw.uy[i] * sw.ux[j])
        allowed = _max(di, dj) * turn * slope
        allowed = allowed + sw.jump_sigmas * hypot(sw._sigma[i], sw._sigma[j])
        return fabs(di - dj) <= allowed

    cdef void drop_steep(self):
        """A line the beam would meet past the drop-out angle cannot be what it saw.

        A reading whose line it meets steeper than the rejection angle leaves it. A line that
        most of its readings meet at or past the drop-out angle (less ``pinned_rad``) is not
        a surface: a radial streak (readings off a thin cylinder's edge, stretched along the
        beams by θ = 0) or a runaway (θ up → d down → the line turns radial → θ up, which a
        curve whose a(θ) falls with θ allows on a cylinder's face). A real wall that steep
        would return nothing. Such a line is dropped.
        """
        cdef Sweep sw = self.sw
        cdef Py_ssize_t i, l, n = self.n_lines, k = sw.k
        cdef Py_ssize_t[::1] lab = self._label
        cdef double hot = sw.cap - sw.pinned
        cdef bint any_pinned = False, any_streak = False
        cdef unsigned char[::1] good = sw.flag
        cdef double[::1] tl = sw.dscr[0]
        cdef Py_ssize_t[::1] n_pin, n_good
        for i in range(k):
            # tl only where good: a reading on no line has no angle to look up (and with
            # no lines at all there is no line 0 either)
            l = lab[i]
            good[i] = l >= 0 and self._usable[l] and (sw.all_usable or sw.usable[i])
            if good[i]:
                tl[i] = _incidence(sw.hm[i], self._alpha[l])
                if tl[i] >= hot:
                    any_pinned = True
        if any_pinned:
            n_pin, n_good = sw.iscr[0], sw.iscr[1]
            for l in range(n):
                n_pin[l] = n_good[l] = 0
            for i in range(k):
                if good[i]:
                    n_good[lab[i]] += 1
                    if tl[i] >= hot:
                        n_pin[lab[i]] += 1
            for l in range(n):
                if <double>n_pin[l] / <double>max(n_good[l], 1) > 0.5:   # a streak
                    self._usable[l] = 0
                    n_pin[l] = -1
                    any_streak = True
            if any_streak:
                self.tab_ok = False
                for i in range(k):
                    if good[i] and n_pin[lab[i]] < 0:
                        good[i] = 0
        for i in range(k):
            if not (good[i] and tl[i] <= sw.reject):
                lab[i] = -1

    cdef void adopt(self):
        """Readings on no usable line join one if, read with that line's θ, they land on it.

        These are mostly readings next to a corner, which θ = 0 put off both walls, and the
        last few readings of a sweep past a corner (the neighbouring sensor sees that wall).
        Every orphan is tried against every usable line: it joins the nearest (relative to
        its split threshold) within that threshold and near the line's extent.
        """
        cdef Sweep sw = self.sw
        cdef Py_ssize_t i, j, u, U = 0, L, best
        cdef Py_ssize_t[::1] lab = self._label, sel = sw.iscr[0]
        for i in range(sw.k):
            if lab[i] < 0 and (sw.all_usable or sw.usable[i]):
                sel[U] = i
                U += 1
        if U == 0 or not self._any_usable():
            return
        self._table()
        L = self.n_use
        cdef double[::1] d, th, row = sw.dscr[0]
        cdef Py_ssize_t u0, per = _max_n(REREAD_BLOCK // _max_n(L, 1), 1)
        for u0 in range(0, U, per):       # (re-read a block of readings at a time)
            d = self._reread(sel[u0:min(u0 + per, U)], None)
            th = sw.rr_th
            for u in range(min(per, U - u0)):
                i = sel[u0 + u]
                self._residuals(i, 0, L, &d[u * L], &th[u * L], -1, &row[0])
                for j in range(L):
                    row[j] = row[j] / sw._thr[i]
                best = _argmin(&row[0], L)
                if row[best] <= 1.0:
                    lab[i] = self.t_use[best]

    cdef void refit(self):
        """The same members, lines refitted at their moved positions (total least squares,
        the members in line order, sums about the sweep's centre); a line left with fewer
        than two members, or all of them at one point, keeps its fit but gives θ no more."""
        cdef Sweep sw = self.sw
        cdef Py_ssize_t i, l, n = self.n_lines, M = 0, s, c
        cdef Py_ssize_t[::1] lab = self._label, start = sw.iscr[0], fill = sw.iscr[1]
        cdef double x, y, a
        self.tab_ok = False
        # members grouped by line, in reading order within a line (a stable sort)
        for l in range(n + 1):
            start[l] = 0
        for i in range(sw.k):
            if lab[i] >= 0 and (sw.all_usable or sw.usable[i]):
                start[lab[i] + 1] += 1
                M += 1
        if M == 0:
            for l in range(n):
                self._usable[l] = 0
            return
        for l in range(n):
            start[l + 1] += start[l]
            fill[l] = start[l]
        cdef double[:, ::1] buf = sw.dscr[2:7]
        cdef Py_ssize_t row = buf.strides[0] // sizeof(double)
        for i in range(sw.k):
            if lab[i] >= 0 and (sw.all_usable or sw.usable[i]):
                s = fill[lab[i]]
                fill[lab[i]] += 1
                x = sw._px[i] - sw.cx0
                y = sw._py[i] - sw.cy0
                buf[0, s], buf[1, s], buf[2, s], buf[3, s], buf[4, s] = x, y, x * x, y * y, x * y
        cdef double[::1] p = self.lscr[0], q = self.lscr[1], spread = self.lscr[2]
        cdef double[::1] mxs = self.lscr[3], mys = self.lscr[4]
        for l in range(n):
            s, c = start[l], start[l + 1] - start[l]
            if c == 0:
                p[l] = q[l] = 0.0
                continue
            spread[l] = _tls(&buf[0, s], row, c, <double>c, &p[l], &q[l], &mxs[l], &mys[l])
        _arctan2(self.p_obj, self.q_obj, self.p_obj)
        for l in range(n):
            c = start[l + 1] - start[l]
            # a line needs two members with some spread (all coincident: no direction)
            if c >= 2 and spread[l] > 0:
                self._cx[l] = mxs[l] + sw.cx0
                self._cy[l] = mys[l] + sw.cy0
                a = p[l] * 0.5
                if a < 0:
                    a += PI
                self._alpha[l] = a
            else:
                self._usable[l] = 0

    def regroup(self, before):
        """The membership pass of a new grouping: :meth:`members`, :meth:`settle_corners`,
        :meth:`drop_steep`, :meth:`adopt`, then every line refitted to its members
        (:meth:`refit`), so θ comes from the members' own lines. Returns whether the labels
        differ from ``before`` (the previous grouping's; None: there was none)."""
        self.members()
        self.settle_corners()
        self.drop_steep()
        self.adopt()
        changed = before is None or not same(before, self.label)
        self.refit()
        return changed

    def check(self, bint corners=True):
        """The membership check at the readings' new places: the lines refitted where their
        members now are (:meth:`refit`), then :meth:`corner_sides` (if ``corners``),
        :meth:`drop_steep`, :meth:`adopt`; if that changed who belongs where, the lines are
        refitted to their new members. Returns whether it changed."""
        cdef Py_ssize_t i
        cdef Py_ssize_t[::1] snap = self.sw.snap
        cdef bint changed = False
        for i in range(self.sw.k):
            snap[i] = self._label[i]
        self.refit()
        if corners:
            self.corner_sides()
        self.drop_steep()
        self.adopt()
        for i in range(self.sw.k):
            if snap[i] != self._label[i]:
                changed = True
                break
        if changed:
            self.refit()
        return changed

    def plain_step(self, double[::1] theta, Py_ssize_t[::1] last_moving,
                   unsigned char[::1] on_line, Py_ssize_t it, double tolerance_rad):
        """θ ← θ_new (Table II's step from the grouping): each reading's θ from its line,
        capped at the drop-out angle, 0 off any line; records who moved by ≥ the tolerance
        (``last_moving`` ← ``it``) and who is on a line. Returns whether any moved."""
        cdef Sweep sw = self.sw
        cdef Py_ssize_t i, l
        cdef double t
        cdef bint moving = False
        _per_reading(min(theta.shape[0], last_moving.shape[0], on_line.shape[0]), sw.k,
                     "theta, last_moving or on_line")
        for i in range(sw.k):
            l = self._label[i]
            t = _min(_incidence(sw.hm[i], self._alpha[l]), sw.cap) if l >= 0 else 0.0
            if fabs(t - theta[i]) >= tolerance_rad:
                last_moving[i] = it
                moving = True
            theta[i] = t
            on_line[i] = l >= 0
        return moving


# --------------------------------------------------------------------------- held iterations


@cython.final
cdef class Held:
    """The iteration with held membership, in line order: each line's members' θ follow from
    one direction angle a (θ_i = |π/2 − |h_i − a||), so a step is: points at θ(a) → TLS
    angle G(a) of every line at once (sums over the members in line order) → new a. With
    ``secant`` the step is a safeguarded secant step on G(a) − a per line, its gain at most
    ``max_gain`` (see :meth:`_advance`). A line with a single member keeps its angle.

    ``perm``: the members (live indices) in line order; ``theta``: their current θ.
    """

    cdef Sweep sw
    cdef readonly Py_ssize_t km, n_lines
    # per member (km, in line order): its live index, its line's slot; hm, ls, ox, oy, ux,
    # uy copied from the sweep (origins about its centre); θ, the step θ_new − θ, its line's
    # θ uncapped (tl); e: Eq. 10's exponent log d at θ, which _fit turns into d in place
    cdef Py_ssize_t[::1] perm, slot
    cdef double[::1] hm, ls, ox, oy, ux, uy, theta, step, tl, e
    # per line with members (n_lines): first member, count (a double: it divides the
    # sums), whether it has one member only, a and G(a) now and before, arctan2's p and q
    cdef Py_ssize_t[::1] lstart
    cdef double[::1] n, a, a_prev, g_prev, g, p, q
    cdef unsigned char[::1] lone
    cdef double[:, ::1] buf         # _fit's moments (x, y, x², y², xy) per member
    cdef object e_obj, p_obj, q_obj, g_obj   # arrays under e, p, q, g for numpy's exp/arctan2
    cdef bint secant, has_prev, any_hot, any_reject, moving
    cdef double max_gain, biggest

    def __init__(self, Sweep sw, Grouping grouping, const double[::1] theta, bint secant,
                 double max_gain):
        """The grouping's members (readings with a label) sorted by line, stably (a counting
        sort: reading order within a line, as the sums need), with what the iterations read
        per member copied next to each other; lines without members get no slot. Each
        line's a starts at the grouping's α, each member at its θ (live readings)."""
        cdef Py_ssize_t i, l, s, km = 0, nl = 0, n_all = grouping.n_lines
        cdef double la, b
        _per_reading(theta.shape[0], sw.k, "theta")
        if grouping.sw is not sw:
            raise ValueError("the grouping is of another sweep")
        cdef Py_ssize_t[::1] lab = grouping._label, start = sw.iscr[0], slot_of = sw.iscr[1]
        for l in range(n_all + 1):
            start[l] = 0
        for i in range(sw.k):
            if lab[i] >= 0:
                start[lab[i] + 1] += 1
                km += 1
        for l in range(n_all):
            if start[l + 1]:
                nl += 1
            start[l + 1] += start[l]
        self.sw = sw
        self.km, self.n_lines = km, nl
        self.secant = secant
        self.max_gain = max_gain
        self.has_prev = False
        ints = _empty((2, km), dtype=_intp)
        cdef Py_ssize_t[:, ::1] iv = ints
        self.perm, self.slot = iv[0], iv[1]
        self.lstart = _empty(nl, dtype=_intp)
        self.lone = _empty(nl, dtype=_uint8)
        per_line = _empty((7, nl))
        cdef double[:, ::1] lv = per_line
        self.n, self.a, self.a_prev, self.g_prev = lv[0], lv[1], lv[2], lv[3]
        self.p, self.q, self.g = lv[4], lv[5], lv[6]
        self.p_obj, self.q_obj, self.g_obj = per_line[4], per_line[5], per_line[6]
        per_member = _empty((15, km))
        cdef double[:, ::1] mv = per_member
        self.hm, self.ls, self.ox, self.oy, self.ux = mv[0], mv[1], mv[2], mv[3], mv[4]
        self.uy, self.theta, self.step, self.tl, self.e = mv[5], mv[6], mv[7], mv[8], mv[9]
        self.buf = mv[10:15]
        self.e_obj = per_member[9]
        s = 0
        for l in range(n_all):
            if start[l + 1] > start[l]:
                slot_of[l] = s
                self.lstart[s] = start[l]
                self.n[s] = <double>(start[l + 1] - start[l])
                self.lone[s] = start[l + 1] - start[l] < 2
                self.a[s] = grouping._alpha[l]
                s += 1
        for i in range(sw.k):
            l = lab[i]
            if l < 0:
                continue
            s = start[l]
            start[l] += 1
            self.perm[s] = i
            self.slot[s] = slot_of[l]
            self.hm[s], self.ls[s] = sw.hm[i], sw.ls[i]
            self.ox[s], self.oy[s] = sw.ox[i] - sw.cx0, sw.oy[i] - sw.cy0
            self.ux[s], self.uy[s] = sw.ux[i], sw.uy[i]
            self.theta[s] = theta[i]
            sw.look(theta[i], &la, &b)
            self.e[s] = la + b * sw.ls[i]

    def put_theta(self, double[::1] theta):
        """The members' current θ into the sweep's θ (live readings)."""
        cdef Py_ssize_t i
        _per_reading(theta.shape[0], self.sw.k, "theta")
        for i in range(self.km):
            theta[self.perm[i]] = self.theta[i]

    cdef void _fit(self, double tolerance_rad):
        """Fit every line to its members' points at the current θ (``e`` holds the exponent
        of Eq. 10 there): the lines' angles G(a) (``g``), the θ of each member's line
        uncapped (``tl``) and its step θ_new − θ; flags whether any member is hot (within
        ``pinned_rad`` of the drop-out angle) or past the rejection angle, whether any step
        is ≥ ``tolerance_rad`` and the largest |step|."""
        cdef Sweep sw = self.sw
        cdef Py_ssize_t i, l, row = self.buf.strides[0] // sizeof(double)
        cdef double x, y, mx, my, ga, tl, step
        cdef double hot = sw.cap - sw.pinned
        _exp(self.e_obj, self.e_obj)
        for i in range(self.km):
            x = self.e[i] * self.ux[i] + self.ox[i]
            y = self.e[i] * self.uy[i] + self.oy[i]
            self.buf[0, i], self.buf[1, i] = x, y
            self.buf[2, i], self.buf[3, i], self.buf[4, i] = x * x, y * y, x * y
        for l in range(self.n_lines):
            _tls(&self.buf[0, self.lstart[l]], row, <Py_ssize_t>self.n[l], self.n[l],
                 &self.p[l], &self.q[l], &mx, &my)
        _arctan2(self.p_obj, self.q_obj, self.g_obj)
        for l in range(self.n_lines):
            ga = self.g[l] * 0.5
            if ga < 0.0:
                ga += PI
            if self.lone[l]:
                ga = self.a[l]
            self.g[l] = ga
        self.any_hot = self.any_reject = self.moving = False
        self.biggest = 0.0
        for i in range(self.km):
            tl = _incidence(self.hm[i], self.g[self.slot[i]])
            self.tl[i] = tl
            step = _min(tl, sw.cap) - self.theta[i]
            self.step[i] = step
            if tl >= hot:
                self.any_hot = True
                if tl > sw.reject:
                    self.any_reject = True
            if fabs(step) >= tolerance_rad:
                self.moving = True
            self.biggest = _max(fabs(step), self.biggest)

    cdef bint _most_hot(self):
        """Whether most of a line's members sit at the drop-out angle (a streak or runaway,
        see Grouping.drop_steep)."""
        cdef Sweep sw = self.sw
        cdef Py_ssize_t i, l
        cdef double hot = sw.cap - sw.pinned
        cdef Py_ssize_t[::1] n_hot = sw.iscr[0]
        for l in range(self.n_lines):
            n_hot[l] = 0
        for i in range(self.km):
            if self.tl[i] >= hot:
                n_hot[self.slot[i]] += 1
        for l in range(self.n_lines):
            if n_hot[l] > 0.5 * self.n[l]:
                return True
        return False

    cdef void _advance(self, Py_ssize_t it, Py_ssize_t[::1] last_moving,
                       double tolerance_rad):
        """Members that moved get ``last_moving`` ← ``it``; then the next a: the plain step
        a ← G(a), or (``secant``) a secant step towards the root of g(a) = G(a) − a from
        this and the previous iteration, its gain held to [1/64, max_gain]: below 1 it damps
        an oscillation (G' < 0), above 1 it speeds up a slow contraction (0 < G' < 1); where
        G' ≥ 1 (a runaway) the step stays plain. Angles are compared mod π. The members' θ
        follow (capped at the drop-out angle), and the exponent of Eq. 10 at them."""
        cdef Sweep sw = self.sw
        cdef Py_ssize_t i, l
        cdef double g, a, da, dg, gain, t, la, b
        for l in range(self.n_lines):
            a = self.a[l]
            g = self.g[l] - a
            g -= PI * rint(g * INV_PI)
            gain = 1.0
            if self.secant and self.has_prev:
                da = a - self.a_prev[l]
                da -= PI * rint(da * INV_PI)
                dg = self.g_prev[l] - g
                # gain −1/slope with slope = (g − g_prev)/da: only where the slope is negative
                if dg * da > 0.0:
                    gain = _min(_max(da / dg, 1.0 / 64.0), self.max_gain)
                self.a_prev[l], self.g_prev[l] = a, g
                a = a + gain * g
            else:
                self.a_prev[l], self.g_prev[l] = a, g
                a = a + g
            a -= PI * floor(a * INV_PI)
            self.a[l] = a
        self.has_prev = True
        for i in range(self.km):
            if fabs(self.step[i]) >= tolerance_rad:
                last_moving[self.perm[i]] = it
            t = _min(_incidence(self.hm[i], self.a[self.slot[i]]), sw.cap)
            self.theta[i] = t
            sw.look(t, &la, &b)
            self.e[i] = la + b * self.ls[i]

    def run(self, Py_ssize_t it, Py_ssize_t limit, double tolerance_rad, bint checked,
            Py_ssize_t[::1] last_moving, Py_ssize_t regroup_before, double regroup_until_rad,
            bint one_step=False):
        """Held iterations from iteration ``it`` until one of (status, it, settled, checked):

        - CHECK: a member meets its line past the rejection angle, or most of a line's
          members sit at the drop-out angle (not tested in a ``checked`` first iteration,
          which a membership check has just passed); this iteration is not taken;
        - SETTLED: no member's θ moved by ``tolerance_rad``;
        - REGROUP: θ has settled coarsely (every step < ``regroup_until_rad``) at an
          iteration before ``regroup_before``;
        - STEPPED: one iteration taken (``one_step``);
        - LIMIT: ``it`` reached ``limit``.

        Members that moved get ``last_moving`` ← their iteration. ``settled``: whether the
        last iteration taken settled (None if none was taken); ``checked``: whether that
        iteration was the checked one.
        """
        cdef bint was_checked = checked
        _per_reading(last_moving.shape[0], self.sw.k, "last_moving")
        settled = None
        while it < limit:
            self._fit(tolerance_rad)
            if not checked and self.any_hot and (self.any_reject or self._most_hot()):
                return CHECK, it, settled, was_checked
            self._advance(it, last_moving, tolerance_rad)
            it += 1
            was_checked = checked
            checked = False
            settled = not self.moving
            if not self.moving:
                return SETTLED, it, settled, was_checked
            if it < regroup_before and self.biggest < regroup_until_rad:
                return REGROUP, it, settled, was_checked
            if one_step:
                return STEPPED, it, settled, was_checked
        return LIMIT, it, settled, was_checked
