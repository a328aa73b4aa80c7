"""`irring bench accuracy`: what accuracy costs in time, one knob at a time."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from .. import errors
from ..outputs import check_out
from ..studies.report import study_files
from ..pipeline import progress_bar
from ..studies import accuracy
from ..studies.accuracy import DEFAULT_SCENARIOS, KNOBS
from ..studies.executor import WARMUP_NOTE, capacity, executor
from ..core import MAX_SEEDS
from ..scenario import scenario_file
from ._common import (add_executor_options, describe, named_once, out_path, scenario_name,
                      seed_count)

EPILOG = """\
configurations (one knob changed at a time around the scenario as written, the "default"):
  step        read every 2nd / 4th motor step (2.16°, 4.32°) instead of every 1.08° step
  samples     average 2 / 4 / 8 readings per step (the averaging effect; 38.3 ms each)
  settle      wait 0 / 20 / 40 / 60 ms at each step, with belt_dynamics + timing added to the
              scene (a wait only matters when the belt's swing and the GP2's clock are
              simulated); hardware time is then the timed schedule's; these rows are kept
              off the Pareto fronts and drawn as a dashed line
  iterations  estimator: θ = 0 (no iterations), at most 1 / 2 / 5 iterations (default 20);
              a capped run shows the estimate after k iterations: readings still moving
              are kept at the θ they reached
  tolerance   estimator convergence tolerance 1° (default 0.1°)
  regroup     estimator groups the end points into lines at most 1 / 2 / 6 times (default 3),
              then holds the grouping; each grouping is its costliest step
  resolution  map cells of 5 / 20 mm (default 10 mm)
  design      radial12 (the ring held still), rotating1 (one GP2 turning at the centre)

what it measures per configuration (mean over scenarios × seeds; timings: median):
  hardware s  seconds the real ring spends on one 360° view at one pose
  compute ms  estimator + mapper per sweep on this machine, CPU time (so parallel
              workers do not inflate it); the simulator's own time is sim_ms in the
              CSV/JSON: the testbed's cost, not the robot's
  angle mrad  belt+timing rows: RMS of true − assumed beam heading at the measurement
  RMSE mm     estimated − true range over the readings called valid; steep: true
              incidence ≥ 40°; point: end point to true hit point; valid: share of the
              readings with a true return called valid
  F1 occ, coverage, free acc, shadow   the map scores of `irring run`
  front       on the Pareto front for hardware time (hw) / compute time (cpu): nothing
              else is as cheap and at least as good on occupied F1, coverage and range
              RMSE

Runs go through a local process pool (--workers) or a Dask cluster (--dask); results other
than the timings are identical whoever runs them.

writes to DIR: accuracy.json (everything), accuracy.csv (one row per configuration),
runs.csv (one row per run), accuracy.png (accuracy vs hardware time and vs compute time).

examples:
  irring bench accuracy                               t_room_cylinder + t_room, 3 seeds
  irring bench accuracy --knob samples --knob step --seeds 5
  irring bench accuracy --workers 1 --json > accuracy.json
  irring bench accuracy --dask tcp://scheduler:8786   on a Dask cluster (pip install 'irring[dask]')
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Vary the knobs that trade time for accuracy (sensor step, samples per "
             "step, settle time, estimator iterations, tolerance and regrouping, grid "
             "resolution, "
             "design), one at a time around the scenario's default; record accuracy "
             "against hardware time and compute time, mark the Pareto front, write "
             "CSV/JSON and a chart.",
             EPILOG)
    p.add_argument("--scenario", action="append", metavar="S", type=scenario_name,
                   help="bundled scenario name or YAML path; repeat for several (default: "
                        + ", ".join(DEFAULT_SCENARIOS) + ")")
    p.add_argument("--knob", action="append", choices=KNOBS, metavar="K",
                   help="knob to vary; repeat for several (default: all: " + ", ".join(KNOBS)
                        + ")")
    p.add_argument("--seeds", type=seed_count, default=3, metavar="N",
                   help="runs per configuration and scenario, seeds scenario.seed, +1, … "
                        f"(1 … {MAX_SEEDS}; default: 3)")
    add_executor_options(p)
    p.add_argument("--out", type=out_path, default="out/bench_accuracy", metavar="DIR",
                   help="output folder (default: out/bench_accuracy)")
    p.add_argument("--json", action="store_true",
                   help="print the result (configurations, per scenario, every run) as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    scenarios = args.scenario or list(accuracy.DEFAULT_SCENARIOS)
    named_once(scenarios, "--scenario", scenario_file)
    named_once(args.knob or (), "--knob")
    configs = accuracy.configurations(args.knob)
    # a study holding the folder, or a folder of an output's name: refused before the work
    check_out(args.out, held=False, files=study_files("accuracy"))
    total = len(configs) * len(scenarios) * args.seeds
    with executor(args.workers, args.dask) as ex, \
            progress_bar(total, "bench accuracy", unit="run", warmup=capacity(ex),
                         warmup_note=WARMUP_NOTE) as bar:
        result = accuracy.measure(scenarios, seeds=args.seeds, configs=configs, ex=ex,
                                  progress=lambda _: bar.update())
    paths = accuracy.write_outputs(result, args.out)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    meta = result["meta"]
    print(f"what accuracy costs in time: {', '.join(meta['scenarios'])}, {meta['seeds']} "
          f"seed(s), {meta['jobs']} runs in {meta['wall_s']:.1f} s; one knob at a time "
          "around the default")
    print(accuracy.table(result["configs"]))
    print(f"wrote {errors.printable(str(args.out))}/: "
          + ", ".join(sorted(Path(p).name for p in paths.values())))
    return 0
