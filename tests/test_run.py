"""`irring run` / `irring replay` end to end: targets on the bundled scenarios, the files
it writes, exact replay, determinism."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("mujoco")

from irring import pipeline  # noqa: E402
from irring.cli import main  # noqa: E402
from irring.maps.mapping import OccupancyGrid  # noqa: E402
from irring.maps.metrics import SCORE_KEYS  # noqa: E402
from irring.recording import load_recording  # noqa: E402
from irring.scenario import load_scenario  # noqa: E402

SCENARIOS = ("t_room", "t_room_cylinder", "t_room_three_cylinders")


@pytest.fixture(scope="module")
def runs():
    return {name: pipeline.run(load_scenario(name), progress=False) for name in SCENARIOS}


@pytest.mark.parametrize("name", SCENARIOS)
def test_bundled_scenarios_meet_the_map_targets(runs, name):
    s = runs[name].scores
    assert s["occupied_f1"] >= 0.9, s
    assert s["free_accuracy"] >= 0.95, s


def test_the_ring_maps_the_wall_behind_the_table_leg(runs):
    """Paper Fig. 16: the wall behind the cylinder is seen by the rotating sensors."""
    assert runs["t_room_cylinder"].scores["shadow"] >= 0.5


def test_summary_has_the_documented_keys(runs):
    r = runs["t_room"]
    s = r.summary()
    assert set(s) == {"scenario", "design", "poses", "readings", "scores", "hardware_time_s",
                      "compute_time_s"}
    assert s["scenario"] == "t_room" and s["design"] == "rotating12" and s["poses"] == 4
    assert set(s["scores"]) == set(SCORE_KEYS)
    assert s["readings"]["total"] == 4 * 71 * 12
    assert s["readings"]["valid"] + sum(v for k, v in s["readings"].items()
                                        if k not in ("total", "valid")) == 4 * 71 * 12
    # four sweeps of 71 steps at one 38.3 ms GP2 period each
    assert s["hardware_time_s"] == pytest.approx(4 * 71 * 0.0383)
    assert set(s["compute_time_s"]) >= {"simulate", "estimate", "map", "score", "total"}


def test_run_is_deterministic_under_its_seed(runs):
    sc = load_scenario("t_room_cylinder")
    again = pipeline.run(sc, progress=False, score=False)
    assert np.array_equal(again.grid.log_odds, runs["t_room_cylinder"].grid.log_odds)
    other = pipeline.run(sc, seed=sc.seed + 1, progress=False, score=False)
    assert not np.array_equal(other.grid.log_odds, again.grid.log_odds)


def test_cli_run_writes_every_output_and_replay_reproduces_the_map(tmp_path, capsys):
    out = tmp_path / "cyl"
    assert main(["run", "t_room_cylinder", "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["scenario"] == "t_room_cylinder" and summary["poses"] == 1
    for name in ("map.png", "map_building.gif", "map.pgm", "map.yaml", "sweeps.npz"):
        assert (out / name).stat().st_size > 0, name

    import imageio.v2 as imageio

    png = imageio.imread(out / "map.png")
    assert png.ndim == 3 and png.shape[0] > 400 and png.shape[1] > 600
    gif = imageio.mimread(out / "map_building.gif")
    assert len(gif) == 1 + pipeline.FRAMES_PER_SWEEP   # empty map, then the sweep in parts
    assert not np.array_equal(gif[0], gif[-1])

    # the PGM is the map, and reloads to the same cells
    grid = OccupancyGrid.from_pgm(out / "map.yaml")
    run = pipeline.run(load_scenario("t_room_cylinder"), progress=False, score=False)
    np.testing.assert_array_equal(grid.classify(), run.grid.classify())
    np.testing.assert_allclose(grid.origin_xy_m, run.grid.origin_xy_m)

    # the recording holds the sweeps and what replay needs
    sweeps, meta = load_recording(out / "sweeps.npz")
    assert len(sweeps) == 1 and sweeps[0].truth is not None
    assert meta["scenario"] == "t_room_cylinder" and meta["scenario_yaml"]

    replayed = pipeline.replay(out / "sweeps.npz", progress=False)
    assert np.array_equal(replayed.grid.log_odds, run.grid.log_odds)
    assert replayed.scores == summary["scores"]

    rep = tmp_path / "rep"
    assert main(["replay", str(out / "sweeps.npz"), "--out", str(rep), "--no-animation"]) == 0
    text = capsys.readouterr().out
    assert "occupied  F1" in text and "hardware" in text
    assert (rep / "map.pgm").read_bytes() == (out / "map.pgm").read_bytes()
    assert not (rep / "map_building.gif").exists()


def test_replay_without_out_writes_beside_the_run_it_names(tmp_path, capsys, monkeypatch):
    """The default folder its help promises: a sweeps.npz is named by its run's folder,
    any other recording by its own file name."""
    monkeypatch.chdir(tmp_path)
    assert main(["run", "t_room_cylinder", "--out", "runs/cyl", "--no-animation"]) == 0
    (tmp_path / "lab.npz").write_bytes((tmp_path / "runs/cyl/sweeps.npz").read_bytes())
    capsys.readouterr()
    assert main(["replay", "runs/cyl/sweeps.npz", "--no-animation"]) == 0
    assert main(["replay", "lab.npz", "--no-animation"]) == 0
    out = capsys.readouterr().out
    assert "wrote     out/cyl-replay/: map.png" in out and "wrote     out/lab-replay/: " in out
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["cyl-replay", "lab-replay"]
    for name in ("cyl-replay", "lab-replay"):
        assert (tmp_path / "out" / name / "map.pgm").read_bytes() == \
            (tmp_path / "runs/cyl/map.pgm").read_bytes()


def test_replay_with_another_calibration_changes_the_map(tmp_path):
    from irring.estimation.calibration import Calibration

    sc = load_scenario("t_room_cylinder")
    base = pipeline.run(sc, progress=False, score=False)
    pipeline.write_outputs(base, tmp_path / "a", animation=False)
    cal = Calibration.nominal("gp2d12", sc.ring, emitter_offset_m=0.030)
    path = cal.save(tmp_path / "cal.yaml")
    other = pipeline.replay(tmp_path / "a" / "sweeps.npz", calibration_file=path, score=False)
    assert not np.array_equal(other.grid.log_odds, base.grid.log_odds)
    # the calibration travels with the new recording, so replaying that one is exact too
    pipeline.write_outputs(other, tmp_path / "b", animation=False)
    again = pipeline.replay(tmp_path / "b" / "sweeps.npz", score=False)
    assert np.array_equal(again.grid.log_odds, other.grid.log_odds)


def test_readable_summary_and_bad_input(tmp_path, capsys):
    assert main(["run", "t_room_cylinder", "--out", str(tmp_path), "--no-animation"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("t_room_cylinder — ")
    for word in ("occupied  F1", "free      accuracy", "shadow", "hardware 2.7 s", "compute",
                 "map.pgm"):
        assert word in text
    assert main(["run", "no_such_scenario"]) == 1
    assert "no such file and no bundled scenario" in capsys.readouterr().err
    assert main(["replay", str(tmp_path / "nothing.npz")]) == 1
    assert "no such recording" in capsys.readouterr().err


def test_progress_bar_only_at_a_terminal(monkeypatch):
    monkeypatch.setattr("sys.stderr.isatty", lambda: True, raising=False)
    monkeypatch.setenv("CI", "true")
    assert not pipeline.progress_enabled()
    monkeypatch.delenv("CI")
    assert pipeline.progress_enabled()


def test_a_hidden_progress_bar_does_not_load_tqdm():
    import subprocess
    import sys

    code = ("import sys; from irring import pipeline\n"
            "with pipeline.progress_bar(3, 'x', False) as bar:\n"
            "    bar.update(); bar.reset(total=5)\n"
            "print('tqdm' in sys.modules)\n"
            "with pipeline.progress_bar(3, 'x', True) as bar:\n"
            "    bar.update(2); print(bar.n, 'tqdm' in sys.modules)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["False", "2", "True"]


def test_a_warmup_bar_gives_no_eta_until_the_slow_first_runs_are_done(monkeypatch, capsys):
    """A study's first run on each of 2 workers takes 4 s, every later one 0.25 s (one at a
    time): tqdm's own ETA after the first run is 29 × 4 s; the warm-up bar says why it gives
    none until both first runs are done, then tqdm's from the runs since (27 at 4 runs/s),
    its elapsed still counted from the start. A fake clock, not a timed test."""
    import tqdm.std

    now = [0.0]
    monkeypatch.setattr(tqdm.std, "time", lambda: now[0])
    monkeypatch.setattr(tqdm.std.tqdm, "monitor_interval", 0)   # its thread reads a real clock

    def states(bar, times) -> list[str]:
        capsys.readouterr()
        seen = []
        for t in times:
            now[0] = t
            bar.update()
            seen.append(capsys.readouterr().err.split("\r")[-1].strip())
        return seen

    now[0] = 0.0
    with pipeline.progress_bar(0, "study", True, unit="run") as bar:
        bar.reset(total=30)
        assert states(bar, [4.0])[0].endswith("1/30 [00:04<01:56,  4.00s/run]")
    now[0] = 0.0
    with pipeline.progress_bar(0, "study", True, unit="run", warmup=2,
                               warmup_note="ETA after each worker's first run") as bar:
        bar.reset(total=30)
        first, second, third = states(bar, [4.0, 4.25, 4.5])
        assert first.endswith("1/30 [00:04<?, ETA after each worker's first run]")
        assert second.endswith("2/30 [00:04<?, ?run/s]")
        assert third.endswith("3/30 [00:04<00:06,  4.00run/s]")
        assert bar.n == 3 and bar.total == 30
        bar.reset(total=4)    # back to the warm-up, as tqdm's reset goes back to 0
        assert states(bar, [5.0])[0].endswith("1/4 [00:00<?, ETA after each worker's first run]")


def test_help_explains_units_defaults_and_examples(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = capsys.readouterr().out
    for word in ("t_room", "./out/<scenario>", "10 mm", "map_server", "examples:", "--seed"):
        assert word in text
    with pytest.raises(SystemExit):
        main(["replay", "--help"])
    assert "--calibration" in capsys.readouterr().out


def test_ground_truth_can_be_reused_across_runs(runs):
    first = runs["t_room_cylinder"]
    again = pipeline.map_sweeps(first.sweeps, scenario=first.scenario, truth=first.truth,
                                progress=False)
    assert again.truth is first.truth and again.scores == first.scores


def test_a_recording_keeps_mapper_rules_turned_off_with_inf(runs, tmp_path):
    """no_return_stop and lone_sigma_m are off at +inf: a recording of such a run replays
    with them off (the same map), and inf anywhere else is refused, naming the two."""
    import dataclasses
    import math

    from irring.maps.mapping import MapperParams
    from irring.recording import save_recording

    params = MapperParams(no_return_stop=math.inf, lone_sigma_m=math.inf)
    sweeps = runs["t_room_cylinder"].sweeps
    path = save_recording(tmp_path / "off.npz", sweeps, {"mapper": dataclasses.asdict(params)})
    replayed = pipeline.replay(path, progress=False)
    assert replayed.grid.params == params
    want = pipeline.map_sweeps(sweeps, params=params, progress=False)
    assert np.array_equal(replayed.grid.log_odds, want.grid.log_odds)
    assert not np.array_equal(want.grid.log_odds,
                              pipeline.map_sweeps(sweeps, progress=False).grid.log_odds)
    bad = dict(dataclasses.asdict(MapperParams()), l_occ=math.inf)
    with pytest.raises(ValueError, match="no_return_stop, lone_sigma_m may also be inf"):
        save_recording(tmp_path / "bad.npz", sweeps, {"mapper": bad})   # replay would refuse it
    assert not (tmp_path / "bad.npz").exists()


def test_replay_maps_with_the_recorded_mapper_params_on_any_grid(runs, tmp_path):
    """A recording that names its mapper numbers but no grid or scenario (written by hand,
    or by another tool) is mapped with those numbers on a grid around its points."""
    import dataclasses

    from irring.maps.mapping import MapperParams
    from irring.recording import save_recording

    params = MapperParams(l_occ=1.0, l_max=2.0)
    sweeps = runs["t_room_cylinder"].sweeps
    path = save_recording(tmp_path / "bare.npz", sweeps, {"mapper": dataclasses.asdict(params)})
    replayed = pipeline.replay(path, progress=False)
    assert replayed.grid.params == params and replayed.scores is None
    want = pipeline.map_sweeps(sweeps, params=params, progress=False)
    assert np.array_equal(replayed.grid.log_odds, want.grid.log_odds)
    assert replayed.grid.log_odds.max() == 2.0


def test_the_shadow_line_says_how_many_hidden_cells_a_sensor_could_range(runs):
    """A shadow of 0 where no sensor could range the hidden wall is all any map can score:
    the summary says so, with the counts the share is of."""
    from irring.cli.run import summary_lines

    three = summary_lines(runs["t_room_three_cylinders"], {})
    assert [ln for ln in three if ln.startswith("  shadow")] == [
        "  shadow    0.444 of the wall behind obstacles mapped (54 wall cell(s) hidden from "
        "every pose centre; a sensor could range 24 of them)"]
    box = summary_lines(pipeline.run(load_scenario("box_room"), progress=False), {})
    assert [ln for ln in box if ln.startswith("  shadow")] == [
        "  shadow    0.000 of the wall behind obstacles mapped (7 wall cell(s) hidden from "
        "every pose centre; a sensor could range none of them)"]
    plain = summary_lines(runs["t_room"], {})
    assert ("  shadow    n/a (no wall in the sensors' reach is hidden behind an obstacle from "
            "every pose centre)") in plain
