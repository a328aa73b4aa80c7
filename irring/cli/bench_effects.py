"""`irring bench effects`: the cost of each effect per sweep, and of the effects that are off."""

from __future__ import annotations

import argparse
import json

from .. import errors
from ..core import bounds
from ..scenario import Scan, load_scenario
from ..studies.effects import measure
from ._common import at_least, describe, seed

EPILOG = """\
what it prints (µs per 71 × 12 sweep, median over rounds; no MuJoCo involved):
  alone      the effect on its own, minus the ideal pipeline (no effects)
  in full    all eight effects minus all but this one: its work at the scale the full
             pipeline runs it (per ray under beam, per sample under averaging)
  neutral    the stage built with do-nothing parameters (σ = 0, zero rates, …): what
             switching an effect off by its parameters would still cost
  off        an effect that is off is never built; the only cost it could have is the
             pipeline's fixed dispatch shared by all effects: ideal pipeline − the bare
             curve written out by hand. Checked against 2 % of the full sweep: over
             it, the command exits 6 (after printing the figures, text or --json).
  The beam's extra rays are cast once by an analytic stand-in for SimRing.cast and then
  replayed, so casting (the simulator's cost) is not in these figures.

examples:
  irring bench effects                  default: t_room's sensor, 4 samples per step
  irring bench effects --json           the same figures as JSON
  irring bench effects --rounds 5       quicker, noisier
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Time the effects pipeline on a synthetic 71 × 12 sweep of the paper's "
             "ring: each effect alone and within the full pipeline, and what the "
             "effects that are off cost (they are not built).",
             EPILOG)
    p.add_argument("--scenario", default="t_room", metavar="NAME_OR_PATH",
                   help="scenario whose sensor block (model, ADC bits) is used; its effects "
                        "are replaced (default: t_room)")
    lo, hi = bounds(Scan, "samples")
    p.add_argument("--samples", type=at_least(lo, hi), default=4, metavar="N",
                   help=f"scan.samples for the averaging effect ({lo} … {hi} as in a scenario; "
                        "default: 4)")
    p.add_argument("--rounds", type=at_least(1), default=25, metavar="N",
                   help="timing rounds; the median over rounds is reported (≥ 1; default: 25)")
    p.add_argument("--batch", type=at_least(1), default=40, metavar="N",
                   help="sweeps per configuration per round (≥ 1; default: 40)")
    p.add_argument("--seed", type=seed, default=0, help="noise seed ≥ 0 (default: 0)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(func=run)


def _fmt(x: float | None) -> str:
    return "—" if x is None else f"{x:8.1f}"


def run(args: argparse.Namespace) -> int:
    r = measure(load_scenario(args.scenario), samples=args.samples, rounds=args.rounds,
                batch=args.batch, seed=args.seed)
    status = errors.OK if r["off_within_budget"] else errors.TARGET_MISSED
    if args.json:
        print(json.dumps(r, indent=2))
        return status
    print(f"effects pipeline, {r['sweep_shape'][0]} × {r['sweep_shape'][1]} sweep, "
          f"{r['sensor']}, {r['adc_bits']}-bit ADC, averaging {r['samples']} samples, "
          f"beam {r['beam_rays']} rays; µs per sweep, median of {r['rounds']} rounds × "
          f"{r['batch']} sweeps")
    print(f"{'effect':<13}{'alone':>9}{'in full':>10}{'% of full':>11}{'neutral':>10}")
    for e in r["effects"]:
        print(f"{e['effect']:<13}{_fmt(e['alone_us']):>9}{_fmt(e['in_full_us']):>10}"
              f"{e['in_full_pct']:>10.1f}%{_fmt(e['neutral_us']):>10}")
    print(f"full pipeline (all 8 effects)   {r['full_us']:8.1f} µs")
    print(f"ideal pipeline (no effects)     {r['ideal_us']:8.1f} µs")
    print(f"bare curve, written by hand     {r['bare_curve_us']:8.1f} µs")
    print(f"stand-in caster, one beam batch {r['fake_cast_us']:8.1f} µs (not in the figures)")
    verdict = "within" if r["off_within_budget"] else "OVER"
    print(f"an effect that is off: {r['off_us']:.1f} µs = {r['off_pct_of_full']:.2f} % of the "
          f"full sweep ({verdict} the {r['off_budget_pct']:g} % budget; shared by all effects "
          f"that are off, since none of them is built)")
    return status
