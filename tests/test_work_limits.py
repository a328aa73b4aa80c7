"""Hostile inputs refused up front with the right exit status, naming the file and key
(tests/hostile findings: work too big for memory, values that used to end in exit 70)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from irring import errors
from irring.cli import main

BOX = """
name: {name}
room:
  outline_mm: [[0, 0], [2100, 0], [2100, 1400], [0, 1400]]
robot:
{robot}
{effects}
"""
POSE = "  poses: [{x_mm: 1040, y_mm: 730}]"


def scene(tmp_path, name, robot=POSE, effects=""):
    path = tmp_path / f"{name}.yaml"
    path.write_text(BOX.format(name=name, robot=robot, effects=effects))
    return path


def run_status(path, tmp_path, capsys):
    t0 = time.perf_counter()
    code = main(["run", str(path), "--no-animation", "--out", str(tmp_path / "out")])
    return code, capsys.readouterr().err, time.perf_counter() - t0


def test_a_crawling_drive_is_refused_before_any_sweep(tmp_path, capsys):
    # 1 m at 0.001 mm/s: 301 423 sweeps of 71 × 12 readings (it ran 16 min into 23.6 GB)
    path = scene(tmp_path, "crawl", effects="""effects:
  motion:
    path: [{x_mm: 480, y_mm: 730}, {x_mm: 1480, y_mm: 730}]
    speed_mm_s: 0.001
""")
    code, err, seconds = run_status(path, tmp_path, capsys)
    assert code == errors.TOO_BIG
    assert str(path) in err and "301,423 sweeps × 71 steps × 12 sensors" in err
    assert "GB" in err and "effects.motion.speed_mm_s" in err
    assert not (tmp_path / "out").exists()
    assert seconds < 30   # refused at model build, not after sweeping


def test_a_drive_too_long_is_refused_before_its_odometry_is_made(tmp_path, capsys,
                                                                  monkeypatch):
    """A path of 20,000 waypoints took 1 GB (a dead-reckoning sample every 5 mm of its 28 km)
    before it was refused as more sweeps than a run takes; 200,000 fit in a scenario file.
    The odometry is made when a sweep needs it, after the run's size is checked."""
    from irring.simulation import dynamics

    monkeypatch.setattr(dynamics.Odometry, "along",
                        classmethod(lambda *a, **k: pytest.fail("odometry made")))
    waypoints = ", ".join(f"{{x_mm: {480 + 1000 * (k % 2)}, y_mm: 730}}" for k in range(2_001))
    path = scene(tmp_path, "long", effects=f"effects:\n  motion:\n    path: [{waypoints}]\n")
    code, err, _ = run_status(path, tmp_path, capsys)
    assert code == errors.TOO_BIG
    assert "a run takes at most 10,000 sweeps; raise effects.motion.speed_mm_s" in err, err


def test_more_poses_than_a_run_takes_are_refused_naming_the_poses(tmp_path, capsys):
    """10,001 scan poses and no motion: the refusal said to raise effects.motion.speed_mm_s
    or shorten effects.motion.path, keys the scene does not have."""
    poses = ", ".join(f"{{x_mm: {300 + k % 1500}, y_mm: {700 + k % 7}}}" for k in range(10_001))
    code, err, _ = run_status(scene(tmp_path, "poses", robot=f"  poses: [{poses}]"), tmp_path,
                              capsys)
    assert code == errors.TOO_BIG
    assert ("10,001 sweeps × 71 steps × 12 sensors = 8,520,852 readings" in err
            and "a run takes at most 10,000 sweeps; list at most 10,000 robot.poses (a sweep "
            "each), or split them into several scenarios" in err), err
    assert "motion" not in err and not (tmp_path / "out").exists()


def test_a_sweep_of_more_steps_than_a_run_takes_is_refused(tmp_path, capsys):
    robot = ("  design: custom\n  ring: {sensors: 72, radius_mm: 150, motor_step_deg: 0.01, "
             "gear: 0.01, min_step: -100000, max_step: 60000, joint_limit_deg: 360}\n" + POSE)
    code, err, _ = run_status(scene(tmp_path, "wide", robot=robot), tmp_path, capsys)
    assert code == errors.TOO_BIG
    assert "160,001 steps × 72 sensors = 11,520,072 readings" in err
    assert "at most 100,000 steps" in err and "scan.step_stride" in err


def test_too_many_readings_in_total_are_refused_with_the_memory(tmp_path, capsys):
    # 72 sensors × 4 001 steps × 8 poses = 2.3 M readings, each sweep allowed alone
    poses = ", ".join(f"{{x_mm: {400 + 150 * k}, y_mm: {610 + 20 * k}}}" for k in range(8))
    robot = ("  design: custom\n  ring: {sensors: 72, radius_mm: 150, motor_step_deg: 0.01, "
             "gear: 0.01, min_step: -2000, max_step: 2000, joint_limit_deg: 360}\n"
             f"  poses: [{poses}]")
    code, err, _ = run_status(scene(tmp_path, "many", robot=robot), tmp_path, capsys)
    assert code == errors.TOO_BIG
    assert "8 sweeps × 4,001 steps × 72 sensors = 2,304,576 readings (about 2.2 GB)" in err
    assert "more than the 2 GB" in err and "robot.poses" in err


def test_belt_physics_too_long_for_memory_is_refused_naming_the_belt_keys(tmp_path, capsys):
    path = scene(tmp_path, "belt", effects="""effects:
  belt_dynamics: {timestep_ms: 0.01, step_time_ms: 1000}
""")
    code, err, seconds = run_status(path, tmp_path, capsys)
    assert code == errors.TOO_BIG
    assert "belt physics steps" in err and "effects.belt_dynamics.timestep_ms" in err
    assert seconds < 30


@pytest.mark.parametrize("effects, key, message", [
    ("outliers: {short_rate: 0.6, random_rate: 0.3, max_rate: 0.2}", "effects.outliers",
     "short_rate + random_rate + max_rate = 1.1; they are shares of exclusive cases"),
    ("belt_dynamics: {timestep_ms: 3, belt_timeconst_ms: 1.1, step_time_ms: 0.2}",
     "effects.belt_dynamics.timestep_ms", "3 ms is more than 2.5 × belt_timeconst_ms (1.1 ms)"),
    ("incidence: {max_incidence_deg: 0}", "effects.incidence.max_incidence_deg", "must be > 0°"),
])
def test_bad_effect_combinations_are_input_errors_at_load(tmp_path, capsys, effects, key,
                                                          message):
    path = scene(tmp_path, "bad", effects=f"effects:\n  {effects}\n")
    code, err, _ = run_status(path, tmp_path, capsys)
    assert code == errors.INPUT
    assert f"{path}: {key}: {message}" in err
    assert "internal error" not in err and "WARNING" not in err


def test_belt_at_the_stability_limit_loads_but_its_unconverged_sweep_is_refused(tmp_path):
    """The loader's RK4 rule (timestep ≤ 2.5 τ) lets 2.5 ms at τ = 1 ms through and the
    rollout stays finite without a MuJoCo warning, but halving the step moves the sensors by
    hundreds of degrees: the first sweep is refused, naming a halved step that passes."""
    from irring.scenario import ScenarioError, loads
    from irring.simulation import dynamics
    from irring.simulation.sim import SimRing
    text = BOX.format(name="belt", robot=POSE, effects="effects:\n  belt_dynamics: "
                      "{timestep_ms: 2.5, belt_timeconst_ms: 1, step_time_ms: 4}\n")
    sim = SimRing(loads(text, "belt.yaml"))
    run = sim.dynamics.physics.run(sim.dynamics.schedule(sim.default_steps()))
    assert np.isfinite(run.sensor_rad).all()
    with pytest.raises(ScenarioError, match=r"belt\.yaml: effects\.belt_dynamics\.timestep_ms: "
                                            r"2\.5 ms is not converged: .* by \d+°, more than "
                                            r"the 0\.1° allowed; timestep_ms: 0\.625 passes"):
        sim.sweep(0)
    assert dynamics.CONVERGED_ANGLE_RAD == pytest.approx(math.radians(0.1))
    with pytest.raises(ScenarioError, match="belt.yaml: effects.belt_dynamics.timestep_ms"):
        loads(text.replace("timestep_ms: 2.5", "timestep_ms: 2.51"), "belt.yaml")


@pytest.mark.parametrize("argv, message", [
    (["geometry", "--range-mm", "0"], "argument --range-mm: must be a number > 0"),
    (["geometry", "--range-mm", "nan"], "got 'nan'"),
    (["geometry", "--range-mm", "inf"], "got 'inf'"),
    (["geometry", "--range-mm", "3", "--samples", "1000"],
     "--range-mm 3: R·sin(Φ/2) = 0.03882 m exceeds the range D = 0.003 m"),
    (["bench", "estimator", "--min-theta", "nan"], "argument --min-theta: must be a number ≥ 0"),
    (["bench", "estimator", "--min-theta", "90.5"], "≤ 90, got '90.5'"),
])
def test_out_of_range_options_are_usage_errors(capsys, argv, message):
    with pytest.raises(SystemExit) as exit_:
        code = main(argv)
        raise SystemExit(code)
    assert exit_.value.code == errors.USAGE
    err = capsys.readouterr().err
    assert message in err and "internal error" not in err



def test_a_detection_distance_past_float_range_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["compare", "--design", "laser", "--distances-mm", "400,1e300"])
    assert exit_.value.code == errors.USAGE
    assert "up to 100000, like 250,500,1000; got '400,1e300'" in capsys.readouterr().err


DENSE_ROBOT = ("  design: custom\n  ring: {sensors: 72, radius_mm: 150, motor_step_deg: 0.01, "
               "gear: 0.01, min_step: -10000, max_step: 10000, joint_limit_deg: 3}\n"
               "  poses: [{x_mm: 410, y_mm: 370}]")


def test_one_sweep_too_big_to_estimate_is_refused_up_front(tmp_path, capsys):
    # 72 × 20 001 readings in an 800 × 760 mm room, every one a return: the budget called it
    # 0.9 GB and let it run; estimating it peaked at 4.0 GB
    path = tmp_path / "dense.yaml"
    path.write_text("name: dense\nroom:\n  outline_mm: [[0, 0], [800, 0], [800, 760], "
                    "[0, 760]]\nrobot:\n" + DENSE_ROBOT + "\n")
    code, err, seconds = run_status(path, tmp_path, capsys)
    assert code == errors.TOO_BIG, err
    assert "1 sweeps × 20,001 steps × 72 sensors = 1,440,072 readings (about 4.8 GB)" in err
    assert "more than the 2 GB" in err and "robot.ring.sensors" in err
    assert seconds < 30


def test_a_grid_far_past_memory_says_its_gigabytes_in_a_few_digits():
    """A 10¹⁵ × 10¹⁵-cell grid (a recording's metadata may say so) read "about
    600000000000000016777216.0 GB"; one decimal stays below a million GB."""
    from irring.errors import TooBig
    from irring.maps.mapping import BYTES_PER_CELL, check_grid_size

    assert BYTES_PER_CELL == 60
    with pytest.raises(TooBig) as huge:
        check_grid_size(10**15, 2 * 10**15, 0.01)
    assert "would need about 1.2e+23 GB; at most" in str(huge.value)
    with pytest.raises(TooBig) as big:
        check_grid_size(200_000, 300_000, 0.01)
    assert "would need about 3600.0 GB; at most" in str(big.value)
