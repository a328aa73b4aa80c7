"""A curved wall made of straight pieces, seen with fold-over (docs/foldover.md, "Curved
walls"): the lines fitted each over several of its pieces read their members at a θ 10-30°
off and 20-60 mm long, drawing the wall outside the room; the circle the lines lie on reads
them at its own incidence."""

from __future__ import annotations

import numpy as np
import pytest

from irring import pipeline
from irring.estimation import estimate as est
from irring.estimation import bends as est_bends
from irring.estimation import foldover as est_foldover
from irring.estimation.calibration import scene_calibration
from irring.scenario import load_scenario, loads
from irring.studies.foldover import cells_outside, reading_errors

# a round room of 29 pieces (radius 490 mm to its corners), the ring 180 mm from its wall,
# a GP2Y0A21 mapped on 6 mm cells (our own; drawn by a seeded script as a fold-over room of
# the held-out sets' "arc" family)
_ANGLES = np.arange(29) * 2 * np.pi / 29
ROUND_ROOM = f"""
name: round_room_29
seed: 214
room: {{outline_mm: {[[round(1601 + 490 * float(np.cos(a)), 1), round(1600 + 490 * float(np.sin(a)), 1)]
                     for a in _ANGLES]}}}
robot: {{poses: [{{x_mm: 1796.8, y_mm: 1376.2, yaw_deg: 21.0}}]}}
sensor: {{model: gp2y0a21}}
effects: [incidence, noise, quantization, foldover]
map: {{resolution_mm: 6}}
"""


def _run(text: str, seed: int, arcs: bool, monkeypatch):
    sc = loads(text)
    with monkeypatch.context() as m:
        if not arcs:
            m.setattr(est_foldover, "onto_concave_arcs", lambda p, *a, **k: p)
            # (the lines as the snap left them: facets_reread would split those lines the
            # circle takes, and leave 78 readings INCIDENCE_UNKNOWN)
            m.setattr(est_foldover, "facets_reread", lambda p, *a, **k: p)
        run = pipeline.run(sc, seed=seed, progress=False)
    errors = np.concatenate([reading_errors(p, sw.truth.hit_point) for sw, p in zip(run.sweeps, run.points)])
    return sc, run, errors


def test_a_round_rooms_wall_is_read_on_its_circle_not_outside_the_room(monkeypatch):
    sc, with_arcs, err = _run(ROUND_ROOM, 214, True, monkeypatch)
    _, lines_only, err_lines = _run(ROUND_ROOM, 214, False, monkeypatch)
    outline = sc.room.outline_m
    # the lines alone: members 2-6σ long, 70 cells drawn more than 1.5 cells + 10 mm out,
    # the worst reading 56 mm off, RMS 14.6 mm
    assert cells_outside(lines_only.grid, outline) > 50
    assert err_lines.max() > 0.050 and np.sqrt(np.mean(err_lines ** 2)) > 0.012
    # on the circle: none out, every valid reading within 5 mm of its true hit (RMS 1.6 mm)
    assert cells_outside(with_arcs.grid, outline) == 0
    assert err.size == err_lines.size         # the same readings valid: only moved
    assert err.max() < 0.010 and np.sqrt(np.mean(err ** 2)) < 0.003
    assert with_arcs.scores["occupied_f1"] > lines_only.scores["occupied_f1"] + 0.1


@pytest.mark.parametrize("name, seeds", [("foldover_corner", (613, 614)),
                                         ("fold_room", (7, 8))])
def test_a_polygon_rooms_readings_are_not_moved(name, seeds, monkeypatch):
    from tests.test_foldover import ROOM   # (the fold-over room of test_foldover)
    sc = (load_scenario(name) if name == "foldover_corner"
          else loads(ROOM + "effects: [incidence, noise, quantization, foldover]\n"))
    cal, _ = scene_calibration(sc)
    for seed in seeds:
        acq, _ = pipeline.simulated(sc, seed=seed, progress=False)
        for sw in acq.sweeps:
            got = est.estimate(sw, cal)
            with monkeypatch.context() as m:
                m.setattr(est_foldover, "onto_concave_arcs", lambda p, *a, **k: p)
                lines_only = est.estimate(sw, cal)
            np.testing.assert_array_equal(got.valid, lines_only.valid)
            np.testing.assert_array_equal(got.d[got.valid], lines_only.d[got.valid])
            np.testing.assert_array_equal(got.sigma_m[got.valid],
                                          lines_only.sigma_m[got.valid])


def test_a_circle_is_refitted_to_its_readings_at_its_own_incidence():
    # noise-free counts of a circle of radius 0.6 m seen from inside, read from a start
    # 100 mm off in radius and 50 mm off in centre: the circle and every θ come back
    sc = loads(ROUND_ROOM)
    cal, _ = scene_calibration(sc)
    cx, cy, r = 0.1, -0.05, 0.6
    heading = np.linspace(-1.2, 1.2, 40)
    ox, oy = np.full(40, 0.3), np.full(40, 0.0)
    ux, uy = np.cos(heading), np.sin(heading)
    t, cos = est_bends._beam_meets_circle(ox, oy, ux, uy, cx, cy, r)
    counts = np.asarray(cal.counts(t, np.arccos(cos)), dtype=float)
    got = est_bends._read_on_circle(np.arange(40), ox, oy, ux, uy, counts, cal,
                                    (cx + 0.05, cy, r - 0.1))
    assert got is not None
    (fx, fy, fr), chi2, theta = got
    assert abs(fx - cx) < 1e-4 and abs(fy - cy) < 1e-4 and abs(fr - r) < 1e-4
    np.testing.assert_allclose(theta, np.arccos(cos), atol=1e-4)
    # a circle that would hold an emitter outside it (a post seen from outside) is refused
    assert est_bends._read_on_circle(np.arange(40), ox + 1.0, oy, ux, uy, counts, cal,
                                     (cx, cy, 0.3)) is None
