"""The occupancy grid's update in plain numpy: the oracle of the compiled ``add_beams``,
``neighbour_ranges`` and ``explained_ranges``.

Slow and readable: every cell a beam crosses (:func:`~irring.maps.mapping.traverse`) gets
the inverse sensor model of docs/mapping.md, evaluated with ``math.erf``. The kernel
(irring/maps/_traverse.pyx) computes the same update with row runs and an approximate erfc;
tests/test_mapping_oracle.py holds them to the tolerance stated there.
"""

from __future__ import annotations

import math

import numpy as np

from ..core import Points, Reason
from .mapping import (MapperParams, add_between, ahead_weight, hit_weight, known_sigma,
                      mapped_beams, placed_readings, returns_of, silences_of, traverse)


def hit_depths(points: Points, params: MapperParams, resolution_m: float) -> np.ndarray:
    """(S, N) m: how deep behind each reading's end point its hit's surface goes.
    ``hit_depth_cells`` for a sharp valid end point (σ ≤ ``hold_sigma_m``) on an occluding
    edge: the step before or after it, same sensor, reads nothing (``NO_RETURN``) or
    ≥ ``edge_jump_cells`` farther (a post's flank, turned away from the beams that pass it);
    0 elsewhere."""
    ox, oy = np.asarray(points.origin_x, float), np.asarray(points.origin_y, float)
    px, py = np.asarray(points.x, float), np.asarray(points.y, float)
    with np.errstate(invalid="ignore"):
        valid = np.asarray(points.valid, bool) & np.isfinite(px + py) & np.isfinite(ox + oy)
        # (as the kernel's sqrt(Δx² + Δy²): a reading moved to its neighbour's range ties
        # with it, and one rounding of hypot's would decide a jump of 0 the other way)
        d = np.where(valid, np.sqrt((px - ox) * (px - ox) + (py - oy) * (py - oy)), np.nan)
        sigma = np.maximum(np.nan_to_num(np.asarray(points.sigma_m, float),
                                         nan=params.default_sigma_m), params.min_sigma_m)
        ranged = np.where(np.asarray(points.reason) == int(Reason.NO_RETURN), np.inf, d)
        jump = params.edge_jump_cells * resolution_m
        edge = np.zeros(d.shape, bool)
        edge[1:] |= ranged[:-1] - d[1:] >= jump            # the step before
        edge[:-1] |= ranged[1:] - d[:-1] >= jump           # the step after
    sharp = valid & (sigma <= params.hold_sigma_m) & edge
    return np.where(sharp, params.hit_depth_cells * resolution_m, 0.0)


def _nearest_valid(valid: np.ndarray, steps: int, later: bool) -> np.ndarray:
    """(S, N) row of each reading's nearest valid reading of the same sensor (column) at
    most ``steps`` rows before it (``later``: after it); −1 where there is none."""
    rows = np.arange(valid.shape[0])[:, None]
    marks = np.where(valid, rows, -1 if not later else valid.shape[0])
    if later:
        nearest = np.minimum.accumulate(marks[::-1], axis=0)[::-1]
        nearest = np.vstack([nearest[1:], np.full((1, valid.shape[1]), valid.shape[0])])
        return np.where((nearest < valid.shape[0]) & (nearest - rows <= steps), nearest, -1)
    nearest = np.maximum.accumulate(marks, axis=0)
    nearest = np.vstack([np.full((1, valid.shape[1]), -1), nearest[:-1]])
    return np.where((nearest >= 0) & (rows - nearest <= steps), nearest, -1)


def neighbour_ranges(points: Points, params: MapperParams) -> np.ndarray:
    """The numpy statement of the compiled :func:`irring.maps.mapping.neighbour_ranges`
    (its contract and why, stated there): (S, N) m, NaN where a reading stays."""
    shape = np.shape(points.valid)
    out = np.full(shape, np.nan)
    steps = int(params.neighbour_steps)
    if steps == 0 or points.cone_half_angle_rad > 0 or len(shape) != 2 or shape[0] < 3:
        return out
    ox, oy = np.asarray(points.origin_x, float), np.asarray(points.origin_y, float)
    px, py = np.asarray(points.x, float), np.asarray(points.y, float)
    with np.errstate(invalid="ignore"):
        valid = np.asarray(points.valid, bool) & np.isfinite(px + py) & np.isfinite(ox + oy)
        sigma = np.maximum(np.nan_to_num(np.asarray(points.sigma_m, float),
                                         nan=params.default_sigma_m), params.min_sigma_m)
        cand = valid & (sigma >= params.explain_sharper * params.min_sigma_m)
        if not cand.any():
            return out
        d = np.where(valid, np.hypot(px - ox, py - oy), np.nan)
        cols = np.arange(shape[1])[None, :]
        behind, before = cand.copy(), cand.copy()      # behind both neighbours / before both
        farther, nearer = np.zeros(shape), np.full(shape, np.inf)
        turns, present, behind_one = [], [], []
        for later in (False, True):
            row = _nearest_valid(valid, steps, later)
            r = np.maximum(row, 0)
            near = (row >= 0) & (np.hypot(px[r, cols] - px, py[r, cols] - py)
                                 <= params.explain_sigmas * np.hypot(sigma[r, cols], sigma))
            present.append(row >= 0)
            # (a one-sided neighbour: sharper, shorter, within the noise)
            behind_one.append(np.where(near & (sigma[r, cols] < sigma) & (d[r, cols] < d),
                                       d[r, cols], np.nan))
            # the turn from the earlier beam to the later one (z of their cross product)
            bx, by = px[r, cols] - ox[r, cols], py[r, cols] - oy[r, cols]
            turns.append(np.sign(bx * (py - oy) - by * (px - ox)) if not later else
                         np.sign((px - ox) * by - (py - oy) * bx))
            other = np.where(near, d[r, cols], np.nan)
            behind &= near & (other < d)
            before &= near & (other > d)
            farther, nearer = np.fmax(farther, other), np.fmin(nearer, other)
        bracketed = (turns[0] * turns[1] > 0)   # its beam between theirs: rows in any order
        behind &= bracketed
        # (an uncertain end point is never moved out: a thin thing in front of the
        # surface its neighbours see may be what it met)
        before &= bracketed & (sigma <= params.lone_sigma_m)
        out[behind] = farther[behind]
        out[before] = nearer[before]
        # an uncertain end point with a neighbour on one side only (silence, an unplaced
        # step or the sweep's end on the other) is not read behind that sharper neighbour
        broad = cand & (sigma > params.lone_sigma_m)
        for side in (0, 1):
            one = broad & present[side] & ~present[1 - side] & np.isfinite(behind_one[side])
            out[one] = behind_one[side][one]
    return out


def explained_ranges(points: Points, shape, origin_xy_m, resolution_m: float,
                     params: MapperParams) -> np.ndarray:
    """The numpy statement of the compiled :func:`irring.maps.mapping.explained_ranges`
    (its contract, stated there): every cell of each candidate's window from
    :func:`~irring.maps.mapping.traverse`, a cell's sharper hits a prefix sum of the batch's
    end points sorted by cell, then σ."""
    p, res = params, float(resolution_m)
    ny, nx = (int(n) for n in shape)
    points = known_sigma(points)      # σ = +inf: no reading (its rule's one home)
    out = np.full(np.shape(points.valid), np.nan)
    vi = np.flatnonzero(np.asarray(points.valid, bool).ravel())
    if p.explain_sigmas <= 0 or vi.size == 0:
        return out
    sigma = np.asarray(points.sigma_m, float).ravel()[vi]
    sigma = np.maximum(np.where(np.isnan(sigma), p.default_sigma_m, sigma), p.min_sigma_m)
    cand = (sigma >= p.explain_sharper * p.min_sigma_m) & (sigma <= p.lone_sigma_m)
    if not cand.any():                 # (most sweeps of near walls: nothing to explain)
        return out
    ox, oy = (np.asarray(a, float).ravel()[vi] for a in (points.origin_x, points.origin_y))
    px, py = (np.asarray(a, float).ravel()[vi] for a in (points.x, points.y))
    with np.errstate(invalid="ignore"):
        d = np.hypot(px - ox, py - oy)
        near = np.maximum(d - p.explain_sigmas * sigma, 0.0)
        cand = np.flatnonzero(cand & np.isfinite(d) & (d - res > near))
    if cand.size == 0:
        return out
    # the batch's end points by cell, then σ: a cell's hits of σ up to s are a prefix sum
    with np.errstate(invalid="ignore"):
        ix = np.floor((px - origin_xy_m[0]) / res)
        iy = np.floor((py - origin_xy_m[1]) / res)
        inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
    key = (iy * nx + ix)[inside] + np.minimum(sigma[inside], 0.5)   # σ < 1 m
    order = np.argsort(key, kind="stable")
    key = key[order]
    cum = np.concatenate(([0.0], np.cumsum(hit_weight(sigma[inside][order], p))))
    # each candidate's beam from d − kσ to its end point
    dc, a, sc, x0, y0 = d[cand], near[cand], sigma[cand], ox[cand], oy[cand]
    ux, uy = (px[cand] - x0) / dc, (py[cand] - y0) / dc
    v = traverse(x0 + ux * a, y0 + uy * a, px[cand], py[cand], origin_xy_m, (ny, nx), res)
    r = v.ray
    s_a, s_b = a[r] + v.t_enter * (dc - a)[r], a[r] + v.t_exit * (dc - a)[r]
    at = (v.iy * nx + v.ix).astype(float)
    sharper = (cum[np.searchsorted(key, at + np.minimum(sc[r] / p.explain_sharper, 0.5),
                                   side="right")]
               - cum[np.searchsorted(key, at, side="left")])
    confirmed = np.flatnonzero((s_b <= dc[r] - res) & (sharper >= p.explain_log_odds))
    if confirmed.size:
        rays, first = np.unique(r[confirmed], return_index=True)   # visits run along the ray
        hit = confirmed[first]
        out.reshape(-1)[vi[cand[rays]]] = 0.5 * (s_a[hit] + s_b[hit])
    return out


def placed(batches, shape, origin_xy_m, resolution_m: float, params: MapperParams) -> list:
    """:func:`irring.maps.mapping.placed_readings` with this module's rules: each batch's
    readings moved by its neighbouring steps, then explained against every batch's."""
    return placed_readings(batches, shape, origin_xy_m, resolution_m, params,
                           neighbours=neighbour_ranges, explained=explained_ranges)


def add(log_odds: np.ndarray, points: Points, origin_xy_m, resolution_m: float,
        params: MapperParams, lo: float = -np.inf, hi: float = np.inf,
        already_placed: bool = False, ends: np.ndarray | None = None) -> np.ndarray:
    """``log_odds`` (ny, nx) after one batch of readings, clamped to [lo, hi] (a new array).

    As :meth:`OccupancyGrid.insert` (with ``lo, hi`` its clamps) and :meth:`~OccupancyGrid.delta`
    (the grid as it is, no clamp: silent beams stop at its cells); readings from a wide cone
    go in as their fan of rays, and pencil beams a sharper surface explains at its range
    (:func:`explained_ranges`), as :func:`placed` places a batch alone (``already_placed``:
    they are). ``ends`` (ny, nx) bool: the cells holding an end point before this batch
    (:attr:`OccupancyGrid.end_cells`), marked with the batch's own (in place; None: none
    before). The kernel clamps only the box of cells
    its beams reach; on a grid already inside [lo, hi] that is the same.
    """
    shape = np.shape(log_odds)
    if not already_placed:
        points = placed([points], shape, origin_xy_m, resolution_m, params)[0]
    given = points
    points, p = mapped_beams(points, params, resolution_m)
    res = float(resolution_m)
    ox, oy = points.origin_x.ravel().astype(float), points.origin_y.ravel().astype(float)
    px, py = points.x.ravel().astype(float), points.y.ravel().astype(float)
    hd = points.heading.ravel().astype(float)
    with np.errstate(invalid="ignore"):
        valid = points.valid.ravel().astype(bool) & np.isfinite(px + py) & np.isfinite(ox + oy)
        no_return = (~valid & (points.reason.ravel() == int(Reason.NO_RETURN))
                     & np.isfinite(ox + oy) & np.isfinite(hd))

    # cells holding a sharp end point (σ ≤ hold_sigma_m) take no free evidence from the batch
    sigma = np.maximum(np.nan_to_num(points.sigma_m.ravel().astype(float),
                                     nan=p.default_sigma_m), p.min_sigma_m)
    held = np.zeros(shape, bool)
    hx = np.floor((px[valid] - origin_xy_m[0]) / res)
    hy = np.floor((py[valid] - origin_xy_m[1]) / res)
    sharp = sigma[valid] <= p.hold_sigma_m
    inside = sharp & (hx >= 0) & (hx < shape[1]) & (hy >= 0) & (hy < shape[0])
    held[hy[inside].astype(int), hx[inside].astype(int)] = True
    # cells holding any valid end point: with stop_at_end_cells, the only ones that stop a
    # silent beam
    ends = np.zeros(shape, bool) if ends is None else ends
    inside = (hx >= 0) & (hx < shape[1]) & (hy >= 0) & (hy < shape[0])
    ends[hy[inside].astype(int), hx[inside].astype(int)] = True

    # valid beams: emitter → end point, continued into the surface: by the hit's depth (a
    # sharp end point on an occluding edge) and tail_sigmas·σ
    vi = np.flatnonzero(valid)
    d = np.hypot(px[vi] - ox[vi], py[vi] - oy[vi])
    s = sigma[vi]
    depth = hit_depths(points, p, res).ravel()[vi]
    length = d + depth + p.tail_sigmas * s
    with np.errstate(invalid="ignore", divide="ignore"):
        ux = np.where(d > 0, (px[vi] - ox[vi]) / d, np.cos(hd[vi]))
        uy = np.where(d > 0, (py[vi] - oy[vi]) / d, np.sin(hd[vi]))
    ux, uy = np.nan_to_num(ux), np.nan_to_num(uy)
    v = traverse(ox[vi], oy[vi], ox[vi] + ux * length, oy[vi] + uy * length,
                 origin_xy_m, shape, res)
    r = v.ray
    s_a, s_b = v.t_enter * length[r], v.t_exit * length[r]
    # the hit: σ-weighted (l_occ up to occ_sigma_m, l_occ·occ_sigma_m/σ beyond, at least
    # l_occ_min; in the cells wholly in front of the end point the floor only by
    # ahead_floor), Gaussian in the gap between the cell and the end point, up to
    # tail_sigmas·σ behind it
    trust = np.minimum(1.0, p.lone_sigma_m / s)
    l_hit = hit_weight(s, p)
    l_ahead = ahead_weight(s, p)
    gap = np.maximum(np.maximum(s_a - d[r], d[r] - s_b), 0.0)
    w_hit = np.where(s_a < d[r] + p.tail_sigmas * s[r],
                     np.where(s_b < d[r], l_ahead[r], l_hit[r])
                     * np.exp(-0.5 * (gap / s[r]) ** 2), 0.0)
    # the surface's depth: a cell entered behind an end point with one gets at least l_occ_min
    # (no more than the hit), Gaussian in its gap to [d, d + depth]; kept apart until the
    # silent beams are in (an inferred surface does not stop them)
    l_depth = np.minimum(min(p.l_occ_min, p.l_occ), l_hit[r])
    gap_depth = np.maximum(s_a - d[r] - depth[r], 0.0)
    w_depth = np.where((s_a > d[r]) & (depth[r] > 0), np.maximum(
        l_depth * np.exp(-0.5 * (gap_depth / s[r]) ** 2) - w_hit, 0.0), 0.0)
    # the pass: l_free·Φ((stop − s_b)/σ) where the cell ends before the free evidence stops,
    # the free margin plus free_sigmas × the σ beyond the floor in front of the end point
    stop = d - p.free_margin_cells * res - p.free_sigmas * (s - p.min_sigma_m)
    z = (stop[r] - s_b) / s[r]
    phi = np.array([0.5 * (1.0 + math.erf(q / math.sqrt(2.0))) for q in z])
    w_free = p.l_free * trust[r] * np.where((s_b < stop[r]) & ~held[v.iy, v.ix], phi, 0.0)
    out = np.array(log_odds, dtype=float)
    np.add.at(out, (v.iy, v.ix), w_hit + w_free)
    add_between(out, given, origin_xy_m, resolution_m, params)   # (the sweep's pencil beams)
    deep = np.zeros(shape)
    np.add.at(deep, (v.iy, v.ix), w_depth)

    # no-return beams: along the heading to the max range, or to the first cell whose
    # log-odds (the grid's with this batch's valid readings) exceed no_return_stop; none in
    # held cells
    # (or to its reach_m, where the estimator found a surface that explains the silence and
    # that is shorter; a reach ≤ 0 maps nothing)
    reach = (np.full(px.size, np.nan) if points.reach_m is None
             else np.asarray(points.reach_m, float).ravel())
    explained = np.isfinite(reach) & (reach < points.max_range_m)
    ni = np.flatnonzero(no_return & ~(explained & (reach <= 0)))
    far = np.where(explained, reach, float(points.max_range_m))[ni]
    v = traverse(ox[ni], oy[ni], ox[ni] + np.cos(hd[ni]) * far, oy[ni] + np.sin(hd[ni]) * far,
                 origin_xy_m, shape, res)
    blocked = out[v.iy, v.ix] > p.no_return_stop
    if p.stop_at_end_cells:
        blocked &= ends[v.iy, v.ix]
    before = np.ones(len(v.ray), bool)
    for ray in np.unique(v.ray[blocked]):
        first = np.flatnonzero((v.ray == ray) & blocked)[0]   # visits run along the ray
        before[first:np.searchsorted(v.ray, ray, side="right")] = False
    keep = before & ~held[v.iy, v.ix]
    np.add.at(out, (v.iy[keep], v.ix[keep]), p.l_no_return)
    return np.clip(out + deep, lo, hi)


def add_run(log_odds: np.ndarray, batches, origin_xy_m, resolution_m: float,
            params: MapperParams, lo: float = -np.inf, hi: float = np.inf) -> np.ndarray:
    """``log_odds`` after a run's batches, as :meth:`OccupancyGrid.insert_run`: the readings
    placed against the whole run (:func:`placed`), every batch's returns, in order, then
    every batch's silent beams, each :func:`add` clamped to [lo, hi]."""
    out = np.array(log_odds, dtype=float)
    ends = np.zeros(np.shape(out), bool)
    for points in placed(batches, np.shape(out), origin_xy_m, resolution_m, params):
        out = add(out, returns_of(points), origin_xy_m, resolution_m, params, lo, hi,
                  already_placed=True, ends=ends)
    for points in batches:
        out = add(out, silences_of(points), origin_xy_m, resolution_m, params, lo, hi,
                  ends=ends)
    return out
