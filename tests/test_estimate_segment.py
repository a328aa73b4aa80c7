"""Line segmentation (split-and-merge, corners, TLS lines) of the compiled kernel
irring/estimation/_lines.pyx behind irring.estimation.lines.segment: edge cases, structural invariants of its
pieces on generated polylines, TLS lines against an independent eigen-decomposition, and
the tie-breaking it shares with the numpy code it replaced.

(Its answers equal the numpy code's bit for bit over every bundled scenario; that is
checked against recorded reference outputs, not here, since the numpy code is gone.)
"""

from __future__ import annotations

import array
import math
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from irring.estimation import _lines
from irring.estimation.lines import LineOptions, Pieces, segment

OPTS = LineOptions()
HARD = settings(max_examples=200, deadline=None, derandomize=not os.environ.get("IRRING_EXPLORE"),
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def seg(px, py, thr=0.01, sensor=None, prev=None, opts=OPTS):
    px, py = np.asarray(px, float), np.asarray(py, float)
    thr = np.broadcast_to(np.asarray(thr, float), px.shape).copy()
    sensor = np.zeros(px.size, np.intp) if sensor is None else np.asarray(sensor, np.intp)
    centre = (float(px.mean()), float(py.mean())) if px.size else (0.0, 0.0)
    return segment(px, py, thr, sensor, opts, centre, prev)


def test_no_points_give_no_pieces():
    """The numpy version raised IndexError here; the estimator can call it with no points
    when no live reading lies within 1.5× the sweep's range."""
    p = seg([], [])
    for name in ("starts", "ends", "brk", "owner", "n_points", "cx", "alpha", "usable"):
        assert getattr(p, name).size == 0, name
    assert p.starts.dtype == np.intp and p.owner.dtype == np.intp and p.usable.dtype == bool
    again = seg([], [], prev=p)
    assert again.starts.size == 0


def test_one_point_is_one_piece_that_gives_no_line():
    p = seg([0.3], [0.1])
    assert p.starts.tolist() == [0] and p.ends.tolist() == [0] and p.owner.tolist() == [0]
    assert p.brk.tolist() == [True] and p.n_points.tolist() == [1]
    assert (p.cx[0], p.cy[0]) == (0.3, 0.1) and p.lmax[0] == 0.0 and not p.usable[0]


def test_a_vertical_run_has_an_exact_direction():
    p = seg(np.full(20, 0.25), np.linspace(-0.2, 0.2, 20))
    assert p.starts.tolist() == [0] and p.usable[0]
    assert p.alpha[0] == math.pi / 2 and p.lmin[0] == 0.0


def test_polylines_break_at_gaps_and_sensor_changes():
    x = np.r_[np.linspace(0, 0.2, 10), np.linspace(0.5, 0.7, 10), np.linspace(0.7, 0.9, 10)]
    y = np.zeros(30)
    sensor = np.r_[np.zeros(20), np.ones(10)].astype(np.intp)
    p = seg(x, y, sensor=sensor)
    assert p.brk.nonzero()[0].tolist() == [0, 10, 20]      # 0.3 m gap, then a new sensor
    assert p.starts.tolist() == [0, 10, 20] and p.ends.tolist() == [9, 19, 29]


def test_equal_costs_put_the_corner_at_the_earlier_reading():
    """A mirror-symmetric corner on a dyadic grid: the corner fits equally well one reading
    either side of the middle, and like numpy's argmin the earlier place wins."""
    x = np.array([2.0, 0.0, 0.0, 0.0, -2.0]) / 256
    y = np.array([3.25, 2.25, 0.0, 2.25, 3.25]) / 256
    p = seg(x, y, thr=1 / 256)
    assert p.starts.tolist() == [0, 1] and p.ends.tolist() == [1, 4]


def test_regrouping_keeps_the_pieces_and_moves_corners_only():
    rng = np.random.default_rng(1)
    t = np.linspace(0, 0.3, 30)
    x = np.r_[t, np.full(29, 0.3)] + rng.normal(0, 1e-3, 59)
    y = np.r_[np.zeros(30), t[1:]] + rng.normal(0, 1e-3, 59)
    first = seg(x, y)
    assert first.starts.size == 2 and first.usable.all()
    # the same polylines at moved positions: the same pieces, corners refined
    again = seg(x + rng.normal(0, 2e-3, 59), y + rng.normal(0, 2e-3, 59), prev=first)
    assert again.starts.size == 2 and np.all(np.abs(again.ends[0] - first.ends[0]) <= 10)
    # different polylines: split afresh
    other = seg(np.r_[x[:30], x[30:] + 1.0], y, prev=first)
    assert other.brk.nonzero()[0].tolist() == [0, 30]


def test_a_regroup_splits_anew_only_the_polylines_a_range_jump_cuts():
    """Regrouping with polylines that changed (a range jump found at the straightened θ cuts
    one): the unchanged polyline keeps the earlier pieces (here a corner the points no
    longer show: split afresh it would be one piece), the cut one is split anew; the numpy
    oracle gives the same pieces."""
    from irring.estimation import estimate_numpy

    rng = np.random.default_rng(5)
    t = np.linspace(0.0, 0.3, 31)
    x = np.r_[t, 0.6 + 0.01 * np.arange(40)]
    y = np.r_[np.zeros(31), np.full(40, 0.5)] + rng.normal(0, 1e-4, 71)
    kinked = y.copy()
    kinked[15:31] += 0.5 * (t[15:] - t[15])          # sensor 0 bent at its reading 15
    sensor = np.r_[np.zeros(31, np.intp), np.ones(40, np.intp)]
    first = seg(x, kinked, sensor=sensor)
    assert first.starts.tolist() == [0, 15, 31]
    chains = np.r_[sensor[:51], np.full(20, 2, np.intp)]   # sensor 1 cut at its reading 20
    again = seg(x, y, sensor=chains, prev=first)
    assert again.brk.nonzero()[0].tolist() == [0, 31, 51]
    # the kept corner is refined (it may move by up to 5 readings), not dropped
    assert again.starts.size == 4 and 10 <= again.starts[1] <= 20
    assert again.starts[[0, 2, 3]].tolist() == [0, 31, 51]
    fresh = seg(x, y, sensor=chains)
    assert fresh.starts.tolist() == [0, 31, 51]
    thr = np.full(71, 0.01)
    oracle = estimate_numpy._segment(x, y, thr, chains, OPTS, (float(x.mean()), float(y.mean())),
                                     first)
    np.testing.assert_array_equal(oracle.starts, again.starts)
    np.testing.assert_array_equal(oracle.ends, again.ends)


def test_a_grouping_with_more_pieces_than_the_points_is_split_afresh():
    """The estimator regroups fewer points when some move out of range; an earlier grouping
    with more pieces than there are points now is of other polylines, not an error (the
    kernel raised ValueError here)."""
    t = np.arange(40)
    x, y = t * 0.02, np.where(t % 2, 0.05, 0.0)         # a zigzag: a piece per leg
    first = seg(x, y)
    assert first.starts.size > 5
    again = seg(x[:5], y[:5], prev=first)
    fresh = seg(x[:5], y[:5])
    for name in ("starts", "ends", "owner", "alpha", "usable"):
        np.testing.assert_array_equal(getattr(again, name), getattr(fresh, name))


@pytest.mark.parametrize("starts, ends", [([], []), ([5], [19]), ([0, 12], [12, 15]),
                                          ([0, 3, 3], [3, 3, 19]), ([0, 9], [10, 19])])
def test_previous_pieces_that_do_not_tile_the_points_are_refused(starts, ends):
    """Reused pieces must tile the points (from the first to the last, each starting on
    its predecessor's end or the reading after): the kernel reads and writes per-piece
    arrays through the owner of every reading, and pieces that leave a reading without one
    made it write out of bounds (a crash, or a corrupted heap)."""
    x, y = np.linspace(0, 0.4, 20), np.zeros(20)
    first = seg(x, y)
    bad = Pieces(**{**vars(first), "starts": np.array(starts, np.intp),
                     "ends": np.array(ends, np.intp)})
    with pytest.raises(ValueError, match="not pieces of these points"):
        seg(x, y, prev=bad)


def test_inputs_are_converted_once_and_checked_by_the_kernel():
    x = np.linspace(0, 0.3, 12)
    y = 0.2 * x
    ref = seg(x, y)
    p32 = segment(x.astype(np.float32).astype(float), y.astype(np.float32).astype(float),
                  np.full(12, 0.01), np.zeros(12, np.int32), OPTS, (0.15, 0.03))
    assert p32.starts.tolist() == ref.starts.tolist()
    with pytest.raises(TypeError):
        _lines.segment(x.astype(np.float32), y, np.full(12, 0.01), np.zeros(12, np.intp),
                       0.0225, 0.0, 0.0, None, None, None, 4.0, 3, 0.08, 3.0)
    with pytest.raises(TypeError):
        _lines.segment(x, y[:11], np.full(12, 0.01), np.zeros(12, np.intp),
                       0.0225, 0.0, 0.0, None, None, None, 4.0, 3, 0.08, 3.0)


def test_the_kernel_releases_every_buffer_it_took_on_every_path():
    """It takes its arrays' buffers by hand (PyObject_GetBuffer); an array.array cannot grow
    while one is held, so growing each afterwards shows it was released: after a result,
    after a reuse, and after each kind of error part-way through taking them."""
    def arr(values, code):
        return array.array(code, [v.item() for v in np.asarray(values)])

    def free(*arrays):
        for a in arrays:
            a.append(a[0])
            a.pop()
        return True

    k = 20
    x, y, thr = arr(np.linspace(0, 0.4, k), "d"), arr(np.zeros(k), "d"), arr(np.full(k, 0.01), "d")
    sensor = arr(np.zeros(k, np.intp), "q")
    args = (0.0225, 0.2, 0.0)
    tail = (4.0, 3, 0.08, 3.0)
    out = _lines.segment(x, y, thr, sensor, *args, None, None, None, *tail)
    assert free(x, y, thr, sensor)
    starts, ends, brk = arr(out[0], "q"), arr(out[1], "q"), out[2].copy()
    _lines.segment(x, y, thr, sensor, *args, starts, ends, brk, *tail)
    assert free(x, y, thr, sensor, starts, ends)
    with pytest.raises(TypeError):
        _lines.segment(x, y, thr, arr(np.zeros(k, np.intp), "i"), *args, None, None, None, *tail)
    assert free(x, y, thr)
    short = arr(out[1], "q")
    short[-1] -= 1
    with pytest.raises(ValueError):
        _lines.segment(x, y, thr, sensor, *args, starts, short, brk, *tail)
    assert free(x, y, thr, sensor, starts, short)
    with pytest.raises(TypeError):
        _lines.segment(x, y, thr, sensor, *args, starts, ends, brk.view(np.int8), *tail)
    assert free(x, y, thr, sensor, starts, ends)


@st.composite
def polylines(draw):
    """Runs of straight legs with corners, noise, repeated points, several sensors."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    pts, sensor = [], []
    for s in range(draw(st.integers(1, 3))):
        p = rng.uniform(-1, 1, 2)
        for _ in range(draw(st.integers(1, 4))):
            ang = draw(st.sampled_from([0.0, math.pi / 2, math.pi])) if rng.random() < 0.3 \
                else rng.uniform(0, 2 * math.pi)
            step = rng.choice([0.0, 0.005, 0.01, 0.02])
            for _ in range(draw(st.integers(1, 25))):
                p = p + step * np.array([math.cos(ang), math.sin(ang)])
                pts.append(p.copy())
                sensor.append(s)
    xy = np.array(pts) + rng.normal(0, draw(st.sampled_from([0.0, 1e-4, 3e-3])), (len(pts), 2))
    thr = np.maximum(0.01, rng.uniform(0, 0.02, len(pts)))
    return xy[:, 0].copy(), xy[:, 1].copy(), thr, np.array(sensor, np.intp)


@HARD
@given(polylines())
def test_pieces_tile_the_polylines_and_fit_tls_lines(case):
    x, y, thr, sensor = case
    k = x.size
    p = seg(x, y, thr, sensor)
    # polylines: a new one at a sensor change or a gap of more than gap_m
    gap = np.r_[True, (np.hypot(np.diff(x), np.diff(y)) > OPTS.gap_m) | (np.diff(sensor) != 0)]
    np.testing.assert_array_equal(p.brk, gap)
    # pieces tile each polyline in order, neighbours sharing their corner reading
    s, e = p.starts, p.ends
    assert s[0] == 0 and e[-1] == k - 1 and np.all(e >= s)
    nxt = s[1:]
    shared = nxt == e[:-1]
    assert np.all(shared | ((nxt == e[:-1] + 1) & p.brk[nxt]))
    assert not np.any(p.brk[nxt[shared]])
    # every reading joins one piece: its own, or at a shared corner the one before
    assert np.all(np.diff(p.owner) >= 0) and p.owner.min() == 0 and p.owner.max() < s.size
    inside = (s[p.owner] <= np.arange(k)) & (np.arange(k) <= e[p.owner])
    assert inside.all()
    np.testing.assert_array_equal(p.n_points, np.bincount(p.owner, minlength=s.size))
    # each piece's TLS line: centroid, variances across/along, direction in [0, π] (a
    # direction a hair below 0 lifted by π rounds to π)
    assert np.all((p.alpha >= 0) & (p.alpha <= math.pi))
    for j in range(s.size):
        px, py = x[s[j]:e[j] + 1], y[s[j]:e[j] + 1]
        scale = 1e-9 * (1 + np.abs(px).max() + np.abs(py).max())
        assert abs(p.cx[j] - px.mean()) < scale and abs(p.cy[j] - py.mean()) < scale
        lam, vec = np.linalg.eigh(np.cov(px, py, bias=True))
        np.testing.assert_allclose([p.lmin[j], p.lmax[j]], lam, atol=1e-12, rtol=1e-6)
        if lam[1] > 1e-10 and lam[1] - lam[0] > 1e-3 * lam[1]:
            along = vec[:, 1]
            assert abs(math.sin(math.atan2(along[1], along[0]) - p.alpha[j])) < 1e-5
    # a usable line has enough readings over enough length
    assert np.all(p.n_points[p.usable] >= OPTS.min_points)
    assert np.all(p.length_m[p.usable] >= OPTS.min_length_m)
