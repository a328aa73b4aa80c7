"""A SerialRing whose sweep ended in a lost link (a reboot, a timeout, a replay, another
ring) sweeps again only after a new handshake: the device's numbering and the ring's step
are no longer what the session counted, so readings taken on would be placed blind."""

from __future__ import annotations

import re

import pytest

import hostile_devices as hd
from irring.hardware import DeviceError, DeviceRebooted, DeviceTimeout, SerialRing

TIMEOUT_S = 0.15   # a fake device answers at once


def _rebooted_ring(dev) -> SerialRing:
    """A session whose second sweep found the board rebooted at step 2 (the first sweep's
    end), DeviceRebooted caught."""
    ring = SerialRing(dev.link, timeout_s=TIMEOUT_S).open()
    ring.sweep(resweep=0)
    with pytest.raises(DeviceRebooted):
        ring.sweep(resweep=0)
    return ring


def test_a_sweep_after_device_rebooted_is_refused_until_a_new_handshake():
    """Caught DeviceRebooted, then sweep() again: the renumbered board's readings were
    taken as good (all 5 steps, each 2 steps off where the ring stood when it woke). Now
    refused, naming the reboot and what to do; after hello() the session starts anew."""
    dev = hd.HostileDevice(hd.reboots_between_sweeps(False))
    try:
        ring = _rebooted_ring(dev)
        sent = dev.seq
        with pytest.raises(DeviceError) as err:
            ring.sweep(resweep=0)
        assert not isinstance(err.value, DeviceRebooted)
        assert str(err.value) == (
            f"the last sweep on {dev.link} ended with the device rebooted: the ring's step and "
            "the device's IRSCN numbering are no longer this session's, so what it reads now "
            "could be placed at the wrong steps. Turn the ring back to radial and reset the "
            "board as that error said, then handshake again (ring.hello(), or close this "
            "SerialRing and open a new one) before sweeping")
        assert dev.seq == sent   # nothing was asked of the device
        ring.hello()
        sweep = ring.sweep(resweep=0)
        assert [int(s) for s in sweep.steps] == list(range(hd.MIN_STEP, hd.MAX_STEP + 1))
        ring.close()
    finally:
        dev.close()


def test_a_sweep_after_a_timeout_is_refused_until_a_new_handshake():
    """A device that fell silent mid-sweep (DeviceTimeout) may have reset in its silence;
    the next sweep would take a renumbered board's readings unchecked."""
    dev = hd.HostileDevice(hd.good_then(hd.silent, sweeps=1))
    try:
        ring = SerialRing(dev.link, timeout_s=TIMEOUT_S, retries=0).open()
        ring.sweep(resweep=0)
        with pytest.raises(DeviceTimeout):
            ring.sweep(resweep=0)
        with pytest.raises(DeviceError, match=re.escape(
                f"the last sweep on {dev.link} ended with the device stopped answering: ")):
            ring.sweep(resweep=0)
        ring.close()
    finally:
        dev.close()
