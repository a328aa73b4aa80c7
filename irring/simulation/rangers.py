"""Sensor behaviour the GP2 pipeline lacks, for the non-IR designs: :class:`SonarConeStage`
(the nearest echo in a cone, only from surfaces facing the transducer) in the effects
pipeline's ``beam`` slot, and :func:`pipeline_for`, a scene's pipeline with it added for a
sonar (``SimRing``'s default). How the cone is cast: docs/simulation.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..gp2 import sensor_spec
from . import effects
from .effects import Frame, Pipeline, Setup, Stage


@dataclass(frozen=True)
class SonarCone:
    """A sonar's cone: full fan ±``half_angle_rad`` with ``rays`` rays (odd: one on axis);
    echoes from surfaces hit more obliquely than ``max_incidence_rad`` are lost
    (None: the sensor model's limit)."""

    half_angle_rad: float = math.radians(15.0)
    rays: int = 61
    max_incidence_rad: float | None = None


class SonarConeStage(Stage):
    """Nearest specular echo within the cone (see the module docstring)."""

    name = "beam"          # the pipeline's slot for "a cone of rays instead of one"
    params_type = SonarCone

    def __init__(self, params: SonarCone, setup: Setup):
        super().__init__(params, setup)
        if params.rays < 1:
            raise ValueError(f"SonarCone.rays must be ≥ 1, got {params.rays}")
        self.offsets_rad = (np.linspace(-params.half_angle_rad, params.half_angle_rad,
                                        params.rays) if params.rays > 1 else np.zeros(1))
        self.max_incidence_rad = (params.max_incidence_rad
                                  if params.max_incidence_rad is not None
                                  else setup.model.max_incidence_rad)
        self._c, self._s = np.cos(self.offsets_rad), np.sin(self.offsets_rad)

    def directions(self, direction: np.ndarray) -> np.ndarray:
        """(..., R, 3) the beam axes (..., 3) turned about world z by each fan offset."""
        d = np.asarray(direction, dtype=float)[..., None, :]
        out = np.empty(d.shape[:-2] + (len(self.offsets_rad), 3))
        out[..., 0] = self._c * d[..., 0] - self._s * d[..., 1]
        out[..., 1] = self._s * d[..., 0] + self._c * d[..., 1]
        out[..., 2] = d[..., 2]
        return out

    def rays(self, f: Frame, cast: Callable | None) -> None:
        hits = effects.cast_from_emitters(f.truth, self.directions(f.truth.direction), cast,
                                          "the sonar cone casts a fan of rays")
        inc = np.asarray(hits.incidence_rad, dtype=float)
        d = np.asarray(hits.distance_m, dtype=float)
        f.d = np.where(inc > self.max_incidence_rad, np.nan, d)  # no specular echo back
        f.incidence = inc
        f.reflectance = np.asarray(hits.reflectance, dtype=float)

    def combine(self, f: Frame) -> np.ndarray:
        d = np.where(np.isnan(f.v), np.inf, f.d)
        k = np.argmin(d, axis=-1)[..., None]
        nearest = np.take_along_axis(f.v, k, axis=-1)[..., 0]
        if np.ndim(f.noise_scale) == np.ndim(f.d):
            f.noise_scale = np.take_along_axis(np.broadcast_to(f.noise_scale, f.d.shape), k,
                                               axis=-1)[..., 0]
        return np.where(np.isnan(nearest), self.setup.model.no_return_v, nearest)


def pipeline_for(scenario, cone: SonarCone | None = None) -> Pipeline:
    """The scenario's effects pipeline, with the sonar cone when its sensor is a sonar.

    A scene that also lists ``beam`` (a GP2 cone) keeps the sonar cone instead: a
    transducer has one beam.
    """
    base = Pipeline.from_scenario(scenario)
    if scenario.sensor.model != "sonar":
        return base

    if cone is None:
        cone = SonarCone(half_angle_rad=sensor_spec("sonar").beam_half_angle_rad)
    stages = tuple(s for s in base.stages if s.name != "beam")
    return Pipeline(base.setup, (SonarConeStage(cone, base.setup),) + stages)


assert "beam" in effects.STAGE_ORDER  # the slot SonarConeStage takes
