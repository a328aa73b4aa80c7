"""A sensor turning a full turn has no sweep ends: where its step numbers start (the seam)
must not change its estimate (irring.estimation.seam; docs/estimator.md)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from irring import pipeline
from irring.core import Truth
from irring.designs import get
from irring.estimation import estimate as fast
from irring.estimation import estimate_numpy as oracle
from irring.estimation import seam
from irring.estimation.calibration import Calibration
from irring.scenario import loads

# an irregular octagon a GP2D12 reads all round (walls 250-600 mm: no silent step), and a
# pentagon with a niche a GP2Y0A21 reads to 800 mm (silent where the room is deeper)
_OCTAGON = """
name: octagon
seed: 5150
room:
  outline_mm: [[0, 0], [520, -60], [930, 180], [1010, 640], [760, 1010], [300, 1060],
               [-60, 780], [-120, 330]]
robot:
  design: rotating1
  poses: [{x_mm: 440, y_mm: 480, yaw_deg: -5}]
effects: {incidence: {}, noise: {sigma_v: 0.015}, quantization: {}}
"""
_PENTAGON = """
name: pentagon
seed: 99112
room:
  outline_mm: [[0, 0], [1420, 130], [1550, 980], [940, 1500], [560, 1380], [620, 1160],
               [-90, 1010]]
obstacles:
  - {type: box, center_mm: [1080, 430], size_mm: [210, 160], yaw_deg: -38}
robot:
  design: rotating1
  poses: [{x_mm: 700, y_mm: 650, yaw_deg: 41}]
sensor: {model: gp2y0a21, max_range_mm: 800}
effects: {incidence: {}, noise: {sigma_v: 0.015}, quantization: {}}
"""


def _sweep(text: str):
    scene = loads(text)
    return pipeline.simulated(scene, progress=False)[0].sweeps[0], Calibration.for_scene(scene)


def _seam_moved(sweep, rows: int):
    """The same readings (each with its own beam) with the step numbers starting ``rows``
    rows later: only where the seam lies changes."""
    roll = lambda a: np.roll(np.asarray(a), -rows, axis=0)   # noqa: E731
    truth = Truth(**{f.name: roll(getattr(sweep.truth, f.name))
                     for f in dataclasses.fields(Truth)})
    return dataclasses.replace(sweep, counts=roll(sweep.counts),
                               sensor_angles=roll(sweep.sensor_angles), truth=truth)


@pytest.mark.parametrize("text", [_OCTAGON, _PENTAGON], ids=["all-in-range", "with-silence"])
@pytest.mark.parametrize("estimator", [fast.estimate_detail, oracle.estimate_detail],
                         ids=["kernels", "oracle"])
def test_a_full_turns_estimate_does_not_depend_on_where_its_steps_start(text, estimator):
    """Read from step 0 as numbered, the octagon's estimate moved with its seam: of its
    326 valid readings 180 (seam 97 rows on) and 111 (211 on) moved by more than 0.1 mm,
    up to 40.7 mm; the pentagon's 54 (211 on). Both estimators."""
    sweep, cal = _sweep(text)
    assert sweep.counts.shape == (334, 1)
    ref = estimator(sweep, cal).points
    assert ref.valid.sum() > 100
    for rows in (97, 211):
        got = estimator(_seam_moved(sweep, rows), cal).points
        back = lambda a: np.roll(a, rows, axis=0)   # noqa: E731
        np.testing.assert_array_equal(back(got.valid), ref.valid)
        np.testing.assert_array_equal(back(got.reason), ref.reason)
        np.testing.assert_allclose(back(got.d), ref.d, rtol=0, atol=1e-9)


def _silent_turn(silent_rows, n=40):
    """A 40-step full turn of 9° whose listed rows read below the return level."""
    cal = Calibration.for_scene(loads(_OCTAGON))
    sweep, _ = _sweep(_OCTAGON)
    counts = np.full((n, 1), cal.no_return_counts + 200.0)
    counts[list(silent_rows), 0] = cal.no_return_counts
    return dataclasses.replace(sweep, steps=np.arange(n), counts=counts,
                               sensor_angles=np.radians(9.0) * np.arange(n)[:, None] + 0.2,
                               timestamps_s=np.arange(n) * 0.04, truth=None), cal


def test_a_full_turn_starts_in_the_middle_of_its_longest_silence():
    """Silent rows 3-5 and 21-30: read from row 26 (21 + 10 // 2) round to row 25."""
    sweep, cal = _silent_turn([3, 4, 5, *range(21, 31)])
    np.testing.assert_array_equal(seam.turn_start(sweep, cal), np.roll(np.arange(40), -26))


def test_a_silence_across_the_seam_counts_as_one_run():
    """Silent rows 33-39 and 0-4 (12 rows round the seam) beat rows 15-24 (10): the middle
    of the twelve is row 39 (33 + 12 // 2 = 39)."""
    sweep, cal = _silent_turn([*range(33, 40), *range(5), *range(15, 25)])
    np.testing.assert_array_equal(seam.turn_start(sweep, cal), np.roll(np.arange(40), -39))


def test_a_turn_already_starting_in_its_silence_and_a_ring_that_does_not_turn_are_kept():
    """Silent rows 36-39 and 0-3: its middle is row 0, nothing to move; the paper's ring
    (each sensor ±37.8°) never closes a turn; nor does a 40-step turn of 8.9°."""
    sweep, cal = _silent_turn([36, 37, 38, 39, 0, 1, 2, 3])
    assert seam.turn_start(sweep, cal) is None
    short = dataclasses.replace(sweep, sensor_angles=np.radians(8.9) * np.arange(40)[:, None])
    assert seam.turn_start(short, cal) is None
    ring = get("rotating12").ring
    steps = np.arange(ring.min_step, ring.max_step + 1)
    angles = steps[:, None] * ring.motor_step_rad * ring.gear + np.zeros((1, 12))
    paper = dataclasses.replace(sweep, steps=steps, sensor_angles=angles,
                                counts=np.full(angles.shape, 900.0),
                                timestamps_s=np.zeros(steps.size), ring=ring)
    assert seam.turn_start(paper, cal) is None


def test_a_turn_read_all_round_starts_after_its_largest_jump_in_counts():
    """No silent row: counts rise by 160 at row 17, fall by 150 at row 30 and by 10 from
    row 39 round to row 0: row 17 leads."""
    sweep, cal = _silent_turn([])
    counts = np.asarray(sweep.counts).copy()
    counts[17:30, 0] += 160.0
    counts[30:, 0] += 10.0
    sweep = dataclasses.replace(sweep, counts=counts)
    np.testing.assert_array_equal(seam.turn_start(sweep, cal), np.roll(np.arange(40), -17))
