"""An animation's frames in work linear in the run (mapping.RunSilences): each frame is, bit
for bit, what OccupancyGrid.insert_run makes of the sweeps so far, and a frame walks again
only the sweeps whose silent beams the new returns can stop elsewhere."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from irring import pipeline
from irring.maps import mapping
from irring.maps.mapping import MapperParams, OccupancyGrid, RunSilences, returns_of
from irring.scenario import loads

# A room of our own, 3.1 × 1.7 m with a post and a turned box, scanned at nine poses along
# a path that comes back past its start (so later returns stop earlier silent beams)
ROOM = """\
name: silent_walk
seed: 23
room:
  outline_mm: [[0, 0], [3140, 0], [3140, 1730], [1920, 1730], [1920, 1210], [0, 1210]]
obstacles:
  - {type: cylinder, center_mm: [1370, 610], radius_mm: 45}
  - {type: box, center_mm: [2410, 1420], size_mm: [230, 140], yaw_deg: 21}
robot:
  poses:
    - {x_mm: 420, y_mm: 380}
    - {x_mm: 960, y_mm: 840, yaw_deg: 12}
    - {x_mm: 1710, y_mm: 300}
    - {x_mm: 2480, y_mm: 520, yaw_deg: -35}
    - {x_mm: 2870, y_mm: 760}
    - {x_mm: 2230, y_mm: 930, yaw_deg: 80}
    - {x_mm: 1530, y_mm: 980}
    - {x_mm: 700, y_mm: 910}
    - {x_mm: 530, y_mm: 330, yaw_deg: -4}
effects: [incidence, noise, quantization]
"""


@pytest.fixture(scope="module")
def walk():
    return pipeline.run(loads(ROOM), progress=False, score=False)


def _frames(run, params=None, batches=None):
    """(RunSilences' frames, insert_run's) after each batch: insert_run's second part (every
    silent beam so far, in one insert) over the returns of the sweeps so far, each placed as
    the whole run places it (pipeline.building_frames; the last frame is insert_run's map)."""
    batches = run.points if batches is None else batches
    returns = OccupancyGrid(run.grid.origin_xy_m, run.grid.shape, run.grid.resolution_m,
                            params or run.grid.params)
    silences = RunSilences(returns, batches)
    placed = returns.placed_readings(batches)
    ours, theirs = [], []
    for k, p in enumerate(placed):
        returns.insert(returns_of(p), placed=True)
        ours.append(silences.log_odds(returns, k + 1).copy())
        whole = returns.empty_like()
        for q in placed[:k + 1]:
            whole.insert(returns_of(q), placed=True)
        for q in mapping.silences_of_run(batches[:k + 1]):
            whole.insert(q)
        theirs.append(whole.log_odds)
    whole = returns.empty_like()
    whole.insert_run(batches)
    np.testing.assert_array_equal(_bits(theirs[-1]), _bits(whole.log_odds))
    return ours, theirs, silences


def _bits(a):
    return np.asarray(a, float).view(np.int64)


@pytest.mark.parametrize("params", [None, MapperParams(no_return_stop=-0.3),
                                    MapperParams(no_return_stop=float("inf")),
                                    MapperParams(no_return_stop=0.4, l_no_return=-0.3),
                                    MapperParams(stop_at_end_cells=1.0)])
def test_every_frame_is_insert_run_of_the_sweeps_so_far_as_the_run_places_them(walk, params, monkeypatch):
    monkeypatch.setattr(RunSilences, "RECOUNT_COST", 0.0)     # never walk them all together
    ours, theirs, silences = _frames(walk, params)
    assert silences._incremental
    for a, b in zip(ours, theirs):
        np.testing.assert_array_equal(_bits(a), _bits(b))
    assert np.count_nonzero(ours[-1] < 0) > 5000


def test_a_sweep_is_walked_again_only_where_new_returns_stop_its_beams(walk, monkeypatch):
    monkeypatch.setattr(RunSilences, "RECOUNT_COST", 0.0)
    walked = []
    recount = RunSilences._recount
    monkeypatch.setattr(RunSilences, "_recount",
                        lambda self, j, counting: walked.append(j) or recount(self, j, counting))
    _frames(walk)
    # each sweep once when it comes, and again only when a later one changed its stops:
    # fewer than the 45 walks of inserting every sweep's silent beams at every frame
    assert sorted(set(walked)) == list(range(9)) and len(walked) < 45
    assert len(walked) > 9                       # (the path comes back: some are)


@pytest.mark.parametrize("limit", ["crowded", "memory"])
def test_crowded_or_long_runs_are_walked_together_as_insert_run_does(walk, monkeypatch, limit):
    if limit == "crowded":
        monkeypatch.setattr(RunSilences, "RECOUNT_COST", 1e9)
        monkeypatch.setattr(RunSilences, "HEAD_START", 0)
    else:        # three sweeps' kept passes (~0.13 MB each here) fill the budget
        monkeypatch.setattr(RunSilences, "RECOUNT_COST", 0.0)
        monkeypatch.setattr(RunSilences, "MAX_KEPT_BYTES", 300_000)
    switched = []
    recount = RunSilences._recount
    monkeypatch.setattr(RunSilences, "_recount", lambda self, j, counting: switched.append(
        len(switched)) or recount(self, j, counting))
    ours, theirs, silences = _frames(walk)
    assert not silences._incremental        # from the first frame, or the third
    assert len(switched) == (0 if limit == "crowded" else 3)   # (4 before silent beams were
    #                                       bounded beside their sensor's nearest return)
    for a, b in zip(ours, theirs):
        np.testing.assert_array_equal(_bits(a), _bits(b))


def test_a_sonar_cone_and_batches_of_other_ranges_map_as_insert_run(walk, monkeypatch):
    monkeypatch.setattr(RunSilences, "RECOUNT_COST", 0.0)
    cone = [dataclasses.replace(p, cone_half_angle_rad=0.21) for p in walk.points[:4]]
    params = MapperParams(cone_l_no_return=-0.35)
    ours, theirs, silences = _frames(walk, params, cone)
    assert silences._incremental
    for a, b in zip(ours, theirs):
        np.testing.assert_array_equal(_bits(a), _bits(b))
    mixed = [walk.points[0], dataclasses.replace(walk.points[1], max_range_m=0.47),
             walk.points[2]]
    ours, theirs, silences = _frames(walk, None, mixed)
    assert not silences._incremental
    for a, b in zip(ours, theirs):
        np.testing.assert_array_equal(_bits(a), _bits(b))


def test_the_animation_ends_on_the_runs_map(walk):
    frames = list(pipeline.building_frames(walk, 1))
    assert len(frames) == 10
    np.testing.assert_array_equal(frames[-1][0], walk.grid.classify())
    assert mapping.classify(walk.grid.log_odds).dtype == np.int8
