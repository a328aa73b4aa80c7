"""Lines fitted to their members' counts through the sensor model: the lines their members'
counts contradict (:func:`counts_contradicted`, compiled :func:`counts_contradicted_compiled`),
their members off them (:func:`counts_disown_lines`) or split into the two pieces the counts
fit (:func:`counts_pieces`; the fits :class:`CountsFits` in numpy, :class:`CountsFitKernels`
compiled). Why and what was measured: docs/estimator.md, "A line its counts contradict" and
"A contradicted line's pieces".
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ..core import Points, Reason, points_with
from ..resources import kernel
from .calibration import SIGMA_FLOOR_M, Calibration
from .arcs import members_on_arcs
from .bounds import kept_where_bounded
from .lines import PINNED_RAD, placed_at
from .profiles import AGAIN_SIGMA_M, leave_doubted_line, own_slope_sigma, profiles_compiled


_lines = kernel("estimation._lines")


COUNTS_MIN_MEMBERS = 8  # a line of at least this many valid members is asked …
COUNTS_Z = 4.0  # … whether its members' counts misfit it this many normal σ (χ², p ≈ 3e-5)
COUNTS_SINGLE = 4.0  # … leaving out members each misfit by this many count σ
COUNTS_FLOOR_M = SIGMA_FLOOR_M  # a count σ no smaller than this range's change


def counts_misfit_z(chi2: np.ndarray, dof: np.ndarray) -> np.ndarray:
    """The normal deviate of χ² with ``dof`` degrees of freedom (Wilson–Hilferty cube
    root; within 0.11 of the exact deviate up to z = 4.5 for 6 or more degrees of freedom)."""
    k = np.asarray(dof, dtype=float)
    v = 2.0 / (9.0 * k)
    return (np.cbrt(np.asarray(chi2, dtype=float) / k) - (1.0 - v)) / np.sqrt(v)


def _counts_sigma(cal: Calibration, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(d at θ = 0, count σ) of counts ``s``: the counts' noise, but no smaller than the
    change ``COUNTS_FLOOR_M`` of range makes there (no reading is trusted better than that in
    range: the pose, the beam's direction)."""
    _, b0 = cal._ab0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        d0 = cal.distance(s, 0.0)
        # (np.nan_to_num's NaN → 0 and ±inf → ±max float, in two cheaper calls)
        sig = np.fmax(cal.sigma_counts(), np.minimum(s / (np.abs(b0) * d0),
                                                     np.finfo(float).max) * COUNTS_FLOOR_M)
    return d0, sig


def _counts_at(cal: Calibration, alpha, c, ox, oy, cos_h, sin_h):
    """The counts a line (direction ``alpha``, offset ``c`` along its normal) returns to
    each beam, and whether the beam meets it ahead within the drop-out angle."""
    nx, ny = -np.sin(alpha), np.cos(alpha)
    along = cos_h * nx + sin_h * ny
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = (c - ox * nx - oy * ny) / along
        expect = cal.counts(t, np.arccos(np.minimum(np.abs(along), 1.0)))
    met = (t > 0) & (np.abs(along) > math.cos(cal.max_incidence_rad)) & np.isfinite(expect)
    return np.where(met, expect, 0.0), met


COUNTS_FIT_STEPS = 8  # Gauss–Newton steps of the line fitted to its members' counts
COUNTS_SCALE_LINES = 3  # a sweep of this many asked lines scales the count noise by theirs
_COUNTS_DA, _COUNTS_DC = 1e-5, 1e-6  # central-difference steps (rad, m) of its Jacobian


def _counts_asked(points: Points, label: np.ndarray, vi: np.ndarray, counts: np.ndarray,
                  cal: Calibration, alpha: np.ndarray, cx: np.ndarray, cy: np.ndarray):
    """:func:`counts_contradicted`'s first question (its arguments): None where no line
    asked misfits its members' counts as fitted, unscaled (then none is contradicted);
    else what the rest of it reads (per member asked: line, counts, count σ, beam; per
    line: direction, offset, the members kept, asked, χ², degrees of freedom)."""
    n_lines = alpha.size
    lab = label.reshape(-1)[vi]
    member = (lab >= 0).nonzero()[0]
    if member.size == 0:
        return None
    line = lab[member]
    total = np.bincount(line, minlength=n_lines)
    ask = (total >= COUNTS_MIN_MEMBERS)[line]
    if not ask.any():
        return None
    at, line = vi[member[ask]], line[ask]
    h = points.heading.reshape(-1)[at]
    beam = (points.origin_x.reshape(-1)[at], points.origin_y.reshape(-1)[at], np.cos(h),
            np.sin(h))
    s = np.asarray(counts, dtype=float).reshape(-1)[at]
    sig = _counts_sigma(cal, s)[1]
    a = np.asarray(alpha, dtype=float).copy()
    c = -np.sin(a) * cx + np.cos(a) * cy
    expect, met = _counts_at(cal, a[line], c[line], *beam)
    # a line some member's beam cannot meet is judged elsewhere (corners, silence)
    unmet = np.bincount(line, weights=~met, minlength=n_lines) > 0
    r = (s - expect) / sig
    # a member the line misfits on its own is another surface's (a neighbouring face):
    # the question is whether a line explains the rest
    kept = met & (np.abs(r) < COUNTS_SINGLE)
    n_kept = np.bincount(line, weights=kept, minlength=n_lines)
    asked = (n_kept >= COUNTS_MIN_MEMBERS) & ~unmet
    if not asked.any():
        return None
    # the noise the sweep's own lines show, where it exceeds the calibration's (a curve
    # fitted less well than its repeat noise says, a noisier part): their median reduced χ²
    # about their lines as fitted
    chi2 = np.bincount(line, weights=np.where(kept, r * r, 0.0), minlength=n_lines)
    dof = np.maximum(n_kept - 2, 1)
    # the scale is at least 1: where no line misfits unscaled, none misfits scaled
    if not (asked & (counts_misfit_z(chi2, dof) >= COUNTS_Z)).any():
        return None
    return line, s, sig, beam, a, c, kept, asked, chi2, dof


def counts_contradicted(points: Points, label: np.ndarray, vi: np.ndarray, counts: np.ndarray,
                        cal: Calibration, alpha: np.ndarray, cx: np.ndarray, cy: np.ndarray,
                        fits: type[CountsFits] | None = None) -> np.ndarray:
    """The lines (L,) bool whose valid members' counts (``vi``: the valid readings; ``label``
    their lines as fitted: direction ``alpha``, through (``cx``, ``cy``)) no line near it
    explains through the sensor model (each beam's range and incidence at the line,
    ``cal.counts``): the line refitted to the counts (Gauss–Newton in direction and offset
    from the fitted one) still leaves χ² over ``cal.sigma_counts()`` at least ``COUNTS_Z``
    normal σ above n − 2 degrees of freedom (σ scaled up by the square root of the median
    reduced χ² of the sweep's asked lines as fitted, where there are ``COUNTS_SCALE_LINES``
    or more and it exceeds 1; only lines that misfit as fitted are refitted). Members the
    fitted line misfits by ``COUNTS_SINGLE`` count σ or more each are left out; lines of
    ``COUNTS_MIN_MEMBERS`` or more such members whose beams all meet the fitted line within
    the drop-out angle. ``fits``: the refit (:class:`CountsFits`, numpy's, by default)."""
    n_lines = alpha.size
    out = np.zeros(n_lines, dtype=bool)
    first = _counts_asked(points, label, vi, counts, cal, alpha, cx, cy)
    if first is None:
        return out
    line, s, sig, beam, a, c, kept, asked, chi2, dof = first
    scale = (max(1.0, float(np.median(chi2[asked] / dof[asked])))
             if asked.sum() >= COUNTS_SCALE_LINES else 1.0)
    # a refit only lowers χ²: only the lines that misfit as fitted are refitted
    asked &= counts_misfit_z(chi2 / scale, dof) >= COUNTS_Z
    if not asked.any():
        return out
    sel = kept & asked[line]
    line, s, sig = line[sel], s[sel], sig[sel]
    beam = tuple(v[sel] for v in beam)

    best = (fits or CountsFits).refit(cal, n_lines, line, s, sig, beam, a, c, asked,
                                      COUNTS_FIT_STEPS)[2]
    z = counts_misfit_z(best[asked] / scale, dof[asked])
    out[asked] = z >= COUNTS_Z
    return out


def _counts_jacobian(cal: Calibration, alpha: np.ndarray, c: np.ndarray, beam: tuple
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The counts' derivatives in a line's direction and offset (per reading, the line
    ``alpha``, ``c`` given for each; ``beam``: origin x, y, cos, sin of its heading), by
    central differences of ``_COUNTS_DA`` rad and ``_COUNTS_DC`` m."""
    ja = (_counts_at(cal, alpha + _COUNTS_DA, c, *beam)[0]
          - _counts_at(cal, alpha - _COUNTS_DA, c, *beam)[0]) / (2 * _COUNTS_DA)
    jc = (_counts_at(cal, alpha, c + _COUNTS_DC, *beam)[0]
          - _counts_at(cal, alpha, c - _COUNTS_DC, *beam)[0]) / (2 * _COUNTS_DC)
    return ja, jc


def _counts_refit(cal: Calibration, n_lines: int, line: np.ndarray, s: np.ndarray,
                  sig: np.ndarray, beam: tuple, a: np.ndarray, c: np.ndarray,
                  asked: np.ndarray, steps: int, settled: tuple | None = None):
    """Lines (direction ``a``, offset ``c``, (n_lines,)) refitted to their members' counts
    ``s`` (σ ``sig``; ``line``: each member's line; ``beam``: origin x, y, cos, sin of its
    heading) by Gauss–Newton, at most ``steps`` steps, only the lines ``asked``: (a, c, χ²)
    (χ² inf where a member's beam misses its line within the drop-out angle).
    ``settled`` (rad, m): done once no step moves a line by more than these."""
    def chi2_of(a_, c_):
        e, m = _counts_at(cal, a_[line], c_[line], *beam)
        q = np.bincount(line, weights=((s - e) / sig) ** 2, minlength=n_lines)
        return np.where(np.bincount(line, weights=~m, minlength=n_lines) > 0, np.inf, q), e

    best, e0 = chi2_of(a, c)
    for _ in range(steps):
        ja, jc = _counts_jacobian(cal, a[line], c[line], beam)
        res = s - e0
        saa, sac, scc = (np.bincount(line, weights=w, minlength=n_lines)
                         for w in (ja * ja, ja * jc, jc * jc))
        ga, gc = (np.bincount(line, weights=w * res, minlength=n_lines) for w in (ja, jc))
        det = saa * scc - sac * sac
        ok = asked & np.isfinite(det) & (det > 1e-12 * np.maximum(saa * scc, 1e-300))
        with np.errstate(divide="ignore", invalid="ignore"):
            da = np.where(ok, (scc * ga - sac * gc) / det, 0.0)
            dc = np.where(ok, (saa * gc - sac * ga) / det, 0.0)
        # a step that does not lower χ² is halved (up to four times), else not taken
        small = settled is not None and bool(np.all((np.abs(da) <= settled[0])
                                                    & (np.abs(dc) <= settled[1])))
        moved = np.zeros(n_lines, dtype=bool)
        for _half in range(5):
            trial, _ = chi2_of(a + da, c + dc)
            better = ok & (trial < best)
            a, c = np.where(better, a + da, a), np.where(better, c + dc, c)
            best = np.where(better, trial, best)
            moved |= better
            ok &= ~better
            if not ok.any():
                break
            da, dc = 0.5 * da, 0.5 * dc
        if not moved.any() or small:
            break
        best, e0 = chi2_of(a, c)
    return a, c, best


def counts_contradicted_compiled(points: Points, label: np.ndarray, vi: np.ndarray,
                                 counts: np.ndarray, cal: Calibration, alpha: np.ndarray,
                                 cx: np.ndarray, cy: np.ndarray) -> np.ndarray:
    """:func:`counts_contradicted`, whose first question (:func:`_counts_asked`: does any
    line asked misfit as fitted?) is one compiled call
    (``irring.estimation._lines.counts_misfit_any``, held to it by
    tests/test_count_misfit.py); the rare sweep it answers yes is judged by
    :func:`counts_contradicted` itself, its refit compiled (:class:`CountsFitKernels`)."""
    f = np.ascontiguousarray
    la0, b0 = cal._ab0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        misfit = _lines.counts_misfit_any(
            f(vi, dtype=np.intp), f(label, dtype=np.intp).reshape(-1),
            f(points.heading, dtype=float).reshape(-1),
            f(points.origin_x, dtype=float).reshape(-1),
            f(points.origin_y, dtype=float).reshape(-1), f(counts, dtype=float).reshape(-1),
            f(alpha, dtype=float), f(cx, dtype=float), f(cy, dtype=float), float(la0),
            float(b0), cal.sigma_counts(), COUNTS_FLOOR_M, cal.theta_rad, cal._log_a, cal.b,
            math.cos(cal.max_incidence_rad), COUNTS_MIN_MEMBERS, COUNTS_SINGLE, COUNTS_Z)
    if not misfit:
        return np.zeros(np.asarray(alpha).size, dtype=bool)
    return counts_contradicted(points, label, vi, counts, cal, alpha, cx, cy, CountsFitKernels)


def counts_disown_lines(points: Points, label: np.ndarray, index: np.ndarray,
                        counts: np.ndarray, steps: np.ndarray, cal: Calibration,
                        alpha: np.ndarray, cx: np.ndarray, cy: np.ndarray,
                        profiler: Callable | None = None, judge: Callable | None = None,
                        fitter: type[CountsFits] | None = None) -> tuple[Points, np.ndarray]:
    """Every member of a line its members' counts contradict (:func:`counts_contradicted`)
    off it: at its own profile's θ where that is straight and clearly steep, else
    INCIDENCE_UNKNOWN (:func:`leave_doubted_line`) but where its profile bounds θ enough
    for θ = 0 (:func:`irring.estimation.bounds.kept_where_bounded`); shared by both
    estimators (``judge``: :func:`counts_contradicted_compiled` by default; the oracle
    passes :func:`counts_contradicted`; ``fitter``: :func:`counts_pieces`' fits,
    :class:`CountsFitKernels` by default). Returns the points and ``label``. Why:
    docs/estimator.md ("A line its counts contradict"): a convex corner seen along its
    bisector near the range limit reads, at θ = 0, like a flat wall square on, and the
    iteration settles there."""
    vi = index[points.valid.reshape(-1)[index]]
    if vi.size == 0 or alpha.size == 0:
        return points, label
    bad = (judge or counts_contradicted_compiled)(points, label, vi, counts, cal, alpha, cx, cy)
    if not bad.any():
        return points, label
    lab = label.reshape(-1)[vi]
    pos = ((lab >= 0) & bad[np.maximum(lab, 0)]).nonzero()[0]
    pr = (profiler or profiles_compiled)(points, vi, pos, counts, steps, cal)
    # (one sensor's run across a pillar: on its arc, where one fits)
    points, label, taken = members_on_arcs(points, label, vi, pos, pr, cal)
    points, label = leave_doubted_line(points, label, vi, pos[~taken], pr, ~taken, cal)
    points = counts_pieces(points, vi[pos], lab[pos], counts, cal, pr.convex,
                           fitter or CountsFitKernels)
    kept = kept_where_bounded(points, vi, pos, pr, cal)
    if kept is not None:     # valid again, at θ = 0 with the doubt in σ
        at, d0, sigma = kept
        points = placed_at(points, at, d0, 0.0, sigma)
        valid, reason = points.valid.copy(), np.array(points.reason)
        valid.reshape(-1)[at], reason.reshape(-1)[at] = True, Reason.OK
        points = points_with(points, valid=valid, reason=reason)
    return points, label


PIECE_MIN = COUNTS_MIN_MEMBERS  # a contradicted line's piece: at least this many members …
PIECE_LEVELS = 4  # … split in two at most this often (pieces of 8-16 of 128 members) …
PIECE_FIT_STEPS = COUNTS_FIT_STEPS  # … each fitted to its counts from its θ = 0 line;
PIECE_SETTLED = (1e-3, 1e-4)  # … until no step moves a piece more than this (rad, m)
PIECE_F = 10.0  # a fitted piece's halves replace it where they fit its counts this much better
PIECE_BENT_SHARE = 0.25  # a piece whose members' profiles bend away more often is no line
PIECE_SWITCH = 1.0  # an end member takes the next piece's line where it misfits it this much less


def _counts_misfit_one(cal: Calibration, alpha, c, s, sig, ox, oy, ch, sh) -> np.ndarray:
    """Each reading's squared counts misfit (in count σ ``sig``) to the line (``alpha``,
    ``c``) given for it; inf where its beam misses the line within the drop-out angle."""
    with np.errstate(invalid="ignore"):
        e, met = _counts_at(cal, alpha, c, ox, oy, ch, sh)
    return np.where(met, ((s - e) / sig) ** 2, np.inf)


def _best_halves(x: np.ndarray, y: np.ndarray, lo: int) -> int:
    """Where the points ``x``, ``y`` (in order) split into two runs of at least ``lo``
    points whose total-least-squares lines leave the least squared residual: the first
    point of the second run."""
    n = x.size
    u, v = x - x.mean(), y - y.mean()      # (centred: the running sums lose no digits)
    px, py = np.cumsum(u), np.cumsum(v)
    pxx, pyy, pxy = np.cumsum(u * u), np.cumsum(v * v), np.cumsum(u * v)
    k = np.arange(lo, n - lo + 1)

    def rss(m, sx, sy, sxx, syy, sxy):
        a, b, c = sxx - sx * sx / m, syy - sy * sy / m, sxy - sx * sy / m
        return 0.5 * (a + b) - np.sqrt(0.25 * (a - b) ** 2 + c * c)

    left = rss(k, px[k - 1], py[k - 1], pxx[k - 1], pyy[k - 1], pxy[k - 1])
    right = rss(n - k, px[-1] - px[k - 1], py[-1] - py[k - 1], pxx[-1] - pxx[k - 1],
                pyy[-1] - pyy[k - 1], pxy[-1] - pxy[k - 1])
    return int(k[np.argmin(left + right)])


def _counts_at_compiled(cal: Calibration, alpha, c, ox, oy, cos_h, sin_h):
    """:func:`_counts_at` in one compiled call (``irring.estimation._lines.counts_at``)."""
    f = np.ascontiguousarray
    size = np.asarray(alpha).size
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return _lines.counts_at(*(f(np.broadcast_to(v, size), dtype=float)
                                  for v in (alpha, c, ox, oy, cos_h, sin_h)),
                                cal.theta_rad, cal._log_a, cal.b, math.cos(cal.max_incidence_rad))


class CountsFits:
    """Lines fitted to their members' counts through the sensor model, as numpy statements:
    :func:`_counts_refit`, :func:`_counts_jacobian`, :func:`_counts_misfit_one`, and where
    a piece splits, :func:`_best_halves` (the oracle's, and the readable statement of
    :class:`CountsFitKernels`)."""
    refit = staticmethod(_counts_refit)
    jacobian = staticmethod(_counts_jacobian)
    misfit = staticmethod(_counts_misfit_one)
    halves = staticmethod(_best_halves)


class CountsFitKernels(CountsFits):
    """:class:`CountsFits` in compiled calls (``irring.estimation._lines.counts_refit``,
    ``counts_jacobian``, ``counts_at``, ``best_halves``; arccos, log, exp numpy's on their
    rows, the halves' means numpy's), the same numbers to the bit
    (tests/test_counts_fits.py). Why: docs/speed.md, "A contradicted line's pieces"."""

    @staticmethod
    def refit(cal: Calibration, n_lines: int, line: np.ndarray, s: np.ndarray, sig: np.ndarray,
              beam: tuple, a: np.ndarray, c: np.ndarray, asked: np.ndarray, steps: int,
              settled: tuple | None = None):
        f = np.ascontiguousarray
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return _lines.counts_refit(
                f(line, dtype=np.intp), f(s, dtype=float), f(sig, dtype=float),
                *(f(v, dtype=float) for v in beam), f(a, dtype=float), f(c, dtype=float),
                f(asked, dtype=bool).view(np.uint8), steps, settled is not None,
                *(settled or (0.0, 0.0)), cal.theta_rad, cal._log_a, cal.b,
                math.cos(cal.max_incidence_rad), _COUNTS_DA, _COUNTS_DC)

    @staticmethod
    def jacobian(cal: Calibration, alpha: np.ndarray, c: np.ndarray, beam: tuple):
        f = np.ascontiguousarray
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return _lines.counts_jacobian(
                f(alpha, dtype=float), f(c, dtype=float), *(f(v, dtype=float) for v in beam),
                cal.theta_rad, cal._log_a, cal.b, math.cos(cal.max_incidence_rad), _COUNTS_DA,
                _COUNTS_DC)

    @staticmethod
    def halves(x: np.ndarray, y: np.ndarray, lo: int) -> int:
        return _lines.best_halves(x - x.mean(), y - y.mean(), lo)

    @staticmethod
    def misfit(cal: Calibration, alpha, c, s, sig, ox, oy, ch, sh) -> np.ndarray:
        e, met = _counts_at_compiled(cal, alpha, c, ox, oy, ch, sh)
        return np.where(met, ((s - e) / sig) ** 2, np.inf)


def counts_pieces(points: Points, at: np.ndarray, line: np.ndarray, counts: np.ndarray,
                  cal: Calibration, bent: np.ndarray, fitter: type[CountsFits] | None = None
                  ) -> Points:
    """The members ``at`` (flat, in scan order; ``line``: the contradicted line of each;
    ``bent``: whether its range profile bends away from its beam) that leaving their line
    made INCIDENCE_UNKNOWN, placed on a piece of it their counts explain. A piece is one
    sensor's run of a line's members (not asked where more than ``PIECE_BENT_SHARE`` of it
    is ``bent``), fitted to its counts (:func:`_counts_refit`) and, where they contradict
    it (``COUNTS_Z``), halved where two lines fit best (:func:`_best_halves`; ``PIECE_MIN``
    members a half, ``PIECE_LEVELS`` times at most). A lost member of a piece its counts fit
    is read at the incidence its beam meets the piece's line with, placed where its σ ≤
    ``AGAIN_SIGMA_M`` and θ is not pinned at the drop-out angle. Numpy, shared by both
    estimators; ``fitter``: its fits to the counts (:class:`CountsFits`, numpy's, by default).
    Why and the rule in full: docs/estimator.md, "A contradicted line's pieces"."""
    lost = points.reason.reshape(-1)[at] == Reason.INCIDENCE_UNKNOWN
    if not lost.any():
        return points
    fitter = fitter or CountsFits
    n_sensors = points.valid.shape[1]
    key = line * n_sensors + at % n_sensors
    order = np.argsort(key, kind="stable")        # each run stays in scan order
    at, key, lost, bent = at[order], key[order], lost[order], bent[order]
    cut = np.flatnonzero(np.diff(key)) + 1
    # a run of profiles bent away from the beam is a convex thing's (a box's corner seen
    # tip on reads like a wall square on), not facets: not asked
    pieces = [(a, b) for a, b in zip(np.concatenate([[0], cut]).tolist(),
                                     np.concatenate([cut, [key.size]]).tolist())
              if b - a >= PIECE_MIN and lost[a:b].any()
              and np.count_nonzero(bent[a:b]) <= PIECE_BENT_SHARE * (b - a)]
    if not pieces:
        return points
    # a sensor turning a full turn meets its first step again after its last: a run across
    # that seam starts after its widest gap in heading instead
    turn = np.arange(at.size)
    h = points.heading.reshape(-1)[at]
    for a, b in pieces:
        gap = np.mod(np.diff(np.append(h[a:b], h[a])), 2 * math.pi)
        widest = int(np.argmax(gap))
        if widest < b - a - 1:
            turn[a:b] = np.roll(turn[a:b], -(widest + 1))
    at, lost, bent = at[turn], lost[turn], bent[turn]
    s = np.asarray(counts, dtype=float).reshape(-1)[at]
    d0, sig = _counts_sigma(cal, s)
    h = points.heading.reshape(-1)[at]
    ox, oy = points.origin_x.reshape(-1)[at], points.origin_y.reshape(-1)[at]
    ch, sh = np.cos(h), np.sin(h)
    x0, y0 = ox + d0 * ch, oy + d0 * sh
    if not (np.isfinite(x0).all() and np.isfinite(y0).all()):
        return points
    place = np.zeros(at.size, dtype=bool)
    dtheta = np.full(at.size, np.nan)
    line_ac = np.full((2, at.size), np.nan)   # each member's piece's line: direction, offset
    ends = np.zeros((2, at.size), dtype=np.intp)  # … and that piece's first, last member
    # (start, end, χ² of the fitted piece it halves, or NaN: none fitted)
    pieces = [(a, b, np.nan, (np.nan, np.nan)) for a, b in pieces]
    for level in range(PIECE_LEVELS + 1):
        n_p = len(pieces)
        pid = np.full(at.size, -1, dtype=np.intp)
        for i, (a, b, _, _) in enumerate(pieces):
            pid[a:b] = i
        m = (pid >= 0).nonzero()[0]
        g = pid[m]
        w = np.bincount(g, minlength=n_p).astype(float)
        mx, my = (np.bincount(g, weights=v[m], minlength=n_p) / w for v in (x0, y0))
        ux, uy = x0[m] - mx[g], y0[m] - my[g]
        sxx, syy, sxy = (np.bincount(g, weights=v, minlength=n_p)
                         for v in (ux * ux, uy * uy, ux * uy))
        alpha = 0.5 * np.arctan2(2 * sxy, sxx - syy)
        c = -np.sin(alpha) * mx + np.cos(alpha) * my
        # a half starts from the line its whole settled on (nearer than its θ = 0 line)
        start = np.array([q[3] for q in pieces], dtype=float).reshape(n_p, 2)
        has = np.isfinite(start[:, 0])
        alpha, c = np.where(has, start[:, 0], alpha), np.where(has, start[:, 1], c)
        # fitted about each piece's centroid: offset and direction then hardly couple
        shift = -np.sin(alpha) * mx + np.cos(alpha) * my
        beam = (ox[m] - mx[g], oy[m] - my[g], ch[m], sh[m])
        alpha, c, chi2 = fitter.refit(cal, n_p, g, s[m], sig[m], beam, alpha, c - shift,
                                      np.ones(n_p, dtype=bool), PIECE_FIT_STEPS, PIECE_SETTLED)
        c = c + (-np.sin(alpha) * mx + np.cos(alpha) * my)
        beam = (ox[m], oy[m], ch[m], sh[m])
        with np.errstate(invalid="ignore"):
            fits = np.isfinite(chi2) & (counts_misfit_z(chi2, w - 2) < COUNTS_Z)
        # a convex corner's tip fits a line square on: no piece of bent profiles is one
        fits &= np.bincount(g, weights=bent[m], minlength=n_p) <= PIECE_BENT_SHARE * w
        # halves of a piece its counts fitted count only where they fit clearly better:
        # two lines against one, F on (2, n − 4) degrees of freedom (a facet corner)
        parent = np.array([q[2] for q in pieces])
        halved = np.isfinite(parent)
        if halved.any():     # (past level 0 the pieces come in pairs of halves)
            both = np.repeat(chi2[0::2] + chi2[1::2], 2)
            nn = np.repeat(w[0::2] + w[1::2], 2)
            with np.errstate(divide="ignore", invalid="ignore"):
                f_stat = 0.5 * (parent - both) / (both / (nn - 4))
            better = ~halved | (f_stat >= PIECE_F)
            fits &= better
        else:
            better = np.ones(n_p, dtype=bool)
        if fits.any():
            # the direction's standard error from the counts' weighted Jacobian there
            ja, jc = fitter.jacobian(cal, alpha[g], c[g], beam)
            ja, jc = ja / sig[m], jc / sig[m]
            saa, sac, scc = (np.bincount(g, weights=v, minlength=n_p)
                             for v in (ja * ja, ja * jc, jc * jc))
            with np.errstate(divide="ignore", invalid="ignore"):
                var_a = scc / (saa * scc - sac * sac) * np.fmax(1.0, chi2 / (w - 2))
            took = fits[g]
            mt, gt = m[took], g[took]
            line_ac[:, mt] = alpha[gt], c[gt]
            ends[:, mt] = (np.array([q[0] for q in pieces])[gt],
                           np.array([q[1] for q in pieces])[gt] - 1)
            dtheta[mt] = np.sqrt(var_a[gt])
            place[mt] = True
        if level == PIECE_LEVELS:
            break
        halves = []
        for i in better.nonzero()[0]:     # (a halved piece no better than whole: done)
            a, b, _, _ = pieces[i]
            if b - a >= 2 * PIECE_MIN and lost[a:b].any():
                k = a + fitter.halves(x0[a:b], y0[a:b], PIECE_MIN)
                fitted = chi2[i] if fits[i] else np.nan
                line_i = (alpha[i], c[i]) if np.isfinite(chi2[i]) else (np.nan, np.nan)
                halves += [(a, k, fitted, line_i), (k, b, fitted, line_i)]
        pieces = halves
        if not pieces:
            break
    if not place.any():
        return points
    # a member may belong to the next piece: it takes the line of the piece before or after
    # its own (in its run) where its counts explain it clearly better. Every member is asked,
    # not only a piece's ends (measured: ends only, the D-room's RMS 17.0 -> 16.8 mm in one
    # seed, 20.1 -> 21.5 mm in another)
    best = fitter.misfit(cal, line_ac[0], line_ac[1], s, sig, ox, oy, ch, sh)
    for side, step in ((0, -1), (1, 1)):
        j = np.clip(ends[side] + step, 0, at.size - 1)
        ask = place & (key[j] == key) & place[j] & (ends[side] + step == j)
        if not ask.any():
            continue
        r = fitter.misfit(cal, line_ac[0, j], line_ac[1, j], s, sig, ox, oy, ch, sh)
        move = ask & (r < best - PIECE_SWITCH)
        line_ac[:, move], dtheta[move], best[move] = line_ac[:, j[move]], dtheta[j[move]], r[move]
    along = ch * -np.sin(line_ac[0]) + sh * np.cos(line_ac[0])
    theta = np.arccos(np.minimum(np.abs(along), 1.0))
    place &= lost & np.isfinite(theta) & np.isfinite(dtheta)
    if not place.any():
        return points
    at, s, theta, dtheta = at[place], s[place], theta[place], dtheta[place]
    lo, hi = np.maximum(theta - dtheta, 0.0), np.minimum(theta + dtheta, cal.max_incidence_rad)
    d, d_lo, d_hi = cal.distance(np.concatenate([s, s, s]),
                                 np.concatenate([theta, lo, hi])).reshape(3, -1)
    sigma, ok = own_slope_sigma(cal, theta, d, d_lo, d_hi, cal.sigma_counts() / s)
    ok &= (sigma <= AGAIN_SIGMA_M) & (theta < cal.max_incidence_rad - PINNED_RAD) & (
        d <= points.max_range_m)
    if not ok.any():
        return points
    at = at[ok]
    points = placed_at(points, at, d[ok], theta[ok], sigma[ok])
    valid, reason = points.valid.copy(), np.array(points.reason)
    valid.reshape(-1)[at], reason.reshape(-1)[at] = True, Reason.OK
    return points_with(points, valid=valid, reason=reason)
