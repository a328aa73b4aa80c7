"""`irring bench foldover`: fold-over seen from as close as the housing allows."""

from __future__ import annotations

import argparse
import json
import sys

from .. import errors
from ..outputs import OutputSet, check_out
from ..studies.foldover import (MAP_SCORES, MAX_ERROR_M, OUTSIDE_CELLS, OUTSIDE_MARGIN_M,
                                measure, outside_tolerance_m)
from ..studies.rooms import print_clip_notes, resolve_rooms
from ..core import score_text
from ._common import MAP_COLUMNS, add_room_set_options, describe

SCORE_COLUMNS = tuple(c for c in MAP_COLUMNS if c[0] in MAP_SCORES)

DEFAULT_ROOMS = ("foldover_corner",)

EPILOG = f"""\
what it prints, per room and seed (each run as `irring run` runs it, with the scene's own
effects; a fold-over room lists `foldover` and puts the ring as close to a wall as its
housing allows):
  valid        readings the estimator calls valid
  ambiguous    readings flagged foldover_ambiguous: which side of the GP2's peak undecided
  >{MAX_ERROR_M * 1e3:.0f}mm       valid readings more than {MAX_ERROR_M * 1e3:.0f} mm from their true hit (target 0: none
               on the wrong branch); a valid reading whose beam hit nothing counts here
  max mm       the largest error of a valid reading with a true hit (n/a: none); "inf" when a
               valid reading's beam hit nothing (JSON: no_hit counts them). A beam whose
               surface lies past the sensor's range reads only noise; a valid reading of one
               is judged against that surface (JSON: past_range counts them)
  outside      occupied cells whose centre lies outside the room by more than
               {OUTSIDE_CELLS:g} cells + {OUTSIDE_MARGIN_M * 1e3:.0f} mm ({outside_tolerance_m(0.010) * 1e3:.0f} mm on 10 mm cells; target 0:
               walls never outside)
  nonfinite    valid readings with a NaN or inf x, y or σ (target 0)
  F1 prec rec free  the map's occupied F1, precision, recall and free accuracy, scored as
               `irring bench rooms` scores them (no target here: readings left ambiguous
               are walls the map lacks); the last lines give their mean per sensor model
  verdict      pass when all three targets hold

Figures are per seed (the first is the scenario's own seed + 0). A room file that cannot be
loaded or run is listed with its error and the others are checked.
exit status: 0 when every run passes; {errors.TARGET_MISSED} when a run misses a target (the table says
which); that of the first room's error (1 for a bad file) when a room could not be run.

examples:
  irring bench foldover                        the bundled fold-over room ({', '.join(DEFAULT_ROOMS)})
  irring bench foldover my_rooms/ --seeds 3    rooms of your own: folders of *.yaml or files
  irring bench foldover --json > foldover.json
"""

OUTPUT_FILES = ("foldover.json",)


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Run rooms seen from as close as the ring's housing allows (with the "
             "`foldover` effect) and check issue 13's fold-over targets: no valid reading "
             f"more than {MAX_ERROR_M * 1e3:.0f} mm from its true hit, no wall drawn outside "
             "the room, nothing non-finite.", EPILOG)
    add_room_set_options(p, ", ".join(DEFAULT_ROOMS), 3, "out/bench_foldover", "foldover.json goes")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    scenarios = resolve_rooms(args.rooms or DEFAULT_ROOMS)
    out = check_out(args.out, held=False, files=OUTPUT_FILES)
    rows = measure(scenarios, args.seeds, debug=args.debug)
    with OutputSet(out, files=OUTPUT_FILES) as tmp:
        (tmp / "foldover.json").write_text(json.dumps(rows, indent=2, allow_nan=False))
    failed = [r for r in rows if "error" in r]
    runs = [run for r in rows if "error" not in r for run in r["runs"]]
    n_fail = sum(not run["passed"] for run in runs)
    if args.json:
        print(json.dumps(rows, indent=2, allow_nan=False))
    else:
        _print_table(rows, n_fail, len(runs), out)
    if failed:   # the table has the rest; the status says that not every room was run
        print(f"irring bench foldover: error: {len(failed)} of {len(rows)} room(s) not run; "
              f"{failed[0]['error']}", file=sys.stderr)
        return failed[0]["status"]
    return errors.TARGET_MISSED if n_fail else errors.OK


def _print_table(rows: list[dict], n_fail: int, n_runs: int, out) -> None:
    width = max([len(r["name"]) for r in rows] + [4])
    far = f">{MAX_ERROR_M * 1e3:.0f}mm"
    head = "".join(f"{label:>7}" for _, label, _, _ in SCORE_COLUMNS)
    print(f"{'room':<{width}}  {'seed':>6}{'valid':>7}{'ambiguous':>10}{far:>8}{'max mm':>8}"
          f"{'outside':>8}{'nonfinite':>10}{head}  verdict")
    for r in rows:
        if "error" in r:
            print(f"{r['name']:<{width}}  error: {r['error']}")
            continue
        for i, x in enumerate(r["runs"]):
            name = r["name"] if i == 0 else ""
            worst = ("inf" if x["no_hit"] else "n/a" if x["max_error_m"] is None
                     else f"{x['max_error_m'] * 1e3:.0f}")
            print(f"{name:<{width}}  {x['seed']:>6}{x['valid']:>7}{x['ambiguous']:>10}"
                  f"{x['far']:>8}{worst:>8}{x['cells_outside']:>8}{x['nonfinite']:>10}"
                  f"{_scores(x)}  {'pass' if x['passed'] else 'FAIL'}")
        print_clip_notes(r)
    by_sensor: dict[str, list[dict]] = {}
    for r in rows:
        if "error" not in r:
            by_sensor.setdefault(r["sensor"], []).extend(r["runs"])
    for sensor, runs in sorted(by_sensor.items()):
        mean = {k: _mean([x[k] for x in runs]) for k, _, _, _ in SCORE_COLUMNS}
        print(f"{'mean ' + sensor:<{width}}  {len(runs):>6}{sum(x['valid'] for x in runs):>7}"
              f"{sum(x['ambiguous'] for x in runs):>10}{sum(x['far'] for x in runs):>8}"
              f"{'':>8}{sum(x['cells_outside'] for x in runs):>8}"
              f"{sum(x['nonfinite'] for x in runs):>10}{_scores(mean)}")
    print(f"{n_runs} run(s): {n_fail} miss a target; wrote {errors.printable(str(out))}/foldover.json")


def _scores(x: dict) -> str:
    return "".join(f"{score_text(x[k], s, d):>7}" for k, _, s, d in SCORE_COLUMNS)


def _mean(values: list) -> float | None:
    """The mean of the defined scores (None: none defined)."""
    defined = [v for v in values if v is not None]
    return sum(defined) / len(defined) if defined else None
