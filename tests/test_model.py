"""The MJCF ring and the models built from it: they compile, step cleanly, and are the paper's.

Physical facts checked here: the belt ratio (sensor = 0.6 × motor, in the model's equality
constraints and after physics steps), the ring layout (12 sensors, 30° apart, 0.15 m,
±37.8°), the emitter offset, and walls whose inner faces are the outline itself.
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest

from irring import designs, resources, scenario
from irring.scenario import parse as parse_scene
from irring.simulation import model
from irring import core
from irring.core import Ring, beam_geometry

MODELS = resources.models_dir()
PAPER = designs.PAPER_RING


def _step_one_second(m: mujoco.MjModel, *, ctrl_lo: float, ctrl_hi: float) -> mujoco.MjData:
    """Step 1 s of physics while the motor is commanded across its range in 10 jumps."""
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    n = int(round(1.0 / m.opt.timestep))
    targets = np.linspace(ctrl_lo, ctrl_hi, 10)
    for i in range(n):
        d.ctrl[0] = targets[i * len(targets) // n]
        mujoco.mj_step(m, d)
    return d


def _assert_clean(d: mujoco.MjData, what: str) -> None:
    warnings = {mujoco.mjtWarning(i).name: int(w.number) for i, w in enumerate(d.warning)
                if w.number}
    assert not warnings, f"{what}: MuJoCo warnings {warnings}"
    assert np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel)), what


@pytest.mark.parametrize("path", sorted(MODELS.glob("*.xml")), ids=lambda p: p.name)
def test_every_model_file_compiles_and_steps_one_second_without_warnings(path):
    m = mujoco.MjModel.from_xml_path(str(path))
    d = _step_one_second(m, ctrl_lo=-35 * PAPER.motor_step_rad, ctrl_hi=35 * PAPER.motor_step_rad)
    _assert_clean(d, path.name)
    assert d.time == pytest.approx(1.0)


@pytest.mark.parametrize("name", sorted(scenario.bundled()))
def test_every_bundled_scenario_compiles_and_steps_one_second_without_warnings(name):
    sc = scenario.load_scenario(name)
    built = model.build(sc)
    lo, hi = built.model.actuator_ctrlrange[built.motor_actuator]
    d = _step_one_second(built.model, ctrl_lo=lo, ctrl_hi=hi)
    _assert_clean(d, name)


@pytest.mark.parametrize("name", sorted(designs.DESIGNS))
def test_every_named_design_builds_from_the_template_and_steps(name):
    ring = designs.DESIGNS[name]
    built = model.compile_ring(ring)
    m = built.model
    assert built.n_sensors == ring.sensors
    assert [m.body(b).name for b in m.jnt_bodyid[built.sensor_joints]] == \
        [f"ir_{k:02d}" for k in range(ring.sensors)]
    lo, hi = m.actuator_ctrlrange[built.motor_actuator]
    d = _step_one_second(m, ctrl_lo=lo, ctrl_hi=hi)
    _assert_clean(d, name)


def test_template_is_the_papers_ring():
    """irring.xml itself (what the viewer opens): 12 sensors, 30° apart, R = 0.15 m, ±37.8°,
    belt polycoef 0.6, d_o = 7 mm; its emitter frames are core.beam_geometry's."""
    m = mujoco.MjModel.from_xml_path(str(MODELS / "irring.xml"))
    d = mujoco.MjData(m)
    names = [f"ir_{k:02d}" for k in range(12)]
    hinges = [m.joint(f"{n}_hinge").id for n in names]
    np.testing.assert_allclose(m.jnt_range[hinges], [[-math.radians(37.8), math.radians(37.8)]] * 12,
                               atol=1e-9)
    assert m.jnt_limited[hinges].all()
    for k, n in enumerate(names):
        eq = m.equality(f"belt_{k:02d}")
        assert eq.type == mujoco.mjtEq.mjEQ_JOINT
        assert (eq.obj1id, eq.obj2id) == (m.joint(f"{n}_hinge").id, m.joint("ring_motor").id)
        np.testing.assert_array_equal(eq.data[:5], [0, 0.6, 0, 0, 0])
        rf = m.sensor(f"{n}_range")
        assert rf.type == mujoco.mjtSensor.mjSENS_RANGEFINDER and rf.objid == m.site(f"{n}_emitter").id
        assert rf.cutoff == 0  # max range is ours, never the rangefinder's clamp
    assert m.actuator("ring_motor").trntype == mujoco.mjtTrn.mjTRN_JOINT
    assert m.actuator("ring_motor").biastype == mujoco.mjtBias.mjBIAS_AFFINE  # a position servo
    phi = math.radians(20.0)
    d.qpos[[m.joint(f"{n}_hinge").qposadr[0] for n in names]] = phi
    mujoco.mj_kinematics(m, d)
    xy, heading = beam_geometry(PAPER, np.zeros(3), np.full((1, 12), phi), 0.007)
    sites = [m.site(f"{n}_emitter").id for n in names]
    np.testing.assert_allclose(d.site_xpos[sites, :2], xy[0], atol=1e-8)
    np.testing.assert_allclose(d.site_xpos[sites, 2], 0.10)
    z_axes = d.site_xmat[sites].reshape(12, 3, 3)[:, :, 2]
    np.testing.assert_allclose(z_axes, np.stack([np.cos(heading[0]), np.sin(heading[0]),
                                                 np.zeros(12)], axis=-1), atol=1e-8)


def test_belt_equalities_hold_in_the_model_when_positioned_kinematically(t_room):
    """Kinematic positioning writes sensor = c0 + c1·motor from the model's own polycoef; the
    compiled equality constraints then have zero residual at every motor step."""
    built = model.build(t_room)
    m, d = built.model, mujoco.MjData(built.model)
    np.testing.assert_array_equal(built.belt_coef, [[0.0, 0.6]] * 12)
    for step in range(-35, 36):
        motor = step * PAPER.motor_step_rad
        d.qpos[built.motor_qpos] = motor
        d.qpos[built.sensor_qpos] = built.sensor_qpos_for(motor)
        mujoco.mj_forward(m, d)
        np.testing.assert_allclose(d.qpos[built.sensor_qpos], 0.6 * motor, atol=1e-15)
        eq_rows = d.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
        assert eq_rows.sum() == 12
        np.testing.assert_allclose(d.efc_pos[eq_rows], 0.0, atol=1e-15)


def test_belt_coupling_holds_under_physics(t_room):
    """Stepping the stepper through −34 … +34 (1.8° per step, 100 ms each) with MuJoCo
    physics: after each step settles every sensor sits at 0.6 × the motor angle (< 1e-9 rad);
    during a step the belt lags by less than the documented 0.02 rad (models/README.md)."""
    built = model.build(t_room)
    m, d = built.model, mujoco.MjData(built.model)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    step = PAPER.motor_step_rad
    hold = int(round(0.1 / m.opt.timestep))
    peak, settled = 0.0, []
    for s in range(-34, 35):
        d.ctrl[0] = s * step
        for _ in range(hold):
            mujoco.mj_step(m, d)
            err = np.abs(d.qpos[built.sensor_qpos] - 0.6 * d.qpos[built.motor_qpos]).max()
            peak = max(peak, err)
        settled.append(err)
        assert d.qpos[built.motor_qpos] == pytest.approx(s * step, abs=1e-4)
    _assert_clean(d, "belt")
    assert max(settled) < 1e-9
    assert peak < 0.02


def test_other_designs_come_from_the_same_template():
    """A 5-sensor ring of radius 0.2 m, ±20°, gear 0.5, d_o = 10 mm, at 80 mm: every number
    lands in the model, and the emitter frames are beam_geometry's."""
    ring = Ring(sensors=5, radius_m=0.2, motor_step_rad=math.radians(2.0), gear=0.5,
                min_step=-20, max_step=20, emitter_offset_m=0.01, sensor_height_m=0.08,
                joint_limit_rad=math.radians(20.0))
    built = model.compile_ring(ring)
    m, d = built.model, mujoco.MjData(built.model)
    assert m.nbody == 3 + 5 and built.n_sensors == 5 and m.neq == 5 and m.nsensor == 5
    np.testing.assert_allclose(built.belt_coef, [[0.0, 0.5]] * 5)
    np.testing.assert_allclose(m.jnt_range[built.sensor_joints], [[-math.radians(20), math.radians(20)]] * 5)
    np.testing.assert_allclose(m.actuator_ctrlrange[0], [-20 * math.radians(2.0), 20 * math.radians(2.0)])
    motor = 13 * ring.motor_step_rad
    d.qpos[built.motor_qpos] = motor
    d.qpos[built.sensor_qpos] = built.sensor_qpos_for(motor)
    pose = np.array([0.3, -0.2, 0.7])
    d.mocap_pos[0] = [pose[0], pose[1], 0.0]
    d.mocap_quat[0] = [math.cos(0.35), 0, 0, math.sin(0.35)]
    mujoco.mj_kinematics(m, d)
    xy, heading = beam_geometry(ring, pose, np.full((1, 5), 0.5 * motor), 0.01)
    np.testing.assert_allclose(d.site_xpos[built.emitter_sites, :2], xy[0], atol=1e-12)
    np.testing.assert_allclose(d.site_xpos[built.emitter_sites, 2], 0.08, atol=1e-12)


def test_single_sensor_at_the_centre_turning_a_full_circle():
    """rotating1: radius 0, one sensor, hinge ±360°, 333 motor steps of 1.8° × 0.6."""
    built = model.compile_ring(designs.DESIGNS["rotating1"])
    m = built.model
    assert built.n_sensors == 1
    np.testing.assert_allclose(m.body("ir_00").pos, [0.0, 0.0, 0.10])
    np.testing.assert_allclose(m.jnt_range[built.sensor_joints[0]], [-2 * math.pi, 2 * math.pi])
    assert m.actuator_ctrlrange[0, 1] == pytest.approx(333 * math.radians(1.8))


def test_walls_have_their_inner_faces_on_the_outline_whichever_way_it_winds():
    """Each wall box lies outside the room; convex corners are closed, reflex ones not."""
    outline = ((0.0, 0.0), (2.0, 0.0), (2.0, 1.0), (1.0, 1.0), (1.0, 2.0), (0.0, 2.0))  # an L
    for pts in (outline, outline[::-1]):
        boxes = model.wall_boxes(pts, 0.02, 0.3)
        assert len(boxes) == len(pts)
        for (half, centre, yaw), a, b in zip(boxes, pts, pts[1:] + pts[:1]):
            u = np.array([math.cos(yaw), math.sin(yaw)])
            np.testing.assert_allclose(u, np.subtract(b, a) / math.dist(a, b), atol=1e-12)
            n = np.array([-u[1], u[0]])
            # inner face: the box's face plane nearest the room contains the wall segment
            offset = np.dot(np.subtract(centre[:2], a), n)
            assert abs(offset) == pytest.approx(0.01, abs=1e-12)
            assert core.inside_outline(*(np.add(a, b) / 2 - n * np.sign(offset) * 0.005), pts)
            assert half[2] == pytest.approx(0.15) and centre[2] == pytest.approx(0.15)
        # walls are lengthened by the thickness at each convex corner; the two walls meeting
        # at the reflex corner (1, 1) of the L are not, or they would stick into the room
        lengths = [round(2 * h[0], 9) for h, _, _ in boxes]
        by_wall = dict(zip([(a, b) for a, b in zip(pts, pts[1:] + pts[:1])], lengths))
        assert sorted(lengths) == [1.02, 1.02, 1.04, 1.04, 2.04, 2.04]
        reflex = [length for (a, b), length in by_wall.items() if (1.0, 1.0) in (a, b)]
        assert reflex == [1.02, 1.02]


def test_reflectance_map_covers_walls_and_obstacles_only(t_room_raw):
    t_room_raw["room"]["reflectance"] = 0.5
    t_room_raw["obstacles"] = [{"type": "cylinder", "center_mm": [2170, 220], "radius_mm": 22,
                                "reflectance": 0.3},
                               {"type": "box", "center_mm": [300, 700], "size_mm": [80, 40],
                                "yaw_deg": 30, "reflectance": 0.8}]
    sc = scenario.parse(t_room_raw, "refl.yaml")
    built = model.build(sc)
    m = built.model
    walls = [m.geom(f"wall_{i:02d}").id for i in range(8)]
    np.testing.assert_array_equal(built.reflectance[walls], 0.5)
    assert built.reflectance[m.geom("obstacle_00").id] == 0.3
    assert built.reflectance[m.geom("obstacle_01").id] == 0.8
    assert sorted(built.ray_geoms) == sorted(walls + [m.geom("obstacle_00").id,
                                                      m.geom("obstacle_01").id])
    others = np.setdiff1d(np.arange(m.ngeom), built.ray_geoms)
    assert np.isnan(built.reflectance[others]).all()
    assert (m.geom_group[others] != model.RAY_GROUP).all()  # robot and floor are never hit
    # obstacles are as tall as the walls, so a beam cannot pass over them
    assert m.geom("obstacle_00").size[1] == pytest.approx(sc.room.wall_height_m / 2)


def test_paper_design_model_matches_template_dimensions(t_room):
    """The rebuilt paper ring has the same bodies, joints, sites and sensors as irring.xml."""
    template = mujoco.MjModel.from_xml_path(str(MODELS / "irring.xml"))
    built = model.compile_ring(dataclasses.replace(PAPER))
    m = built.model
    for attr in ("nbody", "njnt", "nq", "nsite", "nsensor", "nsensordata", "neq", "nu", "ngeom"):
        assert getattr(m, attr) == getattr(template, attr), attr
    for k in range(12):
        np.testing.assert_allclose(m.body(f"ir_{k:02d}").pos, template.body(f"ir_{k:02d}").pos,
                                   atol=1e-9)
        np.testing.assert_allclose(m.site(f"ir_{k:02d}_emitter").pos,
                                   template.site(f"ir_{k:02d}_emitter").pos, atol=1e-12)


def test_rangefinders_never_see_the_robot_over_a_sweep():
    """In scene.xml (floor, no walls) no rangefinder hits a robot part at any of the 71 steps,
    although rangefinders, unlike our ray casts, are not filtered by geom group."""
    m = mujoco.MjModel.from_xml_path(str(MODELS / "scene.xml"))
    d = mujoco.MjData(m)
    motor = m.joint("ring_motor").qposadr[0]
    hinges = [m.joint(f"ir_{k:02d}_hinge").qposadr[0] for k in range(12)]
    dist = [m.sensor_adr[m.sensor(f"ir_{k:02d}_range").id] for k in range(12)]
    for step in range(-35, 36):
        d.qpos[motor] = step * PAPER.motor_step_rad
        d.qpos[hinges] = 0.6 * d.qpos[motor]
        mujoco.mj_forward(m, d)
        np.testing.assert_array_equal(d.sensordata[dist], -1.0)


@pytest.mark.parametrize("effects", [{"noise": {"sigma_v": 0.015}, "quantization": {}},
                                     {"belt_dynamics": {"backlash_deg": 0.5}}],
                         ids=["noise", "belt dynamics"])
def test_a_ring_held_by_joint_limit_zero_reads_as_radial12(effects):
    # joint_limit_deg: 0 with steps 0 … 0 is what a user writes for a still ring; MuJoCo
    # refuses a [0, 0] hinge range (irring run died with an internal error, exit 70)
    from irring import pipeline

    def scene(ring: dict):
        return parse_scene({"name": "held", "seed": 17,
                            "room": {"outline_mm": [[0, 0], [900, 0], [900, 700], [0, 700]]},
                            "robot": {"design": "radial12", "ring": ring,
                                      "poses": [{"x_mm": 430, "y_mm": 360}]},
                            "effects": effects})

    held_scene = scene({"min_step": 0, "max_step": 0, "joint_limit_deg": 0})
    assert held_scene.ring.joint_limit_rad == 0.0
    assert scene({}).ring.joint_limit_rad == pytest.approx(math.radians(37.8))
    held, free = pipeline.run(held_scene), pipeline.run(scene({}))
    (a,), (b,) = held.sweeps, free.sweeps
    assert a.counts.shape == (1, 12)
    np.testing.assert_array_equal(a.counts, b.counts)
    assert np.abs(a.sensor_angles).max() <= model.HELD_HINGE_RAD
    assert held.readings()["valid"] == free.readings()["valid"] == 12
