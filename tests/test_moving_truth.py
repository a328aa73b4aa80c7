"""A moving scene's ground truth is judged from where its ring read along the drive, and
`irring run` says how the drive's path ended against its sweeps (docs/mapping.md, "A moving
ring's truth"; docs/dynamics.md, "Where the path ends")."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from irring import pipeline
from irring.cli.run import summary_lines
from irring.core import Pose
from irring.maps.mapping import OccupancyGrid
from irring.maps.metrics import VIEW_SPAN_CELLS, ground_truth, views
from irring.scenario import loads
from irring.simulation.sim import SimRing
from irring.studies.rooms import ideal

# 13 walls, nothing symmetric; the robot drives 445 mm at 80 mm/s turning from -96.6° to
# -139.3°; at 75 ms settle a sweep takes 5.6 s, so it is swept once, arriving at the path's
# end (also the second listed pose) before the last step
THIRTEEN = """
name: thirteen_walls_moving
seed: 1
room:
  outline_mm: [[1668, 812], [1531, 1033], [1298, 1453], [1012, 1591], [860, 1537],
               [545, 1495], [352, 1311], [106, 1097], [24, 959], [108, 799], [336, 217],
               [817, 213], [1470, 287]]
robot:
  design: rotating12
  poses:
    - {x_mm: 603, y_mm: 816, yaw_deg: -96.6}
    - {x_mm: 1038, y_mm: 908, yaw_deg: -139.3}
sensor: {model: gp2d12}
scan: {settle_ms: 75}
effects:
  incidence: {}
  noise: {sigma_v: 0.015}
  quantization: {}
  belt_dynamics: {}
  timing: {}
  motion:
    speed_mm_s: 80
    path:
      - {x_mm: 603, y_mm: 816, yaw_deg: -96.6}
      - {x_mm: 1038, y_mm: 908, yaw_deg: -139.3}
map: {resolution_mm: 10}
"""

# an empty 2.4 x 1.2 m room, poses at (500, 600) and (1900, 600) mm, 50 mm cells; with timing
# a step reads 75 ms settle after its move (4 ms a step, none before the first): read i at
# 0.075 + 0.079 i s, i = 0 … 70, the last at 5.605 s; the rewind (70 steps + one GP2
# period) starts the next sweep at 5.9233 s
BOX = """
name: box_drive
seed: 3
room: {outline_mm: [[0, 0], [2400, 0], [2400, 1200], [0, 1200]]}
robot:
  design: rotating12
  poses: [{x_mm: 500, y_mm: 600}, {x_mm: 1900, y_mm: 600}]
sensor: {model: gp2d12}
scan: {settle_ms: 75}
effects:
  timing: {}
  motion:
    speed_mm_s: SPEED
    path: [{x_mm: 500, y_mm: 600, yaw_deg: 0}, {x_mm: END, y_mm: 600, yaw_deg: YAW}]
map: {resolution_mm: 50}
"""


def box(end_mm: float, speed_mm_s: float = 100, yaw_deg: float = 0):
    text = BOX.replace("SPEED", f"{speed_mm_s:g}").replace("END", f"{end_mm:g}") \
        .replace("YAW", f"{yaw_deg:g}")
    return loads(text, "box_drive.yaml")


def test_a_moving_scenes_ideal_sensor_maps_what_its_truth_calls_visible():
    # judged from its two listed poses this room's ideal map scored F1 0.745 (recall 0.593):
    # the truth counted the wall in reach of the path's end, which the ring never swept at
    sc = loads(THIRTEEN, "thirteen.yaml")
    run = pipeline.run(ideal(sc), progress=False)
    assert len(run.sweeps) == 1
    assert summary_lines(run, {})[2] == ("  note      the robot reached the path's end during "
                                         "sweep 1: its last step (of 71) was read standing "
                                         "there (kept)")
    assert run.scores["occupied_f1"] >= 0.95, run.scores
    assert run.scores["occupied_recall"] >= 0.95, run.scores


def test_the_truth_counts_only_what_is_in_reach_of_where_the_ring_read():
    # a path of no length (a turn in place takes no time): the ring sweeps standing at the
    # first pose, turned to 30°, so the truth is the standing ring's there, and nothing near
    # the second listed pose, 1.4 m off, is in range
    sc = box(500, yaw_deg=30)
    turned = (Pose(0.5, 0.6, math.radians(30)),)
    standing = dataclasses.replace(sc, effects={},
                                   robot=dataclasses.replace(sc.robot, poses=turned))
    both = dataclasses.replace(standing, robot=sc.robot)
    grid = OccupancyGrid.for_scenario(sc)
    got, alone, listed = (ground_truth(s, grid) for s in (sc, standing, both))
    (view,) = views(sc, grid)
    assert view.full and (view.x_m, view.y_m) == (0.5, 0.6)
    assert view.yaw_rad == pytest.approx(math.radians(30), abs=1e-15)
    for field in ("in_range", "visible", "reachable_free"):
        np.testing.assert_array_equal(getattr(got, field), getattr(alone, field))
    xs, ys = grid.cell_centers()
    px, py = np.meshgrid(xs, ys)
    far = np.hypot(px - 0.5, py - 0.6) > got.reach_m
    assert int((got.in_range & far).sum()) == 0
    assert int((listed.in_range & far).sum()) > 100   # what the listed poses' truth held


def test_the_truth_of_a_drive_follows_its_path_and_not_its_listed_end():
    # 1400 mm at 100 mm/s: 14 s, two full sweeps and a third from 11.85 s cut at the end
    # (reads from 14 s on stand there); the truth's reach is the drive's (views grouping its
    # steps), and a path that stops earlier reaches nothing past it
    sc = box(1900)
    grid = OccupancyGrid.for_scenario(sc)
    truth = ground_truth(sc, grid)
    vs = views(sc, grid)
    xy = np.array([(v.x_m, v.y_m) for v in vs])
    assert xy[:, 0].max() == pytest.approx(1.9) and np.all(np.abs(xy[:, 1] - 0.6) < 1e-12)
    # every read the simulator takes is within a cell (half a group's span) of a view
    with SimRing(sc) as sim:
        read = np.concatenate([sim.sweep(k).reading_poses[:, 0, :2]
                               for k in range(sim.n_sweeps)])
    assert sim.n_sweeps == 3 and read[:, 0].max() == pytest.approx(1.9)
    gap = np.min(np.hypot(*(read[:, None] - xy[None]).transpose(2, 0, 1)), axis=1)
    assert gap.max() <= VIEW_SPAN_CELLS / 2 * grid.resolution_m + 1e-9
    assert len(vs) >= 1.4 / (VIEW_SPAN_CELLS * grid.resolution_m)
    xs, ys = grid.cell_centers()
    px, py = np.meshgrid(xs, ys)
    near = np.min(np.hypot(px[..., None] - xy[:, 0], py[..., None] - xy[:, 1]), axis=-1)
    assert not (truth.in_range & (near > truth.reach_m + 1e-9)).any()
    short = box(1200)                            # a path that stops 700 mm earlier
    t_short = ground_truth(short, grid)
    right = px > 1.2 + t_short.reach_m
    assert int((t_short.in_range & right).sum()) == 0
    assert int((truth.in_range & right).sum()) > 0


def _lines(sc):
    run = pipeline.run(sc, progress=False)
    return run, summary_lines(run, {})


def test_a_path_that_ends_during_a_sweep_says_its_last_steps_were_read_standing():
    # 453.85 mm at 100 mm/s: arrives at 4.5385 s, between read 56 (4.499 s) and read 57
    # (4.578 s): reads 57 … 70 (14) are taken standing at the end, and kept
    run, lines = _lines(box(953.85))
    assert len(run.sweeps) == 1 and run.readings()["total"] == 71 * 12
    drive = run.summary()["drive"]
    assert drive["cut"] == {"sweep": 1, "steps_standing": 14, "steps": 71}
    assert drive["unswept_m"] == 0.0
    assert lines[1] == "  design rotating12, 1 sweep(s) along a 454 mm path, 852 readings: " \
        + lines[1].split("852 readings: ")[1]
    assert lines[2] == ("  note      the robot reached the path's end during sweep 1: its last "
                        "14 of 71 steps were read standing there (kept)")
    poses = run.sweeps[0].reading_poses[:, 0]
    np.testing.assert_allclose(poses[57:, 0], 0.95385, atol=1e-12)
    assert poses[56, 0] < 0.95385


def test_a_path_that_ends_after_the_last_sweep_says_what_was_not_swept():
    # 290 mm at 50 mm/s: arrives at 5.8 s, after sweep 1's last read (5.605 s) and before
    # sweep 2 would start (5.9233 s): no second sweep, the last 9.75 mm unswept
    run, lines = _lines(box(790, speed_mm_s=50))
    assert len(run.sweeps) == 1
    drive = run.summary()["drive"]
    assert drive["cut"] is None
    assert drive["unswept_m"] == pytest.approx(0.00975, abs=1e-9)
    assert lines[2] == ("  note      the path's last 10 mm were driven after the last sweep "
                        "(during its rewind); no sweep starts once the robot has arrived, so "
                        "nothing was read there")
    # the map picture draws the route the ring read along, not rings at listed poses
    route = run.route
    assert route.shape == (71, 2)
    np.testing.assert_allclose(route[[0, -1]], [[0.50375, 0.6], [0.78025, 0.6]], atol=1e-9)


def test_a_standing_scene_has_no_drive_and_no_route():
    run = pipeline.run(dataclasses.replace(box(1900), effects={}), progress=False)
    assert "drive" not in run.summary() and run.route is None
    assert "2 pose(s)" in summary_lines(run, {})[1]
