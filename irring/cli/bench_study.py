"""`irring bench study`: how `irring study` scales with workers, and its memory as grids grow."""

from __future__ import annotations

import argparse
import json

from ..studies.scaling import measure, report
from ..core import MAX_SEEDS
from ._common import at_least, describe, seed_count

EPILOG = """\
grid: every named design × t_room, t_room_cylinder, t_room_three_cylinders × seeds 1 … S,
run as `irring study` runs it (rows streamed to a temporary results.csv, summary, chart).

prints, per worker count: wall time (executor start to chart), runs per second, speed-up
over the first count, median and longest run; then, for a small and a ten times larger
grid, each run by `irring study` in a fresh process, the peak memory of that process and of
its largest worker (flat memory: the two grids agree).
The load average before and after says how busy the machine was.

examples:
  irring bench study                           300 runs on 1 and on 2 workers; 60 and 600 runs
  irring bench study --seeds 4 --memory-seeds 2 --memory-seeds 8      a quick look
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Time a grid of designs × rooms × seeds on 1 and on N local workers, "
             "and measure peak memory on a small and a larger grid.",
             EPILOG)
    p.add_argument("--seeds", type=seed_count, default=20, metavar="S",
                   help=f"seeds per design and room for the timing (1 … {MAX_SEEDS}; default: "
                        f"20, 300 runs)")
    p.add_argument("--workers", type=at_least(1), action="append", metavar="N",
                   help="worker counts to time, repeatable (default: 1 and 2)")
    p.add_argument("--memory-seeds", type=seed_count, action="append", metavar="S",
                   help="seeds of the memory grids, repeatable (default: 4 and 40: 60 and "
                        "600 runs)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    r = measure(args.seeds, args.workers or (1, 2), args.memory_seeds or (4, 40))
    print(json.dumps(r, indent=2) if args.json else report(r))
    return 0
