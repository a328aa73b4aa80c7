"""The simulated ring: move the sensors kinematically, cast MuJoCo rays, make a :class:`Sweep`.

How it works, its assumptions and measured figures: docs/simulation.md.
"""

from __future__ import annotations

import copy
import math
import functools
from dataclasses import dataclass

import mujoco
import mujoco.batch
import numpy as np

from ..core import (BYTES_PER_PHYSICS_VALUE, MAX_STEPS, MAX_SWEEPS, SEED_MAX, Sweep, Truth, as_pose,
                    check_steps, count_text, gigabytes, hardware_duration_s, work_bytes,
                    work_refusal)
from ..errors import TooBig
from ..scenario import Scenario
from . import dynamics as dynamics_lib
from . import model as model_lib
from .rangers import pipeline_for

_POS = mujoco.mjtStage.mjSTAGE_POS
# Kinematic positioning needs only frames: no contacts, constraints, sensors or actuators.
_KINEMATICS_ONLY = int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT | mujoco.mjtDisableBit.mjDSBL_CONTACT
                       | mujoco.mjtDisableBit.mjDSBL_SENSOR | mujoco.mjtDisableBit.mjDSBL_ACTUATION)
_FRAME_CACHE = 8   # robot-frame frames kept for this many distinct angle sets


@dataclass(frozen=True)
class RayHits:
    """What a batch of rays hit. Leading shape ``(...)`` is that of the rays cast.

    ``distance_m``: from the ray origin along the unit direction; NaN where nothing is hit
    within the max range. ``incidence_rad``: angle between the ray and the surface normal,
    0 … π/2; NaN where no hit. ``hit_point`` (..., 3) world; NaN where no hit.
    ``geom_id``: MuJoCo geom id, −1 where no hit. ``reflectance``: the scenario's
    reflectance of the surface hit; NaN where no hit.
    """

    distance_m: np.ndarray
    incidence_rad: np.ndarray
    hit_point: np.ndarray
    geom_id: np.ndarray
    reflectance: np.ndarray


def pose_quat(yaw_rad: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions of yaw rotations about world z."""
    yaw = np.asarray(yaw_rad, dtype=float)
    out = np.zeros(yaw.shape + (4,))
    out[..., 0] = np.cos(yaw / 2.0)
    out[..., 3] = np.sin(yaw / 2.0)
    return out


def check_work(sim: SimRing) -> None:
    """Raise :class:`irring.errors.TooBig` when the scene's run (every sweep's readings and
    the belt physics) exceeds the limits in :mod:`irring.core`, naming what it would take and
    the keys that set it."""
    where = sim.scenario.source or sim.scenario.name
    steps, sensors, sweeps = len(sim.default_steps()), sim.built.n_sensors, sim.n_sweeps
    readings = sweeps * steps * sensors
    physics_steps = 0
    if sim.dynamics is not None and sim.dynamics.belt is not None:
        sched = sim.dynamics.schedule(sim.default_steps())
        physics_steps = int(math.ceil(sched.duration_s / sim.dynamics.belt.timestep_s)) + 1
    physics_bytes = physics_steps * (sim.model.nq + sim.model.nv) * BYTES_PER_PHYSICS_VALUE
    reading_bytes = work_bytes(readings, steps * sensors)
    need = reading_bytes + physics_bytes
    work = (f"{count_text(sweeps)} sweeps × {steps:,} steps × {sensors} sensors = "
            f"{count_text(readings)} readings"
            + (f" and {count_text(physics_steps)} belt physics steps" if physics_steps else ""))
    sweep_keys = "narrow robot.ring min_step … max_step or raise scan.step_stride"
    if steps > MAX_STEPS:
        raise TooBig(f"{where}: {work} (about {gigabytes(need)}): a sweep takes at most "
                     f"{MAX_STEPS:,} steps; {sweep_keys}")
    if sweeps > MAX_SWEEPS:
        fix = ("raise effects.motion.speed_mm_s or shorten effects.motion.path"
               if sim.scenario.has("motion") else
               f"list at most {MAX_SWEEPS:,} robot.poses (a sweep each), or split them "
               "into several scenarios")
        raise TooBig(f"{where}: {work} (about {gigabytes(need)}): a run takes at most "
                     f"{MAX_SWEEPS:,} sweeps; {fix}")
    keys = (f"{sweep_keys}, or use fewer robot.ring.sensors, robot.poses or a shorter or "
            f"faster effects.motion")
    if physics_bytes > reading_bytes:
        keys = ("raise effects.belt_dynamics.timestep_ms or lower step_time_ms, lower "
                f"scan.settle_ms or scan.samples, or {sweep_keys}")
    refusal = work_refusal(work, need, "a run", keys)
    if refusal:
        raise TooBig(f"{where}: {refusal}")


class SimRing:
    """The scenario's ring in its room, swept kinematically.

    ``SimRing(scenario, seed=None, pipeline=None)``: ``seed`` defaults to ``scenario.seed``;
    ``pipeline`` (an :class:`irring.simulation.effects.Pipeline`) defaults to
    ``rangers.pipeline_for(scenario)``: the scene's effects, with the sonar cone for a sonar.
    The k-th sweep at pose p draws its noise from ``np.random.default_rng([seed, p, k])``, so
    a fresh ``SimRing`` with the same scenario and seed reproduces every sweep; :meth:`reset`
    forgets the sweep counters. A :class:`irring.core.RingSource`: ``pipeline.acquire``
    drives it as it drives the real ring (``close`` releases nothing; MuJoCo's memory goes
    with the object).

    Attributes: ``model`` (``mujoco.MjModel``), ``data`` (an ``MjData`` for callers who step
    physics), ``ray_model`` (the room alone, which the rays are cast into:
    :func:`irring.simulation.model.room_model`), ``built``
    (:class:`irring.simulation.model.RingModel`: ids and addresses), ``scenario``,
    ``ring``, ``pipeline`` (the scene's effects pipeline, built on first use unless given),
    ``dynamics`` (:class:`irring.simulation.dynamics.Dynamics` when the scene lists ``belt_dynamics``,
    ``timing`` or ``motion``, else None), ``n_sweeps`` (sweeps the scene takes: one per
    scan pose, or with ``motion`` back to back along the path).
    """

    def __init__(self, scenario: Scenario, *, seed: int | None = None, pipeline=None):
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))
                                 or not 0 <= seed <= SEED_MAX):
            # numpy's "expected non-negative integer" named no seed; 1.5 was taken as 1
            raise ValueError(f"seed must be a whole number 0 … {SEED_MAX}, got {seed!r}")
        self.scenario = scenario
        self.ring = scenario.ring
        self.built = model_lib.build(scenario)
        self.model = self.built.model
        self.data = mujoco.MjData(self.model)
        mujoco.mj_resetDataKeyframe(self.model, self.data, 0)
        mujoco.mj_forward(self.model, self.data)
        self.max_range_m = float(scenario.sensor.max_range_m)
        self.adc_bits = int(scenario.sensor.adc_bits)
        self.seed = int(scenario.seed if seed is None else seed)
        self._kin_model = copy.copy(self.model)
        self._kin_model.opt.disableflags |= _KINEMATICS_ONLY
        self._kin: dict[int, tuple] = {}  # number of steps → (batch, bound arrays)
        self._frame_cache: dict[bytes, tuple] = {}  # angles → robot-frame emitter frames
        # rays go to the room alone (model.room_model); hits name the scene model's geoms
        self.ray_model, room_geoms = model_lib.room_model(scenario, self.model)
        self._rays = mujoco.batch.Batch(self.ray_model, 1, nthread=1)
        self._scene_geom = np.append(room_geoms, -1)   # a miss's id −1 reads the last
        self._pipeline = pipeline
        self._sweeps: dict[int, int] = {}
        # what every full static sweep needs and only the scenario decides, worked out once:
        # its steps and the belt's sensor angles for them (handed out as copies), and the
        # hardware time of one step
        steps = self.default_steps()
        self._full_sweep = (steps, self.built.sensor_qpos_for(steps * self.ring.motor_step_rad))
        self._step_s = hardware_duration_s(1, scenario.scan.settle_s, scenario.samples_per_step)
        # reflectance by room-model geom id with a NaN at the end, where a miss's id −1 reads
        self._reflectance = np.append(self.built.reflectance[room_geoms], np.nan)
        self.dynamics = None  # irring.simulation.dynamics.Dynamics, only for scenes that need it
        if dynamics_lib.uses_dynamics(scenario):
            self.dynamics = dynamics_lib.Dynamics(scenario, self.built, self.seed)
        check_work(self)   # refuse a run too big for memory before any sweep

    # ------------------------------------------------------------------ set-up and state

    @property
    def pipeline(self):
        if self._pipeline is None:
            self._pipeline = pipeline_for(self.scenario)  # its effects, a sonar's cone included
        return self._pipeline

    def close(self) -> None:
        """Nothing to release (a RingSource closes; a simulator holds no device)."""

    def __enter__(self) -> SimRing:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def reset(self, seed: int | None = None) -> None:
        """Forget the sweep counters (and take a new seed if given)."""
        if seed is not None:
            self.seed = int(seed)
            if self.dynamics is not None:  # clocks and odometry come from the seed
                self.dynamics = dynamics_lib.Dynamics(self.scenario, self.built, self.seed)
        self._sweeps.clear()

    @functools.cached_property
    def n_sweeps(self) -> int:
        """Sweeps the scene takes: one per scan pose; with ``motion``, back to back until the
        robot reaches the end of its path. ``sweep(k)`` for k in range(n_sweeps). The scene
        alone decides it (not the seed), so it is worked out once: a moving sweep checks its
        index against it."""
        if self.dynamics is None:
            return len(self.scenario.robot.poses)
        return self.dynamics.n_sweeps(self.default_steps())

    def pose(self, pose_index: int = 0) -> np.ndarray:
        """(3,) x m, y m, yaw rad of the scenario's scan pose ``pose_index``."""
        poses = self.scenario.robot.poses
        if not -len(poses) <= pose_index < len(poses):
            raise IndexError(f"pose_index {pose_index} is out of range: scenario "
                             f"{self.scenario.name!r} has {len(poses)} pose(s), 0 … {len(poses) - 1}")
        p = poses[pose_index]
        return np.array([p.x_m, p.y_m, p.yaw_rad])

    def default_steps(self) -> np.ndarray:
        """Motor steps of a full sweep: min_step … max_step by ``scan.step_stride``."""
        return dynamics_lib.full_sweep_steps(self.scenario)

    def _check_steps(self, steps) -> np.ndarray:
        return check_steps(steps, self.ring.min_step, self.ring.max_step)

    # ------------------------------------------------------------------ kinematics

    def _kin_batch(self, n: int):
        entry = self._kin.get(n)
        if entry is None:
            batch = mujoco.batch.Batch(self._kin_model, n, nthread=1)
            batch.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
            entry = (batch, batch.bind("qpos"), batch.bind("mocap_pos"),
                     batch.bind("mocap_quat"), batch.bind("site_xpos"), batch.bind("site_xmat"))
            self._kin[n] = entry
        return entry

    def frames(self, sensor_angles: np.ndarray, pose: np.ndarray, *, reuse: bool = True
               ) -> tuple[np.ndarray, np.ndarray]:
        """Emitter positions and unit beam directions, (S, N, 3) each, from MuJoCo kinematics.

        ``sensor_angles`` (S, N) rad are the sensor hinge angles; ``pose`` is (3,) for the
        whole sweep, (S, 3) per step or (S, N, 3) per reading (x m, y m, yaw rad: a moving
        robot whose sensors measure at different instants).

        The chassis is rigid, so MuJoCo computes the frames once in the robot frame (one
        batched forward over all steps, kept for the last few distinct angle sets: a static
        scene sweeps the same angles every time) and each call places them at its pose;
        ``reuse=False`` runs MuJoCo's forward even for angles seen before (to time it).
        """
        angles = np.asarray(sensor_angles, dtype=float)
        pose = np.asarray(pose, dtype=float)
        frames = self._robot_frames(angles, reuse)       # origins and directions, stacked
        if pose.ndim == 2:                   # per step: the same pose for its N readings
            pose = pose[:, None, :]
        c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
        lead = np.shape(pose[..., 0])
        shift = np.zeros((2, 2) + (1,) * (2 - len(lead)) + lead)   # origins move, not directions
        shift[0, 0], shift[0, 1] = pose[..., 0], pose[..., 1]
        x, y = frames[..., 0], frames[..., 1]
        out = np.empty(frames.shape)
        out[..., 0] = c * x - s * y + shift[:, 0]
        out[..., 1] = s * x + c * y + shift[:, 1]
        out[..., 2] = frames[..., 2]
        return out[0], out[1]

    def _robot_frames(self, angles: np.ndarray, reuse: bool = True) -> np.ndarray:
        """Emitter positions and beam directions (2, S, N, 3) with the chassis at the origin:
        one batched MuJoCo position stage over all steps, remembered for the last
        ``_FRAME_CACHE`` angle sets (stacked, so placing them is one set of array steps)."""
        key = angles.tobytes() + bytes(str(angles.shape), "ascii")
        hit = self._frame_cache.get(key) if reuse else None
        if hit is not None:
            return hit
        batch, qpos, mpos, mquat, site_xpos, site_xmat = self._kin_batch(angles.shape[0])
        built = self.built
        qpos[:, built.sensor_qpos] = angles
        m = built.chassis_mocap
        mpos[:, m] = 0.0
        mquat[:, m] = (1.0, 0.0, 0.0, 0.0)
        batch.forward(stage=_POS)
        sites = built.emitter_sites
        frames = np.stack([site_xpos[:, sites],               # (a copy)
                           site_xmat[:, sites][..., 2::3]])   # site z axis: column 2 of xmat
        self._frame_cache.pop(key, None)
        if len(self._frame_cache) >= _FRAME_CACHE:
            self._frame_cache.pop(next(iter(self._frame_cache)))
        self._frame_cache[key] = frames
        return frames

    # ------------------------------------------------------------------ rays

    def cast(self, origin: np.ndarray, direction: np.ndarray, *,
             max_range_m: float | None = None) -> RayHits:
        """Cast rays from ``origin`` (..., 3) along ``direction`` (..., 3) (need not be unit).

        All rays go to MuJoCo in one batched call; only the room (walls, obstacles) is hit.
        Hits beyond ``max_range_m`` (default: the scenario's sensor max range) count as none.
        """
        o = np.asarray(origin, dtype=float)
        v = np.asarray(direction, dtype=float)
        given = (o.shape, v.shape)
        if o.shape != v.shape:  # broadcast only when needed (a sweep's rays need not)
            shape = np.broadcast_shapes(o.shape, v.shape)
            o, v = np.broadcast_to(o, shape), np.broadcast_to(v, shape)
        if o.shape[-1:] != (3,):
            raise ValueError(f"origin and direction must end in 3 coordinates, got {given[0]} "
                             f"and {given[1]}")
        lead = o.shape[:-1]
        o = o.reshape(-1, 3)
        v = v.reshape(-1, 3)
        length = np.sqrt(np.einsum("ij,ij->i", v, v))
        if not length.min(initial=np.inf) > 0:  # NaN fails too
            raise ValueError("ray directions must be non-zero")
        limit = self.max_range_m if max_range_m is None else float(max_range_m)
        return self._cast_unit(o, v / length[:, None], limit, lead)

    def _cast_unit(self, o: np.ndarray, u: np.ndarray, limit: float, lead: tuple) -> RayHits:
        """Rays (M, 3) with unit directions → RayHits shaped ``lead``."""
        if len(o):
            dist, gid, normal = self._rays.ray(o[None], u[None], geomgroup=model_lib.RAY_GEOMGROUP,
                                               normal=True)
            dist, gid, normal = dist[0], gid[0], normal[0]
        else:
            dist, gid, normal = np.zeros(0), np.zeros(0, np.int32), np.zeros((0, 3))
        miss = gid < 0
        miss |= dist > limit
        # θ = arccos|u·n|: near θ = 0 it is off by at most √ε ≈ 1.5e-8 rad, as any form from
        # the cosine alone; misses become NaN in the distance (the hit point inherits it) and
        # the incidence, and -1 in the geom. The arrays are ours, so the steps work in place
        dist[miss] = np.nan
        incidence = np.einsum("ij,ij->i", u, normal)
        np.abs(incidence, out=incidence)
        np.minimum(incidence, 1.0, out=incidence)
        np.arccos(incidence, out=incidence)
        incidence[miss] = np.nan
        point = u * dist[:, None]
        point += o
        distance, geom = dist, gid
        geom[miss] = -1
        refl = self._reflectance.take(geom)  # a miss (−1) reads the appended NaN
        geom = self._scene_geom.take(geom)   # the scene model's ids
        return RayHits(distance_m=distance.reshape(lead), incidence_rad=incidence.reshape(lead),
                       hit_point=point.reshape(lead + (3,)), geom_id=geom.reshape(lead),
                       reflectance=refl.reshape(lead))

    # ------------------------------------------------------------------ sweeps

    def truth(self, pose_index: int = 0, *, steps: np.ndarray | None = None,
              pose: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, Truth]:
        """Steps (S,), sensor angles (S, N) rad and the ground :class:`Truth` of a sweep.

        ``pose`` overrides the scenario's pose ``pose_index``: (3,) or per step (S, 3).
        """
        if steps is None:
            steps, angles = (a.copy() for a in self._full_sweep)
        else:
            steps = self._check_steps(steps)
            angles = self.built.sensor_qpos_for(steps * self.ring.motor_step_rad)
        pose = self.pose(pose_index) if pose is None else np.asarray(pose, dtype=float)
        return steps, angles, self.truth_at(*self.frames(angles, pose))

    def truth_at(self, origin: np.ndarray, direction: np.ndarray) -> Truth:
        """The :class:`Truth` of beams from emitter frames (S, N, 3) each, as :meth:`frames`
        gives them: the directions must be unit vectors (they are not normalised again).
        """
        hits = self._cast_unit(origin.reshape(-1, 3), direction.reshape(-1, 3), self.max_range_m,
                               origin.shape[:-1])
        return Truth(distance_m=hits.distance_m, incidence_rad=hits.incidence_rad,
                     hit_point=hits.hit_point, origin=origin, direction=direction,
                     geom_id=hits.geom_id, reflectance=hits.reflectance)

    def _where(self, pose) -> tuple[int, np.ndarray | None]:
        """(noise stream index, pose (3,) or None: the scene's) of a ``sweep`` argument."""
        if isinstance(pose, (int, np.integer)) and not isinstance(pose, bool):
            return int(pose), None
        xyz = as_pose(pose)
        if self.dynamics is not None and self.dynamics.motion is not None:
            raise ValueError(f"scenario {self.scenario.name!r} drives while it scans "
                             f"(`motion`): sweep it by index along its drive, 0 … "
                             f"{self.n_sweeps - 1}, not at a pose ({pose!r})")
        for k, p in enumerate(self.scenario.robot.poses):
            if np.array_equal(xyz, (p.x_m, p.y_m, p.yaw_rad)):
                return k, None
        # a pose the scenario does not list: its own stream, keyed by its coordinates' bits
        return (1 << 64) + int.from_bytes(xyz.tobytes(), "little"), xyz

    def sweep(self, pose=0, *, steps: np.ndarray | None = None) -> Sweep:
        """One sweep with the robot at ``pose``: counts, angles, truth.

        ``pose`` is the index of one of the scenario's scan poses, or a pose — (x m, y m,
        yaw rad) or a scenario ``Pose`` — anywhere in the room: one of the scenario's reads
        with that pose's noise stream (the same sweeps as by its index), any other with its
        own. ``steps``: motor steps in order (default: :meth:`default_steps`).

        ``counts`` come from the scene's effects pipeline
        (``pipeline.run(truth, rng, cast=self.cast)``); ``duration_s`` is the time the real
        ring would need (steps × (settle + samples × 38.3 ms)); ``timestamps_s[i]`` is when
        step i's reading is complete, from the start of the sweep.

        With ``belt_dynamics``, ``timing`` or ``motion`` the readings are cast from where
        and when :meth:`irring.simulation.dynamics.Dynamics.plan` says they were taken, the sweep's
        times include the moves (see that module), ``sensor_angles`` stay the commanded
        angles, and with ``motion`` ``pose`` is the sweep's index along the drive
        (0 … ``n_sweeps`` − 1) and ``reading_poses`` carries the odometry pose of each read.
        """
        pose_index, at = self._where(pose)
        if self.dynamics is not None:
            return self._dynamic_sweep(pose_index, steps, at)
        if at is None:
            pose = self.pose(pose_index)
            pose_index = pose_index % len(self.scenario.robot.poses)
        else:
            pose = at
        steps, angles, truth = self.truth(steps=steps, pose=pose)
        return self._finish(pose_index, self._count(pose_index), steps, angles, truth,
                            timestamps_s=self._step_s * np.arange(1, len(steps) + 1),
                            duration_s=self._step_s * len(steps), pose=pose)

    def _dynamic_sweep(self, index: int, steps: np.ndarray | None,
                       at: np.ndarray | None = None) -> Sweep:
        """A sweep whose readings physics, the GP2 clocks or the drive placed (``at``: a
        pose the scenario does not list, ``index`` its stream)."""
        dyn = self.dynamics
        steps = self.default_steps() if steps is None else self._check_steps(steps)
        if dyn.motion is not None:
            n = self.n_sweeps
            if not -n <= index < n:
                raise IndexError(f"sweep {index} is out of range: scenario "
                                 f"{self.scenario.name!r} drives its path in {n} sweep(s), "
                                 f"0 … {n - 1}")
            index %= n
            pose = None
        elif at is not None:
            pose = at
        else:
            pose = self.pose(index)
            index %= len(self.scenario.robot.poses)
        k = self._count(index)
        plan = dyn.plan(index, steps, k, pose)
        truth = self.truth_at(*self.frames(plan.sensor_rad, plan.pose))
        return self._finish(index, k, steps, plan.commanded_rad, truth,
                            timestamps_s=plan.schedule.done_s.copy(),
                            duration_s=plan.schedule.duration_s, pose=plan.sweep_pose,
                            reading_poses=plan.reading_poses)

    def _count(self, index: int) -> int:
        """How many sweeps ``index`` had before this one (counting this one)."""
        k = self._sweeps.get(index, 0)
        self._sweeps[index] = k + 1
        return k

    def _finish(self, index: int, k: int, steps: np.ndarray, angles: np.ndarray, truth: Truth,
                *, timestamps_s: np.ndarray, duration_s: float, pose: np.ndarray,
                reading_poses: np.ndarray | None = None) -> Sweep:
        """The k-th sweep at ``index``: counts from the scene's effects, drawing noise from
        ``default_rng([seed, index, k])``, and the :class:`Sweep` around them."""
        rng = np.random.default_rng([self.seed, index, k])
        counts = self.pipeline.run(truth, rng, cast=self.cast)
        scan, sensor = self.scenario.scan, self.scenario.sensor
        return Sweep(steps=steps, sensor_angles=angles, counts=counts, timestamps_s=timestamps_s,
                     duration_s=float(duration_s), pose=pose, ring=self.ring,
                     sensor_model=sensor.model, adc_bits=sensor.adc_bits, vref_v=sensor.vref_v,
                     max_range_m=sensor.max_range_m, samples=self.scenario.samples_per_step,
                     settle_s=scan.settle_s, truth=truth, reading_poses=reading_poses,
                     source="sim")
