"""IRR serial protocol version 2 (docs/protocol.md): pure encode/decode of sentences, no I/O.

:func:`encode` makes one sentence's bytes from a typed message (a frozen dataclass per
sentence type); :func:`decode` parses one or raises :class:`ProtocolError` naming its
:class:`Fault`; :class:`Decoder` cuts a byte stream into messages and rejections, never
raising on what the wire delivers. Each takes ``version``: 2 (a CRC-16, the default) or 1
(the old 8-bit XOR, spoken only to an old device the host was told to accept).
"""

from __future__ import annotations

import binascii
import dataclasses
import enum
import math
import re
from dataclasses import dataclass, fields
from fractions import Fraction
from typing import ClassVar, Union

from ..core import MAX_SAMPLES, Ring

PROTOCOL_VERSION = 2      # what this irring speaks
PROTOCOL_VERSIONS = (1, 2)  # what it can frame: v1 only to identify (or, told to, use) an old device
MAX_SENTENCE_BYTES = 128  # from `$` to `\n` inclusive
SEQ_MODULO = 1 << 16      # IRSCN sequence numbers wrap at 65536
CLOCK_MODULO = 1 << 32    # the device clock (ms) wraps at 2³²
INT32_MIN, INT32_MAX = -(1 << 31), (1 << 31) - 1

# Error codes a device answers with (docs/protocol.md, IRERR).
ERR_BAD_SENTENCE = 1
ERR_UNKNOWN_TYPE = 2
ERR_BAD_ARGUMENT = 3
ERR_STEP_RANGE = 4
ERR_BUSY = 5
ERROR_TEXT = {ERR_BAD_SENTENCE: "bad sentence", ERR_UNKNOWN_TYPE: "unknown type",
              ERR_BAD_ARGUMENT: "bad argument", ERR_STEP_RANGE: "step out of range",
              ERR_BUSY: "busy"}


# --------------------------------------------------------------------------- errors


class Fault(enum.Enum):
    """Why a sentence was rejected."""

    NO_START = "does not start with `$`"
    TOO_LONG = f"longer than {MAX_SENTENCE_BYTES} bytes"
    INTERRUPTED = "cut short by a new `$` before its end"
    NO_TERMINATOR = "does not end with \\r\\n"
    NO_CHECKSUM = "has no `*` before the checksum"
    BAD_CHECKSUM_FORMAT = "checksum is not upper-case hex digits of the protocol's length"
    OTHER_VERSION = "is framed for another protocol version"
    CHECKSUM_MISMATCH = "checksum does not match"
    BAD_CHARACTER = "contains a byte that is not printable ASCII or a reserved `$`/`*`"
    BAD_TYPE = "type is not 5 upper-case letters starting with IR"
    UNKNOWN_TYPE = "unknown sentence type"
    FIELD_COUNT = "wrong number of fields"
    BAD_FIELD = "malformed field"
    OUT_OF_RANGE = "field value out of range"

    @property
    def device_error_code(self) -> int:
        """The IRERR code a device answers a rejected command with."""
        if self is Fault.UNKNOWN_TYPE:
            return ERR_UNKNOWN_TYPE
        if self is Fault.OUT_OF_RANGE:
            return ERR_BAD_ARGUMENT
        return ERR_BAD_SENTENCE


class ProtocolError(ValueError):
    """A sentence that must be dropped; ``fault`` says why, ``raw`` holds its bytes."""

    def __init__(self, fault: Fault, raw: bytes = b"", detail: str = ""):
        self.fault = fault
        self.raw = bytes(raw)
        self.detail = detail
        shown = self.raw[:40] + (b"..." if len(self.raw) > 40 else b"")
        text = f"sentence {shown!r} {fault.value}"
        super().__init__(f"{text}: {detail}" if detail else text)


# --------------------------------------------------------------------------- messages
# Field kinds: (lo, hi) inclusive integer bounds, or TEXT.

TEXT = "text"
_ANY_STEP = (INT32_MIN, INT32_MAX)


@dataclass(frozen=True)
class Message:
    """Base of every sentence type; ``TYPE`` is the 5-letter tag, ``SPEC`` the field kinds."""

    TYPE: ClassVar[str] = ""
    SPEC: ClassVar[tuple] = ()

    def check(self) -> None:
        """Cross-field rules beyond each field's own range (raises ProtocolError)."""


@dataclass(frozen=True)
class Hello(Message):
    """Host → device: hello; the device answers :class:`Info`."""

    TYPE: ClassVar[str] = "IRHLO"


@dataclass(frozen=True)
class SweepCommand(Message):
    """Host → device: sweep motor steps ``from_step`` … ``to_step`` inclusive (either
    direction), settle ``settle_ms`` ms at each step, average ``samples`` readings (1–64)."""

    TYPE: ClassVar[str] = "IRSWP"
    SPEC: ClassVar[tuple] = (_ANY_STEP, _ANY_STEP, (1, MAX_SAMPLES), (0, INT32_MAX))
    from_step: int
    to_step: int
    samples: int = 1
    settle_ms: int = 0


@dataclass(frozen=True)
class GoTo(Message):
    """Host → device: move to motor step ``step``; the device answers :class:`Position`."""

    TYPE: ClassVar[str] = "IRGTO"
    SPEC: ClassVar[tuple] = (_ANY_STEP,)
    step: int


@dataclass(frozen=True)
class Stop(Message):
    """Host → device: stop a sweep in progress; the device answers :class:`Done`."""

    TYPE: ClassVar[str] = "IRSTP"


@dataclass(frozen=True)
class Info(Message):
    """Device → host: what the ring is. ``step_mdeg`` is the motor full step in millidegrees;
    the sensors turn ``gear_num/gear_den`` of the motor; allowed steps min_step … max_step."""

    TYPE: ClassVar[str] = "IRINF"
    SPEC: ClassVar[tuple] = ((1, 65535), (1, 4096), (1, 32), (1, 360_000), (1, INT32_MAX),
                             (1, INT32_MAX), _ANY_STEP, _ANY_STEP, TEXT)
    proto: int
    nsensors: int
    adc_bits: int
    step_mdeg: int
    gear_num: int
    gear_den: int
    min_step: int
    max_step: int
    firmware: str

    def check(self) -> None:
        if self.min_step > self.max_step:
            raise ProtocolError(Fault.OUT_OF_RANGE, encode(self, check=False),
                                f"min_step {self.min_step} > max_step {self.max_step}")


@dataclass(frozen=True)
class Scan(Message):
    """Device → host: the readings at one step. ``seq`` 0–65535 (+1 per Scan, wraps),
    ``t_ms`` the device clock in ms (wraps at 2³²), ``counts`` one ADC count per sensor."""

    TYPE: ClassVar[str] = "IRSCN"
    SPEC: ClassVar[tuple] = ((0, SEQ_MODULO - 1), _ANY_STEP, (0, CLOCK_MODULO - 1))
    COUNT: ClassVar[tuple] = (0, CLOCK_MODULO - 1)  # each count; the host checks adc_bits
    seq: int
    step: int
    t_ms: int
    counts: tuple[int, ...]


@dataclass(frozen=True)
class Done(Message):
    """Device → host: sweep finished or stopped; ``seq`` of the last Scan sent (−1: none)."""

    TYPE: ClassVar[str] = "IRDON"
    SPEC: ClassVar[tuple] = ((-1, SEQ_MODULO - 1),)
    seq: int


@dataclass(frozen=True)
class Position(Message):
    """Device → host: the motor is at ``step``."""

    TYPE: ClassVar[str] = "IRPOS"
    SPEC: ClassVar[tuple] = (_ANY_STEP,)
    step: int


@dataclass(frozen=True)
class ErrorReply(Message):
    """Device → host: ``IRERR,<code>,<text>`` (codes in :data:`ERROR_TEXT`). The text field
    may be absent on the wire (``IRERR,1``); it then decodes as ""."""

    TYPE: ClassVar[str] = "IRERR"
    SPEC: ClassVar[tuple] = ((1, 99), TEXT)
    code: int
    text: str = ""


AnyMessage = Union[Hello, SweepCommand, GoTo, Stop, Info, Scan, Done, Position, ErrorReply]
MESSAGE_TYPES: dict[str, type[Message]] = {
    cls.TYPE: cls for cls in (Hello, SweepCommand, GoTo, Stop, Info, Scan, Done, Position,
                              ErrorReply)}
HOST_TYPES = frozenset({"IRHLO", "IRSWP", "IRGTO", "IRSTP"})


# --------------------------------------------------------------------------- encode

_TYPE_RE = re.compile(rb"IR[A-Z]{3}")
_INT_RE = re.compile(rb"-?[0-9]+")
_HEX = b"0123456789ABCDEF"

# The check value's hex digits per protocol version: v1 an 8-bit XOR, v2 a CRC-16.
CHECK_DIGITS = {1: 2, 2: 4}

# v2's CRC: CRC-16/IBM-SDLC (also called CRC-16/X-25; HDLC's and PPP's frame check):
# width 16, poly 0x1021, init 0xFFFF, refin and refout true, xorout 0xFFFF;
# check value (the CRC of b"123456789") 0x906E. Reflected, so its bits run in the UART's
# order (least significant bit first): a burst of up to 16 bits on the wire is a burst of
# up to 16 in the polynomial, which a CRC-16 always detects.
CRC16_POLY_REFLECTED = 0x8408
CRC16_INIT = 0xFFFF
CRC16_XOROUT = 0xFFFF
CRC16_CHECK = 0x906E


def _crc16_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ CRC16_POLY_REFLECTED if crc & 1 else crc >> 1
        table.append(crc)
    return tuple(table)


_CRC16_TABLE = _crc16_table()


def crc16_oracle(body: bytes) -> int:
    """CRC-16/IBM-SDLC of ``body``, byte by byte from its table: the readable statement
    that :func:`crc16` (the fast one) is tested against."""
    crc = CRC16_INIT
    for byte in body:
        crc = (crc >> 8) ^ _CRC16_TABLE[(crc ^ byte) & 0xFF]
    return crc ^ CRC16_XOROUT


# binascii.crc_hqx is the same polynomial unreflected, in C: fed each byte bit-reversed
# and its result bit-reversed, it computes the reflected CRC, several times faster than
# the table loop (docs/protocol.md).
_REVERSED = bytes(int(f"{b:08b}"[::-1], 2) for b in range(256))


def crc16(body: bytes) -> int:
    """CRC-16/IBM-SDLC of ``body`` (protocol v2's check of the bytes between `$` and `*`)."""
    crc = binascii.crc_hqx(bytes(body).translate(_REVERSED), CRC16_INIT)
    return ((_REVERSED[crc & 0xFF] << 8) | _REVERSED[crc >> 8]) ^ CRC16_XOROUT


def xor8(body: bytes) -> int:
    """XOR of every byte of ``body``: protocol v1's checksum."""
    cs = 0
    for byte in body:
        cs ^= byte
    return cs


_CHECK_FIELD = {1: re.compile(rb"[0-9A-Fa-f]{2}"), 2: re.compile(rb"[0-9A-Fa-f]{4}")}


def misframing(line: bytes, version: int = PROTOCOL_VERSION) -> str | None:
    """What a rejected sentence got wrong, when it is a mistake a firmware makes in every
    sentence rather than line noise (the check field in lower case, another CRC-16 than
    IBM-SDLC, \\n without \\r), said for a person; None if it is none of those."""
    line = bytes(line)
    star = line.rfind(b"*")
    if not line.startswith(b"$") or star < 0 or not line.endswith(b"\n"):
        return None
    body, cs = line[1:star], line[star + 1:].rstrip(b"\r\n")
    if not _CHECK_FIELD[check_version(version)].fullmatch(cs) or \
            line[star + 1:] not in (cs + b"\r\n", cs + b"\n"):
        return None
    mistakes = []
    if not line.endswith(b"\r\n"):
        mistakes.append("it ends with \\n alone; a sentence ends with \\r\\n")
    if cs != cs.upper():
        mistakes.append("its check field is in lower-case hex; the protocol's is upper-case")
    value = int(cs, 16)
    right = crc16(body) if version == 2 else xor8(body)
    if value != right:
        if version != 2:
            return None
        unreflected = "the unreflected polynomial from {}: avr-libc's _crc_xmodem_update"
        known = {binascii.crc_hqx(body, 0): f"CRC-16/XMODEM ({unreflected.format(0)})",
                 binascii.crc_hqx(body, 0xFFFF): "CRC-16/CCITT-FALSE "
                                                 f"({unreflected.format('0xFFFF')})",
                 right ^ CRC16_XOROUT: "CRC-16/IBM-SDLC without the final XOR with 0xFFFF",
                 ((right & 0xFF) << 8) | (right >> 8): "CRC-16/IBM-SDLC with its two bytes "
                                                       "swapped"}
        if value not in known:
            return None
        name = known[value]
        mistakes.append(f"its check is {name}" + ("" if name.startswith("CRC-16/IBM-SDLC")
                                                  else ", not CRC-16/IBM-SDLC"))
    return "; ".join(mistakes) or None


def check_version(version: int) -> int:
    """``version`` if this irring can frame it, else ValueError naming the allowed ones."""
    if version not in PROTOCOL_VERSIONS:
        raise ValueError(f"IRR protocol version {version!r}: this irring frames versions "
                         f"{', '.join(map(str, PROTOCOL_VERSIONS))}")
    return version


def checksum(body: bytes, version: int = PROTOCOL_VERSION) -> bytes:
    """The check field of a sentence whose bytes between `$` and `*` are ``body``: four
    upper-case hex digits of :func:`crc16` (v2), two of :func:`xor8` (v1)."""
    if check_version(version) == 1:
        return b"%02X" % xor8(body)
    return b"%04X" % crc16(body)


def frame(body: bytes, version: int = PROTOCOL_VERSION) -> bytes:
    """``$body*CHECK\\r\\n``: one sentence around ``body``, whatever its fields say."""
    return b"$" + bytes(body) + b"*" + checksum(body, version) + b"\r\n"


def text_ok(text: str) -> bool:
    """Whether an IRR text field can carry ``text``: printable ASCII but ``$``, ``*``, ``,``."""
    return all(0x20 <= ord(c) <= 0x7E and c not in "$*," for c in text)


def _field_values(msg: Message) -> list:
    values = [getattr(msg, f.name) for f in fields(msg)]
    if isinstance(msg, Scan):
        values = values[:-1] + list(msg.counts)
    if isinstance(msg, ErrorReply) and msg.text == "":
        values = values[:-1]  # `IRERR,1` is a valid sentence
    return values


def encode(msg: Message, *, check: bool = True, version: int = PROTOCOL_VERSION) -> bytes:
    """The bytes of one sentence for ``msg``, ``$`` to ``\\r\\n``, framed for ``version``.

    Raises ValueError if a field is out of its range, a text field holds a reserved or
    unprintable character, or the sentence would exceed 128 bytes.
    """
    parts = [msg.TYPE.encode("ascii")]
    for i, value in enumerate(_field_values(msg)):
        if isinstance(value, str):
            if check and not text_ok(value):
                raise ValueError(f"{msg.TYPE} text {value!r}: only printable ASCII without "
                                 f"`$`, `*` or `,` may be sent")
            parts.append(value.encode("ascii"))
        else:
            value = int(value)
            if check:
                lo, hi = _bounds(msg, i)
                if not lo <= value <= hi:
                    raise ValueError(f"{msg.TYPE} field {i + 1} = {value} is outside {lo} … {hi}")
            parts.append(str(value).encode("ascii"))
    body = b",".join(parts)
    line = frame(body, version)
    if check and len(line) > MAX_SENTENCE_BYTES:
        raise ValueError(f"{msg.TYPE} sentence is {len(line)} bytes; the protocol allows "
                         f"{MAX_SENTENCE_BYTES}")
    return line


def _bounds(msg: Message | type[Message], i: int) -> tuple[int, int] | str:
    """Field ``i``'s kind: its (lo, hi) bounds, or TEXT."""
    spec = msg.SPEC
    if i < len(spec):
        return spec[i]
    return Scan.COUNT  # the variable tail of IRSCN


# --------------------------------------------------------------------------- decode


def decode(line: bytes, *, version: int = PROTOCOL_VERSION) -> AnyMessage:
    """Decode one whole sentence (``$`` … ``\\r\\n``) framed for ``version`` or raise
    :class:`ProtocolError` (OTHER_VERSION: a check field of the other version's length)."""
    line = bytes(line)
    if len(line) > MAX_SENTENCE_BYTES:
        raise ProtocolError(Fault.TOO_LONG, line, f"{len(line)} bytes")
    if not line.startswith(b"$"):
        raise ProtocolError(Fault.NO_START, line)
    if not line.endswith(b"\r\n"):
        raise ProtocolError(Fault.NO_TERMINATOR, line)
    star = line.rfind(b"*")
    if star < 0:
        raise ProtocolError(Fault.NO_CHECKSUM, line)
    body, cs = line[1:star], line[star + 1:-2]
    digits = CHECK_DIGITS[version]
    if any(c not in _HEX for c in cs):
        raise ProtocolError(Fault.BAD_CHECKSUM_FORMAT, line, f"got {cs!r}")
    if len(cs) != digits:
        other = [v for v, n in CHECK_DIGITS.items() if n == len(cs)]
        if other:
            raise ProtocolError(Fault.OTHER_VERSION, line, f"{len(cs)} hex digits: a protocol "
                                f"v{other[0]} check; this link speaks v{version} ({digits})")
        raise ProtocolError(Fault.BAD_CHECKSUM_FORMAT, line, f"got {cs!r}")
    expected = checksum(body, version)
    if cs != expected:
        raise ProtocolError(Fault.CHECKSUM_MISMATCH, line,
                            f"sent {cs.decode()}, computed {expected.decode()}")
    if any(b < 0x20 or b > 0x7E or b in b"$*" for b in body):
        raise ProtocolError(Fault.BAD_CHARACTER, line)
    tag, *raw_fields = body.split(b",")
    if not _TYPE_RE.fullmatch(tag):
        raise ProtocolError(Fault.BAD_TYPE, line, f"got {tag!r}")
    cls = MESSAGE_TYPES.get(tag.decode())
    if cls is None:
        raise ProtocolError(Fault.UNKNOWN_TYPE, line, f"{tag.decode()}")
    values = _parse_fields(cls, raw_fields, line)
    if cls is Scan:
        msg = Scan(*values[:3], counts=tuple(values[3:]))
    else:
        msg = cls(*values)
    msg.check()
    return msg


def _parse_fields(cls: type[Message], raw: list[bytes], line: bytes) -> list:
    n_spec = len(cls.SPEC)
    if cls is Scan:
        ok = len(raw) >= n_spec + 1
        want = f"at least {n_spec + 1}"
    elif cls is ErrorReply:
        ok = len(raw) in (1, 2)
        want = "1 or 2"
    else:
        ok = len(raw) == n_spec
        want = str(n_spec)
    if not ok:
        raise ProtocolError(Fault.FIELD_COUNT, line, f"{cls.TYPE} takes {want}, got {len(raw)}")
    values: list = []
    names = [f.name for f in fields(cls)]
    for i, text in enumerate(raw):
        kind = _bounds(cls, i)
        what = f"{cls.TYPE} field {i + 1} ({names[min(i, len(names) - 1)]})"
        if kind == TEXT:
            values.append(text.decode("ascii"))  # characters were checked above
            continue
        if not _INT_RE.fullmatch(text):
            raise ProtocolError(Fault.BAD_FIELD, line,
                                f"{what} {text!r} is not a decimal integer")
        value = int(text)
        lo, hi = kind
        if not lo <= value <= hi:
            raise ProtocolError(Fault.OUT_OF_RANGE, line,
                                f"{what} = {value} is outside {lo} … {hi}")
        values.append(value)
    return values


# --------------------------------------------------------------------------- stream


class Decoder:
    """Cuts a byte stream into sentences; never raises on what it is fed.

    ``feed(data)`` returns, in arrival order, every decoded message and every
    :class:`ProtocolError` for a rejected sentence. Bytes outside a sentence are ignored
    (counted in ``ignored_bytes``); a ``$`` inside a sentence ends it as INTERRUPTED and
    starts a new one; a sentence that grows past 128 bytes without ``\\n`` is TOO_LONG and
    the decoder hunts for the next ``$``. ``version`` frames the sentences it accepts
    (settable between feeds: a host learns the device's in the handshake).
    """

    def __init__(self, version: int = PROTOCOL_VERSION) -> None:
        self.version = check_version(version)
        self._buf = bytearray()
        self._in_sentence = False
        self._overflow = False  # discarding the rest of a too-long sentence
        self.ignored_bytes = 0

    def reset(self) -> None:
        self._buf.clear()
        self._in_sentence = False
        self._overflow = False

    def feed(self, data: bytes) -> list[AnyMessage | ProtocolError]:
        out: list[AnyMessage | ProtocolError] = []
        i, n = 0, len(data)
        while i < n:
            if not self._in_sentence:
                start = data.find(b"$", i)
                if start < 0:
                    self.ignored_bytes += n - i
                    break
                self.ignored_bytes += start - i
                self._buf = bytearray(b"$")
                self._in_sentence, self._overflow = True, False
                i = start + 1
                continue
            # inside a sentence: copy up to the next `$` or `\n`, whichever comes first
            j = i
            while j < n and data[j] not in (0x24, 0x0A):  # `$`, `\n`
                j += 1
            if not self._overflow:
                self._buf += data[i:j]
                if len(self._buf) >= MAX_SENTENCE_BYTES:  # no room left for `\n`
                    out.append(ProtocolError(Fault.TOO_LONG, bytes(self._buf),
                                             f"no end within {MAX_SENTENCE_BYTES} bytes"))
                    self._overflow = True
                    self._buf.clear()
            else:
                self.ignored_bytes += j - i
            if j == n:
                break
            if data[j] == 0x24:  # `$`: a new sentence starts, the current one is cut short
                if not self._overflow:
                    out.append(ProtocolError(Fault.INTERRUPTED, bytes(self._buf)))
                self._in_sentence = False
                i = j
                continue
            # `\n` ends the sentence
            if not self._overflow:
                self._buf += b"\n"
                try:
                    out.append(decode(bytes(self._buf), version=self.version))
                except ProtocolError as exc:
                    # returned, not raised: without its traceback it holds no frames (whose
                    # locals a caller's big arrays may be) in a cycle only the GC breaks
                    out.append(exc.with_traceback(None))
            else:
                self.ignored_bytes += 1
            self._in_sentence, self._overflow = False, False
            self._buf = bytearray()
            i = j + 1
        return out


# --------------------------------------------------------------------------- geometry
# IRINF carries the motor step in millidegrees and the belt ratio as a fraction; these map
# it to and from the project's Ring (SI units). Pure arithmetic, no I/O.

GEAR_MAX_DENOMINATOR = 10_000


def ring_from_info(info: Info, template: Ring, *, radius_m: float | None = None,
                   emitter_offset_m: float | None = None) -> Ring:
    """The Ring a device describes: sensors, step, belt ratio and step limits from IRINF;
    radius, emitter offset, sensor height and joint limit from ``template`` (the device does
    not report them) unless given. Where IRINF agrees with the template to the protocol's
    resolution, the template's exact float is kept so equal designs compare equal."""
    step_rad = math.radians(info.step_mdeg / 1000.0)
    if _step_mdeg(template.motor_step_rad) == info.step_mdeg:
        step_rad = template.motor_step_rad
    gear = info.gear_num / info.gear_den
    if _gear_fraction(template.gear) == Fraction(info.gear_num, info.gear_den):
        gear = template.gear
    changes: dict = dict(sensors=info.nsensors, motor_step_rad=step_rad, gear=gear,
                         min_step=info.min_step, max_step=info.max_step)
    if radius_m is not None:
        changes["radius_m"] = float(radius_m)
    if emitter_offset_m is not None:
        changes["emitter_offset_m"] = float(emitter_offset_m)
    return dataclasses.replace(template, **changes)


def info_for_ring(ring: Ring, adc_bits: int, firmware: str,
                  version: int = PROTOCOL_VERSION) -> Info:
    """The IRINF a device with this ring speaking ``version`` sends (step rounded to
    0.001°, belt ratio to a fraction with denominator ≤ 10 000)."""
    gear = _gear_fraction(ring.gear)
    return Info(check_version(version), ring.sensors, adc_bits, _step_mdeg(ring.motor_step_rad),
                gear.numerator, gear.denominator, ring.min_step, ring.max_step, firmware)


def longest_scan_bytes(info: Info, sensors: int | None = None) -> int:
    """Bytes of the longest IRSCN a device of ``info`` (with ``sensors`` in place of its
    count) can send: every count at the ADC's top, the longest seq, step and clock."""
    n = info.nsensors if sensors is None else sensors
    step = max(info.min_step, info.max_step, key=lambda s: len(str(s)))
    scan = Scan(SEQ_MODULO - 1, step, CLOCK_MODULO - 1, ((1 << info.adc_bits) - 1,) * n)
    return len(encode(scan, check=False, version=info.proto))


def scan_too_long(info: Info) -> str | None:
    """Why a device of ``info`` could send an IRSCN longer than the protocol allows, naming
    how many sensors would fit (None: every IRSCN fits)."""
    longest = longest_scan_bytes(info)
    if longest <= MAX_SENTENCE_BYTES:
        return None
    fit = info.nsensors
    while fit > 0 and longest_scan_bytes(info, fit) > MAX_SENTENCE_BYTES:
        fit -= 1
    return (f"{info.nsensors} sensors with a {info.adc_bits}-bit ADC send IRSCN sentences of "
            f"up to {longest} bytes (every count {(1 << info.adc_bits) - 1}, seq "
            f"{SEQ_MODULO - 1}, clock {CLOCK_MODULO - 1} ms), and IRR protocol v{info.proto} "
            f"allows {MAX_SENTENCE_BYTES}: at most {fit} sensors at {info.adc_bits} bits fit")


def _step_mdeg(step_rad: float) -> int:
    """A motor step as IRINF carries it: whole millidegrees."""
    return round(math.degrees(step_rad) * 1000)


def _gear_fraction(gear: float) -> Fraction:
    """A belt ratio as IRINF carries it: a fraction with denominator ≤ 10 000."""
    return Fraction(gear).limit_denominator(GEAR_MAX_DENOMINATOR)
