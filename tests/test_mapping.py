"""Occupancy grid: exact traversal on the hard cases, the inverse sensor model, PGM/YAML."""

from __future__ import annotations

import dataclasses
import math
from collections import Counter

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from irring.core import Points, Reason
from irring.maps import mapping_numpy
from irring.maps.mapping import (FREE, OCCUPIED, PGM_FREE, PGM_OCCUPIED, PGM_UNKNOWN, UNKNOWN,
                            MapperParams, OccupancyGrid, read_pgm, traverse)
from irring.scenario import load_scenario

from _synthetic import single_ray


def cells(*segment, shape=(6, 6), origin=(0.0, 0.0), res=1.0):
    v = traverse(*[np.array([c], float) for c in segment], origin, shape, res)
    return list(zip(v.ix.tolist(), v.iy.tolist()))


# --------------------------------------------------------------------------- traversal


def test_diagonal_through_corners_visits_only_the_diagonal():
    assert cells(1, 1, 4, 4) == [(1, 1), (2, 2), (3, 3)]
    assert cells(4, 4, 1, 1) == [(3, 3), (2, 2), (1, 1)]
    assert cells(0.5, 0.5, 3.5, 3.5) == [(0, 0), (1, 1), (2, 2), (3, 3)]


def test_ray_along_a_cell_border_belongs_to_the_cells_above_or_right():
    assert cells(0, 2, 5, 2) == [(0, 2), (1, 2), (2, 2), (3, 2), (4, 2)]
    assert cells(5, 2, 0, 2) == [(4, 2), (3, 2), (2, 2), (1, 2), (0, 2)]
    assert cells(3, 0.2, 3, 2.8) == [(3, 0), (3, 1), (3, 2)]
    # along the grid's top border: outside the (half-open) grid
    assert cells(1, 6, 4, 6) == []


def test_zero_length_ray_visits_its_one_cell():
    assert cells(2.3, 2.3, 2.3, 2.3) == [(2, 2)]
    assert cells(2, 2, 2, 2) == [(2, 2)]
    assert cells(9, 9, 9, 9) == []


def test_end_points_outside_the_grid_are_clipped():
    assert cells(-3, 2.5, 10, 2.5) == [(i, 2) for i in range(6)]
    assert cells(-3, -3, -1, -1) == []
    v = traverse(np.array([-3.0]), np.array([2.5]), np.array([10.0]), np.array([2.5]),
                 (0, 0), (6, 6), 1.0)
    assert v.t_enter[0] == pytest.approx(3 / 13) and v.t_exit[-1] == pytest.approx(9 / 13)


def test_non_finite_segments_have_no_visits_and_leave_the_others_alone():
    v = traverse(np.array([np.nan, 1.0, 1.0, 1e300, 0.5]), np.array([1.0, np.inf, 1.0, 1.0, 0.5]),
                 np.array([3.0, 3.0, np.nan, -1e300, 3.5]), np.array([1.0, 1.0, 1.0, 1.0, 0.5]),
                 (0, 0), (6, 6), 1.0)
    assert v.ray.tolist() == [4] * 4 and v.ix.tolist() == [0, 1, 2, 3]


def test_shallow_ray_steps_in_x_then_y():
    assert cells(0.5, 0.5, 3.5, 1.5) == [(0, 0), (1, 0), (2, 1), (3, 1)]


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(-3, 9, allow_nan=False).map(lambda v: round(v * 4) / 4), min_size=4,
                max_size=4) | st.lists(st.floats(-3, 9, allow_nan=False, allow_subnormal=False),
                                       min_size=4, max_size=4))
def test_traversal_matches_dense_sampling(seg):
    """Every cell a dense sample of the segment stays in for more than a point is visited,
    nothing else is, each once, in order, stepping to a neighbour (8-connected at corners)."""
    x0, y0, x1, y1 = seg
    v = traverse(*[np.array([c]) for c in seg], (0, 0), (6, 6), 1.0)
    got = list(zip(v.ix.tolist(), v.iy.tolist()))
    assert len(set(got)) == len(got)
    t = np.linspace(0, 1, 4001)
    x, y = x0 + t * (x1 - x0), y0 + t * (y1 - y0)
    inside = (x >= 0) & (x < 6) & (y >= 0) & (y < 6)
    seen = Counter(zip(np.floor(x[inside]).astype(int).tolist(),
                       np.floor(y[inside]).astype(int).tolist()))
    length = math.hypot(x1 - x0, y1 - y0)
    for cell, n in seen.items():
        if n > 1 or length == 0:
            assert cell in got
    for cell, t0, t1 in zip(got, v.t_enter, v.t_exit):
        assert t1 >= t0
        # long enough for the samples (t.size - 1 steps along the segment) to see it
        if length > 0 and (t1 - t0) * (t.size - 1) > 1.5:
            assert cell in seen
    if len(got) > 1:
        steps = np.abs(np.diff(np.array(got), axis=0))
        assert steps.max() <= 1
        assert np.all(np.diff(v.t_enter) > 0)


def _exact_cells(x0, y0, x1, y1, touch=1e-9):
    """The cells a segment crosses, in rational arithmetic (unit cells at the origin; pieces
    shorter than ``touch`` cells are corner touches)."""
    from fractions import Fraction as F

    gx0, gy0, dx, dy = F(x0), F(y0), F(x1) - F(x0), F(y1) - F(y0)
    ts = {F(0), F(1)}
    for g0, d in ((gx0, dx), (gy0, dy)):
        if d:
            lo, hi = sorted((g0, g0 + d))
            ts |= {(b - g0) / d for b in range(math.floor(lo), math.ceil(hi) + 1)
                   if 0 <= (b - g0) / d <= 1}
    ts = sorted(ts)
    length = math.hypot(float(dx), float(dy))
    out = []
    for a, b in zip(ts, ts[1:]):
        if float(b - a) * length >= touch:
            m = (a + b) / 2
            cell = (math.floor(gx0 + m * dx), math.floor(gy0 + m * dy))
            if 0 <= cell[0] < 6 and 0 <= cell[1] < 6 and (not out or out[-1] != cell):
                out.append(cell)
    return out


def test_traversal_is_exact_for_beams_along_cell_borders():
    """Headings at multiples of 45° carry rounding (cos 90° = 6e-17): a beam starting on a
    border drifts off it by 1e-16 cells. The cells must follow that drift exactly."""
    rng = np.random.default_rng(5)
    angle = np.radians(rng.integers(0, 8, 400) * 45.0)
    start = rng.integers(0, 7, (400, 2)) + rng.choice([0.0, 0.5], (400, 2))
    length = rng.choice([1.0, 2.5, 4.0, 4 * math.sqrt(2), 0.3], 400)
    end = start + length[:, None] * np.column_stack([np.cos(angle), np.sin(angle)])
    v = traverse(start[:, 0], start[:, 1], end[:, 0], end[:, 1], (0, 0), (6, 6), 1.0)
    for r in range(400):
        got = list(zip(v.ix[v.ray == r].tolist(), v.iy[v.ray == r].tolist()))
        assert got == _exact_cells(*start[r], *end[r]), (start[r], end[r])


def test_traversal_is_vectorised_over_rays():
    rng = np.random.default_rng(0)
    a = rng.uniform(-1, 7, (500, 4))
    v = traverse(a[:, 0], a[:, 1], a[:, 2], a[:, 3], (0, 0), (6, 6), 1.0)
    for r in (0, 17, 499):
        one = traverse(*[a[r:r + 1, i] for i in range(4)], (0, 0), (6, 6), 1.0)
        m = v.ray == r
        assert v.ix[m].tolist() == one.ix.tolist() and v.iy[m].tolist() == one.iy.tolist()


# --------------------------------------------------------------------------- grid updates


def small_grid(**params):
    return OccupancyGrid((0.0, 0.0), (40, 60), 0.01, MapperParams(**params))


def test_valid_reading_frees_its_ray_and_marks_its_end_point():
    g = small_grid()
    for _ in range(3):
        g.insert(single_ray(0.055, 0.205, 0.0, 0.40, sigma_m=0.005))
    cls = g.classify()
    ix, iy = g.cell_of(0.055 + 0.40, 0.205)
    assert cls[iy, ix] == OCCUPIED
    assert np.all(cls[iy, 5:ix - 2] == FREE)           # the beam's path, well in front
    assert np.all(cls[iy, ix + 3:] == UNKNOWN)          # beyond the tail: untouched
    assert np.all(cls[iy + 2:] == UNKNOWN) and np.all(cls[:iy - 1] == UNKNOWN)


def test_one_clean_pass_frees_and_a_hit_outweighs_a_pass():
    """The default numbers (module doc): one valid beam marks the cells it clearly crossed
    free; a cell holding an end point stays occupied after one beam passes through it and is
    not made free by two; a no-return beam is half a clean pass."""
    g = small_grid()
    g.insert(single_ray(0.055, 0.205, 0.0, 0.40, sigma_m=0.005))
    ix, iy = g.cell_of(0.455, 0.205)
    cls = g.classify()
    assert np.all(cls[iy, 6:ix - 2] == FREE) and cls[iy, ix] == OCCUPIED
    g.insert(single_ray(0.055, 0.205, 0.0, 0.55, sigma_m=0.005))     # passes through the hit
    assert g.classify()[iy, ix] == OCCUPIED
    g.insert(single_ray(0.055, 0.205, 0.0, 0.55, sigma_m=0.005))
    assert g.classify()[iy, ix] == UNKNOWN
    nr = small_grid()
    for expect in (UNKNOWN, FREE):
        nr.insert(single_ray(0.055, 0.205, 0.0, np.nan, valid=False, reason=Reason.NO_RETURN,
                             max_range_m=0.3))
        assert np.all(nr.classify()[20, 6:35] == expect)


def _batch(*rays):
    """One batch (a (1, n) sweep) of single_ray readings."""
    return type(rays[0])(**{k: (np.concatenate([getattr(r, k) for r in rays], axis=1)
                                if isinstance(v, np.ndarray) else v)
                            for k, v in vars(rays[0]).items()})


def test_a_sharp_end_point_is_not_freed_by_passes_of_its_own_sweep():
    """A leg's edge cell: one sharp reading ends in it, three beams of the same sweep pass
    through it (grazing the silhouette). The hit holds (the passes show only part of the cell
    free); the same passes in a later sweep do clear it, and a fuzzy hit (σ 12 mm) is
    not held."""
    hit = single_ray(0.055, 0.205, 0.0, 0.403, sigma_m=0.001)
    passes = [single_ray(0.055, 0.207 - 0.003 * k, 0.0, 0.55, sigma_m=0.001) for k in range(3)]
    nr = single_ray(0.055, 0.203, 0.0, np.nan, valid=False, reason=Reason.NO_RETURN)
    ix, iy = small_grid().cell_of(0.458, 0.205)
    g = small_grid()
    g.insert(_batch(hit, *passes, nr))
    assert g.log_odds[iy, ix] == pytest.approx(g.params.l_occ, abs=1e-3)
    assert g.classify()[iy, ix] == OCCUPIED
    assert g.log_odds[iy, ix + 3] < 0                     # cells the passes cross elsewhere: freed
    later = small_grid()
    later.insert(hit)
    later.insert(_batch(*passes, nr))
    assert later.classify()[iy, ix] == FREE
    fuzzy = small_grid()
    fuzzy.insert(_batch(single_ray(0.055, 0.205, 0.0, 0.403, sigma_m=0.012), *passes))
    assert fuzzy.classify()[iy, ix] != OCCUPIED
    off = small_grid(hold_sigma_m=0.0)
    off.insert(_batch(hit, *passes, nr))
    assert off.classify()[iy, ix] == FREE


def _steps(*rays):
    """One sensor's readings at successive steps of a sweep ((n, 1) Points) from single_ray."""
    return type(rays[0])(**{k: (np.concatenate([getattr(r, k) for r in rays], axis=0)
                                if isinstance(v, np.ndarray) else v)
                            for k, v in vars(rays[0]).items()})


def test_a_sharp_hit_on_an_occluding_edge_gets_the_surfaces_depth():
    """One sensor's steps along row 20: sharp hits at 0.403 m (end point x = 0.458, cell 45),
    then the beam passes the object (nothing comes back). The last hit is on an occluding
    edge: the cells its beam enters within 1.25 cells behind the end point (46, 47) get
    l_occ_min, and no more. So does a hit right after the silence, or 60 mm nearer than the
    next step's; none a hit whose neighbours read within 50 mm, a fuzzy edge hit (σ 12 mm),
    or any with hit_depth_cells = 0. The depth stops no silent beam of its sweep, though two
    hits' depths hold 3.2 > no_return_stop."""
    def hit(d=0.403, sigma_m=0.002):
        return single_ray(0.055, 0.205, 0.0, d, sigma_m=sigma_m)

    gone = single_ray(0.055, 0.205, 0.0, np.nan, valid=False, reason=Reason.NO_RETURN)
    p = small_grid().params
    steps = _steps(hit(), hit(), gone, hit(), hit(0.443), hit(0.503))
    depths = mapping_numpy.hit_depths(steps, p, 0.01)
    assert (depths[:, 0] * 1e3).tolist() == pytest.approx([0.0, 12.5, 0.0, 12.5, 12.5, 0.0])
    g = small_grid()
    g.insert(_steps(hit(), hit()))
    assert np.count_nonzero(g.log_odds[20, 46:]) == 0
    g = small_grid()
    g.insert(_steps(hit(), hit(), gone))
    assert g.log_odds[20, 45] == p.l_max
    assert g.log_odds[20, 46:48] == pytest.approx([p.l_occ_min] * 2, abs=1e-12)
    assert np.count_nonzero(g.log_odds[20, 48:]) == 0
    assert g.classify()[20, 46] == OCCUPIED
    fuzzy = small_grid()
    fuzzy.insert(_steps(hit(), hit(sigma_m=0.012), gone))
    off = small_grid(hit_depth_cells=0.0)
    off.insert(_steps(hit(), hit(), gone))
    assert fuzzy.log_odds[20, 47] == 0.0 and np.count_nonzero(off.log_odds[20, 46:]) == 0
    # a silent beam of the same sweep up column 46, through both hits' depth
    up = single_ray(0.465, 0.055, math.pi / 2, np.nan, valid=False, reason=Reason.NO_RETURN)
    g = small_grid()
    g.insert(_steps(hit(), gone, hit(), up))
    assert g.log_odds[20, 46] == pytest.approx(2 * p.l_occ_min + p.l_no_return, abs=1e-12)
    assert np.all(g.log_odds[21:, 46] == p.l_no_return)


def test_ideal_sensor_keeps_the_table_legs_edge_cells():
    """The ideal sensor's exact end points on the T-room's table legs map their edge cells
    (they were freed by the beams grazing the legs: recall 0.989 and 0.995, below the noisy
    sensor's), and it is no worse than the noisy sensor on any score."""
    from irring import pipeline
    from irring.studies.rooms import ideal

    for name, want in (("t_room_cylinder", 0.995), ("t_room_three_cylinders", 0.999)):
        sc = load_scenario(name)
        clean = pipeline.run(ideal(sc), progress=False).scores
        noisy = pipeline.run(sc, progress=False).scores
        assert clean["occupied_recall"] >= want, (name, clean)
        for k, v in noisy.items():
            if v is not None:
                assert clean[k] >= v - 1e-9, (name, k, clean[k], v)


# One pose, one 30 mm post up and to the right of it in a room of our own (not square to it).
THIN_POST_ROOM = """\
name: thin_post
seed: 3
room:
  outline_mm: [[0, 0], [1130, 0], [1130, 970], [0, 970]]
obstacles:
  - {type: cylinder, center_mm: [700, 610], radius_mm: 30}
robot:
  design: rotating12
  poses:
    - {x_mm: 430, y_mm: 370}
sensor: {model: gp2d12, max_range_mm: 624, adc_bits: 12}
effects: [incidence, noise, quantization]
"""


def test_ideal_sensor_maps_a_thin_posts_flanks():
    """The ideal sensor's beams meet the post's flanks at 60-70° only every 15-25 mm of
    surface. The post has 9 cells a beam can meet from the side they face (11 when the
    truth let beams see the back of the flank through the post: those 2, 2 cells from any
    hit, were the ideal map's misses). With and without the depth at the occluding edge
    every visible post cell has an occupied cell beside it, nothing is marked off the
    post, and the ideal map is no worse than the noisy one."""
    from irring import pipeline
    from irring.maps import metrics
    from irring.scenario import loads
    from irring.studies.rooms import ideal

    sc = loads(THIN_POST_ROOM, "thin_post.yaml")
    missed = {}
    for depth in (0.0, MapperParams().hit_depth_cells):
        run = pipeline.run(ideal(sc), progress=False, params=MapperParams(hit_depth_cells=depth))
        truth = metrics.ground_truth(sc, run.grid)
        post = truth.visible & (truth.surface_owner == metrics.OBSTACLE0)
        assert int(post.sum()) == 9
        lost = post & ~metrics._dilate(run.grid.classify() == OCCUPIED)
        missed[depth] = sorted((int(x), int(y)) for y, x in zip(*np.nonzero(lost)))
        assert run.scores["occupied_precision"] == 1.0
    assert missed == {0.0: [], 1.25: []}
    noisy = pipeline.run(sc, progress=False).scores
    for k, v in noisy.items():
        if v is not None:
            assert run.scores[k] >= v - 1e-9, (k, run.scores[k], v)


def test_gaussian_spread_follows_sigma():
    """A fuzzier reading spreads its occupied evidence over more cells (paper §IV; followed
    2σ into the surface to see it) and adds less to its end cell: l_occ up to occ_sigma_m
    (5 mm), l_occ·5 mm/σ beyond, never less than l_occ_min up to lone_sigma_m (30 mm),
    l_occ_min·30 mm/σ beyond."""
    grids = {s: small_grid(tail_sigmas=2.0) for s in (0.003, 0.006, 0.02, 0.04)}
    for sigma, g in grids.items():
        g.insert(single_ray(0.055, 0.205, 0.0, 0.4049, sigma_m=sigma))
    ix, iy = grids[0.003].cell_of(0.4599, 0.205)
    end = {s: g.log_odds[iy, ix] for s, g in grids.items()}
    p = grids[0.003].params
    assert end[0.003] == pytest.approx(p.l_occ, abs=1e-3)
    assert end[0.006] == pytest.approx(p.l_occ * 0.005 / 0.006, abs=1e-3)     # 2.08
    assert end[0.02] == pytest.approx(p.l_occ_min, abs=1e-3)                  # not 0.62
    assert end[0.04] == pytest.approx(p.l_occ_min * 0.03 / 0.04, abs=1e-3)    # 1.2
    spread = [(g.log_odds > 0).sum() for g in grids.values()]
    assert spread[0] < spread[1] < spread[2] < spread[3]


def test_no_return_frees_up_to_max_range_and_marks_nothing():
    g = small_grid()
    g.insert(single_ray(0.055, 0.205, 0.0, np.nan, valid=False, reason=Reason.NO_RETURN,
                        max_range_m=0.3))
    touched = np.nonzero(g.log_odds[20])[0]
    assert g.log_odds.max() == 0.0
    assert touched.min() == 5 and touched.max() == 35      # 0.055 m … 0.355 m
    assert np.count_nonzero(g.log_odds) == len(touched)


@pytest.mark.parametrize("reach, last", [(0.17, 22), (np.nan, 35), (0.5, 35), (0.0, None),
                                         (-0.1, None)])
def test_no_return_frees_only_up_to_its_reach(reach, last):
    """A silent beam a surface explains (``Points.reach_m``) frees cells only up to its
    reach (0.055 + 0.17 m: the cell at 0.2249 m is column 22); a reach beyond the max range
    or NaN leaves the max range, and one ≤ 0 maps nothing."""
    g = small_grid()
    p = single_ray(0.055, 0.205, 0.0, np.nan, valid=False, reason=Reason.NO_RETURN,
                   max_range_m=0.3)
    g.insert(dataclasses.replace(p, reach_m=np.array([[reach]])))
    touched = np.nonzero(g.log_odds[20])[0]
    assert g.log_odds.max() == 0.0
    if last is None:
        assert touched.size == 0
    else:
        assert touched.min() == 5 and touched.max() == last
        np.testing.assert_allclose(g.log_odds[20, touched], g.params.l_no_return)
    assert np.count_nonzero(g.log_odds) == len(touched)


def test_no_return_stops_at_the_first_cell_the_map_holds_occupied():
    """A no-return beam frees the cells before the first cell above no_return_stop (1.7: a
    sharp hit, not a lone uncertain one) and nothing from there on: a surface at grazing
    incidence returns nothing, and the beam must not carve through it."""
    nr = single_ray(0.055, 0.205, 0.0, np.nan, valid=False, reason=Reason.NO_RETURN,
                    max_range_m=0.3)
    for prior, cleared in ((2.5, 20), (1.6, 31), (-1.0, 31)):
        g = small_grid()
        g.log_odds[20, 25] = prior                          # x 0.25-0.26 m
        g.insert(nr)
        changed = np.flatnonzero(g.log_odds[20] != np.where(np.arange(60) == 25, prior, 0.0))
        assert len(changed) == cleared, (prior, changed)   # columns 5-24, or 5-35 through it
        assert np.all(g.log_odds[20, changed] == pytest.approx(
            np.where(changed == 25, prior, 0.0) + g.params.l_no_return))
    through = small_grid(no_return_stop=math.inf)
    through.log_odds[20, 25] = 4.0
    through.insert(nr)
    assert np.count_nonzero(through.log_odds[20] < 0) == 30 and through.log_odds[20, 25] == 3.25


def test_no_return_grazing_a_box_seen_in_the_same_sweep_leaves_the_box_alone():
    """Sharp readings of one sweep mark a box's face (x = 0.30 m); a no-return beam of the
    same sweep crosses that face into the box: it frees the cells in front of the face (the
    exact cells traverse() lists before it) and none inside; without the stop it would free
    a streak inside the box."""
    box = (slice(10, 30), slice(30, 51))                     # y 0.10-0.30, x 0.30-0.51 m
    hits = [single_ray(0.055, 0.105 + 0.01 * k, 0.0, 0.25, sigma_m=0.003) for k in range(20)]
    heading = math.atan2(0.12, 0.40)                          # from (0.055, 0.055): 17° up
    nr = single_ray(0.055, 0.055, heading, np.nan, valid=False, reason=Reason.NO_RETURN)
    sweep = _batch(*hits, nr)
    g, through = small_grid(), small_grid(no_return_stop=math.inf)
    for grid in (g, through):
        grid.insert(sweep)
    assert np.all(g.log_odds[box][:, 1:] == 0.0)              # the box behind its face column
    assert (through.log_odds[box][:, 1:] < 0).sum() >= 15
    # where they differ: the beam's cells from the face on, l_no_return each (none in the
    # face's cells that hold a sharp end point)
    reach = 0.055 + nr.max_range_m * np.array([math.cos(heading), math.sin(heading)])
    v = traverse([0.055], [0.055], [reach[0]], [reach[1]], g.origin_xy_m, g.shape, 0.01)
    first = np.flatnonzero(g.log_odds[v.iy, v.ix] > g.params.no_return_stop)[0]
    assert v.ix[first] == 30 and 10 <= v.iy[first] < 30      # it stopped at the face
    beyond = {(y, x) for y, x in zip(v.iy[first:].tolist(), v.ix[first:].tolist()) if x != 30}
    diff = through.log_odds - g.log_odds
    assert {(int(y), int(x)) for y, x in zip(*np.nonzero(diff))} == beyond
    assert np.all(diff[np.nonzero(diff)] == pytest.approx(g.params.l_no_return))


def test_exact_cells_cleared_and_marked_for_a_known_beam():
    """One beam along row 20 from x = 0.055 m to an end point at 0.455 m (cell 45): with
    σ 5 mm columns 5-43 turn free (cell 43 ends 1σ before the free margin: −1.5·Φ(2) + a
    hit tail of 0.03 = −1.44 < −1.41) and 44-45 occupied (44 ends 1σ before the end point:
    2.5·e^−½ = 1.52); with σ 40 mm (a θ = 0 fallback's) the reading weighs 30/40 of one:
    the cells well in front get exactly −1.125, none turns free, and the end cell gets
    1.6·0.75 = 1.2."""
    sharp = small_grid()
    sharp.insert(single_ray(0.055, 0.205, 0.0, 0.40, sigma_m=0.005))
    cls = sharp.classify()[20]
    assert np.flatnonzero(cls == FREE).tolist() == list(range(5, 44))
    assert np.flatnonzero(cls == OCCUPIED).tolist() == [44, 45]
    assert np.count_nonzero(sharp.log_odds) == 41
    vague = small_grid()
    vague.insert(single_ray(0.055, 0.205, 0.0, 0.40, sigma_m=0.04))
    assert np.all(vague.classify() != FREE)
    assert vague.log_odds[20, 5:20] == pytest.approx(np.full(15, -1.5 * 0.75), abs=1e-4)
    assert vague.log_odds[20, 45] == pytest.approx(1.6 * 0.75, abs=1e-4)
    twice = small_grid()
    for _ in range(2):
        twice.insert(single_ray(0.055, 0.205, 0.0, 0.40, sigma_m=0.04))
    assert np.all(twice.classify()[20, 5:25] == FREE)        # two agreeing ones do clear


def test_a_vague_reading_past_a_box_face_frees_no_cell_inside_the_box():
    """A reading that overshoots a box face by 100 mm with σ 40 mm (a θ = 0 fallback at
    65°, as in a kitchen's island seen from the side): the box's cells on its beam get at most 0.75 of a pass and are
    not freed, though the map knew nothing of the box; the same end point claimed with
    σ 10 mm frees 7 of the 10 cells between the face and it (the σ is what the mapper
    trusts)."""
    face_x = 0.30
    for sigma, freed_inside in ((0.04, 0), (0.01, 7)):
        g = small_grid()
        g.insert(single_ray(0.055, 0.205, 0.0, face_x - 0.055 + 0.10, sigma_m=sigma))
        ix_face = g.cell_of(face_x, 0.205)[0]
        inside = g.classify()[20, ix_face:]
        assert np.count_nonzero(inside == FREE) == freed_inside, sigma


@pytest.mark.parametrize("reason", [Reason.OUT_OF_RANGE, Reason.FOLDOVER_AMBIGUOUS,
                                    Reason.SATURATED, Reason.NOT_CONVERGED, Reason.MISSING])
def test_other_invalid_readings_change_nothing(reason):
    g = small_grid()
    g.insert(single_ray(0.055, 0.205, 0.0, 0.3, valid=False, reason=reason))
    assert not g.log_odds.any()


def test_end_point_outside_the_grid_frees_inside_and_marks_nothing_outside():
    g = small_grid()
    g.insert(single_ray(0.055, 0.205, 0.0, 2.0, sigma_m=0.005))
    assert np.all(g.log_odds[20, 6:] < 0) and g.log_odds.max() == 0.0


def test_slanted_beam_leaving_the_grid_frees_only_the_cells_inside():
    """A valid beam whose end point lies beyond the grid: everything inside is in front of
    it (free evidence, walked as runs), and the runs stop at the grid's edge."""
    g = small_grid()
    pts = single_ray(0.105, 0.105, math.radians(35), 0.9, sigma_m=0.005)
    g.insert(pts)
    want = np.clip(reference_delta(g, pts), g.params.l_min, g.params.l_max)
    np.testing.assert_allclose(g.log_odds, want, atol=2e-4)
    assert g.log_odds.max() == 0.0 and (g.log_odds < 0).sum() >= 40


def test_zero_length_reading_marks_its_cell():
    g = small_grid()
    g.insert(single_ray(0.105, 0.105, 0.3, 0.0, sigma_m=0.002))
    assert g.classify()[10, 10] == OCCUPIED


def test_log_odds_saturate_at_the_clamps():
    g = small_grid(l_min=-2.0, l_max=3.0)
    for _ in range(50):
        g.insert(single_ray(0.055, 0.205, 0.0, 0.40, sigma_m=0.005))
    assert g.log_odds.max() == 3.0 and g.log_odds.min() == -2.0
    # a clamped cell still turns after enough contrary evidence: the map stays responsive
    for _ in range(10):
        g.insert(single_ray(0.055, 0.205, 0.0, 0.55, sigma_m=0.005))
    ix, iy = g.cell_of(0.455, 0.205)
    assert g.classify()[iy, ix] == FREE


def test_batch_insert_is_order_independent_and_deterministic():
    sc = load_scenario("t_room")
    from _synthetic import points_for_pose

    p = points_for_pose(sc, 0, sigma_m="gp2", rng=np.random.default_rng(3))
    a, b = OccupancyGrid.for_scenario(sc), OccupancyGrid.for_scenario(sc)
    a.insert(p)
    flipped = type(p)(**{k: (v[::-1, ::-1] if isinstance(v, np.ndarray) else v)
                         for k, v in vars(p).items()})
    b.insert(flipped)
    np.testing.assert_allclose(a.log_odds, b.log_odds, atol=1e-12)


def reference_delta(grid, points):
    """The documented inverse sensor model on a zero grid, unclamped: the numpy oracle
    (irring/maps/mapping_numpy.py), visit by visit on :func:`traverse`."""
    return mapping_numpy.add(np.zeros(grid.shape), points, grid.origin_xy_m, grid.resolution_m,
                             grid.params)


def random_points(rng, n, *, box=(0.6, 0.4), max_range_m=0.3):
    """Readings from random emitters: valid end points (some beyond the grid), no-returns,
    and other invalid readings."""
    ox, oy = rng.uniform(-0.05, box[0] + 0.05, n), rng.uniform(-0.05, box[1] + 0.05, n)
    heading = rng.uniform(-np.pi, np.pi, n)
    d = rng.uniform(0.0, max_range_m, n)
    kind = rng.choice([Reason.OK, Reason.NO_RETURN, Reason.OUT_OF_RANGE], n, p=[0.7, 0.2, 0.1])
    valid = kind == Reason.OK
    dd = np.where(valid, d, np.nan)
    # σ: mostly drawn, some NaN (not given), +inf (unknown: no evidence) and −inf (floored)
    pick = rng.random(n)
    sigma = np.where(pick < 0.1, np.nan, rng.uniform(0.001, 0.03, n))
    sigma = np.where(pick > 0.96, np.inf, np.where(pick > 0.94, -np.inf, sigma))
    # some silent beams explained by a surface: known free only to their reach
    reach = np.where(rng.random(n) < 0.5, rng.uniform(-0.02, 1.2 * max_range_m, n), np.nan)
    return Points(x=ox + dd * np.cos(heading), y=oy + dd * np.sin(heading), d=dd,
                  theta=np.zeros(n), origin_x=ox, origin_y=oy, heading=heading, sigma_m=sigma,
                  iterations=np.ones(n, int), valid=valid, reason=kind.astype(np.uint8),
                  max_range_m=max_range_m, reach_m=reach)


@pytest.mark.parametrize("params", [{}, {"l_no_return": -0.3, "tail_sigmas": 3.0},
                                    {"free_margin_cells": 0.0, "min_sigma_m": 0.002},
                                    {"occ_sigma_m": 0.012, "l_occ_min": 0.0, "tail_sigmas": 0.5},
                                    {"occ_sigma_m": 0.003, "l_occ_min": 2.5},
                                    {"l_occ": 1.0, "l_occ_min": 1.7},
                                    {"hold_sigma_m": 0.02}, {"hold_sigma_m": 0.0}])
def test_insert_follows_the_documented_model_visit_by_visit(params):
    """The fast insert (row runs, near-end columns, A&S erfc) against the formula evaluated
    on every traverse() visit: equal to the documented 1e-4 (erfc to 2.5e-5, the constant
    part to 4e-5)."""
    rng = np.random.default_rng(7)
    for _ in range(3):
        g = small_grid(**params)
        pts = random_points(rng, 400)
        want = np.clip(reference_delta(g, pts), g.params.l_min, g.params.l_max)
        g.insert(pts)
        np.testing.assert_allclose(g.log_odds, want, atol=2e-4)
        assert np.array_equal(g.log_odds != 0, want != 0)   # the same cells, no stray ones


def test_insert_follows_the_reference_through_cell_corners_and_along_borders():
    """Beams on exact diagonals and cell borders, starting and ending on corners: the runs
    and near-end columns keep traverse()'s rules (corner touches are no visits)."""
    starts = [(x, y) for x in (2.0, 2.5, 3.0) for y in (2.0, 2.5, 3.0)]
    angles = np.radians(np.arange(0, 360, 45))
    # valid readings end where no cell border lies at d − margin (the weight has a step there)
    lengths = (4.2, 4 * math.sqrt(2), 3.7)
    rows = [(x, y, a, r) for x, y in starts for a in angles for r in lengths]
    x, y, a, r = (np.array(v) for v in zip(*rows))
    n = len(x)
    for reason in (Reason.NO_RETURN, Reason.OK):
        for max_range in (4.0, 4 * math.sqrt(2)):
            ok = reason == Reason.OK
            d = np.where(ok, r, np.nan)
            pts = Points(x=x + d * np.cos(a), y=y + d * np.sin(a), d=d, theta=np.zeros(n),
                         origin_x=x, origin_y=y, heading=a, sigma_m=np.full(n, 0.3),
                         iterations=np.ones(n, int), valid=np.full(n, ok),
                         reason=np.full(n, reason, np.uint8), max_range_m=max_range)
            g = OccupancyGrid((0.0, 0.0), (8, 9), 1.0, MapperParams(min_sigma_m=0.3))
            g.insert(pts)
            want = np.clip(reference_delta(g, pts), g.params.l_min, g.params.l_max)
            np.testing.assert_allclose(g.log_odds, want, atol=2e-4)
            assert np.array_equal(g.log_odds != 0, want != 0)


def test_insert_matches_the_reference_on_a_t_room_sweep():
    sc = load_scenario("t_room")
    from _synthetic import points_for_pose

    for pose in range(len(sc.robot.poses)):
        p = points_for_pose(sc, pose, sigma_m="gp2", rng=np.random.default_rng(pose))
        g = OccupancyGrid.for_scenario(sc)
        g.insert(p)
        want = np.clip(reference_delta(g, p), g.params.l_min, g.params.l_max)
        np.testing.assert_allclose(g.log_odds, want, atol=2e-4)


def test_grid_much_smaller_than_the_beams_reach_follows_the_reference():
    """Beams start and end outside a 4 × 5-cell grid, pass through it or miss it: only the
    cells inside change, as the formula on traverse() says."""
    rng = np.random.default_rng(11)
    for _ in range(5):
        pts = random_points(rng, 400)
        g = OccupancyGrid((0.25, 0.15), (4, 5), 0.01)
        g.insert(pts)
        want = np.clip(reference_delta(g, pts), g.params.l_min, g.params.l_max)
        np.testing.assert_allclose(g.log_odds, want, atol=2e-4)
        assert np.array_equal(g.log_odds != 0, want != 0) and (want != 0).any()


def test_a_reading_of_unknown_sigma_adds_nothing_in_kernel_and_oracle():
    """σ = +inf (accuracy unknown) maps as no reading: the kernel turned it into the 10 mm
    default σ (a hit of 2.5 and a freed beam) where the numpy oracle kept it near 0; NaN
    takes default_sigma_m and −inf the min_sigma_m floor, in both."""
    ox, oy = np.array([0.055, 0.105, 0.205]), np.array([0.205, 0.115, 0.305])
    heading = np.radians([0.0, 30.0, -20.0])
    d = np.array([0.397, 0.253, 0.171])      # (no end − margin on a cell border)

    def batch(sigma):
        n = len(ox)
        return Points(x=ox + d * np.cos(heading), y=oy + d * np.sin(heading), d=d,
                      theta=np.zeros(n), origin_x=ox, origin_y=oy, heading=heading,
                      sigma_m=np.array(sigma, float), iterations=np.ones(n, int),
                      valid=np.ones(n, bool), reason=np.zeros(n, np.uint8), max_range_m=0.5)

    def both(pts):
        g = small_grid()
        return g.delta(pts), reference_delta(g, pts)

    fast, slow = both(batch([np.inf, 0.012, 0.007]))
    lone = batch([0.012, 0.007])
    lone = dataclasses.replace(lone, **{k: getattr(lone, k)[1:] for k in
                                        ("x", "y", "d", "theta", "origin_x", "origin_y",
                                         "heading", "iterations", "valid", "reason")})
    want, _ = both(lone)
    np.testing.assert_array_equal(fast, want)
    np.testing.assert_allclose(slow, want, atol=2e-4)
    assert np.count_nonzero(fast) == np.count_nonzero(want) > 0
    for given_, meant in (([np.nan, 0.012, 0.007], [0.01, 0.012, 0.007]),
                          ([-np.inf, 0.012, 0.007], [0.005, 0.012, 0.007])):
        fast, slow = both(batch(given_))
        want, _ = both(batch(meant))
        np.testing.assert_array_equal(fast, want)
        np.testing.assert_allclose(slow, want, atol=2e-4)
    only_unknown = batch([np.inf, np.inf, np.inf])
    fast, slow = both(only_unknown)
    assert not fast.any() and not slow.any()


def test_batches_with_nothing_to_map_change_nothing():
    """No readings, only invalid ones with NaN end points and emitters, or beams that all
    miss the grid: insert and delta leave every cell at its value."""
    rng = np.random.default_rng(2)
    empty = random_points(rng, 0)
    invalid = random_points(rng, 50)
    invalid.valid[:] = False
    invalid.reason[:] = Reason.OUT_OF_RANGE
    invalid.x[::2] = invalid.origin_x[::3] = np.nan
    missing = random_points(rng, 50)
    missing.origin_x[:] += 5.0                         # 5 m to the right of the 0.6 m grid
    missing.x[:] += 5.0
    for pts in (empty, invalid, missing):
        g = small_grid()
        g.log_odds[3, 4] = 1.25
        g.insert(pts)
        assert np.count_nonzero(g.log_odds) == 1 and g.log_odds[3, 4] == 1.25
        assert not g.delta(pts).any()


def test_insert_takes_float32_and_non_contiguous_readings():
    """The kernel wants flat float64 arrays and a C-ordered grid; insert converts at the
    boundary."""
    pts = random_points(np.random.default_rng(4), 300)
    f32 = Points(**{k: (v.astype(np.float32) if isinstance(v, np.ndarray) and v.dtype == float
                        else v) for k, v in vars(pts).items()})
    as_f64 = Points(**{k: (v.astype(float) if isinstance(v, np.ndarray) and v.dtype == np.float32
                           else v) for k, v in vars(f32).items()})
    strided = Points(**{k: (np.repeat(v, 2)[::2] if isinstance(v, np.ndarray) else v)
                        for k, v in vars(as_f64).items()})
    a, b, c = small_grid(), small_grid(), small_grid()
    c.log_odds = np.asfortranarray(c.log_odds)
    a.insert(f32)
    b.insert(as_f64)
    c.insert(strided)
    assert a.log_odds.any()
    np.testing.assert_array_equal(a.log_odds, b.log_odds)
    np.testing.assert_array_equal(c.log_odds, b.log_odds)


def test_for_scenario_covers_outline_plus_margin_with_walls_through_cell_centres():
    sc = load_scenario("t_room")
    g = OccupancyGrid.for_scenario(sc)
    x0, x1, y0, y1 = g.extent_m
    assert x0 <= -sc.map.margin_m and x1 >= 2.42 + sc.map.margin_m
    assert y0 <= -sc.map.margin_m and y1 >= 1.80 + sc.map.margin_m
    assert g.resolution_m == 0.010
    xs, ys = g.cell_centers()
    assert np.min(np.abs(xs - 0.0)) < 1e-9 and np.min(np.abs(ys - 0.9)) < 1e-9


def test_a_grid_around_points_is_laid_out_like_the_scenario_grid_of_their_box():
    """pipeline.grid_for_points and for_scenario lay out a box the same way: readings whose
    emitters and end points span a room's outline get that room's grid, half a cell and the
    margin beyond it, with no extra row where round-off puts the box's edge a hair below a
    cell border (0.3 − 0.1 m is 19.999999999999996 cells)."""
    import dataclasses

    from irring.pipeline import grid_for_points

    base = load_scenario("t_room")
    outline = tuple((x + 0.3, y + 0.3) for x, y in base.room.outline_m)
    sc = dataclasses.replace(base, room=dataclasses.replace(base.room, outline_m=outline))
    corners = np.array(outline, float).T[:, None, :]
    n = corners.shape[2]
    pts = Points(x=corners[0], y=corners[1], d=np.zeros((1, n)), theta=np.zeros((1, n)),
                 origin_x=corners[0], origin_y=corners[1], heading=np.zeros((1, n)),
                 sigma_m=np.full((1, n), 0.01), iterations=np.ones((1, n), int),
                 valid=np.ones((1, n), bool), reason=np.zeros((1, n), np.uint8))
    g = grid_for_points([pts], sc.map.resolution_m, sc.map.margin_m)
    want = OccupancyGrid.for_scenario(sc)
    assert g.shape == want.shape
    np.testing.assert_array_equal(g.origin_xy_m, want.origin_xy_m)
    np.testing.assert_allclose(g.origin_xy_m, [0.3 - 0.1 - 0.005] * 2, atol=1e-12)

# --------------------------------------------------------------------------- map_server export


def test_pgm_yaml_follow_map_server_and_reload_to_the_same_grid(tmp_path):
    g = small_grid()
    g.insert(single_ray(0.055, 0.205, 0.0, 0.40, sigma_m=0.005))
    g.insert(single_ray(0.055, 0.205, 0.0, 0.40, sigma_m=0.005))
    g.origin_xy_m = np.array([-1.25, 0.5])
    pgm, yml = g.to_pgm(tmp_path / "map.pgm")
    raw = pgm.read_bytes()
    assert raw.startswith(b"P5\n# CREATOR: irring 0.010 m/pix\n60 40\n255\n")
    img = read_pgm(pgm)
    assert img.shape == (40, 60) and img.dtype == np.uint8
    assert set(np.unique(img).tolist()) == {PGM_OCCUPIED, PGM_UNKNOWN, PGM_FREE}
    # top image row is the grid's highest y row
    cls = g.classify()
    assert img[40 - 1 - 20, 45] == PGM_OCCUPIED and cls[20, 45] == OCCUPIED
    meta = yaml.safe_load(yml.read_text())
    assert meta == {"image": "map.pgm", "mode": "trinary", "resolution": 0.01,
                    "origin": [-1.25, 0.5, 0.0], "negate": 0, "occupied_thresh": 0.65,
                    "free_thresh": 0.196}
    # map_server's own rule on each byte value: p = (255 - v) / 255
    for v, want in ((PGM_FREE, FREE), (PGM_OCCUPIED, OCCUPIED), (PGM_UNKNOWN, UNKNOWN)):
        p = (255 - v) / 255
        got = OCCUPIED if p > 0.65 else FREE if p < 0.196 else UNKNOWN
        assert got == want
    back = OccupancyGrid.from_pgm(yml)
    assert back.shape == g.shape and back.resolution_m == g.resolution_m
    np.testing.assert_allclose(back.origin_xy_m, g.origin_xy_m)
    np.testing.assert_array_equal(back.classify(), cls)
    # and the reloaded grid writes the identical files again
    pgm2, yml2 = back.to_pgm(tmp_path / "again" / "map.pgm")
    assert pgm2.read_bytes() == raw and yml2.read_text() == yml.read_text()


def test_read_pgm_rejects_other_formats(tmp_path):
    p = tmp_path / "x.pgm"
    p.write_bytes(b"P2\n2 1\n255\n0 255\n")
    with pytest.raises(ValueError, match="P5"):
        read_pgm(p)


def test_cell_of_and_cell_centres_take_each_axis_from_its_own_origin():
    # origin x != y and a non-square grid: swapping the axes anywhere moves every answer
    g = OccupancyGrid((-0.30, 0.12), (7, 11), 0.05)
    ix, iy = g.cell_of(np.array([-0.30, -0.26, 0.249]), np.array([0.12, 0.171, 0.469]))
    assert ix.tolist() == [0, 0, 10] and iy.tolist() == [0, 1, 6]
    ix, iy = g.cell_of(-0.301, 0.119)                        # just outside both low edges
    assert (int(ix), int(iy)) == (-1, -1)
    x, y = g.cell_centers()
    assert x.shape == (11,) and y.shape == (7,)
    assert x[0] == pytest.approx(-0.275) and y[0] == pytest.approx(0.145)
    assert y[-1] == pytest.approx(0.12 + 6.5 * 0.05)


@pytest.mark.parametrize("bad, message", [
    ({"free_sigmas": -0.5}, "finite free_sigmas ≥ 0, got -0.5"),
    ({"free_sigmas": math.inf}, "finite free_sigmas ≥ 0, got inf"),
    ({"lone_sigma_m": 0.0}, r"lone_sigma_m > 0 \(inf: off\), got 0.0"),
    ({"lone_sigma_m": math.nan}, r"lone_sigma_m > 0 \(inf: off\), got nan"),
    ({"no_return_stop": math.nan}, "no_return_stop must be a log-odds value or inf"),
])
def test_mapper_params_refuse_bad_free_space_knobs_by_name(bad, message):
    with pytest.raises(ValueError, match=message):
        MapperParams(**bad)
    MapperParams(no_return_stop=-math.inf, lone_sigma_m=math.inf)   # the extremes are allowed
