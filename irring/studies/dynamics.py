"""What the belt, the GP2's clock and a moving robot do to the readings, in numbers:
:func:`coupling`, :func:`convergence`, :func:`timestep_table`, :func:`check_cost`,
:func:`settling`, :func:`mujoco_clocks` and :func:`motion` return plain figures (``irring bench dynamics`` prints them,
tests/test_dynamics.py asserts on them). What each measures: docs/dynamics.md.
"""

from __future__ import annotations

import dataclasses
import time
import types
from collections.abc import Callable

import mujoco
import numpy as np

from .. import pipeline, safe_yaml
from ..core import Ring
from ..estimation.calibration import scene_calibration
from ..scenario import BeltDynamicsEffect, Scenario, load_scenario, loads, parse, resolve
from ..simulation import dynamics as dyn, model as model_lib
from ..simulation.sim import SimRing

SETTLE_S = (0.0, 0.010, 0.020, 0.0383, 0.0529, 0.075)
# docs/dynamics.md's time-step table: (belt τ ms, step time ms, backlash °, time steps ms)
TIMESTEP_CASES = ((2.0, 4.0, 0.0, (0.5, 1.0, 1.5, 1.75, 2.0, 3.0, 4.0)),
                  (10.0, 4.0, 0.0, (2.0, 3.0, 4.0, 5.0)),
                  (0.5, 4.0, 0.0, (0.45,)),
                  (0.25, 4.0, 0.0, (0.5,)),
                  (0.2, 4.0, 5.0, (0.5,)))
BOX_ROOM = """name: box
seed: 2
room:
  outline_mm: [[0, 0], [1300, 0], [1300, 900], [0, 900]]
robot:
  poses: [{{x_mm: 500, y_mm: 400}}]
effects:
  belt_dynamics: {{timestep_ms: {dt}, belt_timeconst_ms: {tau}, step_time_ms: {step},
                  backlash_deg: {backlash}}}
"""


def variant(name: str, *, effects: dict | None = None, drop: tuple = (), scan: dict | None = None,
            motion: dict | None = None, poses: list | None = None) -> Scenario:
    """A bundled scenario with effects added/replaced/dropped, its scan block replaced and
    motion keys changed (spell them as the file does, e.g. ``odometry_sigma_mm``)."""
    raw = safe_yaml.load_file(resolve(name), "scenario file")
    raw.setdefault("effects", {})
    for key in drop:
        raw["effects"].pop(key, None)
    raw["effects"].update(effects or {})
    if scan is not None:
        raw["scan"] = scan
    if motion:
        raw["effects"]["motion"] = {**raw["effects"]["motion"], **motion}
    if poses is not None:
        raw["robot"]["poses"] = poses
    return parse(raw, f"{name} (variant)")


def coupling(n_sweeps: int = 1000, params: BeltDynamicsEffect | None = None,
             ring: Ring | None = None, on_sweeps: Callable[[int], object] | None = None) -> dict:
    """The belt over ``n_sweeps`` continuous back-and-forth sweeps (see the module doc);
    ``on_sweeps(k)`` is told each time k more are done (a progress bar's ``update``)."""
    ring = ring or Ring()
    physics = dyn.BeltPhysics(ring, params or BeltDynamicsEffect())
    t0 = time.perf_counter()
    r = endurance(physics, np.arange(ring.min_step, ring.max_step + 1), n_sweeps,
                  on_sweeps=on_sweeps)
    return {"sweeps": n_sweeps, "physics_steps": r["physics_steps"],
            "timestep_s": physics.dt_s, "stretch_max_rad": float(r["stretch_rad"].max()),
            "stretch_first_rad": float(r["stretch_rad"][0]),
            "stretch_last_rad": float(r["stretch_rad"][-1]),
            "read_error_max_rad": float(r["read_error_rad"].max()),
            "stretch_per_sweep_rad": r["stretch_rad"], "warnings": r["warnings"],
            "compute_s": time.perf_counter() - t0}


def endurance(physics: dyn.BeltPhysics, steps: np.ndarray, n_sweeps: int, *,
              chunk: int = 50, on_sweeps: Callable[[int], object] | None = None) -> dict:
    """Sweep back and forth ``n_sweeps`` times in one continuous run, never resting: each
    sweep moves step to step every ``step_time_s`` and reads at each arrival (a timed sweep
    with no settle, the belt's hardest duty), the next starting where the last ended.
    Returns per-sweep maxima over every physics step of |belt stretch| (``stretch_rad``,
    (n_sweeps,)) and over the reads of |sensor − commanded| (``read_error_rad``), the physics
    steps run and MuJoCo's warning count (a warning or a non-finite state raises, see
    :meth:`~irring.simulation.dynamics.BeltPhysics.follow`)."""
    steps = np.asarray(steps, dtype=np.int64)
    ring, dt_s = physics.ring, physics.dt_s
    up = dyn.schedule(steps, ring, step_time_s=physics.params.step_time_s, timing=True)
    down = dyn.schedule(steps[::-1], ring, step_time_s=physics.params.step_time_s, timing=True)
    per = int(round(up.duration_s / dt_s))
    if abs(per * dt_s - up.duration_s) > 1e-9:
        raise ValueError("a sweep must last a whole number of physics steps here; its "
                         f"{up.duration_s:g} s is not a multiple of {dt_s:g} s")
    mid = (np.arange(per) + 0.5) * dt_s
    legs = (up.motor_at(mid), down.motor_at(mid))
    reads = [np.rint(s.read_s[:, 0] / dt_s).astype(np.int64) for s in (up, down)]
    commanded = [s.motor_rad[:, None] * physics.gear for s in (up, down)]
    starts = range(0, n_sweeps, chunk)
    targets = (np.concatenate([legs[(done + j) % 2] for j in range(min(chunk, n_sweeps - done))])
               for done in starts)
    stretch = np.zeros(n_sweeps)
    read_err = np.zeros(n_sweeps)
    for done, run in zip(starts, physics.follow(targets, up.motor_rad[0], np.zeros(ring.sensors))):
        belt = np.abs(run.stretch_rad).max(axis=1)     # sample i at i·dt from the chunk
        for j in range((len(belt) - 1) // per):
            leg = (done + j) % 2
            a = j * per
            stretch[done + j] = belt[a:a + per + 1].max()
            at = run.sensor_rad[a + reads[leg]]
            read_err[done + j] = np.abs(at - commanded[leg]).max()
        if on_sweeps is not None:
            on_sweeps(min(chunk, n_sweeps - done))
    # follow raises on any MuJoCo warning: a run that ends had none
    return {"stretch_rad": stretch, "read_error_rad": read_err,
            "physics_steps": n_sweeps * per, "warnings": 0}


def _sweep_at(scenario: Scenario, timestep_s: float, seed: int):
    effects = dict(scenario.effects)
    effects["belt_dynamics"] = dataclasses.replace(effects["belt_dynamics"], timestep_s=timestep_s)
    sc = dataclasses.replace(scenario, effects=types.MappingProxyType(effects))
    sim = SimRing(sc, seed=seed)
    sim.dynamics.verify_timestep = False   # this measures convergence, at any time step
    plan = sim.dynamics.plan(0, sim.default_steps(), 0, sim.pose(0))
    return plan, sim.sweep(0)


def convergence(scenario: Scenario, timestep_s: float | None = None, seed: int = 1) -> dict:
    """One sweep of ``scenario`` (which lists belt_dynamics) at dt and at dt/2: the largest
    change of a true sensor angle, a true distance, an ADC count."""
    dt = timestep_s or scenario.effects["belt_dynamics"].timestep_s
    (pa, sa), (pb, sb) = _sweep_at(scenario, dt, seed), _sweep_at(scenario, dt / 2, seed)
    da = np.asarray(sa.truth.distance_m)
    db = np.asarray(sb.truth.distance_m)
    both = np.isfinite(da) & np.isfinite(db)
    return {"timestep_s": dt, "angle_rad": float(np.abs(pa.sensor_rad - pb.sensor_rad).max()),
            "distance_m": float(np.abs(da - db)[both].max()),
            "hit_changed": int(np.count_nonzero(np.isfinite(da) != np.isfinite(db))),
            "counts": float(np.abs(np.asarray(sa.counts, float)
                                   - np.asarray(sb.counts, float)).max()),
            "angle_error_rms_rad": float(np.sqrt(np.mean(pa.angle_error_rad ** 2)))}


def timestep_table(cases=TIMESTEP_CASES, seed: int = 2) -> list[dict]:
    """Per case and time step, one sweep of a 1.3 × 0.9 m box from (500, 400) mm: how far
    halving the step moves a true sensor angle at a read (what the first sweep's check
    measures, ``passes`` if ≤ :data:`~irring.simulation.dynamics.CONVERGED_ANGLE_RAD`) and the
    occupied F1 of the map made at that step anyway (the check off)."""
    rows = []
    for tau_ms, step_ms, backlash_deg, dts_ms in cases:
        for dt_ms in dts_ms:
            sc = loads(BOX_ROOM.format(dt=dt_ms, tau=tau_ms, step=step_ms, backlash=backlash_deg),
                       "timestep table")
            sim = SimRing(sc, seed=seed)
            sim.dynamics.verify_timestep = False
            acq = pipeline.acquire(sim, range(sim.n_sweeps), progress=False)
            sched, run = sim.dynamics.timeline(sim.default_steps())
            change = dyn.timestep_change(sim.dynamics.physics, sched, sim.dynamics.timing, run)
            result = pipeline.map_sweeps(acq.sweeps, scenario=sc,
                                         calibration=scene_calibration(sc)[0])
            rows.append({"belt_timeconst_s": tau_ms / 1e3, "step_time_s": step_ms / 1e3,
                         "backlash_rad": float(np.radians(backlash_deg)),
                         "timestep_s": dt_ms / 1e3, "angle_change_rad": change,
                         "passes": change <= dyn.CONVERGED_ANGLE_RAD,
                         "occupied_f1": float(result.scores["occupied_f1"])})
    return rows


def check_cost(name: str = "t_room_moving", repeats: int = 3) -> dict:
    """What the first sweep's time-step check costs on ``name``'s sweep, best of ``repeats``
    (seconds): the belt physics at the scene's step (``physics_s``), the check as it runs
    (``check_s``: the sweep at twice the step, and at half of it unless that passes) and the
    sweep at half the step alone (``halving_s``); ratios to the physics."""
    sim = SimRing(load_scenario(name))
    dynamics = sim.dynamics
    sched = dynamics.schedule(sim.default_steps())
    times: dict[str, list[float]] = {"physics_s": [], "check_s": [], "halving_s": []}
    for _ in range(repeats):
        t0 = time.perf_counter()
        run = dynamics.physics.run(sched)
        t1 = time.perf_counter()
        dyn.forget_timestep_checks()
        change, _ = dyn.check_timestep(dynamics.physics, sched, dynamics.timing, run)
        t2 = time.perf_counter()
        halving = dyn.timestep_change(dynamics.physics, sched, dynamics.timing, run)
        t3 = time.perf_counter()
        for key, seconds in zip(times, (t1 - t0, t2 - t1, t3 - t2)):
            times[key].append(seconds)
    out = {key: min(values) for key, values in times.items()}
    return {"scene": name, "physics_steps": len(run.motor_rad), **out,
            "check_ratio": out["check_s"] / out["physics_s"],
            "halving_ratio": out["halving_s"] / out["physics_s"],
            "check_change_rad": change, "halving_change_rad": halving}


def settling(effects: dict, settles_s=SETTLE_S, seed: int = 1, name: str = "t_room") -> list[dict]:
    """Angle error and hardware time of one sweep at each settle time (pose 0 of ``name``)."""
    rows = []
    for settle in settles_s:
        sc = variant(name, effects=effects, scan={"settle_s": settle})
        sim = SimRing(sc, seed=seed)
        plan = sim.dynamics.plan(0, sim.default_steps(), 0, sim.pose(0))
        err = plan.angle_error_rad
        rows.append({"settle_s": settle, "hardware_s": plan.schedule.duration_s,
                     "angle_error_rms_rad": float(np.sqrt(np.mean(err ** 2))),
                     "angle_error_max_rad": float(np.abs(err).max())})
    return rows


def mujoco_clocks(scenario: Scenario, seed: int = 3) -> dict:
    """Readings of one timed sweep from MuJoCo's periodic, delayed rangefinders vs ours.

    The scene must list ``belt_dynamics`` and ``timing``. Each sensor gets a period on the
    physics grid and a phase a quarter step off it, MuJoCo's rangefinders the same
    ``interval`` and ``delay`` (the latency, on the grid), and their histories the rest
    pose's reading (the GP2 measured before the sweep started). MuJoCo computes a periodic
    sensor at the first time step at or after each due instant, so ours is evaluated there
    too for ``agree_quantized`` (share of readings within 1 µm; same physics, same clock
    rule: it should be 1) while ``agree`` / ``max_diff_m`` compare with the simulator's own
    continuous instants (they differ by at most one time step of motion). ``stale_m``: how
    far the timed readings are from instantaneous ones (mean).
    """
    sim = SimRing(scenario, seed=seed)
    dynamics = sim.dynamics
    physics = dynamics.physics
    dt = physics.dt_s
    timing = dynamics.timing
    n = sim.built.n_sensors
    period = np.maximum(np.round(dynamics.periods_s / dt), 2) * dt
    phase = (np.floor(np.random.default_rng([seed, 7]).uniform(0, 1, n) * period / dt)
             + 0.25) * dt
    latency = np.round(timing.latency_s / dt) * dt
    clocks = dyn.SensorClocks(period_s=period, phase_s=phase, latency_s=latency)
    steps = sim.default_steps()
    sched = dynamics.schedule(steps)
    traj = physics.run(sched)
    first = np.broadcast_to(sched.read_s[:, :1], (len(steps), n))
    measured = clocks.measured_at(first)

    def distances(t_s):
        origin, direction = sim.frames(traj.sensors_at(t_s), sim.pose(0))
        return sim.cast(origin, direction).distance_m

    ours = distances(measured)
    ours_q = distances(np.ceil(measured / dt - 1e-9) * dt)

    spec, _ = model_lib.scenario_spec(scenario)
    spec = dyn.physics_spec(scenario.ring, dynamics.belt, spec)
    nsample = int(np.ceil(latency / period.min())) + 2
    for k in range(n):
        rf = spec.sensor(f"{model_lib.sensor_name(k)}_range")
        rf.nsample = nsample
        rf.interval = [period[k], phase[k] - period[k]]   # MuJoCo: last computed before t = 0
        rf.delay = latency
    m = spec.compile()
    dyn.tune_belt(m, dynamics.belt)
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    d = mujoco.MjData(m)

    def jid(name):
        return m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)]

    sensors = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR,
                                 f"{model_lib.sensor_name(k)}_range") for k in range(n)]
    motor, hinges = jid("ring_motor"), [jid(f"{model_lib.sensor_name(k)}_hinge")
                                        for k in range(n)]
    d.qpos[motor] = sched.motor_rad[0]
    d.qpos[hinges] = physics.gear * sched.motor_rad[0]
    d.ctrl[0] = sched.motor_rad[0]
    pose = sim.pose(0)
    chassis = m.body_mocapid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "chassis")]
    d.mocap_pos[chassis] = [pose[0], pose[1], 0.0]
    d.mocap_quat[chassis] = [np.cos(pose[2] / 2), 0.0, 0.0, np.sin(pose[2] / 2)]
    # the rest pose's reading fills each history (computed undelayed, then restored)
    saved = m.sensor_delay.copy(), m.sensor_interval.copy()
    m.sensor_delay[:], m.sensor_interval[:] = 0.0, 0.0
    mujoco.mj_forward(m, d)
    rest = [d.sensordata[m.sensor_adr[s]:m.sensor_adr[s] + m.sensor_dim[s]].copy()
            for s in sensors]
    m.sensor_delay[:], m.sensor_interval[:] = saved
    for k, s in enumerate(sensors):
        mujoco.mj_initSensorHistory(m, d, s, None, np.tile(rest[k], (nsample, 1)),
                                    phase[k] - period[k])
    reads = {int(i): j for j, i in enumerate(np.rint(sched.read_s[:, 0] / dt).astype(int))}
    theirs = np.full((len(steps), n), np.nan)
    adr = m.sensor_adr[sensors]
    for i, u in enumerate(physics.controls(sched)):
        d.ctrl[0] = u
        mujoco.mj_step(m, d)   # sensordata now describes time i·dt
        if i in reads:
            theirs[reads[i]] = d.sensordata[adr]
    warnings = int(sum(w.number for w in d.warning))
    ok = np.isfinite(ours) & np.isfinite(ours_q)
    diff = np.abs(theirs - ours)[ok]
    instant = sim.truth(0)[2].distance_m
    both = ok & np.isfinite(instant)
    return {"readings": int(ok.sum()), "agree": float(np.mean(diff < 1e-6)),
            "agree_quantized": float(np.mean(np.abs(theirs - ours_q)[ok] < 1e-6)),
            "max_diff_m": float(diff.max()), "warnings": warnings,
            "stale_m": float(np.mean(np.abs(ours - instant)[both])), "timestep_s": dt}


def motion(seeds=(1,)) -> dict:
    """Occupied F1 (mean over ``seeds``): static t_room, static scans where the moving run's
    sweeps were (mid-sweep true poses), the moving run with perfect and bundled odometry."""
    perfect = variant("t_room_moving", motion={"odometry_sigma_mm": 0, "odometry_sigma_deg": 0})
    sim = SimRing(perfect)
    steps = sim.default_steps()
    mid = [sim.dynamics.plan(k, steps).pose[len(steps) // 2, 0] for k in range(sim.n_sweeps)]
    along = variant("t_room_moving", drop=dyn.DYNAMIC_EFFECTS,
                    poses=[{"x_m": float(p[0]), "y_m": float(p[1]), "yaw_rad": float(p[2])}
                           for p in mid])
    runs = {"static_t_room": load_scenario("t_room"), "static_along_path": along,
            "moving_perfect_odometry": perfect, "moving_bundled": load_scenario("t_room_moving")}
    out: dict = {"seeds": list(seeds), "sweeps": {}}
    for key, sc in runs.items():
        f1, hw = [], 0.0
        for seed in seeds:
            r = pipeline.run(sc, seed=seed, progress=False)
            f1.append(r.scores["occupied_f1"])
            hw = r.hardware_time_s
            out["sweeps"][key] = len(r.sweeps)
        out[key] = float(np.mean(f1))
        out[f"{key}_hardware_s"] = hw
    return out


def measure(*, sweeps: int = 1000, seeds=(1,), with_motion: bool = True,
            timesteps: bool = False, progress: bool | None = None) -> dict:
    """Everything above with the defaults (what ``irring bench dynamics`` prints); the
    time-step table only with ``timesteps``. ``progress``: bars over the belt's sweeps,
    then the other parts (None: at a terminal, ``pipeline.progress_enabled``)."""
    belt_timing = {"belt_dynamics": {}, "timing": {}}
    fast = variant("t_room", effects=belt_timing, scan={"settle_s": 0.0})
    belt_only = variant("t_room", effects={"belt_dynamics": {}}, scan={"settle_s": 0.0})
    parts = {
        "convergence": lambda: [dict(convergence(sc), scene=label) for label, sc in
                                (("belt, settle 0", belt_only),
                                 ("belt + timing, settle 0", fast))],
        "settling_belt_timing": lambda: settling(belt_timing),
        "settling_belt": lambda: settling({"belt_dynamics": {}}, (0.0, 0.005, 0.010, 0.020)),
        "settling_timing": lambda: settling({"timing": {}}),
        "mujoco_clocks": lambda: mujoco_clocks(fast),
        "check_cost": check_cost,
    }
    if with_motion:
        parts["motion"] = lambda: motion(seeds)
    if timesteps:
        parts["timesteps"] = timestep_table
    with pipeline.progress_bar(sweeps, "belt", progress, unit="sweep") as bar:
        out = {"coupling": coupling(sweeps, on_sweeps=bar.update)}
    out["coupling"].pop("stretch_per_sweep_rad")
    with pipeline.progress_bar(len(parts), "bench dynamics", progress, unit="part") as bar:
        for key, part in parts.items():
            out[key] = part()
            bar.update()
    return out
