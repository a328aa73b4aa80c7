"""Round twenty-five of hostile input: each test names the input that broke and asserts
what happens now."""

from __future__ import annotations

import time

import pytest

import hostile_devices as hd
from irring.cli import main
from irring.hardware import protocol as p


def _other_ring_after_sweep_one(delay_s: float):
    """A device that, after sweep 1's IRDON (at once, or ``delay_s`` later), announces an
    8-sensor ring: a late IRINF, as if answering an earlier IRHLO, of another board."""
    def behaviour(dev, cmd):
        if isinstance(cmd, p.Hello):
            dev.send(hd.info())
        elif isinstance(cmd, p.SweepCommand):
            dev.sweeps = getattr(dev, "sweeps", 0) + 1
            data = b"".join(hd.scan(dev.seq + i, s) for i, s in
                            enumerate(range(cmd.from_step, cmd.to_step + 1)))
            dev.seq += cmd.to_step - cmd.from_step + 1
            data += hd.line(f"IRDON,{dev.seq - 1}")
            late = hd.info(sensors=8) if dev.sweeps == 1 else b""
            if delay_s:
                dev.send(data)
                time.sleep(delay_s)
                dev.send(late)
            else:
                dev.send(data + late)
        elif isinstance(cmd, p.Stop):
            dev.send(hd.line(f"IRDON,{dev.seq - 1}"))
        elif isinstance(cmd, p.GoTo):
            dev.send(hd.line(f"IRPOS,{cmd.step}"))
    return behaviour


@pytest.mark.parametrize("delay_s", [0.0, 0.1])
def test_a_late_irinf_of_another_ring_between_sweeps_is_device_changed(delay_s):
    # read with sweep 1's IRDON, or arriving while the host waited between sweeps, the
    # 8-sensor IRINF was dropped without a word (the rest of the read, then the flush before
    # sweep 2) and sweep 2 came back "clean link"; mid-sweep it was DeviceChanged
    from irring.hardware.serial_ring import DeviceChanged, SerialRing
    dev = hd.HostileDevice(_other_ring_after_sweep_one(delay_s))
    kept = []
    try:
        with SerialRing(dev.link, timeout_s=0.3) as ring:
            with pytest.raises(DeviceChanged) as changed:
                for _ in range(2):
                    kept.append(ring.sweep())
                    time.sleep(0.3)
    finally:
        dev.close()
    assert "now announces another ring: 8 sensors, 12-bit ADC" in str(changed.value)
    assert "where the handshake said 12 sensors" in str(changed.value)
    # what came before it is kept, whole: sweep 1 itself, or with the exception
    (sweep,) = kept or [changed.value.partial]
    assert [int(s) for s in sweep.steps] == [hd.MIN_STEP + i for i in range(5)]
    assert [list(row) for row in sweep.counts] == [hd.counts_for(s) for s in sweep.steps]


@pytest.mark.parametrize("where, said", [
    ("[fe80::1]:0", "; a link-local address needs its interface ([fe80::1%eth0], as `ip addr` "
                    "names it), or name an address of this machine (127.0.0.1, [::1]) or a "
                    "name it resolves"),
    ("192.0.2.7:0", "; not an address of this machine: name one (127.0.0.1, [::1]) or a name "
                    "it resolves"),
])
def test_an_address_the_emulator_cannot_listen_on_says_what_is_allowed(where, said, capsys):
    # `irring emulate --tcp [fe80::1]:0` said only "Invalid argument", and an address of
    # another machine only "Cannot assign requested address"
    import socket
    if where.startswith("[") and not socket.has_ipv6:
        pytest.skip("no IPv6 on this machine")
    assert main(["emulate", "t_room", "--tcp", where, "--quiet"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"irring emulate: error: --tcp {where}: ") and line.endswith(said)


def test_a_port_in_use_and_the_warning_of_an_ipv6_bind_say_what_to_do(capsys):
    # a port another program listens on said only "Address already in use"; `--tcp [::]:0`
    # was told "use 127.0.0.1 to keep it on this machine", an address of the other family
    import socket

    from irring.cli.emulate import _exposed
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        assert main(["emulate", "t_room", "--tcp", f"127.0.0.1:{port}", "--quiet"]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"irring emulate: error: --tcp 127.0.0.1:{port}: Address already in use; another "
        "program listens there: pick another PORT, or 0 for a free one"]
    assert _exposed("[::]:0", "::") == (
        "--tcp [::]:0 serves the ring to every machine that can reach ::, with no "
        "authentication; use [::1] to keep it on this machine")
    assert _exposed("0.0.0.0:7", "0.0.0.0").endswith("use 127.0.0.1 to keep it on this machine")


def _answers_stop_before_its_readings(dev, cmd):
    """Sweep 1's readings (every count 7), sent 0.6 s late, after its IRDON to the host's
    IRSTP had said they were sent; silent to sweep 2's first IRSWP, then a correct device."""
    if isinstance(cmd, p.Hello):
        dev.send(hd.info())
    elif isinstance(cmd, p.SweepCommand):
        dev.sweeps = getattr(dev, "sweeps", 0) + 1
        if dev.sweeps == 2:
            return
        data = b"".join(hd.line(f"IRSCN,{dev.seq + i},{s},{1000 + dev.seq + i},"
                                + ",".join(["7"] * hd.SENSORS)) if dev.sweeps == 1
                        else hd.scan(dev.seq + i, s)
                        for i, s in enumerate(range(cmd.from_step, cmd.to_step + 1)))
        dev.seq += cmd.to_step - cmd.from_step + 1
        data += hd.line(f"IRDON,{dev.seq - 1}")
        if dev.sweeps == 1:
            import threading
            threading.Timer(0.6, dev.send, (data,)).start()
        else:
            dev.send(data)
    elif isinstance(cmd, p.Stop):
        dev.send(hd.line(f"IRDON,{dev.seq - 1}"))
    elif isinstance(cmd, p.GoTo):
        dev.send(hd.line(f"IRPOS,{cmd.step}"))


def test_readings_late_past_the_irdon_that_said_they_were_sent_are_not_the_next_sweeps():
    # sweep 1 silent, its IRSTP answered IRDON 4 (seq 0 … 4 sent), then IRSCN 0 … 4 and IRDON
    # 4 came during sweep 2: taken as a device numbering anew (rebooted between sweeps), so
    # sweep 2 held sweep 1's readings, "clean link"
    from irring.hardware.serial_ring import NoReadings, SerialRing
    dev = hd.HostileDevice(_answers_stop_before_its_readings)
    try:
        with SerialRing(dev.link, timeout_s=0.3) as ring:
            with pytest.raises(NoReadings):
                ring.sweep(resweep=0)
            sweep = ring.sweep(resweep=1)
            report = ring.last_report.message
    finally:
        dev.close()
    assert [int(s) for s in sweep.steps] == [hd.MIN_STEP + i for i in range(5)]
    assert [list(row) for row in sweep.counts] == [hd.counts_for(s) for s in sweep.steps]
    assert "6 stale IRSCN dropped" in report


def test_a_room_written_in_mm_under_outline_m_is_refused_by_the_check(tmp_path, capsys):
    # `irring scenarios my.yaml` listed it as fine, then `irring run my.yaml` refused its
    # 2,420 km room's grid (exit 5): the check did not check what run checks first
    from irring.scenario import bundled
    text = bundled()["t_room"].read_text().replace("outline_mm:", "outline_m:")
    (tmp_path / "mm.yaml").write_text(text)
    assert main(["scenarios", str(tmp_path / "mm.yaml")]) == 5
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"irring scenarios: error: {tmp_path / 'mm.yaml'}: a grid of "
                           "180,022 × 242,022 cells of 10 mm would need about 2614.2 GB")
    assert line.endswith("(its outline spans 2,420 × 1,800 m; room.outline_m is read in "
                         "metres, outline_mm in millimetres)")


@pytest.mark.parametrize("step, said", [
    (60, "60 ° is out of range; allowed 0.006 … 27 °"),
    (0.005, "0.005 ° is out of range; allowed 0.006 … 27 °"),
])
def test_a_design_step_beyond_the_motors_is_refused_in_the_design_files_words(step, said):
    # step_deg 60 passed the design's check (0.01 … 90) and was refused as
    # "ring.motor_step_rad: 100 ° is out of range; allowed 0.01 … 45 °": a key and a value the
    # user never wrote (the sensor step is the motor's times the belt's 0.6)
    from irring.studies.study import StudyError, design_spec
    with pytest.raises(StudyError) as refused:
        design_spec("", "--design", {"sensors": 8, "radius_mm": 120,
                                     "sweep_half_angle_deg": 45, "step_deg": step})
    assert str(refused.value) == f"--design.step_deg: {said}"
    spec = design_spec("", "--design", {"sensors": 8, "radius_mm": 120,
                                        "sweep_half_angle_deg": 27, "step_deg": 27})
    assert spec.build().ring.max_step == 1   # the largest step is one motor step of 45°
