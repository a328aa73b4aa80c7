"""`irring bench dynamics`: the belt's stretch, physics convergence, settling vs smear, motion."""

from __future__ import annotations

import argparse
import json
import math

from ..core import MAX_SWEEPS
from ._common import at_least, describe, named_once, seed

EPILOG = """\
what it prints (the paper's ring in the T-room, pose 0 unless said; angles at the sensor):
  belt        stretch (sensor − 0.6 × motor) over --sweeps back-and-forth sweeps without
              rest (each 1.8° step in 4 ms, read on arrival): max over every physics step,
              first and last sweep, largest read error, MuJoCo warnings
  convergence one sweep at the default time step and at half of it: largest change of a
              true sensor angle, true distance, ADC count
  check       what the first sweep's time-step check costs on t_room_moving's sweep,
              against the belt physics itself, and the sweep at half the step alone
  timesteps   (--timesteps) a 1.3 × 0.9 m box at several belt time constants and time
              steps: the check's angle change, its verdict, and the map's F1 made anyway
  settling    hardware time per sweep and angle error (true − commanded sensor angle where
              the reading was measured, rms / max) for settle times: belt + GP2 timing,
              belt alone, timing alone. Settle ≥ 52.9 ms (slowest GP2 period 47.9 ms +
              5 ms latency) means every reading was measured after its move
  mujoco      the timed readings from MuJoCo's periodic, delayed rangefinders (interval,
              delay) vs irring's clock model: share equal on MuJoCo's step grid, largest
              difference against irring's continuous instants
  motion      occupied F1 of the static T-room (4 scans), of static scans where the moving
              run swept, of t_room_moving with perfect odometry and as bundled (--seeds)

examples:
  irring bench dynamics                    everything (≈ 30 s)
  irring bench dynamics --sweeps 100       a shorter belt run
  irring bench dynamics --no-motion --json figures as JSON, without the mapping runs
  irring bench dynamics --no-motion --sweeps 10 --timesteps   docs/dynamics.md's table
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Measure what belt_dynamics, timing and motion do: the belt's stretch "
             "over many sweeps, whether halving the physics time step changes the "
             "readings, how settle time trades hardware time for angle error, "
             "MuJoCo's own sensor timing against irring's, and maps made on the move.",
             EPILOG)
    p.add_argument("--sweeps", type=at_least(1, MAX_SWEEPS), default=1000, metavar="N",
                   help=f"back-and-forth sweeps for the belt figures (1 … {MAX_SWEEPS}, "
                        f"a run's limit; default: 1000)")
    p.add_argument("--seeds", type=seed, nargs="+", default=[1], metavar="SEED",
                   help="seeds ≥ 0 for the motion figures, averaged (default: 1)")
    p.add_argument("--no-motion", action="store_true", help="skip the mapping runs")
    p.add_argument("--timesteps", action="store_true",
                   help="also the time-step table: which belt time steps are converged and "
                        "what the map loses at those that are not (≈ 15 s)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(func=run)


def _deg(x: float) -> str:
    return f"{math.degrees(x):9.4f}°"


def run(args: argparse.Namespace) -> int:
    named_once(args.seeds, "--seeds")   # `--seeds 1 1` weighed seed 1 twice in the means
    from ..studies.dynamics import measure   # deferred: loads MuJoCo, which --help does not need

    r = measure(sweeps=args.sweeps, seeds=tuple(args.seeds), with_motion=not args.no_motion,
                timesteps=args.timesteps)
    if args.json:
        print(json.dumps(r, indent=2))
        return 0
    c = r["coupling"]
    print(f"belt: {c['sweeps']} sweeps back and forth, {c['physics_steps']} physics steps of "
          f"{c['timestep_s'] * 1e3:g} ms in {c['compute_s']:.1f} s, MuJoCo warnings: "
          f"{c['warnings']}")
    print(f"  stretch max {c['stretch_max_rad']:.2e} rad ({_deg(c['stretch_max_rad']).strip()}); "
          f"first sweep {c['stretch_first_rad']:.2e}, last {c['stretch_last_rad']:.2e}; "
          f"read error max {c['read_error_max_rad']:.2e} rad")
    print("convergence: one sweep at dt and dt/2")
    for v in r["convergence"]:
        print(f"  {v['scene']:<26} dt {v['timestep_s'] * 1e3:g} ms: angle {v['angle_rad']:.1e} rad,"
              f" distance {v['distance_m'] * 1e3:.4f} mm, counts {v['counts']:g}, hits changed "
              f"{v['hit_changed']}")
    k = r["check_cost"]
    print(f"timestep check on {k['scene']}'s sweep ({k['physics_steps']:,} physics steps), once "
          f"per scene and schedule: physics {k['physics_s']:.2f} s; check {k['check_s']:.2f} s "
          f"({k['check_ratio']:.2f}×: twice the step moves {math.degrees(k['check_change_rad']):.1e}°"
          f"); the sweep at half the step alone {k['halving_s']:.2f} s "
          f"({k['halving_ratio']:.1f}×, moves {math.degrees(k['halving_change_rad']):.1e}°)")
    for key, title in (("settling_belt_timing", "belt + timing"), ("settling_belt", "belt only"),
                       ("settling_timing", "timing only")):
        print(f"settling, {title}:   settle    hardware/sweep   angle error rms        max")
        for row in r[key]:
            print(f"  {'':<18}{row['settle_s'] * 1e3:6.1f} ms {row['hardware_s']:9.2f} s  "
                  f"{row['angle_error_rms_rad']:.2e} rad {row['angle_error_max_rad']:10.2e} rad")
    m = r["mujoco_clocks"]
    print(f"mujoco clocks: {m['readings']} timed readings; equal on MuJoCo's "
          f"{m['timestep_s'] * 1e3:g} ms grid: {m['agree_quantized'] * 100:.1f} %; vs continuous "
          f"instants max {m['max_diff_m'] * 1e3:.2f} mm; timed vs instantaneous mean "
          f"{m['stale_m'] * 1e3:.1f} mm")
    if "motion" in r:
        mo = r["motion"]
        print(f"motion: occupied F1 (seeds {mo['seeds']})")
        for key, label in (("static_t_room", "static t_room"),
                           ("static_along_path", "static, where the drive swept"),
                           ("moving_perfect_odometry", "moving, perfect odometry"),
                           ("moving_bundled", "moving, bundled odometry")):
            print(f"  {label:<32} {mo[key]:.3f}  ({mo['sweeps'][key]} sweeps, "
                  f"{mo[key + '_hardware_s']:.1f} s hardware)")
    if "timesteps" in r:
        print("timesteps: 1.3 × 0.9 m box, one sweep from (500, 400) mm, seed 2; change of a "
              "true angle at a read when the step is halved (check: ≤ 0.1°)")
        print("  τ ms  step ms  backlash   dt ms   change        check    occupied F1 (made anyway)")
        for t in r["timesteps"]:
            print(f"  {t['belt_timeconst_s'] * 1e3:4g}  {t['step_time_s'] * 1e3:7g}  "
                  f"{math.degrees(t['backlash_rad']):7g}°  {t['timestep_s'] * 1e3:6g}  "
                  f"{_deg(t['angle_change_rad'])}  {'passes ' if t['passes'] else 'refused'}  "
                  f"{t['occupied_f1']:.3f}")
    return 0
