"""Log-odds occupancy grid built from estimated end points (paper §IV, after Elfes 1989).

How it works, its assumptions and measured figures: docs/mapping.md.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from .. import safe_yaml
from ..core import UNCERTAIN_SIGMA_M, Points, Reason, bounds, gigabytes, points_with
from ..errors import TooBig
from ..resources import kernel

_traverse = kernel("maps._traverse")

FREE = 0
OCCUPIED = 1
UNKNOWN = -1

# map_server's trinary thresholds (probability of occupancy); the grid classifies the same way.
OCCUPIED_THRESH = 0.65
FREE_THRESH = 0.196
# Byte values map_saver writes (free 254, occupied 0, unknown 205).
PGM_FREE, PGM_OCCUPIED, PGM_UNKNOWN = 254, 0, 205

# (a plain int: comparing an array with the IntEnum member takes numpy's slow path)
_NO_RETURN = int(Reason.NO_RETURN)


# MapperParams knobs whose +inf turns their rule off (never stop a silent beam; no reading
# weighs less for its σ): the one non-finite value a recording's mapper numbers may hold.
OFF_AT_INFINITY = ("no_return_stop", "lone_sigma_m")


@dataclass(frozen=True)
class MapperParams:
    """The inverse sensor model's knobs (log-odds units; lengths in metres). docs/mapping.md
    says what the defaults do to a cell: one clean pass marks it free, one end-point hit
    marks it occupied and outweighs a pass, a no-return beam counts half a clean pass.
    """

    l_occ: float = 2.5            # added to the cell holding a valid end point
    l_free: float = -1.5          # added to a cell a valid beam clearly passed through
    l_no_return: float = -0.75    # added along a no-return beam, up to the max range …
    no_return_stop: float = 1.7   # … or to the first cell above this (> a lone l_occ_min hit)
    # 1: … only where that cell holds a valid reading's end point (a sensor that returns at
    # any incidence: pipeline.mapper_params); 0: any cell above the stop
    stop_at_end_cells: float = 0.0
    l_min: float = -4.0           # clamp: the most certain "free"
    l_max: float = 4.0            # clamp: the most certain "occupied"
    tail_sigmas: float = 0.25     # the beam is followed to d (+ depth) + tail_sigmas·σ
    min_sigma_m: float = 0.005    # floor on a reading's σ: half a 10 mm cell (finer is not resolved)
    # … in a beam's update at most this many cells: a finer grid resolves finer (the rules
    # that place readings keep min_sigma_m)
    min_sigma_cells: float = 0.5
    default_sigma_m: float = 0.01  # used where a valid reading's sigma_m is NaN (not given)
    free_margin_cells: float = 0.5  # no free evidence within this many cells before the end point
    free_sigmas: float = 0.0      # … nor within this many σ before that (an uncertain reading clears less)
    occ_sigma_m: float = 0.005    # a hit with σ above this weighs l_occ·occ_sigma_m/σ …
    l_occ_min: float = 1.6        # … but at least this (a lone far hit still marks its cell) …
    lone_sigma_m: float = UNCERTAIN_SIGMA_M  # σ above this weighs lone_sigma_m/σ (hit and pass)
    # share of the l_occ_min floor a hit of σ ≤ lone_sigma_m keeps in the cells wholly in
    # front of its end point (the σ-weighted hit does not change; 1: the floor as at the end
    # point, as before 2026-11-27)
    ahead_floor: float = 0.0
    # hits along the segment between consecutive steps of a sensor whose ranges agree within
    # explain_sigmas combined σ beyond a slanted surface's d·Δh·tan θ (σ ≤ lone_sigma_m):
    # this share of the weaker one's (0: off; 0.6: any pair of σ ≤ lone_sigma_m marks a cell
    # alone, 0.96: at step_stride 2 in 5-8 mm cells one pair is all a gap between hits gets) …
    between_steps: float = 0.6
    # … in the segment's cells at least this many cells (Chebyshev) from both end points'
    # cells: the nearer ones are within a cell of an end point's own hit already
    between_end_cells: float = 2.0
    hold_sigma_m: float = 0.005   # a cell holding an end point of σ ≤ this is not freed by its batch
    # … and where the next or previous step of its sensor reads ≥ edge_jump_cells farther (or
    # nothing: an occluding edge), the surface behind it weighs l_occ_min this deep (cells)
    hit_depth_cells: float = 1.25
    edge_jump_cells: float = 5.0
    # a valid reading (σ from explain_sharper·min_sigma_m to lone_sigma_m) whose beam
    # crosses, within explain_sigmas·σ and at least a cell before its end point, a cell
    # where the batch's end points explain_sharper times sharper hold explain_log_odds is
    # mapped as ending there, with their σ (explain_sigmas 0: off)
    explain_sigmas: float = 3.0
    explain_log_odds: float = 3.0
    explain_sharper: float = 2.0
    # a valid reading (σ ≥ explain_sharper·min_sigma_m) its sensor's nearest valid readings
    # before and after it (at most neighbour_steps rows of the sweep away, beams on either
    # side of its own, end points within explain_sigmas combined σ of its own) both read
    # shorter (longer: σ ≤ lone_sigma_m only) is mapped at the farther (nearer) of their
    # ranges, the median of the three; one of σ > lone_sigma_m with such a neighbour on one
    # side only, sharper and shorter, at its range (0: off)
    neighbour_steps: float = 2.0
    # readings from a wide cone (Points.cone_half_angle_rad > 0: sonar), mapped as arcs
    cone_step_rad: float = math.radians(1.0)  # spacing of the fan of rays across the cone
    cone_l_occ: float = 1.25      # a hit on the arc
    cone_l_free: float = -0.5     # a pass through the cone
    cone_l_no_return: float = 0.0  # a cone that heard nothing

    def __post_init__(self) -> None:
        if not (self.l_occ > 0 and self.l_free < 0 and self.l_no_return <= 0):
            raise ValueError("need l_occ > 0, l_free < 0 and l_no_return ≤ 0 (log-odds)")
        if not self.l_min < 0 < self.l_max:
            raise ValueError(f"need l_min < 0 < l_max, got {self.l_min}, {self.l_max}")
        if (self.tail_sigmas < 0 or self.min_sigma_m <= 0 or self.default_sigma_m <= 0
                or not self.min_sigma_cells > 0):
            raise ValueError("tail_sigmas must be ≥ 0 and the σ floors > 0")
        if not (self.cone_step_rad > 0 and self.cone_l_occ > 0 and self.cone_l_free < 0
                and self.cone_l_no_return <= 0):
            raise ValueError("need cone_step_rad > 0, cone_l_occ > 0, cone_l_free < 0 and "
                             "cone_l_no_return ≤ 0")
        if not (math.isfinite(self.free_sigmas) and self.free_sigmas >= 0):
            raise ValueError(f"need a finite free_sigmas ≥ 0, got {self.free_sigmas}")
        if not self.lone_sigma_m > 0:
            raise ValueError(f"need lone_sigma_m > 0 (inf: off), got {self.lone_sigma_m}")
        if math.isnan(self.no_return_stop):
            raise ValueError("no_return_stop must be a log-odds value or inf (never stop), "
                             "got nan")
        if self.stop_at_end_cells not in (0, 1):
            raise ValueError(f"need stop_at_end_cells 0 (any cell above no_return_stop stops a "
                             f"silent beam) or 1 (only one holding an end point), got "
                             f"{self.stop_at_end_cells}")
        if not (math.isfinite(self.ahead_floor) and 0 <= self.ahead_floor <= 1):
            raise ValueError(f"need ahead_floor within 0 … 1, got {self.ahead_floor}")
        if not (math.isfinite(self.between_steps) and 0 <= self.between_steps <= 1):
            raise ValueError(f"need between_steps within 0 … 1 (0: off), got "
                             f"{self.between_steps}")
        if not (self.between_end_cells in range(1, 1001)):
            raise ValueError(f"need a whole number 1 … 1000 of between_end_cells (1: every "
                             f"cell between the end points' own), got {self.between_end_cells}")
        if not self.hold_sigma_m >= 0:
            raise ValueError(f"need hold_sigma_m ≥ 0, got {self.hold_sigma_m}")
        for name in ("hit_depth_cells", "edge_jump_cells"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"need a finite {name} ≥ 0, got {value}")
        if not (math.isfinite(self.explain_sigmas) and self.explain_sigmas >= 0):
            raise ValueError(f"need a finite explain_sigmas ≥ 0 (0: off), got "
                             f"{self.explain_sigmas}")
        if not (math.isfinite(self.explain_log_odds) and self.explain_log_odds > 0):
            raise ValueError(f"need a finite explain_log_odds > 0, got {self.explain_log_odds}")
        if not (math.isfinite(self.explain_sharper) and self.explain_sharper >= 1):
            raise ValueError(f"need a finite explain_sharper ≥ 1, got {self.explain_sharper}")
        if not (self.neighbour_steps in range(0, 1001)):
            raise ValueError(f"need a whole number 0 … 1000 of neighbour_steps (0: off), got "
                             f"{self.neighbour_steps}")
        if not (self.occ_sigma_m > 0 and self.l_occ_min >= 0):
            raise ValueError(f"need occ_sigma_m > 0 and l_occ_min ≥ 0, got "
                             f"{self.occ_sigma_m}, {self.l_occ_min}")


# --------------------------------------------------------------------------- traversal


@dataclass(frozen=True)
class Visits:
    """Cells crossed by a batch of segments, one row per (segment, cell) visit.

    ``ray`` indexes the input segments, ``ix``/``iy`` the cell, ``t_enter``/``t_exit`` the
    fraction (0…1) of the segment at which it enters and leaves the cell. Visits are ordered
    by ray, then along the ray. Segments entirely outside the grid have no visits.
    """

    ray: np.ndarray
    ix: np.ndarray
    iy: np.ndarray
    t_enter: np.ndarray
    t_exit: np.ndarray


def traverse(x0, y0, x1, y1, origin_xy_m, shape, resolution_m) -> Visits:
    """Every grid cell each segment (x0, y0) → (x1, y1) (metres) crosses, exactly.

    Amanatides–Woo in the compiled walk (irring/maps/_traverse.pyx, shared with
    :meth:`OccupancyGrid.insert`): segments are clipped to the grid (Liang–Barsky), then
    walked column by column along their major axis.
    Conventions for the hard cases: a segment running exactly along a cell border belongs
    to the cells above / right of it (``floor``); a segment through a cell corner does not
    visit the two cells it only touches (nor any cell it stays in for less than 1e-9 cells);
    a zero-length segment visits the one cell holding it; parts outside the grid are dropped.
    """
    ny, nx = int(shape[0]), int(shape[1])
    res = float(resolution_m)
    with np.errstate(all="ignore"):   # non-finite segments are dropped by the walk
        g = [(np.asarray(v, dtype=float).ravel() - origin_xy_m[i % 2]) / res
             for i, v in enumerate((x0, y0, x1, y1))]
        dx, dy = g[2] - g[0], g[3] - g[1]
    return Visits(*_traverse.walk(g[0], g[1], dx, dy, nx, ny))


# --------------------------------------------------------------------------- the grid


def _flat(values) -> np.ndarray:
    """A flat float64 C-contiguous array (a view where it already is one), for the kernel."""
    return np.ascontiguousarray(values, dtype=float).ravel()


# A run keeps ~60 bytes per cell (log-odds, ground-truth labels and distances, the picture's
# RGBA raster and a palette frame); 25 M cells (a 50 m × 50 m room at 10 mm) is ~1.5 GB.
MAX_GRID_CELLS = 25_000_000
BYTES_PER_CELL = 60


def check_grid_size(ny: int, nx: int, resolution_m: float, where: str = "the map",
                    advice: str | None = None, room: str = "") -> None:
    """Raise :class:`irring.errors.TooBig` (before anything is allocated) for a grid of more
    than :data:`MAX_GRID_CELLS` cells, naming the memory it would need; ``advice`` says
    what to change (default: a scenario's cells or room, ``room`` said after it)."""
    cells = int(ny) * int(nx)
    if cells > MAX_GRID_CELLS:
        scale = math.sqrt(cells / MAX_GRID_CELLS)
        fix = advice or (f"use coarser cells (map.resolution_mm ≥ "
                         f"{math.ceil(resolution_m * 1e3 * scale)}) or a smaller room{room}")
        raise TooBig(f"{where}: a grid of {ny:,} × {nx:,} cells of {resolution_m * 1e3:g} mm "
                     f"would need about {gigabytes(cells * BYTES_PER_CELL)}; at most "
                     f"{MAX_GRID_CELLS:,} cells (~{MAX_GRID_CELLS * BYTES_PER_CELL / 1e9:.1f} GB) "
                     f"are mapped: {fix}")


def _layout(lo_xy_m, hi_xy_m, resolution_m: float) -> tuple[np.ndarray, tuple[int, int]]:
    """(origin, (ny, nx)) of :meth:`OccupancyGrid.covering`."""
    res = float(resolution_m)
    origin = np.floor(np.asarray(lo_xy_m, dtype=float) / res + 1e-9) * res - res / 2
    shape = np.ceil((np.asarray(hi_xy_m, dtype=float) - origin) / res - 1e-9).astype(int) + 1
    return origin, (int(shape[1]), int(shape[0]))


def _scenario_box(scenario) -> tuple[np.ndarray, np.ndarray]:
    outline = np.asarray(scenario.room.outline_m, dtype=float)
    return (outline.min(axis=0) - scenario.map.margin_m,
            outline.max(axis=0) + scenario.map.margin_m)


def check_covering(lo_xy_m, hi_xy_m, resolution_m: float, where: str,
                   advice: str | None = None) -> None:
    """:func:`check_grid_size` for the grid :meth:`OccupancyGrid.covering` would build."""
    _, (ny, nx) = _layout(lo_xy_m, hi_xy_m, resolution_m)
    check_grid_size(ny, nx, resolution_m, where, advice)


def check_scenario_grid(scenario) -> None:
    """:func:`check_grid_size` for the grid :meth:`OccupancyGrid.for_scenario` would build."""
    _, (ny, nx) = _layout(*_scenario_box(scenario), scenario.map.resolution_m)
    # the span shows a room written in mm under outline_m (2600 m for 2.6 m) for what it is
    w, h = np.ptp(np.asarray(scenario.room.outline_m, dtype=float), axis=0)
    room = (f" (its outline spans {_metres(w)} × {_metres(h)} m; room.outline_m is read in "
            f"metres, outline_mm in millimetres)")
    # coarser cells than the schema allows are no remedy: name the room alone then
    coarsest = bounds(type(scenario.map), "resolution_m")[1]
    _, (cy, cx) = _layout(*_scenario_box(scenario), coarsest)
    advice = None if cy * cx <= MAX_GRID_CELLS else (
        f"use a smaller room{room}; even the coarsest cells (map.resolution_mm "
        f"{coarsest * 1e3:g}) would be {cy:,} × {cx:,}")
    check_grid_size(ny, nx, scenario.map.resolution_m, f"{scenario.source or scenario.name}",
                    advice=advice, room=room)


def _metres(x: float) -> str:
    return f"{x:,.0f}" if x >= 100 else f"{x:.3g}"


class OccupancyGrid:
    """A 2-D log-odds occupancy grid (paper §IV).

    ``origin_xy_m`` is the world position of the outer corner of cell (0, 0); ``shape`` is
    (rows, columns) = (ny, nx); ``log_odds[iy, ix]`` starts at 0 (probability ½, unknown).
    """

    def __init__(self, origin_xy_m, shape, resolution_m: float = 0.010,
                 params: MapperParams | None = None):
        if resolution_m <= 0:
            raise ValueError(f"resolution_m must be > 0, got {resolution_m}")
        ny, nx = (int(s) for s in shape)
        if ny < 1 or nx < 1:
            raise ValueError(f"shape must be at least 1 × 1 cells, got {tuple(shape)}")
        check_grid_size(ny, nx, resolution_m)
        self.origin_xy_m = np.asarray(origin_xy_m, dtype=float).reshape(2).copy()
        self.resolution_m = float(resolution_m)
        self.params = params or MapperParams()
        self.log_odds = np.zeros((ny, nx))
        # the cells holding a valid reading's end point: with stop_at_end_cells, the only
        # cells that stop a silent beam (a hit's spread into the cell in front of it is not)
        self.end_cells = np.zeros((ny, nx), np.uint8)

    # ---- construction

    @classmethod
    def covering(cls, lo_xy_m, hi_xy_m, resolution_m: float = 0.010,
                 params: MapperParams | None = None) -> OccupancyGrid:
        """A grid covering the box ``lo_xy_m`` … ``hi_xy_m`` (world (x, y), metres).

        The origin is shifted by half a cell so walls on round coordinates (multiples of
        the resolution) run through cell centres rather than along cell borders — a wall's
        surface then lies in one row of cells instead of on the fence between two. A box
        edge on a round coordinate counts as on it despite round-off (−0.1 / 0.01 is
        −10.000000000000002), so it gets no extra row of cells.
        """
        origin, shape = _layout(lo_xy_m, hi_xy_m, resolution_m)
        return cls(origin, shape, resolution_m, params)

    @classmethod
    def for_scenario(cls, scenario, params: MapperParams | None = None) -> OccupancyGrid:
        """A grid covering the room outline plus ``scenario.map.margin_m`` on every side
        (:meth:`covering`: walls on round coordinates run through cell centres)."""
        return cls.covering(*_scenario_box(scenario), scenario.map.resolution_m, params)

    def empty_like(self) -> OccupancyGrid:
        return OccupancyGrid(self.origin_xy_m, self.shape, self.resolution_m, self.params)

    # ---- geometry

    @property
    def shape(self) -> tuple[int, int]:
        return self.log_odds.shape  # type: ignore[return-value]

    @property
    def extent_m(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) of the grid's outer border (for imshow)."""
        ny, nx = self.shape
        x0, y0 = self.origin_xy_m
        return (x0, x0 + nx * self.resolution_m, y0, y0 + ny * self.resolution_m)

    def cell_of(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """(ix, iy) of the cells holding world points (may lie outside the grid)."""
        ix = np.floor((np.asarray(x, float) - self.origin_xy_m[0]) / self.resolution_m)
        iy = np.floor((np.asarray(y, float) - self.origin_xy_m[1]) / self.resolution_m)
        return ix.astype(np.int64), iy.astype(np.int64)

    def cell_centers(self) -> tuple[np.ndarray, np.ndarray]:
        """World x (nx,) and y (ny,) of the cell centres."""
        ny, nx = self.shape
        x = self.origin_xy_m[0] + (np.arange(nx) + 0.5) * self.resolution_m
        y = self.origin_xy_m[1] + (np.arange(ny) + 0.5) * self.resolution_m
        return x, y

    # ---- updates

    def _add(self, log_odds: np.ndarray, points: Points, lo: float, hi: float,
             placed: bool = False, ends: np.ndarray | None = None) -> None:
        """Add the log-odds of ``points`` to ``log_odds`` (this grid's shape, float64,
        C-contiguous) and clamp the cells their beams can reach to [lo, hi] (the kernel's
        ``add_beams``), with the hits between a sensor's steps (:func:`add_between`). Work
        and memory scale with the beams, not the grid. Readings from a cone go in as
        :func:`cone_fan` with the ``cone_*`` weights; pencil beams are first placed as
        :func:`placed_readings` places a batch of its own (``placed``: they are already); σ
        as :func:`known_sigma`."""
        if not placed:
            points = self.placed_readings([points])[0]
        # (a sweep's pencil beams, before their clamp; a cone's fan has no steps to join)
        add_between(log_odds, points, self.origin_xy_m, self.resolution_m, self.params)
        points, params = mapped_beams(points, self.params, self.resolution_m)
        _traverse.add_beams(
            log_odds, _flat(points.origin_x), _flat(points.origin_y), _flat(points.heading),
            _flat(points.x), _flat(points.y), _flat(points.sigma_m),
            np.asarray(points.valid, bool).ravel().view(np.uint8),
            (np.asarray(points.reason).ravel() == _NO_RETURN).view(np.uint8),
            _flat(np.full(np.shape(points.valid), np.nan) if points.reach_m is None
                  else points.reach_m),
            math.prod(np.shape(points.valid)[1:]),       # a step's readings (its sensors)
            float(points.max_range_m), float(self.origin_xy_m[0]), float(self.origin_xy_m[1]),
            self.resolution_m, params, lo, hi, self.end_cells if ends is None else ends)

    def delta(self, points: Points) -> np.ndarray:
        """The log-odds change (ny, nx) the readings in ``points`` would add to this grid
        (before clamping; no-return beams stop at cells this grid holds occupied)."""
        out = np.array(self.log_odds, dtype=float, order="C")
        self._add(out, points, -np.inf, np.inf, ends=self.end_cells.copy())
        return out - self.log_odds

    def insert(self, points: Points, placed: bool = False) -> None:
        """Add one batch of readings (typically a sweep) to the map; only the cells its beams
        can reach are touched. Its readings are first placed as :meth:`placed_readings`
        places a batch alone, unless ``placed`` says that they already are (a batch of a
        run, placed against the whole run)."""
        self.log_odds = np.ascontiguousarray(self.log_odds, dtype=float)   # (as the kernel wants)
        self._add(self.log_odds, points, self.params.l_min, self.params.l_max, placed)

    def placed_readings(self, batches: Sequence[Points]) -> list[Points]:
        """:func:`placed_readings` on this grid's cells and with its mapper numbers."""
        return placed_readings(batches, self.shape, self.origin_xy_m, self.resolution_m,
                               self.params)

    def insert_run(self, batches: Sequence[Points]) -> None:
        """Add a run's batches (sweeps) so that its silent beams stop at every surface the
        run's returns establish, whichever batch saw it, and a reading that surface explains
        ends on it: the batches' readings placed against the whole run
        (:meth:`placed_readings`), every batch's returns (:func:`returns_of`) in order, then
        every batch's silent beams (:func:`silences_of_run`: in one insert).
        A silent beam never lowers a cell above ``no_return_stop``, so the second part does
        not depend on the order of the batches (docs/mapping.md, "Silent beams and the
        run's returns"); nor does the first, but for the clamps."""
        for points in self.placed_readings(batches):
            self.insert(returns_of(points), placed=True)
        for points in silences_of_run(batches):
            self.insert(points)

    # ---- reading the map

    def classify(self) -> np.ndarray:
        """int8 (ny, nx): OCCUPIED (1), FREE (0) or UNKNOWN (−1), with map_server's thresholds."""
        return classify(self.log_odds)

    # ---- ROS map_server export

    def to_pgm(self, path) -> tuple[Path, Path]:
        """Write ``path`` (.pgm, binary P5) and the YAML next to it (same stem), as ROS
        map_saver does: free 254, occupied 0, unknown 205; the image's top row is the
        grid's highest y; ``origin`` is the world pose of the lower-left pixel.
        Returns (pgm path, yaml path).
        """
        pgm = Path(path)
        if pgm.suffix != ".pgm":
            pgm = pgm.with_suffix(".pgm")
        yaml_path = pgm.with_suffix(".yaml")
        cls = self.classify()
        img = np.full(cls.shape, PGM_UNKNOWN, np.uint8)
        img[cls == FREE] = PGM_FREE
        img[cls == OCCUPIED] = PGM_OCCUPIED
        img = np.flipud(img)
        ny, nx = cls.shape
        header = f"P5\n# CREATOR: irring {self.resolution_m:.3f} m/pix\n{nx} {ny}\n255\n"
        pgm.parent.mkdir(parents=True, exist_ok=True)
        pgm.write_bytes(header.encode("ascii") + np.ascontiguousarray(img).tobytes())
        yaml_path.write_text(
            f"image: {pgm.name}\n"
            f"mode: trinary\n"
            f"resolution: {self.resolution_m:.6f}\n"
            f"origin: [{self.origin_xy_m[0]:.6f}, {self.origin_xy_m[1]:.6f}, 0.000000]\n"
            f"negate: 0\n"
            f"occupied_thresh: {OCCUPIED_THRESH}\n"
            f"free_thresh: {FREE_THRESH}\n")
        return pgm, yaml_path

    @classmethod
    def from_pgm(cls, yaml_path, params: MapperParams | None = None) -> OccupancyGrid:
        """Read a map_server YAML + PGM pair (as :meth:`to_pgm` or map_saver write it).

        Pixels are classified the way map_server does (p = (255 − v)/255, or v/255 with
        ``negate: 1``; occupied above occupied_thresh, free below free_thresh); occupied
        cells get ``l_max``, free ``l_min``, unknown 0.
        """
        yaml_path = Path(yaml_path)
        meta = safe_yaml.load_file(yaml_path, "map_server YAML")
        missing = {"image", "resolution", "origin", "negate", "occupied_thresh",
                   "free_thresh"} - set(meta if isinstance(meta, dict) else {})
        if missing:
            raise ValueError(f"{yaml_path}: not a map_server YAML, missing {sorted(missing)}")

        def number(value, key: str, what: str, ok) -> float:
            # a damaged or hand-edited file: one line naming it and the key, not a TypeError
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not ok(value):
                raise ValueError(f"{yaml_path}: {key}: expected {what}, got {value!r}")
            return float(value)

        origin = meta["origin"]
        if not (isinstance(origin, list) and len(origin) in (2, 3)):
            raise ValueError(f"{yaml_path}: origin: expected [x, y, yaw], got {origin!r}")
        xy = [number(v, "origin", "[x, y, yaw] of finite numbers", math.isfinite)
              for v in origin]
        resolution = number(meta["resolution"], "resolution", "a number of metres > 0",
                            lambda v: math.isfinite(v) and v > 0)
        occ, free = (number(meta[key], key, "a number 0 … 1", lambda v: 0 <= v <= 1)
                     for key in ("occupied_thresh", "free_thresh"))
        if meta["negate"] not in (0, 1) or isinstance(meta["negate"], bool):
            raise ValueError(f"{yaml_path}: negate: expected 0 or 1, got {meta['negate']!r}")
        if not isinstance(meta["image"], str) or not meta["image"]:
            raise ValueError(f"{yaml_path}: image: expected a file name, got {meta['image']!r}")
        try:
            img = read_pgm(yaml_path.parent / meta["image"])
        except OSError as exc:
            raise ValueError(f"{yaml_path}: image: {meta['image']}: "
                             f"{exc.strerror or exc}") from None
        p = img.astype(float) / 255.0 if meta["negate"] else (255.0 - img) / 255.0
        grid = cls(xy[:2], img.shape, resolution, params)
        lo = np.zeros(img.shape)
        lo[p > occ] = grid.params.l_max
        lo[p < free] = grid.params.l_min
        grid.log_odds = np.flipud(lo).copy()
        grid.end_cells[...] = 1        # (which cells hold end points is not kept: any may)
        return grid


def classify(log_odds: np.ndarray) -> np.ndarray:
    """int8 cells of a log-odds array (a grid's, or an animation frame's): OCCUPIED (1), FREE
    (0) or UNKNOWN (−1), with map_server's thresholds."""
    prob = 1.0 / (1.0 + np.exp(-log_odds))              # P(occupied)
    out = np.full(np.shape(log_odds), UNKNOWN, np.int8)
    out[prob > OCCUPIED_THRESH] = OCCUPIED
    out[prob < FREE_THRESH] = FREE
    return out


def read_pgm(path) -> np.ndarray:
    """A binary (P5) 8-bit PGM as a uint8 array (rows top to bottom); comments allowed."""
    data = Path(path).read_bytes()
    fields: list[bytes] = []
    pos = 0
    while len(fields) < 4:
        while pos < len(data) and data[pos:pos + 1].isspace():
            pos += 1
        if pos >= len(data) or data[pos:pos + 1] == b"#" and b"\n" not in data[pos:]:
            raise ValueError(f"{path}: cut short in its header (magic, width, height and "
                             f"maxval, then the pixels)")
        if data[pos:pos + 1] == b"#":
            pos = data.index(b"\n", pos) + 1
            continue
        end = pos
        while end < len(data) and not data[end:end + 1].isspace():
            end += 1
        fields.append(data[pos:end])
        pos = end
    if fields[0] != b"P5":
        raise ValueError(f"{path}: not a binary PGM (magic {fields[0]!r}, expected b'P5')")
    for name, field in zip(("width", "height", "maxval"), fields[1:]):
        if not field.isdigit() or int(field) == 0:
            raise ValueError(f"{path}: its {name} {field!r} is not a whole number ≥ 1")
    width, height, maxval = (int(f) for f in fields[1:])
    if maxval != 255:
        raise ValueError(f"{path}: only 8-bit PGM (maxval 255) is supported, got {maxval}")
    pixels = data[pos + 1:pos + 1 + width * height]
    if len(pixels) != width * height:
        raise ValueError(f"{path}: truncated, {len(pixels)} of {width * height} pixels")
    return np.frombuffer(pixels, np.uint8).reshape(height, width).copy()


def cone_fan(points: Points, step_rad: float) -> Points:
    """Each reading of a wide-cone sensor as a fan of rays across its cone, ≤ ``step_rad``
    apart (an odd number, one on the axis), all of the reading's range from its emitter:
    (S, N) readings → (S, N·n) rays, with ``cone_half_angle_rad`` 0 (pencil beams)."""
    half = float(points.cone_half_angle_rad)
    n = 2 * int(math.ceil(half / step_rad)) + 1
    offsets = np.linspace(-half, half, n)
    rows = np.shape(points.valid)[0]
    cols = n * math.prod(np.shape(points.valid)[1:])   # (not −1: an empty batch has no rows)

    def fan(a):
        return np.repeat(np.asarray(a)[..., None], n, axis=-1).reshape(rows, cols)

    heading = (np.asarray(points.heading, float)[..., None] + offsets).reshape(rows, cols)
    d, ox, oy = fan(points.d), fan(points.origin_x), fan(points.origin_y)
    return dataclasses.replace(
        points, x=ox + d * np.cos(heading), y=oy + d * np.sin(heading), d=d,
        theta=fan(points.theta), origin_x=ox, origin_y=oy, heading=heading,
        sigma_m=fan(points.sigma_m), iterations=fan(points.iterations), valid=fan(points.valid),
        reason=fan(points.reason), cone_half_angle_rad=0.0,
        reach_m=None if points.reach_m is None else fan(points.reach_m))


def known_sigma(points: Points) -> Points:
    """``points`` as the mapper takes them: a valid reading whose σ is +inf (its accuracy
    unknown, its end point anywhere on its beam) is mapped as no reading at all, neither a
    hit nor free space (the limit of the lone_sigma_m/σ weight); a σ of −inf is floored like
    any σ below ``min_sigma_m``. NaN (no σ given) takes ``default_sigma_m`` later. The one
    home of that rule for the kernel and the numpy oracle (docs/mapping.md)."""
    sigma = np.asarray(points.sigma_m, float)
    if not np.isinf(sigma).any():     # one pass for the usual batch, which has neither
        return points
    unknown = np.asarray(points.valid, bool) & (sigma == np.inf)
    below = sigma == -np.inf
    return points_with(points, valid=np.asarray(points.valid, bool) & ~unknown,
                       sigma_m=np.where(below, 0.0, sigma))


def mapped_beams(points: Points, params: MapperParams, resolution_m: float
                 ) -> tuple[Points, MapperParams]:
    """The pencil beams a batch of readings is mapped as, and the weights they take on
    cells of ``resolution_m``: readings from a wide cone (``cone_half_angle_rad`` > 0) as
    :func:`cone_fan` with the ``cone_*`` weights (an arc holds no cell: no sharp end point;
    its hit keeps its floor in front of the arc), others as they are; the σ floor
    ``min_sigma_m`` at most ``min_sigma_cells`` cells (docs/mapping.md, "A sharp hit on
    fine cells")."""
    floor = params.min_sigma_cells * resolution_m
    if floor < params.min_sigma_m:
        params = dataclasses.replace(params, min_sigma_m=floor)
    if points.cone_half_angle_rad > 0:
        return cone_fan(points, params.cone_step_rad), dataclasses.replace(
            params, l_occ=params.cone_l_occ, l_free=params.cone_l_free,
            l_no_return=params.cone_l_no_return, hold_sigma_m=0.0, ahead_floor=1.0)
    return points, params


def hit_weight(sigma: np.ndarray, params: MapperParams) -> np.ndarray:
    """The log-odds of a valid reading's hit at its end point, from its σ (m, floored):
    l_occ up to ``occ_sigma_m``, l_occ·occ_sigma_m/σ beyond, at least l_occ_min, and that
    floor scaled by lone_sigma_m/σ beyond ``lone_sigma_m`` (docs/mapping.md)."""
    trust = np.minimum(1.0, params.lone_sigma_m / sigma)
    return np.maximum(min(params.l_occ_min, params.l_occ) * trust,
                      params.l_occ * np.minimum(1.0, params.occ_sigma_m / sigma))


def ahead_weight(sigma: np.ndarray, params: MapperParams) -> np.ndarray:
    """The log-odds peak of a valid reading's hit in the cells wholly in front of its end
    point, from its σ (m, floored): the σ-weighted hit l_occ·min(1, occ_sigma_m/σ), the
    l_occ_min floor only by ``ahead_floor``; a reading above ``lone_sigma_m`` its
    :func:`hit_weight` there too (docs/mapping.md, "Fine cells")."""
    sigma = np.asarray(sigma, float)
    floored = params.l_occ * np.minimum(1.0, params.occ_sigma_m / sigma)
    floor = params.ahead_floor * min(params.l_occ_min, params.l_occ)
    return np.where(sigma <= params.lone_sigma_m, np.maximum(floor, floored),
                    hit_weight(sigma, params))


def between_steps(points: Points, shape, origin_xy_m, resolution_m: float,
                  params: MapperParams) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(iy, ix, log-odds) the hits between a sensor's consecutive steps add: for valid
    readings of σ ≤ ``lone_sigma_m`` in consecutive rows (steps) of one column (sensor)
    whose ranges differ by at most ``explain_sigmas`` combined σ plus what a flat surface at
    the smaller of their θ draws the range out by over the beams' turn, d·Δh·tan θ (one
    surface the beam swept from one to the other), every cell the segment between their end
    points crosses at least ``between_end_cells`` cells (Chebyshev) from both end cells,
    ``between_steps`` × the weaker :func:`hit_weight` of the two once. None
    when there is nothing to add (off, a cone, a batch that is not a sweep's rows). Numpy,
    the same for the compiled insert and the oracle (docs/mapping.md, "Fine
    cells")."""
    shape_p = np.shape(points.valid)
    if (params.between_steps <= 0 or points.cone_half_angle_rad > 0 or len(shape_p) != 2
            or shape_p[0] < 2):
        return None
    x, y = np.asarray(points.x, float), np.asarray(points.y, float)
    d = np.asarray(points.d, float)
    sigma = np.maximum(np.nan_to_num(np.asarray(points.sigma_m, float),
                                     nan=params.default_sigma_m), params.min_sigma_m)
    with np.errstate(invalid="ignore"):
        ok = (np.asarray(points.valid, bool) & np.isfinite(x + y + d)
              & (sigma <= params.lone_sigma_m))
        # a flat surface met at θ draws the range out by about d·Δh·tan θ over a turn of
        # Δh between the beams: that much more (at the pair's smaller θ, so a square-on
        # reading beside an edge allows none) is one surface still
        theta = np.nan_to_num(np.minimum(np.asarray(points.theta, float)[1:],
                                         np.asarray(points.theta, float)[:-1]))
        turn = np.diff(np.asarray(points.heading, float), axis=0)
        turn = np.abs(turn - 2.0 * np.pi * np.round(turn / (2.0 * np.pi)))
        slant = 0.5 * (d[1:] + d[:-1]) * turn * np.tan(theta)
        pair = (ok[:-1] & ok[1:] & (np.abs(d[1:] - d[:-1])
                                    <= params.explain_sigmas * np.hypot(sigma[1:], sigma[:-1])
                                    + slant))
    r, k = np.nonzero(pair)
    gap = params.between_end_cells
    with np.errstate(invalid="ignore"):
        cx, cy = (np.floor((c - o) / resolution_m) for c, o in ((x, origin_xy_m[0]),
                                                                (y, origin_xy_m[1])))
    if r.size:   # (end points in one cell or two sharing a side: no cell between them; end
        #           cells under 2·gap − 1 apart: none of them gap cells from both)
        dx = np.abs(cx[r + 1, k] - cx[r, k])
        dy = np.abs(cy[r + 1, k] - cy[r, k])
        apart = (dx + dy > 1) & (np.maximum(dx, dy) >= 2 * gap - 1)
        r, k = r[apart], k[apart]
    if r.size == 0:
        return None
    w = params.between_steps * np.minimum(hit_weight(sigma[r, k], params),
                                          hit_weight(sigma[r + 1, k], params))
    v = traverse(x[r, k], y[r, k], x[r + 1, k], y[r + 1, k], origin_xy_m, shape, resolution_m)
    inner = (v.t_enter > 0) & (v.t_exit < 1)     # (the end points' own cells have their hits)
    if gap > 1:
        a, b = (r[v.ray], k[v.ray]), (r[v.ray] + 1, k[v.ray])
        inner &= ((np.maximum(np.abs(v.ix - cx[a]), np.abs(v.iy - cy[a])) >= gap)
                  & (np.maximum(np.abs(v.ix - cx[b]), np.abs(v.iy - cy[b])) >= gap))
    if not inner.any():
        return None
    return v.iy[inner], v.ix[inner], w[v.ray[inner]]


def add_between(log_odds: np.ndarray, points: Points, origin_xy_m, resolution_m: float,
                params: MapperParams) -> None:
    """Add :func:`between_steps`' hits to ``log_odds`` in place, unclamped: part of the
    batch's returns, summed with its beams' before the clamp and before its silent beams
    look for a cell to stop at (the kernel's insert and the oracle alike)."""
    hits = between_steps(points, np.shape(log_odds), origin_xy_m, resolution_m, params)
    if hits is not None:
        np.add.at(log_odds, hits[:2], hits[2])


def explained_ranges(points: Points, shape, origin_xy_m, resolution_m: float,
                     params: MapperParams) -> np.ndarray:
    """(S, N) m: the range each valid reading a surface explains is mapped at instead of
    its own (NaN for the others), on a grid of ``shape`` (ny, nx) cells.

    A reading is explained when its σ lies in [``explain_sharper``·``min_sigma_m``,
    ``lone_sigma_m``] and its beam crosses, within ``explain_sigmas``·σ before its end point
    and leaving it at least a cell before, a cell that sharper end points of the batch
    confirm: the hits (:func:`hit_weight`) of those in it whose σ is at most
    σ/``explain_sharper`` reach ``explain_log_odds``. That surface, within the reading's
    noise in front of it, explains the reading, which is mapped at the middle of its beam's
    passage through the first such cell. Compiled (irring/maps/_traverse.pyx); the numpy
    oracle is :func:`irring.maps.mapping_numpy.explained_ranges`. docs/mapping.md says why
    and what it changed.
    """
    return _explained(known_sigma(points), shape, origin_xy_m, resolution_m, params)


def placed_readings(batches: Sequence[Points], shape, origin_xy_m, resolution_m: float,
                    params: MapperParams, neighbours=None, explained=None) -> list[Points]:
    """Each batch (sweep) as the map takes its readings (:func:`known_sigma`): pencil beams
    its sensors' neighbouring steps bracket moved first (:func:`neighbour_ranges`, within
    the batch: a sweep's rows), then those a sharper surface explains
    (:func:`explained_ranges`) moved onto it, where that surface is confirmed by the end
    points of **every batch given**, not only the reading's own: a wall other sweeps or
    poses saw sharper ends the beam that meets it. ``neighbours(points, params)`` and
    ``explained(points, shape, origin_xy_m, resolution_m, params)`` default to the compiled
    rules (the numpy oracle passes its own). docs/mapping.md, "Explained against the run"."""
    neighbours = neighbour_ranges if neighbours is None else neighbours
    explained = _explained if explained is None else explained
    out = [known_sigma(p) for p in batches]
    pencil = [i for i, p in enumerate(out)
              if p.cone_half_angle_rad == 0 and np.any(p.valid)]    # (silent beams: none)
    for i in pencil:
        out[i] = along_beams(out[i], neighbours(out[i], params))
    if params.explain_sigmas <= 0 or not pencil:
        return out
    if len(pencil) == 1:     # (one insert: its batch as it is, no copies)
        only = pencil[0]
        out[only] = at_ranges(out[only], explained(out[only], shape, origin_xy_m,
                                                   resolution_m, params), params)
        return out
    # every batch's end points as one row: each reading against the run's surfaces
    ranges = np.asarray(explained(joined_row([out[i] for i in pencil]), shape, origin_xy_m,
                                  resolution_m, params), float).ravel()
    start = 0
    for i in pencil:
        n = math.prod(np.shape(out[i].valid))
        out[i] = at_ranges(out[i], ranges[start:start + n].reshape(np.shape(out[i].valid)),
                           params)
        start += n
    return out


# Points' per-reading fields and the dtype a joined row holds them in
_READING_FIELDS = (("x", float), ("y", float), ("d", float), ("theta", float),
                   ("origin_x", float), ("origin_y", float), ("heading", float),
                   ("sigma_m", float), ("iterations", np.int64), ("valid", bool),
                   ("reason", np.uint8))


def joined_row(batches: Sequence[Points]) -> Points:
    """``batches`` (sweeps, each (S_i, N_i)) as one Points of shape (1, ΣS_i·N_i): every
    per-reading field joined in the same order (``reach_m`` NaN for a batch without one),
    ``max_range_m`` and ``cone_half_angle_rad`` the first batch's."""
    joined = {name: np.concatenate([np.asarray(getattr(p, name), dtype).ravel()
                                    for p in batches])[None, :]
              for name, dtype in _READING_FIELDS}
    if any(p.reach_m is not None for p in batches):
        joined["reach_m"] = np.concatenate([
            np.full(math.prod(np.shape(p.valid)), np.nan) if p.reach_m is None
            else np.asarray(p.reach_m, float).ravel() for p in batches])[None, :]
    else:
        joined["reach_m"] = None
    return points_with(batches[0], **joined)


def _explained(points: Points, shape, origin_xy_m, resolution_m: float,
               params: MapperParams) -> np.ndarray:
    """:func:`explained_ranges` of points already through :func:`known_sigma`."""
    ny, nx = (int(n) for n in shape)
    return _traverse.explained_ranges(
        _flat(points.origin_x), _flat(points.origin_y), _flat(points.x), _flat(points.y),
        _flat(points.sigma_m), np.asarray(points.valid, bool).ravel().view(np.uint8),
        float(origin_xy_m[0]), float(origin_xy_m[1]), float(resolution_m), nx, ny,
        params).reshape(np.shape(points.valid))


def neighbour_ranges(points: Points, params: MapperParams) -> np.ndarray:
    """(S, N) m: the range each valid reading its sensor's neighbouring steps bracket is
    mapped at, NaN for the others.

    A reading of σ from ``explain_sharper``·``min_sigma_m`` (one that cannot place its
    surface in one cell) whose sensor's nearest valid readings before and after it in the
    sweep (rows, at most ``neighbour_steps`` away, their beams on either side of its own)
    both end within ``explain_sigmas`` combined σ of its end point, and both read shorter
    than it (or, for σ up to ``lone_sigma_m``, both longer), is mapped at the farther
    (nearer) of their ranges: the median of the three. A reading of σ above
    ``lone_sigma_m`` with a valid reading within ``neighbour_steps`` on one side only,
    sharper, shorter and within ``explain_sigmas`` combined σ, is mapped at its range.
    Compiled
    (irring/maps/_traverse.pyx); the numpy oracle is
    :func:`irring.maps.mapping_numpy.neighbour_ranges`. docs/mapping.md says why ("A
    sensor's neighbouring steps")."""
    shape = np.shape(points.valid)
    if (params.neighbour_steps == 0 or points.cone_half_angle_rad > 0 or len(shape) != 2
            or shape[0] < 3):
        return np.full(shape, np.nan)
    return _traverse.neighbour_ranges(
        _flat(points.origin_x), _flat(points.origin_y), _flat(points.x), _flat(points.y),
        _flat(points.sigma_m), np.asarray(points.valid, bool).ravel().view(np.uint8),
        shape[0], shape[1], params).reshape(shape)


def along_beams(points: Points, ranges: np.ndarray, sigma_m=None) -> Points:
    """``points`` with each valid reading whose ``ranges`` (m) entry is finite moved along
    its beam to that range (with σ ``sigma_m`` where given); the others as they are."""
    moved = np.asarray(points.valid, bool) & np.isfinite(ranges)
    if not moved.any():
        return points
    at = np.flatnonzero(moved)     # a few readings of a batch: computed there alone

    def picked(v):
        return np.asarray(v, float).ravel()[at]

    ox, oy, px, py = (picked(v) for v in (points.origin_x, points.origin_y, points.x, points.y))
    r = picked(ranges)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = r / np.hypot(px - ox, py - oy)
    x, y, d = (np.array(v, float) for v in (points.x, points.y, points.d))
    x.ravel()[at], y.ravel()[at], d.ravel()[at] = ox + (px - ox) * scale, oy + (py - oy) * scale, r
    sigma = points.sigma_m
    if sigma_m is not None:
        sigma = np.array(points.sigma_m, float)
        sigma.ravel()[at] = np.broadcast_to(sigma_m, sigma.shape).ravel()[at]
    return points_with(points, x=x, y=y, d=d, sigma_m=sigma)


def at_ranges(points: Points, ranges: np.ndarray, params: MapperParams) -> Points:
    """``points`` with each valid reading whose ``ranges`` (m) entry is finite moved along
    its beam to that range, with σ/``explain_sharper`` (the σ of the readings that confirm
    the surface it was moved to); the others as they are."""
    return along_beams(points, ranges, np.asarray(points.sigma_m, float) / params.explain_sharper)


def returns_of(points: Points) -> Points:
    """``points`` with its silent beams (NO_RETURN) mapping nothing (a reach of 0) but still
    marking its occluding edges (the surface's depth): the valid readings' part of a batch."""
    silent = np.asarray(points.reason) == _NO_RETURN
    if not silent.any():
        return points
    reach = (np.full(silent.shape, np.nan) if points.reach_m is None
             else np.asarray(points.reach_m, float))
    return points_with(points, reach_m=np.where(silent, 0.0, reach))


def silences_of(points: Points) -> Points:
    """``points`` with no valid reading: only its silent beams map (to their reach, or to
    the first cell the grid holds above ``no_return_stop``)."""
    return points_with(points, valid=np.zeros(np.shape(points.valid), bool))


def silences_of_run(batches: Sequence[Points]) -> list[Points]:
    """:func:`silences_of` each batch, joined into one batch (one row) where they share the
    max range and cone: the order of silent beams does not matter (they never lower a cell
    that stops them), so one insert maps them as the batches' own would, with one call."""
    batches = list(batches)
    if not batches:
        return []
    kinds = {(float(p.max_range_m), float(p.cone_half_angle_rad)) for p in batches}
    if len(kinds) > 1:
        return [silences_of(p) for p in batches]
    silent = [np.asarray(p.reason).ravel() == _NO_RETURN for p in batches]

    def joined(values):
        return np.concatenate([np.asarray(v, float).ravel()[k]
                               for v, k in zip(values, silent)])[None, :]

    reach = joined([np.full(k.shape, np.nan) if p.reach_m is None else p.reach_m
                    for p, k in zip(batches, silent)])
    if reach.size == 0:
        return []
    nan = np.full(reach.shape, np.nan)     # a silent beam has no end point, d, θ or σ
    return [points_with(
        batches[0], x=nan, y=nan, d=nan, theta=nan, sigma_m=nan,
        origin_x=joined([p.origin_x for p in batches]),
        origin_y=joined([p.origin_y for p in batches]),
        heading=joined([p.heading for p in batches]), iterations=np.zeros(reach.shape, int),
        valid=np.zeros(reach.shape, bool), reason=np.full(reach.shape, _NO_RETURN, np.uint8),
        reach_m=reach)]


class RunSilences:
    """The log-odds :meth:`OccupancyGrid.insert_run` makes of a run's first k batches, bit for
    bit, for k = 1, 2, … in turn (an animation's frames), without walking every earlier
    batch's silent beams again for each k where it can: a batch is walked again only when
    the returns changed whether a cell one of its beams passes or stops on holds more than
    ``no_return_stop``. Batches of different max ranges or cones, runs whose batches keep
    crossing each other (``RECOUNT_COST``, after ``HEAD_START`` walks) and runs whose kept
    passes would pass ``MAX_KEPT_BYTES`` are walked joined, as insert_run walks them. How
    and why: docs/mapping.md, "Pictures".
    """

    # walking one batch's silent beams alone costs about this many times its share of a
    # joined insert of all of them (2.2× in a T-room of 100 sweeps, 3× in a 6 m room)
    RECOUNT_COST = 3.0
    HEAD_START = 50        # walks any run may spend before its crowding is judged
    # what the kept passes may take (a box of int32 passes and bool cells a sweep: 0.13 MB
    # in the T-room); a longer run is walked joined from there on
    MAX_KEPT_BYTES = 200_000_000

    def __init__(self, grid: OccupancyGrid, batches: Sequence[Points]):
        self._grid, self._batches = grid, list(batches)
        params = grid.params
        self._stop = params.no_return_stop
        kinds = {(float(p.max_range_m), float(p.cone_half_angle_rad)) for p in self._batches}
        self._incremental = len(kinds) <= 1
        if not self._incremental:
            return
        self._l_nr = (mapped_beams(self._batches[0], params, grid.resolution_m)[1].l_no_return
                      if self._batches else params.l_no_return)
        # passes counted as −1 each, from a base below the stop that they cannot round off
        self._counter = OccupancyGrid(grid.origin_xy_m, grid.shape, grid.resolution_m,
                                      dataclasses.replace(params, l_no_return=-1.0,
                                                          cone_l_no_return=-1.0))
        self._counter.end_cells[...] = 1      # (its stops are the cells set to +inf)
        stop = self._stop
        self._base = min(0.0, math.floor(stop) - 1.0) if math.isfinite(stop) else 0.0
        self._passes = np.zeros(grid.shape, np.int64)
        self._above = np.zeros(grid.shape, bool)
        # per batch, in the box of cells its silent beams can reach (rows r0:r1, columns
        # c0:c1): how often they pass each cell, and the cells whose change could move where
        # one of them stops (those passed, their neighbours and the emitters' cells)
        self._kept: list[tuple[int, int, int, int, np.ndarray, np.ndarray]] = []
        self._recounts = self._walks = 0   # batches walked alone; as many walked joined
        self._kept_bytes = 0

    def log_odds(self, returns: OccupancyGrid, k: int) -> np.ndarray:
        """(ny, nx): ``returns`` (every return of the first ``k`` batches, as insert_run's
        first part leaves them) with the silent beams of the first ``k`` batches; k never
        smaller than in the call before."""
        if self._incremental:
            above = returns.log_odds > self._stop
            if self._grid.params.stop_at_end_cells:
                above &= returns.end_cells != 0
            changed = above != self._above
            stale = []
            if changed.any():
                stale = [j for j, (r0, r1, c0, c1, _, near) in enumerate(self._kept)
                         if (changed[r0:r1, c0:c1] & near).any()]
            stale += range(len(self._kept), k)
            self._recounts += len(stale)
            self._walks += k
            if (self._recounts * self.RECOUNT_COST <= max(self._walks, self.HEAD_START)
                    and self._kept_bytes <= self.MAX_KEPT_BYTES):
                return self._recounted(returns, above, stale)
            self._incremental = False     # crowded or long: walk them all from now on
            del self._kept, self._passes, self._above
        grid = OccupancyGrid(returns.origin_xy_m, returns.shape, returns.resolution_m,
                             returns.params)
        grid.log_odds = returns.log_odds.copy()
        grid.end_cells = returns.end_cells.copy()
        for q in silences_of_run(self._batches[:k]):
            grid.insert(q)
        return grid.log_odds

    def _recounted(self, returns: OccupancyGrid, above: np.ndarray, stale) -> np.ndarray:
        self._above = above
        if stale:
            counting = np.where(above, np.inf, self._base)
            for j in stale:
                self._recount(j, counting)
        out = returns.log_odds + self._passes * self._l_nr
        return np.clip(out, self._grid.params.l_min, self._grid.params.l_max, out=out)

    def _recount(self, j: int, counting: np.ndarray) -> None:
        """Walk batch j's silent beams on ``counting`` (restored after) and keep its passes
        and the cells where a change could move one of its beams' stops."""
        g, points = self._grid, self._batches[j]
        if j < len(self._kept):
            r0, r1, c0, c1, passes, near = self._kept[j]
            self._passes[r0:r1, c0:c1] -= passes
            self._kept_bytes -= passes.nbytes + near.nbytes
        else:
            r0, r1, c0, c1 = self._box(points)
        before = counting[r0:r1, c0:c1].copy()
        self._counter._add(counting, silences_of(points), -np.inf, np.inf)
        now = counting[r0:r1, c0:c1]
        walked = now != before
        passes = np.where(walked, self._base - now, 0.0).astype(np.int32)
        now[...] = before
        self._passes[r0:r1, c0:c1] += passes
        # a beam stops on the cell after its last pass (an edge or a corner away) or, passing
        # none, on its first: its emitter's
        near = walked.copy()
        near[1:] |= walked[:-1]
        near[:-1] |= walked[1:]
        near[:, 1:] |= near[:, :-1].copy()
        near[:, :-1] |= near[:, 1:].copy()
        silent = np.asarray(points.reason).ravel() == _NO_RETURN
        ox = np.asarray(points.origin_x, float).ravel()[silent]
        oy = np.asarray(points.origin_y, float).ravel()[silent]
        mapped = np.isfinite(ox + oy)
        ix, iy = g.cell_of(ox[mapped], oy[mapped])
        ix, iy = ix - c0, iy - r0
        if ((ix < 0) | (ix >= c1 - c0) | (iy < 0) | (iy >= r1 - r0)).any():
            near[...] = True          # an emitter off the box: its first cell is anywhere
        else:
            near[iy, ix] = True
        self._kept[j:j + 1] = [(r0, r1, c0, c1, passes, near)]
        self._kept_bytes += passes.nbytes + near.nbytes

    def _box(self, points: Points) -> tuple[int, int, int, int]:
        """Rows and columns (start, stop) holding every cell the batch's silent beams can
        reach: their emitters ± the max range, and two cells more; the whole grid when an
        emitter is off it (a beam's first cell is where it enters)."""
        g = self._grid
        ny, nx = g.shape
        silent = np.asarray(points.reason) == _NO_RETURN
        ox, oy = (np.asarray(v, float)[silent] for v in (points.origin_x, points.origin_y))
        ok = np.isfinite(ox + oy)
        reach = float(points.max_range_m)
        ix, iy = g.cell_of(ox[ok], oy[ok])
        if not ok.any() or not math.isfinite(reach) or not (
                (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)).all():
            return 0, ny, 0, nx
        res = g.resolution_m

        def span(v, origin, n):
            lo = math.floor((float(v.min()) - reach - origin) / res) - 2
            hi = math.floor((float(v.max()) + reach - origin) / res) + 3
            return min(max(lo, 0), n), min(max(hi, 0), n)

        return (*span(oy[ok], g.origin_xy_m[1], ny), *span(ox[ok], g.origin_xy_m[0], nx))


def slice_steps(points: Points, rows: slice) -> Points:
    """The readings of some steps (rows) of a sweep's Points."""
    changes = {f.name: getattr(points, f.name)[rows] for f in dataclasses.fields(points)
               if isinstance(getattr(points, f.name), np.ndarray)}
    return dataclasses.replace(points, **changes)
