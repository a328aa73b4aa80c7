"""Pictures of maps: a PNG of the final map and an animation of the map being built.

The picture shows the map's three cell states (unknown grey, free white, occupied black),
the ground truth (walls and obstacles as blue outlines), each scan pose (a red ring of the
robot's radius with its number), and the sensor reach around each pose (dashed orange
circle: max range + ring radius), with a legend, a scale bar and axes in metres.
Matplotlib runs headless (Agg); animations are GIFs written with imageio.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from .mapping import FREE, OCCUPIED, OccupancyGrid, classify

UNKNOWN_RGB = (0.75, 0.75, 0.75)
FREE_RGB = (1.0, 1.0, 1.0)
OCCUPIED_RGB = (0.0, 0.0, 0.0)
TRUTH_COLOR = "#1f6fd1"
POSE_COLOR = "#d62728"
RANGE_COLOR = "#ff8c00"


def map_rgb(classes: np.ndarray) -> np.ndarray:
    """(ny, nx, 3) float image of a classified grid (row 0 = lowest y)."""
    img = np.empty(classes.shape + (3,))
    img[:] = UNKNOWN_RGB
    img[classes == FREE] = FREE_RGB
    img[classes == OCCUPIED] = OCCUPIED_RGB
    return img


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


class MapFigure:
    """One figure reused for every frame: static overlays drawn once, the map image updated."""

    def __init__(self, grid: OccupancyGrid, scenario=None, poses: Sequence = (),
                 reach_m: float | None = None, ring_radius_m: float = 0.15, title: str = "",
                 width_in: float = 8.0):
        plt = _plt()
        from matplotlib.lines import Line2D
        from matplotlib.patches import Circle, Patch, Polygon

        x0, x1, y0, y1 = grid.extent_m
        aspect = (y1 - y0) / (x1 - x0)
        self.fig, self.ax = plt.subplots(figsize=(width_in, width_in * aspect * 0.9 + 1.5),
                                         dpi=100)
        ax = self.ax
        self.image = ax.imshow(map_rgb(grid.classify()), origin="lower",
                               extent=grid.extent_m, interpolation="nearest", zorder=0)
        handles = [Patch(facecolor=UNKNOWN_RGB, edgecolor="k", lw=0.5, label="unknown"),
                   Patch(facecolor=FREE_RGB, edgecolor="k", lw=0.5, label="free"),
                   Patch(facecolor=OCCUPIED_RGB, edgecolor="k", lw=0.5, label="occupied")]
        if scenario is not None:
            ax.add_patch(Polygon(np.asarray(scenario.room.outline_m), closed=True, fill=False,
                                 ec=TRUTH_COLOR, lw=1.0, alpha=0.8, zorder=3))
            from .scenario import Cylinder
            from .metrics import box_corners

            for ob in scenario.obstacles:
                if isinstance(ob, Cylinder):
                    ax.add_patch(Circle(ob.center_m, ob.radius_m, fill=False, ec=TRUTH_COLOR,
                                        lw=1.0, zorder=3))
                else:
                    ax.add_patch(Polygon(box_corners(ob), closed=True, fill=False,
                                         ec=TRUTH_COLOR, lw=1.0, zorder=3))
            handles.append(Line2D([], [], color=TRUTH_COLOR, lw=1.2,
                                  label="true walls / obstacles"))
        self.pose_artists = []
        for k, pose in enumerate(poses):
            x, y = float(pose[0]), float(pose[1])
            arts = [ax.add_patch(Circle((x, y), ring_radius_m, fill=False, ec=POSE_COLOR,
                                        lw=1.5, zorder=4)),
                    ax.plot([x], [y], "+", color=POSE_COLOR, ms=8, mew=1.5, zorder=4)[0],
                    ax.text(x, y + ring_radius_m * 0.35, str(k + 1), color=POSE_COLOR,
                            ha="center", va="bottom", fontsize=10, weight="bold", zorder=5)]
            if reach_m:
                arts.append(ax.add_patch(Circle((x, y), reach_m, fill=False, ec=RANGE_COLOR,
                                                lw=1.0, ls="--", zorder=4)))
            self.pose_artists.append(arts)
        if len(poses):
            handles.append(Line2D([], [], color=POSE_COLOR, marker="o", ls="", mfc="none",
                                  ms=9, mew=1.5, label="ring at scan pose (number = order)"))
        if reach_m and len(poses):
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
        self.fig.tight_layout()

    def _scale_bar(self, x0, x1, y0, y1) -> None:
        from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

        bar = 0.5 if x1 - x0 > 1.5 else 0.1
        self.ax.add_artist(AnchoredSizeBar(self.ax.transData, bar, f"{bar * 1000:.0f} mm",
                                           loc="upper left", pad=0.4, borderpad=0.6, sep=3,
                                           size_vertical=(y1 - y0) * 0.008, frameon=True,
                                           fontproperties={"size": 8}))

    def update(self, classes: np.ndarray, poses_shown: int | None = None,
               title: str | None = None) -> None:
        self.image.set_data(map_rgb(classes))
        if poses_shown is not None:
            for k, arts in enumerate(self.pose_artists):
                for a in arts:
                    a.set_visible(k < poses_shown)
        if title is not None:
            self.title.set_text(title)

    def rgb(self) -> np.ndarray:
        self.fig.canvas.draw()
        return np.asarray(self.fig.canvas.buffer_rgba())[..., :3].copy()

    def save(self, path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        self.fig.savefig(path, dpi=110, bbox_inches="tight")
        return path

    def close(self) -> None:
        _plt().close(self.fig)


def save_map_png(path, grid: OccupancyGrid, scenario=None, poses: Sequence = (),
                 reach_m: float | None = None, ring_radius_m: float = 0.15,
                 title: str = "") -> Path:
    """Write the map picture (see the module doc) to ``path``."""
    fig = MapFigure(grid, scenario, poses, reach_m, ring_radius_m, title)
    try:
        return fig.save(path)
    finally:
        fig.close()


def save_animation(path, grid: OccupancyGrid, frames: Sequence[tuple[np.ndarray, int, str]],
                   scenario=None, poses: Sequence = (), reach_m: float | None = None,
                   ring_radius_m: float = 0.15, frame_s: float = 0.25,
                   hold_s: float = 2.0) -> Path:
    """Write a GIF of the map being built.

    ``frames``: (log-odds (ny, nx), poses scanned so far, caption) per frame; the last frame
    is held ``hold_s`` seconds. Cells are classified as the map's (:func:`mapping.classify`).
    """
    import imageio.v2 as imageio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig = MapFigure(grid, scenario, poses, reach_m, ring_radius_m, "")
    images = []
    try:
        for log_odds, shown, caption in frames:
            fig.update(classify(log_odds), shown, caption)
            images.append(fig.rgb())
    finally:
        fig.close()
    durations = [frame_s] * len(images)
    if durations:
        durations[-1] = hold_s
    # imageio's pillow GIF writer takes durations in milliseconds
    imageio.mimsave(path, images, format="GIF", duration=[d * 1000 for d in durations], loop=0)
    return path
