"""The iterative estimator (paper Table II) against the θ = 0 assumption on simulated sweeps:
range RMSE at steep incidence and overall, iterations per reading, time per sweep
(``irring bench estimator``). Which readings each figure counts: docs/estimator.md.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..core import Reason
from ..estimation.calibration import Calibration
from ..estimation.estimate import estimate


def _rmse(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x))) if x.size else float("nan")


def measure(scenario, *, sweeps_per_pose: int = 5, min_theta_deg: float = 40.0,
            calibration: Calibration | None = None, seed: int | None = None,
            max_iterations: int = 20) -> dict:
    """Run the comparison on ``scenario`` (a loaded Scenario); return plain figures."""
    from ..simulation.sim import SimRing   # deferred: loads MuJoCo, which --help does not need

    sim = SimRing(scenario, seed=seed)
    cal = calibration
    err_it, err_0, err_0_raw, err_it_all_steep = [], [], [], []
    all_it, all_0 = [], []
    iters, times = [], []
    not_converged = 0
    selected = 0
    theta_errors = []
    for pose in range(len(scenario.robot.poses)):
        for _ in range(sweeps_per_pose):
            sw = sim.sweep(pose)
            if cal is None:  # the calibration of what the scene simulates
                cal = Calibration.for_scene(scenario)
            t0 = time.perf_counter()
            p = estimate(sw, cal, max_iterations=max_iterations)
            times.append(time.perf_counter() - t0)
            p0 = estimate(sw, cal, iterate=False)
            d = sw.truth.distance_m
            inc = sw.truth.incidence_rad
            hit = np.isfinite(d)
            steep = hit & (inc >= math.radians(min_theta_deg))
            selected += int(steep.sum())
            both = p.valid & p0.valid & hit
            m = both & steep
            err_it.append(p.d[m] - d[m])
            err_0.append(p0.d[m] - d[m])
            # θ = 0 distances even where that estimate calls them out of range
            raw0 = cal.distance(np.where(p.valid, sw.counts, 1.0).astype(float), 0.0)
            ms = p.valid & steep
            err_it_all_steep.append(p.d[ms] - d[ms])
            err_0_raw.append(raw0[ms] - d[ms])
            all_it.append(p.d[both] - d[both])
            all_0.append(p0.d[both] - d[both])
            theta_errors.append(p.theta[ms] - inc[ms])
            iters.append(p.iterations[p.valid])
            not_converged += int(np.sum(p.reason == Reason.NOT_CONVERGED))
    cat = np.concatenate
    e_it, e_0 = cat(err_it), cat(err_0)
    r_it, r_0 = _rmse(e_it), _rmse(e_0)
    e_its, e_0r = cat(err_it_all_steep), cat(err_0_raw)
    it = cat(iters)
    th = cat(theta_errors)
    return {
        "scenario": scenario.name,
        "effects": list(scenario.effects),
        "calibration": cal.source if cal is not None else "",
        "sweeps": len(times),
        "min_theta_deg": float(min_theta_deg),
        "steep_readings": selected,
        "steep": {"n": int(e_it.size), "rmse_iterative_m": r_it, "rmse_theta0_m": r_0,
                  "ratio": r_it / r_0 if r_0 > 0 else float("nan")},
        "steep_all": {"n": int(e_its.size), "rmse_iterative_m": _rmse(e_its),
                      "rmse_theta0_m": _rmse(e_0r),
                      "ratio": _rmse(e_its) / _rmse(e_0r) if e_0r.size else float("nan")},
        "all": {"n": int(cat(all_it).size), "rmse_iterative_m": _rmse(cat(all_it)),
                "rmse_theta0_m": _rmse(cat(all_0))},
        "theta_error_deg": {"median_abs": float(np.degrees(np.median(np.abs(th)))) if th.size
                            else float("nan"),
                            "rms": float(np.degrees(_rmse(th)))},
        "iterations": {"mean": float(it.mean()) if it.size else float("nan"),
                       "median": float(np.median(it)) if it.size else float("nan"),
                       "p95": float(np.percentile(it, 95)) if it.size else float("nan"),
                       "max": int(it.max()) if it.size else 0},
        "not_converged": not_converged,
        "estimate_ms_per_sweep": float(np.median(times) * 1e3),
    }
