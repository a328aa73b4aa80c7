"""SimRing against geometry worked out by hand: ray–segment and ray–circle intersections.

The analytic side never touches MuJoCo: emitter positions and headings come from
``core.beam_geometry`` (the frame convention), hits from the outline polygon and the
cylinders' circles. The simulator must agree to 1e-6 m and 1e-6 rad, including the rays
that hit nothing and the hits beyond the sensor's max range (both NaN).
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from irring import Sweep, designs, scenario
from irring.core import beam_geometry, sensor_angles_for_steps
from irring.core import Box, Cylinder
from irring.simulation import model as model_lib
from irring.simulation.sim import RayHits, SimRing

TOL_M = 1e-6
TOL_RAD = 1e-6


def analytic_hits(origin_xy: np.ndarray, heading: np.ndarray, sc: scenario.Scenario,
                  max_range_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(distance, incidence, nearest distance ignoring max range) of 2-D rays in the room.

    Ray p + t·u, u = (cos h, sin h). Segment a + s·(b − a): t = (w × e)/(u × e),
    s = (w × u)/(u × e) with w = a − p. Circle |p + t·u − c| = r: t = −β − √(β² − γ),
    β = u·(p − c), γ = |p − c|² − r². θ = angle between the ray and the surface normal.
    """
    p = origin_xy.reshape(-1, 2)
    u = np.stack([np.cos(heading), np.sin(heading)], axis=-1).reshape(-1, 2)
    best = np.full(len(p), np.inf)
    theta = np.full(len(p), np.nan)

    def cross(a, b):
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    outline = sc.room.outline_m
    for a, b in zip(outline, outline[1:] + outline[:1]):
        e = np.subtract(b, a)
        w = np.asarray(a) - p
        denom = cross(u, e)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):   # ray ∥ wall
            t = cross(w, e) / denom
            s = cross(w, u) / denom
        ok = (np.abs(denom) > 1e-15) & (t > 0) & (s >= 0) & (s <= 1) & (t < best)
        normal = np.array([e[1], -e[0]]) / np.hypot(*e)
        best = np.where(ok, t, best)
        theta = np.where(ok, np.arccos(np.clip(np.abs(u @ normal), 0, 1)), theta)
    for ob in sc.obstacles:
        assert isinstance(ob, Cylinder)
        pc = p - np.asarray(ob.center_m)
        beta = np.einsum("ij,ij->i", u, pc)
        gamma = np.einsum("ij,ij->i", pc, pc) - ob.radius_m ** 2
        disc = beta ** 2 - gamma
        with np.errstate(invalid="ignore"):
            t = -beta - np.sqrt(disc)
        ok = (disc >= 0) & (t > 0) & (t < best)
        hit = p + u * t[:, None]
        normal = (hit - ob.center_m) / ob.radius_m
        cos = np.abs(np.einsum("ij,ij->i", u, normal))
        best = np.where(ok, t, best)
        theta = np.where(ok, np.arccos(np.clip(cos, 0, 1)), theta)
    nearest = np.where(np.isfinite(best), best, np.nan)
    within = nearest <= max_range_m
    shape = np.shape(heading)
    return (np.where(within, nearest, np.nan).reshape(shape),
            np.where(within, theta, np.nan).reshape(shape), nearest.reshape(shape))


def _assert_matches(sim: SimRing, truth, angles, pose) -> dict[str, int]:
    sc = sim.scenario
    xy, heading = beam_geometry(sim.ring, pose, angles, sim.ring.emitter_offset_m)
    dist, theta, nearest = analytic_hits(xy, heading, sc, sc.sensor.max_range_m)
    np.testing.assert_array_equal(np.isnan(truth.distance_m), np.isnan(dist))
    np.testing.assert_allclose(truth.distance_m, dist, atol=TOL_M, rtol=0)
    np.testing.assert_allclose(truth.incidence_rad, theta, atol=TOL_RAD, rtol=0)
    hit = ~np.isnan(dist)
    expect_point = xy + np.stack([np.cos(heading), np.sin(heading)], -1) * dist[..., None]
    np.testing.assert_allclose(truth.hit_point[..., :2][hit], expect_point[hit], atol=TOL_M)
    np.testing.assert_allclose(truth.hit_point[..., 2][hit], sim.ring.sensor_height_m, atol=1e-9)
    assert np.isnan(truth.hit_point[~hit]).all()
    assert (truth.geom_id[~hit] == -1).all() and (truth.geom_id[hit] >= 0).all()
    assert np.isnan(truth.reflectance[~hit]).all() and (truth.reflectance[hit] == 1.0).all()
    return {"hits": int(hit.sum()), "beyond_range": int((np.isfinite(nearest) & ~hit).sum()),
            "no_surface": int(np.isnan(nearest).sum())}


POSES = [None, None, None, None, (1.40, 0.30, 0.7), (0.40, 0.62, -2.5), (1.21, 1.55, 3.0)]


@pytest.mark.parametrize("pose_index", range(len(POSES)))
def test_true_distances_and_incidence_equal_the_analytic_t_room(t_room, pose_index):
    """Every reading of a full sweep (71 × 12) at the paper's poses and some turned ones."""
    sim = SimRing(t_room)
    pose = POSES[pose_index]
    steps, angles, truth = sim.truth(min(pose_index, 3), pose=pose)
    pose = sim.pose(pose_index) if pose is None else np.array(pose)
    counts = _assert_matches(sim, truth, angles, pose)
    assert counts["hits"] > 100
    assert counts["beyond_range"] > 50  # walls beyond 624 mm: no return (NaN), our own logic


def test_every_ray_agrees_when_the_range_is_long(three_cylinders):
    """With a 30 m range every beam hits a wall or a cylinder; all must agree."""
    sc = dataclasses.replace(three_cylinders,
                             sensor=dataclasses.replace(three_cylinders.sensor, max_range_m=30.0))
    sim = SimRing(sc)
    for k in range(len(sc.robot.poses)):
        _, angles, truth = sim.truth(k)
        counts = _assert_matches(sim, truth, angles, sim.pose(k))
        assert counts["hits"] == 71 * 12
    cylinder_ids = {sim.model.geom(f"obstacle_{j:02d}").id for j in range(3)}
    _, _, truth = sim.truth(0)
    assert cylinder_ids & set(truth.geom_id.ravel())  # the corner table leg is seen


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(x=st.floats(0.20, 2.22), y=st.floats(0.20, 0.70), yaw=st.floats(-math.pi, math.pi),
       step=st.integers(-35, 35))
def test_random_poses_agree_with_the_analytic_room(three_cylinders, x, y, yaw, step):
    """Anywhere in the bar of the T (clear of the cylinders), any yaw and motor step."""
    for ob in three_cylinders.obstacles:
        if math.hypot(x - ob.center_m[0], y - ob.center_m[1]) < ob.radius_m + 0.2:
            return
    sim = _long_range_sim(three_cylinders)
    _, angles, truth = sim.truth(0, steps=np.array([step]), pose=(x, y, yaw))
    _assert_matches(sim, truth, angles, np.array([x, y, yaw]))


_LONG = {}


def _long_range_sim(sc: scenario.Scenario) -> SimRing:
    if sc.name not in _LONG:
        _LONG[sc.name] = SimRing(dataclasses.replace(
            sc, sensor=dataclasses.replace(sc.sensor, max_range_m=5.0)))
    return _LONG[sc.name]


def test_rays_that_hit_nothing_are_nan(t_room):
    """Rays from outside the room pointing away, and vertical rays, meet no surface."""
    sim = SimRing(dataclasses.replace(t_room, sensor=dataclasses.replace(t_room.sensor,
                                                                           max_range_m=30.0)))
    origin = np.array([[3.0, 0.45, 0.1], [-1.0, 0.45, 0.1], [1.2, 0.45, 0.1], [1.2, 0.45, 0.1]])
    direction = np.array([[1.0, 0.0, 0.0], [-1.0, 0.2, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    hits = sim.cast(origin, direction)
    assert np.isnan(hits.distance_m).all() and np.isnan(hits.incidence_rad).all()
    assert np.isnan(hits.hit_point).all() and (hits.geom_id == -1).all()
    assert np.isnan(hits.reflectance).all()
    # the same outside rays turned round hit the outer faces of the 20 mm walls
    back = sim.cast(origin[:2], -direction[:2])
    np.testing.assert_allclose(back.distance_m, [3.0 - 2.42 - 0.02,
                                                 np.hypot(1.0, 0.2) - 0.02 * np.hypot(1.0, 0.2)],
                               atol=1e-12)


def test_cast_max_range_is_ours_and_directions_need_not_be_unit(t_room):
    sim = SimRing(t_room)
    origin = np.array([1.21, 0.45, 0.1])   # 450 mm from the bottom wall, 450 mm from the top
    down = np.array([0.0, -3.0, 0.0])       # not unit on purpose
    hits = sim.cast(origin, down)
    assert hits.distance_m == pytest.approx(0.45, abs=1e-12) and hits.incidence_rad == 0.0
    np.testing.assert_allclose(hits.hit_point, [1.21, 0.0, 0.1], atol=1e-12)
    assert np.isnan(sim.cast(origin, down, max_range_m=0.4499).distance_m)
    # leading shapes are kept: (2, 4, 5, 3) rays → (2, 4, 5) results
    many = sim.cast(np.broadcast_to(origin, (2, 4, 5, 3)), np.broadcast_to(down, (2, 4, 5, 3)))
    assert isinstance(many, RayHits) and many.distance_m.shape == (2, 4, 5)
    assert many.hit_point.shape == (2, 4, 5, 3)
    with pytest.raises(ValueError, match="non-zero"):
        sim.cast(origin, np.zeros(3))


def test_emitter_frames_equal_data_beam_geometry(t_room):
    """MuJoCo's emitter sites (positions and beam axes) are exactly core.beam_geometry's."""
    sim = SimRing(t_room)
    steps = sim.default_steps()
    angles = sensor_angles_for_steps(sim.ring, steps)
    for pose in (sim.pose(0), np.array([0.5, 0.4, 2.9]), np.array([1.0, 0.5, -1.2])):
        origin, direction = sim.frames(angles, pose)
        xy, heading = beam_geometry(sim.ring, pose, angles, sim.ring.emitter_offset_m)
        np.testing.assert_allclose(origin[..., :2], xy, atol=1e-12)
        np.testing.assert_allclose(origin[..., 2], sim.ring.sensor_height_m, atol=1e-12)
        np.testing.assert_allclose(direction, np.stack([np.cos(heading), np.sin(heading),
                                                        np.zeros_like(heading)], -1), atol=1e-12)


def test_kept_robot_frames_equal_mujoco_at_the_pose(t_room):
    """A static scene reuses the robot-frame frames: placing them at a pose equals MuJoCo's
    own forward with the chassis at that pose, and a caller writing into what it got back
    cannot change the next sweep's frames."""
    sim = SimRing(t_room)
    steps = sim.default_steps()
    angles = sensor_angles_for_steps(sim.ring, steps)
    pose = np.array([1.1, 0.35, 2.2])
    d = mujoco.MjData(sim.model)
    m = sim.built.chassis_mocap
    d.mocap_pos[m] = [pose[0], pose[1], 0.0]
    d.mocap_quat[m] = [np.cos(pose[2] / 2), 0.0, 0.0, np.sin(pose[2] / 2)]
    want_o, want_d = np.empty(angles.shape + (3,)), np.empty(angles.shape + (3,))
    sites = sim.built.emitter_sites
    for i, a in enumerate(angles):
        d.qpos[sim.built.sensor_qpos] = a
        mujoco.mj_kinematics(sim.model, d)
        want_o[i], want_d[i] = d.site_xpos[sites], d.site_xmat[sites][:, 2::3]
    first = sim.frames(angles, pose)
    first[0][:] = np.nan
    again = sim.frames(angles, pose)
    fresh = sim.frames(angles, pose, reuse=False)
    for got in (again, fresh):
        np.testing.assert_allclose(got[0], want_o, atol=1e-12)
        np.testing.assert_allclose(got[1], want_d, atol=1e-12)


def test_frames_follow_a_pose_per_step(t_room):
    """A moving robot (the motion effect): each step has its own pose."""
    sim = SimRing(t_room)
    steps = np.arange(-35, 36, 5)
    angles = sensor_angles_for_steps(sim.ring, steps)
    poses = np.stack([np.linspace(0.5, 1.9, len(steps)), np.full(len(steps), 0.45),
                      np.linspace(-0.3, 0.4, len(steps))], axis=-1)
    origin, direction = sim.frames(angles, poses)
    per_reading = np.repeat(poses[:, None, :], sim.ring.sensors, axis=1)
    xy, heading = beam_geometry(sim.ring, per_reading, angles, sim.ring.emitter_offset_m)
    np.testing.assert_allclose(origin[..., :2], xy, atol=1e-12)
    np.testing.assert_allclose(direction[..., 0], np.cos(heading), atol=1e-12)
    _, _, truth = sim.truth(0, steps=steps, pose=poses)
    _assert_matches(sim, truth, angles, per_reading)


@pytest.mark.parametrize("design", ["rotating1", "radial12", "laser"])
def test_other_designs_sweep_with_the_same_frames(t_room_raw, design):
    t_room_raw["robot"]["design"] = design
    if design == "laser":
        t_room_raw.pop("sensor")  # the laser brings its own sensor block
    sc = scenario.parse(t_room_raw, f"{design}.yaml")
    sim = SimRing(sc)
    steps, angles, truth = sim.truth(1)
    ring = designs.DESIGNS[design]
    assert len(steps) == ring.max_step - ring.min_step + 1 and angles.shape == (len(steps), ring.sensors)
    xy, heading = beam_geometry(ring, sim.pose(1), angles, ring.emitter_offset_m)
    np.testing.assert_allclose(truth.origin[..., :2], xy, atol=1e-12)
    _assert_matches(sim, truth, angles, sim.pose(1))


def test_sweep_is_the_papers_sweep(t_room):
    """71 steps −35 … +35, each sensor at 0.6 × 1.8° × step off its radial direction."""
    sim = SimRing(t_room)
    sweep = sim.sweep(2)
    assert isinstance(sweep, Sweep)
    np.testing.assert_array_equal(sweep.steps, np.arange(-35, 36))
    assert sweep.counts.shape == sweep.sensor_angles.shape == (71, 12)
    np.testing.assert_allclose(sweep.sensor_angles,
                               np.repeat(np.radians(1.08) * np.arange(-35, 36)[:, None], 12, 1),
                               atol=1e-15)
    assert sweep.sensor_angles.max() == pytest.approx(math.radians(37.8))
    np.testing.assert_array_equal(sweep.pose, [0.5, 0.45, 0.0])
    assert sweep.duration_s == pytest.approx(71 * 0.0383)
    assert sweep.timestamps_s[-1] == pytest.approx(sweep.duration_s)
    assert sweep.truth.distance_m.shape == (71, 12) and sweep.truth.origin.shape == (71, 12, 3)
    assert (sweep.sensor_model, sweep.adc_bits, sweep.max_range_m) == ("gp2d12", 12, 0.624)


def test_sweep_steps_are_checked(t_room):
    sim = SimRing(t_room)
    with pytest.raises(ValueError, match=r"-35 … 35"):
        sim.truth(0, steps=np.array([0, 36]))
    with pytest.raises(IndexError, match="has 4 pose"):
        sim.sweep(4)
    # a step listed twice was read twice, estimated and mapped twice, and written into a
    # sweeps.npz that irring replay refuses ("step 1 is listed twice")
    with pytest.raises(ValueError, match="step 30 is listed twice; a sweep reads each step once"):
        sim.sweep(0, steps=[1, 30, 2, 30])


def test_same_seed_same_sweeps_and_noise_differs_between_sweeps(t_room):
    """A fresh SimRing with the same seed reproduces every sweep; consecutive sweeps at a
    pose draw fresh noise; reset() starts the sequence again."""
    pytest.importorskip("irring.simulation.effects")
    a, b = SimRing(t_room), SimRing(t_room)
    first = [a.sweep(0).counts, a.sweep(0).counts, a.sweep(3).counts]
    second = [b.sweep(0).counts, b.sweep(0).counts, b.sweep(3).counts]
    for x, y in zip(first, second):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(first[0], first[1])  # the scene has noise: new draws
    a.reset()
    np.testing.assert_array_equal(a.sweep(0).counts, first[0])
    other = SimRing(t_room, seed=t_room.seed + 1).sweep(0).counts
    assert not np.array_equal(other, first[0])


def test_truth_needs_no_effects_and_is_deterministic(t_room):
    _, _, one = SimRing(t_room).truth(1)
    _, _, two = SimRing(t_room).truth(1)
    for field in dataclasses.fields(one):
        np.testing.assert_array_equal(getattr(one, field.name), getattr(two, field.name))


def test_rays_into_the_room_alone_hit_what_the_whole_scene_hits(t_room):
    """SimRing casts into the room without the robot (model.room_model); every ray's
    distance, normal and geom (the scene's id) are bit for bit those of the same call on the
    whole scene model, in a room with a box, a cylinder and a turned wall, from inside and
    outside the room, past the robot's own geoms too."""
    sc = dataclasses.replace(
        t_room, obstacles=(Box(center_m=(0.61, 0.37), size_m=(0.13, 0.05),
                                        yaw_rad=0.4, reflectance=0.35),
                           Cylinder(center_m=(1.83, 0.52), radius_m=0.04, reflectance=0.8)),
        room=dataclasses.replace(t_room.room, outline_m=(
            (0.0, 0.0), (2.42, 0.0), (2.42, 0.9), (1.66, 0.9), (1.51, 1.8), (0.76, 1.8),
            (0.76, 0.9), (0.0, 0.9))))
    sim = SimRing(sc)
    assert sim.ray_model.ngeom < sim.model.ngeom
    rng = np.random.default_rng(7)
    origin = np.column_stack([rng.uniform(-0.3, 2.7, 4000), rng.uniform(-0.2, 2.0, 4000),
                              rng.uniform(0.0, 0.35, 4000)])
    direction = rng.normal(size=(4000, 3)) * [1.0, 1.0, 0.05]
    unit = direction / np.sqrt(np.einsum("ij,ij->i", direction, direction))[:, None]  # as cast
    whole = mujoco.batch.Batch(sim.model, 1, nthread=1)
    dist, gid, normal = (a[0] for a in whole.ray(origin[None], unit[None],
                                                 geomgroup=model_lib.RAY_GEOMGROUP,
                                                 normal=True))
    hits = sim.cast(origin, direction, max_range_m=10.0)
    hit = gid >= 0
    assert 2000 < hit.sum() < 4000 and set(sim.built.ray_geoms) == set(gid[hit])
    np.testing.assert_array_equal(hits.geom_id, gid)
    np.testing.assert_array_equal(hits.distance_m[hit], dist[hit])
    assert np.isnan(hits.distance_m[~hit]).all()
    cos = np.abs(np.einsum("ij,ij->i", unit, normal))[hit]
    np.testing.assert_array_equal(hits.incidence_rad[hit], np.arccos(np.minimum(cos, 1.0)))
    np.testing.assert_array_equal(hits.reflectance[hit], sim.built.reflectance[gid[hit]])
