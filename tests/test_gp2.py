"""The sensor curves: datasheet fits, Eq. 10 and its inverse, θ-dependence, fold-over, ADC."""

from __future__ import annotations

import importlib.util
import math
import sys

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from irring import gp2

GP2 = ("gp2d12", "gp2y0a21", "gp2y0a02")
ALL = GP2 + ("sonar", "laser")


def _raw(name: str) -> dict:
    return yaml.safe_load((gp2.sensors_dir() / f"{name}.yaml").read_text())


def test_bundled_models_are_listed():
    assert set(ALL) <= set(gp2.available())


def test_unknown_sensor_names_the_choices():
    with pytest.raises(ValueError, match=r"unknown sensor model 'gp2xx'.*gp2d12"):
        gp2.sensor("gp2xx")


@pytest.mark.parametrize("name", ["gp2d12", "gp2y0a02"])
def test_table_row_zero_is_the_log_log_fit_of_the_files_points(name):
    raw = _raw(name)
    d = np.asarray(raw["points"]["distance_m"])
    v = np.asarray(raw["points"]["voltage_v"])
    b, log_a = np.polyfit(np.log(v), np.log(d), 1)
    m = gp2.sensor(name)
    assert m.a0 == pytest.approx(math.exp(log_a), rel=1e-8)
    assert m.b0 == pytest.approx(b, rel=1e-8)
    res = d - m.distance(v)
    assert np.allclose(res, raw["fit"]["residual_m"], atol=6e-5)
    assert float(np.sqrt(np.mean(res ** 2))) == pytest.approx(raw["fit"]["rms_residual_m"],
                                                             abs=6e-5)


def test_the_curve_files_are_what_refit_writes_with_the_calibration_fit():
    """models/sensors/refit.py fits each part's points with the calibration's Eq. 10 fit
    (irring.estimation.calibration.fit_curve) and renders every bundled file byte for byte:
    no file was edited by hand past its generator. Loading it changes nothing of this
    process (it imported irring from a sys.path entry of its own)."""
    path_before = list(sys.path)
    spec = importlib.util.spec_from_file_location("refit", gp2.sensors_dir() / "refit.py")
    refit = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(refit)
    assert sys.path == path_before
    assert set(refit.SPECS) == set(ALL)
    for name, part in refit.SPECS.items():
        assert refit.render(name, part) == (gp2.sensors_dir() / f"{name}.yaml").read_text(), name


def test_gp2d12_fit_matches_datasheet_points_to_about_a_centimetre():
    raw = _raw("gp2d12")
    m = gp2.sensor("gp2d12")
    d = np.asarray(raw["points"]["distance_m"])
    v = np.asarray(raw["points"]["voltage_v"])
    res = d - m.distance(v)
    assert np.sqrt(np.mean(res ** 2)) < 0.006
    assert np.max(np.abs(res)) < 0.015
    # docs/paper.md: ≈ 2.4 V at 10 cm, ≈ 0.4 V at 80 cm
    assert m.voltage(0.10) == pytest.approx(2.45, abs=0.05)
    assert m.voltage(0.80) == pytest.approx(0.42, abs=0.02)


def test_gp2y0a21_is_the_public_fit():
    m = gp2.sensor("gp2y0a21")
    v = np.linspace(0.4, 2.5, 7)
    assert np.allclose(m.distance(v) * 100, 27.728 * v ** -1.2045, rtol=1e-12)


@pytest.mark.parametrize("name", GP2)
def test_gp2_curves_have_a_positive_b_negative_and_fall_with_distance(name):
    m = gp2.sensor(name)
    assert np.all(m.a > 0) and np.all(m.b < 0)  # paper, Eq. 10
    d = np.linspace(m.peak_distance_m, m.max_range_m, 200)
    for theta in (0.0, math.radians(40), math.radians(80)):
        assert np.all(np.diff(m.voltage(d, theta)) < 0)


@settings(max_examples=200, deadline=None)
@given(name=st.sampled_from(ALL), frac=st.floats(0, 1), theta=st.floats(-1.55, 1.55))
def test_inverse_undoes_forward_everywhere_in_range(name, frac, theta):
    m = gp2.sensor(name)
    d = m.min_range_m + frac * (m.max_range_m - m.min_range_m)
    assert abs(m.distance(m.voltage(d, theta), theta) - d) < 1e-12


def test_vectorised_over_distance_and_angle_arrays():
    m = gp2.sensor("gp2d12")
    d = np.full((71, 12), 0.4)
    theta = np.linspace(0, 1.2, 12)[None, :].repeat(71, 0)
    v = m.voltage(d, theta)
    assert v.shape == (71, 12)
    assert np.allclose(m.distance(v, theta), d)
    a, b = m.ab(-theta)  # symmetric in θ
    assert np.allclose(a, m.ab(theta)[0]) and np.allclose(b, m.ab(theta)[1])


def test_fig8_reading_a_50_degree_return_with_the_normal_curve_is_off_by_8_to_16_cm():
    m = gp2.sensor("gp2d12")
    v50 = m.voltage(0.60, math.radians(50))
    error = float(m.distance(v50, 0.0)) - 0.60
    assert 0.08 <= error <= 0.16
    # the error grows with the angle and with distance (a and b both vary, as the paper says)
    errs = [float(m.distance(m.voltage(0.6, math.radians(t)))) - 0.6 for t in (0, 20, 40, 60)]
    assert errs[0] == pytest.approx(0.0, abs=1e-12) and np.all(np.diff(errs) > 0)
    near = float(m.distance(m.voltage(0.3, math.radians(50)))) - 0.3
    assert 0 < near < error / 2 + 0.02


def test_table_interpolates_between_rows_and_holds_past_the_end():
    m = gp2.sensor("gp2d12")
    t0, t1 = m.theta_rad[3], m.theta_rad[4]
    a_mid, b_mid = m.ab(0.5 * (t0 + t1))
    assert a_mid == pytest.approx(0.5 * (m.a[3] + m.a[4]))
    assert b_mid == pytest.approx(0.5 * (m.b[3] + m.b[4]))
    assert m.ab(math.radians(89))[0] == m.a[-1]


def test_foldover_one_voltage_two_distances():
    m = gp2.sensor("gp2d12")
    assert 0.07 <= m.peak_distance_m <= 0.10
    v = np.array([0.6, 1.2, 2.0, 2.6])
    near, far = m.distances(v)
    assert np.all(near < m.peak_distance_m) and np.all(far > m.peak_distance_m)
    assert np.allclose(m.voltage_folded(near), v) and np.allclose(m.voltage_folded(far), v)
    # above the peak nothing gives that voltage
    n, f = m.distances(m.peak_v() + 0.1)
    assert np.isnan(n) and np.isnan(f)
    # the near branch rises towards the peak
    assert np.all(np.diff(m.voltage_folded(np.linspace(0.001, m.peak_distance_m, 50))) > 0)


def test_no_return_is_the_noise_floor_and_reads_as_max_range():
    m = gp2.sensor("gp2d12")
    assert 0.3 <= m.no_return_v <= 0.45
    assert float(m.distance(m.no_return_v)) == pytest.approx(m.max_range_m, abs=1e-12)


@pytest.mark.parametrize("bits,full", [(10, 1023), (12, 4095)])
def test_adc_counts_at_5_volts(bits, full):
    assert gp2.lsb_v(bits, 5.0) == 5.0 / 2 ** bits
    assert gp2.counts_from_voltage(2.5, bits, 5.0) == 2 ** (bits - 1)
    assert gp2.counts_from_voltage(9.0, bits, 5.0) == full
    assert gp2.counts_from_voltage(-1.0, bits, 5.0) == 0
    v = np.linspace(0, 4.99, 101)
    assert np.allclose(gp2.voltage_from_counts(gp2.counts_from_voltage(v, bits), bits), v,
                       atol=1e-15)
    assert gp2.voltage_from_counts(full + 5, bits) == full * 5.0 / 2 ** bits


def test_counts_form_of_eq10_for_the_estimator():
    m = gp2.sensor("gp2d12")
    s = np.array([100.0, 500.0, 1500.0])
    a_c, b = m.ab_counts(math.radians(30), bits=12, vref_v=5.0)
    assert np.allclose(a_c * s ** b, m.distance(gp2.voltage_from_counts(s, 12), math.radians(30)))


def test_linear_hooks_for_sonar_and_laser():
    for name in ("sonar", "laser"):
        m = gp2.sensor(name)
        assert not m.folds and np.all(m.b == 1.0)
        d = np.linspace(m.min_range_m, m.max_range_m, 9)
        assert np.allclose(np.diff(m.voltage(d), 2), 0, atol=1e-12)  # linear
        assert m.no_return_v < 5.0
    assert gp2.sensor("sonar").max_incidence_rad < gp2.sensor("gp2d12").max_incidence_rad


def test_bad_tables_are_refused():
    good = dict(name="x", min_range_m=0.1, max_range_m=0.8, peak_distance_m=0.09,
                theta_rad=np.array([0.0, 0.5]), a=np.array([0.3, 0.2]), b=np.array([-1.2, -1.1]),
                max_incidence_rad=1.2)
    gp2.SensorModel(**good)
    with pytest.raises(ValueError, match="start at θ = 0"):
        gp2.SensorModel(**{**good, "theta_rad": np.array([0.1, 0.5])})
    with pytest.raises(ValueError, match="a > 0"):
        gp2.SensorModel(**{**good, "a": np.array([0.3, -0.2])})
    with pytest.raises(ValueError, match="peak_distance_m"):
        gp2.SensorModel(**{**good, "peak_distance_m": 0.2})


def test_load_sensor_reports_a_bad_file(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("name: bad\nmin_range_m: 0.1\n")
    with pytest.raises(ValueError, match="bad.yaml: not a sensor curve file"):
        gp2.load_sensor(p)
