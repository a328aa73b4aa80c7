"""The short far lines (far_lines.short_far_lines) and a reading read at its own profile's θ
(profiles.own_slope_read), compiled (``_lines.short_far_lines``, ``_lines.own_slope_reads``)
against their numpy statements: the same masks, distances, σ and flags, bit for bit, on the
states the fast estimator asked of them and on those states spoilt."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from irring import pipeline
from irring.estimation import estimate as fast
from irring.estimation import far_lines, profiles
from irring.estimation.calibration import scene_calibration
from irring.scenario import load_scenario

# bundled rooms whose sweeps (seed 0) have short far lines both doubted and loose, and
# members read at their own θ as they leave (scripts: none; counted when this was written)
SCENES = ("t_room", "posts", "far_hexagon")


@functools.lru_cache(maxsize=1)
def _asked():
    """(short far lines' states, own-θ reads' states) the fast estimator asked on SCENES."""
    short, own = [], []
    sfl, osr = far_lines.short_far_lines_compiled, profiles.own_slope_read_compiled

    def spy_short(*state):
        short.append(state)
        return sfl(*state)

    def spy_own(*state):
        own.append(state)
        return osr(*state)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(fast, "short_far_lines_compiled", spy_short)
        mp.setattr(profiles, "own_slope_read_compiled", spy_own)
        for name in SCENES:
            sc = load_scenario(name)
            cal, _ = scene_calibration(sc)
            for sweep in pipeline.simulated(sc, seed=0, progress=False)[0].sweeps:
                fast.estimate(sweep, cal)
    return short, own


def _spoiled_short(state, spoil, seed):
    """A state short_far_lines was asked, spoilt: readings moved (nearer or farther, so
    lines turn far or not), NaN, invalid, labels changed or dropped, σ and θ changed, the
    max range changed (which lines are far; loose asked or not where the calibration reads
    to its own range)."""
    points, label, index, cal = state
    rng = np.random.default_rng(seed)
    label = label.copy()
    pick = rng.random(label.shape) < rng.uniform(0.02, 0.4)
    if spoil == "scale":
        d = points.d * np.where(pick, rng.uniform(0.6, 1.6), 1.0)
        points = dataclasses.replace(points, d=d, x=points.origin_x + d * np.cos(points.heading),
                                     y=points.origin_y + d * np.sin(points.heading))
    elif spoil == "nan":
        points = dataclasses.replace(points, d=np.where(pick, np.nan, points.d),
                                     x=np.where(pick[::-1], np.nan, points.x))
    elif spoil == "invalid":
        points = dataclasses.replace(points, valid=points.valid & ~pick)
    elif spoil == "relabel":
        label = np.where(pick, rng.integers(-1, label.max() + 3, label.shape), label)
    elif spoil == "unlabel":
        label[pick] = -1
    elif spoil == "sigma":
        points = dataclasses.replace(
            points, sigma_m=points.sigma_m * np.where(pick, rng.uniform(0.0, 20.0), 1.0),
            theta=np.where(pick, rng.uniform(-1.6, 1.6, pick.shape), points.theta))
    elif spoil == "range":
        points = dataclasses.replace(points, max_range_m=float(
            points.max_range_m * rng.uniform(0.5, 2.0)))
    return points, label, index, cal


def _short_agrees(state) -> str:
    """Asserts the kernel gives the numpy statement's answer on ``state``; returns what it
    was: "none", "doubt" (doubted lines only) or "loose" (some loose line too)."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        slow = far_lines.short_far_lines(*state)
        now = far_lines.short_far_lines_compiled(*state)
    if slow is None:
        assert now is None
        return "none"
    assert now is not None
    for a, b in zip(now, slow):
        assert a.dtype == b.dtype == bool and a.shape == b.shape == (state[1].size,)
        np.testing.assert_array_equal(a, b)
    return "loose" if slow[1].any() else "doubt"


@settings(max_examples=150, deadline=None)
@given(data=st.data(), spoil=st.sampled_from([None, "scale", "nan", "invalid", "relabel",
                                               "unlabel", "sigma", "range"]))
def test_the_short_far_lines_kernel_agrees_with_its_numpy_statement(data, spoil):
    """``_lines.short_far_lines`` against ``far_lines.short_far_lines``, exactly (discrete:
    the doubted and the loose lines' members), on the states the fast estimator asked and
    on them spoilt (see :func:`_spoiled_short`)."""
    states = _asked()[0]
    _short_agrees(_spoiled_short(states[data.draw(st.integers(0, len(states) - 1))], spoil,
                                 data.draw(st.integers(0, 2 ** 31 - 1))))


def test_the_short_far_lines_kernel_found_none_doubted_and_loose():
    """Not vacuous: over the same states, spoilt in a fixed order, the kernel agrees where
    no line is short and far, where only doubted lines are, and where loose ones are too."""
    seen = {"none": 0, "doubt": 0, "loose": 0}
    for seed in range(20):
        for spoil in (None, "range", "unlabel"):
            for i, state in enumerate(_asked()[0]):
                seen[_short_agrees(_spoiled_short(state, spoil, 1000 * seed + i))] += 1
        if min(seen.values()) > 0:
            break
    assert min(seen.values()) > 0, seen


def _own_agrees(state) -> tuple[int, int]:
    """Asserts the kernel gives own_slope_read's d, σ and placed bit for bit (NaN where it
    has NaN); returns (readings placed, readings not)."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        slow = profiles.own_slope_read(*state)
        now = profiles.own_slope_read_compiled(*state)
    for a, b, what in zip(now, slow, ("d", "sigma", "placed")):
        assert a.dtype == b.dtype and a.shape == b.shape, what
        np.testing.assert_array_equal(a, b, err_msg=what)
    return int(slow[2].sum()), int((~slow[2]).sum())


@settings(max_examples=150, deadline=None)
@given(data=st.data(), spoil=st.sampled_from([None, "slope", "theta", "counts", "odd"]))
def test_the_own_slope_kernel_agrees_with_its_numpy_statement(data, spoil):
    """``_lines.own_slope_reads`` against ``profiles.own_slope_read``, bit for bit (d and σ
    to the last bit, placed exactly: the estimates stay as they were), on the readings the
    fast estimator asked and on them changed: slopes and their errors from flat to past the
    drop-out angle, θ negative or past the curve's table, counts from 1 to full scale, and
    NaN, ±inf and 0 among them."""
    states = _asked()[1]
    cal, s, theta, slope, se, sig_s = states[data.draw(st.integers(0, len(states) - 1))]
    rng = np.random.default_rng(data.draw(st.integers(0, 2 ** 31 - 1)))
    n = s.size
    if spoil == "slope":
        slope = rng.choice([-1.0, 1.0], n) * rng.uniform(0.0, 4.0, n)
        se = rng.uniform(0.0, 1.5, n)
    elif spoil == "theta":
        theta = rng.uniform(-0.5, 2.0, n)
    elif spoil == "counts":
        s = rng.uniform(1.0, 4095.0, n)
        sig_s = cal.sigma_counts() / s
    elif spoil == "odd":
        odd = np.array([np.nan, np.inf, -np.inf, 0.0, -0.0])
        slope, se, theta, s = (np.where(rng.random(n) < 0.3, rng.choice(odd, n), v)
                               for v in (slope, se, theta, s))
    _own_agrees((cal, s, theta, slope, se, sig_s))


def test_the_own_slope_kernel_placed_some_and_not_others():
    """Not vacuous: on the readings asked, and on them with steep slopes of large error
    (placed short of the min range or not at all), the kernel agrees where the reading is
    placed and where it is not."""
    placed = left = 0
    for cal, s, theta, slope, se, sig_s in _asked()[1]:
        p, q = _own_agrees((cal, s, theta, slope, se, sig_s))
        placed += p
        p, q = _own_agrees((cal, s * 40.0, theta, slope * 5.0, se + 1.0, sig_s))
        left += q
    assert placed > 0 and left > 0, (placed, left)


def test_the_kernels_name_what_they_refuse():
    lab, ok, one, two = (np.zeros(6, dtype=np.intp), np.ones(6, dtype=np.uint8), np.zeros(6),
                         np.zeros(4))
    with pytest.raises(ValueError, match=r"^short_far_lines' arrays differ in length: label 6, "
                                         r"valid 6, d 6, sigma 6, theta 4, x 6, y 6$"):
        far_lines._lines.short_far_lines(np.arange(6), ok, lab, one, one, two, one, one, 1.0,
                                         3, 25, 9, 0.07, True)
    with pytest.raises(IndexError, match=r"^index\[2\] = 6 is not a reading \(0 … 5\)$"):
        far_lines._lines.short_far_lines(np.array([0, 1, 6]), ok, lab, one, one, one, one,
                                         one, 1.0, 3, 25, 9, 0.07, True)
    nodes = np.array([0.0, 0.5, 1.0])
    with pytest.raises(ValueError, match=r"^own_slope_reads' arrays differ in length: s 6, "
                                         r"theta 6, slope 4, se 6, sig_s 6, xp 3"):
        profiles._lines.own_slope_reads(one, one, two, one, one, nodes, nodes, nodes, 1.2,
                                        0.1, 0.001)
    with pytest.raises(ValueError, match=r"^own_slope_reads: the calibration has no nodes$"):
        profiles._lines.own_slope_reads(one, one, one, one, one, np.zeros(0), np.zeros(0),
                                        np.zeros(0), 1.2, 0.1, 0.001)
