"""`irring bench …`: benchmarks that print measured figures.

Each benchmark is a module ``irring/cli/bench_<name>.py`` with ``register(subparsers)``;
the measurements themselves live in ``irring/studies/``.
"""

from __future__ import annotations

import argparse
import importlib

BENCHES = ("accuracy", "speed", "effects", "estimator", "dynamics", "rooms", "study", "render")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="benchmarks: what accuracy costs in time, stage speeds",
                       description="Benchmarks that measure and print figures on this machine.")
    inner = p.add_subparsers(dest="bench", metavar="BENCH")
    for name in BENCHES:
        importlib.import_module(f"{__package__}.bench_{name}").register(inner)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])
