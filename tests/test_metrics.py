"""Ground truth and map scores: exact cell counts, perfect and broken maps, the shadow."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from irring.core import Points, Reason
from irring.maps.mapping import OccupancyGrid
from irring.maps import metrics
from irring.maps.metrics import (OBSTACLE0, SCORE_KEYS, WALL, ground_truth, score,
                            shadow_by_obstacle)
from irring.scenario import load_scenario

from _synthetic import FAR_CORNER, points_for_pose, ray_distances


@pytest.fixture(scope="module")
def room():
    sc = load_scenario("t_room")
    grid = OccupancyGrid.for_scenario(sc)
    return sc, grid, ground_truth(sc, grid)


@pytest.fixture(scope="module")
def cylinder():
    sc = load_scenario("t_room_cylinder")
    grid = OccupancyGrid.for_scenario(sc)
    return sc, grid, ground_truth(sc, grid)


def painted(grid, truth, occupied, free):
    g = grid.empty_like()
    g.log_odds[free] = g.params.l_min
    g.log_odds[occupied] = g.params.l_max
    return g


def test_t_room_outline_rasterises_to_its_perimeter(room):
    sc, grid, truth = room
    # 8440 mm of wall through cell centres at 10 mm: one cell per 10 mm, corners shared
    assert truth.surface.sum() == 844
    assert np.all(truth.surface_owner[truth.surface] == WALL)
    # wall material 20 mm thick: two cell rows beyond each face (plus the convex corners)
    assert not (truth.free & truth.occupied).any()
    free_area = truth.free.sum() * grid.resolution_m ** 2
    room_area = 2.42 * 0.9 + 0.9 * 0.9
    assert free_area == pytest.approx(room_area, rel=0.02)


def test_every_t_room_wall_is_seen_from_some_pose(room):
    """Four poses (paper Fig. 17) reach every wall cell of the T-room."""
    sc, grid, truth = room
    assert truth.visible.sum() == truth.surface.sum()
    assert truth.shadow.sum() == 0
    assert truth.reach_m == pytest.approx(0.624 + 0.15)


def test_perfect_map_scores_one(cylinder):
    sc, grid, truth = cylinder
    g = painted(grid, truth, truth.surface, truth.free)
    s = score(g, sc, truth)
    assert set(s) == set(SCORE_KEYS)
    assert all(s[k] == 1.0 for k in SCORE_KEYS)


def test_empty_map_scores_zero_or_undefined(cylinder):
    sc, grid, truth = cylinder
    s = score(grid.empty_like(), sc, truth)
    # walls to see and none mapped: F1 0 (a miss), though precision has nothing to judge
    assert s["occupied_precision"] is None and s["occupied_f1"] == 0.0
    assert s["occupied_recall"] == 0.0 and s["coverage"] == 0.0 and s["shadow"] == 0.0
    assert s["free_accuracy"] is None


def test_one_cell_tolerance_and_not_more(room):
    sc, grid, truth = room
    for shift, expect_perfect in ((1, True), (3, False)):
        occ = np.roll(truth.surface, shift, axis=0)
        s = score(painted(grid, truth, occ, np.zeros_like(occ)), sc, truth)
        if expect_perfect:
            assert s["occupied_precision"] == 1.0 and s["occupied_recall"] == 1.0
        else:  # horizontal walls moved 3 cells: most of them are wrong and missed
            assert s["occupied_precision"] < 0.7 and s["occupied_recall"] < 0.7


def test_free_accuracy_counts_free_cells_inside_walls_as_wrong(room):
    sc, grid, truth = room
    free = truth.free.copy()
    s_good = score(painted(grid, truth, truth.surface, free), sc, truth)
    wall_inside = (truth.label == WALL)
    wall_inside &= ~np.roll(truth.surface, 1, 0) & ~np.roll(truth.surface, -1, 0)
    wall_inside &= ~np.roll(truth.surface, 1, 1) & ~np.roll(truth.surface, -1, 1)
    n_bad = int(wall_inside.sum())
    s_bad = score(painted(grid, truth, truth.surface, free | wall_inside), sc, truth)
    assert s_good["free_accuracy"] == 1.0
    # the second row of wall material is 2 cells from free space: beyond the tolerance
    assert s_bad["free_accuracy"] == pytest.approx(free.sum() / (free.sum() + n_bad), rel=0.02)


def test_shadow_cells_lie_behind_the_cylinder_as_seen_from_the_pose(cylinder):
    sc, grid, truth = cylinder
    cyl = sc.obstacles[0]
    pose = sc.robot.poses[0]
    assert 5 <= truth.shadow.sum() <= 40
    assert np.all(truth.shadow_owner[truth.shadow] == OBSTACLE0)
    xs, ys = grid.cell_centers()
    iy, ix = np.nonzero(truth.shadow)
    bearing = np.arctan2(ys[iy] - pose.y_m, xs[ix] - pose.x_m)
    to_cyl = math.atan2(cyl.center_m[1] - pose.y_m, cyl.center_m[0] - pose.x_m)
    half = math.asin(cyl.radius_m / math.hypot(cyl.center_m[0] - pose.x_m,
                                                 cyl.center_m[1] - pose.y_m))
    assert np.all(np.abs(bearing - to_cyl) <= half + 0.02)  # within the shadow cone (+1 cell)
    dist = np.hypot(xs[ix] - pose.x_m, ys[iy] - pose.y_m)
    assert np.all(dist <= truth.reach_m)
    # the corner behind the cylinder: the shadow is on the bottom and right walls there
    assert np.all((xs[ix] > 2.3) & (ys[iy] < 0.15))


def test_rotating_ring_sees_behind_a_thin_cylinder_and_a_centre_scanner_does_not(cylinder):
    """The paper's headline on exact geometry: sensors offset on the ring look past the
    table leg; rays from the ring's centre (a radial scanner there) cannot."""
    sc, grid, truth = cylinder
    ring = grid.empty_like()
    ring.insert(points_for_pose(sc, 0))
    assert score(ring, sc, truth)["shadow"] >= 0.8

    pose = sc.robot.poses[0]
    heading = np.radians(np.arange(0, 360, 0.25))[None, :]
    ox = np.full(heading.shape, pose.x_m)
    oy = np.full(heading.shape, pose.y_m)
    d = ray_distances(ox, oy, heading, sc)
    reach = truth.reach_m
    valid = d <= reach
    dv = np.where(valid, d, np.nan)
    centre = grid.empty_like()
    pts = Points(x=ox + dv * np.cos(heading), y=oy + dv * np.sin(heading), d=dv, theta=dv * 0,
                 origin_x=ox, origin_y=oy, heading=heading, sigma_m=np.full(d.shape, 0.003),
                 iterations=np.ones(d.shape, int), valid=valid,
                 reason=np.where(valid, Reason.OK, Reason.NO_RETURN).astype(np.uint8),
                 max_range_m=reach)
    for _ in range(2):
        centre.insert(pts)
    s = score(centre, sc, truth)
    assert s["occupied_recall"] >= 0.95
    assert s["shadow"] <= 0.35   # only the cone's edge cells, within the 1-cell tolerance
    assert shadow_by_obstacle(centre, truth)[0][0] == truth.shadow.sum()


def test_synthetic_noisy_scans_meet_the_targets():
    """With GP2-like range noise and a perfect estimator the mapper reaches the issue's
    targets on all three bundled scenarios (the sim+estimator version is in test_run)."""
    for name in ("t_room", "t_room_cylinder", "t_room_three_cylinders"):
        sc = load_scenario(name)
        grid = OccupancyGrid.for_scenario(sc)
        rng = np.random.default_rng(7)
        for k in range(len(sc.robot.poses)):
            grid.insert(points_for_pose(sc, k, sigma_m="gp2", rng=rng))
        s = score(grid, sc)
        assert s["occupied_f1"] >= 0.95, (name, s)
        assert s["free_accuracy"] >= 0.99, (name, s)
        if name == "t_room_cylinder":
            assert s["shadow"] >= 0.5


def test_truth_must_match_the_grid(cylinder):
    sc, grid, truth = cylinder
    other = OccupancyGrid(grid.origin_xy_m, (10, 10), grid.resolution_m)
    with pytest.raises(ValueError, match="ground_truth"):
        score(other, sc, truth)


def test_box_obstacles_rasterise(room):
    sc, grid, _ = room
    from irring.core import Box

    boxed = dataclasses.replace(sc, obstacles=(Box(center_m=(1.2, 0.45), size_m=(0.1, 0.05),
                                                   yaw_rad=0.3),))
    truth = ground_truth(boxed, grid)
    inside = truth.label == OBSTACLE0
    assert inside.sum() * grid.resolution_m ** 2 == pytest.approx(0.1 * 0.05, rel=0.15)
    assert (truth.surface_owner == OBSTACLE0).sum() == pytest.approx(2 * (10 + 5), rel=0.3)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), fill=st.floats(0.0, 0.4),
       res=st.sampled_from([0.001, 0.01, 0.037]),
       pose=st.tuples(st.one_of(st.floats(-0.2, 1.3), st.integers(-3, 34).map(lambda k: k / 31)),
                      st.one_of(st.floats(-0.2, 1.1), st.integers(-2, 25).map(lambda k: k / 23))))
def test_compiled_line_of_sight_is_its_numpy_oracle(seed, fill, res, pose):
    # random material (labels 1 … 4) on a 23 × 31 grid, every cell a target, the pose
    # anywhere: inside, outside the grid, on cell borders
    rng = np.random.default_rng(seed)
    shape = (23, 31)
    label = np.where(rng.random(shape) < fill, rng.integers(1, 5, shape), 0).astype(np.int16)
    origin = (-0.013, 0.029)
    pose_xy = (origin[0] + pose[0] * shape[1] * res, origin[1] + pose[1] * shape[0] * res)
    ty, tx = np.nonzero(np.ones(shape, bool))
    fast = metrics._sight(shape, origin, res, label, pose_xy, tx, ty)
    slow = metrics._sight_oracle(shape, origin, res, label, pose_xy, tx, ty)
    np.testing.assert_array_equal(fast, slow)
    # one start per line (sensor emitters)
    starts = (origin[0] + rng.uniform(-0.2, 1.2, tx.size) * shape[1] * res,
              origin[1] + rng.uniform(-0.2, 1.2, tx.size) * shape[0] * res)
    np.testing.assert_array_equal(metrics._sight(shape, origin, res, label, starts, tx, ty),
                                  metrics._sight_oracle(shape, origin, res, label, starts, tx, ty))


@pytest.mark.parametrize("name", ["t_room_three_cylinders", "box_room", "posts"])
def test_compiled_line_of_sight_matches_the_oracle_on_rooms(name):
    sc = load_scenario(name)
    grid = OccupancyGrid.for_scenario(sc)
    truth = ground_truth(sc, grid)
    material = np.where(truth.label > 0, truth.label, 0).astype(np.int16)
    ty, tx = np.nonzero(truth.surface | truth.free)
    for pose in sc.robot.poses:
        args = (grid.shape, grid.origin_xy_m, grid.resolution_m, material,
                (pose.x_m, pose.y_m), tx, ty)
        first = metrics._sight(*args)
        np.testing.assert_array_equal(first, metrics._sight_oracle(*args))
        assert 0 < (first > 0).sum() < len(first)     # some lines blocked, not all


def _on_beam(pose, ring, k, sensor_angle_rad, t_m):
    """The point sensor k of ``ring`` at ``pose`` ranges at ``t_m`` when turned by the angle."""
    rho = pose.yaw_rad + 2 * math.pi * k / ring.sensors
    psi = rho + sensor_angle_rad
    d_o = ring.emitter_offset_m
    return (pose.x_m + ring.radius_m * math.cos(rho) + d_o * math.sin(psi) + t_m * math.cos(psi),
            pose.y_m + ring.radius_m * math.sin(rho) - d_o * math.cos(psi) + t_m * math.sin(psi))


def test_measurable_is_the_sensors_interval_from_the_ring_within_its_sweep():
    from irring.core import Pose
    from irring.designs import PAPER_RING

    pose, k = Pose(0.43, 0.31, 0.3), 4
    ranging = (PAPER_RING, 0.10, 0.624, -math.radians(37.8), math.radians(37.8))
    cases = {  # (sensor angle, distance along the beam) → measurable
        (0.0, 0.10 + 1e-6): True, (0.0, 0.10 - 1e-6): False,      # GP2D12's 100 mm minimum
        (0.0, 0.624 - 1e-6): True, (0.0, 0.624 + 1e-6): False,    # the scene's max range
        (math.radians(37.7), 0.31): True,                         # within the ±37.8° sweep
    }
    for (angle, t), want in cases.items():
        x, y = _on_beam(pose, PAPER_RING, k, angle, t)
        assert metrics._measurable(np.array([x]), np.array([y]), pose, *ranging)[0] == want, (
            angle, t)
    # 190 mm from the centre between two sensors: 60 mm from both hinges, too far round for
    # the others (97° off radial): wall beside the ring no sensor can range
    rho = pose.yaw_rad + 2 * math.pi * (k + 0.5) / 12
    x, y = pose.x_m + 0.19 * math.cos(rho), pose.y_m + 0.19 * math.sin(rho)
    assert not metrics._measurable(np.array([x]), np.array([y]), pose, *ranging)[0]


# A pose 190 mm from the west wall (and 230 mm from the south one), another in the open.
CORNER_190 = """\
name: corner190
seed: 21
room:
  outline_mm: [[0, 0], [1300, 0], [1300, 1000], [0, 1000]]
robot:
  poses:
    - {x_mm: 190, y_mm: 230}
    - {x_mm: 820, y_mm: 560}
"""


def test_wall_too_close_to_range_is_not_counted_as_visible():
    # the ideal sensor cannot map wall nearer than 100 mm to every sensor that could point
    # at it; counting it made even the ideal ring's recall 0.917 here
    from irring import pipeline
    from irring.scenario import loads

    sc = loads(CORNER_190, "corner190.yaml")
    grid = OccupancyGrid.for_scenario(sc)
    truth = ground_truth(sc, grid)
    assert int(truth.visible.sum()) == 400
    run = pipeline.run(sc, progress=False)
    assert run.scores["occupied_recall"] >= 0.995
    assert run.scores["occupied_precision"] == 1.0


# Walls 5 mm off the 10 mm grid (so along cell edges), one pose in a corner: the south wall
# 101–106 mm from the nearest sensors, the east and north walls at the 624 mm reach.
EDGE_CORNER = """\
name: edge_corner
seed: 7
room:
  outline_mm: [[5, 15], [1055, 15], [1055, 1035], [5, 1035]]
robot:
  poses:
    - {x_mm: 279, y_mm: 266, yaw_deg: -128}
"""


def test_in_range_is_judged_at_the_wall_in_the_cell_not_at_its_centre():
    # a wall along a cell edge lies half a cell from the cell's centre: judged at the centre,
    # 17 cells of east and north wall 625-629 mm from every sensor counted as in the 624 mm
    # reach (no sensor, the ideal one too, can map them: ideal recall 0.928), and 5 cells of
    # south wall 100-105 mm from a sensor as too near to measure
    from irring import pipeline
    from irring.core import distance_to_outline
    from irring.scenario import loads

    sc = loads(EDGE_CORNER, "edge_corner.yaml")
    grid = OccupancyGrid.for_scenario(sc)
    truth = ground_truth(sc, grid)
    sy, sx = np.nonzero(truth.surface)
    sp = truth.surface_point[sy, sx]
    assert np.isnan(truth.surface_point[~truth.surface]).all()
    assert distance_to_outline(sp[:, 0], sp[:, 1], sc.room.outline_m).max() < 1e-12
    ix, iy = grid.cell_of(sp[:, 0], sp[:, 1])
    np.testing.assert_array_equal(ix, sx)
    np.testing.assert_array_equal(iy, sy)

    xs, ys = grid.cell_centers()
    pose, ranging = sc.robot.poses[0], metrics._ranging(sc)
    at_centre = metrics._measurable(xs[sx], ys[sy], pose, *ranging)
    at_wall = metrics._measurable(sp[:, 0], sp[:, 1], pose, *ranging)
    dist = np.hypot(sp[:, 0] - pose.x_m, sp[:, 1] - pose.y_m)
    assert (at_centre & ~at_wall).sum() == 17 and dist[at_centre & ~at_wall].min() > 0.76
    near = ~at_centre & at_wall    # the south wall beside the pose
    assert near.sum() == 5 and np.allclose(sp[near, 1], 0.015) and dist[near].max() < 0.26
    assert int(truth.visible.sum()) == 210
    np.testing.assert_array_equal(truth.visible[sy, sx], at_wall)

    run = pipeline.run(sc, progress=False)
    assert run.scores["occupied_recall"] >= 0.99
    assert run.scores["occupied_precision"] == 1.0


def test_shadow_credits_only_wall_a_sensor_could_range():
    # hidden wall no sensor can range along a clear line (behind box_room's crate: 7 cells,
    # none) is missed by every map, however its cells are painted; behind the three
    # table legs 24 of 54 hidden cells can be ranged
    for name, cells, ranged in (("box_room", 7, 0), ("t_room_three_cylinders", 54, 24)):
        sc = load_scenario(name)
        grid = OccupancyGrid.for_scenario(sc)
        truth = ground_truth(sc, grid)
        assert (int(truth.shadow.sum()), int(truth.shadow_ranged.sum())) == (cells, ranged)
        assert not (truth.shadow_ranged & ~truth.shadow).any()
        painted_map = painted(grid, truth, truth.surface, truth.free)
        assert score(painted_map, sc, truth)["shadow"] == pytest.approx(ranged / cells)


# A room of our own with a turned box, a 55 mm pillar and a 12 mm post around one pose.
PILLARS = """\
name: pillars_own
seed: 31
room:
  outline_mm: [[0, 0], [1310, 0], [1310, 1050], [0, 1050]]
obstacles:
  - {type: box, center_mm: [320, 300], size_mm: [80, 100], yaw_deg: 17}
  - {type: cylinder, center_mm: [960, 760], radius_mm: 55}
  - {type: cylinder, center_mm: [350, 800], radius_mm: 12}
robot:
  poses:
    - {x_mm: 660, y_mm: 540}
effects: [incidence, noise, quantization]
"""


def test_the_ideal_sensor_maps_all_rangeable_shadow_and_noise_never_more():
    # noisy end points 1-2 cells off, or a σ-wide hit's neighbour, used to land on hidden wall
    # no sensor ranged and count (ideal 0.43 < noisy 0.48 on a held-out room like this one)
    from irring import pipeline
    from irring.scenario import loads
    from irring.studies.rooms import ideal

    sc = loads(PILLARS, "pillars_own.yaml")
    grid = OccupancyGrid.for_scenario(sc)
    truth = ground_truth(sc, grid)
    assert (int(truth.shadow.sum()), int(truth.shadow_ranged.sum())) == (22, 11)
    for seed in (31, 32):
        noisy = pipeline.run(sc, seed=seed, progress=False).scores["shadow"]
        perfect = pipeline.run(ideal(sc), seed=seed, progress=False).scores["shadow"]
        assert perfect == 0.5 and noisy <= perfect


def test_a_design_judged_on_the_scenes_truth_gets_shadow_credit_for_what_it_ranged():
    # a laser at the centre cannot see behind the table leg from one pose (it scored 0.18 on
    # σ-tails and tolerance); from four poses its 8 m reach ranges most of what the legs hide
    from irring.studies.compare import run_scene

    one, four = load_scenario("t_room_cylinder"), load_scenario("t_room_three_cylinders")
    assert run_scene(one, "laser")["shadow"] == 0.0
    assert run_scene(one, "rotating12")["shadow"] == 1.0
    assert run_scene(four, "laser")["shadow"] > run_scene(four, "rotating12")["shadow"] + 0.3


def _facing(pose, ring, k, sensor_angle_rad, incidence_rad):
    """A unit surface normal that sensor k's beam (turned by the angle) meets at the
    incidence (turned counter-clockwise from facing the beam square on)."""
    psi = pose.yaw_rad + 2 * math.pi * k / ring.sensors + sensor_angle_rad + math.pi
    return math.cos(psi + incidence_rad), math.sin(psi + incidence_rad)


def _sensor_can(k, *args, **kwargs) -> bool:
    """Whether sensor k alone (:func:`metrics._sensor_views`) ranges the one point."""
    return bool(list(metrics._sensor_views(*args, **kwargs))[k][0][0])


def test_a_return_needs_an_incidence_and_a_signal_the_sensor_can_tell_from_nothing():
    # GP2D12 with the incidence effect: a(θ), b(θ) dim a slanted return, and one no brighter
    # than a surface at the 624 mm max range square on reads as nothing (a wall 600 mm off
    # at 30° reads 633 mm); past the 70° drop-out angle nothing comes back at all
    from irring.core import Pose
    from irring.designs import PAPER_RING

    pose, k, angle = Pose(0.43, 0.31, 0.3), 7, math.radians(-12.0)
    geometric = (PAPER_RING, 0.10, 0.624, -math.radians(37.8), math.radians(37.8))
    slanted = geometric + (metrics.Returns("gp2d12", max_incidence_rad=math.radians(70.0)),)
    cases = {  # (distance along the beam m, incidence °) → a return
        (0.30, 65.0): True, (0.30, -69.0): True,   # reads 395 / 418 mm
        (0.30, 71.0): False,                        # past the drop-out angle
        (0.50, 50.0): True, (0.50, -60.0): False,   # reads 585 / 640 mm
        (0.60, 0.0): True, (0.60, 30.0): False,     # reads 600 / 633 mm
    }
    for (t, inc), want in cases.items():
        x, y = _on_beam(pose, PAPER_RING, k, angle, t)
        nx, ny = _facing(pose, PAPER_RING, k, angle, math.radians(inc))
        surface = (np.array([nx]), np.array([ny]), np.array([1.0]))
        at = (np.array([x]), np.array([y]), pose)
        assert _sensor_can(k, *at, *slanted, surface=surface) == want, (t, inc)
        assert _sensor_can(k, *at, *geometric)                  # range and sweep: all in
        assert _sensor_can(k, *at, *geometric, metrics.Returns("gp2d12"),
                           surface=surface)                     # no effect: no condition
    # reflectance 0.1 with min_signal 0.2: seen to 0.8 m · √(0.1 / 0.2) = 566 mm
    dark = geometric + (metrics.Returns("gp2d12", min_signal=0.2),)
    for t, want in ((0.55, True), (0.58, False)):
        x, y = _on_beam(pose, PAPER_RING, k, angle, t)
        surface = (np.array([0.0]), np.array([1.0]), np.array([0.1]))
        assert _sensor_can(k, np.array([x]), np.array([y]), pose, *dark,
                           surface=surface) == want, t
    with pytest.raises(ValueError, match="surface=.normal x, normal y, reflectance"):
        metrics._measurable(np.array([x]), np.array([y]), pose, *slanted)


def test_visible_wall_is_wall_the_scenes_sensor_returns_from():
    # the same room with and without the incidence effect: the wall only seen obliquely
    # near the reach leaves the visible wall (no sensor could tell it from nothing), the
    # rest stays; the geometry (in range, shadow) does not change
    from irring.scenario import loads

    ideal = loads(FAR_CORNER, "far_corner.yaml")
    slanted = loads(FAR_CORNER + "effects: [incidence, noise, quantization]\n",
                    "far_corner.yaml")
    grid = OccupancyGrid.for_scenario(ideal)
    a, b = ground_truth(ideal, grid), ground_truth(slanted, grid)
    np.testing.assert_array_equal(a.in_range, b.in_range)
    np.testing.assert_array_equal(a.shadow, b.shadow)
    assert not (b.visible & ~a.visible).any()
    gone = a.visible & ~b.visible
    sy, sx = np.nonzero(gone)
    sp = b.surface_point[sy, sx]
    pose = ideal.robot.poses[0]
    dist = np.hypot(sp[:, 0] - pose.x_m, sp[:, 1] - pose.y_m)
    assert gone.sum() == 41 and dist.min() > 0.6           # only far, oblique wall leaves
    ky, kx = np.nonzero(a.visible)
    near = np.hypot(b.surface_point[ky, kx, 0] - pose.x_m,
                    b.surface_point[ky, kx, 1] - pose.y_m) < 0.45
    assert b.visible[ky[near], kx[near]].all()
    # each surface cell knows the side it lies on: south and north walls ±y, west ±x
    n = b.surface_normal[b.surface]
    assert np.allclose(np.hypot(n[:, 0], n[:, 1]), 1.0)
    assert np.isnan(b.surface_normal[~b.surface]).all()
    west = b.surface & (np.abs(b.surface_point[..., 0]) < 1e-9) \
        & (b.surface_point[..., 1] > 0.01) & (b.surface_point[..., 1] < 0.98)
    assert np.allclose(np.abs(b.surface_normal[west][:, 0]), 1.0)


# A 39 mm post 0.28 m from the ring's centre, to its left: the pose centre sees past the
# post's silhouette to a cell on its far flank.
BACK_OF_POST = """\
name: back_of_post
seed: 5
room:
  outline_mm: [[0, 0], [1150, 0], [1150, 1280], [0, 1280]]
obstacles:
  - {type: cylinder, center_mm: [433, 781], radius_mm: 39}
robot:
  design: rotating12
  poses:
    - {x_mm: 713, y_mm: 827, yaw_deg: -21}
sensor: {model: gp2d12, max_range_mm: 624, adc_bits: 12}
effects: [incidence, noise, quantization]
"""


def test_visible_wall_is_wall_a_sensor_meets_from_the_front():
    # cell (52, 92) of the post is in the pose centre's line of sight and its surface point
    # lies in sensor 7's sweep and interval at 68° (|cos|): the rule before counted it
    # visible. But sensor 7, the only sensor that can point at it, has it on the post's far
    # side (its normal turns away from the emitter), so no beam meets it: the ideal map,
    # exact, missed it (recall 0.9957) while the noisy one's scattered end points marked it
    # in every seed (recall 1.000). It is no longer visible wall; both maps are judged alike
    from irring import pipeline
    from irring.maps.mapping import OCCUPIED
    from irring.scenario import loads
    from irring.studies.rooms import ideal

    sc = loads(BACK_OF_POST, "back_of_post.yaml")
    pose = sc.robot.poses[0]
    run = pipeline.run(ideal(sc), progress=False, score=False)
    truth = ground_truth(sc, run.grid)
    post = truth.surface_owner == OBSTACLE0
    assert int((truth.visible & post).sum()) == 7 and int(truth.visible.sum()) == 233
    x, y = 52, 92
    assert truth.surface[y, x] and not truth.visible[y, x]
    p, n = truth.surface_point[y, x], truth.surface_normal[y, x]
    ranging = metrics._ranging(sc)
    surface = (np.array([n[0]]), np.array([n[1]]), np.array([1.0]))
    # what the rule before asked: the pose centre's line of sight and a return at its point
    assert metrics._sight(run.grid.shape, run.grid.origin_xy_m, run.grid.resolution_m,
                          np.where(truth.label > 0, truth.label, 0).astype(np.int16),
                          (pose.x_m, pose.y_m), np.array([x]), np.array([y]))[0] == 0
    views = list(metrics._sensor_views(np.array([p[0]]), np.array([p[1]]), pose, *ranging,
                                       surface=surface))
    assert [k for k, (can, _, _) in enumerate(views) if can[0]] == [7]
    _, ex, ey = views[7]
    assert np.dot(n, p - np.array([ex[0], ey[0]])) > 0.01     # the far side, from sensor 7
    # the ideal map marks every visible cell and is no worse than the noisy one on any score
    occupied = metrics._dilate(run.grid.classify() == OCCUPIED)
    assert not (truth.visible & ~occupied).any() and not occupied[y, x]
    exact = score(run.grid, sc, truth)
    luck = []
    for seed in (5, 6, 7):
        noisy = pipeline.run(sc, seed=seed, progress=False, score=False)
        luck.append(bool(metrics._dilate(noisy.grid.classify() == OCCUPIED)[y, x]))
        for k, v in score(noisy.grid, sc, truth).items():
            assert v is None or exact[k] >= v, (seed, k, exact[k], v)
    # the noisy map's luck (every seed until the curve was read below 100 mm, which
    # moved the post's near readings: docs/calibration.md)
    assert luck == [True, False, False]


# A 220 × 120 mm box turned 88°, north-east of the ring: its north face turned to the ring,
# its east face away.
BOX_CORNER = """\
name: box_corner
seed: 5
room:
  outline_mm: [[0, 0], [1180, 0], [1180, 1130], [0, 1130]]
obstacles:
  - {type: box, center_mm: [929, 127], size_mm: [220, 120], yaw_deg: 88}
robot:
  design: rotating12
  poses:
    - {x_mm: 733, y_mm: 437, yaw_deg: 12}
sensor: {model: gp2d12, max_range_mm: 624, adc_bits: 12}
effects: [incidence, noise, quantization]
"""


def test_a_cell_is_met_where_any_of_its_surface_is():
    # cell (109, 33) holds the box's north-east corner: its point nearest the centre lies on
    # the east face, turned away from both sensors that can point at it, but the last 3 mm
    # of the north face, in the same cell, is met; judged at that one point the cell was
    # dropped from the visible wall although the maps mark it
    from irring import pipeline
    from irring.core import box_corners
    from irring.maps.mapping import OCCUPIED
    from irring.scenario import loads
    from irring.studies.rooms import ideal

    sc = loads(BOX_CORNER, "box_corner.yaml")
    pose, ranging = sc.robot.poses[0], metrics._ranging(sc)
    run = pipeline.run(ideal(sc), progress=False, score=False)
    truth = ground_truth(sc, run.grid)
    assert int(truth.visible.sum()) == 286
    assert int((truth.visible & (truth.surface_owner == OBSTACLE0)).sum()) == 33
    x, y = 109, 33
    p, n = truth.surface_point[y, x], truth.surface_normal[y, x]
    views = list(metrics._sensor_views(np.array([p[0]]), np.array([p[1]]), pose, *ranging[:5]))
    assert [k for k, (can, _, _) in enumerate(views) if can[0]] == [10, 11]
    for k in (10, 11):
        assert np.dot(n, p - np.array([views[k][1][0], views[k][2][0]])) > 0.1   # turned away
    corner, west = box_corners(sc.obstacles[0])[1:3]
    north = np.array([west[1] - corner[1], corner[0] - west[0]]) / np.hypot(*(west - corner))
    q = corner + 0.003 * (west - corner) / np.hypot(*(west - corner))
    assert tuple(int(v) for v in run.grid.cell_of(q[0], q[1])) == (x, y)
    assert metrics._met(sc, run.grid, np.array([q[0]]), np.array([q[1]]), np.array([x]),
                        np.array([y]), (np.array([north[0]]), np.array([north[1]]),
                                        np.array([1.0])), pose, ranging)[0]
    assert truth.visible[y, x]
    occupied = metrics._dilate(run.grid.classify() == OCCUPIED)
    assert occupied[y, x] and not (truth.visible & ~occupied).any()


def test_a_surface_is_met_from_its_free_side():
    # the truth's normals point to the free side, out of a box and a post (test_a_beam_meets_
    # a_face_from_its_front_only: into the room); a beam meets a point only through free
    # space all the way from its emitter (a wall under a box standing on it: by no beam)
    from irring.core import Box, Cylinder, box_corners, inside_obstacle
    from irring.scenario import loads

    box = Box(center_m=(0.6, 0.3), size_m=(0.3, 0.1), yaw_rad=0.4)
    post = Cylinder(center_m=(0.31, 0.62), radius_m=0.04)
    for ob in (box, post):
        points, normals = metrics._surface_samples(ob, 0.005)
        assert not inside_obstacle(ob, *(points + 0.001 * normals).T).any()
        if ob is box:                      # (a corner, moved along one side, stays on it)
            keep = np.hypot(*(points[:, None] - box_corners(box)[None]).T).min(axis=0) > 1e-6
            points, normals = points[keep], normals[keep]
        assert inside_obstacle(ob, *(points - 0.001 * normals).T).all()
    sc = loads("name: flush\nroom: {outline_mm: [[0, 0], [1200, 0], [1200, 900], [0, 900]]}\n"
               "obstacles: [{type: box, center_mm: [600, 50], size_mm: [300, 100], "
               "yaw_deg: 0}, {type: cylinder, center_mm: [250, 760], radius_mm: 40}]\n"
               "robot: {poses: [{x_mm: 430, y_mm: 520}]}\n", "flush.yaml")
    # the way from (0.43, 0.52) to just before: the open wall, the wall under the box, the
    # box's top, the post's near side, its far side, and a point past the east wall
    tx = np.array([0.300, 0.600, 0.700, 0.2746, 0.2254, 1.300])
    ty = np.array([0.001, 0.001, 0.101, 0.7272, 0.7928, 0.450])
    clear = metrics._clear_way(sc, np.full(6, 0.43), np.full(6, 0.52), tx, ty)
    assert clear.tolist() == [True, False, True, True, False, False]


def test_a_clear_way_is_one_no_point_of_which_is_in_material():
    # the exact test against its plain statement: 4,000 points along each of 600 segments,
    # none in an obstacle (a turned box, a post) nor outside the room (an L: a way can leave
    # and re-enter)
    from irring.core import inside_obstacle, inside_outline
    from irring.scenario import loads

    sc = loads("name: ways\nroom: {outline_mm: [[0, 0], [1300, 0], [1300, 500], [700, 500], "
               "[700, 1100], [0, 1100]]}\n"
               "obstacles: [{type: box, center_mm: [900, 250], size_mm: [230, 90], "
               "yaw_deg: 33}, {type: cylinder, center_mm: [330, 720], radius_mm: 55}]\n"
               "robot: {poses: [{x_mm: 250, y_mm: 250}]}\n", "ways.yaml")
    rng = np.random.default_rng(11)
    x0, y0 = rng.uniform(-0.1, 1.4, 600), rng.uniform(-0.1, 1.2, 600)
    x1, y1 = x0 + rng.normal(0, 0.4, 600), y0 + rng.normal(0, 0.4, 600)
    t = np.linspace(0.0, 1.0, 4000)[:, None]
    px, py = x0 + t * (x1 - x0), y0 + t * (y1 - y0)
    free = inside_outline(px, py, sc.room.outline_m)
    for ob in sc.obstacles:
        free &= ~inside_obstacle(ob, px, py)
    want = free.all(axis=0)
    got = metrics._clear_way(sc, x0, y0, x1, y1)
    np.testing.assert_array_equal(got, want)
    assert int(want.sum()) == 112


def test_scoring_moves_a_progress_bar_and_chunks_change_nothing(monkeypatch):
    # a 1 mm grid of a few m² walks ~10⁹ cells of lines of sight a pose (half a minute):
    # the walk goes in chunks with a bar over the cells; the truth is the same
    from irring.scenario import loads

    sc = loads(FAR_CORNER.replace("    - {x_mm: 262", "    - {x_mm: 700, y_mm: 610}\n"
                                  "    - {x_mm: 262"), "two_poses.yaml")
    grid = OccupancyGrid.for_scenario(sc)
    whole = ground_truth(sc, grid)

    class Bar:
        total, done, calls = None, 0, 0

        def __init__(self):
            self.sizes = []

        def reset(self, total):
            self.total = total

        def update(self, n):
            self.done += n
            self.calls += 1
            self.sizes.append(n)

    bar = Bar()
    monkeypatch.setattr(metrics, "SIGHT_CHUNK_CELLS", 3001)
    chunked = ground_truth(sc, grid, bar)
    for field in ("visible", "reachable_free", "in_range", "shadow", "shadow_ranged"):
        np.testing.assert_array_equal(getattr(chunked, field), getattr(whole, field))
    assert bar.done == bar.total
    # both poses' cells in range, each pose's walk cut into pieces of at most 3001 (then the
    # cells it need not walk again: seen from the pose before, or already visible)
    assert bar.total > int(whole.in_range.sum())
    assert bar.sizes.count(3001) >= 3 and bar.calls >= 2 * 2


SLAB = """
name: slab_one_side
seed: 41
room: {outline_mm: [[0, 0], [1600, 0], [1600, 1200], [0, 1200]]}
obstacles:
  - {type: box, center_mm: [830, 720], size_mm: [620, 14], yaw_deg: 17}
robot: {poses: [{x_mm: 760, y_mm: 390, yaw_deg: 8}]}
sensor: {model: gp2d12, max_range_mm: 624}
effects: {incidence: {}, noise: {sigma_v: 0.015}, quantization: {}}
map: {resolution_mm: 10}
"""


def test_a_beam_meets_a_face_from_its_front_only():
    # a 14 mm slab seen from one side: the line of sight to its far face is clear (no cell
    # centre lies inside the slab), yet no beam can meet that face, so it is not visible wall;
    # an ideal sensor maps every visible cell (its recall was 0.9962, 58 back-face cells in
    # the truth), and listing the room's corners the other way round changes nothing
    from irring import pipeline
    from irring.scenario import loads
    from irring.studies.rooms import ideal

    sc = loads(SLAB, "slab.yaml")
    grid = pipeline.run(ideal(sc), seed=sc.seed, progress=False, score=False).grid
    truth = ground_truth(sc, grid)
    ob = sc.obstacles[0]
    c, s = math.cos(ob.yaw_rad), math.sin(ob.yaw_rad)
    slab = truth.visible & (truth.surface_owner == OBSTACLE0)
    sy, sx = np.nonzero(slab)
    sp = truth.surface_point[sy, sx]
    across = -s * (sp[:, 0] - ob.center_m[0]) + c * (sp[:, 1] - ob.center_m[1])
    assert np.all(across < -0.0069) and slab.sum() == 73    # the near face, 7 mm below
    assert score(grid, sc, truth)["occupied_recall"] == 1.0
    # the outline listed clockwise: the walls still face into the room
    flipped = SLAB.replace("[[0, 0], [1600, 0], [1600, 1200], [0, 1200]]",
                           "[[0, 1200], [1600, 1200], [1600, 0], [0, 0]]")
    other = ground_truth(loads(flipped, "slab.yaml"), grid)
    np.testing.assert_array_equal(other.visible, truth.visible)
    walls = truth.surface_owner == WALL
    inward = (truth.surface_normal[walls] * np.sign(
        np.array([0.8, 0.6]) - truth.surface_point[walls])).max(axis=1)
    assert (inward > 0.99).all()                             # each wall's normal points in


def test_a_cell_is_visible_only_where_one_pose_both_returns_from_and_meets_it(monkeypatch):
    """Visible wall needs a return and a meeting beam from the same pose (docs/mapping.md):
    with returns granted only to the T-room's first pose and meeting beams only to its
    last, no cell is visible (before 0c7705c a return from any pose counted: this failed);
    both granted to either pose, part of the wall is."""
    sc = load_scenario("t_room")
    grid = OccupancyGrid.for_scenario(sc)
    first, last = metrics.views(sc, grid)[0], metrics.views(sc, grid)[-1]   # its scan poses
    assert (first.x_m, last.x_m) == (sc.robot.poses[0].x_m, sc.robot.poses[-1].x_m)
    measurable, met = metrics._measurable_returning, metrics._met

    def truth(returns_from, meets_from):
        def returning(px, py, pose, ranging, surface):
            near, ret = measurable(px, py, pose, ranging, surface)
            return near, ret & (pose == returns_from)

        def meets(*args):      # (scenario, grid, px, py, tx, ty, surface, pose, ranging)
            return met(*args) & (args[7] == meets_from)

        monkeypatch.setattr(metrics, "_measurable_returning", returning)
        monkeypatch.setattr(metrics, "_met", meets)
        return ground_truth(sc, grid)

    assert truth(first, last).visible.sum() == 0
    for pose in (first, last):      # each alone sees part of the T-room's 844 wall cells
        assert 0 < truth(pose, pose).visible.sum() < 844
