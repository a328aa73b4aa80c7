"""A reading its sensor's neighbouring steps both read shorter (longer) is mapped at the
farther (nearer) of their ranges, the median of the three (MapperParams.neighbour_steps,
mapping.neighbour_ranges; docs/mapping.md, "A sensor's neighbouring steps")."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from irring.core import Points, Reason
from irring.maps import mapping_numpy
from irring.maps.mapping import OCCUPIED, MapperParams, OccupancyGrid, neighbour_ranges

WALL_Y = 0.605            # a wall's surface in the middle of cell row 60 (10 mm cells)
EMITTER = (0.503, 0.05)   # one sensor's emitter
FIRST_DEG, STEP_DEG = 70.3, 1.07   # the sensor's heading at the first step, and per step


def grid(**params) -> OccupancyGrid:
    return OccupancyGrid((0.0, 0.0), (80, 100), 0.01, MapperParams(**params))


def one_sensor(extra_m, sigma_m, valid=None) -> Points:
    """One sensor's steps across the wall (S rows, one column): each reads the wall's
    distance plus ``extra_m`` (per step), with σ ``sigma_m`` (per step or one for all)."""
    extra = np.asarray(extra_m, float)
    heading = np.radians(FIRST_DEG + STEP_DEG * np.arange(extra.size))
    d = (WALL_Y - EMITTER[1]) / np.sin(heading) + extra
    col = lambda a: np.asarray(a, float).reshape(-1, 1)  # noqa: E731
    ok = np.ones(extra.size, bool) if valid is None else np.asarray(valid, bool)
    nan = np.where(ok, 1.0, np.nan)
    return Points(x=col((EMITTER[0] + d * np.cos(heading)) * nan),
                  y=col((EMITTER[1] + d * np.sin(heading)) * nan), d=col(d * nan),
                  theta=col(np.zeros(extra.size)), origin_x=col(np.full(extra.size, EMITTER[0])),
                  origin_y=col(np.full(extra.size, EMITTER[1])), heading=col(heading),
                  sigma_m=col(np.broadcast_to(sigma_m, extra.shape) * nan),
                  iterations=np.ones((extra.size, 1), int), valid=ok.reshape(-1, 1),
                  reason=np.where(ok, int(Reason.OK), int(Reason.NOT_CONVERGED)).astype(
                      np.uint8).reshape(-1, 1), max_range_m=0.624)


def cells_behind(g: OccupancyGrid, beyond_m: float) -> int:
    """Occupied cells whose centre lies more than ``beyond_m`` behind the wall's surface."""
    _, cy = g.cell_centers()
    return int((g.classify()[cy > WALL_Y + beyond_m] == OCCUPIED).sum())


def moved(points: Points, params: MapperParams) -> dict[int, float]:
    """{step: range} of the readings neighbour_ranges moves (one sensor; ranges from the
    end points, so equal to ``Points.d`` within round-off)."""
    r = neighbour_ranges(points, params)[:, 0]
    return {int(i): float(r[i]) for i in np.flatnonzero(np.isfinite(r))}


# nine steps of σ 20 mm on the wall; the fifth read 40 mm (2 σ) long
LONG = [0.0, 0.0, 0.0, 0.0, 0.040, 0.0, 0.0, 0.0, 0.0]


def test_a_reading_behind_both_neighbours_draws_no_wall_outside():
    """Without the rule the long reading's hit marks its cell 35–45 mm behind the wall (no
    beam can clear it; with the floor in front of its end point, ahead_floor 1, the cell in
    front too); with it, none: it is mapped at its farther neighbour's range, on the wall."""
    batch = one_sensor(LONG, 0.020)
    off = grid(neighbour_steps=0, between_steps=0)   # (the rule alone: no hits between steps)
    off.insert(batch)
    assert cells_behind(off, 0.025) == 1
    floored = grid(neighbour_steps=0, between_steps=0, ahead_floor=1.0)
    floored.insert(batch)
    assert cells_behind(floored, 0.025) == 2
    g = grid()
    g.insert(batch)
    assert cells_behind(g, 0.025) == 0
    # step 4 at the farther of steps 3 and 5 (73.5°, 75.7°); step 3, now nearer than both
    # its neighbours, at step 2's range (3.3 mm out: the median of three, on a slope)
    assert moved(batch, g.params) == pytest.approx({3: batch.d[2, 0], 4: batch.d[3, 0]},
                                                 abs=1e-12)


def test_a_reading_before_both_neighbours_moves_out_to_the_nearer_one():
    """The same step read 40 mm short: mapped at step 5's range (the nearer of its two
    neighbours; step 5, now farther than both, at step 6's); the cell 40 mm in front of the
    wall it marked is no longer occupied."""
    short = one_sensor([-v for v in LONG], 0.020)
    assert moved(short, MapperParams()) == pytest.approx({4: short.d[5, 0], 5: short.d[6, 0]},
                                                      abs=1e-12)
    g, off = grid(), grid(neighbour_steps=0)
    g.insert(short)
    off.insert(short)
    x = EMITTER[0] + short.d[4, 0] * math.cos(short.heading[4, 0])
    assert [o.classify()[o.cell_of(x, short.y[4, 0])[::-1]] for o in (off, g)] == [OCCUPIED, -1]


def test_only_uncertain_readings_bracketed_within_their_noise_move():
    """Not moved: a reading of σ 8 mm 15 mm long (it places its surface in its cell); one
    120 mm long (a gap, 4.2 combined σ behind its neighbours: a surface seen through it);
    one whose neighbour on one side is a post 250 mm in front (an occluding edge: the wall
    behind a table leg), nor that post (the wall beside it is 8.8 combined σ behind)."""
    p = MapperParams()
    sharp = LONG[:4] + [0.015] + LONG[5:]
    assert not np.isfinite(neighbour_ranges(one_sensor(sharp, 0.008), p)).any()
    gap = LONG[:4] + [0.120] + LONG[5:]
    assert not np.isfinite(neighbour_ranges(one_sensor(gap, 0.020), p)).any()
    leg = LONG[:3] + [-0.250] + LONG[4:]
    assert not np.isfinite(neighbour_ranges(one_sensor(leg, 0.020), p)).any()


# seven steps on the wall, σ 10 mm; the fourth a θ = 0 fallback of σ 45 mm read 90 mm long
FALLBACK = [0.0, 0.0, 0.0, 0.090, 0.0, 0.0, 0.0]
FALLBACK_SIGMA = [0.010, 0.010, 0.010, 0.045, 0.010, 0.010, 0.010]


def test_an_uncertain_reading_behind_both_neighbours_draws_no_wall_outside():
    """A reading of σ 45 mm (above lone_sigma_m) read 90 mm long between two of σ 10 mm:
    its hit alone marked 3 cells 80–100 mm behind the wall; mapped at the farther of its
    neighbours' ranges, none (the rule held only readings of σ ≤ 30 mm before). Step 2,
    of σ 10 mm, moves out to step 1's range as it did."""
    batch = one_sensor(FALLBACK, FALLBACK_SIGMA)
    off = grid(neighbour_steps=0)
    off.insert(batch)
    assert cells_behind(off, 0.025) == 3
    g = grid()
    g.insert(batch)
    assert cells_behind(g, 0.025) == 0
    assert moved(batch, g.params) == pytest.approx({2: batch.d[1, 0], 3: batch.d[2, 0]},
                                                 abs=1e-12)
    np.testing.assert_array_equal(mapping_numpy.neighbour_ranges(batch, g.params),
                                  neighbour_ranges(batch, g.params))


def test_an_uncertain_reading_before_both_neighbours_stays():
    """Read 40 mm short (a thin thing in front of the wall its neighbours see may be what
    it met): a reading of σ 45 mm is not moved out onto the wall; one of σ 20 mm is, to
    the nearer of its neighbours' ranges, as before."""
    short = [0.0, 0.0, 0.0, -0.040, 0.0, 0.0, 0.0]
    for rule in (neighbour_ranges, mapping_numpy.neighbour_ranges):
        assert np.isnan(rule(one_sensor(short, FALLBACK_SIGMA), MapperParams())[3, 0])
    sharper = one_sensor(short, [0.010, 0.010, 0.010, 0.020, 0.010, 0.010, 0.010])
    assert moved(sharper, MapperParams())[3] == pytest.approx(sharper.d[4, 0], abs=1e-12)


def test_an_uncertain_last_reading_is_not_read_behind_its_one_sharper_neighbour():
    """The fallback reading as the last valid step before two the estimator could not place
    (INCIDENCE_UNKNOWN: invalid here): mapped at its one neighbour's range (σ 10 mm,
    within 3 combined σ, shorter), no cell behind the wall; not when that neighbour is
    no sharper (σ 45 mm too) or lies beyond 3 combined σ (a reading 200 mm long); nor a
    reading of σ ≤ 30 mm (it needs a neighbour on each side)."""
    valid = [1, 1, 1, 1, 0, 0, 1]
    batch = one_sensor(FALLBACK, FALLBACK_SIGMA, valid=valid)
    off = grid(neighbour_steps=0)
    off.insert(batch)
    assert cells_behind(off, 0.025) == 3
    g = grid()
    g.insert(batch)
    assert cells_behind(g, 0.025) == 0
    assert moved(batch, g.params) == pytest.approx({2: batch.d[1, 0], 3: batch.d[2, 0]},
                                                 abs=1e-12)
    # the same from the other side (rows reversed: its one neighbour after it)
    back = in_rows(batch, list(range(6, -1, -1)))
    assert moved(back, g.params) == pytest.approx({4: batch.d[1, 0], 3: batch.d[2, 0]},
                                                abs=1e-12)
    blunt = one_sensor(FALLBACK, [0.010, 0.010, 0.045, 0.045, 0.010, 0.010, 0.010],
                       valid=valid)
    assert 3 not in moved(blunt, g.params)
    far = one_sensor([0.0, 0.0, 0.0, 0.200, 0.0, 0.0, 0.0], FALLBACK_SIGMA, valid=valid)
    assert 3 not in moved(far, g.params)
    sharp = one_sensor([0.0, 0.0, 0.0, 0.040, 0.0, 0.0, 0.0],
                       [0.010, 0.010, 0.010, 0.020, 0.010, 0.010, 0.010], valid=valid)
    assert 3 not in moved(sharp, g.params)
    for p in (batch, back, blunt, far, sharp):
        np.testing.assert_array_equal(mapping_numpy.neighbour_ranges(p, g.params),
                                      neighbour_ranges(p, g.params))


def test_the_nearest_valid_neighbour_within_neighbour_steps_counts():
    """Step 3 not converged: step 2 is the long reading's neighbour before it (2 steps away)
    and it moves; with steps 2 and 3 both out, the nearest before is 3 steps away and it
    does not (nor with neighbour_steps 1 and step 3 out)."""
    batch = one_sensor(LONG, 0.020, valid=[1, 1, 1, 0, 1, 1, 1, 1, 1])
    # step 4 at step 2's range (72.4°, farther than step 5); step 2 at step 1's
    assert moved(batch, MapperParams()) == pytest.approx({2: batch.d[1, 0], 4: batch.d[2, 0]},
                                                      abs=1e-12)
    assert not np.isfinite(neighbour_ranges(batch, MapperParams(neighbour_steps=1))).any()
    two_out = one_sensor(LONG, 0.020, valid=[1, 1, 0, 0, 1, 1, 1, 1, 1])
    assert not np.isfinite(neighbour_ranges(two_out, MapperParams())[4]).any()


def test_kernel_and_oracle_map_bracketed_readings_alike():
    """grid.delta (compiled kernel) and mapping_numpy.add (the oracle) with the rule on:
    the same cells within the oracle tests' 2e-4, and not the map without it."""
    batch = one_sensor(LONG, 0.020)
    g = grid()
    g.log_odds[40:45, 10:20] = 1.25
    want = mapping_numpy.add(g.log_odds, batch, g.origin_xy_m, g.resolution_m, g.params)
    np.testing.assert_allclose(g.log_odds + g.delta(batch), want, atol=2e-4)
    off = grid(neighbour_steps=0)
    assert np.abs(off.delta(batch) - g.delta(batch)).max() > 1.0


def in_rows(points: Points, order) -> Points:
    """``points`` with its rows (steps) in ``order``: a sweep read in the order asked."""
    return dataclasses.replace(points, **{
        f: np.asarray(getattr(points, f))[order] for f in (
            "x", "y", "d", "theta", "origin_x", "origin_y", "heading", "sigma_m",
            "iterations", "valid", "reason")})


def test_only_readings_whose_neighbouring_rows_bracket_their_beam_move():
    """Rows in the order a sweep asked for its steps: reversed (a descending sweep), the
    same steps move to the same ranges. Asked 0, 1, 2, 4, 3, 5, …: step 4's neighbouring
    rows are steps 2 and 3, both on one side of its beam, and it stays (it was mapped at
    step 2's range, a beam 2.1° away); step 2, between steps 1 and 4, moves out."""
    batch = one_sensor(LONG, 0.020)
    p = MapperParams()
    back = list(range(8, -1, -1))
    assert moved(in_rows(batch, back), p) == pytest.approx(
        {back.index(3): batch.d[2, 0], back.index(4): batch.d[3, 0]}, abs=1e-12)
    swapped = in_rows(batch, [0, 1, 2, 4, 3, 5, 6, 7, 8])
    assert moved(swapped, p) == pytest.approx({2: batch.d[1, 0]}, abs=1e-12)
    np.testing.assert_array_equal(mapping_numpy.neighbour_ranges(swapped, p),
                                  neighbour_ranges(swapped, p))


@pytest.mark.parametrize("bad", [1.5, -1.0, math.nan, math.inf, 1001.0])
def test_bad_neighbour_steps_are_refused_by_name(bad):
    with pytest.raises(ValueError, match="neighbour_steps"):
        MapperParams(neighbour_steps=bad)


def drawn_sweep(rng, steps, sensors, steps_knob, shuffled=False):
    """A sweep of ``sensors`` emitters on a ring each turning through ``steps`` steps
    past a wall, posts and gaps: ranges with noise of their σ (5–120 mm, some NaN), some
    readings invalid, some out of the wall's reach (a post in front, a gap behind);
    ``shuffled``: its rows (steps) in a random order."""
    base = rng.uniform(0.0, 2 * np.pi, sensors)
    heading = base[None, :] + np.radians(1.07) * np.arange(steps)[:, None]
    ox = 0.15 * np.cos(base)[None, :] + np.zeros((steps, 1))
    oy = 0.15 * np.sin(base)[None, :] + np.zeros((steps, 1))
    sigma = np.exp(rng.uniform(math.log(0.005), math.log(0.12), (steps, sensors)))
    d = rng.uniform(0.3, 0.6, sensors)[None, :] + rng.normal(0.0, 1.0, (steps, sensors)) * sigma
    d += np.where(rng.random((steps, sensors)) < 0.1, rng.choice([-0.2, 0.15], (steps, sensors)),
                  0.0)
    sigma[rng.random((steps, sensors)) < 0.05] = np.nan
    valid = rng.random((steps, sensors)) < 0.8
    d = np.where(valid, d, np.nan)
    points = Points(x=ox + d * np.cos(heading), y=oy + d * np.sin(heading), d=d,
                    theta=np.zeros(d.shape), origin_x=ox, origin_y=oy, heading=heading,
                    sigma_m=sigma, iterations=np.ones(d.shape, int), valid=valid,
                    reason=np.where(valid, int(Reason.OK), int(Reason.NOT_CONVERGED)).astype(
                        np.uint8), max_range_m=0.624)
    if shuffled:
        points = in_rows(points, rng.permutation(steps))
    return points, MapperParams(neighbour_steps=steps_knob)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2 ** 20), steps=st.integers(1, 40), sensors=st.integers(1, 12),
       knob=st.sampled_from([2, 1, 3, 0]), shuffled=st.booleans())
def test_the_kernel_agrees_with_its_numpy_statement(seed, steps, sensors, knob, shuffled):
    """mapping.neighbour_ranges (compiled) and mapping_numpy.neighbour_ranges: the same
    readings moved (NaN pattern exact) to the same range (bit for bit), rows in step order
    or not."""
    points, params = drawn_sweep(np.random.default_rng(seed), steps, sensors, knob, shuffled)
    got = neighbour_ranges(points, params)
    want = mapping_numpy.neighbour_ranges(points, params)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    np.testing.assert_array_equal(got[np.isfinite(got)], want[np.isfinite(want)])


def test_the_drawn_sweeps_move_readings_both_ways():
    """Not vacuous: over 50 drawn sweeps of 40 steps and 12 sensors the rule moves
    readings in (behind both neighbours) and out (before both), and leaves most alone."""
    moved_in = moved_out = total = 0
    for seed in range(50):
        points, params = drawn_sweep(np.random.default_rng(seed), 40, 12, 2)
        r = mapping_numpy.neighbour_ranges(points, params)
        moved_in += int((r < points.d).sum())
        moved_out += int((r > points.d).sum())
        total += int(points.valid.sum())
    assert moved_in > 500 and moved_out > 500 and moved_in + moved_out < total / 2
