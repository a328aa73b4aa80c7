"""What each effect costs per sweep, and that an effect that is off costs nothing: a synthetic
71 × 12 sweep of the paper's ring through pipelines built with
:meth:`~irring.simulation.effects.Pipeline.from_scenario`, no MuJoCo (:class:`RoundRoom`
stands in for the ray casts). Figures in µs per sweep, defined in docs/speed.md.
"""

from __future__ import annotations

import dataclasses
import math
import time
import types
from typing import Callable

import numpy as np

from .. import gp2
from ..core import MAX_RANGE_M, Truth, beam_geometry, sensor_angles_for_steps
from ..designs import PAPER_RING
from ..pipeline import progress_bar
from ..simulation.effects import STAGE_ORDER, Pipeline
from ..scenario import (EFFECTS, IncidenceEffect, NoiseEffect, OutliersEffect,
                        ReflectanceEffect, Scenario)

OFF_BUDGET = 0.02

# Parameters under which a stage is built but changes nothing (or next to nothing).
NEUTRAL = {
    "incidence": IncidenceEffect(max_incidence_rad=math.radians(90.0)),
    "noise": NoiseEffect(sigma_v=0.0),
    "reflectance": ReflectanceEffect(min_signal=0.0),
    "outliers": OutliersEffect(short_rate=0.0, random_rate=0.0, max_rate=0.0),
}


class RoundRoom:
    """Analytic ray caster: a round room (radius 0.70 m, white) with a grey post.

    Same call as ``SimRing.cast``: origins (..., 3), directions (..., 3) → an object with
    distance_m, incidence_rad, hit_point, geom_id, reflectance (NaN past ``max_range_m``).
    """

    def __init__(self, room_radius_m: float = 0.70, post_xy_m=(0.45, 0.12),
                 post_radius_m: float = 0.04, post_reflectance: float = 0.3,
                 max_range_m: float = MAX_RANGE_M):
        self.room_radius_m = room_radius_m
        self.post = np.array(post_xy_m, dtype=float)
        self.post_radius_m = post_radius_m
        self.post_reflectance = post_reflectance
        self.max_range_m = max_range_m

    @staticmethod
    def _circle(o, u, c, r, inside: bool):
        """Distance along unit u (2-D) from o to the circle (c, r); NaN if missed."""
        oc = o - c
        b = np.sum(oc * u, axis=-1)
        disc = b * b - (np.sum(oc * oc, axis=-1) - r * r)
        root = np.sqrt(np.where(disc >= 0, disc, np.nan))
        t = -b + root if inside else -b - root
        return np.where(t > 0, t, np.nan)

    def __call__(self, origin: np.ndarray, direction: np.ndarray) -> types.SimpleNamespace:
        o, u3 = np.asarray(origin, float), np.asarray(direction, float)
        horiz = np.linalg.norm(u3[..., :2], axis=-1)
        u = u3[..., :2] / horiz[..., None]
        t_wall = self._circle(o[..., :2], u, np.zeros(2), self.room_radius_m, inside=True)
        t_post = self._circle(o[..., :2], u, self.post, self.post_radius_m, inside=False)
        on_post = t_post < t_wall
        t2 = np.where(on_post, t_post, t_wall)
        d = t2 / horiz  # along the 3-D ray
        d = np.where(d <= self.max_range_m, d, np.nan)
        p2 = o[..., :2] + t2[..., None] * u
        normal = np.where(on_post[..., None], p2 - self.post, -p2)
        normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
        cos_inc = np.abs(np.sum(normal * u, axis=-1)) * horiz
        hit = ~np.isnan(d)
        return types.SimpleNamespace(
            distance_m=d, incidence_rad=np.where(hit, np.arccos(np.clip(cos_inc, 0, 1)), np.nan),
            hit_point=np.where(hit[..., None], o + d[..., None] * u3, np.nan),
            geom_id=np.where(hit, np.where(on_post, 1, 0), -1),
            reflectance=np.where(hit, np.where(on_post, self.post_reflectance, 1.0), np.nan))


def synthetic_truth(cast: RoundRoom | None = None) -> Truth:
    """The paper ring's 71 × 12 sweep at the room's centre, cast with ``cast``."""
    cast = cast or RoundRoom()
    ring = PAPER_RING
    angles = sensor_angles_for_steps(ring, np.arange(ring.min_step, ring.max_step + 1))
    emitter, heading = beam_geometry(ring, np.zeros(3), angles, ring.emitter_offset_m)
    origin = np.concatenate([emitter, np.full(heading.shape + (1,), ring.sensor_height_m)],
                            axis=-1)
    direction = np.stack([np.cos(heading), np.sin(heading), np.zeros_like(heading)], axis=-1)
    h = cast(origin, direction)
    return Truth(distance_m=h.distance_m, incidence_rad=h.incidence_rad, hit_point=h.hit_point,
                 origin=origin, direction=direction, geom_id=h.geom_id,
                 reflectance=h.reflectance)


class _Replay:
    """Casts each distinct ray batch once, then replays the hits, so the timings below are
    the pipeline's own work and not the stand-in caster's."""

    def __init__(self, cast: Callable):
        self.cast = cast
        self.cache: dict = {}

    def __call__(self, origin: np.ndarray, direction: np.ndarray):
        key = (origin.shape, origin.tobytes()[:64], direction.tobytes()[:64])
        if key not in self.cache:
            self.cache[key] = self.cast(origin, direction)
        return self.cache[key]


def _with_effects(base: Scenario, effects: dict, samples: int) -> Scenario:
    return dataclasses.replace(base, effects=types.MappingProxyType(dict(effects)),
                               scan=dataclasses.replace(base.scan, samples=samples))


def _time(configs: dict[str, Callable[[], object]], rounds: int, batch: int,
          progress: bool | None = None) -> dict[str, float]:
    """Median over rounds of µs per call, configurations interleaved; a bar over the
    rounds (``progress``, as :func:`irring.pipeline.progress_bar` takes it)."""
    samples: dict[str, list[float]] = {k: [] for k in configs}
    for fn in configs.values():  # warm up caches and lazy imports
        fn()
    with progress_bar(rounds, "bench effects", progress, unit="round") as bar:
        for _ in range(rounds):
            for name, fn in configs.items():
                t0 = time.perf_counter_ns()
                for _ in range(batch):
                    fn()
                samples[name].append((time.perf_counter_ns() - t0) / batch / 1e3)
            bar.update()
    return {k: float(np.median(v)) for k, v in samples.items()}


def measure(base: Scenario, *, samples: int = 4, rounds: int = 25, batch: int = 40,
            seed: int = 0, progress: bool | None = None) -> dict:
    """Per-sweep cost of each effect and of the effects that are off (see module doc);
    ``progress``: a bar over the rounds (None: at a terminal)."""
    room = RoundRoom(max_range_m=base.sensor.max_range_m)
    truth = synthetic_truth(room)
    rng = np.random.default_rng(seed)
    all_on = {name: EFFECTS[name]() for name in STAGE_ORDER}
    cast = _Replay(room)

    def pipe(effects: dict) -> Callable[[], object]:
        p = Pipeline.from_scenario(_with_effects(base, effects, samples))
        return lambda: p.run(truth, rng, cast=cast)

    model = gp2.sensor(base.sensor.model)
    bits, vref, floor = base.sensor.adc_bits, base.sensor.vref_v, model.no_return_v

    def bare():  # the ideal curve written out, no pipeline
        v = model.voltage(truth.distance_m)
        return gp2.counts_from_voltage(np.where(np.isnan(v), floor, v), bits, vref)

    beam_params = all_on["beam"]
    directions = np.ones(truth.direction.shape[:2] + (beam_params.rays, 3)) / math.sqrt(3)
    origins = np.broadcast_to(truth.origin[..., None, :], directions.shape).copy()

    configs: dict[str, Callable[[], object]] = {
        "bare": bare, "ideal": pipe({}), "full": pipe(all_on),
        "fake_cast": lambda: room(origins, directions)}
    for name in STAGE_ORDER:
        configs[f"alone:{name}"] = pipe({name: all_on[name]})
        configs[f"without:{name}"] = pipe({k: v for k, v in all_on.items() if k != name})
        if name in NEUTRAL:
            configs[f"neutral:{name}"] = pipe({name: NEUTRAL[name]})
    t = _time(configs, rounds, batch, progress)

    full, ideal = t["full"], t["ideal"]
    off = ideal - t["bare"]  # signed: timing noise can make it slightly negative
    rows = []
    for name in STAGE_ORDER:
        rows.append({
            "effect": name,
            "alone_us": t[f"alone:{name}"] - ideal,
            "in_full_us": full - t[f"without:{name}"],
            "in_full_pct": 100.0 * (full - t[f"without:{name}"]) / full,
            "neutral_us": (t[f"neutral:{name}"] - ideal) if name in NEUTRAL else None,
            "off_us": off,
        })
    return {
        "sweep_shape": list(truth.distance_m.shape),
        "sensor": base.sensor.model, "adc_bits": bits, "samples": samples,
        "beam_rays": beam_params.rays,
        "rounds": rounds, "batch": batch,
        "full_us": full, "ideal_us": ideal, "bare_curve_us": t["bare"],
        "fake_cast_us": t["fake_cast"],
        "off_us": off, "off_pct_of_full": 100.0 * off / full,
        "off_budget_pct": 100.0 * OFF_BUDGET,
        "off_within_budget": off <= OFF_BUDGET * full,
        "effects": rows,
    }
