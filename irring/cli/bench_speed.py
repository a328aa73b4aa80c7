"""`irring bench speed`: median time per sweep of each stage, against raw MuJoCo and the ring."""

from __future__ import annotations

import argparse
import json

from .. import errors
from ..scenario import load_scenario
from ..studies.speed import measure, report
from ._common import add_pose_option, at_least, describe, pose_index, seed

EPILOG = """\
stages (ms per sweep, median over rounds, each round times every stage once in turn):
  kinematics      emitter frames of every step from one batched MuJoCo forward
  rays            a sweep's rays (SimRing.truth_at): one batched MuJoCo ray call + range,
                  incidence, hit point, reflectance
  effect: NAME    each effect the scenario lists, timed inside the effects pipeline
  effects core    the pipeline's always-on work (voltage curve, counts, no-return fill)
  estimator       the iterative estimator (paper Table II), calibrated once
  mapper          occupancy-grid insert of the sweep's points
and, in the same rounds:
  raw MuJoCo      the same batched ray call on the same rays with none of our code
  whole sweep     SimRing.sweep → estimate → insert, fresh noise each sweep (sweep_ms)
  real-time       the sweep's hardware time (steps × (settle + samples × 38.3 ms)) / sweep_ms

targets (this project's, for a 2-core machine): whole sweep ≤ 2 ms; rays within 1.5× of raw
MuJoCo; ≥ 1000× faster than the hardware. --check exits 6 when one is missed (after
printing the figures; 1 stays for a bad scenario file).

JSON keys: sweep_ms, ray_ms, raw_mujoco_ms, ray_vs_raw_ratio, realtime_factor,
sweeps_per_s, hardware_time_s, stages [{stage, ms}], targets, machine, …

examples:
  irring bench speed                        t_room, pose 1, 200 rounds
  irring bench speed --json
  irring bench speed --scenario t_room_three_cylinders --rounds 50
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Median time per sweep of every stage (ray casts, each effect, "
             "estimator, mapper), raw MuJoCo on the same rays, sweeps per second and "
             "the real-time factor against the ring's hardware time.",
             EPILOG)
    p.add_argument("--scenario", default="t_room", metavar="NAME_OR_PATH",
                   help="bundled scenario name or YAML path (default: t_room)")
    add_pose_option(p, 1, "where the sweep is timed")
    p.add_argument("--rounds", type=at_least(1), default=200, metavar="N",
                   help="timing rounds; medians over rounds are reported (≥ 1; default: 200)")
    p.add_argument("--seed", type=seed, default=None, help="noise seed ≥ 0 (default: the scenario's)")
    p.add_argument("--check", action="store_true",
                   help=f"exit {errors.TARGET_MISSED} when a target is missed")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    scenario = load_scenario(args.scenario)
    r = measure(scenario, rounds=args.rounds, pose_index=pose_index(args.pose, scenario),
                seed=args.seed)
    print(json.dumps(r, indent=2) if args.json else report(r))
    missed = [k for k, t in r["targets"].items() if not t["met"]]
    return errors.TARGET_MISSED if (args.check and missed) else errors.OK
