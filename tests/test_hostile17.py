"""Round seventeen of hostile input: each test names the input that broke and asserts what
happens now."""

from __future__ import annotations

import numpy as np
import pytest

from irring.designs import PAPER_RING
from irring.hardware import SerialRing
from irring.hardware.emulator import Device, DevicePort

from _fake_source import FakeSource
from test_serial_ring import HELLO, PARK, STOP, SWEEP, virtual_time  # noqa: F401 (fixture)

TIMEOUT_S = 0.1


def _device() -> Device:
    return Device(FakeSource(lambda pose, steps, k: 1000 + 20 * np.asarray(steps)[:, None]
                             + 100 * np.arange(PAPER_RING.sensors)), realtime=True)


class _Board(DevicePort):
    """The emulated firmware on an in-process port, every byte the host wrote kept. After
    ``after`` IRSCN were read, ``event(device)`` happens and the read raises Ctrl-C once
    (``ctrl_c``)."""

    def __init__(self, device: Device, after: int, event, ctrl_c: bool = True):
        super().__init__(device)
        self.written: list[bytes] = []
        self.after, self.event, self.scans_read, self.ctrl_c = after, event, 0, ctrl_c

    def write(self, data_: bytes) -> int:
        self.written.append(bytes(data_))
        return super().write(data_)

    def read(self, size: int = 1) -> bytes:
        if self.event is not None and self.scans_read >= self.after:
            event, self.event = self.event, None
            event(self.device)
            if self.ctrl_c:
                raise KeyboardInterrupt
        out = super().read(size)
        self.scans_read += out.count(b"IRSCN")
        return out


def _reset(device: Device) -> None:
    """The board resets where the motor stands: the sweep is forgotten, no IRSCN has been
    sent since power-up (IRSTP gets IRDON -1), and that step is its step 0 now."""
    device._job, device._seq, device._position = None, -1, 0


def test_a_board_that_reset_in_the_sweep_ctrl_c_ended_is_not_said_to_be_back_at_step_0(
        virtual_time):
    """A board that reset in its sweep (a brown-out) went silent; the operator pressed
    Ctrl-C. close()'s IRSTP got IRDON -1 (none sent since power-up), its IRGTO,0 an IRPOS,0
    at once (the board's step 0 is where it woke, 32 steps from radial here), and close()
    said nothing: the next session would read every step off by where it woke."""
    port = _Board(_device(), after=3, event=_reset)
    ring = SerialRing(port, timeout_s=TIMEOUT_S).open()
    with pytest.raises(KeyboardInterrupt):
        ring.sweep()
    ring.close()
    assert port.written == [HELLO, SWEEP, STOP]   # no IRGTO,0: it would turn nowhere useful
    assert ring.park_failure == (
        "the ring on device://emulator was not turned back to step 0 at the end of the session "
        "(an IRSTP was answered IRDON -1, no IRSCN sent since it powered up, though 3 came "
        "this session: it rebooted, and its firmware took the step it woke at for step 0; it "
        "was last heard of at step -33). Its firmware takes the step it stands at when it "
        "starts for step 0, and an Arduino restarts each time its port is opened: turn the "
        "ring radial by hand (its step 0 is where it woke, so no IRGTO can), then reset the "
        "board, before the next session")


def test_a_board_that_reset_in_the_last_sweep_is_not_turned_to_where_it_woke(virtual_time):
    """Without re-sweeps (the API's default, drive --resweep 0) a board that reset in the
    last sweep of a session left it short, its IRSTP answered IRDON -1, and no IRSCN came
    after to tell by its clock: close() turned the ring 'back to step 0', where it woke."""
    def reset(device: Device) -> None:
        _reset(device)
        device._t0 = virtual_time.monotonic()   # its clock starts anew

    port = _Board(_device(), after=3, event=reset, ctrl_c=False)
    ring = SerialRing(port, timeout_s=TIMEOUT_S).open()
    sweep = ring.sweep()
    assert list(sweep.steps) == [-35, -34, -33] and len(sweep.missing_steps) == 68
    ring.close()
    assert port.written == [HELLO, SWEEP, STOP]
    assert ring.park_failure.startswith(
        "the ring on device://emulator was not turned back to step 0 at the end of the session "
        "(an IRSTP was answered IRDON -1, no IRSCN sent since it powered up, though 3 came "
        "this session: it rebooted, ")


def test_a_board_that_never_swept_may_answer_irstp_with_irdon_minus_1_and_is_turned_back(
        virtual_time):
    """IRDON -1 is a reboot only after IRSCN came: Ctrl-C before the sweep's first one."""
    port = _Board(_device(), after=0, event=None)
    ring = SerialRing(port, timeout_s=TIMEOUT_S).open()
    port.event = lambda device: None
    with pytest.raises(KeyboardInterrupt):
        ring.sweep()
    ring.close()
    assert port.written == [HELLO, SWEEP, STOP, PARK] and ring.park_failure is None



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


@pytest.mark.parametrize("theta", ["1e308", "-5.0", "90.0"])
def test_a_calibration_row_at_an_impossible_angle_is_named_without_a_numpy_warning(theta):
    """theta_deg: 1e308 in a calibration file: numpy's 'RuntimeWarning: overflow encountered
    in multiply' (with its source line) came before the error, which showed the row as inf
    (θ to radians and back)."""
    import warnings

    from irring.errors import IrringError
    from irring.estimation.calibration import Calibration, load_calibration
    from irring.scenario import load_scenario

    text = Calibration.for_scene(load_scenario("t_room")).to_yaml()
    assert "theta_deg: 5.0," in text
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(IrringError) as err:
            load_calibration(text.replace("theta_deg: 5.0,", f"theta_deg: {theta},"),
                             is_text=True)
    assert str(err.value) == (f"<recording's calibration>: curve[1].theta_deg: "
                              f"{float(theta)!r} is out of range; allowed 0 … 90 (below 90)")

