"""Round fourteen of hostile input (FINDINGS14.md): each test names the input that broke and
asserts what happens now."""

from __future__ import annotations

import pytest

from irring.cli import main

pytest.importorskip("mcap_ros2")   # --mcap needs the mcap extra


def test_mcap_never_replaces_a_file_that_is_not_an_mcap(tmp_path, capsys):
    """`run box_room --mcap photo.png` (a slip of the path: the user's picture, or another
    run's map.png) replaced the picture with MCAP bytes, exit 0; so did any other file. An
    MCAP, or an empty file, is replaced as before."""
    photo = tmp_path / "photo.png"
    photo.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)))
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes\n")
    before = {p: p.read_bytes() for p in (photo, notes)}
    out = str(tmp_path / "b")
    for path, what in ((photo, "a PNG picture"), (notes, "a file")):
        assert main(["run", "box_room", "--out", out, "--no-animation", "--mcap",
                     str(path)]) == 4
        assert capsys.readouterr().err == (
            f"irring run: error: --mcap {path}: is {what}, not an MCAP; writing there would "
            "replace it (an MCAP replaces only an MCAP): name another file\n")
        assert not (tmp_path / "b").exists()
    assert {p: p.read_bytes() for p in before} == before
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    assert main(["run", "box_room", "--out", out, "--no-animation", "--mcap", str(empty)]) == 0
    mcap = empty.read_bytes()
    assert mcap.startswith(b"\x89MCAP0\r\n")
    assert main(["run", "box_room", "--out", out, "--no-animation", "--mcap", str(empty),
                 "--seed", "2"]) == 0
    assert empty.read_bytes() != mcap
