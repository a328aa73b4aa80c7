"""`irring study`: a grid of designs × scenarios × seeds × knobs, resumable, on any executor."""

from __future__ import annotations

import argparse
import json
import sys
import time
import traceback
from pathlib import Path

from .. import errors
from ..core import MAX_RUNS
from ..outputs import check_out, folder_name, folder_note
from ..pipeline import progress_bar, progress_enabled
from ..studies import study
from ..studies.executor import WARMUP_NOTE, WorkerLost, capacity, executor
from ._common import add_executor_options, describe, given, out_path

EPILOG = f"""\
the study file (YAML):
  designs:   [rotating12, radial12, {{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 45,
              step_deg: 1.08}}]     named designs (rotating12 radial12 rotating1 laser sonar12)
                                   or parametric rings (optional: sensor, name; the
                                   half-angle is rounded to whole steps)
  scenarios: [t_room, t_room_cylinder, my_room.yaml, my_rooms/]   bundled names, paths or
             folders (every *.yaml in them, in name order)
  seeds:     [1, 2, 3]             explicit seeds, or a count N: each scenario's seed, +1, …
  knobs:     {{step_stride: [1, 2], samples: [1, 4], settle_ms: [0, 40]}}      optional; a
             knob left out keeps the scenario's value. settle_ms only changes the map when
             the scenario simulates belt_dynamics and timing (e.g. t_room_moving); otherwise
             it only adds hardware time

one run per design × scenario × knob values × seed (at most {MAX_RUNS:,} runs a
study): every pose swept, estimated, mapped and scored as `irring run` does, every design judged on the
scenario's own ground truth. --resume refuses kept runs of a design since changed under
its name.

writes to DIR:
  results.csv     one row per run, appended as each finishes (a killed study loses only the
                  runs in flight; --resume runs the rest), rewritten in grid order at the end:
                  design, scenario, step_stride, samples, settle_ms, seed (the grid point),
                  the design's numbers, every score, hardware time (one 360° view / all
                  poses), compute and simulation time, run time, the worker's peak memory,
                  irring version. Only the timing columns differ between two runs of a study.
  results.parquet the same, if pyarrow is installed
  summary.csv/.json  per configuration (design × knob values): mean and sd of each score
                  (shadow over the runs in rooms that hide wall behind an obstacle: shadow_runs)
  study.png       occupied F1 (its axis stretched towards 1) and coverage against hardware
                  time, Pareto front marked; titled with the study file's name and its runs
                  (designs × rooms × …)

a run that fails stops the study, its line ending with how many finished runs are kept for
--resume (a worker killed under its run, as by the out-of-memory killer: exit 130).

runs made elsewhere (one study split by seeds over machines) merge: append each part's
results.csv rows, without the header, to one DIR/results.csv and run the whole study with
--resume (start each part alike: a room's path as the study file reaches it names its rows).

examples:
  irring study designs.yaml --out out/designs --workers 2
  irring study designs.yaml --out out/designs --resume        after an interruption
  irring study designs.yaml --dask tcp://scheduler:8786       on a Dask cluster
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Run every design of a study file on every scenario, seed and knob "
             "setting; stream one row per run to DIR/results.csv, then summarise "
             "(mean and spread per configuration) and chart accuracy against hardware "
             "time with the Pareto front.",
             EPILOG)
    p.add_argument("file", metavar="FILE.yaml", type=given("a study file"),
                   help="the study file (see below)")
    p.add_argument("--out", type=out_path, default=None, metavar="DIR",
                   help="output folder (default: out/<file name without .yaml>, with ~ and "
                        "8 hex digits of its SHA-256 after a name of other than lower-case "
                        "letters, digits and ._-)")
    add_executor_options(p)
    p.add_argument("--resume", action="store_true",
                   help="keep the runs already in DIR/results.csv and run only the others")
    p.add_argument("--json", action="store_true",
                   help="print the summary (one record per configuration) as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    spec = study.load_study(args.file)
    stem = Path(args.file).stem
    out = check_out(args.out if args.out else Path("out") / folder_name(stem),
                    files=study.SUMMARY_FILES.values())
    t0 = time.perf_counter()
    shown = progress_enabled() and not args.json
    started: list[int] = []
    try:
        with executor(args.workers, args.dask) as ex, \
                progress_bar(0, "study", shown, unit="run", warmup=capacity(ex),
                             warmup_note=WARMUP_NOTE) as bar:
            result = study.run_study(
                spec, out, ex, resume=args.resume,
                on_start=lambda done, todo: (started.append(todo), bar.reset(total=todo)),
                progress=lambda _: bar.update())
    except WorkerLost as exc:   # killed from outside as Ctrl-C would stop it: the rows stay
        raise WorkerLost(f"{exc}; {_kept(out)}") from exc
    except BaseException as exc:   # Ctrl-C, SIGTERM, or an import they cut short
        if errors.interrupted(exc):
            return _interrupted(out)
        if not started or isinstance(exc, errors.IrringError):
            raise
        # a run that raised (a bug): its line, and that the runs before it are kept
        if getattr(args, "debug", False):
            traceback.print_exc()
        status, message = errors.describe(exc)
        print(f"irring study: error: {message}; {_kept(out)}", file=sys.stderr)
        return status
    wall = time.perf_counter() - t0
    by, records = study.summary_records(out)
    if args.json:
        print(json.dumps(records, indent=2))
        return 0
    ran = result["ran"]
    kept = [f"{result['done_before']} already in the file"] if result["done_before"] else []
    # a resumed study whose file lost a design, room or seed keeps those rows, unsummarised
    outside = len(result["rows"]) - result["done_before"] - ran
    if outside:
        kept.append(f"{outside} run(s) of grid points no longer in "
                    f"{errors.printable(args.file)}: kept in the file, left out of the summary")
    kept = f" ({'; '.join(kept)})" if kept else ""
    rate = f", {ran / wall:.1f} runs/s" if ran else ""
    print(f"{len(result['rows'])} run(s) in {errors.printable(str(out / study.RESULTS))}: ran {ran} in {wall:.1f} s"
          f"{rate}{kept}")
    print(study.table(records, by))
    print("mean ± sd over scenarios × seeds; shadow only over the runs in rooms that hide "
          "wall behind an obstacle (in k/n: k of the n runs; —: none); RMSE: range error of "
          "the valid readings against the true range; hardware: one 360° view; compute: "
          "estimator + mapper CPU per sweep (median); front: on the Pareto "
          "front of hardware time against occupied F1 (f1), coverage (cov), range RMSE (rmse)")
    for kind, path in result["paths"].items():
        print(f"  {kind:<13}{errors.printable(str(path))}")
    note = None if args.out else folder_note(stem, out, "the study file")
    if note:
        print(f"  note         {note}")
    return 0


def _kept(out: Path) -> str:
    """How many finished runs the file keeps, and how to run the rest."""
    path = out / study.RESULTS
    kept = len(study.read_results(path)) if path.exists() else 0
    return (f"{kept} finished run(s) kept in {errors.printable(str(path))}: run the same "
            "command with --resume to run the rest")


def _interrupted(out: Path) -> int:
    """Ctrl-C or SIGTERM: say how many runs the file keeps for --resume."""
    print(f"irring study: interrupted; {_kept(out)}", file=sys.stderr)
    return errors.INTERRUPTED
