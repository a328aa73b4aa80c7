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
probability 0.65 (log-odds > 0.62), *free* below 0.196 (log-odds < −1.41) and *unknown* in
between — the thresholds ROS map_server uses, so the PGM export and the grid agree.

The default numbers (:class:`MapperParams`) and what they do to a cell:

* ``l_free`` = −1.5: **one clean pass marks a cell free** (p = 0.18). A user reads a light
  cell as "a beam went through here"; a design whose beams rarely overlap (a radial ring)
  then shows its beams instead of nothing. Cells within a few σ of the end point get less
  (l_free·Φ) and may stay unknown: there the beam does not say much.
* ``l_occ`` = 2.5: one hit marks a cell occupied (p = 0.92) and **outweighs a passing beam**:
  hit + pass = 1.0 (occupied), hit + two passes = −0.5 (unknown, not free); two hits reach
  the clamp (4) and take four clean passes to turn free.
* ``l_no_return`` = −0.75: a beam that saw nothing counts **half a clean pass** (two make a
  cell free). A missing return is weaker evidence — a dark, shiny or grazing surface gives
  none either — and at full weight such beams cleared cells behind walls.
* ``tail_sigmas`` = 0.5 and ``free_margin_cells`` = 0.5: the occupied evidence reaches half a
  σ into the surface and beams clear cells up to half a cell before their own end point, so
  walls stay one or two cells thick at this l_occ (with a 2σ tail and a one-cell margin the
  stronger hits thickened them: occupied precision 0.94–0.97 → 0.85–0.89).

Measured on the bundled scenes (simulated, estimated and mapped as `irring run` does; mean
of seeds 0–2; T-room / cylinder / three cylinders), previous two-pass defaults (l_occ 0.85,
l_free −0.75, 2σ tail, one-cell margin) → these: occupied F1 0.968/0.981/0.974 →
0.971/0.969/0.972, free accuracy 1.00 → 1.00, coverage 0.898/0.846/0.894 → 0.909/0.859/0.906,
shadow behind the table leg 1.00 → 1.00. A radial ring (radial12: 12 fixed beams per pose)
goes from coverage 0.00 to 0.03 — its beams now show as free lines.

Ray traversal (:func:`traverse`) is Amanatides & Woo's exact voxel walk, vectorised over all
rays at once: every ray is walked column by column along its major axis (one or two cells
per column), all columns of all rays laid out in flat arrays. No Python loop runs per ray or
per cell.

An insert works on the box of cells its beams reach, never on the whole grid, and splits
each beam where its weight stops being constant: a no-return beam, and a valid beam up to
``_NEAR_SIGMAS`` (4.5) σ before its free margin, add one constant per cell, so they go in as
*row runs* (in each minor-axis row a beam visits a contiguous run of cells: +1 at the run's
start, −1 past its end, one ``bincount`` and an integer ``cumsum`` along the rows — work per
border crossing, not per cell); only the last few columns of a valid beam are walked cell by
cell and weighed with the formula above, in float32. Both follow :func:`traverse`'s rules
exactly (the same cells; tests compare them visit by visit); the weights differ from the
formula by < 1e-4 log-odds (the constant part is within 4e-5 of it, erfc is A&S 7.1.25).
One T-room sweep (852 readings, 10 mm cells) takes ~0.58 ms warm on the 2-core reference
machine (~0.7–0.85 ms inside ``irring bench speed``, whose other stages evict the caches; it
was ~3.0 ms with a sort-based traversal and per-visit weights over the whole grid). What is
left is mostly per-call numpy overhead — ~150 calls on arrays of a few hundred to a few
thousand entries (clip ~50 µs, runs ~140, near-end columns and weights ~170) — and a few
box-sized passes (bincount, cumsum, weights, clamp ~130 µs).

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
# get exactly l_free: the model there is l_free·Φ(4.5) + l_occ·exp(−4.5²/2), within 4e-5 of it.
_NEAR_SIGMAS = 4.5
# When their weights differ, no-return beams are counted in units of 2^20 beside valid ones.
_NR_BITS = 20
_NR_UNIT = float(1 << _NR_BITS)
# Beams reaching farther than this many cells from the grid's corner are not mapped (their
# numbers would swamp the cell arithmetic; 1e9 cells is 10 000 km at 10 mm).
_FAR_CELLS = 1e9
# (a plain int: comparing an array with the IntEnum member takes numpy's slow path)
_NO_RETURN = int(Reason.NO_RETURN)


@dataclass(frozen=True)
class MapperParams:
    """The inverse sensor model's knobs (log-odds units; lengths in metres). The module doc
    says what the defaults do to a cell: one clean pass marks it free, one end-point hit
    marks it occupied and outweighs a pass, a no-return beam counts half a clean pass.
    """

    l_occ: float = 2.5            # added to the cell holding a valid end point
    l_free: float = -1.5          # added to a cell a valid beam clearly passed through
    l_no_return: float = -0.75    # added along a no-return beam, up to the max range
    l_min: float = -4.0           # clamp: the most certain "free"
    l_max: float = 4.0            # clamp: the most certain "occupied"
    tail_sigmas: float = 0.5      # the beam is followed to d + tail_sigmas·σ
    min_sigma_m: float = 0.005    # floor on a reading's σ: half a 10 mm cell (finer is not resolved)
    default_sigma_m: float = 0.01  # used where a valid reading's sigma_m is NaN
    free_margin_cells: float = 0.5  # no free evidence within this many cells before the end point

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
class _Rays:
    """Segments clipped to the grid and split into their major (p) and minor (q) axis; cell
    units from the grid's corner. Every array has one entry per kept segment."""

    rays: np.ndarray | None  # indices of the kept input segments (ascending); None: all
    xmaj: np.ndarray     # the major axis is x (|Δx| ≥ |Δy|), so |slope| ≤ 1
    p0: np.ndarray       # start and extent along the major …
    dp: np.ndarray
    q0: np.ndarray       # … and the minor axis, q0 from q_ref: minor coordinates are kept
    dq: np.ndarray       # small, so a touch length (1e-9 cells × slope) stays representable
    q_ref: np.ndarray    # (floor of the start's minor coordinate) even for a beam along a border
    t0: np.ndarray       # the part inside the grid, as fractions of the segment
    t1: np.ndarray
    length: np.ndarray   # of the whole segment (cells)
    short: np.ndarray | None  # inside part shorter than _SHORT_CELLS (None: none is)
    cs: np.ndarray       # the first column walked (major-axis cell index) …
    count: np.ndarray    # … and how many
    t_col: np.ndarray    # t per column, 1/|dp|
    t_col0: np.ndarray   # t where the line enters column cs
    tol_p: np.ndarray    # a touch length along the major / minor axis, signed like dp / dq
    tol_q: np.ndarray    # (0 for short segments)
    last: np.ndarray     # the last column index of the grid along the major axis


_SWAP = [1, 0, 3, 2]


def _clip(e: np.ndarray, nx: int, ny: int, inside: bool = False) -> _Rays:
    """Segments e = (x0, y0, Δx, Δy) (4, n) in cells, clipped to [0, nx) × [0, ny)
    (Liang–Barsky, all four borders at once) and split into major and minor axis.
    ``inside``: the caller knows every end point lies in the grid (nothing to clip).

    The columns walked start and end a touch length inside the clipped part, so a first or
    last column the segment barely enters (it starts or ends on its border) is not walked.
    A segment shorter than a few touch lengths visits just the cell it starts in.
    """
    length = np.sqrt(e[2] * e[2] + e[3] * e[3])
    n = e.shape[1]
    rays = None
    if inside:
        t0 = np.zeros(n)
        t1 = np.ones(n)
    else:
        gx0, gy0, dx, dy = e
        p = np.stack([-dx, dx, -dy, dy])
        q = np.stack([gx0, nx - gx0, gy0, ny - gy0])
        r = q / p
        t0 = np.maximum(np.where(p < 0, r, -np.inf).max(axis=0), 0.0)
        t1 = np.minimum(np.where(p > 0, r, np.inf).min(axis=0), 1.0)
        # cells are half-open [i, i+1): a segment along the top/right border lies outside
        outside = (p == 0) & ((q < 0) | ((q == 0) & _UPPER_BORDER))
        keep = ~outside.any(axis=0) & np.isfinite(length) & np.isfinite(gx0) & np.isfinite(gy0)
        # a segment only touching the grid's border has no visits; a zero-length one inside has one
        keep &= (t0 <= t1) & (((t1 - t0) * length >= _TOUCH_CELLS) | (length < _TOUCH_CELLS))
        if not keep.all():
            rays = np.flatnonzero(keep)
            e, t0, t1, length = e[:, rays], t0[rays], t1[rays], length[rays]
    xmaj = np.abs(e[2]) >= np.abs(e[3])
    p0, q0, dp, dq = np.where(xmaj, e, e[_SWAP])
    q_ref = np.floor(q0)
    q0 -= q_ref                                       # exact: the fractional part
    last = np.where(xmaj, nx - 1, ny - 1)
    tol = _TOUCH_CELLS / length
    t_col = 1.0 / np.abs(dp)
    short = (t1 - t0) * length < _SHORT_CELLS
    if short.any():
        tol[short] = 0.0
    else:
        short = None
    tol_p = tol * dp
    cs = _clamp(np.floor(p0 + tol_p if inside else p0 + t0 * dp + tol_p), 0, last)
    ce = _clamp(np.floor(p0 + dp - tol_p if inside else p0 + t1 * dp - tol_p), 0, last)
    back = dp < 0
    # the line enters column cs at the border p = cs (forwards) or cs + 1 (backwards)
    t_col0 = (cs + back - p0) * np.where(back, -t_col, t_col)
    if short is not None:
        ce[short] = cs[short]
        t_col[short] = 0.0
        t_col0[short] = 0.0
    return _Rays(rays=rays, xmaj=xmaj, p0=p0, dp=dp, q0=q0, dq=dq, q_ref=q_ref, t0=t0, t1=t1,
                 length=length, short=short, cs=cs,
                 count=(np.abs(ce - cs) + 1).astype(np.intp), t_col=t_col, t_col0=t_col0,
                 tol_p=tol_p, tol_q=tol * dq, last=last)


_UPPER_BORDER = np.array([[False], [True], [False], [True]])  # rows of _clip's p and q


@dataclass
class _Cols:
    """Cells of some columns of some segments (see :func:`_columns`), one entry per column."""

    n: np.ndarray        # columns per selected segment (they come in segment order)
    two: np.ndarray      # the column has a slot B
    flat_a: np.ndarray   # float holding exact integers
    flat_b: np.ndarray   # meaningful where ``two``
    u_in: np.ndarray     # u (= t·scale − shift) where slot A is entered …
    u_mid: np.ndarray    # … where it is left (the A→B crossing, or the column's exit) …
    u_out: np.ndarray    # … and where the segment leaves the column


def _columns(rr: _Rays, sel, k_lo, stride_x: float, stride_y: float, offset: float,
             scale=1.0, shift=0.0) -> _Cols:
    """The cells of columns k_lo … count − 1 of segments ``sel`` (a slice or indices into
    ``rr``), walked along the major axis: in each column the segment is in slot A's cell
    and, if it crosses a minor-axis border there, in slot B's after it (|slope| ≤ 1: at most
    one). Cells it stays in for less than ``_TOUCH_CELLS`` (corner touches) are not visits:
    A and B are taken that far inside the column. flat = ix·stride_x + iy·stride_y + offset.
    Positions along a segment come as u = t·scale − shift (per segment; scale > 0).

    All columns of all segments are laid out flat with their segment's parameters repeated;
    a column's borders are affine in its number, so nothing accumulates along a ray.
    """
    xm, dq, q0, t_col, t_col0 = rr.xmaj[sel], rr.dq[sel], rr.q0[sel], rr.t_col[sel], rr.t_col0[sel]
    tol_q = rr.tol_q[sel]
    n = rr.count[sel] - k_lo
    first = np.cumsum(n)
    first -= n
    per = np.empty((14, len(n)))
    np.subtract(k_lo, first, out=per[0])
    uc = np.multiply(t_col, scale, out=per[3])
    np.subtract(t_col0 * scale, shift, out=per[1])     # u where column 0 is entered …
    np.add(per[1], uc, out=per[2])                     # … and left
    np.subtract(rr.t0[sel] * scale, shift, out=per[4])  # the clipped part, in u
    np.subtract(rr.t1[sel] * scale, shift, out=per[5])
    dq_u = np.divide(dq, scale, out=per[8])         # minor coordinate per u
    cross = scale / dq                                 # u of minor border b: b·cross + cross0
    cross[~np.isfinite(cross)] = 0.0                   # (a segment too flat to cross one)
    q_u0 = q0 + shift * dq_u                           # minor coordinate at u = 0
    np.add(q_u0, tol_q, out=per[6])                    # slot A: a touch length in, …
    np.subtract(q_u0, tol_q, out=per[7])               # … slot B: a touch length before the end
    stride_p = np.where(xm, stride_x, stride_y)
    per[9] = np.where(xm, stride_y, stride_x)
    np.add(rr.cs[sel] * stride_p + rr.q_ref[sel] * per[9], offset, out=per[10])
    np.copyto(per[11], np.where(rr.dp[sel] < 0, -stride_p, stride_p))
    per[12] = cross
    np.negative(q_u0 * cross, out=per[13])
    short = rr.short[sel] if rr.short is not None else None
    if short is not None and short.any():             # the start cell only, whole segment
        per[1][short] = -np.inf
        per[2][short] = np.inf
        per[6][short] = per[7][short] = (q0 + rr.t0[sel] * dq)[short]
        per[8][short] = 0.0
        per[12][short] = per[13][short] = 0.0
    per = np.repeat(per, n, axis=1)
    k = _arange(per.shape[1]) + per[0]
    u_in = np.maximum(per[1] + k * per[3], per[4])
    u_out = per[2] + k * per[3]
    np.minimum(u_out, per[5], out=u_out)
    a = np.floor(per[6] + u_in * per[8])
    z = np.floor(per[7] + u_out * per[8])
    two = z != a
    u_cross = np.maximum(a, z)                         # the border between A and B
    u_cross *= per[12]
    u_cross += per[13]
    u_mid = np.where(two, _clamp(u_cross, u_in, u_out), u_out)
    flat_a = a * per[9]
    flat_a += per[10]
    flat_a += k * per[11]
    flat_b = np.subtract(z, a, out=z)
    flat_b *= per[9]
    flat_b += flat_a
    return _Cols(n=n, two=two, flat_a=flat_a, flat_b=flat_b, u_in=u_in, u_mid=u_mid, u_out=u_out)


def _runs(rr: _Rays, t_end: np.ndarray, ok: np.ndarray, unit: np.ndarray,
          box: tuple[int, int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Segments from t0 to ``t_end`` (those with ``ok``, each at least ``_SHORT_CELLS``
    long) as row runs: (indices, weights) of a difference array whose cumulative sum along
    the major axis adds ``unit`` (per segment) to every cell the segment visits (same touch
    rule as :func:`_columns`). Excluded segments point at index 2·size (a spare bin).

    In every minor-axis row a segment (|slope| ≤ 1) visits one contiguous run of columns;
    runs begin and end where it crosses minor-axis borders, so the work is per crossing, not
    per cell. box = (ix0, iy0, width, height): the cells, padded by one on every side.
    Index layout: x-major segments in the box as rows y × columns x, y-major ones after it
    as rows x × columns y.
    """
    ix0, iy0, bw, bh = box
    size = bw * bh
    xm, p0, dp, q0, dq, t0, tol_p, tol_q = (rr.xmaj, rr.p0, rr.dp, rr.q0, rr.dq, rr.t0,
                                            rr.tol_p, rr.tol_q)
    fwd = dp >= 0
    back = ~fwd
    up = dq > 0
    # last column and first / last row, a touch length inside the piece
    ce = _clamp(np.floor(p0 + t_end * dp - tol_p), 0, rr.last)
    m_s = np.floor(q0 + t0 * dq + tol_q)                       # (from q_ref)
    m_e = np.floor(q0 + t_end * dq - tol_q)
    k = np.abs(m_e - m_s)                                       # minor-axis borders crossed
    # index = row·row_stride + column + base (row and column in grid cells)
    row_stride = np.where(xm, float(bw), float(bh))
    base = np.where(xm, (1.0 - iy0) * bw + (1.0 - ix0), size + (1.0 - ix0) * bh + (1.0 - iy0))
    base += rr.q_ref * row_stride
    row0 = m_s * row_stride
    row0 += base
    # a run's first cell gets +unit and the cell after its last −unit: moving forwards that
    # is the start and past the end, backwards the end and past the start
    starts = row0 + rr.cs + back
    ends = m_e * row_stride + base + ce + fwd
    w = np.where(fwd, unit, -unit)
    if not ok.all():
        starts[~ok] = ends[~ok] = 2 * size
        k[~ok] = 0
    k = k.astype(np.intp)
    # crossing i (of border m_s + up ± i) at p = p_cross + i·p_step: the run before it ends
    # at floor(p ∓ tol), the one after begins at floor(p ± tol)
    slope = dp / dq
    slope[~np.isfinite(slope)] = 0.0                  # (a segment too flat to cross a row)
    p_cross = p0 + (m_s + up - q0) * slope
    row_step = np.where(up, row_stride, -row_stride)
    per = np.empty((7, len(k)))
    first = np.cumsum(k)
    nk = int(first[-1]) if len(k) else 0
    np.subtract(k, first, out=per[0])
    np.add(p_cross - tol_p, fwd, out=per[1])
    np.add(p_cross + tol_p, back, out=per[2])
    np.copyto(per[3], np.where(up, slope, -slope))
    per[4] = row0
    per[5] = row_step
    per[6] = w
    per = np.repeat(per, k, axis=1)
    i = _arange(per.shape[1]) + per[0]
    ip = i * per[3]
    i *= per[5]
    i += per[4]                                        # the row before crossing i
    # written straight into the outputs: starts, ends, before, after
    m = len(k)
    entries = np.empty(2 * (m + nk))
    weights = np.empty(2 * (m + nk))
    entries[:m] = starts
    entries[m:2 * m] = ends
    weights[:m] = w
    np.negative(w, out=weights[m:2 * m])
    before = np.add(per[1], ip, out=entries[2 * m:2 * m + nk])
    np.floor(before, out=before)
    before += i
    after = np.add(per[2], ip, out=entries[2 * m + nk:])
    np.floor(after, out=after)
    after += i
    after += per[5]
    np.negative(per[6], out=weights[2 * m:2 * m + nk])
    weights[2 * m + nk:] = per[6]
    return entries, weights


_ARANGE = np.arange(0.0)
# np.clip's ufunc, without the Python wrapper around it (~2 µs a call)
_clamp = getattr(np, "_core", getattr(np, "core", None)).umath.clip


def _arange(n: int) -> np.ndarray:
    """0.0, 1.0, … n − 1 as a view of one cached array (grown as needed, read-only)."""
    global _ARANGE
    if len(_ARANGE) < n:
        _ARANGE = np.arange(float(max(n, 2 * len(_ARANGE), 1 << 16)))
        _ARANGE.flags.writeable = False
    return _ARANGE[:n]


def traverse(x0, y0, x1, y1, origin_xy_m, shape, resolution_m) -> Visits:
    """Every grid cell each segment (x0, y0) → (x1, y1) (metres) crosses, exactly.

    Vectorised Amanatides–Woo: segments are clipped to the grid (Liang–Barsky), then walked
    column by column along their major axis, all at once (see :func:`_columns`).
    Conventions for the hard cases: a segment running exactly along a cell border belongs
    to the cells above / right of it (``floor``); a segment through a cell corner does not
    visit the two cells it only touches (nor any cell it stays in for less than 1e-9 cells);
    a zero-length segment visits the one cell holding it; parts outside the grid are dropped.
    """
    with np.errstate(all="ignore"):   # non-finite and degenerate segments are handled explicitly
        return _traverse_batches(x0, y0, x1, y1, origin_xy_m, shape, resolution_m)


def _traverse_batches(x0, y0, x1, y1, origin_xy_m, shape, resolution_m) -> Visits:
    ny, nx = int(shape[0]), int(shape[1])
    res = float(resolution_m)
    g = [(np.asarray(v, dtype=float).ravel() - origin_xy_m[i % 2]) / res
         for i, v in enumerate((x0, y0, x1, y1))]
    e = np.stack([g[0], g[1], g[2] - g[0], g[3] - g[1]])
    # batches of ~2^16 columns bound the memory for many long segments
    cols = np.minimum(np.maximum(np.abs(e[2]), np.abs(e[3])), nx + ny) + 2
    ends = np.cumsum(np.where(np.isfinite(cols), cols, 0))
    cuts = list(np.searchsorted(ends, np.arange(1, int(ends[-1] // _BATCH_COLUMNS) + 1)
                                * _BATCH_COLUMNS)) if len(ends) else []
    bounds = [(lo, hi) for lo, hi in zip([0, *cuts], [*cuts, len(cols)]) if hi > lo] or [(0, 0)]
    parts = [_traverse(e[:, lo:hi], nx, ny) for lo, hi in bounds]
    return Visits(*(np.concatenate([getattr(v, f) + (lo if f == "ray" else 0)
                                    for v, (lo, _) in zip(parts, bounds)])
                    for f in ("ray", "ix", "iy", "t_enter", "t_exit")))


_BATCH_COLUMNS = 1 << 16


def _traverse(e: np.ndarray, nx: int, ny: int) -> Visits:
    """:func:`traverse` for one batch, e = (x0, y0, Δx, Δy) in cells."""
    rr = _clip(e, nx, ny)
    # flat indices on the grid padded by one cell, so a rounding step off the edge is caught
    width = nx + 2
    c = _columns(rr, slice(None), 0, 1.0, float(width), float(width + 1))
    keep = np.stack([np.ones(len(c.two), bool), c.two], axis=1).ravel()
    flat = np.stack([c.flat_a, c.flat_b], axis=1).ravel()[keep].astype(np.int64)
    ix = flat % width - 1
    iy = flat // width - 1
    inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
    pick = np.flatnonzero(keep)[inside]
    ray = np.repeat(np.arange(len(c.n)), 2 * c.n)[pick]
    return Visits(ray=ray if rr.rays is None else rr.rays[ray], ix=ix[inside], iy=iy[inside],
                  t_enter=np.stack([c.u_in, c.u_mid], axis=1).ravel()[pick],
                  t_exit=np.stack([c.u_mid, c.u_out], axis=1).ravel()[pick])


# --------------------------------------------------------------------------- the grid


def _erfc_pos(x: np.ndarray) -> np.ndarray:
    """erfc(x) for x ≥ 0 to 2.5e-5 (Abramowitz & Stegun 7.1.25), in x's dtype; numpy has no
    erf and scipy is not a dependency."""
    c = x.dtype.type
    t = c(0.47047) * x
    t += c(1.0)
    np.reciprocal(t, out=t)
    poly = c(0.7478556) * t
    poly += c(-0.0958798)
    poly *= t
    poly += c(0.3480242)
    poly *= t
    e = np.square(x)
    np.negative(e, out=e)
    poly *= np.exp(e, out=e)
    return poly


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
        with np.errstate(all="ignore"):   # non-finite and degenerate beams are handled explicitly
            return self._beams_delta(points)

    def _beams_delta(self, points: Points) -> tuple[np.ndarray, int, int] | None:
        """The log-odds change of ``points`` on the box of cells their beams can reach:
        (change (h, w), ix, iy of its corner cell), or None when no beam is mapped. The box
        has a border of one cell beyond the beams (zero there).

        Work and memory scale with the beams, not the grid. Cells a beam crosses at constant
        weight (a no-return beam; a valid beam more than ``_NEAR_SIGMAS``·σ + margin in front
        of its end point) are counted as row runs; only the columns after that are weighed
        with the model, cell by cell.
        """
        p = self.params
        res = self.resolution_m
        ox = np.asarray(points.origin_x, float).ravel()
        oy = np.asarray(points.origin_y, float).ravel()
        heading = np.asarray(points.heading, float).ravel()
        ex = np.asarray(points.x, float).ravel()
        ey = np.asarray(points.y, float).ravel()
        finite_o = np.isfinite(ox + oy)
        valid = np.asarray(points.valid, bool).ravel() & np.isfinite(ex + ey) & finite_o
        iv = np.flatnonzero(valid)
        nr = np.flatnonzero(~valid & (np.asarray(points.reason).ravel() == _NO_RETURN)
                            & finite_o & np.isfinite(heading))
        nv = len(iv)
        nb = nv + len(nr)
        if nb == 0:
            return None
        # valid beams: emitter → end point, continued tail_sigmas·σ into the surface
        sigma = np.asarray(points.sigma_m, float).ravel()[iv]
        sigma = np.maximum(np.where(np.isfinite(sigma), sigma, p.default_sigma_m), p.min_sigma_m)
        e = np.empty((4, nb))        # beams in cells: x0, y0, Δx, Δy
        both = np.concatenate([iv, nr])
        np.subtract(ox[both], self.origin_xy_m[0], out=e[0])
        np.subtract(oy[both], self.origin_xy_m[1], out=e[1])
        vx = np.subtract(ex[iv], ox[iv], out=e[2, :nv])
        vy = np.subtract(ey[iv], oy[iv], out=e[3, :nv])
        d = np.sqrt(vx * vx + vy * vy)
        length = d + p.tail_sigmas * sigma
        stretch = length / d
        if nv and not d.min() > 0:   # an end point on its emitter: along the heading
            at = d == 0
            hx, hy = np.cos(heading[iv]), np.sin(heading[iv])
            vx[at] = np.where(np.isfinite(hx), hx, 0.0)[at]
            vy[at] = np.where(np.isfinite(hy), hy, 0.0)[at]
            stretch[at] = length[at]
        e[2:, :nv] *= stretch
        # no-return beams: emitter → max range along the heading
        h = heading[nr]
        rmax = float(points.max_range_m)
        np.multiply(np.cos(h), rmax, out=e[2, nv:])
        np.multiply(np.sin(h), rmax, out=e[3, nv:])
        e *= 1.0 / res
        if not np.abs(e).max() < _FAR_CELLS:   # overflowed or absurd numbers: not mapped
            keep = (np.abs(e) < _FAR_CELLS).all(axis=0)
            e, d, sigma, length = e[:, keep], d[keep[:nv]], sigma[keep[:nv]], length[keep[:nv]]
            nv = len(d)
            if not e.shape[1]:
                return None

        # the beams' bounding box on the grid, one cell wider on every side (an end point a
        # rounding step from a border may lie in the next cell), and a border of one cell
        # beyond that for the runs' ends
        ny, nx = self.shape
        tips = e[:2] + e[2:]
        lo_x, lo_y = np.minimum(e[:2], tips).min(axis=1).tolist()
        hi_x, hi_y = np.maximum(e[:2], tips).max(axis=1).tolist()
        inside = lo_x >= 0 and lo_y >= 0 and hi_x < nx and hi_y < ny
        bx0, by0 = max(math.floor(lo_x) - 1, 0), max(math.floor(lo_y) - 1, 0)
        bx1, by1 = min(math.floor(hi_x) + 1, nx - 1), min(math.floor(hi_y) + 1, ny - 1)
        if bx0 > bx1 or by0 > by1:
            return None
        bw, bh = bx1 - bx0 + 3, by1 - by0 + 3
        size = bw * bh
        rr = _clip(e, nx, ny, inside)
        if not len(rr.t0):
            return None
        kv = nv if rr.rays is None else int(np.searchsorted(rr.rays, nv))  # valid beams first
        if rr.rays is not None:
            d, sigma, length = d[rr.rays[:kv]], sigma[rr.rays[:kv]], length[rr.rays[:kv]]

        # a valid beam's columns in front of its near-end part, and every no-return beam
        # but the shortest, are counted as runs
        margin_m = p.free_margin_cells * res
        t_col0, t_col = rr.t_col0[:kv], rr.t_col[:kv]
        n_far = np.floor(((d - margin_m - _NEAR_SIGMAS * sigma) / length - t_col0) / t_col)
        n_far = _clamp(n_far, 0.0, rr.count[:kv])
        if rr.short is not None:
            n_far[rr.short[:kv]] = 0.0
        # (a beam leaving the grid may have only far columns: they end where it leaves)
        t_end = np.concatenate([np.minimum(t_col0 + n_far * t_col, rr.t1[:kv]), rr.t1[kv:]])
        ok = (t_end - rr.t0) * rr.length >= _SHORT_CELLS
        n_far[~ok[:kv]] = 0.0
        n_far = n_far.astype(np.intp)
        # visits counted exactly (integers in float64): valid beams 1, no-return beams 2^20
        same = p.l_no_return == p.l_free
        unit = np.ones(len(ok))
        if not same:
            unit[kv:] = _NR_UNIT
        entries, weights = _runs(rr, t_end, ok, unit, (bx0, by0, bw, bh))
        diff = np.bincount(entries.astype(np.int32), weights, minlength=2 * size + 1)
        # one flat cumsum is the per-row one: every run starts and ends in its own row (the
        # box's border cells hold the run ends), so each row's entries sum to zero
        # (int32 while every sum fits: no bin or count exceeds twice the beams' units)
        small = 2 * len(ok) * (1.0 if same else _NR_UNIT) < 2.0 ** 31
        runs = diff.astype(np.int32 if small else np.int64)
        np.cumsum(runs, out=runs)
        counts = runs[:size].reshape(bh, bw) + runs[size:2 * size].reshape(bw, bh).T
        change = counts * p.l_free
        if not same:   # counts = valid + 2^20·no-return visits
            change += (counts >> _NR_BITS) * (p.l_no_return - _NR_UNIT * p.l_free)

        offset = float(bw * (1 - by0) + 1 - bx0)
        if kv:   # the near-end columns of valid beams, in σ from the end point (u = (s − d)/σ)
            c = _columns(rr, slice(0, kv), n_far, 1.0, float(bw), offset,
                         scale=length / sigma, shift=d / sigma)
            kb = np.flatnonzero(c.two)
            mu = np.repeat(margin_m / sigma, c.n)
            w = self._weight(np.concatenate([c.u_in, c.u_mid[kb]]),
                             np.concatenate([c.u_mid, c.u_out[kb]]),
                             np.concatenate([mu, mu[kb]]))
            cells = np.concatenate([c.flat_a, c.flat_b[kb]]).astype(np.int32)
            change += np.bincount(cells, w, minlength=size).reshape(bh, bw)
        if rr.short is not None and rr.short[kv:].any():
            # no-return beams clipped to a few touch lengths: their start cell
            short = kv + np.flatnonzero(rr.short[kv:])
            c = _columns(rr, short, 0, 1.0, float(bw), offset)
            change += (np.bincount(c.flat_a.astype(np.intp), minlength=size).reshape(bh, bw)
                       * p.l_no_return)
        return change, bx0 - 1, by0 - 1

    def _weight(self, z_a: np.ndarray, z_b: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """Log-odds for a cell a valid beam crosses from z_a to z_b, in σ from its end point
        (the module doc's formula); ``mu`` = the free margin in σ. In float32 (to ~1e-5)."""
        p = self.params
        f32 = np.float32
        z_b = z_b.astype(f32)
        # occupied: l_occ·exp(−gap²/2), gap = how far the cell's [z_a, z_b] is from 0
        gap = np.maximum(z_a.astype(f32), np.negative(z_b))
        np.maximum(gap, f32(0), out=gap)
        occ = np.square(gap, out=gap)
        occ *= f32(-0.5)
        np.exp(occ, out=occ)
        occ *= f32(p.l_occ)
        # free: l_free·Φ(y) for y = −(z_b + mu) > 0 (the whole cell in front of the margin),
        # Φ(y) = 1 − erfc(y/√2)/2
        y = np.add(z_b, mu, out=z_b, casting="unsafe")
        y *= f32(-1.0 / math.sqrt(2.0))
        in_front = y > 0
        free = _erfc_pos(np.maximum(y, f32(0), out=y))
        free *= f32(-0.5 * p.l_free)
        free += f32(p.l_free)
        free *= in_front
        occ += free
        return occ

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
        _clamp(np.add(view, change[1:-1, 1:-1]), self.params.l_min, self.params.l_max, out=view)

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
