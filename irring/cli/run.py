"""`irring run [SCENARIO]`: simulate a scenario's scan poses, estimate, map, score, draw."""

from __future__ import annotations

import argparse
import json
import math
import os
from pathlib import Path

from .. import errors, pipeline
from ..core import score_text
from ..maps import metrics
from ..outputs import RUN_FILES, check_out, folder_name, folder_note
from ..scenario import DEFAULT_SCENARIO, load_scenario
from ._common import (add_mcap_option, describe, given, mcap_beside_outputs, out_path,
                      scenario_name, seed, spare_inputs)

HELP = """\
Simulate one sweep of the ring at each of the scenario's scan poses, turn the ADC counts
into end points with the paper's iterative estimator, build the occupancy grid pose by pose
(10 mm cells by default) and score it against the scenario's ground truth.

Writes into --out (default ./out/<scenario>; a name of other than lower-case letters,
digits and ._- gets ~ and 8 hex digits of its SHA-256, so no two names share a folder):
  map.png            the map: unknown grey, free white, occupied black; true walls in blue,
                     scan poses in red, each pose's sensor reach as a dashed orange circle
  map_building.gif   the map being built, sweep by sweep
  map.pgm, map.yaml  the map for ROS map_server (free 254, occupied 0, unknown 205)
  sweeps.npz         the sweeps, for `irring replay`

Scores (0 … 1, 1-cell tolerance; see irring/maps/metrics.py): occupied precision / recall / F1,
free accuracy, coverage of the free area the poses can reach, and shadow (share of the wall
hidden behind obstacles from every pose centre that is mapped; n/a where none is: a wall one
pose cannot see past a table leg and another pose sees is no shadow). Hardware time is what
the real ring would spend (71 steps × 38.3 ms per sweep by default); compute time is this
machine's, per stage.

Readings: "N valid (…)" says why the others are not (irring.core.Reason): no return (nothing
within range), out of range (outside the sensor's calibrated range), incidence unknown (on
no wall line and too few neighbours to tell the angle of incidence: read square on, it could
be over 100 mm long), not converged (the iteration did not settle), foldover ambiguous (with
the foldover effect: which side of the GP2's peak is undecided), saturated (ADC at full
scale), missing (lost on the serial link, `irring drive`).

examples:
  irring run                                  # the default scenario, t_room
  irring run t_room_cylinder --out out/cyl    # a bundled scenario by name
  irring run my_room.yaml --json              # your own scenario file; JSON on stdout
  irring run t_room --mcap out/t_room.mcap    # also as MCAP for Foxglove / rosbag2
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, HELP)
    p.add_argument("scenario", nargs="?", default=None, metavar="SCENARIO",
                   type=scenario_name,
                   help="bundled scenario name or YAML path (default: t_room; "
                        "`irring scenarios` lists them; writing your own: every key, unit "
                        "and range in scenarios/README.md)")
    p.add_argument("--out", type=out_path, default=None, metavar="DIR",
                   help="output folder (default: ./out/<scenario>)")
    p.add_argument("--json", action="store_true",
                   help="print a JSON summary on stdout instead of the readable one")
    p.add_argument("--seed", type=seed, default=None,
                   help="noise seed ≥ 0 (default: the scenario's `seed`)")
    p.add_argument("--calibration", type=given("a calibration file", Path), default=None,
                   metavar="FILE",
                   help="calibration YAML from `irring calibrate` (default: what the scene "
                        "simulates: its sensor curve, a(θ), b(θ) only with `incidence`, its "
                        "noise; docs/calibration.md)")
    p.add_argument("--no-animation", action="store_true",
                   help="skip the GIF")
    add_mcap_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    spare_inputs({"--mcap": args.mcap}, {"SCENARIO": args.scenario,
                                         "--calibration": args.calibration})
    scenario = load_scenario(args.scenario or DEFAULT_SCENARIO)
    out = check_out(args.out if args.out is not None else Path("out") / folder_name(scenario.name),
                    held=False, files=RUN_FILES)   # a study holding it: refused before the run
    mcap_beside_outputs(args.mcap, out)
    frames = 0 if args.no_animation else pipeline.FRAMES_PER_SWEEP
    result = pipeline.run(scenario, seed=args.seed, calibration_file=args.calibration,
                          frames_per_sweep=frames)
    paths = pipeline.write_outputs(result, out, animation=not args.no_animation,
                                   mcap=args.mcap)
    report(result, paths, as_json=args.json)
    note = None if args.out is not None or args.json else \
        folder_note(scenario.name, out, "the scenario named")
    if note:
        print(f"  note      {note}")
    return 0


def report(result, paths: dict, *, as_json: bool, extra: dict | None = None) -> None:
    """Print the run's summary: JSON (plus ``extra`` keys), or a few readable lines (shared
    with replay and drive)."""
    summary = result.summary()
    if as_json:
        summary.update(extra or {})
        summary["outputs"] = {k: str(v) for k, v in paths.items()}
        print(json.dumps(summary, indent=2))
        return
    for line in summary_lines(result, paths, summary):
        print(line)


def _unnamed_ring(result) -> str:
    """The ring the sweeps were mapped with, when no scenario names its design (the real
    ring without --truth): what the device reported and what was assumed for the rest."""
    if not result.sweeps:
        return "unknown (no scenario, no sweeps)"
    sw = result.sweeps[0]
    ring = sw.ring
    turn = math.degrees(max(abs(ring.min_step), abs(ring.max_step)) * ring.motor_step_rad
                        * ring.gear)
    return (f"not named (no scenario; mapped as {ring.sensors} {sw.sensor_model} sensors on "
            f"R {ring.radius_m * 1000:g} mm, turning ±{turn:.1f}°)")


_f = score_text   # the map's title formats its scores the same way


def _shadow_cells(truth) -> str:
    """How many hidden wall cells the shadow is a share of, and how many of them a sensor
    could range: with none, 0.000 is all any map can score, not a miss."""
    if truth is None:
        return ""
    hidden = int(truth.shadow.sum())
    ranged = int((truth.shadow_ranged & truth.shadow).sum())
    return (f" ({hidden} wall cell(s) hidden from every pose centre; a sensor could range "
            + (f"{ranged} of them)" if ranged else "none of them)"))


def summary_lines(result, paths: dict, summary: dict | None = None) -> list[str]:
    """The readable lines of ``summary`` (``result.summary()``, made here when not given)."""
    s = result.summary() if summary is None else summary
    sc = result.scenario
    lines = []
    source = result.sweeps[0].source if result.sweeps else ""
    head = s["scenario"] or (f"sweeps from {source}" if source else "recorded sweeps")
    if sc is not None and sc.description:
        head += f" — {sc.description}"
    lines.append(head)
    r = s["readings"]
    invalid = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in r.items()
                        if k not in ("total", "valid"))
    drive = s.get("drive")
    where = (f"{s['poses']} sweep(s) along a {drive['path_m'] * 1000:.0f} mm path" if drive
             else f"{s['poses']} pose(s)")
    lines.append(f"  design {s['design'] or _unnamed_ring(result)}, {where}, "
                 f"{r['total']} readings: {r['valid']} valid"
                 + (f" ({invalid})" if invalid else ""))
    for stuck in s.get("stuck_sensors", ()):
        lines.append(f"  warning   {stuck}")
    if drive and drive["note"]:
        lines.append(f"  note      {drive['note']}")
    for clip in s.get("clipped_obstacles", ()):   # a note, not an error: it may be on purpose
        lines.append(f"  note      {clip['note']}")
    sc_ = s["scores"]
    if sc_:
        lines.append(f"  occupied  F1 {_f(sc_['occupied_f1'])}  (precision "
                     f"{_f(sc_['occupied_precision'])}, recall {_f(sc_['occupied_recall'])})")
        reach = None if sc is None else metrics.visible_range_m(sc)
        if reach is not None:   # what the noise costs at the far end, said where it applies
            lines.append(f"            recall counts wall within {reach * 1000:.0f} mm (past it "
                         f"one {sc.sensor.model.upper()} reading tells wall from nothing less "
                         f"than half the time)")
        lines.append(f"  free      accuracy {_f(sc_['free_accuracy'])}, coverage "
                     f"{_f(sc_['coverage'])} of the reachable free area")
        shadow = sc_["shadow"]
        lines.append("  shadow    " + (f"n/a ({metrics.SHADOW_NA})" if shadow is None
                                       else f"{_f(shadow)} of the wall behind obstacles mapped"
                                       + _shadow_cells(result.truth)))
    elif s.get("unscored"):
        lines.append(f"  (not scored: {errors.printable(s['unscored'], 2000)})")
    else:
        lines.append("  (no ground truth: not scored)")
    t = s["compute_time_s"]
    stages = ", ".join(f"{k} {v:.2f}" for k, v in t.items() if k != "total")
    lines.append(f"  time      hardware {s['hardware_time_s']:.1f} s (the real ring); "
                 f"compute {t['total']:.2f} s ({stages})")
    if paths:
        folder = Path(next(iter(paths.values()))).parent
        inside = [Path(p).name for p in paths.values() if Path(p).parent == folder]
        # `--mcap map.mcap`, listed bare after "o/:", was looked for in o/: a file elsewhere
        # is named by its path from the current folder (./map.mcap) or from the root
        elsewhere = [str(p) if Path(p).is_absolute() else f".{os.sep}{p}"
                     for p in paths.values() if Path(p).parent != folder]
        lines.append(f"  wrote     {errors.printable(str(folder))}/: " + ", ".join(inside)
                     + "".join(f"; and {errors.printable(p)}" for p in elsewhere))
    return lines
