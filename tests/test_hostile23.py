"""Round twenty-three of hostile input: each test names the input that broke and asserts
what happens now."""

from __future__ import annotations

import errno
import io
import math
import os
import sys

import numpy as np
import pytest

from irring.cli import build_parser, main
from irring.cli._common import glue_negative_values


def test_a_negative_coordinate_list_is_read_as_the_options_value(capsys):
    # `--pose -500,450` (a pose left of the origin) was told only "argument --pose: expected
    # one argument": argparse takes a word beginning with '-' for an option unless it is a
    # plain number such as -5
    argv = ["drive", "--port", "ring.pty", "--pose", "-500,-450,-90", "--pose", "1210,450"]
    args = build_parser().parse_args(glue_negative_values(argv))
    assert args.pose == [(-0.5, -0.45, math.radians(-90)), (1.21, 0.45, 0.0)]
    # a negative number is now refused by the option's own check, which says what is allowed
    with pytest.raises(SystemExit) as stop:
        main(["geometry", "--range-mm", "-1e3"])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert (stop.value.code, err) == (2, "irring geometry: error: argument --range-mm: must be "
                                         "a number > 0 and ≤ 100000, got '-1e3'")
    # plain negative numbers, values given with '=', and words after `--` are left as they were
    assert glue_negative_values(["view", "--step", "-5", "--pose=-1,2", "--", "--x", "-1,2"]) \
        == ["view", "--step", "-5", "--pose=-1,2", "--", "--x", "-1,2"]


def test_an_mcap_written_outside_the_output_folder_is_named_where_it_is(tmp_path, monkeypatch,
                                                                       capsys):
    pytest.importorskip("mcap_ros2")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub").mkdir()
    # `--mcap 'm ü.mcap'` (the current folder) was listed as "wrote o/: map.png, …, m ü.mcap",
    # so a user looked for it in o/
    for mcap, said in [("m ü.mcap", "; and ./m ü.mcap"), ("sub/x.mcap", "; and ./sub/x.mcap")]:
        assert main(["run", "--out", "o", "--mcap", mcap, "--no-animation"]) == 0
        last = capsys.readouterr().out.splitlines()[-1]
        assert last == f"  wrote     o/: map.png, map.pgm, map.yaml, sweeps.npz{said}"
        assert (tmp_path / mcap).stat().st_size > 1000
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == [
        "map.pgm", "map.png", "map.yaml", "sweeps.npz"]


def test_a_seed_listed_twice_for_the_motion_means_is_refused(capsys):
    # `bench dynamics --seeds 1 1` averaged seed 1's motion figures twice without a word, where
    # compare and bench accuracy refuse a repeated --design, --scenario or --knob
    assert main(["bench", "dynamics", "--seeds", "3", "1", "3", "--sweeps", "1"]) == 2
    assert capsys.readouterr().err.strip() == (
        "irring bench dynamics: error: --seeds 3: given twice; it would be run and counted in "
        "the means twice, so name each once")


class _FullDisk(io.TextIOBase):
    """Standard output on a full disk (`> /dev/full`): every write fails."""

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["bench", "rooms", "-h"]])
def test_help_that_cannot_be_written_is_an_output_error(argv, monkeypatch, capsys):
    # `irring --help > /dev/full` printed nothing and exited 0: argparse drops a write error
    monkeypatch.setattr(sys, "stdout", _FullDisk())
    assert main(argv) == 4
    assert capsys.readouterr().err == "irring: error: standard output: No space left on device\n"


def test_a_recording_with_a_sweep_removed_is_refused_naming_the_missing(tmp_path):
    """A recording whose sweeps are numbered 0, 1, 3, 6 (two taken out of the zip, or
    renumbered by another tool) replayed the four that were left without a word: what the
    file lacked went unsaid. It is refused naming the numbers present and missing."""
    import zipfile

    from irring.errors import InputError
    from irring.recording import load_recording, save_recording
    from test_recording import make_sweep

    rng = np.random.default_rng(23)
    sweeps = [make_sweep(rng, truth=False) for _ in range(7)]
    whole = tmp_path / "whole.npz"
    save_recording(whole, sweeps, meta={})
    cut = tmp_path / "cut.npz"
    with zipfile.ZipFile(whole) as src, zipfile.ZipFile(cut, "w") as dst:
        for item in src.infolist():
            if not item.filename.startswith(("sweep002/", "sweep004/", "sweep005/")):
                dst.writestr(item, src.read(item.filename))
    assert len(load_recording(whole)[0]) == 7
    with pytest.raises(InputError) as err:
        load_recording(cut)
    assert str(err.value).endswith(
        "holds sweeps numbered 0–1, 3, 6: 2, 4–5 are missing; a recording numbers its "
        "sweeps sweep000, sweep001, … without a gap")


def test_calibrate_baud_without_a_port_is_refused(tmp_path, capsys):
    """`irring calibrate --baud 9600` calibrated the simulated rig and ignored the speed
    without a word, while --resume and --accept-protocol-v1 without --port are refused."""
    out = tmp_path / "c.yaml"
    assert main(["calibrate", "--baud", "9600", "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip() == (
        "irring calibrate: error: --baud is the real ring's serial speed; give its --port too")
    assert not out.exists()
