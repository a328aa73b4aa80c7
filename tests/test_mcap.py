"""`--mcap`: a run as ROS 2 messages in MCAP, read back with the mcap reader: one point cloud
and one transform per sweep, the map, the true outline — the numbers the run holds."""

from __future__ import annotations

import dataclasses
import math
import os
import re

import numpy as np
import pytest

pytest.importorskip("mujoco")
pytest.importorskip("mcap_ros2")

from mcap.reader import make_reader  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402

from irring import pipeline  # noqa: E402
from irring.cli import main  # noqa: E402
from irring.errors import OutputError  # noqa: E402
from irring.recording import load_recording  # noqa: E402
from irring.scenario import load_scenario  # noqa: E402
from irring.safe_yaml import MCAP_MAGIC  # noqa: E402


def _messages(path):
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        out = {}
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            out.setdefault(channel.topic, []).append((schema.name, message, decoded))
    return summary, out


def test_run_writes_one_message_per_sweep_the_map_and_the_truth(tmp_path):
    out = tmp_path / "room"
    assert main(["run", "t_room_three_cylinders", "--out", str(out), "--no-animation",
                 "--mcap", str(tmp_path / "run.mcap")]) == 0
    summary, msgs = _messages(tmp_path / "run.mcap")
    assert summary.statistics.message_count == 4 + 4 + 1 + 1 + 3
    sweeps, _ = load_recording(out / "sweeps.npz")
    run = pipeline.replay(out / "sweeps.npz", progress=False)

    clouds = msgs["/irring/points"]
    assert len(clouds) == len(sweeps) == 4
    t = 0
    for (schema, message, cloud), sweep, points in zip(clouds, sweeps, run.points):
        assert schema == "sensor_msgs/msg/PointCloud2" and cloud.header.frame_id == "map"
        t += round(sweep.duration_s * 1e9)        # stamped when the real ring would finish
        assert message.log_time == t == cloud.header.stamp.sec * 10**9 + cloud.header.stamp.nanosec
        xyz = np.frombuffer(bytes(cloud.data), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                                                      ("range", "<f4")])
        assert cloud.width == xyz.size == np.count_nonzero(points.valid)
        assert [f.name for f in cloud.fields] == ["x", "y", "z", "range"]
        np.testing.assert_allclose(xyz["x"], points.x[points.valid], atol=1e-6)
        np.testing.assert_allclose(xyz["y"], points.y[points.valid], atol=1e-6)

    tfs = msgs["/tf"]
    assert len(tfs) == 4 and tfs[0][0] == "tf2_msgs/msg/TFMessage"
    for (_, _, tf), sweep in zip(tfs, sweeps):
        (tr,) = tf.transforms
        assert (tr.header.frame_id, tr.child_frame_id) == ("map", "base_link")
        x, y, yaw = sweep.pose
        assert (tr.transform.translation.x, tr.transform.translation.y) == pytest.approx((x, y))
        assert 2 * math.atan2(tr.transform.rotation.z, tr.transform.rotation.w) == \
            pytest.approx(yaw, abs=1e-12)

    ((schema, _, grid),) = msgs["/map"]
    ny, nx = run.grid.shape
    assert schema == "nav_msgs/msg/OccupancyGrid" and (grid.info.width, grid.info.height) == (nx, ny)
    assert grid.info.resolution == pytest.approx(run.grid.resolution_m)
    assert (grid.info.origin.position.x, grid.info.origin.position.y) == \
        pytest.approx(tuple(run.grid.origin_xy_m))
    cells = np.array(grid.data, np.int8).reshape(ny, nx)
    classes = run.grid.classify()
    # map_server's thresholds (occupied above 0.65, free below 0.196), in whole percent
    assert np.all(cells[classes == 1] >= 65) and np.all((cells[classes == 0] >= 0) &
                                                        (cells[classes == 0] <= 20))
    assert np.all(cells[run.grid.log_odds == 0] == -1)

    ((_, _, outline),) = msgs["/truth/outline"]
    room = run.scenario.room.outline_m
    np.testing.assert_allclose([(p.x, p.y) for p in outline.polygon.points], room, atol=1e-6)
    obstacles = msgs["/truth/obstacles"]
    assert len(obstacles) == len(run.scenario.obstacles) == 3
    ob = run.scenario.obstacles[0]
    pts = np.array([(p.x, p.y) for p in obstacles[0][2].polygon.points])
    np.testing.assert_allclose(np.hypot(*(pts - ob.center_m).T), ob.radius_m, rtol=1e-5)


def test_a_failed_mcap_write_leaves_no_partial_file(tmp_path, monkeypatch):
    """The MCAP is written beside its place and renamed in when whole: a failure after half
    the messages leaves the earlier file byte for byte, and no temporary behind."""
    from irring.maps import mcap_export

    run = pipeline.run(load_scenario("t_room"), progress=False)
    target = tmp_path / "run.mcap"
    earlier = MCAP_MAGIC + b"an earlier run's file"   # an MCAP replaces only an MCAP
    target.write_bytes(earlier)
    real, calls = mcap_export.point_cloud, []

    def failing(points, t):
        calls.append(t)
        if len(calls) == 2:       # the first sweep's messages are already in the file
            raise OSError(28, "No space left on device")
        return real(points, t)

    monkeypatch.setattr(mcap_export, "point_cloud", failing)
    with pytest.raises(OutputError, match=f"^{target}: No space left on device$"):
        mcap_export.write_mcap(run, target)
    assert target.read_bytes() == earlier
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.mcap"]

    monkeypatch.setattr(mcap_export, "point_cloud", real)
    mcap_export.write_mcap(run, tmp_path / "new.mcap")
    summary, msgs = _messages(tmp_path / "new.mcap")
    assert len(msgs["/irring/points"]) == 4 and len(msgs["/map"]) == 1
    assert (tmp_path / "new.mcap").stat().st_mode & 0o777 == 0o666 & ~_umask()


def _files(folder) -> dict[str, bytes]:
    """Every file below ``folder`` (hidden temporaries too) and its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.mark.parametrize("inside", [False, True], ids=["beside --out", "--out/map.mcap"])
def test_ctrl_c_while_the_mcap_is_written_leaves_the_set_and_the_mcap_as_they_were(
        tmp_path, monkeypatch, inside):
    """The MCAP was written after the set was committed: Ctrl-C in its 0.16 s left the new
    set beside an earlier run's MCAP (with --mcap in --out, the new set without any)."""
    from irring.maps import mcap_export

    scenario = load_scenario("t_room")
    out = tmp_path / "o"
    mcap = out / "map.mcap" if inside else tmp_path / "run.mcap"
    pipeline.write_outputs(pipeline.run(scenario, seed=1, progress=False), out,
                           animation=False, mcap=mcap)
    before = _files(tmp_path)
    assert {"o/map.pgm", "o/sweeps.npz"} <= set(before) and mcap.exists()
    real, calls = mcap_export.point_cloud, []

    def interrupted(points, t):
        calls.append(t)
        if len(calls) == 2:       # Ctrl-C with half the messages written
            raise KeyboardInterrupt
        return real(points, t)

    other = pipeline.run(scenario, seed=2, progress=False)
    monkeypatch.setattr(mcap_export, "point_cloud", interrupted)
    with pytest.raises(KeyboardInterrupt):
        pipeline.write_outputs(other, out, animation=False, mcap=mcap)
    assert _files(tmp_path) == before     # no file changed, no temporary left
    monkeypatch.setattr(mcap_export, "point_cloud", real)
    pipeline.write_outputs(other, out, animation=False, mcap=mcap)
    after = _files(tmp_path)
    assert set(after) == set(before)
    assert all(after[name] != before[name] for name in ("o/sweeps.npz", "o/map.pgm"))
    assert after[str(mcap.relative_to(tmp_path))] != before[str(mcap.relative_to(tmp_path))]


def test_an_mcap_that_cannot_be_written_is_an_output_error_naming_it(tmp_path, capsys):
    """--mcap below a file: exit 4 (an output), one line naming the option and the file in
    the way, before the run (it was exit 1 with mkdir's bare 'File exists', then after the
    run); written from code, the path and the file in the way. A missing folder is made."""
    from irring.maps import mcap_export

    (tmp_path / "taken").write_text("keep")
    bad = tmp_path / "taken" / "run.mcap"
    argv = ["run", "t_room_three_cylinders", "--out", str(tmp_path / "room"), "--no-animation"]
    assert main(argv + ["--mcap", str(bad)]) == 4
    err = capsys.readouterr().err
    assert err == (f"irring run: error: --mcap {tmp_path / 'taken'}: is a file; expected a "
                   "folder for the outputs\n")
    assert not (tmp_path / "room").exists()   # refused before the run
    assert main(argv) == 0
    run = pipeline.replay(tmp_path / "room" / "sweeps.npz", progress=False)
    with pytest.raises(OutputError, match=re.escape(
            f"{bad}: {tmp_path / 'taken'} is a file, so the folder cannot be made")):
        mcap_export.write_mcap(run, bad)
    made = tmp_path / "new" / "deeper" / "run.mcap"
    assert mcap_export.write_mcap(run, made) == made and made.stat().st_size > 0


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_sweep_times_past_ros_time_are_an_output_error_not_an_internal_one(tmp_path, capsys):
    """A recording of 216 sweeps of 9.99e6 s each (every one within the loader's 10⁷ s) adds
    up past ROS 2's int32 seconds: replay --mcap ended in exit 70 (struct.error)."""
    from irring import core
    from irring.recording import save_recording

    ring = core.Ring(sensors=3, min_step=0, max_step=1)
    sweep = core.Sweep(steps=np.array([0, 1]), sensor_angles=np.zeros((2, 3)),
                       counts=np.full((2, 3), 1500), timestamps_s=np.array([0.0, 0.04]),
                       duration_s=9.99e6, pose=np.array([0.4, 0.3, 0.2]), ring=ring)
    # each at its own pose: one sweep saved 216 times is refused as copies
    rec = save_recording(tmp_path / "long.npz", [dataclasses.replace(
        sweep, pose=sweep.pose + [0.001 * k, 0.0, 0.0]) for k in range(216)])
    mcap = tmp_path / "long.mcap"
    code = main(["replay", str(rec), "--out", str(tmp_path / "o"), "--no-animation",
                 "--mcap", str(mcap)])
    err = capsys.readouterr().err
    assert code == 4, err
    assert (f"{mcap}: the sweeps' hardware time adds up to 2157840000 s, past the ROS 2 time "
            "stamp's 2147483647 s (68 years); MCAP not written") in err
    assert not mcap.exists() and (tmp_path / "o" / "sweeps.npz").exists()
