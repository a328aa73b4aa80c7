"""Corrupted sentences: protocol v2's CRC-16 lets none of the two-bit errors or ≤ 16-bit
bursts through that v1's XOR lets through (irring/studies/link_integrity.py, `irring bench
link`), counted exhaustively for one IRSCN and over 200,000 random ones under a seed."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from irring.cli.bench_link import report
from irring.hardware import protocol as p
from irring.studies import link_integrity as li


def test_bench_link_200000_corrupted_scans_and_every_two_bit_error_of_one():
    """`irring bench link` in a child process (its arrays would stay in this one's memory):
    v2 accepts none of 200,000 bursts of ≤ 16 bits or two-bit errors, nor any of all
    225,456 two-bit errors of one IRSCN, of which v1 accepts 4,147 of 214,840."""
    run = subprocess.run([sys.executable, "-m", "irring", "bench", "link", "--json"],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    result = json.loads(run.stdout)
    rows = {(t["version"], t["kind"]): t for t in result["tallies"]}
    assert (result["trials"], result["seed"], result["target_met"]) == (200_000, 7, True)
    assert all(rows[v, k]["trials"] == 200_000 for v in (1, 2) for k in li.KINDS)
    # a CRC-16 detects every burst of ≤ 16 bits; and no two-bit error got through either
    assert rows[2, "burst16"]["accepted"] == rows[2, "two_bits"]["accepted"] == 0
    v1 = rows[1, "two_bits"]
    assert 0.015 < v1["accepted"] / v1["trials"] < 0.025   # 1.7 % was measured on such scans
    assert v1["changed"] == v1["accepted"]                   # each one with changed values
    assert 0 < rows[1, "burst16"]["accepted"] < 100
    assert (rows[1, "every_two_bits"]["trials"], rows[1, "every_two_bits"]["accepted"],
            rows[1, "every_two_bits"]["changed"]) == (214_840, 4_147, 4_147)
    assert (rows[2, "every_two_bits"]["trials"], rows[2, "every_two_bits"]["accepted"]) == \
        (225_456, 0)
    assert set(result["decode_us_per_scan"]) == {"v1", "v2"}
    text = report(result)
    assert text.startswith("200,000 corrupted IRSCN per row (seed 7); load average ")
    assert "  v2 CRC-16   every_two_bits     225,456         0   0.000%         0" in text
    assert text.endswith("target: v2 accepts no burst of ≤ 16 bits: met")


def test_two_bit_errors_are_every_pair_once():
    line = p.encode(p.Hello())
    frames = li.two_bit_errors(line)
    bits = np.unpackbits(frames ^ np.frombuffer(line, np.uint8), axis=1, bitorder="little")
    assert len(frames) == 104 * 103 // 2 and (bits.sum(axis=1) == 2).all()
    assert len({row.tobytes() for row in frames}) == len(frames)


@pytest.mark.parametrize("kind", li.KINDS)
@pytest.mark.parametrize("version", [1, 2])
def test_vectorised_verdicts_equal_one_decoder_per_sentence(kind, version):
    rng = np.random.default_rng(3)
    sent = li.scans(40, rng)
    encoded = [p.encode(m, version=version) for m in sent]
    pick = rng.integers(0, len(sent), 3000)
    lengths = np.array([len(encoded[i]) for i in pick])
    masks = li.error_masks(lengths, kind, rng)
    frames = np.zeros_like(masks)
    for row, i in enumerate(pick):
        frames[row, :lengths[row]] = np.frombuffer(encoded[i], np.uint8)
    frames ^= masks
    ok, changed = li._verdicts(frames, lengths, version, [sent[i] for i in pick])
    for row, i in enumerate(pick):
        got = li.accepted_oracle(frames[row, :lengths[row]].tobytes(), version)
        assert ok[row] == bool(got) and changed[row] == any(m != sent[i] for m in got)
    if version == 1 and kind == "two_bits":
        assert ok.sum() > 10   # the comparison met accepted sentences too


def test_error_masks_are_what_they_say():
    rng = np.random.default_rng(9)
    lengths = rng.integers(10, 90, 5000)
    bits = np.unpackbits(li.error_masks(lengths, "two_bits", rng), axis=1, bitorder="little")
    assert (bits.sum(axis=1) == 2).all()
    assert (bits.shape[1] - np.argmax(bits[:, ::-1], axis=1) <= lengths * 8).all()
    bits = np.unpackbits(li.error_masks(lengths, "burst16", rng), axis=1, bitorder="little")
    first = np.argmax(bits, axis=1)
    last = bits.shape[1] - 1 - np.argmax(bits[:, ::-1], axis=1)
    span = last - first + 1
    assert (bits.sum(axis=1) >= 1).all() and (last < lengths * 8).all()
    assert span.min() == 1 and span.max() == 16
    assert set(np.bincount(span)[1:]) != {0}   # every span 1 … 16 drawn
    with pytest.raises(ValueError, match="kind 'three': expected one of two_bits, burst16"):
        li.error_masks(lengths, "three", rng)


def _crc_of_error(errors: np.ndarray, reflected: bool) -> np.ndarray:
    """The CRC's linear part (zero start, no final XOR) of each row of error bytes: a body
    changed by an error passes iff this is 0 (a CRC is affine in its input; zero bytes
    before an error change nothing, zero bytes after it an invertible map)."""
    if reflected:
        table = np.asarray(p._CRC16_TABLE, np.int64)
    else:   # CRC-16/CCITT-FALSE's update, most significant bit first
        table = np.zeros(256, np.int64)
        for byte in range(256):
            crc = byte << 8
            for _ in range(8):
                crc = ((crc << 1) ^ 0x1021 if crc & 0x8000 else crc << 1) & 0xFFFF
            table[byte] = crc
    state = np.zeros(len(errors), np.int64)
    for col in errors.T.astype(np.int64):
        if reflected:
            state = (state >> 8) ^ table[(state ^ col) & 0xFF]
        else:
            state = ((state << 8) & 0xFFFF) ^ table[((state >> 8) ^ col) & 0xFF]
    return state


def test_every_burst_of_up_to_16_bits_in_uart_order_changes_the_crc():
    """All 262,144 bursts of 1 … 16 bits, as a UART sends them (each byte least significant
    bit first), at each of the 8 bit offsets in a byte: wherever a burst lies in a body it
    is one of these (the CRC is linear), and none leaves the CRC unchanged. The reflected
    CRC reads bits in the wire's order, so this holds for it by construction; for the CCITT
    polynomial it holds unreflected too (CRC-16/CCITT-FALSE), checked the same way."""
    import binascii

    offsets, spans, inner = [], [], []
    for span in range(1, 17):
        fill = np.arange(1 << max(span - 2, 0), dtype=np.int64)
        pattern = (1 | (fill << 1) | (1 << (span - 1))) & ((1 << span) - 1)
        for offset in range(8):
            offsets.append(np.full(len(pattern), offset))
            spans.append(np.full(len(pattern), span))
            inner.append(pattern)
    wire = np.concatenate(inner) << np.concatenate(offsets)
    assert len(wire) == 262_144 and wire.max() < 1 << 23
    errors = np.stack([(wire >> (8 * k)) & 0xFF for k in range(3)], axis=1).astype(np.uint8)
    assert (_crc_of_error(errors, reflected=True) != 0).all()
    assert (_crc_of_error(errors, reflected=False) != 0).all()
    # the linear parts are the real CRCs': a body and itself changed by an error
    body = np.frombuffer(b"IRSCN,0,-35,1000,812,790,1203,1510,655,700,702,1498", np.uint8)
    for row in errors[::9973]:
        changed = body.copy()
        changed[20:23] ^= row
        lin = np.zeros(len(body), np.uint8)
        lin[20:23] = row
        assert p.crc16(changed.tobytes()) ^ p.crc16(body.tobytes()) == \
            _crc_of_error(lin[None, :], reflected=True)[0]
        assert binascii.crc_hqx(changed.tobytes(), 0xFFFF) ^ \
            binascii.crc_hqx(body.tobytes(), 0xFFFF) == \
            _crc_of_error(lin[None, :], reflected=False)[0]


_messages = st.builds(p.Scan, st.integers(0, 65535), st.integers(-35, 35),
                      st.integers(0, 2**32 - 1),
                      st.lists(st.integers(0, 4095), min_size=12, max_size=12).map(tuple))


@settings(max_examples=300, deadline=None)
@given(_messages, st.data())
def test_any_burst_of_up_to_16_bits_is_never_accepted_in_v2(msg, data):
    line = bytearray(p.encode(msg))
    span = data.draw(st.integers(1, 16))
    start = data.draw(st.integers(0, len(line) * 8 - span))
    pattern = data.draw(st.integers(0, (1 << span) - 1)) | 1 | (1 << (span - 1))
    for k in range(span):
        if pattern >> k & 1:
            bit = start + k
            line[bit // 8] ^= 1 << (bit % 8)
    assert li.accepted_oracle(bytes(line), 2) == []
