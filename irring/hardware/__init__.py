"""The real ring over a serial port, and a device emulator that speaks its protocol.

``protocol`` encodes and decodes IRR sentences (pure, no I/O); :class:`SerialRing` drives a
ring through pyserial and returns the same :class:`irring.data.Sweep` as the simulator;
``emulator`` is a device on a pseudo-terminal backed by the simulator (import it explicitly:
it pulls in MuJoCo, the driver does not).
"""

from __future__ import annotations

from .serial_ring import (DeviceDisconnected, DeviceError, DeviceRejected, DeviceTimeout,
                          HandshakeError, LinkLost, LinkStats, SerialRing, SweepReport)

__all__ = ["SerialRing", "SweepReport", "LinkStats", "DeviceError", "DeviceTimeout",
           "DeviceDisconnected", "DeviceRejected", "HandshakeError", "LinkLost"]
