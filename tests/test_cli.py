"""The `irring` command as a user meets it: help for every command, the scenario list, and
clear errors for bad input."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest
import serial

from irring import errors, scenario
from irring.cli import COMMANDS, build_parser, main
from irring.cli.bench import BENCHES
from irring.estimation.calibration import CalibrationError
from irring.hardware import DeviceTimeout, HandshakeError
from irring.recording import RecordingError
from irring.scenario import ScenarioError
from irring.studies.executor import ExecutorError
from irring.studies.study import StudyError


def test_no_command_prints_help_and_fails(capsys):
    assert main([]) == 2
    out = capsys.readouterr().out
    for name in COMMANDS:
        assert name in out


@pytest.mark.parametrize("argv", [[name, "--help"] for name in COMMANDS] +
                         [["bench", name, "--help"] for name in BENCHES])
def test_every_command_explains_itself(argv, capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: irring " + " ".join(argv[:-1]))
    assert len(out.splitlines()) >= 4  # more than a bare usage line
    # prose (a line at the margin) fits the terminal; indented examples keep their lines
    assert [line for line in out.splitlines() if len(line) > 80 and line[:1].strip()] == []


def _help(argv, capsys, monkeypatch) -> str:
    monkeypatch.setenv("COLUMNS", "200")
    with pytest.raises(SystemExit):
        main(argv)
    return " ".join(capsys.readouterr().out.split())


def test_top_level_help_names_every_bench_that_can_exit_6(capsys, monkeypatch):
    # it listed only speed and effects while rooms, foldover, grazing and link exit 6 too
    code = errors.TARGET_MISSED
    says_so = [name for name in BENCHES if re.search(
        rf"exits? {code}\b|\b{code} when", _help(["bench", name, "--help"], capsys, monkeypatch))]
    assert {"speed", "effects", "rooms", "foldover", "grazing", "link"} <= set(says_so)
    clause = re.search(rf"\b{code} a benchmark's target missed \(([^)]*)\)",
                       _help(["--help"], capsys, monkeypatch)).group(1)
    assert [name for name in says_so if not re.search(rf"\b{name}\b", clause)] == []


def test_drive_and_calibrate_say_how_they_leave_the_ring(capsys, monkeypatch):
    # neither said that a session ends with the ring turned back to step 0 (IRGTO,0), which
    # an Arduino, restarted by the next open, takes for step 0; nor what a warning means
    for argv in (["drive", "--help"], ["calibrate", "--help"]):
        text = _help(argv, capsys, monkeypatch)
        assert "sweep still running" in text and "(IRSTP)" in text
        assert "back to step 0 (IRGTO,0)" in text
        assert "an Arduino restarts each time its port is opened" in text
        assert "A ring that does not confirm it is named in a warning" in text


def test_scenarios_lists_every_bundled_scenario_and_marks_the_default(capsys):
    assert main(["scenarios"]) == 0
    lines = capsys.readouterr().out.splitlines()
    names = [line.split()[0] for line in lines]
    assert names == sorted(scenario.bundled())
    default = [line for line in lines if line.startswith(scenario.DEFAULT_SCENARIO + " ")]
    assert default and default[0].endswith("(default)")


HALF_THROUGH = """
name: half_through
room: {outline_mm: [[0, 0], [2420, 0], [2420, 900], [0, 900]]}
obstacles:
  - {type: cylinder, center_mm: [600, 450], radius_mm: 30}
  - {type: box, center_mm: [2500, 300], size_mm: [300, 200]}
robot: {poses: [{x_mm: 1200, y_mm: 450}]}
"""
HALF_NOTE = ("obstacles[1], a 300 × 200 mm box at (2500, 300) mm, reaches 230 mm through wall 1 "
             "((2420, 0) → (2420, 900) mm): 76.7% of it lies beyond the walls, clipped (never "
             "seen, not scored)")


def test_an_obstacle_half_through_a_wall_is_noted_where_the_user_looks(tmp_path, capsys):
    """A mistyped centre (2500 for 2300) put a box 230 mm through a wall: it loaded and ran
    without a word. `irring scenarios FILE`, `irring run`'s summary and its JSON name it (a
    note on stdout, no warning: `python -W error` runs and parsers of the JSON are unharmed;
    the box flush with the wall prints no note and no JSON key)."""
    import json
    import warnings

    room = tmp_path / "half.yaml"
    room.write_text(HALF_THROUGH)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert main(["scenarios", str(room), "t_room"]) == 0
        listed = capsys.readouterr().out.splitlines()
        assert main(["run", str(room), "--no-animation", "--out", str(tmp_path / "o")]) == 0
        readable = capsys.readouterr().out.splitlines()
        assert main(["run", str(room), "--json", "--no-animation", "--out",
                     str(tmp_path / "o")]) == 0
        summary = json.loads(capsys.readouterr().out)
    assert listed[0].split() == [str(room), "1", "pose(s)", "2", "obstacle(s)"]
    assert listed[1:] == [f"  note: {HALF_NOTE}", listed[2]] and listed[2].startswith("t_room ")
    assert readable[2] == f"  note      {HALF_NOTE}"
    assert summary["clipped_obstacles"] == [{"obstacle": 1, "walls": [1], "reach_mm": 230.0,
                                             "share_clipped": 0.7667, "note": HALF_NOTE}]
    room.write_text(HALF_THROUGH.replace("[2500, 300]", "[2270, 300]"))   # flush: no note
    assert main(["run", str(room), "--json", "--no-animation", "--out",
                 str(tmp_path / "o")]) == 0
    assert "clipped_obstacles" not in json.loads(capsys.readouterr().out)
    assert main(["scenarios", str(room)]) == 0
    assert "note" not in capsys.readouterr().out


def test_an_unknown_scenario_names_the_bundled_ones(capsys):
    assert main(["run", "t_rooom", "--out", "/nonexistent/never-written"]) == 1
    err = capsys.readouterr().err
    assert "t_rooom: no such file and no bundled scenario of that name (did you mean `t_room`?)" \
        "; bundled: angled_walls, big_room, " in err
    assert "t_room_cylinder" in err


@pytest.mark.parametrize("given, near", [
    ("t_room_cylinder.yaml", " (did you mean `t_room_cylinder`?)"),
    ("corridor", " (did you mean `corridor_table`?)"),
    ("nothing_like_it", ""),
    ("rooms/big_rooom.yaml", ""),     # a path: the user's own file, not a bundled one
])
def test_a_mistyped_scenario_name_gets_the_nearest_bundled_one(given, near, capsys):
    assert main(["scenarios", given]) == 1
    assert capsys.readouterr().err.startswith(
        f"irring scenarios: error: {given}: no such file and no bundled scenario of that "
        f"name{near}; bundled: angled_walls, ")


def test_a_scenario_named_without_yaml_beside_its_file_names_the_file(tmp_path, capsys,
                                                                     monkeypatch):
    # it suggested the nearest bundled name (`t_room`) for my_lroom beside my_lroom.yaml
    (tmp_path / "rooms").mkdir()
    (tmp_path / "rooms" / "my_lroom.yaml").write_text("name: my_lroom\n")
    monkeypatch.chdir(tmp_path)
    assert main(["scenarios", "rooms/my_lroom", "my_lroom"]) == 1
    err = capsys.readouterr().err
    assert "rooms/my_lroom: no such file and no bundled scenario of that name (did you mean " \
        "`rooms/my_lroom.yaml`?); bundled: " in err
    assert "my_lroom: no such file and no bundled scenario of that name (did you mean " \
        "`t_room`?)" in err                             # no my_lroom.yaml in this folder


# Every range-checked option: a bad value is a usage error (argparse's exit 2, usage line,
# the option, what was given and what is allowed), never exit 1, which means a failed run.
BAD_VALUES = [
    (["bench", "accuracy", "--seeds", "0"], "--seeds", "must be in 1 … 100000, got 0"),
    (["bench", "accuracy", "--workers", "0"], "--workers", "must be ≥ 1, got 0"),
    (["bench", "dynamics", "--sweeps", "0"], "--sweeps", "must be in 1 … 10000, got 0"),
    (["bench", "effects", "--rounds", "0"], "--rounds", "must be ≥ 1, got 0"),
    (["bench", "effects", "--batch", "-3"], "--batch", "must be ≥ 1, got -3"),
    (["bench", "effects", "--samples", "0"], "--samples", "must be in 1 … 64, got 0"),
    (["bench", "estimator", "--sweeps", "0"], "--sweeps", "must be ≥ 1, got 0"),
    (["bench", "estimator", "--max-iterations", "0"], "--max-iterations", "must be ≥ 1, got 0"),
    (["bench", "speed", "--rounds", "0"], "--rounds", "must be ≥ 1, got 0"),
    (["bench", "speed", "--rounds", "many"], "--rounds", "must be an integer ≥ 1, got 'many'"),
    (["calibrate", "--sweeps", "0"], "--sweeps", "must be in 1 … 10000, got 0"),
    (["compare", "--seeds", "0"], "--seeds", "must be in 1 … 100000, got 0"),
    (["compare", "--bearings", "7"], "--bearings", "must be in 8 … 3600, got 7"),
    (["compare", "--distances-mm", "250,0"], "--distances-mm",
     "must be one or more positive distances in mm up to 100000, like 250,500,1000; got '250,0'"),
    (["compare", "--distances-mm", ","], "--distances-mm",
     "must be one or more positive distances in mm up to 100000, like 250,500,1000; got ','"),
    (["geometry", "--distances-mm", "250,abc"], "--distances-mm",
     "must be positive distances in mm separated by commas, like 250,500,1000; got '250,abc'"),
    (["geometry", "--samples", "999"], "--samples", "must be in 1000 … 10000000, got 999"),
    (["geometry", "--samples", "100000000000"], "--samples",
     "must be in 1000 … 10000000, got 100000000000"),       # was exit 5, out of memory
    # every seed option takes what a scenario's seed: takes, 0 … 2**63 - 1
    (["run", "--seed", "-3"], "--seed", "must be ≥ 0, got -3"),
    (["geometry", "--seed", "-1"], "--seed", "must be ≥ 0, got -1"),
    (["bench", "speed", "--seed", "-1"], "--seed", "must be ≥ 0, got -1"),
    (["bench", "estimator", "--seed", "-7"], "--seed", "must be ≥ 0, got -7"),
    (["bench", "effects", "--seed", "9223372036854775808"], "--seed",
     "must be 0 … 9223372036854775807, got 9223372036854775808"),
    (["calibrate", "--seed", "-1"], "--seed", "must be ≥ 0, got -1"),
    (["emulate", "--seed", "-2"], "--seed", "must be ≥ 0, got -2"),
    (["bench", "dynamics", "--seeds", "-4"], "--seeds", "must be ≥ 0, got -4"),
    (["emulate", "--fault-seed", "x"], "--fault-seed",
     "must be an integer 0 … 9223372036854775807, got 'x'"),
    # these were `type=int`/`float`: -5 named a field (stall_after) with no usage line, and a
    # negative --stall-seconds was taken
    (["emulate", "--stall-after", "-5"], "--stall-after", "must be ≥ 0, got -5"),
    (["emulate", "--disconnect-after", "-1"], "--disconnect-after", "must be ≥ 0, got -1"),
    (["emulate", "--stall-seconds", "-2"], "--stall-seconds",
     "must be a number ≥ 0 and ≤ 86400, got '-2'"),
    (["drive", "--settle-ms", "70000"], "--settle-ms", "must be in 0 … 60000, got 70000"),
    (["drive", "--samples", "65"], "--samples", "must be in 1 … 64, got 65"),
    (["calibrate", "--sensor", "-1"], "--sensor", "must be ≥ 0, got -1"),
    # int() refuses over 4,300 digits: 'must be an integer ≥ 0' and all 5,000 of them (5 kB)
    (["run", "--seed", "9" * 5000], "--seed",
     "must be 0 … 9223372036854775807, got a number of 5,000 digits"),
    (["compare", "--seeds", "7" * 4400], "--seeds", "must be in 1 … 100000, got a number of "
                                                    "4,400 digits"),
    (["bench", "effects", "--seed", "8" * 300], "--seed",
     "must be 0 … 9223372036854775807, got 888888888888888888...8888888888888888888"),
]


@pytest.mark.parametrize("argv, option, message", BAD_VALUES,
                         ids=[" ".join(argv)[:60] for argv, _, _ in BAD_VALUES])
def test_an_out_of_range_value_is_a_usage_error(argv, option, message, capsys):
    command = " ".join(argv[:-2])
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(f"usage: irring {command}")
    assert f"irring {command}: error: argument {option}: {message}" in err


def test_the_boundary_values_are_accepted():
    parse = build_parser().parse_args
    assert parse(["bench", "accuracy", "--seeds", "1", "--workers", "1"]).workers == 1
    assert parse(["bench", "dynamics", "--sweeps", "1"]).sweeps == 1
    args = parse(["bench", "effects", "--rounds", "1", "--batch", "1", "--samples", "1"])
    assert (args.rounds, args.batch, args.samples) == (1, 1, 1)
    args = parse(["bench", "estimator", "--sweeps", "1", "--max-iterations", "1"])
    assert (args.sweeps, args.max_iterations) == (1, 1)
    assert parse(["bench", "speed", "--rounds", "1"]).rounds == 1
    assert parse(["calibrate", "--sweeps", "1"]).sweeps == 1
    args = parse(["compare", "--seeds", "1", "--bearings", "8", "--distances-mm", "0.5, 300"])
    assert (args.seeds, args.bearings) == (1, 8)
    assert args.distances_mm == pytest.approx([0.0005, 0.3])
    assert parse(["geometry", "--samples", "1000"]).samples == 1000
    assert parse(["geometry", "--samples", "10000000"]).samples == 10_000_000
    assert parse(["run", "t_room", "--seed", "0"]).seed == 0
    assert parse(["emulate", "--fault-seed", str(2**63 - 1)]).fault_seed == 2**63 - 1


def test_the_default_distances_are_parsed_to_metres():
    parse = build_parser().parse_args
    assert parse(["geometry"]).distances_mm == pytest.approx([0.25, 0.5, 0.75, 1.0])
    assert parse(["compare"]).distances_mm == pytest.approx([0.25, 0.35, 0.45, 0.55, 0.65, 0.75])
    assert parse(["bench", "accuracy"]).workers is None
    assert parse(["calibrate"]).sweeps is None


@pytest.mark.parametrize("argv, option, message", BAD_VALUES,
                         ids=[" ".join(argv)[:60] for argv, _, _ in BAD_VALUES])
def test_help_states_the_allowed_range(argv, option, message, capsys):
    with pytest.raises(SystemExit):
        main([*argv[:-2], "--help"])
    blocks = capsys.readouterr().out.split("\n  --")
    block = " ".join(next(b for b in blocks if b.startswith(option[2:] + " ")).split())
    if "0 … 9223372036854775807" in message:
        allowed = "≥ 0"                                   # a seed: 0 … 2**63 - 1
    elif "≥" in message:
        allowed = "≥ " + message.split("≥ ")[1].split(",")[0]
    elif "must be in " in message:                        # a range: "1000 … 10000000"
        allowed = message.split("must be in ")[1].split(",")[0]
    else:
        allowed = "positive"
    assert allowed in block


def test_version_prints_the_installed_package_version(capsys):
    from importlib.metadata import version

    from irring.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"irring {version('irring')}"


def test_the_docs_a_user_is_sent_to_exist(capsys):
    """README and every command's --help name files of this repository that exist."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    texts = {"README.md": (root / "README.md").read_text()}
    for name in COMMANDS:
        with pytest.raises(SystemExit):
            main([name, "--help"])
        texts[f"irring {name} --help"] = capsys.readouterr().out
    named = {(where, doc) for where, text in texts.items()
             for doc in re.findall(r"(?<![\w/.])((?:[\w-]+/)*[\w-]+\.md)\b", text)}
    # a bare name (README's layout map lists docs/'s files by name) may sit in a folder
    missing = sorted((w, d) for w, d in named if not (root / d).exists()
                     and ("/" in d or not any(root.glob(f"*/{d}"))))
    assert missing == []


def test_markdown_links_stay_inside_the_repository():
    """Every [text](target) of the repository's Markdown names a file of the repository
    that exists (or an #anchor): a checkout read offline has everything it links to."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    pages = [p for p in root.rglob("*.md")   # not .pytest_cache/, out/, build/, *.egg-info/
             if not any(part.startswith(".") or part in ("out", "build")
                        or part.endswith("egg-info") for part in p.relative_to(root).parts)]
    assert root / "README.md" in pages and root / "firmware" / "README.md" in pages
    bad = sorted((str(page.relative_to(root)), target)
                 for page in pages
                 for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text())
                 if not target.startswith("#")
                 and (":" in target
                      or not (page.parent / target.split("#")[0]).resolve().is_relative_to(root)
                      or not (page.parent / target.split("#")[0]).exists()))
    assert bad == []
    # a link to a section names a heading of the page, as GitHub makes its anchor
    for page in pages:
        text = page.read_text()
        anchors = {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-")
                   for h in re.findall(r"^#+ (.+)$", text, flags=re.M)}
        assert set(re.findall(r"\]\(#([^)]+)\)", text)) <= anchors, page


def test_markdown_pages_hold_no_restructuredtext():
    """docs/ is read as Markdown (on GitHub, in an editor): a Sphinx role (:class:`X`)
    shows as literal text, and a reST table's ===== line turns the paragraph above it into
    a heading."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    pages = [root / "README.md", *sorted((root / "docs").glob("*.md"))]
    found = sorted((p.name, m) for p in pages for m in re.findall(
        r":(?:class|func|meth|data|attr|mod|exc|obj):`|^=+ +=+ *$", p.read_text(), flags=re.M))
    assert found == []


def test_the_docs_index_lists_every_page():
    """docs/README.md is where a newcomer looks for a part: every page of docs/ is linked."""
    from pathlib import Path

    docs = Path(__file__).resolve().parents[1] / "docs"
    linked = set(re.findall(r"\]\(([\w-]+\.md)\)", (docs / "README.md").read_text()))
    assert linked == {p.name for p in docs.glob("*.md")} - {"README.md"}


def test_a_command_loads_only_its_own_module():
    """Building the parser imports no subcommand; `irring run` parses without loading
    what other commands need (the studies, the serial link, Dask, matplotlib charts)."""

    code = """
import sys
from irring.cli import build_parser
parser = build_parser()
print(sorted(m for m in sys.modules if m.startswith("irring.cli.") and m != "irring.cli._common"))
args = parser.parse_args(["run", "t_room", "--seed", "3"])
print(args.seed, args.func.__module__)
print(sorted(m for m in sys.modules if m.startswith(("irring.cli.", "irring.studies",
      "irring.hardware", "serial", "dask", "matplotlib", "importlib.metadata"))))
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        "[]", "3 irring.cli.run", "['irring.cli._common', 'irring.cli.run']"]


def test_bench_loads_only_the_benchmark_asked_for():
    parser = build_parser()
    before = {m for m in sys.modules if m.startswith("irring.cli.bench_")}
    args = parser.parse_args(["bench", "render", "--repeats", "2"])
    loaded = {m for m in sys.modules if m.startswith("irring.cli.bench_")} - before
    assert args.repeats == 2 and args.func.__module__ == "irring.cli.bench_render"
    assert loaded <= {"irring.cli.bench_render"}


@pytest.mark.parametrize("users_gl", [None, "osmesa"])
def test_commands_that_draw_nothing_with_mujoco_skip_its_opengl_library(users_gl):
    """MuJoCo loads GLFW on import unless MUJOCO_GL says not to: only `irring view` draws
    with OpenGL. The user's own MUJOCO_GL stays as it was, and so does the environment."""

    pytest.importorskip("mujoco")
    code = """
import contextlib, io, os, sys
from irring.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    assert main(["geometry", "--samples", "1000", "--distances-mm", "500"]) == 0
print("mujoco" in sys.modules, "glfw" in sys.modules, os.environ.get("MUJOCO_GL"))
"""
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    if users_gl:
        env["MUJOCO_GL"] = users_gl
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, env=env)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["True", "False", str(users_gl)]


def test_every_user_error_is_one_line_with_its_exit_status():
    """Each module's error derives from irring.errors, which maps it to a status without
    importing the module (errors imports nothing of irring)."""
    cases = [(ScenarioError("room.yaml: walls: expected a list"), errors.INPUT),
             (StudyError("s.yaml: seeds: expected ≥ 1"), errors.INPUT),
             (RecordingError("x.npz: not an irring recording"), errors.INPUT),
             (CalibrationError("c.yaml: curve: too few points"), errors.INPUT),
             (ExecutorError("no Dask: pip install 'irring[dask]'"), errors.USAGE),
             (HandshakeError("no IRINF answer\non /dev/ttyUSB0"), errors.DEVICE),
             (DeviceTimeout(""), errors.DEVICE),
             (serial.SerialException("port gone"), errors.DEVICE),
             (errors.TooBig("a 90000 × 80000 grid"), errors.TOO_BIG),
             (KeyError("x"), errors.INTERNAL)]
    got = [errors.describe(exc) for exc, _ in cases]
    assert [status for status, _ in got] == [status for _, status in cases]
    assert got[5][1] == "no IRINF answer on /dev/ttyUSB0"   # one line
    assert got[6][1] == "DeviceTimeout"                      # never an empty line
    assert got[0][1] == "room.yaml: walls: expected a list"
    assert got[-1][1].startswith("internal error (KeyError: 'x'); rerun with --debug")
    # still the built-in kinds callers catch
    assert isinstance(cases[0][0], ValueError) and isinstance(cases[3][0], ValueError)
    assert isinstance(cases[4][0], RuntimeError) and isinstance(cases[5][0], RuntimeError)


def test_a_reader_that_stops_early_ends_the_command_quietly():
    """`irring geometry --design all | head -1`: when the reader has gone, the command stops
    with status 4 (an output not written) and no error line or traceback on stderr."""

    # one distance: the same 35 lines to write, a third of the Monte Carlo (1.6 s CPU, not 4.6)
    proc = subprocess.Popen([sys.executable, "-m", "irring", "geometry", "--design", "all",
                             "--samples", "1000", "--distances-mm", "500"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()                    # before it prints: every write finds no reader
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 4
    assert err == b""


def _with_closed(fd: int, argv: list[str], cwd) -> subprocess.CompletedProcess:
    """`irring ARGV` started with standard stream ``fd`` closed (`>&-`, `2>&-`, `<&-`), the
    others captured (stdin: /dev/null)."""

    return subprocess.run([sys.executable, "-m", "irring", *argv], cwd=cwd,
                          stdin=subprocess.DEVNULL, capture_output=True, text=True,
                          preexec_fn=lambda: os.close(fd), timeout=300)


def test_a_closed_standard_output_is_an_output_error(tmp_path):
    """`irring scenarios >&-`: exit 70, 'internal error (AttributeError: 'NoneType' object has
    no attribute 'write')' (Python leaves a stream closed at start None), and the next file
    the command opened took descriptor 1, so whatever wrote to it would land in that file.
    Now exit 4 naming standard output, with /dev/null holding the descriptor."""
    done = _with_closed(1, ["scenarios"], tmp_path)
    assert done.returncode == errors.OUTPUT
    assert done.stderr == ("irring scenarios: error: standard output is closed (as by >&-), "
                           "so nothing can be written to it\n")
    probe = ("import os, sys\nfrom irring import cli\ncli._hold_closed_streams()\n"
             "print(os.readlink('/proc/self/fd/1'), file=sys.stderr)")
    held = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                          preexec_fn=lambda: __import__("os").close(1), timeout=60)
    assert held.stderr == "/dev/null\n"


def test_a_closed_standard_error_costs_only_the_messages(tmp_path):
    """`irring geometry 2>&-` (a cron job, a daemon): exit 70 before any work (progress bars
    asked the missing stream isatty()), and an error line went to standard output instead
    (print(file=None) writes there). Now the work is done, messages go to /dev/null, and an
    error still ends in its status with nothing on standard output."""
    done = _with_closed(2, ["geometry", "--samples", "1000", "--range-mm", "300"], tmp_path)
    assert done.returncode == 0
    assert "overlap" in done.stdout and done.stdout.count("\n") > 3
    failed = _with_closed(2, ["replay", "missing.npz"], tmp_path)
    assert (failed.returncode, failed.stdout) == (errors.INPUT, "")


@pytest.mark.parametrize("argv, module, target", [
    (["emulate", "l_room", "--link", "x.pty"], "irring.cli.emulate", "Device"),
    (["bench", "speed", "--scenario", "l_room"], "irring.cli.bench_speed", "measure"),
    (["view", "l_room", "--out", "x.png"], "irring.simulation.view", "SceneView"),
])
def test_a_pose_is_typed_as_the_map_numbers_it_from_1(argv, module, target, monkeypatch,
                                                      capsys):
    """--pose K is scan pose K of 1 … N in every command (map.png and the progress lines
    count from 1): pose 2 of l_room's 3 is index 1; 0, 4 and -1 are refused naming
    what is allowed (bench speed and emulate took 0-based indices, and -1 silently meant
    the last pose)."""
    import importlib

    mod = importlib.import_module(module)
    seen = {}

    class Stop(SystemExit):   # main lets a SystemExit through
        pass

    def record(*a, **k):
        seen.update(k)
        raise Stop

    monkeypatch.setattr(mod, target, record)
    with pytest.raises(Stop):
        main(argv + ["--pose", "2"])
    assert seen[{"Device": "fixed_pose", "measure": "pose_index", "SceneView": "pose"}[target]] == 1
    assert main(argv + ["--pose", "4"]) == 2
    assert capsys.readouterr().err.endswith(
        "error: --pose 4 is out of range: scenario 'l_room' has 3 scan pose(s), "
        "1 … 3\n")
    for bad in ("0", "-1"):
        with pytest.raises(SystemExit) as e:
            main(argv + ["--pose", bad])
        assert e.value.code == 2
        assert f"argument --pose: must be ≥ 1, got {bad}" in capsys.readouterr().err


@pytest.mark.parametrize("argv, command, said", [
    (["run", "t_room", "--bogus"], "irring run", "unrecognized option: --bogus"),
    (["bench", "speed", "--json", "x"], "irring bench speed", "unrecognized arguments: x")])
def test_an_unknown_option_is_reported_by_its_command_with_its_usage(argv, command, said,
                                                                     capsys):
    """argparse's own output (usage, then one error line, exit 2), but the command's: it
    printed `irring`'s usage (COMMAND ...) and 'irring: error:' for a subcommand's option."""
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(f"usage: {command} [-h]")
    assert err.endswith(f"\n{command}: error: {said}\n")


@pytest.mark.parametrize("argv, extra, meant", [
    (["run", "t_room", "--seeds", "3"], "--seeds", "--seed"),
    (["run", "--ouT", "x"], "--ouT", "--out"),          # x is taken as the SCENARIO
    (["view", "--steps", "3"], "--steps", "--step"),
    (["bench", "rooms", "--jsn"], "--jsn", "--json"),
    (["drive", "--port", "p", "--calibraton", "c"], "--calibraton", "--calibration"),
])
def test_a_mistyped_option_is_named_with_the_one_meant(argv, extra, meant, capsys, tmp_path,
                                                       monkeypatch):
    """Python 3.11's argparse says only 'unrecognized arguments'; a scenario key or name
    typed wrong already gets a 'did you mean'. Nothing runs."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    assert capsys.readouterr().err.endswith(
        f": error: unrecognized option: {extra} (did you mean {meant}?)\n")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", [["run", "t_room"], ["replay", "sweeps.npz"],
                                     ["drive", "--port", "ring.pty"]])
def test_mcap_without_its_extra_is_refused_before_any_work(command, tmp_path, monkeypatch,
                                                            capsys):
    """Without the mcap extra, --mcap ended a whole run in exit 70 after every other file
    was written; it is a usage error at the command line."""
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "mcap_ros2" else real(name, *a))
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_:
        main(command + ["--mcap", "run.mcap"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "writing run.mcap needs the mcap extra: pip install 'irring[mcap]'" in err
    assert list(tmp_path.iterdir()) == []        # nothing simulated, nothing written


def test_run_help_explains_every_reason_the_readings_line_can_give(capsys, monkeypatch):
    """`irring run` prints '2153 valid (no return 1181, out of range 56, incidence unknown
    18)'; a newcomer finds each word explained in its help, and a new Reason must be too."""
    from irring.core import Reason

    monkeypatch.setenv("COLUMNS", "200")
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    readings = capsys.readouterr().out.split("Readings:", 1)[1].split("examples:")[0]
    said = re.findall(r"(?:^|\), |: )([a-z][a-z ]+?) \(", " ".join(readings.split()))
    assert sorted(said) == sorted(r.name.lower().replace("_", " ") for r in Reason
                                  if r != Reason.OK)


@pytest.mark.parametrize("argv, near", [
    (["compare", "--seeds", "1", "--distances-mm", "350,0.25"], "0.25"),  # metres typed as mm
    (["geometry", "--samples", "1000", "--distances-mm", "500,169"], "169"),
])
def test_a_cylinder_inside_the_housing_is_refused_before_the_work(argv, near, capsys):
    # robot centre to the cylinder's near side: within rotating12's 150 mm ring + 20 mm
    # housing the cylinder is inside the robot (every bearing read as a miss, exit 0, before)
    assert main(argv) == errors.USAGE
    err = capsys.readouterr().err
    assert f"--distances-mm {near}: a cylinder that near is inside rotating12's housing" in err
    assert "beyond 170" in err


def test_a_cylinder_just_past_the_housing_is_measured(capsys):
    assert main(["geometry", "--design", "rotating12", "--samples", "1000",
                 "--distances-mm", "171"]) == 0
    assert "at    171 mm" in capsys.readouterr().out


def test_scenarios_checks_every_yaml_in_a_folder(tmp_path, capsys, monkeypatch):
    """`irring scenarios my_rooms/` was refused ("is a folder"), though `irring bench rooms
    my_rooms/` and now a study take a folder: each *.yaml is checked, a bad
    one named, the others listed, and the count says how many files were checked."""
    (tmp_path / "rooms").mkdir()
    (tmp_path / "empty").mkdir()
    (tmp_path / "rooms" / "b.yaml").write_text(HALF_THROUGH.replace("[2500, 300]",
                                                                    "[2270, 300]"))
    (tmp_path / "rooms" / "a.yaml").write_text("name: a\n")
    monkeypatch.chdir(tmp_path)
    assert main(["scenarios", "rooms", "empty", "t_room"]) == 1
    out, err = capsys.readouterr()
    assert [line.split()[:3] for line in out.splitlines()] == [
        ["rooms/b.yaml", "1", "pose(s)"], ["t_room", "4", "pose(s)"]]
    assert err.splitlines() == [
        "irring scenarios: error: empty: the folder holds no *.yaml scenario",
        "irring scenarios: error: rooms/a.yaml: room: required key is missing",
        "irring scenarios: 2 of 4 scenario(s) refused"]
