"""Round thirteen of hostile input: each test names the input that broke and
asserts what happens now."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from irring.cli import main
from irring.errors import OutputError
from irring.estimation.calibration import CalibrationError
from irring.recording import load_recording, save_recording
from irring.scenario import resolve
from irring.studies.study import StudyError, load_study

NOISELESS_TWICE = """name: twice
seed: 1
room:
  outline_mm: [[0, 0], [2420, 0], [2420, 900], [0, 900]]
robot:
  poses:
    - {x_mm: 1920, y_mm: 450}
    - {x_mm: 1920, y_mm: 450}
    - {x_mm: 500, y_mm: 450}
effects: {}
"""


def test_replay_refuses_a_recording_whose_sweep_is_copied(tmp_path, capsys):
    """t_room's recording saved with its sweeps twice over (8 sweeps) was replayed as eight
    poses: 4306 valid readings of 2153, coverage 0.922 -> 0.931, exit 0: every reading
    counted twice as evidence. A noiseless scene that lists one pose twice sweeps it twice
    alike, honestly, and is replayed as before."""
    assert main(["run", "t_room", "--out", str(tmp_path / "t"), "--no-animation"]) == 0
    sweeps, meta = load_recording(tmp_path / "t" / "sweeps.npz")
    twice = save_recording(tmp_path / "twice.npz", sweeps + sweeps, meta)
    one = save_recording(tmp_path / "one.npz", [sweeps[0], sweeps[1], sweeps[0]], meta)
    capsys.readouterr()
    assert main(["replay", str(twice), "--out", str(tmp_path / "r"), "--no-animation"]) == 1
    assert capsys.readouterr().err == (
        f"irring replay: error: {twice}: sweep 5 repeats sweep 1 reading for reading (its pose, "
        "steps, 852 counts and timestamps): a copy, whose readings would be mapped twice; the "
        "recorded scenario 't_room' does not list that pose twice. Remove the copy\n")
    assert not (tmp_path / "r").exists()
    assert main(["replay", str(one), "--out", str(tmp_path / "r"), "--no-animation"]) == 1
    assert "sweep 3 repeats sweep 1 reading for reading" in capsys.readouterr().err

    room = tmp_path / "twice.yaml"
    room.write_text(NOISELESS_TWICE)
    assert main(["run", str(room), "--out", str(tmp_path / "n"), "--no-animation"]) == 0
    same, _ = load_recording(tmp_path / "n" / "sweeps.npz")
    assert np.array_equal(same[0].counts, same[1].counts)   # noiseless: alike
    assert main(["replay", str(tmp_path / "n" / "sweeps.npz"), "--out", str(tmp_path / "m"),
                 "--no-animation"]) == 0
    # …but its third sweep copied in place of the second is still a copy
    sweeps, meta = load_recording(tmp_path / "n" / "sweeps.npz")
    bad = save_recording(tmp_path / "bad.npz", [sweeps[0], sweeps[2], sweeps[2]], meta)
    capsys.readouterr()
    assert main(["replay", str(bad), "--out", str(tmp_path / "b"), "--no-animation"]) == 1
    assert capsys.readouterr().err == (
        f"irring replay: error: {bad}: sweep 3 repeats sweep 2 reading for reading (its pose, "
        "steps, 852 counts and timestamps): a copy, whose readings would be mapped twice; the "
        "recorded scenario 'twice' does not list that pose twice. Remove the copy\n")


ONE_POSE_BOX = """name: same
room:
  outline_mm: [[0, 0], [{w}, 0], [{w}, 1500], [0, 1500]]
robot:
  poses:
    - {{x_mm: 700, y_mm: 750}}
"""


def test_bench_rooms_tells_two_rooms_of_one_name_apart(tmp_path, capsys):
    """Two folders each holding a room named 'same' (1400 and 2600 mm wide): rooms.json kept
    each file's source, but rooms.csv and the table said 'same' twice, so which row was
    which room could not be told (coverage 0.955 and 0.238 of two different rooms)."""
    for sub, w in (("s1", 1400), ("s2", 2600)):
        (tmp_path / sub).mkdir()
        (tmp_path / sub / "room.yaml").write_text(ONE_POSE_BOX.format(w=w))
    out = tmp_path / "bench"
    a, b = tmp_path / "s1" / "room.yaml", tmp_path / "s2" / "room.yaml"
    assert main(["bench", "rooms", str(a.parent), str(b.parent), "narrow_room",
                 "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    # both 'same' rooms list no effects: each has the note that its two rows are alike
    notes = [line for line in lines if line.startswith("  note: its scene lists no")]
    assert len(notes) == 2
    lines = [line for line in lines if line not in notes]
    assert [line.split("  ")[0] for line in lines[1:7:2]] == [f"same ({a})", f"same ({b})",
                                                              "narrow_room"]
    with open(out / "rooms.csv") as fh:
        table = list(csv.DictReader(fh))
    narrow = str(resolve("narrow_room"))
    assert [(r["room"], r["source"], r["sensor"]) for r in table] == [
        ("same", str(a), "effects"), ("same", str(a), "ideal"),
        ("same", str(b), "effects"), ("same", str(b), "ideal"),
        ("narrow_room", narrow, "effects"), ("narrow_room", narrow, "ideal")]
    assert table[0]["coverage"] != table[2]["coverage"]


def test_an_output_name_taken_by_a_folder_is_never_swapped_away(tmp_path, capsys):
    """`irring run t_room --out o` where o/ held a folder map.png/ (the user's thesis.tex in
    it) and nothing else: the run swapped o/ whole for its outputs, and map.png/thesis.tex
    was gone (exit 0). With another file beside it the run did all its work, then exit 4
    "cannot move the outputs in: Is a directory", naming neither the entry nor the cause."""
    out = tmp_path / "o"
    (out / "map.png").mkdir(parents=True)
    (out / "map.png" / "thesis.tex").write_text("precious")
    assert main(["run", "t_room", "--out", str(out), "--no-animation"]) == 4
    assert capsys.readouterr().err == (
        f"irring run: error: --out {out}: map.png there is a folder; irring writes a file of "
        "that name and never replaces a folder: move it away or choose another --out\n")
    assert (out / "map.png" / "thesis.tex").read_text() == "precious"
    assert sorted(p.name for p in out.iterdir()) == ["map.png"]

    # found only when the files are moved in (a library caller, a study's summary): nothing
    # moved, nothing removed
    from irring.outputs import OutputSet
    (out / "map.yaml").write_text("old")
    target = OutputSet(out)
    with pytest.raises(OutputError) as refused:
        with target as tmp:
            for name in ("map.yaml", "map.png", "sweeps.npz"):
                (tmp / name).write_text("new")
    assert str(refused.value) == (
        f"--out {out}: map.png there is a folder; irring writes a file of that name and never "
        "replaces a folder: move it away or choose another --out")
    assert (out / "map.yaml").read_text() == "old" and not (out / "sweeps.npz").exists()
    assert (out / "map.png" / "thesis.tex").read_text() == "precious"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".irring-")]


def test_bench_rooms_refuses_an_output_folder_whose_csv_is_a_folder(tmp_path, capsys):
    """`bench rooms --out o` with o/rooms.csv/ a folder: o/ was swapped whole, the folder
    (and whatever it held) removed, exit 0."""
    out = tmp_path / "o"
    (out / "rooms.csv").mkdir(parents=True)
    (out / "rooms.csv" / "notes.txt").write_text("mine")
    assert main(["bench", "rooms", "narrow_room", "--out", str(out)]) == 4
    assert capsys.readouterr().err.endswith(
        f"--out {out}: rooms.csv there is a folder; irring writes a file of that name and "
        "never replaces a folder: move it away or choose another --out\n")
    assert (out / "rooms.csv" / "notes.txt").read_text() == "mine"


def test_a_study_path_that_names_two_rooms_is_refused(tmp_path, monkeypatch):
    """sub/st.yaml lists `room.yaml`; sub/room.yaml lies beside it (the README: paths
    relative to the study file) and the working folder holds another room.yaml. Run from
    there, the study ran the working folder's room (coverage 0.238, not 0.955) and said
    nothing."""
    sub = tmp_path / "sub"
    sub.mkdir()
    (sub / "room.yaml").write_text(ONE_POSE_BOX.format(w=1400))
    (tmp_path / "room.yaml").write_text(ONE_POSE_BOX.format(w=2600))
    (sub / "st.yaml").write_text("designs: [rotating12]\nscenarios: [room.yaml]\nseeds: 1\n")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(StudyError) as two:
        load_study("sub/st.yaml")
    assert str(two.value) == (
        "sub/st.yaml: scenarios[0]: 'room.yaml' names two files: sub/room.yaml beside the "
        "study file and room.yaml in the working folder; write the path of the one you mean "
        "(e.g. sub/room.yaml)")
    # one of them alone is taken as before; both one file is no question
    (tmp_path / "room.yaml").unlink()
    assert load_study("sub/st.yaml").scenarios == ("sub/room.yaml",)
    monkeypatch.chdir(sub)
    assert load_study("st.yaml").scenarios == ("room.yaml",)
    (sub / "room.yaml").rename(tmp_path / "room.yaml")
    monkeypatch.chdir(tmp_path)
    assert load_study("sub/st.yaml").scenarios == ("room.yaml",)


def test_irrings_own_outputs_named_as_input_files_are_told_for_what_they_are(tmp_path, capsys):
    """A run's own outputs given where a YAML file belongs: sweeps.npz as the scenario (view,
    drive --truth, compare --scenario) or map.png as --calibration were told "line 1: not
    UTF-8 text (byte 14); save the scenario file as UTF-8", advice no one can follow for a
    recording or a picture; map.yaml (the ROS map) as a scenario or calibration got
    "image: unknown key"."""
    out = tmp_path / "t"
    assert main(["run", "t_room", "--out", str(out), "--mcap", str(tmp_path / "t.mcap")]) == 0
    capsys.readouterr()
    cases = [
        (["view", str(out / "sweeps.npz")], out / "sweeps.npz", "a zip archive, as a "
         "recording (sweeps.npz) is: `irring replay` reads those; expected a scenario file"),
        (["run", "t_room", "--calibration", str(out / "map.png")], out / "map.png",
         "a PNG picture; expected a calibration file"),
        (["run", "t_room", "--calibration", str(out / "map_building.gif")],
         out / "map_building.gif", "a GIF picture; expected a calibration file"),
        (["run", str(out / "map.pgm")], out / "map.pgm",
         "a PGM picture (as map.pgm is); expected a scenario file"),
        (["run", str(tmp_path / "t.mcap")], tmp_path / "t.mcap",
         "an MCAP file (what --mcap writes, for viewers such as Foxglove); expected a "
         "scenario file"),
        (["run", str(out / "map.yaml")], out / "map.yaml",
         "a ROS map_server map (the map.yaml irring writes beside map.pgm); expected a "
         "scenario file"),
        (["run", "t_room", "--calibration", str(out / "map.yaml")], out / "map.yaml",
         "a ROS map_server map (the map.yaml irring writes beside map.pgm); expected a "
         "calibration file"),
    ]
    for argv, path, what in cases:
        assert main(argv + ["--out", str(tmp_path / "o")]) == 1, argv
        assert capsys.readouterr().err.endswith(f": error: {path}: {what}\n"), argv


def test_replay_of_a_run_folder_or_its_picture_points_at_the_recording(tmp_path, capsys):
    """`irring replay out/t` (the run's folder) said "is a folder; expected a sweeps .npz
    recording" though sweeps.npz lay in it; `replay out/t/map.pgm` said "not an irring
    recording (.npz), or a damaged one: BadZipFile: File is not a zip file"."""
    out = tmp_path / "t"
    assert main(["run", "t_room", "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["replay", str(out), "--out", str(tmp_path / "r")]) == 1
    assert capsys.readouterr().err == (
        f"irring replay: error: {out}: is a folder; expected a sweeps .npz recording (this "
        f"one holds one: irring replay {out / 'sweeps.npz'})\n")
    for name, kind in (("map.pgm", "a PGM picture (as map.pgm is)"),
                       ("map.png", "a PNG picture"), ("map_building.gif", "a GIF picture")):
        assert main(["replay", str(out / name), "--out", str(tmp_path / "r")]) == 1
        assert capsys.readouterr().err == (
            f"irring replay: error: {out / name}: {kind}; expected a sweeps .npz recording\n")


def test_a_pyopengl_platform_at_odds_with_the_renderer_is_a_usage_error(tmp_path):
    """PYOPENGL_PLATFORM=bogus (or egl where MuJoCo draws with OSMesa): `irring view` ended
    in exit 70, "internal error (ImportError: …); … please report it", for a setting of the
    user's environment, as MUJOCO_GL=bogus already is told (exit 2)."""
    import os
    import subprocess
    import sys

    from irring.simulation.view import gl_backend

    backend = gl_backend()
    other = "egl" if backend == "osmesa" else "osmesa"
    for value in ("bogus", other):
        env = dict(os.environ, PYOPENGL_PLATFORM=value)
        env.pop("IRRING_DEBUG", None)
        done = subprocess.run([sys.executable, "-m", "irring", "view", "t_room", "--out",
                               str(tmp_path / "v.png")], env=env, capture_output=True,
                              text=True, timeout=300)
        assert done.returncode == 2, done.stderr
        assert done.stderr == (
            f"irring view: error: PYOPENGL_PLATFORM={value!r} is not the OpenGL platform "
            f"MuJoCo draws this picture with ({backend}); unset it, or set it (and "
            f"MUJOCO_GL) to {backend}\n")
        assert not (tmp_path / "v.png").exists()


def _irring(args, tmp_path, **env):
    import os
    import subprocess
    import sys

    full = dict(os.environ, **env)
    full.pop("IRRING_DEBUG", None)
    return subprocess.run([sys.executable, "-m", "irring", *args], env=full, cwd=tmp_path,
                          capture_output=True, timeout=600)


def test_a_bad_mplbackend_does_not_stop_irrings_own_charts(tmp_path):
    """MPLBACKEND=bogus: `irring calibrate` wrote the calibration, then ended in exit 70
    "internal error (ValueError: Key backend: 'bogus' is not a valid value …)" without its
    picture (a study: after every run, without its summary). irring draws its charts on its
    own Agg canvas and opens no window, so the variable has nothing to choose for it."""
    done = _irring(["calibrate", "--scenario", "t_room", "--out", "c.yaml"], tmp_path,
                   MPLBACKEND="bogus")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "c.yaml").is_file() and (tmp_path / "c.png").is_file()


def test_a_terminal_that_cannot_show_unicode_gets_escapes_not_an_internal_error(tmp_path):
    """PYTHONIOENCODING=ascii (or latin-1, as a legacy locale gives): `irring geometry` and
    `irring run` ended in exit 70 "internal error (UnicodeEncodeError: 'ascii' codec can't
    encode character '\\u03a6' …)" at their first Φ or —, run after writing nothing."""
    for encoding in ("ascii", "latin-1"):
        geometry = _irring(["geometry", "--samples", "1000"], tmp_path,
                           PYTHONIOENCODING=encoding)
        assert geometry.returncode == 0, geometry.stderr
        assert b"\\u03a6" in geometry.stdout or b"\\u0394" in geometry.stdout
        run = _irring(["run", "t_room", "--out", "o", "--no-animation"], tmp_path,
                      PYTHONIOENCODING=encoding)
        assert run.returncode == 0, run.stderr
        assert b"t_room \\u2014 Paper's inverted-T room" in run.stdout
        assert (tmp_path / "o" / "map.png").is_file()


def test_csv_files_are_utf8_whatever_the_locale(tmp_path):
    """Under an ASCII locale (LC_ALL=C without Python's UTF-8 mode) a study of a design
    named 'anneau_é' and bench rooms of a room named 'café' ended in exit 70
    (UnicodeEncodeError) writing results.csv and rooms.csv, which were written in the
    locale's encoding; a Latin-1 locale would write a results.csv that --resume, reading
    UTF-8, refuses as 'edited or damaged'."""
    room = ONE_POSE_BOX.format(w=1400).replace("name: same", "name: café")
    (tmp_path / "salle.yaml").write_text(room, encoding="utf-8")
    (tmp_path / "st.yaml").write_text(
        "designs: [{sensors: 8, radius_mm: 120, sweep_half_angle_deg: 45, step_deg: 1.08, "
        "name: anneau_é}]\nscenarios: [salle.yaml]\nseeds: 1\n", encoding="utf-8")
    ascii_locale = dict(LC_ALL="C", PYTHONUTF8="0", PYTHONCOERCECLOCALE="0")
    study = _irring(["study", "st.yaml", "--out", "st", "--workers", "1"], tmp_path,
                    **ascii_locale)
    assert study.returncode == 0, study.stderr
    results = (tmp_path / "st" / "results.csv").read_text(encoding="utf-8")
    assert results.splitlines()[1].startswith("anneau_é,salle.yaml,")
    again = _irring(["study", "st.yaml", "--out", "st", "--workers", "1", "--resume"],
                    tmp_path, **ascii_locale)
    assert again.returncode == 0, again.stderr
    assert (tmp_path / "st" / "summary.csv").read_text(encoding="utf-8").splitlines()[1] \
        .startswith("anneau_é,")
    rooms = _irring(["bench", "rooms", "salle.yaml", "--out", "br"], tmp_path,
                    **ascii_locale)
    assert rooms.returncode == 0, rooms.stderr
    assert (tmp_path / "br" / "rooms.csv").read_text(encoding="utf-8").splitlines()[1] \
        .startswith("café,")


def test_replay_refuses_a_recorded_scenario_of_another_sensor(tmp_path, capsys):
    """t_room's recording with its scenario's sensor block made a GP2Y0A02 (1500 mm):
    replayed and scored as that sensor's map ("recall counts wall within 1318 mm (past it
    one GP2Y0A02 reading …)"), though every sweep says a GP2D12 read it. `irring run` and
    `irring drive` record the sensor their sweeps were read with, so only an edited or
    mixed-up file disagrees."""
    assert main(["run", "t_room", "--out", str(tmp_path / "t"), "--no-animation"]) == 0
    sweeps, meta = load_recording(tmp_path / "t" / "sweeps.npz")
    meta["scenario_yaml"] = meta["scenario_yaml"].replace(
        "model: gp2d12", "model: gp2y0a02").replace("max_range_mm: 624", "max_range_mm: 1500")
    other = save_recording(tmp_path / "other.npz", sweeps, meta)
    capsys.readouterr()
    assert main(["replay", str(other), "--out", str(tmp_path / "r"), "--no-animation"]) == 1
    assert capsys.readouterr().err == (
        f"irring replay: error: {other}: sweep 1 was read by a gp2d12 at 5 V, but the recorded "
        "scenario 't_room' says its ring reads a gp2y0a02 at 5 V; the scenario and the sweeps "
        "do not belong together\n")
    assert not (tmp_path / "r").exists()


def test_a_writable_out_in_a_folder_one_may_not_write_gets_its_outputs(tmp_path, capsys,
                                                                       monkeypatch):
    """`--out /media/me/usb` (a writable folder, or a mount point, in a folder the user may
    not write, as /media/me is for him; reproduced with a tmpfs mounted read-only and another
    mounted writable on it): run did all its work, then exit 4 "--out …: cannot write there:
    Read-only file system", though every output could be written into the folder itself."""
    from irring import outputs

    parent = tmp_path / "media"
    out = parent / "usb"
    out.mkdir(parents=True)
    (out / "notes.txt").write_text("mine")
    made = outputs._hidden_sibling

    def read_only_parent(path, *, folder):   # what mkdir/open beside `out` meets there
        if path.parent == parent:
            raise PermissionError(13, "Permission denied", str(path))
        return made(path, folder=folder)

    monkeypatch.setattr(outputs, "_hidden_sibling", read_only_parent)
    assert main(["run", "t_room", "--out", str(out), "--no-animation"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "map.pgm", "map.png", "map.yaml", "notes.txt", "sweeps.npz"]
    assert sorted(p.name for p in parent.iterdir()) == ["usb"]
    # run again: the previous set replaced file by file, nothing of the temporaries left
    assert main(["run", "t_room", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "map.pgm", "map.png", "map.yaml", "map_building.gif", "notes.txt", "sweeps.npz"]


def test_a_progress_file_whose_counts_no_reading_backs_is_refused(tmp_path):
    """A calibration progress file (calibrate --port … --resume FILE) whose step says counts
    1500 from 0 readings (repeats 0) was resumed and the count fitted as a reading; one with
    no count (null) from 4 readings likewise passed. A placement's count is the mean of the
    readings it counts: save_progress writes null exactly where repeats is 0."""
    import yaml

    from irring.estimation.calibration import (GuidedCalibration, RigReadings,
                                               load_progress, save_progress)

    guided = GuidedCalibration(read_sweep=None, sweeps=4)
    place = guided.placements[0]
    guided.done[0] = RigReadings(
        counts=np.array([1500.0, np.nan, 1480.0]), beam_angle_rad=np.radians([-1.0, 0.0, 1.0]),
        wall_distance_m=np.full(3, place.wall_distance_m), spread_counts=np.full(3, 2.0),
        repeats=np.array([4, 0, 3]), offset=np.full(3, place.purpose == "offset"))
    path = save_progress(tmp_path / "p.yaml", guided)
    assert load_progress(path).done[0][1].repeats.tolist() == [4, 0, 3]   # as written
    raw = yaml.safe_load(path.read_text())
    for step, counts, repeats, why in (
            (1, 1500.0, 0, "counts 1500 from 0 readings"),
            (0, None, 4, "no counts (null) from 4 readings")):
        edited = yaml.safe_load(path.read_text())
        edited["read"][0]["counts"][step] = counts
        edited["read"][0]["repeats"][step] = repeats
        bad = tmp_path / "bad.yaml"
        bad.write_text(yaml.safe_dump(edited))
        with pytest.raises(CalibrationError) as refused:
            load_progress(bad)
        assert str(refused.value) == (
            f"{bad}: read[0]: step {step + 1} says {why}; a step's counts are the mean of "
            "the readings its repeats count (null where none was read)")
    assert raw["read"][0]["counts"][1] is None


def test_scenarios_checks_every_file_it_is_given(tmp_path, capsys):
    """`irring scenarios good.yaml bowtie.yaml flat.yaml box_room` (checking a folder of
    rooms, as its --help offers): the first bad file ended the command, and neither the good
    file before it nor the files after it were listed or checked."""
    good = tmp_path / "good.yaml"
    good.write_text(ONE_POSE_BOX.format(w=1400))
    bowtie = tmp_path / "bowtie.yaml"
    bowtie.write_text(ONE_POSE_BOX.format(w=1400).replace(
        "[[0, 0], [1400, 0], [1400, 1500], [0, 1500]]", "[[0, 0], [1400, 1500], [1400, 0], "
        "[0, 1500]]"))
    flat = tmp_path / "flat.yaml"
    flat.write_text("name: flat\nroom: {outline_mm: [[0, 0], [1000, 0], [2000, 0]]}\n"
                    "robot: {poses: [{x_mm: 400, y_mm: 0}]}\n")
    assert main(["scenarios", str(good), str(bowtie), str(flat), "box_room"]) == 1
    out, err = capsys.readouterr()
    assert [line.split()[0] for line in out.splitlines()] == [str(good), "box_room"]
    assert err == (
        f"irring scenarios: error: {bowtie}: room.outline_mm: walls 0 and 2 cross: the outline "
        "must not intersect itself\n"
        f"irring scenarios: error: {flat}: room.outline_mm: all 3 corners lie on one line, so "
        "the outline encloses no room; list the corners of an area\n"
        "irring scenarios: 2 of 4 scenario(s) refused\n")


def test_one_kind_of_irring_file_given_for_another_is_named(tmp_path, capsys):
    """irring's YAML files given in each other's place: a calibration as the scenario said
    "irring_calibration: unknown key; allowed here: description, effects, …"; a scenario as
    --calibration "name: unknown key; allowed: adc_bits, curve, …"; the progress file that
    calibrate --port leaves as --calibration "irring_calibration_progress: unknown key"; a
    study as the scenario, a calibration as the study. Each key list was right and no help."""
    from irring.estimation.calibration import Calibration

    cal = Calibration.nominal("gp2d12", None, 12, 5.0).save(tmp_path / "cal.yaml")
    study = tmp_path / "st.yaml"
    study.write_text("designs: [rotating12]\nscenarios: [t_room]\nseeds: 1\n")
    progress = tmp_path / "progress.yaml"
    progress.write_text("irring_calibration_progress: 1\nsensor: 0\nread: []\n")
    room = str(resolve("box_room"))
    calibration = ("a calibration file (irring calibrate writes them; give it as "
                   "--calibration)")
    cases = [
        (["run", str(cal)], f"{cal}: {calibration}; expected a scenario file"),
        (["run", str(study)], f"{study}: a study file (irring study reads them); expected a "
                              "scenario file"),
        (["run", "t_room", "--calibration", room],
         f"{room}: a scenario file (irring run reads them); expected a calibration file"),
        (["run", "t_room", "--calibration", str(progress)],
         f"{progress}: a calibration progress file (give it to irring calibrate --port … "
         "--resume); expected a calibration file"),
        (["study", str(cal)], f"{cal}: {calibration}; expected a study file"),
        (["calibrate", "--port", str(tmp_path / "no-port"), "--resume", str(cal)],
         f"{cal}: {calibration}; expected a calibration progress file"),
    ]
    for argv, why in cases:
        assert main(argv + ["--out", str(tmp_path / "o" / "x.yaml")]) == 1, argv
        assert capsys.readouterr().err.endswith(f": error: {why}\n"), argv


def test_an_output_file_never_replaces_an_irring_input_of_another_kind(tmp_path, capsys):
    """A slip of the path: `calibrate --out my_room.yaml` (the user's scenario) replaced the
    scenario with a calibration; `run --mcap sweeps.npz` (another run's recording) and
    `--mcap st.yaml` (a study file) replaced them with MCAP bytes; each exit 0."""
    room = tmp_path / "my_room.yaml"
    room.write_text(ONE_POSE_BOX.format(w=1400))
    study = tmp_path / "st.yaml"
    study.write_text("designs: [rotating12]\nscenarios: [t_room]\nseeds: 1\n")
    assert main(["run", "t_room", "--out", str(tmp_path / "t"), "--no-animation"]) == 0
    recording = tmp_path / "t" / "sweeps.npz"
    before = {p: p.read_bytes() for p in (room, study, recording)}
    capsys.readouterr()
    scenario = "a scenario file (irring run reads them)"
    cases = [
        (["calibrate", "--scenario", "t_room", "--out", str(room)], room, "--out", scenario),
        (["run", "box_room", "--out", str(tmp_path / "b"), "--mcap", str(recording)],
         recording, "--mcap", "a zip archive, as a recording (sweeps.npz) is: `irring "
         "replay` reads those"),
        (["run", "box_room", "--out", str(tmp_path / "b"), "--mcap", str(study)], study,
         "--mcap", "a study file (irring study reads them)"),
    ]
    for argv, path, option, what in cases:
        assert main(argv) == 4, argv
        assert capsys.readouterr().err.endswith(
            f": error: {option} {path}: is {what}; writing there would replace it: name "
            "another file\n"), argv
        assert not (tmp_path / "b").exists()
    assert {p: p.read_bytes() for p in before} == before
    # a calibration may be written over one: the file is what it writes
    cal = tmp_path / "cal.yaml"
    assert main(["calibrate", "--scenario", "t_room", "--out", str(cal)]) == 0
    assert main(["calibrate", "--scenario", "t_room", "--out", str(cal), "--seed", "3"]) == 0
