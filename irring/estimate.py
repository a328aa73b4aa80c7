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

Schedule (how steps 2–6 are repeated; the work goes where it changes the answer):

- *grouping* (step 4 in full) at θ = 0: split-and-merge, corners refined, then each reading
  judged against its piece's line (it must lie on it), readings near a corner re-read with
  every nearby line's θ and put on the line that explains them clearly best, lines the beams
  would meet past the drop-out angle dropped, readings on no line adopted by a line they land
  on when re-read with its θ. θ is then taken from the members' own TLS lines;
- *held iterations*: the members stay, so every member's θ follows from its line's direction
  a (θ_i = |π/2 − |h_i − a||); one iteration fits all lines at once (prefix sums over the
  members sorted by line) and moves a. The plain step is Table II's a ← G(a); with damping on
  (the default) it is a secant step on G(a) − a per line, its gain held to [1/64, 8]: it damps
  an oscillation (G' < 0) and speeds up a slow contraction, and stays plain where G' ≥ 1;
- *regrouping*: once θ has settled coarsely (every step < ``regroup_until_rad``), and in any
  case after the first convergence, the readings are grouped again at their straightened
  positions: the pieces are kept, their corners refined again and membership judged afresh.
  This repeats while it changes who belongs where (not back to the grouping before), up to
  ``regroup_iterations`` groupings in all (the one at θ = 0 included; a third or later only
  within the first 8 iterations, so late regroups cannot keep a corner from settling);
- *membership checks*: when the held iterations settle, the members are checked once more at
  their final positions (a wall ends at its corner: a reading on a line beyond its
  intersection with the next piece's line moves across if it fits there; drop-outs;
  adoptions), and iterated again if that changed anything.

Readings still moving after ``max_iterations`` are NOT_CONVERGED (in the noisy T-room about
0.3 % of readings, mostly where a shoulder's convex corner is seen nearly edge-on).

Fallback: a reading on no usable line (a thin cylinder, an isolated return, a line shorter
than ``LineOptions.min_length_m`` or with fewer than ``min_points`` readings) keeps θ = 0, the
paper's starting assumption. Its θ is unknown, so its ``sigma_m`` includes the RMS error of
the θ = 0 distance over the incidences a round surface gives (sin θ uniform up to the
drop-out angle): ≈ 17 / 39 / 63 mm at 0.2 / 0.4 / 0.6 m on the GP2D12 curve.

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

import functools
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import yaml

from . import _lines
from .data import Points, Reason, Sweep, beam_geometry
from .scenario import Ring

CALIBRATION_FORMAT = 1  # version written into calibration files
_SIGMA_FLOOR_M = 0.001  # no reading is trusted better than 1 mm
_FINE_CELLS = 1 << 16  # cells of the fine (log a, b) table over 0 … 90°
_FALLBACK_NODES = 8   # quadrature nodes for the fallback σ (see _fallback_spread)
_REGROUP_WINDOW = 8  # a third or later grouping only within the first 8 iterations
_MAX_GAIN = 8.0      # the held iteration's secant step at most 8× the plain one
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
        object.__setattr__(self, "_levels", (self.full_scale_counts, self.near_counts,
                                             self.no_return_counts, self.sigma_counts(),
                                             self.falling))
        # (log a, b) on a fine θ grid for the estimator's loop, looked up at the nearest
        # node (a take instead of a search): θ off by ≤ 1.2e-5 rad, d by < 1e-4 relative
        fine = np.linspace(0.0, math.pi / 2, _FINE_CELLS + 1)
        object.__setattr__(self, "_fine", (_FINE_CELLS / (math.pi / 2),
                                           np.interp(fine, theta, np.log(a)),
                                           np.interp(fine, theta, b)))

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


def _tls_angle(n, t):
    """Total-least-squares lines from summed centred moments t = (Σx, Σy, Σx², Σy², Σxy)
    over n points (arrays): mean offset (mx, my) and direction angle α ∈ (−π/2, π/2]."""
    mx = t[0] / n
    my = t[1] / n
    sxy = t[4] - t[0] * my
    dif = (t[2] - t[0] * mx) - (t[3] - t[1] * my)
    alpha = np.arctan2(sxy + sxy, dif)
    alpha *= 0.5
    return mx, my, alpha


def _lengths(first: np.ndarray, total: int) -> np.ndarray:
    """Lengths of the runs starting at ``first`` (ascending) in a sequence of ``total``."""
    n = np.empty(first.size)
    np.subtract(first[1:], first[:-1], out=n[:-1])
    n[-1] = total - first[-1]
    return n


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
    each piece's TLS line: one call of the compiled kernel ``irring._lines.segment``.

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
    T-room: regrouping by corner refinement alone gives the smaller range error).

    The kernel gives the numpy version's answers bit for bit (irring/_lines.pyx says how)
    in ~1/17 of its time: 0.77–0.85 → 0.044–0.064 ms per t_room sweep (median per sweep;
    ``irring bench speed``: estimator 3.15 → 2.5–2.6 ms)."""
    f = np.ascontiguousarray
    return _Pieces(*_lines.segment(
        f(px, dtype=float), f(py, dtype=float), f(thr, dtype=float), f(sensor, dtype=np.intp),
        opts.gap_m ** 2, float(centre[0]), float(centre[1]),
        *((None, None, None) if prev is None else (prev.starts, prev.ends, prev.brk)),
        opts.split_sigmas, opts.min_points, opts.min_length_m, opts.max_rms_sigmas))


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
    """Reasons decided by the counts alone (before any distance is computed). Assigned from
    the weakest claim up, so MISSING > SATURATED > FOLDOVER_AMBIGUOUS > NO_RETURN."""
    full, near, no_return, sigma, falling = cal._levels
    s = counts
    reason = np.zeros(s.shape, dtype=np.uint8)
    margin = 2.0 * sigma
    if falling:
        reason[(s <= no_return + margin) | (s <= 0)] = Reason.NO_RETURN
        reason[s > near] = Reason.FOLDOVER_AMBIGUOUS
    else:  # a linear sensor (sonar/laser hooks): no fold-over, no return reads as max range
        reason[(s >= no_return - margin) | (s <= 0)] = Reason.NO_RETURN
    reason[s >= full - 0.5] = Reason.SATURATED
    reason[~np.isfinite(s)] = Reason.MISSING
    if sweep.missing_steps:
        rows = np.isin(np.asarray(sweep.steps), np.asarray(sweep.missing_steps))
        reason[rows, :] = Reason.MISSING
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


def _incidence(hm: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Angle between beams (heading mod π) and the normals of lines at direction angle α
    (in [0, π)): with δ = h − α, cos θ = |sin δ|, so θ = |π/2 − |δ||."""
    return np.abs(_HALF_PI - np.abs(hm - alpha))


_HALF_PI = math.pi / 2
_INV_PI = 1.0 / math.pi


class _Sweep:
    """One sweep's live readings in scan order (sensor by sensor, by step), and the
    calibration's curve, for the loop: everything per reading that θ does not change."""

    def __init__(self, cal: Calibration, counts, origin, heading, live, steps, opts):
        n_sensors = counts.shape[1]
        scan = _scan_order(steps, n_sensors)
        pos = live.reshape(-1).take(scan).nonzero()[0]      # places in the scan order
        self.index = sel = scan.take(pos)                     # flat (S, N) index of each
        self.k = sel.size
        self.sensor = sel % n_sensors
        # runs for the corner check break at a sensor change or a reading that is not live
        self.run_brk = np.ones(self.k, dtype=bool)
        if self.k > 1:
            self.run_brk[1:] = (self.sensor[1:] != self.sensor[:-1]) | (pos[1:] != pos[:-1] + 1)
        self.counts = counts.reshape(-1).take(sel)
        self.log_s = np.log(self.counts)
        self.ox = origin[..., 0].reshape(-1).take(sel)
        self.oy = origin[..., 1].reshape(-1).take(sel)
        h = heading.reshape(-1).take(sel)
        self.ux, self.uy = np.cos(h), np.sin(h)
        self.hm = h - math.pi * np.floor(h / math.pi)         # heading mod π
        self.centre = ((float(self.ox.sum()) / self.k, float(self.oy.sum()) / self.k) if self.k
                       else (0.0, 0.0))
        self.at = np.arange(self.k)
        self.cal = cal
        self.sig_s = cal._levels[3] / self.counts             # σ_d = |b|·d·σ_S/S
        self.inv_h, self.la_t, self.b_t = cal._fine
        self.opts = opts
        self.cap = cal.max_incidence_rad
        self.reject = self.cap + opts.incidence_margin_rad

    def ab(self, theta: np.ndarray):
        """log a(θ), b(θ) from the fine table (θ in [0, π/2])."""
        i = (theta * self.inv_h + 0.5).astype(np.intp)
        return self.la_t.take(i), self.b_t.take(i)

    def points(self, theta: np.ndarray):
        """d, x, y, σ of every live reading at incidence θ."""
        la, b = self.ab(theta)
        d = np.exp(la + b * self.log_s)
        sigma = np.maximum(np.abs(b) * d * self.sig_s, _SIGMA_FLOOR_M)
        return d, self.ox + d * self.ux, self.oy + d * self.uy, sigma

    def thresholds(self, sigma: np.ndarray) -> np.ndarray:
        return np.maximum(self.opts.min_split_m, self.opts.split_sigmas * sigma)


class _Grouping:
    """The lines of the current iteration and which reading takes θ from which line."""

    def __init__(self, sw: _Sweep, pieces: _Pieces, uidx: np.ndarray | None):
        self.sw = sw
        self.pieces = pieces
        self.uidx = uidx                 # compact index of each usable point (None: all)
        self.cx, self.cy = pieces.cx.copy(), pieces.cy.copy()
        self.alpha = pieces.alpha.copy()
        self.usable = pieces.usable.copy()
        self.first = pieces.starts if uidx is None else uidx.take(pieces.starts)
        self.last = pieces.ends if uidx is None else uidx.take(pieces.ends)
        self.n_lines = pieces.starts.size
        self.label = np.full(sw.k, -1, dtype=np.intp)   # line of each live reading
        self._tab = None

    # ---- membership

    def members(self, px, py, thr) -> None:
        """Each reading keeps its own usable line only if it sits on it (within the split
        threshold; the last readings past a corner often do not)."""
        own = self.pieces.owner
        a = self.alpha.take(own)
        if self.uidx is None:
            x, y, t = px, py, thr
        else:
            x, y, t = px.take(self.uidx), py.take(self.uidx), thr.take(self.uidx)
        r = np.abs((y - self.cy.take(own)) * np.cos(a) - (x - self.cx.take(own)) * np.sin(a))
        ok = (r <= t) & self.usable.take(own)
        lab = np.where(ok, own, -1)
        if self.uidx is None:
            self.label = lab
        else:
            self.label = np.full(self.sw.k, -1, dtype=np.intp)
            self.label[self.uidx] = lab

    def table(self, px, py):
        """The usable lines for re-reading: (indices, α, centroid x, y, direction x, y,
        extent along the line from its end readings ± adopt_margin_m, column of each line)."""
        if self._tab is None:
            use = self.usable.nonzero()[0]
            a, cx, cy = self.alpha.take(use), self.cx.take(use), self.cy.take(use)
            dx, dy = np.cos(a), np.sin(a)
            f, l = self.first.take(use), self.last.take(use)
            t0 = (px.take(f) - cx) * dx + (py.take(f) - cy) * dy
            t1 = (px.take(l) - cx) * dx + (py.take(l) - cy) * dy
            m = self.sw.opts.adopt_margin_m
            col = np.full(self.n_lines + 1, -1)
            col[use] = np.arange(use.size)
            self._tab = (use, a, cx, cy, dx, dy, np.minimum(t0, t1) - m, np.maximum(t0, t1) + m,
                         col)
        return self._tab

    def fit_to(self, idx, px, py, own=None):
        """Readings ``idx`` against every usable line, each re-read with that line's θ:
        (line indices (L,), |perpendicular residual| (U, L)). A line counts only if the
        reading lands within ``adopt_margin_m`` of its extent (its own line, ``own``, always
        counts) and the beam meets it no steeper than the rejection angle; else inf."""
        sw = self.sw
        use, a, cx, cy, dx, dy, lo, hi, col = self.table(px, py)
        th = _incidence(sw.hm.take(idx)[:, None], a)                      # (U, L)
        la, b = sw.ab(np.minimum(th, sw.cap))
        d = np.exp(la + b * sw.log_s.take(idx)[:, None])
        qx = d * sw.ux.take(idx)[:, None]
        qx += sw.ox.take(idx)[:, None] - cx
        qy = d * sw.uy.take(idx)[:, None]
        qy += sw.oy.take(idx)[:, None] - cy
        r = np.abs(qy * dx - qx * dy)
        t = qx * dx + qy * dy
        far = (t < lo) | (t > hi)
        if own is not None:
            far[np.arange(idx.size), col.take(own)] = False
        far |= th > sw.reject
        r[far] = np.inf
        return use, r

    def settle_corners(self, px, py, sigma, thr) -> None:
        """Readings at the ends of their run go to whichever line explains them best.

        Near a corner both walls' lines pass close to the first readings past it, and a
        reading read with the wrong wall's θ can land on that wall's extension (a
        self-consistent but wrong answer). Each reading within ``corner_window`` readings of
        either end of its run (same line, same sensor, consecutive in the scan) is re-read
        with every usable line's θ (see :meth:`fit_to`) and put on the line it then lies
        closest to, if that is clearly better than its own.
        """
        sw = self.sw
        k = sw.k
        if k == 0 or not self.usable.any():
            return
        seq = self.label
        at = sw.at
        new_run = sw.run_brk.copy()
        new_run[1:] |= seq[1:] != seq[:-1]
        run_start = np.maximum.accumulate(np.where(new_run, at, 0))
        end_run = np.ones(k, dtype=bool)
        end_run[:-1] = new_run[1:]
        run_end = np.minimum.accumulate(np.where(end_run, at, k - 1)[::-1])[::-1]
        edge = (np.minimum(at - run_start, run_end - at) < sw.opts.corner_window) & (seq >= 0)
        idx = edge.nonzero()[0]
        if idx.size == 0:
            return
        own = seq.take(idx)
        use, r = self.fit_to(idx, px, py, own=own)
        rows = np.arange(idx.size)
        best = r.argmin(axis=1)
        r_best = r[rows, best]
        r_own = r[rows, self._tab[8].take(own)]
        # switch only for a clear gain (noise alone must not shuffle readings between lines)
        ok = (r_best <= thr.take(idx)) & (r_best < r_own - sw.opts.corner_sigmas * sigma.take(idx))
        if ok.any():
            seq = seq.copy()
            seq[idx[ok]] = use.take(best[ok])
            self.label = seq

    def corner_sides(self, px, py, thr) -> None:
        """A wall ends at its corner: a reading on a line beyond the corner it shares with
        the next piece of the same sweep (past the two lines' intersection) is not on it.

        Next to a corner a reading read with the wrong wall's θ lands on that wall's
        extension, self-consistently, and fits both lines about as well; where it lands
        tells them apart. Such a reading moves to the line across the corner if, read with
        that line's θ, it lies on it (within the split threshold) and on its side.
        """
        pc = self.pieces
        j = ((pc.starts[1:] == pc.ends[:-1]) & self.usable[:-1] & self.usable[1:]).nonzero()[0]
        if j.size == 0:
            return
        a0, a1 = self.alpha.take(j), self.alpha.take(j + 1)
        ok = np.abs(np.sin(a1 - a0)) > 0.5      # lines meeting at > 30°: a real corner
        if not ok.any():
            return
        j, a0, a1 = j[ok], a0[ok], a1[ok]
        m = j.size
        # both sides of every corner: the line, the other line, directions
        line = np.concatenate([j, j + 1])
        other = np.concatenate([j + 1, j])
        aa = np.concatenate([a0, a1])
        dx, dy = np.cos(aa), np.sin(aa)
        cx, cy = self.cx.take(line), self.cy.take(line)
        # intersection X = c0 + s·d0 with (X − c1) × d1 = 0
        s0 = (((cx[m:] - cx[:m]) * dy[m:] - (cy[m:] - cy[:m]) * dx[m:])
              / (dx[:m] * dy[m:] - dy[:m] * dx[m:]))
        X = cx[:m] + s0 * dx[:m]
        Y = cy[:m] + s0 * dy[:m]
        X = np.concatenate([X, X])
        Y = np.concatenate([Y, Y])
        bulk = np.sign((cx - X) * dx + (cy - Y) * dy)   # the side each line's readings are on
        pos = np.full(self.n_lines, -1)
        pos[line] = np.arange(line.size)   # a line with corners at both ends: one of them
        lab = self.label
        c = pos.take(lab)                  # lab −1 → pos[−1]: the last line's entry or −1
        c[lab < 0] = -1
        mem = (c >= 0).nonzero()[0]
        if mem.size == 0:
            return
        c = c.take(mem)
        beyond = ((px.take(mem) - X.take(c)) * dx.take(c)
                  + (py.take(mem) - Y.take(c)) * dy.take(c)) * bulk.take(c) < 0
        if not beyond.any():
            return
        mem, c = mem[beyond], c[beyond]
        tgt = other.take(c)
        _, r = self.fit_to(mem, px, py)
        col = self._tab[8].take(tgt)
        move = (col >= 0) & (r[np.arange(mem.size), col] <= thr.take(mem))
        if not move.any():
            return
        # read with the target's θ the reading must land on the target's side of the corner
        mem, c, tgt = mem[move], c[move], tgt[move]
        sw = self.sw
        c2 = (c + m) % (2 * m)                       # the target's entry (the other side)
        th = _incidence(sw.hm.take(mem), aa.take(c2))
        la, b = sw.ab(np.minimum(th, sw.cap))
        d = np.exp(la + b * sw.log_s.take(mem))
        side = ((sw.ox.take(mem) + d * sw.ux.take(mem) - X.take(c2)) * dx.take(c2)
                + (sw.oy.take(mem) + d * sw.uy.take(mem) - Y.take(c2)) * dy.take(c2))
        ok = side * bulk.take(c2) >= 0
        if ok.any():
            lab = lab.copy()
            lab[mem[ok]] = tgt[ok]
            self.label = lab

    def drop_steep(self, usable) -> None:
        """A line the beam would meet past the drop-out angle cannot be what it saw.

        A reading whose line it meets steeper than the rejection angle leaves it. A line that
        most of its readings meet at or past the drop-out angle (less 2°) is not a surface: a
        radial streak (readings off a thin cylinder's edge, stretched along the beams by
        θ = 0) or a runaway (θ up → d down → the line turns radial → θ up, which a curve whose
        a(θ) falls with θ allows on a cylinder's face). A real wall that steep would return
        nothing. Such a line is dropped.
        """
        sw = self.sw
        label = self.label
        lab = np.maximum(label, 0)
        good = (label >= 0) & self.usable.take(lab)
        if usable is not None:
            good &= usable
        theta_line = _incidence(sw.hm, self.alpha.take(lab))
        pinned = good & (theta_line >= sw.cap - _PINNED_RAD)
        if pinned.any():
            frac = (np.bincount(lab[pinned], minlength=self.n_lines)
                    / np.maximum(np.bincount(lab[good], minlength=self.n_lines), 1))
            streak = frac > 0.5
            if streak.any():
                self.usable &= ~streak
                self._tab = None
                good &= ~streak.take(lab)
        good &= theta_line <= sw.reject
        if not good.all():
            self.label = np.where(good, label, -1)

    def adopt(self, usable, px, py, thr) -> None:
        """Readings on no usable line join one if, read with that line's θ, they land on it.

        These are mostly readings next to a corner, which θ = 0 put off both walls, and the
        last few readings of a sweep past a corner (the neighbouring sensor sees that wall).
        Every orphan is tried against every usable line at once ((orphans, lines) arrays;
        both are few): it joins the nearest within the split threshold and near the line's
        extent.
        """
        orphan = self.label < 0
        if usable is not None:
            orphan &= usable
        sel = orphan.nonzero()[0]
        if sel.size == 0 or not self.usable.any():
            return
        use, r = self.fit_to(sel, px, py)
        r /= thr.take(sel)[:, None]
        best = r.argmin(axis=1)
        ok = r[np.arange(sel.size), best] <= 1.0
        if ok.any():
            self.label = self.label.copy()
            self.label[sel[ok]] = use.take(best[ok])

    def refit(self, usable, px, py) -> None:
        """The same members, lines refitted at their moved positions; a line left with
        fewer than two members keeps its fit but gives θ no more."""
        lab = self.label
        on = lab >= 0
        if usable is not None:
            on &= usable
        mem = on.nonzero()[0]
        self._tab = None
        if mem.size == 0:
            self.usable[:] = False
            return
        l = lab.take(mem)
        order = l.argsort(kind="stable")
        mem, l = mem.take(order), l.take(order)
        new = np.empty(l.size, dtype=bool)
        new[0] = True
        np.not_equal(l[1:], l[:-1], out=new[1:])
        first = new.nonzero()[0]
        lines = l.take(first)
        cx0, cy0 = self.sw.centre
        buf = np.empty((5, mem.size))
        np.subtract(px.take(mem), cx0, out=buf[0])
        np.subtract(py.take(mem), cy0, out=buf[1])
        np.multiply(buf[0], buf[0], out=buf[2])
        np.multiply(buf[1], buf[1], out=buf[3])
        np.multiply(buf[0], buf[1], out=buf[4])
        n = _lengths(first, mem.size)
        t = np.add.reduceat(buf, first, axis=1)
        mx, my, alpha = _tls_angle(n, t)
        # a line needs two members with some spread (all coincident: no direction)
        fitted = (n >= 2) & ((t[2] - t[0] * mx) + (t[3] - t[1] * my) > 0)
        keep = np.zeros(self.n_lines, dtype=bool)
        keep[lines[fitted]] = True
        lf = lines[fitted]
        self.cx = self.cx.copy()
        self.cy = self.cy.copy()
        self.alpha = self.alpha.copy()
        self.cx[lf] = mx[fitted] + cx0
        self.cy[lf] = my[fitted] + cy0
        alpha = alpha[fitted]
        alpha[alpha < 0] += math.pi
        self.alpha[lf] = alpha
        self.usable &= keep

    def theta_new(self):
        """(θ from each reading's line, capped (0 off any line), θ of the line uncapped)."""
        sw = self.sw
        on = self.label >= 0
        theta_line = np.where(on, _incidence(sw.hm, self.alpha.take(np.maximum(self.label, 0))),
                              0.0)
        return np.minimum(theta_line, sw.cap), theta_line


class _Held:
    """The iteration with held membership, in line order: each line's members' θ follow from
    one direction angle a (θ_i = |π/2 − |h_i − a||), so a step is: points at θ(a) → TLS
    angle G(a) of every line at once (np.add.reduceat over the members sorted by line) →
    new a. With ``secant`` the step is a safeguarded secant step on G(a) − a per line."""

    def __init__(self, sw: _Sweep, grouping: _Grouping, theta: np.ndarray, secant: bool):
        label = grouping.label
        mem = (label >= 0).nonzero()[0]
        lm = label.take(mem)
        order = np.argsort(lm, kind="stable")
        self.perm = perm = mem.take(order)
        lm = lm.take(order)
        self.km = km = perm.size
        new = np.ones(km, dtype=bool)
        np.not_equal(lm[1:], lm[:-1], out=new[1:])
        self.lstart = new.nonzero()[0]
        self.line = lm.take(self.lstart)                 # grouping line index of each slot
        self.slot = new.cumsum() - 1
        self.n = _lengths(self.lstart, km)
        lone = self.n < 2                                 # a lone member keeps its line's θ
        self.lone = lone if lone.any() else None
        cx0, cy0 = sw.centre
        self.hm = sw.hm.take(perm)
        self.log_s = sw.log_s.take(perm)
        self.ox, self.oy = sw.ox.take(perm) - cx0, sw.oy.take(perm) - cy0
        self.ux, self.uy = sw.ux.take(perm), sw.uy.take(perm)
        self.buf = np.empty((5, km))
        self.a = grouping.alpha.take(self.line)
        self.theta = theta.take(perm)
        self.sw = sw
        self.secant = secant
        self.a_prev = self.g_prev = None

    def fit(self):
        """Fit every line to its members' points at the current θ: returns (members' step
        θ_new − θ, θ of their lines uncapped)."""
        sw = self.sw
        la, b = sw.ab(self.theta)
        d = np.exp(la + b * self.log_s)
        buf = self.buf
        x, y = buf[0], buf[1]
        np.multiply(d, self.ux, out=x)
        x += self.ox
        np.multiply(d, self.uy, out=y)
        y += self.oy
        np.multiply(x, x, out=buf[2])
        np.multiply(y, y, out=buf[3])
        np.multiply(x, y, out=buf[4])
        _, _, g_out = _tls_angle(self.n, np.add.reduceat(buf, self.lstart, axis=1))
        g_out[g_out < 0.0] += math.pi
        if self.lone is not None:
            g_out[self.lone] = self.a[self.lone]
        self.g_out = g_out
        theta_line = _incidence(self.hm, g_out.take(self.slot))
        return np.minimum(theta_line, sw.cap) - self.theta, theta_line

    def advance(self) -> None:
        """The next a: the plain step a ← G(a), or (``secant``) a secant step towards the
        root of g(a) = G(a) − a from this and the previous iteration, its gain held to
        [1/64, 8]: below 1 it damps an oscillation (G' < 0), above 1 it speeds up a slow
        contraction (0 < G' < 1); where G' ≥ 1 (a runaway) the step stays plain."""
        g = self.g_out - self.a
        g -= math.pi * np.rint(g * _INV_PI)
        a = self.a
        if self.secant and self.a_prev is not None:
            da = a - self.a_prev
            da -= math.pi * np.rint(da * _INV_PI)
            dg = self.g_prev - g
            # gain −1/slope with slope = (g − g_prev)/da: only where the slope is negative
            ok = dg * da > 0.0
            gain = np.ones_like(g)
            gain[ok] = np.minimum(np.maximum(da[ok] / dg[ok], 1.0 / 64.0), _MAX_GAIN)
            self.a_prev, self.g_prev = a, g
            a = a + gain * g
        else:
            self.a_prev, self.g_prev = a, g
            a = a + g
        a -= math.pi * np.floor(a * _INV_PI)
        self.a = a
        self.theta = np.minimum(_incidence(self.hm, a.take(self.slot)), self.sw.cap)


def estimate_detail(sweep: Sweep, calibration: Calibration | None = None, *,
                    max_iterations: int = 20, tolerance_rad: float = math.radians(0.1),
                    iterate: bool = True, lines: LineOptions = LineOptions(),
                    keep_history: bool = False, damping: bool = True) -> Estimate:
    """:func:`estimate` that also returns the final lines and (optionally) θ per iteration.

    ``damping=False`` switches the step control off: every step is the plain a ← G(a) of
    Table II (to show what the control is for).
    """
    cal = calibration if calibration is not None else _nominal_for(
        sweep.sensor_model, sweep.ring, sweep.adc_bits, sweep.vref_v)
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
    shape = counts.shape

    reason = _classify(counts, sweep, cal)
    live = reason == Reason.OK
    max_range = min(float(sweep.max_range_m), cal.max_range_m)
    sw = _Sweep(cal, counts, origin, heading, live, np.asarray(sweep.steps), lines)
    k = sw.k
    theta = np.zeros(k)
    last_moving = np.full(k, -1)        # last iteration in which each reading's θ moved
    history = [np.zeros(shape)] if keep_history else []
    grouping: _Grouping | None = None
    pieces: _Pieces | None = None
    held: _Held | None = None
    on_line = np.zeros(k, dtype=bool)
    regroups = 0
    regroup_changed = True
    older = None          # the labels two groupings ago
    mode = "regroup"
    it = 0
    settled = False
    while it < (max_iterations if iterate and k else 0):
        checked = False
        if mode != "inner":
            # a membership pass: regroup (split-and-merge anew), or check the members
            checked = True
            if held is not None:
                theta[held.perm] = held.theta
            d, px, py, sigma = sw.points(theta)
            thr = sw.thresholds(sigma)
            # readings far outside the range cannot help a line (but stay for the final check)
            usable = d <= 1.5 * max_range
            use_mask = None if bool(usable.all()) else usable
            before = None if grouping is None else grouping.label
            if mode == "regroup":
                uidx = None if use_mask is None else usable.nonzero()[0]
                parts = (px, py, thr, sw.sensor) if uidx is None else (
                    px.take(uidx), py.take(uidx), thr.take(uidx), sw.sensor.take(uidx))
                pieces = _segment(*parts, lines, sw.centre, pieces)
                grouping = _Grouping(sw, pieces, uidx)
                grouping.members(px, py, thr)
                grouping.settle_corners(px, py, sigma, thr)
                regroups += 1
            else:  # the same members, refitted where they now are
                grouping.refit(use_mask, px, py)
                grouping.corner_sides(px, py, thr)
            grouping.drop_steep(use_mask)
            grouping.adopt(use_mask, px, py, thr)
            changed = before is None or not np.array_equal(before, grouping.label)
            # θ from the members' own lines (as the held iterations fit them), so an unchanged
            # grouping leaves θ where it was
            if mode == "regroup" or changed:
                grouping.refit(use_mask, px, py)
            elif settled:
                break          # the members stand and their lines did not move: done
            if mode == "regroup":
                # regroup again only while that changes who belongs where, and not back to
                # the grouping before (readings at a corner flipping between two lines)
                regroup_changed = changed and not (
                    older is not None and np.array_equal(older, grouping.label))
                older = before
            mode = "inner"
            if changed or held is None:  # a plain step from the new grouping
                theta_new, _ = grouping.theta_new()
                moving = np.abs(theta_new - theta) >= tolerance_rad
                theta = theta_new
                on_line = grouping.label >= 0
                last_moving[moving] = it
                it += 1
                if keep_history:
                    history.append(_scatter(theta, sw.index, shape, 0.0))
                if not moving.any():
                    break
                held = _Held(sw, grouping, theta, secant=damping)
                continue
            # unchanged: this iteration is an ordinary held step
        step, theta_line = held.fit()
        hot = theta_line >= sw.cap - _PINNED_RAD
        if not checked and hot.any() and _needs_drop(held, hot, theta_line, sw):
            mode = "member"      # some member left its line: redo this iteration as a check
            continue
        moving = np.abs(step) >= tolerance_rad
        last_moving[held.perm[moving]] = it
        held.advance()
        it += 1
        settled = not moving.any()
        if keep_history:
            history.append(_scatter(theta, sw.index, shape, 0.0, held))
        if not moving.any():
            if regroups == 1 and regroups < lines.regroup_iterations:
                mode = "regroup"   # settled once: split-and-merge the straightened points again
            elif checked:
                break
            else:
                mode = "member"    # settled: a last look at who belongs where
        elif (regroup_changed and regroups < lines.regroup_iterations
              and (regroups == 1 or it < _REGROUP_WINDOW)
              and float(np.max(np.abs(step))) < lines.regroup_until_rad):
            mode = "regroup"       # θ has settled coarsely: group the straightened points again
    n_its = it
    if held is not None:
        theta[held.perm] = held.theta

    # final points with the exact curve
    s = sw.counts
    log_a, b = cal._log_ab(theta)
    d = np.exp(log_a + b * sw.log_s)
    sigma = np.maximum(np.abs(b) * d * sw.sig_s, _SIGMA_FLOOR_M)
    px, py = sw.ox + d * sw.ux, sw.oy + d * sw.uy
    if iterate:  # fallback readings (no line): θ = 0, σ widened by θ's unknown
        off = (~on_line).nonzero()[0]
        if off.size:
            sigma[off] = np.hypot(sigma.take(off), _fallback_spread(cal, s.take(off),
                                                                     d.take(off)))

    iterations = np.minimum(last_moving + 2, n_its)
    moving_at_end = last_moving == n_its - 1 if n_its else np.zeros(k, dtype=bool)
    bad_range = (d > max_range) | (d < cal.min_range_m) | ~np.isfinite(d)
    why = np.where(bad_range, np.uint8(Reason.OUT_OF_RANGE),
                   np.where(moving_at_end, np.uint8(Reason.NOT_CONVERGED), np.uint8(Reason.OK)))
    why = np.where(np.isfinite(px) & np.isfinite(py) & np.isfinite(sigma) | (why != Reason.OK),
                   why, np.uint8(Reason.OUT_OF_RANGE))
    reason.reshape(-1)[sw.index] = why
    valid = reason == Reason.OK
    it_out = np.full(shape, 1 if iterate else 0, dtype=np.int32)
    it_out.reshape(-1)[sw.index] = iterations
    nan = np.nan
    points = Points(
        x=_scatter(px, sw.index, shape, nan, mask=valid),
        y=_scatter(py, sw.index, shape, nan, mask=valid),
        d=_scatter(d, sw.index, shape, nan, mask=valid),
        theta=_scatter(theta, sw.index, shape, nan, mask=valid),
        origin_x=np.array(origin[..., 0]), origin_y=np.array(origin[..., 1]),
        heading=np.array(heading), sigma_m=_scatter(sigma, sw.index, shape, nan, mask=valid),
        iterations=it_out, valid=valid, reason=reason, max_range_m=max_range)
    found = None
    if grouping is not None:  # labels: the line each reading took θ from (−1: none)
        label = np.full(shape, -1, dtype=int)
        label.reshape(-1)[sw.index] = np.where(on_line, grouping.label, -1)
        pieces_out = replace(grouping.pieces, cx=grouping.cx, cy=grouping.cy,
                                         alpha=grouping.alpha, usable=grouping.usable)
        index = sw.index if grouping.uidx is None else sw.index.take(grouping.uidx)
        found = _lines_record(pieces_out, label, index)
    return Estimate(points=points, lines=found, theta_history=tuple(history))


@functools.lru_cache(maxsize=16)
def _nominal_for(sensor_model: str, ring: Ring | None, adc_bits: int, vref_v: float
                 ) -> Calibration:
    """:meth:`Calibration.for_sweep`'s calibration, built once per sensor/ring/ADC: building
    one (its fine θ table) takes longer than estimating a sweep, and ``irring run`` without
    a calibration file estimates every sweep with the default."""
    return Calibration.nominal(sensor_model, ring, adc_bits, vref_v)


def _fallback_spread(cal: Calibration, counts: np.ndarray, d0: np.ndarray) -> np.ndarray:
    """RMS range error of reading ``counts`` with θ = 0 (giving ``d0``) when the true θ is
    unknown: θ as a beam meets a round surface at a uniformly random offset (sin θ uniform
    up to the drop-out angle; most such readings are thin obstacles), by 8-point quadrature.
    The θ = 0 distance is the longest the reading can mean, so the error is one-sided and
    grows steeply with θ: at 0.4 m on the GP2D12 curve ≈ 37 mm."""
    u = (np.arange(_FALLBACK_NODES) + 0.5) / _FALLBACK_NODES * math.sin(cal.max_incidence_rad)
    err = cal.distance(counts[:, None], np.arcsin(u)) - d0[:, None]
    return np.sqrt(np.mean(err * err, axis=1))


def _needs_drop(held: _Held, hot, theta_line, sw: _Sweep) -> bool:
    """Whether a member now meets its line past the rejection angle, or most of a line's
    members sit at the drop-out angle (a streak or runaway, see _Grouping.drop_steep)."""
    if (theta_line > sw.reject).any():
        return True
    n_hot = np.bincount(held.slot[hot], minlength=held.n.size)
    return bool((n_hot > 0.5 * held.n).any())


def _scatter(values, index, shape, fill, held: _Held | None = None, mask=None):
    """Compact per-reading values back into an (S, N) array (``fill`` elsewhere)."""
    out = np.full(shape, fill)
    if held is not None:
        values = values.copy()
        values[held.perm] = held.theta
    out.reshape(-1)[index] = values
    if mask is not None:
        out[~mask] = fill
    return out
