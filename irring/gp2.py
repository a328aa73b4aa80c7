"""Sensor kinds, their curves and the ADC: :data:`SENSORS` (the Sharp GP2 parts, sonar, laser)
and each kind's curve from ``models/sensors/<kind>.yaml`` (:func:`sensor`): paper Eq. 10,
``d = a·V^b`` (volts, metres) with a, b depending on the incidence θ. The model's fold-over
and no-return: docs/sensors.md.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import resources, safe_yaml
from .core import ADC_BITS, DESIGN_RANGE_M, MAX_RANGE_M, VREF_V, SensorSpec


@dataclass(frozen=True, eq=False)
class SensorModel:
    """One range sensor's output curve ``d = a(θ)·V^b(θ)`` (Eq. 10; d in m, V in volts)."""

    name: str
    min_range_m: float           # datasheet measuring range
    max_range_m: float
    peak_distance_m: float       # fold-over point; 0 for parts that do not fold
    theta_rad: np.ndarray        # (T,) table incidence angles, 0 first, increasing
    a: np.ndarray                # (T,) m·V^-b
    b: np.ndarray                # (T,)
    max_incidence_rad: float     # returns at steeper incidence drop out (`incidence` effect)
    part: str = ""
    source: str = ""             # file the numbers were read from

    def __post_init__(self) -> None:
        theta = np.asarray(self.theta_rad, dtype=float)
        a = np.asarray(self.a, dtype=float)
        b = np.asarray(self.b, dtype=float)
        where = f"sensor model {self.name!r}" + (f" ({self.source})" if self.source else "")
        if not (theta.ndim == a.ndim == b.ndim == 1 and theta.size == a.size == b.size >= 1):
            raise ValueError(f"{where}: theta, a and b must be 1-D tables of equal length")
        if not all(np.all(np.isfinite(v)) for v in (theta, a, b, self.min_range_m,
                                                       self.max_range_m, self.peak_distance_m,
                                                       self.max_incidence_rad)):
            raise ValueError(f"{where}: every number must be finite")
        if theta[0] != 0.0 or np.any(np.diff(theta) <= 0):
            raise ValueError(f"{where}: the table must start at θ = 0 and increase")
        if np.any(a <= 0) or np.any(b == 0):
            raise ValueError(f"{where}: need a > 0 and b ≠ 0 in d = a·V^b")
        if not 0.0 < self.min_range_m < self.max_range_m:
            raise ValueError(f"{where}: need 0 < min_range_m < max_range_m")
        if not 0.0 <= self.peak_distance_m <= self.min_range_m:
            raise ValueError(f"{where}: peak_distance_m must lie in 0 … min_range_m")
        for arr in (theta, a, b):
            arr.setflags(write=False)
        object.__setattr__(self, "theta_rad", theta)
        object.__setattr__(self, "a", a)
        object.__setattr__(self, "b", b)

    # ---- the curve

    @property
    def a0(self) -> float:
        return float(self.a[0])

    @property
    def b0(self) -> float:
        return float(self.b[0])

    def ab(self, theta_rad=0.0) -> tuple[np.ndarray, np.ndarray]:
        """a(θ), b(θ) interpolated over |θ| (rad); NaN θ gives NaN."""
        t = np.abs(theta_rad)
        return np.interp(t, self.theta_rad, self.a), np.interp(t, self.theta_rad, self.b)

    def voltage(self, d_m, theta_rad=0.0) -> np.ndarray:
        """Output (V) for distance d (m) at incidence θ (rad): Eq. 10 solved for V, far branch."""
        a, b = self.ab(theta_rad)
        return (np.asarray(d_m, dtype=float) / a) ** (1.0 / b)

    def distance(self, v, theta_rad=0.0) -> np.ndarray:
        """Distance (m) for output v (V) at incidence θ (rad): Eq. 10, far branch."""
        a, b = self.ab(theta_rad)
        return a * np.asarray(v, dtype=float) ** b

    @functools.cached_property
    def no_return_v(self) -> float:
        """Output with nothing in range: the curve's value at max_range_m (θ = 0)."""
        return float(self.voltage(self.max_range_m))

    @property
    def folds(self) -> bool:
        return self.peak_distance_m > 0.0

    def peak_v(self, theta_rad=0.0) -> np.ndarray:
        """The highest output (V), reached at peak_distance_m (NaN for parts that do not fold)."""
        if not self.folds:
            return np.full(np.shape(theta_rad), np.nan)[()]
        return self.voltage(self.peak_distance_m, theta_rad)

    def voltage_folded(self, d_m, theta_rad=0.0) -> np.ndarray:
        """Output (V) with fold-over: below the peak the near branch, else the far branch."""
        d = np.asarray(d_m, dtype=float)
        far = self.voltage(d, theta_rad)
        if not self.folds:
            return far
        near = self.peak_v(theta_rad) * (d / self.peak_distance_m)
        return np.where(d < self.peak_distance_m, near, far)

    def distances(self, v, theta_rad=0.0) -> tuple[np.ndarray, np.ndarray]:
        """Both distances (near, far) in m that give output v (V); NaN where none exists.

        For a folding part every v in (0, peak] has one distance on each side of the peak.
        """
        v = np.asarray(v, dtype=float)
        far = self.distance(v, theta_rad)
        if not self.folds:
            return np.full_like(far, np.nan), far
        vp = self.peak_v(theta_rad)
        ok = (v > 0) & (v <= vp)
        near = np.where(ok, self.peak_distance_m * v / vp, np.nan)
        return near, np.where(ok, far, np.nan)

    def ab_counts(self, theta_rad=0.0, bits: int = ADC_BITS, vref_v: float = VREF_V):
        """a_c(θ), b(θ) of ``d = a_c·S^b`` with S in ADC counts (S = V / LSB)."""
        a, b = self.ab(theta_rad)
        return a * lsb_v(bits, vref_v) ** b, b


# --------------------------------------------------------------------------- ADC


def lsb_v(bits: int, vref_v: float) -> float:
    """Volts per count: vref / 2^bits (MCP3202: code = 4096·V_in / V_ref)."""
    return vref_v / float(1 << bits)


def counts_from_voltage(v, bits: int = ADC_BITS, vref_v: float = VREF_V) -> np.ndarray:
    """ADC counts for v volts, float (not rounded), clipped to [0, 2^bits − 1].

    Rounding to whole counts is the ``quantization`` effect's job.
    """
    return np.clip(np.asarray(v, dtype=float) * (float(1 << bits) / vref_v), 0.0,
                   float((1 << bits) - 1))


def voltage_from_counts(counts, bits: int = ADC_BITS, vref_v: float = VREF_V) -> np.ndarray:
    """Volts for ADC counts (integer or float), clipped to [0, 2^bits − 1] counts first."""
    c = np.clip(np.asarray(counts, dtype=float), 0.0, float((1 << bits) - 1))
    return c * lsb_v(bits, vref_v)


# --------------------------------------------------------------------------- loading


def sensors_dir() -> Path:
    return resources.models_dir() / "sensors"


def available() -> tuple[str, ...]:
    """Names of the bundled sensor models."""
    return tuple(sorted(p.stem for p in sensors_dir().glob("*.yaml")))


def load_sensor(path: str | Path) -> SensorModel:
    """Read a sensor curve file (the format of ``models/sensors/*.yaml``)."""
    path = Path(path)
    raw = safe_yaml.load_file(path, "sensor curve file")
    try:
        table = raw["table"]
        return SensorModel(
            name=str(raw["name"]), part=str(raw.get("part", "")), source=str(path),
            min_range_m=float(raw["min_range_m"]), max_range_m=float(raw["max_range_m"]),
            peak_distance_m=float(raw["peak_distance_m"]),
            max_incidence_rad=float(np.radians(raw["max_incidence_deg"])),
            theta_rad=np.radians(np.asarray(table["theta_deg"], dtype=float)),
            a=np.asarray(table["a"], dtype=float), b=np.asarray(table["b"], dtype=float))
    except (KeyError, TypeError, ValueError) as exc:
        why = f"missing or bad {exc}" if isinstance(exc, KeyError) else str(exc)
        raise safe_yaml.InputError(f"{path}: not a sensor curve file ({why}); see "
                                   f"{sensors_dir() / 'README.md'} for the format") from None


@functools.lru_cache(maxsize=None)
def sensor(name: str) -> SensorModel:
    """A bundled sensor model by name ('gp2d12', 'gp2y0a21', 'gp2y0a02', 'sonar', 'laser')."""
    path = sensors_dir() / f"{name}.yaml"
    if not path.is_file():
        raise ValueError(f"unknown sensor model {name!r}; available: {', '.join(available())} "
                         f"(curve files live in {sensors_dir()})")
    return load_sensor(path)


# --------------------------------------------------------------------------- registry
# Every sensor kind a scenario or design may name: what it implies for a design (SensorSpec);
# its curve is models/sensors/<kind>.yaml (:func:`sensor`), whose range a design uses (the
# paper's GP2D12 excepted: the range its experiments trust and Table I's D, from core).


def _curve_range(kind: str) -> dict:
    rng = sensor(kind).max_range_m
    return {"max_range_m": rng, "design_range_m": rng}


SENSORS: dict[str, SensorSpec] = {
    "gp2d12": SensorSpec("gp2d12", max_range_m=MAX_RANGE_M, design_range_m=DESIGN_RANGE_M,
                         description="Sharp GP2D12; the paper's range limit and Table I's D"),
    "gp2y0a21": SensorSpec("gp2y0a21", **_curve_range("gp2y0a21"),
                           description="Sharp GP2Y0A21YK"),
    "gp2y0a02": SensorSpec("gp2y0a02", **_curve_range("gp2y0a02"),
                           description="Sharp GP2Y0A02YK0F"),
    # SICK LMS200-like (mm mode): σ ≈ 5 mm; its mirror turns at 75 Hz and 0.5° steps are
    # interlaced over two turns, so a 720-reading 360° view takes 2/75 s = 26.7 ms.
    "laser": SensorSpec("laser", **_curve_range("laser"),
                        noise_sigma_m=0.005, reading_period_s=(2.0 / 75.0) / 720,
                        adc_bits=16, settles=False, description="SICK LMS200-like scanner"),
    # MaxBotix LV-MaxSonar-EZ class (the `sonar` curve in models/sensors): one reading per
    # 49 ms (20 Hz); a ring chains its transducers one after another so they do
    # not hear each other. The ±15° cone is our assumption (12 of them close a 360° ring).
    "sonar": SensorSpec("sonar", **_curve_range("sonar"),
                        noise_sigma_m=0.01, beam_half_angle_rad=math.radians(15.0),
                        reading_period_s=0.049, sequential=True, adc_bits=16,
                        description="MaxBotix LV-EZ-class ultrasonic ranger, ±15° cone"),
}


def is_sensor_model(value) -> bool:
    """Whether ``value`` names a model of :data:`SENSORS`; False for anything but a string (a
    file may hold a list there, which is not hashable)."""
    return isinstance(value, str) and value in SENSORS


def sensor_spec(kind: str) -> SensorSpec:
    try:
        return SENSORS[kind]
    except KeyError:
        raise ValueError(f"unknown sensor kind {kind!r}; known: {', '.join(SENSORS)}") from None
