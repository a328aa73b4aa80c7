"""`irring scenarios`: list the bundled scenarios."""

from __future__ import annotations

import argparse

from .. import scenario
from ._common import describe


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "List the bundled scenarios (name, poses, obstacles, "
             "description). Pass a name or a YAML path to other commands.", raw=False)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    rows = []
    for name, path in scenario.bundled().items():
        sc = scenario.load_scenario(path)
        rows.append((name, f"{len(sc.robot.poses)} pose(s)", f"{len(sc.obstacles)} obstacle(s)",
                     sc.description))
    width = max(len(r[0]) for r in rows)
    for name, poses, obstacles, desc in rows:
        default = " (default)" if name == scenario.DEFAULT_SCENARIO else ""
        print(f"{name:<{width}}  {poses:<9} {obstacles:<13} {desc}{default}")
    return 0
