"""The compiled grid update (irring/maps/_traverse.pyx ``add_beams``) against its numpy oracle
(irring/maps/mapping_numpy.py), on grids and readings hypothesis draws: prior maps with
occupied blocks (where no-return beams stop), sharp and uncertain readings (the sharp ones
beside a farther or silent neighbour with the surface's depth), no-returns, other invalid
readings, cones, and any of the knobs this update has.

Tolerance: 2e-4 log-odds per cell. The kernel counts the cells well in front of a valid end
point as whole passes (the formula there differs from l_free by < 4e-5 and a hit's tail
< 1e-4) and uses Abramowitz & Stegun's erfc (to 2.5e-5); every other step is the same
arithmetic. Where a beam stops is decided on those values, so the same cells are changed.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from irring.core import Points, Reason
from irring.maps import _traverse, mapping_numpy
from irring.maps.mapping import MapperParams, OccupancyGrid

TOL = 2e-4


def drawn_readings(rng, n, box, *, max_range_m, cone):
    """Readings from emitters in and around ``box`` (m): valid ones of σ 1-80 mm (some NaN),
    no-returns (some with a reach), and out-of-range ones."""
    ox = rng.uniform(-0.03, box[0] + 0.03, n)
    oy = rng.uniform(-0.03, box[1] + 0.03, n)
    heading = rng.uniform(-np.pi, np.pi, n)
    kind = rng.choice([Reason.OK, Reason.NO_RETURN, Reason.OUT_OF_RANGE], n, p=[0.6, 0.3, 0.1])
    valid = kind == Reason.OK
    d = np.where(valid, rng.uniform(0.0, max_range_m, n), np.nan)
    sigma = np.exp(rng.uniform(math.log(0.001), math.log(0.08), n))
    sigma[rng.random(n) < 0.05] = np.nan
    # some silent beams explained by a surface: known free only to their reach
    reach = np.where(rng.random(n) < 0.3, rng.uniform(-0.02, 1.2 * max_range_m, n), np.nan)
    return Points(x=ox + d * np.cos(heading), y=oy + d * np.sin(heading), d=d,
                  theta=np.zeros(n), origin_x=ox, origin_y=oy, heading=heading, sigma_m=sigma,
                  iterations=np.ones(n, int), valid=valid, reason=kind.astype(np.uint8),
                  max_range_m=max_range_m, cone_half_angle_rad=math.radians(15) if cone else 0.0,
                  reach_m=reach)


def prior_map(rng, shape, params):
    """A clamped map: unknown, with free patches and occupied blocks (walls, boxes)."""
    lo = np.zeros(shape)
    ny, nx = shape
    for _ in range(rng.integers(0, 6)):
        y0, x0 = rng.integers(0, ny), rng.integers(0, nx)
        h, w = rng.integers(1, 6), rng.integers(1, 8)
        lo[y0:y0 + h, x0:x0 + w] = rng.choice([params.l_max, 2.5, 1.6, params.l_min, -1.5])
    return lo


@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 20), ny=st.integers(3, 35), nx=st.integers(3, 50),
       n=st.integers(0, 120), cone=st.booleans(),
       stop=st.sampled_from([1.7, 0.0, -2.0, math.inf]),
       lone=st.sampled_from([0.03, 0.008, math.inf]),
       free_sigmas=st.sampled_from([0.0, 1.5]),
       hold=st.sampled_from([0.005, 0.02, 0.0]),
       depth=st.sampled_from([1.25, 0.0, 3.0]), jump=st.sampled_from([5.0, 0.0, 20.0]),
       sensors=st.sampled_from([1, 3, 12]), ahead=st.sampled_from([0.0, 1.0, 0.4]),
       between=st.sampled_from([0.5, 0.0, 1.0]), gap=st.sampled_from([2, 1, 3]),
       ends=st.sampled_from([0.0, 1.0]))
def test_insert_agrees_with_the_numpy_oracle(seed, ny, nx, n, cone, stop, lone, free_sigmas,
                                             hold, depth, jump, sensors, ahead, between, gap,
                                             ends):
    rng = np.random.default_rng(seed)
    params = MapperParams(no_return_stop=stop, lone_sigma_m=lone, free_sigmas=free_sigmas,
                          hold_sigma_m=hold, hit_depth_cells=depth, edge_jump_cells=jump,
                          ahead_floor=ahead, between_steps=between, between_end_cells=gap,
                          stop_at_end_cells=ends)
    g = OccupancyGrid((0.013, -0.021), (ny, nx), 0.01, params)
    g.log_odds = prior_map(rng, (ny, nx), params)
    g.end_cells[...] = rng.random((ny, nx)) < 0.3      # end points of earlier batches
    ends_before = g.end_cells.astype(bool)
    pts = drawn_readings(rng, n, (nx * 0.01, ny * 0.01), max_range_m=0.3, cone=cone and n <= 30)
    if n % sensors == 0 and not cone:       # as a sweep: (steps, sensors), neighbours by step
        pts = Points(**{k: (v.reshape(-1, sensors) if isinstance(v, np.ndarray) else v)
                        for k, v in vars(pts).items()})
    want_ends = ends_before.copy()
    want = mapping_numpy.add(g.log_odds, pts, g.origin_xy_m, g.resolution_m, params,
                             params.l_min, params.l_max, ends=want_ends)
    before = g.log_odds.copy()
    g.insert(pts)
    np.testing.assert_allclose(g.log_odds, want, rtol=0, atol=TOL)
    np.testing.assert_array_equal(g.end_cells.astype(bool), want_ends)
    # the same cells change (a stop decided differently would change a run of cells)
    assert np.array_equal(np.abs(g.log_odds - before) > 1e-3, np.abs(want - before) > 1e-3)


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 20), ny=st.integers(3, 35), nx=st.integers(3, 50),
       sizes=st.lists(st.integers(0, 60), min_size=1, max_size=4),
       # (no stop a sum of the weights can equal: at −2.0 rounding, not the rule, decided
       # whether a cell stopped a beam)
       stop=st.sampled_from([1.7, 0.3, -2.3, math.inf]),
       depth=st.sampled_from([1.25, 0.0]), sensors=st.sampled_from([1, 3]),
       ends=st.sampled_from([0.0, 1.0]))
def test_a_run_agrees_with_the_oracle_and_its_silent_beams_with_any_order(seed, ny, nx, sizes,
                                                                          stop, depth, sensors,
                                                                          ends):
    """insert_run against mapping_numpy.add_run; and without clamps (where the order of
    returns matters) the same batches in reverse order give the same map: a silent beam
    stops at what any batch's returns established."""
    rng = np.random.default_rng(seed)
    batches = []
    for n in sizes:
        pts = drawn_readings(rng, n * sensors, (nx * 0.01, ny * 0.01), max_range_m=0.3,
                             cone=False)
        batches.append(Points(**{k: (v.reshape(-1, sensors) if isinstance(v, np.ndarray)
                                     else v) for k, v in vars(pts).items()}))
    params = MapperParams(no_return_stop=stop, hit_depth_cells=depth, stop_at_end_cells=ends)
    g = OccupancyGrid((0.013, -0.021), (ny, nx), 0.01, params)
    g.log_odds = prior_map(rng, (ny, nx), params)
    want = mapping_numpy.add_run(g.log_odds, batches, g.origin_xy_m, g.resolution_m, params,
                                 params.l_min, params.l_max)
    prior = g.log_odds.copy()
    g.insert_run(batches)
    np.testing.assert_allclose(g.log_odds, want, rtol=0, atol=TOL * len(batches))
    unclamped = dataclasses.replace(params, l_min=-1e9, l_max=1e9)
    forward, backward = (OccupancyGrid(g.origin_xy_m, g.shape, 0.01, unclamped)
                         for _ in range(2))
    forward.log_odds, backward.log_odds = prior.copy(), prior.copy()
    forward.insert_run(batches)
    backward.insert_run(batches[::-1])
    np.testing.assert_allclose(forward.log_odds, backward.log_odds, rtol=0, atol=1e-9)


def test_silent_beams_past_one_occupied_cell_stop_where_the_oracle_stops():
    """No-return beams fanned 0.1° apart past a single occupied cell (and a 2 × 3 block) of
    a 41 × 63 grid: the kernel counts the columns before any chunk that could stop a beam as
    runs and walks the rest; the cells changed are the oracle's, beam by beam (those that
    graze the cell's corner included), and 54 of the 900 stop there."""
    params = MapperParams()
    g = OccupancyGrid((-0.013, -0.021), (41, 63), 0.01, params)
    g.log_odds[23, 40] = params.l_max
    g.log_odds[8:10, 44:47] = params.l_max
    n = 900
    heading = np.radians(np.linspace(-45.0, 45.0, n)) + 0.013
    ox, oy = np.full(n, 0.031), np.full(n, 0.183)
    nan = np.full(n, np.nan)
    pts = Points(x=nan, y=nan, d=nan, theta=np.zeros(n), origin_x=ox, origin_y=oy,
                 heading=heading, sigma_m=nan, iterations=np.ones(n, int),
                 valid=np.zeros(n, bool), reason=np.full(n, Reason.NO_RETURN, np.uint8),
                 max_range_m=0.55)
    stopped = 0
    for i in range(n):
        one = Points(**{f: (v[i:i + 1] if isinstance(v, np.ndarray) else v)
                        for f, v in vars(pts).items()})
        want = mapping_numpy.add(g.log_odds, one, g.origin_xy_m, g.resolution_m, params,
                                 params.l_min, params.l_max)
        got = g.empty_like()
        got.log_odds = g.log_odds.copy()
        got.insert(one)
        np.testing.assert_array_equal(got.log_odds != g.log_odds, want != g.log_odds)
        np.testing.assert_allclose(got.log_odds, want, rtol=0, atol=1e-12)
        free = mapping_numpy.add(np.zeros(g.shape), one, g.origin_xy_m, g.resolution_m,
                                 params, params.l_min, params.l_max)
        stopped += int((want != g.log_odds).sum() < (free != 0).sum())
    assert stopped == 54


def test_the_grid_kernels_name_each_length_when_arrays_differ():
    """The segment walk indexes its arrays unchecked: different lengths are refused with
    every array's length named."""
    f = np.zeros
    with pytest.raises(ValueError, match=r"^segment arrays differ in length: x0 4, y0 4, "
                                         r"dx 3, dy 4$"):
        _traverse.walk(f(4), f(4), f(3), f(4), 10, 12)
    with pytest.raises(ValueError, match=r"segment arrays differ in length: x0 2, y0 2, "
                                         r"dx 2, dy 2, tx 2, ty 1$"):
        _traverse.first_material(f(2), f(2), f(2), f(2), f((12, 10), np.int16),
                                 f(2, np.intp), f(1, np.intp))
    with pytest.raises(ValueError, match=r"^the readings' arrays \(rows × cols = 6\) differ in "
                                         r"length: origin_x 6, origin_y 6, x 6, y 5, sigma_m 6, "
                                         r"valid 6$"):
        _traverse.neighbour_ranges(f(6), f(6), f(6), f(5), f(6), f(6, np.uint8), 3, 2,
                                   MapperParams())
