"""Hostile inputs refused up front with the right exit status, naming the file and key
(tests/hostile findings: work too big for memory, values that used to end in exit 70)."""

from __future__ import annotations

import time

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


def test_a_sweep_of_more_steps_than_a_run_takes_is_refused(tmp_path, capsys):
    robot = ("  design: custom\n  ring: {sensors: 72, radius_mm: 150, motor_step_deg: 0.01, "
             "gear: 0.01, min_step: -100000, max_step: 60000, joint_limit_deg: 360}\n" + POSE)
    code, err, _ = run_status(scene(tmp_path, "wide", robot=robot), tmp_path, capsys)
    assert code == errors.TOO_BIG
    assert "160,001 steps × 72 sensors = 11,520,072 readings" in err
    assert "at most 100,000 steps" in err and "scan.step_stride" in err


def test_too_many_readings_in_total_are_refused_with_the_memory(tmp_path, capsys):
    # 72 sensors × 40 001 steps × 2 poses = 5.76 M readings, each sweep allowed alone
    robot = ("  design: custom\n  ring: {sensors: 72, radius_mm: 150, motor_step_deg: 0.01, "
             "gear: 0.01, min_step: -20000, max_step: 20000, joint_limit_deg: 360}\n"
             "  poses: [{x_mm: 1040, y_mm: 730}, {x_mm: 900, y_mm: 610}]")
    code, err, _ = run_status(scene(tmp_path, "many", robot=robot), tmp_path, capsys)
    assert code == errors.TOO_BIG
    assert "2 sweeps × 40,001 steps × 72 sensors = 5,760,144 readings (about 3.5 GB)" in err
    assert "more than the 2 GB" in err and "robot.poses" in err


def test_belt_physics_too_long_for_memory_is_refused_naming_the_belt_keys(tmp_path, capsys):
    path = scene(tmp_path, "belt", effects="""effects:
  belt_dynamics: {timestep_ms: 0.01, step_time_ms: 1000}
""")
    code, err, seconds = run_status(path, tmp_path, capsys)
    assert code == errors.TOO_BIG
    assert "belt physics steps" in err and "effects.belt_dynamics.timestep_ms" in err
    assert seconds < 30
