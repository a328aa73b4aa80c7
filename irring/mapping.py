"""Log-odds occupancy grid built from estimated end points (paper §IV, after Elfes 1989).

The paper's map: 10 mm × 10 mm cells; the cells a ray passes are made free, and "in order
to consider the uncertainty of the sensor information, the Gaussian distribution is used"
around the end point. Here every reading adds log-odds to the cells its beam crosses:

* a **valid** reading at distance d with 1-σ range uncertainty σ (``Points.sigma_m``,
  floored at ``min_sigma_m``) adds, to a cell the beam crosses over [s_a, s_b] metres from
  the emitter,

      l_free · Φ((d − m − s_b)/σ) [only if s_b < d − m]  +  l_occ · exp(−gap² / 2σ²)

  where gap is the distance from d to the cell's interval (0 for the cell holding the end
  point) and m = ``free_margin_cells`` cells. Cells well in front get l_free, the end cell
  gets l_occ, cells just behind the end point (inside the surface) a Gaussian tail of l_occ;
  the beam is followed to d + ``tail_sigmas``·σ. The margin m keeps beams from clearing the
  cells just in front of their own end point: a curved or slanted surface (a table leg) only
  partly fills its cells, and beams ending in one cell cross the free corner of the next;
* a **no-return** reading (``Reason.NO_RETURN``) frees every cell up to the max range along
  its heading (weight ``l_no_return``) and marks nothing;
* every other invalid reading (out of range, fold-over, saturated, …) changes nothing.

The updates of one :meth:`OccupancyGrid.insert` are summed, added, then clamped to
[``l_min``, ``l_max``] so no cell becomes too certain to change. A cell is *occupied* above
probability 0.65, *free* below 0.196 and *unknown* in between — the thresholds ROS
map_server uses, so the PGM export and the grid agree.

Ray traversal (:func:`traverse`) is Amanatides & Woo's exact voxel walk, vectorised over all
rays at once: each ray's x- and y-border crossings are generated as flat arrays, sorted per
ray, and the cell after each crossing follows from a cumulative count. No Python loop runs
per ray or per cell.

Frames: the grid's origin is the world (x, y) of the *corner* of cell (0, 0); row ``iy``
grows with y, column ``ix`` with x; ``log_odds[iy, ix]``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .data import Points, Reason

FREE = 0
OCCUPIED = 1
UNKNOWN = -1

# map_server's trinary thresholds (probability of occupancy); the grid classifies the same way.
OCCUPIED_THRESH = 0.65
FREE_THRESH = 0.196
# Byte values map_saver writes (free 254, occupied 0, unknown 205).
PGM_FREE, PGM_OCCUPIED, PGM_UNKNOWN = 254, 0, 205

# Crossings closer than this (in cells) are the same point: a ray through a cell corner
# does not visit the two side cells it only touches.
_TOUCH_CELLS = 1e-9


@dataclass(frozen=True)
class MapperParams:
    """The inverse sensor model's knobs (log-odds units; lengths in metres).

    Chosen so that one end-point hit makes a cell occupied (l_occ > logit 0.65 = 0.62) and
    two clear passes make it free (2·l_free < logit 0.196 = −1.41); tuned on the bundled
    scenarios (the numbers are in the issue-5 report and `irring run`'s README section).
    """

    l_occ: float = 0.85           # added to the cell holding a valid end point
    l_free: float = -0.75         # added to a cell a valid beam clearly passed through
    l_no_return: float = -0.75    # added along a no-return beam, up to the max range
    l_min: float = -4.0           # clamp: the most certain "free"
    l_max: float = 4.0            # clamp: the most certain "occupied"
    tail_sigmas: float = 2.0      # the beam is followed to d + tail_sigmas·σ
    min_sigma_m: float = 0.005    # floor on a reading's σ: half a 10 mm cell (finer is not resolved)
    default_sigma_m: float = 0.01  # used where a valid reading's sigma_m is NaN
    free_margin_cells: float = 1.0  # no free evidence within this many cells before the end point

    def __post_init__(self) -> None:
        if not (self.l_occ > 0 and self.l_free < 0 and self.l_no_return <= 0):
            raise ValueError("need l_occ > 0, l_free < 0 and l_no_return ≤ 0 (log-odds)")
        if not self.l_min < 0 < self.l_max:
            raise ValueError(f"need l_min < 0 < l_max, got {self.l_min}, {self.l_max}")
        if self.tail_sigmas < 0 or self.min_sigma_m <= 0 or self.default_sigma_m <= 0:
            raise ValueError("tail_sigmas must be ≥ 0 and the σ floors > 0")


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

    Vectorised Amanatides–Woo: segments are clipped to the grid (Liang–Barsky), then each
    segment's border crossings are listed, sorted and counted. Conventions for the hard
    cases: a segment running exactly along a cell border belongs to the cells above / right
    of it (``floor``); a segment through a cell corner does not visit the two cells it only
    touches; a zero-length segment visits the one cell holding it; parts outside the grid
    are dropped.
    """
    ny, nx = int(shape[0]), int(shape[1])
    res = float(resolution_m)
    gx0 = (np.asarray(x0, dtype=float).ravel() - origin_xy_m[0]) / res
    gy0 = (np.asarray(y0, dtype=float).ravel() - origin_xy_m[1]) / res
    gx1 = (np.asarray(x1, dtype=float).ravel() - origin_xy_m[0]) / res
    gy1 = (np.asarray(y1, dtype=float).ravel() - origin_xy_m[1]) / res
    dx, dy = gx1 - gx0, gy1 - gy0

    # Liang–Barsky clip to [0, nx] × [0, ny] in cell units, keeping the segment's own t.
    t0 = np.zeros_like(gx0)
    t1 = np.ones_like(gx0)
    keep = np.isfinite(gx0) & np.isfinite(gy0) & np.isfinite(gx1) & np.isfinite(gy1)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # cells are half-open [i, i+1): a segment along the top/right border lies outside
        for p, q, upper in ((-dx, gx0, False), (dx, nx - gx0, True), (-dy, gy0, False),
                            (dy, ny - gy0, True)):
            parallel = p == 0
            keep &= ~(parallel & ((q <= 0) if upper else (q < 0)))
            r = q / p
            enter = ~parallel & (p < 0)
            leave = ~parallel & (p > 0)
            t0 = np.where(enter, np.maximum(t0, r), t0)
            t1 = np.where(leave, np.minimum(t1, r), t1)
    length_all = np.hypot(dx, dy)
    # a segment that only touches the grid's border has no visits; a zero-length one inside has one
    keep &= (t0 <= t1) & (((t1 - t0) * length_all >= _TOUCH_CELLS) | (length_all < _TOUCH_CELLS))
    rays = np.flatnonzero(keep)
    gx0, gy0, dx, dy, t0, t1 = (a[rays] for a in (gx0, gy0, dx, dy, t0, t1))

    ixs = np.clip(np.floor(gx0 + t0 * dx), 0, nx - 1).astype(np.int64)
    iys = np.clip(np.floor(gy0 + t0 * dy), 0, ny - 1).astype(np.int64)
    ixe = np.clip(np.floor(gx0 + t1 * dx), 0, nx - 1).astype(np.int64)
    iye = np.clip(np.floor(gy0 + t1 * dy), 0, ny - 1).astype(np.int64)
    sx = np.where(ixe >= ixs, 1, -1)
    sy = np.where(iye >= iys, 1, -1)
    ncx = np.abs(ixe - ixs)
    ncy = np.abs(iye - iys)

    def crossings(start, step, count, g0, d):
        """Ray id, t and axis flag of every border crossing along one axis."""
        rid = np.repeat(np.arange(len(count)), count)
        first = np.cumsum(count) - count
        j = np.arange(int(count.sum())) - np.repeat(first, count)
        border = start[rid] + np.where(step[rid] > 0, j + 1, -j)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (border - g0[rid]) / d[rid]
        return rid, t

    rx, tx = crossings(ixs, sx, ncx, gx0, dx)
    ry, ty = crossings(iys, sy, ncy, gy0, dy)
    tx = np.clip(tx, t0[rx], t1[rx])
    ty = np.clip(ty, t0[ry], t1[ry])
    # Merge each ray's x- and y-crossings: keys 2·ray + t are already sorted within each
    # list, so a stable sort of the two runs is one linear merge (timsort); on a tie — a cell
    # corner — the x-crossing goes first.
    keys = np.concatenate([2.0 * rx + tx, 2.0 * ry + ty])
    rank = np.empty(len(keys), np.int64)
    rank[np.argsort(keys, kind="stable")] = np.arange(len(keys))
    mx, my = rank[:len(rx)], rank[len(rx):]

    # Lay out each ray's visits: its start cell, then one cell after each crossing; the
    # merged crossing m of ray r lands in slot m + r + 1.
    n = len(rays)
    ncross = ncx + ncy
    first = np.cumsum(ncross + 1) - (ncross + 1)
    total = int((ncross + 1).sum())
    ray = np.repeat(np.arange(n), ncross + 1)
    slot_x = mx + rx + 1
    slot_y = my + ry + 1
    stepx = np.zeros(total, np.int64)
    stepy = np.zeros(total, np.int64)
    stepx[slot_x] = 1
    stepy[slot_y] = 1
    cx = np.cumsum(stepx)
    cy = np.cumsum(stepy)
    # cumulative counts restart at each ray's start slot
    cx -= np.repeat(cx[first], ncross + 1)
    cy -= np.repeat(cy[first], ncross + 1)
    ix = ixs[ray] + sx[ray] * cx
    iy = iys[ray] + sy[ray] * cy
    t_enter = np.empty(total)
    t_enter[first] = t0
    t_enter[slot_x] = tx
    t_enter[slot_y] = ty
    t_exit = np.empty(total)
    t_exit[:-1] = t_enter[1:]
    last = first + ncross
    t_exit[last] = t1

    # Drop corner touches and zero-length entries, but keep one cell for a zero-length ray.
    length_cells = np.hypot(dx, dy)[ray]
    touching = (t_exit - t_enter) * length_cells < _TOUCH_CELLS
    only = np.repeat(ncross == 0, ncross + 1)
    keep_visit = ~touching | only
    if np.any(touching & ~only):
        # a ray whose every visit is a touch (it lies in one cell border corner) keeps its first
        kept_per_ray = np.bincount(ray[keep_visit], minlength=n)
        keep_visit[first[kept_per_ray == 0]] = True
    ix = np.clip(ix[keep_visit], 0, nx - 1)
    iy = np.clip(iy[keep_visit], 0, ny - 1)
    return Visits(ray=rays[ray[keep_visit]], ix=ix, iy=iy, t_enter=t_enter[keep_visit],
                  t_exit=t_exit[keep_visit])


# --------------------------------------------------------------------------- the grid


def _erf(x: np.ndarray) -> np.ndarray:
    """erf to 1.5e-7 (Abramowitz & Stegun 7.1.26); numpy has no erf and scipy is not a dependency."""
    sign = np.sign(x)
    a = np.abs(x)
    t = 1.0 / (1.0 + 0.3275911 * a)
    poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027
                                                                          + t * 1.061405429))))
    return sign * (1.0 - poly * np.exp(-a * a))


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
        self.origin_xy_m = np.asarray(origin_xy_m, dtype=float).reshape(2).copy()
        self.resolution_m = float(resolution_m)
        self.params = params or MapperParams()
        self.log_odds = np.zeros((ny, nx))

    # ---- construction

    @classmethod
    def for_scenario(cls, scenario, params: MapperParams | None = None) -> OccupancyGrid:
        """A grid covering the room outline plus ``scenario.map.margin_m`` on every side.

        The origin is shifted by half a cell so walls on round coordinates (multiples of
        the resolution) run through cell centres rather than along cell borders — a wall's
        surface then lies in one row of cells instead of on the fence between two.
        """
        res = scenario.map.resolution_m
        outline = np.asarray(scenario.room.outline_m, dtype=float)
        lo = outline.min(axis=0) - scenario.map.margin_m
        hi = outline.max(axis=0) + scenario.map.margin_m
        origin = np.floor(lo / res + 1e-9) * res - res / 2
        shape = np.ceil((hi - origin) / res - 1e-9).astype(int) + 1
        return cls(origin, (shape[1], shape[0]), res, params)

    def copy(self) -> OccupancyGrid:
        other = OccupancyGrid(self.origin_xy_m, self.shape, self.resolution_m, self.params)
        other.log_odds = self.log_odds.copy()
        return other

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

    def delta(self, points: Points) -> np.ndarray:
        """The log-odds change (ny, nx) the readings in ``points`` would add (before clamping)."""
        p = self.params
        ox = np.asarray(points.origin_x, float).ravel()
        oy = np.asarray(points.origin_y, float).ravel()
        heading = np.asarray(points.heading, float).ravel()
        reason = np.asarray(points.reason).ravel()
        ex = np.asarray(points.x, float).ravel()
        ey = np.asarray(points.y, float).ravel()
        valid = (np.asarray(points.valid, bool).ravel() & np.isfinite(ex) & np.isfinite(ey)
                 & np.isfinite(ox) & np.isfinite(oy))
        sigma = np.asarray(points.sigma_m, float).ravel()
        sigma = np.where(np.isfinite(sigma), sigma, p.default_sigma_m)
        sigma = np.maximum(sigma, p.min_sigma_m)

        # valid beams: emitter → end point, continued tail_sigmas·σ into the surface
        vx, vy = ex - ox, ey - oy
        d = np.hypot(vx, vy)
        ux = np.where(d > 0, vx / np.where(d > 0, d, 1.0), np.cos(heading))
        uy = np.where(d > 0, vy / np.where(d > 0, d, 1.0), np.sin(heading))
        ux = np.where(np.isfinite(ux), ux, 0.0)
        uy = np.where(np.isfinite(uy), uy, 0.0)
        length = d + p.tail_sigmas * sigma
        iv = np.flatnonzero(valid)

        # no-return beams: emitter → max range along the heading
        nr = np.flatnonzero(~valid & (reason == Reason.NO_RETURN) & np.isfinite(ox)
                            & np.isfinite(oy) & np.isfinite(heading))
        rmax = float(points.max_range_m)

        x0 = np.concatenate([ox[iv], ox[nr]])
        y0 = np.concatenate([oy[iv], oy[nr]])
        x1 = np.concatenate([ox[iv] + ux[iv] * length[iv], ox[nr] + rmax * np.cos(heading[nr])])
        y1 = np.concatenate([oy[iv] + uy[iv] * length[iv], oy[nr] + rmax * np.sin(heading[nr])])
        seg_len = np.concatenate([length[iv], np.full(len(nr), rmax)])
        v = traverse(x0, y0, x1, y1, self.origin_xy_m, self.shape, self.resolution_m)

        nv = len(iv)
        is_valid = v.ray < nv
        w = np.full(len(v.ray), p.l_no_return)
        if np.any(is_valid):
            r = v.ray[is_valid]
            s_a = v.t_enter[is_valid] * seg_len[r]
            s_b = v.t_exit[is_valid] * seg_len[r]
            dd = d[iv][r]
            sg = sigma[iv][r]
            gap = np.maximum.reduce([s_a - dd, dd - s_b, np.zeros_like(dd)])
            # free evidence only where the whole cell lies in front of the end point
            stop = dd - p.free_margin_cells * self.resolution_m
            beyond = np.where(s_b < stop,
                              0.5 * (1.0 + _erf((stop - s_b) / (sg * math.sqrt(2.0)))), 0.0)
            w[is_valid] = p.l_free * beyond + p.l_occ * np.exp(-0.5 * (gap / sg) ** 2)
        ny, nx = self.shape
        flat = v.iy * nx + v.ix
        return np.bincount(flat, weights=w, minlength=ny * nx).reshape(ny, nx)

    def apply(self, delta: np.ndarray) -> None:
        """Add a log-odds change and clamp."""
        np.clip(self.log_odds + delta, self.params.l_min, self.params.l_max, out=self.log_odds)

    def insert(self, points: Points) -> None:
        """Add one batch of readings (typically a sweep) to the map."""
        self.apply(self.delta(points))

    # ---- reading the map

    def probability(self) -> np.ndarray:
        """P(occupied) per cell, (ny, nx)."""
        return 1.0 / (1.0 + np.exp(-self.log_odds))

    def classify(self) -> np.ndarray:
        """int8 (ny, nx): OCCUPIED (1), FREE (0) or UNKNOWN (−1), with map_server's thresholds."""
        prob = self.probability()
        out = np.full(self.shape, UNKNOWN, np.int8)
        out[prob > OCCUPIED_THRESH] = OCCUPIED
        out[prob < FREE_THRESH] = FREE
        return out

    def occupied(self) -> np.ndarray:
        return self.classify() == OCCUPIED

    def free(self) -> np.ndarray:
        return self.classify() == FREE

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
        import yaml

        yaml_path = Path(yaml_path)
        meta = yaml.safe_load(yaml_path.read_text())
        missing = {"image", "resolution", "origin", "negate", "occupied_thresh",
                   "free_thresh"} - set(meta or {})
        if missing:
            raise ValueError(f"{yaml_path}: not a map_server YAML, missing {sorted(missing)}")
        img = read_pgm(yaml_path.parent / meta["image"])
        occ = float(meta["occupied_thresh"])
        free = float(meta["free_thresh"])
        p = img.astype(float) / 255.0 if int(meta["negate"]) else (255.0 - img) / 255.0
        grid = cls(meta["origin"][:2], img.shape, float(meta["resolution"]), params)
        lo = np.zeros(img.shape)
        lo[p > occ] = grid.params.l_max
        lo[p < free] = grid.params.l_min
        grid.log_odds = np.flipud(lo).copy()
        return grid


def read_pgm(path) -> np.ndarray:
    """A binary (P5) 8-bit PGM as a uint8 array (rows top to bottom); comments allowed."""
    data = Path(path).read_bytes()
    fields: list[bytes] = []
    pos = 0
    while len(fields) < 4:
        while pos < len(data) and data[pos:pos + 1].isspace():
            pos += 1
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
    width, height, maxval = (int(f) for f in fields[1:])
    if maxval != 255:
        raise ValueError(f"{path}: only 8-bit PGM (maxval 255) is supported, got {maxval}")
    pixels = data[pos + 1:pos + 1 + width * height]
    if len(pixels) != width * height:
        raise ValueError(f"{path}: truncated, {len(pixels)} of {width * height} pixels")
    return np.frombuffer(pixels, np.uint8).reshape(height, width).copy()


def slice_steps(points: Points, rows: slice) -> Points:
    """The readings of some steps (rows) of a sweep's Points."""
    changes = {f.name: getattr(points, f.name)[rows] for f in dataclasses.fields(points)
               if isinstance(getattr(points, f.name), np.ndarray)}
    return dataclasses.replace(points, **changes)
