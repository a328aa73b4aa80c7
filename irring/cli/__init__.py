"""The `irring` command. Each subcommand lives in its own module under irring/cli/.

A module registers itself with ``register(subparsers)``, which adds a parser whose
``func(args) -> int`` does the work. Nothing below the cli imports it.
"""

from __future__ import annotations

import argparse
import importlib
import sys

# Subcommand modules, in the order `irring --help` lists them.
COMMANDS = ("run", "replay", "view", "scenarios", "calibrate", "emulate", "drive", "geometry",
            "compare", "study", "bench")

DESCRIPTION = """\
irring: a MuJoCo testbed for the rotating infrared range-sensor ring of
Park, Baek & Lee (IEEE/ASME AIM 2005). Twelve Sharp GP2 sensors on a 0.15 m
ring turn ±37.8° together, so neighbouring beams overlap and the ring sees
past thin obstacles. Simulated and real (serial) sweeps go through the same
estimator and occupancy-grid mapper.

Start with `irring run` (the default scenario, t_room) and look at the map
it writes; `irring scenarios` lists the bundled scenarios."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="irring", description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"irring {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"{__name__}.{name}").register(sub)
    return parser


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("irring")
    except PackageNotFoundError:   # a source tree used without installing
        return "unknown (not installed)"


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    from ..studies.executor import ExecutorError
    from ..scenario import ScenarioError

    try:
        return int(args.func(args) or 0)
    except (ScenarioError, ExecutorError) as exc:
        print(f"irring: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("irring: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
