"""Benchmarks: the accuracy-vs-time directions, identical results on every executor, and the
speed benchmark's figures (no timed assertions: speed is printed by `irring bench speed`)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from irring import pipeline
from irring.core import Reason
from irring.estimation.calibration import Calibration
from irring.estimation.estimate import estimate
from irring.maps.mapping import OccupancyGrid
from irring.studies import accuracy, executor, speed
from irring.scenario import load_scenario

SMALL = [accuracy.Config(),
         accuracy.Config("step", "step ×4", 4, step_stride=4),
         accuracy.Config("samples", "4 samples", 4, samples=4),
         accuracy.Config("iterations", "θ = 0", 0, iterate=False)]


@pytest.fixture(scope="module")
def small_grid() -> dict:
    """The one-pose cylinder room, four configurations × 2 seeds, in this process."""
    return accuracy.measure(["t_room_cylinder"], seeds=2, configs=SMALL)


def _row(result: dict, label: str) -> dict:
    return next(r for r in result["configs"] if r["label"] == label)


def test_finer_steps_cost_hardware_time_and_buy_coverage_and_shadow(small_grid):
    d, coarse = _row(small_grid, "default"), _row(small_grid, "step ×4")
    # 71 stops of one 38.3 ms reading vs 18 stops
    assert d["hardware_time_s"] == pytest.approx(71 * 0.0383)
    assert coarse["hardware_time_s"] == pytest.approx(18 * 0.0383)
    # beams 4.32° apart leave the cells between them unmapped and miss more of the wall
    # behind the table leg
    assert d["coverage"] > coarse["coverage"] + 0.3
    assert d["occupied_recall"] > coarse["occupied_recall"]
    assert d["occupied_f1"] > coarse["occupied_f1"]
    assert d["shadow"] >= coarse["shadow"]


def test_more_samples_cost_hardware_time_and_buy_range_accuracy(small_grid):
    d, avg = _row(small_grid, "default"), _row(small_grid, "4 samples")
    assert avg["hardware_time_s"] == pytest.approx(4 * d["hardware_time_s"])
    # averaging 4 independent readings halves the noise σ; the range error follows
    assert avg["range_rmse_m"] < 0.8 * d["range_rmse_m"]
    # both map this room all but perfectly (F1 0.993 / 0.992): equal to within a cell or two
    assert avg["occupied_f1"] >= d["occupied_f1"] - 0.002


def test_iterations_cost_compute_and_buy_accuracy_at_steep_incidence(small_grid):
    d, flat = _row(small_grid, "default"), _row(small_grid, "θ = 0")
    assert flat["hardware_time_s"] == d["hardware_time_s"]   # same readings
    # the estimator's work (a machine-independent measure of its compute time)
    assert flat["iterations_mean"] == 0 and d["iterations_mean"] > 2
    assert d["range_rmse_steep_m"] < 0.5 * flat["range_rmse_steep_m"]
    assert d["occupied_f1"] > flat["occupied_f1"] + 0.1


SETTLE = [accuracy.Config("settle", f"settle {ms} ms (belt+timing)", ms, settle_s=ms / 1e3,
                          dynamics=True) for ms in (0, 20, 60)]


@pytest.fixture(scope="module")
def settle_grid() -> dict:
    """The cylinder room with the belt's swing and the GP2's clock simulated, 3 settle times."""
    return accuracy.measure(["t_room_cylinder"], seeds=2, configs=SETTLE)


def test_settling_under_belt_and_timing_costs_hardware_time_and_buys_accuracy(settle_grid):
    rows = [_row(settle_grid, c.label) for c in SETTLE]
    hw = [r["hardware_time_s"] for r in rows]
    angle = [r["angle_error_rms_rad"] for r in rows]
    assert hw == sorted(hw) and hw[0] < hw[-1]                 # waiting is hardware time
    # 71 moves of 4 ms each, plus the wait at every stop
    assert hw[0] == pytest.approx(71 * 0.004, rel=0.05)
    assert hw[-1] == pytest.approx(71 * (0.004 + 0.060), rel=0.05)
    # the belt swings and the GP2 reports a stale measurement: the wait buys the beam angle …
    assert angle[0] > 0.05 and angle[1] < 0.5 * angle[0] and angle[2] < 1e-3
    # … and with it the range, the end points and the map
    assert rows[2]["range_rmse_m"] < rows[0]["range_rmse_m"]
    assert rows[2]["point_rmse_m"] < 0.5 * rows[0]["point_rmse_m"]
    assert rows[2]["occupied_f1"] > rows[0]["occupied_f1"] + 0.1
    # a different simulation of the room: never on (or dominating) a Pareto front
    assert all(accuracy.fronts(r) == "·" for r in rows)


def test_settle_configurations_add_belt_dynamics_and_timing():
    base = load_scenario("t_room")
    settle = [c for c in accuracy.configurations(["settle"]) if c.knob == "settle"]
    assert [c.value for c in settle] == list(accuracy.SETTLE_MS)
    for c in settle:
        sc = accuracy.apply(base, c)
        assert "belt+timing" in c.label and sc.has("belt_dynamics") and sc.has("timing")
        assert sc.scan.settle_s == pytest.approx(c.value / 1e3)
    assert not accuracy.apply(base, accuracy.Config()).has("timing")


def test_every_run_is_recorded_with_costs_and_scores(small_grid):
    runs = small_grid["runs"]
    assert len(runs) == len(SMALL) * 2
    assert [r["seed"] for r in runs[:2]] == [2, 3]           # scenario seed, +1
    for r in runs:
        assert r["compute_ms"] == pytest.approx(r["estimate_ms"] + r["map_ms"])
        assert 0 < r["valid_share"] <= 1 and r["range_rmse_m"] > 0
    keys = {accuracy.front_key(c, m) for c in accuracy.COSTS for m in accuracy.FRONT_METRICS}
    assert all(keys <= set(row) for row in small_grid["configs"])


def test_the_timed_mapping_is_the_maps_own_work(monkeypatch):
    """The accuracy-vs-time chart charges the map what it costs: the timed mapper makes the
    inserts map_sweeps makes (each sweep's returns, then the run's silent beams in one) and
    ends on the same grid, bit for bit. It timed one insert of each whole sweep: not the
    map the run drew, and one insert fewer."""
    sc = load_scenario("t_room")
    sweeps = pipeline.simulated(sc, seed=3, progress=False)[0].sweeps
    cal = Calibration.for_scene(sc)
    calls, grids = [], []
    insert, insert_run = OccupancyGrid.insert, OccupancyGrid.insert_run

    def spy(grid, points, placed=False):
        calls.append((int(np.count_nonzero(points.valid)),
                      int(np.count_nonzero(np.asarray(points.reason) == Reason.NO_RETURN)),
                      np.shape(points.valid), placed))
        insert(grid, points, placed)

    def spy_run(grid, batches):
        insert_run(grid, batches)
        grids.append(grid)

    monkeypatch.setattr(OccupancyGrid, "insert", spy)
    monkeypatch.setattr(OccupancyGrid, "insert_run", spy_run)
    mapped = pipeline.map_sweeps(sweeps, grid=OccupancyGrid.for_scenario(sc), calibration=cal,
                                 score=False, progress=False).grid
    made = calls[:]
    assert len(made) == len(sweeps) + 1 and made[-1][0] == 0 and made[-1][1] > 100
    del calls[:], grids[:]
    accuracy._compute_time(sweeps, cal, estimate, OccupancyGrid.for_scenario(sc))
    assert calls == made * accuracy.TIMING_REPEATS
    assert len(grids) == accuracy.TIMING_REPEATS
    for g in grids:
        np.testing.assert_array_equal(g.log_odds, mapped.log_odds)


def test_pareto_front_keeps_only_undominated_configurations():
    def row(name, hw, f1, valid=1.0):
        return {"label": name, "hardware_time_s": hw, "compute_ms": 1.0, "occupied_f1": f1,
                "coverage": 0.5, "range_rmse_m": 0.01, "valid_share": valid}

    rows = [row("fast", 1.0, 0.5), row("slow-better", 4.0, 0.9), row("slow-worse", 5.0, 0.8),
            row("tie-worse", 1.0, 0.4), row("none", 0.5, None)]
    accuracy.mark_pareto(rows)
    on = {r["label"] for r in rows if r["front_hw_f1"]}
    assert on == {"fast", "slow-better"}
    few = [row("ok", 1.0, 0.5), row("few-valid", 0.5, 0.5, valid=0.1)]
    few[1]["range_rmse_m"] = 0.001
    accuracy.mark_pareto(few)
    # an RMSE over a tenth of the readings does not win the RMSE front
    assert not few[1]["front_hw_rmse"] and few[0]["front_hw_rmse"]
    assert accuracy.fronts(few[1]) == "hw:f1,cov cpu:f1,cov"


def test_configurations_vary_one_knob_at_a_time():
    configs = accuracy.configurations()
    assert configs[0] == accuracy.Config()
    assert {c.knob for c in configs[1:]} == set(accuracy.KNOBS)
    base = load_scenario("t_room")
    for c in configs[1:]:
        sc = accuracy.apply(base, c)
        changed = {name for name in ("scan", "map", "effects", "robot", "sensor")
                   if getattr(sc, name) != getattr(base, name)}
        assert len(changed) <= 2, (c, changed)               # samples: scan + averaging
    with pytest.raises(ValueError, match="unknown knob"):
        accuracy.configurations(["speed"])


# --------------------------------------------------------------------------- scaling out

TINY = [accuracy.Config(), accuracy.Config("step", "step ×4", 4, step_stride=4)]


@pytest.fixture(scope="module")
def tiny() -> dict:
    """accuracy.measure on t_room_cylinder, one seed, TINY's two configurations, in process."""
    return accuracy.measure(["t_room_cylinder"], seeds=1, configs=TINY)


@pytest.fixture(scope="module")
def serial_tiny(tiny) -> list[dict]:
    return [accuracy.deterministic(r) for r in tiny["runs"]]


def test_process_pool_gives_identical_results(serial_tiny):
    with executor.executor(workers=2) as ex:
        assert isinstance(ex, executor.ProcessPoolExecutor)
        result = accuracy.measure(["t_room_cylinder"], seeds=1, configs=TINY, ex=ex)
    assert [accuracy.deterministic(r) for r in result["runs"]] == serial_tiny


def test_dask_cluster_gives_identical_results(serial_tiny):
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster, \
            executor.executor(dask=cluster.scheduler_address) as ex:
        result = accuracy.measure(["t_room_cylinder"], seeds=1, configs=TINY, ex=ex)
    assert [accuracy.deterministic(r) for r in result["runs"]] == serial_tiny


def _square(x: int) -> int:
    if x < 0:
        raise ValueError("negative")
    return x * x


def test_run_jobs_keeps_job_order_and_raises_the_jobs_error():
    seen = []
    assert executor.run_jobs(_square, [3, 1, 2], progress=seen.append) == [9, 1, 4]
    assert seen == [9, 1, 4]
    with executor.executor(workers=1) as ex:
        assert isinstance(ex, executor.SerialExecutor)
        with pytest.raises(ValueError, match="negative"):
            executor.run_jobs(_square, [1, -1], ex)


# --------------------------------------------------------------------------- speed


def test_speed_reports_every_stage_and_the_ratios():
    r = speed.measure(load_scenario("t_room"), rounds=3, warmup=1)
    names = [s["stage"] for s in r["stages"]]
    assert names == ["kinematics", "rays", "effect: incidence", "effect: noise",
                     "effect: quantization", "effects core", "estimator", "mapper"]
    assert (r["steps"], r["sensors"], r["rays"]) == (71, 12, 852)
    assert all(s["ms"] >= 0 for s in r["stages"])
    assert r["kinematics_mujoco_ms"] > 0     # the uncached forward is timed too, not assumed
    assert r["ray_vs_raw_ratio"] == pytest.approx(r["ray_ms"] / r["raw_mujoco_ms"])
    assert r["realtime_factor"] == pytest.approx(71 * 0.0383 / (r["sweep_ms"] / 1e3))
    assert r["sweeps_per_s"] == pytest.approx(1e3 / r["sweep_ms"])
    assert set(r["targets"]) == {"sweep_ms", "ray_vs_raw_ratio", "realtime_factor"}
    # how busy the machine was, before and after, as the report prints it
    before, after = r["machine"]["load_before"], r["machine"]["load_after"]
    assert len(before) == len(after) == 3 and min(before + after) >= 0
    line = next(x for x in speed.report(r).splitlines() if x.startswith("load average"))
    assert f"before {before[0]:.2f} {before[1]:.2f} {before[2]:.2f} and after {after[0]:.2f}" in line
    json.dumps(r)                                             # plain figures only


def test_the_benchmarks_print_the_load_average_in_one_way():
    """bench speed, render and study: one line, the three load averages before and after."""
    from irring.studies import scaling
    from irring.studies.report import load_line

    before, after = [6.35, 3.42, 1.861], [0.6, 0.5, 0.47]
    line = load_line(before, after, 2)
    assert line == ("load average (1, 5, 15 min) before 6.35 3.42 1.86 and after 0.60 0.50 "
                    "0.47; with more than 2 busy the figures are slower than the machine")
    r = {"grid": "3 designs × 3 rooms × seeds", "cpus": 2, "load_before": before,
         "load_after": after, "speed": [], "memory": []}
    assert scaling.report(r).splitlines() == ["3 designs × 3 rooms × seeds; 2 CPUs", line]


def test_timed_pipeline_gives_the_same_counts_as_the_plain_one():
    import numpy as np

    from irring.simulation.effects import Pipeline
    from irring.simulation.sim import SimRing

    sc = load_scenario("t_room")
    sim = SimRing(sc)
    _, _, truth = sim.truth(0)
    tally: dict = {}
    timed = speed.timed_pipeline(sc, tally).run(truth, np.random.default_rng(5), cast=sim.cast)
    plain = Pipeline.from_scenario(sc).run(truth, np.random.default_rng(5), cast=sim.cast)
    np.testing.assert_array_equal(timed, plain)
    assert set(tally) == {"incidence", "noise", "quantization"}
    assert all(math.isfinite(v) and v >= 0 for v in tally.values())


def test_cli_speed_check_exits_6_only_when_a_target_is_missed(monkeypatch, capsys):
    """6, not 1 (a bad scenario file): the figures are printed, a target was not met."""
    from irring.cli import main

    easy = {"sweep_ms": 1e9, "ray_vs_raw_ratio": 1e9, "realtime_factor": 0.0}
    for key, value in easy.items():
        monkeypatch.setitem(speed.TARGETS, key, value)
    assert main(["bench", "speed", "--rounds", "1", "--check"]) == 0
    monkeypatch.setitem(speed.TARGETS, "realtime_factor", 1e12)   # no machine is that fast
    assert main(["bench", "speed", "--rounds", "1"]) == 0          # reported, not checked
    assert main(["bench", "speed", "--rounds", "1", "--check"]) == 6
    out = capsys.readouterr().out.splitlines()
    assert [ln.split()[-1] for ln in out[-3:]] == ["met", "met", "MISSED"]
    assert main(["bench", "speed", "--scenario", "no_such_room", "--check"]) == 1


def test_cli_speed_json(capsys):
    from irring.cli import main

    assert main(["bench", "speed", "--rounds", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("sweep_ms", "ray_ms", "raw_mujoco_ms", "ray_vs_raw_ratio", "realtime_factor"):
        assert out[key] > 0


@pytest.fixture(scope="module")
def tiny_chart(tiny, tmp_path_factory) -> list:
    """The figures accuracy.chart of ``tiny`` makes (one), drawn once for the tests that
    read it (each drew the same chart, ~3 s)."""
    from irring.maps import render

    made: list = []
    real = render.figure
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(render, "figure", lambda *a, **k: made.append(real(*a, **k)) or made[-1])
        accuracy.chart(tiny, tmp_path_factory.mktemp("chart") / "a.png")
    return made


def test_the_accuracy_chart_legend_says_what_a_ring_means(tiny_chart):
    """accuracy.png ringed the configurations on each Pareto front and said nowhere what a
    ring meant (study.png's title does)."""
    legend = [t.get_text() for t in tiny_chart[0].axes[2].get_legend().get_texts()]
    assert legend.count("ringed: on the front") == 1 and "Pareto front" in legend


def test_the_accuracy_charts_f1_axes_are_stretched_towards_one(tiny_chart):
    """accuracy.png's F1 panels drew the knobs' 0.957 … 0.999 as one crowd at the top of
    0 … 1, their labels on each other; they are stretched towards 1, and the legend sits
    where no point does (coverage against hardware time, lower right)."""
    assert len(tiny_chart) == 1
    axes = tiny_chart[0].axes
    for ax in axes[:2]:
        assert ax.get_yscale() == "function"
        assert ax.get_ylabel() == "occupied F1 (higher is better;\nscale stretched towards 1)"
        lo, hi = ax.get_ylim()
        ticks = [t.get_text() for t in ax.get_yticklabels() if lo <= t.get_position()[1] <= hi]
        assert ticks[-4:] == ["0.99", "0.995", "0.998", "1"] and hi > 1
    assert [ax.get_legend() is not None for ax in axes] == [False, False, True, False, False,
                                                             False]
    assert all(ax.get_yscale() == "linear" for ax in axes[2:])
