"""`irring bench long`: the estimator's time and memory per reading as a sweep grows."""

from __future__ import annotations

import argparse
import json

from .. import errors
from ..core import MAX_ESTIMATED_READINGS
from ..studies.long_sweeps import KINDS, MAX_LONG_STEPS, SENSORS, STEPS, measure, report
from ._common import at_least, describe

EPILOG = f"""\
what it prints, per sweep (each estimated twice: timed, then with tracemalloc on):
  room      t_room's second scan pose simulated with the paper's ring sweeping its ±37.8°
            in STEPS steps (71 is the paper's): the same walls, ever denser readings
  circle    a device's sweep of STEPS motor steps of 0.01° (belt ratio 1), every reading
            1300 counts: 36,000 steps turn each sensor round the full circle
  CPU s, µs/reading    the estimator's CPU time on the sweep, and per reading
  peak MB, B/reading   its peak traced memory (numpy's arrays), and per reading, against
                       the work check's model (core.ESTIMATE_BYTES_PER_READING)

A sweep of more than {MAX_ESTIMATED_READINGS:,} readings is refused by the estimator
(core.MAX_ESTIMATED_READINGS, exit 5): {MAX_LONG_STEPS:,} steps of {SENSORS} sensors at most here.

examples:
  irring bench long                            both kinds, 71 … 18,000 steps (≈ 1 min)
  irring bench long --kind circle --steps 36000
  irring bench long --numpy --steps 71 710 4500   the numpy statement beside the kernels
  irring bench long --json
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Time and peak memory of the estimator per reading on sweeps of more and "
             "more steps: one room read ever more finely, and a device's sweep whose every "
             "reading returns.", EPILOG)
    p.add_argument("--kind", choices=KINDS, action="append",
                   help="room or circle (repeatable; default: both)")
    # a longer sweep would be refused by the estimator after the shorter ones were measured
    p.add_argument("--steps", type=at_least(2, MAX_LONG_STEPS), nargs="+", default=list(STEPS),
                   metavar="N", help=f"steps a sweep (2 … {MAX_LONG_STEPS:,}; default: "
                                     f"{' '.join(str(s) for s in STEPS)})")
    p.add_argument("--numpy", action="store_true",
                   help="also the numpy statement of the estimator (estimate_numpy)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    r = measure(tuple(args.kind or KINDS), tuple(args.steps),
                ("fast", "numpy") if args.numpy else ("fast",))
    print(json.dumps(r, indent=2) if args.json else report(r))
    return errors.OK
