"""Named and parametric ring designs, and how a scenario picks one."""

from __future__ import annotations

import dataclasses
import math

import pytest

from irring import core, designs, scenario
from irring.core import Ring
from irring.scenario import ScenarioError, load_scenario, loads

DEG = math.pi / 180

T_ROOM = """
name: t
room: {outline_mm: [[0, 0], [2420, 0], [2420, 900], [0, 900]]}
robot:
  design: %s
  %s
  poses: [{x_mm: 1210, y_mm: 450}]
"""


def test_named_designs_exist_and_their_rings_pass_the_schema_bounds():
    assert set(designs.DESIGN_BY_NAME) == {"rotating12", "radial12", "rotating1", "laser",
                                           "sonar12"}
    for d in designs.DESIGN_LIST:
        designs._check_ring(d.ring)  # raises if a number is outside the loader's bounds


def test_rotating12_is_the_papers_ring():
    d = designs.get("rotating12")
    assert d.ring == designs.PAPER_RING == Ring()
    assert d.ring.sensors == 12 and d.ring.radius_m == 0.15
    assert math.degrees(d.step_rad) == pytest.approx(1.08)
    assert math.degrees(d.sweep_half_angle_rad) == pytest.approx(37.8)
    assert d.positions() == 71
    assert d.sensor.design_range_m == 0.686 and d.sensor.max_range_m == 0.624


def test_radial12_is_the_same_ring_held_still():
    d = designs.get("radial12")
    assert dataclasses.replace(d.ring, min_step=-35, max_step=35) == designs.PAPER_RING
    assert not d.rotating and d.positions() == 1
    assert d.ray_step_rad() == pytest.approx(30 * DEG)


def test_rotating1_turns_once_round_in_paper_steps():
    d = designs.get("rotating1")
    assert d.ring.sensors == 1 and d.ring.radius_m == 0.0
    assert math.degrees(d.step_rad) == pytest.approx(1.08)
    covered = d.positions() * d.step_rad
    assert 2 * math.pi <= covered < 2 * math.pi + d.step_rad


def test_laser_is_a_fine_long_range_scanner():
    d = designs.get("laser")
    assert d.positions() == 720 and math.degrees(d.step_rad) == pytest.approx(0.5)
    assert d.sensor.max_range_m >= 8.0 and d.sensor.noise_sigma_m <= 0.01
    assert d.hardware_time_s() == pytest.approx(2 / 75)  # two mirror turns at 75 Hz
    assert d.hardware_time_s(settle_s=0.05) == d.hardware_time_s()  # the mirror never stops
    assert d.hardware_time_s(samples=2) == pytest.approx(4 / 75)


def test_sonar12_has_a_cone_that_closes_the_ring_and_fires_in_turn():
    d = designs.get("sonar12")
    assert d.ring.sensors == 12 and not d.rotating
    assert d.sensor.beam_half_angle_rad == pytest.approx(15 * DEG)
    assert d.ray_step_rad() == 0.0                  # ±15° cones 30° apart leave no gap
    assert d.hardware_time_s() == pytest.approx(12 * 0.049)  # 20 Hz each, in turn


def test_hardware_time_matches_the_sweep_duration_for_gp2_rings():
    for name in ("rotating12", "radial12", "rotating1"):
        d = designs.get(name)
        for stride, settle, samples in ((1, 0.0, 1), (2, 0.01, 4)):
            n = d.positions(stride)
            assert d.hardware_time_s(step_stride=stride, settle_s=settle, samples=samples) == \
                pytest.approx(core.hardware_duration_s(n, settle, samples))
    # the trade a designer makes: the rotating ring pays 71 readings for its overlap
    assert designs.get("rotating12").hardware_time_s() == pytest.approx(71 * 0.0383)


def test_parametric_rebuilds_the_papers_ring():
    d = designs.parametric(12, 0.15, 37.8 * DEG, 1.08 * DEG)
    assert d.ring.min_step == -35 and d.ring.max_step == 35
    for f in ("sensors", "radius_m", "gear", "min_step", "max_step", "emitter_offset_m"):
        assert getattr(d.ring, f) == getattr(designs.PAPER_RING, f)
    assert d.ring.motor_step_rad == pytest.approx(designs.PAPER_RING.motor_step_rad)
    assert d.ring.joint_limit_rad == pytest.approx(designs.PAPER_RING.joint_limit_rad)


def test_parametric_full_turn_and_radial_and_errors():
    full = designs.parametric(1, 0.0, math.pi, 2 * DEG, "gp2y0a02")
    assert full.positions() == 180 and full.sensor.max_range_m == 1.5
    radial = designs.parametric(16, 0.2, 0.0, 1 * DEG)
    assert not radial.rotating and radial.ray_step_rad() == pytest.approx(22.5 * DEG)
    with pytest.raises(ValueError, match="unknown sensor kind 'gp2x'"):
        designs.parametric(12, 0.15, 0.5, 0.02, "gp2x")
    with pytest.raises(ValueError, match="ring.radius_m"):
        designs.parametric(12, 3.0, 0.5, 0.02)
    with pytest.raises(ValueError, match="unknown design 'rotating13'.*rotating12"):
        designs.get("rotating13")


def test_scenario_names_a_design():
    sc = loads(T_ROOM % ("rotating1", ""))
    assert sc.ring == designs.get("rotating1").ring


def test_scenario_ring_numbers_override_the_named_design():
    sc = loads(T_ROOM % ("radial12", "ring: {sensors: 8, radius_mm: 120}"))
    assert sc.ring.sensors == 8 and sc.ring.radius_m == pytest.approx(0.12)
    assert sc.ring.min_step == sc.ring.max_step == 0     # still radial12's


def test_a_ring_number_the_file_gives_overrides_the_design_even_at_the_papers_value():
    """Only fields that differed from the paper's ring replaced a named design's: radial12
    with `ring: {min_step: -35, max_step: 35}` stayed still (steps 0 … 0), rotating1 with
    `ring: {sensors: 12, radius_mm: 150}` stayed one sensor at the centre, and laser with
    `gear: 0.6` kept its 1.0, all without a word."""
    sc = loads(T_ROOM % ("radial12", "ring: {min_step: -35, max_step: 35}"))
    assert (sc.ring.min_step, sc.ring.max_step) == (-35, 35)
    assert sc.ring.radius_m == designs.get("radial12").ring.radius_m
    sc = loads(T_ROOM % ("rotating1", "ring: {sensors: 12, radius_mm: 150, joint_limit_deg: 360}"))
    assert (sc.ring.sensors, sc.ring.radius_m, sc.ring.max_step) == (12, 0.15, 333)
    laser = designs.get("laser").ring
    sc = loads(T_ROOM % ("laser", "ring: {gear: 0.6, max_step: 700}"))
    assert (sc.ring.gear, sc.ring.max_step, sc.ring.motor_step_rad) == (0.6, 700,
                                                                       laser.motor_step_rad)
    # the same scenario text read again is the same scene (what recordings and workers get)
    assert loads(sc.text) == sc


def test_custom_design_takes_the_ring_as_written_and_needs_one():
    sc = loads(T_ROOM % ("custom", "ring: {sensors: 6, min_step: -10, max_step: 10}"))
    assert (sc.ring.sensors, sc.ring.min_step, sc.ring.max_step) == (6, -10, 10)
    with pytest.raises(ScenarioError, match="robot.ring: required when robot.design is custom"):
        loads(T_ROOM % ("custom", ""))


def test_apply_keeps_the_scene_and_swaps_the_robot():
    sc = load_scenario("t_room_cylinder")
    assert scenario.design_for(sc).name == "rotating12"
    other = scenario.apply_design(sc, "radial12")
    assert other.ring == designs.get("radial12").ring
    assert other.robot.design == "radial12"
    assert scenario.design_for(other).name == "radial12"
    for f in ("room", "obstacles", "map", "seed", "scan"):
        assert getattr(other, f) == getattr(sc, f)
    assert other.robot.poses == sc.robot.poses
    assert dict(other.effects) == dict(sc.effects)       # a GP2 ring keeps the scene's effects
    custom = scenario.apply_design(sc, designs.parametric(8, 0.15, 30 * DEG, 1.08 * DEG))
    assert custom.robot.design == "custom" and custom.ring.sensors == 8


def test_apply_gives_laser_and_sonar_their_own_sensor_and_noise():
    from irring import gp2

    sc = load_scenario("t_room_cylinder")
    for name in ("laser", "sonar12"):
        d = designs.get(name)
        other = scenario.apply_design(sc, name)
        assert other.sensor.model == d.sensor.kind
        assert other.sensor.max_range_m == d.sensor.max_range_m
        assert other.sensor.adc_bits == 16
        # the scene's GP2 noise (volts) became the design's range noise through the curve
        model = gp2.sensor(d.sensor.kind)
        sigma_m = other.effects["noise"].sigma_v * model.a0  # linear: d = a·V
        assert sigma_m == pytest.approx(d.sensor.noise_sigma_m, rel=1e-3)
        assert other.effects["incidence"].max_incidence_rad is None  # the sensor's own limit
        assert "quantization" in other.effects
