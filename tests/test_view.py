"""`irring view`: the MuJoCo scene rendered offscreen with no display — walls, beams and hit
marks where they must be — and clear errors for a bad pose or step."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

from irring.simulation import view  # noqa: E402
from irring.cli import main  # noqa: E402
from irring.scenario import load_scenario  # noqa: E402


def _offscreen_or_skip():
    try:
        view.gl_backend()
    except RuntimeError as exc:     # .ci/system-deps installs libosmesa6; a bare machine may lack it
        pytest.skip(str(exc))


def test_cli_writes_a_picture_headless_and_leaves_no_mujoco_log(tmp_path, monkeypatch, capsys):
    _offscreen_or_skip()
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", "t_room", "--out", "view.png", "--size", "640x480"]) == 0
    assert "9 of 12 beams hit within 624 mm" in capsys.readouterr().out
    from PIL import Image

    img = np.asarray(Image.open(tmp_path / "view.png").convert("RGB"), int)
    assert img.shape == (480, 640, 3) and img.std() > 20
    green = (img[..., 1] > 150) & (img[..., 0] < 100) & (img[..., 2] < 120)
    assert np.count_nonzero(green) > 300          # the beams
    assert sorted(p.name for p in tmp_path.iterdir()) == ["view.png"]   # no MUJOCO_LOG.TXT
    # without --out and without a display: the picture goes to out/<scenario>/view.png
    assert main(["view", "t_room_cylinder", "--step", "-35", "--size", "320x240"]) == 0
    assert (tmp_path / "out" / "t_room_cylinder" / "view.png").stat().st_size > 0
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_each_hit_is_marked_or_behind_a_wall_never_on_bare_floor():
    _offscreen_or_skip()
    scene = view.SceneView(load_scenario("t_room_cylinder"), pose=0, step=10)
    b = scene.beams
    # the true ranges at step 10: the table leg at 0.30 m, walls, three beams with no return
    assert np.count_nonzero(np.isnan(b.distance_m)) == 3
    img = view.render(scene, 800, 600).astype(int)
    px = np.round(scene.last_camera(b.hits)).astype(int)
    inside = (px[:, 0] >= 1) & (px[:, 0] < 799) & (px[:, 1] >= 1) & (px[:, 1] < 599)
    assert inside.all()
    colours = np.array([img[r - 1:r + 2, c - 1:c + 2].reshape(-1, 3).mean(0) for c, r in px])
    red = (colours[:, 0] > 180) & (colours[:, 1] < 90) & (colours[:, 2] < 90)
    # a wall face is neutral grey; the floor is blue-grey (its blue well above its red)
    floor = colours[:, 2] - colours[:, 0] > 15
    assert np.count_nonzero(red) >= 4 and not floor.any()
    # a point of bare floor between the ring and the leg is floor-coloured
    x, y, _ = scene.sim.pose(0)
    (c, r), = np.round(scene.last_camera([[x - 0.3, y + 0.25, 0.0]])).astype(int)
    assert img[r, c, 2] - img[r, c, 0] > 15


def test_bad_pose_or_step_names_what_is_allowed(capsys):
    assert main(["view", "t_room", "--pose", "5", "--out", "x.png"]) == 2
    assert "--pose 5 is out of range: scenario 't_room' has 4 scan pose(s), 1 … 4" in \
        capsys.readouterr().err
    assert main(["view", "t_room", "--step", "36", "--out", "x.png"]) == 2
    assert "motor step 36 is out of range: the ring turns from step -35 to 35" in \
        capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["view", "t_room", "--pose", "0"])


def test_out_without_png_is_a_folder_and_an_unwritable_out_exits_4(tmp_path, monkeypatch, capsys):
    _offscreen_or_skip()
    monkeypatch.chdir(tmp_path)
    assert main(["view", "t_room", "--out", "pics", "--size", "48x32"]) == 0
    assert capsys.readouterr().out.startswith("wrote pics/view.png: t_room, pose 1")
    from PIL import Image

    assert Image.open(tmp_path / "pics" / "view.png").size == (48, 32)
    (tmp_path / "afile").write_text("mine")
    (tmp_path / "d.png").mkdir()
    for out, why in [("a.jpg", "--out a.jpg: a picture is written as PNG"),
                     ("afile/x.png", "--out afile: is a file"),
                     ("d.png", "--out d.png: is a folder")]:
        assert main(["view", "t_room", "--out", out, "--size", "48x32"]) == 4, out
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and why in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "d.png", "pics"]
    assert (tmp_path / "afile").read_text() == "mine" and not any((tmp_path / "d.png").iterdir())


def test_the_camera_frames_the_room_when_the_reach_is_larger():
    """The IR ring's 0.77 m reach is what the picture frames in the T-room; a laser's 8 m
    would leave the room a speck in the middle (it did), so the room's farthest corner
    bounds the framing."""
    from irring.scenario import apply_design

    t_room = load_scenario("t_room")
    ir = view.SceneView(t_room).camera()
    assert ir.distance == pytest.approx(2.4 * (0.624 + 0.150))
    laser = view.SceneView(apply_design(t_room, "laser")).camera()
    x, y = t_room.robot.poses[0].x_m, t_room.robot.poses[0].y_m
    corners = np.asarray(t_room.room.outline_m)
    farthest = np.hypot(corners[:, 0] - x, corners[:, 1] - y).max()
    assert 1.5 < farthest < 2.5 and laser.distance == pytest.approx(2.4 * farthest)


def test_a_picture_that_cannot_be_written_leaves_no_folder_behind(tmp_path, monkeypatch, capsys):
    """A full disk while writing view.png left the empty --out folder (and its parents)
    that the command had made for it."""
    import errno

    from PIL import Image

    _offscreen_or_skip()
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine").mkdir()

    def full_disk(self, fp, *a, **k):
        raise OSError(errno.ENOSPC, "No space left on device", str(fp))

    monkeypatch.setattr(Image.Image, "save", full_disk)
    for out in ("v1", "a/b/v2", "mine/v3", "c/shot.png"):
        assert main(["view", "t_room", "--out", out, "--size", "48x32"]) == 4, out
        assert "No space left on device" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine"]
    assert not any((tmp_path / "mine").iterdir())


def _libraries(monkeypatch, *installed):
    """ctypes finds only the libraries named (OSMesa, EGL)."""
    import ctypes.util

    monkeypatch.setattr(ctypes.util, "find_library",
                        lambda name: f"lib{name}.so.1" if name in installed else None)


def test_a_mujoco_gl_naming_a_library_not_installed_says_what_to_install(
        tmp_path, monkeypatch, capsys):
    """MUJOCO_GL=osmesa on a machine without OSMesa: `import mujoco` failed inside PyOpenGL
    and `irring view` said "internal error (AttributeError: 'NoneType' object has no
    attribute 'glGetError') … please report it" (exit 70)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MUJOCO_GL", "osmesa")
    _libraries(monkeypatch, "EGL")
    assert main(["view", "t_room", "--out", "v.png"]) == 2
    assert capsys.readouterr().err == (
        "irring view: error: MUJOCO_GL=osmesa: the OSMesa library is not installed; EGL is: "
        "set MUJOCO_GL=egl or unset it, or install it (Debian: apt install libosmesa6)\n")
    monkeypatch.setenv("MUJOCO_GL", "egl")
    _libraries(monkeypatch)
    assert main(["view", "t_room", "--out", "v.png"]) == 2
    assert capsys.readouterr().err == (
        "irring view: error: MUJOCO_GL=egl: the EGL library is not installed; install it "
        "(Debian: apt install libegl1 libgl1-mesa-dri)\n")
    assert not (tmp_path / "v.png").exists()


def test_a_backend_that_cannot_make_a_context_says_what_to_use_instead(monkeypatch):
    """An EGL without a driver for a display-less device (libegl1 without
    libgl1-mesa-dri): MuJoCo's "Cannot initialize a EGL device display" ended `irring view`
    as an internal error to report (exit 70)."""
    import sys
    import types

    fake = types.ModuleType("mujoco.egl")

    class GLContext:
        def __init__(self, width, height):
            raise ImportError("Cannot initialize a EGL device display.")

    fake.GLContext = GLContext
    monkeypatch.setitem(sys.modules, "mujoco.egl", fake)
    monkeypatch.setenv("MUJOCO_GL", "egl")
    scene = view.SceneView(load_scenario("t_room"), pose=0, step=0)
    with pytest.raises(RuntimeError) as err:
        view.render(scene, 64, 48)
    assert str(err.value) == (
        "EGL cannot make an offscreen OpenGL context here (ImportError: Cannot initialize a "
        "EGL device display.); OSMesa needs no driver: install it (Debian: apt install "
        "libosmesa6) and set MUJOCO_GL=osmesa")

    def platform_at_odds(width, height):   # the user's PYOPENGL_PLATFORM: said elsewhere
        raise ImportError("Cannot use EGL: the PYOPENGL_PLATFORM environment variable …")

    fake.GLContext = platform_at_odds
    with pytest.raises(ImportError, match="PYOPENGL_PLATFORM environment variable"):
        view.render(scene, 64, 48)


def test_the_picture_says_what_it_shows(tmp_path, monkeypatch):
    """view.png had no caption: which room, pose and step, and what green, red and grey
    mean, were on stdout only. They are in a band along its foot and in the PNG's
    Description; a picture too small for words gets none."""
    _offscreen_or_skip()
    from PIL import Image

    from irring.cli import view as view_cli

    monkeypatch.chdir(tmp_path)
    said = ("t_room_cylinder, pose 1 (1920, 450) mm, motor step 10 (sensors turned +10.8°): "
            "beams green to their hits (red), grey where nothing is within 624 mm")
    assert main(["view", "t_room_cylinder", "--step", "10", "--out", "v.png",
                 "--size", "640x480"]) == 0
    png = Image.open(tmp_path / "v.png")
    assert png.info["Description"] == said
    img = np.asarray(png.convert("RGB"), int)
    band = img[-44:]        # two lines of 12 px type 16 px apart, 6 px above and below
    assert band.max() == 255 and np.count_nonzero(band.min(axis=2) > 200) > 400   # white text
    assert np.median(band) < 60                    # on a darkened band
    # the caption alone: the rest of the picture as drawn, a small one left whole
    plain = np.full((480, 640, 3), 200, np.uint8)
    captioned = view_cli.caption(plain, said)
    rows = np.flatnonzero((captioned != plain).any(axis=(1, 2)))
    assert rows.min() == 480 - 44 and rows.max() == 479
    assert view_cli.caption(plain[:299], said) is not None
    assert np.array_equal(view_cli.caption(plain[:299], said), plain[:299])
    assert np.array_equal(view_cli.caption(plain[:, :399], said), plain[:, :399])
