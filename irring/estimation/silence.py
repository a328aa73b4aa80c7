"""The ends of the range: readings classified by their counts alone (:func:`classify`, near
readings nothing confirms: :func:`unconfirmed_near`), readings near the no-return level
pooled with their neighbours (:func:`pooled_counts`), what a silent beam says (its reach:
:func:`no_return_reach`, :func:`beside_a_return`, :func:`silent_reach`), and line members
past the range or censored by the return level (:func:`drop_beyond_range`,
:func:`censored_lines`, :func:`noise_past_line_end`, :func:`silent_behind_a_wall`). Why and
what was measured: docs/estimator.md, "Pooled readings", "Silent beams", "At the range
limit", "Censored lines".
"""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np

from ..core import Points, Reason, Sweep, points_with, rows_in_step_order
from ..resources import kernel
from .calibration import RANGE_SIGMAS, RETURN_SIGMAS, Calibration
from .lines import LineOptions, Lines, invalidated, read_to_own_range
from .seam import closes_turn


_iterate = kernel("estimation._iterate")
_lines = kernel("estimation._lines")
# plain ints: an array compared with an IntEnum member takes numpy's slow path (~7 µs)
_NO_RETURN, _OUT_OF_RANGE = int(Reason.NO_RETURN), int(Reason.OUT_OF_RANGE)
_INCIDENCE_UNKNOWN, _MISSING = int(Reason.INCIDENCE_UNKNOWN), int(Reason.MISSING)


def classify(counts: np.ndarray, sweep: Sweep, cal: Calibration) -> np.ndarray:
    """Reasons decided by the counts alone (before any distance is computed; see
    ``_iterate.classify``), MISSING for the steps the hardware never delivered, and
    FOLDOVER_AMBIGUOUS for the readings below the datasheet's range nothing confirms
    (:func:`unconfirmed_near`)."""
    full, near, no_return, _, falling = cal._levels
    reason = np.zeros(counts.shape, dtype=np.uint8)
    _iterate.classify(counts.reshape(-1), reason.reshape(-1), full, near, no_return,
                      cal.no_return_margin_counts, cal.return_margin_counts, falling)
    if sweep.missing_steps:
        rows = np.isin(np.asarray(sweep.steps), np.asarray(sweep.missing_steps))
        reason[rows, :] = Reason.MISSING
    alone = unconfirmed_near(counts, reason, sweep.steps, cal)
    if alone is not None:
        reason[alone] = Reason.FOLDOVER_AMBIGUOUS
    return reason


NEAR_AGREE_M = 0.03   # a neighbouring step's θ = 0 distance within this confirms a near reading


def unconfirmed_near(counts: np.ndarray, reason: np.ndarray, steps, cal: Calibration
                     ) -> np.ndarray | None:
    """(S, N) bool: the readings (``reason`` OK) brighter than ``cal.confirm_counts``, i.e.
    below the sensor model's datasheet range, that neither neighbouring step of their
    sensor (by step order) confirms: its θ = 0 distance within ``NEAR_AGREE_M`` of theirs,
    or at full scale (nearer still). None where nothing is asked (every calibration that
    reads nothing below the datasheet's range). Shared by both estimators. Why: a surface
    that near is met by consecutive steps (a step moves the beam ≤ 4 mm across at 0.2 m),
    a spurious short reading (the `outliers` effect) alone; main refused both."""
    level = cal.confirm_counts
    if not math.isfinite(level):
        return None
    s = np.asarray(counts, dtype=float)
    ask = (reason == Reason.OK) & (s > level)
    if not ask.any():
        return None
    order = rows_in_step_order(steps)
    so = s[order]
    top = so >= cal.full_scale_counts - 0.5
    ok = np.zeros(so.shape, dtype=bool)
    # counts past the curve read inf or NaN (1 V of noise): a neighbour at inf confirms none
    with np.errstate(divide="ignore", invalid="ignore"):
        d0 = cal.distance(so, 0.0)
        ok[1:] |= (np.abs(d0[1:] - d0[:-1]) <= NEAR_AGREE_M) | top[:-1]
        ok[:-1] |= (np.abs(d0[:-1] - d0[1:]) <= NEAR_AGREE_M) | top[1:]
    confirmed = np.empty_like(ok)
    confirmed[order] = ok
    return ask & ~confirmed


def censored_lines(points: Points, label: np.ndarray, counts: np.ndarray, steps: np.ndarray,
                   cal: Calibration) -> Points:
    """Each valid member of a line moved out along its beam by the mean noise of the returns
    its line kept: σ·λ(f), λ(f) = φ(Φ⁻¹(f))/(1 − f), where f is the share of the line's beams
    whose counts fell below the return level (``no_return_counts + RETURN_SIGMAS`` count σ;
    NO_RETURN or OUT_OF_RANGE) and σ the member's range noise |b|·d·σ_S/S.

    A line's beams: each sensor's readings from its first to its last member step (round
    the seam of a sensor turning a full turn, :func:`_across_seam`). Only
    where that level cuts into the range (``cal.silent_range_m`` short of
    ``points.max_range_m``: a part read to its own range); elsewhere ``points`` as given.
    ``label`` (S, N): each reading's line (−1: none); ``counts`` (S, N); ``steps`` (S,).
    Why and what it measured: docs/estimator.md, "Censored lines"."""
    if not read_to_own_range(cal, points.max_range_m):
        return points
    shape = points.valid.shape
    s = np.asarray(counts, dtype=float).reshape(shape)
    label = np.asarray(label).reshape(shape)
    member = points.valid & (label >= 0)
    if not member.any():
        return points
    n_lines, n_sensors = int(label[member].max()) + 1, shape[1]
    rank = np.empty(shape[0], dtype=np.intp)            # each row's place in step order
    rank[rows_in_step_order(steps)] = np.arange(shape[0])
    row, sensor = member.nonzero()
    pair = label[row, sensor] * n_sensors + sensor       # (line, sensor)
    lo = np.full(n_lines * n_sensors, shape[0], dtype=np.intp)
    hi = np.full(n_lines * n_sensors, -1, dtype=np.intp)
    np.minimum.at(lo, pair, rank[row])
    np.maximum.at(hi, pair, rank[row])
    lo, hi, seam = _across_seam(points.heading, rank, row, sensor, pair, lo, hi)
    silent = (points.reason == _NO_RETURN) | (points.reason == _OUT_OF_RANGE)
    cut = silent & (s < cal.no_return_counts + RETURN_SIGMAS * cal.sigma_counts())
    c_row, c_sensor = cut.nonzero()
    lo, hi = lo.reshape(n_lines, n_sensors), hi.reshape(n_lines, n_sensors)
    seam = seam.reshape(n_lines, n_sensors)[:, c_sensor]
    after, before = lo[:, c_sensor] <= rank[c_row], rank[c_row] <= hi[:, c_sensor]
    on = np.where(seam, after | before, after & before)   # (L, C)
    lost = on.sum(axis=1)
    if not lost.any():
        return points
    kept = np.bincount(label[member], minlength=n_lines)
    share = lost / np.maximum(lost + kept, 1)
    normal = NormalDist()
    mills = np.array([normal.pdf(normal.inv_cdf(f)) / (1.0 - f) if f > 0 else 0.0
                      for f in share])
    _, b = cal.log_ab(points.theta[member])
    sigma = np.abs(b) * points.d[member] * cal.sigma_counts() / s[member]
    d = np.array(points.d)
    d[member] += mills[label[member]] * sigma
    return points_with(points, d=d, x=points.origin_x + d * np.cos(points.heading),
                       y=points.origin_y + d * np.sin(points.heading))


def _across_seam(heading: np.ndarray, rank: np.ndarray, row: np.ndarray, sensor: np.ndarray,
                 pair: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple:
    """Each (line, sensor) pair's first and last member rank, ``lo`` and ``hi``, and
    ``seam``: whether its members run across a full turn's seam (then its beams are those
    from ``lo`` past the last step and on from the first to ``hi``). A sensor turns a full
    turn where its headings go round (their steps add up to 2π) and its last step's heading
    lies within 1.5 of its widest step of its first's; a run of its members crosses the seam
    where the widest gap between them (in step order) is not the one from its last member
    round to its first."""
    seam = np.zeros(lo.size, dtype=bool)
    n_rows = heading.shape[0]
    if n_rows < 3:
        return lo, hi, seam
    order = np.argsort(rank)
    h = heading[order]                                    # (S, N) rows in step order
    closed = closes_turn(h)                               # (N,)
    if not closed[sensor].any():
        return lo, hi, seam
    pick = closed[sensor]
    key = pair[pick] * n_rows + rank[row[pick]]
    srt = np.sort(key)
    p, r = srt // n_rows, srt % n_rows
    new = np.flatnonzero(np.diff(p)) + 1
    first = np.concatenate([[0], new])
    last = np.concatenate([new, [p.size]]) - 1
    gap = np.append(np.diff(r), -1)
    gap[new - 1] = -1                                     # no gap between two pairs
    widest = np.maximum.reduceat(gap, first)
    across = widest > r[first] + n_rows - r[last]         # wider than the gap round the seam
    if not across.any():
        return lo, hi, seam
    run = np.repeat(np.arange(first.size), last - first + 1)
    at = np.flatnonzero((gap == widest[run]) & across[run])
    _, one = np.unique(run[at], return_index=True)        # the first widest gap of each run
    at = at[one]
    q = p[at]
    lo[q], hi[q], seam[q] = r[at + 1], r[at], True
    return lo, hi, seam


POOL_STEPS = 6   # a reading near the no-return level is pooled with 6 steps either way
POOL_BLOCK_M = 0.5  # a wall silences a pooled beam this far past its readings (to a corner)
# ... but not where either half of its window (itself and its 6 steps one way) stands less than
# this many standard errors above the level: that side saw nothing, the window straddles a
# surface's end, and its mean would carry the face past it (docs/estimator.md, "Pooled readings")
POOL_SIDE_SIGMAS = 2.0


def pool_edge_counts(cal: Calibration, max_range_m: float) -> float:
    """The counts each half of a pool's window must stand clear of. Read to the curve's end
    (``max_range_m`` ≥ ``cal.max_range_m``): the no-return level. Read short of it: those of
    a surface square on at ``max_range_m`` (a surface past the range reads as the no-return
    level, the simulator's and the firmware's output with nothing in range, while one just
    inside reads more, so a half that ran past the range reads below them)."""
    if max_range_m >= cal.max_range_m:
        return cal.no_return_counts
    return max(cal.no_return_counts, float(cal.counts(max_range_m, 0.0)))


def pooled_counts(counts: np.ndarray, reason: np.ndarray, steps: np.ndarray, cal: Calibration,
                  max_range_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(counts, reason), both (S, N), with each reading near the no-return level read as the
    mean of its sensor's 2·``POOL_STEPS`` + 1 readings around it (by step), where that mean
    stands ``RETURN_SIGMAS`` standard errors (count σ/√(2·POOL_STEPS + 1)) above the
    no-return level, and so does each half of it (the reading and its ``POOL_STEPS`` steps one
    way; ``POOL_SIDE_SIGMAS`` standard errors, count σ/√(``POOL_STEPS`` + 1)): such a
    reading becomes OK with the mean's counts; all others are returned as given.

    Near the level: below it plus ``RETURN_SIGMAS + RANGE_SIGMAS`` count σ, NO_RETURN,
    OUT_OF_RANGE or OK, and so is every reading of the window (it ends at none: a sweep's
    first and last steps are not pooled). Only where the no-return level cuts into the range
    (``cal.silent_range_m`` short of ``max_range_m``); no change elsewhere. Where the range
    stops short of the curve's end, each half must stand those standard errors above
    :func:`pool_edge_counts` instead. Why and what it measured: docs/estimator.md, "Pooled
    readings" and "Pooled readings where the range is cut short"."""
    if not read_to_own_range(cal, max_range_m):
        return counts, reason
    shape = counts.shape
    order = rows_in_step_order(steps)
    s, why = counts[order], reason[order]
    sigma = cal.sigma_counts()
    near = ((s < cal.no_return_counts + (RETURN_SIGMAS + RANGE_SIGMAS) * sigma)
            & ((why == Reason.NO_RETURN) | (why == Reason.OUT_OF_RANGE) | (why == Reason.OK)))
    n = 2 * POOL_STEPS + 1
    if shape[0] < n or not near.any():
        return counts, reason
    zero = np.zeros((1, shape[1]))
    total = np.vstack([zero, np.cumsum(np.where(near, s, 0.0), axis=0)])
    count = np.vstack([zero, np.cumsum(near, axis=0)])
    mean = (total[n:] - total[:-n]) / n                        # windows' means, centred rows
    whole = (count[n:] - count[:-n]) == n
    seen = (mean - cal.no_return_counts) * math.sqrt(n) >= RETURN_SIGMAS * sigma
    # each half (the centre and POOL_STEPS rows one way) must show the surface too, and one
    # nearer than the range's edge (a wall receding past a range cut reads as nothing there)
    edge = pool_edge_counts(cal, max_range_m)
    half, rows = POOL_STEPS + 1, shape[0] - 2 * POOL_STEPS
    side = np.minimum(total[half:half + rows] - total[:rows],            # rows i-6 … i
                      total[n:] - total[POOL_STEPS:POOL_STEPS + rows])   # rows i … i+6
    seen &= (side / half - edge) * math.sqrt(half) >= POOL_SIDE_SIGMAS * sigma
    centre = slice(POOL_STEPS, shape[0] - POOL_STEPS)
    pick = near[centre] & whole & seen
    if not pick.any():
        return counts, reason
    s, why = s.copy(), why.copy()
    s[centre][pick] = mean[pick]
    why[centre][pick] = Reason.OK
    out_s, out_why = np.empty_like(counts), np.empty_like(reason)
    out_s[order], out_why[order] = s, why
    return out_s, out_why


def held_and_pooled(counts: np.ndarray, reason: np.ndarray, hold: np.ndarray | None,
                    steps: np.ndarray, cal: Calibration, max_range_m: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pooled_counts` of the classified readings with those ``hold`` marks (S, N; or
    None) FOLDOVER_AMBIGUOUS: before pooling, so they join no pool, and after it, so that
    pooling (which makes a reading near the no-return level OK) revives none of them."""
    if hold is None:
        return pooled_counts(counts, reason, steps, cal, max_range_m)
    reason = reason.copy()
    reason[hold & (reason == Reason.OK)] = Reason.FOLDOVER_AMBIGUOUS
    counts, reason = pooled_counts(counts, reason, steps, cal, max_range_m)
    reason = reason.copy()
    reason[hold & (reason == Reason.OK)] = Reason.FOLDOVER_AMBIGUOUS
    return counts, reason


_HIDES_BELOW = 0.5 * math.pi - 1e-6   # θ + γ this near 90° or more: the face hides nothing


def beside_a_return(points: Points, counts: np.ndarray, cal: Calibration,
                    options: LineOptions, label: np.ndarray | None = None) -> Points:
    """``points`` with each NO_RETURN beam's ``reach_m`` at most r·cos θ / cos(θ + γ), from
    the nearest reading of its sensor (by row, either way: the nearest step where the rows
    rise or fall by step, as :func:`irring.core.in_turn_order` leaves a run's sweeps; rows
    in any other order are taken as they lie) that heard a surface (valid, or
    unplaced with ``counts`` at least the return level; not MISSING): r the nearest its
    surface can be (where its θ is known, a member of a line of ``label`` (S, N; −1 none) or
    θ > 0: its d; any other reading, too near to place, past the range or read at θ = 0: the
    far-branch distance of its counts at the drop-out angle, the steepest it could have
    returned at), θ = :func:`end_hide_angle`, γ the heading gap to it; no limit where
    θ + γ ≥ 90°. A face through that reading's hit, turned past the drop-out angle, may
    cross this beam unheard from there on (docs/estimator.md, "Silent beams beside a return").
    numpy, the statement :func:`beside_a_return_compiled` is held to."""
    silent = points.reason == _NO_RETURN
    if not np.count_nonzero(silent):
        return points
    theta = end_hide_angle(cal, options)
    c = np.minimum(np.asarray(counts, dtype=float), cal.full_scale_counts)
    heard = points.valid | ((c >= cal.no_return_counts + cal.return_margin_counts) & ~silent
                            & (np.asarray(points.reason) != _MISSING))
    steps = silent.shape[0]
    heard2 = heard.reshape(steps, -1)
    _, _, (before, after) = nearest_heard_rows(heard2)
    # only the silent beams' bounds are asked for: each beam (row, cols) twice, with the
    # nearest heard reading before it, then after it, (at, cols)
    srow, scol = silent.reshape(steps, -1).nonzero()
    other = np.concatenate((before[srow, scol], after[srow, scol]))
    row, cols = np.concatenate((srow, srow)), np.concatenate((scol, scol))
    has = (other >= 0) & (other < steps)
    at = np.where(has, other, row)

    def there(v):
        return np.asarray(v).reshape(steps, -1)[at, cols]

    valid, d = there(points.valid), there(points.d)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = (cal.distance(np.where(there(heard), there(c), cal.full_scale_counts),
                          cal.max_incidence_rad)
             if cal.falling else np.where(valid, d, np.nan))   # (linear hooks)
    # where its θ is known (on a line, or estimated: θ > 0; NaN compares False) its d stands
    known = valid & (there(np.asarray(points.theta, dtype=float)) > 0)
    if label is not None:
        known |= valid & (there(label) >= 0)
    r = np.where(known, d, r)
    use = there(heard) & np.isfinite(r)
    h = np.asarray(points.heading, dtype=float).reshape(steps, -1)
    gap = h[at, cols] - h[row, cols]
    gamma = np.abs(gap - 2.0 * math.pi * np.rint(gap / (2.0 * math.pi)))
    hides = has & use & (theta + gamma < _HIDES_BELOW)
    stop = np.where(use, r, 0.0) * math.cos(theta) / np.cos(np.where(hides, theta + gamma, 0.0))
    bound = np.where(hides, stop, np.inf)
    bound = np.minimum(bound[:srow.size], bound[srow.size:])
    cut = np.isfinite(bound)
    if not cut.any():
        return points
    reach = (np.full(silent.shape, np.nan) if points.reach_m is None
             else np.array(points.reach_m, dtype=float))
    flat = reach.reshape(-1)
    at = (srow * h.shape[1] + scol)[cut]
    flat[at] = np.fmin(flat[at], bound[cut])
    return points_with(points, reach_m=reach)


def beside_a_return_compiled(points: Points, counts: np.ndarray, cal: Calibration,
                             options: LineOptions, label: np.ndarray | None = None) -> Points:
    """:func:`beside_a_return` in one compiled call (``irring.estimation._lines.beside_a_return``,
    held to it by tests/test_silence_beside.py)."""
    if not np.count_nonzero(points.reason == _NO_RETURN):
        return points
    f = np.ascontiguousarray
    theta = end_hide_angle(cal, options)
    full, _, no_return, _, falling = cal._levels
    at, bound = _lines.beside_a_return(
        f(points.reason, dtype=np.uint8).reshape(-1), f(points.valid, dtype=np.uint8).reshape(-1),
        f(counts, dtype=float).reshape(-1), f(points.d, dtype=float).reshape(-1),
        f(points.theta, dtype=float).reshape(-1), f(points.heading, dtype=float).reshape(-1),
        _NO_LABEL if label is None else f(label, dtype=np.intp).reshape(-1), label is not None,
        points.valid.shape[1], _NO_RETURN, _MISSING, full, no_return + cal.return_margin_counts,
        falling, *cal._ab_drop, theta, math.cos(theta), _HIDES_BELOW)
    if not at.size:
        return points
    reach = (np.full(points.valid.shape, np.nan) if points.reach_m is None
             else np.array(points.reach_m, dtype=float))
    flat = reach.reshape(-1)
    flat[at] = np.fmin(flat[at], bound)
    return points_with(points, reach_m=reach)


_NO_LABEL = np.zeros(0, dtype=np.intp)


def nearest_heard_rows(heard: np.ndarray):
    """(row (S, 1), cols (1, N), (before, after) (S, N)): for each (step row, sensor column)
    of ``heard`` (S, N bool), the nearest row at or before it, and at or after it, in the same
    column that is ``heard``; −1 (before) or S (after) where there is none."""
    steps = heard.shape[0]
    row = np.arange(steps)[:, None]
    cols = np.arange(heard.shape[1])[None, :]
    before = np.maximum.accumulate(np.where(heard, row, -1), axis=0)
    after = np.minimum.accumulate(np.where(heard, row, steps)[::-1], axis=0)[::-1]
    return row, cols, (before, after)


def silent_reach(points: Points, cal: Calibration) -> Points:
    """``points`` with every NO_RETURN beam's ``reach_m`` at most ``cal.silent_range_m``,
    where that is shorter than ``points.max_range_m``: past it a surface square on reads as
    silence too often for silence to rule it out (docs/estimator.md, "Silent beams")."""
    limit = cal.silent_range_m
    if not limit < points.max_range_m:
        return points
    silent = points.reason == _NO_RETURN
    if not np.count_nonzero(silent):
        return points
    reach = (np.full(silent.shape, np.nan) if points.reach_m is None
             else np.array(points.reach_m, dtype=float))
    reach[silent] = np.fmin(reach[silent], limit)
    return points_with(points, reach_m=reach)


def drop_beyond_range(points: Points) -> Points:
    """``points`` with every valid reading still past ``max_range_m`` made OUT_OF_RANGE.

    The estimator keeps a line member read up to :data:`RANGE_SIGMAS` of its σ past the
    max range valid for its line's fit (a surface at the range limit that noise read
    long: dropping those biased the lines of such walls inward); once
    :func:`snap_to_lines` has put the members on their lines, one its line did not bring
    within range is not trusted as a point (docs/estimator.md, "At the range limit")."""
    beyond = points.valid & (points.d > points.max_range_m)
    if not np.count_nonzero(beyond):
        return points
    return invalidated(points, beyond, Reason.OUT_OF_RANGE)


REACH_MIN_MEMBERS = 5      # a line explains silent beams with at least this many members …
REACH_CLEAR_M = 0.01       # … which stop this far (across the line) before meeting it


def no_return_reach(points: Points, found: Lines | None, cal: Calibration,
                    options: LineOptions) -> np.ndarray | None:
    """How far each NO_RETURN beam is known free (S, N, m; NaN: to the max range; None: no
    silent beam meets a line that explains it), from the sweep's lines ``found``.

    A silent beam is stopped 10 mm before the first usable line of ≥ 5 valid members it
    meets within range, inside that line's span (members' extent plus 0.25 m, not past a
    corner), at an incidence ≥ the drop-out angle less ``options.incidence_margin_rad``;
    past the members' end, where a face turned away there could hide from it.
    One compiled call (``irring.estimation._lines.no_return_reach``); the readable statement
    and the why: :func:`irring.estimation.estimate_numpy.no_return_reach`."""
    if found is None or found.usable.size == 0:
        return None
    f = np.ascontiguousarray
    flat = [f(a, dtype=float).reshape(-1) for a in (points.heading, points.origin_x,
                                                     points.origin_y, points.x, points.y)]
    reach = _lines.no_return_reach(
        *flat, f(found.label, dtype=np.intp).reshape(-1),
        f(points.valid, dtype=bool).reshape(-1).view(np.uint8),
        f(points.reason, dtype=np.uint8).reshape(-1), int(Reason.NO_RETURN),
        f(found.centroid, dtype=float), f(found.direction, dtype=float),
        f(found.normal, dtype=float), f(found.usable, dtype=bool).view(np.uint8),
        REACH_MIN_MEMBERS, REACH_CLEAR_M, _FOLD_BLOCK_M, _CORNER_MIN_SIN, _CORNER_PAST_M,
        reach_cos_limit(cal, options), float(points.max_range_m), end_hide_angle(cal, options),
        math.prod(np.shape(points.valid)[1:]))
    return None if reach is None else reach.reshape(points.valid.shape)


def noise_past_line_end(points: Points, found: Lines, raw_counts: np.ndarray,
                        cal: Calibration) -> Points:
    """``points`` with each valid line member whose own counts (``raw_counts``, before
    pooling) are at the noise level (at most ``cal.no_return_counts`` +
    ``cal.no_return_margin_counts``: valid only by pooling) made NO_RETURN where it lies
    past the extent, along its line (``found``), of the line's members that are not: its
    counts say nothing of where the surface ends, and its pool's mean, from its
    neighbours, placed it on their line beyond what they saw (docs/estimator.md, "Pooled
    readings"). Its beam is then a silent one (reach by :func:`no_return_reach`)."""
    lab = found.label
    member = points.valid & (lab >= 0)
    noise = member & (np.asarray(raw_counts, dtype=float)
                      <= cal.no_return_counts + cal.no_return_margin_counts)
    if not noise.any():
        return points
    n_lines = found.centroid.shape[0]
    li = np.where(member, lab, 0)
    c, e = found.centroid[li], found.direction[li]
    along = (points.x - c[..., 0]) * e[..., 0] + (points.y - c[..., 1]) * e[..., 1]
    clear = member & ~noise
    lo = np.full(n_lines, np.inf)
    hi = np.full(n_lines, -np.inf)
    np.minimum.at(lo, lab[clear], along[clear])
    np.maximum.at(hi, lab[clear], along[clear])
    gone = noise & np.isfinite(lo[li]) & ((along < lo[li]) | (along > hi[li]))
    return invalidated(points, gone, Reason.NO_RETURN) if gone.any() else points


def silent_behind_a_wall(points: Points, pooled: np.ndarray, found: Lines, cal: Calibration,
                         options: LineOptions, among: np.ndarray | None = None,
                         members: Points | None = None) -> Points:
    """``points`` with each reading of ``pooled`` (S, N: valid only by pooling, its counts
    below the return level) made NO_RETURN where its beam meets a line of ``found`` (those
    ``among``, default all; its members those of ``members``, default ``points``) that
    explains a silent beam (:func:`no_return_reach`'s:
    ≥ ``REACH_MIN_MEMBERS`` valid members, within its span, at an incidence past the
    drop-out angle less ``options.incidence_margin_rad``) more than 3σ (at least
    ``REACH_CLEAR_M``) before its end point; its beam is known free (``reach_m``) to
    ``REACH_CLEAR_M`` before that line. Why (a pool near the no-return level mixes a beam
    that dropped out with the wall behind): docs/estimator.md, "Pooled readings"."""
    members = points if members is None else members
    lab = found.label.reshape(-1)
    n_mem = np.bincount(lab[(lab >= 0) & members.valid.reshape(-1)],
                        minlength=found.usable.size)
    ok = found.usable & (n_mem >= REACH_MIN_MEMBERS)
    if among is not None:
        ok &= np.isin(np.arange(ok.size), among)
    use = ok.nonzero()[0]
    if use.size == 0:
        return points
    at = pooled.reshape(-1).nonzero()[0]
    c, e, nrm = found.centroid[use], found.direction[use], found.normal[use]
    *_, lo, hi = member_spans(members, found, use)
    lo_b, hi_b = clip_at_corners(c, e, lo, hi, POOL_BLOCK_M)
    h = points.heading.reshape(-1)[at]
    un, t, ahead, along = beam_crossings(points.origin_x.reshape(-1)[at],
                                         points.origin_y.reshape(-1)[at], np.cos(h), np.sin(h),
                                         c, e, nrm)                          # (B, L)
    d, sigma = points.d.reshape(-1)[at], points.sigma_m.reshape(-1)[at]
    clear = np.maximum(3.0 * sigma, REACH_CLEAR_M)
    cos_inc = np.abs(un)
    before = (ahead & (cos_inc <= reach_cos_limit(cal, options))
              & (t < (d - clear)[:, None]) & (along >= lo_b[None, :]) & (along <= hi_b[None, :])
              & (lab[at][:, None] != use[None, :]))
    hit = before.any(axis=1)
    if not hit.any():
        return points
    gone = at[hit]
    stop = np.where(before, t - REACH_CLEAR_M / np.where(before, cos_inc, 1.0), np.inf)
    reach = (np.full(points.valid.shape, np.nan) if points.reach_m is None
             else np.array(points.reach_m, dtype=float))
    reach.reshape(-1)[gone] = np.maximum(stop[hit].min(axis=1), 0.0)
    return points_with(invalidated(points, gone, Reason.NO_RETURN), reach_m=reach)


def reach_cos_limit(cal: Calibration, options: LineOptions) -> float:
    """A silent beam meeting a line with |cos incidence| at most this would have dropped out
    there: the drop-out angle less ``options.incidence_margin_rad``."""
    return math.cos(cal.max_incidence_rad - options.incidence_margin_rad)


def end_hide_angle(cal: Calibration, options: LineOptions) -> float:
    """The least angle (rad, from its normal) at which a face past a line's end meets a
    silent beam it hides from: the drop-out angle less ``options.incidence_margin_rad``
    (π/2 or more: no face hides there, the beams past a line's end keep their reach)."""
    return max(cal.max_incidence_rad - options.incidence_margin_rad, 0.0)


def member_spans(points: Points, found: Lines, use: np.ndarray):
    """The valid members of the lines ``use`` (indices into ``found``) and their extent.

    Returns (col, at, mcol, along, lo, hi): ``col`` (L,) each line's position in ``use`` (−1:
    not used); ``at`` the members' flat (S·N) indices, ``mcol`` their line's position and
    ``along`` their coordinate along it from its centroid (m); ``lo``,
    ``hi`` (len(use),) the least and greatest member coordinate along each line from its
    centroid (m; ±inf for a line without valid members)."""
    lab = found.label.reshape(-1)
    at = ((lab >= 0) & points.valid.reshape(-1)).nonzero()[0]
    col = np.full(found.usable.size, -1)
    col[use] = np.arange(use.size)
    mcol = col[lab[at]]
    keep = mcol >= 0
    at, mcol = at[keep], mcol[keep]
    c, e = found.centroid[use], found.direction[use]
    mx, my = points.x.reshape(-1)[at], points.y.reshape(-1)[at]
    along = (mx - c[mcol, 0]) * e[mcol, 0] + (my - c[mcol, 1]) * e[mcol, 1]
    lo = np.full(use.size, np.inf)
    hi = np.full(use.size, -np.inf)
    np.minimum.at(lo, mcol, along)
    np.maximum.at(hi, mcol, along)
    return col, at, mcol, along, lo, hi


def beam_crossings(ox, oy, ux, uy, c, e, nrm):
    """Beams (B,) from (ox, oy) along unit (ux, uy) against lines (L,) through centroids
    ``c`` along unit ``e`` with unit normals ``nrm``; all (B, L): ``un`` = beam · normal
    (|un| = cos incidence), ``t`` the distance along the beam to the line where it lies ahead
    (else 0), ``ahead``, and ``along`` the crossing's coordinate along the line from ``c``."""
    un = ux[:, None] * nrm[None, :, 0] + uy[:, None] * nrm[None, :, 1]
    gap = ((c[None, :, 0] - ox[:, None]) * nrm[None, :, 0]
           + (c[None, :, 1] - oy[:, None]) * nrm[None, :, 1])               # emitter → line
    with np.errstate(divide="ignore", invalid="ignore"):
        t = gap / un
    ahead = (np.abs(un) > 1e-9) & np.isfinite(t) & (t > 0)
    t = np.where(ahead, t, 0.0)
    along = ((ox[:, None] + t * ux[:, None] - c[None, :, 0]) * e[None, :, 0]
             + (oy[:, None] + t * uy[:, None] - c[None, :, 1]) * e[None, :, 1])
    return un, t, ahead, along


_FOLD_BLOCK_M = 0.25   # a known wall blocks a beam this far past its readings' ends


_CORNER_MIN_SIN = 0.1  # lines crossing at under ~6° (sine of the angle) make no corner …
_CORNER_PAST_M = 0.01  # … a line's span ends this far past the corner it meets


def clip_at_corners(c, e, lo, hi, block_m: float = _FOLD_BLOCK_M):
    """Each line's span extended by ``block_m`` either way, but not past the point where
    it meets another line's extended span (a corner, 10 mm beyond it)."""
    lo_b, hi_b = lo - block_m, hi + block_m
    if c.shape[0] < 2:
        return lo_b, hi_b
    # intersection of line i with line j, as a coordinate along i (a) and along j (b)
    den = e[:, None, 0] * e[None, :, 1] - e[:, None, 1] * e[None, :, 0]       # e_i × e_j
    dx = c[None, :, 0] - c[:, None, 0]
    dy = c[None, :, 1] - c[:, None, 1]
    ok = np.abs(den) > _CORNER_MIN_SIN        # lines meeting at < ~6° make no corner
    den = np.where(ok, den, 1.0)
    a = (dx * e[None, :, 1] - dy * e[None, :, 0]) / den
    b = (dx * e[:, None, 1] - dy * e[:, None, 0]) / den
    corner = (ok & (b >= lo_b[None, :]) & (b <= hi_b[None, :])
              & ~np.eye(c.shape[0], dtype=bool))
    high = corner & (a > hi[:, None]) & (a < hi_b[:, None])
    low = corner & (a < lo[:, None]) & (a > lo_b[:, None])
    hi_b = np.minimum(hi_b, np.where(high, a + _CORNER_PAST_M, np.inf).min(axis=1))
    lo_b = np.maximum(lo_b, np.where(low, a - _CORNER_PAST_M, -np.inf).max(axis=1))
    return lo_b, hi_b
