"""Pictures of maps: a PNG of the final map and a GIF of it being built, drawn with Pillow
and numpy (matplotlib, which costs a fresh ``irring run`` more than making the map, is only
for charts: :func:`figure`). What the pictures show and how the GIF is streamed:
docs/mapping.md.
"""

from __future__ import annotations

import functools
import importlib.util
import io
import math
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
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
PNG_DPI = 110
MAX_MAP_HEIGHT_IN = 8.0        # the axes' height at most (the figure adds 1.5 in)
MIN_MAP_HEIGHT_IN = 0.6   # … and at least this, so the axes keep a height past the margins


def figure(width_in: float, height_in: float, dpi: float = 100):
    """A matplotlib Figure on its own Agg canvas, for charts: no pyplot, so drawing it
    neither switches the caller's backend (a notebook's inline one) nor adds to pyplot's
    open figures."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # deferred: charts only
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def plain_log(ax, axis: str = "x") -> None:
    """Make ``ax``'s ``axis`` ("x" or "y") logarithmic, labelled in plain numbers (0.05, 0.1,
    0.2 … 10, or 1.5, 2, 3, 4 across less than 1.5 decades) where matplotlib writes 10⁻¹,
    10⁰ and 2×10⁰: read at a glance. Call it after plotting (it reads the axis' span)."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter  # deferred: charts only

    getattr(ax, f"set_{axis}scale")("log")
    lo, hi = getattr(ax, f"get_{axis}lim")()
    subs = (1.0, 2.0, 5.0) if hi / lo >= 10 ** 1.5 else (1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0)
    which = getattr(ax, f"{axis}axis")
    which.set_major_locator(LogLocator(subs=subs))
    which.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    which.set_minor_formatter(NullFormatter())


# A score that crowds the top of 0 … 1 (F1 0.995 and 0.998 drawn as one dot) is drawn on
# -log10(1 + STRETCH_EPS - y): 1 at the top, 0.99 two thirds of the way up, 0 at the foot
STRETCH_EPS = 1e-3
STRETCH_TICKS = (0.0, 0.5, 0.8, 0.9, 0.95, 0.98, 0.99, 0.995, 0.998, 1.0)


def stretch_towards_one(ax) -> None:
    """Make ``ax``'s y axis (a score of at most 1) spread out near 1, ticked in plain numbers
    (0, 0.5, 0.8, 0.9, 0.95 … 0.998, 1), its top just above 1, its foot the tick at or below
    the foot as set."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator  # deferred: charts only

    top = 1.0 + STRETCH_EPS / 2   # a point at 1 is drawn whole, not cut by the frame

    def forward(y):
        return -np.log10(1.0 + STRETCH_EPS - np.minimum(np.asarray(y, float), top))

    def inverse(t):
        return 1.0 + STRETCH_EPS - 10.0 ** -np.asarray(t, float)

    # down to a tick at or below the lowest point, so no point lies below the last label
    lo = ax.get_ylim()[0]
    lo = min(lo, max(t for t in STRETCH_TICKS if t <= max(lo, 0.0)))
    ax.set_yscale("function", functions=(forward, inverse))
    ax.set_ylim(lo, top)
    ax.yaxis.set_major_locator(FixedLocator([t for t in STRETCH_TICKS if t >= lo]))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_locator(NullLocator())


def map_rgb(classes: np.ndarray) -> np.ndarray:
    """(ny, nx, 3) float image of a classified grid (row 0 = lowest y)."""
    return _CLASS_RGB[np.asarray(classes, np.intp) - _CLASS0]


def crowded(poses: Sequence, ring_radius_m: float) -> bool:
    """True when two poses' rings overlap (a moving scan's sweeps, a dense survey): the
    picture then draws the poses as a numbered path instead of rings and reach circles."""
    xy = np.array([[float(p[0]), float(p[1])] for p in poses]).reshape(-1, 2)
    xy = xy[np.isfinite(xy).all(axis=1)]
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


# --------------------------------------------------------------------------- drawing

def _rgb255(color: str) -> tuple[int, int, int]:
    return tuple(int(color[i:i + 2], 16) for i in (1, 3, 5))


# The inks drawn over the map; a picture's pixel is a base colour (a cell class's, or the
# figure's white = the free cells' white) under at most one ink at some coverage.
BLACK, TRUTH, POSE, RANGE = range(4)
_INK_RGB = np.array([(0, 0, 0), _rgb255(TRUTH_COLOR), _rgb255(POSE_COLOR),
                     _rgb255(RANGE_COLOR)], np.float32)
_WHITE = FREE - _CLASS0            # the figure's white, as a base: the free cells' colour
_BASE_RGB8 = np.round(_CLASS_RGB * 255).astype(np.uint8)
_LEVELS = 16                       # ink coverages a GIF frame tells apart


@functools.lru_cache(maxsize=1)
def _palette() -> tuple[bytes, np.ndarray]:
    """The one palette of every frame (3 bases × 4 inks × 17 coverages ≤ 256 colours) and
    the index of each (base, ink, coverage level): (3, 4, 17) uint8."""
    a = (np.arange(_LEVELS + 1) / _LEVELS)[None, None, :, None]
    blends = a * _INK_RGB[None, :, None, :] + (1 - a) * (_CLASS_RGB * 255)[:, None, None, :]
    pal, index = np.unique(np.round(blends).astype(np.uint8).reshape(-1, 3), axis=0,
                           return_inverse=True)
    return pal.tobytes().ljust(256 * 3, b"\0"), index.reshape(blends.shape[:3]).astype(np.uint8)


@functools.lru_cache(maxsize=None)
def font(size_px: float, bold: bool = False):
    """DejaVu Sans (matplotlib's font, from its package data; found without importing
    matplotlib) at ``size_px``; Pillow's own font if that is missing."""
    name = "DejaVuSans-Bold.ttf" if bold else "DejaVuSans.ttf"
    spec = importlib.util.find_spec("matplotlib")
    for folder in (spec.submodule_search_locations or []) if spec else []:
        path = Path(folder) / "mpl-data" / "fonts" / "ttf" / name
        if path.exists():
            return ImageFont.truetype(str(path), size_px)
    return ImageFont.load_default(size_px)


class _Ink:
    """One ink's coverage (0 … 1) over a box of the picture, anti-aliased: shapes by each
    pixel centre's distance to them, text by FreeType. Coordinates: picture pixels."""

    def __init__(self, box: tuple[int, int, int, int]):
        self.c0, self.r0, c1, r1 = box
        self.cover = np.zeros((r1 - self.r0, c1 - self.c0), np.float32)
        self._text = None

    def _window(self, lo_x, lo_y, hi_x, hi_y):
        """(the array's slice, pixel centres' x, y) over a bounding box, or None if outside."""
        h, w = self.cover.shape
        c0, c1 = max(0, int(lo_x) - self.c0), min(w, math.ceil(hi_x) + 1 - self.c0)
        r0, r1 = max(0, int(lo_y) - self.r0), min(h, math.ceil(hi_y) + 1 - self.r0)
        if c1 <= c0 or r1 <= r0:
            return None
        x = np.arange(c0, c1, dtype=np.float32)[None, :] + (self.c0 + 0.5)
        y = np.arange(r0, r1, dtype=np.float32)[:, None] + (self.r0 + 0.5)
        return (slice(r0, r1), slice(c0, c1)), x, y

    def _put(self, win, cover) -> None:
        s = win[0]
        np.maximum(self.cover[s], np.clip(cover, 0, 1), out=self.cover[s])

    def line(self, xy, width_px: float, dash: tuple[float, float] | None = None) -> None:
        """A polyline ``width_px`` wide (round ends); ``dash``: (on, off) lengths in pixels."""
        pts = np.asarray(xy, float)
        for a, b in zip(pts[:-1], pts[1:]):
            length = float(np.hypot(*(b - a)))
            if dash is None or length == 0:
                self._segment(a, b, width_px)
                continue
            for t0 in np.arange(0, length, sum(dash)):
                t1 = min(t0 + dash[0], length)
                self._segment(a + (b - a) * t0 / length, a + (b - a) * t1 / length, width_px)

    def _segment(self, a, b, width_px: float) -> None:
        half = width_px / 2 + 1
        win = self._window(min(a[0], b[0]) - half, min(a[1], b[1]) - half,
                           max(a[0], b[0]) + half, max(a[1], b[1]) + half)
        if win is None:
            return
        _, x, y = win
        d = np.asarray(b - a, np.float32)
        den = float(d @ d) or 1.0
        t = np.clip(((x - a[0]) * d[0] + (y - a[1]) * d[1]) / den, 0, 1)
        dist = np.hypot(x - (a[0] + t * d[0]), y - (a[1] + t * d[1]))
        self._put(win, width_px / 2 + 0.5 - dist)

    def polygon(self, xy, width_px: float) -> None:
        pts = [tuple(p) for p in np.asarray(xy, float)]
        self.line(pts + pts[:1], width_px)

    def circle(self, centre, r_px: float, width_px: float,
               dash: tuple[float, float] | None = None) -> None:
        """A ring of radius ``r_px``; ``dash``: (on, off) arc lengths in pixels, rounded to
        whole dashes round the circle."""
        cx, cy = centre
        out = r_px + width_px / 2 + 1
        win = self._window(cx - out, cy - out, cx + out, cy + out)
        if win is None:
            return
        _, x, y = win
        cover = width_px / 2 + 0.5 - np.abs(np.hypot(x - cx, y - cy) - r_px)
        if dash is not None:
            period = 2 * math.pi * r_px / max(1, round(2 * math.pi * r_px / sum(dash)))
            on = np.nonzero(cover > 0)           # the angle only where the ring is
            dy, dx = y[on[0], 0] - cy, x[0, on[1]] - cx
            s = np.mod(np.arctan2(dy, dx) * r_px, period)     # along the arc
            cover[on] = np.minimum(cover[on], np.minimum(s, dash[0] - s) + 0.5)
        self._put(win, cover)

    def dot(self, centre, r_px: float) -> None:
        cx, cy = centre
        win = self._window(cx - r_px - 1, cy - r_px - 1, cx + r_px + 1, cy + r_px + 1)
        if win is not None:
            _, x, y = win
            self._put(win, r_px + 0.5 - np.hypot(x - cx, y - cy))

    def text(self, xy, text: str, font, anchor: str, vertical: bool = False) -> None:
        if self._text is None:
            self._text = Image.new("L", self.cover.shape[::-1], 0)
        x, y = xy[0] - self.c0, xy[1] - self.r0
        if not vertical:
            ImageDraw.Draw(self._text).text((x, y), text, fill=255, font=font, anchor=anchor)
            return
        l, t, r, b = font.getbbox(text, anchor="mm")
        img = Image.new("L", (r - l + 2, b - t + 2), 0)
        ImageDraw.Draw(img).text((1 - l, 1 - t), text, fill=255, font=font, anchor="mm")
        img = img.rotate(90, expand=True)        # reads bottom to top, as a y label does
        self._text.paste(img, (round(x - img.width / 2), round(y - img.height / 2)), img)

    def coverage(self) -> np.ndarray:
        """(rows, cols) float32 coverage 0 … 1."""
        if self._text is not None:
            np.maximum(self.cover, np.asarray(self._text, np.float32) / 255, out=self.cover)
        return self.cover


class _Layer:
    """One ink's pixels, kept sparse: flat pixel indices into the picture, coverage 0 … 1."""

    __slots__ = ("ink", "index", "alpha")

    def __init__(self, ink: int, index: np.ndarray, alpha: np.ndarray):
        self.ink, self.index, self.alpha = ink, index, alpha


class MapPicture:
    """The map picture, and frames of the map being built, composed with numpy.

    Laid out once: the axes box (the map at equal scale), ticks and labels in metres, the
    true outlines, a scale bar, the legend, a title line; each pose's marks as a layer of
    their own. A picture is the map's cells, upsampled by index, under those inks. A GIF
    frame goes through one palette (an index image, one byte a pixel); the PNG is full
    colour. Both are cut to what is drawn, with 0.1 in around it.
    """

    def __init__(self, grid: OccupancyGrid, scenario=None, poses: Sequence = (),
                 reach_m: float | None = None, ring_radius_m: float = 0.15,
                 dpi: float = PNG_DPI, title: str = "", width_in: float = 8.0,
                 route=None):
        self.dpi = dpi
        pt = dpi / 72                                    # pixels per point
        x0, x1, y0, y1 = self.extent_m = grid.extent_m
        # laid out on width_in, drawn on a canvas wider by `spare` each side (an end tick's
        # label or a long y label may stick out), then cut to what is drawn
        spare = round(0.5 * dpi)
        width = round(width_in * dpi) + 2 * spare
        # a tall map is drawn narrower, not taller than a screen (a 3 m shaft: 3000 pixels)
        # … and a long thin one no flatter than the margins need (a 30 m × 0.4 m corridor
        # left the axes a negative height)
        height = round((min(max(width_in * (y1 - y0) / (x1 - x0) * 0.9, MIN_MAP_HEIGHT_IN),
                            MAX_MAP_HEIGHT_IN) + 1.5) * dpi)
        # the axes: the box left by fixed margins (inches), shrunk to the map's aspect
        bl, br = spare + 0.8 * dpi, width - spare - 0.15 * dpi
        bt, bb = 0.4 * dpi, height - 1.3 * dpi
        scale = min((br - bl) / (x1 - x0), (bb - bt) / (y1 - y0))     # pixels per metre
        left = (bl + br) / 2 - scale * (x1 - x0) / 2
        top = (bt + bb) / 2 - scale * (y1 - y0) / 2
        self._box = [left, top, left + scale * (x1 - x0), top + scale * (y1 - y0)]
        self.scale = scale

        full = (0, 0, width, height)
        inks = {k: _Ink(full) for k in (BLACK, TRUTH, POSE, RANGE)}
        fills: list[tuple[tuple[int, int, int, int], int]] = []   # opaque boxes over all
        drawn = [tuple(round(v) for v in self._box)]              # boxes the crop keeps
        black = inks[BLACK]
        lw_axes = 0.8 * pt
        black.polygon(self._box_corners(), lw_axes)
        small, normal = font(8 * pt), font(10 * pt)

        # ticks (outward) and their labels; the axis labels beyond them
        tick, pad = 3.5 * pt, 3.5 * pt
        L, T, R, B = self._box
        xt, dx = _ticks(x0, x1, scale, 1.0 * dpi)
        yt, dy = _ticks(y0, y1, scale, 0.6 * dpi)
        for v in xt:
            x, _ = self.to_px(v, y0)
            black.line([(x, B), (x, B + tick)], lw_axes)
            black.text((x, B + tick + pad), _tick_label(v, dx), normal, "mt")
            half = normal.getlength(_tick_label(v, dx)) / 2
            drawn.append((round(x - half), round(B), round(x + half), round(B + tick + pad)))
        label_w = 0
        for v in yt:
            _, y = self.to_px(x0, v)
            black.line([(L, y), (L - tick, y)], lw_axes)
            black.text((L - tick - pad, y), _tick_label(v, dy), normal, "rm")
            label_w = max(label_w, normal.getlength(_tick_label(v, dy)))
        x_label_top = B + tick + pad + normal.size * 1.2 + 4 * pt
        black.text(((L + R) / 2, x_label_top), "x (m)", normal, "mt")
        ylx = L - tick - pad - label_w - 4 * pt - normal.size * 0.6
        black.text((ylx, (T + B) / 2), "y (m)", normal, "mm", vertical=True)
        drawn.append((round(ylx - normal.size), round(T), round(L), round(B)))

        # the ground truth (under the poses' marks, like the walls they outline)
        truth = inks[TRUTH]
        if scenario is not None:
            truth.polygon(self.to_px(*np.asarray(scenario.room.outline_m).T), 1.0 * pt)
            for ob in scenario.obstacles:
                if isinstance(ob, Cylinder):
                    truth.circle(self.to_px(*ob.center_m), ob.radius_m * scale, 1.0 * pt)
                else:
                    truth.polygon(self.to_px(*np.asarray(box_corners(ob)).T), 1.0 * pt)

        # the scale bar: a framed white box in the upper left corner of the axes, or, where
        # it would hide a third of a flat map (a corridor), right of the x label below them
        bar_m = _round_below((x1 - x0) / 5)               # 0.5 m on the T-room
        bar_h = max(2.0, (y1 - y0) * 0.008 * scale)
        text = f"{bar_m * 1000:.0f} mm" if bar_m < 1 else f"{bar_m:g} m"
        inner = 0.4 * 8 * pt
        sb_w = 2 * inner + max(bar_m * scale, small.getlength(text))
        sb_h = 2 * inner + bar_h + 3 * pt + small.size
        if sb_h + 1.2 * 8 * pt <= (B - T) / 3:
            bx0, by0 = L + 0.6 * 8 * pt, T + 0.6 * 8 * pt
        else:
            bx0, by0 = R - sb_w, x_label_top
        sb = (round(bx0), round(by0), round(bx0 + sb_w), round(by0 + sb_h))
        fills.append((sb, _WHITE))
        drawn.append(sb)
        black.polygon([(sb[0], sb[1]), (sb[2], sb[1]), (sb[2], sb[3]), (sb[0], sb[3])], lw_axes)
        bar_y = sb[1] + inner + bar_h / 2
        bar_x = (sb[0] + sb[2]) / 2 - bar_m * scale / 2
        black.line([(bar_x, bar_y), (bar_x + bar_m * scale, bar_y)], bar_h)
        black.text(((sb[0] + sb[2]) / 2, bar_y + bar_h / 2 + 3 * pt), text, small, "mt")

        # the legend, three columns filled top to bottom, below the x label
        route = None if route is None else np.asarray(route, float).reshape(-1, 2)
        driven = self.driven = route is not None and len(route) > 1
        # a moving ring's sweeps are no scan poses: its route and where each sweep began
        self.crowded = driven or crowded(poses, ring_radius_m)
        entries = [("patch", UNKNOWN - _CLASS0, "unknown"), ("patch", FREE - _CLASS0, "free"),
                   ("patch", OCCUPIED - _CLASS0, "occupied")]
        if scenario is not None:
            entries.append(("line", TRUTH, "true walls / obstacles"))
        if driven:
            entries.append(("path", POSE, "path driven while sweeping (dots: sweep starts)"))
        elif len(poses) and self.crowded:
            entries.append(("path", POSE, "scan poses in order (numbered where a number fits)"))
        elif len(poses):
            entries.append(("ring", POSE, "ring at scan pose (number = order)"))
        if reach_m and len(poses) and not self.crowded:
            # from the robot's centre: the ring's radius and the sensor's range, each named
            # (a bare 774 mm read as the GP2D12's range, which is 624 mm)
            entries.append(("dash", RANGE, f"sensor reach (ring {ring_radius_m * 1000:.0f} + "
                                           f"range {(reach_m - ring_radius_m) * 1000:.0f} mm)"))
        self.legend = [label for _, _, label in entries]
        fs = small.size
        rows = math.ceil(len(entries) / 3)
        columns = [entries[i:i + rows] for i in range(0, len(entries), rows)]
        widths = [2.8 * fs + max(small.getlength(e[2]) for e in col) for col in columns]
        total = sum(widths) + 2.0 * fs * (len(columns) - 1)
        lx = (L + R) / 2 - total / 2
        ly = x_label_top + normal.size * 1.2 + 0.8 * fs
        for col, w in zip(columns, widths):
            for i, (kind, what, label) in enumerate(col):
                cy = ly + (i + 0.5) * 1.5 * fs
                h0, h1 = lx, lx + 2.0 * fs
                if kind == "patch":
                    box = (round(h0), round(cy - 0.35 * fs), round(h1), round(cy + 0.35 * fs))
                    fills.append((box, what))
                    black.polygon([(box[0], box[1]), (box[2], box[1]), (box[2], box[3]),
                                   (box[0], box[3])], 0.5 * pt)
                elif kind == "ring":
                    inks[what].circle(((h0 + h1) / 2, cy), 4.5 * pt - 0.75 * pt, 1.5 * pt)
                else:
                    inks[what].line([(h0, cy), (h1, cy)], (1.2 if kind == "line" else 0.8
                                                           if kind == "path" else 1.0) * pt,
                                    dash=(3.7 * pt, 1.6 * pt) if kind == "dash" else None)
                    if kind == "path":
                        inks[what].dot(((h0 + h1) / 2, cy), 1.5 * pt)
                black.text((h1 + 0.8 * fs, cy), label, small, "lm")
            lx += w + 2.0 * fs
        drawn.append((round((L + R) / 2 - total / 2), round(ly),
                      round((L + R) / 2 + total / 2), round(ly + rows * 1.5 * fs)))

        # the title line: its baseline 6 pt above the axes, centred on them
        self._title_xy = ((L + R) / 2, T - 6 * pt)
        self._title_font = normal
        tl, tt, tr, tb = normal.getbbox(title or "pose 0 of 0", anchor="ms")
        drawn.append((round(self._title_xy[0] + tl), round(self._title_xy[1] + tt),
                      round(self._title_xy[0] + tr), round(self._title_xy[1] + tb)))

        # the static picture: truth, the legend's coloured marks, then the opaque boxes,
        # then black (the scale bar's frame and text over its box)
        n = width * height
        self._alpha = np.zeros(n, np.float32)
        self._ink = np.zeros(n, np.uint8)
        self._over = np.zeros((n, 3), np.float32)     # premultiplied RGB 0 … 255
        self._bg = np.full((height, width), _WHITE, np.int8)   # -1: the map shows
        ri, ci = np.arange(height)[:, None] + 0.5, np.arange(width)[None, :] + 0.5
        self._bg[(ci >= L) & (ci < R) & (ri >= T) & (ri < B)] = -1
        covered = np.zeros((height, width), bool)
        for (c0, r0, c1, r1), base in fills:
            self._bg[r0:r1, c0:c1] = base
            covered[r0:r1, c0:c1] = True
        if driven:   # the route, clipped to the axes box like the poses' marks
            drawn_route = _Ink(full)
            drawn_route.line(self.to_px(route[:, 0], route[:, 1]), 0.8 * pt)
            a = drawn_route.coverage()
            a[~(ci >= L) | ~(ci < R) | ~(ri >= T) | ~(ri < B)] = 0
            a[covered] = 0
            self._composite(_layer(POSE, a * 0.7))       # red, a little see-through
        for k in (TRUTH, POSE, RANGE):
            a = inks[k].coverage()
            a[covered] = 0
            self._composite(_layer(k, a))
        self._composite(_layer(BLACK, black.coverage()))

        # cut to what is drawn, 0.1 in around it
        margin = round(0.1 * dpi)
        box = np.array(drawn)
        c0, r0 = max(0, box[:, 0].min() - margin), max(0, box[:, 1].min() - margin)
        c1, r1 = min(width, box[:, 2].max() + margin), min(height, box[:, 3].max() + margin)
        keep = (slice(r0, r1), slice(c0, c1))
        self.height, self.width = r1 - r0, c1 - c0
        self._alpha = self._alpha.reshape(height, width)[keep].ravel()
        self._ink = self._ink.reshape(height, width)[keep].ravel()
        self._over = self._over.reshape(height, width, 3)[keep].reshape(-1, 3)
        self._bg = self._bg[keep].ravel()
        self._covered = covered[keep]
        self._box = [L - c0, T - r0, R - c0, B - r0]
        self._title_xy = (self._title_xy[0] - c0, self._title_xy[1] - r0)

        # which cell each pixel shows (nearest), as a flat cell index
        ny, nx = grid.shape
        L, T, R, B = self._box
        cx = (np.arange(self.width) + 0.5 - L) / (R - L) * nx
        cy = (B - np.arange(self.height) - 0.5) / (B - T) * ny
        rows_ = np.clip(np.floor(cy), 0, ny - 1).astype(np.intp)
        cols_ = np.clip(np.floor(cx), 0, nx - 1).astype(np.intp)
        self._cell = (rows_[:, None] * nx + cols_[None, :]).ravel()

        self._poses = self._pose_layers(poses, ring_radius_m, reach_m, pt)
        self._palette, self._pal_index = _palette()
        self._tables = np.zeros((3, self.height * self.width), np.uint8)
        self._set_tables()
        self._caption_box = None
        self._shown = 0

    # ---- geometry

    def to_px(self, x, y):
        """Picture pixel coordinates (column, row; floats) of map coordinates (m)."""
        x0, _, y0, _ = self.extent_m
        L, _, _, B = self._box
        x, y = np.asarray(x, float), np.asarray(y, float)
        cols, rows = L + (x - x0) * self.scale, B - (y - y0) * self.scale
        return (float(cols), float(rows)) if cols.ndim == 0 else np.stack([cols, rows], -1)

    def _box_corners(self):
        L, T, R, B = self._box
        return [(L, T), (R, T), (R, B), (L, B)]

    def _pose_layers(self, poses, ring_radius_m, reach_m, pt) -> list[list[_Layer]]:
        """Each pose's marks as layers of the cut picture, clipped to the axes box and
        kept off the scale bar: a ring, a cross, the reach circle, the number; crowded, a
        dot and a line from the pose before."""
        label_m = 8 * pt * 2.0 / self.scale
        offsets = label_offsets(poses, ring_radius_m, self.extent_m, label_m)
        L, T, R, B = self._box
        ri = np.arange(self.height)[:, None] + 0.5
        ci = np.arange(self.width)[None, :] + 0.5
        inside = (ci >= L) & (ci < R) & (ri >= T) & (ri < B) & ~self._covered
        out = []
        for k, pose in enumerate(poses):
            c = self.to_px(float(pose[0]), float(pose[1]))
            if not np.all(np.isfinite(c)):
                out.append([])           # (a pose with no place has no marks to draw)
                continue
            reach = (reach_m or 0) * self.scale if not self.crowded else 0
            half = max(ring_radius_m * self.scale, reach, 16 * pt) + 4 * pt
            prev = self.to_px(float(poses[k - 1][0]), float(poses[k - 1][1])) if k else c
            if not np.all(np.isfinite(prev)):
                prev = c
            box = (max(0, int(min(c[0], prev[0]) - half)), max(0, int(min(c[1], prev[1]) - half)),
                   min(self.width, math.ceil(max(c[0], prev[0]) + half)),
                   min(self.height, math.ceil(max(c[1], prev[1]) + half)))
            if box[2] <= box[0] or box[3] <= box[1]:
                out.append([])
                continue
            marks, under = _Ink(box), _Ink(box)     # red marks over what goes under them
            under_ink, under_weight = RANGE, 1.0
            if self.crowded:       # a numbered path: a dot per pose, a line from the last
                marks.dot(c, 1.5 * pt)
                if k and not self.driven:   # (a drive's own route is drawn instead)
                    under.line([prev, c], 0.8 * pt)
                    under_ink, under_weight = POSE, 0.7          # red, a little see-through
            else:
                marks.circle(c, ring_radius_m * self.scale, 1.5 * pt)
                arm = 4 * pt
                marks.line([(c[0] - arm, c[1]), (c[0] + arm, c[1])], 1.5 * pt)
                marks.line([(c[0], c[1] - arm), (c[0], c[1] + arm)], 1.5 * pt)
                if reach_m:
                    under.circle(c, reach, 1.0 * pt, dash=(3.7 * pt, 1.6 * pt))
            if offsets[k] is not None:
                dx, dy = offsets[k]
                marks.text((c[0] + dx * self.scale, c[1] - dy * self.scale), str(k + 1),
                           font((8 if self.crowded else 10) * pt, bold=True), "mm")
            c0, r0, c1, r1 = box
            clip = inside[r0:r1, c0:c1]
            flat = (np.arange(r0, r1)[:, None] * self.width + np.arange(c0, c1)[None, :])
            layers = []
            for ink, draw, weight in ((under_ink, under, under_weight), (POSE, marks, 1.0)):
                a = draw.coverage() * weight
                a[~clip] = 0
                nz = np.nonzero(a)
                layers.append(_Layer(ink, flat[nz], a[nz]))
            out.append(layers)
        return out

    # ---- composing

    def _composite(self, layer: _Layer, over=None, alpha=None, ink=None) -> None:
        """Put a layer over the picture (or the given arrays), in place; where inks meet,
        a pixel keeps the ink that contributes most (a GIF pixel shows one ink)."""
        over = self._over if over is None else over
        alpha = self._alpha if alpha is None else alpha
        ink = self._ink if ink is None else ink
        i, a = layer.index, layer.alpha
        below = alpha[i] * (1 - a)
        over[i] = _INK_RGB[layer.ink] * a[:, None] + over[i] * (1 - a)[:, None]
        alpha[i] = a + below
        ink[i] = np.where(a >= below, layer.ink, ink[i])

    def _set_tables(self, i=None) -> None:
        """Palette index of pixels ``i`` (default: all) for each cell class under them,
        kept as the unknown colour's and modular (uint8) steps to the free and occupied
        ones. Only pixels with ink or a box over them need a look-up."""
        if i is None:
            bare = self._pal_index[:, 0, 0]
            self._tables[0], self._tables[1], self._tables[2] = bare[0], *(bare[1:] - bare[0])
            i = np.flatnonzero((self._alpha > 0) | (self._bg >= 0))
        level = np.rint(self._alpha[i] * _LEVELS).astype(np.intp)
        bg, ink = self._bg[i], self._ink[i]
        t = [self._pal_index[np.where(bg < 0, k, bg), ink, level] for k in range(3)]
        self._tables[0, i] = t[0]
        self._tables[1, i], self._tables[2, i] = t[1] - t[0], t[2] - t[0]

    def _show_poses(self, n: int) -> None:
        while self._shown < min(n, len(self._poses)):
            for layer in self._poses[self._shown]:
                self._composite(layer)
                self._set_tables(layer.index)
            self._shown += 1

    def frame(self, classes: np.ndarray, poses_shown: int, caption: str) -> np.ndarray:
        """(height, width) palette indices: cells (int8 classes, (ny, nx)), the first
        ``poses_shown`` poses (never fewer than an earlier frame showed), the caption."""
        self._show_poses(poses_shown)
        c = np.take((np.asarray(classes) - _CLASS0).astype(np.uint8).ravel(), self._cell)
        t = self._tables      # the unknown colour plus modular (uint8) steps to the others
        out = (t[0] + t[1] * (c == 1) + t[2] * (c == 2)).reshape(self.height, self.width)
        if caption:
            self._caption(out, caption)
        return out

    def _caption_mask(self, text: str, box=None):
        """(box, coverage 0 … 1) of ``text`` on the title line; ``box`` at least."""
        font, (x, y) = self._title_font, self._title_xy
        left, top, right, bottom = font.getbbox(text, anchor="ms")
        r0, r1 = max(0, int(y + top) - 2), min(self.height, math.ceil(y + bottom) + 2)
        c0, c1 = max(0, int(x + left) - 2), min(self.width, math.ceil(x + right) + 2)
        if box is not None:        # the union, so a shorter caption clears a longer
            r0, r1, c0, c1 = min(r0, box[0]), max(r1, box[1]), min(c0, box[2]), max(c1, box[3])
        mask = Image.new("L", (c1 - c0, r1 - r0), 0)
        ImageDraw.Draw(mask).text((x - c0, y - r0), text, fill=255, font=font, anchor="ms")
        return (r0, r1, c0, c1), np.asarray(mask, np.float32) / 255

    def _caption(self, out: np.ndarray, caption: str) -> None:
        """The caption drawn over the title line (outside the map: on white)."""
        self._caption_box, a = self._caption_mask(caption, self._caption_box)
        r0, r1, c0, c1 = self._caption_box
        level = np.rint(a * _LEVELS).astype(np.intp)
        under = out[r0:r1, c0:c1]
        out[r0:r1, c0:c1] = np.where(level > 0, self._pal_index[_WHITE, BLACK, level], under)

    def palette_image(self, indices: np.ndarray):
        """A frame as a Pillow palette image."""
        img = Image.frombytes("P", (self.width, self.height), np.ascontiguousarray(indices))
        img.putpalette(self._palette)
        return img

    def rgb(self, classes: np.ndarray, title: str = "") -> np.ndarray:
        """(height, width, 3) uint8: the map picture of ``classes`` with every pose and
        ``title``, in full colour."""
        over, alpha, ink = self._over.copy(), self._alpha.copy(), self._ink.copy()
        for layers in self._poses[self._shown:]:
            for layer in layers:
                self._composite(layer, over, alpha, ink)
        c = np.take((np.asarray(classes) - _CLASS0).astype(np.int8).ravel(), self._cell)
        img = _BASE_RGB8[np.where(self._bg < 0, c, self._bg)]
        i = np.flatnonzero(alpha)                 # blend only where something is drawn
        base = img[i].astype(np.float32)
        img[i] = (over[i] + (1 - alpha[i])[:, None] * base + 0.5).astype(np.uint8)
        img = img.reshape(self.height, self.width, 3)
        if title:
            (r0, r1, c0, c1), a = self._caption_mask(title)
            img[r0:r1, c0:c1] = (img[r0:r1, c0:c1] * (1 - a)[..., None] + 0.5).astype(np.uint8)
        return img

    def save_png(self, path, classes: np.ndarray, title: str = "") -> Path:
        """Write :meth:`rgb` as a PNG."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(self.png_bytes(classes, title))
        return path

    def png_bytes(self, classes: np.ndarray, title: str = "") -> bytes:
        buf = io.BytesIO()
        # zlib level 3: a third of the default level's time for a file ~10 % larger
        Image.fromarray(self.rgb(classes, title)).save(buf, format="PNG",
                                                       dpi=(self.dpi, self.dpi),
                                                       compress_level=3)
        return buf.getvalue()


def _layer(ink: int, coverage: np.ndarray) -> _Layer:
    flat = coverage.ravel()
    i = np.flatnonzero(flat)
    return _Layer(ink, i, flat[i])


def _ticks(lo: float, hi: float, px_per_m: float, min_gap_px: float) -> tuple[list, float]:
    """Tick values in [lo, hi] on a 1-2-2.5-5 step at least ``min_gap_px`` apart, and
    the step."""
    want = min_gap_px / px_per_m
    exp = math.floor(math.log10(want))
    step = next(m * 10 ** e for e in (exp, exp + 1) for m in (1, 2, 2.5, 5)
                if m * 10 ** e >= want * (1 - 1e-9))
    first = math.ceil(lo / step - 1e-9)
    return [round(k * step, 10) for k in range(first, math.floor(hi / step + 1e-9) + 1)], step


def _round_below(length: float) -> float:
    """The largest 1, 2 or 5 × 10ᵏ not above ``length`` (> 0)."""
    exp = math.floor(math.log10(length))
    return max(m * 10.0 ** e for e in (exp - 1, exp) for m in (1, 2, 5)
               if m * 10.0 ** e <= length * (1 + 1e-9))


def _tick_label(value: float, step: float) -> str:
    decimals = max(0, -math.floor(math.log10(step) + 1e-9))
    if round(step * 10 ** decimals, 6) % 1:
        decimals += 1                      # 0.25 needs two
    return f"{value:.{decimals}f}"


def save_map_png(path, grid: OccupancyGrid, scenario=None, poses: Sequence = (),
                 reach_m: float | None = None, ring_radius_m: float = 0.15,
                 title: str = "", route=None) -> Path:
    """Write the map picture (see the module doc) to ``path``; ``route``: (K, 2) m, the
    path a moving ring read along (``poses`` are then where its sweeps began)."""
    return MapPicture(grid, scenario, poses, reach_m, ring_radius_m,
                      title=title, route=route).save_png(path, grid.classify(), title)


def save_animation(path, grid: OccupancyGrid,
                   frames: Iterable[tuple[np.ndarray, int, str]], n_frames: int,
                   scenario=None, poses: Sequence = (), reach_m: float | None = None,
                   ring_radius_m: float = 0.15, frame_s: float = 0.25, hold_s: float = 2.0,
                   png_path=None, title: str = "", route=None) -> Path:
    """Write a GIF of the map being built, streaming the frames to the writer.

    ``frames``: an iterable (e.g. a generator) of (cell classes (ny, nx) int8, poses scanned
    so far, caption), ``n_frames`` of them; the last is held ``hold_s`` seconds. With
    ``png_path``, also the map picture of ``grid`` with ``title`` (as :func:`save_map_png`
    draws it), from the same layout.
    """
    if n_frames < 1:
        raise ValueError(f"an animation needs at least one frame, got n_frames={n_frames}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    pic = MapPicture(grid, scenario, poses, reach_m, ring_radius_m, title=title, route=route)
    images = (pic.palette_image(pic.frame(*f)) for f in frames)
    first = next(images)
    durations = [round(frame_s * 1000)] * n_frames
    durations[-1] = round(hold_s * 1000)
    first.save(path, format="GIF", save_all=True, append_images=images, duration=durations,
               loop=0, optimize=False)
    if png_path is not None:
        pic.save_png(png_path, grid.classify(), title)
    return path
