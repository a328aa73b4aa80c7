"""Far walls drawn outside the room, and far readings > 100 mm off, from short far lines
in a fold-over's second pass (issue 13, fold-over must-show).

- Fragments: the second pass holds out the readings whose branch it cannot decide; what is
  left of a far wall's line can be a fragment of 6-16 members whose direction, from a few
  noisy readings, sets θ 5-15° off: its members read 20-50 mm long, cells 30-50 mm outside
  the room. The first pass held the same readings on a line of at least twice the members;
  they are put where their beams meet it (estimate._onto_first_lines).
- Lines the members disown: a short far line of two sensors can settle 20-45° off the wall
  (its members 100-115 mm long); each member's own range profile (its sensor's neighbouring
  steps) lies on average more than a standard error from the line's θ, and the members
  leave the line (estimate.local_incidence).

docs/foldover.md, "Short far lines". Rooms of our own, every pose 171-179 mm from a wall."""

from __future__ import annotations

import math

import numpy as np
import pytest

from irring import pipeline
from irring.core import distance_to_outline, inside_outline
from irring.estimation import estimate as est
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
    monkeypatch.setattr(est, "REGAIN_RATIO", math.inf)
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
    monkeypatch.setattr(est, "FAR_LINE_Z", math.inf)
    # (3 of the 6 are FOLDOVER_AMBIGUOUS by the straight-trace test; docs/foldover.md)
    assert _readings_over(seed_9750, 0.080) == 3
    monkeypatch.setattr(est, "_near_trace_straight",
                        lambda counts, *a: np.zeros(np.shape(counts), bool))
    assert _readings_over(seed_9750, 0.080) == 6
    assert _readings_over(seed_9750, 0.100) == 3


@pytest.mark.parametrize("effects", ["[foldover]", "[noise, quantization, foldover]"])
def test_a_sensor_with_no_incidence_effect_has_no_line_doubted(effects, monkeypatch):
    # where θ does not change the distance, no θ can read a member long: nothing moves
    sc = loads(PENTAGON + f"effects: {effects}\n", source="<test>")
    sweeps = pipeline.simulated(sc, progress=False)[0].sweeps
    cal = scene_calibration(sc)[0]

    def changed():   # readings that differ from the rule's (validity or distance)
        return sum(int(np.count_nonzero((p.valid != q.valid) | (p.valid & (p.d != q.d))))
                   for p, q in zip(with_rule, (est.estimate(sw, cal) for sw in sweeps)))
    with_rule = [est.estimate(sw, cal) for sw in sweeps]
    z = est.FAR_LINE_Z
    monkeypatch.setattr(est, "FAR_LINE_Z", math.inf)
    assert changed() == 0
    # not vacuous: the slopes do disown lines here (37 and 18 readings leave them without
    # the shift test); FAR_LINE_SHIFT_M is what keeps them
    monkeypatch.setattr(est, "FAR_LINE_Z", z)
    monkeypatch.setattr(est, "FAR_LINE_SHIFT_M", 0.0)
    assert changed() >= 10
