"""Compare ring designs on simulated scenes: each design in place of the scenario's, run
through ``irring run``'s pipeline for several seeds and scored on the scenario's own ground
truth, beside its detection curve (:func:`irring.studies.geometry.detection`). How designs
are judged: docs/designs.md."""

from __future__ import annotations

import math
import textwrap

import numpy as np

from .. import designs as designs_mod
from ..core import Cylinder
from ..designs import Design
from ..maps.metrics import SCORE_KEYS, SHADOW_NA
from ..pipeline import progress_bar
from ..scenario import check_distinct_names, counted_seeds, load_scenario
from . import accuracy, study
from .executor import WARMUP_NOTE, capacity, run_jobs
from .geometry import DEFAULT_DISTANCES_M, MAX_RADIUS_M, Detection, detection
from .report import mean_of, write_study

# --------------------------------------------------------------------------- scenes

# in the detection curves' bar, where an ETA would go
CURVES_NOTE = "no ETA: each design's curve costs its own"


def run_scene(scenario, design: Design | str, seed: int | None = None) -> dict:
    """One scenario seen by one design: every pose swept, then estimated, mapped and scored
    as ``irring run`` does — one run of a study (:func:`irring.studies.study.run_point`), in
    this process.

    The estimator reads each design with the calibration of what its scene simulates
    (``calibration.scene_calibration``, as ``irring run`` does). One deliberate difference from
    ``irring run``, so designs are compared fairly: the map is scored against the ground
    truth of the scenario as written (with its own design's reach), so every design is
    judged on the same cells: a design that cannot reach a wall loses recall and shadow for
    it instead of having the wall dropped from its exam.

    Returns the six ``metrics.SCORE_KEYS`` plus ``hardware_time_s`` (one 360° view of the
    design, :meth:`Design.hardware_time_s`), ``hardware_time_total_s`` (all poses),
    ``compute_time_s`` (sweep + estimate + map per view) and ``readings``.
    """
    d = designs_mod.get(design) if isinstance(design, str) else design
    p = _point(scenario, d, scenario.seed if seed is None else seed)
    # the scenario object itself: it may differ from its file
    task = study.Task(p, None, scenario.source, scenario)
    return _record(study.run_point(task), scenario.name)


def _point(scenario, design: Design, seed: int):
    return study.point(study.DesignSpec(design.name, design=design), scenario, seed)


def _record(row: dict, scenario_name: str) -> dict:
    """A study row as compare's run record."""
    return {"scenario": scenario_name, "design": row["design"], "seed": row["seed"],
            "poses": row["poses"], **{k: row[k] for k in SCORE_KEYS},
            "hardware_time_s": row["hardware_time_s"],
            "hardware_time_total_s": row["hardware_time_total_s"],
            "compute_time_s": (row["sim_ms"] + row["compute_ms"]) / 1e3,
            "readings": row["readings"]}


def seed_sd(groups) -> float | None:
    """The spread of a score from seed to seed: the sample standard deviations of each
    group's values (one room's seeds; ``None`` left out) pooled by their degrees of freedom,
    so rooms that score apart add nothing to it; None without a group of two."""
    vals = [np.array([v for v in g if v is not None], float) for g in groups]
    dof = sum(len(v) - 1 for v in vals if len(v) > 1)
    if not dof:
        return None
    return float(np.sqrt(sum(((v - v.mean()) ** 2).sum() for v in vals if len(v) > 1) / dof))


def summarise(runs: list[dict], detections: dict[str, Detection] | None = None) -> list[dict]:
    """One record per design: run scores averaged over scenarios and seeds (``None`` scores
    left out of the mean) with their spread from seed to seed (``<score>_sd``,
    :func:`seed_sd` over the rooms; per room in ``by_scenario``), hardware time of a 360°
    view, compute time per view, and the detection curve when given."""
    out = []
    for name in dict.fromkeys(r["design"] for r in runs):
        mine = [r for r in runs if r["design"] == name]
        rec = {"design": name,
               "scenarios": sorted({r["scenario"] for r in mine}),
               "runs": len(mine)}
        rooms = list(dict.fromkeys(r["scenario"] for r in mine))
        for k in SCORE_KEYS:
            rec[k] = mean_of(r[k] for r in mine)
            rec[f"{k}_sd"] = seed_sd([r[k] for r in mine if r["scenario"] == sc] for sc in rooms)
            if k != "shadow":
                continue
            vals = [r[k] for r in mine if r[k] is not None]
            rec["shadow_min"] = float(min(vals)) if vals else None
        rec["by_scenario"] = {sc: {**{k: mean_of(r[k] for r in mine if r["scenario"] == sc)
                                      for k in SCORE_KEYS},
                                   "shadow_sd": seed_sd([[r["shadow"] for r in mine
                                                          if r["scenario"] == sc]])}
                              for sc in rec["scenarios"]}
        rec["poses"] = {sc: next(r["poses"] for r in mine if r["scenario"] == sc)
                        for sc in rec["scenarios"]}
        rec["hardware_time_s"] = float(np.mean([r["hardware_time_s"] for r in mine]))
        rec["compute_time_s"] = float(np.median([r["compute_time_s"] for r in mine]))
        if detections and name in detections:
            det = detections[name]
            rec["detection_distances_m"] = det.distances_m.tolist()
            rec["min_detectable_radius_m"] = [None if not math.isfinite(v) else float(v)
                                              for v in det.min_detectable_radius_m]
            rec["too_near"] = det.too_near.tolist()   # None above, for the minimum range
            rec["min_range_m"] = det.min_range_m
        out.append(rec)
    return out


def compare(scenarios, design_list, seeds: int = 1, *, detection_distances_m=None,
            bearings: int = 180, progress: bool | None = False, ex=None) -> dict:
    """Run every design on every scenario for ``seeds`` seeds (scenario seed, +1, …): a
    predefined study, run on ``ex`` (a ``concurrent.futures`` executor from
    :func:`irring.studies.executor.executor`; default: this process).
    ``progress``: show a bar (None: only at a terminal, see ``pipeline.progress_enabled``).

    Returns ``{"designs": summarise(...), "runs": [...], "detection_distances_m": [...],
    "cylinders": cylinders(scenarios)}``.
    """
    scs = [load_scenario(s) if isinstance(s, str) else s for s in scenarios]
    check_distinct_names(scs)
    ds = [designs_mod.get(d) if isinstance(d, str) else d for d in design_list]
    for sc in scs:   # before any run: a ring a room cannot hold is refused, never measured
        for d in ds:
            accuracy.design_in(sc, d)
    points = [_point(sc, d, seed) for sc in scs for d in ds for seed in counted_seeds(sc, seeds)]
    names = [sc.name for sc in scs for d in ds for k in range(seeds)]
    dist = DEFAULT_DISTANCES_M if detection_distances_m is None else detection_distances_m
    detections = {}
    # two bars: the runs' ETA waits for each worker's first (it starts the worker); the
    # curves, one a design after the runs, differ 30-fold in cost (radial12's 12 rays a
    # view, rotating12's 852), so their bar gives no ETA rather than a wrong one
    with progress_bar(len(points), "compare runs", progress, unit="run",
                      warmup=capacity(ex), warmup_note=WARMUP_NOTE) as bar:
        tasks = study.tasks_for(points, {p.scenario: sc for p, sc in zip(
            points, [sc for sc in scs for d in ds for k in range(seeds)])})
        rows = run_jobs(study.run_point, tasks, ex, progress=lambda _: bar.update())
    runs = [_record(r, name) for r, name in zip(rows, names)]
    with progress_bar(len(ds), "compare detection curves", progress, unit="design",
                      warmup=len(ds), warmup_note=CURVES_NOTE) as bar:
        for d in ds:
            detections[d.name] = detection(d, dist, bearings=bearings)
            bar.update()
    return {"designs": summarise(runs, detections), "runs": runs,
            "detection_distances_m": list(map(float, dist)), "cylinders": cylinders(scs)}


def cylinders(scenarios) -> list[dict]:
    """The cylinders' radii of ``scenarios``, each radius once in increasing order with the
    scenarios it stands in: ``[{"radius_m": 0.022, "scenarios": ["t_room_cylinder"]}, …]``
    (the chart marks them on the detection curve; a room with none marks nothing)."""
    by_radius: dict[float, list[str]] = {}
    for sc in scenarios:
        for r in dict.fromkeys(ob.radius_m for ob in sc.obstacles if isinstance(ob, Cylinder)):
            by_radius.setdefault(float(r), []).append(sc.name)
    return [{"radius_m": r, "scenarios": by_radius[r]} for r in sorted(by_radius)]


# --------------------------------------------------------------------------- outputs

TABLE_SCORES = ("occupied_f1", "free_accuracy", "coverage", "shadow")


# why a radius column says "too near" rather than "miss" (radial12 at 250 mm: its sensors
# sit 150 mm out, so the near side is 100 mm from the one facing it, the GP2D12's minimum)
TOO_NEAR = ("none ≤ 200 mm is seen at every bearing only because the near side is within "
            "the sensor's minimum range of the sensor facing it")


def table(records: list[dict]) -> str:
    """A plain-text table of the per-design records (scores, times, detection)."""
    dists = records[0].get("detection_distances_m", []) if records else []
    # the shadow of each scene with something to hide behind, by its number of scans (one
    # scan shows what the rotating sensors see past a post; several, what other poses add)
    shadowed = [sc for sc in (records[0]["scenarios"] if records else [])
                if any(r["by_scenario"][sc]["shadow"] is not None for r in records)]
    scans = {sc: records[0]["poses"][sc] for sc in shadowed}
    by_count = len(set(scans.values())) == len(scans)
    # one such scene: its column would repeat the shadow column (0.474 beside 0.47)
    per_scene = shadowed if len(shadowed) > 1 else []
    shadow_head = [f"shadow {n} scan{'s' if n > 1 else ''}" if by_count else f"shadow {sc}"
                   for sc, n in scans.items() if sc in per_scene]
    head = (["design", "F1 occ", "free acc", "coverage", "shadow"] + shadow_head
            + ["360° view", "compute"] + [f"r@{d * 1e3:g}mm" for d in dists])
    rows = [head]
    for r in records:
        row = [r["design"]] + [_spread(r[k], r.get(f"{k}_sd"), 3) for k in TABLE_SCORES]
        row += [_spread(r["by_scenario"][sc]["shadow"], r["by_scenario"][sc].get("shadow_sd"), 2)
                for sc in per_scene]
        row += [_seconds(r["hardware_time_s"]), f"{r['compute_time_s'] * 1e3:.1f} ms"]
        radii = r.get("min_detectable_radius_m", [])
        row += [("too near" if near else "miss") if v is None else f"{v * 1e3:.1f}mm"
                for v, near in zip(radii, r.get("too_near") or [False] * len(radii))]
        rows.append(row)
    widths = [max(len(row[i]) for row in rows) for i in range(len(head))]
    lines = ["  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in
                       enumerate(zip(row, widths))) for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    if per_scene and by_count:
        lines.append(", ".join(f"{h}: {sc}" for h, sc in zip(shadow_head, per_scene)))
    elif shadowed and not per_scene:
        n = scans[shadowed[0]]
        lines.append(f"shadow: in {shadowed[0]} ({n} scan{'s' if n > 1 else ''}), the one "
                     "scenario here that hides wall behind an obstacle")
    if any(r["shadow"] is None for r in records):
        lines.append(f"shadow —: n/a, {SHADOW_NA} (in any of these scenarios)")
    if any(r.get(f"{k}_sd") is not None for r in records for k in TABLE_SCORES):
        lines.append(f"±: {SPREAD}")
    near = [f"{r['design']}: {r['min_range_m'] * 1e3:.0f} mm" for r in records
            if any(r.get("too_near", ()))]
    if near:
        lines.append(f"too near: {TOO_NEAR} ({', '.join(near)})")
    return "\n".join(lines)


# radii closer than this ratio share one label on the chart's log axis (posts: 35, 40 mm)
LABEL_RATIO = 1.25


def label_groups(cyls: list[dict]) -> list[list[dict]]:
    """:func:`cylinders`' radii (increasing) in runs whose labels would overlap."""
    groups: list[list[dict]] = []
    for c in cyls:
        if groups and c["radius_m"] < groups[-1][0]["radius_m"] * LABEL_RATIO:
            groups[-1].append(c)
        else:
            groups.append([c])
    return groups


def cylinder_label(group: list[dict]) -> str:
    """The chart's words for radii of :func:`cylinders` drawn together."""
    rooms = list(dict.fromkeys(sc for c in group for sc in c["scenarios"]))
    shown = ", ".join(rooms[:3]) + (f" and {len(rooms) - 3} more" if len(rooms) > 3 else "")
    radii = ", ".join(f"{c['radius_m'] * 1e3:g}" for c in group)
    return f"cylinder{'s' if len(group) > 1 else ''} r = {radii} mm in {shown}"


# what a table's "±" is: noise, where a mean over rooms would count how rooms differ
SPREAD = ("the spread from seed to seed (sd within each room, pooled over the rooms): "
          "designs closer than that differ by noise; `irring study` runs more seeds")


def _spread(value: float | None, sd: float | None, digits: int) -> str:
    if value is None:
        return "—"
    return f"{value:.{digits}f}" + ("" if sd is None else f" ± {sd:.{digits}f}")


def _seconds(s: float) -> str:
    return f"{s * 1e3:.0f} ms" if s < 1 else f"{s:.2f} s"


CSV_KEYS = ("design", "runs", "occupied_precision", "occupied_recall", "occupied_f1",
            "free_accuracy", "coverage", "shadow", "shadow_min", "hardware_time_s",
            "compute_time_s") + tuple(f"{k}_sd" for k in SCORE_KEYS)


# the hardware-time bars go on a log axis only when the designs' times differ more than this
# (a laser's 27 ms beside one GP2's 12.8 s); closer, bars from 0 compare as lengths
TIME_LOG_SPAN = 10.0


def chart(result: dict, path) -> None:
    """Four panels: map scores per design, shadow per scenario, hardware time per 360°
    view, and the smallest cylinder each design is sure to see versus distance."""
    # deferred: matplotlib (no pyplot: the backend stays)
    from ..maps.render import figure, plain_log

    recs = result["designs"]
    names = [r["design"] for r in recs]
    x = np.arange(len(names))
    fig = figure(13, 8.5)
    axes = fig.subplots(2, 2)
    (a_scores, a_shadow), (a_time, a_det) = axes

    def bars(ax, series: dict[str, tuple[list, list]], title: str) -> None:
        """``series``: label → (values, spreads from seed to seed), one each a design."""
        w = 0.8 / max(len(series), 1)
        for i, (label, (vals, sds)) in enumerate(series.items()):
            vals = np.array([np.nan if v is None else v for v in vals], dtype=float)
            sds = np.array([np.nan if s is None else s for s in sds], dtype=float)
            xs = x + (i - (len(series) - 1) / 2) * w
            ax.bar(xs, vals, w, label=label, yerr=None if np.isnan(sds).all() else sds,
                   capsize=2, error_kw={"lw": 0.8})
            for xi, v in zip(xs, vals):  # say so where a bar is invisible
                if not v > 0.005:
                    ax.annotate("n/a" if np.isnan(v) else "0", (xi, 0.01), ha="center",
                                va="bottom", fontsize=7, rotation=90)
                elif v >= 0.15:   # the value inside its bar: 0.990 and 0.992 look alike
                    ax.annotate(f"{v:.3f}", (xi, v - 0.01), ha="center", va="top",
                                fontsize=7, rotation=90, color="white")
                else:
                    ax.annotate(f"{v:.3f}", (xi, v + 0.01), ha="center", va="bottom",
                                fontsize=7, rotation=90)
        ax.set_title(title, fontsize=9)
        ax.set_xlim(-0.5, len(names) - 0.5)   # the designs under the other panels'
        if series:
            ax.set_xticks(x, names)
            ax.set_ylim(0, 1.0)
            ax.set_ylabel("score (1 = perfect)")
            ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.07), ncols=4)
        else:   # nothing to label (matplotlib warns on an empty legend): say why it is empty;
            # no ticks (a lone design's name sat in the corner of the empty axes)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.text(0.5, 0.5, textwrap.fill(f"shadow n/a: {SHADOW_NA} (in any of these "
                                            "scenarios)", 64),
                    ha="center", va="center", fontsize=9, transform=ax.transAxes)
        ax.grid(axis="y", alpha=0.3)

    runs = recs[0]["runs"] if recs else 0
    def scores(key: str) -> tuple[list, list]:
        return [r[key] for r in recs], [r.get(f"{key}_sd") for r in recs]

    bars(a_scores, {"occupied F1": scores("occupied_f1"),
                    "free accuracy": scores("free_accuracy"), "coverage": scores("coverage")},
         f"Map scores, mean over {runs} runs per design (scenarios × seeds; "
         "± sd from seed to seed)")
    with_shadow = [sc for sc in (recs[0]["scenarios"] if recs else [])
                   if any(r["by_scenario"][sc]["shadow"] is not None for r in recs)]
    bars(a_shadow, {f"{sc} ({recs[0]['poses'][sc]} scan{'s' if recs[0]['poses'][sc] > 1 else ''})":
                    ([r["by_scenario"][sc]["shadow"] for r in recs],
                     [r["by_scenario"][sc].get("shadow_sd") for r in recs])
                    for sc in with_shadow},
         "Shadow: share of the wall hidden behind obstacles that the map shows")

    hw = [r["hardware_time_s"] for r in recs]
    a_time.bar(x, hw, color="0.4")
    if hw and min(hw) > 0 and max(hw) / min(hw) > TIME_LOG_SPAN:
        plain_log(a_time, "y")
    else:   # bars from 0: on a log axis 1.65 s against 2.72 s drew a sliver against a bar
        a_time.set_ylim(0, max(hw, default=1) * 1.1)
    a_time.set_xticks(x, names)
    a_time.set_ylabel("seconds (lower is better)")
    a_time.set_title("Hardware time for one 360° view at one pose", fontsize=9)
    for xi, v in zip(x, hw):
        a_time.annotate(_seconds(v), (xi, v), ha="center", va="bottom", fontsize=8)
    a_time.grid(axis="y", alpha=0.3)

    dist = np.asarray(result["detection_distances_m"]) * 1e3
    nears = 0
    for r in recs:
        if "min_detectable_radius_m" not in r:
            continue
        y = np.array([np.nan if v is None else v * 1e3 for v in r["min_detectable_radius_m"]])
        line, = a_det.plot(dist, y, marker="o", label=r["design"])
        near = np.asarray(r.get("too_near") or [False] * len(dist), bool)
        if near.any():   # a miss the minimum range alone makes, drawn at the 200 mm top,
            # each design's a little to the right of the last's (radial12 and sonar12 share 250)
            a_det.plot(dist[near] + 12 * nears, np.full(near.sum(), MAX_RADIUS_M * 1e3),
                       ls="", marker="x", ms=9, mew=2, color=line.get_color(), clip_on=False)
            nears += 1
    # the compared rooms' own cylinders on the scale (none above the curve's 200 mm top)
    cyls = [c for c in result.get("cylinders", ()) if c["radius_m"] <= MAX_RADIUS_M]
    for group in label_groups(cyls):
        for c in group:
            a_det.axhline(c["radius_m"] * 1e3, color="k", ls=":", lw=1)
        a_det.annotate(cylinder_label(group), (dist[0], group[-1]["radius_m"] * 1e3 * 1.08),
                       fontsize=8)
    plain_log(a_det, "y")
    a_det.set_xlabel("distance from the robot centre to the cylinder (mm)")
    a_det.set_ylabel("radius, mm (lower is better)")
    a_det.set_title("Smallest cylinder seen at every bearing (no point: none up to 200 mm;\n"
                    "× at 200 mm: too near, inside the sensor's minimum range)", fontsize=9)
    if a_det.get_legend_handles_labels()[0]:   # a laser-only compare draws no curve
        a_det.legend(fontsize=8)
    a_det.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def write_outputs(result: dict, out_dir) -> dict[str, str]:
    """compare.json, compare.csv (one row per design), runs.csv, compare.png in ``out_dir``."""
    return write_study(out_dir, "compare", result, result["designs"], CSV_KEYS, chart)
