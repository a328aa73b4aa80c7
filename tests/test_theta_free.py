"""Readings no θ moves (docs/estimator.md, "Readings no θ moves"): a calibration without θ
dependence (a scene without the ``incidence`` effect: the ideal sensor of `irring bench
rooms`) reads every reading exactly at θ = 0, so none is INCIDENCE_UNKNOWN, whichever rule
left it so."""

from __future__ import annotations

import numpy as np

from irring import pipeline
from irring.core import Reason
from irring.estimation import estimate as fast
from irring.estimation import estimate_numpy as oracle
from irring.estimation.calibration import scene_calibration
from irring.maps import metrics
from irring.scenario import loads

# A room of our own (after a held-out-like clutter room): a GP2Y0A21 on an 8-sensor ring, a
# post of radius 16.3 mm 0.51-0.56 m from the sensors that see it and a box 88 × 44 mm
# 160 mm beside it; its walls 0.6-1.6 m away. No effects: the ideal sensor.
POST_BESIDE_BOX = """\
name: post_beside_box
seed: 24402
room:
  outline_mm: [[-2721.6, 4387.7], [-5955.5, 4060.0], [-5776.7, 2295.1], [-2542.7, 2622.8]]
obstacles:
  - {type: cylinder, center_mm: [-3699.2, 3851.7], radius_mm: 16.3}
  - {type: box, center_mm: [-3547.9, 3791.0], size_mm: [88.1, 44.0], yaw_deg: -135.84}
robot:
  design: custom
  ring: {sensors: 8, radius_mm: 166, min_step: -47, max_step: 47, joint_limit_deg: 51.8}
  poses:
    - {x_mm: -4214.7, y_mm: 3393.5, yaw_deg: 3.9}
sensor: {model: gp2y0a21, adc_bits: 12}
map: {resolution_mm: 20}
"""
POST = (-3.6992, 3.8517, 0.0163)


def _measure(scene):
    run = pipeline.run(scene, progress=False)
    sw, p = run.sweeps[0], run.points[0]
    hit = sw.truth.hit_point
    on = np.abs(np.hypot(hit[..., 0] - POST[0], hit[..., 1] - POST[1]) - POST[2]) < 0.002
    truth = run.truth
    visible = truth.visible & (truth.surface_owner >= metrics.OBSTACLE0)
    found = visible & metrics._dilate(run.grid.classify() == metrics.OCCUPIED)
    return run, sw, p, on, (int(visible.sum()), int(found.sum()))


def test_an_ideal_sensors_post_is_not_left_unknown(monkeypatch):
    """POST_BESIDE_BOX, seed 24402: the post's six readings (two sensors, three steps each)
    join the box's line, which a silent gap contradicts, and leave it INCIDENCE_UNKNOWN
    (across_silence's final pass), and far_posts takes none of them. Their θ = 0 distances
    are exact: placed
    there, all six are valid within 1 µm of the truth and the obstacles' 12 visible cells are
    all mapped, against 8 (recall 0.951) with them unknown."""
    scene = loads(POST_BESIDE_BOX)
    run, sw, p, on, cells = _measure(scene)
    assert int(on.sum()) == 6 and bool(p.valid[on].all())
    assert np.abs(p.d - sw.truth.distance_m)[on].max() < 1e-6 and np.all(p.theta[on] == 0.0)
    assert cells == (12, 12) and run.scores["occupied_recall"] == 1.0
    # the numpy oracle (final_estimate is shared) reads them alike
    cal, _ = scene_calibration(scene)
    slow = oracle.estimate_detail(sw, cal).points
    np.testing.assert_array_equal(slow.valid[on], p.valid[on])
    np.testing.assert_allclose(slow.d[on], p.d[on], rtol=0, atol=1e-12)
    monkeypatch.setattr(fast, "unknown_theta_free", lambda points, counts, cal: points)
    run0, _, p0, on0, cells0 = _measure(scene)
    assert int((on0 & (p0.reason == Reason.INCIDENCE_UNKNOWN)).sum()) == 6
    assert cells0 == (12, 8) and run0.scores["occupied_recall"] < 0.96


def test_a_sensor_with_incidence_keeps_its_unknowns(monkeypatch):
    """The same room with the default effects (incidence, 15 mV noise, quantization): θ
    moves every reading there by far more than its noise, so the rule places none and the
    estimate is the same field for field with it or without it."""
    scene = loads(POST_BESIDE_BOX.replace(
        "map:", "effects: {incidence: {}, noise: {sigma_v: 0.015}, quantization: {}}\nmap:"))
    acq, _ = pipeline.simulated(scene, progress=False)
    cal, _ = scene_calibration(scene)
    sw = acq.sweeps[0]
    with_rule = fast.estimate(sw, cal)
    assert int((with_rule.reason == Reason.INCIDENCE_UNKNOWN).sum()) > 0
    monkeypatch.setattr(fast, "unknown_theta_free", lambda points, counts, cal: points)
    without = fast.estimate(sw, cal)
    for name in ("x", "y", "d", "theta", "sigma_m", "valid", "reason"):
        np.testing.assert_array_equal(getattr(with_rule, name), getattr(without, name), name)
