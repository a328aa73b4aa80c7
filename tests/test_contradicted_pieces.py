"""A line its counts contradict, read as pieces its counts do fit (counts.counts_pieces):
one sensor turning a full turn in a many-sided room (docs/estimator.md, "A contradicted
line's pieces")."""

from __future__ import annotations

import numpy as np

from irring import pipeline
from irring.core import Reason
from irring.estimation import estimate as fast
from irring.estimation import counts as est_counts
from irring.estimation.estimate import estimate
from irring.estimation.counts import _best_halves
from irring.scenario import loads

# a D-shaped room (part of a 20-gon, radius ~1 m, a flat chord side) seen by one GP2D12
# turning off its centre: its sweep's lines run over several facets (corners of 18°), and
# their counts contradict them (from (2776, 2954) mm the only such line was the one the
# turn's seam cut in two, read whole since irring.estimation.seam)
D_ROOM_ROT1 = """
name: d_room_rot1
seed: 5201
room:
  outline_mm: [[2596, 1560], [2903, 1607], [3178, 1740], [3372, 1966], [3522, 2227],
               [3537, 2533], [3426, 2824], [3266, 3092], [3008, 3282], [2724, 3439],
               [2401, 3462], [2102, 3383], [1828, 3253], [1634, 3030]]
robot:
  design: rotating1
  poses:
    - {x_mm: 2900, y_mm: 2700, yaw_deg: 93.7}
sensor: {model: gp2d12, max_range_mm: 800, adc_bits: 12}
effects: {incidence: {}, noise: {sigma_v: 0.015}, quantization: {}}
"""


def _sweep():
    sc = loads(D_ROOM_ROT1)
    acq, _ = pipeline.simulated(sc, seed=5201, progress=False)
    return acq.sweeps[0], pipeline.scene_calibration(sc)[0]


def test_two_lines_make_the_best_halves_of_a_bent_run():
    # 8 points along y = 0, then 6 up a wall at x = 8.5: only the split after the eighth
    # leaves both runs straight
    x = np.r_[np.arange(8.0), np.full(6, 8.5)]
    y = np.r_[np.zeros(8), np.arange(1.0, 7.0)]
    assert _best_halves(x, y, 3) == 8
    assert _best_halves(x[::-1], y[::-1], 3) == 6
    # each run must keep lo points: with 7 of 14 the one split left is the middle
    assert _best_halves(x, y, 7) == 7


def test_a_turning_sensor_keeps_the_facets_its_lines_ran_over(monkeypatch):
    sw, cal = _sweep()
    p = estimate(sw, cal)
    hit = sw.truth.hit_point[..., :2]
    err = np.hypot(p.x - hit[..., 0], p.y - hit[..., 1])[p.valid]
    # all 110 returns read on the facet pieces at 19.8 mm RMS, the worst 51 mm (a corner's
    # reading on the next facet's piece)
    assert np.count_nonzero(p.reason == Reason.INCIDENCE_UNKNOWN) == 0
    assert np.count_nonzero(p.valid) == 110
    assert np.sqrt(np.mean(err ** 2)) < 0.021
    assert err.max() < 0.055
    # without the pieces: 55 INCIDENCE_UNKNOWN (the lines' members, their own ±5-step
    # profiles too flat to bound θ), 55 kept at θ = 0
    monkeypatch.setattr(est_counts, "counts_pieces", lambda points, *args: points)
    p = estimate(sw, cal)
    assert np.count_nonzero(p.reason == Reason.INCIDENCE_UNKNOWN) == 55
    assert np.count_nonzero(p.valid) == 55


def test_the_pieces_agree_in_the_oracle_and_the_compiled_estimator():
    from test_estimate_oracle import assert_agree
    sw, cal = _sweep()
    assert_agree(sw, cal)
