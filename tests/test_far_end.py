"""The far end of a curve read to its part's own range (docs/estimator.md, "Silent beams"):
the GP2Y0A21 read to 800 mm and the GP2Y0A02 to 1500 mm end at the no-return level, so a
silent beam rules out a surface only as far as ``Calibration.silent_range_m``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from irring import gp2, pipeline
from irring.core import Reason
from irring.estimation import estimate as fast
from irring.estimation.calibration import (NO_RETURN_SIGMAS, RETURN_SIGMAS, Calibration,
                                           scene_calibration)
from irring.maps import metrics
from irring.maps.mapping import FREE
from irring.scenario import loads

# A room of our own: 1830 × 1590 mm, one pose off its middle and turned 13°, the GP2Y0A21
# read to its full 800 mm: its walls lie 610-800 mm from the sensors facing them.
FAR_A21 = """\
name: far_a21
seed: 97
room:
  outline_mm: [[0, 0], [1830, 0], [1830, 1590], [0, 1590]]
robot:
  poses:
    - {x_mm: 880, y_mm: 760, yaw_deg: 13}
sensor: {model: gp2y0a21, max_range_mm: 800}
effects: [incidence, noise, quantization]
"""


def _silent_range_from_volts(model: str, sigma_v: float, bits: int = 12) -> float:
    """The same distance worked out in volts on the part's curve (irring.gp2)."""
    m = gp2.sensor(model)
    sigma = math.hypot(sigma_v, gp2.lsb_v(bits, 5.0) / math.sqrt(12.0))
    return float(m.distance(m.no_return_v + (NO_RETURN_SIGMAS + RETURN_SIGMAS) * sigma))


@pytest.mark.parametrize("model, expected_m", [("gp2y0a21", 0.6379), ("gp2y0a02", 1.2360),
                                               ("gp2d12", 0.6436)])
def test_silent_range_is_where_a_surface_square_on_reads_silent_once_in_10000(model, expected_m):
    cal = Calibration.nominal(model, noise_sigma_v=0.015)
    assert cal.silent_range_m == pytest.approx(_silent_range_from_volts(model, 0.015), rel=1e-9)
    assert cal.silent_range_m == pytest.approx(expected_m, abs=5e-5)
    # a surface there reads at or below the no-return band with the 1e-4 tail RETURN_SIGMAS
    # stands for (its counts mean minus the band's top, in count σ)
    band_top = cal.no_return_counts + NO_RETURN_SIGMAS * cal.sigma_counts()
    z = (cal.counts(cal.silent_range_m) - band_top) / cal.sigma_counts()
    assert 0.5 * math.erfc(z / math.sqrt(2.0)) == pytest.approx(1e-4, rel=0.01)


def test_silent_range_follows_the_noise_and_ignores_linear_sensors():
    # quantisation alone (an ideal sensor): 5.72 × 0.29 counts short of 800 mm
    quiet = Calibration.nominal("gp2y0a21", noise_sigma_v=1e-6)
    assert quiet.silent_range_m == pytest.approx(_silent_range_from_volts("gp2y0a21", 1e-6))
    assert 0.794 < quiet.silent_range_m < quiet.max_range_m == 0.8
    assert Calibration.nominal("gp2d12", noise_sigma_v=0.030).silent_range_m == pytest.approx(
        _silent_range_from_volts("gp2d12", 0.030), rel=1e-9)               # 0.563 m < 0.624
    laser = Calibration.nominal("laser", noise_sigma_v=0.015)
    assert laser.silent_range_m == laser.max_range_m


def _false_free(scene, monkeypatch=None):
    run = pipeline.run(scene, progress=False)
    truth = metrics.ground_truth(scene, run.grid)
    free = run.grid.classify() == FREE
    return int((free & ~metrics._dilate(truth.free)).sum()), run


def test_silent_beams_no_longer_free_cells_behind_walls_they_could_not_return_from(monkeypatch):
    """Before, a silent beam freed its cells to 800 mm: 241 cells outside this room were
    mapped free (free accuracy 0.989)."""
    scene = loads(FAR_A21)
    cal = scene_calibration(scene)[0]
    false_free, run = _false_free(scene)
    p = run.points[0]
    silent = p.reason == Reason.NO_RETURN
    assert int(silent.sum()) == 616
    np.testing.assert_array_less(p.reach_m[silent], cal.silent_range_m + 1e-12)
    assert false_free == 0 and run.scores["free_accuracy"] == 1.0
    monkeypatch.setattr(fast, "silent_reach", lambda points, cal: points)
    before, _ = _false_free(scene)
    assert before == 241


def test_the_papers_range_is_left_as_it_was():
    """GP2D12 read to 624 mm with 15 mV of noise: silence rules a surface out to 644 mm,
    past the range, so silent beams keep their reach (None: to the max range)."""
    scene = loads(FAR_A21.replace("{model: gp2y0a21, max_range_mm: 800}", "{model: gp2d12}"))
    points = pipeline.run(scene, progress=False).points[0]
    assert int((points.reason == Reason.NO_RETURN).sum()) > 100
    reach = points.reach_m
    assert reach is None or not np.isfinite(reach[points.reason == Reason.NO_RETURN]).any()
