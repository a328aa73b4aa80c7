"""`irring bench sigma`: each valid reading's σ against its range error, per distance band."""

from __future__ import annotations

import argparse
import json

from .. import errors
from ..studies.sigma import BANDS, Z_HIGH, Z_LOW, measure, wall_rooms
from ._common import describe, seed_count

EPILOG = f"""\
what it prints: per sensor model, on a room of simulated walls written for it (an irregular
pentagon seen from three poses at 30-100 % of the range, the bundled default effects), over
the valid readings whose beam hit a surface, per 1/{BANDS} of the range:
  n          readings
  err mm     RMS range error (estimated minus true distance along the beam)
  σ mm       median σ (Points.sigma_m, what the mapper spreads a hit over)
  err/σ      RMS of error over σ: ≈ 1 where σ states the error
  >2σ        share beyond 2σ (4.6 % for a Gaussian)
a band outside {Z_LOW}–{Z_HIGH} is marked (σ too large below, too small above); figures
only, exit status 0.

examples:
  irring bench sigma
  irring bench sigma --seeds 4 --json
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Print how well each valid reading's σ states its range error: err/σ RMS "
             f"per 1/{BANDS} of the range, per sensor model, on simulated walls.", EPILOG)
    p.add_argument("--seeds", type=seed_count, default=2, metavar="N",
                   help="seeds per room: the room's seed, +1, … (default: 2)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(func=run)


def _f(v, scale: float = 1.0, digits: int = 1) -> str:
    return "n/a" if v is None else f"{v * scale:.{digits}f}"


def run(args: argparse.Namespace) -> int:
    rooms = measure(wall_rooms(), args.seeds)
    if args.json:
        print(json.dumps(rooms, indent=2))
        return errors.OK
    for r in rooms:
        print(f"{r['sensor']} read to {r['max_range_m'] * 1e3:.0f} mm ({r['name']}, "
              f"{args.seeds} seed(s))")
        print(f"  {'band mm':>11}{'n':>7}{'err mm':>8}{'σ mm':>7}{'err/σ':>7}{'>2σ':>7}")
        for b in r["bands"]:
            if not b["n"]:
                continue
            z = b["z_rms"]
            mark = "" if Z_LOW <= z <= Z_HIGH else ("  σ too large" if z < Z_LOW
                                                    else "  σ too small")
            print(f"  {b['lo_m'] * 1e3:>5.0f}–{b['hi_m'] * 1e3:<5.0f}{b['n']:>7}"
                  f"{_f(b['err_rms_m'], 1e3):>8}{_f(b['sigma_median_m'], 1e3):>7}"
                  f"{z:>7.2f}{b['beyond_2sigma'] * 100:>6.1f}%{mark}")
    return errors.OK
