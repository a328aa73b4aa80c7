"""What accuracy costs in time: the knobs that trade time for accuracy, one at a time.

How it works, its assumptions and measured figures: docs/accuracy.md.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
import types
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from .. import pipeline, scenario as scenario_lib
from ..estimation.calibration import Calibration
from ..estimation.estimate import estimate
from ..estimation.lines import LineOptions
from ..maps import metrics
from ..maps.mapping import OccupancyGrid
from ..pipeline import scenario_text
from ..scenario import (AveragingEffect, BeltDynamicsEffect, TimingEffect, counted_seeds,
                        load_scenario, loads)
from .report import mean_of, write_study
from .executor import run_jobs

DEFAULT_SCENARIOS = ("t_room_cylinder", "t_room")
STEEP_RAD = math.radians(40.0)
DEFAULT_TOLERANCE_RAD = math.radians(0.1)   # estimate()'s default
DEFAULT_MAX_ITERATIONS = 20                 # estimate()'s default

# What each knob costs, for the table and the chart.
KNOB_COST = {"default": "", "step": "hardware", "samples": "hardware", "settle": "hardware",
             "iterations": "compute", "tolerance": "compute", "regroup": "compute",
             "resolution": "compute",
             "design": "hardware"}
KNOBS = tuple(k for k in KNOB_COST if k != "default")
ACCURACY_KEYS = ("range_rmse_m", "range_rmse_steep_m", "point_rmse_m", "valid_share", "occupied_precision",
                 "occupied_recall", "occupied_f1", "free_accuracy", "coverage", "shadow")
TIME_KEYS = ("compute_ms", "estimate_ms", "map_ms", "sim_ms")
SETTLE_MS = (0, 20, 40, 60)   # settle configurations, all with belt_dynamics + timing
TIMING_REPEATS = 3   # estimator + mapper timed this many times per run; the least is kept


@dataclass(frozen=True)
class Config:
    """The scenario as written, with at most one knob changed (None: the scenario's own)."""

    knob: str = "default"
    label: str = "default"
    value: float = 0.0                  # the knob's setting, for ordering (chart, table)
    step_stride: int | None = None
    samples: int | None = None          # > 1 switches the averaging effect on
    settle_s: float | None = None
    iterate: bool = True
    max_iterations: int = DEFAULT_MAX_ITERATIONS
    tolerance_rad: float = DEFAULT_TOLERANCE_RAD
    regroup_iterations: int | None = None   # LineOptions.regroup_iterations (None: default)
    resolution_m: float | None = None
    design: str | None = None
    dynamics: bool = False              # add belt_dynamics + timing (their defaults)


def configurations(knobs: Iterable[str] | None = None,
                   designs: Sequence[str] = ("radial12", "rotating1")) -> list[Config]:
    """The default configuration, then each knob's other settings (see docs/accuracy.md)."""
    knobs = KNOBS if knobs is None else tuple(knobs)
    unknown = [k for k in knobs if k not in KNOBS]
    if unknown:
        raise ValueError(f"unknown knob(s) {unknown}; known: {', '.join(KNOBS)}")
    step_deg = 1.08
    out = [Config()]
    for k in knobs:
        if k == "step":
            out += [Config(k, f"step ×{s} ({s * step_deg:.2f}°)", s, step_stride=s)
                    for s in (2, 4)]
        elif k == "samples":
            out += [Config(k, f"{n} samples", n, samples=n) for n in (2, 4, 8)]
        elif k == "settle":
            # a wait only matters with the belt's swing and the GP2's clock simulated
            out += [Config(k, f"settle {ms} ms (belt+timing)", ms, settle_s=ms / 1e3,
                           dynamics=True) for ms in SETTLE_MS]
        elif k == "iterations":
            out.append(Config(k, "θ = 0 (no iterations)", 0, iterate=False))
            out += [Config(k, f"{n} iteration{'s' if n > 1 else ''}", n, max_iterations=n)
                    for n in (1, 2, 5)]
        elif k == "tolerance":
            out.append(Config(k, "tolerance 1°", 1.0, tolerance_rad=math.radians(1.0)))
        elif k == "regroup":
            out += [Config(k, f"regroup {n}×", n, regroup_iterations=n) for n in (1, 2, 6)]
        elif k == "resolution":
            out += [Config(k, f"grid {mm} mm", mm, resolution_m=mm / 1e3) for mm in (5, 20)]
        elif k == "design":
            out += [Config(k, name, i + 1, design=name) for i, name in enumerate(designs)]
    return out


def default_value(knob: str, scenario) -> float:
    """Where the default configuration sits on a knob's axis (for the chart's lines)."""
    return {"step": scenario.scan.step_stride,
            "samples": scenario.samples_per_step,
            "settle": scenario.scan.settle_s * 1e3, "iterations": DEFAULT_MAX_ITERATIONS,
            "tolerance": math.degrees(DEFAULT_TOLERANCE_RAD),
            "regroup": LineOptions().regroup_iterations,
            "resolution": scenario.map.resolution_m * 1e3, "design": 0}.get(knob, 0.0)


def design_in(scenario, design):
    """``scenario_lib.apply_design``, and a motion path that keeps the design's ring clear
    of walls and obstacles: ScenarioError naming the design for a ring the scene cannot
    hold, checked before any run (compare, a study, the design knob)."""
    sc = scenario_lib.apply_design(scenario, design)
    motion = sc.effects.get("motion")
    if motion is not None:
        from ..simulation.dynamics import Path   # deferred: loads MuJoCo (as run_job's)

        name = design if isinstance(design, str) else design.name
        Path.from_effect(motion).check_clearance(sc, f" of design {name!r}")
    return sc


def apply(scenario, cfg: Config):
    """The scenario with the configuration's sweep, map and design changes."""
    sc = design_in(scenario, cfg.design) if cfg.design else scenario
    scan = {}
    if cfg.step_stride is not None:
        scan["step_stride"] = int(cfg.step_stride)
    if cfg.settle_s is not None:
        scan["settle_s"] = float(cfg.settle_s)
    effects = dict(sc.effects)
    if cfg.samples is not None:
        scan["samples"] = int(cfg.samples)
        effects.setdefault("averaging", AveragingEffect())
    if cfg.dynamics:
        effects.setdefault("belt_dynamics", BeltDynamicsEffect())
        effects.setdefault("timing", TimingEffect())
    changes: dict[str, Any] = {"scan": dataclasses.replace(sc.scan, **scan),
                               "effects": types.MappingProxyType(effects)}
    if cfg.resolution_m is not None:
        changes["map"] = dataclasses.replace(sc.map, resolution_m=float(cfg.resolution_m))
    return dataclasses.replace(sc, **changes)


# --------------------------------------------------------------------------- one run


@dataclass(frozen=True)
class Job:
    """One run: everything a worker needs, picklable (the scenario travels as YAML text).
    ``scenario``: a Scenario object instead of the text, for a run in this process only
    (a scenario made in code has no file; its ground truth is not cached)."""

    scenario_yaml: str | None
    scenario_source: str
    config: Config
    seed: int
    scenario: Any = None


_TRUTH_CACHE: dict[tuple, Any] = {}   # per process: the reference's GroundTruth per grid


@functools.lru_cache(maxsize=16)
def scenario_from_text(text: str, source: str):
    """The scenario a job carries, parsed once per process: YAML parsing cost ~40 % of a
    run when every run parsed it again (a Scenario is frozen, so runs can share it)."""
    return loads(text, source=source)


def _rmse(err: np.ndarray) -> float | None:
    return float(np.sqrt(np.mean(err * err))) if err.size else None


def _compute_time(sweeps, cal, estimator, grid) -> tuple[float, float]:
    """CPU seconds the estimator (with calibration ``cal``) and the mapper take for all
    sweeps, the least of ``TIMING_REPEATS`` runs on fresh grids, each the work
    :func:`pipeline.map_sweeps` does for the map: every sweep estimated (a cone's marked),
    then the run mapped as ``insert_run`` maps it (the returns sweep by sweep, then the
    silent beams). CPU time of this thread, not wall time: while workers share the cores
    with each other and with whatever else runs, a job's wall time grows with the load, its
    CPU time hardly at all."""
    est, mapper = [], []
    for _ in range(TIMING_REPEATS):
        g = grid.empty_like()
        t0 = time.thread_time()
        points = [pipeline.with_cone(estimator(sw, cal), sw) for sw in sweeps]
        t1 = time.thread_time()
        g.insert_run(points)
        est.append(t1 - t0)
        mapper.append(time.thread_time() - t1)
    return min(est), min(mapper)


def run_job(job: Job) -> dict:
    """Sweep every pose, estimate, map and score one configuration; a plain dict."""
    from ..simulation import dynamics   # deferred: loads MuJoCo; a study file is read without it
    base = job.scenario if job.scenario is not None else \
        scenario_from_text(job.scenario_yaml, job.scenario_source)
    cfg = job.config
    sc = apply(base, cfg)
    acq, _ = pipeline.simulated(sc, seed=job.seed, progress=False)
    sweeps = acq.sweeps
    lines = LineOptions() if cfg.regroup_iterations is None else \
        LineOptions(regroup_iterations=cfg.regroup_iterations)
    estimator = functools.partial(estimate, max_iterations=cfg.max_iterations,
                                  tolerance_rad=cfg.tolerance_rad, iterate=cfg.iterate,
                                  lines=lines, keep_unconverged=cfg.knob == "iterations")
    cal = Calibration.for_scene(sc)
    # the mapper's numbers as irring run picks them (a θ-free calibration's silent beams)
    grid = OccupancyGrid.for_scenario(sc, pipeline.mapper_params(cal, sweeps))
    result = pipeline.map_sweeps(sweeps, scenario=sc, grid=grid, calibration=cal, score=False,
                                 progress=False, estimator=estimator)
    # every configuration is judged on the default design's ground truth, on its own cells
    reference = apply(base, Config(resolution_m=sc.map.resolution_m))
    truth = (metrics.ground_truth(reference, result.grid) if job.scenario_yaml is None else
             metrics.cached_ground_truth(reference, result.grid, _TRUTH_CACHE, job.scenario_yaml))
    scores = metrics.score(result.grid, reference, truth, mapped_by=sc)

    err, err_steep, iters, err_pt = [], [], [], []
    hits = valid_hits = 0
    for sw, p in zip(sweeps, result.points):
        d_true = sw.truth.distance_m
        hit = np.isfinite(d_true)
        ok = p.valid & hit
        hits += int(hit.sum())
        valid_hits += int(ok.sum())
        err.append(p.d[ok] - d_true[ok])
        hp = sw.truth.hit_point
        err_pt.append(np.hypot(p.x[ok] - hp[..., 0][ok], p.y[ok] - hp[..., 1][ok]))
        steep = ok & (sw.truth.incidence_rad >= STEEP_RAD)
        err_steep.append(p.d[steep] - d_true[steep])
        iters.append(p.iterations[p.valid])
    err_all, err_st, it, e_pt = (np.concatenate(a) for a in (err, err_steep, iters, err_pt))
    poses = len(sweeps)
    if cfg.dynamics:
        # the timed schedule (moves, settle, firmware waits): one sweep is one 360° view
        view_s = float(np.mean([sw.duration_s for sw in sweeps]))
        heading = np.concatenate([dynamics.heading_error(sw).ravel() for sw in sweeps])
        angle_rms = float(np.sqrt(np.mean(heading ** 2)))
    else:
        view_s = scenario_lib.design_for(sc).hardware_time_s(
            step_stride=sc.scan.step_stride, settle_s=sc.scan.settle_s,
            samples=sweeps[0].samples)
        angle_rms = None
    est_s, map_s = _compute_time(sweeps, cal, estimator, grid)
    est_ms, map_ms = est_s * 1e3 / poses, map_s * 1e3 / poses
    return {
        "scenario": base.name, "knob": cfg.knob, "label": cfg.label, "value": cfg.value,
        "seed": int(job.seed), "poses": poses,
        "readings": int(sum(sw.counts.size for sw in sweeps)),
        "range_rmse_m": _rmse(err_all), "range_rmse_steep_m": _rmse(err_st),
        "point_rmse_m": _rmse(e_pt),
        "steep_readings": int(err_st.size),
        "valid_share": valid_hits / hits if hits else None,
        **{k: scores[k] for k in metrics.SCORE_KEYS},
        "iterations_mean": float(it.mean()) if it.size else 0.0,
        "dynamics": bool(cfg.dynamics), "angle_error_rms_rad": angle_rms,
        "hardware_time_s": float(view_s), "hardware_time_total_s": float(view_s * poses),
        "compute_ms": est_ms + map_ms, "estimate_ms": est_ms, "map_ms": map_ms,
        "sim_ms": acq.seconds * 1e3 / poses,
    }


# --------------------------------------------------------------------------- the study


def jobs_for(scenarios: Sequence, configs: Sequence[Config], seeds: int) -> list[Job]:
    """Every configuration × scenario × seed (seeds: scenario.seed, +1, …)."""
    out = []
    loaded = [load_scenario(s) if isinstance(s, str) else s for s in scenarios]
    scenario_lib.check_distinct_names(loaded)
    for sc in loaded:
        text = scenario_text(sc)
        if text is None:
            raise ValueError(f"scenario {sc.name!r} has no YAML source file; jobs carry the "
                             "scenario as YAML text so any worker can rebuild it")
        for design in dict.fromkeys(cfg.design for cfg in configs if cfg.design):
            design_in(sc, design)   # before any run: one its room cannot hold
        out += [Job(text, sc.source, cfg, seed) for cfg in configs
                for seed in counted_seeds(sc, seeds)]
    return out


def summarise(runs: list[dict], by: Sequence[str] = ("knob", "label")) -> list[dict]:
    """One row per configuration (and whatever else ``by`` names): accuracy averaged over the
    runs (a None score left out), hardware time averaged, compute times the median."""
    groups: dict[tuple, list[dict]] = {}
    for r in runs:
        groups.setdefault(tuple(r[k] for k in by), []).append(r)
    rows = []
    for key, mine in groups.items():
        row = dict(zip(by, key))
        row["value"] = mine[0]["value"]
        row["scenarios"] = sorted({r["scenario"] for r in mine})
        row["runs"] = len(mine)
        row["dynamics"] = bool(mine[0].get("dynamics", False))
        for k in ACCURACY_KEYS + ("iterations_mean", "angle_error_rms_rad"):
            row[k] = mean_of(r.get(k) for r in mine)
        row["hardware_time_s"] = float(np.mean([r["hardware_time_s"] for r in mine]))
        for k in TIME_KEYS:
            row[k] = float(np.median([r[k] for r in mine]))
        rows.append(row)
    return rows


# The Pareto fronts: each cost against each accuracy measure (True: higher is better).
COSTS = {"hw": "hardware_time_s", "cpu": "compute_ms"}
FRONT_METRICS = {"f1": ("occupied_f1", True), "cov": ("coverage", True),
                 "rmse": ("range_rmse_m", False)}
# An RMSE over a few readings says little: configurations whose estimator calls less than
# this share of the returns valid (say, capped iterations) are left off the RMSE fronts.
MIN_VALID_SHARE_FOR_RMSE = 0.5


def front_key(cost: str, metric: str) -> str:
    """Row key of a Pareto flag, e.g. ``front_hw_f1``."""
    return f"front_{cost}_{metric}"


def _eligible(r: dict, metric: str) -> bool:
    key, _ = FRONT_METRICS[metric]
    if r[key] is None or r.get("dynamics"):
        # belt+timing rows simulate more than the others (and charge hardware time by the
        # timed schedule): a different experiment in the same room, kept off the fronts
        return False
    return metric != "rmse" or (r["valid_share"] or 0.0) >= MIN_VALID_SHARE_FOR_RMSE


def mark_pareto(rows: list[dict]) -> None:
    """Set ``front_<cost>_<metric>`` on each row: True when no other row is at least as cheap
    and at least as accurate on that measure, and strictly better on one of the two. Rows
    simulated with belt+timing (``dynamics``) are never on a front and never dominate."""
    for cost, ck in COSTS.items():
        for metric, (mk, higher) in FRONT_METRICS.items():
            sign = 1.0 if higher else -1.0
            pts = [(r[ck], sign * r[mk]) if _eligible(r, metric) else None for r in rows]
            for r, p in zip(rows, pts):
                r[front_key(cost, metric)] = p is not None and not any(
                    q is not None and q[0] <= p[0] and q[1] >= p[1] and (q[0] < p[0] or q[1] > p[1])
                    for q in pts)


def fronts(r: dict) -> str:
    """The fronts a row is on, e.g. ``hw:f1,cov cpu:rmse`` (``·``: none)."""
    parts = []
    for cost in COSTS:
        on = [m for m in FRONT_METRICS if r.get(front_key(cost, m))]
        if on:
            parts.append(f"{cost}:{','.join(on)}")
    return " ".join(parts) or "·"


def measure(scenarios: Sequence = DEFAULT_SCENARIOS, *, seeds: int = 3,
            configs: Sequence[Config] | None = None, ex=None,
            progress: Callable[[dict], None] | None = None) -> dict:
    """Run the study; ``ex`` is a ``concurrent.futures`` executor (default: this process).

    Returns ``{"configs": [...], "by_scenario": [...], "runs": [...], "meta": {...}}``:
    ``configs`` one row per configuration (mean over scenarios × seeds, Pareto flags),
    ``by_scenario`` the same per scenario, ``runs`` every run in job order.
    """
    configs = configurations() if configs is None else list(configs)
    jobs = jobs_for(scenarios, configs, seeds)
    t0 = time.perf_counter()
    runs = run_jobs(run_job, jobs, ex, progress=progress)
    wall = time.perf_counter() - t0
    rows = summarise(runs)
    mark_pareto(rows)

    first = load_scenario(scenarios[0]) if isinstance(scenarios[0], str) else scenarios[0]
    default = next((r for r in rows if r["knob"] == "default"), None)
    return {
        "configs": rows,
        "by_scenario": summarise(runs, ("scenario", "knob", "label")),
        "runs": runs,
        "meta": {"scenarios": sorted({r["scenario"] for r in runs}), "seeds": seeds,
                 "jobs": len(jobs), "wall_s": wall,
                 "default_values": {k: default_value(k, first) for k in KNOBS},
                 "default": default},
    }


# --------------------------------------------------------------------------- outputs


def deterministic(run: dict) -> dict:
    """A run without its wall-clock timings: what must agree whoever ran it."""
    return {k: v for k, v in run.items() if k not in TIME_KEYS}


def _fmt(v, scale: float = 1.0, digits: int = 3) -> str:
    return "—" if v is None else f"{v * scale:.{digits}f}"


def table(rows: list[dict]) -> str:
    """Plain-text table: one line per configuration."""
    head = ["knob", "configuration", "hardware s", "compute ms", "angle mrad", "RMSE mm",
            "steep mm", "point mm", "valid", "F1 occ", "coverage", "free acc", "shadow", "front"]
    lines = [head]
    for r in rows:
        lines.append([r["knob"], r["label"], f"{r['hardware_time_s']:.2f}",
                      f"{r['compute_ms']:.1f}", _fmt(r.get("angle_error_rms_rad"), 1e3, 2),
                      _fmt(r["range_rmse_m"], 1e3, 1),
                      _fmt(r["range_rmse_steep_m"], 1e3, 1), _fmt(r["point_rmse_m"], 1e3, 1),
                      _fmt(r["valid_share"], 1, 2),
                      _fmt(r["occupied_f1"]), _fmt(r["coverage"]), _fmt(r["free_accuracy"]),
                      _fmt(r["shadow"]),
                      fronts(r)])
    widths = [max(len(row[i]) for row in lines) for i in range(len(head))]
    out = ["  ".join(c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in
                     enumerate(zip(row, widths))) for row in lines]
    out.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(out)


CSV_KEYS = ("knob", "label", "value", "dynamics", "runs", "hardware_time_s", "compute_ms",
            "estimate_ms", "map_ms", "sim_ms", "iterations_mean", "angle_error_rms_rad") + \
           ACCURACY_KEYS + \
           tuple(front_key(c, m) for c in COSTS for m in FRONT_METRICS)


_COLOURS = {"step": "tab:blue", "samples": "tab:orange", "settle": "tab:brown",
            "iterations": "tab:green", "tolerance": "tab:olive", "regroup": "tab:cyan",
            "resolution": "tab:purple", "design": "tab:red"}


def chart(result: dict, path) -> None:
    """Accuracy (occupied F1, coverage, range RMSE) against hardware and compute time.

    Each knob is a line through the default configuration (black square) and its other
    settings (designs are points); the settle knob, simulated with belt+timing, is a dashed
    line through its own settings and not through the default; the grey staircase is that panel's Pareto front and a
    ring marks the configurations on it. A hollow point: the estimator called less than
    half the returns valid, so its RMSE describes few readings.
    """
    rows = result["configs"]
    default = next(r for r in rows if r["knob"] == "default")
    defaults = result["meta"]["default_values"]
    metrics = (("f1", "occupied F1 (higher is better;\nscale stretched towards 1)", 1.0),
               ("cov", "coverage of the free area (higher is better)", 1.0),
               ("rmse", "range RMSE, mm (lower is better)", 1e3))
    costs = (("hw", "hardware time per 360° scan, s (what the real ring spends)"),
             ("cpu", "compute per sweep, ms CPU (estimator + mapper, this machine)"))
    # deferred: matplotlib (no pyplot: the backend stays)
    from ..maps.render import figure, plain_log, stretch_towards_one

    fig = figure(13, 12.5)
    axes = fig.subplots(len(metrics), 2)
    for i, (metric, mlabel, scale) in enumerate(metrics):
        mk = FRONT_METRICS[metric][0]
        for j, (cost, clabel) in enumerate(costs):
            ck = COSTS[cost]
            ax = axes[i, j]
            notes: list[tuple] = []

            def xy(r):
                return r[ck], (np.nan if r[mk] is None else r[mk] * scale)

            front = sorted((r for r in rows if r.get(front_key(cost, metric))),
                           key=lambda r: r[ck])
            if front:
                fx, fy = zip(*(xy(r) for r in front))
                ax.step(fx, fy, where="post", color="0.6", lw=2.5, alpha=0.5, zorder=1,
                        label="Pareto front")
            for knob, colour in _COLOURS.items():
                mine = [r for r in rows if r["knob"] == knob]
                if not mine:
                    continue
                dyn = any(r.get("dynamics") for r in mine)
                if knob != "design":
                    # a belt+timing line is a different simulation: not through the default
                    extra = [] if dyn else [dict(default, value=defaults.get(knob, 0))]
                    line = sorted(mine + extra, key=lambda r: r["value"])
                    lx, ly = zip(*(xy(r) for r in line))
                    ax.plot(lx, ly, "--" if dyn else "-", color=colour, lw=1.2, alpha=0.8,
                            label=f"{knob} (belt+timing)" if dyn else knob)
                for r in mine:
                    x, y = xy(r)
                    if not np.isfinite(y):
                        continue
                    few = metric == "rmse" and \
                        (r["valid_share"] or 0.0) < MIN_VALID_SHARE_FOR_RMSE
                    ax.plot([x], [y], "o", color=colour, ms=5,
                            mfc="none" if few else colour,
                            label="design" if knob == "design" and r is mine[0] else None)
                    notes.append((x, y, _short(r), colour))
            for r in front:   # the legend says what the ring means
                ax.plot(*xy(r), "o", mfc="none", mec="k", ms=11, mew=1.0, zorder=6,
                        label="ringed: on the front" if r is front[0] else None)
            x, y = xy(default)
            if np.isfinite(y):
                ax.plot([x], [y], "s", color="k", ms=7, zorder=5, label="default")
            plain_log(ax)
            if metric == "f1":   # the knobs' F1 0.957 … 0.999 were one crowd on 0 … 1
                stretch_towards_one(ax)
            _annotate(ax, notes)
            ax.set_xlabel(clabel)
            ax.set_ylabel(mlabel)
            ax.grid(alpha=0.3, which="both")
            # in coverage against hardware time, whose lower right is empty (in F1's it
            # hid the points the stretched scale spread there)
            if i == 1 and j == 0 and ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=8, loc="lower right")
    meta = result["meta"]
    fig.suptitle(f"What accuracy costs in time — one knob at a time around the default; "
                 f"{', '.join(meta['scenarios'])}, {meta['seeds']} seed(s) each",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


# label offsets tried in turn (points); a label that fits none is left off (its point
# sits on or next to a labelled one: same settings give the same result, e.g. tolerance 1°)
_OFFSETS = ((4, 3), (4, -10), (-6, 6), (-6, -12), (4, 12), (4, -19))


def _annotate(ax, notes: list[tuple]) -> None:
    """Label points without letting labels overlap each other or run off the axes."""
    ax.autoscale_view()
    ax.figure.draw_without_rendering()   # fix the limits (log axes): data → pixels final
    bbox = ax.get_window_extent()
    taken: list[tuple[float, float, float, float]] = []
    px = ax.figure.dpi / 72.0
    # the extreme points first: they are the ones a reader looks for
    for x, y, text, colour in notes:
        if not (np.isfinite(x) and np.isfinite(y)):
            continue
        X, Y = ax.transData.transform((x, y))
        w, h = 4.3 * len(text) * px, 8.0 * px
        for dx, dy in _OFFSETS:
            x0 = X + dx * px - (w if dx < 0 else 0)
            y0 = Y + dy * px
            box = (x0, y0, x0 + w, y0 + h)
            inside = bbox.x0 <= box[0] and box[2] <= bbox.x1 and bbox.y0 <= box[1] \
                and box[3] <= bbox.y1
            if inside and not any(box[0] < b[2] and b[0] < box[2] and box[1] < b[3]
                                  and b[1] < box[3] for b in taken):
                taken.append(box)
                ax.annotate(text, (x, y), fontsize=7, xytext=(dx, dy),
                            textcoords="offset points", color=colour,
                            ha="right" if dx < 0 else "left", va="bottom")
                break


def _short(r: dict) -> str:
    k, v = r["knob"], r["value"]
    if k == "step":
        return f"×{v:g}"
    if k == "samples":
        return f"{v:g} smp"
    if k == "settle":
        return f"{v:g} ms" + (" b+t" if r.get("dynamics") else "")
    if k == "iterations":
        return "θ=0" if v == 0 else f"{v:g} it"
    if k == "tolerance":
        return f"tol {v:g}°"
    if k == "regroup":
        return f"rg {v:g}"
    if k == "resolution":
        return f"{v:g} mm"
    return r["label"]


def write_outputs(result: dict, out_dir) -> dict[str, str]:
    """accuracy.json (everything), accuracy.csv (one row per configuration), runs.csv,
    accuracy.png (the chart) in ``out_dir``."""
    return write_study(out_dir, "accuracy", result, result["configs"], CSV_KEYS, chart)
