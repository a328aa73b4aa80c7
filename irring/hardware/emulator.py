"""A ring device that speaks the IRR protocol on a pseudo-terminal, backed by the simulator.

How it works, its assumptions and measured figures: docs/emulator.md.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import math
import os
import select
import socket
import struct
import termios
import threading
import time
import tty
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import core
from . import protocol as p

FIRMWARE = "irring-emulator-1"
# `irring emulate`'s IRINF names its room after FIRMWARE, so `irring drive --truth` can
# refuse another room's readings; 40 characters keep any IRINF inside the 128-byte line
ROOM_TAG = " room "
ROOM_TAG_MAX = 40
MOVE_S_PER_STEP = 0.002  # stepper time per motor step (500 steps/s) for IRGTO / reaching `from`
# Output not yet handed to the link, at most: a command that finds this much waiting is
# dropped unanswered (DeviceStats.commands_dropped), as the board's 32-byte RX buffer
# overruns while it blocks on a full 64-byte TX buffer (firmware/avr/hal_avr.c). It holds
# a sweep's IRSCN + IRDON (≤ 2 × 128 bytes), so only a host flooding it meets the bound.
OUT_LIMIT_BYTES = 2 * p.MAX_SENTENCE_BYTES


def room_tag(name: str) -> str:
    """A scenario's name as `irring emulate`'s IRINF carries it: the name itself when it is
    at most ROOM_TAG_MAX characters IRR text carries (:func:`protocol.text_ok`) but space;
    else those (others as `_`) cut to fit, `~` and 8 hex digits of its SHA-256."""
    ok = [c != " " and p.text_ok(c) for c in name]
    if len(name) <= ROOM_TAG_MAX and name and all(ok):
        return name
    digest = hashlib.sha256(name.encode("utf-8", "surrogatepass")).hexdigest()[:8]
    kept = "".join(c if good else "_" for c, good in zip(name, ok))
    return f"{kept[:ROOM_TAG_MAX - 9]}~{digest}"


def firmware_for(name: str) -> str:
    """IRINF's firmware field of an emulator of the scenario named ``name``."""
    return f"{FIRMWARE}{ROOM_TAG}{room_tag(name)}"


def emulated_room(firmware: str) -> str | None:
    """The room tag an `irring emulate` IRINF names (:func:`firmware_for`), or None: a
    board, or an emulator that names no room."""
    head = FIRMWARE + ROOM_TAG
    return firmware[len(head):] if firmware.startswith(head) else None


@dataclass(frozen=True)
class Faults:
    """What goes wrong on the emulated device's output (its input is delivered intact).

    corrupt_rate: probability that each byte sent is replaced by a different random byte.
    bitflip_rate: probability that each bit sent is flipped (line noise, a UART's bit
        errors: most garbled sentences differ from the sent one in a single bit).
    drop_rate: probability that a whole sentence is never sent.
    stall_after: after this many sentences the device stops answering (reads and ignores
        input) for ``stall_s`` seconds (default: for good), then aborts its sweep and
        recovers.
    disconnect_after: after this many sentences the device closes the port.
    reverse_sweeps: the device sweeps every IRSWP from ``to`` to ``from``, against the asked
        direction, each IRSCN naming the step it was read at (a firmware that ignores the
        direction it is given).
    motor_reversed: the motor turns the other way than the firmware counts (its DIR wired
        reversed, firmware built without IRR_DIR_INVERT): an IRSCN naming step s was read at
        step −s. The link cannot show it; the readings land mirrored.
    seed: of the fault generator (independent of the readings' noise).
    """

    corrupt_rate: float = 0.0
    bitflip_rate: float = 0.0
    drop_rate: float = 0.0
    stall_after: int | None = None
    stall_s: float = math.inf
    disconnect_after: int | None = None
    reverse_sweeps: bool = False
    motor_reversed: bool = False
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("corrupt_rate", "bitflip_rate", "drop_rate"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be 0 … 1, got {value}")
        for name in ("stall_after", "disconnect_after"):
            value = getattr(self, name)
            if value is not None and value < 0:
                raise ValueError(f"{name} must be ≥ 0 sentences, got {value}")


@dataclass
class DeviceStats:
    sentences_produced: int = 0  # including dropped ones
    sentences_dropped: int = 0
    bytes_sent: int = 0
    bytes_corrupted: int = 0
    bits_flipped: int = 0
    sentences_corrupted: int = 0  # sent with a byte replaced or a bit flipped
    commands: int = 0
    commands_rejected: int = 0
    commands_dropped: int = 0    # arrived while OUT_LIMIT_BYTES of output waited: no answer
    sweeps: int = 0


@dataclass
class _SweepJob:
    steps: np.ndarray
    counts: np.ndarray      # (S, N) int
    step_s: float           # settle + samples × GP2 period, per step
    next_index: int = 0
    due: float = 0.0        # host time the next IRSCN is due (realtime)


class Device:
    """The ring's firmware, emulated: protocol logic and fault injection, no I/O.

    Feed host bytes with :meth:`receive`; collect device bytes with :meth:`poll`, which
    returns what is due at ``now`` and when to call it again. ``disconnected`` turns true
    when the device decides to close the port.
    """

    def __init__(self, source: core.RingSource, *, faults: Faults = Faults(),
                 realtime: bool = False, firmware: str = FIRMWARE,
                 clock_start_ms: int = 1000, fixed_pose: int | None = None,
                 protocol: int = p.PROTOCOL_VERSION):
        self.source = source
        self.protocol = p.check_version(protocol)   # 1: an old, unreflashed board
        self.info = p.info_for_ring(source.ring, source.adc_bits, firmware, protocol)
        too_long = p.scan_too_long(self.info)   # else an internal error at its first such sweep
        if too_long:
            raise ValueError(f"cannot emulate this ring: {too_long}")
        if faults.motor_reversed and self.info.min_step != -self.info.max_step:
            raise ValueError(f"motor_reversed needs steps symmetric about 0, got "
                             f"{self.info.min_step} … {self.info.max_step}: turned the other "
                             f"way the ring would pass its end")
        self.poses = max(1, int(source.n_sweeps))  # the robot visits source poses 0 … poses-1
        self.faults = faults
        self.realtime = realtime
        self.fixed_pose = fixed_pose
        self.decoder = p.Decoder(protocol)
        self.stats = DeviceStats()
        self._rng = np.random.default_rng([faults.seed, 0x1F])
        self._out: deque[bytes] = deque()
        self._job: _SweepJob | None = None
        self._seq = -1                   # last IRSCN seq sent (−1: none yet)
        self._position = 0               # motor step
        self._pose = 0
        self._full_sweeps = 0
        self._clock_start_ms = clock_start_ms
        self._virtual_ms = 0.0
        self._t0: float | None = None
        self._stall_until: float | None = None
        self._stall_used = False
        self._pending_pos: tuple[float, int] | None = None  # (due, step) of an IRGTO
        self.disconnected = False

    # ---------------------------------------------------------------- clock

    def clock_ms(self, now: float) -> int:
        if self._t0 is None:
            self._t0 = now
        elapsed = (now - self._t0) * 1000.0 if self.realtime else self._virtual_ms
        return int(self._clock_start_ms + elapsed) % p.CLOCK_MODULO

    # ---------------------------------------------------------------- input

    def receive(self, chunk: bytes, now: float) -> None:
        if self._t0 is None:
            self._t0 = now
        if self.disconnected or self._stalled(now):
            return  # a hung device hears nothing
        for item in self.decoder.feed(chunk):
            self.stats.commands += 1
            if sum(map(len, self._out)) >= OUT_LIMIT_BYTES:
                self.stats.commands_dropped += 1    # a flooding host: the board's RX overran
                continue
            if isinstance(item, p.ProtocolError) and item.fault is p.Fault.OTHER_VERSION \
                    and self.protocol == 2:
                self._answer_old_host(item.raw)
            elif isinstance(item, p.ProtocolError):
                self.stats.commands_rejected += 1
                code = item.fault.device_error_code
                self._say(p.ErrorReply(code, p.ERROR_TEXT[code]))
            else:
                self._handle(item, now)

    def _answer_old_host(self, line: bytes) -> None:
        """A v1-framed sentence to a v2 device is answered in v1 framing: IRHLO with the
        IRINF whose version field tells an old host what it met, anything else IRERR
        (firmware/core/irr_proto.c does the same)."""
        try:
            msg = p.decode(line, version=1)
        except p.ProtocolError as exc:
            code = exc.fault.device_error_code
        else:
            if isinstance(msg, p.Hello):
                self._say(self.info, version=1)
                return
            code = p.ERR_UNKNOWN_TYPE if msg.TYPE not in p.HOST_TYPES else p.ERR_BAD_SENTENCE
        self.stats.commands_rejected += 1
        self._say(p.ErrorReply(code, p.ERROR_TEXT[code]), version=1)

    def _handle(self, msg: p.AnyMessage, now: float) -> None:
        if msg.TYPE not in p.HOST_TYPES:
            self.stats.commands_rejected += 1
            self._say(p.ErrorReply(p.ERR_UNKNOWN_TYPE, f"{msg.TYPE} is not a command"))
        elif isinstance(msg, p.Hello):
            # a host says hello when it opens the link: a new session starts the robot again
            # at its first pose, as a person would put the real robot back (a second drive
            # against one emulator began at pose 2+ and scored against the wrong poses)
            self._pose, self._full_sweeps = 0, 0
            self._say(self.info)
        elif isinstance(msg, p.Stop):
            self._job = None  # stop after the step in progress: IRDON with the last seq sent
            self._say(p.Done(self._seq))
        elif self._job is not None or self._pending_pos is not None:
            self.stats.commands_rejected += 1
            self._say(p.ErrorReply(p.ERR_BUSY, p.ERROR_TEXT[p.ERR_BUSY]))
        elif isinstance(msg, p.GoTo):
            if not self._in_range(msg.step):
                return
            move_s = abs(msg.step - self._position) * MOVE_S_PER_STEP
            self._advance(move_s)
            self._pending_pos = (now + (move_s if self.realtime else 0.0), msg.step)
        elif isinstance(msg, p.SweepCommand):
            if not (self._in_range(msg.from_step) and self._in_range(msg.to_step)):
                return
            self._start_sweep(msg, now)

    def _in_range(self, step: int) -> bool:
        if self.info.min_step <= step <= self.info.max_step:
            return True
        self.stats.commands_rejected += 1
        self._say(p.ErrorReply(p.ERR_STEP_RANGE, p.ERROR_TEXT[p.ERR_STEP_RANGE]))
        return False

    def _start_sweep(self, cmd: p.SweepCommand, now: float) -> None:
        d = 1 if cmd.to_step >= cmd.from_step else -1
        steps = np.arange(cmd.from_step, cmd.to_step + d, d)
        if self.faults.reverse_sweeps:
            steps = steps[::-1]
        full = {cmd.from_step, cmd.to_step} == {self.info.min_step, self.info.max_step}
        if full:
            if self._full_sweeps and self.fixed_pose is None:
                self._pose = (self._pose + 1) % self.poses
            self._full_sweeps += 1
        pose = self._pose if self.fixed_pose is None else self.fixed_pose
        settle_s = cmd.settle_ms / 1000.0
        turned = -steps if self.faults.motor_reversed else steps   # where the ring really is
        raw = np.asarray(self.source.sweep(pose, steps=turned).counts, dtype=float)
        top = (1 << self.info.adc_bits) - 1
        # a real ADC reports whole counts in range; NaN (no reading) reads as 0
        counts = np.clip(np.rint(np.nan_to_num(raw, nan=0.0)), 0, top).astype(np.int64)
        # Moving to `from_step` costs motor time; the one-step moves inside the sweep happen
        # within each step's settle time, so a sweep lasts core.hardware_duration_s.
        move_s = abs(int(steps[0]) - self._position) * MOVE_S_PER_STEP
        step_s = core.hardware_duration_s(1, settle_s, cmd.samples)
        self._advance(move_s)
        first_due = now + (move_s + step_s if self.realtime else 0.0)
        self._job = _SweepJob(steps, counts.reshape(len(steps), -1), step_s, due=first_due)
        self.stats.sweeps += 1

    def _advance(self, seconds: float) -> None:
        if not self.realtime:
            self._virtual_ms += seconds * 1000.0

    # ---------------------------------------------------------------- output

    def poll(self, now: float) -> tuple[bytes, float | None]:
        """Bytes due by ``now`` (after faults) and the host time of the next due output
        (None: nothing scheduled; ``now``: call again at once)."""
        if self._t0 is None:
            self._t0 = now
        if self.disconnected:
            return b"", None
        if self._stalled(now):
            self._out.clear()
            return b"", self._stall_until if math.isfinite(self._stall_until) else None
        if self._pending_pos is not None and now >= self._pending_pos[0]:
            self._position = self._pending_pos[1]
            self._pending_pos = None
            self._say(p.Position(self._position))
        job = self._job
        if job is not None and not self._out and now >= job.due:
            i = job.next_index
            self._advance(job.step_s)
            self._position = int(job.steps[i])
            self._seq = (self._seq + 1) % p.SEQ_MODULO
            self._say(p.Scan(self._seq, self._position, self.clock_ms(now),
                             tuple(int(c) for c in job.counts[i])))
            job.next_index += 1
            job.due = now + job.step_s if self.realtime else now
            if job.next_index == len(job.steps):
                self._job = None
                self._say(p.Done(self._seq))
        out = bytearray()
        while self._out and not self.disconnected:
            out += self._transmit(self._out.popleft(), now)
        nxt = None
        if self._job is not None:
            nxt = self._job.due
        if self._pending_pos is not None:
            nxt = self._pending_pos[0] if nxt is None else min(nxt, self._pending_pos[0])
        return bytes(out), nxt

    def _say(self, msg: p.Message, version: int | None = None) -> None:
        self._out.append(p.encode(msg, version=version or self.protocol))

    def _transmit(self, line: bytes, now: float) -> bytes:
        """Apply the faults to one sentence on its way out."""
        f = self.faults
        k = self.stats.sentences_produced + 1
        if f.disconnect_after is not None and k > f.disconnect_after:
            self.disconnected = True
            self._out.clear()
            return b""
        if f.stall_after is not None and k > f.stall_after and not self._stall_used:
            self._stall_used = True
            self._stall_until = now + f.stall_s
            self._out.clear()
            return b""
        self.stats.sentences_produced = k
        if f.drop_rate and self._rng.random() < f.drop_rate:
            self.stats.sentences_dropped += 1
            return b""
        sent = line
        if f.corrupt_rate:
            buf = np.frombuffer(line, dtype=np.uint8).copy()
            hit = self._rng.random(buf.size) < f.corrupt_rate
            if hit.any():
                buf[hit] ^= self._rng.integers(1, 256, hit.sum(), dtype=np.uint8)
                self.stats.bytes_corrupted += int(hit.sum())
                line = buf.tobytes()
        if f.bitflip_rate:
            flip = self._rng.random(len(line) * 8) < f.bitflip_rate
            if flip.any():
                line = (np.frombuffer(line, dtype=np.uint8) ^ np.packbits(flip)).tobytes()
                self.stats.bits_flipped += int(flip.sum())
        self.stats.sentences_corrupted += line != sent
        self.stats.bytes_sent += len(line)
        return line

    def _stalled(self, now: float) -> bool:
        if self._stall_until is None:
            return False
        if now < self._stall_until:
            return True
        # the watchdog fired: the sweep in progress is lost, the device listens again
        self._stall_until = None
        self._job = None
        self._pending_pos = None
        self.decoder.reset()
        return False


class _Server:
    """Serving lifecycle shared by the pty and TCP emulators: open on first use, serve on a
    daemon thread, stop by event; subclasses provide open(), serve_forever() and _close()."""

    _thread_name = "irring-emulator"

    def __init__(self, device: Device, baud: int):
        self.device = device
        self.baud = int(baud)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _is_open(self) -> bool:
        raise NotImplementedError

    def open(self) -> str:
        raise NotImplementedError

    def serve_forever(self) -> None:
        raise NotImplementedError

    def _close(self) -> None:
        raise NotImplementedError

    def __enter__(self):
        if not self._is_open():
            self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def start_thread(self):
        if not self._is_open():
            self.open()
        self._thread = threading.Thread(target=self.serve_forever, name=self._thread_name,
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 2.0) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout_s)
        self._close()


class PtyEmulator(_Server):
    """Runs a :class:`Device` on a pseudo-terminal.

    ``path`` is the slave device (``/dev/pts/N``) a host opens like a serial port; ``link``,
    if given, is a symlink to it (a stale one replaced, one in use refused). ``baud`` > 0 paces output like a
    UART at that rate (10 bits per byte); 0 sends as fast as the pty takes it.
    """

    def __init__(self, device: Device, *, link: str | os.PathLike | None = None,
                 baud: int = 0):
        super().__init__(device, baud)
        self.link = Path(link) if link is not None else None
        self.path: str | None = None
        self._master: int | None = None
        self._slave: int | None = None

    def _is_open(self) -> bool:
        return self._master is not None

    def open(self) -> str:
        """Create the pty (and the link); returns the slave path."""
        master, slave = os.openpty()
        tty.setraw(slave)            # no echo, no CR/LF translation before the host opens it
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.path = os.ttyname(slave)
        if self.link is not None:
            try:
                self._make_link()
            except OSError:
                self._close()
                raise
        return self.path

    def _make_link(self) -> None:
        """Point ``link`` at the pty: a new symlink, or one that replaces a stale symlink (to
        a pty that closed: its emulator stopped) in a single rename. Anything else at that
        path is left alone: a file, a folder, or a link in use (its pty open: another
        emulator's) raise FileExistsError saying what to do."""
        link = self.link
        if link.is_symlink() and link.exists():
            raise FileExistsError(errno.EEXIST, f"{link} is in use: it points at "
                                  f"{os.readlink(link)}, which is open (another irring "
                                  "emulate?); stop that one, or pick another link with "
                                  "--link PATH")
        if link.exists() and not link.is_symlink():
            raise FileExistsError(errno.EEXIST, f"{link} exists and is not a symlink; not "
                                                "replacing it (remove it or pick another --link)")
        tmp = link.with_name(f".{link.name}.{os.getpid()}.link")
        tmp.unlink(missing_ok=True)
        os.symlink(self.path, tmp)
        try:
            os.replace(tmp, link)
        except OSError:
            tmp.unlink(missing_ok=True)
            raise

    def _close(self) -> None:
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None
        if self.link is not None and self.link.is_symlink():
            try:
                if os.readlink(self.link) == self.path:
                    self.link.unlink()
            except OSError:
                pass

    def _unread(self) -> int:
        """Bytes sent that the host has not read yet."""
        # The kernel hands pty output to the slave from a work queue; FIONREAD alone may
        # read 0 before it ran, while polling the slave waits for it to finish.
        select.select([self._slave], [], [], 0)
        raw = fcntl.ioctl(self._slave, termios.FIONREAD, b"\0\0\0\0")
        return struct.unpack("i", raw)[0]

    def _linger(self, max_s: float = 1.0) -> None:
        # Closing the master hangs up the tty and flushes what the host has not read yet;
        # the sentences before an injected disconnect should still arrive.
        deadline = time.monotonic() + max_s
        while self._unread() > 0 and time.monotonic() < deadline and not self._stop.is_set():
            time.sleep(0.005)

    def serve_forever(self) -> None:
        """Answer the host until :meth:`stop` or the device disconnects."""
        if self._master is None:
            self.open()
        try:
            _serve_fd(self._master, self.device, self.baud, self._stop, self._linger)
        finally:
            self._close()


def _serve_fd(fd: int, dev: Device, baud: int, stop: threading.Event,
              before_disconnect=lambda: None) -> str:
    """Shuttle bytes between a non-blocking fd and ``dev`` until ``stop`` is set ("stop"),
    the device disconnects ("disconnected") or the peer closes a socket ("eof")."""
    pending = bytearray()
    budget_t, budget_sent = time.monotonic(), 0  # UART pacing
    while not stop.is_set():
        now = time.monotonic()
        next_due = None
        if len(pending) < 256:
            chunk, next_due = dev.poll(now)
            if not pending:
                budget_t, budget_sent = now, 0
            pending += chunk
        if dev.disconnected and not pending:
            before_disconnect()
            return "disconnected"
        allowed = len(pending)
        if baud > 0 and pending:
            allowed = int((now - budget_t) * baud / 10) - budget_sent
            allowed = max(0, min(allowed, len(pending)))
        wait = 0.05
        if next_due is not None:
            wait = min(wait, max(0.0, next_due - now))
        if pending and allowed == 0:
            wait = min(wait, 10.0 / baud)
        want_write = bool(pending) and allowed > 0
        r, w, _ = select.select([fd], [fd] if want_write else [], [], wait)
        if r:
            try:
                incoming = os.read(fd, 4096)
            except BlockingIOError:
                incoming = None
            except OSError as exc:
                if exc.errno not in (errno.EIO, errno.ECONNRESET):
                    raise
                incoming = b"" if exc.errno == errno.ECONNRESET else None
            if incoming == b"":
                return "eof"  # a pty never reads b"" here (we hold its slave); a socket closed
            if incoming:
                dev.receive(incoming, time.monotonic())
        if w:
            try:
                n = os.write(fd, bytes(pending[:allowed]))
            except BlockingIOError:
                n = 0
            except (BrokenPipeError, ConnectionResetError):
                return "eof"
            del pending[:n]
            budget_sent += n
    return "stop"


class TcpEmulator(_Server):
    """Runs a :class:`Device` on a TCP port, one host connection at a time; the host opens
    ``socket://HOST:PORT`` (pyserial). The device keeps its state across connections; an
    injected disconnect closes the connection and ends serving."""

    def __init__(self, device: Device, *, host: str = "127.0.0.1", port: int = 0,
                 baud: int = 0):
        super().__init__(device, baud)
        self.host, self.port = host, int(port)
        self._listener: socket.socket | None = None

    _thread_name = "irring-emulator-tcp"

    def _is_open(self) -> bool:
        return self._listener is not None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host   # IPv6, as URLs write it
        return f"socket://{host}:{self.port}"

    def open(self) -> str:
        """Bind and listen (port 0: any free port) on the host's first address, IPv4 or
        IPv6 (``::1`` was refused: "Address family for hostname not supported"); returns the
        pyserial URL. Raises OSError (socket.gaierror for a name that does not resolve)."""
        family, kind, proto, _, address = socket.getaddrinfo(
            self.host, self.port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)[0]
        sock = socket.socket(family, kind, proto)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        sock.listen(1)
        self.port = sock.getsockname()[1]
        self._listener = sock
        return self.url

    def _close(self) -> None:
        if self._listener is not None:
            self._listener.close()
            self._listener = None

    def serve_forever(self) -> None:
        if self._listener is None:
            self.open()
        listener = self._listener
        try:
            while not self._stop.is_set() and not self.device.disconnected:
                ready, _, _ = select.select([listener], [], [], 0.05)
                if not ready:
                    continue
                conn, _ = listener.accept()
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                conn.setblocking(False)
                try:
                    _serve_fd(conn.fileno(), self.device, self.baud, self._stop)
                finally:
                    try:
                        conn.shutdown(socket.SHUT_RDWR)  # delivers what was sent, then FIN
                    except OSError:
                        pass
                    conn.close()
        finally:
            self.stop(timeout_s=0)


class DevicePort:
    """A pyserial-like port wired straight to a :class:`Device`, in-process: no pty, no
    thread. ``SerialRing(DevicePort(Device(source)))`` runs the driver against the emulated
    firmware anywhere (also where ptys do not exist). Output is delivered as soon as the
    device produces it, so an IRSTP cannot interrupt an unthrottled sweep here."""

    def __init__(self, device: Device, *, name: str = "device://emulator"):
        self.device = device
        self.name = name
        self.timeout: float | None = 0.02
        self.is_open = True
        self._buf = bytearray()

    def _pump(self) -> None:
        now = time.monotonic()
        for _ in range(100_000):  # everything due now (a sweep step per poll)
            chunk, due = self.device.poll(now)
            self._buf += chunk
            if due is None or due > now:
                break

    def _check(self) -> None:
        if not self.is_open:
            import serial   # deferred: pyserial; the pty and TCP emulators do without it

            raise serial.PortNotOpenError()
        if self.device.disconnected and not self._buf:
            import serial   # deferred: pyserial; the pty and TCP emulators do without it

            raise serial.SerialException("device disconnected")

    @property
    def in_waiting(self) -> int:
        self._check()
        self._pump()
        return len(self._buf)

    def read(self, size: int = 1) -> bytes:
        deadline = time.monotonic() + (self.timeout or 0.0)
        while True:
            self._check()
            self._pump()
            if self._buf or time.monotonic() >= deadline:
                out = bytes(self._buf[:size])
                del self._buf[:size]
                return out
            time.sleep(0.002)

    def write(self, data_: bytes) -> int:
        self._check()
        self.device.receive(bytes(data_), time.monotonic())
        return len(data_)

    def reset_input_buffer(self) -> None:
        self._pump()
        self._buf.clear()

    def open(self) -> None:
        self.is_open = True

    def close(self) -> None:
        self.is_open = False
