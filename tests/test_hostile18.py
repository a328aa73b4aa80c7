"""Round eighteen of hostile input: each test names the input that broke and asserts what
happens now."""

from __future__ import annotations

import json

import numpy as np
import pytest

from irring import load_scenario, pipeline
from irring.cli import main
from irring.core import MAX_ESTIMATED_READINGS
from irring.designs import PAPER_RING
from irring.hardware import SerialRing
from irring.hardware.emulator import Device
from irring.outputs import OutputError
from irring.recording import RecordingError

from _fake_source import FakeSource
from test_firmware import TIMEOUT_S as FIRMWARE_TIMEOUT_S, device, host_binary  # noqa: F401
from test_hostile17 import _Board, _reset
from test_serial_ring import HELLO, PARK, STOP, SWEEP, virtual_time  # noqa: F401 (fixture)

TIMEOUT_S = 0.1


def _device() -> Device:
    return Device(FakeSource(lambda pose, steps, k: 1000 + 20 * np.asarray(steps)[:, None]
                             + 100 * np.arange(PAPER_RING.sensors)), realtime=True)


def test_a_board_that_reset_at_rest_after_its_last_sweep_is_not_turned_to_where_it_woke(
        virtual_time):
    """A board that reset at rest after the session's last sweep (a loose supply while the
    operator was at the prompt, then Ctrl-D) answered close()'s IRGTO,0 with IRPOS,0 at once,
    from step 35 where it woke, and close() said nothing: the next session read every step
    37.8° off. close() asks first with IRSTP, answered at any time with the last seq sent
    since power-up: -1 after 71 IRSCN came is a board that reset."""
    port = _Board(_device(), after=0, event=None)
    ring = SerialRing(port, timeout_s=TIMEOUT_S).open()
    assert len(ring.sweep().steps) == 71
    _reset(port.device)
    ring.close()
    assert port.written == [HELLO, SWEEP, STOP]   # no IRGTO,0: it would turn nowhere useful
    assert ring.park_failure == (
        "the ring on device://emulator was not turned back to step 0 at the end of the session "
        "(an IRSTP at rest was answered IRDON -1, no IRSCN sent since it powered up, though "
        "71 came this session: it rebooted at rest at step 35, and its firmware took that "
        "step for step 0). Its firmware takes the step it stands at when it starts for step 0, "
        "and an Arduino restarts each time its port is opened: turn the ring radial by hand, "
        "or send $IRGTO,-35*B59F (radial is its step -35 now), then reset the board, before "
        "the next session")


def test_a_board_that_did_not_reset_at_rest_is_asked_and_turned_back(virtual_time):
    """The control: the same session without the reset. IRSTP at rest is answered IRDON 70
    (its last seq), and the ring is turned back to step 0 as before."""
    port = _Board(_device(), after=0, event=None)
    ring = SerialRing(port, timeout_s=TIMEOUT_S).open()
    ring.sweep()
    ring.close()
    assert port.written == [HELLO, SWEEP, STOP, PARK]
    assert ring.park_failure is None and ring.stands_at == 0


def test_the_reference_firmware_answers_irstp_at_rest_with_its_last_seq(device):  # noqa: F811
    """The C firmware (host build on a pty) is asked IRSTP at rest at the end of a session:
    it answers with the seq of the sweep's last IRSCN, not -1, so the ring is turned back
    to step 0 with no warning (a firmware answering -1 there would be told it reset)."""
    ring = SerialRing(device(), timeout_s=FIRMWARE_TIMEOUT_S).open()
    assert len(ring.sweep().steps) == 71
    ring.close()
    assert ring.park_failure is None and ring.stands_at == 0


def _edited(entries: dict, path, **changes):
    np.savez(path, **{**entries, **changes})
    return path


def test_a_recording_whose_angles_contradict_their_steps_is_refused(t_room_recording, tmp_path):
    """sweep000's sensor angles moved 10 rows on (each row the angle of the step 10 before,
    the steps as they were): every reading of that sweep mapped at another bearing than its
    step, F1 0.995 -> 0.449, exit 0. The driver and the simulator record the commanded angle
    (step × motor step × belt ratio), so angles that contradict it were edited."""
    rolled = np.roll(t_room_recording["sweep000/sensor_angles"], 10, axis=0)
    path = _edited(t_room_recording, tmp_path / "rolled.npz",
                   **{"sweep000/sensor_angles": rolled})
    with pytest.raises(RecordingError) as err:
        pipeline.replay(path)
    assert str(err.value) == (
        f"{path}: sweep 1's sensor 0 at step -35 is at 0.490088 rad, where its ring turns step "
        "-35 to -0.659734 rad (step × motor step × belt ratio, every sensor alike, as irring's "
        "simulator and driver record it); the angles and the steps do not belong together")
    # the same rows in another order (steps, angles and counts together) are one sweep
    order = np.arange(70, -1, -1)
    rows = {f"sweep000/{name}": t_room_recording[f"sweep000/{name}"][order]
            for name in ("steps", "sensor_angles", "counts", "timestamps_s")}
    rows.update({k: v[order] for k, v in t_room_recording.items()
                 if k.startswith("sweep000/truth/")})
    same = pipeline.replay(_edited(t_room_recording, tmp_path / "reversed.npz", **rows))
    assert sum(int(p.valid.sum()) for p in same.points) == 2153


def test_a_simulated_sweep_whose_ring_is_not_its_scenarios_is_refused(t_room_recording, tmp_path):
    """Every sweep's ring given a radius of 0.2 m (t_room's ring, which simulated them, is
    0.15): the end points placed 50 mm out. The sensor model was checked against the
    recorded scenario; the ring was not. (Sweep 3's alone: F1 0.995 -> 0.679, exit 0.)"""
    def rings(radius_m: float, source: str | None = None) -> dict:
        out = {}
        for k in range(4):
            scalars = json.loads(str(t_room_recording[f"sweep{k:03d}/scalars"]))
            scalars["ring"]["radius_m"] = radius_m
            if source is not None:
                scalars["source"] = source
            out[f"sweep{k:03d}/scalars"] = np.array(json.dumps(scalars))
        return out

    path = _edited(t_room_recording, tmp_path / "ring.npz", **rings(0.2))
    with pytest.raises(RecordingError) as err:
        pipeline.replay(path)
    assert str(err.value) == (
        f"{path}: sweep 1 was simulated with ring.radius_m 0.2, but the recorded scenario "
        "'t_room', which simulated it, has 0.15; the scenario and the sweeps do not belong "
        "together")
    # a device's ring is its IRINF's, which may differ from the truth scene's: replayed
    device = _edited(t_room_recording, tmp_path / "device.npz",
                     **rings(0.2, "serial:/dev/ttyACM0"))
    assert len(pipeline.replay(device).points) == 4


def test_a_recording_of_two_rings_is_refused_not_an_internal_error(t_room_recording,
                                                                    tmp_path, capsys):
    """A device's recording whose first sweep is of 11 sensors (the last column cut, its ring
    saying 11) and the others of 12: the replay wrote its outputs, then its stuck-sensor check
    stacked every sweep's readings: "internal error (ValueError: all the input array
    dimensions except for the concatenation axis must match exactly …)", exit 70."""
    edits = {k: v[:, :11] for k, v in t_room_recording.items()
             if k.startswith("sweep000/") and v.ndim >= 2 and v.shape[1] == 12}
    for k in range(4):
        scalars = json.loads(str(t_room_recording[f"sweep{k:03d}/scalars"]))
        scalars["source"] = "serial:/dev/ttyACM0"
        if k == 0:
            scalars["ring"]["sensors"] = 11
        edits[f"sweep{k:03d}/scalars"] = np.array(json.dumps(scalars))
    path = _edited(t_room_recording, tmp_path / "two.npz", **edits)
    out = tmp_path / "o"
    assert main(["replay", str(path), "--out", str(out), "--no-animation"]) == 1
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"irring replay: error: {path}: sweep 2's ring has sensors 12, sweep 1's 11; the sweeps "
        "of one recording are one ring's (irring run and irring drive record one), so these "
        "were edited or pieced together")
    assert not out.exists()


def test_a_standing_scenes_sweep_with_a_pose_for_each_reading_is_refused(t_room_recording,
                                                                          tmp_path):
    """sweep000 given a pose for each reading (all at the origin), as a moving robot's sweep
    carries: its readings were placed from there, F1 0.995 -> 0.812, exit 0. The simulator
    writes them only for a scene that drives (effects.motion), and t_room stands."""
    path = _edited(t_room_recording, tmp_path / "poses.npz",
                   **{"sweep000/reading_poses": np.zeros((71, 12, 3))})
    with pytest.raises(RecordingError) as err:
        pipeline.replay(path)
    assert str(err.value) == (
        f"{path}: sweep 1 carries a pose for each reading (a moving robot's), but the recorded "
        "scenario 't_room', which simulated it, stands still at each of its poses; the "
        "scenario and the sweeps do not belong together")


def test_a_moving_scenes_sweep_stripped_of_its_reading_poses_is_refused(tmp_path):
    """t_room_moving's sweeps stripped of their pose for each reading were mapped from each
    sweep's first pose, F1 0.898 -> 0.598, exit 0: the simulator writes them for every sweep
    of a scene that drives (effects.motion), so one without them was edited."""
    out = tmp_path / "run"
    pipeline.write_outputs(pipeline.run(load_scenario("t_room_moving")), out, animation=False)
    with np.load(out / "sweeps.npz") as z:
        entries = {k: z[k] for k in z.keys()}
    assert entries["sweep001/reading_poses"].shape == (71, 12, 3)
    del entries["sweep001/reading_poses"]
    path = _edited(entries, tmp_path / "stripped.npz")
    with pytest.raises(RecordingError) as err:
        pipeline.replay(path)
    assert str(err.value) == (
        f"{path}: sweep 2 carries no pose for each reading, but the recorded scenario "
        "'t_room_moving', which simulated it, drives while it sweeps (effects.motion); the "
        "scenario and the sweeps do not belong together")


def test_an_mcap_that_cannot_be_written_says_the_runs_own_outputs_were(tmp_path):
    """`irring run t_room --out o --mcap /proc/x.mcap` (as root, whom the check before the
    work lets write anywhere): the whole set was written to o/, then "irring run: error:
    /proc/x.mcap: cannot write there: No such file or directory", exit 4, nothing said of o/
    (README: "an MCAP that fails still leaves the new set, and says so")."""
    pytest.importorskip("mcap_ros2")
    (tmp_path / "notes").write_text("a file, not a folder")
    result = pipeline.map_sweeps(pipeline.simulated(load_scenario("t_room"), progress=False)[0]
                                 .sweeps[:1], scenario=load_scenario("t_room"))
    out = tmp_path / "o"
    with pytest.raises(OutputError) as err:
        pipeline.write_outputs(result, out, animation=False, mcap=tmp_path / "notes" / "x.mcap")
    assert str(err.value) == (
        f"{tmp_path / 'notes' / 'x.mcap'}: {tmp_path / 'notes'} is a file, so the folder cannot "
        f"be made; the run's other outputs were written: {out}/: map.png, map.pgm, map.yaml, "
        "sweeps.npz")
    assert sorted(p.name for p in out.iterdir()) == ["map.pgm", "map.png", "map.yaml",
                                                     "sweeps.npz"]


class _ResetsTurningBack(_Board):
    """The board resets as it turns back to step 0 (close()'s IRGTO,0): the move is lost, no
    IRPOS comes, and its step 0 is now where it woke."""

    def write(self, data_: bytes) -> int:
        n = super().write(data_)
        if data_ == PARK:
            _reset(self.device)
            self.device._pending_pos = None   # the move it was making
        return n


def test_a_board_that_reset_as_it_turned_back_is_not_told_to_be_sent_irgto_0(virtual_time):
    """A board that reset as close() turned it back sent no IRPOS; the warning said "turn
    the ring radial by hand, or send $IRGTO,0*E3DD": that IRGTO,0 is answered IRPOS,0 at
    once from where it woke, and the user who sent it was told nothing was wrong. An IRSTP
    after the silence is answered IRDON -1 by such a board."""
    port = _ResetsTurningBack(_device(), after=0, event=None)
    ring = SerialRing(port, timeout_s=TIMEOUT_S).open()
    ring.sweep()
    ring.close()
    assert port.written == [HELLO, SWEEP, STOP, PARK, STOP]
    assert ring.park_failure == (
        "the ring on device://emulator was not turned back to step 0 at the end of the session "
        "(no IRPOS answered IRGTO,0 within 0.45 s, and an IRSTP then was answered IRDON -1, no "
        "IRSCN sent since it powered up, though 71 came this session: it rebooted as it turned "
        "back, and its firmware took the step it woke at for step 0; it stands between step 35 "
        "and step 0). Its firmware takes the step it stands at when it starts for step 0, and "
        "an Arduino restarts each time its port is opened: turn the ring radial by hand (its "
        "step 0 is where it woke, so no IRGTO can), then reset the board, before the next "
        "session")


@pytest.mark.parametrize("argv, option, what", [
    (["run", ""], "SCENARIO", "a bundled scenario (irring scenarios lists them) or a YAML file"),
    (["replay", " "], "RECORDING", "a sweeps .npz recording"),
    (["run", "t_room", "--calibration", ""], "--calibration", "a calibration file"),
    (["bench", "rooms", ""], "ROOM", "a bundled scenario (irring scenarios lists them) or a "
                                     "YAML file, or a folder of them"),
])
def test_an_empty_name_is_refused_not_read_as_the_default_or_the_current_folder(
        argv, option, what, tmp_path, monkeypatch, capsys):
    """`irring run "$ROOM"` with ROOM unset ran t_room into out/t_room, replacing the run
    there, exit 0; `--calibration ""` said ".: is a folder"; `bench rooms ""` ": the folder
    holds no *.yaml scenario" (--out "" was refused so already)."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as err:
        main(argv)
    assert err.value.code == 2
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"irring {' '.join(argv[:2] if argv[0] == 'bench' else argv[:1])}: error: argument "
        f"{option}: an empty name; name {what}")
    assert list(tmp_path.iterdir()) == []
