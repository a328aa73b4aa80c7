"""Round twenty-one of hostile input: each test names the input that broke and asserts what
happens now."""

from __future__ import annotations

import os
import warnings

import numpy as np
import pytest

from irring import load_scenario
from irring.cli import main
from irring.core import Reason
from irring.estimation.calibration import Calibration
from irring.estimation.silence import unconfirmed_near
from irring.pipeline import load_calibration


def test_neighbouring_zero_counts_ask_no_near_reading_with_a_numpy_warning():
    # a sweep of 1 V noise reads 0 counts (an infinite distance) on neighbouring steps: their
    # inf - inf printed "RuntimeWarning: invalid value encountered in subtract" on stderr
    cal = Calibration.for_scene(load_scenario("t_room"))
    counts = np.array([[0.0, 3000.0], [0.0, 3005.0], [3100.0, 0.0], [700.0, 0.0]])
    reason = np.full(counts.shape, Reason.OK)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        alone = unconfirmed_near(counts, reason, np.array([-1, 0, 1, 2]), cal)
    assert alone.tolist() == [[False, False], [False, False], [True, False], [False, False]]


MOVING = """\
name: crawl
room:
  outline_mm: [[0, 0], [2420, 0], [2420, 900], [0, 900]]
robot:
  poses: [{x_mm: 500, y_mm: 450}]
effects:
  motion:
    path: [{x_mm: 500, y_mm: 450}, {x_mm: 1900, y_mm: 450}]
    speed_mm_s: SPEED
"""


@pytest.mark.parametrize("speed, said", [
    # 1400 mm at 1e-300 mm/s: 4.2e302 sweeps, an int past a float's range for the memory
    ("1e-300", "crawl.yaml: 4.21e+302 sweeps × 71 steps × 12 sensors = 3.59e+305 readings "
               "(about 2.15e+299 GB): a run takes at most 10,000 sweeps; raise "
               "effects.motion.speed_mm_s"),
    # 1e-320 mm/s: the drive's duration is infinite, and math.ceil(inf) raised
    ("1e-320", "crawl.yaml: effects.motion.speed_mm_s: 9.88131e-321 mm/s would never drive "
               "the path's 1400 mm; a run takes at most 10,000 sweeps"),
])
def test_a_drive_too_slow_for_a_float_is_refused_not_an_internal_error(tmp_path, capsys, speed,
                                                                        said):
    (tmp_path / "crawl.yaml").write_text(MOVING.replace("SPEED", speed))
    status = main(["run", str(tmp_path / "crawl.yaml"), "--out", str(tmp_path / "out"),
                   "--no-animation"])
    err = capsys.readouterr().err.strip()
    assert (status, err.count("\n")) == ((5 if speed == "1e-300" else 1), 0)
    assert said in err and "internal error" not in err
    assert not (tmp_path / "out").exists()


def test_a_custom_design_without_a_ring_names_the_file(tmp_path, capsys):
    # every other key's error starts with the file; this one alone came without it
    path = tmp_path / "mine.yaml"
    path.write_text("name: mine\nroom:\n  outline_mm: [[0, 0], [2000, 0], [2000, 1500], "
                    "[0, 1500]]\nrobot:\n  design: custom\n  poses: [{x_mm: 900, y_mm: 700}]\n")
    assert main(["scenarios", str(path)]) == 1
    assert capsys.readouterr().err == (
        f"irring scenarios: error: {path}: robot.ring: required when robot.design is custom; "
        "give the ring's numbers (sensors, radius_mm, min_step, max_step, …)\n")


@pytest.mark.parametrize("name", ["''", "' '"])
def test_an_empty_scenario_name_in_a_study_is_refused_not_read_as_its_folder(tmp_path, capsys,
                                                                              name):
    # a study.yml (not *.yaml) beside room.yaml: `scenarios: ['']` ran room.yaml unasked
    (tmp_path / "room.yaml").write_text(
        "name: room\nroom:\n  outline_mm: [[0, 0], [2000, 0], [2000, 1500], [0, 1500]]\n"
        "robot:\n  poses: [{x_mm: 900, y_mm: 700}]\n")
    (tmp_path / "study.yml").write_text(f"designs: [radial12]\nscenarios: [{name}]\n"
                                        "seeds: [1]\n")
    status = main(["study", str(tmp_path / "study.yml"), "--out", str(tmp_path / "out"),
                   "--workers", "1"])
    assert status == 1
    assert capsys.readouterr().err == (
        f"irring study: error: {tmp_path / 'study.yml'}: scenarios[0]: an empty name "
        f"({name}); name a bundled scenario, a YAML file or a folder of them (. is the study "
        "file's folder)\n")
    assert not (tmp_path / "out").exists()


def test_a_calibration_whose_picture_does_not_fit_says_the_file_is_written(tmp_path):
    # 10 kB a file: the calibration (~1.6 kB) fits, its picture does not; the line said only
    # "cal.png: File too large", as if the calibration were lost too
    import resource
    import subprocess
    import sys

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (10_000, 10_000))

    out = tmp_path / "cal.yaml"
    done = subprocess.run([sys.executable, "-m", "irring", "calibrate", "--out", str(out),
                           "--sweeps", "1"], preexec_fn=limit, capture_output=True, text=True,
                          timeout=120)
    assert (done.returncode, done.stderr) == (4, (
        f"irring calibrate: error: {tmp_path / 'cal.png'}: cannot write the picture: File too "
        f"large; the calibration {out} is written whole (it needs no picture)\n"))
    assert sorted(os.listdir(tmp_path)) == ["cal.yaml"]   # no half picture, no temporaries
    assert load_calibration(out)[0].sensor_model == "gp2d12"
