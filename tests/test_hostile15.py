"""Round fifteen of hostile input: each test names the input that broke and
asserts what happens now."""

from __future__ import annotations

import pytest

from irring.cli import main
from irring.studies import study

STUDY = "designs: [radial12]\nscenarios: [box_room]\nseeds: [1]\n"


@pytest.mark.parametrize("resume", [False, True])
@pytest.mark.parametrize("text, begins", [
    (b"my notes on the study, no newline at the end", "b'my notes on the study, no newline at the'"),
    (b'{"runs": 3, "by": "design"}', "b'{\"runs\": 3, \"by\": \"design\"}'"),
])
def test_a_study_never_replaces_a_file_that_is_not_its_results(tmp_path, capsys, resume, text,
                                                               begins):
    """A results.csv in --out without a newline (a one-line note, a picture) was taken for a
    header cut short by a kill: `irring study s.yaml --out DIR` (with or without --resume)
    replaced it with the study's rows, exit 0."""
    spec = tmp_path / "s.yaml"
    spec.write_text(STUDY)
    out = tmp_path / "o"
    out.mkdir()
    (out / "results.csv").write_bytes(text)
    argv = ["study", str(spec), "--out", str(out), "--workers", "1"] + ["--resume"] * resume
    assert main(argv) == 1
    assert capsys.readouterr().err == (
        f"irring study: error: {out / 'results.csv'}: is not the results.csv irring study "
        f"writes (it begins {begins}, not with its columns); choose another --out, or move "
        "the file away to start afresh\n")
    assert (out / "results.csv").read_bytes() == text


def test_a_header_cut_short_by_a_kill_is_still_written_afresh(tmp_path):
    spec = tmp_path / "s.yaml"
    spec.write_text(STUDY)
    out = tmp_path / "o"
    out.mkdir()
    (out / "results.csv").write_bytes(b"\xef\xbb\xbf" + ",".join(study.COLUMNS)[:30].encode())
    result = study.run_study(study.load_study(spec), out, resume=True)
    assert result["ran"] == 1 and len(study.read_results(out / "results.csv")) == 1


def test_view_out_replaces_only_a_picture_view_drew(tmp_path, capsys, monkeypatch):
    """`irring view t_room --out photo.png` (or a run's map.png) replaced the picture, exit 0
    (round 14's leftover). A FILE.png named by --out is replaced only if irring view drew it
    (its Software field) or it is empty; view.png in view's own places is replaced as before."""
    from PIL import Image

    monkeypatch.chdir(tmp_path)
    photo = tmp_path / "photo.png"
    Image.new("RGB", (20, 10), (200, 30, 40)).save(photo, format="PNG")
    before = photo.read_bytes()
    assert main(["view", "t_room", "--out", str(photo), "--size", "48x32"]) == 4
    assert capsys.readouterr().err == (
        f"irring view: error: --out {photo}: is a PNG picture, not a picture irring view drew; "
        "writing there would replace it (irring view replaces only a picture it drew, which "
        "names it in its PNG's Software field): name another file\n")
    assert photo.read_bytes() == before
    mine = tmp_path / "mine.png"
    mine.write_bytes(b"")
    for _ in range(2):   # empty, then its own picture again
        assert main(["view", "t_room", "--out", str(mine), "--size", "48x32"]) == 0
        with Image.open(mine) as im:
            assert im.info["Software"] == "irring view" and im.size == (48, 32)
    default = tmp_path / "out" / "t_room" / "view.png"
    default.parent.mkdir(parents=True)
    Image.new("RGB", (20, 10)).save(default, format="PNG")   # drawn before the marker
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", "t_room", "--size", "48x32"]) == 0
    with Image.open(default) as im:
        assert im.size == (48, 32)


@pytest.mark.parametrize("column, cell, allowed", [
    ("occupied_f1", "7.5", "a number 0 … 1 or empty (n/a)"),
    ("coverage", "-0.2", "a number 0 … 1 or empty (n/a)"),
    ("range_rmse_m", "-0.004", "a number ≥ 0"),
])
def test_a_resumed_score_outside_its_range_is_refused(tmp_path, capsys, column, cell, allowed):
    """results.csv edited by hand with an F1 of 7.5 was resumed and summarised as 'F1 occ
    4.245 ± 4.603', exit 0 (a text or a NaN there was already refused)."""
    spec = tmp_path / "s.yaml"
    spec.write_text(STUDY.replace("[1]", "[1, 2]"))
    out = tmp_path / "o"
    study.run_study(study.load_study(spec), out)
    rows = study.read_results(out / "results.csv")
    rows[0][column] = cell
    study._write_sorted(out / "results.csv", rows)
    before = (out / "results.csv").read_bytes()
    assert main(["study", str(spec), "--out", str(out), "--resume", "--workers", "1"]) == 1
    assert capsys.readouterr().err == (
        f"irring study: error: {out / 'results.csv'}: line 2, {column}: '{cell}' is not "
        f"allowed; {allowed}; the file was edited or damaged\n")
    assert (out / "results.csv").read_bytes() == before


@pytest.mark.parametrize("text, said", [
    ("name: x\nrobot: {poses: [{<<: {x_mm: 100}, y_mm: 450}]}\n",
     "line 2: YAML merge keys (<<) are not allowed; write the keys out"),
    ("name: !!python/object:os.system x\n",
     "line 1: YAML tags (tag:yaml.org,2002:python/object:os.system) are not allowed; write a "
     "plain value"),
])
def test_a_yaml_merge_key_or_tag_is_named_whole(tmp_path, capsys, text, said):
    """A merge key (<<) in a scenario said 'not valid YAML: could not determine a
    const...ag 'tag:yaml.org,2002:merge'', PyYAML's message cut short in the middle."""
    path = tmp_path / "m.yaml"
    path.write_text(text)
    assert main(["scenarios", str(path)]) == 1
    assert capsys.readouterr().err == f"irring scenarios: error: {path}: {said}\n"


def test_a_sensor_that_reads_0_counts_all_round_is_warned_of(tmp_path, capsys):
    """t_room's recording with sensor 3 at 0 counts in every reading (its wire cut, the
    sensor unplugged): mapped as no return, free to its reach through walls (F1 0.995 ->
    0.989, free accuracy 1.000 -> 0.998), exit 0, without a word (round 14's leftover).
    Mapped as before, and warned of."""
    from irring.recording import load_recording, save_recording

    assert main(["run", "t_room", "--out", str(tmp_path / "t"), "--no-animation"]) == 0
    capsys.readouterr()
    sweeps, meta = load_recording(tmp_path / "t" / "sweeps.npz")
    floor = min(int(s.counts.min()) for s in sweeps)
    for sweep in sweeps:
        sweep.counts[:, 3] = 0
    cut = save_recording(tmp_path / "cut.npz", sweeps, meta)
    assert main(["replay", str(cut), "--out", str(tmp_path / "r"), "--no-animation"]) == 0
    out = capsys.readouterr().out
    assert ("\n  warning   sensor 3 (of 0 … 11) read 0 counts at every one of its 284 readings, "
            "at 4 poses, where a powered sensor with nothing in range reads its no-return "
            f"level (the others never read below {floor}): a sensor unplugged or its wire cut "
            "reads so. Its readings are mapped as no return, free to the sensor's reach, walls "
            "or not; check the sensor's connector and its ADC channel\n") in out
    assert "F1 0.989" in out
