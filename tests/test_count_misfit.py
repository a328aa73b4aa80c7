"""A line its members' counts contradict (counts.counts_contradicted): a convex corner
seen along its bisector near the range limit reads, at θ = 0, like a flat wall square on,
and the iteration settles on that line; the counts, read back from the line through the
sensor model, misfit it. docs/estimator.md, "A line its counts contradict"."""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from irring import pipeline
from irring.core import Points, Reason
from irring.estimation import estimate as est
from irring.estimation import counts as est_counts
from irring.estimation.calibration import Calibration
from irring.scenario import load_scenario

CAL = Calibration.nominal("gp2d12")


@pytest.mark.parametrize("dof, chi2", [(6, 22.458), (10, 29.588), (20, 45.315), (10, 18.307)])
def test_misfit_deviate_matches_chi2_quantiles(dof, chi2):
    # exact upper quantiles of χ² (0.999: z = 3.0902; 0.95 for 10 dof: z = 1.6449)
    exact = 1.6449 if chi2 == 18.307 else 3.0902
    assert abs(float(est_counts.counts_misfit_z(chi2, dof)) - exact) < 0.03


def _fan(hit_x, hit_y, counts):
    """Readings of one sensor at the origin, beams towards (hit_x, hit_y), as Points with
    their end points on the line x = the first hit's x (the line the iteration took)."""
    heading = np.arctan2(hit_y, hit_x)[:, None]
    shape = heading.shape
    d = np.hypot(hit_x, hit_y)[:, None]
    zeros = np.zeros(shape)
    pts = Points(x=(d * np.cos(heading)), y=(d * np.sin(heading)), d=d, theta=zeros,
                 origin_x=zeros, origin_y=zeros, heading=heading, sigma_m=zeros + 0.01,
                 iterations=np.ones(shape, dtype=int), valid=np.ones(shape, dtype=bool),
                 reason=np.zeros(shape, dtype=np.uint8), max_range_m=0.8)
    return pts, np.asarray(counts, dtype=float)[:, None]


def _wall_line(pts):
    """The least-squares line x = c through the end points (direction along +y)."""
    return np.array([math.pi / 2]), np.array([float(np.mean(pts.x))]), np.array([0.0])


def test_a_flat_wall_square_on_fits_its_counts_a_corner_tip_does_not():
    # two sensors' 24 readings over -11..12° (not symmetric about square on), 50 seeds
    phi = np.radians(np.linspace(-11.0, 12.0, 24))
    sig = CAL.sigma_counts()
    label = np.zeros((phi.size, 1), dtype=np.intp)
    vi = np.arange(phi.size)
    # a corner 0.50 m away along its bisector, faces at 45° to it: ranges and incidence
    # grow both ways from the tip, its counts fall from 455 to 340-351
    r = 0.50 * math.sin(math.radians(135)) / np.sin(math.radians(45) - np.abs(phi))
    corner_exact = CAL.counts(r, math.radians(45) + np.abs(phi))
    wall_exact = CAL.counts(0.61 / np.cos(phi), phi)      # a wall 0.61 m away square on
    walls = corners = 0
    for seed in range(50):
        rng = np.random.default_rng(seed)
        wall = wall_exact + rng.normal(0.0, sig, phi.size)
        pts, counts = _fan(np.full(phi.size, 0.61), 0.61 * np.tan(phi), wall)
        walls += est_counts.counts_contradicted(pts, label, vi, counts, CAL, *_wall_line(pts))[0]
        corner = corner_exact + rng.normal(0.0, sig, phi.size)
        d0 = CAL.distance(corner, 0.0)  # read at θ = 0: the V of a wall square on
        pts, counts = _fan(d0 * np.cos(phi), d0 * np.sin(phi), corner)
        corners += est_counts.counts_contradicted(pts, label, vi, counts, CAL, *_wall_line(pts))[0]
    assert walls == 0
    assert corners >= 48


def test_members_the_line_misfits_singly_are_left_out_of_the_test():
    # a wall whose line took two readings of a neighbouring face (each 6σ off): not
    # contradicted, but the same with the misfit spread over every member is
    phi = np.radians(np.linspace(-9.0, 14.0, 12))
    sig = CAL.sigma_counts()
    x = np.full(phi.size, 0.55)
    exact = CAL.counts(0.55 / np.cos(phi), phi)
    label = np.zeros((phi.size, 1), dtype=np.intp)
    vi = np.arange(phi.size)
    two = exact.copy()
    two[[0, 7]] -= 6.0 * sig
    pts, counts = _fan(x, x * np.tan(phi), two)
    assert not est_counts.counts_contradicted(pts, label, vi, counts, CAL, *_wall_line(pts))[0]
    spread = exact + np.where(np.arange(phi.size) % 2 == 0, 2.5, -2.5) * sig
    pts, counts = _fan(x, x * np.tan(phi), spread)
    assert est_counts.counts_contradicted(pts, label, vi, counts, CAL, *_wall_line(pts))[0]


def test_too_few_members_are_not_asked():
    phi = np.radians(np.linspace(-5.0, 8.0, est_counts.COUNTS_MIN_MEMBERS - 1))
    x = np.full(phi.size, 0.5)
    bad = (CAL.counts(0.5 / np.cos(phi), phi)
           + np.where(np.arange(phi.size) % 2 == 0, 3.0, -3.0) * CAL.sigma_counts())
    pts, counts = _fan(x, x * np.tan(phi), bad)
    label = np.zeros((phi.size, 1), dtype=np.intp)
    assert not est_counts.counts_contradicted(pts, label, np.arange(phi.size), counts, CAL,
                                              *_wall_line(pts))[0]


def test_t_room_convex_corner_along_its_bisector_is_not_read_as_a_wall():
    # the second pose looks at the corner (1.66, 0.90) along its bisector at 0.5-0.6 m: the
    # readings there settled on one line perpendicular to the beams, 40-117 mm behind the
    # corner, 2-10σ off; now each is placed at its own profile's θ or INCIDENCE_UNKNOWN
    run = pipeline.run(load_scenario("t_room"), progress=False)
    sw, p = run.sweeps[1], run.points[1]
    for sensor, steps in ((2, np.arange(14, 26)), (1, np.arange(46, 56))):
        hit = sw.truth.hit_point[steps, sensor]
        err = np.hypot(p.x[steps, sensor] - hit[:, 0], p.y[steps, sensor] - hit[:, 1])
        ok = p.valid[steps, sensor]
        assert ok.sum() >= 4
        assert np.all(err[ok] <= 1.5 * p.sigma_m[steps, sensor][ok])
        assert np.all(err[ok] < 0.05)
        assert np.all(p.reason[steps, sensor][~ok] == Reason.INCIDENCE_UNKNOWN)
        # the corner's faces are met at 41-53°: no valid reading there is read under 30°
        # but the tip's, left off the line at θ = 0 with its σ widened
        steep = p.theta[steps, sensor][ok] > math.radians(30)
        assert np.all(steep | (p.sigma_m[steps, sensor][ok] > 0.05))


def test_a_sweep_noisier_than_its_calibration_scales_the_test():
    # four walls at 0.42-0.61 m square on, 40 readings each, their counts 1.8× as noisy as
    # the calibration says (40 seeds): one such line alone is contradicted 32 times in 40;
    # in a sweep of four the lines' own median reduced χ² scales the noise and none is
    n, alone, together = 40, 0, 0
    phi = np.radians(np.linspace(-8.0, 13.0, n))
    alpha = np.full(4, math.pi / 2)
    label = np.repeat(np.arange(4), n)[:, None]
    for seed in range(40):
        rng = np.random.default_rng(seed)
        parts, counts = [], []
        for dist in (0.61, 0.42, 0.55, 0.48):
            counts.append(CAL.counts(dist / np.cos(phi), phi)
                          + rng.normal(0.0, 1.8 * CAL.sigma_counts(), n))
            parts.append(_fan(np.full(n, dist), dist * np.tan(phi), counts[-1])[0])
        pts = Points(**{f: np.concatenate([getattr(q, f) for q in parts]) for f in
                        ("x", "y", "d", "theta", "origin_x", "origin_y", "heading", "sigma_m",
                         "iterations", "valid", "reason")}, max_range_m=0.8)
        cx = np.array([float(np.mean(q.x)) for q in parts])
        together += est_counts.counts_contradicted(pts, label, np.arange(4 * n), np.concatenate(counts),
                                                   CAL, alpha, cx, np.zeros(4)).any()
        alone += est_counts.counts_contradicted(parts[0], np.zeros((n, 1), dtype=np.intp),
                                                np.arange(n), counts[0][:, None], CAL, alpha[:1],
                                                cx[:1], np.zeros(1))[0]
    assert together == 0
    assert alone >= 25


@functools.lru_cache(maxsize=1)
def _judged():
    """The arguments of every counts_contradicted question the numpy estimator asks on
    the bundled t_room, far_hexagon and l_room (seed 0) and big_room (seed 1)."""
    from irring.estimation import estimate_numpy
    states, original = [], est_counts.counts_contradicted

    def record(*args):
        states.append(args)
        return original(*args)

    est_numpy_judge = estimate_numpy.counts_contradicted
    estimate_numpy.counts_contradicted = record
    try:
        for name, seed in (("t_room", 0), ("far_hexagon", 0), ("l_room", 0), ("big_room", 1)):
            sc = load_scenario(name)
            cal = pipeline.scene_calibration(sc)[0]
            for sweep in pipeline.simulated(sc, seed=seed, progress=False)[0].sweeps:
                estimate_numpy.estimate_detail(sweep, cal)
    finally:
        estimate_numpy.counts_contradicted = est_numpy_judge
    return tuple(states)


_ANSWERS = {True: 0, False: 0}


@settings(max_examples=300, deadline=None)
@given(data=st.data(), gain=st.floats(0.7, 1.4), jitter=st.sampled_from([0.0, 0.02, 0.2]),
       spoil=st.sampled_from([None, "nan", "zero", "negative", "merge", "unlabel", "turn"]),
       noise=st.sampled_from([0.0, 3.0]))
def test_the_first_counts_question_kernel_agrees_with_its_numpy_statement(data, gain, jitter,
                                                                         spoil, noise):
    """``_lines.counts_misfit_any`` against ``_counts_asked(...) is not None`` on the
    questions the numpy estimator asked in four bundled rooms, with the counts scaled and
    jittered (lines then misfit), NaN, zero or negative counts, lines merged (one line's
    members on another), members taken off their lines, lines turned, a noisier
    calibration: the same answer, and counts_contradicted_compiled the same lines; both
    answers occur (checked by the test after this one)."""
    states = _judged()
    points, label, vi, counts, cal, alpha, cx, cy = states[
        data.draw(st.integers(0, len(states) - 1))]
    rng = np.random.default_rng(data.draw(st.integers(0, 2 ** 31 - 1)))
    counts = np.asarray(counts, dtype=float) * gain * (1.0 + jitter * rng.standard_normal(
        np.shape(counts)))
    label, alpha = label.copy(), np.array(alpha, dtype=float)
    pick = rng.random(counts.shape) < 0.1
    if spoil in ("nan", "zero", "negative"):
        counts[pick] = {"nan": np.nan, "zero": 0.0, "negative": -5.0}[spoil]
    elif spoil == "merge" and alpha.size > 1:
        label[label == 1] = 0
    elif spoil == "unlabel":
        label[pick] = -1
    elif spoil == "turn":
        alpha = alpha + rng.normal(0.0, 0.2, alpha.size)
    if noise:
        cal = dataclasses.replace(cal, noise_counts=noise)
    args = (points, label, vi, counts, cal, alpha, cx, cy)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        slow = est_counts._counts_asked(*args) is not None
        slow_lines = est_counts.counts_contradicted(*args)
    f = np.ascontiguousarray
    la0, b0 = cal._ab0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        fast = est._lines.counts_misfit_any(
            f(vi, dtype=np.intp), f(label, dtype=np.intp).reshape(-1),
            f(points.heading, dtype=float).reshape(-1),
            f(points.origin_x, dtype=float).reshape(-1),
            f(points.origin_y, dtype=float).reshape(-1), f(counts).reshape(-1), alpha,
            f(cx, dtype=float), f(cy, dtype=float), float(la0), float(b0),
            cal.sigma_counts(), est_counts.COUNTS_FLOOR_M, cal.theta_rad, cal._log_a, cal.b,
            math.cos(cal.max_incidence_rad), est_counts.COUNTS_MIN_MEMBERS, est_counts.COUNTS_SINGLE,
            est_counts.COUNTS_Z)
        fast_lines = est_counts.counts_contradicted_compiled(*args)
    assert fast == slow
    np.testing.assert_array_equal(fast_lines, slow_lines)
    _ANSWERS[bool(fast)] += 1


def test_the_first_counts_question_was_answered_both_ways():
    """Not vacuous: the agreement test above met lines that misfit and sweeps where none
    does (run after it, in this file's order)."""
    if sum(_ANSWERS.values()) == 0:
        pytest.skip("the agreement test did not run first")
    assert _ANSWERS[True] > 0 and _ANSWERS[False] > 0
