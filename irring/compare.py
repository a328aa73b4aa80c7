"""Compare ring designs by simulation: what each one sees, misses, and costs.

Two kinds of result, per design:

1. **Detection** (:func:`detection`): the smallest cylinder each design is sure to see at a
   given distance from the robot centre, over all bearings. The beams are the design's
   actual rays — emitter positions and directions read from its built MuJoCo model at
   every motor step of a full view (a sonar's ±15° cone as a fan of rays) — intersected
   with circles exactly. A cylinder counts as seen when some ray hits it within the
   sensor's working range (min … max) at an incidence the sensor still answers (GP2 70°,
   sonar 20°, laser 85°, the sensor model's limits). Open space, no noise: this is the
   geometry of the design; Eq. 1 is its closed form for a fan from one point.
2. **Scenes** (:func:`compare`): the scenario run through the whole pipeline of
   ``irring run`` (sweeps → estimator → occupancy grid → scores) with each design in place
   of the scenario's (:func:`irring.designs.apply`), for several seeds: occupied F1, free
   accuracy, coverage, shadow, hardware time of a 360° view, compute time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import designs as designs_mod
from .designs import Design

DEFAULT_DISTANCES_M = (0.25, 0.35, 0.45, 0.55, 0.65, 0.75)
CONE_RAY_STEP_RAD = math.radians(0.25)  # fan spacing used to stand in for a sonar cone


# --------------------------------------------------------------------------- rays


@dataclass(frozen=True)
class Rays:
    """Every ray of one full view, robot at the origin facing +x. (M, 2) arrays, metres."""

    origin: np.ndarray
    direction: np.ndarray

    def __len__(self) -> int:
        return len(self.origin)


def design_rays(design: Design, step_stride: int = 1) -> Rays:
    """The rays of a full view of ``design``, read from its built MuJoCo model.

    The ring is posed at each motor step (``geometry.model_frames``); each emitter's
    position and beam direction is one ray. A sensor with a beam cone contributes a fan of
    rays every ``CONE_RAY_STEP_RAD`` across the cone.
    """
    from . import geometry, model

    rm = model.compile_ring(design.ring)
    steps = range(design.ring.min_step, design.ring.max_step + 1, step_stride)
    origins, headings = [], []
    for s in steps:  # one kinematics call per motor position; the rays are arrays
        f = geometry.model_frames(rm, s)
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
    from . import gp2

    return float(gp2.sensor(design.sensor.kind).max_incidence_rad)


def seen(rays: Rays, centres: np.ndarray, radius_m: float, *, min_range_m: float,
         max_range_m: float, max_incidence_rad: float) -> np.ndarray:
    """(B,) bool: is a cylinder of ``radius_m`` at each of ``centres`` (B, 2) hit by a ray
    within [min_range_m, max_range_m] at incidence ≤ ``max_incidence_rad``?"""
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
    cylinder radius (m) seen at every bearing (``inf``: not even ``MAX_RADIUS_M``), and the
    largest radius found missed at some bearing (0: none)."""

    design: str
    distances_m: np.ndarray
    min_detectable_radius_m: np.ndarray
    max_missed_radius_m: np.ndarray
    bearings: int
    rays: int


MIN_RADIUS_M = 0.001
MAX_RADIUS_M = 0.2
_COARSE_RADII_M = np.geomspace(MIN_RADIUS_M, MAX_RADIUS_M, 25)   # ~25 % apart
_BISECTIONS = 8                                                  # then ≈ 0.1 % apart


def symmetry_period_rad(design: Design, step_stride: int = 1) -> float:
    """Bearing period over which the design's rays repeat: 2π/N for a ring, one step for a
    single sensor turning a full circle at the centre."""
    ring = design.ring
    if ring.sensors > 1:
        return 2.0 * math.pi / ring.sensors
    if design.rotating and design.positions(step_stride) * design.step_rad * step_stride \
            >= 2.0 * math.pi - 1e-9:
        return design.step_rad * step_stride
    return 2.0 * math.pi


def detection(design: Design, distances_m=DEFAULT_DISTANCES_M, *, bearings: int = 360,
              step_stride: int = 1, rays: Rays | None = None) -> Detection:
    """Smallest detectable cylinder radius versus distance for ``design`` (see module doc).

    ``bearings`` cylinder positions are spread over one symmetry period of the design, half
    a spacing off the rays' own symmetry, so the worst place (between two beams) is
    sampled. A radius is "detected" when it is seen at every bearing. Radii 1 … 200 mm are
    tried ~25 % apart; the boundary between the largest missed and the next detected one
    is then bisected (assumes one boundary in that bracket).
    """
    rays = design_rays(design, step_stride) if rays is None else rays
    period = symmetry_period_rad(design, step_stride)
    b = (np.arange(bearings) + 0.5) / bearings * period
    unit = np.c_[np.cos(b), np.sin(b)]
    sens = design.sensor
    kw = dict(min_range_m=sens.min_range_m, max_range_m=sens.max_range_m,
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
    return Detection(design.name, dist, min_ok, max_miss, bearings, len(rays))
