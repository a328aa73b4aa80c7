"""Calibration rigs: the simulated one recovers the model's d_o and curve; the guided one
for the real ring runs on injected I/O; `irring calibrate` writes a usable file."""

from __future__ import annotations

import dataclasses
import math
import re
import types

import numpy as np
import pytest

from irring import gp2
from irring.estimation.calibration import (Calibration, CalibrationAborted, CalibrationError,
                                      GuidedCalibration, Placement, RigReadings, SimulatedRig,
                                      collect, default_placements, solve)
from irring.core import Sweep
from irring.core import Ring


@pytest.fixture(scope="module")
def rig_fit(t_room):
    return SimulatedRig(t_room).fit()


@pytest.fixture(scope="module")
def rig_cal(rig_fit):
    return rig_fit.calibration


def _with(scenario, **kwargs):
    """The scenario with its ring's numbers changed (as a `robot.ring:` override would)."""
    ring = dataclasses.replace(scenario.ring, **kwargs)
    return dataclasses.replace(scenario, robot=dataclasses.replace(scenario.robot, ring=ring))


def _no_effects(scenario):
    return dataclasses.replace(scenario, effects=types.MappingProxyType({}))


def test_simulated_rig_recovers_d_o_within_1_mm(t_room, rig_cal):
    assert {"noise", "quantization", "incidence"} <= set(t_room.effects)
    assert abs(rig_cal.emitter_offset_m - t_room.ring.emitter_offset_m) < 1e-3


def test_simulated_rig_curve_reproduces_distances_within_1_percent(t_room, rig_cal):
    """Across the range (0.10 … 0.80 m) and every incidence the sensor returns at, the fitted
    a(θ), b(θ) read the model's noise-free counts back to within 1 % of the distance."""
    model = gp2.sensor(t_room.sensor.model)
    top = min(rig_cal.max_theta_rad, model.max_incidence_rad)
    assert math.degrees(top) >= 60.0            # the table reaches steep incidence
    d = np.linspace(model.min_range_m, model.max_range_m, 57)[:, None]
    theta = np.radians(np.arange(0.0, math.degrees(top) + 1e-9, 1.0))[None, :]
    counts = gp2.counts_from_voltage(model.voltage(d, theta), t_room.sensor.adc_bits,
                                     t_room.sensor.vref_v)
    rel = rig_cal.distance(counts, theta) / d - 1.0
    assert np.max(np.abs(rel)) < 0.01, np.max(np.abs(rel))
    # the noise it measured is the scene's 15 mV (≈ 12.3 counts) and quantisation
    lsb = gp2.lsb_v(t_room.sensor.adc_bits, t_room.sensor.vref_v)
    assert rig_cal.noise_counts == pytest.approx(t_room.effects["noise"].sigma_v / lsb, rel=0.15)
    # returns past the drop-out angle were seen as missing, not fitted
    assert rig_cal.max_incidence_rad <= model.max_incidence_rad + 1e-9


def test_rig_without_effects_is_exact_and_flat(t_room):
    """No effects: the sim reads the θ = 0 curve whatever the incidence; the rig says so."""
    cal = SimulatedRig(_no_effects(t_room), sweeps=2).calibrate()   # 2: a spread, of 0
    assert cal.emitter_offset_m == pytest.approx(t_room.ring.emitter_offset_m, abs=1e-7)
    nominal = Calibration.nominal(t_room.sensor.model, t_room.ring)
    assert cal.a[0] == pytest.approx(nominal.a[0], rel=1e-6)
    np.testing.assert_allclose(cal.b, nominal.b[0], rtol=1e-6)
    assert cal.noise_counts == 0.0


@pytest.mark.parametrize("d_o", [0.0, 0.012, -0.004])
def test_rig_follows_the_ring_it_is_given(t_room, d_o):
    cal = SimulatedRig(_no_effects(_with(t_room, emitter_offset_m=d_o)), sweeps=1).calibrate()
    assert cal.emitter_offset_m == pytest.approx(d_o, abs=1e-6)


def test_rig_is_deterministic_under_its_seed(t_room):
    a = SimulatedRig(t_room, seed=5, sweeps=2).calibrate()
    b = SimulatedRig(t_room, seed=5, sweeps=2).calibrate()
    c = SimulatedRig(t_room, seed=6, sweeps=2).calibrate()
    assert a.emitter_offset_m == b.emitter_offset_m and np.array_equal(a.a, b.a)
    assert a.emitter_offset_m != c.emitter_offset_m


def test_rig_places_the_wall_where_it_says(t_room):
    """The generated scene puts the sensor's hinge y from the wall, turned by ψ: the true
    distances of the sim match Eq. 5 with the beam angle h = ψ + φ."""
    rig = SimulatedRig(_no_effects(t_room), sweeps=1,
                       placements=[Placement(0.3, 0.0, "offset"), Placement(0.2, 0.6)])
    for i, placement in enumerate(rig.placements):
        sweep = rig.sim.sweep(i)
        got = sweep.truth.distance_m[:, rig.sensor]
        h = placement.yaw_rad + sweep.sensor_angles[:, rig.sensor]
        want = placement.wall_distance_m / np.cos(h) - t_room.ring.emitter_offset_m * np.tan(h)
        ok = np.isfinite(got)
        assert ok.sum() > 30
        np.testing.assert_allclose(got[ok], want[ok], atol=1e-9)


def test_rig_calibration_serves_the_estimator(t_room, rig_cal, tmp_path):
    """A calibration from the rig, saved and loaded, still halves the steep-incidence error
    on the T-room (the estimator never sees the simulator's own tables)."""
    from irring.studies.estimator import measure

    cal = Calibration.load(rig_cal.save(tmp_path / "cal.yaml"))
    r = measure(t_room, sweeps_per_pose=2, calibration=cal)
    assert r["steep"]["ratio"] <= 0.5, r


# --------------------------------------------------------------------------- pieces


def _sweep(steps, counts, angles=None):
    steps = np.asarray(steps)
    counts = np.asarray(counts, dtype=float).reshape(len(steps), 1)
    angles = np.radians(steps * 1.08)[:, None] if angles is None else angles
    return Sweep(steps=steps, sensor_angles=angles, counts=counts,
                 timestamps_s=np.zeros(len(steps)), duration_s=0.0, pose=np.zeros(3),
                 ring=Ring(sensors=1, radius_m=0.0))


def test_collect_matches_steps_drops_outliers_and_measures_spread():
    a = _sweep([-1, 0, 1], [100.0, 200.0, 300.0])
    b = _sweep([-1, 1], [102.0, 302.0])                      # step 0 never arrived
    c = _sweep([-1, 0, 1], [101.0, 9999.0, 301.0])           # an outlier at step 0
    d = _sweep([-1, 0, 1], [99.0, 202.0, 299.0])
    r = collect([a, b, c, d], Placement(0.3, 0.1, "offset"))
    np.testing.assert_allclose(r.counts, [100.5, 201.0, 300.5])
    np.testing.assert_array_equal(r.repeats, [4, 2, 4])
    np.testing.assert_allclose(r.beam_angle_rad, 0.1 + np.radians([-1.08, 0.0, 1.08]))
    assert r.offset.all() and np.allclose(r.wall_distance_m, 0.3)
    assert r.spread_counts[1] == pytest.approx(math.sqrt(2.0))


def test_collect_and_solve_errors():
    with pytest.raises(CalibrationError, match="at least one sweep"):
        collect([], Placement(0.3))
    model = gp2.sensor("gp2d12")
    y, h = np.meshgrid([0.2, 0.3, 0.4], np.radians(np.arange(-30.0, 31.0, 1.0)))
    y, h = y.ravel(), h.ravel()
    counts = gp2.counts_from_voltage(model.voltage(y / np.cos(h)))
    curve_only = RigReadings(counts=counts, beam_angle_rad=h, wall_distance_m=y,
                             spread_counts=np.zeros(h.size), repeats=np.ones(h.size, int),
                             offset=np.zeros(h.size, bool))
    with pytest.raises(CalibrationError, match="offset placements"):
        solve(curve_only, sensor_model="gp2d12")
    with pytest.raises(CalibrationError, match="no readings"):
        RigReadings.concat([])


def test_default_placements_cover_the_range():
    p = default_placements(0.10, 0.80)
    offsets = [q for q in p if q.purpose == "offset"]
    assert offsets and all(q.yaw_rad == 0.0 for q in offsets)
    central = [q.wall_distance_m / math.cos(q.yaw_rad) for q in p if q.purpose == "curve"]
    assert min(central) >= 0.10 and max(central) <= 0.80
    assert max(q.yaw_rad for q in p) >= math.radians(45)
    assert "mm from sensor 0's rotation axis" in p[-1].describe()


# --------------------------------------------------------------------------- guided procedure


class FakeUser:
    """Answers the guided procedure's prompts and tells the simulated ring which placement
    the wall is at (the placement named in the last prompt, or a wrong one to begin with)."""

    def __init__(self, rig, answers=(), misplace_first=False):
        self.rig = rig
        self.answers = list(answers)
        self.prompts: list[str] = []
        self.shown: list[str] = []
        self.current = 0
        self.reads = 0
        self.misplace = misplace_first

    def prompt(self, text: str) -> str:
        self.prompts.append(text)
        m = re.match(r"\[(\d+)/(\d+)\] Place", text)
        if m:
            self.current = int(m.group(1)) - 1
        return self.answers.pop(0) if self.answers else ""

    def show(self, text: str) -> None:
        self.shown.append(text)

    def read_sweep(self) -> Sweep:
        self.reads += 1
        index = self.current
        if self.misplace:                      # the wall is somewhere else at first
            index = len(self.rig.placements) - 1 - self.current
        return self.rig.sim.sweep(index)


def _guided(rig, user, sweeps=3):
    return GuidedCalibration(read_sweep=user.read_sweep, prompt=user.prompt, show=user.show,
                             sensor_model="gp2d12", sweeps=sweeps, placements=rig.placements)


def test_guided_calibration_on_injected_io(t_room, rig_cal):
    rig = SimulatedRig(t_room, seed=3)
    user = FakeUser(rig)
    cal = _guided(rig, user).run()
    n = len(rig.placements)
    assert user.reads == 3 * n
    assert sum("Place a flat, white wall" in p for p in user.prompts) == n
    assert any("d_o =" in s for s in user.shown)
    assert "guided calibration" in cal.source
    assert abs(cal.emitter_offset_m - t_room.ring.emitter_offset_m) < 1e-3
    d = np.linspace(0.12, 0.7, 20)
    np.testing.assert_allclose(cal.distance(rig_cal.counts(d, 0.3), 0.3), d, rtol=0.02)


def test_guided_calibration_offers_a_retake_for_a_misplaced_wall(t_room):
    """The first look finds the wall elsewhere (far, turned): the user is asked, retakes,
    and the calibration comes out right."""
    rig = SimulatedRig(t_room, seed=4)
    user = FakeUser(rig, answers=["", "r"], misplace_first=True)

    def read_then_fix():
        sweep = user.read_sweep()
        user.misplace = False          # after the first look the user moves the wall
        return sweep

    cal = GuidedCalibration(read_sweep=read_then_fix, prompt=user.prompt, show=user.show,
                            sensor_model="gp2d12", sweeps=2, placements=rig.placements).run()
    asked = [p for p in user.prompts if "is the wall where it should be?" in p]
    assert len(asked) == 1 and asked[0].startswith("[1/")
    assert user.reads == 2 * (len(rig.placements) + 1)
    assert abs(cal.emitter_offset_m - t_room.ring.emitter_offset_m) < 1e-3


def test_guided_calibration_quit_and_skip(t_room):
    rig = SimulatedRig(t_room)
    user = FakeUser(rig, answers=["", "q"])
    with pytest.raises(CalibrationAborted, match="placement 2"):
        _guided(rig, user, sweeps=1).run()
    offsets = sum(p.purpose == "offset" for p in rig.placements)
    user = FakeUser(rig, answers=["s"] * offsets)
    with pytest.raises(CalibrationError, match="no offset placement"):
        _guided(rig, user, sweeps=1).run()
    assert sum("skipped" in s for s in user.shown) == offsets


# --------------------------------------------------------------------------- the command


def test_irring_calibrate_writes_a_loadable_file(tmp_path, capsys):
    from irring.cli import main

    out = tmp_path / "ring.yaml"
    assert main(["calibrate", "--out", str(out), "--sweeps", "2"]) == 0
    text = capsys.readouterr().out
    assert "wrote" in text and "d_o =" in text
    cal = Calibration.load(out)
    assert cal.sensor_model == "gp2d12" and abs(cal.emitter_offset_m - 0.007) < 1e-3
    # and its picture beside it, named with .png: a PNG of the stated size
    from PIL import Image

    from irring.estimation import calibration_chart

    png = tmp_path / "ring.png"
    assert f"wrote {png} (the readings, the fitted curve and its errors)" in text
    with Image.open(png) as image:
        assert image.format == "PNG"
        assert image.size == tuple(round(v * calibration_chart.DPI)
                                   for v in calibration_chart.SIZE_IN) == (1100, 850)


def test_irring_calibrate_help_explains_units_and_port(capsys):
    from irring.cli import main

    with pytest.raises(SystemExit):
        main(["calibrate", "--help"])
    text = capsys.readouterr().out
    for phrase in ("--port", "mm", "degrees", "Eq. 9", "Eq. 10", "examples"):
        assert phrase in text
    assert "its picture is written beside it, named with .png\n" \
           "                        (calibration.png)" in text


def test_irring_calibrate_reports_a_bad_port(tmp_path, capsys):
    from irring.cli import main

    code = main(["calibrate", "--port", str(tmp_path / "no-such-tty"), "--out",
                 str(tmp_path / "x.yaml")])
    assert code == 3
    assert "cannot open" in capsys.readouterr().err
    assert not (tmp_path / "x.yaml").exists()


def test_guided_calibration_blames_the_placement_when_nothing_fits(t_room):
    """Readings of a room instead of the requested walls (what `irring emulate` serves):
    no curve fits, and the error says which placements already looked wrong."""
    from irring.simulation.sim import SimRing

    sim = SimRing(t_room)
    user = FakeUser(SimulatedRig(t_room))
    g = GuidedCalibration(read_sweep=lambda: sim.sweep(0), prompt=user.prompt, show=user.show,
                          sensor_model="gp2d12", sweeps=1)
    with pytest.raises(CalibrationError, match="was the wall where it was asked to be"):
        g.run()


@pytest.mark.parametrize("seed", [1, 3])
def test_one_sweep_a_placement_ends_the_table_before_steep_rows_it_cannot_fit(t_room, seed):
    """`irring calibrate --sweeps 1` (allowed: ≥ 1) failed for 2 seeds in 6 with 'fitted b(θ)
    changes sign … are the readings and distances paired correctly?': the 85° row rests on
    a few noisy readings. The table now ends before the first row of the wrong sign."""
    cal = SimulatedRig(t_room, sweeps=1, seed=seed).calibrate()
    assert np.all(cal.b < 0) and 60.0 <= math.degrees(cal.max_theta_rad) < 85.0
    # one sweep measures no spread: the noise is the datasheet's and says so (it was 0.0,
    # so the estimator judged returns by quantisation alone)
    nominal = Calibration.nominal(t_room.sensor.model, None, t_room.sensor.adc_bits,
                                  t_room.sensor.vref_v)
    assert cal.noise_counts == nominal.noise_counts > 10.0
    assert cal.source.endswith("; noise: the datasheet's (no repeated readings to measure it)")
    model = gp2.sensor(t_room.sensor.model)
    d = np.linspace(model.min_range_m, model.max_range_m, 15)[:, None]
    theta = np.radians(np.arange(0.0, 46.0, 5.0))[None, :]
    counts = gp2.counts_from_voltage(model.voltage(d, theta), t_room.sensor.adc_bits,
                                     t_room.sensor.vref_v)
    assert np.max(np.abs(cal.distance(counts, theta) / d - 1.0)) < 0.03


def test_a_fit_whose_second_row_flips_sign_is_still_refused():
    """Only steep rows are trimmed: readings that flip b at 5° are not of a wall."""
    from irring.estimation.calibration import fit_curve

    rng = np.random.default_rng(2)
    d = rng.uniform(0.1, 0.8, 200)
    theta = np.where(np.arange(200) % 2, math.radians(5.0), 0.0)
    counts = np.where(theta > 0, 40.0 * d, 0.5 / d)    # rising at 5°, falling at 0°
    with pytest.raises(CalibrationError, match="changes sign"):
        fit_curve(counts, d, theta, np.radians([0.0, 5.0, 10.0]), min_readings=2)


@pytest.mark.parametrize("design, message", [
    # "cannot determine the emitter offset d_o: Σ tan²φ = 0 over 4 readings … sweep the sensor
    # across angles on both sides of the wall normal": a radial ring cannot
    ("radial12", "its design, radial12, does not turn its sensors (motor steps 0 … 0); the "
                 "procedure reads d_o from a sensor turned across a wall (paper Eq. 9): use a "
                 "turning design (rotating12, rotating1)"),
    # "emitter_offset_m -0.161 is not a plausible d_o (|d_o| < 0.1 m)"
    ("laser", "its sensor, laser, reads distance linearly; irring calibrate fits a GP2's curve "
              "d = a(θ)·S^b(θ) (paper Eq. 10): use a scenario with a GP2 sensor"),
    ("sonar12", "its sensor, sonar, reads distance linearly"),
])
def test_calibrate_refuses_a_scene_the_wall_procedure_cannot_calibrate(tmp_path, capsys, design,
                                                                       message):
    from irring.cli import main
    scene = tmp_path / "scene.yaml"
    scene.write_text("name: s\nroom: {outline_mm: [[0, 0], [1000, 0], [1000, 800], [0, 800]]}\n"
                     f"robot: {{design: {design}, poses: [{{x_mm: 500, y_mm: 400}}]}}\n")
    assert main(["calibrate", "--scenario", str(scene), "--out", str(tmp_path / "c.yaml"),
                 "--sweeps", "1"]) == 1
    assert f"irring calibrate: error: {scene}: {message}" in capsys.readouterr().err
    assert not (tmp_path / "c.yaml").exists()


# --------------------------------------------------------------------------- the picture


def test_the_picture_plots_the_fitted_readings_and_the_calibrations_curve(t_room, rig_fit):
    """What `irring calibrate` draws comes from the fit: the readings it fitted (and, apart,
    those it did not), its curve at those distances, each reading's error under it, and
    the sensor's fold-over peak."""
    from irring.estimation.calibration_chart import CURVE_THETAS_DEG, chart_data

    cal, r, used = rig_fit.calibration, rig_fit.readings, rig_fit.used
    c = chart_data(rig_fit)
    ok = np.isfinite(r.counts)
    assert 0 < used.sum() < ok.sum()        # no-return readings past the drop-out were left
    assert not (used & ~ok).any()           # the fit uses finite counts only (the chart relies on it)
    np.testing.assert_array_equal(c["counts"], r.counts[used])
    assert c["counts"].size + c["unused_counts"].size == ok.sum()
    true_mm = r.true_distance(cal.emitter_offset_m)[used] * 1e3
    np.testing.assert_array_equal(c["distance_mm"], true_mm)
    # fitted within the range (the last fit's d_o differs from the final one by < 1 mm)
    assert cal.min_range_m * 1e3 - 1 < true_mm.min() and true_mm.max() < cal.max_range_m * 1e3 + 1
    # the curves: the calibration's counts at the plotted distances, θ = 0 up to the drop-out
    thetas = [t for t, _, _ in c["curves"]]
    assert thetas == [t for t in CURVE_THETAS_DEG if t <= math.degrees(cal.max_incidence_rad)]
    assert thetas[0] == 0.0 and len(thetas) >= 4
    for t, d_mm, n in c["curves"]:
        assert d_mm[0] == pytest.approx(cal.min_range_m * 1e3)
        assert d_mm[-1] == pytest.approx(cal.max_range_m * 1e3)
        np.testing.assert_allclose(n, cal.counts(d_mm / 1e3, math.radians(t)), rtol=1e-12)
    # the errors: what the calibration reads from each reading minus the wall's distance;
    # the scene's 15 mV noise, not a bias
    theta = np.abs(r.beam_angle_rad[used])
    np.testing.assert_allclose(c["error_mm"],
                               cal.distance(r.counts[used], theta) * 1e3 - true_mm, atol=1e-9)
    assert abs(np.median(c["error_mm"])) < 1.0 and 1.0 < np.sqrt(np.mean(c["error_mm"] ** 2)) < 10
    # the fold-over peak: the GP2D12's, at its peak output in this ADC's counts
    model = gp2.sensor("gp2d12")
    lsb = gp2.lsb_v(t_room.sensor.adc_bits, t_room.sensor.vref_v)
    assert c["peak"] == pytest.approx((model.peak_distance_m * 1e3, model.peak_v(0.0) / lsb))
    assert c["volts_per_count"] == lsb


def test_picture_named_beside_the_calibration_file(tmp_path):
    from irring.cli.calibrate import picture_path

    assert picture_path(tmp_path / "ring.yaml") == tmp_path / "ring.png"
    assert picture_path(tmp_path / "ring") == tmp_path / "ring.png"
    assert picture_path(tmp_path / "cal.PNG") == tmp_path / "cal.PNG.png"   # never itself


def test_guided_calibration_keeps_what_it_fitted(t_room):
    rig = SimulatedRig(t_room, seed=3)
    guided = _guided(rig, FakeUser(rig), sweeps=1)
    assert guided.fitted is None
    cal = guided.run()
    assert guided.fitted.calibration is cal
    assert guided.fitted.readings.counts.size == guided.fitted.used.size > 0
    again = solve(guided.fitted.readings, sensor_model="gp2d12",
                  emitter_offset_guess_m=guided.emitter_offset_guess_m)
    assert {**again.to_dict(), "source": ""} == {**cal.to_dict(), "source": ""}


def test_the_picture_never_replaces_the_scenario_it_reads(tmp_path, capsys):
    from irring.cli import main
    from irring.scenario import resolve

    scene = tmp_path / "room.png"   # a scenario under a picture's name
    scene.write_text(resolve("t_room").read_text())
    assert main(["calibrate", "--scenario", str(scene), "--out", str(tmp_path / "room.yaml")]) == 2
    assert (f"its picture {scene}: is the file --scenario {scene}, which this command reads"
            in capsys.readouterr().err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["room.png"]
