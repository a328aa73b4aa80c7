"""A line's members judged by what lies beside them: members a silent gap contradicts, moved to
the line of their side of it (:func:`silent_gaps`, :func:`across_silence`), members alone at
a nearer surface's edge (:func:`alone_at_an_edge`), readings alone on no line
(:func:`unplaced_alone`), members whose beams meet another wall first, read on it
(:func:`past_other_lines`, its compiled gates :func:`past_members_compiled`), and dim returns
beside a line put on it (:func:`dim_returns_on_lines`). Why and what was measured:
docs/estimator.md, "Silent gaps", "Alone at an edge", "A beam that meets another wall first"
and "Dim returns beside a line".
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ..core import UNCERTAIN_SIGMA_M, Points, Reason, points_with, rows_in_step_order
from ..resources import kernel
from .calibration import SIGMA_FLOOR_M, Calibration, range_sigma
from .lines import (SNAP_MIN, LineOptions, invalidated, member_axes, placed_at,
                    read_to_own_range, scan_order, theta0_sigma)
from .silence import beam_crossings


_lines = kernel("estimation._lines")
# plain ints: an array compared with an IntEnum member takes numpy's slow path (~7 µs)
_NO_RETURN, _OUT_OF_RANGE = int(Reason.NO_RETURN), int(Reason.OUT_OF_RANGE)
_INCIDENCE_UNKNOWN, _MISSING = int(Reason.INCIDENCE_UNKNOWN), int(Reason.MISSING)


SILENT_DIP_SIGMAS = 3.0  # a sensor's readings either side of steps read this many count σ
#                          below both (silent, out of range) are not of one flat surface


def silent_gaps(index: np.ndarray, counts: np.ndarray, steps: np.ndarray,
                reason: np.ndarray, sigma_counts: float) -> np.ndarray:
    """Which readings ``index`` (flat (S, N) indices in scan order: each sensor's by step)
    follow their sensor's previous one across steps whose lowest count (``counts`` (S, N))
    lies ``SILENT_DIP_SIGMAS`` × ``sigma_counts`` below both of theirs: (k,) bool.

    Along one flat surface neither the range nor the incidence of the beams between two
    readings exceeds both ends', so no reading between them returns much less light: a
    silent step between two returns is an edge (a wall ending, another starting behind a
    gap). Before, a line's θ, a wall's read at 3°, was carried across six NO_RETURN steps
    onto a wall at 69° (:func:`across_silence`; docs/estimator.md, "Silent gaps"). MISSING
    steps (never read) say nothing."""
    k = index.size
    cut = np.zeros(k, dtype=bool)
    if k < 2:
        return cut
    n_sensors = counts.shape[1]
    scan = scan_order(steps, n_sensors)
    pos = np.empty(scan.size, dtype=np.intp)
    pos[scan] = np.arange(scan.size)
    p = pos[index]
    gap = (p[1:] - p[:-1] > 1) & (index[1:] % n_sensors == index[:-1] % n_sensors)
    if not gap.any():
        return cut
    flat = np.asarray(counts, dtype=float).reshape(-1)
    column = np.where(np.asarray(reason).reshape(-1) == int(Reason.MISSING), np.inf, flat)
    column = column[scan]
    at = gap.nonzero()[0]
    # the lowest count strictly between the two readings: minimum.reduceat over each gap
    bounds = np.stack([p[at] + 1, p[at + 1]], axis=1).reshape(-1)
    low = np.minimum.reduceat(np.append(column, np.inf), bounds)[::2]
    ends = np.minimum(flat[index[at]], flat[index[at + 1]])
    cut[at + 1] = low < ends - SILENT_DIP_SIGMAS * sigma_counts
    return cut


def silent_gaps_compiled(index: np.ndarray, counts: np.ndarray, steps: np.ndarray,
                         reason: np.ndarray, sigma_counts: float) -> np.ndarray:
    """:func:`silent_gaps` in one compiled call (``irring.estimation._lines.silent_gaps``,
    held to it by tests/test_silent_gaps.py)."""
    f = np.ascontiguousarray
    counts = f(counts, dtype=float)
    return _lines.silent_gaps(
        f(index, dtype=np.intp), counts.reshape(-1),
        rows_in_step_order(steps), f(reason, dtype=np.uint8).reshape(-1),
        counts.shape[1], _MISSING, SILENT_DIP_SIGMAS * sigma_counts).view(bool)


DIM_CHAIN = 3      # a dim return this many of its sensor's readings from a line's member …
DIM_SIGMAS = 1.5   # … whose counts lie within this many count σ of the line's at its beam …
DIM_REACH_M = 0.1  # … where it meets the line this near that member's end point …
DIM_INCIDENCE_RAD = math.radians(50)  # … and less steeply than this (steeper, the line's
#                                       counts fall fast enough to match anything dim)


def dim_returns_on_lines(points: Points, label: np.ndarray | None, counts: np.ndarray,
                         raw_counts: np.ndarray | None, steps: np.ndarray, cal: Calibration
                         ) -> Points:
    """``points`` with each dim return put on the line beside it, where a part is read to its
    own range: a reading OUT_OF_RANGE by its counts alone (between the no-return and the
    return margins above the no-return level) at most ``DIM_CHAIN`` readings of its sensor
    (in step order, only such readings between) from a valid member of a line of
    ≥ ``SNAP_MIN`` (``label`` (S, N), the snap's; None, or a scene that folds over:
    ``points`` as given), whose beam meets that line (fitted to its members' end points)
    within range, at less than ``DIM_INCIDENCE_RAD`` (and the drop-out angle), within
    ``DIM_REACH_M`` of that member's end point and not past a valid reading ``EDGE_JUMP_M``
    nearer at the first stop the other way (a nearer surface's edge), where the line's
    counts at that distance and incidence lie within ``DIM_SIGMAS`` count σ of its own
    (``raw_counts``, else ``counts``). It takes that
    distance, the incidence and the member's σ. Numpy, shared by both estimators. Why: a far
    wall's returns near the return level are dropped one by one, most at its ends
    (docs/estimator.md, "Dim returns beside a line")."""
    if label is None or cal.folds or not read_to_own_range(cal, points.max_range_m):
        return points     # (where readings may fold over, the branches' lines stay as decided)
    c = np.asarray(counts if raw_counts is None else raw_counts, dtype=float)
    level = cal.no_return_counts
    dim = ((points.reason == _OUT_OF_RANGE) & (c > level + cal.no_return_margin_counts)
           & (c <= level + cal.return_margin_counts))
    if not dim.any():
        return points
    member = points.valid & (label >= 0)
    if not member.any():
        return points
    g = label[member]
    n = np.bincount(g)
    member[member] = n[g] >= SNAP_MIN
    if not member.any():
        return points
    g, n, x, y, mx, my, u, v, alpha = member_axes(points, member, label)
    nx, ny = -np.sin(alpha), np.cos(alpha)
    # in step order: each dim reading's nearest member either way with only dim readings
    # between, at most DIM_CHAIN readings away
    order = rows_in_step_order(steps)
    lab_o = np.where(member, label, -1)[order]
    dim_o = dim[order]
    rows = np.arange(order.size)[:, None]
    stop = (lab_o >= 0) | ~dim_o
    best = np.full(dim_o.shape, np.inf)
    t_best = np.zeros(dim_o.shape)
    inc_best = np.zeros(dim_o.shape)
    sig_best = np.zeros(dim_o.shape)
    ox, oy = points.origin_x[order], points.origin_y[order]
    px, py, c_o = points.x[order], points.y[order], c[order]
    ch, sh = np.cos(points.heading[order]), np.sin(points.heading[order])
    sig_o = points.sigma_m[order]
    sc = cal.sigma_counts()
    last = order.size - 1
    valid_o, d_o = points.valid[order], points.d[order]
    cols = np.broadcast_to(np.arange(dim_o.shape[1]), dim_o.shape)
    sides = []
    for flip in (False, True):
        # the nearest stop at or before each row (after it, flipped), its distance in rows
        st = stop[::-1] if flip else stop
        near = np.maximum.accumulate(np.where(st, rows, -1), axis=0)
        gap = rows - near
        if flip:
            near = np.where(near >= 0, last - near, -1)[::-1]
            gap = gap[::-1]
        sides.append((near, gap))
    for side in (0, 1):
        near, gap = sides[side]
        other = np.maximum(sides[1 - side][0], 0)
        # the stop the other way, where it is a valid reading: no nearer surface's edge
        other_d = np.where((sides[1 - side][0] >= 0) & valid_o[other, cols],
                           d_o[other, cols], np.inf)
        j = np.maximum(near, 0)
        L = lab_o[j, cols]
        ask = dim_o & (near >= 0) & (L >= 0) & (gap <= DIM_CHAIN)
        if not ask.any():
            continue
        Lk = L[ask]
        un = ch[ask] * nx[Lk] + sh[ask] * ny[Lk]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((mx[Lk] - ox[ask]) * nx[Lk] + (my[Lk] - oy[ask]) * ny[Lk]) / un
        inc = np.arccos(np.minimum(np.abs(un), 1.0))
        at_x, at_y = ox[ask] + t * ch[ask], oy[ask] + t * sh[ask]
        jr = j[ask]
        jc = np.nonzero(ask)[1]
        reach = np.hypot(at_x - px[jr, jc], at_y - py[jr, jc])
        ok = (np.isfinite(t) & (t >= cal.min_range_m) & (t <= points.max_range_m)
              & (inc < min(cal.max_incidence_rad, DIM_INCIDENCE_RAD))
              & (reach <= DIM_REACH_M) & (other_d[ask] >= t - EDGE_JUMP_M))
        miss = np.full(t.shape, np.inf)
        if ok.any():
            miss[ok] = np.abs(c_o[ask][ok] - cal.counts(t[ok], inc[ok])) / sc
        better = ok & (miss <= DIM_SIGMAS) & (miss < best[ask])
        if better.any():
            at = tuple(a[better] for a in np.nonzero(ask))
            best[at] = miss[better]
            t_best[at], inc_best[at] = t[better], inc[better]
            sig_best[at] = sig_o[j[at], at[1]]
    put = np.isfinite(best)
    if not put.any():
        return points
    back = np.empty_like(order)
    back[order] = np.arange(order.size)
    put, t_best, inc_best, sig_best = put[back], t_best[back], inc_best[back], sig_best[back]
    d = np.where(put, t_best, points.d)
    return points_with(
        points, d=d, x=np.where(put, points.origin_x + d * np.cos(points.heading), points.x),
        y=np.where(put, points.origin_y + d * np.sin(points.heading), points.y),
        theta=np.where(put, inc_best, points.theta),
        sigma_m=np.where(put, sig_best, points.sigma_m), valid=points.valid | put,
        reason=np.where(put, Reason.OK, points.reason).astype(points.reason.dtype))


PAST_MIN = 10          # a line of at least this many valid members is a wall a beam stops at …
PAST_REACH_SHARE = 0.5  # … over its members' extent and past its ends by this share of the
#                         crossing's range (at least LineOptions.corner_reach_m) …
PAST_CLEAR_SIGMAS = 3.0  # … where a reading's end point lies this many σ …
PAST_CLEAR_M = 0.02      # … and this much past it …
PAST_FEW = 4            # … and at most this many of its line's members do


def past_other_lines(points: Points, label: np.ndarray, counts: np.ndarray, cal: Calibration,
                     options: LineOptions, finder: Callable | None = None
                     ) -> tuple[Points, np.ndarray]:
    """(points, label) with the valid members of a line whose beams meet another line of ≥
    ``PAST_MIN`` members first — within its members' extent or past its ends by up to
    ``PAST_REACH_SHARE`` of the range — ahead of their end points by ``PAST_CLEAR_SIGMAS`` σ
    + ``PAST_CLEAR_M``, on the side of that line where at most ``PAST_FEW`` of their line's
    members lie (a corner, not a wall passing behind the other's end): each read on the
    nearest such line at its incidence where its counts put it there within max(2 cm, 3σ)
    (label −1: placed, not snapped); the others as they were. ``label`` (S, N): the lines as
    kinked_lines left them; ``finder``: the members so asked (the compiled
    :func:`past_members_compiled` by default; the oracle passes its numpy statement
    :func:`past_members`). Why: a wall's last readings at grazing past a corner join the
    line they continue, read at its θ 100-270 mm long (docs/estimator.md, "A beam that meets
    another wall first")."""
    found = (finder or past_members_compiled)(points, label, options)
    if found is None:
        return points, label
    flat, t, un, sig = found
    theta = np.arccos(np.minimum(np.abs(un), 1.0))
    with np.errstate(invalid="ignore"):
        d_l = cal.distance(np.asarray(counts, dtype=float).reshape(-1)[flat], theta)
    fit = ((theta <= cal.max_incidence_rad) & np.isfinite(d_l)
           & (np.abs(d_l - t) <= np.maximum(0.02, 3.0 * sig)))
    taken = {}
    for i, tt, dd, th, ok, sg in zip(flat.tolist(), t.tolist(), d_l.tolist(), theta.tolist(),
                                     fit.tolist(), sig.tolist()):
        if ok and (i not in taken or tt < taken[i][0]):
            taken[i] = (tt, dd, th, sg)
    if not taken:
        return points, label
    flat = np.fromiter(taken, dtype=np.intp)
    _, d_l, theta, sig = (np.array(v) for v in zip(*taken.values()))
    new_label = np.array(label)
    new_label.reshape(-1)[flat] = -1
    return placed_at(points, flat, d_l, theta, sig), new_label


def past_members(points: Points, label: np.ndarray, options: LineOptions
                 ) -> tuple[np.ndarray, ...] | None:
    """:func:`past_other_lines`' gates in numpy: None where none is asked; else the members
    whose beams meet another line first, per pair of lines (the end's, the other) in label
    order, as flat indices, the distance ``t`` along their beams to the other line, their
    beams · its normal ``un`` (:func:`beam_crossings`') and their σ."""
    member = points.valid & (label >= 0)
    if not member.any():
        return None
    wall = np.bincount(label[member]) >= PAST_MIN
    if np.count_nonzero(wall) < 2:
        return None
    g, n, x, y, mx, my, u, v, alpha = member_axes(points, member, label)
    ca, sa = np.cos(alpha), np.sin(alpha)
    along = u * ca[g] + v * sa[g]
    lo = np.full(n.size, np.inf)
    hi = np.full(n.size, -np.inf)
    np.minimum.at(lo, g, along)
    np.maximum.at(hi, g, along)
    # first, the walls' ends: an end seen from the ring past another wall, or none to ask
    walls = wall.nonzero()[0]
    cx, cy = float(points.origin_x.mean()), float(points.origin_y.mean())
    ends = np.concatenate([lo[walls], hi[walls]])
    owner = np.concatenate([walls, walls])
    ex, ey = mx[owner] + ends * ca[owner], my[owner] + ends * sa[owner]
    rng = np.hypot(ex - cx, ey - cy)
    nrm = np.stack([-sa[walls], ca[walls]], 1)
    un, t, ahead, at = beam_crossings(np.full(ex.size, cx), np.full(ex.size, cy),
                                      (ex - cx) / rng, (ey - cy) / rng,
                                      np.stack([mx[walls], my[walls]], 1),
                                      np.stack([ca[walls], sa[walls]], 1), nrm)
    reach = np.maximum(options.corner_reach_m, PAST_REACH_SHARE * t)
    # (a member past by less than PAST_CLEAR_SIGMAS σ + PAST_CLEAR_M at the σ floor is not asked)
    pair = (ahead & (t < rng[:, None] - PAST_CLEAR_SIGMAS * SIGMA_FLOOR_M - PAST_CLEAR_M)
            & (at >= lo[walls] - reach)
            & (at <= hi[walls] + reach) & (owner[:, None] != walls[None, :]))
    if not pair.any():
        return None
    # then, per such pair of lines (a few a sweep), the end's line's members past the other
    idx = member.reshape(-1).nonzero()[0]
    found = []
    for b, c in sorted(set(zip(owner[pair.nonzero()[0]].tolist(),
                                walls[pair.nonzero()[1]].tolist()))):
        k = (g == b).nonzero()[0]
        f = idx[k]
        h = points.heading.reshape(-1)[f]
        un_c, t_c, ahead_c, at_c = beam_crossings(
            points.origin_x.reshape(-1)[f], points.origin_y.reshape(-1)[f], np.cos(h),
            np.sin(h), np.array([[mx[c], my[c]]]), np.array([[ca[c], sa[c]]]),
            np.array([[-sa[c], ca[c]]]))
        un_c, t_c, ahead_c, at_c = un_c[:, 0], t_c[:, 0], ahead_c[:, 0], at_c[:, 0]
        reach_c = np.maximum(options.corner_reach_m, PAST_REACH_SHARE * t_c)
        sig = points.sigma_m.reshape(-1)[f]
        past = (ahead_c & (at_c >= lo[c] - reach_c) & (at_c <= hi[c] + reach_c)
                & (t_c + PAST_CLEAR_SIGMAS * sig + PAST_CLEAR_M < points.d.reshape(-1)[f]))
        # a corner: the line's members all on one side of the other's, but these few
        side = ((x[k] - mx[c]) * -sa[c] + (y[k] - my[c]) * ca[c]) > 0.0
        few = side if 2 * np.count_nonzero(side) < side.size else ~side
        past &= few
        if not past.any() or np.count_nonzero(few) > PAST_FEW:
            continue
        found.append((f[past], t_c[past], un_c[past], sig[past]))
    return tuple(np.concatenate(v) for v in zip(*found)) if found else None


def past_members_compiled(points: Points, label: np.ndarray, options: LineOptions
                          ) -> tuple[np.ndarray, ...] | None:
    """:func:`past_members` in one compiled call (``irring.estimation._lines.past_members``,
    held to it bit for bit by tests/test_past_kernel.py)."""
    f = np.ascontiguousarray
    ox, oy = points.origin_x, points.origin_y
    # (the ring centre by numpy itself, as past_members takes it: a kernel restating numpy's
    # pairwise sum would hang on numpy's internals)
    centre = (float(ox.mean()), float(oy.mean()))
    return _lines.past_members(
        f(label, dtype=np.intp).reshape(-1),
        f(points.valid, dtype=bool).reshape(-1).view(np.uint8),
        f(points.x, dtype=float).reshape(-1), f(points.y, dtype=float).reshape(-1),
        f(ox, dtype=float).reshape(-1), f(oy, dtype=float).reshape(-1),
        f(points.heading, dtype=float).reshape(-1), f(points.d, dtype=float).reshape(-1),
        f(points.sigma_m, dtype=float).reshape(-1), *centre, PAST_MIN, PAST_FEW,
        options.corner_reach_m, PAST_REACH_SHARE, PAST_CLEAR_SIGMAS, PAST_CLEAR_M,
        PAST_CLEAR_SIGMAS * SIGMA_FLOOR_M)


# a reading on no line placed no better than this is not placed: its θ, from its own
# sensor's neighbours alone, puts it anywhere within several σ (docs/estimator.md, "A reading
# on no line placed no better than uncertain")
ALONE_PLACED_SIGMA_M = 2 * UNCERTAIN_SIGMA_M


def unplaced_alone(points: Points, label: np.ndarray) -> Points:
    """``points`` with each valid reading on no line (``label`` (S, N) < 0), placed at a θ
    its own profile gave (θ ≠ 0: a post's or an undecided reading's θ = 0 keeps its doubt as
    σ), whose σ exceeds :data:`ALONE_PLACED_SIGMA_M` made INCIDENCE_UNKNOWN."""
    gone = (points.valid & (np.asarray(label).reshape(points.valid.shape) < 0)
            & (points.sigma_m > ALONE_PLACED_SIGMA_M) & (points.theta != 0.0))
    return invalidated(points, gone.reshape(-1).nonzero()[0], Reason.INCIDENCE_UNKNOWN) \
        if gone.any() else points


EDGE_JUMP_M = 0.10  # a sensor's adjacent reading this much nearer: a nearer surface's edge


def alone_at_an_edge(points: Points, label: np.ndarray, counts: np.ndarray,
                     steps: np.ndarray, cal: Calibration) -> tuple[Points, np.ndarray]:
    """``points`` and ``label`` (S, N: each reading's line, −1: none) with every valid line
    member made INCIDENCE_UNKNOWN and taken off its line where neither of its sensor's
    adjacent steps (``steps`` (S,): the rows' motor steps) is a valid reading of its line
    or of anything not ``EDGE_JUMP_M`` nearer, and one of them is nearer by that: valid
    there, or a return (``counts`` (S, N), NOT_CONVERGED or INCIDENCE_UNKNOWN) that even
    the drop-out angle reads nearer (a sweep's first and last steps are left: the beam beside
    them is another sensor's). Numpy (the oracle's; the fast estimator's:
    :func:`alone_at_an_edge_compiled`). Such a reading lies
    at a nearer surface's edge: a beam past the edge onto the line's wall and a beam
    grazing the edge's flank (dim, read far at the wall's θ) give the same counts, and
    nothing of its own sensor vouches for the wall there. Why: docs/estimator.md, "Alone
    at an edge"."""
    valid = np.asarray(points.valid, dtype=bool)
    steps = np.asarray(steps)
    # rows in step order (a sweep's rows usually are: then no copies)
    order = (slice(None) if steps.size < 2 or bool((steps[1:] > steps[:-1]).all())
             else rows_in_step_order(steps))
    v, lab_o, d = valid[order], np.where(valid, label, -1)[order], points.d[order]
    # how far each reading can lie: its range where valid, past everything where not (a
    # return: below, as far as the drop-out angle reads it)
    r = np.where(v, d, np.inf)
    reason = np.asarray(points.reason)[order]
    returned = (reason == Reason.NOT_CONVERGED) | (reason == Reason.INCIDENCE_UNKNOWN)
    if returned.any():
        far_end = _far_end(cal, np.asarray(counts, dtype=float)[order][returned])
        r[returned] = np.where(np.isfinite(far_end), far_end, np.inf)
    prev_v, prev_l, prev_r = v[:-1], lab_o[:-1], r[:-1]    # the step before rows 1…
    next_v, next_l, next_r = v[1:], lab_o[1:], r[1:]       # the step after rows …S−2
    # a sweep's first and last steps: their other neighbour is another sensor's beam, unread
    alone = lab_o >= 0
    alone[0] = alone[-1] = False
    near_any = np.zeros_like(alone)
    for sl, nv, nl, nr in ((slice(1, None), prev_v, prev_l, prev_r),
                           (slice(None, -1), next_v, next_l, next_r)):
        near = nr <= d[sl] - EDGE_JUMP_M
        alone[sl] &= (nl != lab_o[sl]) & (near | ~nv)
        near_any[sl] |= near
    alone &= near_any
    if not alone.any():
        return points, label
    gone = np.zeros_like(valid)
    gone[order] = alone
    label = label.copy()
    label[gone] = -1
    return invalidated(points, gone, Reason.INCIDENCE_UNKNOWN), label


def _far_end(cal: Calibration, counts: np.ndarray) -> np.ndarray:
    """How far the drop-out angle reads returns of ``counts`` (m; numpy's exp and log)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return cal.distance(counts, cal.max_incidence_rad)


def alone_at_an_edge_compiled(points: Points, label: np.ndarray, counts: np.ndarray,
                              steps: np.ndarray, cal: Calibration
                              ) -> tuple[Points, np.ndarray]:
    """:func:`alone_at_an_edge` with its readings found in one compiled call
    (``irring.estimation._lines.edge_alone``, held to it by tests/test_edge_members.py):
    the same points and labels, to the bit."""
    f = np.ascontiguousarray
    gone = _lines.edge_alone(
        f(label, dtype=np.intp).reshape(-1),
        f(points.valid, dtype=bool).reshape(-1).view(np.uint8),
        f(points.d, dtype=float).reshape(-1), f(points.reason, dtype=np.uint8).reshape(-1),
        f(counts, dtype=float).reshape(-1), rows_in_step_order(steps),
        points.valid.shape[1], Reason.NOT_CONVERGED, Reason.INCIDENCE_UNKNOWN, EDGE_JUMP_M,
        lambda c: _far_end(cal, c))
    if gone is None:
        return points, label
    gone = gone.view(bool).reshape(points.valid.shape)
    label = label.copy()
    label[gone] = -1
    return invalidated(points, gone, Reason.INCIDENCE_UNKNOWN), label


def _line_contradicted(points: Points, counts: np.ndarray, steps: np.ndarray,
                       cal: Calibration, vi: np.ndarray, at: np.ndarray, before: np.ndarray,
                       line: np.ndarray, alpha: np.ndarray, cx: np.ndarray, cy: np.ndarray,
                       need: int = 1) -> np.ndarray:
    """Whether line ``line`` (per reading ``vi[at]``) would have returned
    ``CONTRADICT_SIGMAS`` count σ more than ``need`` of the steps of the gap beside that
    reading read (the gap before it where ``before``, else after; same sensor; up to the
    sensor's next valid reading, at most ``ACROSS_MAX`` + 3 steps): the beam meets the line
    in front of the emitter within the drop-out angle."""
    n_steps, n_sensors = np.shape(counts)
    order = rows_in_step_order(steps)
    rank = np.empty(n_steps, dtype=np.intp)
    rank[order] = np.arange(n_steps)
    flat = vi[at]
    row, k = flat // n_sensors, flat % n_sensors
    step = np.where(before, -1, 1)
    # the sensor's valid reading across the gap bounds it
    other = np.clip(at + step, 0, vi.size - 1)
    same = (vi[other] % n_sensors == k) & (other != at)
    bound = np.where(same, rank[vi[other] // n_sensors], np.where(before, -1, n_steps))
    flat_counts = np.asarray(counts, dtype=float).reshape(-1)
    nx, ny = -np.sin(alpha[line]), np.cos(alpha[line])
    found = np.zeros(at.size, dtype=np.intp)
    for j in range(1, ACROSS_MAX + 4):
        r = rank[row] + j * step
        inside = (r >= 0) & (r < n_steps) & ((r - bound) * step < 0)
        if not inside.any():
            break
        g = order[np.clip(r, 0, n_steps - 1)] * n_sensors + k
        h = points.heading.reshape(-1)[g]
        ox, oy = points.origin_x.reshape(-1)[g], points.origin_y.reshape(-1)[g]
        along = np.cos(h) * nx + np.sin(h) * ny
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((cx[line] - ox) * nx + (cy[line] - oy) * ny) / along
            expect = cal.counts(t, np.arccos(np.minimum(np.abs(along), 1.0)))
        met = (inside & (t > 0) & (np.abs(along) > math.cos(cal.max_incidence_rad))
               & np.isfinite(expect))
        found += met & (expect > flat_counts[g] + CONTRADICT_SIGMAS * cal.sigma_counts())
    return found >= need


def _off_beam(points: Points, at: np.ndarray, line: np.ndarray, alpha: np.ndarray,
              cx: np.ndarray, cy: np.ndarray) -> np.ndarray:
    """|d − t| / σ of each reading ``at`` (flat): how far its range ``d`` lies from ``t``,
    where its beam meets ``line`` (direction ``alpha``, through ``cx``, ``cy``), in its σ
    (inf where the beam runs along the line or meets it behind the emitter)."""
    h = points.heading.reshape(-1)[at]
    nx, ny = -np.sin(alpha[line]), np.cos(alpha[line])
    ox, oy = points.origin_x.reshape(-1)[at], points.origin_y.reshape(-1)[at]
    along = np.cos(h) * nx + np.sin(h) * ny
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((cx[line] - ox) * nx + (cy[line] - oy) * ny) / along
        z = np.abs(points.d.reshape(-1)[at] - t) / points.sigma_m.reshape(-1)[at]
    return np.where(np.isfinite(z) & (t > 0), z, np.inf)


def _on_line(points: Points, at: np.ndarray, line: np.ndarray, alpha: np.ndarray,
             cx: np.ndarray, cy: np.ndarray, cal: Calibration) -> np.ndarray:
    """Whether each reading ``at`` (flat) lies on its ``line`` (direction ``alpha``, through
    ``cx``, ``cy``), within ``LONE_ON_SIGMAS`` of its σ plus ``LONE_ON_M`` across it, read
    at least ``LONE_ON_MARGIN_RAD`` short of the drop-out angle."""
    x, y = points.x.reshape(-1)[at], points.y.reshape(-1)[at]
    off = np.abs(-(x - cx[line]) * np.sin(alpha[line]) + (y - cy[line]) * np.cos(alpha[line]))
    return ((off <= LONE_ON_SIGMAS * points.sigma_m.reshape(-1)[at] + LONE_ON_M)
            & (points.theta.reshape(-1)[at] <= cal.max_incidence_rad - LONE_ON_MARGIN_RAD))


LONE_ON_SIGMAS = 3.0   # the sensor's reading across a gap lies on a line this many σ …
LONE_ON_M = 0.02       # … plus this across it, …
LONE_ON_MARGIN_RAD = math.radians(10)   # … read this far short of the drop-out angle, as
#                                         the few are (a wall read near it falls silent by itself)


CONTRADICT_SIGMAS = 5.0  # a line that would have read a silent step this many count σ
#                          brighter (of up to ACROSS_MAX + 3 steps: 5σ, not 3σ) is not there
ACROSS_MAX = 5  # at most this many readings a line took across a silent gap are moved
OFF_BEAM_SIGMAS = 4.0  # … or whose every reading, at its line's θ, reads this many σ short
#                         of (or past) where its beam meets the line: their own ranges
#                         contradict it (a steep wall that fell silent by itself)
LONE_GAP_MIN = 2  # … or, with no other line beside them, are taken where this many silent
#                  steps contradict it (a surface's end drops out over several steps; a
#                  single silent step in a wall is a flicker)


def across_silence(points: Points, label: np.ndarray, index: np.ndarray, counts: np.ndarray,
                   steps: np.ndarray, cal: Calibration, alpha: np.ndarray, cx: np.ndarray,
                   cy: np.ndarray, gapper: Callable | None = None, alone: bool = False,
                   moves: bool = True) -> tuple[Points, np.ndarray]:
    """Line members whose membership a silent gap contradicts, moved to the line of their
    side of it; numpy, shared by both estimators.

    A sensor's valid readings are split into runs at its silent gaps (:func:`silent_gaps`).
    A run that begins (or ends) with at most ``ACROSS_MAX`` members of a line whose other
    members of this sensor lie across the gap only, followed (preceded) by at least as many
    members of another line, where the line would have returned clearly more light than a
    silent step beside them read (:func:`_line_contradicted`; ``alpha``, ``cx``, ``cy``
    (L,): each line's direction and centroid), or where every one of them lies
    ``OFF_BEAM_SIGMAS`` σ along its beam from the line (:func:`_off_beam`: a steep wall falls
    silent by itself), took those few across the gap: they move to
    the other line, read at the incidence their beam meets it with the noise σ at that θ
    (moved by their ranges alone, only if they then lie on it within ``OFF_BEAM_SIGMAS``);
    where it meets it past the drop-out angle they leave their line, read at θ = 0 with the
    fallback σ (:func:`local_incidence` asks them); ``moves`` False: none of this. With
    ``alone`` (the final pass, after :func:`rejoin_traces`), a run that holds no other line
    beside them, where the line's readings of this sensor go on in the run across the gap
    (or, another line of the wall having taken them, the sensor's reading across the gap
    lies on the line: :func:`_on_line`, it and the few read well short of the drop-out
    angle) and nowhere past them, and ``LONE_GAP_MIN`` of the gap's steps contradict the
    line, has them INCIDENCE_UNKNOWN: nothing on their side says where they lie (their own
    profile runs across the gap). ``label`` (S, N): each reading's line
    or −1; ``index``: the live readings' flat indices in scan order; ``gapper``: the gaps
    (:func:`silent_gaps_compiled` by default; the oracle passes :func:`silent_gaps`).
    Why: docs/estimator.md ("Silent gaps")."""
    n_sensors = label.shape[1]
    vi = index[points.valid.reshape(-1)[index]]
    lab = label.reshape(-1)[vi]
    if vi.size < 3 or not (lab >= 0).any():
        return points, label
    cut = (gapper or silent_gaps_compiled)(vi, counts, steps, points.reason, cal._levels[3])
    if not cut.any():
        return points, label
    sensor = vi % n_sensors
    new_run = cut | np.r_[True, sensor[1:] != sensor[:-1]]
    run = np.cumsum(new_run) - 1
    # stretches: consecutive readings of one run and one label
    new_stretch = new_run | np.r_[True, lab[1:] != lab[:-1]]
    first = new_stretch.nonzero()[0]
    last = np.r_[first[1:] - 1, vi.size - 1]
    s_lab, s_run, s_len = lab[first], run[first], last - first + 1
    s_sens = sensor[first]
    few = (s_lab >= 0) & (s_len <= ACROSS_MAX)
    if not moves:   # the lone case only: a few members' stretch beside a gap, or nothing
        cut_end = np.r_[cut[1:], False]
        if not (few & (cut[first] | cut_end[last])).any():
            return points, label
    n_lines, n_runs = alpha.size, int(run[-1]) + 1
    if alone:   # each row's place in step order (the lone case's gap, final pass only)
        rank = np.empty(len(steps), dtype=np.intp)
        rank[rows_in_step_order(steps)] = np.arange(len(steps))
    mem = lab >= 0
    # members per (run, line) and the runs each (line, sensor) holds members in
    in_run = np.zeros((n_runs, n_lines), dtype=np.intp)
    np.add.at(in_run, (run[mem], lab[mem]), 1)
    runs_of = np.zeros((n_lines, n_sensors), dtype=np.intp)
    held = in_run > 0
    r_idx, l_idx = held.nonzero()
    np.add.at(runs_of, (l_idx, sensor[first[np.searchsorted(s_run, r_idx)]]), 1)
    run_sens = np.zeros(n_runs, dtype=np.intp)
    run_sens[s_run] = s_sens
    # each (line, sensor)'s first and last run holding its members
    run_lo = np.full((n_lines, n_sensors), n_runs, dtype=np.intp)
    run_hi = np.full((n_lines, n_sensors), -1, dtype=np.intp)
    np.minimum.at(run_lo, (lab[mem], sensor[mem]), run[mem])
    np.maximum.at(run_hi, (lab[mem], sensor[mem]), run[mem])
    n_s = first.size
    to = np.full(n_s, -1, dtype=np.intp)
    off = np.zeros(n_s, dtype=bool)   # … or off their line: no other line beside them
    by_range = np.zeros(n_s, dtype=bool)   # moved by their own ranges only (not the light)
    for before, side, nb in ((True, new_run[first], np.arange(1, n_s + 1)),   # a run's first
                             (False, np.r_[new_run[1:], True][last], np.arange(-1, n_s - 1))):
        nb = np.clip(nb, 0, n_s - 1)
        m_lab = s_lab[nb]
        lab_c, m_c = np.maximum(s_lab, 0), np.maximum(m_lab, 0)
        own = side & few & (in_run[s_run, lab_c] == s_len)
        few_here = own & (runs_of[lab_c, s_sens] >= 2)
        beside = (s_run[nb] == s_run) & (nb != np.arange(n_s))
        ok = (few_here & beside & (m_lab >= 0) & (m_lab != s_lab)
              & (in_run[s_run, m_c] >= s_len) & moves)
        # the run holds nothing else on a line (a steep wall's last readings before its
        # drop-out, taken across it by the far wall's line: docs/estimator.md, "Silent gaps"),
        # the line's members of this sensor go on in the run across the gap, and this run is
        # the last (first) of them: they end the line's trace, not a stretch within it
        adj = np.clip(s_run + (-1 if before else 1), 0, n_runs - 1)
        end = (run_hi if before else run_lo)[lab_c, s_sens] == s_run
        # … or the sensor's reading across the gap lies on the line (another line of the
        # same wall took the sensor's readings there: two sensors' lines of one far wall),
        # both it and the few read well short of the drop-out angle, the gap no longer than
        # the steps that contradict the line are read from (a longer one: an opening)
        on_it = np.zeros_like(own)
        if alone:
            at_gap = vi[first if before else last]
            across = np.clip(first - 1 if before else last + 1, 0, vi.size - 1)
            gap = np.abs(rank[vi[across] // n_sensors] - rank[at_gap // n_sensors]) - 1
            on_it = (own & (run[across] == adj) & (sensor[across] == s_sens)
                     & (gap <= ACROSS_MAX + 3)
                     & (points.theta.reshape(-1)[at_gap]
                        <= cal.max_incidence_rad - LONE_ON_MARGIN_RAD)
                     & _on_line(points, vi[across], lab_c, alpha, cx, cy, cal))
        lone = ((few_here | on_it) & ~(beside & (m_lab >= 0)) & alone & end & (adj != s_run)
                & (run_sens[adj] == s_sens) & ((in_run[adj, lab_c] > 0) | on_it))
        for sel, need, act in ((ok, 1, "to"), (lone & ~ok, LONE_GAP_MIN, "off")):
            ask = sel.nonzero()[0]
            if not ask.size:   # the light test (the costly part) only where the rest holds
                continue
            hit = np.zeros(n_s, dtype=bool)
            hit[ask] = _line_contradicted(points, counts, steps, cal, vi,
                                          first[ask] if before else last[ask],
                                          np.full(ask.size, before), lab_c[ask], alpha, cx,
                                          cy, need)
            if act == "to":
                # … or their own ranges contradict their line (a steep wall's own silence
                # contradicts nothing): every one of them off its beam's meet
                rep = np.repeat(ask, s_len[ask])
                j = np.arange(rep.size) - np.repeat(np.cumsum(s_len[ask]) - s_len[ask],
                                                    s_len[ask])
                z = _off_beam(points, vi[first[rep] + j], s_lab[rep], alpha, cx, cy)
                far = np.zeros(n_s, dtype=bool)
                far[ask] = np.minimum.reduceat(z, np.cumsum(s_len[ask]) - s_len[ask]) \
                    > OFF_BEAM_SIGMAS
                by_range |= far & ~hit & (to < 0)
                to = np.where((hit | far) & (to < 0), m_lab, to)
            else:
                off |= hit
    off &= to < 0
    if not ((to >= 0).any() or off.any()):
        return points, label
    label = label.copy()
    if off.any():
        # nothing on their side of the gap says where they lie (their own profile runs
        # across it): not placed
        gone = np.zeros(points.valid.shape, dtype=bool)
        gone.reshape(-1)[vi[np.repeat(off, s_len)]] = True
        label[gone] = -1
        points = invalidated(points, gone, Reason.INCIDENCE_UNKNOWN)
    # (readings their line put past the range are dropped as read: none is made valid)
    move = np.repeat(to >= 0, s_len) & (points.d.reshape(-1)[vi] <= points.max_range_m)
    if not move.any():
        return points, label
    at, to = vi[move], np.repeat(to, s_len)[move]
    h = points.heading.reshape(-1)[at]
    theta = np.arccos(np.minimum(np.abs(np.sin(h - alpha[to])), 1.0))
    s = np.asarray(counts, dtype=float).reshape(-1)[at]
    d = cal.distance(s, theta)
    _, b = cal.log_ab(theta)
    sig_s = cal.sigma_counts() / s
    sigma = range_sigma(b, d, sig_s)
    met = (theta <= cal.max_incidence_rad) & np.isfinite(d) & (d >= cal.min_range_m)
    # those their own ranges took off their line must lie on the target line there
    ranged = np.repeat(by_range, s_len)[move]
    if ranged.any():
        met[ranged] &= _off_beam(placed_at(points, at, d, theta, sigma), at[ranged],
                                 to[ranged], alpha, cx, cy) <= OFF_BEAM_SIGMAS
    # a reading the line of its run meets past the drop-out leaves its line for θ = 0 and
    # the fallback σ: local_incidence then asks its own profile
    la0, b0 = cal._ab0
    d0 = np.exp(la0 + b0 * np.log(s[~met]))
    theta[~met], d[~met], to[~met] = 0.0, d0, -1
    sigma[~met] = theta0_sigma(cal, s[~met], d0, sig_s[~met])
    label.reshape(-1)[at] = to
    return placed_at(points, at, d, theta, sigma), label
