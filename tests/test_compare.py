"""Design comparison: detection geometry from the built models, and simulated scenes."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from irring.studies import compare, geometry
from irring import designs

DEG = math.pi / 180


# --------------------------------------------------------------------------- detection


def test_rays_come_from_the_built_model():
    rays = geometry.design_rays(designs.get("rotating12"))
    assert len(rays) == 71 * 12
    # sensor 0 at its first step: the emitter d_o right of the hinge at (0.15, 0), beam −37.8°
    h = -37.8 * DEG
    np.testing.assert_allclose(rays.direction[0], [math.cos(h), math.sin(h)], atol=1e-9)
    np.testing.assert_allclose(rays.origin[0], [0.15 + 0.007 * math.sin(h), -0.007 * math.cos(h)],
                               atol=1e-9)
    sonar = geometry.design_rays(designs.get("sonar12"))
    assert len(sonar) == 12 * 121            # a fan every 0.25° across ±15°


def test_a_centred_scanner_matches_eq1():
    """The laser (one emitter at the centre, 0.5° steps) misses exactly Eq. 1's cylinder."""
    d = np.array([0.5, 1.0, 2.0])
    det = geometry.detection(designs.get("laser"), d, bearings=60)
    eq1 = geometry.blind_spot_m(d, 0.5 * DEG)
    np.testing.assert_allclose(det.min_detectable_radius_m, eq1, rtol=0.03)
    assert np.all(det.max_missed_radius_m < det.min_detectable_radius_m)


def test_overlap_beats_a_single_scanner_and_radial_rings_miss_table_legs():
    d = (0.35, 0.55, 0.7)
    ring = geometry.detection(designs.get("rotating12"), d, bearings=120)
    single = geometry.detection(designs.get("rotating1"), d, bearings=60)
    radial = geometry.detection(designs.get("radial12"), d, bearings=120)
    # overlapping sweeps of neighbours close the gaps a single 1.08° scanner leaves
    assert ring.min_detectable_radius_m[0] < 0.8 * single.min_detectable_radius_m[0]
    # past the GP2's 624 mm the centred scanner sees nothing; the ring still reaches
    assert math.isinf(single.min_detectable_radius_m[2])
    assert ring.min_detectable_radius_m[2] < 0.01
    # a 22 mm table leg hides between radial beams 30° apart
    assert np.all(radial.min_detectable_radius_m > 0.1)


# --------------------------------------------------------------------------- scenes

from irring.maps.metrics import SCORE_KEYS  # noqa: E402
from irring.scenario import load_scenario  # noqa: E402


@pytest.fixture(scope="module")
def cylinder_runs():
    """t_room_cylinder (paper Fig. 16) seen by three designs, three seeds each."""
    sc = load_scenario("t_room_cylinder")
    return {name: [compare.run_scene(sc, name, sc.seed + k) for k in range(3)]
            for name in ("rotating12", "radial12", "rotating1")}


def test_rotating_ring_sees_the_wall_behind_the_table_leg(cylinder_runs):
    """The paper's Fig. 4 vs Fig. 16 point: overlapping rotating sensors map the wall behind a
    thin cylinder; a radial ring and a single rotating scanner at the centre do not."""
    shadow = {n: float(np.mean([r["shadow"] for r in runs])) for n, runs in cylinder_runs.items()}
    assert shadow["rotating12"] >= 0.4, shadow
    assert shadow["rotating12"] >= shadow["radial12"] + 0.3, shadow
    assert shadow["rotating12"] >= shadow["rotating1"] + 0.3, shadow


def test_run_records_carry_run_scores_and_hardware_time(cylinder_runs):
    r = cylinder_runs["rotating12"][0]
    assert set(SCORE_KEYS) | {"hardware_time_s", "compute_time_s"} <= set(r)
    assert r["hardware_time_s"] == pytest.approx(71 * 0.0383)
    assert cylinder_runs["radial12"][0]["hardware_time_s"] == pytest.approx(0.0383)
    assert cylinder_runs["rotating1"][0]["hardware_time_s"] == pytest.approx(334 * 0.0383)
    assert r["readings"] == 71 * 12
    # the same scene and seed give the same map
    again = compare.run_scene(load_scenario("t_room_cylinder"), "rotating12", r["seed"])
    assert {k: again[k] for k in SCORE_KEYS} == {k: r[k] for k in SCORE_KEYS}


def test_laser_and_sonar_run_through_the_same_pipeline():
    sc = load_scenario("t_room_cylinder")
    laser = compare.run_scene(sc, "laser")
    sonar = compare.run_scene(sc, "sonar12")
    assert laser["readings"] == 720 and sonar["readings"] == 12
    assert laser["occupied_f1"] > 0.9               # a fine, accurate scanner maps the room
    assert sonar["occupied_f1"] < laser["occupied_f1"]  # nearest echo smears azimuth
    assert laser["hardware_time_s"] < 0.05 and sonar["hardware_time_s"] == pytest.approx(0.588)


def test_cli_compare_writes_table_csv_json_and_chart(tmp_path, capsys, monkeypatch):
    import csv
    import json
    import shutil

    from irring.cli import main
    from irring.studies import compare as compare_mod

    real, results = compare_mod.compare, []   # the runs once: the table prints the same ones
    monkeypatch.setattr(compare_mod, "compare",
                        lambda *a, **k: results[0] if results else results.append(
                            real(*a, **k)) or results[0])
    out = tmp_path / "cmp"
    argv = ["compare", "--scenario", "t_room_cylinder", "--design", "rotating12", "--design",
            "radial12", "--seeds", "1", "--bearings", "16", "--distances-mm", "400",
            "--out", str(out)]
    assert main(argv + ["--json"]) == 0
    records = json.loads(capsys.readouterr().out)
    assert [r["design"] for r in records] == ["rotating12", "radial12"]
    for r in records:
        assert set(SCORE_KEYS) | {"hardware_time_s"} <= set(r)
        assert len(r["min_detectable_radius_m"]) == 1
    with open(out / "compare.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["design"] for r in rows] == ["rotating12", "radial12"]
    assert float(rows[0]["hardware_time_s"]) == pytest.approx(2.7193)
    assert (out / "compare.png").stat().st_size > 10_000
    assert json.loads((out / "compare.json").read_text())["runs"][0]["scenario"] == \
        "t_room_cylinder"
    # the same result: its chart is the one drawn and checked above, copied, not drawn again
    monkeypatch.setattr(compare_mod, "chart",
                        lambda result, path: shutil.copyfile(out / "compare.png", path))
    assert main(argv) == 0 and len(results) == 1
    text = capsys.readouterr().out
    assert "rotating12" in text and "360° view" in text and "2.72 s" in text


def test_table_prints_the_shadow_of_one_scan_and_of_four_scans():
    from irring.studies import compare as compare_mod

    def rec(name, one, four):
        scores = {"occupied_f1": 0.9, "free_accuracy": 1.0, "coverage": 0.8, "shadow": 0.7}
        return {"design": name, **scores, "hardware_time_s": 2.72, "compute_time_s": 0.004,
                "scenarios": ["t_room", "t_room_cylinder", "t_room_three_cylinders"],
                "poses": {"t_room": 4, "t_room_cylinder": 1, "t_room_three_cylinders": 4},
                "by_scenario": {"t_room": {**scores, "shadow": None},
                                "t_room_cylinder": {**scores, "shadow": one},
                                "t_room_three_cylinders": {**scores, "shadow": four}}}

    text = compare_mod.table([rec("rotating12", 1.0, 0.53), rec("laser", 0.15, 0.875)])
    head, _, ring, laser, legend = text.splitlines()
    assert "shadow 1 scan" in head and "shadow 4 scans" in head
    assert head.index("shadow 1 scan") < head.index("shadow 4 scans")
    assert "1.00" in ring.split() and "0.53" in ring.split()
    assert "0.15" in laser.split() and "0.88" in laser.split()
    assert legend == "shadow 1 scan: t_room_cylinder, shadow 4 scans: t_room_three_cylinders"


def test_table_with_one_room_hiding_wall_prints_its_shadow_once():
    """A designer's own room beside t_room: the table printed "shadow 0.474" and "shadow 2
    scans 0.47", the same figure twice, with a legend naming the room for the second."""
    from irring.studies import compare as compare_mod

    def rec(name, shadow):
        scores = {"occupied_f1": 0.9, "free_accuracy": 1.0, "coverage": 0.8, "shadow": shadow}
        return {"design": name, **scores, "hardware_time_s": 2.72, "compute_time_s": 0.004,
                "scenarios": ["office", "t_room"], "poses": {"office": 2, "t_room": 4},
                "by_scenario": {"office": scores, "t_room": {**scores, "shadow": None}}}

    head, _, ring, radial, legend = compare_mod.table(
        [rec("rotating12", 0.4744), rec("radial12", 0.0)]).splitlines()
    assert head.split()[:6] == ["design", "F1", "occ", "free", "acc", "coverage"]
    assert head.split().count("shadow") == 1 and "scans" not in head
    assert ring.split()[:5] == ["rotating12", "0.900", "1.000", "0.800", "0.474"]
    assert radial.split()[4:6] == ["0.000", "2.72"]
    assert legend == ("shadow: in office (2 scans), the one scenario here that hides wall "
                      "behind an obstacle")


@pytest.mark.parametrize("design", ["rotating12", "laser"])
def test_chart_with_nothing_to_label_draws_no_empty_legend(tmp_path, design):
    """t_room hides no wall behind a post (an empty shadow panel) and a laser has no
    detection curve: neither may warn, so `python -W error` runs compare."""
    import warnings

    from irring.cli import main

    out = tmp_path / "cmp"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert main(["compare", "--scenario", "t_room", "--design", design, "--seeds", "1",
                     "--workers", "1", "--bearings", "16", "--distances-mm", "90000",
                     "--out", str(out)]) == 0
    assert (out / "compare.png").stat().st_size > 10_000


def test_table_heads_each_detection_distance_with_its_own_value():
    """--distances-mm 0.0001 headed its column "r@0mm"; 250.5 read "r@250mm"."""
    from irring.studies import compare as compare_mod

    scores = {"occupied_f1": 0.9, "free_accuracy": 1.0, "coverage": 0.8, "shadow": None}
    rec = {"design": "rotating12", **scores, "hardware_time_s": 2.72, "compute_time_s": 0.004,
           "scenarios": ["t_room"], "poses": {"t_room": 4}, "by_scenario": {"t_room": scores},
           "detection_distances_m": [1e-7, 0.2505, 0.75],
           "min_detectable_radius_m": [None, 0.0121, 0.02]}
    head, _, row = compare_mod.table([rec]).splitlines()[:3]
    assert head.split()[-3:] == ["r@0.0001mm", "r@250.5mm", "r@750mm"]
    assert row.split()[-3:] == ["miss", "12.1mm", "20.0mm"]


def test_an_undefined_shadow_says_why_in_the_table_and_the_chart(tmp_path, figures):
    """A room of one's own with posts whose walls lie beyond the sensors' reach: the chart
    said "no scenario here hides a wall behind a thin post" and the table's "—" went
    unexplained."""
    from irring.studies import compare as compare_mod

    scores = {"occupied_f1": 0.9, "free_accuracy": 1.0, "coverage": 0.8, "shadow": None}
    rec = {"design": "rotating12", **scores, "hardware_time_s": 2.72, "compute_time_s": 0.004,
           "runs": 1, "scenarios": ["lab"], "poses": {"lab": 3},
           "by_scenario": {"lab": scores}, "min_detectable_radius_m": [0.002]}
    assert compare_mod.table([rec]).splitlines()[-1] == (
        "shadow —: n/a, no wall in the sensors' reach is hidden behind an obstacle from every "
        "pose centre (in any of these scenarios)")
    compare_mod.chart({"designs": [rec], "detection_distances_m": [0.35]}, tmp_path / "c.png")
    texts = [t.get_text() for ax in figures[0].axes for t in ax.texts]
    assert ("shadow n/a: no wall in the sensors' reach is hidden behind an\n"
            "obstacle from every pose centre (in any of these scenarios)") in texts


def test_the_chart_writes_each_score_on_its_bar(tmp_path, figures):
    """Two rings at F1 0.990 and 0.992 drew bars of one height on the 0 … 1 axis: each bar
    carries its value (inside a tall bar, above a short one), the shadow's too."""
    from irring.studies import compare as compare_mod

    def rec(name, f1, cov, shadow):
        scores = {"occupied_f1": f1, "free_accuracy": 1.0, "coverage": cov, "shadow": shadow}
        return {"design": name, **scores, "hardware_time_s": 2.72, "compute_time_s": 0.004,
                "runs": 1, "scenarios": ["lab"], "poses": {"lab": 1},
                "by_scenario": {"lab": scores}, "min_detectable_radius_m": [0.002]}

    compare_mod.chart({"designs": [rec("a", 0.9904, 0.8763, 0.625), rec("b", 0.9916, 0.083, 0.0)],
                       "detection_distances_m": [0.35]}, tmp_path / "c.png")
    scores_ax, shadow_ax = figures[0].axes[:2]
    got = sorted((t.get_text(), t.get_color()) for t in scores_ax.texts)
    assert got == sorted([("0.990", "white"), ("1.000", "white"), ("0.876", "white"),
                          ("0.992", "white"), ("1.000", "white"), ("0.083", "black")])
    assert sorted(t.get_text() for t in shadow_ax.texts) == ["0", "0.625"]


ROOM_WITHOUT_POSTS = """\
name: lab_no_posts
room: {outline_mm: [[0, 0], [1900, 0], [1900, 700], [1200, 1300], [0, 1300]]}
obstacles: [{type: box, center_mm: [1500, 250], size_mm: [200, 120]}]
robot: {poses: [{x_mm: 700, y_mm: 500}]}
"""


def test_the_chart_marks_the_compared_rooms_cylinders_and_no_others(tmp_path, figures):
    """compare.png drew "t_room_cylinder's table leg, r = 22 mm" whatever rooms were
    compared: it marks the radii of the compared rooms' own cylinders, each
    once, and nothing in a room without one."""
    from irring.scenario import load_scenario, loads

    own = loads(ROOM_WITHOUT_POSTS, "lab_no_posts.yaml")
    three = load_scenario("t_room_three_cylinders")   # radii 22, 22 and 70 mm
    assert compare.cylinders([own]) == []
    assert compare.cylinders([three, own]) == [
        {"radius_m": 0.022, "scenarios": ["t_room_three_cylinders"]},
        {"radius_m": 0.07, "scenarios": ["t_room_three_cylinders"]}]
    scores = {"occupied_f1": 0.9, "free_accuracy": 1.0, "coverage": 0.8, "shadow": None}
    rec = {"design": "rotating12", **scores, "hardware_time_s": 2.72, "compute_time_s": 0.004,
           "runs": 1, "scenarios": ["lab_no_posts"], "poses": {"lab_no_posts": 1},
           "by_scenario": {"lab_no_posts": scores}, "detection_distances_m": [0.35, 0.65],
           "min_detectable_radius_m": [0.002, 0.0041]}

    def marks(cyls):
        compare.chart({"designs": [rec], "detection_distances_m": [0.35, 0.65],
                       "cylinders": cyls}, tmp_path / "c.png")
        det = figures[-1].axes[3]
        level = [ln.get_ydata()[0] for ln in det.get_lines() if ln.get_linestyle() == ":"]
        return level, [t.get_text() for t in det.texts]

    assert marks(compare.cylinders([own])) == ([], [])
    assert marks(compare.cylinders([three, own])) == (
        [22.0, 70.0], ["cylinder r = 22 mm in t_room_three_cylinders",
                       "cylinder r = 70 mm in t_room_three_cylinders"])
    # radii closer than LABEL_RATIO share a label; one above the 200 mm axis is not drawn
    many = [{"radius_m": r, "scenarios": [sc]} for r, sc in
            ((0.015, "posts"), (0.016, "b"), (0.03, "posts"), (0.25, "posts"))]
    assert marks(many) == ([15.0, 16.0, 30.0], ["cylinders r = 15, 16 mm in posts, b",
                                                "cylinder r = 30 mm in posts"])


def test_compare_bars_give_no_eta_before_the_first_run_nor_for_the_curves(monkeypatch,
                                                                          capsys):
    """compare's one bar said 132 s left after the first of 45 runs, for 10 s (2 workers:
    a worker's first run starts it), and 0.5 s for the 6 s of detection curves after the
    runs. The runs' bar waits for each worker's first run (here one: this
    process), the curves' bar gives none. A fake clock: the first run 4 s, the others 1 s,
    a curve 3 s."""
    import tqdm.std

    from irring.scenario import loads
    from irring.studies import study

    now = [0.0]
    monkeypatch.setattr(tqdm.std, "time", lambda: now[0])
    monkeypatch.setattr(tqdm.std.tqdm, "monitor_interval", 0)   # its thread reads a real clock
    real_run, real_curve = study.run_point, compare.detection
    costs = iter([4.0, 1.0, 1.0, 1.0])

    def run_point(task):
        row = real_run(task)
        now[0] += next(costs)
        return row

    def curve(*args, **kw):
        det = real_curve(*args, **kw)
        now[0] += 3.0
        return det

    monkeypatch.setattr(study, "run_point", run_point)
    monkeypatch.setattr(compare, "detection", curve)
    capsys.readouterr()
    compare.compare([loads(ROOM_WITHOUT_POSTS, "lab_no_posts.yaml")], ["rotating12", "radial12"],
                    2, detection_distances_m=[0.35], bearings=8, progress=True)
    states = [s.strip() for s in capsys.readouterr().err.split("\r") if s.strip()]
    runs = [s for s in states if s.startswith("compare runs:")]
    curves = [s for s in states if s.startswith("compare detection curves:")]
    assert runs[1].endswith("1/4 [00:04<?, ETA after each worker's first run]")
    assert runs[-3].endswith("2/4 [00:05<00:02,  1.00run/s]")   # tqdm's was 00:12 here
    assert curves[1].endswith("1/2 [00:03<?, no ETA: each design's curve costs its own]")
    assert all("<?," in s for s in curves)   # tqdm's said 00:03 for radial12's 0.1 s


def test_the_table_gives_each_score_its_spread_from_seed_to_seed(tmp_path, figures):
    """compare's table had no spread (study's has ± sd): with 3 seeds, ring8's shadow 0.51
    against the paper ring's 0.47 read as a difference. Each score now carries
    the sd over seeds within a room, pooled over the rooms, not the sd over every run,
    which counts how the rooms differ (here 0.209 where the seeds move F1 by 0.026)."""
    def run(room, seed, f1, shadow):
        return {"scenario": room, "design": "ring8", "seed": seed, "poses": 1,
                **{k: 0.5 for k in SCORE_KEYS}, "occupied_f1": f1, "shadow": shadow,
                "hardware_time_s": 1.5, "hardware_time_total_s": 1.5, "compute_time_s": 0.01,
                "readings": 100}

    runs = [run("lab", 1, 0.90, 0.40), run("lab", 2, 0.92, 0.46),
            run("hall", 5, 0.50, None), run("hall", 6, 0.56, None), run("hall", 7, 0.53, None)]
    rec, = compare.summarise(runs)
    assert rec["occupied_f1"] == pytest.approx(0.682)
    assert rec["occupied_f1_sd"] == pytest.approx(math.sqrt((0.0002 + 0.0018) / 3))
    assert np.std([r["occupied_f1"] for r in runs], ddof=1) == pytest.approx(0.209, abs=5e-4)
    assert rec["shadow_sd"] == pytest.approx(math.sqrt(0.0018))   # lab's two runs alone
    assert rec["coverage_sd"] == 0.0
    lines = compare.table([rec]).splitlines()
    assert re.split(r"\s{2,}", lines[2])[:5] == ["ring8", "0.682 ± 0.026", "0.500 ± 0.000",
                                        "0.500 ± 0.000", "0.430 ± 0.042"]
    assert lines[-1] == ("±: the spread from seed to seed (sd within each room, pooled over "
                         "the rooms): designs closer than that differ by noise; `irring study` "
                         "runs more seeds")
    one, = compare.summarise([runs[0], runs[2]])   # one seed a room: no spread to give
    assert one["occupied_f1_sd"] is None
    assert "±" not in compare.table([one])
    # the chart's bars carry the same spread
    compare.chart({"designs": [rec], "detection_distances_m": [0.35]}, tmp_path / "c.png")
    scores = figures[0].axes[0]
    f1 = [c for c in scores.containers if c.get_label() == "occupied F1"][0]
    assert f1.errorbar is not None
    ys = f1.errorbar.lines[2][0].get_segments()[0][:, 1]
    assert ys.tolist() == pytest.approx([0.682 - rec["occupied_f1_sd"],
                                         0.682 + rec["occupied_f1_sd"]])


def test_a_miss_the_minimum_range_alone_makes_is_too_near():
    """radial12's sensors sit 150.2 mm out: a cylinder whose near side is 250 mm from the
    centre is 99.8 mm from the one facing it, inside the GP2D12's 100 mm, so no radius is
    seen at every bearing there, though 94.7 mm is without the minimum range and 98.2 mm is
    at 260 mm with it. At 650 mm the miss is the beams' 30° gaps: not too near."""
    radial = geometry.detection(designs.get("radial12"), (0.25, 0.26, 0.65), bearings=180)
    assert radial.min_range_m == 0.1
    assert math.isinf(radial.min_detectable_radius_m[0])
    assert radial.min_detectable_radius_m[1] == pytest.approx(0.0982, abs=5e-4)
    assert math.isinf(radial.min_detectable_radius_m[2])
    assert radial.too_near.tolist() == [True, False, False]
    free = geometry.detection(designs.get("radial12"), (0.25,), bearings=180, min_range_m=0.0)
    assert free.min_detectable_radius_m[0] == pytest.approx(0.0947, abs=5e-4)
    assert free.too_near.tolist() == [False]
    sonar = geometry.detection(designs.get("sonar12"), (0.25, 0.35), bearings=60)
    assert sonar.min_range_m == pytest.approx(0.1524) and sonar.too_near.tolist() == [True, False]
    ring = geometry.detection(designs.get("rotating12"), (0.25,), bearings=180)
    assert ring.too_near.tolist() == [False] and ring.min_detectable_radius_m[0] < 0.005


def test_the_table_and_chart_say_too_near_rather_than_miss(tmp_path, figures):
    """compare printed a bare "miss" for radial12 at 250 mm beside 132 mm at 350 mm: the
    table says "too near" and why, with each design's minimum range, and the chart draws
    a × at 200 mm where the curve has no point."""
    scores = {"occupied_f1": 0.2, "free_accuracy": 1.0, "coverage": 0.0, "shadow": 0.0}
    rec = {"design": "radial12", **scores, "hardware_time_s": 0.038, "compute_time_s": 0.002,
           "runs": 1, "scenarios": ["lab"], "poses": {"lab": 1}, "by_scenario": {"lab": scores},
           "detection_distances_m": [0.25, 0.35, 0.65],
           "min_detectable_radius_m": [None, 0.1324, None], "too_near": [True, False, False],
           "min_range_m": 0.1}
    lines = compare.table([rec]).splitlines()
    assert lines[2].split()[-4:] == ["too", "near", "132.4mm", "miss"]
    assert lines[-1] == ("too near: none ≤ 200 mm is seen at every bearing only because the "
                         "near side is within the sensor's minimum range of the sensor facing "
                         "it (radial12: 100 mm)")
    compare.chart({"designs": [rec], "detection_distances_m": [0.25, 0.35, 0.65]},
                  tmp_path / "c.png")
    crosses = [ln for ax in figures[0].axes for ln in ax.get_lines() if ln.get_marker() == "x"]
    assert len(crosses) == 1
    assert crosses[0].get_xdata().tolist() == [250.0] and crosses[0].get_ydata().tolist() == [200.0]


def test_cli_compare_takes_a_ring_of_ones_own_as_a_study_file_writes_it(tmp_path, capsys):
    """A designer's own ring (8 GP2s on R = 120 mm, ±45°) could be studied but not compared:
    `--design` took only the five names ("invalid choice: 'custom'"), so the detection
    curve and compare.png were out of reach for it."""
    import json

    from irring.cli import main
    from irring.studies import study

    ring8 = "{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 45, step_deg: 1.08, name: ring8}"
    out = tmp_path / "cmp"
    assert main(["compare", "--scenario", "t_room_cylinder", "--design", ring8, "--design",
                 "radial12", "--seeds", "1", "--workers", "1", "--bearings", "16",
                 "--distances-mm", "400", "--out", str(out), "--json"]) == 0
    mine, radial = json.loads(capsys.readouterr().out)
    assert (mine["design"], radial["design"]) == ("ring8", "radial12")
    # ±45° in 1.08° steps is rounded to ±42 steps: 85 readings of one GP2 period each
    assert mine["hardware_time_s"] == pytest.approx(85 * 0.0383)
    assert mine["min_detectable_radius_m"][0] < 0.01 < radial["min_detectable_radius_m"][0]
    # the same run as the same ring in a study file
    spec = study.design_spec("s.yaml", "designs[0]", {
        "sensors": 8, "radius_mm": 120, "sweep_half_angle_deg": 45, "step_deg": 1.08,
        "name": "ring8"})
    from irring.scenario import load_scenario

    sc = load_scenario("t_room_cylinder")
    row = study.run_point(study.Task(study.point(spec, sc, sc.seed), None, sc.source, sc))
    assert mine["occupied_f1"] == row["occupied_f1"] and mine["shadow"] == row["shadow"]


@pytest.mark.parametrize("given, said", [
    ("custom", "--design 'custom': not a named design; choose one of: rotating12, radial12, "
               "rotating1, laser, sonar12, or give a ring of your own as a study file writes "
               "it: '{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 45, step_deg: 1.08, "
               "name: ring8}'"),
    ("{sensors: 100, radius_mm: 120, sweep_half_angle_deg: 45, step_deg: 1.08}",
     "--design.sensors: 100 is out of range; allowed 1 … 64"),
    ("{sensors: 8, radius: 120, sweep_half_angle_deg: 45, step_deg: 1.08}",
     "--design.radius: unknown key (did you mean `radius_mm`?); allowed here: sensors, "
     "radius_mm, sweep_half_angle_deg, step_deg, sensor, name"),
])
def test_cli_compare_names_what_a_design_may_be(tmp_path, capsys, given, said):
    from irring.cli import main

    assert main(["compare", "--design", given, "--out", str(tmp_path / "cmp")]) == 2
    assert capsys.readouterr().err == f"irring compare: error: {said}\n"
    assert not (tmp_path / "cmp").exists()


def test_the_time_and_detection_axes_read_in_plain_numbers_and_say_lower_is_better(
        tmp_path, figures):
    """compare.png's hardware-time bars sat on a log axis ticked 10⁻¹, 10⁰, 10¹ (2.6×10⁰ …
    for two rings of 1.65 and 2.72 s, whose bottom cut the 1.65 s bar to a sliver) and the
    detection panel's radius on 10⁰ … 10²; neither said lower is better."""
    scores = {"occupied_f1": 0.9, "free_accuracy": 1.0, "coverage": 0.8, "shadow": None}

    def rec(name, hw):
        return {"design": name, **scores, "hardware_time_s": hw, "compute_time_s": 0.004,
                "runs": 1, "scenarios": ["lab"], "poses": {"lab": 1},
                "by_scenario": {"lab": scores}, "detection_distances_m": [0.35, 0.65],
                "min_detectable_radius_m": [0.0018, 0.13]}

    def labels(ax, axis="y"):
        ax.figure.canvas.draw()
        lo, hi = getattr(ax, f"get_{axis}lim")()
        return [t.get_text() for t in getattr(ax, f"get_{axis}ticklabels")()
                if lo <= t.get_position()[1] <= hi]

    compare.chart({"designs": [rec("rotating12", 2.72), rec("ring16", 1.65)],
                   "detection_distances_m": [0.35, 0.65]}, tmp_path / "c.png")
    hw, det = figures[-1].axes[2], figures[-1].axes[3]
    assert hw.get_yscale() == "linear" and hw.get_ylim()[0] == 0      # bars from 0
    assert hw.get_ylabel() == "seconds (lower is better)"
    assert det.get_yscale() == "log" and det.get_ylabel() == "radius, mm (lower is better)"
    assert labels(det) == ["2", "5", "10", "20", "50", "100"]
    compare.chart({"designs": [rec("rotating1", 12.79), rec("laser", 0.027)],
                   "detection_distances_m": [0.35, 0.65]}, tmp_path / "c.png")
    hw = figures[-1].axes[2]
    assert hw.get_yscale() == "log"          # 470× apart: lengths would hide the laser
    assert labels(hw) == ["0.02", "0.05", "0.1", "0.2", "0.5", "1", "2", "5", "10"]
