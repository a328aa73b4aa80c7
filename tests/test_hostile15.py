"""Round fifteen of hostile input (FINDINGS15.md): each test names the input that broke and
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
