"""Round twenty-two of hostile input: each test names the input that broke and asserts what
happens now."""

from __future__ import annotations

from irring.cli import main

ROOM = """\
name: vast
room:
  outline_mm: [[0, 0], [SIDE, 0], [SIDE, DEPTH], [0, DEPTH]]
robot:
  poses: [{x_mm: 500, y_mm: 450}]
"""


def test_a_room_too_big_for_the_coarsest_cells_is_not_told_to_use_coarser_ones(tmp_path,
                                                                                capsys):
    # 100 km square: the refusal said 'use coarser cells (map.resolution_mm ≥ 20001)', which the
    # schema refuses (1 … 500 mm); a 6 km corridor still fits 500 mm cells and keeps that advice
    for side, depth, said in [
            (1e8, 1e8, "are mapped: use a smaller room (its outline spans 100,000 × 100,000 m; "
                       "room.outline_m is read in metres, outline_mm in millimetres); even the "
                       "coarsest cells (map.resolution_mm 500) would be 200,003 × 200,003"),
            (6e6, 900, "are mapped: use coarser cells (map.resolution_mm ≥ 17) or a smaller room "
                  "(its outline spans 6,000 × 0.9 m;")]:
        (tmp_path / "vast.yaml").write_text(ROOM.replace("SIDE", f"{side:.0f}").replace(
            "DEPTH", f"{depth:.0f}"))
        status = main(["run", str(tmp_path / "vast.yaml"), "--out", str(tmp_path / "out")])
        err = capsys.readouterr().err.strip()
        assert (status, err.count("\n")) == (5, 0), err
        assert said in err
        assert not (tmp_path / "out").exists()
