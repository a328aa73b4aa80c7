"""Ring designs a designer can compare, all built from the one MJCF ring template.

A :class:`Design` is a :class:`~irring.scenario.Ring` (where the sensors sit and how they
turn) plus the sensor it carries (:class:`SensorSpec`: kind, max range, noise, beam cone,
reading period). The simulator builds every design's MuJoCo model from ``models/irring.xml``
with the ring's numbers; nothing here writes MJCF.

Named designs (:data:`DESIGNS`):

==============  ============================================================================
``rotating12``  the paper's ring: 12 GP2D12 on R = 0.15 m, each turning ±37.8° in 1.08° steps
``radial12``    the same ring held still (one reading per sensor, 30° apart)
``rotating1``   one GP2D12 at the centre turning 360° in 1.08° steps (an "IR scanner")
``laser``       a SICK-like scanner at the centre: 0.5° steps over 360°, 8 m, σ = 5 mm
``sonar12``     a radial ring of 12 ultrasonic rangers, ±15° cone, nearest echo, 6.45 m
==============  ============================================================================

:func:`parametric` makes any other ring (N, radius, sweep angle, step, sensor).

A scenario names a design with ``robot.design`` and may give ``robot.ring`` numbers; see
:func:`ring_for` for how the two combine. :func:`apply` turns any scenario into the same
scene seen by another design (ring, sensor block and sensor effects), which is what
``irring compare`` runs.
"""

from __future__ import annotations

import dataclasses
import math
import types
from dataclasses import dataclass
from typing import Mapping

from .data import GP2_PERIOD_S, hardware_duration_s
from .scenario import IncidenceEffect, NoiseEffect, Ring, Robot, Scenario, ScenarioError, Sensor


# --------------------------------------------------------------------------- sensors


@dataclass(frozen=True)
class SensorSpec:
    """What a sensor kind implies for a design. Lengths m, angles rad, times s.

    ``max_range_m``: readings beyond are no return (the scenario's ``sensor.max_range_m``).
    ``design_range_m``: D of the paper's Eqs. 2–3 (Table I uses 0.686 m for the GP2D12,
    the experiments 0.624 m). ``noise_sigma_m``: 1-σ range noise the sensor implies, or
    None when the scenario's own effects (volts, for GP2 curves) govern.
    ``beam_half_angle_rad``: cone half-angle (0 for a pencil beam). ``reading_period_s``:
    time one reading costs. ``sequential``: sensors fire one after another (sonar
    crosstalk) instead of all at once (the IR ring's ADCs read the 12 sensors together).
    """

    kind: str
    max_range_m: float
    design_range_m: float
    noise_sigma_m: float | None = None
    beam_half_angle_rad: float = 0.0
    reading_period_s: float = GP2_PERIOD_S
    sequential: bool = False
    adc_bits: int = 12
    settles: bool = True   # a stepped sensor waits scan.settle_s per position; a laser's
                           # mirror turns continuously, so settling does not apply
    description: str = ""

    @property
    def is_ir(self) -> bool:
        return self.kind.startswith("gp2")

    @property
    def min_range_m(self) -> float:
        """Readings nearer than this are not trusted: the sensor curve's own (``gp2``)."""
        from . import gp2  # the curve's owner

        return gp2.sensor(self.kind).min_range_m


SENSORS: dict[str, SensorSpec] = {
    "gp2d12": SensorSpec("gp2d12", max_range_m=0.624, design_range_m=0.686,
                         description="Sharp GP2D12, 10–80 cm; paper's limit 624 mm, "
                                     "Table I's D 686 mm"),
    "gp2y0a21": SensorSpec("gp2y0a21", max_range_m=0.80, design_range_m=0.80,
                           description="Sharp GP2Y0A21YK, 10–80 cm"),
    "gp2y0a02": SensorSpec("gp2y0a02", max_range_m=1.50, design_range_m=1.50,
                           description="Sharp GP2Y0A02YK0F, 20–150 cm"),
    # SICK LMS200-like: 8 m (mm mode), σ ≈ 5 mm; its mirror turns at 75 Hz and 0.5° steps are
    # interlaced over two turns, so a 720-reading 360° view takes 2/75 s = 26.7 ms.
    "laser": SensorSpec("laser", max_range_m=8.0, design_range_m=8.0,
                        noise_sigma_m=0.005, reading_period_s=(2.0 / 75.0) / 720,
                        adc_bits=16, settles=False, description="SICK LMS200-like scanner, 8 m, σ 5 mm"),
    # MaxBotix LV-MaxSonar-EZ class (the `sonar` curve in models/sensors): 0.15–6.45 m, one
    # reading per 49 ms (20 Hz); a ring chains its transducers one after another so they do
    # not hear each other. The ±15° cone is our assumption (12 of them close a 360° ring).
    "sonar": SensorSpec("sonar", max_range_m=6.45, design_range_m=6.45,
                        noise_sigma_m=0.01, beam_half_angle_rad=math.radians(15.0),
                        reading_period_s=0.049, sequential=True, adc_bits=16,
                        description="MaxBotix LV-EZ-class ultrasonic ranger, ±15° cone, 6.45 m"),
}


def sensor_spec(kind: str) -> SensorSpec:
    try:
        return SENSORS[kind]
    except KeyError:
        raise ValueError(f"unknown sensor kind {kind!r}; known: {', '.join(SENSORS)}") from None


# --------------------------------------------------------------------------- designs


@dataclass(frozen=True)
class Design:
    """A ring and the sensor it carries."""

    name: str
    ring: Ring
    sensor: SensorSpec
    description: str = ""

    # ---- derived numbers
    @property
    def step_rad(self) -> float:
        """Sensor turn per motor step (rad): motor step × belt ratio."""
        return self.ring.motor_step_rad * self.ring.gear

    @property
    def sweep_half_angle_rad(self) -> float:
        """α: half of the angle each sensor's beam sweeps (0 for a radial ring)."""
        return (self.ring.max_step - self.ring.min_step) * self.step_rad / 2.0

    @property
    def rotating(self) -> bool:
        return self.ring.max_step > self.ring.min_step

    @property
    def spacing_rad(self) -> float:
        """Φ = 2π/N between neighbouring sensors."""
        return 2.0 * math.pi / self.ring.sensors

    def positions(self, step_stride: int = 1) -> int:
        """Motor positions a sweep visits (the sweep's steps)."""
        return len(range(self.ring.min_step, self.ring.max_step + 1, step_stride))

    def ray_step_rad(self, step_stride: int = 1) -> float:
        """Δθ of Eq. 1: the widest angular gap between neighbouring rays of one view.

        A rotating sensor: its own step (× stride). A radial ring: the sensor spacing Φ,
        narrowed by the beam cone on both sides (a ±15° sonar on a 30° ring leaves none).
        """
        if self.rotating:
            gap = self.step_rad * step_stride
        else:
            gap = self.spacing_rad
        return max(gap - 2.0 * self.sensor.beam_half_angle_rad, 0.0)

    def hardware_time_s(self, *, step_stride: int = 1, settle_s: float = 0.0,
                        samples: int = 1) -> float:
        """Seconds the real device needs for one full 360° view at one pose.

        positions × (settle + samples × reading period), × sensors when they fire one at a
        time (settle not for a laser, whose mirror never stops): ``data.hardware_duration_s``
        over those readings with the sensor's period.
        """
        fires = self.ring.sensors if self.sensor.sequential else 1
        return hardware_duration_s(self.positions(step_stride) * fires,
                                   settle_s if self.sensor.settles else 0.0, samples,
                                   self.sensor.reading_period_s)

    # ---- what the simulator needs
    def sensor_block(self, base: Sensor | None = None) -> Sensor:
        """The scenario ``sensor:`` block for this design (ADC settings kept from ``base``
        for IR sensors)."""
        if self.sensor.is_ir and base is not None:
            return dataclasses.replace(base, model=self.sensor.kind,
                                       max_range_m=self.sensor.max_range_m)
        vref = base.vref_v if base is not None else 5.0
        return Sensor(model=self.sensor.kind, max_range_m=self.sensor.max_range_m,
                      adc_bits=self.sensor.adc_bits, vref_v=vref)


PAPER_RING = Ring()  # the paper's: 12 sensors, R = 0.15 m, ±35 motor steps of 1.8°, gear 0.6

_LASER_STEP_RAD = math.radians(0.5)

DESIGN_LIST: tuple[Design, ...] = (
    Design("rotating12", PAPER_RING, SENSORS["gp2d12"],
           "the paper's ring: 12 GP2D12 on R = 0.15 m, each turning ±37.8° in 1.08° steps"),
    Design("radial12", dataclasses.replace(PAPER_RING, min_step=0, max_step=0), SENSORS["gp2d12"],
           "the paper's ring held still: 12 GP2D12, one reading each, 30° apart"),
    Design("rotating1",
           # 334 positions × 1.08° = 360.7°: the last step closes the circle
           Ring(sensors=1, radius_m=0.0, min_step=0, max_step=333, joint_limit_rad=2 * math.pi),
           SENSORS["gp2d12"], "one GP2D12 at the centre turning 360° in 1.08° steps"),
    Design("laser",
           Ring(sensors=1, radius_m=0.0, motor_step_rad=_LASER_STEP_RAD, gear=1.0, min_step=0,
                max_step=719, emitter_offset_m=0.0, joint_limit_rad=2 * math.pi),
           SENSORS["laser"], "SICK-like scanner at the centre: 0.5° steps over 360°, 8 m"),
    Design("sonar12",
           # held still; the hinge keeps the template's ±37.8° limit (a zero range won't compile)
           Ring(sensors=12, radius_m=0.15, min_step=0, max_step=0, emitter_offset_m=0.0),
           SENSORS["sonar"], "radial ring of 12 ultrasonic transducers, ±15° cone, nearest echo"),
)

DESIGN_BY_NAME: dict[str, Design] = {d.name: d for d in DESIGN_LIST}

# Name → Ring, kept for code that only needs the ring.
DESIGNS: Mapping[str, Ring] = types.MappingProxyType({d.name: d.ring for d in DESIGN_LIST})


def get(name: str) -> Design:
    """A named design; the error lists the names."""
    try:
        return DESIGN_BY_NAME[name]
    except KeyError:
        raise ValueError(f"unknown design {name!r}; known: {', '.join(DESIGN_BY_NAME)} "
                         f"(or build one with designs.parametric)") from None


def parametric(sensors: int, radius_m: float, sweep_half_angle_rad: float, step_rad: float,
               sensor: str = "gp2d12", *, gear: float = 0.6, name: str = "custom",
               emitter_offset_m: float | None = None) -> Design:
    """Any ring: ``sensors`` on ``radius_m``, each sweeping ±``sweep_half_angle_rad`` in
    ``step_rad`` sensor steps (0 half-angle: a radial ring), carrying ``sensor``.

    A half-angle ≥ π means a full turn (0 … 360° − step, like ``rotating1``). The motor step
    is ``step_rad / gear`` (the paper's belt ratio 0.6 by default). The half-angle is
    rounded to whole steps.
    """
    spec = sensor_spec(sensor)
    if sensors < 1:
        raise ValueError(f"sensors must be ≥ 1, got {sensors}")
    if step_rad <= 0:
        raise ValueError(f"step_rad must be > 0, got {step_rad}")
    if sweep_half_angle_rad < 0:
        raise ValueError(f"sweep_half_angle_rad must be ≥ 0, got {sweep_half_angle_rad}")
    if sweep_half_angle_rad >= math.pi:
        lo, hi = 0, math.ceil(2 * math.pi / step_rad - 1e-9) - 1
        limit = 2 * math.pi
    else:
        half = round(sweep_half_angle_rad / step_rad)
        lo, hi = -half, half
        limit = max(half, 1) * step_rad  # MuJoCo needs a non-empty hinge range
    if emitter_offset_m is None:
        emitter_offset_m = PAPER_RING.emitter_offset_m if spec.is_ir else 0.0
    ring = Ring(sensors=sensors, radius_m=radius_m, motor_step_rad=step_rad / gear, gear=gear,
                min_step=lo, max_step=hi, emitter_offset_m=emitter_offset_m,
                joint_limit_rad=limit)
    _check_ring(ring)
    desc = (f"{sensors} × {sensor} on R = {radius_m * 1e3:g} mm, ±{math.degrees(limit):g}° in "
            f"{math.degrees(step_rad):g}° steps")
    return Design(name, ring, spec, desc)


def _check_ring(ring: Ring) -> None:
    """The scenario loader's own bounds check (a ``ScenarioError``, a ``ValueError``, in the
    loader's words and units), for rings made in code."""
    from .scenario import _Loader

    loader = _Loader("")
    for f in dataclasses.fields(Ring):
        loader.check(getattr(ring, f.name), f.metadata, f"ring.{f.name}")


# --------------------------------------------------------------------------- scenarios


def _overrides(ring: Ring) -> dict:
    """Fields of a scenario's ``robot.ring`` that differ from the paper's ring."""
    return {f.name: getattr(ring, f.name) for f in dataclasses.fields(Ring)
            if getattr(ring, f.name) != getattr(PAPER_RING, f.name)}


def ring_for(robot: Robot) -> Ring:
    """The ring a robot uses.

    ``design: custom`` takes ``robot.ring`` as written (fields left out keep the paper's
    values). A named design takes that design's ring, and any ``robot.ring`` field that
    differs from the paper's value replaces the design's (so ``design: radial12`` with
    ``ring: {sensors: 8}`` is a still ring of 8).
    """
    if robot.design == "custom":
        if robot.ring is None:
            raise ScenarioError("robot.ring: required when robot.design is custom; give the "
                                "ring's numbers (sensors, radius_mm, min_step, max_step, …)")
        return robot.ring
    ring = get(robot.design).ring
    if robot.ring is not None:
        ring = dataclasses.replace(ring, **_overrides(robot.ring))
    return ring


def design_for(scenario: Scenario) -> Design:
    """The design a scenario runs: its named design with its ring and sensor model."""
    ring = scenario.ring
    if scenario.robot.design in DESIGN_BY_NAME and ring == get(scenario.robot.design).ring \
            and scenario.sensor.model == get(scenario.robot.design).sensor.kind:
        return get(scenario.robot.design)
    spec = dataclasses.replace(sensor_spec(scenario.sensor.model),
                               max_range_m=scenario.sensor.max_range_m)
    return Design(scenario.robot.design, ring, spec, "from the scenario")


def apply(scenario: Scenario, design: Design | str) -> Scenario:
    """The same scene (room, obstacles, poses, map, seed) seen by another design.

    The robot's ring and design name, and the ``sensor:`` block, become the design's. For
    GP2 designs the scenario's effects stay as they are; for laser and sonar the GP2-specific
    stages (incidence curves, fold-over, volts of noise) are replaced by the design's own
    range noise, so each design is simulated with the sensor it would carry.
    """
    d = get(design) if isinstance(design, str) else design
    robot_design = d.name if d.name in DESIGN_BY_NAME else "custom"
    robot = dataclasses.replace(scenario.robot, design=robot_design,
                                ring=None if robot_design != "custom" else d.ring)
    sensor = d.sensor_block(scenario.sensor)
    effects = scenario.effects if d.sensor.is_ir else sensor_effects(d, scenario.effects)
    return dataclasses.replace(scenario, robot=robot, sensor=sensor,
                               effects=types.MappingProxyType(dict(effects)))


# Stages whose parameters describe a GP2 (volts of noise, an IR beam cone, IR reflectivity,
# fold-over); a laser or sonar design gets its own instead.
_GP2_ONLY = ("incidence", "foldover", "noise", "reflectance", "beam")


def sensor_effects(design: Design, effects: Mapping) -> dict:
    """Effects for a non-IR design: the scene's sensor-independent effects (quantisation,
    outliers, averaging, timing, motion, …), grazing drop-out at the sensor's own limit if
    the scene has drop-out at all, and the design's range noise.

    The noise stage works in volts on the sensor's curve (``gp2``); the range noise σ_m the
    design implies becomes volts through the curve's slope (linear for laser and sonar).
    """
    out = {k: v for k, v in effects.items() if k not in _GP2_ONLY}
    if "incidence" in effects:
        out["incidence"] = IncidenceEffect()  # max_incidence None: the sensor model's limit
    if design.sensor.noise_sigma_m:
        out["noise"] = NoiseEffect(sigma_v=noise_sigma_v(design))
    return out


def noise_sigma_v(design: Design) -> float:
    """Volts of output noise that give the design's range σ at half its max range."""
    from . import gp2  # the curve's owner; laser/sonar curves live there

    model = gp2.sensor(design.sensor.kind)
    d = 0.5 * design.sensor.max_range_m
    h = 1e-3 * d
    slope = abs(float(model.voltage(d + h) - model.voltage(d - h)) / (2 * h))  # V per m
    return float(min(max(design.sensor.noise_sigma_m * slope, 0.0), 1.0))
