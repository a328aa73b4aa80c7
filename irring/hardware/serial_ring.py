"""The real ring (or its emulator) over a serial port, returning the same Sweep as SimRing.

    with SerialRing("/dev/ttyUSB0") as ring:          # opens, then IRHLO → IRINF
        sweep = ring.sweep((0.5, 0.45, 0.0))           # core.Sweep; sweep.missing_steps

A step that never arrived is listed in ``Sweep.missing_steps``, never invented; a silent
device raises :class:`DeviceTimeout`, a closed port :class:`DeviceDisconnected`, both
holding ``.partial``. Closing stops a sweep still running and turns the ring back to step 0.
Ports, link checks, counters, the boot wait and the return to step 0: docs/protocol.md.
"""

from __future__ import annotations

import dataclasses
import errno
import logging
import math
import os
import re
import time
import urllib.parse
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable

import numpy as np
import serial

from .. import core
from ..designs import PAPER_RING
from ..errors import DeviceError, interrupts_noted, printable
from ..core import Ring
from . import protocol as p

log = logging.getLogger("irring.hardware")

DEFAULT_BAUD = 115200
DEFAULT_TIMEOUT_S = 1.0
MOVE_ALLOWANCE_S = 0.005  # per motor step the ring may travel before a sweep's first reading
# An Arduino resets when its serial port is opened (DTR) and its bootloader takes the bytes
# of the next second or so: for BOOT_S after opening a serial device, IRHLO is sent again
# after each BOOT_RESEND_S in which nothing arrived (a stray byte sends optiboot on to the
# firmware within ~0.1 s), not counted as a timeout or a resent command
BOOT_S = 2.0
BOOT_RESEND_S = 0.25


# --------------------------------------------------------------------------- errors


# What a device may announce in IRINF is what a Ring may be (core.Ring's field bounds, the
# scenario schema's; an IRSCN of 72 counts no longer fits a 128-byte sentence anyway), and an
# ADC of at most core.MAX_ADC_BITS bits (a recording's and a calibration file's bound)
# a sweep pass that makes no progress (no new step) for this many timeouts beyond its
# IRSTP retries is given up, whatever else the device keeps sending
NO_PROGRESS_TIMEOUTS = 3
# a sweep pass in which this many bytes arrive without a new step (32 of the longest
# sentences: dozens of steps' worth) is treated like a silent one (IRSTP, counted): a link
# that talks (noise, useless or garbled sentences) but never delivers an intact step is
# bounded by what it sends, not by a clock
CHATTER_LIMIT_BYTES = 32 * p.MAX_SENTENCE_BYTES
# an IRSTP answered by a garbled sentence was heard: it is sent again this soon, and not
# counted among the unanswered (the no-progress limit above still bounds the whole pass)
GARBLED_ANSWER_RETRY_S = 0.1
# A device clock that runs on advances from one IRSCN to the next about as far as this
# computer's clock: within CLOCK_RATE_TOLERANCE (a UART keeps 115200 baud only within a few
# per cent) and CLOCK_LATENCY_S (reading the port, scheduling). One that a reboot restarted
# advances less, by what it had counted before, whether or not its count goes back: millis()
# of a board reset 2 s ago says 2000 ms, past the 1500 of its last IRSCN before the reset
CLOCK_RATE_TOLERANCE = 0.05
CLOCK_LATENCY_S = 0.1


class HandshakeError(DeviceError):
    """No usable IRINF answer to IRHLO."""


# a sentence whose check field matched but whose fields break the protocol's rules
_FIELD_FAULTS = (p.Fault.FIELD_COUNT, p.Fault.BAD_FIELD, p.Fault.OUT_OF_RANGE)


def _info_faults(info: p.Info) -> list[str]:
    """What in an IRINF no ring has: each fault names the field and the allowed range."""
    def allowed(name: str, scale: float = 1.0, unit: str = "") -> str:
        lo, hi = core.bounds(Ring, name)
        return f"allowed {lo * scale:g} … {hi * scale:g}{unit}"

    gear = info.gear_num / info.gear_den
    step_lo, step_hi = core.bounds(Ring, "max_step")
    turn = max(abs(info.min_step), abs(info.max_step)) * info.step_mdeg / 1000.0 * gear
    limit_deg = math.degrees(core.bounds(Ring, "joint_limit_rad")[1])
    faults = []
    if not core.bounds(Ring, "sensors")[0] <= info.nsensors <= core.bounds(Ring, "sensors")[1]:
        faults.append(f"{info.nsensors} sensors (nsensors; {allowed('sensors')})")
    if not 1 <= info.adc_bits <= core.MAX_ADC_BITS:
        faults.append(f"a {info.adc_bits}-bit ADC (adc_bits; allowed 1 … {core.MAX_ADC_BITS})")
    if not (step_lo <= info.min_step and info.max_step <= step_hi
            and info.max_step - info.min_step < core.MAX_STEPS):
        faults.append(f"steps {info.min_step} … {info.max_step} (min_step, max_step; allowed "
                      f"{step_lo} … {step_hi}, at most {core.MAX_STEPS:,} steps)")
    step_rad = math.radians(info.step_mdeg / 1000.0)
    lo, hi = core.bounds(Ring, "motor_step_rad")
    if not lo - 1e-12 <= step_rad <= hi + 1e-12:
        faults.append(f"a motor step of {info.step_mdeg / 1000:g}° (step_mdeg; allowed "
                      f"{math.degrees(lo) * 1000:g} … {math.degrees(hi) * 1000:g} m°)")
    lo, hi = core.bounds(Ring, "gear")
    if not lo <= gear <= hi:
        faults.append(f"a belt ratio of {gear:g} (gear_num/gear_den; {allowed('gear')})")
    if not faults and turn > limit_deg + 1e-9:
        faults.append(f"a sweep turning the sensors to ±{turn:g}° (steps {info.min_step} … "
                      f"{info.max_step} × {info.step_mdeg / 1000:g}° × belt {gear:g}; allowed "
                      f"at most ±{limit_deg:g}°, a sensor turned once round)")
    return faults


def _ring_text(info: p.Info) -> str:
    return (f"{info.nsensors} sensors, {info.adc_bits}-bit ADC, steps {info.min_step} … "
            f"{info.max_step} of {info.step_mdeg / 1000:g}° × {info.gear_num}/{info.gear_den}, "
            f"firmware {info.firmware!r}")


class DeviceRejected(DeviceError, core.SourceLost):
    """The device answered a command with IRERR (bad argument, step out of range, …); in a
    sweep, ``partial`` and ``report`` hold what arrived before it (as :class:`LinkLost`)."""

    def __init__(self, message: str, code: int, text: str):
        super().__init__(message)
        self.code, self.text = code, text


class LinkLost(DeviceError, core.SourceLost):
    """The device went away mid-operation; ``partial`` holds what was received, ``report``
    the :class:`SweepReport` of the sweep it cut short."""


class NoReadings(LinkLost):
    """A sweep ended without a single step arriving (``partial`` holds the empty sweep)."""


class DeviceChanged(LinkLost):
    """Mid-session the device announced (IRINF) another ring than the handshake's: it was
    reflashed or swapped; in a sweep, the readings of the ring it was are in ``partial``."""


class DeviceReplayed(LinkLost):
    """The device answered a sweep with its previous sweep's IRSCN again, sentence for
    sentence (seq, step, clock and counts): a firmware replaying its buffer, not reading."""


class DeviceRebooted(LinkLost):
    """The device rebooted (its IRSCN numbered and its clock started anew) while the ring
    stood away from step 0: its firmware takes where it wakes as step 0, so every step it
    names since is off by where it stood; what it read since is not taken."""


class DeviceTimeout(LinkLost):
    """The device stopped answering (no sentence for ``timeout_s``, IRSTP retries unanswered)."""


class DeviceDisconnected(LinkLost):
    """The port failed (cable pulled, emulator gone, socket closed)."""


# --------------------------------------------------------------------------- reports


@dataclass
class LinkStats:
    """Counters of everything that went wrong (or right) on the link, cumulative."""

    sentences: int = 0          # decoded and accepted sentences of every type
    scans: int = 0              # IRSCN accepted into a sweep
    checksum_failures: int = 0  # sentences dropped for a wrong checksum
    malformed: int = 0          # sentences dropped for any other framing/field fault
    ignored_bytes: int = 0      # bytes outside any sentence (line noise)
    seq_gaps: int = 0           # places where the IRSCN sequence jumped
    lost_scans: int = 0         # IRSCN the device sent that never arrived intact
    inconsistent: int = 0       # valid-checksum IRSCN contradicting the sweep (or each
    #                             other: one step twice with other counts), dropped
    stale: int = 0              # IRSCN/IRDON left over from an earlier exchange, dropped
    duplicates: int = 0         # a second IRSCN for a step already read, dropped
    out_of_order: int = 0       # IRSCN that arrived after a later one (kept; not a loss)
    timeouts: int = 0           # waits of timeout_s with nothing arriving
    disconnects: int = 0
    device_errors: int = 0      # IRERR answers received
    resent_commands: int = 0    # commands sent again after IRERR 1 / busy / timeout
    resweeps: int = 0           # IRSWP re-issued for missing steps only
    clock_faults: int = 0       # passes whose device clock ran impossibly fast, backwards or
    #                             stood still (the pass's hardware time is then the nominal one)
    reversed_passes: int = 0    # passes the device swept to → from, against the asked order
    #                             (read: each IRSCN names its step; its seq runs the other way)

    def as_dict(self) -> dict[str, int]:
        return dataclasses.asdict(self)

    def minus(self, earlier: dict[str, int]) -> dict[str, int]:
        return {k: v - earlier.get(k, 0) for k, v in self.as_dict().items()}


@dataclass(frozen=True)
class SweepReport:
    """What happened during one :meth:`SerialRing.sweep` call."""

    requested_steps: tuple[int, ...]
    received_steps: int
    missing_steps: tuple[int, ...]
    link: dict[str, int]          # LinkStats counted during this sweep only
    complete: bool                # the device ended every pass with IRDON
    wall_time_s: float            # host time the call took
    message: str                  # one line for a person

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _describe_link(link: dict[str, int], dropped: str | None = None,
                   garbled: str | None = None) -> str:
    """The link counters that are not zero, for a person; ``dropped`` names the first IRSCN
    dropped as inconsistent, ``garbled`` the first malformed sentence."""
    names = {"checksum_failures": "checksum failures", "malformed": "malformed sentences",
             "lost_scans": "IRSCN lost", "seq_gaps": "seq gaps", "timeouts": "timeouts",
             "inconsistent": "inconsistent IRSCN dropped", "stale": "stale IRSCN dropped",
             "out_of_order": "IRSCN late (after a later one)",
             "duplicates": "duplicates", "device_errors": "IRERR answers",
             "resent_commands": "commands resent", "resweeps": "re-sweeps",
             "disconnects": "disconnects", "clock_faults": "device clock faults",
             "reversed_passes": "passes swept against the asked direction"}
    first = {"inconsistent": dropped, "malformed": garbled}
    parts = [f"{link[k]} {v}" + (f" (the first: {first[k]})" if first.get(k) else "")
             for k, v in names.items() if link.get(k)]
    return ", ".join(parts) if parts else "clean link"


# --------------------------------------------------------------------------- driver


MISMATCH_MIN_BYTES = 16   # bytes, most of them not ASCII, before a baud mismatch is named
_SENTENCE_BYTES = bytes(range(0x20, 0x7F)) + b"\r\n"   # all an IRR sentence is made of
PORT_LOCKED = ("another program has it open and locked (an irring drive or calibrate still "
               "running on it?)")


def _open_failure(exc: BaseException) -> str:
    """Why a port did not open: the operating system's reason (pyserial wraps it as
    "[Errno 2] could not open port X: [Errno 2] No such file or directory: 'X'"), else
    the error's own text."""
    reason, seen = None, exc
    while seen is not None:
        code, text = (tuple(seen.args) + (None, None))[:2]
        if not isinstance(seen, serial.SerialException) and isinstance(code, int) \
                and isinstance(text, str):   # an OSError, or termios.error (errno, text)
            reason = ("not a serial port" if code == errno.ENOTTY else PORT_LOCKED
                      if code in (errno.EAGAIN, errno.EWOULDBLOCK) and "lock" in str(exc).lower()
                      else text)
        seen = seen.__cause__ or seen.__context__
    return reason or str(exc)


def _may_reset(port: str) -> bool:
    """Whether opening ``port`` may reset the board behind it: a serial device path, or a
    pyserial URL that may open one (any but loop://; spy:// and alt:// only if the path they
    wrap is no pseudo-terminal). Why these: docs/protocol.md."""
    scheme, sep, _ = port.partition("://")
    if sep:
        scheme = scheme.lower()
        if scheme == "loop":
            return False
        if scheme not in ("spy", "alt"):
            return True
        parts = urllib.parse.urlsplit(port)
        port = parts.netloc + parts.path
    real = os.path.realpath(port)
    return not (real.startswith("/dev/pts/") or re.fullmatch(r"/dev/ttys\d+", real))


def _check_settings(samples: int, settle_s: float, resweep: int) -> None:
    if not 1 <= samples <= p.MAX_SAMPLES:
        raise ValueError(f"samples must be 1 … {p.MAX_SAMPLES}, got {samples}")
    if not settle_s >= 0:
        raise ValueError(f"settle_s must be ≥ 0, got {settle_s}")
    if resweep < 0:
        raise ValueError(f"resweep must be ≥ 0 rounds, got {resweep}")


def _runs(steps: list[int]) -> list[tuple[int, int]]:
    """Consecutive runs (±1 per step, one direction) → [(from, to)], in order."""
    runs: list[tuple[int, int]] = []
    i = 0
    while i < len(steps):
        j = i
        if j + 1 < len(steps) and abs(steps[j + 1] - steps[j]) == 1:
            d = steps[j + 1] - steps[j]
            while j + 1 < len(steps) and steps[j + 1] - steps[j] == d:
                j += 1
        runs.append((steps[i], steps[j]))
        i = j + 1
    return runs


def _renumbered(scans: list[p.Scan], ps: _Pass, done_seq: int) -> bool | None:
    """Whether ``scans`` (IRSCN numbered before the pass began) are one numbering of the
    pass ``ps``'s steps — each seq minus its step's place in the sending order the same —
    that the IRDON ``done_seq`` ends (its seq is theirs at the place of the last step
    received or a later one): None if not, else whether they number the steps from the
    pass's last one (swept reversed)."""
    pos_of = ps.index
    if not scans or done_seq < 0 or any(sc.step not in pos_of for sc in scans):
        return None
    n = len(pos_of)
    for reverse in (False, True):
        places = [ps.sent_at(pos_of[sc.step], reverse) for sc in scans]
        bases = {(sc.seq - at) % p.SEQ_MODULO for sc, at in zip(scans, places)}
        if len(bases) == 1 and max(places) <= (done_seq - bases.pop()) % p.SEQ_MODULO < n:
            return reverse
    return None


def _numbered_with(suspects: list[p.Scan], fresh: p.Scan, ps: _Pass) -> list[p.Scan]:
    """The ``suspects`` (IRSCN that looked stale) whose seq is that of their step in the
    numbering ``fresh`` gives ``ps`` (swept either way), earliest sent first."""
    pos_of = ps.index
    if fresh.step not in pos_of:
        return []
    at = pos_of[fresh.step]
    fits = [sc for sc in suspects if sc.step in pos_of and any(
        (fresh.seq - sc.seq) % p.SEQ_MODULO == ps.sent_at(at, r) - ps.sent_at(pos_of[sc.step], r)
        for r in (False, True))]
    return sorted(fits, key=lambda sc: (sc.seq - fresh.seq) % p.SEQ_MODULO)


@dataclass
class _Pass:
    """Bookkeeping of one IRSWP: which steps it asked for and what arrived."""

    run: tuple[int, int]                 # (from, to) inclusive, either direction
    got: dict[int, p.Scan] = field(default_factory=dict)
    done: bool = False
    # the device swept to → from (its IRSCN name their steps; their seq runs against them)
    reversed: bool = False
    # host time a step may take at most before the pass is given up (its no-progress
    # limit): a device clock claiming more per step than this is wrong
    max_step_s: float = float("inf")

    @property
    def expected(self) -> list[int]:
        lo, hi = self.run
        d = 1 if hi >= lo else -1
        return list(range(lo, hi + d, d))

    @property
    def index(self) -> dict[int, int]:
        """step → its place in the pass."""
        return {s: i for i, s in enumerate(self.expected)}

    def sent_at(self, pos: int, reverse: bool | None = None) -> int:
        """The place in the device's sending order of the step at place ``pos`` (swept as
        ``reverse`` says, else as the pass is believed swept)."""
        reverse = self.reversed if reverse is None else reverse
        return abs(self.run[1] - self.run[0]) - pos if reverse else pos


class SerialRing:
    """A ring speaking the IRR protocol over a pyserial port.

    Parameters
    ----------
    port: a pyserial URL or device path, or an open/openable pyserial port object.
    baudrate: UART speed (both ends must agree; 115200 by default).
    timeout_s: longest silence (not a byte arriving) tolerated while an answer is due, on
        top of the time the device needs per step (settle + samples × 38.3 ms). After it
        the driver sends IRSTP and repeats it up to ``retries`` times (``retries + 1`` in
        all, each with its own ``timeout_s``) before giving up with :class:`DeviceTimeout`.
        During a sweep, CHATTER_LIMIT_BYTES arriving without a new step count as one such
        silence (a link that talks but delivers nothing); IRHLO and IRGTO wait ``timeout_s``
        for their answer (the first IRHLO at least ``boot_s``; :meth:`close`'s IRGTO,0 also
        MOVE_ALLOWANCE_S a motor step).
    retries: how often a command is repeated after IRERR 1, busy or a timeout.
    template: the ring design whose numbers the device does not report (radius, emitter
        offset, sensor height, joint limit); IRINF overrides sensors, step, gear, limits.
    radius_m / emitter_offset_m: override the template's (paper: 0.15 m / 0.007 m).
    sensor_model, vref_v, max_range_m: what the Sweep says about the sensors (the device
        does not report them; take them from your calibration file).
    samples, settle_s, resweep: how :meth:`sweep` sweeps unless told otherwise: readings
        averaged per step by the device (1–64), wait at each step before reading (s), rounds
        of re-sweeping only the steps still missing.
    accept_v1: speak IRR protocol v1 (an 8-bit XOR checksum: two bit errors in one bit
        column pass as changed readings) to a device not yet reflashed for v2, with a
        warning (:attr:`protocol_warning`, logged); by default such a device is refused
        with :class:`HandshakeError` saying how to reflash it.
    boot_s: seconds after :meth:`open` opens the port in which the board may still be
        starting (an Arduino resets when its port opens): IRHLO is sent again after each
        BOOT_RESEND_S of silence meanwhile. None: BOOT_S where opening the port may reset a
        board (a serial device path, or a URL that may open one: docs/protocol.md), 0 for a
        pty, loop:// or a port object.
    opener: ``serial.serial_for_url``-compatible factory, replaceable in tests.

    A :class:`irring.core.RingSource`: ``pipeline.acquire`` drives it as it drives SimRing.
    """

    def __init__(self, port: str | serial.SerialBase, *, baudrate: int = DEFAULT_BAUD,
                 timeout_s: float = DEFAULT_TIMEOUT_S, retries: int = 2,
                 template: Ring = PAPER_RING, radius_m: float | None = None,
                 emitter_offset_m: float | None = None, sensor_model: str = core.SENSOR_MODEL,
                 vref_v: float = core.VREF_V, max_range_m: float = core.MAX_RANGE_M, samples: int = 1,
                 settle_s: float = 0.0, resweep: int = 0, accept_v1: bool = False,
                 boot_s: float | None = None,
                 opener: Callable[..., serial.SerialBase] = serial.serial_for_url):
        if timeout_s <= 0:
            raise ValueError(f"timeout_s must be > 0, got {timeout_s}")
        if boot_s is not None and not 0 <= boot_s <= 60:
            raise ValueError(f"boot_s must be 0 … 60 s, got {boot_s}")
        _check_settings(samples, settle_s, resweep)
        self.samples, self.settle_s, self.resweep = int(samples), float(settle_s), int(resweep)
        self.port_name = port if isinstance(port, str) else getattr(port, "name", None) or "port"
        self._port_arg = port
        self._port: serial.SerialBase | None = None
        self.baudrate = baudrate
        self.timeout_s = float(timeout_s)
        self.retries = int(retries)
        self.template = template
        self.radius_m = radius_m
        self.emitter_offset_m = emitter_offset_m
        self.sensor_model, self.vref_v, self.max_range_m = sensor_model, vref_v, max_range_m
        self.opener = opener
        self.poll_s = min(0.02, self.timeout_s / 4)
        self.accept_v1 = bool(accept_v1)
        self.decoder = p.Decoder()   # v2; v1 only after a handshake found an old device
        self.protocol_warning: str | None = None
        self._other_framing = 0  # sentences framed for another protocol version, heard
        self._refused_info: p.ProtocolError | None = None  # an intact IRINF out of range
        self._misframed_info: list[bytes] = []  # IRINF answers rejected for their framing
        self._rx_bytes = 0     # bytes read from the port, all told (silence is none arriving)
        self._not_ascii = 0    # of them, bytes no IRR sentence holds (not printable ASCII)
        self.stats = LinkStats()
        self.info: p.Info | None = None
        self.ring: Ring | None = None
        self.last_report: SweepReport | None = None
        self._last_seq: int | None = None  # seq of the device's last IRSCN, from IRDON
        # (seq, n): the IRDON of a pass n steps short said IRSCN up to seq were sent
        self._owed: tuple[int, int] | None = None
        self._position: int | None = None  # motor step last reported (None: unknown)
        self._dropped: str | None = None  # the sweep's first IRSCN dropped as inconsistent
        self._garbled: str | None = None  # the sweep's first malformed sentence, and why
        self._sweep_before: dict[str, int] = {}   # the counters when the sweep began
        self._previous: dict[int, p.Scan] = {}   # the last sweep's IRSCN by step
        self._clock: int | None = None   # device clock of the latest IRSCN taken (ms)
        self._clock_at: float | None = None   # when it arrived (time.monotonic())
        # an IRDON -1 (none sent since power-up) after IRSCN were taken: the device said it
        # rebooted; the ring stood then from one step to another (the same: at rest; None:
        # unknown): a board that resets in a command has turned some way towards its target
        self._woke: tuple[int | None, int | None] | None = None
        self._woke_scans = 0
        self._woke_at_close = False   # close() saw that reboot (IRGTO,0 would not help)
        self._woke_at_rest: int | None = None   # … at rest, at this step (IRGTO,-step helps)
        self.boot_s = boot_s
        self._boot_window = 0.0     # s after opening in which the board may be starting
        self._boot_until = 0.0      # host time that window ends
        self._running = False       # an IRSWP or IRGTO sent and not yet ended (IRDON, IRPOS)
        self._stop_sent = False     # an IRSTP sent for it, its IRDON not read yet
        self._moved = False         # the motor may stand away from step 0
        self._link_dead = False     # the device stopped answering or the port failed
        self._position_lost = False  # it rebooted away from step 0, or another ring answered
        # why the last sweep lost the link ("device rebooted", …): the device's numbering
        # and the ring's step are no longer this session's, so no sweep before a handshake
        self._lost_sweep: str | None = None
        self._heard: int | None = None   # the last step the device named (IRSCN, IRPOS)
        # where the ring stands at rest, as the device last confirmed it (None: not known)
        self.stands_at: int | None = None
        # a Ctrl-C (or a SIGTERM raised as one) came while close() turned the ring back
        self.close_interrupted = False
        self.park_failure: str | None = None

    # ---------------------------------------------------------------- lifecycle

    def open(self, handshake: bool = True) -> SerialRing:
        """Open the port (if given as a URL/path), flush it and, by default, handshake."""
        if self._port is None:
            if isinstance(self._port_arg, str):
                try:
                    # exclusive: a second irring on the port read the other's IRSCN as its
                    # own (the device's replies go to whoever reads first), mapped unwarned
                    self._port = self.opener(self._port_arg, baudrate=self.baudrate,
                                             timeout=self.poll_s, write_timeout=self.timeout_s,
                                             exclusive=True)
                except (serial.SerialException, OSError, ValueError) as exc:
                    network = self._port_arg.lower().startswith(
                        tuple(f"{s}://" for s in core.NETWORK_URL_SCHEMES))
                    advice = ("that the ring's server listens at that host and port, or start "
                              "the emulator: irring emulate t_room --tcp PORT" if network else
                              "the device path (ls /dev/ttyUSB* /dev/ttyACM*), that you may "
                              "use it (group dialout), or start the emulator: irring emulate "
                              "t_room (then --port ring.pty)")
                    why = _open_failure(exc)
                    if why == PORT_LOCKED:
                        advice = "which program has it (fuser, lsof) and run this when it is done"
                    raise DeviceError(f"cannot open {self._port_arg}: {why}. "
                                      f"Check {advice}") from exc
                self._boot_window = self.boot_s if self.boot_s is not None else \
                    BOOT_S if _may_reset(self._port_arg) else 0.0
            else:
                self._port = self._port_arg
                if not self._port.is_open:
                    self._port.open()
                self._port.timeout = self.poll_s
                self._boot_window = self.boot_s or 0.0
            self._boot_until = time.monotonic() + self._boot_window
            self._flush()
        if handshake:
            self.hello()
        return self

    def close(self) -> None:
        """Stop a sweep or move still running (IRSTP; at rest the same asks whether the
        board reset), turn the ring back to step 0 (IRGTO,0), close the port. :attr:`park_failure` says why the ring was not turned
        back and where it stands (None: it was, or need not be; not tried after a lost link,
        a reboot or another ring). A Ctrl-C (or SIGTERM raised as one) meanwhile does not cut
        the waits short (IRSTP does not stop an IRGTO: the ring turns on to step 0) and is
        not raised; :attr:`close_interrupted` says it came. Why: docs/protocol.md."""
        if self._port is not None:
            try:
                self._park()
            finally:
                try:
                    self._port.close()
                except (serial.SerialException, OSError):
                    pass
                self._port = None

    def _park(self) -> None:
        """IRSTP if a sweep or move may still run, then IRGTO,0 if the motor may stand
        elsewhere; not counted in :attr:`stats`; a failure is said in
        :attr:`park_failure`."""
        self.park_failure = None
        self._woke_at_close, self._woke_at_rest = False, None
        if self.info is None or self._link_dead or not (self._running or self._moved):
            return
        counted = dataclasses.replace(self.stats)
        why = None
        try:
            # noted, not raised: one landing between IRGTO,0 sent and the wait for its IRPOS
            # gave up on a ring that turned on to step 0
            with interrupts_noted(self._note_interrupt):
                why = self._turn_back()
        except KeyboardInterrupt:   # raised by other code than a signal's handler (a port's)
            self.close_interrupted = True
            why = "interrupted"
        except DeviceError as exc:
            why = str(exc)
        finally:
            self.stats = counted
        if why is not None:
            self.stands_at = None
            send = (" (its step 0 is where it woke, so no IRGTO can), then reset the board"
                    if self._woke_at_close else
                    f", or send {p.encode(p.GoTo(-self._woke_at_rest)).decode().strip()} ("
                    f"radial is its step {-self._woke_at_rest} now), then reset the board"
                    if self._woke_at_rest is not None else
                    f", or send {p.encode(p.GoTo(0)).decode().strip()}")
            self.park_failure = (
                f"the ring on {self.port_name} was not turned back to step 0 at the end of the "
                f"session ({why}). Its firmware takes the step it stands at when it starts for "
                f"step 0, and an Arduino restarts each time its port is opened: turn the ring "
                f"radial by hand{send}, before the next session")
            log.warning("%s", self.park_failure)

    def _turn_back(self) -> str | None:
        """The park's exchanges: None when the ring stands at step 0, else why not and
        where it stands."""
        heard = ("where it stands is not known" if self._heard is None
                 else f"it was last heard of at step {self._heard}")
        # IRSTP abandons the step in progress: a stopped sweep may stand one step on
        past = " or the sweep's step after it" if self._running and self._heard else ""
        if self._running:
            if not self._stop_sent:
                self._send(p.Stop())
            done = self._await_through((p.Done,), self.timeout_s)
            if done is None:
                return (f"no IRDON answered IRSTP within {self.timeout_s:g} s, so it may "
                        f"still turn; {heard}")
            self._running = False
            self._said_booted(done.seq, None, None)
        elif self._moved and not self._position_lost and self._woke is None \
                and self._clock is not None and self._position not in (None, 0):
            # at rest away from step 0, IRSCN taken: IRSTP asks for the last seq sent since
            # power-up, whose -1 is a board that reset at rest (IRPOS,0 would come at once)
            self._send(p.Stop())
            done = self._await_through((p.Done,), self.timeout_s)
            self._stop_sent = False
            if done is not None:
                self._said_booted(done.seq, self._position, self._position)
        if self._woke not in (None, (0, 0)) and not self._position_lost \
                and self.stats.scans == self._woke_scans:
            # IRDON -1 (none sent since power-up) after IRSCN came, and none since to tell by
            # its clock: it reset, and IRGTO,0 would turn it to where it woke
            self._position_lost = self._woke_at_close = True
            a, b = self._woke
            if a is not None and a == b:   # at rest: its step 0 is where it stood
                self._woke_at_close, self._woke_at_rest = False, a
                return (f"an IRSTP at rest was answered IRDON -1, no IRSCN sent since it "
                        f"powered up, though {self.stats.scans} came this session: it "
                        f"rebooted at rest at step {a}, and its firmware took that step for "
                        f"step 0")
            return (f"an IRSTP was answered IRDON -1, no IRSCN sent since it powered up, "
                    f"though {self.stats.scans} came this session: it rebooted, and its "
                    f"firmware took the step it woke at for step 0; {heard}")
        if not self._moved or self._position_lost:
            return None
        # if the move did not end, it stands between where it started and step 0
        between = ("where it stands is not known" if self._heard is None else
                   f"it stands between step {self._heard}{past} and step 0" if self._heard
                   else "it stands at step 0 or one step from it")
        self._send(p.GoTo(0))
        wait_s = self.timeout_s + (self.info.max_step - self.info.min_step) * MOVE_ALLOWANCE_S
        msg = self._await_through((p.Position, p.ErrorReply), wait_s)
        if isinstance(msg, p.Position) and msg.step == 0:
            self._running = self._moved = False
            self._position = self._heard = self.stands_at = 0
            return None
        if msg is None and self._clock is not None:
            # still turning, hung, or reset as it turned: IRSTP (answered at any time, a move
            # not stopped) gets IRDON -1 from a board that woke on the way
            self._send(p.Stop())
            done = self._await_through((p.Done,), self.timeout_s)
            self._stop_sent = False
            if done is not None and done.seq < 0:
                self._position_lost = self._woke_at_close = True
                return (f"no IRPOS answered IRGTO,0 within {wait_s:g} s, and an IRSTP then was "
                        f"answered IRDON -1, no IRSCN sent since it powered up, though "
                        f"{self.stats.scans} came this session: it rebooted as it turned back, "
                        f"and its firmware took the step it woke at for step 0; {between}")
        return (f"no IRPOS answered IRGTO,0 within {wait_s:g} s: {between}" if msg is None
                else f"it answered IRGTO,0 with {p.encode(msg).decode().strip()}: {between}")

    def _note_interrupt(self) -> None:
        self.close_interrupted = True

    def _await_through(self, kinds: tuple[type, ...], wait_s: float) -> p.AnyMessage | None:
        """:meth:`_await`, which a KeyboardInterrupt does not cut short: the ring turns on
        whatever is sent, and only its answer tells where it stands; noted in
        :attr:`close_interrupted`."""
        deadline = time.monotonic() + wait_s
        while True:
            try:
                return self._await(kinds, max(0.0, deadline - time.monotonic()))
            except KeyboardInterrupt:
                self.close_interrupted = True

    def __enter__(self) -> SerialRing:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def port(self) -> serial.SerialBase:
        if self._port is None:
            raise DeviceError("the port is not open; call open() or use `with SerialRing(...)`")
        return self._port

    # ---------------------------------------------------------------- I/O

    def _flush(self, check_ring: bool = False) -> None:
        """Drop what arrived unasked (late answers, a stopped sweep's tail); with
        ``check_ring``, an IRINF among it announcing another ring is :class:`DeviceChanged`,
        as it is mid-sweep (it was dropped without a word between sweeps)."""
        stale = bytearray()
        try:
            while check_ring and len(stale) < CHATTER_LIMIT_BYTES:   # a flood: the rest dropped
                waiting = self.port.in_waiting   # (a socket:// port says 1 while any wait)
                chunk = self.port.read(waiting) if waiting else b""
                if not chunk:
                    break
                stale += chunk
            self.port.reset_input_buffer()
        except (serial.SerialException, OSError) as exc:
            raise self._lost(DeviceDisconnected, f"flushing failed: {exc}") from exc
        told = [m for m in self.decoder.feed(bytes(stale)) if isinstance(m, p.Info)]
        self.decoder.reset()
        for info in told if self.info is not None else ():
            self._same_ring(info)

    @property
    def moved(self) -> bool:
        """Whether the ring may stand away from step 0: a sweep or move was sent this session
        (or the handshake stopped an earlier session's sweep) and not turned back since."""
        return self._moved

    @property
    def protocol(self) -> int:
        """The IRR protocol version this link speaks (2, or 1 with ``accept_v1``)."""
        return self.decoder.version

    def _send(self, msg: p.Message) -> None:
        line = p.encode(msg, version=self.decoder.version)
        log.debug("host → %r", line)
        if isinstance(msg, (p.SweepCommand, p.GoTo)):
            self._running = self._moved = True
        self._stop_sent = isinstance(msg, p.Stop)
        try:
            self.port.write(line)
        except serial.SerialTimeoutException as exc:
            self.stats.timeouts += 1
            raise self._lost(DeviceTimeout, f"could not send {msg.TYPE} within "
                                            f"{self.timeout_s:g} s (flow control?)") from exc
        except (serial.SerialException, OSError) as exc:
            raise self._lost(DeviceDisconnected, str(exc)) from exc

    def _receive(self) -> list[p.AnyMessage]:
        """Whatever arrives within one poll interval, decoded; rejections are counted."""
        try:
            waiting = self.port.in_waiting
            chunk = self.port.read(waiting if waiting else 1)
        except (serial.SerialException, OSError) as exc:
            raise self._lost(DeviceDisconnected, str(exc)) from exc
        if not chunk:
            return []
        self._rx_bytes += len(chunk)
        self._not_ascii += len(chunk.translate(None, _SENTENCE_BYTES))
        before = self.decoder.ignored_bytes
        out = []
        for item in self.decoder.feed(chunk):
            if isinstance(item, p.ProtocolError):
                if item.fault is p.Fault.CHECKSUM_MISMATCH:
                    self.stats.checksum_failures += 1
                else:
                    self._other_framing += item.fault is p.Fault.OTHER_VERSION
                    self.stats.malformed += 1
                    if self._garbled is None:   # named in the sweep's report
                        self._garbled = str(item)
                    if item.raw.startswith(b"$IRINF") and item.fault in _FIELD_FAULTS:
                        self._refused_info = item   # its check field matched: not noise
                if item.raw.startswith(b"$IRINF") and len(self._misframed_info) < 16:
                    self._misframed_info.append(item.raw)   # (cleared by each hello)
                log.debug("dropped: %s", item)
            else:
                self.stats.sentences += 1
                log.debug("device → %r", item)
                out.append(item)
        self.stats.ignored_bytes += self.decoder.ignored_bytes - before
        return out

    def _lost(self, cls: type[LinkLost], what: str, lost_scans: int = 0) -> LinkLost:
        """The error for a lost link; sweep() attaches the partial sweep and report.
        ``lost_scans``: IRSCN this sweep lost before the device fell silent, which blames
        the link (a board that hangs loses nothing on the way first)."""
        if cls in (DeviceDisconnected, DeviceTimeout):
            self._link_dead = True   # nothing more to ask of it (close() parks no ring)
        if cls is DeviceDisconnected:
            self.stats.disconnects += 1
            msg = (f"ring on {self.port_name} disconnected ({what}). Check the cable and power; "
                   f"if you use the emulator, is `irring emulate` still running?")
        elif lost_scans:
            msg = (f"ring on {self.port_name} stopped answering ({what}), though this sweep "
                   f"lost {lost_scans} IRSCN on the way (their seq numbers skipped): a link "
                   "that drops sentences drops answers too. Check the cable, its connectors "
                   f"and noise near it, and the baud rate ({self.baudrate}); reset the board "
                   "if it hangs.")
        else:
            msg = (f"ring on {self.port_name} stopped answering ({what}). Check power, cable "
                   f"and baud rate ({self.baudrate}); reset the board if it hangs.")
        return cls(msg)

    # ---------------------------------------------------------------- handshake

    def hello(self) -> p.Info:
        """IRHLO → IRINF: learn the ring's geometry and protocol version; sets :attr:`info`
        and :attr:`ring`. A device answering in v1 framing is asked again in v1 (an old
        board answers a v2 IRHLO with a v1 IRERR 1) and refused unless ``accept_v1``."""
        tries = self.retries + 1
        refusals: list[p.ErrorReply] = []
        self._refused_info = None
        self._misframed_info = []
        every_refused = True
        echoes = 0   # our own IRHLO heard back
        heard = self.stats.sentences + self.stats.checksum_failures + self.stats.malformed
        boot_hellos = 0   # IRHLO sent again while a board just opened may be starting
        for attempt in range(tries):
            if attempt:
                self.stats.resent_commands += 1
            self._send(p.Hello())
            start = time.monotonic()
            deadline = start + self.timeout_s
            booting = attempt == 0 and start < self._boot_until
            if booting:   # its bootloader may take this IRHLO: say it again while all is quiet
                deadline = max(deadline, self._boot_until)
                again, quiet = start + BOOT_RESEND_S, self._rx_bytes
            refused = probed = False
            framed_before = self._other_framing
            while not refused and time.monotonic() < deadline:
                if booting and self._rx_bytes != quiet:
                    # it talks (a boot message, a stray byte as it starts): not an answer,
                    # and no reason to stop greeting it; again once it has been quiet a while
                    quiet, again = self._rx_bytes, time.monotonic() + BOOT_RESEND_S
                elif booting and time.monotonic() >= again:
                    self._send(p.Hello())
                    boot_hellos += 1
                    again = time.monotonic() + BOOT_RESEND_S
                if self._other_framing > framed_before and self.decoder.version != 1:
                    info, probed = self._hello_v1(), True
                    if info is not None:
                        return self._accept_info(info)
                    break   # garbled, or a v2 device after all: no answer, say hello again
                for msg in self._receive():
                    if isinstance(msg, p.Info):
                        return self._accept_info(msg)
                    echoes += isinstance(msg, p.Hello)
                    if isinstance(msg, p.ErrorReply):
                        # IRERR 1/2: our IRHLO was garbled; 5: a sweep still runs, stop it
                        self.stats.device_errors += 1
                        refusals.append(msg)
                        if msg.code == p.ERR_BUSY:
                            # an earlier session's sweep turned it away; known before the
                            # IRSTP goes, so a Ctrl-C as it is sent cannot lose it
                            self._moved = True
                            self._send(p.Stop())
                        refused = True
            if not refused:
                self.stats.timeouts += not probed   # a probe that timed out counted itself
                every_refused = False
        if every_refused:   # a working link to a device that will not say hello
            last = refusals[-1]
            raise HandshakeError(
                f"the device on {self.port_name} answered each of {tries} IRHLO with IRERR "
                f"{last.code} ({last.text or p.ERROR_TEXT.get(last.code, '?')}), never IRINF: "
                + ("its firmware does not know IRHLO; it needs IRR protocol "
                   f"v{p.PROTOCOL_VERSION} firmware" if last.code == p.ERR_UNKNOWN_TYPE else
                   f"it cannot read what this host sends; check the baud rate ({self.baudrate}) "
                   "and the cable" if last.code == p.ERR_BAD_SENTENCE else "reset the board"))
        if self._refused_info is not None:   # was 'no IRINF answer … a loose cable'
            bad = self._refused_info
            raise HandshakeError(
                f"the device on {self.port_name} answers IRHLO with an IRINF that IRR protocol "
                f"v{self.decoder.version} does not allow ({bad.detail}): "
                f"{printable(bad.raw.decode('ascii', 'replace').strip())}; no ring has that, so "
                f"its IRINF is not trusted")
        mistakes = [p.misframing(raw, self.decoder.version) for raw in self._misframed_info]
        habit = next((m for m in mistakes if m is not None and mistakes.count(m) >= 2), None)
        if habit is not None:   # the same mistake twice or more: the firmware's, not noise
            raw = self._misframed_info[mistakes.index(habit)]
            raise HandshakeError(
                f"the device on {self.port_name} answers each IRHLO with an IRINF framed "
                f"otherwise than IRR protocol v{self.decoder.version} asks, the same way each "
                f"time (not line noise): {habit}: "
                f"{printable(raw.decode('ascii', 'replace').strip())}. Fix the firmware's "
                f"framing (docs/protocol.md, \"The CRC\": the CRC of the nine bytes "
                f"123456789 is 0x{p.CRC16_CHECK:04X})")
        if echoes and echoes == (self.stats.sentences + self.stats.checksum_failures
                                 + self.stats.malformed - heard):   # nothing but our own
            raise HandshakeError(
                f"no IRINF answer from {self.port_name} to {tries} IRHLO of {self.timeout_s:g} "
                f"s each, only this host's own IRHLO sent back ({echoes} times): the port "
                f"echoes what it is sent (loop://, a loopback plug, an adapter or terminal that "
                f"echoes). Check that it is the ring's port and that the ring is powered")
        booted = (f" (and {boot_hellos} more in the first {self._boot_window:g} s after "
                  "opening the port, while a board that restarts when its port opens would "
                  "be starting)" if boot_hellos else "")
        raise HandshakeError(
            f"no IRINF answer from {self.port_name} to {tries} IRHLO of {self.timeout_s:g} s "
            f"each{booted}. Check the port, the baud rate ({self.baudrate}), that the ring is "
            f"powered and runs IRR protocol v{p.PROTOCOL_VERSION} firmware (firmware/README.md) "
            f"({self.stats.checksum_failures} checksum failures, {self.stats.malformed} "
            f"malformed sentences, {self.stats.ignored_bytes} stray bytes seen)."
            + (" Sentences that arrive garbled point at line noise or a loose cable."
               if self.stats.checksum_failures + self.stats.malformed else "")
            + (f" {self._not_ascii} of the {self._rx_bytes} bytes that came are not printable "
               "ASCII, which an IRR sentence never holds: the mark of a device at another baud rate "
               "than this port's; try the ring's with --baud"
               if self._not_ascii * 2 > self._rx_bytes >= MISMATCH_MIN_BYTES else ""))

    def _hello_v1(self) -> p.Info | None:
        """IRHLO in v1 framing, after v1-framed sentences answered a v2 one: the IRINF of
        an old (v1) device, or None (no v1 answer, or a v2 device: the link goes on in v2)."""
        self.decoder.version = 1
        self._send(p.Hello())
        msg = self._await((p.Info,), self.timeout_s)
        if isinstance(msg, p.Info) and msg.proto == 1:
            return msg   # the decoder stays at v1 if it is accepted
        self.decoder.version = p.PROTOCOL_VERSION
        return None

    def _accept_info(self, info: p.Info) -> p.Info:
        # a new session: its clock and numbering are new
        self._clock = self._clock_at = self._woke = None
        self._link_dead = False
        self._lost_sweep = None
        if info.proto == 1 and self.decoder.version == 1:
            what = (f"the device on {self.port_name} runs IRR protocol v1 firmware "
                    f"({info.firmware}), whose 8-bit XOR checksum lets two bit errors in one "
                    f"bit column through as changed readings; this irring speaks "
                    f"v{p.PROTOCOL_VERSION} (a CRC-16)")
            if not self.accept_v1:
                raise HandshakeError(
                    f"{what}. Reflash the ring with this irring's firmware (firmware/README.md:"
                    f" make -C firmware avr flash PORT={self.port_name}), or accept v1 for now "
                    f"(irring drive/calibrate --accept-protocol-v1, SerialRing(accept_v1=True))")
            self.protocol_warning = (f"{what}; speaking v1 as asked (--accept-protocol-v1): "
                                     f"reflash it (firmware/README.md) to have every sentence "
                                     f"CRC-checked")
            log.warning("%s", self.protocol_warning)
        elif info.proto != self.decoder.version:
            raise HandshakeError(f"the device on {self.port_name} speaks IRR protocol "
                                 f"v{info.proto}; this irring speaks v{p.PROTOCOL_VERSION} "
                                 f"(and v1 to an old board): "
                                 + ("update irring" if info.proto > p.PROTOCOL_VERSION else
                                    "its IRINF contradicts its own framing"))
        # sizes the host allocates by, and angles it maps by: refuse what no ring has
        # before trusting them (Ring's bounds, one home with the scenario schema)
        for fault in _info_faults(info):
            raise HandshakeError(f"the device on {self.port_name} announces {fault}; no ring "
                                 f"has that, so its IRINF is not trusted")
        # a reading whose IRSCN is too long is dropped as malformed: only the near ones (large
        # counts, more digits) would be lost, and the map drawn from the far ones (exit 0)
        if (too_long := p.scan_too_long(info)) is not None:
            raise HandshakeError(f"the device on {self.port_name} announces a ring whose "
                                 f"readings do not fit the protocol's sentences: {too_long}")
        self.info = info
        self.ring = p.ring_from_info(info, self.template, radius_m=self.radius_m,
                                     emitter_offset_m=self.emitter_offset_m)
        log.info("ring %s: %d sensors, %d-bit ADC, %.3f° motor step × %d/%d, steps %d … %d",
                 info.firmware, info.nsensors, info.adc_bits, info.step_mdeg / 1000,
                 info.gear_num, info.gear_den, info.min_step, info.max_step)
        return info

    def _require_info(self) -> p.Info:
        if self.info is None:
            raise DeviceError("no handshake yet: call open() (or hello()) before sweeping")
        return self.info

    # ---------------------------------------------------------------- motion

    def goto(self, step: int) -> int:
        """Move to motor ``step``; returns the step the device reports (IRPOS)."""
        info = self._require_info()
        if not info.min_step <= step <= info.max_step:
            raise ValueError(f"step {step} is outside the ring's {info.min_step} … "
                             f"{info.max_step}")
        for _ in range(self.retries + 1):
            self._send(p.GoTo(int(step)))
            msg = self._await((p.Position, p.ErrorReply), self.timeout_s)
            if isinstance(msg, p.Position):
                self._position = self._heard = self.stands_at = msg.step
                self._running, self._moved = False, msg.step != 0
                return msg.step
            if isinstance(msg, p.ErrorReply):
                self._raise_rejected(msg, f"IRGTO,{step}")
            self.stats.resent_commands += 1
        raise self._lost(DeviceTimeout, f"no IRPOS within {self.timeout_s:g} s after IRGTO")

    def stop(self) -> int | None:
        """Stop a sweep in progress; returns the device's last IRSCN seq (None: no answer)."""
        for _ in range(self.retries + 1):
            self._send(p.Stop())
            msg = self._await((p.Done,), self.timeout_s)
            if isinstance(msg, p.Done):
                self._last_seq = msg.seq if msg.seq >= 0 else None   # -1: (re)booted
                self._said_booted(msg.seq, self._position, self._position)
                self._running = False
                return msg.seq
        return None

    def _same_ring(self, info: p.Info) -> None:
        """An IRINF after the handshake: a late answer if it equals the handshake's, else
        :class:`DeviceChanged` (the board was reflashed or swapped)."""
        if info != self.info:
            self._position_lost = True   # not the ring whose steps this session counted
            raise DeviceChanged(
                f"the device on {self.port_name} now announces another ring: "
                f"{_ring_text(info)}, where the handshake said {_ring_text(self.info)}; "
                f"it was reflashed or swapped; connect again to read the new one.")

    def _await(self, kinds: tuple[type, ...], wait_s: float) -> p.AnyMessage | None:
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            for msg in self._receive():
                if isinstance(msg, p.Info) and self.info is not None:
                    self._same_ring(msg)
                if isinstance(msg, p.ErrorReply):
                    self.stats.device_errors += 1
                    if msg.code in (p.ERR_BAD_SENTENCE, p.ERR_BUSY) and p.ErrorReply not in kinds:
                        return None  # our command was garbled or refused: resend
                if isinstance(msg, kinds):
                    return msg
        self.stats.timeouts += 1
        return None

    def _raise_rejected(self, msg: p.ErrorReply, command: str) -> None:
        if msg.code in (p.ERR_BAD_SENTENCE, p.ERR_BUSY):
            return  # retried by the caller
        raise DeviceRejected(f"the ring rejected {command}: IRERR {msg.code} "
                             f"({msg.text or p.ERROR_TEXT.get(msg.code, '?')})", msg.code,
                             msg.text)

    # ---------------------------------------------------------------- sweeping

    def full_range(self) -> np.ndarray:
        info = self._require_info()
        return np.arange(info.min_step, info.max_step + 1)

    def sweep(self, pose: Any = (0.0, 0.0, 0.0), *, steps: Iterable[int] | None = None,
              samples: int | None = None, settle_s: float | None = None,
              resweep: int | None = None) -> core.Sweep:
        """Sweep the ring and return a :class:`core.Sweep` of the readings that arrived.

        pose: where the robot stands, (x m, y m, yaw rad) or a scenario ``Pose``; the ring
            cannot know it, so it is stored in the Sweep as given.
        steps: motor steps to read, in order (default: min_step … max_step from IRINF).
            Consecutive steps go out as one IRSWP; other steps as one IRSWP each.
        samples, settle_s, resweep: this sweep's, instead of the ring's settings
            (readings averaged per step, 1–64; wait at each step, sent as whole ms; rounds of
            re-sweeping only the steps still missing).

        Missing steps are absent from ``counts`` and listed in ``missing_steps``;
        :attr:`last_report` says why. Raises :class:`DeviceTimeout` /
        :class:`DeviceDisconnected` (with ``.partial``) if the device goes away; after any
        :class:`LinkLost` out of a sweep, a :class:`DeviceError` until :meth:`hello`.
        """
        info = self._require_info()
        if self._lost_sweep is not None:
            then = ("Turn the ring back to radial and reset the board as that error said, then "
                    "handshake" if self._lost_sweep == "device rebooted" else "Handshake")
            raise DeviceError(
                f"the last sweep on {self.port_name} ended with the {self._lost_sweep}: the "
                "ring's step and the device's IRSCN numbering are no longer this session's, so "
                f"what it reads now could be placed at the wrong steps. {then} again "
                "(ring.hello(), or close this SerialRing and open a new one) before sweeping")
        # (1.5 was read as step 1)
        req = [int(s) for s in (self.full_range() if steps is None else
                                core.check_steps(steps, info.min_step, info.max_step))]
        samples = self.samples if samples is None else samples
        settle_s = self.settle_s if settle_s is None else settle_s
        resweep = self.resweep if resweep is None else resweep
        _check_settings(samples, settle_s, resweep)
        settle_ms = int(round(settle_s * 1000))
        pose_arr = core.as_pose(pose)
        started = time.monotonic()
        before = self._sweep_before = self.stats.as_dict()
        self._dropped = self._garbled = None
        passes: list[_Pass] = []

        def build(complete: bool, reason: str) -> tuple[core.Sweep, SweepReport]:
            sweep = self._assemble(req, passes, samples, settle_ms, pose_arr)
            self._previous = {step: scan for ps in passes for step, scan in ps.got.items()}
            report = self._report(req, sweep, before, complete, started, reason)
            self.last_report = report
            return sweep, report

        try:
            for run in _runs(req):
                passes.append(_Pass(run))
                self._pass(passes[-1], samples, settle_ms)
            for _ in range(int(resweep)):
                got = {s for ps in passes for s in ps.got}
                missing = [s for s in req if s not in got]
                if not missing:
                    break
                self.stats.resweeps += 1
                log.info("re-sweeping %d missing steps", len(missing))
                for run in _runs(missing):
                    passes.append(_Pass(run))
                    self._pass(passes[-1], samples, settle_ms)
            scans = [scan for ps in passes for scan in ps.got.values()]
            if self._replayed(scans):
                for ps in passes:
                    ps.got.clear()   # not taken: the partial sweep holds none of them
                self.stats.scans -= len(scans)
                self.stats.stale += len(scans)   # readings of the last sweep, again
                raise self._replay_error(scans, req)
        except (LinkLost, DeviceRejected, KeyboardInterrupt) as exc:
            # what arrived before the failure (or Ctrl-C) goes with the exception: a caller
            # keeps it (pipeline.acquire) instead of losing the readings
            self._last_seq = None  # the device may still be numbering IRSCN we never saw
            self._owed = None
            self._position = None
            reason = ("device stopped answering" if isinstance(exc, DeviceTimeout) else
                      "device disconnected" if isinstance(exc, DeviceDisconnected) else
                      "device changed" if isinstance(exc, DeviceChanged) else
                      "device replayed its last sweep" if isinstance(exc, DeviceReplayed) else
                      "device rebooted" if isinstance(exc, DeviceRebooted) else
                      "device refused" if isinstance(exc, DeviceRejected) else "interrupted")
            if isinstance(exc, LinkLost):
                self._lost_sweep = reason
            sweep, report = build(False, reason)
            exc.partial, exc.report = sweep, report
            if isinstance(exc, KeyboardInterrupt):
                # the ring would turn on to the sweep's end: one IRSTP, not waited for
                try:
                    self._send(p.Stop())   # (close() waits for its IRDON)
                except DeviceError:
                    pass
            else:
                exc.args = (f"{exc} {report.message}",)
            raise
        sweep, report = build(all(ps.done for ps in passes), "")
        if not len(sweep.steps):
            raise NoReadings(f"the ring on {self.port_name} ended the sweep but no step of it "
                             f"arrived intact: {report.message}", sweep, report)
        if sweep.missing_steps:
            log.info("%s", report.message)
        return sweep

    def _pass(self, ps: _Pass, samples: int, settle_ms: int) -> None:
        """One IRSWP over ``ps.run``, filling ``ps`` as IRSCN arrive (so a LinkLost raised
        here still leaves what arrived); losses are counted, not raised."""
        info = self._require_info()
        lo, hi = ps.run
        pos_of = ps.index
        # The device numbers IRSCN globally. `hint` (last IRDON + 1) only unmasks stale
        # IRSCN; `base` (the seq of this pass's first step) comes from the first IRSCN.
        hint = None if self._last_seq is None else (self._last_seq + 1) % p.SEQ_MODULO
        base: int | None = None
        last_seq: int | None = None
        max_count = (1 << info.adc_bits) - 1
        per_step_s = core.hardware_duration_s(1, settle_ms / 1000, samples)
        # the first IRSCN may need a move to `lo` first (allow 5 ms per motor step), or to
        # `hi` on a device that sweeps the other way
        travel = (info.max_step - info.min_step if self._position is None
                  else max(abs(lo - self._position), abs(hi - self._position)))
        first_wait = self.timeout_s + per_step_s + travel * MOVE_ALLOWANCE_S
        cmd = p.SweepCommand(lo, hi, samples, settle_ms)
        self._flush(check_ring=True)
        self._send(cmd)
        wait_s = first_wait        # the silence allowed now (no byte arriving)
        deadline = time.monotonic() + wait_s
        stops = resends = 0
        # Silence is no byte for wait_s: bytes move the deadline, so a noisy link that talks
        # is not stopped. A device that talks without progress (garbage, repeated IRSCN,
        # endless IRPOS) is stopped like a silent one after CHATTER_LIMIT_BYTES.
        chatter = 0                # bytes since the last new step or IRSTP
        stalled_since = time.monotonic()
        # past the retries + 1 IRSTP a silent device gets (each a timeout), so this net
        # catches only a device that talks on without progress, never cuts the retries short
        stall_limit = first_wait + (self.retries + NO_PROGRESS_TIMEOUTS) * (self.timeout_s
                                                                            + per_step_s)
        ps.max_step_s = stall_limit
        heard = False   # a garbled sentence arrived since the last IRSTP: the device answers
        framed, accepted = self._other_framing, self.stats.sentences
        suspects: list[p.Scan] = []   # IRSCN numbered before `hint`: stale, or a renumbering
        heard_at: dict[int, float] = {}   # when each suspect arrived, by id
        contradicted: set[int] = set()   # steps read twice with other counts in this pass
        # A device sweeps from → to. One whose IRSCN come to → from, each naming its step,
        # is read as it swept: the step places the reading, the seq only runs the other way.
        # The first IRSCN kept guesses the direction; a second one (or the IRDON) settles it.
        first: p.Scan | None = None
        settled = len(pos_of) == 1

        def settle(reverse: bool) -> None:
            nonlocal base, settled
            settled = True
            if reverse != ps.reversed:   # `first` alone was misread: place it anew
                pos = pos_of[first.step]
                old, new = ps.sent_at(pos), ps.sent_at(pos, reverse)
                base = (first.seq - new) % p.SEQ_MODULO
                self.stats.lost_scans += new - old
                self.stats.seq_gaps += (new > 0) - (old > 0)
                ps.reversed = reverse
            self.stats.reversed_passes += reverse

        def alone() -> bool:
            """Only `first` is kept and the direction is not settled yet."""
            return not settled and len(ps.got) == 1 and first is not None \
                and first.step in ps.got

        def take(msg: p.Scan, at: float) -> None:
            """Keep one IRSCN of this pass (arrived at ``at``, time.monotonic()), counting
            gaps, duplicates and contradictions."""
            nonlocal base, last_seq, first
            pos = pos_of.get(msg.step)
            if pos is None:
                self._inconsistent(f"IRSCN {msg.seq} is of step {msg.step}, outside "
                                   f"IRSWP,{lo},{hi}")
                return
            if base is None:
                if not settled:   # its first IRSCN: the pass's last step if swept reversed
                    ps.reversed = pos == len(pos_of) - 1
                base = (msg.seq - ps.sent_at(pos)) % p.SEQ_MODULO
            elif (msg.seq - base) % p.SEQ_MODULO != ps.sent_at(pos):
                flip = not ps.reversed
                if not (alone() and msg.step != first.step
                        and (msg.seq - first.seq) % p.SEQ_MODULO
                        == (ps.sent_at(pos, flip) - ps.sent_at(pos_of[first.step], flip))
                        % p.SEQ_MODULO):
                    self._inconsistent(f"IRSCN {msg.seq} is of step {msg.step}, which this "
                                       f"pass numbers {(base + ps.sent_at(pos)) % p.SEQ_MODULO}")
                    return
                settle(flip)
            elif alone() and msg.step != first.step:
                settle(ps.reversed)
            if msg.step in contradicted:
                self._inconsistent(f"step {msg.step} came again after two IRSCN with other "
                                   f"counts")
                return
            if msg.step in ps.got:
                if ps.got[msg.step].counts == msg.counts:
                    self.stats.duplicates += 1   # a resend: the same reading
                    return
                # the same IRSCN with other readings, both intact: which is right is not
                # known, so neither is kept (the step is missing, re-swept)
                del ps.got[msg.step]
                contradicted.add(msg.step)
                self.stats.scans -= 1
                self._inconsistent(f"IRSCN {msg.seq} of step {msg.step} came twice with other "
                                   f"counts", 2)
                return
            if self._woke is not None and self._restarted(msg, at):
                stood, self._woke = self._woke, None
                if stood != (0, 0):
                    raise self._rebooted(msg, at, stood, "IRDON -1 (no IRSCN sent since "
                                         "power-up) ended a sweep after IRSCN had come")
                self._clock = None   # woken at step 0: its steps are right, its clock new
            gap = (msg.seq - (base - 1 if last_seq is None else last_seq) - 1) % p.SEQ_MODULO
            if gap >= p.SEQ_MODULO // 2:
                # an earlier IRSCN, late: the gap its seq left counted it lost, but it came
                self.stats.out_of_order += 1
                self.stats.lost_scans -= self.stats.lost_scans > 0
            else:
                if gap:
                    self.stats.seq_gaps += 1
                    self.stats.lost_scans += gap
                last_seq = msg.seq
            self._position = self._heard = msg.step
            self.stands_at = None   # turning
            if self._clock is None or not self._went_back(msg):
                self._clock, self._clock_at = msg.t_ms, at
            ps.got[msg.step] = msg
            if first is None:
                first = msg
            self.stats.scans += 1

        while True:
            had = len(ps.got)
            garbled = self.stats.checksum_failures + self.stats.malformed
            rx = self._rx_bytes
            msgs = self._receive()
            now = time.monotonic()
            if self._rx_bytes > rx:
                chatter += self._rx_bytes - rx
                deadline = max(deadline, now + wait_s)
            if stops and self.stats.checksum_failures + self.stats.malformed > garbled:
                heard = True
                deadline = min(deadline, now + min(self.timeout_s, GARBLED_ANSWER_RETRY_S))
            if now - stalled_since > stall_limit:
                raise self._given_up(
                    framed, accepted,
                    f"no progress for {now - stalled_since:.1f} s during IRSWP,{lo},{hi}: "
                    f"{len(ps.got)} of {len(ps.expected)} steps arrived, "
                    f"{self.stats.sentences} sentences in all")
            for i, msg in enumerate(msgs):
                if isinstance(msg, p.Scan):
                    if len(msg.counts) != info.nsensors:
                        self._inconsistent(f"IRSCN {msg.seq} of step {msg.step} carries "
                                           f"{len(msg.counts)} counts; the IRINF announced "
                                           f"{info.nsensors} sensors")
                        continue
                    if max(msg.counts) > max_count:
                        self._inconsistent(f"IRSCN {msg.seq} of step {msg.step} has a count of "
                                           f"{max(msg.counts)}, beyond the {info.adc_bits}-bit "
                                           f"ADC's {max_count}")
                        continue
                    if hint is not None and (msg.seq - hint) % p.SEQ_MODULO >= p.SEQ_MODULO // 2:
                        self.stats.stale += 1  # numbered before this pass began
                        suspects.append(msg)
                        heard_at[id(msg)] = now
                        continue
                    if base is None and suspects:
                        # held as stale, yet numbered as this first fresh IRSCN numbers the
                        # pass: the last IRDON said more than the device had sent (a firmware
                        # counting its IRSCN instead of naming the last), since an honest one
                        # numbers every leftover before each step of this pass
                        for scan in _numbered_with(suspects, msg, ps):
                            suspects.remove(scan)
                            self.stats.stale -= 1
                            take(scan, heard_at[id(scan)])
                    take(msg, now)
                elif isinstance(msg, p.Done):
                    reverse = (None if ps.got or self._owed_late(suspects)
                               else _renumbered(suspects, ps, msg.seq))
                    if reverse is not None:
                        # every IRSCN looked stale, but they and this IRDON number this very
                        # pass: the device numbers from elsewhere (it rebooted between sweeps,
                        # or its last IRDON was wrong), so they are this pass's readings
                        back = next((sc for sc in suspects
                                     if self._restarted(sc, heard_at[id(sc)])), None)
                        if back is not None and not self._replayed(suspects):
                            # numbered and clocked anew, with new readings: it rebooted,
                            # at rest where the last pass or move left the ring
                            if self._position != 0:
                                raise self._rebooted(back, heard_at[id(back)],
                                                     (self._position, self._position),
                                                     "its IRSCN are numbered from 0 again")
                            self._clock = None   # woken at step 0: its steps are right
                        log.info("the device renumbered its IRSCN; %d of this pass's "
                                 "readings kept", len(suspects))
                        self.stats.stale -= len(suspects)
                        hint = None
                        ps.reversed = reverse
                        if len(suspects) > 1:
                            settle(reverse)
                        for scan in suspects:
                            take(scan, heard_at[id(scan)])
                        suspects.clear()
                    if (not stops and not ps.got and hint is not None
                            and msg.seq == (hint - 1) % p.SEQ_MODULO):
                        # reports nothing new and we did not ask to stop: the late answer
                        # to an earlier IRSTP, not the end of this sweep
                        self.stats.stale += 1
                        continue
                    if base is None:
                        base = hint
                    if alone() and not stops and msg.seq >= 0:
                        # one IRSCN kept: how many the device sent after it tells the way
                        after = (msg.seq - first.seq) % p.SEQ_MODULO
                        pos = pos_of[first.step]
                        if after in (pos, len(pos_of) - 1 - pos) and 2 * pos != len(pos_of) - 1:
                            settle(after == pos)
                    if msg.seq >= 0 and base is not None:
                        ahead = (msg.seq - (base - 1 if last_seq is None else last_seq)) \
                            % p.SEQ_MODULO
                        if 0 < ahead < p.SEQ_MODULO // 2:  # IRSCN after the last one we got
                            self.stats.seq_gaps += 1
                            self.stats.lost_scans += ahead
                    # IRDON -1: no IRSCN sent since the device (re)booted; its numbering
                    # starts again at 0, which must not read as stale in the next pass
                    self._last_seq = msg.seq if msg.seq >= 0 else None
                    short = len(pos_of) - len(ps.got)
                    self._owed = (msg.seq, short) if msg.seq >= 0 and short else None
                    self._said_booted(msg.seq, *self._turning(ps))
                    ps.done = True
                    self._running = False
                    for later in msgs[i + 1:]:   # read with the IRDON; the rest is stale
                        if isinstance(later, p.Info):
                            self._same_ring(later)
                    return
                elif isinstance(msg, p.ErrorReply):
                    self.stats.device_errors += 1
                    if msg.code == p.ERR_BUSY or (msg.code == p.ERR_BAD_SENTENCE and not ps.got
                                                  and not stops):
                        if resends >= self.retries:
                            raise DeviceRejected(f"the ring kept refusing "
                                                 f"{p.encode(cmd).decode().strip()}: "
                                                 f"IRERR {msg.code} ({msg.text})", msg.code,
                                                 msg.text)
                        resends += 1
                        self.stats.resent_commands += 1
                        if msg.code == p.ERR_BUSY:
                            self.stop()
                        self._send(cmd)
                    elif msg.code == p.ERR_BAD_SENTENCE and stops:
                        self._send(p.Stop())  # our IRSTP was garbled
                    elif msg.code != p.ERR_BAD_SENTENCE:
                        self._raise_rejected(msg, p.encode(cmd).decode().strip())
                elif isinstance(msg, p.Info):
                    self._same_ring(msg)
                # IRPOS, and IRINF equal to the handshake's, are late answers: ignore
            if len(ps.got) > had:
                stalled_since = now
                chatter = 0
                wait_s = self.timeout_s + per_step_s
                if len(ps.got) == len(pos_of) and not stops:
                    # every IRSCN is in: IRDON follows at once unless it was lost, in which
                    # case IRSTP fetches it sooner than a full timeout would
                    wait_s = min(self.timeout_s, max(0.1, 2 * per_step_s))
                deadline = now + wait_s
            flooded = chatter >= CHATTER_LIMIT_BYTES
            if flooded or now >= deadline:
                # silence, talk without progress, or a garbled answer: ask the device to end
                # the sweep; IRDON tells what it sent
                if flooded or not heard:
                    if not flooded:
                        self.stats.timeouts += 1
                    if stops > self.retries:
                        got = f"{len(ps.got)} of {len(ps.expected)} steps"
                        raise self._given_up(framed, accepted, (
                            f"no progress during IRSWP,{lo},{hi}: {CHATTER_LIMIT_BYTES} bytes "
                            f"arrived without a new step {stops + 1} times, {stops} IRSTP did "
                            f"not end it; {got} arrived") if flooded else (
                            f"no sentence for {self.timeout_s:g} s during IRSWP,{lo},{hi} after "
                            f"{got}; {stops} IRSTP unanswered"))
                    stops += 1
                heard = False
                chatter = 0
                self.stats.resent_commands += 1
                self._send(p.Stop())
                wait_s = self.timeout_s
                deadline = now + wait_s

    def _owed_late(self, scans: list[p.Scan]) -> bool:
        """Whether each of ``scans`` (numbered before the pass) carries a seq the last short
        pass's IRDON said was sent, though it never came: that pass's readings, late (a
        device answering IRSTP before what it had buffered), not a device numbering anew."""
        if self._owed is None:
            return False
        last, short = self._owed
        return all((last - sc.seq) % p.SEQ_MODULO < short for sc in scans)

    def _replayed(self, scans: list[p.Scan]) -> bool:
        """``scans`` (two or more) repeat the last sweep's readings, step for step, device
        clock and counts alike (whatever their seq): a device's clock runs on from sweep to
        sweep, and one that rebooted starts it anew with new readings, so only a firmware
        sending its buffer again repeats both."""
        def reading(scan: p.Scan | None) -> tuple | None:
            return None if scan is None else (scan.t_ms, scan.counts)
        return len(scans) > 1 and all(reading(self._previous.get(sc.step)) == reading(sc)
                                      for sc in scans)

    def _replay_error(self, scans: list[p.Scan], req: list[int]) -> DeviceReplayed:
        clocks = sorted(sc.t_ms for sc in scans)
        return DeviceReplayed(
            f"the ring on {self.port_name} answered the sweep of steps {req[0]} … {req[-1]} "
            f"with its last sweep's readings again: {len(scans)} IRSCN repeat that sweep's "
            f"steps, device clock ({clocks[0]} … {clocks[-1]} ms) and counts, where a new "
            "sweep's clock runs on: a firmware replaying its buffer, not reading the sensors; "
            "not taken. Reset the board and sweep this pose again.")

    def _turning(self, ps: _Pass) -> tuple[int | None, int | None]:
        """Where the ring may stand in pass ``ps``, which an IRDON ends: from the last step
        heard of to the step the device turns to next (the pass's first, if none of it came;
        the last step itself once the pass is whole). A board that resets there takes where
        it stands for step 0."""
        if self._position is None:
            return None, None
        order = [ps.expected[ps.sent_at(i)] for i in range(len(ps.expected))]
        if not ps.got:
            return self._position, order[0]
        at = order.index(self._position) if self._position in order else len(order) - 1
        return self._position, order[min(at + 1, len(order) - 1)]

    def _said_booted(self, done_seq: int, stood: int | None, toward: int | None) -> None:
        """Note an IRDON -1 (none sent since power-up) that came after IRSCN were taken,
        with where the ring stood (from step ``stood`` to ``toward``, turning): a reboot, if
        the next IRSCN's clock confirms it."""
        if done_seq < 0 and self._clock is not None and self._woke is None:
            self._woke = (stood, toward) if stood is not None else (None, None)
            self._woke_scans = self.stats.scans   # close(): none taken since, none to tell

    def _went_back(self, scan: p.Scan) -> bool:
        """``scan``'s device clock is earlier than the latest IRSCN's taken (modulo its wrap):
        a device's clock runs on, and a rebooted one's starts anew."""
        return self._clock is not None and \
            0 < (self._clock - scan.t_ms) % p.CLOCK_MODULO < p.CLOCK_MODULO // 2

    def _ran_short(self, scan: p.Scan, at: float) -> bool:
        """``scan``'s device clock (arrived at ``at``) advanced from the latest IRSCN taken
        less than this computer's clock did, beyond CLOCK_RATE_TOLERANCE and
        CLOCK_LATENCY_S: restarted, though its count need not go back."""
        if self._clock is None or self._clock_at is None:
            return False
        ahead_s = ((scan.t_ms - self._clock) % p.CLOCK_MODULO) / 1000.0
        here_s = at - self._clock_at
        return ahead_s < (here_s - CLOCK_LATENCY_S) * (1.0 - CLOCK_RATE_TOLERANCE)

    def _restarted(self, scan: p.Scan, at: float) -> bool:
        """``scan``'s device clock started anew since the latest IRSCN taken: it went back,
        or it ran short of the time that passed here."""
        return self._went_back(scan) or self._ran_short(scan, at)

    def _rebooted(self, scan: p.Scan, at: float, stood: tuple[int | None, int | None],
                  sign: str) -> DeviceRebooted:
        """The error for a device seen rebooting (``sign``: how its numbering said so; its
        clock restarted by ``scan``'s, arrived at ``at``) while the ring stood from step
        ``stood[0]`` to ``stood[1]`` (turning; None: not known)."""
        info = self.info
        a, b = stood
        if a is None or b is None:
            where, off = "at a step not known", "by an unknown number of steps"
        elif a != b:
            where = f"while it turned from step {a} to step {b}"
            off = f"by the step it stood at, from step {a} to step {b},"
        else:
            deg = abs(a) * info.step_mdeg * info.gear_num / info.gear_den / 1000
            where, off = f"at step {a}", f"by {abs(a)} steps ({deg:.1f}°)"
        fix = (f"turn the ring back to radial (IRGTO,{-a} turns it there now)"
               if a is not None and a == b else "turn the ring back to radial by hand"
               + (" (where it stood is not known, so no IRGTO can)" if a is not None else ""))
        clock = (f"{scan.t_ms} ms after {self._clock} ms" if self._went_back(scan) else
                 f"it says {scan.t_ms} ms, {(scan.t_ms - self._clock) % p.CLOCK_MODULO} ms on "
                 f"from the {self._clock} ms of the last IRSCN taken, where this computer's "
                 f"clock ran {at - self._clock_at:.1f} s")
        self._position_lost = True   # its step 0 is not radial: close() must not go there
        return DeviceRebooted(
            f"the ring on {self.port_name} rebooted {where}: {sign}, and its clock started "
            f"anew ({clock}). Its firmware takes the step it "
            f"wakes at as step 0, so every step it names since is off {off} and its readings "
            f"would land beside their walls; none read since is taken. Then {fix}, reset the "
            "board, and drive the poses not swept again.")

    def _inconsistent(self, why: str, n: int = 1) -> None:
        """Count ``n`` IRSCN dropped as inconsistent; the sweep's report names the first."""
        self.stats.inconsistent += n
        if self._dropped is None:
            self._dropped = why

    def _given_up(self, framed: int, accepted: int, what: str) -> LinkLost:
        """The error of a pass given up (DeviceTimeout, ``what`` saying why), unless since it
        began (``framed``, ``accepted``: the counters then) more sentences came framed for
        the other protocol version than intact, a few at least: then the device answers in
        the other framing (reflashed or swapped mid-session), which no IRSTP changes."""
        other = self._other_framing - framed
        if other < 3 or other <= self.stats.sentences - accepted:
            lost = self.stats.lost_scans - self._sweep_before.get("lost_scans", 0)
            return self._lost(DeviceTimeout, what, lost)
        spoken = self.decoder.version
        them = 3 - spoken   # the other of p.PROTOCOL_VERSIONS
        self._position_lost = True
        return DeviceChanged(
            f"the device on {self.port_name} now frames its sentences for IRR protocol "
            f"v{them} ({other} sentences with a {p.CHECK_DIGITS[them]}-digit check field "
            f"since this pass began, dropped), where the handshake spoke v{spoken}: it was "
            f"reflashed or swapped; connect again to read it.")

    def _assemble(self, req: list[int], passes: list[_Pass], samples: int, settle_ms: int,
                  pose: np.ndarray) -> core.Sweep:
        info = self.info
        got: dict[int, p.Scan] = {}
        for ps in passes:
            for step, scan in ps.got.items():
                got.setdefault(step, scan)
        steps = np.array([s for s in req if s in got], dtype=int)
        missing = tuple(s for s in req if s not in got)
        n = info.nsensors
        counts = np.array([got[s].counts for s in steps], dtype=np.int64).reshape(len(steps), n)
        # device clock, unwrapped from the first reading of this sweep (ms → s)
        scans = [sc for ps in passes for sc in ps.got.values()]
        if scans:
            t0 = scans[0].t_ms  # the first reading to arrive
            rel = np.array([(got[s].t_ms - t0) % p.CLOCK_MODULO for s in steps], dtype=float)
            rel[rel >= p.CLOCK_MODULO // 2] -= p.CLOCK_MODULO  # a reading before the first
            timestamps = (t0 + rel) / 1000.0
        else:
            timestamps = np.zeros(0)
        duration = sum(self._pass_duration(ps, samples, settle_ms) for ps in passes)
        if duration > core.MAX_DURATION_S:   # more than a recording may hold
            self.stats.clock_faults += 1
            duration = core.hardware_duration_s(len(req), settle_ms / 1000, samples)
        return core.Sweep(
            steps=steps, sensor_angles=core.sensor_angles_for_steps(self.ring, steps),
            counts=counts, timestamps_s=timestamps, duration_s=duration, pose=pose,
            ring=self.ring, sensor_model=self.sensor_model, adc_bits=info.adc_bits,
            vref_v=self.vref_v, max_range_m=self.max_range_m, samples=samples,
            settle_s=settle_ms / 1000, missing_steps=missing, source=f"serial:{self.port_name}")

    def _pass_duration(self, ps: _Pass, samples: int, settle_ms: int) -> float:
        """Device-clock time of one pass: the span between its first and last readings,
        extended by one mean step interval (the first step's own time, which no timestamp
        brackets). With fewer than two readings, or a clock that claims more time a step
        than the pass's no-progress limit allows (it jumped, or ran backwards) or less than
        ``samples`` readings of the fastest sensor (it stood still), the nominal hardware
        time (counted in ``stats.clock_faults``)."""
        nominal = core.hardware_duration_s(len(ps.expected), settle_ms / 1000, samples)
        if len(ps.got) < 2:
            return nominal
        index = ps.index
        sent = {step: ps.sent_at(index[step]) for step in ps.got}
        first = min(ps.got.values(), key=lambda sc: sent[sc.step])
        last = max(ps.got.values(), key=lambda sc: sent[sc.step])
        span_s = ((last.t_ms - first.t_ms) % p.CLOCK_MODULO) / 1000.0
        per_step = span_s / (sent[last.step] - sent[first.step])
        # faster than any sensor reads (a clock standing still), or slower than the pass's
        # no-progress limit allowed
        if not core.MIN_READING_PERIOD_S * samples <= per_step <= ps.max_step_s:
            self.stats.clock_faults += 1
            log.info("device clock: %.0f s a step between steps %d and %d; using the "
                     "nominal %.3f s a step", per_step, first.step, last.step,
                     nominal / len(ps.expected))
            return nominal
        return per_step * len(ps.expected)

    def _report(self, req: list[int], sweep: core.Sweep, before: dict[str, int],
                complete: bool, started: float, reason: str) -> SweepReport:
        link = self.stats.minus(before)
        n_req, n_got = len(req), len(sweep.steps)
        if sweep.missing_steps:
            shown = ", ".join(map(str, sweep.missing_steps[:12]))
            more = " …" if len(sweep.missing_steps) > 12 else ""
            msg = (f"{n_got} of {n_req} steps received; missing steps {shown}{more} "
                   f"(not invented, left out of the sweep)")
        else:
            msg = f"all {n_req} steps received"
        msg += f"; {_describe_link(link, self._dropped, self._garbled)}"
        if reason:
            msg = f"{reason}: {msg}"
        return SweepReport(tuple(req), n_got, sweep.missing_steps, link, complete,
                           time.monotonic() - started, msg)
