"""Round things cut into short lines (issue 13, item 3): a column's arc seen from 0.4–0.6 m is
split into short lines that settle on a θ 20–30° too steep, and their readings were placed
30–130 mm in front of the surface, a false wall the mapper painted. Such a line's members
leave it and are read as readings on no line (arcs.local_incidence, "Round things" in
docs/estimator.md). A room of our own with round things of sizes no held-out room has (a
220 mm column, a 130 mm post), asymmetric poses. Before this rule (main at 922d3b9), over
the three seeds: 263 of 401 valid readings on the column and 73 of 142 on the post more
than 25 mm in front of the surface, occupied precision 0.881–0.919, F1 0.893–0.927."""

from __future__ import annotations

import math

import numpy as np

from _synthetic import make_sweep
from irring import pipeline
from irring.core import Ring
from irring.designs import PAPER_RING
from irring.estimation.estimate import Calibration, estimate_detail
from irring.scenario import loads

ROOM = """
name: round_column_110
seed: 71
room: {outline_mm: [[0, 0], [2300, 0], [2300, 1750], [0, 1750]]}
obstacles:
  - {type: cylinder, center_mm: [1430, 980], radius_mm: 110}
  - {type: cylinder, center_mm: [640, 1290], radius_mm: 65}
robot:
  poses:
    - {x_mm: 880, y_mm: 640, yaw_deg: 7}
    - {x_mm: 1960, y_mm: 560, yaw_deg: -23}
    - {x_mm: 1150, y_mm: 1480, yaw_deg: 41}
sensor: {model: gp2d12, max_range_mm: 624}
effects: [incidence, noise, quantization]
"""


def test_round_things_are_not_painted_in_front_of_themselves():
    sc = loads(ROOM, source="<test>")
    in_front = {0: [0, 0], 1: [0, 0]}      # per round thing: readings > 25 mm in front, all
    for seed in range(sc.seed, sc.seed + 3):
        run = pipeline.run(sc, seed=seed, progress=False)
        for j, ob in enumerate(sc.obstacles):
            (cx, cy), r = ob.center_m, ob.radius_m
            for sw, p in zip(run.sweeps, run.points):
                hit = sw.truth.hit_point
                on = p.valid & (np.hypot(hit[..., 0] - cx, hit[..., 1] - cy) < r + 0.002)
                ahead = np.hypot(p.x - cx, p.y - cy)[on] - r
                in_front[j][0] += int((ahead > 0.025).sum())
                in_front[j][1] += int(on.sum())
        # measured after: precision 0.975, 0.982, 0.985; F1 0.970, 0.976, 0.979
        assert run.scores["occupied_precision"] >= 0.95, (seed, run.scores)
        assert run.scores["occupied_f1"] >= 0.95, (seed, run.scores)
        assert run.scores["free_accuracy"] >= 0.99, (seed, run.scores)
    # measured after: 32 of 330 on the column, 11 of 134 on the post
    (col, col_n), (post, post_n) = in_front[0], in_front[1]
    assert col_n >= 300 and post_n >= 120, in_front
    assert col / col_n <= 0.15 and post / post_n <= 0.15, in_front


def test_a_straight_wall_seen_steeply_keeps_its_line():
    """The rule asks only lines whose members' own profiles bend away from the beam: a
    flat wall met at 35–60° is straight in every sensor's profile, so its readings stay
    on their line and keep its θ (within a few degrees of the truth)."""
    cal = Calibration.nominal("gp2d12", PAPER_RING)
    ring = Ring(sensors=3, radius_m=0.15)
    wall = [((0.41, -0.9), (0.41, 0.9))]
    sweep, d, inc = make_sweep(cal, walls=wall, pose=(0.0, 0.0, math.radians(47)), ring=ring,
                               noise_counts=1.0, seed=5, quantize=True)
    est = estimate_detail(sweep, cal)
    p = est.points
    steep = p.valid & (inc > math.radians(35)) & (inc < math.radians(60))
    assert steep.sum() >= 20
    assert np.all(est.lines.label[steep] >= 0)
    assert np.median(np.degrees(np.abs(p.theta - inc))[steep]) < 3.0
    assert np.percentile(np.abs(p.d - d)[steep], 90) < 0.015
