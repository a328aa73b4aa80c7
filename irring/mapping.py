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
rays at once: every ray is walked column by column along its major axis (one or two cells
per column), all columns of all rays laid out in flat arrays. No Python loop runs per ray or
per cell. An insert touches only the box of cells its beams can reach.

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
# Clipped segments shorter than this visit just the cell they start in.
_SHORT_CELLS = 4 * _TOUCH_CELLS
# A valid beam's cells more than this many σ (plus the free margin) in front of its end point
# get l_free exactly: Φ(8) = 1 − 6e-16 and exp(−8²/2) = 1.3e-14.
_NEAR_SIGMAS = 8.0


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


@dataclass
class _Walk:
    """A batch of segments walked column by column along each one's major axis.

    Kept ray r (``rays[r]`` indexes the input) has ``count[r]`` columns, numbered
    ``first[r]`` … ``first[r] + count[r] − 1`` in the flat per-column arrays. In each column
    the segment visits the cell it enters in (slot A, minor index ``a``) and, if it crosses a
    minor-axis border inside the column, the cell after it (slot B, index ``z``; ``two``).
    Cells it stays in for less than ``_TOUCH_CELLS`` (corner touches) are not visits: ``a``
    and ``z`` are taken that far inside the column, and a first or last column the clipped
    segment barely enters has ``flat_a`` = ``dummy`` and no slot B.
    ``flat`` = ix·stride_x + iy·stride_y + offset, as float holding exact integers.
    """

    rays: np.ndarray
    count: np.ndarray
    first: np.ndarray
    a: np.ndarray          # per column: minor-axis index of slot A (float)
    z: np.ndarray          # per column: minor-axis index of slot B (= a when there is none)
    two: np.ndarray        # per column: slot B is a visit
    flat_a: np.ndarray
    flat_b: np.ndarray     # meaningful where ``two``
    short: np.ndarray      # per ray: shorter than a few touch lengths, one cell
    t0: np.ndarray         # per ray: clipped part of the segment, as fractions of it
    t1: np.ndarray
    t_col0: np.ndarray     # per ray: t where the line enters column 0 (may be < t0)
    t_col: np.ndarray      # per ray: t per column (1/|major extent|; 0 for short rays)
    q0: np.ndarray         # per ray: minor coordinate (cells) at t = 0 …
    dq: np.ndarray         # … and its change over the whole segment


def _walk(gx0, gy0, gx1, gy1, nx: int, ny: int, stride_x: float, stride_y: float,
          offset: float, dummy: float) -> _Walk:
    """The column walk behind :func:`traverse` and the mapper; coordinates in cell units
    relative to the grid's corner, grid [0, nx) × [0, ny).

    Each segment is walked along its major axis (|Δ| largest), so a column holds one or two
    of its cells (|slope| ≤ 1). All columns of all segments are laid out flat with their
    ray's parameters repeated, so the work is a fixed number of array operations; a column's
    minor coordinate is affine in its flat number, so nothing is accumulated along a ray.
    """
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
            t0 = np.where(~parallel & (p < 0), np.maximum(t0, r), t0)
            t1 = np.where(~parallel & (p > 0), np.minimum(t1, r), t1)
    length = np.hypot(dx, dy)
    # a segment that only touches the grid's border has no visits; a zero-length one inside has one
    keep &= (t0 <= t1) & (((t1 - t0) * length >= _TOUCH_CELLS) | (length < _TOUCH_CELLS))
    rays = np.flatnonzero(keep)
    if len(rays) < len(keep):
        gx0, gy0, dx, dy, t0, t1, length = (a[rays] for a in (gx0, gy0, dx, dy, t0, t1, length))

    xmaj = np.abs(dx) >= np.abs(dy)
    p0 = np.where(xmaj, gx0, gy0)
    q0 = np.where(xmaj, gy0, gx0)
    dp = np.where(xmaj, dx, dy)
    dq = np.where(xmaj, dy, dx)
    last_col = np.where(xmaj, nx - 1, ny - 1)
    cs = np.clip(np.floor(p0 + t0 * dp), 0, last_col)
    ce = np.clip(np.floor(p0 + t1 * dp), 0, last_col)
    short = (t1 - t0) * length < _SHORT_CELLS
    back = dp < 0
    count = np.where(short, 1, np.abs(ce - cs) + 1).astype(np.intp)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_col = np.where(short, 0.0, 1.0 / np.abs(dp))
        # the touch length along the minor axis, signed with the direction of travel
        tol_q = np.where(short | (length == 0), 0.0, _TOUCH_CELLS * dq / length)
    # the line enters column 0 at the border p = cs (forwards) or cs + 1 (backwards)
    t_col0 = np.where(short, 0.0, (cs + back - p0) * np.where(back, -t_col, t_col))
    qk = t_col * dq              # minor coordinate change per column
    step_p = np.where(back, -1.0, 1.0) * np.where(xmaj, stride_x, stride_y)
    stride_q = np.where(xmaj, stride_y, stride_x)

    first = np.cumsum(count) - count
    total = int(first[-1] + count[-1]) if len(count) else 0
    # column j of the flat layout enters at minor coordinate q_base + j·qk, its cell's
    # major-axis part of flat is p_base + j·step_p
    per_col = np.repeat(np.stack([q0 + t_col0 * dq - first * qk, qk, tol_q, stride_q,
                                  cs * np.where(xmaj, stride_x, stride_y) + offset
                                  - first * step_p, step_p]), count, axis=1)
    j = _arange(total + 1)
    q_in = per_col[0] + j[:-1] * per_col[1]
    q_out = per_col[0] + j[1:] * per_col[1]
    # the first and last columns start / end where the clipped segment does
    last = first + count - 1
    q_in[first] = q0 + t0 * dq
    q_out[last] = q0 + t1 * dq
    q_out[first[short]] = q_in[first[short]]      # a very short segment: its start cell only
    # slot A is where the segment is a touch length into the column, B a touch length before
    # its end; |slope| ≤ 1 puts them in the same or neighbouring rows
    a = np.floor(q_in + per_col[2])
    z = np.floor(np.subtract(q_out, per_col[2], out=q_out), out=q_out)
    flat_a = a * per_col[3]
    flat_a += per_col[4]
    flat_a += j[:-1] * per_col[5]
    two = z != a
    flat_b = (z - a) * per_col[3]
    flat_b += flat_a
    # first / last columns the clipped segment barely enters (it starts or ends on their border)
    with np.errstate(invalid="ignore"):
        first_len = (np.minimum(t_col0 + t_col, t1) - t0) * length
        last_len = (t1 - np.maximum(t_col0 + (count - 1) * t_col, t0)) * length
    touch = np.concatenate([first[(first_len < _TOUCH_CELLS) & ~short],
                            last[(last_len < _TOUCH_CELLS) & ~short]])
    flat_a[touch] = dummy
    two[touch] = False
    return _Walk(rays=rays, count=count, first=first, a=a, z=z, two=two, flat_a=flat_a,
                 flat_b=flat_b, short=short, t0=t0, t1=t1, t_col0=t_col0, t_col=t_col,
                 q0=q0, dq=dq)


_ARANGE = np.arange(0.0)


def _arange(n: int) -> np.ndarray:
    """0.0, 1.0, … n − 1 as a view of one cached array (grown as needed, read-only)."""
    global _ARANGE
    if len(_ARANGE) < n:
        _ARANGE = np.arange(float(max(n, 2 * len(_ARANGE), 1 << 16)))
        _ARANGE.flags.writeable = False
    return _ARANGE[:n]


def _slot_t(w: _Walk, cols: np.ndarray, ray: np.ndarray):
    """(t where slot A is entered, t of the A→B crossing or the column's exit, t of the
    column's exit) for columns ``cols`` of ``w`` and their rays (indices into w.rays)."""
    k = cols - w.first[ray]
    t_col0, t_col = w.t_col0[ray], w.t_col[ray]
    t_in = np.maximum(t_col0 + k * t_col, w.t0[ray])
    t_out = np.minimum(t_col0 + (k + 1.0) * t_col, w.t1[ray])
    short = w.short[ray]
    if np.any(short):
        t_in = np.where(short, w.t0[ray], t_in)
        t_out = np.where(short, w.t1[ray], t_out)
    a, z = w.a[cols], w.z[cols]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_cross = np.clip((np.maximum(a, z) - w.q0[ray]) / w.dq[ray], t_in, t_out)
    return t_in, np.where(w.two[cols], t_cross, t_out), t_out


def traverse(x0, y0, x1, y1, origin_xy_m, shape, resolution_m) -> Visits:
    """Every grid cell each segment (x0, y0) → (x1, y1) (metres) crosses, exactly.

    Vectorised Amanatides–Woo: segments are clipped to the grid (Liang–Barsky), then walked
    column by column along their major axis, all at once (see :func:`_walk`). Conventions
    for the hard cases: a segment running exactly along a cell border belongs to the cells
    above / right of it (``floor``); a segment through a cell corner does not visit the two
    cells it only touches (nor any cell it stays in for less than 1e-9 cells); a zero-length
    segment visits the one cell holding it; parts outside the grid are dropped.
    """
    ny, nx = int(shape[0]), int(shape[1])
    res = float(resolution_m)
    g = [(np.asarray(v, dtype=float).ravel() - origin_xy_m[i % 2]) / res
         for i, v in enumerate((x0, y0, x1, y1))]
    # batches of ~2^16 columns keep the flat column numbers (and rounding in them) small
    with np.errstate(invalid="ignore"):
        cols = np.minimum(np.maximum(np.abs(g[2] - g[0]), np.abs(g[3] - g[1])), nx + ny) + 2
    ends = np.cumsum(np.where(np.isfinite(cols), cols, 0))
    cuts = np.searchsorted(ends, np.arange(1, int(ends[-1] // _BATCH_COLUMNS) + 1)
                           * _BATCH_COLUMNS) if len(ends) else []
    parts = [_traverse(*[v[lo:hi] for v in g], nx, ny) for lo, hi in
             zip([0, *cuts], [*cuts, len(cols)]) if hi > lo] or [_traverse(*g, nx, ny)]
    starts = np.cumsum([0] + [hi - lo for lo, hi in zip([0, *cuts], [*cuts, len(cols)])
                              if hi > lo])
    return Visits(*(np.concatenate([getattr(v, f) + (s if f == "ray" else 0)
                                    for v, s in zip(parts, starts)])
                    for f in ("ray", "ix", "iy", "t_enter", "t_exit")))


_BATCH_COLUMNS = 1 << 16


def _traverse(gx0, gy0, gx1, gy1, nx: int, ny: int) -> Visits:
    """:func:`traverse` for one batch, in cell units."""
    # flat indices on the grid padded by one cell, so a rounding step off the edge is caught
    width = nx + 2
    w = _walk(gx0, gy0, gx1, gy1, nx, ny, 1.0, float(width), float(width + 1), -1.0)
    ray = np.repeat(np.arange(len(w.rays)), w.count)
    t_in, t_mid, t_out = _slot_t(w, np.arange(len(w.a)), ray)
    keep = np.stack([w.flat_a >= 0, w.two], axis=1).ravel()
    flat = np.stack([w.flat_a, w.flat_b], axis=1).ravel()[keep].astype(np.int64)
    ix = flat % width - 1
    iy = flat // width - 1
    inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
    pick = np.flatnonzero(keep)[inside]
    return Visits(ray=w.rays[np.repeat(ray, 2)[pick]], ix=ix[inside], iy=iy[inside],
                  t_enter=np.stack([t_in, t_mid], axis=1).ravel()[pick],
                  t_exit=np.stack([t_mid, t_out], axis=1).ravel()[pick])


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

    def _box_delta(self, points: Points) -> tuple[np.ndarray, int, int] | None:
        """The log-odds change of ``points`` on the box of cells their beams can touch:
        (change (h, w), ix, iy of the box's first cell), or None when no beam is mapped.

        Work and memory scale with the beams, not the grid: one column walk over all beams,
        one ``bincount`` over the box. A valid beam's cells well in front of its end point
        (where Φ and the Gaussian are 1 and 0 to 1e-14) get ``l_free`` as a constant; only
        the cells within ``_NEAR_SIGMAS``·σ + margin of the end point are weighed exactly.
        """
        p = self.params
        res = self.resolution_m
        ox = np.asarray(points.origin_x, float).ravel()
        oy = np.asarray(points.origin_y, float).ravel()
        heading = np.asarray(points.heading, float).ravel()
        reason = np.asarray(points.reason).ravel()
        ex = np.asarray(points.x, float).ravel()
        ey = np.asarray(points.y, float).ravel()
        finite_o = np.isfinite(ox) & np.isfinite(oy)
        valid = np.asarray(points.valid, bool).ravel() & np.isfinite(ex) & np.isfinite(ey) & finite_o
        iv = np.flatnonzero(valid)
        nr = np.flatnonzero(~valid & (reason == Reason.NO_RETURN) & finite_o & np.isfinite(heading))
        if len(iv) + len(nr) == 0:
            return None

        # valid beams: emitter → end point, continued tail_sigmas·σ into the surface
        sigma = np.asarray(points.sigma_m, float).ravel()[iv]
        sigma = np.maximum(np.where(np.isfinite(sigma), sigma, p.default_sigma_m), p.min_sigma_m)
        vx, vy = ex[iv] - ox[iv], ey[iv] - oy[iv]
        d = np.hypot(vx, vy)
        hv = heading[iv]
        pos = d > 0
        ux = np.where(pos, vx / np.where(pos, d, 1.0), np.cos(hv))
        uy = np.where(pos, vy / np.where(pos, d, 1.0), np.sin(hv))
        ux = np.where(np.isfinite(ux), ux, 0.0)
        uy = np.where(np.isfinite(uy), uy, 0.0)
        length = d + p.tail_sigmas * sigma
        # no-return beams: emitter → max range along the heading
        rmax = float(points.max_range_m)
        x0 = np.concatenate([ox[iv], ox[nr]])
        y0 = np.concatenate([oy[iv], oy[nr]])
        x1 = np.concatenate([x0[:len(iv)] + ux * length, ox[nr] + rmax * np.cos(heading[nr])])
        y1 = np.concatenate([y0[:len(iv)] + uy * length, oy[nr] + rmax * np.sin(heading[nr])])
        gx0 = (x0 - self.origin_xy_m[0]) / res
        gy0 = (y0 - self.origin_xy_m[1]) / res
        gx1 = (x1 - self.origin_xy_m[0]) / res
        gy1 = (y1 - self.origin_xy_m[1]) / res

        # the beams' bounding box on the grid, padded by one cell for rounding at its edges
        ny, nx = self.shape
        bx0, bx1 = (int(min(max(v, 0.0), nx - 1.0)) for v in
                    (np.floor(min(gx0.min(), gx1.min())), np.floor(max(gx0.max(), gx1.max()))))
        by0, by1 = (int(min(max(v, 0.0), ny - 1.0)) for v in
                    (np.floor(min(gy0.min(), gy1.min())), np.floor(max(gy0.max(), gy1.max()))))
        bw, bh = bx1 - bx0 + 3, by1 - by0 + 3
        size = bw * bh
        w = _walk(gx0, gy0, gx1, gy1, nx, ny, 1.0, float(bw), float(bw * (1 - by0) + 1 - bx0),
                  float(size))   # dropped slots go to one spare bin past the box

        # every visit first gets its beam's constant (l_free or l_no_return) …
        kv = int(np.searchsorted(w.rays, len(iv)))     # kept valid beams come first
        cv = int(w.first[kv]) if kv < len(w.rays) else len(w.a)
        flat = np.concatenate([w.flat_a, np.compress(w.two, w.flat_b)]).astype(np.intp)
        if p.l_no_return == p.l_free:
            acc = np.bincount(flat, minlength=size + 1) * p.l_free
        else:
            wts = np.full(len(flat), p.l_no_return)
            wts[:cv] = p.l_free
            wts[len(w.a):len(w.a) + int(np.count_nonzero(w.two[:cv]))] = p.l_free
            acc = np.bincount(flat, wts, minlength=size + 1)

        # … then the columns near each valid end point get the exact model minus l_free
        if kv:
            rv = w.rays[:kv]
            dk, sk, lk = d[rv], sigma[rv], length[rv]
            count = w.count[:kv]
            with np.errstate(divide="ignore", invalid="ignore"):
                t_far = (dk - p.free_margin_cells * res - _NEAR_SIGMAS * sk) / lk
                n_far = np.floor((t_far - w.t_col0[:kv]) / w.t_col[:kv]) - 1.0
            n_far = np.where(np.isfinite(n_far), np.clip(n_far, 0, count), 0).astype(np.intp)
            n_near = count - n_far
            ends = np.cumsum(n_near)
            ray = np.repeat(np.arange(kv), n_near)
            cols = np.arange(int(ends[-1])) + np.repeat(w.first[:kv] + n_far - ends + n_near, n_near)
            t_in, t_mid, t_out = _slot_t(w, cols, ray)
            scale = (lk / sk)[ray]          # z = (s − d)/σ = t·L/σ − d/σ
            shift = (dk / sk)[ray]
            mu = (p.free_margin_cells * res / sk)[ray]
            z_in, z_mid, z_out = (t * scale - shift for t in (t_in, t_mid, t_out))
            fa = w.flat_a[cols]
            ka, kb = fa != size, w.two[cols]
            extra = np.concatenate([self._weight(z_in, z_mid, mu)[ka],
                                    self._weight(z_mid, z_out, mu)[kb]]) - p.l_free
            where = np.concatenate([fa[ka], w.flat_b[cols][kb]]).astype(np.intp)
            acc += np.bincount(where, extra, minlength=size + 1)
        return acc[:size].reshape(bh, bw), bx0 - 1, by0 - 1

    def _weight(self, z_a: np.ndarray, z_b: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """Log-odds for a cell a valid beam crosses from z_a to z_b, in σ from its end point
        (the module doc's formula); ``mu`` = the free margin in σ."""
        p = self.params
        gap = np.maximum(np.maximum(z_a, -z_b), 0.0)
        # free evidence only where the whole cell lies in front of the end point
        y = -(z_b + mu)
        beyond = np.where(y > 0, 0.5 * (1.0 + _erf(y * (1.0 / math.sqrt(2.0)))), 0.0)
        return p.l_free * beyond + p.l_occ * np.exp(-0.5 * gap * gap)

    def delta(self, points: Points) -> np.ndarray:
        """The log-odds change (ny, nx) the readings in ``points`` would add (before clamping)."""
        out = np.zeros(self.shape)
        box = self._box_delta(points)
        if box is not None:
            change, ix, iy = box
            out[iy + 1:iy + change.shape[0] - 1, ix + 1:ix + change.shape[1] - 1] = change[1:-1, 1:-1]
        return out

    def apply(self, delta: np.ndarray) -> None:
        """Add a log-odds change (ny, nx) and clamp."""
        np.clip(self.log_odds + delta, self.params.l_min, self.params.l_max, out=self.log_odds)

    def insert(self, points: Points) -> None:
        """Add one batch of readings (typically a sweep) to the map; only the cells its beams
        can reach are touched."""
        box = self._box_delta(points)
        if box is None:
            return
        change, ix, iy = box
        h, w = change.shape
        view = self.log_odds[iy + 1:iy + h - 1, ix + 1:ix + w - 1]
        view += change[1:-1, 1:-1]
        np.clip(view, self.params.l_min, self.params.l_max, out=view)

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
