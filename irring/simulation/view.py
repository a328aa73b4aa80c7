"""The scenario's MuJoCo scene as a picture (room, obstacles, the ring at one pose and motor
step, its beams to where they hit) or the interactive viewer playing the sweep.

Offscreen pictures need no display: OSMesa (``libosmesa6``) or EGL (``libegl1``), as
``MUJOCO_GL`` says, else OSMesa if installed. MuJoCo's warnings go to Python's ``warnings``
instead of a ``MUJOCO_LOG.TXT`` in the working directory.
"""

from __future__ import annotations

import contextlib
import math
import os
import time
import warnings
from dataclasses import dataclass

import mujoco
import numpy as np

from ..scenario import Scenario
from .gl import context_failed, gl_backend
from .sim import SimRing

BEAM_RGBA = (0.1, 0.85, 0.2, 1.0)      # a beam that returns: emitter → hit
MISS_RGBA = (0.55, 0.55, 0.6, 0.5)     # a beam with nothing within range: to max range
HIT_RGBA = (0.9, 0.05, 0.05, 1.0)      # the hit point
HIT_RADIUS_M = 0.012
BEAM_WIDTH_M = 0.002


@dataclass(frozen=True)
class Beams:
    """The ring's beams at one motor step, world frame: emitters (N, 3), unit directions
    (N, 3), true distances (N,) m (NaN: nothing within the sensor's range)."""

    origin: np.ndarray
    direction: np.ndarray
    distance_m: np.ndarray
    max_range_m: float

    @property
    def hits(self) -> np.ndarray:
        """(H, 3) hit points of the beams that return."""
        ok = np.isfinite(self.distance_m)
        return self.origin[ok] + self.direction[ok] * self.distance_m[ok, None]


class SceneView:
    """The scenario's model posed at a scan pose and motor step, with its beams.

    ``pose`` indexes the scenario's scan poses; ``step`` is a motor step within the ring's
    limits. Raises ValueError naming the bad value and what is allowed.
    """

    def __init__(self, scenario: Scenario, *, pose: int = 0, step: int = 0):
        self.sim = SimRing(scenario)
        self.model, self.data = self.sim.model, self.sim.data
        n = len(scenario.robot.poses)
        if not 0 <= pose < n:
            raise ValueError(f"pose index {pose} is out of range: scenario {scenario.name!r} "
                             f"has {n} scan pose(s), 0 … {n - 1}")
        self.pose_index = pose
        self.set_step(step)

    def set_step(self, step: int) -> Beams:
        """Pose the model at motor ``step`` (chassis at the scan pose, belt-driven sensor
        angles) and cast its beams."""
        ring = self.sim.ring
        if not ring.min_step <= step <= ring.max_step:
            raise ValueError(f"motor step {step} is out of range: the ring turns from step "
                             f"{ring.min_step} to {ring.max_step} "
                             f"({math.degrees(ring.motor_step_rad):.2f}° a motor step)")
        self.step = int(step)
        _, angles, truth = self.sim.truth(self.pose_index, steps=np.array([self.step]))
        x, y, yaw = self.sim.pose(self.pose_index)
        built, d = self.sim.built, self.data
        d.mocap_pos[built.chassis_mocap, :2] = (x, y)
        d.mocap_quat[built.chassis_mocap] = (math.cos(yaw / 2), 0, 0, math.sin(yaw / 2))
        d.qpos[built.motor_qpos] = self.step * ring.motor_step_rad
        d.qpos[built.sensor_qpos] = angles[0]
        mujoco.mj_forward(self.model, d)
        self.beams = Beams(truth.origin[0], truth.direction[0], truth.distance_m[0],
                           self.sim.max_range_m)
        return self.beams

    def camera(self) -> mujoco.MjvCamera:
        """A free camera looking down at the pose from behind and above, the sensors'
        reach in view, or the room where it is smaller (a laser's 8 m would shrink it)."""
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        x, y, yaw = self.sim.pose(self.pose_index)
        cam.lookat[:] = (x, y, 0.0)
        corners = np.asarray(self.sim.scenario.room.outline_m)
        farthest_wall = float(np.hypot(corners[:, 0] - x, corners[:, 1] - y).max())
        cam.distance = 2.4 * min(self.sim.max_range_m + self.sim.ring.radius_m, farthest_wall)
        cam.elevation = -65.0
        cam.azimuth = 90.0 - 25.0
        return cam

    def add_beams(self, scene: mujoco.MjvScene) -> None:
        """Append the beams (lines to their hits or to max range) and the hit markers to
        ``scene``'s geoms, as far as it has room."""
        b = self.beams
        eye = np.eye(3).ravel()
        for k in range(len(b.distance_m)):
            hit = np.isfinite(b.distance_m[k])
            end = b.origin[k] + b.direction[k] * (b.distance_m[k] if hit else b.max_range_m)
            _add(scene, mujoco.mjtGeom.mjGEOM_CAPSULE, np.zeros(3), np.zeros(3), eye,
                 BEAM_RGBA if hit else MISS_RGBA, connect=(b.origin[k], end))
            if hit:
                _add(scene, mujoco.mjtGeom.mjGEOM_SPHERE, np.full(3, HIT_RADIUS_M), end, eye,
                     HIT_RGBA)


def scene_option() -> mujoco.MjvOption:
    """MuJoCo's defaults without its own rangefinder rays: the beams drawn here are the
    simulator's (the same batched casts a sweep uses), ending at the sensor's range."""
    opt = mujoco.MjvOption()
    opt.flags[mujoco.mjtVisFlag.mjVIS_RANGEFINDER] = 0
    return opt


def _add(scene, kind, size, pos, mat, rgba, connect=None) -> None:
    if scene.ngeom >= scene.maxgeom:
        return
    g = scene.geoms[scene.ngeom]
    mujoco.mjv_initGeom(g, kind, size, pos, mat, np.asarray(rgba, np.float32))
    if connect is not None:
        mujoco.mjv_connector(g, kind, BEAM_WIDTH_M, *(np.asarray(p, float) for p in connect))
    g.emission = 0.6
    scene.ngeom += 1


# --------------------------------------------------------------------------- offscreen


def _gl_context(width: int, height: int):
    backend = gl_backend()
    try:
        if backend == "egl":
            from mujoco.egl import GLContext   # deferred: only the chosen backend can load
        else:
            from mujoco.osmesa import GLContext   # deferred: only the chosen backend can load
        ctx = GLContext(width, height)
        ctx.make_current()
    except Exception as exc:   # noqa: BLE001 - PyOpenGL's and the driver's, any of them
        if isinstance(exc, ImportError) and "PYOPENGL_PLATFORM" in str(exc):
            raise   # the user's PYOPENGL_PLATFORM at odds with it: errors.describe says so
        raise context_failed(backend, exc) from exc
    return ctx


@contextlib.contextmanager
def mujoco_warnings():
    """Route MuJoCo's warnings to Python's ``warnings`` (MuJoCo would otherwise append them
    to MUJOCO_LOG.TXT in the working directory)."""
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda msg: warnings.warn(f"MuJoCo: {msg}", stacklevel=2))
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)


def render(view: SceneView, width: int = 1280, height: int = 960) -> np.ndarray:
    """(height, width, 3) uint8 RGB of the scene with its beams, rendered offscreen."""
    model = view.model
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    with mujoco_warnings():
        ctx = _gl_context(width, height)
        try:
            scene = mujoco.MjvScene(model, maxgeom=model.ngeom + 4 * view.sim.ring.sensors + 100)
            con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
            try:
                mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, con)
                mujoco.mjv_updateScene(model, view.data, scene_option(), None,
                                       view.camera(), mujoco.mjtCatBit.mjCAT_ALL, scene)
                view.add_beams(scene)
                rect = mujoco.MjrRect(0, 0, width, height)
                mujoco.mjr_render(rect, scene, con)
                # the two eyes' cameras sit half an eye distance apart: their mean draws
                view.last_camera = _Projection.of(
                    mujoco.mjv_averageCamera(scene.camera[0], scene.camera[1]), width, height)
                rgb = np.empty((height, width, 3), np.uint8)
                mujoco.mjr_readPixels(rgb, None, rect, con)
            finally:
                con.free()
        finally:
            ctx.free()
    return np.flipud(rgb).copy()


@dataclass(frozen=True)
class _Projection:
    """Where world points land in a rendered picture (pixel column, row from the top)."""

    pos: np.ndarray
    forward: np.ndarray
    up: np.ndarray
    near: float
    center: float
    half_width: float
    bottom: float
    top: float
    width: int
    height: int

    @classmethod
    def of(cls, cam, width: int, height: int) -> _Projection:
        half_h = (cam.frustum_top - cam.frustum_bottom) / 2
        half_w = cam.frustum_width or half_h * width / height   # 0: from the aspect ratio
        return cls(np.array(cam.pos), np.array(cam.forward), np.array(cam.up),
                   float(cam.frustum_near), float(cam.frustum_center), float(half_w),
                   float(cam.frustum_bottom), float(cam.frustum_top), width, height)

    def __call__(self, points) -> np.ndarray:
        """(n, 2) pixel (column, row) of world points (n, 3)."""
        v = np.atleast_2d(points) - self.pos
        right = np.cross(self.forward, self.up)
        z = v @ self.forward
        x, y = (v @ right) * self.near / z, (v @ self.up) * self.near / z
        col = (x - (self.center - self.half_width)) / (2 * self.half_width) * self.width
        row = (self.top - y) / (self.top - self.bottom) * self.height
        return np.stack([col, row], axis=1)


# --------------------------------------------------------------------------- interactive


def display_problem() -> str | None:
    """Why the interactive viewer cannot open a window here (None: it can): no display
    named, or one named that GLFW cannot open (a forwarded X display gone, a wrong
    DISPLAY); the viewer itself would end the process with 'could not initialize GLFW'."""
    named = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    if not named:
        return "no display"
    try:
        import glfw   # deferred: the viewer's window library, only to probe the display

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # GLFWError warnings: said below in one line
            if glfw.init():
                return None
    except Exception as exc:   # noqa: BLE001 - any failure means no window
        return f"GLFW cannot be loaded ({type(exc).__name__}: {exc})"
    return f"the display {named!r} cannot be opened (GLFW could not connect to it)"


def play(view: SceneView, step_s: float = 0.05) -> None:
    """The interactive MuJoCo viewer (passive) playing the sweep back and forth, beams
    drawn, until its window is closed."""
    import mujoco.viewer   # deferred: loads GLFW, which needs a display

    ring = view.sim.ring
    steps = list(range(ring.min_step, ring.max_step + 1))
    order = steps + steps[-2:0:-1]
    with mujoco_warnings(), mujoco.viewer.launch_passive(view.model, view.data) as viewer:
        viewer.opt.flags[mujoco.mjtVisFlag.mjVIS_RANGEFINDER] = 0
        viewer.cam.lookat[:] = view.camera().lookat
        viewer.cam.distance = view.camera().distance
        viewer.cam.elevation = view.camera().elevation
        k = 0
        while viewer.is_running():
            with viewer.lock():
                view.set_step(order[k % len(order)])
                viewer.user_scn.ngeom = 0
                view.add_beams(viewer.user_scn)
            viewer.sync()
            time.sleep(step_s)
            k += 1
