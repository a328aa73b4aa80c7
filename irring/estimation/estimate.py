"""Calibration and the paper's iterative range estimator (Park, Baek & Lee 2005, Table II).

How it works, its assumptions and measured figures: docs/estimator.md.
"""

from __future__ import annotations

import functools
import math
import operator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np
import yaml

from .. import gp2, safe_yaml
from ..core import HOUSING_M, Points, Reason, Ring, Sweep, beam_geometry
from ..errors import InputError, brief
from ..outputs import write_text_atomic
from ..resources import MissingKernel

try:
    from . import _iterate
except ImportError:  # a source tree never installed: the estimator fails when it is used
    _iterate = MissingKernel("estimation._iterate")
try:
    from . import _lines
except ImportError:
    _lines = MissingKernel("estimation._lines")

CALIBRATION_FORMAT = 1  # version written into calibration files
_SIGMA_FLOOR_M = 0.001  # no reading is trusted better than 1 mm
# Count σ above the no-return level: at or below NO_RETURN_SIGMAS a reading saw nothing (its
# beam frees the cells up to the max range); above RETURN_SIGMAS it is a return, with a
# one-sided Gaussian tail of 1e-4, so one reading in 10 000 that saw nothing passes for one
# (a T-room sweep has ~400 of them; at 2σ, 2.3 % did, each a valid point at the curve's far
# end, 100-300 mm in front of a wall beyond the range). Between, it is too weak to tell noise
# from a far, steep surface: OUT_OF_RANGE, neither mapped nor freed.
NO_RETURN_SIGMAS = 2.0
RETURN_SIGMAS = 3.72
_FINE_CELLS = 1 << 16  # cells of the fine (log a, b) table over 0 … 90°
_FALLBACK_NODES = 8   # quadrature nodes for the fallback σ (see _fallback_nodes)
_REGROUP_WINDOW = 8  # a third or later grouping only within the first 8 iterations
_MAX_GAIN = 8.0      # the held iteration's secant step at most 8× the plain one
_PINNED_RAD = math.radians(2.0)  # a line most readings meet within this of the drop-out angle
#                                  is a runaway, not a wall (see _drop_steep)


# --------------------------------------------------------------------------- calibration


class CalibrationError(InputError):
    """Calibration data that cannot determine a parameter, or a bad calibration file."""


def _frozen(a: Any, name: str) -> np.ndarray:
    arr = np.array(a, dtype=float).reshape(-1)
    if not np.all(np.isfinite(arr)):
        raise CalibrationError(f"{name}: every value must be finite, got {arr}")
    arr.setflags(write=False)
    return arr


def _table_end(theta: np.ndarray) -> float:
    """The drop-out angle a curve table implies by itself: its last row (a table of the
    θ = 0 row alone: just short of 90°)."""
    return float(theta[-1]) or math.pi / 2 - 1e-3


def _source_text(value: Any, fail) -> str:
    if not isinstance(value, str) or len(value) > 4096:
        raise fail("source", "expected a line of text (at most 4096 characters)")
    return value


@dataclass(frozen=True, eq=False)
class Calibration:
    """Everything the estimator needs to turn ADC counts into distances.

    ``d[m] = a(θ)·S^b(θ)`` (paper Eq. 10) with S in ADC counts of an ``adc_bits`` converter at
    ``vref_v``; ``a``, ``b`` tabulated at incidence angles ``theta_rad`` (ascending, the first
    0), interpolated linearly in (log a, b) over |θ| and held at the ends. ``emitter_offset_m``
    is d_o (paper Fig. 7, Eq. 9). The curve is trusted on [min_range_m, max_range_m].
    ``noise_counts`` is the 1-σ reading noise in counts (for ``Points.sigma_m``).
    ``max_incidence_rad``: returns steeper than this drop out (default: the table's end), so
    a line that would put a reading beyond it is not that reading's surface.
    ``peak_distance_m`` > 0: the sensor folds over below this distance (its output falls
    again, linearly to 0 at contact, as ``irring.gp2`` models it), so every reading may lie
    on either branch and the estimator resolves the branch (:func:`resolve_foldover`); 0:
    readings are trusted on the far branch down to ``min_range_m``.
    """

    sensor_model: str
    emitter_offset_m: float
    theta_rad: np.ndarray
    a: np.ndarray
    b: np.ndarray
    adc_bits: int = 12
    vref_v: float = 5.0
    min_range_m: float = 0.10
    max_range_m: float = 0.80
    noise_counts: float = 0.0
    source: str = ""
    max_incidence_rad: float | None = None
    peak_distance_m: float = 0.0

    def __post_init__(self) -> None:
        theta = _frozen(self.theta_rad, "theta")
        a = _frozen(self.a, "a")
        b = _frozen(self.b, "b")
        if not (theta.size == a.size == b.size) or theta.size == 0:
            raise CalibrationError(f"theta, a and b need the same non-zero length, got "
                                   f"{theta.size}, {a.size}, {b.size}")
        if abs(theta[0]) > 1e-12 or np.any(np.diff(theta) <= 0) or theta[-1] >= math.pi / 2:
            raise CalibrationError("theta must start at 0 and increase strictly below 90°, got "
                                   f"{np.degrees(theta).round(3).tolist()} deg")
        if np.any(a <= 0) or not (np.all(b < 0) or np.all(b > 0)):
            raise CalibrationError("Eq. 10 needs a > 0 and b of one sign at every θ (b < 0 for "
                                   "a Sharp GP2, whose output falls with distance); got "
                                   f"a={a.tolist()}, b={b.tolist()}")
        if not (0 < self.min_range_m < self.max_range_m) or not math.isfinite(self.max_range_m):
            raise CalibrationError(f"need 0 < min_range_m < max_range_m, got "
                                   f"{self.min_range_m}, {self.max_range_m}")
        if not (math.isfinite(self.emitter_offset_m) and abs(self.emitter_offset_m) < 0.1):
            raise CalibrationError(f"emitter_offset_m {self.emitter_offset_m!r} is not a "
                                   "plausible d_o (|d_o| < 0.1 m)")
        if not (math.isfinite(self.peak_distance_m)
                and 0.0 <= self.peak_distance_m < self.min_range_m):
            raise CalibrationError(f"peak_distance_m must lie in 0 … min_range_m "
                                   f"({self.min_range_m}), got {self.peak_distance_m!r}")
        if not (math.isfinite(self.noise_counts) and self.noise_counts >= 0):
            raise CalibrationError(f"noise_counts must be ≥ 0, got {self.noise_counts!r}")
        if self.max_incidence_rad is None:
            object.__setattr__(self, "max_incidence_rad", _table_end(theta))
        if not 0.0 < self.max_incidence_rad < math.pi / 2:
            raise CalibrationError(f"max_incidence must lie in (0°, 90°), got "
                                   f"{math.degrees(self.max_incidence_rad):g}°")
        object.__setattr__(self, "theta_rad", theta)
        object.__setattr__(self, "a", a)
        object.__setattr__(self, "b", b)
        object.__setattr__(self, "_log_a", np.log(a))

    # ---- what the estimator reads per sweep, built on its first sweep (a calibration that
    # is only fitted, saved or shown never needs them: the fine table takes ~3 ms)

    @functools.cached_property
    def _levels(self) -> tuple[float, float, float, float, bool]:
        """The count levels ``_iterate.classify`` judges readings by, and σ of a count."""
        return (self.full_scale_counts, self.near_counts, self.no_return_counts,
                self.sigma_counts(), self.falling)

    @functools.cached_property
    def _fine(self) -> tuple[float, np.ndarray, bool]:
        """(log a, b) on a fine θ grid for the estimator's loop, looked up at the nearest
        node (no search): θ off by ≤ 1.2e-5 rad, d by < 1e-4 relative. Returned with the
        grid's cells per radian and whether the kernels may recompute each row from the
        nodes (they give the table bit for bit: checked here for every row), sparing the
        cache the 1 MB table."""
        fine = np.linspace(0.0, math.pi / 2, _FINE_CELLS + 1)
        table = np.stack([np.interp(fine, self.theta_rad, self._log_a),
                          np.interp(fine, self.theta_rad, self.b)], axis=1)
        return (_FINE_CELLS / (math.pi / 2), table,
                _iterate.fine_table_is_interp(self.theta_rad, self._log_a, self.b, table))

    @functools.cached_property
    def _spread(self) -> tuple[np.ndarray, np.ndarray]:
        """log a, b at the fallback σ's quadrature nodes (see :func:`_fallback_nodes`)."""
        return _fallback_nodes(self)

    # ---- the curve

    @property
    def full_scale_counts(self) -> float:
        return float(2 ** self.adc_bits - 1)

    @property
    def max_theta_rad(self) -> float:
        return float(self.theta_rad[-1])

    def _log_ab(self, theta_rad: Any) -> tuple[np.ndarray, np.ndarray]:
        """log a(θ), b(θ) at |θ|: linear in (log a, b), held beyond the table."""
        t = np.abs(np.asarray(theta_rad, dtype=float))
        return np.interp(t, self.theta_rad, self._log_a), np.interp(t, self.theta_rad, self.b)

    def ab(self, theta_rad: Any) -> tuple[np.ndarray, np.ndarray]:
        """a(θ), b(θ) at |θ|: linear in (log a, b), held beyond the table."""
        log_a, b = self._log_ab(theta_rad)
        return np.exp(log_a), b

    def distance(self, counts: Any, theta_rad: Any = 0.0) -> np.ndarray:
        """Eq. 10: metres from counts (> 0) at incidence θ; vectorised."""
        s = np.asarray(counts, dtype=float)
        log_a, b = self._log_ab(theta_rad)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.exp(log_a + b * np.log(s))

    def counts(self, distance_m: Any, theta_rad: Any = 0.0) -> np.ndarray:
        """The inverse of Eq. 10: the counts a return at ``distance_m`` and θ gives."""
        d = np.asarray(distance_m, dtype=float)
        log_a, b = self._log_ab(theta_rad)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.exp((np.log(d) - log_a) / b)

    @property
    def falling(self) -> bool:
        """True for a Sharp GP2 (b < 0: more counts, nearer); False for linear hooks."""
        return bool(self.b[0] < 0)

    @property
    def no_return_counts(self) -> float:
        """Counts of a return at max_range_m square on (a GP2's output with nothing in
        range); readings within :attr:`no_return_margin_counts` of it, or beyond it, are no
        return."""
        return float(self.counts(self.max_range_m, 0.0))

    @property
    def no_return_margin_counts(self) -> float:
        """Up to this many counts past :attr:`no_return_counts` a reading is no return;
        ``NO_RETURN_SIGMAS`` count σ (the noise this calibration knows)."""
        return NO_RETURN_SIGMAS * self.sigma_counts()

    @property
    def return_margin_counts(self) -> float:
        """From this many counts past :attr:`no_return_counts` a reading is a return
        (``RETURN_SIGMAS`` count σ); between the two margins it is OUT_OF_RANGE."""
        return RETURN_SIGMAS * self.sigma_counts()

    @property
    def near_counts(self) -> float:
        """The near end of the calibrated curve (any θ): a GP2 reading brighter than this
        lies on the peak or its fold-over side, where one reading has two distances."""
        near = self.counts(self.min_range_m, self.theta_rad)
        return float(np.max(near) if self.falling else np.min(near))

    def sigma_counts(self) -> float:
        """1-σ count noise including quantisation (one count, uniform)."""
        return math.sqrt(self.noise_counts ** 2 + 1.0 / 12.0)

    @property
    def folds(self) -> bool:
        """Whether readings may lie on the fold-over (near) branch."""
        return self.peak_distance_m > 0.0 and self.falling

    def near_distance(self, counts: Any, theta_rad: Any = 0.0) -> np.ndarray:
        """The near-branch distance of ``counts`` at θ: the output rises linearly from 0 at
        contact to the far branch's value at ``peak_distance_m``."""
        peak = self.counts(self.peak_distance_m, theta_rad)
        return self.peak_distance_m * np.asarray(counts, dtype=float) / peak

    # ---- construction

    @classmethod
    def nominal(cls, sensor_model: str = "gp2d12", ring: Ring | None = None, adc_bits: int = 12,
                vref_v: float = 5.0, *, emitter_offset_m: float | None = None,
                noise_sigma_v: float = 0.015) -> Calibration:
        """The datasheet calibration from ``irring.gp2``'s tables, for an uncalibrated ring.

        ``d = a_V·V^b`` with V = k·S (k volts per count) becomes ``d = (a_V·k^b)·S^b``
        (:meth:`irring.gp2.SensorModel.ab_counts` at the table's rows below 90°).
        d_o comes from ``emitter_offset_m``, else the ring design's, else 7 mm.
        """
        model = gp2.sensor(sensor_model)
        theta = model.theta_rad[model.theta_rad < math.pi / 2]
        a, b = model.ab_counts(theta, adc_bits, vref_v)   # np.interp at its nodes: the rows
        if emitter_offset_m is None:
            emitter_offset_m = ring.emitter_offset_m if ring is not None else 0.007
        return cls(sensor_model=model.name, emitter_offset_m=float(emitter_offset_m),
                   theta_rad=theta, a=a, b=b, adc_bits=int(adc_bits), vref_v=float(vref_v),
                   min_range_m=float(model.min_range_m), max_range_m=float(model.max_range_m),
                   noise_counts=float(noise_sigma_v) / gp2.lsb_v(adc_bits, vref_v),
                   max_incidence_rad=min(model.max_incidence_rad, _table_end(theta)),
                   source=f"nominal {model.name} datasheet curve")

    @classmethod
    def for_scene(cls, scenario: Any) -> Calibration:
        """The calibration of what a simulated scene simulates (docs/calibration.md): the
        scene's sensor curve and ADC; a(θ), b(θ) and the drop-out angle only with the
        ``incidence`` effect (without it the readings do not depend on θ: the θ = 0 row
        alone, no drop-out); the ``noise`` effect's σ (0.1 mV floor without it); the fold-over
        peak only with the ``foldover`` effect."""
        model = gp2.sensor(scenario.sensor.model)
        sensor = scenario.sensor
        noise = scenario.effects.get("noise")
        cal = cls.nominal(model.name, scenario.ring, sensor.adc_bits, sensor.vref_v,
                          noise_sigma_v=max(noise.sigma_v if noise else 0.0, 1e-4))
        if "foldover" in scenario.effects and model.folds:
            cal = replace(cal, peak_distance_m=float(model.peak_distance_m))
        effects = ", ".join(scenario.effects) or "none"
        incidence = scenario.effects.get("incidence")
        if incidence is None:
            return replace(cal, theta_rad=cal.theta_rad[:1], a=cal.a[:1], b=cal.b[:1],
                           max_incidence_rad=None,
                           source=f"{model.name} curve as scene {scenario.name!r} simulates it "
                                  f"(effects: {effects}; no incidence: a, b independent of θ)")
        limit = incidence.max_incidence_rad
        return replace(cal, max_incidence_rad=min(
            model.max_incidence_rad if limit is None else limit, _table_end(cal.theta_rad)),
            source=f"{model.name} curve as scene {scenario.name!r} simulates it "
                   f"(effects: {effects})")

    @classmethod
    def for_sweep(cls, sweep: Sweep, **kwargs: Any) -> Calibration:
        """The nominal calibration matching a sweep's sensor model, ADC and ring."""
        return cls.nominal(sweep.sensor_model, sweep.ring, sweep.adc_bits, sweep.vref_v, **kwargs)

    # ---- files

    def to_dict(self) -> dict:
        return {
            "irring_calibration": CALIBRATION_FORMAT,
            "sensor_model": self.sensor_model,
            "source": self.source,
            "emitter_offset_mm": float(self.emitter_offset_m * 1e3),
            "adc_bits": int(self.adc_bits),
            "vref_v": float(self.vref_v),
            "min_range_mm": float(self.min_range_m * 1e3),
            "max_range_mm": float(self.max_range_m * 1e3),
            "noise_counts": float(self.noise_counts),
            "max_incidence_deg": round(math.degrees(self.max_incidence_rad), 9),
            "peak_distance_mm": float(self.peak_distance_m * 1e3),
            "curve": [{"theta_deg": round(math.degrees(t), 9), "a": float(a), "b": float(b)}
                      for t, a, b in zip(self.theta_rad, self.a, self.b)],
        }

    def to_yaml(self) -> str:
        """The calibration file's text (mm and degrees for people, d = a·S^b, S in counts)."""
        header = ("# irring calibration: d[m] = a(θ)·S^b(θ), S in ADC counts (paper Eq. 10);\n"
                  "# emitter offset d_o (paper Eq. 9) in mm; load with "
                  "irring.estimation.estimate.Calibration.load\n")
        return header + yaml.safe_dump(self.to_dict(), sort_keys=False, allow_unicode=True)

    def save(self, path: str | Path) -> Path:
        """Write :meth:`to_yaml` to a file."""
        return write_text_atomic(path, self.to_yaml())

    @classmethod
    def from_dict(cls, raw: Any, source: str = "<dict>") -> Calibration:
        def fail(key: str, msg: str) -> CalibrationError:
            return CalibrationError(f"{source}: {key}: {msg}")

        if not isinstance(raw, Mapping):
            raise fail("<top>", "a calibration file must be a mapping")
        known = {"irring_calibration", "sensor_model", "source", "emitter_offset_mm", "adc_bits",
                 "vref_v", "min_range_mm", "max_range_mm", "noise_counts", "curve",
                 "max_incidence_deg", "peak_distance_mm"}
        for key in raw:
            if key not in known:
                raise fail(str(key), f"unknown key; allowed: {', '.join(sorted(known))}")
        version = raw.get("irring_calibration")
        if version != CALIBRATION_FORMAT:
            raise fail("irring_calibration", f"expected format {CALIBRATION_FORMAT}, got "
                                             f"{version!r} (is this an irring calibration file?)")
        for key in ("sensor_model", "emitter_offset_mm", "curve"):
            if key not in raw:
                raise fail(key, "required key is missing")

        def number(key: str, default: float | None = None, lo: float = -math.inf,
                   hi: float = math.inf) -> float:
            value = raw.get(key, default)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise fail(key, f"expected a number, got {brief(value)}")
            if not (math.isfinite(value) and lo <= value <= hi):
                raise fail(key, f"{brief(value)} is out of range; allowed {lo:g} … {hi:g}")
            return float(value)

        model = raw["sensor_model"]
        if model not in gp2.SENSORS:
            raise fail("sensor_model", f"{brief(model)} is not a sensor model; choose one of: "
                                       f"{', '.join(gp2.SENSORS)}")

        curve = raw["curve"]
        if not isinstance(curve, list) or not curve:
            raise fail("curve", "expected a non-empty list of {theta_deg, a, b}")
        rows = []
        for i, row in enumerate(curve):
            if not isinstance(row, Mapping) or set(row) != {"theta_deg", "a", "b"}:
                raise fail(f"curve[{i}]", f"expected keys theta_deg, a, b; got {brief(row)}")
            values = [row["theta_deg"], row["a"], row["b"]]
            if not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       and math.isfinite(v) for v in values):
                raise fail(f"curve[{i}]", f"expected finite numbers, got {brief(row)}")
            rows.append([float(v) for v in values])
        table = np.array(rows)
        # a GP2's output falls with distance (b < 0); the linear laser/sonar curves rise
        falling = str(model).startswith("gp2")
        if np.any(table[:, 2] >= 0) if falling else np.any(table[:, 2] <= 0):
            raise fail("curve", f"a {model} curve d = a·S^b needs b "
                                f"{'< 0 (output falls with distance)' if falling else '> 0'} "
                                f"at every θ; got b = {brief(table[:, 2].tolist())}")
        bits = raw.get("adc_bits", 12)
        if isinstance(bits, bool) or not isinstance(bits, int) or not 1 <= bits <= 24:
            raise fail("adc_bits", f"expected a whole number 1 … 24, got {bits!r}")
        try:
            return cls(sensor_model=str(model),
                       emitter_offset_m=number("emitter_offset_mm", hi=100.0, lo=-100.0) * 1e-3,
                       theta_rad=np.radians(table[:, 0]), a=table[:, 1], b=table[:, 2],
                       adc_bits=bits, vref_v=number("vref_v", 5.0, 0.1, 50.0),
                       min_range_m=number("min_range_mm", 100.0, 0.0, 1e5) * 1e-3,
                       max_range_m=number("max_range_mm", 800.0, 0.0, 1e5) * 1e-3,
                       noise_counts=number("noise_counts", 0.0, 0.0, 1e7),
                       peak_distance_m=number("peak_distance_mm", 0.0, 0.0, 1e5) * 1e-3,
                       max_incidence_rad=(math.radians(number("max_incidence_deg"))
                                          if "max_incidence_deg" in raw else None),
                       source=_source_text(raw.get("source", ""), fail))
        except CalibrationError as exc:
            raise CalibrationError(f"{source}: {exc}") from None

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        path = Path(path)
        try:
            raw = safe_yaml.load_file(path, "calibration file")
        except safe_yaml.InputError as exc:
            raise CalibrationError(str(exc)) from None
        return cls.from_dict(raw, str(path))


# --------------------------------------------------------------------------- fitting


def emitter_offset_from_wall(distance_m: Any, sensor_angle_rad: Any,
                             wall_distance_m: Any) -> float:
    """d_o by paper Eq. 9 from readings against a flat wall facing the sensor.

    ``d_o = Σ(y_i·tan φ_i / cos φ_i − d_i·tan φ_i) / Σ tan² φ_i`` with d_i the measured
    distance, φ_i the beam's angle off the wall normal and y_i the wall's perpendicular
    distance from the hinge axis (arrays broadcast together; NaN readings are ignored).
    Raises :class:`CalibrationError` when Σ tan² φ ≈ 0: readings straight at the wall do not
    depend on d_o.
    """
    d, phi, y = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in
                                      (distance_m, sensor_angle_rad, wall_distance_m)))
    ok = np.isfinite(d) & np.isfinite(phi) & np.isfinite(y) & (np.abs(phi) < 1.5)
    tan = np.tan(phi[ok])
    den = float(np.sum(tan * tan))
    if ok.sum() == 0 or den < 1e-6 * max(int(ok.sum()), 1):
        raise CalibrationError(
            f"cannot determine the emitter offset d_o: Σ tan²φ = {den:.3g} over {int(ok.sum())} "
            "readings. Readings taken straight at the wall (φ ≈ 0) do not depend on d_o; sweep "
            "the sensor across angles on both sides of the wall normal (e.g. ±35 motor steps).")
    num = float(np.sum(y[ok] * tan / np.cos(phi[ok]) - d[ok] * tan))
    return num / den


def fit_curve(counts: Any, distance_m: Any, theta_rad: Any, theta_grid_rad: Any,
              *, min_readings: int = 6, smoothing: float = 1e-6
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """a(θ), b(θ) of Eq. 10 by least squares in log–log space.

    Model: ``log d = log a(θ) + b(θ)·log S`` with log a and b piecewise linear in |θ| over
    ``theta_grid_rad`` (the same interpolation :class:`Calibration` uses), so readings at
    any incidence count, and readings exactly at the grid angles reduce to one straight-line
    fit per angle. Grid angles with fewer than ``min_readings`` readings' worth of support are
    dropped (θ = 0 must stay). A tiny curvature penalty keeps sparse tables well posed.
    Returns (theta_rad, a, b) of the kept grid angles.
    """
    s, d, t = (np.asarray(v, dtype=float).reshape(-1) for v in (counts, distance_m, theta_rad))
    if not (s.size == d.size == t.size):
        raise CalibrationError("counts, distance_m and theta_rad need the same length")
    ok = np.isfinite(s) & np.isfinite(d) & np.isfinite(t) & (s > 0) & (d > 0)
    s, d, t = s[ok], d[ok], np.abs(t[ok])
    grid = np.asarray(theta_grid_rad, dtype=float).reshape(-1)
    if grid.size == 0 or grid[0] != 0.0 or np.any(np.diff(grid) <= 0):
        raise CalibrationError("theta grid must start at 0 and increase strictly")
    grid, t_sel = _supported_grid(grid, t, min_readings)
    s, d, t = s[t_sel], d[t_sel], t[t_sel]
    if s.size < 2 or np.ptp(np.log(s)) < 1e-6:
        raise CalibrationError(f"need readings at ≥ 2 different distances to fit a and b; got "
                               f"{s.size} usable readings")
    w = _hat_weights(t, grid)                       # (M, J)
    ls = np.log(s)
    design = np.hstack([w, w * ls[:, None]])         # unknowns: log a_j, b_j
    rhs = np.log(d)
    j = grid.size
    if j >= 3:  # second differences of log a and of b, scaled to the data's weight
        d2 = np.zeros((j - 2, j))
        idx = np.arange(j - 2)
        d2[idx, idx], d2[idx, idx + 1], d2[idx, idx + 2] = 1.0, -2.0, 1.0
        lam = math.sqrt(smoothing * s.size)
        reg = np.zeros((2 * (j - 2), 2 * j))
        reg[: j - 2, :j] = lam * d2
        reg[j - 2:, j:] = lam * d2 * float(np.mean(np.abs(ls)))
        design = np.vstack([design, reg])
        rhs = np.concatenate([rhs, np.zeros(2 * (j - 2))])
    sol, *_ = np.linalg.lstsq(design, rhs, rcond=None)
    log_a, b = sol[:j], sol[j:]
    if not np.all(np.isfinite(sol)) or not (np.all(b < 0) or np.all(b > 0)):
        raise CalibrationError(f"fitted b(θ) changes sign ({b.round(4)}); are the readings "
                               "and distances paired correctly?")
    return grid, np.exp(log_a), b


def _hat_weights(t: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """(M, J) linear-interpolation weights of |θ| over the grid, held at the ends."""
    tc = np.clip(t, grid[0], grid[-1])
    if grid.size == 1:
        return np.ones((t.size, 1))
    k = np.clip(np.searchsorted(grid, tc, side="right") - 1, 0, grid.size - 2)
    frac = (tc - grid[k]) / (grid[k + 1] - grid[k])
    w = np.zeros((t.size, grid.size))
    rows = np.arange(t.size)
    w[rows, k] = 1.0 - frac
    w[rows, k + 1] += frac
    return w


def _supported_grid(grid: np.ndarray, t: np.ndarray, min_readings: int
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Drop grid angles the data barely touch; keep readings inside the kept span."""
    while True:
        support = _hat_weights(t, grid).sum(axis=0)
        weak = support < min_readings
        if not weak.any():
            break
        if weak[0]:
            raise CalibrationError(
                f"too few readings near θ = 0 ({support[0]:.1f} < {min_readings}); the "
                "calibration needs readings with the beam square to the wall")
        worst = int(np.argmin(np.where(weak, support, np.inf)))
        grid = np.delete(grid, worst)
    return grid, t <= grid[-1] + 1e-9


# --------------------------------------------------------------------------- line grouping


@dataclass(frozen=True)
class LineOptions:
    """How end points are grouped into lines (step 4 of Table II)."""

    split_sigmas: float = 4.0      # split where a point lies this many σ off the chord …
    min_split_m: float = 0.010     # … and at least this far
    gap_m: float = 0.15            # consecutive readings farther apart start a new polyline …
    jump_sigmas: float = 3.5       # … as do a sensor's readings whose ranges jump (_chains)
    min_points: int = 3            # a line usable for θ has at least this many readings …
    min_length_m: float = 0.08     # … spanning at least this length
    max_rms_sigmas: float = 3.0    # … and fits them to within this RMS (in σ)
    regroup_iterations: int = 3    # group the readings into lines at most this often …
    regroup_until_rad: float = math.radians(1.0)  # … again once θ has settled to this
    adopt_margin_m: float = 0.05   # a reading on no line may join one this far past its ends
    corner_window: int = 4         # readings this close to a corner may change line …
    corner_sigmas: float = 0.5     # … if another line fits them this many σ better
    incidence_margin_rad: float = math.radians(5.0)  # a line meeting a beam this far past
    #                                                  the drop-out angle is not its surface


@dataclass(frozen=True)
class Lines:
    """Lines found in a sweep. ``label`` (S, N): line index of each reading or −1."""

    label: np.ndarray
    centroid: np.ndarray     # (L, 2) m, world
    normal: np.ndarray       # (L, 2) unit
    direction: np.ndarray    # (L, 2) unit, along the line
    n_points: np.ndarray     # (L,)
    length_m: np.ndarray     # (L,) extent of the readings along the line
    rms_m: np.ndarray        # (L,) RMS perpendicular residual
    usable: np.ndarray       # (L,) bool: good enough to give θ
    start: np.ndarray        # (L,) first/last index into the flat sensor-major scan order
    end: np.ndarray


def _scan_order(steps: np.ndarray, n_sensors: int) -> np.ndarray:
    """Flat indices into (S, N) arrays, sensor-major, each sensor's readings by step."""
    order = np.argsort(np.asarray(steps), kind="stable")
    return (order[None, :] * n_sensors + np.arange(n_sensors)[:, None]).reshape(-1)


@dataclass
class _Pieces:
    """The split-and-merge result over the usable points (indices into their compact order)
    and each piece's TLS line; ``owner`` (U,) is the piece each point joins."""

    starts: np.ndarray
    ends: np.ndarray
    brk: np.ndarray          # polyline starts the segmentation began from (for reuse)
    owner: np.ndarray
    cx: np.ndarray           # (L,) centroid, world
    cy: np.ndarray
    alpha: np.ndarray        # (L,) direction angle in [0, π)
    lmin: np.ndarray
    lmax: np.ndarray
    n_points: np.ndarray
    length_m: np.ndarray
    usable: np.ndarray


def _segment(px, py, thr, sensor, opts: LineOptions, centre, prev: _Pieces | None = None
             ) -> _Pieces:
    """Split-and-merge over ordered points (one sensor's readings by step form polylines,
    broken where consecutive readings are more than ``gap_m`` apart), corners refined, and
    each piece's TLS line: one call of the compiled kernel ``irring.estimation._lines.segment``.

    - split: iterative end-point fit (Douglas–Peucker) of every polyline: a piece splits at
      the reading farthest from its chord while that lies more than its threshold ``thr``
      off; the two pieces share that reading (their corner);
    - merge: adjacent pieces whose joint TLS line fits every reading within its threshold
      join, cheapest first, non-overlapping joins per round;
    - corners: each shared corner moves by up to 5 readings to where the two pieces' TLS
      lines fit best (2 rounds);
    - lines: each piece's TLS line from prefix sums of the moments centred on ``centre``;
      a corner reading joins the nearer of its two lines; a line is usable with
      ≥ ``min_points`` readings spanning ≥ ``min_length_m`` that it fits to within
      ``max_rms_sigmas`` of their mean σ.

    With ``prev`` from the same polylines (a regroup once θ has straightened the points)
    its pieces are kept and only their corners are refined: splitting anew would mostly
    repeat them, and the pieces of the first grouping are the better start (measured on the
    T-room: regrouping by corner refinement alone gives the smaller range error). Where a
    range jump now cuts some polylines (``_chains``), only those are split anew; the others
    keep ``prev``'s pieces.

    The kernel gives the numpy version's answers bit for bit (irring/estimation/_lines.pyx says how)
    in ~1/17 of its time: 0.77–0.85 → 0.044–0.064 ms per t_room sweep."""
    f = np.ascontiguousarray
    return _Pieces(*_lines.segment(
        f(px, dtype=float), f(py, dtype=float), f(thr, dtype=float), f(sensor, dtype=np.intp),
        opts.gap_m ** 2, float(centre[0]), float(centre[1]),
        *((None, None, None) if prev is None else (prev.starts, prev.ends, prev.brk)),
        opts.split_sigmas, opts.min_points, opts.min_length_m, opts.max_rms_sigmas))


def _chains(d: np.ndarray, sigma: np.ndarray, heading: np.ndarray, sensor: np.ndarray,
            reject_rad: float, sigmas: float) -> np.ndarray:
    """Polyline ids of readings in scan order: a new one at a sensor change or at a *range
    jump*, where consecutive readings of a sensor differ in range by more than one surface
    could make them (readings on one plane at incidence θ change range by d·tanθ per
    radian the beam turns; θ up to ``reject_rad``), plus ``sigmas`` times their noise.

    Such a jump is an occlusion edge (a box's corner in front of the wall behind it) or
    a convex corner seen across at the current θ (the faces' θ differ). Joined into one
    polyline (consecutive end points were within the 0.15 m gap), the wall's readings past
    a counter's corner were fitted with the counter's face: θ ~20° off, end points up to
    110 mm off with σ 7–16 mm (tests/test_estimate.py has that galley)."""
    k = d.size
    cut = np.ones(k, dtype=bool)
    if k > 1:
        turn = np.abs(heading[1:] - heading[:-1])
        turn = np.minimum(turn, 2.0 * math.pi - turn)
        allowed = np.maximum(d[1:], d[:-1]) * turn * math.tan(min(reject_rad, 1.5))
        allowed += sigmas * np.hypot(sigma[1:], sigma[:-1])
        np.greater(np.abs(d[1:] - d[:-1]), allowed, out=cut[1:])
        cut[1:] |= sensor[1:] != sensor[:-1]
    return np.cumsum(cut)


def _lines_record(pieces: _Pieces | None, label: np.ndarray, index: np.ndarray) -> Lines:
    """Public :class:`Lines` from pieces; ``index`` maps compact point order → flat (S, N)."""
    if pieces is None or pieces.starts.size == 0:
        z2, z1 = np.zeros((0, 2)), np.zeros(0)
        return Lines(label=label, centroid=z2, normal=z2, direction=z2,
                     n_points=np.zeros(0, int), length_m=z1, rms_m=z1,
                     usable=np.zeros(0, bool), start=np.zeros(0, int), end=np.zeros(0, int))
    a = pieces.alpha
    direction = np.stack([np.cos(a), np.sin(a)], axis=-1)
    return Lines(label=label, centroid=np.stack([pieces.cx, pieces.cy], axis=-1),
                 normal=np.stack([-direction[:, 1], direction[:, 0]], axis=-1),
                 direction=direction, n_points=pieces.n_points, length_m=pieces.length_m,
                 rms_m=np.sqrt(pieces.lmin), usable=pieces.usable.copy(),
                 start=index[pieces.starts], end=index[pieces.ends])


def fit_lines(x: np.ndarray, y: np.ndarray, ok: np.ndarray, sigma_m: np.ndarray,
              steps: np.ndarray | None = None, options: LineOptions = LineOptions()) -> Lines:
    """Group the end points of a sweep into lines (split-and-merge, see :func:`_segment`).

    ``x``, ``y``, ``ok``, ``sigma_m`` are (S, N); readings with ``ok`` False are skipped.
    Each sensor's readings, ordered by ``steps``, form polylines (broken where consecutive
    readings are more than ``gap_m`` apart); each polyline is split at the reading farthest
    from its chord while that exceeds max(min_split_m, split_sigmas·σ) (all polylines at
    once per round), then adjacent pieces whose joint TLS line still fits every reading within
    that threshold are merged. A corner reading shared by two pieces joins the line it is
    nearer to.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    shape = x.shape
    n_steps, n_sensors = shape
    if steps is None:
        steps = np.arange(n_steps)
    flat = _scan_order(steps, n_sensors)
    okf = np.asarray(ok, dtype=bool).reshape(-1)[flat]
    okf &= np.isfinite(x.reshape(-1)[flat]) & np.isfinite(y.reshape(-1)[flat])
    idx = flat[okf]
    label = np.full(n_steps * n_sensors, -1, dtype=int)
    if idx.size == 0:
        return _lines_record(None, label.reshape(shape), idx)
    px, py = x.reshape(-1)[idx], y.reshape(-1)[idx]
    thr = np.maximum(options.min_split_m, options.split_sigmas * np.nan_to_num(
        np.asarray(sigma_m, float).reshape(-1)[idx], nan=0.0, posinf=1.0))
    pieces = _segment(px, py, thr, idx % n_sensors, options, (float(px.mean()), float(py.mean())))
    label[idx] = pieces.owner
    return _lines_record(pieces, label.reshape(shape), idx)


# --------------------------------------------------------------------------- estimation


@dataclass(frozen=True)
class Estimate:
    """Points plus what the estimator saw (for plots, tests and benchmarks)."""

    points: Points
    lines: Lines | None
    theta_history: tuple[np.ndarray, ...] = field(default=())


def _classify(counts: np.ndarray, sweep: Sweep, cal: Calibration) -> np.ndarray:
    """Reasons decided by the counts alone (before any distance is computed; see
    ``_iterate.classify``), and MISSING for the steps the hardware never delivered."""
    full, near, no_return, _, falling = cal._levels
    reason = np.zeros(counts.shape, dtype=np.uint8)
    _iterate.classify(counts.reshape(-1), reason.reshape(-1), full, near, no_return,
                      cal.no_return_margin_counts, cal.return_margin_counts, falling)
    if sweep.missing_steps:
        rows = np.isin(np.asarray(sweep.steps), np.asarray(sweep.missing_steps))
        reason[rows, :] = Reason.MISSING
    return reason


def estimate(sweep: Sweep, calibration: Calibration | None = None, *, max_iterations: int = 20,
             tolerance_rad: float = math.radians(0.1), iterate: bool = True,
             lines: LineOptions = LineOptions(), keep_unconverged: bool = False) -> Points:
    """Counts → end points by the iterative estimation of Table II (see docs/estimator.md).

    ``calibration`` defaults to :meth:`Calibration.for_sweep` (the datasheet curve).
    ``iterate=False`` gives the θ = 0 assumption (Eq. 10 with a(0), b(0)).
    ``keep_unconverged``: readings still moving after ``max_iterations`` are valid at the θ
    they reached (the estimate after k iterations) instead of NOT_CONVERGED.
    """
    return _estimate(sweep, calibration, max_iterations, tolerance_rad, iterate, lines,
                     keep_history=False, damping=True, detail=False,
                     keep_unconverged=keep_unconverged).points


def estimate_detail(sweep: Sweep, calibration: Calibration | None = None, *,
                    max_iterations: int = 20, tolerance_rad: float = math.radians(0.1),
                    iterate: bool = True, lines: LineOptions = LineOptions(),
                    keep_history: bool = False, damping: bool = True,
                    keep_unconverged: bool = False) -> Estimate:
    """:func:`estimate` that also returns the final lines and (optionally) θ per iteration.

    ``damping=False`` switches the step control off: every step is the plain a ← G(a) of
    Table II (to show what the control is for).
    """
    return _estimate(sweep, calibration, max_iterations, tolerance_rad, iterate, lines,
                     keep_history=keep_history, damping=damping, detail=True,
                     keep_unconverged=keep_unconverged)


def _estimate(sweep: Sweep, calibration: Calibration | None, max_iterations: int,
              tolerance_rad: float, iterate: bool, lines: LineOptions, *, keep_history: bool,
              damping: bool, detail: bool, hold: np.ndarray | None = None,
              snap: bool = True, keep_unconverged: bool = False) -> Estimate:
    """The estimator: this function is the schedule of docs/estimator.md, its phases run
    as compiled kernels (:mod:`irring.estimation._iterate`). ``detail``: also the final lines.
    ``hold`` (S, N): readings kept out (FOLDOVER_AMBIGUOUS); None with a folding
    calibration: resolve the fold-over first (:func:`resolve_foldover`). ``snap``: line
    members' end points onto their lines (:func:`snap_to_lines`)."""
    cal = calibration if calibration is not None else _nominal_for(
        sweep.sensor_model, sweep.ring, sweep.adc_bits, sweep.vref_v)
    if hold is None and cal.folds and iterate:
        return resolve_foldover(lambda held, full, snap: _estimate(
            sweep, cal, max_iterations, tolerance_rad, iterate, lines, keep_history=keep_history,
            damping=damping, detail=full, hold=held, snap=snap,
            keep_unconverged=keep_unconverged), sweep, cal, detail)
    # the kernels take a C integer: a float would fail only once an iteration needs it
    max_iterations = operator.index(max_iterations)
    if max_iterations < 1:
        raise ValueError(f"max_iterations must be ≥ 1, got {max_iterations}")
    if not (math.isfinite(tolerance_rad) and tolerance_rad > 0):
        raise ValueError(f"tolerance_rad must be a finite angle > 0, got {tolerance_rad}")
    counts = np.ascontiguousarray(sweep.counts, dtype=float)
    if counts.ndim != 2:
        raise ValueError(f"sweep.counts must be (steps, sensors), got shape {counts.shape}")
    steps = np.asarray(sweep.steps)
    if steps.shape != counts.shape[:1]:
        # the scan order indexes the readings by step: more steps than rows would read and
        # write past the arrays, fewer would leave readings unestimated but marked OK
        raise ValueError(f"sweep.steps must have one entry per row of sweep.counts "
                         f"{counts.shape}, got shape {steps.shape}")
    angles = np.asarray(sweep.sensor_angles, dtype=float)
    pose = sweep.reading_poses if sweep.reading_poses is not None else sweep.pose
    origin, heading = beam_geometry(sweep.ring, np.asarray(pose, dtype=float), angles,
                                    cal.emitter_offset_m)
    if origin.shape != counts.shape + (2,):
        origin = np.broadcast_to(origin, counts.shape + (2,))
    if heading.shape != counts.shape:
        heading = np.broadcast_to(heading, counts.shape)
    shape = counts.shape

    reason = _classify(counts, sweep, cal)
    if hold is not None:
        reason[hold & (reason == Reason.OK)] = Reason.FOLDOVER_AMBIGUOUS
    max_range = min(float(sweep.max_range_m), cal.max_range_m)
    sw = _iterate.Sweep(cal, lines, counts.reshape(-1), np.ascontiguousarray(origin).reshape(-1),
                        np.ascontiguousarray(heading).reshape(-1), reason.reshape(-1),
                        _scan_order(steps, shape[1]), shape[1],
                        _SIGMA_FLOOR_M, _PINNED_RAD)
    k = sw.k
    scan_heading = np.ascontiguousarray(heading).reshape(-1).take(sw.index)
    theta = np.zeros(k)
    last_moving = np.full(k, -1, dtype=np.intp)  # last iteration in which each θ moved
    on_line = np.zeros(k, dtype=np.uint8)        # took θ from a line in the last plain step
    history = [np.zeros(shape)] if keep_history else []
    grouping: _iterate.Grouping | None = None
    held: _iterate.Held | None = None
    regroups = 0
    regroup_changed = True
    older = None          # the labels two groupings ago
    mode = "regroup"
    it = 0
    settled = False
    limit = max_iterations if iterate and k else 0
    while it < limit:
        checked = False
        if mode != "inner":
            # a membership pass: regroup (split-and-merge anew), or check the members
            checked = True
            if held is not None:
                held.put_theta(theta)
            # readings far outside the range cannot help a line (but stay for the final check)
            uidx = sw.place(theta, 1.5 * max_range)
            if mode == "regroup":
                chains = _chains(sw.d, sw.sigma, scan_heading, sw.sensor, sw.reject,
                                 lines.jump_sigmas)
                parts = (sw.px, sw.py, sw.thr, chains)
                if uidx is not None:
                    parts = tuple(v.take(uidx) for v in parts)
                before = None if grouping is None else grouping.label
                # the last grouping's pieces are refined where they are of the same
                # polylines; once θ moved readings across the usable range they are of
                # other points, and the segmentation splits afresh by itself
                pieces = _segment(*parts, lines, sw.centre,
                                  None if grouping is None else grouping.pieces)
                grouping = _iterate.Grouping(sw, pieces, uidx)
                changed = grouping.regroup(before)
                regroups += 1
                # regroup again only while that changes who belongs where, and not back to
                # the grouping before (readings at a corner flipping between two lines)
                regroup_changed = changed and not (
                    older is not None and _iterate.same(older, grouping.label))
                older = before
            else:  # the same members, refitted where they now are, checked again
                changed = grouping.check()
                if not changed and settled:
                    break      # the members stand and their lines did not move: done
            mode = "inner"
            if changed or held is None:  # a plain step from the new grouping
                moving = grouping.plain_step(theta, last_moving, on_line, it, tolerance_rad)
                it += 1
                if keep_history:
                    history.append(sw.scatter_theta(theta).reshape(shape))
                if not moving:
                    break
                held = _iterate.Held(sw, grouping, theta, damping, _MAX_GAIN)
                continue
            # unchanged: this iteration is an ordinary held step
        # held iterations until they settle, a regroup or a membership check is due
        if not (regroup_changed and regroups < lines.regroup_iterations):
            regroup_before = -1
        else:  # a third or later grouping only early on
            regroup_before = limit + 1 if regroups == 1 else _REGROUP_WINDOW
        status, it, last_settled, was_checked = held.run(
            it, limit, tolerance_rad, checked, last_moving, regroup_before,
            lines.regroup_until_rad, one_step=keep_history)  # a history records every step
        if last_settled is not None:
            settled = last_settled
        if status == _iterate.CHECK:
            mode = "member"      # some member left its line: redo this iteration as a check
            continue
        if keep_history:
            history.append(sw.scatter_theta(theta, held).reshape(shape))
        if status == _iterate.SETTLED:
            if regroups == 1 and regroups < lines.regroup_iterations:
                mode = "regroup"   # settled once: split-and-merge the straightened points again
            elif was_checked:
                break
            else:
                mode = "member"    # settled: a last look at who belongs where
        elif status == _iterate.REGROUP:
            mode = "regroup"       # θ has settled coarsely: group the straightened points again
    n_its = it
    if held is not None:
        held.put_theta(theta)

    # final points with the exact curve; fallback readings (no line): θ = 0, σ widened by
    # θ's unknown (see _fallback_nodes)
    x, y, d, theta_out, sigma, it_out, valid = sw.finish(
        theta, on_line, last_moving, n_its, iterate, cal, max_range, reason.reshape(-1),
        keep_unconverged)
    points = Points(
        x=x.reshape(shape), y=y.reshape(shape), d=d.reshape(shape),
        theta=theta_out.reshape(shape),
        origin_x=np.array(origin[..., 0]), origin_y=np.array(origin[..., 1]),
        heading=np.array(heading), sigma_m=sigma.reshape(shape),
        iterations=it_out.reshape(shape), valid=valid.reshape(shape), reason=reason,
        max_range_m=max_range)
    return _finish(points, grouping, on_line, sw.index, cal, snap, detail, history)


def _finish(points: Points, grouping, on_line, index: np.ndarray, cal: Calibration, snap: bool,
            detail: bool, history: list) -> Estimate:
    """The estimate from the final points and grouping (either estimator's): line members
    onto their lines (:func:`snap_to_lines`) and, with ``detail``, the :class:`Lines`."""
    if grouping is None:
        return Estimate(points=points, lines=None, theta_history=tuple(history))
    shape = points.valid.shape
    label = np.full(shape, -1, dtype=np.intp)  # the line each reading took θ from (−1: none)
    label.reshape(-1)[index] = np.where(on_line, grouping.label, -1)
    if snap:
        points = snap_to_lines(points, label, cal.min_range_m)
    pieces_out = replace(grouping.pieces, cx=grouping.cx, cy=grouping.cy,
                         alpha=grouping.alpha, usable=grouping.usable)
    used = index if grouping.uidx is None else index.take(grouping.uidx)
    found = _lines_record(pieces_out, label, used)
    points = replace(points, reach_m=no_return_reach(points, found, cal))
    return Estimate(points=points, lines=found if detail else None,
                    theta_history=tuple(history))


# --------------------------------------------------------------------------- silent beams

_REACH_MIN_MEMBERS = 5      # a line explains silent beams with at least this many members …
_REACH_CLEAR_M = 0.01       # … which stop this far (across the line) before meeting it


def no_return_reach(points: Points, lines: Lines, cal: Calibration) -> np.ndarray | None:
    """How far each NO_RETURN beam is known free (S, N; NaN: to the max range), from the
    sweep's lines.

    A GP2 returns nothing from a surface met past its drop-out angle, so a silent beam only
    says "no surface I could have seen": one grazing a box's face passes into the box, and
    a few such beams at full length mapped the inside of boxes free (free accuracy 0.980 in
    a held-out kitchen). A silent beam that meets a usable line (≥ 5 valid members; its
    members' extent plus 0.25 m, not past a corner: ``_clip_at_corners``) within its range
    at an incidence the sensor would drop out at (≥ the drop-out angle less
    ``LineOptions.incidence_margin_rad``) is explained by it: it is known free only to where
    it comes within 10 mm of that line. A line met at a smaller incidence is not what the
    beam saw (it would have returned), so it explains nothing."""
    nr = (points.reason == Reason.NO_RETURN).reshape(-1).nonzero()[0]
    if nr.size == 0 or lines is None or lines.usable.size == 0:
        return None
    lab = lines.label.reshape(-1)
    member = (lab >= 0) & points.valid.reshape(-1)
    n_mem = np.bincount(lab[member], minlength=lines.usable.size)
    use = (lines.usable & (n_mem >= _REACH_MIN_MEMBERS)).nonzero()[0]
    if use.size == 0:
        return None
    c, e, nrm = lines.centroid[use], lines.direction[use], lines.normal[use]
    col = np.full(lines.usable.size, -1)
    col[use] = np.arange(use.size)
    mcol = col[lab[member]]
    keep = mcol >= 0
    mcol = mcol[keep]
    mx, my = points.x.reshape(-1)[member][keep], points.y.reshape(-1)[member][keep]
    along = (mx - c[mcol, 0]) * e[mcol, 0] + (my - c[mcol, 1]) * e[mcol, 1]
    lo = np.full(use.size, np.inf)
    hi = np.full(use.size, -np.inf)
    np.minimum.at(lo, mcol, along)
    np.maximum.at(hi, mcol, along)
    lo_b, hi_b = _clip_at_corners(c, e, lo, hi)
    h = points.heading.reshape(-1)[nr]
    ux, uy = np.cos(h), np.sin(h)
    ox, oy = points.origin_x.reshape(-1)[nr], points.origin_y.reshape(-1)[nr]
    un = ux[:, None] * nrm[None, :, 0] + uy[:, None] * nrm[None, :, 1]          # (B, L)
    gap = ((c[None, :, 0] - ox[:, None]) * nrm[None, :, 0]
           + (c[None, :, 1] - oy[:, None]) * nrm[None, :, 1])               # emitter → line
    with np.errstate(divide="ignore", invalid="ignore"):
        t = gap / un
    cos_inc = np.abs(un)
    grazing = cos_inc <= math.cos(cal.max_incidence_rad - LineOptions.incidence_margin_rad)
    ok = grazing & (cos_inc > 1e-9) & np.isfinite(t) & (t > 0) & (t <= points.max_range_m)
    t = np.where(ok, t, 0.0)
    qa = ((ox[:, None] + t * ux[:, None] - c[None, :, 0]) * e[None, :, 0]
          + (oy[:, None] + t * uy[:, None] - c[None, :, 1]) * e[None, :, 1])
    ok &= (qa >= lo_b[None, :]) & (qa <= hi_b[None, :])
    # the beam stops where it comes within _REACH_CLEAR_M of the line
    stop = np.where(ok, t - _REACH_CLEAR_M / np.where(ok, cos_inc, 1.0), np.inf).min(axis=1)
    if not np.isfinite(stop).any():
        return None
    reach = np.full(points.valid.size, np.nan)
    reach[nr] = np.where(np.isfinite(stop), np.maximum(stop, 0.0), np.nan)
    return reach.reshape(points.valid.shape)


# --------------------------------------------------------------------------- end points on lines

_SNAP_SIGMAS = 3.0   # a member moves onto its line if that is within 3σ of its distance …
_SNAP_MIN = 10       # … and the line has at least 10 members (short lines are less sure)
_SNAP_OWN = 0.5      # share of a member's own σ kept in its σ on the line


def snap_to_lines(points: Points, member: np.ndarray, min_range_m: float) -> Points:
    """End points of the readings on a line put where their beams meet it.

    ``member`` (S, N): the line each reading took θ from (−1: none). Each line is fitted
    (total least squares) to its valid members' final end points; a member's end point
    moves along its beam to the line if that is within 3σ of its distance. The line
    averages the noise of all its members, so a wall seen at 13 mm RMS per reading comes
    out a few mm thick; a reading the line does not explain keeps its own distance, and
    none leaves [``min_range_m``, ``points.max_range_m``]. A moved reading's σ is the
    line's uncertainty where its beam meets it, with half its own σ added in quadrature."""
    on = (points.valid & (member >= 0)).reshape(-1).nonzero()[0]
    if on.size == 0:
        return points
    g = member.reshape(-1).take(on)              # line indices: small, so bincount directly
    x, y = points.x.reshape(-1).take(on), points.y.reshape(-1).take(on)
    n = np.bincount(g)
    keep = n >= _SNAP_MIN
    if not keep.any():
        return points
    nn = np.maximum(n, 1)
    mx, my = np.bincount(g, x) / nn, np.bincount(g, y) / nn
    u, v = x - mx.take(g), y - my.take(g)
    alpha = 0.5 * np.arctan2(2.0 * np.bincount(g, u * v), np.bincount(g, u * u)
                             - np.bincount(g, v * v))
    nx, ny = -np.sin(alpha), np.cos(alpha)
    along = u * np.cos(alpha).take(g) + v * np.sin(alpha).take(g)
    h = points.heading.reshape(-1).take(on)
    ch, sh = np.cos(h), np.sin(h)
    ngx, ngy = nx.take(g), ny.take(g)
    un = ch * ngx + sh * ngy
    ox, oy = points.origin_x.reshape(-1).take(on), points.origin_y.reshape(-1).take(on)
    # the line through the members' centroid: t along the beam to it (members offset by u, v)
    rel = u * ngx + v * ngy                      # each member's signed offset from its line
    d = points.d.reshape(-1).take(on)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = d - rel / un
    ok = (keep.take(g) & np.isfinite(t)
          & (np.abs(t - d) <= _SNAP_SIGMAS * points.sigma_m.reshape(-1).take(on))
          & (t >= min_range_m) & (t <= points.max_range_m))
    if not ok.any():
        return points
    # σ of a point on the line: the fitted line's own uncertainty where the beam meets it
    # (its offset, rms²/n, and its angle, growing with the distance s from the centroid:
    # rms²·s²/(n·var_along)), along the beam
    var_perp = np.bincount(g, rel * rel) / nn
    var_along = np.maximum(np.bincount(g, along * along) / nn, 1e-12)
    perp2 = var_perp.take(g) / nn.take(g) * (1.0 + along * along / var_along.take(g))
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma_line = np.sqrt(perp2) / np.abs(un)
    at, t = on[ok], t[ok]
    out = {f: np.array(getattr(points, f)) for f in ("x", "y", "d", "sigma_m")}
    # plus half the reading's own σ: the line is a model, a wall's end or a slightly
    # wrong θ moves a member off it (with none, 4 % of T-room members lie beyond 3σ)
    own = points.sigma_m.reshape(-1)[at]
    out["sigma_m"].reshape(-1)[at] = np.maximum(np.hypot(sigma_line[ok], _SNAP_OWN * own),
                                                _SIGMA_FLOOR_M)
    out["d"].reshape(-1)[at] = t
    out["x"].reshape(-1)[at] = ox[ok] + t * ch[ok]
    out["y"].reshape(-1)[at] = oy[ok] + t * sh[ok]
    return replace(points, **out)


# --------------------------------------------------------------------------- fold-over

_FOLD_BLOCK_M = 0.25   # a known wall blocks a beam this far past its readings' ends …
_FOLD_ON_M = 0.10      # … and a reading lies on it this far past them


def resolve_foldover(run: Callable[[np.ndarray, bool, bool], Estimate], sweep: Sweep,
                     cal: Calibration, detail: bool) -> Estimate:
    """Estimate a sweep of a folding sensor: every reading has a far-branch distance (Eq. 10)
    and a near one (:meth:`Calibration.near_distance`, below the peak); pick the branch
    from what the rest of the sweep says, or flag FOLDOVER_AMBIGUOUS.

    ``run(hold, detail, snap)`` is the estimator with the readings ``hold`` kept out. Three
    steps (docs/foldover.md has the geometry and the measured outcome):

    1. the whole sweep estimated on the far branch: walls give lines (a near wall's readings
       read far give a curve, which the lines of the neighbouring sensors contradict);
    2. each reading judged against those lines (:func:`_fold_branches`): far if its far end
       point lies on another sensor's line and no line blocks its beam before it, while its
       near end point lies on none; near if a line blocks the beam before the far end point
       and its near end point lies on a line; certainly far if its near end point would lie
       inside the ring's housing; else ambiguous;
    3. the sweep estimated again without the near and ambiguous readings; the near readings
       get their near distance at the incidence of the line they lie on.
    """
    # the judging pass reads each end point on its own (not snapped onto its line)
    first = run(np.zeros(np.shape(sweep.counts), dtype=bool), True, False)
    near, far, d_fold, theta_fold, sigma_fold = _fold_branches(first, sweep, cal)
    ambiguous = (d_fold == 0) & ~far
    ambiguous &= (first.points.reason == Reason.OK) | (first.points.reason == Reason.NOT_CONVERGED)
    second = run(near | ambiguous, True, True)
    p = second.points
    # near readings, and far ones the second pass found on no line (its neighbours held
    # out): the distance at the incidence of the line that decided their branch
    lost = p.valid & (second.lines.label < 0)
    put = near | (far & lost & (d_fold > 0))
    # … and far ones on a line in the first pass only: that pass's reading
    q = first.points
    keep = lost & ~put & q.valid & (first.lines.label >= 0)
    # a reading both passes read, differently: which lines it belongs to depended on how
    # its neighbours were read; it cannot be decided
    differ = (p.valid & q.valid & ~put & ~keep
              & (np.abs(p.d - q.d) > np.maximum(0.03, 3.0 * np.fmax(p.sigma_m, q.sigma_m))))
    if put.any() or keep.any() or differ.any():
        x, y, d, theta, sigma = (np.array(v) for v in (p.x, p.y, p.d, p.theta, p.sigma_m))
        d[put], theta[put], sigma[put] = d_fold[put], theta_fold[put], sigma_fold[put]
        x[put] = p.origin_x[put] + d_fold[put] * np.cos(p.heading[put])
        y[put] = p.origin_y[put] + d_fold[put] * np.sin(p.heading[put])
        for mine, theirs in ((x, q.x), (y, q.y), (d, q.d), (theta, q.theta), (sigma, q.sigma_m)):
            mine[keep] = theirs[keep]
        valid, reason, iterations = p.valid.copy(), p.reason.copy(), p.iterations.copy()
        valid[near], reason[near], iterations[near] = True, Reason.OK, 1
        valid[differ], reason[differ] = False, Reason.FOLDOVER_AMBIGUOUS
        for v in (x, y, d, theta, sigma):
            v[differ] = np.nan
        p = replace(p, x=x, y=y, d=d, theta=theta, sigma_m=sigma, valid=valid, reason=reason,
                    iterations=iterations)
    return replace(second, points=p, lines=second.lines if detail else None)


def _fold_branches(first: Estimate, sweep: Sweep, cal: Calibration):
    """(near, far, d, θ, σ), all (S, N), from the far-branch estimate ``first`` (see
    :func:`resolve_foldover`); vectorised over (readings, lines). ``far`` includes the
    readings whose near end point would lie inside the housing; d > 0 where a line decided
    the branch: the distance on that branch at that line's incidence (0 elsewhere)."""
    p, found = first.points, first.lines
    shape = p.valid.shape
    counts = np.asarray(sweep.counts, dtype=float)
    live = (p.reason == Reason.OK) | (p.reason == Reason.NOT_CONVERGED)
    ox, oy, h = p.origin_x, p.origin_y, p.heading
    pose = np.asarray(sweep.reading_poses if sweep.reading_poses is not None else sweep.pose,
                      dtype=float)
    # the farthest the near branch can put a reading (its peak counts are lowest at the
    # steepest θ): inside the housing even there, the reading is on the far branch
    rows = cal.theta_rad[cal.theta_rad <= cal.max_incidence_rad]
    far_near = cal.peak_distance_m * counts / float(np.min(cal.counts(cal.peak_distance_m, rows)))
    hx, hy = ox + far_near * np.cos(h), oy + far_near * np.sin(h)
    housing = np.hypot(hx - pose[..., 0], hy - pose[..., 1]) < sweep.ring.radius_m + HOUSING_M
    cand = live & ~housing
    if not cand.any():
        return np.zeros(shape, bool), housing & live, *(np.zeros(shape) for _ in range(3))
    idx = cand.reshape(-1).nonzero()[0]
    s = counts.reshape(-1)[idx]
    o = np.stack([ox.reshape(-1)[idx], oy.reshape(-1)[idx]], axis=1)       # (A, 2)
    u = np.stack([np.cos(h.reshape(-1)[idx]), np.sin(h.reshape(-1)[idx])], axis=1)
    own = found.label.reshape(-1)[idx] if found is not None else np.full(idx.size, -1)
    n_sensors = shape[1]
    sensor = idx % n_sensors
    # the lines with the extent of their valid members along them
    use = (np.zeros(0, dtype=int) if found is None else found.usable.nonzero()[0])
    lab = found.label.reshape(-1) if found is not None else np.zeros(0, int)
    member = (lab >= 0) & p.valid.reshape(-1)
    if use.size:
        c, e, nrm = found.centroid[use], found.direction[use], found.normal[use]
        col = np.full(found.usable.size, -1)
        col[use] = np.arange(use.size)
        mcol = col[lab[member]]
        keep = mcol >= 0
        mx, my = p.x.reshape(-1)[member][keep], p.y.reshape(-1)[member][keep]
        mcol = mcol[keep]
        along = (mx - c[mcol, 0]) * e[mcol, 0] + (my - c[mcol, 1]) * e[mcol, 1]
        lo = np.full(use.size, np.inf)
        hi = np.full(use.size, -np.inf)
        np.minimum.at(lo, mcol, along)
        np.maximum.at(hi, mcol, along)
        # a line one sensor alone saw may be a wrong-branch curve cut into pieces (or a few
        # readings at the peak, where both branches meet, with a poor direction): only lines
        # two sensors agree on judge other readings
        msensor = member.nonzero()[0][keep] % n_sensors
        pairs = np.unique(mcol * n_sensors + msensor)
        trusted = np.bincount(pairs // n_sensors, minlength=use.size) >= 2
        line_sensor = found.start[use] % n_sensors
    else:
        c = e = nrm = np.zeros((0, 2))
        lo = hi = np.zeros(0)
        trusted = np.zeros(0, bool)
        line_sensor = np.zeros(0, int)
    # a wall ends at a corner: a line's extension stops where it meets another trusted line
    # (past a box's corner its extension would cut the beams that graze the next face)
    lo_b, hi_b = _clip_at_corners(c, e, lo, hi)
    # every candidate's beam against every line: crossing distance t, incidence there
    un = u @ nrm.T                                                          # (A, L)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((c[None, :, 0] - o[:, None, 0]) * nrm[None, :, 0]
             + (c[None, :, 1] - o[:, None, 1]) * nrm[None, :, 1]) / un
    t = np.where(np.abs(un) > 1e-9, t, np.inf)
    ahead = np.isfinite(t) & (t > 0)
    t = np.where(ahead, t, 0.0)
    qx = o[:, None, 0] + t * u[:, None, 0] - c[None, :, 0]
    qy = o[:, None, 1] + t * u[:, None, 1] - c[None, :, 1]
    along = qx * e[None, :, 0] + qy * e[None, :, 1]
    # each reading's own line is where its far end point lies: it blocks nothing
    other = (use[None, :] != own[:, None]) & trusted[None, :]
    block_span = ahead & other & (along >= lo_b) & (along <= hi_b)
    on_span = ahead & other & (along >= lo - _FOLD_ON_M) & (along <= hi + _FOLD_ON_M)
    theta_l = np.arccos(np.clip(np.abs(un), 0.0, 1.0))
    seen = theta_l <= cal.max_incidence_rad
    sig_s = cal.sigma_counts() / s                                          # relative
    s2 = s[:, None]
    d_far = cal.distance(s2, theta_l)
    d_near = cal.near_distance(s2, theta_l)
    tol_far = np.maximum(0.02, 3.0 * np.abs(cal.ab(theta_l)[1]) * d_far * sig_s[:, None])
    tol_near = np.maximum(0.008, 3.0 * d_near * sig_s[:, None])
    # the shortest far distance the reading can mean (its θ unknown) and the nearest near one
    far_min = np.minimum(cal.distance(s, 0.0), cal.distance(s, cal.max_incidence_rad))
    near_min = cal.near_distance(s, 0.0)
    blocked_far = (block_span & (t < far_min[:, None] - tol_far)).any(axis=1)
    blocked_near = (block_span & (t < near_min[:, None] - tol_near)).any(axis=1)
    near_fit = np.where(on_span & seen, np.abs(t - d_near) / tol_near, np.inf)
    near_on = (near_fit <= 1.0).any(axis=1)
    far_fit = np.where(on_span & seen & (line_sensor[None, :] != sensor[:, None]),
                       np.abs(t - d_far) / tol_far, np.inf)
    is_near = blocked_far & near_on & ~blocked_near
    is_far = ~blocked_far & (far_fit <= 1.0).any(axis=1) & ~near_on
    near, far = np.zeros(shape, bool), housing & live
    near.reshape(-1)[idx] = is_near
    far.reshape(-1)[idx] = is_far
    out = [np.zeros(shape) for _ in range(3)]
    if use.size and (is_near | is_far).any():
        rows = np.arange(idx.size)
        pick_n = (rows, np.argmin(near_fit, axis=1))
        pick_f = (rows, np.argmin(far_fit, axis=1))
        dist = np.where(is_near, d_near[pick_n], np.where(is_far, d_far[pick_f], 0.0))
        theta = np.where(is_near, theta_l[pick_n], np.where(is_far, theta_l[pick_f], 0.0))
        slope = np.where(is_near, 1.0, np.abs(cal.ab(theta)[1]))     # |d ln d / d ln S|
        out[0].reshape(-1)[idx] = dist
        out[1].reshape(-1)[idx] = theta
        out[2].reshape(-1)[idx] = np.where(dist > 0, np.maximum(slope * dist * sig_s,
                                                                 _SIGMA_FLOOR_M), 0.0)
    return near, far, out[0], out[1], out[2]


def _clip_at_corners(c, e, lo, hi):
    """Each line's span extended by ``_FOLD_BLOCK_M`` either way, but not past the point where
    it meets another line's extended span (a corner, 10 mm beyond it)."""
    lo_b, hi_b = lo - _FOLD_BLOCK_M, hi + _FOLD_BLOCK_M
    if c.shape[0] < 2:
        return lo_b, hi_b
    # intersection of line i with line j, as a coordinate along i (a) and along j (b)
    den = e[:, None, 0] * e[None, :, 1] - e[:, None, 1] * e[None, :, 0]       # e_i × e_j
    dx = c[None, :, 0] - c[:, None, 0]
    dy = c[None, :, 1] - c[:, None, 1]
    ok = np.abs(den) > 0.1                    # lines meeting at < ~6° make no corner
    den = np.where(ok, den, 1.0)
    a = (dx * e[None, :, 1] - dy * e[None, :, 0]) / den
    b = (dx * e[:, None, 1] - dy * e[:, None, 0]) / den
    corner = (ok & (b >= lo_b[None, :]) & (b <= hi_b[None, :])
              & ~np.eye(c.shape[0], dtype=bool))
    high = corner & (a > hi[:, None]) & (a < hi_b[:, None])
    low = corner & (a < lo[:, None]) & (a > lo_b[:, None])
    hi_b = np.minimum(hi_b, np.where(high, a + 0.01, np.inf).min(axis=1))
    lo_b = np.maximum(lo_b, np.where(low, a - 0.01, -np.inf).max(axis=1))
    return lo_b, hi_b


@functools.lru_cache(maxsize=16)
def _nominal_for(sensor_model: str, ring: Ring | None, adc_bits: int, vref_v: float
                 ) -> Calibration:
    """:meth:`Calibration.for_sweep`'s calibration, built once per sensor/ring/ADC: its fine θ
    table (built on its first sweep) takes longer than estimating a sweep, and ``irring run``
    without a calibration file estimates every sweep with the default."""
    return Calibration.nominal(sensor_model, ring, adc_bits, vref_v)


def _fallback_nodes(cal: Calibration) -> tuple[np.ndarray, np.ndarray]:
    """log a(θ), b(θ) at the nodes of the fallback σ's quadrature.

    A reading on no line keeps θ = 0 (the paper's starting assumption, giving d0). Its θ is
    unknown, so its σ includes the RMS error of reading its counts S with θ = 0 when the true
    θ is that of a beam meeting a round surface at a uniformly random offset (sin θ uniform
    up to the drop-out angle; most such readings are thin obstacles), by 8-point quadrature:
    sqrt(mean_j (a(θ_j)·S^b(θ_j) − d0)²), summed by ``_iterate.Sweep.finish``. The θ = 0
    distance is the longest the reading can mean, so the error is one-sided and grows
    steeply with θ: at 0.4 m on the GP2D12 curve ≈ 37 mm."""
    u = (np.arange(_FALLBACK_NODES) + 0.5) / _FALLBACK_NODES * math.sin(cal.max_incidence_rad)
    return cal._log_ab(np.arcsin(u))
