"""Readings nearer than the GP2's peak: which side of the curve each reading is on
(:func:`resolve_foldover`: two passes of the estimator, the branches decided by the lines
two sensors agree on, :func:`_fold_branches`), and the rules that judge the second pass's
result. Why and what was measured: docs/foldover.md.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable

import numpy as np

from ..core import (HOUSING_M, UNCERTAIN_SIGMA_M, Points, Reason, Sweep, points_with,
                    reading_stride, rows_in_step_order)
from .calibration import SIGMA_FLOOR_M, Calibration
from .bends import facets_reread, onto_concave_arcs
from .far_lines import FAR_LINE_MAX_MEMBERS
from .lines import (PINNED_RAD, SNAP_MIN, Estimate, LineOptions, Lines, direction_se,
                    far_sigma_cap, jump_slope, read_to_own_range, scan_order, unplaced)
from .members import CONTRADICT_SIGMAS
from .profiles import LOCAL_STEPS, UNKNOWN_M, profiles_compiled
from .silence import (beam_crossings, classify, clip_at_corners, held_and_pooled, member_spans,
                      silent_behind_a_wall)


REGAIN_RATIO = 2.0  # a fold-over's first-pass line this many times as long gives back θ


_FOLD_ON_M = 0.10      # a reading lies on a known wall this far past its readings' ends
_FOLD_ANCHOR = 2       # a line decides "far" once this many of its members are certainly far
_FOLD_SEEN_M = 0.05    # … where a member of it lies this near the far end point along it
_FOLD_OWN_COS = math.cos(math.radians(20.0))  # … and, unless its own line is anchored,
#                        its own line runs this near its direction, the end point between
#                        the line's members (a near face's far curve crossed it at 25-47°)
_FOLD_TRACE_STEPS = 10  # a reading's own traces: its sensor's readings this many steps either
_FOLD_TRACE_RATIO = 2.0  # side; the near one "as straight" within this ratio of reduced χ²
# the readings whose branch is judged: every one that returned something. A reading the far
# branch puts out of range or at an unknown θ may be on the near branch all the same, and the
# second pass (its neighbours held out) could otherwise read it valid on the far one
_FOLD_JUDGED = (Reason.OK, Reason.NOT_CONVERGED, Reason.OUT_OF_RANGE, Reason.INCIDENCE_UNKNOWN)


_FOLD_PAST_MAX = 6     # a line with at most this many members past a wall its last members'
#                        counts fit ahead of them did not run on past that wall: the few
#                        last readings of the steep wall before its drop-out (1-6 seen; a
#                        wall seen past such a line had 8 or more)
_FOLD_OWN_Z = 3.0      # a member whose own straight slope is this many standard errors off
#                        its line's θ, reading it farther than _placed_apart elsewhere, is
#                        not placed
_APART_SIGMAS = 3.0    # two placements of a reading disagree past this many σ …
_APART_MIN_M = 0.03    # … and this far at least


def _placed_apart(sigma):
    """How far (m) two placements of a reading with σ ``sigma`` (m) may lie before they
    disagree: ``_APART_SIGMAS`` σ, ``_APART_MIN_M`` at least."""
    return np.maximum(_APART_MIN_M, _APART_SIGMAS * sigma)


# a fold-over's reading whose σ says it is placed no better than this (θ = 0 for want of a
# line: σ 65-75 mm; a profile's uncertain θ: 30-60 mm) is INCIDENCE_UNKNOWN: around a ring at
# the housing limit the walls that would pin its θ are held out as near or ambiguous
# (docs/foldover.md, "Far readings nothing places")
FOLD_PLACED_SIGMA_M = UNCERTAIN_SIGMA_M


def resolve_foldover(run: Callable[[np.ndarray, bool, bool], Estimate], sweep: Sweep,
                     cal: Calibration, detail: bool, profiler: Callable | None = None,
                     options: LineOptions = LineOptions()) -> Estimate:
    """Estimate a sweep of a folding sensor: every reading has a far-branch distance (Eq. 10)
    and a near one (:meth:`Calibration.near_distance`, below the peak); pick the branch
    from what the rest of the sweep says, or flag FOLDOVER_AMBIGUOUS.

    ``run(hold, detail, snap)`` is the estimator with the readings ``hold`` kept out;
    ``profiler`` as for :func:`final_estimate`; ``options`` the estimator's. Three steps (docs/foldover.md has the geometry and the measured outcome):

    1. the whole sweep estimated on the far branch: walls give lines (a near wall's readings
       read far give a curve, which the lines of the neighbouring sensors contradict);
    2. each reading judged against those lines (:func:`_fold_branches`): far if its far end
       point lies on another sensor's anchored line (two members certainly far) and no line
       blocks its beam before it, while its near end point lies on no line nor any line's
       extension; near if a line blocks the beam before the far end point and its near end
       point lies on a line; certainly far if its near end point would lie inside the
       ring's housing; else ambiguous;
    3. the sweep estimated again without the near and ambiguous readings; the near readings
       get their near distance at the incidence of the line they lie on, and the lines of a
       curved wall are read on their circle (:func:`onto_concave_arcs`).
    """
    # the judging pass reads each end point on its own (not snapped onto its line)
    first = run(np.zeros(np.shape(sweep.counts), dtype=bool), True, False)
    near, far, d_fold, theta_fold, sigma_fold, walls, doubted = _fold_branches(first, sweep,
                                                                                 cal)
    ambiguous = (d_fold == 0) & ~far & np.isin(first.points.reason, _FOLD_JUDGED)
    second = run(near | ambiguous, True, True)
    p = second.points
    # near readings, and far ones the second pass found on no line (its neighbours held
    # out) nor gave a θ from their own sensor's slope (local_incidence): the distance at
    # the incidence of the line that decided their branch
    lost = p.valid & (second.lines.label < 0) & (p.theta == 0.0)
    put = near | (far & lost & (d_fold > 0))
    q = first.points
    on_first = q.valid & (first.lines.label >= 0)

    def apart(d1, s1, d2, s2):
        return np.abs(d1 - d2) > _placed_apart(np.fmax(s1, s2))

    # … unless the first pass read it on a line of its own elsewhere: the line that decided
    # the branch may be a wall behind the one its beam meets; it cannot be decided
    torn = put & ~near & on_first & apart(d_fold, sigma_fold, q.d, q.sigma_m)
    put &= ~torn
    # … and far ones on a line in the first pass only: that pass's reading
    keep = lost & ~put & ~torn & on_first
    # a reading both passes read, differently: which lines it belongs to depended on how
    # its neighbours were read; it cannot be decided
    differ = torn | (p.valid & q.valid & ~put & ~keep & apart(p.d, p.sigma_m, q.d, q.sigma_m))
    # … or one the first pass put on a line past the range, where its beam meets that line
    differ |= _past_range_elsewhere(p, q, first.lines, ~put & ~keep, apart)
    # a far reading on a fragment of a line the first pass saw whole: on that line
    placed = p.theta
    p = _onto_first_lines(p, q, first.lines, second.lines.label,
                          p.valid & q.valid & ~put & ~keep & ~differ)
    # a curved wall's lines, each fitted over several of its pieces: on their circle
    counts, _ = held_and_pooled(np.asarray(sweep.counts, dtype=float),
                                classify(np.asarray(sweep.counts, dtype=float), sweep, cal),
                                near | ambiguous, np.asarray(sweep.steps), cal,
                                min(float(sweep.max_range_m), cal.max_range_m))
    lab2 = np.where(p.valid & ~put & ~keep & ~differ, second.lines.label, -1)
    arcs = onto_concave_arcs(p, lab2, counts, cal, far_sigma_cap(cal, p.max_range_m))
    # a line over a round room's facets, on no circle: its members re-read on its pieces
    on_arc = np.zeros(p.valid.shape, dtype=bool) if arcs is p else (
        (arcs.d != p.d) | (arcs.theta != p.theta))
    lab2 = np.where(np.isin(lab2, lab2[on_arc & (lab2 >= 0)]), -1, lab2)
    p = facets_reread(arcs, lab2, counts, cal)
    # the far readings still read at a short line's θ: θ is as sure as that line's direction
    from_line = ~put & ~keep & ~differ & (p.theta == placed)
    if put.any() or keep.any() or differ.any():
        x, y, d, theta, sigma = (np.array(v) for v in (p.x, p.y, p.d, p.theta, p.sigma_m))
        d[put], theta[put], sigma[put] = d_fold[put], theta_fold[put], sigma_fold[put]
        x[put] = p.origin_x[put] + d_fold[put] * np.cos(p.heading[put])
        y[put] = p.origin_y[put] + d_fold[put] * np.sin(p.heading[put])
        for mine, theirs in ((x, q.x), (y, q.y), (d, q.d), (theta, q.theta), (sigma, q.sigma_m)):
            mine[keep] = theirs[keep]
        valid, reason, iterations = p.valid.copy(), p.reason.copy(), p.iterations.copy()
        valid[near], reason[near], iterations[near] = True, Reason.OK, 1
        valid[differ], reason[differ] = False, Reason.FOLDOVER_AMBIGUOUS
        for v in (x, y, d, theta, sigma):
            v[differ] = np.nan
        p = replace(p, x=x, y=y, d=d, theta=theta, sigma_m=sigma, valid=valid, reason=reason,
                    iterations=iterations)
    # a far line member behind a wall its counts fit, where its line does not run on past it
    p = _behind_a_wall(p, second.lines.label, first.lines, walls, sweep, cal)
    # … and one whose own profile reads it farther than its 3σ (30 mm at least) from where
    # its line puts it; the profile also reads the far readings the two passes disagreed on
    # (their counts are the wall's all the same): a sweep's first three steps on a steep
    # wall, taken in by the next wall's line, had only each other, too few to tell the 60°
    # slope from the line's 12°
    p = _disowned_by_own_profile(p, second.lines.label, sweep, cal, profiler, p.valid | differ)
    # … and a lone member between two of its own sensor's readings on another line, far off it
    p = _between_another_line(p, second.lines, sweep)
    # a far reading whose own near trace is as straight as its far one: undecided (it took
    # part in the second pass as a far one, so the other readings are read as before)
    if doubted.any():
        p = unplaced(p, (doubted & p.valid).reshape(-1).nonzero()[0], Reason.FOLDOVER_AMBIGUOUS)
    # a beam the judging pass, which saw every reading, found silent stays silent: the
    # second pass, its neighbours held out, put one the first silenced behind a wall it
    # met at 74° (silent_behind_a_wall) on a line at 69°, 127 mm short
    revived = p.valid & (q.reason == Reason.NO_RETURN)
    if revived.any():
        p = unplaced(p, revived.reshape(-1).nonzero()[0], Reason.NO_RETURN)
    # a silent beam is known free only to the nearest line either pass explains it by: the
    # second pass lacks the lines of the readings it held out
    if q.reach_m is not None:
        reach = q.reach_m if p.reach_m is None else np.fmin(p.reach_m, q.reach_m)
        p = replace(p, reach_m=reach)
    # a reading valid only by pooling, behind a wall the second pass held out (a near one)
    if read_to_own_range(cal, p.max_range_m):
        pooled = p.valid & (np.asarray(sweep.counts, dtype=float)
                            < cal.no_return_counts + cal.return_margin_counts)
        if pooled.any():
            p = silent_behind_a_wall(p, pooled, first.lines, cal, options, among=walls,
                                     members=q)
    # a far line member beside a nearer surface its own sensor's next step saw, undecided
    p = _beside_a_hidden_edge(p, second.lines.label, sweep, cal, options)
    # a far reading the judging pass put on no line, placed > 100 mm from θ = 0 by a θ that
    # only the second pass's lines give, or pinned at the drop-out angle: θ undecided
    p = _theta_unsupported(p, ~near & (first.lines.label < 0), second.lines.label, sweep, cal)
    # a far member of a short line: its σ covers the line's direction error
    p = _short_line_sigma(p, second, from_line, cal)
    # a reading placed no better than FOLD_PLACED_SIGMA_M: its θ is 0 for want of a line, an
    # uncertain profile's or a short line's; such end points read 20-90 mm long drew walls
    # outside the room
    vague = p.valid & (p.sigma_m > FOLD_PLACED_SIGMA_M)
    if vague.any():
        p = unplaced(p, vague.reshape(-1).nonzero()[0])
    return replace(second, points=p, lines=second.lines if detail else None)


def _short_line_sigma(p: Points, second: Estimate, from_line: np.ndarray,
                      cal: Calibration) -> Points:
    """``p`` (the fold-over's result) with the σ of each valid far-branch reading that is read
    at the θ of a line of the second pass too short to be snapped onto (fewer than
    ``SNAP_MIN`` members; ``from_line``: it still has that line's θ) widened by that line's
    direction standard error (:func:`direction_se`), as a reading placed by its own
    profile's slope is (:func:`own_slope_sigma`): half the spread of its distance over
    θ ± the error. Unsnapped, such a member keeps its own distance at the line's θ, so the
    direction error enters only through a(θ), b(θ). docs/foldover.md, "A short line's
    direction in its members' σ"."""
    q, label = second.points, second.lines.label
    on = q.valid & (label >= 0)
    if not on.any():
        return p
    line = label[on]
    n = np.bincount(line)
    se = direction_se(q.x[on], q.y[on], q.sigma_m[on] * np.cos(q.theta[on]), line, n.size)
    short = n < SNAP_MIN
    lab = np.where(on, label, 0)
    ask = (p.valid & from_line & on & short.take(lab)
           & (p.d > cal.peak_distance_m) & np.isfinite(p.theta))
    if not ask.any():
        return p
    theta, d, e = p.theta[ask], p.d[ask], se.take(lab[ask])
    counts = cal.counts(d, theta)     # the counts the far branch read at θ (its inverse)
    d_lo, d_hi = cal.distance(np.concatenate([counts, counts]), np.concatenate(
        [np.maximum(theta - e, 0.0), np.minimum(theta + e, cal.max_incidence_rad)])
    ).reshape(2, -1)
    spread = 0.5 * np.abs(d_lo - d_hi)
    sigma = np.array(p.sigma_m)
    # a line so short its direction is not defined leaves its members' σ infinite
    sigma[ask] = np.where(np.isfinite(spread), np.hypot(sigma[ask], spread), np.inf)
    return points_with(p, sigma_m=sigma)


def _beside_a_hidden_edge(p: Points, label: np.ndarray, sweep: Sweep, cal: Calibration,
                          options: LineOptions) -> Points:
    """``p`` (the fold-over's result) with INCIDENCE_UNKNOWN for each valid line member
    (``label``: the second pass's, −1 none) whose own sensor's previous or next reading
    (:func:`~irring.core.reading_stride` motor steps away) is FOLDOVER_AMBIGUOUS and reads,
    far at θ = 0, nearer than the member by more than one surface could make them
    (:func:`polyline_ids`' jump, ``options.jump_sigmas`` times the member's σ for each),
    where the member's counts read at the drop-out angle reach that nearer range: a thin
    post before a wall, its readings held out, its edge met at 62-65° read like the wall
    behind it and joined that wall's line, 100-128 mm long.
    docs/foldover.md, "Beside a nearer surface held out"."""
    mem = p.valid & (label >= 0)
    amb = p.reason == Reason.FOLDOVER_AMBIGUOUS
    if not (mem.any() and amb.any()) or p.valid.shape[0] < 2:
        return p
    counts = np.asarray(sweep.counts, dtype=float)
    far0 = cal.distance(counts, 0.0)
    # neighbours in step order (a falling or shuffled sweep's rows are not), one stride
    # apart (with step_stride 2 no two readings were 1 step apart: it never fired)
    order = rows_in_step_order(sweep.steps)
    far0_s, amb_s = far0[order], amb[order]
    nearer_s = np.full(counts.shape, np.inf)   # the nearer undecided neighbour's θ = 0 range
    turn_s = np.zeros(counts.shape)            # … and how far the beam turned to it
    next_to = (np.diff(np.asarray(sweep.steps)[order]) == reading_stride(sweep))[:, None]
    dh = np.abs(np.diff(p.heading[order], axis=0))
    dh = np.minimum(dh, 2.0 * math.pi - dh)
    for mine, theirs in ((np.s_[:-1], np.s_[1:]), (np.s_[1:], np.s_[:-1])):
        d_nb = np.where(next_to & amb_s[theirs], far0_s[theirs], np.inf)
        closer = d_nb < nearer_s[mine]
        nearer_s[mine] = np.where(closer, d_nb, nearer_s[mine])
        turn_s[mine] = np.where(closer, dh, turn_s[mine])
    nearer, turn = np.empty_like(nearer_s), np.empty_like(turn_s)
    nearer[order], turn[order] = nearer_s, turn_s
    with np.errstate(invalid="ignore"):
        allowed = (p.d * turn * jump_slope(cal.max_incidence_rad)
                   + options.jump_sigmas * math.sqrt(2.0) * p.sigma_m)
        # the curve falls with θ: at the drop-out angle the counts read nearest
        gone = (mem & (nearer < p.d - allowed)
                & (cal.distance(counts, cal.max_incidence_rad) <= nearer))
    if not gone.any():
        return p
    return unplaced(p, gone.reshape(-1).nonzero()[0])


def _theta_unsupported(p: Points, no_first_line: np.ndarray, label: np.ndarray, sweep: Sweep,
                       cal: Calibration) -> Points:
    """``p`` (the fold-over's result) with INCIDENCE_UNKNOWN for each valid reading of
    ``no_first_line`` (far ones the judging pass, which saw every reading, put on no line)
    whose θ reads it more than ``UNKNOWN_M`` from its θ = 0 distance, where that θ is a
    line's of the second pass (``label`` ≥ 0: built without the readings held out) or lies
    within ``PINNED_RAD`` of the drop-out angle (the model's clamp, not a measured slope):
    a GP2Y0A21's walls 600-670 mm away met at 21-33° joined a second-pass line at 58-68°
    and read 120-170 mm short; a flank read at the 70° clamp, 211 mm short.
    docs/foldover.md, "A column read far onto a wall's line; θ that only the second pass
    gives"."""
    ask = p.valid & no_first_line & ((label >= 0)
                                     | (p.theta >= cal.max_incidence_rad - PINNED_RAD))
    if not ask.any():
        return p
    d0 = cal.distance(np.maximum(np.asarray(sweep.counts, dtype=float)[ask], 1.0), 0.0)
    gone = np.zeros(ask.shape, bool)
    gone[ask] = np.abs(p.d[ask] - d0) > UNKNOWN_M
    if not gone.any():
        return p
    return unplaced(p, gone.reshape(-1).nonzero()[0])


def _past_range_elsewhere(p: Points, q: Points, first: Lines, judged: np.ndarray,
                          apart: Callable) -> np.ndarray:
    """(S, N): the readings ``judged`` the second pass (``p``) reads valid that the first
    (``q``, lines ``first``) put on a line but past the max range (OUT_OF_RANGE), where
    their beam meets that line ``apart`` (``apart(d1, σ1, d2, σ2)``, bool) from the second
    pass's distance, or not ahead: the second pass, its neighbours held out, took them into
    another line. docs/foldover.md, "Readings the judging pass read out of range"."""
    lab = first.label
    ask = judged & p.valid & ~q.valid & (q.reason == Reason.OUT_OF_RANGE) & (lab >= 0)
    out = np.zeros(ask.shape, dtype=bool)
    if not ask.any():
        return out
    line = lab[ask]
    h = p.heading[ask]
    un, t, ahead, _ = beam_crossings(p.origin_x[ask], p.origin_y[ask], np.cos(h), np.sin(h),
                                     first.centroid[line], first.direction[line],
                                     first.normal[line])
    k = np.arange(line.size)
    t, ahead = t[k, k], ahead[k, k]
    out[ask] = ~ahead | apart(t, p.sigma_m[ask], p.d[ask], p.sigma_m[ask])
    return out


def _behind_a_wall(p: Points, label: np.ndarray, first: Lines, walls: np.ndarray,
                   sweep: Sweep, cal: Calibration) -> Points:
    """``p`` (the fold-over's result) with INCIDENCE_UNKNOWN for each valid member of a line
    (``label``: the second pass's, −1 none) whose beam crosses a line ``walls`` of the
    judging pass (indices into ``first``; anywhere along it, not the reading's own) where its
    counts read at that line's incidence put it within 3σ, and ahead of its end point by more
    than the 3σ of the two placements' difference, while at most ``_FOLD_PAST_MAX`` members of
    its own line lie past that line (then also its line's members whose counts fit that line
    ahead of them by more than their own 3σ): a wall's last readings before its drop-out,
    adopted at the θ of the wall past the corner, land behind the corner on that wall's
    extension, 100-220 mm long; nothing tells which wall they met. docs/foldover.md, "Past a
    wall its counts fit"."""
    mem = p.valid & (label >= 0)
    if not walls.size or not mem.any():
        return p
    idx = mem.reshape(-1).nonzero()[0]
    s = np.asarray(sweep.counts, dtype=float).reshape(-1)[idx]
    h = p.heading.reshape(-1)[idx]
    ox, oy = p.origin_x.reshape(-1)[idx], p.origin_y.reshape(-1)[idx]
    c, nrm = first.centroid[walls], first.normal[walls]
    un, t, ahead, _ = beam_crossings(ox, oy, np.cos(h), np.sin(h), c, first.direction[walls],
                                     nrm)
    theta_l = np.arccos(np.clip(np.abs(un), 0.0, 1.0))
    d_l = cal.distance(s[:, None], theta_l)
    tol = np.maximum(0.02, 3.0 * np.abs(cal.ab(theta_l)[1]) * d_l
                     * (cal.sigma_counts() / s)[:, None])
    d, sigma = p.d.reshape(-1)[idx][:, None], p.sigma_m.reshape(-1)[idx][:, None]
    # past the crossing by more than its own 3σ, where its counts fit that line …
    behind = (ahead & (theta_l <= cal.max_incidence_rad) & (np.abs(t - d_l) <= tol)
              & (t < d - 3.0 * sigma)
              & (walls[None, :] != first.label.reshape(-1)[idx][:, None]))
    # … and by more than the 3σ of the two placements' difference (each 3σ in quadrature)
    fits = behind & (d - t > np.hypot(tol, 3.0 * sigma))
    pa, pw = fits.nonzero()
    if not pa.size:
        return p
    # the members of each pair's own line, on the far side of the crossed line from the
    # reading's emitter: a wall seen well past that line is not bounded by it there
    lab = label.reshape(-1)
    at = mem.reshape(-1).nonzero()[0]
    at = at[np.argsort(lab[at], kind="stable")]
    n_lines = int(lab[at[-1]]) + 1
    start = np.searchsorted(lab[at], np.arange(n_lines))
    line = lab[idx[pa]]
    n = np.bincount(lab[at], minlength=n_lines)[line]
    pair = np.repeat(np.arange(pa.size), n)
    m = at[np.repeat(start[line] - (np.cumsum(n) - n), n) + np.arange(n.sum())]
    cx, cy, nx, ny = c[pw[pair], 0], c[pw[pair], 1], nrm[pw[pair], 0], nrm[pw[pair], 1]
    side = ((p.x.reshape(-1)[m] - cx) * nx + (p.y.reshape(-1)[m] - cy) * ny
            ) * ((ox[pa[pair]] - cx) * nx + (oy[pa[pair]] - cy) * ny)
    past = np.bincount(pair, weights=side < 0.0, minlength=pa.size)
    ok = past <= _FOLD_PAST_MAX
    # where one member cannot be on its line past that wall, its line's other members behind
    # the same wall are not placed either: nothing tells which of the two they met
    ba, bw = behind.nonzero()
    both = np.isin(lab[idx[ba]] * walls.size + bw, lab[idx[pa[ok]]] * walls.size + pw[ok])
    gone = np.unique(np.r_[idx[pa[ok]], idx[ba[both]]])
    if not gone.size:
        return p
    return unplaced(p, gone)


def _disowned_by_own_profile(p: Points, label: np.ndarray, sweep: Sweep, cal: Calibration,
                             profiler: Callable | None, seen: np.ndarray | None = None
                             ) -> Points:
    """``p`` (the fold-over's result) with INCIDENCE_UNKNOWN for each valid member of a line
    (``label``: the second pass's, −1 none) whose own range profile (:func:`range_profiles`;
    ``profiler``, the compiled :func:`profiles_compiled` by default) is straight and clearly
    steep at a θ more than ``_FOLD_OWN_Z`` standard errors from its line's, where the two
    θ read it more than 3σ apart (30 mm at least): the first reading past a corner, taken in by
    the steep wall's line at 67° (its own slope: 25°), read 135 mm short. The profiles read
    the readings ``seen`` (default: the valid ones). docs/foldover.md, "Past a wall its
    counts fit"."""
    if not (p.valid & (label >= 0)).any():
        return p
    seen = p.valid if seen is None else seen
    steps = np.asarray(sweep.steps)
    index = scan_order(steps, p.valid.shape[1])
    vi = index[seen.reshape(-1)[index]]
    ask = ((label.reshape(-1)[vi] >= 0) & p.valid.reshape(-1)[vi]).nonzero()[0]
    pr = (profiler or profiles_compiled)(p, vi, ask, sweep.counts, steps, cal)
    at = vi[ask]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (np.tan(p.theta.reshape(-1)[at]) - np.abs(pr.slope)) / pr.se
    apart = (np.abs(p.d.reshape(-1)[at] - cal.distance(pr.s[ask], pr.theta))
             > _placed_apart(p.sigma_m.reshape(-1)[at]))
    gone = at[pr.ok & (pr.se > 0) & (np.abs(z) > _FOLD_OWN_Z) & apart]
    if not gone.size:
        return p
    return unplaced(p, gone)


def _between_another_line(p: Points, lines: Lines, sweep: Sweep) -> Points:
    """``p`` (the fold-over's result) with INCIDENCE_UNKNOWN for each valid member of a line
    of ``lines`` (the second pass's) whose own sensor's previous and next readings
    (:func:`~irring.core.reading_stride` motor steps away) are both valid members of one other
    line, with no other reading of its sensor on its own line within ``LOCAL_STEPS`` rows,
    where that line crosses its beam farther from its end point than the 3σ of the difference
    (its 3σ, 30 mm at least, and its neighbours' in quadrature): the beams
    either side met that wall, so a lone reading elsewhere is its noise or an edge narrower
    than two steps, and nothing tells which (a 3σ count spike, taken in by a line 20° off
    the wall beside it, read 100 mm short). docs/foldover.md, "A lone reading between
    another line's"."""
    label = np.where(p.valid, lines.label, -1)
    if p.valid.shape[0] < 3 or not (label >= 0).any():
        return p
    order = rows_in_step_order(sweep.steps)
    lab, sig = label[order], p.sigma_m[order]
    next_to = (np.diff(np.asarray(sweep.steps)[order]) == reading_stride(sweep))[:, None]
    before = np.full(lab.shape, -1)
    after = np.full(lab.shape, -1)
    before[1:] = np.where(next_to, lab[:-1], -1)
    after[:-1] = np.where(next_to, lab[1:], -1)
    # … and no other reading of its sensor within LOCAL_STEPS rows on its line (a far wall
    # split in two lines 35 mm apart, its sensor's readings alternating, is one wall)
    alone = (lab >= 0) & (before >= 0) & (before == after) & (before != lab)
    for k in range(2, LOCAL_STEPS + 1):
        alone[k:] &= lab[:-k] != lab[k:]
        alone[:-k] &= lab[k:] != lab[:-k]
    lone = np.zeros(lab.shape, dtype=bool)
    lone[order] = alone
    if not lone.any():
        return p
    other, sig_nb = np.empty_like(before), np.zeros(lab.shape)
    other[order] = before
    sig_nb[order[1:-1]] = np.fmax(sig[:-2], sig[2:])   # the neighbours' placement's noise
    at = lone.nonzero()
    _, _, _, t = _paired_crossings(p, at, lines, other[at])
    # … off by more than the 3σ of the two placements' difference (each 3σ in quadrature)
    off = (t > 0.0) & (np.abs(t - p.d[at])
                       > np.hypot(_placed_apart(p.sigma_m[at]), _APART_SIGMAS * sig_nb[at]))
    if not off.any():
        return p
    return unplaced(p, np.ravel_multi_index(tuple(a[off] for a in at), p.valid.shape))


def _paired_crossings(p: Points, at, lines: Lines, line: np.ndarray):
    """Each reading ``at`` (an index or mask of ``p``'s arrays) against its own ``line`` of
    ``lines``: its beam's unit direction (ux, uy), beam · the line's normal (``across``) and
    the distance along the beam to where it meets the line (``t``; inf or NaN where parallel).
    :func:`silence.beam_crossings` pairs every beam with every line."""
    ux, uy = np.cos(p.heading[at]), np.sin(p.heading[at])
    nx, ny = lines.normal[line, 0], lines.normal[line, 1]
    across = nx * ux + ny * uy
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((lines.centroid[line, 0] - p.origin_x[at]) * nx
             + (lines.centroid[line, 1] - p.origin_y[at]) * ny) / across
    return ux, uy, across, t


def _onto_first_lines(p: Points, q: Points, first: Lines, label_second: np.ndarray,
                      both: np.ndarray) -> Points:
    """``p`` (the fold-over's second pass) with the readings ``both`` passes read valid that
    sit on a short line of the second pass (at most ``FAR_LINE_MAX_MEMBERS`` members) but
    on a line of the first pass (``q``, ``first``) with at least ``REGAIN_RATIO`` times the
    members put where their beam meets that line, when it lies within 3σ of their reading at
    its θ: the second pass held out the ambiguous readings, and the fragment left takes its
    direction from a few noisy ones (15° off on a 7-member piece of a 27-member line).
    docs/foldover.md, "Short far lines"."""
    def size(label):
        on = label >= 0
        return np.where(on, np.bincount(label[on], minlength=1).take(np.maximum(label, 0)), 0)

    lab1, n2 = first.label, size(label_second)
    regain = (both & (label_second >= 0) & (n2 <= FAR_LINE_MAX_MEMBERS)
              & (size(lab1) >= REGAIN_RATIO * np.maximum(n2, 1)))
    if not regain.any():
        return p
    ux, uy, across, t = _paired_crossings(p, regain, first, lab1[regain])
    fits = ((np.abs(across) > 1e-9) & (np.abs(t - q.d[regain]) <= 3.0 * q.sigma_m[regain])
            & (t > 0.0) & (t <= p.max_range_m))   # never a point past the range
    at = tuple(a[fits] for a in np.nonzero(regain))
    if not at[0].size:
        return p
    x, y, d, theta = (np.array(v) for v in (p.x, p.y, p.d, p.theta))
    d[at], theta[at] = t[fits], q.theta[at]
    x[at] = p.origin_x[at] + t[fits] * ux[fits]
    y[at] = p.origin_y[at] + t[fits] * uy[fits]
    return replace(p, x=x, y=y, d=d, theta=theta)


def _fold_branches(first: Estimate, sweep: Sweep, cal: Calibration):
    """(near, far, d, θ, σ), all (S, N), the lines two sensors agree on (indices into
    ``first.lines``) and ``doubted`` (S, N), from the far-branch estimate ``first`` (see
    :func:`resolve_foldover`); vectorised over (readings, lines). ``far`` includes the
    readings whose near end point would lie inside the housing; d > 0 where a line decided
    the branch: the distance on that branch at that line's incidence (0 elsewhere);
    ``doubted``: far ones whose own near trace is as straight as their far one while their
    own line is not anchored (:func:`_near_trace_straight`), undecided in the end."""
    p, found = first.points, first.lines
    shape = p.valid.shape
    counts = np.asarray(sweep.counts, dtype=float)
    live = np.isin(p.reason, _FOLD_JUDGED)
    ox, oy, h = p.origin_x, p.origin_y, p.heading
    pose = np.asarray(sweep.reading_poses if sweep.reading_poses is not None else sweep.pose,
                      dtype=float)
    # the farthest the near branch can put a reading (its peak counts are lowest at the
    # steepest θ): inside the housing even there, the reading is on the far branch
    rows = cal.theta_rad[cal.theta_rad <= cal.max_incidence_rad]
    far_near = cal.peak_distance_m * counts / float(np.min(cal.counts(cal.peak_distance_m, rows)))
    hx, hy = ox + far_near * np.cos(h), oy + far_near * np.sin(h)
    housing = np.hypot(hx - pose[..., 0], hy - pose[..., 1]) < sweep.ring.radius_m + HOUSING_M
    cand = live & ~housing
    if not cand.any():
        return (np.zeros(shape, bool), housing & live, *(np.zeros(shape) for _ in range(3)),
                np.zeros(0, np.intp), np.zeros(shape, bool))
    idx = cand.reshape(-1).nonzero()[0]
    s = counts.reshape(-1)[idx]
    h_idx = h.reshape(-1)[idx]
    own = found.label.reshape(-1)[idx] if found is not None else np.full(idx.size, -1)
    n_sensors = shape[1]
    sensor = idx % n_sensors
    # the lines with the extent of their valid members along them
    use = (np.zeros(0, dtype=int) if found is None else found.usable.nonzero()[0])
    if use.size:
        c, e, nrm = found.centroid[use], found.direction[use], found.normal[use]
        col, at, mcol, m_along, lo, hi = member_spans(p, found, use)
        # a line one sensor alone saw may be a wrong-branch curve cut into pieces (or a few
        # readings at the peak, where both branches meet, with a poor direction): only lines
        # two sensors agree on judge other readings
        pairs = np.unique(mcol * n_sensors + at % n_sensors)
        trusted = np.bincount(pairs // n_sensors, minlength=use.size) >= 2
        line_sensor = found.start[use] % n_sensors
        # certainly far members: their near end point would lie inside the housing
        sure = housing.reshape(-1)[at]
        certain = np.bincount(mcol[sure], minlength=use.size)
        anchored = certain >= _FOLD_ANCHOR
    else:
        certain = np.zeros(1, int)
        anchored = np.zeros(0, bool)
        at = mcol = np.zeros(0, int)
        m_along = np.zeros(0)
        c = e = nrm = np.zeros((0, 2))
        lo = hi = np.zeros(0)
        trusted = np.zeros(0, bool)
        line_sensor = np.zeros(0, int)
    # a wall ends at a corner: a line's extension stops where it meets another trusted line
    # (past a box's corner its extension would cut the beams that graze the next face)
    lo_b, hi_b = clip_at_corners(c, e, lo, hi)
    # every candidate's beam against every line: crossing distance t, incidence there
    un, t, ahead, along = beam_crossings(ox.reshape(-1)[idx], oy.reshape(-1)[idx],
                                         np.cos(h_idx), np.sin(h_idx), c, e, nrm)   # (A, L)
    # each reading's own line is where its far end point lies: it blocks nothing
    other = (use[None, :] != own[:, None]) & trusted[None, :]
    block_span = ahead & other & (along >= lo_b) & (along <= hi_b)
    on_span = ahead & other & (along >= lo - _FOLD_ON_M) & (along <= hi + _FOLD_ON_M)
    theta_l = np.arccos(np.clip(np.abs(un), 0.0, 1.0))
    seen = theta_l <= cal.max_incidence_rad
    sig_s = cal.sigma_counts() / s                                          # relative
    s2 = s[:, None]
    d_far = cal.distance(s2, theta_l)
    d_near = cal.near_distance(s2, theta_l)
    tol_far = np.maximum(0.02, 3.0 * np.abs(cal.ab(theta_l)[1]) * d_far * sig_s[:, None])
    tol_near = np.maximum(0.008, 3.0 * d_near * sig_s[:, None])
    # the shortest far distance the reading can mean (its θ unknown) and the nearest near one
    far_min = np.minimum(cal.distance(s, 0.0), cal.distance(s, cal.max_incidence_rad))
    near_min = cal.near_distance(s, 0.0)
    blocks = block_span & (t < far_min[:, None] - tol_far)
    blocked_far = blocks.any(axis=1)
    blocked_near = (block_span & (t < near_min[:, None] - tol_near)).any(axis=1)
    near_fit = np.where(on_span & seen, np.abs(t - d_near) / tol_near, np.inf)
    near_on = (near_fit <= 1.0).any(axis=1)
    ocol = (np.where(own >= 0, col[np.maximum(own, 0)], -1) if use.size
            else np.full(idx.size, -1))
    gap = _across_a_gap(blocks, (along >= lo) & (along <= hi), ocol, trusted,
                        ahead & seen & (along >= lo) & (along <= hi)
                        & (np.abs(t - d_far) <= tol_far), e)
    is_near = blocked_far & near_on & ~blocked_near & ~gap
    # a near end point on a trusted line anywhere along it (a wall runs on past the stretch
    # seen far: where it passes a sensor closely, only sensors further round see it far)
    # leaves the near branch possible
    near_any = (ahead & other & seen & (np.abs(t - d_near) <= tol_near)).any(axis=1)
    can_far = ~blocked_far & ~near_on & ~near_any
    fit_far = np.where(on_span & seen & (line_sensor[None, :] != sensor[:, None]),
                       np.abs(t - d_far) / tol_far, np.inf)
    # … and only where the line is seen: behind a pilaster or a box the wall's line runs on
    # unseen, and a near reading of the face in front, read far, lands on it there
    seen_there, between = _seen_there(fit_far <= 1.0, along, mcol, m_along)
    # … and only where the reading's own far trace agrees (a near face read far can land
    # on the wall behind it)
    # its own line anchored by certainly far members of its own sensor, of its own trace: a
    # line its sensor's readings join across a silence (a post's flank dropping out, then
    # the wall beyond) is two surfaces, and the far side's readings vouch for none on the
    # near side (docs/foldover.md, "A post read far onto the wall its sensor meets next")
    own_certain, bridged = _own_trace_members(p, np.asarray(sweep.steps), counts, cal, idx,
                                              ocol, sensor, at, mcol, housing.reshape(-1)[at],
                                              (c, e, nrm, lo, hi), n_sensors)
    fit_far[~seen_there | ~_own_trace_agrees(between & ~bridged[:, None], ocol, own_certain,
                                             e)] = np.inf
    # Two sensors agreeing on a line is no proof it is seen far: two neighbours close to one
    # surface both read it far, and their far end points (curves) can fit one line behind it.
    # A line decides "far" only once it is anchored: _FOLD_ANCHOR members certainly far (near
    # end point inside the housing, or decided far on an anchored line), spread line to line.
    while True:
        far_fit = np.where(anchored[None, :], fit_far, np.inf)
        is_far = can_far & (far_fit <= 1.0).any(axis=1)
        sel = is_far & (ocol >= 0)
        more = anchored | (np.bincount(ocol[sel], minlength=use.size) >= _FOLD_ANCHOR)
        if np.array_equal(more, anchored):
            break
        anchored = more
    # … and not where its sensor's near trace is as straight as its far one, unless its own
    # line is anchored: a near face's far curve can run along the wall behind it while its
    # near trace fits the face, and then which branch it is on cannot be told. Flagged after
    # the second pass only: held out of either pass, such readings un-anchored right lines
    # and left other readings valid > 100 mm off (docs/foldover.md)
    straight = _near_trace_straight(counts, p, np.asarray(sweep.steps), cand, cal)
    doubted = np.zeros(shape, bool)
    doubted.reshape(-1)[idx] = is_far & straight.reshape(-1)[idx] & ~own_certain
    near, far = np.zeros(shape, bool), housing & live
    near.reshape(-1)[idx] = is_near
    far.reshape(-1)[idx] = is_far
    out = [np.zeros(shape) for _ in range(3)]
    if use.size and (is_near | is_far).any():
        rows = np.arange(idx.size)
        pick_n = (rows, np.argmin(near_fit, axis=1))
        pick_f = (rows, np.argmin(far_fit, axis=1))
        dist = np.where(is_near, d_near[pick_n], np.where(is_far, d_far[pick_f], 0.0))
        theta = np.where(is_near, theta_l[pick_n], np.where(is_far, theta_l[pick_f], 0.0))
        slope = np.where(is_near, 1.0, np.abs(cal.ab(theta)[1]))     # |d ln d / d ln S|
        out[0].reshape(-1)[idx] = dist
        out[1].reshape(-1)[idx] = theta
        out[2].reshape(-1)[idx] = np.where(dist > 0, np.maximum(slope * dist * sig_s,
                                                                 SIGMA_FLOOR_M), 0.0)
    return near, far, out[0], out[1], out[2], use[trusted], doubted


def _across_a_gap(blocks: np.ndarray, in_span: np.ndarray, ocol: np.ndarray,
                  trusted: np.ndarray, far_on: np.ndarray, e: np.ndarray) -> np.ndarray:
    """(A,): the readings whose beam the lines ``blocks`` (A, L) only past their members'
    span (``in_span``, (A, L): the crossing between them), while the far end point lies on a
    line two sensors agree on (``trusted``, (L,)) running within 20° (``_FOLD_OWN_COS``) of
    such a blocking line (directions ``e``, (L, 2)): the reading's own first-pass line
    (``ocol``, position among the lines, −1 none) or one it fits between its members
    (``far_on``, (A, L)). The walls either side of a niche, extended across its mouth,
    block the beams looking in, whose far end points lie on its back: the mouth may be open,
    or that line a near wall read far; the near branch is not decided.
    docs/foldover.md, "Across a niche's mouth"."""
    holds = ((ocol[:, None] == np.arange(e.shape[0])[None, :]) | far_on) & trusted[None, :]
    # a niche's back runs along its mouth; a corner's other wall, across it, is often where
    # a near reading of one wall lands when read far
    along_it = (holds.astype(float) @ (np.abs(e @ e.T) >= _FOLD_OWN_COS).astype(float)) > 0
    return (blocks & ~in_span & along_it).any(axis=1) & ~(blocks & in_span).any(axis=1)


def _trace_chi2(x: np.ndarray, y: np.ndarray, sigma: np.ndarray, use: np.ndarray,
                order: np.ndarray, steps_either_side: int) -> np.ndarray:
    """(S, N): the reduced χ² of one straight line through each reading's end point (x, y,
    σ, all (S, N)) and those of its sensor's readings ``use`` within ``steps_either_side``
    steps either side (rows in step ``order``); NaN where fewer than 5 such points."""
    shape = use.shape
    x, y, sigma, ok = (np.where(use, v, 0.0)[order] for v in (x, y, sigma, use.astype(float)))
    w = steps_either_side
    x, y, sigma, ok = (np.pad(v, ((w, w), (0, 0))) for v in (x, y, sigma, ok))
    rows = shape[0]
    # sums relative to each reading's own point (no cancellation)
    x0, y0 = x[w:w + rows], y[w:w + rows]
    n = sx = sy = sxx = syy = sxy = ss = np.zeros(shape)
    for o in range(2 * w + 1):
        m = ok[o:o + rows]
        dx, dy = (x[o:o + rows] - x0) * m, (y[o:o + rows] - y0) * m
        n, sx, sy, ss = n + m, sx + dx, sy + dy, ss + sigma[o:o + rows] ** 2 * m
        sxx, syy, sxy = sxx + dx * dx, syy + dy * dy, sxy + dx * dy
    with np.errstate(divide="ignore", invalid="ignore"):
        a, c = sxx / n - (sx / n) ** 2, syy / n - (sy / n) ** 2
        b = sxy / n - (sx / n) * (sy / n)
        smallest = 0.5 * (a + c) - np.sqrt(0.25 * (a - c) ** 2 + b * b)
        chi2 = n * n * np.maximum(smallest, 0.0) / ((n - 2.0) * ss)
    chi2[(n < 5) | (ok[w:w + rows] == 0)] = np.nan
    out = np.empty(shape)
    out[order] = chi2
    return out


def _near_trace_straight(counts: np.ndarray, p: Points, steps: np.ndarray,
                         use: np.ndarray, cal: Calibration) -> np.ndarray:
    """(S, N) bool: whether a reading's own near trace is as straight as its far one: the
    end points (θ = 0) of its sensor's readings ``use`` within ``_FOLD_TRACE_STEPS`` steps
    either side fit one line on the near branch with a reduced χ² at most
    ``_FOLD_TRACE_RATIO`` times the far branch's (NaN, fewer than 5 points: False). A flat
    face 30 mm in front gives a straight near trace; a wall read far a straight far one.
    docs/foldover.md, "Both branches straight"."""
    order = rows_in_step_order(steps)
    rel = cal.sigma_counts() / np.maximum(counts, 1.0)
    chi2 = []
    for d, slope in ((cal.near_distance(counts, 0.0), 1.0),
                     (cal.distance(np.maximum(counts, 1.0), 0.0), abs(float(cal.ab(0.0)[1])))):
        x, y = p.origin_x + d * np.cos(p.heading), p.origin_y + d * np.sin(p.heading)
        chi2.append(_trace_chi2(x, y, np.maximum(slope * d * rel, 1e-6), use, order,
                                _FOLD_TRACE_STEPS))
    near, far = chi2
    return near <= _FOLD_TRACE_RATIO * far


def _own_trace_members(p: Points, steps: np.ndarray, counts: np.ndarray, cal: Calibration,
                       idx: np.ndarray, ocol: np.ndarray, sensor: np.ndarray, at: np.ndarray,
                       mcol: np.ndarray, sure: np.ndarray, lines: tuple, n_sensors: int
                       ) -> tuple[np.ndarray, np.ndarray]:
    """(own_certain, bridged), each (A,), for the readings ``idx`` (flat) of ``sensor`` on
    their first-pass lines ``ocol`` (−1 none; members ``at`` of line ``mcol``, ``sure``
    certainly far; ``lines`` = (c, e, nrm, lo, hi) as in :func:`_fold_branches`).
    ``bridged``: the line takes readings of the sensor from either side of a silent
    (NO_RETURN) step of it whose beam would have met the line within its members' span and
    the drop-out angle, ``CONTRADICT_SIGMAS`` count σ brighter than it read: two surfaces,
    not one. There ``own_certain`` counts only the certainly far members of the reading's
    own stretch (between such silences): ``_FOLD_ANCHOR`` of them. A post's flank drops out
    near 70°, and the wall its beam meets next continues the post's far curve on one line.
    docs/foldover.md, "A post read far onto the wall its sensor meets next"."""
    S = counts.shape[0]
    has = ocol >= 0
    key = np.where(has, ocol * n_sensors + sensor, 0)
    pair = mcol * n_sensors + at % n_sensors
    n_pairs = max(int(max(pair.max(initial=0), key.max(initial=0))) + 1,
                  lines[0].shape[0] * n_sensors)
    plain = np.bincount(pair[sure], minlength=n_pairs)
    own_certain = has & (plain[key] >= _FOLD_ANCHOR)
    bridged = np.zeros(idx.size, bool)
    silent = np.asarray(p.reason) == Reason.NO_RETURN
    if not at.size or not silent.any():
        return own_certain, bridged
    # each reading's stretch: the silent steps of its sensor before it, in step order
    order = rows_in_step_order(steps)
    seg = np.empty(silent.shape, np.int64)
    seg[order] = np.cumsum(silent[order], axis=0)
    seg = seg.reshape(-1)
    mseg = seg[at]
    lo_s = np.full(n_pairs, np.iinfo(np.int64).max)
    hi_s = np.full(n_pairs, -1)
    np.minimum.at(lo_s, pair, mseg)
    np.maximum.at(hi_s, pair, mseg)
    # the silent beams against every line: met ahead, within the span and the drop-out
    # angle, and the counts it would have returned
    c, e, nrm, lo, hi = lines
    g = silent.reshape(-1).nonzero()[0]
    gk = np.arange(c.shape[0])[None, :] * n_sensors + (g % n_sensors)[:, None]   # (G, L)
    across = (lo_s[gk] < seg[g][:, None]) & (seg[g][:, None] <= hi_s[gk])
    ask = across.any(axis=1)
    if not ask.any():
        return own_certain, bridged
    g, gk, across = g[ask], gk[ask], across[ask]
    h = p.heading.reshape(-1)[g]
    un, t, ahead, along = beam_crossings(p.origin_x.reshape(-1)[g], p.origin_y.reshape(-1)[g],
                                         np.cos(h), np.sin(h), c, e, nrm)       # (G, L)
    met = (ahead & (along >= lo) & (along <= hi)
           & (np.abs(un) > math.cos(cal.max_incidence_rad)))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        expect = cal.counts(np.where(met, t, 1.0), np.arccos(np.minimum(np.abs(un), 1.0)))
    met &= np.isfinite(expect) & (expect > counts.reshape(-1)[g][:, None]
                                  + CONTRADICT_SIGMAS * cal.sigma_counts())
    split = np.bincount(gk[across & met], minlength=n_pairs) > 0
    bridged = has & split[key]
    if bridged.any():
        rows = S + 1
        sure_keys = np.sort(pair[sure] * rows + mseg[sure])
        q = key * rows + seg[idx]
        n = (np.searchsorted(sure_keys, q, side="right")
             - np.searchsorted(sure_keys, q, side="left"))
        own_certain = np.where(bridged, has & (n >= _FOLD_ANCHOR), own_certain)
    return own_certain, bridged


def _own_trace_agrees(between: np.ndarray, ocol: np.ndarray, own_certain: np.ndarray,
                      e: np.ndarray) -> np.ndarray:
    """(A, L): whether a reading's far end point on a line may decide "far" as far as its
    own first-pass line is concerned: that line (``ocol``, position among the lines of
    direction ``e``; −1 none) has ``_FOLD_ANCHOR`` members of the reading's own sensor
    certainly far (``own_certain``, (A,)), or the end point lies ``between`` the line's
    members (:func:`_seen_there`) and its own line runs within 20° of it
    (``_FOLD_OWN_COS``). A face 30 mm in front read far lands on the wall behind a box as
    deep as its far-branch distance, where the wall comes into view past the box (0-50 mm
    past its last member) or across its seen stretch, while the face's own far curve runs
    across the wall and holds no certainly far member; a column 22 mm away read far joins
    the line of the wall behind it, whose other sensor's members anchor it.
    docs/foldover.md, "A near face read far onto the wall behind a box"."""
    has = ocol >= 0
    along = np.zeros(between.shape, bool)
    if e.shape[0]:
        along = has[:, None] & (np.abs(e[np.maximum(ocol, 0)] @ e.T) >= _FOLD_OWN_COS)
    return (has & own_certain)[:, None] | (between & along)


def _seen_there(pairs: np.ndarray, along: np.ndarray, mcol: np.ndarray,
                m_along: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(seen, between), each (A, L): for the (reading, line) ``pairs``, whether the line has
    a valid member (line ``mcol``, at ``m_along`` along it: :func:`member_spans`) within
    ``_FOLD_SEEN_M`` of the crossing ``along`` it, and whether it has one that near on
    either side of it (both True elsewhere)."""
    out = np.ones(pairs.shape, bool)
    both = np.ones(pairs.shape, bool)
    a_idx, l_idx = pairs.nonzero()
    if not a_idx.size:
        return out, both
    # members sorted by line, then along it: a query's neighbours are found by bisection
    span = 2.0 * (float(np.max(np.abs(m_along))) + 1.0)
    keys = np.sort(mcol * span + m_along)
    q = l_idx * span + along[a_idx, l_idx]
    i = np.searchsorted(keys, q)
    left = keys[np.clip(i - 1, 0, keys.size - 1)]
    right = keys[np.clip(i, 0, keys.size - 1)]
    # keys of other lines lie more than ``span`` away; at the ends searchsorted clips
    below, above = np.abs(q - left) <= _FOLD_SEEN_M, np.abs(q - right) <= _FOLD_SEEN_M
    below &= left <= q
    above &= right >= q
    out[a_idx, l_idx] = np.minimum(np.abs(q - left), np.abs(q - right)) <= _FOLD_SEEN_M
    both[a_idx, l_idx] = below & above
    return out, both
