"""Leftovers of earlier rounds of hostile input and new users' reports: each test names the
input and asserts what happens now."""

from __future__ import annotations

import numpy as np
import pytest

from irring.cli import main


@pytest.mark.parametrize("count", [0, 4095])
def test_a_simulated_recording_of_one_count_all_round_is_named_as_edited(tmp_path, capsys,
                                                                         count):
    """t_room's recording with every reading set to 0 counts (the ADC unpowered) or 4095
    (full scale) was refused as a copy: "sweep 2 … repeats sweep 1's 852 counts reading for
    reading … Remove the copy", the wrong cause and the wrong
    remedy. It says what the sweeps read and why no simulation reads so."""
    from irring.recording import load_recording, save_recording

    assert main(["run", "t_room", "--out", str(tmp_path / "t"), "--no-animation"]) == 0
    sweeps, meta = load_recording(tmp_path / "t" / "sweeps.npz")
    for sweep in sweeps:
        sweep.counts[:] = count
    flat = save_recording(tmp_path / "flat.npz", sweeps, meta)
    capsys.readouterr()
    assert main(["replay", str(flat), "--out", str(tmp_path / "r"), "--no-animation"]) == 1
    assert capsys.readouterr().err == (
        f"irring replay: error: {flat}: sweeps 1 and 2 read {count} counts at every one of "
        "their 852 readings each; the recorded scenario 't_room' adds noise of 12 counts (σ "
        "0.015 V) to every reading, so no sweep it simulates reads one count all round: the "
        "recording was edited or damaged\n")


def test_a_device_whose_every_sensor_read_0_counts_is_warned_of(tmp_path, capsys):
    """From a device, every channel at 0 counts (the ADC unpowered) was mapped as silence,
    free to every sensor's reach, without a word: the cut-wire warning needs one live
    sensor to compare with. No sensor model's no-return level is 0
    counts at any ADC a scenario may have (8 bits, 50 V: gp2y0a21's 0.415 V is 2 counts)."""
    import dataclasses

    from irring import gp2
    from irring.recording import load_recording, save_recording

    assert min(int(gp2.counts_from_voltage(gp2.sensor(m).no_return_v, 8, 50.0))
               for m in gp2.available()) == 2
    assert main(["run", "t_room", "--out", str(tmp_path / "t"), "--no-animation"]) == 0
    sweeps, meta = load_recording(tmp_path / "t" / "sweeps.npz")
    dead = [dataclasses.replace(s, counts=np.zeros_like(s.counts), source="serial:/dev/ttyUSB0")
            for s in sweeps]
    path = save_recording(tmp_path / "dead.npz", dead, meta)
    capsys.readouterr()
    assert main(["replay", str(path), "--out", str(tmp_path / "r"), "--no-animation"]) == 0
    assert ("\n  warning   every sensor (0 … 11) read 0 counts at every one of their 284 "
            "readings each, at 4 poses, where a powered sensor with nothing in range reads its "
            "no-return level: an ADC unpowered or without its reference reads so. The readings "
            "are mapped as no return, free to the sensors' reach, walls or not; check the "
            "ADC's supply, reference and wiring\n") in capsys.readouterr().out


def test_a_picture_too_big_for_memory_is_refused_before_the_rendering(tmp_path, capsys):
    """`irring view --size 8192x8192` rendered a picture of 5.7 GB at its peak, with no
    refusal up front as other commands have. Refused at exit 5 past
    the 2 GB budget (core.VIEW_BYTES_PER_PIXEL over VIEW_BASE_BYTES; the measurements:
    README, exit status 5); anything up to 20 million pixels is still drawn."""
    from irring.cli.view import size_refusal

    out = tmp_path / "big.png"
    assert main(["view", "t_room", "--size", "8192x8192", "--out", str(out)]) == 5
    assert capsys.readouterr().err == (
        "irring view: error: --size 8192x8192: a picture of 67,108,864 pixels (about 6.0 GB), "
        "more than the 2 GB irring view may use: choose at most 20,000,000 pixels (4096x3072 "
        "is 12,582,912)\n")
    assert not out.exists()
    assert size_refusal(4096, 3072) is None and size_refusal(5000, 4000) is None
    assert size_refusal(5000, 4001).startswith("--size 5000x4001: a picture of 20,005,000")
