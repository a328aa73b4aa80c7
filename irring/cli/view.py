"""`irring view SCENARIO`: the MuJoCo scene with the ring's beams, as a picture or live."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from .. import errors
from ..core import VIEW_BASE_BYTES, VIEW_BYTES_PER_PIXEL, WORK_MEMORY_BYTES, work_refusal
from ..errors import OutputError, TooBig
from ..outputs import (VIEW_FILE, VIEW_IN_FOLDER, VIEW_SOFTWARE, atomic_file, check_out,
                       check_replaceable, folder_name, folder_note)
from ..scenario import DEFAULT_SCENARIO, load_scenario
from ..simulation import gl
from ._common import add_pose_option, describe, out_path, pose_index, scenario_name

# --size's bounds: each side, and the pixels in all that fit the memory irring view may use
SIDE_PIXELS = (16, 8192)
MAX_PIXELS = (WORK_MEMORY_BYTES - VIEW_BASE_BYTES) // VIEW_BYTES_PER_PIXEL

HELP = """\
Show the scenario's MuJoCo scene: the room, the obstacles, the ring at one scan pose and
motor step, and its beams, one per sensor (green to where they hit, a red mark on each hit; grey
where nothing is within the sensor's range).

With --out, or without a display, the picture is rendered offscreen (EGL or OSMesa, no
display needed; MUJOCO_GL=egl|osmesa picks one) and written as a PNG (default without a
display: ./out/<scenario>/view.png, in the folder `irring run` writes), captioned along its
foot with the scenario, pose, step and what the colours mean (not under 400 × 300 pixels;
the caption is also the PNG's Description). With a display and
no --out, MuJoCo's interactive viewer opens and plays the sweep, beams drawn, until you
close it; a DISPLAY that cannot be opened (a forwarded X display gone) is said on stderr
and the picture written instead.

examples:
  irring view t_room_cylinder --out cyl.png        # the picture, headless
  irring view t_room --pose 4 --step -35           # live viewer at the 4th scan pose
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, HELP)
    p.add_argument("scenario", nargs="?", default=None, metavar="SCENARIO",
                   type=scenario_name,
                   help="bundled scenario name or YAML path (default: t_room)")
    add_pose_option(p, 1, "where the robot stands")
    p.add_argument("--step", type=int, default=0, metavar="S",
                   help="motor step, within the ring's limits (the paper's ring: -35 … 35; "
                        "default: 0, the sensors facing outwards)")
    p.add_argument("--out", type=out_path, default=None, metavar="FILE.png",
                   help="write the picture here instead of opening the viewer (a name "
                        "without .png is a folder: view.png inside it); a FILE.png there "
                        "already is replaced only if irring view drew it, and view.png in a "
                        "folder only if it is a PNG no other program drew")
    p.add_argument("--size", default="1280x960", metavar="WxH",
                   help=f"picture size in pixels, {SIDE_PIXELS[0]} … {SIDE_PIXELS[1]} each "
                        f"and at most {MAX_PIXELS:,} in all (the "
                        f"{WORK_MEMORY_BYTES / 1e9:g} GB irring view may use; default: "
                        "1280x960)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    gl.check_chosen_library()   # importing MuJoCo loads the library MUJOCO_GL names
    from ..simulation import view   # deferred: loads MuJoCo, which --help does not need

    scenario = load_scenario(args.scenario or DEFAULT_SCENARIO)
    lo, hi = SIDE_PIXELS
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
        if not (lo <= width <= hi and lo <= height <= hi):
            raise ValueError
    except ValueError:
        print(f"irring view: error: --size must be WIDTHxHEIGHT in pixels, {lo} … {hi} each, "
              f"like 1280x960; got {args.size!r}", file=sys.stderr)
        return 2
    pose = pose_index(args.pose, scenario)
    try:
        scene = view.SceneView(scenario, pose=pose, step=args.step)
    except ValueError as exc:
        print(f"irring view: error: --step: {exc}", file=sys.stderr)
        return 2
    if args.out is None:
        problem = view.display_problem()
        if problem is None:
            view.play(scene)
            return 0
        if problem != "no display":   # a display was named: say why no window opens
            print(f"irring view: {problem}; writing the picture instead", file=sys.stderr)
    refusal = size_refusal(width, height)   # the picture's, not the live viewer's window
    if refusal:
        raise TooBig(refusal)
    out = picture_path(args.out if args.out is not None else Path("out") / folder_name(scenario.name))
    # a FILE.png named by --out may be anyone's; view.png (in out/<scenario>/ or the --out
    # folder) is view's by its name, if a PNG no other program drew
    named = out == args.out
    check_replaceable(out, "--out", VIEW_FILE if named else VIEW_IN_FOLDER)   # before rendering
    try:
        image = view.render(scene, width, height)
    except RuntimeError as exc:
        print(f"irring view: error: {exc}", file=sys.stderr)
        return 1
    b = scene.beams
    ring = scene.sim.ring
    x, y, _ = scene.sim.pose(scene.pose_index)
    turned = math.degrees(scene.step * ring.motor_step_rad * ring.gear)
    said = (f"{scenario.name}, pose {args.pose} ({x * 1e3:.0f}, {y * 1e3:.0f}) mm, motor step "
            f"{scene.step} (sensors turned {turned:+.1f}°): beams green to their hits (red), "
            f"grey where nothing is within {b.max_range_m * 1000:.0f} mm")
    path = write_png(caption(image, errors.printable(said)), out, own=named,
                     description=said)
    print(f"wrote {errors.printable(str(path))}: {scenario.name}, pose {args.pose}, motor step {scene.step}; "
          f"{int(b.hits.shape[0])} of {b.distance_m.size} beams hit within "
          f"{b.max_range_m * 1000:.0f} mm")
    note = None if args.out is not None else \
        folder_note(scenario.name, out.parent, "the scenario named")
    if note:
        print(f"note: {note}")
    return 0


def size_refusal(width: int, height: int) -> str | None:
    """Why a ``width`` × ``height`` picture is too big to render (:func:`work_refusal`'s
    wording), or None."""
    return work_refusal(f"--size {width}x{height}: a picture of {width * height:,} pixels",
                        VIEW_BASE_BYTES + width * height * VIEW_BYTES_PER_PIXEL, "irring view",
                        f"choose at most {MAX_PIXELS:,} pixels (4096x3072 is 12,582,912)")


def picture_path(out: Path) -> Path:
    """The PNG ``--out`` names: the file itself when it ends in .png, else view.png in that
    folder. Checked before any rendering. Raises OutputError (a suffix other than .png, a
    folder that cannot be made or written)."""
    try:
        is_dir = out.is_dir()
    except OSError as exc:   # a name longer than the file system takes
        raise OutputError(f"--out {out}: cannot be written: {exc.strerror or exc}") from None
    if out.suffix.lower() == ".png":
        if is_dir:
            raise OutputError(f"--out {out}: is a folder; name a .png file or the folder "
                              "without .png")
        check_out(out.parent)
        return out
    if out.suffix and not is_dir:
        raise OutputError(f"--out {out}: a picture is written as PNG; name a .png file or a "
                          "folder (view.png inside it)")
    return check_out(out) / "view.png"


# a caption needs room: on a smaller picture its words would cover what it shows
CAPTION_MIN_PX = (400, 300)


def caption(image, text: str):
    """``image`` (H×W×3 uint8) with ``text`` in white on a darkened band along its foot,
    wrapped to its width (at most a quarter of its height; what does not fit ends in "…"),
    so the picture read alone says what it shows. One smaller than CAPTION_MIN_PX is
    returned as it is."""
    from PIL import Image, ImageDraw   # deferred: Pillow, only to save a picture

    from ..maps.render import font   # deferred: Pillow's fonts, only for a picture

    h, w = image.shape[:2]
    if w < CAPTION_MIN_PX[0] or h < CAPTION_MIN_PX[1]:
        return image
    size = max(12, round(h / 48))          # 20 px on a 960-pixel picture
    face, pad = font(size), size // 2
    measure = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    lines: list[str] = []
    for word in text.split(" "):
        if lines and measure.textlength(f"{lines[-1]} {word}", font=face) <= w - 2 * pad:
            lines[-1] += f" {word}"
        else:
            lines.append(word)
    step = round(size * 1.3)
    fits = max(1, (h // 4 - 2 * pad) // step)
    if len(lines) > fits:
        lines = lines[:fits - 1] + [lines[fits - 1] + " …"]
    band = len(lines) * step + 2 * pad
    out = np.array(image, copy=True)
    out[h - band:] = (out[h - band:] * 0.3).astype(out.dtype)
    picture = Image.fromarray(out)
    draw = ImageDraw.Draw(picture)
    for k, line in enumerate(lines):
        draw.text((pad, h - band + pad + k * step), line, fill=(255, 255, 255), font=face)
    return np.asarray(picture)


def write_png(image, path: Path, own: bool = True, description: str = "") -> Path:
    """``image`` (H×W×3 uint8) to ``path`` as PNG, whole or not at all, naming irring view in
    its Software field (and ``description`` in its Description). With ``own`` it replaces
    only a picture irring view drew (or an empty file); else (view.png in view's folder)
    also a PNG naming no program. Raises OutputError."""
    from PIL import Image, PngImagePlugin   # deferred: Pillow, only to save a picture

    info = PngImagePlugin.PngInfo()
    info.add_text("Software", VIEW_SOFTWARE)
    if description:
        info.add_text("Description", description)
    with atomic_file(path, "--out", VIEW_FILE if own else VIEW_IN_FOLDER) as tmp:
        Image.fromarray(image).save(tmp, format="PNG", pnginfo=info)
    return path
