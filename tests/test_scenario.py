"""Scenario files: the bundled ones are the paper's, units convert once, mistakes are errors.

Every bad file below must fail with a message that names the YAML key path and says what
is allowed — a typo never becomes a silent default.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import re
import typing

import numpy as np
import pytest

from irring import designs, gp2, resources
from irring import scenario as S
from irring.scenario import ScenarioError, load_scenario, loads, parse


def _set(raw: dict, path: str, value=None, *, delete: bool = False) -> dict:
    *parents, last = path.split(".")
    node = raw
    for key in parents:
        node = node[int(key)] if isinstance(node, list) else node[key]
    if delete:
        del node[last]
    else:
        node[last] = value
    return raw


# (id, how to break t_room.yaml, patterns the message must contain)
BAD = [
    ("unknown top-level key", lambda r: _set(r, "rooom", {}),
     [r"^bad\.yaml: rooom: unknown key", r"did you mean `room`", r"allowed here: .*robot, room"]),
    ("typo in a nested key", lambda r: _set(r, "room.wall_heigth_mm", 300),
     [r"room\.wall_heigth_mm: unknown key", r"did you mean `wall_height_mm`",
      r"allowed here: .*wall_height_mm"]),
    # it said "did you mean `radius_m`": followed, radius_cm: 3 became a 3 m post
    ("a length in centimetres", lambda r: _set(r, "obstacles", [{"type": "cylinder",
                                                               "center_mm": [500, 300],
                                                               "radius_cm": 3}]),
     [r"obstacles\[0\]\.radius_cm: unknown key \(a unit irring does not read; write "
      r"`radius_mm` or `radius_m`\); allowed here: center_m, center_mm, radius_m, radius_mm"]),
    # `radius: 22` said "did you mean `radius_m`" (a 22 m post), `x: 500` nothing at all
    ("a length without its unit", lambda r: _set(r, "obstacles", [{"type": "cylinder",
                                                                 "center_mm": [500, 300],
                                                                 "radius": 22}]),
     [r"obstacles\[0\]\.radius: unknown key \(a quantity is written with its unit: "
      r"`radius_mm` or `radius_m`\); allowed here: center_m, center_mm, radius_m, radius_mm"]),
    ("a position without its unit", lambda r: _set(r, "robot.poses", [{"x": 500, "y_mm": 450}]),
     [r"robot\.poses\[0\]\.x: unknown key \(a quantity is written with its unit: `x_mm` or "
      r"`x_m`\)"]),
    ("an angle spelt out", lambda r: _set(r, "robot.poses.0.yaw_degrees", 30),
     [r"robot\.poses\[0\]\.yaw_degrees: unknown key \(a unit irring does not read; write "
      r"`yaw_deg` or `yaw_rad`\)"]),
    ("text where a number belongs", lambda r: _set(r, "seed", "abc"),
     [r"seed: expected a whole number, got 'abc'"]),
    ("true where a number belongs", lambda r: _set(r, "room.wall_height_mm", True),
     [r"room\.wall_height_mm: expected a number, got True"]),
    ("value out of range, in the unit written", lambda r: _set(r, "sensor.max_range_mm", 50000),
     [r"sensor\.max_range_mm: 50000 mm is out of range; allowed 20 … 30000 mm"]),
    ("negative radius", lambda r: _set(r, "obstacles", [{"type": "cylinder",
                                                        "center_mm": [500, 300],
                                                        "radius_mm": -5}]),
     [r"obstacles\[0\]\.radius_mm: -5 mm is out of range; allowed 2 … 2000 mm"]),
    # shown as written: in metres 5e-324 mm is 0, and the message read "0 mm"
    ("a subnormal radius", lambda r: _set(r, "obstacles", [{"type": "cylinder",
                                                           "center_mm": [500, 300],
                                                           "radius_mm": 5e-324}]),
     [r"obstacles\[0\]\.radius_mm: 5e-324 mm is out of range; allowed 2 … 2000 mm$"]),
    ("a subnormal resolution", lambda r: _set(r, "map.resolution_mm", 1e-320),
     [r"map\.resolution_mm: 1e-320 mm is out of range; allowed 1 … 500 mm$"]),
    # in the unit its key names: 1e307 m read "inf mm", 9000 mm/s "9.0 … allowed 0 … 5"
    ("a size in metres past float's mm",
     lambda r: _set(r, "sensor", {"model": "gp2d12", "max_range_m": 1e307}),
     [r"sensor\.max_range_m: 1e\+307 m is out of range; allowed 0\.02 … 30 m$"]),
    ("a speed in mm/s", lambda r: _set(r, "effects", {"motion": {
        "path": [{"x_mm": 500, "y_mm": 450}, {"x_mm": 600, "y_mm": 450}],
        "speed_mm_s": 9000}}),
     [r"effects\.motion\.speed_mm_s: 9000 mm/s is out of range; allowed 0 … 5000 mm/s$"]),
    ("not a known sensor", lambda r: _set(r, "sensor.model", "gp2d13"),
     [r"sensor\.model: 'gp2d13' is not allowed; choose one of: gp2d12, .*laser"]),
    ("not a known design", lambda r: _set(r, "robot.design", "rotating13"),
     [r"robot\.design: 'rotating13' is not allowed; choose one of: rotating12, .*custom"]),
    ("required key missing", lambda r: _set(r, "room.outline_mm", delete=True),
     [r"room\.outline_m or outline_mm: required key is missing"]),
    ("self-intersecting outline",
     lambda r: _set(r, "room.outline_mm", [[0, 0], [2000, 2000], [2000, 0], [0, 2000]]),
     [r"room\.outline_mm: walls 0 and 2 cross: the outline must not intersect itself"]),
    ("a wall doubling back over the last",   # no proper crossing: it used to run
     lambda r: _set(r, "room.outline_mm", [[0, 0], [2420, 0], [2420, 900], [1800, 900],
                                           [2200, 900], [0, 900]]),
     [r"room\.outline_mm: wall 2 \(\(2420, 900\) → \(1800, 900\) mm\) and wall 3 "
      r"\(\(1800, 900\) → \(2200, 900\) mm\) overlap along 400 mm: a wall must not run back "
      r"over another$"]),
    ("a wall running back over one far from it",
     lambda r: _set(r, "room.outline_mm", [[0, 0], [2420, 0], [2420, 900], [1200, 900],
                                           [1200, 1500], [600, 1500], [600, 900], [1400, 900],
                                           [1400, 600], [0, 600]]),
     [r"room\.outline_mm: wall 2 \(.*\) and wall 6 \(\(600, 900\) → \(1400, 900\) mm\) "
      r"overlap along 200 mm"]),
    ("three corners on one line (no area)",   # was: "pose (1210, 450) mm is outside"
     lambda r: _set(r, "room.outline_mm", [[0, 0], [1000, 0], [2400, 0]]),
     [r"room\.outline_mm: all 3 corners lie on one line, so the outline encloses no room; "
      r"list the corners of an area$"]),
    ("a sloped outline of no area",
     lambda r: _set(r, "room.outline_mm", [[10, 20], [1210, 920], [410, 320], [2410, 1820]]),
     [r"room\.outline_mm: all 4 corners lie on one line"]),
    ("a description of a megabyte",   # printed whole by every run
     lambda r: _set(r, "description", "d" * 1_000_001),
     [r"description: 1,000,001 characters; a description is a line of at most 1,000 "
      r"\(irring run and irring scenarios print it\)$"]),
    ("more obstacles than a scene takes",   # 20,000 took 3 min to score
     lambda r: _set(r, "obstacles", [{"type": "cylinder", "center_mm": [1000 + i % 40,
                                                                       700 + i // 40],
                                      "radius_mm": 2} for i in range(10_001)]),
     [r"obstacles: 10,001 obstacles; at most 10,000 are allowed$"]),
    ("outline of two corners", lambda r: _set(r, "room.outline_mm", [[0, 0], [2000, 2000]]),
     [r"room\.outline_mm: needs at least 3 corners, got 2"]),
    ("a corner with three numbers",
     lambda r: _set(r, "room.outline_mm", [[0, 0, 0], [2000, 0], [2000, 2000]]),
     [r"room\.outline_mm\[0\]: expected 2 numbers, got 3"]),
    ("pose outside the room", lambda r: _set(r, "robot.poses", [{"x_mm": 3000, "y_mm": 450}]),
     [r"robot\.poses\[0\]: pose \(3000, 450\) mm is outside the room"]),
    ("pose inside a wall", lambda r: _set(r, "robot.poses", [{"x_mm": 100, "y_mm": 450}]),
     [r"robot\.poses\[0\]: the ring \(radius 170 mm with housing\) would be inside a wall"]),
    ("pose on an obstacle",
     lambda r: _set(r, "obstacles", [{"type": "cylinder", "center_mm": [1950, 450],
                                      "radius_mm": 30}]),
     [r"robot\.poses\[0\]: the ring .* would overlap obstacles\[0\] \(cylinder at "
      r"\(1950, 450\) mm\); keep the pose ≥ 170 mm from it"]),
    ("obstacle outside the room",
     lambda r: _set(r, "obstacles", [{"type": "cylinder", "center_mm": [5000, 450],
                                      "radius_mm": 30}]),
     [r"obstacles\[0\]\.center_mm: the cylinder \(radius 30 mm\) at \(5000, 450\) mm lies "
      r"wholly outside the room"]),
    ("a box wholly outside the room, past a wall",
     lambda r: _set(r, "obstacles", [{"type": "box", "center_mm": [2600, 300],
                                      "size_mm": [300, 200]}]),
     [r"obstacles\[0\]\.center_mm: the box \(300 × 200 mm\) at \(2600, 300\) mm lies wholly "
      r"outside the room; an obstacle must stand at least partly inside it \(what reaches "
      r"beyond a wall is ignored\)$"]),
    ("a cylinder outside touching a wall",
     lambda r: _set(r, "obstacles", [{"type": "cylinder", "center_mm": [500, 960],
                                      "radius_mm": 60}]),
     [r"obstacles\[0\]\.center_mm: the cylinder \(radius 60 mm\) at \(500, 960\) mm lies "
      r"wholly outside the room"]),
    ("unknown obstacle type",
     lambda r: _set(r, "obstacles", [{"type": "sphere", "center_mm": [500, 450],
                                      "radius_mm": 30}]),
     [r"obstacles\[0\]\.type: 'sphere' is not allowed; choose one of: cylinder, box"]),
    ("flat box", lambda r: _set(r, "obstacles", [{"type": "box", "center_mm": [300, 700],
                                                  "size_mm": [0, 40]}]),
     [r"obstacles\[0\]\.size_mm: box sides \(0, 40\) mm must each be ≥ 2 mm"]),
    ("unknown effect", lambda r: _set(r, "effects.nosie", {}),
     [r"effects\.nosie: unknown effect \(did you mean `noise`\?\); allowed: incidence, noise"]),
    ("effect parameter out of range", lambda r: _set(r, "effects.noise", {"sigma_v": 5}),
     [r"effects\.noise\.sigma_v: 5\.0 is out of range; allowed 0 … 1"]),
    ("a quantity in two units", lambda r: _set(r, "map", {"resolution_mm": 10,
                                                          "resolution_m": 0.01}),
     [r"map\.resolution_m: resolution_m given twice \(in two units\)"]),
    ("no poses", lambda r: _set(r, "robot.poses", []),
     [r"robot\.poses: at least one scan pose is required"]),
    ("steps the wrong way round",
     lambda r: _set(r, "robot", {"design": "custom", "ring": {"min_step": 10, "max_step": -10},
                                 "poses": r["robot"]["poses"]}),
     [r"robot\.ring\.min_step: min_step 10 > max_step -10"]),
    ("sweep past the joint limit on the negative side",
     lambda r: _set(r, "robot", {"design": "custom", "ring": {"min_step": -50, "max_step": 10},
                                 "poses": r["robot"]["poses"]}),
     [r"robot\.ring: the sweep turns the sensors to ±54° \(steps -50 … 10 × 1\.8° × gear "
      r"0\.6\) but joint_limit is ±37\.8°"]),
    ("sweep past the joint limit on the positive side",
     lambda r: _set(r, "robot", {"design": "custom", "ring": {"min_step": -10, "max_step": 60},
                                 "poses": r["robot"]["poses"]}),
     [r"robot\.ring: the sweep turns the sensors to ±64\.8° \(steps -10 … 60 "]),
    ("sensors above the walls",
     lambda r: _set(r, "robot", {"design": "custom", "ring": {"sensor_height_mm": 400},
                                 "poses": r["robot"]["poses"]}),
     [r"robot\.ring\.sensor_height_mm: sensors at 400 mm would look over the 300 mm walls"]),
    ("not a number at all", lambda r: _set(r, "room.wall_height_mm", float("nan")),
     [r"room\.wall_height_mm: expected a finite number, got nan"]),
    ("a mapping where a list belongs", lambda r: _set(r, "robot.poses", {"x_mm": 1}),
     [r"robot\.poses: expected a list"]),
    ("an effect's parameter without its key", lambda r: _set(r, "effects.noise", 0.02),
     [r"effects\.noise: expected a mapping of keys, got 0\.02; allowed here: sigma_v$"]),
    ("a number for an effect that has no keys", lambda r: _set(r, "effects.quantization", 12),
     [r"effects\.quantization: expected a mapping of keys, got 12; allowed here: none, write "
      r"\{\} for the defaults$"]),
    ("corners where the room's mapping belongs",
     lambda r: _set(r, "room", [[0, 0], [2000, 0], [2000, 900]]),
     [r"room: expected a mapping of keys, got \[\[0, 0\], .*; allowed here: outline_m, "
      r"outline_mm, reflectance"]),
]


@pytest.mark.parametrize("case", BAD, ids=[c[0] for c in BAD])
def test_bad_scenario_gives_a_clear_error(t_room_raw, case):
    _, mutate, patterns = case
    with pytest.raises(ScenarioError) as info:
        parse(mutate(t_room_raw), "bad.yaml")
    message = str(info.value)
    assert message.startswith("bad.yaml: ")
    for pattern in patterns:
        assert re.search(pattern, message), f"{pattern!r} not in {message!r}"


def test_there_are_at_least_ten_kinds_of_mistake():
    assert len(BAD) >= 10


def test_broken_files_name_the_file(tmp_path):
    with pytest.raises(ScenarioError, match=r"x\.yaml: line 2: not valid YAML"):
        loads("room: [\n", "x.yaml")
    with pytest.raises(ScenarioError, match=r"a scenario file must be a mapping"):
        loads("- 1\n- 2\n", "x.yaml")
    with pytest.raises(ScenarioError, match=r"no such file .* bundled: .*t_room"):
        load_scenario(tmp_path / "missing.yaml")
    path = tmp_path / "typo.yaml"
    path.write_text("name: x\nroom: {outline_mm: [[0, 0], [1000, 0], [1000, 1000]]}\n"
                    "robot: {poses: [{x_mm: 600, y_mm: 300}]}\nsensr: {}\n")
    with pytest.raises(ScenarioError, match=rf"^{re.escape(str(path))}: sensr: unknown key"):
        load_scenario(path)


def test_bundled_t_room_is_the_papers():
    sc = load_scenario("t_room")
    # a 2420 × 900 mm bar with a 900 × 900 mm stem centred on it: 760 mm shoulders
    np.testing.assert_allclose(sc.room.outline_m, [(0, 0), (2.42, 0), (2.42, 0.9), (1.66, 0.9),
                                                   (1.66, 1.8), (0.76, 1.8), (0.76, 0.9), (0, 0.9)],
                               atol=1e-12)
    x = [p.x_m for p in sc.robot.poses]
    y = [p.y_m for p in sc.robot.poses]
    assert x[0] > x[1] > x[2] and y[0] == y[1] == y[2] < 0.9 < y[3]  # lower R, C, L, top
    assert x[3] == pytest.approx((0.76 + 1.66) / 2)
    assert sc.ring == designs.PAPER_RING
    assert sc.sensor.max_range_m == pytest.approx(0.624)
    assert sc.map.resolution_m == pytest.approx(0.010)
    assert set(sc.effects) == {"incidence", "noise", "quantization"}


@pytest.mark.parametrize("name", sorted(S.bundled()))
def test_every_bundled_scenario_loads_and_says_what_the_paper_leaves_open(name):
    sc = load_scenario(name)
    assert sc.name == name and sc.description
    header = S.resolve(name).read_text().split("\nname:")[0]
    assert "Not given by the paper" in header


def test_units_convert_once_at_load(t_room_raw):
    a = parse(t_room_raw, "a.yaml")
    t_room_raw["room"] = {"outline_m": [[x / 1e3, y / 1e3] for x, y in
                                         t_room_raw["room"]["outline_mm"]],
                          "wall_height_m": 0.3}
    t_room_raw["robot"]["poses"] = [{"x_m": p["x_mm"] / 1e3, "y_m": p["y_mm"] / 1e3,
                                     "yaw_rad": 0.0} for p in t_room_raw["robot"]["poses"]]
    t_room_raw["robot"]["ring"] = {"joint_limit_rad": math.radians(37.8)}
    t_room_raw["sensor"]["max_range_m"] = t_room_raw["sensor"].pop("max_range_mm") / 1e3
    b = parse(t_room_raw, "b.yaml")
    np.testing.assert_allclose(b.room.outline_m, a.room.outline_m, atol=1e-12)
    assert b.robot.poses == a.robot.poses and b.sensor == a.sensor
    assert b.ring == a.ring
    c = loads("name: d\nroom: {outline_mm: [[0, 0], [2000, 0], [2000, 2000]]}\n"
              "robot: {poses: [{x_mm: 1400, y_mm: 500, yaw_deg: 90}]}\n"
              "scan: {settle_ms: 40}\n")
    assert c.robot.poses[0].yaw_rad == pytest.approx(math.pi / 2)
    assert c.scan.settle_s == pytest.approx(0.04)


def test_effects_as_a_list_are_the_defaults(t_room_raw):
    t_room_raw["effects"] = ["incidence", "noise"]
    sc = parse(t_room_raw)
    assert dict(sc.effects) == {"incidence": S.IncidenceEffect(), "noise": S.NoiseEffect()}
    with pytest.raises(TypeError):
        sc.effects["foldover"] = S.FoldoverEffect()  # read-only


def test_a_list_left_empty_is_empty_as_a_section_left_empty_is(t_room_raw):
    """`effects:` with nothing after it meant no effects, `obstacles:` was refused ("expected
    a list, got None"): a key left empty is now its empty value, list or mapping alike."""
    t_room_raw["obstacles"] = None
    t_room_raw["effects"] = None
    sc = parse(t_room_raw)
    assert sc.obstacles == () and dict(sc.effects) == {}
    t_room_raw["obstacles"] = [{"type": "cylinder", "center_mm": [2170, 220], "radius_mm": 22}]
    assert len(parse(t_room_raw).obstacles) == 1
    for path, value, message in [
            ("robot.poses", None, "robot.poses: at least one scan pose is required"),
            ("room.outline_mm", None, "room.outline_mm: needs at least 3 corners, got 0"),
            ("obstacles.0.center_mm", None, "obstacles[0].center_mm: expected a list, got None"),
            ("obstacles", {}, "obstacles: expected a list, got {}"),
            ("seed", None, "seed: expected a whole number, got None")]:
        raw = _set(copy.deepcopy(t_room_raw), path, value)
        with pytest.raises(ScenarioError, match=f"^{re.escape(message)}$"):
            parse(raw)


@pytest.mark.parametrize("design, kind", [("laser", "laser"), ("sonar12", "sonar")])
def test_a_non_ir_design_brings_its_own_sensor(t_room_raw, design, kind):
    t_room_raw["robot"]["design"] = design
    t_room_raw.pop("sensor", None)
    sc = parse(t_room_raw)
    assert sc.sensor.model == kind
    assert sc.sensor.max_range_m > 1.0  # not the GP2D12's 0.624 m
    t_room_raw["sensor"] = {"model": "gp2d12"}
    with pytest.raises(ScenarioError, match=r"sensor\.model: 'gp2d12' does not fit design "
                                            f"'{design}'.*model: {kind}"):
        parse(t_room_raw)


@pytest.mark.parametrize("model, expected_m", [("gp2d12", 0.624), ("gp2y0a21", 0.8),
                                               ("gp2y0a02", 1.5), ("laser", 8.0),
                                               ("sonar", 6.45)])
def test_a_sensor_block_without_a_range_reads_to_its_models_range(t_room_raw, model,
                                                                  expected_m):
    """The GP2D12 to the paper's 624 mm, every other part to its curve's end (a GP2Y0A02
    read to 624 mm saw 40 % of its range); a range the file names is kept, in either unit."""
    t_room_raw["sensor"] = {"model": model, "adc_bits": 10}
    sc = parse(t_room_raw)
    assert sc.sensor.max_range_m == gp2.sensor_spec(model).max_range_m == expected_m
    assert sc.sensor.adc_bits == 10
    t_room_raw["sensor"] = {"model": model, "max_range_mm": 431}
    assert parse(t_room_raw).sensor.max_range_m == pytest.approx(0.431)
    t_room_raw["sensor"] = {"model": model, "max_range_m": 0.624}
    assert parse(t_room_raw).sensor.max_range_m == 0.624


def test_no_sensor_block_is_the_papers_gp2d12_to_624_mm(t_room_raw):
    t_room_raw.pop("sensor", None)
    assert parse(t_room_raw).sensor == S.Sensor(model="gp2d12", max_range_m=0.624)


# --------------------------------------------------------------------------- the user docs

README = resources.scenarios_dir() / "README.md"


def _yaml_examples() -> list[str]:
    blocks = re.findall(r"```yaml\n(.*?)```", README.read_text(), flags=re.S)
    return [b for b in blocks if b.lstrip().startswith("name:")]


@pytest.mark.parametrize("text", _yaml_examples(), ids=lambda t: t.split("\n", 1)[0])
def test_readme_examples_load(text):
    sc = loads(text, "README example")
    assert sc.robot.poses


def _schema_keys() -> set[str]:
    classes = [S.Scenario, S.Room, S.Cylinder, S.Box, S.Robot, S.Pose, S.Ring, S.Sensor, S.Scan,
               S.MapSpec, S.Waypoint, *S.EFFECTS.values()]
    keys = set(S.EFFECTS)
    for cls in classes:
        for f in dataclasses.fields(cls):
            if f.name not in S.NOT_IN_FILE:
                keys.update(k for k, _ in S._yaml_keys(f.name))
    return keys


def test_readme_documents_every_key_in_every_unit():
    """If this fails, a schema key was added without documenting it in scenarios/README.md."""
    text = README.read_text()
    missing = sorted(k for k in _schema_keys() if f"`{k}`" not in text)
    assert not missing, f"scenarios/README.md does not document: {', '.join(missing)}"


def test_readme_defaults_match_the_schema():
    """Spot checks of the numbers a user is most likely to rely on."""
    text = README.read_text()
    for row in ("| `sensors` | whole number | 1 … 72 | 12 |",
                "| 150 mm |", "| 1.8° |", "| 0.6 |", "| −35, 35 |", "| 7 mm |", "| 37.8° |",
                "| the model's: 624 mm for `gp2d12` (the paper's)", "| 10 mm |"):
        assert row in text, row
    ring = S.Ring()
    assert (ring.sensors, ring.radius_m, ring.gear, ring.min_step, ring.max_step) == \
        (12, 0.15, 0.6, -35, 35)
    assert ring.emitter_offset_m == 0.007 and math.degrees(ring.joint_limit_rad) == \
        pytest.approx(37.8) and math.degrees(ring.motor_step_rad) == pytest.approx(1.8)
    assert S.Sensor().max_range_m == 0.624 and S.MapSpec().resolution_m == 0.010
    hints = typing.get_type_hints(S.Room)
    assert hints["outline_m"] == tuple[tuple[float, float], ...]


def test_the_scenarios_readme_table_lists_every_bundled_scenario():
    """scenarios/README.md's table: one row per bundled file, with its poses and obstacles."""
    text = (resources.scenarios_dir() / "README.md").read_text()
    rows = {m.group(1): (m.group(2), m.group(3)) for m in re.finditer(
        r"^\| `(\w+)\.yaml` \| [^|]+ \| (\d+) \| (\d+|–) \|$", text, flags=re.MULTILINE)}
    bundled = S.bundled()
    assert sorted(rows) == sorted(bundled)
    for name, (poses, obstacles) in rows.items():
        sc = load_scenario(bundled[name])
        assert int(poses) == len(sc.robot.poses), name
        assert (0 if obstacles == "–" else int(obstacles)) == len(sc.obstacles), name


def _hall(poses, obstacles=()) -> dict:
    """A 1400 × 1200 mm room (asymmetric) with the paper's ring at ``poses``."""
    return {"name": "edge", "room": {"outline_mm": [[0, 0], [1400, 0], [1400, 1200], [0, 1200]]},
            "robot": {"poses": [{"x_mm": x, "y_mm": y} for x, y in poses]},
            "obstacles": list(obstacles)}


# Surfaces exactly 170 mm (ring radius + housing) from the pose: what the message allows.
AT_THE_LIMIT = {
    "post east": _hall([(700, 600)], [{"type": "cylinder", "center_mm": [890, 600],
                                       "radius_mm": 20}]),
    "post south": _hall([(700, 600)], [{"type": "cylinder", "center_mm": [700, 405],
                                        "radius_mm": 25}]),
    "box face west": _hall([(700, 600)], [{"type": "box", "center_mm": [510, 600],
                                           "size_mm": [40, 90]}]),
    "walls north-east": _hall([(1230, 1030)]),
    "wall west": _hall([(170, 610)]),
}


@pytest.mark.parametrize("name", AT_THE_LIMIT)
def test_a_surface_exactly_at_the_housing_is_allowed(name):
    sc = parse(AT_THE_LIMIT[name], "edge.yaml")
    assert len(sc.robot.poses) == 1


@pytest.mark.parametrize("name, raw, pattern", [
    ("post 0.01 mm inside", _hall([(700, 600)], [{"type": "cylinder", "center_mm": [700, 405.01],
                                                  "radius_mm": 25}]),
     r"edge\.yaml: robot\.poses\[0\]: the ring \(radius 170 mm with housing\) at \(700, 600\) mm "
     r"would overlap obstacles\[0\] \(cylinder at \(700, 405\.01\) mm\); keep the pose ≥ 170 mm "
     r"from it$"),
    ("wall 0.01 mm inside", _hall([(1230.01, 600)]),
     r"edge\.yaml: robot\.poses\[0\]: the ring \(radius 170 mm with housing\) would be inside a "
     r"wall at \(1230\.01, 600\) mm; keep the pose ≥ 170 mm from every wall$"),
])
def test_a_surface_just_inside_the_housing_is_refused(name, raw, pattern):
    with pytest.raises(ScenarioError, match=pattern):
        parse(raw, "edge.yaml")


# --------------------------------------------------------------------------- big outlines


def _ellipse_mm(n: int, cx=1210.0, cy=450.0, rx=800.0, ry=400.0) -> list:
    return [[cx + rx * math.cos(2 * math.pi * k / n), cy + ry * math.sin(2 * math.pi * k / n)]
            for k in range(n)]


def test_an_outline_of_more_corners_than_allowed_is_refused_naming_the_key(t_room_raw):
    """100 000 corners (4.8 MB of YAML) kept the loader checking wall pairs for hours."""
    _set(t_room_raw, "room.outline_mm", _ellipse_mm(10_001))
    _set(t_room_raw, "robot.poses", [{"x_mm": 1210, "y_mm": 450}])
    with pytest.raises(ScenarioError, match=r"bad\.yaml: room\.outline_mm: 10,001 corners; at "
                                            r"most 10,000 are allowed"):
        parse(t_room_raw, "bad.yaml")


def test_a_crossing_in_the_largest_outline_allowed_is_found_and_named(t_room_raw):
    outline = _ellipse_mm(10_000)
    outline[7000], outline[7001] = outline[7001], outline[7000]   # a twist near the end
    _set(t_room_raw, "room.outline_mm", outline)
    _set(t_room_raw, "robot.poses", [{"x_mm": 1210, "y_mm": 450}] * 3 + [{"x_mm": 1211,
                                                                          "y_mm": 451}])
    with pytest.raises(ScenarioError, match=r"room\.outline_mm: walls 6999 and 7001 cross"):
        parse(t_room_raw, "bad.yaml")
    outline[7000], outline[7001] = outline[7001], outline[7000]
    sc = parse(t_room_raw, "ok.yaml")
    assert len(sc.room.outline_m) == 10_000 and len(sc.robot.poses) == 4


def _crossing_oracle(outline):
    """The loader's former pairwise check, pair by pair in Python."""
    def orient(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])

    n = len(outline)
    for i in range(n):
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue
            p1, p2, q1, q2 = outline[i], outline[(i + 1) % n], outline[j], outline[(j + 1) % n]
            if orient(q1, q2, p1) * orient(q1, q2, p2) < 0 and \
                    orient(p1, p2, q1) * orient(p1, p2, q2) < 0:
                return i, j
    return None


def test_first_crossing_finds_the_pair_the_pairwise_oracle_finds():
    from irring.core import first_crossing

    rng = np.random.default_rng(7)
    found = 0
    for trial in range(600):
        n = int(rng.integers(3, 14))
        pts = (rng.integers(0, 5, (n, 2)).astype(float) if trial % 2   # touching, collinear
               else rng.uniform(-1.0, 2.0, (n, 2)))
        outline = [tuple(p) for p in pts]
        assert first_crossing(outline) == _crossing_oracle(outline), outline
        found += _crossing_oracle(outline) is not None
    assert 100 < found < 550   # both outcomes are exercised


def _overlap_oracle(outline):
    """Walls (i, j) on one line sharing a stretch > 1 µm, pair by pair in Python (exact
    fractions: integer corners)."""
    from fractions import Fraction

    n = len(outline)
    for i in range(n):
        for j in range(i + 1, n):
            p, q = outline[i], outline[(i + 1) % n]
            r, t = outline[j], outline[(j + 1) % n]
            d = (q[0] - p[0], q[1] - p[1])
            if any(d[0] * (w[1] - p[1]) - d[1] * (w[0] - p[0]) for w in (r, t)):
                continue
            dd = d[0] ** 2 + d[1] ** 2
            s_r = Fraction(int((r[0] - p[0]) * d[0] + (r[1] - p[1]) * d[1]), int(dd))
            s_t = Fraction(int((t[0] - p[0]) * d[0] + (t[1] - p[1]) * d[1]), int(dd))
            if min(1, max(s_r, s_t)) - max(0, min(s_r, s_t)) > 0:
                return i, j
    return None


def test_first_overlap_finds_the_pair_the_pairwise_oracle_finds():
    from irring.core import first_overlap

    rng = np.random.default_rng(11)
    found = 0
    for trial in range(600):
        n = int(rng.integers(3, 12))
        pts = rng.integers(0, 4, (n, 2)).astype(float)   # small grid: many collinear walls
        keep = np.any(pts != np.roll(pts, -1, axis=0), axis=1)
        outline = [tuple(p) for p in pts[keep]]
        if len(outline) < 3:
            continue
        got = first_overlap(outline)
        assert (got and got[:2]) == _overlap_oracle(outline), outline
        found += got is not None
    assert 100 < found < 500   # both outcomes are exercised
    # walls that meet end to end along one line, or touch at a corner, do not overlap
    assert first_overlap([(0, 0), (1, 0), (2, 0), (2, 1), (1, 1), (1, 0.5), (0, 1)]) is None
    assert first_overlap([(0, 0), (2, 0), (2, 2), (1, 0), (0, 2)]) is None


def test_an_outline_with_a_corner_midway_along_a_wall_still_loads(t_room_raw):
    _set(t_room_raw, "room.outline_mm", [[0, 0], [1000, 0], [2420, 0], [2420, 900],
                                         [1660, 900], [1660, 1800], [760, 1800], [760, 900],
                                         [0, 900]])
    assert len(parse(t_room_raw, "ok.yaml").room.outline_m) == 9


def test_an_obstacle_reaching_through_a_wall_loads_and_is_clipped_at_the_wall(t_room_raw):
    """A partition built into a wall, a pillar centred on one, a box flush in a corner (rooms
    people write): they load; the ground truth holds no obstacle beyond the walls (before:
    the pillar's outer half was occupied truth up to the map's edge, 100 mm outside) and no
    wall face inside one."""
    from irring.maps import metrics
    from irring.maps.mapping import OccupancyGrid

    _set(t_room_raw, "obstacles", [
        {"type": "box", "center_mm": [1180, 1350], "size_mm": [860, 30]},    # into x = 760
        {"type": "box", "center_mm": [2420, 300], "size_mm": [300, 200]},    # on wall 1
        {"type": "cylinder", "center_mm": [2420, 700], "radius_mm": 40},     # on wall 1
        {"type": "box", "center_mm": [100, 60], "size_mm": [200, 120]}])     # flush, corner
    _set(t_room_raw, "robot.poses", [{"x_mm": 1210, "y_mm": 450}])
    sc = parse(t_room_raw, "ok.yaml")
    assert len(sc.obstacles) == 4
    grid = OccupancyGrid.for_scenario(sc)   # 100 mm beyond the walls' inner face
    truth = metrics.ground_truth(sc, grid)
    xs, ys = grid.cell_centers()
    px, py = np.meshgrid(xs, ys)
    beyond = S.distance_to_outline(px, py, sc.room.outline_m) > sc.room.wall_thickness_m + 0.01
    beyond &= ~S.inside_outline(px, py, sc.room.outline_m)
    assert not (truth.occupied & beyond).any()
    assert not (truth.label >= metrics.OBSTACLE0)[beyond].any()
    pillar_in_room = (np.abs(px - 2.345) < 0.06) & (np.abs(py - 0.3) < 0.09)
    assert (truth.label[pillar_in_room] == metrics.OBSTACLE0 + 1).all()
    assert beyond[(np.abs(px - 2.5) < 0.015) & (np.abs(py - 0.3) < 0.09)].all()   # judged there
    # the wall the pillar is built into is no face to see (before: it was shadow to map)
    buried = (np.abs(px - 2.42) < 0.006) & (np.abs(py - 0.3) < 0.09)
    assert buried.sum() == 17   # y 0.22 … 0.38, one column
    assert not (truth.surface_owner == metrics.WALL)[buried].any()
    assert not truth.shadow[buried].any()


def test_an_obstacle_the_walls_clip_is_named_with_how_far_and_how_much(t_room_raw):
    """A mistyped centre put a box half through a wall and the scene loaded without a word.
    Each obstacle clipped by more than 1 mm is named: the walls it goes through, how far it
    reaches past them and the share of its footprint beyond; one written flush with a wall
    (exactly, or 0.5 mm past: rounding) is not."""
    _set(t_room_raw, "obstacles", [
        {"type": "box", "center_mm": [1100, 300], "size_mm": [200, 120]},    # inside
        {"type": "box", "center_mm": [1700, 950], "size_mm": [200, 120]},    # T's inner corner
        {"type": "box", "center_mm": [2270, 700], "size_mm": [300, 200]},    # flush, wall 1
        {"type": "box", "center_mm": [2320.5, 300], "size_mm": [200, 90]},   # 0.5 mm past
        {"type": "box", "center_mm": [400, 899.4], "size_mm": [120, 3]},     # 0.9 mm past
        {"type": "box", "center_mm": [300, 58], "size_mm": [50, 120]},       # 2 mm past wall 0
        {"type": "cylinder", "center_mm": [2435, 450], "radius_mm": 40}])    # centre outside
    _set(t_room_raw, "robot.poses", [{"x_mm": 1210, "y_mm": 1300}])
    sc = parse(t_room_raw, "ok.yaml")
    clipped = S.clipped_obstacles(sc)
    assert [c.index for c in clipped] == [1, 5, 6]
    corner, low, pillar = clipped
    assert corner.note == (
        "obstacles[1], a 200 × 120 mm box at (1700, 950) mm, reaches 110 mm through wall 2 "
        "((2420, 900) → (1660, 900) mm) and wall 3 ((1660, 900) → (1660, 1800) mm): 64.2% of "
        "it lies beyond the walls, clipped (never seen, not scored)")
    assert corner.walls == (2, 3) and corner.share == pytest.approx(140 * 110 / (200 * 120))
    assert low.walls == (0,) and low.reach_m == pytest.approx(0.002)
    assert low.share == pytest.approx(2 / 120)
    # all but the circle's segment 25 mm deep left in the room (the footprint a 360-gon)
    r, h = 0.040, 0.025
    segment = r * r * math.acos((r - h) / r) - (r - h) * math.sqrt(2 * r * h - h * h)
    assert pillar.share == pytest.approx(1 - segment / (math.pi * r * r), rel=1e-4)
    assert pillar.reach_m == pytest.approx(0.055, abs=1e-6) and pillar.walls == (1,)
    assert pillar.as_json() == {"obstacle": 6, "walls": [1], "reach_mm": 55.0,
                                "share_clipped": round(pillar.share, 4), "note": pillar.note}
    assert pillar.note.startswith("obstacles[6], a cylinder of radius 40 mm at (2435, 450) mm, "
                                  "reaches 55 mm through wall 1 ((2420, 0) → (2420, 900) mm): "
                                  "73.3% of it")


def test_first_wall_into_agrees_with_points_sampled_in_the_obstacle():
    """Random boxes and cylinders in the T-room: a wall comes into one exactly when some of
    its points (a fine grid over it) lie outside the room, away from the borderline."""
    from irring.core import (Box, Cylinder, distance_to_outline, first_wall_into,
                             inside_obstacle, inside_outline, obstacle_distance)

    outline = load_scenario("t_room").room.outline_m
    rng = np.random.default_rng(5)
    xs, ys = np.linspace(-0.2, 2.62, 1129), np.linspace(-0.2, 2.0, 881)
    counts = [0, 0]
    for trial in range(300):
        centre = (float(rng.uniform(0, 2.42)), float(rng.uniform(0, 1.8)))
        if not inside_outline(*centre, outline):
            continue
        ob = (Cylinder(centre, float(rng.uniform(0.01, 0.3))) if trial % 2 else
              Box(centre, (float(rng.uniform(0.01, 0.6)), float(rng.uniform(0.01, 0.3))),
                  float(rng.uniform(-3, 3))))
        # the grid's points within the obstacle's circumscribed circle, a step wider: the
        # same points inside it as the whole grid has, without judging a million others
        reach = (ob.radius_m if isinstance(ob, Cylinder) else math.hypot(*ob.size_m) / 2) + 0.01
        ix = slice(*np.searchsorted(xs, [centre[0] - reach, centre[0] + reach]))
        iy = slice(*np.searchsorted(ys, [centre[1] - reach, centre[1] + reach]))
        gx, gy = np.meshgrid(xs[ix], ys[iy])
        cells = inside_obstacle(ob, gx, gy)
        out = cells & ~inside_outline(gx, gy, outline)
        if (out.any() and np.max(-obstacle_distance(ob, gx[out], gy[out])) < 0.01) or \
                (not out.any() and np.min(distance_to_outline(gx[cells], gy[cells],
                                                              outline)) < 0.005):
            continue   # within a few grid cells of touching: the grid cannot judge it
        wall = first_wall_into(ob, outline)
        assert (wall is not None) == bool(out.any()), (ob, wall)
        counts[wall is not None] += 1
    assert min(counts) > 30   # both outcomes exercised


def test_a_changed_scenario_no_longer_claims_the_text_it_was_loaded_from():
    # dataclasses.replace keeps `text`: a scenario changed in code was recorded and shipped
    # to study workers as the file it came from (another seed rebuilt as seed 1, the ideal
    # sensor's scene rebuilt with incidence, noise and quantization)
    import dataclasses

    from irring.pipeline import scenario_text
    from irring.studies import rooms, study

    sc = load_scenario("t_room")
    assert scenario_text(sc) == sc.text and "incidence" in sc.text
    for changed in (dataclasses.replace(sc, seed=777), rooms.ideal(sc)):
        assert changed.text == sc.text
        assert scenario_text(changed) is None
    # a study of the changed scene carries it as itself, not as the file's text
    point = study.point(study.DesignSpec("rotating12"), sc, 3)
    task, = study.tasks_for([point], {point.scenario: rooms.ideal(sc)})
    assert task.scenario_yaml is None and not task.scenario.effects


def test_a_whole_number_bound_is_written_exactly(t_room_raw):
    """`seed: -3` said "allowed 0 … 9.22337e+18" where scenarios/README.md says 0 … 2⁶³−1:
    %g rounded the bound; a whole-number bound is written as it is."""
    for path, value, message in [
            ("seed", -3, "seed: -3 is out of range; allowed 0 … 9223372036854775807"),
            ("seed", 2 ** 63, "seed: 9223372036854775808 is out of range; allowed 0 … "
                              "9223372036854775807"),
            ("robot.ring", {"sensors": 73}, "robot.ring.sensors: 73 is out of range; allowed "
                                            "1 … 72")]:
        raw = _set(copy.deepcopy(t_room_raw), path, value)
        with pytest.raises(ScenarioError, match=f"^{re.escape(message)}$"):
            parse(raw)


def test_an_unknown_key_of_an_effect_without_settings_says_none_is_allowed(t_room_raw):
    """`effects: {foldover: {zz: 1}}` ended "unknown key; allowed here:" with nothing after
    it: foldover, quantization and averaging take no settings."""
    for effect in ("foldover", "quantization", "averaging"):
        raw = copy.deepcopy(t_room_raw)
        raw["effects"] = {effect: {"zz": 1}}
        with pytest.raises(ScenarioError, match=re.escape(
                f"effects.{effect}.zz: unknown key; allowed here: none, write {{}} for the "
                "defaults") + "$"):
            parse(raw)
