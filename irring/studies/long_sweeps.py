"""How the estimator's time and memory grow with the readings of one sweep (``irring bench
long``): the same room swept in ever finer steps, and a device's sweep round the full circle
whose every reading returns (docs/speed.md, "Long sweeps").
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
import tracemalloc

import numpy as np

from .. import pipeline
from ..core import (BYTES_PER_READING, ESTIMATE_BYTES_PER_READING, MAX_ESTIMATED_READINGS, Ring,
                    Sweep, bounds, sensor_angles_for_steps)
from ..estimation import estimate as fast, estimate_numpy as oracle
from ..estimation.estimate import nominal_calibration
from ..scenario import load_scenario
from .report import load_average, load_line

STEPS = (71, 710, 4_500, 9_000, 18_000)
KINDS = ("room", "circle")
CIRCLE_STEP_DEG = 0.01     # the circle's motor step (IRINF's finest) …
CIRCLE_COUNTS = 1300       # … and every reading's counts (a wall ~0.3 m away all round)
LARGE = 50_000             # readings from which a sweep's fixed costs are a few per cent
SENSORS = Ring().sensors   # both kinds' rings: t_room's (the paper's) and the circle's
MAX_LONG_STEPS = MAX_ESTIMATED_READINGS // SENSORS   # the longest sweep the estimator takes


def room_sweep(steps: int, scenario: str = "t_room", pose: int = 1, seed: int = 0):
    """(sweep, calibration): ``scenario``'s ``pose``-th scan simulated with its ring's sweep
    (the paper's ±37.8°) read in ``steps`` steps instead of 71 (motor step and belt ratio
    scaled so the motor step stays within a ring's bounds)."""
    sc = load_scenario(scenario)
    ring = sc.robot.ring or Ring()
    sensor_step = (ring.motor_step_rad * ring.gear * (ring.max_step - ring.min_step)
                   / (steps - 1))
    floor = bounds(Ring, "motor_step_rad")[0]
    k = max(1, math.ceil(floor / (sensor_step / ring.gear) - 1e-9))
    ring = dataclasses.replace(ring, motor_step_rad=sensor_step / ring.gear * k,
                               gear=ring.gear / k, min_step=-(steps // 2),
                               max_step=steps - 1 - steps // 2)
    robot = dataclasses.replace(sc.robot, design="custom", ring=ring, ring_keys=(),
                                poses=sc.robot.poses[pose:pose + 1])
    sc = dataclasses.replace(sc, robot=robot)
    cal, _ = pipeline.scene_calibration(sc)
    acq, _ = pipeline.simulated(sc, seed=seed, progress=False)
    return acq.sweeps[0], cal


def circle_sweep(steps: int, sensors: int = SENSORS, step_deg: float = CIRCLE_STEP_DEG):
    """(sweep, calibration): a device's sweep of ``steps`` motor steps of ``step_deg``
    (belt ratio 1) centred on step 0, every reading ``CIRCLE_COUNTS``: 36 000 steps of
    0.01° turn each sensor round the full circle (a hostile device's)."""
    lo = -(steps // 2)
    ring = Ring(sensors=sensors, motor_step_rad=math.radians(step_deg), gear=1.0,
                min_step=lo, max_step=lo + steps - 1, joint_limit_rad=2 * math.pi)
    at = np.arange(lo, lo + steps)
    sweep = Sweep(steps=at, sensor_angles=sensor_angles_for_steps(ring, at),
                  counts=np.full((steps, sensors), float(CIRCLE_COUNTS)),
                  timestamps_s=at * 0.04, duration_s=steps * 0.04,
                  pose=np.array([1.0, 1.0, 0.0]), ring=ring, adc_bits=12, source="device")
    return sweep, nominal_calibration(sweep.sensor_model, ring, sweep.adc_bits, sweep.vref_v)


def measure(kinds=KINDS, steps=STEPS, estimators=("fast",)) -> dict:
    """Per kind, steps and estimator: the estimator's CPU time on the sweep (its second
    run: the first builds the calibration's tables), then its peak memory (tracemalloc, a
    third run), each per reading; plain figures."""
    run = {"fast": fast.estimate_detail, "numpy": oracle.estimate_detail}
    load_before = load_average()
    rows = []
    for kind in kinds:
        for n in steps:
            sweep, cal = room_sweep(n) if kind == "room" else circle_sweep(n)
            readings = int(sweep.counts.size)
            for name in estimators:
                run[name](sweep, cal)
                t0 = time.process_time()
                est = run[name](sweep, cal)
                cpu = time.process_time() - t0
                del est
                tracemalloc.start()
                try:
                    run[name](sweep, cal)
                    peak = tracemalloc.get_traced_memory()[1]
                finally:
                    tracemalloc.stop()
                rows.append({"kind": kind, "steps": int(sweep.counts.shape[0]),
                             "sensors": int(sweep.counts.shape[1]), "readings": readings,
                             "estimator": name, "cpu_s": cpu,
                             "us_per_reading": 1e6 * cpu / readings, "peak_bytes": peak,
                             "bytes_per_reading": peak / readings})
    return {"rows": rows, "model_bytes_per_reading": ESTIMATE_BYTES_PER_READING,
            "run_bytes_per_reading": BYTES_PER_READING,
            "machine": {"cpus": os.cpu_count(), "load_before": load_before,
                        "load_after": load_average()}}


def report(r: dict) -> str:
    """The lines ``irring bench long`` prints."""
    lines = ["the estimator on one sweep: CPU time and peak traced memory per reading",
             "  room: t_room pose 2, the paper's ±37.8° in finer steps; circle: every reading "
             f"returns, {CIRCLE_STEP_DEG}° steps",
             f"  {'kind':<7}{'estimator':<10}{'steps':>8}{'readings':>10}{'CPU s':>9}"
             f"{'µs/reading':>12}{'peak MB':>9}{'B/reading':>11}"]
    for w in r["rows"]:
        lines.append(f"  {w['kind']:<7}{w['estimator']:<10}{w['steps']:>8,}{w['readings']:>10,}"
                     f"{w['cpu_s']:>9.3f}{w['us_per_reading']:>12.2f}"
                     f"{w['peak_bytes'] / 1e6:>9.1f}{w['bytes_per_reading']:>11,.0f}")
    big = [w["bytes_per_reading"] for w in r["rows"] if w["readings"] >= LARGE]
    lines += [f"the work check's model: {r['model_bytes_per_reading']:,} B a reading of the sweep "
              f"estimated (core.ESTIMATE_BYTES_PER_READING; {r['run_bytes_per_reading']} more "
              f"for every reading of a run)" + (
                  f"; the most measured here on sweeps of {LARGE:,} readings or more: "
                  f"{max(big):,.0f}" if big else ""),
              load_line(r["machine"]["load_before"], r["machine"]["load_after"],
                        r["machine"]["cpus"])]
    return "\n".join(lines)
