"""Readings on no line (issue 13, item 3): a wall seen at 60–70° gives a few readings too
short for a line; read at θ = 0 they lay 100–190 mm behind it. They take the slope of their
own sensor's neighbouring steps (arcs.local_incidence), or are INCIDENCE_UNKNOWN when
nothing decides θ and θ = 0 could read more than 100 mm long. Rooms of our own, asymmetric;
before this change they had 10, 5 and 6 valid readings more than 100 mm off over the three
seeds (worst 171, 187, 139 mm)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from _synthetic import make_sweep
from irring import pipeline
from irring.core import Reason, Ring
from irring.designs import PAPER_RING
from irring.estimation.estimate import Calibration, estimate, estimate_detail
from irring.scenario import loads
from irring.estimation.calibration import scene_calibration

NOMINAL = Calibration.nominal("gp2d12", PAPER_RING)
ONE = Ring(sensors=1, radius_m=0.0)   # a single sensor on its hinge

# fold-over on, poses as close to the walls as the housing allows (170 mm)
CLOSE_CORNER = """
name: fo_close_corner
seed: 41
room: {outline_mm: [[0, 0], [1370, 0], [1370, 1080], [0, 1080]]}
robot:
  poses:
    - {x_mm: 171, y_mm: 172, yaw_deg: 9}
    - {x_mm: 1196, y_mm: 173, yaw_deg: -4}
sensor: {model: gp2d12, max_range_mm: 624}
effects: [incidence, noise, quantization, foldover]
"""
CLOSE_PASSAGE = """
name: fo_close_passage
seed: 43
room: {outline_mm: [[0, 0], [1650, 0], [1650, 352], [0, 352]]}
robot:
  poses:
    - {x_mm: 430, y_mm: 176, yaw_deg: 3}
    - {x_mm: 1180, y_mm: 171, yaw_deg: -6}
sensor: {model: gp2d12, max_range_mm: 624}
effects: [incidence, noise, quantization, foldover]
"""
# two turned boxes whose faces some sensors see only at 60–70°
GRAZING_BOXES = """
name: grazing_box
seed: 45
room: {outline_mm: [[0, 0], [1900, 0], [1900, 1300], [0, 1300]]}
obstacles:
  - {type: box, center_mm: [1120, 720], size_mm: [380, 240], yaw_deg: 23}
  - {type: box, center_mm: [520, 980], size_mm: [300, 160], yaw_deg: -11}
robot:
  poses:
    - {x_mm: 700, y_mm: 470, yaw_deg: 5}
    - {x_mm: 1480, y_mm: 380, yaw_deg: -17}
    - {x_mm: 1000, y_mm: 1120, yaw_deg: 31}
sensor: {model: gp2d12, max_range_mm: 624}
effects: [incidence, noise, quantization]
"""


def runs_within_100_mm(sc):
    """The estimated sweeps of ``sc`` over its seed and the next two, each checked to have
    no valid end point more than 100 mm from the true hit; yields (seed, Points)."""
    for seed in range(sc.seed, sc.seed + 3):
        run = pipeline.run(sc, seed=seed, progress=False)
        for sw, p in zip(run.sweeps, run.points):
            hit = sw.truth.hit_point
            err = np.hypot(p.x - hit[..., 0], p.y - hit[..., 1])[p.valid]
            assert np.all(np.isfinite(err)) and err.max() <= 0.100, (seed, err.max())
            yield seed, p


# (328 and 1015 valid before the readings the judging pass read out of range were judged
# too: 58 and 110 of them, truly 82-101 mm away at the GP2D12's 90 mm peak, are undecided;
# the passage 884 -> 870 since a line decides "far" only where the reading's own far trace
# agrees: right readings past a line's last member whose own line is not anchored; 857 since
# a reading placed no better than 30 mm is left unplaced: foldover.FOLD_PLACED_SIGMA_M)
@pytest.mark.parametrize("text, min_valid", [(CLOSE_CORNER, 260), (CLOSE_PASSAGE, 850),
                                             (GRAZING_BOXES, 4300)])
def test_no_valid_reading_more_than_100_mm_off_and_none_outside_the_room(text, min_valid):
    sc = loads(text, source="<test>")
    (x0, y0), (x1, y1) = np.min(sc.room.outline_m, axis=0), np.max(sc.room.outline_m, axis=0)
    valid = 0
    for _, p in runs_within_100_mm(sc):
        v = p.valid
        valid += int(v.sum())
        outside = np.maximum.reduce([x0 - p.x[v], p.x[v] - x1, y0 - p.y[v], p.y[v] - y1])
        assert outside.max() <= 0.030     # end points within noise of the walls
    assert valid >= min_valid       # the readings are kept, not flagged away


# turned rooms, fold-over on, poses at the housing limit: a sensor meets a far wall near a
# corner at 60-66° in a few readings (3 at the sweep's edge; 6 among ambiguous ones) whose
# profile noise bent 2.2 SE away from the beam; kept as a post at θ = 0 they lay 106-166 mm
# long (3 readings in each room before the convex rule asked for a surer bend)
TURNED_31 = """
name: turned_31
seed: 9108
room: {outline_mm: [[0, 0], [1371.47, 824.06], [495.9, 2281.25], [-875.56, 1457.18]]}
robot:
  poses:
    - {x_mm: -70.43, y_mm: 447.67, yaw_deg: 77}
    - {x_mm: 1071.07, y_mm: 993.55, yaw_deg: 150}
    - {x_mm: -102.17, y_mm: 1723.32, yaw_deg: 12}
sensor: {model: gp2d12, max_range_mm: 624}
effects: [incidence, noise, quantization, foldover]
"""
TURNED_M8 = """
name: turned_m8
seed: 9109
room: {outline_mm: [[0, 0], [2277.62, -320.1], [2451.58, 917.74], [173.97, 1237.84]]}
robot:
  poses:
    - {x_mm: 204.73, y_mm: 233.78, yaw_deg: 10}
    - {x_mm: 2241.29, y_mm: 644.34, yaw_deg: 200}
    - {x_mm: 1338.6, y_mm: 902.28, yaw_deg: -30}
sensor: {model: gp2d12, max_range_mm: 624}
effects: [incidence, noise, quantization, foldover]
"""


# (692 and 510 valid before readings the judging pass read out of range were judged: 83 and 69
# of them, truly 82-100 mm away at the peak, 1-30 mm off on the far branch, are undecided;
# 52 and 27 more, 0-6 mm off, were decided far by a line 50-100 mm past where it is seen;
# 557 and 414 -> 521 and 395 since the own-trace rule: right readings past a line's last
# member whose own line is not anchored, or whose own line runs > 20° off, are undecided;
# 521 -> 507 since readings placed no better than 30 mm are left unplaced:
# foldover.FOLD_PLACED_SIGMA_M; TURNED_M8 391 -> 379 since a short line's direction error
# is in its far members' σ: 12 readings 1-47 mm off, 6 of them 20 mm or more; 379 -> 374
# since facets_reread's split with a piece of 3-5 members: 5 readings 6-37 mm off, 3 of them
# 20 mm or more)
@pytest.mark.parametrize("text, min_valid", [(TURNED_31, 500), (TURNED_M8, 370)])
def test_a_far_steep_wall_bent_by_noise_is_not_kept_as_a_post(text, min_valid):
    sc = loads(text, source="<test>")
    valid = sum(int(p.valid.sum()) for _, p in runs_within_100_mm(sc))
    assert valid >= min_valid       # the readings are kept, not flagged away


def _short_wall(length_m, distance_m, tilt_deg):
    """A wall segment centred ``distance_m`` ahead (3 cm to the left), its normal turned
    ``tilt_deg`` from the beam's axis."""
    n = math.radians(180.0 + tilt_deg)
    c = np.array([distance_m, 0.03])
    e = np.array([-math.sin(n), math.cos(n)])
    return (tuple(c - 0.5 * length_m * e), tuple(c + 0.5 * length_m * e))


@pytest.mark.parametrize("length, distance, tilt, n_valid", [
    (0.09, 0.40, 64, 6), (0.05, 0.41, 66, 3), (0.09, 0.36, -61, 2)])
def test_a_short_steep_wall_takes_its_sensors_slope(length, distance, tilt, n_valid):
    """Three to six readings at 55–69°, on no line: read at θ = 0 they lie 75–160 mm long;
    from their own slope within 15 mm (θ within 4°), with a σ that covers the error. Near
    the drop-out angle (the last case, 64–69°) the slope model bends (θ held at 70°) and
    those readings are INCIDENCE_UNKNOWN instead."""
    cal = dataclasses.replace(NOMINAL, noise_counts=2.0)
    sweep, d, inc = make_sweep(cal, walls=[_short_wall(length, distance, tilt)], ring=ONE,
                               noise_counts=2.0, seed=3, quantize=True)
    est = estimate_detail(sweep, cal)
    p, p0 = est.points, estimate(sweep, cal, iterate=False)
    seen = np.isfinite(d)
    assert 3 <= seen.sum() <= 6 and np.all(np.degrees(inc[seen]) > 54)
    assert np.all(est.lines.label[seen] < 0)
    assert np.all(p0.d[seen] - d[seen] > 0.075)
    ok = seen & p.valid
    assert ok.sum() == n_valid
    assert np.all(p.reason[seen & ~p.valid] == Reason.INCIDENCE_UNKNOWN)
    assert np.all(np.abs(p.d - d)[ok] <= 0.015)
    assert np.all(np.abs(p.theta - inc)[ok] <= math.radians(4.0))
    assert np.all(np.abs(p.d - d)[ok] <= 3.0 * p.sigma_m[ok])


def test_two_readings_of_a_steep_wall_are_incidence_unknown():
    """Two readings cannot give a slope: θ = 0 reads them 120–140 mm long, and at the
    drop-out angle they could lie 150 mm nearer; they are flagged, not placed."""
    cal = dataclasses.replace(NOMINAL, noise_counts=2.0)
    sweep, d, inc = make_sweep(cal, walls=[_short_wall(0.03, 0.42, 67)], ring=ONE,
                               noise_counts=2.0, seed=3, quantize=True)
    p, p0 = estimate(sweep, cal), estimate(sweep, cal, iterate=False)
    seen = np.isfinite(d)
    assert seen.sum() == 2 and np.all(p0.d[seen] - d[seen] > 0.1)
    assert np.all(p.reason[seen] == Reason.INCIDENCE_UNKNOWN)
    assert not np.any(p.valid[seen]) and np.all(np.isnan(p.d[seen]))


@pytest.mark.parametrize("radius, cx, cy", [(0.0075, 0.33, 0.012), (0.02, 0.27, -0.008)])
def test_a_posts_centre_is_read_near_square_on(radius, cx, cy):
    """A post's readings bend away from the beam: the ones that meet it within 25° of
    square on stay valid at θ = 0 or at their arc's θ (arcs.arc_incidence), never read
    steeper than 30°; none is worse than θ = 0 by more than 1 cm; a steep edge reading
    θ = 0 would put > 50 mm long may be flagged."""
    cal = dataclasses.replace(NOMINAL, noise_counts=2.0)
    sweep, d, inc = make_sweep(cal, circles=[((cx, cy), radius)], ring=ONE,
                               noise_counts=2.0, seed=5, quantize=True)
    p, p0 = estimate(sweep, cal), estimate(sweep, cal, iterate=False)
    seen = np.isfinite(d)
    square = seen & (inc < math.radians(25))
    assert square.sum() >= 1
    assert np.all(p.valid[square] & (p.theta[square] <= math.radians(30)))
    ok = seen & p.valid
    assert np.all(np.abs(p.d - d)[ok] <= np.abs(p0.d - d)[ok] + 0.01)
    flagged = seen & ~p.valid
    assert np.all(p.reason[flagged] == Reason.INCIDENCE_UNKNOWN)
    assert np.all(p0.d[flagged] - d[flagged] > 0.05)


# four 11 mm chair legs on a 370 mm square: a sensor sees a leg in 3-5 readings whose ranges
# bend away from the beam (a convex thing); flagging those INCIDENCE_UNKNOWN lost the legs
# (a held-out office with such a chair: recall 0.96 -> 0.89 when the flag came in)
CHAIR = """
name: chair_legs
seed: 24
room: {outline_mm: [[0, 0], [2100, 0], [2100, 1650], [0, 1650]]}
obstacles:
  - {type: cylinder, center_mm: [1130, 640], radius_mm: 11}
  - {type: cylinder, center_mm: [1130, 1010], radius_mm: 11}
  - {type: cylinder, center_mm: [1500, 640], radius_mm: 11}
  - {type: cylinder, center_mm: [1500, 1010], radius_mm: 11}
robot:
  poses:
    - {x_mm: 620, y_mm: 560, yaw_deg: 7}
    - {x_mm: 1320, y_mm: 300, yaw_deg: 31}
    - {x_mm: 1650, y_mm: 1290, yaw_deg: -48}
sensor: {model: gp2d12, max_range_mm: 624}
effects: [incidence, noise, quantization]
"""


def test_a_leg_seen_bent_away_from_the_beam_stays_valid(monkeypatch):
    from irring.estimation import estimate as est
    from irring.estimation import profiles as est_profiles

    sc = loads(CHAIR, source="<test>")
    sweeps = pipeline.simulated(sc, progress=False)[0].sweeps
    cal = scene_calibration(sc)[0]
    # one sensor's own profile alone: far_posts would place the flagged readings of a leg
    # two sensors see on one circle (and does, in the same 3 places)
    monkeypatch.setattr(est, "far_posts", lambda points, *args: points)
    kept = [estimate(sw, cal) for sw in sweeps]
    monkeypatch.setattr(est_profiles, "_CONVEX_BELOW_DROP_RAD", 10.0)   # no profile counts as convex
    flagged = [estimate(sw, cal) for sw in sweeps]
    added = 0
    for sw, new, old in zip(sweeps, kept, flagged):
        more = new.valid & ~old.valid
        assert np.all(old.reason[more] == Reason.INCIDENCE_UNKNOWN)
        hit = sw.truth.hit_point
        err = np.hypot(new.x - hit[..., 0], new.y - hit[..., 1])
        # kept at θ = 0 with the σ of how steeply its side may have been met
        assert np.all(err[more] <= 2.0 * new.sigma_m[more]), (err[more], new.sigma_m[more])
        added += int(more.sum())
    assert added >= 3


def test_a_ring_held_still_keeps_its_readings_with_the_sigma_of_its_doubt():
    """A radial ring reads each bearing once: no neighbouring step can give a slope, so a
    reading is kept at θ = 0 (not INCIDENCE_UNKNOWN, which took nearly every reading of
    radial12) with a σ that covers the error θ = 0 makes on a steep wall."""
    from _synthetic import rectangle

    cal = dataclasses.replace(NOMINAL, noise_counts=2.0)
    walls = rectangle(-0.37, -0.29, 0.43, 0.52)
    still, d, inc = make_sweep(cal, walls=walls, pose=(0.0, 0.0, math.radians(31)),
                               noise_counts=2.0, seed=4, quantize=True, steps=np.array([0]))
    p = estimate(still, cal)
    seen = np.isfinite(d)
    assert seen.sum() >= 8 and np.degrees(inc[seen]).max() > 30
    assert np.all(p.valid[seen]) and not np.any(p.reason == Reason.INCIDENCE_UNKNOWN)
    assert np.all(p.theta[seen] == 0.0)
    assert np.all(np.abs(p.d - d)[seen] <= 2.0 * p.sigma_m[seen])
    # the same sensors turning: the steep readings get their θ or are flagged, never kept long
    turning, d2, _ = make_sweep(cal, walls=walls, pose=(0.0, 0.0, math.radians(31)),
                                noise_counts=2.0, seed=4, quantize=True)
    q = estimate(turning, cal)
    assert np.all(np.abs(q.d - d2)[q.valid] < 0.1)


# our own room (GP2Y0A21): a 250 x 371 mm box at -19.4°, its 371 mm face seen by sensor 9 at 66-68° just
# past the corner it shares with the 250 mm face
BOX_PAST_CORNER = """
name: box_past_corner
seed: 1081
room: {outline_mm: [[0, 0], [2336, 0], [2336, 2576], [0, 2576]]}
obstacles:
  - {type: box, center_mm: [1780, 1533], size_mm: [250, 371], yaw_deg: -19.4}
robot:
  design: rotating12
  poses:
    - {x_mm: 1344, y_mm: 1193, yaw_deg: 139.8}
sensor: {model: gp2y0a21, adc_bits: 12}
effects: {incidence: {}, noise: {sigma_v: 0.015}, quantization: {}}
"""


def test_a_face_past_a_corner_takes_the_slope_of_its_own_readings(monkeypatch):
    """Three readings of a box face at 66-68°, on no line: their profile window took in the
    other face's line members and bent, so they were INCIDENCE_UNKNOWN. Asked again of the
    readings on no line alone, they are placed within 20 mm (θ within 4° of the truth) with
    a σ that covers the error. (Their profile held sensor 9's readings past the 70° drop-out,
    pooled with the face's; since a pool one half of which saw nothing is left as it was,
    POOL_SIDE_SIGMAS, those stay silent, the profile is too short and the three stay
    INCIDENCE_UNKNOWN: the asking again is checked with the halves' rule off.)"""
    from irring.estimation import estimate as estimate_module
    from irring.estimation import arcs as est_arcs
    from irring.estimation import silence as est_silence

    sc = loads(BOX_PAST_CORNER, source="<test>")
    run = pipeline.run(sc, seed=sc.seed, progress=False)
    assert np.all(run.points[0].reason[np.isin(run.sweeps[0].steps, [-3, -2, -1]), 9]
                  == Reason.INCIDENCE_UNKNOWN)
    monkeypatch.setattr(est_silence, "POOL_SIDE_SIGMAS", -math.inf)
    face = None
    for asked_again in (True, False):
        if not asked_again:
            monkeypatch.setattr(est_arcs, "off_line_profiles", lambda *a, **k: None)
        run = pipeline.run(sc, seed=sc.seed, progress=False)
        sw, p = run.sweeps[0], run.points[0]
        if face is None:
            face = np.zeros(p.valid.shape, bool)
            face[np.isin(sw.steps, [-3, -2, -1]), 9] = True
            inc = np.degrees(sw.truth.incidence_rad[face])
            assert np.all((inc > 65.5) & (inc < 68.5)), inc
        if asked_again:
            assert np.all(p.valid[face])
            err = np.hypot(p.x - sw.truth.hit_point[..., 0], p.y - sw.truth.hit_point[..., 1])
            assert np.all(err[face] <= 0.020), err[face]
            assert np.all(np.abs(p.theta - sw.truth.incidence_rad)[face] <= math.radians(4.0))
            assert np.all(err[face] <= 2.0 * p.sigma_m[face])
        else:
            assert np.all(p.reason[face] == Reason.INCIDENCE_UNKNOWN)


# our own room (GP2D12 read to 624 mm): a 203 x 381 mm box at 36.5° and a 496 x 263 mm box at
# 4.6°; the first's face 470-560 mm away at 48-56° makes sensor 7 a line of few members
TWO_FAR_BOXES = """
name: two_far_boxes
seed: 1072
room: {outline_mm: [[0, 0], [2876, 0], [2876, 2236], [0, 2236]]}
obstacles:
  - {type: box, center_mm: [1342, 763], size_mm: [203, 381], yaw_deg: 36.5}
  - {type: box, center_mm: [1958, 1901], size_mm: [496, 263], yaw_deg: 4.6}
robot:
  design: rotating12
  poses:
    - {x_mm: 1511, y_mm: 1408, yaw_deg: 159.9}
sensor: {model: gp2d12, adc_bits: 12}
effects: {incidence: {}, noise: {sigma_v: 0.015}, quantization: {}}
"""


def test_a_short_far_line_of_unsure_direction_leaves_its_members_their_own_slope(monkeypatch):
    """Lines of at most 9 readings 0.72 of the range or more away whose direction standard
    error exceeds 4°: a member whose own profile is straight, its slope more than half its
    standard error off the line's, reads at its own θ. Sensor 7's five such readings of the
    first box (48-55°, read 5-14° too steep): before, 3 lay 4.2-5.0σ off their true hits
    (56-58 mm); after, none lies 2σ off, and their RMS error falls by a third or more
    (50 -> 28 mm)."""
    from irring.estimation import estimate as estimate_module
    from irring.estimation import far_lines as est_far_lines

    sc = loads(TWO_FAR_BOXES, source="<test>")
    runs = {}
    for rule in (True, False):
        if not rule:
            monkeypatch.setattr(est_far_lines, "SHORT_LINE_SE_MAX", math.inf)
        run = pipeline.run(sc, seed=sc.seed, progress=False)
        runs[rule] = [(p.valid, p.d, p.sigma_m, np.hypot(p.x - sw.truth.hit_point[..., 0],
                                                         p.y - sw.truth.hit_point[..., 1]))
                      for sw, p in zip(run.sweeps, run.points)]
    (v1, d1, s1, e1), (v0, d0, s0, e0) = (
        [np.concatenate([r[i].ravel() for r in runs[rule]]) for i in range(4)]
        for rule in (True, False))
    moved = v0 & v1 & (np.abs(d1 - d0) > 1e-4)
    assert moved.sum() == 5
    assert np.all(v1 == v0)
    assert np.count_nonzero(e0[moved] > 3.0 * s0[moved]) == 3
    assert np.all(e1[moved] <= 2.0 * s1[moved])
    assert np.sqrt(np.mean(e1[moved] ** 2)) <= 0.67 * np.sqrt(np.mean(e0[moved] ** 2))
