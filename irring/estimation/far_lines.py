"""Far lines and far posts: short far lines whose direction rests on a few noisy readings,
doubted where their members' own profiles vote them off (:func:`short_far_lines`,
:func:`doubt_far_lines`), the overlapping lines of one wall fitted as one where a part is read
to its own range (:func:`fused_lines`), and a thin post far away, its few readings fitted as
one circle (:func:`far_posts`). Why and what was measured: docs/foldover.md, "Short far
lines"; docs/estimator.md, "A short far line's direction", "Far lines fused across sensors",
"Far posts".
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ..core import Points, Reason, points_with, rows_in_step_order
from ..resources import kernel
from .calibration import (NO_RETURN_SIGMAS, RANGE_SIGMAS, RETURN_SIGMAS, SIGMA_FLOOR_M,
                          Calibration, range_sigma)
from .arcs import ARC_DOUBT_RAD, ARC_MISFIT, ARC_MISS, ARC_ON, meet_circle, members_on_arcs
from .lines import direction_se, placed_at, read_to_own_range
from .profiles import LOCAL_MIN, LOCAL_STEPS, Profile, leave_doubted_line, profiles_compiled
from .silence import beam_crossings


_lines = kernel("estimation._lines")
# plain ints: an array compared with an IntEnum member takes numpy's slow path (~7 µs)
_NO_RETURN, _OUT_OF_RANGE = int(Reason.NO_RETURN), int(Reason.OUT_OF_RANGE)
_INCIDENCE_UNKNOWN, _MISSING = int(Reason.INCIDENCE_UNKNOWN), int(Reason.MISSING)


FUSE_MIN = 5            # lines of at least this many valid members are tried together …
FUSE_Z = 2.5            # … where direction and offset agree within this many standard errors …
FUSE_OVERLAP_M = 0.05   # … over at least this much of both lines' extents …
FUSE_TURN_MAX = math.radians(5)  # … and whose directions differ by at most this


def fused_lines(points: Points, label: np.ndarray) -> np.ndarray:
    """``label`` (S, N: each reading's line, −1 none) with lines that are one surface joined:
    lines of ≥ ``FUSE_MIN`` valid members whose extents overlap by ≥ ``FUSE_OVERLAP_M`` and
    whose directions, and offsets at the middle of the overlap, differ by at most ``FUSE_Z``
    of their combined standard errors (total least squares; the members' scatter about
    their line or, where more, their own noise across it) take the smallest label of their
    group. Overlapping lines are of different sensors that saw one wall; the snap then fits
    them as one, which averages their independent offsets. Why: docs/estimator.md, "Far
    lines fused across sensors"."""
    label = np.asarray(label)
    member = points.valid & (label >= 0)
    if not member.any():
        return label
    g = label[member]
    n_lines = int(label.max()) + 1     # invalid readings may hold the highest labels
    n = np.bincount(g, minlength=n_lines)
    cand = (n >= FUSE_MIN).nonzero()[0]
    if cand.size < 2:
        return label
    x, y = points.x[member], points.y[member]
    nn = np.maximum(n, 1)
    mx, my = np.bincount(g, x, n_lines) / nn, np.bincount(g, y, n_lines) / nn
    u, v = x - mx.take(g), y - my.take(g)
    alpha = 0.5 * np.arctan2(2.0 * np.bincount(g, u * v, n_lines),
                             np.bincount(g, u * u - v * v, n_lines))
    ca, sa = np.cos(alpha), np.sin(alpha)
    along = u * ca.take(g) + v * sa.take(g)
    rel = v * ca.take(g) - u * sa.take(g)
    # the members' scatter about their line, or their own noise across it where that is
    # more: pooled readings (13 steps' mean counts) share their noise and scatter less
    own = points.sigma_m[member] * np.cos(points.theta[member])
    var_perp = np.maximum(np.bincount(g, rel * rel, n_lines),
                          np.bincount(g, own * own, n_lines)) / nn
    spread = np.maximum(np.bincount(g, along * along, n_lines), 1e-12)
    lo = np.full(n_lines, np.inf)
    hi = np.full(n_lines, -np.inf)
    np.minimum.at(lo, g, along)
    np.maximum.at(hi, g, along)
    i, j = (a.ravel() for a in np.meshgrid(cand, cand, indexing="ij"))
    keep = i < j
    i, j = i[keep], j[keep]
    # j's extent in i's frame (along i's direction, from i's centroid)
    dxc, dyc = mx[j] - mx[i], my[j] - my[i]
    cj = dxc * ca[i] + dyc * sa[i]
    dot = ca[i] * ca[j] + sa[i] * sa[j]
    ends = cj + dot * lo[j], cj + dot * hi[j]
    a = np.maximum(lo[i], np.minimum(*ends))
    b = np.minimum(hi[i], np.maximum(*ends))
    s = 0.5 * (a + b)                                   # the overlap's middle, on i
    px, py = mx[i] + s * ca[i], my[i] + s * sa[i]
    off = (py - my[j]) * ca[j] - (px - mx[j]) * sa[j]   # j's line from there, across j
    sj = (px - mx[j]) * ca[j] + (py - my[j]) * sa[j]
    var_a = var_perp[i] / spread[i] + var_perp[j] / spread[j]
    var_off = (var_perp[i] / nn[i] + var_perp[i] / spread[i] * s * s
               + var_perp[j] / nn[j] + var_perp[j] / spread[j] * sj * sj)
    turn = np.arcsin(np.clip(np.abs(ca[i] * sa[j] - sa[i] * ca[j]), 0.0, 1.0))
    join = ((b - a >= FUSE_OVERLAP_M) & (turn <= np.minimum(FUSE_Z * np.sqrt(var_a),
                                                             FUSE_TURN_MAX))
            & (np.abs(off) <= FUSE_Z * np.sqrt(var_off)))
    if not join.any():
        return label
    root = np.arange(n_lines)

    def find(k):
        while root[k] != k:
            root[k] = root[root[k]]
            k = root[k]
        return k
    for p, q in zip(i[join], j[join]):
        rp, rq = find(p), find(q)
        if rp != rq:
            root[max(rp, rq)] = min(rp, rq)
    top = np.array([find(k) for k in range(n_lines)])
    out = label.copy()
    out[label >= 0] = top.take(label[label >= 0])
    return out


FAR_LINE_MAX_MEMBERS = 25  # a line of at most this many members is short: its direction
#                            rests on a few noisy readings; a short line …
FAR_LINE_MIN_SHARE = 0.72  # … whose members lie this share of the max range away on average
#                            (the GP2D12's 0.45 of 0.624 m), …
FAR_LINE_Z = 1.0           # … whose members' own slopes differ from its θ by this many of
#                            their standard errors on average (either way) …
FAR_LINE_SHIFT_M = 0.01    # … and would move them by a map cell on average is doubted


SHORT_LINE_MAX_MEMBERS = 9  # elsewhere a far line of at most this many members (unsnapped) …
SHORT_LINE_SE_MAX = math.radians(4)  # … whose direction is known no better leaves each member
#                                      its own θ where its own profile is straight …
SHORT_LINE_OWN_SE = 0.5      # … and its slope this many of its standard errors off the line's


POST_RADII_M = np.geomspace(0.01, 0.07, 13)  # a far post is tried as a circle of these radii
#                                              (the largest fitting best: not a post) …
POST_LINK_M = 0.12       # … through readings on no line whose θ = 0 end points chain this near …
POST_RUN_MAX = 5         # … at most this many of one sensor (more: a surface, not a post) …
POST_SENSORS = 2         # … from at least this many sensors …
POST_JUMP_M = 0.10       # … each sensor's run flanked by silence or readings this much farther;
POST_ON_TESTED = 4       # readings on the circle where a flank is itself on no line (not 3)
POST_BEARING_RAD = 0.0025  # its centre searched on this bearing grid …
POST_RANGE_M = 0.005     # … and this range grid; a silent flanking beam it meets this far
POST_SILENT_RAD = math.radians(15)  # inside the drop-out angle (within the return range) misfits
POST_COARSE = 4          # the search: every 4th radius on a grid 4× as coarse, then fine about it
POST_CELL_REACH = 3      # candidates are paired cell by cell, cells of half POST_LINK_M: a link
#                          spans at most 2 cells' offset (3 with floor's rounding)


def post_cells(px: np.ndarray, py: np.ndarray, link_m: float, crowd: int):
    """The far posts' candidates (end points ``px``, ``py``) by square cells of side
    ``link_m`` / 2, so that a cell's candidates are all within ``link_m`` of each other and
    a link joins cells at most ``POST_CELL_REACH`` apart: (order, start, crowded, key,
    width): the candidates with finite end points in cell order (by index within a cell),
    each cell's first place in ``order`` (and one past the last), whether it holds more
    than ``crowd`` candidates (uint8), its key (int64, ascending; a cell dx, dy across is
    key + dx·width + dy) and width. One statement for the kernel and its numpy oracle."""
    finite = (np.isfinite(px) & np.isfinite(py)).nonzero()[0]
    side = 0.5 * link_m
    ix = np.floor(px[finite] / side).astype(np.int64)
    iy = np.floor(py[finite] / side).astype(np.int64)
    if finite.size:
        ix -= ix.min()
        iy += POST_CELL_REACH - iy.min()
    width = int(iy.max(initial=0)) + POST_CELL_REACH + 1
    cell = ix * width + iy
    order = np.argsort(cell, kind="stable")      # (finite is in index order)
    cell = cell[order]
    first = np.ones(cell.size, dtype=bool)
    first[1:] = cell[1:] != cell[:-1]
    start = np.append(first.nonzero()[0], cell.size).astype(np.intp)
    crowded = (np.diff(start) > crowd).astype(np.uint8)
    return finite[order].astype(np.intp), start, crowded, cell[first], width


def far_posts(points: Points, label: np.ndarray, counts: np.ndarray, steps: np.ndarray,
              cal: Calibration, grouper: Callable | None = None) -> Points:
    """Readings on no line (valid, or INCIDENCE_UNKNOWN; clear returns only) that are one
    thin post seen by several sensors, read at the θ at which their beams meet one circle
    fitted to them all; numpy, shared by both estimators.

    A group: ≥ 3 readings whose θ = 0 end points chain within ``POST_LINK_M``, from
    ≥ ``POST_SENSORS`` sensors, ≤ ``POST_RUN_MAX`` of each, each sensor's run flanked by a
    silent beam or a reading ``POST_JUMP_M`` farther (one on no line itself: then
    ``POST_ON_TESTED`` readings on the circle). Its circle (radius in
    ``POST_RADII_M``, not the largest) is scored as an arc (:func:`arc_incidence`) plus
    ``ARC_MISS`` for each flanking silent beam it would have returned; kept at a mean misfit
    below ``ARC_MISFIT`` with ≥ 3 readings on it (misfit ≤ ``ARC_ON``), which become valid at
    its θ, at their own distance there, σ as on an arc. ``label`` (S, N): each reading's
    line (−1 none); ``counts`` (S, N); ``steps`` (S,); ``grouper``: the groups (the compiled
    :func:`post_groups_compiled` by default; its statement: ``estimate_numpy.post_groups``).
    Why: docs/estimator.md, "Far posts"."""
    found = (grouper or post_groups_compiled)(points, label, counts, cal)
    if found is None:        # most sweeps: no group that could be a post, nothing to fit
        return points
    row, col, comp, groups, px, py = found
    shape = points.valid.shape
    s = np.asarray(counts, dtype=float).reshape(shape)
    heading = np.asarray(points.heading, dtype=float)
    ox, oy = np.asarray(points.origin_x, float), np.asarray(points.origin_y, float)
    cand = np.zeros(shape, dtype=bool)
    cand[row, col] = True
    silent = (points.reason == _NO_RETURN) | (points.reason == _OUT_OF_RANGE)
    has = s > 0
    d0 = np.full(shape, np.nan)
    d0[has] = cal.distance(s[has], 0.0)
    ex, ey = np.cos(heading), np.sin(heading)
    rank = np.empty(shape[0], dtype=np.intp)            # each row's place in step order
    order = rows_in_step_order(steps)
    rank[order] = np.arange(shape[0])
    cx0, cy0 = float(np.mean(ox)), float(np.mean(oy))
    log_s = np.log(np.where(has, s, 1.0))
    out = None
    for c in groups:
        ii, kk = row[comp == c], col[comp == c]
        flank, standing, tested = [], True, False
        for k in np.unique(kk):
            r_k = np.sort(rank[ii[kk == k]])
            far = np.nanmax(d0[ii[kk == k], k]) + POST_JUMP_M
            for q in (r_k[0] - 1, r_k[-1] + 1):
                if not 0 <= q < shape[0]:
                    continue            # the sweep's end: nothing says either way
                j = order[q]
                if silent[j, k]:
                    flank.append((j, k))
                elif not d0[j, k] > far:
                    standing = False
                elif cand[j, k]:      # on no line itself: the post's grazed edge, or more
                    tested = True     # of a steep surface; a circle fitted must be tested
        if not standing:
            continue
        fi = np.array([f[0] for f in flank], dtype=np.intp)
        fk = np.array([f[1] for f in flank], dtype=np.intp)
        bearing = np.arctan2(py[comp == c] - cy0, px[comp == c] - cx0)
        if bearing.max() - bearing.min() > math.pi:   # across ±π: the grid not round the ring
            bearing = np.where(bearing < 0.0, bearing + 2.0 * math.pi, bearing)
        near_m, far_m = np.nanmin(d0[ii, kk]) - 0.15, np.nanmax(d0[ii, kk]) + 0.05

        def score(radius, a, t):
            """Each candidate circle's summed misfit and its readings' θ, d, misfit, noise
            (radius, bearing a and centre range t: (C, 1))."""
            centre = (cx0 + t * np.cos(a), cy0 + t * np.sin(a))
            t_i, th_i, meets = meet_circle(centre, radius, ox[ii, kk], oy[ii, kk],
                                            ex[ii, kk], ey[ii, kk])
            la, b = cal.log_ab(th_i)
            d_i = np.exp(la + b * log_s[ii, kk])
            noise = np.abs(b) * d_i * cal.sigma_counts() / s[ii, kk]
            z = (d_i - t_i) / noise
            each = np.where(meets & (th_i <= cal.max_incidence_rad),
                            np.minimum(z * z, ARC_MISS), ARC_MISS)
            cost = each.sum(axis=1)
            if fi.size:
                t_f, th_f, meets_f = meet_circle(centre, radius, ox[fi, fk], oy[fi, fk],
                                                  ex[fi, fk], ey[fi, fk])
                cost = cost + ARC_MISS * np.count_nonzero(
                    meets_f & (th_f < cal.max_incidence_rad - POST_SILENT_RAD)
                    & (t_f < cal.return_range_m), axis=1)
            return cost, th_i, d_i, each, noise

        # coarse (every POST_COARSE-th radius, POST_COARSE-times the grid steps), then fine
        # about the best: 30× fewer circles than the fine grid (docs/estimator.md, cost)
        step_a, step_t = POST_COARSE * POST_BEARING_RAD, POST_COARSE * POST_RANGE_M
        grid_a = np.arange(bearing.min() - 8 * POST_BEARING_RAD,
                           bearing.max() + 8 * POST_BEARING_RAD + step_a, step_a)
        cand_r, cand_a, cand_t = [], [], []
        for radius in POST_RADII_M[::POST_COARSE]:
            a_g, t_g = np.meshgrid(grid_a, np.arange(near_m + radius, far_m + radius + step_t,
                                                     step_t))
            cand_r.append(np.full(a_g.size, radius))
            cand_a.append(a_g.ravel())
            cand_t.append(t_g.ravel())
        r_c, a_c, t_c = (np.concatenate(v).reshape(-1, 1) for v in (cand_r, cand_a, cand_t))
        q = int(np.argmin(score(r_c, a_c, t_c)[0]))
        at = int(np.argmin(np.abs(POST_RADII_M - r_c[q, 0])))
        fine = np.arange(-POST_COARSE, POST_COARSE + 1)
        r_f, a_f, t_f = np.meshgrid(POST_RADII_M[max(at - POST_COARSE + 1, 0):at + POST_COARSE],
                                    a_c[q, 0] + fine * POST_BEARING_RAD,
                                    fine * POST_RANGE_M, indexing="ij")
        t_f = t_f + t_c[q, 0] - r_c[q, 0] + r_f      # the same surface, each radius behind it
        r_f, a_f, t_f = (v.reshape(-1, 1) for v in (r_f, a_f, t_f))
        cost, th, d, each, noise = score(r_f, a_f, t_f)
        q = int(np.argmin(cost))
        cost, radius, th, d, each, noise = cost[q], r_f[q, 0], th[q], d[q], each[q], noise[q]
        if cost > ARC_MISFIT * (ii.size + fi.size) or radius >= POST_RADII_M[-1]:
            continue
        on = (each <= ARC_ON) & (d >= cal.min_range_m) & (d <= points.max_range_m)
        # a circle is three numbers: three readings on it (one more where it must be tested)
        if np.count_nonzero(on) < (POST_ON_TESTED if tested else 3):
            continue
        lo = cal.distance(s[ii, kk], np.maximum(th - ARC_DOUBT_RAD, 0.0))
        hi = cal.distance(s[ii, kk], np.minimum(th + ARC_DOUBT_RAD, cal.max_incidence_rad))
        sigma = np.hypot(np.maximum(noise, SIGMA_FLOOR_M), 0.5 * np.abs(lo - hi))
        if out is None:
            out = {f: np.array(getattr(points, f))
                   for f in ("x", "y", "d", "theta", "sigma_m", "valid", "reason")}
        i, k = ii[on], kk[on]
        out["d"][i, k], out["theta"][i, k], out["sigma_m"][i, k] = d[on], th[on], sigma[on]
        out["x"][i, k] = ox[i, k] + d[on] * ex[i, k]
        out["y"][i, k] = oy[i, k] + d[on] * ey[i, k]
        out["valid"][i, k], out["reason"][i, k] = True, Reason.OK
    return points if out is None else points_with(points, **out)


def post_groups_compiled(points: Points, label: np.ndarray, counts: np.ndarray,
                         cal: Calibration):
    """``estimate_numpy.post_groups`` (the statement) in one compiled call
    (``irring.estimation._lines.post_groups``, held to it by tests/test_estimate_oracle.py)."""
    f = np.ascontiguousarray
    la0, b0 = cal._ab0
    _, _, no_return, sigma_counts, _ = cal._levels      # (cached: the properties cost µs)
    return _lines.post_groups(
        f(points.reason, dtype=np.uint8).reshape(-1),
        f(points.valid, dtype=bool).reshape(-1).view(np.uint8),
        f(label, dtype=np.intp).reshape(-1), _INCIDENCE_UNKNOWN,
        f(counts, dtype=float).reshape(-1), f(points.heading, dtype=float).reshape(-1),
        f(points.origin_x, dtype=float).reshape(-1), f(points.origin_y, dtype=float).reshape(-1),
        points.valid.shape[1], no_return + (RETURN_SIGMAS + RANGE_SIGMAS) * sigma_counts,
        la0, b0, POST_LINK_M, POST_SENSORS, POST_RUN_MAX, post_cells, POST_CELL_REACH)


def short_far_lines(points: Points, label: np.ndarray, index: np.ndarray, cal: Calibration
                    ) -> tuple[np.ndarray, np.ndarray] | None:
    """The members of short far lines, as fitted (flat (S·N,) masks; None where there are
    none): those of lines of ``LOCAL_MIN`` to ``FAR_LINE_MAX_MEMBERS`` members lying on
    average ``FAR_LINE_MIN_SHARE`` of the range away, which their members' profiles vote
    on, and, unless a part is read to its own range, those of such lines of at most
    ``SHORT_LINE_MAX_MEMBERS`` whose direction standard error exceeds ``SHORT_LINE_SE_MAX``
    (:func:`doubt_far_lines` asks both)."""
    vi = index[points.valid.reshape(-1)[index]]
    lab = label.reshape(-1)[vi]
    member = (lab >= 0).nonzero()[0]
    if member.size == 0:
        return None
    line = lab[member]
    total = np.bincount(line)
    at = vi[member]
    far = (np.bincount(line, weights=points.d.reshape(-1)[at], minlength=total.size)
           >= FAR_LINE_MIN_SHARE * points.max_range_m * total)
    # fewer than LOCAL_MIN members never outvote their line: not asked
    doubt = np.zeros(label.size, dtype=bool)
    doubt[at] = (far & (total >= LOCAL_MIN) & (total <= FAR_LINE_MAX_MEMBERS))[line]
    loose = np.zeros(label.size, dtype=bool)
    few_far = far & (total <= SHORT_LINE_MAX_MEMBERS)
    if few_far.any() and not read_to_own_range(cal, points.max_range_m):
        sel = few_far[line].nonzero()[0]   # (the directions of those lines' members alone)
        at_s = at[sel]
        sigma_perp = (points.sigma_m.reshape(-1)[at_s]
                      * np.cos(points.theta.reshape(-1)[at_s]))
        se_dir = direction_se(points.x.reshape(-1)[at_s], points.y.reshape(-1)[at_s],
                              sigma_perp, line[sel], total.size)
        loose[at_s] = (se_dir > SHORT_LINE_SE_MAX)[line[sel]]
    return (doubt, loose) if doubt.any() or loose.any() else None


def short_far_lines_compiled(points: Points, label: np.ndarray, index: np.ndarray,
                             cal: Calibration) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`short_far_lines` (the statement) in one compiled call
    (``irring.estimation._lines.short_far_lines``; tests/test_far_line_kernels.py holds it
    to the statement)."""
    f = np.ascontiguousarray
    return _lines.short_far_lines(
        f(index, dtype=np.intp), f(points.valid, dtype=bool).reshape(-1).view(np.uint8),
        f(label, dtype=np.intp).reshape(-1),
        *(f(getattr(points, k), dtype=float).reshape(-1)
          for k in ("d", "sigma_m", "theta", "x", "y")),
        FAR_LINE_MIN_SHARE * points.max_range_m, LOCAL_MIN, FAR_LINE_MAX_MEMBERS,
        SHORT_LINE_MAX_MEMBERS, SHORT_LINE_SE_MAX, not read_to_own_range(cal,
                                                                         points.max_range_m))


def doubt_far_lines(points: Points, label: np.ndarray, index: np.ndarray, counts: np.ndarray,
                    steps: np.ndarray, cal: Calibration, doubt: np.ndarray, loose: np.ndarray,
                    profiler: Callable | None = None, voter: Callable | None = None
                    ) -> tuple[Points, np.ndarray]:
    """The members of short far lines (:func:`short_far_lines`: ``doubt``, ``loose``) their
    own profiles (:func:`local_incidence`'s) disown, off their lines; numpy, shared by both
    estimators.

    Where the members of a ``doubt`` line differ from its θ by more than ``FAR_LINE_Z``
    standard errors on average and would move ``FAR_LINE_SHIFT_M`` on average, every member
    leaves it, at its own θ where its profile is straight and clearly steep, else
    INCIDENCE_UNKNOWN; a ``loose`` line loses the members whose own profile is straight and
    whose slope lies ``SHORT_LINE_OWN_SE`` of its standard error off the line's, at their
    own θ where that lies within the range. Only members still on their line are asked (not
    those a circle took: :func:`round_runs`). ``voter``: the vote (compiled by default; the
    oracle passes ``estimate_numpy.far_line_vote``). Returns the points and ``label``.
    Why: docs/foldover.md ("Short far lines", "On every sweep"), docs/estimator.md ("A short
    far line's direction")."""
    vi = index[points.valid.reshape(-1)[index]]
    lab = label.reshape(-1)[vi]
    on = lab >= 0
    doubt, loose = doubt[vi] & on, loose[vi] & on
    ask = (doubt | loose).nonzero()[0]
    if ask.size == 0:
        return points, label
    pr = (profiler or profiles_compiled)(points, vi, ask, counts, steps, cal)
    theta_now = points.theta.reshape(-1)[vi]
    doubted = np.zeros(ask.size, dtype=bool)
    asked = doubt[ask]
    if asked.any():      # the members' own slopes, on average, against the line's θ
        off_line = (voter or _far_line_vote_compiled)(
            ask[asked], asked.nonzero()[0], lab, theta_now, pr, points.d.reshape(-1), vi,
            int(lab.max()) + 1, cal, LOCAL_STEPS, LOCAL_MIN, FAR_LINE_Z, FAR_LINE_SHIFT_M)
        doubted[asked] = off_line[lab[ask[asked]]]
    voted = doubted.copy()   # (a line its members voted off: every member leaves it)
    taken = np.zeros(ask.size, dtype=bool)
    if voted.any():   # (one sensor's run across a pillar: on its arc, where one fits)
        points, label, taken[voted] = members_on_arcs(points, label, vi, ask[voted], pr, cal)
        voted &= ~taken
    if loose.any():   # … each member whose own straight slope is clearly not the line's
        doubted |= loose[ask] & pr.ok & (np.abs(np.tan(theta_now[ask]) - np.abs(pr.slope))
                                         > SHORT_LINE_OWN_SE * pr.se)
    doubted &= ~taken
    if not doubted.any():
        return points, label
    return leave_doubted_line(points, label, vi, ask[doubted], pr, doubted, cal,
                               stay=loose[ask[doubted]] & ~voted[doubted])


def _far_line_vote_compiled(at, sel, lab, theta_now, pr: Profile, d, vi, n_lines: int,
                            cal: Calibration, half: int, min_n: int, z_max: float,
                            shift_m: float) -> np.ndarray:
    """``estimate_numpy.far_line_vote`` (the statement and the why) in one compiled call
    (``irring.estimation._lines.far_line_vote``, held to it by tests/test_estimate_oracle.py):
    the lines voted off, (n_lines,) bool."""
    f = np.ascontiguousarray
    return _lines.far_line_vote(
        at, sel, lab, f(theta_now, dtype=float), pr.chain, pr.step, pr.n, pr.se, pr.slope,
        pr.theta, pr.s, f(d, dtype=float), vi, cal.theta_rad, cal._node_log_a, cal.b,
        n_lines, half, min_n, z_max, shift_m)


CROSS_RANGE_M = 1.0     # a part rated beyond this (GP2Y0A02: 1.5 m) …
CROSS_MIN = 5           # … places its unplaced returns on a line of ≥ this many members …
CROSS_RMS_M = 0.008     # … lying within this RMS of it …
CROSS_MARGIN_M = 0.05   # … that their beam crosses within this of the members' extent …
CROSS_Z = 3.0           # … where their counts read that range within this many σ there
CROSS_OUT_MARGIN_M = 0.10   # an OUT_OF_RANGE return: the margin past the members' extent …
CROSS_SIDE_STEPS = 2        # … where its counts and its sensor's this many steps either way …
CROSS_SIDE_SIGMAS = 2.5     # … stand this many standard errors over the no-return level
NEAR_GAP_M = 0.06       # a surface nearer than the crossing by this …
NEAR_WIDTH_M = 0.03     # … a valid end point within this of the beam, or another line crossed


def unplaced_returns(points: Points, counts: np.ndarray, cal: Calibration,
                     left: np.ndarray | None = None) -> np.ndarray:
    """(S, N) bool: the returns (counts ``NO_RETURN_SIGMAS`` count σ above the no-return level)
    left INCIDENCE_UNKNOWN or OUT_OF_RANGE, where :func:`onto_crossed_lines` may place them
    (none but on a part rated beyond ``CROSS_RANGE_M``, read to its own range, whose curve
    does not fold: a folding sweep's unplaced readings are its fold-over's to judge).
    ``left`` (S, N) uint8 (None: any): each reading's reason as :func:`local_incidence` left
    it; only one still with that reason is asked (not one a later rule unplaced on
    purpose)."""
    if (cal.folds or not (cal.max_range_m > CROSS_RANGE_M
                          and read_to_own_range(cal, points.max_range_m))):
        return np.zeros(points.valid.shape, dtype=bool)
    reason = points.reason
    return (((reason == _INCIDENCE_UNKNOWN) | (reason == _OUT_OF_RANGE))
            & (True if left is None else left == reason)
            & (counts > cal.no_return_counts + NO_RETURN_SIGMAS * cal.sigma_counts()))


def onto_crossed_lines(points: Points, lines, counts: np.ndarray, cal: Calibration,
                       left: np.ndarray | None = None, steps: np.ndarray | None = None
                       ) -> Points:
    """``points`` with the returns left unplaced (:func:`unplaced_returns`; ``left``: as
    there) placed on the first line (``lines``: :class:`~irring.estimation.lines.Lines`, often
    another sensor's) their beam crosses: valid at that crossing's range and incidence, with
    σ the line's valid members' mean σ or their RMS about it, the larger (at least
    ``SIGMA_FLOOR_M``), where the line has ≥ ``CROSS_MIN`` valid members within
    ``CROSS_RMS_M`` RMS of it, the crossing lies within ``CROSS_MARGIN_M`` of their extent
    along it (an OUT_OF_RANGE return: ``CROSS_OUT_MARGIN_M``, and past the extent only where
    its own counts and its sensor's ``CROSS_SIDE_STEPS`` steps on either side each stand
    ``CROSS_SIDE_SIGMAS`` standard errors over the no-return level; ``steps`` (S,): each
    row's motor step, None: rows in step order) and inside the max range and drop-out angle,
    the reading's counts (``counts`` (S, N), its own) give that range at that incidence within
    ``CROSS_Z`` count-noise σ, and nothing nearer explains them: no other line of ≥ 2 valid
    members crossed within their extent and no valid end point (but the line's own) within
    ``NEAR_WIDTH_M`` of the beam, ``NEAR_GAP_M`` or more before the crossing. Why and what it
    measured: docs/estimator.md, "Unplaced far returns on a crossed line"."""
    cand = unplaced_returns(points, counts, cal, left)
    label = lines.label
    member = points.valid & (label >= 0)
    n_lines = lines.centroid.shape[0]
    if n_lines == 0 or not (cand.any() and member.any()):
        return points
    g = label[member]
    n = np.bincount(g, minlength=n_lines)
    (cx, cy), (ux, uy), (nx, ny) = lines.centroid.T, lines.direction.T, lines.normal.T
    du, dv = points.x[member] - cx.take(g), points.y[member] - cy.take(g)
    t = du * ux.take(g) + dv * uy.take(g)
    lo, hi = np.full(n_lines, np.inf), np.full(n_lines, -np.inf)
    np.minimum.at(lo, g, t)
    np.maximum.at(hi, g, t)
    r = du * nx.take(g) + dv * ny.take(g)
    rms = np.sqrt(np.bincount(g, r * r, n_lines) / np.maximum(n, 1))
    # (σ: the members' own on their line, or their RMS about it if more: snapped, ~0)
    sig = np.bincount(g, points.sigma_m[member], n_lines) / np.maximum(n, 1)
    at = np.flatnonzero(cand)
    h = points.heading.reshape(-1)[at]
    # (readings, lines): the range along each beam to each line (0 where it lies behind or
    # along the beam: none), and where along the line
    cos_in, rng, _, along = beam_crossings(
        points.origin_x.reshape(-1)[at], points.origin_y.reshape(-1)[at], np.cos(h), np.sin(h),
        lines.centroid, lines.direction, lines.normal)
    theta = np.arccos(np.minimum(np.abs(cos_in), 1.0))
    weak = points.reason.reshape(-1)[at] == _OUT_OF_RANGE
    margin = np.where(weak, CROSS_OUT_MARGIN_M, CROSS_MARGIN_M)[:, None]
    crossed = ((n >= CROSS_MIN) & (rms <= CROSS_RMS_M) & (along >= lo - margin)
               & (along <= hi + margin) & (rng > cal.min_range_m)
               & (theta < cal.max_incidence_rad))
    first = np.argmin(np.where(crossed, rng, np.inf), axis=1)
    k = np.arange(at.size)
    d, th = rng[k, first], theta[k, first]
    meets = crossed[k, first] & (d < points.max_range_m)
    d, th = np.where(meets, d, 0.0), np.where(meets, th, 0.0)
    s = counts.reshape(-1)[at].astype(float)
    d_s = cal.distance(s, th)
    _, b = cal.log_ab(th)
    put = meets & (np.abs(d_s - d) <= CROSS_Z * range_sigma(b, d_s, cal.sigma_counts() / s))
    # a weak return past the line's members: a beam past a face's end into nothing reads
    # noise, its sensor's next steps too (CRATES_A02), where a wall going on returns alike
    past = (along[k, first] < lo[first]) | (along[k, first] > hi[first])
    ask = put & weak & past
    if ask.any():
        put[ask] = _both_sides_return(at[ask], counts, cal, points.valid.shape, steps)
    put[put] = ~_nearer_surface(points, label, at[put], first[put], d[put], along[put],
                                rng[put], n, lo, hi, cal)
    if not put.any():
        return points
    line = first[put]
    placed = placed_at(points, at[put], d[put], th[put],
                       np.maximum(np.maximum(sig[line], rms[line]), SIGMA_FLOOR_M))
    valid, why = placed.valid.copy(), np.array(placed.reason)
    valid.reshape(-1)[at[put]] = True
    why.reshape(-1)[at[put]] = Reason.OK
    return points_with(placed, valid=valid, reason=why)


def _both_sides_return(at: np.ndarray, counts: np.ndarray, cal: Calibration, shape,
                       steps: np.ndarray | None) -> np.ndarray:
    """(A,) bool: for the flat readings ``at``, whether the mean counts of the reading and its
    sensor's ``CROSS_SIDE_STEPS`` steps before it, and those of it and the steps after it
    (each side as far as the sweep goes), both stand ``CROSS_SIDE_SIGMAS`` standard errors
    (count σ/√n) over the no-return level."""
    n_rows, n_sensors = shape
    order = rows_in_step_order(np.arange(n_rows) if steps is None else steps)
    pos = np.empty(n_rows, dtype=np.intp)
    pos[order] = np.arange(n_rows)
    row, col = np.divmod(at, n_sensors)
    ok = np.ones(at.size, dtype=bool)
    for side in (-1, 1):
        q = pos[row][:, None] + side * np.arange(CROSS_SIDE_STEPS + 1)
        inside = (q >= 0) & (q < n_rows)
        c = np.where(inside, counts[order[np.clip(q, 0, n_rows - 1)], col[:, None]], 0.0)
        m = inside.sum(axis=1)
        ok &= ((c.sum(axis=1) / m - cal.no_return_counts) * np.sqrt(m)
               >= CROSS_SIDE_SIGMAS * cal.sigma_counts())
    return ok


def _nearer_surface(points: Points, label: np.ndarray, at: np.ndarray, first: np.ndarray,
                    d: np.ndarray, along: np.ndarray, rng: np.ndarray, n: np.ndarray,
                    lo: np.ndarray, hi: np.ndarray, cal: Calibration) -> np.ndarray:
    """(A,) bool: whether something nearer than ``NEAR_GAP_M`` before each beam's crossing at
    ``d`` (m) on line ``first`` could have returned its counts: another line of ≥ 2 valid
    members (``n``, their extent ``lo`` … ``hi`` along it) crossed within that extent
    (``along``, ``rng`` (A, L): where and at what range each beam meets each line), or a valid
    end point of the sweep, not the crossed line's member, within ``NEAR_WIDTH_M`` of the
    beam."""
    before = d[:, None] - NEAR_GAP_M
    line = ((n >= 2) & (along >= lo) & (along <= hi) & (rng > cal.min_range_m)
            & (rng < before)).any(axis=1)
    v = np.flatnonzero(points.valid.reshape(-1))
    ox, oy = points.origin_x.reshape(-1)[at, None], points.origin_y.reshape(-1)[at, None]
    h = points.heading.reshape(-1)[at, None]
    px, py = points.x.reshape(-1)[v] - ox, points.y.reshape(-1)[v] - oy
    t = px * np.cos(h) + py * np.sin(h)            # along each beam
    off = np.abs(py * np.cos(h) - px * np.sin(h))  # … and beside it
    other = label.reshape(-1)[v] != first[:, None]
    point = (other & (t > cal.min_range_m) & (t < before) & (off < NEAR_WIDTH_M)).any(axis=1)
    return line | point
