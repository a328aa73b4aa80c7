"""Belt and stepper physics, GP2 timing and a moving robot (irring/simulation/dynamics.py).

Documented figures (models/README.md, irring/simulation/dynamics.py), measured by
``irring bench dynamics`` and held here:

- belt stretch (sensor − 0.6 × motor) ≤ STRETCH_BOUND_RAD = 0.007 rad at every physics step
  over back-and-forth sweeps without rest (measured 0.0064; steady from the second sweep),
  no MuJoCo warnings, no NaN;
- halving the 0.5 ms time step moves a true sensor angle by < ANGLE_TOL_RAD = 1e-4 rad and a
  true distance by < DIST_TOL_M = 0.1 mm (measured 1e-5 rad, 5 µm) and no ADC count;
- belt + timing, settle 0: angle error rms 0.13 rad (readings ~6 steps stale); settle 52.9 ms
  (slowest GP2 period + latency): 2.6e-4 rad; 75 ms: 1e-7 rad.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import mujoco
import mujoco.batch
import mujoco.rollout
import numpy as np
import pytest

from irring.simulation import dynamics as D
from irring import pipeline
from irring.studies import dynamics as bench
from irring.core import Sweep, beam_geometry
from irring.estimation.estimate import estimate
from irring.core import Ring
from irring.scenario import BeltDynamicsEffect, ScenarioError, TimingEffect, load_scenario, loads
from irring.simulation.sim import SimRing

STRETCH_BOUND_RAD = 0.007
ANGLE_TOL_RAD = 1e-4
DIST_TOL_M = 1e-4
P_SLOW_S = 0.0383 + 0.0096 + 0.005  # slowest GP2 period + output latency


def timed(settle_s: float, effects=None):
    return bench.variant("t_room", effects=effects or {"belt_dynamics": {}, "timing": {}},
                         scan={"settle_s": settle_s})


# --------------------------------------------------------------------------- off means off


def test_a_scene_without_these_effects_never_steps_physics(monkeypatch, t_room):
    def forbidden(*args, **kwargs):
        raise AssertionError("a static scene stepped physics")

    for owner, name in ((mujoco, "mj_step"), (mujoco, "mj_step1"), (mujoco, "mj_step2"),
                        (mujoco.batch.Batch, "step"), (mujoco.batch.Batch, "rollout"),
                        (mujoco.rollout, "rollout"), (D, "BeltPhysics"), (D, "Dynamics")):
        monkeypatch.setattr(owner, name, forbidden)
    sim = SimRing(t_room)
    assert sim.dynamics is None and sim.n_sweeps == 4
    sweep = sim.sweep(0)
    assert sweep.reading_poses is None
    assert pipeline.run(t_room, progress=False).scores["occupied_f1"] > 0.9


def test_only_listed_effects_change_anything(t_room):
    """Belt alone keeps the pose; timing alone steps no physics and stays kinematic."""
    sim = SimRing(timed(0.0, {"timing": {}}))
    assert sim.dynamics._physics is None
    sim.sweep(0)
    assert sim.dynamics._physics is None  # a rigid belt needs no physics
    sweep = SimRing(timed(0.02, {"belt_dynamics": {}})).sweep(0)
    assert sweep.reading_poses is None and np.array_equal(sweep.pose, SimRing(t_room).pose(0))


# --------------------------------------------------------------------------- the timeline


def test_schedule_charges_moves_settle_and_periods():
    ring = Ring()
    steps = np.arange(-35, 36, 2)
    untimed = D.schedule(steps, ring, settle_s=0.01, samples=2)
    # untimed sensor: each reading costs a GP2 period, as for kinematic sweeps, plus moves
    per = 2 * 0.004 + 0.01 + 2 * 0.0383
    np.testing.assert_allclose(np.diff(untimed.done_s), per)
    assert untimed.done_s[0] == pytest.approx(0.01 + 2 * 0.0383)
    np.testing.assert_allclose(untimed.read_s[:, 1] - untimed.read_s[:, 0], 0.0383)
    timed_ = D.schedule(steps, ring, settle_s=0.01, samples=2, timing=True)
    # timed sensor: only the waits the firmware makes (move, settle, between two samples)
    np.testing.assert_allclose(np.diff(timed_.done_s), 2 * 0.004 + 0.01 + 0.0383)
    assert timed_.duration_s < untimed.duration_s


def test_moves_follow_a_minimum_jerk_profile():
    sched = D.schedule(np.array([0, 1, 3]), Ring(), settle_s=0.005, step_time_s=0.004)
    step = Ring().motor_step_rad
    t = np.linspace(sched.command_s[1], sched.command_s[1] + 0.004, 4001)
    motor = sched.motor_at(t)
    assert motor[0] == pytest.approx(0.0, abs=1e-15) and motor[-1] == pytest.approx(step)
    speed = np.gradient(motor, t)
    assert np.all(speed >= -1e-9)
    assert speed.max() == pytest.approx(1.875 * step / 0.004, rel=1e-3)
    # two steps take twice as long at the same peak speed
    t2 = np.linspace(sched.command_s[2], sched.command_s[2] + 0.008, 8001)
    assert sched.move_s[2] == pytest.approx(0.008)
    assert np.gradient(sched.motor_at(t2), t2).max() == pytest.approx(1.875 * step / 0.004,
                                                                      rel=1e-3)
    # at rest between moves
    assert sched.motor_at(sched.read_s[1, 0]) == pytest.approx(step)


def test_belt_physics_runs_once_per_step_list_and_changes_no_reading(monkeypatch):
    """Every sweep over the same steps starts at rest, so its physics is run once and reused;
    the sweeps read exactly what a fresh physics run gives."""
    sc = timed(0.0, {"belt_dynamics": {"backlash_deg": 1.0}, "timing": {}})
    steps = np.arange(-3, 4)
    runs = []
    run = D.BeltPhysics.run
    monkeypatch.setattr(D.BeltPhysics, "run", lambda self, *a, **k: runs.append(1) or run(
        self, *a, **k))
    cached, fresh = SimRing(sc), SimRing(sc)
    for pose in (0, 1, 0):
        a = cached.sweep(pose, steps=steps)
        fresh.dynamics._timelines.clear()
        b = fresh.sweep(pose, steps=steps)
        assert np.array_equal(a.counts, b.counts, equal_nan=True)
        assert np.array_equal(a.truth.direction, b.truth.direction)
    cached.sweep(0)  # other steps: their own physics
    assert len(runs) == 1 + 3 + 1


# --------------------------------------------------------------------------- belt physics


def test_belt_stretch_is_bounded_and_steady_from_the_second_sweep():
    """Back-and-forth sweeps in one run, never resting (each 1.8° step in 4 ms, read on
    arrival): the hardest duty for the belt; slower sweeps only add rest in which the stretch
    decays (next test). The first sweep starts from rest; from the second on every sweep
    starts in the same state, so the second and third stretch alike and so would the 1000th."""
    r = bench.coupling(3)
    stretch = r["stretch_per_sweep_rad"]
    assert r["warnings"] == 0 and np.all(np.isfinite(stretch)) and stretch.shape == (3,)
    assert stretch.max() < STRETCH_BOUND_RAD, stretch.max()
    assert stretch.max() > 0.001  # the belt does stretch: a real compliance, not rigid
    np.testing.assert_allclose(stretch[2], stretch[1], rtol=1e-6)
    assert r["read_error_max_rad"] < 0.02  # the sensors lag a 4-ms step by < 1.2°


def test_belt_physics_follows_one_run_through_chunks_of_targets():
    """BeltPhysics.follow, the public way to run the belt on (studies.dynamics.endurance
    uses it): chunks continue one run, so two chunks are the same physics as their
    concatenation, each chunk's first sample the last of the one before; run() is follow's
    single chunk from rest at the sweep's first step."""
    ring = load_scenario("t_room").ring
    physics = D.BeltPhysics(ring, BeltDynamicsEffect())
    sched = D.schedule(np.arange(ring.min_step, ring.max_step + 1), ring,
                       step_time_s=physics.params.step_time_s, timing=True)
    ctrl = physics.controls(sched)
    cut = 37                                            # not a step boundary
    stretch = np.linspace(-0.002, 0.001, ring.sensors)  # asymmetric start
    a, b = physics.follow([ctrl[:cut], ctrl[cut:]], sched.motor_rad[0], stretch)
    (whole,) = physics.follow([ctrl], sched.motor_rad[0], stretch)
    assert len(a.sensor_rad) == cut + 1 and len(b.sensor_rad) == len(ctrl) - cut + 1
    assert np.array_equal(a.sensor_rad[-1], b.sensor_rad[0])
    np.testing.assert_allclose(np.concatenate([a.sensor_rad, b.sensor_rad[1:]]),
                               whole.sensor_rad, rtol=0, atol=1e-12)
    np.testing.assert_allclose(whole.stretch_rad[0], stretch, rtol=0, atol=1e-15)
    assert not np.allclose(whole.stretch_rad[-1], stretch)      # the belt moved
    run = physics.run(sched)
    (rest,) = physics.follow([ctrl], sched.motor_rad[0], physics.rest_offset(sched.steps))
    assert np.array_equal(run.sensor_rad, rest.sensor_rad)


def test_belt_lag_decays_with_settle_time():
    rows = bench.settling({"belt_dynamics": {}}, (0.0, 0.020, 0.1))
    assert 0.005 < rows[0]["angle_error_rms_rad"] < 0.02     # read on arrival: ~0.7° behind
    assert rows[1]["angle_error_max_rad"] < 1e-4              # 20 ms later
    assert rows[2]["angle_error_max_rad"] < 1e-9
    assert rows[0]["hardware_s"] < rows[1]["hardware_s"] < rows[2]["hardware_s"]


@pytest.mark.parametrize("settle_s", [0.0, 0.010])
def test_halving_the_timestep_changes_readings_by_less_than_the_tolerance(settle_s):
    """Belt and timing on, so measurements fall mid-move too; same seed, dt 0.5 vs 0.25 ms."""
    r = bench.convergence(timed(settle_s))
    assert r["angle_rad"] < ANGLE_TOL_RAD, r
    assert r["distance_m"] < DIST_TOL_M and r["hit_changed"] == 0, r
    assert r["counts"] == 0, r
    assert r["angle_error_rms_rad"] > 100 * ANGLE_TOL_RAD  # the effect itself is far larger


def test_backlash_leaves_an_error_that_settling_cannot_remove():
    half = math.radians(1.0) / 2
    slack = bench.settling({"belt_dynamics": {"backlash_deg": 1.0}}, (0.1,))[0]
    tight = bench.settling({"belt_dynamics": {}}, (0.1,))[0]
    assert tight["angle_error_max_rad"] < 1e-9
    assert half / 4 < slack["angle_error_max_rad"] <= half + 1e-4


def test_unstable_physics_says_what_to_change(monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)  # MuJoCo writes MUJOCO_LOG.TXT on a warning
    with pytest.raises(ScenarioError, match=r"effects\.belt_dynamics\.timestep_ms: 10 ms is more "
                                            r"than 2\.5 × belt_timeconst_ms \(2 ms\)"):
        bench.variant("t_room", effects={"belt_dynamics": {"timestep_ms": 10}})
    # built in code past the loader's rule, the rollout's error still names the keys
    sc = bench.variant("t_room", effects={"belt_dynamics": {"timestep_ms": 4}})
    belt = dataclasses.replace(sc.effects["belt_dynamics"], timestep_s=0.010)
    sim = SimRing(dataclasses.replace(sc, effects={**sc.effects, "belt_dynamics": belt}))
    with pytest.raises(ScenarioError, match=r"effects\.belt_dynamics: belt physics went unstable"
                                            r".*timestep_ms .*10 ms.*belt_timeconst_ms"):
        sim.sweep(0)


# --------------------------------------------------------------------------- time step check

def box_file(tmp_path, dt, tau, more=""):
    path = tmp_path / "box.yaml"
    # the timestep table's room (studies.dynamics), 4 ms steps, no backlash
    path.write_text(bench.BOX_ROOM.format(dt=dt, tau=tau, step=4, backlash=0) + more)
    return path


def test_an_unconverged_belt_time_step_is_refused_by_irring_run(tmp_path, capsys):
    """τ = 0.25 ms at 0.5 ms passes the loader's RK4 rule (2 τ ≤ 2.5 τ) and MuJoCo never
    warns, but the map fell apart (F1 0.37): halving the step moves the sensors by ~900°."""
    from irring import errors
    from irring.cli import main
    D.forget_timestep_checks()
    out = tmp_path / "out"
    code = main(["run", str(box_file(tmp_path, 0.5, 0.25)), "--no-animation", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == errors.INPUT == 1
    assert (f"{tmp_path / 'box.yaml'}: effects.belt_dynamics.timestep_ms: 0.5 ms is not "
            "converged: halving it moves a sensor's true angle at a reading by ") in err
    degrees = float(err.split("at a reading by ")[1].split("°")[0])
    assert 100 < degrees < 2000, err
    assert "more than the 0.1° allowed; timestep_ms: 0.25 passes" in err
    assert "internal error" not in err and not (out / "map.png").exists()


def test_a_converged_time_step_runs_and_its_change_is_below_the_tolerance(tmp_path):
    """τ = 0.5 ms at 0.45 ms (0.9 τ) is converged (measured 0.003°); the default 0.5 ms at
    τ = 2 ms by three orders of magnitude."""
    D.forget_timestep_checks()
    sc = load_scenario(box_file(tmp_path, 0.45, 0.5))
    result = pipeline.run(sc, progress=False)
    assert result.scores["occupied_f1"] > 0.95
    sim = SimRing(sc)
    sched = sim.dynamics.schedule(sim.default_steps())
    change, advice = D.check_timestep(sim.dynamics.physics, sched)
    assert 1e-3 * D.CONVERGED_ANGLE_RAD < change < D.CONVERGED_ANGLE_RAD and advice == ""
    default = SimRing(bench.variant("t_room", effects={"belt_dynamics": {}}))
    sched = default.dynamics.schedule(default.default_steps())
    assert D.timestep_change(default.dynamics.physics, sched) < 1e-3 * D.CONVERGED_ANGLE_RAD


def test_a_step_whose_doubling_already_passes_is_not_rolled_at_half(monkeypatch, tmp_path,
                                                                    capfd):
    """The default 0.5 ms: the sweep at 1 ms moves the angles 0.012°, within 0.1°, so it
    passes on a quarter of the work. 0.45 ms at τ = 0.5 ms: 0.9 ms is past RK4's limit
    (0.58 ms), so the sweep at half the step decides. 0.5 ms at τ = 0.25 ms: 1 ms blows up,
    without a word (no MuJoCo warning printed or logged)."""
    monkeypatch.chdir(tmp_path)
    D.forget_timestep_checks()
    default = SimRing(bench.variant("t_room", effects={"belt_dynamics": {}}))
    sched = default.dynamics.schedule(default.default_steps())
    halving = D.timestep_change
    monkeypatch.setattr(D, "timestep_change", lambda *a, **k: pytest.fail("rolled at dt/2"))
    change, advice = D.check_timestep(default.dynamics.physics, sched)
    assert math.radians(0.005) < change < math.radians(0.05) and advice == ""
    monkeypatch.setattr(D, "timestep_change", halving)
    sc = load_scenario(box_file(tmp_path, 0.45, 0.5))
    sim = SimRing(sc)
    sched = sim.dynamics.schedule(sim.default_steps())
    assert D._doubling_change(sim.dynamics.physics, sched, None, None) > 1.0
    change, advice = D.check_timestep(sim.dynamics.physics, sched)
    assert change == D.timestep_change(sim.dynamics.physics, sched) and advice == ""
    sim.sweep(0)
    unstable = SimRing(load_scenario(box_file(tmp_path, 0.5, 0.25)))
    sched = unstable.dynamics.schedule(unstable.default_steps())
    heard = []
    mine = heard.append
    mujoco.set_mju_user_warning(mine)
    try:
        assert D._doubling_change(unstable.dynamics.physics, sched, None, None) is None
        assert mujoco.get_mju_user_warning() is mine and heard == []   # put back, unused
    finally:
        mujoco.set_mju_user_warning(None)
    assert D._doubling_change(unstable.dynamics.physics, sched, None, None) is None
    assert mujoco.get_mju_user_warning() is None
    out, err = capfd.readouterr()
    assert "WARNING" not in out + err and not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_the_time_step_is_checked_once_per_schedule_and_scene(monkeypatch, tmp_path):
    """The check rolls the sweep out again at dt/2: once per ring, belt and schedule in a
    process, so further sweeps, SimRings and seeds of the same scene reuse its verdict."""
    D.forget_timestep_checks()
    calls = []
    change = D._doubling_change   # the check's first roll-out, whatever follows
    monkeypatch.setattr(D, "_doubling_change",
                        lambda *a, **k: calls.append(a[1].steps.copy()) or change(*a, **k))
    sc = bench.variant("t_room", effects={"belt_dynamics": {"belt_timeconst_ms": 1.3}},
                       scan={"settle_s": 0.003})
    sim = SimRing(sc)
    for pose in (0, 1, 2, 0):
        sim.sweep(pose)
    assert len(calls) == 1
    SimRing(sc, seed=5).sweep(3)
    sim.reset(seed=7)
    sim.sweep(1)
    assert len(calls) == 1
    sim.sweep(0, steps=np.arange(-3, 12))       # another schedule: its own check
    sim.sweep(2, steps=np.arange(-3, 12))
    assert len(calls) == 2 and np.array_equal(calls[1], np.arange(-3, 12))
    slower = bench.variant("t_room", effects={"belt_dynamics": {"belt_timeconst_ms": 1.7}},
                           scan={"settle_s": 0.003})
    SimRing(slower).sweep(0)                     # another belt: its own check
    assert len(calls) == 3


def test_a_refusal_is_remembered_with_its_advice(monkeypatch, tmp_path):
    D.forget_timestep_checks()
    sc = load_scenario(box_file(tmp_path, 1.5, 2))
    with pytest.raises(ScenarioError, match=r"1\.5 ms is not converged: .* by 0\.2\d+°.*; "
                                            r"timestep_ms: 0\.75 passes") as first:
        SimRing(sc).sweep(0)
    monkeypatch.setattr(D, "timestep_change", lambda *a, **k: pytest.fail("checked again"))
    with pytest.raises(ScenarioError) as again:
        SimRing(sc, seed=9).sweep(0)
    assert str(again.value) == str(first.value)


def test_a_long_sweep_is_refused_with_an_estimate_instead_of_a_checked_step(monkeypatch,
                                                                            tmp_path):
    """Checking dt/2 would roll 6× the sweep's physics steps; past ADVICE_MAX_STEPS the
    advice is RK4's fourth-order estimate, half of dt·(0.1° / change)^¼, and says it is one."""
    D.forget_timestep_checks()
    sim = SimRing(load_scenario(box_file(tmp_path, 0.5, 0.25)))
    steps = len(sim.dynamics.physics.controls(sim.dynamics.schedule(sim.default_steps())))
    assert steps == 6000
    monkeypatch.setattr(D, "ADVICE_MAX_STEPS", 6 * steps - 1)
    with pytest.raises(ScenarioError) as refused:
        sim.sweep(0)
    message = str(refused.value)
    change = float(message.split("at a reading by ")[1].split("°")[0])
    guess = 0.5 * (0.1 / change) ** 0.25 / 2
    assert message.endswith(f"lower timestep_ms, to about {guess:.2g} ms (estimated, not checked)")
    assert 0.01 < guess < 0.05


def test_timed_reads_are_checked_wherever_a_measurement_may_fall():
    """With timing a read returns a measurement from latency + up to the longest period
    before it; the check compares every physics step in those windows (and nothing else),
    for every sensor."""
    ring = Ring()
    timing = TimingEffect(period_s=0.0173, jitter_s=0.0041, latency_s=0.0029)
    sched = D.schedule(np.array([4, 5, 7, 6]), ring, settle_s=0.031, step_time_s=0.0037,
                       timing=True, period_s=timing.period_s)
    dt = 0.0005
    t, k = D.check_instants(sched, 12, dt, timing)
    grid = np.arange(int(sched.duration_s / dt) + 1) * dt
    ends = sched.read_s[:, 0] - timing.latency_s
    inside = [g for g in grid
              if any(0 <= e - g <= timing.period_s + timing.jitter_s for e in ends)]
    np.testing.assert_array_equal(t[::12], inside)
    assert len(t) == 12 * len(inside) and 0 < len(inside) < len(grid)
    np.testing.assert_array_equal(k[:24], np.tile(np.arange(12), 2))
    t, k = D.check_instants(sched, 12, dt, None)   # untimed: each step's first read
    np.testing.assert_array_equal(t, np.repeat(sched.read_s[:, 0], 12))


def test_a_timed_sweep_is_checked_where_it_measures_not_only_at_its_reads(tmp_path):
    """Settle 20 ms with timing, 1.3 ms at τ = 2 ms: at the reads the belt has settled and
    halving the step moves it by 0.01°, but a GP2 may have measured up to 48 ms earlier,
    during the move, where it moves by 0.23°: refused."""
    D.forget_timestep_checks()
    sc = load_scenario(box_file(tmp_path, 1.3, 2, "  timing: {}\nscan: {settle_ms: 20}\n"))
    sim = SimRing(sc)
    sched = sim.dynamics.schedule(sim.default_steps())
    at_reads = D.timestep_change(sim.dynamics.physics, sched, None)
    measured = D.timestep_change(sim.dynamics.physics, sched, sim.dynamics.timing)
    assert at_reads < D.CONVERGED_ANGLE_RAD / 5 and measured > 2 * D.CONVERGED_ANGLE_RAD
    with pytest.raises(ScenarioError, match=r"effects\.belt_dynamics\.timestep_ms: 1\.3 ms is "
                                            r"not converged: .* by 0\.2\d+°"):
        sim.sweep(0)


def test_the_timestep_table_shows_what_an_unconverged_step_costs_the_map():
    """docs/dynamics.md's table (irring bench dynamics --timesteps), two of its rows: the
    default step passes and maps the box perfectly; 2 ms at τ = 2 ms is refused, and the map
    made there anyway loses walls."""
    fine, coarse = bench.timestep_table(((2.0, 4.0, 0.0, (0.5, 2.0)),))
    assert fine["passes"] and fine["angle_change_rad"] < 1e-5
    assert fine["occupied_f1"] == pytest.approx(1.0)
    assert not coarse["passes"] and math.radians(2) < coarse["angle_change_rad"] < math.radians(5)
    assert 0.7 < coarse["occupied_f1"] < 0.95


def test_streamed_angles_equal_the_stored_run_across_chunks(monkeypatch):
    """angles_at keeps only the chunk it reads: the same angles as the whole run's."""
    sc = bench.variant("t_room", effects={"belt_dynamics": {"timestep_ms": 0.4,
                                                            "backlash_deg": 0.3}})
    physics = D.BeltPhysics(sc.ring, sc.effects["belt_dynamics"])
    sched = D.schedule(np.arange(-35, 36), sc.ring)
    whole = physics.run(sched)
    rng = np.random.default_rng(4)
    t = np.concatenate([rng.uniform(0, sched.duration_s, 500), [0.0, sched.duration_s,
                                                                 997 * 0.0004]])
    k = rng.integers(0, 12, len(t))
    monkeypatch.setattr(D, "ROLLOUT_CHUNK_STEPS", 997)
    streamed = D.angles_at(physics, sched, t, k)
    np.testing.assert_allclose(streamed, whole.sensors_at(np.tile(t[:, None], 12))[
        np.arange(len(t)), k], rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- GP2 timing


def test_a_read_returns_the_last_measurement_whose_output_is_valid():
    periods = D.SensorClocks.periods(TimingEffect(), 12, seed=4)
    assert np.all((periods >= 0.0383 - 0.0096) & (periods <= 0.0383 + 0.0096))
    assert np.array_equal(periods, D.SensorClocks.periods(TimingEffect(), 12, seed=4))
    clocks = D.SensorClocks.draw(TimingEffect(), periods, np.random.default_rng(0))
    reads = np.linspace(0.0, 1.0, 2001)[:, None] + np.zeros(12)
    m = clocks.measured_at(reads)
    # on the sensor's clock, output valid by the read, and the next one not yet valid
    n = (m - clocks.phase_s) / clocks.period_s
    np.testing.assert_allclose(n, np.round(n), atol=1e-9)
    assert np.all(m + clocks.latency_s <= reads + 1e-12)
    assert np.all(m + clocks.period_s + clocks.latency_s > reads)


def test_fast_sweep_smears_and_settling_one_sensor_period_removes_it():
    rows = {r["settle_s"]: r for r in bench.settling({"belt_dynamics": {}, "timing": {}},
                                                     (0.0, P_SLOW_S, 0.075))}
    fast, settled, rested = rows[0.0], rows[P_SLOW_S], rows[0.075]
    print(f"\nbelt + timing: settle 0: {fast['angle_error_rms_rad']:.3e} rad rms in "
          f"{fast['hardware_s']:.2f} s; settle {P_SLOW_S * 1e3:.1f} ms: "
          f"{settled['angle_error_rms_rad']:.3e} rad rms in {settled['hardware_s']:.2f} s; "
          f"75 ms: {rested['angle_error_rms_rad']:.3e} rad")
    step = Ring().motor_step_rad * Ring().gear
    assert fast["angle_error_rms_rad"] > 3 * step            # readings several steps stale
    assert settled["angle_error_rms_rad"] < 0.03 * fast["angle_error_rms_rad"]
    assert settled["angle_error_max_rad"] < step / 5          # belt still ringing a little
    assert rested["angle_error_max_rad"] < 1e-5
    assert fast["hardware_s"] < settled["hardware_s"] / 10    # what the accuracy costs


def test_mujoco_periodic_delayed_rangefinders_agree_with_the_clock_model():
    r = bench.mujoco_clocks(timed(0.0))
    assert r["warnings"] == 0 and r["readings"] > 500
    assert r["agree_quantized"] == 1.0, r            # same rule on MuJoCo's step grid
    assert r["max_diff_m"] < 0.003, r                # ≤ one 0.5 ms step of motion otherwise
    assert r["stale_m"] > 0.005                      # and timing matters at all


def test_timing_is_reproducible_and_fresh_per_sweep():
    sc = timed(0.0, {"timing": {}, "noise": {}})
    a, b = SimRing(sc, seed=5), SimRing(sc, seed=5)
    s1, s2 = a.sweep(0), a.sweep(0)
    assert np.array_equal(s1.counts, b.sweep(0).counts)
    assert not np.array_equal(s1.truth.direction, s2.truth.direction)  # new clock phases


# --------------------------------------------------------------------------- motion


def test_frames_take_a_pose_per_reading(t_room):
    sim = SimRing(t_room)
    steps = sim.default_steps()
    angles = sim.built.sensor_qpos_for(steps * sim.ring.motor_step_rad)
    rng = np.random.default_rng(1)
    n = len(steps)
    per_step = np.column_stack([rng.uniform(0.5, 1.9, n), rng.uniform(0.3, 0.6, n),
                                rng.uniform(-3, 3, n)])
    o1, d1 = sim.frames(angles, per_step)
    o2, d2 = sim.frames(angles, np.repeat(per_step[:, None], sim.ring.sensors, axis=1))
    np.testing.assert_allclose(o2, o1, atol=1e-12)
    np.testing.assert_allclose(d2, d1, atol=1e-12)


def _perfect_moving(drop=()):
    return bench.variant("t_room_moving", drop=drop,
                         motion={"odometry_sigma_mm": 0, "odometry_sigma_deg": 0})


def test_every_reading_carries_its_pose_and_the_estimator_uses_it():
    sim = SimRing(_perfect_moving(drop=("belt_dynamics", "timing")))
    n = sim.n_sweeps
    assert n > 4
    sweep = sim.sweep(n // 2)
    poses = sweep.reading_poses
    assert poses.shape == sweep.counts.shape + (3,)
    assert np.ptp(poses[:, 0, 0]) + np.ptp(poses[:, 0, 1]) > 0.05  # it moved during the sweep
    origin, _ = beam_geometry(sweep.ring, poses, sweep.sensor_angles, sweep.ring.emitter_offset_m)
    np.testing.assert_allclose(origin, sweep.truth.origin[..., :2], atol=1e-9)
    pts = estimate(sweep)
    np.testing.assert_allclose(pts.origin_x, sweep.truth.origin[..., 0], atol=1e-9)
    # the same counts read as if standing at the sweep's pose would put points elsewhere
    frozen = estimate(Sweep(**{**sweep.__dict__, "reading_poses": None}))
    ok = pts.valid & frozen.valid
    assert np.nanmax(np.hypot(pts.x - frozen.x, pts.y - frozen.y)[ok]) > 0.05
    with pytest.raises(IndexError, match="drives its path in"):
        sim.sweep(n)


def test_perfect_odometry_maps_as_well_as_static_scans():
    """Same sweep positions, standing vs driving through them: occupied F1 no worse than 0.02.
    (Against t_room's four scans the moving run has more sweeps, and the mapper's precision
    falls with the number of sweeps whether the robot moves or not: irring bench dynamics.)"""
    moving_sc = _perfect_moving()
    moving = pipeline.run(moving_sc, progress=False)
    sim = SimRing(moving_sc)
    steps = sim.default_steps()
    mid = [sim.dynamics.plan(k, steps).pose[len(steps) // 2, 0] for k in range(sim.n_sweeps)]
    static = pipeline.run(bench.variant(
        "t_room_moving", drop=D.DYNAMIC_EFFECTS,
        poses=[{"x_m": float(p[0]), "y_m": float(p[1]), "yaw_rad": float(p[2])} for p in mid]),
        progress=False)
    f1_m, f1_s = moving.scores["occupied_f1"], static.scores["occupied_f1"]
    print(f"\noccupied F1: moving {f1_m:.3f}, static at the same places {f1_s:.3f}")
    assert len(moving.sweeps) == len(static.sweeps)
    # as well: not worse by more than 0.02 (it maps better: 0.960 against 0.934 today)
    assert f1_m >= f1_s - 0.02
    assert moving.scores["free_accuracy"] >= 0.95


@functools.cache
def _odometry_run(mm: float, deg: float):
    """t_room_moving without its belt at odometry sigma (mm, deg), run once per process: the
    tests only read it (the 1000 mm, 57 deg run is both the worst of the noise ladder and the
    run that drifts off its grid)."""
    sc = bench.variant("t_room_moving", drop=("belt_dynamics",),
                       motion={"odometry_sigma_mm": mm, "odometry_sigma_deg": deg})
    return pipeline.run(sc, progress=False)


def test_odometry_noise_degrades_the_map_gracefully():
    f1 = []
    for mm, deg in ((0, 0), (5, 0.5), (100, 10), (1000, 57)):
        run = _odometry_run(mm, deg)
        assert all(np.all(np.isfinite(s.reading_poses)) for s in run.sweeps)
        f1.append(run.scores["occupied_f1"])
    assert f1[0] - 0.15 < f1[1] <= f1[0] + 0.01   # good odometry: a modest loss
    assert f1[2] < f1[1] and f1[3] < f1[1]        # bad odometry: a bad map, still a map


def test_a_run_whose_odometry_drifts_off_its_grid_replays_to_the_same_map(tmp_path):
    """odometry_sigma 1 m a metre (allowed) carries sweep 3's believed pose to (2.69, 1.57) m,
    off the T-room's grid: the run mapped what landed on it, but irring replay refused its
    sweeps.npz ('meta.grid: sweep 3's pose … lies outside the recorded grid')."""
    from irring.cli import main
    run = _odometry_run(1000, 57)
    lo, res = run.grid.origin_xy_m, run.grid.resolution_m
    hi = lo + res * np.array(run.grid.shape[::-1])
    off = [k for k, s in enumerate(run.sweeps)
           if not np.all((lo <= s.pose[:2]) & (s.pose[:2] <= hi))]
    assert off == [2, 4, 6, 8] and len(run.sweeps) == 11
    pipeline.write_outputs(run, tmp_path / "run")
    assert main(["replay", str(tmp_path / "run" / "sweeps.npz"), "--out", str(tmp_path / "rep"),
                 "--no-animation"]) == 0
    assert ((tmp_path / "rep" / "map.pgm").read_bytes()
            == (tmp_path / "run" / "map.pgm").read_bytes())


def test_odometry_drift_has_the_stated_sigma_per_metre():
    path = D.Path(xy_m=np.array([[0.0, 0.0], [1.0, 0.0]]), yaw_rad=np.zeros(2),
                  arc_m=np.array([0.0, 1.0]), speed_m_s=0.1)
    ends = np.array([D.Odometry.along(path, 0.02, 0.0, np.random.default_rng(s)).pose[-1]
                     for s in range(400)])
    assert np.std(ends[:, 0]) == pytest.approx(0.02, rel=0.15)
    assert np.std(ends[:, 1]) == pytest.approx(0.02, rel=0.15)
    turned = np.array([D.Odometry.along(path, 0.0, 0.05, np.random.default_rng(s)).pose[-1]
                       for s in range(400)])
    assert np.std(turned[:, 2]) == pytest.approx(0.05, rel=0.15)
    exact = D.Odometry.along(path, 0.0, 0.0, np.random.default_rng(0))
    np.testing.assert_allclose(exact.pose_at(np.array([0.0, 5.0, 99.0])),
                               [[0, 0, 0], [0.5, 0, 0], [1, 0, 0]], atol=1e-12)


def test_exact_odometry_turns_in_place_where_the_true_pose_does():
    """A turn in place takes no time: the true pose jumps at its waypoint. Odometry sampled
    every 5 mm ramped the 69° turn over the last sample gap before it, so readings there
    were drawn up to 69° off with exact odometry (an ideal run mapped worse than a noisy one)."""
    path = D.Path(xy_m=np.array([[0.2, 0.1], [1.3, 0.4], [1.3, 0.4], [1.9, -0.35]]),
                  yaw_rad=np.array([0.3, 0.3, -0.9, -0.9]),
                  arc_m=np.concatenate([[0.0], np.cumsum([np.hypot(1.1, 0.3), 0.0,
                                                          np.hypot(0.6, 0.75)])]),
                  speed_m_s=0.06)
    t_turn = path.arc_m[1] / path.speed_m_s
    t = np.concatenate([np.linspace(0.0, path.duration_s, 2001),
                        t_turn + np.array([-0.2, -0.05, -1e-6, 0.0, 1e-6, 0.05])])
    exact = D.Odometry.along(path, 0.0, 0.0, np.random.default_rng(0))
    np.testing.assert_allclose(exact.pose_at(t), path.pose_at(t), atol=1e-9)
    before, after = exact.pose_at(np.array([t_turn - 1e-6, t_turn]))
    assert before[2] == pytest.approx(0.3) and after[2] == pytest.approx(-0.9)
    # with noise the turn is still a jump: the yaw 1 µs before it is the pre-turn heading
    noisy = D.Odometry.along(path, 0.01, 0.01, np.random.default_rng(3))
    yaw = noisy.pose_at(np.array([t_turn - 1e-6, t_turn]))[:, 2]
    assert yaw[0] - yaw[1] == pytest.approx(1.2, abs=0.02)


def test_a_path_through_a_wall_is_an_error_naming_the_segment(t_room_raw):
    from irring.scenario import parse

    t_room_raw["effects"]["motion"] = {"path": [{"x_mm": 1920, "y_mm": 450},
                                                {"x_mm": 500, "y_mm": 450},
                                                {"x_mm": 1210, "y_mm": 1350}]}
    with pytest.raises(ScenarioError, match=r"motion\.path\[1\] → \[2\].*hit a wall"):
        SimRing(parse(t_room_raw, "bad.yaml"))


def test_bundled_moving_scenario_maps_and_replays_exactly(tmp_path):
    sc = load_scenario("t_room_moving")
    assert {"belt_dynamics", "timing", "motion"} <= set(sc.effects)
    assert isinstance(sc.effects["belt_dynamics"], BeltDynamicsEffect)
    run = pipeline.run(sc, progress=False)
    assert run.scores["occupied_f1"] > 0.7 and run.scores["free_accuracy"] > 0.95
    assert run.hardware_time_s == pytest.approx(sum(s.duration_s for s in run.sweeps))
    # the recording keeps each reading's pose, so replay rebuilds the very same map
    paths = pipeline.write_outputs(run, tmp_path, animation=False)
    again = pipeline.replay(paths["recording"], progress=False)
    assert np.array_equal(again.grid.log_odds, run.grid.log_odds)


def test_a_belt_rollout_in_chunks_equals_one_rollout(monkeypatch):
    """The belt is rolled out ROLLOUT_CHUNK_STEPS at a time so Ctrl-C lands between MuJoCo
    calls; the chunks continue one run exactly."""
    sc = bench.variant("t_room", effects={"belt_dynamics": {"timestep_ms": 0.4,
                                                            "backlash_deg": 0.3}})
    dyn = D.Dynamics(sc, SimRing(sc).built, 0)
    sched = dyn.schedule(np.arange(-35, 36))
    monkeypatch.setattr(D, "ROLLOUT_CHUNK_STEPS", 10**9)
    whole = dyn.physics.run(sched)
    assert len(whole.motor_rad) > 3 * 997
    monkeypatch.setattr(D, "ROLLOUT_CHUNK_STEPS", 997)
    chunked = dyn.physics.run(sched)
    for name in ("motor_rad", "motor_vel", "sensor_rad", "sensor_vel"):
        assert np.array_equal(getattr(chunked, name), getattr(whole, name)), name


def test_the_belt_run_reports_its_progress_without_changing_a_figure():
    """``on_sweeps`` (irring bench dynamics' progress bar) hears of every sweep, chunk by
    chunk, and the figures are those of a run nobody watches."""
    heard = []
    watched = bench.coupling(53, on_sweeps=heard.append)
    assert heard == [50, 3]
    alone = bench.coupling(53)
    np.testing.assert_array_equal(watched["stretch_per_sweep_rad"], alone["stretch_per_sweep_rad"])
    assert watched["read_error_max_rad"] == alone["read_error_max_rad"]


# A room of our own for the path clearance check: 1.53 × 0.97 m, a post and a box off-centre.
_CLEAR_ROOM = """\
name: path_clearance
room:
  outline_mm: [[0, 0], [1530, 0], [1530, 970], [0, 970]]
obstacles:
  - {type: cylinder, center_mm: [1110, 380], radius_mm: 41}
  - {type: box, center_mm: [430, 690], size_mm: [120, 70], yaw_deg: 17}
robot:
  poses:
    - {x_mm: 260, y_mm: 240}
effects:
  motion:
    path: PATH
"""


def _clearance_oracle(path, scenario):
    """The first failing sample, one at a time (the check before it was vectorised)."""
    from irring.core import HOUSING_M, distance_to_outline, inside_outline, obstacle_distance
    clearance = scenario.ring.radius_m + HOUSING_M
    n = max(2, int(math.ceil(path.length_m / D._PATH_SAMPLE_M)) + 1)
    for x, y, _ in path.pose_at_arc(np.linspace(0.0, path.length_m, n)):
        gaps = [distance_to_outline(x, y, scenario.room.outline_m)] + [
            obstacle_distance(ob, x, y) for ob in scenario.obstacles]
        if not inside_outline(x, y, scenario.room.outline_m) or min(gaps) < clearance:
            return f"at ({x * 1e3:.0f}, {y * 1e3:.0f}) mm"
    return None


@pytest.mark.parametrize("waypoints, segment", [
    ([(260, 240), (700, 240), (700, 600)], None),                         # clear all the way
    ([(260, 240), (700, 240), (700, 600), (1110, 560)], "[2] → [3]"),     # into the post
    ([(260, 240), (430, 500)], "[0] → [1]"),                              # into the box
    ([(260, 240), (700, 240), (700, 600), (1400, 800)], "[2] → [3]"),     # into the far corner
])
def test_path_clearance_finds_the_sample_the_one_at_a_time_check_finds(monkeypatch, waypoints,
                                                                       segment):
    """check_clearance took a sample at a time (2,000 waypoints: 6 min before the run was
    refused as too big); in blocks it must stop at the same first sample, also across a
    block's edge (blocks of 7 samples here)."""
    monkeypatch.setattr(D, "_CLEARANCE_BLOCK", 7)
    path_yaml = "[" + ", ".join(f"{{x_mm: {x}, y_mm: {y}}}" for x, y in waypoints) + "]"
    sc = loads(_CLEAR_ROOM.replace("PATH", path_yaml), "path_clearance.yaml")
    path = D.Path.from_effect(sc.effects["motion"])
    expected = _clearance_oracle(path, sc)
    if segment is None:
        assert expected is None
        path.check_clearance(sc)
        return
    with pytest.raises(ScenarioError) as caught:
        path.check_clearance(sc)
    assert f"effects.motion.path{segment}: {expected} the ring" in str(caught.value)
