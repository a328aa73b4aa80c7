"""A sensor's trace: line members that a better-held line their own sensor's trace continues on
places, moved to it (:func:`rejoin_traces`, its steps :class:`TraceSteps` in numpy and
:class:`TraceKernels` compiled), and the far lines a usable line's trace runs into first
(:func:`vague_far_lines`). Why and what was measured: docs/estimator.md, "Traces" and "Vague
far lines".
"""

from __future__ import annotations

import math

import numpy as np

from ..core import Points, rows_in_step_order
from ..resources import kernel
from .calibration import SIGMA_FLOOR_M, Calibration, range_sigma
from .lines import LineOptions, direction_se, placed_at, read_to_own_range, scan_order, unplaced


_lines = kernel("estimation._lines")


TRACE_ROUNDS = 64   # at most this many readings a trace carries its line across, each way
TRACE_CORNER_RAD = math.radians(30)  # lines meeting at more than this make a corner
TRACE_LOOSE = 2.0   # a line whose members scatter this many times more than another's …
TRACE_LOOSE_MIN_M = 0.005  # … and by more than this (half a map cell) is looser
TRACE_ON_SIGMAS = 2.5  # a reading re-read at a line's θ lies on it within this many σ (≥ 10 mm)
TRACE_SKIP = 2      # a trace links readings across at most this many of its readings on no line


def _past_a_corner(qx: np.ndarray, qy: np.ndarray, ox: np.ndarray, oy: np.ndarray,
                   line: np.ndarray, other: np.ndarray, alpha: np.ndarray, cx: np.ndarray,
                   cy: np.ndarray, lo: np.ndarray, hi: np.ndarray, mx: np.ndarray,
                   my: np.ndarray, options: LineOptions) -> np.ndarray:
    """(k, m) bool: whether points (qx, qy) (k,) put on lines ``line`` lie past the corner
    their line makes with lines ``other`` ((k, m) or (1, m)): the two met at more than
    ``TRACE_CORNER_RAD`` within ``corner_reach_m`` (or ``corner_reach_share`` of the
    corner's distance from the points' emitters ``ox``, ``oy``, where more) of both lines'
    member extents (``lo``, ``hi`` along each line from its point ``cx``, ``cy``), the point
    on the other line's far side from its own line's members (their mean ``mx``, ``my``).
    A wall ends at its corner: read past it, a reading would sit behind the other wall."""
    ca, sa = np.cos(alpha), np.sin(alpha)
    b = line[:, None]
    c = other
    # (parallel lines meet nowhere: inf and nan compare False below)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # where line c meets line b, along each from its point
        wx, wy = cx[c] - cx[b], cy[c] - cy[b]
        cross = ca[b] * sa[c] - sa[b] * ca[c]
        tb = (wx * sa[c] - wy * ca[c]) / cross
        tc = (wx * sa[b] - wy * ca[b]) / cross
        # the reach grows with the corner's distance from the emitter (a far corner's
        # drop-out gap is wider: docs/estimator.md, "A far corner")
        reach = np.maximum(options.corner_reach_m, options.corner_reach_share * np.hypot(
            cx[b] + tb * ca[b] - ox[:, None], cy[b] + tb * sa[b] - oy[:, None]))
    side_b = (my[b] - cy[c]) * ca[c] - (mx[b] - cx[c]) * sa[c]
    side_q = (qy[:, None] - cy[c]) * ca[c] - (qx[:, None] - cx[c]) * sa[c]
    return ((np.abs(cross) > math.sin(TRACE_CORNER_RAD))
            & (tb >= lo[b] - reach) & (tb <= hi[b] + reach)
            & (tc >= lo[c] - reach) & (tc <= hi[c] + reach)
            & (side_b * side_q < 0) & (np.abs(side_q) > options.min_split_m))


def _trace_moves(ask: np.ndarray, i: np.ndarray, j: np.ndarray, a: np.ndarray,
                 b: np.ndarray, run_lo: np.ndarray, run_hi: np.ndarray, kx: np.ndarray,
                 ky: np.ndarray, counts: np.ndarray, h: np.ndarray, ox: np.ndarray,
                 oy: np.ndarray, alpha: np.ndarray, cx: np.ndarray, cy: np.ndarray,
                 lo: np.ndarray, hi: np.ndarray, mx: np.ndarray, my: np.ndarray,
                 n_mem: np.ndarray, good: np.ndarray, cal: Calibration, max_range_m: float,
                 options: LineOptions, to_corner: bool):
    """One round of :func:`rejoin_traces`: for the frontier pairs ``ask`` (reading ``i`` on
    line ``a``, its neighbour ``j`` on line ``b``), the run of ``a``'s readings from ``i``
    away from ``j`` (its run's bounds ``run_lo``, ``run_hi``, in scan order) as far as each,
    read at the incidence its beam meets ``b`` with, lies on ``b`` (within
    ``TRACE_ON_SIGMAS`` σ; within ``adopt_margin_m`` of ``b``'s members' extent ``lo``..``hi``
    along it from its point ``cx``, ``cy``, grown by the run's readings before it, or up to
    its corner with ``a`` where ``to_corner``, each then past that corner: their end points
    ``kx``, ``ky``), not past a corner ``b`` makes (:func:`_past_a_corner`; ``mx``, ``my``:
    the members' mean); a reading two runs take goes where it lies closer. (readings,
    targets, d, θ, σ), or None."""
    if not ask.any():
        return None
    i, j, a, b = i[ask], j[ask], a[ask], b[ask]
    step = np.where(i > j, 1, -1)
    span = np.where(step > 0, run_hi[i] - i, i - run_lo[i]) + 1
    t = np.arange(min(int(span.max()), TRACE_ROUNDS))
    e = i[:, None] + step[:, None] * t          # (P, T) the run, outward from i
    inside = t < span[:, None]
    e = np.where(inside, e, i[:, None])
    bb = b[:, None].repeat(e.shape[1], axis=1)   # (np.broadcast_to costs more)
    ca, sa = np.cos(alpha), np.sin(alpha)
    theta = np.arccos(np.minimum(np.abs(np.sin(h[e] - alpha[bb])), 1.0))
    d = cal.distance(counts[e], theta)
    _, bexp = cal.log_ab(theta)
    sigma = np.maximum(np.abs(bexp) * d * cal.sigma_counts() / counts[e], SIGMA_FLOOR_M)
    qx, qy = ox[e] + d * np.cos(h[e]), oy[e] + d * np.sin(h[e])
    perp = np.abs((qy - cy[bb]) * ca[bb] - (qx - cx[bb]) * sa[bb])
    u = (qx - cx[bb]) * ca[bb] + (qy - cy[bb]) * sa[bb]
    thr = np.maximum(TRACE_ON_SIGMAS * sigma, options.min_split_m)
    first, last = lo[b], hi[b]
    if to_corner:   # across a corner the target runs on to it
        with np.errstate(divide="ignore", invalid="ignore"):
            tx = (((cx[a] - cx[b]) * sa[a] - (cy[a] - cy[b]) * ca[a])
                  / (ca[b] * sa[a] - sa[b] * ca[a]))
        first, last = np.fmin(first, tx), np.fmax(last, tx)
    # the extent grows by the run's readings before each
    # (np.concatenate, not np.r_ / np.c_: those cost more than the arithmetic here)
    grow_lo = np.minimum(first[:, None], np.minimum.accumulate(
        np.concatenate((np.full((len(i), 1), np.inf), u[:, :-1]), axis=1), axis=1))
    grow_hi = np.maximum(last[:, None], np.maximum.accumulate(
        np.concatenate((np.full((len(i), 1), -np.inf), u[:, :-1]), axis=1), axis=1))
    ok = (inside & (theta <= cal.max_incidence_rad) & np.isfinite(d)
          & (d >= cal.min_range_m) & (d <= max_range_m) & (perp <= thr)
          & (u >= grow_lo - options.adopt_margin_m) & (u <= grow_hi + options.adopt_margin_m))
    # a run moves only as far as each of it lies on b: the corner tests ask nothing past
    ok = np.logical_and.accumulate(ok, axis=1)
    if not ok.any():
        return None
    if to_corner:   # each of the run past its own line's corner with b
        w = ok.nonzero()
        ok[w] = _past_a_corner(kx[e[w]], ky[e[w]], ox[e[w]], oy[e[w]], a[w[0]],
                               b[w[0]][:, None], alpha, cx, cy, lo, hi, mx, my, options)[:, 0]
    if ok.any():
        w = ok.nonzero()
        corners = (good & (n_mem >= options.min_points)).nonzero()[0][None, :]
        ok[w] = ~_past_a_corner(qx[w], qy[w], ox[e[w]], oy[e[w]], b[w[0]], corners, alpha,
                                cx, cy, lo, hi, mx, my, options).any(axis=1)
    ok = np.logical_and.accumulate(ok, axis=1)  # as far as each of the run lies on b
    if not ok.any():
        return None
    # a reading two runs take: the target it lies closer to
    r, miss = e[ok], (perp / thr)[ok]
    order = np.lexsort((miss, r))
    pick = order[np.concatenate(([True], r[order][1:] != r[order][:-1]))]
    return (r[pick], bb[ok][pick], d[ok][pick], theta[ok][pick], sigma[ok][pick])


class TraceSteps:
    """:func:`rejoin_traces`' steps over its arrays, in numpy (``pairs`` once, then each
    round's frontier, ``round``, and what it moves, ``moves`` = :func:`_trace_moves`): the
    statement the compiled :class:`TraceKernels` is held to (tests/test_grazing.py)."""

    @staticmethod
    def pairs(vi: np.ndarray, lab: np.ndarray, steps: np.ndarray, n_sensors: int):
        """(joined (k − 1,) bool, reading, nbr): of the valid readings ``vi`` (flat (S·N)
        indices in scan order; ``lab`` their lines or −1), which follow their previous one
        at their sensor's next step; and each member's neighbouring reading of its sensor,
        both ways (all the previous ones first) as pairs (positions into ``vi``): the next
        valid reading, past at most ``TRACE_SKIP`` on no line (those never move)."""
        scan = scan_order(steps, n_sensors)
        pos = np.empty(scan.size, dtype=np.intp)
        pos[scan] = np.arange(scan.size)
        sensor = vi % n_sensors
        # valid readings of one sensor at consecutive steps (no invalid reading between)
        joined = (sensor[1:] == sensor[:-1]) & (pos[vi[1:]] - pos[vi[:-1]] == 1)
        k = vi.size
        ar = np.arange(k)
        reading, nbr = [], []
        for step, link in ((-1, np.concatenate(([False], joined))),
                           (1, np.concatenate((joined, [False])))):
            nb = np.where(link, ar + step, -1)
            for _ in range(TRACE_SKIP):
                on_none = (nb >= 0) & (lab[np.maximum(nb, 0)] < 0)
                nb = np.where(on_none, np.where(link[np.maximum(nb, 0)], nb + step, -1), nb)
            keep = (nb >= 0) & (lab >= 0)
            reading.append(ar[keep])
            nbr.append(nb[keep])
        return joined, np.concatenate(reading), np.concatenate(nbr)

    @staticmethod
    def round(lab, moved, joined, reading, nbr, good, lost, px, py, ox, oy, alpha, cx, cy,
              options: LineOptions):
        """One round's frontier and what it is judged by, or None where it is empty: the
        pairs (``reading`` on line a, ``nbr`` on another usable line b; not moved yet) as
        (i, j, a, b); each reading's run's bounds (run_lo, run_hi: consecutive readings of
        one sensor on one line, none moved or all); each line's members' count, mean,
        extent along it (lo, hi); and which pairs may move now: absorb (a's line weaker or
        gone: a line that ``lost`` more members than it kept takes none) and cross (a's
        reading past its line's corner with b)."""
        a, b = lab[reading], lab[nbr]
        f = ~moved[reading] & (b >= 0) & (b != a)
        f[f] = good[b[f]]
        if not f.any():
            return None
        i, j, a, b = reading[f], nbr[f], a[f], b[f]
        k, n_lines = lab.size, alpha.size
        new_run = np.concatenate(
            ([True], ~joined | (lab[1:] != lab[:-1]) | (moved[1:] != moved[:-1])))
        start = new_run.nonzero()[0]
        run = np.cumsum(new_run) - 1
        run_lo, run_hi = start[run], np.concatenate((start[1:] - 1, [k - 1]))[run]
        ca, sa = np.cos(alpha), np.sin(alpha)
        mem = lab >= 0
        g = lab[mem]
        n_mem = np.bincount(g, minlength=n_lines)
        nm = np.maximum(n_mem, 1)
        mx, my = np.bincount(g, px[mem], n_lines) / nm, np.bincount(g, py[mem], n_lines) / nm
        # each line's members' extent along it and their scatter across it
        along = (px[mem] - cx[g]) * ca[g] + (py[mem] - cy[g]) * sa[g]
        across = (py[mem] - cy[g]) * ca[g] - (px[mem] - cx[g]) * sa[g]
        lo, hi = np.full(n_lines, np.inf), np.full(n_lines, -np.inf)
        np.minimum.at(lo, g, along)
        np.maximum.at(hi, g, along)
        rms = np.sqrt(np.bincount(g, across * across, n_lines) / nm)
        gone = lost > n_mem
        f = ~gone[b]               # a line that gave up more than it kept takes none
        # first a weaker line's members (or a gone line's), then members past a corner
        absorb = f & (gone[a] | ((n_mem[a] < n_mem[b])
                                 & (rms[a] > np.maximum(TRACE_LOOSE * rms[b], TRACE_LOOSE_MIN_M))
                                 & (np.abs(np.sin(alpha[a] - alpha[b]))
                                    <= math.sin(TRACE_CORNER_RAD))))
        cross = f.copy()
        at = i[f]
        cross[f] = _past_a_corner(px[at], py[at], ox[at], oy[at], a[f], b[f][:, None],
                                  alpha, cx, cy, lo, hi, mx, my, options)[:, 0]
        return i, j, a, b, run_lo, run_hi, n_mem, mx, my, lo, hi, absorb, cross

    moves = staticmethod(_trace_moves)


class TraceKernels(TraceSteps):
    """:class:`TraceSteps` in compiled calls (``irring.estimation._lines.trace_pairs``,
    ``trace_round`` and ``trace_moves``, held to it by tests/test_grazing.py)."""

    @staticmethod
    def pairs(vi: np.ndarray, lab: np.ndarray, steps: np.ndarray, n_sensors: int):
        return _lines.trace_pairs(vi, lab, rows_in_step_order(steps),
                                  n_sensors, TRACE_SKIP)

    @staticmethod
    def round(lab, moved, joined, reading, nbr, good, lost, px, py, ox, oy, alpha, cx, cy,
              options: LineOptions):
        f = np.ascontiguousarray
        return _lines.trace_round(
            lab, moved.view(np.uint8), f(joined).view(np.uint8), reading, nbr,
            f(good).view(np.uint8), lost, px, py, ox, oy, f(alpha, dtype=float),
            f(cx, dtype=float), f(cy, dtype=float), options.corner_reach_m,
            options.corner_reach_share, options.min_split_m, TRACE_LOOSE, TRACE_LOOSE_MIN_M,
            math.sin(TRACE_CORNER_RAD))

    @staticmethod
    def moves(ask, i, j, a, b, run_lo, run_hi, kx, ky, counts, h, ox, oy, alpha, cx, cy, lo,
              hi, mx, my, n_mem, good, cal: Calibration, max_range_m: float,
              options: LineOptions, to_corner: bool):
        if not ask.any():
            return None
        f = np.ascontiguousarray
        with np.errstate(divide="ignore", invalid="ignore"):
            return _lines.trace_moves(
                ask.view(np.uint8), i, j, a, b, run_lo, run_hi, kx, ky, counts, h, ox, oy,
                f(alpha, dtype=float), f(cx, dtype=float), f(cy, dtype=float), lo, hi, mx, my,
                n_mem, f(good).view(np.uint8), cal.theta_rad, cal._log_a, cal.b,
                cal.sigma_counts(), cal.max_incidence_rad, cal.min_range_m, max_range_m,
                options.min_split_m, options.adopt_margin_m, options.corner_reach_m,
                options.corner_reach_share, math.sin(TRACE_CORNER_RAD), TRACE_ON_SIGMAS,
                SIGMA_FLOOR_M, TRACE_ROUNDS, options.min_points, to_corner)


VAGUE_RATIO = 2.0   # a far line whose direction standard error is this many times another's …
VAGUE_MIN_RAD = math.radians(2.0)   # … and at least this (its members tell it no better) …
VAGUE_TURN_Z = 3.0  # … turned from it by at most this many of their combined errors …
VAGUE_Z = 2.5       # … whose members, read at that line's θ, lie on it within this many
#                     standard errors of their mean, joins it whole


def vague_far_lines(points: Points, vi: np.ndarray, lab: np.ndarray, reading: np.ndarray,
                    nbr: np.ndarray, good: np.ndarray, counts: np.ndarray, alpha: np.ndarray,
                    cx: np.ndarray, cy: np.ndarray, cal: Calibration):
    """Where a part is read to its own range: the members of each line a that a usable line
    b its members' traces meet (``reading``, ``nbr``: :meth:`TraceSteps.pairs`) knows the
    direction of far better, re-read on b. a and b within ``TRACE_CORNER_RAD`` of each
    other and by at most ``VAGUE_TURN_Z`` of their combined direction standard errors
    (:func:`direction_se`); a's ≥ ``VAGUE_RATIO`` times b's and ≥ ``VAGUE_MIN_RAD``; a's
    members, read at the incidence their beams meet b with, lie on b on average (their mean
    offset across b within ``VAGUE_Z`` standard errors of the mean, from their own noise);
    of several such b, the one they lie on best, unless b joins another line itself. Those
    members placed within the range and the drop-out angle move.
    (positions into ``vi``, target lines, d, θ, σ), or None. ``vi``: the valid readings,
    ``lab`` their lines (−1: none), ``counts`` theirs. Why: docs/estimator.md, "Vague far
    lines"."""
    if not read_to_own_range(cal, points.max_range_m):
        return None
    a, b = lab[reading], lab[nbr]
    f = (a >= 0) & (b >= 0) & (a != b)
    f[f] = good[b[f]]
    if not f.any():
        return None
    n_lines = alpha.size
    key = np.unique(a[f] * n_lines + b[f])
    a, b = key // n_lines, key % n_lines
    near = np.abs(np.sin(alpha[a] - alpha[b])) <= math.sin(TRACE_CORNER_RAD)
    mem = (lab >= 0).nonzero()[0]          # the members, as positions into vi
    at = vi[mem]
    g = lab[mem]
    theta_now = points.theta.reshape(-1)[at]
    se = direction_se(points.x.reshape(-1)[at], points.y.reshape(-1)[at],
                      points.sigma_m.reshape(-1)[at] * np.cos(theta_now), g, n_lines)
    turn = np.arcsin(np.minimum(np.abs(np.sin(alpha[a] - alpha[b])), 1.0))
    near &= ((se[a] >= VAGUE_RATIO * se[b]) & (se[a] >= VAGUE_MIN_RAD)
             & (turn <= VAGUE_TURN_Z * np.hypot(se[a], se[b])))
    if not near.any():
        return None
    a, b = a[near], b[near]
    # each pair's members of a (m: positions among the members), re-read on b
    order = np.argsort(g, kind="stable")
    n_a = np.bincount(g, minlength=n_lines)[a]
    pair = np.repeat(np.arange(a.size), n_a)
    first = np.searchsorted(g[order], a)
    m = order[np.repeat(first - np.cumsum(n_a) + n_a, n_a) + np.arange(pair.size)]
    bb = b[pair]
    h = points.heading.reshape(-1)[at[m]]
    theta = np.arccos(np.minimum(np.abs(np.sin(h - alpha[bb])), 1.0))
    s = counts[mem[m]]
    d = cal.distance(s, theta)
    _, bexp = cal.log_ab(theta)
    sigma = range_sigma(bexp, d, cal.sigma_counts() / s)
    qx = points.origin_x.reshape(-1)[at[m]] + d * np.cos(h)
    qy = points.origin_y.reshape(-1)[at[m]] + d * np.sin(h)
    across = (qy - cy[bb]) * np.cos(alpha[bb]) - (qx - cx[bb]) * np.sin(alpha[bb])
    s_across = sigma * np.cos(theta)
    mean = np.bincount(pair, across, a.size) / n_a
    z = np.abs(mean) / (np.sqrt(np.bincount(pair, s_across * s_across, a.size)) / n_a)
    z = np.where(np.isfinite(z) & (z <= VAGUE_Z), z, np.inf)
    # each a into the b it lies on best
    best = np.lexsort((z, a))
    best = best[np.concatenate(([True], a[best][1:] != a[best][:-1]))]
    best = best[np.isfinite(z[best])]
    best = best[~np.isin(b[best], a[best])]   # not into a line that joins another itself
    if not best.size:
        return None
    ok = (np.isin(pair, best) & (theta <= cal.max_incidence_rad) & np.isfinite(d)
          & (d >= cal.min_range_m) & (d <= points.max_range_m))
    if not ok.any():
        return None
    return mem[m[ok]], bb[ok], d[ok], theta[ok], sigma[ok]


def rejoin_traces(points: Points, label: np.ndarray, index: np.ndarray, counts: np.ndarray,
                  steps: np.ndarray, cal: Calibration, alpha: np.ndarray, cx: np.ndarray,
                  cy: np.ndarray, usable: np.ndarray, options: LineOptions,
                  tracer: type[TraceSteps] = TraceSteps) -> tuple[Points, np.ndarray]:
    """Line members that a better-held line their own sensor's trace continues on places,
    moved to it; shared by both estimators (``tracer``: its steps, numpy's
    :class:`TraceSteps` or the compiled :class:`TraceKernels`).

    A member whose sensor's neighbouring reading (at the next step, or across at most
    ``TRACE_SKIP`` valid readings on no line) is on another usable line B moves to B where
    its own line holds it weakly and, read at the incidence its beam meets B with, it lies
    on B (``TRACE_ON_SIGMAS`` σ, ≥ ``min_split_m``; within ``adopt_margin_m`` of B's
    members' extent), not past a corner B makes (:func:`_past_a_corner`). Weakly: first
    ("absorb") a line within ``TRACE_CORNER_RAD`` of B with fewer members scattering
    ``TRACE_LOOSE`` times as much (and over ``TRACE_LOOSE_MIN_M``), or one that gave up more
    members than it kept; where none such is left ("cross"), a member lying past its line's
    corner with B (B's extent then runs on to the corner). A round moves each such run of
    a line's readings outward as far as each lies on B; a reading moves once; readings on
    no line never move. At grazing incidence one sensor's readings beside a corner fit a
    line of their own at a wrong direction (7–25° off the wall, 38–125 mm off), which no
    corner test sees (< 30° from the wall's line); the wall's line, fitted by other
    sensors' readings, places them. Before the traces, where a part is read to its own
    range, a line whose direction another line knows far better and whose members lie on
    that one joins it whole (:func:`vague_far_lines`). ``label`` (S, N): each reading's
    line or −1;
    ``steps`` (S,): each row's motor step; ``alpha``, ``cx``, ``cy``, ``usable``
    (L,): the lines. Why and what it measured: docs/estimator.md ("Traces")."""
    n_sensors = label.shape[1]
    vi = index[points.valid.reshape(-1)[index]]
    lab = label.reshape(-1)[vi]
    if vi.size < 2 or not (lab >= 0).any():
        return points, label
    lab = lab.copy()
    joined, reading, nbr = tracer.pairs(vi, lab, steps, n_sensors)
    k = vi.size
    n_lines = alpha.size
    good = np.asarray(usable, dtype=bool)
    counts_at = np.asarray(counts, dtype=float).reshape(-1)[vi]
    h = points.heading.reshape(-1)[vi]
    ox, oy = points.origin_x.reshape(-1)[vi], points.origin_y.reshape(-1)[vi]
    px, py = points.x.reshape(-1)[vi], points.y.reshape(-1)[vi]
    moved = np.zeros(k, dtype=bool)
    new_d, new_t, new_sig = np.full(k, np.nan), np.full(k, np.nan), np.full(k, np.nan)
    lost = np.zeros(n_lines, dtype=np.intp)     # members each line gave up
    # far out: a line whose direction another line knows far better, its members lying on
    # that one read at its θ, joins it whole (docs/estimator.md, "Vague far lines")
    whole = vague_far_lines(points, vi, lab, reading, nbr, good, counts_at, alpha, cx, cy,
                            cal)

    def move(at, to, d, theta, sigma):
        """Members ``at`` to line ``to``, read at ``d``, ``theta``, ``sigma``."""
        np.add.at(lost, lab[at], 1)
        lab[at] = to
        moved[at] = True
        new_d[at], new_t[at], new_sig[at] = d, theta, sigma
        px[at], py[at] = ox[at] + d * np.cos(h[at]), oy[at] + d * np.sin(h[at])

    if whole is not None:
        move(*whole)
    for _ in range(TRACE_ROUNDS):
        # the trace's frontier: a member not moved yet whose neighbour is on another usable line
        front = tracer.round(lab, moved, joined, reading, nbr, good, lost, px, py, ox, oy,
                             alpha, cx, cy, options)
        if front is None:
            break
        i, j, a, b, run_lo, run_hi, n_mem, mx, my, lo, hi, absorb, cross = front
        args = (i, j, a, b, run_lo, run_hi, px, py, counts_at, h, ox, oy, alpha, cx, cy, lo,
                hi, mx, my, n_mem, good, cal, points.max_range_m, options)
        go = tracer.moves(absorb, *args, False)
        if go is None:
            go = tracer.moves(cross, *args, True)
        if go is None:
            break
        move(*go)
    if not moved.any():
        return points, label
    # a line that gave up more members than it kept gives the rest no θ: INCIDENCE_UNKNOWN
    mem = lab >= 0
    left = mem & (lost > np.bincount(lab[mem], minlength=n_lines))[np.maximum(lab, 0)]
    lab[left] = -1
    at = vi[moved]
    label = label.copy()
    label.reshape(-1)[vi[moved | left]] = lab[moved | left]
    points = placed_at(points, at, new_d[moved], new_t[moved], new_sig[moved])
    return (unplaced(points, vi[left]) if left.any() else points), label
