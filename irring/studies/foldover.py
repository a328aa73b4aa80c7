"""Fold-over seen from as close as the housing allows (issue 13's must-show, ``irring bench
foldover``): per room and seed, no valid reading more than :data:`MAX_ERROR_M` from its true
hit, no occupied cell outside the room, no non-finite valid output. The story:
docs/foldover.md.
"""

from __future__ import annotations

import numpy as np

from .. import pipeline
from ..core import Reason, distance_to_outline, inside_outline
from ..maps.mapping import OCCUPIED, OccupancyGrid
from ..maps.metrics import SCORE_KEYS
from ..scenario import Scenario, counted_seeds
from ..simulation.sim import SimRing
from .rooms import Unusable, each_room

MAX_ERROR_M = 0.100   # a valid reading farther than this from its true hit is on the wrong branch
# An occupied cell lies "outside the room" when its centre is farther beyond the outline than
# the scores' 1-cell tolerance plus half a cell (a wall's cell centre), plus this margin.
OUTSIDE_CELLS = 1.5
OUTSIDE_MARGIN_M = 0.010
# What a room's map is worth once fold-over has been resolved (readings left ambiguous are
# cells lost): shown beside the targets, not judged.
MAP_SCORES = tuple(k for k in SCORE_KEYS if k not in ("coverage", "shadow"))


def outside_tolerance_m(resolution_m: float) -> float:
    """How far (m) beyond the outline an occupied cell's centre may lie on cells of this size."""
    return OUTSIDE_CELLS * resolution_m + OUTSIDE_MARGIN_M


def reading_errors(points, hit_point: np.ndarray) -> np.ndarray:
    """End-point error (m) of each valid reading of a sweep against its true hit
    ``hit_point`` (S, N, 3), flat; inf for a valid reading whose beam hit nothing or whose
    end point is not finite."""
    e = np.hypot(points.x - hit_point[..., 0], points.y - hit_point[..., 1])
    e = e[points.valid]
    return np.where(np.isfinite(e), e, np.inf)


def hits_past_range(sweep, points, scenario: Scenario) -> tuple[np.ndarray, int]:
    """(the sweep's true hit points (S, N, 3), with the surface each valid reading's beam
    meets past the sensor's range where it met none within it; how many such readings). The
    simulated sensor reads only noise from a surface past its range, so such a reading is a
    noise spike the estimator placed; it is judged by where its beam's surface really is."""
    truth = sweep.truth
    past = points.valid & ~np.isfinite(truth.distance_m)
    if not past.any():
        return truth.hit_point, 0
    hit = truth.hit_point.copy()
    with SimRing(scenario) as sim:
        hit[past] = sim.cast(truth.origin[past], truth.direction[past],
                             max_range_m=np.inf).hit_point
    return hit, int(past.sum())


def worst_error(errors: np.ndarray) -> tuple[float | None, int]:
    """(the largest finite error in m, None without one; how many are inf: valid readings
    whose beam hit nothing). Kept apart so the JSON holds numbers only."""
    finite = np.isfinite(errors)
    return (float(errors[finite].max()) if finite.any() else None), int((~finite).sum())


def nonfinite_outputs(points) -> int:
    """Valid readings of a sweep with a NaN or inf x, y or σ."""
    v = points.valid
    return int((~(np.isfinite(points.x[v]) & np.isfinite(points.y[v])
                  & np.isfinite(points.sigma_m[v]))).sum())


def cells_outside(grid: OccupancyGrid, outline) -> int:
    """Occupied cells whose centre lies outside ``outline`` (m) by more than
    :func:`outside_tolerance_m`: walls drawn outside the room."""
    iy, ix = np.nonzero(grid.classify() == OCCUPIED)
    cx, cy = grid.cell_centers()
    x, y = cx[ix], cy[iy]
    out = ~inside_outline(x, y, outline)
    out &= distance_to_outline(x, y, outline) > outside_tolerance_m(grid.resolution_m)
    return int(out.sum())


def check_run(scenario: Scenario, seed: int | None = None) -> dict:
    """One room, one seed, as written: ``seed``, ``valid`` readings, ``ambiguous``
    (FOLDOVER_AMBIGUOUS), ``far`` (valid readings > :data:`MAX_ERROR_M` off),
    ``max_error_m`` (the largest finite error; None without one), ``no_hit`` (valid readings
    whose beam hit nothing, counted in ``far``), ``past_range`` (valid readings whose beam
    meets its surface only past the sensor's range: judged against that surface,
    :func:`hits_past_range`), ``cells_outside``, ``nonfinite``, the map
    scores of :data:`MAP_SCORES` (as ``irring run`` and ``irring bench rooms`` score a map;
    None where undefined; not targets here) and ``passed`` (no far reading, no cell outside,
    nothing non-finite)."""
    run = pipeline.run(scenario, seed=seed, progress=False)
    errs, past_range = [], 0
    for sw, p in zip(run.sweeps, run.points):
        hit, n = hits_past_range(sw, p, scenario)
        errs.append(reading_errors(p, hit))
        past_range += n
    errs = np.concatenate(errs)
    row = {"seed": run.seed, "valid": int(errs.size),
           "ambiguous": int(sum((p.reason == Reason.FOLDOVER_AMBIGUOUS).sum()
                                for p in run.points)),
           "far": int((errs > MAX_ERROR_M).sum()),
           **dict(zip(("max_error_m", "no_hit"), worst_error(errs))),
           "past_range": past_range,
           "cells_outside": cells_outside(run.grid, scenario.room.outline_m),
           "nonfinite": sum(nonfinite_outputs(p) for p in run.points),
           **{k: run.scores[k] for k in MAP_SCORES}}
    row["passed"] = row["far"] == 0 and row["cells_outside"] == 0 and row["nonfinite"] == 0
    return row


def _check_room(sc: Scenario, n_seeds: int, bar) -> dict:
    runs = []
    for seed in counted_seeds(sc, n_seeds):
        runs.append(check_run(sc, seed))
        bar.update()
    return {"name": sc.name, "source": sc.source, "sensor": sc.sensor.model,
            "effects": list(sc.effects), "runs": runs}


def measure(scenarios: list[Scenario | Unusable], n_seeds: int = 1, *,
            progress: bool | None = None, debug: bool = False) -> list[dict]:
    """Per room: ``name``, ``source``, ``sensor`` (its model), ``effects`` and ``runs``: :func:`check_run` for each
    seed (the scenario's own, +1, …); a room that cannot be loaded or run is an error row
    (:func:`rooms.each_room`)."""
    return each_room(scenarios, n_seeds, _check_room, label="fold-over", progress=progress,
                     debug=debug)
