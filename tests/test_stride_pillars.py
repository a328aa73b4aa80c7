"""A pillar read every other step (docs/estimator.md, "A pillar read every other step"): the
line model cuts its arc into steep lines whose θ = 0 circle is below ``ROUND_RADII_M``;
``round_runs`` asks such runs too where the sweep reads every k-th step, k ≥ 2."""

from __future__ import annotations

import numpy as np
import pytest

from _synthetic import make_sweep, rectangle
from irring.core import beam_geometry, step_stride
from irring.designs import PAPER_RING
from irring.estimation import arcs as est_arcs
from irring.estimation import estimate as est
from irring.estimation import estimate_numpy as oracle
from irring.estimation.estimate import Calibration, estimate, estimate_detail

CENTRE, RADIUS = (0.44, 0.07), 0.095     # a 190 mm pillar 0.2-0.3 m off two sensors


def test_the_stride_is_the_steps_greatest_common_divisor():
    assert step_stride(np.arange(-35, 36)) == 1
    assert step_stride(np.arange(-35, 36, 2)) == 2
    assert step_stride(np.arange(-36, 37, 3)) == 3
    assert step_stride(np.array([7])) == 1
    assert step_stride(np.delete(np.arange(-35, 36, 2), 4)) == 2   # a lost step: a gap
    assert step_stride(np.arange(35, -36, -2)) == 2
    assert est_arcs._least_radius(np.arange(-35, 36, 2)) == est_arcs.ROUND_SMALL_M
    assert est_arcs._least_radius(np.arange(-35, 36)) == est_arcs.ROUND_RADII_M[0]


def _pillar(stride: int, seed: int):
    cal = Calibration.nominal("gp2y0a21", PAPER_RING)
    sweep, d, _ = make_sweep(cal, walls=rectangle(-0.9, -0.75, 1.1, 0.8),
                             circles=[(CENTRE, RADIUS)], pose=(0.0, 0.0, 0.21),
                             noise_counts=cal.sigma_counts(), seed=seed, quantize=True,
                             steps=np.arange(-35, 36, stride), max_range_m=0.8)
    origin, heading = beam_geometry(sweep.ring, sweep.pose, sweep.sensor_angles,
                                    cal.emitter_offset_m)
    hx = origin[..., 0] + d * np.cos(heading)
    hy = origin[..., 1] + d * np.sin(heading)
    on = np.abs(np.hypot(hx - CENTRE[0], hy - CENTRE[1]) - RADIUS) < 1e-6
    return cal, sweep, d, on


def _pillar_errors(cal, sweep, d, on):
    """The pillar's valid readings: their errors (m) and how many lie beyond 3σ."""
    p = estimate(sweep, cal)
    m = on & p.valid
    err = (p.d - d)[m]
    return err, int(np.count_nonzero(np.abs(err) > 3.0 * p.sigma_m[m]))


@pytest.mark.parametrize("seed, beyond_before, rms_before, rms_after",
                         [(3, 16, 0.0194, 0.0081), (4, 10, 0.0312, 0.0203),
                          (5, 9, 0.0311, 0.0202)])
def test_a_pillar_read_every_other_step_takes_its_arc(monkeypatch, seed, beyond_before,
                                                      rms_before, rms_after):
    """Two sensors read the pillar 28 times; main's rule (runs asked only where their θ = 0
    circle reaches ``ROUND_RADII_M``) left 9-16 of them beyond 3σ on steep lines, the arc
    leaves at most one."""
    cal, sweep, d, on = _pillar(2, seed)
    assert int(on.sum()) == 28
    err, beyond = _pillar_errors(cal, sweep, d, on)
    assert beyond <= 1, beyond
    assert np.sqrt(np.mean(err ** 2)) == pytest.approx(rms_after, abs=2e-4)
    monkeypatch.setattr(est_arcs, "ROUND_SMALL_M", est_arcs.ROUND_RADII_M[0])
    # (the column across sensors, which came later, takes the arc too: main's rule alone)
    monkeypatch.setattr(est, "columns_across_sensors", lambda points, label, *a: (points, label))
    err0, beyond0 = _pillar_errors(cal, sweep, d, on)
    assert beyond0 == beyond_before
    assert np.sqrt(np.mean(err0 ** 2)) == pytest.approx(rms_before, abs=2e-4)


def test_every_step_read_the_rule_is_not_asked(monkeypatch):
    """At stride 1 the pillar's estimate is main's bit for bit (its readings stay off lines
    there and are read from their own profiles)."""
    cal, sweep, d, on = _pillar(1, 4)
    now = estimate(sweep, cal)
    monkeypatch.setattr(est_arcs, "ROUND_SMALL_M", 1e9)
    before = estimate(sweep, cal)
    for f in ("x", "y", "d", "theta", "sigma_m", "valid", "reason"):
        np.testing.assert_array_equal(getattr(now, f), getattr(before, f), err_msg=f)


def test_the_oracle_reads_the_same_pillar():
    """round_runs is numpy shared by both estimators; on the stride-2 pillar both agree."""
    cal, sweep, _, on = _pillar(2, 3)
    fast = estimate_detail(sweep, cal)
    slow = oracle.estimate_detail(sweep, cal)
    np.testing.assert_array_equal(fast.points.valid, slow.points.valid)
    np.testing.assert_array_equal(fast.lines.label, slow.lines.label)
    assert int(np.count_nonzero(on & fast.points.valid & (fast.lines.label < 0))) >= 20
    for f in ("x", "y", "d", "theta", "sigma_m"):
        np.testing.assert_allclose(getattr(fast.points, f), getattr(slow.points, f), rtol=0,
                                   atol=1e-9, err_msg=f)
