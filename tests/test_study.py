"""`irring study`: the grid, its file's errors, identical rows on every executor, resuming
after a kill, and the summary."""

from __future__ import annotations

import itertools
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from irring import errors
from irring.studies import executor, study
from irring.cli import main
from irring.scenario import resolve

# A room of our own: an L-shaped room (x ≠ y everywhere), one post, one pose off-centre.
ROOM = """\
name: l_room_post
seed: 7
room:
  outline_mm: [[0, 0], [1300, 0], [1300, 700], [600, 700], [600, 1100], [0, 1100]]
obstacles:
  - {type: cylinder, center_mm: [980, 260], radius_mm: 30}
robot:
  design: rotating12
  poses:
    - {x_mm: 720, y_mm: 380, yaw_deg: 10}
sensor: {model: gp2d12, max_range_mm: 624}
effects:
  incidence: {}
  noise: {sigma_v: 0.012}
  quantization: {}
map: {resolution_mm: 10}
"""

STUDY = """\
designs: [rotating12, {sensors: 7, radius_mm: 110, sweep_half_angle_deg: 30, step_deg: 2.16}]
scenarios: [l_room_post.yaml]
seeds: [3, 11]
knobs: {step_stride: [1, 3]}
"""


def write(tmp: Path, text: str = STUDY, name: str = "s.yaml") -> Path:
    (tmp / "l_room_post.yaml").write_text(ROOM)
    p = tmp / name
    p.write_text(text)
    return p


def deterministic(rows) -> list[tuple]:
    """Rows without the columns that time this machine."""
    keep = [c for c in study.COLUMNS if c not in study.TIMING_COLUMNS]
    return [tuple(r[c] for c in keep) for r in rows]


# --------------------------------------------------------------------------- the grid


def test_grid_is_every_combination_in_grid_order(tmp_path):
    s = study.load_study(write(tmp_path))
    points = study.grid(s)
    assert len(points) == 2 * 1 * 2 * 2
    assert [(p.design.label, p.step_stride, p.seed) for p in points] == [
        ("rotating12", 1, 3), ("rotating12", 1, 11), ("rotating12", 3, 3), ("rotating12", 3, 11),
        ("ring7_r110_a30_s2.16", 1, 3), ("ring7_r110_a30_s2.16", 1, 11),
        ("ring7_r110_a30_s2.16", 3, 3), ("ring7_r110_a30_s2.16", 3, 11)]
    # knobs the study leaves out keep the scenario's values; the path is the study file's
    assert {(p.samples, p.settle_ms) for p in points} == {(1, 0.0)}
    assert points[0].scenario == str(tmp_path / "l_room_post.yaml")
    assert len({p.key for p in points}) == len(points)


def test_a_seed_count_counts_from_each_scenarios_own_seed(tmp_path):
    s = study.load_study(write(tmp_path, "designs: [radial12]\nscenarios: [l_room_post.yaml, "
                                          "t_room]\nseeds: 3\n"))
    assert [(Path(p.scenario).stem, p.seed) for p in study.grid(s)] == [
        ("l_room_post", 7), ("l_room_post", 8), ("l_room_post", 9),
        ("t_room", 1), ("t_room", 2), ("t_room", 3)]


def test_a_parametric_design_is_the_ring_it_names(tmp_path):
    s = study.load_study(write(tmp_path))
    d = s.designs[1].build()
    assert d.ring.sensors == 7
    assert d.ring.radius_m == pytest.approx(0.110)
    assert d.ring.motor_step_rad * d.ring.gear == pytest.approx(math.radians(2.16))
    assert (d.ring.min_step, d.ring.max_step) == (-14, 14)      # 30° / 2.16° = 13.9 → 14 steps


# --------------------------------------------------------------------------- file errors

BAD = [
    ("designs: [rotating12]\nscenarios: [t_room]\nseed: [1]\n",
     r"s\.yaml: seed: unknown key \(did you mean `seeds`\?\); allowed here: designs, "
     r"scenarios, seeds, knobs"),
    ("scenarios: [t_room]\n", r"s\.yaml: designs: required key is missing"),
    ("designs: [rotating13]\nscenarios: [t_room]\n",
     r"designs\[0\]: 'rotating13' is not a named design; choose one of: rotating12, radial12"),
    ("designs: [{sensors: 8, radius_mm: 120, step_deg: 1}]\nscenarios: [t_room]\n",
     r"designs\[0\]\.sweep_half_angle_deg: required key is missing"),
    ("designs: [{sensors: 8, radius_mm: 1200, sweep_half_angle_deg: 40, step_deg: 1}]\n"
     "scenarios: [t_room]\n", r"designs\[0\]\.radius_mm: 1200 mm is out of range; allowed 0 … 1000 mm$"),
    # a number with the unit its key names (a subnormal as written)
    ("designs: [{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 40, step_deg: 5e-324}]\n"
     "scenarios: [t_room]\n",
     r"designs\[0\]\.step_deg: 5e-324 ° is out of range; allowed 0\.006 … 27 °$"),
    ("designs: [{sensors: 8.5, radius_mm: 120, sweep_half_angle_deg: 40, step_deg: 1}]\n"
     "scenarios: [t_room]\n", r"designs\[0\]\.sensors: expected an integer in 1 … 64, got 8\.5"),
    ("designs: [{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 40, step_deg: 1, "
     "sensor: lidar}]\nscenarios: [t_room]\n",
     r"designs\[0\]\.sensor: 'lidar' is not allowed; choose one of: gp2d12"),
    ("designs: [radial12, radial12]\nscenarios: [t_room]\n",
     r"designs\[1\]: design 'radial12' is listed twice"),
    # one room by two names ran twice and counted twice in the summary's means
    (f"designs: [radial12]\nscenarios: [t_room, {resolve('t_room')}]\n",
     rf"scenarios\[1\]: scenario '{re.escape(str(resolve('t_room')))}' is listed twice \(as "
     r"'t_room', the same file\); it would be run and counted in the means twice"),
    ("designs: [radial12]\nscenarios: [no_such_room]\n",
     r"scenarios\[0\]: no_such_room: no such file and no bundled scenario"),
    ("designs: [radial12]\nscenarios: [t_room]\nseeds: [1, -2]\n",
     r"seeds\[1\]: -2 is out of range; allowed 0 … 9223372036854775807"),
    ("designs: [radial12]\nscenarios: [t_room]\nknobs: {stride: [1, 2]}\n",
     r"knobs\.stride: unknown key \(did you mean `step_stride`\?\); allowed here: step_stride, "
     r"samples, settle_ms"),
    ("designs: [radial12]\nscenarios: [t_room]\nknobs: {samples: [1, 65]}\n",
     r"knobs\.samples\[1\]: 65 is out of range; allowed 1 … 64"),
    ("designs: [radial12]\nscenarios: [t_room]\nknobs: {settle_ms: [0, fast]}\n",
     r"knobs\.settle_ms\[1\]: expected a number in 0 … 5000 ms, got 'fast'"),
    ("designs: []\nscenarios: [t_room]\n", r"designs: expected a non-empty list of designs"),
    ("- rotating12\n", r"<top>: a study file must be a mapping"),
    ("designs: [radial12\n", r"s\.yaml: line 2: not valid YAML"),
    ("designs: [radial12]\ndesigns: [laser]\n", r"s\.yaml: line 2: key .designs. given twice"),
    ("designs: [{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 40, step_deg: 1, "
     "sensor: [gp2d12]}]\nscenarios: [t_room]\n",
     r"designs\[0\]\.sensor: \['gp2d12'\] is not allowed; choose one of: gp2d12"),
    # printed raw in the summary table (a terminal escape; a line break split the row)
    ('designs: [{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 40, step_deg: 1, '
     'name: "\\e[31mred"}]\nscenarios: [t_room]\n',
     r"designs\[0\]\.name: '\\x1b\[31mred': control characters \(terminal escapes, line "
     r"breaks\) are not allowed"),
    ('designs: [{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 40, step_deg: 1, '
     'name: "ring\\n8"}]\nscenarios: [t_room]\n', r"designs\[0\]\.name: 'ring\\n8': control"),
    ("designs: [{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 40, step_deg: 1, "
     f"name: {'r' * 201}}}]\nscenarios: [t_room]\n",
     r"designs\[0\]\.name: expected a text of 1 … 200 characters, got 'rrrr"),
]


@pytest.mark.parametrize("designs, refused", [(5, False), (6, True)])
def test_a_study_too_big_for_the_work_budget_is_refused_as_too_big(tmp_path, capsys, designs,
                                                                   refused):
    """One budget for every command (core.WORK_MEMORY_BYTES, core.work_refusal): a study's
    results read back take 3,800 bytes a run, so 500,000 runs (1.9 GB) fit and 600,000
    (2.3 GB) do not. It was a limit of its own (200,000 runs, exit 1, its own wording):
    6,400,000 runs, whose grid alone filled memory before the first run, were refused as a
    bad file."""
    names = ", ".join(["radial12", "rotating12", "rotating1", "laser", "sonar12",
                       "{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 40, step_deg: 1, "
                       "name: ring8}"][:designs])
    p = write(tmp_path, f"designs: [{names}]\nscenarios: [t_room]\nseeds: 100000\n")
    if not refused:
        spec = study.load_study(p)
        assert len(spec.designs) * len(spec.scenarios) * spec.seed_count == 500_000
        return
    with pytest.raises(errors.TooBig) as caught:
        study.load_study(p)
    assert str(caught.value) == (
        f"{p}: 6 designs × 1 scenarios × 1 knob settings × 100000 seeds = 600,000 runs, their "
        "results read back to summarise (about 2.3 GB), more than the 2 GB a study may use: "
        "use fewer seeds, knob values, designs or scenarios, or split it into several studies")
    assert main(["study", str(p), "--out", str(tmp_path / "out")]) == errors.TOO_BIG
    err = capsys.readouterr().err
    assert err.startswith("irring study: error: ") and err.count("\n") == 1, err
    assert "more than the 2 GB a study may use" in err and not (tmp_path / "out").exists()


@pytest.mark.parametrize("text, message", BAD)
def test_a_bad_study_file_is_one_line_naming_the_key(tmp_path, capsys, text, message):
    p = write(tmp_path, text)
    with pytest.raises(study.StudyError, match=message):
        study.load_study(p)
    assert main(["study", str(p), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("irring study: error: ") and err.count("\n") == 1, err
    assert not (tmp_path / "out").exists()


def test_the_grid_loads_each_scenario_once(tmp_path, monkeypatch):
    # 2 000 seeds took 60 s to lay out (a scenario read and checked again for every point)
    p = write(tmp_path, "designs: [radial12, rotating12]\nscenarios: [t_room, l_room_post.yaml]\n"
                        "seeds: 2000\nknobs: {samples: [1, 3]}\n")
    spec = study.load_study(p)
    loads = []
    real = study.load_scenario
    monkeypatch.setattr(study, "load_scenario", lambda s: loads.append(s) or real(s))
    points = study.grid(spec)
    assert len(points) == 2 * 2 * 2 * 2000 and sorted(loads) == sorted(spec.scenarios)
    assert points[0].key == ("radial12", "t_room", "1", "1", "0.0", "1")
    assert points[-1].key[1:] == (str(tmp_path / "l_room_post.yaml"), "1", "3", "0.0", "2006")


def test_an_existing_results_file_is_kept_unless_resumed(tmp_path):
    p = write(tmp_path, "designs: [radial12]\nscenarios: [l_room_post.yaml]\n")
    out = tmp_path / "out"
    study.run_study(study.load_study(p), out)
    before = (out / study.RESULTS).read_text()
    with pytest.raises(study.StudyError, match=r"already holds 1 run\(s\); pass --resume"):
        study.run_study(study.load_study(p), out)
    assert (out / study.RESULTS).read_text() == before
    (out / study.RESULTS).write_text("design,scenario,seed\nradial12,x,1\n")
    with pytest.raises(study.StudyError, match=r"its columns are not the ones"):
        study.run_study(study.load_study(p), out, resume=True)



def test_resuming_with_a_design_changed_under_its_name_is_refused(tmp_path, capsys):
    # the 16-sensor run was summarised with the 8-sensor one as two runs of "ring"
    ring8 = "{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 45, step_deg: 1.08, name: ring}"
    p = write(tmp_path, f"designs: [{ring8}]\nscenarios: [l_room_post.yaml]\nseeds: [3]\n")
    out = tmp_path / "out"
    study.run_study(study.load_study(p), out)
    before = (out / study.RESULTS).read_text()
    p.write_text(p.read_text().replace("sensors: 8,", "sensors: 16,").replace("[3]", "[3, 4]"))
    assert main(["study", str(p), "--out", str(out), "--resume", "--workers", "1"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert f"{out / study.RESULTS}: line 2: ring (" in err
    assert "l_room_post.yaml, seed 3) was run with sensors 8; the study file's ring has 16" in err
    assert (out / study.RESULTS).read_text() == before


def test_an_out_folder_that_cannot_be_one_is_one_line(tmp_path, capsys):
    p = write(tmp_path, "designs: [radial12]\nscenarios: [l_room_post.yaml]\n")
    (tmp_path / "a file").write_text("mine")
    assert main(["study", str(p), "--out", str(tmp_path / "a file"), "--workers", "1"]) == 4
    err = capsys.readouterr().err   # checked before any run: the output status, 4
    assert "a file: is a file; expected a folder for the outputs" in err
    assert "Traceback" not in err
    assert (tmp_path / "a file").read_text() == "mine"

# --------------------------------------------------------------------------- executors


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> tuple[Path, list[dict]]:
    """The small study run in this process: the reference rows."""
    tmp = tmp_path_factory.mktemp("study")
    p = write(tmp)
    result = study.run_study(study.load_study(p), tmp / "serial")
    return p, result["rows"]


def test_rows_are_runs_in_grid_order_with_every_score(small):
    p, rows = small
    assert [study.row_key(r) for r in rows] == [pt.key for pt in study.grid(study.load_study(p))]
    r = rows[0]
    assert float(r["hardware_time_s"]) == pytest.approx(71 * 0.0383)
    assert float(rows[2]["hardware_time_s"]) == pytest.approx(24 * 0.0383)   # stride 3: 24 stops
    for k in study.SCORE_COLUMNS:
        assert r[k] != "", k
    assert 0.8 < float(r["occupied_f1"]) <= 1.0
    assert r["irring_version"] and float(r["compute_ms"]) > 0
    # a seed changes the noise and so the scores
    assert rows[0]["range_rmse_m"] != rows[1]["range_rmse_m"]


def test_process_pool_and_dask_give_the_serial_rows(small, tmp_path):
    p, serial = small
    with executor.executor(workers=2) as ex:
        pool = study.run_study(study.load_study(p), tmp_path / "pool", ex)["rows"]
    assert deterministic(pool) == deterministic(serial)
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster, \
            executor.executor(dask=cluster.scheduler_address) as ex:
        dask_rows = study.run_study(study.load_study(p), tmp_path / "dask", ex)["rows"]
    assert deterministic(dask_rows) == deterministic(serial)


def test_a_killed_study_resumes_to_the_uninterrupted_rows(small, tmp_path):
    p, serial = small
    out = tmp_path / "out"
    results = out / study.RESULTS
    cmd = [sys.executable, "-m", "irring", "study", str(p), "--out", str(out), "--workers", "1"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if results.exists() and results.read_text().count("\n") >= 1 + 3:
                break
            time.sleep(0.01)
        assert proc.poll() is None, "the study finished before it could be killed"
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    finally:
        if proc.poll() is None:
            proc.kill()
    kept = study.read_results(results)
    assert 3 <= len(kept) < len(serial)
    # a row being written when the kill came: cut short, dropped on resume
    with open(results, "a") as fh:
        fh.write("rotating12,half a row")
    assert main(["study", str(p), "--out", str(out), "--resume", "--workers", "1"]) == 0
    final = study.read_results(results)
    assert deterministic(final) == deterministic(serial)
    assert [r["compute_ms"] for r in final if study.row_key(r) in
            {study.row_key(k) for k in kept}] == [r["compute_ms"] for r in kept]


def _process_state(pid: int) -> tuple[str, int] | None:
    """(state, parent pid) of a process from /proc, or None when it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    state, ppid = text[text.rindex(")") + 2:].split()[:2]
    return state, int(ppid)


def _descendants(pid: int) -> set[int]:
    """Every living process below ``pid`` (zombies are done: left out)."""
    kids: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        seen = _process_state(int(entry.name)) if entry.name.isdigit() else None
        if seen is not None and seen[0] != "Z":
            kids.setdefault(seen[1], []).append(int(entry.name))
    found, todo = set(), [pid]
    while todo:
        for kid in kids.get(todo.pop(), ()):
            found.add(kid)
            todo.append(kid)
    return found


def _living(pids) -> list[int]:
    return sorted(p for p in pids if (_process_state(p) or ("Z",))[0] != "Z")


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads processes from /proc")
def test_a_sigkilled_study_leaves_no_process_behind(tmp_path):
    """`irring study --workers 2` killed with SIGKILL left its two workers idle for good,
    parent 1, and the forkserver and resource tracker they keep alive: each
    worker now ends when its parent does, and the helpers with them. Polled, within 30 s."""
    p = tmp_path / "long.yaml"
    p.write_text("designs: [rotating12, radial12]\nscenarios: [t_room]\nseeds: 40\n")
    results = tmp_path / "out" / study.RESULTS
    cmd = [sys.executable, "-m", "irring", "study", str(p), "--out", str(tmp_path / "out"),
           "--workers", "2"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    helpers: set[int] = set()
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            helpers = _descendants(proc.pid)   # the tracker, the forkserver, 2 workers
            if len(helpers) >= 4 and results.exists() and \
                    results.read_text().count("\n") >= 1 + 2:
                break
            time.sleep(0.05)
        assert proc.poll() is None, "the study finished before it could be killed"
        assert len(helpers) == 4, helpers
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and _living(helpers):
            time.sleep(0.05)
        assert _living(helpers) == []
    finally:
        if proc.poll() is None:
            proc.kill()
        for pid in _living(helpers):   # what a failure left: ours, by id
            os.kill(pid, signal.SIGKILL)


def test_an_unreachable_scheduler_is_one_line_within_seconds():
    import socket

    pytest.importorskip("dask.distributed")
    with socket.socket() as s:                      # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.monotonic()
    with pytest.raises(executor.ExecutorError,
                       match=rf"cannot reach the Dask scheduler at 'tcp://127.0.0.1:{port}'"):
        with executor.executor(dask=f"tcp://127.0.0.1:{port}"):
            pass
    assert time.monotonic() - t0 < 20          # Dask's own default waits 30 s



@pytest.mark.parametrize("answer", [b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n\r\n",
                                    b"", None])
def test_a_server_that_is_not_a_scheduler_is_one_line_within_seconds(answer):
    """The dashboard's port (8787, HTTP) for the scheduler's, or anything else listening:
    Dask reads the reply as a frame length (an HTTP reply asks for 3 EiB: MemoryError)."""
    import socket
    import threading

    pytest.importorskip("dask.distributed")
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen()
    port = srv.getsockname()[1]
    held = []

    def serve():
        while True:
            try:
                conn, _ = srv.accept()
            except OSError:
                return
            if answer is None:      # accepts and says nothing
                held.append(conn)
                continue
            conn.sendall(answer)
            conn.close()

    threading.Thread(target=serve, daemon=True).start()
    t0 = time.monotonic()
    try:
        with pytest.raises(executor.ExecutorError,
                           match=rf"cannot reach the Dask scheduler at 'tcp://127.0.0.1:{port}'"):
            with executor.executor(dask=f"tcp://127.0.0.1:{port}"):
                pass
    finally:
        srv.close()
        for c in held:
            c.close()
    assert time.monotonic() - t0 < 20

class _Recording(executor.Executor):
    """Runs each job at submit, like a pool whose workers are instant, and counts submits."""

    def __init__(self):
        self.submitted = 0

    def submit(self, fn, /, *args):
        from concurrent.futures import Future

        self.submitted += 1
        f = Future()
        f.set_result(fn(*args))
        return f


def test_stream_keeps_a_bounded_window_and_run_jobs_the_job_order():
    ex = _Recording()
    ahead = []
    for n, (i, r) in enumerate(executor.stream(abs, list(range(-10, 0)), ex, window=3)):
        assert r == abs(i - 10)
        ahead.append(ex.submitted - n)
    assert ex.submitted == 10 and max(ahead) == 3       # never more than 3 uncollected
    assert executor.run_jobs(abs, [-3, 1, -2], _Recording()) == [3, 1, 2]


# --------------------------------------------------------------------------- summary


def _row(design: str, f1: float, hw: float, seed: int) -> dict:
    r = {c: "" for c in study.COLUMNS}
    r.update(design=design, scenario="x", step_stride="1", samples="1", settle_ms="0.0",
             seed=str(seed), occupied_f1=repr(f1), coverage=repr(f1 / 2),
             hardware_time_s=repr(hw), compute_ms="1.0", valid_share="0.9",
             range_rmse_m="0.01")
    return r


def test_summary_is_mean_and_sd_per_design_with_the_pareto_front(tmp_path):
    rows = [_row("slow_good", 0.9, 3.0, 1), _row("slow_good", 0.7, 3.0, 2),
            _row("fast_bad", 0.3, 0.5, 1), _row("fast_bad", 0.4, 0.5, 2),
            _row("dominated", 0.5, 4.0, 1), _row("dominated", 0.6, 4.0, 2)]
    recs = {r["design"]: r for r in study.summarise(rows)}
    assert recs["slow_good"]["occupied_f1"] == pytest.approx(0.8)
    assert recs["slow_good"]["occupied_f1_std"] == pytest.approx(math.sqrt(0.02))
    assert recs["fast_bad"]["coverage"] == pytest.approx(0.175)
    assert recs["slow_good"]["shadow"] is None                  # no shadow in any run
    assert [n for n, r in recs.items() if r["front_hw_f1"]] == ["slow_good", "fast_bad"]


def test_the_shadow_is_averaged_over_the_rooms_that_have_one_and_says_so():
    """Three runs, the shadow defined in two (a room with a post, 0.5 and 0.8) and not in
    the third (nothing hidden): the mean is 0.65 and the table says `in 2/3`."""
    rows = [_row("ring", 0.9, 3.0, s) for s in (1, 2, 3)]
    rows[0]["shadow"], rows[2]["shadow"] = "0.5", "0.8"
    rows.append(_row("other", 0.8, 2.0, 1))
    rows[-1]["shadow"] = "0.25"
    recs = study.summarise(rows)
    assert recs[0]["shadow"] == pytest.approx(0.65) and recs[0]["shadow_runs"] == 2
    lines = study.table(recs).splitlines()
    assert "0.650 ± 0.212 in 2/3" in lines[2]
    assert "0.250 ± 0.000" in lines[3] and " in 1/1" not in lines[3]   # all runs: no note


def test_the_chart_leaves_the_users_backend_alone(tmp_path):
    import matplotlib

    matplotlib.use("svg")
    recs = study.summarise([_row("a", 0.9, 3.0, 1), _row("b", 0.3, 0.5, 1)])
    study.chart(recs, tmp_path / "c.png")
    assert matplotlib.get_backend() == "svg"
    assert (tmp_path / "c.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _grid_rows(seeds: dict[str, list[int]]) -> list[dict]:
    """2 designs × the rooms of ``seeds`` (room → its seeds) × 2 values of each knob."""
    rows = []
    for d, f1, hw in (("ring_a", 0.9, 3.0), ("ring_b", 0.4, 0.5)):
        for room, room_seeds in seeds.items():
            for stride, samples, settle in itertools.product("14", "28", ("0.0", "40.0")):
                for seed in room_seeds:
                    r = _row(d, f1 - 0.01 * seed, hw * int(stride), seed)
                    r.update(scenario=room, step_stride=stride, samples=samples,
                             settle_ms=settle)
                    rows.append(r)
    return rows


def test_the_chart_is_titled_with_the_study_and_its_legend_is_under_the_panels(tmp_path,
                                                                               figures):
    """study.png says which study it shows and how many runs of what (in the picture and
    in the PNG's Title); its legend, beside the panels a sixth of the width and mostly
    blank, is under them, inside the figure, with 8 knob settings of long labels."""
    from PIL import Image

    knobs = ["step_stride", "samples", "settle_ms"]
    rows = _grid_rows({"room_x": [1, 2], "room_y": [2, 3]})
    title = ("a$b.yaml: 64 runs = 2 designs × 2 rooms × 2 step_stride values × 2 samples "
             "values × 2 settle_ms values × 2 seeds per room")
    assert study.study_title("a$b.yaml", rows, knobs) == title
    assert study.study_title("s.yaml", rows[1:], knobs) == (
        "s.yaml: 63 runs of 2 designs, 2 rooms, 2 step_stride values, 2 samples values, "
        "2 settle_ms values, 2 seeds per room")
    same = _grid_rows({"room_x": [4, 5, 6], "room_y": [4, 5, 6]})
    assert study.study_title("s.yaml", same, knobs) == (
        "s.yaml: 96 runs = 2 designs × 2 rooms × 2 step_stride values × 2 samples values × "
        "2 settle_ms values × 3 seeds (4–6)")
    assert study.study_title("s.yaml", _grid_rows({"r": [3, 9]}), knobs).endswith(
        "= 2 designs × 1 room × 2 step_stride values × 2 samples values × 2 settle_ms values "
        "× 2 seeds (3, 9)")

    paths = study.write_summary(rows, tmp_path / "mine", knobs, "a$b.yaml")
    assert Image.open(paths["chart"]).text["Title"] == title
    # the figure it saved: study.chart of these rows' summary by design and knobs, so titled
    fig = figures[0]
    study.write_summary(rows, tmp_path / "out", knobs)   # from code: named by its folder
    assert Image.open(tmp_path / "out" / "study.png").text["Title"].startswith(
        "the study in out: 64 runs = ")
    assert len(figures) == 2

    assert fig.get_suptitle() == title.replace("$", r"\$")   # drawn as text, not mathtext
    renderer = fig.canvas.get_renderer()
    width = fig.get_figwidth() * fig.dpi
    lowest_panel = min(ax.get_tightbbox(renderer).y0 for ax in fig.axes)
    assert len(fig.legends) == 2
    for legend in fig.legends:
        box = legend.get_window_extent(renderer)
        assert 0 <= box.x0 and box.x1 <= width and box.y0 >= 0
        assert box.y1 <= lowest_panel        # under the panels, below their axis labels
    assert fig.axes[0].get_position().x0 < 0.1 and fig.axes[1].get_position().x1 > 0.95
    labels = [[t.get_text() for t in legend.get_texts()] for legend in fig.legends]
    assert labels[1] == ["ring_a", "ring_b"]           # the designs' row above the markers'
    assert labels[0][0] == "stride 1, samples 2, settle ms 0.0"
    assert labels[0][-1] == "Pareto front" and len(labels[0]) == 9


def test_parquet_holds_the_csv_rows_typed(small):
    pq = pytest.importorskip("pyarrow.parquet")
    p, rows = small
    table = pq.read_table(p.parent / "serial" / "results.parquet")
    assert table.column_names == list(study.COLUMNS)
    assert table.num_rows == len(rows)
    assert table.column("occupied_f1").to_pylist() == [float(r["occupied_f1"]) for r in rows]
    assert table.column("seed").to_pylist() == [int(r["seed"]) for r in rows]


def test_a_failed_parquet_write_leaves_the_earlier_file(tmp_path, monkeypatch):
    """results.parquet is written beside its place and renamed in when whole (pyarrow
    stood in for by a writer that fails half-way, so this runs without pyarrow too)."""
    import types

    csv_path = tmp_path / study.RESULTS
    csv_path.write_text("design,seed\nradial12,3\n")
    parquet = tmp_path / "results.parquet"
    parquet.write_bytes(b"last study's table")

    def write_table(table, where):
        Path(where).write_bytes(b"PAR1 half a table")
        if table == "fail":
            raise OSError(28, "No space left on device")

    reads = iter(["fail", "table"])
    fake_csv = types.SimpleNamespace(read_csv=lambda path: next(reads))
    monkeypatch.setitem(sys.modules, "pyarrow", types.ModuleType("pyarrow"))
    monkeypatch.setitem(sys.modules, "pyarrow.csv", fake_csv)
    monkeypatch.setitem(sys.modules, "pyarrow.parquet",
                        types.SimpleNamespace(write_table=write_table))
    with pytest.raises(OSError, match="No space left"):
        study._write_parquet(csv_path)
    assert parquet.read_bytes() == b"last study's table"
    assert sorted(p.name for p in tmp_path.iterdir()) == [study.RESULTS, "results.parquet"]
    assert study._write_parquet(csv_path) == parquet
    assert parquet.read_bytes() == b"PAR1 half a table"


def test_ctrl_c_says_how_many_runs_are_kept_and_how_to_resume(small, tmp_path, monkeypatch,
                                                              capsys):
    p, rows = small
    out = tmp_path / "out"
    out.mkdir()
    lines = (p.parent / "serial" / study.RESULTS).read_text().splitlines(keepends=True)
    (out / study.RESULTS).write_text("".join(lines[:3]))           # header + 2 finished runs

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(study, "run_study", interrupted)
    assert main(["study", str(p), "--out", str(out), "--workers", "1", "--resume"]) == 130
    err = capsys.readouterr().err
    assert err == (f"irring study: interrupted; 2 finished run(s) kept in {out / study.RESULTS}: "
                   "run the same command with --resume to run the rest\n")


def test_an_interrupted_study_leaves_no_summary_of_an_earlier_smaller_one(small, tmp_path,
                                                                         monkeypatch):
    """A finished study grown (more seeds) and resumed, then stopped by Ctrl-C, kept the
    first study's summary.csv/.json, study.png and results.parquet (2 runs) beside a
    results.csv of more: the folder looked finished."""
    p, rows = small
    out = tmp_path / "out"
    out.mkdir()
    lines = (p.parent / "serial" / study.RESULTS).read_text().splitlines(keepends=True)
    (out / study.RESULTS).write_text("".join(lines[:3]))           # an earlier study: 2 runs
    study.write_summary(study.read_results(out / study.RESULTS), out)
    (out / "results.parquet").write_bytes(b"PAR1 the 2 runs")
    real, ran = study.run_point, []

    def the_second_is_interrupted(task):
        if ran:
            raise KeyboardInterrupt
        ran.append(task)
        return real(task)

    monkeypatch.setattr(study, "run_point", the_second_is_interrupted)
    with pytest.raises(KeyboardInterrupt):
        study.run_study(study.load_study(p), out, resume=True)
    assert len(study.read_results(out / study.RESULTS)) == 3
    assert sorted(f.name for f in out.iterdir()) == [study.RESULTS, study.SCENARIOS]
    monkeypatch.setattr(study, "run_point", real)
    done = study.run_study(study.load_study(p), out, resume=True)
    assert done["ran"] == len(rows) - 3
    assert {f.name for f in out.iterdir()} >= {study.RESULTS, study.SCENARIOS,
                                               *study.SUMMARY_FILES.values()}
    summary = json.loads((out / "summary.json").read_text())["configurations"]
    assert sum(c["runs"] for c in summary) == len(rows)


def test_ctrl_c_stops_a_pool_at_once_and_terminates_its_running_workers():
    """SIGINT to `irring study --workers 2` left the workers running their jobs."""
    import time

    from irring.studies.executor import executor, run_jobs

    workers = []

    def interrupt(_):
        workers.extend(ex._processes.values())
        raise KeyboardInterrupt

    t0 = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        with executor(2) as ex:
            run_jobs(time.sleep, [0.0, 120.0, 120.0, 120.0], ex, progress=interrupt)
    assert time.monotonic() - t0 < 60   # not the 120 s a running job would take
    assert len(workers) == 2 and not any(w.is_alive() for w in workers)


def test_sigterm_to_a_pool_parent_ends_like_ctrl_c_and_restores_the_default():
    import os
    import signal
    import time

    from irring.studies.executor import executor

    with pytest.raises(KeyboardInterrupt):
        with executor(2):
            # never send SIGTERM to the test process unless the handler is in place
            assert signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(10)
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


def test_a_folder_of_rooms_is_its_yaml_files_in_name_order(tmp_path, monkeypatch):
    """A study over many rooms had to list every file: `scenarios: [rooms/]` was refused
    ("is a folder; expected a scenario file") where `irring bench rooms rooms/` takes it.
    Relative to the study file, as a file is; a pipe among the rooms, an
    empty folder and a room listed again beside its folder are refused before any run."""
    sub = tmp_path / "sub"
    (sub / "rooms").mkdir(parents=True)
    (sub / "rooms" / "b_room.yaml").write_text(ROOM.replace("l_room_post", "b_room"))
    (sub / "rooms" / "a_room.yaml").write_text(ROOM.replace("l_room_post", "a_room")
                                               .replace("seed: 7", "seed: 40"))
    (sub / "rooms" / "notes.txt").write_text("not a room")
    (sub / "st.yaml").write_text("designs: [rotating12]\nscenarios: [rooms, t_room]\nseeds: 2\n")
    monkeypatch.chdir(tmp_path)
    s = study.load_study("sub/st.yaml")
    assert s.scenarios == ("sub/rooms/a_room.yaml", "sub/rooms/b_room.yaml", "t_room")
    assert [(p.scenario, p.seed) for p in study.grid(s)] == [
        ("sub/rooms/a_room.yaml", 40), ("sub/rooms/a_room.yaml", 41),
        ("sub/rooms/b_room.yaml", 7), ("sub/rooms/b_room.yaml", 8), ("t_room", 1), ("t_room", 2)]
    (sub / "empty").mkdir()
    (sub / "st.yaml").write_text("designs: [rotating12]\nscenarios: [empty]\n")
    with pytest.raises(study.StudyError) as empty:
        study.load_study("sub/st.yaml")
    assert str(empty.value) == ("sub/st.yaml: scenarios[0]: sub/empty: the folder holds no "
                                "*.yaml scenario")
    (sub / "st.yaml").write_text("designs: [rotating12]\n"
                                 "scenarios: [rooms, rooms/b_room.yaml]\n")
    with pytest.raises(study.StudyError) as twice:
        study.load_study("sub/st.yaml")
    assert str(twice.value) == ("sub/st.yaml: scenarios[1]: scenario 'sub/rooms/b_room.yaml' "
                                "is listed twice")
    os.mkfifo(sub / "rooms" / "c_pipe.yaml")
    (sub / "st.yaml").write_text("designs: [rotating12]\nscenarios: [rooms]\n")
    with pytest.raises(study.StudyError) as pipe:
        study.load_study("sub/st.yaml")
    assert str(pipe.value) == (
        "sub/st.yaml: scenarios[0]: sub/rooms/c_pipe.yaml: is a pipe, socket or device, not "
        "a scenario file; a folder's rooms are its regular *.yaml files")


def test_a_resumed_study_says_which_kept_runs_it_left_out_of_the_summary(tmp_path, capsys):
    """A study cut down and resumed (a design dropped, seeds added) printed "6 run(s) in
    results.csv: ran 2 (2 already in the file)" above a table of 4 runs: the dropped
    design's 2 rows stay in the file, unsummarised, and nothing said so."""
    spec = write(tmp_path, "designs: [radial12, rotating12]\nscenarios: [l_room_post.yaml]\n"
                           "seeds: [3, 11]\n")
    out = tmp_path / "out"
    assert main(["study", str(spec), "--workers", "1", "--out", str(out)]) == 0
    capsys.readouterr()
    spec.write_text("designs: [radial12]\nscenarios: [l_room_post.yaml]\nseeds: [3, 11, 12]\n")
    assert main(["study", str(spec), "--workers", "1", "--out", str(out), "--resume"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert re.fullmatch(
        rf"5 run\(s\) in {re.escape(str(out / 'results.csv'))}: ran 1 in \d+\.\d s, "
        rf"\d+\.\d runs/s \(2 already in the file; 2 run\(s\) of grid points no longer in "
        rf"{re.escape(str(spec))}: kept in the file, left out of the summary\)", first), first


def test_study_and_bench_accuracy_bars_wait_for_each_workers_first_run(tmp_path, monkeypatch):
    """Both commands' bars are told how many first runs pay a worker's start (its ETA
    waits for them: tests/test_run.py checks the bar): one per worker of the pool."""
    from irring import pipeline
    from irring.cli import bench_accuracy as bench_cli
    from irring.cli import study as study_cli

    asked = []

    def bar(total, desc, enabled=None, **kw):
        asked.append((desc, kw["warmup"], kw["warmup_note"]))
        return pipeline.progress_bar(total, desc, False)

    monkeypatch.setattr(study_cli, "progress_bar", bar)
    monkeypatch.setattr(bench_cli, "progress_bar", bar)
    # the bars are the matter here, not the charts (drawn and checked by their own tests)
    from irring.studies import accuracy as accuracy_mod

    def no_chart(result, path, *a, **k):
        Path(path).write_bytes(b"")

    monkeypatch.setattr(study, "chart", no_chart)
    monkeypatch.setattr(accuracy_mod, "chart", no_chart)
    p = tmp_path / "one.yaml"
    p.write_text("designs: [radial12]\nscenarios: [t_room]\nseeds: 1\n")
    assert main(["study", str(p), "--out", str(tmp_path / "s"), "--workers", "2"]) == 0
    assert main(["bench", "accuracy", "--scenario", "t_room", "--knob", "resolution",
                 "--seeds", "1", "--workers", "1", "--out", str(tmp_path / "a")]) == 0
    note = "ETA after each worker's first run"
    assert asked == [("study", 2, note), ("bench accuracy", 1, note)]


def test_a_dollar_in_a_design_name_is_drawn_as_text(tmp_path):
    """A design named "a$\\frac$" (printable, so allowed) made matplotlib parse mathtext and
    the chart fail after every run; "r$2$" drew a 2 in italics."""
    recs = study.summarise([_row("a$\\frac$", 0.9, 3.0, 1), _row("r$2$", 0.4, 0.5, 1)])
    fig = study.chart(recs, tmp_path / "c.png", title="s.yaml: 2 runs")
    labels = [t.get_text() for legend in fig.legends for t in legend.get_texts()]
    assert labels == ["Pareto front", "a\\$\\frac\\$", "r\\$2\\$"]
    assert (tmp_path / "c.png").stat().st_size > 10_000


def test_the_printed_table_says_what_each_column_measures(tmp_path, capsys):
    """The summary table's "RMSE mm", "hardware" and "compute" were explained only in the
    study file's CSV columns (results.csv, --help); a designer reading the table asked which
    error, which time."""
    from irring.cli import main

    p = tmp_path / "s.yaml"
    p.write_text("designs: [radial12]\nscenarios: [t_room_cylinder]\nseeds: 1\n")
    assert main(["study", str(p), "--out", str(tmp_path / "o"), "--workers", "1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split()[8:11] == ["RMSE", "mm", "hardware"]
    assert lines[4] == (
        "mean ± sd over scenarios × seeds; shadow only over the runs in rooms that hide wall "
        "behind an obstacle (in k/n: k of the n runs; —: none); RMSE: range error of the valid "
        "readings against the true range; hardware: one 360° view; compute: estimator + mapper "
        "CPU per sweep (median); front: on the Pareto front of hardware time against occupied "
        "F1 (f1), coverage (cov), range RMSE (rmse)")


def test_a_worker_killed_mid_study_says_how_many_runs_are_kept(small, tmp_path, monkeypatch,
                                                               capsys):
    """A pool worker killed under its run (the out-of-memory killer, `kill`) ended the study
    as "internal error (BrokenProcessPool: …); … please report it", exit 70, and nothing
    said that the finished runs were kept or that --resume runs the rest."""
    p, rows = small
    out = tmp_path / "out"
    real = study.stream

    def then_a_worker_is_killed(fn, jobs, ex):
        jobs = list(jobs)
        yield from real(fn, jobs[:2], ex)
        yield from real(signal.raise_signal, [signal.SIGKILL], ex)   # on a worker of the pool

    monkeypatch.setattr(study, "stream", then_a_worker_is_killed)
    assert main(["study", str(p), "--out", str(out), "--workers", "2"]) == errors.INTERRUPTED
    assert capsys.readouterr().err == (
        "irring study: error: a worker process ended before its run did (killed: out of "
        "memory, or `kill`; or it crashed: if again at the same run, please report it with "
        f"--debug); 2 finished run(s) kept in {out / study.RESULTS}: run the same command "
        "with --resume to run the rest\n")
    monkeypatch.setattr(study, "stream", real)
    assert main(["study", str(p), "--out", str(out), "--resume", "--workers", "1"]) == 0
    assert deterministic(study.read_results(out / study.RESULTS)) == deterministic(rows)


def test_a_job_whose_workers_died_is_worker_lost_on_every_executor():
    """The pool's BrokenProcessPool and Dask's KilledWorker (a job given up after its
    workers died under it) are one error; any other exception of a job is its own."""
    with pytest.raises(executor.WorkerLost) as pool:
        with executor.executor(2) as ex:
            executor.run_jobs(signal.raise_signal, [signal.SIGKILL], ex)
    assert str(pool.value) == executor.WORKER_LOST
    assert pool.value.status == errors.INTERRUPTED
    distributed = pytest.importorskip("distributed")

    class Dying(executor.Executor):   # as a Dask client's executor hands back the failure
        def submit(self, fn, /, *args, **kwargs):
            f = executor.Future()
            f.set_exception(distributed.KilledWorker("run_point-3f2a", None, 3))
            return f

    with pytest.raises(executor.WorkerLost, match=re.escape(executor.WORKER_LOST)):
        executor.run_jobs(abs, [-3], Dying())
    with pytest.raises(ZeroDivisionError):
        executor.run_jobs(abs, [-3], type("Failing", (executor.Executor,), {
            "submit": lambda self, fn, *a: executor.SerialExecutor().submit(divmod, 1, 0)})())


def test_parts_of_a_study_run_apart_merge_into_its_results(small, tmp_path):
    """A study split by seeds over two machines (README, "Runs made elsewhere merge"):
    each part's rows appended to one results.csv, the whole study resumed there runs
    nothing again and holds the rows of the study run whole."""
    p, rows = small
    (tmp_path / "l_room_post.yaml").write_text(ROOM)
    parts = []
    for seed in (3, 11):
        part = tmp_path / f"seed{seed}.yaml"
        part.write_text(STUDY.replace("seeds: [3, 11]", f"seeds: [{seed}]"))
        parts.append(study.run_study(study.load_study(part), tmp_path / f"out{seed}"))
    whole = tmp_path / "whole"
    whole.mkdir()
    first, second = ((tmp_path / f"out{seed}" / study.RESULTS).read_text().splitlines(True)
                     for seed in (3, 11))
    (whole / study.RESULTS).write_text("".join(first + second[1:]))
    merged = study.run_study(study.load_study(write(tmp_path, name="whole.yaml")), whole,
                             resume=True)
    assert (merged["ran"], merged["done_before"]) == (0, 8)
    # the same rows but the room's path (this test's folder, not the fixture's)
    assert [r[:1] + r[2:] for r in deterministic(merged["rows"])] == \
        [r[:1] + r[2:] for r in deterministic(rows)]
    (whole / study.RESULTS).write_text("".join(first + second[1:] + first[1:2]))
    with pytest.raises(study.StudyError, match=r"line 10 repeats the run of line 2 "):
        study.run_study(study.load_study(tmp_path / "whole.yaml"), whole, resume=True)


def test_the_chart_labels_its_time_axis_in_plain_seconds(small, tmp_path):
    """study.png's log axis read 10⁻¹, 10⁰, 10¹ (and 2×10⁰, 3×10⁰ on a study within one
    decade): a number to decode before reading the chart. Now 0.5, 1, 2 … as accuracy.png."""
    p, rows = small
    by = ("design", "step_stride")
    records = study.summarise(rows, by)             # 0.9 … 3.3 s: within 1.5 decades
    held_still = dict(records[0], design="radial12", hardware_time_s=0.0383)
    for recs, labels in ((records, ["0.4", "0.5", "0.6", "0.8", "1", "1.5", "2", "3", "4"]),
                         (records + [held_still], ["0.05", "0.1", "0.2", "0.5", "1", "2", "5"])):
        fig = study.chart(recs, tmp_path / "study.png", by)
        fig.canvas.draw()
        for ax in fig.axes[:2]:
            lo, hi = ax.get_xlim()
            assert [t.get_text() for t in ax.get_xticklabels()
                    if t.get_text() and lo <= t.get_position()[0] <= hi] == labels


def test_a_run_that_raises_says_how_many_runs_are_kept(small, tmp_path, monkeypatch, capsys):
    """A run that raised (a bug in one room or seed) ended the study with the bug's line
    alone: nothing said the runs before it were kept for --resume."""
    p, rows = small
    out = tmp_path / "out"
    real, ran = study.run_point, []

    def the_third_raises(task):
        ran.append(task)
        if len(ran) == 3:
            raise ValueError("a bug in run 3")
        return real(task)

    monkeypatch.setattr(study, "run_point", the_third_raises)
    assert main(["study", str(p), "--out", str(out), "--workers", "1"]) == errors.INTERNAL
    assert capsys.readouterr().err == (
        "irring study: error: internal error (ValueError: a bug in run 3); rerun with --debug "
        f"(or IRRING_DEBUG=1) for the traceback and please report it; 2 finished run(s) kept "
        f"in {out / study.RESULTS}: run the same command with --resume to run the rest\n")
    assert len(study.read_results(out / study.RESULTS)) == 2


def test_the_f1_axis_is_stretched_towards_one_and_says_which_way_is_better(small, tmp_path):
    """study.png drew F1 on 0 … 1: rings at 0.995 and 0.998 sat one pixel apart among the
    top 2 % of the panel (docs/study.png: five rings one blob). The F1 axis is stretched
    towards 1 and ticked in plain numbers; both panels say higher is better."""
    p, rows = small
    by = ("design", "step_stride")
    base = study.summarise(rows, by)[0]
    recs = [dict(base, design="a", occupied_f1=0.995, occupied_f1_std=0.0),
            dict(base, design="b", occupied_f1=0.998, occupied_f1_std=0.0),
            dict(base, design="held", occupied_f1=0.155, occupied_f1_std=0.0)]
    fig = study.chart(recs, tmp_path / "study.png", by)
    fig.canvas.draw()
    f1, cov = fig.axes[:2]
    px = [f1.transData.transform((1.0, y))[1] for y in (0.155, 0.995, 0.998)]
    assert px[2] - px[1] > 20 and px[1] - px[0] > 100    # linear: 0.9 px apart
    lo, hi = f1.get_ylim()
    assert [t.get_text() for t in f1.get_yticklabels() if lo <= t.get_position()[1] <= hi] == \
        ["0", "0.5", "0.8", "0.9", "0.95", "0.98", "0.99", "0.995", "0.998", "1"]
    assert f1.get_ylabel() == ("occupied F1, higher is better\n(mean ± 1 sd over runs; scale "
                               "stretched towards 1)")
    assert cov.get_yscale() == "linear"
    assert cov.get_ylabel() == "coverage, higher is better\n(mean ± 1 sd over runs)"
