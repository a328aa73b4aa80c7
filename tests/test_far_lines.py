"""Far walls drawn outside the room, and far readings > 100 mm off, from short far lines
in a fold-over's second pass (issue 13, fold-over must-show), and the same doubt of short far
lines on every sweep (a GP2D12 that does not fold, below).

- Fragments: the second pass holds out the readings whose branch it cannot decide; what is
  left of a far wall's line can be a fragment of 6-16 members whose direction, from a few
  noisy readings, sets θ 5-15° off: its members read 20-50 mm long, cells 30-50 mm outside
  the room. The first pass held the same readings on a line of at least twice the members;
  they are put where their beams meet it (foldover._onto_first_lines).
- Lines the members disown: a short far line of two sensors can settle 20-45° off the wall
  (its members 100-115 mm long); each member's own range profile (its sensor's neighbouring
  steps) lies on average more than a standard error from the line's θ, and the members
  leave the line (far_lines.doubt_far_lines).

docs/foldover.md, "Short far lines". Rooms of our own, every pose 171-179 mm from a wall
but those of the GP2D12 that does not fold (at the end)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from irring import pipeline
from irring.core import Reason, distance_to_outline, inside_outline
from irring.estimation import estimate as est
from irring.estimation import bends as est_bends
from irring.estimation import counts as est_counts
from irring.estimation import far_lines as est_far_lines
from irring.estimation import foldover as est_foldover
from irring.estimation import profiles as est_profiles
from irring.estimation.calibration import scene_calibration
from irring.maps import mapping
from irring.scenario import loads

QUAD = """
name: far_line_quad
seed: 9802
room: {outline_mm: [[2548.7, 1930.6], [737.8, 2162.8], [191.0, 1128.6], [421.8, 924.0]]}
robot:
  poses:
    - {x_mm: 1506.19, y_mm: 1632.26, yaw_deg: -26}
    - {x_mm: 831.81, y_mm: 1966.64, yaw_deg: 29}
    - {x_mm: 1383.7, y_mm: 1906.23, yaw_deg: 8}
sensor: {model: gp2d12, max_range_mm: 624, adc_bits: 12}
map: {resolution_mm: 10}
effects: [incidence, noise, quantization, foldover]
"""


PENTAGON = """
name: far_line_pentagon
seed: 9732
room: {outline_mm: [[0, 0], [1900, -250], [2500, 900], [1300, 1950], [-200, 1300]]}
obstacles:
  - {type: box, center_mm: [1500, 900], size_mm: [240, 410], yaw_deg: -14}
robot:
  poses:
    - {x_mm: 1910.39, y_mm: 139.6, yaw_deg: 17}
    - {x_mm: 456.17, y_mm: 1389.26, yaw_deg: -33}
    - {x_mm: 1466.83, y_mm: -16.5, yaw_deg: 4}
sensor: {model: gp2d12, max_range_mm: 624, adc_bits: 12}
map: {resolution_mm: 10}
"""
FOLDING = PENTAGON + "effects: [incidence, noise, quantization, foldover]\n"


def _worst_reading_and_cells_outside(text: str):
    """(the largest valid end point's distance from its true hit, the occupied cells whose
    centre lies more than 1.5 cells + 10 mm outside the room) of one run, metres."""
    sc = loads(text, source="<test>")
    run = pipeline.run(sc, progress=False)
    worst = 0.0
    for sw, p in zip(run.sweeps, run.points):
        hit = sw.truth.hit_point
        err = np.hypot(p.x - hit[..., 0], p.y - hit[..., 1])[p.valid]
        assert np.all(np.isfinite(err))
        worst = max(worst, float(err.max(initial=0.0)))
    grid = run.grid
    iy, ix = np.nonzero(mapping.classify(grid.log_odds) == mapping.OCCUPIED)
    x = grid.origin_xy_m[0] + (ix + 0.5) * grid.resolution_m
    y = grid.origin_xy_m[1] + (iy + 0.5) * grid.resolution_m
    outline = sc.room.outline_m
    out = ~inside_outline(x, y, outline) & (distance_to_outline(x, y, outline)
                                            > 1.5 * grid.resolution_m + 0.010)
    return worst, int(out.sum())


def test_a_fragment_of_a_far_line_is_read_on_the_first_passs_line():
    worst, outside = _worst_reading_and_cells_outside(QUAD)
    assert worst <= 0.030 and outside == 0, (worst, outside)


def test_without_the_first_passs_line_the_fragment_draws_wall_outside(monkeypatch):
    # main before this: a reading 48 mm off, two occupied cells 30-40 mm outside the room
    # (the cells stay inside since a line decides "far" only where it is seen)
    monkeypatch.setattr(est_foldover, "REGAIN_RATIO", math.inf)
    worst, _ = _worst_reading_and_cells_outside(QUAD)
    assert worst > 0.040


def _readings_over(text: str, limit_m: float) -> int:
    """Valid end points of one run more than ``limit_m`` from their true hit."""
    run = pipeline.run(loads(text, source="<test>"), progress=False)
    return sum(int(np.count_nonzero(np.hypot(p.x - sw.truth.hit_point[..., 0],
                                             p.y - sw.truth.hit_point[..., 1])[p.valid]
                                    > limit_m)) for sw, p in zip(run.sweeps, run.points))


def test_a_short_far_line_its_members_disown_is_left():
    # one reading stays 111 mm off: a wall met at 65° that a 20-member line adopted at 14°
    assert _readings_over(FOLDING, 0.080) <= 1


def test_without_the_rule_the_far_line_kept_readings_100_mm_off(monkeypatch):
    # no line ever doubted: a line of two sensors at θ 1-8° on a wall met at 40-53° keeps
    # six readings 91-116 mm long (seed 9750; seed 9732's 13-member line of that kind,
    # 80-115 mm long, no longer forms since a line decides "far" only where the reading's
    # own far trace agrees: its readings are FOLDOVER_AMBIGUOUS)
    seed_9750 = FOLDING.replace("seed: 9732", "seed: 9750")
    assert _readings_over(seed_9750, 0.080) == 0
    monkeypatch.setattr(est_far_lines, "FAR_LINE_Z", math.inf)
    # facets_reread's split with a piece of 3-5 members takes them too (the line bends over
    # the two walls); without it as well:
    assert _readings_over(seed_9750, 0.080) == 0
    monkeypatch.setattr(est_bends, "REREAD_SMALL_CHI", math.inf)
    # (3 of the 6 are FOLDOVER_AMBIGUOUS by the straight-trace test; docs/foldover.md)
    assert _readings_over(seed_9750, 0.080) == 3
    monkeypatch.setattr(est_foldover, "_near_trace_straight",
                        lambda counts, *a: np.zeros(np.shape(counts), bool))
    assert _readings_over(seed_9750, 0.080) == 6
    assert _readings_over(seed_9750, 0.100) == 3


@pytest.mark.parametrize("effects, without_shift", [("[foldover]", 0),
                                                    ("[noise, quantization, foldover]", 9)])
def test_a_sensor_with_no_incidence_effect_has_no_line_doubted(effects, without_shift,
                                                               monkeypatch):
    # where θ does not change the distance, no θ can read a member long: nothing moves
    sc = loads(PENTAGON + f"effects: {effects}\n", source="<test>")
    sweeps = pipeline.simulated(sc, progress=False)[0].sweeps
    cal = scene_calibration(sc)[0]

    def changed():   # readings that differ from the rule's (validity or distance)
        return sum(int(np.count_nonzero((p.valid != q.valid) | (p.valid & (p.d != q.d))))
                   for p, q in zip(with_rule, (est.estimate(sw, cal) for sw in sweeps)))
    with_rule = [est.estimate(sw, cal) for sw in sweeps]
    z = est_far_lines.FAR_LINE_Z
    monkeypatch.setattr(est_far_lines, "FAR_LINE_Z", math.inf)
    assert changed() == 0
    # with noise the slopes do disown a line here (9 readings leave it without the shift
    # test): FAR_LINE_SHIFT_M is what keeps it. Noise-free, the profiles whose window sees
    # their line alone agree with it (those across a corner, which once disowned lines of
    # 37 readings, judge no line that has three others)
    monkeypatch.setattr(est_far_lines, "FAR_LINE_Z", z)
    monkeypatch.setattr(est_far_lines, "FAR_LINE_SHIFT_M", 0.0)
    assert changed() == without_shift


# A GP2D12 without fold-over (the rule once ran only in a fold-over's second pass): a room of
# our own with 113-147° corners, one pose 250-560 mm from its walls
def _corner_room(seed: int, pose: str) -> str:
    return f"""
name: far_line_corners
seed: {seed}
room: {{outline_mm: [[1210, 480], [805, 1160], [140, 1470], [-610, 1130], [-880, 330],
                     [-390, -310], [990, 40]]}}
robot: {{poses: [{pose}]}}
sensor: {{model: gp2d12, adc_bits: 12}}
map: {{resolution_mm: 10}}
effects: [incidence, noise, quantization]
"""


def _left_and_before(text: str, monkeypatch):
    """(run, the same run with no line ever voted off (FAR_LINE_Z = inf), and for each line
    member the rules took off its line: (sensor, placed at its own slope)) of a one-pose
    scene."""
    sc = loads(text, source="<test>")
    leave, left = est_profiles.leave_doubted_line, []

    def recording(points, label, vi, pos, *args, **kwargs):
        out = leave(points, label, vi, pos, *args, **kwargs)
        at = vi[pos]
        at = at[out[1].reshape(-1)[at] < 0]     # (not those ``stay`` kept on their line)
        left.extend(zip((at % points.valid.shape[1]).tolist(),
                        out[0].valid.reshape(-1)[at].tolist()))
        return out
    monkeypatch.setattr(est_counts, "leave_doubted_line", recording)
    monkeypatch.setattr(est_far_lines, "leave_doubted_line", recording)
    run = pipeline.run(sc, progress=False)
    with monkeypatch.context() as m:
        m.setattr(est_far_lines, "FAR_LINE_Z", math.inf)
        before = pipeline.run(sc, progress=False)
    return run, before, left


def _readings_over_run(run, limit_m: float) -> int:
    """Valid end points of a run more than ``limit_m`` from their true hit."""
    return sum(int(np.count_nonzero(np.hypot(p.x - sw.truth.hit_point[..., 0],
                                             p.y - sw.truth.hit_point[..., 1])[p.valid]
                                    > limit_m)) for sw, p in zip(run.sweeps, run.points))


def test_a_gp2d12_line_across_a_corner_its_members_disown_is_left(monkeypatch):
    # a 13-member line of sensors 1 and 2 at 580-620 mm settled at θ 39-53° on walls met at
    # 15-30°: its members read 37-81 mm short, cells in front of the wall. Their own
    # profiles disown it; too flat to place, all 13 become INCIDENCE_UNKNOWN
    run, before, left = _left_and_before(
        _corner_room(4108, "{x_mm: 661, y_mm: 959, yaw_deg: 105.4}"), monkeypatch)
    assert len(left) == 13 and {k for k, _ in left} == {1, 2}
    assert not any(placed for _, placed in left)
    p0, hit = before.points[0], before.sweeps[0].truth.hit_point
    gone = p0.valid & (run.points[0].reason == Reason.INCIDENCE_UNKNOWN)
    err0 = np.hypot(p0.x - hit[..., 0], p0.y - hit[..., 1])[gone]
    assert err0.size == 13 and 0.035 < err0.min() and err0.max() < 0.085
    assert _readings_over_run(before, 0.050) == 10 and _readings_over_run(run, 0.050) == 0
    # (0.952 and F1 0.955 without the rule since the near wall is read below the GP2D12's
    # 100 mm, docs/calibration.md; 0.942 and 0.950 since the mapper's hit floor stays in its
    # end point's cell; 0.94 and +0.03 before)
    assert before.scores["occupied_precision"] < 0.955
    assert run.scores["occupied_precision"] > 0.99
    assert run.scores["occupied_f1"] > before.scores["occupied_f1"] + 0.02


def test_lines_of_up_to_25_members_are_asked(monkeypatch):
    # a 21-member line of sensors 0 and 1 bridges a corner's drop-out gap: at θ 4-25° on
    # walls met at 15-32° and, before the gap, 60-61° (two members 61-77 mm short). Asked
    # (up to FAR_LINE_MAX_MEMBERS = 25), its members' profiles disown it: 10 are read at
    # their own slope, 11 are INCIDENCE_UNKNOWN. rejoin_traces, after the doubt, leaves no
    # reading over 50 mm off, asked or not; without it (and without past_other_lines, later,
    # which takes those of the 'before' past the corner as well), as before:
    text = _corner_room(5025, "{x_mm: 538, y_mm: 915, yaw_deg: 120.8}")
    with monkeypatch.context() as m:
        m.setattr(est, "rejoin_traces", lambda points, label, *args: (points, label))
        m.setattr(est, "past_other_lines", lambda points, label, *args: (points, label))
        # (and the later faceted_lines: with rejoin_traces off it splits a line of this
        # sweep and puts one more reading over 50 mm off, 3 for 2)
        m.setattr(est_bends, "faceted_lines", lambda before, label, after, cal: after)
        run, before, left = _left_and_before(text, m)
        assert len(left) == 21 and {k for k, _ in left} == {0, 1}
        assert sum(placed for _, placed in left) == 10
        assert _readings_over_run(before, 0.050) == 4 and _readings_over_run(run, 0.050) == 2
    run, before, left = _left_and_before(text, monkeypatch)
    assert len(left) == 21 and {k for k, _ in left} == {0, 1}
    assert sum(placed for _, placed in left) == 10
    assert _readings_over_run(before, 0.050) == 0 and _readings_over_run(run, 0.050) == 0
    # with the cap at 16 the line is not asked: the run is the one with no line doubted
    monkeypatch.setattr(est_far_lines, "FAR_LINE_MAX_MEMBERS", 16)
    monkeypatch.setattr(est_foldover, "FAR_LINE_MAX_MEMBERS", 16)
    left.clear()
    capped = pipeline.run(loads(text, source="<test>"), progress=False)
    assert not left
    assert np.array_equal(capped.points[0].d, before.points[0].d, equal_nan=True)
