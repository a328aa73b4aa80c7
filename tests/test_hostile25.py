"""Round twenty-five of hostile input: each test names the input that broke and asserts
what happens now."""

from __future__ import annotations

import time

import pytest

import hostile_devices as hd
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
