"""From true ranges to the ADC counts the real ring would report, one effect per stage.

:meth:`Pipeline.from_scenario` builds a stage for each effect the scene lists and nothing
else (an effect that is off is not built, not called and draws no random numbers); stages
run in a fixed physical order, whatever order the scene lists them in. With no effects the
result is the ideal curve in float counts. The order and phases: docs/simulation.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar

import numpy as np

from .. import gp2
from ..core import ADC_BITS, SENSOR_MODEL, VREF_V, Truth
from ..scenario import (AveragingEffect, BeamEffect, FoldoverEffect, IncidenceEffect,
                       NoiseEffect, OutliersEffect, QuantizationEffect, ReflectanceEffect)

# The order stages run in (by their first phase); also the order of Pipeline.stages.
STAGE_ORDER = ("beam", "incidence", "reflectance", "foldover", "averaging", "outliers", "noise",
               "quantization")
PHASES = ("rays", "returns", "fold", "combine", "expand", "sample", "adc", "reduce")


@dataclass(frozen=True)
class Setup:
    """What every stage may need to know about the sensor and the ADC."""

    model: gp2.SensorModel
    adc_bits: int = ADC_BITS
    vref_v: float = VREF_V
    samples: int = 1              # scan.samples (used by `averaging` only)
    foldover: bool = False        # the scene folds readings below the peak
    quantized: bool = False       # the scene rounds to whole counts

    def reading_voltage(self, d_m, theta_rad=0.0) -> np.ndarray:
        """The voltage a return from d reads (folded if the scene folds)."""
        if self.foldover:
            return self.model.voltage_folded(d_m, theta_rad)
        return self.model.voltage(d_m, theta_rad)


@dataclass
class Frame:
    """Working arrays of one run. ``d`` etc. gain a trailing ray axis under ``beam``."""

    truth: Truth
    d: np.ndarray                 # (S, N[, R]) m; NaN: no return (dropped or nothing hit)
    incidence: np.ndarray         # (S, N[, R]) rad
    reflectance: np.ndarray       # (S, N[, R])
    theta: Any = 0.0              # θ the curve uses: 0 unless the incidence stage sets it
    v: np.ndarray | None = None   # voltage
    noise_scale: Any = 1.0        # multiplies the noise σ (reflectance stage)


class Stage:
    """One effect. ``name`` is its key under ``effects:``; ``params`` its scenario dataclass.

    A stage implements the phase methods it takes part in (see the module docstring):
    ``rays(frame, cast)``, ``returns(frame)``, ``fold(frame)``, ``combine(frame) -> v``,
    ``expand(v) -> v``, ``sample(v, frame, rng) -> v``, ``adc(counts) -> counts``,
    ``reduce(counts) -> counts``.
    """

    name: ClassVar[str] = ""
    params_type: ClassVar[type] = object

    def __init__(self, params: Any, setup: Setup):
        self.params = params
        self.setup = setup
        if not isinstance(params, self.params_type):
            raise TypeError(f"{type(self).__name__} needs {self.params_type.__name__} "
                            f"parameters, got {type(params).__name__}")

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.params!r})"


def cast_from_emitters(truth: Truth, directions: np.ndarray, cast: Callable | None, what: str):
    """RayHits of the rays ``directions`` (S, N, R, 3) from each reading's emitter, in one
    ``cast`` call (the ``rays`` phase of a stage that replaces the single ray by several).

    The origins go to ``cast`` as a read-only broadcast view: ``SimRing.cast`` copies them
    once as it flattens them. ``what`` starts the error raised when no ``cast`` was given.
    """
    if cast is None:
        raise ValueError(f"{what}: pass cast= to Pipeline.run (SimRing passes its batched ray "
                         f"caster SimRing.cast)")
    return cast(np.broadcast_to(truth.origin[..., None, :], directions.shape), directions)


# --------------------------------------------------------------------------- stages


class BeamStage(Stage):
    """A cone of ``rays`` rays with Gaussian weights (Webots' aperture / gaussianWidth).

    ``aperture_rad`` is the full cone angle. Ray directions fill the cone's disk on a
    Vogel (sunflower) spiral, so the pattern is fixed and even for any ray count; a ray at
    angle α off the axis weighs exp(−½ (α / (gaussian_width · aperture/2))²). A
    position-sensitive detector reports the centroid of the light it gets, so the reading
    is the mean of the rays' voltages weighted by aperture weight × reflectance / d²
    (rays that miss or drop out add no light). At an edge that mixes near and far surfaces,
    which is the "mixed reading" of a wide beam. Needs ``cast`` in :meth:`Pipeline.run`.
    """

    name = "beam"
    params_type = BeamEffect

    def __init__(self, params: BeamEffect, setup: Setup):
        super().__init__(params, setup)
        n = params.rays
        half = 0.5 * params.aperture_rad
        i = np.arange(n)
        self.off_axis_rad = half * np.sqrt((i + 0.5) / n)          # α_i
        self.around_rad = i * math.pi * (3.0 - math.sqrt(5.0))     # ψ_i, golden angle
        sigma = params.gaussian_width * half
        if sigma > 0:
            # shifted by the largest exponent (the ray nearest the axis weighs 1): a narrow
            # Gaussian that underflows at every ray keeps its ratios, not NaN weights
            z = -0.5 * (self.off_axis_rad / sigma) ** 2
            w = np.exp(z - z.max())
        else:
            w = np.ones(n)
        self.weights = w / w.sum()
        # ray = cos α · axis + sin α cos ψ · right + sin α sin ψ · up
        self._coeffs = np.stack([np.cos(self.off_axis_rad),
                                 np.sin(self.off_axis_rad) * np.cos(self.around_rad),
                                 np.sin(self.off_axis_rad) * np.sin(self.around_rad)], axis=-1)

    def directions(self, direction: np.ndarray) -> np.ndarray:
        """(..., R, 3) unit ray directions around the beam axes ``direction`` (..., 3)."""
        axis = np.asarray(direction, dtype=float)
        ax, ay, az = axis[..., 0], axis[..., 1], axis[..., 2]
        # right = axis × ẑ, normalised (np.cross is slow on small trailing axes)
        norm = np.hypot(ax, ay)
        flat = norm < 1e-9  # a vertical beam has no horizontal "right"; use x̂ there
        inv = 1.0 / np.where(flat, 1.0, norm)
        rx, ry = np.where(flat, 1.0, ay * inv), np.where(flat, 0.0, -ax * inv)
        basis = np.stack([axis,                                                 # (..., 3, 3)
                          np.stack([rx, ry, np.zeros_like(rx)], axis=-1),
                          np.stack([ry * az, -rx * az, rx * ay - ry * ax], axis=-1)],  # up
                         axis=-2)
        return self._coeffs @ basis  # (R, 3) @ (..., 3, 3) → (..., R, 3)

    def rays(self, f: Frame, cast: Callable | None) -> None:
        hits = cast_from_emitters(f.truth, self.directions(f.truth.direction), cast,
                                  "the beam effect casts extra rays")
        f.d = np.asarray(hits.distance_m, dtype=float)
        f.incidence = np.asarray(hits.incidence_rad, dtype=float)
        f.reflectance = np.asarray(hits.reflectance, dtype=float)

    def combine(self, f: Frame) -> np.ndarray:
        rho = np.where(np.isnan(f.reflectance), 1.0, f.reflectance)
        returned = ~np.isnan(f.v)
        light = np.where(returned, self.weights * rho / np.where(returned, f.d, 1.0) ** 2, 0.0)
        total = light.sum(axis=-1)
        v = (light * np.where(returned, f.v, 0.0)).sum(axis=-1) / np.where(total > 0, total, 1.0)
        if np.ndim(f.noise_scale) == np.ndim(f.d):  # reflectance gave a per-ray noise scale
            f.noise_scale = ((light * f.noise_scale).sum(axis=-1)
                             / np.where(total > 0, total, 1.0))
            f.noise_scale = np.where(total > 0, f.noise_scale, 1.0)
        return np.where(total > 0, v, self.setup.model.no_return_v)


class IncidenceStage(Stage):
    """The curve uses a(θ), b(θ) at the true incidence; past the limit the return drops out."""

    name = "incidence"
    params_type = IncidenceEffect

    def __init__(self, params: IncidenceEffect, setup: Setup):
        super().__init__(params, setup)
        self.max_incidence_rad = params.drop_out_rad(setup.model)

    def returns(self, f: Frame) -> None:
        f.theta = f.incidence
        f.d = np.where(np.abs(f.incidence) > self.max_incidence_rad, np.nan, f.d)


class ReflectanceStage(Stage):
    """Dark surfaces return less light: shorter reach, more noise.

    Signal s = ρ · (max_range / d)², i.e. 1 for a white surface (ρ = 1) at the sensor
    model's max range. Returns with s < ``min_signal`` drop out, so a surface of
    reflectance ρ is seen out to max_range·√(ρ / min_signal) (capped by the sensor's range;
    with min_signal 0.2, ρ = 0.1 reaches 0.57 m on a GP2D12). The reading itself does not
    move (triangulation, paper §III); the ``noise`` stage's σ grows as 1/√s where s < 1,
    like shot noise on a weak spot (no change for s ≥ 1; none at all without ``noise``).
    """

    name = "reflectance"
    params_type = ReflectanceEffect

    def returns(self, f: Frame) -> None:
        rho = np.where(np.isnan(f.reflectance), 1.0, f.reflectance)
        s = ReflectanceEffect.signal(rho, f.d, self.setup.model.max_range_m)
        weak = s < self.params.min_signal
        f.d = np.where(weak, np.nan, f.d)
        ok = ~weak & ~np.isnan(s)
        f.noise_scale = np.where(ok, 1.0 / np.sqrt(np.where(ok, np.minimum(s, 1.0), 1.0)), 1.0)


class FoldoverStage(Stage):
    """Below the peak distance the output falls again (near branch): one voltage, two ranges."""

    name = "foldover"
    params_type = FoldoverEffect

    def fold(self, f: Frame) -> None:
        m = self.setup.model
        if not m.folds:
            return  # a linear sonar/laser curve has no near branch (decided once per sweep)
        near = m.peak_v(f.theta) * (f.d / m.peak_distance_m)
        f.v = np.where(f.d < m.peak_distance_m, near, f.v)


class AveragingStage(Stage):
    """``scan.samples`` readings per step, each with its own outliers and noise, averaged.

    Each sample is quantised (if quantization is on) before the mean, as a firmware that
    sums ADC readings would; the mean is then rounded to whole counts again.
    """

    name = "averaging"
    params_type = AveragingEffect

    def expand(self, v: np.ndarray) -> np.ndarray:
        return np.broadcast_to(v, (self.setup.samples,) + np.shape(v))

    def reduce(self, counts: np.ndarray) -> np.ndarray:
        mean = counts.mean(axis=0)
        return np.rint(mean).astype(np.int64) if self.setup.quantized else mean


class OutliersStage(Stage):
    """Beam-model mixture (Thrun, Burgard & Fox, Probabilistic Robotics §6.3).

    Per reading (per sample under averaging), with the given rates (mutually exclusive):
    short: an unexpected nearer object, distance ~ exponential(λ) truncated to
    [0, true d] (to the max range when there is no return); random: distance uniform over
    the sensor's [min_range, max_range]; max: a failed reading, the no-return voltage.
    Short and random distances read as the scene's curve (θ = 0, folded if it folds).
    """

    name = "outliers"
    params_type = OutliersEffect

    def __init__(self, params: OutliersEffect, setup: Setup):
        super().__init__(params, setup)
        total = params.short_rate + params.random_rate + params.max_rate
        if total > 1.0:
            raise ValueError(f"effects.outliers: short_rate + random_rate + max_rate = "
                             f"{total:g} > 1; they are probabilities of exclusive cases")
        self.edges = np.cumsum([params.short_rate, params.random_rate, params.max_rate])

    def sample(self, v: np.ndarray, f: Frame, rng: np.random.Generator) -> np.ndarray:
        m = self.setup.model
        u = rng.random((3,) + np.shape(v))
        z = np.where(np.isnan(f.truth.distance_m), m.max_range_m, f.truth.distance_m)
        lam = self.params.short_lambda_per_m
        d_short = -np.log1p(-u[1] * -np.expm1(-lam * z)) / lam
        d_random = m.min_range_m + u[2] * (m.max_range_m - m.min_range_m)
        e0, e1, e2 = self.edges
        out = np.where(u[0] < e0, self.setup.reading_voltage(d_short), v)
        out = np.where((u[0] >= e0) & (u[0] < e1), self.setup.reading_voltage(d_random), out)
        return np.where((u[0] >= e1) & (u[0] < e2), m.no_return_v, out)


class NoiseStage(Stage):
    """Gaussian output noise of ``sigma_v`` volts rms, independent per reading and sample."""

    name = "noise"
    params_type = NoiseEffect

    def sample(self, v: np.ndarray, f: Frame, rng: np.random.Generator) -> np.ndarray:
        return v + (self.params.sigma_v * f.noise_scale) * rng.standard_normal(np.shape(v))


class QuantizationStage(Stage):
    """Round to whole ADC counts (``sensor.adc_bits``, LSB = vref / 2^bits), as integers."""

    name = "quantization"
    params_type = QuantizationEffect

    def adc(self, counts: np.ndarray) -> np.ndarray:
        return np.rint(counts).astype(np.int64)


STAGES: dict[str, type[Stage]] = {cls.name: cls for cls in (
    BeamStage, IncidenceStage, ReflectanceStage, FoldoverStage, AveragingStage, OutliersStage,
    NoiseStage, QuantizationStage)}


# --------------------------------------------------------------------------- pipeline


@dataclass
class Pipeline:
    """Truth → ADC counts through the stages a scene asked for, in physical order."""

    setup: Setup
    stages: tuple[Stage, ...] = ()
    _phases: dict = field(init=False, repr=False)

    def __post_init__(self) -> None:
        order = {name: i for i, name in enumerate(STAGE_ORDER)}
        self.stages = tuple(sorted(self.stages, key=lambda s: order[s.name]))
        names = [s.name for s in self.stages]
        if len(set(names)) != len(names):
            raise ValueError(f"a stage appears twice: {names}")
        # The work list of each phase, fixed now so a run does no per-effect checks.
        self._phases = {p: tuple(getattr(s, p) for s in self.stages if hasattr(s, p))
                        for p in PHASES}
        combine = self._phases["combine"]
        self._combine = combine[0] if combine else self._fill_no_return

    @classmethod
    def from_scenario(cls, scenario) -> Pipeline:
        """The stages ``scenario.effects`` lists (and only those), for its sensor and ADC."""
        effects = scenario.effects
        setup = Setup(model=gp2.sensor(scenario.sensor.model), adc_bits=scenario.sensor.adc_bits,
                      vref_v=scenario.sensor.vref_v, samples=scenario.scan.samples,
                      foldover="foldover" in effects, quantized="quantization" in effects)
        return cls(setup, tuple(STAGES[name](effects[name], setup)
                                for name in STAGE_ORDER if name in effects))

    @classmethod
    def ideal(cls, model: str | gp2.SensorModel = SENSOR_MODEL, adc_bits: int = ADC_BITS,
              vref_v: float = VREF_V) -> Pipeline:
        """No effects: the noise-free curve value in float counts."""
        m = gp2.sensor(model) if isinstance(model, str) else model
        return cls(Setup(model=m, adc_bits=adc_bits, vref_v=vref_v))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.stages)

    @property
    def model(self) -> gp2.SensorModel:
        return self.setup.model

    @property
    def samples(self) -> int:
        """Readings per step the hardware takes with this pipeline (for hardware time)."""
        return self.setup.samples if "averaging" in self.names else 1

    def _fill_no_return(self, f: Frame) -> np.ndarray:
        return np.where(np.isnan(f.v), self.setup.model.no_return_v, f.v)

    def run(self, truth: Truth, rng: np.random.Generator | None = None,
            cast: Callable | None = None) -> np.ndarray:
        """ADC counts (S, N) for a sweep's truth: float, or int64 with ``quantization``.

        ``rng`` feeds every random stage (it may be None when no stage draws); ``cast``
        (origins (..., 3), directions (..., 3)) → RayHits is needed by ``beam`` only.
        """
        ph = self._phases
        f = Frame(truth=truth, d=truth.distance_m, incidence=truth.incidence_rad,
                  reflectance=truth.reflectance)
        for step in ph["rays"]:
            step(f, cast)
        for step in ph["returns"]:
            step(f)
        f.v = self.setup.model.voltage(f.d, f.theta)
        for step in ph["fold"]:
            step(f)
        v = self._combine(f)
        for step in ph["expand"]:
            v = step(v)
        for step in ph["sample"]:
            v = step(v, f, rng)
        counts = gp2.counts_from_voltage(v, self.setup.adc_bits, self.setup.vref_v)
        for step in ph["adc"]:
            counts = step(counts)
        for step in ph["reduce"]:
            counts = step(counts)
        return counts
