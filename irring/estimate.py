"""Calibration and the paper's iterative range estimator (Park, Baek & Lee 2005, Table II).

A Sharp GP2 reading S (ADC counts) gives the distance by Eq. 10, ``d = a(θ)·S^b(θ)``, but
the coefficients depend on the incidence angle θ between the beam and the surface normal,
which a single reading cannot tell. The estimator of Table II recovers θ from the shape of
the scene, vectorised over a whole sweep (S steps × N sensors):

1. assume θ = 0 for every reading;
2. d from Eq. 10 with a(θ), b(θ) of the :class:`Calibration`;
3. end points from d, the sensor angle and the emitter offset d_o (``data.beam_geometry``);
4. group the end points into lines: per sensor the readings are ordered by sensor angle, so
   each sensor's sweep is a polyline; it is split at its corners (iterative end-point fit,
   i.e. Douglas–Peucker, with a noise-scaled threshold) and adjacent collinear pieces are
   merged again; every piece gets a total-least-squares line (vertical lines are fine);
5. θ_new = angle between each reading's beam and the normal of its line;
6. repeat from 2 until |θ_new − θ| < ε for every reading, or ``max_iterations``.

Fallback: a reading on no usable line (a thin cylinder, an isolated return, a line shorter
than ``LineOptions.min_length_m`` or with fewer than ``min_points`` readings) keeps θ = 0, the
paper's starting assumption, and its ``sigma_m`` is widened by half the gap between its θ = 0
and θ = 45° distances.

Damping: a reading whose θ update reverses the previous one without shrinking to half of it
(an oscillation, not ordinary convergence) has its step gain halved (down to 1/64); the gain
recovers by ×1.25 per calm iteration. The line grouping is recomputed while some θ still
moves by more than ``LineOptions.regroup_until_rad`` (at most ``regroup_iterations``
times) and then held: members keep their line, readings on no line may still join one, so
readings at a corner cannot flip between two lines forever. Readings still moving after
``max_iterations`` are NOT_CONVERGED (in the noisy T-room about 0.4 % of readings, where a
shoulder's convex corner is seen nearly edge-on and its two walls barely differ).

Validity (:class:`irring.data.Reason`): a missing reading (NaN counts or a step in
``Sweep.missing_steps``) is MISSING; counts at ADC full scale SATURATED; counts at or below the
weakest count any in-range return can give (the noise floor) NO_RETURN; counts brighter than
the calibrated near end of the curve FOLDOVER_AMBIGUOUS (below the peak distance one voltage
has two distances); a final distance outside [min_range, max_range] OUT_OF_RANGE; a reading
whose θ still moved by ≥ ε after ``max_iterations`` NOT_CONVERGED. A valid reading never
carries NaN or inf.

Units: metres, radians, ADC counts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import yaml

from .data import Points, Reason, Sweep, beam_geometry
from .scenario import Ring

CALIBRATION_FORMAT = 1  # version written into calibration files
_SIGMA_FLOOR_M = 0.001  # no reading is trusted better than 1 mm
_FALLBACK_SPREAD_RAD = math.radians(45.0)
_PINNED_RAD = math.radians(2.0)  # a line most readings meet within this of the drop-out angle
#                                  is a runaway, not a wall (see _drop_steep)


# --------------------------------------------------------------------------- calibration


class CalibrationError(ValueError):
    """Calibration data that cannot determine a parameter, or a bad calibration file."""


def _frozen(a: Any, name: str) -> np.ndarray:
    arr = np.array(a, dtype=float).reshape(-1)
    if not np.all(np.isfinite(arr)):
        raise CalibrationError(f"{name}: every value must be finite, got {arr}")
    arr.setflags(write=False)
    return arr


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
        if not (math.isfinite(self.noise_counts) and self.noise_counts >= 0):
            raise CalibrationError(f"noise_counts must be ≥ 0, got {self.noise_counts!r}")
        if self.max_incidence_rad is None:
            object.__setattr__(self, "max_incidence_rad", float(theta[-1]) or math.pi / 2 - 1e-3)
        if not 0.0 < self.max_incidence_rad < math.pi / 2:
            raise CalibrationError(f"max_incidence must lie in (0°, 90°), got "
                                   f"{math.degrees(self.max_incidence_rad):g}°")
        object.__setattr__(self, "theta_rad", theta)
        object.__setattr__(self, "a", a)
        object.__setattr__(self, "b", b)
        object.__setattr__(self, "_log_a", np.log(a))

    # ---- the curve

    @property
    def full_scale_counts(self) -> float:
        return float(2 ** self.adc_bits - 1)

    @property
    def max_theta_rad(self) -> float:
        return float(self.theta_rad[-1])

    def ab(self, theta_rad: Any) -> tuple[np.ndarray, np.ndarray]:
        """a(θ), b(θ) at |θ|: linear in (log a, b), held beyond the table."""
        t = np.abs(np.asarray(theta_rad, dtype=float))
        log_a = np.interp(t, self.theta_rad, self._log_a)
        return np.exp(log_a), np.interp(t, self.theta_rad, self.b)

    def distance(self, counts: Any, theta_rad: Any = 0.0) -> np.ndarray:
        """Eq. 10: metres from counts (> 0) at incidence θ; vectorised."""
        s = np.asarray(counts, dtype=float)
        t = np.abs(np.asarray(theta_rad, dtype=float))
        log_a = np.interp(t, self.theta_rad, self._log_a)
        b = np.interp(t, self.theta_rad, self.b)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.exp(log_a + b * np.log(s))

    def counts(self, distance_m: Any, theta_rad: Any = 0.0) -> np.ndarray:
        """The inverse of Eq. 10: the counts a return at ``distance_m`` and θ gives."""
        d = np.asarray(distance_m, dtype=float)
        t = np.abs(np.asarray(theta_rad, dtype=float))
        log_a = np.interp(t, self.theta_rad, self._log_a)
        b = np.interp(t, self.theta_rad, self.b)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.exp((np.log(d) - log_a) / b)

    @property
    def falling(self) -> bool:
        """True for a Sharp GP2 (b < 0: more counts, nearer); False for linear hooks."""
        return bool(self.b[0] < 0)

    @property
    def no_return_counts(self) -> float:
        """Counts of a return at max_range_m square on (a GP2's output with nothing in
        range); readings within 2σ of it, or beyond it, are no return."""
        return float(self.counts(self.max_range_m, 0.0))

    @property
    def near_counts(self) -> float:
        """The near end of the calibrated curve (any θ): a GP2 reading brighter than this
        lies on the peak or its fold-over side, where one reading has two distances."""
        near = self.counts(self.min_range_m, self.theta_rad)
        return float(np.max(near) if self.falling else np.min(near))

    def sigma_counts(self) -> float:
        """1-σ count noise including quantisation (one count, uniform)."""
        return math.sqrt(self.noise_counts ** 2 + 1.0 / 12.0)

    # ---- construction

    @classmethod
    def nominal(cls, sensor_model: str = "gp2d12", ring: Ring | None = None, adc_bits: int = 12,
                vref_v: float = 5.0, *, emitter_offset_m: float | None = None,
                noise_sigma_v: float = 0.015) -> Calibration:
        """The datasheet calibration from ``irring.gp2``'s tables, for an uncalibrated ring.

        ``d = a_V·V^b`` with V = k·S (k volts per count) becomes ``d = (a_V·k^b)·S^b``.
        d_o comes from ``emitter_offset_m``, else the ring design's, else 7 mm.
        """
        from . import gp2

        model = gp2.sensor(sensor_model)
        volts_per_count = gp2.lsb_v(adc_bits, vref_v)
        theta = np.asarray(model.theta_rad, dtype=float)
        keep = theta < math.pi / 2
        a_v, b = (np.asarray(v, dtype=float)[keep] for v in (model.a, model.b))
        if emitter_offset_m is None:
            emitter_offset_m = ring.emitter_offset_m if ring is not None else 0.007
        return cls(sensor_model=model.name, emitter_offset_m=float(emitter_offset_m),
                   theta_rad=theta[keep], a=a_v * volts_per_count ** b, b=b,
                   adc_bits=int(adc_bits), vref_v=float(vref_v),
                   min_range_m=float(model.min_range_m), max_range_m=float(model.max_range_m),
                   noise_counts=float(noise_sigma_v) / volts_per_count,
                   max_incidence_rad=float(min(model.max_incidence_rad, theta[keep][-1]
                                               if theta[keep][-1] > 0 else math.pi / 2 - 1e-3)),
                   source=f"nominal {model.name} datasheet curve")

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
            "curve": [{"theta_deg": round(math.degrees(t), 9), "a": float(a), "b": float(b)}
                      for t, a, b in zip(self.theta_rad, self.a, self.b)],
        }

    def save(self, path: str | Path) -> Path:
        """Write a YAML calibration file (mm and degrees for people, d = a·S^b, S in counts)."""
        path = Path(path)
        header = ("# irring calibration: d[m] = a(θ)·S^b(θ), S in ADC counts (paper Eq. 10);\n"
                  "# emitter offset d_o (paper Eq. 9) in mm; load with "
                  "irring.estimate.Calibration.load\n")
        path.write_text(header + yaml.safe_dump(self.to_dict(), sort_keys=False,
                                                allow_unicode=True), encoding="utf-8")
        return path

    @classmethod
    def from_dict(cls, raw: Any, source: str = "<dict>") -> Calibration:
        def fail(key: str, msg: str) -> CalibrationError:
            return CalibrationError(f"{source}: {key}: {msg}")

        if not isinstance(raw, Mapping):
            raise fail("<top>", "a calibration file must be a mapping")
        known = {"irring_calibration", "sensor_model", "source", "emitter_offset_mm", "adc_bits",
                 "vref_v", "min_range_mm", "max_range_mm", "noise_counts", "curve",
                 "max_incidence_deg"}
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

        def number(key: str, default: float | None = None) -> float:
            value = raw.get(key, default)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise fail(key, f"expected a number, got {value!r}")
            return float(value)

        curve = raw["curve"]
        if not isinstance(curve, list) or not curve:
            raise fail("curve", "expected a non-empty list of {theta_deg, a, b}")
        rows = []
        for i, row in enumerate(curve):
            if not isinstance(row, Mapping) or set(row) != {"theta_deg", "a", "b"}:
                raise fail(f"curve[{i}]", f"expected keys theta_deg, a, b; got {row!r}")
            try:
                rows.append([float(row["theta_deg"]), float(row["a"]), float(row["b"])])
            except (TypeError, ValueError):
                raise fail(f"curve[{i}]", f"expected numbers, got {row!r}") from None
        table = np.array(rows)
        bits = raw.get("adc_bits", 12)
        if isinstance(bits, bool) or not isinstance(bits, int) or not 1 <= bits <= 24:
            raise fail("adc_bits", f"expected a whole number 1 … 24, got {bits!r}")
        try:
            return cls(sensor_model=str(raw["sensor_model"]),
                       emitter_offset_m=number("emitter_offset_mm") * 1e-3,
                       theta_rad=np.radians(table[:, 0]), a=table[:, 1], b=table[:, 2],
                       adc_bits=bits, vref_v=number("vref_v", 5.0),
                       min_range_m=number("min_range_mm", 100.0) * 1e-3,
                       max_range_m=number("max_range_mm", 800.0) * 1e-3,
                       noise_counts=number("noise_counts", 0.0),
                       max_incidence_rad=(math.radians(number("max_incidence_deg"))
                                          if "max_incidence_deg" in raw else None),
                       source=str(raw.get("source", "")))
        except CalibrationError as exc:
            raise CalibrationError(f"{source}: {exc}") from None

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        path = Path(path)
        try:
            raw = yaml.safe_load(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise CalibrationError(f"{path}: cannot read calibration file: {exc}") from exc
        except yaml.YAMLError as exc:
            raise CalibrationError(f"{path}: not valid YAML: {exc}") from exc
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
    gap_m: float = 0.15            # consecutive readings farther apart start a new polyline
    min_points: int = 3            # a line usable for θ has at least this many readings …
    min_length_m: float = 0.08     # … spanning at least this length
    max_rms_sigmas: float = 3.0    # … and fits them to within this RMS (in σ)
    regroup_iterations: int = 8    # regroup at most this many iterations …
    regroup_until_rad: float = math.radians(1.0)  # … and only while some θ moves more
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
    s = len(order)
    return (order[None, :] * n_sensors + np.arange(n_sensors)[:, None]).reshape(-1), s


def _tls(sx, sy, sxx, syy, sxy, n):
    """Total-least-squares line from summed moments (arrays). Returns centroid, normal,
    direction, λ_min, λ_max (variances along the normal / the line)."""
    n = np.maximum(n, 1)
    mx, my = sx / n, sy / n
    cxx = np.maximum(sxx / n - mx * mx, 0.0)
    cyy = np.maximum(syy / n - my * my, 0.0)
    cxy = sxy / n - mx * my
    half = 0.5 * (cxx - cyy)
    root = np.hypot(half, cxy)
    mean = 0.5 * (cxx + cyy)
    lam_min = np.maximum(mean - root, 0.0)
    lam_max = mean + root
    alpha = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)  # major axis: exact for vertical lines
    direction = np.stack([np.cos(alpha), np.sin(alpha)], axis=-1)
    normal = np.stack([-np.sin(alpha), np.cos(alpha)], axis=-1)
    return np.stack([mx, my], axis=-1), normal, direction, lam_min, lam_max


class _Moments:
    """Prefix sums of x, y, x², y², xy over a flat point sequence: any contiguous range's
    TLS line in O(1). Coordinates are centred first so small spreads keep their digits."""

    def __init__(self, px: np.ndarray, py: np.ndarray):
        self.cx = float(np.mean(px)) if px.size else 0.0
        self.cy = float(np.mean(py)) if py.size else 0.0
        x, y = px - self.cx, py - self.cy
        cols = np.stack([np.ones_like(x), x, y, x * x, y * y, x * y])
        self.cum = np.concatenate([np.zeros((6, 1)), np.cumsum(cols, axis=1)], axis=1)

    def fit(self, start: np.ndarray, end: np.ndarray):
        """TLS over inclusive ranges [start, end]."""
        tot = self.cum[:, end + 1] - self.cum[:, start]
        c, normal, direction, lmin, lmax = _tls(tot[1], tot[2], tot[3], tot[4], tot[5], tot[0])
        c = c + np.array([self.cx, self.cy])
        return c, normal, direction, lmin, lmax, tot[0]


def fit_lines(x: np.ndarray, y: np.ndarray, ok: np.ndarray, sigma_m: np.ndarray,
              steps: np.ndarray | None = None, options: LineOptions = LineOptions()) -> Lines:
    """Group the end points of a sweep into lines (vectorised split-and-merge).

    ``x``, ``y``, ``ok``, ``sigma_m`` are (S, N); readings with ``ok`` False are skipped.
    Each sensor's readings, ordered by ``steps``, form polylines (broken where consecutive
    readings are more than ``gap_m`` apart); each polyline is split at the reading farthest
    from its chord while that exceeds max(min_split_m, split_sigmas·σ) (all polylines at
    once per round), then adjacent pieces whose joint TLS line still fits every reading within
    that threshold are merged. A corner reading shared by two pieces joins the line it is
    nearer to.
    """
    x = np.asarray(x, dtype=float)
    shape = x.shape
    n_steps, n_sensors = shape
    if steps is None:
        steps = np.arange(n_steps)
    flat, _ = _scan_order(steps, n_sensors)
    okf = np.asarray(ok, dtype=bool).reshape(-1)[flat]
    okf &= np.isfinite(x.reshape(-1)[flat]) & np.isfinite(np.asarray(y, float).reshape(-1)[flat])
    idx = flat[okf]                                   # original flat index of each kept point
    px = x.reshape(-1)[idx]
    py = np.asarray(y, dtype=float).reshape(-1)[idx]
    thr = np.maximum(options.min_split_m,
                     options.split_sigmas * np.nan_to_num(
                         np.asarray(sigma_m, float).reshape(-1)[idx], nan=0.0, posinf=1.0))
    sensor = idx % n_sensors
    k = px.size
    label = np.full(n_steps * n_sensors, -1, dtype=int)
    if k == 0:
        return _empty_lines(label.reshape(shape))

    # polylines: new one at a sensor change or a jump
    jump = np.hypot(np.diff(px), np.diff(py)) > options.gap_m
    brk = np.flatnonzero((np.diff(sensor) != 0) | jump) + 1
    run_start = np.concatenate([[0], brk])
    run_end = np.concatenate([brk - 1, [k - 1]])

    starts, ends = _split(px, py, thr, run_start, run_end)
    starts, ends = _refine_corners(px, py, starts, ends)
    starts, ends = _merge(px, py, thr, starts, ends)
    starts, ends = _refine_corners(px, py, starts, ends)

    mom = _Moments(px, py)
    centroid, normal, direction, lmin, lmax, npts = mom.fit(starts, ends)
    seg = np.arange(k)
    owner = np.searchsorted(starts, seg, side="right") - 1   # shared corners → right piece
    # a corner shared with the previous piece joins the nearer line
    shared = np.zeros(k, dtype=bool)
    prev_end = np.full(k, -1)
    shared_idx = starts[1:][starts[1:] == ends[:-1]]
    shared[shared_idx] = True
    prev_end[shared_idx] = np.flatnonzero(starts[1:] == ends[:-1])
    pts = np.stack([px, py], axis=-1)
    r_own = np.abs(np.einsum("ij,ij->i", pts - centroid[owner], normal[owner]))
    alt = np.where(shared, prev_end, owner)
    r_alt = np.abs(np.einsum("ij,ij->i", pts - centroid[alt], normal[alt]))
    owner = np.where(shared & (r_alt < r_own), alt, owner)

    ext = np.einsum("ij,ij->i", pts[ends] - pts[starts], direction)
    rms = np.sqrt(lmin)
    n_pts = np.bincount(owner, minlength=starts.size)
    mean_sig = np.bincount(owner, weights=thr / options.split_sigmas, minlength=starts.size)
    mean_sig = mean_sig / np.maximum(n_pts, 1)
    usable = ((n_pts >= options.min_points) & (np.abs(ext) >= options.min_length_m)
              & (lmax > 0) & (rms <= options.max_rms_sigmas * np.maximum(mean_sig, 1e-6))
              & np.all(np.isfinite(normal), axis=-1))
    label[idx] = owner
    return Lines(label=label.reshape(shape), centroid=centroid, normal=normal,
                 direction=direction, n_points=n_pts, length_m=np.abs(ext), rms_m=rms,
                 usable=usable, start=idx[starts], end=idx[ends])


def _empty_lines(label: np.ndarray) -> Lines:
    z2, z1 = np.zeros((0, 2)), np.zeros(0)
    return Lines(label=label, centroid=z2, normal=z2, direction=z2,
                 n_points=np.zeros(0, int), length_m=z1, rms_m=z1,
                 usable=np.zeros(0, bool), start=np.zeros(0, int), end=np.zeros(0, int))


def _split(px, py, thr, starts, ends):
    """Iterative end-point fit on every piece at once. Pieces share their corner reading."""
    k = px.size
    idx = np.arange(k)
    for _ in range(k):  # each round splits ≥ 1 piece or stops; bounded by the point count
        owner = np.searchsorted(starts, idx, side="right") - 1
        s, e = starts[owner], ends[owner]
        ax, ay = px[s], py[s]
        dx, dy = px[e] - ax, py[e] - ay
        chord = np.hypot(dx, dy)
        cross = np.abs(dx * (py - ay) - dy * (px - ax))
        dist = np.where(chord > 1e-12, cross / np.maximum(chord, 1e-12),
                        np.hypot(px - ax, py - ay))
        score = np.where((idx > s) & (idx < e), dist / thr, 0.0)
        best = np.maximum.reduceat(score, starts)
        split = best > 1.0
        if not split.any():
            break
        cand = np.where(score >= best[owner] * (1 - 1e-12), idx, k)
        at = np.minimum.reduceat(cand, starts)[split]
        starts = np.sort(np.concatenate([starts, at]))
        ends = np.sort(np.concatenate([ends, at]))
    return starts, ends


def _refine_corners(px, py, starts, ends, window: int = 5, rounds: int = 2):
    """Move each corner shared by two pieces to where the two TLS lines fit best.

    The end-point fit splits at the reading farthest from the chord, which for a corner near
    the end of a polyline, or seen at a slant, is a few readings off the true corner. Each
    shared corner is tried at up to ``window`` readings either side (keeping ≥ 2 readings per
    piece) and put where the summed squared perpendicular residuals of the two pieces are
    least; all corners at once, from prefix sums.
    """
    mom = _Moments(px, py)
    for _ in range(rounds):
        j = np.flatnonzero(starts[1:] == ends[:-1])       # piece j and j + 1 share a corner
        if j.size == 0:
            break
        lo, v, hi = starts[j], ends[j], ends[j + 1]
        cand = v[:, None] + np.arange(-window, window + 1)[None, :]      # (P, K)
        ok = (cand >= lo[:, None] + 1) & (cand <= hi[:, None] - 1)
        c = np.where(ok, cand, v[:, None])
        *_, lmin_a, _, n_a = mom.fit(np.broadcast_to(lo[:, None], c.shape).ravel(), c.ravel())
        *_, lmin_b, _, n_b = mom.fit(c.ravel(), np.broadcast_to(hi[:, None], c.shape).ravel())
        cost = (lmin_a * n_a + lmin_b * n_b).reshape(c.shape)
        cost = np.where(ok, cost, np.inf)
        best = c[np.arange(j.size), np.argmin(cost, axis=1)]
        if np.array_equal(best, v):
            break
        ends = ends.copy()
        starts = starts.copy()
        ends[j] = best
        starts[j + 1] = best
    return starts, ends


def _merge(px, py, thr, starts, ends):
    """Merge adjacent pieces (sharing a corner) whose joint TLS line fits every reading
    within its threshold; cheapest joins first, non-overlapping joins per round."""
    k = px.size
    idx = np.arange(k)
    mom = _Moments(px, py)
    for _ in range(starts.size):
        joinable = np.flatnonzero(starts[1:] == ends[:-1])  # piece j with piece j+1
        if joinable.size == 0:
            break
        c, n, *_ = mom.fit(starts[joinable], ends[joinable + 1])
        # worst normalised residual of each candidate union
        pair_of = np.full(starts.size, -1)
        pair_of[joinable] = np.arange(joinable.size)
        owner = np.searchsorted(starts, idx, side="right") - 1
        worst = np.zeros(joinable.size)
        for piece_shift in (0, 1):  # readings of the left piece, then of the right piece
            p = pair_of[np.clip(owner - piece_shift, 0, None)]
            use = (p >= 0) & (owner - piece_shift >= 0)
            r = np.abs((px[use] - c[p[use], 0]) * n[p[use], 0]
                       + (py[use] - c[p[use], 1]) * n[p[use], 1]) / thr[use]
            np.maximum.at(worst, p[use], r)
        ok = worst <= 1.0
        if not ok.any():
            break
        # choose joins that are the cheapest among their neighbours (so none overlap)
        cost = np.where(ok, worst, np.inf)
        left = np.concatenate([[np.inf], cost[:-1]])
        right = np.concatenate([cost[1:], [np.inf]])
        adjacent_left = np.concatenate([[False], joinable[1:] == joinable[:-1] + 1])
        adjacent_right = np.concatenate([joinable[1:] == joinable[:-1] + 1, [False]])
        pick = ok & ~(adjacent_left & (left <= cost)) & ~(adjacent_right & (right < cost))
        j = joinable[pick]
        keep = np.ones(starts.size, dtype=bool)
        keep[j + 1] = False
        new_ends = ends.copy()
        new_ends[j] = ends[j + 1]
        starts, ends = starts[keep], new_ends[keep]
    return starts, ends


# --------------------------------------------------------------------------- estimation


@dataclass(frozen=True)
class Estimate:
    """Points plus what the estimator saw (for plots, tests and benchmarks)."""

    points: Points
    lines: Lines | None
    theta_history: tuple[np.ndarray, ...] = field(default=())


def _classify(counts: np.ndarray, sweep: Sweep, cal: Calibration) -> np.ndarray:
    """Reasons decided by the counts alone (before any distance is computed)."""
    reason = np.zeros(counts.shape, dtype=np.uint8)
    s = counts
    finite = np.isfinite(s)
    reason[~finite] = Reason.MISSING
    if sweep.missing_steps:
        rows = np.isin(np.asarray(sweep.steps), np.asarray(sweep.missing_steps))
        reason[rows, :] = Reason.MISSING
    ok = reason == Reason.OK
    full = cal.full_scale_counts
    reason[ok & (s >= full - 0.5)] = Reason.SATURATED
    ok = reason == Reason.OK
    margin = 2.0 * cal.sigma_counts()
    if cal.falling:
        reason[ok & (s > cal.near_counts)] = Reason.FOLDOVER_AMBIGUOUS
        ok = reason == Reason.OK
        reason[ok & ((s <= cal.no_return_counts + margin) | (s <= 0))] = Reason.NO_RETURN
    else:  # a linear sensor (sonar/laser hooks): no fold-over, no return reads as max range
        reason[ok & ((s >= cal.no_return_counts - margin) | (s <= 0))] = Reason.NO_RETURN
    return reason


def estimate(sweep: Sweep, calibration: Calibration | None = None, *, max_iterations: int = 20,
             tolerance_rad: float = math.radians(0.1), iterate: bool = True,
             lines: LineOptions = LineOptions()) -> Points:
    """Counts → end points by the iterative estimation of Table II (see the module doc).

    ``calibration`` defaults to :meth:`Calibration.for_sweep` (the datasheet curve).
    ``iterate=False`` gives the θ = 0 assumption (Eq. 10 with a(0), b(0)).
    """
    return estimate_detail(sweep, calibration, max_iterations=max_iterations,
                           tolerance_rad=tolerance_rad, iterate=iterate, lines=lines).points


def estimate_detail(sweep: Sweep, calibration: Calibration | None = None, *,
                    max_iterations: int = 20, tolerance_rad: float = math.radians(0.1),
                    iterate: bool = True, lines: LineOptions = LineOptions(),
                    keep_history: bool = False, damping: bool = True) -> Estimate:
    """:func:`estimate` that also returns the final lines and (optionally) θ per iteration.

    ``damping=False`` switches the oscillation damping off (to show what it is for).
    """
    cal = calibration if calibration is not None else Calibration.for_sweep(sweep)
    if max_iterations < 1:
        raise ValueError(f"max_iterations must be ≥ 1, got {max_iterations}")
    counts = np.asarray(sweep.counts, dtype=float)
    if counts.ndim != 2:
        raise ValueError(f"sweep.counts must be (steps, sensors), got shape {counts.shape}")
    angles = np.asarray(sweep.sensor_angles, dtype=float)
    pose = sweep.reading_poses if sweep.reading_poses is not None else sweep.pose
    origin, heading = beam_geometry(sweep.ring, np.asarray(pose, dtype=float), angles,
                                    cal.emitter_offset_m)
    origin = np.broadcast_to(origin, counts.shape + (2,))
    heading = np.broadcast_to(heading, counts.shape)
    ux, uy = np.cos(heading), np.sin(heading)

    reason = _classify(counts, sweep, cal)
    live = reason == Reason.OK
    s_safe = np.where(live, counts, 1.0)
    max_range = min(float(sweep.max_range_m), cal.max_range_m)
    theta_cap = cal.max_incidence_rad
    theta_reject = theta_cap + lines.incidence_margin_rad
    sig_counts = cal.sigma_counts()

    def points_at(theta):
        d = cal.distance(s_safe, theta)
        _, b = cal.ab(theta)
        sigma = np.maximum(np.abs(b) * d * sig_counts / s_safe, _SIGMA_FLOOR_M)
        return d, origin[..., 0] + d * ux, origin[..., 1] + d * uy, sigma

    theta = np.zeros(counts.shape)
    gain = np.ones(counts.shape)
    last_step = np.zeros(counts.shape)
    iterations = np.zeros(counts.shape, dtype=np.int32)
    moving = np.zeros(counts.shape, dtype=bool)
    was_moving = np.ones(counts.shape, dtype=bool)
    on_line = np.zeros(counts.shape, dtype=bool)
    history = [theta.copy()] if keep_history else []
    found: Lines | None = None
    steps = np.asarray(sweep.steps)
    scan, _ = _scan_order(steps, counts.shape[1])
    regroup = True
    n_iter = max_iterations if iterate else 0
    for it in range(n_iter):
        d, px, py, sigma = points_at(theta)
        # readings far outside the range cannot help a line (but stay for the final check)
        usable = live & (d <= 1.5 * max_range)
        if regroup:
            found = fit_lines(px, py, usable, sigma, steps, lines)
            line_of = _members(found, usable, px, py, sigma, lines)
            line_of = _settle_corners(line_of, found, scan, cal, s_safe, origin, ux, uy, px,
                                      py, sigma, theta_reject, lines)
        else:  # held grouping: the same members refitted at their new positions
            found = _refit(found, line_of, px, py, usable)
        found, line_of = _drop_steep(found, line_of, usable, ux, uy, theta_cap, theta_reject)
        # readings on no line may join one (while held: join, never leave, so no flip-flop)
        orphan = usable & (line_of < 0)
        if orphan.any():
            line_of = _adopt(line_of, orphan, found, cal, s_safe, origin, ux, uy, px, py,
                             sigma, theta_reject, lines)
        good = line_of >= 0
        theta_line = _incidence(found, line_of, ux, uy)
        theta_new = np.where(good, np.minimum(theta_line, theta_cap), 0.0)
        on_line = good
        step = theta_new - theta
        moving = live & (np.abs(step) >= tolerance_rad)
        # damping: an update that reverses the previous one halves the gain
        # (a reversal that shrinks fast is ordinary convergence and keeps its gain)
        flip = moving & (step * last_step < 0) & (np.abs(step) > 0.5 * np.abs(last_step))
        flip &= damping
        gain = np.where(flip, np.maximum(gain * 0.5, 1.0 / 64.0), np.minimum(gain * 1.25, 1.0))
        applied = gain * step
        theta = np.clip(theta + np.where(live, applied, 0.0), 0.0, theta_cap)
        last_step = np.where(moving, step, 0.0)
        # a reading's count: iterations until its θ stopped moving (the confirming one included)
        iterations = np.where(moving | was_moving, it + 1, iterations).astype(np.int32)
        was_moving = moving
        if keep_history:
            history.append(theta.copy())
        if not moving.any():
            break
        # regroup while θ still moves coarsely, then hold the grouping
        regroup = regroup and it + 1 < lines.regroup_iterations and \
            float(np.max(np.abs(applied), initial=0.0)) > lines.regroup_until_rad

    d, px, py, sigma = points_at(theta)
    # fallback readings (no line): θ = 0, σ widened by half the spread to θ = 45°
    d45 = cal.distance(s_safe, np.full(counts.shape, _FALLBACK_SPREAD_RAD))
    sigma = np.where(on_line | (not iterate), sigma,
                     np.hypot(sigma, 0.5 * np.abs(d45 - d)))
    bad_range = live & ((d > max_range) | (d < cal.min_range_m) | ~np.isfinite(d))
    reason[bad_range] = Reason.OUT_OF_RANGE
    reason[live & ~bad_range & moving] = Reason.NOT_CONVERGED
    valid = reason == Reason.OK
    valid &= np.isfinite(px) & np.isfinite(py) & np.isfinite(sigma) & np.isfinite(theta)
    nan = np.nan
    points = Points(
        x=np.where(valid, px, nan), y=np.where(valid, py, nan), d=np.where(valid, d, nan),
        theta=np.where(valid, theta, nan),
        origin_x=np.array(origin[..., 0]), origin_y=np.array(origin[..., 1]),
        heading=np.array(heading), sigma_m=np.where(valid, sigma, nan),
        iterations=iterations, valid=valid, reason=reason, max_range_m=max_range)
    if found is not None:  # labels: the line each reading took θ from (−1: none)
        found = replace(found, label=np.where(on_line, line_of, -1))
    return Estimate(points=points, lines=found, theta_history=tuple(history))


def _members(found: Lines, usable: np.ndarray, px: np.ndarray, py: np.ndarray,
             sigma: np.ndarray, opts: LineOptions) -> np.ndarray:
    """(S, N) line index giving each reading its θ, or −1: a reading keeps its own usable
    line only if it sits on it (within the split threshold; the last readings past a
    corner often do not)."""
    label = found.label
    good = (label >= 0) & usable
    good[good] = found.usable[label[good]]
    thr = np.maximum(opts.min_split_m, opts.split_sigmas * sigma)
    lg = label[good]
    off = np.abs((px[good] - found.centroid[lg, 0]) * found.normal[lg, 0]
                 + (py[good] - found.centroid[lg, 1]) * found.normal[lg, 1]) > thr[good]
    good[good] = ~off
    return np.where(good, label, -1)


def _settle_corners(line_of: np.ndarray, found: Lines, scan: np.ndarray, cal: Calibration,
                    s_safe: np.ndarray, origin: np.ndarray, ux: np.ndarray, uy: np.ndarray,
                    px: np.ndarray, py: np.ndarray, sigma: np.ndarray, theta_reject: float,
                    opts: LineOptions) -> np.ndarray:
    """Readings at the ends of their run go to whichever line explains them best.

    Near a corner both walls' lines pass close to the first readings past it, and a reading
    read with the wrong wall's θ can land on that wall's extension (a self-consistent but
    wrong answer). Each reading within ``opts.corner_window`` readings of either end of its
    run (same line, same sensor, consecutive in the scan) is re-read with every usable
    line's θ (see :func:`_fit_to_lines`) and put on the line it then lies closest to.
    """
    m = scan.size
    if m == 0 or not found.usable.any():
        return line_of
    n_sensors = line_of.shape[1]
    seq = line_of.reshape(-1)[scan]
    sens = scan % n_sensors
    at = np.arange(m)
    new_run = np.ones(m, dtype=bool)
    new_run[1:] = (seq[1:] != seq[:-1]) | (sens[1:] != sens[:-1])
    run_start = np.maximum.accumulate(np.where(new_run, at, 0))
    end_run = np.ones(m, dtype=bool)
    end_run[:-1] = new_run[1:]
    run_end = np.minimum.accumulate(np.where(end_run, at, m - 1)[::-1])[::-1]
    edge = (seq >= 0) & (np.minimum(at - run_start, run_end - at) < opts.corner_window)
    if not edge.any():
        return line_of
    idx = scan[edge]
    lines_idx, r, _ = _fit_to_lines(idx, found, cal, s_safe, origin, ux, uy, px, py,
                                    theta_reject, opts, own=seq[edge])
    best = np.argmin(r, axis=1)
    rows = np.arange(idx.size)
    own_col = np.searchsorted(lines_idx, seq[edge])
    own_ok = (own_col < lines_idx.size) & (lines_idx[np.minimum(own_col, lines_idx.size - 1)]
                                          == seq[edge])
    r_own = np.where(own_ok, r[rows, np.minimum(own_col, lines_idx.size - 1)], np.inf)
    # switch only for a clear gain (noise alone must not shuffle readings between lines)
    sig = sigma.reshape(-1)[idx]
    thr = np.maximum(opts.min_split_m, opts.split_sigmas * sig)
    ok = (r[rows, best] <= thr) & (r[rows, best] < r_own - opts.corner_sigmas * sig)
    out = line_of.copy()
    out.reshape(-1)[idx[ok]] = lines_idx[best[ok]]
    return out


def _fit_to_lines(idx: np.ndarray, found: Lines, cal: Calibration, s_safe: np.ndarray,
                  origin: np.ndarray, ux: np.ndarray, uy: np.ndarray, px: np.ndarray,
                  py: np.ndarray, theta_reject: float, opts: LineOptions,
                  own: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Readings ``idx`` (flat) against every usable line, each reading re-read with that
    line's θ: returns (line indices (L,), |perpendicular residual| (U, L), θ (U, L)).

    A line counts only if the reading's point lies within ``opts.adopt_margin_m`` of the
    line's extent (its own line, ``own``, always counts) and the beam meets it no steeper than
    ``theta_reject``; other entries are inf.
    """
    usable = np.flatnonzero(found.usable)
    n = found.normal[usable]                                            # (L, 2)
    u = np.stack([ux.reshape(-1)[idx], uy.reshape(-1)[idx]], axis=-1)   # (U, 2)
    cos_t = np.abs(u @ n.T)                                             # (U, L)
    sin_t = np.abs(u[:, 1:2] * n[None, :, 0] - u[:, 0:1] * n[None, :, 1])
    th = np.arctan2(sin_t, cos_t)
    d = cal.distance(s_safe.reshape(-1)[idx][:, None], np.minimum(th, cal.max_incidence_rad))
    o = origin.reshape(-1, 2)[idx]
    c = found.centroid[usable]
    qx = o[:, 0:1] + d * u[:, 0:1] - c[:, 0]
    qy = o[:, 1:2] + d * u[:, 1:2] - c[:, 1]
    r = np.abs(qx * n[:, 0] + qy * n[:, 1])
    # extent of each line along its direction, from its end readings
    dirs = found.direction[usable]
    sx, sy = px.reshape(-1)[found.start[usable]], py.reshape(-1)[found.start[usable]]
    ex, ey = px.reshape(-1)[found.end[usable]], py.reshape(-1)[found.end[usable]]
    t0 = (sx - c[:, 0]) * dirs[:, 0] + (sy - c[:, 1]) * dirs[:, 1]
    t1 = (ex - c[:, 0]) * dirs[:, 0] + (ey - c[:, 1]) * dirs[:, 1]
    lo = np.minimum(t0, t1) - opts.adopt_margin_m
    hi = np.maximum(t0, t1) + opts.adopt_margin_m
    t = qx * dirs[:, 0] + qy * dirs[:, 1]
    near = (t >= lo) & (t <= hi)
    if own is not None:
        near |= usable[None, :] == own[:, None]
    r = np.where(near & np.isfinite(r) & (th <= theta_reject), r, np.inf)
    return usable, r, th


def _incidence(found: Lines, line_of: np.ndarray, ux: np.ndarray, uy: np.ndarray
               ) -> np.ndarray:
    """(S, N) angle between each reading's beam and its line's normal (0 off any line)."""
    on = line_of >= 0
    nx = np.zeros(line_of.shape)
    ny = np.zeros(line_of.shape)
    nx[on] = found.normal[line_of[on], 0]
    ny[on] = found.normal[line_of[on], 1]
    return np.where(on, np.arctan2(np.abs(nx * uy - ny * ux), np.abs(nx * ux + ny * uy)), 0.0)


def _drop_steep(found: Lines, line_of: np.ndarray, usable: np.ndarray, ux: np.ndarray,
                uy: np.ndarray, theta_cap: float, theta_reject: float
                ) -> tuple[Lines, np.ndarray]:
    """A line the beam would meet past the drop-out angle cannot be what it saw.

    A reading whose line it meets steeper than ``theta_reject`` leaves it. A line that most
    of its readings meet at or past the drop-out angle ``theta_cap`` (less 2°) is not a
    surface: a radial streak (readings off a thin cylinder's edge, stretched along the
    beams by θ = 0) or a runaway (θ up → d down → the line turns radial → θ up, which a
    curve whose a(θ) falls with θ allows on a cylinder's face). A real wall that steep would
    return nothing. Such a line is dropped (for good while the grouping is held).
    """
    good = (line_of >= 0) & usable
    good[good] = found.usable[line_of[good]]
    line_of = np.where(good, line_of, -1)
    theta_line = _incidence(found, line_of, ux, uy)
    steep = good & (theta_line > theta_reject)
    # readings pinned at the drop-out angle are as suspect: a real wall that steep returns
    # nothing, while a runaway (θ up → d down → the line turns radial → θ up) ends there
    pinned = good & (theta_line >= theta_cap - _PINNED_RAD)
    if pinned.any():
        n_lines = found.normal.shape[0]
        frac = (np.bincount(line_of[pinned], minlength=n_lines)
                / np.maximum(np.bincount(line_of[good], minlength=n_lines), 1))
        streak = frac > 0.5
        if streak.any():
            found = replace(found, usable=found.usable & ~streak)
            good[good] = ~streak[line_of[good]]
    good &= ~steep
    return found, np.where(good, line_of, -1)


def _adopt(line_of: np.ndarray, orphan: np.ndarray, found: Lines, cal: Calibration,
           s_safe: np.ndarray, origin: np.ndarray, ux: np.ndarray, uy: np.ndarray,
           px: np.ndarray, py: np.ndarray, sigma: np.ndarray, theta_reject: float,
           opts: LineOptions) -> np.ndarray:
    """Readings on no usable line join one if, read with that line's θ, they land on it.

    These are mostly readings next to a corner, which θ = 0 put off both walls, and the last
    few readings of a sweep past a corner (the neighbouring sensor sees that wall). Every
    orphan is tried against every usable line at once ((orphans, lines) arrays; both are
    few): it joins the nearest within the split threshold and near the line's extent.
    """
    if not orphan.any() or not found.usable.any():
        return line_of
    sel = np.flatnonzero(orphan.reshape(-1))
    lines_idx, r, _ = _fit_to_lines(sel, found, cal, s_safe, origin, ux, uy, px, py,
                                    theta_reject, opts)
    thr = np.maximum(opts.min_split_m, opts.split_sigmas * sigma.reshape(-1)[sel])
    r = r / thr[:, None]
    best = np.argmin(r, axis=1)
    ok = r[np.arange(sel.size), best] <= 1.0
    out = line_of.copy()
    out.reshape(-1)[sel[ok]] = lines_idx[best[ok]]
    return out


def _refit(prev: Lines, line_of: np.ndarray, px: np.ndarray, py: np.ndarray,
           usable: np.ndarray) -> Lines:
    """The same members, lines refitted at their moved positions (vectorised by bincount)."""
    n_lines = prev.normal.shape[0]
    if n_lines == 0:
        return prev
    lab = line_of.reshape(-1)
    use = (lab >= 0) & usable.reshape(-1)
    l = lab[use]
    x, y = px.reshape(-1)[use], py.reshape(-1)[use]
    cx, cy = (float(np.mean(x)), float(np.mean(y))) if x.size else (0.0, 0.0)
    x, y = x - cx, y - cy

    def tot(w):
        return np.bincount(l, weights=w, minlength=n_lines)

    n = tot(np.ones_like(x))
    c, normal, direction, lmin, lmax = _tls(tot(x), tot(y), tot(x * x), tot(y * y), tot(x * y), n)
    fitted = n >= 2
    # keep the previous orientation's sign so normals do not flip between iterations
    normal = np.where(fitted[:, None], normal, prev.normal)
    direction = np.where(fitted[:, None], direction, prev.direction)
    return replace(prev, label=line_of, centroid=np.where(fitted[:, None], c + [cx, cy],
                                                          prev.centroid),
                   normal=normal, direction=direction,
                   rms_m=np.where(fitted, np.sqrt(lmin), prev.rms_m),
                   usable=prev.usable & fitted & (lmax > 0))
