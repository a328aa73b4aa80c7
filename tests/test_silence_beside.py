"""Silent beams beside a return, and noise-level pooled readings past their line's end
(docs/estimator.md, "Silent beams beside a return" and "Pooled readings")."""
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
from irring.estimation import estimate as fast
from irring.estimation.calibration import scene_calibration
from irring.estimation.estimate import points_with
from irring.estimation.lines import LineOptions, Lines
from irring.estimation.silence import (beside_a_return, beside_a_return_compiled, end_hide_angle,
                                       noise_past_line_end)
from irring.scenario import loads

# a GP2Y0A02 (200 mm minimum range) 172-190 mm from a bench's end, which it grazes
BENCH_A02 = """\
name: bench_a02
seed: 16163
room: {outline_mm: [[0, 0], [2600, 0], [2600, 2000], [0, 2000]]}
robot: {poses: [{x_mm: 1969.8, y_mm: 1161.8, yaw_deg: -27}]}
sensor: {model: gp2y0a02, adc_bits: 12}
effects: {incidence: {}, noise: {sigma_v: 0.015}, quantization: {}}
obstacles: [{type: box, center_mm: [1300, 1000], size_mm: [1000, 280], yaw_deg: -8}]
"""

# a GP2Y0A21 read to its 800 mm curve end, 176 mm from a side wall, 693 mm from a corner
CORNER_A21 = """\
name: corner_a21
seed: 18120
room: {outline_mm: [[0, 0], [1821, 0], [1821, 1588], [0, 1588]]}
robot: {poses: [{x_mm: 176, y_mm: 693, yaw_deg: -33}]}
sensor: {model: gp2y0a21, adc_bits: 12, max_range_mm: 800}
effects: {incidence: {}, noise: {sigma_v: 0.015}, quantization: {}}
"""


@functools.cache
def _a21_cal():
    """CORNER_A21's calibration (frozen, so made once and shared: building it parses and
    checks the scene, most of a hypothesis example's time)."""
    return scene_calibration(loads(CORNER_A21))[0]


@functools.cache
def _a21_rising_cal():
    """_a21_cal with a linear hook's curve: d = a·S, more counts farther."""
    cal = _a21_cal()
    top = 2 ** cal.adc_bits - 1
    return dataclasses.replace(cal, a=np.full(cal.b.shape, cal.max_range_m / top),
                               b=np.ones(cal.b.shape))


def _column(reason, d, heading_deg, counts_max=0.0):
    """One sensor's readings, (S, 1): origin (0, 0), the given reasons, d and headings."""
    n = len(reason)
    reason = np.array(reason, np.uint8)[:, None]
    valid = reason == Reason.OK
    d = np.where(valid, np.array(d, float)[:, None], np.nan)
    h = np.radians(np.array(heading_deg, float))[:, None]
    z = np.zeros((n, 1))
    return Points(x=d * np.cos(h), y=d * np.sin(h), d=d, theta=np.where(valid, 0.0, np.nan),
                  origin_x=z, origin_y=z, heading=h, sigma_m=np.where(valid, 0.01, np.nan),
                  iterations=np.ones((n, 1), int), valid=valid, reason=reason, max_range_m=0.8)


def test_a_silent_beam_beside_a_return_is_free_only_to_where_a_face_turned_from_it_could_hide():
    """Steps 1°, one sensor: a line member at 0.5 m, three silent beams, a saturated reading
    (too near to place), then 42 silent beams. Each
    silent beam is known free to r·cos θ / cos(θ + γ) from its nearest return: r the
    member's d, the saturated reading's the far-branch distance of full scale at the
    drop-out angle; θ the drop-out angle less the margin (65°), γ the heading gap."""
    cal = _a21_cal()
    options = LineOptions()
    ok, nr, sat = Reason.OK, Reason.NO_RETURN, Reason.SATURATED
    reasons = [ok, nr, nr, nr, sat] + [nr] * 42
    p = _column(reasons, [0.5] + [np.nan] * 46, range(47))
    counts = np.full(p.valid.shape, 300.0)
    counts[0], counts[4] = 450.0, cal.full_scale_counts
    label = np.full(p.valid.shape, -1)
    label[0] = 3
    out = beside_a_return(p, counts, cal, options, label)
    theta = end_hide_angle(cal, options)
    assert theta == pytest.approx(math.radians(65.0))
    r_sat = float(cal.distance(cal.full_scale_counts, cal.max_incidence_rad))
    assert 0.02 < r_sat < 0.1                       # within the sensor's 0.1 m minimum range

    def stop(r, gap_deg):
        return r * math.cos(theta) / math.cos(theta + math.radians(gap_deg))
    reach = out.reach_m[:, 0]
    want = [min(stop(0.5, 1), stop(r_sat, 3)), min(stop(0.5, 2), stop(r_sat, 2)),
            min(stop(0.5, 3), stop(r_sat, 1)), stop(r_sat, 1), stop(r_sat, 2)]
    np.testing.assert_allclose(reach[[1, 2, 3, 5, 6]], want, rtol=1e-12)
    # 24° past the saturated reading: θ + γ = 89° still hides; 25° on: no limit
    assert reach[28] == pytest.approx(stop(r_sat, 24)) and np.isnan(reach[29:]).all()
    # the same member off any line: the nearest its counts allow at the drop-out angle
    off_line = beside_a_return(p, counts, cal, options, None)
    r_own = float(cal.distance(450.0, cal.max_incidence_rad))
    assert r_own < 0.5
    assert off_line.reach_m[1, 0] == pytest.approx(min(stop(r_own, 1), stop(r_sat, 3)))
    # a MISSING reading or a weak one (below the return level) is not a return
    weak = counts.copy()
    weak[4] = cal.no_return_counts + cal.return_margin_counts - 1.0
    r2 = np.array(p.reason)
    r2[4] = Reason.OUT_OF_RANGE
    q = beside_a_return(points_with(p, reason=r2), weak, cal, options, label)
    assert q.reach_m[5, 0] == pytest.approx(stop(0.5, 5))


_REASONS = np.array([Reason.OK, Reason.NO_RETURN, Reason.MISSING, Reason.SATURATED,
                     Reason.OUT_OF_RANGE, Reason.INCIDENCE_UNKNOWN], np.uint8)


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2 ** 31 - 1), steps=st.integers(0, 14), sensors=st.integers(1, 4),
       silent=st.floats(0.0, 1.0), nan_share=st.sampled_from([0.0, 0.1, 0.5]),
       labelled=st.booleans(), reached=st.booleans(), rising=st.booleans(),
       margin_deg=st.sampled_from([0.0, 20.0, 90.0]), tie=st.booleans())
def test_the_beside_kernel_agrees_with_its_numpy_statement(seed, steps, sensors, silent,
                                                          nan_share, labelled, reached, rising,
                                                          margin_deg, tie):
    """``_lines.beside_a_return`` (compiled) against :func:`beside_a_return` on random
    readings: any share silent (none, one reading, all), MISSING, saturated and unplaced
    readings, valid flags that disagree with the reasons, NaN in d, θ, counts and the reach
    already known, counts above full scale, headings wrapping past ±π (or all one heading:
    ties of the gap), with and without line labels, a falling curve and a rising one (linear
    hooks), the margin from none to past the drop-out angle: the same reach, bit for bit (NaN
    where the other has NaN), and the points themselves back where nothing is bounded."""
    rng = np.random.default_rng(seed)
    cal = _a21_rising_cal() if rising else _a21_cal()
    assert cal.falling != rising
    shape = (steps, sensors)
    reason = np.where(rng.random(shape) < silent, np.uint8(Reason.NO_RETURN),
                      rng.choice(_REASONS, shape)).astype(np.uint8)
    valid = np.where(rng.random(shape) < 0.9, reason == Reason.OK, rng.random(shape) < 0.5)
    d = rng.uniform(0.05, 1.0, shape)
    theta = np.where(rng.random(shape) < 0.5, 0.0, rng.uniform(0.0, 1.4, shape))
    heading = (np.full(shape, 3.1) if tie
               else rng.uniform(-math.pi, math.pi, (steps, 1)) + rng.uniform(-0.3, 0.3, shape))
    counts = rng.uniform(0.0, 1.2 * cal.full_scale_counts, shape)
    reach = rng.uniform(0.0, 1.0, shape) if reached else None
    for a in (d, theta, counts) + ((reach,) if reached else ()):
        a[rng.random(shape) < nan_share * 0.3] = np.nan
    z = np.zeros(shape)
    p = Points(x=z, y=z, d=d, theta=theta, origin_x=z, origin_y=z, heading=heading,
               sigma_m=z + 0.01, iterations=np.ones(shape, int), valid=valid, reason=reason,
               max_range_m=0.8, reach_m=reach)
    label = rng.integers(-1, 3, shape) if labelled else None
    options = LineOptions(incidence_margin_rad=math.radians(margin_deg))
    with np.errstate(invalid="ignore", divide="ignore"):
        slow = beside_a_return(p, counts, cal, options, label)
    fast = beside_a_return_compiled(p, counts, cal, options, label)
    assert (fast is p) == (slow is p)
    assert (fast.reach_m is None) == (slow.reach_m is None)
    if fast.reach_m is not None:
        assert fast.reach_m.tobytes() == slow.reach_m.tobytes()


def test_the_beside_kernel_bounds_beams_it_should():
    """Not vacuous: the kernel bounds the silent beams of the hand-made column above exactly
    as the statement does (most of them), and a column with no return bounds none."""
    cal = _a21_cal()
    ok, nr, sat = Reason.OK, Reason.NO_RETURN, Reason.SATURATED
    p = _column([ok, nr, nr, nr, sat] + [nr] * 42, [0.5] + [np.nan] * 46, range(47))
    counts = np.full(p.valid.shape, 300.0)
    counts[0], counts[4] = 450.0, cal.full_scale_counts
    fast = beside_a_return_compiled(p, counts, cal, LineOptions())
    slow = beside_a_return(p, counts, cal, LineOptions())
    assert np.isfinite(fast.reach_m).sum() == 27
    assert fast.reach_m.tobytes() == slow.reach_m.tobytes()
    quiet = _column([nr] * 5, [np.nan] * 5, range(5))
    assert beside_a_return_compiled(quiet, np.full((5, 1), 10.0), cal, LineOptions()) is quiet


def test_a_noise_level_member_past_its_lines_other_members_is_silent():
    """A line along x at y = 0.7 m: clear members at x 0.10-0.30 m, noise-level members
    (own counts at most the no-return level plus its margin: valid only by pooling) at
    x 0.20 (inside the others' extent: kept) and at 0.36 and 0.04 (past it: NO_RETURN); a
    weak member (counts above that margin) at 0.33 is kept and counts as clear, and a line
    of noise-level members alone is left as it is."""
    cal = _a21_cal()
    floor = cal.no_return_counts + cal.no_return_margin_counts
    xs = np.array([0.10, 0.15, 0.25, 0.30, 0.20, 0.36, 0.04, 0.33, 0.9, 1.0])
    ys = np.array([0.7] * 8 + [0.2, 0.3])
    raw = np.array([420, 430, 440, 410, floor, floor - 20, 330, floor + 1, 340, 345], float)
    n = xs.size
    o = np.zeros((n, 1))
    d = np.hypot(xs, ys)[:, None]
    p = Points(x=xs[:, None], y=ys[:, None], d=d, theta=o.copy(), origin_x=o, origin_y=o,
               heading=np.arctan2(ys, xs)[:, None], sigma_m=np.full((n, 1), 0.01),
               iterations=np.ones((n, 1), int), valid=np.ones((n, 1), bool),
               reason=np.zeros((n, 1), np.uint8), max_range_m=0.8)
    label = np.array([0] * 8 + [1, 1])[:, None]
    lines = Lines(label=label, centroid=np.array([[0.2, 0.7], [0.95, 0.25]]),
                  normal=np.array([[0.0, 1.0], [-0.7071, 0.7071]]),
                  direction=np.array([[1.0, 0.0], [0.7071, 0.7071]]),
                  n_points=np.array([8, 2]), length_m=np.array([0.36, 0.14]),
                  rms_m=np.zeros(2), usable=np.ones(2, bool), start=np.zeros(2, int),
                  end=np.zeros(2, int))
    out = noise_past_line_end(p, lines, raw[:, None], cal)
    gone = ~out.valid[:, 0]
    assert gone.nonzero()[0].tolist() == [5, 6]
    assert np.all(out.reason[gone] == Reason.NO_RETURN) and np.isnan(out.x[gone]).all()
    assert np.array_equal(out.x[~gone], p.x[~gone])


def _free_run_in_bench(p) -> tuple[int, float]:
    """(silent beams whose known-free run lies > 20 mm inside the bench, the longest, m)."""
    silent = p.reason == Reason.NO_RETURN
    reach = (np.full(silent.shape, p.max_range_m) if p.reach_m is None else
             np.fmin(np.nan_to_num(np.asarray(p.reach_m, float), nan=p.max_range_m),
                     p.max_range_m))
    t = np.arange(0.0, p.max_range_m, 0.005)
    x = p.origin_x[..., None] + t * np.cos(p.heading)[..., None] - 1.3
    y = p.origin_y[..., None] + t * np.sin(p.heading)[..., None] - 1.0
    a = math.radians(-8.0)
    u, v = x * math.cos(a) + y * math.sin(a), -x * math.sin(a) + y * math.cos(a)
    inside = (np.abs(u) < 0.5) & (np.abs(v) < 0.14) & (t <= reach[..., None])
    run = inside.sum(axis=-1) * 0.005
    return int((silent & (run > 0.02)).sum()), round(float(np.max(np.where(silent, run, 0))), 3)


def _datasheet_range(sweep, cal):
    """The estimate with the curve trusted from the datasheet's 200 mm, as a real ring's
    calibration trusts it (the scene's, which does not fold, reads on down to 82 mm)."""
    return fast.estimate(sweep, dataclasses.replace(cal, min_range_m=0.2))


def test_silent_beams_grazing_a_bench_beside_readings_too_near_to_place(monkeypatch):
    """BENCH_A02, seeds 16163-16165, read with the datasheet's range: beams grazing the
    bench's long face at 70-80° beside readings too near to place (SATURATED,
    FOLDOVER_AMBIGUOUS) or met at θ = 0 off any line were known free up to 990 mm through it
    (47-48 beams > 20 mm inside); beside a return they stop where a face turned from it
    could hide: 17 beams, at most 530 mm (a sensor whose silent beams are 40° from any
    return, which nothing bounds). With the scene's calibration the readings down to 82 mm
    are placed: 8-9 beams, at most 405 mm."""
    scene = loads(BENCH_A02)
    seeds = (16163, 16164, 16165)

    def runs(**kw):
        return [_free_run_in_bench(pipeline.run(scene, seed=s, progress=False, score=False,
                                                **kw).points[0]) for s in seeds]

    assert runs(estimator=_datasheet_range) == [(17, 0.53)] * 3
    assert runs() == [(9, 0.4), (8, 0.405), (8, 0.405)]
    monkeypatch.setattr(fast, "beside_a_return_compiled", lambda points, *a, **k: points)
    assert runs(estimator=_datasheet_range) == [(47, 0.99), (48, 0.99), (48, 0.99)]
    assert runs() == [(11, 0.4), (8, 0.405), (8, 0.405)]


def test_a_noise_level_reading_pooled_past_a_walls_last_return_is_not_placed(monkeypatch):
    """CORNER_A21, seed 18120: a beam met at 73.6°, its own counts (337) below the no-return
    level plus its margin, valid by pooling, was the last member of the wall's line, 81 mm
    past the others, 127 mm from its true hit. Now silent; of the 10 noise-level valid
    readings 7 are left, all within 100 mm of their hits."""
    scene = loads(CORNER_A21)
    cal = scene_calibration(scene)[0]

    def noise_level(seed):
        run = pipeline.run(scene, seed=seed, progress=False, score=False)
        sw, p = run.sweeps[0], run.points[0]
        t = sw.truth
        err = np.hypot(p.x - t.hit_point[..., 0], p.y - t.hit_point[..., 1])
        noise = p.valid & (np.asarray(sw.counts)
                           <= cal.no_return_counts + cal.no_return_margin_counts)
        return int(noise.sum()), int((noise & (err > 0.1)).sum())
    assert noise_level(18120) == (7, 0)
    monkeypatch.setattr(fast, "noise_past_line_end", lambda points, *a, **k: points)
    assert noise_level(18120) == (10, 1)
