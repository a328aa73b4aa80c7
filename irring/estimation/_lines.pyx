# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Line segmentation of the estimator (step 4 of Table II) in one compiled call.

:func:`segment` does all of it over ordered end points: polylines → iterative end-point fit
(split) → merge of collinear neighbours → corner refinement → each piece's TLS line, who
owns the corners, which lines are usable. ``irring.estimation.lines.segment`` wraps it into
``Pieces``; the algorithm is explained there and next to each phase below.

Same answers as the numpy code it replaced, bit for bit: the same operations in the same
order (prefix sums accumulate sequentially, residuals and moments are formed term by term
as numpy did, no fused multiply-add), the same tie-breaking (first farthest reading, first
cheapest corner, numpy's NaN rules for max/argmin), and the line angles from numpy's own
``arctan2`` (batched, one call per merge round and one for the final lines): on x86-64 with
AVX-512 numpy's float64 arctan2 is SIMD code that differs from libm's by 1 ulp on ~8 % of
inputs, while sin, cos, hypot and sqrt agree with libm.

Speed, measured on the 2-core dev machine (shared, so figures spread with load): on
t_room pose 0 the segmentation (``_segment``, ~2 calls per sweep) took 0.77–0.85 ms per
sweep with numpy and takes 0.044–0.064 ms with this kernel (median per sweep over 600
estimates, ~17×); ``irring bench speed`` shows the estimator stage at 3.15 → 2.5–2.6 ms
median. A call is ~4 µs of fixed cost (its ~12 output arrays, 1–4 numpy arctan2 calls)
plus ~5–10 µs of work on ~630 points.
"""

from cpython.buffer cimport (PyObject_GetBuffer, PyBuffer_Release, PyBUF_C_CONTIGUOUS,
                            PyBUF_FORMAT, PyBUF_WRITABLE)
from libc.math cimport (sin, cos, sqrt, fabs, hypot, isfinite, exp, log, atan, nearbyint, M_PI,
                        INFINITY, NAN, asin, tan, fmin, fmax, atan2)
from libc.stdlib cimport calloc, free, malloc

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

_arctan2 = np.arctan2      # numpy's, for the same angles to the last bit (see above)

cdef extern from *:
    """
    /* round like numpy: never fuse a*b + c into one fused multiply-add */
    #if defined(__clang__)
    #pragma STDC FP_CONTRACT OFF
    #elif defined(__GNUC__)
    #pragma GCC optimize ("fp-contract=off")
    #endif
    """

ctypedef Py_ssize_t idx_t

cdef enum:
    WINDOW = 5      # corner refinement: readings tried either side of a corner
    NM = 5          # moments per point: x, y, x², y², xy (centred)


cdef inline void _moments2(double n, const double* lo, const double* hi,
                           double* t, double* d, double* c) noexcept nogil:
    """Of the range whose moment sums are hi − lo, over n points: t = cxx + cyy,
    d = cxx − cyy, c = 2·cxy of its (n-scaled) scatter; the TLS residual sum (doubled) is
    t − hypot(d, c)."""
    cdef double sx = hi[0] - lo[0], sy = hi[1] - lo[1]
    cdef double sxx = hi[2] - lo[2], syy = hi[3] - lo[3], sxy = hi[4] - lo[4]
    cdef double inv = 1.0 / n
    cdef double cxx = sxx - sx * sx * inv
    cdef double cyy = syy - sy * sy * inv
    cdef double cxy = sxy - sx * sy * inv
    t[0] = cxx + cyy
    d[0] = cxx - cyy
    c[0] = cxy + cxy


cdef inline double _rss(double n, const double* lo, const double* hi) noexcept nogil:
    """Summed squared perpendicular residuals (doubled) of the TLS line of a range whose
    moment sums are hi − lo, over n points; only their order matters."""
    cdef double t, d, c
    _moments2(n, lo, hi, &t, &d, &c)
    return t - hypot(d, c)


cdef inline idx_t _shared_corners(const idx_t* S, const idx_t* E, idx_t P,
                                  idx_t* cand) noexcept nogil:
    """The pieces j < P − 1 whose end is the next one's start (the corner the two share: the
    places a merge or a corner move can happen) into ``cand``, in order; returns how many."""
    cdef idx_t j, m = 0
    for j in range(P - 1):
        if S[j + 1] == E[j]:
            cand[m] = j
            m += 1
    return m


# ---------------------------------------------------------------------------- split


cdef idx_t _farthest(const double* px, const double* py, const double* inv_thr,
                     idx_t s, idx_t e) noexcept nogil:
    """The reading of piece [s, e] farthest from its chord (in thresholds), the first of
    equals, if it lies more than one threshold off; else −1. A piece whose ends meet
    (chord < 1e-12) measures from its end point instead."""
    if e - s < 2:
        return -1
    cdef double ax = px[s], ay = py[s]
    cdef double dx = px[e] - ax, dy = py[e] - ay
    cdef double chord = hypot(dx, dy), c0, d, m = 0.0
    cdef idx_t i, at = -1
    cdef int nan = 0
    if chord < 1e-12:
        for i in range(s + 1, e):
            d = hypot(px[i] - ax, py[i] - ay) * inv_thr[i]
            if d > m:
                m = d
                at = i
            nan |= d != d
    else:
        dx = dx / chord
        dy = dy / chord
        c0 = dx * ay - dy * ax
        for i in range(s + 1, e):
            d = fabs(dx * py[i] - dy * px[i] - c0) * inv_thr[i]
            if d > m:
                m = d
                at = i
            nan |= d != d
    if nan or not (m > 1.0):
        return -1
    return at


cdef idx_t _split(const double* px, const double* py, const double* inv_thr,
                  const unsigned char* brk, idx_t k, idx_t* S, idx_t* E,
                  idx_t* stack) noexcept nogil:
    """Iterative end-point fit of every polyline: a piece splits at the reading farthest from
    its chord while that lies more than the threshold off; the two pieces share that reading
    (their corner). Depth first, left piece first, so the pieces come out in order. Returns
    their number."""
    cdef idx_t n = 0, f = 0, l, top, s, e, at
    while f < k:
        l = f
        while l + 1 < k and not brk[l + 1]:
            l += 1
        stack[0] = f
        stack[1] = l
        top = 2
        while top:
            top -= 2
            s = stack[top]
            e = stack[top + 1]
            at = _farthest(px, py, inv_thr, s, e)
            if at < 0:
                S[n] = s
                E[n] = e
                n += 1
            else:
                stack[top] = at
                stack[top + 1] = e
                stack[top + 2] = s
                stack[top + 3] = at
                top += 4
        f = l + 1
    return n


# ---------------------------------------------------------------------------- merge


cdef idx_t _merge(const double* px, const double* py, const double* inv_thr, idx_t k,
                  const double* cum, double cx, double cy, idx_t* S, idx_t* E, idx_t P,
                  idx_t* cand, idx_t* qj, unsigned char* flag, double* W, double* cost,
                  double* qmx, double* qmy, double* q, r0, r1, r2) except -1:
    """Merge adjacent pieces (sharing a corner) whose joint TLS line fits every reading
    within its threshold; cheapest joins first, non-overlapping joins per round.

    A join's worst residual covers the readings of both pieces (each corner reading counted
    with the piece it starts); it depends only on the two pieces and the next one's start,
    so it is kept (W) until a join next to it changes them. The joint lines' angles come
    from one numpy arctan2 per round over the buffer q (rows 2·sxy, dif, angle, each of
    length P; r0, r1, r2 are those rows as numpy arrays). Returns the number of pieces."""
    cdef idx_t rounds = P, P0 = P, rnd, m, i, j, nq, lo, hi, end, p, n_new
    cdef double n, t0, t1, t2, t3, t4, mx, my, sxy, alpha, nx, ny, c0, w, r
    cdef const double* a
    cdef const double* b
    cdef bint any_ok
    cdef int nan
    for p in range(P):
        flag[p] = 0                        # bit 0 (1): W[p] is known; bit 2 (4): p joins p + 1
    for rnd in range(rounds):
        m = _shared_corners(S, E, P, cand)
        if m == 0:
            break
        # the joint lines not known yet: moments, then their angles in one arctan2
        nq = 0
        for i in range(m):
            j = cand[i]
            if flag[j] & 1:
                continue
            lo, hi = S[j], E[j + 1]
            n = <double>(hi - lo) + 1.0
            a = cum + lo * NM
            b = cum + (hi + 1) * NM
            t0 = b[0] - a[0]
            t1 = b[1] - a[1]
            t2 = b[2] - a[2]
            t3 = b[3] - a[3]
            t4 = b[4] - a[4]
            mx = t0 / n
            my = t1 / n
            sxy = t4 - t0 * my
            q[nq] = sxy + sxy
            q[P0 + nq] = (t2 - t0 * mx) - (t3 - t1 * my)
            qmx[nq] = mx
            qmy[nq] = my
            qj[nq] = j
            nq += 1
        if nq:
            _arctan2(r0, r1, r2)
        for i in range(nq):
            j = qj[i]
            alpha = q[2 * P0 + i] * 0.5
            nx = -sin(alpha)
            ny = cos(alpha)
            c0 = nx * (qmx[i] + cx) + ny * (qmy[i] + cy)
            end = S[j + 2] if j + 2 < P else k
            # the largest residual; NaN if any is NaN (numpy's maximum)
            w = 0.0
            nan = 0
            for p in range(S[j], end):
                r = fabs(nx * px[p] + ny * py[p] - c0) * inv_thr[p]
                if r > w:
                    w = r
                nan |= r != r
            if nan:
                w = NAN
            W[j] = w
            flag[j] |= 1
        any_ok = False
        for i in range(m):
            w = W[cand[i]]
            if w <= 1.0:
                cost[i] = w
                any_ok = True
            else:
                cost[i] = INFINITY
        if not any_ok:
            break
        # a join is taken if no overlapping join is cheaper (the earlier of equals wins)
        for i in range(m):
            j = cand[i]
            if not (W[j] <= 1.0):
                continue
            if i > 0 and cand[i - 1] + 1 == j and cost[i - 1] <= cost[i]:
                continue
            if i + 1 < m and cand[i + 1] == j + 1 and cost[i + 1] < cost[i]:
                continue
            flag[j] |= 4
        n_new = 0
        p = 0
        while p < P:
            S[n_new] = S[p]
            W[n_new] = W[p]
            if flag[p] & 4:                # p takes p + 1: its joins either side change
                E[n_new] = E[p + 1]
                flag[n_new] = 0
                if n_new:
                    flag[n_new - 1] &= ~1
                p += 2
            else:
                E[n_new] = E[p]
                flag[n_new] = flag[p] & 1
                p += 1
            n_new += 1
        P = n_new
    return P


# ---------------------------------------------------------------------------- corners


cdef enum:
    NCAND = 2 * WINDOW + 1


cdef inline bint _squares_safe(double d, double c) noexcept nogil:
    """Whether sqrt(d² + c²) is within a few ulp of hypot(d, c): both 0, or the larger
    square a normal number that does not overflow (the smaller one's underflow is then
    negligible)."""
    cdef double a = fabs(d) + fabs(c)
    return (d == 0.0 and c == 0.0) or 1e-140 < a < 1e140


cdef idx_t _best_place(const double* cum, idx_t lo, idx_t v, idx_t hi) noexcept nogil:
    """The place c in v ± 5 (lo < c < hi) where the residuals of the pieces [lo, c] and
    [c, hi] about their TLS lines sum least: numpy's argmin over the 11 places (the first
    least; a NaN wins; places off the pieces cost inf, and the argmin landing on one
    keeps v).

    Same answer, fewer hypot calls: each cost is t_L − hypot(d_L, c_L) + t_R − hypot(..),
    and with sqrt(d² + c²) (within ~2.3 ulp of hypot unless it under/overflows) instead
    it is off by less than 8·ε·(|t_L| + h_L + |t_R| + h_R). Only places whose cost can
    still be the least within those bounds get their exact cost; the others are strictly
    dearer than one of them. Anything non-finite, or d, c outside 1e-140 … 1e140 (see
    _squares_safe), takes the exact way for all 11."""
    cdef double tl[NCAND]
    cdef double dl[NCAND]
    cdef double cl[NCAND]
    cdef double tr[NCAND]
    cdef double dr[NCAND]
    cdef double cr[NCAND]
    cdef double ap[NCAND]
    cdef double bd[NCAND]
    cdef double hl, hr, up = INFINITY, cst, mp = 0.0
    cdef idx_t w, c, bi = v
    cdef bint safe = True, first = True
    for w in range(NCAND):
        c = v + w - WINDOW
        if c <= lo or c >= hi:
            continue
        # left piece [lo, c], right piece [c, hi]
        _moments2(<double>(c - lo + 1), cum + lo * NM, cum + (c + 1) * NM,
                  &tl[w], &dl[w], &cl[w])
        _moments2(<double>(hi - c + 1), cum + c * NM, cum + (hi + 1) * NM,
                  &tr[w], &dr[w], &cr[w])
        if not (_squares_safe(dl[w], cl[w]) and _squares_safe(dr[w], cr[w])):
            safe = False
            break
        hl = sqrt(dl[w] * dl[w] + cl[w] * cl[w])
        hr = sqrt(dr[w] * dr[w] + cr[w] * cr[w])
        ap[w] = (tl[w] - hl) + (tr[w] - hr)
        bd[w] = 8.0 * 2.220446049250313e-16 * (fabs(tl[w]) + hl + fabs(tr[w]) + hr)
        if not (isfinite(ap[w]) and isfinite(bd[w])):
            safe = False
            break
        if ap[w] + bd[w] < up:
            up = ap[w] + bd[w]
    if safe:
        for w in range(NCAND):
            c = v + w - WINDOW
            if c <= lo or c >= hi or ap[w] - bd[w] > up:
                continue
            cst = (tl[w] - hypot(dl[w], cl[w])) + (tr[w] - hypot(dr[w], cr[w]))
            if first or cst < mp:
                mp = cst
                bi = c
                first = False
        return bi
    # the exact way: numpy's argmin over all 11 costs
    for w in range(NCAND):
        c = v + w - WINDOW
        if c <= lo or c >= hi:
            cst = INFINITY
        else:
            cst = _rss(<double>(c - lo + 1), cum + lo * NM, cum + (c + 1) * NM)
            cst = cst + _rss(<double>(hi - c + 1), cum + c * NM, cum + (hi + 1) * NM)
        if w == 0 or not (cst >= mp):
            mp = cst
            bi = v if (c <= lo or c >= hi) else c
            if mp != mp:
                break
    return bi


cdef void _refine_corners(const double* cum, idx_t* S, idx_t* E, idx_t P, int rounds,
                          idx_t* cand, idx_t* best, idx_t* S2, idx_t* E2,
                          idx_t* seen) noexcept nogil:
    """Move each corner shared by two pieces to where the two TLS lines fit best.

    The end-point fit splits at the reading farthest from the chord, which for a corner near
    the end of a polyline, or seen at a slant, is a few readings off the true corner. Each
    shared corner is tried at up to 5 readings either side (keeping ≥ 2 readings per piece)
    and put where the summed squared perpendicular residuals of the two pieces are least
    (see _best_place); all corners at once, from prefix sums. Two corners moving towards
    each other must leave ≥ 2 readings between them, else both stay. A corner whose pieces
    did not change since the last round has the same costs, so its place is taken from
    then (``seen``: lo, v, hi, place per corner)."""
    cdef int rnd
    cdef idx_t m, i, j, lo, v, hi, p, bi
    cdef bint moved, short_any
    cdef idx_t* sn
    for rnd in range(rounds):
        m = _shared_corners(S, E, P, cand)
        if m == 0:
            break
        moved = False
        for i in range(m):
            j = cand[i]
            lo, v, hi = S[j], E[j], E[j + 1]
            sn = seen + 4 * i
            if rnd and sn[0] == lo and sn[1] == v and sn[2] == hi:
                bi = sn[3]
            else:
                bi = _best_place(cum, lo, v, hi)
                sn[0], sn[1], sn[2], sn[3] = lo, v, hi, bi
            best[i] = bi
            if bi != v:
                moved = True
        if not moved:
            break
        for p in range(P):
            S2[p] = S[p]
            E2[p] = E[p]
        for i in range(m):
            j = cand[i]
            E2[j] = best[i]
            S2[j + 1] = best[i]
        short_any = False
        for p in range(P):
            if E2[p] - S2[p] < 1 and E[p] - S[p] >= 1:
                short_any = True
                break
        if short_any:
            for i in range(m):
                j = cand[i]
                if ((E2[j] - S2[j] < 1 and E[j] - S[j] >= 1)
                        or (E2[j + 1] - S2[j + 1] < 1 and E[j + 1] - S[j + 1] >= 1)):
                    best[i] = E[j]
            for i in range(m):
                j = cand[i]
                E2[j] = best[i]
                S2[j + 1] = best[i]
        for p in range(P):
            S[p] = S2[p]
            E[p] = E2[p]


# ---------------------------------------------------------------------------- entry point


cdef void* _data(obj, Py_buffer* views, int* held, Py_ssize_t n, Py_ssize_t itemsize,
                 const char* codes, bint writable) except NULL:
    """Data of a C-contiguous array of n items (one of the format ``codes``), through the
    plain buffer protocol: a typed memoryview would cost ~0.3 µs per new array here. The
    buffer goes to views[held[0]] and held[0] counts it only once it is acquired and checked,
    so the caller releases views[:held[0]] on every path, an error's included."""
    cdef Py_buffer* view = views + held[0]
    PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT
                       | (PyBUF_WRITABLE if writable else 0))
    cdef const char* f = view.format
    cdef const char* c = codes
    if f[0] in b"@=<":
        f += 1
    while c[0] and not (f[0] == c[0] and f[1] == 0):
        c += 1
    if view.itemsize != itemsize or not c[0] or view.len != n * itemsize:
        PyBuffer_Release(view)
        raise TypeError(f"expected {n} contiguous items of format {codes.decode()!r} "
                        f"and size {itemsize}, got {obj!r:.60}")
    held[0] += 1
    if view.buf == NULL:                     # an empty array: any non-null pointer will do
        return <void*> view
    return view.buf


cdef bint _tiles(const idx_t* S, const idx_t* E, idx_t P, idx_t k) noexcept nogil:
    """Whether the pieces [S[p], E[p]] tile readings 0 … k − 1 as every result's do: in
    order from the first reading to the last, each starting on the reading after its
    predecessor or on its end (their shared corner; the predecessor then has ≥ 2 readings).
    Reused pieces must: the rest indexes by them unchecked (each reading's owner, P ≤ k)."""
    cdef idx_t p
    if P == 0:
        return k == 0
    if S[0] != 0 or E[P - 1] != k - 1:
        return False
    for p in range(P):
        if E[p] < S[p]:
            return False
        if p and not (S[p] == E[p - 1] + 1 or (S[p] == E[p - 1] and E[p - 1] > S[p - 1])):
            return False
    return True


cdef idx_t _keep_unchanged(const unsigned char* brk, const unsigned char* pb, idx_t k,
                           const idx_t* ps, const idx_t* pe, idx_t nprev, idx_t* S, idx_t* E,
                           idx_t P, idx_t* S2, idx_t* E2) noexcept nogil:
    """Pieces (into S, E; returns their count): the earlier result's (ps, pe) in every
    polyline of ``brk`` that it had too (same first and last reading, by ``pb``), the fresh
    ones (S, E, P) in the others; both in order. (estimate_numpy._keep_unchanged)"""
    cdef idx_t a = 0, b, i, p = 0, q = 0, n = 0
    cdef bint same
    while a < k:
        b = a + 1
        while b < k and not brk[b]:
            b += 1
        # [a, b) is a polyline; the same one before if it started at a and ended at b − 1
        same = pb[a] != 0 and (b == k or pb[b] != 0)
        i = a + 1
        while same and i < b:
            if pb[i]:
                same = False
            i += 1
        if same:
            while p < nprev and ps[p] < a:
                p += 1
            while p < nprev and ps[p] < b:
                S2[n] = ps[p]
                E2[n] = pe[p]
                n += 1
                p += 1
        else:
            while q < P and S[q] < a:
                q += 1
            while q < P and S[q] < b:
                S2[n] = S[q]
                E2[n] = E[q]
                n += 1
                q += 1
        a = b
    for i in range(n):
        S[i] = S2[i]
        E[i] = E2[i]
    return n


cdef const char* _ANY_INT = b"lqn"          # numpy's intp on LP64 ('l') or LLP64 ('q')


def segment(px_arr, py_arr, thr_arr, sensor_arr, double gap2, double cx, double cy,
            prev_starts, prev_ends, prev_brk, double split_sigmas, idx_t min_points,
            double min_length_m, double max_rms_sigmas):
    """Split-and-merge over ordered points, corners refined, each piece's TLS line.

    px, py, thr (k,) float64 C-contiguous: points and their split thresholds; sensor (k,)
    intp. A new polyline starts at a sensor change or where consecutive points are more
    than sqrt(gap2) apart. The moments' prefix sums are centred on (cx, cy), so small
    spreads keep their digits. With prev_* (the starts, ends and polyline starts ``brk`` of
    an earlier result) over the same polylines only the corners are refined (pieces that do
    not tile the points are a ValueError); where the polylines differ (as many points), the
    polylines that are the same keep the earlier pieces and the others are split anew. Returns
    (starts, ends, brk, owner, cx, cy, alpha, lmin, lmax, n_points, length_m, usable) as
    ``irring.estimation.lines.Pieces`` holds them.
    """
    cdef Py_buffer views[8]                 # px, py, thr, sensor, prev_* (3), q
    cdef int held = 0                       # how many of them are acquired
    cdef idx_t k = len(px_arr), cap = k + 1, i, P = 0, p, nprev = 0, nbrk = 0
    cdef const double* px
    cdef const double* py
    cdef const double* thr
    cdef const idx_t* sensor
    cdef const idx_t* ps = NULL
    cdef const idx_t* pe = NULL
    cdef const unsigned char* pb = NULL
    cdef double* q
    cdef char* mem = NULL
    cdef double* cum
    cdef double* inv_thr
    cdef double* W
    cdef double* cost
    cdef double* qmx
    cdef double* qmy
    cdef idx_t* S
    cdef idx_t* E
    cdef idx_t* cand
    cdef idx_t* qj
    cdef idx_t* S2
    cdef idx_t* E2
    cdef idx_t* seen
    cdef idx_t* stack
    cdef unsigned char* brk
    cdef unsigned char* flag
    cdef size_t nd, ni
    cdef double dx, dy, mxv, myv, s0, s1, s2, s3, s4
    cdef double* c
    cdef bint reuse
    try:
        px = <const double*> _data(px_arr, views, &held, k, 8, b"d", False)
        py = <const double*> _data(py_arr, views, &held, k, 8, b"d", False)
        thr = <const double*> _data(thr_arr, views, &held, k, 8, b"d", False)
        sensor = <const idx_t*> _data(sensor_arr, views, &held, k, sizeof(idx_t), _ANY_INT,
                                      False)
        if prev_starts is not None:
            nprev = len(prev_starts)
            nbrk = len(prev_brk)
            ps = <const idx_t*> _data(prev_starts, views, &held, nprev, sizeof(idx_t), _ANY_INT,
                                      False)
            pe = <const idx_t*> _data(prev_ends, views, &held, nprev, sizeof(idx_t), _ANY_INT,
                                      False)
            pb = <const unsigned char*> _data(prev_brk, views, &held, nbrk, 1, b"?", False)
        # scratch: prefix sums (5 per point and one row of zeros), 1/thr, merge's join costs
        # and joint-line centres; piece starts/ends and their copies, corner and join lists,
        # refinement's memo (4 per corner), the split's stack; polyline starts, merge flags
        nd = NM * cap + k + 4 * cap
        ni = 14 * cap + 4
        mem = <char*> malloc(nd * sizeof(double) + ni * sizeof(idx_t) + 2 * cap)
        if mem == NULL:
            raise MemoryError()
        cum = <double*> mem
        inv_thr = cum + NM * cap
        W = inv_thr + k
        cost = W + cap
        qmx = cost + cap
        qmy = qmx + cap
        S = <idx_t*> (mem + nd * sizeof(double))
        E = S + cap
        cand = E + cap
        qj = cand + cap
        S2 = qj + cap
        E2 = S2 + cap
        seen = E2 + cap
        stack = seen + 4 * cap
        brk = <unsigned char*> (stack + 4 * cap + 4)
        flag = brk + cap

        if k:
            brk[0] = 1
        for i in range(1, k):
            dx = px[i] - px[i - 1]
            dy = py[i] - py[i - 1]
            brk[i] = (dx * dx + dy * dy > gap2) | (sensor[i] != sensor[i - 1])
        # prefix sums of the centred moments, point-major: cum[(i + 1)·5 + r] = Σ over ≤ i,
        # accumulated one point after the other as numpy's cumsum does (from the first value)
        for i in range(NM):
            cum[i] = 0.0
        if k:
            mxv = px[0] - cx
            myv = py[0] - cy
            s0, s1, s2, s3, s4 = mxv, myv, mxv * mxv, myv * myv, mxv * myv
            for i in range(k):
                if i:
                    mxv = px[i] - cx
                    myv = py[i] - cy
                    s0 = s0 + mxv
                    s1 = s1 + myv
                    s2 = s2 + mxv * mxv
                    s3 = s3 + myv * myv
                    s4 = s4 + mxv * myv
                c = cum + (i + 1) * NM
                c[0], c[1], c[2], c[3], c[4] = s0, s1, s2, s3, s4

        # an earlier result is reused only over the same polylines (else it is of other points)
        reuse = pb != NULL and nbrk == k
        if reuse:
            for i in range(k):
                if (pb[i] != 0) != (brk[i] != 0):
                    reuse = False
                    break
        if reuse:
            if not _tiles(ps, pe, nprev, k):
                raise ValueError("prev_starts, prev_ends are not pieces of these points")
            P = nprev
            for p in range(P):
                S[p] = ps[p]
                E[p] = pe[p]
        elif k:
            for i in range(k):
                inv_thr[i] = 1.0 / thr[i]
            P = _split(px, py, inv_thr, brk, k, S, E, stack)
        if k and not reuse:
            # the buffer numpy's arctan2 works in: rows 2·sxy, dif, angle of the joins
            q_arr = np.zeros((3, P))
            q = <double*> _data(q_arr, views, &held, 3 * P, 8, b"d", True)
            P = _merge(px, py, inv_thr, k, cum, cx, cy, S, E, P, cand, qj, flag, W, cost,
                       qmx, qmy, q, q_arr[0], q_arr[1], q_arr[2])
        if k and not reuse and pb != NULL and nbrk == k:
            # polylines the same as in the earlier result keep its pieces (a range jump
            # found at a regroup re-splits only the polylines it cuts)
            if not _tiles(ps, pe, nprev, k):
                raise ValueError("prev_starts, prev_ends are not pieces of these points")
            P = _keep_unchanged(brk, pb, k, ps, pe, nprev, S, E, P, S2, E2)
        _refine_corners(cum, S, E, P, 2, cand, qj, S2, E2, seen)
        return _piece_lines(px, py, thr, k, cum, cx, cy, S, E, P, brk, split_sigmas,
                            min_points, min_length_m, max_rms_sigmas)
    finally:
        free(mem)
        for i in range(held):
            PyBuffer_Release(&views[i])


cdef tuple _piece_lines(const double* px, const double* py, const double* thr, idx_t k,
                        const double* cum, double cx0, double cy0, const idx_t* S,
                        const idx_t* E, idx_t P, const unsigned char* brk, double split_sigmas,
                        idx_t min_points, double min_length_m, double max_rms_sigmas):
    """Each piece's TLS line from its moment sums (mean offset, direction angle α exact for
    vertical lines, λ_min/λ_max the variances across/along it), who owns the corners (a
    corner shared with the previous piece joins the nearer line), and which lines are good
    enough: ≥ min_points readings spanning ≥ min_length_m with an RMS residual within
    max_rms_sigmas of their mean σ (thr / split_sigmas). The outputs are views of three
    blocks (integers, floats, flags); the angles come from numpy's arctan2 over two spare
    rows of the float block."""
    cdef Py_buffer views[3]
    cdef int held = 0
    cdef idx_t p, i, at, lo, hi
    cdef double n, inv, mx, my, cxx, cyy, cxy2, dif, root, mean, alpha, nx, ny, x, y
    cdef double r_own, r_alt, ms
    cdef const double* a
    cdef const double* b
    cdef idx_t* iv
    cdef double* f
    cdef unsigned char* bv
    cdef idx_t* owner
    cdef idx_t* npts
    cdef double* fcx
    cdef double* fcy
    cdef double* fal
    cdef double* flmin
    cdef double* flmax
    cdef double* flen
    cdef double* f2c
    cdef double* fdif
    iblk = np.empty(3 * P + k, dtype=np.intp)      # starts, ends, n_points, owner
    fblk = np.empty((8, P))     # cx, cy, alpha, lmin, lmax, length_m; 2·cxy, dif (spare)
    bblk = np.empty(k + P, dtype=bool)             # brk, usable
    try:
        iv = <idx_t*> _data(iblk, views, &held, 3 * P + k, sizeof(idx_t), _ANY_INT, True)
        f = <double*> _data(fblk, views, &held, 8 * P, 8, b"d", True)
        bv = <unsigned char*> _data(bblk, views, &held, k + P, 1, b"?", True)
        npts, owner = iv + 2 * P, iv + 3 * P
        fcx, fcy, fal, flmin, flmax, flen = f, f + P, f + 2 * P, f + 3 * P, f + 4 * P, f + 5 * P
        f2c, fdif = f + 6 * P, f + 7 * P
        for i in range(k):
            bv[i] = brk[i]
        for p in range(P):
            iv[p] = S[p]
            iv[P + p] = E[p]
            lo, hi = S[p], E[p]
            n = <double>(hi - lo) + 1.0
            a = cum + lo * NM
            b = cum + (hi + 1) * NM
            inv = 1.0 / (n if n >= 1.0 else 1.0)
            mx = (b[0] - a[0]) * inv
            my = (b[1] - a[1]) * inv
            cxx = (b[2] - a[2]) * inv - mx * mx
            if cxx < 0.0:
                cxx = 0.0
            cyy = (b[3] - a[3]) * inv - my * my
            if cyy < 0.0:
                cyy = 0.0
            cxy2 = ((b[4] - a[4]) * inv - mx * my) * 2.0
            dif = cxx - cyy
            root = hypot(dif, cxy2) * 0.5
            mean = (cxx + cyy) * 0.5
            fcx[p] = mx + cx0
            fcy[p] = my + cy0
            flmin[p] = mean - root
            if flmin[p] < 0.0:
                flmin[p] = 0.0
            flmax[p] = mean + root
            f2c[p] = cxy2
            fdif[p] = dif
        alpha_arr = fblk[2]
        if P:
            _arctan2(fblk[6], fblk[7], alpha_arr)
        for p in range(P):
            fal[p] = fal[p] * 0.5
        # owner: the last piece starting at or before each point (a shared corner: the
        # right one), then a corner shared with the previous piece joins the nearer line
        for p in range(P):
            for i in range(S[p], S[p + 1] if p + 1 < P else k):
                owner[i] = p
        for p in range(P - 1):
            if S[p + 1] != E[p]:
                continue
            at = S[p + 1]
            x, y = px[at], py[at]
            alpha = fal[p + 1]
            r_own = fabs((x - fcx[p + 1]) * -sin(alpha) + (y - fcy[p + 1]) * cos(alpha))
            alpha = fal[p]
            r_alt = fabs((x - fcx[p]) * -sin(alpha) + (y - fcy[p]) * cos(alpha))
            if r_alt < r_own:
                owner[at] = p
        # readings and summed thresholds per piece, in reading order (as np.bincount adds
        # them); owner never decreases, so each piece's readings are one run
        for p in range(P):
            npts[p] = 0
            f2c[p] = 0.0
        i = 0
        while i < k:
            p = owner[i]
            ms = 0.0
            at = i
            while i < k and owner[i] == p:
                ms = ms + thr[i]
                i += 1
            npts[p] = i - at
            f2c[p] = ms
        for p in range(P):
            alpha = fal[p]
            nx = -sin(alpha)
            ny = cos(alpha)
            flen[p] = fabs((px[E[p]] - px[S[p]]) * ny + (py[E[p]] - py[S[p]]) * -nx)
            ms = f2c[p] / (split_sigmas * <double>(npts[p] if npts[p] > 1 else 1))
            if ms < 1e-6:
                ms = 1e-6
            bv[k + p] = (npts[p] >= min_points and flen[p] >= min_length_m and flmax[p] > 0
                         and sqrt(flmin[p]) <= max_rms_sigmas * ms and isfinite(alpha))
            if alpha < 0:
                fal[p] = alpha + M_PI
    finally:
        for i in range(held):
            PyBuffer_Release(&views[i])
    return (iblk[:P], iblk[P:2 * P], bblk[:k], iblk[3 * P:], fblk[0], fblk[1], alpha_arr,
            fblk[3], fblk[4], iblk[2 * P:3 * P], fblk[5], bblk[k:])


# --------------------------------------------------------------------------- silent beams

def no_return_reach(const double[::1] heading, const double[::1] ox, const double[::1] oy,
                    const double[::1] x, const double[::1] y, const idx_t[::1] label,
                    const unsigned char[::1] valid, const unsigned char[::1] reason,
                    unsigned char no_return, const double[:, ::1] centroid,
                    const double[:, ::1] direction, const double[:, ::1] normal,
                    const unsigned char[::1] usable, idx_t min_members, double clear_m,
                    double block_m, double corner_min_sin, double corner_past_m,
                    double cos_limit, double max_range, double end_theta, idx_t width):
    """How far each silent beam is known free: ``irring.estimation.estimate_numpy.no_return_reach``
    (the statement and the why) in one pass: the same operations in the same order, the
    beam's cos and sin libm's (numpy's agree with them, see the top of this file).

    Per reading (K,) float64 / intp / uint8, flat: heading, origin ox, oy, end point x, y, line
    label (−1: none), valid, reason (``no_return``: a silent beam). Per line (L,): centroid,
    direction, normal (L, 2) and usable. Lines with ≥ ``min_members`` valid members explain
    beams; their span is the members' extent plus ``block_m``, clipped ``corner_past_m`` past
    a corner (``irring.estimation.silence.clip_at_corners``). Past a line's members' end a
    beam stops where a face turned ``end_theta`` + γ from it could hide (γ at most the
    heading gap to the nearest reading ``width`` apart, a step before or after in the same
    sensor's column, that was not silent: ``estimate_numpy.return_gaps``). Returns reach (K,)
    (NaN: to the max range) or None when no beam is explained; a label ≥ L is a ValueError."""
    cdef idx_t K = heading.shape[0], L = usable.shape[0], U = 0, i, j, l, u, v, side
    cdef double along, den, dx, dy, a, b, ux, uy, un, gap, cos_inc, t, s, stop
    cdef double end, ex, ey, t_end, off, angle, hide, cross, gamma, heard, up, down, dh
    cdef idx_t other
    cdef bint found = False
    if not (ox.shape[0] == oy.shape[0] == x.shape[0] == y.shape[0] == label.shape[0]
            == valid.shape[0] == reason.shape[0] == K):
        raise lengths_differ("per-reading arrays", heading=K, ox=ox.shape[0], oy=oy.shape[0],
                             x=x.shape[0], y=y.shape[0], label=label.shape[0],
                             valid=valid.shape[0], reason=reason.shape[0])
    if not (centroid.shape[0] == direction.shape[0] == normal.shape[0] == L
            and centroid.shape[1] == direction.shape[1] == normal.shape[1] == 2):
        raise ValueError("line arrays must be (L, 2) for the L usable flags")
    for i in range(K):
        if label[i] >= L:
            raise ValueError(f"line label {label[i]} of reading {i}: only {L} lines")
    n_mem = np.zeros(L, dtype=np.intp)
    col = np.full(L, -1, dtype=np.intp)
    cdef idx_t[::1] nm = n_mem, cl = col
    for i in range(K):
        if label[i] >= 0 and valid[i]:
            nm[label[i]] += 1
    for l in range(L):
        if usable[l] and nm[l] >= min_members:
            cl[l] = U
            U += 1
    if U == 0:
        return None
    spans = np.empty((6, U))
    use_arr = np.empty(U, dtype=np.intp)
    cdef double[:, ::1] sp = spans
    cdef double[::1] lo = sp[0], hi = sp[1], lo_b0 = sp[2], hi_b0 = sp[3], lo_b = sp[4], hi_b = sp[5]
    cdef idx_t[::1] use = use_arr
    for l in range(L):
        if cl[l] >= 0:
            use[cl[l]] = l
    for u in range(U):
        lo[u] = INFINITY
        hi[u] = -INFINITY
    # the members' extent along each line (NaN propagates as numpy's minimum.at does)
    for i in range(K):
        if label[i] < 0 or not valid[i]:
            continue
        u = cl[label[i]]
        if u < 0:
            continue
        l = label[i]
        along = (x[i] - centroid[l, 0]) * direction[l, 0] + (y[i] - centroid[l, 1]) * direction[l, 1]
        if along < lo[u] or along != along:
            if lo[u] == lo[u]:
                lo[u] = along
        if along > hi[u] or along != along:
            if hi[u] == hi[u]:
                hi[u] = along
    # spans clipped at corners: where line u meets line v's (unclipped) span
    for u in range(U):
        lo_b0[u] = lo[u] - block_m
        hi_b0[u] = hi[u] + block_m
        lo_b[u] = lo_b0[u]
        hi_b[u] = hi_b0[u]
    if U >= 2:
        for u in range(U):
            i = use[u]
            for v in range(U):
                if v == u:
                    continue
                j = use[v]
                den = direction[i, 0] * direction[j, 1] - direction[i, 1] * direction[j, 0]
                if not fabs(den) > corner_min_sin:
                    continue
                dx = centroid[j, 0] - centroid[i, 0]
                dy = centroid[j, 1] - centroid[i, 1]
                b = (dx * direction[i, 1] - dy * direction[i, 0]) / den
                if not (b >= lo_b0[v] and b <= hi_b0[v]):
                    continue
                a = (dx * direction[j, 1] - dy * direction[j, 0]) / den
                if a > hi[u] and a < hi_b0[u] and a + corner_past_m < hi_b[u]:
                    hi_b[u] = a + corner_past_m
                if a < lo[u] and a > lo_b0[u] and a - corner_past_m > lo_b[u]:
                    lo_b[u] = a - corner_past_m
    # each silent beam stops clear_m (across the line) before the first line that explains it
    reach_arr = np.full(K, NAN)
    cdef double[::1] reach = reach_arr
    for i in range(K):
        if reason[i] != no_return:
            continue
        ux = cos(heading[i])
        uy = sin(heading[i])
        # the heading gaps to the nearest readings of the same column that were not silent
        up = NAN
        down = NAN
        for side in range(2):
            if width <= 0:
                break
            other = i - width if side == 0 else i + width
            while 0 <= other < K and reason[other] == no_return:
                other = other - width if side == 0 else other + width
            if not 0 <= other < K:
                continue
            dh = heading[other] - heading[i]
            dh = dh - 2.0 * M_PI * nearbyint(dh / (2.0 * M_PI))
            if dh > 0 and not up <= dh:
                up = dh
            elif dh < 0 and not down <= -dh:
                down = -dh
        stop = INFINITY
        for u in range(U):
            l = use[u]
            un = ux * normal[l, 0] + uy * normal[l, 1]
            cos_inc = fabs(un)
            if not cos_inc > 1e-9:
                continue
            gap = (centroid[l, 0] - ox[i]) * normal[l, 0] + (centroid[l, 1] - oy[i]) * normal[l, 1]
            t = gap / un
            if not (isfinite(t) and t > 0 and t <= max_range):
                continue
            along = ((ox[i] + t * ux - centroid[l, 0]) * direction[l, 0]
                     + (oy[i] + t * uy - centroid[l, 1]) * direction[l, 1])
            if cos_inc <= cos_limit and along >= lo_b[u] and along <= hi_b[u]:
                s = t - clear_m / cos_inc
                if s < 0.0:
                    s = 0.0
                if s < stop:
                    stop = s
            # past an end of the members: where a face turned away there could hide
            for side in range(2):
                if side == 0:
                    if not along > hi[u]:
                        continue
                    end = hi[u]
                else:
                    if not along < lo[u]:
                        continue
                    end = lo[u]
                ex = centroid[l, 0] + end * direction[l, 0] - ox[i]
                ey = centroid[l, 1] + end * direction[l, 1] - oy[i]
                t_end = ex * ux + ey * uy
                if not t_end > 0:
                    continue
                cross = ux * ey - uy * ex
                off = fabs(cross)
                gamma = asin(fmin(off / fmax(hypot(ex, ey), 1e-12), 1.0))
                heard = up if cross > 0 else down
                if heard < gamma:
                    gamma = heard
                angle = end_theta + gamma
                if not angle < 0.5 * M_PI - 1e-6:
                    continue
                hide = t_end + off * tan(angle)
                s = t if t > hide else hide
                if s < stop:
                    stop = s
        if stop < INFINITY:
            reach[i] = stop
            found = True
    return reach_arr if found else None


# --------------------------------------------------------------------------- end points on lines

def snap_to_lines(const idx_t[::1] member, const unsigned char[::1] valid,
                  const double[::1] x, const double[::1] y, const double[::1] d,
                  const double[::1] sigma_m, const double[::1] heading, const double[::1] ox,
                  const double[::1] oy, idx_t min_members, double snap_sigmas, double own_share,
                  double own_cap, double sigma_floor, double min_range, double max_range):
    """Line members' end points moved onto their lines:
    ``irring.estimation.estimate_numpy.snap_to_lines`` (the statement and the why) in two
    passes over the readings, the same operations in the same order (the per-line sums
    accumulate in reading order, as numpy's bincount does; the line angles from numpy's
    own arctan2, the cos and sin libm's, see the top of this file).

    Per reading (K,) flat: line index ``member`` (−1: none), valid (uint8), end point x, y,
    distance d, sigma_m, heading, emitter ox, oy; ``own_cap``: the most ``own_share`` of a
    member's σ adds (+inf: no cap). Returns new (x, y, d, sigma_m) arrays, or None when no
    end point moves."""
    cdef idx_t K = member.shape[0], L = 0, i, g, moved = 0
    cdef double u, v, ca, sa, ngx, ngy, ch, sh, un, rel, t, al, perp2, sl, own
    if not (valid.shape[0] == x.shape[0] == y.shape[0] == d.shape[0] == sigma_m.shape[0]
            == heading.shape[0] == ox.shape[0] == oy.shape[0] == K):
        raise lengths_differ("per-reading arrays", member=K, valid=valid.shape[0],
                             x=x.shape[0], y=y.shape[0], d=d.shape[0],
                             sigma_m=sigma_m.shape[0], heading=heading.shape[0],
                             ox=ox.shape[0], oy=oy.shape[0])
    for i in range(K):
        if valid[i] and member[i] >= L:
            L = member[i] + 1
    if L == 0:
        return None
    # per line: n, Σx, Σy, then Σuv, Σuu, Σvv, Σrel², Σalong² (numpy's bincount order)
    sums = np.zeros((10, L))
    cdef double[:, ::1] S = sums
    cdef double[::1] n = S[0], mx = S[1], my = S[2], suv = S[3], suu = S[4], svv = S[5]
    cdef double[::1] sr = S[6], sal = S[7], cos_a = S[8], sin_a = S[9]
    cdef bint any_kept = False
    for i in range(K):
        if valid[i] and member[i] >= 0:
            g = member[i]
            n[g] += 1.0
            mx[g] += x[i]
            my[g] += y[i]
    for g in range(L):
        if n[g] >= min_members:
            any_kept = True
        if n[g] < 1.0:
            n[g] = 1.0                         # nn = max(n, 1)
        mx[g] = mx[g] / n[g]
        my[g] = my[g] / n[g]
    if not any_kept:
        return None
    for i in range(K):
        if valid[i] and member[i] >= 0:
            g = member[i]
            u = x[i] - mx[g]
            v = y[i] - my[g]
            suv[g] += u * v
            suu[g] += u * u
            svv[g] += v * v
    for g in range(L):
        suv[g] = 2.0 * suv[g]
        suu[g] = suu[g] - svv[g]
    alpha = _arctan2(sums[3], sums[4])
    alpha *= 0.5
    cdef double[::1] a = alpha
    for g in range(L):
        cos_a[g] = cos(a[g])
        sin_a[g] = sin(a[g])
    # the moves, and the sums the moved points' σ needs
    # t of each reading that moves, its beam's cos and sin, its place along its line and the
    # beam's cosine to the line's normal (the σ pass reads them back)
    step = np.full((5, K), NAN)
    cdef double[:, ::1] tcs = step
    cdef double[::1] tt = tcs[0], cos_h = tcs[1], sin_h = tcs[2], along = tcs[3], to_n = tcs[4]
    for i in range(K):
        if not (valid[i] and member[i] >= 0):
            continue
        g = member[i]
        u = x[i] - mx[g]
        v = y[i] - my[g]
        ngx = -sin_a[g]
        ngy = cos_a[g]
        al = u * cos_a[g] + v * sin_a[g]
        rel = u * ngx + v * ngy
        sr[g] += rel * rel
        sal[g] += al * al
        cos_h[i] = cos(heading[i])
        sin_h[i] = sin(heading[i])
        un = cos_h[i] * ngx + sin_h[i] * ngy
        t = d[i] - rel / un
        # behind its line: always onto it; short of it: within snap_sigmas σ (the oracle's why)
        if (n[g] >= min_members and isfinite(t) and t - d[i] <= snap_sigmas * sigma_m[i]
                and t >= min_range and t <= max_range):
            tt[i] = t
            along[i] = al
            to_n[i] = un
            moved += 1
    if moved == 0:
        return None
    out = np.empty((4, K))
    cdef double[:, ::1] o = out
    o[0, :] = x
    o[1, :] = y
    o[2, :] = d
    o[3, :] = sigma_m
    for i in range(K):
        t = tt[i]
        if t != t:
            continue
        g = member[i]
        al = along[i]
        un = to_n[i]
        ch = cos_h[i]
        sh = sin_h[i]
        sl = sal[g] / n[g]
        if not sl >= 1e-12:
            sl = 1e-12 if sl == sl else sl
        perp2 = (sr[g] / n[g]) / n[g] * (1.0 + al * al / sl)
        sl = sqrt(perp2) / fabs(un)
        own = own_share * sigma_m[i]
        own = hypot(sl, own_cap if own > own_cap else own)
        o[3, i] = sigma_floor if own < sigma_floor else own    # (NaN stays, as numpy's)
        o[2, i] = t
        o[0, i] = ox[i] + t * ch
        o[1, i] = oy[i] + t * sh
    return out[0], out[1], out[2], out[3]


# --------------------------------------------------------------------------- range profiles

cdef inline void _interp_ab(double t, const double[::1] xp, const double[::1] la,
                            const double[::1] bb, double inv_dx, double* out_la,
                            double* out_b) noexcept nogil:
    """log a(θ), b(θ) at θ = t ≥ 0 linear between the calibration's nodes, held beyond
    them (np.interp's rule). The cell is guessed as if the nodes were evenly spaced
    (``inv_dx``: cells per radian over their span) and walked to from there."""
    cdef idx_t m = xp.shape[0], lo
    cdef double f
    if t <= xp[0]:
        out_la[0] = la[0]
        out_b[0] = bb[0]
        return
    if t >= xp[m - 1]:
        out_la[0] = la[m - 1]
        out_b[0] = bb[m - 1]
        return
    lo = <idx_t> ((t - xp[0]) * inv_dx)
    if lo > m - 2:
        lo = m - 2
    while lo > 0 and xp[lo] > t:
        lo -= 1
    while lo < m - 2 and xp[lo + 1] <= t:
        lo += 1
    f = (t - xp[lo]) / (xp[lo + 1] - xp[lo])
    out_la[0] = la[lo] + f * (la[lo + 1] - la[lo])
    out_b[0] = bb[lo] + f * (bb[lo + 1] - bb[lo])


def polyline_ids(const double[::1] d, const double[::1] sigma, const double[::1] heading,
                 const idx_t[::1] sensor, double tan_reject, double sigmas):
    """``irring.estimation.lines.polyline_ids`` (the statement and the why) bit for bit:
    readings (k,) in scan order; ``tan_reject`` = ``lines.jump_slope(reject)``. Returns the
    polyline id of each reading (intp, from 1), as np.cumsum of the cuts."""
    cdef idx_t k = d.shape[0], i, run = 1
    cdef double turn, wrap, far, allowed
    if not (sigma.shape[0] == heading.shape[0] == sensor.shape[0] == k):
        raise lengths_differ("per-reading arrays", d=k, sigma=sigma.shape[0],
                             heading=heading.shape[0], sensor=sensor.shape[0])
    out = np.empty(k, dtype=np.intp)
    if k == 0:
        return out
    cdef idx_t[::1] ids = out
    ids[0] = 1
    for i in range(1, k):
        # np.minimum / np.maximum: a NaN wins; a NaN allowance cuts nothing
        turn = fabs(heading[i] - heading[i - 1])
        wrap = 2.0 * M_PI - turn
        if not (turn != turn or turn <= wrap):
            turn = wrap
        far = d[i]
        if not (far != far or far >= d[i - 1]):
            far = d[i - 1]
        allowed = far * turn * tan_reject
        allowed = allowed + sigmas * hypot(sigma[i], sigma[i - 1])
        if fabs(d[i] - d[i - 1]) > allowed or sensor[i] != sensor[i - 1]:
            run += 1
        ids[i] = run
    return out


def profile_inputs(const double[::1] counts, const double[::1] heading,
                   const double[::1] origin_x, const double[::1] origin_y,
                   const idx_t[::1] steps, const idx_t[::1] vi, idx_t n_sensors,
                   double sigma_counts, double la0, double b0, double sigma_floor,
                   double tan_reject, double jump_sigmas):
    """``irring.estimation.profiles._profile_inputs`` bit for bit in one call (log and exp
    are numpy's, on this call's rows): per valid reading ``vi`` (flat (S·N) indices in scan
    order) of the flat (S·N) ``counts``, ``heading``, ``origin_x``, ``origin_y`` and the
    (S,) ``steps``. Returns (K,) rows s, h, ox, oy, log s, σ_S/S, d0 (one float block) and
    the polyline ids at θ = 0 (as :func:`polyline_ids`) and motor steps (intp)."""
    cdef idx_t K = vi.shape[0], size = counts.shape[0], i, f, run = 1
    cdef double turn, wrap, far, allowed, sg, sg_prev = 0.0, c
    if not (heading.shape[0] == origin_x.shape[0] == origin_y.shape[0] == size
            and n_sensors >= 1 and steps.shape[0] * n_sensors == size):
        raise ValueError("counts, heading, origin_x, origin_y need one entry per reading "
                         "and steps one per row")
    rows = np.empty((7, K))
    ints = np.empty((2, K), dtype=np.intp)
    if K == 0:
        return rows[0], rows[1], rows[2], rows[3], rows[4], rows[5], rows[6], ints[0], ints[1]
    cdef double[:, ::1] R = rows
    cdef idx_t[:, ::1] I = ints
    for i in range(K):
        f = vi[i]
        if f < 0 or f >= size:
            raise IndexError(f"vi[{i}] = {f} is not a reading (0 … {size - 1})")
        c = counts[f]
        R[0, i] = c
        R[1, i] = heading[f]
        R[2, i] = origin_x[f]
        R[3, i] = origin_y[f]
        R[5, i] = sigma_counts / c              # σ_d = |b|·d·σ_S/S
        I[1, i] = steps[f // n_sensors]
    np.log(rows[0], out=rows[4])
    for i in range(K):
        R[6, i] = la0 + b0 * R[4, i]
    np.exp(rows[6], out=rows[6])
    for i in range(K):
        sg = fabs(b0) * R[6, i] * R[5, i]
        if not (sg != sg or sg >= sigma_floor):     # np.maximum: a NaN wins
            sg = sigma_floor
        if i == 0:
            I[0, i] = run
            sg_prev = sg
            continue
        turn = fabs(R[1, i] - R[1, i - 1])
        wrap = 2.0 * M_PI - turn
        if not (turn != turn or turn <= wrap):
            turn = wrap
        far = R[6, i]
        if not (far != far or far >= R[6, i - 1]):
            far = R[6, i - 1]
        allowed = far * turn * tan_reject
        allowed = allowed + jump_sigmas * hypot(sg, sg_prev)
        if fabs(R[6, i] - R[6, i - 1]) > allowed or vi[i] % n_sensors != vi[i - 1] % n_sensors:
            run += 1
        I[0, i] = run
        sg_prev = sg
    return rows[0], rows[1], rows[2], rows[3], rows[4], rows[5], rows[6], ints[0], ints[1]


def profiles(const double[::1] ox, const double[::1] oy, const double[::1] heading,
             const double[::1] log_s, const double[::1] sig_s, const idx_t[::1] chain,
             const idx_t[::1] step, const idx_t[::1] ask, const double[::1] xp,
             const double[::1] node_log_a, const double[::1] node_b, double max_inc,
             double convex_below, idx_t half, idx_t min_n, double spread_m, double n_se,
             const double[::1] chi2_95, double sigma_floor, double sure_se,
             double bend_min_share):
    """Each asked reading's range profile: ``irring.estimation.profiles.range_profiles`` (the
    statement and the why) reading by reading, to within rounding (the sums accumulate in
    window order, θ's curve between nodes as np.interp draws it).

    Per valid reading in scan order (K,): emitter ox, oy, heading, log counts, σ_S/S,
    polyline id and motor step; ``ask`` (M,) positions into them. Returns (n, slope, se,
    theta, steep) float arrays and (ok, convex, sure, concave) uint8 arrays, each (M,);
    sure: bent away by ``sure_se`` standard errors; no bend where fewer than ``min_n``
    readings or the curvature term keeps at most ``bend_min_share`` of Σ(v²)²."""
    cdef idx_t K = ox.shape[0], M = ask.shape[0], i, p, c, w, r, nw, dof, n_ok, n_steps, w2
    cdef idx_t W = 2 * half + 1
    cdef double inv_dx = 0.0
    cdef double ux, uy, signed, th, la, b, d, x, y, nn, mu, mv, svv, sl, t, se, chi2, res
    cdef double sqq, qm, qdv, bend, bend_se, sig, e2, q_norm
    cdef bint straight
    if not (oy.shape[0] == heading.shape[0] == log_s.shape[0] == sig_s.shape[0]
            == chain.shape[0] == step.shape[0] == K):
        raise lengths_differ("per-reading arrays", ox=K, oy=oy.shape[0],
                             heading=heading.shape[0], log_s=log_s.shape[0],
                             sig_s=sig_s.shape[0], chain=chain.shape[0], step=step.shape[0])
    if xp.shape[0] > 1 and xp[xp.shape[0] - 1] > xp[0]:
        inv_dx = (xp.shape[0] - 1) / (xp[xp.shape[0] - 1] - xp[0])
    out_f = np.zeros((5, M))
    out_b = np.zeros((4, M), dtype=np.uint8)
    cdef double[:, ::1] F = out_f
    cdef unsigned char[:, ::1] B = out_b
    cdef idx_t* win = <idx_t*> malloc(W * sizeof(idx_t))
    cdef double* turn = <double*> malloc(W * sizeof(double))
    cdef double* u = <double*> malloc(W * sizeof(double))
    cdef double* v = <double*> malloc(W * sizeof(double))
    cdef double* sg = <double*> malloc(W * sizeof(double))
    cdef double* q = <double*> malloc(W * sizeof(double))
    cdef double* rx = <double*> malloc(4 * W * sizeof(double))
    cdef double* ry = rx + W
    cdef double* ch = rx + 2 * W
    cdef double* sh = rx + 3 * W
    # each valid reading's beam direction, computed the first time a window needs it
    # (windows overlap: most readings are in several)
    cdef double* cos_k = <double*> malloc(2 * K * sizeof(double) + 1)
    cdef double* sin_k = cos_k + K
    cdef unsigned char* have = <unsigned char*> calloc(K + 1, 1)
    if (win == NULL or turn == NULL or u == NULL or v == NULL or sg == NULL or q == NULL
            or rx == NULL or cos_k == NULL or have == NULL):
        free(win); free(turn); free(u); free(v); free(sg); free(q); free(rx)
        free(cos_k); free(have)
        raise MemoryError()
    try:
        for i in range(M):
            p = ask[i]
            if p < 0 or p >= K:
                raise IndexError(f"ask[{i}] = {p} is outside 0 … {K - 1}")
            nw = 0
            for c in range(p - half, p + half + 1):
                if c < 0 or c >= K or chain[c] != chain[p]:
                    continue
                if step[c] - step[p] > half or step[p] - step[c] > half:
                    continue
                win[nw] = c
                t = heading[c] - heading[p]
                turn[nw] = t - 2.0 * M_PI * nearbyint(t / (2.0 * M_PI))
                rx[nw] = ox[c] - ox[p]
                ry[nw] = oy[c] - oy[p]
                if not have[c]:
                    cos_k[c] = cos(heading[c])
                    sin_k[c] = sin(heading[c])
                    have[c] = 1
                ch[nw] = cos_k[c]
                sh[nw] = sin_k[c]
                nw += 1
            if not have[p]:
                cos_k[p] = cos(heading[p])
                sin_k[p] = sin(heading[p])
                have[p] = 1
            ux = cos_k[p]
            uy = sin_k[p]
            nn = nw if nw > 1 else 1.0
            signed = 0.0
            sl = 0.0
            svv = 1e-12
            for r in range(3):
                # on a flat surface a neighbour meets it at θ plus the angle the beam turned
                mu = 0.0
                mv = 0.0
                for w in range(nw):
                    c = win[w]
                    th = fabs(signed + turn[w])
                    if th > max_inc:
                        th = max_inc
                    _interp_ab(th, xp, node_log_a, node_b, inv_dx, &la, &b)
                    d = exp(la + b * log_s[c])
                    x = rx[w] + d * ch[w]
                    y = ry[w] + d * sh[w]
                    u[w] = x * ux + y * uy
                    v[w] = y * ux - x * uy
                    if r == 2:    # the noise of the last round's distances
                        sig = fabs(b) * d * sig_s[c]
                        sg[w] = sig if sig > sigma_floor else sigma_floor
                    mu += u[w]
                    mv += v[w]
                mu /= nn
                mv /= nn
                svv = 0.0
                sl = 0.0
                for w in range(nw):
                    u[w] -= mu
                    v[w] -= mv
                    svv += v[w] * v[w]
                    sl += u[w] * v[w]
                if svv < 1e-12:
                    svv = 1e-12
                sl /= svv
                signed = atan(sl)
                if signed > max_inc:
                    signed = max_inc
                elif signed < -max_inc:
                    signed = -max_inc
            e2 = 0.0
            chi2 = 0.0
            qm = 0.0
            qdv = 0.0
            q_norm = 0.0
            for w in range(nw):
                e2 += (sg[w] * v[w]) * (sg[w] * v[w])
                res = (u[w] - sl * v[w]) / sg[w]
                chi2 += res * res
                q[w] = v[w] * v[w]
                q_norm += q[w] * q[w]
                qm += q[w]
                qdv += q[w] * v[w]
            se = sqrt(e2) / svv
            qm /= nn
            qdv /= svv
            sqq = 0.0
            bend = 0.0
            bend_se = 0.0
            for w in range(nw):
                # the curvature term, orthogonal to 1 and v
                q[w] = q[w] - qm - qdv * v[w]
                sqq += q[w] * q[w]
            # readings of one step repeated lie on one spot: they give no slope; nor do fewer
            # than min_n distinct steps (a step read repeatedly is one spot, however often)
            n_steps = 0
            for w in range(nw):
                for w2 in range(w):
                    if step[win[w2]] == step[win[w]]:
                        break
                else:
                    n_steps += 1
            n_ok = nw if (svv >= nw * spread_m * spread_m and n_steps >= min_n) else 0
            # at two spots the curvature term is rounding: no bend (as range_profiles says)
            if n_ok >= min_n and sqq > bend_min_share * q_norm:
                if sqq < 1e-30:
                    sqq = 1e-30
                for w in range(nw):
                    bend += u[w] * q[w]
                    bend_se += (sg[w] * q[w]) * (sg[w] * q[w])
                bend /= sqq
                bend_se = sqrt(bend_se) / sqq
            dof = n_ok - 2
            if dof < 1:
                dof = 1
            elif dof > chi2_95.shape[0]:
                dof = chi2_95.shape[0]
            th = fabs(signed)
            F[0, i] = n_ok
            F[1, i] = sl
            F[2, i] = se
            F[3, i] = th
            straight = (n_ok >= min_n and chi2 <= chi2_95[dof - 1]
                        and fabs(bend) <= n_se * bend_se)
            B[0, i] = straight and fabs(sl) > n_se * se
            B[1, i] = n_ok >= min_n and bend > n_se * bend_se and th < max_inc - convex_below
            B[2, i] = bend > sure_se * bend_se
            B[3, i] = bend < -n_se * bend_se
            # the slope bounds θ only where the profile is straight or bent away
            if n_ok < min_n or B[3, i] or not (straight or bend > n_se * bend_se):
                F[4, i] = max_inc
            else:
                t = atan(fabs(sl) + n_se * se)
                F[4, i] = t if t < max_inc else max_inc
    finally:
        free(win); free(turn); free(u); free(v); free(sg); free(q); free(rx)
        free(cos_k); free(have)
    return (out_f[0], out_f[1], out_f[2], out_f[3], out_f[4], out_b[0], out_b[1], out_b[2],
            out_b[3])


def far_line_vote(const idx_t[::1] at, const idx_t[::1] sel, const idx_t[::1] lab,
                  const double[::1] theta_now, const idx_t[::1] chain, const idx_t[::1] step,
                  const double[::1] n, const double[::1] se, const double[::1] slope,
                  const double[::1] theta_own, const double[::1] s, const double[::1] d,
                  const idx_t[::1] vi, const double[::1] xp, const double[::1] node_log_a,
                  const double[::1] node_b, idx_t n_lines, idx_t half, idx_t min_n,
                  double z_max, double shift_m):
    """``irring.estimation.estimate_numpy.far_line_vote`` (the statement and the why) in one
    pass, the sums in its order, to within rounding (tan, log, exp and log a, b between the
    calibration's nodes ``xp``, ``node_log_a``, ``node_b`` are libm's and this file's, not
    numpy's). ``at`` (A,) the asked members' places among the K valid readings ``vi`` (flat
    indices into ``d``), ``sel`` (A,) their places among the profiled readings; per valid
    reading (K,): ``lab`` line (−1 none), ``theta_now``, ``chain``, ``step``, ``s``
    (counts); per profiled reading: ``n``, ``se``, ``slope``, ``theta_own``. Returns
    ``off_line`` (n_lines,) uint8."""
    cdef idx_t A = at.shape[0], K = lab.shape[0], M = n.shape[0], i, q, p, c, L, lo, hi
    cdef idx_t n_nodes = xp.shape[0]
    cdef bint u, pure, any_off = False
    cdef double inv_dx = 0.0, la, b
    if not (sel.shape[0] == A and theta_now.shape[0] == chain.shape[0] == step.shape[0]
            == s.shape[0] == vi.shape[0] == K and se.shape[0] == slope.shape[0]
            == theta_own.shape[0] == M):
        raise lengths_differ("far_line_vote's arrays", at=A, sel=sel.shape[0], lab=K,
                             theta_now=theta_now.shape[0], chain=chain.shape[0],
                             step=step.shape[0], s=s.shape[0], vi=vi.shape[0], n=M,
                             se=se.shape[0], slope=slope.shape[0],
                             theta_own=theta_own.shape[0])
    if n_nodes > 1 and xp[n_nodes - 1] > xp[0]:
        inv_dx = (n_nodes - 1) / (xp[n_nodes - 1] - xp[0])
    off_arr = np.zeros(n_lines, dtype=np.uint8)
    flags = np.zeros((2, A), dtype=np.uint8)      # use, pure
    sums = np.zeros((4, n_lines))     # pure members, members used, their summed z, shift
    cdef unsigned char[::1] off = off_arr
    cdef unsigned char[:, ::1] F = flags
    cdef double[:, ::1] S = sums
    for i in range(A):
        p = at[i]
        q = sel[i]
        if p < 0 or p >= K or q < 0 or q >= M:
            raise IndexError(f"at[{i}] = {p} or sel[{i}] = {q} is outside 0 … {K - 1} "
                             f"or 0 … {M - 1}")
        L = lab[p]
        if L < 0 or L >= n_lines:
            raise IndexError(f"reading {p} is on line {L}, not one of 0 … {n_lines - 1}")
        u = n[q] >= min_n and se[q] > 0
        pure = u
        if u:         # another line's reading (or one on none) in the profile's window
            lo = p - half if p >= half else 0
            hi = p + half if p + half < K else K - 1
            for c in range(lo, hi + 1):
                if (chain[c] == chain[p] and step[c] - step[p] <= half
                        and step[p] - step[c] <= half and lab[c] != L):
                    pure = False
                    break
        F[0, i] = u
        F[1, i] = pure
        S[0, L] += pure
    for i in range(A):
        L = lab[at[i]]
        q = sel[i]
        if F[0, i] and not (F[1, i] or S[0, L] < min_n):
            F[0, i] = 0
        S[1, L] += F[0, i]
        S[2, L] += (tan(theta_now[at[i]]) - fabs(slope[q])) / se[q] if F[0, i] else 0.0
    for L in range(n_lines):
        off[L] = S[1, L] >= min_n and fabs(S[2, L]) > z_max * (S[1, L] if S[1, L] > 1 else 1.0)
        any_off = any_off or off[L]
    if not any_off:
        return off_arr.view(bool)
    for i in range(A):        # … and whether their own θ would move them at all
        L = lab[at[i]]
        if F[0, i] and off[L]:
            _interp_ab(fabs(theta_own[sel[i]]), xp, node_log_a, node_b, inv_dx, &la, &b)
            S[3, L] += fabs(d[vi[at[i]]] - exp(la + b * log(s[at[i]])))
    for L in range(n_lines):
        off[L] = off[L] and S[3, L] >= shift_m * S[1, L]
    return off_arr.view(bool)


def short_far_lines(const idx_t[::1] index, const unsigned char[::1] valid,
                    const idx_t[::1] label, const double[::1] d, const double[::1] sigma,
                    const double[::1] theta, const double[::1] x, const double[::1] y,
                    double far_m, idx_t min_n, idx_t max_n, idx_t few_n, double se_max,
                    bint ask_loose):
    """``irring.estimation.far_lines.short_far_lines`` (the statement and the why) to the
    bit: the members (in scan order ``index``, flat (S·N) indices) of each line whose
    members' summed ``d`` reaches ``far_m`` (the share of the max range) times their number;
    ``doubt`` where it has ``min_n`` … ``max_n`` members; with ``ask_loose``, ``loose``
    where it has at most ``few_n`` and ``lines.direction_se`` (its sums in scan order,
    numpy's arctan2, cos and sin) exceeds ``se_max``. Arrays flat (S·N); ``label`` −1 on no
    line. Returns (doubt, loose) (S·N,) bool, or None where neither holds anywhere."""
    cdef idx_t k = index.shape[0], size = label.shape[0], i, f, l, L = 0, m = 0, ms = 0
    cdef bint far, any_doubt = False, any_few = False, any_loose = False
    cdef double u, v, along
    if not (valid.shape[0] == d.shape[0] == sigma.shape[0] == theta.shape[0] == x.shape[0]
            == y.shape[0] == size):
        raise lengths_differ("short_far_lines' arrays", label=size, valid=valid.shape[0],
                             d=d.shape[0], sigma=sigma.shape[0], theta=theta.shape[0],
                             x=x.shape[0], y=y.shape[0])
    for i in range(k):
        f = index[i]
        if f < 0 or f >= size:
            raise IndexError(f"index[{i}] = {f} is not a reading (0 … {size - 1})")
        if valid[f] and label[f] >= 0:
            m += 1
            if label[f] >= L:
                L = label[f] + 1
    if m == 0:
        return None
    # per line (np.bincount's sums, in scan order): members, Σd; then the flags
    # 0 doubt, 1 few and far
    counts_arr = np.zeros(L, dtype=np.intp)
    sums_arr = np.zeros((7, L))       # Σd, then the few far lines' Σx, Σy, Σuv, Σ(u²−v²),
    flags_arr = np.zeros((2, L), dtype=np.uint8)          # Σalong², Σσ⊥²
    doubt_arr = np.zeros(size, dtype=bool)
    loose_arr = np.zeros(size, dtype=bool)
    cdef idx_t[::1] total = counts_arr
    cdef double[:, ::1] S = sums_arr
    cdef unsigned char[:, ::1] F = flags_arr
    cdef unsigned char[::1] doubt = doubt_arr.view(np.uint8)
    cdef unsigned char[::1] loose = loose_arr.view(np.uint8)
    cdef const double[::1] ca, sa, cos_t, se
    cdef idx_t[::1] sel
    cdef double[::1] ts
    for i in range(k):
        f = index[i]
        if valid[f] and label[f] >= 0:
            total[label[f]] += 1
            S[0, label[f]] += d[f]
    for l in range(L):
        far = S[0, l] >= far_m * <double>total[l]
        F[0, l] = far and total[l] >= min_n and total[l] <= max_n
        F[1, l] = far and total[l] <= few_n
        any_few = any_few or F[1, l]
    for i in range(k):
        f = index[i]
        if valid[f] and label[f] >= 0:
            if F[0, label[f]]:
                doubt[f] = 1
                any_doubt = True
            if F[1, label[f]]:
                ms += 1
    if any_few and ask_loose:
        # lines.direction_se over the few far lines' members (the others' rows stay 0)
        sel_arr = np.empty(ms, dtype=np.intp)
        theta_sel = np.empty(ms)
        sel = sel_arr
        ts = theta_sel
        ms = 0
        for i in range(k):
            f = index[i]
            if valid[f] and label[f] >= 0 and F[1, label[f]]:
                sel[ms] = f
                ts[ms] = theta[f]
                ms += 1
                S[1, label[f]] += x[f]
                S[2, label[f]] += y[f]
        for l in range(L):
            if F[1, l]:       # (np.maximum(n, 1): a line of no such member keeps 0 / 1)
                S[1, l] = S[1, l] / <double>total[l]
                S[2, l] = S[2, l] / <double>total[l]
        for i in range(ms):
            f = sel[i]
            l = label[f]
            u = x[f] - S[1, l]
            v = y[f] - S[2, l]
            S[3, l] += u * v
            S[4, l] += u * u - v * v
        for l in range(L):
            S[3, l] = 2.0 * S[3, l]
        al = 0.5 * _arctan2(sums_arr[3], sums_arr[4])
        ca_arr = np.cos(al)
        sa_arr = np.sin(al)
        cos_arr = np.cos(theta_sel)
        ca, sa, cos_t = ca_arr, sa_arr, cos_arr
        for i in range(ms):
            f = sel[i]
            l = label[f]
            u = x[f] - S[1, l]
            v = y[f] - S[2, l]
            along = u * ca[l] + v * sa[l]
            S[5, l] += along * along
            u = sigma[f] * cos_t[i]
            S[6, l] += u * u
        for l in range(L):
            if not (S[5, l] != S[5, l] or S[5, l] >= 1e-12):    # np.maximum: NaN wins
                S[5, l] = 1e-12
            v = <double>(total[l] if F[1, l] else 1)
            S[6, l] = S[6, l] / v / S[5, l]
        se_arr = np.sqrt(sums_arr[6])
        se = se_arr
        for i in range(ms):
            f = sel[i]
            if se[label[f]] > se_max:
                loose[f] = 1
                any_loose = True
    if not (any_doubt or any_loose):
        return None
    return doubt_arr, loose_arr


def own_slope_reads(const double[::1] s, const double[::1] theta, const double[::1] slope,
                    const double[::1] se, const double[::1] sig_s, const double[::1] xp,
                    const double[::1] node_log_a, const double[::1] node_b, double max_inc,
                    double min_range, double sigma_floor):
    """``irring.estimation.profiles.own_slope_read`` (the statement) to the bit: readings
    (counts ``s``, σ_S/S ``sig_s``) read at their own profile's ``theta``, ``slope`` and its
    standard error ``se``: d at θ, σ (the noise at θ with half the spread of d over θ ± the
    slope's error, ``own_slope_sigma``'s) and whether they are placed. np.interp's log a, b
    on the nodes ``xp``, ``node_log_a``, ``node_b``; numpy's arctan, log and exp on this
    call's rows. Returns (d, σ, placed bool)."""
    cdef idx_t n = s.shape[0], i, j
    cdef double t, v, la, b
    if not (theta.shape[0] == slope.shape[0] == se.shape[0] == sig_s.shape[0] == n
            and node_log_a.shape[0] == node_b.shape[0] == xp.shape[0]):
        raise lengths_differ("own_slope_reads' arrays", s=n, theta=theta.shape[0],
                             slope=slope.shape[0], se=se.shape[0], sig_s=sig_s.shape[0],
                             xp=xp.shape[0], node_log_a=node_log_a.shape[0],
                             node_b=node_b.shape[0])
    if xp.shape[0] == 0:
        raise ValueError("own_slope_reads: the calibration has no nodes")
    cdef idx_t m = xp.shape[0]
    rows = np.empty((6, n))     # θ ± the error's bound angles, then log s, then d at θ, lo, hi
    placed_arr = np.zeros(n, dtype=bool)
    cdef double[:, ::1] R = rows
    cdef unsigned char[::1] placed = placed_arr.view(np.uint8)
    for i in range(n):
        t = fabs(slope[i])
        v = t - se[i]
        R[0, i] = v if (v >= 0.0 or v != v) else 0.0       # np.maximum: NaN wins
        R[1, i] = t + se[i]
        R[2, i] = s[i]
    np.arctan(rows[:2], out=rows[:2])
    np.log(rows[2], out=rows[2])
    for i in range(n):
        v = R[1, i]
        if not (v <= max_inc or v != v):                     # np.minimum: NaN wins
            R[1, i] = max_inc
        for j in range(3):
            v = fabs(theta[i] if j == 0 else R[j - 1, i])
            la = _np_interp(v, &xp[0], &node_log_a[0], m)
            b = _np_interp(v, &xp[0], &node_b[0], m)
            R[3 + j, i] = la + b * R[2, i]
    np.exp(rows[3:], out=rows[3:])
    sigma_arr = np.empty(n)
    cdef double[::1] sigma = sigma_arr
    for i in range(n):
        b = _np_interp(fabs(theta[i]), &xp[0], &node_b[0], m)
        v = fabs(b) * R[3, i] * sig_s[i]
        if not (v >= sigma_floor or v != v):
            v = sigma_floor
        sigma[i] = hypot(v, 0.5 * fabs(R[4, i] - R[5, i]))
        placed[i] = isfinite(R[3, i]) and R[3, i] >= min_range and isfinite(sigma[i])
    return rows[3].copy(), sigma_arr, placed_arr


def post_groups(const unsigned char[::1] reason, const unsigned char[::1] valid,
                const idx_t[::1] label, unsigned char unknown, const double[::1] counts,
                const double[::1] heading, const double[::1] ox, const double[::1] oy,
                idx_t n_sensors, double clear_counts, double la0, double b0, double link_m,
                idx_t min_sensors, idx_t run_max, cells, idx_t reach):
    """``irring.estimation.estimate_numpy.post_groups`` (the statement and the why): of the
    flat (S·N) readings, those on no line (``reason`` ``unknown``, or ``valid`` with
    ``label`` < 0) whose ``counts`` are at least
    ``clear_counts``, their θ = 0 end points (log and exp, cos and sin are numpy's, on this
    call's candidates), the groups chained within ``link_m`` (each labelled by its smallest
    member) and which groups hold ≥ 3 readings of ≥ ``min_sensors`` sensors, ≤ ``run_max``
    of each. ``cells``: ``far_lines.post_cells`` (the candidates by cell; two cells are
    compared within ``reach`` cells of each other). Returns None where no group qualifies,
    else (row, col, comp, groups) intp and (px, py) float, the candidates in flat order."""
    cdef idx_t size = counts.shape[0], m = 0, i, j, f, a, b, r, g, k, nk, top
    if not (reason.shape[0] == valid.shape[0] == label.shape[0] == heading.shape[0]
            == ox.shape[0] == oy.shape[0] == size and n_sensors >= 1 and size % n_sensors == 0):
        raise lengths_differ("per-reading arrays", reason=reason.shape[0],
                             valid=valid.shape[0], label=label.shape[0], counts=size,
                             heading=heading.shape[0], ox=ox.shape[0], oy=oy.shape[0])
    for f in range(size):
        if ((reason[f] == unknown or (valid[f] and label[f] < 0))
                and counts[f] >= clear_counts):
            m += 1
    if m < 3:
        return None
    flat_arr = np.empty(m, dtype=np.intp)
    cdef idx_t[::1] flat = flat_arr
    seen_arr = np.zeros(n_sensors, dtype=np.intp)
    cdef idx_t[::1] seen = seen_arr
    j = 0
    nk = 0
    for f in range(size):
        if ((reason[f] == unknown or (valid[f] and label[f] < 0))
                and counts[f] >= clear_counts):
            flat[j] = f
            j += 1
            if not seen[f % n_sensors]:
                seen[f % n_sensors] = 1
                nk += 1
    if nk < min_sensors:
        return None
    rows = np.empty((4, m))        # counts → their log → d0, heading → its cos, sin
    cdef double[:, ::1] R = rows
    for j in range(m):
        R[0, j] = counts[flat[j]]
        R[1, j] = heading[flat[j]]
    np.log(rows[0], out=rows[2])
    for j in range(m):
        R[2, j] = la0 + b0 * R[2, j]
    np.exp(rows[2], out=rows[2])
    cs = np.cos(rows[1])
    sn = np.sin(rows[1])
    cdef double[::1] C = cs, SN = sn
    pxy = np.empty((2, m))
    cdef double[:, ::1] P = pxy
    for j in range(m):
        P[0, j] = ox[flat[j]] + R[2, j] * C[j]
        P[1, j] = oy[flat[j]] + R[2, j] * SN[j]
    # connected groups (union-find, each group's root its smallest member) over the cells
    # of post_cells: a cell's candidates are all linked; two cells' are compared where
    # the cells lie within reach, they are not yet one group and not both crowded
    comp_arr = np.arange(m, dtype=np.intp)
    cdef idx_t[::1] comp = comp_arr
    if m <= run_max * n_sensors:    # no cell can be crowded: every pair, as the cells would
        order_np = start_np = np.zeros(1, dtype=np.intp)
        crowded_np, key_np, width = np.zeros(0, dtype=np.uint8), np.zeros(0, np.int64), 0
    else:
        order_np, start_np, crowded_np, key_np, width = cells(pxy[0], pxy[1], link_m,
                                                               run_max * n_sensors)
    cdef idx_t[::1] order = order_np, start = start_np
    cdef const unsigned char[::1] crowded = crowded_np
    cdef const long long[::1] key = key_np
    cdef idx_t n_cells = start.shape[0] - 1, ca, cb, lo, hi, mid, dx, dy
    cdef long long want, w = width
    cdef bint linked
    if m <= run_max * n_sensors:
        for i in range(m):
            for j in range(i + 1, m):
                if hypot(P[0, i] - P[0, j], P[1, i] - P[1, j]) < link_m:
                    a = i
                    while comp[a] != a:
                        a = comp[a]
                    b = j
                    while comp[b] != b:
                        b = comp[b]
                    if a < b:
                        comp[b] = a
                    elif b < a:
                        comp[a] = b
    for ca in range(n_cells):
        for i in range(start[ca] + 1, start[ca + 1]):   # in index order: the first is least
            comp[order[i]] = order[start[ca]]
    for ca in range(n_cells):
        for dx in range(reach + 1):
            for dy in range(-reach, reach + 1):
                if dx == 0 and dy <= 0:
                    continue
                want = key[ca] + dx * w + dy
                lo, hi = ca + 1, n_cells          # the cell of key ``want``, if any
                while lo < hi:
                    mid = (lo + hi) // 2
                    if key[mid] < want:
                        lo = mid + 1
                    else:
                        hi = mid
                cb = lo
                if cb >= n_cells or key[cb] != want or (crowded[ca] and crowded[cb]):
                    continue
                a = order[start[ca]]
                while comp[a] != a:
                    a = comp[a]
                b = order[start[cb]]
                while comp[b] != b:
                    b = comp[b]
                if a == b:
                    continue
                linked = False
                for i in range(start[ca], start[ca + 1]):
                    for j in range(start[cb], start[cb + 1]):
                        if hypot(P[0, order[i]] - P[0, order[j]],
                                 P[1, order[i]] - P[1, order[j]]) < link_m:
                            linked = True
                            break
                    if linked:
                        break
                if linked:
                    if a < b:
                        comp[b] = a
                    else:
                        comp[a] = b
    for i in range(m):        # members precede in index order: their root is final already
        comp[i] = comp[comp[i]]
    # per group: members, sensors and the most of one sensor (groups by counting sort; a
    # group of more than run_max × n_sensors cannot qualify and is not counted by sensor)
    bound_arr = np.zeros(m + 1, dtype=np.intp)
    cdef idx_t[::1] bound = bound_arr
    for i in range(m):
        bound[comp[i] + 1] += 1
    for i in range(m):
        bound[i + 1] += bound[i]
    member_arr = np.empty(m, dtype=np.intp)
    cdef idx_t[::1] member = member_arr
    fill_arr = bound_arr[:m].copy()
    cdef idx_t[::1] fill = fill_arr
    for i in range(m):
        member[fill[comp[i]]] = i
        fill[comp[i]] += 1
    each_arr = np.zeros(n_sensors, dtype=np.intp)
    cdef idx_t[::1] each = each_arr
    ok_arr = np.zeros(m, dtype=np.intp)
    cdef idx_t[::1] ok = ok_arr
    g = 0
    for r in range(m):
        a = bound[r + 1] - bound[r]
        if comp[r] != r or a < 3 or a > run_max * n_sensors:
            continue
        nk = 0
        top = 0
        for i in range(bound[r], bound[r + 1]):
            k = flat[member[i]] % n_sensors
            each[k] += 1
            nk += each[k] == 1
            if each[k] > top:
                top = each[k]
        for i in range(bound[r], bound[r + 1]):
            each[flat[member[i]] % n_sensors] = 0
        if nk >= min_sensors and top <= run_max:
            ok[g] = r
            g += 1
    if g == 0:
        return None
    return (flat_arr // n_sensors, flat_arr % n_sensors, comp_arr, ok_arr[:g].copy(),
            pxy[0], pxy[1])


cdef object _rank_of_rows(const idx_t[::1] order):
    """(S,) intp: each row's place in ``order`` (the S rows in step order); IndexError
    naming an entry of ``order`` that is no row."""
    cdef idx_t S = order.shape[0], q, r
    rank_arr = np.empty(S, dtype=np.intp)
    cdef idx_t[::1] rank = rank_arr
    for q in range(S):
        r = order[q]
        if r < 0 or r >= S:
            raise IndexError(f"order[{q}] = {r} is not a row (0 … {S - 1})")
        rank[r] = q
    return rank_arr


def silent_gaps(const idx_t[::1] index, const double[::1] counts, const idx_t[::1] order,
                const unsigned char[::1] reason, idx_t n_sensors, unsigned char missing,
                double dip):
    """``irring.estimation.members.silent_gaps`` (the statement and the why), exactly:
    ``index`` (k,) flat (S·N) readings in scan order, ``counts`` and ``reason`` flat (S·N),
    ``order`` (S,) the rows in step order; ``dip`` = SILENT_DIP_SIGMAS × σ of a count.
    Returns (k,) uint8: 1 where a reading follows its sensor's previous one across steps
    whose lowest count (``missing`` ones: none) lies ``dip`` below both of theirs."""
    cdef idx_t k = index.shape[0], size = counts.shape[0], S = order.shape[0], i, a, b, q, r
    cdef idx_t col
    cdef double low, v, ends
    if not (reason.shape[0] == size and n_sensors >= 1 and S * n_sensors == size):
        raise lengths_differ("silent_gaps' arrays", counts=size, reason=reason.shape[0],
                             steps_times_sensors=S * n_sensors)
    cut_arr = np.zeros(k, dtype=np.uint8)
    if k < 2:
        return cut_arr
    rank_arr = _rank_of_rows(order)
    cdef unsigned char[::1] cut = cut_arr
    cdef idx_t[::1] rank = rank_arr
    for i in range(k):
        if index[i] < 0 or index[i] >= size:
            raise IndexError(f"index[{i}] = {index[i]} is not a reading (0 … {size - 1})")
    for i in range(1, k):
        a = index[i - 1]
        b = index[i]
        col = b % n_sensors
        if a % n_sensors != col or rank[b // n_sensors] - rank[a // n_sensors] <= 1:
            continue
        low = INFINITY
        for q in range(rank[a // n_sensors] + 1, rank[b // n_sensors]):
            r = order[q] * n_sensors + col
            v = INFINITY if reason[r] == missing else counts[r]
            if v != v or low != low:        # np.minimum: a NaN wins
                low = NAN
            elif v < low:
                low = v
        ends = counts[a]
        if counts[b] < ends or counts[b] != counts[b]:
            ends = counts[b]
        cut[i] = low < ends - dip
    return cut_arr


# --------------------------------------------------------------------------- silent beams beside a return

def beside_a_return(const unsigned char[::1] reason, const unsigned char[::1] valid,
                    const double[::1] counts, const double[::1] d, const double[::1] theta,
                    const double[::1] heading, const idx_t[::1] label, bint has_label,
                    idx_t n_sensors, unsigned char no_return, unsigned char missing,
                    double full_scale, double level, bint falling, double la, double b,
                    double hide, double cos_hide, double limit):
    """``irring.estimation.silence.beside_a_return`` (the statement and the why), exactly
    (log and exp are numpy's, on this call's rows): flat (S·N) arrays; ``label`` read only
    with ``has_label``; ``level`` = the return level; (``la``, ``b``) = log a, b at the
    drop-out angle; ``hide`` = ``end_hide_angle``, ``cos_hide`` = math.cos of it,
    ``limit`` = π/2 − 1e-6. Returns (flat indices, bounds) of the NO_RETURN beams whose
    reach a reading beside them bounds, in row-major order."""
    cdef idx_t size = reason.shape[0], S, i, r, col, m = 0, q, f, o, w, slot
    cdef double c, gap, gamma, rr, stop, lo, hi, two_pi = 2.0 * M_PI
    cdef bint has, use, hides, known
    if not (valid.shape[0] == counts.shape[0] == d.shape[0] == theta.shape[0]
            == heading.shape[0] == size and n_sensors >= 1 and size % n_sensors == 0
            and (not has_label or label.shape[0] == size)):
        raise lengths_differ("beside_a_return's arrays", reason=size, valid=valid.shape[0],
                             counts=counts.shape[0], d=d.shape[0], theta=theta.shape[0],
                             heading=heading.shape[0], label=label.shape[0])
    S = size // n_sensors
    for f in range(size):
        if reason[f] == no_return:
            m += 1
    if m == 0:
        return np.zeros(0, dtype=np.intp), np.zeros(0)
    heard_arr = np.zeros(size, dtype=np.uint8)
    near_arr = np.empty(2 * size, dtype=np.intp)   # the nearest heard row at or before, after
    cdef unsigned char[::1] heard = heard_arr
    cdef idx_t[::1] near = near_arr
    for f in range(size):
        c = counts[f]
        if c > full_scale:       # np.minimum: a NaN stays
            c = full_scale
        heard[f] = valid[f] or (c >= level and reason[f] != no_return and reason[f] != missing)
    for col in range(n_sensors):
        o = -1
        for r in range(S):
            if heard[r * n_sensors + col]:
                o = r
            near[r * n_sensors + col] = o
        o = S
        for r in range(S - 1, -1, -1):
            if heard[r * n_sensors + col]:
                o = r
            near[size + r * n_sensors + col] = o
    # each silent beam (row-major), with the nearest heard reading before it, then after it
    beam_arr = np.empty(m, dtype=np.intp)
    there_arr = np.empty(2 * m, dtype=np.intp)
    has_arr = np.empty(2 * m, dtype=np.uint8)
    cc_arr = np.empty(2 * m)
    cdef idx_t[::1] beam = beam_arr, there = there_arr
    cdef unsigned char[::1] have = has_arr
    cdef double[::1] cc = cc_arr
    q = 0
    for f in range(size):
        if reason[f] != no_return:
            continue
        beam[q] = f
        r = f // n_sensors
        col = f - r * n_sensors
        for w in range(2):
            o = near[w * size + f]
            has = 0 <= o < S
            slot = w * m + q
            have[slot] = has
            there[slot] = (o if has else r) * n_sensors + col
            c = counts[there[slot]]
            if c > full_scale:
                c = full_scale
            cc[slot] = c if heard[there[slot]] else full_scale
        q += 1
    dist_arr = None
    cdef double[::1] dist
    if falling:    # cal.distance(counts, drop-out angle): exp(log a + b·log s), numpy's
        dist_arr = np.log(cc_arr)
        dist = dist_arr
        for q in range(2 * m):
            dist[q] = la + b * dist[q]
        np.exp(dist_arr, out=dist_arr)
    at_arr = np.empty(m, dtype=np.intp)
    bound_arr = np.empty(m)
    cdef idx_t[::1] at = at_arr
    cdef double[::1] bound = bound_arr
    cdef idx_t n_cut = 0
    for q in range(m):
        lo = INFINITY
        for w in range(2):
            slot = w * m + q
            o = there[slot]
            if falling:
                rr = dist[slot]
            else:
                rr = d[o] if valid[o] else NAN
            # where its θ is known (on a line, or θ > 0; NaN compares False) its d stands
            known = valid[o] and (theta[o] > 0 or (has_label and label[o] >= 0))
            if known:
                rr = d[o]
            use = heard[o] and isfinite(rr)
            gap = heading[o] - heading[beam[q]]
            gamma = fabs(gap - two_pi * nearbyint(gap / two_pi))
            hides = have[slot] and use and hide + gamma < limit
            stop = (rr if use else 0.0) * cos_hide / cos(hide + gamma if hides else 0.0)
            hi = stop if hides else INFINITY
            if w == 0:
                lo = hi
            elif hi != hi or lo != lo:     # np.minimum: a NaN wins
                lo = NAN
            elif hi < lo:
                lo = hi
        if isfinite(lo):
            at[n_cut] = beam[q]
            bound[n_cut] = lo
            n_cut += 1
    return at_arr[:n_cut].copy(), bound_arr[:n_cut].copy()


# --------------------------------------------------------------------------- traces (rejoin_traces)

def trace_pairs(const idx_t[::1] vi, const idx_t[::1] lab, const idx_t[::1] order,
                idx_t n_sensors, idx_t skip):
    """``irring.estimation.traces.TraceSteps.pairs`` (the statement), exactly: ``vi`` (k,)
    flat (S·N) readings, ``lab`` their lines (−1: none), ``order`` (S,) the rows in step
    order; ``skip`` = TRACE_SKIP. Returns (joined (k − 1,) uint8, reading, nbr)."""
    cdef idx_t k = vi.shape[0], S = order.shape[0], i, q, r, nb, w, n_pairs = 0, step, t
    if not (lab.shape[0] == k and n_sensors >= 1):
        raise lengths_differ("trace_pairs' readings", vi=k, lab=lab.shape[0])
    rank_arr = _rank_of_rows(order)
    cdef idx_t[::1] rank = rank_arr
    for i in range(k):
        if vi[i] < 0 or vi[i] >= S * n_sensors:
            raise IndexError(f"vi[{i}] = {vi[i]} is not a reading (0 … {S * n_sensors - 1})")
    joined_arr = np.zeros(max(k - 1, 0), dtype=np.uint8)
    cdef unsigned char[::1] joined = joined_arr
    for i in range(k - 1):
        joined[i] = (vi[i + 1] % n_sensors == vi[i] % n_sensors
                     and rank[vi[i + 1] // n_sensors] - rank[vi[i] // n_sensors] == 1)
    pairs_arr = np.empty((2, 2 * k), dtype=np.intp)
    cdef idx_t[:, ::1] P = pairs_arr
    for w in range(2):
        step = -1 if w == 0 else 1
        for i in range(k):
            if lab[i] < 0:
                continue
            # the link from i one step on: joined between the two
            nb = -1
            if step < 0 and i >= 1 and joined[i - 1]:
                nb = i - 1
            elif step > 0 and i + 1 < k and joined[i]:
                nb = i + 1
            for t in range(skip):
                if nb >= 0 and lab[nb] < 0:
                    if step < 0:
                        nb = nb - 1 if nb >= 1 and joined[nb - 1] else -1
                    else:
                        nb = nb + 1 if nb + 1 < k and joined[nb] else -1
            if nb >= 0:
                P[0, n_pairs] = i
                P[1, n_pairs] = nb
                n_pairs += 1
    return joined_arr, pairs_arr[0, :n_pairs].copy(), pairs_arr[1, :n_pairs].copy()


cdef inline bint _past_corner(double qx, double qy, double ox, double oy, idx_t b, idx_t c,
                              const double[::1] alpha, const double[::1] cx,
                              const double[::1] cy, const double* lo, const double* hi,
                              const double* mx, const double* my, double reach_m,
                              double reach_share, double min_split_m,
                              double sin_corner) noexcept nogil:
    """``traces._past_a_corner`` for one point (qx, qy) put on line b, against line c."""
    cdef double cab = cos(alpha[b]), sab = sin(alpha[b]), cac = cos(alpha[c]), sac = sin(alpha[c])
    cdef double wx = cx[c] - cx[b], wy = cy[c] - cy[b]
    cdef double crs = cab * sac - sab * cac
    cdef double tb = (wx * sac - wy * cac) / crs
    cdef double tc = (wx * sab - wy * cab) / crs
    cdef double reach = reach_share * hypot(cx[b] + tb * cab - ox, cy[b] + tb * sab - oy)
    cdef double side_b, side_q
    if reach < reach_m:          # np.maximum: a NaN stays
        reach = reach_m
    side_b = (my[b] - cy[c]) * cac - (mx[b] - cx[c]) * sac
    side_q = (qy - cy[c]) * cac - (qx - cx[c]) * sac
    return (fabs(crs) > sin_corner and tb >= lo[b] - reach and tb <= hi[b] + reach
            and tc >= lo[c] - reach and tc <= hi[c] + reach and side_b * side_q < 0
            and fabs(side_q) > min_split_m)


def trace_round(const idx_t[::1] lab, const unsigned char[::1] moved,
                const unsigned char[::1] joined, const idx_t[::1] reading,
                const idx_t[::1] nbr, const unsigned char[::1] good, const idx_t[::1] lost,
                const double[::1] px, const double[::1] py, const double[::1] ox,
                const double[::1] oy, const double[::1] alpha, const double[::1] cx,
                const double[::1] cy, double reach_m, double reach_share, double min_split_m,
                double loose, double loose_min, double sin_corner):
    """``irring.estimation.traces.TraceSteps.round`` (the statement and the why), exactly:
    per valid reading (k,) ``lab``, ``moved``, end points, emitters; ``joined`` (k − 1,);
    the pairs ``reading``, ``nbr``; per line (L,) ``good``, ``lost``, ``alpha``, ``cx``,
    ``cy``; ``loose`` = TRACE_LOOSE, ``loose_min`` = TRACE_LOOSE_MIN_M, ``sin_corner`` = sin
    TRACE_CORNER_RAD. Returns None (no frontier) or (i, j, a, b, run_lo, run_hi, n_mem,
    mx, my, lo, hi, absorb, cross), absorb and cross bool."""
    cdef idx_t k = lab.shape[0], L = alpha.shape[0], n_p = reading.shape[0], p, m = 0
    cdef idx_t i, g, a, b, start
    cdef double ca, sa, along, across, v, t
    cdef bint f
    if not (moved.shape[0] == px.shape[0] == py.shape[0] == ox.shape[0] == oy.shape[0] == k
            and joined.shape[0] == max(k - 1, 0) and nbr.shape[0] == n_p):
        raise lengths_differ("trace_round's readings", lab=k, moved=moved.shape[0],
                             px=px.shape[0], py=py.shape[0], ox=ox.shape[0], oy=oy.shape[0],
                             joined_plus_1=joined.shape[0] + 1, reading=n_p, nbr=nbr.shape[0])
    if not (good.shape[0] == lost.shape[0] == cx.shape[0] == cy.shape[0] == L):
        raise lengths_differ("trace_round's lines", alpha=L, good=good.shape[0],
                             lost=lost.shape[0], cx=cx.shape[0], cy=cy.shape[0])
    for i in range(k):
        if lab[i] >= L:
            raise IndexError(f"lab[{i}] = {lab[i]} is not a line (−1 … {L - 1})")
    for p in range(n_p):
        if not (0 <= reading[p] < k and 0 <= nbr[p] < k):
            raise IndexError(f"pair {p} ({reading[p]}, {nbr[p]}) is not of readings 0 … {k - 1}")
    front_arr = np.empty((4, n_p), dtype=np.intp)
    cdef idx_t[:, ::1] F = front_arr
    for p in range(n_p):
        a = lab[reading[p]]
        b = lab[nbr[p]]
        if moved[reading[p]] or b < 0 or b == a or not good[b]:
            continue
        if a < 0:    # (pairs are of members, and a member moves only onto a line)
            raise ValueError(f"pair {p}: reading {reading[p]} is on no line")
        F[0, m] = reading[p]
        F[1, m] = nbr[p]
        F[2, m] = a
        F[3, m] = b
        m += 1
    if m == 0:
        return None
    runs_arr = np.empty((2, k), dtype=np.intp)
    cdef idx_t[:, ::1] R = runs_arr
    start = 0
    for i in range(k):
        if i > 0 and (not joined[i - 1] or lab[i] != lab[i - 1] or moved[i] != moved[i - 1]):
            start = i
        R[0, i] = start
    start = k - 1
    for i in range(k - 1, -1, -1):
        if i < k - 1 and R[0, i + 1] == i + 1:
            start = i
        R[1, i] = start
    n_mem_arr = np.zeros(L, dtype=np.intp)
    stats_arr = np.zeros((5, L))      # mx, my, lo, hi, rms
    cdef idx_t[::1] n_mem = n_mem_arr
    cdef double[:, ::1] T = stats_arr
    cdef double* mx = &T[0, 0] if L else NULL
    cdef double* my = mx + L
    cdef double* lo = mx + 2 * L
    cdef double* hi = mx + 3 * L
    cdef double* rms = mx + 4 * L
    for g in range(L):
        lo[g] = INFINITY
        hi[g] = -INFINITY
    for i in range(k):
        g = lab[i]
        if g < 0:
            continue
        n_mem[g] += 1
        mx[g] += px[i]
        my[g] += py[i]
    for i in range(k):
        g = lab[i]
        if g < 0:
            continue
        ca = cos(alpha[g])
        sa = sin(alpha[g])
        along = (px[i] - cx[g]) * ca + (py[i] - cy[g]) * sa
        across = (py[i] - cy[g]) * ca - (px[i] - cx[g]) * sa
        if along != along or lo[g] != lo[g]:     # np.minimum / np.maximum: a NaN wins
            lo[g] = NAN
        elif along < lo[g]:
            lo[g] = along
        if along != along or hi[g] != hi[g]:
            hi[g] = NAN
        elif along > hi[g]:
            hi[g] = along
        rms[g] += across * across
    for g in range(L):
        t = n_mem[g] if n_mem[g] > 1 else 1
        mx[g] = mx[g] / t
        my[g] = my[g] / t
        rms[g] = sqrt(rms[g] / t)
    flags_arr = np.zeros((2, m), dtype=np.uint8)
    cdef unsigned char[:, ::1] B = flags_arr
    for p in range(m):
        i = F[0, p]
        a = F[2, p]
        b = F[3, p]
        f = not (lost[b] > n_mem[b])
        if not f:
            continue
        v = loose * rms[b]
        if v < loose_min:        # np.maximum: a NaN stays
            v = loose_min
        B[0, p] = (lost[a] > n_mem[a]) or (n_mem[a] < n_mem[b] and rms[a] > v
                                           and fabs(sin(alpha[a] - alpha[b])) <= sin_corner)
        B[1, p] = _past_corner(px[i], py[i], ox[i], oy[i], a, b, alpha, cx, cy, lo, hi, mx,
                               my, reach_m, reach_share, min_split_m, sin_corner)
    return (front_arr[0, :m].copy(), front_arr[1, :m].copy(), front_arr[2, :m].copy(),
            front_arr[3, :m].copy(), runs_arr[0], runs_arr[1], n_mem_arr, stats_arr[0],
            stats_arr[1], stats_arr[2], stats_arr[3], flags_arr[0].view(bool),
            flags_arr[1].view(bool))


def trace_moves(const unsigned char[::1] ask, const idx_t[::1] i_in, const idx_t[::1] j_in,
                const idx_t[::1] a_in, const idx_t[::1] b_in, const idx_t[::1] run_lo,
                const idx_t[::1] run_hi, const double[::1] kx, const double[::1] ky,
                const double[::1] counts, const double[::1] h, const double[::1] ox,
                const double[::1] oy, const double[::1] alpha, const double[::1] cx,
                const double[::1] cy, const double[::1] lo, const double[::1] hi,
                const double[::1] mx, const double[::1] my, const idx_t[::1] n_mem,
                const unsigned char[::1] good, xp, node_log_a, node_b, double sigma_counts,
                double max_inc, double min_range, double max_range, double min_split,
                double adopt, double reach_m, double reach_share, double sin_corner,
                double on_sigmas, double sigma_floor, idx_t max_rounds, idx_t min_points,
                bint to_corner):
    """``irring.estimation.traces._trace_moves`` (the statement and the why), exactly:
    arccos, the curve's interpolation (np.interp over ``xp``, ``node_log_a``, ``node_b``:
    the calibration's nodes, as ``log_ab``), log and exp are numpy's, on this call's rows;
    the rest the same operations per element. Returns None or (readings, targets, d, θ, σ)."""
    cdef idx_t n_in = ask.shape[0], k = kx.shape[0], L = alpha.shape[0]
    cdef idx_t P = 0, T = 0, p, t, q, e, r, c, n_c = 0, w
    cdef double x, dd, sg, qx, qy, ca, sa, first, last, tx, acc_lo, acc_hi, glo, ghi
    cdef double u, perp, thr
    cdef bint ok, any_ok = False
    if not (i_in.shape[0] == j_in.shape[0] == a_in.shape[0] == b_in.shape[0] == n_in):
        raise lengths_differ("trace_moves' pairs", ask=n_in, i=i_in.shape[0], j=j_in.shape[0],
                             a=a_in.shape[0], b=b_in.shape[0])
    if not (ky.shape[0] == counts.shape[0] == h.shape[0] == ox.shape[0] == oy.shape[0]
            == run_lo.shape[0] == run_hi.shape[0] == k):
        raise lengths_differ("trace_moves' readings", kx=k, ky=ky.shape[0],
                             counts=counts.shape[0], h=h.shape[0], ox=ox.shape[0],
                             oy=oy.shape[0], run_lo=run_lo.shape[0], run_hi=run_hi.shape[0])
    if not (cx.shape[0] == cy.shape[0] == lo.shape[0] == hi.shape[0] == mx.shape[0]
            == my.shape[0] == n_mem.shape[0] == good.shape[0] == L):
        raise lengths_differ("trace_moves' lines", alpha=L, cx=cx.shape[0], cy=cy.shape[0],
                             lo=lo.shape[0], hi=hi.shape[0], mx=mx.shape[0], my=my.shape[0],
                             n_mem=n_mem.shape[0], good=good.shape[0])
    for q in range(n_in):
        if ask[q]:
            if not (0 <= i_in[q] < k and 0 <= a_in[q] < L and 0 <= b_in[q] < L
                    and 0 <= run_lo[i_in[q]] <= i_in[q] <= run_hi[i_in[q]] < k):
                raise IndexError(f"pair {q}: reading {i_in[q]} (of {k}), lines {a_in[q]}, "
                                 f"{b_in[q]} (of {L}) or its run is out of range")
            P += 1
    if P == 0:
        return None
    pairs_arr = np.empty((5, P), dtype=np.intp)    # i, a, b, step, span
    cdef idx_t[:, ::1] A = pairs_arr
    p = 0
    for q in range(n_in):
        if ask[q]:
            A[0, p] = i_in[q]
            A[1, p] = a_in[q]
            A[2, p] = b_in[q]
            A[3, p] = 1 if i_in[q] > j_in[q] else -1
            A[4, p] = (run_hi[i_in[q]] - i_in[q] if A[3, p] > 0 else i_in[q] - run_lo[i_in[q]]) + 1
            if A[4, p] > T:
                T = A[4, p]
            p += 1
    if T > max_rounds:
        T = max_rounds
    # the runs, outward from each i (P, T): where past its run, i itself (as the statement)
    grid_i = np.empty(P * T, dtype=np.intp)
    grid_f = np.empty((3, P * T))     # min(|sin(h − α_b)|, 1); counts; then log a + b·log s
    cdef idx_t[::1] E = grid_i
    cdef double[:, ::1] G = grid_f
    for p in range(P):
        for t in range(T):
            q = p * T + t
            e = A[0, p] + A[3, p] * t if t < A[4, p] else A[0, p]
            E[q] = e
            x = fabs(sin(h[e] - alpha[A[2, p]]))
            if x > 1.0:              # np.minimum: a NaN stays
                x = 1.0
            G[0, q] = x
            G[1, q] = counts[e]
    theta_arr = np.arccos(grid_f[0])
    la_arr = np.interp(theta_arr, xp, node_log_a)
    bexp_arr = np.interp(theta_arr, xp, node_b)
    d_arr = np.log(grid_f[1])
    cdef double[::1] TH = theta_arr, LA = la_arr, BE = bexp_arr, D = d_arr
    for q in range(P * T):
        D[q] = LA[q] + BE[q] * D[q]
    np.exp(d_arr, out=d_arr)
    out_f = np.empty((5, P * T))       # σ, x, y, perp / thr, ok
    cdef double[:, ::1] O = out_f
    ok_arr = np.zeros(P * T, dtype=np.uint8)
    cdef unsigned char[::1] OK = ok_arr
    for p in range(P):
        b = A[2, p]
        ca = cos(alpha[b])
        sa = sin(alpha[b])
        first = lo[b]
        last = hi[b]
        if to_corner:    # across a corner the target runs on to it
            c = A[1, p]
            tx = (((cx[c] - cx[b]) * sin(alpha[c]) - (cy[c] - cy[b]) * cos(alpha[c]))
                  / (ca * sin(alpha[c]) - sa * cos(alpha[c])))
            first = fmin(first, tx)
            last = fmax(last, tx)
        acc_lo = INFINITY
        acc_hi = -INFINITY
        for t in range(T):
            q = p * T + t
            e = E[q]
            dd = D[q]
            sg = fabs(BE[q]) * dd * sigma_counts / G[1, q]
            if sg < sigma_floor:     # np.maximum: a NaN stays
                sg = sigma_floor
            qx = ox[e] + dd * cos(h[e])
            qy = oy[e] + dd * sin(h[e])
            perp = fabs((qy - cy[b]) * ca - (qx - cx[b]) * sa)
            u = (qx - cx[b]) * ca + (qy - cy[b]) * sa
            thr = on_sigmas * sg
            if thr < min_split:
                thr = min_split
            # the extent grows by the run's readings before each (NaN wins, as np.minimum)
            glo = NAN if first != first or acc_lo != acc_lo else (first if first < acc_lo
                                                                  else acc_lo)
            ghi = NAN if last != last or acc_hi != acc_hi else (last if last > acc_hi
                                                               else acc_hi)
            ok = (t < A[4, p] and TH[q] <= max_inc and isfinite(dd) and dd >= min_range
                  and dd <= max_range and perp <= thr and u >= glo - adopt
                  and u <= ghi + adopt)
            # a run moves only as far as each of it lies on b
            OK[q] = ok and (t == 0 or OK[q - 1])
            if u != u or acc_lo != acc_lo:
                acc_lo = NAN
            elif u < acc_lo:
                acc_lo = u
            if u != u or acc_hi != acc_hi:
                acc_hi = NAN
            elif u > acc_hi:
                acc_hi = u
            O[0, q] = sg
            O[1, q] = qx
            O[2, q] = qy
            O[3, q] = perp / thr
            any_ok = any_ok or OK[q]
    if not any_ok:
        return None
    corners_arr = np.empty(L, dtype=np.intp)
    cdef idx_t[::1] corners = corners_arr
    for c in range(L):
        if good[c] and n_mem[c] >= min_points:
            corners[n_c] = c
            n_c += 1
    cdef const double* plo = &lo[0]
    cdef const double* phi = &hi[0]
    cdef const double* pmx = &mx[0]
    cdef const double* pmy = &my[0]
    for p in range(P):
        for t in range(T):
            q = p * T + t
            if not OK[q]:
                break
            e = E[q]
            if to_corner and not _past_corner(kx[e], ky[e], ox[e], oy[e], A[1, p], A[2, p],
                                              alpha, cx, cy, plo, phi, pmx, pmy, reach_m,
                                              reach_share, min_split, sin_corner):
                OK[q] = 0
                break
            for w in range(n_c):
                if _past_corner(O[1, q], O[2, q], ox[e], oy[e], A[2, p], corners[w], alpha,
                                cx, cy, plo, phi, pmx, pmy, reach_m, reach_share, min_split,
                                sin_corner):
                    OK[q] = 0
                    break
            if not OK[q]:
                break
        # (as far as each of the run lies on b: the rest of the run stays)
        for t in range(t + 1, T):
            OK[p * T + t] = 0
    # a reading two runs take: the target it lies closer to (the first such, on a tie)
    best_arr = np.full(k, -1, dtype=np.intp)
    cdef idx_t[::1] best = best_arr
    cdef idx_t n_out = 0
    for q in range(P * T):
        if OK[q]:
            r = E[q]
            if best[r] < 0:
                best[r] = q
                n_out += 1
            elif O[3, q] < O[3, best[r]]:
                best[r] = q
    if n_out == 0:
        return None
    at_arr = np.empty((2, n_out), dtype=np.intp)
    res_arr = np.empty((3, n_out))
    cdef idx_t[:, ::1] AT = at_arr
    cdef double[:, ::1] RES = res_arr
    w = 0
    for r in range(k):
        q = best[r]
        if q < 0:
            continue
        AT[0, w] = r
        AT[1, w] = A[2, q // T]
        RES[0, w] = D[q]
        RES[1, w] = TH[q]
        RES[2, w] = O[0, q]
        w += 1
    return at_arr[0], at_arr[1], res_arr[0], res_arr[1], res_arr[2]


# --------------------------------------------------------------------------- counts against lines

def counts_misfit_any(const idx_t[::1] vi, const idx_t[::1] label, const double[::1] heading,
                      const double[::1] origin_x, const double[::1] origin_y,
                      const double[::1] counts, const double[::1] alpha,
                      const double[::1] cx, const double[::1] cy, double la0, double b0,
                      double sigma_counts, double floor_m, xp, node_log_a, node_b,
                      double cos_max_inc, idx_t min_members, double single, double z_min):
    """``irring.estimation.counts._counts_asked(...) is not None`` (the statement; the why:
    ``counts_contradicted``): some line asked misfits its members' counts by ``z_min``
    normal σ before the sweep's noise scale and the refit, exactly (log, exp,
    arccos, the curve's interpolation (np.interp over ``xp``, ``node_log_a``, ``node_b``)
    and cbrt numpy's on this call's rows). ``vi`` (k,): the valid readings, flat (S·N)
    indices; ``label``, ``heading``, ``origin_x``, ``origin_y``, ``counts`` flat (S·N);
    (``la0``, ``b0``): log a, b at θ = 0. False: it answers no line."""
    cdef idx_t K = vi.shape[0], size = label.shape[0], L = alpha.shape[0], i, f, g, m = 0, q
    cdef double hh, a, nx, ny, along, x, e, r, s
    cdef bint any_asked = False
    if not (heading.shape[0] == origin_x.shape[0] == origin_y.shape[0] == counts.shape[0]
            == size and cx.shape[0] == cy.shape[0] == L):
        raise lengths_differ("counts_misfit_any's arrays", label=size, heading=heading.shape[0],
                             origin_x=origin_x.shape[0], origin_y=origin_y.shape[0],
                             counts=counts.shape[0], alpha=L, cx=cx.shape[0], cy=cy.shape[0])
    for i in range(K):
        f = vi[i]
        if f < 0 or f >= size:
            raise IndexError(f"vi[{i}] = {f} is not a reading (0 … {size - 1})")
        if label[f] >= L:
            raise IndexError(f"label[{f}] = {label[f]} is not a line (−1 … {L - 1})")
    if L == 0:
        return False
    per_line = np.zeros((5, L))      # members, kept, unmet, χ², c
    cdef double[:, ::1] PL = per_line
    for i in range(K):
        g = label[vi[i]]
        if g >= 0:
            PL[0, g] += 1.0
    # the members of lines of min_members or more, in vi's order
    at_arr = np.empty(K, dtype=np.intp)
    cdef idx_t[::1] at = at_arr
    for i in range(K):
        g = label[vi[i]]
        if g >= 0 and PL[0, g] >= min_members:
            at[m] = vi[i]
            m += 1
    if m == 0:
        return False
    for g in range(L):
        PL[4, g] = -sin(alpha[g]) * cx[g] + cos(alpha[g]) * cy[g]
    rows = np.empty((6, m))           # s, log s → d0, along, t → log t, θ, expect
    cdef double[:, ::1] W = rows
    for q in range(m):
        W[0, q] = counts[at[q]]
    np.log(rows[0], out=rows[1])
    for q in range(m):
        W[1, q] = la0 + b0 * W[1, q]
    np.exp(rows[1], out=rows[1])                   # d0 = cal.distance(s, 0)
    for q in range(m):
        f = at[q]
        g = label[f]
        hh = heading[f]
        a = alpha[g]
        nx = -sin(a)
        ny = cos(a)
        along = cos(hh) * nx + sin(hh) * ny
        W[2, q] = along
        W[3, q] = (PL[4, g] - origin_x[f] * nx - origin_y[f] * ny) / along
        x = fabs(along)
        if x > 1.0:              # np.minimum: a NaN stays
            x = 1.0
        W[4, q] = x
    np.arccos(rows[4], out=rows[4])
    la_arr = np.interp(rows[4], xp, node_log_a)
    bb_arr = np.interp(rows[4], xp, node_b)
    cdef double[::1] LA = la_arr, BB = bb_arr
    np.log(rows[3], out=rows[5])
    for q in range(m):
        W[5, q] = (W[5, q] - LA[q]) / BB[q]
    np.exp(rows[5], out=rows[5])                   # cal.counts(t, θ)
    for q in range(m):
        f = at[q]
        g = label[f]
        s = W[0, q]
        met = W[3, q] > 0 and fabs(W[2, q]) > cos_max_inc and isfinite(W[5, q])
        e = W[5, q] if met else 0.0
        x = s / (fabs(b0) * W[1, q])
        if x > 1.7976931348623157e308:     # np.minimum(x, max float): a NaN stays
            x = 1.7976931348623157e308
        x = fmax(sigma_counts, x * floor_m)
        r = (s - e) / x
        if not met:
            PL[2, g] += 1.0
        if met and fabs(r) < single:
            PL[1, g] += 1.0
            PL[3, g] += r * r
        else:
            PL[3, g] += 0.0
    # asked: enough members kept, every beam meeting its line; the normal deviate of χ²
    z_arr = np.empty(L)
    dof_arr = np.empty(L)
    cdef double[::1] Z = z_arr, DOF = dof_arr
    for g in range(L):
        DOF[g] = PL[1, g] - 2.0 if PL[1, g] - 2.0 > 1.0 else 1.0
        Z[g] = PL[3, g] / DOF[g]
    np.cbrt(z_arr, out=z_arr)
    for g in range(L):
        if PL[1, g] >= min_members and not PL[2, g] > 0:
            x = 2.0 / (9.0 * DOF[g])
            if (Z[g] - (1.0 - x)) / sqrt(x) >= z_min:
                return True
    return False


# --------------------------------------------------------------------------- curved walls

cdef bint _solve3(double* m, double* r) noexcept nogil:
    """m (3×3, row-major) x = r by Gaussian elimination with partial pivoting (LAPACK's
    dgesv's LU), in place: x in r. False on a zero pivot (numpy raises there)."""
    cdef int i, j, k, p
    cdef double t, f
    for k in range(3):
        p = k
        for i in range(k + 1, 3):
            if fabs(m[3 * i + k]) > fabs(m[3 * p + k]):
                p = i
        if m[3 * p + k] == 0.0:
            return False
        if p != k:
            for j in range(3):
                t = m[3 * k + j]
                m[3 * k + j] = m[3 * p + j]
                m[3 * p + j] = t
            t = r[k]
            r[k] = r[p]
            r[p] = t
        for i in range(k + 1, 3):
            f = m[3 * i + k] / m[3 * k + k]
            for j in range(k, 3):
                m[3 * i + j] = m[3 * i + j] - f * m[3 * k + j]
            r[i] = r[i] - f * r[k]
    for k in range(2, -1, -1):
        t = r[k]
        for j in range(k + 1, 3):
            t = t - m[3 * k + j] * r[j]
        r[k] = t / m[3 * k + k]
    return True


def bow_pre_f(const idx_t[::1] label, const unsigned char[::1] valid,
              const double[::1] origin_x, const double[::1] origin_y,
              const double[::1] heading, const double[::1] counts, const double[::1] d,
              const double[::1] theta, double sigma_counts, double floor_m,
              const double[::1] xp, const double[::1] node_log_a, const double[::1] node_b,
              idx_t min_members):
    """``irring.estimation.bends.bowed_lines``' pre-gate (its numpy statement:
    ``_bow_asked``): for each line of ``min_members`` valid members or more, in label
    order, the F by which a weighted parabola through its members as they lie (in the
    frame of their TLS line) beats that line, and the scale of its rounding error
    (Σ w·n² over the F's denominator). Its own sums and 3×3 solve, libm's trig: F within
    a tolerance of numpy's, not bit for bit (``BOW_PRE_TOL``); +inf where the fit is
    singular or anything is not finite. Arrays flat (S·N); ``label`` −1 on no line."""
    cdef idx_t size = label.shape[0], i, f, k, gi, n_g = 0, L = 0, m = 0
    cdef idx_t n_nodes = xp.shape[0]
    cdef double inv_dx = 0.0, la, b, h, ex, ey, x, y, u, v, ux, uy, en, noise, wt, s, nn
    cdef double wk, r0, den, dof, mat[9]
    cdef double rhs[3]
    if not (valid.shape[0] == origin_x.shape[0] == origin_y.shape[0] == heading.shape[0]
            == counts.shape[0] == d.shape[0] == theta.shape[0] == size
            and node_log_a.shape[0] == node_b.shape[0] == n_nodes):
        raise lengths_differ("bow_pre_f's arrays", label=size, valid=valid.shape[0],
                             origin_x=origin_x.shape[0], origin_y=origin_y.shape[0],
                             heading=heading.shape[0], counts=counts.shape[0], d=d.shape[0],
                             theta=theta.shape[0], xp=n_nodes,
                             node_log_a=node_log_a.shape[0], node_b=node_b.shape[0])
    if n_nodes == 0:
        raise ValueError("bow_pre_f: the calibration has no nodes")
    if n_nodes > 1 and xp[n_nodes - 1] > xp[0]:
        inv_dx = (n_nodes - 1) / (xp[n_nodes - 1] - xp[0])
    for f in range(size):
        if valid[f] and label[f] >= L:
            L = label[f] + 1
    members_arr = np.zeros(L, dtype=np.intp)
    rank_arr = np.full(L, -1, dtype=np.intp)
    cdef idx_t[::1] members = members_arr, rank = rank_arr
    for f in range(size):
        if valid[f] and label[f] >= 0:
            members[label[f]] += 1
    for k in range(L):
        if members[k] >= min_members:
            rank[k] = n_g
            n_g += 1
            m += members[k]
    out = np.zeros((2, n_g))         # F, its error's scale
    if n_g == 0:
        return out[0], out[1]
    # per line: members, Σx, Σy → centre, Σuv, Σ(u²−v²), Σw·s^0..4, Σw·n·s^0..2, Σw·n², χ²
    grp_arr = np.zeros((15, n_g))
    row_arr = np.empty((6, m))       # x → u, y → v, cos h, sin h, σ, s
    at_arr = np.empty(m, dtype=np.intp)
    cdef double[:, ::1] G = grp_arr, R = row_arr
    cdef idx_t[::1] at = at_arr
    bad_arr = np.zeros(n_g, dtype=np.uint8)
    cdef unsigned char[::1] bad = bad_arr
    i = 0
    for f in range(size):
        if valid[f] and label[f] >= 0 and rank[label[f]] >= 0:
            gi = rank[label[f]]
            at[i] = gi
            h = heading[f]
            ex = cos(h)
            ey = sin(h)
            x = origin_x[f] + d[f] * ex
            y = origin_y[f] + d[f] * ey
            R[0, i] = x
            R[1, i] = y
            R[2, i] = ex
            R[3, i] = ey
            b = NAN
            if isfinite(theta[f]):
                _interp_ab(fabs(theta[f]), xp, node_log_a, node_b, inv_dx, &la, &b)
            noise = fabs(b) * d[f] * (sigma_counts / counts[f])
            if not isfinite(noise):
                bad[gi] = 1
            R[4, i] = fmax(noise, floor_m)
            G[0, gi] += 1.0
            G[1, gi] += x
            G[2, gi] += y
            i += 1
    for gi in range(n_g):
        G[1, gi] = G[1, gi] / G[0, gi]
        G[2, gi] = G[2, gi] / G[0, gi]
    for i in range(m):
        gi = at[i]
        u = R[0, i] - G[1, gi]
        v = R[1, i] - G[2, gi]
        R[0, i] = u
        R[1, i] = v
        G[3, gi] += u * v
        G[4, gi] += u * u - v * v
    for gi in range(n_g):
        G[3, gi] = 0.5 * atan2(2.0 * G[3, gi], G[4, gi])       # the line's direction
    for i in range(m):
        gi = at[i]
        ux = cos(G[3, gi])
        uy = sin(G[3, gi])
        u = R[0, i]
        v = R[1, i]
        en = -R[2, i] * uy + R[3, i] * ux
        noise = R[4, i] * fabs(en)
        if not isfinite(noise):
            bad[gi] = 1
        noise = fmax(noise, floor_m)
        wt = 1.0 / (noise * noise)
        s = u * ux + v * uy
        nn = -u * uy + v * ux
        R[4, i] = wt
        R[5, i] = s
        R[1, i] = nn
        wk = wt
        for k in range(5):
            G[5 + k, gi] += wk
            if k < 3:
                G[10 + k, gi] += wk * nn
            wk = wk * s
        G[13, gi] += wt * nn * nn
    coef_arr = np.empty((n_g, 3))
    cdef double[:, ::1] C = coef_arr
    cdef unsigned char[::1] ok
    ok_arr = np.ones(n_g, dtype=np.uint8)
    ok = ok_arr
    for gi in range(n_g):
        for i in range(3):
            for k in range(3):
                mat[3 * i + k] = G[5 + i + k, gi]
            mat[4 * i] += 1e-12
            rhs[i] = G[10 + i, gi]
        ok[gi] = _solve3(mat, rhs)
        for i in range(3):
            C[gi, i] = rhs[i]
    for i in range(m):
        gi = at[i]
        s = R[5, i]
        r0 = R[1, i] - (C[gi, 0] + (C[gi, 1] + C[gi, 2] * s) * s)
        G[14, gi] += R[4, i] * r0 * r0
    cdef double[:, ::1] O = out
    for gi in range(n_g):
        dof = G[0, gi] - 3.0
        den = fmax(G[14, gi] / (dof if dof > 1.0 else 1.0), 1.0)
        O[0, gi] = (G[13, gi] - G[14, gi]) / den
        O[1, gi] = G[13, gi] / den
        if bad[gi] or not (ok[gi] and isfinite(O[0, gi]) and isfinite(O[1, gi])):
            O[0, gi] = INFINITY
            O[1, gi] = INFINITY
    return out[0], out[1]


cdef struct _Along:
    double s        # where a member lies along its line
    idx_t i         # its place among the line's members in flat order (ties: numpy's)


cdef inline bint _along_lt(const _Along* a, const _Along* b) noexcept nogil:
    """a's s before b's in numpy's sort: ascending, NaN last."""
    return a.s < b.s or (a.s == a.s and b.s != b.s)


cdef void _sort_along(_Along* a, _Along* tmp, idx_t n) noexcept nogil:
    """Sort a[0 … n − 1] by s as numpy's stable sort does (ties keep their order): runs of
    8 by insertion, then merged bottom-up (a line seen by several sensors in turn comes in
    as their runs interleaved)."""
    cdef idx_t lo, hi, i, j, k, mid, width = 8
    cdef _Along x
    cdef _Along* src = a
    cdef _Along* dst = tmp
    cdef _Along* swap
    lo = 0
    while lo < n:
        hi = lo + width if lo + width < n else n
        for i in range(lo + 1, hi):
            x = a[i]
            j = i
            while j > lo and _along_lt(&x, &a[j - 1]):
                a[j] = a[j - 1]
                j -= 1
            a[j] = x
        lo = hi
    while width < n:
        lo = 0
        while lo < n:
            mid = lo + width if lo + width < n else n
            hi = lo + 2 * width if lo + 2 * width < n else n
            i, j, k = lo, mid, lo
            while i < mid and j < hi:
                if _along_lt(&src[j], &src[i]):
                    dst[k] = src[j]
                    j += 1
                else:
                    dst[k] = src[i]
                    i += 1
                k += 1
            while i < mid:
                dst[k] = src[i]
                i += 1
                k += 1
            while j < hi:
                dst[k] = src[j]
                j += 1
                k += 1
            lo = hi
        swap = src
        src = dst
        dst = swap
        width *= 2
    if src != a:
        for i in range(n):
            a[i] = src[i]


cdef inline void _facet_fit(const double* q, idx_t m1, idx_t a, idx_t b, double* chi,
                            double* slope) noexcept nogil:
    """``_facet_asked``'s fit of sorted members a … b − 1 from the prefix sums ``q`` (six
    rows of m1: w, w·s, w·s², w·r, w·s·r, w·r²), its operations in numpy's order."""
    cdef double W = q[b] - q[a], S = q[m1 + b] - q[m1 + a], S2 = q[2 * m1 + b] - q[2 * m1 + a]
    cdef double R = q[3 * m1 + b] - q[3 * m1 + a], SR = q[4 * m1 + b] - q[4 * m1 + a]
    cdef double R2 = q[5 * m1 + b] - q[5 * m1 + a]
    cdef double sss = S2 - S * S / W, ssr = SR - S * R / W
    cdef double m = ssr / sss
    cdef double c = R2 - R * R / W - ssr * m
    chi[0] = c if (c > 0.0 or c != c) else 0.0       # np.maximum(c, 0): NaN stays
    slope[0] = m


def facet_pre(const idx_t[::1] label, const unsigned char[::1] valid,
              const double[::1] d_before, const double[::1] d_after,
              const double[::1] sigma_before, const double[::1] sigma_after,
              const double[::1] origin_x, const double[::1] origin_y,
              const double[::1] heading, double floor_m, idx_t min_members, idx_t side,
              double f_min, double chi_min, double turn_min, double tol):
    """``irring.estimation.bends.faceted_lines``' split search (its numpy statement:
    ``_facet_asked``) as its pre-gate: for each line of ``min_members`` members the snap
    moved (d or σ changed) or more, in label order, the F and χ² gain of its best split
    into two pieces of ``side`` members at least, the largest turn (rad) of any split
    whose χ² is within 2 · ``tol`` · (1 + scale) of the best's, the scale (Σ w·r² of the
    sorted members up to the line's end: the size of the prefix sums' rounding), and
    whether the line may pass ``f_min``, ``chi_min`` and ``turn_min`` with each statistic
    widened by ``tol`` (F by ``tol`` · (1 + scale) · (1 + |F|), the gain by ``tol`` ·
    (1 + scale), the turn by ``tol``; NaN may). The same sums in the same order as numpy
    (one prefix sum over every line, no fused multiply-add) but libm's trig: within a
    tolerance of numpy's, not bit for bit. Arrays flat (S·N); ``label`` −1 on no line."""
    cdef idx_t size = label.shape[0], f, i, j, k, gi, n_g = 0, L = 0, m = 0, lo, hi, a, n
    cdef double h, ex, ey, x, y, u, v, ux, uy, sg, wt, chi_l, chi_r, m_l, m_r, both, split
    cdef double chi0, m0, lim, turn, scale, F, gain, e
    cdef idx_t m1
    cdef double[:, ::1] O
    if not (valid.shape[0] == d_before.shape[0] == d_after.shape[0] == sigma_before.shape[0]
            == sigma_after.shape[0] == origin_x.shape[0] == origin_y.shape[0]
            == heading.shape[0] == size):
        raise lengths_differ("facet_pre's arrays", label=size, valid=valid.shape[0],
                             d_before=d_before.shape[0], d_after=d_after.shape[0],
                             sigma_before=sigma_before.shape[0],
                             sigma_after=sigma_after.shape[0], origin_x=origin_x.shape[0],
                             origin_y=origin_y.shape[0], heading=heading.shape[0])
    for f in range(size):
        if label[f] >= L:
            L = label[f] + 1
    cdef idx_t* members = <idx_t*>calloc(L + 1, sizeof(idx_t))
    if members == NULL:
        raise MemoryError("facet_pre: no memory for the lines' counts")
    cdef double* G = NULL          # per line: n, Σx → cx, Σy → cy, Σuv → ux, Σ(u²−v²) → uy, start
    cdef double* R = NULL          # per member: u → s, v → r, w (flat order)
    cdef idx_t* at = NULL          # per member: its line
    cdef _Along* key = NULL        # per sorted place: s, member
    cdef _Along* tmp = NULL        # the sort's scratch
    cdef double* cum = NULL        # six prefix sums of m + 1
    cdef double* buf = NULL        # per sorted place: both, slope left, slope right
    cdef idx_t* fill = NULL
    try:
        for f in range(size):
            if (label[f] >= 0 and valid[f] and (d_after[f] != d_before[f]
                                                 or sigma_after[f] != sigma_before[f])):
                members[label[f]] += 1
        for k in range(L):
            if members[k] >= min_members:
                m += members[k]
                members[k] = n_g         # now the line's rank
                n_g += 1
            else:
                members[k] = -1
        out = np.empty((5, n_g))         # F, χ² gain, turn, scale, may (0/1)
        if n_g == 0:
            return out[0], out[1], out[2], out[3], out[4].astype(bool)
        O = out
        G = <double*>calloc(6 * n_g, sizeof(double))
        R = <double*>malloc(3 * m * sizeof(double))
        at = <idx_t*>malloc(m * sizeof(idx_t))
        key = <_Along*>malloc(m * sizeof(_Along))
        tmp = <_Along*>malloc(m * sizeof(_Along))
        m1 = m + 1
        cum = <double*>malloc(6 * m1 * sizeof(double))
        buf = <double*>malloc(3 * m * sizeof(double))
        fill = <idx_t*>calloc(n_g, sizeof(idx_t))
        if (G == NULL or R == NULL or at == NULL or key == NULL or tmp == NULL or cum == NULL
                or buf == NULL or fill == NULL):
            raise MemoryError("facet_pre: no memory for the lines' members")
        i = 0
        for f in range(size):
            if (label[f] >= 0 and members[label[f]] >= 0 and valid[f]
                    and (d_after[f] != d_before[f] or sigma_after[f] != sigma_before[f])):
                gi = members[label[f]]
                at[i] = gi
                h = heading[f]
                ex = cos(h)
                ey = sin(h)
                x = origin_x[f] + d_before[f] * ex
                y = origin_y[f] + d_before[f] * ey
                R[3 * i] = x
                R[3 * i + 1] = y
                sg = sigma_before[f]
                if sg < floor_m:             # np.maximum: NaN stays
                    sg = floor_m
                R[3 * i + 2] = 1.0 / (sg * sg)
                G[6 * gi] += 1.0
                G[6 * gi + 1] += x
                G[6 * gi + 2] += y
                i += 1
        for gi in range(n_g):
            G[6 * gi + 1] = G[6 * gi + 1] / G[6 * gi]
            G[6 * gi + 2] = G[6 * gi + 2] / G[6 * gi]
            G[6 * gi + 5] = (G[6 * gi - 1] + G[6 * gi - 6]) if gi > 0 else 0.0
        for i in range(m):
            gi = at[i]
            u = R[3 * i] - G[6 * gi + 1]
            v = R[3 * i + 1] - G[6 * gi + 2]
            R[3 * i] = u
            R[3 * i + 1] = v
            G[6 * gi + 3] += u * v
            G[6 * gi + 4] += u * u - v * v
        for gi in range(n_g):
            h = 0.5 * atan2(2.0 * G[6 * gi + 3], G[6 * gi + 4])      # the line's direction
            G[6 * gi + 3] = cos(h)
            G[6 * gi + 4] = sin(h)
        for i in range(m):
            gi = at[i]
            ux = G[6 * gi + 3]
            uy = G[6 * gi + 4]
            u = R[3 * i]
            v = R[3 * i + 1]
            R[3 * i] = u * ux + v * uy
            R[3 * i + 1] = -u * uy + v * ux
            j = <idx_t>G[6 * gi + 5] + fill[gi]
            fill[gi] += 1
            key[j].s = R[3 * i]
            key[j].i = i
        for gi in range(n_g):
            _sort_along(&key[<idx_t>G[6 * gi + 5]], tmp, <idx_t>G[6 * gi])
        # one prefix sum over every line in sorted order, as numpy's cumsum
        for k in range(6):
            cum[k * m1] = 0.0
        for j in range(m):
            i = key[j].i
            x = R[3 * i]
            y = R[3 * i + 1]
            wt = R[3 * i + 2]
            cum[j + 1] = cum[j] + wt
            cum[m1 + j + 1] = cum[m1 + j] + wt * x
            cum[2 * m1 + j + 1] = cum[2 * m1 + j] + wt * (x * x)
            cum[3 * m1 + j + 1] = cum[3 * m1 + j] + wt * y
            cum[4 * m1 + j + 1] = cum[4 * m1 + j] + wt * (x * y)
            cum[5 * m1 + j + 1] = cum[5 * m1 + j] + wt * (y * y)
        for gi in range(n_g):
            n = <idx_t>G[6 * gi]
            lo = <idx_t>G[6 * gi + 5]
            hi = lo + n
            _facet_fit(cum, m1, lo, hi, &chi0, &m0)
            # the least χ² split, numpy's lexsort's: the first least, NaN never
            split = INFINITY
            for a in range(lo + side, hi - side + 1):
                _facet_fit(cum, m1, lo, a, &chi_l, &m_l)
                _facet_fit(cum, m1, a, hi, &chi_r, &m_r)
                both = chi_l + chi_r
                buf[3 * a] = both
                buf[3 * a + 1] = m_l
                buf[3 * a + 2] = m_r
                if both < split:
                    split = both
            scale = cum[5 * m1 + hi]
            e = tol * (1.0 + scale)
            turn = NAN
            if isfinite(split):
                lim = split + 2.0 * e
                turn = -INFINITY
                for a in range(lo + side, hi - side + 1):
                    if buf[3 * a] <= lim:
                        h = fabs(atan(buf[3 * a + 2]) - atan(buf[3 * a + 1]))
                        if h != h:
                            turn = INFINITY      # not known: it may turn enough
                        elif h > turn:
                            turn = h
            F = (chi0 - split) / 2.0 / fmax(split / (n - 4.0 if n - 4.0 > 1.0 else 1.0),
                                            1e-300)
            gain = chi0 - split
            O[0, gi] = F
            O[1, gi] = gain
            O[2, gi] = turn
            O[3, gi] = scale
            O[4, gi] = not (F + e * (1.0 + fabs(F)) < f_min or gain + e < chi_min
                              or turn + tol < turn_min)
    finally:
        free(members)
        free(G)
        free(R)
        free(at)
        free(key)
        free(tmp)
        free(cum)
        free(buf)
        free(fill)
    return out[0], out[1], out[2], out[3], out[4].astype(bool)


# --------------------------------------------------------------------------- counts fits

cdef inline double _np_interp(double x, const double* xp, const double* fp, idx_t n) noexcept nogil:
    """np.interp(x, xp, fp) for one x (numpy's rule, to the bit: held beyond the ends, a node
    read as its own value, slope · (x − xp[j]) + fp[j] within, NaN as NaN; one node: its
    value for every x, NaN too)."""
    cdef idx_t lo = 0, hi = n - 1, mid
    cdef double slope, r
    if n == 1:
        return fp[0]
    if x != x:
        return x
    if x > xp[n - 1]:
        return fp[n - 1]
    if x < xp[0]:
        return fp[0]
    if x == xp[n - 1]:
        return fp[n - 1]
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if xp[mid] <= x:
            lo = mid
        else:
            hi = mid
    if xp[lo] == x:
        return fp[lo]
    slope = (fp[lo + 1] - fp[lo]) / (xp[lo + 1] - xp[lo])
    r = slope * (x - xp[lo]) + fp[lo]
    if r != r:
        r = slope * (x - xp[lo + 1]) + fp[lo + 1]
        if r != r and fp[lo] == fp[lo + 1]:
            r = fp[lo]
    return r


cdef class _CountsModel:
    """``counts._counts_at`` over a batch of beams: each beam's line (direction, offset)
    and its expected counts, numpy's arccos, log and exp on the batch's rows."""
    cdef object rows_arr, xp_arr, la_arr, b_arr
    cdef double[:, ::1] R
    cdef const double[::1] xp, la, bb
    cdef double cos_max
    cdef idx_t cap

    def __init__(self, idx_t cap, xp, node_log_a, node_b, double cos_max):
        self.xp_arr = np.ascontiguousarray(xp, dtype=float)
        self.la_arr = np.ascontiguousarray(node_log_a, dtype=float)
        self.b_arr = np.ascontiguousarray(node_b, dtype=float)
        if not (self.xp_arr.ndim == self.la_arr.ndim == self.b_arr.ndim == 1
                and self.xp_arr.shape[0] == self.la_arr.shape[0] == self.b_arr.shape[0] >= 1):
            raise lengths_differ("the curve's nodes (at least 1)", xp=self.xp_arr.size,
                                 node_log_a=self.la_arr.size, node_b=self.b_arr.size)
        self.xp, self.la, self.bb = self.xp_arr, self.la_arr, self.b_arr
        self.cap = cap if cap > 1 else 1
        self.rows_arr = np.empty((4, self.cap))   # along, t, |along| → θ, log t → counts
        self.R = self.rows_arr
        self.cos_max = cos_max

    cdef void expect(self, idx_t n, const double* al, const double* cl, const double* ox,
                     const double* oy, const double* ch, const double* sh, double* e,
                     unsigned char* met):
        """e[q], met[q] of beam q (origin ox, oy; heading cos ch, sin sh) at the line al[q],
        cl[q], q < n ≤ cap: ``_counts_at``'s operations in its order."""
        cdef idx_t q, m = self.xp.shape[0]
        cdef double nx, ny, along, x, la, b
        cdef double[:, ::1] R = self.R
        if n == 0:
            return
        for q in range(n):
            nx = -sin(al[q])
            ny = cos(al[q])
            along = ch[q] * nx + sh[q] * ny
            R[0, q] = along
            R[1, q] = (cl[q] - ox[q] * nx - oy[q] * ny) / along
            x = fabs(along)
            if x > 1.0:          # np.minimum: a NaN stays
                x = 1.0
            R[2, q] = x
        rows = self.rows_arr
        np.arccos(rows[2, :n], out=rows[2, :n])
        np.log(rows[1, :n], out=rows[3, :n])
        for q in range(n):
            x = fabs(R[2, q])
            la = _np_interp(x, &self.xp[0], &self.la[0], m)
            b = _np_interp(x, &self.xp[0], &self.bb[0], m)
            R[3, q] = (R[3, q] - la) / b
        np.exp(rows[3, :n], out=rows[3, :n])
        for q in range(n):
            x = R[3, q]
            met[q] = R[1, q] > 0 and fabs(R[0, q]) > self.cos_max and isfinite(x)
            e[q] = x if met[q] else 0.0


def counts_at(const double[::1] alpha, const double[::1] c, const double[::1] ox,
              const double[::1] oy, const double[::1] cos_h, const double[::1] sin_h, xp,
              node_log_a, node_b, double cos_max_inc):
    """``irring.estimation.counts._counts_at`` (the statement), to the bit: the counts each
    beam (origin ``ox``, ``oy``; heading ``cos_h``, ``sin_h``) returns from its line
    (``alpha``, ``c``; one per beam), 0 where it misses it within the drop-out angle
    (``cos_max_inc``: that angle's cosine), and whether it meets it (bool). The curve:
    np.interp over ``xp``, ``node_log_a``, ``node_b``; arccos, log, exp numpy's."""
    cdef idx_t n = alpha.shape[0]
    if not (c.shape[0] == ox.shape[0] == oy.shape[0] == cos_h.shape[0] == sin_h.shape[0] == n):
        raise lengths_differ("counts_at's beams", alpha=n, c=c.shape[0], ox=ox.shape[0],
                             oy=oy.shape[0], cos_h=cos_h.shape[0], sin_h=sin_h.shape[0])
    cdef _CountsModel model = _CountsModel(n, xp, node_log_a, node_b, cos_max_inc)
    e_arr = np.zeros(n)
    met_arr = np.zeros(n, dtype=np.uint8)
    cdef double[::1] E = e_arr
    cdef unsigned char[::1] MET = met_arr
    if n:
        model.expect(n, &alpha[0], &c[0], &ox[0], &oy[0], &cos_h[0], &sin_h[0], &E[0], &MET[0])
    return e_arr, met_arr.view(bool)


def counts_refit(const idx_t[::1] line, const double[::1] s, const double[::1] sig,
                 const double[::1] ox, const double[::1] oy, const double[::1] cos_h,
                 const double[::1] sin_h, const double[::1] a_in, const double[::1] c_in,
                 const unsigned char[::1] asked, int steps, bint has_settled,
                 double settled_a, double settled_c, xp, node_log_a, node_b,
                 double cos_max_inc, double step_a, double step_c):
    """``irring.estimation.counts._counts_refit`` (the statement; ``settled`` given as
    ``has_settled``, ``settled_a``, ``settled_c``), to the bit: (a, c, χ²) of the lines
    (``a_in``, ``c_in``) refitted by Gauss–Newton to their members' counts (``line``: each
    member's line, ``s``, ``sig``, its beam ``ox``, ``oy``, ``cos_h``, ``sin_h``), only
    those ``asked``; the Jacobian by central differences of ``step_a`` rad, ``step_c`` m.
    The same sums in the same order; only the lines a step still asks about are evaluated,
    and a line's χ² and counts after a step are those of the trial it took (numpy's
    re-evaluation gives the same numbers)."""
    cdef idx_t M = line.shape[0], L = a_in.shape[0], i, q, g, n, it, half, k
    if not (s.shape[0] == sig.shape[0] == ox.shape[0] == oy.shape[0] == cos_h.shape[0]
            == sin_h.shape[0] == M and c_in.shape[0] == asked.shape[0] == L):
        raise lengths_differ("counts_refit's arrays", line=M, s=s.shape[0], sig=sig.shape[0],
                             ox=ox.shape[0], oy=oy.shape[0], cos_h=cos_h.shape[0],
                             sin_h=sin_h.shape[0], a=L, c=c_in.shape[0], asked=asked.shape[0])
    for i in range(M):
        if line[i] < 0 or line[i] >= L:
            raise IndexError(f"line[{i}] = {line[i]} is not a line (0 … {L - 1})")
    a_arr = np.array(a_in, dtype=float)
    c_arr = np.array(c_in, dtype=float)
    best_arr = np.zeros(L)
    cdef double[::1] A = a_arr, C = c_arr, BEST = best_arr
    if M == 0:
        return a_arr, c_arr, best_arr
    cdef _CountsModel model = _CountsModel(4 * M, xp, node_log_a, node_b, cos_max_inc)
    work = np.empty((8, 4 * M))     # per evaluated beam: al, cl, ox, oy, ch, sh, e; e0 (M)
    cdef double[:, ::1] W = work
    who_arr = np.empty(4 * M, dtype=np.intp)
    cdef idx_t[::1] who = who_arr
    met_arr = np.empty(4 * M, dtype=np.uint8)
    cdef unsigned char[::1] MET = met_arr
    per = np.zeros((12, L))    # unmet, saa, sac, scc, ga, gc, da, dc, trial, ok, moved, q
    cdef double[:, ::1] P = per
    cdef double det, r, x, two_a = 2 * step_a, two_c = 2 * step_c
    cdef double ja, jc, res
    cdef bint small, any_ok, any_moved

    # best, e0 = chi2_of(a, c): every member
    for i in range(M):
        g = line[i]
        W[0, i] = A[g]
        W[1, i] = C[g]
        W[2, i] = ox[i]
        W[3, i] = oy[i]
        W[4, i] = cos_h[i]
        W[5, i] = sin_h[i]
    model.expect(M, &W[0, 0], &W[1, 0], &W[2, 0], &W[3, 0], &W[4, 0], &W[5, 0], &W[6, 0],
                 &MET[0])
    for i in range(M):
        g = line[i]
        W[7, i] = W[6, i]
        r = (s[i] - W[6, i]) / sig[i]
        P[11, g] += r * r
        P[0, g] += 0.0 if MET[i] else 1.0
    for g in range(L):
        BEST[g] = INFINITY if P[0, g] > 0 else P[11, g]

    for it in range(steps):
        # the Jacobian at each asked line's members: a ± step_a, c ± step_c in one batch
        n = 0
        for i in range(M):
            g = line[i]
            if not asked[g]:
                continue
            who[n] = i
            n += 1
        for q in range(n):
            i = who[q]
            g = line[i]
            for k in range(4):
                W[0, 4 * q + k] = A[g] + step_a if k == 0 else (A[g] - step_a if k == 1 else A[g])
                W[1, 4 * q + k] = C[g] + step_c if k == 2 else (C[g] - step_c if k == 3 else C[g])
                W[2, 4 * q + k] = ox[i]
                W[3, 4 * q + k] = oy[i]
                W[4, 4 * q + k] = cos_h[i]
                W[5, 4 * q + k] = sin_h[i]
        model.expect(4 * n, &W[0, 0], &W[1, 0], &W[2, 0], &W[3, 0], &W[4, 0], &W[5, 0],
                     &W[6, 0], &MET[0])
        for g in range(L):
            for k in range(1, 6):
                P[k, g] = 0.0
        for q in range(n):
            i = who[q]
            g = line[i]
            ja = (W[6, 4 * q] - W[6, 4 * q + 1]) / two_a
            jc = (W[6, 4 * q + 2] - W[6, 4 * q + 3]) / two_c
            res = s[i] - W[7, i]
            P[1, g] += ja * ja
            P[2, g] += ja * jc
            P[3, g] += jc * jc
            P[4, g] += ja * res
            P[5, g] += jc * res
        small = has_settled
        any_ok = False
        for g in range(L):
            det = P[1, g] * P[3, g] - P[2, g] * P[2, g]
            x = P[1, g] * P[3, g]
            if not (x > 1e-300 or x != x):    # np.maximum: a NaN stays
                x = 1e-300
            if asked[g] and isfinite(det) and det > 1e-12 * x:
                P[9, g] = 1.0
                any_ok = True
                P[6, g] = (P[3, g] * P[4, g] - P[2, g] * P[5, g]) / det
                P[7, g] = (P[1, g] * P[5, g] - P[2, g] * P[4, g]) / det
            else:
                P[9, g] = 0.0
                P[6, g] = 0.0
                P[7, g] = 0.0
            if not (fabs(P[6, g]) <= settled_a and fabs(P[7, g]) <= settled_c):
                small = False
            P[10, g] = 0.0
        any_moved = False
        for half in range(5):
            if any_ok:     # (none asked: the trial changes nothing)
                n = 0
                for i in range(M):
                    g = line[i]
                    if P[9, g] == 0.0:
                        continue
                    who[n] = i
                    W[0, n] = A[g] + P[6, g]
                    W[1, n] = C[g] + P[7, g]
                    W[2, n] = ox[i]
                    W[3, n] = oy[i]
                    W[4, n] = cos_h[i]
                    W[5, n] = sin_h[i]
                    n += 1
                model.expect(n, &W[0, 0], &W[1, 0], &W[2, 0], &W[3, 0], &W[4, 0], &W[5, 0],
                             &W[6, 0], &MET[0])
                for g in range(L):
                    P[0, g] = 0.0
                    P[8, g] = 0.0
                for q in range(n):
                    i = who[q]
                    g = line[i]
                    r = (s[i] - W[6, q]) / sig[i]
                    P[8, g] += r * r
                    P[0, g] += 0.0 if MET[q] else 1.0
                for g in range(L):
                    if P[9, g] == 0.0:
                        continue
                    x = INFINITY if P[0, g] > 0 else P[8, g]
                    if x < BEST[g]:
                        A[g] = A[g] + P[6, g]
                        C[g] = C[g] + P[7, g]
                        BEST[g] = x
                        P[10, g] = 1.0
                        P[9, g] = 0.0
                        any_moved = True
                for q in range(n):      # the counts it took: e0 of the next step
                    i = who[q]
                    if P[10, line[i]] != 0.0 and P[9, line[i]] == 0.0:
                        W[7, i] = W[6, q]
            any_ok = False
            for g in range(L):
                if P[9, g] != 0.0:
                    any_ok = True
            if not any_ok:
                break
            for g in range(L):
                P[6, g] = 0.5 * P[6, g]
                P[7, g] = 0.5 * P[7, g]
        if not any_moved or small:
            break
    return a_arr, c_arr, best_arr


def counts_jacobian(const double[::1] alpha, const double[::1] c, const double[::1] ox,
                    const double[::1] oy, const double[::1] cos_h, const double[::1] sin_h,
                    xp, node_log_a, node_b, double cos_max_inc, double step_a, double step_c):
    """``irring.estimation.counts._counts_jacobian`` (the statement), to the bit: each
    beam's counts' derivatives (ja, jc) in its line's direction ``alpha`` and offset ``c``
    by central differences of ``step_a`` rad and ``step_c`` m (:func:`counts_at`'s model,
    its four evaluations in one batch)."""
    cdef idx_t n = alpha.shape[0], q, k
    if not (c.shape[0] == ox.shape[0] == oy.shape[0] == cos_h.shape[0] == sin_h.shape[0] == n):
        raise lengths_differ("counts_jacobian's beams", alpha=n, c=c.shape[0], ox=ox.shape[0],
                             oy=oy.shape[0], cos_h=cos_h.shape[0], sin_h=sin_h.shape[0])
    ja_arr = np.empty(n)
    jc_arr = np.empty(n)
    if n == 0:
        return ja_arr, jc_arr
    cdef double[::1] JA = ja_arr, JC = jc_arr
    cdef _CountsModel model = _CountsModel(4 * n, xp, node_log_a, node_b, cos_max_inc)
    work = np.empty((7, 4 * n))     # al, cl, ox, oy, ch, sh, e
    cdef double[:, ::1] W = work
    met_arr = np.empty(4 * n, dtype=np.uint8)
    cdef unsigned char[::1] MET = met_arr
    cdef double two_a = 2 * step_a, two_c = 2 * step_c
    for q in range(n):
        for k in range(4):
            W[0, 4 * q + k] = (alpha[q] + step_a if k == 0 else
                               (alpha[q] - step_a if k == 1 else alpha[q]))
            W[1, 4 * q + k] = c[q] + step_c if k == 2 else (c[q] - step_c if k == 3 else c[q])
            W[2, 4 * q + k] = ox[q]
            W[3, 4 * q + k] = oy[q]
            W[4, 4 * q + k] = cos_h[q]
            W[5, 4 * q + k] = sin_h[q]
    model.expect(4 * n, &W[0, 0], &W[1, 0], &W[2, 0], &W[3, 0], &W[4, 0], &W[5, 0], &W[6, 0],
                 &MET[0])
    for q in range(n):
        JA[q] = (W[6, 4 * q] - W[6, 4 * q + 1]) / two_a
        JC[q] = (W[6, 4 * q + 2] - W[6, 4 * q + 3]) / two_c
    return ja_arr, jc_arr


def best_halves(const double[::1] u, const double[::1] v, idx_t lo):
    """``irring.estimation.counts._best_halves`` (the statement) on the points already
    centred (``u``, ``v``: x − mean, y − mean, numpy's), to the bit: the running sums
    accumulate in order as np.cumsum does, the first least total (a NaN first, as
    np.argmin) names the first point of the second run."""
    cdef idx_t n = u.shape[0], i, k, best_k = -1
    cdef double px = 0.0, py = 0.0, pxx = 0.0, pyy = 0.0, pxy = 0.0, tot, best = 0.0
    if v.shape[0] != n:
        raise lengths_differ("best_halves' points", u=n, v=v.shape[0])
    if lo < 1 or n - lo < lo:
        raise ValueError(f"best_halves: {n} points hold no two runs of {lo}")
    sums = np.empty((5, n))
    cdef double[:, ::1] S = sums
    for i in range(n):
        px += u[i]
        py += v[i]
        pxx += u[i] * u[i]
        pyy += v[i] * v[i]
        pxy += u[i] * v[i]
        S[0, i] = px
        S[1, i] = py
        S[2, i] = pxx
        S[3, i] = pyy
        S[4, i] = pxy
    for k in range(lo, n - lo + 1):
        tot = (_halves_rss(<double> k, S[0, k - 1], S[1, k - 1], S[2, k - 1], S[3, k - 1],
                           S[4, k - 1])
               + _halves_rss(<double> (n - k), S[0, n - 1] - S[0, k - 1],
                             S[1, n - 1] - S[1, k - 1], S[2, n - 1] - S[2, k - 1],
                             S[3, n - 1] - S[3, k - 1], S[4, n - 1] - S[4, k - 1]))
        if best_k < 0 or (best == best and (tot < best or tot != tot)):
            best, best_k = tot, k
    return best_k


cdef inline double _halves_rss(double m, double sx, double sy, double sxx, double syy,
                               double sxy) noexcept nogil:
    """``_best_halves``' rss: the least squared residual of a TLS line through m points."""
    cdef double a = sxx - sx * sx / m, b = syy - sy * sy / m, c = sxy - sx * sy / m
    return 0.5 * (a + b) - sqrt(0.25 * ((a - b) * (a - b)) + c * c)


# --------------------------------------------------------------------------- past other lines

cdef inline bint _crosses(double ox, double oy, double ux, double uy, double mx, double my,
                          double ca, double sa, double* un, double* t,
                          double* at) noexcept nogil:
    """``silence.beam_crossings`` of one beam and one line (centroid (mx, my), direction
    (ca, sa)), term by term as numpy forms it: whether the line lies ahead; ``un``, ``t``
    (0 where not ahead) and the crossing's coordinate ``at`` along it."""
    un[0] = ux * -sa + uy * ca
    t[0] = ((mx - ox) * -sa + (my - oy) * ca) / un[0]
    cdef bint ahead = fabs(un[0]) > 1e-9 and isfinite(t[0]) and t[0] > 0
    if not ahead:
        t[0] = 0.0
    at[0] = (ox + t[0] * ux - mx) * ca + (oy + t[0] * uy - my) * sa
    return ahead


cdef idx_t _number_lines(const idx_t[::1] label, const unsigned char[::1] valid, idx_t* rank,
                         idx_t L, idx_t min_members, idx_t* members) noexcept nogil:
    """Each label's valid members counted in ``rank`` (L, zeroed; np.bincount's), then in
    its place the line's number among the labels of ``min_members`` members or more, in
    label order, else −1; ``members``: theirs in all. Returns how many are numbered."""
    cdef idx_t f, k, n = 0
    members[0] = 0
    for f in range(label.shape[0]):
        if valid[f] and label[f] >= 0:
            rank[label[f]] += 1
    for k in range(L):
        if rank[k] >= min_members:
            members[0] += rank[k]
            rank[k] = n
            n += 1
        else:
            rank[k] = -1
    return n


def past_members(const idx_t[::1] label, const unsigned char[::1] valid,
                 const double[::1] x, const double[::1] y, const double[::1] origin_x,
                 const double[::1] origin_y, const double[::1] heading, const double[::1] d,
                 const double[::1] sigma, double cx, double cy, idx_t min_members,
                 idx_t few_max, double corner_reach, double reach_share, double clear_sigmas,
                 double clear_m, double floor_clear_m):
    """``irring.estimation.members.past_members`` (``past_other_lines``' gates), to the
    bit: each line's TLS fit and extent over its valid members (the angle from numpy's
    ``arctan2``), the walls' ends seen from the ring centre (``cx``, ``cy``: the caller's
    numpy mean of the origins, as the numpy statement takes it) past another wall, and per such pair of
    walls (in label order) the few members of the end's wall past the other. None where
    none is found; else the members, in that order, as flat index, t, un
    (``beam_crossings``') and σ. Arrays flat (S·N); ``label`` −1 on no line; the scalars
    are the rule's constants (``clear_m``: the 2 cm; ``floor_clear_m``: the clearance at
    the σ floor)."""
    cdef idx_t size = label.shape[0], f, i, j, k, b, c, L = 0, nw = 0, m = 0, e, n_side
    cdef idx_t room = 0, n_out = 0
    cdef double ex, ey, rng, ux, uy, un, t, at, reach, a, ca, sa, mxc, myc
    cdef bint ahead, few
    cdef double[:, ::1] O, ND
    cdef const double[::1] alpha
    cdef double* CS = NULL
    cdef idx_t[::1] OF
    if not (valid.shape[0] == x.shape[0] == y.shape[0] == origin_x.shape[0]
            == origin_y.shape[0] == heading.shape[0] == d.shape[0] == sigma.shape[0] == size):
        raise lengths_differ("past_members' arrays", label=size, valid=valid.shape[0],
                             x=x.shape[0], y=y.shape[0], origin_x=origin_x.shape[0],
                             origin_y=origin_y.shape[0], heading=heading.shape[0],
                             d=d.shape[0], sigma=sigma.shape[0])
    if few_max < 0:
        raise ValueError(f"past_members: few_max {few_max} is negative (at least 0)")
    for f in range(size):
        if valid[f] and label[f] >= L:
            L = label[f] + 1
    if L == 0:
        return None
    cdef idx_t* rank = <idx_t*> calloc(L, sizeof(idx_t))
    cdef idx_t* start = NULL
    cdef idx_t* at_f = NULL
    cdef double* W = NULL
    cdef double* M = NULL
    cdef unsigned char* pair = NULL
    try:
        if rank == NULL:
            raise MemoryError()
        nw = _number_lines(label, valid, rank, L, min_members, &m)  # walls: min_members or more
        if nw < 2:
            return None
        # per wall: its members' start; rows of W: members, Σx, Σy, mx, my, Σuv, Σuu, Σvv,
        # lo, hi
        start = <idx_t*> calloc(nw + 1, sizeof(idx_t))
        at_f = <idx_t*> malloc(m * sizeof(idx_t))
        W = <double*> calloc(10 * nw, sizeof(double))
        M = <double*> malloc(2 * m * sizeof(double))      # each member's u, v
        pair = <unsigned char*> calloc(nw * nw, 1)
        CS = <double*> malloc(2 * nw * sizeof(double))    # each wall's cos α, sin α
        if (start == NULL or at_f == NULL or W == NULL or M == NULL or pair == NULL
                or CS == NULL):
            raise MemoryError()
        for f in range(size):
            if valid[f] and label[f] >= 0 and rank[label[f]] >= 0:
                b = rank[label[f]]
                W[b] += 1.0
                W[nw + b] += x[f]
                W[2 * nw + b] += y[f]
        for b in range(nw):
            start[b + 1] = start[b] + <idx_t> W[b]
            W[3 * nw + b] = W[nw + b] / fmax(W[b], 1.0)       # (numpy's: of no member, 0)
            W[4 * nw + b] = W[2 * nw + b] / fmax(W[b], 1.0)
            W[8 * nw + b] = INFINITY
            W[9 * nw + b] = -INFINITY
        for b in range(nw):                # (a cursor per wall, in W's Σx row, now free)
            W[nw + b] = <double> start[b]
        for f in range(size):              # each wall's members in flat order: numpy's sums'
            if valid[f] and label[f] >= 0 and rank[label[f]] >= 0:
                b = rank[label[f]]
                i = <idx_t> W[nw + b]
                W[nw + b] += 1.0
                at_f[i] = f
                M[2 * i] = x[f] - W[3 * nw + b]
                M[2 * i + 1] = y[f] - W[4 * nw + b]
                W[5 * nw + b] += M[2 * i] * M[2 * i + 1]
                W[6 * nw + b] += M[2 * i] * M[2 * i]
                W[7 * nw + b] += M[2 * i + 1] * M[2 * i + 1]
        nd_arr = np.empty((2, nw))
        ND = nd_arr
        for b in range(nw):
            ND[0, b] = 2.0 * W[5 * nw + b]
            ND[1, b] = W[6 * nw + b] - W[7 * nw + b]
        alpha = _arctan2(nd_arr[0], nd_arr[1])
        for b in range(nw):
            CS[2 * b] = cos(0.5 * alpha[b])
            CS[2 * b + 1] = sin(0.5 * alpha[b])
            for i in range(start[b], start[b + 1]):
                a = M[2 * i] * CS[2 * b] + M[2 * i + 1] * CS[2 * b + 1]
                # (np.minimum / np.maximum: a NaN once met stays)
                if W[8 * nw + b] == W[8 * nw + b] and not (a >= W[8 * nw + b]):
                    W[8 * nw + b] = a
                if W[9 * nw + b] == W[9 * nw + b] and not (a <= W[9 * nw + b]):
                    W[9 * nw + b] = a
        # first, the walls' ends: an end seen from the ring past another wall, or none to ask
        for e in range(2 * nw):
            b = e % nw
            ca = CS[2 * b]
            sa = CS[2 * b + 1]
            ex = W[3 * nw + b] + W[(8 + e // nw) * nw + b] * ca
            ey = W[4 * nw + b] + W[(8 + e // nw) * nw + b] * sa
            rng = hypot(ex - cx, ey - cy)
            ux = (ex - cx) / rng
            uy = (ey - cy) / rng
            for c in range(nw):
                if c == b or pair[b * nw + c]:
                    continue
                ahead = _crosses(cx, cy, ux, uy, W[3 * nw + c], W[4 * nw + c], CS[2 * c],
                                 CS[2 * c + 1], &un, &t, &at)
                reach = reach_share * t
                if not (reach > corner_reach):
                    reach = corner_reach
                if (ahead and t < rng - floor_clear_m - clear_m
                        and at >= W[8 * nw + c] - reach and at <= W[9 * nw + c] + reach):
                    pair[b * nw + c] = 1
                    # (room for the most it can give: its few, or all its members)
                    room += min(few_max, start[b + 1] - start[b])
        if room == 0:
            return None
        # then, per such pair (a few a sweep), the end's wall's few members past the other
        out = np.empty((3, room))
        out_f = np.empty(room, dtype=np.intp)
        O = out
        OF = out_f
        for b in range(nw):
            for c in range(nw):
                if not pair[b * nw + c]:
                    continue
                ca = CS[2 * c]
                sa = CS[2 * c + 1]
                mxc = W[3 * nw + c]
                myc = W[4 * nw + c]
                # a corner: the wall's members all on one side of the other's, but these few
                n_side = 0
                for i in range(start[b], start[b + 1]):
                    f = at_f[i]
                    n_side += (x[f] - mxc) * -sa + (y[f] - myc) * ca > 0.0
                k = start[b + 1] - start[b]
                few = 2 * n_side < k
                if (n_side if few else k - n_side) > few_max:
                    continue
                j = n_out
                for i in range(start[b], start[b + 1]):
                    f = at_f[i]
                    if ((x[f] - mxc) * -sa + (y[f] - myc) * ca > 0.0) != few:
                        continue
                    ahead = _crosses(origin_x[f], origin_y[f], cos(heading[f]),
                                     sin(heading[f]), mxc, myc, ca, sa, &un, &t, &at)
                    reach = reach_share * t
                    if not (reach > corner_reach):
                        reach = corner_reach
                    if (ahead and at >= W[8 * nw + c] - reach and at <= W[9 * nw + c] + reach
                            and t + clear_sigmas * sigma[f] + clear_m < d[f]):
                        OF[j] = f
                        O[0, j] = t
                        O[1, j] = un
                        O[2, j] = sigma[f]
                        j += 1
                n_out = j
        if n_out == 0:
            return None
        return out_f[:n_out], out[0, :n_out], out[1, :n_out], out[2, :n_out]
    finally:
        free(rank)
        free(start)
        free(at_f)
        free(W)
        free(M)
        free(pair)
        free(CS)


cdef void _bulge(const double* px, const double* py, const double* ox, const double* oy,
                 const idx_t* first, idx_t n_g, double bulge_m, double behind,
                 unsigned char* keep, unsigned char* hollow) noexcept nogil:
    """``arcs._bulging`` per group of the points ``first[g]`` … ``first[g + 1] - 1``: its
    keep (``keep``) and whether more than ``behind`` of them lie ``bulge_m`` behind the chord
    (``hollow``), numpy's operations in numpy's order (bincount's sums sequential)."""
    cdef idx_t g, i, a, z
    cdef double ux, uy, norm, side, tw, s_tw, n_behind
    for g in range(n_g):
        a, z = first[g], first[g + 1] - 1
        ux, uy = px[z] - px[a], py[z] - py[a]
        norm = hypot(ux, uy)
        if norm < 1e-12:             # np.maximum(norm, 1e-12) (NaN stays NaN)
            norm = 1e-12
        ux, uy = ux / norm, uy / norm
        side = (ox[a] - px[a]) * uy - (oy[a] - py[a]) * ux
        side = (1.0 if side > 0.0 else (-1.0 if side < 0.0 else (0.0 if side == 0.0 else side)))
        s_tw = 0.0
        n_behind = 0.0
        for i in range(a, z + 1):
            tw = ((px[i] - px[a]) * uy - (py[i] - py[a]) * ux) * side
            s_tw += tw
            if tw < -bulge_m:
                n_behind += 1.0
        keep[g] = (s_tw >= bulge_m * <double>(z + 1 - a)) and (
            n_behind <= behind * <double>(z + 1 - a))
        hollow[g] = n_behind > behind * <double>(z + 1 - a)


def round_pre(const idx_t[::1] vi, const idx_t[::1] label, const idx_t[::1] steps,
              idx_t n_sensors, const double[::1] d0, const double[::1] cos_h,
              const double[::1] sin_h, const double[::1] x, const double[::1] y,
              const double[::1] origin_x, const double[::1] origin_y, idx_t gap_steps,
              double jump_m, idx_t run_min, double bulge_m, double behind, double min_radius):
    """``irring.estimation.arcs.round_runs``' cheap checks (its numpy statement:
    ``arcs._round_asked``) as its pre-gate, to the bit: per candidate run (a sensor's run of
    ``run_min`` valid readings or more holding two labels, in scan order) whether it is
    kept, bulging as estimated or, hollow as estimated, at θ = 0, and no smaller than
    ``min_radius`` by its θ = 0 end points' Kåsa circle. ``vi``: the valid readings in scan
    order (flat indices into ``label``, ``x``, ``y``, ``origin_x``, ``origin_y``, flat
    S·N; ``steps`` (S,)); ``d0``, ``cos_h``, ``sin_h``: per ``vi``, the θ = 0 range and the
    heading's cosine and sine, numpy's (its SIMD exp, log, cos and sin)."""
    cdef idx_t n = vi.shape[0], i, g, k, n_c = 0, m = 0, a, z
    cdef double cnt, mx, my, u, v, zz, suu, suv, svv, suz, svz, sz, det, ca, cb, r
    if not (d0.shape[0] == cos_h.shape[0] == sin_h.shape[0] == n):
        raise lengths_differ("round_pre's per-reading arrays", vi=n, d0=d0.shape[0],
                             cos_h=cos_h.shape[0], sin_h=sin_h.shape[0])
    if not (label.shape[0] == x.shape[0] == y.shape[0] == origin_x.shape[0]
            == origin_y.shape[0] == steps.shape[0] * n_sensors):
        raise lengths_differ("round_pre's flat arrays", label=label.shape[0], x=x.shape[0],
                             y=y.shape[0], origin_x=origin_x.shape[0],
                             origin_y=origin_y.shape[0], steps_times_sensors=steps.shape[0]
                             * n_sensors)
    keep_arr = np.zeros(0, dtype=np.uint8)
    if n == 0:
        return keep_arr
    for i in range(n):
        if vi[i] < 0 or vi[i] >= label.shape[0]:
            raise IndexError(f"round_pre: vi[{i}] = {vi[i]} outside the {label.shape[0]} "
                             "readings")
    # runs: [start[k], start[k + 1]) in vi; a candidate holds run_min readings and a change
    # of label inside it
    cdef idx_t* start = <idx_t*>malloc((n + 1) * sizeof(idx_t))
    cdef idx_t* first = <idx_t*>malloc((n + 1) * sizeof(idx_t))   # candidates' starts (in their readings)
    cdef double* buf = <double*>malloc(6 * n * sizeof(double) + 1)
    cdef unsigned char* flags = <unsigned char*>malloc(4 * n + 4)
    if start == NULL or first == NULL or buf == NULL or flags == NULL:
        free(start); free(first); free(buf); free(flags)
        raise MemoryError("round_pre: no memory for the runs")
    cdef double* px = buf
    cdef double* py = buf + n
    cdef double* ex = buf + 2 * n
    cdef double* ey = buf + 3 * n
    cdef double* qx = buf + 4 * n
    cdef double* qy = buf + 5 * n
    cdef unsigned char* keep = flags
    cdef unsigned char* hollow = flags + n + 1
    cdef unsigned char* keep0 = flags + 2 * n + 2
    cdef unsigned char* unused = flags + 3 * n + 3
    cdef idx_t n_run = 0, f, fp, s_i, s_p
    cdef bint change
    try:
        with nogil:
            for i in range(n):
                f = vi[i]
                s_i = steps[f // n_sensors]
                if i == 0:
                    start[n_run] = 0
                    n_run += 1
                    continue
                fp = vi[i - 1]
                s_p = steps[fp // n_sensors]
                if ((f % n_sensors != fp % n_sensors) or (s_i - s_p > gap_steps)
                        or (s_p - s_i > gap_steps) or (fabs(d0[i] - d0[i - 1]) > jump_m)):
                    start[n_run] = i
                    n_run += 1
            start[n_run] = n
            for k in range(n_run):
                a, z = start[k], start[k + 1]
                if z - a < run_min:
                    continue
                change = False
                for i in range(a + 1, z):
                    if label[vi[i]] != label[vi[i - 1]]:
                        change = True
                        break
                if not change:
                    continue
                first[n_c] = m
                n_c += 1
                for i in range(a, z):
                    f = vi[i]
                    px[m], py[m] = x[f], y[f]
                    ex[m], ey[m] = origin_x[f], origin_y[f]
                    qx[m] = origin_x[f] + d0[i] * cos_h[i]
                    qy[m] = origin_y[f] + d0[i] * sin_h[i]
                    m += 1
            first[n_c] = m
            # as estimated; those hollow as estimated are asked at θ = 0
            _bulge(px, py, ex, ey, first, n_c, bulge_m, behind, keep, hollow)
            _bulge(qx, qy, ex, ey, first, n_c, bulge_m, behind, keep0, unused)
            for g in range(n_c):
                keep[g] = keep[g] or (hollow[g] and keep0[g])
                # the θ = 0 end points' Kåsa circle (arcs._kasa_radii): centred sums
                a, z = first[g], first[g + 1]
                cnt = <double>(z - a)
                mx = 0.0
                my = 0.0
                for i in range(a, z):
                    mx += qx[i]
                    my += qy[i]
                mx = mx / cnt
                my = my / cnt
                suu = 0.0; suv = 0.0; svv = 0.0; suz = 0.0; svz = 0.0; sz = 0.0
                for i in range(a, z):
                    u = qx[i] - mx
                    v = qy[i] - my
                    zz = u * u + v * v
                    suu += u * u
                    suv += u * v
                    svv += v * v
                    suz += u * zz
                    svz += v * zz
                    sz += zz
                det = suu * svv - suv * suv
                r = suu + svv
                if det > 1e-12 * (r * r):
                    ca = 0.5 * (svv * suz - suv * svz) / det
                    cb = 0.5 * (suu * svz - suv * suz) / det
                    r = sqrt(ca * ca + cb * cb + sz / cnt)
                else:
                    r = INFINITY
                keep[g] = keep[g] and (r >= min_radius)
        keep_arr = np.empty(n_c, dtype=np.uint8)
        for g in range(n_c):
            keep_arr[g] = keep[g]
        return keep_arr
    finally:
        free(start); free(first); free(buf); free(flags)


# --------------------------------------------------------------------------- a wall's shallow bend

_sin = np.sin      # numpy's (SIMD: libm's may differ in the last bit), on the lines' angles
_cos = np.cos


cdef inline idx_t _member_at(const idx_t* flat, idx_t m, idx_t f) noexcept nogil:
    """Where the flat reading ``f`` lies in the ascending ``flat`` (m,): its place, or −1."""
    cdef idx_t lo = 0, hi = m, mid
    while lo < hi:
        mid = (lo + hi) >> 1
        if flat[mid] < f:
            lo = mid + 1
        else:
            hi = mid
    return lo if lo < m and flat[lo] == f else -1


def bend_gate(const idx_t[::1] label, const unsigned char[::1] valid, const idx_t[::1] order,
              idx_t n_sensors, const double[::1] x, const double[::1] y,
              const double[::1] origin_x, const double[::1] origin_y, const double[::1] d,
              const double[::1] theta, const double[::1] counts, double sigma_counts,
              double floor_m, const double[::1] xp, const double[::1] node_b,
              idx_t min_members, double near_m, double z):
    """``irring.estimation.bends.bent_ends``' gate (its numpy statement: the members
    ``_bend_members`` asks, then ``_bend_gate``), to the bit: on a line of ``min_members``
    valid members or more, fitted to all of them, whether some sensor's last (or first)
    member in step order lies ``near_m`` nearer than the line along its beam and so does
    the member before it in that sensor's trace, or it alone lies ``z`` noise σ nearer.
    The same sums in numpy's order, numpy's arctan2, sin and cos on the lines' angles,
    np.interp's b(|θ|) on the nodes ``xp``, ``node_b``. Arrays flat (S·N); ``label`` −1 on
    no line; ``order`` (S,) the rows in step order."""
    cdef idx_t size = label.shape[0], S = order.shape[0], n_nodes = xp.shape[0]
    cdef idx_t f, i, j, k, gi, r, L = 0, n_valid = 0, m = 0, n_g = 0, q, c, pf, nf
    cdef double en, w, noise
    cdef bint on_prev, on_next, found = False
    cdef idx_t* line = NULL
    cdef idx_t* at = NULL
    cdef double* buf = NULL
    cdef double* u
    cdef double* v
    cdef double* short
    cdef idx_t[::1] rank
    cdef double[:, ::1] G
    cdef const double[::1] nx, ny
    if not (valid.shape[0] == x.shape[0] == y.shape[0] == origin_x.shape[0]
            == origin_y.shape[0] == d.shape[0] == theta.shape[0] == counts.shape[0] == size
            == S * n_sensors and node_b.shape[0] == n_nodes):
        raise lengths_differ("bend_gate's arrays", label=size, valid=valid.shape[0],
                             x=x.shape[0], y=y.shape[0], origin_x=origin_x.shape[0],
                             origin_y=origin_y.shape[0], d=d.shape[0], theta=theta.shape[0],
                             counts=counts.shape[0], steps_times_sensors=S * n_sensors,
                             xp=n_nodes, node_b=node_b.shape[0])
    if n_nodes == 0:
        raise ValueError("bend_gate: the calibration has no nodes")
    rank_arr = _rank_of_rows(order)
    rank = rank_arr
    for r in range(S):       # (a row listed twice leaves another's place unset)
        q = rank[r]
        if q < 0 or q >= S or order[q] != r:
            raise ValueError(f"bend_gate: order never lists row {r} (it must hold each of "
                             f"the {S} rows once, in step order)")
    for f in range(size):
        if label[f] >= 0 and valid[f]:
            n_valid += 1
            if label[f] >= L:
                L = label[f] + 1
    if n_valid < min_members:
        return False
    # each label's members (np.bincount), then its line's number among those asked or −1
    line = <idx_t*>calloc(L, sizeof(idx_t))
    if line == NULL:
        raise MemoryError("bend_gate: no memory for the lines' counts")
    try:
        n_g = _number_lines(label, valid, line, L, min_members, &m)
        if n_g == 0:
            return False
        at = <idx_t*>malloc(m * sizeof(idx_t))              # the members' flat indices
        buf = <double*>malloc(3 * m * sizeof(double))
        if at == NULL or buf == NULL:
            raise MemoryError("bend_gate: no memory for the members")
        u, v, short = buf, buf + m, buf + 2 * m
        # per line, np.bincount's sums (sequential): members, Σx → cx, Σy → cy, then
        # 2·Σuv and Σ(u² − v²) of the members about that centre
        sums_arr = np.zeros((5, n_g))
        G = sums_arr
        i = 0
        for f in range(size):
            if label[f] >= 0 and valid[f] and line[label[f]] >= 0:
                at[i] = f
                gi = line[label[f]]
                G[0, gi] += 1.0
                G[1, gi] += x[f]
                G[2, gi] += y[f]
                i += 1
        for gi in range(n_g):
            G[1, gi] = G[1, gi] / G[0, gi]
            G[2, gi] = G[2, gi] / G[0, gi]
        for i in range(m):
            f = at[i]
            gi = line[label[f]]
            u[i] = x[f] - G[1, gi]
            v[i] = y[f] - G[2, gi]
            G[3, gi] += u[i] * v[i]
            G[4, gi] += u[i] * u[i] - v[i] * v[i]
        for gi in range(n_g):
            G[3, gi] = 2.0 * G[3, gi]
        al = 0.5 * _arctan2(sums_arr[3], sums_arr[4])
        nx_arr = -_sin(al)
        ny_arr = _cos(al)
        nx, ny = nx_arr, ny_arr
        # how much nearer than the line along its beam: t − d = −(its offset)/cos
        for i in range(m):
            f = at[i]
            gi = line[label[f]]
            en = (x[f] - origin_x[f]) * nx[gi] + (y[f] - origin_y[f]) * ny[gi]
            w = en if fabs(en) > 1e-12 else 1e-12
            short[i] = -(u[i] * nx[gi] + v[i] * ny[gi]) * d[f] / w
        # a near member at its trace's end on its line (the row before or after it in step
        # order, same sensor, on another line or none): the member inside it near too, or
        # it alone z σ nearer (an OR over the ends: numpy's two any()s in either order)
        for i in range(m):
            if not short[i] >= near_m:
                continue
            f = at[i]
            q = rank[f // n_sensors]
            c = f % n_sensors
            pf = order[q - 1] * n_sensors + c if q > 0 else -1
            nf = order[q + 1] * n_sensors + c if q + 1 < S else -1
            on_prev = pf >= 0 and valid[pf] and label[pf] == label[f]
            on_next = nf >= 0 and valid[nf] and label[nf] == label[f]
            if on_prev and on_next:
                continue
            if on_prev or on_next:
                j = _member_at(at, m, nf if on_next else pf)
                if short[j] >= near_m:
                    found = True
                    break
            noise = fabs(_np_interp(fabs(theta[f]), &xp[0], &node_b[0], n_nodes)) * d[f] * (
                sigma_counts / counts[f])
            if not (noise >= floor_m or noise != noise):     # np.maximum: NaN stays
                noise = floor_m
            if short[i] >= z * noise:
                found = True
                break
        return found
    finally:
        free(line)
        free(at)
        free(buf)


# --------------------------------------------------------------------------- alone at an edge

def edge_alone(const idx_t[::1] label, const unsigned char[::1] valid, const double[::1] d,
               const unsigned char[::1] reason, const double[::1] counts,
               const idx_t[::1] order, idx_t n_sensors, unsigned char not_converged,
               unsigned char incidence_unknown, double jump_m, far_end):
    """``irring.estimation.members.alone_at_an_edge``' readings (its numpy statement), to
    the bit: (S·N,) uint8, 1 where a valid line member has neither of its sensor's adjacent
    steps (rows ``order`` (S,): in step order) a valid reading of its line or of anything
    not ``jump_m`` nearer, and one of them nearer by that (valid there, or a return,
    ``not_converged`` or ``incidence_unknown``, as far as ``far_end`` (numpy's, called on
    the counts of those returns in step order, once, where there are any) reads it); a
    sweep's first and last steps left. None where there is no such reading. Arrays flat
    (S·N); ``label`` −1 on no line."""
    cdef idx_t size = label.shape[0], S = order.shape[0], q, c, f, a, r, side, n_ret = 0
    cdef double lim, rn
    cdef bint near, near_any, alone, found = False
    cdef double[::1] fe
    if not (valid.shape[0] == d.shape[0] == reason.shape[0] == counts.shape[0] == size
            == S * n_sensors):
        raise lengths_differ("edge_alone's arrays", label=size, valid=valid.shape[0],
                             d=d.shape[0], reason=reason.shape[0], counts=counts.shape[0],
                             steps_times_sensors=S * n_sensors)
    rank_arr = _rank_of_rows(order)
    cdef idx_t[::1] rank = rank_arr
    for r in range(S):       # (a row listed twice leaves another's place unset)
        q = rank[r]
        if q < 0 or q >= S or order[q] != r:
            raise ValueError(f"edge_alone: order never lists row {r} (it must hold each of "
                             f"the {S} rows once, in step order)")
    out_arr = np.zeros(size, dtype=np.uint8)
    if S < 3:
        return None
    # how far each reading can lie: its range where valid, past everything where not; a
    # return as far as the drop-out angle reads it (numpy's exp and log, in numpy's order)
    far_arr = np.empty(size)
    cdef double[::1] far = far_arr
    cdef unsigned char[::1] out = out_arr
    for f in range(size):
        far[f] = d[f] if valid[f] else INFINITY
        if reason[f] == not_converged or reason[f] == incidence_unknown:
            n_ret += 1
    if n_ret:
        ret_arr = np.empty(n_ret)
        fe = ret_arr
        a = 0
        for q in range(S):
            for c in range(n_sensors):
                f = order[q] * n_sensors + c
                if reason[f] == not_converged or reason[f] == incidence_unknown:
                    fe[a] = counts[f]
                    a += 1
        fe = np.ascontiguousarray(far_end(ret_arr), dtype=float)
        if fe.shape[0] != n_ret:
            raise lengths_differ("edge_alone's far ends", returns=n_ret, far_end=fe.shape[0])
        a = 0
        for q in range(S):
            for c in range(n_sensors):
                f = order[q] * n_sensors + c
                if reason[f] == not_converged or reason[f] == incidence_unknown:
                    far[f] = fe[a] if isfinite(fe[a]) else INFINITY
                    a += 1
    for q in range(1, S - 1):
        for c in range(n_sensors):
            f = order[q] * n_sensors + c
            if not (valid[f] and label[f] >= 0):
                continue
            lim = d[f] - jump_m
            alone = True
            near_any = False
            for side in range(2):        # the step before it, then the step after
                a = order[q - 1 + 2 * side] * n_sensors + c
                rn = far[a]
                near = rn <= lim
                near_any = near_any or near
                if (valid[a] and label[a] == label[f]) or not (near or not valid[a]):
                    alone = False
            if alone and near_any:
                out[f] = 1
                found = True
    return out_arr if found else None
