"""Round twenty-four of hostile input: each test names the input that broke and asserts
what happens now."""

from __future__ import annotations

import os

import pytest

from irring.cli import main


@pytest.mark.parametrize("argv, said", [
    (["run", "--seed", "3", "--out", "o", "--seed", "4"],
     "irring run: error: argument --seed: given twice ('3', then '4'); it takes one value, so "
     "give it once"),
    (["bench", "dynamics", "--seeds", "2", "5", "--seeds=3"],
     "irring bench dynamics: error: argument --seeds: given twice ('2 5', then '3'); list every "
     "value after one --seeds (--seeds 2 5 3)"),
])
def test_an_option_given_twice_with_other_values_is_refused(argv, said, tmp_path, monkeypatch,
                                                            capsys):
    # `--seeds 2 --seeds 3` ran seed 3 alone and `--seed 3 --seed 4` ran 4, without a word:
    # argparse keeps the last value
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert (stop.value.code, capsys.readouterr().err.splitlines()[-1]) == (2, said)
    assert list(tmp_path.iterdir()) == []


def test_an_option_given_twice_with_the_same_value_is_kept(capsys):
    # the same value twice loses nothing (`--seed 3 --seed 03`): kept, as are flags given twice
    from irring.cli import build_parser
    args = build_parser().parse_args(["run", "--seed", "3", "--json", "--seed", "03", "--json"])
    assert (args.seed, args.json) == (3, True)
    assert "_irring_given" not in vars(args)


def test_a_calibration_named_as_its_picture_is_refused(tmp_path, monkeypatch, capsys):
    # `calibrate --out c.png` wrote the YAML into c.png and the chart as c.png.png
    monkeypatch.chdir(tmp_path)
    assert main(["calibrate", "--out", "c ü.PNG", "--sweeps", "1"]) == 2
    assert capsys.readouterr().err == (
        "irring calibrate: error: --out c ü.PNG: a calibration is written as YAML, with its "
        "picture beside it; name the YAML file (--out c ü.yaml writes c ü.yaml and c ü.png)\n")
    assert list(tmp_path.iterdir()) == []


def _results(path, **scores):
    """A results.csv of one run whose cells are ``scores`` (the rest plausible)."""
    from irring.studies import study
    row = {c: "" for c in study.COLUMNS}
    row.update(design="rotating12", scenario="t_room", step_stride="1", samples="1",
               settle_ms="0.0", seed="1", sensor="gp2d12", sensors="12", radius_mm="150.0",
               sweep_half_angle_deg="37.8", step_deg="1.8", poses="3", readings="900",
               hardware_time_s="10.9", hardware_time_total_s="10.9", compute_ms="540.0",
               estimate_ms="30.0", map_ms="10.0", sim_ms="60.0", run_s="0.6",
               worker_peak_mb="200.0", iterations_mean="3.0",
               irring_version="0", **scores)
    study._write_sorted(path, [row])
    return path


@pytest.mark.parametrize("p, r, f1, said", [
    # an F1 edited to 0.5 beside precision 0.994 and recall 0.995 went into summary.csv as
    # 0.745 (round 23's leftover)
    ("0.9943262411347518", "0.995260663507109", "0.5", "0.5 is not the F1 of the row's "
     "occupied_precision 0.9943262411347518 and occupied_recall 0.995260663507109, which is "
     "0.994793"),
    ("0.9943262411347518", "0.995260663507109", "", "empty is not the F1 of the row's "
     "occupied_precision 0.9943262411347518 and occupied_recall 0.995260663507109, which is "
     "0.994793"),
    ("", "", "0.25", "0.25 is not the F1 of the row's occupied_precision empty and "
     "occupied_recall empty, which is empty (n/a)"),
])
def test_a_resumed_f1_its_precision_and_recall_contradict_is_refused(tmp_path, p, r, f1, said):
    from irring.studies.study import StudyError, read_results
    path = _results(tmp_path / "results.csv", occupied_precision=p, occupied_recall=r,
                    occupied_f1=f1)
    with pytest.raises(StudyError) as refused:
        read_results(path)
    assert str(refused.value) == (f"{path}: line 2, occupied_f1: {said}; the file was edited "
                                  "or damaged")


@pytest.mark.parametrize("p, r, f1", [
    ("0.994326241134752", "0.995260663507109", "0.994793232892172"),   # a spreadsheet's digits
    ("", "0.4", "0.0"),   # walls to see, none mapped
    ("", "", ""),         # no wall in sight
    ("0.0", "0.0", "0.0"),
])
def test_a_resumed_f1_its_precision_and_recall_give_is_kept(tmp_path, p, r, f1):
    from irring.studies.study import read_results
    (row,) = read_results(_results(tmp_path / "results.csv", occupied_precision=p,
                                   occupied_recall=r, occupied_f1=f1))
    assert (row["occupied_precision"], row["occupied_recall"], row["occupied_f1"]) == (p, r, f1)


def test_a_progress_file_resumes_with_its_own_sweeps_or_refuses_others(tmp_path, capsys,
                                                                      monkeypatch):
    # an 8-sweep progress file resumed with the default 4: placements averaged over 8 and
    # over 4 sweeps went into one fit without a word
    import hostile_devices as hd
    from irring.estimation.calibration import load_progress
    from test_hostile import _calibrate, _kept   # calibrate --port on a device, a person
    assert _calibrate(tmp_path, monkeypatch, hd.good, 3, "q", sweeps="2")[0] == 1
    saved = _kept(tmp_path).rename(tmp_path / "progress.yaml")
    capsys.readouterr()
    code, _, placed, _ = _calibrate(tmp_path, monkeypatch, hd.good, None, None,
                                    "--resume", str(saved), sweeps="3")
    assert (code, placed) == (1, [])
    assert capsys.readouterr().err == (
        f"irring calibrate: error: {saved}: cannot resume: its placements were read with 2 "
        "sweeps each; this run asks --sweeps 3: leave --sweeps out (or give 2) to resume with "
        "the same\n")
    # without --sweeps it resumes with the file's 2, and keeps them for the next resume
    code, _, placed, _ = _calibrate(tmp_path, monkeypatch, hd.good, 4, "q",
                                    "--resume", str(saved), sweeps=None)
    assert (code, placed) == (1, [3])
    assert "resuming from" in capsys.readouterr().out
    (again,) = set((tmp_path / "spare").iterdir())
    progress = load_progress(again)
    assert (progress.sweeps, sorted(progress.done)) == (2, [0, 1, 2])
    assert {int(r.repeats.max()) for _, r in progress.done.values()} == {2}


def test_the_emulator_serves_on_an_ipv6_address(t_room, capsys):
    # `irring emulate --tcp [::1]:0` said only "Address family for hostname not supported":
    # the listener was IPv4 alone
    import socket

    import numpy as np

    from irring.hardware import SerialRing
    from irring.hardware.emulator import Device, TcpEmulator
    from irring.simulation.sim import SimRing
    if not socket.has_ipv6:
        pytest.skip("no IPv6 on this machine")
    with TcpEmulator(Device(SimRing(t_room)), host="::1").start_thread() as emu:
        assert emu.url == f"socket://[::1]:{emu.port}" and emu.port > 0
        with SerialRing(emu.url, timeout_s=2.0) as ring:
            assert np.array_equal(ring.sweep().counts, SimRing(t_room).sweep(0).counts)
    # a name that does not resolve is one line naming the option as it was given
    assert main(["emulate", "--tcp", "[no:such:host]:0", "--quiet"]) == 2
    (line,) = capsys.readouterr().err.splitlines()   # the resolver's words differ by system
    assert line.startswith("irring emulate: error: --tcp [no:such:host]:0: ")
    assert line.endswith("; name an address of this machine (127.0.0.1, [::1]) or a name it "
                         "resolves")


@pytest.mark.parametrize("tail", [1000, 37])
def test_a_recording_with_bytes_joined_after_it_is_refused(tmp_path, t_room_recording, tail):
    # `cat a.npz b.npz > ab.npz` cut short (b's first half; its end record never written)
    # replayed a alone without a word: zipfile finds a's end record and skips what follows
    import numpy as np

    from irring.recording import RecordingError, load_recording
    whole = tmp_path / "a.npz"
    np.savez(whole, **t_room_recording)
    sweeps, _ = load_recording(whole)
    assert len(sweeps) == 4
    joined = tmp_path / "ab.npz"
    joined.write_bytes(whole.read_bytes() + whole.read_bytes()[:tail])
    with pytest.raises(RecordingError) as refused:
        load_recording(joined)
    assert str(refused.value) == (f"{joined}: {tail:,} bytes after the recording's end (another "
                                  "file, or part of one, joined to it?); replay each .npz on its "
                                  "own")


def test_an_output_folder_below_a_dangling_link_is_refused_before_the_work(tmp_path, capsys,
                                                                          monkeypatch):
    # `--out dl/o` with dl a link to a folder that is gone passed the check, ran, then ended
    # "cannot write there: File exists" (mkdir of dl)
    monkeypatch.chdir(tmp_path)
    os.symlink(tmp_path / "gone", "dl")
    assert main(["run", "--out", "dl/o/p", "--no-animation"]) == 4
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"irring run: error: --out dl/o/p: dl is a link to {tmp_path / 'gone'}, which does not "
        "exist (or a loop of links); make that folder or name another")
    assert sorted(os.listdir(tmp_path)) == ["dl"]


@pytest.mark.parametrize("gone", ["removed", "moved"])
def test_a_study_whose_results_file_goes_mid_study_stops_saying_so(tmp_path, gone):
    # `rm -rf OUT` (or `mv OUT elsewhere`) mid-study: the rows went on into the open file no
    # one could read, every run ran, and the study ended "cannot read the study's results:
    # No such file or directory" (exit 1, a bad input)
    from irring.errors import OutputError
    from irring.studies import study
    spec = tmp_path / "s.yaml"
    spec.write_text("designs: [radial12]\nscenarios: [box_room]\nseeds: [1, 2, 3]\n")
    out, ran = tmp_path / "o", []

    def progress(row):
        ran.append(row["seed"])
        if len(ran) == 1:
            (out / "results.csv").rename(tmp_path / "elsewhere.csv") if gone == "moved" else \
                (out / "results.csv").unlink()

    with pytest.raises(OutputError) as stopped:
        study.run_study(study.load_study(spec), out, progress=progress)
    assert str(stopped.value) == (
        f"{out / 'results.csv'}: was removed, moved or replaced while the study wrote to it, so "
        "its rows went where no one reads them; the study stopped: run it again (with --resume "
        "where the file is whole) to run what is missing")
    assert ran == [1]   # the second run's row found the file gone; the third never ran
    if gone == "moved":   # the moved file holds both rows written
        assert [r["seed"] for r in study.read_results(tmp_path / "elsewhere.csv")] == ["1", "2"]
