"""Outputs are atomic and --out is checked first (issue 15) for the study commands:
`irring compare`, `irring bench accuracy`, `irring bench rooms` and `irring study`'s summary.
(`irring run` has its own in test_hostile.py.)"""

from __future__ import annotations

import errno
import importlib
import os
import re
from pathlib import Path

import pytest

from irring.cli import main
from irring.errors import OutputError
from irring.outputs import OutputSet, atomic_file
from irring.studies import report

# A room of our own: 0.93 × 0.71 m, one post off-centre, one pose (x ≠ y everywhere).
ROOM = """\
name: post_box
seed: 4
room:
  outline_mm: [[0, 0], [930, 0], [930, 710], [0, 710]]
obstacles:
  - {type: cylinder, center_mm: [690, 210], radius_mm: 26}
robot:
  poses:
    - {x_mm: 410, y_mm: 330, yaw_deg: 7}
effects: [incidence, noise, quantization]
"""

STUDY = "designs: [radial12]\nscenarios: [post_box.yaml]\nseeds: 1\n"

# each command: the argv before --out (given the folder holding ROOM/STUDY), and the module
# attribute the command calls to do the runs
COMMANDS = {
    "compare": (lambda d: ["compare", "--scenario", str(d / "post_box.yaml"), "--design",
                           "radial12", "--seeds", "1", "--bearings", "8", "--distances-mm",
                           "400"], "irring.studies.compare", "compare"),
    "bench accuracy": (lambda d: ["bench", "accuracy", "--scenario", str(d / "post_box.yaml"),
                                  "--knob", "tolerance", "--seeds", "1", "--workers", "1"],
                       "irring.studies.accuracy", "measure"),
    "bench rooms": (lambda d: ["bench", "rooms", str(d / "post_box.yaml")],
                    "irring.cli.bench_rooms", "measure"),
    "study": (lambda d: ["study", str(d / "s.yaml"), "--workers", "1"], "irring.studies.study",
              "run_study"),
}


@pytest.fixture
def inputs(tmp_path):
    d = tmp_path / "in"
    d.mkdir()
    (d / "post_box.yaml").write_text(ROOM)
    (d / "s.yaml").write_text(STUDY)
    return d


def _snapshot(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def _never(*a, **k):
    raise AssertionError("the runs started before --out was checked")


@pytest.mark.parametrize("command", list(COMMANDS))
def test_out_naming_a_file_is_refused_before_any_run(command, inputs, tmp_path, monkeypatch,
                                                      capsys):
    argv, name, runner = COMMANDS[command]
    module = importlib.import_module(name)
    monkeypatch.setattr(module, runner, _never)
    target = tmp_path / "taken.txt"
    target.write_text("keep")
    assert main(argv(inputs) + ["--out", str(target)]) == 4
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"--out {target}: is a file; expected a folder for the outputs" in err
    assert target.read_text() == "keep"
    # a folder below a file cannot be made either
    assert main(argv(inputs) + ["--out", str(target / "sub")]) == 4
    assert f"{target} is a file, so the folder cannot be made" in capsys.readouterr().err
    assert sorted(os.listdir(tmp_path)) == ["in", "taken.txt"]


@pytest.mark.parametrize("command", list(COMMANDS))
def test_out_naming_a_broken_link_is_refused_before_any_run(command, inputs, tmp_path,
                                                            monkeypatch, capsys):
    # the whole work was done, then 'cannot move the outputs in: Not a directory' (exit 4)
    argv, name, runner = COMMANDS[command]
    monkeypatch.setattr(importlib.import_module(name), runner, _never)
    (tmp_path / "gone").symlink_to(tmp_path / "scratch" / "out")
    (tmp_path / "loop").symlink_to("loop")
    for link, to in (("gone", tmp_path / "scratch" / "out"), ("loop", "loop")):
        assert main(argv(inputs) + ["--out", str(tmp_path / link)]) == 4
        assert capsys.readouterr().err.endswith(
            f": error: --out {tmp_path / link}: is a link to {to}, which does not exist (or a "
            "loop of links); make that folder or name another\n")
    assert sorted(os.listdir(tmp_path)) == ["gone", "in", "loop"]


def _full_disk(*a, **k):
    raise OSError(errno.ENOSPC, "No space left on device")


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_failed_write_leaves_the_earlier_outputs_byte_identical(command, inputs, tmp_path,
                                                                  monkeypatch, capsys):
    argv, name, runner = COMMANDS[command]
    module = importlib.import_module(name)
    out = tmp_path / "out"
    real, results = getattr(module, runner), []

    def remember(*a, **k):
        results.append(real(*a, **k))
        return results[-1]

    monkeypatch.setattr(module, runner, remember)
    assert main(argv(inputs) + ["--out", str(out)]) == 0
    before = _snapshot(out)
    if command == "study":
        assert set(before) == {"results.csv", "scenarios.json", "summary.csv", "summary.json",
                               "study.png"}
        # a second seed on --resume: one more row streamed to results.csv, a new summary
        (inputs / "s.yaml").write_text(STUDY.replace("seeds: 1", "seeds: 2"))
        argv_again = argv(inputs) + ["--resume"]
    else:   # the first run's result, told apart: every file of the set would change
        again = ([dict(r, again=True) for r in results[0]] if command == "bench rooms"
                 else dict(results[0], again=True))
        monkeypatch.setattr(module, runner, lambda *a, **k: again)
        argv_again = argv(inputs)
    capsys.readouterr()
    if command == "bench rooms":   # no chart: the disk fills while writing rooms.csv
        import csv

        monkeypatch.setattr(csv, "writer", _full_disk)
    else:   # the disk fills as the chart is written (drawing it again would only cost time)
        monkeypatch.setattr(module, "chart", _full_disk)
    assert main(argv_again + ["--out", str(out)]) == 4
    assert (f"--out {out}: cannot write the outputs there: No space left on device; nothing "
            "was changed") in capsys.readouterr().err
    after = _snapshot(out)
    if command == "study":   # the checkpoint streams on (and keeps both rows); the first
        # run's summary went when the new row came (it would count one run of two)
        assert after.pop("results.csv").count(b"\n") == before.pop("results.csv").count(b"\n") + 1
        assert after.pop("scenarios.json") == before["scenarios.json"]   # the same room
        before = {}
    assert after == before
    assert sorted(os.listdir(tmp_path)) == ["in", "out"]   # no temporaries left
    monkeypatch.undo()
    if command != "study":   # and the set is whole after a write that succeeds
        monkeypatch.setattr(module, runner, lambda *a, **k: results[0])
        if "chart" in vars(module):   # the first run's result: its chart, not drawn again
            png = next(n for n in before if n.endswith(".png"))
            monkeypatch.setattr(module, "chart",
                                lambda result, path, *a, **k: Path(path).write_bytes(before[png]))
        assert main(argv(inputs) + ["--out", str(out)]) == 0
        assert set(_snapshot(out)) == set(before)


def test_an_output_set_replaces_its_own_files_and_keeps_the_others(tmp_path):
    out = tmp_path / "study"
    out.mkdir()
    (out / "results.csv").write_bytes(b"streamed rows\n")
    (out / "summary.csv").write_text("old summary")
    (out / "study.png").write_text("old chart")
    files = ("summary.csv", "summary.json", "study.png")

    with pytest.raises(KeyboardInterrupt):
        with OutputSet(out, files=files) as tmp:
            (tmp / "summary.csv").write_text("new summary")
            raise KeyboardInterrupt
    assert _snapshot(out) == {"results.csv": b"streamed rows\n", "study.png": b"old chart",
                              "summary.csv": b"old summary"}

    with OutputSet(out, files=files) as tmp:   # this run writes no chart
        (tmp / "summary.csv").write_text("new summary")
        (tmp / "summary.json").write_text("{}")
    # the old chart is not left beside the new summary; the checkpoint is untouched
    assert _snapshot(out) == {"results.csv": b"streamed rows\n", "summary.csv": b"new summary",
                              "summary.json": b"{}"}
    assert sorted(os.listdir(tmp_path)) == ["study"]


def test_a_folder_of_only_the_sets_files_is_swapped_whole(tmp_path):
    out = tmp_path / "cmp"
    out.mkdir()
    (out / "compare.png").write_text("old")
    (out / "runs.csv").write_text("old runs")
    inode = out.stat().st_ino
    with OutputSet(out, files=report.study_files("compare")) as tmp:
        (tmp / "compare.json").write_text("[]")
    assert _snapshot(out) == {"compare.json": b"[]"}
    assert out.stat().st_ino != inode          # one rename: no moment with a mix of runs
    assert sorted(os.listdir(tmp_path)) == ["cmp"]


def test_outputs_get_the_modes_the_users_files_get(tmp_path):
    """The hidden folder a set is written in becomes the output folder: made as any folder
    of the user's is (umask applied), not private as tempfile's are."""
    from irring.outputs import write_text_atomic

    mask = os.umask(0o027)
    try:
        with OutputSet(tmp_path / "new") as tmp:
            (tmp / "map.yaml").write_text("image: map.pgm\n")
        write_text_atomic(tmp_path / "cal.yaml", "a: 1\n")
    finally:
        os.umask(mask)
    assert (tmp_path / "new").stat().st_mode & 0o777 == 0o750
    assert (tmp_path / "cal.yaml").stat().st_mode & 0o777 == 0o640


def test_atomic_file_makes_its_folder_and_names_the_path_it_cannot_write(tmp_path):
    """One home for a single file's write failures: a file where a folder should be, a
    folder where the file should be, a full disk are OutputError (exit 4) naming the path
    (after the option, when given); nothing is left behind; other errors pass unchanged."""
    from irring.errors import OUTPUT, OutputError
    from irring.outputs import atomic_file, write_text_atomic

    made = write_text_atomic(tmp_path / "a" / "b" / "cal.yaml", "a: 1\n")
    assert made.read_text() == "a: 1\n"
    (tmp_path / "taken").write_text("keep")
    with pytest.raises(OutputError) as e:
        write_text_atomic(tmp_path / "taken" / "sub" / "cal.yaml", "a: 1\n")
    assert e.value.status == OUTPUT
    assert str(e.value) == (f"{tmp_path}/taken/sub/cal.yaml: {tmp_path}/taken is a file, so "
                            "the folder cannot be made")
    with pytest.raises(OutputError, match=f"^--mcap {tmp_path}/a: is a folder; expected a file$"):
        with atomic_file(tmp_path / "a", "--mcap"):
            raise AssertionError("the block ran for a folder")
    with pytest.raises(OutputError, match=f"^{tmp_path}/x.bin: No space left on device$"):
        with atomic_file(tmp_path / "x.bin") as tmp:
            tmp.write_bytes(b"half")
            _full_disk()
    with pytest.raises(FileNotFoundError):     # reading an input is not the output's fault
        with atomic_file(tmp_path / "y.bin"):
            open(tmp_path / "no-such-input")
    with pytest.raises(ValueError, match="^bad$"):
        with atomic_file(tmp_path / "z.bin"):
            raise ValueError("bad")
    assert sorted(os.listdir(tmp_path)) == ["a", "taken"]
    assert (tmp_path / "taken").read_text() == "keep"


def test_a_device_or_pipe_at_an_output_path_is_refused_never_replaced(tmp_path, capsys):
    """As root, `--mcap /dev/full` and `irring calibrate --out /dev/full` printed 'wrote
    /dev/full' and had renamed a regular file over the device node (so /dev/null could be
    replaced too); a named pipe stands in for the device here."""
    from irring.errors import OutputError
    from irring.outputs import write_text_atomic

    pipe = tmp_path / "pipe"
    os.mkfifo(pipe)
    link = tmp_path / "to-pipe.yaml"
    link.symlink_to(pipe)
    for target in (pipe, link):
        with pytest.raises(OutputError, match=f"^{target}: is not a regular file"):
            write_text_atomic(target, "a: 1\n")
    assert main(["calibrate", "--out", str(pipe)]) == 4
    assert (f"irring calibrate: error: {pipe}: is not a regular file (a device, pipe or "
            "socket); irring writes a new file there, so name one") in capsys.readouterr().err
    assert pipe.is_fifo() and link.is_symlink() and sorted(os.listdir(tmp_path)) == [
        "pipe", "to-pipe.yaml"]


def test_mcap_at_a_device_is_refused_before_the_run(tmp_path, capsys):
    """`--mcap` naming a pipe (through a symlink) is a usage error before any work; without
    the mcap extra the option is refused for that reason instead (test_cli tests that)."""
    pytest.importorskip("mcap_ros2")
    pipe = tmp_path / "pipe"
    os.mkfifo(pipe)
    link = tmp_path / "to-pipe.yaml"
    link.symlink_to(pipe)
    with pytest.raises(SystemExit) as usage:
        main(["run", "t_room", "--mcap", str(link), "--out", str(tmp_path / "o")])
    assert usage.value.code == 2
    assert f"--mcap: {link}: is a folder or a device; name a file" in capsys.readouterr().err
    assert pipe.is_fifo() and link.is_symlink() and sorted(os.listdir(tmp_path)) == [
        "pipe", "to-pipe.yaml"]



def test_a_write_that_fails_removes_the_folders_it_made_and_only_those(tmp_path):
    """atomic_file and OutputSet make missing parents; a write that failed left them behind
    empty (irring view --out v1 on a full disk: the folder v1)."""
    (tmp_path / "kept").mkdir()
    (tmp_path / "busy").mkdir()
    for target in (tmp_path / "a" / "b" / "view.png", tmp_path / "kept" / "c" / "x.mcap",
                   tmp_path / "busy" / "y.mcap"):
        with pytest.raises(OutputError, match="No space left on device"):
            with atomic_file(target, "--out") as tmp:
                (tmp_path / "busy" / "theirs").write_text("another writer's")
                raise OSError(errno.ENOSPC, "No space left on device", str(tmp))
    for out in (tmp_path / "d" / "e" / "run", tmp_path / "kept" / "run"):
        with pytest.raises(OutputError, match="nothing was changed"):
            with OutputSet(out) as tmp:
                (tmp / "map.png").write_bytes(b"half")
                raise OSError(errno.EFBIG, "File too large")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["busy", "kept"]
    assert not any((tmp_path / "kept").iterdir())
    assert [p.name for p in (tmp_path / "busy").iterdir()] == ["theirs"]
    with atomic_file(tmp_path / "f" / "g" / "ok.txt") as tmp:   # a write that succeeds keeps them
        tmp.write_text("whole")
    assert (tmp_path / "f" / "g" / "ok.txt").read_text() == "whole"


def test_two_commits_into_one_folder_leave_one_set_never_a_mix(tmp_path, monkeypatch):
    """Into a folder holding a file of the user's, a set is renamed in file by file; two
    runs committing at once left a map.pgm of one beside the sweeps.npz of the other (seen
    with a commit slowed by 3 s a file: irring run t_room and t_room_cylinder into one
    --out, both exit 0). A commit now holds the folder's lock, as another process's commit
    (played here by a thread holding it) does."""
    import fcntl
    import threading
    import time

    from irring import outputs

    out = tmp_path / "shared"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    held, done = threading.Event(), threading.Event()

    def other_commit():   # renames its set in one by one, holding the lock
        fd = os.open(out, os.O_RDONLY)
        fcntl.flock(fd, fcntl.LOCK_EX)
        held.set()
        for name in ("map.pgm", "sweeps.npz"):
            (tmp_path / name).write_text("A")
            os.replace(tmp_path / name, out / name)
            time.sleep(0.4)
        os.close(fd)
        done.set()

    thread = threading.Thread(target=other_commit)
    thread.start()
    held.wait()
    with OutputSet(out) as tmp:
        for name in ("map.pgm", "sweeps.npz"):
            (tmp / name).write_text("B")
    thread.join()
    assert done.is_set()
    assert {p.name: p.read_text() for p in out.iterdir()} == {
        "notes.txt": "mine", "map.pgm": "B", "sweeps.npz": "B"}
    # a folder held past the wait (a study writing there) is left as it was, named
    monkeypatch.setattr(outputs, "COMMIT_WAIT_S", 0.2)
    fd = os.open(out, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)
    try:
        with pytest.raises(OutputError, match=re.escape(
                f"--out {out}: another irring process held the folder for 0.2 s (a study "
                "writing there?); nothing was changed")):
            with OutputSet(out) as tmp:
                (tmp / "map.pgm").write_text("C")
    finally:
        os.close(fd)
    assert (out / "map.pgm").read_text() == "B"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["shared"]


def test_a_folder_on_a_file_system_without_locks_is_written_unlocked(tmp_path, monkeypatch):
    """flock fails with ENOLCK on an NFS mount without a lock daemon: a study there ended
    'No locks available' (exit 1) before its first run, and so would every run's commit.
    Where no lock can be had, nothing is held (as on Windows)."""
    import fcntl

    from irring.outputs import sole_writer

    def no_locks(fd, operation):
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(fcntl, "flock", no_locks)
    out = tmp_path / "o"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with sole_writer(out, "a study's results.csv"):
        with OutputSet(out) as tmp:
            (tmp / "map.png").write_text("B")
    assert {p.name: p.read_text() for p in out.iterdir()} == {"notes.txt": "mine", "map.png": "B"}
