"""End points and lines, what the estimator's rules share: the compiled kernels, the options and
results (:class:`LineOptions`, :class:`Lines`, :class:`Estimate`), step 4 of Table II (end
points grouped into lines: polylines, split-and-merge, :func:`fit_lines`), readings placed or
invalidated, and line members snapped onto their lines (:func:`snap_to_lines`).

The schedule that runs them: :mod:`irring.estimation.estimate`; the long story:
docs/estimator.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..core import Points, Reason, points_with, rows_in_step_order, step_stride
from ..resources import kernel
from .calibration import SIGMA_FLOOR_M, Calibration, fallback_thetas, range_sigma


_lines = kernel("estimation._lines")


PINNED_RAD = math.radians(2.0)  # a line most readings meet within this of the drop-out angle
#                                  is a runaway, not a wall (see _drop_steep)


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


def segment(px, py, thr, sensor, opts: LineOptions, centre, prev: Pieces | None = None
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


def lines_record(pieces: Pieces | None, label: np.ndarray, index: np.ndarray) -> Lines:
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
    """Group the end points of a sweep into lines (split-and-merge, see :func:`segment`).

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
        return lines_record(None, label.reshape(shape), idx)
    px, py = x.reshape(-1)[idx], y.reshape(-1)[idx]
    thr = np.maximum(options.min_split_m,
                     options.split_sigmas * np.nan_to_num(sigma[idx], nan=0.0))
    pieces = segment(px, py, thr, idx % n_sensors, options, (float(px.mean()), float(py.mean())))
    label[idx] = pieces.owner
    return lines_record(pieces, label.reshape(shape), idx)


@dataclass(frozen=True)
class Estimate:
    """Points plus what the estimator saw (for plots, tests and benchmarks)."""

    points: Points
    lines: Lines | None
    theta_history: tuple[np.ndarray, ...] = field(default=())


def member_axes(points: Points, member: np.ndarray, label: np.ndarray) -> tuple:
    """Each line's principal axis through its members' end points (``member`` (S, N) bool,
    ``label`` (S, N) line index): (g, n, x, y, mx, my, u, v, alpha) — the members' lines
    and end points, each line's member count, mean point and direction angle (rad), and
    the members' offsets from their line's mean. Rules that fit the lines as the readings
    now lie share this one statement of the fit."""
    g = label[member]
    n = np.bincount(g)
    nn = np.maximum(n, 1)
    x, y = points.x[member], points.y[member]
    mx, my = np.bincount(g, x) / nn, np.bincount(g, y) / nn
    u, v = x - mx[g], y - my[g]
    alpha = 0.5 * np.arctan2(2.0 * np.bincount(g, u * v, n.size),
                             np.bincount(g, u * u, n.size) - np.bincount(g, v * v, n.size))
    return g, n, x, y, mx, my, u, v, alpha


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


SNAP_SIGMAS = 3.0   # a member moves out onto its line if that is within 3σ (in from behind: always) …
SNAP_MIN = 10       # … and the line has at least 10 members at step_stride 1 (short lines
#                     are less sure; :func:`snap_members`)
SNAP_OWN = 0.5      # share of a member's own σ kept in its σ on the line …
SNAP_OWN_CAP_M = 0.010  # … at most this where a part is read to its own range (far_sigma_cap)


def snap_members(steps: np.ndarray) -> int:
    """The members a line needs to be snapped to (:func:`snap_to_lines`) in a sweep of these
    motor ``steps`` (S,): ``SNAP_MIN`` where every step is read, ⌈``SNAP_MIN``/k⌉ where
    every k-th is (k the greatest common divisor of the steps between its rows), so that a
    line over the same stretch of wall, with 1/k of the readings, is snapped alike
    (docs/estimator.md, "Snapped at every stride")."""
    return -(-SNAP_MIN // step_stride(steps))


def snap_to_lines(points: Points, member: np.ndarray, min_range_m: float,
                  own_cap_m: float = math.inf, min_members: int = SNAP_MIN) -> Points:
    """End points of the readings on a line put where their beams meet it.

    ``member`` (S, N): the line each reading took θ from (−1: none). A valid member of a
    line of ≥ ``min_members`` (:func:`snap_members`) moves along its beam onto the line
    refitted to the members' end points (those a little past the max range too:
    :func:`drop_beyond_range`) when it lies behind it or ≤ 3σ short of it, within
    [``min_range_m``, ``points.max_range_m``]; its σ becomes the line's there with half its
    own added (at most ``own_cap_m``). Compiled; the numpy statement and the why:
    :func:`irring.estimation.estimate_numpy.snap_to_lines`."""
    f = np.ascontiguousarray
    moved = _lines.snap_to_lines(
        f(member, dtype=np.intp).reshape(-1),
        f(points.valid, dtype=bool).reshape(-1).view(np.uint8),
        *(f(getattr(points, k), dtype=float).reshape(-1)
          for k in ("x", "y", "d", "sigma_m", "heading", "origin_x", "origin_y")),
        int(min_members), SNAP_SIGMAS, SNAP_OWN, float(own_cap_m), SIGMA_FLOOR_M,
        float(min_range_m), float(points.max_range_m))
    if moved is None:
        return points
    shape = points.valid.shape
    x, y, d, sigma = (v.reshape(shape) for v in moved)
    return points_with(points, x=x, y=y, d=d, sigma_m=sigma)


def unplaced(p: Points, gone: np.ndarray, why: Reason = Reason.INCIDENCE_UNKNOWN
              ) -> Points:
    """``p`` with the readings at flat indices ``gone`` made ``why`` (INCIDENCE_UNKNOWN by
    default): not valid, no end point, distance, θ or σ (:func:`invalidated`; its own name
    so that the fold-over's guards can be switched off in tests one by one)."""
    return invalidated(p, gone, why)
