"""Compare ring designs by simulation: what each one sees, misses, and costs.

Two kinds of result, per design:

1. **Detection** (:func:`detection`): the smallest cylinder each design is sure to see at a
   given distance from the robot centre, over all bearings. The beams are the design's
   actual rays — emitter positions and directions read from its built MuJoCo model at
   every motor step of a full view (a sonar's ±15° cone as a fan of rays) — intersected
   with circles exactly. A cylinder counts as seen when some ray hits it within the
   sensor's working range (min … max) at an incidence the sensor still answers (GP2 70°,
   sonar 20°, laser 85°, the sensor model's limits). Open space, no noise: this is the
   geometry of the design; Eq. 1 is its closed form for a fan from one point.
2. **Scenes** (:func:`compare`): the scenario run through the whole pipeline of
   ``irring run`` (sweeps → estimator → occupancy grid → scores) with each design in place
   of the scenario's (:func:`irring.scenario.apply_design`), for several seeds: occupied F1, free
   accuracy, coverage, shadow, hardware time of a 360° view, compute time.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from .. import designs as designs_mod
from .. import gp2
from ..designs import Design
from ..outputs import OutputSet

DEFAULT_DISTANCES_M = (0.25, 0.35, 0.45, 0.55, 0.65, 0.75)
CONE_RAY_STEP_RAD = math.radians(0.25)  # fan spacing used to stand in for a sonar cone


# --------------------------------------------------------------------------- rays


@dataclass(frozen=True)
class Rays:
    """Every ray of one full view, robot at the origin facing +x. (M, 2) arrays, metres."""

    origin: np.ndarray
    direction: np.ndarray

    def __len__(self) -> int:
        return len(self.origin)


def design_rays(design: Design, step_stride: int = 1) -> Rays:
    """The rays of a full view of ``design``, read from its built MuJoCo model.

    The ring is posed at each motor step (``geometry.model_frames``); each emitter's
    position and beam direction is one ray. A sensor with a beam cone contributes a fan of
    rays every ``CONE_RAY_STEP_RAD`` across the cone.
    """
    import mujoco

    from . import geometry
    from ..simulation import model

    rm = model.compile_ring(design.ring)
    data = mujoco.MjData(rm.model)  # one, re-posed at every step
    steps = range(design.ring.min_step, design.ring.max_step + 1, step_stride)
    origins, headings = [], []
    for s in steps:  # one kinematics call per motor position; the rays are arrays
        f = geometry.model_frames(rm, s, data)
        origins.append(f.emitter_xyz[:, :2])
        headings.append(f.heading_rad)
    o = np.concatenate(origins)
    h = np.concatenate(headings)
    half = design.sensor.beam_half_angle_rad
    if half > 0:
        k = int(math.ceil(half / CONE_RAY_STEP_RAD))
        offsets = np.linspace(-half, half, 2 * k + 1)
        o = np.repeat(o, len(offsets), axis=0)
        h = (h[:, None] + offsets[None, :]).ravel()
    return Rays(o, np.c_[np.cos(h), np.sin(h)])


def _incidence_limit_rad(design: Design) -> float:

    return float(gp2.sensor(design.sensor.kind).max_incidence_rad)


def seen(rays: Rays, centres: np.ndarray, radius_m: float, *, min_range_m: float,
         max_range_m: float, max_incidence_rad: float) -> np.ndarray:
    """(B,) bool: is a cylinder of ``radius_m`` at each of ``centres`` (B, 2) hit by a ray
    within [min_range_m, max_range_m] at incidence ≤ ``max_incidence_rad``?"""
    rel = centres[:, None, :] - rays.origin[None, :, :]            # (B, M, 2)
    along = np.einsum("bmi,mi->bm", rel, rays.direction)           # to the foot of the centre
    across = rel[..., 1] * rays.direction[:, 0] - rel[..., 0] * rays.direction[:, 1]
    p = np.abs(across) / radius_m                                  # sin(incidence) where hit
    with np.errstate(invalid="ignore"):
        t = along - radius_m * np.sqrt(1.0 - p ** 2)              # distance to the surface
    hit = (p <= math.sin(max_incidence_rad)) & (t >= min_range_m) & (t <= max_range_m)
    return hit.any(axis=1)


@dataclass(frozen=True)
class Detection:
    """Per distance (from the robot centre to the cylinder's near side, m): the smallest
    cylinder radius (m) seen at every bearing (``inf``: not even ``MAX_RADIUS_M``), and the
    largest radius found missed at some bearing (0: none)."""

    design: str
    distances_m: np.ndarray
    min_detectable_radius_m: np.ndarray
    max_missed_radius_m: np.ndarray
    bearings: int
    rays: int


MIN_RADIUS_M = 0.001
MAX_RADIUS_M = 0.2
_COARSE_RADII_M = np.geomspace(MIN_RADIUS_M, MAX_RADIUS_M, 25)   # ~25 % apart
_BISECTIONS = 8                                                  # then ≈ 0.1 % apart


def symmetry_period_rad(design: Design, step_stride: int = 1) -> float:
    """Bearing period over which the design's rays repeat: 2π/N for a ring, one step for a
    single sensor turning a full circle at the centre."""
    ring = design.ring
    if ring.sensors > 1:
        return design.spacing_rad
    if design.rotating and design.positions(step_stride) * design.step_rad * step_stride \
            >= 2.0 * math.pi - 1e-9:
        return design.step_rad * step_stride
    return 2.0 * math.pi


def detection(design: Design, distances_m=DEFAULT_DISTANCES_M, *, bearings: int = 360,
              step_stride: int = 1, rays: Rays | None = None) -> Detection:
    """Smallest detectable cylinder radius versus distance for ``design`` (see module doc).

    ``bearings`` cylinder positions are spread over one symmetry period of the design, half
    a spacing off the rays' own symmetry, so the worst place (between two beams) is
    sampled. A radius is "detected" when it is seen at every bearing. Radii 1 … 200 mm are
    tried ~25 % apart; the boundary between the largest missed and the next detected one
    is then bisected (assumes one boundary in that bracket).
    """
    rays = design_rays(design, step_stride) if rays is None else rays
    period = symmetry_period_rad(design, step_stride)
    b = (np.arange(bearings) + 0.5) / bearings * period
    unit = np.c_[np.cos(b), np.sin(b)]
    sens = design.sensor
    kw = dict(min_range_m=gp2.sensor(sens.kind).min_range_m, max_range_m=sens.max_range_m,
              max_incidence_rad=_incidence_limit_rad(design))
    dist = np.asarray(distances_m, dtype=float)
    min_ok = np.full(len(dist), np.inf)
    max_miss = np.zeros(len(dist))
    for i, d in enumerate(dist):
        def all_seen(r: float) -> bool:
            return bool(seen(rays, unit * (d + r), r, **kw).all())

        ok = np.array([all_seen(r) for r in _COARSE_RADII_M])
        missed = np.flatnonzero(~ok)
        if missed.size == 0:
            min_ok[i] = _COARSE_RADII_M[0]
            continue
        j = missed[-1]
        if j + 1 == len(_COARSE_RADII_M):
            max_miss[i] = _COARSE_RADII_M[j]
            continue
        lo, hi = _COARSE_RADII_M[j], _COARSE_RADII_M[j + 1]
        for _ in range(_BISECTIONS):
            mid = math.sqrt(lo * hi)
            lo, hi = (lo, mid) if all_seen(mid) else (mid, hi)
        min_ok[i], max_miss[i] = hi, lo
    return Detection(design.name, dist, min_ok, max_miss, bearings, len(rays))


# --------------------------------------------------------------------------- scenes


def run_scene(scenario, design: Design | str, seed: int | None = None) -> dict:
    """One scenario seen by one design: every pose swept, then estimated, mapped and scored
    as ``irring run`` does — one run of a study (:func:`irring.studies.study.run_point`), in
    this process.

    The estimator reads each design with the calibration of what its scene simulates
    (``pipeline.scene_calibration``, as ``irring run`` does). One deliberate difference from
    ``irring run``, so designs are compared fairly: the map is scored against the ground
    truth of the scenario as written (with its own design's reach), so every design is
    judged on the same cells: a design that cannot reach a wall loses recall and shadow for
    it instead of having the wall dropped from its exam.

    Returns the six ``metrics.SCORE_KEYS`` plus ``hardware_time_s`` (one 360° view of the
    design, :meth:`Design.hardware_time_s`), ``hardware_time_total_s`` (all poses),
    ``compute_time_s`` (sweep + estimate + map per view) and ``readings``.
    """
    from . import study

    d = designs_mod.get(design) if isinstance(design, str) else design
    p = _point(scenario, d, scenario.seed if seed is None else seed)
    # the scenario object itself: it may differ from its file
    task = study.Task(p, None, scenario.source, scenario)
    return _record(study.run_point(task), scenario.name)


def _point(scenario, design: Design, seed: int):
    from . import study

    return study.point(study.DesignSpec(design.name, design=design), scenario, seed)


def _record(row: dict, scenario_name: str) -> dict:
    """A study row as compare's run record."""
    from ..maps.metrics import SCORE_KEYS

    return {"scenario": scenario_name, "design": row["design"], "seed": row["seed"],
            "poses": row["poses"], **{k: row[k] for k in SCORE_KEYS},
            "hardware_time_s": row["hardware_time_s"],
            "hardware_time_total_s": row["hardware_time_total_s"],
            "compute_time_s": (row["sim_ms"] + row["compute_ms"]) / 1e3,
            "readings": row["readings"]}


def mean_of(values) -> float | None:
    """Mean of the values that are not None (None when there are none)."""
    vals = [v for v in values if v is not None]
    return float(np.mean(vals)) if vals else None


def summarise(runs: list[dict], detections: dict[str, Detection] | None = None) -> list[dict]:
    """One record per design: run scores averaged over scenarios and seeds (``None`` scores
    left out of the mean), hardware time of a 360° view, compute time per view, and the
    detection curve when given."""
    from ..maps.metrics import SCORE_KEYS

    out = []
    for name in dict.fromkeys(r["design"] for r in runs):
        mine = [r for r in runs if r["design"] == name]
        rec = {"design": name,
               "scenarios": sorted({r["scenario"] for r in mine}),
               "runs": len(mine)}
        for k in SCORE_KEYS:
            rec[k] = mean_of(r[k] for r in mine)
            if k != "shadow":
                continue
            vals = [r[k] for r in mine if r[k] is not None]
            rec["shadow_min"] = float(min(vals)) if vals else None
        rec["by_scenario"] = {sc: {k: mean_of(r[k] for r in mine if r["scenario"] == sc)
                                   for k in SCORE_KEYS} for sc in rec["scenarios"]}
        rec["poses"] = {sc: next(r["poses"] for r in mine if r["scenario"] == sc)
                        for sc in rec["scenarios"]}
        rec["hardware_time_s"] = float(np.mean([r["hardware_time_s"] for r in mine]))
        rec["compute_time_s"] = float(np.median([r["compute_time_s"] for r in mine]))
        if detections and name in detections:
            det = detections[name]
            rec["detection_distances_m"] = det.distances_m.tolist()
            rec["min_detectable_radius_m"] = [None if not math.isfinite(v) else float(v)
                                              for v in det.min_detectable_radius_m]
        out.append(rec)
    return out


def compare(scenarios, design_list, seeds: int = 1, *, detection_distances_m=None,
            bearings: int = 180, progress: bool | None = False, ex=None) -> dict:
    """Run every design on every scenario for ``seeds`` seeds (scenario seed, +1, …): a
    predefined study, run on ``ex`` (a ``concurrent.futures`` executor from
    :func:`irring.studies.executor.executor`; default: this process).
    ``progress``: show a bar (None: only at a terminal, see ``pipeline.progress_enabled``).

    Returns ``{"designs": summarise(...), "runs": [...], "detection": {...}}``.
    """
    from . import study
    from .executor import run_jobs
    from ..pipeline import progress_bar
    from ..scenario import load_scenario

    scs = [load_scenario(s) if isinstance(s, str) else s for s in scenarios]
    ds = [designs_mod.get(d) if isinstance(d, str) else d for d in design_list]
    points = [_point(sc, d, sc.seed + k) for sc in scs for d in ds for k in range(seeds)]
    names = [sc.name for sc in scs for d in ds for k in range(seeds)]
    dist = DEFAULT_DISTANCES_M if detection_distances_m is None else detection_distances_m
    detections = {}
    with progress_bar(len(points) + len(ds), "compare", progress, unit="run") as bar:
        tasks = study.tasks_for(points, {p.scenario: sc for p, sc in zip(
            points, [sc for sc in scs for d in ds for k in range(seeds)])})
        rows = run_jobs(study.run_point, tasks, ex, progress=lambda _: bar.update())
        runs = [_record(r, name) for r, name in zip(rows, names)]
        for d in ds:
            detections[d.name] = detection(d, dist, bearings=bearings)
            bar.update()
    return {"designs": summarise(runs, detections), "runs": runs,
            "detection_distances_m": list(map(float, dist))}


# --------------------------------------------------------------------------- outputs

TABLE_SCORES = ("occupied_f1", "free_accuracy", "coverage", "shadow")


def table(records: list[dict]) -> str:
    """A plain-text table of the per-design records (scores, times, detection)."""
    dists = records[0].get("detection_distances_m", []) if records else []
    # the shadow of each scene with something to hide behind, by its number of scans (one
    # scan shows what the rotating sensors see past a post; several, what other poses add)
    shadowed = [sc for sc in (records[0]["scenarios"] if records else [])
                if any(r["by_scenario"][sc]["shadow"] is not None for r in records)]
    scans = {sc: records[0]["poses"][sc] for sc in shadowed}
    by_count = len(set(scans.values())) == len(scans)
    shadow_head = [f"shadow {n} scan{'s' if n > 1 else ''}" if by_count else f"shadow {sc}"
                   for sc, n in scans.items()]
    head = (["design", "F1 occ", "free acc", "coverage", "shadow"] + shadow_head
            + ["360° view", "compute"] + [f"r@{d * 1e3:.0f}mm" for d in dists])
    rows = [head]
    for r in records:
        row = [r["design"]] + [("—" if r[k] is None else f"{r[k]:.3f}") for k in TABLE_SCORES]
        row += ["—" if r["by_scenario"][sc]["shadow"] is None
                else f"{r['by_scenario'][sc]['shadow']:.2f}" for sc in shadowed]
        row += [_seconds(r["hardware_time_s"]), f"{r['compute_time_s'] * 1e3:.1f} ms"]
        row += ["miss" if v is None else f"{v * 1e3:.1f}mm"
                for v in r.get("min_detectable_radius_m", [])]
        rows.append(row)
    widths = [max(len(row[i]) for row in rows) for i in range(len(head))]
    lines = ["  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in
                       enumerate(zip(row, widths))) for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    if shadowed and by_count:
        lines.append(", ".join(f"{h}: {sc}" for h, sc in zip(shadow_head, shadowed)))
    return "\n".join(lines)


def _seconds(s: float) -> str:
    return f"{s * 1e3:.0f} ms" if s < 1 else f"{s:.2f} s"


CSV_KEYS = ("design", "runs", "occupied_precision", "occupied_recall", "occupied_f1",
            "free_accuracy", "coverage", "shadow", "shadow_min", "hardware_time_s",
            "compute_time_s")


def write_csv(path, rows: list[dict], keys) -> None:
    import csv

    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for r in rows:
            w.writerow(["" if r.get(k) is None else r.get(k) for k in keys])


def chart(result: dict, path) -> None:
    """Four panels: map scores per design, shadow per scenario, hardware time per 360°
    view, and the smallest cylinder each design is sure to see versus distance."""
    from ..maps.render import figure   # no pyplot: the caller's matplotlib backend stays as it is

    recs = result["designs"]
    names = [r["design"] for r in recs]
    x = np.arange(len(names))
    fig = figure(13, 8.5)
    axes = fig.subplots(2, 2)
    (a_scores, a_shadow), (a_time, a_det) = axes

    def bars(ax, series: dict[str, list], title: str) -> None:
        w = 0.8 / max(len(series), 1)
        for i, (label, vals) in enumerate(series.items()):
            vals = np.array([np.nan if v is None else v for v in vals], dtype=float)
            xs = x + (i - (len(series) - 1) / 2) * w
            ax.bar(xs, vals, w, label=label)
            for xi, v in zip(xs, vals):  # say so where a bar is invisible
                if not v > 0.005:
                    ax.annotate("n/a" if np.isnan(v) else "0", (xi, 0.01), ha="center",
                                va="bottom", fontsize=7, rotation=90)
        ax.set_xticks(x, names)
        ax.set_ylim(0, 1.0)
        ax.set_ylabel("score (1 = perfect)")
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.07), ncols=4)
        ax.grid(axis="y", alpha=0.3)

    runs = recs[0]["runs"] if recs else 0
    bars(a_scores, {"occupied F1": [r["occupied_f1"] for r in recs],
                    "free accuracy": [r["free_accuracy"] for r in recs],
                    "coverage": [r["coverage"] for r in recs]},
         f"Map scores, mean over {runs} runs per design (scenarios × seeds)")
    with_shadow = [sc for sc in (recs[0]["scenarios"] if recs else [])
                   if any(r["by_scenario"][sc]["shadow"] is not None for r in recs)]
    bars(a_shadow, {f"{sc} ({recs[0]['poses'][sc]} scan{'s' if recs[0]['poses'][sc] > 1 else ''})":
                    [r["by_scenario"][sc]["shadow"] for r in recs] for sc in with_shadow},
         "Shadow: share of the wall behind thin posts that the map shows")

    hw = [r["hardware_time_s"] for r in recs]
    a_time.bar(x, hw, color="0.4")
    a_time.set_yscale("log")
    a_time.set_xticks(x, names)
    a_time.set_ylabel("seconds")
    a_time.set_title("Hardware time for one 360° view at one pose", fontsize=9)
    for xi, v in zip(x, hw):
        a_time.annotate(_seconds(v), (xi, v), ha="center", va="bottom", fontsize=8)
    a_time.grid(axis="y", alpha=0.3)

    dist = np.asarray(result["detection_distances_m"]) * 1e3
    for r in recs:
        if "min_detectable_radius_m" not in r:
            continue
        y = np.array([np.nan if v is None else v * 1e3 for v in r["min_detectable_radius_m"]])
        a_det.plot(dist, y, marker="o", label=r["design"])
    a_det.axhline(22, color="k", ls=":", lw=1)
    a_det.annotate("table leg, r = 22 mm", (dist[0], 24), fontsize=8)
    a_det.set_yscale("log")
    a_det.set_xlabel("distance from the robot centre to the cylinder (mm)")
    a_det.set_ylabel("radius (mm)")
    a_det.set_title("Smallest cylinder seen at every bearing (no point: none up to 200 mm)",
                    fontsize=9)
    a_det.legend(fontsize=8)
    a_det.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def study_files(name: str) -> tuple[str, ...]:
    """The files :func:`write_study` may write for the study ``name``."""
    return f"{name}.json", f"{name}.csv", "runs.csv", f"{name}.png"


def write_study(out_dir, name: str, result: dict, rows: list[dict], keys, draw) -> dict[str, str]:
    """A study's files in ``out_dir``, all together (:class:`irring.outputs.OutputSet`: a
    failed or interrupted write leaves the folder as it was): <name>.json (all of
    ``result``), <name>.csv (``rows`` with columns ``keys``), runs.csv (``result["runs"]``,
    if any) and <name>.png (``draw(result, path)``). Raises ``OutputError``."""
    target = OutputSet(out_dir, files=study_files(name))
    with target as tmp:
        paths = dict(zip(("json", "csv", "runs_csv", "chart"),
                         (tmp / f for f in study_files(name))))
        paths["json"].write_text(json.dumps(result, indent=2))
        write_csv(paths["csv"], rows, keys)
        if result["runs"]:
            write_csv(paths["runs_csv"], result["runs"], list(result["runs"][0]))
        else:
            del paths["runs_csv"]
        draw(result, paths["chart"])
    return {k: str(target.out / p.name) for k, p in paths.items()}


def write_outputs(result: dict, out_dir) -> dict[str, str]:
    """compare.json, compare.csv (one row per design), runs.csv, compare.png in ``out_dir``."""
    return write_study(out_dir, "compare", result, result["designs"], CSV_KEYS, chart)
