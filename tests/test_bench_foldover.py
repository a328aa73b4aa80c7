"""`irring bench foldover` and `irring bench grazing`: issue 13's fold-over and grazing
must-shows counted on hand-made readings and maps, and the commands' exit statuses."""

from __future__ import annotations

import json
import math
import types

import numpy as np
import pytest

from irring import errors, pipeline
from irring.cli import main
from irring.maps.mapping import OccupancyGrid
from irring.scenario import load_scenario, resolve
from irring.studies import foldover, grazing

# An asymmetric room: a wall rising at 48.6° from the origin (m).
OUTLINE = ((0.0, 0.0), (1.13, 0.0), (1.13, 0.87), (0.766, 0.87))


def _readings(x, y, valid, hit_x, hit_y, sigma=None):
    """A sweep's points and truth, as the checks read them: (S, N) arrays."""
    x, y, hit_x, hit_y = (np.asarray(a, float) for a in (x, y, hit_x, hit_y))
    hit = np.stack([hit_x, hit_y, np.zeros_like(hit_x)], axis=-1)
    sigma = np.full(x.shape, 0.005) if sigma is None else np.asarray(sigma, float)
    return (types.SimpleNamespace(x=x, y=y, valid=np.asarray(valid), sigma_m=sigma),
            types.SimpleNamespace(hit_point=hit))


def test_a_planted_wrong_branch_reading_is_counted_beyond_100_mm_and_nothing_else():
    hx = np.array([[0.40, 0.55, 0.61], [0.30, 0.20, 0.70]])
    hy = np.array([[0.17, 0.02, 0.33], [0.44, 0.90, 0.25]])
    off = np.array([[0.030, 0.101, 0.099], [0.5, 0.0, 0.2]])   # metres along x
    valid = np.array([[True, True, True], [False, True, True]])
    p, truth = _readings(hx + off, hy, valid, hx, hy)
    truth.hit_point[1, 2] = np.nan   # that beam hit nothing: a valid reading there is off
    e = foldover.reading_errors(p, truth.hit_point)
    assert e.size == 5   # the invalid reading 500 mm off is not judged
    assert e[:4] == pytest.approx([0.030, 0.101, 0.099, 0.0])
    assert e[4] == math.inf
    assert int((e > foldover.MAX_ERROR_M).sum()) == 2
    assert foldover.worst_error(e) == (pytest.approx(0.101), 1)   # JSON gets no Infinity
    assert foldover.worst_error(e[4:]) == (None, 1)
    assert foldover.nonfinite_outputs(p) == 0
    p.y[0, 2] = np.nan           # a valid output gone NaN …
    p.sigma_m[1, 1] = np.inf     # … and an infinite σ
    p.sigma_m[1, 0] = np.nan     # an invalid reading's NaN does not count
    assert foldover.nonfinite_outputs(p) == 2


def test_occupied_cells_count_as_outside_only_beyond_one_and_a_half_cells_plus_10_mm():
    grid = OccupancyGrid.covering((-0.2, -0.2), (1.3, 1.0), 0.010)
    cx, cy = grid.cell_centers()
    assert foldover.outside_tolerance_m(grid.resolution_m) == pytest.approx(0.025)

    def occupy(x, y, log_odds=5.0):
        ix, iy = grid.cell_of(x, y)
        grid.log_odds[iy, ix] = log_odds
        return cx[ix], cy[iy]

    occupy(0.50, 0.004)          # on the floor wall: inside or on it
    occupy(0.50, -0.015)         # 15 mm below the floor wall: within the tolerance
    x, y = occupy(1.161, 0.40)   # east of the 1.13 m wall
    assert x - 1.13 > 0.025      # centre 30+ mm out: counted
    occupy(0.50, -0.120)         # far below the floor: counted
    occupy(0.20, 0.60)           # beyond the 48.6° wall (outside, ~0.25 m off): counted
    occupy(0.60, -0.150, log_odds=-5.0)   # free, not occupied: not counted
    occupy(0.90, 0.50, log_odds=0.1)      # unknown: not counted
    assert foldover.cells_outside(grid, OUTLINE) == 3


def test_grazing_bins_rms_and_gain_against_a_hand_made_case():
    e = np.array([0.001, 0.003, 0.004, 0.012, 0.500])
    e0 = np.array([0.002, 0.020, 0.010, 0.030, 0.100])
    inc = np.array([5.0, 50.0, 59.9, 65.0, 75.0])
    table = grazing.bins(e, e0, inc)
    assert [b["n"] for b in table] == [1, 0, 0, 0, 0, 2, 1, 1, 0]
    b50 = table[5]
    assert (b50["lo_deg"], b50["hi_deg"]) == (50, 60)
    assert b50["rms_m"] == pytest.approx(math.sqrt((0.003 ** 2 + 0.004 ** 2) / 2))
    assert b50["rms_theta0_m"] == pytest.approx(math.sqrt((0.02 ** 2 + 0.01 ** 2) / 2))
    assert b50["gain"] == pytest.approx(math.sqrt(500 / 25))
    assert b50["max_m"] == 0.004
    assert table[1]["rms_m"] is None and table[1]["gain"] is None
    band = grazing.band(e, e0, inc, *grazing.GAIN_BAND_DEG)
    assert band["n"] == 3
    assert band["gain"] == pytest.approx(math.sqrt(1400 / 169))   # 2.88: below 3
    # 60–70° at 12 mm misses; 70–80° at 500 mm is past the target's reach
    assert grazing.misses(table, band) == [
        "60–70°: RMS 12.0 mm > 10 mm", "50–70°: θ = 0 only 2.9× worse (target ≥ 3×)"]
    empty = grazing.band(e[:1], e0[:1], inc[:1], *grazing.GAIN_BAND_DEG)
    assert grazing.misses(grazing.bins(e[:1], e0[:1], inc[:1]), empty) == [
        "no reading at 50–70°"]


def _room_file(tmp_path, name: str, seed: int):
    text = resolve(name).read_text().replace(f"name: {name}", f"name: {name}_{seed}")
    text = "\n".join(f"seed: {seed}" if ln.startswith("seed:") else ln
                     for ln in text.splitlines())
    path = tmp_path / f"{name}_{seed}.yaml"
    path.write_text(text)
    return path


def test_foldover_cli_runs_the_other_rooms_and_ends_with_a_bad_files_status(tmp_path, capsys):
    rooms = tmp_path / "rooms"
    rooms.mkdir()
    (rooms / "a_bad.yaml").write_text("name: a_bad\nroom: {outline_mm: [[0, 0], [1, 0]]}\n")
    good = _room_file(rooms, "foldover_corner", 614)
    out = tmp_path / "out"
    status = main(["bench", "foldover", str(rooms), "--seeds", "1", "--out", str(out)])
    assert status == errors.INPUT
    text, err = capsys.readouterr()
    assert err.startswith("irring bench foldover: error: 1 of 2 room(s) not run; ")
    assert str(rooms / "a_bad.yaml") in err
    lines = text.splitlines()
    assert lines[1].startswith("a_bad") and "error:" in lines[1]
    rows = json.loads((out / "foldover.json").read_text())
    run = rows[1]["runs"][0]
    assert (rows[1]["name"], run["seed"]) == ("foldover_corner_614", 614)
    # the fold-over targets: none on the wrong branch, nothing outside, nothing non-finite
    assert run["passed"] and run["far"] == 0 and run["cells_outside"] == 0
    assert run["nonfinite"] == 0 and run["valid"] > 100 and run["ambiguous"] > 0
    assert run["max_error_m"] < foldover.MAX_ERROR_M and run["no_hit"] == 0
    assert lines[2].split()[-1] == "pass"
    # the map's scores, as `irring run` scores that room and seed
    scores = pipeline.run(load_scenario(good), progress=False).scores
    assert {k: run[k] for k in foldover.MAP_SCORES} == {k: scores[k] for k in (
        "occupied_f1", "occupied_precision", "occupied_recall", "free_accuracy")}
    assert 0.3 < run["occupied_f1"] < 0.99 and run["free_accuracy"] > 0.9
    assert rows[1]["sensor"] == "gp2d12"
    assert lines[2].split()[-5] == f"{run['occupied_f1']:.3f}"
    mean = lines[3].split()   # one room of that model, one seed: its own scores
    assert mean[:2] == ["mean", "gp2d12"] and mean[-4] == f"{run['occupied_f1']:.3f}"
    # the good room alone passes: status 0
    assert main(["bench", "foldover", str(good), "--seeds", "1", "--json",
                 "--out", str(out)]) == errors.OK
    assert json.loads(capsys.readouterr().out)[0]["runs"] == rows[1]["runs"]


def test_grazing_cli_names_a_missing_file_and_pools_the_others(tmp_path, capsys):
    assert main(["bench", "grazing", str(tmp_path / "nope.yaml")]) == errors.INPUT
    assert "nope.yaml" in capsys.readouterr().err
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nseed: -3\n")
    good = _room_file(tmp_path, "grazing_corridor", 427)
    status = main(["bench", "grazing", str(bad), str(good), "--json", "--out",
                   str(tmp_path / "o")])
    assert status == errors.INPUT
    r = json.loads(capsys.readouterr().out)
    assert [row["name"] for row in r["rooms"]] == ["bad", "grazing_corridor_427"]
    assert r["rooms"][0]["status"] == errors.INPUT
    assert r["n"] == r["rooms"][1]["n"] == sum(b["n"] for b in r["bins"]) > 1000
    # walls-only corridor: readings out to 60–70°, θ = 0 far worse there
    assert r["bins"][6]["n"] > 0 and r["gain_band"]["gain"] > grazing.GAIN_TARGET


# A GP2D12 (624 mm) facing a wall 650 mm from its emitter: the simulated sensor reads only
# noise from it (the truth has no hit within range), yet the beam does meet it.
PAST_RANGE_ROOM = """
name: past_range
room: {outline_mm: [[-1070, -730], [800, -730], [800, 910], [-1070, 910]]}
robot: {poses: [{x_mm: 0, y_mm: 0, yaw_deg: 0}]}
sensor: {model: gp2d12}
effects: [incidence, noise, quantization, foldover]
"""


def test_a_valid_reading_past_the_range_is_judged_against_the_surface_its_beam_meets():
    from irring.core import points_with
    from irring.estimation.estimate import estimate
    from irring.scenario import loads
    from irring.simulation.sim import SimRing

    sc = loads(PAST_RANGE_ROOM)
    with SimRing(sc) as sim:
        sw = sim.sweep(0)
    s, k = int(np.flatnonzero(np.asarray(sw.steps) == 0)[0]), 0   # sensor 0 faces +x
    t = sw.truth
    assert not np.isfinite(t.distance_m[s, k])
    o, u = t.origin[s, k], t.direction[s, k]
    wall = (0.800 - o[0]) / u[0]       # how far along the beam it meets the wall at x = 0.8
    assert 0.624 < wall < 0.660
    # a reading planted valid on that beam, 0.57 m out: short of the wall by wall - 0.57
    p = estimate(sw)
    valid = np.zeros_like(p.valid)
    valid[s, k] = True
    x, y = p.x.copy(), p.y.copy()
    x[s, k], y[s, k] = o[0] + 0.570 * u[0], o[1] + 0.570 * u[1]
    p = points_with(p, valid=valid, x=x, y=y)
    assert foldover.reading_errors(p, t.hit_point).tolist() == [math.inf]   # the truth alone
    hit, n = foldover.hits_past_range(sw, p, sc)
    assert n == 1
    assert hit[s, k, :2] == pytest.approx([0.800, o[1] + wall * u[1]], abs=1e-6)
    assert foldover.reading_errors(p, hit) == pytest.approx([wall - 0.570], abs=1e-6)
    # every other beam keeps its truth
    other = np.ones(valid.shape, dtype=bool)
    other[s, k] = False
    np.testing.assert_array_equal(hit[other], t.hit_point[other])
