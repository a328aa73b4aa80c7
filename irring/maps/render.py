"""Pictures of maps: a PNG of the final map and a GIF of it being built, drawn on
matplotlib's own Agg canvas (never pyplot: the caller's backend and figures are left alone).
What the pictures show and how the GIF is streamed: docs/mapping.md.
"""

from __future__ import annotations

import functools
import io
import math
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
# loaded with the module, not per picture: pipeline.write_outputs imports this module before
# it starts the render stage's clock, as the other stages' modules load with irring
from matplotlib import font_manager
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_rgb
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch, Polygon
from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar
from PIL import Image, ImageDraw, ImageFont

from ..core import Cylinder, box_corners
from .mapping import FREE, OCCUPIED, UNKNOWN, OccupancyGrid

UNKNOWN_RGB = (0.75, 0.75, 0.75)
FREE_RGB = (1.0, 1.0, 1.0)
OCCUPIED_RGB = (0.0, 0.0, 0.0)
TRUTH_COLOR = "#1f6fd1"
POSE_COLOR = "#d62728"
RANGE_COLOR = "#ff8c00"
# each cell class's colour, indexed by class - _CLASS0 (the classes are consecutive ints)
_CLASS0 = min(UNKNOWN, FREE, OCCUPIED)
_CLASS_RGB = np.array([{UNKNOWN: UNKNOWN_RGB, FREE: FREE_RGB, OCCUPIED: OCCUPIED_RGB}[c]
                       for c in range(_CLASS0, _CLASS0 + 3)])


def figure(width_in: float, height_in: float, dpi: float = 100):
    """A matplotlib Figure on its own Agg canvas: no pyplot, so drawing it neither switches
    the caller's backend (a notebook's inline one) nor adds to pyplot's open figures."""
    fig = Figure(figsize=(width_in, height_in), dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def map_rgb(classes: np.ndarray) -> np.ndarray:
    """(ny, nx, 3) float image of a classified grid (row 0 = lowest y)."""
    return _CLASS_RGB[np.asarray(classes, np.intp) - _CLASS0]


def crowded(poses: Sequence, ring_radius_m: float) -> bool:
    """True when two poses' rings overlap (a moving scan's sweeps, a dense survey): the
    picture then draws the poses as a numbered path instead of rings and reach circles."""
    xy = np.array([[float(p[0]), float(p[1])] for p in poses]).reshape(-1, 2)
    if len(xy) < 2:
        return False
    d = np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1)) + np.eye(len(xy)) * 1e9
    return bool(d.min() < 2 * ring_radius_m)


def label_offsets(poses: Sequence, ring_radius_m: float, extent: Sequence[float],
                  label_m: float) -> list[tuple[float, float] | None]:
    """Where each pose's number goes, as an offset from the pose (metres), or None for no
    number.

    Apart (not :func:`crowded`): inside each ring, above its centre. Crowded: beside the
    pose, in the first of eight directions whose label clears every pose and every label
    placed so far, the first and last pose first; a pose with no such place goes unnumbered,
    so numbers never sit on each other or on the path. ``label_m``: a label box's size (m).
    """
    xy = np.array([[float(p[0]), float(p[1])] for p in poses]).reshape(-1, 2)
    n = len(xy)
    if not crowded(poses, ring_radius_m):
        return [(0.0, ring_radius_m * 0.35 + label_m / 2)] * n
    x0, x1, y0, y1 = extent
    dirs = np.array([(0, 1), (0, -1), (1, 0), (-1, 0), (0.71, 0.71), (-0.71, 0.71),
                     (0.71, -0.71), (-0.71, -0.71)]) * 0.75 * label_m
    out: list[tuple[float, float] | None] = [None] * n
    placed: list[np.ndarray] = []
    for k in [0, n - 1] + list(range(1, n - 1)):
        for off in dirs:
            p = xy[k] + off
            if not (x0 + label_m / 2 < p[0] < x1 - label_m / 2 and
                    y0 + label_m / 2 < p[1] < y1 - label_m / 2):
                continue
            if np.any(np.all(np.abs(xy - p) < label_m * 0.6, axis=1)):
                continue         # on a pose dot
            if placed and np.any(np.all(np.abs(np.array(placed) - p) < label_m, axis=1)):
                continue         # on another number
            out[k] = (float(off[0]), float(off[1]))
            placed.append(p)
            break
    return out


class MapFigure:
    """The map picture: the map image, the static overlays, and each pose's marks."""

    def __init__(self, grid: OccupancyGrid, scenario=None, poses: Sequence = (),
                 reach_m: float | None = None, ring_radius_m: float = 0.15, title: str = "",
                 width_in: float = 8.0, dpi: float = 100):

        x0, x1, y0, y1 = grid.extent_m
        aspect = (y1 - y0) / (x1 - x0)
        self.fig = figure(width_in, width_in * aspect * 0.9 + 1.5, dpi)
        self.grid_shape = grid.shape
        ax = self.ax = self.fig.add_subplot()
        self.image = ax.imshow(map_rgb(grid.classify()), origin="lower",
                               extent=grid.extent_m, interpolation="nearest", zorder=0)
        handles = [Patch(facecolor=UNKNOWN_RGB, edgecolor="k", lw=0.5, label="unknown"),
                   Patch(facecolor=FREE_RGB, edgecolor="k", lw=0.5, label="free"),
                   Patch(facecolor=OCCUPIED_RGB, edgecolor="k", lw=0.5, label="occupied")]
        if scenario is not None:
            ax.add_patch(Polygon(np.asarray(scenario.room.outline_m), closed=True, fill=False,
                                 ec=TRUTH_COLOR, lw=1.0, alpha=0.8, zorder=3))
            for ob in scenario.obstacles:
                if isinstance(ob, Cylinder):
                    ax.add_patch(Circle(ob.center_m, ob.radius_m, fill=False, ec=TRUTH_COLOR,
                                        lw=1.0, zorder=3))
                else:
                    ax.add_patch(Polygon(box_corners(ob), closed=True, fill=False,
                                         ec=TRUTH_COLOR, lw=1.0, zorder=3))
            handles.append(Line2D([], [], color=TRUTH_COLOR, lw=1.2,
                                  label="true walls / obstacles"))
        # a label's box: 8 pt bold digits (crowded poses), as metres on this figure
        m_per_in = (x1 - x0) / (width_in * 0.8)
        label_m = 8 / 72 * 2.0 * m_per_in
        offsets = label_offsets(poses, ring_radius_m, grid.extent_m, label_m)
        self.pose_artists = []
        self.crowded = crowded(poses, ring_radius_m)
        for k, pose in enumerate(poses):
            x, y = float(pose[0]), float(pose[1])
            if self.crowded:       # a numbered path: a dot per pose, a line from the last
                arts = [ax.plot([x], [y], "o", color=POSE_COLOR, ms=3, zorder=4)[0]]
                if k:
                    px, py = float(poses[k - 1][0]), float(poses[k - 1][1])
                    arts.append(ax.plot([px, x], [py, y], "-", color=POSE_COLOR, lw=0.8,
                                        alpha=0.7, zorder=4)[0])
            else:
                arts = [ax.add_patch(Circle((x, y), ring_radius_m, fill=False, ec=POSE_COLOR,
                                            lw=1.5, zorder=4)),
                        ax.plot([x], [y], "+", color=POSE_COLOR, ms=8, mew=1.5, zorder=4)[0]]
                if reach_m:
                    arts.append(ax.add_patch(Circle((x, y), reach_m, fill=False,
                                                    ec=RANGE_COLOR, lw=1.0, ls="--",
                                                    zorder=4)))
            if offsets[k] is not None:
                dx, dy = offsets[k]
                arts.append(ax.text(x + dx, y + dy, str(k + 1), color=POSE_COLOR,
                                    ha="center", va="center", weight="bold", zorder=5,
                                    fontsize=8 if self.crowded else 10, clip_on=True))
            self.pose_artists.append(arts)
        if len(poses) and self.crowded:
            handles.append(Line2D([], [], color=POSE_COLOR, marker="o", ms=3, lw=0.8,
                                  label="scan poses in order (numbered where room)"))
        elif len(poses):
            handles.append(Line2D([], [], color=POSE_COLOR, marker="o", ls="", mfc="none",
                                  ms=9, mew=1.5, label="ring at scan pose (number = order)"))
        if reach_m and len(poses) and not self.crowded:
            handles.append(Line2D([], [], color=RANGE_COLOR, ls="--", lw=1.0,
                                  label=f"sensor reach ({reach_m * 1000:.0f} mm)"))
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        self._scale_bar(x0, x1, y0, y1)
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3,
                  fontsize=8, frameon=False)
        self.title = ax.set_title(title, fontsize=10)
        # fixed margins (inches) where tight_layout would measure every label (a third of
        # the drawing's cost): tick labels and y label left, title top, x label and legend
        h_in = self.fig.get_figheight()
        self.fig.subplots_adjust(left=0.8 / width_in, right=1 - 0.15 / width_in,
                                 top=1 - 0.4 / h_in, bottom=1.3 / h_in)

    def _scale_bar(self, x0, x1, y0, y1) -> None:

        bar = 0.5 if x1 - x0 > 1.5 else 0.1
        self.ax.add_artist(AnchoredSizeBar(self.ax.transData, bar, f"{bar * 1000:.0f} mm",
                                           loc="upper left", pad=0.4, borderpad=0.6, sep=3,
                                           size_vertical=(y1 - y0) * 0.008, frameon=True,
                                           fontproperties={"size": 8}))

    def save(self, path, dpi: float | None = None) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        self.fig.savefig(path, dpi=dpi or PNG_DPI, bbox_inches="tight")
        return path

    def png_bytes(self, dpi: float = 80) -> bytes:
        buf = io.BytesIO()
        self.fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
        return buf.getvalue()


def save_map_png(path, grid: OccupancyGrid, scenario=None, poses: Sequence = (),
                 reach_m: float | None = None, ring_radius_m: float = 0.15,
                 title: str = "") -> Path:
    """Write the map picture (see the module doc) to ``path``."""
    return MapFigure(grid, scenario, poses, reach_m, ring_radius_m, title).save(path)


# --------------------------------------------------------------------------- animation

PNG_DPI = 110


class _Layer:
    """Straight-alpha RGBA pixels of one drawn artist group, kept sparse: flat pixel
    indices into the frame and their (n, 4) float32 colours (0 … 1)."""

    __slots__ = ("index", "rgba")

    def __init__(self, buf: np.ndarray, box: tuple[int, int, int, int]):
        r0, r1, c0, c1 = box
        patch = buf[r0:r1, c0:c1]
        rr, cc = np.nonzero(patch[..., 3])
        self.index = (rr + r0) * buf.shape[1] + (cc + c0)
        self.rgba = patch[rr, cc].astype(np.float32) / 255.0


class MapAnimator:
    """Frames of a map being built, and the final map picture, composed with numpy from
    one matplotlib drawing.

    The figure is drawn once without the map, on a transparent canvas: that is the overlay
    (axes, outlines, legend, scale bar) with each pixel's opacity; the map goes under it
    inside the axes, the figure's white outside. Each pose's marks are drawn once, alone,
    on the cleared canvas. A frame is the map's cells, upsampled by index, under the overlay
    and the poses shown so far, with a caption; colours go through one palette, so a frame
    is an index image (one byte a pixel).
    """

    def __init__(self, grid: OccupancyGrid, scenario=None, poses: Sequence = (),
                 reach_m: float | None = None, ring_radius_m: float = 0.15,
                 dpi: float = PNG_DPI):
        mf = MapFigure(grid, scenario, poses, reach_m, ring_radius_m, "", dpi=dpi)
        self._mf = mf
        canvas = mf.fig.canvas
        hidden = [mf.fig.patch, mf.ax.patch, mf.image] + [a for arts in mf.pose_artists
                                                          for a in arts]
        for a in hidden:
            a.set_visible(False)
        canvas.draw()
        layer = np.asarray(canvas.buffer_rgba()).astype(np.float32)
        self.height, self.width = layer.shape[:2]
        n = self.height * self.width
        alpha = layer[..., 3].reshape(n) / 255.0
        over = layer[..., :3].reshape(n, 3) * alpha[:, None]
        # the map lies under the overlay inside the image's box, the figure's white outside
        ny, nx = grid.shape
        x0, x1, y0, y1 = grid.extent_m
        (dx0, dy0), (dx1, dy1) = mf.ax.transData.transform([(x0, y0), (x1, y1)])
        cx = (np.arange(self.width) + 0.5 - dx0) / (dx1 - dx0) * nx
        cy = (self.height - np.arange(self.height) - 0.5 - dy0) / (dy1 - dy0) * ny
        inside = (((cy >= 0) & (cy < ny))[:, None] & ((cx >= 0) & (cx < nx))[None, :]).ravel()
        over[~inside] += (1 - alpha[~inside])[:, None] * 255
        alpha[~inside] = 1.0
        self._over, self._alpha = over, alpha
        # which cell each pixel shows (nearest, as imshow draws it), as a flat cell index
        rows = np.clip(np.floor(cy), 0, ny - 1).astype(np.intp)
        cols = np.clip(np.floor(cx), 0, nx - 1).astype(np.intp)
        self._cell = (rows[:, None] * nx + cols[None, :]).ravel()

        self._renderer = canvas.get_renderer()
        self._poses = []
        for arts in mf.pose_artists:
            self._renderer.clear()
            for a in arts:
                a.set_visible(True)
                mf.ax.draw_artist(a)
            box = self._box(arts)      # (a hidden text has no extent)
            for a in arts:
                a.set_visible(False)
            self._poses.append(_Layer(np.asarray(self._renderer.buffer_rgba()), box))
        self._font = None
        self._caption_box = None
        self._palette, self._lut = _palette()
        self._t0, self._d1, self._d2 = (np.zeros(n, np.uint8) for _ in range(3))
        self._set_tables()
        self._shown = 0

    def _box(self, artists) -> tuple[int, int, int, int]:
        """(row0, row1, col0, col1) of the pixels the artists can touch, with a margin."""
        boxes = [a.get_window_extent(self._renderer) for a in artists]
        x0 = min(b.x0 for b in boxes) - 3
        x1 = max(b.x1 for b in boxes) + 3
        y0 = min(b.y0 for b in boxes) - 3
        y1 = max(b.y1 for b in boxes) + 3
        h, w = self.height, self.width
        return (max(0, int(h - y1)), min(h, int(math.ceil(h - y0))),
                max(0, int(x0)), min(w, int(math.ceil(x1))))

    # ---- colours

    def _index(self, rgb: np.ndarray) -> np.ndarray:
        """Palette indices of RGB colours (…, 3), 0 … 255."""
        q = (np.asarray(rgb, np.float32) * np.float32(31 / 255) + np.float32(0.5)).astype(np.int32)
        np.clip(q, 0, 31, out=q)   # (premultiplied colours may round a hair past 255)
        return self._lut[(q[..., 0] * 32 + q[..., 1]) * 32 + q[..., 2]]

    def _set_tables(self, i=slice(None)) -> None:
        """Palette index of pixels ``i`` (default: all) for each cell class under the overlay,
        kept as the unknown colour plus modular (uint8) steps to the free and occupied ones.
        Only the pixels the overlay blends need a look-up per class."""
        over, alpha = self._over[i], self._alpha[i]
        t = np.empty((3, alpha.size), np.uint8)
        bare, opaque = alpha == 0, alpha == 1
        mixed = ~(bare | opaque)
        t[:, opaque] = self._index(over[opaque])
        for k, c in enumerate(_CLASS_RGB):
            t[k, bare] = self._index(np.array(c) * 255)
            t[k, mixed] = self._index(over[mixed] + (1 - alpha[mixed])[:, None] * (c * 255))
        self._t0[i], self._d1[i], self._d2[i] = t[0], t[1] - t[0], t[2] - t[0]

    # ---- frames

    def _show_poses(self, n: int) -> None:
        while self._shown < n:
            layer = self._poses[self._shown]
            _composite(self._over, self._alpha, layer)
            self._set_tables(layer.index)
            self._shown += 1

    def frame(self, classes: np.ndarray, poses_shown: int, caption: str) -> np.ndarray:
        """(height, width) palette indices: cells (int8 classes, (ny, nx)), the first
        ``poses_shown`` poses (never fewer than an earlier frame showed), the caption."""
        self._show_poses(poses_shown)
        c = np.take((np.asarray(classes) - _CLASS0).astype(np.uint8).ravel(), self._cell)
        out = self._t0 + self._d1 * (c == 1) + self._d2 * (c == 2)
        out = out.reshape(self.height, self.width)
        if caption:
            self._caption(out, classes, caption)
        return out

    def _under(self, classes, r0, r1, c0, c1) -> tuple[np.ndarray, np.ndarray]:
        """RGB (0 … 255) of a box of the picture as composed so far, and its flat indices."""
        flat = np.arange(r0, r1)[:, None] * self.width + np.arange(c0, c1)[None, :]
        cls = np.take((np.asarray(classes) - _CLASS0).astype(np.intp).ravel(), self._cell[flat])
        return self._over[flat] + (1 - self._alpha[flat])[..., None] * (_CLASS_RGB[cls] * 255), flat

    def _caption(self, out: np.ndarray, classes, caption: str) -> None:
        """Write the caption where the title goes, drawn by FreeType through Pillow in
        matplotlib's own title font and size (matplotlib's text layout would cost more
        than the rest of the frame)."""
        font, (x, y), ink = self._title_font()
        left, top, right, bottom = font.getbbox(caption, anchor="ms")
        box = (max(0, int(y + top) - 2), min(self.height, int(math.ceil(y + bottom)) + 2),
               max(0, int(x + left) - 2), min(self.width, int(math.ceil(x + right)) + 2))
        if self._caption_box is not None:   # the union, so a shorter caption clears a longer
            b = self._caption_box
            box = (min(box[0], b[0]), max(box[1], b[1]), min(box[2], b[2]), max(box[3], b[3]))
        self._caption_box = r0, r1, c0, c1 = box
        mask = Image.new("L", (c1 - c0, r1 - r0), 0)
        ImageDraw.Draw(mask).text((x - c0, y - r0), caption, fill=255, font=font, anchor="ms")
        a = np.asarray(mask, np.float32)[..., None] / 255.0
        under, _ = self._under(classes, r0, r1, c0, c1)
        out[r0:r1, c0:c1] = self._index(ink * a + under * (1 - a))

    def _title_font(self):
        """(Pillow font, the title's centre and baseline in pixels, its RGB 0 … 255): the
        title's own font file and size; its place found by laying out one title."""
        if self._font is None:

            title = self._mf.title
            title.set_text("pose 0")
            ext = title.get_window_extent(self._renderer)
            _, _, descent = self._renderer.get_text_width_height_descent(
                "pose 0", title.get_fontproperties(), ismath=False)
            title.set_text("")
            px = title.get_fontsize() * self._mf.fig.dpi / 72
            font = ImageFont.truetype(font_manager.findfont(title.get_fontproperties()), px)
            xy = ((ext.x0 + ext.x1) / 2, self.height - (ext.y0 + descent))
            self._font = font, xy, np.array(to_rgb(title.get_color()), np.float32) * 255
        return self._font

    def palette_image(self, indices: np.ndarray):
        """A frame as a Pillow palette image."""
        img = Image.frombytes("P", (self.width, self.height), np.ascontiguousarray(indices))
        img.putpalette(self._palette)
        return img

    def save_png(self, path, classes: np.ndarray, title: str = "") -> Path:
        """The map picture (:func:`save_map_png`'s) of ``classes`` with every pose and
        ``title``, composed like a frame in full colour (the title drawn by matplotlib)
        and cut to what is drawn, as ``savefig(bbox_inches="tight")`` would."""
        mf = self._mf
        over, alpha = self._over.copy(), self._alpha.copy()
        for layer in self._poses[self._shown:]:
            _composite(over, alpha, layer)
        c = np.take((np.asarray(classes) - _CLASS0).astype(np.intp).ravel(), self._cell)
        rgb = over + (1 - alpha)[:, None] * (_CLASS_RGB[c] * 255)
        for arts in mf.pose_artists:
            for a in arts:
                a.set_visible(True)
        if title:
            mf.title.set_text(title)
            self._renderer.clear()
            mf.ax.draw_artist(mf.title)
            t = _Layer(np.asarray(self._renderer.buffer_rgba()), self._box([mf.title]))
            a = t.rgba[:, 3:]
            rgb[t.index] = t.rgba[:, :3] * 255 * a + rgb[t.index] * (1 - a)
        # the tight box: everything not the figure's white, and 0.1 in around it (as
        # savefig's bbox_inches="tight" pads, measured on the pixels instead of re-laid out)
        img = (rgb.reshape(self.height, self.width, 3) + 0.5).astype(np.uint8)
        ink = np.any(img < 250, axis=2)
        rows, cols = np.flatnonzero(ink.any(axis=1)), np.flatnonzero(ink.any(axis=0))
        dpi = mf.fig.dpi
        pad = int(round(0.1 * dpi))
        r0, r1 = max(0, rows[0] - pad), min(self.height, rows[-1] + 1 + pad)
        c0, c1 = max(0, cols[0] - pad), min(self.width, cols[-1] + 1 + pad)
        img = img[r0:r1, c0:c1]
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        # zlib level 3: a third of the default level's time for a file ~10 % larger
        Image.fromarray(img).save(path, format="PNG", dpi=(dpi, dpi), compress_level=3)
        return path


@functools.lru_cache(maxsize=1)
def _palette() -> tuple[bytes, np.ndarray]:
    """The one 256-colour palette of every frame, and its 32³ RGB → index lookup table.

    Every colour a frame can show is a cell colour (unknown, free, occupied, or the figure's
    white) under at most one ink (black text and axes, the truth, pose and reach colours)
    at some coverage: those blends, 17 coverages each, are the palette; a pixel where two
    inks cross takes the nearest. Worked out once, whatever the scene.
    """
    bases = np.vstack([_CLASS_RGB, [1.0, 1.0, 1.0]]) * 255
    inks = np.array([(0.0, 0.0, 0.0)] + [to_rgb(c) for c in
                                          (TRUTH_COLOR, POSE_COLOR, RANGE_COLOR)]) * 255
    cover = np.linspace(0, 1, 17)[:, None, None, None]
    blends = cover * inks[None, :, None] + (1 - cover) * bases[None, None, :]
    pal = np.unique(np.round(blends.reshape(-1, 3)).astype(np.uint8), axis=0)[:256]
    levels = np.round(np.arange(32) * 255 / 31).astype(np.float32)
    cube = np.stack(np.meshgrid(levels, levels, levels, indexing="ij"), -1).reshape(-1, 3)
    p = pal.astype(np.float32)
    # nearest by |c - p|² = |p|² - 2 c·p (+ |c|², the same for every p): one product
    lut = ((p * p).sum(1)[None, :] - 2 * cube @ p.T).argmin(1).astype(np.uint8)
    return pal.tobytes().ljust(256 * 3, b"\0"), lut


def _composite(over: np.ndarray, alpha: np.ndarray, layer: _Layer) -> None:
    """Put a straight-alpha layer over a premultiplied (over 0 … 255, alpha) image, in place."""
    i, c = layer.index, layer.rgba
    a = c[:, 3]
    over[i] = c[:, :3] * 255 * a[:, None] + over[i] * (1 - a)[:, None]
    alpha[i] = a + alpha[i] * (1 - a)


def save_animation(path, grid: OccupancyGrid,
                   frames: Iterable[tuple[np.ndarray, int, str]], n_frames: int,
                   scenario=None, poses: Sequence = (), reach_m: float | None = None,
                   ring_radius_m: float = 0.15, frame_s: float = 0.25, hold_s: float = 2.0,
                   png_path=None, title: str = "") -> Path:
    """Write a GIF of the map being built, streaming the frames to the writer.

    ``frames``: an iterable (e.g. a generator) of (cell classes (ny, nx) int8, poses scanned
    so far, caption), ``n_frames`` of them; the last is held ``hold_s`` seconds. With
    ``png_path``, also the map picture of ``grid`` with ``title`` (as :func:`save_map_png`
    draws it), from the same drawing.
    """
    if n_frames < 1:
        raise ValueError(f"an animation needs at least one frame, got n_frames={n_frames}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    anim = MapAnimator(grid, scenario, poses, reach_m, ring_radius_m)
    images = (anim.palette_image(anim.frame(*f)) for f in frames)
    first = next(images)
    durations = [round(frame_s * 1000)] * n_frames
    durations[-1] = round(hold_s * 1000)
    first.save(path, format="GIF", save_all=True, append_images=images, duration=durations,
               loop=0, optimize=False)
    if png_path is not None:
        anim.save_png(png_path, grid.classify(), title)
    return path
