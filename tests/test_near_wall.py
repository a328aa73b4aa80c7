"""Wall 85–130 mm from the ring: what the sensors read there and what the map makes of it."""

from __future__ import annotations

import numpy as np
import pytest

from irring import pipeline
from irring.core import Reason
from irring.maps import metrics
from irring.maps.mapping import FREE, OCCUPIED
from irring.scenario import loads

# A corner room of our own, walls 5 mm off the 10 mm grid (along cell edges): the ring's
# sensors 93 mm from the west wall and 118 mm from the south one, turned 17°; the far walls
# 0.8 m and 0.7 m from the pose.
NEAR_CORNER = """\
name: near_corner
seed: 13
room:
  outline_mm: [[5, 15], [1045, 15], [1045, 985], [5, 985]]
robot:
  poses:
    - {x_mm: 248, y_mm: 283, yaw_deg: 17}
"""
CLOSE_M = 0.45   # cells this near the pose centre: the near walls, 0-300 mm from the ring


def _run(effects: str, seed: int | None):
    sc = loads(NEAR_CORNER + effects, "near_corner.yaml")
    run = pipeline.run(sc, seed=seed, progress=False)
    sweep, points = run.sweeps[0], run.points[0]
    truth_d = sweep.truth.distance_m
    err = np.hypot(points.x - sweep.truth.hit_point[..., 0],
                   points.y - sweep.truth.hit_point[..., 1])
    return sc, run, points, truth_d, err


def _close_map_errors(sc, run):
    """(visible near-wall cells, missed, false occupied, false free) within CLOSE_M."""
    grid = run.grid
    truth = metrics.ground_truth(sc, grid)
    cls = grid.classify()
    xs, ys = grid.cell_centers()
    px, py = np.meshgrid(xs, ys)
    pose = sc.robot.poses[0]
    close = np.hypot(px - pose.x_m, py - pose.y_m) < CLOSE_M
    missed = truth.visible & ~metrics._dilate(cls == OCCUPIED)
    false_occ = (cls == OCCUPIED) & ~metrics._dilate(truth.occupied)
    false_free = (cls == FREE) & ~metrics._dilate(truth.free)
    return tuple(int((m & close).sum()) for m in (truth.visible, missed, false_occ, false_free))


def test_ideal_readings_below_100mm_are_read_on_the_curve_and_exact():
    # the GP2D12's datasheet range starts at 100 mm, but a scene without `foldover` does not
    # fold: its curve goes on to the ADC's full scale (43.8 mm), one distance per count, so
    # the readings brighter than the 100 mm level are read on it (before: FOLDOVER_AMBIGUOUS)
    sc, run, points, truth_d, err = _run("", None)
    below = truth_d < 0.100
    near = (truth_d >= 0.100) & (truth_d <= 0.130)
    assert int(below.sum()) == 41 and float(np.nanmin(truth_d)) == pytest.approx(0.0966, abs=1e-4)
    assert points.valid[below].all() and err[below].max() < 1e-6
    assert int(near.sum()) == 147 and points.valid[near].all()
    assert err[near].max() < 1e-6
    assert _close_map_errors(sc, run) == (117, 0, 0, 0)
    assert run.scores["occupied_recall"] == 1.0


def test_recall_measures_range_as_the_simulated_beam_does():
    # the scores' "could range" (metrics._sensor_views: from the hinge, emitter d_o beside the
    # beam) and the simulated rangefinder (its site on the hinge axis, d_o aside) measure
    # the same length: not from the ring's housing (20 mm further out) or the centre
    import math

    sc, run, points, truth_d, err = _run("", None)
    sweep, ring, pose = run.sweeps[0], sc.ring, sc.robot.poses[0]
    rho = pose.yaw_rad + 2 * math.pi * np.arange(ring.sensors) / ring.sensors
    hx, hy = pose.x_m + ring.radius_m * np.cos(rho), pose.y_m + ring.radius_m * np.sin(rho)
    hit = sweep.truth.hit_point
    along = np.sqrt((hit[..., 0] - hx) ** 2 + (hit[..., 1] - hy) ** 2 - ring.emitter_offset_m ** 2)
    seen = np.isfinite(truth_d)
    assert seen.sum() > 500
    np.testing.assert_allclose(along[seen], truth_d[seen], atol=1e-9)
    ranging = metrics._ranging(sc)
    can = np.zeros(seen.sum(), bool)
    for c, _, _ in metrics._sensor_views(hit[seen][:, 0], hit[seen][:, 1], pose, *ranging):
        can |= c
    assert (can == (truth_d[seen] >= 0.100)).all()   # every hit from 100 mm is rangeable


@pytest.mark.parametrize("seed", [13, 14, 15])
def test_near_walls_are_mapped_whole_and_in_place_with_the_default_effects(seed):
    sc, run, points, truth_d, err = _run("effects: [incidence, noise, quantization]\n", seed)
    near = truth_d <= 0.130
    ok = near & points.valid
    assert ok.sum() >= 140 and err[ok].max() < 0.005   # measured: ≤ 0.4 mm
    assert (points.reason[near & ~points.valid] != Reason.NO_RETURN).all()
    assert _close_map_errors(sc, run) == (117, 0, 0, 0)
