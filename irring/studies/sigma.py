"""err/σ per distance band and sensor model (``irring bench sigma``): how well each valid
reading's σ (``Points.sigma_m``, what the mapper spreads a hit over) states its range error,
on rooms of simulated walls. A σ that states the error gives err/σ RMS ≈ 1 in every band.
The figures and why: docs/estimator.md, "A reading's σ against its error"."""

from __future__ import annotations

import math

import numpy as np

from .. import pipeline
from ..scenario import Scenario, counted_seeds, loads

BANDS = 5          # equal bands of the scene's max range, from 0
Z_LOW, Z_HIGH = 0.8, 1.25   # err/σ RMS of a σ that states its error, within sampling

# One room per sensor model, written for this study: an irregular pentagon three poses see
# at 30-100 % of the range (walls 0.25-0.62 m for the GP2D12 read to 624 mm, 0.32-0.80 m for
# the GP2Y0A21 to 800 mm, 0.75-1.5 m for the GP2Y0A02 to 1500 mm).
_ROOM = """\
name: sigma_walls_{model}
seed: {seed}
room:
  outline_mm: {outline}
robot:
  design: rotating12
  poses:
{poses}
sensor: {{model: {model}, max_range_mm: {range_mm}, adc_bits: 12}}
effects: [incidence, noise, quantization]
map: {{resolution_mm: 10}}
"""
_SHAPE = [(0.0, 0.0), (1.0, -0.043), (1.098, 0.76), (0.496, 1.047), (-0.075, 0.724)]
_POSES = [(0.468, 0.425, 8), (0.602, 0.366, -27), (0.366, 0.516, 61)]
_SCALE = {"gp2d12": (1080, 624, 7305), "gp2y0a21": (1380, 800, 7303),
          "gp2y0a02": (2540, 1500, 7301)}


def wall_rooms() -> list[Scenario]:
    """The study's rooms: one per sensor model of :data:`_SCALE`."""
    out = []
    for model, (size, range_mm, seed) in _SCALE.items():
        outline = [[round(x * size), round(y * size)] for x, y in _SHAPE]
        poses = "\n".join(f"    - {{x_mm: {round(x * size)}, y_mm: {round(y * size)}, "
                          f"yaw_deg: {yaw}}}" for x, y, yaw in _POSES)
        out.append(loads(_ROOM.format(model=model, seed=seed, outline=outline, poses=poses,
                                      range_mm=range_mm), source=f"sigma study ({model})"))
    return out


def reading_z(run) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flat over a run's sweeps, the valid readings whose beam hit a surface: true distance
    (m), range error (m, estimated minus true along the beam) and σ (m)."""
    td, err, sig = [], [], []
    for sweep, p in zip(run.sweeps, run.points):
        d = sweep.truth.distance_m
        m = p.valid & np.isfinite(d)
        td.append(d[m])
        err.append((p.d - d)[m])
        sig.append(p.sigma_m[m])
    return tuple(np.concatenate(a) for a in (td, err, sig))


def band_table(true_m: np.ndarray, err_m: np.ndarray, sigma_m: np.ndarray,
               max_range_m: float, bands: int = BANDS) -> list[dict]:
    """Per band of ``max_range_m``/``bands``: ``lo_m``, ``hi_m``, ``n``, ``err_rms_m``,
    ``sigma_median_m``, ``z_rms`` (err/σ RMS) and ``beyond_2sigma`` (share); None where
    empty."""
    edges = np.linspace(0.0, max_range_m, bands + 1)
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (true_m >= lo) & (true_m < hi)
        z = err_m[m] / sigma_m[m]
        rows.append({"lo_m": float(lo), "hi_m": float(hi), "n": int(m.sum()),
                     "err_rms_m": float(math.sqrt(np.mean(err_m[m] ** 2))) if m.any() else None,
                     "sigma_median_m": float(np.median(sigma_m[m])) if m.any() else None,
                     "z_rms": float(math.sqrt(np.mean(z * z))) if m.any() else None,
                     "beyond_2sigma": float(np.mean(np.abs(z) > 2.0)) if m.any() else None})
    return rows


def measure(scenarios: list[Scenario], n_seeds: int = 1) -> list[dict]:
    """Per room: ``name``, ``sensor``, ``max_range_m`` and ``bands`` (:func:`band_table` over
    its seeds, the scenario's own, +1, …)."""
    out = []
    for sc in scenarios:
        parts = [reading_z(pipeline.run(sc, seed=s, progress=False, score=False))
                 for s in counted_seeds(sc, n_seeds)]
        td, err, sig = (np.concatenate(a) for a in zip(*parts))
        rng = sc.sensor.max_range_m
        out.append({"name": sc.name, "sensor": sc.sensor.model, "max_range_m": rng,
                    "bands": band_table(td, err, sig, rng)})
    return out
