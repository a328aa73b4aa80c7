"""The paper's iterative range estimator (Park, Baek & Lee 2005, Table II): ADC counts and a
:class:`~irring.estimation.calibration.Calibration` in, end points out.

How it works, its assumptions and measured figures: docs/estimator.md.
"""

from __future__ import annotations

import functools
import math
import operator
from statistics import NormalDist
from dataclasses import dataclass, field, replace
from types import SimpleNamespace
from typing import Callable

import numpy as np

from ..core import (HOUSING_M, UNCERTAIN_SIGMA_M, Points, Reason, Ring, Sweep, beam_geometry,
                    points_with, reading_stride, rows_in_step_order)
from ..resources import kernel
# Calibration is the estimator's input; calibration files written before 2026-11-26 name
# it here (irring.estimation.estimate.Calibration.load), so this module exports it too
from .calibration import (RANGE_SIGMAS, RETURN_SIGMAS, SIGMA_FLOOR_M, Calibration,
                          fallback_thetas, range_sigma)
from .bounds import clamped_slopes, kept_where_bounded

_iterate = kernel("estimation._iterate")
_lines = kernel("estimation._lines")
# plain ints: an array compared with an IntEnum member takes numpy's slow path (~7 µs)
_NO_RETURN, _OUT_OF_RANGE = int(Reason.NO_RETURN), int(Reason.OUT_OF_RANGE)
_INCIDENCE_UNKNOWN, _MISSING = int(Reason.INCIDENCE_UNKNOWN), int(Reason.MISSING)

REGROUP_WINDOW = 8  # a third or later grouping only within the first 8 iterations
CORNER_WINDOW = 14  # corners re-decided at a grouping's first check, later ones only before
#                     this iteration (a late move left its lines too few iterations to settle)
MAX_GAIN = 8.0      # the held iteration's secant step at most 8× the plain one
PINNED_RAD = math.radians(2.0)  # a line most readings meet within this of the drop-out angle
#                                  is a runaway, not a wall (see _drop_steep)


# --------------------------------------------------------------------------- line grouping


@dataclass(frozen=True)
class LineOptions:
    """How end points are grouped into lines (step 4 of Table II)."""

    split_sigmas: float = 4.0      # split where a point lies this many σ off the chord …
    min_split_m: float = 0.010     # … and at least this far
    gap_m: float = 0.15            # consecutive readings farther apart start a new polyline …
    jump_sigmas: float = 3.5       # … as do a sensor's readings whose ranges jump (polyline_ids)
    min_points: int = 3            # a line usable for θ has at least this many readings …
    min_length_m: float = 0.08     # … spanning at least this length
    max_rms_sigmas: float = 3.0    # … and fits them to within this RMS (in σ)
    regroup_iterations: int = 3    # group the readings into lines at most this often …
    regroup_until_rad: float = math.radians(1.0)  # … again once θ has settled to this
    adopt_margin_m: float = 0.05   # a reading on no line may join one this far past its ends
    corner_window: int = 4         # readings this close to a corner may change line …
    corner_sigmas: float = 0.5     # … if another line fits them this many σ better
    corner_reach_m: float = 0.25   # lines meeting within this of both's readings: a corner …
    corner_reach_share: float = 0.3  # … or this share of its distance from the ring if more
    #                                  (a far corner's drop-out gap is wider);
    corner_past_m: float = 0.02    # readings closer to it need more evidence to move across
    incidence_margin_rad: float = math.radians(5.0)  # a line meeting a beam this far past
    #                                                  the drop-out angle is not its surface


@dataclass(frozen=True)
class Lines:
    """Lines found in a sweep. ``label`` (S, N): line index of each reading or −1."""

    label: np.ndarray
    centroid: np.ndarray     # (L, 2) m, world
    normal: np.ndarray       # (L, 2) unit
    direction: np.ndarray    # (L, 2) unit, along the line
    n_points: np.ndarray     # (L,)
    length_m: np.ndarray     # (L,) extent of the readings along the line
    rms_m: np.ndarray        # (L,) RMS perpendicular residual
    usable: np.ndarray       # (L,) bool: good enough to give θ
    start: np.ndarray        # (L,) first/last index into the flat sensor-major scan order
    end: np.ndarray


def scan_order(steps: np.ndarray, n_sensors: int) -> np.ndarray:
    """Flat indices into (S, N) arrays, sensor-major, each sensor's readings by step."""
    order = rows_in_step_order(steps)
    return (order[None, :] * n_sensors + np.arange(n_sensors)[:, None]).reshape(-1)


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


@dataclass
class Pieces:
    """The split-and-merge result over the usable points (indices into their compact order)
    and each piece's TLS line; ``owner`` (U,) is the piece each point joins."""

    starts: np.ndarray
    ends: np.ndarray
    brk: np.ndarray          # polyline starts the segmentation began from (for reuse)
    owner: np.ndarray
    cx: np.ndarray           # (L,) centroid, world
    cy: np.ndarray
    alpha: np.ndarray        # (L,) direction angle in [0, π)
    lmin: np.ndarray
    lmax: np.ndarray
    n_points: np.ndarray
    length_m: np.ndarray
    usable: np.ndarray


def _segment(px, py, thr, sensor, opts: LineOptions, centre, prev: Pieces | None = None
             ) -> Pieces:
    """Split-and-merge over ordered points (one sensor's readings by step form polylines,
    broken where consecutive readings are more than ``gap_m`` apart), corners refined, and
    each piece's TLS line: one call of the compiled kernel ``irring.estimation._lines.segment``.

    - split: iterative end-point fit (Douglas–Peucker) of every polyline: a piece splits at
      the reading farthest from its chord while that lies more than its threshold ``thr``
      off; the two pieces share that reading (their corner);
    - merge: adjacent pieces whose joint TLS line fits every reading within its threshold
      join, cheapest first, non-overlapping joins per round;
    - corners: each shared corner moves by up to 5 readings to where the two pieces' TLS
      lines fit best (2 rounds);
    - lines: each piece's TLS line from prefix sums of the moments centred on ``centre``;
      a corner reading joins the nearer of its two lines; a line is usable with
      ≥ ``min_points`` readings spanning ≥ ``min_length_m`` that it fits to within
      ``max_rms_sigmas`` of their mean σ.

    With ``prev`` from the same polylines (a regroup once θ has straightened the points)
    its pieces are kept and only their corners are refined: splitting anew would mostly
    repeat them, and the pieces of the first grouping are the better start (measured on the
    T-room: regrouping by corner refinement alone gives the smaller range error). Where a
    range jump now cuts some polylines (``polyline_ids``), only those are split anew; the others
    keep ``prev``'s pieces.

    The kernel gives the numpy version's answers bit for bit (irring/estimation/_lines.pyx says how)
    in a fraction of its time (measured: docs/estimator.md, "Speed")."""
    f = np.ascontiguousarray
    return Pieces(*_lines.segment(
        f(px, dtype=float), f(py, dtype=float), f(thr, dtype=float), f(sensor, dtype=np.intp),
        opts.gap_m ** 2, float(centre[0]), float(centre[1]),
        *((None, None, None) if prev is None else (prev.starts, prev.ends, prev.brk)),
        opts.split_sigmas, opts.min_points, opts.min_length_m, opts.max_rms_sigmas))


def jump_slope(reject_rad: float) -> float:
    """tan of the steepest incidence :func:`polyline_ids` lets a surface have: ``reject_rad``,
    at most 1.5 rad (tan 14; towards 90° it grows without bound and no jump would cut).
    The compiled ``_lines.polyline_ids`` and ``profile_inputs`` take it (``tan_reject``)."""
    return math.tan(min(reject_rad, 1.5))


def polyline_ids(d: np.ndarray, sigma: np.ndarray, heading: np.ndarray, sensor: np.ndarray,
                 reject_rad: float, sigmas: float) -> np.ndarray:
    """Polyline ids of readings in scan order: a new one at a sensor change or at a *range
    jump*, where consecutive readings of a sensor differ in range by more than one surface
    could make them (readings on one plane at incidence θ change range by d·tanθ per
    radian the beam turns; θ up to ``reject_rad``), plus ``sigmas`` times their noise.

    Such a jump is an occlusion edge (a box's corner in front of the wall behind it) or
    a convex corner seen across at the current θ (the faces' θ differ). Joined into one
    polyline (consecutive end points were within the 0.15 m gap), the wall's readings past
    a counter's corner were fitted with the counter's face: θ ~20° off, end points up to
    110 mm off with σ 7–16 mm (tests/test_estimate.py has that galley).

    numpy, the statement the kernel ``_lines.polyline_ids`` (which the estimator calls) is
    held to bit for bit (tests/test_estimate_oracle.py)."""
    k = d.size
    cut = np.ones(k, dtype=bool)
    if k > 1:
        turn = np.abs(heading[1:] - heading[:-1])
        turn = np.minimum(turn, 2.0 * math.pi - turn)
        allowed = np.maximum(d[1:], d[:-1]) * turn * jump_slope(reject_rad)
        allowed += sigmas * np.hypot(sigma[1:], sigma[:-1])
        np.greater(np.abs(d[1:] - d[:-1]), allowed, out=cut[1:])
        cut[1:] |= sensor[1:] != sensor[:-1]
    return np.cumsum(cut)


def _lines_record(pieces: Pieces | None, label: np.ndarray, index: np.ndarray) -> Lines:
    """Public :class:`Lines` from pieces; ``index`` maps compact point order → flat (S, N)."""
    if pieces is None or pieces.starts.size == 0:
        z2, z1 = np.zeros((0, 2)), np.zeros(0)
        return Lines(label=label, centroid=z2, normal=z2, direction=z2,
                     n_points=np.zeros(0, int), length_m=z1, rms_m=z1,
                     usable=np.zeros(0, bool), start=np.zeros(0, int), end=np.zeros(0, int))
    a = pieces.alpha
    centroid, direction, normal = np.empty((3, a.size, 2))   # (one block: np.stack thrice
    centroid[:, 0], centroid[:, 1] = pieces.cx, pieces.cy    # cost more than the lines)
    direction[:, 0], direction[:, 1] = np.cos(a), np.sin(a)
    normal[:, 0], normal[:, 1] = -direction[:, 1], direction[:, 0]
    return Lines(label=label, centroid=centroid, normal=normal,
                 direction=direction, n_points=pieces.n_points, length_m=pieces.length_m,
                 rms_m=np.sqrt(pieces.lmin), usable=pieces.usable.copy(),
                 start=index[pieces.starts], end=index[pieces.ends])


def fit_lines(x: np.ndarray, y: np.ndarray, ok: np.ndarray, sigma_m: np.ndarray,
              steps: np.ndarray | None = None, options: LineOptions = LineOptions()) -> Lines:
    """Group the end points of a sweep into lines (split-and-merge, see :func:`_segment`).

    ``x``, ``y``, ``ok``, ``sigma_m`` are (S, N); readings with ``ok`` False, a non-finite
    end point or σ = +inf (accuracy unknown: anywhere on its beam) are skipped; a NaN σ (none
    given) splits at ``min_split_m``.
    Each sensor's readings, ordered by ``steps``, form polylines (broken where consecutive
    readings are more than ``gap_m`` apart); each polyline is split at the reading farthest
    from its chord while that exceeds max(min_split_m, split_sigmas·σ) (all polylines at
    once per round), then adjacent pieces whose joint TLS line still fits every reading within
    that threshold are merged. A corner reading shared by two pieces joins the line it is
    nearer to.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    shape = x.shape
    n_steps, n_sensors = shape
    if steps is None:
        steps = np.arange(n_steps)
    flat = scan_order(steps, n_sensors)
    sigma = np.broadcast_to(np.asarray(sigma_m, float), shape).reshape(-1)
    okf = np.asarray(ok, dtype=bool).reshape(-1)[flat]
    okf &= (np.isfinite(x.reshape(-1)[flat]) & np.isfinite(y.reshape(-1)[flat])
            & (sigma[flat] != np.inf))
    idx = flat[okf]
    label = np.full(n_steps * n_sensors, -1, dtype=int)
    if idx.size == 0:
        return _lines_record(None, label.reshape(shape), idx)
    px, py = x.reshape(-1)[idx], y.reshape(-1)[idx]
    thr = np.maximum(options.min_split_m,
                     options.split_sigmas * np.nan_to_num(sigma[idx], nan=0.0))
    pieces = _segment(px, py, thr, idx % n_sensors, options, (float(px.mean()), float(py.mean())))
    label[idx] = pieces.owner
    return _lines_record(pieces, label.reshape(shape), idx)


# --------------------------------------------------------------------------- estimation


@dataclass(frozen=True)
class Estimate:
    """Points plus what the estimator saw (for plots, tests and benchmarks)."""

    points: Points
    lines: Lines | None
    theta_history: tuple[np.ndarray, ...] = field(default=())


def _classify(counts: np.ndarray, sweep: Sweep, cal: Calibration) -> np.ndarray:
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
    with np.errstate(divide="ignore", invalid="ignore"):
        d0 = cal.distance(so, 0.0)
    top = so >= cal.full_scale_counts - 0.5
    ok = np.zeros(so.shape, dtype=bool)
    ok[1:] |= (np.abs(d0[1:] - d0[:-1]) <= NEAR_AGREE_M) | top[:-1]
    ok[:-1] |= (np.abs(d0[:-1] - d0[1:]) <= NEAR_AGREE_M) | top[1:]
    confirmed = np.empty_like(ok)
    confirmed[order] = ok
    return ask & ~confirmed


def estimate(sweep: Sweep, calibration: Calibration | None = None, *, max_iterations: int = 20,
             tolerance_rad: float = math.radians(0.1), iterate: bool = True,
             lines: LineOptions = LineOptions(), keep_unconverged: bool = False) -> Points:
    """Counts → end points by the iterative estimation of Table II (see docs/estimator.md).

    ``calibration`` defaults to :meth:`Calibration.for_sweep` (the datasheet curve).
    ``iterate=False`` gives the θ = 0 assumption (Eq. 10 with a(0), b(0)).
    ``keep_unconverged``: readings still moving after ``max_iterations`` are valid at the θ
    they reached (the estimate after k iterations) instead of NOT_CONVERGED.
    """
    return _estimate(sweep, calibration, max_iterations, tolerance_rad, iterate, lines,
                     keep_history=False, damping=True, detail=False,
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
    return _estimate(sweep, calibration, max_iterations, tolerance_rad, iterate, lines,
                     keep_history=keep_history, damping=damping, detail=True,
                     keep_unconverged=keep_unconverged)


def _estimate(sweep: Sweep, calibration: Calibration | None, max_iterations: int,
              tolerance_rad: float, iterate: bool, lines: LineOptions, *, keep_history: bool,
              damping: bool, detail: bool, hold: np.ndarray | None = None,
              snap: bool = True, keep_unconverged: bool = False) -> Estimate:
    """The estimator: this function is the schedule of docs/estimator.md, its phases run
    as compiled kernels (:mod:`irring.estimation._iterate`). ``detail``: also the final lines.
    ``hold`` (S, N): readings kept out (FOLDOVER_AMBIGUOUS); None with a folding
    calibration: resolve the fold-over first (:func:`resolve_foldover`). ``snap``: line
    members' end points onto their lines (:func:`snap_to_lines`)."""
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
    counts, reason = held_and_pooled(counts, _classify(counts, sweep, cal), hold, steps, cal,
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
                pieces = _segment(*parts, lines, sw.centre,
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
                   voter: Callable | None = None, post_grouper: Callable | None = None,
                   gapper: Callable | None = None, raw_counts: np.ndarray | None = None,
                   beside: Callable | None = None, tracer: type[TraceSteps] | None = None,
                   judge: Callable | None = None, bower: Callable | None = None,
                   fitter: type[CountsFits] | None = None,
                   past_finder: Callable | None = None,
                   faceter: Callable | None = None) -> Estimate:
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
    chords read on its circle (:func:`bowed_lines`) and a far line over a corner read as two
    (:func:`kinked_lines`); line members onto their lines
    (``snapper``, the compiled :func:`snap_to_lines` by default), members read just past
    the max range kept only where their line put them within it (:func:`drop_beyond_range`),
    each silent beam's reach (``reach``, the compiled :func:`no_return_reach` by default; the
    oracle passes its numpy statements of both; never past ``cal.silent_range_m``:
    :func:`silent_reach`), last (``snap`` only) dim returns beside a line's members put on it
    (:func:`dim_returns_on_lines`) and, with ``detail``, the :class:`Lines`. Line members are
    first moved out by what the return level cut off their lines (:func:`censored_lines`).
    ``profiler``: the readings' range profiles (the compiled :func:`profiles_compiled` by
    default; the oracle passes its numpy statement :func:`range_profiles`); ``voter`` and
    ``post_grouper``: the short far lines' vote and the far posts' groups (compiled by
    default; the oracle passes its numpy ``far_line_vote`` and ``post_groups``);
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
    oracle: :func:`faceted_lines`).
    ``raw_counts`` (S, N): the sweep's counts before pooling (None: ``counts``), which tell a
    pooled reading's own level (:func:`noise_past_line_end`)."""
    shape = points.valid.shape
    beside = beside or beside_a_return_compiled
    if grouping is None:       # nothing to group (e.g. every reading invalid): no lines
        empty = _lines_record(None, np.full(shape, -1, dtype=np.intp), np.zeros(0, np.intp))
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
    short = short_far_lines(points, label, index, cal) if snap else None
    # one profile call for local_incidence, round_runs and the doubt while no reading leaves
    profiler = _SharedProfiles(profiler or profiles_compiled,
                               None if short is None else short[0] | short[1])
    points, label = local_incidence(points, label, index, counts, steps, cal, profiler)
    points, label = round_runs(points, label, index, counts, steps, cal, grouping.alpha,
                               grouping.cx, grouping.cy, profiler, snap,
                               far_sigma_cap(cal, points.max_range_m))
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
        points, label = alone_at_an_edge(points, label, counts, steps, cal)
        # a curved wall's chords on its circle (the lines as the rules above left them)
        points, label = (bower or bowed_lines_compiled)(points, label, counts, cal)
        # a line over a corner as two pieces (the snap's label; the grouping keeps its lines)
        points, split = kinked_lines(points, label, counts, cal)
        # members whose beam meets another wall first: read on that wall
        points, split = past_other_lines(points, split, counts, cal, options, past_finder)
    else:
        split = label
    points = censored_lines(points, split, counts, steps, cal)
    snap_label = None
    if snap:
        # a part read to its own range: the overlapping lines of one wall fitted as one
        snap_label = (fused_lines(points, split) if read_to_own_range(cal, points.max_range_m)
                      else split)
        snapped = (snapper or snap_to_lines)(points, snap_label, cal.min_range_m,
                                             far_sigma_cap(cal, points.max_range_m))
        # a line over a many-sided wall's facets: its members on two pieces
        points = (faceter or faceted_lines_compiled)(points, snap_label, snapped, cal)
    points = drop_beyond_range(points)
    if snap:
        # a thin post far away: its few readings, several sensors', fitted as one circle
        points = far_posts(points, label, counts, steps, cal, post_grouper)
        points = unplaced_alone(points, split)
    pooled = (points.valid & (counts < cal.no_return_counts + cal.return_margin_counts)
              if read_to_own_range(cal, points.max_range_m) else None)
    silent = bool(np.count_nonzero(points.reason == _NO_RETURN))
    # dim returns beside a line's members put on it once every rule above has decided
    # (snap_label None: a fold-over's judging pass keeps its lines as fitted)
    if not (detail or silent or (pooled is not None and pooled.any())):
        return Estimate(points=dim_returns_on_lines(points, snap_label, counts, raw_counts,
                                                    steps, cal),
                        lines=None, theta_history=tuple(history))
    pieces_out = replace(grouping.pieces, cx=grouping.cx, cy=grouping.cy,
                         alpha=grouping.alpha, usable=grouping.usable)
    used = index if grouping.uidx is None else index.take(grouping.uidx)
    found = _lines_record(pieces_out, label, used)
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
    return Estimate(points=points, lines=found if detail else None,
                    theta_history=tuple(history))


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
    g = label[member]
    n = np.bincount(g)
    nn = np.maximum(n, 1)
    x, y = points.x[member], points.y[member]
    mx, my = np.bincount(g, x) / nn, np.bincount(g, y) / nn
    u, v = x - mx[g], y - my[g]
    alpha = 0.5 * np.arctan2(2.0 * np.bincount(g, u * v, n.size),
                             np.bincount(g, u * u, n.size) - np.bincount(g, v * v, n.size))
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
    """(points, label) with the valid members of a line whose beams meet another line of
    ≥ ``PAST_MIN`` members first — within its members' extent or past its ends by up to
    ``PAST_REACH_SHARE`` of the range — ahead of their end points by ``PAST_CLEAR_SIGMAS`` σ
    + ``PAST_CLEAR_M``, on the side of that line where at most ``PAST_FEW`` of their line's members lie
    (a corner, not a wall passing behind the other's end): each read on the nearest such
    line at its incidence where its counts put it there within max(2 cm, 3σ) (label −1:
    placed, not snapped); the others as they were. ``label`` (S, N): the lines as
    kinked_lines left them; ``finder``: the members so asked (the compiled
    :func:`past_members_compiled` by default; the oracle passes its numpy statement
    :func:`past_members`). Why: a wall's last readings at grazing past a corner join the
    line they continue, read at its θ 100-270 mm long (docs/estimator.md, "A beam that
    meets another wall first")."""
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
    g = label[member]
    n = np.bincount(g)
    wall = n >= PAST_MIN
    if np.count_nonzero(wall) < 2:
        return None
    nn = np.maximum(n, 1)
    x, y = points.x[member], points.y[member]
    mx, my = np.bincount(g, x) / nn, np.bincount(g, y) / nn
    u, v = x - mx[g], y - my[g]
    alpha = 0.5 * np.arctan2(2.0 * np.bincount(g, u * v, n.size),
                             np.bincount(g, u * u, n.size) - np.bincount(g, v * v, n.size))
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
    # (the ring centre numpy's way: the kernel sums a contiguous array as np.mean does)
    centre = ((math.nan, math.nan) if ox.flags.c_contiguous and oy.flags.c_contiguous
              else (float(ox.mean()), float(oy.mean())))
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
    them is another sensor's). Numpy, shared by both estimators. Such a reading lies
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
        with np.errstate(divide="ignore", invalid="ignore"):
            far_end = cal.distance(np.asarray(counts, dtype=float)[order][returned],
                                   cal.max_incidence_rad)
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


CONTRADICT_SIGMAS = 5.0  # a line that would have read a silent step this many count σ
#                          brighter (of up to ACROSS_MAX + 3 steps: 5σ, not 3σ) is not there
ACROSS_MAX = 5  # at most this many readings a line took across a silent gap are moved
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
    (L,): each line's direction and centroid), took those few across the gap: they move to
    the other line, read at the incidence their beam meets it with the noise σ at that θ;
    where it meets it past the drop-out angle they leave their line, read at θ = 0 with the
    fallback σ (:func:`local_incidence` asks them); ``moves`` False: none of this. With
    ``alone`` (the final pass, after :func:`rejoin_traces`), a run that holds no other line
    beside them, where the line's readings of this sensor go on in the run across the gap
    and nowhere past them, and ``LONE_GAP_MIN`` of the gap's steps contradict the line, has
    them INCIDENCE_UNKNOWN: nothing on their side says where they lie (their own profile
    runs across the gap). ``label`` (S, N): each reading's line
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
    for before, side, nb in ((True, new_run[first], np.arange(1, n_s + 1)),   # a run's first
                             (False, np.r_[new_run[1:], True][last], np.arange(-1, n_s - 1))):
        nb = np.clip(nb, 0, n_s - 1)
        m_lab = s_lab[nb]
        lab_c, m_c = np.maximum(s_lab, 0), np.maximum(m_lab, 0)
        few_here = (side & few & (in_run[s_run, lab_c] == s_len)
                    & (runs_of[lab_c, s_sens] >= 2))
        beside = (s_run[nb] == s_run) & (nb != np.arange(n_s))
        ok = (few_here & beside & (m_lab >= 0) & (m_lab != s_lab)
              & (in_run[s_run, m_c] >= s_len) & moves)
        # the run holds nothing else on a line (a steep wall's last readings before its
        # drop-out, taken across it by the far wall's line: docs/estimator.md, "Silent gaps"),
        # the line's members of this sensor go on in the run across the gap, and this run is
        # the last (first) of them: they end the line's trace, not a stretch within it
        adj = np.clip(s_run + (-1 if before else 1), 0, n_runs - 1)
        end = (run_hi if before else run_lo)[lab_c, s_sens] == s_run
        lone = (few_here & ~(beside & (m_lab >= 0)) & alone & end & (adj != s_run)
                & (run_sens[adj] == s_sens) & (in_run[adj, lab_c] > 0))
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
                to = np.where(hit & (to < 0), m_lab, to)
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
    # a reading the line of its run meets past the drop-out leaves its line for θ = 0 and
    # the fallback σ: local_incidence then asks its own profile
    la0, b0 = cal._ab0
    d0 = np.exp(la0 + b0 * np.log(s[~met]))
    theta[~met], d[~met], to[~met] = 0.0, d0, -1
    sigma[~met] = theta0_sigma(cal, s[~met], d0, sig_s[~met])
    label.reshape(-1)[at] = to
    return placed_at(points, at, d, theta, sigma), label


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
    return (_unplaced(points, vi[left]) if left.any() else points), label


def invalidated(points: Points, gone: np.ndarray, why: Reason) -> Points:
    """``points`` with the readings ``gone`` (flat (S·N,) indices, or a bool mask of any
    shape) made ``why``: not valid, no end point, distance, θ or σ."""
    gone = np.flatnonzero(gone) if gone.dtype == bool else gone
    out = {f: np.array(getattr(points, f)) for f in ("x", "y", "d", "theta", "sigma_m")}
    for v in out.values():
        v.reshape(-1)[gone] = np.nan
    valid, reason = points.valid.copy(), np.array(points.reason)
    valid.reshape(-1)[gone] = False
    reason.reshape(-1)[gone] = why
    return points_with(points, valid=valid, reason=reason, **out)


def placed_at(points: Points, at: np.ndarray, d, theta, sigma) -> Points:
    """``points`` with the flat readings ``at`` read at range ``d`` (m), incidence ``theta``
    (rad) and ``sigma`` (m), their end points along their own headings."""
    h = points.heading.reshape(-1)[at]
    out = {f: np.array(getattr(points, f)) for f in ("x", "y", "d", "theta", "sigma_m")}
    for f, v in (("d", d), ("theta", theta), ("sigma_m", sigma),
                 ("x", points.origin_x.reshape(-1)[at] + d * np.cos(h)),
                 ("y", points.origin_y.reshape(-1)[at] + d * np.sin(h))):
        out[f].reshape(-1)[at] = v
    return points_with(points, **out)


FUSE_MIN = 5            # lines of at least this many valid members are tried together …
FUSE_Z = 2.5            # … where direction and offset agree within this many standard errors …
FUSE_OVERLAP_M = 0.05   # … over at least this much of both lines' extents …
FUSE_TURN_MAX = math.radians(5)  # … and whose directions differ by at most this


def fused_lines(points: Points, label: np.ndarray) -> np.ndarray:
    """``label`` (S, N: each reading's line, −1 none) with lines that are one surface joined:
    lines of ≥ ``FUSE_MIN`` valid members whose extents overlap by ≥ ``FUSE_OVERLAP_M`` and
    whose directions, and offsets at the middle of the overlap, differ by at most ``FUSE_Z``
    of their combined standard errors (total least squares; the members' scatter about
    their line or, where more, their own noise across it) take the smallest label of their
    group. Overlapping lines are of different sensors that saw one wall; the snap then fits
    them as one, which averages their independent offsets. Why: docs/estimator.md, "Far
    lines fused across sensors"."""
    label = np.asarray(label)
    member = points.valid & (label >= 0)
    if not member.any():
        return label
    g = label[member]
    n_lines = int(label.max()) + 1     # invalid readings may hold the highest labels
    n = np.bincount(g, minlength=n_lines)
    cand = (n >= FUSE_MIN).nonzero()[0]
    if cand.size < 2:
        return label
    x, y = points.x[member], points.y[member]
    nn = np.maximum(n, 1)
    mx, my = np.bincount(g, x, n_lines) / nn, np.bincount(g, y, n_lines) / nn
    u, v = x - mx.take(g), y - my.take(g)
    alpha = 0.5 * np.arctan2(2.0 * np.bincount(g, u * v, n_lines),
                             np.bincount(g, u * u - v * v, n_lines))
    ca, sa = np.cos(alpha), np.sin(alpha)
    along = u * ca.take(g) + v * sa.take(g)
    rel = v * ca.take(g) - u * sa.take(g)
    # the members' scatter about their line, or their own noise across it where that is
    # more: pooled readings (13 steps' mean counts) share their noise and scatter less
    own = points.sigma_m[member] * np.cos(points.theta[member])
    var_perp = np.maximum(np.bincount(g, rel * rel, n_lines),
                          np.bincount(g, own * own, n_lines)) / nn
    spread = np.maximum(np.bincount(g, along * along, n_lines), 1e-12)
    lo = np.full(n_lines, np.inf)
    hi = np.full(n_lines, -np.inf)
    np.minimum.at(lo, g, along)
    np.maximum.at(hi, g, along)
    i, j = (a.ravel() for a in np.meshgrid(cand, cand, indexing="ij"))
    keep = i < j
    i, j = i[keep], j[keep]
    # j's extent in i's frame (along i's direction, from i's centroid)
    dxc, dyc = mx[j] - mx[i], my[j] - my[i]
    cj = dxc * ca[i] + dyc * sa[i]
    dot = ca[i] * ca[j] + sa[i] * sa[j]
    ends = cj + dot * lo[j], cj + dot * hi[j]
    a = np.maximum(lo[i], np.minimum(*ends))
    b = np.minimum(hi[i], np.maximum(*ends))
    s = 0.5 * (a + b)                                   # the overlap's middle, on i
    px, py = mx[i] + s * ca[i], my[i] + s * sa[i]
    off = (py - my[j]) * ca[j] - (px - mx[j]) * sa[j]   # j's line from there, across j
    sj = (px - mx[j]) * ca[j] + (py - my[j]) * sa[j]
    var_a = var_perp[i] / spread[i] + var_perp[j] / spread[j]
    var_off = (var_perp[i] / nn[i] + var_perp[i] / spread[i] * s * s
               + var_perp[j] / nn[j] + var_perp[j] / spread[j] * sj * sj)
    turn = np.arcsin(np.clip(np.abs(ca[i] * sa[j] - sa[i] * ca[j]), 0.0, 1.0))
    join = ((b - a >= FUSE_OVERLAP_M) & (turn <= np.minimum(FUSE_Z * np.sqrt(var_a),
                                                             FUSE_TURN_MAX))
            & (np.abs(off) <= FUSE_Z * np.sqrt(var_off)))
    if not join.any():
        return label
    root = np.arange(n_lines)

    def find(k):
        while root[k] != k:
            root[k] = root[root[k]]
            k = root[k]
        return k
    for p, q in zip(i[join], j[join]):
        rp, rq = find(p), find(q)
        if rp != rq:
            root[max(rp, rq)] = min(rp, rq)
    top = np.array([find(k) for k in range(n_lines)])
    out = label.copy()
    out[label >= 0] = top.take(label[label >= 0])
    return out


def read_to_own_range(cal: Calibration, max_range_m: float) -> bool:
    """Whether a part is read to its own range: silence ends short of ``max_range_m``
    (``cal.silent_range_m``), so its far readings are pooled and its far lines censored."""
    return bool(cal.falling and cal.silent_range_m < max_range_m)


def far_sigma_cap(cal: Calibration, max_range_m: float) -> float:
    """The most a line member's own σ may add to its σ on its line (m):
    :data:`SNAP_OWN_CAP_M` where a part is read to its own range (``cal.silent_range_m``
    short of ``max_range_m``: its far end's noise reaches 30–55 mm, which the line averages
    away), else +inf (half the member's own σ, as ever). Why and what it measured:
    docs/estimator.md, "A far line's σ"."""
    return SNAP_OWN_CAP_M if read_to_own_range(cal, max_range_m) else math.inf


def censored_lines(points: Points, label: np.ndarray, counts: np.ndarray, steps: np.ndarray,
                   cal: Calibration) -> Points:
    """Each valid member of a line moved out along its beam by the mean noise of the returns
    its line kept: σ·λ(f), λ(f) = φ(Φ⁻¹(f))/(1 − f), where f is the share of the line's beams
    whose counts fell below the return level (``no_return_counts + RETURN_SIGMAS`` count σ;
    NO_RETURN or OUT_OF_RANGE) and σ the member's range noise |b|·d·σ_S/S.

    A line's beams: each sensor's readings from its first to its last member step. Only
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
    silent = (points.reason == _NO_RETURN) | (points.reason == _OUT_OF_RANGE)
    cut = silent & (s < cal.no_return_counts + RETURN_SIGMAS * cal.sigma_counts())
    c_row, c_sensor = cut.nonzero()
    lo, hi = lo.reshape(n_lines, n_sensors), hi.reshape(n_lines, n_sensors)
    on = (lo[:, c_sensor] <= rank[c_row]) & (rank[c_row] <= hi[:, c_sensor])   # (L, C)
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


# --------------------------------------------------------------------------- readings on no line

_LOCAL_STEPS = 5        # a reading on no line looks this many steps either way …
_LOCAL_MIN = 3          # … and needs this many readings of one surface (itself included) …
_LOCAL_SPREAD_M = 0.001  # … spread across its beam by at least this RMS …
_LOCAL_SLOPE_SE = 2.0   # … a range slope this many standard errors from flat …
_CHI2_95 = np.array([3.84, 5.99, 7.81, 9.49, 11.07])  # … and a straight profile: χ² within
#                                                    its 95 % point (1 … 5 degrees of freedom)
_CONVEX_BELOW_DROP_RAD = math.radians(5)  # a bend with θ this near the drop-out is the model's clamp
_UNKNOWN_M = 0.10       # fewer readings, and θ = 0 may read this much long: INCIDENCE_UNKNOWN
_CONVEX_SURE_SE = 3.0   # … unless its profile bends away this many standard errors: a post
_BEND_MIN_SHARE = 1e-12  # a bend is read only where the curvature term keeps this share of
#                          Σ(v²)²: readings at three spots across the beam or more


@dataclass(frozen=True)
class _Profile:
    """What a reading's own sensor's neighbouring steps say of the surface it met
    (:func:`range_profiles`); arrays over the asked readings, ``s``, ``d0`` and ``sig_s``
    over every valid reading."""
    s: np.ndarray         # counts of every valid reading in scan order
    d0: np.ndarray        # their θ = 0 distances
    sig_s: np.ndarray     # their relative count noise σ_S/S
    n: np.ndarray         # readings of the same surface in the window
    slope: np.ndarray     # range slope across the beam (tan θ, signed)
    se: np.ndarray        # its standard error
    theta: np.ndarray     # θ = atan|slope|, at most the drop-out angle
    ok: np.ndarray        # a straight profile clearly not flat: θ is its slope
    convex: np.ndarray    # bent away from the beam: a post, a leg, a column
    sure: np.ndarray      # bent away by _CONVEX_SURE_SE standard errors (not noise)
    concave: np.ndarray   # bent towards the beam: a concave corner
    steep: np.ndarray     # the steepest θ the readings allow
    chain: np.ndarray     # polyline id (at θ = 0) of every valid reading in scan order …
    heading: np.ndarray   # … its beam's heading …
    ox: np.ndarray        # … its emitter …
    oy: np.ndarray
    step: np.ndarray      # … and motor step


def _profile_inputs(points: Points, vi: np.ndarray, counts: np.ndarray, steps: np.ndarray,
                    cal: Calibration):
    """Per valid reading in scan order (``vi``): counts, heading, emitter, log counts,
    σ_S/S, θ = 0 distance, polyline id (at θ = 0) and motor step. numpy, the statement
    the kernel ``_lines.profile_inputs`` (which :func:`profiles_compiled` calls) is held to."""
    n_sensors = points.valid.shape[1]
    s = np.asarray(counts, dtype=float).reshape(-1)[vi]
    h = points.heading.reshape(-1)[vi]
    ox, oy = points.origin_x.reshape(-1)[vi], points.origin_y.reshape(-1)[vi]
    log_s = np.log(s)
    sig_s = cal.sigma_counts() / s              # σ_d = |b|·d·σ_S/S
    la0, b0 = cal._ab0
    d0 = np.exp(la0 + b0 * log_s)
    chain = polyline_ids(d0, range_sigma(b0, d0, sig_s), h,
                         vi % n_sensors, cal.max_incidence_rad, LineOptions.jump_sigmas)
    step = np.asarray(steps).reshape(-1)[vi // n_sensors]
    return s, h, ox, oy, log_s, sig_s, d0, chain, step


def profiles_compiled(points: Points, vi: np.ndarray, off: np.ndarray, counts: np.ndarray,
                      steps: np.ndarray, cal: Calibration, apart: np.ndarray | None = None
                      ) -> _Profile:
    """:func:`range_profiles` in two compiled calls (``irring.estimation._lines.profile_inputs``
    and ``profiles``, held to it by tests/test_estimate_oracle.py)."""
    f = np.ascontiguousarray
    la0, b0 = cal._ab0
    s, h, ox, oy, log_s, sig_s, d0, chain, step = _lines.profile_inputs(
        f(counts, dtype=float).reshape(-1), f(points.heading, dtype=float).reshape(-1),
        f(points.origin_x, dtype=float).reshape(-1), f(points.origin_y, dtype=float).reshape(-1),
        np.asarray(steps).reshape(-1).astype(np.intp), f(vi, dtype=np.intp),
        points.valid.shape[1], cal.sigma_counts(), la0, b0, SIGMA_FLOOR_M,
        jump_slope(cal.max_incidence_rad), LineOptions.jump_sigmas)
    chain = _set_apart(chain, apart)
    n, slope, se, theta, steep, ok, convex, sure, concave = _lines.profiles(
        ox, oy, h, log_s, sig_s, chain, step,
        np.ascontiguousarray(off, dtype=np.intp), cal.theta_rad,
        cal._node_log_a, cal.b, cal.max_incidence_rad,
        _CONVEX_BELOW_DROP_RAD, _LOCAL_STEPS, _LOCAL_MIN, _LOCAL_SPREAD_M, _LOCAL_SLOPE_SE,
        _CHI2_95, SIGMA_FLOOR_M, _CONVEX_SURE_SE, _BEND_MIN_SHARE)
    return _Profile(s=s, d0=d0, sig_s=sig_s, n=n, slope=slope, se=se, theta=theta,
                    ok=ok.view(bool), convex=convex.view(bool), sure=sure.view(bool),
                    concave=concave.view(bool), steep=steep, chain=chain, heading=h,
                    ox=ox, oy=oy, step=step)


def _set_apart(chain: np.ndarray, apart: np.ndarray | None) -> np.ndarray:
    """Polyline ids ``chain`` (scan order) with each reading where ``apart`` holds a polyline
    of its own, its neighbours either side cut from each other too."""
    if apart is None or not apart.any():
        return chain
    cut = np.ones(chain.size, dtype=bool)
    cut[1:] = (chain[1:] != chain[:-1]) | apart[1:] | apart[:-1]
    return np.cumsum(cut).astype(chain.dtype)


def range_profiles(points: Points, vi: np.ndarray, off: np.ndarray, counts: np.ndarray,
                   steps: np.ndarray, cal: Calibration, apart: np.ndarray | None = None
                   ) -> _Profile:
    """The range profile of each reading ``vi[off]`` (``vi``: the valid readings' flat
    indices in scan order) from its sensor's valid readings of the same polyline within
    ``_LOCAL_STEPS`` steps, read as a flat surface would be (:func:`local_incidence`);
    ``apart`` (over ``vi``, optional): readings that are a polyline of their own.
    numpy, the statement :func:`profiles_compiled` is held to."""
    s, h, ox, oy, log_s, sig_s, d0, chain, step = _profile_inputs(points, vi, counts, steps,
                                                                 cal)
    chain = _set_apart(chain, apart)
    # the window: same polyline, within _LOCAL_STEPS steps
    j = off[:, None] + np.arange(-_LOCAL_STEPS, _LOCAL_STEPS + 1)[None, :]
    jc = np.clip(j, 0, vi.size - 1)
    w = ((j == jc) & (chain[jc] == chain[off][:, None])
         & (np.abs(step[jc] - step[off][:, None]) <= _LOCAL_STEPS)).astype(float)
    n = w.sum(axis=1)
    ux, uy = np.cos(h[off])[:, None], np.sin(h[off])[:, None]
    rx, ry = ox[jc] - ox[off][:, None], oy[jc] - oy[off][:, None]
    cj, sj = np.cos(h[jc]), np.sin(h[jc])
    lsj = log_s[jc]
    turn = h[jc] - h[off][:, None]
    turn -= 2.0 * math.pi * np.round(turn / (2.0 * math.pi))
    signed = np.zeros(off.size)          # θ with the sign of the slope
    for _ in range(3):
        # on a flat surface a neighbour meets it at θ plus the angle the beam turned
        theta_j = np.minimum(np.abs(signed[:, None] + turn), cal.max_incidence_rad)
        la, b = cal.log_ab(theta_j)
        d = np.exp(la + b * lsj)
        x, y = rx + d * cj, ry + d * sj
        u, v = x * ux + y * uy, y * ux - x * uy
        nn = np.maximum(n, 1.0)
        mu, mv = (w * u).sum(axis=1) / nn, (w * v).sum(axis=1) / nn
        du, dv = (u - mu[:, None]) * w, (v - mv[:, None]) * w
        svv = np.maximum((dv * dv).sum(axis=1), 1e-12)
        slope = (du * dv).sum(axis=1) / svv
        signed = np.clip(np.arctan(slope), -cal.max_incidence_rad, cal.max_incidence_rad)
    theta = np.abs(signed)
    sig = range_sigma(b, d, sig_s[jc])
    se = np.sqrt(((sig * dv) ** 2).sum(axis=1)) / svv
    res = (du - slope[:, None] * dv) / sig
    chi2 = (res * res).sum(axis=1)
    # readings of one step repeated lie on one spot: they give no slope
    n = np.where(svv >= n * _LOCAL_SPREAD_M ** 2, n, 0.0)
    dof = np.clip(n - 2.0, 1.0, _CHI2_95.size).astype(np.intp)
    # bent: a curvature term (v², orthogonal to 1 and v) clearly off zero; a post's side
    # bends away from the beam (θ changes ~10× faster than the beam turns), a flat wall
    # is straight whatever its θ
    q = dv * dv
    q_norm = (q * q).sum(axis=1)
    q = (q - (q.sum(axis=1) / nn)[:, None] * w
         - ((q * dv).sum(axis=1) / svv)[:, None] * dv) * w
    sqq = (q * q).sum(axis=1)
    # at two spots (two readings, or a step repeated) the term is zero but for rounding and
    # its bend noise over noise, which numpy and the kernel round apart: no bend there
    curved = (n >= _LOCAL_MIN) & (sqq > _BEND_MIN_SHARE * q_norm)
    sqq = np.maximum(sqq, 1e-30)
    bend = np.where(curved, (du * q).sum(axis=1) / sqq, 0.0)
    bend_se = np.where(curved, np.sqrt(((sig * q) ** 2).sum(axis=1)) / sqq, 0.0)
    straight = ((n >= _LOCAL_MIN) & (chi2 <= _CHI2_95[dof - 1])
                & (np.abs(bend) <= _LOCAL_SLOPE_SE * bend_se))
    ok = straight & (np.abs(slope) > _LOCAL_SLOPE_SE * se)
    # undecided: too few readings (θ anywhere up to the drop-out), a bent profile or one
    # whose slope may be anything from flat to steep; kept at θ = 0 they may read long
    # (a post's centre has a flat slope: it stays); a profile bent towards the beam is a
    # concave corner, the reading on either wall: θ anywhere up to the drop-out
    concave = bend < -_LOCAL_SLOPE_SE * bend_se
    # the slope bounds θ only where the profile is straight (or a post's, bent away): a
    # window across a corner fails χ², and its slope's noise-only error bounded a reading
    # 39° steep at 47°, keeping it at θ = 0 105 mm long
    bounded = straight | (bend > _LOCAL_SLOPE_SE * bend_se)
    steep = np.where((n < _LOCAL_MIN) | concave | ~bounded, cal.max_incidence_rad, np.minimum(
        np.arctan(np.abs(slope) + _LOCAL_SLOPE_SE * se), cal.max_incidence_rad))
    # a profile bent away from the beam is a convex thing (a post, a leg): kept at θ = 0,
    # as a post's readings are; flagging them lost thin legs' recall (0.96 -> 0.89)
    convex = ((n >= _LOCAL_MIN) & (bend > _LOCAL_SLOPE_SE * bend_se)
              & (theta < cal.max_incidence_rad - _CONVEX_BELOW_DROP_RAD))
    return _Profile(s=s, d0=d0, sig_s=sig_s, n=n, slope=slope, se=se, theta=theta, ok=ok,
                    convex=convex, sure=bend > _CONVEX_SURE_SE * bend_se, concave=concave,
                    steep=steep, chain=chain, heading=h, ox=ox, oy=oy, step=step)


class _SharedProfiles:
    """A profiler (``profiler``'s signature) that also profiles the readings of ``extra``
    (flat (S·N,) mask) whenever it calls ``profiler`` and answers later calls from that call
    while the valid readings ``vi`` are the same: a reading's profile depends on ``vi`` and
    on no other asked reading (the shared profile_inputs and one kernel call saved a sweep).
    Readings set apart, or never asked, are asked of ``profiler`` alone."""

    def __init__(self, profiler: Callable, extra: np.ndarray | None):
        self.profiler, self.extra, self.vi, self.asked, self.pr = profiler, extra, None, None, None

    def __call__(self, points: Points, vi: np.ndarray, off: np.ndarray, counts: np.ndarray,
                 steps: np.ndarray, cal: Calibration, apart: np.ndarray | None = None
                 ) -> _Profile:
        if apart is not None or self.extra is None:
            return self.profiler(points, vi, off, counts, steps, cal, apart=apart)
        if self.pr is not None and np.array_equal(vi, self.vi):
            row = np.searchsorted(self.asked, off)
            # (a first call that asked nothing leaves nothing to take from)
            have = self.asked.take(row, mode="clip") if self.asked.size else self.asked
            if not np.array_equal(have, off):
                return self.profiler(points, vi, off, counts, steps, cal)
            out = object.__new__(_Profile)    # (dataclasses.replace costs several times more)
            out.__dict__.update(self.pr.__dict__)
            out.__dict__.update({f: getattr(self.pr, f).take(row) for f in _PROFILE_ROWS})
            return out
        # the first call, or a reading left since: the doubt's members asked with it
        asked = self.extra[vi]
        asked[off] = True
        self.vi, self.asked = vi, asked.nonzero()[0]
        self.pr = self.profiler(points, vi, self.asked, counts, steps, cal)
        return self(points, vi, off, counts, steps, cal)


_PROFILE_ROWS = ("n", "slope", "se", "theta", "ok", "convex", "sure", "concave", "steep")


ROUND_SHARE = 0.4        # a line is a round thing's when this share of its members' profiles
#                          bend away from the beam, …
ROUND_OVER_OK = 1.5      # … this many times as many as are straight and steep (a convex
#                          corner's faces are), …
ROUND_MIN_THETA = math.radians(30)  # … and its members' mean θ is at least this
FAR_LINE_MAX_MEMBERS = 25  # a line of at most this many members is short: its direction
#                            rests on a few noisy readings; a short line …
FAR_LINE_MIN_SHARE = 0.72  # … whose members lie this share of the max range away on average
#                            (the GP2D12's 0.45 of 0.624 m), …
FAR_LINE_Z = 1.0           # … whose members' own slopes differ from its θ by this many of
#                            their standard errors on average (either way) …
FAR_LINE_SHIFT_M = 0.01    # … and would move them by a map cell on average is doubted
REGAIN_RATIO = 2.0  # a fold-over's first-pass line this many times as long gives back θ
DIRECTION_SE_MAX = math.radians(6)  # a far line whose direction is known no better gives no θ
SHORT_LINE_MAX_MEMBERS = 9  # elsewhere a far line of at most this many members (unsnapped) …
SHORT_LINE_SE_MAX = math.radians(4)  # … whose direction is known no better leaves each member
#                                      its own θ where its own profile is straight …
SHORT_LINE_OWN_SE = 0.5      # … and its slope this many of its standard errors off the line's


def direction_se(x: np.ndarray, y: np.ndarray, sigma_perp: np.ndarray, line: np.ndarray,
                 n_lines: int) -> np.ndarray:
    """Each line's direction standard error (rad) from its members' own noise: the RMS of
    their σ across the line (``sigma_perp``, m) over the root of the members' summed squared
    spread along it (total least squares); ``x``, ``y`` (m) and ``line`` over the members."""
    n = np.maximum(np.bincount(line, minlength=n_lines), 1)
    u = x - (np.bincount(line, x, n_lines) / n).take(line)
    v = y - (np.bincount(line, y, n_lines) / n).take(line)
    alpha = 0.5 * np.arctan2(2.0 * np.bincount(line, u * v, n_lines),
                             np.bincount(line, u * u - v * v, n_lines))
    along = u * np.cos(alpha).take(line) + v * np.sin(alpha).take(line)
    spread = np.maximum(np.bincount(line, along * along, n_lines), 1e-12)
    return np.sqrt(np.bincount(line, sigma_perp * sigma_perp, n_lines) / n / spread)


def _fewer_distinct(values: np.ndarray, n: int) -> bool:
    """Whether ``values`` hold fewer than ``n`` distinct values (np.unique(values).size < n;
    integers are sorted and counted instead, several times quicker on a sweep's steps)."""
    v = np.asarray(values).reshape(-1)
    if v.dtype.kind not in "iub":
        return bool(np.unique(v).size < n)
    if v.size < n:
        return True
    v = np.sort(v)
    return bool(np.count_nonzero(v[1:] != v[:-1]) + 1 < n)


ARC_RADII_M = np.geomspace(0.008, 0.6, 12)  # the radii a round thing's arc is tried at, …
ARC_REFINE = np.array([-0.5, -0.25, 0.0, 0.25, 0.5])  # … then these grid steps about the best
ARC_MIN = 5             # a sensor's arc needs this many readings on no line …
ARC_SIDE = 2            # … this many either side of its apex (a whole arc seen) …
ARC_GAP_STEPS = 4       # … no more than this many motor steps apart …
ARC_APEX_STEPS = 4      # … whose apex lies within this many readings of its nearest one …
ARC_MISFIT = 4.0        # … and reads them at the arc's θ within this mean squared misfit (σ²),
ARC_MISS = 16.0         # each at most this (a beam that misses the arc: this); a reading
ARC_ON = 9.0            # takes the arc's θ where its own misfit is at most this
ARC_DOUBT_RAD = math.radians(5)  # a reading on an arc: σ includes d over θ ± this


def _arc_misfit(geo, apex: np.ndarray, radius: np.ndarray, cal: Calibration):
    """Candidate circles (C, K): apex reading index and radius (m) of each polyline's
    circle; ``geo`` its readings' padded arrays (C, J). Returns the summed misfit (C, K) and
    each reading's θ, d and misfit at that circle (C, K, J)."""
    ox, oy, ex, ey, d0, log_s, noise, mask = geo
    ax, ay = np.take_along_axis(ex, apex, axis=1), np.take_along_axis(ey, apex, axis=1)
    cx = np.take_along_axis(ox + d0 * ex, apex, axis=1) + radius * ax
    cy = np.take_along_axis(oy + d0 * ey, apex, axis=1) + radius * ay
    rx = cx[..., None] - ox[:, None, :]
    ry = cy[..., None] - oy[:, None, :]
    ejx, ejy = ex[:, None, :], ey[:, None, :]
    along = rx * ejx + ry * ejy
    r = radius[..., None]
    disc = along * along - (rx * rx + ry * ry - r * r)
    t = along - np.sqrt(np.maximum(disc, 0.0))           # where the beam meets the circle
    cos = np.clip(-((t * ejx - rx) * ejx + (t * ejy - ry) * ejy) / r, 0.0, 1.0)
    th = np.arccos(cos)
    meets = (disc > 0.0) & (along > 0.0) & (th <= cal.max_incidence_rad)
    la, b = cal.log_ab(th)
    d = np.exp(la + b * log_s[:, None, :])
    z = (d - t) / noise[:, None, :]
    each = np.where(meets, np.minimum(z * z, ARC_MISS), ARC_MISS)
    return np.where(mask[:, None, :], each, 0.0).sum(axis=-1), th, d, each


def arc_incidence(pr: _Profile, pos: np.ndarray, cal: Calibration,
                  radii: np.ndarray = ARC_RADII_M):
    """θ of readings on no line from one circle per arc (a sensor's readings of a round
    thing), numpy; shared by both estimators.

    ``pos``: positions into the valid readings in scan order (ascending). An arc is a run of
    at least ``ARC_MIN`` of them on one polyline, steps at most ``ARC_GAP_STEPS`` apart. It
    is tried as part of a circle whose nearest point lies on one of its readings' beams at
    that reading's θ = 0 distance (the apex, met square on; within ``ARC_APEX_STEPS`` of its
    nearest reading) with a radius of ``radii`` (refined by ``ARC_REFINE``): every
    reading is read at the θ at which its beam meets that circle and scored by how far that
    distance lies from the circle (in its noise σ, squared, at most ``ARC_MISS``). The best
    circle is kept where its apex has ``ARC_SIDE`` readings either side (a whole arc seen)
    and its mean misfit is below ``ARC_MISFIT``; a reading takes it where its own misfit is
    at most ``ARC_ON``. Returns θ (rad), d (m), σ (m: noise at θ plus the spread of d over
    θ ± ``ARC_DOUBT_RAD``), ``good`` and each reading's misfit at its arc's best circle
    (``ARC_MISS`` where it is on none), each (len(pos),), and that circle's centre x, y and
    radius (3, len(pos)). Why: docs/estimator.md, "Round
    things seen far away"."""
    m = pos.size
    theta, dist, sigma = np.full(m, np.nan), np.full(m, np.nan), np.full(m, np.nan)
    good = np.zeros(m, dtype=bool)
    misfit = np.full(m, ARC_MISS)
    circle = np.full((3, m), np.nan)
    if m < ARC_MIN:
        return theta, dist, sigma, good, misfit, circle
    # an arc: consecutive readings of one polyline (its ids grow along the scan order, so
    # they are consecutive in ``pos``, ordered by step), broken where steps are missing (a
    # polyline runs on over silent beams: two posts 39° apart made one)
    chain, step = pr.chain[pos], pr.step[pos]
    cut = np.ones(m, dtype=bool)
    cut[1:] = (chain[1:] != chain[:-1]) | (np.abs(step[1:] - step[:-1]) > ARC_GAP_STEPS)
    ids, first, size = np.unique(np.cumsum(cut), return_index=True, return_counts=True)
    group = np.repeat(np.arange(ids.size), size)
    rank = np.arange(m) - np.repeat(first, size)
    keep = size[group] >= ARC_MIN
    if not keep.any():
        return theta, dist, sigma, good, misfit, circle
    big = (size >= ARC_MIN).nonzero()[0]
    row = np.full(ids.size, -1)
    row[big] = np.arange(big.size)
    c, j = row[group[keep]], rank[keep]
    n_c, n_j = big.size, int(size[big].max())
    mask = np.zeros((n_c, n_j), dtype=bool)
    mask[c, j] = True

    def pad(v, fill):
        out = np.full((n_c, n_j), fill)
        out[c, j] = v[pos[keep]]
        return out
    s, d0, sig_s = pad(pr.s, 1.0), pad(pr.d0, np.inf), pad(pr.sig_s, 0.0)
    h = pad(pr.heading, 0.0)
    ex, ey = np.cos(h), np.sin(h)
    _, b0 = cal._ab0
    noise = range_sigma(b0, np.where(mask, d0, 1.0), sig_s)
    geo = (pad(pr.ox, 0.0), pad(pr.oy, 0.0), ex, ey, np.where(mask, d0, 1.0), np.log(s),
           noise, mask)
    n_in = mask.sum(axis=1)
    # the apex: near the nearest reading, by three-reading means (noise moves a single one)
    left = np.concatenate([d0[:, :1], d0[:, :-1]], axis=1)
    right = np.concatenate([d0[:, 1:], d0[:, -1:]], axis=1)
    right = np.where(np.isfinite(right), right, d0)
    near = np.argmin(d0 + left + right, axis=1)
    span = np.arange(-ARC_APEX_STEPS, ARC_APEX_STEPS + 1)
    apex = np.clip(near[:, None] + span[None, :], 0, (n_in - 1)[:, None])
    k_r = radii.size
    apex1 = np.repeat(apex, k_r, axis=1)
    radius1 = np.tile(radii, (n_c, span.size))
    cost1 = _arc_misfit(geo, apex1, radius1, cal)[0]
    best1 = np.argmin(cost1, axis=1)
    # refine: the best apex and its neighbours, radii between the grid's
    a1 = apex1[np.arange(n_c), best1]
    grid_step = math.log(radii[1] / radii[0])
    apex2 = np.clip(a1[:, None] + np.repeat([-1, 0, 1], ARC_REFINE.size)[None, :], 0,
                    (n_in - 1)[:, None])
    radius2 = radius1[np.arange(n_c), best1][:, None] * np.exp(
        grid_step * np.tile(ARC_REFINE, 3))[None, :]
    cost2, th2, d2, mis2 = _arc_misfit(geo, apex2, radius2, cal)
    best = np.argmin(cost2, axis=1)
    a = apex2[np.arange(n_c), best]
    fits = ((a >= ARC_SIDE) & (a < n_in - ARC_SIDE)
            & (cost2[np.arange(n_c), best] < ARC_MISFIT * n_in))
    th_best = th2[np.arange(n_c), best]                       # (C, J)
    d_best = d2[np.arange(n_c), best]
    on = mis2[np.arange(n_c), best] <= ARC_ON
    lo = cal.distance(s, np.maximum(th_best - ARC_DOUBT_RAD, 0.0))
    hi = cal.distance(s, np.minimum(th_best + ARC_DOUBT_RAD, cal.max_incidence_rad))
    _, b_th = cal.log_ab(th_best)
    sig = np.hypot(range_sigma(b_th, d_best, sig_s),
                   0.5 * np.abs(lo - hi))
    at = keep.nonzero()[0]
    theta[at], dist[at], sigma[at] = th_best[c, j], d_best[c, j], sig[c, j]
    good[at] = (fits[c] & on[c, j] & np.isfinite(dist[at]) & (dist[at] >= cal.min_range_m)
                & np.isfinite(sigma[at]))
    misfit[at] = mis2[np.arange(n_c), best][c, j]
    # the circle: its apex on the apex reading's beam at that reading's θ = 0 distance
    ox, oy, ex, ey, d_apex = (v[np.arange(n_c), a] for v in geo[:5])
    rad = radius2[np.arange(n_c), best]
    circle[:, at] = np.stack([ox + (d_apex + rad) * ex, oy + (d_apex + rad) * ey, rad])[:, c]
    return theta, dist, sigma, good, misfit, circle


ROUND_RADII_M = np.geomspace(0.1, 1.2, 12)  # a sensor's run cut into lines is tried as an arc
ROUND_RUN_MIN = 8        # … where it holds this many valid readings, steps ARC_GAP_STEPS apart
ROUND_JUMP_M = 0.10      # … θ = 0 ranges this near (a jump: another surface) …
ROUND_BULGE_M = 0.01     # … whose end points bulge this far towards it on average …
ROUND_BEHIND = 0.2       # … at most this share of them as far behind the chord of its ends
ROUND_BETTER = 0.5       # an arc replaces the lines where it misfits at most this share of one
ROUND_LINE_ITERATIONS = 4  # line through the run's readings (read as Table II would, this often)
ROUND_RETRY_Z = 3.0      # a run hollow as estimated that one line fits as noise alone would
#                          (χ² within this many of its σ above its n readings) is a wall's
ROUND_UNEXPLAINED = ARC_MISFIT  # a run's reading on no line costs its pieces this (σ²): no line
#                                 explains it; a reading that just fits a circle costs as much


def _bulging(px: np.ndarray, py: np.ndarray, ox: np.ndarray, oy: np.ndarray,
             group: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Per group (n,) of end points ``px``, ``py`` seen from emitters ``ox``, ``oy`` (each
    group's points in scan order): whether they bulge towards the sensor off the chord
    between the group's ends by ``ROUND_BULGE_M`` on average with at most ``ROUND_BEHIND``
    of them as far behind it; and each point's distance towards the sensor off it (m)."""
    first = np.searchsorted(group, np.arange(n))
    last = np.append(first[1:], group.size) - 1
    ux, uy = px[last] - px[first], py[last] - py[first]
    norm = np.hypot(ux, uy)
    ux, uy = ux / np.maximum(norm, 1e-12), uy / np.maximum(norm, 1e-12)
    side = np.sign((ox[first] - px[first]) * uy - (oy[first] - py[first]) * ux)
    toward = ((px - px[first][group]) * uy[group] - (py - py[first][group]) * ux[group]) \
        * side[group]
    n_in = np.bincount(group, minlength=n)
    return ((np.bincount(group, toward, n) >= ROUND_BULGE_M * n_in)
            & (np.bincount(group, toward < -ROUND_BULGE_M, n) <= ROUND_BEHIND * n_in)), toward


def _kasa_radii(x: np.ndarray, y: np.ndarray, group: np.ndarray, n: int) -> np.ndarray:
    """Radius (m) of the least-squares (Kåsa) circle through each group's points (n,);
    infinite for collinear points."""
    cnt = np.bincount(group, minlength=n).astype(float)
    u = x - (np.bincount(group, x, n) / cnt)[group]
    v = y - (np.bincount(group, y, n) / cnt)[group]
    z = u * u + v * v
    suu, suv, svv, suz, svz, sz = (np.bincount(group, w, n)
                                   for w in (u * u, u * v, v * v, u * z, v * z, z))
    # centred: Σu = Σv = 0, so the centre solves a 2×2 system
    det = suu * svv - suv * suv
    ok = det > 1e-12 * (suu + svv) ** 2
    det = np.where(ok, det, 1.0)
    a = 0.5 * (svv * suz - suv * svz) / det
    b = 0.5 * (suu * svz - suv * suz) / det
    return np.where(ok, np.sqrt(a * a + b * b + sz / cnt), np.inf)


def _one_line_misfit(pr: _Profile, pos: np.ndarray, group: np.ndarray, n: int,
                     cal: Calibration) -> np.ndarray:
    """Each reading's misfit (as :func:`_arc_misfit` scores it) when its group's readings
    (``pr`` positions ``pos``, groups ``group`` < ``n``) are read as one straight line: Table
    II's iteration on one total-least-squares line per group, ``ROUND_LINE_ITERATIONS``
    times from θ = 0. (``pr``: a profile, or anything with its ox, oy, heading, s, d0 and
    sig_s.)"""
    ox, oy, h = pr.ox[pos], pr.oy[pos], pr.heading[pos]
    ex, ey = np.cos(h), np.sin(h)
    log_s, d = np.log(pr.s[pos]), pr.d0[pos]
    _, b0 = cal._ab0
    noise = range_sigma(b0, d, pr.sig_s[pos])
    cnt = np.bincount(group, minlength=n).astype(float)
    for _ in range(ROUND_LINE_ITERATIONS):
        x, y = ox + d * ex, oy + d * ey
        mx, my = np.bincount(group, x, n) / cnt, np.bincount(group, y, n) / cnt
        u, v = x - mx[group], y - my[group]
        alpha = 0.5 * np.arctan2(2.0 * np.bincount(group, u * v, n),
                                 np.bincount(group, u * u - v * v, n))
        nx, ny = -np.sin(alpha)[group], np.cos(alpha)[group]
        across = nx * ex + ny * ey
        t = (nx * (mx[group] - ox) + ny * (my[group] - oy)) / np.where(across == 0, 1.0, across)
        th = np.arccos(np.minimum(np.abs(across), 1.0))
        meets = (across != 0) & (t > 0) & (th <= cal.max_incidence_rad)
        la, b = cal.log_ab(np.minimum(th, cal.max_incidence_rad))
        d = np.exp(la + b * log_s)
    z = (d - t) / noise
    return np.where(meets, np.minimum(z * z, ARC_MISS), ARC_MISS)


def _one_line_explains(points: Points, at: np.ndarray, counts: np.ndarray, cal: Calibration,
                       d0: np.ndarray, group: np.ndarray, asked: np.ndarray) -> np.ndarray:
    """Per group (``asked.size``,) of readings ``at`` (flat indices, θ = 0 distances ``d0``,
    groups ``group``): whether one line fits the ``asked`` groups' readings as noise alone
    would (:func:`_one_line_misfit`'s χ² within ``ROUND_RETRY_Z`` of its σ above its count);
    read from the counts, without the range profiles."""
    pick = asked[group]
    s = np.asarray(counts, dtype=float).reshape(-1)[at[pick]]
    lite = SimpleNamespace(ox=points.origin_x.reshape(-1)[at[pick]],
                           oy=points.origin_y.reshape(-1)[at[pick]],
                           heading=points.heading.reshape(-1)[at[pick]], s=s, d0=d0[pick],
                           sig_s=cal.sigma_counts() / s)
    n = int(np.count_nonzero(asked))
    g = (np.cumsum(asked) - 1)[group[pick]]
    cost = np.bincount(g, _one_line_misfit(lite, np.arange(s.size), g, n, cal), n)
    n_in = np.bincount(g, minlength=n)
    out = np.zeros(asked.size, dtype=bool)
    out[asked] = cost <= n_in + ROUND_RETRY_Z * np.sqrt(2.0 * n_in)
    return out


def _pieces_misfit(pr: _Profile, pos: np.ndarray, lab: np.ndarray, alpha: np.ndarray,
                   cx: np.ndarray, cy: np.ndarray, cal: Calibration) -> np.ndarray:
    """Each reading's misfit (as :func:`_arc_misfit` scores it) on the line it is a member
    of (``lab`` ≥ 0; lines by direction ``alpha`` and centroid ``cx``, ``cy``), read at the
    θ its beam meets that line with; ``ARC_MISS`` for a reading on no line."""
    on = lab >= 0
    li = np.maximum(lab, 0)
    h = pr.heading[pos]
    ex, ey = np.cos(h), np.sin(h)
    nx, ny = -np.sin(alpha[li]), np.cos(alpha[li])
    across = nx * ex + ny * ey
    t = ((nx * (cx[li] - pr.ox[pos]) + ny * (cy[li] - pr.oy[pos]))
         / np.where(across == 0, 1.0, across))
    th = np.arccos(np.minimum(np.abs(across), 1.0))
    meets = on & (across != 0) & (t > 0) & (th <= cal.max_incidence_rad)
    la, b = cal.log_ab(np.minimum(th, cal.max_incidence_rad))
    d = np.exp(la + b * np.log(pr.s[pos]))
    _, b0 = cal._ab0
    z = (d - t) / range_sigma(b0, pr.d0[pos], pr.sig_s[pos])
    return np.where(meets, np.minimum(z * z, ARC_MISS), ARC_MISS)


def round_runs(points: Points, label: np.ndarray, index: np.ndarray, counts: np.ndarray,
               steps: np.ndarray, cal: Calibration, line_alpha: np.ndarray,
               line_cx: np.ndarray, line_cy: np.ndarray, profiler: Callable | None = None,
               snap: bool = False, own_cap_m: float = math.inf) -> tuple[Points, np.ndarray]:
    """A sensor's run of readings that the line model cut into pieces (several lines, or
    lines and readings on no line) re-read as one circle's arc where one fits, and the
    sweep's other runs on such a circle with it; numpy, shared by both estimators.

    A run: valid readings of one sensor, steps at most ``ARC_GAP_STEPS`` apart and θ = 0
    ranges within ``ROUND_JUMP_M``. One of at least ``ROUND_RUN_MIN`` readings holding two
    labels or more, whose end points bulge towards the sensor (``ROUND_BULGE_M``,
    ``ROUND_BEHIND``: not a wall, not a concave corner; a run hollow as estimated is asked
    again at θ = 0 unless one line fits it within noise, ``ROUND_RETRY_Z``) and whose θ = 0
    end points' circle is no smaller than the smallest of ``ROUND_RADII_M`` (not a post, not
    a box's corner), is tried by :func:`arc_incidence` (radii ``ROUND_RADII_M``); its arc is
    kept where it misfits at most ``ROUND_BETTER`` of one line through the run and, by BIC,
    no more than the pieces do, the run's readings on no line counted against them
    (:func:`_round_wins`). Any other run of ``ARC_MIN`` readings or more then tries the kept
    circles (a sensor that saw one flank only: no apex of its own) and keeps the one it fits
    best where it fits within ``ARC_MISFIT`` (the circle's evidence is another sensor's: its
    own pieces, each a chord read at its θ, fit themselves as well). Each reading taken
    (its own misfit at most ``ARC_ON``) leaves its line (label −1) at the arc's θ, d and σ
    (noise at θ plus d over θ ± ``ARC_DOUBT_RAD``). ``line_alpha``, ``line_cx``,
    ``line_cy``: the lines' directions and centroids. With ``snap`` the readings taken are
    then put on their circle (:func:`onto_circles`; ``own_cap_m`` as for
    :func:`snap_to_lines`). Returns the points and ``label``. Why: docs/estimator.md,
    "Large round things"."""
    flat_valid = points.valid.reshape(-1)
    vi = index[flat_valid[index]]
    if vi.size < ROUND_RUN_MIN:
        return points, label
    n_sensors = points.valid.shape[1]
    lab = label.reshape(-1)[vi]
    sensor = vi % n_sensors
    step = np.asarray(steps).reshape(-1)[vi // n_sensors]
    # ranges at θ = 0: a line's θ, wrong where it cuts an arc, makes jumps of its own
    la0, b0 = cal._ab0
    d0 = np.exp(la0 + b0 * np.log(np.asarray(counts, dtype=float).reshape(-1)[vi]))
    cut = np.ones(vi.size, dtype=bool)
    cut[1:] = ((sensor[1:] != sensor[:-1]) | (np.abs(step[1:] - step[:-1]) > ARC_GAP_STEPS)
               | (np.abs(d0[1:] - d0[:-1]) > ROUND_JUMP_M))
    run = np.cumsum(cut) - 1
    n_run = int(run[-1]) + 1
    size = np.bincount(run, minlength=n_run)
    change = np.zeros(vi.size)
    change[1:] = ~cut[1:] & (lab[1:] != lab[:-1])
    cand = (size >= ROUND_RUN_MIN) & (np.bincount(run, change, n_run) > 0)
    if not cand.any():
        return points, label
    sel = cand[run].nonzero()[0]
    gi = (np.cumsum(cand) - 1)[run[sel]]
    n_c = int(np.count_nonzero(cand))
    # the run's end points bulge towards the sensor off the chord between its ends, nowhere
    # fall behind it (a concave corner), and not by noise alone (a wall cut in two); where
    # they fall behind it as estimated, their θ = 0 end points are asked: a line read too
    # steep across an arc pulls its members in and makes the arc look hollow
    # (docs/estimator.md, "A table's flank taken for a line")
    at = vi[sel]
    hh = points.heading.reshape(-1)[at]
    ox, oy = points.origin_x.reshape(-1)[at], points.origin_y.reshape(-1)[at]
    px, py = ox + d0[sel] * np.cos(hh), oy + d0[sel] * np.sin(hh)
    keep, toward = _bulging(points.x.reshape(-1)[at], points.y.reshape(-1)[at], ox, oy, gi,
                            n_c)
    retried = (np.bincount(gi, toward < -ROUND_BULGE_M, n_c)
               > ROUND_BEHIND * np.bincount(gi, minlength=n_c))
    if retried.any():
        retried &= _bulging(px, py, ox, oy, gi, n_c)[0]
        keep = keep | retried
    if not keep.any():
        return points, label
    # … and their circle at θ = 0 is a round thing's, not a post's or a box's corner (θ = 0
    # reads an arc's flanks long: that circle is smooth, if smaller than the arc's)
    keep &= _kasa_radii(px, py, gi, n_c) >= ROUND_RADII_M[0]
    if not keep.any():
        return points, label
    retried &= keep
    if retried.any():
        # a run hollow as estimated that one line explains within noise is a wall's (its
        # noise fell behind the chord), not an arc: no circle is tried on it
        keep &= ~_one_line_explains(points, at, counts, cal, d0[sel], gi, retried)
        if not keep.any():
            return points, label
    pos = sel[keep[gi]]
    pr = (profiler or profiles_compiled)(points, vi, np.zeros(0, dtype=np.intp), counts,
                                         steps, cal)
    th, dist, sig, good, arc_mis, circle = arc_incidence(pr, pos, cal, ROUND_RADII_M)
    if not good.any():
        return points, label
    gk = (np.cumsum(keep) - 1)[gi[keep[gi]]]
    n_k = int(np.count_nonzero(keep))
    # the simpler model wins where it explains the run as well: one line through it
    line_cost = np.bincount(gk, _one_line_misfit(pr, pos, gk, n_k, cal), n_k)
    wins = ((np.bincount(gk, arc_mis, n_k) <= ROUND_BETTER * line_cost)
            & _round_wins(pr, pos, lab[pos], gk, n_k, arc_mis, 3, line_alpha, line_cx,
                          line_cy, cal))
    good &= wins[gk]
    if not good.any():
        return points, label
    # the other runs on a kept circle: one per run kept, the readings on it taken
    taken = np.zeros(vi.size, dtype=bool)
    taken[pos[good]] = True
    kept = good.nonzero()[0]
    kept_groups, first_of = np.unique(gk[kept], return_index=True)
    circ = circle[:, kept[first_of]]
    cid = np.searchsorted(kept_groups, gk)      # each good reading's circle in circ
    left = np.bincount(run, ~taken, n_run)
    other = left >= ARC_MIN
    if other.any():
        o_pos = (other[run] & ~taken).nonzero()[0]
        o_run = (np.cumsum(other) - 1)[run[o_pos]]
        n_o = int(np.count_nonzero(other))
        th_o, d_o, sig_o, mis_o, c_o = _on_circles(pr, o_pos, o_run, n_o, circ, cal)
        n_in = np.bincount(o_run, minlength=n_o)
        fits = np.bincount(o_run, mis_o, n_o) <= ARC_MISFIT * n_in
        on = fits[o_run] & (mis_o <= ARC_ON) & np.isfinite(d_o) & (d_o >= cal.min_range_m)
        pos = np.concatenate([pos[good], o_pos[on]])
        th, dist, sig, cid = (np.concatenate([v[good], w[on]])
                              for v, w in ((th, th_o), (dist, d_o), (sig, sig_o),
                                           (cid, c_o)))
    else:
        pos, th, dist, sig, cid = pos[good], th[good], dist[good], sig[good], cid[good]
    at = vi[pos]
    label = label.copy()
    label.reshape(-1)[at] = -1
    points = placed_at(points, at, dist, th, sig)
    if snap:
        points = onto_circles(points, at, cid, circ, cal.min_range_m, own_cap_m)
    return points, label


BOW_MIN = 10            # a line of at least this many valid members is asked for a bow …
BOW_PRE_F = 10.0        # … where its members as they lie bow by this F already (cheap) …
BOW_PRE_TOL = 1e-6      # (the compiled pre-gate's F, within this × (1 + Σw·n²/den) of numpy's)
BOW_ITERATIONS = 8      # … then read on a parabola by Table II's iteration (at most this
BOW_SETTLED_RAD = math.radians(0.2)  # many steps, settled to this) and kept where the
BOW_F = 25.0            # parabola beats the line by this F (1, n − 3), …
BOW_TURN_RAD = math.radians(3)   # … turns at least this much across the members …
BOW_RADIUS_M = (0.5, 4.0)        # … at a radius within these (tighter: round_runs')
BOW_POOL_M = 0.02       # a circle holds the bowed lines whose members lie this near it on average
BOW_CIRCLES = 3         # at most this many circles a sweep
BOW_JOIN_MIN = 5        # a line of at least this many valid members takes a circle …
BOW_MISFIT = ARC_MISFIT  # … that its members, read at the circle's θ, misfit this little
BOW_WORSE = 1.0         # … and at most this much more than their own line (σ²); the
BOW_REFITS = 1          # circles refitted to the lines they took this often at most
BOW_DOUBT_RAD = math.radians(3)  # a reading on a circle: σ includes d over θ ± this


def _bow_fit(g: np.ndarray, n_g: int, s: np.ndarray, nn: np.ndarray, w: np.ndarray
             ) -> np.ndarray:
    """Weighted least-squares parabola nn = a + b·s + c·s² per group: (n_g, 3)."""
    pw, r = np.empty((5, n_g)), np.empty((n_g, 3, 1))
    wk = w
    for k in range(5):
        pw[k] = np.bincount(g, wk, n_g)
        if k < 3:
            r[:, k, 0] = np.bincount(g, wk * nn, n_g)
        wk = wk * s
    m = pw[np.add.outer(np.arange(3), np.arange(3))].transpose(2, 0, 1)
    m[:, [0, 1, 2], [0, 1, 2]] += 1e-12
    try:
        return np.linalg.solve(m, r)[..., 0]
    except np.linalg.LinAlgError:   # a group whose members share one spot along the line
        return (np.linalg.pinv(m) @ r)[..., 0]


BOW_KINK_SHARE = 0.5   # two straight pieces leave this share of a parabola's misfit or less:
#                        a corner, not a curve (an arc's two chords fit no better than it) …
BOW_KINK_RAD = math.radians(20)   # … where the two pieces turn by this much


def _line_rss(W, S, Y, SS, SY, YY):
    """Weighted least-squares misfit of a line y = a + b·s from the sums of w, w·s, w·y,
    w·s², w·s·y and w·y² (arrays: one per candidate split)."""
    W = np.maximum(W, 1e-300)
    vs = SS - S * S / W
    cov = SY - S * Y / W
    return np.maximum(YY - Y * Y / W - cov * cov / np.maximum(vs, 1e-300), 0.0)


def _kinked(g: np.ndarray, n_g: int, s: np.ndarray, nn: np.ndarray, w: np.ndarray,
            chi_par: np.ndarray, ask: np.ndarray) -> np.ndarray:
    """(n_g,) bool: groups ``ask`` whose members (``s`` along, ``nn`` across, weights ``w``)
    two straight pieces split at one place along ``s`` (at least 3 members each) fit better
    than a parabola through them: at most ``BOW_KINK_SHARE`` of its weighted misfit
    ``chi_par``."""
    out = np.zeros(n_g, dtype=bool)
    for k in np.flatnonzero(ask):      # (a few bowed lines a sweep)
        on = g == k
        order = np.argsort(s[on], kind="stable")
        ss, yy, ww = s[on][order], nn[on][order], w[on][order]
        n = ss.size
        if n < 8:
            continue
        m = [np.cumsum(np.concatenate(([0.0], q))) for q in
             (ww, ww * ss, ww * yy, ww * ss * ss, ww * ss * yy, ww * yy * yy)]
        tot = [q[-1] for q in m]

        cut = np.arange(3, n - 2)
        lm = [q[cut] for q in m]
        rm = [t - q[cut] for t, q in zip(tot, m)]
        both = _line_rss(*lm) + _line_rss(*rm)
        at = int(np.argmin(both))
        if both[at] > BOW_KINK_SHARE * chi_par[k]:
            continue
        # ... turning at least BOW_KINK_RAD there (a polygonal arc's facets turn less)
        slope = [(q[4][at] - q[1][at] * q[2][at] / max(q[0][at], 1e-300))
                 / max(q[3][at] - q[1][at] ** 2 / max(q[0][at], 1e-300), 1e-300)
                 for q in (lm, rm)]
        out[k] = abs(math.atan(slope[0]) - math.atan(slope[1])) >= BOW_KINK_RAD
    return out


KINK_MIN = 20           # a line over a corner: a line of at least this many valid members …
KINK_SIDE = 4           # … each piece holds at least this many …
KINK_PRE_F = 10.0       # … two pieces beat the line by this F as its members lie (cheap) …
KINK_ITERATIONS = 8     # … then each piece is read by Table II's iteration (at most this
#                         many steps, settled to BOW_SETTLED_RAD) …
KINK_MISFIT = 1.0       # … where the line misfits its members by this χ² a member or more …
KINK_F = 10.0           # … the two pieces, so read, beat it by this F …
KINK_TURN_RAD = BOW_KINK_RAD   # … turn by this much …
KINK_MEET_M = 0.1       # … and meet within this of both pieces' members


def kinked_lines(points: Points, label: np.ndarray, counts: np.ndarray, cal: Calibration
                 ) -> tuple[Points, np.ndarray]:
    """Where a part is read to its own range: a line of ≥ ``KINK_MIN`` valid members over a
    corner (two walls, or a wall and a box face, fitted as one) split at its best place along
    it and each piece read by Table II's iteration, kept where the pieces beat the line
    (``KINK_PRE_F`` as the members lie, ``KINK_MISFIT``, ``KINK_F`` as re-read), turn by
    ``KINK_TURN_RAD``, meet within ``KINK_MEET_M`` of both and no member reaches the drop-out
    angle. Returns the points (a kept piece's members at their θ, σ their noise) and a label
    (S, N) giving one piece of each kept line a new number, for the snap (the grouping keeps
    ``label``). Numpy, shared by both estimators. Why and the rule in full:
    docs/estimator.md, "A line over a corner"."""
    if not read_to_own_range(cal, points.max_range_m):
        return points, label
    asked = _bow_asked(points, label, counts, cal)
    if asked is None:
        return points, label
    (idx, g, n_g, nm, ox, oy, ex, ey, s_c, sig_s, d_line, en, noise, w, ux, uy, cx, cy, s0,
     n0, _, _) = asked
    # every split of every line at once: prefix sums of the weighted moments in s order
    o = np.lexsort((s0, g))
    gs, ss, yy, ww = g[o], s0[o], n0[o], w[o]
    sums = [np.concatenate(([0.0], np.cumsum(q))) for q in
            (ww, ww * ss, ww * yy, ww * ss * ss, ww * ss * yy, ww * yy * yy)]
    start = np.searchsorted(gs, np.arange(n_g))
    end = start + nm.astype(np.intp)
    j = np.arange(gs.size)
    left = [q[j] - q[start[gs]] for q in sums]
    right = [q[end[gs]] - q[j] for q in sums]
    both = _line_rss(*left) + _line_rss(*right)
    pos = j - start[gs]
    both[(pos < KINK_SIDE) | (nm[gs] - pos < KINK_SIDE)] = np.inf
    one = _line_rss(*[q[end] - q[start] for q in sums])
    # (every line asked has BOW_MIN members: a split of KINK_SIDE a side; else the line)
    best = np.minimum(np.minimum.reduceat(both, start), one)
    f_pre = (one - best) / np.maximum(best / np.maximum(nm - 4, 1), 1e-12)
    # the line against its members: their distances against where their beams meet it
    den = ex * -uy + ey * ux
    t_line = (((cx[g] - ox) * -uy + (cy[g] - oy) * ux)
              / np.where(np.abs(den) > 1e-9, den, 1e-9))
    chi1 = np.bincount(g, ((d_line - t_line) / noise) ** 2, n_g)
    ask = (nm >= KINK_MIN) & (f_pre >= KINK_PRE_F) & (chi1 >= KINK_MISFIT * nm)
    if not ask.any():
        return points, label
    # the asked lines' members, each line cut at its best split: pieces 2c and 2c + 1
    first = np.minimum.reduceat(np.where(both == best[gs], j, gs.size), start)
    keep = ask[gs]
    mem, gk = o[keep], gs[keep]
    cand = (np.cumsum(ask) - 1)[gk]
    n_c = int(np.count_nonzero(ask))
    piece = 2 * cand + (j[keep] >= first[gk])
    n_p = 2 * n_c
    npc = np.bincount(piece, minlength=n_p).astype(float)
    mex, mey, mox, moy = ex[mem], ey[mem], ox[mem], oy[mem]
    log_s = np.log(s_c[mem])

    def tls(d):
        """Each piece's TLS line through its members at ``d``: centre, unit normal."""
        x, y = mox + d * mex, moy + d * mey
        px, py = np.bincount(piece, x, n_p) / npc, np.bincount(piece, y, n_p) / npc
        u, v = x - px[piece], y - py[piece]
        al = 0.5 * np.arctan2(2.0 * np.bincount(piece, u * v, n_p),
                              np.bincount(piece, u * u - v * v, n_p))
        return x, y, px, py, -np.sin(al), np.cos(al)

    # Table II's iteration, each piece its own line
    d, th = d_line[mem], None
    settled = np.zeros(n_c, dtype=bool)
    for _ in range(KINK_ITERATIONS):
        _, _, _, _, nx, ny = tls(d)
        th_new = np.arccos(np.clip(np.abs(mex * nx[piece] + mey * ny[piece]), 0.0, 1.0))
        if th is not None:
            settled = np.bincount(cand, np.abs(th_new - th) > BOW_SETTLED_RAD, n_c) == 0
        th = th_new
        la, b = cal.log_ab(th)
        d = np.exp(la + b * log_s)
        if settled.all():
            break
    sig = range_sigma(b, d, sig_s[mem])
    x, y, px, py, nx, ny = tls(d)
    den = mex * nx[piece] + mey * ny[piece]
    t = (((px[piece] - mox) * nx[piece] + (py[piece] - moy) * ny[piece])
         / np.where(np.abs(den) > 1e-9, den, 1e-9))
    chi2 = np.bincount(cand, ((d - t) / sig) ** 2, n_c)
    nmc = nm[ask]
    f = (chi1[ask] - chi2) / np.maximum(chi2 / np.maximum(nmc - 4, 1), 1e-12)
    # the two pieces' lines: how they turn and where they cross
    na, nb = np.arange(0, n_p, 2), np.arange(1, n_p, 2)
    sin = nx[na] * ny[nb] - ny[na] * nx[nb]
    ca, cb = nx[na] * px[na] + ny[na] * py[na], nx[nb] * px[nb] + ny[nb] * py[nb]
    s_ = np.where(np.abs(sin) > 1e-12, sin, 1e-12)
    kx, ky = (ca * ny[nb] - cb * ny[na]) / s_, (nx[na] * cb - nx[nb] * ca) / s_
    gap = np.full(n_p, np.inf)
    np.minimum.at(gap, piece, np.hypot(x - kx[cand], y - ky[cand]))
    past = np.bincount(cand, th >= cal.max_incidence_rad, n_c) > 0
    split_ok = (settled & ~past & (f >= KINK_F)
                & (np.arcsin(np.minimum(np.abs(sin), 1.0)) >= KINK_TURN_RAD)
                & (np.maximum(gap[na], gap[nb]) <= KINK_MEET_M))
    if not split_ok.any():
        return points, label
    take = split_ok[cand]
    at = idx[mem[take]]
    split = label.copy()
    second = take & (piece % 2 == 1)
    split.reshape(-1)[idx[mem[second]]] = label.max() + 1 + cand[second]
    return placed_at(points, at, d[take], th[take], sig[take]), split


def _kasa_circle(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The least-squares (Kåsa) circle through points: centre x, y and radius."""
    mx, my = x.mean(), y.mean()
    u, v = x - mx, y - my
    w = u * u + v * v
    suu, svv, suv = (u * u).sum(), (v * v).sum(), (u * v).sum()
    suw, svw = (u * w).sum(), (v * w).sum()
    det = suu * svv - suv * suv
    det = det if abs(det) > 1e-18 else 1e-18
    a = 0.5 * (suw * svv - svw * suv) / det
    b = 0.5 * (svw * suu - suw * suv) / det
    return np.array([mx + a, my + b, math.sqrt(a * a + b * b + (suu + svv) / x.size)])


def _bow_circles(x: np.ndarray, y: np.ndarray, g: np.ndarray, n_g: int, good: np.ndarray,
                 strength: np.ndarray) -> np.ndarray:
    """Circles (3, C: centre x, y, radius) through the groups ``good`` (members ``x``, ``y``
    of group ``g``): one fitted to them all, refitted to those whose members lie on it within
    ``BOW_POOL_M`` on average until that holds, then the rest likewise (from the strongest
    (``strength``) where none lies on the circle of all), at most ``BOW_CIRCLES``."""
    nm = np.maximum(np.bincount(g, minlength=n_g), 1)
    left = good.copy()
    circles = []
    while left.any() and len(circles) < BOW_CIRCLES:
        agree = left & False
        for use in (left, np.arange(n_g) == np.flatnonzero(left)[np.argmax(strength[left])]):
            for _ in range(4):
                on = use[g]
                c = _kasa_circle(x[on], y[on])
                res = np.abs(np.hypot(x - c[0], y - c[1]) - c[2])
                agree = left & (np.bincount(g, res, n_g) / nm <= BOW_POOL_M)
                if not agree.any() or np.array_equal(agree, use):
                    break
                use = agree
            if agree.any():
                break
        if not agree.any():
            break
        circles.append(c)
        left &= ~agree
    return np.stack(circles, axis=1) if circles else np.zeros((3, 0))


def bowed_lines(points: Points, label: np.ndarray, counts: np.ndarray, cal: Calibration
                ) -> tuple[Points, np.ndarray]:
    """Line members on a curved wall (a polygonal arc, a round room's many sides) read at
    the incidence their beams meet its circle; numpy, shared by both estimators.

    A line of at least ``BOW_MIN`` valid members is one chord of such a wall: each member
    took the chord's θ, wrong by as much as the wall turns along it. Where its members bow
    (``BOW_PRE_F``), they are read on a parabola in the line's frame by Table II's
    iteration (fit, re-read each at the incidence its beam meets the curve, until θ
    settles); the line is bowed where the parabola then beats it by ``BOW_F`` (F test
    against the parabola's own scatter) and turns by ``BOW_TURN_RAD`` or more at a radius
    within ``BOW_RADIUS_M``. The bowed lines' members make up to ``BOW_CIRCLES`` circles
    (:func:`_bow_circles`), and every line of ``BOW_JOIN_MIN`` valid members or more takes
    the circle its members, read at the θ their beams meet it with, misfit least where that
    is within ``BOW_MISFIT`` on average (σ², each at most ``ARC_MISS``) and at most
    ``BOW_WORSE`` more than their own line (a short line read far along the same wall fits
    its chord as well: the circle's evidence is the long lines'; an ellipse's lines lie off a
    circle fitted elsewhere on it); each circle is refitted to the lines it took and asked
    again, ``BOW_REFITS`` times. A taken line's members whose beams miss the circle are
    INCIDENCE_UNKNOWN (their θ was the line's). The others leave their line (label −1) at
    that θ and are put where their beams meet the circle as :func:`snap_to_lines` puts a
    member on its line (in from behind always, out by at most ``SNAP_SIGMAS`` σ, within the
    range; σ the circle's there plus ``SNAP_OWN`` of their own: their noise and d over
    θ ± ``BOW_DOUBT_RAD``). Returns the points and ``label``. Why: docs/estimator.md,
    "Curved walls"."""
    asked = _bow_asked(points, label, counts, cal)
    if asked is None or not (pre := asked[-1] >= BOW_PRE_F).any():
        return points, label
    (idx, g, n_g, nm, ox, oy, ex, ey, s_c, sig_s, d_line, en, noise, w, ux, uy, cx, cy, s0,
     n0, chi0, _) = asked
    sel = pre[g]
    s0_k, n0_k, chi0_k = s0[sel], n0[sel], chi0[pre]   # (as they lie: the corner test's)
    idx, ox, oy, ex, ey, s_c, sig_s, d_line, en, noise, w, ux, uy = (
        a[sel] for a in (idx, ox, oy, ex, ey, s_c, sig_s, d_line, en, noise, w, ux, uy))
    cx, cy = cx[pre], cy[pre]
    g = (np.cumsum(pre) - 1)[g[sel]]
    n_g = int(np.count_nonzero(pre))
    nm = nm[pre]
    es = ex * ux + ey * uy
    so = (ox - cx[g]) * ux + (oy - cy[g]) * uy
    no = -(ox - cx[g]) * uy + (oy - cy[g]) * ux
    log_s = np.log(s_c)

    def meet(coef, t):
        """Where each beam meets its line's parabola (Newton from t), the incidence there
        and the curve's slope."""
        a, b, c = coef[g, 0], coef[g, 1], coef[g, 2]
        for _ in range(4):
            ss = so + t * es
            f = no + t * en - (a + (b + c * ss) * ss)
            fp = en - (b + 2.0 * c * ss) * es
            t = t - f / np.where(np.abs(fp) > 1e-9, fp, 1e-9)
        m = b + 2.0 * c * (so + t * es)
        cos = np.abs(en - m * es) / np.sqrt(1.0 + m * m)
        return t, np.arccos(np.clip(cos, 0.0, 1.0)), m

    # the line: its members against it (the held iterations' fixed point)
    t, _, _ = meet(np.zeros((n_g, 3)), d_line)
    z = (d_line - t) / noise
    chi_line = np.bincount(g, z * z, n_g)
    # the parabola: Table II's iteration with the curve in place of the line
    d, th = d_line, None
    settled = np.zeros(n_g, dtype=bool)
    for _ in range(BOW_ITERATIONS):
        coef = _bow_fit(g, n_g, so + d * es, no + d * en, w)
        _, th_new, _ = meet(coef, d)
        th_new = np.minimum(th_new, cal.max_incidence_rad)
        settled = (np.bincount(g, np.abs(th_new - th) > BOW_SETTLED_RAD, n_g) == 0
                   if th is not None else settled)
        th = th_new
        la, b = cal.log_ab(th)
        d = np.exp(la + b * log_s)
        if settled.all():
            break
    coef = _bow_fit(g, n_g, so + d * es, no + d * en, w)
    t, _, m = meet(coef, d)
    z = (d - t) / range_sigma(b, d, sig_s)
    chi_par = np.bincount(g, z * z, n_g)
    ang = np.arctan(m)
    lo, hi = np.full(n_g, np.inf), np.full(n_g, -np.inf)
    np.minimum.at(lo, g, ang)
    np.maximum.at(hi, g, ang)
    radius = 1.0 / np.maximum(np.abs(2.0 * coef[:, 2]), 1e-12)
    F = (chi_line - chi_par) / np.maximum(chi_par / np.maximum(nm - 3, 1), 1.0)
    good = (settled & (F >= BOW_F) & (hi - lo >= BOW_TURN_RAD) & (radius >= BOW_RADIUS_M[0])
            & (radius <= BOW_RADIUS_M[1])
            & (np.bincount(g, ~(np.isfinite(t) & (t > 0)), n_g) == 0))
    # a line over a corner bows too: two straight pieces that fit its members clearly
    # better than the parabola make it a corner, not a curve
    good &= ~_kinked(g, n_g, s0_k, n0_k, w, chi0_k, good)
    if not good.any():
        return points, label
    circ = _bow_circles(ox + d * ex, oy + d * ey, g, n_g, good, F)
    if circ.shape[1] == 0:
        return points, label
    return _onto_bow_circles(points, label, counts, cal, circ)


def bowed_lines_compiled(points: Points, label: np.ndarray, counts: np.ndarray,
                         cal: Calibration) -> tuple[Points, np.ndarray]:
    """:func:`bowed_lines`, whose pre-gate (:func:`_bow_asked`: do a line's members as they
    lie bow?) is first asked of one compiled call (``irring.estimation._lines.bow_pre_f``,
    held to it by tests/test_curved_walls.py): where its F, widened by ``BOW_PRE_TOL``,
    passes no line, neither would numpy's and nothing bows (most sweeps)."""
    f = np.ascontiguousarray
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        F, scale = _lines.bow_pre_f(
            f(label, dtype=np.intp).reshape(-1),
            f(points.valid, dtype=bool).reshape(-1).view(np.uint8),
            f(points.origin_x, dtype=float).reshape(-1),
            f(points.origin_y, dtype=float).reshape(-1),
            f(points.heading, dtype=float).reshape(-1), f(counts, dtype=float).reshape(-1),
            f(points.d, dtype=float).reshape(-1), f(points.theta, dtype=float).reshape(-1),
            cal.sigma_counts(), SIGMA_FLOOR_M, f(cal.theta_rad, dtype=float),
            f(cal._log_a, dtype=float), f(cal.b, dtype=float), BOW_MIN)
    if not (F + BOW_PRE_TOL * (1.0 + scale) >= BOW_PRE_F).any():
        return points, label
    return bowed_lines(points, label, counts, cal)


def _bow_asked(points: Points, label: np.ndarray, counts: np.ndarray, cal: Calibration):
    """:func:`bowed_lines`' pre-gate: None where no line has ``BOW_MIN`` valid members;
    else per member of those lines (flat index ``idx``, line ``g``) its beam, where it lies
    in its line's frame (the TLS line of its members: centre (cx, cy), direction (ux, uy);
    s0 along, n0 across) and its weight ``w``, and per line the χ² ``chi0`` of a weighted
    parabola through its members as they lie and the F (the last item) by which it beats
    that line."""
    flat = label.reshape(-1)
    valid = points.valid.reshape(-1)
    idx = ((flat >= 0) & valid).nonzero()[0]
    if idx.size < BOW_MIN:
        return None
    lab = flat[idx]
    ask = np.bincount(lab) >= BOW_MIN
    if not ask.any():
        return None
    sel = ask[lab]
    idx = idx[sel]
    g = (np.cumsum(ask) - 1)[lab[sel]]
    n_g = int(np.count_nonzero(ask))
    nm = np.bincount(g, minlength=n_g).astype(float)
    ox, oy = points.origin_x.reshape(-1)[idx], points.origin_y.reshape(-1)[idx]
    h = points.heading.reshape(-1)[idx]
    ex, ey = np.cos(h), np.sin(h)
    s_c = np.asarray(counts, dtype=float).reshape(-1)[idx]
    d_line = points.d.reshape(-1)[idx]
    x, y = ox + d_line * ex, oy + d_line * ey
    # each line's frame: its members' TLS line; s along it, n across
    cx, cy = np.bincount(g, x, n_g) / nm, np.bincount(g, y, n_g) / nm
    u, v = x - cx[g], y - cy[g]
    al = 0.5 * np.arctan2(2.0 * np.bincount(g, u * v, n_g), np.bincount(g, u * u - v * v, n_g))
    ux, uy = np.cos(al)[g], np.sin(al)[g]
    en = -ex * uy + ey * ux
    sig_s = cal.sigma_counts() / s_c
    noise = range_sigma(cal.log_ab(points.theta.reshape(-1)[idx])[1], d_line, sig_s)
    w = 1.0 / np.maximum(noise * np.abs(en), SIGMA_FLOOR_M) ** 2
    # asked further only where the members as they lie already bow (one fit)
    s0, n0 = u * ux + v * uy, -u * uy + v * ux
    c0 = _bow_fit(g, n_g, s0, n0, w)
    r0 = n0 - (c0[g, 0] + (c0[g, 1] + c0[g, 2] * s0) * s0)
    chi0 = np.bincount(g, w * r0 * r0, n_g)
    F = ((np.bincount(g, w * n0 * n0, n_g) - chi0)
         / np.maximum(chi0 / np.maximum(nm - 3, 1), 1.0))
    return (idx, g, n_g, nm, ox, oy, ex, ey, s_c, sig_s, d_line, en, noise, w, ux, uy, cx, cy,
            s0, n0, chi0, F)


def _onto_bow_circles(points: Points, label: np.ndarray, counts: np.ndarray,
                      cal: Calibration, circ: np.ndarray) -> tuple[Points, np.ndarray]:
    """:func:`bowed_lines`' second half: every line of ``BOW_JOIN_MIN`` valid members or more
    read on the circle ``circ`` (3, C) it fits best, where it fits, and put on it."""
    flat = label.reshape(-1)
    idx = ((flat >= 0) & points.valid.reshape(-1)).nonzero()[0]
    g = np.unique(flat[idx], return_inverse=True)[1]
    n_g = int(g.max()) + 1
    nm = np.bincount(g, minlength=n_g)
    ox, oy = points.origin_x.reshape(-1)[idx], points.origin_y.reshape(-1)[idx]
    h = points.heading.reshape(-1)[idx]
    ex, ey = np.cos(h), np.sin(h)
    s_c = np.asarray(counts, dtype=float).reshape(-1)[idx]
    sig_s = cal.sigma_counts() / s_c
    # each line's own misfit: its members against their TLS line where they lie
    d_now = points.d.reshape(-1)[idx]
    x, y = ox + d_now * ex, oy + d_now * ey
    nm_f = np.maximum(nm, 1)
    mx, my = np.bincount(g, x, n_g) / nm_f, np.bincount(g, y, n_g) / nm_f
    u, v = x - mx[g], y - my[g]
    al = 0.5 * np.arctan2(2.0 * np.bincount(g, u * v, n_g), np.bincount(g, u * u - v * v, n_g))
    nx, ny = -np.sin(al)[g], np.cos(al)[g]
    cos_b = ex * nx + ey * ny
    t_line = ((mx[g] - ox) * nx + (my[g] - oy) * ny) / np.where(np.abs(cos_b) > 1e-9, cos_b,
                                                                1e-9)
    _, b_now = cal.log_ab(points.theta.reshape(-1)[idx])
    z_line = (d_now - t_line) / range_sigma(b_now, d_now, sig_s)
    own = np.bincount(g, np.minimum(z_line * z_line, ARC_MISS), n_g) / nm_f
    log_s = np.log(s_c)
    cols = np.arange(n_g)
    fits = np.zeros(n_g, dtype=bool)
    for _ in range(BOW_REFITS + 1):
        # each beam on each circle: ahead of it, from inside (a room's wall) or outside (a bay)
        rx, ry = circ[0][:, None] - ox, circ[1][:, None] - oy          # (C, M)
        along = rx * ex + ry * ey
        r = circ[2][:, None]
        inside = rx * rx + ry * ry < r * r
        disc = along * along - (rx * rx + ry * ry - r * r)
        root = np.sqrt(np.maximum(disc, 0.0))
        t = np.where(inside, along + root, along - root)
        th = np.arccos(np.clip(np.abs((t * ex - rx) * ex + (t * ey - ry) * ey) / r, 0.0, 1.0))
        meets = (disc > 0.0) & (t > 0.0) & (th <= cal.max_incidence_rad)
        la, b = cal.log_ab(np.minimum(th, cal.max_incidence_rad))
        dd = np.exp(la + b * log_s)
        noise = range_sigma(b, dd, sig_s)
        z = (dd - t) / noise
        mis = np.where(meets, np.minimum(z * z, ARC_MISS), ARC_MISS)
        cost = np.stack([np.bincount(g, m_, n_g) for m_ in mis]) / nm_f   # (C, L)
        best = np.argmin(cost, axis=0)
        c_best = cost[best, cols]
        # … where it fits, and no worse than its own line (an ellipse's or an irregular
        # polygon's lines lie off a circle fitted elsewhere on it; a chord fits both alike)
        now = (c_best <= BOW_MISFIT) & (c_best <= own + BOW_WORSE) & (nm >= BOW_JOIN_MIN)
        if np.array_equal(now, fits):
            break
        fits = now
        # the circles refitted to the lines they took, read at their θ
        for k in range(circ.shape[1]):
            on = (fits & (best == k))[g] & meets[k]
            if np.count_nonzero(on) >= BOW_MIN:
                circ[:, k] = _kasa_circle((ox + dd[k] * ex)[on], (oy + dd[k] * ey)[on])
    taken = fits[g]
    if not taken.any():
        return points, label
    on_circle = taken & meets[best[g], np.arange(idx.size)]
    # a taken line's members whose beams miss its circle (past the drop-out angle) keep no
    # θ: theirs came from the line, now on the circle
    gone = idx[taken & ~on_circle]
    label = label.copy()
    label.reshape(-1)[idx[taken]] = -1
    if gone.size:
        points = invalidated(points, gone, Reason.INCIDENCE_UNKNOWN)
    j = on_circle.nonzero()[0]
    if j.size == 0:
        return points, label
    c = best[g[j]]
    at = idx[j]
    th_t, d_t, s_t = th[c, j], dd[c, j], s_c[j]
    lo_d = cal.distance(s_t, np.maximum(th_t - BOW_DOUBT_RAD, 0.0))
    hi_d = cal.distance(s_t, np.minimum(th_t + BOW_DOUBT_RAD, cal.max_incidence_rad))
    sig = np.hypot(noise[c, j], 0.5 * np.abs(lo_d - hi_d))
    points = placed_at(points, at, d_t, th_t, sig)
    # onto the circle: its uncertainty there from its readings' radial scatter
    t_c = t[c, j]
    radial = np.abs(np.hypot(ox[j] + d_t * ex[j] - circ[0][c], oy[j] + d_t * ey[j] - circ[1][c])
                    - circ[2][c])
    n_on = np.maximum(np.bincount(c, minlength=circ.shape[1]), 1)
    rms = np.sqrt(np.bincount(c, radial * radial, circ.shape[1]) / n_on)
    fit = rms[c] / np.sqrt(n_on[c]) / np.maximum(np.cos(th_t), 0.1)
    on = ((t_c - d_t <= SNAP_SIGMAS * sig) & (t_c >= cal.min_range_m)
          & (t_c <= points.max_range_m))
    if on.any():
        sig_on = np.maximum(np.hypot(fit, SNAP_OWN * sig), SIGMA_FLOOR_M)
        points = placed_at(points, at[on], t_c[on], th_t[on], sig_on[on])
    return points, label

def onto_circles(points: Points, at: np.ndarray, circle: np.ndarray, circles: np.ndarray,
                 min_range_m: float, own_cap_m: float = math.inf) -> Points:
    """The flat readings ``at`` of round things (``circle``: which of ``circles`` (3, C:
    centre x, y, radius; :func:`round_runs`' kept circles) each was read on) put where their
    beams meet that circle's radius refitted to the end points of all its readings, as
    :func:`snap_to_lines` puts a line's members on their line: a circle of at least
    ``SNAP_MIN`` readings, each moved in from behind it or out by at most ``SNAP_SIGMAS`` σ,
    within [``min_range_m``, ``points.max_range_m``]; its σ becomes the circle's uncertainty
    there (its members' radial RMS over √n, along the beam) with half its own σ added (at
    most ``own_cap_m``). Why: docs/estimator.md, "Onto a round thing's circle"."""
    if at.size == 0:
        return points
    n_c = circles.shape[1]
    n = np.bincount(circle, minlength=n_c)
    x, y = points.x.reshape(-1)[at], points.y.reshape(-1)[at]
    cxm, cym = circles[0], circles[1]
    radial = np.hypot(x - cxm[circle], y - cym[circle])
    rm = np.bincount(circle, radial, n_c) / np.maximum(n, 1)
    use = n >= SNAP_MIN
    if not use[circle].any():
        return points
    resid = radial - rm[circle]
    rms = np.sqrt(np.bincount(circle, resid * resid, n_c) / np.maximum(n, 1))
    h = points.heading.reshape(-1)[at]
    ox, oy = points.origin_x.reshape(-1)[at], points.origin_y.reshape(-1)[at]
    rx, ry = cxm[circle] - ox, cym[circle] - oy
    ex, ey = np.cos(h), np.sin(h)
    along = rx * ex + ry * ey
    disc = along * along - (rx * rx + ry * ry - rm[circle] ** 2)
    t = along - np.sqrt(np.maximum(disc, 0.0))
    d = points.d.reshape(-1)[at]
    own = points.sigma_m.reshape(-1)[at]
    ok = (use[circle] & (disc > 0.0) & (along > 0.0) & (t - d <= SNAP_SIGMAS * own)
          & (t >= min_range_m) & (t <= points.max_range_m))
    if not ok.any():
        return points
    # the beam's cosine on the circle where it meets it: the fit's normal error along it
    cos = np.clip(((ox + t * ex - cxm[circle]) * -ex + (oy + t * ey - cym[circle]) * -ey)
                  / np.maximum(rm[circle], 1e-12), 1e-3, 1.0)
    fit = rms[circle] / np.sqrt(np.maximum(n[circle], 1)) / cos
    sigma = np.maximum(np.hypot(fit, np.minimum(SNAP_OWN * own, own_cap_m)), SIGMA_FLOOR_M)
    return placed_at(points, at[ok], t[ok], points.theta.reshape(-1)[at[ok]], sigma[ok])


def _round_wins(pr: _Profile, pos: np.ndarray, lab: np.ndarray, group: np.ndarray, n: int,
                arc_mis: np.ndarray, arc_params: int, line_alpha: np.ndarray,
                line_cx: np.ndarray, line_cy: np.ndarray, cal: Calibration) -> np.ndarray:
    """Per group (n,): whether its readings misfit their arc (``arc_mis``, ``arc_params``
    parameters of its own) no more than its pieces by BIC: a line member on its line, each
    distinct line worth 3 (direction, offset and where it ends; the last 2), a reading on no
    line (``lab`` < 0) at ``ROUND_UNEXPLAINED`` (the lines leave it unexplained). A box's
    convex corner seen by one sensor is two lines within noise and a circle well outside it;
    an arc whose flank one line took too steep fits the readings that line left."""
    mem = lab >= 0
    lm, gm = lab[mem], group[mem]
    piece_cost = (np.bincount(gm, _pieces_misfit(pr, pos[mem], lm, line_alpha, line_cx,
                                                 line_cy, cal), n)
                  + ROUND_UNEXPLAINED * np.bincount(group[~mem], minlength=n))
    # distinct lines (a run's readings may alternate between two of them)
    width = int(lm.max(initial=0)) + 1
    n_pieces = np.bincount(np.unique(gm * width + lm) // width, minlength=n)
    log_n = np.log(np.maximum(np.bincount(group, minlength=n), 2))
    arc_cost = np.bincount(group, arc_mis, n)
    return ((arc_cost + arc_params * log_n <= piece_cost + (3.0 * n_pieces - 1.0) * log_n)
            | (n_pieces == 0))


def _on_circles(pr: _Profile, pos: np.ndarray, group: np.ndarray, n: int,
                circles: np.ndarray, cal: Calibration):
    """Readings ``pr`` positions ``pos`` (groups ``group`` < ``n``) read on each of
    ``circles`` (3, C: centre x, y, radius); each group takes the circle it misfits least.
    Returns θ, d, σ (as :func:`arc_incidence` gives them), misfit and the circle taken, each
    per reading."""
    h = pr.heading[pos]
    ex, ey = np.cos(h), np.sin(h)
    t, th, meets = _meet_circle(circles[:2, :, None], circles[2][:, None], pr.ox[pos],
                                pr.oy[pos], ex, ey)
    meets &= th <= cal.max_incidence_rad                      # (C, J)
    s = pr.s[pos]
    log_s = np.log(s)
    la, b = cal.log_ab(th)
    d = np.exp(la + b * log_s)
    _, b0 = cal._ab0
    noise = range_sigma(b0, pr.d0[pos], pr.sig_s[pos])
    z = (d - t) / noise
    mis = np.where(meets, np.minimum(z * z, ARC_MISS), ARC_MISS)
    cost = np.stack([np.bincount(group, m, n) for m in mis])  # (C, n)
    best = np.argmin(cost, axis=0)[group]
    j = np.arange(pos.size)
    th_b, d_b, mis_b = th[best, j], d[best, j], mis[best, j]
    lo = cal.distance(s, np.maximum(th_b - ARC_DOUBT_RAD, 0.0))
    hi = cal.distance(s, np.minimum(th_b + ARC_DOUBT_RAD, cal.max_incidence_rad))
    _, b_th = cal.log_ab(th_b)
    sig = np.hypot(range_sigma(b_th, d_b, pr.sig_s[pos]),
                   0.5 * np.abs(lo - hi))
    return th_b, d_b, sig, mis_b, best


POST_RADII_M = np.geomspace(0.01, 0.07, 13)  # a far post is tried as a circle of these radii
#                                              (the largest fitting best: not a post) …
POST_LINK_M = 0.12       # … through readings on no line whose θ = 0 end points chain this near …
POST_RUN_MAX = 5         # … at most this many of one sensor (more: a surface, not a post) …
POST_SENSORS = 2         # … from at least this many sensors …
POST_JUMP_M = 0.10       # … each sensor's run flanked by silence or readings this much farther;
POST_ON_TESTED = 4       # readings on the circle where a flank is itself on no line (not 3)
POST_BEARING_RAD = 0.0025  # its centre searched on this bearing grid …
POST_RANGE_M = 0.005     # … and this range grid; a silent flanking beam it meets this far
POST_SILENT_RAD = math.radians(15)  # inside the drop-out angle (within the return range) misfits
POST_COARSE = 4          # the search: every 4th radius on a grid 4× as coarse, then fine about it


def far_posts(points: Points, label: np.ndarray, counts: np.ndarray, steps: np.ndarray,
              cal: Calibration, grouper: Callable | None = None) -> Points:
    """Readings on no line (valid, or INCIDENCE_UNKNOWN; clear returns only) that are one
    thin post seen by several sensors, read at the θ at which their beams meet one circle
    fitted to them all; numpy, shared by both estimators.

    A group: ≥ 3 readings whose θ = 0 end points chain within ``POST_LINK_M``, from
    ≥ ``POST_SENSORS`` sensors, ≤ ``POST_RUN_MAX`` of each, each sensor's run flanked by a
    silent beam or a reading ``POST_JUMP_M`` farther (one on no line itself: then
    ``POST_ON_TESTED`` readings on the circle). Its circle (radius in
    ``POST_RADII_M``, not the largest) is scored as an arc (:func:`arc_incidence`) plus
    ``ARC_MISS`` for each flanking silent beam it would have returned; kept at a mean misfit
    below ``ARC_MISFIT`` with ≥ 3 readings on it (misfit ≤ ``ARC_ON``), which become valid at
    its θ, at their own distance there, σ as on an arc. ``label`` (S, N): each reading's
    line (−1 none); ``counts`` (S, N); ``steps`` (S,); ``grouper``: the groups (the compiled
    :func:`post_groups_compiled` by default; its statement: ``estimate_numpy.post_groups``).
    Why: docs/estimator.md, "Far posts"."""
    found = (grouper or post_groups_compiled)(points, label, counts, cal)
    if found is None:        # most sweeps: no group that could be a post, nothing to fit
        return points
    row, col, comp, groups, px, py = found
    shape = points.valid.shape
    s = np.asarray(counts, dtype=float).reshape(shape)
    heading = np.asarray(points.heading, dtype=float)
    ox, oy = np.asarray(points.origin_x, float), np.asarray(points.origin_y, float)
    cand = np.zeros(shape, dtype=bool)
    cand[row, col] = True
    silent = (points.reason == _NO_RETURN) | (points.reason == _OUT_OF_RANGE)
    has = s > 0
    d0 = np.full(shape, np.nan)
    d0[has] = cal.distance(s[has], 0.0)
    ex, ey = np.cos(heading), np.sin(heading)
    rank = np.empty(shape[0], dtype=np.intp)            # each row's place in step order
    order = rows_in_step_order(steps)
    rank[order] = np.arange(shape[0])
    cx0, cy0 = float(np.mean(ox)), float(np.mean(oy))
    log_s = np.log(np.where(has, s, 1.0))
    out = None
    for c in groups:
        ii, kk = row[comp == c], col[comp == c]
        flank, standing, tested = [], True, False
        for k in np.unique(kk):
            r_k = np.sort(rank[ii[kk == k]])
            far = np.nanmax(d0[ii[kk == k], k]) + POST_JUMP_M
            for q in (r_k[0] - 1, r_k[-1] + 1):
                if not 0 <= q < shape[0]:
                    continue            # the sweep's end: nothing says either way
                j = order[q]
                if silent[j, k]:
                    flank.append((j, k))
                elif not d0[j, k] > far:
                    standing = False
                elif cand[j, k]:      # on no line itself: the post's grazed edge, or more
                    tested = True     # of a steep surface; a circle fitted must be tested
        if not standing:
            continue
        fi = np.array([f[0] for f in flank], dtype=np.intp)
        fk = np.array([f[1] for f in flank], dtype=np.intp)
        bearing = np.arctan2(py[comp == c] - cy0, px[comp == c] - cx0)
        if bearing.max() - bearing.min() > math.pi:   # across ±π: the grid not round the ring
            bearing = np.where(bearing < 0.0, bearing + 2.0 * math.pi, bearing)
        near_m, far_m = np.nanmin(d0[ii, kk]) - 0.15, np.nanmax(d0[ii, kk]) + 0.05

        def score(radius, a, t):
            """Each candidate circle's summed misfit and its readings' θ, d, misfit, noise
            (radius, bearing a and centre range t: (C, 1))."""
            centre = (cx0 + t * np.cos(a), cy0 + t * np.sin(a))
            t_i, th_i, meets = _meet_circle(centre, radius, ox[ii, kk], oy[ii, kk],
                                            ex[ii, kk], ey[ii, kk])
            la, b = cal.log_ab(th_i)
            d_i = np.exp(la + b * log_s[ii, kk])
            noise = np.abs(b) * d_i * cal.sigma_counts() / s[ii, kk]
            z = (d_i - t_i) / noise
            each = np.where(meets & (th_i <= cal.max_incidence_rad),
                            np.minimum(z * z, ARC_MISS), ARC_MISS)
            cost = each.sum(axis=1)
            if fi.size:
                t_f, th_f, meets_f = _meet_circle(centre, radius, ox[fi, fk], oy[fi, fk],
                                                  ex[fi, fk], ey[fi, fk])
                cost = cost + ARC_MISS * np.count_nonzero(
                    meets_f & (th_f < cal.max_incidence_rad - POST_SILENT_RAD)
                    & (t_f < cal.return_range_m), axis=1)
            return cost, th_i, d_i, each, noise

        # coarse (every POST_COARSE-th radius, POST_COARSE-times the grid steps), then fine
        # about the best: 30× fewer circles than the fine grid (docs/estimator.md, cost)
        step_a, step_t = POST_COARSE * POST_BEARING_RAD, POST_COARSE * POST_RANGE_M
        grid_a = np.arange(bearing.min() - 8 * POST_BEARING_RAD,
                           bearing.max() + 8 * POST_BEARING_RAD + step_a, step_a)
        cand_r, cand_a, cand_t = [], [], []
        for radius in POST_RADII_M[::POST_COARSE]:
            a_g, t_g = np.meshgrid(grid_a, np.arange(near_m + radius, far_m + radius + step_t,
                                                     step_t))
            cand_r.append(np.full(a_g.size, radius))
            cand_a.append(a_g.ravel())
            cand_t.append(t_g.ravel())
        r_c, a_c, t_c = (np.concatenate(v).reshape(-1, 1) for v in (cand_r, cand_a, cand_t))
        q = int(np.argmin(score(r_c, a_c, t_c)[0]))
        at = int(np.argmin(np.abs(POST_RADII_M - r_c[q, 0])))
        fine = np.arange(-POST_COARSE, POST_COARSE + 1)
        r_f, a_f, t_f = np.meshgrid(POST_RADII_M[max(at - POST_COARSE + 1, 0):at + POST_COARSE],
                                    a_c[q, 0] + fine * POST_BEARING_RAD,
                                    fine * POST_RANGE_M, indexing="ij")
        t_f = t_f + t_c[q, 0] - r_c[q, 0] + r_f      # the same surface, each radius behind it
        r_f, a_f, t_f = (v.reshape(-1, 1) for v in (r_f, a_f, t_f))
        cost, th, d, each, noise = score(r_f, a_f, t_f)
        q = int(np.argmin(cost))
        cost, radius, th, d, each, noise = cost[q], r_f[q, 0], th[q], d[q], each[q], noise[q]
        if cost > ARC_MISFIT * (ii.size + fi.size) or radius >= POST_RADII_M[-1]:
            continue
        on = (each <= ARC_ON) & (d >= cal.min_range_m) & (d <= points.max_range_m)
        # a circle is three numbers: three readings on it (one more where it must be tested)
        if np.count_nonzero(on) < (POST_ON_TESTED if tested else 3):
            continue
        lo = cal.distance(s[ii, kk], np.maximum(th - ARC_DOUBT_RAD, 0.0))
        hi = cal.distance(s[ii, kk], np.minimum(th + ARC_DOUBT_RAD, cal.max_incidence_rad))
        sigma = np.hypot(np.maximum(noise, SIGMA_FLOOR_M), 0.5 * np.abs(lo - hi))
        if out is None:
            out = {f: np.array(getattr(points, f))
                   for f in ("x", "y", "d", "theta", "sigma_m", "valid", "reason")}
        i, k = ii[on], kk[on]
        out["d"][i, k], out["theta"][i, k], out["sigma_m"][i, k] = d[on], th[on], sigma[on]
        out["x"][i, k] = ox[i, k] + d[on] * ex[i, k]
        out["y"][i, k] = oy[i, k] + d[on] * ey[i, k]
        out["valid"][i, k], out["reason"][i, k] = True, Reason.OK
    return points if out is None else points_with(points, **out)


def post_groups_compiled(points: Points, label: np.ndarray, counts: np.ndarray,
                         cal: Calibration):
    """``estimate_numpy.post_groups`` (the statement) in one compiled call
    (``irring.estimation._lines.post_groups``, held to it by tests/test_estimate_oracle.py)."""
    f = np.ascontiguousarray
    la0, b0 = cal._ab0
    _, _, no_return, sigma_counts, _ = cal._levels      # (cached: the properties cost µs)
    return _lines.post_groups(
        f(points.reason, dtype=np.uint8).reshape(-1),
        f(points.valid, dtype=bool).reshape(-1).view(np.uint8),
        f(label, dtype=np.intp).reshape(-1), _INCIDENCE_UNKNOWN,
        f(counts, dtype=float).reshape(-1), f(points.heading, dtype=float).reshape(-1),
        f(points.origin_x, dtype=float).reshape(-1), f(points.origin_y, dtype=float).reshape(-1),
        points.valid.shape[1], no_return + (RETURN_SIGMAS + RANGE_SIGMAS) * sigma_counts,
        la0, b0, POST_LINK_M, POST_SENSORS, POST_RUN_MAX)


def _meet_circle(centre, radius: float, ox, oy, ex, ey):
    """Where beams (origins ``ox, oy``, unit directions ``ex, ey``: (J,)) meet circles
    (``centre``: x, y of shape (C, 1)): the distance t (C, J), the incidence there and
    whether they meet at all (ahead of the origin)."""
    rx, ry = centre[0] - ox, centre[1] - oy
    along = rx * ex + ry * ey
    disc = along * along - (rx * rx + ry * ry - radius * radius)
    t = along - np.sqrt(np.maximum(disc, 0.0))
    cos = np.clip(-((t * ex - rx) * ex + (t * ey - ry) * ey) / radius, 0.0, 1.0)
    return t, np.arccos(cos), (disc > 0.0) & (along > 0.0)


def theta0_sigma(cal: Calibration, counts: np.ndarray, d0: np.ndarray,
                 sig_s: np.ndarray) -> np.ndarray:
    """σ (m) of readings ``counts`` read at θ = 0 (``d0``) on no line: their noise
    (``sig_s``, relative) through θ = 0's slope, floored, with :func:`fallback_spread`."""
    _, b0 = cal._ab0
    return np.hypot(range_sigma(b0, d0, sig_s),
                    fallback_spread(cal, counts, d0))


def fallback_spread(cal: Calibration, counts: np.ndarray, d0: np.ndarray) -> np.ndarray:
    """RMS range error (m) of reading ``counts`` with θ = 0 (giving ``d0``) when the true θ
    is unknown, over the quadrature of :func:`calibration.fallback_thetas`."""
    err = cal.distance(counts[:, None], fallback_thetas(cal)) - d0[:, None]
    return np.sqrt(np.mean(err * err, axis=1))


def local_incidence(points: Points, label: np.ndarray, index: np.ndarray, counts: np.ndarray,
                    steps: np.ndarray, cal: Calibration, profiler: Callable | None = None
                    ) -> tuple[Points, np.ndarray]:
    """Readings on no line (``label`` −1, θ = 0), and the members of lines that are a round
    thing's, re-read at the incidence their own sensor's neighbouring steps give; numpy,
    shared by both estimators.

    ``index``: flat (S, N) indices of the live readings in scan order (each sensor's by
    step); ``steps`` (S,): each row's motor step. The valid readings of the same surface
    (polyline) within ``_LOCAL_STEPS`` steps are fitted as u = u0 + v·tan θ in the reading's
    beam frame. A straight profile clearly not flat gives θ and a σ that includes the slope's
    standard error; a profile bent away from the beam (a post) keeps θ = 0 with the σ of its
    doubt; one that decides nothing, where θ = 0 may read more than ``_UNKNOWN_M`` long, is
    INCIDENCE_UNKNOWN, unless the readings on no line alone give it a straight profile that
    places it surely (:func:`_off_line_profiles`). The members of a steep line whose own
    profiles mostly bend away (a column's arc cut into short lines; ``ROUND_*``) leave it
    first and are read the same way (short far lines: :func:`doubt_far_lines`). Returns the
    points and ``label`` without those members. The why and the measured effects:
    docs/estimator.md ("Readings on no line", "Round things", "A short far line's
    direction"), docs/foldover.md ("Short far lines")."""
    flat_valid = points.valid.reshape(-1)
    vi = index[flat_valid[index]]               # valid readings in scan order
    if vi.size == 0:
        return points, label
    lab = label.reshape(-1)[vi]
    theta_now = points.theta.reshape(-1)[vi]
    off = (lab < 0) & (theta_now == 0.0)
    # only a line read steeply can be read too steeply: its members are asked too
    member = (lab >= 0).nonzero()[0]
    line = lab[member]
    total = np.bincount(line)
    steep = np.bincount(line, weights=theta_now[member], minlength=total.size)
    maybe = np.zeros(vi.size, dtype=bool)
    maybe[member] = (steep >= ROUND_MIN_THETA * total)[line]
    # where a part is read to its own range, a far line of few noisy readings may know its
    # direction only to 10-20°, and its members read at that θ lie 20-150 mm off: a line
    # whose direction is that unsure gives its members no θ (docs/estimator.md, "A far
    # line's direction"; elsewhere: doubt_far_lines)
    unsure = np.zeros(vi.size, dtype=bool)
    if member.size and read_to_own_range(cal, points.max_range_m):
        at = vi[member]
        sigma_perp = points.sigma_m.reshape(-1)[at] * np.cos(theta_now[member])
        se_dir = direction_se(points.x.reshape(-1)[at], points.y.reshape(-1)[at],
                              sigma_perp, line, total.size)
        unsure[member] = (se_dir > DIRECTION_SE_MAX)[line]
    maybe |= unsure
    ask = (off | maybe).nonzero()[0]
    if ask.size == 0:
        return points, label
    pr = (profiler or profiles_compiled)(points, vi, ask, counts, steps, cal)
    # round lines: their members bend away more often than not straight and steep
    asked = maybe[ask]
    line = lab[ask[asked]]
    bent = np.bincount(line, weights=pr.convex[asked], minlength=total.size)
    straight = np.bincount(line, weights=pr.ok[asked], minlength=total.size)
    round_line = (bent >= ROUND_SHARE * total) & (bent >= ROUND_OVER_OK * straight)
    taken = unsure[ask]
    taken[asked] |= round_line[line]
    if taken.any():    # back to θ = 0 with the σ of a reading on no line
        at = vi[ask[taken]]
        s0, d0 = pr.s[ask[taken]], pr.d0[ask[taken]]
        points = placed_at(points, at, d0, 0.0,
                           theta0_sigma(cal, s0, d0, pr.sig_s[ask[taken]]))
        label = label.copy()
        label.reshape(-1)[at] = -1
    mine = off[ask] | taken                     # the readings on no line now
    if not mine.any():
        return points, label
    off = ask[mine]
    s, d0, sig_s = pr.s, pr.d0, pr.sig_s
    ok, convex, sure, steep, theta, slope, se = (v[mine] for v in (
        pr.ok, pr.convex, pr.sure, pr.steep, pr.theta, pr.slope, pr.se))
    s_off = s[off]
    s_ok = s_off[ok]
    th, t, e = theta[ok], np.abs(slope[ok]), se[ok]
    # θ ± the slope's standard error: the range of d it leaves
    lo = np.arctan(np.maximum(t - e, 0.0))
    hi = np.minimum(np.arctan(t + e), cal.max_incidence_rad)
    # the curve read once for all (elementwise: the same numbers as one call each): at the
    # steepest θ allowed, at θ, and at θ ± its standard error
    d_steep, d_new, d_lo, d_hi = np.split(
        cal.distance(np.concatenate([s_off, s_ok, s_ok, s_ok]),
                     np.concatenate([steep, th, lo, hi])),
        np.cumsum([s_off.size, s_ok.size, s_ok.size]))
    # how much longer θ = 0 reads than the steepest θ the readings allow
    span = d0[off] - d_steep
    # a slope past the drop-out angle places a reading only where its lower bound does
    clamp = clamped_slopes(cal, s_ok, slope[ok], se[ok], pr.n[mine][ok], _UNKNOWN_M)
    if clamp.any():
        ok = ok.copy()
        ok[ok.nonzero()[0][clamp]] = False
        th, t, e, lo, hi = (v[~clamp] for v in (th, t, e, lo, hi))
        s_ok, d_new, d_lo, d_hi = (v[~clamp] for v in (s_ok, d_new, d_lo, d_hi))
    # where θ = 0 may read more than _UNKNOWN_M long, a bend noise could make (a steep far
    # wall's few readings bent 2.2 SE by noise were kept 106-166 mm long) is not enough
    convex = convex & (~(span > _UNKNOWN_M) | sure)
    # a ring held still (fewer motor steps than a slope needs) has no neighbours to ask: its
    # readings are what it has (flagging them lost a radial ring nearly every reading)
    still = _fewer_distinct(steps, _LOCAL_MIN)
    few = ~ok & ~convex & (not still) & (span > _UNKNOWN_M)
    if few.any() and member.size:
        # a short face beside a line's face (a box's end past its corner) bends the profile
        # of its readings where their window takes in the line's members: asked again of
        # the readings on no line alone, a straight profile gives θ
        again = _off_line_profiles(points, label, off[few], vi, counts, steps, cal, profiler)
        if again is not None:
            fix = few.nonzero()[0][again[0]]
            sure = _placed_surely(cal, s_off[fix], *again[1:], sig_s[off[fix]])
            if sure.any():
                fix = fix[sure]
                ok, few = ok.copy(), few.copy()
                ok[fix], few[fix] = True, False
                theta, slope, se = theta.copy(), slope.copy(), se.copy()
                theta[fix], slope[fix], se[fix] = (v[sure] for v in again[1:])
                th, t, e = theta[ok], np.abs(slope[ok]), se[ok]
                lo = np.arctan(np.maximum(t - e, 0.0))
                hi = np.minimum(np.arctan(t + e), cal.max_incidence_rad)
                s_ok = s_off[ok]
                d_new, d_lo, d_hi = cal.distance(np.concatenate([s_ok, s_ok, s_ok]),
                                                 np.concatenate([th, lo, hi])).reshape(3, -1)
    # a convex thing's reading may have met its side steeply, a still ring's any surface:
    # θ = 0 with the σ of that doubt
    wide = (convex | still) & ~ok
    # a polyline holding a bent profile is a round thing's arc: its readings on no line
    # take θ from one circle through them where one fits (arc_incidence)
    arc = np.zeros(0, dtype=np.intp)
    if convex.any() and not still:
        on_arc = np.isin(pr.chain[off], np.unique(pr.chain[off[convex]]))
        th_a, d_a, sig_a, fit, _, _ = arc_incidence(pr, off[on_arc], cal)
        arc = on_arc.nonzero()[0][fit]
        th_a, d_a, sig_a = th_a[fit], d_a[fit], sig_a[fit]
        on = np.zeros(off.size, dtype=bool)
        on[arc] = True
        rest = ~on[ok]          # the slopes' readings not on an arc
        th, d_new, d_lo, d_hi = th[rest], d_new[rest], d_lo[rest], d_hi[rest]
        ok, few, wide = ok & ~on, few & ~on, wide & ~on
    if not (ok.any() or few.any() or wide.any() or arc.size):
        return points, label
    if few.any():    # (few, wide and ok are readings apart)
        points = invalidated(points, vi[off[few]], Reason.INCIDENCE_UNKNOWN)
    out = {f: np.array(getattr(points, f)) for f in ("x", "y", "d", "theta", "sigma_m")}
    if wide.any():
        at = vi[off[wide]]
        doubt = 0.5 * span[wide]
        out["sigma_m"].reshape(-1)[at] = np.hypot(out["sigma_m"].reshape(-1)[at], doubt)
    at = vi[off[ok]]
    sigma, keep = _own_slope_sigma(cal, th, d_new, d_lo, d_hi, sig_s[off[ok]])
    at, th, d_new, sigma = at[keep], th[keep], d_new[keep], sigma[keep]
    if arc.size:
        at = np.concatenate([at, vi[off[arc]]])
        th, d_new, sigma = (np.concatenate(v) for v in ((th, th_a), (d_new, d_a), (sigma, sig_a)))
    hh = points.heading.reshape(-1)[at]
    out["d"].reshape(-1)[at] = d_new
    out["theta"].reshape(-1)[at] = th
    out["sigma_m"].reshape(-1)[at] = sigma
    out["x"].reshape(-1)[at] = points.origin_x.reshape(-1)[at] + d_new * np.cos(hh)
    out["y"].reshape(-1)[at] = points.origin_y.reshape(-1)[at] + d_new * np.sin(hh)
    return points_with(points, **out), label


def short_far_lines(points: Points, label: np.ndarray, index: np.ndarray, cal: Calibration
                    ) -> tuple[np.ndarray, np.ndarray] | None:
    """The members of short far lines, as fitted (flat (S·N,) masks; None where there are
    none): those of lines of ``_LOCAL_MIN`` to ``FAR_LINE_MAX_MEMBERS`` members lying on
    average ``FAR_LINE_MIN_SHARE`` of the range away, which their members' profiles vote
    on, and, unless a part is read to its own range, those of such lines of at most
    ``SHORT_LINE_MAX_MEMBERS`` whose direction standard error exceeds ``SHORT_LINE_SE_MAX``
    (:func:`doubt_far_lines` asks both)."""
    vi = index[points.valid.reshape(-1)[index]]
    lab = label.reshape(-1)[vi]
    member = (lab >= 0).nonzero()[0]
    if member.size == 0:
        return None
    line = lab[member]
    total = np.bincount(line)
    at = vi[member]
    far = (np.bincount(line, weights=points.d.reshape(-1)[at], minlength=total.size)
           >= FAR_LINE_MIN_SHARE * points.max_range_m * total)
    # fewer than _LOCAL_MIN members never outvote their line: not asked
    doubt = np.zeros(label.size, dtype=bool)
    doubt[at] = (far & (total >= _LOCAL_MIN) & (total <= FAR_LINE_MAX_MEMBERS))[line]
    loose = np.zeros(label.size, dtype=bool)
    few_far = far & (total <= SHORT_LINE_MAX_MEMBERS)
    if few_far.any() and not read_to_own_range(cal, points.max_range_m):
        sel = few_far[line].nonzero()[0]   # (the directions of those lines' members alone)
        at_s = at[sel]
        sigma_perp = (points.sigma_m.reshape(-1)[at_s]
                      * np.cos(points.theta.reshape(-1)[at_s]))
        se_dir = direction_se(points.x.reshape(-1)[at_s], points.y.reshape(-1)[at_s],
                              sigma_perp, line[sel], total.size)
        loose[at_s] = (se_dir > SHORT_LINE_SE_MAX)[line[sel]]
    return (doubt, loose) if doubt.any() or loose.any() else None


def doubt_far_lines(points: Points, label: np.ndarray, index: np.ndarray, counts: np.ndarray,
                    steps: np.ndarray, cal: Calibration, doubt: np.ndarray, loose: np.ndarray,
                    profiler: Callable | None = None, voter: Callable | None = None
                    ) -> tuple[Points, np.ndarray]:
    """The members of short far lines (:func:`short_far_lines`: ``doubt``, ``loose``) their
    own profiles (:func:`local_incidence`'s) disown, off their lines; numpy, shared by both
    estimators.

    Where the members of a ``doubt`` line differ from its θ by more than ``FAR_LINE_Z``
    standard errors on average and would move ``FAR_LINE_SHIFT_M`` on average, every member
    leaves it, at its own θ where its profile is straight and clearly steep, else
    INCIDENCE_UNKNOWN; a ``loose`` line loses the members whose own profile is straight and
    whose slope lies ``SHORT_LINE_OWN_SE`` of its standard error off the line's, at their
    own θ where that lies within the range. Only members still on their line are asked (not
    those a circle took: :func:`round_runs`). ``voter``: the vote (compiled by default; the
    oracle passes ``estimate_numpy.far_line_vote``). Returns the points and ``label``.
    Why: docs/foldover.md ("Short far lines", "On every sweep"), docs/estimator.md ("A short
    far line's direction")."""
    vi = index[points.valid.reshape(-1)[index]]
    lab = label.reshape(-1)[vi]
    on = lab >= 0
    doubt, loose = doubt[vi] & on, loose[vi] & on
    ask = (doubt | loose).nonzero()[0]
    if ask.size == 0:
        return points, label
    pr = (profiler or profiles_compiled)(points, vi, ask, counts, steps, cal)
    theta_now = points.theta.reshape(-1)[vi]
    doubted = np.zeros(ask.size, dtype=bool)
    asked = doubt[ask]
    if asked.any():      # the members' own slopes, on average, against the line's θ
        off_line = (voter or _far_line_vote_compiled)(
            ask[asked], asked.nonzero()[0], lab, theta_now, pr, points.d.reshape(-1), vi,
            int(lab.max()) + 1, cal, _LOCAL_STEPS, _LOCAL_MIN, FAR_LINE_Z, FAR_LINE_SHIFT_M)
        doubted[asked] = off_line[lab[ask[asked]]]
    voted = doubted.copy()   # (a line its members voted off: every member leaves it)
    if loose.any():   # … each member whose own straight slope is clearly not the line's
        doubted |= loose[ask] & pr.ok & (np.abs(np.tan(theta_now[ask]) - np.abs(pr.slope))
                                         > SHORT_LINE_OWN_SE * pr.se)
    if not doubted.any():
        return points, label
    return _leave_doubted_line(points, label, vi, ask[doubted], pr, doubted, cal,
                               stay=loose[ask[doubted]] & ~voted[doubted])


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
    INCIDENCE_UNKNOWN (:func:`_leave_doubted_line`) but where its profile bounds θ enough
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
    points, label = _leave_doubted_line(points, label, vi, pos, pr,
                                        np.ones(pos.size, dtype=bool), cal)
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
    ``_AGAIN_SIGMA_M`` and θ is not pinned at the drop-out angle. Numpy, shared by both
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
    sigma, ok = _own_slope_sigma(cal, theta, d, d_lo, d_hi, cal.sigma_counts() / s)
    ok &= (sigma <= _AGAIN_SIGMA_M) & (theta < cal.max_incidence_rad - PINNED_RAD) & (
        d <= points.max_range_m)
    if not ok.any():
        return points
    at = at[ok]
    points = placed_at(points, at, d[ok], theta[ok], sigma[ok])
    valid, reason = points.valid.copy(), np.array(points.reason)
    valid.reshape(-1)[at], reason.reshape(-1)[at] = True, Reason.OK
    return points_with(points, valid=valid, reason=reason)


def _off_line_profiles(points: Points, label: np.ndarray, pos: np.ndarray, vi: np.ndarray,
                       counts: np.ndarray, steps: np.ndarray, cal: Calibration,
                       profiler: Callable | None):
    """The range profiles of the valid readings ``vi[pos]`` (on no line) from their sensor's
    valid readings on no line alone (``label`` −1; a line's member cuts the polyline):
    (which are straight and clearly sloped, their θ, slope, standard error) or None where
    none is."""
    pr = (profiler or profiles_compiled)(points, vi, pos, counts, steps, cal,
                                         apart=label.reshape(-1)[vi] >= 0)
    if not pr.ok.any():
        return None
    return pr.ok, pr.theta[pr.ok], pr.slope[pr.ok], pr.se[pr.ok]


_AGAIN_SIGMA_M = _UNKNOWN_M / 3  # a profile asked again places a reading only this surely …


def _placed_surely(cal: Calibration, s: np.ndarray, theta: np.ndarray, slope: np.ndarray,
                   se: np.ndarray, sig_s: np.ndarray) -> np.ndarray:
    """Which readings (counts ``s``) a profile asked again may place at its ``theta``
    (``slope`` and its standard error ``se``; ``sig_s``: σ_S/S): σ at most
    ``_AGAIN_SIGMA_M`` (θ = 0 would be off by 3σ or more), θ not pinned at the drop-out
    angle (a slope that steep is two surfaces', not one face's)."""
    t = np.abs(slope)
    lo = np.arctan(np.maximum(t - se, 0.0))
    hi = np.minimum(np.arctan(t + se), cal.max_incidence_rad)
    d, d_lo, d_hi = cal.distance(np.concatenate([s, s, s]),
                                 np.concatenate([theta, lo, hi])).reshape(3, -1)
    sigma, placed = _own_slope_sigma(cal, theta, d, d_lo, d_hi, sig_s)
    return placed & (sigma <= _AGAIN_SIGMA_M) & (theta < cal.max_incidence_rad - PINNED_RAD)


def _own_slope_sigma(cal: Calibration, theta: np.ndarray, d: np.ndarray, d_lo: np.ndarray,
                     d_hi: np.ndarray, sig_s: np.ndarray):
    """(σ, placed) of readings read at their own profile's θ (distance ``d``; ``d_lo``,
    ``d_hi`` at θ ± the slope's standard error; ``sig_s``: σ_S/S): the noise at θ plus half
    the spread of d over θ ± that error; placed: d and σ finite, d within the curve."""
    spread = 0.5 * np.abs(d_lo - d_hi)
    _, b_new = cal.log_ab(theta)
    sigma = np.hypot(range_sigma(b_new, d, sig_s), spread)
    return sigma, np.isfinite(d) & (d >= cal.min_range_m) & np.isfinite(sigma)


def _far_line_vote_compiled(at, sel, lab, theta_now, pr: _Profile, d, vi, n_lines: int,
                            cal: Calibration, half: int, min_n: int, z_max: float,
                            shift_m: float) -> np.ndarray:
    """``estimate_numpy.far_line_vote`` (the statement and the why) in one compiled call
    (``irring.estimation._lines.far_line_vote``, held to it by tests/test_estimate_oracle.py):
    the lines voted off, (n_lines,) bool."""
    f = np.ascontiguousarray
    return _lines.far_line_vote(
        at, sel, lab, f(theta_now, dtype=float), pr.chain, pr.step, pr.n, pr.se, pr.slope,
        pr.theta, pr.s, f(d, dtype=float), vi, cal.theta_rad, cal._node_log_a, cal.b,
        n_lines, half, min_n, z_max, shift_m)


def _leave_doubted_line(points: Points, label: np.ndarray, vi: np.ndarray, pos: np.ndarray,
                        pr: _Profile, doubted: np.ndarray, cal: Calibration,
                        stay: np.ndarray | None = None) -> tuple[Points, np.ndarray]:
    """The members of doubted short far lines off their lines (``pos``: their places among
    the valid readings ``vi``; ``doubted``: which of the readings ``pr`` profiled they are):
    each at its own profile's θ where that is straight and clearly steep, else
    INCIDENCE_UNKNOWN (far, and nothing places it), unless no θ reads it beyond its noise
    (:func:`_theta_free`: then at θ = 0). ``stay`` (over ``pos``): members
    left on their line, as they were, where their own θ does not place them within the
    range."""
    placed = pr.ok[doubted].copy()  # only a straight, clearly steep profile places one
    if placed.any():
        s, theta = pr.s[pos[placed]], pr.theta[doubted][placed]
        t, e = np.abs(pr.slope[doubted][placed]), pr.se[doubted][placed]
        lo = np.arctan(np.maximum(t - e, 0.0))
        hi = np.minimum(np.arctan(t + e), cal.max_incidence_rad)
        d_new, d_lo, d_hi = cal.distance(np.concatenate([s, s, s]),
                                         np.concatenate([theta, lo, hi])).reshape(3, -1)
        sigma, fits = _own_slope_sigma(cal, theta, d_new, d_lo, d_hi, pr.sig_s[pos[placed]])
        if stay is not None:     # (a stayer is placed only within the range)
            fits &= ~stay[placed] | (d_new <= points.max_range_m)
        placed[placed] = fits
        if fits.any():
            points = placed_at(points, vi[pos[placed]], d_new[fits], theta[fits], sigma[fits])
    leave = np.ones(pos.size, dtype=bool) if stay is None else placed | ~stay
    # a reading no θ moves beyond its noise (an ideal sensor's) is placed by its counts alone
    rest = (leave & ~placed).nonzero()[0]
    if rest.size:
        at, sigma = _theta_free(cal, pr.s[pos[rest]], pr.d0[pos[rest]], pr.sig_s[pos[rest]],
                                points.max_range_m)
        if at.any():
            points = placed_at(points, vi[pos[rest[at]]], pr.d0[pos[rest[at]]], 0.0, sigma)
            placed[rest[at]] = True
    label = label.copy()
    label.reshape(-1)[vi[pos[leave]]] = -1
    gone = vi[pos[leave & ~placed]]
    if gone.size:
        points = invalidated(points, gone, Reason.INCIDENCE_UNKNOWN)
    return points, label


def _theta_free(cal: Calibration, s: np.ndarray, d0: np.ndarray, sig_s: np.ndarray,
                max_range_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(which, σ) of readings (counts ``s``, θ = 0 distance ``d0``, ``sig_s``: σ_S/S) that
    no incidence up to the drop-out angle reads more than their noise σ away from ``d0``
    (a calibration without θ dependence: the ideal sensor's), within [min range, max
    range]: what θ is does not matter to them, so nothing is unknown. σ: their θ = 0 σ."""
    thetas = np.append(cal.theta_rad[cal.theta_rad <= cal.max_incidence_rad],
                       cal.max_incidence_rad)
    spread = np.max(np.abs(cal.distance(s[:, None], thetas[None, :]) - d0[:, None]), axis=1,
                    initial=0.0)
    sigma = theta0_sigma(cal, s, d0, sig_s)
    return (np.isfinite(d0) & (d0 >= cal.min_range_m) & (d0 <= max_range_m)
            & (spread <= range_sigma(cal._ab0[1], d0, sig_s)) & np.isfinite(sigma)), sigma


# --------------------------------------------------------------------------- silent beams

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


# --------------------------------------------------------------------------- curved walls

CONCAVE_RADII_M = (0.25, 2.5)  # a curved wall's circle: radii from this to this …
CONCAVE_ITERATIONS = 8         # … its members read at its incidence and it refitted (at most)
CONCAVE_FIT_Z = 2.0            # … it fits them within this reduced χ² (their noise) …
CONCAVE_MIN_LINES = 3          # … and joins at least this many lines (two: a corner's walls) …
# … and, by BIC, better than its lines: a χ² lower by the log of its members per parameter
# saved (a circle 3 for 2 per line)


def _circle_fit(x: np.ndarray, y: np.ndarray, w: np.ndarray, start) -> tuple | None:
    """The circle (cx, cy, r) nearest points ``x``, ``y`` (m) with weights ``w`` (1/σ²
    across it): Gauss–Newton on the geometric distance from ``start`` (cx, cy, r); None
    where it does not settle."""
    cx, cy, r = (float(v) for v in start)
    for _ in range(30):
        dx, dy = x - cx, y - cy
        rho = np.maximum(np.hypot(dx, dy), 1e-9)
        jac = np.stack([-dx / rho, -dy / rho, -np.ones_like(rho)], axis=1)
        res = rho - r
        a = jac.T @ (jac * w[:, None])
        try:
            step = np.linalg.solve(a, -(jac.T @ (w * res)))
        except np.linalg.LinAlgError:
            return None
        cx, cy, r = cx + step[0], cy + step[1], r + step[2]
        if not np.all(np.isfinite((cx, cy, r))):
            return None
        if np.abs(step).max() < 1e-7:
            return cx, cy, r
    return None


def _beam_meets_circle(ox, oy, ux, uy, cx, cy, r):
    """(t, cos θ) where beams from inside a circle meet it going out: distance (m) and the
    cosine of the incidence (beam against the radius there)."""
    fx, fy = ox - cx, oy - cy
    b = fx * ux + fy * uy
    t = -b + np.sqrt(np.maximum(b * b - (fx * fx + fy * fy - r * r), 0.0))
    cos = np.abs(ux * (fx + t * ux) + uy * (fy + t * uy)) / r
    return t, np.clip(cos, 0.0, 1.0)


def _read_on_circle(group, ox, oy, ux, uy, s, cal, circle):
    """Self-consistent circle of readings ``group``: each read at the incidence where its
    beam meets the circle, the circle refitted to those end points, ``CONCAVE_ITERATIONS``
    times. Returns (circle, χ², θ) or None where it leaves the radii, the ring or the
    drop-out angle."""
    lo, hi = CONCAVE_RADII_M
    for _ in range(CONCAVE_ITERATIONS):
        cx, cy, r = circle
        if np.any(np.hypot(ox[group] - cx, oy[group] - cy) >= r):
            return None
        t, cos = _beam_meets_circle(ox[group], oy[group], ux[group], uy[group], cx, cy, r)
        theta = np.arccos(cos)
        if np.any(theta > cal.max_incidence_rad):
            return None
        d = np.asarray(cal.distance(s[group], theta), dtype=float)
        _, b = cal.log_ab(theta)
        sigma = range_sigma(b, d, cal.sigma_counts() / s[group]) * cos
        w = 1.0 / np.maximum(sigma, 1e-6) ** 2
        x, y = ox[group] + d * ux[group], oy[group] + d * uy[group]
        fit = _circle_fit(x, y, w, circle)
        if fit is None:
            return None
        settled = max(abs(a - b) for a, b in zip(fit, circle)) < 1e-6
        circle = fit
        if settled:
            break
    cx, cy, r = circle
    if not lo <= r <= hi or np.any(np.hypot(ox[group] - cx, oy[group] - cy) >= r):
        return None
    t, cos = _beam_meets_circle(ox[group], oy[group], ux[group], uy[group], cx, cy, r)
    theta = np.arccos(cos)
    if np.any(theta > cal.max_incidence_rad):
        return None
    chi2 = float(np.sum(w * (np.hypot(x - cx, y - cy) - r) ** 2))
    return circle, chi2, theta


def _line_chi2(group, ox, oy, ux, uy, s, cal, theta):
    """χ² of readings ``group`` about their own line, each read at its line's θ (TLS)."""
    d = np.asarray(cal.distance(s[group], theta[group]), dtype=float)
    _, b = cal.log_ab(theta[group])
    sigma = range_sigma(b, d, cal.sigma_counts() / s[group]) * np.cos(theta[group])
    w = 1.0 / np.maximum(sigma, 1e-6) ** 2
    x, y = ox[group] + d * ux[group], oy[group] + d * uy[group]
    mx, my = np.average(x, weights=w), np.average(y, weights=w)
    u, v = x - mx, y - my
    alpha = 0.5 * np.arctan2(2.0 * np.sum(w * u * v), np.sum(w * (u * u - v * v)))
    perp = -u * np.sin(alpha) + v * np.cos(alpha)
    return float(np.sum(w * perp * perp))


def onto_concave_arcs(p: Points, label: np.ndarray, counts: np.ndarray, cal: Calibration,
                      own_cap_m: float = math.inf) -> Points:
    """``p`` with the members of neighbouring lines (``label``, −1 none; lines of at least
    ``SNAP_MIN`` valid members) that one circle around the ring fits better put on it: a
    curved wall made of straight pieces (a round room, a bay), which lines fit each over
    several pieces, their θ 10–30° off the pieces' and their members 20–40 mm long (2–6σ).
    Lines are joined in the order of their bearing from the ring's centre while their
    members, each read at the incidence where its beam meets the circle
    (:func:`_read_on_circle`), fit it within ``CONCAVE_FIT_Z`` reduced χ² and, by BIC,
    better than the lines did; the circle encloses every emitter (a wall seen from inside,
    never a post) with a radius within ``CONCAVE_RADII_M``. Each member its own reading at the
    circle's incidence puts within ``SNAP_SIGMAS`` of it is then put where its beam meets the
    circle, at that incidence, its σ the circle's uncertainty there with half its own (at
    most ``own_cap_m``), as :func:`snap_to_lines` puts a line's. ``counts`` (S, N): the counts the lines were read
    from. numpy, shared by both estimators. docs/foldover.md, "Curved walls"."""
    member = p.valid & (label >= 0)
    if not member.any():
        return p
    n_lines = int(label[member].max()) + 1
    size = np.bincount(label[member], minlength=n_lines)
    lines = (size >= SNAP_MIN).nonzero()[0]
    if lines.size == 0:
        return p
    ox, oy = p.origin_x.reshape(-1), p.origin_y.reshape(-1)
    ux, uy = np.cos(p.heading).reshape(-1), np.sin(p.heading).reshape(-1)
    s = np.asarray(counts, dtype=float).reshape(-1)
    theta = np.asarray(p.theta, dtype=float).reshape(-1)
    lab = np.where(member, label, -1).reshape(-1)
    idx = [np.flatnonzero(lab == k) for k in lines]
    centre = np.array([np.mean(ox), np.mean(oy)])      # the ring's (its emitters' mean)
    bearing = np.array([math.atan2(np.mean(p.y.reshape(-1)[i]) - centre[1],
                                   np.mean(p.x.reshape(-1)[i]) - centre[0]) for i in idx])
    order = np.argsort(bearing)
    chi_line = np.array([_line_chi2(i, ox, oy, ux, uy, s, cal, theta) for i in idx])
    taken = []          # (lines, readings, circle, χ², θ) per circle kept
    k = 0
    while k < order.size:
        best = None
        for stop in range(k + CONCAVE_MIN_LINES, order.size + 1):
            trial = order[k:stop]
            group = np.concatenate([idx[j] for j in trial])
            # from the circle one line fewer took, else the circle about the ring's centre
            # through the lines' mean range
            start = best[2] if best is not None else (centre[0], centre[1], float(np.mean(
                np.hypot(p.x.reshape(-1)[group] - centre[0],
                         p.y.reshape(-1)[group] - centre[1]))))
            got = _read_on_circle(group, ox, oy, ux, uy, s, cal, start)
            if got is None or got[1] / max(group.size - 3, 1) > CONCAVE_FIT_Z:
                break
            circle, chi2, th = got
            n = group.size
            saved = 2 * trial.size - 3          # parameters the circle saves over the lines
            lines_chi = float(chi_line[trial].sum())
            # the noise scale the lines leave (a pooled reading's σ overstates its scatter)
            scale = max(lines_chi / max(n - 2 * trial.size, 1), 1e-6)
            if (chi2 - lines_chi) / scale > saved * math.log(n):
                break
            best = (trial, group, circle, chi2, th)
        if best is None:
            k += 1
            continue
        taken.append(best)
        k += best[0].size
    if not taken:
        return p
    x, y, d, th, sg = (np.array(v, dtype=float).reshape(-1)
                       for v in (p.x, p.y, p.d, p.theta, p.sigma_m))
    for trial, group, (cx, cy, r), chi2, theta_c in taken:
        t, cos = _beam_meets_circle(ox[group], oy[group], ux[group], uy[group], cx, cy, r)
        own = np.asarray(cal.distance(s[group], theta_c), dtype=float)
        _, b = cal.log_ab(theta_c)
        noise = range_sigma(b, own, cal.sigma_counts() / s[group])
        w = 1.0 / np.maximum(noise * cos, 1e-6) ** 2
        se = math.sqrt(max(chi2 / max(group.size - 3, 1), 1.0) * 3.0 / float(w.sum()))
        # as onto a line (snap_to_lines): a member its own reading puts within 3σ of it
        on = np.abs(own - t) <= SNAP_SIGMAS * noise
        g, t, cos, noise = group[on], t[on], cos[on], noise[on]
        d[g], th[g] = t, theta_c[on]
        x[g], y[g] = ox[g] + t * ux[g], oy[g] + t * uy[g]
        sg[g] = np.hypot(se / np.maximum(cos, 1e-3), np.minimum(SNAP_OWN * noise, own_cap_m))
    shape = p.valid.shape
    return points_with(p, x=x.reshape(shape), y=y.reshape(shape), d=d.reshape(shape),
                       theta=th.reshape(shape), sigma_m=sg.reshape(shape))


# --------------------------------------------------------------------------- end points on lines

SNAP_SIGMAS = 3.0   # a member moves out onto its line if that is within 3σ (in from behind: always) …
SNAP_MIN = 10       # … and the line has at least 10 members (short lines are less sure)
SNAP_OWN = 0.5      # share of a member's own σ kept in its σ on the line …
SNAP_OWN_CAP_M = 0.010  # … at most this where a part is read to its own range (far_sigma_cap)


def snap_to_lines(points: Points, member: np.ndarray, min_range_m: float,
                  own_cap_m: float = math.inf) -> Points:
    """End points of the readings on a line put where their beams meet it.

    ``member`` (S, N): the line each reading took θ from (−1: none). A valid member of a
    line with ≥ 10 members moves along its beam onto the line refitted to their end points
    (members read a little past the max range included: see :func:`drop_beyond_range`)
    when the member lies behind it or short of it by no more than 3σ, within [``min_range_m``,
    ``points.max_range_m``]; its σ becomes the line's uncertainty there (half its own σ
    added, at most ``own_cap_m``). One compiled call (``irring.estimation._lines.snap_to_lines``);
    the readable statement and the why: :func:`irring.estimation.estimate_numpy.snap_to_lines`."""
    f = np.ascontiguousarray
    moved = _lines.snap_to_lines(
        f(member, dtype=np.intp).reshape(-1),
        f(points.valid, dtype=bool).reshape(-1).view(np.uint8),
        *(f(getattr(points, k), dtype=float).reshape(-1)
          for k in ("x", "y", "d", "sigma_m", "heading", "origin_x", "origin_y")),
        SNAP_MIN, SNAP_SIGMAS, SNAP_OWN, float(own_cap_m), SIGMA_FLOOR_M, float(min_range_m),
        float(points.max_range_m))
    if moved is None:
        return points
    shape = points.valid.shape
    x, y, d, sigma = (v.reshape(shape) for v in moved)
    return points_with(points, x=x, y=y, d=d, sigma_m=sigma)


FACET_MIN = 12          # a snapped line of at least this many moved members is asked …
FACET_SIDE = 6          # … for its best split into two pieces of at least this many each …
FACET_F = 5.0           # … that beat the line by this F (2, n − 4) as the members lie …
FACET_CHI = 15.0        # … and by this χ² against the members' own σ (pooled far readings
# share their noise: their scatter is 0.06-0.3 σ², so F alone splits a straight wall there) …
FACET_TURN_RAD = math.radians(5)   # … and turn by this much (a straight wall's noise: less)
FACET_ITERATIONS = 4    # each piece then read by Table II's iteration, this many steps
FACET_PRE_TOL = 1e-6    # (the compiled pre-gate's F, gain and turn, within this × (1 + scale))


def faceted_lines(before: Points, label: np.ndarray, after: Points, cal: Calibration
                  ) -> Points:
    """A snapped line over a many-sided wall's facets read as two pieces; numpy, shared by
    both estimators, after the snap.

    ``before`` and ``after``: the points as :func:`snap_to_lines` took and returned them,
    ``label`` the lines it fitted. The members the snap moved, of a line of at least
    ``FACET_MIN`` of them, are split at their best place along the line (``FACET_SIDE`` a
    piece at least; weighted least squares in the line's frame, every line at once by
    prefix sums); where the pieces beat the line by ``FACET_F`` (against their scatter) and
    ``FACET_CHI`` (against their σ) as the members lie and turn by ``FACET_TURN_RAD`` or more,
    each piece is read by Table II's iteration
    (``FACET_ITERATIONS`` steps: fit, re-read each member at the incidence its beam meets
    the piece with) and its members are put where their beams meet it (at most
    ``SNAP_SIGMAS`` of their own σ from where they were read, within the range; θ and σ as
    the snap left them). A line over 2–4 facets of a round room, straight through their
    bends, puts its members up to 20–30 mm off them at 0.6 m: 3–5 cells of 5 mm. Why:
    docs/estimator.md, "A line over facets"."""
    asked = _facet_asked(before, label, after)
    if asked is None:
        return after
    (idx, g, ox, oy, ex, ey, d0, sig, cx, cy, ux, uy, order, gs, w, at, best, split, F, gain,
     turn) = asked
    good = (np.isfinite(split) & (F >= FACET_F) & (gain >= FACET_CHI)
            & (turn >= FACET_TURN_RAD))
    if not good.any():
        return after
    # the pieces (two a good line), each read by Table II's iteration
    keep = good[gs]
    piece = 2 * gs + (at >= best[gs])
    o = order[keep]
    piece = np.unique(piece[keep], return_inverse=True)[1]
    n_p = int(piece.max()) + 1
    gk = g[o]
    es = ex[o] * ux[o] + ey[o] * uy[o]
    en = -ex[o] * uy[o] + ey[o] * ux[o]
    so = (ox[o] - cx[gk]) * ux[o] + (oy[o] - cy[gk]) * uy[o]
    no = -(ox[o] - cx[gk]) * uy[o] + (oy[o] - cy[gk]) * ux[o]
    wk = w[keep]
    la0, b0 = cal.log_ab(before.theta.reshape(-1)[idx[o]])
    log_s = (np.log(d0[o]) - la0) / b0           # the reading as the estimator read it
    d = d0[o]
    for step in range(FACET_ITERATIONS + 1):
        ps, pr = so + d * es, no + d * en
        W, S, S2, R, SR = (np.bincount(piece, wk * q, n_p) for q in
                           (np.ones_like(ps), ps, ps * ps, pr, ps * pr))
        den = W * S2 - S * S
        with np.errstate(divide="ignore", invalid="ignore"):
            m_p = np.where(den > 1e-18, (W * SR - S * R) / den, 0.0)
            m, c = m_p[piece], ((R - m_p * S) / W)[piece]
        if step == FACET_ITERATIONS:
            break
        cos = np.abs(en - m * es) / np.sqrt(1.0 + m * m)
        la, b = cal.log_ab(np.minimum(np.arccos(np.clip(cos, 0.0, 1.0)),
                                      cal.max_incidence_rad))
        d = np.exp(la + b * log_s)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (c + m * so - no) / (en - m * es)
    flat_at = idx[o]
    # (a piece's noise-tilted end read 100 mm off on a straight wall: no member moves more
    # than the snap would move it out)
    ok = (np.isfinite(t) & (t >= cal.min_range_m) & (t <= before.max_range_m)
          & (np.abs(t - d0[o]) <= SNAP_SIGMAS * sig[o]))
    if not ok.any():
        return after
    flat_at, t = flat_at[ok], t[ok]
    out = {f: np.array(getattr(after, f)) for f in ("x", "y", "d")}
    out["d"].reshape(-1)[flat_at] = t
    out["x"].reshape(-1)[flat_at] = before.origin_x.reshape(-1)[flat_at] + t * np.cos(
        before.heading.reshape(-1)[flat_at])
    out["y"].reshape(-1)[flat_at] = before.origin_y.reshape(-1)[flat_at] + t * np.sin(
        before.heading.reshape(-1)[flat_at])
    return points_with(after, **out)


def faceted_lines_compiled(before: Points, label: np.ndarray, after: Points,
                           cal: Calibration) -> Points:
    """:func:`faceted_lines`, whose split search (:func:`_facet_asked`) is first asked of
    one compiled call (``irring.estimation._lines.facet_pre``, held to it by
    tests/test_faceted_lines.py): where its F, χ² gain and turn, each widened by
    ``FACET_PRE_TOL``, pass no line, neither would numpy's and nothing is split (most
    sweeps); else :func:`faceted_lines` itself."""
    f = np.ascontiguousarray
    may = _lines.facet_pre(
        f(label, dtype=np.intp).reshape(-1),
        f(before.valid, dtype=bool).reshape(-1).view(np.uint8),
        f(before.d, dtype=float).reshape(-1), f(after.d, dtype=float).reshape(-1),
        f(before.sigma_m, dtype=float).reshape(-1), f(after.sigma_m, dtype=float).reshape(-1),
        f(before.origin_x, dtype=float).reshape(-1), f(before.origin_y, dtype=float).reshape(-1),
        f(before.heading, dtype=float).reshape(-1), SIGMA_FLOOR_M, FACET_MIN, FACET_SIDE,
        FACET_F, FACET_CHI, FACET_TURN_RAD, FACET_PRE_TOL)[-1]
    if not may.any():
        return after
    return faceted_lines(before, label, after, cal)


def _facet_asked(before: Points, label: np.ndarray, after: Points):
    """:func:`faceted_lines`' split search, numpy (the statement the compiled pre-gate
    ``_lines.facet_pre`` is held to): None where no line has ``FACET_MIN`` members the snap
    moved; else per such member (flat index ``idx``, line ``g``) its beam, reading and σ,
    its line's centre and direction, the members' order along their lines (``order``,
    ``gs``: sorted by line then ``s``), their weights ``w`` and sorted places ``at``; and per
    line its best split (``best``, a sorted place: the first member of the right-hand
    piece), that split's χ² ``split``, the F and χ² ``gain`` by which it beats the line and
    how much its pieces ``turn`` (rad)."""
    flat = label.reshape(-1)
    d0_all, sig_all = before.d.reshape(-1), before.sigma_m.reshape(-1)
    with np.errstate(invalid="ignore"):
        moved = ((flat >= 0) & before.valid.reshape(-1)
                 & ((after.d.reshape(-1) != d0_all) | (after.sigma_m.reshape(-1) != sig_all)))
    idx = moved.nonzero()[0]
    if idx.size < FACET_MIN:
        return None
    ask = np.bincount(flat[idx]) >= FACET_MIN
    if not ask.any():
        return None
    idx = idx[ask[flat[idx]]]
    g = np.unique(flat[idx], return_inverse=True)[1]
    n_g = int(g.max()) + 1
    nm = np.bincount(g, minlength=n_g).astype(float)
    ox, oy = before.origin_x.reshape(-1)[idx], before.origin_y.reshape(-1)[idx]
    h = before.heading.reshape(-1)[idx]
    ex, ey = np.cos(h), np.sin(h)
    d0, sig = d0_all[idx], sig_all[idx]
    x, y = ox + d0 * ex, oy + d0 * ey
    cx, cy = np.bincount(g, x, n_g) / nm, np.bincount(g, y, n_g) / nm
    u, v = x - cx[g], y - cy[g]
    al = 0.5 * np.arctan2(2.0 * np.bincount(g, u * v, n_g), np.bincount(g, u * u - v * v, n_g))
    ux, uy = np.cos(al)[g], np.sin(al)[g]
    s, r = u * ux + v * uy, -u * uy + v * ux
    order = np.lexsort((s, g))
    gs, ss, rs = g[order], s[order], r[order]
    w = 1.0 / np.maximum(sig[order], SIGMA_FLOOR_M) ** 2
    cum = [np.concatenate(([0.0], np.cumsum(w * q))) for q in
           (np.ones_like(ss), ss, ss * ss, rs, ss * rs, rs * rs)]
    start = np.searchsorted(gs, np.arange(n_g))
    end = np.append(start[1:], gs.size)

    def fit(a, b):
        """Weighted least-squares line of sorted members a … b − 1: (χ², slope); NaN where
        they are fewer than two (the split search masks those)."""
        W, S, S2, R, SR, R2 = (q[b] - q[a] for q in cum)
        with np.errstate(divide="ignore", invalid="ignore"):
            sss, ssr = S2 - S * S / W, SR - S * R / W
            m = ssr / sss
            return np.maximum(R2 - R * R / W - ssr * m, 0.0), m

    # every sorted member as the first of a right-hand piece; the best per line
    at = np.arange(gs.size)
    lo, hi = start[gs], end[gs]
    can = (at - lo >= FACET_SIDE) & (hi - at >= FACET_SIDE)
    chi_l, m_l = fit(lo, at)
    chi_r, m_r = fit(at, hi)
    both = np.where(can, chi_l + chi_r, np.inf)
    best = np.lexsort((both, gs))[start]            # each line's least χ² split
    chi0 = fit(start, end)[0]
    split = both[best]
    with np.errstate(divide="ignore", invalid="ignore"):
        F = (chi0 - split) / 2.0 / np.maximum(split / np.maximum(nm - 4, 1), 1e-300)
        gain = chi0 - split
    turn = np.abs(np.arctan(m_r[best]) - np.arctan(m_l[best]))
    return (idx, g, ox, oy, ex, ey, d0, sig, cx, cy, ux, uy, order, gs, w, at, best, split, F,
            gain, turn)


# --------------------------------------------------------------------------- fold-over

_FOLD_BLOCK_M = 0.25   # a known wall blocks a beam this far past its readings' ends …
_FOLD_ON_M = 0.10      # … and a reading lies on it this far past them
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
_CORNER_MIN_SIN = 0.1  # lines crossing at under ~6° (sine of the angle) make no corner …
_CORNER_PAST_M = 0.01  # … a line's span ends this far past the corner it meets
_FOLD_PAST_MAX = 6     # a line with at most this many members past a wall its last members'
#                        counts fit ahead of them did not run on past that wall: the few
#                        last readings of the steep wall before its drop-out (1-6 seen; a
#                        wall seen past such a line had 8 or more)
_FOLD_OWN_Z = 3.0      # a member whose own straight slope is this many standard errors off
#                        its line's θ, reading it > _UNKNOWN_M elsewhere, is not placed


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
        return np.abs(d1 - d2) > np.maximum(0.03, 3.0 * np.fmax(s1, s2))

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
                                _classify(np.asarray(sweep.counts, dtype=float), sweep, cal),
                                near | ambiguous, np.asarray(sweep.steps), cal,
                                min(float(sweep.max_range_m), cal.max_range_m))
    p = onto_concave_arcs(p, np.where(p.valid & ~put & ~keep & ~differ, second.lines.label, -1),
                          counts, cal, far_sigma_cap(cal, p.max_range_m))
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
    # … and one whose own profile reads it more than 100 mm from where its line puts it
    p = _disowned_by_own_profile(p, second.lines.label, sweep, cal, profiler)
    # a far reading whose own near trace is as straight as its far one: undecided (it took
    # part in the second pass as a far one, so the other readings are read as before)
    if doubted.any():
        p = _unplaced(p, (doubted & p.valid).reshape(-1).nonzero()[0], Reason.FOLDOVER_AMBIGUOUS)
    # a beam the judging pass, which saw every reading, found silent stays silent: the
    # second pass, its neighbours held out, put one the first silenced behind a wall it
    # met at 74° (silent_behind_a_wall) on a line at 69°, 127 mm short
    revived = p.valid & (q.reason == Reason.NO_RETURN)
    if revived.any():
        p = _unplaced(p, revived.reshape(-1).nonzero()[0], Reason.NO_RETURN)
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
        p = _unplaced(p, vague.reshape(-1).nonzero()[0])
    return replace(second, points=p, lines=second.lines if detail else None)


def _short_line_sigma(p: Points, second: Estimate, from_line: np.ndarray,
                      cal: Calibration) -> Points:
    """``p`` (the fold-over's result) with the σ of each valid far-branch reading that is read
    at the θ of a line of the second pass too short to be snapped onto (fewer than
    ``SNAP_MIN`` members; ``from_line``: it still has that line's θ) widened by that line's
    direction standard error (:func:`direction_se`), as a reading placed by its own
    profile's slope is (:func:`_own_slope_sigma`): half the spread of its distance over
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
    return _unplaced(p, gone.reshape(-1).nonzero()[0])


def _theta_unsupported(p: Points, no_first_line: np.ndarray, label: np.ndarray, sweep: Sweep,
                       cal: Calibration) -> Points:
    """``p`` (the fold-over's result) with INCIDENCE_UNKNOWN for each valid reading of
    ``no_first_line`` (far ones the judging pass, which saw every reading, put on no line)
    whose θ reads it more than ``_UNKNOWN_M`` from its θ = 0 distance, where that θ is a
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
    gone[ask] = np.abs(p.d[ask] - d0) > _UNKNOWN_M
    if not gone.any():
        return p
    return _unplaced(p, gone.reshape(-1).nonzero()[0])


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
    than both placements' 3σ together, while at most ``_FOLD_PAST_MAX`` members of its own
    line lie past that line: a wall's last readings before its drop-out, adopted at the θ of
    the wall past the corner, land behind the corner on that wall's extension, 100-220 mm
    long; nothing tells which wall they met. docs/foldover.md, "Past a wall its counts fit"."""
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
    fits = (ahead & (theta_l <= cal.max_incidence_rad) & (np.abs(t - d_l) <= tol)
            & (t + tol < d - 3.0 * sigma)
            & (walls[None, :] != first.label.reshape(-1)[idx][:, None]))
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
    gone = np.unique(idx[pa[past <= _FOLD_PAST_MAX]])
    if not gone.size:
        return p
    return _unplaced(p, gone)


def _unplaced(p: Points, gone: np.ndarray, why: Reason = Reason.INCIDENCE_UNKNOWN
              ) -> Points:
    """``p`` with the readings at flat indices ``gone`` made ``why`` (INCIDENCE_UNKNOWN by
    default): not valid, no end point, distance, θ or σ (:func:`invalidated`; its own name
    so that the fold-over's guards can be switched off in tests one by one)."""
    return invalidated(p, gone, why)


def _disowned_by_own_profile(p: Points, label: np.ndarray, sweep: Sweep, cal: Calibration,
                             profiler: Callable | None) -> Points:
    """``p`` (the fold-over's result) with INCIDENCE_UNKNOWN for each valid member of a line
    (``label``: the second pass's, −1 none) whose own range profile (:func:`range_profiles`;
    ``profiler``, the compiled :func:`profiles_compiled` by default) is straight and clearly
    steep at a θ more than ``_FOLD_OWN_Z`` standard errors from its line's, where the two
    θ read it more than ``_UNKNOWN_M`` apart: the first reading past a corner, taken in by
    the steep wall's line at 67° (its own slope: 25°), read 135 mm short.
    docs/foldover.md, "Past a wall its counts fit"."""
    if not (p.valid & (label >= 0)).any():
        return p
    steps = np.asarray(sweep.steps)
    index = scan_order(steps, p.valid.shape[1])
    vi = index[p.valid.reshape(-1)[index]]
    ask = (label.reshape(-1)[vi] >= 0).nonzero()[0]
    pr = (profiler or profiles_compiled)(p, vi, ask, sweep.counts, steps, cal)
    at = vi[ask]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (np.tan(p.theta.reshape(-1)[at]) - np.abs(pr.slope)) / pr.se
    apart = np.abs(p.d.reshape(-1)[at] - cal.distance(pr.s[ask], pr.theta)) > _UNKNOWN_M
    gone = at[pr.ok & (pr.se > 0) & (np.abs(z) > _FOLD_OWN_Z) & apart]
    if not gone.size:
        return p
    return _unplaced(p, gone)


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
    line = lab1[regain]
    ux, uy = np.cos(p.heading[regain]), np.sin(p.heading[regain])
    nx, ny = first.normal[line, 0], first.normal[line, 1]
    across = nx * ux + ny * uy
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((first.centroid[line, 0] - p.origin_x[regain]) * nx
             + (first.centroid[line, 1] - p.origin_y[regain]) * ny) / across
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


@functools.lru_cache(maxsize=16)
def nominal_calibration(sensor_model: str, ring: Ring | None, adc_bits: int, vref_v: float
                        ) -> Calibration:
    """:meth:`Calibration.for_sweep`'s calibration, built once per sensor/ring/ADC: its fine θ
    table (built on its first sweep) takes longer than estimating a sweep, and ``irring run``
    without a calibration file estimates every sweep with the default."""
    return Calibration.nominal(sensor_model, ring, adc_bits, vref_v)
