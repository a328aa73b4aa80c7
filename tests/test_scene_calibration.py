"""The estimator reads a simulated scene with the calibration of what the scene simulates
(issue 13 item 1): no ``incidence`` → no θ dependence; the noise it adds; one path for run,
compare, bench and replay; a recording carries it; an ideal sensor never maps worse."""

from __future__ import annotations

import math

import numpy as np
import pytest

from irring.studies import compare
from irring import pipeline
from irring.estimation.calibration import Calibration, scene_calibration
from irring.estimation.estimate import estimate
from irring.scenario import loads

# a 1.5 × 0.7 m room of our own (not bundled), two poses off the centre line
ROOM = """
name: narrow_room
seed: 3
room:
  outline_mm: [[0, 0], [1500, 0], [1500, 700], [0, 700]]
robot:
  poses:
    - {x_mm: 400, y_mm: 350}
    - {x_mm: 1100, y_mm: 330}
sensor: {model: gp2d12, max_range_mm: 624}
"""


def scene(effects: str) -> object:
    return loads(ROOM + f"effects: {effects}\n", source="<test>")


def test_a_scene_without_incidence_gets_a_curve_without_theta():
    cal = Calibration.for_scene(scene("{noise: {sigma_v: 0.004}}"))
    assert cal.theta_rad.tolist() == [0.0]
    a0, b0 = cal.ab(0.0)
    a60, b60 = cal.ab(math.radians(60))
    assert (a60, b60) == (a0, b0)
    # the scene's noise, in counts of its 12-bit 5 V ADC (1.2207 mV per count)
    assert cal.noise_counts == pytest.approx(0.004 / (5.0 / 4096), rel=1e-12)
    assert "no incidence" in cal.source


def test_a_scene_with_incidence_gets_the_table_and_its_drop_out_angle():
    cal = Calibration.for_scene(scene("{incidence: {max_incidence_deg: 62}}"))
    nominal = Calibration.nominal("gp2d12")
    np.testing.assert_array_equal(cal.theta_rad, nominal.theta_rad)
    np.testing.assert_array_equal(cal.a, nominal.a)
    assert math.degrees(cal.max_incidence_rad) == pytest.approx(62.0)
    # no noise effect: the 0.1 mV floor, not the datasheet's 15 mV
    assert cal.noise_counts == pytest.approx(1e-4 / (5.0 / 4096))


def test_the_ideal_sensor_reads_exactly_and_maps_no_worse_than_the_noisy_one():
    ideal, noisy = scene("{}"), scene("[incidence, noise, quantization]")
    errs = {}
    for name, sc in (("ideal", ideal), ("noisy", noisy)):
        sweeps = pipeline.simulated(sc, progress=False)[0].sweeps
        cal = scene_calibration(sc)[0]
        e = []
        for sw in sweeps:
            p = estimate(sw, cal)
            hit = sw.truth.hit_point[..., :2]
            ok = p.valid & np.isfinite(hit[..., 0])
            e.append(np.hypot(p.x - hit[..., 0], p.y - hit[..., 1])[ok])
        errs[name] = np.sqrt(np.mean(np.concatenate(e) ** 2))
    # the ideal curve read with its own calibration: end points within float round-off
    assert errs["ideal"] < 1e-6
    assert 0.0005 < errs["noisy"] < 0.012      # noise, and θ still to be found
    runs = {name: pipeline.run(sc, progress=False) for name, sc in
            (("ideal", ideal), ("noisy", noisy))}
    for key in ("occupied_f1", "occupied_precision", "occupied_recall", "free_accuracy"):
        assert runs["ideal"].scores[key] >= runs["noisy"].scores[key], key
    assert runs["ideal"].scores["occupied_f1"] > 0.99


def test_run_records_the_scene_calibration_and_replay_uses_it(tmp_path):
    sc = scene("[incidence, noise]")
    result = pipeline.run(sc, progress=False)
    text = result.recording_meta()["calibration_yaml"]
    assert Calibration.from_dict(__import__("yaml").safe_load(text)).source == \
        Calibration.for_scene(sc).source
    paths = pipeline.write_outputs(result, tmp_path, animation=False)
    again = pipeline.replay(paths["recording"], progress=False)
    assert again.calibration_text == text
    np.testing.assert_array_equal(again.grid.log_odds, result.grid.log_odds)


def test_compare_reads_each_design_with_its_scene_calibration(monkeypatch):
    # the estimator's calibration; the scores ask each scene's curve for its return level
    # on their own (metrics.Returns), so their calls are left out
    import inspect
    from irring.maps import metrics

    seen = []
    real = Calibration.for_scene

    def spy(sc):
        if not any(f.filename == metrics.__file__ for f in inspect.stack()):
            seen.append(sc.sensor.model)
        return real(sc)

    monkeypatch.setattr(Calibration, "for_scene", staticmethod(spy))
    compare.run_scene(scene("[noise]"), "laser")
    assert seen == ["laser"]
