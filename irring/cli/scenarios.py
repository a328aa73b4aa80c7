"""`irring scenarios [SCENARIO ...]`: list the bundled scenarios, or check the ones named."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .. import scenario
from ..errors import IrringError, printable
from ..maps.mapping import check_scenario_grid
from ._common import describe, scenarios_or_folders


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "List the bundled scenarios (name, poses, obstacles, "
             "description). Pass a name or a YAML path to other commands. With names or "
             "paths, list those instead: each is loaded and checked as `irring run` would "
             "(a bad file is an error naming it, and the others are still checked), and a note names any obstacle the walls "
             "clip (one reaching through a wall: what lies beyond it is never seen). "
             "Writing your own: every key, unit and range in scenarios/README.md.",
             raw=False)
    p.add_argument("scenario", nargs="*", metavar="SCENARIO",
                   type=scenarios_or_folders,
                   help="bundled scenario names, YAML paths or folders (every *.yaml in "
                        "them) to check (default: the bundled scenarios)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    named = args.scenario
    rows = []
    failed: list[IrringError] = []

    def refuse(exc: IrringError) -> None:
        # each file is checked: one bad file hid the verdict on all the others
        print(f"irring scenarios: error: {printable(str(exc))}", file=sys.stderr)
        failed.append(exc)

    listed = []   # (name or path, found in a folder): a folder stands for its *.yaml
    for given in named:
        try:
            listed += scenario.listed(given)
        except IrringError as exc:   # a folder holding no *.yaml
            refuse(exc)
    total = len(listed) + len(failed)
    for name, in_folder in listed if named else [(n, False) for n in scenario.bundled()]:
        try:
            why = scenario.not_a_scenario_file(Path(name)) if in_folder else None
            if why:
                raise scenario.ScenarioError(why)
            sc = scenario.load_scenario(name if named else scenario.bundled()[name])
            check_scenario_grid(sc)   # `irring run` refuses its map before any work
        except IrringError as exc:
            if not named:   # a bundled scenario that does not load: the install is broken
                raise
            refuse(exc)
            continue
        default = "" if named or name != scenario.DEFAULT_SCENARIO else " (default)"
        rows.append((printable(name) if named else name, f"{len(sc.robot.poses)} pose(s)",
                     f"{len(sc.obstacles)} obstacle(s)", printable(sc.description) + default,
                     [c.note for c in scenario.clipped_obstacles(sc)]))
    width = max((len(r[0]) for r in rows), default=0)
    for name, poses, obstacles, desc, notes in rows:
        print(f"{name:<{width}}  {poses:<9} {obstacles:<13} {desc}".rstrip())
        for note in notes:
            print(f"  note: {note}")
    if failed:
        if total > 1:
            print(f"irring scenarios: {len(failed)} of {total} scenario(s) refused",
                  file=sys.stderr)
        return failed[0].status
    return 0
