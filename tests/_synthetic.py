"""Synthetic readings from exact geometry, for mapper and metrics tests.

An analytic 2-D ray caster (room outline segments and cylinders) stands in for the
simulator and the estimator: it gives the `Points` a perfect estimator would produce for the
ring's real beam geometry, plus optional Gaussian range noise. Independent of irring.sim.
"""

from __future__ import annotations

import numpy as np

from irring.data import Points, Reason, beam_geometry, sensor_angles_for_steps
from irring.scenario import Cylinder, Scenario


def ray_distances(ox, oy, heading, scenario: Scenario) -> np.ndarray:
    """Distance (m) from each origin along each heading to the first wall or cylinder."""
    ux, uy = np.cos(heading), np.sin(heading)
    best = np.full(np.shape(ox), np.inf)
    outline = scenario.room.outline_m
    for i in range(len(outline)):
        (ax, ay), (bx, by) = outline[i], outline[(i + 1) % len(outline)]
        ex, ey = bx - ax, by - ay
        den = ux * ey - uy * ex
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((ax - ox) * ey - (ay - oy) * ex) / den
            s = ((ax - ox) * uy - (ay - oy) * ux) / den
        ok = (np.abs(den) > 1e-12) & (t > 0) & (s >= 0) & (s <= 1)
        best = np.where(ok & (t < best), t, best)
    for ob in scenario.obstacles:
        assert isinstance(ob, Cylinder)
        cx, cy = ox - ob.center_m[0], oy - ob.center_m[1]
        b = cx * ux + cy * uy
        c = cx * cx + cy * cy - ob.radius_m ** 2
        disc = b * b - c
        with np.errstate(invalid="ignore"):
            t = -b - np.sqrt(disc)
        ok = (disc >= 0) & (t > 0)
        best = np.where(ok & (t < best), t, best)
    return best


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
