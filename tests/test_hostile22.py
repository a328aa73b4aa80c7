"""Round twenty-two of hostile input: each test names the input that broke and asserts what
happens now."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from irring import load_scenario
import hostile_devices as hd
from irring.cli import main
from irring.hardware import protocol as p
from irring.recording import check_sweep, load_recording, save_recording
from irring.simulation.sim import SimRing
from irring.studies.study import design_spec

ROOM = """\
name: vast
room:
  outline_mm: [[0, 0], [SIDE, 0], [SIDE, DEPTH], [0, DEPTH]]
robot:
  poses: [{x_mm: 500, y_mm: 450}]
"""


def test_a_room_too_big_for_the_coarsest_cells_is_not_told_to_use_coarser_ones(short_tmp,
                                                                                capsys):
    tmp_path = short_tmp   # the refusal names the file: pytest's folder under -n 2 cut it
    # 100 km square: the refusal said 'use coarser cells (map.resolution_mm ≥ 20001)', which the
    # schema refuses (1 … 500 mm); a 6 km corridor still fits 500 mm cells and keeps that advice
    for side, depth, said in [
            (1e8, 1e8, "are mapped: use a smaller room (its outline spans 100,000 × 100,000 m; "
                       "room.outline_m is read in metres, outline_mm in millimetres); even the "
                       "coarsest cells (map.resolution_mm 500) would be 200,003 × 200,003"),
            (6e6, 900, "are mapped: use coarser cells (map.resolution_mm ≥ 17) or a smaller room "
                  "(its outline spans 6,000 × 0.9 m;")]:
        (tmp_path / "vast.yaml").write_text(ROOM.replace("SIDE", f"{side:.0f}").replace(
            "DEPTH", f"{depth:.0f}"))
        status = main(["run", str(tmp_path / "vast.yaml"), "--out", str(tmp_path / "out")])
        err = capsys.readouterr().err.strip()
        assert (status, err.count("\n")) == (5, 0), err
        assert said in err
        assert not (tmp_path / "out").exists()


FORMULA = "=HYPERLINK(\"http://example.com\",\"ring8\")"


@pytest.mark.parametrize("argv, said", [
    # a study's design name went as-is into results.csv's first column, which a spreadsheet
    # opening the file ran as a formula
    (["study", "study.yaml"], "study.yaml: designs[0].name: '=HYPERLINK(\"http://example.com\","
                              "\"ring8\")' begins with '='"),
    (["compare", "--design", "{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 45, "
                             "step_deg: 1.08, name: '-2+3'}"],
     "--design.name: '-2+3' begins with '-'"),
    # a room's name goes into rooms.csv and compare's runs.csv
    (["run", "room.yaml"], "room.yaml: name: '@SUM(1+1)' begins with '@'"),
])
def test_a_name_a_spreadsheet_would_run_as_a_formula_is_refused(tmp_path, capsys, monkeypatch,
                                                                argv, said):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "study.yaml").write_text(
        f"designs: [{{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 45, step_deg: 1.08, "
        f"name: '{FORMULA}'}}]\nscenarios: [t_room]\nseeds: [1]\n")
    (tmp_path / "room.yaml").write_text(ROOM.replace("vast", "'@SUM(1+1)'").replace(
        "SIDE", "2420").replace("DEPTH", "900"))
    status = main([*argv, "--out", "out"])
    err = capsys.readouterr().err.strip()
    assert status in (1, 2) and err.count("\n") == 0, err
    assert said + (", which a spreadsheet opening the CSV files it is written to would run as "
                   "a formula; begin it with none of = + - @") in err
    assert not (tmp_path / "out").exists()


def test_a_name_with_a_formula_sign_after_its_first_character_is_kept(tmp_path):
    (tmp_path / "room.yaml").write_text(ROOM.replace("vast", "'room =a+b-c@d'").replace(
        "SIDE", "2420").replace("DEPTH", "900"))
    spec = design_spec("s.yaml", "designs[0]", {"sensors": 8, "radius_mm": 120,
                                                 "sweep_half_angle_deg": 45, "step_deg": 1.08,
                                                 "name": "ring8=a+b-c@d"})
    assert (load_scenario(tmp_path / "room.yaml").name, spec.label) == ("room =a+b-c@d",
                                                                         "ring8=a+b-c@d")


@pytest.mark.parametrize("argv", [["run", "t_room"], ["replay", "sweeps.npz"]])
def test_an_empty_mcap_path_is_called_empty(tmp_path, capsys, monkeypatch, argv):
    # --mcap "$FILE" with FILE unset said "argument --mcap: : is a folder or a device"
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as caught:
        main([*argv, "--out", "out", "--mcap", ""])
    err = capsys.readouterr().err.strip().splitlines()
    assert caught.value.code == 2
    assert err[-1].endswith("error: argument --mcap: an empty path; name a file (such as "
                            "map.mcap)")
    assert list(tmp_path.iterdir()) == []


def test_a_sweep_made_in_code_with_a_tuple_pose_and_list_counts_is_recorded_replayably(
        tmp_path):
    # check_sweep took them, but save_recording wrote the pose into the sweep's scalars and
    # load_recording refused the file it had just written: 'sweep000/pose: missing'
    sweep = SimRing(load_scenario("t_room")).sweep(0)
    made = dataclasses.replace(sweep, pose=(1.5, 0.25, 0.125), counts=sweep.counts.tolist(),
                               steps=list(sweep.steps))
    check_sweep(made)
    (back,), _ = load_recording(save_recording(tmp_path / "r.npz", [made]))
    assert back.pose.tolist() == [1.5, 0.25, 0.125]
    assert np.array_equal(back.counts, sweep.counts) and np.array_equal(back.steps, sweep.steps)


WIDE = 24   # sensors: with a 12-bit ADC an IRSCN of large counts is longer than 128 bytes


def _wide_ring(dev, cmd):
    """Near readings (4-digit counts) at odd steps, far ones (3-digit) at even steps."""
    if isinstance(cmd, p.Hello):
        dev.send(hd.info(sensors=WIDE))
    elif isinstance(cmd, p.SweepCommand):
        for step in range(cmd.from_step, cmd.to_step + 1):
            counts = [(3000 if step % 2 else 300) + k for k in range(WIDE)]
            dev.send(hd.line(f"IRSCN,{dev.seq},{step},{1000 + dev.seq},"
                             f"{','.join(map(str, counts))}"))
            dev.seq += 1
        dev.send(hd.line(f"IRDON,{dev.seq - 1}"))
    elif isinstance(cmd, p.Stop):
        dev.send(hd.line(f"IRDON,{dev.seq - 1}"))


def test_a_ring_whose_near_readings_do_not_fit_a_sentence_is_refused_before_sweeping(
        tmp_path, capsys):
    # its far readings arrived, its near ones were dropped as malformed (longer than 128
    # bytes): drive mapped 3 of 5 steps, the near ones missing every time, and exited 0
    dev = hd.HostileDevice(_wide_ring)
    try:
        status = main(["drive", "--port", dev.link, "--timeout", "0.3", "--no-wait",
                       "--no-animation", "--out", str(tmp_path / "out"), "--pose", "0,0,0"])
    finally:
        dev.close()
    err = capsys.readouterr().err.strip()
    assert (status, err.count("\n")) == (3, 0), err
    assert (f"irring drive: error: the device on {dev.link} announces a ring whose readings "
            "do not fit the protocol's sentences: 24 sensors with a 12-bit ADC send IRSCN "
            "sentences of up to 153 bytes") in err
    assert "at most 19 sensors at 12 bits fit" in err
    assert list(tmp_path.iterdir()) == []
