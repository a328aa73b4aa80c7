"""Line members snapped at every step stride (docs/estimator.md, "Snapped at every stride"):
a line needs SNAP_MIN members where every step is read, 1/k of them where every k-th is."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

import irring.estimation.estimate as E
from irring import pipeline, scenario as S
from irring.core import Points
from irring.estimation import estimate_numpy as oracle
from irring.estimation.lines import SNAP_MIN, snap_members, snap_to_lines


def test_a_line_needs_fewer_members_where_fewer_steps_are_read():
    assert SNAP_MIN == 10
    assert snap_members(np.arange(-35, 36)) == 10          # every step
    assert snap_members(np.arange(-35, 36, 2)) == 5        # every other (step_stride 2)
    assert snap_members(np.arange(-36, 37, 3)) == 4        # every third: ⌈10/3⌉
    assert snap_members(np.array([7])) == 10               # one step: no stride to tell
    # a step lost on the way leaves a wider gap, not a coarser stride
    assert snap_members(np.delete(np.arange(-35, 36, 2), 4)) == 5
    # the ring turning back lists steps in any order
    assert snap_members(np.arange(35, -36, -2)) == 5


def seven_on_a_wall() -> Points:
    """One sensor at (-41, 23) mm reading a wall y = 0.8 + 0.3·x every other step (2.16°
    apart), 7 readings, each end point 12 mm long or short along its beam by turns."""
    heading = np.radians(70.0 + 2.16 * np.arange(7))[:, None]
    ox, oy = -0.041, 0.023
    # beam (ox + d cos h, oy + d sin h) meets y = 0.8 + 0.3 x
    d_true = (0.8 + 0.3 * ox - oy) / (np.sin(heading) - 0.3 * np.cos(heading))
    d = d_true + 0.012 * np.array([1, -1, 1, 1, -1, 1, -1])[:, None]
    n = heading.shape
    return Points(x=ox + d * np.cos(heading), y=oy + d * np.sin(heading), d=d,
                  theta=np.full(n, 0.3), origin_x=np.full(n, ox), origin_y=np.full(n, oy),
                  heading=heading, sigma_m=np.full(n, 0.01), iterations=np.ones(n, int),
                  valid=np.ones(n, bool), reason=np.zeros(n, np.uint8), max_range_m=1.5)


def test_a_short_line_read_every_other_step_is_snapped_by_both_estimators():
    """7 members: under SNAP_MIN none moves; with ``min_members`` 5 (every other step)
    each goes onto their fitted line (residual under 1e-9 m), the compiled call and the
    numpy statement alike, and their mean error along the beam falls 12 → 3.9 mm."""
    p = seven_on_a_wall()
    label = np.zeros(p.valid.shape, np.intp)
    for snap in (snap_to_lines, oracle.snap_to_lines):
        assert np.array_equal(snap(p, label, 0.1, math.inf).d, p.d)
        moved = snap(p, label, 0.1, math.inf, 5)
        assert (moved.d != p.d).all()
        x, y = moved.x[:, 0], moved.y[:, 0]
        # all 7 on one line: the cross product of every point with the first two is 0
        cross = (x[1] - x[0]) * (y - y[0]) - (y[1] - y[0]) * (x - x[0])
        assert np.abs(cross).max() < 1e-9
        d_true = p.d - 0.012 * np.array([1, -1, 1, 1, -1, 1, -1])[:, None]
        err = np.abs(moved.d - d_true).mean()
        assert round(err * 1000, 1) == 3.9
    np.testing.assert_allclose(snap_to_lines(p, label, 0.1, math.inf, 5).d,
                               oracle.snap_to_lines(p, label, 0.1, math.inf, 5).d, atol=1e-12)


def test_the_estimate_snaps_a_stride_2_sweeps_short_lines(monkeypatch):
    """t_room read every other step (seed 3): the estimate's first sweep puts 19 members of
    lines of 5–9 onto their lines, their mean error 13.6 → 10.8 mm, where SNAP_MIN alone
    would leave them; read every step, nothing changes."""
    sc = S.load_scenario("t_room")
    runs = {}
    for stride in (1, 2):
        scene = dataclasses.replace(sc, scan=dataclasses.replace(sc.scan, step_stride=stride))
        cal, _ = pipeline.scene_calibration(scene)
        sweep = pipeline.simulated(scene, seed=3, progress=False)[0].sweeps[0]
        now = E.estimate_detail(sweep, cal)
        with monkeypatch.context() as m:
            m.setattr(E, "snap_members", lambda steps: SNAP_MIN)
            before = E.estimate_detail(sweep, cal).points
        runs[stride] = (sweep, now, before)
    _, now, before = runs[1]
    assert np.array_equal(now.points.d, before.d, equal_nan=True)
    sweep, now, before = runs[2]
    changed = now.points.valid & (now.points.d != before.d)
    assert changed.sum() == 19
    lab = now.lines.label
    members = np.bincount(lab[lab >= 0])[lab[changed]]
    assert members.min() >= 5 and members.max() <= 9
    truth = sweep.truth.distance_m[changed]
    err_before = np.abs(before.d[changed] - truth).mean()
    err_now = np.abs(now.points.d[changed] - truth).mean()
    assert round(err_before * 1000, 1) == 13.6 and round(err_now * 1000, 1) == 10.8
