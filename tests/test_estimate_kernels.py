"""The estimator's compiled kernels (irring/_iterate.pyx) at the edges the numpy code handled,
and their two ways of reading the calibration curve giving the same answer.

The kernels replicate the numpy estimator bit for bit (checked against recorded outputs of
the numpy code over every bundled scenario when they were written); these tests pin what
must stay true without that record.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from _synthetic import PAPER_RING, make_sweep, rectangle, stand_in_calibration
from irring import _iterate
from irring.data import Reason
from irring.estimate import Calibration, estimate, estimate_detail

NOMINAL = Calibration.nominal("gp2d12", PAPER_RING)
FIELDS = ("x", "y", "d", "theta", "sigma_m", "iterations", "valid", "reason")


def _table_only(cal: Calibration) -> Calibration:
    """A copy of ``cal`` whose fine table the estimator must read row by row."""
    other = dataclasses.replace(cal)
    inv_h, table, exact = other._fine
    assert exact
    object.__setattr__(other, "_fine", (inv_h, table, False))
    return other


@pytest.mark.parametrize("cal", [NOMINAL, stand_in_calibration()], ids=["gp2d12", "stand-in"])
def test_computed_curve_equals_the_fine_table(cal):
    """Where the calibration's check passes, the kernels compute each (log a, b) row from
    the nodes instead of reading the 1 MB table (and the final points' curve likewise);
    reading the table must give the very same points."""
    sweep, _, _ = make_sweep(cal, walls=rectangle(-0.45, -0.35, 0.5, 0.4), pose=(0.02, -0.03, 0.3),
                             noise_counts=2.0, seed=3)
    fast, slow = estimate(sweep, cal), estimate(sweep, _table_only(cal))
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(fast, f), getattr(slow, f), err_msg=f)
    assert fast.valid.sum() > 100


def test_fine_table_check_notices_one_ulp():
    """The check that lets the kernels compute the table's rows is exact: one row one ulp
    off (another numpy rounding np.interp differently) turns it off."""
    inv_h, table, exact = NOMINAL._fine
    assert exact and _iterate.fine_table_is_interp(NOMINAL.theta_rad, NOMINAL._log_a,
                                                   NOMINAL.b, table)
    bad = table.copy()
    bad[12345, 0] = np.nextafter(bad[12345, 0], np.inf)
    assert not _iterate.fine_table_is_interp(NOMINAL.theta_rad, NOMINAL._log_a, NOMINAL.b, bad)


def test_sweep_without_live_readings():
    """No live reading (all missing or no return): no iteration, every reason set, no NaN
    leaks into valid points because there are none."""
    sweep, _, _ = make_sweep(NOMINAL, walls=rectangle(-0.4, -0.4, 0.4, 0.4))
    counts = np.full(np.shape(sweep.counts), np.nan)
    counts[::2] = 0.0
    sweep = dataclasses.replace(sweep, counts=counts)
    est = estimate_detail(sweep, NOMINAL, keep_history=True)
    p = est.points
    assert not p.valid.any()
    assert set(np.unique(p.reason)) == {Reason.MISSING, Reason.NO_RETURN}
    assert np.all(p.iterations == 1) and est.lines is None and len(est.theta_history) == 1


def test_single_live_reading_keeps_theta_zero():
    """One reading alone cannot make a line: it keeps θ = 0 with the widened σ."""
    sweep, _, _ = make_sweep(NOMINAL, walls=rectangle(-0.4, -0.4, 0.4, 0.4))
    counts = np.zeros(np.shape(sweep.counts))
    counts[10, 3] = sweep.counts[10, 3]
    p = estimate(dataclasses.replace(sweep, counts=counts), NOMINAL)
    assert p.valid.sum() == 1 and p.theta[10, 3] == 0.0
    plain = estimate(dataclasses.replace(sweep, counts=counts), NOMINAL, iterate=False)
    assert p.d[10, 3] == plain.d[10, 3] and p.sigma_m[10, 3] > plain.sigma_m[10, 3]


def test_history_follows_the_iterations():
    """θ history: θ = 0 first, then one entry per iteration taken, ending at the final θ."""
    sweep, _, _ = make_sweep(NOMINAL, walls=rectangle(-0.45, -0.35, 0.5, 0.4), noise_counts=1.0)
    est = estimate_detail(sweep, NOMINAL, keep_history=True)
    h = est.theta_history
    p = est.points
    assert np.all(h[0] == 0.0) and len(h) == int(p.iterations.max()) + 1
    v = p.valid
    np.testing.assert_array_equal(h[-1][v], p.theta[v])
    same = estimate(sweep, NOMINAL)
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(p, f), getattr(same, f), err_msg=f)
