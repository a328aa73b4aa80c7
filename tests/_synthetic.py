"""Synthetic readings from exact geometry, for the estimator, mapper and metrics tests.

One analytic 2-D ray caster (:func:`cast`: walls as segments, cylinders as circles, giving
distance and incidence) stands in for MuJoCo. On it:

- :func:`make_sweep`: a ``Sweep`` of an analytic scene, counts by a calibration's forward
  curve (the inverse of Eq. 10), for estimator tests that need geometry they control
  exactly (corners, a thin cylinder, grazing walls); the T-room tests use SimRing;
- :func:`points_for_pose`: the ``Points`` a perfect estimator would produce for a
  scenario's pose and the ring's real beam geometry, plus optional Gaussian range noise,
  for the mapper and metrics tests.

Independent of irring.simulation.sim.
"""

from __future__ import annotations

import math

import numpy as np

from irring.core import Points, Reason, Sweep, beam_geometry, sensor_angles_for_steps
from irring.designs import PAPER_RING
from irring.estimation.calibration import Calibration
from irring.core import Cylinder, Ring
from irring.scenario import Scenario, load_scenario

def stand_in_calibration(d_o: float = 0.007, strength: float = 0.25, bits: int = 12,
                         noise_counts: float = 0.0) -> Calibration:
    """GP2D12-like power law (d[cm] = 27.728·V^−1.2045) with a(θ) growing as 1 − cos θ."""
    theta = np.radians(np.arange(0.0, 86.0, 5.0))
    volts_per_count = 5.0 / (2 ** bits - 1)
    b = np.full(theta.size, -1.2045)
    a = 0.27728 * volts_per_count ** b * (1.0 + strength * (1.0 - np.cos(theta)))
    return Calibration(sensor_model="stand-in", emitter_offset_m=d_o, theta_rad=theta, a=a,
                       b=b, adc_bits=bits, min_range_m=0.08, max_range_m=0.80,
                       noise_counts=noise_counts, source="test stand-in")


def cast(origin: np.ndarray, heading: np.ndarray, walls=(), circles=()):
    """Nearest hit of rays (…, 2)/(…) on segments ((x1, y1), (x2, y2)) and circles
    ((cx, cy), r). Returns distance (inf if none) and incidence angle (rad)."""
    ox, oy = origin[..., 0], origin[..., 1]
    ux, uy = np.cos(heading), np.sin(heading)
    best = np.full(heading.shape, np.inf)
    inc = np.full(heading.shape, np.nan)
    for (x1, y1), (x2, y2) in walls:
        ex, ey = x2 - x1, y2 - y1
        den = ux * ey - uy * ex
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((x1 - ox) * ey - (y1 - oy) * ex) / den
            u = ((x1 - ox) * uy - (y1 - oy) * ux) / den
        hit = (np.abs(den) > 1e-12) & (t > 1e-9) & (u >= 0) & (u <= 1) & (t < best)
        nx, ny = -ey / math.hypot(ex, ey), ex / math.hypot(ex, ey)
        cos_t = np.abs(ux * nx + uy * ny)
        best = np.where(hit, t, best)
        inc = np.where(hit, np.arccos(np.clip(cos_t, 0, 1)), inc)
    for (cx, cy), r in circles:
        fx, fy = ox - cx, oy - cy
        bq = fx * ux + fy * uy
        cq = fx * fx + fy * fy - r * r
        disc = bq * bq - cq
        with np.errstate(invalid="ignore"):
            t = -bq - np.sqrt(disc)
        hit = (disc > 0) & (t > 1e-9) & (t < best)
        hx, hy = fx + t * ux, fy + t * uy
        cos_t = np.abs(hx * ux + hy * uy) / r
        best = np.where(hit, t, best)
        inc = np.where(hit, np.arccos(np.clip(cos_t, 0, 1)), inc)
    return best, inc


def make_sweep(cal: Calibration, *, walls=(), circles=(), pose=(0.0, 0.0, 0.0),
               ring: Ring = PAPER_RING, noise_counts: float = 0.0, seed: int = 0,
               max_range_m: float = 0.624, dtype=float, quantize: bool = False,
               steps: np.ndarray | None = None):
    """A Sweep of the scene read through ``cal``'s forward curve; also true d and θ (NaN
    where nothing returns: no hit, beyond the curve's range or past its drop-out angle)."""
    if steps is None:
        steps = np.arange(ring.min_step, ring.max_step + 1)
    angles = sensor_angles_for_steps(ring, steps)
    origin, heading = beam_geometry(ring, np.asarray(pose, float), angles, cal.emitter_offset_m)
    d, inc = cast(origin, heading, walls, circles)
    # like the `incidence` effect: past the calibration's drop-out angle nothing returns
    in_range = np.isfinite(d) & (d <= cal.max_range_m) & (inc <= cal.max_incidence_rad)
    counts = np.where(in_range, cal.counts(np.where(in_range, d, 1.0), np.nan_to_num(inc)), 0.0)
    rng = np.random.default_rng(seed)
    counts = counts + noise_counts * rng.standard_normal(counts.shape)
    counts = np.clip(counts, 0, cal.full_scale_counts)
    if quantize:
        counts = np.round(counts)
    sweep = Sweep(steps=np.asarray(steps), sensor_angles=angles.astype(dtype),
                  counts=counts.astype(dtype), timestamps_s=np.zeros(len(steps)), duration_s=0.0,
                  pose=np.asarray(pose, float), ring=ring, sensor_model="stand-in",
                  adc_bits=cal.adc_bits, max_range_m=max_range_m)
    return sweep, np.where(in_range, d, np.nan), np.where(in_range, inc, np.nan)


def rectangle(x0, y0, x1, y1):
    c = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    return [(c[i], c[(i + 1) % 4]) for i in range(4)]


def polygon(corners):
    return [(corners[i], corners[(i + 1) % len(corners)]) for i in range(len(corners))]


_T = load_scenario("t_room")   # the paper's T-room, as bundled: its walls and scan poses
T_ROOM = polygon(_T.room.outline_m)
T_POSES = [(p.x_m, p.y_m, p.yaw_rad) for p in _T.robot.poses]


def ray_distances(ox, oy, heading, scenario: Scenario) -> np.ndarray:
    """Distance (m) from each origin along each heading to the first wall or cylinder of a
    scenario (inf where nothing is hit)."""
    assert all(isinstance(ob, Cylinder) for ob in scenario.obstacles)
    ox, oy, heading = np.broadcast_arrays(ox, oy, np.asarray(heading, dtype=float))
    origin = np.stack([ox, oy], axis=-1)
    d, _ = cast(origin, heading, polygon(scenario.room.outline_m),
                [(ob.center_m, ob.radius_m) for ob in scenario.obstacles])
    return d


def gp2_sigma_m(d_m):
    """Range σ of a GP2D12 with 15 mV output noise: ≈ 6 mm at 0.3 m, 21 mm at 0.6 m."""
    return 0.021 * (np.abs(d_m) / 0.6) ** 1.8


def points_for_pose(scenario: Scenario, pose_index: int, *, sigma_m=0.0,
                    rng: np.random.Generator | None = None, steps=None) -> Points:
    """The Points a perfect estimator would give for one sweep at a scenario pose.

    ``sigma_m``: range noise σ, a number or ``"gp2"`` for :func:`gp2_sigma_m`."""
    ring = scenario.ring
    pose = scenario.robot.poses[pose_index]
    if steps is None:
        steps = np.arange(ring.min_step, ring.max_step + 1)
    angles = sensor_angles_for_steps(ring, np.asarray(steps))
    origin, heading = beam_geometry(ring, np.array([pose.x_m, pose.y_m, pose.yaw_rad]), angles,
                                    ring.emitter_offset_m)
    ox, oy = origin[..., 0], origin[..., 1]
    d = ray_distances(ox, oy, heading, scenario)
    sigma = gp2_sigma_m(np.where(np.isfinite(d), d, 1.0)) if sigma_m == "gp2" else \
        np.full(d.shape, float(sigma_m))
    if np.any(sigma > 0):
        d = d + (rng or np.random.default_rng(0)).normal(0.0, 1.0, d.shape) * sigma
    rmax = scenario.sensor.max_range_m
    valid = d <= rmax
    dv = np.where(valid, d, np.nan)
    reason = np.where(valid, Reason.OK, Reason.NO_RETURN).astype(np.uint8)
    return Points(x=ox + dv * np.cos(heading), y=oy + dv * np.sin(heading), d=dv,
                  theta=np.where(valid, 0.0, np.nan), origin_x=ox, origin_y=oy, heading=heading,
                  sigma_m=np.maximum(sigma, 0.002), iterations=np.ones(d.shape, int),
                  valid=valid, reason=reason, max_range_m=rmax)


def single_ray(ox, oy, heading, d, *, valid=True, reason=Reason.OK, sigma_m=0.005,
               max_range_m=0.624) -> Points:
    """Points holding one reading (shape (1, 1))."""
    a = lambda v: np.array([[v]], dtype=float)  # noqa: E731
    dd = d if valid else np.nan
    return Points(x=a(ox + dd * np.cos(heading)), y=a(oy + dd * np.sin(heading)), d=a(dd),
                  theta=a(0.0 if valid else np.nan), origin_x=a(ox), origin_y=a(oy),
                  heading=a(heading), sigma_m=a(sigma_m), iterations=np.ones((1, 1), int),
                  valid=np.array([[valid]]), reason=np.array([[reason]], np.uint8),
                  max_range_m=max_range_m)


# One pose near the south-west corner of a room whose far walls lie near the reach
# (metrics and bench-rooms tests of what counts as visible wall).
FAR_CORNER = """\
name: far_corner
seed: 5
room:
  outline_mm: [[0, 0], [1030, 0], [1030, 990], [0, 990]]
robot:
  poses:
    - {x_mm: 262, y_mm: 243, yaw_deg: 17}
"""
