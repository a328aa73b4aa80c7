"""A far reading that sharper readings of its sweep explain is mapped on their surface
(MapperParams.explain_*, mapping.explained_ranges; docs/mapping.md, "Readings a sharper
surface explains")."""

from __future__ import annotations

import math

import numpy as np
import pytest

from irring.core import Points, Reason
from irring.maps import mapping_numpy
from irring.maps.mapping import (OCCUPIED, MapperParams, OccupancyGrid, at_ranges,
                                 explained_ranges)
from hypothesis import given, settings
from hypothesis import strategies as st

WALL_Y = 0.605            # a wall's surface in the middle of cell row 60 (10 mm cells)
EMITTER = (0.503, 0.05)   # the emitter every beam starts from


def grid(**params) -> OccupancyGrid:
    return OccupancyGrid((0.0, 0.0), (80, 100), 0.01, MapperParams(**params))


def sweep(*beams, steps: int = 2) -> Points:
    """One batch: each beam (heading in degrees, range m, σ m) from EMITTER, ``steps`` times
    (steps of a sweep that read alike), as a (steps, n) Points."""
    heading = np.radians([b[0] for b in beams])
    d = np.array([b[1] for b in beams], float)
    sigma = np.array([b[2] for b in beams], float)
    rows = lambda a: np.tile(a, (steps, 1))  # noqa: E731
    ox, oy = np.full(d.size, EMITTER[0]), np.full(d.size, EMITTER[1])
    return Points(x=rows(ox + d * np.cos(heading)), y=rows(oy + d * np.sin(heading)),
                  d=rows(d), theta=rows(np.zeros(d.size)), origin_x=rows(ox),
                  origin_y=rows(oy), heading=rows(heading), sigma_m=rows(sigma),
                  iterations=np.ones((steps, d.size), int),
                  valid=np.ones((steps, d.size), bool),
                  reason=np.full((steps, d.size), int(Reason.OK), np.uint8), max_range_m=0.624)


def wall_beams(sigma_m: float):
    """Beams from 80° to 100° every 0.5° that end on the wall, but for the one at 90° (the
    long reading's; of the others only 89.5° ends in the wall cell its beam crosses)."""
    return [(h, (WALL_Y - EMITTER[1]) / math.sin(math.radians(h)), sigma_m)
            for h in np.arange(80.0, 100.01, 0.5) if abs(h - 90.0) > 1e-9]


def occupied_at(g: OccupancyGrid, x: float, y: float) -> bool:
    ix, iy = g.cell_of(x, y)
    return bool(g.classify()[iy, ix] == OCCUPIED)


LONG = (90.0, WALL_Y - EMITTER[1] + 0.045, 0.020)   # straight up, 45 mm (2.25 σ) long


def test_a_long_reading_behind_a_wall_sharper_readings_confirm_draws_no_wall_behind_it():
    """The wall seen by sharp readings (σ 8 mm) and one reading of σ 20 mm that noise put
    45 mm behind it: the map has no occupied cell more than a cell behind the wall; without
    the rule the long reading marks its cell 45 mm outside."""
    batch = sweep(*wall_beams(0.008), LONG)
    g = grid()
    g.insert(batch)
    rows = np.flatnonzero((g.classify() == OCCUPIED).any(axis=1))
    assert rows.max() == 60 and 60 in rows                  # the wall's row, nothing behind
    assert not occupied_at(g, EMITTER[0], WALL_Y + 0.045)
    off = grid(explain_sigmas=0.0)
    off.insert(batch)
    assert occupied_at(off, EMITTER[0], WALL_Y + 0.045)


def test_the_explained_reading_is_mapped_on_the_confirmed_cell_with_the_sharper_sigma():
    """explained_ranges gives the middle of the beam's passage through the wall's cell
    (0.55 … 0.56 m up the beam) for the long reading and NaN for every other; at_ranges
    moves it there with σ / explain_sharper."""
    batch = sweep(*wall_beams(0.008), LONG)
    g = grid()
    ranges = explained_ranges(batch, g.shape, g.origin_xy_m, g.resolution_m, g.params)
    assert ranges.shape == (2, 41)
    assert np.isfinite(ranges).sum() == 2                    # the long reading, both steps
    np.testing.assert_allclose(ranges[:, -1], 0.555, atol=1e-9)
    moved = at_ranges(batch, ranges, g.params)
    np.testing.assert_allclose(moved.y[:, -1], WALL_Y, atol=1e-9)
    np.testing.assert_allclose(moved.x[:, -1], EMITTER[0], atol=1e-9)
    np.testing.assert_allclose(moved.sigma_m[:, -1], 0.010)
    np.testing.assert_array_equal(moved.x[:, :-1], batch.x[:, :-1])
    np.testing.assert_array_equal(moved.sigma_m[:, :-1], batch.sigma_m[:, :-1])


def test_a_lone_uncertain_reading_with_nothing_in_front_still_marks_its_cell():
    """A thin post seen by one reading of σ 20 mm (nothing confirmed along its beam) and a
    surface 80 mm (4 σ) behind a confirmed wall (seen through a gap): both stay marked."""
    post = (135.0, 0.42, 0.020)
    deep = (90.0, WALL_Y - EMITTER[1] + 0.080, 0.020)
    g = grid()
    g.insert(sweep(*wall_beams(0.008), post, deep))
    h = math.radians(135.0)
    assert occupied_at(g, EMITTER[0] + 0.42 * math.cos(h), EMITTER[1] + 0.42 * math.sin(h))
    assert occupied_at(g, EMITTER[0], WALL_Y + 0.080)


def test_readings_no_sharper_than_the_long_one_do_not_explain_it():
    """The same wall read with σ 12 mm (more than 20 mm / explain_sharper): the long
    reading keeps its end point; and a wall of σ 8 mm read by one step of the sweep (one end
    point, 1.6, in the cell the long beam crosses: below explain_log_odds 3) does not explain
    it either, while two steps (3.2) do."""
    g = grid()
    g.insert(sweep(*wall_beams(0.012), LONG))
    assert occupied_at(g, EMITTER[0], WALL_Y + 0.045)
    once = sweep(*wall_beams(0.008), LONG, steps=1)
    r = explained_ranges(once, g.shape, g.origin_xy_m, g.resolution_m, g.params)
    assert not np.isfinite(r).any()
    twice = sweep(*wall_beams(0.008), LONG, steps=2)
    r = explained_ranges(twice, g.shape, g.origin_xy_m, g.resolution_m, g.params)
    assert np.isfinite(r[:, -1]).all() and not np.isfinite(r[:, :-1]).any()


def test_kernel_and_oracle_map_explained_readings_alike():
    """grid.delta (compiled kernel) and mapping_numpy.add (the oracle) on the batch with an
    explained reading: the same cells within the oracle tests' 2e-4."""
    batch = sweep(*wall_beams(0.008), LONG, (135.0, 0.42, 0.020))
    g = grid()
    g.log_odds[40:45, 10:20] = 1.25
    want = mapping_numpy.add(g.log_odds, batch, g.origin_xy_m, g.resolution_m, g.params)
    np.testing.assert_allclose(g.log_odds + g.delta(batch), want, atol=2e-4)


@pytest.mark.parametrize("bad, message", [
    ({"explain_sigmas": -1.0}, "explain_sigmas ≥ 0"),
    ({"explain_sigmas": math.inf}, "explain_sigmas ≥ 0"),
    ({"explain_log_odds": 0.0}, "explain_log_odds > 0"),
    ({"explain_log_odds": math.nan}, "explain_log_odds > 0"),
    ({"explain_sharper": 0.5}, "explain_sharper ≥ 1"),
])
def test_bad_explain_knobs_are_refused_by_name(bad, message):
    with pytest.raises(ValueError, match=message):
        MapperParams(**bad)


def test_explain_sigmas_zero_turns_the_rule_off():
    batch = sweep(*wall_beams(0.008), LONG)
    g = grid(explain_sigmas=0.0)
    r = explained_ranges(batch, g.shape, g.origin_xy_m, g.resolution_m, g.params)
    assert not np.isfinite(r).any()


def _some_unknown(pick, sigma):
    """σ with 5 % NaN (not given) and 3 % +inf (unknown: mapped as no reading)."""
    return np.where(pick < 0.05, np.nan, np.where(pick > 0.97, np.inf, sigma))


def noisy_walls(seed: int) -> Points:
    """Readings of two slanted walls from three emitters: σ from 4 to 30 mm (some NaN or
    +inf), each end point moved along its beam by Gaussian noise of its σ (two steps of 60
    beams)."""
    rng = np.random.default_rng(seed)
    ox = np.repeat(rng.uniform(0.2, 0.8, 3), 40)
    oy = np.repeat(rng.uniform(0.05, 0.2, 3), 40)
    heading = rng.uniform(math.radians(40), math.radians(140), 120)
    slope, y0 = rng.uniform(-0.3, 0.3), rng.uniform(0.5, 0.7)   # wall y = y0 + slope·x
    ux, uy = np.cos(heading), np.sin(heading)
    d = (y0 + slope * ox - oy) / (uy - slope * ux)
    sigma = rng.uniform(0.004, 0.030, 120)
    noisy = d + rng.normal(0.0, 1.0, 120) * sigma
    valid = (d > 0.05) & (d < 0.75) & (rng.random(120) > 0.1)
    nd = np.where(valid, noisy, np.nan)
    shape = (2, 60)
    return Points(x=(ox + nd * ux).reshape(shape), y=(oy + nd * uy).reshape(shape),
                  d=nd.reshape(shape), theta=np.zeros(shape), origin_x=ox.reshape(shape),
                  origin_y=oy.reshape(shape), heading=heading.reshape(shape),
                  sigma_m=_some_unknown(rng.random(120), sigma).reshape(shape),
                  iterations=np.ones(shape, int), valid=valid.reshape(shape),
                  reason=np.where(valid, int(Reason.OK), int(Reason.OUT_OF_RANGE)).astype(
                      np.uint8).reshape(shape), max_range_m=0.8)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), log_odds=st.sampled_from([1.5, 3.0]),
       sharper=st.sampled_from([1.0, 2.0]))
def test_compiled_explained_ranges_match_the_numpy_oracle(seed, log_odds, sharper):
    """The kernel against mapping_numpy.explained_ranges on noisy readings of a slanted wall
    (explain_log_odds 1.5 and 3, explain_sharper 1 and 2): the same readings explained, at
    ranges equal to 1e-9 m."""
    pts = noisy_walls(seed)
    g = grid(explain_log_odds=log_odds, explain_sharper=sharper)
    fast = explained_ranges(pts, g.shape, g.origin_xy_m, g.resolution_m, g.params)
    slow = mapping_numpy.explained_ranges(pts, g.shape, g.origin_xy_m, g.resolution_m,
                                          g.params)
    np.testing.assert_array_equal(np.isfinite(fast), np.isfinite(slow))
    np.testing.assert_allclose(fast[np.isfinite(fast)], slow[np.isfinite(slow)], atol=1e-9)


def test_noisy_walls_have_readings_to_explain():
    """The comparison above is not all NaN: with the defaults, seeds 0–29 of noisy_walls
    have 8 readings both statements explain, each moved forward by less than 3σ."""
    g = grid()
    moved = 0
    for seed in range(30):
        pts = noisy_walls(seed)
        fast = explained_ranges(pts, g.shape, g.origin_xy_m, g.resolution_m, g.params)
        slow = mapping_numpy.explained_ranges(pts, g.shape, g.origin_xy_m, g.resolution_m,
                                              g.params)
        np.testing.assert_array_equal(np.isfinite(fast), np.isfinite(slow))
        m = np.isfinite(fast)
        assert np.all(fast[m] < pts.d[m]) and np.all(pts.d[m] - fast[m] < 3 * pts.sigma_m[m])
        moved += int(m.sum())
    assert moved == 8


# --------------------------------------------------------------------------- across a run

def test_a_long_reading_of_one_sweep_ends_on_the_wall_another_sweep_confirms():
    """The wall seen sharp (σ 8 mm) by one sweep, the long reading (σ 20 mm, 45 mm behind
    it) by another: insert_run places it on the wall (nothing occupied behind the wall's
    row), in either order of the sweeps; inserted one sweep at a time, with nothing of its
    own batch in front of it, it marks its cell 45 mm outside."""
    wall, long = sweep(*wall_beams(0.008)), sweep(LONG)
    for order in ([wall, long], [long, wall]):
        g = grid()
        g.insert_run(order)
        rows = np.flatnonzero((g.classify() == OCCUPIED).any(axis=1))
        assert rows.max() == 60 and 60 in rows
    alone = grid()
    for batch in (wall, long):
        alone.insert(batch)
    assert occupied_at(alone, EMITTER[0], WALL_Y + 0.045)
    placed = grid().placed_readings([long, wall])
    np.testing.assert_allclose(placed[0].y, WALL_Y, atol=1e-9)        # moved onto the wall
    np.testing.assert_allclose(placed[0].sigma_m, 0.010)              # with σ / 2
    np.testing.assert_array_equal(placed[1].y, wall.y)                # the wall's stay


def test_a_run_confirms_a_wall_no_single_sweep_does():
    """Two sweeps each read the wall cell the long beam crosses once (σ 8 mm, 1.6 each:
    below explain_log_odds 3 alone, 3.2 together): the run explains the long reading, each
    sweep with it alone does not; readings no sharper than σ/2 (12 mm) never do."""
    one = sweep(*wall_beams(0.008), steps=1)
    g = grid()
    alone = g.placed_readings([one, sweep(LONG, steps=1)])[1]
    both = g.placed_readings([one, one, sweep(LONG, steps=1)])[2]
    assert alone.y[0, 0] == pytest.approx(WALL_Y + 0.045)
    assert both.y[0, 0] == pytest.approx(WALL_Y)
    blunt = sweep(*wall_beams(0.012), steps=1)
    kept = g.placed_readings([blunt, blunt, blunt, sweep(LONG, steps=1)])[3]
    assert kept.y[0, 0] == pytest.approx(WALL_Y + 0.045)


def test_kernel_and_oracle_map_a_run_explained_across_sweeps_alike():
    """insert_run (compiled) and mapping_numpy.add_run (the oracle) on sweeps whose
    readings other sweeps explain: the same cells within the oracle tests' 2e-4, and the
    cell behind the wall not occupied in either."""
    batches = [sweep(*wall_beams(0.008), steps=1), sweep(LONG, (135.0, 0.42, 0.020)),
               sweep(*wall_beams(0.008), steps=1)]
    g = grid()
    want = mapping_numpy.add_run(g.log_odds, batches, g.origin_xy_m, g.resolution_m,
                                 g.params, g.params.l_min, g.params.l_max)
    g.insert_run(batches)
    np.testing.assert_allclose(g.log_odds, want, atol=2e-4)
    assert not occupied_at(g, EMITTER[0], WALL_Y + 0.045)


def test_the_run_joined_for_the_explain_rule_is_one_consistent_points():
    """Sweeps of different shapes are explained against each other as one row: every
    per-reading field is joined in the same order (the rule was given x, y, d, σ, origins
    and valid joined, (1, K), but heading, θ, reason and the rest of the first sweep, (S, N):
    right only while the rule read no other field)."""
    from irring.core import points_with
    from irring.maps import mapping

    wall = sweep(*wall_beams(0.008))                               # (2, 40)
    long = points_with(sweep(LONG, steps=3), reach_m=np.full((3, 1), 0.3),
                       reason=np.full((3, 1), int(Reason.NO_RETURN), np.uint8))
    given = []

    def explained(points, *args):
        given.append(points)
        return mapping._explained(points, *args)

    g = grid()
    placed = mapping.placed_readings([wall, long], g.shape, g.origin_xy_m, g.resolution_m,
                                     g.params, explained=explained)
    (row,) = given
    for field in ("x", "y", "d", "theta", "origin_x", "origin_y", "heading", "sigma_m",
                  "iterations", "valid", "reason", "reach_m"):
        value = getattr(row, field)
        assert value.shape == (1, 83), field
        if field in ("x", "y", "d", "sigma_m", "valid"):
            continue   # (as the map takes them: known_sigma and along_beams may move them)
        parts = [np.ravel(getattr(b, field)) if getattr(b, field) is not None
                 else np.full(b.valid.size, np.nan) for b in (wall, long)]
        np.testing.assert_array_equal(value[0], np.concatenate(parts), err_msg=field)
    assert row.reason.dtype == np.uint8 and row.valid.dtype == bool
    assert np.isnan(row.reach_m[0, :80]).all() and (row.reach_m[0, 80:] == 0.3).all()
    assert placed[0].valid.shape == (2, 40) and placed[1].valid.shape == (3, 1)
