"""Lines fitted to their members' counts, compiled (counts.CountsFitKernels, irring/
estimation/_lines.pyx: counts_refit, counts_jacobian, counts_at, best_halves) against their
numpy statements (counts.CountsFits): the same numbers to the bit (tolerance 0), on lines
and beams hypothesis draws and on a sweep where a contradicted line is read in pieces.
docs/speed.md, "A contradicted line's pieces"."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from irring import pipeline
from irring.core import Reason
from irring.estimation import _lines
from irring.estimation import estimate as est
from irring.estimation import counts as est_counts
from irring.estimation.calibration import Calibration
from irring.scenario import load_scenario
from irring.studies.rooms import ideal

CALS = {m: Calibration.nominal(m) for m in ("gp2d12", "gp2y0a21", "gp2y0a02")}
# an ideal sensor's calibration: one node (θ = 0), its curve the same at every incidence
CALS["ideal"] = pipeline.scene_calibration(ideal(load_scenario("t_room")))[0]
NUMPY, KERNELS = est.CountsFits, est_counts.CountsFitKernels


def _bits(x):
    x = np.asarray(x)
    return x.dtype, x.shape, np.ascontiguousarray(x).tobytes()


@st.composite
def _lines_and_beams(draw):
    """1-4 lines (direction, offset), each met by 3-30 beams of one sensor 0.1-0.9 m from it
    (some past the drop-out angle or behind the sensor), their counts the model's at a line
    turned and moved from the one asked, plus noise; each line asked or not."""
    model = draw(st.sampled_from(sorted(CALS)))
    cal = CALS[model]
    n_lines = draw(st.integers(1, 4))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    line, ox, oy, h, s = [], [], [], [], []
    a = rng.uniform(-math.pi, math.pi, n_lines)
    dist = rng.uniform(0.1, 0.9, n_lines)
    for g in range(n_lines):
        n = draw(st.integers(3, 30))
        x0, y0 = rng.uniform(-0.3, 0.4, 2)
        nx, ny = -math.sin(a[g]), math.cos(a[g])
        # headings about the line's normal from the sensor, up to ±69° (some past the drop-out)
        spread = draw(st.floats(0.05, 1.2))
        phi = math.atan2(ny, nx) + rng.uniform(-spread, spread * 0.9, n)
        true_a = a[g] + rng.normal(0.0, 0.05)
        t = np.abs(dist[g] / np.cos(phi - math.atan2(ny, nx)))
        inc = np.abs(np.arccos(np.clip(np.abs(np.cos(phi - math.atan2(
            math.cos(true_a), -math.sin(true_a)))), 0.0, 1.0)))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            counts = cal.counts(np.clip(t, 0.08, 2.0), inc)
        counts = np.where(np.isfinite(counts), counts, 200.0) + rng.normal(
            0.0, 3 * cal.sigma_counts(), n)
        line += [g] * n
        ox.append(np.full(n, x0))
        oy.append(np.full(n, y0))
        h.append(phi)
        s.append(np.clip(counts, 5.0, None))
    h = np.concatenate(h)
    beam = (np.concatenate(ox), np.concatenate(oy), np.cos(h), np.sin(h))
    s = np.concatenate(s)
    c = -np.sin(a) * (beam[0][0] + 0.0) + np.cos(a) * beam[1][0] + dist * rng.choice([-1, 1])
    sig = est_counts._counts_sigma(cal, s)[1]
    asked = np.asarray(draw(st.lists(st.booleans(), min_size=n_lines, max_size=n_lines)))
    settled = draw(st.sampled_from([None, est_counts.PIECE_SETTLED, (1e-2, 1e-3)]))
    order = rng.permutation(s.size) if draw(st.booleans()) else np.arange(s.size)
    return (cal, n_lines, np.asarray(line, dtype=np.intp)[order], s[order], sig[order],
            tuple(v[order] for v in beam), a, c, asked, settled)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_lines_and_beams(), st.integers(1, 8))
def test_refit_kernel_is_the_numpy_statement_to_the_bit(drawn, steps):
    cal, n_lines, line, s, sig, beam, a, c, asked, settled = drawn
    want = NUMPY.refit(cal, n_lines, line, s, sig, beam, a, c, asked, steps, settled)
    got = KERNELS.refit(cal, n_lines, line, s, sig, beam, a, c, asked, steps, settled)
    for w, g in zip(want, got):
        assert _bits(g) == _bits(w)
    # the lines not asked stay where they were; the caller's arrays are not written
    assert _bits(got[0][~asked]) == _bits(a[~asked])


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_lines_and_beams())
def test_jacobian_and_misfit_kernels_are_the_numpy_statements_to_the_bit(drawn):
    cal, _, line, s, sig, beam, a, c, _, _ = drawn
    for w, g in zip(NUMPY.jacobian(cal, a[line], c[line], beam),
                    KERNELS.jacobian(cal, a[line], c[line], beam)):
        assert _bits(g) == _bits(w)
    want = NUMPY.misfit(cal, a[line], c[line], s, sig, *beam)
    assert _bits(KERNELS.misfit(cal, a[line], c[line], s, sig, *beam)) == _bits(want)
    # beams past the drop-out angle or behind the sensor: inf, in both
    e, met = est_counts._counts_at(cal, a[line], c[line], *beam)
    assert np.array_equal(np.isinf(want), ~met)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0)), min_size=4,
                max_size=60), st.integers(1, 8))
def test_best_halves_kernel_is_the_numpy_statement(points, lo):
    xy = np.asarray(points, dtype=float)
    if xy.shape[0] < 2 * lo:
        with pytest.raises(ValueError, match="no two runs of"):
            KERNELS.halves(xy[:, 0], xy[:, 1], lo)
        return
    assert KERNELS.halves(xy[:, 0], xy[:, 1], lo) == est_counts._best_halves(xy[:, 0], xy[:, 1], lo)


def test_one_node_reads_the_same_curve_at_every_incidence():
    # np.interp over one node gives its value at any θ (a NaN θ too): so does the kernel
    cal = CALS["ideal"]
    assert cal.theta_rad.size == 1
    h = np.array([0.0, 0.4, -0.9, 1.2, np.nan])
    alpha, c = np.full(h.size, math.pi / 2), np.full(h.size, -0.52)
    zero = np.zeros(h.size)
    want = est_counts._counts_at(cal, alpha, c, zero, zero, np.cos(h), np.sin(h))
    got = est_counts._counts_at_compiled(cal, alpha, c, zero, zero, np.cos(h), np.sin(h))
    assert _bits(got[0]) == _bits(want[0]) and np.array_equal(got[1], want[1])
    assert np.array_equal(got[1], [True, True, True, True, False])


def test_counts_at_reads_the_curve_as_np_interp_at_and_beyond_its_nodes():
    # beams meeting a wall 0.43 m away (x = 0.43) at each node's incidence, between nodes,
    # and past the table (held): the compiled interpolation is numpy's to the bit
    cal = CALS["gp2y0a21"]
    theta = np.concatenate([cal.theta_rad, 0.5 * (cal.theta_rad[1:] + cal.theta_rad[:-1]),
                            [cal.theta_rad[-1] + 0.01, 1.5]])
    h = theta * np.where(np.arange(theta.size) % 2 == 0, 1.0, -1.0)
    alpha = np.full(h.size, math.pi / 2)
    c = np.full(h.size, -0.43)      # (direction +y: the normal points to −x, offset −0.43)
    zero = np.zeros(h.size)
    want = est_counts._counts_at(cal, alpha, c, zero, zero, np.cos(h), np.sin(h))
    got = est_counts._counts_at_compiled(cal, alpha, c, zero, zero, np.cos(h), np.sin(h))
    assert _bits(got[0]) == _bits(want[0]) and np.array_equal(got[1], want[1])
    # within the drop-out angle every beam meets it; past it none does
    assert np.array_equal(got[1], theta < cal.max_incidence_rad)
    assert np.all(got[0][got[1]] > 0) and np.all(got[0][~got[1]] == 0)


def test_no_member_moves_no_line():
    cal = CALS["gp2d12"]
    a, c, none = np.array([0.3, -1.2]), np.array([0.5, 0.7]), np.zeros(0)
    for fits in (NUMPY, KERNELS):
        got = fits.refit(cal, 2, np.zeros(0, dtype=np.intp), none, none,
                         (none, none, none, none), a, c, np.ones(2, dtype=bool), 8)
        assert _bits(got[0]) == _bits(a) and _bits(got[1]) == _bits(c)
        assert np.array_equal(got[2], np.zeros(2))


def test_kernels_name_what_they_refuse():
    cal = CALS["gp2d12"]
    one, two = np.ones(1), np.ones(2)
    with pytest.raises(ValueError, match="counts_refit's arrays differ in length"):
        _lines.counts_refit(np.zeros(2, dtype=np.intp), two, one, two, two, two, two, one,
                            one, np.ones(1, dtype=np.uint8), 3, False, 0.0, 0.0,
                            cal.theta_rad, cal._log_a, cal.b, 0.2, 1e-5, 1e-6)
    with pytest.raises(IndexError, match=r"line\[1\] = 3 is not a line \(0 … 1\)"):
        _lines.counts_refit(np.array([0, 3]), two, two, two, two, two, two, two, two,
                            np.ones(2, dtype=np.uint8), 3, False, 0.0, 0.0,
                            cal.theta_rad, cal._log_a, cal.b, 0.2, 1e-5, 1e-6)
    with pytest.raises(ValueError, match="counts_jacobian's beams differ in length"):
        _lines.counts_jacobian(two, one, two, two, two, two, cal.theta_rad, cal._log_a,
                               cal.b, 0.2, 1e-5, 1e-6)
    with pytest.raises(ValueError, match="the curve's nodes \\(at least 1\\) differ"):
        _lines.counts_at(one, one, one, one, one, one, cal.theta_rad, cal._log_a[:-1],
                         cal.b, 0.2)


def test_pieces_read_with_the_kernels_are_the_numpy_pieces():
    # the D-room's sweep (tests/test_contradicted_pieces.py): its contradicted lines' lost
    # members, read in pieces through either fits, placed the same to the bit, and some are
    from test_contradicted_pieces import _sweep
    sw, cal = _sweep()
    seen = {}

    def record(points, at, line, counts, cal_, bent, fitter=None):
        seen["args"] = (points, at, line, counts, cal_, bent)
        return original(points, at, line, counts, cal_, bent, fitter)

    original = est_counts.counts_pieces
    est_counts.counts_pieces = record
    try:
        est.estimate(sw, cal)
    finally:
        est_counts.counts_pieces = original
    points, at, line, counts, cal_, bent = seen["args"]
    want = est_counts.counts_pieces(points, at, line, counts, cal_, bent, NUMPY)
    got = est_counts.counts_pieces(points, at, line, counts, cal_, bent, KERNELS)
    for f in ("x", "y", "d", "theta", "sigma_m", "valid", "reason"):
        assert _bits(getattr(got, f)) == _bits(getattr(want, f))
    placed = (got.reason.reshape(-1)[at] == Reason.OK) & (
        points.reason.reshape(-1)[at] == Reason.INCIDENCE_UNKNOWN)
    assert placed.sum() >= 10
