"""Scenario files: YAML → validated, frozen dataclasses (the schema: scenarios/README.md).

Inside the code every quantity is SI; YAML may write ``foo_m`` as ``foo_mm``, ``foo_rad`` as
``foo_deg`` and ``foo_s`` as ``foo_ms``, converted once here. Unknown keys, wrong types and
out-of-range values raise :class:`ScenarioError` naming the YAML path and what is allowed,
so a typo never becomes a silent default.
"""

from __future__ import annotations

import collections.abc
import dataclasses
import difflib
import math
import re
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from . import designs, gp2, resources, safe_yaml
from .core import (ADC_BITS, GEOMETRY_TOL_M, GP2_PERIOD_S, HOUSING_M, MAX_ABS_COORDINATE_M,
                   MAX_OBSTACLES, MAX_OUTLINE_CORNERS, MAX_RANGE_M, MAX_SWEEPS,
                   MIN_READING_PERIOD_S, SEED_MAX, SENSOR_MODEL, VREF_V, Box, Cylinder, Pose,
                   Ring, Room, bounds,
                   bounds_error, built_wall_thickness, choice, clip_to_convex,
                   distance_to_outline, first_crossing, first_overlap, first_wall_into,
                   first_wall_intrusion, footprint, inside_outline, num, obstacle_distance,
                   segment_distance,
                   on_one_line, polygon_area, reach_outside, unit_suffix, UNITS, walls_into)
from .designs import Design
from .errors import InputError, brief, formula_start
from .outputs import name_key

# --------------------------------------------------------------------------- errors


class ScenarioError(InputError):
    """A scenario file that cannot be used; the message names the YAML path."""


# --------------------------------------------------------------------------- schema
@dataclass(frozen=True)
class Robot:
    design: str = choice("rotating12", (*designs.DESIGN_BY_NAME, "custom"))
    ring: Ring | None = None
    poses: tuple[Pose, ...] = ()
    # the robot.ring fields a file gave: a named design takes each of them, even one that
    # equals the paper's value (made in code: the fields that differ from the paper's)
    ring_keys: tuple[str, ...] = ()


@dataclass(frozen=True)
class Sensor:
    model: str = choice(SENSOR_MODEL, tuple(gp2.SENSORS))
    max_range_m: float = num(MAX_RANGE_M, lo=0.02, hi=30.0,
                             doc="readings beyond are treated as no return (default: the "
                                 "model's, gp2.SENSORS; the paper's GP2D12: 624 mm)")
    adc_bits: int = choice(ADC_BITS, (8, 10, 12, 16))
    vref_v: float = num(VREF_V, lo=1.0, hi=10.0)


@dataclass(frozen=True)
class Scan:
    """How a sweep is taken; these knobs cost hardware time."""

    step_stride: int = num(1, lo=1, hi=64, doc="motor steps between readings")
    settle_s: float = num(0.0, lo=0.0, hi=5.0, doc="wait at each step before reading")
    samples: int = num(1, lo=1, hi=64, doc="readings averaged per step")


@dataclass(frozen=True)
class MapSpec:
    resolution_m: float = num(0.010, lo=0.001, hi=0.5)
    margin_m: float = num(0.10, lo=0.0, hi=5.0, doc="grid border around the room outline")


# ---- effects: one frozen dataclass each; listed under `effects:` to switch them on


@dataclass(frozen=True)
class IncidenceEffect:
    """a(θ), b(θ) of the sensor curve plus grazing drop-out."""

    max_incidence_rad: float | None = num(None, lo=0.0, hi=math.radians(90.0),
                                          doc="returns at steeper incidence drop out "
                                              "(default: the sensor model's, GP2: 70°, sonar: 20°)")

    def drop_out_rad(self, model) -> float:
        """The incidence (rad) past which returns drop out: this effect's, else ``model``'s
        (a ``gp2.SensorModel``)."""
        return self.max_incidence_rad if self.max_incidence_rad is not None \
            else model.max_incidence_rad


@dataclass(frozen=True)
class NoiseEffect:
    sigma_v: float = num(0.015, lo=0.0, hi=1.0, doc="Gaussian output noise (volts rms)")


@dataclass(frozen=True)
class QuantizationEffect:
    """Rounds to ADC counts; the bit count is `sensor.adc_bits`."""


@dataclass(frozen=True)
class FoldoverEffect:
    """Below the peak distance the output falls again."""


@dataclass(frozen=True)
class ReflectanceEffect:
    """Per-surface reflectivity weakens the return: more noise, shorter reach."""

    min_signal: float = num(0.2, lo=0.0, hi=1.0,
                            doc="returns weaker than this (reflectance / d² relative to max range)"
                                " drop out; 0.2 lets 18 % grey card (0.2 of white) reach the "
                                "sensor's full range, as the GP2 datasheets specify")

    @staticmethod
    def signal(reflectance, distance_m, max_range_m: float):
        """Signal of a return: reflectance · (max_range / d)², 1 for white at the sensor
        model's ``max_range_m``; it drops out below ``min_signal``."""
        return reflectance * (max_range_m / distance_m) ** 2


@dataclass(frozen=True)
class OutliersEffect:
    """Beam-model mixture (Thrun et al.): short, random and max-range readings."""

    short_rate: float = num(0.005, lo=0.0, hi=1.0)
    random_rate: float = num(0.005, lo=0.0, hi=1.0)
    max_rate: float = num(0.005, lo=0.0, hi=1.0)
    short_lambda_per_m: float = num(5.0, lo=0.01, hi=1000.0)


@dataclass(frozen=True)
class BeamEffect:
    """A cone of rays with Gaussian weights, like Webots' aperture / gaussianWidth."""

    aperture_rad: float = num(math.radians(4.0), lo=0.0, hi=math.radians(60.0))
    rays: int = num(5, lo=2, hi=64)
    gaussian_width: float = num(0.5, lo=0.01, hi=10.0,
                                doc="weight σ as a fraction of the half aperture")


@dataclass(frozen=True)
class AveragingEffect:
    """Averages `scan.samples` readings per step (independent noise per sample)."""


@dataclass(frozen=True)
class BeltDynamicsEffect:
    timestep_s: float = num(0.0005, lo=1e-5, hi=0.01)
    belt_timeconst_s: float = num(0.002, lo=1e-4, hi=1.0,
                                  doc="belt spring time constant τ: stiffness = sensor inertia / τ²,"
                                      " critically damped (irring/simulation/dynamics.py)")
    backlash_rad: float = num(0.0, lo=0.0, hi=math.radians(5.0), doc="dead band in the belt")
    step_time_s: float = num(0.004, lo=1e-4, hi=1.0,
                             doc="time the motor takes per 1.8° step (minimum-jerk move)")


@dataclass(frozen=True)
class TimingEffect:
    period_s: float = num(GP2_PERIOD_S, lo=MIN_READING_PERIOD_S, hi=1.0)
    jitter_s: float = num(0.0096, lo=0.0, hi=1.0)
    latency_s: float = num(0.005, lo=0.0, hi=1.0)


@dataclass(frozen=True)
class Waypoint:
    x_m: float
    y_m: float
    yaw_rad: float = num(0.0, lo=-2 * math.pi, hi=2 * math.pi)


@dataclass(frozen=True)
class MotionEffect:
    path: tuple[Waypoint, ...]
    speed_m_s: float = num(0.05, lo=0.0, hi=5.0)
    odometry_sigma_m: float = num(0.0, lo=0.0, hi=1.0, doc="per-metre translational drift σ")
    odometry_sigma_rad: float = num(0.0, lo=0.0, hi=1.0, doc="per-metre heading drift σ")


EFFECTS: dict[str, type] = {
    "incidence": IncidenceEffect,
    "noise": NoiseEffect,
    "quantization": QuantizationEffect,
    "foldover": FoldoverEffect,
    "reflectance": ReflectanceEffect,
    "outliers": OutliersEffect,
    "beam": BeamEffect,
    "averaging": AveragingEffect,
    "belt_dynamics": BeltDynamicsEffect,
    "timing": TimingEffect,
    "motion": MotionEffect,
}


# fields that say where a scenario came from, and what the loader notes of the file
NOT_IN_FILE = ("source", "text", "ring_keys")


@dataclass(frozen=True)
class Scenario:
    name: str
    room: Room
    robot: Robot
    description: str = ""
    obstacles: tuple[Cylinder | Box, ...] = ()
    sensor: Sensor = Sensor()
    scan: Scan = Scan()
    map: MapSpec = MapSpec()
    effects: Mapping[str, Any] = field(default_factory=dict)
    seed: int = num(0, lo=0, hi=SEED_MAX)
    source: str = ""  # file it was loaded from, for messages
    # the YAML it was loaded from, recorded with its sweeps (a pipe cannot be read again)
    text: str = field(default="", repr=False, compare=False)

    def has(self, effect: str) -> bool:
        return effect in self.effects

    @property
    def samples_per_step(self) -> int:
        """Readings taken (and GP2 periods spent) per step: ``scan.samples`` when the scene
        averages, else 1."""
        return self.scan.samples if self.has("averaging") else 1

    @property
    def ring(self) -> Ring:
        """The ring design in force (the design's numbers with any `robot.ring` overrides)."""
        return ring_for(self.robot)


# --------------------------------------------------------------------------- loader

_UNIT_ALIASES = {si: ((alt, to_si),) if alt is not None else () for si, _, alt, _, to_si in UNITS}
def _yaml_keys(name: str) -> list[tuple[str, float]]:
    """YAML spellings of a dataclass field and the factor to SI."""
    suf = unit_suffix(name)
    keys = [(name, 1.0)]
    if suf:
        base = name[: -len(suf)]
        keys += [(base + alt, f) for alt, f in _UNIT_ALIASES[suf]]
    return keys


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", str(tp))


class _Loader:
    def __init__(self, source: str):
        self.source = source

    def fail(self, path: str, msg: str) -> ScenarioError:
        where = f"{self.source}: " if self.source else ""
        return ScenarioError(f"{where}{path or '<top>'}: {msg}")

    def dataclass_(self, cls: type, raw: Any, path: str, scale: float = 1.0) -> Any:
        if raw is None:
            raw = {}
        hints = typing.get_type_hints(cls)
        allowed: dict[str, tuple[dataclasses.Field, float]] = {}
        for f in dataclasses.fields(cls):
            if f.name in NOT_IN_FILE:
                continue
            for key, factor in _yaml_keys(f.name):
                allowed[key] = (f, factor)
        if not isinstance(raw, Mapping):   # named by its keys: the class is not in the file
            keys = ", ".join(sorted(allowed)) or "none, write {} for the defaults"
            raise self.fail(path, f"expected a mapping of keys, got {brief(raw)}; allowed here: {keys}")
        kwargs: dict[str, Any] = {}
        for key, value in raw.items():
            if key not in allowed:
                # an effect without settings (foldover) ended "allowed here:" with nothing
                names = ", ".join(sorted(allowed)) or "none, write {} for the defaults"
                hint = _other_unit(str(key), cls) or _close(str(key), allowed)
                raise self.fail(_join(path, key), f"unknown key{hint}; allowed here: {names}")
            f, factor = allowed[key]
            if f.name in kwargs:
                raise self.fail(_join(path, key), f"{f.name} given twice (in two units)")
            kwargs[f.name] = self.value(hints[f.name], value, _join(path, key), factor, f)
        for f in dataclasses.fields(cls):
            if (f.name not in kwargs and f.default is dataclasses.MISSING
                    and f.default_factory is dataclasses.MISSING):
                spellings = " or ".join(k for k, _ in _yaml_keys(f.name))
                raise self.fail(_join(path, spellings), "required key is missing")
        try:
            return cls(**kwargs)
        except TypeError as exc:  # pragma: no cover - schema bug, not a user error
            raise self.fail(path, str(exc)) from exc

    def value(self, tp: Any, raw: Any, path: str, factor: float,
              f: dataclasses.Field | None = None) -> Any:
        origin = typing.get_origin(tp)
        args = typing.get_args(tp)
        meta = f.metadata if f is not None else {}
        if origin in (typing.Union, types.UnionType):
            options = [a for a in args if a is not type(None)]
            if raw is None and type(None) in args:
                return None
            if all(dataclasses.is_dataclass(a) for a in options) and len(options) > 1:
                return self.tagged(options, raw, path)
            return self.value(options[0], raw, path, factor, f)
        if dataclasses.is_dataclass(tp):
            return self.dataclass_(tp, raw, path)
        if origin is tuple:
            if raw is None and len(args) == 2 and args[1] is Ellipsis:
                raw = []   # a list left empty is empty, as a section left empty (`effects:`) is
            if not isinstance(raw, (list, tuple)):
                raise self.fail(path, f"expected a list, got {brief(raw)}")
            if len(args) == 2 and args[1] is Ellipsis:
                return tuple(self.value(args[0], r, f"{path}[{i}]", factor)
                             for i, r in enumerate(raw))
            if len(raw) != len(args):
                raise self.fail(path, f"expected {len(args)} numbers, got {len(raw)}")
            return tuple(self.value(a, r, f"{path}[{i}]", factor) for i, (a, r) in
                         enumerate(zip(args, raw)))
        if origin in (Mapping, dict, collections.abc.Mapping) or tp is Mapping:
            return self.effects(raw, path)
        if tp is bool:
            if not isinstance(raw, bool):
                raise self.fail(path, f"expected true or false, got {brief(raw)}")
            return raw
        if tp is int:
            if isinstance(raw, bool) or not isinstance(raw, int):
                raise self.fail(path, f"expected a whole number, got {brief(raw)}")
            self.check(raw, meta, path)
            return raw
        if tp is float:
            if isinstance(raw, bool) or not isinstance(raw, (int, float)):
                raise self.fail(path, f"expected a number, got {brief(raw)}")
            try:
                value = float(raw) * factor
            except OverflowError:   # a whole number past float's range
                value = math.inf
            if not math.isfinite(value):
                raise self.fail(path, f"expected a finite number, got {brief(raw)}")
            if "lo" not in meta and "hi" not in meta:   # positions and sizes (m)
                meta = {"lo": -MAX_ABS_COORDINATE_M, "hi": MAX_ABS_COORDINATE_M}
            self.check(value, meta, path, raw, factor)
            return value
        if tp is str:
            if not isinstance(raw, str):
                raise self.fail(path, f"expected text, got {brief(raw)}")
            self.check(raw, meta, path)
            return raw
        raise self.fail(path, f"unsupported type {_type_name(tp)}")  # pragma: no cover

    def check(self, value: Any, meta: Mapping, path: str, written: float | None = None,
              factor: float = 1.0) -> None:
        why = bounds_error(value, meta, path, written, factor)
        if why is not None:
            raise self.fail(path, why)

    def tagged(self, options: list[type], raw: Any, path: str) -> Any:
        by_tag = {cls.__name__.lower(): cls for cls in options}
        if not isinstance(raw, Mapping) or "type" not in raw:
            raise self.fail(path, f"expected a mapping with `type:` one of {', '.join(by_tag)}")
        tag = raw["type"]
        if not isinstance(tag, str) or tag not in by_tag:   # a list: unhashable
            raise self.fail(_join(path, "type"),
                            f"{tag!r} is not allowed; choose one of: {', '.join(by_tag)}")
        rest = {k: v for k, v in raw.items() if k != "type"}
        return self.dataclass_(by_tag[tag], rest, path)

    def effects(self, raw: Any, path: str) -> Mapping[str, Any]:
        if raw is None:
            return types.MappingProxyType({})
        if isinstance(raw, list):  # `effects: [noise, {beam: {rays: 3}}]`: defaults or a mapping
            listed: dict = {}
            for i, item in enumerate(raw):
                if isinstance(item, Mapping) and len(item) == 1:
                    (name, params), = item.items()
                elif isinstance(item, str):
                    name, params = item, {}
                else:
                    raise self.fail(f"{path}[{i}]", "expected an effect name or a one-key mapping "
                                                    "{name: {parameters}}")
                if not isinstance(name, str) or name in listed:
                    raise self.fail(f"{path}[{i}]", f"effect {name!r} listed twice" if
                                    isinstance(name, str) else "expected an effect name")
                listed[name] = params
            raw = listed
        if not isinstance(raw, Mapping):
            raise self.fail(path, f"expected a mapping of effect names, got {brief(raw)}")
        out = {}
        for name, params in raw.items():
            if name not in EFFECTS:
                raise self.fail(_join(path, name), "unknown effect" + _close(str(name), EFFECTS) +
                                f"; allowed: {', '.join(EFFECTS)}")
            out[name] = self.dataclass_(EFFECTS[name], params, _join(path, name))
        return types.MappingProxyType(out)


def load_dataclass(cls: type, raw: Any, path: str, source: str = "") -> Any:
    """A schema dataclass (a :class:`Ring`, …) from parsed YAML or JSON, checked as the loader
    checks a scenario; raises ScenarioError naming ``source`` and ``path``."""
    return _Loader(source).dataclass_(cls, raw, path)


def _join(path: str, key: Any) -> str:
    return f"{path}.{key}" if path else str(key)


# unit words a key may end in (radius_cm, yaw_degrees), not any word (x_offset)
_UNIT_WORD = re.compile(r"[µukcdm]?m|in(ch(es)?)?|ft|feet|foot|(milli|centi)?met(re|er)s?|"
                        r"m?rad(ians?|s)?|deg(rees?|s)?|[mµun]?s|m?secs?|(milli)?seconds?|min")


def _other_unit(key: str, cls: type) -> str:
    """' (a unit irring does not read; write `radius_mm` or `radius_m`)' for ``radius_cm``: a
    known quantity in another unit, where "did you mean `radius_m`" would scale it 100×; for
    ``radius`` without a unit, ' (a quantity is written with its unit: `radius_mm` or
    `radius_m`)'."""
    for f in dataclasses.fields(cls):
        suf = unit_suffix(f.name)
        if suf is None or f.name in NOT_IN_FILE:
            continue
        base = f.name[: -len(suf)] + "_"
        rest = key[len(base):]
        spellings = " or ".join(f"`{k}`" for k, _ in reversed(_yaml_keys(f.name)))
        if key.startswith(base) and _UNIT_WORD.fullmatch(rest.lower()):
            return f" (a unit irring does not read; write {spellings})"
        if key == base[:-1]:   # `radius: 22`: "did you mean `radius_m`" read it as 22 m
            return f" (a quantity is written with its unit: {spellings})"
    return ""


def _close(word: str, options: Mapping | list) -> str:
    """' (did you mean `t_room`?)' for the option nearest ``word`` in any case (T_ROOM)."""
    lower = {str(o).lower(): o for o in options}
    match = difflib.get_close_matches(word.lower(), list(lower), n=1)
    return f" (did you mean `{lower[match[0]]}`?)" if match else ""


# --------------------------------------------------------------------------- geometry checks


def _wall_mm(outline, k: int) -> str:
    (x1, y1), (x2, y2) = outline[k], outline[(k + 1) % len(outline)]
    return f"wall {k} (({x1 * 1e3:g}, {y1 * 1e3:g}) → ({x2 * 1e3:g}, {y2 * 1e3:g}) mm)"


def _check_wall_thickness(sc: Scenario, fail) -> None:
    """Refuse two walls closer outside the outline than the thinnest wall: the simulator builds
    each wall as a box outward of the outline, thinner where two walls lie closer than the
    room's thickness (core.built_wall_thickness), but never thinner than a file may ask."""
    outline = sc.room.outline_m
    least = bounds(Room, "wall_thickness_m")[0]
    if built_wall_thickness(outline, sc.room.wall_thickness_m) >= least:
        return
    hit = first_wall_intrusion(outline, least)
    if hit is None:   # pragma: no cover - thinner than the least is an intrusion at the least
        return
    i, j = hit
    (ax, ay), (bx, by) = outline[i], outline[(i + 1) % len(outline)]
    (cx, cy), (dx, dy) = outline[j], outline[(j + 1) % len(outline)]
    gap = float(min(segment_distance(cx, cy, ax, ay, bx, by),
                    segment_distance(dx, dy, ax, ay, bx, by),
                    segment_distance(ax, ay, cx, cy, dx, dy),
                    segment_distance(bx, by, cx, cy, dx, dy)))
    raise fail("room.outline_mm",
               f"{_wall_mm(outline, i)} and {_wall_mm(outline, j)} lie {gap * 1e3:g} mm apart "
               f"outside the outline, closer than the thinnest wall ({least * 1e3:g} mm): the "
               f"wall built outward of one would stand in the room beyond the other; move them "
               f"apart, or join them into one wall")


def _validate_geometry(sc: Scenario, fail) -> None:
    outline = sc.room.outline_m
    n = len(outline)
    if n < 3:
        raise fail("room.outline_mm", f"needs at least 3 corners, got {n}")
    if n > MAX_OUTLINE_CORNERS:
        raise fail("room.outline_mm", f"{n:,} corners; at most {MAX_OUTLINE_CORNERS:,} are "
                                      f"allowed (a wall a corner)")
    for i in range(n):
        a, b = outline[i], outline[(i + 1) % n]
        if math.hypot(b[0] - a[0], b[1] - a[1]) < 1e-6:
            raise fail(f"room.outline_mm[{i}]", "repeats the next corner (zero-length wall)")
    if on_one_line(outline):   # else named as its poses being outside it
        raise fail("room.outline_mm", f"all {n} corners lie on one line, so the outline "
                                      f"encloses no room; list the corners of an area")
    crossing = first_crossing(outline)
    if crossing is not None:
        raise fail("room.outline_mm", f"walls {crossing[0]} and {crossing[1]} cross: the "
                                      f"outline must not intersect itself")
    overlap = first_overlap(outline)
    if overlap is not None:
        i, j, shared = overlap
        raise fail("room.outline_mm", f"{_wall_mm(outline, i)} and {_wall_mm(outline, j)} "
                                      f"overlap along {shared * 1e3:g} mm: a wall must not run "
                                      f"back over another")
    _check_wall_thickness(sc, fail)
    if not sc.robot.poses:
        raise fail("robot.poses", "at least one scan pose is required")
    if len(sc.obstacles) > MAX_OBSTACLES:
        raise fail("obstacles", f"{len(sc.obstacles):,} obstacles; at most {MAX_OBSTACLES:,} "
                                f"are allowed")
    check_ring_placement(sc, fail)
    centres = np.array([ob.center_m for ob in sc.obstacles], dtype=float).reshape(-1, 2)
    in_room = inside_outline(centres[:, 0], centres[:, 1], outline)
    off_wall = distance_to_outline(centres[:, 0], centres[:, 1], outline)
    # how far each obstacle reaches from its centre: only those near a wall are clipped
    ob_reach = np.array([ob.radius_m if isinstance(ob, Cylinder) else
                         math.hypot(*ob.size_m) / 2 for ob in sc.obstacles], dtype=float)
    for j, ob in enumerate(sc.obstacles):
        if isinstance(ob, Box) and min(ob.size_m) < 0.002:
            raise fail(f"obstacles[{j}].size_mm", f"box sides ({ob.size_m[0] * 1e3:g}, "
                                                  f"{ob.size_m[1] * 1e3:g}) mm must each be ≥ 2 mm")
        # one reaching through a wall is clipped there (a partition built into it); one
        # wholly outside is a mistake (nothing of it could be seen)
        if not in_room[j] and (ob_reach[j] <= off_wall[j] + GEOMETRY_TOL_M
                               or first_wall_into(ob, outline) is None):
            what = (f"cylinder (radius {ob.radius_m * 1e3:g} mm)" if isinstance(ob, Cylinder)
                    else f"box ({ob.size_m[0] * 1e3:g} × {ob.size_m[1] * 1e3:g} mm)")
            raise fail(f"obstacles[{j}].center_mm",
                       f"the {what} at ({ob.center_m[0] * 1e3:g}, {ob.center_m[1] * 1e3:g}) mm "
                       f"lies wholly outside the room; an obstacle must stand at least partly "
                       f"inside it (what reaches beyond a wall is ignored)")
    ring = sc.ring
    if ring.min_step > ring.max_step:
        raise fail("robot.ring.min_step", f"min_step {ring.min_step} > max_step {ring.max_step}")
    reach = max(abs(ring.min_step), abs(ring.max_step)) * ring.motor_step_rad * ring.gear
    if reach > ring.joint_limit_rad + 1e-9:
        raise fail("robot.ring", f"the sweep turns the sensors to ±{math.degrees(reach):g}° "
                                 f"(steps {ring.min_step} … {ring.max_step} × "
                                 f"{math.degrees(ring.motor_step_rad):g}° × gear {ring.gear:g}) "
                                 f"but joint_limit is ±{math.degrees(ring.joint_limit_rad):g}°; "
                                 f"narrow the steps or raise joint_limit_deg")


def check_ring_placement(sc: Scenario, fail: Callable[[str, str], Exception]) -> None:
    """Where the ring may stand: every scan pose inside the room with the ring and its
    housing clear of walls and obstacles, the sensors below the walls' tops; else raises
    ``fail(path, message)`` for the first pose (in file order) or key that fails."""
    ring, outline = sc.ring, sc.room.outline_m
    clearance = ring.radius_m + HOUSING_M  # sensors plus their housing
    # every pose at once (a scenario may hold 10 000 poses and 10 000 corners)
    px = np.array([pose.x_m for pose in sc.robot.poses])
    py = np.array([pose.y_m for pose in sc.robot.poses])
    outside = ~inside_outline(px, py, outline)
    near_wall = distance_to_outline(px, py, outline) < clearance - GEOMETRY_TOL_M
    overlaps = np.zeros((len(sc.obstacles), px.size), bool)
    for j, ob in enumerate(sc.obstacles):
        overlaps[j] = obstacle_distance(ob, px, py) < clearance - GEOMETRY_TOL_M
    bad = np.flatnonzero(outside | near_wall | overlaps.any(axis=0))
    if bad.size:   # the first pose that fails, as the file lists them
        k = int(bad[0])
        pose, path = sc.robot.poses[k], f"robot.poses[{k}]"
        if outside[k]:
            raise fail(path, f"pose ({pose.x_m * 1e3:g}, {pose.y_m * 1e3:g}) mm is outside the room")
        if near_wall[k]:
            raise fail(path, f"the ring (radius {clearance * 1e3:g} mm with housing) would be "
                             f"inside a wall at ({pose.x_m * 1e3:g}, {pose.y_m * 1e3:g}) mm; "
                             f"keep the pose ≥ {clearance * 1e3:g} mm from every wall")
        j = int(np.argmax(overlaps[:, k]))
        ob = sc.obstacles[j]
        raise fail(path, f"the ring (radius {clearance * 1e3:g} mm with housing) at "
                         f"({pose.x_m * 1e3:g}, {pose.y_m * 1e3:g}) mm would overlap "
                         f"obstacles[{j}] ({type(ob).__name__.lower()} at "
                         f"({ob.center_m[0] * 1e3:g}, {ob.center_m[1] * 1e3:g}) mm); "
                         f"keep the pose ≥ {clearance * 1e3:g} mm from it")
    if ring.sensor_height_m >= sc.room.wall_height_m:
        raise fail("robot.ring.sensor_height_mm",
                   f"sensors at {ring.sensor_height_m * 1e3:g} mm would look over the "
                   f"{sc.room.wall_height_m * 1e3:g} mm walls (and obstacles, which are as tall); "
                   f"allowed: below room.wall_height_mm")


# --------------------------------------------------------------------------- public API

# an obstacle reaching less than this past a wall is one written flush with it (a rounded
# centre or size): clipped all the same, but not worth a note
CLIP_NOTE_MIN_M = 0.001


@dataclass(frozen=True)
class Clipped:
    """An obstacle reaching through the walls (:func:`clipped_obstacles`)."""

    index: int                # in ``scenario.obstacles`` (the file's obstacles[index])
    walls: tuple[int, ...]    # the walls that come into it (outline indices)
    reach_m: float            # how far it reaches past the walls' inner face
    share: float              # the part of its footprint's area beyond the walls (0 … 1)
    note: str                 # the one line saying so (run summaries, `irring scenarios`)

    def as_json(self) -> dict:
        return {"obstacle": self.index, "walls": list(self.walls),
                "reach_mm": round(self.reach_m * 1e3, 1), "share_clipped": round(self.share, 4),
                "note": self.note}


def clipped_obstacles(sc: Scenario) -> list[Clipped]:
    """The obstacles the walls clip by more than CLIP_NOTE_MIN_M, in file order: a box put
    against a wall on purpose is normal, a mistyped centre putting one half through a wall
    is not, and only the user can tell them apart (a note, never an error)."""
    outline = sc.room.outline_m
    centres = np.array([ob.center_m for ob in sc.obstacles], dtype=float).reshape(-1, 2)
    reach_max = np.array([ob.radius_m if isinstance(ob, Cylinder) else
                          math.hypot(*ob.size_m) / 2 for ob in sc.obstacles], dtype=float)
    near = reach_max > distance_to_outline(centres[:, 0], centres[:, 1], outline)
    out = []
    for j in np.flatnonzero(near).tolist():
        ob = sc.obstacles[j]
        into = np.flatnonzero(walls_into(ob, outline))
        if not into.size:
            continue
        reach = reach_outside(ob, outline)
        if reach <= CLIP_NOTE_MIN_M:
            continue
        shape = footprint(ob)
        share = 1.0 - polygon_area(clip_to_convex(outline, shape)) / polygon_area(shape)
        what = (f"a cylinder of radius {ob.radius_m * 1e3:g} mm" if isinstance(ob, Cylinder)
                else f"a {ob.size_m[0] * 1e3:g} × {ob.size_m[1] * 1e3:g} mm box")
        walls = " and ".join(_wall_mm(outline, int(k)) for k in into)
        note = (f"obstacles[{j}], {what} at ({ob.center_m[0] * 1e3:g}, "
                f"{ob.center_m[1] * 1e3:g}) mm, reaches {reach * 1e3:.0f} mm through {walls}: "
                f"{share:.1%} of it lies beyond the walls, clipped (never seen, not scored)")
        out.append(Clipped(j, tuple(int(k) for k in into), reach, share, note))
    return out


def bundled_dir() -> Path:
    """Folder of the bundled scenarios (works for editable and plain installs)."""
    return resources.scenarios_dir()


def bundled() -> dict[str, Path]:
    return {p.stem: p for p in sorted(bundled_dir().glob("*.yaml"))}


DEFAULT_SCENARIO = "t_room"
MAX_DESCRIPTION = 1000   # characters


def resolve(name_or_path: str | Path) -> Path:
    """A path, or the name of a bundled scenario (`t_room`)."""
    p = Path(name_or_path)
    found = bundled()
    if p.exists() and not (p.is_dir() and str(name_or_path) in found):  # `--out t_room` made a folder
        return p
    if str(name_or_path) in found:
        return found[str(name_or_path)]
    near = _close(p.name, found) if p.parent == Path(".") else ""   # a name, not a path
    # `irring run my_room` beside my_room.yaml: the file, not the nearest bundled name
    files = [q for q in ((p.with_name(p.name + ".yaml"), p.with_name(p.name + ".yml"))
                         if p.name and not p.suffix else ()) if q.is_file()]
    if files:
        near = f" (did you mean `{files[0]}`?)"
    raise ScenarioError(f"{name_or_path}: no such file and no bundled scenario of that name"
                        f"{near}; bundled: {', '.join(found)}")


def parse(raw: Any, source: str = "") -> Scenario:
    """Validate an already-parsed YAML document."""
    loader = _Loader(source)
    if not isinstance(raw, Mapping):
        raise loader.fail("", "a scenario file must be a mapping (key: value) at the top")
    sc = loader.dataclass_(Scenario, raw, "")
    if not sc.name.strip() or len(sc.name) > 200:
        raise loader.fail("name", "expected a name of 1 … 200 characters")
    if len(sc.description) > MAX_DESCRIPTION:   # a 7 MB one was printed by every run
        raise loader.fail("description", f"{len(sc.description):,} characters; a description "
                                         f"is a line of at most {MAX_DESCRIPTION:,} (irring run "
                                         f"and irring scenarios print it)")
    for key, text in (("name", sc.name), ("description", sc.description)):
        if any(not (ch.isprintable() or ch in "\n\t") for ch in text):
            raise loader.fail(key, "control characters (terminal escapes) are not allowed")
    if "\n" in sc.name:   # map.png's title: Pillow's text layout failed on it (exit 70)
        raise loader.fail("name", "a line break is not allowed; a name is one line (the title "
                                  "of map.png, the output folder)")
    if (why := formula_start(sc.name)) is not None:
        raise loader.fail("name", why)
    sc = dataclasses.replace(sc, source=source)
    ring_raw = raw["robot"].get("ring") if isinstance(raw.get("robot"), Mapping) else None
    if isinstance(ring_raw, Mapping):
        given = tuple(f.name for f in dataclasses.fields(Ring)
                      if any(k in ring_raw for k, _ in _yaml_keys(f.name)))
        sc = dataclasses.replace(sc, robot=dataclasses.replace(sc.robot, ring_keys=given))
    sc = _part_range(sc, raw)
    sc = _sensor_for_design(sc, raw, loader.fail)
    try:   # a custom design without a ring: named with the file, like every other key
        ring_for(sc.robot)
    except ScenarioError as exc:
        raise ScenarioError(f"{source}: {exc}" if source else str(exc)) from None
    _validate_geometry(sc, loader.fail)
    _validate_effects(sc, loader.fail)
    return sc


# RK4 on the critically damped belt spring: stable up to timestep ≈ 2.6 τ (measured: 2.5 τ runs,
# 2.7 τ goes unstable, for τ = 0.2 and 1 ms); the loader allows 2.5 τ.
BELT_STABLE_STEP_RATIO = 2.5


def _validate_effects(sc: Scenario, fail) -> None:
    """What the schema's per-field bounds cannot say: knobs that only act with an effect,
    and a motion path that goes somewhere."""
    if sc.scan.samples != 1 and not sc.has("averaging"):
        raise fail("scan.samples", f"{sc.scan.samples} readings per step are averaged only "
                                   "with the `averaging` effect (and would be charged in "
                                   "hardware time for nothing); add `averaging` to effects or "
                                   "leave scan.samples out")
    outliers = sc.effects.get("outliers")
    if outliers is not None:
        total = outliers.short_rate + outliers.random_rate + outliers.max_rate
        if total > 1.0:
            raise fail("effects.outliers", f"short_rate + random_rate + max_rate = {total:g}; "
                                           "they are shares of exclusive cases, so their sum "
                                           "must be ≤ 1")
    incidence = sc.effects.get("incidence")
    if incidence is not None and incidence.max_incidence_rad is not None \
            and incidence.max_incidence_rad <= 0:
        raise fail("effects.incidence.max_incidence_deg", "must be > 0° (at 0° every return "
                                                          "would drop out)")
    belt = sc.effects.get("belt_dynamics")
    if belt is not None and belt.timestep_s > BELT_STABLE_STEP_RATIO * belt.belt_timeconst_s:
        raise fail("effects.belt_dynamics.timestep_ms",
                   f"{belt.timestep_s * 1e3:g} ms is more than {BELT_STABLE_STEP_RATIO:g} × "
                   f"belt_timeconst_ms ({belt.belt_timeconst_s * 1e3:g} ms), where the belt "
                   f"physics goes unstable; lower timestep_ms or raise belt_timeconst_ms")
    motion = sc.effects.get("motion")
    if motion is not None:
        if len(motion.path) < 2:
            raise fail("effects.motion.path", f"needs at least 2 waypoints to drive along, got "
                                              f"{len(motion.path)}")
        if motion.speed_m_s <= 0:
            raise fail("effects.motion.speed_mm_s", "must be > 0 to drive the path")
        length_m = sum(math.hypot(b.x_m - a.x_m, b.y_m - a.y_m)
                       for a, b in zip(motion.path, motion.path[1:]))
        if not math.isfinite(length_m / motion.speed_m_s):   # 1e-320 mm/s: no end in a float
            raise fail("effects.motion.speed_mm_s",
                       f"{motion.speed_m_s * 1e3:g} mm/s would never drive the path's "
                       f"{length_m * 1e3:g} mm; a run takes at most {MAX_SWEEPS:,} sweeps")


def _part_range(sc: Scenario, raw: Mapping) -> Scenario:
    """A ``sensor:`` block that names no max range reads to its model's range
    (``gp2.SENSORS``: the GP2D12 to the paper's 624 mm, the other parts to their curve's
    end), not to the GP2D12's: a GP2Y0A02 read to 624 mm sees 40 % of its range."""
    block = raw.get("sensor")
    if isinstance(block, Mapping) and any(k in block for k, _ in _yaml_keys("max_range_m")):
        return sc
    part = gp2.sensor_spec(sc.sensor.model).max_range_m
    if part == sc.sensor.max_range_m:
        return sc
    return dataclasses.replace(sc, sensor=dataclasses.replace(sc.sensor, max_range_m=part))


def _sensor_for_design(sc: Scenario, raw: Mapping, fail) -> Scenario:
    """A design that carries a non-IR sensor (laser, sonar12) brings its sensor block when the
    file names no sensor model; naming a different kind of sensor is an error, never a silent
    GP2D12 default under a laser's name."""
    if sc.robot.design not in designs.DESIGN_BY_NAME:
        return sc
    design = designs.get(sc.robot.design)
    if design.sensor.is_ir:
        return sc
    sensor_raw = raw.get("sensor") or {}
    if "model" not in sensor_raw:   # the robot as written: its ring keeps what it gives
        return dataclasses.replace(_with_design(sc, design), robot=sc.robot)
    if sc.sensor.model != design.sensor.kind:
        raise fail("sensor.model", f"{sc.sensor.model!r} does not fit design "
                                   f"{sc.robot.design!r}, which carries a {design.sensor.kind!r} "
                                   f"sensor; use model: {design.sensor.kind} or leave `model` out")
    return sc


def folder_files(folder: str | Path) -> list[Path]:
    """The scenarios a folder holds: its ``*.yaml`` files, sorted by name (ScenarioError
    when it holds none)."""
    files = sorted(Path(folder).glob("*.yaml"))
    if not files:
        raise ScenarioError(f"{folder}: the folder holds no *.yaml scenario")
    return files


def not_a_scenario_file(path: Path) -> str | None:
    """Why a ``*.yaml`` found in a folder is not read as a scenario, or None for a regular
    file (a pipe among the rooms would be waited on for good)."""
    if path.is_file():
        return None
    kind = ("a folder" if path.is_dir() else "a pipe, socket or device" if path.exists()
            else "a broken link (or a loop of links)")
    return f"{path}: is {kind}, not a scenario file; a folder's rooms are its regular *.yaml files"


def is_folder(name_or_path: str) -> bool:
    """``name_or_path`` names a folder of scenarios (a bundled name stays a name even where
    a folder of that name exists, as `--out t_room` makes one)."""
    return Path(name_or_path).is_dir() and name_or_path not in bundled()


def listed(name_or_path: str) -> list[tuple[str, bool]]:
    """What one argument of a command or study names: a folder's ``*.yaml`` files, each
    ``(path, True)`` (ScenarioError when it holds none), else ``[(name_or_path, False)]``.
    A file found in a folder is asked :func:`not_a_scenario_file` before it is read."""
    if is_folder(name_or_path):
        return [(str(f), True) for f in folder_files(name_or_path)]
    return [(name_or_path, False)]


def scenario_file(name_or_path: str | Path) -> Path | str:
    """The file a bundled name or a path means (links and ``..`` resolved), or
    ``name_or_path`` itself where it means none: two names of one room compare equal."""
    try:
        return resolve(name_or_path).resolve()
    except (ScenarioError, OSError):
        return name_or_path


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load and validate a scenario file (or a bundled scenario by name)."""
    path = resolve(name_or_path)
    try:
        text = safe_yaml.read_text(path, "scenario file")
    except safe_yaml.InputError as exc:
        raise ScenarioError(str(exc)) from None
    return loads(text, str(path))


def check_distinct_names(scenarios: Sequence[Scenario]) -> None:
    """ScenarioError when two scenarios share a ``name:`` (its Unicode forms, NFC and NFD,
    are one name): compare and bench accuracy report each scene by its name, so two rooms
    of one name would be averaged as one, or printed as one name twice."""
    seen: dict[str, Scenario] = {}
    for sc in scenarios:
        other = seen.setdefault(name_key(sc.name), sc)
        if other is not sc:
            form = "" if other.name == sc.name else " (in another Unicode form)"
            raise ScenarioError(
                f"{sc.source or sc.name}: named {sc.name!r}, as {other.source or other.name} "
                f"is{form}; the results name each scenario by its `name:`, so the two rooms "
                "would be merged into one; give them different names")


def counted_seeds(sc: Scenario, count: int) -> list[int]:
    """The seeds of ``count`` runs of ``sc`` (its seed, +1, …), as study, compare and bench
    count them; :class:`ScenarioError` naming the scenario when the last passes
    ``SEED_MAX``, a seed ``irring run --seed`` and the scenario file refuse (its run could not
    be run again)."""
    last = sc.seed + count - 1
    if last > SEED_MAX:
        raise ScenarioError(f"{sc.source or sc.name}: seed: {sc.seed} and {count:,} seeds counted "
                            f"up from it reach {last}; allowed up to {SEED_MAX} (the largest "
                            f"seed a scenario or --seed takes): give the scenario a seed of at "
                            f"most {SEED_MAX - count + 1}")
    return [sc.seed + k for k in range(count)]


def loads(text: str, source: str = "<string>") -> Scenario:
    """Load and validate a scenario from its YAML ``text``; ``source`` names it in errors."""
    try:
        raw = safe_yaml.load(text, source, "scenario file")
    except safe_yaml.InputError as exc:
        raise ScenarioError(str(exc)) from None
    return dataclasses.replace(parse(raw, source), text=text)


# --------------------------------------------------------------------------- designs in scenes


def sensor_block(design: Design, base: Sensor | None = None) -> Sensor:
    """The scenario ``sensor:`` block for a design (ADC settings kept from ``base`` for IR
    sensors)."""
    if design.sensor.is_ir and base is not None:
        return dataclasses.replace(base, model=design.sensor.kind,
                                   max_range_m=design.sensor.max_range_m)
    vref = base.vref_v if base is not None else VREF_V
    return Sensor(model=design.sensor.kind, max_range_m=design.sensor.max_range_m,
                  adc_bits=design.sensor.adc_bits, vref_v=vref)


def _overrides(ring: Ring) -> dict:
    """Fields of a scenario's ``robot.ring`` that differ from the paper's ring."""
    return {f.name: getattr(ring, f.name) for f in dataclasses.fields(Ring)
            if getattr(ring, f.name) != getattr(designs.PAPER_RING, f.name)}


def ring_for(robot: Robot) -> Ring:
    """The ring a robot uses.

    ``design: custom`` takes ``robot.ring`` as written (fields left out keep the paper's
    values). A named design takes that design's ring, and each ``robot.ring`` field the file
    gave (``ring_keys``) or that differs from the paper's value replaces the design's (so
    ``design: radial12`` with ``ring: {sensors: 8}`` is a still ring of 8).
    """
    if robot.design == "custom":
        if robot.ring is None:
            raise ScenarioError("robot.ring: required when robot.design is custom; give the "
                                "ring's numbers (sensors, radius_mm, min_step, max_step, …)")
        return robot.ring
    ring = designs.get(robot.design).ring
    if robot.ring is not None:
        given = {k: getattr(robot.ring, k) for k in robot.ring_keys}
        ring = dataclasses.replace(ring, **{**_overrides(robot.ring), **given})
    return ring


def design_for(scenario: Scenario) -> Design:
    """The design a scenario runs: its named design with its ring and sensor model."""
    ring = scenario.ring
    named = designs.DESIGN_BY_NAME.get(scenario.robot.design)
    if named is not None and ring == named.ring and scenario.sensor.model == named.sensor.kind:
        return named
    spec = dataclasses.replace(gp2.sensor_spec(scenario.sensor.model),
                               max_range_m=scenario.sensor.max_range_m)
    return Design(scenario.robot.design, ring, spec, "from the scenario")


def apply_design(scenario: Scenario, design: Design | str) -> Scenario:
    """The same scene (room, obstacles, poses, map, seed) seen by another design.

    The robot's ring and design name, and the ``sensor:`` block, become the design's. For
    GP2 designs the scenario's effects stay as they are; for laser and sonar the GP2-specific
    stages (incidence curves, fold-over, volts of noise) are replaced by the design's own
    range noise, so each design is simulated with the sensor it would carry.

    The design's ring must stand where the scene's did as a file's own ring must (scan poses
    clear of walls and obstacles by its radius and housing, sensors below the walls): else
    ScenarioError naming the scene and the design. (A motion path is checked where the
    drive is built; ``studies.accuracy.design_in`` checks it first.)
    """
    d = designs.get(design) if isinstance(design, str) else design
    sc = _with_design(scenario, d)
    check_ring_placement(sc, _Loader(f"{scenario.source or scenario.name}: design {d.name!r} "
                                     f"in place of its ring").fail)
    return sc


def _with_design(scenario: Scenario, d: Design) -> Scenario:
    """:func:`apply_design` without its checks."""
    robot_design = d.name if d.name in designs.DESIGN_BY_NAME else "custom"
    robot = dataclasses.replace(scenario.robot, design=robot_design,
                                ring=None if robot_design != "custom" else d.ring)
    sensor = sensor_block(d, scenario.sensor)
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
    model = gp2.sensor(design.sensor.kind)
    d = 0.5 * design.sensor.max_range_m
    h = 1e-3 * d
    slope = abs(float(model.voltage(d + h) - model.voltage(d - h)) / (2 * h))  # V per m
    return float(min(max(design.sensor.noise_sigma_m * slope, 0.0), 1.0))
