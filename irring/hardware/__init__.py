"""The real ring over a serial port, and a device emulator that speaks its protocol.

``protocol`` encodes and decodes IRR sentences (pure, no I/O, no pyserial);
:class:`SerialRing` drives a ring through pyserial and returns the same
:class:`irring.core.Sweep` as the simulator; ``emulator`` is a device on a pseudo-terminal
backed by the simulator (import it explicitly). The driver's names load on first use, so
``import irring.hardware.protocol`` needs no pyserial.
"""

from __future__ import annotations

__all__ = ["SerialRing", "SweepReport", "LinkStats", "DeviceError", "DeviceTimeout",
           "DeviceChanged", "DeviceDisconnected", "DeviceRebooted", "DeviceRejected",
           "DeviceReplayed", "HandshakeError", "LinkLost", "NoReadings"]


def __getattr__(name: str):
    if name in __all__:
        from . import serial_ring   # deferred: pyserial; the protocol codec does without it

        return getattr(serial_ring, name)
    raise AttributeError(f"module 'irring.hardware' has no attribute {name!r}")
