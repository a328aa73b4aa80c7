"""IRR protocol v2: docs/protocol.md's test vectors and CRC, every malformed kind, stream
resync, and v1 framing (an old device's) kept apart from v2."""

from __future__ import annotations

import binascii
import re
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import numpy as np

from irring.designs import PAPER_RING
from irring.hardware import protocol as p

DOC = (Path(__file__).resolve().parents[1] / "docs" / "protocol.md").read_text()
# docs/protocol.md, section "Example", copied verbatim (host and device lines).
EXAMPLE = [
    b"$IRHLO*26D0",
    b"$IRINF,2,12,12,1800,3,5,-35,35,atmega8535-2.0*2FB3",
    b"$IRSWP,-35,35,1,40*45E7",
    b"$IRSCN,0,-35,1000,812,790,1203,1510,655,700,702,1498,2210,980,640,633*9565",
    b"$IRSCN,1,-34,1041,815,788,1190,1532,660,698,705,1488,2251,979,641,630*9B26",
    b"$IRDON,70*6212",
    b"$IRERR,4,step out of range*64CF",
]
EXAMPLE_GTO = b"$IRGTO,99*86A9"
# v1's XOR of `IRGTO,99` is 0x6B; the first specification printed 0x73. Both are dropped by v2.
V1_GTO, V1_BAD_GTO = b"$IRGTO,99*6B", b"$IRGTO,99*73"


def sentence(body: str | bytes, version: int = 2) -> bytes:
    """A sentence with the right check field, so a test isolates one other fault."""
    body = body.encode("latin-1") if isinstance(body, str) else body
    return p.frame(body, version)


def test_the_examples_here_are_the_documents():
    example = DOC.split("## Example", 1)[1].split("##", 1)[0]
    lines = re.findall(r"^(?:host|device):\s+(\$.*?\*[0-9A-F]{4})", example, re.M)
    assert [ln.encode() for ln in lines] == EXAMPLE[:5] + EXAMPLE[5:6] + [EXAMPLE_GTO] + EXAMPLE[6:]


def test_the_readmes_protocol_lines_are_v2_sentences():
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    block = readme.split("### The protocol in one screen", 1)[1].split("```\n", 2)[1]
    lines = [ln.encode() + b"\r\n" for ln in block.splitlines() if ln.startswith("$")]
    assert len(lines) == 9
    for line in lines:
        assert p.encode(p.decode(line)) == line


def test_crc_check_value_parameters_and_fast_path_agree_with_the_oracle():
    # the catalogue's check value for CRC-16/IBM-SDLC, and the document's
    assert p.crc16(b"123456789") == p.crc16_oracle(b"123456789") == p.CRC16_CHECK == 0x906E
    assert "is 0x906E" in DOC
    # the document's bit-by-bit loop (its code block), run as written
    code = DOC.split("```python\n", 1)[1].split("```", 1)[0]
    scope: dict = {}
    exec(code, scope)
    # unreflected CCITT from 0xFFFF (CRC-16/CCITT-FALSE, binascii.crc_hqx) is another CRC
    assert binascii.crc_hqx(b"123456789", 0xFFFF) == 0x29B1
    rng = np.random.default_rng(11)
    for n in (0, 1, 2, 7, 64, 125):
        body = bytes(rng.integers(0, 256, n, dtype=np.uint8))
        assert p.crc16(body) == p.crc16_oracle(body) == scope["crc16"](body)


def test_worked_example_frame_bytes_and_register_trace():
    line = p.encode(p.GoTo(5))
    assert line == b"$IRGTO,5*B470\r\n"
    assert line.hex(" ").upper() in DOC
    crc, trace = p.CRC16_INIT, []
    for byte in b"IRGTO,5":
        crc = (crc >> 8) ^ p._CRC16_TABLE[(crc ^ byte) & 0xFF]
        trace.append(f"{crc:04X}")
    assert "| register | " + " | ".join(trace) + " |" in DOC
    assert trace[-1] == "4B8F" and 0x4B8F ^ 0xFFFF == 0xB470


@pytest.mark.parametrize("line", EXAMPLE + [EXAMPLE_GTO])
def test_protocol_md_examples_decode_and_reencode_byte_for_byte(line):
    msg = p.decode(line + b"\r\n")
    assert p.encode(msg) == line + b"\r\n"


def test_protocol_md_example_values():
    info = p.decode(EXAMPLE[1] + b"\r\n")
    assert (info.nsensors, info.adc_bits, info.step_mdeg, info.gear_num, info.gear_den,
            info.min_step, info.max_step, info.firmware) == (12, 12, 1800, 3, 5, -35, 35,
                                                               "atmega8535-2.0")
    scan = p.decode(EXAMPLE[3] + b"\r\n")
    assert (scan.seq, scan.step, scan.t_ms, len(scan.counts), scan.counts[0]) == (0, -35, 1000,
                                                                                  12, 812)
    assert p.decode(EXAMPLE[2] + b"\r\n") == p.SweepCommand(-35, 35, 1, 40)
    assert p.decode(EXAMPLE[-1] + b"\r\n") == p.ErrorReply(4, "step out of range")


def test_v1_lines_decode_only_as_v1_and_v2_lines_only_as_v2():
    assert p.decode(V1_GTO + b"\r\n", version=1) == p.GoTo(99)
    with pytest.raises(p.ProtocolError) as err:
        p.decode(V1_BAD_GTO + b"\r\n", version=1)
    assert err.value.fault is p.Fault.CHECKSUM_MISMATCH and "computed 6B" in str(err.value)
    with pytest.raises(p.ProtocolError) as err:
        p.decode(V1_GTO + b"\r\n")
    assert err.value.fault is p.Fault.OTHER_VERSION
    assert "2 hex digits: a protocol v1 check; this link speaks v2 (4)" in str(err.value)
    with pytest.raises(p.ProtocolError) as err:
        p.decode(EXAMPLE_GTO + b"\r\n", version=1)
    assert err.value.fault is p.Fault.OTHER_VERSION
    assert "4 hex digits: a protocol v2 check; this link speaks v1 (2)" in str(err.value)
    with pytest.raises(ValueError, match="version 3: this irring frames versions 1, 2"):
        p.Decoder(3)


def test_v1_xor_cannot_tell_two_changes_in_one_bit_column_apart_and_v2_can():
    # the document's example: IRINF's `1` → `2` in two places keeps the XOR
    v1 = p.encode(p.Info(1, 12, 12, 1800, 3, 5, -35, 35, "atmega8535-1.0"), version=1)
    v2_text = p.encode(p.Info(2, 12, 12, 1800, 3, 5, -35, 35, "atmega8535-2.0"), version=1)
    assert v1[-4:] == v2_text[-4:] == b"77\r\n"
    assert p.checksum(v1[1:-5]) != p.checksum(v2_text[1:-5])
    assert v2_text[1:-5] + b"*77" in DOC.encode() and b"*2FB3" in DOC.encode()


def test_paper_ring_and_example_irinf_map_to_each_other_exactly():
    info = p.decode(EXAMPLE[1] + b"\r\n")
    assert p.info_for_ring(PAPER_RING, 12, "atmega8535-2.0") == info
    assert p.ring_from_info(info, PAPER_RING) == PAPER_RING
    other = p.Info(1, 8, 10, 900, 1, 2, -10, 20, "x")
    ring = p.ring_from_info(other, PAPER_RING, radius_m=0.2, emitter_offset_m=0.01)
    assert (ring.sensors, ring.gear, ring.min_step, ring.max_step, ring.radius_m,
            ring.emitter_offset_m) == (8, 0.5, -10, 20, 0.2, 0.01)
    assert ring.motor_step_rad == pytest.approx(0.9 * 3.141592653589793 / 180)


# --------------------------------------------------------------------------- malformed

MALFORMED = [
    # (why, bytes, fault)
    ("no $", b"IRHLO*26D0\r\n", p.Fault.NO_START),
    ("129 bytes", sentence(f"IRSCN,0,1,2,{'1' * 114}"), p.Fault.TOO_LONG),
    ("bare \\n", b"$IRHLO*26D0\n", p.Fault.NO_TERMINATOR),
    ("bare \\r", b"$IRHLO*26D0\r", p.Fault.NO_TERMINATOR),
    ("no terminator", b"$IRHLO*26D0", p.Fault.NO_TERMINATOR),
    ("no *", b"$IRHLO\r\n", p.Fault.NO_CHECKSUM),
    ("one hex digit", b"$IRHLO*2\r\n", p.Fault.BAD_CHECKSUM_FORMAT),
    ("three hex digits", b"$IRHLO*26D\r\n", p.Fault.BAD_CHECKSUM_FORMAT),
    ("five hex digits", b"$IRHLO*26D00\r\n", p.Fault.BAD_CHECKSUM_FORMAT),
    ("lower-case hex", b"$IRGTO,99*86a9\r\n", p.Fault.BAD_CHECKSUM_FORMAT),
    ("not hex", b"$IRHLO*G6D0\r\n", p.Fault.BAD_CHECKSUM_FORMAT),
    ("v1 check", b"$IRHLO*50\r\n", p.Fault.OTHER_VERSION),
    ("wrong checksum", b"$IRHLO*26D1\r\n", p.Fault.CHECKSUM_MISMATCH),
    ("control byte", sentence(b"IRERR,1,bad\x01text"), p.Fault.BAD_CHARACTER),
    ("8-bit byte", sentence(b"IRERR,1,caf\xe9"), p.Fault.BAD_CHARACTER),
    ("tab", sentence(b"IRGTO,\t5"), p.Fault.BAD_CHARACTER),
    ("lower-case type", sentence("irhlo"), p.Fault.BAD_TYPE),
    ("not IR", sentence("XXHLO"), p.Fault.BAD_TYPE),
    ("4 letters", sentence("IRHL"), p.Fault.BAD_TYPE),
    ("6 letters", sentence("IRHLOO"), p.Fault.BAD_TYPE),
    ("digit in type", sentence("IRHL0"), p.Fault.BAD_TYPE),
    ("empty", sentence(""), p.Fault.BAD_TYPE),
    ("unknown type", sentence("IRABC"), p.Fault.UNKNOWN_TYPE),
    ("field on IRHLO", sentence("IRHLO,1"), p.Fault.FIELD_COUNT),
    ("IRSWP 3 fields", sentence("IRSWP,-35,35,1"), p.Fault.FIELD_COUNT),
    ("IRSWP 5 fields", sentence("IRSWP,-35,35,1,40,0"), p.Fault.FIELD_COUNT),
    ("IRSCN no counts", sentence("IRSCN,0,-35,1000"), p.Fault.FIELD_COUNT),
    ("IRINF 8 fields", sentence("IRINF,1,12,12,1800,3,5,-35,35"), p.Fault.FIELD_COUNT),
    ("IRERR 3 fields", sentence("IRERR,1,a,b"), p.Fault.FIELD_COUNT),
    ("IRDON no field", sentence("IRDON"), p.Fault.FIELD_COUNT),
    ("plus sign", sentence("IRGTO,+5"), p.Fault.BAD_FIELD),
    ("decimal point", sentence("IRGTO,1.5"), p.Fault.BAD_FIELD),
    ("empty field", sentence("IRGTO,"), p.Fault.BAD_FIELD),
    ("trailing comma", sentence("IRDON,70,"), p.Fault.FIELD_COUNT),
    ("space", sentence("IRGTO, 5"), p.Fault.BAD_FIELD),
    ("hex number", sentence("IRGTO,0x10"), p.Fault.BAD_FIELD),
    ("double minus", sentence("IRGTO,--1"), p.Fault.BAD_FIELD),
    ("text where int", sentence("IRERR,x,oops"), p.Fault.BAD_FIELD),
    ("samples 0", sentence("IRSWP,-35,35,0,40"), p.Fault.OUT_OF_RANGE),
    ("samples 65", sentence("IRSWP,-35,35,65,40"), p.Fault.OUT_OF_RANGE),
    ("negative settle", sentence("IRSWP,-35,35,1,-1"), p.Fault.OUT_OF_RANGE),
    ("seq 65536", sentence("IRSCN,65536,0,0,1"), p.Fault.OUT_OF_RANGE),
    ("seq -1 on IRSCN", sentence("IRSCN,-1,0,0,1"), p.Fault.OUT_OF_RANGE),
    ("clock 2^32", sentence("IRSCN,0,0,4294967296,1"), p.Fault.OUT_OF_RANGE),
    ("negative count", sentence("IRSCN,0,0,0,5,-1"), p.Fault.OUT_OF_RANGE),
    ("IRDON -2", sentence("IRDON,-2"), p.Fault.OUT_OF_RANGE),
    ("IRINF min > max", sentence("IRINF,1,12,12,1800,3,5,35,-35,fw"), p.Fault.OUT_OF_RANGE),
    ("IRINF 0 sensors", sentence("IRINF,1,0,12,1800,3,5,-35,35,fw"), p.Fault.OUT_OF_RANGE),
    ("IRINF gear 3/0", sentence("IRINF,1,12,12,1800,3,0,-35,35,fw"), p.Fault.OUT_OF_RANGE),
    ("step beyond int32", sentence("IRGTO,2147483648"), p.Fault.OUT_OF_RANGE),
]


@pytest.mark.parametrize("why,line,fault", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_every_malformed_kind_is_rejected(why, line, fault):
    with pytest.raises(p.ProtocolError) as err:
        p.decode(line)
    assert err.value.fault is fault
    assert err.value.raw == line[:len(err.value.raw)]


def test_every_fault_kind_has_a_malformed_example():
    covered = {m[2] for m in MALFORMED} | {p.Fault.INTERRUPTED}  # stream-only, tested below
    assert covered == set(p.Fault)


def test_128_bytes_is_allowed_129_is_not():
    body = "IRSCN,1,1,2," + ",".join(["4095"] * 21 + ["409"])  # 120 bytes between `$` and `*`
    line = sentence(body)
    assert len(line) == 128
    assert len(p.decode(line).counts) == 22
    assert p.Decoder().feed(line)[0] == p.decode(line)
    longer = sentence(body.replace("IRSCN,1", "IRSCN,10"))
    assert len(longer) == 129
    (err,) = p.Decoder().feed(longer)
    assert err.fault is p.Fault.TOO_LONG


def test_device_error_codes_follow_the_protocol():
    assert p.Fault.CHECKSUM_MISMATCH.device_error_code == 1
    assert p.Fault.FIELD_COUNT.device_error_code == 1
    assert p.Fault.UNKNOWN_TYPE.device_error_code == 2
    assert p.Fault.OUT_OF_RANGE.device_error_code == 3


def test_irerr_text_is_optional_on_the_wire():
    assert p.decode(sentence("IRERR,1")) == p.ErrorReply(1, "")
    assert p.encode(p.ErrorReply(1)) == sentence("IRERR,1")


@pytest.mark.parametrize("msg,why", [
    (p.ErrorReply(1, "a,b"), "printable ASCII"),
    (p.Info(1, 12, 12, 1800, 3, 5, -35, 35, "fw*1"), "printable ASCII"),
    (p.SweepCommand(-35, 35, 0, 40), "outside 1 … 64"),
    (p.Scan(70000, 0, 0, (1,)), "outside 0 … 65535"),
    (p.Scan(0, 0, 0, (4095,) * 30), "128"),
])
def test_encode_refuses_what_a_receiver_would_drop(msg, why):
    with pytest.raises(ValueError, match=why):
        p.encode(msg)


# --------------------------------------------------------------------------- stream


def test_garbage_stream_resyncs_at_the_next_dollar():
    wanted = [p.Hello(), p.Done(70), p.Scan(3, -2, 99, (1, 2, 3))]
    stream = (b"\x00\xffnoise\r\n" + p.encode(wanted[0])
              + b"$IRSC" + p.encode(wanted[1])             # cut short by the next `$`
              + b"$" + b"x" * 300 + b"\r\n"                # far too long, then a newline
              + b"*12\r\n$IRHLO*0000\r\n"                  # stray tail, bad checksum
              + p.encode(wanted[2]))
    out = p.Decoder().feed(stream)
    messages = [m for m in out if not isinstance(m, p.ProtocolError)]
    faults = [m.fault for m in out if isinstance(m, p.ProtocolError)]
    assert messages == wanted
    assert faults == [p.Fault.INTERRUPTED, p.Fault.TOO_LONG, p.Fault.CHECKSUM_MISMATCH]


def test_rejections_are_returned_without_a_traceback():
    """A returned ProtocolError with its traceback held the frames down to the caller's
    (and their locals) in a cycle until the GC ran: `irring bench link` peaked at 690 MB."""
    (err,) = p.Decoder().feed(b"$IRHLO*0000\r\n")
    assert err.fault is p.Fault.CHECKSUM_MISMATCH and err.__traceback__ is None


def test_decoder_counts_ignored_bytes():
    dec = p.Decoder()
    dec.feed(b"abc" + p.encode(p.Hello()) + b"\r\n\x00")
    assert dec.ignored_bytes == 6


# --------------------------------------------------------------------------- fuzzing

ints = st.integers
text = st.text(st.characters(min_codepoint=0x20, max_codepoint=0x7E, blacklist_characters="$*,"),
               max_size=20)
messages = st.one_of(
    st.builds(p.Hello), st.builds(p.Stop),
    st.builds(p.SweepCommand, ints(-1000, 1000), ints(-1000, 1000), ints(1, 64), ints(0, 10**6)),
    st.builds(p.GoTo, ints(p.INT32_MIN, p.INT32_MAX)),
    st.builds(p.Info, ints(1, 9), ints(1, 72), ints(1, 32), ints(1, 360_000), ints(1, 1000),
              ints(1, 1000), ints(-100, 0), ints(0, 100), text),
    st.builds(p.Scan, ints(0, 65535), ints(-1000, 1000), ints(0, 2**32 - 1),
              st.lists(ints(0, 65535), min_size=1, max_size=12).map(tuple)),
    st.builds(p.Done, ints(-1, 65535)),
    st.builds(p.Position, ints(-10**6, 10**6)),
    st.builds(p.ErrorReply, ints(1, 99), text),
)


@settings(max_examples=300, deadline=None)
@given(messages)
def test_encode_decode_round_trip(msg):
    line = p.encode(msg)
    assert len(line) <= p.MAX_SENTENCE_BYTES
    assert p.decode(line) == msg
    assert p.encode(p.decode(line)) == line


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=600))
def test_decoder_never_raises_on_arbitrary_bytes(data):
    for item in p.Decoder().feed(data):
        assert isinstance(item, (p.Message, p.ProtocolError))


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300), messages)
def test_a_sentence_after_any_garbage_is_recovered(garbage, msg):
    out = p.Decoder().feed(garbage + p.encode(msg))
    assert out[-1] == msg


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.binary(max_size=30).map(lambda b: b.replace(b"$", b"")), messages),
                max_size=8),
       st.lists(ints(1, 40), min_size=1, max_size=10))
def test_chunking_does_not_change_what_is_decoded(items, cuts):
    stream = b"".join(g + p.encode(m) for g, m in items)
    whole = p.Decoder().feed(stream)
    dec, pieces, i, k = p.Decoder(), [], 0, 0
    while i < len(stream):
        n = cuts[k % len(cuts)]
        pieces += dec.feed(stream[i:i + n])
        i, k = i + n, k + 1
    assert [m for m in pieces if isinstance(m, p.Message)] == [m for _, m in items]
    assert [str(m) for m in pieces] == [str(m) for m in whole]


@settings(max_examples=200, deadline=None)
@given(messages, st.data())
def test_any_single_corrupted_byte_is_never_accepted_as_a_different_message(msg, data):
    line = bytearray(p.encode(msg))
    i = data.draw(st.integers(0, len(line) - 1))
    line[i] ^= data.draw(st.integers(1, 255))
    for item in p.Decoder().feed(bytes(line)):
        assert not isinstance(item, p.Message) or item == msg
