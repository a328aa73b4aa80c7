"""Fine cells and readings noisier than a cell (docs/mapping.md, "Fine cells"): the hit's
floor stays in the end point's cell, and a sensor's consecutive steps on one surface mark
the cells between their end points."""

from __future__ import annotations

import math

import numpy as np

from irring.core import Points, Reason, points_with
from irring.maps import mapping_numpy
from irring.maps.mapping import (OCCUPIED, MapperParams, OccupancyGrid, between_steps,
                                 mapped_beams)

RES = 0.005                      # 5 mm cells, origin (0, 0): cell k spans [5k, 5k + 5) mm
EMITTER = (0.0123, 0.0371)       # one beam along +x in cell row 7


def one_beam(sigma_m: float, d: float = 0.3) -> Points:
    a = lambda v: np.array([[v]], float)  # noqa: E731
    return Points(x=a(EMITTER[0] + d), y=a(EMITTER[1]), d=a(d), theta=a(0.0),
                  origin_x=a(EMITTER[0]), origin_y=a(EMITTER[1]), heading=a(0.0),
                  sigma_m=a(sigma_m), iterations=np.ones((1, 1), int), valid=np.ones((1, 1), bool),
                  reason=np.zeros((1, 1), np.uint8), max_range_m=0.8)


def both(params: MapperParams, points: Points, shape=(20, 90)) -> tuple[np.ndarray, np.ndarray]:
    """The compiled insert's change and the numpy oracle's, on an empty grid."""
    g = OccupancyGrid((0.0, 0.0), shape, RES, params)
    oracle = mapping_numpy.add(np.zeros(shape), points, g.origin_xy_m, RES, params)
    return g.delta(points), oracle


def phi(z: float) -> float:
    return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


def test_a_hit_keeps_its_floor_in_its_own_cell_and_its_sigma_weight_in_front():
    """σ 20 mm, end point 300 mm out at x = 312.3 mm (cell 62). Cell 60 (300–305 mm, 7.3 mm
    in front) gets l_occ·σ_occ/σ = 0.625 Gaussian in its gap plus the pass; with the floor
    (ahead_floor 1) l_occ_min = 1.6 there. The end point's cell holds 1.6 either way."""
    sigma, d = 0.020, 0.3
    s_b = 0.305 - EMITTER[0]
    gap = d - s_b
    free = -1.5 * phi((d - 0.5 * RES - s_b) / sigma)
    for floor, peak in ((0.0, 2.5 * 0.005 / sigma), (1.0, 1.6)):
        kernel, oracle = both(MapperParams(ahead_floor=floor), one_beam(sigma, d))
        want = peak * math.exp(-0.5 * (gap / sigma) ** 2) + free
        assert abs(kernel[7, 60] - want) < 1e-4 and abs(oracle[7, 60] - want) < 1e-9
        assert abs(kernel[7, 62] - 1.6) < 1e-4 and abs(oracle[7, 62] - 1.6) < 1e-9


def test_uncertain_and_sharp_hits_are_as_before():
    """A reading above lone_sigma_m (40 mm: a θ = 0 fallback) keeps its scaled floor in front
    (a thin thing's near face); one of σ ≤ occ_sigma_m has no floor to lose."""
    for sigma in (0.040, 0.004):
        without, _ = both(MapperParams(ahead_floor=0.0), one_beam(sigma))
        floored, _ = both(MapperParams(ahead_floor=1.0), one_beam(sigma))
        np.testing.assert_array_equal(without, floored)


EMITTERS = ((0.4317, 0.0529), (0.3102, 0.0611), (0.5521, 0.0477))   # three sensors' emitters
WALL_Y = 0.6013                  # a wall in cell row 120 (600–605 mm)


def wall_sweep(sigma_m: float) -> Points:
    """Three sensors' 31 steps each, 1.07° apart, onto the wall y = 601.3 mm seen 16° off
    square to 16° beyond, every end point on the wall: a snapped line's members, their σ on
    their line ``sigma_m``."""
    heading = np.radians(90.0 - 16.0 + 1.07 * np.arange(31))[:, None] + np.zeros(3)
    ox = np.array([e[0] for e in EMITTERS]) + np.zeros((31, 1))
    oy = np.array([e[1] for e in EMITTERS]) + np.zeros((31, 1))
    d = (WALL_Y - oy) / np.sin(heading)
    n = heading.shape
    return Points(x=ox + d * np.cos(heading), y=oy + d * np.sin(heading), d=d,
                  theta=np.zeros(n), origin_x=ox, origin_y=oy, heading=heading,
                  sigma_m=np.full(n, sigma_m), iterations=np.ones(n, int),
                  valid=np.ones(n, bool), reason=np.zeros(n, np.uint8), max_range_m=0.8)


def test_a_wall_read_by_agreeing_readings_is_drawn_within_a_cell_of_it():
    """Every end point on the wall, σ 10.5 mm (a GP2Y0A02 line member far out): with the
    floor in front (ahead_floor 1) cells of row 118, 10–15 mm in front of the wall's row and
    outside the map's 1-cell tolerance, are occupied where the hits of several sensors'
    beams overlap; without it only the wall's row and the row in front of it. The wall's
    row between the end points' cells is unbroken only with the hits between steps in every
    cell between (``between_end_cells`` 1, at ½); its end points lie 2–3 cells apart, so the
    default (0.3 from 2 cells off both ends) maps it as without them, every cell of the row
    within a cell of an occupied one."""
    pts = wall_sweep(0.0105)
    cols = np.floor(pts.x / RES).astype(int)
    span = np.arange(cols.min(), cols.max() + 1)
    rows, unbroken, maps = {}, {}, {}
    for floor, between in ((0.0, 0.5), (1.0, 0.5), (0.0, 0.0)):
        g = OccupancyGrid((0.0, 0.0), (140, 200), RES,
                          MapperParams(ahead_floor=floor, between_steps=between,
                                       between_end_cells=1))
        g.insert(pts)
        occ = g.classify() == OCCUPIED
        rows[floor, between] = set(np.nonzero(occ)[0].tolist())
        unbroken[floor, between] = bool(occ[120, span].all())
        maps[floor, between] = occ
    assert rows[0.0, 0.5] == rows[0.0, 0.0] == {119, 120}
    assert rows[1.0, 0.5] == {118, 119, 120}
    assert unbroken[0.0, 0.5] and not unbroken[0.0, 0.0]
    default = OccupancyGrid((0.0, 0.0), (140, 200), RES)
    default.insert(pts)
    occ = default.classify() == OCCUPIED
    np.testing.assert_array_equal(occ, maps[0.0, 0.0])
    near = np.zeros_like(occ)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            near |= np.roll(np.roll(occ, dy, 0), dx, 1)
    assert near[120, span].all()


def two_steps(ys=(0.6025, 0.6025), xs=(0.3113, 0.3371), sigma=(0.010, 0.012)) -> Points:
    """Two consecutive steps of sensor 0 (rows 0, 1) from (330, 50) mm, and sensor 1 (column
    1) beside them, valid only at step 0."""
    ox, oy = 0.33, 0.05
    x = np.array([[xs[0], 0.2100], [xs[1], np.nan]])
    y = np.array([[ys[0], 0.6025], [ys[1], np.nan]])
    d = np.hypot(x - ox, y - oy)
    return Points(x=x, y=y, d=d, theta=np.zeros((2, 2)), origin_x=np.full((2, 2), ox),
                  origin_y=np.full((2, 2), oy), heading=np.arctan2(y - oy, x - ox),
                  sigma_m=np.array([[sigma[0], 0.01], [sigma[1], np.nan]]),
                  iterations=np.ones((2, 2), int),
                  valid=np.array([[True, True], [True, False]]),
                  reason=np.array([[0, 0], [0, int(Reason.NO_RETURN)]], np.uint8), max_range_m=0.8)


def test_consecutive_steps_on_one_surface_mark_the_cells_between():
    """End points at x = 311.3 and 337.1 mm in cell row 120 (cells 62 and 67): the cells
    strictly between them (63–66) get half the weaker hit (σ 12 mm: l_occ_min 1.6), 0.8
    each, with ``between_end_cells`` 1; by default only those 2 cells or more from both end
    cells (64, 65), 0.6 of it (0.96: over the occupied threshold's 0.62 alone), and
    nothing else; sensor 1's lone reading joins nothing."""
    pts = two_steps()
    off, _ = both(MapperParams(between_steps=0.0), pts, (140, 140))
    np.testing.assert_array_equal(off[120, 63:67], 0.0)
    for params, cells, w_want in ((MapperParams(between_steps=0.5, between_end_cells=1),
                                   [63, 64, 65, 66], 0.8),
                                  (MapperParams(), [64, 65], 0.96)):
        iy, ix, w = between_steps(pts, (140, 140), (0.0, 0.0), RES, params)
        assert iy.tolist() == [120] * len(cells) and ix.tolist() == cells
        np.testing.assert_allclose(w, w_want)
        kernel, oracle = both(params, pts, (140, 140))
        np.testing.assert_allclose(kernel[120, cells], w_want, atol=1e-4)
        np.testing.assert_allclose(oracle[120, cells], w_want, atol=1e-12)
        rest = np.ones(off.shape, bool)
        rest[120, cells] = False
        np.testing.assert_array_equal(kernel[rest], off[rest])


def test_steps_that_disagree_or_fit_in_two_cells_join_nothing():
    """Ranges 50 mm apart at σ 10 / 12 mm (more than 3 combined σ = 46.9 mm): two surfaces,
    nothing between; the same steps on 20 mm cells lie in two neighbouring cells: nothing
    between either (a coarse map is not changed by the rule)."""
    params = MapperParams(between_steps=0.5)
    far = two_steps(ys=(0.6025, 0.6525))
    assert abs(far.d[1, 0] - far.d[0, 0]) > 3 * math.hypot(0.010, 0.012)
    assert between_steps(far, (140, 140), (0.0, 0.0), RES, params) is None
    assert between_steps(two_steps(), (40, 40), (0.0, 0.0), 0.020, params) is None
    # σ above lone_sigma_m (a θ = 0 fallback) joins nothing
    assert between_steps(two_steps(sigma=(0.010, 0.040)), (140, 140), (0.0, 0.0), RES,
                         params) is None


FAR_Y = 1.2013                   # a far wall in cell row 240 (1200–1205 mm)


def far_sweep(sigma_m: float, emitters) -> Points:
    """Sensors at ``emitters`` read every other step (2.16° apart, ``step_stride`` 2) onto
    the wall y = 1201.3 mm, 10° off square to 9.4° beyond, each end point on the wall (a
    GP2Y0A02's far wall): its end points 8–9 five-mm cells apart along it."""
    heading = np.radians(90.0 - 10.0 + 2.16 * np.arange(10))[:, None] + np.zeros(len(emitters))
    ox = np.array([e[0] for e in emitters]) + np.zeros((10, 1))
    oy = np.array([e[1] for e in emitters]) + np.zeros((10, 1))
    d = (FAR_Y - oy) / np.sin(heading)
    n = heading.shape
    return Points(x=ox + d * np.cos(heading), y=oy + d * np.sin(heading), d=d,
                  theta=np.zeros(n), origin_x=ox, origin_y=oy, heading=heading,
                  sigma_m=np.full(n, sigma_m), iterations=np.ones(n, int),
                  valid=np.ones(n, bool), reason=np.zeros(n, np.uint8), max_range_m=1.5)


def far_gaps(params: MapperParams, points: Points) -> tuple[int, int]:
    """(cells of the wall's row between the end points farther than a cell from any
    occupied cell, occupied cells)."""
    g = OccupancyGrid((0.0, 0.0), (260, 200), RES, params)
    g.insert(points)
    occ = g.classify() == OCCUPIED
    near = np.zeros_like(occ)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            near |= np.roll(np.roll(occ, dy, 0), dx, 1)
    cols = np.floor(points.x / RES).astype(int)
    assert set(np.nonzero(occ)[0].tolist()) <= {239, 240}    # nothing off the wall
    return int((~near[240, cols.min():cols.max() + 1]).sum()), int(occ.sum())


def test_a_far_wall_read_every_other_step_is_drawn_between_its_end_points():
    """A sharp sensor (σ 1 mm, the ideal sensor's) reading a far wall every other step
    leaves 50 of the wall's cells more than a cell from its hits; the segments between its
    steps leave none. One noisy sensor's segments (σ 12 mm: 0.6 of l_occ_min, 0.96) leave
    none of its 49 either, where 0.3 of it (0.48) marked nothing alone; two sensors that
    swept the same stretch of wall leave none of the 37 gaps."""
    off = MapperParams(between_steps=0.0)
    one, two = ((0.4317, 0.0529),), ((0.4317, 0.0529), (0.4391, 0.0502))
    assert far_gaps(off, far_sweep(0.001, one)) == (50, 21)
    assert far_gaps(MapperParams(), far_sweep(0.001, one)) == (0, 72)
    assert far_gaps(off, far_sweep(0.012, one)) == (49, 22)
    assert far_gaps(MapperParams(between_steps=0.3), far_sweep(0.012, one)) == (49, 22)
    assert far_gaps(MapperParams(), far_sweep(0.012, one)) == (0, 73)
    assert far_gaps(off, far_sweep(0.012, two))[0] == 37
    assert far_gaps(MapperParams(), far_sweep(0.012, two))[0] == 0


def slanted_sweep(sigma_m: float, theta_deg: float) -> Points:
    """One sensor at (431.7, 52.9) mm reading every other step (2.16° apart) onto a wall
    800 mm out along its first beam, whose normal points back at it 55° off that beam, the
    beam turning away from the normal: incidence 55° rising to 70.1° over 8 steps at
    0.80–1.35 m, each end point on the wall; ``theta_deg`` the estimator's θ for every
    reading (None: the true incidence)."""
    o = np.array([0.4317, 0.0529])
    first = math.radians(57.0)                     # the first beam's heading
    wall = o + 0.8 * np.array([math.cos(first), math.sin(first)])
    normal_heading = first + math.pi - math.radians(55.0)
    n = np.array([math.cos(normal_heading), math.sin(normal_heading)])
    heading = first + np.radians(2.16 * np.arange(8))[:, None]
    u = np.stack([np.cos(heading), np.sin(heading)], -1)
    d = ((wall - o) @ n) / (u @ n)
    inc = np.arccos(np.abs(u @ n))
    theta = inc if theta_deg is None else np.full(inc.shape, math.radians(theta_deg))
    shape = heading.shape
    return Points(x=o[0] + d * np.cos(heading), y=o[1] + d * np.sin(heading), d=d,
                  theta=theta, origin_x=np.full(shape, o[0]), origin_y=np.full(shape, o[1]),
                  heading=heading, sigma_m=np.full(shape, sigma_m),
                  iterations=np.ones(shape, int), valid=np.ones(shape, bool),
                  reason=np.zeros(shape, np.uint8), max_range_m=1.5)


def test_a_slanted_wall_read_every_other_step_is_one_surface_between_its_steps():
    """A wall met at 55–70° read every other step: its consecutive ranges differ by 46–127
    mm, far more than 3 combined σ (σ 5 mm: 21 mm), though it is one flat surface; a flat
    surface at θ draws the range out by d·Δh·tan θ over the beams' turn Δh, so the pairs
    allowed that much more (at the smaller θ of the two) are joined: all 7 of them, each at
    0.6 of a σ-5-mm hit (1.5, a cell alone), 106 cells, each on the wall. Read square on
    (θ = 0, as a reading on no line is kept), the same ranges allow nothing more and join
    nothing."""
    params = MapperParams()
    pts = slanted_sweep(0.005, None)
    step = np.abs(np.diff(pts.d[:, 0]))
    assert 0.046 < step.min() and step.max() < 0.127
    assert step.min() > 3 * math.hypot(0.005, 0.005)
    hits = between_steps(pts, (400, 400), (0.0, 0.0), RES, params)
    assert hits is not None
    iy, ix, w = hits
    assert iy.size == 106            # the wall's cells 2 or more from both end cells
    np.testing.assert_allclose(w, 1.5)
    # every segment between the 8 end points adds cells, each cell on the wall
    cx, cy = (ix + 0.5) * RES, (iy + 0.5) * RES
    wall = np.array([0.4317, 0.0529]) + 0.8 * np.array([math.cos(math.radians(57.0)),
                                                         math.sin(math.radians(57.0))])
    nh = math.radians(57.0) + math.pi - math.radians(55.0)
    off_wall = np.abs((cx - wall[0]) * math.cos(nh) + (cy - wall[1]) * math.sin(nh))
    assert off_wall.max() < RES * math.sqrt(0.5)
    ey = np.floor(pts.y[:, 0] / RES)              # (the wall runs 34° off the y axis)
    between = [((ey[r] < iy) & (iy < ey[r + 1])).any() for r in range(7)]
    assert between == [True] * 7
    assert between_steps(slanted_sweep(0.005, 0.0), (400, 400), (0.0, 0.0), RES,
                         params) is None


def test_the_sigma_floor_is_half_a_cell_on_cells_finer_than_10_mm():
    """mapped_beams floors σ at min(min_sigma_m, min_sigma_cells · the cell): 2.5 mm on 5 mm
    cells, 4 mm on 8 mm; 5 mm from 10 mm up; a cone's weights keep the same floor."""
    beam = one_beam(0.003)
    for res, floor in ((0.005, 0.0025), (0.008, 0.004), (0.010, 0.005), (0.025, 0.005)):
        assert mapped_beams(beam, MapperParams(), res)[1].min_sigma_m == floor
    cone = points_with(beam, cone_half_angle_rad=0.2)
    assert mapped_beams(cone, MapperParams(), 0.005)[1].min_sigma_m == 0.0025
    assert mapped_beams(beam, MapperParams(min_sigma_cells=2.0), 0.005)[1].min_sigma_m == 0.005


def test_a_sharp_hit_on_5_mm_cells_spreads_by_its_own_sigma_not_by_a_cell():
    """σ 3 mm, end point at x = 300.1 mm (cell 60, 0.1 mm into it). Cell 58 (290–295 mm) lies
    5.1 mm in front: with the 5 mm floor (a whole 5 mm cell) each beam added
    2.5·e^(−½(5.1/5)²) − 1.5·Φ(2.6/5) = +0.44 there and two agreeing beams marked it
    occupied, two cells in front of the wall; at its own σ each adds
    2.5·e^(−½(5.1/3)²) − 1.5·Φ(2.6/3) = −0.62. The end point's cell holds as before."""
    d = 0.3001 - EMITTER[0]
    s_b = 0.295 - EMITTER[0]
    two = _two(one_beam(0.003, d))
    for cells, sigma in ((0.5, 0.003), (1.0, 0.005)):
        params = MapperParams(min_sigma_cells=cells)
        kernel, oracle = both(params, two)
        want = 2 * (2.5 * math.exp(-0.5 * ((d - s_b) / sigma) ** 2)
                    - 1.5 * phi((d - 0.5 * RES - s_b) / sigma))
        assert abs(kernel[7, 58] - want) < 1e-4 and abs(oracle[7, 58] - want) < 1e-9
        assert abs(kernel[7, 60] - 5.0) < 1e-4 and abs(oracle[7, 60] - 5.0) < 1e-9
    assert round(want, 2) == 0.88              # the old floor: occupied (> 0.62) …
    assert both(MapperParams(), two)[0][7, 58] < -1.2     # … now not
    # 10 mm cells: the floor is 5 mm either way, the same map
    g10 = [OccupancyGrid((0.0, 0.0), (10, 45), 0.010, MapperParams(min_sigma_cells=c))
           for c in (0.5, 100.0)]
    np.testing.assert_array_equal(g10[0].delta(two), g10[1].delta(two))


def _two(beam: Points) -> Points:
    """One batch of two copies of a (1, 1) reading: two sensors' agreeing beams."""
    return Points(**{k: (np.concatenate([v, v], axis=1) if isinstance(v, np.ndarray) else v)
                     for k, v in vars(beam).items()})
