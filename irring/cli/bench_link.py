"""`irring bench link`: corrupted IRSCN the decoder accepts, protocol v1 vs v2; decode time."""

from __future__ import annotations

import argparse
import json
import os

from .. import errors
from ..studies.link_integrity import (DISTINCT_SCANS, MAX_BURST_BITS, REFERENCE_SCAN,
                                      decode_seconds_per_scan, every_two_bit_error, measure)
from ._common import at_least, describe, seed

DEFAULT_TRIALS = 200_000
DEFAULT_SEED = 7

EPILOG = f"""\
what it does: encodes {DISTINCT_SCANS} random IRSCN sentences of the paper's ring in protocol v1
(8-bit XOR checksum) and v2 (CRC-16/IBM-SDLC), corrupts TRIALS of each (drawn from them) in
two ways, feeds each to a fresh decoder and counts what it accepts:
  two_bits   two distinct random bits flipped anywhere in the sentence
  burst16    a burst of 1 … {MAX_BURST_BITS} bits (its first and last bits flipped, those between at
             random), in the order a UART sends them (each byte least significant bit first)
columns: accepted (decoded to a message) and changed (… other than the one sent).
Then every two-bit error of one IRSCN (all pairs of its bits, counted exactly), and the time a decoder takes per IRSCN (a stream of 1000, best of 5) in each version.
target: v2 accepts none of the bursts (a CRC-16 detects every burst of ≤ 16 bits).
exit status: 0 when the target holds, {errors.TARGET_MISSED} when it does not.

examples:
  irring bench link                       {DEFAULT_TRIALS:,} trials per kind and version, seed {DEFAULT_SEED}
  irring bench link --trials 20000 --json
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Corrupt IRSCN sentences (two random bit flips; bursts of up to 16 bits) "
             "and count how many the decoder accepts under protocol v1's XOR checksum and "
             "v2's CRC-16; time the decoder per scan in each.", EPILOG)
    p.add_argument("--trials", type=at_least(1, 10_000_000), default=DEFAULT_TRIALS,
                   metavar="N", help=f"corrupted sentences per kind and version (default "
                                     f"{DEFAULT_TRIALS:,})")
    p.add_argument("--seed", type=seed, default=DEFAULT_SEED,
                   help=f"seed ≥ 0 of the scans and the bit flips (default {DEFAULT_SEED})")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    tallies = measure(args.trials, args.seed)
    every = [every_two_bit_error(v) for v in (1, 2)]
    decode_us = {v: decode_seconds_per_scan(v) * 1e6 for v in (1, 2)}
    missed = [t for t in tallies if t.version == 2 and t.kind == "burst16" and t.accepted]
    result = {"trials": args.trials, "seed": args.seed, "load_average": os.getloadavg()[0],
              "tallies": [_row(t) for t in tallies + every],
              "decode_us_per_scan": {f"v{v}": round(us, 2) for v, us in decode_us.items()},
              "target_met": not missed}
    print(json.dumps(result, indent=2) if args.json else report(result))
    return errors.OK if not missed else errors.TARGET_MISSED


def _row(t) -> dict:
    return dict(version=t.version, kind=t.kind, trials=t.trials, accepted=t.accepted,
                changed=t.changed)


def report(result: dict) -> str:
    """The table `irring bench link` prints, from its JSON."""
    lines = [f"{result['trials']:,} corrupted IRSCN per row (seed {result['seed']}); load "
             f"average {result['load_average']:.1f}",
             f"  {'protocol':<12}{'corruption':<16}{'of':>10}{'accepted':>10}{'':>9}"
             f"{'changed':>10}"]
    for t in result["tallies"]:
        name = "v1 XOR-8" if t["version"] == 1 else "v2 CRC-16"
        lines.append(f"  {name:<12}{t['kind']:<16}{t['trials']:>10,}{t['accepted']:>10,}"
                     f"{t['accepted'] / t['trials']:>9.3%}{t['changed']:>10,}")
    us = result["decode_us_per_scan"]
    lines.append("(every_two_bits: all pairs of bits of one IRSCN sentence, "
                 f"{REFERENCE_SCAN.TYPE},{REFERENCE_SCAN.seq},{REFERENCE_SCAN.step},…)")
    lines.append(f"decode per IRSCN: v1 {us['v1']:.1f} µs, v2 {us['v2']:.1f} µs (v2/v1 "
                 f"{us['v2'] / us['v1']:.2f})")
    lines.append("target: v2 accepts no burst of ≤ 16 bits: " +
                 ("met" if result["target_met"] else "MISSED"))
    return "\n".join(lines)
