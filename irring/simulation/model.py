"""MuJoCo models for a ring design and a scenario, built with ``mujoco.MjSpec`` from the one
template ``models/irring.xml`` (no XML is templated as text). Ray targets are in geom group
``RAY_GROUP``, so a ray cast filtered to ``RAY_GEOMGROUP`` sees only the room. How a ring is
replicated, and the compiled model's names: docs/simulation.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from .. import resources
from ..core import Box, Cylinder, Ring, built_wall_thickness, wall_extents
from ..scenario import Scenario

TEMPLATE = "irring.xml"
PROTOTYPE = "ir_00"
RAY_GROUP = 0                 # geom group of everything a beam can hit (walls, obstacles)
FLOOR_GROUP = 1
RAY_GEOMGROUP = np.array([g == RAY_GROUP for g in range(6)], dtype=np.uint8)

WALL_RGBA = (0.93, 0.92, 0.88, 1.0)
OBSTACLE_RGBA = (0.75, 0.45, 0.2, 1.0)
# joint_limit 0 is a ring held still (steps 0 … 0); MuJoCo refuses a hinge range [0, 0], so a
# held hinge gets ±this: no sweep turns it (the loader refuses steps past the limit).
HELD_HINGE_RAD = 1e-6


def sensor_name(k: int) -> str:
    """Name of sensor k's body (``ir_00`` …); its hinge, site, rangefinder and belt follow."""
    return f"ir_{k:02d}"


def template_path() -> Path:
    return resources.models_dir() / TEMPLATE


def _yaw_quat(yaw_rad: float) -> list[float]:
    return [math.cos(yaw_rad / 2.0), 0.0, 0.0, math.sin(yaw_rad / 2.0)]


# --------------------------------------------------------------------------- the robot


def ring_spec(ring: Ring) -> mujoco.MjSpec:
    """The robot of a ring design, from the template: N sensors replicated from ``ir_00``."""
    spec = mujoco.MjSpec.from_file(str(template_path()))
    for body in list(spec.bodies):  # their belts and rangefinders go with them
        if body.name.startswith("ir_") and body.name != PROTOTYPE:
            spec.delete(body)
    proto = spec.body(PROTOTYPE)
    proto_eq = spec.equality("belt_00")
    proto_rf = spec.sensor("ir_00_range")
    if proto is None or proto_eq is None or proto_rf is None:
        raise RuntimeError(f"{template_path()}: the template must define body {PROTOTYPE}, "
                           "equality belt_00 and rangefinder ir_00_range")
    chassis = spec.body("chassis")

    spec.copy_during_attach = True
    holder = chassis.add_frame()  # identity frame: copies keep body-relative poses
    for k in range(1, ring.sensors):
        tag = sensor_name(k)
        body = holder.attach_body(proto, "", f"#{k}")  # a deep copy, with its rangefinder
        _rename(body, PROTOTYPE, tag)
        rf = spec.sensor(f"ir_00_range#{k}")
        rf.name, rf.objname = f"{tag}_range", f"{tag}_emitter"
        spec.add_equality(name=f"belt_{k:02d}", type=proto_eq.type, objtype=proto_eq.objtype,
                          name1=f"{tag}_hinge", name2=proto_eq.name2, data=proto_eq.data,
                          solref=proto_eq.solref, solimp=proto_eq.solimp,
                          active=proto_eq.active)

    step_lo, step_hi = ring.min_step * ring.motor_step_rad, ring.max_step * ring.motor_step_rad
    for k in range(ring.sensors):
        tag = sensor_name(k)
        rho = 2.0 * math.pi * k / ring.sensors
        body = spec.body(tag)
        body.pos = [ring.radius_m * math.cos(rho), ring.radius_m * math.sin(rho),
                    ring.sensor_height_m]
        body.quat = _yaw_quat(rho)
        body.alt.euler = [0.0, 0.0, 0.0]  # the template spells orientation as euler
        body.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
        hinge = spec.joint(f"{tag}_hinge")
        limit = max(ring.joint_limit_rad, HELD_HINGE_RAD)
        hinge.range = [-limit, limit]
        hinge.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        # the emitter (and its lens) d_o to the right of the hinge: body −y
        spec.site(f"{tag}_emitter").pos = [0.0, -ring.emitter_offset_m, 0.0]
        lens = spec.geom(f"{tag}_emitter_lens")
        lens.pos = [lens.pos[0], -ring.emitter_offset_m, lens.pos[2]]
        belt = spec.equality(f"belt_{k:02d}")
        data = np.array(belt.data)
        data[:5] = [0.0, ring.gear, 0.0, 0.0, 0.0]  # sensor = gear × motor
        belt.data = data

    motor = spec.actuator("ring_motor")
    # the motor may be commanded over the design's step range (and never less than ±1 step)
    motor.ctrlrange = [min(step_lo, -ring.motor_step_rad), max(step_hi, ring.motor_step_rad)]
    spec.joint("ring_motor").range = [0.0, 0.0]  # unlimited: the sensors carry the limits

    for key in list(spec.keys):  # qpos sizes changed; a fresh home pose
        spec.delete(key)
    spec.add_key(name="home", qpos=np.zeros(1 + ring.sensors), ctrl=[0.0],
                 mpos=[0.0, 0.0, 0.0], mquat=[1.0, 0.0, 0.0, 0.0])
    spec.modelname = "irring" if ring == Ring() else f"irring_{ring.sensors}"
    return spec


def _rename(body: mujoco.MjsBody, old: str, new: str) -> None:
    """Give a copied sensor body and its children the names of sensor `new`."""
    def fix(name: str) -> str:
        return new + name.split("#", 1)[0][len(old):] if name else name

    body.name = fix(body.name)
    for kind in ("geom", "site", "joint"):
        for el in body.find_all(kind):
            el.name = fix(el.name)


# --------------------------------------------------------------------------- the room


def add_room(spec: mujoco.MjSpec, scenario: Scenario) -> dict[str, float]:
    """Add floor, light, walls and obstacles; return geom name → reflectance."""
    world = spec.worldbody
    world.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05],
                   group=FLOOR_GROUP, rgba=[0.25, 0.3, 0.35, 1.0])
    xs = [p[0] for p in scenario.room.outline_m]
    ys = [p[1] for p in scenario.room.outline_m]
    centre = [(min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2]
    world.add_light(name="top", pos=[centre[0], centre[1], 3.0], dir=[0, 0, -1],
                    type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
    reflectance: dict[str, float] = {}
    room = scenario.room
    thickness = built_wall_thickness(room.outline_m, room.wall_thickness_m)   # a partition's
    for i, (size, pos, yaw) in enumerate(wall_boxes(room.outline_m, thickness, room.wall_height_m)):
        name = f"wall_{i:02d}"
        world.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, size=size, pos=pos,
                       quat=_yaw_quat(yaw), group=RAY_GROUP, rgba=WALL_RGBA)
        reflectance[name] = room.reflectance
    half_h = room.wall_height_m / 2.0
    for j, ob in enumerate(scenario.obstacles):
        name = f"obstacle_{j:02d}"
        if isinstance(ob, Cylinder):
            world.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                           size=[ob.radius_m, half_h, 0], pos=[*ob.center_m, half_h],
                           group=RAY_GROUP, rgba=OBSTACLE_RGBA)
        elif isinstance(ob, Box):
            world.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX,
                           size=[ob.size_m[0] / 2, ob.size_m[1] / 2, half_h],
                           pos=[*ob.center_m, half_h], quat=_yaw_quat(ob.yaw_rad),
                           group=RAY_GROUP, rgba=OBSTACLE_RGBA)
        else:  # pragma: no cover - the schema only has these two
            raise TypeError(f"obstacles[{j}]: unsupported obstacle {ob!r}")
        reflectance[name] = ob.reflectance
    return reflectance


def wall_boxes(outline: tuple[tuple[float, float], ...], thickness_m: float,
               height_m: float) -> list[tuple[list[float], list[float], float]]:
    """(half sizes, centre, yaw) of one box per wall.

    Each box lies OUTSIDE the room with its inner face exactly on the outline segment, so a
    beam from inside hits the outline itself. At convex corners a box is lengthened by the
    thickness to close the outside corner; at reflex (inward) corners it is not, or it would
    stick into the room.
    """
    pts = np.asarray(outline, dtype=float)
    n = len(pts)
    u, outward, ext_a, ext_b, length = wall_extents(pts, thickness_m)
    boxes = []
    for i in range(n):
        a, b = pts[i], pts[(i + 1) % n]
        centre = ((a + b) / 2 + u[i] * (ext_b[i] - ext_a[i]) / 2
                  + outward[i] * thickness_m / 2)
        half = [(float(length[i]) + ext_a[i] + ext_b[i]) / 2, thickness_m / 2, height_m / 2]
        boxes.append(([float(h) for h in half], [float(centre[0]), float(centre[1]), height_m / 2],
                      math.atan2(u[i][1], u[i][0])))
    return boxes


def scenario_spec(scenario: Scenario) -> tuple[mujoco.MjSpec, dict[str, float]]:
    """The robot of the scenario's design in its room; also geom name → reflectance."""
    spec = ring_spec(scenario.ring)
    spec.modelname = f"irring_{scenario.name}"
    reflectance = add_room(spec, scenario)
    return spec, reflectance


# --------------------------------------------------------------------------- compiled model


@dataclass(frozen=True)
class RingModel:
    """A compiled model with every name resolved to ids and addresses once.

    Arrays over sensors are ordered k = 0 … N−1 (``ir_00`` …).
    """

    model: mujoco.MjModel
    ring: Ring
    motor_qpos: int           # its qpos address
    motor_actuator: int       # actuator id of ring_motor
    sensor_joints: np.ndarray  # (N,) joint ids of the sensor hinges
    sensor_qpos: np.ndarray   # (N,) their qpos addresses
    emitter_sites: np.ndarray  # (N,) site ids of the emitters
    belt_coef: np.ndarray     # (N, 2): sensor angle = c0 + c1 · motor angle
    chassis_mocap: int        # mocap index of the chassis (the robot pose)
    ray_geoms: np.ndarray     # ids of the geoms beams can hit (walls, obstacles)
    reflectance: np.ndarray   # (ngeom,) reflectance of ray targets; NaN for other geoms

    @property
    def n_sensors(self) -> int:
        return len(self.sensor_joints)

    def sensor_qpos_for(self, motor_rad: np.ndarray) -> np.ndarray:
        """(..., N) sensor hinge angles the belt imposes for motor angles (...,)."""
        m = np.asarray(motor_rad, dtype=float)[..., None]
        return self.belt_coef[:, 0] + self.belt_coef[:, 1] * m


def compile_ring(ring: Ring) -> RingModel:
    """The robot alone (no room), e.g. to look at a design's sensor frames."""
    return _resolve(ring_spec(ring).compile(), ring, {})


def build(scenario: Scenario) -> RingModel:
    """The scenario's MuJoCo model (robot of its design, walls, obstacles)."""
    spec, reflectance = scenario_spec(scenario)
    return _resolve(spec.compile(), scenario.ring, reflectance)


def room_model(scenario: Scenario, scene: mujoco.MjModel) -> tuple[mujoco.MjModel, np.ndarray]:
    """The scenario's room alone (floor, walls, obstacles: no robot) for ray casts, and the
    ``scene`` model's geom id of each of its geoms. A ray call tests every geom of its model
    against every ray, group filter or not: without the robot's geoms it takes less time for
    the same hits (both models place the world's geoms from the same numbers;
    docs/simulation.md has the figures)."""
    spec = mujoco.MjSpec()
    spec.modelname = f"irring_{scenario.name}_room"
    add_room(spec, scenario)
    room = spec.compile()
    ids = np.array([mujoco.mj_name2id(scene, mujoco.mjtObj.mjOBJ_GEOM, room.geom(g).name)
                    for g in range(room.ngeom)], dtype=np.int32)
    if ids.min(initial=0) < 0:
        raise RuntimeError("the room model has a geom the scene model lacks")
    return room, ids


def _resolve(model: mujoco.MjModel, ring: Ring, reflectance: dict[str, float]) -> RingModel:
    def jid(name: str) -> int:
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)

    names = [sensor_name(k) for k in range(ring.sensors)]
    sensor_joints = np.array([jid(f"{n}_hinge") for n in names], dtype=int)
    sites = np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"{n}_emitter")
                      for n in names], dtype=int)
    rfs = np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, f"{n}_range")
                    for n in names], dtype=int)
    belts = np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, f"belt_{k:02d}")
                      for k in range(ring.sensors)], dtype=int)
    if min(sensor_joints.min(), sites.min(), rfs.min(), belts.min()) < 0:
        raise RuntimeError("the compiled ring lacks a sensor's hinge, site, rangefinder or belt")
    motor = jid("ring_motor")
    chassis = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "chassis")
    refl = np.full(model.ngeom, np.nan)
    for name, value in reflectance.items():
        refl[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)] = value
    ray_geoms = np.flatnonzero(model.geom_group == RAY_GROUP)
    return RingModel(
        model=model, ring=ring, motor_qpos=int(model.jnt_qposadr[motor]),
        motor_actuator=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, "ring_motor"),
        sensor_joints=sensor_joints, sensor_qpos=model.jnt_qposadr[sensor_joints].copy(),
        emitter_sites=sites, belt_coef=model.eq_data[belts, :2].copy(),
        chassis_mocap=int(model.body_mocapid[chassis]), ray_geoms=ray_geoms,
        reflectance=refl)
