"""Ring designs a designer can compare (:data:`DESIGNS`: rotating12, radial12, rotating1,
laser, sonar12; :func:`parametric` for any other), all built from the one MJCF template.

A :class:`Design` is a :class:`~irring.core.Ring` plus the sensor it carries. A scenario
names one with ``robot.design`` (:func:`irring.scenario.ring_for`), and
:func:`irring.scenario.apply_design` shows a scene as another design sees it. Nothing here
writes MJCF. The named designs: docs/designs.md.
"""

from __future__ import annotations

import dataclasses
import math
import types
from dataclasses import dataclass
from typing import Mapping

from .core import SENSOR_MODEL, Ring, SensorSpec, bounds_error, hardware_duration_s
from .gp2 import SENSORS, sensor_spec


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
        time (settle not for a laser, whose mirror never stops): ``core.hardware_duration_s``
        over those readings with the sensor's period.
        """
        fires = self.ring.sensors if self.sensor.sequential else 1
        return hardware_duration_s(self.positions(step_stride) * fires,
                                   settle_s if self.sensor.settles else 0.0, samples,
                                   self.sensor.reading_period_s)


PAPER_RING = Ring()  # the paper's: 12 sensors, R = 0.15 m, ±35 motor steps of 1.8°, gear 0.6

_LASER_STEP_RAD = math.radians(0.5)

DESIGN_LIST: tuple[Design, ...] = (
    Design("rotating12", PAPER_RING, SENSORS[SENSOR_MODEL],
           "the paper's ring: 12 GP2D12 on R = 0.15 m, each turning ±37.8° in 1.08° steps"),
    Design("radial12", dataclasses.replace(PAPER_RING, min_step=0, max_step=0),
           SENSORS[SENSOR_MODEL],
           "the paper's ring held still: 12 GP2D12, one reading each, 30° apart"),
    Design("rotating1",
           # 334 positions × 1.08° = 360.7°: the last step closes the circle
           Ring(sensors=1, radius_m=0.0, min_step=0, max_step=333, joint_limit_rad=2 * math.pi),
           SENSORS[SENSOR_MODEL], "one GP2D12 at the centre turning 360° in 1.08° steps"),
    Design("laser",
           Ring(sensors=1, radius_m=0.0, motor_step_rad=_LASER_STEP_RAD, gear=1.0, min_step=0,
                max_step=719, emitter_offset_m=0.0, joint_limit_rad=2 * math.pi),
           SENSORS["laser"], "SICK-like scanner at the centre: 0.5° steps over 360°, 8 m"),
    Design("sonar12",
           # held still (steps 0 … 0); the hinge keeps the template's ±37.8° limit
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
               sensor: str = SENSOR_MODEL, *, gear: float = PAPER_RING.gear,
               name: str = "custom", emitter_offset_m: float | None = None) -> Design:
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
        limit = max(half, 1) * step_rad  # ±1 step when radial (0 builds too: HELD_HINGE_RAD)
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
    """The bounds the scenario loader checks (a ``ValueError`` in the loader's words and
    units), for rings made in code."""
    for f in dataclasses.fields(Ring):
        why = bounds_error(getattr(ring, f.name), f.metadata, f"ring.{f.name}")
        if why is not None:
            raise ValueError(f"ring.{f.name}: {why}")
