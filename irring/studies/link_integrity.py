"""How often a corrupted IRSCN passes as a sentence: protocol v1's XOR against v2's CRC-16.

:func:`measure` flips bits of encoded scan sentences (two random bits, or a random burst of
up to 16 bits, in the order a UART sends them: byte by byte, least significant bit first)
and feeds each one to a fresh :class:`~irring.hardware.protocol.Decoder`, counting what it
accepts and what it accepts with changed values. The verdicts are vectorised over all
trials (numpy); :func:`accepted_oracle` is the plain reading (one Decoder per sentence)
they are tested against. Figures and the command: docs/protocol.md.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..hardware import protocol as p

KINDS = ("two_bits", "burst16")  # two random bit flips; a burst of 1 … 16 bits
MAX_BURST_BITS = 16
DISTINCT_SCANS = 1000            # scans cycled through by the trials


@dataclass(frozen=True)
class Tally:
    """What the decoder made of ``trials`` corrupted sentences of one kind and version."""

    version: int
    kind: str
    trials: int
    accepted: int   # decoded to a message
    changed: int    # … which differs from the one sent

    @property
    def accepted_fraction(self) -> float:
        return self.accepted / self.trials

    @property
    def changed_fraction(self) -> float:
        return self.changed / self.trials


def scans(n: int, rng: np.random.Generator, sensors: int = 12, adc_bits: int = 12) -> list[p.Scan]:
    """``n`` plausible IRSCN messages of the paper's ring: seq, step −35 … 35, clock, counts."""
    out = []
    for _ in range(n):
        counts = tuple(int(c) for c in rng.integers(0, 1 << adc_bits, sensors))
        out.append(p.Scan(int(rng.integers(0, p.SEQ_MODULO)), int(rng.integers(-35, 36)),
                          int(rng.integers(0, 10**7)), counts))
    return out


def error_masks(lengths: np.ndarray, kind: str, rng: np.random.Generator) -> np.ndarray:
    """XOR masks, one row per sentence of ``lengths`` bytes (padded to the longest): two
    distinct random bits, or a burst of 1 … 16 bits whose first and last bits flip and whose
    inner bits flip at random. Bits count in UART order (LSB first within each byte)."""
    n, width = len(lengths), int(lengths.max())
    rows = np.arange(n)
    total = lengths * 8
    if kind == "two_bits":
        first = (rng.random(n) * total).astype(np.int64)
        second = (rng.random(n) * (total - 1)).astype(np.int64)
        second += second >= first                      # distinct from the first
        starts, patterns = np.stack([first, second]), np.ones((2, n), np.int64)
    elif kind == "burst16":
        span = rng.integers(1, MAX_BURST_BITS + 1, n)
        start = (rng.random(n) * (total - span + 1)).astype(np.int64)
        inner = rng.integers(0, 1 << MAX_BURST_BITS, n) & ((1 << span) - 1)
        starts, patterns = start[None, :], (inner | 1 | (1 << (span - 1)))[None, :]
    else:
        raise ValueError(f"kind {kind!r}: expected one of {', '.join(KINDS)}")
    masks = np.zeros((n, width + 3), np.uint8)
    for start, pattern in zip(starts, patterns):
        shifted = pattern << (start % 8)               # spread over up to three bytes
        for k in range(3):
            np.bitwise_xor.at(masks, (rows, start // 8 + k), ((shifted >> (8 * k)) & 0xFF)
                              .astype(np.uint8))
    return masks[:, :width]


def accepted_oracle(line: bytes, version: int) -> list[p.AnyMessage]:
    """What a fresh Decoder of ``version`` makes of ``line`` alone: the messages it accepts."""
    return [m for m in p.Decoder(version).feed(line) if not isinstance(m, p.ProtocolError)]


CHUNK_ROWS = 16_384   # rows judged at once: bounds the temporaries (~20 MB, not ~1 GB)


def _verdicts(frames: np.ndarray, lengths: np.ndarray, version: int,
              sent: list[p.Scan]) -> tuple[np.ndarray, np.ndarray]:
    """(accepted, changed) per row of ``frames`` (corrupted sentences, zero-padded)."""
    parts = [_verdicts_block(frames[i:i + CHUNK_ROWS], lengths[i:i + CHUNK_ROWS], version,
                             sent[i:i + CHUNK_ROWS]) for i in range(0, len(frames), CHUNK_ROWS)]
    return (np.concatenate([a for a, _ in parts]) if parts else np.zeros(0, bool),
            np.concatenate([c for _, c in parts]) if parts else np.zeros(0, bool))


def _verdicts_block(frames: np.ndarray, lengths: np.ndarray, version: int,
                    sent: list[p.Scan]) -> tuple[np.ndarray, np.ndarray]:
    n = len(frames)
    digits = p.CHECK_DIGITS[version]
    rows = np.arange(n)
    star = lengths - 3 - digits
    body_len = star - 1
    cols = np.arange(frames.shape[1])[None, :]
    in_body = (cols >= 1) & (cols < star[:, None])
    in_check = (cols > star[:, None]) & (cols < (lengths - 2)[:, None])
    dollar, star_byte, newline = frames == ord("$"), frames == ord("*"), frames == ord("\n")
    special = dollar | star_byte | newline
    intact = ((frames[:, 0] == ord("$")) & (frames[rows, star] == ord("*"))
              & (frames[rows, lengths - 2] == ord("\r")) & (frames[rows, lengths - 1] == ord("\n"))
              & ~np.any(special & (in_body | in_check), axis=1))
    # the check field's value (−1 where a digit is not upper-case hex)
    hex_value = np.full(256, -1, np.int64)
    for i, c in enumerate(b"0123456789ABCDEF"):
        hex_value[c] = i
    sent_check = np.zeros(n, np.int64)
    for j in range(digits):
        d = hex_value[frames[rows, star + 1 + j]]
        sent_check = np.where((d < 0) | (sent_check < 0), -1, sent_check * 16 + d)
    # the check computed over each body, byte by byte for all rows at once
    if version == 1:
        computed = np.bitwise_xor.reduce(np.where(in_body, frames, 0), axis=1).astype(np.int64)
    else:
        table = np.asarray(p._CRC16_TABLE, np.int64)
        crc = np.full(n, p.CRC16_INIT, np.int64)
        for col in range(1, int(star.max())):
            live = col <= body_len
            step = (crc >> 8) ^ table[(crc ^ frames[:, col]) & 0xFF]
            crc = np.where(live, step, crc)
        computed = crc ^ p.CRC16_XOROUT
    accepted = np.zeros(n, bool)
    changed = np.zeros(n, bool)
    # A decoder accepts nothing from a row without a `$`, a `*` and a `\r\n`. Rows whose
    # framing survived and whose check matches, and rows whose framing was hit but which
    # still hold all three, are decoded in full; the others are rejected without it.
    crlf = np.any(newline[:, 1:] & (frames[:, :-1] == ord("\r")), axis=1)
    framable = crlf & np.any(dollar, axis=1) & np.any(star_byte, axis=1)
    for i in np.flatnonzero(np.where(intact, sent_check == computed, framable)):
        got = accepted_oracle(frames[i, :lengths[i]].tobytes(), version)
        accepted[i] = bool(got)
        changed[i] = any(m != sent[i] for m in got)
    return accepted, changed


REFERENCE_SCAN = p.Scan(4711, -17, 123456789, (812, 790, 1203, 1510, 655, 700, 702, 1498,
                                                2210, 980, 640, 633))


def two_bit_errors(line: bytes) -> np.ndarray:
    """``line`` with every pair of its bits flipped, one row per pair (L·8·(L·8−1)/2 rows)."""
    i, j = np.triu_indices(len(line) * 8, 1)
    rows = np.arange(len(i))
    masks = np.zeros((len(i), len(line)), np.uint8)
    for bit in (i, j):
        np.bitwise_xor.at(masks, (rows, bit // 8), (1 << (bit % 8)).astype(np.uint8))
    return np.frombuffer(line, np.uint8)[None, :] ^ masks


def every_two_bit_error(version: int, msg: p.Scan = REFERENCE_SCAN) -> Tally:
    """What the decoder accepts of all two-bit errors of ``msg``'s sentence: exact counts."""
    line = p.encode(msg, version=version)
    frames = two_bit_errors(line)
    n = len(frames)
    accepted, changed = _verdicts(frames, np.full(n, len(line)), version, [msg] * n)
    return Tally(version, "every_two_bits", n, int(accepted.sum()), int(changed.sum()))


def measure(n: int = 200_000, seed: int = 7, versions: tuple[int, ...] = (1, 2),
            kinds: tuple[str, ...] = KINDS) -> list[Tally]:
    """Corrupt ``n`` scan sentences per version and kind (the same scans, and error masks
    drawn from the same seed, for each version) and tally what the decoder accepts."""
    rng = np.random.default_rng(seed)
    distinct = scans(DISTINCT_SCANS, rng)
    pick = rng.integers(0, DISTINCT_SCANS, n)
    sent = [distinct[i] for i in pick]
    tallies = []
    for kind in kinds:
        kind_seed = int(rng.integers(0, 2**63))
        for version in versions:
            encoded = [p.encode(m, version=version) for m in distinct]
            lengths_d = np.array([len(e) for e in encoded])
            table = np.zeros((DISTINCT_SCANS, lengths_d.max()), np.uint8)
            for i, e in enumerate(encoded):
                table[i, :len(e)] = np.frombuffer(e, np.uint8)
            lengths = lengths_d[pick]
            masks = error_masks(lengths, kind, np.random.default_rng(kind_seed))
            frames = table[pick, :masks.shape[1]] ^ masks
            accepted, changed = _verdicts(frames, lengths, version, sent)
            tallies.append(Tally(version, kind, n, int(accepted.sum()), int(changed.sum())))
    return tallies


def decode_seconds_per_scan(version: int, n: int = 1000, repeats: int = 5,
                            seed: int = 7) -> float:
    """Best-of-``repeats`` wall time a :class:`~irring.hardware.protocol.Decoder` of
    ``version`` takes per IRSCN, fed a stream of ``n`` scan sentences at once (s)."""
    stream = b"".join(p.encode(m, version=version) for m in scans(n, np.random.default_rng(seed)))
    best = math.inf
    for _ in range(repeats):
        decoder = p.Decoder(version)
        t0 = time.perf_counter()
        got = decoder.feed(stream)
        best = min(best, time.perf_counter() - t0)
        if len(got) != n or any(isinstance(m, p.ProtocolError) for m in got):
            raise AssertionError(f"v{version}: the clean stream did not decode to {n} scans")
    return best / n
