"""`irring geometry`: the paper's design geometry for a ring design (Eqs. 1–3 and Monte Carlo)."""

from __future__ import annotations

import argparse
import json
import math

from .. import designs
from ..designs import DESIGN_BY_NAME
from ..errors import UsageError
from ..pipeline import progress_bar
from ..studies import geometry
from ._common import at_least, check_distances_clear, describe, distances_mm, number_in, seed

EPILOG = """\
what it prints:
  beta_deg            Eq. 2: angle β of the overlap of two neighbouring sweeps (deg);
                      negative when they do not meet (its size is then the gap)
  overlap_area_m2     Eq. 3: area S both neighbours see (m²), from R, Φ = 360°/N, α, D
  overlap_area_mc_m2  the same area counted by Monte Carlo in the BUILT MuJoCo model:
                      hinge positions and beam directions read at the first and last
                      motor step (not from R, Φ, α); it agrees with Eq. 3 when the model
                      is the design the equations describe
  blind_spot_m        Eq. 1: radius of the largest cylinder that can hide between two
                      neighbouring rays at each distance (m), with the design's ray step
  blind_spot_rays_m   for a sensor with a beam cone (sonar12): the same from the design's
                      rays as `irring compare` casts them (null for a pencil beam)

examples:
  irring geometry                          the paper's ring (Table I: β 19.56°, S 0.1376 m²)
  irring geometry --design radial12        the same ring held still: no overlap
  irring geometry --design all --json      every named design, as JSON
  irring geometry --range-mm 624           D = 624 mm (the experiments) instead of 686 mm
"""


MAX_SAMPLES = 10_000_000   # 0.04 % standard error; more only costs memory (16 bytes a point and more)


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "The paper's design geometry for a ring design: the overlap angle β and "
             "area S of neighbouring sensors (Eqs. 2–3, and S measured by Monte Carlo "
             "from the built MuJoCo model's sensor frames) and the blind spot r(d) "
             "(Eq. 1).",
             EPILOG)
    p.add_argument("--design", default="rotating12", metavar="NAME",
                   choices=[*DESIGN_BY_NAME, "all"],
                   help=f"one of {', '.join(DESIGN_BY_NAME)}, or all (default: rotating12)")
    p.add_argument("--range-mm", type=number_in(0, 100_000, low_open=True), default=None,
                   metavar="D",
                   help="max range D in mm for Eqs. 2–3, > 0 and ≤ 100000 (default: the "
                        "sensor's design range, 686 mm for the GP2D12 as in Table I)")
    p.add_argument("--distances-mm", type=distances_mm, default="250,500,750,1000",
                   metavar="LIST",
                   help="comma-separated positive distances in mm (robot centre to the cylinder's "
                        "near side, beyond the ring and its housing) for the blind spot "
                        "(default: 250,500,750,1000)")
    p.add_argument("--samples", type=at_least(1000, MAX_SAMPLES), default=400_000, metavar="N",
                   help=f"Monte-Carlo points per neighbouring pair (1000 … {MAX_SAMPLES}; "
                        "default: 400000, standard error ≈ 0.2 %% of S; 10⁷ takes ~40 s and "
                        "0.6 GB)")
    p.add_argument("--seed", type=seed, default=0, help="Monte-Carlo seed ≥ 0 (default: 0)")
    p.add_argument("--json", action="store_true", help="print JSON (one object, or a list "
                                                       "with --design all)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    names = list(designs.DESIGN_BY_NAME) if args.design == "all" else [args.design]
    range_m = None if args.range_mm is None else args.range_mm * 1e-3
    check_distances_clear(args.distances_mm, [designs.get(n) for n in names])
    pairs = sum(len(geometry.neighbour_pairs(designs.get(n).ring.sensors)) for n in names)
    try:   # the Monte Carlo is the slow part (--samples says how slow): a bar over its pairs
        with progress_bar(pairs, "overlap (Monte Carlo)", unit="pair") as bar:
            reports = [geometry.design_report(designs.get(n), args.distances_mm,
                                              range_m=range_m, samples=args.samples,
                                              seed=args.seed, on_pair=bar.update)
                       for n in names]
    except ValueError as exc:   # a range too short for the ring's geometry (Eq. 2)
        if args.range_mm is None:
            raise
        raise UsageError(f"--range-mm {args.range_mm:g}: {exc}") from None
    if args.json:
        print(json.dumps(reports if args.design == "all" else reports[0], indent=2))
        return 0
    for r in reports:
        print(_text(r))
    return 0


def _text(r: dict) -> str:
    if r["beta_deg"] is None:
        beta = "— (one sensor: no neighbour)"
    elif r["beta_deg"] < 0:   # Eq. 2 goes negative when the sweeps do not meet
        beta = f"none: neighbouring sweeps {-r['beta_deg']:.2f}° apart (Eq. 2 gives {r['beta_deg']:.2f}°)"
    else:
        beta = f"{r['beta_deg']:.2f}°"
    lines = [
        f"{r['design']}: N = {r['sensors']}, R = {r['radius_m'] * 1e3:g} mm, "
        f"Φ = {r['spacing_deg']:.4g}°, α = {r['alpha_deg']:.4g}°, D = {r['range_m'] * 1e3:g} mm",
        f"  overlap angle β (Eq. 2)          {beta}",
        f"  overlap area S (Eq. 3)           {r['overlap_area_m2']:.4f} m²",
        f"  overlap area S (Monte Carlo,     {r['overlap_area_mc_m2']:.4f} m² "
        f"± {r['overlap_area_mc_stderr_m2']:.4f}",
        "    from the MuJoCo model's frames)",
        f"  blind spot r (Eq. 1, Δθ = {r['step_deg']:.3g}°):",
    ]
    rays = r.get("blind_spot_rays_m")
    if rays is not None:
        lines[-1] += ("  [the cones touch on paper; from the model's rays, as "
                      "irring compare: an echo returns only near square to a ray]")
    for k, (d, b) in enumerate(zip(r["distances_m"], r["blind_spot_m"])):
        shown = "unbounded" if not math.isfinite(b) else f"{b * 1e3:.1f} mm"
        if rays is not None:
            v = rays[k]
            shown = f"Eq. 1: {shown}; rays: " + (
                "not even a 200 mm post is seen at every bearing" if not math.isfinite(v)
                else f"posts up to {v * 1e3:.0f} mm hide")
        lines.append(f"    at {d * 1e3:6.0f} mm   {shown}")
    return "\n".join(lines)
