"""The estimator's compiled kernels (irring/estimation/_iterate.pyx) at the edges the numpy code handled,
and their two ways of reading the calibration curve giving the same answer.

The kernels replicate the numpy estimator bit for bit (checked against recorded outputs of
the numpy code over every bundled scenario when they were written); these tests pin what
must stay true without that record.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from _synthetic import PAPER_RING, make_sweep, rectangle, stand_in_calibration
from irring.estimation import _iterate, _lines
from irring.core import Reason, beam_geometry
from irring.estimation.calibration import Calibration
from irring.estimation.estimate import estimate, estimate_detail
from irring.estimation.lines import LineOptions

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
    assert np.all(p.iterations == 1) and len(est.theta_history) == 1
    # detail asked for: an empty lines record, every reading on no line
    assert est.lines.n_points.size == 0 and (est.lines.label == -1).all()


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
    """θ history: θ = 0 first, then one entry per iteration taken, ending at the final θ
    of every reading that kept its line (the others are read again after the iterations:
    arcs.local_incidence; here a 5-member line at 59–64° on a wall met at 27–30°, which
    the round-line rule takes off it)."""
    sweep, _, _ = make_sweep(NOMINAL, walls=rectangle(-0.45, -0.35, 0.5, 0.4), noise_counts=1.0)
    est = estimate_detail(sweep, NOMINAL, keep_history=True)
    h = est.theta_history
    p = est.points
    assert np.all(h[0] == 0.0) and len(h) == int(p.iterations.max()) + 1
    v = p.valid & (est.lines.label >= 0)
    assert v.sum() >= 800
    np.testing.assert_array_equal(h[-1][v], p.theta[v])
    same = estimate(sweep, NOMINAL)
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(p, f), getattr(same, f), err_msg=f)


def test_steps_must_match_the_rows_of_counts():
    """The scan order indexes the readings by step, and the kernels index through it
    unchecked: one step too many read and wrote past the arrays (heap corruption), too few
    left readings unestimated yet marked OK with NaN points. Both are refused up front."""
    sweep, _, _ = make_sweep(NOMINAL, walls=rectangle(-0.4, -0.4, 0.4, 0.4))
    for steps in (sweep.steps[:-5], np.append(sweep.steps, sweep.steps[-1] + 1)):
        with pytest.raises(ValueError, match="sweep.steps"):
            estimate(dataclasses.replace(sweep, steps=steps), NOMINAL)


def test_scan_order_outside_the_readings_is_refused():
    """The kernels' own guard (estimate checks first, but nothing else stands between a
    caller and unchecked indexing): a scan index past the readings is a ValueError."""
    sweep, _, _ = make_sweep(NOMINAL, walls=rectangle(-0.4, -0.4, 0.4, 0.4))
    counts = np.ascontiguousarray(sweep.counts, dtype=float).reshape(-1)
    n = counts.size
    reason = np.zeros(n, dtype=np.uint8)
    scan = np.arange(n, dtype=np.intp)
    scan[-1] = n
    with pytest.raises(ValueError, match="scan"):
        _iterate.Sweep(NOMINAL, LineOptions(), counts, np.zeros(2 * n), np.zeros(n), reason,
                       scan, 12, 0.001, 0.03)


def test_sweep_takes_the_callers_beam_directions_or_computes_them():
    """The estimator hands the kernel numpy's cos and sin of the headings (computed anyway
    for the emitters); without them the kernel computes libm's. Both place every reading
    at the same end point, bit for bit, and wrong lengths are refused."""
    sweep, _, _ = make_sweep(NOMINAL, walls=rectangle(-0.45, -0.35, 0.5, 0.4),
                             pose=(0.03, -0.02, 2.9), noise_counts=1.0, seed=5)
    counts = np.ascontiguousarray(sweep.counts, dtype=float).reshape(-1)
    n = counts.size
    origin, heading, cos_h, sin_h = beam_geometry(
        PAPER_RING, np.asarray(sweep.pose), np.asarray(sweep.sensor_angles),
        NOMINAL.emitter_offset_m, trig=True)
    reason = np.where(counts > 0, 0, int(Reason.NO_RETURN)).astype(np.uint8)
    args = (NOMINAL, LineOptions(), counts, origin.reshape(-1), heading.reshape(-1), reason,
            np.arange(n, dtype=np.intp), 12, 0.001, 0.03)
    given = _iterate.Sweep(*args, cos_h.reshape(-1), sin_h.reshape(-1))
    own = _iterate.Sweep(*args)
    theta = np.full(given.k, 0.3)
    given.place(theta, 2.0)
    own.place(theta, 2.0)
    assert given.k == own.k > 400
    for f in ("px", "py", "d"):
        np.testing.assert_array_equal(getattr(given, f), getattr(own, f), err_msg=f)
    with pytest.raises(ValueError, match="cos_h, sin_h"):
        _iterate.Sweep(*args, cos_h.reshape(-1)[:-1], sin_h.reshape(-1))


def test_readings_leaving_the_usable_range_between_groupings():
    """A regroup splits the readings still within 1.5 × max range. Here a calibration whose
    a(θ) grows with θ puts the only two usable readings (an oblique wall; the rest lie
    beyond range) out of it once they take their line's θ, so the regroup has no points:
    the first grouping's pieces cannot be refined on them (the segmentation refused them
    with a ValueError), and no line is left (no line 0 to look at either)."""
    cal = stand_in_calibration(strength=1.0)
    sweep, _, inc = make_sweep(cal, walls=[((-2.0, 0.45), (2.0, 0.45))])
    s, n = 35, 5
    assert np.radians(55) < inc[s, n] < np.radians(65)
    counts = np.zeros(np.shape(sweep.counts))
    counts[s:s + 2, n] = sweep.counts[s:s + 2, n]
    d0 = cal.distance(counts[s:s + 2, n], 0.0)
    sweep = dataclasses.replace(sweep, counts=counts, max_range_m=float(d0.max()) * 1.05 / 1.5)
    est = estimate_detail(sweep, cal, lines=LineOptions(min_points=2, min_length_m=0.0),
                          keep_history=True)
    assert est.lines is not None and est.lines.normal.shape == (0, 2)
    # θ went to the wall's (so the points moved out of range), then back to 0 off any line
    seen = np.array([h[s:s + 2, n] for h in est.theta_history])
    np.testing.assert_allclose(seen.max(axis=0), inc[s:s + 2, n], atol=np.radians(0.5))
    assert np.all(seen[-1] == 0.0) and not est.points.valid.any()


def test_max_iterations_must_be_an_integer():
    """A float count reached the kernels only once a held iteration ran, so it failed on
    some sweeps and not others; now it fails on every sweep."""
    sweep, _, _ = make_sweep(NOMINAL, walls=rectangle(-0.4, -0.4, 0.4, 0.4))
    counts = np.zeros(np.shape(sweep.counts))
    counts[10, 3] = sweep.counts[10, 3]     # one reading: no line, no held iteration
    with pytest.raises(TypeError):
        estimate(dataclasses.replace(sweep, counts=counts), NOMINAL, max_iterations=5.0)
    assert estimate(sweep, NOMINAL, max_iterations=np.int32(5)).valid.any()


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 16), keep=st.floats(0.0, 1.0),
       max_iterations=st.sampled_from([1, 2, 3, 20]),
       max_range_m=st.sampled_from([0.15, 0.3, 0.624]),
       min_points=st.integers(1, 3))
def test_sparse_sweeps_keep_the_contract(seed, keep, max_iterations, max_range_m, min_points):
    """Sweeps thinned to a few readings (gaps, NaN, a short max range, a curve whose a(θ)
    grows so readings leave the usable range as θ grows) at any iteration limit: valid
    points are finite, no reading takes more iterations than allowed, and recording the θ
    history changes nothing."""
    cal = stand_in_calibration(strength=1.0)
    rng = np.random.default_rng(seed)
    x0, y0 = -rng.uniform(0.2, 0.7, 2)
    x1, y1 = rng.uniform(0.2, 0.7, 2)
    sweep, _, _ = make_sweep(cal, walls=rectangle(x0, y0, x1, y1), noise_counts=1.0, seed=seed,
                             pose=(0.0, 0.0, rng.uniform(-3, 3)), max_range_m=max_range_m)
    counts = np.array(sweep.counts)
    counts[rng.random(counts.shape) > keep] = 0.0
    counts[rng.random(counts.shape) < 0.05] = np.nan
    sweep = dataclasses.replace(sweep, counts=counts)
    opts = LineOptions(min_points=min_points, min_length_m=0.02)
    est = estimate_detail(sweep, cal, max_iterations=max_iterations, lines=opts,
                          keep_history=True)
    p = est.points
    v = p.valid
    assert np.all(np.isfinite(p.x[v]) & np.isfinite(p.y[v]) & np.isfinite(p.sigma_m[v]))
    assert p.iterations.max() <= max_iterations and len(est.theta_history) <= max_iterations + 1
    same = estimate(sweep, cal, max_iterations=max_iterations, lines=opts)
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(p, f), getattr(same, f), err_msg=f)


def test_a_kernel_given_arrays_of_different_lengths_names_each_length():
    """The kernels index unchecked, so arrays that must share a length are checked first;
    the refusal names every array's length, so a caller sees which one is off."""
    f = np.zeros
    with pytest.raises(ValueError, match=r"^per-reading arrays differ in length: d 5, "
                                         r"sigma 4, heading 5, sensor 5$"):
        _lines.polyline_ids(f(5), f(4), f(5), f(5, np.intp), 1.0, 2.0)
    with pytest.raises(ValueError, match=r"^counts and reason differ in length: counts 7, "
                                         r"reason 6$"):
        _iterate.classify(f(7), f(6, np.uint8), 900.0, 600.0, 30.0, 5.0, 10.0, True)
    with pytest.raises(ValueError, match=r"differ in length: ox 3, oy 3, heading 3, "
                                         r"log_s 3, sig_s 3, chain 2, step 3$"):
        _lines.profiles(f(3), f(3), f(3), f(3), f(3), f(2, np.intp), f(3, np.intp),
                        f(1, np.intp), f(2), f(2), f(2), 1.2, 0.1, 5, 3, 0.001, 2.0, f(5),
                        0.001, 3.0, 1e-12)
