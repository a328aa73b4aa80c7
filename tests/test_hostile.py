"""Bad input never crashes, hangs or loses data (issue 15).

Hypothesis over scenario YAML, recordings and calibration files, and a set of hostile pty
devices: every outcome is a value or the input's own error class (one line, no traceback,
the right exit status), nothing hangs, nothing is written for a failed run, and no reading
is invented. `tests/hostile_corpus.py` holds the hand-written corpus the README's table
counts.
"""

from __future__ import annotations

import copy
import dataclasses
import errno
import io
import json
import math
import os
import re
import subprocess
import sys
import time
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import hostile_devices as hd
from irring import errors, pipeline, safe_yaml
from irring.cli import main
from irring.core import Sweep
from irring.errors import OutputError, TooBig
from irring.estimation.calibration import (MAX_CURVE_ROWS, PROGRESS_MAX_READINGS, Calibration,
                                           CalibrationError, GuidedCalibration, RigReadings,
                                           load_calibration, load_progress, save_progress)
from irring.hardware import DeviceError, DeviceRebooted, NoReadings, SerialRing
from irring.hardware.serial_ring import CHATTER_LIMIT_BYTES, DeviceTimeout
from irring.hardware import protocol as p_
from irring.recording import RecordingError, load_recording, save_recording
from irring.core import Ring
from irring.scenario import ScenarioError, load_scenario, loads, resolve
from irring.studies.accuracy import Config, jobs_for
from irring.studies.study import COLUMNS, StudyError, grid, load_study

FUZZ = settings(max_examples=60, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

T_ROOM = yaml.safe_load(resolve("t_room").read_text())

# --------------------------------------------------------------------------- YAML reader


STRICT_REFUSALS = [
    ("a: 1\nb: 2\na: 3\n", "line 3: key 'a' given twice (first on line 1)"),
    ("a: &x [1, 2]\nb: *x\n", "line 2: YAML aliases (*x) are not allowed"),
    ("[" * 10_000 + "]" * 10_000, "nested more than 64 levels deep"),
    ("? [1, 2]\n: 3\n", "a mapping key must be a plain value"),
    ("a: [1, 2\n", "line 2: not valid YAML"),
    # YAML 1.1 reads these as numbers no one meant: refused, not 488 or 90
    ("a: 1\nb: 0750\n", "line 2: 0750 is an octal number in YAML 1.1 (488)"),
    ("a: 1\nb: 1:30\n", "line 2: 1:30 is a base-60 number in YAML 1.1 (90)"),
    ("a: 1:30.5\n", "line 1: 1:30.5 is a base-60 number in YAML 1.1 (90.5)"),
    # values PyYAML cannot build ended in exit 70 (ValueError, OverflowError)
    ("a: 1\nb: 2026-13-45\n", "line 2: '2026-13-45' cannot be read as timestamp: month"),
    ("a: !!int abc\n", "line 1: 'abc' cannot be read as int"),
    ("a: 1\nb: " + "7" * 5000 + "\n", "line 2: a whole number of 5,000 digits; no field takes "
                                      "one of more than 100"),
]


@pytest.mark.parametrize("text, message", STRICT_REFUSALS)
def test_strict_yaml_refuses_what_safe_load_lets_through(text, message):
    with pytest.raises(safe_yaml.YamlError, match=message.replace("*", r"\*").replace(
            "(", r"\(").replace(")", r"\)").replace("[", r"\[")):
        safe_yaml.load(text, "f.yaml")


@pytest.mark.parametrize("text, line, hint", [
    ("name: t\nroom:\n\toutline_mm: [[0, 0]]\n", 3, True),     # a tab indenting a key
    ("a:\n  b: 1\n\tc: 2\n", 3, True),                          # libyaml: "violates indentation"
    ("a: 'x\ty'\nb: [1, 2\n", 3, False),                         # a tab, but not the fault
])
def test_a_tab_that_breaks_the_yaml_is_named(text, line, hint):
    """libyaml's 'found character that cannot start any token' does not say which
    character; a newcomer's editor put a tab where YAML wants spaces."""
    with pytest.raises(safe_yaml.YamlError) as e:
        safe_yaml.load(text, "f.yaml")
    said = str(e.value)
    assert said.startswith(f"f.yaml: line {line}: not valid YAML: ")
    assert said.endswith(" (a tab: YAML indents with spaces, never tabs)") == hint


def test_numbers_are_read_as_written():
    # YAML 1.1 reads 1e-3 and 1.0e300 as text ("expected a number, got '1e-3'"); 07 and 00
    # are the same in octal and decimal, 1_000 is digit grouping
    assert safe_yaml.load("a: 1e-3\nb: 1.0e300\nc: -2.5E2\nd: .5e1\ne: 07\nf: 1_000\n"
                          "g: '0750'\n") == {"a": 0.001, "b": 1e300, "c": -250.0, "d": 5.0,
                                              "e": 7, "f": 1000, "g": "0750"}
    raw = copy.deepcopy(T_ROOM)
    raw["effects"]["noise"]["sigma_v"] = "SIGMA"
    text = yaml.safe_dump(raw).replace("SIGMA", "2.5e-2")
    assert loads(text, "x.yaml").effects["noise"].sigma_v == 0.025


def test_the_pure_python_yaml_reader_reads_and_refuses_alike(tmp_path):
    """Where PyYAML was built without libyaml, safe_yaml parses with PyYAML's own reader,
    scanner and parser (a subprocess told so before it imports irring): the same values and
    the same messages, line numbers included, as with libyaml here."""
    texts = [text for text, _ in STRICT_REFUSALS] + [
        resolve("t_room").read_text(), _calibration_of(40),
        "a: 1e-3\nb: 1.0e300\nc: -2.5E2\nd: .5e1\ne: 07\nf: 1_000\ng: '0750'\n",
        "a: 'Küche €'\nb: 'x\x07'\n",        # a control character after multi-byte ones
        "a: [" + "1, " * 996 + "2]", "a: [" + "1, " * 997 + "2]",   # map_server's 1,000 values
        "a: 1\n  b: 2\n", "\ufeffa: 1\n", "a:\n- 1\n- {b: [2, 3], c: null}\n",
        "name: t\nroom:\n\toutline_mm: [[0, 0]]\n"]
    script = (
        "import json, sys, yaml\n"
        "yaml.__with_libyaml__ = False   # as a PyYAML built without libyaml\n"
        "from irring import safe_yaml\n"
        "out = [[c.__name__ for c in safe_yaml._PARSING]]\n"
        "for text in json.load(sys.stdin):\n"
        "    try:\n"
        "        out.append(['ok', safe_yaml.load(text, 'f.yaml', 'map_server YAML' if "
        "text.startswith('a: [1') else 'YAML file')])\n"
        "    except safe_yaml.YamlError as exc:\n"
        "        out.append(['error', str(exc)])\n"
        "print(json.dumps(out))\n")
    done = subprocess.run([sys.executable, "-c", script], input=json.dumps(texts), text=True,
                          capture_output=True, timeout=300, check=True)
    parsing, *pure = json.loads(done.stdout)
    assert parsing == ["Reader", "Scanner", "Parser"] and safe_yaml._PARSING[0].__name__ == \
        "CParser"
    here = []
    for text in texts:
        try:
            here.append(["ok", safe_yaml.load(text, "f.yaml", "map_server YAML" if
                                              text.startswith("a: [1") else "YAML file")])
        except safe_yaml.YamlError as exc:
            here.append(["error", str(exc)])
    here = json.loads(json.dumps(here))   # tuples → lists, as the subprocess's
    assert [kind for kind, _ in here].count("ok") == 6
    for text, mine, theirs in zip(texts, here, pure):
        if "not valid YAML: " in mine[1]:   # the parsers word a syntax error their own way
            mine, theirs = mine[1].split(": not valid YAML")[0], theirs[1].split(": not valid")[0]
        assert theirs == mine, text[:80]


def test_billion_laughs_is_refused_at_once():
    bomb = 'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n' + "".join(
        f"{c}: &{c} [{','.join(['*' + p] * 9)}]\n" for p, c in zip("abcdefgh", "bcdefghi"))
    t0 = time.monotonic()
    for load in (lambda: loads(bomb, "bomb.yaml"),
                 lambda: load_calibration(bomb, is_text=True)):
        with pytest.raises((ScenarioError, CalibrationError), match="aliases"):
            load()
    assert time.monotonic() - t0 < 1.0


def test_non_utf8_and_folders_name_the_file(tmp_path):
    bad = tmp_path / "latin1.yaml"
    bad.write_bytes("name: Küche\n".encode("latin-1"))
    with pytest.raises(safe_yaml.InputError, match=r"latin1\.yaml: line 1: not UTF-8"):
        safe_yaml.load_file(bad, "scenario file")
    with pytest.raises(safe_yaml.InputError, match="is a folder; expected a scenario file"):
        safe_yaml.load_file(tmp_path, "scenario file")


def _calibration_of(rows: int, extra: str = "") -> str:
    head = Calibration.nominal("gp2d12").to_yaml().split("curve:")[0]
    return head + extra + "curve:\n" + "".join(
        f"- {{theta_deg: {i * 60 / rows:.7f}, a: {700 - i * 300 / rows:.5f}, b: -1.17}}\n"
        for i in range(rows))


@pytest.mark.parametrize("text, message", [
    # 22,000 valid rows (1.1 MB): PyYAML took ~60 s under load to read 5 MB of them
    (lambda: _calibration_of(22_000), "cal.yaml: 1,096,753 bytes is too big for a calibration "
                                      "file (at most 1 MB, 1,048,576 bytes)"),
    # 440 kB, 150,000 numbers in one flow list: read whole (11 s at load 6), then "unknown key"
    (lambda: _calibration_of(10, "extra: [" + "0, " * 150_000 + "0]\n"),
     "cal.yaml: line 14: more than 100,000 values (numbers, keys, lists); too big for a "
     "calibration file"),
])
def test_a_file_past_the_size_of_its_kind_is_refused_before_it_is_parsed(tmp_path, capsys, text,
                                                                         message):
    cal = tmp_path / "cal.yaml"
    cal.write_text(text())
    assert main(["run", "t_room", "--calibration", str(cal), "--out", str(tmp_path / "o")]) == 1
    assert message in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_a_calibration_file_of_the_rows_its_limits_promise_loads():
    cal, _ = load_calibration(_calibration_of(10_000), is_text=True)   # safe_yaml.LIMITS
    assert cal.theta_rad.size == 10_000 and cal.theta_rad[-1] == pytest.approx(
        math.radians(60 * 9_999 / 10_000))


def test_a_calibration_save_writes_only_what_load_reads(tmp_path):
    """The largest curve a Calibration holds, in the longest form save writes it (17-digit
    a and b, θ to 9 decimals, a long non-ASCII source), loads back; one row more is refused
    where the Calibration is made (it used to save a file load refused)."""
    nominal = Calibration.nominal("gp2d12")
    rows = MAX_CURVE_ROWS
    theta = np.radians(np.linspace(0.0, 89.987654321, rows))
    wiggle = 1.0 + np.sqrt(2.0) * 1e-9 * np.arange(rows) / rows   # long reprs
    log_a, b = nominal.log_ab(np.minimum(theta, nominal.theta_rad[-1]))
    cal = dataclasses.replace(nominal, theta_rad=theta, a=np.exp(log_a) * wiggle, b=b * wiggle,
                              max_incidence_rad=None, source="€𝄞" * 2048)
    back = Calibration.load(cal.save(tmp_path / "cal.yaml"))
    assert back.theta_rad.size == rows and back.source == cal.source
    np.testing.assert_array_equal(back.a, cal.a)
    theta_more = np.radians(np.linspace(0.0, 80.0, rows + 1))
    with pytest.raises(CalibrationError, match=r"^curve: 10,001 rows; a calibration holds at "
                                               r"most 10,000"):
        dataclasses.replace(nominal, theta_rad=theta_more, a=np.full(rows + 1, nominal.a[0]),
                            b=np.full(rows + 1, nominal.b[0]), max_incidence_rad=None)
    text = _calibration_of(rows + 1)     # a file of as many rows, compact enough to parse
    with pytest.raises(CalibrationError, match=r"^cal.yaml: curve: 10,001 rows; a calibration "
                                               r"holds at most 10,000"):
        load_calibration(text, is_text=True, source="cal.yaml")


def test_the_values_limit_counts_every_value():
    at_limit = "a: [" + "1, " * 996 + "2]"     # the mapping, its key and the list are values
    assert safe_yaml.load(at_limit, "f.yaml", "map_server YAML")["a"][-2:] == [1, 2]
    with pytest.raises(safe_yaml.YamlError, match="f.yaml: line 1: more than 1,000 values "
                                                  r"\(numbers, keys, lists\); too big for a "
                                                  "map_server YAML"):
        safe_yaml.load(at_limit.replace("[", "[0, "), "f.yaml", "map_server YAML")


def test_yaml_text_from_a_recording_is_bounded_like_a_file():
    """A recording's embedded calibration and scenario are read with load(), not read_text:
    they were parsed whatever their length (a recording's text may be 8 M characters)."""
    text = _calibration_of(10) + "#" * 2**20
    with pytest.raises(CalibrationError, match=r"<recording's calibration>: 1,049,\d+ characters "
                                               r"is too big for a calibration file \(at most "
                                               r"1,048,576\)"):
        load_calibration(text, is_text=True)
    with pytest.raises(ScenarioError, match="x: line 2: character U\\+D800 is not allowed in YAML "
                                            r"\(it is half of a UTF-16 pair\)"):
        loads("name: a\ndescription: \ud800\n", "x")


# --------------------------------------------------------------------------- scenarios

_VALUES = st.one_of(st.none(), st.booleans(), st.integers(-10**12, 10**12),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
                    st.lists(st.integers(-5, 5000), max_size=4),
                    st.dictionaries(st.text(max_size=6), st.integers(), max_size=3))


def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


T_ROOM_PATHS = [p for p in _paths(T_ROOM) if p]


@FUZZ
@given(edits=st.lists(st.tuples(st.sampled_from(T_ROOM_PATHS), _VALUES), min_size=1,
                      max_size=3))
def test_any_edit_of_a_scenario_loads_or_is_a_scenario_error(edits):
    raw = copy.deepcopy(T_ROOM)
    for path, value in edits:
        node = raw
        try:
            for key in path[:-1]:
                node = node[key]
            node[path[-1]] = value
        except (KeyError, IndexError, TypeError):
            continue
    text = yaml.safe_dump(raw, allow_unicode=True)
    try:
        sc = loads(text, "fuzz.yaml")
    except ScenarioError as exc:
        assert "\n" not in str(exc).strip() or "fuzz.yaml" in str(exc)
        return
    assert sc.room.outline_m and sc.robot.poses       # accepted means usable
    assert all(math.isfinite(v) for xy in sc.room.outline_m for v in xy)


@FUZZ
@given(text=st.text(max_size=300))
def test_any_text_is_a_scenario_or_a_scenario_error(text):
    try:
        loads(text, "fuzz.yaml")
    except ScenarioError:
        pass


@pytest.mark.parametrize("change, message", [
    (lambda r: r.setdefault("scan", {}).update(samples=4), "scan.samples: 4 readings per step are "
                                                           "averaged only with the `averaging`"),
    (lambda r: r.update(effects=[{"noise": {}}, "quantization"]), None),   # accepted
    (lambda r: r.update(effects=[{"noise": {}}, "noise"]), "effect 'noise' listed twice"),
    (lambda r: r.update(effects={"motion": {"path": []}}), "effects.motion.path: needs at least 2"),
    (lambda r: r.update(name="\x1b[31mred"), "name: control characters"),
    (lambda r: r.update(name=""), "name: expected a name of 1"),
    # map.png's title: Pillow's layout raised RuntimeError on two lines (exit 70 after the run)
    (lambda r: r.update(name="a\nb"), "name: a line break is not allowed; a name is one line"),
    # a list or mapping where a name belongs ended in exit 70 (TypeError: unhashable type)
    (lambda r: r.update(obstacles=[{"type": ["box"], "center_mm": [1, 2]}]),
     "'box'] is not allowed; choose one of: cylinder, box"),
    (lambda r: r.update(obstacles=[{"type": {"box": 1}, "center_mm": [1, 2]}]),
     "type: {'box': 1} is not allowed; choose one of: cylinder, box"),
    # a position past ±1e9 mm overflowed the outline checks (exit 70, RuntimeWarning)
    (lambda r: r["room"]["outline_mm"][1].__setitem__(0, 1e200),
     "room.outline_mm[1][0]: 1e+200 mm is out of range; allowed -1e+09 … 1e+09 mm"),
    (lambda r: r["robot"]["poses"][2].__setitem__("y_mm", -3e9),
     "robot.poses[2].y_mm: -3e+09 mm is out of range; allowed -1e+09 … 1e+09 mm"),
    # a long bad value no longer crowds out what is allowed (a message is cut at 400 characters)
    (lambda r: r.update(map=list(range(10_000))),
     "map: expected a mapping of keys, got [0, 1, 2, 3, 4, 5, ...]; allowed here: margin_m"),
    (lambda r: r.update(seed=int("7" * 90)), "seed: " + "7" * 59 + "… is out of range; allowed 0 …"),
])
def test_silently_accepted_scenarios_are_now_errors(change, message):
    raw = copy.deepcopy(T_ROOM)
    change(raw)
    text = yaml.safe_dump(raw, allow_unicode=True)
    if message is None:
        assert loads(text, "x.yaml").has("noise")
        return
    with pytest.raises(ScenarioError, match=re.escape(message)):
        loads(text, "x.yaml")


def test_a_whole_number_past_floats_range_is_not_a_crash():
    # JSON (a recording's ring) takes integers of hundreds of digits; float() overflowed
    from irring.scenario import load_dataclass
    with pytest.raises(ScenarioError, match=r"ring\.radius_m: expected a finite number, got 1000"):
        load_dataclass(Ring, {"radius_m": 10**400}, "ring", "rec.npz")


# --------------------------------------------------------------------------- recordings


def _sweep(rng, n_steps=5, sensors=4, bits=12) -> Sweep:
    ring = Ring(sensors=sensors, min_step=-2, max_step=2)
    steps = np.arange(-2, -2 + n_steps)
    return Sweep(steps=steps, sensor_angles=np.zeros((n_steps, sensors)) + 0.01 * steps[:, None],
                 counts=rng.integers(0, 2 ** bits, (n_steps, sensors)),
                 timestamps_s=np.arange(n_steps) * 0.04, duration_s=0.2,
                 pose=np.array([0.5, 0.4, 0.1]), ring=ring, adc_bits=bits)


@pytest.fixture(scope="module")
def good_recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "sweeps.npz"
    save_recording(path, [_sweep(np.random.default_rng(3))], {"seed": 3})
    return path.read_bytes()


def _rewrite(data: bytes, member: str, array) -> bytes:
    """The recording with one member replaced by ``array`` (any dtype or shape)."""
    src = zipfile.ZipFile(io.BytesIO(data))
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as dst:
        for info in src.infolist():
            if info.filename == member + ".npy":
                buf = io.BytesIO()
                np.lib.format.write_array(buf, np.asarray(array), allow_pickle=True)
                dst.writestr(info.filename, buf.getvalue())
            else:
                dst.writestr(info, src.read(info))
    return out.getvalue()


def _appended(data: bytes, member: str, array) -> bytes:
    """The recording with one more zip entry ``member`` (a name it may already hold)."""
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asarray(array))
    out = io.BytesIO(data)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # zipfile warns of a name written twice
        with zipfile.ZipFile(out, "a") as z:
            z.writestr(member + ".npy", buf.getvalue())
    return out.getvalue()


def _scalars(data: bytes, **changes) -> bytes:
    src = zipfile.ZipFile(io.BytesIO(data))
    buf = io.BytesIO(src.read("sweep000/scalars.npy"))
    scalars = json.loads(str(np.lib.format.read_array(buf)))
    scalars.update(changes)
    return _rewrite(data, "sweep000/scalars", np.array(json.dumps(scalars)))


@pytest.mark.parametrize("make, message", [
    (lambda d: d[: len(d) // 2], "not an irring recording"),
    (lambda d: _rewrite(d, "sweep000/counts", np.array([object()], dtype=object)),
     "holds object data"),
    (lambda d: _rewrite(d, "sweep000/counts", -np.ones((5, 4), int)), "lie outside a 12-bit ADC"),
    (lambda d: _rewrite(d, "sweep000/counts", np.ones((5, 4), bool)), "holds bool"),
    (lambda d: _rewrite(d, "sweep000/counts", np.ones((5, 4), complex)), "holds complex"),
    (lambda d: _rewrite(d, "sweep000/counts", np.ones((5, 3), int)), "does not match"),
    (lambda d: _rewrite(d, "sweep000/sensor_angles", np.full((5, 4), np.nan)), "NaN or infinite"),
    (lambda d: _rewrite(d, "sweep000/pose", np.array([1e300, -2e6, 0.1])),
     "sweep000/pose: holds 1e+300; positions and angles lie within ±1e+06 (m, rad)"),
    (lambda d: _rewrite(d, "sweep000/sensor_angles", np.full((5, 4), -3e7)),
     "sweep000/sensor_angles: holds 3e+07; positions and angles lie within"),
    # |−2⁶³| overflows to −2⁶³ in int64: the pose passed the bound and was replayed (exit 0)
    (lambda d: _rewrite(d, "sweep000/pose", np.array([-2**63, 4, 0], np.int64)),
     "sweep000/pose: holds 9.22337e+18; positions and angles lie within ±1e+06 (m, rad)"),
    (lambda d: _scalars(d, adc_bits=0), "adc_bits: 0 is not allowed"),
    (lambda d: _scalars(d, adc_bits=64), "adc_bits: 64 is not allowed"),
    (lambda d: _scalars(d, max_range_m=float("nan")), "max_range_m: nan is not allowed"),
    (lambda d: _scalars(d, samples=True), "samples: True is not allowed"),
    (lambda d: _scalars(d, sensor_model="gp2zz"), "sensor_model: 'gp2zz' is not allowed"),
    (lambda d: _scalars(d, ring={"sensors": 0}), "ring.sensors: 0 is out of range"),
    (lambda d: _rewrite(d, "meta", np.array(json.dumps(
        {"grid": {"origin_xy_m": [0, 0], "shape": [200000, 200000], "resolution_m": 0.01}}))),
     "200,000 × 200,000 cells of 10 mm would need about 2400.0 GB"),
    (lambda d: _rewrite(d, "meta", np.array("[" * 100_000)), "meta: not valid JSON"),
    # a grid that is not the sweeps': replay mapped 617 valid readings onto nothing, exit 0
    (lambda d: _rewrite(d, "meta", np.array(json.dumps(
        {"grid": {"origin_xy_m": [1000, -3], "shape": [30, 20], "resolution_m": 0.01}}))),
     "meta.grid: sweep 1's pose (0.5, 0.4) m lies outside the recorded grid (x 1000 … 1000.2 m, "
     "y -3 … -2.7 m), as do all the others; the grid and the sweeps do not belong together"),
    (lambda d: _rewrite(d, "meta", np.array(json.dumps(
        {"grid": {"origin_xy_m": [0, 0], "shape": [3, 3], "resolution_m": 10.0}}))),
     "resolution_m 0.001 … 0.5 (a scenario's map cells)"),
    # a step read twice was mapped twice; one outside the ring contradicts the sweep (a
    # driver or simulator never writes it)
    (lambda d: _rewrite(d, "sweep000/steps", np.array([-2, -1, -1, 0, 1])),
     "sweep000/steps: step -1 is listed twice; a sweep reads each step once"),
    (lambda d: _rewrite(d, "sweep000/steps", np.array([-2, -1, 0, 1, 7])),
     "sweep000/steps: step 7 lies outside the ring's steps -2 … 2"),
    (lambda d: _scalars(d, missing_steps=[3, 0]),
     "sweep000/scalars.missing_steps: step 3 lies outside the ring's steps -2 … 2"),
    # a recording from an irring whose mapper has another parameter: the message listed
    # this mapper's 28 parameters and was cut before it said which key was wrong
    (lambda d: _rewrite(d, "meta", np.array(json.dumps({"mapper": {"l_occ": 2.0,
                                                                   "beam_width": 3.0}}))),
     "meta.mapper.beam_width: a mapper parameter this irring does not have (a recording from "
     "another irring version?); it maps with ahead_floor, between_end_cells, between_steps, "
     "cone_l_free, "),
    (lambda d: _rewrite(d, "meta", np.array(json.dumps({"mapper": {"l_occ": 2.0,
                                                                   "l_free": "-1.5"}}))),
     "meta.mapper.l_free: expected a finite number -1000 … 1000, got '-1.5'"),
    # a seed irring run --seed refuses replayed and was written back into outputs
    (lambda d: _rewrite(d, "meta", np.array(json.dumps({"seed": 2**63}))),
     "meta.seed: expected a whole number 0 … 9223372036854775807, got 9223372036854775808"),
    # a ring field left out took the paper's value: a laser's radius 0 became 0.15 m
    (lambda d: _scalars(d, ring={k: v for k, v in dataclasses.asdict(
        Ring(sensors=4, min_step=-2, max_step=2, radius_m=0.0)).items() if k != "radius_m"}),
     "sweep000/scalars.ring.radius_m: missing; a recording lists every ring field (sensors, "
     "radius_m, motor_step_rad, gear, "),
    (lambda d: _scalars(d, ring=None), "sweep000/scalars.ring.sensors: missing"),
    # an entry given twice: replay read the last silently, a map of other readings (exit 0)
    (lambda d: _appended(d, "sweep000/counts", np.zeros((5, 4), np.int64)),
     "sweep000/counts: given twice in the zip; a recording holds each entry once"),
    (lambda d: _appended(d, "sweep0/counts", np.zeros((5, 4), np.int64)),
     "sweep0 and sweep000 both number sweep 0; a recording numbers each sweep once"),
    (lambda d: _rewrite(d, "meta", np.array('{"seed": 3, "seed": 4}')),
     "meta: key 'seed' given twice"),
    # `cat a.npz b.npz > c.npz` replayed b alone (zipfile reads the last zip of a file)
    (lambda d: _scalars(d, adc_bits=10) + d,
     "bytes before the recording (two recordings joined into one file?); replay each .npz "
     "on its own"),
])
def test_broken_recordings_are_one_clear_error(tmp_path, good_recording, make, message):
    path = tmp_path / "bad.npz"
    path.write_bytes(make(good_recording))
    with pytest.raises((RecordingError, TooBig), match=re.escape(message)):
        load_recording(path)


def test_the_bound_on_poses_and_angles_holds_in_any_dtype(tmp_path):
    """check_sweep took |x| in the array's own dtype: an int64 pose of −2⁶³ passed as −2⁶³,
    and float16 angles printed 'RuntimeWarning: overflow encountered in cast' (1e6 cast to
    float16) on stderr of a replay that succeeded."""
    from irring.recording import check_sweep

    sweep = _sweep(np.random.default_rng(9))
    with pytest.raises(ValueError, match=re.escape("holds 9.22337e+18; positions and angles")):
        check_sweep(dataclasses.replace(sweep, pose=np.array([-2**63, 1, 0], np.int64)))
    half = dataclasses.replace(sweep, sensor_angles=sweep.sensor_angles.astype(np.float16))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_sweep(half)
        save_recording(tmp_path / "half.npz", [half])
        assert load_recording(tmp_path / "half.npz")[0][0].sensor_angles.dtype == np.float16


def test_save_recording_refuses_a_meta_its_loader_refuses(tmp_path):
    """A seed past SEED_MAX was written and replayed (and written back); now the writer
    refuses what the reader would, before anything is written."""
    path = tmp_path / "big_seed.npz"
    with pytest.raises(ValueError, match=re.escape(
            "meta.seed: expected a whole number 0 … 9223372036854775807, got 10000000000")):
        save_recording(path, [_sweep(np.random.default_rng(5))], {"seed": 10 ** 40})
    assert not path.exists()
    save_recording(path, [_sweep(np.random.default_rng(5))], {"seed": 2 ** 63 - 1})
    assert load_recording(path)[1]["seed"] == 2 ** 63 - 1


def test_save_recording_refuses_a_truth_its_loader_refuses(tmp_path):
    """A sweep cut to 8 of 12 sensors in code kept its 12-sensor truth: save_recording wrote
    it, and replay refused the file ('sweep001/truth/distance_m: shape (71, 12) does not
    match the sweep's 71 steps × 8 sensors')."""
    from irring.core import Truth

    sweep = _sweep(np.random.default_rng(7))
    shape = sweep.counts.shape
    truth = Truth(distance_m=np.ones(shape), incidence_rad=np.zeros(shape),
                  hit_point=np.zeros(shape + (3,)), origin=np.zeros(shape + (3,)),
                  direction=np.ones(shape + (3,)), geom_id=np.zeros(shape, int),
                  reflectance=np.ones(shape))
    path = tmp_path / "t.npz"
    save_recording(path, [dataclasses.replace(sweep, truth=truth)])
    assert load_recording(path)[0][0].truth.hit_point.shape == (5, 4, 3)
    for field, value, message in [
            ("distance_m", np.ones((5, 12)), "expected numbers of shape (5, 4), got float64 "
                                             "(5, 12)"),
            ("hit_point", np.zeros((5, 4)), "expected numbers of shape (5, 4, 3)"),
            ("direction", np.full(shape + (3,), np.nan), "holds NaN or infinite values")]:
        bad = dataclasses.replace(sweep, truth=dataclasses.replace(truth, **{field: value}))
        with pytest.raises(ValueError, match=re.escape(f"sweeps[1].truth.{field}: {message}")):
            save_recording(tmp_path / "bad.npz", [sweep, bad])
        assert not (tmp_path / "bad.npz").exists()


def test_a_damaged_recorded_calibration_names_the_recording(tmp_path, capsys, good_recording):
    """It named '<recording's calibration>' only: which of the files replayed?"""
    cal = Calibration.nominal("gp2d12").to_yaml().replace("adc_bits: 12",
                                                          "adc_bits: 12\nadc_bits: 12")
    path = tmp_path / "rec.npz"
    path.write_bytes(_rewrite(good_recording, "meta", np.array(json.dumps(
        {"seed": 3, "calibration_yaml": cal}))))
    line = cal.splitlines().index("adc_bits: 12") + 2
    assert main(["replay", str(path), "--out", str(tmp_path / "o")]) == 1
    assert (f"irring replay: error: {path} (recorded calibration): line {line}: key 'adc_bits' "
            f"given twice (first on line {line - 1})" in capsys.readouterr().err)


def test_a_recorded_calibration_of_another_sensor_says_how_to_replay(tmp_path, capsys,
                                                                    good_recording):
    """Its advice was 'or leave --calibration out', given to a replay without --calibration:
    leaving it out is what reads the recorded calibration that does not fit."""
    cal = Calibration.nominal("gp2d12").to_yaml().replace("adc_bits: 12", "adc_bits: 10")
    path = tmp_path / "rec.npz"
    path.write_bytes(_rewrite(good_recording, "meta", np.array(json.dumps(
        {"seed": 3, "calibration_yaml": cal}))))
    assert main(["replay", str(path), "--out", str(tmp_path / "o")]) == 1
    assert capsys.readouterr().err == (
        f"irring replay: error: {path} (recorded calibration): the calibration is for a gp2d12 "
        "with a 10-bit ADC at 5 V, but sweep 1 was read by a gp2d12 with a 12-bit ADC at 5 V; "
        "replay it with --calibration FILE, a calibration of that sensor (irring calibrate)\n")
    fits = tmp_path / "fits.yaml"
    fits.write_text(Calibration.nominal("gp2d12").to_yaml())
    assert main(["replay", str(path), "--calibration", str(fits), "--out",
                 str(tmp_path / "o"), "--no-animation"]) == 0


def test_a_recording_whose_scenario_this_irring_cannot_read_is_mapped_unscored(tmp_path,
                                                                             capsys):
    """A recording from an irring whose scenarios have an effect this one lacks was refused
    whole ('effects.multipath: unknown key'): its sweeps could not be mapped again, though
    the scenario only scores them. With a recorded calibration it is mapped, not scored, and
    says why; without one (its scene's calibration needs the scene) it is still refused."""
    assert main(["run", "t_room_cylinder", "--out", str(tmp_path / "o"), "--no-animation"]) == 0
    first = (tmp_path / "o" / "map.pgm").read_bytes()
    data = (tmp_path / "o" / "sweeps.npz").read_bytes()
    meta = json.loads(str(np.lib.format.read_array(io.BytesIO(
        zipfile.ZipFile(io.BytesIO(data)).read("meta.npy")))))
    meta["scenario_yaml"] = meta["scenario_yaml"].replace("effects:\n", "effects:\n  multipath: {}\n")
    newer = tmp_path / "newer.npz"
    newer.write_bytes(_rewrite(data, "meta", np.array(json.dumps(meta))))
    capsys.readouterr()
    assert main(["replay", str(newer), "--out", str(tmp_path / "r"), "--no-animation"]) == 0
    out = capsys.readouterr().out
    assert (f"(not scored: {newer} (recorded scenario): effects.multipath: unknown effect; "
            "allowed: incidence, noise") in out, out
    assert "F1" not in out and (tmp_path / "r" / "map.pgm").read_bytes() == first
    del meta["calibration_yaml"]
    older = tmp_path / "older.npz"
    older.write_bytes(_rewrite(data, "meta", np.array(json.dumps(meta))))
    assert main(["replay", str(older), "--out", str(tmp_path / "r2")]) == 1
    assert f"{older} (recorded scenario): effects.multipath:" in capsys.readouterr().err
    assert not (tmp_path / "r2").exists()


@pytest.fixture(scope="module")
def t_room_sweep():
    from irring import SimRing
    room = load_scenario("t_room")
    return room, SimRing(room).sweep(0)


@pytest.mark.parametrize("edit, message", [
    (lambda s: {"counts": np.where(np.arange(s.counts.size).reshape(s.counts.shape) % 7, s.counts,
                                   np.nan)}, "sweeps[0].counts: holds NaN or infinite values"),
    (lambda s: {"counts": s.counts - 5000.0}, "sweeps[0].counts: readings -4"),
    (lambda s: {"sensor_angles": s.sensor_angles + np.inf},
     "sweeps[0].sensor_angles: holds NaN or infinite values"),
    (lambda s: {"pose": np.array([np.nan, 0.45, 0.0])}, "sweeps[0].pose: holds NaN or infinite"),
    (lambda s: {"steps": np.where(s.steps == 3, 2, s.steps)},
     "sweeps[0].steps: step 2 is listed twice; a sweep reads each step once"),
    (lambda s: {"duration_s": -1.0}, "sweeps[0].duration_s: -1.0 is not allowed; 0 … 10,000,000 s"),
    (lambda s: {"adc_bits": 0}, "sweeps[0].adc_bits: 0 is not allowed; a whole number 1 … 24"),
    (lambda s: {"timestamps_s": s.timestamps_s[:-1]},
     "sweeps[0].timestamps_s: expected numbers of shape (71,), got float64 (70,)"),
])
def test_a_sweep_a_replay_would_refuse_is_refused_by_map_sweeps(tmp_path, t_room_sweep, edit,
                                                                 message):
    """pipeline.map_sweeps (the README's API for any RingSource) mapped such sweeps: NaN end
    points dropped without a word, a repeated step mapped twice, adc_bits 0 a RuntimeWarning;
    write_outputs then wrote a sweeps.npz that irring replay refused."""
    room, sweep = t_room_sweep
    bad = dataclasses.replace(sweep, **edit(sweep))
    with pytest.raises(ValueError, match=re.escape(message)):
        pipeline.map_sweeps([bad, sweep], scenario=room)
    with pytest.raises(ValueError, match=re.escape(message.replace("[0]", "[1]"))):
        save_recording(tmp_path / "x.npz", [sweep, bad])
    assert not (tmp_path / "x.npz").exists()


@FUZZ
@given(flips=st.lists(st.tuples(st.integers(0, 10**6), st.integers(1, 255)), min_size=1,
                      max_size=4),
       cut=st.one_of(st.none(), st.integers(0, 10**6)))
def test_damaged_recordings_load_exactly_or_fail_cleanly(tmp_path_factory, good_recording,
                                                         flips, cut):
    data = bytearray(good_recording)
    for pos, mask in flips:
        data[pos % len(data)] ^= mask
    if cut is not None:
        data = data[: cut % len(data)]
    path = tmp_path_factory.mktemp("fz") / "x.npz"
    path.write_bytes(bytes(data))
    try:
        sweeps, _ = load_recording(path)
    except RecordingError:
        return
    # what loads is what was written: a flip that survives CRC and checks changes nothing
    ref = _sweep(np.random.default_rng(3))
    assert len(sweeps) == 1 and np.array_equal(sweeps[0].counts, ref.counts)


# --------------------------------------------------------------------------- calibrations


@FUZZ
@given(key=st.sampled_from(["sensor_model", "emitter_offset_mm", "adc_bits", "vref_v",
                            "min_range_mm", "max_range_mm", "noise_counts", "curve", "source",
                            "max_incidence_deg", "irring_calibration", "extra"]),
       value=_VALUES)
def test_any_edit_of_a_calibration_loads_or_is_a_calibration_error(key, value):
    from irring import gp2

    raw = _CAL.to_dict()
    raw[key] = value
    try:
        cal = Calibration.from_dict(safe_yaml.load(yaml.safe_dump(raw), "c.yaml"), "c.yaml")
    except CalibrationError:
        return
    assert cal.sensor_model in gp2.available() and 0.1 <= cal.vref_v <= 50
    assert np.all(cal.b < 0)   # a GP2's curve falls


_CAL = Calibration.for_scene(loads(yaml.safe_dump(T_ROOM), "t_room.yaml"))


@pytest.mark.parametrize("model, bits, vref, read_as", [
    ("gp2d12", 10, 5.0, "a 10-bit ADC"), ("gp2y0a21", 12, 5.0, "a gp2y0a21"),
    ("gp2d12", 12, 3.3, "at 3.3 V"),
])
def test_a_calibration_for_another_sensor_or_adc_is_refused(tmp_path, capsys, model, bits,
                                                             vref, read_as):
    """`run --calibration` with a 10-bit file read t_room's 12-bit counts as 10-bit ones: exit
    0 with 1536 'valid' readings and F1 0.000 (gp2y0a21: F1 0.723), a silently wrong map."""
    cal = tmp_path / "other.yaml"
    Calibration.nominal(model, None, bits, vref).save(cal)
    out = tmp_path / "o"
    t0 = time.monotonic()
    assert main(["run", "t_room", "--calibration", str(cal), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert time.monotonic() - t0 < 5
    assert f"{cal}: the calibration is for a {model} with a {bits}-bit ADC at {vref:g} V" in err
    assert "but t_room reads a gp2d12 with a 12-bit ADC at 5 V" in err and read_as in err
    assert not out.exists()
    # replay: the recorded sweeps against the same file
    assert main(["run", "t_room_cylinder", "--out", str(out), "--no-animation"]) == 0
    capsys.readouterr()
    assert main(["replay", str(out / "sweeps.npz"), "--calibration", str(cal),
                 "--out", str(tmp_path / "re")]) == 1
    assert ("but sweep 1 was read by a gp2d12 with a 12-bit ADC at 5 V"
            in capsys.readouterr().err)
    assert not (tmp_path / "re").exists()


@pytest.mark.parametrize("row, edit, reads", [
    (0, {"a": 1e300}, "5.65e+295 … 1e+300 m"),
    (0, {"b": -1e-300}, "774 … 774 m"),
    (0, {"b": -1e300}, "0 … 774 m"),   # 774 m at count 1, nothing from 2 on
    (4, {"a": 1e-9}, "5.99e-14 … 1e-09 m"),   # a row within the drop-out angle
])
def test_a_calibration_that_reads_no_count_in_range_is_refused(tmp_path, capsys, row, edit,
                                                               reads):
    """a = 1e300 or b = -1e300 passed the loader (a > 0, b < 0) and mapped nothing (exit 0,
    F1 0.000, every reading 'no return'); b = -1e-300 ended in exit 70 under -W error
    (overflow in exp). Refused at load, naming the row and what is allowed."""
    raw = Calibration.nominal("gp2d12", None, 12, 5.0).to_dict()
    raw["curve"][row].update(edit)
    cal = tmp_path / "impossible.yaml"
    cal.write_text(yaml.safe_dump(raw))
    theta = raw["curve"][row]["theta_deg"]
    message = (f"{cal}: curve[{row}] (θ = {theta:g}°): a = {raw['curve'][row]['a']:.6g}, b = "
               f"{raw['curve'][row]['b']:.6g} read the counts 1 … 4095 of a 12-bit ADC as "
               f"{reads}, never within the 0.1 … 0.8 m range (min_range_mm … max_range_mm); "
               f"allowed: a, b under which some count reads within it")
    with pytest.raises(CalibrationError) as caught:
        Calibration.load(cal)
    assert message in str(caught.value)
    out = tmp_path / "o"
    assert main(["run", "t_room", "--calibration", str(cal), "--out", str(out)]) == 1
    assert message in capsys.readouterr().err
    assert not out.exists()
    # drive: before the port is opened
    assert main(["drive", "--port", str(tmp_path / "no-such-port"), "--calibration", str(cal),
                 "--out", str(out)]) == 1
    assert f"irring drive: error: {message}" in capsys.readouterr().err


@pytest.mark.parametrize("model", [["gp2d12"], {"name": "gp2d12"}])
def test_a_calibration_naming_its_sensor_by_a_list_or_mapping_is_one_clear_error(tmp_path, capsys,
                                                                                model):
    # `sensor_model: [gp2d12]` ended in exit 70 (TypeError: unhashable type: 'list')
    raw = _CAL.to_dict()
    raw["sensor_model"] = model
    path = tmp_path / "cal.yaml"
    path.write_text(yaml.safe_dump(raw))
    assert main(["run", "t_room", "--calibration", str(path), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert f"{path}: sensor_model: {model!r} is not a sensor model; choose one of: gp2d12" in err


def test_a_curve_row_past_the_drop_out_angle_is_not_judged(tmp_path):
    """Rows past max_incidence are never read with (the return drops out there)."""
    raw = Calibration.nominal("gp2d12", None, 12, 5.0).to_dict()
    raw["max_incidence_deg"] = 60.0
    raw["curve"][-1]["a"] = 1e-9
    cal = Calibration.from_dict(raw)
    assert cal.a[-1] == 1e-9 and math.degrees(cal.max_incidence_rad) == pytest.approx(60.0)


def test_drive_with_a_bad_calibration_file_exits_1_as_its_help_says(tmp_path, capsys):
    """It exited 2 (a usage error) and named the file twice."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("irring_calibration: 1\nsensor_model: gp2d12\n")
    assert main(["drive", "--port", str(tmp_path / "no-such-port"), "--calibration",
                 str(bad)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"irring drive: error: {bad}: ") and err.count(str(bad)) == 1


def test_a_port_that_cannot_be_opened_is_named_on_one_line(tmp_path, capsys):
    """A --port holding a line break (or a terminal escape) was printed raw: the error
    broke over two lines, the second starting mid-path."""
    port = str(tmp_path / "ring\n\x1b[31mred")
    assert main(["drive", "--port", port, "--pose", "0,0", "--no-wait", "--out",
                 str(tmp_path / "o")]) == 3
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "\x1b" not in err
    assert f"irring drive: error: cannot open {tmp_path}/ring \\x1b[31mred: No such file" in err


def test_a_network_port_that_cannot_be_opened_gets_network_advice(tmp_path, capsys):
    """It was told to check /dev/ttyUSB* and the dialout group."""
    import socket
    with socket.socket() as s:   # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    assert main(["drive", "--port", f"socket://127.0.0.1:{port}", "--no-wait", "--out",
                 str(tmp_path / "o")]) == 3
    assert (f"cannot open socket://127.0.0.1:{port}: Connection refused. Check that the ring's "
            "server listens at that host and port, or start the emulator: irring emulate "
            "t_room --tcp PORT" in capsys.readouterr().err)


def test_drive_with_a_calibration_for_another_adc_exits_1_naming_the_file(tmp_path, capsys):
    """It exited 2 (a usage error), naming neither the file nor the port."""
    cal = tmp_path / "cal10.yaml"
    cal.write_text(Calibration.nominal("gp2d12", adc_bits=10).to_yaml())
    dev = hd.HostileDevice(hd.good)   # announces 12 bits
    try:
        assert main(["drive", "--port", dev.link, "--calibration", str(cal), "--no-wait",
                     "--out", str(tmp_path / "o")]) == 1
    finally:
        dev.close()
    assert (f"irring drive: error: {cal}: a calibration for a 10-bit ADC; the ring on "
            f"{dev.link} reports 12 bits: calibrate this ring (irring calibrate)"
            in capsys.readouterr().err)
    assert not (tmp_path / "o").exists()


def test_drive_refuses_a_ring_whose_adc_the_datasheet_curve_cannot_read_before_sweeping(
        tmp_path, capsys):
    """A ring announcing a 1-bit ADC (IRINF allows 1 … 24) was swept at every pose, then
    refused with exit 1, a bad input file, though none was given ('curve[0] … No sensor reads
    so: calibrate it again'). Refused after the handshake, before the ring turns (exit 3)."""
    sweeps = []

    def one_bit(dev, cmd):
        if isinstance(cmd, hd.p.Hello):
            dev.send(hd.info(bits=1))
        elif isinstance(cmd, hd.p.SweepCommand):
            sweeps.append(cmd)

    dev = hd.HostileDevice(one_bit)
    try:
        assert main(["drive", "--port", dev.link, "--no-wait", "--out", str(tmp_path / "o"),
                     "--pose", "0,0", "--pose", "300,0"]) == errors.DEVICE
    finally:
        dev.close()
    err = capsys.readouterr().err
    assert err.startswith(f"irring drive: error: the ring on {dev.link} reports a 1-bit ADC, "
                          "whose counts the gp2d12 datasheet curve reads as no distance within "
                          "its range (")
    assert err.endswith("): calibrate this ring (irring calibrate) and drive it with "
                        "--calibration FILE\n")
    assert sweeps == [] and not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- devices

TIMEOUT_S = 0.15


def _sweep_on(behaviour, **ring_kw):
    dev = hd.HostileDevice(behaviour)
    ring = SerialRing(dev.link, timeout_s=TIMEOUT_S, **ring_kw)
    t0 = time.monotonic()
    try:
        with ring:
            return ring.sweep(resweep=1), time.monotonic() - t0
    finally:
        dev.close()


@pytest.mark.parametrize("behaviour, error", [
    (hd.silent, "no IRINF answer"),
    (hd.silent_after_hello, "stopped answering"),
    (hd.disconnect_on_sweep, "disconnected|stopped answering"),
    (hd.flood_irpos, "stopped answering|no progress"),
    (hd.repeat_irscn, "stopped answering|no progress"),
    (hd.sentence_every_quarter_second, "stopped answering|no progress"),
    (hd.done_without_steps, "no step of it arrived"),
    (hd.wrong_sensor_count, "no step of it arrived"),
    (hd.error_reply(3), "IRERR 3"),
    (hd.error_reply(4), "IRERR 4"),
    (hd.error_reply(5), "kept refusing|IRERR 5"),
    # a device refusing every IRHLO was 'no IRINF answer … Check the port, the baud rate'
    (hd.refuses_hello(2), re.escape("answered each of 3 IRHLO with IRERR 2 (unknown type), "
                                    "never IRINF: its firmware does not know IRHLO")),
    (hd.refuses_hello(1), re.escape("answered each of 3 IRHLO with IRERR 1 (bad sentence), "
                                    "never IRINF: it cannot read what this host sends")),
    # an IRINF outside the protocol's own ranges, intact (its CRC matched), was told as 'no
    # IRINF answer … Sentences that arrive garbled point at line noise or a loose cable'
    (hd.announces(sensors=0), re.escape(
        "answers IRHLO with an IRINF that IRR protocol v2 does not allow (IRINF field 2 "
        "(nsensors) = 0 is outside 1 … 4096): $IRINF,2,0,12,")),
    (hd.announces(den=0), re.escape("(IRINF field 6 (gear_den) = 0 is outside 1 … 2147483647)")),
    (hd.announces(lo=5, hi=-5), re.escape("does not allow (min_step 5 > max_step -5)")),
    (hd.announces(sensors=4096), re.escape("announces 4096 sensors (nsensors; allowed 1 … 72)")),
    (hd.announces(bits=32), re.escape("announces a 32-bit ADC (adc_bits; allowed 1 … 24)")),
    (hd.announces(lo=-2**31 + 1, hi=2**31 - 1), re.escape(
        "announces steps -2147483647 … 2147483647 (min_step, max_step; allowed -100000 … 100000")),
])
def test_a_hostile_device_is_a_clear_error_within_a_bounded_time(behaviour, error):
    t0 = time.monotonic()
    with pytest.raises(DeviceError, match=error) as caught:
        _sweep_on(behaviour)
    took = time.monotonic() - t0
    assert took < 30 * TIMEOUT_S + 1.0, took          # never a hang
    partial = getattr(caught.value, "partial", None)
    if partial is not None:                            # no invented reading
        for step, row in zip(partial.steps, partial.counts):
            assert list(row) == hd.counts_for(int(step))


def _contradicts_once(dev, cmd):
    """Its first IRSWP sends every IRSCN twice under one seq, the copy with other counts
    (each with a valid CRC); after that a correct device."""
    if isinstance(cmd, p_.SweepCommand) and not getattr(dev, "lied", False):
        dev.lied = True
        for step in range(cmd.from_step, cmd.to_step + 1):
            dev.send(hd.scan(dev.seq, step))
            other = ",".join(str(c + 7) for c in hd.counts_for(step))
            dev.send(hd.line(f"IRSCN,{dev.seq},{step},{1000 + dev.seq},{other}"))
            dev.seq += 1
        dev.send(hd.line(f"IRDON,{dev.seq - 1}"))
        return
    hd.good(dev, cmd)


def test_an_irscn_sent_again_with_other_readings_is_dropped_and_swept_again():
    """Both copies pass the CRC, so which is right is not known: the first was kept and the
    sweep reported '5 duplicates', as for a harmless resend. Now the step is dropped as
    inconsistent and re-swept."""
    dev = hd.HostileDevice(_contradicts_once)
    try:
        with SerialRing(dev.link, timeout_s=TIMEOUT_S) as ring:
            sweep = ring.sweep(resweep=1)
            assert list(sweep.steps) == list(range(hd.MIN_STEP, hd.MAX_STEP + 1))
            assert [list(r) for r in sweep.counts] == [hd.counts_for(s) for s in sweep.steps]
            assert (ring.stats.inconsistent, ring.stats.duplicates, ring.stats.resweeps) == \
                (10, 0, 1)
            assert "10 inconsistent IRSCN dropped" in ring.last_report.message
        dev.lied = False   # and without a re-sweep the steps are missing, never invented
        with SerialRing(dev.link, timeout_s=TIMEOUT_S) as ring:
            with pytest.raises(NoReadings):
                ring.sweep(resweep=0)
    finally:
        dev.close()


def test_a_second_irring_on_a_port_in_use_is_refused_before_it_reads(tmp_path):
    """Two `irring drive` on one emulator each read some of the other's IRSCN as their own
    (the device answers whoever reads first): one scored F1 0.784 against the other's 0.979,
    exit 0 for both. The port is opened exclusively; the second is told it is in use."""
    dev = hd.HostileDevice(hd.good)
    try:
        with SerialRing(dev.link, timeout_s=TIMEOUT_S) as first:
            second = SerialRing(dev.link, timeout_s=TIMEOUT_S)
            with pytest.raises(DeviceError, match=re.escape(
                    f"cannot open {dev.link}: another program has it open and locked (an irring "
                    "drive or calibrate still running on it?). Check which program has it "
                    "(fuser, lsof) and run this when it is done")):
                second.open()
            sweep = first.sweep()
            assert [list(r) for r in sweep.counts] == [hd.counts_for(s) for s in sweep.steps]
        with SerialRing(dev.link, timeout_s=TIMEOUT_S) as again:   # free once closed
            assert again.info.nsensors == hd.SENSORS
    finally:
        dev.close()


def test_a_noisy_link_that_never_falls_silent_is_not_stopped():
    """timeout_s is the longest silence: 14 garbled sentences, one every 0.2 s, is 2.8 s
    without an intact step but never 1.2 s without a byte (a 1 s margin for a starved
    device thread). The driver sent IRSTP after 1.2 s without a new step, and the board,
    stopping, lost the four steps still to come."""
    dev = hd.HostileDevice(hd.garbled_stretch(14, 0.2))
    try:
        with SerialRing(dev.link, timeout_s=1.2) as ring:
            sweep = ring.sweep()
            assert list(sweep.steps) == list(range(hd.MIN_STEP, hd.MAX_STEP + 1))
            assert sweep.missing_steps == ()
            assert getattr(dev, "stops", 0) == 0
            assert ring.stats.timeouts == 0 and ring.stats.checksum_failures == 14
    finally:
        dev.close()


def test_a_device_that_talks_but_never_sends_a_step_is_stopped_by_a_byte_budget():
    """Never silent, so no timeout ever fires (timeout_s 30 s): after CHATTER_LIMIT_BYTES
    without a new step the driver sends IRSTP, as for silence, and after its retries + 1
    IRSTP gives up. Counts, not clocks: exactly 3 IRSTP reach the device (it waited for
    the 30 s no-progress limit before)."""
    dev = hd.HostileDevice(hd.talks_without_steps)
    try:
        with SerialRing(dev.link, timeout_s=30.0, retries=2) as ring:
            with pytest.raises(DeviceTimeout) as caught:
                ring.sweep()
        waited = time.monotonic()      # the last IRSTP may still be on its way
        while getattr(dev, "stops", 0) < 3 and time.monotonic() - waited < 10.0:
            time.sleep(0.01)
        assert getattr(dev, "stops", 0) == 3
        assert (f"no progress during IRSWP,{hd.MIN_STEP},{hd.MAX_STEP}: "
                f"{CHATTER_LIMIT_BYTES} bytes arrived without a new step 4 times, 3 IRSTP did "
                f"not end it; 0 of 5 steps arrived") in str(caught.value)
    finally:
        dev.close()


@pytest.mark.parametrize("announced, message", [
    # 20 steps of 45° through a belt of 10: the sensors turned ±9000°, accepted and mapped
    (dict(lo=-20, hi=20, step_mdeg=45_000, num=10, den=1),
     "a sweep turning the sensors to ±9000° (steps -20 … 20 × 45° × belt 10; allowed at most "
     "±360°, a sensor turned once round)"),
    (dict(step_mdeg=50_000), "a motor step of 50° (step_mdeg; allowed 10 … 45000 m°)"),
    (dict(num=100, den=1), "a belt ratio of 100 (gear_num/gear_den; allowed 0.01 … 10)"),
    (dict(lo=-60_000, hi=60_000), "steps -60000 … 60000 (min_step, max_step; allowed -100000 "
                                  "… 100000, at most 100,000 steps)"),
])
def test_a_device_announcing_a_ring_no_scenario_allows_is_refused_naming_the_field(
        announced, message):
    """The handshake bounded sizes but not angles: a device could announce a sweep of
    ±9000° (the scenario schema caps joint_limit at ±360°) and be mapped."""
    with pytest.raises(DeviceError) as caught:
        _sweep_on(hd.announces(**announced))
    assert f"announces {message}; no ring has that" in str(caught.value)


@pytest.mark.parametrize("behaviour", [hd.trickle, hd.out_of_order, hd.good])
def test_slow_or_reordered_devices_deliver_exactly_what_they_sent(behaviour):
    sweep, _ = _sweep_on(behaviour)
    assert list(sweep.steps) == list(range(hd.MIN_STEP, hd.MAX_STEP + 1))
    assert sweep.missing_steps == ()
    for step, row in zip(sweep.steps, sweep.counts):
        assert list(row) == hd.counts_for(int(step))


def test_out_of_order_scans_are_not_counted_as_millions_lost():
    dev = hd.HostileDevice(hd.out_of_order)
    try:
        with SerialRing(dev.link, timeout_s=TIMEOUT_S) as ring:
            ring.sweep()
            assert ring.stats.lost_scans <= 5 and ring.stats.out_of_order == 4
    finally:
        dev.close()


@pytest.mark.parametrize("behaviour", [hd.flood_irpos, hd.done_without_steps, hd.error_reply(4)])
def test_drive_on_a_hostile_device_exits_3_with_one_line_and_writes_nothing(
        tmp_path, capsys, behaviour):
    dev = hd.HostileDevice(behaviour)
    out = tmp_path / "out"
    try:
        code = main(["drive", "--port", dev.link, "--timeout", str(TIMEOUT_S), "--no-wait",
                     "--no-animation", "--out", str(out)])
    finally:
        dev.close()
    err = capsys.readouterr().err
    assert code == 3, err
    assert "Traceback" not in err
    assert not out.exists() and list(tmp_path.iterdir()) == []   # no partial output


def _drive(tmp_path, behaviour, *extra, poses=3, timeout_s=TIMEOUT_S):
    """irring drive on a hostile device at ``poses`` poses 100 mm apart → (status, out)."""
    dev = hd.HostileDevice(behaviour)
    out = tmp_path / "out"
    argv = ["drive", "--port", dev.link, "--timeout", str(timeout_s), "--no-wait",
            "--no-animation", "--out", str(out), "--resweep", "0", *extra]
    for k in range(poses):
        argv += ["--pose", f"{100 * k},{30 + 7 * k},{5 * k}"]
    try:
        return main(argv), out
    finally:
        dev.close()


def _recorded(out) -> list:
    sweeps, _ = load_recording(out / "sweeps.npz")
    for sweep in sweeps:   # what was recorded is what the device sent, nothing invented
        for step, row in zip(sweep.steps, sweep.counts):
            assert list(row) == hd.counts_for(int(step))
    return sweeps


def _irdon_counting(dev, cmd):
    """A firmware whose IRDON gives how many IRSCN it has sent, not the seq of the last: one
    more than the protocol's number."""
    if isinstance(cmd, hd.p.SweepCommand):
        for step in range(cmd.from_step, cmd.to_step + 1):
            dev.send(hd.scan(dev.seq, step))
            dev.seq += 1
        dev.send(hd.line(f"IRDON,{dev.seq}"))
    elif isinstance(cmd, hd.p.Stop):
        dev.send(hd.line(f"IRDON,{dev.seq}"))
    else:
        hd.good(dev, cmd)


def test_an_irdon_one_past_the_last_seq_loses_no_step_of_the_next_sweep(tmp_path, capsys):
    """A firmware whose IRDON counts its IRSCN (one past the last seq): the next sweep's first
    IRSCN, numbered before what that IRDON said, was dropped as stale at every pose after the
    first (step -2 missing at 3 of 4 poses, and from each re-sweep too), though it arrived
    intact and its seq fits the sweep's own numbering. It is taken; a leftover of an earlier
    sweep, numbered before every step of this one by an honest IRDON, still is not."""
    code, out = _drive(tmp_path, _irdon_counting, poses=4)
    err = capsys.readouterr().err
    assert code == 0, err
    sweeps = _recorded(out)
    assert [list(s.steps) for s in sweeps] == [[-2, -1, 0, 1, 2]] * 4
    assert all(s.missing_steps == () for s in sweeps)
    report = json.loads((out / "link.json").read_text())
    assert [r["link"]["stale"] for r in report["sweeps"]] == [0, 0, 0, 0]


@pytest.mark.parametrize("later, said", [
    (hd.error_reply(3), "the ring rejected $IRSWP,-2,2,1,0*408C: IRERR 3 (bad argument)"),
    (hd.error_reply(5), "the ring kept refusing $IRSWP,-2,2,1,0*408C: IRERR 5 (busy)"),
])
def test_a_device_refusing_the_second_pose_keeps_the_first(tmp_path, capsys, later, said):
    """A refusal ended the drive as exit 3 with nothing written: the complete first sweep
    was thrown away."""
    code, out = _drive(tmp_path, hd.good_then(later))
    err = capsys.readouterr().err
    assert code == 3, err
    assert said in err and "Traceback" not in err
    sweeps = _recorded(out)
    assert len(sweeps) == 1 and list(sweeps[0].steps) == [-2, -1, 0, 1, 2]
    assert np.allclose(sweeps[0].pose, [0.0, 0.030, 0.0])
    link = json.loads((out / "link.json").read_text())
    assert len(link["sweeps"]) == 1 and said in link["error"]


def test_input_ending_at_the_pose_prompt_keeps_what_was_swept(tmp_path, capsys, monkeypatch):
    """Ctrl-D at "press Enter" was an internal error (exit 70) that lost the first sweep."""
    class Terminal(io.StringIO):   # a terminal whose input has ended
        def isatty(self):
            return True

    monkeypatch.setattr("sys.stdin", Terminal(""))
    dev = hd.HostileDevice(hd.good)
    out = tmp_path / "out"
    try:
        code = main(["drive", "--port", dev.link, "--timeout", str(TIMEOUT_S), "--out",
                     str(out), "--no-animation", "--pose", "0,30", "--pose", "100,37"])
    finally:
        dev.close()
    err = capsys.readouterr().err
    assert code == 130, err
    assert "irring drive: input ended before pose 2 of 2; the 1 pose swept is mapped" in err
    assert "internal error" not in err
    assert len(_recorded(out)) == 1


def test_ctrl_c_in_a_sweep_keeps_the_finished_poses_and_the_steps_that_arrived(tmp_path,
                                                                               capsys):
    heard = []
    device = hd.good_then(hd.interrupt_after(3))

    def listening(dev, cmd):
        heard.append(cmd.TYPE)
        device(dev, cmd)

    # a silence of timeout_s ends the pass with IRSTP before the Ctrl-C: the device is quiet
    # for its 0.05 s pause and a loaded machine can stretch that past 0.15 s (it did, at
    # load 10-16); the interrupt, not the timeout, ends the drive, so a long one costs nothing
    code, out = _drive(tmp_path, listening, timeout_s=2.0)
    err = capsys.readouterr().err
    # the ring is told to stop turning (heard while the host maps, before the pty closes);
    # this device goes quiet, so its IRDON is waited for at close, not asked for again, and
    # the ring is not turned back to step 0: the person is told
    assert heard == ["IRHLO", "IRSWP", "IRSWP", "IRSTP"]
    assert code == 130, err
    warning = next(ln for ln in err.splitlines() if ln.startswith("irring drive: warning:"))
    assert warning.endswith(
        " was not turned back to step 0 at the end of the session (no IRDON answered IRSTP "
        "within 2 s, so it may still turn; it was last heard of at step 0). Its firmware "
        "takes the step it stands at when it starts for step 0, and an Arduino restarts each "
        "time its port is opened: turn the ring radial by hand, or send $IRGTO,0*E3DD, "
        "before the next session")
    assert ("irring drive: interrupted during pose 2 of 3; the 1 pose swept and 3 of 5 steps "
            "of pose 2 are mapped") in err
    first, second = _recorded(out)
    assert list(first.steps) == [-2, -1, 0, 1, 2]
    assert list(second.steps) == [-2, -1, 0] and second.missing_steps == (1, 2)
    assert json.loads((out / "link.json").read_text())["error"] == "interrupted"


def test_a_device_clock_that_jumps_days_is_not_the_sweeps_hardware_time(tmp_path, capsys):
    """Two steps 2³¹ ms apart on the device clock made a 5-step sweep "take" 10.7 million s:
    drive printed it and wrote a sweeps.npz that replay refused (duration_s > 10⁷ s)."""
    code, out = _drive(tmp_path, hd.clock_jump, poses=1)
    assert code == 0, capsys.readouterr().err
    (sweep,) = _recorded(out)                          # replay can read what drive wrote
    assert list(sweep.steps) == [-2, -1] and sweep.missing_steps == (0, 1, 2)
    assert sweep.duration_s == pytest.approx(5 * 0.0383)   # the nominal 5 steps × 38.3 ms
    link = json.loads((out / "link.json").read_text())
    assert link["totals"]["clock_faults"] == 1
    assert "1 device clock faults" in link["sweeps"][0]["message"]
    assert main(["replay", str(out / "sweeps.npz"), "--out", str(tmp_path / "re"),
                 "--no-animation"]) == 0


def test_a_device_clock_that_stands_still_is_not_the_sweeps_hardware_time(tmp_path, capsys):
    """Every step at the same device time: drive reported "hardware 0.0 s" for the sweep and
    recorded it, though no sensor reads faster than a reading in 1 ms."""
    code, out = _drive(tmp_path, hd.stuck_clock, poses=1)
    assert code == 0, capsys.readouterr().err
    (sweep,) = _recorded(out)
    assert list(sweep.steps) == [-2, -1, 0, 1, 2]
    assert sweep.duration_s == pytest.approx(5 * 0.0383)   # the nominal 5 steps × 38.3 ms
    assert json.loads((out / "link.json").read_text())["totals"]["clock_faults"] == 1


def test_drive_poses_too_far_apart_to_map_are_refused_before_any_sweep(tmp_path, capsys):
    """--pose 0,0 --pose 1000000,-700000: both poses were swept, then the map's grid was
    refused (exit 5) and every reading was lost; the message advised map.resolution_mm,
    which drive does not have."""
    swept = []

    def counting(dev, cmd):
        swept.append(isinstance(cmd, p_.SweepCommand))
        hd.good(dev, cmd)

    dev = hd.HostileDevice(counting)
    out = tmp_path / "out"
    try:
        code = main(["drive", "--port", dev.link, "--timeout", str(TIMEOUT_S), "--no-wait",
                     "--out", str(out), "--pose", "0,0", "--pose", "1000000,-700000,90"])
    finally:
        dev.close()
    err = capsys.readouterr().err
    assert code == 5, err
    # 700 m + 2 × (150 mm ring + 2 × 624 mm reach + 100 mm margin) = 702.996 m: 70,302 rows
    assert "--pose: a grid of 70,302 × 100,302 cells of 10 mm would need about 423.1 GB" in err
    assert ("are mapped: poses 1000 m × 700 m apart are too far apart to map together; map "
            "each part on its own") in err and "resolution_mm" not in err
    assert not any(swept) and not out.exists()


def test_calibrate_on_a_sensor_the_ring_does_not_have_says_so_before_a_placement(
        tmp_path, capsys, monkeypatch):
    """--sensor 20 on a 12-sensor ring asked for the first wall, then ended in exit 70
    (IndexError) once it was placed; on the simulated rig the same was exit 1."""
    monkeypatch.setattr("builtins.input", lambda prompt="": pytest.fail("asked: " + prompt))
    dev = hd.HostileDevice(hd.good)
    try:
        code = main(["calibrate", "--port", dev.link, "--sensor", "12",
                     "--out", str(tmp_path / "c.yaml")])
    finally:
        dev.close()
    assert code == 2
    assert ("irring calibrate: error: --sensor 12: the ring on "
            f"{dev.link} has sensors 0 … 11") in capsys.readouterr().err
    assert main(["calibrate", "--scenario", "t_room", "--sensor", "12",
                 "--out", str(tmp_path / "c.yaml")]) == 2
    assert ("irring calibrate: error: --sensor 12: t_room's ring has sensors 0 … 11"
            in capsys.readouterr().err)
    assert list(tmp_path.iterdir()) == []


def test_seeds_counted_past_the_largest_seed_are_refused_naming_the_scenario(short_tmp, capsys):
    """A scenario of seed 2^63 - 1 and 2 seeds ran seed 2^63 in study, compare and bench rooms
    (results.csv held it); `irring run --seed` refuses that seed, so the run could not be run
    again by hand."""
    tmp_path = short_tmp
    text = resolve("t_room").read_text().replace("\nseed: 1\n", "\nseed: 9223372036854775807\n")
    (tmp_path / "top.yaml").write_text(text)
    (tmp_path / "s.yaml").write_text("designs: [rotating12]\nscenarios: [top.yaml]\nseeds: 2\n")
    said = (f"{tmp_path / 'top.yaml'}: seed: 9223372036854775807 and 2 seeds counted up from it "
            "reach 9223372036854775808; allowed up to 9223372036854775807 (the largest seed a "
            "scenario or --seed takes): give the scenario a seed of at most 9223372036854775806")
    for argv, status in (
            (["study", str(tmp_path / "s.yaml"), "--out", str(tmp_path / "st")], 1),
            (["compare", "--scenario", str(tmp_path / "top.yaml"), "--design", "rotating12",
              "--seeds", "2", "--out", str(tmp_path / "cmp")], 1),
            (["bench", "rooms", str(tmp_path / "top.yaml"), "--seeds", "2", "--out",
              str(tmp_path / "br")], 1)):
        assert main(argv) == status, argv
        err = capsys.readouterr().err
        assert said in err and "internal error" not in err, argv
    with pytest.raises(StudyError, match=re.escape(f"s.yaml: seeds: scenarios[0]: {said}")):
        load_study(tmp_path / "s.yaml")
    assert not (tmp_path / "st").exists() and not (tmp_path / "cmp").exists()
    with pytest.raises(ScenarioError, match=re.escape(said)):
        jobs_for([str(tmp_path / "top.yaml")], [Config()], 2)
    (tmp_path / "s.yaml").write_text("designs: [rotating12]\nscenarios: [top.yaml]\nseeds: 1\n")
    assert [p.seed for p in grid(load_study(tmp_path / "s.yaml"))] == [2**63 - 1]


@pytest.fixture(scope="module")
def one_run_study(tmp_path_factory):
    """A finished one-run study (t_room_cylinder, rotating12, seed 1): (study file, out)."""
    d = tmp_path_factory.mktemp("study")
    (d / "s.yaml").write_text("designs: [rotating12]\nscenarios: [t_room_cylinder]\n"
                              "seeds: [1]\n")
    assert main(["study", str(d / "s.yaml"), "--out", str(d / "o"), "--workers", "1"]) == 0
    return d / "s.yaml", (d / "o" / "results.csv").read_text()


@pytest.mark.parametrize("edit, message", [
    (lambda row: row.update(occupied_recall="inf"),
     "line 2, occupied_recall: 'inf' is not allowed; a number 0 … 1 or empty (n/a)"),
    (lambda row: row.update(occupied_f1="nan"), "line 2, occupied_f1: 'nan' is not allowed"),
    (lambda row: row.update(hardware_time_s="hello"),
     "line 2, hardware_time_s: 'hello' is not allowed; a finite number"),
    (lambda row: row.update(seed="2.5"), "line 2, seed: '2.5' is not allowed; a whole number"),
    (lambda row: row.update(compute_ms=""), "line 2, compute_ms: '' is not allowed"),
    (None, "line 3 repeats the run of line 2 (rotating12, t_room_cylinder, seed 1)"),
    # past csv's field limit (128 kB): exit 70 "Error: field larger than field limit"
    (lambda row: row.update(sensor="x" * 200_000), "line 2 is longer than 65,536 bytes (a study "
                                                   "writes ~500); the file was edited or damaged"),
])
def test_a_damaged_results_csv_is_refused_on_resume_naming_line_and_column(
        tmp_path, capsys, one_run_study, edit, message):
    """--resume read 'inf' or text in a score as exit 70 (RuntimeWarning / ValueError), a
    'nan' score as NaN in summary.json, and a repeated row as a third run of a 2-seed
    configuration (runs: 3)."""
    study, text = one_run_study
    header, line = text.splitlines()[:2]
    row = dict(zip(header.split(","), line.split(",")))
    if edit is None:
        lines = [header, line, line]
    else:
        edit(row)
        lines = [header, ",".join(row.values())]
    out = tmp_path / "o"
    out.mkdir()
    (out / "results.csv").write_text("\n".join(lines) + "\n")
    assert main(["study", str(study), "--out", str(out), "--workers", "1", "--resume"]) == 1
    err = capsys.readouterr().err
    assert f"{out / 'results.csv'}: {message}" in err and "internal error" not in err
    assert sorted(p.name for p in out.iterdir()) == ["results.csv"]   # nothing run or summarised


@pytest.mark.parametrize("edit, status, message", [
    # Excel's "CSV UTF-8" starts with a BOM: read as "columns are not the ones this irring
    # writes (33 columns, expected 33 …)"; now resumed
    (lambda data: b"\xef\xbb\xbf" + data, 0, None),
    # saved in Latin-1 / cp1252: exit 70 (UnicodeDecodeError)
    (lambda data: data.replace(b"t_room_cylinder", b"t_r\xe9om", 2), 1,
     "line 2: not UTF-8 text (byte "),
    (lambda data: data.replace(b",seed,", b",Seed,", 1), 1,
     "its columns are not the ones this irring writes (column 6 is 'Seed', expected 'seed')"),
])
def test_a_results_csv_saved_by_a_spreadsheet_is_resumed_or_named(tmp_path, capsys,
                                                                  one_run_study, edit, status,
                                                                  message):
    study, text = one_run_study
    out = tmp_path / "o"
    out.mkdir()
    (out / "results.csv").write_bytes(edit(text.encode()))
    assert main(["study", str(study), "--out", str(out), "--workers", "1", "--resume"]) == status
    err = capsys.readouterr().err
    if message is None:   # nothing run again: the kept row, rewritten without the BOM
        assert (out / "results.csv").read_text() == text
        assert json.loads((out / "summary.json").read_text())["configurations"][0]["runs"] == 1
    else:
        assert f"{out / 'results.csv'}: {message}" in err and "internal error" not in err


def test_a_results_csv_with_a_blank_first_line_is_refused_not_overwritten(tmp_path, capsys,
                                                                         one_run_study):
    """Read line by line, a blank first line was taken for an empty file: the study then
    opened results.csv afresh ('w') and its kept run was lost, without --resume."""
    study, text = one_run_study
    out = tmp_path / "o"
    out.mkdir()
    (out / "results.csv").write_text("\n" + text)
    assert main(["study", str(study), "--out", str(out), "--workers", "1"]) == 1
    err = capsys.readouterr().err
    assert (f"{out / 'results.csv'}: its columns are not the ones this irring writes "
            f"(0 columns, expected {len(COLUMNS)})") in err
    assert (out / "results.csv").read_text() == "\n" + text
    assert sorted(p.name for p in out.iterdir()) == ["results.csv"]


def test_a_results_csv_that_is_not_a_file_is_refused_not_read(tmp_path, one_run_study):
    """results.csv was read whole (read_bytes): a pipe there hung --resume for good (a link
    to /dev/zero filled memory: exit 5 'ran out of memory' under a memory limit)."""
    import subprocess
    import sys

    study, _ = one_run_study
    out = tmp_path / "o"
    out.mkdir()
    os.mkfifo(out / "results.csv")
    done = subprocess.run([sys.executable, "-m", "irring", "study", str(study), "--out",
                           str(out), "--workers", "1", "--resume"], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 1, done.stderr
    assert (f"irring study: error: {out / 'results.csv'}: not a regular file; a study's "
            "results.csv is the file it wrote: choose another --out") in done.stderr


@pytest.mark.parametrize("resume", [False, True])
def test_a_results_csv_that_is_a_link_is_refused_not_written_through(tmp_path, capsys,
                                                                     one_run_study, resume):
    """A dangling link made the study create its target (anywhere: we run as root) and write
    its rows there, then replace the link; a link to another study's results.csv had this
    study's rows appended to it with --resume."""
    study, text = one_run_study
    out, elsewhere = tmp_path / "o", tmp_path / "elsewhere.csv"
    out.mkdir()
    if resume:
        elsewhere.write_text(text)
    (out / "results.csv").symlink_to(elsewhere)
    argv = ["study", str(study), "--out", str(out), "--workers", "1"]
    assert main(argv + ["--resume"] * resume) == 4
    assert (f"{out / 'results.csv'}: a symbolic link (to {elsewhere}); a study appends to its "
            "own results.csv in --out: remove the link or choose another --out"
            in capsys.readouterr().err)
    assert (elsewhere.read_text() == text) if resume else not elsewhere.exists()
    assert (out / "results.csv").is_symlink() and os.listdir(out) == ["results.csv"]


def test_a_study_into_the_folder_another_study_is_writing_is_refused(tmp_path, capsys,
                                                                     one_run_study):
    """Two studies into one --out (the second with --resume while the first ran): each
    rewrote the results.csv the other was appending to; exit 0 twice, the second's 40 runs
    lost and a cut row ("ing12,…") left in the file. A running study holds its --out (an
    flock on the folder, as taken here); a second is refused before it reads or runs."""
    fcntl = pytest.importorskip("fcntl")
    study, text = one_run_study
    out = tmp_path / "o"
    out.mkdir()
    (out / "results.csv").write_text(text)
    argv = ["study", str(study), "--out", str(out), "--workers", "1", "--resume"]
    fd = os.open(out, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)   # what the running study holds
        assert main(argv) == 4
        assert (f"irring study: error: {out}: another irring process is writing a study's "
                "results.csv there; wait for it to finish, or choose another --out"
                in capsys.readouterr().err)
        assert (out / "results.csv").read_text() == text and os.listdir(out) == ["results.csv"]
    finally:
        os.close(fd)
    assert main(argv) == 0 and (out / "results.csv").read_text() == text   # held no more


@pytest.mark.parametrize("command", ["run", "replay", "bench rooms", "compare",
                                     "bench accuracy"])
def test_a_run_into_a_folder_another_process_holds_is_refused_before_the_work(
        tmp_path, capsys, monkeypatch, good_recording, command):
    """A run into the --out a study holds waited 30 s for the commit lock after the whole
    run, then exit 4 with the run's work lost. The folder is probed before the work: held
    past PROBE_WAIT_S (a commit is over by then, a study is not), exit 4, nothing run."""
    fcntl = pytest.importorskip("fcntl")
    from irring import outputs

    monkeypatch.setattr(outputs, "PROBE_WAIT_S", 0.3)
    monkeypatch.setattr(pipeline, "run", lambda *a, **k: pytest.fail("ran"))
    monkeypatch.setattr(pipeline, "replay", lambda *a, **k: pytest.fail("ran"))
    from irring.studies import accuracy, compare
    monkeypatch.setattr(compare, "compare", lambda *a, **k: pytest.fail("ran"))
    monkeypatch.setattr(accuracy, "measure", lambda *a, **k: pytest.fail("ran"))
    out = tmp_path / "held out"
    out.mkdir()
    (out / "results.csv").write_text("design\n")
    recording = tmp_path / "rec.npz"
    recording.write_bytes(good_recording)
    argv = {"run": ["run", "t_room_cylinder"], "replay": ["replay", str(recording)],
            "bench rooms": ["bench", "rooms", "t_room_cylinder"],
            "compare": ["compare", "--scenario", "t_room_cylinder"],
            "bench accuracy": ["bench", "accuracy", "--scenario", "t_room_cylinder"]}[command]
    fd = os.open(out, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)   # what a running study holds
        started = time.monotonic()
        assert main([*argv, "--out", str(out)]) == 4
        assert time.monotonic() - started < 20
    finally:
        os.close(fd)
    assert capsys.readouterr().err.endswith(
        f"error: --out {out}: another irring process holds the folder (a study writing its "
        "results there?); nothing was run: choose another --out, or run again when it is "
        "done\n")
    assert os.listdir(out) == ["results.csv"]
    assert sorted(os.listdir(tmp_path)) == ["held out", "rec.npz"]


def test_a_folder_held_for_a_moment_is_waited_for(tmp_path, monkeypatch):
    """A commit holds the folder for milliseconds: the probe waits it out, not refuses.
    Counted, not timed (a timer releasing the lock after 0.3 s, the probe bound to finish
    within 3 s of wall clock, failed under load): the probe's clock and sleeps are this
    test's, and the holder lets go during the probe's 15th poll, 0.3 s into its wait."""
    fcntl = pytest.importorskip("fcntl")
    from irring import outputs

    out = tmp_path / "o"
    out.mkdir()
    fd = os.open(out, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    polls = []

    class Clock:   # the probe's time: advanced only by its own polls
        now = 0.0

        @classmethod
        def monotonic(cls):
            return cls.now

        @classmethod
        def sleep(cls, seconds):
            polls.append(seconds)
            cls.now += seconds
            if len(polls) == 15:
                os.close(fd)   # the other commit ends

    monkeypatch.setattr(outputs, "time", Clock)
    assert outputs.check_out(out, held=False) == out
    assert polls == [0.02] * 15                     # held at each try before, taken after
    assert Clock.now == pytest.approx(0.3) and Clock.now < outputs.PROBE_WAIT_S
    probe = os.open(out, os.O_RDONLY)               # and let go again
    try:
        fcntl.flock(probe, fcntl.LOCK_EX | fcntl.LOCK_NB)
    finally:
        os.close(probe)


def test_a_pipe_or_folder_among_a_folders_rooms_is_named_not_waited_for(tmp_path):
    """`irring bench rooms DIR` with a FIFO named c.yaml in DIR waited for a writer for good
    (killed after 60 s: 'interrupted'); a folder b.yaml too would be read as a room. Each is
    a row naming it, and the other rooms are scored."""
    import threading

    from irring.studies.rooms import Unusable, resolve_rooms

    (tmp_path / "a.yaml").write_text(resolve("t_room_cylinder").read_text())
    (tmp_path / "b.yaml").mkdir()
    os.mkfifo(tmp_path / "c.yaml")
    (tmp_path / "d.yaml").symlink_to(tmp_path / "gone.yaml")
    (tmp_path / "e.yaml").symlink_to("e.yaml")   # a loop: Path.resolve raised RuntimeError
    got = []
    worker = threading.Thread(target=lambda: got.extend(resolve_rooms([tmp_path])), daemon=True)
    worker.start()
    worker.join(60)
    if worker.is_alive():   # free the thread before failing: open the pipe's far end
        os.close(os.open(tmp_path / "c.yaml", os.O_WRONLY | os.O_NONBLOCK))
        pytest.fail("resolve_rooms waited on the pipe")
    assert got[0].name == "t_room_cylinder"
    assert got[1:] == [
        Unusable("b", str(tmp_path / "b.yaml"), 1, f"{tmp_path}/b.yaml: is a folder, not a "
                 "scenario file; a folder's rooms are its regular *.yaml files"),
        Unusable("c", str(tmp_path / "c.yaml"), 1, f"{tmp_path}/c.yaml: is a pipe, socket or "
                 "device, not a scenario file; a folder's rooms are its regular *.yaml files"),
        Unusable("d", str(tmp_path / "d.yaml"), 1, f"{tmp_path}/d.yaml: is a broken link (or a "
                 "loop of links), not a scenario file; a folder's rooms are its regular *.yaml "
                 "files"),
        Unusable("e", str(tmp_path / "e.yaml"), 1, f"{tmp_path}/e.yaml: is a broken link (or a "
                 "loop of links), not a scenario file; a folder's rooms are its regular *.yaml "
                 "files")]


def test_a_loop_of_links_named_as_a_path_is_an_error_not_a_crash(tmp_path, capsys):
    """A link to itself as the recording, or as --mcap, ended in exit 70 (RuntimeError:
    Symlink loop, from Path.resolve)."""
    from irring.cli._common import mcap_beside_outputs

    loop = tmp_path / "loop"
    loop.symlink_to("loop")
    assert main(["replay", str(loop), "--out", str(tmp_path / "o")]) == 1
    assert capsys.readouterr().err == f"irring replay: error: {loop}: no such recording\n"
    # --mcap at the loop is a file name like any other: the MCAP replaces the link
    assert mcap_beside_outputs(loop, tmp_path / "o") is None
    assert sorted(os.listdir(tmp_path)) == ["loop"]


def test_an_mcap_given_to_replay_is_named_as_one(tmp_path, capsys):
    # was "not an irring recording (.npz), or a damaged one: BadZipFile: File is not a zip
    # file", of the file `run --mcap` wrote beside the recording
    mcap = tmp_path / "map.mcap"
    mcap.write_bytes(b"\x89MCAP0\r\n" + bytes(64))
    assert main(["replay", str(mcap), "--out", str(tmp_path / "o")]) == 1
    assert capsys.readouterr().err == (
        f"irring replay: error: {mcap}: an MCAP file (what --mcap writes for viewers such as "
        "Foxglove), not a recording; replay the sweeps.npz written beside it\n")
    assert os.listdir(tmp_path) == ["map.mcap"]


def test_an_output_path_with_a_line_break_or_an_escape_is_printed_on_one_line(tmp_path,
                                                                              capsys):
    # "wrote" printed --out raw: a line break split the summary, an escape reached the
    # terminal (error lines were already made printable, round 7's D14)
    out = tmp_path / "a\nb \x1b[31mred"
    assert main(["run", "t_room_cylinder", "--out", str(out), "--no-animation"]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == (
        f"  wrote     {tmp_path}/a b \\x1b[31mred/: map.png, map.pgm, map.yaml, sweeps.npz")
    assert sorted(os.listdir(out)) == ["map.pgm", "map.png", "map.yaml", "sweeps.npz"]


def test_an_error_of_a_bench_names_the_bench(tmp_path, capsys):
    # said "irring bench: error: …", where the bench's own errors say "irring bench rooms"
    assert main(["bench", "rooms", str(tmp_path)]) == 1
    assert capsys.readouterr().err == (f"irring bench rooms: error: {tmp_path}: the folder "
                                       "holds no *.yaml scenario\n")


def test_a_results_csv_with_a_line_break_in_a_cell_is_resumed(tmp_path, capsys):
    """A scenario path with a line break is written quoted over two lines; --resume split
    the file at every line break and refused the study's own file ('line 2 has 2 cells')."""
    scene = tmp_path / "t\nroom.yaml"
    scene.write_text(resolve("t_room_cylinder").read_text())
    (tmp_path / "s.yaml").write_text(f'designs: [rotating12]\nscenarios: ["{tmp_path}/t\\nroom.yaml"]'
                                     "\nseeds: 2\n")
    argv = ["study", str(tmp_path / "s.yaml"), "--out", str(tmp_path / "o"), "--workers", "1"]
    assert main(argv) == 0
    text = (tmp_path / "o" / "results.csv").read_text()
    assert text.count("\n") == 5          # the header and two rows of two lines each
    capsys.readouterr()
    assert main(argv + ["--resume"]) == 0
    assert ": ran 0 in " in capsys.readouterr().out
    assert (tmp_path / "o" / "results.csv").read_text() == text


@pytest.mark.parametrize("seeds, long, by", [((1, 2, 3), False, "3 by line 4"),
                                             ((1, 2), True, "2 by line 3")])
def test_a_results_csv_of_more_runs_than_a_study_may_read_back_is_refused(
        tmp_path, capsys, one_run_study, monkeypatch, seeds, long, by):
    """It was read whole, whatever its size; now row by row, each costing what a row read
    back holds (RESULT_ROW_BYTES), a long line its excess as well."""
    from irring.studies import study as study_mod
    monkeypatch.setattr(study_mod, "RESULT_ROW_BYTES", 10**9)   # a study may read back 2 rows
    study, text = one_run_study
    header, line = text.splitlines()[:2]
    out = tmp_path / "o"
    out.mkdir()
    rows = [line.replace("t_room_cylinder,1,1,0.0,1,", f"t_room_cylinder,1,1,0.0,{seed},")
            for seed in seeds]
    if long:   # 60 kB: within a line's limit, so two rows cost more than 2 GB
        rows[0] = rows[0].replace("rotating12", "r" * 60_000)
    (out / "results.csv").write_text("\n".join([header, *rows]) + "\n")
    assert main(["study", str(study), "--out", str(out), "--workers", "1", "--resume"]) == 5
    assert (f"{out / 'results.csv'}: its runs read back to summarise ({by}) (about "
            f"{len(seeds):.1f} GB), more than the 2 GB a study may use: choose another --out, "
            "or split the file" in capsys.readouterr().err)


def test_a_resume_whose_kept_and_new_runs_are_too_many_to_read_back_is_refused(
        tmp_path, capsys, one_run_study, monkeypatch):
    """Rows of points no longer in the study are kept and read back with the new ones: a
    file of many old runs resumed with another study of many runs passed each bound alone."""
    from irring.studies import study as study_mod
    monkeypatch.setattr(study_mod, "RESULT_ROW_BYTES", 10**9)   # a study may read back 2 rows
    _, text = one_run_study
    out = tmp_path / "o"
    out.mkdir()
    (out / "results.csv").write_text(text)                     # seed 1
    (tmp_path / "s.yaml").write_text("designs: [rotating12]\nscenarios: [t_room_cylinder]\n"
                                     "seeds: [2, 3]\n")
    assert main(["study", str(tmp_path / "s.yaml"), "--out", str(out), "--workers", "1",
                 "--resume"]) == 5
    assert (f"1 runs kept in {out / 'results.csv'} and 2 to run, read back to summarise (about "
            "3.0 GB), more than the 2 GB a study may use: choose another --out"
            in capsys.readouterr().err)
    assert (out / "results.csv").read_text() == text


def test_a_results_csv_that_cannot_be_written_names_it_and_keeps_the_runs(tmp_path, capsys,
                                                                          monkeypatch):
    """A full disk or a file-size limit (ulimit -f) while streaming results.csv ended in
    exit 1 'File too large' (or exit 4 'No space left on device'), naming no file."""
    from irring.studies import study as study_mod
    (tmp_path / "s.yaml").write_text("designs: [rotating12]\nscenarios: [t_room_cylinder]\n"
                                     "seeds: 3\n")
    real_writer = study_mod.csv.writer

    class Filling:   # the header and two rows fit; the third does not
        def __init__(self, fh):
            self.fh, self.rows, self.w = fh, 0, real_writer(fh)

        def writerow(self, cells):
            self.rows += 1
            if self.rows > 3:
                raise OSError(errno.EFBIG, "File too large")
            return self.w.writerow(cells)

    monkeypatch.setattr(study_mod.csv, "writer", Filling)
    out = tmp_path / "o"
    argv = ["study", str(tmp_path / "s.yaml"), "--out", str(out), "--workers", "1"]
    assert main(argv) == 4
    err = capsys.readouterr().err
    assert (f"{out / 'results.csv'}: cannot write the study's results: File too large; the 2 "
            "run(s) written before are kept (free space, then rerun with --resume)") in err
    assert len((out / "results.csv").read_text().splitlines()) == 3
    monkeypatch.undo()
    assert main(argv + ["--resume"]) == 0   # the third run only
    assert len((out / "results.csv").read_text().splitlines()) == 4


def test_a_run_on_a_full_disk_names_its_out_folder(tmp_path):
    """ENOSPC / EFBIG while writing the outputs said only 'No space left on device' or
    'File too large' (EFBIG as exit 1, 'bad input')."""
    import resource
    import subprocess
    import sys

    def limit():   # about 30 KB a file: the map PNG fits, the GIF does not
        resource.setrlimit(resource.RLIMIT_FSIZE, (30_000, 30_000))

    out = tmp_path / "o"
    done = subprocess.run([sys.executable, "-m", "irring", "run", "t_room_cylinder", "--out",
                           str(out)], preexec_fn=limit, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 4, done.stderr
    assert (f"irring run: error: --out {out}: cannot write the outputs there: File too large; "
            "nothing was changed") in done.stderr
    assert os.listdir(tmp_path) == []   # no output folder, no temporaries left


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGHUP"])
@pytest.mark.parametrize("command, writer", [
    (["run", "t_room_cylinder", "--out", "{out}"], "irring.recording.save_recording"),
    (["run", "t_room_cylinder", "--out", "{out}", "--mcap", "{tmp}/m.mcap"],
     "irring.maps.mcap_export._polygon"),
])
def test_a_command_killed_while_writing_leaves_no_half_written_outputs(tmp_path, command,
                                                                       writer, sig):
    """`kill` (SIGTERM, what timeout(1), a job scheduler or systemd send) while a run wrote
    its outputs ended the process at once: a hidden .irring-o-…/ folder of half the files or
    a half .irring-m.mcap-… file stayed beside --out, one more each time. It now stops as
    Ctrl-C does (exit 130) and removes them; so does SIGHUP (the terminal or SSH session
    closed: exit 129 and the temporaries, before). The signal is sent from inside the writer."""
    module, name = writer.rsplit(".", 1)
    script = (f"import os, signal, sys, {module} as m\n"
              f"real = m.{name}\n"
              "def killed(*a, **k):\n"
              f"    os.kill(os.getpid(), signal.{sig})\n"
              "    return real(*a, **k)\n"
              f"m.{name} = killed\n"
              "from irring.cli import main\n"
              "sys.exit(main(sys.argv[1:]))\n")
    argv = [a.format(out=tmp_path / "o", tmp=tmp_path) for a in command]
    done = subprocess.run([sys.executable, "-c", script, *argv], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 130, done.stderr
    assert "irring run: interrupted" in done.stderr
    # killed while the MCAP is written, the set is not moved in either (it was: a new set
    # beside no MCAP, or an earlier run's)
    left = sorted(os.listdir(tmp_path))
    assert left == [], left


def test_a_drive_whose_terminal_hangs_up_keeps_the_poses_swept(tmp_path):
    """SIGHUP (the SSH session or terminal closed) mid-drive killed it outright: exit 129,
    nothing written, every pose swept lost (SIGTERM and Ctrl-C map and write them). The
    hang-up is sent as the second pose's sweep begins, from a subprocess on a pty device."""
    script = (
        "import os, signal, sys\n"
        f"sys.path.insert(0, {os.path.dirname(os.path.abspath(__file__))!r})\n"
        "import hostile_devices as hd\n"
        "from irring.hardware import SerialRing\n"
        "real, calls = SerialRing.sweep, []\n"
        "def sweep(self, *a, **k):\n"
        "    calls.append(1)\n"
        "    if len(calls) == 2:\n"
        "        os.kill(os.getpid(), signal.SIGHUP)\n"
        "    return real(self, *a, **k)\n"
        "SerialRing.sweep = sweep\n"
        "dev = hd.HostileDevice(hd.good)\n"
        "from irring.cli import main\n"
        "code = main(['drive', '--port', dev.link, '--pose', '500,450', '--pose', '800,450',\n"
        "             '--pose', '900,450', '--no-wait', '--no-animation', '--out', sys.argv[1]])\n"
        "dev.close()\n"
        "sys.exit(code)\n")
    out = tmp_path / "o"
    done = subprocess.run([sys.executable, "-c", script, str(out)], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 130, done.stderr
    assert ("irring drive: interrupted during pose 2 of 3; the 1 pose swept is mapped"
            in done.stderr), done.stderr
    assert len(_recorded(out)) == 1


def test_a_drive_with_its_standard_input_closed_sweeps_every_pose(tmp_path):
    """`irring drive … <&-` (started from a service or a script that closed stdin): pose 1
    was swept, then asking the missing stdin isatty() before pose 2 ended the drive in exit
    70 with nothing written. A closed stdin is now read as /dev/null: no terminal, no wait."""
    script = (
        "import sys\n"
        f"sys.path.insert(0, {os.path.dirname(os.path.abspath(__file__))!r})\n"
        "import hostile_devices as hd\n"
        "dev = hd.HostileDevice(hd.good)\n"
        "from irring.cli import main\n"
        "code = main(['drive', '--port', dev.link, '--pose', '500,450', '--pose', '800,450',\n"
        "             '--no-animation', '--out', sys.argv[1]])\n"
        "dev.close()\n"
        "sys.exit(code)\n")
    out = tmp_path / "o"
    done = subprocess.run([sys.executable, "-c", script, str(out)], capture_output=True,
                          text=True, timeout=300, preexec_fn=lambda: os.close(0))
    assert done.returncode == 0, done.stderr
    assert "pose 2/2: all 5 steps received" in done.stdout
    assert len(_recorded(out)) == 2


def test_drive_asks_for_the_next_pose_on_standard_error(tmp_path, capsys, monkeypatch):
    """`irring drive … --json > summary.json` at a terminal: input() wrote each 'move the robot
    to pose K' prompt to standard output, into summary.json (no longer JSON) and unseen by the
    person the drive waited for. The prompt is for the person: it goes to standard error."""
    class Terminal(io.StringIO):   # Enter pressed at each prompt
        def isatty(self):
            return True

    monkeypatch.setattr(sys, "stdin", Terminal("\n\n"))
    dev = hd.HostileDevice(hd.good)
    try:
        code = main(["drive", "--port", dev.link, "--timeout", str(TIMEOUT_S), "--json",
                     "--no-animation", "--out", str(tmp_path / "o"), "--pose", "500,450",
                     "--pose", "800,450,90", "--pose", "900,450"])
    finally:
        dev.close()
    out, err = capsys.readouterr()
    assert code == 0, err
    assert json.loads(out)["poses"] == 3
    assert err.count("and press Enter") == 2
    assert "move the robot to pose 2 of 3 (800 mm, 450 mm, 90°) and press Enter" in err


def test_a_drive_whose_reader_leaves_keeps_sweeping_and_writes_every_pose(tmp_path):
    """`irring drive … | head -1`: the reader took the first line and left, the next progress
    line ('pose 1/3: …') raised BrokenPipeError inside the acquisition, and the drive ended
    exit 4 with nothing written: the swept poses were lost. A progress line is not worth
    the readings: the drive goes on, writes --out, and ends exit 4 when the report cannot
    be printed. The device takes 0.3 s a sweep, so the reader is gone by pose 1's line."""
    script = (
        "import sys, time\n"
        f"sys.path.insert(0, {os.path.dirname(os.path.abspath(__file__))!r})\n"
        "import hostile_devices as hd\n"
        "def slow(dev, cmd):\n"
        "    if isinstance(cmd, hd.p.SweepCommand):\n"
        "        time.sleep(0.3)\n"
        "    hd.good(dev, cmd)\n"
        "dev = hd.HostileDevice(slow)\n"
        "from irring.cli import main\n"
        "code = main(['drive', '--port', dev.link, '--pose', '500,450', '--pose', '800,450',\n"
        "             '--pose', '900,450', '--no-animation', '--out', sys.argv[1]])\n"
        "dev.close()\n"
        "sys.exit(code)\n")
    out = tmp_path / "o"
    proc = subprocess.Popen([sys.executable, "-c", script, str(out)], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = proc.stdout.readline()
    proc.stdout.close()   # `| head -1`
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == errors.OUTPUT, err
    assert first.startswith(b"ring on ")
    assert err == ""
    assert len(_recorded(out)) == 3


@pytest.mark.parametrize("failure, status", [
    (OutputError("out/map.png: No space left on device"), 4),
    (KeyboardInterrupt(), 130),
])
def test_drive_saves_the_sweeps_elsewhere_when_its_outputs_cannot_be_written(
        tmp_path, capsys, monkeypatch, failure, status):
    """A full disk (or a second Ctrl-C) while writing --out lost every sweep of the drive:
    exit 4 with nothing kept, after the robot had been walked through every pose."""
    from irring import pipeline

    def fail(*a, **k):
        raise failure

    monkeypatch.setattr(pipeline, "write_outputs", fail)
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path / "spare"))
    (tmp_path / "spare").mkdir()
    code, out = _drive(tmp_path, hd.good, poses=2)
    err = capsys.readouterr().err
    assert code == status, err
    (saved,) = (tmp_path / "spare").iterdir()
    assert saved.name.startswith("irring-drive-") and saved.suffix == ".npz"
    assert f"the 2 sweeps are kept in {saved}: irring replay {saved}" in err
    sweeps, _ = load_recording(saved)
    assert [list(s.steps) for s in sweeps] == [[-2, -1, 0, 1, 2]] * 2
    assert all(list(row) == hd.counts_for(int(step))
               for s in sweeps for step, row in zip(s.steps, s.counts))
    assert not out.exists()


# --------------------------------------------------------------------------- command line


@pytest.mark.parametrize("argv, status, message", [
    (["drive", "--port", "x", "--timeout", "0"], 2, "--timeout: must be a number of seconds > 0"),
    # exit 3 "Could not open port socket://: '<=' not supported between instances of 'int'
    # and 'NoneType'. Check the device path (ls /dev/ttyUSB* …)"; socket://:99999 said
    # "'debug|info|warning|error'"
    (["drive", "--port", "socket://"], 2,
     "argument --port: expected socket://HOST:PORT with PORT 1 … 65535, got 'socket://'"),
    (["drive", "--port", "socket://:99999"], 2, "expected socket://HOST:PORT with PORT 1 … "
                                                "65535, got 'socket://:99999'"),
    (["calibrate", "--port", "rfc2217://ring.local"], 2,
     "argument --port: expected rfc2217://HOST:PORT with PORT 1 … 65535"),
    (["drive", "--port", ""], 2, "argument --port: an empty port; name a device"),
    (["drive", "--port", "x", "--samples", "65"], 2, "--samples: must be in 1 … 64"),
    # more sweeps than a recording holds: drive wrote a sweeps.npz replay refused
    (["drive", "--port", "x", "--poses", "10001"], 2, "--poses: must be 1 … 10000, got 10001"),
    (["drive", "--port", "x", "--pose", "nan,nan"], 2, "--pose: 'nan,nan': expected"),
    (["emulate", "--baud", "-100"], 2, "--baud: must be ≥ 0"),
    (["calibrate", "--port", "loop://", "--baud", "0"], 2, "--baud: must be ≥ 1, got 0"),
    (["calibrate", "--sensor", "-1"], 2, "--sensor: must be ≥ 0, got -1"),
    (["emulate", "--tcp", "127.0.0.1:99999"], 2, "PORT 0 … 65535"),
    # said 'corrupt_rate must be 0 … 1, got nan' (no option named); an empty --link was
    # the current folder ('--link : . exists and is not a symlink')
    (["emulate", "--corrupt-rate", "nan"], 2,
     "argument --corrupt-rate: must be a number ≥ 0 and ≤ 1, got 'nan'"),
    (["emulate", "--bitflip-rate", "-0.001"], 2,
     "argument --bitflip-rate: must be a number ≥ 0 and ≤ 1, got '-0.001'"),
    (["emulate", "--drop-rate", "1.5"], 2,
     "argument --drop-rate: must be a number ≥ 0 and ≤ 1, got '1.5'"),
    (["emulate", "--link", ""], 2, "argument --link: an empty path; name the link to make "
                                   "(default ring.pty)"),
    # counts that grew memory without bound: 10^12 ran out of it (exit 5, wrong advice)
    (["bench", "effects", "--samples", "65"], 2, "--samples: must be in 1 … 64, got 65"),
    (["bench", "dynamics", "--sweeps", "10001"], 2, "--sweeps: must be in 1 … 10000, got 10001"),
    (["bench", "study", "--seeds", "100001"], 2, "--seeds: must be in 1 … 100000, got 100001"),
    (["bench", "study", "--memory-seeds", "10**12"], 2, "--memory-seeds: must be an integer in 1"),
    (["compare", "--bearings", "3601"], 2, "--bearings: must be in 8 … 3600, got 3601"),
    (["compare", "--seeds", "1000000000000"], 2, "--seeds: must be in 1 … 100000"),
    (["bench", "accuracy", "--seeds", "100001"], 2, "--seeds: must be in 1 … 100000"),
    (["bench", "rooms", "--seeds", "100001"], 2, "--seeds: must be in 1 … 100000"),
    # `--out "$DIR"` with DIR unset wrote into the current folder (run, replay, view,
    # compare) or the default (calibrate, study) without a word
    (["run", "t_room", "--out", ""], 2, "argument --out: an empty path; name a folder or file"),
    (["replay", "x.npz", "--out", " "], 2, "argument --out: an empty path"),
    (["calibrate", "--out", ""], 2, "argument --out: an empty path"),
    (["study", "s.yaml", "--out", ""], 2, "argument --out: an empty path"),
])
def test_bad_options_are_usage_errors(capsys, argv, status, message):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == status
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    (["compare", "--scenario", "t_room_cylinder", "--scenario", "{cyl}", "--design", "rotating12"],
     "--scenario {cyl}: given twice (as t_room_cylinder and {cyl}); it would be run and counted "
     "in the means twice, so name each once"),
    (["compare", "--scenario", "t_room_cylinder", "--design", "radial12", "--design", "radial12"],
     "--design radial12: given twice; it would be run and counted in the means twice"),
    (["bench", "accuracy", "--scenario", "t_room", "--scenario", "t_room"],
     "--scenario t_room: given twice; it would be run and counted in the means twice"),
    (["bench", "accuracy", "--knob", "samples", "--knob", "samples"], "--knob samples: given twice"),
])
def test_a_scenario_or_design_given_twice_is_refused_not_counted_twice(tmp_path, capsys, argv,
                                                                        message):
    """compare ran a room or design given twice twice: 'runs 2' for one run, and the repeated
    room weighed double in a design's mean over rooms (bench rooms already refused it)."""
    cyl = str(resolve("t_room_cylinder"))
    argv = [a.format(cyl=cyl) for a in argv] + ["--seeds", "1", "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    assert f"error: {message.format(cyl=cyl)}" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv, message", [
    (["--stall-seconds", "5"], "--stall-seconds 5 recovers from a stall, so it needs "
                               "--stall-after N"),
    (["--tcp", "0", "--link", "x.pty"], "--link and --tcp: the device is on a pty"),
])
def test_emulate_refuses_an_option_it_would_ignore(tmp_path, monkeypatch, capsys, argv, message):
    """Both ran an emulator that silently ignored the option (no stall; no link)."""
    monkeypatch.chdir(tmp_path)
    assert main(["emulate", "t_room", "--quiet", *argv]) == 2
    assert message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_emulate_link_never_replaces_a_regular_file(tmp_path, capsys):
    target = tmp_path / "precious.txt"
    target.write_text("keep me")
    assert main(["emulate", "t_room", "--link", str(target), "--quiet"]) == 2
    assert target.read_text() == "keep me"
    assert "is not a symlink; not replacing it" in capsys.readouterr().err


def test_out_naming_a_file_is_refused_before_the_work(tmp_path, capsys):
    target = tmp_path / "file"
    target.write_text("x")
    t0 = time.monotonic()
    assert main(["run", "t_room", "--out", str(target), "--no-animation"]) == 4
    assert time.monotonic() - t0 < 2.0       # before simulating
    assert "is a file; expected a folder" in capsys.readouterr().err
    assert target.read_text() == "x"


def test_a_scenario_name_never_leaves_the_out_parent(tmp_path, monkeypatch, capsys):
    raw = copy.deepcopy(T_ROOM)
    raw["name"] = "../../escape/../x y"
    (tmp_path / "evil.yaml").write_text(yaml.safe_dump(raw))
    monkeypatch.chdir(tmp_path)
    assert main(["run", "evil.yaml", "--no-animation"]) == 0
    made = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert made == ["escape_x_y~c48a397d"]   # its own folder: tests/test_folder_names.py
    assert sorted(os.listdir(tmp_path)) == ["evil.yaml", "out"]


def test_an_interrupted_run_leaves_the_previous_outputs_whole(tmp_path, monkeypatch):
    from irring.maps import render

    out = tmp_path / "run"
    assert main(["run", "t_room_cylinder", "--out", str(out), "--no-animation"]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(render, "save_map_png", interrupted)
    assert main(["run", "t_room_cylinder", "--out", str(out), "--no-animation",
                 "--seed", "9"]) == 130
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]   # no temporaries left


def test_a_room_too_big_for_memory_is_refused_up_front(tmp_path, capsys):
    raw = copy.deepcopy(T_ROOM)
    raw["room"]["outline_mm"] = [[0, 0], [100_000, 0], [100_000, 100_000], [0, 100_000]]
    (tmp_path / "big.yaml").write_text(yaml.safe_dump(raw))
    assert main(["run", str(tmp_path / "big.yaml"), "--out", str(tmp_path / "o")]) == 5
    err = capsys.readouterr().err
    assert "would need about 6.0 GB" in err and "map.resolution_mm ≥ 21" in err
    assert not (tmp_path / "o").exists()


def test_a_room_written_in_mm_under_outline_m_is_shown_in_metres(tmp_path, capsys):
    # the message advised coarser cells only; the room's span shows the unit slip
    raw = copy.deepcopy(T_ROOM)
    raw["room"] = {"outline_m": [[0, 0], [2600, 0], [2600, 1100], [0, 1100]]}
    (tmp_path / "lab.yaml").write_text(yaml.safe_dump(raw))
    assert main(["run", str(tmp_path / "lab.yaml"), "--out", str(tmp_path / "o")]) == 5
    err = capsys.readouterr().err
    assert err.rstrip().endswith(
        "or a smaller room (its outline spans 2,600 × 1,100 m; room.outline_m is read in "
        "metres, outline_mm in millimetres)")


def test_an_unexpected_exception_is_one_line_unless_debug(monkeypatch, capsys):
    from irring.cli import scenarios

    def boom(args):
        raise ZeroDivisionError("\x1b[2J" + "x" * 10_000)

    monkeypatch.setattr(scenarios, "run", boom)
    monkeypatch.delenv("IRRING_DEBUG", raising=False)
    assert main(["scenarios"]) == 70
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and len(err) < 500 and "\x1b" not in err
    assert err.startswith("irring scenarios: error: internal error (ZeroDivisionError: \\x1b[2J")
    assert main(["scenarios", "--debug"]) == 70
    assert "Traceback" in capsys.readouterr().err


def test_dataclass_fields_of_sweep_are_all_checked():
    """A new Sweep field must get a rule in the recording schema (not pass unchecked)."""
    from irring import recording

    checked = set(recording._SWEEP_ARRAYS) | {"ring", "truth", "sensor_model", "adc_bits",
                                              "vref_v", "max_range_m", "samples", "settle_s",
                                              "duration_s", "source", "missing_steps"}
    assert {f.name for f in dataclasses.fields(Sweep)} <= checked


# --------------------------------------------------------------------------- calibrate --port


def _calibrate(tmp_path, monkeypatch, behaviour, stop_at=None, stop=KeyboardInterrupt, *extra,
               sweeps: str | None = "1"):
    """irring calibrate --port on a hostile device (``--sweeps sweeps``, None: not given), the
    person pressing Enter at every prompt and ``stop`` (an exception to raise, or an answer)
    at placement ``stop_at``'s → (status, link, prompts asked to place the wall, out)."""
    placed = []

    def person(text):
        if "Place a flat, white wall" in text:
            k = int(re.match(r"\[(\d+)/", text).group(1))
            if k == stop_at:
                if isinstance(stop, str):
                    return stop
                raise stop()
            placed.append(k)
        return ""

    monkeypatch.setattr("builtins.input", person)
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path / "spare"))
    (tmp_path / "spare").mkdir(exist_ok=True)
    dev = hd.HostileDevice(behaviour)
    out = tmp_path / "ring.yaml"
    try:
        return (main(["calibrate", "--port", dev.link, *["--sweeps", sweeps] * bool(sweeps),
                      "--out", str(out), *extra]), dev.link, placed, out)
    finally:
        dev.close()


def _kept(tmp_path):
    (saved,) = (tmp_path / "spare").iterdir()
    assert saved.name.startswith("irring-calibrate-") and saved.suffix == ".yaml"
    return saved


@pytest.mark.parametrize("behaviour, stop, status, said", [
    (hd.good, KeyboardInterrupt, 130, "interrupted at placement 4 of 28"),
    (hd.good, EOFError, 1, "input ended at placement 4 of 28"),
    (hd.good, "q", 1, "calibration stopped by the user at placement 4"),
    (hd.good_then(hd.disconnect_on_sweep, sweeps=3), None, 3, "error: ring on"),
])
def test_calibrate_keeps_the_placements_read_when_it_stops_early(
        tmp_path, capsys, monkeypatch, behaviour, stop, status, said):
    """Ctrl-C, Ctrl-D, q or a device failing at placement 4 lost the three placements the
    person had already set the wall up for ('nothing written')."""
    code, link, placed, out = _calibrate(tmp_path, monkeypatch, behaviour,
                                         None if stop is None else 4, stop)
    err = capsys.readouterr().err
    assert code == status, err
    assert placed == [1, 2, 3] + ([4] if stop is None else [])
    saved = _kept(tmp_path)
    assert f"irring calibrate: {said}" in err
    assert (f"the 3 placements read (of 28) are kept in {saved}; resume with: irring calibrate "
            f"--port {link} --resume {saved} --out {out} --sweeps 1\n") in err  # no --baud None
    progress = load_progress(saved)
    assert sorted(progress.done) == [0, 1, 2] and progress.sensor == 0
    for place, readings in progress.done.values():   # what the device sent, sensor 0's
        assert list(readings.counts) == [hd.counts_for(s)[0] for s in range(-2, 3)]
        assert place.purpose == "offset" and list(readings.repeats) == [1] * 5
    assert not out.exists()


def test_calibrate_says_when_the_ring_was_not_turned_back_to_step_0(tmp_path, capsys,
                                                                  monkeypatch):
    """A calibration ends with the ring where its last sweep left it (step 2 here); an
    Arduino reset by the next session's open takes that for step 0. close() turns it back;
    a ring that does not answer IRGTO,0 is named, with what to do."""
    def never_turns_back(dev, cmd):
        if not isinstance(cmd, hd.p.GoTo):
            hd.good(dev, cmd)

    code, link, _, _ = _calibrate(tmp_path, monkeypatch, never_turns_back, 2, "q")
    err = capsys.readouterr().err
    assert code == 1, err
    assert (f"irring calibrate: warning: the ring on {link} was not turned back to step 0 at "
            "the end of the session (no IRPOS answered IRGTO,0 within 1.02 s: it stands between "
            "step 2 and step 0). Its firmware takes the step it stands at when it starts for "
            "step 0, and an Arduino restarts each time its port is opened: turn the ring "
            "radial by hand, or send $IRGTO,0*E3DD, before the next session") in err
    (tmp_path / "good").mkdir()
    code, _, _, _ = _calibrate(tmp_path / "good", monkeypatch, hd.good, 2, "q")
    assert code == 1 and "warning" not in capsys.readouterr().err


def test_calibrate_resumes_asking_only_for_the_placements_not_read(tmp_path, capsys,
                                                                   monkeypatch):
    code, link, _, out = _calibrate(tmp_path, monkeypatch, hd.good, 4)
    assert code == 130
    saved = _kept(tmp_path)
    saved = saved.rename(tmp_path / "progress.yaml")
    capsys.readouterr()
    code, _, placed, out = _calibrate(tmp_path, monkeypatch, hd.good, None, None,
                                      "--resume", str(saved))
    captured = capsys.readouterr()
    assert placed == list(range(4, 29))   # placements 1-3 were not measured again
    assert f"resuming from {saved}: 3 of 28 placements read before" in captured.out
    assert "[1/28] read before (resumed)" in captured.out
    # the device's counts are no wall, so no curve fits: all 28 are kept for another try
    assert code == 1, captured.err
    assert "the 28 placements read (of 28) are kept in" in captured.err


@pytest.mark.parametrize("extra, message", [
    (["--sensor", "1"], "sensor 1, a gp2d12 with a 12-bit ADC at 5 V"),
    (["--scenario", "SCENE"], "sensor 0, a gp2y0a21 with a 12-bit ADC at 5 V"),
])
def test_calibrate_refuses_to_resume_another_procedure(tmp_path, capsys, monkeypatch, extra,
                                                       message):
    scene = copy.deepcopy(T_ROOM)
    scene["sensor"]["model"] = "gp2y0a21"
    (tmp_path / "y0a21.yaml").write_text(yaml.safe_dump(scene))
    extra = [str(tmp_path / "y0a21.yaml") if a == "SCENE" else a for a in extra]
    code, _, _, _ = _calibrate(tmp_path, monkeypatch, hd.good, 2)
    saved = _kept(tmp_path).rename(tmp_path / "progress.yaml")
    capsys.readouterr()
    code, _, placed, _ = _calibrate(tmp_path, monkeypatch, hd.good, None, None,
                                    "--resume", str(saved), *extra)
    err = capsys.readouterr().err
    assert code == 1 and placed == []
    assert (f"irring calibrate: error: {saved}: cannot resume: it was read from sensor 0, a "
            f"gp2d12 with a 12-bit ADC at 5 V; this run calibrates {message}") in err


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["read"][0]["counts"].__setitem__(0, 1e9),
     "read[0].counts: 1000000000.0 is not allowed; expected numbers 0 … 4095 or null"),
    (lambda d: d["read"][0]["repeats"].pop(), "read[0]: its lists differ in length"),
    (lambda d: d["read"][0].update(placement=99), "read[0].placement: expected a whole number "
                                                  "1 … 28, got 99"),
    (lambda d: d["read"].append(copy.deepcopy(d["read"][0])),
     "read[1].placement: placement 1 is read twice"),
    (lambda d: d.update(irring_calibration_progress=2), "irring_calibration_progress: "
                                                        "expected format 1"),
    (lambda d: d.update(irring_calibration_progress=True), "irring_calibration_progress: "
                                                           "expected format 1"),
    (lambda d: d["read"][0].update(wall_distance_mm=float("nan")),
     "read[0].wall_distance_mm: expected a number"),
    (lambda d: d["read"][0].update(wall_distance_mm=400.0), "cannot resume: its placement 1 "
                                                           "(a flat, white wall 400 mm"),
    # sweeps and the repeats they give share one bound (sweeps 10^6 passed, repeats > 10^4 not)
    (lambda d: d.update(sweeps=10_001), "sweeps: expected a whole number 1 … 10000, got 10001"),
    # a placement's repeats are at most the file's sweeps, and its keys those written
    (lambda d: (d.update(sweeps=2), d["read"][0]["repeats"].__setitem__(0, 3)),
     "read[0].repeats: 3 is not allowed; expected whole numbers 0 … 2"),
    (lambda d: d["read"][0].update(colour="red"),
     "read[0].colour: unknown key; allowed: placement, wall_distance_mm, yaw_deg, purpose"),
    # a list where a name belongs ended in exit 70 (TypeError: unhashable type)
    (lambda d: d.update(sensor_model=["gp2d12"]), "sensor_model: ['gp2d12'] is not a sensor "
                                                  "model; choose one of: gp2d12"),
])
def test_a_damaged_progress_file_is_refused_naming_the_key(tmp_path, capsys, monkeypatch,
                                                           edit, message):
    _calibrate(tmp_path, monkeypatch, hd.good, 2)
    saved = _kept(tmp_path).rename(tmp_path / "progress.yaml")
    doc = yaml.safe_load(saved.read_text())
    edit(doc)
    saved.write_text(yaml.safe_dump(doc))
    capsys.readouterr()
    code, _, placed, _ = _calibrate(tmp_path, monkeypatch, hd.good, None, None,
                                    "--resume", str(saved))
    err = capsys.readouterr().err
    assert code == 1 and placed == [] and "internal error" not in err
    assert f"{saved}: {message}" in err


def test_calibrate_sweeps_are_bounded_by_what_a_progress_file_holds(tmp_path, capsys):
    # --sweeps 20000 read placements whose repeats (up to 20000 a step) no --resume could load
    with pytest.raises(SystemExit) as stop:
        main(["calibrate", "--sweeps", "10001", "--out", str(tmp_path / "c.yaml")])
    assert stop.value.code == 2
    assert "--sweeps: must be in 1 … 10000, got 10001" in capsys.readouterr().err
    assert not (tmp_path / "c.yaml").exists()


def test_calibrate_refuses_a_ring_whose_readings_a_progress_file_cannot_keep(tmp_path, capsys,
                                                                            monkeypatch):
    """A ring of 9,000 steps a sweep (IRINF allows 100,000) read 28 placements whose progress
    file (10 MB) --resume refused as too big: such a ring is refused before the first wall."""
    code, _, placed, out = _calibrate(tmp_path, monkeypatch,
                                      hd.announces(lo=-893, hi=893, step_mdeg=10))
    err = capsys.readouterr().err
    assert code == 5 and placed == [] and not out.exists()
    assert ("irring calibrate: error: a sweep of 1,787 steps × 28 placements is 50,036 "
            "readings; a calibration keeps at most 50,000 (sweeps of at most 1,785 steps)") in err


def test_the_largest_progress_a_calibration_keeps_is_resumed(tmp_path):
    """save_progress of PROGRESS_MAX_READINGS step readings, each in the longest form it
    writes, is read back by load_progress whole."""
    guided = GuidedCalibration(read_sweep=None, adc_bits=24, sweeps=10_000)
    n = len(guided.placements)
    steps = PROGRESS_MAX_READINGS // n
    guided.check_steps(steps)
    with pytest.raises(TooBig):
        guided.check_steps(steps + 1)
    top = 2.0 ** 24 - 1
    for i, place in enumerate(guided.placements):
        k = np.arange(steps)
        guided.done[i] = RigReadings(
            counts=top - 1 - (k + i) * 1.23456789e-3, beam_angle_rad=np.radians(
                -359.987654321 + k * 1e-7 * math.pi), wall_distance_m=np.full(steps,
                place.wall_distance_m), spread_counts=top / 3 + k * math.pi * 1e-6,
            repeats=np.full(steps, 10_000), offset=np.full(steps, place.purpose == "offset"))
    progress = load_progress(save_progress(tmp_path / "p.yaml", guided))
    assert sorted(progress.done) == list(range(n))
    np.testing.assert_allclose(progress.done[n - 1][1].counts, guided.done[n - 1].counts,
                               rtol=0, atol=1e-6)


def test_calibrate_resume_needs_a_port(tmp_path, capsys):
    assert main(["calibrate", "--resume", str(tmp_path / "p.yaml")]) == 2
    assert "--resume continues a guided calibration of the real ring" in capsys.readouterr().err


# --------------------------------------------------------------------------- files and environment


@pytest.mark.parametrize("argv, limit", [
    (["run", "/dev/zero"], "8 MB; too big for a scenario file"),
    (["run", "t_room", "--calibration", "/dev/zero"], "1 MB; too big for a calibration file"),
])
def test_a_device_named_as_an_input_file_is_read_only_up_to_the_limit(tmp_path, capsys, argv,
                                                                      limit):
    """/dev/zero (size 0 to stat) was read until memory ran out: the process was killed by
    the kernel (exit 137), or under a memory limit exit 5 'ran out of memory'."""
    assert main([*argv, "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert f"/dev/zero: more than {limit}" in err
    assert not (tmp_path / "o").exists()


def test_a_scenario_read_from_a_pipe_is_recorded_with_its_sweeps(tmp_path, capsys):
    """`irring run <(cat room.yaml)`: the scenario was read again from the spent pipe when
    the recording was written, so sweeps.npz held an empty scenario_yaml and replay could
    neither score nor name the room."""
    text = resolve("t_room_cylinder").read_text()
    r, w = os.pipe()
    os.write(w, text.encode())
    os.close(w)
    try:
        out = tmp_path / "o"
        assert main(["run", f"/dev/fd/{r}", "--out", str(out), "--no-animation", "--json"]) == 0
    finally:
        os.close(r)
    ran = json.loads(capsys.readouterr().out)
    _, meta = load_recording(out / "sweeps.npz")
    assert meta["scenario_yaml"] == text
    assert main(["replay", str(out / "sweeps.npz"), "--out", str(tmp_path / "re"),
                 "--no-animation", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["scores"] == ran["scores"]


def _irring(tmp_path, *argv, **env):
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "irring", *argv], cwd=tmp_path, text=True,
                          capture_output=True, timeout=120, stdin=subprocess.DEVNULL,
                          env={**os.environ, "CI": "true", **env})


def test_a_mujoco_gl_value_mujoco_does_not_take_is_a_usage_error_of_view_alone(tmp_path):
    """MUJOCO_GL=nonsense made every command that simulates exit 70 'internal error
    (RuntimeError: invalid value for environment variable MUJOCO_GL: nonsense)'. Only
    `irring view` draws with OpenGL: the others import MuJoCo with none and run (an
    MUJOCO_GL=egl exported on a machine without EGL failed every `irring run`)."""
    done = _irring(tmp_path, "run", "t_room_cylinder", "--out", "o", MUJOCO_GL="nonsense")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "o" / "map.png").stat().st_size > 1000
    done = _irring(tmp_path, "view", "t_room_cylinder", "--out", "v.png", MUJOCO_GL="nonsense")
    assert done.returncode == 2, done.stderr
    assert done.stderr == ("irring view: error: MUJOCO_GL='nonsense' is not a value MuJoCo "
                           "takes; set MUJOCO_GL=egl or osmesa (pictures without a display), "
                           "glfw (with a display), or unset it\n")


def test_view_with_a_display_that_cannot_be_opened_writes_the_picture(tmp_path):
    """DISPLAY naming no X server (a forwarded display gone): `irring view` ended with
    MuJoCo's 'ERROR: could not initialize GLFW' and exit 1, nothing written."""
    done = _irring(tmp_path, "view", "t_room_cylinder", DISPLAY=":97", WAYLAND_DISPLAY="")
    assert done.returncode == 0, done.stderr
    assert ("irring view: the display ':97' cannot be opened (GLFW could not connect to it); "
            "writing the picture instead") in done.stderr
    assert (tmp_path / "out" / "t_room_cylinder" / "view.png").stat().st_size > 1000


def test_drive_refuses_a_ring_too_big_to_map_before_any_sweep(tmp_path, capsys):
    """A device announcing 72 sensors × 40 001 steps (allowed by the handshake): one sweep
    is 2.9 M readings, about 9.5 GB to estimate; drive would sweep it for 25 min, then run
    out of memory and lose it. Here 18 sensors × 8 poses, the same readings: 72 sensors of a
    12-bit ADC no longer pass the handshake (their IRSCN do not fit a sentence)."""
    asked = []

    def big_ring(dev, cmd):
        if isinstance(cmd, p_.Hello):
            dev.send(hd.info(sensors=18, lo=-20000, hi=20000, step_mdeg=10, num=1, den=100))
        elif isinstance(cmd, p_.SweepCommand):
            asked.append(cmd)

    dev = hd.HostileDevice(big_ring)
    out = tmp_path / "out"
    try:
        code = main(["drive", "--port", dev.link, "--timeout", str(TIMEOUT_S), "--no-wait",
                     "--no-animation", "--out", str(out), "--poses", "8"])
    finally:
        dev.close()
    err = capsys.readouterr().err
    assert code == errors.TOO_BIG, err
    assert ("8 sweeps × 40,001 steps × 18 sensors (the ring's IRINF) = 5,760,144 readings "
            "(about 5.4 GB)") in err
    assert "more than the 2 GB" in err and "--poses" in err
    assert asked == [] and not out.exists()


def test_a_device_that_reboots_mid_sweep_keeps_only_the_steps_read_before_it():
    """After a reboot the device numbers IRSCN from 0 and answers IRSTP with IRDON -1. The
    driver once dropped the re-sweep as stale; then it kept it, but a board takes the step it
    wakes at as step 0 (firmware/README.md), so each step read since is off by where the ring
    stood (a drive of t_room whose board reset at step 9 of pose 2: F1 0.997 -> 0.519, exit
    0). The steps read before the reboot are kept, none after. Reset as it
    turned on from step -1, the ring stood at -1 or 0: no IRGTO can say which."""
    dev = hd.HostileDevice(hd.reboots_in_sweep(21))   # seq ~100 ahead of the new numbering
    try:
        with SerialRing(dev.link, timeout_s=TIMEOUT_S) as ring:
            for _ in range(20):
                ring.sweep()
            with pytest.raises(DeviceRebooted) as err:
                ring.sweep(resweep=1)
    finally:
        dev.close()
    sweep = err.value.partial
    assert list(sweep.steps) == [hd.MIN_STEP, hd.MIN_STEP + 1]
    for step, row in zip(sweep.steps, sweep.counts):
        assert list(row) == hd.counts_for(int(step))
    assert str(err.value).startswith(
        f"the ring on {dev.link} rebooted while it turned from step -1 to step 0: IRDON -1 (no "
        "IRSCN sent since power-up) ended a sweep after IRSCN had come, and its clock started "
        "anew (1000 ms after 1101 ms). Its firmware takes the step it wakes at as step 0, so "
        "every step it names since is off by the step it stood at, from step -1 to step 0, and "
        "its readings would land beside their walls; none read since is taken. Then turn the "
        "ring back to radial by hand (where it stood is not known, so no IRGTO can), reset the "
        "board, and drive the poses not swept again. device rebooted: 2 of 5 steps received")


@pytest.mark.parametrize("lose_first", [False, True])
def test_a_device_that_reboots_between_sweeps_away_from_step_0_is_refused(lose_first):
    """After a reboot between sweeps the device numbers IRSCN (and IRDON) from 0. The driver
    once dropped the whole next sweep as stale, then kept it; but the ring stood at the last
    sweep's end (step 2), where the board woke and took step 0, so the sweep read 2 steps off
    (a drive of t_room whose board reset between poses 1 and 2, at step 35: F1 0.997 ->
    0.389, 'all 71 steps received', exit 0). Nothing of it is taken."""
    dev = hd.HostileDevice(hd.reboots_between_sweeps(lose_first))
    try:
        with SerialRing(dev.link, timeout_s=TIMEOUT_S) as ring:
            ring.sweep(resweep=0)
            with pytest.raises(DeviceRebooted) as err:
                ring.sweep(resweep=0)
    finally:
        dev.close()
    assert len(err.value.partial.steps) == 0
    assert str(err.value).startswith(
        f"the ring on {dev.link} rebooted at step 2: its IRSCN are numbered from 0 again, and "
        f"its clock started anew ({40 + lose_first} ms after 1004 ms). Its firmware takes the "
        "step it wakes at as step 0, so every step it names since is off by 2 steps (2.2°)")


@pytest.mark.parametrize("lose_first", [False, True])
def test_a_device_that_reboots_between_sweeps_at_step_0_keeps_the_next_sweep(lose_first):
    """Woken where the ring was turned back to (IRGTO,0), the board's step 0 is the ring's:
    the renumbered sweep is its readings (the driver once dropped it as stale: --resweep 0,
    NoReadings; else a timeout and a full re-sweep). Their numbering and the IRDON that ends
    it confirm them."""
    dev = hd.HostileDevice(hd.reboots_between_sweeps(lose_first))
    try:
        with SerialRing(dev.link, timeout_s=TIMEOUT_S) as ring:
            ring.sweep(resweep=0)
            assert ring.goto(0) == 0
            t0 = time.monotonic()
            sweep = ring.sweep(resweep=0)
            took = time.monotonic() - t0
            link = ring.last_report.link
    finally:
        dev.close()
    kept = list(range(hd.MIN_STEP + lose_first, hd.MAX_STEP + 1))
    assert list(sweep.steps) == kept
    assert sweep.missing_steps == ((hd.MIN_STEP,) if lose_first else ())
    for step, row in zip(sweep.steps, sweep.counts):
        assert list(row) == hd.counts_for(int(step))
    assert (link["stale"], link["lost_scans"], link["timeouts"]) == (0, int(lose_first), 0)
    assert took < TIMEOUT_S, took   # no timeout waited for an IRDON already received


def test_stale_scans_the_irdon_does_not_confirm_are_still_dropped():
    """The renumbering is taken only when the IRDON ends the stale-looking IRSCN: ones from
    an earlier exchange, followed by this sweep's own IRDON, stay dropped."""
    def leftovers(dev, cmd):
        if isinstance(cmd, p_.SweepCommand):
            dev.sweeps_seen = getattr(dev, "sweeps_seen", 0) + 1
            if dev.sweeps_seen == 2:   # two old IRSCN, then this sweep's IRDON, nothing sent
                dev.send(hd.scan(dev.seq - 5, cmd.from_step)
                         + hd.scan(dev.seq - 4, cmd.from_step + 1))
                dev.seq += 5
                dev.send(hd.line(f"IRDON,{dev.seq - 1}"))
                return
        hd.good(dev, cmd)
    dev = hd.HostileDevice(leftovers)
    try:
        with SerialRing(dev.link, timeout_s=TIMEOUT_S) as ring:
            ring.sweep(resweep=0)
            with pytest.raises(NoReadings):
                ring.sweep(resweep=0)
            assert ring.last_report.link["stale"] == 2
    finally:
        dev.close()


@pytest.mark.parametrize("calibration", [False, True])
def test_replay_into_the_recordings_own_folder_is_refused(tmp_path, capsys, monkeypatch,
                                                         good_recording, calibration):
    """irring replay out/drive/sweeps.npz --out out/drive removed the drive's link.json (the
    only record of its link) and, with --calibration, replaced the recorded calibration."""
    folder = tmp_path / "drive"
    folder.mkdir()
    (folder / "sweeps.npz").write_bytes(good_recording)
    (folder / "link.json").write_text('{"lost_scans": 3, "checksum_failures": 7}\n')
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    monkeypatch.chdir(tmp_path)
    argv = ["replay", "drive/sweeps.npz", "--out", str(folder)]
    if calibration:
        argv += ["--calibration", "other.yaml"]
    assert main(argv) == 2
    assert (f"--out {folder}: holds the recording being replayed (drive/sweeps.npz); its "
            "outputs would replace it") in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


@pytest.mark.parametrize("argv, option, named", [
    (["run", "IN/room.yaml", "--mcap", "IN/room.yaml", "--out", "OUT"], "--mcap", "SCENARIO"),
    (["run", "t_room", "--calibration", "IN/cal.yaml", "--mcap", "IN/cal.yaml", "--out", "OUT"],
     "--mcap", "--calibration"),
    (["replay", "IN/rec.npz", "--mcap", "IN/rec.npz", "--out", "OUT"], "--mcap", "RECORDING"),
    (["calibrate", "--scenario", "IN/room.yaml", "--out", "IN/room.yaml"], "--out",
     "--scenario"),
])
def test_an_output_naming_an_input_of_the_same_command_is_refused(tmp_path, capsys,
                                                                   good_recording, argv,
                                                                   option, named):
    """irring run my.yaml --mcap my.yaml: exit 0, and my.yaml held MCAP bytes afterwards; the
    same for a replayed recording, a calibration, calibrate's scenario."""
    d = tmp_path / "in"
    d.mkdir()
    (d / "room.yaml").write_text(resolve("t_room_cylinder").read_text())
    (d / "cal.yaml").write_text("not read: refused before\n")
    (d / "rec.npz").write_bytes(good_recording)
    before = {p.name: p.read_bytes() for p in d.iterdir()}
    argv = [a.replace("IN", str(d)).replace("OUT", str(tmp_path / "o")) for a in argv]
    assert main(argv) == 2
    target = argv[argv.index(option) + 1]
    assert (f"{option} {target}: is the file {named} {target}, which this command reads; "
            "writing there would replace it") in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in d.iterdir()} == before
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv", [
    ["run", "t_room_cylinder", "--no-animation"],
    ["replay", "IN/rec.npz", "--no-animation"],
])
@pytest.mark.parametrize("name", ["sweeps.npz", "map.png", "map.yaml"])
def test_an_mcap_naming_a_file_of_the_output_set_is_refused(tmp_path, capsys, good_recording,
                                                            argv, name, monkeypatch):
    """irring run t_room --out o --mcap o/sweeps.npz: exit 0, and o/sweeps.npz held the
    MCAP, the recording gone (written after the set, the MCAP replaced it)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "rec.npz").write_bytes(good_recording)
    (tmp_path / "o").mkdir()
    (tmp_path / "o" / name).write_bytes(b"an earlier run's")
    argv = [a.replace("IN", "in") for a in argv]
    assert main(argv + ["--out", "o", "--mcap", f"o/../o/{name}"]) == 2
    assert (f"--mcap o/../o/{name}: is the {name} this command writes into --out o; the MCAP "
            "would replace it, so name another file (such as o/map.mcap)"
            in capsys.readouterr().err)
    assert [(p.name, p.read_bytes()) for p in (tmp_path / "o").iterdir()] == [
        (name, b"an earlier run's")]
    assert main(argv + ["--out", "o", "--mcap", "o/map.mcap"]) == 0
    assert sorted(p.name for p in (tmp_path / "o").iterdir())[:2] == ["map.mcap", "map.pgm"]
    assert (tmp_path / "o" / "map.mcap").read_bytes().startswith(b"\x89MCAP")


@pytest.mark.parametrize("out, mcap", [("o", "o"), ("o/sub", "o"), ("o/sub", "o/sub/..")])
def test_an_mcap_naming_the_out_folder_is_refused_before_the_run(tmp_path, capsys,
                                                                  monkeypatch, out, mcap):
    """irring run --out o --mcap o: the whole run, the set written into o, then exit 4 with
    'o: is a folder; expected a file' (not naming --mcap)."""
    monkeypatch.chdir(tmp_path)
    assert main(["run", "t_room", "--no-animation", "--out", out, "--mcap", mcap]) == 2
    assert capsys.readouterr().err == (
        f"irring run: error: --mcap {mcap}: is the folder --out {out} or holds it, and this "
        f"command writes its outputs there; name a file (such as {out}/map.mcap)\n")
    assert list(tmp_path.iterdir()) == []


def test_a_calibration_value_out_of_range_names_its_file_once(tmp_path, capsys):
    """'cal.yaml: cal.yaml: noise_counts: inf is out of range': the key's own error, already
    naming the file, was wrapped again with it."""
    from irring.estimation.calibration import scene_calibration
    from irring.scenario import load_scenario
    _, text = scene_calibration(load_scenario("t_room"))
    cal = tmp_path / "cal.yaml"
    cal.write_text(re.sub(r"(?m)^noise_counts: .*$", "noise_counts: 1e400", text))
    assert main(["run", "t_room", "--calibration", str(cal), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert f"error: {cal}: noise_counts: inf is out of range; allowed 0 … 1e+07" in err
    assert err.count(str(cal)) == 1


def test_a_full_standard_output_is_named(tmp_path, capsys, monkeypatch):
    """irring run --json > /dev/full: exit 4 'No space left on device' — though the outputs
    in --out were written whole, the message named no file. Now it names standard output;
    a broken pipe is still told apart (BrokenPipeError)."""
    class Full(io.StringIO):
        def write(self, text):
            raise OSError(errno.ENOSPC, "No space left on device")

    class Closed(io.StringIO):
        def write(self, text):
            raise OSError(errno.EPIPE, "Broken pipe")

    monkeypatch.setattr(sys, "stdout", Full())
    assert main(["run", "t_room_cylinder", "--out", str(tmp_path / "o"), "--no-animation",
                 "--json"]) == errors.OUTPUT
    assert capsys.readouterr().err == ("irring run: error: standard output: No space left on "
                                       "device\n")
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == [
        "map.pgm", "map.png", "map.yaml", "sweeps.npz"]
    assert isinstance(sys.stdout, Full)   # given back as it was
    seen = []
    monkeypatch.setattr(errors, "describe", lambda exc: (seen.append(exc), (4, "x"))[1])
    monkeypatch.setattr(sys, "stdout", Closed())
    assert main(["scenarios"]) == errors.OUTPUT
    assert isinstance(seen[0], BrokenPipeError) and seen[0].filename == "standard output"


def test_a_name_too_long_for_the_file_system_is_named_with_its_option(tmp_path, capsys,
                                                                      monkeypatch):
    """A 300-character --out or --mcap (most file systems take 255 bytes a name): exit 1,
    'bad input file', as 'irring run: error: xxx…: File name too long'; --mcap's check ran
    inside argparse and said 'irring: error:' (no command, no option)."""
    monkeypatch.chdir(tmp_path)
    long = "x" * 300
    assert main(["run", "t_room_cylinder", "--out", long, "--no-animation"]) == 4
    assert capsys.readouterr().err == (f"irring run: error: --out {long}: cannot be a folder: "
                                       "File name too long\n")
    assert main(["view", "t_room", "--out", long + ".png"]) == 4
    assert (f"irring view: error: --out {long}.png: cannot be written: File name too long"
            in capsys.readouterr().err)
    with pytest.raises(SystemExit) as stop:
        main(["run", "t_room_cylinder", "--mcap", long + ".mcap"])
    assert stop.value.code == 2
    assert (f"irring run: error: argument --mcap: {long}.mcap: File name too long"
            in capsys.readouterr().err)
    from irring.outputs import atomic_file
    with pytest.raises(OutputError, match=re.escape(
            f"--out {long}.yaml: cannot be written: File name too long")):
        with atomic_file(long + ".yaml", "--out"):
            pass
    assert os.listdir(tmp_path) == []


def test_a_recording_that_is_a_pipe_is_refused_not_waited_for(tmp_path, good_recording):
    """irring replay FIFO waited for a writer for good; `cat rec.npz | irring replay
    /dev/stdin` said the recording was 'not an irring recording (.npz), or a damaged one:
    File is not a zip file' (a zip is read by seeking). Run in a subprocess with a limit."""
    fifo = tmp_path / "rec.npz"
    os.mkfifo(fifo)
    done = subprocess.run([sys.executable, "-m", "irring", "replay", str(fifo), "--out",
                           str(tmp_path / "o")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1, done.stderr
    assert (f"irring replay: error: {fifo}: is not a regular file (a pipe or a device); a "
            "recording is read from a saved .npz file" in done.stderr)
    piped = subprocess.run([sys.executable, "-m", "irring", "replay", "/dev/stdin", "--out",
                            str(tmp_path / "o")], input=good_recording, capture_output=True,
                           timeout=120)
    assert piped.returncode == 1 and b"is not a regular file" in piped.stderr, piped.stderr
    assert sorted(os.listdir(tmp_path)) == ["rec.npz"]


def test_an_mcap_folder_that_cannot_be_written_is_refused_before_the_run(tmp_path, capsys,
                                                                         monkeypatch):
    """irring run --out o --mcap ro/x.mcap on a read-only ro/: the whole run was computed and
    o/ written before 'ro/x.mcap: cannot write there: Read-only file system' (exit 4, the
    option unnamed). Now refused first, as an unwritable --out is (os.access, as
    check_out asks it, says no for ro/: the tests run as root)."""
    from irring import outputs

    monkeypatch.chdir(tmp_path)
    (tmp_path / "ro").mkdir()
    real = os.access
    monkeypatch.setattr(outputs.os, "access",
                        lambda p, mode: real(p, mode) and os.path.basename(p) != "ro")
    assert main(["run", "t_room_cylinder", "--out", "o", "--mcap", "ro/x.mcap"]) == 4
    assert capsys.readouterr().err == "irring run: error: --mcap ro: ro is not writable\n"
    assert sorted(os.listdir(tmp_path)) == ["ro"] and not any((tmp_path / "ro").iterdir())


@pytest.mark.parametrize("argv, status", [(["--help"], 0), (["--kind", "serial"], 2),
                                          (["--lsit"], 2)])
def test_the_corpus_script_answers_help_and_typos_before_its_census(argv, status, capsys,
                                                                    monkeypatch):
    """`python tests/hostile_corpus.py --help` (or a mistyped option) started the ~2 min
    census of 105 fresh processes; now it prints the usage or names the argument."""
    import hostile_corpus

    monkeypatch.setattr(hostile_corpus, "cases", lambda top: pytest.fail("census started"))
    assert hostile_corpus.main(argv) == status
    out, err = capsys.readouterr()
    if status == 0:
        assert "python tests/hostile_corpus.py --list" in out and err == ""
    else:
        assert err == (f"hostile_corpus.py: unknown argument {argv[0]!r}; allowed: --list, "
                       "--kind=NAME, --help\n")


# --------------------------------------------------------------------------- designs in rooms

NARROW_ROOM = """name: narrow
room:
  outline_mm: [[0, 0], [2000, 0], [2000, 200], [0, 200]]
robot:
  design: custom
  ring: {radius_mm: 40}
  poses: [{x_mm: 1000, y_mm: 100}]
"""
LOW_ROOM = """name: low
room:
  outline_mm: [[0, 0], [1000, 0], [1000, 800], [0, 800]]
  wall_height_mm: 60
robot:
  design: custom
  ring: {sensor_height_mm: 30}
  poses: [{x_mm: 500, y_mm: 400}]
"""
NEAR_PATH = NARROW_ROOM.replace("[2000, 200], [0, 200]", "[2000, 1500], [0, 1500]").replace(
    "y_mm: 100}]", "y_mm: 750}]") + """effects:
  motion:
    path: [{x_mm: 1000, y_mm: 750}, {x_mm: 1000, y_mm: 120}]
"""


def test_compare_refuses_a_design_whose_ring_the_room_cannot_hold(monkeypatch):
    """`irring compare --scenario narrow.yaml --design rotating12` put the paper's 150 mm ring
    at a pose 100 mm from both walls of a 200 mm room (the file's own 40 mm ring fits) and
    measured it: F1 0.869, free accuracy 0.825, from sensors inside the walls. A 60 mm high
    room seen by rotating1 (sensors at 100 mm) scored F1 0.000 over the walls. Both are now
    refused before any run, as the file would be with that ring."""
    from irring.studies import compare

    monkeypatch.setattr(compare, "run_jobs", lambda *a, **k: pytest.fail("a run started"))
    with pytest.raises(ScenarioError) as exc:
        compare.compare([loads(NARROW_ROOM, "narrow.yaml")], ["radial12", "rotating12"])
    assert str(exc.value) == (
        "narrow.yaml: design 'radial12' in place of its ring: robot.poses[0]: the ring "
        "(radius 170 mm with housing) would be inside a wall at (1000, 100) mm; keep the pose "
        "≥ 170 mm from every wall")
    with pytest.raises(ScenarioError) as exc:
        compare.compare([loads(LOW_ROOM, "low.yaml")], ["rotating1"])
    assert str(exc.value) == (
        "low.yaml: design 'rotating1' in place of its ring: robot.ring.sensor_height_mm: "
        "sensors at 100 mm would look over the 60 mm walls (and obstacles, which are as tall); "
        "allowed: below room.wall_height_mm")


def test_a_study_design_the_rooms_cannot_hold_is_refused_at_load(tmp_path):
    """A study's parametric ring of radius 1000 mm ran in t_room's 900 mm corridor (F1 0.624,
    free accuracy 0.541, exit 0): a ring no scenario file could hold there."""
    f = tmp_path / "study.yaml"
    f.write_text("designs:\n  - {sensors: 12, radius_mm: 1000, sweep_half_angle_deg: 30, "
                 "step_deg: 1.08, name: huge}\n  - rotating12\nscenarios: [t_room]\n")
    with pytest.raises(StudyError) as exc:
        load_study(f)
    assert str(exc.value) == (
        f"{f}: designs[0]: {resolve('t_room')}: design 'huge' in place of its ring: "
        "robot.poses[0]: the ring (radius 1020 mm with housing) would be inside a wall at "
        "(1920, 450) mm; keep the pose ≥ 1020 mm from every wall")


def test_bench_accuracy_refuses_a_design_knob_the_room_cannot_hold(tmp_path):
    f = tmp_path / "narrow.yaml"
    f.write_text(NARROW_ROOM)
    with pytest.raises(ScenarioError, match=r"narrow.yaml: design 'radial12' in place of its "
                                            r"ring: robot.poses\[0\]: the ring \(radius 170 mm"):
        jobs_for([str(f)], [Config(), Config("design", "radial12", 1, design="radial12")], 1)
    assert len(jobs_for([str(f)], [Config()], 2)) == 2   # its own ring fits


def test_a_design_whose_ring_the_drive_brings_into_a_wall_says_whose_ring():
    """Run with the paper's ring, a path 120 mm from a wall was refused mid-run as 'the ring
    (radius 170 mm …)' of a file whose ring is 40 mm; now before it, naming the design."""
    from irring.studies.accuracy import design_in

    sc = loads(NEAR_PATH, "path.yaml")
    with pytest.raises(ScenarioError) as exc:
        design_in(sc, "rotating12")
    assert str(exc.value) == (
        "path.yaml: effects.motion.path[0] → [1]: at (1000, 165) mm the ring of design "
        "'rotating12' (radius 170 mm with housing) would hit a wall or obstacle; add a "
        "waypoint that keeps ≥ 170 mm clear")
    assert design_in(sc, "rotating1").ring.radius_m == 0.0   # a ring that fits


@pytest.mark.parametrize("pose, why", [
    ("5000,5000", "pose (5000, 5000) mm is outside the room"),
    ("100,450,30", "the ring (radius 170 mm with housing) would be inside a wall at (100, 450) "
                   "mm; keep the pose ≥ 170 mm from every wall"),
    ("2100,300", "the ring (radius 170 mm with housing) at (2100, 300) mm would overlap "
                 "obstacles[0] (cylinder at (2170, 220) mm); keep the pose ≥ 170 mm from it")])
def test_drive_refuses_a_pose_the_truth_room_cannot_hold_before_the_port(tmp_path, capsys,
                                                                         pose, why):
    """`drive --truth t_room --pose 5000,5000` (outside the room) was swept, mapped and
    scored against t_room (F1 0.000, exit 0), as were poses in its walls (F1 0.015 at the
    corner): scores of a ring the room cannot hold. Now a usage error, before the port."""
    out = tmp_path / "out"
    assert main(["drive", "--port", str(tmp_path / "no-such-port"), "--truth",
                 "t_room_cylinder", "--pose", "1920,450", "--pose", pose, "--no-wait",
                 "--out", str(out)]) == 2
    x, y, *yaw = pose.split(",")
    assert capsys.readouterr().err == (f"irring drive: error: --pose {x},{y},{(yaw or [0])[0]} "
                                       f"with --truth t_room_cylinder: {why}\n")
    assert not out.exists()


MOVING_BOX = """name: moving_box
room:
  outline_mm: [[0, 0], [2000, 0], [2000, 1500], [0, 1500]]
robot:
  poses: [{x_mm: 700, y_mm: 750}]
effects:
  motion:
    speed_mm_s: 100
    path: [{x_mm: 700, y_mm: 750}, {x_mm: 1300, y_mm: 750}]
"""


def test_replay_refuses_a_recorded_scenario_whose_room_does_not_hold_the_sweeps(tmp_path,
                                                                                capsys):
    """A t_room recording whose sweeps stand at (2.2, 1.6) m, inside the recorded grid but
    outside the T (its missing corner), was replayed and scored against t_room (F1 0.018,
    exit 0): a scenario and sweeps that do not belong together, as a grid holding none of
    the poses already was. A moving scene's believed poses may drift past a wall, so there
    only a room holding none of them is refused."""
    assert main(["run", "t_room", "--out", str(tmp_path / "t"), "--no-animation"]) == 0
    data = (tmp_path / "t" / "sweeps.npz").read_bytes()
    moved = tmp_path / "moved.npz"
    moved.write_bytes(_rewrite(data, "sweep001/pose", [2.2, 1.6, 0.0]))
    capsys.readouterr()
    assert main(["replay", str(moved), "--out", str(tmp_path / "r"), "--no-animation"]) == 1
    assert capsys.readouterr().err == (
        f"irring replay: error: {moved}: sweep 2's pose (2.2, 1.6) m lies outside the room of "
        "the recorded scenario 't_room'; the scenario and the sweeps do not belong together\n")
    assert not (tmp_path / "r").exists()

    room = tmp_path / "moving_box.yaml"
    room.write_text(MOVING_BOX)
    assert main(["run", str(room), "--out", str(tmp_path / "m"), "--no-animation"]) == 0
    data = (tmp_path / "m" / "sweeps.npz").read_bytes()
    assert len(load_recording(tmp_path / "m" / "sweeps.npz")[0]) == 2
    drifted = tmp_path / "drifted.npz"
    drifted.write_bytes(_rewrite(data, "sweep001/pose", [2.05, 0.75, 0.0]))
    assert main(["replay", str(drifted), "--out", str(tmp_path / "d"), "--no-animation"]) == 0
    for k in range(2):
        data = _rewrite(data, f"sweep{k:03d}/pose", [2.05, 0.75, 0.0])
    drifted.write_bytes(data)
    capsys.readouterr()
    assert main(["replay", str(drifted), "--out", str(tmp_path / "e"), "--no-animation"]) == 1
    assert capsys.readouterr().err == (
        f"irring replay: error: {drifted}: sweep 1's pose (2.05, 0.75) m lies outside the room "
        "of the recorded scenario 'moving_box', as do all the others; the scenario and the "
        "sweeps do not belong together\n")


@pytest.mark.parametrize("model, vref", [("gp2y0a21", 5.0), ("gp2d12", 3.3)])
def test_drive_refuses_a_calibration_whose_sensor_the_truth_contradicts(tmp_path, capsys,
                                                                         model, vref):
    """`drive --truth t_room --calibration y21.yaml` (a GP2Y0A21's curve, t_room's ring
    carries GP2D12s) read the emulator's GP2D12 counts through the GP2Y0A21 curve and scored
    them against t_room (F1 0.789, exit 0), where `irring run` refuses the same pair."""
    cal = tmp_path / "other.yaml"
    Calibration.nominal(model, None, 12, vref).save(cal)
    out = tmp_path / "o"
    assert main(["drive", "--port", str(tmp_path / "no-such-port"), "--truth", "t_room",
                 "--calibration", str(cal), "--no-wait", "--out", str(out)]) == 1
    assert capsys.readouterr().err == (
        f"irring drive: error: {cal}: the calibration is for a {model} at {vref:g} V, but "
        "--truth t_room says the ring reads a gp2d12 at 5 V; use a calibration of that sensor "
        "(irring calibrate), or a --truth whose sensor block names this one\n")
    assert not out.exists()


def test_compare_and_bench_accuracy_refuse_two_rooms_of_one_name(tmp_path, monkeypatch):
    """Two room files both `name: same` (a copied file, renamed but not edited): compare and
    bench accuracy ran both and reported one scenario 'same', its scores the mean of two
    different rooms (coverage 0.578 of 0.918 and 0.238), its runs.csv rows told apart by
    nothing. A study names its scenarios by path and keeps them apart."""
    from irring.studies import compare

    monkeypatch.setattr(compare, "run_jobs", lambda *a, **k: pytest.fail("a run started"))
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    a.write_text(NARROW_ROOM.replace("name: narrow", "name: same"))
    b.write_text(NEAR_PATH.replace("name: narrow", "name: same").split("effects:")[0])
    message = (f"{b}: named 'same', as {a} is; the results name each scenario by its `name:`, "
               "so the two rooms would be merged into one; give them different names")
    with pytest.raises(ScenarioError) as exc:
        compare.compare([str(a), str(b)], ["rotating1"])
    assert str(exc.value) == message
    with pytest.raises(ScenarioError) as exc:
        jobs_for([str(a), str(b)], [Config()], 1)
    assert str(exc.value) == message
    b.write_text(NEAR_PATH.split("effects:")[0])
    assert len(jobs_for([str(a), str(b)], [Config()], 1)) == 2


@pytest.mark.parametrize("bits, steps, said", [
    (10, (-2, 2), ["steps -2 … 2 (t_room's: -35 … 35)", "a 10-bit ADC (t_room's: 12-bit)"]),
    (12, (-35, 35), [])])
def test_drive_says_how_the_ring_differs_from_the_truth_and_not_of_a_calibrated_offset(
        tmp_path, capsys, bits, steps, said):
    """drive --truth warned 'the device's geometry differs from t_room's ring; using the
    device's' without saying how (8 sensors of 12? other steps?), said it too of a ring whose
    IRINF matched t_room's when --calibration's measured d_o (6.94 mm) replaced t_room's 7 mm,
    and said nothing of a 10-bit ADC where the truth's sensor block says 12 bits."""
    def device(dev, cmd):   # hd's counts stay below 1024
        if isinstance(cmd, p_.Hello):
            dev.send(hd.info(bits=bits, lo=steps[0], hi=steps[1]))
        else:
            hd.good(dev, cmd)

    cal = tmp_path / "cal.yaml"
    dataclasses.replace(Calibration.nominal("gp2d12", None, bits, 5.0),
                        emitter_offset_m=0.00694).save(cal)
    dev = hd.HostileDevice(device)
    try:
        code = main(["drive", "--port", dev.link, "--truth", "t_room", "--calibration", str(cal),
                     "--timeout", str(TIMEOUT_S), "--no-wait", "--no-animation", "--out",
                     str(tmp_path / "o")])
    finally:
        dev.close()
    assert code == 0
    warned = [line for line in capsys.readouterr().out.splitlines() if "warning" in line]
    assert warned == ([f"warning: the ring on {dev.link} differs from t_room's: "
                       f"{', '.join(said)}; using the ring's"] if said else [])


def test_resuming_a_study_whose_scenario_file_changed_is_refused(tmp_path, capsys):
    """room.yaml edited after its study ran (the room 600 mm narrower), then `irring study
    --resume`: 'ran 0 (2 already in the file)' and the old room's scores summarised as the
    new room's (F1 0.974), exit 0. A comment added changes nothing."""
    room, spec, out = tmp_path / "room.yaml", tmp_path / "study.yaml", tmp_path / "o"
    room.write_text(NEAR_PATH.split("effects:")[0])
    spec.write_text("designs: [rotating1]\nscenarios: [room.yaml, t_room_cylinder]\n")
    argv = ["study", str(spec), "--out", str(out), "--workers", "1"]
    assert main(argv) == 0
    room.write_text(room.read_text() + "# checked\n")
    assert main(argv + ["--resume"]) == 0
    capsys.readouterr()
    room.write_text(room.read_text().replace("[2000, 0], [2000, 1500]", "[1400, 0], [1400, 1500]"))
    assert main(argv + ["--resume"]) == 1
    assert capsys.readouterr().err == (
        f"irring study: error: {out / 'results.csv'}: its 1 run(s) of {room} were made before "
        "the file changed (another room, ring, effects or knobs); resumed, they would be "
        "summarised as runs of it: restore the file, save the changed one under another name, "
        "or choose another --out\n")


def test_a_drive_of_fewer_or_other_poses_is_scored_on_what_it_swept(t_room):
    """`drive --truth t_room --poses 1` (or --pose 1920,450, or a drive stopped after its
    first pose) swept one pose, yet was scored against the wall t_room's four poses see:
    recall 0.332, F1 0.498, coverage 0.335, where t_room with that one pose listed scores
    F1 0.999. The sweeps' own poses judge a standing scene now; `irring run` is unchanged."""
    from irring.simulation.sim import SimRing

    one = dataclasses.replace(t_room, robot=dataclasses.replace(
        t_room.robot, poses=t_room.robot.poses[:1]))
    sweep = SimRing(t_room).sweep(0)
    cal = Calibration.for_scene(t_room)
    first = pipeline.map_sweeps([sweep], scenario=t_room, calibration=cal)
    alone = pipeline.map_sweeps([sweep], scenario=one, calibration=cal)
    assert first.scores == alone.scores
    assert first.scores["occupied_recall"] > 0.99
    every = [SimRing(t_room).sweep(k) for k in range(len(t_room.robot.poses))]
    assert pipeline.swept_scenario(t_room, every) is t_room   # irring run's: as listed
