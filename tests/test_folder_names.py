"""Where a command writes without --out: one folder a name, never another name's.
safe_name made `room 🏠` and `room`, `room a` and `room_a`, `café` (NFC) and
`caf`, one folder, and the second run replaced the first's files, exit 0."""

from __future__ import annotations

import unicodedata

import pytest

from irring.cli import main
from irring.outputs import REPLAY_SUFFIX, folder_name
from irring.recording import load_recording
from irring.scenario import ScenarioError, loads

ROOM = """\
room: {{outline_mm: [[0, 0], [1900, 0], [1900, 700], [1200, 1300], [0, 1300]]}}
obstacles: [{{type: box, center_mm: [{x}, 250], size_mm: [200, 120]}}]
robot: {{poses: [{{x_mm: 700, y_mm: 500}}]}}
"""
NFC, NFD = unicodedata.normalize("NFC", "café"), unicodedata.normalize("NFD", "café")


def test_every_name_gets_a_folder_of_its_own():
    names = ["room", "room 🏠", "Room", "ROOM", "room a", "room_a", "room/a", NFC, "caf",
             "cafe", "lab-replay", "lab", "🏠", "scenario", "x" * 100, "x" * 101, "t_room"]
    folders = [folder_name(n) for n in names]
    assert folders[:4] == ["room", "room~4886013c", "Room~911ea89c", "ROOM~577fba0b"]
    assert folders[4:7] == ["room_a~0e762122", "room_a", "room_a~f1a6f1e5"]
    assert folders[7:10] == ["cafe~850f7dc4", "caf", "cafe"]
    assert folders[10:14] == ["lab-replay~a2e76dfa", "lab", "scenario~a1965d92", "scenario"]
    assert folders[-1] == "t_room" and len(folders[-3]) == len(folders[-2]) == 80
    # apart even where the file system is blind to case, and from every replay's folder
    assert len({f.lower() for f in folders}) == len(names)
    assert not {f.lower() for f in folders} & {(f + REPLAY_SUFFIX).lower() for f in folders}
    assert folder_name(NFD) == folder_name(NFC)   # one name, two Unicode forms


def run_note(folder, name):
    return (f"  note      {folder}/ is the folder of the scenario named {name!r}: a name of "
            "other than lower-case letters, digits and ._- is written with ~ and 8 hex digits "
            "of its SHA-256, so no other name's outputs replace it")


def test_two_runs_whose_names_made_one_folder_keep_both(tmp_path, monkeypatch, capsys):
    """`room 🏠` then `room` (another room): both went to out/room/, the second replacing
    the first's map and sweeps; each now has its folder, the first says why its is not
    its name."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "house.yaml").write_text('name: "room 🏠"\n' + ROOM.format(x=1500))
    (tmp_path / "plain.yaml").write_text("name: room\n" + ROOM.format(x=400))
    assert main(["run", "house.yaml", "--no-animation"]) == 0
    house = capsys.readouterr().out.splitlines()
    assert house[-2].startswith("  wrote     out/room~4886013c/: map.png")
    assert house[-1] == run_note("out/room~4886013c", "room 🏠")
    assert main(["run", "plain.yaml", "--no-animation"]) == 0
    assert capsys.readouterr().out.splitlines()[-1].startswith("  wrote     out/room/: map.png")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["room", "room~4886013c"]
    for folder, name in (("room~4886013c", "room 🏠"), ("room", "room")):
        assert load_recording(tmp_path / "out" / folder / "sweeps.npz")[1]["scenario"] == name


def test_replays_and_studies_of_two_names_keep_both(tmp_path, monkeypatch, capsys):
    """`my lab.npz` and `my_lab.npz` were replayed into one out/my_lab-replay/; a study
    file `my study.yaml` and `my_study.yaml` shared out/my_study/ (the second refused, or
    with --resume its rows beside the other's)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "plain.yaml").write_text("name: room\n" + ROOM.format(x=400))
    assert main(["run", "plain.yaml", "--no-animation", "--out", "rec"]) == 0
    (tmp_path / "my lab.npz").write_bytes((tmp_path / "rec" / "sweeps.npz").read_bytes())
    (tmp_path / "my_lab.npz").write_bytes((tmp_path / "rec" / "sweeps.npz").read_bytes())
    capsys.readouterr()
    assert main(["replay", "my lab.npz", "--no-animation"]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == (
        "  note      out/my_lab~e283ee3c-replay/ is the folder of the replay of 'my lab': a "
        "name of other than lower-case letters, digits and ._- is written with ~ and 8 hex "
        "digits of its SHA-256, so no other name's outputs replace it")
    assert main(["replay", "my_lab.npz", "--no-animation"]) == 0
    assert "note" not in capsys.readouterr().out
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        "my_lab-replay", "my_lab~e283ee3c-replay"]
    spec = "designs: [radial12]\nscenarios: [plain.yaml]\nseeds: 1\n"
    (tmp_path / "my study.yaml").write_text(spec)
    (tmp_path / "my_study.yaml").write_text(spec)
    assert main(["study", "my study.yaml", "--workers", "1"]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == (
        "  note         out/my_study~67549874/ is the folder of the study file 'my study': a "
        "name of other than lower-case letters, digits and ._- is written with ~ and 8 hex "
        "digits of its SHA-256, so no other name's outputs replace it")
    assert main(["study", "my_study.yaml", "--workers", "1"]) == 0
    for folder in ("my_study", "my_study~67549874"):
        assert (tmp_path / "out" / folder / "results.csv").read_text().count("\n") == 2


def test_compare_refuses_one_name_in_two_unicode_forms(tmp_path, monkeypatch):
    """`café` written composed (NFC) and decomposed (NFD) in two rooms: compare ran both and
    printed two rows 'café' told apart by nothing."""
    from irring.studies import compare

    monkeypatch.setattr(compare, "run_jobs", lambda *a, **k: pytest.fail("a run started"))
    a = loads(f"name: {NFC}\n" + ROOM.format(x=1500), "a.yaml")
    b = loads(f"name: {NFD}\n" + ROOM.format(x=400), "b.yaml")
    with pytest.raises(ScenarioError) as exc:
        compare.compare([a, b], ["rotating1"])
    assert str(exc.value) == (
        f"b.yaml: named {NFD!r}, as a.yaml is (in another Unicode form); the results name "
        "each scenario by its `name:`, so the two rooms would be merged into one; give them "
        "different names")


def test_view_draws_into_the_folder_of_its_scenarios_run(tmp_path, monkeypatch, capsys):
    """`irring view` without --out (no display) wrote out/room/view.png for `room 🏠`, into
    the run folder of `room`; it goes where `irring run` writes the same scenario."""
    from irring.simulation import view

    try:
        view.gl_backend()
    except RuntimeError as exc:     # a machine without an offscreen OpenGL
        pytest.skip(str(exc))
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    (tmp_path / "house.yaml").write_text('name: "room 🏠"\n' + ROOM.format(x=1500))
    assert main(["view", "house.yaml", "--size", "64x48"]) == 0
    said = capsys.readouterr().out.splitlines()
    assert said[0].startswith("wrote out/room~4886013c/view.png: room 🏠, pose 1")
    assert said[1] == run_note("out/room~4886013c", "room 🏠").replace("  note      ", "note: ")
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["room~4886013c"]
