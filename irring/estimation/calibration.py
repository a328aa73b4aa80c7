"""Calibrating a ring: emitter offset d_o (paper Eq. 9) and the curve a(θ), b(θ) (Eq. 10).

One procedure serves the simulator and the real ring; only where readings come from
differs. A flat wall is placed in front of one sensor (``sensor``, 0 by default) at a known
perpendicular distance y from the sensor's hinge axis, turned so that the sensor's radial
direction meets the wall normal at a known angle ψ. A sweep then gives readings at beam
angles h = ψ + φ off the wall normal, where the geometry (Eq. 5 with h for φ) gives the
true distance ``d = y / cos h − d_o·tan h`` and incidence θ = |h|.

- Offset placements (ψ = 0, a few y): d_o by Eq. 9 over readings on both sides of the
  normal. The θ-dependent curve error is even in h and tan h is odd, so it cancels.
- Curve placements (ψ = 0°, 25°, 50°; distances across the range): a(θ), b(θ) by least
  squares in log–log space (:func:`irring.estimation.estimate.fit_curve`) against the true distances.
- d_o and the curve are solved alternately (three rounds; each barely moves the other).

Each placement is read ``sweeps`` times; per step the readings are averaged (after
dropping any beyond 4 robust σ, e.g. outliers), and their spread gives the noise σ in
counts that the estimator uses for ``Points.sigma_m``.

:class:`SimulatedRig` reads placements from :class:`irring.simulation.sim.SimRing` in a generated
4 m × 4 m room with the scenario's ring, sensor and effects (minus ``motion``).
:class:`GuidedCalibration` walks a person through the same placements on the real ring:
``prompt`` (like :func:`input`) and ``show`` (like :func:`print`) are the user interface and
``read_sweep()`` returns one :class:`irring.core.Sweep` from the hardware, so the procedure
can be tested without either.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

import numpy as np

from .. import gp2
from ..core import Pose, Ring, Sweep
from .estimate import Calibration, CalibrationError, emitter_offset_from_wall, fit_curve

DEFAULT_THETA_GRID_RAD = np.radians(np.arange(0.0, 86.0, 5.0))
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


def default_placements(min_range_m: float = 0.10, max_range_m: float = 0.80,
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


def solve(readings: RigReadings, *, sensor_model: str, adc_bits: int = 12, vref_v: float = 5.0,
          min_range_m: float | None = None, max_range_m: float | None = None,
          theta_grid_rad: np.ndarray = DEFAULT_THETA_GRID_RAD, emitter_offset_guess_m: float = 0.0,
          source: str = "") -> Calibration:
    """d_o (Eq. 9) and a(θ), b(θ) (Eq. 10) from a rig's readings, solved alternately.

    A reading is used for the curve if its counts are above the ADC floor and below full
    scale, its true distance lies in [min_range, max_range] (default: the sensor model's
    datasheet range) and it is not within 3σ of the no-return level (a dropped return reads
    as that level, not as its distance).
    """
    r = readings
    spread = r.spread_counts[np.isfinite(r.spread_counts) & (r.repeats > 1)]
    noise = float(np.sqrt(np.mean(spread ** 2))) if spread.size else 0.0
    # the datasheet curve says what "nothing there" reads until our own curve can say it,
    # and its range is the default
    cal = dataclasses.replace(Calibration.nominal(sensor_model, None, adc_bits, vref_v),
                              noise_counts=noise)
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
    return dataclasses.replace(cal, emitter_offset_m=d_o, max_incidence_rad=steepest)


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
        sc = self.scenario
        return solve(self.readings(), sensor_model=sc.sensor.model,
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
    the usual mistake).
    """

    def __init__(self, *, read_sweep: Callable[[], Sweep], prompt: Callable[[str], str] = input,
                 show: Callable[[str], None] = print, sensor_model: str = "gp2d12",
                 adc_bits: int = 12, vref_v: float = 5.0, sensor: int = 0, sweeps: int = 4,
                 placements: Sequence[Placement] | None = None,
                 emitter_offset_guess_m: float = 0.007):
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
        parts = []
        doubtful: list[int] = []   # placements kept although their reading looked wrong
        for k, placement in enumerate(self.placements, start=1):
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
                parts.append(collect(sweeps, placement, self.sensor))
                show(f"[{k}/{n}] read {len(sweeps)} sweeps")
                break
        if not any(p.offset.any() for p in parts):
            raise CalibrationError("no offset placement (wall square to the sensor) was read; "
                                   "d_o needs at least one")
        try:
            cal = solve(RigReadings.concat(parts), sensor_model=self.sensor_model,
                        adc_bits=self.adc_bits, vref_v=self.vref_v,
                        emitter_offset_guess_m=self.emitter_offset_guess_m,
                        source=f"guided calibration of the real ring, sensor {self.sensor}, "
                               f"{len(parts)} placements × {self.sweeps} sweeps")
        except CalibrationError as exc:
            hint = (f"; placements {', '.join(map(str, doubtful))} read far from the nominal "
                    "curve: was the wall where it was asked to be?" if doubtful else "")
            raise CalibrationError(f"{exc}{hint}") from exc
        show(f"d_o = {cal.emitter_offset_m * 1e3:.2f} mm; a(0) = {cal.a[0]:.4g}, "
             f"b(0) = {cal.b[0]:.4f}; θ table up to {math.degrees(cal.max_theta_rad):.0f}°; "
             f"noise {cal.noise_counts:.1f} counts")
        return cal
