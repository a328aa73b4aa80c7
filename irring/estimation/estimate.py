"""The paper's iterative range estimator (Park, Baek & Lee 2005, Table II): ADC counts and a
:class:`~irring.estimation.calibration.Calibration` in, end points out.

This module is the schedule (:func:`_estimate`, :func:`final_estimate`); the rules it runs live
beside it, one module per topic (lines, bounds, profiles, arcs, bends, far_lines, traces,
counts, members, silence, foldover: docs/estimator.md, "Where the code is").

How it works, its assumptions and measured figures: docs/estimator.md.
"""

from __future__ import annotations

import functools
import math
import operator
from dataclasses import replace
from typing import Callable

import numpy as np

from ..core import (MAX_ESTIMATED_READINGS, Points, Reason, Ring, Sweep, beam_geometry,
                    points_with, work_bytes, work_refusal)
from ..errors import TooBig
from ..resources import kernel
# Calibration is the estimator's input; calibration files written before 2026-11-26 name
# it here (irring.estimation.estimate.Calibration.load), so this module exports it too
from .calibration import RANGE_SIGMAS, SIGMA_FLOOR_M, Calibration
from .arcs import (columns_across_sensors, local_incidence, onto_post_circles,
                   round_runs_compiled)
from .bends import (bent_ends_compiled, bowed_lines_compiled, faceted_lines_compiled,
                    kinked_lines)
from .counts import CountsFits, counts_disown_lines
from .far_lines import (doubt_far_lines, far_posts, fused_lines, onto_crossed_lines,
                        short_far_lines_compiled, unplaced_returns)
from .foldover import resolve_foldover
from .lines import (PINNED_RAD, Estimate, LineOptions, Lines, far_sigma_cap, jump_slope,
                    lines_record, read_to_own_range, scan_order, segment, snap_members,
                    snap_to_lines)
from .members import (across_silence, alone_at_an_edge_compiled, dim_returns_on_lines,
                      past_other_lines, unplaced_alone)
from .profiles import (SharedProfiles, profiles_compiled, theta_free_in_noise,
                       unknown_theta_free)
from .seam import in_sweep_rows, started_at, turn_start
from .silence import (beside_a_return_compiled, censored_lines, classify, drop_beyond_range,
                      held_and_pooled, no_return_reach, noise_past_line_end, silent_behind_a_wall,
                      silent_reach)
from .traces import TraceKernels, TraceSteps, rejoin_traces


_iterate = kernel("estimation._iterate")
_lines = kernel("estimation._lines")
# plain ints: an array compared with an IntEnum member takes numpy's slow path (~7 µs)
_NO_RETURN, _OUT_OF_RANGE = int(Reason.NO_RETURN), int(Reason.OUT_OF_RANGE)


REGROUP_WINDOW = 8  # a third or later grouping only within the first 8 iterations
CORNER_WINDOW = 14  # corners re-decided at a grouping's first check, later ones only before
#                     this iteration (a late move left its lines too few iterations to settle)
MAX_GAIN = 8.0      # the held iteration's secant step at most 8× the plain one


def estimate(sweep: Sweep, calibration: Calibration | None = None, *, max_iterations: int = 20,
             tolerance_rad: float = math.radians(0.1), iterate: bool = True,
             lines: LineOptions = LineOptions(), keep_unconverged: bool = False) -> Points:
    """Counts → end points by the iterative estimation of Table II (see docs/estimator.md).

    ``calibration`` defaults to :meth:`Calibration.for_sweep` (the datasheet curve).
    ``iterate=False`` gives the θ = 0 assumption (Eq. 10 with a(0), b(0)).
    ``keep_unconverged``: readings still moving after ``max_iterations`` are valid at the θ
    they reached (the estimate after k iterations) instead of NOT_CONVERGED.
    """
    return full_turn(_estimate, sweep, calibration, max_iterations, tolerance_rad, iterate,
                     lines, keep_history=False, damping=True, detail=False,
                     keep_unconverged=keep_unconverged).points


def estimate_detail(sweep: Sweep, calibration: Calibration | None = None, *,
                    max_iterations: int = 20, tolerance_rad: float = math.radians(0.1),
                    iterate: bool = True, lines: LineOptions = LineOptions(),
                    keep_history: bool = False, damping: bool = True,
                    keep_unconverged: bool = False) -> Estimate:
    """:func:`estimate` that also returns the final lines and (optionally) θ per iteration.

    ``damping=False`` switches the step control off: every step is the plain a ← G(a) of
    Table II (to show what the control is for).
    """
    return full_turn(_estimate, sweep, calibration, max_iterations, tolerance_rad, iterate,
                     lines, keep_history=keep_history, damping=damping, detail=True,
                     keep_unconverged=keep_unconverged)


def full_turn(run: Callable[..., Estimate], sweep: Sweep, calibration: Calibration | None,
              *args, **kwargs) -> Estimate:
    """``run(sweep, calibration, *args, **kwargs)`` on ``sweep`` started where a full turn
    breaks (:func:`~irring.estimation.seam.turn_start`), its estimate put back in
    ``sweep``'s rows; ``run`` itself on any other sweep."""
    cal = calibration if calibration is not None else nominal_calibration(
        sweep.sensor_model, sweep.ring, sweep.adc_bits, sweep.vref_v)
    rows = turn_start(sweep, cal)
    if rows is None:
        return run(sweep, calibration, *args, **kwargs)
    return in_sweep_rows(run(started_at(sweep, rows), calibration, *args, **kwargs), rows)


def _estimate(sweep: Sweep, calibration: Calibration | None, max_iterations: int,
              tolerance_rad: float, iterate: bool, lines: LineOptions, *, keep_history: bool,
              damping: bool, detail: bool, hold: np.ndarray | None = None,
              snap: bool = True, keep_unconverged: bool = False) -> Estimate:
    """The estimator: this function is the schedule of docs/estimator.md, its phases run
    as compiled kernels (:mod:`irring.estimation._iterate`). ``detail``: also the final lines.
    ``hold`` (S, N): readings kept out (FOLDOVER_AMBIGUOUS); None with a folding
    calibration: resolve the fold-over first (:func:`resolve_foldover`). ``snap``: line
    members' end points onto their lines (:func:`snap_to_lines`)."""
    check_work(np.shape(sweep.counts))
    cal = calibration if calibration is not None else nominal_calibration(
        sweep.sensor_model, sweep.ring, sweep.adc_bits, sweep.vref_v)
    if hold is None and cal.folds and iterate:
        return resolve_foldover(lambda held, full, snap: _estimate(
            sweep, cal, max_iterations, tolerance_rad, iterate, lines, keep_history=keep_history,
            damping=damping, detail=full, hold=held, snap=snap,
            keep_unconverged=keep_unconverged), sweep, cal, detail, options=lines)
    # the kernels take a C integer: a float would fail only once an iteration needs it
    max_iterations = operator.index(max_iterations)
    if max_iterations < 1:
        raise ValueError(f"max_iterations must be ≥ 1, got {max_iterations}")
    if not (math.isfinite(tolerance_rad) and tolerance_rad > 0):
        raise ValueError(f"tolerance_rad must be a finite angle > 0, got {tolerance_rad}")
    counts = np.ascontiguousarray(sweep.counts, dtype=float)
    if counts.ndim != 2:
        raise ValueError(f"sweep.counts must be (steps, sensors), got shape {counts.shape}")
    steps = np.asarray(sweep.steps)
    if steps.shape != counts.shape[:1]:
        # the scan order indexes the readings by step: more steps than rows would read and
        # write past the arrays, fewer would leave readings unestimated but marked OK
        raise ValueError(f"sweep.steps must have one entry per row of sweep.counts "
                         f"{counts.shape}, got shape {steps.shape}")
    angles = np.asarray(sweep.sensor_angles, dtype=float)
    pose = sweep.reading_poses if sweep.reading_poses is not None else sweep.pose
    origin, heading, cos_h, sin_h = beam_geometry(
        sweep.ring, np.asarray(pose, dtype=float), angles, cal.emitter_offset_m, trig=True)
    if origin.shape != counts.shape + (2,):
        origin = np.broadcast_to(origin, counts.shape + (2,))
    if heading.shape != counts.shape:
        heading, cos_h, sin_h = (np.broadcast_to(v, counts.shape)
                                 for v in (heading, cos_h, sin_h))
    shape = counts.shape

    max_range = min(float(sweep.max_range_m), cal.max_range_m)
    counts, reason = held_and_pooled(counts, classify(counts, sweep, cal), hold, steps, cal,
                                     max_range)
    sw = _iterate.Sweep(cal, lines, counts.reshape(-1), np.ascontiguousarray(origin).reshape(-1),
                        np.ascontiguousarray(heading).reshape(-1), reason.reshape(-1),
                        scan_order(steps, shape[1]), shape[1],
                        SIGMA_FLOOR_M, PINNED_RAD, np.ascontiguousarray(cos_h).reshape(-1),
                        np.ascontiguousarray(sin_h).reshape(-1))
    k = sw.k
    scan_heading = np.ascontiguousarray(heading).reshape(-1).take(sw.index)
    tan_reject = jump_slope(sw.reject)
    theta = np.zeros(k)
    last_moving = np.full(k, -1, dtype=np.intp)  # last iteration in which each θ moved
    on_line = np.zeros(k, dtype=np.uint8)        # took θ from a line in the last plain step
    history = [np.zeros(shape)] if keep_history else []
    grouping: _iterate.Grouping | None = None
    held: _iterate.Held | None = None
    regroups = 0
    regroup_changed = True
    older = None          # the labels two groupings ago
    passes = []           # (iteration, θ, last_moving) at each membership pass
    mode = "regroup"
    it = 0
    settled = False
    limit = max_iterations if iterate and k else 0
    while it < limit:
        checked = False
        if mode != "inner":
            # a membership pass: regroup (split-and-merge anew), or check the members
            checked = True
            if held is not None:
                held.put_theta(theta)
                passes.append((it, theta.copy(), last_moving.copy()))
            # readings far outside the range cannot help a line (but stay for the final check)
            uidx = sw.place(theta, 1.5 * max_range)
            if mode == "regroup":
                chains = _lines.polyline_ids(sw.d, sw.sigma, scan_heading, sw.sensor,
                                             tan_reject, lines.jump_sigmas)
                parts = (sw.px, sw.py, sw.thr, chains)
                if uidx is not None:
                    parts = tuple(v.take(uidx) for v in parts)
                before = None if grouping is None else grouping.label
                # the last grouping's pieces are refined where they are of the same
                # polylines; once θ moved readings across the usable range they are of
                # other points, and the segmentation splits afresh by itself
                pieces = segment(*parts, lines, sw.centre,
                                  None if grouping is None else grouping.pieces)
                grouping = _iterate.Grouping(sw, pieces, uidx)
                changed = grouping.regroup(before)
                corners_checked = False    # the grouping's first check re-decides corners
                regroups += 1
                # regroup again only while that changes who belongs where, and not back to
                # the grouping before (readings at a corner flipping between two lines)
                regroup_changed = changed and not (
                    older is not None and _iterate.same(older, grouping.label))
                older = before
            else:  # the same members, refitted where they now are, checked again
                changed = grouping.check(not corners_checked or it < CORNER_WINDOW)
                corners_checked = True
                if not changed and settled:
                    break      # the members stand and their lines did not move: done
            mode = "inner"
            if changed or held is None:  # a plain step from the new grouping
                moving = grouping.plain_step(theta, last_moving, on_line, it, tolerance_rad)
                it += 1
                if keep_history:
                    history.append(sw.scatter_theta(theta).reshape(shape))
                if not moving:
                    break
                held = _iterate.Held(sw, grouping, theta, damping, MAX_GAIN)
                continue
            # unchanged: this iteration is an ordinary held step
        # held iterations until they settle, a regroup or a membership check is due
        if not (regroup_changed and regroups < lines.regroup_iterations):
            regroup_before = -1
        else:  # a third or later grouping only early on
            regroup_before = limit + 1 if regroups == 1 else REGROUP_WINDOW
        status, it, last_settled, was_checked = held.run(
            it, limit, tolerance_rad, checked, last_moving, regroup_before,
            lines.regroup_until_rad, one_step=keep_history)  # a history records every step
        if last_settled is not None:
            settled = last_settled
        if status == _iterate.CHECK:
            mode = "member"      # some member left its line: redo this iteration as a check
            continue
        if keep_history:
            history.append(sw.scatter_theta(theta, held).reshape(shape))
        if status == _iterate.SETTLED:
            if regroups == 1 and regroups < lines.regroup_iterations:
                mode = "regroup"   # settled once: split-and-merge the straightened points again
            elif was_checked:
                break
            else:
                mode = "member"    # settled: a last look at who belongs where
        elif status == _iterate.REGROUP:
            mode = "regroup"       # θ has settled coarsely: group the straightened points again
    n_its = it
    if held is not None:
        held.put_theta(theta)
    if not keep_unconverged:
        settled_within_noise(passes, theta, last_moving, n_its, cal, sw.log_s)

    # final points with the exact curve; fallback readings (no line): θ = 0, σ widened by
    # θ's unknown (see _fallback_nodes)
    x, y, d, theta_out, sigma, it_out, valid = sw.finish(
        theta, on_line, last_moving, n_its, iterate, cal, max_range, reason.reshape(-1),
        keep_unconverged, RANGE_SIGMAS)
    points = Points(
        x=x.reshape(shape), y=y.reshape(shape), d=d.reshape(shape),
        theta=theta_out.reshape(shape),
        origin_x=np.array(origin[..., 0]), origin_y=np.array(origin[..., 1]),
        heading=np.array(heading), sigma_m=sigma.reshape(shape),
        iterations=it_out.reshape(shape), valid=valid.reshape(shape), reason=reason,
        max_range_m=max_range)
    return final_estimate(points, grouping, on_line, sw.index, cal, lines, snap, detail, history,
                          counts, steps, raw_counts=np.asarray(sweep.counts, dtype=float))


def check_work(shape: tuple) -> None:
    """:class:`TooBig` for a sweep of ``shape`` (steps, sensors) with more readings than
    the estimator may take (:data:`irring.core.MAX_ESTIMATED_READINGS`: one sweep's
    :func:`irring.core.work_bytes` within the work budget), before any of its work."""
    if len(shape) != 2 or shape[0] * shape[1] <= MAX_ESTIMATED_READINGS:
        return        # (within the budget; a shape no sweep has is the estimator's to name)
    n = int(shape[0]) * int(shape[1])
    refusal = work_refusal(
        f"a sweep of {shape[0]:,} steps × {shape[1]} sensors = {n:,} readings to estimate",
        work_bytes(n, n), "the estimator",
        f"estimate at most {MAX_ESTIMATED_READINGS:,} readings a sweep (fewer steps, or the "
        f"sweep in parts)")
    if refusal:
        raise TooBig(refusal)


SETTLED_SIGMAS = 1.0  # a reading caught moving reads within this many σ of its converged d


def settled_within_noise(passes: list, theta: np.ndarray, last_moving: np.ndarray, n_its: int,
                         cal: Calibration, log_s: np.ndarray) -> None:
    """Readings still moving at the cap (``last_moving`` = ``n_its`` − 1) that met Table II's
    test (no move in the iteration before) at a membership pass and whose distance at the cap
    lies within ``SETTLED_SIGMAS`` of their noise σ of the distance they had there are
    marked converged in ``last_moving`` (in place): a regroup or check set them moving again,
    and what they report has not moved beyond their noise. ``passes``: (iteration, θ,
    last_moving) at each pass; θ, ``log_s`` (log counts): per live reading. Why:
    docs/estimator.md, "Caught by the cap"."""
    late = last_moving == n_its - 1 if n_its else None
    if late is None or not late.any():
        return
    for it, theta_then, moving_then in reversed(passes):   # the latest still state judges
        i = (late & (moving_then < it - 1)).nonzero()[0]
        if not i.size:
            continue
        late[i] = False
        log_a, b = cal.log_ab(theta.take(i))
        d = np.exp(log_a + b * log_s.take(i))
        log_a, b_then = cal.log_ab(theta_then.take(i))
        d_then = np.exp(log_a + b_then * log_s.take(i))
        sigma = np.maximum(np.abs(b) * d * cal.sigma_counts() * np.exp(-log_s.take(i)),
                           SIGMA_FLOOR_M)
        last_moving[i[np.abs(d - d_then) <= SETTLED_SIGMAS * sigma]] = n_its - 2


def final_estimate(points: Points, grouping, on_line, index: np.ndarray, cal: Calibration,
                   options: LineOptions, snap: bool, detail: bool, history: list,
                   counts: np.ndarray, steps: np.ndarray, reach: Callable | None = None,
                   snapper: Callable | None = None, profiler: Callable | None = None,
                   voter: Callable | None = None, shorter: Callable | None = None,
                   post_grouper: Callable | None = None,
                   gapper: Callable | None = None, raw_counts: np.ndarray | None = None,
                   beside: Callable | None = None, tracer: type[TraceSteps] | None = None,
                   judge: Callable | None = None, bower: Callable | None = None,
                   fitter: type[CountsFits] | None = None,
                   past_finder: Callable | None = None,
                   faceter: Callable | None = None,
                   rounder: Callable | None = None,
                   bender: Callable | None = None,
                   edger: Callable | None = None) -> Estimate:
    """The estimate from the final points and grouping (either estimator's), in this order:
    a line's few members a silent gap contradicts moved to the line of their side of it
    (:func:`across_silence`),
    readings on no line at the incidence their own sensor's neighbours give
    (:func:`local_incidence`; ``counts`` (S, N), ``steps`` (S,): the sweep's), round things'
    arcs (:func:`round_runs`); with ``snap`` only (not a fold-over's judging pass): short far
    lines doubted (:func:`doubt_far_lines`), members that a better-held line their sensor's
    trace continues on places moved to it (:func:`rejoin_traces`), then the members of a
    line their counts contradict (as rejoined) off it (:func:`counts_disown_lines`),
    members alone at a nearer surface's edge (:func:`alone_at_an_edge`), a curved wall's
    chords read on its circle (:func:`bowed_lines`), a far line over a corner read as two
    (:func:`kinked_lines`), members whose beams meet another wall first read on it
    (:func:`past_other_lines`) and a line's members past a wall's shallow bend read on the
    turned wall (:func:`bent_ends`); line members onto their lines
    (``snapper``, the compiled :func:`snap_to_lines` by default), a line over a many-sided
    wall's facets read as two pieces (:func:`faceted_lines`), members read just past
    the max range kept only where their line put them within it (:func:`drop_beyond_range`),
    (``snap`` only) far posts' circles and readings unplaced alone, INCIDENCE_UNKNOWN readings
    no θ moves (an ideal sensor's) at θ = 0 (:func:`unknown_theta_free`; last of all,
    any of them placed past its noise back at θ = 0: :func:`theta_free_in_noise`),
    each silent beam's reach (``reach``, the compiled :func:`no_return_reach` by default; the
    oracle passes its numpy statements of both; never past ``cal.silent_range_m``:
    :func:`silent_reach`), last (``snap`` only) dim returns beside a line's members put on it
    (:func:`dim_returns_on_lines`), then far returns left unplaced on a line their beam
    crosses (:func:`onto_crossed_lines`) and, with ``detail``, the :class:`Lines`. Line members are
    first moved out by what the return level cut off their lines (:func:`censored_lines`).
    ``profiler``: the readings' range profiles (the compiled :func:`profiles_compiled` by
    default; the oracle passes its numpy statement :func:`range_profiles`); ``voter`` and
    ``post_grouper``: the short far lines' vote and the far posts' groups (compiled by
    default; the oracle passes its numpy ``far_line_vote`` and ``post_groups``);
    ``shorter``: the short far lines (:func:`short_far_lines_compiled`; the oracle:
    :func:`short_far_lines`);
    ``gapper``: the silent gaps (:func:`silent_gaps_compiled`; the oracle: :func:`silent_gaps`);
    ``beside``: the silent beams beside a return (:func:`beside_a_return_compiled`; the
    oracle: :func:`beside_a_return`); ``tracer``: :func:`rejoin_traces`' steps
    (:class:`TraceKernels`; the oracle: :class:`TraceSteps`); ``judge``: the lines their
    counts contradict (:func:`counts_contradicted_compiled`; the oracle:
    :func:`counts_contradicted`); ``bower``: a curved wall's chords
    (:func:`bowed_lines_compiled`; the oracle: :func:`bowed_lines`); ``fitter``: lines fitted
    to their members' counts (:class:`CountsFitKernels`; the oracle: :class:`CountsFits`);
    ``past_finder``: the members :func:`past_other_lines` asks
    (:func:`past_members_compiled`; the oracle: :func:`past_members`);
    ``faceter``: a line over facets as two pieces (:func:`faceted_lines_compiled`; the
    oracle: :func:`faceted_lines`); ``rounder``: round things' arcs
    (:func:`round_runs_compiled`; the oracle: :func:`round_runs`); ``bender``: a line's
    members past a shallow bend (:func:`bent_ends_compiled`; the oracle: :func:`bent_ends`);
    ``edger``: members alone at a nearer surface's edge (:func:`alone_at_an_edge_compiled`;
    the oracle: :func:`alone_at_an_edge`).
    ``raw_counts`` (S, N): the sweep's counts before pooling (None: ``counts``), which tell a
    pooled reading's own level (:func:`noise_past_line_end`)."""
    shape = points.valid.shape
    beside = beside or beside_a_return_compiled
    if grouping is None:       # nothing to group (e.g. every reading invalid): no lines
        empty = lines_record(None, np.full(shape, -1, dtype=np.intp), np.zeros(0, np.intp))
        return Estimate(points=silent_reach(beside(drop_beyond_range(points), counts, cal,
                                                   options), cal),
                        lines=empty if detail else None, theta_history=tuple(history))
    label = np.full(shape, -1, dtype=np.intp)  # the line each reading took θ from (−1: none)
    label.reshape(-1)[index] = np.where(on_line, grouping.label, -1)
    points, label = across_silence(points, label, index, counts, steps, cal, grouping.alpha,
                                   grouping.cx, grouping.cy, gapper)
    # short far lines are doubted in the final pass (a fold-over's judging pass keeps its
    # lines whole: they decide the branches; docs/foldover.md, "Short far lines"), judged as
    # fitted, but after round_runs: a column's arc cut into short far lines is a circle's
    # first (doubted first, its members made INCIDENCE_UNKNOWN cut the column's runs)
    short = (shorter or short_far_lines_compiled)(points, label, index, cal) if snap else None
    # one profile call for local_incidence, round_runs and the doubt while no reading leaves
    profiler = SharedProfiles(profiler or profiles_compiled,
                               None if short is None else short[0] | short[1])
    arcs: list = []
    points, label = local_incidence(points, label, index, counts, steps, cal, profiler, arcs)
    before = points
    left = points.reason.copy()   # (onto_crossed_lines asks only what no later rule unplaced)
    points, label = (rounder or round_runs_compiled)(
        points, label, index, counts, steps, cal, grouping.alpha, grouping.cx, grouping.cy,
        profiler, snap, far_sigma_cap(cal, points.max_range_m))
    rounded = (np.flatnonzero(points.valid & ((points.d != before.d)
                                              | (points.theta != before.theta)))
               if points is not before else np.zeros(0, dtype=np.intp))
    if arcs and rounded.size:    # (the readings round_runs put on its circles stay)
        arcs.append((rounded, np.zeros((3, 0))))
    # a post's circle, fitted where a sensor saw its arc, read by the flanks others saw
    shared = points
    points, label = onto_post_circles(points, label, index, counts, steps, cal, arcs)
    if points is not shared:
        rounded = np.union1d(rounded, np.flatnonzero(
            points.valid & ((points.d != shared.d) | (points.theta != shared.theta))))
    # a round thing no sensor's own run holds the apex of: one circle across the sensors
    points, label = columns_across_sensors(
        points, label, index, counts, steps, cal, grouping.alpha, grouping.cx, grouping.cy,
        np.concatenate([a for a, _ in arcs] + [rounded]))
    if short is not None:
        points, label = doubt_far_lines(points, label, index, counts, steps, cal, *short,
                                        profiler, voter)
    if snap:   # (a fold-over's judging pass keeps its lines as fitted: they decide branches;
        # after round_runs: a round thing's arc cut into lines is its circle's first)
        points, label = rejoin_traces(points, label, index, counts, steps, cal,
                                      grouping.alpha, grouping.cx, grouping.cy,
                                      grouping.usable, options, tracer or TraceKernels)
        # a line's few readings at its trace's end that a silence contradicts, with no other
        # line beside them (after the traces: those they carry to their own wall stay)
        points, label = across_silence(points, label, index, counts, steps, cal,
                                       grouping.alpha, grouping.cx, grouping.cy, gapper,
                                       alone=True, moves=False)
        points, label = counts_disown_lines(points, label, index, counts, steps, cal,
                                            grouping.alpha, grouping.cx, grouping.cy, profiler,
                                            judge, fitter)
        points, label = (edger or alone_at_an_edge_compiled)(points, label, counts, steps,
                                                             cal)
        # a curved wall's chords on its circle (the lines as the rules above left them)
        points, label = (bower or bowed_lines_compiled)(points, label, counts, cal)
        # a line over a corner as two pieces (the snap's label; the grouping keeps its lines)
        points, split = kinked_lines(points, label, counts, cal)
        # members whose beam meets another wall first: read on that wall
        points, split = past_other_lines(points, split, counts, cal, options, past_finder)
        # a wall's shallow bend: a line's members past its end read on the turned wall
        points, bent = (bender or bent_ends_compiled)(points, split, counts, steps, cal)
        label = np.where((bent < 0) & (split >= 0), -1, label)
        split = bent
    else:
        split = label
    points = censored_lines(points, split, counts, steps, cal)
    snap_label = None
    if snap:
        # a part read to its own range: the overlapping lines of one wall fitted as one
        snap_label = (fused_lines(points, split) if read_to_own_range(cal, points.max_range_m)
                      else split)
        snapped = (snapper or snap_to_lines)(points, snap_label, cal.min_range_m,
                                             far_sigma_cap(cal, points.max_range_m),
                                             snap_members(steps))
        # a line over a many-sided wall's facets: its members on two pieces
        points = (faceter or faceted_lines_compiled)(points, snap_label, snapped, cal)
    points = drop_beyond_range(points)
    if snap:
        # a thin post far away: its few readings, several sensors', fitted as one circle
        points = far_posts(points, label, counts, steps, cal, post_grouper)
        points = unplaced_alone(points, split)
    # whichever rule left a reading's incidence unknown, one no θ moves is placed (the ideal
    # sensor's: no θ dependence)
    points = unknown_theta_free(points, counts, cal)
    pooled = (points.valid & (counts < cal.no_return_counts + cal.return_margin_counts)
              if read_to_own_range(cal, points.max_range_m) else None)
    silent = bool(np.count_nonzero(points.reason == _NO_RETURN))
    own = counts if raw_counts is None else raw_counts   # (each reading's own, not pooled)
    def record() -> Lines:
        pieces_out = replace(grouping.pieces, cx=grouping.cx, cy=grouping.cy,
                             alpha=grouping.alpha, usable=grouping.usable)
        used = index if grouping.uidx is None else index.take(grouping.uidx)
        return lines_record(pieces_out, label, used)

    # dim returns beside a line's members put on it once every rule above has decided
    # (snap_label None: a fold-over's judging pass keeps its lines as fitted)
    if not (detail or silent or (pooled is not None and pooled.any())):
        points = dim_returns_on_lines(points, snap_label, counts, raw_counts, steps, cal)
        points = theta_free_in_noise(points, own, cal)
        if snap and unplaced_returns(points, own, cal, left).any():
            # last: unplaced far returns on a line their beam crosses
            points = onto_crossed_lines(points, record(), own, cal, left, steps)
        return Estimate(points=points, lines=None, theta_history=tuple(history))
    found = record()
    if pooled is not None and pooled.any():
        points = noise_past_line_end(points, found,
                                     counts if raw_counts is None else raw_counts, cal)
        points = silent_behind_a_wall(points, pooled & points.valid, found, cal, options)
        silent = bool(np.count_nonzero(points.reason == _NO_RETURN))
    if silent:
        reach_m = (reach or no_return_reach)(points, found, cal, options)
        if points.reach_m is not None:
            # the lines' reach past a line's members runs up to the line itself: a beam
            # silent_behind_a_wall silenced keeps its clearance before the wall it met
            reach_m = points.reach_m if reach_m is None else np.fmin(points.reach_m, reach_m)
        points = silent_reach(beside(points_with(points, reach_m=reach_m), counts, cal,
                                     options, found.label), cal)
    points = dim_returns_on_lines(points, snap_label, counts, raw_counts, steps, cal)
    # last: whatever a rule above did, a reading no θ moves stays within its noise
    points = theta_free_in_noise(points, own, cal)
    if snap:   # then unplaced far returns on a line their beam crosses
        points = onto_crossed_lines(points, found, own, cal, left, steps)
    return Estimate(points=points, lines=found if detail else None,
                    theta_history=tuple(history))


@functools.lru_cache(maxsize=16)
def nominal_calibration(sensor_model: str, ring: Ring | None, adc_bits: int, vref_v: float
                        ) -> Calibration:
    """:meth:`Calibration.for_sweep`'s calibration, built once per sensor/ring/ADC: its fine θ
    table (built on its first sweep) takes longer than estimating a sweep, and ``irring run``
    without a calibration file estimates every sweep with the default."""
    return Calibration.nominal(sensor_model, ring, adc_bits, vref_v)
