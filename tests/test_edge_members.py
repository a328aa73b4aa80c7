"""A line member alone at a nearer surface's edge (members.alone_at_an_edge): a beam
grazing a post's flank returns a dim reading that the far wall's line behind the post
takes at that wall's θ, 180-250 mm long; its sensor's adjacent steps read the post
(nearer) or nothing, never the wall. Such a reading is INCIDENCE_UNKNOWN."""

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
from irring.estimation.members import EDGE_JUMP_M, alone_at_an_edge, alone_at_an_edge_compiled
from irring.scenario import load_scenario, loads
from _synthetic import stand_in_calibration

# GP2Y0A21 to 800 mm: a 15 mm post 350 mm in front of the far wall (730-770 mm from the
# second pose, where that wall's returns are near the no-return level)
POST_BEFORE_FAR_WALL = """
name: post_before_far_wall
seed: 5241
room: {outline_mm: [[0, 0], [899.5, 0], [811.6, 1050.8], [357, 1050.8]]}
obstacles:
  - {type: cylinder, center_mm: [540, 788], radius_mm: 15}
robot:
  poses:
    - {x_mm: 240.88, y_mm: 172.57, yaw_deg: 9}
    - {x_mm: 710.61, y_mm: 188.85, yaw_deg: -18}
sensor: {model: gp2y0a21}
effects: [incidence, noise, quantization]
"""


def test_a_post_flank_read_at_the_wall_behind_is_not_valid():
    sc = loads(POST_BEFORE_FAR_WALL, source="<test>")
    run = pipeline.run(sc, seed=5241, progress=False)
    sweep, p = run.sweeps[1], run.points[1]
    hit = sweep.truth.hit_point
    on_post = np.abs(np.hypot(hit[..., 0] - 0.540, hit[..., 1] - 0.788) - 0.015) < 1e-3
    # the flanks: the post met at 60-66°, the wall behind it 700-760 mm off
    flanks = [(3, 5), (39, 4), (42, 4)]
    for at in flanks:
        assert on_post[at] and 60 < math.degrees(sweep.truth.incidence_rad[at]) < 66
        assert p.reason[at] == Reason.INCIDENCE_UNKNOWN
    # (before: valid, 240-247 mm behind the post on the wall's line)
    err = np.hypot(p.x - hit[..., 0], p.y - hit[..., 1])
    assert err[p.valid].max() < 0.100
    # the post's bright middle readings stay valid, within 40 mm of it (its circle: far_posts)
    middle = on_post & p.valid
    assert middle.sum() == 4 and err[middle].max() < 0.040


def _points(d, reason):
    """(7, 2) Points, rows out of step order; d (m) per row and sensor, NaN where not valid."""
    d = np.asarray(d, dtype=float)
    valid = np.asarray(reason) == Reason.OK
    heading = np.zeros(d.shape)
    return Points(x=d.copy(), y=np.zeros(d.shape), d=d.copy(), theta=np.where(valid, 0.2, np.nan),
                  origin_x=np.zeros(d.shape), origin_y=np.zeros(d.shape), heading=heading,
                  sigma_m=np.where(valid, 0.01, np.nan), iterations=np.ones(d.shape, int),
                  valid=valid, reason=np.asarray(reason, np.uint8), max_range_m=0.8)


@pytest.mark.parametrize("rule", [alone_at_an_edge, alone_at_an_edge_compiled])
def test_members_alone_beside_a_nearer_return_leave_their_line(rule):
    """Steps 0-6 stored in rows ``order``. Sensor 1: line 2 at steps 0, 1, 3, 5, 6; step 2
    silent; step 4 valid on no line 0.25 m nearer than step 3 -> step 3 goes (alone between
    silence and a nearer return); step 5 (0.01 m short of the jump behind step 4) stays.
    Sensor 0: line 1 at steps 0, 2, 5; step 1 INCIDENCE_UNKNOWN whose counts read nearer than
    step 2 by more than the jump even at the drop-out angle, step 3 silent -> step 2 goes;
    step 0 beside it stays (the sweep's first step: its other neighbour is unread); step 5
    beside an INCIDENCE_UNKNOWN step whose counts could lie behind it, and silence -> stays."""
    cal = stand_in_calibration()
    far_inc = cal.max_incidence_rad
    ok, nr, unk = Reason.OK, Reason.NO_RETURN, Reason.INCIDENCE_UNKNOWN
    nan = np.nan
    by_step_d = [[0.60, 0.70], [nan, 0.70], [0.62, nan], [nan, 0.71], [nan, 0.46],
                 [0.64, 0.46 + EDGE_JUMP_M - 0.01], [nan, 0.72]]
    by_step_reason = [[ok, ok], [unk, ok], [ok, nr], [nr, ok], [unk, ok], [ok, ok], [nr, ok]]
    by_step_label = [[1, 2], [-1, 2], [1, -1], [-1, 2], [-1, -1], [1, 2], [-1, 2]]
    counts_by_step = np.full((7, 2), 500.0)
    # step 1, sensor 0: at the drop-out angle still 0.62 - EDGE_JUMP_M - 0.02 m
    counts_by_step[1, 0] = float(cal.counts(0.62 - EDGE_JUMP_M - 0.02, far_inc))
    # step 4, sensor 0: at the drop-out angle 0.60 m, no nearer than step 5's 0.64 - jump
    counts_by_step[4, 0] = float(cal.counts(0.60, far_inc))
    order = np.array([4, 0, 6, 2, 5, 1, 3])              # row r holds step order[r]
    pts = _points(np.array(by_step_d)[order], np.array(by_step_reason)[order])
    label = np.array(by_step_label)[order]
    out, lab = rule(pts, label, counts_by_step[order], order.copy(), cal)
    rows = np.argsort(order)                             # the row of each step
    gone = (out.reason == Reason.INCIDENCE_UNKNOWN) & pts.valid
    assert sorted(zip(*np.nonzero(gone))) == sorted([(rows[2], 0), (rows[3], 1)])
    assert lab[rows[2], 0] == -1 and lab[rows[3], 1] == -1
    assert (lab[~gone] == label[~gone]).all()
    assert out.valid.sum() == pts.valid.sum() - 2
    assert np.isnan(out.d[gone]).all()


@functools.lru_cache(maxsize=1)
def _edge_states():
    """The states the fast estimator asked :func:`alone_at_an_edge_compiled`: the bundled
    t_room, box_room and posts (seed 0) and the post before a far wall above."""
    states = []
    compiled = alone_at_an_edge_compiled

    def spy(*state):
        states.append(state)
        return compiled(*state)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(fast, "alone_at_an_edge_compiled", spy)
        for sc, seed in ((load_scenario("t_room"), 0), (load_scenario("box_room"), 0),
                         (load_scenario("posts"), 0),
                         (loads(POST_BEFORE_FAR_WALL, source="<test>"), 5241)):
            cal, _ = scene_calibration(sc)
            for sweep in pipeline.simulated(sc, seed=seed, progress=False)[0].sweeps:
                fast.estimate(sweep, cal)
    return states


def _spoiled_edge(state, spoil, seed):
    """A state :func:`alone_at_an_edge_compiled` was asked, spoilt as
    :func:`test_the_edge_kernel_agrees_with_its_numpy_statement` says."""
    points, label, counts, steps, cal = state
    rng = np.random.default_rng(seed)
    label, counts, steps = label.copy(), np.array(counts, dtype=float), np.array(steps)
    pick = rng.random(label.shape) < rng.uniform(0.02, 0.3)
    if spoil == "near":         # readings moved to either side of a neighbour's jump
        d = points.d + np.where(pick, rng.choice([-1.0, 1.0], label.shape)
                                * rng.uniform(0.9, 1.1, label.shape) * EDGE_JUMP_M, 0.0)
        points = dataclasses.replace(points, d=d)
    elif spoil == "relabel":
        label = np.where(pick, rng.integers(-1, label.max() + 2, label.shape), label)
    elif spoil == "unlabel":
        label[pick] = -1
    elif spoil == "invalid":
        points = dataclasses.replace(points, valid=points.valid & ~pick)
    elif spoil == "returns":    # readings made returns (or silent) that their counts place
        reason = np.where(pick, rng.choice([Reason.NOT_CONVERGED, Reason.INCIDENCE_UNKNOWN,
                                            Reason.NO_RETURN], label.shape), points.reason)
        points = dataclasses.replace(points, reason=reason.astype(np.uint8),
                                     valid=points.valid & ~pick)
    elif spoil == "counts":     # a return's counts of 0 or NaN: read nowhere
        counts = np.where(pick, rng.choice([0.0, np.nan, 1.0, 4095.0]), counts)
    elif spoil == "steps":      # rows out of step order, or steps held
        steps = rng.permutation(steps) if rng.random() < 0.5 else steps // 5
    elif spoil == "nan":
        points = dataclasses.replace(points, d=np.where(pick, np.nan, points.d))
    return points, label, counts, steps, cal


@settings(max_examples=150, deadline=None)
@given(data=st.data(), spoil=st.sampled_from([None, "near", "relabel", "unlabel", "invalid",
                                               "returns", "counts", "steps", "nan"]))
def test_the_edge_kernel_agrees_with_its_numpy_statement(data, spoil):
    """``alone_at_an_edge_compiled`` (``_lines.edge_alone``) against ``alone_at_an_edge``,
    bit for bit, on the states the fast estimator asked (bundled rooms, the post before a
    far wall), with readings moved across a neighbour's jump or NaN, labels changed or
    dropped, readings invalid or made returns, counts of 0 or NaN, rows out of step order
    or on held steps: the same points and labels."""
    states = _edge_states()
    _edge_agrees(_spoiled_edge(states[data.draw(st.integers(0, len(states) - 1))], spoil,
                               data.draw(st.integers(0, 2 ** 31 - 1))))


def _edge_agrees(state) -> bool:
    """Asserts ``alone_at_an_edge_compiled`` gives ``alone_at_an_edge``'s points and labels
    on ``state``, bit for bit; returns whether the rule took any member."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        slow = alone_at_an_edge(*state)
        now = alone_at_an_edge_compiled(*state)
    for f in ("x", "y", "d", "theta", "sigma_m", "valid", "reason"):
        np.testing.assert_array_equal(getattr(now[0], f), getattr(slow[0], f), err_msg=f)
    np.testing.assert_array_equal(now[1], slow[1])
    return slow[1] is not state[1]


def test_the_edge_kernel_met_readings_alone_and_none():
    """Not vacuous: over the same states, unspoilt, the kernel agrees where some member is
    alone at an edge and where none is (on its own, in any order)."""
    fired = [_edge_agrees(state) for state in _edge_states()]
    assert any(fired) and not all(fired), fired


def test_the_edge_kernel_names_what_it_refuses():
    lab, ok, one = np.zeros(6, dtype=np.intp), np.ones(6, dtype=np.uint8), np.zeros(6)
    with pytest.raises(ValueError, match=r"^edge_alone's arrays differ in length: label 6, "
                                         r"valid 6, d 4, reason 6"):
        fast._lines.edge_alone(lab, ok, np.zeros(4), ok, one, np.arange(3), 2, 5, 7, 0.1,
                               None)
    with pytest.raises(ValueError, match=r"^edge_alone: order never lists row 1 \(it must "
                                         r"hold each of the 3 rows once, in step order\)"):
        fast._lines.edge_alone(lab, ok, one, ok, one, np.array([0, 2, 2]), 2, 5, 7, 0.1, None)
