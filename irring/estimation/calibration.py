"""Calibration: what the estimator needs to turn ADC counts into distances, in one home.

:class:`Calibration` (d_o and the curve a(θ), b(θ) of paper Eqs. 9–10) and its files; the
calibration of a simulated scene (:meth:`Calibration.for_scene`, :func:`scene_calibration`)
and of an uncalibrated ring (:meth:`Calibration.nominal`); the fits (:func:`fit_curve`,
:func:`emitter_offset_from_wall`); and the procedure that measures one, below.

How the procedure works and which calibration each command reads with: docs/calibration.md.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np
import yaml

from .. import gp2, safe_yaml
from ..core import (ADC_BITS, HOUSING_M, MAX_ADC_BITS, MAX_STEPS, MAX_SWEEPS, SENSOR_MODEL,
                    VREF_RANGE_V, VREF_V, Pose, Ring, Sweep, bounds)
from ..errors import InputError, TooBig, brief
from ..outputs import write_text_atomic
from ..resources import kernel

_iterate = kernel("estimation._iterate")

CALIBRATION_FORMAT = 1  # version written into calibration files
# rows of a curve table (`irring calibrate` fits ~19): one home for save and load, whose
# file of this many rows (≤ 90 bytes, 7 values each) fits safe_yaml's calibration limits
MAX_CURVE_ROWS = 10_000
# Count σ above the no-return level: at or below NO_RETURN_SIGMAS a reading saw nothing (its
# beam frees the cells up to the max range); above RETURN_SIGMAS it is a return, with a
# one-sided Gaussian tail of 1e-4, so one reading in 10 000 that saw nothing passes for one
# (a T-room sweep has ~400 of them; at 2σ, 2.3 % did, each a valid point at the curve's far
# end, 100-300 mm in front of a wall beyond the range). Between, it is too weak to tell noise
# from a far, steep surface: OUT_OF_RANGE, neither mapped nor freed.
NO_RETURN_SIGMAS = 2.0
RETURN_SIGMAS = 3.72
# A return read past the max range by at most RANGE_SIGMAS of its range σ may be a surface
# at the range limit that noise pushed out: it is fitted with its line, and kept if that
# line meets its beam within range (docs/estimator.md, "At the range limit"). Dropping it
# instead biased the lines of walls near the limit inward (the readings noise moved out
# were lost, those it moved in kept).
RANGE_SIGMAS = 2.0
_FINE_CELLS = 1 << 16  # cells of the fine (log a, b) table over 0 … 90°
FALLBACK_NODES = 8   # quadrature nodes for the fallback σ (see _fallback_nodes)
# the paper's sensor curve (models/sensors/gp2d12.yaml): a calibration's default range
_PAPER_CURVE = gp2.sensor(SENSOR_MODEL)

SIGMA_FLOOR_M = 0.001  # no reading is trusted better than 1 mm


def range_sigma(b, d, rel):
    """σ (m) of readings at range ``d`` on a curve of exponent ``b`` (Eq. 10: d ∝ S^b) whose
    counts S have relative noise ``rel`` = σ_S/S: |b|·d·σ_S/S, at least ``SIGMA_FLOOR_M``."""
    return np.maximum(np.abs(b) * d * rel, SIGMA_FLOOR_M)


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


def _reads_in_range(a: float, b: float, lo: float, hi: float, top: int) -> bool:
    """Whether some whole count n in 1 … ``top`` reads a·n^b within [lo, hi] (m), to 1e-9."""
    with np.errstate(over="ignore", under="ignore", divide="ignore", invalid="ignore"):
        # log n at the two ends of the range; n lies between them (either order)
        ends = (np.log([lo * (1 - 1e-9), hi * (1 + 1e-9)]) - math.log(a)) / b
        first, last = float(np.min(ends)), float(np.max(ends))
        if np.isnan(ends).any():
            return False
        n_lo = max(1.0, math.ceil(math.exp(min(first, 60.0))))
        n_hi = min(float(top), math.floor(math.exp(min(last, 60.0))))
        if n_hi - n_lo >= 2:
            return True
        # an end count of a narrow interval may be rounding (b = -1e300): read it directly
        near = np.clip([n_lo - 1, n_lo, n_hi, n_hi + 1], 1, top)
        d = a * np.power(near, b)
        return bool(np.any((d >= lo * (1 - 1e-9)) & (d <= hi * (1 + 1e-9))))


def _count_span_m(a: float, b: float, top: int) -> tuple[float, float]:
    """The distances (m, nearest first) the counts 1 and ``top`` read under a·n^b."""
    with np.errstate(over="ignore", under="ignore"):
        ends = a * np.power(np.array([1.0, float(top)]), b)
    return float(ends.min()), float(ends.max())


def _source_text(value: Any, fail) -> str:
    if not isinstance(value, str) or len(value) > 4096:
        raise fail("source", "expected a line of text (at most 4096 characters)")
    return value


def _is_format(value: Any, fmt: int) -> bool:
    """A file's format marker is exactly the whole number ``fmt`` (YAML's ``true`` and ``1.0``
    equal 1 in Python but mark no irring file)."""
    return type(value) is int and value == fmt

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
    adc_bits: int = ADC_BITS
    vref_v: float = VREF_V
    min_range_m: float = _PAPER_CURVE.min_range_m
    max_range_m: float = _PAPER_CURVE.max_range_m
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
        if theta.size > MAX_CURVE_ROWS:
            raise CalibrationError(f"curve: {theta.size:,} rows; a calibration holds at most "
                                   f"{MAX_CURVE_ROWS:,} (θ every 0.01° to 90° is 9,000)")
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
        # a > 0 and b of one sign are not enough: a = 1e300 or b = -1e-300 reads every count
        # as a distance outside the range, and nothing would be mapped, without a word
        top = 2 ** int(self.adc_bits) - 1
        for i, (t, a_i, b_i) in enumerate(zip(theta, a, b)):
            if t > self.max_incidence_rad + 1e-12:
                break   # past the drop-out angle no return is read with this row
            if not _reads_in_range(float(a_i), float(b_i), self.min_range_m,
                                   self.max_range_m, top):
                near, far = _count_span_m(float(a_i), float(b_i), top)
                raise CalibrationError(
                    f"curve[{i}] (θ = {math.degrees(t):g}°): a = {a_i:.6g}, b = {b_i:.6g} read "
                    f"the counts 1 … {top} of a {self.adc_bits}-bit ADC as {near:.3g} … "
                    f"{far:.3g} m, never within the {self.min_range_m:g} … "
                    f"{self.max_range_m:g} m range (min_range_mm … max_range_mm); allowed: a, "
                    f"b under which some count reads within it. No sensor reads so: "
                    f"calibrate it again")

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
    def _ab0(self) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`log_ab` at θ = 0, which the estimator asks every sweep."""
        return self.log_ab(0.0)

    @functools.cached_property
    def _ab_drop(self) -> tuple[float, float]:
        """:meth:`log_ab` at the drop-out angle (the silent beams beside a return ask it)."""
        log_a, b = self.log_ab(self.max_incidence_rad)
        return float(log_a), float(b)

    @functools.cached_property
    def _node_log_a(self) -> np.ndarray:
        """:meth:`log_ab`'s log a at the curve's own nodes (``_lines.profiles`` reads it)."""
        return self.log_ab(self.theta_rad)[0]

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

    def log_ab(self, theta_rad: Any) -> tuple[np.ndarray, np.ndarray]:
        """log a(θ), b(θ) at |θ|: linear in (log a, b), held beyond the table."""
        t = np.abs(np.asarray(theta_rad, dtype=float))
        return np.interp(t, self.theta_rad, self._log_a), np.interp(t, self.theta_rad, self.b)

    def ab(self, theta_rad: Any) -> tuple[np.ndarray, np.ndarray]:
        """a(θ), b(θ) at |θ|: linear in (log a, b), held beyond the table."""
        log_a, b = self.log_ab(theta_rad)
        return np.exp(log_a), b

    def distance(self, counts: Any, theta_rad: Any = 0.0) -> np.ndarray:
        """Eq. 10: metres from counts (> 0) at incidence θ; vectorised."""
        s = np.asarray(counts, dtype=float)
        # (θ = 0, the default and most callers' θ, from the cache: the same numbers)
        log_a, b = (self._ab0 if type(theta_rad) is float and theta_rad == 0.0
                    else self.log_ab(theta_rad))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.exp(log_a + b * np.log(s))

    def counts(self, distance_m: Any, theta_rad: Any = 0.0) -> np.ndarray:
        """The inverse of Eq. 10: the counts a return at ``distance_m`` and θ gives."""
        d = np.asarray(distance_m, dtype=float)
        log_a, b = self.log_ab(theta_rad)
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

    @functools.cached_property
    def return_range_m(self) -> float:
        """The farthest a surface square on gives a return at least as often as not (m):
        where its counts stand :attr:`return_margin_counts` above the no-return level, the
        level from which a reading is a return; at most ``max_range_m``. A curve ending at
        the noise floor (a GP2Y0A21 read to its 0.8 m with 15 mV: 0.687 m) reaches it short
        of the max range; linear hooks (laser, sonar): the max range."""
        if not self.falling:
            return self.max_range_m
        level = self.no_return_counts + self.return_margin_counts
        return float(min(self.max_range_m, self.distance(level, 0.0)))

    @functools.cached_property
    def silent_range_m(self) -> float:
        """How far a NO_RETURN reading rules out a surface (m): where a surface square on
        gives counts ``NO_RETURN_SIGMAS + RETURN_SIGMAS`` count σ above the no-return level,
        so it reads as no return with the 1e-4 tail ``RETURN_SIGMAS`` allows the other way;
        at most ``max_range_m``. A curve ending at the noise floor (a GP2Y0A21 read to its
        0.8 m) reaches it short of the max range; linear hooks (laser, sonar): the max range."""
        if not self.falling:
            return self.max_range_m
        told = self.no_return_counts + (NO_RETURN_SIGMAS + RETURN_SIGMAS) * self.sigma_counts()
        return float(min(self.max_range_m, self.distance(told, 0.0)))

    @property
    def near_counts(self) -> float:
        """The near end of the calibrated curve (any θ): a GP2 reading brighter than this
        lies on the peak or its fold-over side, where one reading has two distances."""
        near = self.counts(self.min_range_m, self.theta_rad)
        return float(np.max(near) if self.falling else np.min(near))

    def near_end_m(self) -> float:
        """The nearest distance a count short of full scale reads at an incidence up to the
        drop-out angle, and no nearer than the housing (``HOUSING_M``): where a curve that
        does not fold stops telling distances apart (nearer, every reading is SATURATED)."""
        rows = np.append(self.theta_rad[self.theta_rad <= self.max_incidence_rad],
                         self.max_incidence_rad)
        top = self.full_scale_counts - 0.5   # classify's SATURATED level
        return max(float(np.min(self.distance(top, rows))), HOUSING_M)

    @functools.cached_property
    def confirm_counts(self) -> float:
        """Readings brighter than this, the level of the sensor model's datasheet min range
        square on, are read below that range only where a neighbouring step confirms them
        (``silence.unconfirmed_near``): inf where the calibration reads nothing nearer
        than the datasheet's range (its own range, one that folds, a linear sensor)."""
        if not self.falling or self.folds or self.sensor_model not in gp2.available():
            return math.inf
        datasheet_m = gp2.sensor(self.sensor_model).min_range_m
        if self.min_range_m >= datasheet_m:
            return math.inf
        return float(np.max(self.counts(datasheet_m, self.theta_rad)))

    def sigma_counts(self) -> float:
        """1-σ count noise including quantisation (one count, uniform)."""
        return math.sqrt(self.noise_counts ** 2 + 1.0 / 12.0)

    @functools.cached_property
    def theta_free(self) -> bool:
        """Whether no incidence up to the drop-out angle changes a distance: a(θ), b(θ) the
        same on every row that reads (a scene without the ``incidence`` effect, the ideal
        sensor's)."""
        rows = self.theta_rad <= self.max_incidence_rad + 1e-12
        return bool(np.all(self.a[rows] == self.a[0]) and np.all(self.b[rows] == self.b[0]))

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
    def nominal(cls, sensor_model: str = SENSOR_MODEL, ring: Ring | None = None,
                adc_bits: int = ADC_BITS, vref_v: float = VREF_V, *, emitter_offset_m: float | None = None,
                noise_sigma_v: float = 0.015) -> Calibration:
        """The datasheet calibration from ``irring.gp2``'s tables, for an uncalibrated ring.

        ``d = a_V·V^b`` with V = k·S (k volts per count) becomes ``d = (a_V·k^b)·S^b``
        (:meth:`irring.gp2.SensorModel.ab_counts` at the table's rows below 90°).
        d_o comes from ``emitter_offset_m``, else the ring design's, else the paper ring's.
        """
        model = gp2.sensor(sensor_model)
        theta = model.theta_rad[model.theta_rad < math.pi / 2]
        a, b = model.ab_counts(theta, adc_bits, vref_v)   # np.interp at its nodes: the rows
        if emitter_offset_m is None:
            emitter_offset_m = (ring or Ring()).emitter_offset_m
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
        peak only with the ``foldover`` effect. A GP2 curve the scene does not fold is read
        below the datasheet's min range, down to :meth:`near_end_m` (one distance per count)."""
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
            cal = replace(cal, theta_rad=cal.theta_rad[:1], a=cal.a[:1], b=cal.b[:1],
                          max_incidence_rad=None,
                          source=f"{model.name} curve as scene {scenario.name!r} simulates it "
                                 f"(effects: {effects}; no incidence: a, b independent of θ)")
        else:
            cal = replace(cal, max_incidence_rad=min(incidence.drop_out_rad(model),
                                                     _table_end(cal.theta_rad)),
                          source=f"{model.name} curve as scene {scenario.name!r} simulates it "
                                 f"(effects: {effects})")
        if cal.falling and not cal.folds:
            # the simulated curve goes on below the datasheet's range without folding: a
            # reading brighter than its near end has one distance (docs/calibration.md)
            cal = replace(cal, min_range_m=min(cal.min_range_m, cal.near_end_m()))
        return cal

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
                  "irring.estimation.calibration.Calibration.load\n")
        data = self.to_dict()
        rows = [yaml.safe_dump(row, default_flow_style=True, width=math.inf,
                               sort_keys=False).strip() for row in data.pop("curve")]
        # the table last and in one [...]: a file cut short anywhere is not YAML (cut in
        # block style, between rows or inside a number, it loaded with fewer rows or a b
        # of -1 for -1.175, and mapped unwarned)
        return (header + yaml.safe_dump(data, sort_keys=False, allow_unicode=True)
                + "curve: [\n" + ",\n".join(f"  {row}" for row in rows) + "]\n")

    def save(self, path: str | Path) -> Path:
        """Write :meth:`to_yaml` to a file."""
        return write_text_atomic(path, self.to_yaml(), "calibration file")

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
        if not _is_format(version, CALIBRATION_FORMAT):
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
        if not gp2.is_sensor_model(model):
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
            if not 0 <= row["theta_deg"] < 90:   # (1e308° overflowed back to degrees: inf)
                raise fail(f"curve[{i}].theta_deg", f"{brief(row['theta_deg'])} is out of "
                                                    "range; allowed 0 … 90 (below 90)")
            rows.append([float(v) for v in values])
        table = np.array(rows)
        # a GP2's output falls with distance (b < 0); the linear laser/sonar curves rise
        falling = str(model).startswith("gp2")
        if np.any(table[:, 2] >= 0) if falling else np.any(table[:, 2] <= 0):
            raise fail("curve", f"a {model} curve d = a·S^b needs b "
                                f"{'< 0 (output falls with distance)' if falling else '> 0'} "
                                f"at every θ; got b = {brief(table[:, 2].tolist())}")
        bits = raw.get("adc_bits", ADC_BITS)
        curve = gp2.sensor(str(model))   # a file without its range trusts its curve's
        curve_mm = (curve.min_range_m * 1e3, curve.max_range_m * 1e3)
        if isinstance(bits, bool) or not isinstance(bits, int) or \
                not 1 <= bits <= MAX_ADC_BITS:
            raise fail("adc_bits", f"expected a whole number 1 … {MAX_ADC_BITS}, got {bits!r}")
        # each key checked (its error names the file) before the cross-key checks of
        # __post_init__, whose errors do not: named once, not twice
        values = dict(sensor_model=str(model),
                      emitter_offset_m=number("emitter_offset_mm", hi=100.0, lo=-100.0) * 1e-3,
                      theta_rad=np.radians(table[:, 0]), a=table[:, 1], b=table[:, 2],
                      adc_bits=bits, vref_v=number("vref_v", VREF_V, *VREF_RANGE_V),
                      min_range_m=number("min_range_mm", curve_mm[0], 0.0, 1e5) * 1e-3,
                      max_range_m=number("max_range_mm", curve_mm[1], 0.0, 1e5) * 1e-3,
                      noise_counts=number("noise_counts", 0.0, 0.0, 1e7),
                      peak_distance_m=number("peak_distance_mm", 0.0, 0.0, 1e5) * 1e-3,
                      max_incidence_rad=(math.radians(number("max_incidence_deg"))
                                         if "max_incidence_deg" in raw else None),
                      source=_source_text(raw.get("source", ""), fail))
        try:
            return cls(**values)
        except CalibrationError as exc:
            raise CalibrationError(f"{source}: {exc}") from None

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        """A calibration file (:meth:`save`, ``irring calibrate``); :class:`CalibrationError`
        naming the file when it cannot be read or is not a calibration."""
        return load_calibration(Path(path))[0]


def fallback_thetas(cal: Calibration) -> np.ndarray:
    """θ (rad) at the ``FALLBACK_NODES`` nodes of the fallback σ's quadrature.

    A reading on no line keeps θ = 0 (the paper's starting assumption, giving d0). Its θ is
    unknown, so its σ includes the RMS error of reading its counts S with θ = 0 when the true
    θ is that of a beam meeting a round surface at a uniformly random offset (sin θ uniform
    up to the drop-out angle; most such readings are thin obstacles): sqrt(mean_j
    (a(θ_j)·S^b(θ_j) − d0)²) over these nodes. The θ = 0 distance is the longest the reading
    can mean, so the error is one-sided and grows steeply with θ: at 0.4 m on the GP2D12
    curve ≈ 37 mm."""
    u = (np.arange(FALLBACK_NODES) + 0.5) / FALLBACK_NODES * math.sin(cal.max_incidence_rad)
    return np.arcsin(u)


def _fallback_nodes(cal: Calibration) -> tuple[np.ndarray, np.ndarray]:
    """log a(θ), b(θ) at :func:`fallback_thetas` (the quadrature ``_iterate.Sweep.finish``
    sums)."""
    return cal.log_ab(fallback_thetas(cal))


def load_calibration(path_or_text: str | Path | None, *, is_text: bool = False,
                     source: str = "<recording's calibration>"
                     ) -> tuple[Calibration | None, str | None]:
    """(Calibration or None, YAML text or None) from a file path or from stored YAML text
    (``source`` names it in errors)."""
    if path_or_text is None:
        return None, None
    if is_text:
        text = str(path_or_text)
    else:
        source = str(path_or_text)
        try:
            text = safe_yaml.read_text(path_or_text, "calibration file")
        except safe_yaml.InputError as exc:
            raise CalibrationError(str(exc)) from None
    try:
        raw = safe_yaml.load(text, source, "calibration file")
    except safe_yaml.InputError as exc:
        raise CalibrationError(str(exc)) from None
    return Calibration.from_dict(raw, source), text


def scene_calibration(scenario: Any) -> tuple[Calibration, str]:
    """(Calibration, YAML text) the estimator reads a simulated scene with: the one path
    for ``run``, ``compare``, ``bench`` and ``replay`` (docs/calibration.md)."""
    cal = Calibration.for_scene(scenario)
    return cal, cal.to_yaml()


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
    A row past 60° whose b comes out of the other sign than θ = 0's (few, noisy readings)
    ends the table before it; a flip nearer square on raises :class:`CalibrationError`.
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
    while True:
        log_a, b = _fit_rows(s, d, t, grid, smoothing)
        flipped = np.flatnonzero(np.sign(b) != np.sign(b[0]))
        if flipped.size == 0:
            return grid, np.exp(log_a), b
        if grid[flipped[0]] < _TRIMMABLE_RAD:
            raise CalibrationError(f"fitted b(θ) changes sign ({b.round(4)}); are the readings "
                                   "and distances paired correctly?")
        # rows past 60° rest on few, noisy readings (one sweep a placement): a b of the
        # other sign reads no surface at all there, so the table ends before them (held
        # beyond); a flip nearer square on means readings that are not of the wall
        grid = grid[:flipped[0]]
        inside = t <= grid[-1] + 1e-9
        s, d, t = s[inside], d[inside], t[inside]


def _fit_rows(s: np.ndarray, d: np.ndarray, t: np.ndarray, grid: np.ndarray,
              smoothing: float) -> tuple[np.ndarray, np.ndarray]:
    """log a and b at each grid angle: :func:`fit_curve`'s least squares."""
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
    if not np.all(np.isfinite(sol)):
        raise CalibrationError("the fit of a(θ), b(θ) did not converge; are the readings and "
                               "distances paired correctly?")
    return sol[:j], sol[j:]


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


# --------------------------------------------------------------------------- the procedure

DEFAULT_THETA_GRID_RAD = np.radians(np.arange(0.0, 86.0, 5.0))
_TRIMMABLE_RAD = math.radians(60.0)   # fit_curve may end the table before a steeper row
_ROUNDS = 3


def wall_reading_m(wall_distance_m, beam_angle_rad, emitter_offset_m: float):
    """Eq. 5 with the beam angle h off the wall normal: the distance a beam travels to a wall
    ``wall_distance_m`` from its hinge axis, d = y / cos h − d_o·tan h (m; arrays broadcast)."""
    h = np.asarray(beam_angle_rad, dtype=float)
    return wall_distance_m / np.cos(h) - emitter_offset_m * np.tan(h)


@dataclass(frozen=True)
class Placement:
    """Where the wall goes: ``wall_distance_m`` perpendicular from the sensor's hinge axis,
    ``yaw_rad`` between the sensor's radial direction and the wall normal."""

    wall_distance_m: float
    yaw_rad: float = 0.0
    purpose: str = "curve"   # "offset" (Eq. 9) or "curve" (Eq. 10); both feed both fits

    def describe(self, sensor: int = 0) -> str:
        turn = (f"turned so sensor {sensor} faces {math.degrees(self.yaw_rad):.0f}° off the "
                "wall's normal (counter-clockwise seen from above)"
                if abs(self.yaw_rad) > 1e-9 else f"square to sensor {sensor}'s radial direction")
        return (f"a flat, white wall {self.wall_distance_m * 1e3:.0f} mm from sensor {sensor}'s "
                f"rotation axis, {turn}")


def default_placements(min_range_m: float = _PAPER_CURVE.min_range_m,
                       max_range_m: float = _PAPER_CURVE.max_range_m,
                       yaws_deg: Sequence[float] = (0.0, 25.0, 50.0), distances: int = 8,
                       offset_distances_m: Sequence[float] = (0.15, 0.20, 0.25, 0.30)
                       ) -> list[Placement]:
    """Offset placements (ψ = 0) then curve placements: for each ψ, central-beam distances
    spread over [min, max] range (y = d·cos ψ)."""
    out = [Placement(y, 0.0, "offset") for y in offset_distances_m
           if min_range_m <= y <= max_range_m]
    d = np.linspace(min_range_m * 1.1, max_range_m * 0.95, distances)
    for yaw in np.radians(yaws_deg):
        out += [Placement(float(di * math.cos(yaw)), float(yaw), "curve") for di in d]
    return out


@dataclass(frozen=True)
class RigReadings:
    """Averaged readings of one sensor, one row per (placement, step): counts, the beam
    angle off the wall normal h (rad), the wall's perpendicular distance y (m), the spread of
    the repeated readings (counts) and how many there were."""

    counts: np.ndarray
    beam_angle_rad: np.ndarray
    wall_distance_m: np.ndarray
    spread_counts: np.ndarray
    repeats: np.ndarray
    offset: np.ndarray   # bool: from an offset placement

    @classmethod
    def concat(cls, parts: Iterable[RigReadings]) -> RigReadings:
        parts = list(parts)
        if not parts:
            raise CalibrationError("no readings were taken")
        return cls(*(np.concatenate([getattr(p, f.name) for p in parts])
                     for f in dataclasses.fields(cls)))

    def true_distance(self, emitter_offset_m: float) -> np.ndarray:
        """The distance each reading's beam travels to the wall (:func:`wall_reading_m`)."""
        return wall_reading_m(self.wall_distance_m, self.beam_angle_rad, emitter_offset_m)


def collect(sweeps: Sequence[Sweep], placement: Placement, sensor: int = 0) -> RigReadings:
    """Average repeated sweeps of one placement per step (robustly) for one sensor.

    Sweeps may differ in the steps they carry (a hardware sweep leaves out steps whose
    readings never arrived, ``Sweep.missing_steps``); readings are matched by step.
    """
    if not sweeps:
        raise CalibrationError("a placement needs at least one sweep")
    steps = np.unique(np.concatenate([np.asarray(sw.steps) for sw in sweeps]))
    counts = np.full((len(sweeps), steps.size), np.nan)           # (R, S)
    angle = np.full(steps.size, np.nan)
    for i, sw in enumerate(sweeps):
        at = np.searchsorted(steps, np.asarray(sw.steps))
        counts[i, at] = np.asarray(sw.counts, dtype=float)[:, sensor]
        angle[at] = np.asarray(sw.sensor_angles, dtype=float)[:, sensor]
        if sw.missing_steps:  # rows a source kept but marked missing are not readings
            counts[i, np.isin(steps, sw.missing_steps)] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a step no sweep read stays NaN
        med = np.nanmedian(counts, axis=0)
        mad = np.nanmedian(np.abs(counts - med), axis=0) * 1.4826
    keep = np.isfinite(counts)
    if len(sweeps) > 2:  # drop outliers (beyond 4 robust σ, at least 4 counts)
        keep &= np.abs(counts - med) <= 4.0 * np.maximum(np.nan_to_num(mad), 1.0)
    n = keep.sum(axis=0)
    total = np.where(keep, counts, 0.0).sum(axis=0)
    mean = np.where(n > 0, total / np.maximum(n, 1), np.nan)
    dev = np.where(keep, counts - mean[None, :], 0.0)
    spread = np.where(n > 1, np.sqrt((dev ** 2).sum(axis=0) / np.maximum(n - 1, 1)), np.nan)
    size = steps.size
    return RigReadings(counts=mean, beam_angle_rad=placement.yaw_rad + angle,
                       wall_distance_m=np.full(size, placement.wall_distance_m),
                       spread_counts=spread, repeats=n,
                       offset=np.full(size, placement.purpose == "offset"))


@dataclass(frozen=True)
class Fitted:
    """A calibration with the rig's readings it was fitted to (what `irring calibrate`
    draws: ``calibration_chart``). ``used``: per reading, whether the curve's last fit used
    it (the others were outside the range, at the ADC's ends or no return)."""

    calibration: Calibration
    readings: RigReadings
    used: np.ndarray


def solve(readings: RigReadings, **kwargs: Any) -> Calibration:
    """d_o (Eq. 9) and a(θ), b(θ) (Eq. 10) from a rig's readings: :func:`fit`'s
    calibration."""
    return fit(readings, **kwargs).calibration


def fit(readings: RigReadings, *, sensor_model: str, adc_bits: int = ADC_BITS,
        vref_v: float = VREF_V, min_range_m: float | None = None,
        max_range_m: float | None = None,
        theta_grid_rad: np.ndarray = DEFAULT_THETA_GRID_RAD, emitter_offset_guess_m: float = 0.0,
        source: str = "") -> Fitted:
    """d_o (Eq. 9) and a(θ), b(θ) (Eq. 10) from a rig's readings, solved alternately; with
    the readings and which of them the curve was fitted to.

    A reading is used for the curve if its counts are above the ADC floor and below full
    scale, its true distance lies in [min_range, max_range] (default: the sensor model's
    datasheet range) and it is not within 3σ of the no-return level (a dropped return reads
    as that level, not as its distance).
    """
    r = readings
    spread = r.spread_counts[np.isfinite(r.spread_counts) & (r.repeats > 1)]
    # the datasheet curve says what "nothing there" reads until our own curve can say it,
    # and its range is the default
    cal = Calibration.nominal(sensor_model, None, adc_bits, vref_v)
    if spread.size:
        noise = float(np.sqrt(np.mean(spread ** 2)))
    else:   # one sweep a placement measures no spread: the datasheet's, said, not 0
        noise = cal.noise_counts
        source = f"{source}; noise: the datasheet's (no repeated readings to measure it)"
    cal = dataclasses.replace(cal, noise_counts=noise)
    min_range_m = cal.min_range_m if min_range_m is None else min_range_m
    max_range_m = cal.max_range_m if max_range_m is None else max_range_m
    full = cal.full_scale_counts
    base = np.isfinite(r.counts) & (r.counts > 0.5) & (r.counts < full - 0.5) & \
        (np.abs(r.beam_angle_rad) < math.radians(89.0))
    d_o = float(emitter_offset_guess_m)
    steepest = None
    for _ in range(_ROUNDS):
        d_true = r.true_distance(d_o)
        use = base & (d_true >= min_range_m) & (d_true <= max_range_m)
        # drop returns that read as "nothing there" (dropped out past the incidence limit)
        floor = 3.0 * cal.sigma_counts()
        use &= (r.counts > cal.no_return_counts + floor) if cal.falling else \
            (r.counts < cal.no_return_counts - floor)
        theta, a, b = fit_curve(r.counts[use], d_true[use], r.beam_angle_rad[use],
                                theta_grid_rad)
        cal = Calibration(sensor_model=sensor_model, emitter_offset_m=d_o, theta_rad=theta,
                          a=a, b=b, adc_bits=adc_bits, vref_v=vref_v, min_range_m=min_range_m,
                          max_range_m=max_range_m, noise_counts=noise, source=source,
                          max_incidence_rad=steepest)
        # the steepest incidence that still returned (past it the sensor drops out)
        steepest = min(float(np.max(np.abs(r.beam_angle_rad[use]))), math.radians(89.0))
        off = use & r.offset
        if not off.any():
            raise CalibrationError("no usable readings from the offset placements (ψ = 0); "
                                   "d_o cannot be determined")
        d_meas = cal.distance(r.counts[off], r.beam_angle_rad[off])
        d_o = emitter_offset_from_wall(d_meas, r.beam_angle_rad[off], r.wall_distance_m[off])
    return Fitted(dataclasses.replace(cal, emitter_offset_m=d_o, max_incidence_rad=steepest),
                  r, use)


# --------------------------------------------------------------------------- simulated rig


class SimulatedRig:
    """The calibration rig in simulation: the scenario's ring and sensor in front of one wall
    of a generated 4 m × 4 m room, read through :class:`irring.simulation.sim.SimRing` with the
    scenario's effects. ``sweeps`` repeated sweeps per placement (fresh noise each)."""

    ROOM_M = 4.0

    def __init__(self, scenario, *, sensor: int = 0, sweeps: int = 8, seed: int | None = None,
                 placements: Sequence[Placement] | None = None):
        self.scenario = scenario
        self.sensor = int(sensor)
        self.sweeps = int(sweeps)
        self.ring: Ring = scenario.ring
        if not 0 <= self.sensor < self.ring.sensors:
            raise ValueError(f"sensor {sensor} does not exist; the ring has sensors 0 … "
                             f"{self.ring.sensors - 1}")
        self.model = gp2.sensor(scenario.sensor.model)
        self.placements = list(placements) if placements is not None else default_placements(
            self.model.min_range_m, self.model.max_range_m)
        self.seed = seed
        self._sim = None

    def robot_pose(self, placement: Placement) -> tuple[float, float, float]:
        """Robot (x, y, yaw) that puts the sensor's hinge ``wall_distance_m`` from the room's
        right wall (x = ROOM_M) with its radial direction ``yaw_rad`` off the wall normal."""
        rho = 2.0 * math.pi * self.sensor / self.ring.sensors
        psi = placement.yaw_rad
        x = self.ROOM_M - placement.wall_distance_m - self.ring.radius_m * math.cos(psi)
        y = self.ROOM_M / 2 - self.ring.radius_m * math.sin(psi)
        return x, y, psi - rho

    def scenario_for_rig(self):
        """The generated rig scene: one pose per placement, sensor range = the model's."""
        sc = self.scenario
        s = self.ROOM_M
        poses = tuple(Pose(*self.robot_pose(p)) for p in self.placements)
        effects = {k: v for k, v in sc.effects.items() if k != "motion"}
        return dataclasses.replace(
            sc, name=f"{sc.name}-calibration-rig",
            room=dataclasses.replace(sc.room, outline_m=((0.0, 0.0), (s, 0.0), (s, s), (0.0, s)),
                                     reflectance=1.0),
            obstacles=(), robot=dataclasses.replace(sc.robot, ring=self.ring, poses=poses),
            sensor=dataclasses.replace(sc.sensor, max_range_m=self.model.max_range_m),
            effects=effects)

    @property
    def sim(self):
        if self._sim is None:
            from ..simulation.sim import SimRing   # deferred: MuJoCo; the real ring needs none

            self._sim = SimRing(self.scenario_for_rig(), seed=self.seed)
        return self._sim

    def read(self, index: int) -> list[Sweep]:
        return [self.sim.sweep(index) for _ in range(self.sweeps)]

    def readings(self) -> RigReadings:
        return RigReadings.concat(collect(self.read(i), p, self.sensor)
                                  for i, p in enumerate(self.placements))

    def calibrate(self, theta_grid_rad: np.ndarray = DEFAULT_THETA_GRID_RAD) -> Calibration:
        return self.fit(theta_grid_rad).calibration

    def fit(self, theta_grid_rad: np.ndarray = DEFAULT_THETA_GRID_RAD) -> Fitted:
        """The calibration with the readings it was fitted to (:func:`fit`)."""
        sc = self.scenario
        return fit(self.readings(), sensor_model=sc.sensor.model,
                   adc_bits=sc.sensor.adc_bits, vref_v=sc.sensor.vref_v,
                   theta_grid_rad=theta_grid_rad,
                   source=f"simulated rig ({sc.name}: {', '.join(sc.effects) or 'no effects'}; "
                          f"{len(self.placements)} placements × {self.sweeps} sweeps, "
                          f"sensor {self.sensor})")


# --------------------------------------------------------------------------- the real ring


class CalibrationAborted(RuntimeError):
    """The user quit the guided calibration."""


class GuidedCalibration:
    """The calibration procedure for the real ring, with its I/O injected.

    ``prompt(text) -> str`` asks the user (``input``), ``show(text)`` tells them (``print``),
    ``read_sweep() -> Sweep`` takes one sweep from the ring (e.g. ``SerialRing.sweep``).
    For each placement the user sets up the wall and presses Enter (``s`` skips it, ``q``
    quits); the ring sweeps ``sweeps`` times; a placement whose central reading is far from
    what the nominal curve expects is offered for a retake (a wall in the wrong place is
    the usual mistake). ``done`` (placement index → :class:`RigReadings`, from
    :func:`load_progress`) holds placements read before, which are not measured again;
    :attr:`done` grows as placements are read, so a caller can keep them when the
    procedure stops early (:func:`save_progress`). After :meth:`run`, :attr:`fitted` holds
    the calibration with the readings it was fitted to.
    """

    def __init__(self, *, read_sweep: Callable[[], Sweep], prompt: Callable[[str], str] = input,
                 show: Callable[[str], None] = print, sensor_model: str = SENSOR_MODEL,
                 adc_bits: int = ADC_BITS, vref_v: float = VREF_V, sensor: int = 0,
                 sweeps: int = 4, placements: Sequence[Placement] | None = None,
                 emitter_offset_guess_m: float = Ring().emitter_offset_m,
                 done: Mapping[int, RigReadings] | None = None):
        self.read_sweep = read_sweep
        self.prompt = prompt
        self.show = show
        self.sensor_model = sensor_model
        self.adc_bits = int(adc_bits)
        self.vref_v = float(vref_v)
        self.sensor = int(sensor)
        self.sweeps = max(int(sweeps), 1)
        self.model = gp2.sensor(sensor_model)
        self.placements = list(placements) if placements is not None else default_placements(
            self.model.min_range_m, self.model.max_range_m)
        self.emitter_offset_guess_m = emitter_offset_guess_m
        self._nominal = Calibration.nominal(sensor_model, None, adc_bits, vref_v,
                                            emitter_offset_m=emitter_offset_guess_m)
        # placement index (0-based) → its readings: what a resumed run read before, then
        # each placement as it is read (kept when the procedure stops: save_progress)
        self.done: dict[int, RigReadings] = dict(done or {})
        self.resumed = len(self.done)
        self.at = 0   # the placement (1-based) the procedure is at
        self.fitted: Fitted | None = None   # what run() fitted, with its readings

    def check_steps(self, steps: int) -> None:
        """:class:`TooBig` when placements of ``steps`` steps a sweep are more readings than
        a progress file keeps (:data:`PROGRESS_MAX_READINGS`): what was read could not be
        kept if the procedure stopped."""
        n = len(self.placements)
        if steps * n > PROGRESS_MAX_READINGS:
            raise TooBig(f"a sweep of {steps:,} steps × {n} placements is {steps * n:,} "
                         f"readings; a calibration keeps at most {PROGRESS_MAX_READINGS:,} "
                         f"(sweeps of at most {PROGRESS_MAX_READINGS // n:,} steps) so that "
                         "what was read survives a stop: calibrate on a ring that sweeps "
                         "fewer steps (IRINF min_step … max_step)")

    def _expected_counts(self, placement: Placement, sweep: Sweep) -> tuple[float, float]:
        angles = np.asarray(sweep.sensor_angles, dtype=float)[:, self.sensor]
        i = int(np.argmin(np.abs(angles)))
        h = placement.yaw_rad + angles[i]
        d = wall_reading_m(placement.wall_distance_m, h, self.emitter_offset_guess_m)
        got = float(np.asarray(sweep.counts, dtype=float)[i, self.sensor])
        return float(self._nominal.counts(d, h)), got

    def run(self) -> Calibration:
        show, n = self.show, len(self.placements)
        show(f"Calibrating sensor {self.sensor} ({self.sensor_model}): {n} wall placements, "
             f"{self.sweeps} sweeps each. Distances are from the sensor's rotation axis to the "
             "wall; angles are the turn of the robot (or the wall) so the sensor's radial "
             "direction meets the wall's normal at that angle.")
        doubtful: list[int] = []   # placements kept although their reading looked wrong
        for k, placement in enumerate(self.placements, start=1):
            self.at = k
            if k - 1 in self.done:
                show(f"[{k}/{n}] read before (resumed)")
                continue
            while True:
                answer = self.prompt(f"[{k}/{n}] Place {placement.describe(self.sensor)}. "
                                     "Enter when ready, s to skip, q to quit: ").strip().lower()
                if answer == "q":
                    raise CalibrationAborted(f"calibration stopped by the user at placement {k}")
                if answer == "s":
                    show(f"[{k}/{n}] skipped")
                    break
                sweeps = [self.read_sweep() for _ in range(self.sweeps)]
                expected, got = self._expected_counts(placement, sweeps[0])
                if expected > 0 and abs(got - expected) > 0.3 * expected:
                    again = self.prompt(
                        f"[{k}/{n}] the straight-ahead reading is {got:.0f} counts, the nominal "
                        f"curve expects about {expected:.0f}: is the wall where it should be? "
                        "r to retake, Enter to keep: ").strip().lower()
                    if again == "r":
                        continue
                    doubtful.append(k)
                readings = collect(sweeps, placement, self.sensor)
                self.check_steps(readings.counts.size)
                self.done[k - 1] = readings
                show(f"[{k}/{n}] read {len(sweeps)} sweeps")
                break
        parts = [self.done[i] for i in sorted(self.done)]
        if not any(p.offset.any() for p in parts):
            raise CalibrationError("no offset placement (wall square to the sensor) was read; "
                                   "d_o needs at least one")
        try:
            self.fitted = fit(RigReadings.concat(parts), sensor_model=self.sensor_model,
                              adc_bits=self.adc_bits, vref_v=self.vref_v,
                              emitter_offset_guess_m=self.emitter_offset_guess_m,
                              source=f"guided calibration of the real ring, sensor "
                                     f"{self.sensor}, {len(parts)} placements × "
                                     f"{self.sweeps} sweeps")
            cal = self.fitted.calibration
        except CalibrationError as exc:
            hint = (f"; placements {', '.join(map(str, doubtful))} read far from the nominal "
                    "curve: was the wall where it was asked to be?" if doubtful else "")
            raise CalibrationError(f"{exc}{hint}") from exc
        show(f"d_o = {cal.emitter_offset_m * 1e3:.2f} mm; a(0) = {cal.a[0]:.4g}, "
             f"b(0) = {cal.b[0]:.4f}; θ table up to {math.degrees(cal.max_theta_rad):.0f}°; "
             f"noise {cal.noise_counts:.1f} counts")
        return cal


# --------------------------------------------------------------------------- progress

PROGRESS_FORMAT = 1   # version written into a guided calibration's progress file
# step readings (placements × steps of a sweep) a progress file keeps: save_progress writes
# at most ~60 bytes and 4 values for each, well within safe_yaml's progress-file limits
# (8 MB, 1,000,000 values; such a file takes seconds to read); 28 placements of sweeps of up
# to 1,785 steps (the paper's ring microstepped 1/16 sweeps ~1,130)
PROGRESS_MAX_READINGS = 50_000
# what save_progress writes for each placement read
PROGRESS_READ_KEYS = ("placement", "wall_distance_mm", "yaw_deg", "purpose", "beam_angle_deg",
                      "counts", "spread_counts", "repeats")


def save_progress(path: str | Path, guided: GuidedCalibration) -> Path:
    """Write the placements ``guided`` has read (:attr:`GuidedCalibration.done`) to a YAML
    file that :func:`load_progress` reads back to resume the procedure without measuring
    them again (``irring calibrate --port … --resume FILE``)."""
    def values(arr, digits=6):   # NaN (a step no sweep read) as null
        return [None if not math.isfinite(v) else round(float(v), digits) for v in arr]

    read = []
    for i in sorted(guided.done):
        r, place = guided.done[i], guided.placements[i]
        read.append({"placement": i + 1,
                     "wall_distance_mm": round(place.wall_distance_m * 1e3, 9),
                     "yaw_deg": round(math.degrees(place.yaw_rad), 9),
                     "purpose": place.purpose,
                     "beam_angle_deg": values(np.degrees(r.beam_angle_rad), 9),
                     "counts": values(r.counts), "spread_counts": values(r.spread_counts),
                     "repeats": [int(v) for v in r.repeats]})
    doc = {"irring_calibration_progress": PROGRESS_FORMAT, "sensor": guided.sensor,
           "sensor_model": guided.sensor_model, "adc_bits": guided.adc_bits,
           "vref_v": guided.vref_v, "sweeps": guided.sweeps,
           "placements": len(guided.placements), "read": read}
    header = ("# irring calibrate: the placements read so far; resume with\n"
              "# irring calibrate --port PORT --resume THIS_FILE\n")
    # libyaml's emitter where PyYAML has it: the same text, 4× faster (a stopped procedure
    # saves while its user waits)
    dumper = yaml.CSafeDumper if yaml.__with_libyaml__ else yaml.SafeDumper
    return write_text_atomic(path, header + yaml.dump(doc, Dumper=dumper, sort_keys=False,
                                                      default_flow_style=None, width=100),
                             "calibration progress file")


@dataclass(frozen=True)
class Progress:
    """A progress file's contents: the procedure it belongs to and what was read."""

    sensor: int
    sensor_model: str
    adc_bits: int
    vref_v: float
    placements: int
    sweeps: int   # per placement, averaged
    done: dict   # placement index (0-based) → (Placement, RigReadings)

    def mismatch(self, guided: GuidedCalibration) -> str | None:
        """Why this progress cannot resume ``guided`` (None: it can)."""
        mine = (self.sensor, self.sensor_model, self.adc_bits)
        theirs = (guided.sensor, guided.sensor_model, guided.adc_bits)
        if mine != theirs or not math.isclose(self.vref_v, guided.vref_v, rel_tol=1e-9):
            return (f"it was read from sensor {self.sensor}, a {self.sensor_model} with a "
                    f"{self.adc_bits}-bit ADC at {self.vref_v:g} V; this run calibrates sensor "
                    f"{guided.sensor}, a {guided.sensor_model} with a {guided.adc_bits}-bit ADC "
                    f"at {guided.vref_v:g} V")
        if self.sweeps != guided.sweeps:   # the placements read before would weigh otherwise
            return (f"its placements were read with {self.sweeps} sweeps each; this run asks "
                    f"--sweeps {guided.sweeps}: leave --sweeps out (or give {self.sweeps}) to "
                    "resume with the same")
        if self.placements != len(guided.placements):
            return (f"it belongs to a procedure of {self.placements} placements; this run has "
                    f"{len(guided.placements)}")
        for i, (place, _) in self.done.items():
            want = guided.placements[i]
            if not (math.isclose(place.wall_distance_m, want.wall_distance_m, abs_tol=1e-9)
                    and math.isclose(place.yaw_rad, want.yaw_rad, abs_tol=1e-9)
                    and place.purpose == want.purpose):
                return (f"its placement {i + 1} ({place.describe(self.sensor)}) is not this "
                        f"run's ({want.describe(guided.sensor)})")
        return None


def load_progress(path: str | Path) -> Progress:
    """A progress file :func:`save_progress` wrote; :class:`CalibrationError` naming the file
    and the key for anything else."""
    source = str(path)
    try:
        raw = safe_yaml.load_file(path, "calibration progress file")
    except safe_yaml.InputError as exc:
        raise CalibrationError(str(exc)) from None

    def fail(key: str, msg: str) -> CalibrationError:
        return CalibrationError(f"{source}: {key}: {msg}")

    if not isinstance(raw, Mapping) or not _is_format(raw.get("irring_calibration_progress"),
                                                      PROGRESS_FORMAT):
        raise fail("irring_calibration_progress",
                   f"expected format {PROGRESS_FORMAT} (a file `irring calibrate --port` names "
                   f"when it stops early)")
    known = {"irring_calibration_progress", "sensor", "sensor_model", "adc_bits", "vref_v",
             "sweeps", "placements", "read"}
    for key in raw:
        if key not in known:
            raise fail(str(key), f"unknown key; allowed: {', '.join(sorted(known))}")

    def whole(node, key, lo, hi, where=""):
        value = node.get(key) if isinstance(node, Mapping) else None
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            raise fail(where + key, f"expected a whole number {lo} … {hi}, got {brief(value)}")
        return value

    def real(node, key, lo, hi, where=""):
        value = node.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                not (math.isfinite(value) and lo <= value <= hi):
            raise fail(where + key, f"expected a number {lo:g} … {hi:g}, got {brief(value)}")
        return float(value)

    model = raw.get("sensor_model")
    if not gp2.is_sensor_model(model):
        raise fail("sensor_model", f"{brief(model)} is not a sensor model; choose one of: "
                                   f"{', '.join(gp2.SENSORS)}")
    sweeps = whole(raw, "sweeps", 1, MAX_SWEEPS)   # a placement's repeats are at most its sweeps
    bits = whole(raw, "adc_bits", 1, MAX_ADC_BITS)
    top = 2 ** bits - 1
    n = whole(raw, "placements", 1, 10_000)
    read = raw.get("read")
    if not isinstance(read, list) or len(read) > n:
        raise fail("read", f"expected a list of at most {n} placements read")
    kept = 0   # step readings, at most what save_progress writes
    done: dict = {}
    for j, entry in enumerate(read):
        at = f"read[{j}]."
        if not isinstance(entry, Mapping):
            raise fail(f"read[{j}]", "expected a mapping")
        for key in entry:
            if key not in PROGRESS_READ_KEYS:
                raise fail(at + str(key), "unknown key; allowed: "
                                          + ", ".join(PROGRESS_READ_KEYS))
        k = whole(entry, "placement", 1, n, at)
        if k - 1 in done:
            raise fail(at + "placement", f"placement {k} is read twice")
        purpose = entry.get("purpose")
        if purpose not in ("offset", "curve"):
            raise fail(at + "purpose", f"expected offset or curve, got {brief(purpose)}")
        place = Placement(real(entry, "wall_distance_mm", 1e-3, 1e5, at) * 1e-3,
                          math.radians(real(entry, "yaw_deg", -90, 90, at)), purpose)
        cols = {}
        for key, lo, hi, nullable in (("beam_angle_deg", -360.0, 360.0, False),
                                      ("counts", 0.0, float(top), True),
                                      ("spread_counts", 0.0, float(top), True),
                                      ("repeats", 0, sweeps, False)):
            col = entry.get(key)
            if not isinstance(col, list) or not 1 <= len(col) <= MAX_STEPS:
                raise fail(at + key, f"expected a list of 1 … {MAX_STEPS} values")
            for v in col:
                if v is None and nullable:
                    continue
                if isinstance(v, bool) or not isinstance(v, (int, float)) or \
                        not (math.isfinite(v) and lo <= v <= hi) or \
                        (key == "repeats" and not isinstance(v, int)):
                    raise fail(at + key, f"{brief(v)} is not allowed; expected "
                                         f"{'whole numbers' if key == 'repeats' else 'numbers'} "
                                         f"{lo:g} … {hi:g}{' or null' if nullable else ''}")
            cols[key] = np.array([math.nan if v is None else v for v in col], dtype=float)
        sizes = {key: c.size for key, c in cols.items()}
        if len(set(sizes.values())) != 1:
            raise fail(f"read[{j}]", f"its lists differ in length ({sizes}); one value a step")
        read = cols["repeats"] > 0
        wrong = np.flatnonzero(np.isfinite(cols["counts"]) != read)
        if wrong.size:   # collect() averages a step's readings: NaN exactly where none was
            i = int(wrong[0])
            said = (f"counts {cols['counts'][i]:g} from 0 readings" if not read[i] else
                    f"no counts (null) from {int(cols['repeats'][i])} readings")
            raise fail(f"read[{j}]", f"step {i + 1} says {said}; a step's counts are the mean "
                                     "of the readings its repeats count (null where none was "
                                     "read)")
        size = cols["counts"].size
        kept += size
        if kept > PROGRESS_MAX_READINGS:
            raise fail(f"read[{j}]", f"more than {PROGRESS_MAX_READINGS:,} step readings in "
                                     "all; a calibration keeps at most that many")
        done[k - 1] = (place, RigReadings(
            counts=cols["counts"], beam_angle_rad=np.radians(cols["beam_angle_deg"]),
            wall_distance_m=np.full(size, place.wall_distance_m),
            spread_counts=cols["spread_counts"], repeats=cols["repeats"].astype(int),
            offset=np.full(size, purpose == "offset")))
    return Progress(sensor=whole(raw, "sensor", 0, bounds(Ring, "sensors")[1] - 1),
                    sensor_model=str(model), adc_bits=bits,
                    vref_v=real(raw, "vref_v", *VREF_RANGE_V), placements=n,
                    done=done, sweeps=sweeps)
