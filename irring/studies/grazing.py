"""Walls at grazing incidence (issue 13's must-show, ``irring bench grazing``): end-point RMS
per 10° bin of true incidence beside θ = 0's, pooled over rooms and seeds. Targets: every bin
below :data:`MAX_INCIDENCE_DEG` within :data:`RMS_TARGET_M`, and over :data:`GAIN_BAND_DEG`
the θ = 0 RMS at least :data:`GAIN_TARGET` times the estimator's. The story: docs/estimator.md.
"""

from __future__ import annotations

import math

import numpy as np

from ..scenario import Scenario, counted_seeds
from .rooms import Unusable, compared, each_room, run_with_theta0

BIN_DEG = 10
MAX_INCIDENCE_DEG = 70     # "walls at grazing incidence up to ~70°"
RMS_TARGET_M = 0.010       # end-point RMS of every bin below MAX_INCIDENCE_DEG
GAIN_TARGET = 3.0          # θ = 0's RMS over the estimator's, pooled over GAIN_BAND_DEG
GAIN_BAND_DEG = (50, 70)


def _rms(e: np.ndarray) -> float | None:
    return float(math.sqrt(np.mean(e * e))) if e.size else None


def incidence_errors(run, theta0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flat over a run's sweeps, for the readings both estimates call valid that hit a
    surface (:func:`rooms.compared`): end-point errors (m) of the estimate and of θ = 0, and
    the true incidence (degrees)."""
    e, e0, inc = [], [], []
    for sweep, p, p0 in zip(run.sweeps, run.points, theta0):
        m = compared(sweep, p, p0)
        hx, hy = sweep.truth.hit_point[..., 0][m], sweep.truth.hit_point[..., 1][m]
        e.append(np.hypot(p.x[m] - hx, p.y[m] - hy))
        e0.append(np.hypot(p0.x[m] - hx, p0.y[m] - hy))
        inc.append(np.degrees(sweep.truth.incidence_rad[m]))
    return tuple(np.concatenate(a) if a else np.zeros(0) for a in (e, e0, inc))


def band(e: np.ndarray, e0: np.ndarray, inc_deg: np.ndarray, lo: float, hi: float) -> dict:
    """Readings with lo ≤ incidence < hi (degrees): ``n``, ``rms_m``, ``rms_theta0_m``,
    ``gain`` (θ = 0's RMS over the estimator's), ``max_m``; None where undefined."""
    m = (inc_deg >= lo) & (inc_deg < hi)
    r, r0 = _rms(e[m]), _rms(e0[m])
    return {"lo_deg": lo, "hi_deg": hi, "n": int(m.sum()), "rms_m": r, "rms_theta0_m": r0,
            "gain": r0 / r if r and r0 is not None else None,
            "max_m": float(e[m].max()) if m.any() else None}


def bins(e: np.ndarray, e0: np.ndarray, inc_deg: np.ndarray) -> list[dict]:
    """:func:`band` of each :data:`BIN_DEG` bin from 0 to 90°."""
    return [band(e, e0, inc_deg, lo, lo + BIN_DEG) for lo in range(0, 90, BIN_DEG)]


def misses(table: list[dict], gain_band: dict) -> list[str]:
    """The targets a pooled table (:func:`bins`, and :func:`band` over :data:`GAIN_BAND_DEG`)
    misses, one line each; an empty bin is no miss, an empty gain band is."""
    out = [f"{b['lo_deg']}–{b['hi_deg']}°: RMS {b['rms_m'] * 1e3:.1f} mm > "
           f"{RMS_TARGET_M * 1e3:.0f} mm" for b in table
           if b["hi_deg"] <= MAX_INCIDENCE_DEG and b["rms_m"] is not None
           and b["rms_m"] > RMS_TARGET_M]
    lo, hi = GAIN_BAND_DEG
    if not gain_band["n"]:
        out.append(f"no reading at {lo}–{hi}°")
    elif gain_band["gain"] is not None and gain_band["gain"] < GAIN_TARGET:
        out.append(f"{lo}–{hi}°: θ = 0 only {gain_band['gain']:.1f}× worse (target ≥ "
                   f"{GAIN_TARGET:g}×)")
    return out


def _measure_room(sc: Scenario, n_seeds: int, bar) -> dict:
    parts = []
    for seed in counted_seeds(sc, n_seeds):
        parts.append(incidence_errors(*run_with_theta0(sc, seed)))
        bar.update()
    e, e0, inc = (np.concatenate(a) for a in zip(*parts))
    return {"name": sc.name, "source": sc.source, "n": int(e.size), "rms_m": _rms(e),
            "rms_theta0_m": _rms(e0), "gain_band": band(e, e0, inc, *GAIN_BAND_DEG),
            "_errors": (e, e0, inc)}


def measure(scenarios: list[Scenario | Unusable], n_seeds: int = 1, *,
            progress: bool | None = None, debug: bool = False) -> dict:
    """``rooms``: per room ``name``, ``source``, ``n`` readings compared, ``rms_m``,
    ``rms_theta0_m`` and its ``gain_band`` (:func:`band`), over ``n_seeds`` seeds (an error
    row for a room that cannot be loaded or run, :func:`rooms.each_room`); pooled over all
    rooms and seeds: ``bins``, ``gain_band`` and the targets' ``misses``."""
    rows = each_room(scenarios, n_seeds, _measure_room, label="grazing", progress=progress,
                     debug=debug)
    pooled = [r.pop("_errors") for r in rows if "_errors" in r]
    e, e0, inc = ((np.concatenate(a) for a in zip(*pooled)) if pooled
                  else (np.zeros(0),) * 3)
    table = bins(e, e0, inc)
    gain = band(e, e0, inc, *GAIN_BAND_DEG)
    return {"rooms": rows, "n": int(e.size), "rms_m": _rms(e), "rms_theta0_m": _rms(e0),
            "bins": table, "gain_band": gain, "misses": misses(table, gain)}
