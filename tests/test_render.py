"""Map pictures: animation frames composed with numpy look like matplotlib's drawing of the
same figure, are streamed (counted, thinned for long runs), leave the caller's matplotlib
alone, and pose numbers never sit on each other."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

from irring import pipeline  # noqa: E402
from irring.maps import render  # noqa: E402
from irring.scenario import load_scenario  # noqa: E402


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


def _matplotlib_drawing(run, classes, shown, dpi):
    """The figure as matplotlib alone draws it: the reference the composed frames match."""
    mf = render.MapFigure(run.grid, run.scenario, run.poses, *pipeline._reach(run), "",
                          dpi=dpi)
    mf.image.set_data(render.map_rgb(classes))
    for k, arts in enumerate(mf.pose_artists):
        for a in arts:
            a.set_visible(k < shown)
    mf.fig.canvas.draw()
    return np.asarray(mf.fig.canvas.buffer_rgba())[..., :3].astype(int)


@pytest.mark.parametrize("frame_no", [3, 12, 24])
def test_composed_frames_look_like_matplotlibs_drawing(t_room_run, frame_no):
    frames = list(pipeline.building_frames(t_room_run))
    anim = render.MapAnimator(t_room_run.grid, t_room_run.scenario, t_room_run.poses,
                              *pipeline._reach(t_room_run))
    for f in frames[:frame_no]:
        anim.frame(*f)
    classes, shown, _ = frames[frame_no]
    got = np.asarray(anim.palette_image(anim.frame(classes, shown, "")).convert("RGB"), int)
    want = _matplotlib_drawing(t_room_run, classes, shown, render.PNG_DPI)
    assert got.shape == want.shape
    diff = np.abs(got - want).max(axis=2)
    # the same picture: a GIF palette's rounding everywhere, a handful of edge pixels more
    assert np.mean(diff) < 3.0
    assert np.mean(diff > 40) < 0.002
    # and it is the map: as many pixels of each cell colour as matplotlib puts there (±1 %)
    for rgb in ((191, 191, 191), (255, 255, 255), (0, 0, 0)):
        n_got = np.count_nonzero(np.all(np.abs(got - rgb) <= 4, axis=2))
        n_want = np.count_nonzero(np.all(np.abs(want - rgb) <= 4, axis=2))
        assert n_got == pytest.approx(n_want, rel=0.01, abs=50), rgb


def test_gif_and_png_written_and_the_users_matplotlib_left_alone(t_room_run, tmp_path):
    import matplotlib
    from PIL import Image

    before = matplotlib.get_backend()
    matplotlib.use("svg")           # as a notebook would have its own backend
    try:
        paths = pipeline.write_outputs(t_room_run, tmp_path)
        assert matplotlib.get_backend() == "svg"
        import matplotlib.pyplot as plt

        assert plt.get_fignums() == []
    finally:
        matplotlib.use(before)
    gif = Image.open(paths["animation"])
    assert gif.n_frames == 25 and gif.size[0] > 800
    first = np.asarray(gif.convert("RGB"), int)
    png = np.asarray(Image.open(paths["map_png"]).convert("RGB"), int)

    def pixels(img, color):   # pixels of that hue (outlines blend with what lies under)
        rgb = np.array(matplotlib.colors.to_rgb(color))
        chroma = img - img.min(axis=2, keepdims=True)
        want = (rgb - rgb.min()) / np.ptp(rgb)
        close = np.abs(chroma / np.maximum(chroma.max(axis=2, keepdims=True), 1) - want)
        return np.count_nonzero((chroma.max(axis=2) > 60) & np.all(close < 0.2, axis=2))

    # the true outline before anything is mapped (later the walls' cells cover it); the
    # poses and their reach on the final picture
    assert pixels(first, render.TRUTH_COLOR) > 1000
    assert pixels(png, render.POSE_COLOR) > 1000 and pixels(png, render.RANGE_COLOR) > 1000
    assert pixels(first, render.POSE_COLOR) < 200     # no pose scanned yet (legend only)


def test_a_maprun_shows_its_map_inline(t_room_run):
    data = t_room_run._repr_png_()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000


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


def test_render_bench_times_fresh_processes_and_counts_the_frames():
    from irring.studies import render_bench

    with pytest.raises(ValueError, match="repeats must be ≥ 1, got 0"):
        render_bench.measure("t_room_cylinder", repeats=0)
    r = render_bench.measure("t_room_cylinder", repeats=1)
    assert (r["poses"], r["frames"]) == (1, 1 + pipeline.FRAMES_PER_SWEEP)
    assert r["cpu_render_s"] > 0 and r["cpu_make_map_s"] > 0
    assert r["render_vs_make_map_cpu"] == r["cpu_render_s"] / r["cpu_make_map_s"]
    assert 50 < r["peak_memory_mb"] < 1024
    assert "render / making the map: cpu" in render_bench.report(r)
    # the command as a user runs it: that work plus the interpreter, imports and parser
    assert len(r["wall_irring_run_all_s"]) == 1 and r["wall_irring_run_s"] > 0
    assert r["cpu_irring_run_s"] > r["cpu_make_map_s"] + r["cpu_render_s"]
    assert "whole command `irring run t_room_cylinder`: wall" in render_bench.report(r)
