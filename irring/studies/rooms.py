"""Map scores on a set of rooms, with the scene's effects and with an ideal sensor (none of
:data:`SIGNAL_EFFECTS`), and the end points' RMS error beside θ = 0's (``irring bench
rooms``). An ideal sensor must never map worse. The figures: docs/studies.md.
"""

from __future__ import annotations

import dataclasses
import math
import traceback
import types
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import errors, pipeline
from ..estimation.estimate import estimate
from ..maps import metrics
from ..maps.metrics import SCORE_KEYS
from ..outputs import real_path
from ..pipeline import progress_bar
from ..scenario import (Scenario, ScenarioError, clipped_obstacles, counted_seeds, listed,
                        load_scenario, not_a_scenario_file, resolve)
from .report import mean_of

# The room set of issue 13 (scenarios/), then the paper's rooms; `irring bench rooms` runs
# these unless given others.
ROOMS = ("l_room", "corridor_table", "angled_walls", "posts", "box_room", "big_room",
         "narrow_room", "far_walls", "far_hexagon", "t_room", "t_room_cylinder",
         "t_room_three_cylinders")

# Effects that change the signal a sensor reports; the ideal sensor has none of them.
SIGNAL_EFFECTS = ("incidence", "noise", "quantization", "foldover", "reflectance", "outliers",
                  "beam", "averaging")

# Must-show targets of issue 13 for the scene's own effects (the ideal sensor: ≥ those),
# set for the bundled default effects; a miss of a scene with more is marked with them.
TARGETS = {"occupied_f1": 0.93, "occupied_precision": 0.90, "free_accuracy": 0.99}
TARGET_EFFECTS = ("incidence", "noise", "quantization")

VARIANTS = ("effects", "ideal")


def ideal(scenario: Scenario) -> Scenario:
    """The scenario measured perfectly: every signal effect removed and the odometry exact
    (a moving robot still drives its path, the belt and timing stay: they are the ring, not
    a measurement), so the map differs from the truth only by what the ring cannot see."""
    kept = {k: v for k, v in scenario.effects.items() if k not in SIGNAL_EFFECTS}
    if "motion" in kept:
        kept["motion"] = dataclasses.replace(kept["motion"], odometry_sigma_m=0.0,
                                             odometry_sigma_rad=0.0)
    return dataclasses.replace(scenario, effects=types.MappingProxyType(kept))


def _rms(x: np.ndarray) -> float | None:
    return float(math.sqrt(np.mean(x * x))) if x.size else None


def run_with_theta0(scenario: Scenario, seed: int | None = None) -> tuple:
    """``pipeline.run`` of the scenario (not scored) and, per sweep, the same readings read
    at θ = 0 with the very calibration the run estimates with: (run, [Points, …])."""
    theta0 = []

    def both(sweep, calibration):
        theta0.append(estimate(sweep, calibration, iterate=False))
        return estimate(sweep, calibration)

    run = pipeline.run(scenario, seed=seed, progress=False, estimator=both, score=False)
    return run, theta0


def compared(sweep, points, points_theta0) -> np.ndarray:
    """(S, N) bool: the readings both estimates call valid and that hit a surface."""
    hx, hy = sweep.truth.hit_point[..., 0], sweep.truth.hit_point[..., 1]
    return points.valid & points_theta0.valid & np.isfinite(hx) & np.isfinite(hy)


def point_errors(sweep, points, points_theta0) -> tuple[np.ndarray, np.ndarray]:
    """End-point errors (m) of the :func:`compared` readings: (iterative, θ = 0), each
    against the simulator's true hit point."""
    truth = sweep.truth
    hx, hy = truth.hit_point[..., 0], truth.hit_point[..., 1]
    m = compared(sweep, points, points_theta0)
    return (np.hypot(points.x[m] - hx[m], points.y[m] - hy[m]),
            np.hypot(points_theta0.x[m] - hx[m], points_theta0.y[m] - hy[m]))


def score_room(scenario: Scenario, seed: int | None = None, *,
               judged_on: Scenario | None = None, truth_cache: dict | None = None) -> dict:
    """One room, one seed, as written: the six map scores, ``point_rms_m``,
    ``point_rms_theta0_m`` (None when no reading qualifies), ``readings``, ``valid``.
    ``judged_on``: the scene whose ground truth scores the map (default ``scenario``): the
    same room with other effects, so two sensors are judged on the same visible wall.
    ``truth_cache``: a dict the caller keeps, so runs of one room rasterise its truth once."""
    run, theta0 = run_with_theta0(scenario, seed)
    errs, errs0 = [], []
    for sweep, pts, p0 in zip(run.sweeps, run.points, theta0):
        e, e0 = point_errors(sweep, pts, p0)
        errs.append(e)
        errs0.append(e0)
    readings = run.readings()
    judge = scenario if judged_on is None else judged_on
    truth = (metrics.ground_truth(judge, run.grid) if truth_cache is None else
             metrics.cached_ground_truth(judge, run.grid, truth_cache, judge.source or judge.name))
    scores = metrics.score(run.grid, judge, truth, mapped_by=scenario)
    return {**{k: scores[k] for k in SCORE_KEYS},
            "point_rms_m": _rms(np.concatenate(errs)),
            "point_rms_theta0_m": _rms(np.concatenate(errs0)),
            "readings": readings["total"], "valid": readings["valid"]}


@dataclass(frozen=True)
class Unusable:
    """A room that could not be scored: its name, file, the exit status and one-line
    message ``irring run`` would end with (:func:`errors.describe`)."""

    name: str
    source: str
    status: int
    message: str


def resolve_rooms(names_or_paths) -> list[Scenario | Unusable]:
    """Scenarios from bundled names, YAML paths, or folders (every ``*.yaml`` in them).

    A name that is no file and no bundled scenario, a folder without ``*.yaml``, or a file
    given twice (itself, or in a folder) raises ScenarioError before any work; a file that
    does not load, or a ``*.yaml`` in a folder that is no regular file (a pipe would be
    waited on for good), is an :class:`Unusable` entry, so one bad room in a folder does
    not stop the others."""
    paths: list[tuple[Path, bool]] = []   # (file, found in a folder rather than named)
    given: dict[Path, str] = {}     # each file's real path → the argument that named it
    for item in names_or_paths:
        named = listed(str(item))   # a bundled name stays a name beside a folder of it
        in_folder = named[0][1]
        files = [Path(f) for f, _ in named] if in_folder else [resolve(item)]
        for file in files:
            real = real_path(file)
            if real in given:
                raise ScenarioError(f"{file}: given twice (by {given[real]} and {item}); it "
                                    "would be scored and listed twice, so name each room once")
            given[real] = str(item)
        paths.extend((file, in_folder) for file in files)
    out: list[Scenario | Unusable] = []
    for path, in_folder in paths:
        why = not_a_scenario_file(path) if in_folder else None
        if why:
            out.append(Unusable(path.stem, str(path), errors.INPUT, errors.printable(why)))
            continue
        try:
            out.append(load_scenario(path))
        except ScenarioError as exc:
            status, line = errors.describe(exc)
            out.append(Unusable(path.stem, str(path), status, line))
    return out


def measure(scenarios: list[Scenario | Unusable], n_seeds: int = 1, *,
            progress: bool | None = None, debug: bool = False) -> list[dict]:
    """Per room: ``name``, ``source``, and for each of :data:`VARIANTS` the mean over
    ``n_seeds`` seeds (the scenario's own seed, +1, …) of every figure of :func:`score_room`, plus
    ``misses``: the targets (:data:`TARGETS`) the room's scene misses (an undefined score,
    nothing to score, is none), the scene's effects beyond those the targets are set for
    (``beyond_target_effects``, :data:`TARGET_EFFECTS`), and the scores on which the ideal
    sensor is worse than the scene's (``ideal_worse``). A room that cannot be
    loaded or run is an error row (:func:`each_room`)."""
    return each_room(scenarios, n_seeds, _measure_room, runs_per_seed=len(VARIANTS),
                     progress=progress, debug=debug)


def each_room(scenarios: list[Scenario | Unusable], n_seeds: int, measure_room, *,
              runs_per_seed: int = 1, label: str = "rooms", progress: bool | None = None,
              debug: bool = False) -> list[dict]:
    """``measure_room(scenario, n_seeds, bar)`` (a dict starting with ``name`` and
    ``source``; ``bar.update()`` once per run) for each room, under one progress bar. A room
    that cannot be loaded or run (an :class:`Unusable`, or an error in its run) is a row with
    ``name``, ``source``, ``error`` (the one-line message) and ``status`` (the exit status
    ``irring run`` would give) instead; ``debug``: also print that error's traceback. A room
    whose walls clip an obstacle has ``clipped_obstacles`` (:func:`clipped_obstacles`)."""
    rows = []
    with progress_bar(len(scenarios) * n_seeds * runs_per_seed, label, progress,
                      unit="run") as bar:
        for sc in scenarios:
            if isinstance(sc, Unusable):
                rows.append({"name": sc.name, "source": sc.source, "error": sc.message,
                             "status": sc.status})
                bar.update(runs_per_seed * n_seeds)
                continue
            try:
                row = measure_room(sc, n_seeds, bar)
            except Exception as exc:  # noqa: BLE001 - one room's failure is that room's row
                if debug:
                    traceback.print_exc()
                status, line = errors.describe(exc)
                rows.append({"name": sc.name, "source": sc.source, "error": line,
                             "status": status})
                continue
            clipped = clipped_obstacles(sc)   # rooms of the user's: a mistyped centre is said
            if clipped:
                row["clipped_obstacles"] = [c.as_json() for c in clipped]
            rows.append(row)
    return rows


def print_clip_notes(row: dict) -> None:
    """The note lines for a room's obstacles its walls clip (``each_room``'s rows), and for
    a room of :func:`measure` whose scene lists no signal effect (its two rows are alike)."""
    for clip in row.get("clipped_obstacles", ()):
        print(f"  note: {clip['note']}")
    if row.get("signal_effects") == []:   # a room file of the user's that left effects out
        print("  note: its scene lists no sensor-signal effect, so its effects row is the "
              "ideal sensor too; the bundled rooms' defaults: effects: [incidence, noise, "
              "quantization] (scenarios/README.md)")


def _measure_room(sc: Scenario, n_seeds: int, bar) -> dict:
    seeds = counted_seeds(sc, n_seeds)
    row = {"name": sc.name, "source": sc.source}
    truths: dict = {}
    for variant, scene in (("effects", sc), ("ideal", ideal(sc))):
        runs = []
        for seed in seeds:   # both judged on the scene's truth: the wall its sensor returns from
            runs.append(score_room(scene, seed, judged_on=sc, truth_cache=truths))
            bar.update()
        row[variant] = {k: mean_of([r[k] for r in runs]) for k in runs[0]}
    row["misses"] = {k: row["effects"][k] for k, lim in TARGETS.items()
                     if row["effects"][k] is not None and row["effects"][k] < lim}
    row["beyond_target_effects"] = [k for k in sc.effects if k not in TARGET_EFFECTS]
    row["signal_effects"] = [k for k in sc.effects if k in SIGNAL_EFFECTS]
    row["ideal_worse"] = _ideal_worse(row["effects"], row["ideal"])
    return row


def _ideal_worse(noisy: dict, ideal_: dict) -> list[str]:
    """Scores (higher is better) and RMS (lower is better) where the ideal sensor loses,
    beyond round-off of the means (1e-9); a score undefined for either (nothing to score,
    ``metrics``) is no loss."""
    worse = [k for k in SCORE_KEYS
             if noisy[k] is not None and ideal_[k] is not None and ideal_[k] < noisy[k] - 1e-9]
    if (noisy["point_rms_m"] is not None and ideal_["point_rms_m"] is not None
            and ideal_["point_rms_m"] > noisy["point_rms_m"] + 1e-9):
        worse.append("point_rms_m")
    return worse
