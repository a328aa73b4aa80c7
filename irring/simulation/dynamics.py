"""Where and when the ring reads: belt and stepper physics, GP2 timing, a moving robot.

How it works, its assumptions and measured figures: docs/dynamics.md.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import threading
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import mujoco
import mujoco.batch
import numpy as np

from . import model as model_lib
from ..core import (GP2_PERIOD_S, HOUSING_M, Ring, beam_geometry, distance_to_outline,
                   inside_outline, obstacle_distance)
from ..scenario import BeltDynamicsEffect, MotionEffect, Scenario, ScenarioError, TimingEffect

TIMING_STREAM = 0x7469   # "ti": seeds the GP2 clocks
ODOMETRY_STREAM = 0x6F64  # "od": seeds the odometry drift
DYNAMIC_EFFECTS = ("belt_dynamics", "timing", "motion")
_PATH_SAMPLE_M = 0.005     # odometry / clearance resolution along the path
_CLEARANCE_BLOCK = 100_000  # path samples checked at once (a few MB)
# physics steps per MuJoCo rollout call: Python (Ctrl-C) runs only between calls, and this
# many take well under a second (~0.3 s for the 12-sensor ring at load 3)
ROLLOUT_CHUNK_STEPS = 10_000
# A belt time step is converged when halving it moves no sensor's true angle at a reading by
# more than this. 0.1° is 1.1 mm across at the GP2D12's 624 mm (2.6 mm at 1.5 m): a tenth of
# a 10-mm cell, under a tenth of the sensor's 1.08° step, and 7× below the smallest change
# measured to cost map F1 (docs/dynamics.md, "Is the time step converged?").
CONVERGED_ANGLE_RAD = math.radians(0.1)
_CHECKED_MAX = 256   # timestep verdicts kept per process (one per ring, belt and schedule)
# a refusal's advice checks halved steps only while that rolls out at most this many physics
# steps (~15 s at 15 µs a step): the sweep at dt/2 and dt/4 is 6× its steps at dt
ADVICE_MAX_STEPS = 1_000_000

# Physics of the ring alone: no contacts, no rangefinders (beams are cast by sim.SimRing).
_PHYSICS_OFF = int(mujoco.mjtDisableBit.mjDSBL_SENSOR | mujoco.mjtDisableBit.mjDSBL_CONTACT)


def uses_dynamics(scenario: Scenario) -> bool:
    """Does the scene list any effect that needs this module (and may step physics)?"""
    return any(scenario.has(name) for name in DYNAMIC_EFFECTS)


def min_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk position 0 → 1 for phase s (clipped to 0 … 1): 10s³ − 15s⁴ + 6s⁵."""
    s = np.clip(s, 0.0, 1.0)
    return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)


# --------------------------------------------------------------------------- the timeline


@dataclass(frozen=True)
class Schedule:
    """The firmware's timeline of one sweep; times in seconds from the sweep's start.

    ``command_s[i]`` the move to ``steps[i]`` starts, lasting ``move_s[i]`` (0 for the
    first step: the ring starts there at rest); ``read_s[i, j]`` the j-th ADC read of
    step i; ``done_s[i]`` when step i's reading is complete (``Sweep.timestamps_s``).
    """

    steps: np.ndarray        # (S,) motor steps
    motor_rad: np.ndarray    # (S,) commanded motor angle of each step
    command_s: np.ndarray    # (S,)
    move_s: np.ndarray       # (S,)
    read_s: np.ndarray       # (S, samples)
    done_s: np.ndarray       # (S,)
    duration_s: float        # the sweep's hardware time (= done_s[-1])
    step_time_s: float
    rewind_s: float          # from the sweep's end to the next sweep's start (motion)

    @property
    def cycle_s(self) -> float:
        """From one sweep's start to the next's while driving: the sweep and its rewind."""
        return self.duration_s + self.rewind_s

    def motor_at(self, t_s: np.ndarray) -> np.ndarray:
        """Commanded motor angle (rad) at times ``t_s`` (any shape): the move profiles."""
        t = np.asarray(t_s, dtype=float)
        i = np.clip(np.searchsorted(self.command_s, t, side="right") - 1, 0, len(self.steps) - 1)
        start = self.motor_rad[np.maximum(i - 1, 0)]
        move = self.move_s[i]
        phase = np.where(move > 0, (t - self.command_s[i]) / np.where(move > 0, move, 1.0), 1.0)
        return start + (self.motor_rad[i] - start) * min_jerk(phase)


def schedule(steps: np.ndarray, ring: Ring, *, settle_s: float = 0.0, samples: int = 1,
             step_time_s: float = BeltDynamicsEffect().step_time_s, timing: bool = False,
             period_s: float = GP2_PERIOD_S) -> Schedule:
    """The timeline of a sweep over ``steps`` (see the module doc for the firmware's rules)."""
    steps = np.asarray(steps, dtype=np.int64)
    motor = steps * ring.motor_step_rad
    delta = np.abs(np.diff(steps, prepend=steps[:1]))
    move = delta * float(step_time_s)
    # time from the first read to the next command: an ideal (untimed) sensor is charged a
    # GP2 period per sample; a timed one costs only the waits between averaged reads
    after_first = (samples if not timing else samples - 1) * period_s
    per_step = move + settle_s + after_first
    command = np.concatenate([[0.0], np.cumsum(per_step)[:-1]])
    first = command + move + settle_s
    read = first[:, None] + period_s * np.arange(samples)[None, :]
    done = first + after_first if not timing else read[:, -1]
    span = abs(int(steps[-1]) - int(steps[0]))
    return Schedule(steps=steps, motor_rad=motor, command_s=command, move_s=move, read_s=read,
                    done_s=done, duration_s=float(done[-1]), step_time_s=float(step_time_s),
                    rewind_s=span * float(step_time_s) + period_s)


# --------------------------------------------------------------------------- ring motion


def _hermite(t_grid_dt: float, q: np.ndarray, v: np.ndarray, t_s: np.ndarray,
             col: np.ndarray | None = None) -> np.ndarray:
    """Cubic Hermite interpolation of columns q, v (T, N) sampled every dt from t = 0, at
    times ``t_s`` (..., N) (column k at t_s[..., k]), or of columns ``col`` (same shape as
    ``t_s``) when given; clamped to the samples' span."""
    n = q.shape[0]
    x = np.clip(np.asarray(t_s, dtype=float) / t_grid_dt, 0.0, n - 1.0)
    i = np.minimum(np.floor(x).astype(np.int64), n - 2)
    u = x - i
    col = np.arange(q.shape[1]) if col is None else col
    q0, q1 = q[i, col], q[i + 1, col]
    v0, v1 = v[i, col] * t_grid_dt, v[i + 1, col] * t_grid_dt
    u2, u3 = u * u, u * u * u
    return ((2 * u3 - 3 * u2 + 1) * q0 + (u3 - 2 * u2 + u) * v0 + (-2 * u3 + 3 * u2) * q1
            + (u3 - u2) * v1)


@dataclass(frozen=True)
class Trajectory:
    """The ring's physics over one sweep, sampled every ``dt_s`` from t = 0 (rest).

    ``sensor_rad`` / ``sensor_vel`` (T, N) hinge angles and rates; ``motor_rad`` /
    ``motor_vel`` (T,); ``gear`` (N,) belt ratios (sensor = gear × motor when the belt is
    unstretched). A run that warned never becomes one (:meth:`BeltPhysics.roll` raises).
    """

    dt_s: float
    motor_rad: np.ndarray
    motor_vel: np.ndarray
    sensor_rad: np.ndarray
    sensor_vel: np.ndarray
    gear: np.ndarray

    @property
    def t_s(self) -> np.ndarray:
        return self.dt_s * np.arange(len(self.motor_rad))

    @property
    def stretch_rad(self) -> np.ndarray:
        """(T, N) belt coupling error: sensor − gear × motor, rad at the sensor."""
        return self.sensor_rad - self.gear * self.motor_rad[:, None]

    def sensors_at(self, t_s: np.ndarray) -> np.ndarray:
        """Sensor angles (S, N) at times (S, N) (column k = sensor k); cubic Hermite between
        samples (its error ~ dt⁴, far below the integrator's), clamped to the run."""
        return _hermite(self.dt_s, self.sensor_rad, self.sensor_vel, t_s)


@dataclass(frozen=True)
class RigidRing:
    """Without ``belt_dynamics``: the sensors follow the commanded profile exactly."""

    schedule: Schedule
    built: model_lib.RingModel

    def sensors_at(self, t_s: np.ndarray) -> np.ndarray:
        t = np.asarray(t_s, dtype=float)
        motor = self.schedule.motor_at(t)
        coef = self.built.belt_coef
        return coef[:, 0] + coef[:, 1] * motor


def physics_spec(ring: Ring, params: BeltDynamicsEffect,
                 spec: mujoco.MjSpec | None = None) -> mujoco.MjSpec:
    """The ring's spec (``model.ring_spec`` unless given) with the belt as spring-dampers.

    Each equality ``belt_KK`` is replaced by a fixed tendon of the same name,
    ``ir_KK_hinge − gear·ring_motor`` (its length is the belt's stretch at the sensor), with
    a dead band ±backlash/2 in its spring; stiffness and damping are set on the compiled
    model by :func:`tune_belt` (they need the sensors' inertia). RK4 at ``timestep_s``.
    """
    spec = model_lib.ring_spec(ring) if spec is None else spec
    half = params.backlash_rad / 2.0
    for k in range(ring.sensors):
        eq = spec.equality(f"belt_{k:02d}")
        gear = float(eq.data[1])
        spec.delete(eq)
        tendon = spec.add_tendon(name=f"belt_{k:02d}", springlength=[-half, half])
        tendon.wrap_joint(f"{model_lib.sensor_name(k)}_hinge", 1.0)
        tendon.wrap_joint("ring_motor", -gear)
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_RK4
    spec.option.timestep = params.timestep_s
    return spec


def _without_shapes(spec: mujoco.MjSpec) -> mujoco.MjSpec:
    """The spec without geoms, sites and sensors: with contacts and sensors off they only
    cost kinematics (the bodies' inertias are explicit, so the physics is bit for bit the same,
    ~15 % faster)."""
    for kind in ("sensors", "geoms", "sites"):
        for element in list(getattr(spec, kind)):
            spec.delete(element)
    return spec


def tune_belt(model: mujoco.MjModel, params: BeltDynamicsEffect) -> np.ndarray:
    """Set each belt tendon's stiffness I/τ² and critical damping 2√(K·I); return K (N·m/rad).

    I is the sensor's inertia about its hinge (body + armature), from MuJoCo's mass matrix.
    """
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    tau = params.belt_timeconst_s
    stiff = np.zeros(model.ntendon)
    for t in range(model.ntendon):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_TENDON, t) or ""
        if not name.startswith("belt_"):
            continue
        sensor = int(name[5:])
        joint = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT,
                                  f"{model_lib.sensor_name(sensor)}_hinge")
        dof = model.jnt_dofadr[joint]
        inertia = full[dof, dof]
        stiff[t] = inertia / tau ** 2
        model.tendon_stiffness[t] = stiff[t]
        model.tendon_damping[t] = 2.0 * math.sqrt(stiff[t] * inertia)
    return stiff


class BeltPhysics:
    """The ring alone (no room) stepped by MuJoCo with the belt as spring-dampers.

    ``run(schedule)`` rolls one sweep out from rest at its first step and returns its
    :class:`Trajectory`; the actuator's target at each physics step is the commanded
    profile at the step's midpoint. Raises ``RuntimeError`` on a MuJoCo warning or a
    non-finite state (with what to change).
    """

    def __init__(self, ring: Ring, params: BeltDynamicsEffect, *, nthread: int = 1):
        self.ring = ring
        self.params = params
        self.model = _without_shapes(physics_spec(ring, params)).compile()
        self.model.opt.disableflags |= _PHYSICS_OFF
        self.stiffness = tune_belt(self.model, params)
        m = self.model
        self.motor_qpos = int(m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT,
                                                              "ring_motor")])
        joints = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT,
                                    f"{model_lib.sensor_name(k)}_hinge")
                  for k in range(ring.sensors)]
        self.sensor_qpos = m.jnt_qposadr[joints].copy()
        self.motor_dof = int(m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT,
                                                            "ring_motor")])
        self.sensor_dof = m.jnt_dofadr[joints].copy()
        tendons = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TENDON, f"belt_{k:02d}")
                   for k in range(ring.sensors)]
        # belt_KK = hinge − gear·motor: the gear from the tendon's motor coefficient
        self.gear = np.array([-m.wrap_prm[m.tendon_adr[t] + 1] for t in tendons])
        self.nthread = nthread
        self._batches: dict[int, mujoco.batch.Batch] = {}

    @property
    def dt_s(self) -> float:
        return float(self.model.opt.timestep)

    def batch(self, nsim: int) -> mujoco.batch.Batch:
        """A ``mujoco.batch.Batch`` of ``nsim`` simulations of the belt model (kept, reused)."""
        batch = self._batches.get(nsim)
        if batch is None:
            batch = mujoco.batch.Batch(self.model, nsim, nthread=self.nthread)
            self._batches[nsim] = batch
        return batch

    def rest_offset(self, steps: np.ndarray) -> np.ndarray:
        """(N,) belt stretch at rest before a sweep over ``steps``: with backlash the rewind
        (opposite to the sweep's first move) leaves each sensor at that side of the gap."""
        steps = np.asarray(steps)
        direction = np.sign(steps[-1] - steps[0]) if len(steps) > 1 else 0
        return np.full(self.ring.sensors, direction * self.params.backlash_rad / 2.0)

    def start(self, batch: mujoco.batch.Batch, motor_rad: np.ndarray,
              stretch_rad: np.ndarray) -> None:
        """Put every simulation of ``batch`` at rest: motor angles (nsim,), stretch (N,)."""
        batch.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
        qpos, qvel, ctrl = batch.bind("qpos"), batch.bind("qvel"), batch.bind("ctrl")
        motor = np.asarray(motor_rad, dtype=float)
        qpos[:, self.motor_qpos] = motor
        qpos[:, self.sensor_qpos] = self.gear * motor[:, None] + stretch_rad
        qvel[:] = 0.0
        ctrl[:, 0] = motor

    def controls(self, sched: Schedule, duration_s: float | None = None) -> np.ndarray:
        """(T,) actuator targets for the physics steps covering ``duration_s`` (default: the
        sweep), each the commanded profile at the step's midpoint (second order in dt)."""
        end = sched.duration_s if duration_s is None else duration_s
        n = int(math.ceil(end / self.dt_s - 1e-9)) + 1
        return sched.motor_at((np.arange(n) + 0.5) * self.dt_s)

    def roll(self, batch: mujoco.batch.Batch, ctrl: np.ndarray) -> dict:
        """Step every simulation through its targets ``ctrl`` (nsim, T); record qpos, qvel."""
        out = batch.rollout(ctrl.shape[1], ctrl[..., None], record=("qpos", "qvel"))
        warned = int(batch.warning[..., 1].sum())  # mjWarningStat: (lastinfo, number)
        if warned or not (np.isfinite(out["qpos"]).all() and np.isfinite(out["qvel"]).all()):
            raise RuntimeError(
                f"belt physics went unstable (MuJoCo warnings: {warned}); lower "
                f"belt_dynamics.timestep_ms (now {self.dt_s * 1e3:g} ms) or raise "
                f"belt_timeconst_ms (now {self.params.belt_timeconst_s * 1e3:g} ms)")
        return out

    def run(self, sched: Schedule, *, duration_s: float | None = None) -> Trajectory:
        """One sweep from rest at its first step, through ``duration_s`` (default its end),
        rolled out :data:`ROLLOUT_CHUNK_STEPS` physics steps at a time (Ctrl-C lands between)."""
        ctrl = self.controls(sched, duration_s)
        chunks = [ctrl[i:i + ROLLOUT_CHUNK_STEPS] for i in range(0, len(ctrl), ROLLOUT_CHUNK_STEPS)]
        parts = list(self.follow(chunks, sched.motor_rad[0], self.rest_offset(sched.steps)))
        if len(parts) == 1:
            return parts[0]

        def joined(name: str) -> np.ndarray:  # each chunk after the first repeats its start
            return np.concatenate([getattr(parts[0], name)]
                                  + [getattr(t, name)[1:] for t in parts[1:]])

        return Trajectory(dt_s=self.dt_s, motor_rad=joined("motor_rad"),
                          motor_vel=joined("motor_vel"), sensor_rad=joined("sensor_rad"),
                          sensor_vel=joined("sensor_vel"), gear=self.gear)

    def follow(self, targets: Iterable[np.ndarray], motor_rad: float,
               stretch_rad: np.ndarray) -> Iterator[Trajectory]:
        """One continuous run from rest at ``motor_rad`` with belt stretch ``stretch_rad``
        (N,), through successive chunks of actuator targets (each (T,), one per physics
        step): yields each chunk's :class:`Trajectory`, T + 1 samples from the chunk's start
        (the first is the last of the chunk before). Raises as :meth:`roll`."""
        batch = self.batch(1)
        self.start(batch, np.array([motor_rad], dtype=float), stretch_rad)
        q, v = batch.bind("qpos")[0].copy(), np.zeros(self.model.nv)
        for ctrl in targets:
            out = self.roll(batch, np.asarray(ctrl, dtype=float)[None])
            qpos = np.concatenate([q[None], out["qpos"][0]])
            qvel = np.concatenate([v[None], out["qvel"][0]])
            q, v = qpos[-1].copy(), qvel[-1].copy()
            yield Trajectory(dt_s=self.dt_s, motor_rad=qpos[:, self.motor_qpos],
                             motor_vel=qvel[:, self.motor_dof],
                             sensor_rad=qpos[:, self.sensor_qpos],
                             sensor_vel=qvel[:, self.sensor_dof], gear=self.gear)


def angles_at(physics: BeltPhysics, sched: Schedule, t_s: np.ndarray,
              sensor: np.ndarray) -> np.ndarray:
    """(M,) true angles (rad) of sensors ``sensor`` (M,) at times ``t_s`` (M,) of the sweep
    ``sched`` rolled out from rest, chunk by chunk (only the chunk being read is kept).
    Raises as :meth:`BeltPhysics.roll`."""
    t_s = np.asarray(t_s, dtype=float)
    out = np.zeros(len(t_s))
    done = np.zeros(len(t_s), dtype=bool)
    dt = physics.dt_s
    ctrl = physics.controls(sched)
    starts = range(0, len(ctrl), ROLLOUT_CHUNK_STEPS)
    chunks = (ctrl[i:i + ROLLOUT_CHUNK_STEPS] for i in starts)
    last = (len(ctrl) - 1) // ROLLOUT_CHUNK_STEPS * ROLLOUT_CHUNK_STEPS  # its start
    for i, run in zip(starts, physics.follow(chunks, sched.motor_rad[0],
                                             physics.rest_offset(sched.steps))):
        end = (i + len(run.motor_rad) - 1) * dt
        pick = ~done & ((t_s <= end) | (i == last))
        out[pick] = _hermite(dt, run.sensor_rad, run.sensor_vel, t_s[pick] - i * dt,
                             np.asarray(sensor)[pick])
        done |= pick
    return out


def check_instants(sched: Schedule, n_sensors: int, dt_s: float,
                   timing: TimingEffect | None) -> tuple[np.ndarray, np.ndarray]:
    """Where the timestep check compares angles: times (M,) and sensors (M,). Without
    ``timing`` every sensor at each step's first read; with it every physics step (``dt_s``)
    at which some read's measurement may have been taken: from latency + the longest period
    (period_s + jitter_s, whatever the seed drew) before the read to latency before it."""
    first = sched.read_s[:, 0]
    if timing is None:
        t = first
    else:
        grid = np.arange(int(math.floor(sched.duration_s / dt_s)) + 1) * dt_s
        ends = first - timing.latency_s
        nxt = np.minimum(np.searchsorted(ends, grid), len(ends) - 1)
        t = grid[(grid <= ends[nxt]) & (ends[nxt] - grid <= timing.period_s + timing.jitter_s)]
    return np.repeat(t, n_sensors), np.tile(np.arange(n_sensors), len(t))


def _at_step_and(physics: BeltPhysics, sched: Schedule, timing: TimingEffect | None,
                 run: Trajectory | None, factor: float):
    """The check's instants (t, k), the sensors' angles there at ``physics``'s step (from
    ``run`` if rolled out), and the same belt at ``factor`` × the step (None: no instants)."""
    t, k = check_instants(sched, physics.ring.sensors, physics.dt_s, timing)
    if len(t) == 0:
        return None
    at_step = (_hermite(run.dt_s, run.sensor_rad, run.sensor_vel, t, k) if run is not None
               else angles_at(physics, sched, t, k))
    other = BeltPhysics(physics.ring, dataclasses.replace(physics.params,
                                                          timestep_s=physics.dt_s * factor))
    return t, k, at_step, other


def timestep_change(physics: BeltPhysics, sched: Schedule, timing: TimingEffect | None = None,
                    run: Trajectory | None = None) -> float:
    """How far (rad) halving ``physics``'s time step moves a sensor's true angle, at most,
    at the instants the sweep ``sched`` reads (:func:`check_instants`). ``run``: the sweep at
    the full step if already rolled out. Raises as :meth:`BeltPhysics.roll`."""
    both = _at_step_and(physics, sched, timing, run, 0.5)
    if both is None:
        return 0.0
    t, k, coarse, half = both
    return float(np.abs(coarse - angles_at(half, sched, t, k)).max())


_WARNING_HANDLER = threading.Lock()   # MuJoCo's warning handler is process-wide


def _doubling_change(physics: BeltPhysics, sched: Schedule, timing: TimingEffect | None,
                     run: Trajectory | None) -> float | None:
    """How far (rad) the sweep at twice ``physics``'s step moves from it at the check's
    instants, or None when that run goes unstable (its MuJoCo warnings are silenced: the
    scene's own step is not at fault)."""
    both = _at_step_and(physics, sched, timing, run, 2.0)
    if both is None:
        return 0.0
    t, k, at_step, doubled = both
    with _WARNING_HANDLER:   # one swap at a time, so threads restore what was there
        handler = mujoco.get_mju_user_warning()
        mujoco.set_mju_user_warning(lambda message: None)
        try:
            coarse = angles_at(doubled, sched, t, k)
        except RuntimeError:
            return None
        finally:
            mujoco.set_mju_user_warning(handler)
    return float(np.abs(coarse - at_step).max())


_checked: dict[tuple, tuple[float, str]] = {}   # (ring, belt, timing, schedule) → verdict


def forget_timestep_checks() -> None:
    """Forget every remembered :func:`check_timestep` verdict (a benchmark times it afresh)."""
    _checked.clear()


def _schedule_key(sched: Schedule) -> str:
    digest = hashlib.sha256()
    for a in (sched.motor_rad, sched.command_s, sched.move_s, sched.read_s[:, 0]):
        digest.update(np.ascontiguousarray(a, dtype=float).tobytes())
    return digest.hexdigest()


def check_timestep(physics: BeltPhysics, sched: Schedule, timing: TimingEffect | None = None,
                   run: Trajectory | None = None) -> tuple[float, str]:
    """(change rad, advice): :func:`timestep_change`, and when it exceeds
    :data:`CONVERGED_ANGLE_RAD` what to do (a halved time step that passes, checked, or how
    far it still is). First, for a quarter of the work, the sweep at twice the step: if that
    moves the angles by no more than the tolerance, the step passes and ``change`` is that
    doubling's (halving moves them far less: RK4's error falls ~16× per halving; measured
    ≥ 6.5× over 448 scenes, docs/dynamics.md). Remembered per ring, belt, timing and
    schedule for the process: a study or bench over the same scene checks once. Raises as
    :meth:`BeltPhysics.roll`."""
    key = (physics.ring, physics.params, timing, _schedule_key(sched))
    verdict = _checked.get(key)
    if verdict is None:
        change = _doubling_change(physics, sched, timing, run)
        if change is None or change > CONVERGED_ANGLE_RAD:
            change = timestep_change(physics, sched, timing, run)
        advice = ""
        if change > CONVERGED_ANGLE_RAD:
            advice = _halving_advice(physics, sched, timing, change)
        if len(_checked) >= _CHECKED_MAX:
            _checked.clear()
        verdict = _checked[key] = (change, advice)
    return verdict


def _halving_advice(physics: BeltPhysics, sched: Schedule, timing: TimingEffect | None,
                    change: float) -> str:
    """A halved time step that passes, checked: dt/2, else dt/4. Checking dt/2^j rolls the
    sweep at 2^j and 2^(j+1) times its physics steps, so it stops there, and tries none
    that would take more than :data:`ADVICE_MAX_STEPS`; then RK4's fourth order estimates
    one (said so: not checked)."""
    params = physics.params
    steps = len(physics.controls(sched))
    measured = None
    for halvings in (1, 2):
        if 3 * 2 ** halvings * steps > ADVICE_MAX_STEPS:
            break
        finer = BeltPhysics(physics.ring, dataclasses.replace(
            params, timestep_s=params.timestep_s / 2 ** halvings))
        try:
            measured = timestep_change(finer, sched, timing)
        except RuntimeError:
            continue
        if measured <= CONVERGED_ANGLE_RAD:
            return (f"timestep_ms: {finer.dt_s * 1e3:.4g} passes (halving it moves "
                    f"{math.degrees(measured):.2g}°)")
    if measured is not None:
        return (f"{finer.dt_s * 1e3:.4g} ms still moves {math.degrees(measured):.2g}° when "
                f"halved: lower timestep_ms further")
    guess = physics.dt_s * (CONVERGED_ANGLE_RAD / change) ** 0.25 / 2
    return f"lower timestep_ms, to about {guess * 1e3:.2g} ms (estimated, not checked)"


# --------------------------------------------------------------------------- GP2 clocks


@dataclass(frozen=True)
class SensorClocks:
    """Each GP2's measurement clock: sensor k measures at ``phase_s[k] + n·period_s[k]``
    and its output holds that measurement from ``latency_s`` later (seconds)."""

    period_s: np.ndarray   # (N,)
    phase_s: np.ndarray    # (N,) in [0, period)
    latency_s: float

    @staticmethod
    def periods(params: TimingEffect, n: int, seed: int) -> np.ndarray:
        """(N,) each part's period, uniform in period ± jitter (drawn once from the seed)."""
        rng = np.random.default_rng([seed, TIMING_STREAM])
        lo = max(params.period_s - params.jitter_s, 1e-4)
        return rng.uniform(lo, params.period_s + params.jitter_s, n)

    @classmethod
    def draw(cls, params: TimingEffect, periods_s: np.ndarray,
             rng: np.random.Generator) -> SensorClocks:
        return cls(period_s=periods_s, phase_s=rng.uniform(0.0, 1.0, len(periods_s)) * periods_s,
                   latency_s=params.latency_s)

    def measured_at(self, read_s: np.ndarray) -> np.ndarray:
        """When the measurement an ADC read at ``read_s`` (..., N) returns was taken."""
        r = np.asarray(read_s, dtype=float) - self.latency_s - self.phase_s
        return self.phase_s + self.period_s * np.floor(r / self.period_s)


# --------------------------------------------------------------------------- motion


def _unwrap_yaw(yaws: np.ndarray) -> np.ndarray:
    """Yaws turned the short way between consecutive waypoints."""
    step = np.angle(np.exp(1j * np.diff(yaws)))
    return np.concatenate([[yaws[0]], yaws[0] + np.cumsum(step)])


@dataclass(frozen=True)
class Path:
    """The robot's drive: straight segments between waypoints at constant speed; yaw turns
    linearly along each segment (the short way); a segment that only turns takes no time.
    ``pose_at(t)`` past the end stays at the last waypoint."""

    xy_m: np.ndarray       # (W, 2)
    yaw_rad: np.ndarray    # (W,) unwrapped
    arc_m: np.ndarray      # (W,) arc length at each waypoint
    speed_m_s: float

    @classmethod
    def from_effect(cls, motion: MotionEffect) -> Path:
        xy = np.array([[w.x_m, w.y_m] for w in motion.path], dtype=float)
        yaw = _unwrap_yaw(np.array([w.yaw_rad for w in motion.path], dtype=float))
        arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
        return cls(xy_m=xy, yaw_rad=yaw, arc_m=arc, speed_m_s=float(motion.speed_m_s))

    @property
    def length_m(self) -> float:
        return float(self.arc_m[-1])

    @property
    def duration_s(self) -> float:
        return self.length_m / self.speed_m_s if self.speed_m_s > 0 and self.length_m > 0 else 0.0

    def pose_at_arc(self, s_m: np.ndarray) -> np.ndarray:
        """(..., 3) poses at arc lengths ``s_m`` (...,); a turn in place at s is done."""
        return self._pose_on_segments(s_m, side="right")

    def pose_before_arc(self, s_m: np.ndarray) -> np.ndarray:
        """(..., 3) poses at arc lengths ``s_m`` (...,) before any turn in place there."""
        return self._pose_on_segments(s_m, side="left")

    def _pose_on_segments(self, s_m: np.ndarray, side: str) -> np.ndarray:
        s = np.clip(np.asarray(s_m, dtype=float), 0.0, self.length_m)
        if len(self.arc_m) == 1 or self.length_m == 0:
            last = np.array([*self.xy_m[-1], self.yaw_rad[-1]])
            return np.broadcast_to(last, s.shape + (3,)).copy()
        # side "right": the last waypoint at a given arc (a turn in place jumps to its end yaw)
        i = np.clip(np.searchsorted(self.arc_m, s, side=side) - 1, 0, len(self.arc_m) - 2)
        seg = self.arc_m[i + 1] - self.arc_m[i]
        u = np.where(seg > 0, (s - self.arc_m[i]) / np.where(seg > 0, seg, 1.0), 1.0)
        xy = self.xy_m[i] + (self.xy_m[i + 1] - self.xy_m[i]) * u[..., None]
        yaw = self.yaw_rad[i] + (self.yaw_rad[i + 1] - self.yaw_rad[i]) * u
        return np.concatenate([xy, yaw[..., None]], axis=-1)

    def pose_at(self, t_s: np.ndarray) -> np.ndarray:
        """(..., 3) true pose (x m, y m, yaw rad) at times ``t_s`` from the drive's start."""
        return self.pose_at_arc(np.asarray(t_s, dtype=float) * self.speed_m_s)

    def check_clearance(self, scenario: Scenario, whose: str = "") -> None:
        """Raise ScenarioError where the ring (radius + 20 mm housing) would touch a wall or
        an obstacle along the path (the loader checks scan poses, not paths); ``whose``
        (" of design 'x'") says whose ring in the message."""
        clearance = scenario.ring.radius_m + HOUSING_M
        n = max(2, int(math.ceil(self.length_m / _PATH_SAMPLE_M)) + 1)
        outline = scenario.room.outline_m
        # a block of samples at a time, all walls and obstacles at once (one sample at a
        # time took 6 min for a path of 2,000 waypoints, before the run was refused as too big)
        for first in range(0, n, _CLEARANCE_BLOCK):
            s = np.minimum(np.arange(first, min(n, first + _CLEARANCE_BLOCK))
                           * (self.length_m / (n - 1)), self.length_m)   # linspace's samples
            x, y, _ = self.pose_at_arc(s).T
            gap = distance_to_outline(x, y, outline)
            for ob in scenario.obstacles:
                gap = np.minimum(gap, obstacle_distance(ob, x, y))
            bad = np.flatnonzero(~inside_outline(x, y, outline) | (gap < clearance))
            if bad.size:
                k = int(bad[0])
                x, y, arc = float(x[k]), float(y[k]), float(s[k])
                seg = int(np.clip(np.searchsorted(self.arc_m, arc, side="right") - 1, 0,
                                  max(len(self.arc_m) - 2, 0)))
                raise ScenarioError(
                    f"{scenario.source or scenario.name}: effects.motion.path[{seg}] → "
                    f"[{seg + 1}]: at ({x * 1e3:.0f}, {y * 1e3:.0f}) mm the ring{whose} "
                    f"(radius {clearance * 1e3:g} mm with housing) would hit a wall or obstacle; "
                    f"add a waypoint that keeps ≥ {clearance * 1e3:g} mm clear")


@dataclass(frozen=True)
class Odometry:
    """Dead reckoning along a :class:`Path`: the true increments every ≤ 5 mm, each with
    Gaussian noise in the robot frame (σ² = sigma_m²·ds per axis, sigma_rad²·ds in yaw),
    integrated from the true start pose. Zero sigmas give the true path exactly."""

    path: Path
    arc_m: np.ndarray     # (K,) sample arcs
    pose: np.ndarray      # (K, 3) odometry pose at each

    @classmethod
    def along(cls, path: Path, sigma_m: float, sigma_rad: float,
              rng: np.random.Generator) -> Odometry:
        n = max(2, int(math.ceil(path.length_m / _PATH_SAMPLE_M)) + 1)
        arc = np.unique(np.concatenate([np.linspace(0.0, path.length_m, n), path.arc_m]))
        true = path.pose_at_arc(arc)
        # a turn in place jumps at its arc: a second sample there holds the pose before it,
        # so odometry jumps where the true pose does instead of ramping over the last 5 mm
        turns = np.unique(path.arc_m[1:][(np.diff(path.arc_m) == 0) & (path.arc_m[1:] > 0)])
        if turns.size:
            at = np.searchsorted(arc, turns)
            arc = np.insert(arc, at, turns)
            true = np.insert(true, at, path.pose_before_arc(turns), axis=0)
        if sigma_m == 0 and sigma_rad == 0:
            return cls(path=path, arc_m=arc, pose=true)
        d = np.diff(true, axis=0)
        c, s = np.cos(true[:-1, 2]), np.sin(true[:-1, 2])
        fwd = c * d[:, 0] + s * d[:, 1]          # robot-frame increments
        left = -s * d[:, 0] + c * d[:, 1]
        ds = np.hypot(d[:, 0], d[:, 1])
        fwd = fwd + rng.standard_normal(len(ds)) * sigma_m * np.sqrt(ds)
        left = left + rng.standard_normal(len(ds)) * sigma_m * np.sqrt(ds)
        dyaw = d[:, 2] + rng.standard_normal(len(ds)) * sigma_rad * np.sqrt(ds)
        yaw = true[0, 2] + np.concatenate([[0.0], np.cumsum(dyaw)])
        cy, sy = np.cos(yaw[:-1]), np.sin(yaw[:-1])
        x = true[0, 0] + np.concatenate([[0.0], np.cumsum(cy * fwd - sy * left)])
        y = true[0, 1] + np.concatenate([[0.0], np.cumsum(sy * fwd + cy * left)])
        return cls(path=path, arc_m=arc, pose=np.stack([x, y, yaw], axis=-1))

    def pose_at(self, t_s: np.ndarray) -> np.ndarray:
        """(..., 3) odometry pose at times ``t_s``."""
        s = np.clip(np.asarray(t_s, dtype=float) * self.path.speed_m_s, 0.0, self.path.length_m)
        # the last sample at or before s (after a turn in place at s, as Path.pose_at_arc)
        i = np.clip(np.searchsorted(self.arc_m, s, side="right") - 1, 0, len(self.arc_m) - 2)
        gap = self.arc_m[i + 1] - self.arc_m[i]
        u = np.where(gap > 0, (s - self.arc_m[i]) / np.where(gap > 0, gap, 1.0), 1.0)
        return self.pose[i] + (self.pose[i + 1] - self.pose[i]) * u[..., None]


def full_sweep_steps(scenario: Scenario) -> np.ndarray:
    """Motor steps of a full sweep: min_step … max_step by ``scan.step_stride``."""
    ring = scenario.ring
    return np.arange(ring.min_step, ring.max_step + 1, scenario.scan.step_stride)


def scene_schedule(scenario: Scenario, steps: np.ndarray) -> Schedule:
    """The firmware's timeline of the scene's sweep over ``steps`` (its settle, samples,
    step time and whether each GP2 keeps its own clock)."""
    belt = scenario.effects.get("belt_dynamics") or BeltDynamicsEffect()
    return schedule(steps, scenario.ring, settle_s=scenario.scan.settle_s,
                    samples=scenario.samples_per_step, step_time_s=belt.step_time_s,
                    timing=scenario.has("timing"))


def sweeps_along(path: Path, sched: Schedule) -> int:
    """Sweeps taken driving ``path``, one every ``sched.cycle_s`` (sweep + rewind) from the start:
    each that starts before the robot arrives (at least one). A sweep the arrival cuts is
    taken in full, its remaining steps read standing at the path's end; none starts after
    (docs/dynamics.md, "Where the path ends")."""
    return max(1, int(math.ceil(path.duration_s / sched.cycle_s - 1e-12)))


@dataclass(frozen=True)
class Drive:
    """Where a moving scene's ring read along its path, from the scene alone (no physics,
    no seed: what the ground truth judges a map by): ``poses`` (sweeps, S, 3) the true pose
    at each step's first read, ``sensor_rad`` (S,) each step's commanded sensor angle
    from radial."""

    path: Path
    schedule: Schedule
    poses: np.ndarray
    sensor_rad: np.ndarray

    @classmethod
    def of(cls, scenario: Scenario) -> Drive:
        """The scene's drive (ValueError for a scene without ``motion``)."""
        motion = scenario.effects.get("motion")
        if motion is None:
            raise ValueError(f"scenario {scenario.name!r} does not drive (no effects.motion)")
        steps = full_sweep_steps(scenario)
        sched = scene_schedule(scenario, steps)
        path = Path.from_effect(motion)
        n = sweeps_along(path, sched)
        starts = np.arange(n) * sched.cycle_s
        ring = scenario.ring
        return cls(path=path, schedule=sched,
                   poses=path.pose_at(starts[:, None] + sched.read_s[None, :, 0]),
                   sensor_rad=steps * ring.motor_step_rad * ring.gear)

    @property
    def n_sweeps(self) -> int:
        return len(self.poses)

    def ending(self) -> dict:
        """How the path ended against the sweeps: ``sweeps``, ``path_m``, ``swept_m`` (driven
        from the first read to the last), and ``cut``: None, or ``{"sweep": k (1-based),
        "steps_standing": steps of sweep k read after the robot arrived, "steps": S}`` when
        the robot arrived during the last sweep (those readings are kept, taken at the end),
        and ``unswept_m``: the path driven after the last read (no sweep started there)."""
        sched, path = self.schedule, self.path
        first = (self.n_sweeps - 1) * sched.cycle_s + sched.read_s[:, 0]
        arrive = path.duration_s
        standing = int(np.count_nonzero(first > arrive))
        speed = path.speed_m_s
        last_read_m = min(path.length_m, float(first[-1]) * speed)
        return {"sweeps": self.n_sweeps, "path_m": path.length_m,
                "swept_m": last_read_m - min(path.length_m, float(sched.read_s[0, 0]) * speed),
                "cut": ({"sweep": self.n_sweeps, "steps_standing": standing,
                         "steps": len(first)} if standing else None),
                "unswept_m": path.length_m - last_read_m}


# --------------------------------------------------------------------------- per sweep


@dataclass(frozen=True)
class ReadingPlan:
    """Where and when each reading of one sweep was taken (all times from its start).

    ``sensor_rad`` (S, N): the true hinge angles at the measurement instants
    ``measured_s`` (S, N); ``pose`` (S, N, 3) the true robot pose then, or (3,) for a
    robot that stands; ``reading_poses`` (S, N, 3) what odometry says at the reads
    (motion only); ``sweep_pose`` (3,) the sweep's pose (odometry at its first read);
    ``start_s`` the sweep's start on the drive's clock.
    """

    schedule: Schedule
    commanded_rad: np.ndarray
    sensor_rad: np.ndarray
    measured_s: np.ndarray
    pose: np.ndarray
    reading_poses: np.ndarray | None
    sweep_pose: np.ndarray
    start_s: float = 0.0
    trajectory: Trajectory | None = field(default=None, repr=False)

    @property
    def angle_error_rad(self) -> np.ndarray:
        """(S, N) true − commanded sensor angle at the measurement (lag, overshoot, smear)."""
        return self.sensor_rad - self.commanded_rad


class Dynamics:
    """What ``SimRing`` asks for a scene with ``belt_dynamics``, ``timing`` or ``motion``:
    :meth:`plan` says where and when each reading of a sweep was taken."""

    def __init__(self, scenario: Scenario, built: model_lib.RingModel, seed: int):
        self.scenario = scenario
        self.built = built
        self.seed = int(seed)
        self.belt: BeltDynamicsEffect | None = scenario.effects.get("belt_dynamics")
        self.timing: TimingEffect | None = scenario.effects.get("timing")
        self.motion: MotionEffect | None = scenario.effects.get("motion")
        self._physics: BeltPhysics | None = None
        # refuse a belt time step whose physics is not converged (check_timestep); off only
        # for a study that measures convergence itself (studies.dynamics.convergence)
        self.verify_timestep = True
        self._timelines: dict[bytes, tuple[Schedule, Trajectory | None]] = {}
        self.periods_s = (SensorClocks.periods(self.timing, built.n_sensors, self.seed)
                          if self.timing else None)
        self.path = self._odometry = None
        self.clocks = None
        if self.motion is not None:
            self.path = Path.from_effect(self.motion)
            self.path.check_clearance(scenario)
            if self.timing:  # one continuous clock for the whole drive
                rng = np.random.default_rng([self.seed, TIMING_STREAM, 1])
                self.clocks = SensorClocks.draw(self.timing, self.periods_s, rng)

    @property
    def odometry(self) -> Odometry | None:
        """Dead reckoning along the path (None without motion), made on first use: a sample
        every 5 mm of the drive, so not before the run's size is checked (a path of 20,000
        waypoints took 1 GB here before it was refused as more sweeps than a run takes)."""
        if self._odometry is None and self.path is not None:
            self._odometry = Odometry.along(self.path, self.motion.odometry_sigma_m,
                                            self.motion.odometry_sigma_rad,
                                            np.random.default_rng([self.seed, ODOMETRY_STREAM]))
        return self._odometry

    @property
    def physics(self) -> BeltPhysics:
        if self._physics is None:
            self._physics = BeltPhysics(self.scenario.ring, self.belt)
        return self._physics

    def schedule(self, steps: np.ndarray) -> Schedule:
        return scene_schedule(self.scenario, steps)

    def timeline(self, steps: np.ndarray) -> tuple[Schedule, Trajectory | None]:
        """The schedule of a sweep over ``steps`` and, with ``belt_dynamics``, its physics.

        Every sweep over the same steps starts at rest at its first step, so both are the
        same each time: they are computed once (the physics is nearly all of a belt sweep's
        cost) and shared, read-only, by every plan over these steps. The first time, the
        time step is checked (:func:`check_timestep`, unless ``verify_timestep`` is off).
        Raises ScenarioError when the physics goes unstable or is not converged.
        """
        steps = np.asarray(steps, dtype=np.int64)
        key = steps.tobytes()
        cached = self._timelines.get(key)
        if cached is None:
            sched = self.schedule(steps)
            where = self.scenario.source or self.scenario.name
            traj = None
            try:
                if self.belt is not None:
                    traj = self.physics.run(sched)
                    if self.verify_timestep:
                        change, advice = check_timestep(self.physics, sched, self.timing, traj)
            except RuntimeError as exc:  # a combination the loader's stability rule let through
                raise ScenarioError(f"{where}: effects.belt_dynamics: {exc}") from None
            if traj is not None and self.verify_timestep and change > CONVERGED_ANGLE_RAD:
                raise ScenarioError(
                    f"{where}: effects.belt_dynamics.timestep_ms: {self.belt.timestep_s * 1e3:g} "
                    f"ms is not converged: halving it moves a sensor's true angle at a reading "
                    f"by {math.degrees(change):.3g}°, more than the "
                    f"{math.degrees(CONVERGED_ANGLE_RAD):g}° allowed; {advice}")
            cached = (sched, traj)
            self._timelines[key] = cached
        return cached

    def n_sweeps(self, steps: np.ndarray) -> int:
        """Sweeps the scene takes: one per scan pose, or with motion, back to back until the
        robot reaches the end of its path (:func:`sweeps_along`)."""
        if self.path is None:
            return len(self.scenario.robot.poses)
        return sweeps_along(self.path, self.schedule(steps))

    def plan(self, index: int, steps: np.ndarray, count: int = 0,
             pose: np.ndarray | None = None) -> ReadingPlan:
        """Where and when sweep ``index`` (a scan pose, or with motion the index-th sweep of
        the drive) read; ``count`` is how many sweeps this index had before (fresh clock
        phases per static sweep); ``pose`` the standing robot's pose (static scenes)."""
        sched, traj = self.timeline(steps)
        commanded = self.built.sensor_qpos_for(sched.motor_rad)
        ring_motion = traj if traj is not None else RigidRing(sched, self.built)
        n = self.built.n_sensors
        first_read = np.broadcast_to(sched.read_s[:, :1], (len(sched.steps), n))
        start = 0.0
        if self.path is not None:
            start = index * sched.cycle_s
        if self.timing is not None:
            clocks = self.clocks
            if clocks is None:
                clocks = SensorClocks.draw(self.timing, self.periods_s, np.random.default_rng(
                    [self.seed, index, count, TIMING_STREAM]))
            measured = clocks.measured_at(start + first_read) - start
        else:
            measured = np.array(first_read)
        sensor = ring_motion.sensors_at(measured)
        if self.path is not None:
            true_pose = self.path.pose_at(start + measured)
            reading_poses = self.odometry.pose_at(start + first_read)
            sweep_pose = reading_poses[0, 0].copy()
        else:
            true_pose = np.asarray(pose, dtype=float)
            reading_poses = None
            sweep_pose = true_pose
        return ReadingPlan(schedule=sched, commanded_rad=commanded, sensor_rad=sensor,
                           measured_s=measured, pose=true_pose, reading_poses=reading_poses,
                           sweep_pose=sweep_pose, start_s=start, trajectory=traj)


# --------------------------------------------------------------------------- diagnostics


def heading_error(sweep) -> np.ndarray:
    """(S, N) rad: true beam heading − the heading the estimator assumes (from
    ``sensor_angles`` and ``reading_poses`` or ``pose``), wrapped to ±π. Needs ``truth``."""
    if sweep.truth is None:
        raise ValueError("heading_error needs a simulated sweep (one with truth)")
    d = sweep.truth.direction
    true = np.arctan2(d[..., 1], d[..., 0])
    pose = sweep.reading_poses if sweep.reading_poses is not None else sweep.pose
    _, assumed = beam_geometry(sweep.ring, pose, np.asarray(sweep.sensor_angles), 0.0)
    return np.angle(np.exp(1j * (true - assumed)))
