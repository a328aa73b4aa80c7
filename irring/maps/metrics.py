"""Ground truth on the map's grid (:func:`ground_truth`) and how well a map matches it
(:func:`score`: occupied precision, recall and F1, free accuracy, coverage, shadow; 0 … 1
with a 1-cell tolerance; None, reported as n/a, where a score's denominator is empty). The
definitions: docs/mapping.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .mapping import FREE, OCCUPIED, OccupancyGrid, traverse
from .. import gp2
from ..core import (GEOMETRY_TOL_M, Cylinder, Ring, box_corners, distance_to_outline,
                    first_wall_into, inside_obstacle, inside_outline, obstacle_bounds,
                    obstacle_distance)
from ..resources import kernel
from ..estimation.calibration import Calibration
from ..scenario import ReflectanceEffect, Scenario

_traverse = kernel("maps._traverse")

EXTERIOR = -1   # beyond the walls
FREE_SPACE = 0  # inside the room, no material at the cell centre
WALL = 1        # wall material (the label of obstacle j is OBSTACLE0 + j)
OBSTACLE0 = 2

SCORE_KEYS = ("occupied_precision", "occupied_recall", "occupied_f1", "free_accuracy",
              "coverage", "shadow")
# why a shadow is n/a (score's None): GroundTruth.shadow is empty. Wall out of reach, or one
# pose cannot see past a table leg and another pose sees, is no shadow ("nothing hidden"
# and "no post here" misled); `irring run`'s summary and `irring compare` say it so
SHADOW_NA = "no wall in the sensors' reach is hidden behind an obstacle from every pose centre"


@dataclass(frozen=True)
class GroundTruth:
    """The scenario on the map's cells; all arrays (ny, nx) like ``OccupancyGrid.log_odds``."""

    label: np.ndarray          # int16: EXTERIOR, FREE_SPACE, WALL or OBSTACLE0 + j (cell centre)
    surface: np.ndarray        # bool: a sensed surface crosses the cell
    surface_owner: np.ndarray  # int16: WALL or OBSTACLE0 + j for surface cells, else 0
    surface_point: np.ndarray  # (ny, nx, 2) m: the surface point nearest each surface
    #                            cell's centre (what "in range" measures to), else NaN
    surface_normal: np.ndarray  # (ny, nx, 2): unit normal of the surface there, pointing to
    #                              the side it faces (into the room, out of an obstacle); else NaN
    surface_reflectance: np.ndarray  # (ny, nx): reflectance of the surface there, else NaN
    occupied: np.ndarray       # bool: surface or material
    free: np.ndarray           # bool: free space and not surface
    in_range: np.ndarray       # bool: within max range + ring radius of some view (a scan
    #                            pose, or a moving ring's steps: views)
    visible: np.ndarray        # bool: surface cells seen from a view (in range, line of
    #                            sight, giving the scene's sensor a return: Returns) and met
    #                            there by a sensor's beam from the front (_met)
    reachable_free: np.ndarray  # bool: free cells in range and line of sight of some view
    shadow: np.ndarray         # bool: wall surface cells hidden behind an obstacle from
    #                            a radial ring at the pose centre (docs/mapping.md)
    shadow_ranged: np.ndarray  # bool: shadow cells a sensor could range along a clear line
    shadow_owner: np.ndarray   # int16: OBSTACLE0 + j casting the shadow (first pose that has it)
    reach_m: float             # max range + ring radius used for "in range"


# --------------------------------------------------------------------------- geometry on cells


def _outline_samples(points: np.ndarray, step_m: float, *, inward: bool
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Points every ``step_m`` along a closed polygon (including every corner) and the unit
    normal of the side each lies on (a corner takes its first side's), pointing into the
    polygon (``inward``: a room's walls face in) or out of it (an obstacle's faces out),
    whichever way round its corners are listed."""
    pts = np.asarray(points, float)
    x, y = pts[:, 0], pts[:, 1]
    counter_clockwise = float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)) > 0
    sign = 1.0 if counter_clockwise == inward else -1.0   # the left normal points in on a CCW turn
    out, normals = [], []
    for a, b in zip(pts, np.roll(pts, -1, axis=0)):
        side = b - a
        length = float(np.hypot(*side))
        n = max(int(math.ceil(length / step_m)), 1)
        t = np.arange(n + 1)[:, None] / n
        out.append(a + t * side)
        normal = sign * np.array([-side[1], side[0]]) / length if length > 0 else np.zeros(2)
        normals.append(np.broadcast_to(normal, (n + 1, 2)))
    return np.concatenate(out), np.concatenate(normals)


def _surface_samples(ob, step_m: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_outline_samples` of an obstacle's perimeter (a cylinder's normals radial)."""
    if isinstance(ob, Cylinder):
        n = max(int(math.ceil(2 * math.pi * ob.radius_m / step_m)), 8)
        a = np.arange(n) * (2 * math.pi / n)
        radial = np.stack([np.cos(a), np.sin(a)], axis=1)
        return np.asarray(ob.center_m, float) + ob.radius_m * radial, radial
    return _outline_samples(box_corners(ob), step_m, inward=False)


def _in_room(samples: tuple[np.ndarray, np.ndarray], outline) -> tuple[np.ndarray, np.ndarray]:
    """The surface samples (points, normals) inside the room or on its outline."""
    points, normals = samples
    keep = (inside_outline(points[:, 0], points[:, 1], outline)
            | (distance_to_outline(points[:, 0], points[:, 1], outline) <= GEOMETRY_TOL_M))
    return points[keep], normals[keep]


def _outside_obstacles(samples: tuple[np.ndarray, np.ndarray], obstacles
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The wall surface samples (points, normals) not covered by an obstacle: where a box
    stands flush against a wall or is built into it, that stretch of wall is no face."""
    points, normals = samples
    keep = np.ones(len(points), bool)
    order = np.argsort(points[:, 0], kind="stable")   # each obstacle asks the samples near it
    sorted_x = points[order, 0]
    for ob in obstacles:
        (x0, y0), (x1, y1) = obstacle_bounds(ob)   # wider than GEOMETRY_TOL_M
        idx = order[np.searchsorted(sorted_x, x0):np.searchsorted(sorted_x, x1, side="right")]
        idx = idx[(points[idx, 1] >= y0) & (points[idx, 1] <= y1)]
        keep[idx] &= obstacle_distance(ob, points[idx, 0], points[idx, 1]) > GEOMETRY_TOL_M
    return points[keep], normals[keep]


def _nearest_to_centres(samples: np.ndarray, cell: np.ndarray, cx: np.ndarray,
                        cy: np.ndarray) -> np.ndarray:
    """(ny, nx) on the grid of cell centres ``cx``, ``cy`` (ny, nx; m): for each cell
    holding surface ``samples`` (m; ``cell`` their flat cell index), the index of the sample
    nearest its centre; −1 in cells without one. A wall along a cell's edge lies half a cell
    from the centre: judged at the centre, wall 629 mm from a sensor counted as in its
    624 mm reach."""
    out = np.full(cx.size, -1, np.intp)
    if cell.size:
        dist = np.hypot(samples[:, 0] - cx.take(cell), samples[:, 1] - cy.take(cell))
        order = np.lexsort((dist, cell))
        first = np.unique(cell[order], return_index=True)[1]
        pick = order[first]
        out[cell[pick]] = pick
    return out.reshape(cx.shape)


def _dilate(mask: np.ndarray) -> np.ndarray:
    """3 × 3 binary dilation (the 1-cell tolerance)."""
    p = np.pad(mask, 1)
    ny, nx = mask.shape
    out = np.zeros_like(mask)
    for dy in range(3):
        for dx in range(3):
            out |= p[dy:dy + ny, dx:dx + nx]
    return out


def _chebyshev_near(ix, iy, tx, ty) -> np.ndarray:
    return (np.abs(ix - tx) <= 1) & (np.abs(iy - ty) <= 1)


def _sight(grid_shape, origin, res, material_label, pose_xy, targets_ix, targets_iy):
    """For cells seen from ``pose_xy`` (m; or one point per cell, two arrays): the label of
    the first material cell on the way (0 when the line of sight is clear). Material within
    1 cell of the target is ignored.

    The compiled walk stops at that cell and lists no visits (``_traverse.first_material``;
    :func:`_sight_oracle` is the readable statement it is tested against; docs/mapping.md)."""
    n = len(targets_ix)
    if n == 0:
        return np.zeros(0, np.int16)
    # in cells from the grid's corner, computed as traverse computes them (the same walk)
    x0 = np.ascontiguousarray(np.broadcast_to((np.asarray(pose_xy[0]) - origin[0]) / res, n))
    y0 = np.ascontiguousarray(np.broadcast_to((np.asarray(pose_xy[1]) - origin[1]) / res, n))
    dx = (origin[0] + (targets_ix + 0.5) * res - origin[0]) / res - x0
    dy = (origin[1] + (targets_iy + 0.5) * res - origin[1]) / res - y0
    return _traverse.first_material(x0, y0, dx, dy,
                                    np.ascontiguousarray(material_label, np.int16),
                                    np.ascontiguousarray(targets_ix, np.intp),
                                    np.ascontiguousarray(targets_iy, np.intp))


def _sight_oracle(grid_shape, origin, res, material_label, pose_xy, targets_ix, targets_iy):
    """:func:`_sight` in numpy: every visit of every line of sight (:func:`traverse`), then the
    first blocking one per line."""
    cx = origin[0] + (targets_ix + 0.5) * res
    cy = origin[1] + (targets_iy + 0.5) * res
    n = len(targets_ix)
    if n == 0:
        return np.zeros(0, np.int16)
    v = traverse(np.broadcast_to(pose_xy[0], n), np.broadcast_to(pose_xy[1], n), cx, cy, origin,
                 grid_shape, res)
    lab = material_label[v.iy, v.ix]
    block = (lab > 0) & ~_chebyshev_near(v.ix, v.iy, targets_ix[v.ray], targets_iy[v.ray])
    first_label = np.zeros(n, np.int16)
    hit_rays = v.ray[block]
    if len(hit_rays):
        # visits are ordered along each ray, so the first blocking visit per ray comes first
        rays, first = np.unique(hit_rays, return_index=True)
        first_label[rays] = lab[block][first]
    return first_label


def _reach_m(scenario: Scenario) -> float:
    try:
        radius = scenario.ring.radius_m
    except ValueError:  # a design without a ring preset (e.g. a scanner at the centre)
        radius = 0.0
    return scenario.sensor.max_range_m + radius


@dataclass(frozen=True)
class Returns:
    """What, beyond range and line of sight, the scene's sensor needs to return a reading
    from a surface point: its curve ``model`` (gp2 name); with the ``incidence`` effect, an
    incidence ≤ ``max_incidence_rad`` and a voltage no weaker than nothing in range gives
    (a(θ), b(θ) dim a slanted return: a wall 600 mm off at 65° reads as 825 mm); with the
    ``reflectance`` effect, a signal ≥ ``min_signal`` (None: the effect is off)."""

    model: str
    max_incidence_rad: float | None = None
    min_signal: float | None = None
    # with the scene's noise, the farthest a surface square on returns a reading at least as
    # often as not (Calibration.return_range_m), where that is short of the max range
    # (a GP2Y0A21 read to 800 mm: 687 mm with 15 mV); None: the max range
    return_range_m: float | None = None


def _returns(scenario: Scenario) -> Returns:
    effects = scenario.effects
    model = gp2.sensor(scenario.sensor.model)
    incidence, reflectance = effects.get("incidence"), effects.get("reflectance")
    try:
        scenario.ring
    except ValueError:   # a design without a ring preset: its sensor's own max range
        reach = math.inf
    else:
        reach = Calibration.for_scene(scenario).return_range_m
    return Returns(model=scenario.sensor.model,
                   max_incidence_rad=None if incidence is None else incidence.drop_out_rad(model),
                   min_signal=None if reflectance is None else reflectance.min_signal,
                   return_range_m=reach if reach < scenario.sensor.max_range_m else None)


def visible_range_m(scenario: Scenario) -> float | None:
    """How far a surface square on counts as visible wall (m), where the scene's noise makes
    that shorter than its max range (:class:`Returns`); None where it does not."""
    return _returns(scenario).return_range_m


def _ranging(scenario: Scenario) -> tuple[Ring, float, float, float, float, Returns]:
    """:func:`_geometric_ranging` and what the scene's effects need of a surface for a
    return (:class:`Returns`)."""
    return _geometric_ranging(scenario) + (_returns(scenario),)


def _geometric_ranging(scenario: Scenario) -> tuple[Ring, float, float, float, float]:
    """(ring, min and max range m, sensor angles lo and hi rad) of what a sensor can range:
    the sensor model's measuring interval and the ring's sweep, widened to at least ± half
    the sensor spacing (see :func:`_measurable`)."""
    try:
        ring = scenario.ring
    except ValueError:  # a design without a ring preset: one sensor at the centre, any way
        ring = Ring(sensors=1, radius_m=0.0, emitter_offset_m=0.0)
    turn = ring.motor_step_rad * ring.gear
    lo, hi = ring.min_step * turn, ring.max_step * turn
    half = math.pi / ring.sensors
    return (ring, gp2.sensor(scenario.sensor.model).min_range_m, scenario.sensor.max_range_m,
            min(lo, -half), max(hi, half))


def _gives_return(t, psi, d_max: float, returns: Returns, surface) -> np.ndarray:
    """Whether beams of heading ``psi`` (rad) meeting ``surface`` = (normal x, normal y,
    reflectance) at ``t`` m along them return a reading (:class:`Returns`), judged on the
    noise-free reading, which must also lie within ``return_range_m`` where the scene's
    noise sets a return level short of the max range."""
    model = gp2.sensor(returns.model)
    nx, ny, rho = surface
    ok = np.ones(np.shape(t), bool)
    t = np.maximum(t, 1e-9)
    reach = d_max if returns.return_range_m is None else min(d_max, returns.return_range_m)
    if returns.max_incidence_rad is not None:
        theta = np.arccos(np.minimum(np.abs(np.cos(psi) * nx + np.sin(psi) * ny), 1.0))
        read_square_on = model.distance(model.voltage(t, theta))   # what its voltage means
        ok &= (theta <= returns.max_incidence_rad) & (read_square_on <= reach)
    elif returns.return_range_m is not None:
        ok &= t <= reach
    if returns.min_signal is not None:
        ok &= ReflectanceEffect.signal(rho, t, model.max_range_m) >= returns.min_signal
    return ok


def _geometry(px, py, pose, ring: Ring, d_min: float, d_max: float, a_lo: float, a_hi: float):
    """Per sensor k of ``ring`` at ``pose``: (can, t, psi, ex, ey) for points (m): whether
    sensor k, its hinge at the ring radius, turned to the angle that puts the point on its
    beam (the emitter d_o to the beam's right) within [a_lo, a_hi] of radial, finds it at a
    distance t within [d_min, d_max] of the emitter; the beam's heading psi; where that
    emitter then is."""
    d_o = ring.emitter_offset_m
    for k in range(ring.sensors):
        rho = pose.yaw_rad + 2.0 * math.pi * k / ring.sensors
        hx = pose.x_m + ring.radius_m * math.cos(rho)
        hy = pose.y_m + ring.radius_m * math.sin(rho)
        vx, vy = px - hx, py - hy
        t = np.sqrt(np.maximum(vx * vx + vy * vy - d_o * d_o, 0.0))  # along the beam
        psi = np.arctan2(vy, vx) + np.arctan2(d_o, t)                 # the beam's heading
        can = ((t >= d_min) & (t <= d_max)
               & (np.mod(psi - rho - a_lo, 2.0 * math.pi) <= a_hi - a_lo))
        yield can, t, psi, hx + d_o * np.sin(psi), hy - d_o * np.cos(psi)


def _checks(returns: Returns | None, surface) -> bool:
    """Whether ``returns`` asks anything of the surface (ValueError if ``surface`` is None)."""
    check = returns is not None and (returns.max_incidence_rad is not None
                                     or returns.min_signal is not None
                                     or returns.return_range_m is not None)
    if check and surface is None:
        raise ValueError("the scene's effects make returns depend on the surface: pass "
                         "surface=(normal x, normal y, reflectance)")
    return check


def _sensor_views(px, py, pose, ring: Ring, d_min: float, d_max: float, a_lo: float,
                  a_hi: float, returns: Returns | None = None, *, surface=None):
    """Per sensor k of ``ring`` at ``pose``: (can, ex, ey) for points (m): :func:`_geometry`'s
    ``can`` and, by ``returns``, a return from the point; where the emitter then is.
    ``surface``: (normal x, normal y, reflectance) of each point, needed when ``returns``
    asks for incidence or reflectance (else ValueError)."""
    check = _checks(returns, surface)
    for can, t, psi, ex, ey in _geometry(px, py, pose, ring, d_min, d_max, a_lo, a_hi):
        if check:
            can &= _gives_return(t, psi, d_max, returns, surface)
        yield can, ex, ey


def _measurable(px, py, pose, *ranging, surface=None) -> np.ndarray:
    """Points (m) some sensor of the ring at ``pose`` could range (:func:`_sensor_views`;
    ``ranging`` from :func:`_ranging`)."""
    ok = np.zeros(np.shape(px), bool)
    for can, _, _ in _sensor_views(px, py, pose, *ranging, surface=surface):
        ok |= can
    return ok


def _measurable_returning(px, py, pose, ranging, surface) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_measurable` of surface points without and with ``ranging``'s :class:`Returns`,
    in one pass over the sensors."""
    ring, d_min, d_max, a_lo, a_hi, returns = ranging
    check = _checks(returns, surface)
    reach = np.zeros(np.shape(px), bool)
    ret = np.zeros(np.shape(px), bool)
    for can, t, psi, _, _ in _geometry(px, py, pose, ring, d_min, d_max, a_lo, a_hi):
        reach |= can
        if check:   # asked only of the points in reach (most of a moving view's are not)
            at = np.flatnonzero(can & ~ret)
            ret[at[_gives_return(t[at], psi[at], d_max, returns,
                                 tuple(a[at] for a in surface))]] = True
        else:
            ret |= can
    return reach, ret


# A beam meets a surface point when its way to this far (in cells) before the point is clear
# (:func:`_clear_way`).
ARRIVAL_CELLS = 0.05
# Points per cell along a surface where the truth asks whether a beam meets it: a post's
# flank cell may be met only on a sliver at its edge (a 10 mm cell on a post of radius 11 mm:
# 6° of its 36° of arc, 1 mm)
MET_SAMPLES_PER_CELL = 16


def _clear_way(scenario: Scenario, x0, y0, x1, y1) -> np.ndarray:
    """Whether the segments (x0, y0) → (x1, y1) (m) run through free space: they start in the
    room, cross no wall of its outline and enter no obstacle (exact geometry, not cells)."""
    dx, dy = x1 - x0, y1 - y0
    outline = np.asarray(scenario.room.outline_m, float)
    clear = inside_outline(x0, y0, outline)
    for (ax, ay), (bx, by) in zip(outline, np.roll(outline, -1, axis=0)):
        ex, ey = bx - ax, by - ay
        s0 = dx * (ay - y0) - dy * (ax - x0)          # which side of the segment a and b lie
        s1 = dx * (by - y0) - dy * (bx - x0)
        t0 = ex * (y0 - ay) - ey * (x0 - ax)          # … and the segment's ends of the wall
        t1 = ex * (y1 - ay) - ey * (x1 - ax)
        clear &= ~((s0 * s1 <= 0) & (t0 * t1 <= 0) & ((s0 != s1) | (t0 != t1)))
    for ob in scenario.obstacles:
        if isinstance(ob, Cylinder):
            cx, cy = ob.center_m
            with np.errstate(invalid="ignore", divide="ignore"):
                t = np.clip(((cx - x0) * dx + (cy - y0) * dy) / (dx * dx + dy * dy), 0.0, 1.0)
            t = np.nan_to_num(t)
            clear &= np.hypot(x0 + t * dx - cx, y0 + t * dy - cy) > ob.radius_m
        else:   # a box: the segment in its frame, clipped to its extent (Liang–Barsky)
            c, s = math.cos(ob.yaw_rad), math.sin(ob.yaw_rad)
            px, py = x0 - ob.center_m[0], y0 - ob.center_m[1]
            lo, hi = np.zeros(np.shape(x0)), np.ones(np.shape(x0))
            for p0, dp, half in ((c * px + s * py, c * dx + s * dy, ob.size_m[0] / 2),
                                 (-s * px + c * py, -s * dx + c * dy, ob.size_m[1] / 2)):
                with np.errstate(invalid="ignore", divide="ignore"):
                    ta, tb = (-half - p0) / dp, (half - p0) / dp
                flat = dp == 0
                lo = np.where(flat, np.where(np.abs(p0) <= half, lo, 2.0),
                              np.maximum(lo, np.minimum(ta, tb)))
                hi = np.where(flat, hi, np.minimum(hi, np.maximum(ta, tb)))
            clear &= ~(lo <= hi)
    return clear


def _met(scenario: Scenario, grid: OccupancyGrid, px, py, tx, ty, surface, pose,
         ranging) -> np.ndarray:
    """Per surface point (m; in cells ``tx``, ``ty``; ``surface``: its normal towards the free
    side and reflectance), whether some sensor of the ring at ``pose`` meets a point of its
    cell: within its sweep and measuring interval, with a return (``ranging``'s
    :class:`Returns`), from the front (the beam heads against the normal; a corner's point
    is judged once per side) and through free space from its emitter to just before the
    point (:func:`_clear_way`)."""
    ring, d_min, d_max, a_lo, a_hi, returns = ranging
    check = _checks(returns, surface)
    eps = ARRIVAL_CELLS * grid.resolution_m
    cell = np.unique(ty * grid.shape[1] + tx, return_inverse=True)[1].ravel()
    met = np.zeros(int(cell.max()) + 1 if cell.size else 0, bool)
    ways = []                                     # (point, emitter x, y, beam x, y) to check
    for can, t, psi, ex, ey in _geometry(px, py, pose, ring, d_min, d_max, a_lo, a_hi):
        ask = np.flatnonzero(can)
        if check:
            ask = ask[_gives_return(t[ask], psi[ask], d_max, returns,
                                    tuple(a[ask] for a in surface))]
        ux, uy = np.cos(psi[ask]), np.sin(psi[ask])
        front = ux * surface[0][ask] + uy * surface[1][ask] < 0
        ways.append((ask[front], ex[ask][front], ey[ask][front], ux[front], uy[front]))
    at, ex, ey, ux, uy = (np.concatenate(w) for w in zip(*ways))
    clear = _clear_way(scenario, ex, ey, px[at] - eps * ux, py[at] - eps * uy)
    met[cell[at[clear]]] = True
    return met[cell]


def _surface_at(cells, surface_point, surface_normal, surface_reflectance):
    """(ty, tx, x, y, (normal x, normal y, reflectance)) of the ``cells`` (bool grid)."""
    ty, tx = np.nonzero(cells)
    n = surface_normal[ty, tx]
    return (ty, tx, surface_point[ty, tx, 0], surface_point[ty, tx, 1],
            (n[:, 0], n[:, 1], surface_reflectance[ty, tx]))


def _ranged_in_sight(the_views: list[View], grid: OccupancyGrid, material: np.ndarray,
                     cells: np.ndarray, surface_point: np.ndarray, ranging) -> np.ndarray:
    """The surface ``cells`` (bool, on the grid) some sensor of some view (:func:`views`)
    could range (at their ``surface_point``; ``ranging`` without :class:`Returns`) along a
    clear line from its emitter (no material on the way but within 1 cell of the cell)."""
    ty, tx = np.nonzero(cells)
    px, py = surface_point[ty, tx, 0], surface_point[ty, tx, 1]
    ok = np.zeros(len(tx), bool)
    for view in the_views if len(tx) else ():
        for can, ex, ey in _sensor_views(px, py, view, *_windowed(ranging, view)):
            ask = can & ~ok
            if ask.any():
                first = _sight(grid.shape, grid.origin_xy_m, grid.resolution_m, material,
                               (ex[ask], ey[ask]), tx[ask], ty[ask])
                ok[np.flatnonzero(ask)[first == 0]] = True
    out = np.zeros(cells.shape, bool)
    out[ty[ok], tx[ok]] = True
    return out


# lines of sight walked per call while scoring: a progress bar moves between them (a 1 mm
# grid of a few m² walks ~10⁹ cells a pose: half a minute)
SIGHT_CHUNK_CELLS = 200_000
# A moving ring's steps are judged in groups whose hinges move at most this many cells
# (travel + ring radius × turn): each step's pose within a cell of its group's, ~20 groups a
# sweep at 50 mm/s with t_room_moving's 75 ms settle instead of 71 steps
VIEW_SPAN_CELLS = 2.0


@dataclass(frozen=True)
class View:
    """Where the ground truth judges the ring from: the robot's pose (x m, y m, yaw rad) and
    the sensor angles from radial its sensors turned through there, [a_lo, a_hi] rad;
    ``full``: the whole sweep (a standing ring; reach is then a disc around the pose)."""

    x_m: float
    y_m: float
    yaw_rad: float
    a_lo: float
    a_hi: float
    full: bool


def views(scenario: Scenario, grid: OccupancyGrid) -> list[View]:
    """The ring's views of a scene: a full sweep at each scan pose; with ``motion``, the
    steps of every sweep taken along the drive at the true pose of their reads
    (``dynamics.Drive``), grouped so each group's hinges move at most
    :data:`VIEW_SPAN_CELLS` of ``grid``'s cells, never a listed pose the drive did not
    sweep at (docs/mapping.md, "A moving ring's truth")."""
    ring, _, _, a_lo, a_hi = _geometric_ranging(scenario)
    if not scenario.has("motion"):
        return [View(p.x_m, p.y_m, p.yaw_rad, a_lo, a_hi, True) for p in scenario.robot.poses]
    from ..simulation.dynamics import Drive   # deferred: MuJoCo, only for a moving scene

    drive = Drive.of(scenario)
    a = drive.sensor_rad
    order = np.argsort(a, kind="stable")
    edge = (a[order][1:] + a[order][:-1]) / 2      # each step's share of the sweep …
    lo, hi = np.empty_like(a), np.empty_like(a)
    lo[order] = np.concatenate([[min(a_lo, a[order][0])], edge])
    hi[order] = np.concatenate([edge, [max(a_hi, a[order][-1])]])   # … ends as the static
    out = []
    tol = VIEW_SPAN_CELLS * grid.resolution_m
    for poses in drive.poses:     # a sweep at a time, vectorised over its steps
        move = np.concatenate([[0.0], np.hypot(*np.diff(poses[:, :2], axis=0).T)
                               + ring.radius_m * np.abs(np.diff(poses[:, 2]))])
        group = np.floor(np.cumsum(move) / tol).astype(np.intp)
        starts = np.flatnonzero(np.diff(group, prepend=-1))
        ends = np.append(starts[1:], len(poses))
        mid = (starts + ends - 1) // 2
        turn = poses[:, 2] - poses[np.repeat(mid, ends - starts), 2]   # yaw from the group's
        g_lo = np.minimum.reduceat(lo + turn, starts)
        g_hi = np.maximum.reduceat(hi + turn, starts)
        for k, i in enumerate(mid):
            full = bool(g_lo[k] <= a_lo and g_hi[k] >= a_hi)
            out.append(View(*(float(v) for v in poses[i]), float(g_lo[k]), float(g_hi[k]),
                            full))
    return out


def _windowed(ranging: tuple, view: View) -> tuple:
    """``ranging`` (:func:`_ranging` or :func:`_geometric_ranging`) with ``view``'s sensor
    angles."""
    return ranging[:3] + (view.a_lo, view.a_hi) + ranging[5:]


def _box(grid: OccupancyGrid, view: View, reach: float) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1): the cells [x0, x1) × [y0, y1) of the grid in the bounding box of
    the disc of ``reach`` around the view's centre (empty when x1 <= x0 or y1 <= y0)."""
    (x0, x1), (y0, y1) = grid.cell_of(np.array([view.x_m - reach, view.x_m + reach]),
                                      np.array([view.y_m - reach, view.y_m + reach]))
    ny, nx = grid.shape
    return max(x0, 0), max(y0, 0), min(x1 + 1, nx), min(y1 + 1, ny)


def _box_cells(grid: OccupancyGrid, view: View, reach: float) -> int:
    x0, y0, x1, y1 = _box(grid, view, reach)
    return max(x1 - x0, 0) * max(y1 - y0, 0)


def _disc(free: np.ndarray, grid: OccupancyGrid, view: View, reach: float
          ) -> tuple[np.ndarray, np.ndarray]:
    """(flat index, distance m) of the ``free`` cells whose centres lie within ``reach`` of
    the view's centre (only the cells of the disc's bounding box, :func:`_box`, are looked
    at)."""
    x0, y0, x1, y1 = _box(grid, view, reach)
    nx = grid.shape[1]
    if x1 <= x0 or y1 <= y0:
        return np.zeros(0, np.intp), np.zeros(0)
    ty, tx = np.nonzero(free[y0:y1, x0:x1])
    ty, tx = ty + y0, tx + x0
    xs, ys = grid.cell_centers()
    d = np.hypot(xs[tx] - view.x_m, ys[ty] - view.y_m)
    keep = d <= reach
    return ty[keep] * nx + tx[keep], d[keep]


def _in_window(cells: np.ndarray, dist: np.ndarray, grid: OccupancyGrid, view: View,
               ranging: tuple) -> np.ndarray:
    """Which free ``cells`` (flat; ``dist`` m from the view's centre, within its reach) a
    partial view's beams cross: a beam from some sensor's hinge (radius R) at an angle in
    [a_lo, a_hi] from radial, or inside the ring (a standing ring's disc holds those too).
    A point D from the centre on a beam at angle a (its emitter d_o to the right of the
    hinge) lies at bearing b(a) = φ − asin(R sin φ / D) from that hinge's radial, φ = a −
    asin(d_o / |HP|) its direction from the hinge (increasing in a for D > R), so one
    bearing per cell answers for all the sensors at once."""
    ring, a_lo, a_hi = ranging[0], ranging[3], ranging[4]
    xs, ys = grid.cell_centers()
    ty, tx = np.divmod(cells, grid.shape[1])
    r, d_o = ring.radius_m, ring.emitter_offset_m
    d = np.maximum(dist, r * (1.0 + 1e-9))

    def bearing_of(a):
        from_hinge = np.sqrt(d * d - (r * math.sin(a)) ** 2) - r * math.cos(a)
        phi = a - np.arcsin(np.clip(d_o / np.maximum(from_hinge, d_o), 0.0, 1.0))
        return phi - np.arcsin(np.clip(r * np.sin(phi) / d, -1.0, 1.0))

    lo, hi = bearing_of(a_lo), bearing_of(a_hi)
    spacing = 2.0 * math.pi / ring.sensors
    bearing = np.arctan2(ys[ty] - view.y_m, xs[tx] - view.x_m) - view.yaw_rad
    return (dist <= r) | (np.mod(bearing - lo, spacing) <= hi - lo) | (hi - lo >= spacing)


def ground_truth(scenario: Scenario, grid: OccupancyGrid, bar=None) -> GroundTruth:
    """Rasterise the scenario onto ``grid``'s cells and work out what each view (:func:`views`)
    can see.
    ``bar``: a progress bar (``reset(total)``, ``update(n)``) counting each view's cells (the
    box around its reach, its surface cells in reach), moving as their lines of sight are
    walked."""
    res = grid.resolution_m
    origin = grid.origin_xy_m
    ny, nx = grid.shape
    xs, ys = grid.cell_centers()
    px, py = np.meshgrid(xs, ys)
    outline = scenario.room.outline_m

    # material at cell centres: walls outward of the outline, obstacles where they stand
    inside = inside_outline(px, py, outline)
    dist = distance_to_outline(px, py, outline, within=scenario.room.wall_thickness_m)
    eps = 1e-9
    label = np.full(px.shape, EXTERIOR, np.int16)
    label[inside] = FREE_SPACE
    label[~inside & (dist > eps) & (dist <= scenario.room.wall_thickness_m)] = WALL
    # an obstacle reaching through a wall is clipped there: nothing of it beyond the walls
    # (the scene's walls hide that part, so it is no truth to map)
    through = [first_wall_into(ob, outline) is not None for ob in scenario.obstacles]
    for j, ob in enumerate(scenario.obstacles):   # asked only of the cells around it
        (x0, y0), (x1, y1) = obstacle_bounds(ob)
        near = (slice(np.searchsorted(ys, y0), np.searchsorted(ys, y1, side="right")),
                slice(np.searchsorted(xs, x0), np.searchsorted(xs, x1, side="right")))
        block = label[near]   # a view: written through
        block[inside_obstacle(ob, px[near], py[near]) & (block != EXTERIOR)] = OBSTACLE0 + j

    # surfaces: sample the outline and obstacle perimeters finely, mark the cells they fall in
    surface_owner = np.zeros(px.shape, np.int16)

    def sampled(step, mark=False):
        """(points, normals towards the free side, reflectance, flat cell) every ``step`` m
        along every surface inside the grid; ``mark``: their cells in surface_owner."""
        parts = [(_outside_obstacles(_outline_samples(np.asarray(outline, float), step,
                                                      inward=True), scenario.obstacles),
                  scenario.room.reflectance, WALL)]
        parts += [(_in_room(_surface_samples(ob, step), outline) if through[j] else
                   _surface_samples(ob, step), ob.reflectance, OBSTACLE0 + j)
                  for j, ob in enumerate(scenario.obstacles)]
        out = []
        for (points, normals), reflectance, owner in parts:
            ix, iy = grid.cell_of(points[:, 0], points[:, 1])
            ok = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
            if mark:
                surface_owner[iy[ok], ix[ok]] = owner
            out.append((points[ok], normals[ok], np.full(int(ok.sum()), float(reflectance)),
                        iy[ok] * nx + ix[ok]))
        return tuple(np.concatenate(m) for m in zip(*out))

    samples, normals, rho, cells = sampled(res / 4, mark=True)
    surface = surface_owner > 0
    pick = _nearest_to_centres(samples, cells, px, py)
    has = pick >= 0
    surface_point = np.full(px.shape + (2,), np.nan)
    surface_point[has] = samples[pick[has]]
    surface_normal = np.full(px.shape + (2,), np.nan)
    surface_normal[has] = normals[pick[has]]
    surface_reflectance = np.full(px.shape, np.nan)
    surface_reflectance[has] = rho[pick[has]]
    occupied = surface | (label > 0)
    free = (label == FREE_SPACE) & ~surface

    # Cells centred on a surface are surface, not material, so lines of sight to a wall end
    # in its surface row; a material cell is one whose centre is strictly inside material.
    material = np.where(label > 0, label, 0).astype(np.int16)

    reach = _reach_m(scenario)
    ranging = _ranging(scenario)
    in_range = np.zeros(px.shape, bool)   # surface and free cells in range of some view …
    seen = np.zeros(px.shape, bool)       # … and in its line of sight
    visible = np.zeros(px.shape, bool)    # … giving a return (Returns) and met (_met) there
    hidden_by_obstacle = np.zeros(px.shape, np.int16)
    sy, sx, spx, spy, sdir = _surface_at(surface, surface_point, surface_normal,
                                         surface_reflectance)
    surface_flat = sy * nx + sx
    geometric = ranging[:5]               # range and sweep only: what the shadow is judged by
    the_views = views(scenario, grid)     # a handful of poses, or a drive's steps in groups
    reaching = []                         # per view: surface cells it measures, which return
    for view in the_views:
        sub = np.flatnonzero(np.hypot(spx - view.x_m, spy - view.y_m) <= reach)
        reach_s, ret = _measurable_returning(spx[sub], spy[sub], view, _windowed(ranging, view),
                                             tuple(a[sub] for a in sdir))
        reaching.append((surface_flat[sub[reach_s]], surface_flat[sub[ret]]))
    if bar is not None:   # a view's free cells counted by its disc's box (what _disc looks at)
        bar.reset(total=int(sum(_box_cells(grid, v, reach) + len(s_)
                                for v, (s_, _) in zip(the_views, reaching))))
    coarse = (samples, normals, rho, cells)
    fine = sampled(res / MET_SAMPLES_PER_CELL)
    mark = np.zeros(ny * nx, bool)
    for view, (near_surface, ret) in zip(the_views, reaching):
        ranged = _windowed(ranging, view)
        disc, dist = _disc(free, grid, view, reach)
        # a free cell seen from an earlier view is done (in range and seen); walk only what
        # this view can change: free cells not yet seen, surface cells not yet visible (a
        # seen surface cell may become visible from another view)
        unseen = ~seen.ravel()[disc]
        near_free = disc[unseen]
        if not view.full:
            near_free = near_free[_in_window(near_free, dist[unseen], grid, view, ranged)]
        in_range.ravel()[near_free] = True
        in_range.ravel()[near_surface] = True
        walk = np.concatenate([near_free, near_surface[~visible.ravel()[near_surface]]])
        ty, tx = np.divmod(walk, nx)
        first = np.empty(len(tx), np.int16)
        for at in range(0, len(tx), SIGHT_CHUNK_CELLS):
            part = slice(at, at + SIGHT_CHUNK_CELLS)
            first[part] = _sight((ny, nx), origin, res, material, (view.x_m, view.y_m),
                                 tx[part], ty[part])
            if bar is not None:
                bar.update(len(tx[part]))
        if bar is not None:
            bar.update(_box_cells(grid, view, reach) + len(near_surface) - len(walk))
        clear = walk[first == 0]
        seen.ravel()[clear] = True
        # visible: some of the cell's surface a sensor of this view meets from the front,
        # through free space from its emitter (the coarse points first, then the fine); the
        # cells asked are marked in a scratch grid, so a view costs its cells, not the grid's
        mark[ret] = True
        ask = clear[mark[clear]]
        mark[ret] = False
        mark[ask] = True
        for at in (coarse, fine):
            on = mark[at[3]] & ~visible.ravel()[at[3]]
            if on.any():
                hit = _met(scenario, grid, at[0][on, 0], at[0][on, 1],
                           at[3][on] % nx, at[3][on] // nx,
                           (at[1][on, 0], at[1][on, 1], at[2][on]), view, ranged)
                visible.ravel()[at[3][on][hit]] = True
        mark[ask] = False
        by_obstacle = (first >= OBSTACLE0) & (surface_owner[ty, tx] == WALL)
        unset = hidden_by_obstacle[ty, tx] == 0
        pick = by_obstacle & unset
        hidden_by_obstacle[ty[pick], tx[pick]] = first[pick]
    # the paper's shadow is geometry (wall a centre sensor cannot see); a cell the sensor
    # sees too obliquely to return from is not hidden, and not visible either
    shadow = (surface_owner == WALL) & in_range & ~(seen & surface) & (hidden_by_obstacle > 0)
    shadow_ranged = _ranged_in_sight(the_views, grid, material, shadow, surface_point,
                                     geometric)
    return GroundTruth(label=label, surface=surface, surface_owner=surface_owner,
                       surface_point=surface_point, surface_normal=surface_normal,
                       surface_reflectance=surface_reflectance,
                       occupied=occupied, free=free, in_range=in_range,
                       visible=visible, reachable_free=seen & free, shadow=shadow,
                       shadow_ranged=shadow_ranged,
                       shadow_owner=np.where(shadow, hidden_by_obstacle, 0).astype(np.int16),
                       reach_m=reach)


# --------------------------------------------------------------------------- scores


def cached_ground_truth(scenario: Scenario, grid: OccupancyGrid, cache: dict,
                        key) -> GroundTruth:
    """:func:`ground_truth`, kept in ``cache`` (a dict the caller owns) under ``key`` (what
    identifies the scenario) and the grid's cells: rasterising costs more than scoring, and
    studies judge many runs on the same scenario and cells."""
    full = (key, grid.shape, tuple(grid.origin_xy_m), grid.resolution_m)
    truth = cache.get(full)
    if truth is None:
        truth = cache[full] = ground_truth(scenario, grid)
    return truth


def _share(hit: np.ndarray, of: np.ndarray) -> float | None:
    n = int(of.sum())
    return float((hit & of).sum()) / n if n else None


def f1_score(precision: float | None, recall: float | None) -> float | None:
    """The occupied F1 of a precision and a recall (shares 0 … 1, None: n/a): None with no
    wall to see, 0 with walls to see and none mapped."""
    if recall is None:
        return None
    if precision is None:   # walls to see, none mapped
        return 0.0
    return 0.0 if precision + recall == 0 else 2 * precision * recall / (precision + recall)


def score(grid: OccupancyGrid, scenario: Scenario, truth: GroundTruth | None = None, *,
          mapped_by: Scenario | None = None) -> dict:
    """The six map scores (see the module doc): floats in 0…1, or None when undefined.

    ``mapped_by``: the scene as the ring that made the map saw it, when that is not
    ``scenario`` (a design judged on another design's ground truth): the shadow cells it
    gets credit for are those its own sensors could range."""
    if truth is None:
        truth = ground_truth(scenario, grid)
    if truth.label.shape != grid.shape:
        raise ValueError(f"ground truth is {truth.label.shape} cells but the grid is {grid.shape}; "
                         "build it with ground_truth(scenario, grid) for this grid")
    ranged = truth.shadow_ranged
    if mapped_by is not None and mapped_by is not scenario:
        theirs = (_geometric_ranging(mapped_by), views(mapped_by, grid))
        if theirs != (_geometric_ranging(scenario), views(scenario, grid)):   # other ring or poses
            material = np.where(truth.label > 0, truth.label, 0).astype(np.int16)
            ranged = _ranged_in_sight(theirs[1], grid, material, truth.shadow,
                                      truth.surface_point, theirs[0])
    cls = grid.classify()
    occ = cls == OCCUPIED
    free = cls == FREE
    occ_near = _dilate(occ)
    precision = _share(_dilate(truth.occupied), occ)
    recall = _share(occ_near, truth.visible)
    return {
        "occupied_precision": precision,
        "occupied_recall": recall,
        "occupied_f1": f1_score(precision, recall),
        "free_accuracy": _share(_dilate(truth.free), free),
        "coverage": _share(free, truth.reachable_free),
        "shadow": _share(occ_near & ranged, truth.shadow),
    }


def shadow_by_obstacle(grid: OccupancyGrid, truth: GroundTruth) -> dict[int, tuple[int, float]]:
    """Obstacle index → (shadow cells behind it, share of them the map marks occupied, as
    ``shadow`` counts them)."""
    occ_near = _dilate(grid.classify() == OCCUPIED) & truth.shadow_ranged
    out = {}
    for owner in np.unique(truth.shadow_owner[truth.shadow]):
        cells = truth.shadow_owner == owner
        out[int(owner) - OBSTACLE0] = (int(cells.sum()), float((occ_near & cells).sum() / cells.sum()))
    return out
