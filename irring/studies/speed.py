"""How fast each stage of a sweep is, against raw MuJoCo and against the real ring
(:func:`measure`, ``irring bench speed``); how fast each way of getting a sweep's rays out
of MuJoCo is (:func:`ray_paths`, ``python -m irring.studies.speed``).

How it works, its assumptions and measured figures: docs/speed.md.
"""

from __future__ import annotations

import gc
import os
import platform
import time
from typing import Callable

import numpy as np

from ..estimation.calibration import Calibration
from ..estimation.estimate import estimate
from ..maps.mapping import OccupancyGrid
from ..scenario import load_scenario
from ..simulation.effects import PHASES, Pipeline
from ..simulation.rangers import pipeline_for
from .report import load_average, load_line

TARGETS = {"sweep_ms": 2.0, "ray_vs_raw_ratio": 1.5, "realtime_factor": 1000.0}
RAY_PAIRS = 3   # per round: our ray stage and the raw call, alternating


class _Timed:
    """A stage phase method that adds its wall time to a shared tally."""

    def __init__(self, fn: Callable, tally: dict, name: str):
        self.fn, self.tally, self.name = fn, tally, name

    def __call__(self, *args, **kwargs):
        t0 = time.perf_counter()
        try:
            return self.fn(*args, **kwargs)
        finally:
            self.tally[self.name] = self.tally.get(self.name, 0.0) + time.perf_counter() - t0


def timed_pipeline(scenario, tally: dict):
    """The scenario's effects pipeline with every stage's phase methods timed into
    ``tally`` (stage name → seconds, accumulated)."""
    plain = pipeline_for(scenario)
    stages = []
    for st in plain.stages:
        for phase in PHASES:
            fn = getattr(st, phase, None)
            if fn is not None:  # an instance attribute shadows the method for this stage only
                setattr(st, phase, _Timed(fn, tally, st.name))
        stages.append(st)
    return Pipeline(plain.setup, tuple(stages))


def measure(scenario, *, rounds: int = 200, pose_index: int = 0, seed: int | None = None,
            warmup: int = 5) -> dict:
    """Time every stage of a sweep of ``scenario`` (a loaded Scenario); plain figures."""
    # deferred: MuJoCo and the modules that load it, which --help does not need
    import mujoco
    import mujoco.batch

    from ..simulation import model as model_lib
    from ..simulation.sim import SimRing

    if rounds < 1:
        raise ValueError(f"rounds must be ≥ 1, got {rounds}")
    load_before = load_average()
    sim = SimRing(scenario, seed=seed)
    steps = sim.default_steps()
    motor = steps * sim.ring.motor_step_rad
    angles = sim.built.sensor_qpos_for(motor)
    pose = sim.pose(pose_index)
    origin, direction = sim.frames(angles, pose)
    o = np.ascontiguousarray(origin.reshape(-1, 3))
    u = np.ascontiguousarray(direction.reshape(-1, 3))
    raw = mujoco.batch.Batch(sim.ray_model, 1, nthread=1)   # the model a sweep casts into
    group = model_lib.RAY_GEOMGROUP

    tally: dict[str, float] = {}
    pipe = timed_pipeline(scenario, tally)
    _, _, truth = sim.truth(pose_index)
    sweep = sim.sweep(pose_index)
    cal = Calibration.for_scene(scenario)   # as irring run reads the scene
    points = estimate(sweep, cal)
    grid = OccupancyGrid.for_scenario(scenario)
    chain_grid = OccupancyGrid.for_scenario(scenario)
    rng = np.random.default_rng(0 if seed is None else seed)

    def chain():
        p = estimate(sim.sweep(pose_index), cal)
        chain_grid.insert(p)
        return p

    plain_stages: dict[str, Callable] = {
        "kinematics": lambda: sim.frames(angles, pose),
        "kinematics_mujoco": lambda: sim.frames(angles, pose, reuse=False),
        "sim_sweep": lambda: sim.sweep(pose_index),
        "estimator": lambda: estimate(sweep, cal),
        "mapper": lambda: grid.insert(points),
    }
    ours = lambda: sim.truth_at(origin, direction)  # noqa: E731  (the rays of a sweep)
    bare = lambda: raw.ray(o[None], u[None], geomgroup=group, normal=True)  # noqa: E731
    samples: dict[str, list[float]] = {k: [] for k in
                                       (*plain_stages, "rays", "raw_mujoco", "effects", "sweep")}
    effect_samples: dict[str, list[float]] = {s.name: [] for s in pipe.stages}
    iterations: list[int] = []

    def clock(fn: Callable) -> float:
        t0 = time.perf_counter()
        fn()
        return time.perf_counter() - t0

    def run_block(name: str, keep: bool) -> None:
        if name == "rays":  # ours and raw alternate, so both run in the same cache state
            ours(), bare()  # neither pays for the block that ran before
            pairs = [(clock(ours), clock(bare)) for _ in range(RAY_PAIRS)]
            if keep:
                samples["rays"].extend(a for a, _ in pairs)
                samples["raw_mujoco"].extend(b for _, b in pairs)
        elif name == "effects":
            tally.clear()
            dt = clock(lambda: pipe.run(truth, rng, cast=sim.cast))
            if keep:
                samples["effects"].append(dt)
                for stage in effect_samples:
                    effect_samples[stage].append(tally.get(stage, 0.0))
        elif name == "sweep":
            t0 = time.perf_counter()
            p = chain()
            dt = time.perf_counter() - t0
            if keep:
                samples["sweep"].append(dt)
                iterations.append(int(p.iterations.max(initial=0)))
        else:
            dt = clock(plain_stages[name])
            if keep:
                samples[name].append(dt)

    blocks = [*plain_stages, "rays", "effects", "sweep"]
    order_rng = np.random.default_rng(12345)  # a fixed shuffle: same schedule every run
    gc_was = gc.isenabled()
    gc.disable()
    try:
        for r in range(warmup + rounds):
            # each round runs every block once, in a new order, so no stage always follows
            # the cache-clearing estimator and mapper
            for i in order_rng.permutation(len(blocks)):
                run_block(blocks[i], r >= warmup)
    finally:
        if gc_was:
            gc.enable()

    def ms(xs) -> float:
        return float(np.median(xs) * 1e3)

    effects_ms = {name: ms(v) for name, v in effect_samples.items()}
    core = [t - sum(effect_samples[n][i] for n in effect_samples)
            for i, t in enumerate(samples["effects"])]
    stages = [{"stage": "kinematics", "ms": ms(samples["kinematics"])},
              {"stage": "rays", "ms": ms(samples["rays"])}]
    stages += [{"stage": f"effect: {name}", "ms": v} for name, v in effects_ms.items()]
    stages += [{"stage": "effects core", "ms": ms(core)},
               {"stage": "estimator", "ms": ms(samples["estimator"])},
               {"stage": "mapper", "ms": ms(samples["mapper"])}]
    sweep_ms = ms(samples["sweep"])
    ray_ms, raw_ms = ms(samples["rays"]), ms(samples["raw_mujoco"])
    hw_s = float(sweep.duration_s)
    out = {
        "scenario": scenario.name,
        "effects": list(pipe.names),
        "steps": int(len(steps)), "sensors": int(sim.ring.sensors), "rays": int(len(o)),
        "rounds": rounds,
        "sweep_ms": sweep_ms,
        "sweep_ms_p90": float(np.percentile(samples["sweep"], 90) * 1e3),
        "stages": stages,
        "stages_sum_ms": float(sum(s["ms"] for s in stages)),
        "sim_sweep_ms": ms(samples["sim_sweep"]),
        "kinematics_mujoco_ms": ms(samples["kinematics_mujoco"]),
        "effects_ms": ms(samples["effects"]),
        "ray_ms": ray_ms,
        "raw_mujoco_ms": raw_ms,
        "ray_vs_raw_ratio": ray_ms / raw_ms,
        "estimator_iterations_median": float(np.median(iterations)),
        "sweeps_per_s": 1e3 / sweep_ms,
        "hardware_time_s": hw_s,
        "realtime_factor": hw_s / (sweep_ms / 1e3),
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                    "python": platform.python_version(), "mujoco": mujoco.__version__,
                    "numpy": np.__version__,
                    "load_before": load_before, "load_after": load_average()},
    }
    out["targets"] = {
        "sweep_ms": {"target": f"≤ {TARGETS['sweep_ms']:g} ms", "value": sweep_ms,
                     "met": sweep_ms <= TARGETS["sweep_ms"]},
        "ray_vs_raw_ratio": {"target": f"≤ {TARGETS['ray_vs_raw_ratio']:g}×",
                             "value": out["ray_vs_raw_ratio"],
                             "met": out["ray_vs_raw_ratio"] <= TARGETS["ray_vs_raw_ratio"]},
        "realtime_factor": {"target": f"≥ {TARGETS['realtime_factor']:g}×",
                            "value": out["realtime_factor"],
                            "met": out["realtime_factor"] >= TARGETS["realtime_factor"]},
    }
    return out


def report(r: dict) -> str:
    """The human-readable lines ``irring bench speed`` prints."""
    lines = [f"{r['scenario']}: one sweep of {r['steps']} steps × {r['sensors']} sensors = "
             f"{r['rays']} rays, effects {', '.join(r['effects']) or 'none'}; median of "
             f"{r['rounds']} rounds, ms per sweep",
             f"  {'stage':<24}{'ms':>9}{'share':>8}"]
    total = r["stages_sum_ms"]
    for s in r["stages"]:
        lines.append(f"  {s['stage']:<24}{s['ms']:9.3f}{100 * s['ms'] / total:7.1f}%")
    lines += [
        f"  {'sum of stage medians':<24}{total:9.3f}",
        f"whole sweep (sim → estimate → map)  {r['sweep_ms']:8.3f} ms median "
        f"(p90 {r['sweep_ms_p90']:.3f}); simulator alone {r['sim_sweep_ms']:.3f} ms",
        f"kinematics: {r['kinematics_mujoco_ms']:.3f} ms for MuJoCo's batched forward (new "
        f"angles: a moving or belt-driven scene); a static scene places the kept frames",
        f"rays: ours {r['ray_ms']:.3f} ms, raw MuJoCo batched ray call {r['raw_mujoco_ms']:.3f} ms "
        f"→ {r['ray_vs_raw_ratio']:.2f}×",
        f"sweeps per second {r['sweeps_per_s']:.0f}; hardware time {r['hardware_time_s']:.2f} s "
        f"per sweep → real-time factor {r['realtime_factor']:.0f}×",
        load_line(r["machine"]["load_before"], r["machine"]["load_after"], r["machine"]["cpus"]),
        "targets:"]
    for key, t in r["targets"].items():
        v = t["value"]
        lines.append(f"  {key:<18}{t['target']:>10}   {v:10.3f}   "
                     f"{'met' if t['met'] else 'MISSED'}")
    return "\n".join(lines)


def ray_paths(scenario_name: str = "t_room", repeats: int = 200) -> dict[str, float]:
    """Median ms (over ``repeats``) of a whole sweep (``sweep_ms``: truth and the scene's
    effects), of its truth alone, and of each way to get a sweep's rays out of MuJoCo: the
    measurement behind the simulator's design (docs/simulation.md). Run
    ``python -m irring.studies.speed [SCENARIO]``."""
    # deferred: MuJoCo and the modules that load it, which --help does not need
    import mujoco
    import mujoco.batch

    from ..simulation import model as model_lib
    from ..simulation.sim import SimRing, pose_quat

    sim = SimRing(load_scenario(scenario_name))
    built, m = sim.built, sim.model
    steps = sim.default_steps()
    motor = steps * sim.ring.motor_step_rad
    angles = built.sensor_qpos_for(motor)
    pose = sim.pose(0)
    origin, direction = sim.frames(angles, pose)
    o, u = origin.reshape(-1, 3), direction.reshape(-1, 3)

    def median_ms(fn, n=repeats) -> float:
        fn()
        times = []
        for _ in range(n):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
        return float(np.median(times) * 1e3)

    # (b) one MjData, mj_kinematics per step
    d = mujoco.MjData(m)
    d.mocap_pos[built.chassis_mocap] = [pose[0], pose[1], 0.0]
    d.mocap_quat[built.chassis_mocap] = pose_quat(pose[2])
    qpos = np.zeros((len(steps), m.nq))
    qpos[:, built.sensor_qpos] = angles
    qpos[:, built.motor_qpos] = motor

    sites = built.emitter_sites
    out_o = np.empty(origin.shape)
    out_z = np.empty(direction.shape)

    def kin_loop():  # what frames() would be with one MjData: write, kinematics, copy out
        for i, q in enumerate(qpos):
            d.qpos[:] = q
            mujoco.mj_kinematics(m, d)
            out_o[i] = d.site_xpos[sites]
            out_z[i] = d.site_xmat[sites][:, 2::3]

    # (a) the rangefinder sensors, one simulation per step, batched forward
    rf = mujoco.batch.Batch(m, len(steps), nthread=1)
    rf.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
    rf.bind("mocap_pos")[:, built.chassis_mocap] = [pose[0], pose[1], 0.0]
    rf.bind("mocap_quat")[:, built.chassis_mocap] = pose_quat(pose[2])

    def rangefinders():
        rf.bind("qpos")[:] = qpos
        rf.forward(stage=mujoco.mjtStage.mjSTAGE_POS)
        return rf.bind("sensordata")

    geomid = np.zeros(1, np.int32)
    normal = np.zeros(3)
    dist1 = np.zeros(1)

    def ray_loop():
        for i in range(len(o)):
            mujoco.mj_ray(m, d, o[i], u[i], model_lib.RAY_GEOMGROUP, 1, -1, geomid, normal)

    def multiray_loop():
        for i in range(len(o)):
            mujoco.mj_multiRay(m, d, o[i], u[i], model_lib.RAY_GEOMGROUP, 1, -1, geomid, dist1,
                               normal, 1, 1e9)

    raw = mujoco.batch.Batch(sim.ray_model, 1, nthread=1)   # the batched ray call SimRing.cast makes
    mujoco.mj_kinematics(m, d)
    return {
        "rays": float(len(o)),
        "sweep_ms": median_ms(lambda: sim.sweep(0)),
        "sweep_truth_ms": median_ms(lambda: sim.truth(0)),
        "frames_batch_forward_ms": median_ms(lambda: sim.frames(angles, pose, reuse=False)),
        "frames_cached_ms": median_ms(lambda: sim.frames(angles, pose)),
        "frames_kinematics_loop_ms": median_ms(kin_loop),
        "rangefinders_batch_forward_ms": median_ms(rangefinders),
        "cast_ms": median_ms(lambda: sim.cast(origin, direction)),
        "raw_batch_ray_ms": median_ms(lambda: raw.ray(o[None], u[None],
                                                      geomgroup=model_lib.RAY_GEOMGROUP,
                                                      normal=True)),
        "mj_ray_loop_ms": median_ms(ray_loop, 50),
        "mj_multiray_loop_ms": median_ms(multiray_loop, 50),
    }


if __name__ == "__main__":  # pragma: no cover - a measurement, run by hand
    import sys

    name = sys.argv[1] if len(sys.argv) > 1 else "t_room"
    print(f"{name}: median ms per sweep of 71 steps × 12 sensors")
    for key, value in ray_paths(name).items():
        print(f"  {key:32s} {value:8.3f}")
