"""The seam between the sources (simulator, serial ring) and the consumers (estimator, mapper).

A :class:`Sweep` is what one sweep of the ring produced; the estimator turns it into
:class:`Points`. Neither knows whether the readings came from MuJoCo or a serial port.
Arrays are shaped ``(steps, sensors)``; units are SI.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from .scenario import GP2_PERIOD_S, Ring  # the period lives with the schema's timing default


def hardware_duration_s(n_steps: int, settle_s: float, samples: int,
                        period_s: float = GP2_PERIOD_S) -> float:
    """Seconds the real ring spends on a sweep: steps × (settle + samples × period)."""
    return float(n_steps) * (settle_s + samples * period_s)


@dataclass(frozen=True)
class Truth:
    """Ground truth of a simulated sweep, per reading (absent for hardware)."""

    distance_m: np.ndarray   # (S, N) from the emitter; NaN: nothing within max range
    incidence_rad: np.ndarray  # (S, N) between ray and surface normal; NaN where no hit
    hit_point: np.ndarray    # (S, N, 3) world; NaN where no hit
    origin: np.ndarray       # (S, N, 3) emitter position, world
    direction: np.ndarray    # (S, N, 3) unit beam direction, world
    geom_id: np.ndarray      # (S, N) int, −1 where no hit
    reflectance: np.ndarray  # (S, N) of the surface hit; NaN where no hit


@dataclass(frozen=True)
class Sweep:
    """One sweep of the ring: ADC counts and where the sensors pointed.

    ``sensor_angles[s, k]`` is sensor k's angle (rad, CCW from above) off its radial
    direction at step ``steps[s]``. ``pose`` is the robot pose (x m, y m, yaw rad) of the
    sweep; ``reading_poses`` (S, N, 3) is set only when the robot moved during it.
    """

    steps: np.ndarray            # (S,) motor step indices
    sensor_angles: np.ndarray    # (S, N) rad
    counts: np.ndarray           # (S, N) ADC counts (float unless quantised)
    timestamps_s: np.ndarray     # (S,) when each step was read (device clock for hardware)
    duration_s: float            # hardware time of the sweep
    pose: np.ndarray             # (3,)
    ring: Ring
    sensor_model: str = "gp2d12"
    adc_bits: int = 12
    vref_v: float = 5.0
    max_range_m: float = 0.624
    samples: int = 1
    settle_s: float = 0.0
    truth: Truth | None = None
    reading_poses: np.ndarray | None = None   # (S, N, 3) when the robot moves
    missing_steps: tuple[int, ...] = ()       # steps requested whose readings never arrived
    source: str = "sim"

    @property
    def shape(self) -> tuple[int, int]:
        return self.counts.shape


class Reason(enum.IntEnum):
    """Why a reading is invalid (OK when it is valid)."""

    OK = 0
    NO_RETURN = 1          # counts at or below the noise floor: nothing within range
    OUT_OF_RANGE = 2       # a distance outside the sensor's calibrated range
    FOLDOVER_AMBIGUOUS = 3  # counts above the curve's peak region: two distances possible
    SATURATED = 4          # ADC at full scale
    NOT_CONVERGED = 5      # iterative estimation did not settle
    MISSING = 6            # the reading never arrived (hardware)


@dataclass(frozen=True)
class Points:
    """Estimated end points of every reading of a sweep, in the world frame.

    All arrays (S, N). ``origin_*`` is the emitter, ``heading`` the world beam direction;
    for invalid readings x, y, d, theta are NaN and ``reason`` says why.
    """

    x: np.ndarray
    y: np.ndarray
    d: np.ndarray
    theta: np.ndarray
    origin_x: np.ndarray
    origin_y: np.ndarray
    heading: np.ndarray
    sigma_m: np.ndarray       # 1-σ range uncertainty of the reading
    iterations: np.ndarray    # int
    valid: np.ndarray         # bool
    reason: np.ndarray        # uint8 of Reason
    max_range_m: float = 0.624
    cone_half_angle_rad: float = 0.0  # > 0: each reading is an echo from anywhere in this cone

    def reasons(self) -> dict[str, int]:
        """How many readings fell into each reason."""
        values, counts = np.unique(self.reason, return_counts=True)
        return {Reason(int(v)).name.lower(): int(c) for v, c in zip(values, counts)}


def ring_angles(ring: Ring) -> np.ndarray:
    """(N,) radial direction of each sensor in the robot frame: sensor k at k·2π/N."""
    return np.arange(ring.sensors) * (2.0 * np.pi / ring.sensors)


def sensor_angles_for_steps(ring: Ring, steps: np.ndarray) -> np.ndarray:
    """(S, N) commanded sensor angles: step × motor step × belt ratio, the same for all."""
    angle = np.asarray(steps, dtype=float) * ring.motor_step_rad * ring.gear
    return np.repeat(angle[:, None], ring.sensors, axis=1)


def beam_geometry(ring: Ring, pose: np.ndarray, sensor_angles: np.ndarray,
                  emitter_offset_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Emitter positions (S, N, 2) and world beam headings (S, N) for a sweep.

    Frames (the one convention, shared by the MJCF model and the estimator): sensor k's
    hinge sits at radius R along robot angle ρ_k = k·2π/N; its beam points along
    h = yaw + ρ_k + φ (φ = sensor angle, CCW positive); the emitter sits d_o to the right of
    the hinge, at hinge + d_o·(sin h, −cos h). Against a wall at perpendicular distance y
    from the hinge this gives the paper's Eq. 5, d = −d_o·tan φ + y / cos φ.
    ``pose`` is (3,) or, for a moving robot, (S, N, 3).
    """
    pose = np.asarray(pose, dtype=float)
    x, y, yaw = pose[..., 0], pose[..., 1], pose[..., 2]
    rho = yaw + ring_angles(ring)
    heading = rho + sensor_angles
    hx = x + ring.radius_m * np.cos(rho)
    hy = y + ring.radius_m * np.sin(rho)
    ox = hx + emitter_offset_m * np.sin(heading)
    oy = hy - emitter_offset_m * np.cos(heading)
    return np.stack(np.broadcast_arrays(ox, oy), axis=-1), heading


def as_pose(pose: Any) -> np.ndarray:
    """(3,) x m, y m, yaw rad from a scenario ``Pose`` or a sequence (x, y[, yaw]).

    Raises ValueError naming what was given when it is neither."""
    if hasattr(pose, "x_m"):
        return np.array([pose.x_m, pose.y_m, pose.yaw_rad], dtype=float)
    try:
        arr = np.asarray(pose, dtype=float).ravel()
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.size not in (2, 3) or not np.isfinite(arr).all():
        raise ValueError(f"a pose is (x m, y m[, yaw rad]) or a scenario Pose, got {pose!r}")
    return np.append(arr, 0.0) if arr.size == 2 else arr


@runtime_checkable
class RingSource(Protocol):
    """Anything that sweeps a ring: the simulator (``SimRing``), the real ring over a serial
    port (``SerialRing``), a fake in a test. ``pipeline.acquire`` drives any of them.

    ``sweep(pose, *, steps=None)`` takes one sweep with the robot at ``pose`` — (x m, y m,
    yaw rad) or a scenario ``Pose`` (a simulator also takes a scan-pose index) — over
    ``steps`` (motor steps in order; None: the source's full sweep) and returns a
    :class:`Sweep`; steps whose readings never arrived are listed in ``missing_steps``, never
    invented. A source that goes away mid-sweep raises :class:`SourceLost`. ``close()``
    releases it; as a context manager it opens on entry and closes on exit.
    """

    def sweep(self, pose: Any, *, steps: np.ndarray | None = None) -> Sweep: ...

    def close(self) -> None: ...

    def __enter__(self) -> Any: ...

    def __exit__(self, *exc: object) -> Any: ...


class SourceLost(RuntimeError):
    """The source went away mid-sweep; ``partial`` holds the :class:`Sweep` of what arrived
    (None if nothing did) and ``report`` the source's account of it, if it keeps one."""

    def __init__(self, message: str, partial: Sweep | None = None, report: Any = None):
        super().__init__(message)
        self.partial, self.report = partial, report
