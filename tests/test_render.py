"""Map pictures: cells, walls and poses where they belong; frames streamed (counted,
thinned for long runs) that end as the PNG; the caller's matplotlib left alone (and not
even loaded); pose numbers never sit on each other."""

from __future__ import annotations

import io
import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("mujoco")

from irring import pipeline  # noqa: E402
from irring.maps import render  # noqa: E402
from irring.scenario import load_scenario  # noqa: E402
from irring.core import score_text  # noqa: E402


@pytest.fixture(scope="module")
def t_room_run():
    return pipeline.run(load_scenario("t_room"), progress=False,
                        frames_per_sweep=pipeline.FRAMES_PER_SWEEP)


def test_frames_replay_the_map_being_built(t_room_run):
    frames = list(pipeline.building_frames(t_room_run))
    parts, stride, count = pipeline.frame_plan(4, pipeline.FRAMES_PER_SWEEP)
    assert (parts, stride, count) == (6, 1, 25) and len(frames) == count
    classes, shown, caption = frames[0]
    assert shown == 0 and caption == "before the first sweep" and np.all(classes == -1)
    assert [f[1] for f in frames[1:7]] == [1] * 6
    assert frames[6][2] == "pose 1 of 4: done" and frames[3][2] == "pose 1 of 4: sweeping (3/6)"
    np.testing.assert_array_equal(frames[-1][0], t_room_run.grid.classify())
    known = [np.count_nonzero(f[0] != -1) for f in frames]
    assert all(b >= a for a, b in zip(known, known[1:])) and known[-1] > known[1] > 0


def test_a_long_run_is_thinned_to_a_watchable_animation():
    assert pipeline.frame_plan(300, 6) == (1, 1, 301)      # one frame a sweep
    # 1000 sweeps: every 3rd sweep (3, 6, … 999) and the last one, after the empty map
    assert pipeline.frame_plan(1000, 6) == (1, 3, 335)
    assert pipeline.frame_plan(1, 6) == (6, 1, 7)


def _hue(img, color, min_chroma=60):
    """Mask of pixels of that hue (inks blend with what lies under them)."""
    rgb = np.array([int(color[i:i + 2], 16) for i in (1, 3, 5)], float)
    img = np.asarray(img, float)
    chroma = img - img.min(axis=-1, keepdims=True)
    want = (rgb - rgb.min()) / np.ptp(rgb)
    close = np.abs(chroma / np.maximum(chroma.max(axis=-1, keepdims=True), 1) - want)
    return (chroma.max(axis=-1) > min_chroma) & np.all(close < 0.2, axis=-1)


def _near(mask, col, row, r=2):
    c, w = int(col), int(row)
    return bool(mask[max(0, w - r):w + r + 1, max(0, c - r):c + r + 1].any())


def _picture(run, **kw):
    return render.MapPicture(run.grid, run.scenario, run.poses, *pipeline._reach(run), **kw)


def test_the_picture_puts_cells_walls_and_poses_where_they_are(t_room_run):
    pic = _picture(t_room_run, title="t_room")
    classes = t_room_run.grid.classify()
    img = pic.rgb(classes, "t_room").astype(int)
    assert img.shape == (pic.height, pic.width, 3) and 700 < pic.width < 1000
    # each cell's centre pixel has its class's colour wherever nothing is drawn over it
    ny, nx = classes.shape
    x0, _, y0, _ = t_room_run.grid.extent_m
    res = t_room_run.grid.resolution_m
    rr, cc = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    px = pic.to_px(x0 + (cc.ravel() + 0.5) * res, y0 + (rr.ravel() + 0.5) * res)
    cols, rows = px[:, 0].astype(int), px[:, 1].astype(int)
    drawn = pic._alpha.copy()
    for layers in pic._poses:
        for layer in layers:
            drawn[layer.index] = 1
    bare = drawn.reshape(pic.height, pic.width)[rows, cols] == 0
    bare &= pic._bg.reshape(pic.height, pic.width)[rows, cols] < 0
    assert bare.mean() > 0.7
    got = img[rows[bare], cols[bare]]
    want = np.round(render.map_rgb(classes.ravel()[bare]) * 255)
    np.testing.assert_array_equal(got, want)
    for cls in (-1, 0, 1):                    # all three classes were checked
        assert np.count_nonzero(classes.ravel()[bare] == cls) > 100
    # the true walls: blue along the room outline (away from the black mapped wall cells,
    # the outline is drawn over them), at each corner of the T
    blue = _hue(img, render.TRUTH_COLOR)
    outline = np.asarray(t_room_run.scenario.room.outline_m)
    for x, y in outline:
        assert _near(blue, *pic.to_px(x, y)), (x, y)
    # the poses: a red ring of the ring's radius round each, the dashed orange reach
    red, orange = _hue(img, render.POSE_COLOR), _hue(img, render.RANGE_COLOR)
    reach, ring_r = pipeline._reach(t_room_run)
    theta = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    L, T, R, B = pic._box
    for x, y, *_ in t_room_run.poses:
        ring = [_near(red, *pic.to_px(x + ring_r * np.cos(t), y + ring_r * np.sin(t)), r=1)
                for t in theta]
        assert np.mean(ring) > 0.95
        fine = np.linspace(0, 2 * np.pi, 720, endpoint=False)
        far = pic.to_px(x + reach * np.cos(fine), y + reach * np.sin(fine))
        inside = ((far[:, 0] > L + 3) & (far[:, 0] < R - 3) &
                  (far[:, 1] > T + 3) & (far[:, 1] < B - 3))
        on = [_near(orange, c, r, r=0) for c, r in far[inside]]
        assert inside.sum() > 100 and 0.5 < np.mean(on) < 0.9    # dashed: not all the way
        assert not _near(red, *pic.to_px(x + 0.5 * ring_r, y - 0.5 * ring_r), r=1)
    # the legend names the reach's two parts: the GP2D12's 624 mm is not the circle's 774
    assert pic.legend == ["unknown", "free", "occupied", "true walls / obstacles",
                          "ring at scan pose (number = order)",
                          "sensor reach (ring 150 + range 624 mm)"]
    # the title above the axes: dark text, and nothing but white beside it
    band = img[:int(T) - 2, int(L):int(R)].min(axis=2)
    assert np.count_nonzero(band < 100) > 100


def test_frames_show_the_poses_scanned_so_far_and_end_as_the_png(t_room_run, tmp_path):
    from PIL import Image

    paths = pipeline.write_outputs(t_room_run, tmp_path)
    gif = Image.open(paths["animation"])
    png = np.asarray(Image.open(paths["map_png"]).convert("RGB"), int)
    assert gif.n_frames == 25 and gif.size == png.shape[1::-1]
    pic = _picture(t_room_run)
    centres = [pic.to_px(x, y + 0.15) for x, y, *_ in t_room_run.poses]   # on each ring
    frames = []
    for k in (0, 1, 6, 24):
        gif.seek(k)
        frames.append(np.asarray(gif.convert("RGB"), int))
    shown = [[_near(_hue(f, render.POSE_COLOR), *c, r=1) for c in centres] for f in frames]
    assert shown == [[False] * 4, [True, False, False, False],
                     [True, False, False, False], [True] * 4]
    # the first frame is all unknown inside the walls; the last is the PNG, in the palette
    mid = pic.to_px(1.2, 1.5)
    assert tuple(frames[0][int(mid[1]), int(mid[0])]) == (191, 191, 191)
    L, T, R, B = pic._box
    diff = np.abs(frames[-1] - png)[int(T):].max(axis=2)    # (the caption is not the title)
    assert np.mean(diff) < 2.0 and np.mean(diff > 40) < 0.002
    # each frame's caption where the title goes
    band = lambda f: f[:int(T) - 2, int(L):int(R)].min(axis=2) < 100  # noqa: E731
    assert band(frames[0]).sum() > 50 and np.any(band(frames[0]) != band(frames[1]))


def test_rendering_leaves_the_users_matplotlib_alone(t_room_run, tmp_path):
    import matplotlib

    before = matplotlib.get_backend()
    matplotlib.use("svg")           # as a notebook would have its own backend
    try:
        pipeline.write_outputs(t_room_run, tmp_path)
        t_room_run._repr_png_()
        assert matplotlib.get_backend() == "svg"
        import matplotlib.pyplot as plt

        assert plt.get_fignums() == []
    finally:
        matplotlib.use(before)


def test_irring_run_pictures_do_not_load_matplotlib(tmp_path):
    # matplotlib's start-up costs a fresh `irring run` more than making the map
    code = ("import sys; from irring import pipeline; from irring.scenario import load_scenario; "
            "r = pipeline.run(load_scenario('t_room_cylinder'), progress=False, "
            "frames_per_sweep=2); pipeline.write_outputs(r, sys.argv[1]); r._repr_png_(); "
            "print('matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path)], check=True,
                         capture_output=True, text=True)
    assert out.stdout.strip() == "False"
    assert (tmp_path / "map_building.gif").stat().st_size > 10_000


def test_a_maprun_shows_its_map_inline(t_room_run):
    from PIL import Image

    data = t_room_run._repr_png_()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    img = np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))
    assert 500 < img.shape[1] < 700            # as map.png, at 80 dpi instead of 110
    assert _hue(img, render.POSE_COLOR).sum() > 300 and _hue(img, render.TRUTH_COLOR).sum() > 300


def test_a_tall_map_is_drawn_narrower_not_taller_and_cells_stay_square():
    from irring.maps.mapping import OccupancyGrid

    grid = OccupancyGrid((-0.15, 0.2), (310, 70), 0.01)     # 0.7 m × 3.1 m, off the origin
    classes = np.full(grid.shape, -1, np.int8)
    classes[:, :35] = 1                                      # the left half occupied
    pic = render.MapPicture(grid, poses=[(0.1, 1.3)], reach_m=0.4)
    img = pic.rgb(classes)
    assert img.shape[0] <= (render.MAX_MAP_HEIGHT_IN + 1.5) * render.PNG_DPI
    (c0, r0), (c1, r1) = pic.to_px(-0.15, 0.2), pic.to_px(0.55, 3.3)
    assert (c1 - c0) / (r0 - r1) == pytest.approx(0.7 / 3.1)   # equal scale on x and y
    # the boundary between the halves at x = 0.2 m, at any height
    for y in (0.5, 1.9, 3.0):
        (cl, row), (cr, _) = pic.to_px(0.18, y), pic.to_px(0.22, y)
        assert tuple(img[int(row), int(cl)]) == (0, 0, 0)
        assert tuple(img[int(row), int(cr)]) == (191, 191, 191)


def test_a_tiny_map_gets_a_scale_bar_that_fits_and_its_end_labels_whole():
    from irring.maps.mapping import OccupancyGrid

    grid = OccupancyGrid((0.3, -0.2), (4, 6), 0.01)        # 6 × 4 cm
    pic = render.MapPicture(grid, title="tiny")
    img = pic.rgb(grid.classify(), "tiny").min(axis=2)
    L, T, R, B = pic._box
    # the bar: 10 mm (a fifth of the map at most), its black inside the axes' upper left
    assert render._round_below(0.06 / 5) == 0.01
    bar_row = img[int(T) + 5:int(T) + 25, :]
    dark_cols = np.flatnonzero((bar_row < 50).sum(axis=0) >= 2)
    inside = dark_cols[(dark_cols > L + 3) & (dark_cols < R - 3)]
    assert 0.01 * pic.scale * 0.9 < inside.max() - inside.min() < 0.01 * pic.scale * 1.3
    # the end tick's label (0.36) sticks out past the axes and is kept whole, with white
    # margin beyond it
    below = img[int(B) + 8:int(B) + 30]
    assert np.any(below[:, int(R) + 4:] < 100) and np.all(img[:, -3:] == 255)
    assert [render._round_below(v) for v in (2.65 / 5, 0.16, 7.3)] == [0.5, 0.1, 5.0]


def test_a_pose_with_no_place_gets_no_marks_and_the_others_theirs():
    from irring.maps.mapping import OccupancyGrid

    grid = OccupancyGrid((0, 0), (100, 200), 0.01)
    poses = [(0.5, 0.5), (float("nan"), 0.5), (1.4, 0.3)]
    pic = render.MapPicture(grid, poses=poses, reach_m=0.3)
    img = pic.rgb(grid.classify()).astype(int)
    red = _hue(img, render.POSE_COLOR)
    assert _near(red, *pic.to_px(0.5 + 0.15, 0.5)) and _near(red, *pic.to_px(1.4, 0.3 - 0.15))
    assert [len(layers) for layers in pic._poses] == [2, 0, 2]


def test_ticks_fall_on_round_metres():
    # the T-room's x axis at 287 px/m, ticks ≥ 110 px apart: every 0.5 m from 0
    ticks, step = render._ticks(-0.1, 2.55, 287.0, 110.0)
    assert step == 0.5 and ticks == [0.0, 0.5, 1.0, 1.5, 2.0, 2.5]
    ticks, step = render._ticks(-0.35, 0.9, 287.0, 66.0)
    assert step == 0.25 and ticks == [-0.25, 0.0, 0.25, 0.5, 0.75]
    assert [render._tick_label(v, 0.25) for v in (-0.25, 0.5)] == ["-0.25", "0.50"]
    assert render._tick_label(1.0, 0.5) == "1.0" and render._tick_label(20.0, 10) == "20"


def test_pose_numbers_clear_each_other_when_poses_crowd():
    # eleven sweeps 10 cm apart along a line and back, as a moving scan makes: rings overlap
    poses = [(0.3 + 0.1 * k, 0.5 + 0.02 * (k % 2)) for k in range(8)] + \
        [(0.95 - 0.1 * k, 0.51) for k in range(3)]
    assert render.crowded(poses, 0.15)
    label = 0.06
    offsets = render.label_offsets(poses, 0.15, (0, 2, 0, 1.2), label)
    assert offsets[0] is not None and offsets[-1] is not None   # where it starts and ends
    shown = [k for k, o in enumerate(offsets) if o is not None]
    assert 4 <= len(shown) < 11          # the poses retraced go unnumbered
    centres = np.array([np.add(poses[k], offsets[k]) for k in shown])
    gaps = np.abs(centres[:, None] - centres[None]).max(axis=2) + np.eye(len(shown)) * 9
    assert gaps.min() >= label * 0.99    # no number on another
    dots = np.abs(centres[:, None] - np.array(poses)[None]).max(axis=2)
    assert dots.min() >= label * 0.6     # nor on a pose
    # apart, a pose keeps its number inside its ring, above the centre
    apart = [(1.0, 0.7), (0.4, 0.3)]
    assert not render.crowded(apart, 0.15)
    (dx, dy), _ = render.label_offsets(apart, 0.15, (0, 2, 0, 1.2), label)
    assert dx == 0 and 0 < dy < 0.15


def test_render_bench_times_fresh_processes_and_counts_the_frames(capsys, tmp_path,
                                                                   monkeypatch):
    from irring.studies import render_bench, report

    # run from a folder holding another irring (a checkout beside `pip install .`): its
    # fresh processes still run this one (`python -m` ran the folder's, kernels unbuilt)
    (tmp_path / "irring").mkdir()
    (tmp_path / "irring" / "__init__.py").write_text("raise ImportError('not this irring')\n")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match="repeats must be ≥ 1, got 0"):
        render_bench.measure("t_room_cylinder", repeats=0)
    r = render_bench.measure("t_room_cylinder", repeats=1, progress=True)
    assert "bench render:   0%" in capsys.readouterr().err   # the bar asked for, over 1 repeat
    assert (r["poses"], r["frames"]) == (1, 1 + pipeline.FRAMES_PER_SWEEP)
    assert r["cpu_render_s"] > 0 and r["cpu_make_map_s"] > 0
    assert r["render_vs_make_map_cpu"] == r["cpu_render_s"] / r["cpu_make_map_s"]
    assert 50 < r["peak_memory_mb"] < 1024
    assert "render / making the map: cpu" in render_bench.report(r)
    # the command as a user runs it: that work plus the interpreter, imports and parser
    assert len(r["wall_irring_run_all_s"]) == 1 and r["wall_irring_run_s"] > 0
    assert r["cpu_irring_run_s"] > r["cpu_make_map_s"] + r["cpu_render_s"]
    assert "whole command `irring run t_room_cylinder`: wall" in render_bench.report(r)
    # how busy the machine was, before and after, in the words every benchmark uses
    assert len(r["load_before"]) == len(r["load_after"]) == 3
    assert render_bench.report(r).splitlines()[-1] == report.load_line(
        r["load_before"], r["load_after"], r["cpus"])


def test_the_memory_survey_is_the_t_room_seen_from_300_poses():
    """docs/survey300.yaml, the README's 300-pose memory figure: it loads, it is the T-room's
    outline, and its 300 poses are distinct and inside the bar of the T."""
    from pathlib import Path

    survey = load_scenario(str(Path(__file__).parents[1] / "docs" / "survey300.yaml"))
    t_room = load_scenario("t_room")
    assert survey.room.outline_m == t_room.room.outline_m
    xy = np.array([(p.x_m, p.y_m) for p in survey.robot.poses])
    assert xy.shape == (300, 2) and len(np.unique(xy, axis=0)) == 300
    assert xy[:, 0].min() > 0.15 and xy[:, 0].max() < 2.42 - 0.15
    assert xy[:, 1].min() > 0.15 and xy[:, 1].max() < 0.90 - 0.15


def test_a_long_thin_room_is_drawn_as_a_strip_with_its_walls_and_pose():
    """A 30 m × 0.4 m corridor (a hostile tester's file) left the axes a negative height
    and the render a math domain error after all the work; it is drawn as a thin strip."""
    from PIL import Image

    from irring.maps.mapping import OccupancyGrid
    from irring.scenario import loads

    sc = loads("""
name: corridor
room: {outline_mm: [[0, 0], [30000, 0], [30000, 400], [0, 400]]}
robot: {poses: [{x_mm: 300, y_mm: 170}]}
""", source="corridor.yaml")
    grid = OccupancyGrid.for_scenario(sc)
    pic = render.MapPicture(grid, sc, [np.array([0.3, 0.17, 0.0])], 0.62, 0.15)
    img = pic.rgb(grid.classify(), "corridor").astype(int)
    height, width = img.shape[:2]
    assert height < width / 3
    png = Image.open(io.BytesIO(pic.png_bytes(grid.classify())))
    assert png.height < png.width / 3
    L, T, R, B = pic._box
    assert B - T > 2 and R - L > 0.8 * width
    blue, red = _hue(img, render.TRUTH_COLOR), _hue(img, render.POSE_COLOR)
    for x in (9.0, 15.0, 29.0):          # the long walls, past the scale bar's box
        assert _near(blue, *pic.to_px(x, 0.0)) and _near(blue, *pic.to_px(x, 0.4)), x
    assert _near(red, *pic.to_px(0.3, 0.17), r=4)


def test_a_flat_map_keeps_its_scale_bar_below_the_axes_off_the_poses():
    # in a 6 m × 0.42 m corridor the bar's box in the axes' corner hid the first pose's
    # ring and number and a third of the strip's height; it goes right of the x label
    from irring.maps.mapping import OccupancyGrid
    from irring.scenario import loads

    sc = loads("""
name: corridor6
room: {outline_mm: [[0, 0], [6000, 0], [6000, 420], [0, 420]]}
robot: {poses: [{x_mm: 800, y_mm: 210}, {x_mm: 3100, y_mm: 215}]}
""", source="corridor6.yaml")
    grid = OccupancyGrid.for_scenario(sc)
    poses = [np.array([0.8, 0.21, 0.0]), np.array([3.1, 0.215, 0.0])]
    pic = render.MapPicture(grid, sc, poses, 0.624, 0.15)
    img = pic.rgb(grid.classify(), "corridor6").astype(int)
    L, T, R, B = pic._box
    red = _hue(img, render.POSE_COLOR)
    c, r = pic.to_px(0.8, 0.21)
    for dx, dy in ((0.15, 0.0), (-0.15, 0.0), (0.0, 0.15)):     # pose 1's ring all round
        assert _near(red, *pic.to_px(0.8 + dx, 0.21 + dy), r=3), (dx, dy)
    # the 1 m bar: a black line 1 m long below the axes, ending at their right edge
    half = int((L + R) / 2 + 0.5 * pic.scale)                   # right of the x label
    below = img[int(B) + 20:, half:int(R) + 1].min(axis=2) < 50
    spans = [np.ptp(np.flatnonzero(row)) if row.any() else 0 for row in below]
    bar = [k for k, w in enumerate(spans)                  # the bar, not its wider frame
           if 0.97 * pic.scale < w < 1.04 * pic.scale and below[k].sum() > 0.95 * w]
    assert len(bar) >= 2
    assert abs(half + np.flatnonzero(below[bar[0]]).max() - R) < 0.15 * pic.scale


def test_map_title_gives_the_scores_as_the_summary_does(t_room_run):
    """map.png's title rounded to two places (F1 0.99) where `irring run` printed 0.995: both
    now format a score in one place, core.score_text."""
    from irring.cli.run import summary_lines

    s = t_room_run.scores
    title = pipeline._title(t_room_run)
    lines = summary_lines(t_room_run, {})
    for key, said in (("occupied_f1", "occupied  F1 {}"), ("free_accuracy", "accuracy {}"),
                      ("coverage", "coverage {}")):
        text = score_text(s[key])
        assert len(text) == 5 and float(text) == round(s[key], 3)   # three decimals
        assert any(said.format(text) in ln for ln in lines), (key, lines)
        assert f"{key.replace('occupied_f1', 'occupied F1').replace('_', ' ')} {text}" in title
    assert s["shadow"] is None and title.endswith("shadow n/a")   # the T-room hides nothing
    assert [score_text(v) for v in (0.99549, 0.99551, 1.0, 0.0, None)] == \
        ["0.995", "0.996", "1.000", "0.000", "n/a"]


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="Linux's VmHWM")
def test_a_fresh_process_peak_is_its_own_not_its_big_parents():
    """bench render's, study's and the scaling bench's peak memory is the measured process's
    own: a child started by a process holding ~600 MB (a test session) inherited that as
    ru_maxrss through exec (the suite's render bench read 1026 MB for one pose)."""
    big = np.ones(600 * 2**20 // 8)   # ~600 MB, touched
    code = ("import resource; from irring.studies.report import peak_memory_mb; "
            "print(peak_memory_mb(), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)")
    own, inherited = map(float, subprocess.run([sys.executable, "-c", code], check=True,
                                               capture_output=True, text=True).stdout.split())
    assert big.sum() == big.size
    assert inherited > 600          # what ru_maxrss said
    assert 10 < own < 300           # an interpreter with numpy, not its parent
