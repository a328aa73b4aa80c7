"""Recordings: every field of every sweep survives the .npz round trip bit for bit."""

from __future__ import annotations

import dataclasses
import json
import math
import zipfile

import numpy as np
import pytest

from irring import core
from irring.core import Sweep, Truth
from irring.errors import TooBig
from irring.recording import FORMAT, RecordingError, load_recording, save_recording
from irring.core import Ring


def make_sweep(rng, *, truth=True, moving=False, counts_dtype=np.float64, **kw) -> Sweep:
    S, N = 7, 5
    ring = Ring(sensors=N, radius_m=0.1 + rng.random() / 3, emitter_offset_m=0.0071234567,
                min_step=-3, max_step=3, motor_step_rad=math.radians(1.8) / 3)
    t = None
    if truth:
        d = rng.random((S, N))
        d[0, 0] = np.nan
        t = Truth(distance_m=d, incidence_rad=rng.random((S, N)),
                  hit_point=rng.random((S, N, 3)), origin=rng.random((S, N, 3)),
                  direction=rng.random((S, N, 3)),
                  geom_id=rng.integers(-1, 9, (S, N)).astype(np.int32),
                  reflectance=rng.random((S, N)))
    return Sweep(steps=np.arange(-3, 4), sensor_angles=rng.normal(size=(S, N)),
                 counts=(rng.random((S, N)) * (2 ** kw.get("adc_bits", 12) - 1)).astype(counts_dtype),
                 timestamps_s=np.cumsum(rng.random(S)), duration_s=0.1 + rng.random(),
                 pose=rng.normal(size=3), ring=ring, truth=t,
                 reading_poses=rng.normal(size=(S, N, 3)) if moving else None, **kw)


def assert_same(a: Sweep, b: Sweep) -> None:
    for f in dataclasses.fields(Sweep):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert isinstance(y, np.ndarray) and x.dtype == y.dtype and x.shape == y.shape, f.name
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), f.name
        elif isinstance(x, Truth):
            for tf in dataclasses.fields(Truth):
                u, v = getattr(x, tf.name), getattr(y, tf.name)
                assert u.dtype == v.dtype and np.array_equal(u, v, equal_nan=u.dtype.kind == "f")
        else:
            assert x == y and type(x) is type(y) or (x == y and isinstance(x, float)), f.name


def test_round_trip_is_lossless(tmp_path):
    rng = np.random.default_rng(11)
    sweeps = [make_sweep(rng), make_sweep(rng, truth=False, moving=True, source="serial",
                                          missing_steps=(2, 3), counts_dtype=np.uint16,
                                          sensor_model="gp2y0a02", adc_bits=10, samples=4,
                                          settle_s=0.0123456789)]
    # a grid holding the poses (a normal draw each: within ±5 m)
    meta = {"scenario": "x", "seed": 5, "grid": {"origin_xy_m": [-5.105, -5 - 1 / 3],
                                             "shape": [1000, 1100], "resolution_m": 0.01}}
    path = save_recording(tmp_path / "rec", sweeps, meta)
    assert path.suffix == ".npz"
    back, meta_back = load_recording(path)
    assert meta_back == meta
    assert len(back) == 2
    for a, b in zip(sweeps, back):
        assert_same(a, b)
    assert back[0].ring == sweeps[0].ring          # floats like 1.8°/3 exactly
    assert back[1].missing_steps == (2, 3) and back[1].truth is None


def test_file_is_compressed_and_holds_no_pickles(tmp_path):
    rng = np.random.default_rng(0)
    sweep = make_sweep(rng)
    sweep = dataclasses.replace(sweep, counts=np.zeros((7, 5)))
    path = save_recording(tmp_path / "rec.npz", [sweep] * 3, {})
    with zipfile.ZipFile(path) as z:
        info = z.getinfo("sweep000/counts.npy")
        assert info.compress_type == zipfile.ZIP_DEFLATED
        assert info.compress_size < info.file_size / 3
        assert json.loads(np.load(path)["sweep001/scalars"].item())["ring"]["sensors"] == 5
    with np.load(path, allow_pickle=False) as z:   # loads without pickle
        assert str(z["format"]) == FORMAT


def test_bad_files_give_clear_errors(tmp_path):
    with pytest.raises(RecordingError, match="no such recording"):
        load_recording(tmp_path / "missing.npz")
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip")
    with pytest.raises(RecordingError, match="not an irring recording"):
        load_recording(junk)
    other = tmp_path / "other.npz"
    np.savez(other, a=np.zeros(3))
    with pytest.raises(RecordingError, match="no 'format'"):
        load_recording(other)
    newer = tmp_path / "newer.npz"
    np.savez(newer, format=np.array("irring-recording/99"), meta=np.array("{}"))
    with pytest.raises(RecordingError, match="irring-recording/99"):
        load_recording(newer)


def test_simulated_sweep_round_trips(tmp_path):
    """A real SimRing sweep (truth included) comes back identical."""
    pytest.importorskip("mujoco")
    from irring.scenario import load_scenario
    from irring.simulation.sim import SimRing

    sweep = SimRing(load_scenario("t_room_cylinder")).sweep(0)
    back, _ = load_recording(save_recording(tmp_path / "s.npz", [sweep]))
    assert_same(sweep, back[0])


def test_a_recording_too_big_to_replay_is_refused_before_its_arrays_are_read(tmp_path):
    # 1.2 MB on disk: one sweep of 100 000 steps × 72 sensors, all the same count; replaying
    # it filled 5.5 GB before running out under an 8 GB limit
    ring = core.Ring(sensors=72, radius_m=0.15, motor_step_rad=math.radians(0.01), gear=0.01,
                     min_step=-50000, max_step=49999, emitter_offset_m=0.007,
                     sensor_height_m=0.1, joint_limit_rad=0.6)
    steps = np.arange(-50000, 50000)
    sweep = core.Sweep(steps=steps, sensor_angles=core.sensor_angles_for_steps(ring, steps),
                       counts=np.full((len(steps), 72), 2000, dtype=np.int16),
                       timestamps_s=np.arange(len(steps)) * 0.04, duration_s=4000.0,
                       pose=np.array([0.5, 0.4, 0.0]), ring=ring)
    path = save_recording(tmp_path / "big.npz", [sweep])
    with pytest.raises(TooBig) as caught:
        load_recording(path)
    message = str(caught.value)
    assert str(path) in message
    assert "1 sweeps, 7,200,000 readings (the largest sweep 100,000 steps × 72 sensors)" in message
    assert "about 23.8 GB" in message and "more than the 2 GB" in message


def test_a_recording_driven_over_protocol_v1_by_the_previous_irring_still_loads(tmp_path,
                                                                               capsys):
    """tests/data/drive_protocol_v1.npz: the sweep `irring drive` kept from a v1 emulator
    (t_room, pose 1) before protocol v2. A recording holds decoded sweeps, never wire
    frames, so the protocol change leaves its format alone: it loads, replays, and what
    this irring writes from it has the same members, dtypes and values."""
    from pathlib import Path

    from irring.cli import main

    old = Path(__file__).parent / "data" / "drive_protocol_v1.npz"
    sweeps, meta = load_recording(old)
    (sweep,) = sweeps
    assert sweep.steps.tolist() == list(range(-35, 36)) and sweep.missing_steps == ()
    assert sweep.counts.shape == (71, 12) and sweep.counts.dtype.kind == "i"
    assert 0 < sweep.counts.min() and sweep.counts.max() < 4096
    assert sorted(meta) == ["calibration_yaml", "scenario_yaml"]
    again = save_recording(tmp_path / "again.npz", sweeps, meta)
    with zipfile.ZipFile(old) as a, zipfile.ZipFile(again) as b:
        assert a.namelist() == b.namelist()
    with np.load(old) as a, np.load(again) as b:
        for name in a.files:
            assert a[name].dtype == b[name].dtype and np.array_equal(a[name], b[name]), name
    assert main(["replay", str(old), "--out", str(tmp_path / "replay"), "--no-animation",
                 "--json"]) == 0
    replayed = json.loads(capsys.readouterr().out)
    assert replayed["readings"]["total"] == 71 * 12 and replayed["readings"]["valid"] > 500
    assert (tmp_path / "replay" / "map.pgm").exists()


def test_a_recording_whose_rows_are_out_of_step_order_maps_as_the_ordered_one(tmp_path):
    """Rows shuffled within each sweep (a hand-made recording, a RingSource of one's own
    listing steps as they arrived): the estimate sorts by step, but the mapper takes a
    reading's neighbours from the rows beside it, so t_room's map differed in 519 cells.
    A sweep whose steps neither rise nor fall is mapped in rising step order."""
    from irring import pipeline
    from irring.scenario import load_scenario

    sc = load_scenario("t_room")
    run = pipeline.run(sc, progress=False, score=False)
    rng = np.random.default_rng(1)
    shuffled = []
    for sweep in run.sweeps:
        order = rng.permutation(len(sweep.steps))
        shuffled.append(dataclasses.replace(
            sweep, steps=sweep.steps[order], sensor_angles=sweep.sensor_angles[order],
            counts=sweep.counts[order], timestamps_s=sweep.timestamps_s[order],
            truth=Truth(**{f.name: getattr(sweep.truth, f.name)[order]
                           for f in dataclasses.fields(Truth)})))
    save_recording(tmp_path / "shuffled.npz", shuffled)
    replayed, _ = load_recording(tmp_path / "shuffled.npz")
    again = pipeline.map_sweeps(replayed, scenario=sc, progress=False)
    ordered = pipeline.map_sweeps(run.sweeps, scenario=sc, progress=False)
    assert np.array_equal(again.grid.log_odds, ordered.grid.log_odds)
    assert again.scores == ordered.scores
    assert [s.steps.tolist() for s in again.sweeps] == [list(range(-35, 36))] * 4
    # a sweep falling step by step (the ring turning back) is kept as it is
    falling = dataclasses.replace(run.sweeps[0], steps=run.sweeps[0].steps[::-1])
    assert core.in_turn_order(falling) is falling
