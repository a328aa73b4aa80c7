"""Several sensors' looks at one far thing taken together (docs/estimator.md): where a part
is read to its own range, the overlapping lines different sensors of one sweep fit to one
wall are snapped as one line ("Far lines fused across sensors"); on every part, a thin
post's few readings from several sensors are fitted as one circle ("Far posts")."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from irring import pipeline
from irring.core import Cylinder, Points, Reason, points_with
from irring.estimation.calibration import Calibration
from irring.estimation.lines import Lines
from irring.estimation import estimate as fast
from irring.estimation import arcs as est_arcs
from irring.estimation import far_lines as est_far_lines
from irring.estimation import traces as est_traces
from irring.maps import metrics
from irring.scenario import loads

# A room of our own: a 5470 × 2630 mm hall read by the GP2Y0A02 to its own 1500 mm, a 90 mm
# and a 60 mm post, two poses turned 17° and −29°: most walls 1.1-1.5 m from the sensors.
FAR_HALL = """\
name: far_hall
seed: 3117
room:
  outline_mm: [[0, 0], [5470, 0], [5470, 2630], [0, 2630]]
obstacles:
  - {type: cylinder, center_mm: [2380, 1660], radius_mm: 45}
  - {type: cylinder, center_mm: [3920, 760], radius_mm: 30}
robot:
  poses:
    - {x_mm: 1270, y_mm: 1240, yaw_deg: 17}
    - {x_mm: 3060, y_mm: 1390, yaw_deg: -29}
sensor: {model: gp2y0a02}
effects: [incidence, noise, quantization]
"""


def _lines(specs, rng):
    """Points of several lines, one row each: (centre x, y, direction, offset across, half
    length, members, noise across) per line."""
    xs, ys, sig, lab = [], [], [], []
    for k, (cx, cy, angle, offset, half, n, noise) in enumerate(specs):
        u = np.linspace(-half, half, n)
        v = offset + rng.normal(0.0, noise, n)
        xs.append(cx + u * math.cos(angle) - v * math.sin(angle))
        ys.append(cy + u * math.sin(angle) + v * math.cos(angle))
        sig.append(np.full(n, noise)); lab.append(np.full(n, k))
    width = max(x.size for x in xs)
    pad = lambda parts, fill: np.array([np.r_[p, np.full(width - p.size, fill)] for p in parts])
    x, y, s = pad(xs, np.nan), pad(ys, np.nan), pad(sig, np.nan)
    label = pad(lab, -1).astype(np.intp)
    zeros = np.zeros(x.shape)
    points = Points(x=x, y=y, d=zeros + 1.3, theta=zeros, origin_x=zeros, origin_y=zeros,
                    heading=zeros, sigma_m=s, iterations=zeros.astype(int),
                    valid=label >= 0, reason=np.zeros(x.shape, np.uint8))
    return points, label


def test_overlapping_lines_of_one_wall_are_joined_and_others_kept_apart():
    """Line 0 and 1: one wall seen by two sensors (offsets 14 mm apart, 40 mm of noise a
    member): joined. Line 2: parallel 90 mm behind. Line 3: collinear but 0.4 m further on
    (no overlap). Line 4: crossing line 0 at 9°. Line 5: four members (too few). Line 6:
    joins line 1 and so line 0 (a group of three)."""
    rng = np.random.default_rng(11)
    a = 0.37
    on = lambda s: (1.0 + s * math.cos(a), 2.0 + s * math.sin(a))   # a point along line 0
    points, label = _lines([(*on(0.0), a, 0.007, 0.30, 21, 0.025),
                            (*on(0.1), a, -0.007, 0.25, 25, 0.025),
                            (*on(0.0), a, 0.090, 0.30, 19, 0.010),
                            (*on(1.0), a, 0.0, 0.25, 15, 0.040),
                            (*on(0.0), a + math.radians(9), 0.0, 0.30, 25, 0.010),
                            (*on(0.05), a, 0.0, 0.10, 4, 0.040),
                            (*on(-0.3), a, 0.003, 0.20, 13, 0.025)], rng)
    fused = fast.fused_lines(points, label)
    top = [int(fused[k][label[k] >= 0][0]) for k in range(label.shape[0])]
    assert top == [0, 0, 2, 3, 4, 5, 0]
    np.testing.assert_array_equal(fused[label < 0], -1)
    # no line of its own number changes unless it joined: the labels are the lines' own
    assert fast.fused_lines(points, np.where(np.isin(label, (0, 1, 6)), -1, label)).tolist() \
        == np.where(np.isin(label, (0, 1, 6)), -1, label).tolist()


def test_far_walls_seen_by_several_sensors_come_out_one_line(monkeypatch):
    """FAR_HALL, seed 3117: each sensor's far line (1.1-1.5 m, 16-49 members of 30-50 mm
    noise) lies off its wall by its own 5-25 mm, and the mapper drew each at its own offset:
    walls two cells thick. Snapped as one, the far end points' error across their wall is
    RMS 9.5 mm (11.9 before), 20 lie more than 20 mm off (39), precision 0.981 (0.956; 0.952
    before the mapper's median of neighbouring steps, docs/mapping.md). Since a pool one half
    of which saw nothing is left as it was (POOL_SIDE_SIGMAS: a wall fading out of range at
    30° reads like a face's end), 550 far readings (582): RMS 10.7 mm (12.6 unfused), 26 more
    than 20 mm off (44), precision 0.972 (0.945). Since a noise-level reading past its line's
    other members is silenced (noise_past_line_end; here some were a wall fading out of
    range), 543 far readings, 26 more than 20 mm off, precision 0.967. Since a line member
    alone beside a nearer return is INCIDENCE_UNKNOWN (alone_at_an_edge; here one 6 mm off),
    542. Since a far line whose direction its wall's line knows far better joins it
    (vague_far_lines): RMS 8.6 mm (10.8 without), 10 more than 20 mm off (26), precision
    0.977 (0.966); unfused too, RMS 11.2 mm, 31 off, precision 0.957. Since dim returns
    beside a line are put on it (dim_returns_on_lines), 586 far readings (585 unfused): RMS
    8.5 mm (12.6), 10 more than 20 mm off (46), precision 0.982 (0.945)."""
    scene = loads(FAR_HALL)
    monkeypatch.setattr(fast, "far_posts", lambda points, *args: points)   # lines alone
    # (and far returns left unplaced read on the line their beam crosses,
    # onto_crossed_lines: 615, RMS 8.3 mm, 10 more than 20 mm off, precision 0.982)
    monkeypatch.setattr(fast, "onto_crossed_lines", lambda points, *a, **k: points)

    def far_errors():
        run = pipeline.run(scene, progress=False)
        err = []
        for p, sweep in zip(run.points, run.sweeps):
            d = sweep.truth.distance_m
            far = p.valid & np.isfinite(d) & (d > 1.1)
            err.append(((p.d - d) * np.cos(sweep.truth.incidence_rad))[far])
        return np.concatenate(err), run.scores["occupied_precision"]

    err, precision = far_errors()
    assert err.size == 586 and np.sqrt(np.mean(err ** 2)) < 0.0090
    assert (np.abs(err) > 0.02).sum() <= 10 and precision > 0.975
    monkeypatch.setattr(est_far_lines, "FUSE_MIN", 10 ** 9)
    monkeypatch.setattr(est_traces, "VAGUE_RATIO", math.inf)
    err0, precision0 = far_errors()
    assert err0.size == 585 and np.sqrt(np.mean(err0 ** 2)) > 0.0120
    assert (np.abs(err0) > 0.02).sum() >= 40 and precision0 < 0.955


def _record_far_posts(monkeypatch) -> list:
    """Wrap far_posts: each call appends the mask of readings it changed (valid or θ)."""
    changed, far_posts = [], fast.far_posts

    def recording(points, *args):
        out = far_posts(points, *args)
        changed.append((out.valid != points.valid) | (out.valid & (out.theta != points.theta)))
        return out

    monkeypatch.setattr(fast, "far_posts", recording)
    return changed


def _on_posts(scene, sweep):
    """(S, N) bool: the readings whose true hit lies on one of the scene's cylinders."""
    hit = sweep.truth.hit_point
    on = np.zeros(hit.shape[:2], dtype=bool)
    for o in (o for o in scene.obstacles if isinstance(o, Cylinder)):
        on |= np.abs(np.hypot(hit[..., 0] - o.center_m[0], hit[..., 1] - o.center_m[1])
                     - o.radius_m) < 0.002
    return on


def test_a_far_posts_few_readings_from_several_sensors_are_read_on_one_circle(monkeypatch):
    """FAR_HALL, seed 3117: its 90 and 60 mm posts 1.1-1.3 m away give each sensor 2-4
    readings between silent beams, too few for a slope or an arc; they were INCIDENCE_UNKNOWN
    or θ = 0 fallbacks up to 213 mm off (RMS 59 mm), and 13 of the posts' 33 visible cells
    were mapped. Fitted as one circle across the sensors: 15 readings change, all on the
    posts, now 2-40 mm off (RMS 19 mm); 31 cells are mapped, recall 0.952 → 0.983,
    precision 0.981 → 0.975 (with the far lines' later rules: recall 0.945 → 0.976,
    precision 0.972 → 0.962; with silent beams bounded beside their nearest return and
    noise-level readings past a line's other members silenced, 0.967 → 0.957). 30 cells (12
    without the fit) since the mapper's hit floor stays in its end point's cell (31 and 13 with
    its segments between a sensor's steps, ``between_steps``, off: docs/mapping.md "Fine
    cells")."""
    scene = loads(FAR_HALL)
    def measure():
        run = pipeline.run(scene, progress=False)
        err = [np.hypot(p.x - sw.truth.hit_point[..., 0], p.y - sw.truth.hit_point[..., 1])
               for p, sw in zip(run.points, run.sweeps)]
        on_post = np.concatenate([e[p.valid & _on_posts(scene, sw)]
                                  for e, p, sw in zip(err, run.points, run.sweeps)])
        truth = run.truth
        post = truth.visible & (truth.surface_owner >= metrics.OBSTACLE0)
        found = post & metrics._dilate(run.grid.classify() == metrics.OCCUPIED)
        return run, err, on_post, (int(post.sum()), int(found.sum()))

    changed = _record_far_posts(monkeypatch)
    run, err, on_post, cells = measure()
    assert sum(int(c.sum()) for c in changed) == 15
    assert all(not (c & ~_on_posts(scene, sw)).any() for c, sw in zip(changed, run.sweeps))
    moved = np.concatenate([e[c] for e, c in zip(err, changed)])
    assert moved.max() < 0.045 and np.sqrt(np.mean(moved ** 2)) < 0.021
    assert on_post.size == 29 and cells == (33, 30)
    monkeypatch.setattr(fast, "far_posts", lambda points, *args: points)
    run0, _, on_post0, cells0 = measure()
    assert on_post0.size == 21 and np.sqrt(np.mean(on_post0 ** 2)) > 0.05
    assert cells0 == (33, 12)
    assert run.scores["occupied_recall"] > run0.scores["occupied_recall"] + 0.025
    assert run.scores["occupied_precision"] > run0.scores["occupied_precision"] - 0.011


# A room of our own for the GP2D12 at its default range: three posts 25-39 mm across,
# 0.52-0.56 m from the ring; its walls, 0.9-1.3 m away, are out of range
NEAR_POSTS = """\
name: gp2d12_posts
seed: 6002
room: {outline_mm: [[-900, -700], [1150, -820], [1310, 960], [-760, 1240]]}
obstacles:
  - {type: cylinder, center_mm: [-495, 135], radius_mm: 15.9}
  - {type: cylinder, center_mm: [272, -359], radius_mm: 19.6}
  - {type: cylinder, center_mm: [575, 47], radius_mm: 12.4}
robot:
  poses:
    - {x_mm: 60, y_mm: 140, yaw_deg: 74.5}
sensor: {model: gp2d12, adc_bits: 12}
effects: [incidence, noise, quantization]
"""


def test_a_gp2d12_sees_its_posts_on_circles_too(monkeypatch):
    """NEAR_POSTS, seed 6002: each post gives each of two sensors 2-5 readings, too few for
    a slope; 11 of the posts' 25 readings were INCIDENCE_UNKNOWN and the rest up to 83 mm
    off (RMS 33 mm): 10 of the posts' 15 visible cells mapped, F1 0.769. Fitted as circles
    (far_posts once ran only for a part read to its own range): 24 readings change, all on
    the posts, now within 22 mm (RMS 9 mm); all 15 cells mapped, F1 1.000."""
    scene = loads(NEAR_POSTS)
    def measure():
        run = pipeline.run(scene, progress=False)
        sw, p = run.sweeps[0], run.points[0]
        err = np.hypot(p.x - sw.truth.hit_point[..., 0], p.y - sw.truth.hit_point[..., 1])
        post = _on_posts(scene, sw)
        truth = run.truth
        visible = truth.visible & (truth.surface_owner >= metrics.OBSTACLE0)
        found = visible & metrics._dilate(run.grid.classify() == metrics.OCCUPIED)
        return run, err, post, (int(visible.sum()), int(found.sum()))

    changed = _record_far_posts(monkeypatch)
    run, err, post, cells = measure()
    assert len(changed) == 1 and int(changed[0].sum()) == 24
    assert not (changed[0] & ~post).any()
    assert err[changed[0]].max() < 0.025 and np.sqrt(np.mean(err[changed[0]] ** 2)) < 0.010
    assert cells == (15, 15) and run.scores["occupied_f1"] > 0.999
    monkeypatch.setattr(fast, "far_posts", lambda points, *args: points)
    run0, err0, post0, cells0 = measure()
    p0 = run0.points[0]
    assert int((post0 & (p0.reason == Reason.INCIDENCE_UNKNOWN)).sum()) == 11
    assert int((post0 & p0.valid).sum()) == 13 and err0[post0 & p0.valid].max() > 0.080
    assert cells0 == (15, 10) and run0.scores["occupied_f1"] < 0.78


def _turned(text: str, turn_rad: float) -> str:
    """A scene's text with its whole world turned by ``turn_rad`` about the origin."""
    import yaml
    d = yaml.safe_load(text)
    c, s = math.cos(turn_rad), math.sin(turn_rad)
    turn = lambda p: [round(p[0] * c - p[1] * s, 1), round(p[0] * s + p[1] * c, 1)]  # noqa: E731
    d["room"]["outline_mm"] = [turn(p) for p in d["room"]["outline_mm"]]
    for o in d["obstacles"]:
        o["center_mm"] = turn(o["center_mm"])
    for p in d["robot"]["poses"]:
        p["x_mm"], p["y_mm"] = turn([p["x_mm"], p["y_mm"]])
        p["yaw_deg"] += math.degrees(turn_rad)
    return yaml.safe_dump(d)


def test_a_post_due_west_is_searched_about_its_own_bearing(monkeypatch):
    """A pose 1.0 m north-west of the 60 mm post, the world turned so the post lies due
    west of the ring (its readings' bearings either side of ±π): the bearing grid spanned
    from −π to π, 632 bearings where 10 do: 55,616 circles scored at once where 880 do
    (75 ms a sweep instead of 1.8, load 6). The same readings are taken onto a circle
    either way."""
    west = FAR_HALL.replace("{x_mm: 1270, y_mm: 1240, yaw_deg: 17}",
                            "{x_mm: 3520, y_mm: 1662, yaw_deg: 3}")
    circles = []
    meet = est_arcs.meet_circle

    def counting(centre, radius, *beams):
        circles.append(np.size(centre[0]))
        return meet(centre, radius, *beams)

    monkeypatch.setattr(est_arcs, "meet_circle", counting)
    monkeypatch.setattr(est_far_lines, "meet_circle", counting)
    changed = _record_far_posts(monkeypatch)
    runs = {}
    for name, turn in (("as written", 0.0), ("post due west", math.pi + 1.1527)):
        circles.clear(), changed.clear()
        pipeline.run(loads(_turned(west, turn)), progress=False)
        runs[name] = (max(circles), [int(c.sum()) for c in changed])
    assert runs["as written"][1] == runs["post due west"][1] == [7, 6]
    assert runs["post due west"][0] == runs["as written"][0] == 880


# A canteen corner of our own read to 1300 mm: a 300 mm pillar 0.9 m away and a 50 mm table
# leg 0.6 m away, which the GP2Y0A02 sees at 0.6 m only between beams that graze its sides.
CANTEEN_LEG = """\
name: canteen_leg
seed: 4102
room:
  outline_mm: [[0, 0], [2600, 0], [2600, 2460], [0, 2460]]
obstacles:
  - {type: box, center_mm: [2250, 1520], size_mm: [300, 300], yaw_deg: 7}
  - {type: cylinder, center_mm: [1510, 1950], radius_mm: 25}
robot:
  poses:
    - {x_mm: 1290, y_mm: 1210, yaw_deg: 13}
sensor: {model: gp2y0a02, max_range_mm: 1300}
effects: [incidence, noise, quantization]
"""


def test_a_legs_readings_flanked_by_its_own_grazed_edges_are_read_on_its_circle():
    """CANTEEN_LEG, seeds 4102-4103: three sensors see the 50 mm leg at 600-625 mm with 2-4
    readings each; the beams beside each run graze the leg's sides (62-66°), read 200 mm
    long at θ = 0 and are on no line themselves, which far_posts took for a surface going on:
    the 16 readings that meet the leg at < 45° were all INCIDENCE_UNKNOWN. Such a flank now
    asks four readings on the circle (three fit any circle): each is valid within 25 mm of
    its hit."""
    scene = loads(CANTEEN_LEG)
    err = []
    for seed in (4102, 4103):
        run = pipeline.run(scene, seed=seed, progress=False)
        p, sw = run.points[0], run.sweeps[0]
        leg = _on_posts(scene, sw) & (sw.truth.incidence_rad < math.radians(45))
        assert p.valid[leg].all()
        err.append(np.hypot(p.x - sw.truth.hit_point[..., 0],
                            p.y - sw.truth.hit_point[..., 1])[leg])
    err = np.concatenate(err)
    assert err.size >= 15 and err.max() < 0.025


def _crossing_case(model: str):
    """A wall y = 1.2 m seen by one sensor's line of six members (x 0.05-0.30 m) and four
    other readings from the origin, INCIDENCE_UNKNOWN: (0) its counts read at the range and
    incidence where its beam crosses the wall 0.04 m past the members (within the margin),
    (1) counts 0.30 m long of that, (2) a beam crossing 0.25 m past the members, (3) at the
    noise level. Returns (calibration, points, lines, counts, crossing range, incidence)."""
    cal = Calibration.nominal(model)
    n = 10
    x = np.r_[np.linspace(0.05, 0.30, 6), np.full(4, np.nan)]
    y = np.r_[1.2 + np.array([0.004, -0.006, 0.002, 0.009, -0.003, -0.004]), np.full(4, np.nan)]
    wall_x = np.array([0.34, 0.38, 0.55, 0.38])      # where readings 6-9 meet the wall
    heading = np.r_[np.arctan2(y[:6], x[:6]), np.arctan2(1.2, wall_x)]
    rng = np.r_[np.hypot(x[:6], y[:6]), np.hypot(wall_x, 1.2)]
    theta = np.abs(math.pi / 2 - heading)
    counts = cal.counts(rng, theta)
    counts[7] = cal.counts(rng[7] + 0.30, theta[7])
    counts[9] = cal.no_return_counts + 1.0
    valid = np.arange(n) < 6
    col = lambda v: np.asarray(v, float).reshape(n, 1)
    zeros = col(np.zeros(n))
    reason = np.where(valid, Reason.OK, Reason.INCIDENCE_UNKNOWN).astype(np.uint8)
    points = Points(x=col(x), y=col(y), d=col(np.where(valid, rng, np.nan)),
                    theta=col(np.where(valid, theta, np.nan)), origin_x=zeros,
                    origin_y=zeros.copy(), heading=col(heading),
                    sigma_m=col(np.r_[np.linspace(0.02, 0.03, 6), np.full(4, np.nan)]),
                    iterations=np.ones((n, 1), int), valid=valid.reshape(n, 1),
                    reason=reason.reshape(n, 1), max_range_m=cal.max_range_m)
    label = np.where(valid, 0, -1).reshape(n, 1)
    lines = Lines(label=label, centroid=np.array([[0.175, 1.2]]),
                  normal=np.array([[0.0, 1.0]]), direction=np.array([[1.0, 0.0]]),
                  n_points=np.array([6]), length_m=np.array([0.25]), rms_m=np.zeros(1),
                  usable=np.ones(1, bool), start=np.zeros(1, int), end=np.zeros(1, int))
    return cal, points, lines, counts.reshape(n, 1), rng, theta


def test_an_unplaced_far_return_is_read_on_the_line_its_beam_crosses():
    """GP2Y0A02: reading 6's counts give the range where its beam crosses another sensor's
    line (0.04 m past its members): valid there, at the crossing's incidence, with the members'
    mean σ (25 mm; their RMS about the line, 5 mm, is less) as σ. Reading 7 (counts 0.30 m long:
    many σ off), 8 (crossing 0.25 m past the members) and 9 (no return) stay unplaced; the
    members do not move."""
    cal, points, lines, counts, rng, theta = _crossing_case("gp2y0a02")
    out = est_far_lines.onto_crossed_lines(points, lines, counts, cal)
    assert out.valid[:, 0].tolist() == [True] * 7 + [False] * 3
    assert out.reason[6, 0] == Reason.OK and np.all(out.reason[7:, 0] == Reason.INCIDENCE_UNKNOWN)
    assert out.d[6, 0] == pytest.approx(rng[6], abs=1e-9)
    assert out.theta[6, 0] == pytest.approx(theta[6], abs=1e-9)
    assert (out.x[6, 0], out.y[6, 0]) == (pytest.approx(0.34, abs=1e-9), pytest.approx(1.2))
    assert out.sigma_m[6, 0] == pytest.approx(0.025, abs=1e-12)
    np.testing.assert_array_equal(out.x[:6], points.x[:6])
    assert np.isnan(out.x[7:, 0]).all()


def test_only_a_reading_no_rule_unplaced_since_local_incidence_is_placed():
    """Reading 6 of that case is placed where ``left`` says local_incidence left it as it is
    (INCIDENCE_UNKNOWN or OUT_OF_RANGE); where ``left`` says local_incidence placed it, a
    later rule unplaced it on purpose: it stays unplaced."""
    cal, points, lines, counts, rng, _ = _crossing_case("gp2y0a02")
    left = points.reason.copy()
    assert est_far_lines.onto_crossed_lines(points, lines, counts, cal, left).valid[6, 0]
    left[6, 0] = Reason.OK
    out = est_far_lines.onto_crossed_lines(points, lines, counts, cal, left)
    assert not out.valid[6:, 0].any() and out.reason[6, 0] == Reason.INCIDENCE_UNKNOWN
    weak = points.reason.copy()
    weak[6, 0] = Reason.OUT_OF_RANGE
    out = est_far_lines.onto_crossed_lines(points_with(points, reason=weak), lines, counts, cal,
                                           weak)
    assert out.valid[:, 0].tolist() == [True] * 7 + [False] * 3
    assert out.d[6, 0] == pytest.approx(rng[6], abs=1e-9)


def test_a_weak_return_past_a_lines_end_needs_its_sensors_next_steps():
    """Reading 6 OUT_OF_RANGE, its crossing 0.04 m past the members' end: where its sensor's
    next two steps read the no-return level less one count σ (a beam past a face's end into
    nothing), the mean of its counts and theirs stands 1.72 standard errors over the level,
    under ``CROSS_SIDE_SIGMAS`` = 2.5: unplaced. Where they read a wall going on (the counts
    of their own crossings, 4.57 and 2.60 count σ over the level), placed. An
    INCIDENCE_UNKNOWN reading there is placed either way (its counts are a return)."""
    cal, points, lines, counts, rng, theta = _crossing_case("gp2y0a02")
    weak = points.reason.copy()
    weak[6, 0] = Reason.OUT_OF_RANGE
    points = points_with(points, reason=weak)
    sigma, level = cal.sigma_counts(), cal.no_return_counts
    assert est_far_lines.CROSS_SIDE_STEPS == 2 and est_far_lines.CROSS_SIDE_SIGMAS == 2.5
    nothing = counts.copy()
    nothing[7:9, 0] = level - sigma
    z = (nothing[6:9, 0].mean() - level) * math.sqrt(3) / sigma
    assert z == pytest.approx(1.72, abs=0.005)
    out = est_far_lines.onto_crossed_lines(points, lines, nothing, cal, weak)
    assert not out.valid[6:, 0].any() and out.reason[6, 0] == Reason.OUT_OF_RANGE
    going_on = counts.copy()
    going_on[7:9, 0] = cal.counts(rng[7:9], theta[7:9])
    assert ((going_on[7:9, 0] - level) / sigma).round(2).tolist() == [4.57, 2.6]
    out = est_far_lines.onto_crossed_lines(points, lines, going_on, cal, weak)
    assert out.valid[:, 0].tolist() == [True] * 7 + [False] * 3
    unknown = points_with(points, reason=np.where(np.arange(10) < 6, Reason.OK,
                                                  Reason.INCIDENCE_UNKNOWN)
                          .astype(np.uint8).reshape(10, 1))
    assert est_far_lines.onto_crossed_lines(unknown, lines, nothing, cal).valid[6, 0]


def _beside_beam(points, row: int, rng: float, off: float) -> tuple[float, float]:
    """The point ``rng`` m along reading ``row``'s beam and ``off`` m to its left."""
    h = points.heading[row, 0]
    return (rng * math.cos(h) - off * math.sin(h), rng * math.sin(h) + off * math.cos(h))


def test_a_nearer_surface_keeps_a_far_return_off_the_line_behind_it():
    """Reading 6's crossing lies 1.247 m out. A valid end point on no line (reading 9 made
    one) 0.8 m along its beam and 20 mm beside it, inside ``NEAR_WIDTH_M`` = 30 mm, could
    have returned its counts (a post's flank grazed): unplaced; 40 mm beside it, placed. So
    does another line crossed within its members' extent 0.8 m out (readings 8 and 9, 0.1 m
    either side of the beam: neither within 30 mm of it); the same line ending 0.05 m short
    of the beam does not."""
    cal, points, lines, counts, _, _ = _crossing_case("gp2y0a02")
    assert est_far_lines.NEAR_WIDTH_M == 0.03 and est_far_lines.NEAR_GAP_M == 0.06

    def with_points(rows, xy, label=-1):
        x, y, valid = points.x.copy(), points.y.copy(), points.valid.copy()
        for row, (px, py) in zip(rows, xy):
            x[row, 0], y[row, 0], valid[row, 0] = px, py, True
        lab = lines.label.copy()
        lab[rows, 0] = label
        return points_with(points, x=x, y=y, valid=valid), lab

    for off, placed in ((0.02, False), (0.04, True), (-0.02, False)):
        p, lab = with_points([9], [_beside_beam(points, 6, 0.8, off)])
        out = est_far_lines.onto_crossed_lines(p, replace(lines, label=lab), counts, cal)
        assert out.valid[6, 0] == placed
    h = points.heading[6, 0]
    for ends, placed in ((0.1, False), (-0.05, True)):
        ends_xy = [_beside_beam(points, 6, 0.8, -0.1), _beside_beam(points, 6, 0.8, ends)]
        p, lab = with_points([8, 9], ends_xy, label=1)
        other = replace(lines, label=lab,
                        centroid=np.r_[lines.centroid, [np.mean(ends_xy, axis=0)]],
                        normal=np.r_[lines.normal, [[math.cos(h), math.sin(h)]]],
                        direction=np.r_[lines.direction, [[-math.sin(h), math.cos(h)]]])
        out = est_far_lines.onto_crossed_lines(p, other, counts, cal)
        assert out.valid[6, 0] == placed


def test_a_short_range_part_leaves_its_unplaced_returns_alone():
    """GP2Y0A21 (rated to 0.8 m): the same case changes nothing (on the short-range parts
    the rule moved rooms both ways: docs/estimator.md)."""
    cal, points, lines, counts, _, _ = _crossing_case("gp2y0a21")
    points = points_with(points, max_range_m=1.5)
    out = est_far_lines.onto_crossed_lines(points, lines, counts, cal)
    assert out is points
