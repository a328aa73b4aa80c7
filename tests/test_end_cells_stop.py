"""A silent beam of a sensor that returns at any incidence stops only at cells holding an end
point (``MapperParams.stop_at_end_cells``; docs/mapping.md, "Where the ideal sensor still
maps worse"): exact hits 6 mm past a 25 mm cell's edge spread log-odds above
``no_return_stop`` into the cell in front of them, which no surface fills."""

from __future__ import annotations

import numpy as np

from irring import load_scenario, pipeline
from irring.core import Points, Reason
from irring.maps import mapping_numpy
from irring.maps.mapping import MapperParams, OccupancyGrid
from irring.maps.metrics import SCORE_KEYS
from irring.studies import compare, rooms

RES = 0.025


def leg_and_silent_beam() -> Points:
    """One step of four sensors: three exact readings heading +x whose end points lie 6 mm
    into column 10 (rows 10, 10, 10), and a silent beam heading +y up column 9, past them."""
    ox = np.array([[0.0125, 0.0125, 0.0125, 0.2375]])
    oy = np.array([[0.2555, 0.2625, 0.2695, 0.0125]])
    heading = np.array([[0.0, 0.0, 0.0, np.pi / 2]])
    d = np.array([[0.2435, 0.2435, 0.2435, np.nan]])
    valid = np.array([[True, True, True, False]])
    reason = np.where(valid, Reason.OK, Reason.NO_RETURN).astype(np.uint8)
    return Points(x=ox + d * np.cos(heading), y=oy + d * np.sin(heading), d=d,
                  theta=np.zeros((1, 4)), origin_x=ox, origin_y=oy, heading=heading,
                  sigma_m=np.where(valid, 0.001, np.nan), iterations=np.ones((1, 4), int),
                  valid=valid, reason=reason, max_range_m=0.45)


def test_a_hit_spread_into_the_cell_in_front_stops_no_silent_beam_of_an_exact_sensor():
    pts = leg_and_silent_beam()
    maps = {}
    for ends in (0.0, 1.0):
        g = OccupancyGrid((0.0, 0.0), (20, 16), RES, MapperParams(stop_at_end_cells=ends))
        g.insert(pts)
        maps[ends] = g
        oracle = mapping_numpy.add(np.zeros(g.shape), pts, g.origin_xy_m, RES, g.params,
                                   g.params.l_min, g.params.l_max)
        np.testing.assert_allclose(g.log_odds, oracle, rtol=0, atol=1e-6)
    before, after = maps[0.0], maps[1.0]
    # the cell in front of the end points holds none, but their spread lifts it over the stop
    assert before.end_cells[10, 10] == 1 and before.end_cells[10, 9] == 0
    assert before.log_odds[10, 9] > before.params.no_return_stop
    # any cell above the stop: the silent beam stops there, the 8 cells past it stay unknown
    assert np.all(before.log_odds[11:19, 9] == 0.0)
    # only end cells: it goes on to its max range (0.45 m: row 18) and passes them
    np.testing.assert_array_equal(after.log_odds[11:19, 9], after.params.l_no_return)
    assert after.log_odds[19, 9] == 0.0
    # in front of the leg, and the leg's own cell, it maps the same
    np.testing.assert_array_equal(after.log_odds[:, 10:], before.log_odds[:, 10:])


def test_a_silent_beam_still_stops_at_an_end_cell_of_an_earlier_sweep():
    """Two inserts: the second sweep's silent beam meets the first's end cell, over the stop."""
    pts = leg_and_silent_beam()
    first = Points(**{k: (v[:, :3] if isinstance(v, np.ndarray) else v)
                      for k, v in vars(pts).items()})
    beam = Points(**{k: (v[:, 3:] if isinstance(v, np.ndarray) else v)
                     for k, v in vars(pts).items()})
    beam = Points(**{**vars(beam), "origin_x": np.array([[0.2575]])})   # up column 10
    g = OccupancyGrid((0.0, 0.0), (20, 16), RES, MapperParams(stop_at_end_cells=1.0))
    g.insert(first)
    hit = g.log_odds[10, 10]
    g.insert(beam)
    assert g.log_odds[10, 10] == hit and np.all(g.log_odds[11:19, 10] == 0.0)
    np.testing.assert_array_equal(g.log_odds[1:10, 10], g.params.l_no_return)


def test_the_pipeline_reads_silence_so_only_for_a_calibration_without_theta():
    """End cells only for a θ-free calibration; its silent beams pass as valid ones do only
    where no sweep was read moving (a moving ring's beam points where it was a period ago)."""
    t_room = load_scenario("t_room")
    noisy = pipeline.scene_calibration(t_room)[0]
    exact = pipeline.scene_calibration(rooms.ideal(t_room))[0]
    assert not noisy.theta_free and exact.theta_free
    assert pipeline.mapper_params(noisy) == MapperParams()
    assert pipeline.mapper_params(None) == MapperParams()
    still = pipeline.mapper_params(exact)
    assert still.stop_at_end_cells == 1.0 and still.l_no_return == still.l_free == -1.5
    moving = load_scenario("t_room_moving")
    sweeps = pipeline.simulated(rooms.ideal(moving), seed=0, progress=False)[0].sweeps
    assert sweeps[0].reading_poses is not None
    calibration = pipeline.scene_calibration(rooms.ideal(moving))[0]
    assert pipeline.mapper_params(calibration, sweeps) == MapperParams(stop_at_end_cells=1.0)


def test_an_exact_sensors_silent_beam_takes_a_depth_past_a_corner_to_unknown():
    """The depth (1.25 cells) of an exact end point on an occluding edge, met by a silent beam
    of the same sweep: l_occ_min − 0.75 is still occupied, l_occ_min − 1.5 is not."""
    ox, oy = np.array([[0.0125, 0.2375]]), np.array([[0.2625, 0.0125]])
    heading = np.array([[0.0, np.pi / 2]])
    d = np.array([[0.2435, np.nan]])
    valid = np.array([[True, False]])
    pts = Points(x=ox + d * np.cos(heading), y=oy + d * np.sin(heading), d=d,
                 theta=np.zeros((1, 2)), origin_x=ox, origin_y=oy, heading=heading,
                 sigma_m=np.where(valid, 0.001, np.nan), iterations=np.ones((1, 2), int),
                 valid=valid, reason=np.where(valid, Reason.OK, Reason.NO_RETURN).astype(np.uint8),
                 max_range_m=0.45)
    # the end point's own beam seen alone: its depth reaches column 11 (row 10)
    alone = OccupancyGrid((0.0, 0.0), (20, 16), RES, MapperParams(stop_at_end_cells=1.0))
    alone.insert(Points(**{k: (v[:, :1] if isinstance(v, np.ndarray) else v)
                           for k, v in vars(pts).items()}))
    assert alone.log_odds[10, 11] == 0.0       # no neighbour step: no edge, no depth
    # as a sweep of one sensor: step 0 valid, step 1 silent, its beam up column 11
    steps = Points(**{k: (v.reshape(2, 1) if isinstance(v, np.ndarray) else v)
                      for k, v in vars(pts).items()})
    steps = Points(**{**vars(steps), "origin_x": np.array([[0.0125], [0.2875]])})
    maps = {}
    for l_nr in (-0.75, -1.5):
        g = OccupancyGrid((0.0, 0.0), (20, 16), RES,
                          MapperParams(stop_at_end_cells=1.0, l_no_return=l_nr))
        g.insert(steps)
        maps[l_nr] = g.log_odds[10, 11]
    assert maps[-0.75] > 0.62 > maps[-1.5] > -0.62       # occupied → unknown (map_server)


def test_compare_maps_an_ideal_scene_as_run_does():
    """compare, study and bench accuracy (accuracy.run_job) pick the mapper's numbers as
    ``irring run`` does: before, their θ-free maps cleared less (t_room coverage 0.923 against
    run's 0.930 for the same sweeps)."""
    ideal = rooms.ideal(load_scenario("t_room"))
    row = compare.run_scene(ideal, "rotating12", seed=3)
    sweeps = pipeline.simulated(ideal, seed=3, progress=False)[0].sweeps
    calibration = pipeline.scene_calibration(ideal)[0]
    run = pipeline.map_sweeps(sweeps, scenario=ideal, calibration=calibration, progress=False)
    assert run.grid.params.stop_at_end_cells == 1.0
    assert {k: row[k] for k in SCORE_KEYS} == {k: run.scores[k] for k in SCORE_KEYS}
