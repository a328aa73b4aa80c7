"""The main job end to end: scenario → sweeps → estimate → map → scores, timed per stage.

>>> result = run(load_scenario("t_room"))     # simulate every pose, estimate, map, score
>>> write_outputs(result, "out/t_room")        # PNG, GIF, PGM+YAML, .npz

:func:`acquire` sweeps any ``core.RingSource`` at each pose and :func:`map_sweeps` inserts
the sweeps into the grid in pose order, so ``irring run``, ``replay``, ``compare``, ``bench``
and ``drive`` build a map the same way. Compute times are this machine's wall seconds per
stage; hardware time is what the real ring would spend (sum of ``Sweep.duration_s``).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import importlib
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Sequence

import numpy as np

from . import recording as rec
from .core import (Points, Pose, Reason, RingSource, SourceLost, Sweep, in_turn_order,
                   GP2_PERIOD_S, inside_outline, points_with, score_text,
                   sensor_angles_for_steps)
from .estimation.calibration import (Calibration, CalibrationError, load_calibration,
                                     scene_calibration)
from .estimation.estimate import estimate
from .gp2 import SENSORS
from .maps import metrics
from .maps.mapping import (MapperParams, OccupancyGrid, check_covering, check_scenario_grid,
                           RunSilences, classify, returns_of, slice_steps)
from .maps.mcap_export import write_mcap_to
from .errors import printable
from .outputs import MCAP_FILE, OutputError, OutputSet, atomic_file
from .scenario import Scenario, ScenarioError, clipped_obstacles, loads

FRAMES_PER_SWEEP = 6  # animation frames while one sweep is mapped (the map itself is unaffected)
ANGLE_TOLERANCE_RAD = 1e-9   # a recorded commanded angle's rounding (its product in any order)


def progress_enabled() -> bool:
    """Progress bars only for a person: at a terminal or in a notebook, not when piped,
    not under CI."""
    if os.environ.get("CI", "").lower() in ("true", "1"):
        return False
    return sys.stderr.isatty() or _in_notebook()


def _in_notebook() -> bool:
    shell = sys.modules.get("IPython")
    ip = shell.get_ipython() if shell is not None and hasattr(shell, "get_ipython") else None
    return ip is not None and "IPKernelApp" in getattr(ip, "config", {})


def progress_bar(total: int, desc: str, enabled: bool | None = None, *, unit: str = "pose",
                 warmup: int = 0, warmup_note: str = ""):
    """The one progress bar (tqdm.auto: a widget in a notebook, text at a terminal; a
    context manager): shown when ``enabled``, or when None as :func:`progress_enabled`
    decides; a disabled bar's ``update`` costs nothing. ``warmup``: the first updates pay a
    one-time cost (:class:`_WarmupBar`): no ETA (``warmup_note`` in its place) until they
    are done, then tqdm's ETA from the rate of the updates after them."""
    if not (progress_enabled() if enabled is None else enabled):
        return _NoBar()
    from tqdm.auto import tqdm   # deferred: tqdm, only for a bar that is shown

    if warmup > 0:
        return _WarmupBar(functools.partial(tqdm, desc=desc, unit=unit, leave=False), total,
                          warmup, warmup_note)
    return tqdm(total=total, desc=desc, unit=unit, leave=False)


class _WarmupBar:
    """A tqdm bar whose first ``warmup`` updates are slow for a reason the rest do not share
    (a study's first run on each worker starts the worker): tqdm's rate after the first of
    them overstates the time left many times over (README, "Sizing it"). Until they are
    done the bar shows ``note`` where the ETA goes; then it goes on as a tqdm bar started at
    that count (``initial``), whose rate is that of the updates since."""

    def __init__(self, make: Callable[..., Any], total: int, warmup: int, note: str):
        self._make, self._warmup = make, warmup
        self._format = "{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}<?, " + note + "]"
        self._bar = make(total=total, bar_format=self._format)
        self.warming = True

    @property
    def n(self) -> int:
        return self._bar.n

    @property
    def total(self) -> int:
        return self._bar.total

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def reset(self, total: int | None = None) -> None:
        """Back to 0 (and the warm-up) with ``total``, as tqdm's reset."""
        total = self._bar.total if total is None else total
        self._bar.close()
        self._bar = self._make(total=total, bar_format=self._format)
        self.warming = True

    def update(self, n: int = 1) -> None:
        self._bar.update(n)
        if self.warming and self._bar.n >= self._warmup:
            old = self._bar
            old.close()   # first: an open bar would push the new one a line down
            self._bar = self._make(total=old.total, initial=old.n)
            self._bar.start_t = old.start_t   # elapsed is the whole time, the rate not
            self._bar.refresh()
            self.warming = False

    def close(self) -> None:
        self._bar.close()


class _NoBar:
    """A hidden progress bar: the part of tqdm's interface irring uses, doing nothing."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        pass

    def update(self, n: int = 1) -> None:
        pass

    def reset(self, total: int | None = None) -> None:
        pass

    def close(self) -> None:
        pass


@dataclass
class MapRun:
    """Everything one run produced. ``timings_s`` maps stage → seconds (wall clock)."""

    sweeps: list[Sweep]
    points: list[Points]
    grid: OccupancyGrid
    scenario: Scenario | None = None
    scenario_text: str | None = None     # the YAML the scenario came from (for recordings)
    calibration_text: str | None = None  # the calibration YAML used (None: nominal curve)
    seed: int | None = None
    frames_per_sweep: int = 0            # animation frames per sweep write_outputs draws
    truth: Any = None                    # metrics.GroundTruth when scored
    scores: dict | None = None
    timings_s: dict[str, float] = field(default_factory=dict)
    unscored: str | None = None          # why a replay's recorded scenario could not score it

    @property
    def hardware_time_s(self) -> float:
        """Seconds the real ring would spend on these sweeps."""
        return float(sum(s.duration_s for s in self.sweeps))

    @property
    def compute_time_s(self) -> float:
        return float(sum(self.timings_s.values()))

    @property
    def poses(self) -> list[np.ndarray]:
        return [np.asarray(s.pose, float) for s in self.sweeps]

    @property
    def route(self) -> np.ndarray | None:
        """(K, 2) m: where a moving ring read, step by step over its sweeps (the poses the
        map placed its readings at), or None for sweeps taken standing."""
        at = [np.asarray(s.reading_poses, float)[:, 0, :2] for s in self.sweeps
              if s.reading_poses is not None]
        return np.concatenate(at) if at else None

    def readings(self) -> dict[str, int]:
        """How many readings: total, valid, and per reason (lower-case Reason names)."""
        out = {"total": int(sum(p.valid.size for p in self.points)),
               "valid": int(sum(int(np.count_nonzero(p.valid)) for p in self.points))}
        for reason in Reason:
            n = int(sum(int(np.count_nonzero(p.reason == reason)) for p in self.points))
            if n and reason != Reason.OK:
                out[reason.name.lower()] = n
        return out

    def summary(self) -> dict:
        """The JSON document ``irring run --json`` prints."""
        sc = self.scenario
        clipped = [c.as_json() for c in clipped_obstacles(sc)] if sc else []
        return {
            "scenario": sc.name if sc else None,
            "design": sc.robot.design if sc else None,
            "poses": len(self.sweeps),
            "readings": self.readings(),
            "scores": self.scores,
            "hardware_time_s": self.hardware_time_s,
            "compute_time_s": {**{k: float(v) for k, v in self.timings_s.items()},
                               "total": self.compute_time_s},
            **({"unscored": self.unscored} if self.unscored else {}),
            **({"stuck_sensors": stuck} if (stuck := stuck_sensors(self.sweeps, self.points))
               else {}),
            **({"clipped_obstacles": clipped} if clipped else {}),
            **({"drive": drive_ending(sc)} if sc is not None and sc.has("motion") else {}),
        }

    def _repr_png_(self) -> bytes:
        """The map picture (as map.png, smaller), so a notebook shows a MapRun inline."""
        from .maps import render   # deferred: Pillow, only for a picture

        reach, ring_r = _reach(self) if self.sweeps else (None, 0.15)
        title = _title(self)
        return render.MapPicture(self.grid, self.scenario, self.poses, reach, ring_r, dpi=80,
                                 title=title, route=self.route).png_bytes(self.grid.classify(),
                                                                          title)

    def recording_meta(self) -> dict:
        """What ``irring replay`` needs to rebuild this exact map."""
        return {
            "scenario": self.scenario.name if self.scenario else None,
            "scenario_yaml": self.scenario_text,
            "seed": self.seed,
            "calibration_yaml": self.calibration_text,
            "grid": {"origin_xy_m": self.grid.origin_xy_m.tolist(),
                     "shape": list(self.grid.shape),
                     "resolution_m": self.grid.resolution_m},
            "mapper": dataclasses.asdict(self.grid.params),
        }


def stuck_sensors(sweeps: Sequence[Sweep], points: Sequence[Points]) -> list[str]:
    """A warning for the sensors whose every reading, at two or more poses, is one count that
    the estimator maps as wall: a turning sensor reads the room's changing distances (and its
    noise), so one count all round is a stuck sensor or a dead ADC channel, whose ring of
    wall the map would show (one line for the sensors stuck at one count). Silence all round
    (no return) is not warned of: a sensor that meets no wall within its reach reads so too,
    and maps nothing; 0 counts all round, where another sensor never reads 0, is: a powered
    GP2 never outputs 0 V, a cut wire does, and its beams map free to its reach. Every
    sensor at 0 counts all round is too (one line): an ADC unpowered or without its
    reference reads so, and no sensor model's no-return level is 0 counts at any ADC a
    scenario may have (8 … 16 bits, up to 50 V)."""
    poses = {tuple(np.asarray(s.pose, float).round(6)) for s in sweeps}
    if len(poses) < 2 or len(points) != len(sweeps):
        return []
    counts = np.concatenate([np.asarray(s.counts).reshape(len(s.steps), -1) for s in sweeps])
    valid = np.concatenate([p.valid.reshape(len(s.steps), -1) for s, p in zip(sweeps, points)])
    d = np.concatenate([p.d.reshape(len(s.steps), -1) for s, p in zip(sweeps, points)])
    stuck: dict[int, list[int]] = {}   # count → the sensors stuck at it
    for k in np.flatnonzero((counts == counts[0]).all(axis=0) & valid.any(axis=0)):
        stuck.setdefault(int(counts[0, k]), []).append(int(k))
    out = []
    for count, ks in stuck.items():
        who = (f"sensor {ks[0]}" if len(ks) == 1 else
               f"sensors {', '.join(map(str, ks))}")
        each = "" if len(ks) == 1 else " each"
        out.append(f"{who} (of 0 … {counts.shape[1] - 1}) read {count} counts at every one "
                   f"of {'its' if len(ks) == 1 else 'their'} {len(counts)} readings{each}, at "
                   f"{len(poses)} poses, where a turning sensor's counts follow the room: a "
                   f"stuck sensor or a dead ADC channel reads so. {int(valid[:, ks].sum())} of "
                   f"them are mapped as wall {np.nanmedian(d[:, ks]) * 1000:.0f} mm out all "
                   "round; check " + ("the sensor's connector and its ADC channel" if len(ks) == 1
                                      else "their connectors, ADC channels and the ADC's "
                                      "reference"))
    # 0 V at every reading, where another sensor's silence reads above it: no GP2 outputs
    # 0 V powered (with nothing in range it reads its no-return level), a cut wire does
    live = (counts > 0).all(axis=0)
    if not counts.any():
        out.append(f"every sensor (0 … {counts.shape[1] - 1}) read 0 counts at every one of "
                   f"their {len(counts)} readings each, at {len(poses)} poses, where a powered "
                   "sensor with nothing in range reads its no-return level: an ADC unpowered "
                   "or without its reference reads so. The readings are mapped as no return, "
                   "free to the sensors' reach, walls or not; check the ADC's supply, "
                   "reference and wiring")
    dead = np.flatnonzero((counts == 0).all(axis=0)) if live.any() else []
    if len(dead):
        who = f"sensor {dead[0]}" if len(dead) == 1 else f"sensors {', '.join(map(str, dead))}"
        out.append(f"{who} (of 0 … {counts.shape[1] - 1}) read 0 counts at every one of "
                   f"{'its' if len(dead) == 1 else 'their'} {len(counts)} readings"
                   f"{'' if len(dead) == 1 else ' each'}, at {len(poses)} poses, where a "
                   f"powered sensor with nothing in range reads its no-return level (the "
                   f"others never read below {int(counts[:, live].min())}): a sensor unplugged "
                   "or its wire cut reads so. "
                   f"{'Its' if len(dead) == 1 else 'Their'} readings are mapped as no return, "
                   "free to the sensor's reach, walls or not; check "
                   + ("the sensor's connector and its ADC channel" if len(dead) == 1 else
                      "their connectors and ADC channels"))
    return out


# --------------------------------------------------------------------------- stages


def scenario_text(scenario: Scenario) -> str | None:
    """The YAML a scenario was loaded from, while it still describes it: None for one made
    in code or changed since (``dataclasses.replace`` keeps the text it was loaded with, so
    ``rooms.ideal(sc)`` or another seed would be rebuilt, recorded or shipped as the
    original)."""
    if not scenario.text:
        return None
    try:
        same = loads(scenario.text, scenario.source) == scenario
    except ScenarioError:
        same = False
    return scenario.text if same else None


@dataclass
class Acquisition:
    """What :func:`acquire` got: one sweep per pose swept, in order.

    ``reports[i]`` is the source's account of sweep i when it keeps one (``SerialRing``:
    its :class:`~irring.hardware.SweepReport`), else None. ``error`` is the
    :class:`~irring.core.SourceLost` (or, when interruptible, the KeyboardInterrupt or
    EOFError) that ended the acquisition early (its partial sweep, if any readings arrived,
    is the last of ``sweeps``), None when every pose was swept.
    ``seconds``: wall-clock time spent sweeping.
    """

    sweeps: list[Sweep] = field(default_factory=list)
    reports: list[Any] = field(default_factory=list)
    error: BaseException | None = None
    seconds: float = 0.0

    @property
    def complete(self) -> bool:
        """Every pose swept, with every step's readings."""
        return self.error is None and not any(s.missing_steps for s in self.sweeps)


def acquire(source: RingSource, poses: Iterable, *, steps: np.ndarray | None = None,
            progress: bool | None = None, before: Callable[[int, Any], None] | None = None,
            after: Callable[[int, Sweep, Any], None] | None = None,
            interruptible: bool = False) -> Acquisition:
    """One sweep of ``source`` (a :class:`~irring.core.RingSource`: ``SimRing``,
    ``SerialRing``, …) at each of ``poses``, in order → :class:`Acquisition`.

    ``poses``: what ``source.sweep`` takes — (x m, y m, yaw rad), scenario ``Pose`` s, or a
    simulator's scan-pose indices. ``steps``: motor steps of every sweep (None: the
    source's full sweep). ``before(k, pose)`` is called before sweeping pose k (e.g. to
    wait while a person moves the robot), ``after(k, sweep, report)`` after it.
    A source lost mid-sweep (:class:`~irring.core.SourceLost`) ends the acquisition
    without raising: what arrived is kept and the error is in ``Acquisition.error``.
    ``interruptible``: Ctrl-C (KeyboardInterrupt) or the end of input (EOFError, from
    ``before``) ends it the same way, for a caller that writes what arrived before stopping.
    """
    poses = list(poses)
    out = Acquisition()
    stops = (SourceLost, KeyboardInterrupt, EOFError) if interruptible else SourceLost
    t0 = time.perf_counter()
    with progress_bar(len(poses), "sweep", progress) as bar:
        for k, pose in enumerate(poses):
            try:
                if before is not None:
                    before(k, pose)
                sweep = source.sweep(pose, steps=steps)
            except stops as exc:
                out.error = exc
                partial = getattr(exc, "partial", None)   # a source's SourceLost carries it
                if partial is not None and len(partial.steps):
                    out.sweeps.append(partial)
                    out.reports.append(getattr(exc, "report", None))
                break
            report = getattr(source, "last_report", None)
            out.sweeps.append(sweep)
            out.reports.append(report)
            if after is not None:
                after(k, sweep, report)
            bar.update()
    out.seconds = time.perf_counter() - t0
    return out


def simulated(scenario: Scenario, *, seed: int | None = None, progress: bool | None = None
              ) -> tuple[Acquisition, float]:
    """Every sweep the scene takes (one per scan pose; with ``motion`` back to back along
    its drive), acquired from a new ``SimRing``: (acquisition, seconds building the MuJoCo
    model)."""
    from .simulation.sim import SimRing   # deferred: MuJoCo; replay and drive simulate nothing

    t0 = time.perf_counter()
    with SimRing(scenario, seed=seed) as sim:
        build_s = time.perf_counter() - t0
        return acquire(sim, range(sim.n_sweeps), progress=progress), build_s


def check_pose_spread(poses_xy, reach_m: float, where: str, resolution_m: float = 0.010,
                      margin_m: float = 0.10) -> None:
    """Refuse (TooBig, before any sweep) poses so far apart that :func:`grid_for_points`
    around them and ``reach_m`` beyond each (ring radius + what a sensor may read) could
    not be mapped together."""
    xy = np.asarray(poses_xy, dtype=float).reshape(-1, 2)
    lo, hi = xy.min(axis=0) - reach_m - margin_m, xy.max(axis=0) + reach_m + margin_m
    w, h = xy.max(axis=0) - xy.min(axis=0)
    check_covering(lo, hi, resolution_m, where,
                   f"poses {w:.0f} m × {h:.0f} m apart are too far apart to map together; "
                   f"map each part on its own")


def grid_for_points(points: Sequence[Points], resolution_m: float = 0.010,
                    margin_m: float = 0.10, params: MapperParams | None = None) -> OccupancyGrid:
    """A grid around every emitter and end point, ``margin_m`` beyond them (for sweeps
    without a scenario; laid out as :meth:`OccupancyGrid.covering` lays out every grid)."""
    xs, ys = [], []
    for p in points:
        reach = np.where(p.valid, 0.0, p.max_range_m)
        for x, y in ((p.origin_x, p.origin_y), (p.x, p.y),
                     (p.origin_x + reach * np.cos(p.heading), p.origin_y + reach * np.sin(p.heading))):
            xs.append(np.asarray(x, float).ravel())
            ys.append(np.asarray(y, float).ravel())
    x = np.concatenate(xs)
    y = np.concatenate(ys)
    lo = np.array([np.nanmin(x), np.nanmin(y)]) - margin_m
    hi = np.array([np.nanmax(x), np.nanmax(y)]) + margin_m
    w, h = hi - lo
    check_covering(lo, hi, resolution_m, "the sweeps' poses and readings",
                   f"they span {w:.0f} m × {h:.0f} m, too far to map together; map each "
                   f"part on its own")
    return OccupancyGrid.covering(lo, hi, resolution_m, params)


def mapper_params(calibration, sweeps: Sequence[Sweep] = ()) -> MapperParams:
    """The mapper's numbers for ``sweeps`` read with ``calibration``: the defaults, but for a
    θ-free calibration (:attr:`Calibration.theta_free`: it returns at any incidence) silent
    beams stop only at cells holding an end point (``stop_at_end_cells``) and, where no
    sweep was read moving (``reading_poses``), clear as a valid beam does (``l_no_return``
    = ``l_free``). Why: docs/mapping.md, "Where the ideal sensor still maps worse"."""
    if calibration is None or not calibration.theta_free:
        return MapperParams()
    if any(sweep.reading_poses is not None for sweep in sweeps):
        return MapperParams(stop_at_end_cells=1.0)
    return MapperParams(stop_at_end_cells=1.0, l_no_return=MapperParams().l_free)


def map_sweeps(sweeps: Sequence[Sweep], *, scenario: Scenario | None = None,
               grid: OccupancyGrid | None = None, params: MapperParams | None = None,
               calibration=None, frames_per_sweep: int = 0, score: bool = True,
               progress: bool | None = None, estimator: Callable | None = None,
               truth=None) -> MapRun:
    """Estimate and map recorded or live sweeps, in order; score against the scenario if any.
    A sweep :func:`irring.recording.check_sweep` refuses raises ValueError naming it.

    ``grid`` defaults to the scenario's (or, without one, a grid around the points), with
    the mapper ``params`` (a given grid has its own; none: :func:`mapper_params`).
    ``frames_per_sweep > 0`` asks :func:`write_outputs` for an animation with that many
    frames per sweep (:func:`building_frames` replays the inserts; no frame is kept).
    ``truth``: a ``metrics.GroundTruth`` of this scenario on this grid's cells, to reuse
    across many runs (rasterising it costs more than mapping).
    """
    if isinstance(sweeps, Sweep):
        raise TypeError("sweeps: expected a list of Sweep, got one Sweep (write [sweep])")
    if not len(sweeps) and grid is None and scenario is None:
        raise ValueError("sweeps: none to map, and no scenario or grid to lay the map out by")
    if calibration is not None and not isinstance(calibration, Calibration):
        # a path here failed inside the estimator ('str' object has no attribute 'folds')
        raise TypeError(f"calibration: expected a Calibration (Calibration.load(path)) or "
                        f"None, got {type(calibration).__name__} {calibration!r:.80}")
    for i, sweep in enumerate(sweeps):   # before any work: what a replay would refuse
        rec.check_sweep(sweep, f"sweeps[{i}]")
    # rows listed out of step order mapped differently (a reading's neighbours are rows)
    sweeps = [in_turn_order(sweep) for sweep in sweeps]
    estimator = estimate if estimator is None else estimator
    timings = {"estimate": 0.0, "map": 0.0}
    points: list[Points] = []
    if params is None and grid is None:
        params = mapper_params(calibration, sweeps)
    if grid is None and scenario is not None:
        grid = OccupancyGrid.for_scenario(scenario, params)
    with progress_bar(len(sweeps), "estimate + map", progress) as bar:
        for sweep in sweeps:
            t0 = time.perf_counter()
            points.append(with_motion_sigma(with_cone(estimator(sweep, calibration), sweep),
                                            sweep))
            timings["estimate"] += time.perf_counter() - t0
            bar.update()
    t0 = time.perf_counter()
    if grid is None:
        grid = grid_for_points(points, params=params)
    grid.insert_run(points)
    timings["map"] = time.perf_counter() - t0
    run = MapRun(sweeps=list(sweeps), points=points, grid=grid, scenario=scenario,
                 frames_per_sweep=int(frames_per_sweep), timings_s=timings)
    if score and scenario is not None:
        t0 = time.perf_counter()
        judged = swept_scenario(scenario, sweeps)
        if truth is None:
            with progress_bar(0, "score", progress, unit="cell") as bar:
                truth = metrics.ground_truth(judged, grid, bar)
        run.truth = truth
        run.scores = metrics.score(grid, judged, run.truth)
        run.timings_s["score"] = time.perf_counter() - t0
    return run


def swept_scenario(scenario: Scenario, sweeps: Sequence[Sweep]) -> Scenario:
    """``scenario`` with the scan poses its standing ring was swept at (``irring run``'s are
    its own): a drive given fewer --poses, other --pose or stopped half-way is judged on the
    wall it could see, not on what the poses never swept would have seen. A moving scene is
    judged on its drive (``metrics.views``)."""
    if scenario.has("motion"):
        return scenario
    swept = np.array([np.asarray(sweep.pose, dtype=float)[:3] for sweep in sweeps])
    listed = np.array([(p.x_m, p.y_m, p.yaw_rad) for p in scenario.robot.poses])
    if swept.shape == listed.shape and np.array_equal(swept, listed):
        return scenario
    poses = tuple(Pose(*(float(v) for v in pose)) for pose in swept)
    return dataclasses.replace(scenario, robot=dataclasses.replace(scenario.robot, poses=poses))


def with_cone(points: Points, sweep: Sweep) -> Points:
    """The points of a sweep whose sensor hears an echo anywhere in a cone (the sonar's)
    marked with that cone, so the mapper draws arcs (mapping.cone_fan)."""
    spec = SENSORS.get(sweep.sensor_model)
    half = spec.beam_half_angle_rad if spec is not None else 0.0
    return dataclasses.replace(points, cone_half_angle_rad=half) if half > 0 else points


def with_motion_sigma(points: Points, sweep: Sweep) -> Points:
    """A moving robot's readings (``sweep.reading_poses``) with σ widened by how far their
    beam moves in one GP2 period: hypot(σ, (d·|ω| + |v|)·GP2_PERIOD_S), the turn rate ω and
    speed v of the poses between the sweep's steps (``timestamps_s``; a row's rate is the mean
    of the steps on either side). A reading carries the pose at its read, but was measured
    up to a period before it (docs/mapping.md, "Where the ideal sensor still maps worse").
    A still robot's points, and a cone sensor's (a sonar's period is not the GP2's), are
    returned as they are."""
    poses = sweep.reading_poses
    t = np.asarray(sweep.timestamps_s, dtype=float)
    if poses is None or t.size < 2 or points.cone_half_angle_rad > 0:
        return points
    step = np.diff(np.asarray(poses, dtype=float), axis=0)          # (S − 1, N, 3)
    turn = np.abs((step[..., 2] + math.pi) % (2 * math.pi) - math.pi)
    dt = np.abs(np.diff(t))[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        # the pose's change per second between steps: turn (rad/s, times d for the beam's
        # end point) and travel (m/s)
        rate_d = turn / dt
        rate_v = np.hypot(step[..., 0], step[..., 1]) / dt
    rows_d = np.empty(points.valid.shape)
    rows_v = np.empty(points.valid.shape)
    for rows, rate in ((rows_d, rate_d), (rows_v, rate_v)):
        rows[0], rows[-1] = rate[0], rate[-1]
        rows[1:-1] = 0.5 * (rate[:-1] + rate[1:])
    moved = (points.d * rows_d + rows_v) * GP2_PERIOD_S
    sigma = np.where(points.valid & np.isfinite(moved), np.hypot(points.sigma_m, moved),
                     points.sigma_m)
    return points_with(points, sigma_m=sigma)


MAX_FRAMES = 400  # a longer animation is thinned (fewer parts per sweep, then fewer sweeps)


def frame_plan(n_sweeps: int, frames_per_sweep: int) -> tuple[int, int, int]:
    """(parts per sweep, sweep stride, frames): every ``stride``-th sweep (and the last) is
    shown in ``parts`` frames, so a long run's animation stays within :data:`MAX_FRAMES`."""
    parts = max(1, int(frames_per_sweep))
    if 1 + n_sweeps * parts > MAX_FRAMES:
        parts = 1
    stride = max(1, math.ceil(n_sweeps / (MAX_FRAMES - 2)))
    shown = len(range(stride - 1, n_sweeps - 1, stride)) + (n_sweeps > 0)
    return parts, stride, 1 + shown * parts


def building_frames(result: MapRun, frames_per_sweep: int | None = None
                    ) -> Iterator[tuple[np.ndarray, int, str]]:
    """The map being built, frame by frame, as (cell classes (ny, nx) int8, poses scanned
    so far, caption): the sweeps' points inserted again into an empty grid like the
    result's, so no frame is held; the last frame is the result's map. A sweep shown in
    p parts first shows the beams of its first 1/p, 2/p, … of steps (clamped like an insert),
    then the map after its insert. :func:`frame_plan` says how many frames come."""
    n = len(result.points)
    parts, stride, _ = frame_plan(n, result.frames_per_sweep if frames_per_sweep is None
                                  else frames_per_sweep)
    returns = result.grid.empty_like()     # every return so far (OccupancyGrid.insert_run)
    silences = RunSilences(returns, result.points)   # and the silent beams over them
    grid = returns.empty_like()
    # each sweep's readings where the whole run's map places them (its last frame is the map)
    placed = returns.placed_readings(result.points)
    yield grid.classify(), 0, "before the first sweep"
    for k, p in enumerate(result.points):
        shown = (k + 1) % stride == 0 or k == n - 1
        if shown and parts > 1:
            rows = p.valid.shape[0]
            edges = np.linspace(0, rows, parts + 1).round().astype(int)
            acc = np.zeros(grid.shape)
            for j in range(1, parts):
                acc += grid.delta(slice_steps(p, slice(edges[j - 1], edges[j])))
                lo = np.clip(grid.log_odds + acc, grid.params.l_min, grid.params.l_max)
                yield classify(lo), k + 1, f"pose {k + 1} of {n}: sweeping ({j}/{parts})"
        returns.insert(returns_of(placed[k]), placed=True)
        if shown:    # the map of the run so far: its silent beams against all its returns
            grid = OccupancyGrid(returns.origin_xy_m, returns.shape, returns.resolution_m,
                                 returns.params)
            grid.log_odds = silences.log_odds(returns, k + 1)
            yield grid.classify(), k + 1, f"pose {k + 1} of {n}: done"


def _sensor(model: str, adc_bits: int, vref_v: float) -> str:
    return f"a {model} with a {adc_bits}-bit ADC at {vref_v:g} V"


def check_calibration(calibration, model: str, adc_bits: int, vref_v: float, where: str,
                      what: str, recorded: bool = False) -> None:
    """Raise CalibrationError (naming ``where``, the calibration's file) unless
    ``calibration`` (None: nothing to check) is for this sensor model, ADC bits and reference
    voltage: its a(θ), b(θ) are in that converter's counts, so counts of another converter
    or sensor read as silently wrong distances. ``what`` names the readings; ``recorded``:
    the calibration is a recording's own, which only --calibration replaces."""
    if calibration is None:
        return
    if (calibration.sensor_model, calibration.adc_bits) != (model, adc_bits) or not \
            math.isclose(calibration.vref_v, vref_v, rel_tol=1e-9):
        raise CalibrationError(
            f"{where}: the calibration is for "
            f"{_sensor(calibration.sensor_model, calibration.adc_bits, calibration.vref_v)}, "
            f"but {what} {_sensor(model, adc_bits, vref_v)}; "
            + ("replay it with --calibration FILE, a calibration of that sensor (irring "
               "calibrate)" if recorded else "use a calibration of that sensor (irring "
               "calibrate) or leave --calibration out"))


def run(scenario: Scenario, *, seed: int | None = None, calibration_file: str | Path | None = None,
        frames_per_sweep: int = 0, score: bool = True, progress: bool | None = None,
        params: MapperParams | None = None, estimator: Callable | None = None) -> MapRun:
    """Simulate every pose of ``scenario``, estimate, map and score (``estimator``: as
    :func:`map_sweeps` takes it), with the calibration in ``calibration_file`` or else the
    scene's (:func:`scene_calibration`)."""
    check_scenario_grid(scenario)   # refuse a grid too big for memory before the work
    calibration, cal_text = (load_calibration(calibration_file) if calibration_file is not None
                             else scene_calibration(scenario))
    sensor = scenario.sensor
    check_calibration(calibration, sensor.model, sensor.adc_bits, sensor.vref_v,
                      str(calibration_file), f"{scenario.name} reads")
    acq, build_s = simulated(scenario, seed=seed, progress=progress)
    result = map_sweeps(acq.sweeps, scenario=scenario, params=params, calibration=calibration,
                        frames_per_sweep=frames_per_sweep, score=score, progress=progress,
                        estimator=estimator)
    result.timings_s = {"simulate": build_s + acq.seconds, **result.timings_s}
    result.scenario_text = scenario_text(scenario)
    result.calibration_text = cal_text
    result.seed = scenario.seed if seed is None else int(seed)
    return result


def _check_room_holds_poses(scenario: Scenario, sweeps: Sequence[Sweep], recording) -> None:
    """A recorded scenario whose room does not hold the sweeps' poses is another room's:
    scored against it, the map would be judged on walls the ring never stood among. Every
    pose of a standing scene lies in its room; a moving one's believed poses may drift
    (odometry) past a wall, so there only a room holding none is refused."""
    xy = np.array([np.asarray(sweep.pose, dtype=float)[:2] for sweep in sweeps])
    inside = inside_outline(xy[:, 0], xy[:, 1], scenario.room.outline_m)
    moving = scenario.has("motion")
    if inside.all() or (moving and inside.any()):
        return
    k = int(np.argmin(inside))
    raise rec.RecordingError(
        f"{recording}: sweep {k + 1}'s pose ({xy[k, 0]:g}, {xy[k, 1]:g}) m lies outside the "
        f"room of the recorded scenario {scenario.name!r}"
        f"{', as do all the others' if moving else ''}; the scenario and the sweeps do not "
        "belong together")


def _check_recorded_grid(scenario: Scenario, grid: dict | None, recording) -> None:
    """A recorded grid is the one its scenario laid out (run and drive map on
    OccupancyGrid.for_scenario): one of other cells maps at another resolution than the
    scenario says, and one that leaves out part of the room drops the readings there and
    scores the rest as if it were the room."""
    if grid is None:
        return
    res = grid["resolution_m"]
    if not math.isclose(res, scenario.map.resolution_m, rel_tol=1e-9):
        raise rec.RecordingError(
            f"{recording}: meta.grid has cells of {res * 1e3:g} mm, but the recorded scenario "
            f"{scenario.name!r} maps in cells of {scenario.map.resolution_m * 1e3:g} mm "
            "(map.resolution_mm); the grid and the scenario do not belong together")
    lo = np.asarray(grid["origin_xy_m"], dtype=float)
    hi = lo + res * np.asarray(grid["shape"][::-1], dtype=float)   # shape is rows, columns
    outline = np.asarray(scenario.room.outline_m, dtype=float)
    room_lo, room_hi = outline.min(axis=0), outline.max(axis=0)
    if np.all(lo <= room_lo) and np.all(room_hi <= hi):
        return
    raise rec.RecordingError(
        f"{recording}: meta.grid (x {lo[0]:g} … {hi[0]:g} m, y {lo[1]:g} … {hi[1]:g} m) "
        f"leaves out part of the room of the recorded scenario {scenario.name!r} (x "
        f"{room_lo[0]:g} … {room_hi[0]:g} m, y {room_lo[1]:g} … {room_hi[1]:g} m): the "
        "readings there would be dropped and the rest scored as the room; the grid and the "
        "scenario do not belong together")


def _check_scenario_sensor(scenario: Scenario, sweeps: Sequence[Sweep], recording) -> None:
    """A recorded scenario whose sensor is not the one its sweeps were read with (run and
    drive record both from one source) scores the map with another sensor's reach."""
    for k, sweep in enumerate(sweeps):
        if (sweep.sensor_model, sweep.vref_v) != (scenario.sensor.model,
                                                  scenario.sensor.vref_v):
            raise rec.RecordingError(
                f"{recording}: sweep {k + 1} was read by a {sweep.sensor_model} at "
                f"{sweep.vref_v:g} V, but the recorded scenario {scenario.name!r} says its ring "
                f"reads a {scenario.sensor.model} at {scenario.sensor.vref_v:g} V; the "
                "scenario and the sweeps do not belong together")


def _check_one_ring(sweeps: Sequence[Sweep], recording) -> None:
    """The sweeps of a recording are one ring's (irring run records one scene, irring drive
    one handshake's IRINF): a sweep of another ring was pieced in or edited, and one of 11
    sensors among 12's ended the replay in an internal error after its outputs were written
    (the stuck-sensor check stacks every sweep's readings)."""
    first = sweeps[0].ring
    for k, sweep in enumerate(sweeps[1:], start=2):
        for f in dataclasses.fields(first):
            have, want = getattr(sweep.ring, f.name), getattr(first, f.name)
            if have != want:
                raise rec.RecordingError(
                    f"{recording}: sweep {k}'s ring has {f.name} {have:g}, sweep 1's {want:g}; "
                    "the sweeps of one recording are one ring's (irring run and irring drive "
                    "record one), so these were edited or pieced together")


def _check_simulated_sweeps(scenario: Scenario, sweeps: Sequence[Sweep], recording) -> None:
    """A simulated sweep whose ring is not the recorded scenario's, which simulated it, or
    that carries a pose per reading where the scene stands still (or none where it drives:
    effects.motion) was edited: its end points would be placed by another ring's geometry,
    or from other poses. (A device's ring is its IRINF's, which may differ from the scene's:
    irring drive warned of it then.)"""
    ring, moving = scenario.ring, scenario.has("motion")
    for k, sweep in enumerate(sweeps):
        if sweep.source != "sim":
            continue
        if (sweep.reading_poses is not None) != moving:
            has = ("carries a pose for each reading (a moving robot's)" if not moving else
                   "carries no pose for each reading")
            does = ("stands still at each of its poses" if not moving else
                    "drives while it sweeps (effects.motion)")
            raise rec.RecordingError(
                f"{recording}: sweep {k + 1} {has}, but the recorded scenario "
                f"{scenario.name!r}, which simulated it, {does}; the scenario and the sweeps "
                "do not belong together")
        for f in dataclasses.fields(ring):
            have, want = getattr(sweep.ring, f.name), getattr(ring, f.name)
            if have != want and not math.isclose(have, want, rel_tol=1e-9, abs_tol=1e-12):
                raise rec.RecordingError(
                    f"{recording}: sweep {k + 1} was simulated with ring.{f.name} {have:g}, but "
                    f"the recorded scenario {scenario.name!r}, which simulated it, has "
                    f"{want:g}; the scenario and the sweeps do not belong together")


def _check_commanded_angles(sweeps: Sequence[Sweep], recording) -> None:
    """irring's simulator and driver record each row's sensor angles as its step commands
    them (step × motor step × belt ratio, every sensor alike, even of a belt that lags):
    their sweeps' angles that contradict their steps were edited, and would map each reading
    at another bearing than it was read at. (A source of another program, or a sweep made by
    hand without the simulator's truth, may hold other angles.)"""
    for k, sweep in enumerate(sweeps):
        if not (sweep.source == "sim" and sweep.truth is not None
                or sweep.source.startswith("serial:")):
            continue
        steps, angles = np.asarray(sweep.steps), np.asarray(sweep.sensor_angles, dtype=float)
        want = sensor_angles_for_steps(sweep.ring, steps)
        off = np.abs(angles - want) > ANGLE_TOLERANCE_RAD * (1 + np.abs(want))
        if off.any():
            s, n = (int(i) for i in np.argwhere(off)[0])
            raise rec.RecordingError(
                f"{recording}: sweep {k + 1}'s sensor {n} at step {int(steps[s])} is at "
                f"{angles[s, n]:.6g} rad, where its ring turns step {int(steps[s])} to "
                f"{want[s, n]:.6g} rad (step × motor step × belt ratio, every sensor alike, as "
                f"irring's simulator and driver record it); the angles and the steps do not "
                f"belong together")


def _check_no_copied_sweep(scenario: Scenario | None, sweeps: Sequence[Sweep],
                           recording) -> None:
    """A sweep equal to an earlier one in pose, steps, counts and timestamps is a copy (a
    recording saved with its sweeps twice over): mapped, its readings would count twice as
    evidence. Only a noiseless standing scene that lists one pose twice sweeps it twice
    alike, so there the recorded scenario's own poses vouch for it."""
    def arrays(sweep: Sweep) -> tuple:
        return (sweep.pose, sweep.steps, sweep.counts, sweep.timestamps_s, sweep.reading_poses)

    def key(sweep: Sweep) -> bytes:   # a digest: the recording is not held twice over
        digest = hashlib.sha256()
        for a in arrays(sweep):
            a = np.asarray(a if a is not None else ())
            digest.update(repr((a.shape, a.dtype.str)).encode() + a.tobytes())
        return digest.digest()

    listed = ([] if scenario is None or scenario.has("motion") else
              [(p.x_m, p.y_m, p.yaw_rad) for p in scenario.robot.poses])
    first: dict[bytes, int] = {}
    for k, sweep in enumerate(sweeps):
        i = first.setdefault(key(sweep), k)
        if i == k or not all(np.array_equal(a, b) for a, b in zip(arrays(sweeps[i]),
                                                                  arrays(sweep))) \
                or (len(listed) == len(sweeps) and listed[i] == listed[k]):
            continue
        told = ("" if scenario is None else
                f"; the recorded scenario {scenario.name!r} does not list that pose twice")
        raise rec.RecordingError(
            f"{recording}: sweep {k + 1} repeats sweep {i + 1} reading for reading (its pose, "
            f"steps, {np.asarray(sweep.counts).size} counts and timestamps): a copy, whose "
            f"readings would be mapped twice{told}. Remove the copy")
    _check_no_moved_copy(scenario, sweeps, recording)


def _check_no_moved_copy(scenario: Scenario | None, sweeps: Sequence[Sweep],
                         recording) -> None:
    """A simulated sweep whose counts repeat an earlier one's, in a scene whose noise moves
    every reading by a count or more, is a copy whatever pose it was given: the simulator
    draws new noise for every reading (two sweeps that see nothing differ in nearly all), so
    only a copy moved to another pose reads alike; mapped, it would draw the earlier pose's
    walls at this one."""
    noise = None if scenario is None else scenario.effects.get("noise")
    if noise is None:
        return
    step_v = scenario.sensor.vref_v / (1 << scenario.sensor.adc_bits)
    if noise.sigma_v < step_v:   # less than a count: quantisation may hide it
        return
    first: dict[bytes, int] = {}
    for k, sweep in enumerate(sweeps):
        if sweep.source != "sim":
            continue   # a device's counts: a replaying one is refused by the driver
        counts = np.ascontiguousarray(sweep.counts)
        key = hashlib.sha256(np.asarray(sweep.steps).tobytes() + counts.tobytes()).digest()
        i = first.setdefault(key, k)
        if i == k or not (np.array_equal(sweeps[i].steps, sweep.steps)
                          and np.array_equal(sweeps[i].counts, counts)):
            continue
        xy = [np.asarray(sweeps[j].pose, float)[:2] for j in (i, k)]
        if (counts == counts.flat[0]).all():   # not a copy: nothing simulated reads so
            raise rec.RecordingError(
                f"{recording}: sweeps {i + 1} and {k + 1} read {counts.flat[0]:g} counts at "
                f"every one of their {counts.size} readings each; the recorded scenario "
                f"{scenario.name!r} adds noise of {noise.sigma_v / step_v:.0f} counts (σ "
                f"{noise.sigma_v:g} V) to every reading, so no sweep it simulates reads one "
                "count all round: the recording was edited or damaged")
        raise rec.RecordingError(
            f"{recording}: sweep {k + 1} (at ({xy[1][0]:g}, {xy[1][1]:g}) m) repeats sweep "
            f"{i + 1}'s (at ({xy[0][0]:g}, {xy[0][1]:g}) m) {counts.size} counts reading for "
            f"reading; the recorded scenario {scenario.name!r} adds noise of "
            f"{noise.sigma_v / step_v:.0f} counts (σ {noise.sigma_v:g} V) to every reading, so "
            "no two of its sweeps read alike: a copy, whose readings would be mapped twice. "
            "Remove the copy")


def replay(recording: str | Path, *, calibration_file: str | Path | None = None,
           frames_per_sweep: int = 0, score: bool = True,
           progress: bool | None = None) -> MapRun:
    """Map a recording's sweeps again, on the recorded grid, with the recorded calibration
    (or ``calibration_file``); scored when the recording carries its scenario."""
    t0 = time.perf_counter()
    sweeps, meta = rec.load_recording(recording)
    t_load = time.perf_counter() - t0
    if not sweeps:
        raise rec.RecordingError(f"{recording}: holds no sweeps")
    scenario, unscored = None, None
    if meta.get("scenario_yaml"):
        try:
            scenario = loads(meta["scenario_yaml"], source=f"{recording} (recorded scenario)")
        except ScenarioError as exc:
            # (from another irring version, say): it only scores the map, unless the
            # recording left the calibration to its scene
            if calibration_file is None and not meta.get("calibration_yaml"):
                raise
            unscored = str(exc)
    _check_one_ring(sweeps, recording)
    if scenario is not None:
        _check_room_holds_poses(scenario, sweeps, recording)
        _check_recorded_grid(scenario, meta.get("grid"), recording)
        _check_scenario_sensor(scenario, sweeps, recording)
        _check_simulated_sweeps(scenario, sweeps, recording)
    _check_commanded_angles(sweeps, recording)
    _check_no_copied_sweep(scenario, sweeps, recording)
    if calibration_file is not None:
        calibration, cal_text = load_calibration(calibration_file)
    elif meta.get("calibration_yaml") or scenario is None:
        calibration, cal_text = load_calibration(meta.get("calibration_yaml"), is_text=True,
                                                 source=f"{recording} (recorded calibration)")
    else:  # a simulated recording from before runs recorded the scene's calibration
        calibration, cal_text = scene_calibration(scenario)
    for k, sweep in enumerate(sweeps):
        check_calibration(calibration, sweep.sensor_model, sweep.adc_bits, sweep.vref_v,
                          str(calibration_file or f"{recording} (recorded calibration)"),
                          f"sweep {k + 1} was read by", recorded=calibration_file is None)
    grid = None
    params = MapperParams(**meta["mapper"]) if meta.get("mapper") else None
    if meta.get("grid"):
        g = meta["grid"]
        grid = OccupancyGrid(g["origin_xy_m"], g["shape"], g["resolution_m"], params)
    result = map_sweeps(sweeps, scenario=scenario, grid=grid, params=params,
                        calibration=calibration, frames_per_sweep=frames_per_sweep,
                        score=score, progress=progress)
    result.timings_s = {"load": t_load, **result.timings_s}
    result.unscored = unscored
    result.scenario_text = meta.get("scenario_yaml")
    result.calibration_text = cal_text
    result.seed = meta.get("seed")
    return result


# --------------------------------------------------------------------------- outputs


OUTPUT_NAMES = {"map_png": "map.png", "animation": "map_building.gif", "pgm": "map.pgm",
                "yaml": "map.yaml", "recording": "sweeps.npz"}


def write_outputs(result: MapRun, out_dir: str | Path, *, animation: bool = True,
                  recording: bool = True, title: str | None = None,
                  extra_files: dict[str, tuple[str, str]] | None = None,
                  mcap: str | Path | None = None) -> dict[str, Path]:
    """Write the map PNG, the building animation (if the run asked for frames), the
    map_server PGM + YAML, the sweeps recording and ``extra_files`` ({key: (file name,
    text)}) into ``out_dir``, all together (:class:`irring.outputs.OutputSet`: an
    interrupted or failed write leaves the folder as it was); time it as the "render"
    stage. ``mcap``: also write the run there as MCAP (``mcap_export``; the "mcap" stage),
    which needs the ``mcap`` extra: written first beside its place and renamed in just
    after the set, so an interruption leaves both as they were; an MCAP that fails (an
    OutputError) still leaves the set written, then raises, naming it."""
    importlib.import_module(".maps.render", __package__)  # deferred: Pillow, loaded before the clock

    def write_set() -> dict[str, Path]:
        t0 = time.perf_counter()
        target = OutputSet(out_dir)
        with target as tmp:
            paths = _write_into(result, tmp, animation=animation, recording=recording,
                                title=title)
            for key, (name, text) in (extra_files or {}).items():
                paths[key] = tmp / name
                paths[key].write_text(text, encoding="utf-8")
        result.timings_s["render"] = time.perf_counter() - t0
        return {key: target.out / Path(p).name for key, p in paths.items()}

    if mcap is None:
        return write_set()
    mcap, written = Path(mcap), False
    try:
        # Ctrl-C in the 0.16 s the MCAP took after the set (t_room_moving) left the new set
        # beside an earlier run's MCAP
        with atomic_file(mcap, writes=MCAP_FILE) as tmp:
            t0 = time.perf_counter()
            write_mcap_to(result, tmp, mcap)
            result.timings_s["mcap"] = time.perf_counter() - t0
            written = True
            paths = write_set()
    except OutputError as exc:
        if written:
            raise
        paths = write_set()   # the run's own files are not lost for the MCAP, and it says so
        names = ", ".join(Path(p).name for p in paths.values())
        raise OutputError(f"{exc}; the run's other outputs were written: "
                          f"{printable(str(Path(out_dir)))}/: {names}") from None
    return {**paths, "mcap": mcap}


def _write_into(result: MapRun, out: Path, *, animation: bool, recording: bool,
                title: str | None) -> dict[str, Path]:
    from .maps import render   # deferred: Pillow, only for the pictures

    sc = result.scenario
    reach, ring_r = _reach(result)
    poses = result.poses
    if title is None:
        title = _title(result)
    paths: dict[str, Path] = {}
    png = out / OUTPUT_NAMES["map_png"]
    if animation and result.frames_per_sweep and result.points:
        n_frames = frame_plan(len(result.points), result.frames_per_sweep)[2]
        gif = render.save_animation(out / OUTPUT_NAMES["animation"], result.grid,
                                    building_frames(result), n_frames, sc, poses, reach,
                                    ring_r, png_path=png, title=title, route=result.route)
        paths["map_png"], paths["animation"] = png, gif
    else:
        paths["map_png"] = render.save_map_png(png, result.grid, sc, poses, reach, ring_r, title,
                                               route=result.route)
    paths["pgm"], paths["yaml"] = result.grid.to_pgm(out / OUTPUT_NAMES["pgm"])
    if recording:
        paths["recording"] = rec.save_recording(out / OUTPUT_NAMES["recording"], result.sweeps,
                                                result.recording_meta())
    return paths


def drive_ending(scenario: Scenario) -> dict:
    """How a moving scene's drive went against its sweeps (``dynamics.Drive.ending``) and
    ``note``: what became of the path's end, in a sentence, or None when the last sweep
    ended as the robot arrived."""
    from .simulation.dynamics import Drive   # deferred: MuJoCo

    end = Drive.of(scenario).ending()
    cut, note = end["cut"], None
    if cut is not None:
        n = cut["steps_standing"]
        which = (f"last {n} of {cut['steps']} steps were" if n > 1
                 else f"last step (of {cut['steps']}) was")
        note = (f"the robot reached the path's end during sweep {cut['sweep']}: its {which} "
                f"read standing there (kept)")
    elif end["unswept_m"] >= UNSWEPT_NOTE_M:
        note = (f"the path's last {end['unswept_m'] * 1000:.0f} mm were driven after the "
                f"last sweep (during its rewind); no sweep starts once the robot has "
                f"arrived, so nothing was read there")
    return {**end, "note": note}


UNSWEPT_NOTE_M = 0.0005   # a path's unswept end worth a note (shorter is rounding)


def _reach(result: MapRun) -> tuple[float, float]:
    ring = result.sweeps[0].ring
    max_range = (result.scenario.sensor.max_range_m if result.scenario
                 else result.sweeps[0].max_range_m)
    return max_range + ring.radius_m, ring.radius_m


def _title(result: MapRun) -> str:
    name = result.scenario.name if result.scenario else "recorded sweeps"
    s = result.scores
    if not s:
        return f"{name}: {len(result.sweeps)} sweep(s)"
    f = score_text
    return (f"{name}: occupied F1 {f(s['occupied_f1'])}, free accuracy {f(s['free_accuracy'])}, "
            f"coverage {f(s['coverage'])}, shadow {f(s['shadow'])}")
