"""`irring bench render`: what drawing a run costs against making its map, and peak memory."""

from __future__ import annotations

import argparse
import json

from ..studies.render_bench import measure, report
from ._common import at_least, describe

EPILOG = """\
Runs the scenario end to end (simulate, estimate, map, score) and writes its outputs
(map.png, the GIF, map.pgm, sweeps.npz) to a temporary folder, in --repeats fresh
processes as `irring run` does; prints medians of CPU seconds (each process's own work:
compare these on a shared machine) and wall seconds, their ratio (target: render ≤ 2×
making the map), loading the picture code, the peak memory (target ≤ 1 GB) and, timed as
often, the whole `irring run SCENARIO` command as a user starts it: interpreter, imports
and parser included (target ≤ 1.5 s wall).

examples:
  irring bench render                          t_room, 5 fresh processes
  irring bench render --scenario my_300_poses.yaml --repeats 1   peak memory of a long run
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "CPU and wall seconds of the render stage against the "
             "stages that make the map, and peak memory.",
             EPILOG)
    p.add_argument("--scenario", default="t_room", metavar="NAME_OR_PATH",
                   help="bundled scenario name or YAML path (default: t_room)")
    p.add_argument("--repeats", type=at_least(1), default=5, metavar="N",
                   help="fresh processes, one run each; medians are printed (default: 5)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    r = measure(args.scenario, repeats=args.repeats)
    print(json.dumps(r, indent=2) if args.json else report(r))
    return 0
