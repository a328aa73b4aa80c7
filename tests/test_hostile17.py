"""Round seventeen of hostile input: each test names the input that broke and asserts what
happens now."""

from __future__ import annotations

import numpy as np
import pytest

from irring.hardware import SerialRing
from irring.hardware.emulator import Device

from test_serial_ring import HELLO, virtual_time  # noqa: F401 (fixture)


def test_a_calibration_file_cut_short_anywhere_is_refused_never_read_as_less(tmp_path):
    """A calibration file cut short (a copy that stopped, a disk that filled elsewhere)
    loaded whenever the cut fell in its θ table: with fewer rows, or with a number cut (b =
    -1 for -1.1754), and mapped unwarned (213 of this file's 1571 cuts). The table is
    written last and in one [...]: every cut is refused, or lost nothing (the last newline)."""
    from irring.errors import IrringError
    from irring.estimation.calibration import Calibration, load_calibration
    from irring.scenario import load_scenario

    path = Calibration.for_scene(load_scenario("t_room")).save(tmp_path / "cal.yaml")
    text = path.read_text()
    whole = load_calibration(text, is_text=True)[0]
    changed = []
    for cut in range(len(text)):
        try:
            cal = load_calibration(text[:cut], is_text=True)[0]
        except IrringError:
            continue
        if cal.to_yaml() != whole.to_yaml():   # every field, every row, to the digit
            changed.append(cut)
    assert changed == []
    cut = text[:text.index("b: ", text.index("theta_deg: 5.0")) + 5]   # 'b: -1'
    with pytest.raises(IrringError, match=r"^<recording's calibration>: line \d+: not valid "
                                          r"YAML: "):
        load_calibration(cut, is_text=True)


@pytest.mark.parametrize("edit, said", [
    (("resolution: 0.010000", "resolution: []"), "resolution: expected a number of metres > 0, "
                                                 "got []"),
    (("resolution: 0.010000", "resolution: .nan"), "resolution: expected a number of metres "
                                                   "> 0, got nan"),
    (("origin: [-0.105000, -0.105000, 0.000000]", "origin: 7"), "origin: expected [x, y, yaw], "
                                                                "got 7"),
    (("image: map.pgm", "image: 7"), "image: expected a file name, got 7"),
    (("image: map.pgm", "image: gone.pgm"), "image: gone.pgm: No such file or directory"),
    (("negate: 0", "negate: .inf"), "negate: expected 0 or 1, got inf"),
    (("free_thresh: 0.196", "free_thresh: {}"), "free_thresh: expected a number 0 … 1, got {}"),
])
def test_a_damaged_map_yaml_is_refused_naming_the_file_and_the_key(tmp_path, edit, said):
    """OccupancyGrid.from_pgm read a map.yaml's values as it found them: TypeError
    ('float() argument must be … not list', "'int' object is not subscriptable",
    "unsupported operand type(s) for /: 'PosixPath' and 'int'") or a NaN resolution."""
    from irring.maps.mapping import OccupancyGrid

    grid = OccupancyGrid((-0.105, -0.105), (7, 11), 0.01)
    _, yml = grid.to_pgm(tmp_path / "map.pgm")
    text = yml.read_text()
    assert edit[0] in text
    yml.write_text(text.replace(*edit))
    with pytest.raises(ValueError) as err:
        OccupancyGrid.from_pgm(yml)
    assert str(err.value) == f"{yml}: {said}"


@pytest.mark.parametrize("cut, said", [
    (7, "cut short in its header (magic, width, height and maxval, then the pixels)"),
    (35, "cut short in its header (magic, width, height and maxval, then the pixels)"),
    (None, "its width b'1x' is not a whole number ≥ 1"),
])
def test_a_damaged_map_pgm_header_is_refused_naming_the_file(tmp_path, cut, said):
    """A PGM cut in its comment or before its maxval: ValueError('subsection not found'),
    'invalid literal for int() with base 10: b'''."""
    from irring.maps.mapping import OccupancyGrid, read_pgm

    pgm, _ = OccupancyGrid((-0.105, -0.105), (7, 11), 0.01).to_pgm(tmp_path / "map.pgm")
    raw = pgm.read_bytes()
    pgm.write_bytes(raw[:cut] if cut is not None else raw.replace(b"\n11 7\n", b"\n1x 7\n"))
    with pytest.raises(ValueError) as err:
        read_pgm(pgm)
    assert str(err.value) == f"{pgm}: {said}"


@pytest.mark.parametrize("said", [b"\x00", b"ring firmware starting\r\n"])
def test_a_board_that_says_something_as_it_starts_is_greeted_until_it_answers(virtual_time,
                                                                              said):
    """The boot wait greets a board that restarts when its port opens while the line is
    silent; one that sent a stray byte as it reset (or a line as its firmware started, at
    65 ms) stopped the greeting: its handshake waited out the 2 s, with a timeout and a
    resent IRHLO on its link report, the Uno's trouble the wait was made for."""
    from test_serial_ring import ResettingBoard, StandInSource

    class Talking(ResettingBoard):
        def read(self, size: int = 1) -> bytes:
            if not getattr(self, "spoke", False) and \
                    virtual_time.monotonic() >= self.opened + 0.065:
                self.spoke = True
                return said
            return super().read(size)

    board = Talking(Device(StandInSource()))
    t0 = virtual_time.now
    ring = SerialRing(board, timeout_s=1.0, boot_s=2.0).open()
    assert virtual_time.now - t0 == pytest.approx(0.59, abs=0.03)
    assert (ring.stats.timeouts, ring.stats.resent_commands) == (0, 0)
    assert board.lost == [HELLO] * 2 and ring.info.nsensors == 12
