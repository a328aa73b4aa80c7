"""How ``irring study`` scales: wall time and runs per second on 1 and N local workers, and
peak memory as the grid grows (``irring bench study``). The grid and what is timed:
docs/studies.md.
"""

from __future__ import annotations

import os
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Sequence

from .. import designs
from ..pipeline import progress_bar
from ..resources import python_here
from .executor import executor
from .report import load_average, load_line
from .study import DesignSpec, Study, grid, read_results, run_study

SCENARIOS = ("t_room", "t_room_cylinder", "t_room_three_cylinders")


def study_for(seeds: int):
    """Every named design × the three T-rooms × seeds 1 … ``seeds``."""
    return Study(tuple(DesignSpec(n, name=n) for n in designs.DESIGN_BY_NAME), SCENARIOS,
                 seeds=tuple(range(1, seeds + 1)))


def _timed(seeds: int, workers: int, out: Path, bar) -> dict:
    t0 = time.perf_counter()
    with executor(workers) as ex:
        rows = run_study(study_for(seeds), out, ex, progress=lambda row: bar.update())["rows"]
    wall = time.perf_counter() - t0
    run_s = sorted(float(r["run_s"]) for r in rows)
    return {"runs": len(rows), "workers": workers, "wall_s": wall, "runs_per_s": len(rows) / wall,
            "run_s_median": run_s[len(run_s) // 2], "run_s_max": run_s[-1]}


# Runs `irring study` in a fresh interpreter and prints its own peak memory (MB) last.
_CHILD = """import sys
from irring.cli import main
from irring.studies.report import peak_memory_mb
code = main(sys.argv[1:])
print(peak_memory_mb())
sys.exit(code)
"""


def _memory(seeds: int, workers: int, tmp: Path) -> dict:
    """Peak memory of ``irring study`` on the ``seeds`` grid, in a fresh process (so nothing
    measured before counts): its own peak and its largest worker's."""
    s = study_for(seeds)
    (tmp / "study.yaml").write_text(f"designs: [{', '.join(d.label for d in s.designs)}]\n"
                                    f"scenarios: [{', '.join(s.scenarios)}]\n"
                                    f"seeds: {list(s.seeds)}\n")
    t0 = time.perf_counter()
    out = subprocess.run([*python_here(_CHILD), "study", str(tmp / "study.yaml"),
                          "--out", str(tmp / "out"), "--workers", str(workers)],
                         check=True, capture_output=True, text=True).stdout
    wall = time.perf_counter() - t0
    rows = read_results(tmp / "out" / "results.csv")
    return {"runs": len(rows), "workers": workers, "wall_s": wall,
            "worker_peak_mb": max(float(r["worker_peak_mb"]) for r in rows),
            "parent_peak_mb": float(out.split()[-1])}


def measure(seeds: int = 20, workers: Sequence[int] = (1, 2),
            memory_seeds: Sequence[int] = (4, 40), memory_workers: int = 2,
            progress: bool | None = None) -> dict:
    """Time the ``seeds`` grid on each worker count, then peak memory on each grid of
    ``memory_seeds``; ``progress``: a bar over every run (None: at a terminal). Returns
    plain figures (see :func:`report`)."""
    load_before = load_average()
    speed, memory = [], []
    per_seed = len(grid(study_for(1)))   # runs a seed adds to a grid
    total = per_seed * (seeds * len(workers) + sum(memory_seeds))
    with tempfile.TemporaryDirectory(prefix="irring-scaling-") as tmp, \
            progress_bar(total, "bench study", progress, unit="run") as bar:
        for i, w in enumerate(workers):
            speed.append(_timed(seeds, w, Path(tmp) / f"speed{i}", bar))
        for i, s in enumerate(memory_seeds):
            (Path(tmp) / f"memory{i}").mkdir()
            memory.append(_memory(s, memory_workers, Path(tmp) / f"memory{i}"))
            bar.update(per_seed * s)   # a fresh process: its runs are counted when it ends
    base = speed[0]["wall_s"] if speed else None
    for r in speed:
        r["speedup"] = base / r["wall_s"]
    return {"grid": f"{len(study_for(1).designs)} designs × {len(SCENARIOS)} rooms × seeds",
            "speed": speed, "memory": memory, "cpus": os.cpu_count(),
            "load_before": load_before, "load_after": load_average()}


def report(r: dict) -> str:
    lines = [f"{r['grid']}; {r['cpus']} CPUs",
             load_line(r["load_before"], r["load_after"], r["cpus"])]
    for s in r["speed"]:
        lines.append(f"  {s['runs']} runs, {s['workers']} worker(s): {s['wall_s']:.1f} s, "
                     f"{s['runs_per_s']:.1f} runs/s, speed-up {s['speedup']:.2f}× over the "
                     f"first; per run median {s['run_s_median'] * 1e3:.0f} ms, max "
                     f"{s['run_s_max'] * 1e3:.0f} ms")
    for m in r["memory"]:
        lines.append(f"  {m['runs']} runs, {m['workers']} workers: peak memory per worker "
                     f"{m['worker_peak_mb']:.0f} MB, irring study itself "
                     f"{m['parent_peak_mb']:.0f} MB ({m['wall_s']:.1f} s)")
    return "\n".join(lines)
