"""One source interface: SimRing, SerialRing and a fake all satisfy RingSource, and
``pipeline.acquire`` — the loop ``irring run`` and ``irring drive`` share — gets the same
map from the simulator as from the emulated device on a real pty."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from irring import pipeline
from irring.core import RingSource, SourceLost
from irring.estimation.calibration import scene_calibration
from irring.hardware import DeviceDisconnected, SerialRing
from irring.hardware.emulator import Device, Faults, PtyEmulator
from irring.scenario import load_scenario, loads
from irring.simulation.sim import SimRing

from _fake_source import FakeSource

README = Path(__file__).resolve().parents[1] / "README.md"


@pytest.fixture
def pty_link(tmp_path):
    """Serve a Device on a real pty (thread); returns its link path; stopped after."""
    started: list[PtyEmulator] = []

    def start(device: Device) -> str:
        link = tmp_path / f"tty{len(started)}"
        started.append(PtyEmulator(device, link=link).start_thread())
        return str(link)

    yield start
    for emu in started:
        emu.stop()


def test_simring_serialring_and_a_fake_are_ring_sources(t_room):
    assert isinstance(SimRing(t_room), RingSource)
    assert isinstance(SerialRing("loop://"), RingSource)
    assert isinstance(FakeSource(lambda *a: 0), RingSource)
    assert not isinstance(object(), RingSource)
    # a lost link is a lost source: acquire keeps what arrived from either
    assert issubclass(DeviceDisconnected, SourceLost)


def map_bytes(result: pipeline.MapRun, out: Path) -> dict[str, bytes]:
    paths = pipeline.write_outputs(result, out, animation=False, recording=False)
    return {name: Path(p).read_bytes() for name, p in paths.items()}


def acquire_and_map(source, scenario, out: Path) -> tuple[pipeline.Acquisition, dict]:
    """The acquisition code under test, the same whatever the source."""
    with source:
        got = pipeline.acquire(source, scenario.robot.poses, progress=False)
    result = pipeline.map_sweeps(got.sweeps, scenario=scenario,
                                 calibration=scene_calibration(scenario)[0],
                                 progress=False)
    return got, map_bytes(result, out)


def test_the_same_acquisition_maps_the_simulator_and_the_emulated_device_byte_for_byte(
        t_room, pty_link, tmp_path):
    """t_room's sensor has 12-bit quantisation, so the simulator's counts are the whole
    counts the device sends: every sweep and every map byte agree."""
    link = pty_link(Device(SimRing(t_room)))
    sim, sim_map = acquire_and_map(SimRing(t_room), t_room, tmp_path / "sim")
    dev, dev_map = acquire_and_map(SerialRing(link, timeout_s=2.0), t_room, tmp_path / "dev")
    assert dev.error is None and sim.error is None and dev.complete
    assert len(sim.sweeps) == len(dev.sweeps) == 4
    for s, d in zip(sim.sweeps, dev.sweeps):
        assert np.array_equal(s.counts, d.counts) and s.counts.dtype == d.counts.dtype
        assert np.array_equal(s.pose, d.pose) and np.array_equal(s.steps, d.steps)
        assert np.allclose(s.sensor_angles, d.sensor_angles, rtol=0, atol=1e-12)
    assert set(sim_map) == {"map_png", "pgm", "yaml"}
    assert sim_map == dev_map


def test_without_quantisation_the_device_sends_the_simulators_counts_rounded(pty_link,
                                                                            tmp_path):
    """A scene without the ``quantization`` effect has fractional counts, which no ADC can
    send: the device rounds them (half to even, like np.rint). So the device's map is the
    simulator's map of the rounded counts, byte for byte — and the counts differ by < 0.5."""
    text = Path(load_scenario("t_room_cylinder").source).read_text()
    text = text.replace("  quantization: {}\n", "")
    room = loads(text, source="t_room_cylinder without quantization")
    assert "quantization" not in room.effects and "noise" in room.effects
    link = pty_link(Device(SimRing(room)))
    sim, _ = acquire_and_map(SimRing(room), room, tmp_path / "sim")
    dev, dev_map = acquire_and_map(SerialRing(link, timeout_s=2.0), room, tmp_path / "dev")
    (s,), (d,) = sim.sweeps, dev.sweeps
    frac = s.counts - np.floor(s.counts)
    assert np.count_nonzero((frac > 0.01) & (frac < 0.99)) > 100  # really fractional
    assert np.array_equal(d.counts, np.rint(s.counts)) and np.abs(d.counts - s.counts).max() <= 0.5
    rounded = [dataclasses.replace(s, counts=np.rint(s.counts).astype(np.int64))]
    result = pipeline.map_sweeps(rounded, scenario=room,
                                 calibration=scene_calibration(room)[0], progress=False)
    assert map_bytes(result, tmp_path / "rounded") == dev_map


# --------------------------------------------------------------------------- a fake source


def test_acquire_sweeps_each_pose_in_order_with_the_steps_and_hooks_given():
    fake = FakeSource(lambda pose, steps, k: np.full((len(steps), 12), 7 + k), poses=2)
    poses = [(0.5, 0.45, 0.0), (1.21, 0.4, 0.3), (0.5, 0.45, 0.0)]
    steps = np.array([-3, -1, 4])
    seen = []
    got = pipeline.acquire(fake, poses, steps=steps, progress=False,
                           before=lambda k, pose: seen.append(("before", k, pose)),
                           after=lambda k, sweep, rep: seen.append(("after", k, sweep.pose[0])))
    assert [c[0] for c in fake.calls] == [(0.5, 0.45, 0.0), (1.21, 0.4, 0.3),
                                          (0.5, 0.45, 0.0)]
    assert all(c[1] == (-3, -1, 4) for c in fake.calls)
    assert [s[:2] for s in seen] == [("before", 0), ("after", 0), ("before", 1), ("after", 1),
                                     ("before", 2), ("after", 2)]
    assert seen[3][2] == 1.21 and seen[2][2] == poses[1]
    assert [int(s.counts[0, 0]) for s in got.sweeps] == [7, 7, 8]  # the 2nd visit of pose 0
    assert got.reports == [None] * 3 and got.error is None and got.complete
    assert fake.closed == 0  # acquire does not close what it did not open


def test_acquire_keeps_a_lost_sources_partial_sweep_and_stops_without_raising():
    fake = FakeSource(lambda pose, steps, k: np.ones((len(steps), 12)), missing=(2,))
    fake.lose_at, fake.lose_after = 2, 5
    after = []
    got = pipeline.acquire(fake, [(0.1, 0.2, 0.0), (0.3, 0.2, 0.0), (0.5, 0.2, 0.0)],
                           progress=False, after=lambda k, s, r: after.append(k))
    assert len(fake.calls) == 2 and after == [0]       # the third pose is never swept
    assert isinstance(got.error, SourceLost) and not got.complete
    first, partial = got.sweeps
    assert first.missing_steps == (2,) and len(first.steps) == 70
    assert list(partial.steps) == [-35, -34, -33, -32, -31]
    assert len(partial.missing_steps) == 66 and got.reports[-1] == "lost at 5"


def test_acquire_drops_a_lost_sweep_with_no_readings():
    fake = FakeSource(lambda pose, steps, k: np.ones((len(steps), 12)))
    fake.lose_at, fake.lose_after = 1, 0
    got = pipeline.acquire(fake, [(0.0, 0.0, 0.0)], progress=False)
    assert got.sweeps == [] and got.reports == [] and isinstance(got.error, SourceLost)


def test_acquire_hands_serialrings_sweep_reports_over_and_reports_a_pulled_cable(t_room,
                                                                                pty_link):
    # 1 IRINF + 72 sentences per full sweep: the cable goes 30 readings into pose 2
    link = pty_link(Device(SimRing(t_room), faults=Faults(disconnect_after=1 + 72 + 30)))
    with SerialRing(link, timeout_s=2.0) as ring:
        got = pipeline.acquire(ring, t_room.robot.poses, progress=False)
    assert isinstance(got.error, DeviceDisconnected)
    # every reading sent before the cut arrives (the emulator waits until the host has
    # read them before it hangs up: test_emulator's late reader)
    assert [len(s.steps) for s in got.sweeps] == [71, 30]
    assert list(got.sweeps[1].steps) == list(range(-35, -5))
    assert got.reports[0].message == "all 71 steps received; clean link"
    assert got.reports[1].received_steps == 30 and not got.reports[1].complete
    assert np.array_equal(got.sweeps[1].pose, [t_room.robot.poses[1].x_m,
                                               t_room.robot.poses[1].y_m,
                                               t_room.robot.poses[1].yaw_rad])


# --------------------------------------------------------------------------- SimRing's poses


def test_simring_reads_a_scenario_pose_by_index_or_by_coordinates_alike(t_room):
    a, b = SimRing(t_room), SimRing(t_room)
    p2 = t_room.robot.poses[2]
    for _ in range(2):  # the first and the second sweep there
        by_index, by_pose = a.sweep(2), b.sweep(p2)
        assert np.array_equal(by_index.counts, by_pose.counts)
        assert np.array_equal(by_pose.pose, [p2.x_m, p2.y_m, p2.yaw_rad])
    assert np.array_equal(SimRing(t_room).sweep((p2.x_m, p2.y_m, p2.yaw_rad)).counts,
                          SimRing(t_room).sweep(2).counts)


def test_simring_sweeps_a_pose_the_scenario_does_not_list_with_its_own_noise(t_room):
    p0 = t_room.robot.poses[0]
    off = (p0.x_m + 0.013, p0.y_m - 0.021, p0.yaw_rad + 0.1)
    sim = SimRing(t_room)
    first, again = sim.sweep(off), sim.sweep(off)
    assert np.allclose(first.pose, off) and np.array_equal(first.truth.origin,
                                                           again.truth.origin)
    assert not np.array_equal(first.counts, again.counts)           # a fresh draw each time
    assert np.array_equal(SimRing(t_room).sweep(off).counts, first.counts)  # reproducible
    # the beams start where the pose puts them: 13 mm / −21 mm and 0.1 rad off pose 0's
    at0 = SimRing(t_room).sweep(0).truth.origin[..., :2] - [p0.x_m, p0.y_m]
    c, s = np.cos(0.1), np.sin(0.1)
    turned = at0 @ np.array([[c, s], [-s, c]])
    assert np.allclose(first.truth.origin[..., :2] - off[:2], turned, atol=1e-9)


def test_simring_refuses_a_pose_that_is_not_one_and_a_pose_on_a_moving_scene(t_room):
    with pytest.raises(ValueError, match=r"a pose is \(x m, y m\[, yaw rad\]\).*got 'left'"):
        SimRing(t_room).sweep("left")
    moving = SimRing(load_scenario("t_room_moving"))
    with pytest.raises(ValueError, match=r"drives while it scans.*by index along its drive, "
                                         r"0 … 10"):
        moving.sweep((0.5, 0.45, 0.0))


# --------------------------------------------------------------------------- the README


def readme_block(marker: str) -> str:
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    (block,) = [b for b in blocks if marker in b]
    return block


def test_the_readmes_python_drives_the_simulator_and_the_ring_with_the_same_lines(
        t_room, pty_link, tmp_path, monkeypatch):
    """Run the README's example as written, with the emulator's pty for /dev/ttyUSB0."""
    code = readme_block('SerialRing("/dev/ttyUSB0"')
    link = pty_link(Device(SimRing(t_room)))
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    exec(compile(code.replace("/dev/ttyUSB0", link), "README.md", "exec"), ns)
    sim, real = ns["sim"], ns["real"]
    assert np.array_equal(sim.grid.log_odds, real.grid.log_odds)
    assert real.scores == sim.scores and real.scores["occupied_f1"] > 0.9
    assert (tmp_path / "out" / "real" / "map.pgm").read_bytes() == \
        (tmp_path / "out" / "sim" / "map.pgm").read_bytes()
