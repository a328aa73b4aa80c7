"""Round sixteen of hostile input: each test names the input that broke and
asserts what happens now."""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest

import hostile_devices as hd
from irring.hardware import SerialRing
from irring.hardware import protocol as p
from irring.hardware.serial_ring import DeviceRebooted


def _millis_board(boot_ms: int, reboot):
    """A correct board ``boot_ms`` old at its first IRSCN. ``reboot(dev, cmd, step)`` says,
    before each step it would send (step None: after a sweep's IRDON), whether it resets
    there: it then numbers from 0 and its clock is real from 0 (millis() since the reset),
    and a reset within a sweep leaves it silent (the command forgotten)."""
    # Before the reset its clock is boot_ms + 1 ms an IRSCN, as hd.scan's: a real one read
    # from when the board was made said 16xx ms, not the 15xx tested, when the pty, the
    # thread and the handshake took over 100 ms on a loaded machine. The driver weighs only
    # the clock after a reset against its own.
    st = {"boot": None}

    def clock(dev) -> int:
        if st["boot"] is None:
            return boot_ms + dev.seq
        return int((time.monotonic() - st["boot"]) * 1000)

    def reset(dev) -> None:
        st["boot"] = time.monotonic()
        dev.seq = 0
        dev.said = False   # no IRSCN sent since power-up: IRSTP gets IRDON -1

    def behaviour(dev, cmd):
        if isinstance(cmd, p.Hello):
            dev.send(hd.info())
        elif isinstance(cmd, p.SweepCommand):
            dev.sweeps_seen = getattr(dev, "sweeps_seen", 0) + 1
            d = 1 if cmd.to_step >= cmd.from_step else -1
            for step in range(cmd.from_step, cmd.to_step + d, d):
                if reboot(dev, cmd, step):
                    reset(dev)
                    return
                counts = ",".join(map(str, hd.counts_for(step)))
                dev.send(hd.line(f"IRSCN,{dev.seq},{step},{clock(dev)},{counts}"))
                dev.seq += 1
                dev.said = True
            dev.send(hd.line(f"IRDON,{dev.seq - 1}"))
            if reboot(dev, cmd, None):
                reset(dev)
        elif isinstance(cmd, p.Stop):
            dev.send(hd.line(f"IRDON,{dev.seq - 1 if getattr(dev, 'said', False) else -1}"))
        elif isinstance(cmd, p.GoTo):
            dev.send(hd.line(f"IRPOS,{cmd.step}"))
    return behaviour


def test_a_board_that_reset_between_poses_while_the_robot_was_moved_is_refused():
    """A board whose clock is millis() browned out after the sweep at pose 1 (the ring at
    step 2, the sweep's end), while the robot was moved; pose 2 was swept 2 s later. Its
    clock then said more than at its last IRSCN (2 s since the reset against 1.5 s of its
    first session), so it did not go back: the renumbered sweep was taken, 2 steps off
    (37.8° on the real ring: t_room F1 0.997 -> 0.389), 'all 5 steps'. Its
    clock ran 0.5 s where 2 s passed: it started anew."""
    board = _millis_board(1500, lambda dev, cmd, step: step is None and dev.sweeps_seen == 1)
    dev = hd.HostileDevice(board)
    try:
        with SerialRing(dev.link, timeout_s=hd_timeout()) as ring:
            ring.sweep(resweep=0)
            time.sleep(2.0)
            with pytest.raises(DeviceRebooted) as err:
                ring.sweep(resweep=0)
    finally:
        dev.close()
    assert len(err.value.partial.steps) == 0
    assert re.fullmatch(
        rf"the ring on {re.escape(dev.link)} rebooted at step 2: its IRSCN are numbered from 0 "
        r"again, and its clock started anew \(it says (\d+) ms, (\d+) ms on from the 15\d\d ms "
        r"of the last IRSCN taken, where this computer's clock ran 2\.\d s\)\. Its firmware "
        r"takes the step it wakes at as step 0, so every step it names since is off by 2 "
        r"steps \(2\.2°\) and its readings would land beside their walls; none read since is "
        r"taken\. Then turn the ring back to radial \(IRGTO,-2 turns it there now\), reset "
        r"the board, and drive the poses not swept again\. device rebooted: 0 of 5 steps "
        r"received; .*", str(err.value))


def test_a_young_board_that_reset_in_a_sweep_is_refused():
    """The same board 0.5 s after power-up (an Arduino Uno resets when the port opens)
    resets as it turns from step -1 to 0 of its first sweep; IRSTP after a 1 s timeout gets
    IRDON -1, and the re-sweep's first IRSCN says 1 s or so: later than the 0.5 s of the
    last one, so it was taken as if nothing happened, each step one off."""
    board = _millis_board(500, lambda dev, cmd, step: dev.sweeps_seen == 1 and step == 0)
    dev = hd.HostileDevice(board)
    try:
        with SerialRing(dev.link, timeout_s=1.0) as ring:
            with pytest.raises(DeviceRebooted) as err:
                ring.sweep(resweep=1)
    finally:
        dev.close()
    assert [int(s) for s in err.value.partial.steps] == [-2, -1]
    assert re.fullmatch(
        rf"the ring on {re.escape(dev.link)} rebooted while it turned from step -1 to step "
        r"0: IRDON -1 \(no IRSCN sent since power-up\) ended a sweep after IRSCN had come, "
        r"and its clock started anew \(it says 1\d\d\d ms, \d+ ms on from the 5\d\d ms of the "
        r"last IRSCN taken, where this computer's clock ran \d\.\d s\)\. Its firmware takes "
        r"the step it wakes at as step 0, so every step it names since is off by the step "
        r"it stood at, from step -1 to step 0, and its readings would land beside their "
        r"walls; none read since is taken\. Then turn the ring back to radial by hand \(where "
        r"it stood is not known, so no IRGTO can\), reset the board, and drive the poses not "
        r"swept again\. device rebooted: 2 of 5 steps received; .*", str(err.value))


def test_a_board_that_reset_turning_away_from_step_0_is_refused():
    """Turned back to step 0 (IRGTO,0) after pose 1, the board reset as the motor started
    towards the next sweep's first step (a brown-out when the motor starts, firmware/README.md),
    silent; IRSTP got IRDON -1 and the re-sweep came numbered and clocked anew. The ring
    stood somewhere from step 0 to -2 when it woke, but the driver took it to have stood at
    step 0 (the last step it heard of) and kept the sweep: up to 2 steps off, exit 0."""
    def reboot(dev, cmd, step):
        return dev.sweeps_seen == 2 and step == cmd.from_step and not getattr(dev, "did", 0) \
            and setattr(dev, "did", 1) is None
    dev = hd.HostileDevice(_millis_board(60_000, reboot))
    try:
        with SerialRing(dev.link, timeout_s=hd_timeout()) as ring:
            ring.sweep(resweep=0)
            assert ring.goto(0) == 0
            with pytest.raises(DeviceRebooted) as err:
                ring.sweep(resweep=1)
    finally:
        dev.close()
    assert len(err.value.partial.steps) == 0
    assert re.fullmatch(
        rf"the ring on {re.escape(dev.link)} rebooted while it turned from step 0 to step -2: "
        r"IRDON -1 \(no IRSCN sent since power-up\) ended a sweep after IRSCN had come, and "
        r"its clock started anew \(\d+ ms after 600\d\d ms\)\. Its firmware takes the step it "
        r"wakes at as step 0, so every step it names since is off by the step it stood at, "
        r"from step 0 to step -2, and its readings would land beside their walls; none read "
        r"since is taken\. Then turn the ring back to radial by hand \(where it stood is not "
        r"known, so no IRGTO can\), reset the board, and drive the poses not swept again\. "
        r"device rebooted: 0 of 5 steps received; .*", str(err.value))


def hd_timeout() -> float:
    return 0.15   # test_hostile's: a fake device answers at once


@pytest.mark.parametrize("kind", ["text", "matplotlib"])
def test_view_into_a_folder_replaces_no_view_png_another_program_wrote(tmp_path, capsys, kind):
    """`irring view t_room --out DIR` replaced DIR/view.png whatever it was: a text file of
    that name, or a chart Matplotlib drew, exit 0 (view.png in view's folders is view's by
    its name). Now only a PNG that names irring view or no program (view's
    pictures before they named it) is replaced there."""
    from irring.cli import main

    folder = tmp_path / "pics"
    folder.mkdir()
    target = folder / "view.png"
    if kind == "text":
        target.write_bytes(b"my notes, not a picture\n")
        what = "a file"
    else:
        import matplotlib
        matplotlib.use("Agg")
        from matplotlib.figure import Figure
        Figure(figsize=(1, 1)).savefig(target, format="png")
        what = "a PNG picture"
    before = target.read_bytes()
    assert main(["view", "t_room", "--out", str(folder), "--size", "48x32"]) == 4
    assert capsys.readouterr().err == (
        f"irring view: error: --out {target}: is {what}, not a picture irring view drew; "
        "writing there would replace it (in its folder irring view replaces only a PNG whose "
        "Software field names it, or names no program, as its pictures did before): name "
        "another folder, or a FILE.png\n")
    assert target.read_bytes() == before


def test_view_into_a_folder_still_replaces_its_own_pictures_old_and_new(tmp_path, capsys):
    from PIL import Image

    from irring.cli import main

    folder = tmp_path / "pics"
    folder.mkdir()
    target = folder / "view.png"
    Image.new("RGB", (48, 32), (10, 20, 30)).save(target, format="PNG")   # names no program
    assert main(["view", "t_room", "--out", str(folder), "--size", "48x32"]) == 0
    with Image.open(target) as im:
        assert im.info["Software"] == "irring view"
    assert main(["view", "t_room", "--out", str(folder), "--size", "64x48"]) == 0
    with Image.open(target) as im:
        assert im.size == (64, 48)


def test_detection_of_a_ring_with_many_rays_holds_its_memory(monkeypatch):
    """`irring compare --design '{sensors: 8, radius_mm: 150, sweep_half_angle_deg: 180,
    step_deg: 0.01}'` passed the run's memory check and then asked for over 3 GB for the
    detection curve (288,000 rays × 180 bearings at once): "ran out of memory" under a 3 GB
    limit. A tenth of those rays asked for 290 MB a radius tried; now the bearings go in
    blocks, with the same answer."""
    import math
    import tracemalloc

    import numpy as np

    from irring import designs
    from irring.studies import geometry

    design = designs.parametric(8, 0.15, math.pi, math.radians(0.1))
    rays = geometry.design_rays(design)
    assert len(rays) == 28_800
    b = (np.arange(180) + 0.5) / 180 * geometry.symmetry_period_rad(design)
    centres = 0.4 * np.c_[np.cos(b), np.sin(b)]
    kw = dict(min_range_m=0.1, max_range_m=0.624, max_incidence_rad=math.radians(70))
    tracemalloc.start()
    try:
        got = geometry.seen(rays, centres, 0.01, **kw)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 100e6, peak
    monkeypatch.setattr(geometry, "SEEN_BLOCK", 1 << 40)   # every bearing at once, as before
    assert got.tolist() == geometry.seen(rays, centres, 0.01, **kw).tolist()
    assert got.sum() == 180


def _interrupted_in_an_import(*args, **kwargs):
    """What `import mujoco` raises when Ctrl-C or SIGTERM (raised as KeyboardInterrupt)
    lands in its C module's initialisation: pybind11 turns it into an ImportError."""
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt:
        raise ImportError("initialization failed")   # noqa: B904 - as pybind11 does


def test_a_study_interrupted_while_mujoco_loads_says_interrupted(tmp_path, capsys,
                                                                 monkeypatch):
    """`irring study` killed (SIGTERM while its first run imported MuJoCo) ended "internal
    error (ImportError: initialization failed) … please report it", exit 70; Ctrl-C at
    that moment the same. It is an interruption: exit 130, the runs kept."""
    from irring.cli import main
    from irring.studies import accuracy

    spec = tmp_path / "s.yaml"
    spec.write_text("designs: [radial12]\nscenarios: [box_room]\nseeds: [1, 2]\n")
    monkeypatch.setattr(accuracy, "run_job", _interrupted_in_an_import)
    out = tmp_path / "o"
    assert main(["study", str(spec), "--out", str(out), "--workers", "1"]) == 130
    assert capsys.readouterr().err == (
        f"irring study: interrupted; 0 finished run(s) kept in {out / 'results.csv'}: run the "
        "same command with --resume to run the rest\n")


def test_a_run_interrupted_while_mujoco_loads_says_interrupted(tmp_path, capsys,
                                                               monkeypatch):
    from irring import pipeline
    from irring.cli import main

    monkeypatch.setattr(pipeline, "run", _interrupted_in_an_import)
    assert main(["run", "t_room", "--out", str(tmp_path / "o")]) == 130
    assert capsys.readouterr().err == "irring run: interrupted\n"


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="reads a process's maps")
def test_ctrl_c_while_the_command_starts_is_one_line(tmp_path):
    """Ctrl-C as any command starts (while `irring` imports numpy, before its main() runs)
    printed Python's KeyboardInterrupt traceback, exit -2. Sent once numpy is being loaded
    (mapped into the process: irring/__init__.py has run its first lines), it gets the line
    main() prints, exit 130."""
    import os
    import signal
    import subprocess
    import sys

    script = os.path.join(os.path.dirname(sys.executable), "irring")
    proc = subprocess.Popen([script, "run", "t_room", "--out", str(tmp_path / "o")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        with open(f"/proc/{proc.pid}/maps") as f:
            if "numpy" in f.read():
                break
        time.sleep(0.002)
    proc.send_signal(signal.SIGINT)
    err = proc.communicate(timeout=60)[1].decode()
    assert (proc.returncode, err) == (130, "irring: interrupted\n")
