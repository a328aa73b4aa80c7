"""The emulated ring: its firmware answers per docs/protocol.md, and SerialRing over a REAL pty
gets SimRing's counts exactly — or, under injected faults, a subset of them, never more."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from irring.designs import PAPER_RING
from irring.hardware import DeviceDisconnected, DeviceTimeout, SerialRing
from irring.hardware import protocol as p
from irring.hardware.emulator import OUT_LIMIT_BYTES, Device, Faults, PtyEmulator, TcpEmulator
from irring.scenario import load_scenario
from irring.simulation.sim import SimRing

from _fake_source import FakeSource

TIMEOUT_S = 0.4  # generous: the device is a thread and CI may be loaded; a hang is still caught
LOSSY_TIMEOUT_S = 2.0  # 5 × TIMEOUT_S: a loaded machine (load 7.5, 2 cores) exceeded 0.4 s
FULL = np.arange(-35, 36)


@pytest.fixture(scope="module")
def t_room():
    return load_scenario("t_room")


class RecordingSource(SimRing):
    """SimRing that remembers what each IRSWP produced, to prove nothing is invented."""

    def __init__(self, scenario):
        super().__init__(scenario)
        self.produced: list[tuple[int, np.ndarray, np.ndarray]] = []

    def sweep(self, pose=0, *, steps=None):
        sweep = super().sweep(pose, steps=steps)
        self.produced.append((pose, sweep.steps.copy(), sweep.counts.copy()))
        return sweep


def produced_row(source: RecordingSource, step: int, counts_row: np.ndarray) -> bool:
    """Was this exact row produced for this step by some IRSWP?"""
    for _, steps, counts in source.produced:
        hit = np.flatnonzero(steps == step)
        if hit.size and np.array_equal(counts[hit[0]], counts_row):
            return True
    return False


@pytest.fixture
def pty_device(tmp_path):
    """Start a Device on a real pty (thread) and return the link path; stop it after."""
    started: list[PtyEmulator] = []

    def start(device: Device, baud: int = 0) -> str:
        emu = PtyEmulator(device, link=tmp_path / "ttyIRR", baud=baud).start_thread()
        started.append(emu)
        return str(tmp_path / "ttyIRR")

    yield start
    for emu in started:
        emu.stop()


# --------------------------------------------------------------------------- over a real pty


def test_fault_free_sweeps_over_a_pty_equal_simring_at_every_pose(t_room, pty_device):
    link = pty_device(Device(SimRing(t_room)))
    assert os.path.realpath(link).startswith("/dev/pts/")
    ref = SimRing(t_room, seed=t_room.seed)
    with SerialRing(link, timeout_s=TIMEOUT_S) as ring:
        assert ring.ring == t_room.ring
        for pose in range(len(t_room.robot.poses)):
            got = ring.sweep(pose=ref.pose(pose))
            want = ref.sweep(pose)
            assert np.array_equal(got.steps, want.steps)
            assert np.array_equal(got.counts, want.counts)
            assert got.counts.dtype == want.counts.dtype
            assert np.allclose(got.sensor_angles, want.sensor_angles)
            assert got.missing_steps == ()
            assert got.duration_s == pytest.approx(want.duration_s, abs=2e-3)
        # a partial sweep is SimRing.sweep(pose, steps=...) at the same pose, next k
        part = ring.sweep(steps=np.arange(5, -6, -1))
        assert np.array_equal(part.counts, ref.sweep(3, steps=np.arange(5, -6, -1)).counts)
        assert ring.stats.checksum_failures == ring.stats.lost_scans == 0


def test_lossy_link_over_a_pty_reports_every_missing_step_and_invents_nothing(t_room,
                                                                             pty_device):
    source = RecordingSource(t_room)
    link = pty_device(Device(source, faults=Faults(corrupt_rate=0.01, drop_rate=0.05, seed=5)))
    # The driver's deadline moves on progress only, and about half the IRSCN arrive garbled:
    # a starved emulator thread could go TIMEOUT_S without an intact step, get IRSTP and
    # leave steps unsent (missing, but not lost scans). The asserted counts hold only if no
    # IRSTP cuts a pass short, so this test waits longer than any scheduler delay.
    with SerialRing(link, timeout_s=LOSSY_TIMEOUT_S, retries=4) as ring:
        for pose in range(4):
            sweep = ring.sweep()
            got = set(sweep.steps.tolist())
            assert got | set(sweep.missing_steps) == set(FULL.tolist())
            assert got.isdisjoint(sweep.missing_steps)
            for step, row in zip(sweep.steps, sweep.counts):
                assert produced_row(source, step, row)
            # SimRing's own sweep at this pose, row for row
            want = SimRing(t_room).sweep(pose)
            idx = np.searchsorted(want.steps, sweep.steps)
            assert np.array_equal(sweep.counts, want.counts[idx])
            assert 0 < len(sweep.missing_steps) < 71
            assert ring.last_report.link["lost_scans"] >= len(sweep.missing_steps) - 1
        healed = ring.sweep(resweep=6)
        assert len(healed.missing_steps) <= 2
    assert ring.stats.checksum_failures > 0 and ring.stats.seq_gaps > 0


def test_faults_gauntlet_corruption_drops_a_stall_and_a_disconnect(t_room, pty_device):
    """1 % corrupted bytes, 5 % dropped sentences, a stall mid-sweep longer than the driver's
    patience (the device recovers) and a disconnect mid-sweep: no crash, no hang, every
    missing step reported."""
    stall_s = 4 * TIMEOUT_S
    source = RecordingSource(t_room)
    faults = Faults(corrupt_rate=0.01, drop_rate=0.05, stall_after=1 + 71 + 30, stall_s=stall_s,
                    disconnect_after=1 + 71 + 1 + 30 + 1 + 40, seed=12)
    link = pty_device(Device(source, faults=faults))
    ring = SerialRing(link, timeout_s=TIMEOUT_S, retries=1).open()
    bound_s = TIMEOUT_S + 0.04 + 70 * 0.005 + (ring.retries + 1) * TIMEOUT_S + 0.5
    seen_missing: list[tuple[int, ...]] = []

    first = ring.sweep()                       # lossy but complete
    seen_missing.append(first.missing_steps)

    started = time.monotonic()
    with pytest.raises(DeviceTimeout, match="stopped answering") as stall:
        ring.sweep()
    assert time.monotonic() - started < bound_s
    partial = stall.value.partial
    assert 0 < len(partial.steps) <= 30 and len(partial.missing_steps) == 71 - len(partial.steps)
    assert "missing steps" in str(stall.value)
    seen_missing.append(partial.missing_steps)

    time.sleep(stall_s)                        # the device's watchdog brings it back
    ring.hello()
    started = time.monotonic()
    with pytest.raises(DeviceDisconnected, match="disconnected.*is `irring emulate` still "
                                                 "running") as cut:
        ring.sweep()
    assert time.monotonic() - started < bound_s
    # what arrived before the cable went (the stall's queued replies may use up the sentences
    # before the cut, so none arriving is possible; the stall above pins partial sweeps)
    assert len(cut.value.partial.steps) < 40
    ring.close()
    for sweep in (first, partial, cut.value.partial):
        for step, row in zip(sweep.steps, sweep.counts):
            assert produced_row(source, step, row)   # nothing invented, nothing misplaced
        assert set(sweep.steps.tolist()) | set(sweep.missing_steps) == set(FULL.tolist())
    assert not Path(link).exists()              # the emulator removed its link on disconnect


def test_socket_url_reaches_the_emulator_over_tcp_and_a_cut_is_a_disconnect(t_room):
    with TcpEmulator(Device(SimRing(t_room), faults=Faults(disconnect_after=1 + 72 + 30))
                     ).start_thread() as emu:
        with SerialRing(emu.url, timeout_s=TIMEOUT_S) as ring:
            assert np.array_equal(ring.sweep().counts, SimRing(t_room).sweep(0).counts)
            with pytest.raises(DeviceDisconnected) as cut:
                ring.sweep()
        assert len(cut.value.partial.steps) == 30  # everything sent before the cut arrives


def test_irstp_interrupts_a_realtime_sweep_over_the_pty(t_room, pty_device):
    link = pty_device(Device(SimRing(t_room), realtime=True), baud=115200)
    with SerialRing(link, timeout_s=0.5) as ring:
        ring.port.write(p.encode(p.SweepCommand(-35, 35, 1, 0)))
        time.sleep(0.3)                        # ~7 steps of 38.3 ms
        last = ring.stop()
    assert 3 <= last <= 20


# --------------------------------------------------------------------------- firmware logic


def talk(device: Device, *lines: bytes) -> list:
    now = time.monotonic()
    for line in lines:
        device.receive(line, now)
    out = b""
    for _ in range(1000):
        chunk, due = device.poll(now)
        out += chunk
        if due is None:
            break
    return p.Decoder().feed(out)


class TinySource(FakeSource):
    ring = load_scenario("t_room").ring

    def __init__(self):
        super().__init__(lambda pose, steps, k: np.full((len(steps), 12), 100.0 + pose),
                         ring=self.ring, poses=3)


@pytest.mark.parametrize("line,code", [
    (b"$IRHLO*26D1\r\n", 1),                     # bad CRC
    (b"$IRSWP,1,2\r\n", 1),                      # no checksum
    (p.encode(p.Done(3)), 2),                    # a device sentence is not a command
    (p.frame(b"IRXYZ"), 2),
    (p.frame(b"IRSWP,-35,35,0,40"), 3),
    (p.encode(p.SweepCommand(-36, 35)), 4),
    (p.encode(p.GoTo(99)), 4),
])
def test_firmware_answers_bad_commands_with_the_protocols_error_codes(line, code):
    (reply,) = talk(Device(TinySource()), line)
    assert isinstance(reply, p.ErrorReply) and reply.code == code
    assert reply.text == p.ERROR_TEXT[code] or code == 2


def test_firmware_hello_goto_busy_and_stop():
    dev = Device(TinySource(), realtime=True)
    assert talk(dev, p.encode(p.Hello())) == [p.info_for_ring(TinySource.ring, 12,
                                                              "irring-emulator-1")]
    dev.receive(p.encode(p.SweepCommand(-35, 35, 1, 100)), time.monotonic())
    busy = talk(dev, p.encode(p.GoTo(3)), p.encode(p.SweepCommand(0, 1)))
    assert [m.code for m in busy] == [5, 5]
    assert talk(dev, p.encode(p.Stop())) == [p.Done(-1)]
    assert talk(Device(TinySource()), p.encode(p.GoTo(-7))) == [p.Position(-7)]


def test_a_flooding_host_gets_a_bounded_queue_and_loses_no_reading():
    """10 000 IRHLO in one burst queued 10 000 IRINF (530 kB) for a host that sent them
    faster than they could go out. Now a command that finds OUT_LIMIT_BYTES waiting is
    dropped unanswered and counted, as the board's RX buffer overruns: the first
    ceil(256 / len(IRINF)) are answered; a sweep asked for first still sends every IRSCN,
    and the device answers again once its output has gone."""
    dev = Device(TinySource())
    hello = p.encode(p.Hello())
    answer = len(p.encode(p.info_for_ring(TinySource.ring, 12, "irring-emulator-1")))
    answered = -(-OUT_LIMIT_BYTES // answer)
    out = talk(dev, p.encode(p.SweepCommand(-35, 31)), hello * 10_000)
    assert dev.stats.commands == 10_001
    assert dev.stats.commands_dropped == 10_000 - answered
    assert sum(isinstance(m, p.Info) for m in out) == answered
    assert [m.step for m in out if isinstance(m, p.Scan)] == list(range(-35, 32))
    assert isinstance(out[-1], p.Done) and len(out) == answered + 67 + 1
    assert isinstance(talk(dev, hello)[0], p.Info) and dev.stats.commands_dropped == 10_000 - answered


def test_full_range_sweeps_move_the_robot_to_the_next_pose_partial_ones_do_not():
    src = TinySource()
    dev = Device(src)
    for cmd in [p.SweepCommand(-35, 35), p.SweepCommand(0, 3), p.SweepCommand(35, -35),
                p.SweepCommand(-35, 35), p.SweepCommand(-35, 35)]:
        out = talk(dev, p.encode(cmd))
        assert isinstance(out[-1], p.Done)
    assert [c[0] for c in src.calls] == [0, 0, 1, 2, 0]  # wraps after the last pose
    assert src.calls[2][1] == tuple(range(35, -36, -1))


def test_a_hello_starts_a_new_session_at_the_first_pose():
    """The pose counter outlived the host: a second `drive --truth t_room` against one
    emulator started at its pose 2+ and mapped it as pose 1 (F1 0.145)."""
    src = TinySource()
    dev = Device(src)
    for cmd in [p.Hello(), p.SweepCommand(-35, 35), p.SweepCommand(-35, 35), p.Hello(),
                p.SweepCommand(-35, 35), p.SweepCommand(35, -35), p.SweepCommand(0, 3)]:
        talk(dev, p.encode(cmd))
    assert [c[0] for c in src.calls] == [0, 1, 0, 1, 1]
    held = Device(src := TinySource(), fixed_pose=2)   # --pose K stays at K in every session
    for cmd in [p.SweepCommand(-35, 35), p.Hello(), p.SweepCommand(-35, 35)]:
        talk(held, p.encode(cmd))
    assert [c[0] for c in src.calls] == [2, 2]


def test_fault_rates_are_what_was_asked():
    dev = Device(TinySource(), faults=Faults(drop_rate=0.05, corrupt_rate=0.01, seed=3))
    for _ in range(40):
        talk(dev, p.encode(p.SweepCommand(-35, 35)))
    s = dev.stats
    assert s.sentences_produced == 40 * 72
    assert s.sentences_dropped / s.sentences_produced == pytest.approx(0.05, abs=0.015)
    assert s.bytes_corrupted / s.bytes_sent == pytest.approx(0.01, abs=0.003)


def test_stall_and_disconnect_happen_after_exactly_n_sentences():
    dev = Device(TinySource(), faults=Faults(stall_after=10))
    out = talk(dev, p.encode(p.SweepCommand(-35, 35)))
    assert len(out) == 10 and talk(dev, p.encode(p.Hello())) == []
    dev = Device(TinySource(), faults=Faults(disconnect_after=3))
    assert len(talk(dev, p.encode(p.SweepCommand(-35, 35)))) == 3 and dev.disconnected



def test_the_pty_counts_bytes_as_unread_the_moment_they_are_written():
    # The kernel moves pty output to the host's side from a work queue; FIONREAD alone
    # reads 0 until it has run (~40 % of the time), so the linger before an injected
    # disconnect ended early and the hang-up threw away what the host had not read yet
    # (test_source's pulled cable got 2 of its 30 readings under load).
    late = 0
    for _ in range(2000):  # a fresh pty each time: its first push is the one that lags
        emu = PtyEmulator(Device(TinySource()))
        emu.open()
        try:
            os.write(emu._master, b"x" * 100)
            late += emu._unread() != 100
        finally:
            emu._close()
    assert late == 0


def test_a_host_that_reads_late_still_gets_every_sentence_before_a_disconnect():
    for _ in range(5):
        with PtyEmulator(Device(TinySource(), faults=Faults(disconnect_after=3))) as emu:
            emu.start_thread()
            fd = os.open(emu.path, os.O_RDWR | os.O_NOCTTY)
            try:
                os.write(fd, p.encode(p.SweepCommand(-35, 35)))
                time.sleep(0.15)   # the device has sent its 3 sentences and wants to hang up
                got = b""
                while True:
                    try:
                        chunk = os.read(fd, 4096)
                    except OSError:  # EIO: the device hung up
                        break
                    if not chunk:
                        break
                    got += chunk
            finally:
                os.close(fd)
        assert len(p.Decoder().feed(got)) == 3

@pytest.mark.parametrize("kw", [dict(drop_rate=1.5), dict(corrupt_rate=-0.1),
                                dict(stall_after=-1)])
def test_fault_settings_are_checked(kw):
    with pytest.raises(ValueError):
        Faults(**kw)


# --------------------------------------------------------------------------- CLI


@pytest.mark.parametrize("given, reverse", [(True, False), (False, False), (True, True)],
                         ids=["--link", "default ./ring.pty", "--reverse-sweeps"])
def test_irring_emulate_serves_a_link_and_cleans_up_on_sigterm(tmp_path, t_room, given,
                                                               reverse):
    link = tmp_path / ("irr" if given else "ring.pty")
    proc = subprocess.Popen([sys.executable, "-m", "irring", "emulate", "t_room"]
                            + (["--link", str(link)] if given else [])
                            + (["--reverse-sweeps"] if reverse else []), cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 20
        while not link.exists() and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
        assert link.exists(), proc.stderr.read() if proc.poll() is not None else "no link"
        with SerialRing(str(link), timeout_s=1.0) as ring:
            sweep = ring.sweep()
            report = ring.last_report
        # reversed, the device reads the steps from 35 down: the same steps, another order
        truth = SimRing(t_room).sweep(0, steps=FULL[::-1] if reverse else FULL).counts
        assert np.array_equal(sweep.steps, FULL) and report.link["reversed_passes"] == reverse
        assert np.array_equal(sweep.counts, truth[::-1] if reverse else truth)
    finally:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    assert "on /dev/pts/" in out and "1 sweeps" in out
    assert not link.exists()


def test_a_second_emulator_refuses_a_link_in_use_and_replaces_a_stale_one(tmp_path, t_room,
                                                                         pty_device):
    """A running emulator's link is refused (usage, exit 2, one line naming it and --link),
    and left pointing at its pty; a link whose pty closed (an emulator killed) is replaced,
    as is nothing else: a file of the user's is kept."""
    live = pty_device(Device(SimRing(t_room)))
    target = os.readlink(live)
    second = subprocess.run([sys.executable, "-m", "irring", "emulate", "t_room", "--link",
                             live], capture_output=True, text=True, timeout=60)  # not serve on
    assert second.returncode == 2
    assert second.stderr == (f"irring emulate: error: --link {live}: {live} is in use: it points at "
                   f"{target}, which is open (another irring emulate?); stop that one, or "
                   "pick another link with --link PATH\n")
    assert os.readlink(live) == target
    stale = tmp_path / "stale.pty"
    os.symlink("/dev/pts/no-such-pty", stale)
    emu = PtyEmulator(Device(SimRing(t_room)), link=stale)
    path = emu.open()
    assert os.readlink(stale) == path != target
    emu.stop()
    assert not stale.is_symlink()
    mine = tmp_path / "mine"
    mine.write_text("keep")
    with pytest.raises(FileExistsError, match="exists and is not a symlink"):
        PtyEmulator(Device(SimRing(t_room)), link=mine).open()
    assert mine.read_text() == "keep"


# --------------------------------------------------------------------------- irring drive


def test_irring_drive_on_the_emulator_makes_the_same_map_as_irring_run(tmp_path, t_room,
                                                                       pty_device, capsys):
    import json

    from irring.cli import main

    link = pty_device(Device(SimRing(t_room)))
    assert main(["run", "t_room", "--out", str(tmp_path / "run"), "--no-animation",
                 "--json"]) == 0
    ran = json.loads(capsys.readouterr().out)
    assert main(["drive", "--port", link, "--truth", "t_room", "--out", str(tmp_path / "drive"),
                 "--no-animation", "--json", "--timeout", "0.5"]) == 0
    drove = json.loads(capsys.readouterr().out)
    for name in ("map.pgm", "map.yaml"):
        assert (tmp_path / "run" / name).read_bytes() == (tmp_path / "drive" / name).read_bytes()
    assert drove["scores"] == ran["scores"] and drove["readings"] == ran["readings"]
    assert drove["hardware_time_s"] == pytest.approx(ran["hardware_time_s"], abs=0.01)
    assert drove["link"]["totals"]["lost_scans"] == 0
    assert [s["missing_steps"] for s in drove["link"]["sweeps"]] == [[]] * 4
    # the recording replays to the same map
    assert main(["replay", str(tmp_path / "drive" / "sweeps.npz"), "--out",
                 str(tmp_path / "replay"), "--no-animation", "--json"]) == 0
    capsys.readouterr()
    assert (tmp_path / "replay" / "map.pgm").read_bytes() == \
        (tmp_path / "run" / "map.pgm").read_bytes()
    # drives of 3 poses against the same emulator each start at its pose 1 (the second
    # began at the emulator's pose 4 and scored F1 0.145)
    scores = []
    for out in ("d3", "again"):
        assert main(["drive", "--port", link, "--truth", "t_room", "--poses", "3", "--out",
                     str(tmp_path / out), "--no-animation", "--json", "--timeout", "0.5"]) == 0
        scores.append(json.loads(capsys.readouterr().out)["scores"]["occupied_f1"])
    assert scores[0] > 0.75 and abs(scores[1] - scores[0]) < 0.02, scores


def test_irring_drive_without_truth_says_which_ring_it_mapped_with(tmp_path, t_room,
                                                                 pty_device, capsys):
    """No scenario names the design: the summary says so and gives the ring the map was
    made with (the device's 12 sensors and ±37.8° turn, the paper's radius), never "?"."""
    from irring.cli import main

    link = pty_device(Device(SimRing(t_room)))
    assert main(["drive", "--port", link, "--pose", "500,450,0", "--out", str(tmp_path),
                 "--no-animation", "--timeout", "0.5"]) == 0
    lines = capsys.readouterr().out.splitlines()
    head = lines.index(f"sweeps from serial:{link}")
    assert lines[head + 1].startswith(
        "  design not named (no scenario; mapped as 12 gp2d12 sensors on R 150 mm, turning "
        "±37.8°), 1 pose(s), 852 readings: ")
    assert lines[head + 2] == "  (no ground truth: not scored)"


def test_irring_drive_without_a_calibration_says_what_reads_the_counts(tmp_path, t_room,
                                                                      pty_device, capsys):
    """`irring drive` without --calibration (README's "Calibrate, then drive" skipped) read
    the counts with the datasheet curve and said nothing of it; with one it says nothing."""
    from irring.cli import main
    from irring.estimation.calibration import Calibration

    link = pty_device(Device(SimRing(t_room)))
    args = ["drive", "--port", link, "--pose", "500,450,0", "--no-animation", "--timeout",
            "0.5", "--no-wait"]
    assert main(args + ["--out", str(tmp_path / "bare")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"ring on {link}: ")
    assert lines[1] == (
        "note: no --calibration: the counts are read with the gp2d12 datasheet curve and an "
        f"emitter offset d_o of 7 mm; a real ring's own are measured by `irring calibrate "
        f"--port {link} --out ring.yaml` (then --calibration ring.yaml)")
    cal = tmp_path / "ring.yaml"
    dataclasses.replace(Calibration.nominal("gp2d12"), emitter_offset_m=0.00694).save(cal)
    assert main(args + ["--out", str(tmp_path / "cal"), "--calibration", str(cal)]) == 0
    out = capsys.readouterr().out
    assert "--calibration" not in out and out.startswith(f"ring on {link}: ")


def test_irring_drive_survives_a_bad_link_and_says_what_was_lost(tmp_path, t_room, pty_device,
                                                                capsys):
    import json

    from irring.cli import main

    faults = Faults(corrupt_rate=0.01, drop_rate=0.05, disconnect_after=400, seed=4)
    link = pty_device(Device(SimRing(t_room), faults=faults))
    code = main(["drive", "--port", link, "--truth", "t_room", "--out", str(tmp_path),
                 "--no-animation", "--timeout", str(TIMEOUT_S), "--resweep", "1"])
    out, err = capsys.readouterr()
    assert code == 3
    assert "disconnected" in err and "missing steps" in err
    report = json.loads((tmp_path / "link.json").read_text())
    assert report["error"] and report["totals"]["checksum_failures"] > 0
    assert 1 <= len(report["sweeps"]) < 4
    assert (tmp_path / "map.pgm").exists() and (tmp_path / "sweeps.npz").exists()
    assert "steps missing" in out


@pytest.mark.parametrize("fault", ["stall_after", "disconnect_after"])
def test_irring_drive_on_a_device_dead_after_its_handshake_says_so_in_one_line(
        tmp_path, t_room, pty_device, capsys, fault):
    """The ring answers IRHLO and then nothing: one error line (why, and that nothing was
    written), exit 3; it was two lines, the second a bare 'no readings arrived'."""
    from irring.cli import main

    link = pty_device(Device(SimRing(t_room), faults=Faults(**{fault: 1})))
    assert main(["drive", "--port", link, "--out", str(tmp_path / "d"), "--no-animation",
                 "--timeout", "0.3", "--json"]) == 3
    out, err = capsys.readouterr()
    lost = ("stopped answering (no sentence for 0.3 s during IRSWP,-35,35 after 0 of 71 steps"
            if fault == "stall_after" else "disconnected (")
    assert err.count("irring drive: error:") == 1 and err.endswith(
        "; no reading arrived, so nothing was mapped or written\n")
    assert f"\nirring drive: error: ring on {link} {lost}" in err
    assert out == "" and not (tmp_path / "d").exists()


def test_irring_drive_without_a_device_is_a_clear_error(tmp_path, capsys):
    """The operating system's reason, once (pyserial's own wrapping said it twice, with
    errno numbers); a file that is no terminal is 'not a serial port'."""
    from irring.cli import main

    advice = ("Check the device path (ls /dev/ttyUSB* /dev/ttyACM*), that you may use it "
              "(group dialout), or start the emulator: irring emulate t_room (then --port "
              "ring.pty)\n")
    assert main(["drive", "--port", "/dev/irring-none", "--no-animation"]) == 3
    assert capsys.readouterr().err == ("irring drive: error: cannot open /dev/irring-none: "
                                       "No such file or directory. " + advice)
    (tmp_path / "notes.txt").write_text("not a tty")
    assert main(["drive", "--port", str(tmp_path / "notes.txt"), "--no-animation"]) == 3
    assert capsys.readouterr().err == (f"irring drive: error: cannot open {tmp_path}/notes.txt: "
                                       "not a serial port. " + advice)


def test_a_moving_scene_is_emulated_sweep_by_sweep_but_not_driven(capsys):
    """The emulator replays a whole drive (11 sweeps for t_room_moving, not its 4 listed
    poses); `drive --truth` refuses it, since IRR v1 carries no pose to map it with."""
    from irring.cli import main

    moving = load_scenario("t_room_moving")
    assert Device(SimRing(moving)).poses == SimRing(moving).n_sweeps > len(moving.robot.poses)
    assert main(["drive", "--port", "loop://", "--truth", "t_room_moving"]) == 2
    err = capsys.readouterr().err
    assert "--truth t_room_moving: the scenario drives while scanning (`motion`)" in err
    assert "irring run" in err


# --------------------------------------------------------------------------- protocol versions


def test_a_v2_device_answers_an_old_hosts_v1_sentences_in_v1_framing():
    """An irring that speaks only v1 sends `$IRHLO*50`: it gets an IRINF it can read whose
    version field says 2 (so it refuses with its own clear error), and every other v1
    sentence an IRERR it can read; none is obeyed."""
    dev = Device(TinySource())
    out = b""
    now = time.monotonic()
    for line in (b"$IRHLO*50\r\n", p.encode(p.GoTo(3), version=1),
                 p.encode(p.Done(1), version=1), b"$IRHLO*51\r\n"):
        dev.receive(line, now)
        out += dev.poll(now)[0]
    old_host = p.Decoder(version=1).feed(out)
    assert old_host == [p.info_for_ring(TinySource.ring, 12, "irring-emulator-1", version=2),
                        p.ErrorReply(1, "bad sentence"), p.ErrorReply(2, "unknown type"),
                        p.ErrorReply(1, "bad sentence")]
    assert old_host[0].proto == 2 and dev.stats.sweeps == 0 and dev._pending_pos is None


def test_a_v1_device_answers_a_v2_hello_with_a_v1_irerr_and_a_v1_hello_with_its_irinf():
    dev = Device(TinySource(), protocol=1)
    now = time.monotonic()
    dev.receive(p.encode(p.Hello()) + p.encode(p.Hello(), version=1), now)
    out = dev.poll(now)[0]
    assert out.startswith(b"$IRERR,1,bad sentence*29\r\n$IRINF,1,12,")
    assert p.Decoder(version=1).feed(out)[1].proto == 1


def test_irring_drive_refuses_an_old_ring_and_uses_it_when_told(tmp_path, t_room, pty_device,
                                                               capsys):
    import json

    from irring.cli import main

    link = pty_device(Device(SimRing(t_room), protocol=1))
    args = ["drive", "--port", link, "--truth", "t_room", "--no-animation", "--timeout", "0.5"]
    assert main(args + ["--out", str(tmp_path / "refused")]) == 3
    err = capsys.readouterr().err
    assert "runs IRR protocol v1 firmware (irring-emulator-1)" in err
    assert "this irring speaks v2 (a CRC-16). Reflash the ring" in err
    assert "--accept-protocol-v1" in err and not (tmp_path / "refused").exists()
    assert main(args + ["--out", str(tmp_path / "v1"), "--accept-protocol-v1", "--json"]) == 0
    out, err = capsys.readouterr()
    assert "IRR protocol v1" in err and "warning: the device on" in err
    assert "speaking v1 as asked (--accept-protocol-v1)" in err
    drove = json.loads(out)
    link_json = json.loads((tmp_path / "v1" / "link.json").read_text())
    assert link_json["protocol"] == drove["link"]["protocol"] == 1
    assert drove["link"]["totals"]["lost_scans"] == 0


def test_emulate_protocol_option_is_checked():
    from irring.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["emulate", "t_room", "--protocol", "3"])
    assert exc.value.code == 2


def test_irring_calibrate_refuses_an_old_ring_and_needs_a_port_for_the_option(tmp_path,
                                                                             t_room,
                                                                             pty_device,
                                                                             capsys):
    from irring.cli import main

    link = pty_device(Device(SimRing(t_room), protocol=1))
    assert main(["calibrate", "--port", link, "--out", str(tmp_path / "cal.yaml")]) == 3
    err = capsys.readouterr().err
    assert "runs IRR protocol v1 firmware" in err and "make -C firmware avr flash" in err
    assert not (tmp_path / "cal.yaml").exists()
    assert main(["calibrate", "--accept-protocol-v1", "--out", str(tmp_path / "c.yaml")]) == 2
    assert "--accept-protocol-v1 is for a real ring's old firmware; give its --port too" in \
        capsys.readouterr().err


def test_emulate_motor_reversed_is_refused_for_a_ring_not_symmetric_about_step_0(tmp_path,
                                                                                 capsys):
    from irring.cli import main

    room = tmp_path / "lopsided.yaml"
    room.write_text((Path(__file__).parents[1] / "scenarios" / "t_room.yaml").read_text()
                    .replace("  design: rotating12\n",
                             "  design: rotating12\n  ring: {min_step: -10, max_step: 20}\n"))
    link = tmp_path / "ring.pty"
    assert main(["emulate", str(room), "--motor-reversed", "--link", str(link)]) == 2
    assert capsys.readouterr().err == (
        "irring emulate: error: motor_reversed needs steps symmetric about 0, got -10 … 20: "
        "turned the other way the ring would pass its end\n")
    assert not link.exists()


def test_a_ring_whose_irscn_cannot_fit_128_bytes_is_refused_before_serving(tmp_path, capsys,
                                                                         monkeypatch):
    """`irring emulate` of a 24-sensor scenario started, then ended its first sweep in a
    close room in exit 70 ("internal error (ValueError: IRSCN sentence is 144 bytes; the
    protocol allows 128)"), and the drive on it in "disconnected"; the longest IRSCN the
    ring can send (every count at the top, seq 65535, clock 2³² − 1 ms) is now checked first."""
    import dataclasses

    from irring.cli import main

    wide = dataclasses.replace(PAPER_RING, sensors=24)
    with pytest.raises(ValueError) as exc:
        Device(FakeSource(lambda pose, steps, k: np.zeros((len(steps), 24)), ring=wide))
    assert str(exc.value) == (
        "cannot emulate this ring: 24 sensors with a 12-bit ADC send IRSCN sentences of up to "
        "154 bytes (every count 4095, seq 65535, clock 4294967295 ms), and IRR protocol v2 "
        "allows 128: at most 18 sensors at 12 bits fit")
    fit = dataclasses.replace(PAPER_RING, sensors=18)
    dev = Device(FakeSource(lambda pose, steps, k: np.zeros((len(steps), 18)), ring=fit))
    longest = p.Scan(p.SEQ_MODULO - 1, -35, p.CLOCK_MODULO - 1, (4095,) * 18)
    assert p.longest_scan_bytes(dev.info) == len(p.encode(longest)) == 124   # 19: 129 bytes
    room = tmp_path / "wide.yaml"
    room.write_text((Path(__file__).parents[1] / "scenarios" / "t_room.yaml").read_text()
                    .replace("  design: rotating12\n",
                             "  design: rotating12\n  ring: {sensors: 24}\n"))
    monkeypatch.setattr(PtyEmulator, "serve_forever", lambda self: pytest.fail("served"))
    assert main(["emulate", str(room), "--link", str(tmp_path / "ring.pty")]) == 2
    assert capsys.readouterr().err == f"irring emulate: error: {exc.value}\n"
    assert not (tmp_path / "ring.pty").exists()


@pytest.mark.parametrize("ring, said", [
    ("{motor_step_deg: 0.0104, min_step: -6000, max_step: 6000}",
     "the ring turns its sensors 0.00624° a motor step (0.0104° × gear 0.6); IRINF, in whole "
     "millidegrees and a belt ratio of denominator ≤ 10 000, says 0.006° (0.01° × 3/5), 3.85% "
     "less"),
    ("{motor_step_deg: 0.9, min_step: -70, max_step: 70}", None)])
def test_emulate_warns_of_a_ring_its_irinf_cannot_describe(tmp_path, capsys, monkeypatch, ring,
                                                          said):
    """A scenario's motor step of 0.0104° goes out in IRINF as 10 millidegrees: `irring drive`
    without --truth mapped every angle 3.85 % short (a 0.06° step turns 37.4° as 36°), and
    nothing said so; a step IRINF carries exactly (0.9°) gets no word."""
    from irring.cli import main

    room = tmp_path / "fine.yaml"
    room.write_text((Path(__file__).parents[1] / "scenarios" / "t_room.yaml").read_text()
                    .replace("  design: rotating12\n", f"  design: custom\n  ring: {ring}\n"))

    def stop(self):
        raise KeyboardInterrupt

    monkeypatch.setattr(PtyEmulator, "serve_forever", stop)
    assert main(["emulate", str(room), "--link", str(tmp_path / "ring.pty"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err == ("" if said is None else
                   f"irring emulate: warning: {said}: `irring drive` without --truth turns every "
                   "reading's angle that much off (with --truth it takes the scenario's)\n")


# --------------------------------------------------------------------------- which room


def test_an_emulators_irinf_names_its_room_within_the_line(tmp_path, capsys, monkeypatch):
    """`irring emulate ROOM` says ROOM in IRINF's firmware field (after "irring-emulator-1
    room "), so drive can tell it from another room's; a name IRR text cannot carry, or a
    long one, goes as its characters cut to fit, ~ and 8 hex digits of its SHA-256."""
    from irring.cli import main
    from irring.hardware.emulator import (ROOM_TAG_MAX, emulated_room, firmware_for,
                                          room_tag)

    served = []
    monkeypatch.setattr(PtyEmulator, "serve_forever",
                        lambda self: served.append(self.device.info) or
                        (_ for _ in ()).throw(KeyboardInterrupt))
    assert main(["emulate", "t_room_cylinder", "--link", str(tmp_path / "ring.pty"),
                 "--quiet"]) == 0
    assert served[0].firmware == "irring-emulator-1 room t_room_cylinder"
    assert emulated_room(served[0].firmware) == "t_room_cylinder"
    assert emulated_room("irring-emulator-1") is None and emulated_room("irring-fw-2.0") is None
    odd = "my room, v2 $*" + "x" * 60
    tag = room_tag(odd)
    assert tag == "my_room__v2___" + "x" * 17 + "~" + tag[-8:] and len(tag) == ROOM_TAG_MAX
    assert room_tag(odd + "y") != tag and room_tag("a" * 40) == "a" * 40
    assert room_tag("a" * 41) != room_tag("a" * 42)
    # the widest IRINF a scenario may ask for still fits the protocol's 128 bytes
    widest = p.Info(2, 72, 16, 360_000, 10_000, 9_999, -100_000, 100_000, firmware_for(odd))
    assert len(p.encode(widest)) <= p.MAX_SENTENCE_BYTES
    assert p.Decoder().feed(p.encode(widest))[0].firmware == firmware_for(odd)


def test_drive_refuses_a_truth_of_another_room_than_the_emulators(tmp_path, pty_device,
                                                                  capsys):
    """`irring emulate t_room_cylinder` and `irring drive --truth t_room` mapped the
    cylinder room's readings at t_room's four poses and scored them against t_room (F1
    0.625, exit 0), nothing said. Now refused after the handshake, before any sweep."""
    from irring.cli import main
    from irring.hardware.emulator import firmware_for

    cyl = load_scenario("t_room_cylinder")
    link = pty_device(Device(SimRing(cyl), firmware=firmware_for(cyl.name)))
    args = ["drive", "--port", link, "--no-animation", "--no-wait", "--timeout", "2"]
    assert main(args + ["--truth", "t_room", "--out", str(tmp_path / "wrong")]) == 2
    out, err = capsys.readouterr()
    assert err == (f"irring drive: error: --truth t_room: the emulator on {link} simulates "
                   "t_room_cylinder, not t_room; its readings would be scored against another "
                   "room: run `irring emulate t_room` there, or leave --truth out\n")
    assert "room t_room_cylinder, 12 sensors" in out and not (tmp_path / "wrong").exists()
    assert main(args + ["--truth", "t_room_cylinder", "--out", str(tmp_path / "right")]) == 0
    assert (tmp_path / "right" / "map.png").exists()
