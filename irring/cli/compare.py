"""`irring compare`: ring designs side by side on simulated scenes."""

from __future__ import annotations

import argparse
import json
import textwrap
from collections.abc import Mapping

from .. import designs, errors, safe_yaml
from ..errors import UsageError
from ..designs import DESIGN_BY_NAME
from ..outputs import check_out
from ..studies.report import study_files
from ..pipeline import progress_enabled
from ..studies import compare, study
from ..studies.study import StudyError
from ..studies.executor import executor
from ..core import MAX_SEEDS
from ..scenario import scenario_file
from ._common import (add_executor_options, at_least, check_distances_clear, describe,
                      distances_mm, named_once, out_path, scenario_name, seed_count)

# cylinder bearings a detection curve tries per distance: 3,600 took 20-50 s (0.008° apart
# over the paper ring's 30° period); 10^8 ran out of memory
MAX_BEARINGS = 3_600

DEFAULT_SCENARIOS = ("t_room_cylinder", "t_room_three_cylinders", "t_room")

EPILOG = textwrap.fill(f"what it measures, per design (mean over scenarios × seeds; ± is "
                       f"{compare.SPREAD}):", 90) + """
  occupied_precision/recall/f1, free_accuracy, coverage, shadow
                      the scores of `irring run`, all designs scored against the same
                      ground truth (the scene as written, with its own design's reach);
                      shadow = share of the wall behind thin posts that the map shows
  hardware_time_s     seconds the real device needs for one 360° view at one pose
  compute_time_s      simulate + estimate + map per view on this machine (median; the
                      estimator's and mapper's CPU time, the simulator's wall time)
  min_detectable_radius_m
                      smallest cylinder seen at every bearing, per distance from the
                      robot centre (rays read from each design's built MuJoCo model);
                      too_near: none only because the near side is inside the sensor's
                      minimum range of the sensor facing it (the table: "too near")

designs: rotating12 (the paper's ring), radial12 (the same, held still), rotating1 (one
GP2 turning 360° at the centre), laser (SICK-like, 0.5°, 8 m), sonar12 (12 ultrasonic
rangers, ±15° cone, nearest echo), or a ring of your own as a study file writes it
(sensors, radius_mm, sweep_half_angle_deg rounded to whole steps of step_deg; optional
sensor, default gp2d12, and name). Each design carries its own sensor, so a laser is
simulated as a laser in the same room, poses and effects.

writes to DIR: compare.json (per-design records, every run, detection, the rooms'
cylinder radii), compare.csv (one row per design), runs.csv (one row per run), compare.png
(chart; its detection panel marks the compared rooms' cylinder radii, a dotted line each).

examples:
  irring compare                                        every design, the three T-rooms, 3 seeds
  irring compare --scenario t_room_cylinder --design rotating12 --design radial12
  irring compare --design rotating12 --design '{sensors: 16, radius_mm: 150,
      sweep_half_angle_deg: 0, step_deg: 1.08, name: fixed16}'   the paper's ring vs 16 held still
  irring compare --seeds 1 --json > designs.json
  irring compare --dask tcp://scheduler:8786            the same runs on a Dask cluster
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Compare ring designs: each design sweeps, estimates and "
             "maps the same scenes (as `irring run` does) over several "
             "seeds; prints a table and writes CSV/JSON and a chart.",
             EPILOG)
    p.add_argument("--scenario", action="append", metavar="S", type=scenario_name,
                   help="bundled scenario name or YAML path; repeat for several (default: "
                        + ", ".join(DEFAULT_SCENARIOS) + ")")
    p.add_argument("--design", action="append", metavar="D",
                   help="a design name, or a ring of your own as a study file writes it: "
                        "'{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 45, step_deg: "
                        "1.08, name: ring8}' (optional: sensor, name); repeat for several "
                        "(default: all: " + ", ".join(DESIGN_BY_NAME) + ")")
    p.add_argument("--seeds", type=seed_count, default=3, metavar="N",
                   help="runs per scenario and design, seeds scenario.seed, +1, … "
                        f"(1 … {MAX_SEEDS}; default: 3)")
    p.add_argument("--out", type=out_path, default="out/compare", metavar="DIR",
                   help="output folder (default: out/compare)")
    p.add_argument("--distances-mm", type=distances_mm, default="250,350,450,550,650,750",
                   metavar="LIST",
                   help="comma-separated positive distances (mm, robot centre to the "
                        "cylinder's near side, beyond every design's ring and housing) for the "
                        "detection curve "
                        "(default: 250,350,450,550,650,750)")
    p.add_argument("--bearings", type=at_least(8, MAX_BEARINGS), default=180, metavar="N",
                   help="cylinder bearings tried per distance, over one symmetry period of "
                        f"the design (8 … {MAX_BEARINGS}; default: 180)")
    add_executor_options(p)
    p.add_argument("--json", action="store_true",
                   help="print one JSON record per design instead of the table")
    p.set_defaults(func=run)


def design_arg(text: str) -> designs.Design:
    """A ``--design`` value: a named design, or a parametric ring in a study file's YAML
    mapping (``irring.studies.study.design_spec``). Raises UsageError."""
    if text in DESIGN_BY_NAME:
        return designs.get(text)
    try:
        raw = safe_yaml.load(text, "--design", "design")
    except safe_yaml.YamlError as exc:
        raw, why = None, f" ({exc})"
    else:
        why = ""
    if not isinstance(raw, Mapping):
        raise UsageError(f"--design {text!r}: not a named design{why}; choose one of: "
                         f"{', '.join(DESIGN_BY_NAME)}, or give a ring of your own as a study "
                         "file writes it: '{sensors: 8, radius_mm: 120, sweep_half_angle_deg: "
                         "45, step_deg: 1.08, name: ring8}'")
    try:
        return study.design_spec("", "--design", raw).build()
    except StudyError as exc:
        raise UsageError(str(exc)) from None


def run(args: argparse.Namespace) -> int:
    scenarios = args.scenario or list(DEFAULT_SCENARIOS)
    chosen = [design_arg(d) for d in args.design or list(designs.DESIGN_BY_NAME)]
    names = [d.name for d in chosen]
    named_once(scenarios, "--scenario", scenario_file)
    named_once(names, "--design")
    check_distances_clear(args.distances_mm, chosen)
    # a study holding the folder, or a folder of an output's name: refused before the work
    check_out(args.out, held=False, files=study_files("compare"))
    with executor(args.workers, args.dask) as ex:
        result = compare.compare(scenarios, chosen, args.seeds,
                                 detection_distances_m=args.distances_mm, bearings=args.bearings,
                                 progress=progress_enabled() and not args.json, ex=ex)
    paths = compare.write_outputs(result, args.out)
    if args.json:
        print(json.dumps(result["designs"], indent=2))
        return 0
    runs = len(result["runs"])
    print(f"{len(names)} design(s) × {len(scenarios)} scenario(s) × {args.seeds} seed(s) = "
          f"{runs} runs")
    print(compare.table(result["designs"]))
    print("r@d: smallest cylinder radius seen at every bearing at distance d (miss: none ≤ "
          "200 mm); times: one 360° view")
    for kind, path in paths.items():
        print(f"  {kind:<9}{errors.printable(str(path))}")
    return 0
