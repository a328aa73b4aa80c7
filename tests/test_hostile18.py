"""Round eighteen of hostile input: each test names the input that broke and asserts what
happens now."""

from __future__ import annotations

import numpy as np

from irring.designs import PAPER_RING
from irring.hardware import SerialRing
from irring.hardware.emulator import Device

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
