"""The paper's design geometry (§II): blind spot (Eq. 1), overlap angle (Eq. 2) and overlap
area (Eq. 3), and the same measured on a design's built MuJoCo model (Monte-Carlo overlap,
the smallest cylinder its rays see). Angles in radians, lengths in metres, areas in m².
The equations and what the measurements check: docs/designs.md."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .. import gp2
from ..designs import Design

# Table I of the paper.
TABLE_I_R_M = 0.15
TABLE_I_D_M = 0.686
TABLE_I_PHI_RAD = math.radians(30.0)
TABLE_I_ALPHA_RAD = math.radians(37.8)


# --------------------------------------------------------------------------- analytic


def blind_spot_m(distance_m, step_rad):
    """Eq. 1: radius (m) of the largest circle that can hide between two rays.

    Two rays from one apex, ``step_rad`` apart; a circle at ``distance_m`` from the apex
    that touches neither has at most this radius. Vectorised; ``step_rad`` = 0 gives 0
    (a continuous fan misses nothing), a step ≥ π gives ``inf`` (no bound).
    """
    d = np.asarray(distance_m, dtype=float)
    half = np.asarray(step_rad, dtype=float) / 2.0
    s = np.sin(np.clip(half, 0.0, np.pi / 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(s > 0, d / (1.0 / np.where(s > 0, s, 1.0) - 1.0), 0.0)
    r = np.where(half >= np.pi / 2, np.inf, r)
    return float(r) if r.ndim == 0 else r


def overlap_angle_rad(radius_m: float, range_m: float, spacing_rad: float,
                      alpha_rad: float) -> float:
    """Eq. 2: β, the angle at a sensor between its sweep edge and the overlap's far corner.

    ``radius_m`` R (ring radius), ``range_m`` D (max range), ``spacing_rad`` Φ (2π/N),
    ``alpha_rad`` α (each sensor sweeps ±α). β ≤ 0 means the sectors do not overlap.
    """
    c = radius_m * math.sin(spacing_rad / 2.0) / range_m
    if not -1.0 <= c <= 1.0:
        raise ValueError(f"R·sin(Φ/2) = {radius_m * math.sin(spacing_rad / 2):.4g} m exceeds "
                         f"the range D = {range_m:.4g} m: neighbouring sensors cannot overlap")
    return math.acos(c) - math.pi / 2.0 + alpha_rad - spacing_rad / 2.0


def overlap_area_m2(radius_m: float, range_m: float, spacing_rad: float,
                    alpha_rad: float) -> float:
    """Eq. 3: S (m²), the area seen by both of two neighbouring sensors.

    ``S = 2·[D²·β/2 − ½·D·(R·sin(Φ/2)/cos(π/2 − α + Φ/2))·sin β]``: twice a sector of
    angle β minus the triangle between the sensor, the crossing point of the two inner
    sweep edges, and the far corner. 0 when β ≤ 0 (no overlap).
    """
    beta = overlap_angle_rad(radius_m, range_m, spacing_rad, alpha_rad)
    if beta <= 0.0:
        return 0.0
    edge_to_crossing_m = (radius_m * math.sin(spacing_rad / 2.0)
                          / math.cos(math.pi / 2.0 - alpha_rad + spacing_rad / 2.0))
    return 2.0 * (range_m ** 2 * beta / 2.0 - 0.5 * range_m * edge_to_crossing_m * math.sin(beta))


# --------------------------------------------------------------------------- Monte Carlo


@dataclass(frozen=True)
class SweptSectors:
    """Where each sensor's sweep lies, in the robot's horizontal plane.

    ``apex_xy`` (N, 2) hinge positions (m); ``heading_min_rad`` / ``heading_max_rad`` (N,)
    beam directions at the first and last motor step, widened by the beam's half-angle
    where the sensor has a cone (sonar). The sweep runs counter-clockwise from min to max.
    """

    apex_xy: np.ndarray
    heading_min_rad: np.ndarray
    heading_max_rad: np.ndarray

    @property
    def sensors(self) -> int:
        return int(self.apex_xy.shape[0])

    @property
    def width_rad(self) -> np.ndarray:
        """(N,) angular width of each sweep, in [0, 2π]."""
        w = np.mod(self.heading_max_rad - self.heading_min_rad, 2 * np.pi)
        # a sweep whose edges coincide is either a single ray or a full turn
        full = (np.abs(self.heading_max_rad - self.heading_min_rad) > np.pi) & (w < 1e-9)
        return np.where(full, 2 * np.pi, w)


def in_sector(points_xy: np.ndarray, apex_xy: np.ndarray, heading_min_rad: float,
              width_rad: float, range_m: float) -> np.ndarray:
    """(P,) bool: which points lie within ``range_m`` of the apex and inside the sweep."""
    v = points_xy - apex_xy
    inside = np.einsum("pi,pi->p", v, v) <= range_m ** 2
    rel = np.mod(np.arctan2(v[:, 1], v[:, 0]) - heading_min_rad, 2 * np.pi)
    return inside & (rel <= width_rad + 1e-12)


def neighbour_pairs(sensors: int) -> list[tuple[int, int]]:
    """The neighbouring sensor pairs (k, k+1) around a ring of ``sensors``: none for one,
    one for two, else ``sensors`` (the ring closes)."""
    if sensors < 2:
        return []
    return [(k, (k + 1) % sensors) for k in range(sensors if sensors > 2 else 1)]


def overlap_area_mc_m2(sectors: SweptSectors, range_m: float, *, samples: int = 400_000,
                       seed: int = 0, on_pair: Callable[[], object] | None = None
                       ) -> tuple[float, float]:
    """Monte-Carlo area (m²) seen by both sensors of each neighbouring pair, averaged.

    Returns ``(mean_area_m2, standard_error_m2)``. For each pair (k, k+1) random points
    are drawn uniformly in the box around both sweeps; the share inside both sectors,
    times the box area, estimates the overlap. Fewer than two sensors: (0, 0).
    ``on_pair()`` is called after each pair (a progress bar's ``update``).
    """
    n = sectors.sensors
    if n < 2:
        return 0.0, 0.0
    rng = np.random.default_rng(seed)
    widths = sectors.width_rad
    areas, variances = [], []
    for k, j in neighbour_pairs(n):  # one loop per pair (≤ 72); the points are vectorised
        apexes = sectors.apex_xy[[k, j]]
        lo = apexes.min(axis=0) - range_m
        hi = apexes.max(axis=0) + range_m
        box = float(np.prod(hi - lo))
        pts = lo + rng.random((samples, 2)) * (hi - lo)
        both = (in_sector(pts, apexes[0], sectors.heading_min_rad[k], widths[k], range_m)
                & in_sector(pts, apexes[1], sectors.heading_min_rad[j], widths[j], range_m))
        p = both.mean()
        areas.append(p * box)
        variances.append(p * (1 - p) / samples * box ** 2)
        if on_pair is not None:
            on_pair()
    m = len(areas)
    return float(np.mean(areas)), float(math.sqrt(sum(variances)) / m)


def table_i() -> dict[str, float]:
    """β (deg) and S (m²) for the paper's Table I, from Eqs. 2 and 3."""
    beta = overlap_angle_rad(TABLE_I_R_M, TABLE_I_D_M, TABLE_I_PHI_RAD, TABLE_I_ALPHA_RAD)
    area = overlap_area_m2(TABLE_I_R_M, TABLE_I_D_M, TABLE_I_PHI_RAD, TABLE_I_ALPHA_RAD)
    return {"beta_deg": math.degrees(beta), "overlap_area_m2": area}


# --------------------------------------------------------------------------- the built model


@dataclass(frozen=True)
class SensorFrames:
    """Sensor frames read from MuJoCo at one motor step (world = robot frame, pose 0).

    ``hinge_xyz`` (N, 3) hinge anchors, ``emitter_xyz`` (N, 3) emitter sites,
    ``beam`` (N, 3) unit beam directions (each emitter site's +z axis).
    """

    step: int
    hinge_xyz: np.ndarray
    emitter_xyz: np.ndarray
    beam: np.ndarray

    @property
    def heading_rad(self) -> np.ndarray:
        return np.arctan2(self.beam[:, 1], self.beam[:, 0])


def model_frames(ring_model, step: int, data=None) -> SensorFrames:
    """Pose a compiled ring (``model.RingModel``) at motor ``step`` and read its frames.

    Kinematic: the motor joint at step × motor step, each hinge where its belt equality
    puts it, then ``mj_kinematics``; nothing here uses R, Φ or α. ``data``: an ``MjData``
    of the model to pose (a fresh one by default; allocating it costs ~100× the
    kinematics, so a caller posing many steps passes one).
    """
    import mujoco   # deferred: the equations above need only numpy

    m = ring_model.model
    d = mujoco.MjData(m) if data is None else data
    motor = step * ring_model.ring.motor_step_rad
    d.qpos[ring_model.motor_qpos] = motor
    d.qpos[ring_model.sensor_qpos] = ring_model.sensor_qpos_for(motor)
    mujoco.mj_kinematics(m, d)
    xmat = d.site_xmat[ring_model.emitter_sites].reshape(-1, 3, 3)
    return SensorFrames(step=step, hinge_xyz=d.xanchor[ring_model.sensor_joints].copy(),
                        emitter_xyz=d.site_xpos[ring_model.emitter_sites].copy(),
                        beam=xmat[:, :, 2].copy())


def swept_sectors(ring_model, beam_half_angle_rad: float = 0.0) -> SweptSectors:
    """Each sensor's swept sector from the model: apex at its hinge, edges along its beam at
    the first and last motor step, widened by the beam's half-angle (a sonar cone)."""
    ring = ring_model.ring
    lo = model_frames(ring_model, ring.min_step)
    hi = model_frames(ring_model, ring.max_step)
    return SweptSectors(apex_xy=lo.hinge_xyz[:, :2],
                        heading_min_rad=lo.heading_rad - beam_half_angle_rad,
                        heading_max_rad=hi.heading_rad + beam_half_angle_rad)


def design_report(design, distances_m=(0.25, 0.5, 0.75, 1.0), *, range_m: float | None = None,
                  samples: int = 400_000, seed: int = 0,
                  on_pair: Callable[[], object] | None = None) -> dict:
    """Everything ``irring geometry`` prints for a design (``designs.Design``).

    Analytic β and S from the design's numbers (R, Φ = 2π/N, α, D), the Monte-Carlo S from
    its built MuJoCo model, and Eq. 1's blind spot at ``distances_m`` with the design's
    ray step. ``range_m`` is D (default: the sensor's design range, Table I's 0.686 m);
    ``on_pair`` as :func:`overlap_area_mc_m2` takes it.
    """
    from ..simulation import model as ring_model_mod   # deferred: loads MuJoCo

    D = design.sensor.design_range_m if range_m is None else range_m
    ring = design.ring
    alpha = design.sweep_half_angle_rad + design.sensor.beam_half_angle_rad
    if ring.sensors >= 2:
        beta = overlap_angle_rad(ring.radius_m, D, design.spacing_rad, alpha)
        area = overlap_area_m2(ring.radius_m, D, design.spacing_rad, alpha)
    else:
        beta, area = float("nan"), 0.0  # one sensor has no neighbour to overlap with
    rm = ring_model_mod.compile_ring(ring)
    sectors = swept_sectors(rm, design.sensor.beam_half_angle_rad)
    mc, se = overlap_area_mc_m2(sectors, D, samples=samples, seed=seed, on_pair=on_pair)
    dist = np.asarray(distances_m, dtype=float)
    step = design.ray_step_rad()
    return {
        "design": design.name,
        "sensors": ring.sensors,
        "radius_m": ring.radius_m,
        "spacing_deg": round(math.degrees(design.spacing_rad), 9),
        "alpha_deg": round(math.degrees(alpha), 9),
        "range_m": D,
        "step_deg": round(math.degrees(step), 9),
        "beta_deg": math.degrees(beta) if math.isfinite(beta) else None,
        "overlap_area_m2": area,
        "overlap_area_mc_m2": mc,
        "overlap_area_mc_stderr_m2": se,
        "distances_m": dist.tolist(),
        "blind_spot_m": np.atleast_1d(blind_spot_m(dist, step)).tolist(),
        "blind_spot_rays_m": _blind_spot_from_rays(design, dist),
    }


def _blind_spot_from_rays(design, dist: np.ndarray) -> list[float] | None:
    """For a sensor with a beam cone: the largest post that hides, from the design's rays as
    ``irring compare`` casts them (its detection curve); None for a pencil beam, where Eq. 1
    is the answer. A cone closes Eq. 1's gaps on paper, but an echo returns only from a
    surface near square to a ray, so posts hide between cones after all."""
    if design.sensor.beam_half_angle_rad <= 0:
        return None
    det = detection(design, dist)
    return [float(v) for v in det.min_detectable_radius_m]


# --------------------------------------------------------------------------- detection

DEFAULT_DISTANCES_M = (0.25, 0.35, 0.45, 0.55, 0.65, 0.75)
CONE_RAY_STEP_RAD = math.radians(0.25)  # fan spacing used to stand in for a sonar cone


@dataclass(frozen=True)
class Rays:
    """Every ray of one full view, robot at the origin facing +x. (M, 2) arrays, metres."""

    origin: np.ndarray
    direction: np.ndarray

    def __len__(self) -> int:
        return len(self.origin)


def design_rays(design: Design, step_stride: int = 1) -> Rays:
    """The rays of a full view of ``design``, read from its built MuJoCo model.

    The ring is posed at each motor step (:func:`model_frames`); each emitter's
    position and beam direction is one ray. A sensor with a beam cone contributes a fan of
    rays every ``CONE_RAY_STEP_RAD`` across the cone.
    """
    import mujoco   # deferred: the equations above need only numpy
    from ..simulation import model as ring_model_mod   # deferred: loads MuJoCo

    rm = ring_model_mod.compile_ring(design.ring)
    data = mujoco.MjData(rm.model)  # one, re-posed at every step
    steps = range(design.ring.min_step, design.ring.max_step + 1, step_stride)
    origins, headings = [], []
    for s in steps:  # one kinematics call per motor position; the rays are arrays
        f = model_frames(rm, s, data)
        origins.append(f.emitter_xyz[:, :2])
        headings.append(f.heading_rad)
    o = np.concatenate(origins)
    h = np.concatenate(headings)
    half = design.sensor.beam_half_angle_rad
    if half > 0:
        k = int(math.ceil(half / CONE_RAY_STEP_RAD))
        offsets = np.linspace(-half, half, 2 * k + 1)
        o = np.repeat(o, len(offsets), axis=0)
        h = (h[:, None] + offsets[None, :]).ravel()
    return Rays(o, np.c_[np.cos(h), np.sin(h)])


def _incidence_limit_rad(design: Design) -> float:
    return float(gp2.sensor(design.sensor.kind).max_incidence_rad)


# centres × rays in one block of `seen`: its (B, M) arrays stay ~8 MB each, whatever the
# design (a ring of 8 turning ±180° in 0.01° steps has 288,008 rays: 180 bearings at once
# asked for over 3 GB)
SEEN_BLOCK = 1 << 20


def seen(rays: Rays, centres: np.ndarray, radius_m: float, *, min_range_m: float,
         max_range_m: float, max_incidence_rad: float) -> np.ndarray:
    """(B,) bool: is a cylinder of ``radius_m`` at each of ``centres`` (B, 2) hit by a ray
    within [min_range_m, max_range_m] at incidence ≤ ``max_incidence_rad``?"""
    rows = max(1, SEEN_BLOCK // max(1, len(rays)))
    if len(centres) > rows:
        return np.concatenate([
            seen(rays, centres[i:i + rows], radius_m, min_range_m=min_range_m,
                 max_range_m=max_range_m, max_incidence_rad=max_incidence_rad)
            for i in range(0, len(centres), rows)])
    rel = centres[:, None, :] - rays.origin[None, :, :]            # (B, M, 2)
    along = np.einsum("bmi,mi->bm", rel, rays.direction)           # to the foot of the centre
    across = rel[..., 1] * rays.direction[:, 0] - rel[..., 0] * rays.direction[:, 1]
    p = np.abs(across) / radius_m                                  # sin(incidence) where hit
    with np.errstate(invalid="ignore"):
        t = along - radius_m * np.sqrt(1.0 - p ** 2)              # distance to the surface
    hit = (p <= math.sin(max_incidence_rad)) & (t >= min_range_m) & (t <= max_range_m)
    return hit.any(axis=1)


@dataclass(frozen=True)
class Detection:
    """Per distance (from the robot centre to the cylinder's near side, m): the smallest
    cylinder radius (m) seen at every bearing (``inf``: not even ``MAX_RADIUS_M``), the
    largest radius found missed at some bearing (0: none), and ``too_near``: missed (inf)
    only for the sensor's minimum range ``min_range_m`` (with none, some radius is seen: the
    near side is inside it, from the sensor facing the cylinder)."""

    design: str
    distances_m: np.ndarray
    min_detectable_radius_m: np.ndarray
    max_missed_radius_m: np.ndarray
    bearings: int
    rays: int
    min_range_m: float
    too_near: np.ndarray


MIN_RADIUS_M = 0.001
MAX_RADIUS_M = 0.2
_COARSE_RADII_M = np.geomspace(MIN_RADIUS_M, MAX_RADIUS_M, 25)   # ~25 % apart
_BISECTIONS = 8                                                  # then ≈ 0.1 % apart


def symmetry_period_rad(design: Design, step_stride: int = 1) -> float:
    """Bearing period over which the design's rays repeat: 2π/N for a ring, one step for a
    single sensor turning a full circle at the centre."""
    ring = design.ring
    if ring.sensors > 1:
        return design.spacing_rad
    if design.rotating and design.positions(step_stride) * design.step_rad * step_stride \
            >= 2.0 * math.pi - 1e-9:
        return design.step_rad * step_stride
    return 2.0 * math.pi


def detection(design: Design, distances_m=DEFAULT_DISTANCES_M, *, bearings: int = 360,
              step_stride: int = 1, rays: Rays | None = None,
              min_range_m: float | None = None) -> Detection:
    """Smallest detectable cylinder radius versus distance for ``design``.

    ``bearings`` cylinder positions are spread over one symmetry period of the design, half
    a spacing off the rays' own symmetry, so the worst place (between two beams) is
    sampled. A radius is "detected" when it is seen at every bearing. Radii 1 … 200 mm are
    tried ~25 % apart; the boundary between the largest missed and the next detected one
    is then bisected (assumes one boundary in that bracket). ``min_range_m``: the sensor's
    (None) or another; a distance where no radius is detected is tried again without it
    (``Detection.too_near``).
    """
    rays = design_rays(design, step_stride) if rays is None else rays
    period = symmetry_period_rad(design, step_stride)
    b = (np.arange(bearings) + 0.5) / bearings * period
    unit = np.c_[np.cos(b), np.sin(b)]
    sens = design.sensor
    if min_range_m is None:
        min_range_m = gp2.sensor(sens.kind).min_range_m
    kw = dict(min_range_m=min_range_m, max_range_m=sens.max_range_m,
              max_incidence_rad=_incidence_limit_rad(design))
    dist = np.asarray(distances_m, dtype=float)
    min_ok = np.full(len(dist), np.inf)
    max_miss = np.zeros(len(dist))
    for i, d in enumerate(dist):
        def all_seen(r: float) -> bool:
            return bool(seen(rays, unit * (d + r), r, **kw).all())

        ok = np.array([all_seen(r) for r in _COARSE_RADII_M])
        missed = np.flatnonzero(~ok)
        if missed.size == 0:
            min_ok[i] = _COARSE_RADII_M[0]
            continue
        j = missed[-1]
        if j + 1 == len(_COARSE_RADII_M):
            max_miss[i] = _COARSE_RADII_M[j]
            continue
        lo, hi = _COARSE_RADII_M[j], _COARSE_RADII_M[j + 1]
        for _ in range(_BISECTIONS):
            mid = math.sqrt(lo * hi)
            lo, hi = (lo, mid) if all_seen(mid) else (mid, hi)
        min_ok[i], max_miss[i] = hi, lo
    too_near = np.zeros(len(dist), bool)
    missed = ~np.isfinite(min_ok)
    if min_range_m > 0 and missed.any():   # a miss the minimum range alone makes
        free = detection(design, dist[missed], bearings=bearings, step_stride=step_stride,
                         rays=rays, min_range_m=0.0)
        too_near[missed] = np.isfinite(free.min_detectable_radius_m)
    return Detection(design.name, dist, min_ok, max_miss, bearings, len(rays), min_range_m,
                     too_near)
