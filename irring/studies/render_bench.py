"""What drawing a run costs: the render stage (map.png, the GIF, map.pgm, the recording)
against the stages that make the map (simulate, estimate, map, score), in CPU and wall
seconds, and the peak memory — each repeat a fresh process, as ``irring run`` is — and
the whole ``irring run`` command as a user starts it (interpreter, imports, parser).

CPU time (``time.process_time``; the command's from ``RUSAGE_CHILDREN``) is the process's
own work, the figure to compare on a machine other jobs share; wall time is what a user
waits for.
"""

from __future__ import annotations

import importlib
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

from .. import pipeline
from ..resources import python_here
from ..scenario import load_scenario
from .report import load_average, load_line, peak_memory_mb

KEYS = ("cpu_make_map_s", "wall_make_map_s", "cpu_render_s", "wall_render_s",
        "cpu_load_render_s", "wall_command_s", "cpu_command_s", "peak_memory_mb")
# `python -m {}` in a fresh process, as resources.python_here starts it
_RUN_MODULE = "import runpy; runpy.run_module({!r}, run_name='__main__', alter_sys=True)"


def one_run(scenario_name: str) -> dict:
    """One ``irring run`` in this process, timed by part (the body of each repeat)."""
    c0, w0 = time.process_time(), time.perf_counter()
    scenario = load_scenario(scenario_name)
    c1, w1 = time.process_time(), time.perf_counter()
    result = pipeline.run(scenario, frames_per_sweep=pipeline.FRAMES_PER_SWEEP, progress=False)
    c2, w2 = time.process_time(), time.perf_counter()
    importlib.import_module("irring.maps.render")  # deferred: loading it is a part this times

    c3, w3 = time.process_time(), time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        pipeline.write_outputs(result, out)
    c4, w4 = time.process_time(), time.perf_counter()
    return {"scenario": scenario.name, "poses": len(result.sweeps),
            "frames": pipeline.frame_plan(len(result.sweeps), pipeline.FRAMES_PER_SWEEP)[2],
            "cpu_make_map_s": c2 - c1, "wall_make_map_s": w2 - w1,
            "cpu_load_render_s": c3 - c2, "cpu_render_s": c4 - c3, "wall_render_s": w4 - w3,
            "cpu_command_s": c4 - c0, "wall_command_s": w4 - w0,
            "peak_memory_mb": peak_memory_mb(), "stages_wall_s": result.timings_s}


def measure(scenario_name: str, repeats: int = 5, progress: bool | None = None) -> dict:
    """``repeats`` fresh processes each running :func:`one_run`; medians of every figure
    (peak memory: the largest). ``progress``: a bar over the repeats (None: at a
    terminal). Raises ValueError for repeats < 1."""
    if repeats < 1:
        raise ValueError(f"repeats must be ≥ 1, got {repeats}")
    load_before = load_average()
    runs, commands = [], []
    with pipeline.progress_bar(repeats, "bench render", progress, unit="repeat") as bar:
        for _ in range(repeats):   # the parts and the command in turn: both see the same load
            t = time.perf_counter()
            out = subprocess.run(python_here(_RUN_MODULE.format(__name__)) + [scenario_name],
                                 check=True, capture_output=True, text=True)
            run = json.loads(out.stdout)
            run["wall_process_s"] = time.perf_counter() - t   # interpreter start included
            runs.append(run)
            commands.append(_irring_run(scenario_name))
            bar.update()
    med = {k: statistics.median(r[k] for r in runs) for k in KEYS + ("wall_process_s",)}
    med["peak_memory_mb"] = max(r["peak_memory_mb"] for r in runs)
    return {"scenario": runs[0]["scenario"], "poses": runs[0]["poses"],
            "frames": runs[0]["frames"], "repeats": repeats, **med,
            "render_vs_make_map_cpu": med["cpu_render_s"] / med["cpu_make_map_s"],
            "render_vs_make_map_wall": med["wall_render_s"] / med["wall_make_map_s"],
            "wall_process_all_s": [r["wall_process_s"] for r in runs],
            "wall_irring_run_s": statistics.median(w for w, _ in commands),
            "cpu_irring_run_s": statistics.median(c for _, c in commands),
            "wall_irring_run_all_s": [w for w, _ in commands],
            "load_before": load_before, "load_after": load_average(), "cpus": os.cpu_count()}


def _irring_run(scenario_name: str) -> tuple[float, float]:
    """(wall s, CPU s) of ``irring run SCENARIO`` in a fresh process, outputs to a
    temporary folder."""
    with tempfile.TemporaryDirectory() as tmp:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        subprocess.run(python_here(_RUN_MODULE.format("irring")) + [
            "run", scenario_name, "--out", os.path.join(tmp, "out"), "--json"],
            check=True, capture_output=True)
        wall = time.perf_counter() - t
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def report(r: dict) -> str:
    walls = ", ".join(f"{v:.2f}" for v in r["wall_process_all_s"])
    commands = ", ".join(f"{v:.2f}" for v in r["wall_irring_run_all_s"])
    return "\n".join([
        f"render bench: {r['scenario']} ({r['poses']} poses, {r['frames']} animation frames), "
        f"median of {r['repeats']} fresh processes",
        f"  making the map (simulate, estimate, map, score): cpu {r['cpu_make_map_s']:.2f} s, "
        f"wall {r['wall_make_map_s']:.2f} s",
        f"  render (map.png, GIF, PGM, recording):           cpu {r['cpu_render_s']:.2f} s, "
        f"wall {r['wall_render_s']:.2f} s",
        f"  render / making the map: cpu {r['render_vs_make_map_cpu']:.2f}×, wall "
        f"{r['render_vs_make_map_wall']:.2f}× (target ≤ 2×)",
        f"  loading the picture code (Pillow; before the render clock): cpu "
        f"{r['cpu_load_render_s']:.2f} s",
        f"  the same work in one process: cpu {r['cpu_command_s']:.2f} s; wall "
        f"{r['wall_process_s']:.2f} s with the interpreter's start (each: {walls})",
        f"  whole command `irring run {r['scenario']}`: wall {r['wall_irring_run_s']:.2f} s "
        f"(each: {commands}; target ≤ 1.5 s), cpu {r['cpu_irring_run_s']:.2f} s",
        f"  peak memory: {r['peak_memory_mb']:.0f} MB (target ≤ 1024 MB)",
        load_line(r["load_before"], r["load_after"], r["cpus"]),
    ])


if __name__ == "__main__":   # one repeat: `python -m irring.studies.render_bench SCENARIO`
    print(json.dumps(one_run(sys.argv[1])))
