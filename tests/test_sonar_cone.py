"""A sonar's reading is an echo from somewhere on an arc of its ±15° cone (issue 13 item 7):
the mapper draws the arc (Moravec–Elfes), not a point on the cone's axis."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from _synthetic import single_ray
from irring import pipeline
from irring.maps import metrics
from irring.maps.mapping import OccupancyGrid, cone_fan
from irring.scenario import loads

# a room of our own seen by the 12-transducer sonar ring (its own sensor: no sensor block)
SONAR_ROOM = """\
name: sonar_room
seed: 9
room:
  outline_mm: [[0, 0], [2130, 0], [2130, 1370], [0, 1370]]
robot:
  design: sonar12
  poses:
    - {x_mm: 640, y_mm: 520}
    - {x_mm: 1510, y_mm: 830, yaw_deg: 15}
    - {x_mm: 1180, y_mm: 350, yaw_deg: -7}
"""


def test_a_cone_reading_marks_its_arc_and_frees_its_sector():
    g = OccupancyGrid((0.0, 0.0), (100, 100), 0.01)
    p = dataclasses.replace(single_ray(0.105, 0.505, 0.0, 0.6, sigma_m=0.01),
                            cone_half_angle_rad=math.radians(15))
    g.insert(p)
    c = g.params
    xs, ys = g.cell_centers()
    X, Y = np.meshgrid(xs, ys)
    r, a = np.hypot(X - 0.105, Y - 0.505), np.arctan2(Y - 0.505, X - 0.105)
    arc = (np.abs(r - 0.6) < 0.004) & (np.abs(a) < math.radians(14))
    assert np.all(g.log_odds[arc] > 0.62)                      # the whole arc occupied …
    # … by half a sharp hit per ray of the fan (two rays 1° apart may end in one cell)
    assert g.log_odds.max() <= 2 * c.cone_l_occ + 1e-9
    inside = (r > 0.1) & (r < 0.5) & (np.abs(a) < math.radians(14))
    assert np.all(g.log_odds[inside] < 0)                      # the sector in front cleared
    outside = (np.abs(a) > math.radians(17)) & (r > 0.2)   # (near the emitter cells are wide)
    assert not g.log_odds[outside].any()                       # nothing outside the cone
    # the same as inserting the fan of pencil rays with the cone's weights
    fan = cone_fan(p, c.cone_step_rad)
    assert fan.x.shape == (1, 31) and fan.cone_half_angle_rad == 0.0
    pencil = OccupancyGrid((0.0, 0.0), (100, 100), 0.01, dataclasses.replace(
        c, l_occ=c.cone_l_occ, l_free=c.cone_l_free, l_no_return=c.cone_l_no_return,
        ahead_floor=1.0))
    pencil.insert(fan)
    np.testing.assert_array_equal(g.log_odds, pencil.log_odds)


def test_sonar_ring_maps_with_its_cone_far_better_than_with_axis_points():
    sc = loads(SONAR_ROOM)
    run = pipeline.run(sc, progress=False)
    assert all(p.cone_half_angle_rad == pytest.approx(math.radians(15)) for p in run.points)
    axis = OccupancyGrid.for_scenario(sc)
    for p in run.points:                                       # the old way: echo on the axis
        axis.insert(dataclasses.replace(p, cone_half_angle_rad=0.0))
    old = metrics.score(axis, sc, run.truth)
    new = run.scores
    assert new["occupied_recall"] > 3 * old["occupied_recall"]
    assert new["occupied_f1"] > 0.3 > 2 * old["occupied_f1"]
    assert new["free_accuracy"] >= 0.99                        # silence and passes do not clear walls


def test_ir_points_carry_no_cone():
    run = pipeline.run(loads(SONAR_ROOM.replace("design: sonar12", "design: rotating12")),
                       progress=False, score=False)
    assert all(p.cone_half_angle_rad == 0.0 for p in run.points)
