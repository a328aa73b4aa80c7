"""Round things and readings on no line: each reading on no line at the incidence its own
sensor's neighbours give (:func:`local_incidence`), a round thing's arc (:func:`arc_incidence`),
a sensor's run the line model cut into pieces read on its circle (:func:`round_runs`,
:func:`onto_circles`). Why and what was measured: docs/estimator.md, "Readings on no line",
"Round things" and "Onto a round thing's circle".
"""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Callable

import numpy as np

from ..core import Points, Reason, points_with, step_stride
from ..resources import kernel
from .calibration import SIGMA_FLOOR_M, Calibration, range_sigma
from .bounds import clamped_slopes
from .lines import (SNAP_MIN, SNAP_OWN, SNAP_SIGMAS, direction_se, invalidated, placed_at,
                    read_to_own_range, theta0_sigma)
from .profiles import (LOCAL_MIN, UNKNOWN_M, Profile, off_line_profiles, own_slope_sigma,
                       placed_surely, profiles_compiled)

_lines = kernel("estimation._lines")


ROUND_SHARE = 0.4        # a line is a round thing's when this share of its members' profiles
#                          bend away from the beam, …
ROUND_OVER_OK = 1.5      # … this many times as many as are straight and steep (a convex
#                          corner's faces are), …
ROUND_MIN_THETA = math.radians(30)  # … and its members' mean θ is at least this


DIRECTION_SE_MAX = math.radians(6)  # a far line whose direction is known no better gives no θ


def _fewer_distinct(values: np.ndarray, n: int) -> bool:
    """Whether ``values`` hold fewer than ``n`` distinct values (np.unique(values).size < n;
    integers are sorted and counted instead, several times quicker on a sweep's steps)."""
    v = np.asarray(values).reshape(-1)
    if v.dtype.kind not in "iub":
        return bool(np.unique(v).size < n)
    if v.size < n:
        return True
    v = np.sort(v)
    return bool(np.count_nonzero(v[1:] != v[:-1]) + 1 < n)


ARC_RADII_M = np.geomspace(0.008, 0.6, 12)  # the radii a round thing's arc is tried at, …
ARC_REFINE = np.array([-0.5, -0.25, 0.0, 0.25, 0.5])  # … then these grid steps about the best
ARC_MIN = 5             # a sensor's arc needs this many readings on no line …
ARC_SIDE = 2            # … this many either side of its apex (a whole arc seen) …
ARC_GAP_STEPS = 4       # … no more than this many motor steps apart …
ARC_APEX_STEPS = 4      # … whose apex lies within this many readings of its nearest one …
ARC_MISFIT = 4.0        # … and reads them at the arc's θ within this mean squared misfit (σ²),
ARC_MISS = 16.0         # each at most this (a beam that misses the arc: this); a reading
ARC_ON = 9.0            # takes the arc's θ where its own misfit is at most this
ARC_DOUBT_RAD = math.radians(5)  # a reading on an arc: σ includes d over θ ± this


def _arc_misfit(geo, apex: np.ndarray, radius: np.ndarray, cal: Calibration):
    """Candidate circles (C, K): apex reading index and radius (m) of each polyline's
    circle; ``geo`` its readings' padded arrays (C, J). Returns the summed misfit (C, K) and
    each reading's θ, d and misfit at that circle (C, K, J)."""
    ox, oy, ex, ey, d0, log_s, noise, mask = geo
    ax, ay = np.take_along_axis(ex, apex, axis=1), np.take_along_axis(ey, apex, axis=1)
    cx = np.take_along_axis(ox + d0 * ex, apex, axis=1) + radius * ax
    cy = np.take_along_axis(oy + d0 * ey, apex, axis=1) + radius * ay
    rx = cx[..., None] - ox[:, None, :]
    ry = cy[..., None] - oy[:, None, :]
    ejx, ejy = ex[:, None, :], ey[:, None, :]
    along = rx * ejx + ry * ejy
    r = radius[..., None]
    disc = along * along - (rx * rx + ry * ry - r * r)
    t = along - np.sqrt(np.maximum(disc, 0.0))           # where the beam meets the circle
    cos = np.clip(-((t * ejx - rx) * ejx + (t * ejy - ry) * ejy) / r, 0.0, 1.0)
    th = np.arccos(cos)
    meets = (disc > 0.0) & (along > 0.0) & (th <= cal.max_incidence_rad)
    la, b = cal.log_ab(th)
    d = np.exp(la + b * log_s[:, None, :])
    z = (d - t) / noise[:, None, :]
    each = np.where(meets, np.minimum(z * z, ARC_MISS), ARC_MISS)
    return np.where(mask[:, None, :], each, 0.0).sum(axis=-1), th, d, each


def arc_incidence(pr: Profile, pos: np.ndarray, cal: Calibration,
                  radii: np.ndarray = ARC_RADII_M):
    """θ of readings on no line from one circle per arc (a sensor's readings of a round
    thing), numpy; shared by both estimators.

    ``pos``: positions into the valid readings in scan order (ascending). An arc is a run of
    at least ``ARC_MIN`` of them on one polyline, steps at most ``ARC_GAP_STEPS`` apart. It
    is tried as part of a circle whose nearest point lies on one of its readings' beams at
    that reading's θ = 0 distance (the apex, met square on; within ``ARC_APEX_STEPS`` of its
    nearest reading) with a radius of ``radii`` (refined by ``ARC_REFINE``): every
    reading is read at the θ at which its beam meets that circle and scored by how far that
    distance lies from the circle (in its noise σ, squared, at most ``ARC_MISS``). The best
    circle is kept where its apex has ``ARC_SIDE`` readings either side (a whole arc seen)
    and its mean misfit is below ``ARC_MISFIT``; a reading takes it where its own misfit is
    at most ``ARC_ON``. Returns θ (rad), d (m), σ (m: noise at θ plus the spread of d over
    θ ± ``ARC_DOUBT_RAD``), ``good`` and each reading's misfit at its arc's best circle
    (``ARC_MISS`` where it is on none), each (len(pos),), and that circle's centre x, y and
    radius (3, len(pos)). Why: docs/estimator.md, "Round
    things seen far away"."""
    m = pos.size
    theta, dist, sigma = np.full(m, np.nan), np.full(m, np.nan), np.full(m, np.nan)
    good = np.zeros(m, dtype=bool)
    misfit = np.full(m, ARC_MISS)
    circle = np.full((3, m), np.nan)
    if m < ARC_MIN:
        return theta, dist, sigma, good, misfit, circle
    # an arc: consecutive readings of one polyline (its ids grow along the scan order, so
    # they are consecutive in ``pos``, ordered by step), broken where steps are missing (a
    # polyline runs on over silent beams: two posts 39° apart made one)
    chain, step = pr.chain[pos], pr.step[pos]
    cut = np.ones(m, dtype=bool)
    cut[1:] = (chain[1:] != chain[:-1]) | (np.abs(step[1:] - step[:-1]) > ARC_GAP_STEPS)
    ids, first, size = np.unique(np.cumsum(cut), return_index=True, return_counts=True)
    group = np.repeat(np.arange(ids.size), size)
    rank = np.arange(m) - np.repeat(first, size)
    keep = size[group] >= ARC_MIN
    if not keep.any():
        return theta, dist, sigma, good, misfit, circle
    big = (size >= ARC_MIN).nonzero()[0]
    for runs, width in _arc_batches(size[big]):
        _fit_arcs(pr, pos, cal, radii, big[runs], width, group, rank, ids.size,
                  (theta, dist, sigma, good, misfit, circle))
    return theta, dist, sigma, good, misfit, circle


ARC_BLOCK = 1 << 18      # candidate circles × padded readings scored at once (~100 bytes each)
ARC_PAD = 4              # runs padded to the longest, unless that pads them to more than this
ARC_PAD_MIN = 1 << 16    # many times their readings, and more than this many places in all


def _arc_batches(size: np.ndarray):
    """The runs (``size``: readings of each) fitted together and the width they are padded
    to: all at once to the longest (the sums of misfits over a padded row are numpy's, so
    this keeps them to the last bit), unless that pads them beyond ``ARC_PAD`` times their
    readings (a long sweep's long run beside many short ones): then runs of like length
    together, each batch padded at most twice over (its sums may differ in the last bit)."""
    width = int(size.max())
    if size.size * width <= max(ARC_PAD * int(size.sum()), ARC_PAD_MIN):
        return [(np.arange(size.size), width)]
    order = np.argsort(size, kind="stable")
    out, first = [], 0
    total = np.cumsum(size[order])
    while first < order.size:
        done = total[first - 1] if first else 0
        # the longest run of the batch is its last: grow while padding stays within 2×
        last = first
        while (last + 1 < order.size
               and (last + 2 - first) * size[order[last + 1]] <= 2 * (total[last + 1] - done)):
            last += 1
        out.append((np.sort(order[first:last + 1]), int(size[order[last]])))
        first = last + 1
    return out


def _arc_costs(geo, apex: np.ndarray, radius: np.ndarray, cal: Calibration) -> np.ndarray:
    """:func:`_arc_misfit`'s summed misfit (C, K), scored ``ARC_BLOCK`` circle-readings at a
    time (whole rows, so each sum is the one numpy makes of all of them)."""
    n_c, k, n_j = apex.shape[0], apex.shape[1], geo[0].shape[1]
    if n_c * k * n_j <= ARC_BLOCK:
        return _arc_misfit(geo, apex, radius, cal)[0]
    cost = np.empty((n_c, k))
    per = max(1, ARC_BLOCK // n_j)            # rows of (run, circle) at once
    rows = n_c * k
    for lo in range(0, rows, per):
        r = np.arange(lo, min(lo + per, rows))
        c, kk = r // k, r % k
        g = tuple(v[c] for v in geo)
        cost[c, kk] = _arc_misfit(g, apex[c, kk][:, None], radius[c, kk][:, None], cal)[0][:, 0]
    return cost


def _arc_best(geo, apex: np.ndarray, radius: np.ndarray, cal: Calibration):
    """θ, d and misfit (C, J) of each run's readings at its one circle (``apex``, ``radius``:
    (C,)), ``ARC_BLOCK`` places at a time."""
    n_c, n_j = geo[0].shape
    th, d, each = (np.empty((n_c, n_j)) for _ in range(3))
    per = max(1, ARC_BLOCK // n_j)
    for lo in range(0, n_c, per):
        c = np.arange(lo, min(lo + per, n_c))
        _, t, dd, e = _arc_misfit(tuple(v[c] for v in geo), apex[c][:, None],
                                  radius[c][:, None], cal)
        th[c], d[c], each[c] = t[:, 0], dd[:, 0], e[:, 0]
    return th, d, each


def _fit_arcs(pr: Profile, pos: np.ndarray, cal: Calibration, radii: np.ndarray,
              big: np.ndarray, n_j: int, group: np.ndarray, rank: np.ndarray, n_runs: int,
              out: tuple) -> None:
    """:func:`arc_incidence` on the runs ``big`` (of ``n_runs``; ``group`` and ``rank``:
    each reading's run and place in it), padded to ``n_j`` readings: fills its outputs
    ``out`` (θ, d, σ, good, misfit and circle, per reading) in place."""
    theta, dist, sigma, good, misfit, circle = out
    row = np.full(n_runs, -1)
    row[big] = np.arange(big.size)
    keep = row[group] >= 0
    c, j = row[group[keep]], rank[keep]
    n_c = big.size
    mask = np.zeros((n_c, n_j), dtype=bool)
    mask[c, j] = True

    def pad(v, fill):
        out = np.full((n_c, n_j), fill)
        out[c, j] = v[pos[keep]]
        return out
    s, d0, sig_s = pad(pr.s, 1.0), pad(pr.d0, np.inf), pad(pr.sig_s, 0.0)
    h = pad(pr.heading, 0.0)
    ex, ey = np.cos(h), np.sin(h)
    _, b0 = cal._ab0
    noise = range_sigma(b0, np.where(mask, d0, 1.0), sig_s)
    geo = (pad(pr.ox, 0.0), pad(pr.oy, 0.0), ex, ey, np.where(mask, d0, 1.0), np.log(s),
           noise, mask)
    n_in = mask.sum(axis=1)
    # the apex: near the nearest reading, by three-reading means (noise moves a single one)
    left = np.concatenate([d0[:, :1], d0[:, :-1]], axis=1)
    right = np.concatenate([d0[:, 1:], d0[:, -1:]], axis=1)
    right = np.where(np.isfinite(right), right, d0)
    near = np.argmin(d0 + left + right, axis=1)
    span = np.arange(-ARC_APEX_STEPS, ARC_APEX_STEPS + 1)
    apex = np.clip(near[:, None] + span[None, :], 0, (n_in - 1)[:, None])
    k_r = radii.size
    apex1 = np.repeat(apex, k_r, axis=1)
    radius1 = np.tile(radii, (n_c, span.size))
    cost1 = _arc_costs(geo, apex1, radius1, cal)
    best1 = np.argmin(cost1, axis=1)
    # refine: the best apex and its neighbours, radii between the grid's
    a1 = apex1[np.arange(n_c), best1]
    grid_step = math.log(radii[1] / radii[0])
    apex2 = np.clip(a1[:, None] + np.repeat([-1, 0, 1], ARC_REFINE.size)[None, :], 0,
                    (n_in - 1)[:, None])
    radius2 = radius1[np.arange(n_c), best1][:, None] * np.exp(
        grid_step * np.tile(ARC_REFINE, 3))[None, :]
    if n_c * apex2.shape[1] * n_j <= ARC_BLOCK:
        cost2, th2, d2, mis2 = _arc_misfit(geo, apex2, radius2, cal)
        best = np.argmin(cost2, axis=1)
    else:     # each run's best circle's readings computed again, alone (the same numbers)
        cost2 = _arc_costs(geo, apex2, radius2, cal)
        best = np.argmin(cost2, axis=1)
        pick = (np.arange(n_c), best)
        th2, d2, mis2 = (v[:, None] for v in _arc_best(geo, apex2[pick], radius2[pick], cal))
        cost2, apex2, radius2 = cost2[pick][:, None], apex2[pick][:, None], radius2[pick][:, None]
        best = np.zeros(n_c, dtype=np.intp)
    a = apex2[np.arange(n_c), best]
    fits = ((a >= ARC_SIDE) & (a < n_in - ARC_SIDE)
            & (cost2[np.arange(n_c), best] < ARC_MISFIT * n_in))
    th_best = th2[np.arange(n_c), best]                       # (C, J)
    d_best = d2[np.arange(n_c), best]
    on = mis2[np.arange(n_c), best] <= ARC_ON
    lo = cal.distance(s, np.maximum(th_best - ARC_DOUBT_RAD, 0.0))
    hi = cal.distance(s, np.minimum(th_best + ARC_DOUBT_RAD, cal.max_incidence_rad))
    _, b_th = cal.log_ab(th_best)
    sig = np.hypot(range_sigma(b_th, d_best, sig_s),
                   0.5 * np.abs(lo - hi))
    at = keep.nonzero()[0]
    theta[at], dist[at], sigma[at] = th_best[c, j], d_best[c, j], sig[c, j]
    good[at] = (fits[c] & on[c, j] & np.isfinite(dist[at]) & (dist[at] >= cal.min_range_m)
                & np.isfinite(sigma[at]))
    misfit[at] = mis2[np.arange(n_c), best][c, j]
    # the circle: its apex on the apex reading's beam at that reading's θ = 0 distance
    ox, oy, ex, ey, d_apex = (v[np.arange(n_c), a] for v in geo[:5])
    rad = radius2[np.arange(n_c), best]
    circle[:, at] = np.stack([ox + (d_apex + rad) * ex, oy + (d_apex + rad) * ey, rad])[:, c]


ROUND_RADII_M = np.geomspace(0.1, 1.2, 12)  # a sensor's run cut into lines is tried as an arc
ROUND_RUN_MIN = 8        # … where it holds this many valid readings, steps ARC_GAP_STEPS apart
ROUND_JUMP_M = 0.10      # … θ = 0 ranges this near (a jump: another surface) …
ROUND_BULGE_M = 0.01     # … whose end points bulge this far towards it on average …
ROUND_BEHIND = 0.2       # … at most this share of them as far behind the chord of its ends
ROUND_BETTER = 0.5       # an arc replaces the lines where it misfits at most this share of one
ROUND_LINE_ITERATIONS = 4  # line through the run's readings (read as Table II would, this often)
ROUND_RETRY_Z = 3.0      # a run hollow as estimated that one line fits as noise alone would
#                          (χ² within this many of its σ above its n readings) is a wall's
ROUND_UNEXPLAINED = ARC_MISFIT  # a run's reading on no line costs its pieces this (σ²): no line
#                                 explains it; a reading that just fits a circle costs as much
ROUND_SMALL_STRIDE = 2    # in a sweep read every k-th step, k at least this, a run whose θ = 0
ROUND_SMALL_M = 0.04      # circle is smaller than ROUND_RADII_M but at least this (a pillar of
#                           95 mm: 64–88 mm, its flanks read long at θ = 0) …
ROUND_SMALL_RADII_M = ROUND_RADII_M[0] * (ROUND_RADII_M[1] / ROUND_RADII_M[0]) ** np.arange(
    -4, ROUND_RADII_M.size)  # … is tried at these radii (ROUND_RADII_M's grid, 4 steps down)


def _bulging(px: np.ndarray, py: np.ndarray, ox: np.ndarray, oy: np.ndarray,
             group: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Per group (n,) of end points ``px``, ``py`` seen from emitters ``ox``, ``oy`` (each
    group's points in scan order): whether they bulge towards the sensor off the chord
    between the group's ends by ``ROUND_BULGE_M`` on average with at most ``ROUND_BEHIND``
    of them as far behind it; and each point's distance towards the sensor off it (m)."""
    first = np.searchsorted(group, np.arange(n))
    last = np.append(first[1:], group.size) - 1
    ux, uy = px[last] - px[first], py[last] - py[first]
    norm = np.hypot(ux, uy)
    ux, uy = ux / np.maximum(norm, 1e-12), uy / np.maximum(norm, 1e-12)
    side = np.sign((ox[first] - px[first]) * uy - (oy[first] - py[first]) * ux)
    toward = ((px - px[first][group]) * uy[group] - (py - py[first][group]) * ux[group]) \
        * side[group]
    n_in = np.bincount(group, minlength=n)
    return ((np.bincount(group, toward, n) >= ROUND_BULGE_M * n_in)
            & (np.bincount(group, toward < -ROUND_BULGE_M, n) <= ROUND_BEHIND * n_in)), toward


def _kasa_radii(x: np.ndarray, y: np.ndarray, group: np.ndarray, n: int) -> np.ndarray:
    """Radius (m) of the least-squares (Kåsa) circle through each group's points (n,);
    infinite for collinear points."""
    cnt = np.bincount(group, minlength=n).astype(float)
    u = x - (np.bincount(group, x, n) / cnt)[group]
    v = y - (np.bincount(group, y, n) / cnt)[group]
    z = u * u + v * v
    suu, suv, svv, suz, svz, sz = (np.bincount(group, w, n)
                                   for w in (u * u, u * v, v * v, u * z, v * z, z))
    # centred: Σu = Σv = 0, so the centre solves a 2×2 system
    det = suu * svv - suv * suv
    ok = det > 1e-12 * (suu + svv) ** 2
    det = np.where(ok, det, 1.0)
    a = 0.5 * (svv * suz - suv * svz) / det
    b = 0.5 * (suu * svz - suv * suz) / det
    return np.where(ok, np.sqrt(a * a + b * b + sz / cnt), np.inf)


def _one_line_misfit(pr: Profile, pos: np.ndarray, group: np.ndarray, n: int,
                     cal: Calibration) -> np.ndarray:
    """Each reading's misfit (as :func:`_arc_misfit` scores it) when its group's readings
    (``pr`` positions ``pos``, groups ``group`` < ``n``) are read as one straight line: Table
    II's iteration on one total-least-squares line per group, ``ROUND_LINE_ITERATIONS``
    times from θ = 0. (``pr``: a profile, or anything with its ox, oy, heading, s, d0 and
    sig_s.)"""
    ox, oy, h = pr.ox[pos], pr.oy[pos], pr.heading[pos]
    ex, ey = np.cos(h), np.sin(h)
    log_s, d = np.log(pr.s[pos]), pr.d0[pos]
    _, b0 = cal._ab0
    noise = range_sigma(b0, d, pr.sig_s[pos])
    cnt = np.bincount(group, minlength=n).astype(float)
    for _ in range(ROUND_LINE_ITERATIONS):
        x, y = ox + d * ex, oy + d * ey
        mx, my = np.bincount(group, x, n) / cnt, np.bincount(group, y, n) / cnt
        u, v = x - mx[group], y - my[group]
        alpha = 0.5 * np.arctan2(2.0 * np.bincount(group, u * v, n),
                                 np.bincount(group, u * u - v * v, n))
        nx, ny = -np.sin(alpha)[group], np.cos(alpha)[group]
        across = nx * ex + ny * ey
        t = (nx * (mx[group] - ox) + ny * (my[group] - oy)) / np.where(across == 0, 1.0, across)
        th = np.arccos(np.minimum(np.abs(across), 1.0))
        meets = (across != 0) & (t > 0) & (th <= cal.max_incidence_rad)
        la, b = cal.log_ab(np.minimum(th, cal.max_incidence_rad))
        d = np.exp(la + b * log_s)
    z = (d - t) / noise
    return np.where(meets, np.minimum(z * z, ARC_MISS), ARC_MISS)


def _one_line_explains(points: Points, at: np.ndarray, counts: np.ndarray, cal: Calibration,
                       d0: np.ndarray, group: np.ndarray, asked: np.ndarray) -> np.ndarray:
    """Per group (``asked.size``,) of readings ``at`` (flat indices, θ = 0 distances ``d0``,
    groups ``group``): whether one line fits the ``asked`` groups' readings as noise alone
    would (:func:`_one_line_misfit`'s χ² within ``ROUND_RETRY_Z`` of its σ above its count);
    read from the counts, without the range profiles."""
    pick = asked[group]
    s = np.asarray(counts, dtype=float).reshape(-1)[at[pick]]
    lite = SimpleNamespace(ox=points.origin_x.reshape(-1)[at[pick]],
                           oy=points.origin_y.reshape(-1)[at[pick]],
                           heading=points.heading.reshape(-1)[at[pick]], s=s, d0=d0[pick],
                           sig_s=cal.sigma_counts() / s)
    n = int(np.count_nonzero(asked))
    g = (np.cumsum(asked) - 1)[group[pick]]
    cost = np.bincount(g, _one_line_misfit(lite, np.arange(s.size), g, n, cal), n)
    n_in = np.bincount(g, minlength=n)
    out = np.zeros(asked.size, dtype=bool)
    out[asked] = cost <= n_in + ROUND_RETRY_Z * np.sqrt(2.0 * n_in)
    return out


def _pieces_misfit(pr: Profile, pos: np.ndarray, lab: np.ndarray, alpha: np.ndarray,
                   cx: np.ndarray, cy: np.ndarray, cal: Calibration) -> np.ndarray:
    """Each reading's misfit (as :func:`_arc_misfit` scores it) on the line it is a member
    of (``lab`` ≥ 0; lines by direction ``alpha`` and centroid ``cx``, ``cy``), read at the
    θ its beam meets that line with; ``ARC_MISS`` for a reading on no line."""
    on = lab >= 0
    li = np.maximum(lab, 0)
    h = pr.heading[pos]
    ex, ey = np.cos(h), np.sin(h)
    nx, ny = -np.sin(alpha[li]), np.cos(alpha[li])
    across = nx * ex + ny * ey
    t = ((nx * (cx[li] - pr.ox[pos]) + ny * (cy[li] - pr.oy[pos]))
         / np.where(across == 0, 1.0, across))
    th = np.arccos(np.minimum(np.abs(across), 1.0))
    meets = on & (across != 0) & (t > 0) & (th <= cal.max_incidence_rad)
    la, b = cal.log_ab(np.minimum(th, cal.max_incidence_rad))
    d = np.exp(la + b * np.log(pr.s[pos]))
    _, b0 = cal._ab0
    z = (d - t) / range_sigma(b0, pr.d0[pos], pr.sig_s[pos])
    return np.where(meets, np.minimum(z * z, ARC_MISS), ARC_MISS)


def _runs_at_zero(vi: np.ndarray, n_sensors: int, steps: np.ndarray, counts: np.ndarray,
                  cal: Calibration) -> tuple:
    """The runs of valid readings ``vi`` (flat indices in scan order) that one surface could
    make: one sensor, steps at most ``ARC_GAP_STEPS`` apart, θ = 0 ranges within
    ``ROUND_JUMP_M``: their θ = 0 ranges ``d0``, where a run starts ``cut`` (per reading),
    each reading's run < ``n_run`` and each run's ``size``."""
    sensor = vi % n_sensors
    step = np.asarray(steps).reshape(-1)[vi // n_sensors]
    # ranges at θ = 0: a line's θ, wrong where it cuts an arc, makes jumps of its own
    d0 = cal.distance(np.asarray(counts, dtype=float).reshape(-1)[vi])
    cut = np.ones(vi.size, dtype=bool)
    cut[1:] = ((sensor[1:] != sensor[:-1]) | (np.abs(step[1:] - step[:-1]) > ARC_GAP_STEPS)
               | (np.abs(d0[1:] - d0[:-1]) > ROUND_JUMP_M))
    run = np.cumsum(cut) - 1
    n_run = int(run[-1]) + 1
    return d0, cut, run, n_run, np.bincount(run, minlength=n_run)


def _round_asked(points: Points, label: np.ndarray, index: np.ndarray, counts: np.ndarray,
                 steps: np.ndarray, cal: Calibration) -> SimpleNamespace | None:
    """:func:`round_runs`' cheap checks, numpy (the statement the compiled pre-gate
    ``_lines.round_pre`` is held to): None where no run passes them; else the valid
    readings ``vi`` in scan order, their labels ``lab``, runs ``run`` (< ``n_run``), the
    candidate runs' readings (positions ``sel`` into ``vi``, flat indices ``at``, candidate
    ``gi`` < ``n_c``), the θ = 0 ranges ``d0`` (per ``vi``) and per candidate ``keep`` (it
    passes) and ``retried`` (it passes at θ = 0, hollow as estimated)."""
    flat_valid = points.valid.reshape(-1)
    vi = index[flat_valid[index]]
    if vi.size < ROUND_RUN_MIN:
        return None
    lab = label.reshape(-1)[vi]
    d0, cut, run, n_run, size = _runs_at_zero(vi, points.valid.shape[1], steps, counts, cal)
    change = np.zeros(vi.size)
    change[1:] = ~cut[1:] & (lab[1:] != lab[:-1])
    cand = (size >= ROUND_RUN_MIN) & (np.bincount(run, change, n_run) > 0)
    if not cand.any():
        return None
    sel = cand[run].nonzero()[0]
    gi = (np.cumsum(cand) - 1)[run[sel]]
    n_c = int(np.count_nonzero(cand))
    # the run's end points bulge towards the sensor off the chord between its ends, nowhere
    # fall behind it (a concave corner), and not by noise alone (a wall cut in two); where
    # they fall behind it as estimated, their θ = 0 end points are asked: a line read too
    # steep across an arc pulls its members in and makes the arc look hollow
    # (docs/estimator.md, "A table's flank taken for a line")
    at = vi[sel]
    hh = points.heading.reshape(-1)[at]
    ox, oy = points.origin_x.reshape(-1)[at], points.origin_y.reshape(-1)[at]
    px, py = ox + d0[sel] * np.cos(hh), oy + d0[sel] * np.sin(hh)
    keep, toward = _bulging(points.x.reshape(-1)[at], points.y.reshape(-1)[at], ox, oy, gi,
                            n_c)
    retried = (np.bincount(gi, toward < -ROUND_BULGE_M, n_c)
               > ROUND_BEHIND * np.bincount(gi, minlength=n_c))
    if retried.any():
        retried &= _bulging(px, py, ox, oy, gi, n_c)[0]
        keep = keep | retried
    if not keep.any():
        return None
    # … and their circle at θ = 0 is a round thing's, not a post's or a box's corner (θ = 0
    # reads an arc's flanks long: that circle is smooth, if smaller than the arc's); read
    # every other step, one below ROUND_RADII_M too (a pillar's arc cut into steep lines)
    kasa = _kasa_radii(px, py, gi, n_c)
    keep &= kasa >= _least_radius(steps)
    if not keep.any():
        return None
    return SimpleNamespace(vi=vi, lab=lab, run=run, n_run=n_run, sel=sel, gi=gi, n_c=n_c,
                           at=at, d0=d0, keep=keep, retried=retried & keep,
                           small=kasa < ROUND_RADII_M[0])


def round_runs(points: Points, label: np.ndarray, index: np.ndarray, counts: np.ndarray,
               steps: np.ndarray, cal: Calibration, line_alpha: np.ndarray,
               line_cx: np.ndarray, line_cy: np.ndarray, profiler: Callable | None = None,
               snap: bool = False, own_cap_m: float = math.inf) -> tuple[Points, np.ndarray]:
    """A sensor's run of readings that the line model cut into pieces (several lines, or
    lines and readings on no line) re-read as one circle's arc where one fits, and the
    sweep's other runs on such a circle with it; numpy, shared by both estimators.

    A run: valid readings of one sensor, steps at most ``ARC_GAP_STEPS`` apart and θ = 0
    ranges within ``ROUND_JUMP_M``. One of at least ``ROUND_RUN_MIN`` readings holding two
    labels or more, whose end points bulge towards the sensor (``ROUND_BULGE_M``,
    ``ROUND_BEHIND``: not a wall, not a concave corner; a run hollow as estimated is asked
    again at θ = 0 unless one line fits it within noise, ``ROUND_RETRY_Z``) and whose θ = 0
    end points' circle is no smaller than the smallest of ``ROUND_RADII_M`` (not a post, not
    a box's corner), is tried by :func:`arc_incidence` (radii ``ROUND_RADII_M``); its arc is
    kept where it misfits at most ``ROUND_BETTER`` of one line through the run and, by BIC,
    no more than the pieces do, the run's readings on no line counted against them
    (:func:`_round_wins`); in a sweep read every k-th step, k ≥ ``ROUND_SMALL_STRIDE``, a run
    whose θ = 0 circle is below ``ROUND_RADII_M`` (down to ``ROUND_SMALL_M``) is asked too,
    at ``ROUND_SMALL_RADII_M`` (:func:`_least_radius`). Any other run of ``ARC_MIN``
    readings or more then tries the kept
    circles (a sensor that saw one flank only: no apex of its own) and keeps the one it fits
    best where it fits within ``ARC_MISFIT`` (the circle's evidence is another sensor's: its
    own pieces, each a chord read at its θ, fit themselves as well). Each reading taken
    (its own misfit at most ``ARC_ON``) leaves its line (label −1) at the arc's θ, d and σ
    (noise at θ plus d over θ ± ``ARC_DOUBT_RAD``). ``line_alpha``, ``line_cx``,
    ``line_cy``: the lines' directions and centroids. With ``snap`` the readings taken are
    then put on their circle (:func:`onto_circles`; ``own_cap_m`` as for
    :func:`snap_to_lines`). Returns the points and ``label``. Why: docs/estimator.md,
    "Large round things"."""
    asked = _round_asked(points, label, index, counts, steps, cal)
    if asked is None:
        return points, label
    vi, lab, run, n_run, sel, gi = (asked.vi, asked.lab, asked.run, asked.n_run, asked.sel,
                                    asked.gi)
    at, d0, keep, retried = asked.at, asked.d0, asked.keep, asked.retried
    if retried.any():
        # a run hollow as estimated that one line explains within noise is a wall's (its
        # noise fell behind the chord), not an arc: no circle is tried on it
        keep &= ~_one_line_explains(points, at, counts, cal, d0[sel], gi, retried)
        if not keep.any():
            return points, label
    pos = sel[keep[gi]]
    pr = (profiler or profiles_compiled)(points, vi, np.zeros(0, dtype=np.intp), counts,
                                         steps, cal)
    small = asked.small[gi[keep[gi]]]          # per reading of pos: its run's circle is small
    th, dist, sig, good, arc_mis, circle = arc_incidence(pr, pos[~small], cal, ROUND_RADII_M)
    if small.any():
        fit_small = arc_incidence(pr, pos[small], cal, ROUND_SMALL_RADII_M)
        merged = []
        for big_v, small_v in zip((th, dist, sig, good, arc_mis), fit_small[:5]):
            v = np.empty(pos.size, dtype=big_v.dtype)
            v[~small], v[small] = big_v, small_v
            merged.append(v)
        th, dist, sig, good, arc_mis = merged
        c = np.empty((3, pos.size))
        c[:, ~small], c[:, small] = circle, fit_small[5]
        circle = c
    if not good.any():
        return points, label
    gk = (np.cumsum(keep) - 1)[gi[keep[gi]]]
    n_k = int(np.count_nonzero(keep))
    # the simpler model wins where it explains the run as well: one line through it
    line_cost = np.bincount(gk, _one_line_misfit(pr, pos, gk, n_k, cal), n_k)
    wins = ((np.bincount(gk, arc_mis, n_k) <= ROUND_BETTER * line_cost)
            & _round_wins(pr, pos, lab[pos], gk, n_k, arc_mis, 3, line_alpha, line_cx,
                          line_cy, cal))
    good &= wins[gk]
    if not good.any():
        return points, label
    # the other runs on a kept circle: one per run kept, the readings on it taken
    taken = np.zeros(vi.size, dtype=bool)
    taken[pos[good]] = True
    kept = good.nonzero()[0]
    kept_groups, first_of = np.unique(gk[kept], return_index=True)
    circ = circle[:, kept[first_of]]
    cid = np.searchsorted(kept_groups, gk)      # each good reading's circle in circ
    left = np.bincount(run, ~taken, n_run)
    other = left >= ARC_MIN
    if other.any():
        o_pos = (other[run] & ~taken).nonzero()[0]
        o_run = (np.cumsum(other) - 1)[run[o_pos]]
        n_o = int(np.count_nonzero(other))
        th_o, d_o, sig_o, mis_o, c_o = _on_circles(pr, o_pos, o_run, n_o, circ, cal)
        n_in = np.bincount(o_run, minlength=n_o)
        fits = np.bincount(o_run, mis_o, n_o) <= ARC_MISFIT * n_in
        on = fits[o_run] & (mis_o <= ARC_ON) & np.isfinite(d_o) & (d_o >= cal.min_range_m)
        pos = np.concatenate([pos[good], o_pos[on]])
        th, dist, sig, cid = (np.concatenate([v[good], w[on]])
                              for v, w in ((th, th_o), (dist, d_o), (sig, sig_o),
                                           (cid, c_o)))
    else:
        pos, th, dist, sig, cid = pos[good], th[good], dist[good], sig[good], cid[good]
    at = vi[pos]
    label = label.copy()
    label.reshape(-1)[at] = -1
    points = placed_at(points, at, dist, th, sig)
    if snap:
        points = onto_circles(points, at, cid, circ, cal.min_range_m, own_cap_m)
    return points, label


def _least_radius(steps: np.ndarray) -> float:
    """The least θ = 0 circle (m) a run of a sweep of these motor ``steps`` is asked with:
    ``ROUND_SMALL_M`` where every k-th step is read, k at least ``ROUND_SMALL_STRIDE`` (the
    line model cuts a pillar's arc into lines there), else ``ROUND_RADII_M``'s least (at
    every step a box's corner seen tip on passed for a small arc: docs/estimator.md)."""
    return float(ROUND_SMALL_M if step_stride(steps) >= ROUND_SMALL_STRIDE
                 else ROUND_RADII_M[0])


def _round_pre(points: Points, label: np.ndarray, index: np.ndarray, counts: np.ndarray,
               steps: np.ndarray, cal: Calibration) -> np.ndarray:
    """``_lines.round_pre`` asked :func:`_round_asked`'s question: per candidate run whether
    it passes (uint8; none where fewer than ``ROUND_RUN_MIN`` readings are valid)."""
    vi = index[points.valid.reshape(-1)[index]]
    if vi.size < ROUND_RUN_MIN:
        return np.zeros(0, dtype=np.uint8)
    f = np.ascontiguousarray
    # numpy's exp, log, cos and sin (SIMD: libm's may differ in the last bit)
    d0 = cal.distance(np.asarray(counts, dtype=float).reshape(-1)[vi])
    h = points.heading.reshape(-1)[vi]
    return _lines.round_pre(
        f(vi, dtype=np.intp), f(label, dtype=np.intp).reshape(-1),
        f(steps, dtype=np.intp).reshape(-1), points.valid.shape[1], d0, np.cos(h), np.sin(h),
        f(points.x, dtype=float).reshape(-1), f(points.y, dtype=float).reshape(-1),
        f(points.origin_x, dtype=float).reshape(-1), f(points.origin_y, dtype=float).reshape(-1),
        ARC_GAP_STEPS, ROUND_JUMP_M, ROUND_RUN_MIN, ROUND_BULGE_M, ROUND_BEHIND,
        _least_radius(steps))


def round_runs_compiled(points: Points, label: np.ndarray, index: np.ndarray,
                        counts: np.ndarray, steps: np.ndarray, cal: Calibration,
                        line_alpha: np.ndarray, line_cx: np.ndarray, line_cy: np.ndarray,
                        profiler: Callable | None = None, snap: bool = False,
                        own_cap_m: float = math.inf) -> tuple[Points, np.ndarray]:
    """:func:`round_runs`, whose cheap checks (:func:`_round_asked`) are first asked of one
    compiled call (``irring.estimation._lines.round_pre``, held to it by
    tests/test_round_tables.py): where it keeps no run, neither would numpy's and nothing
    is tried as an arc (most sweeps); else :func:`round_runs` itself."""
    if not _round_pre(points, label, index, counts, steps, cal).any():
        return points, label
    return round_runs(points, label, index, counts, steps, cal, line_alpha, line_cx, line_cy,
                      profiler, snap, own_cap_m)


def onto_circles(points: Points, at: np.ndarray, circle: np.ndarray, circles: np.ndarray,
                 min_range_m: float, own_cap_m: float = math.inf) -> Points:
    """The flat readings ``at`` of round things (``circle``: which of ``circles`` (3, C:
    centre x, y, radius; :func:`round_runs`' kept circles) each was read on) put where their
    beams meet that circle's radius refitted to the end points of all its readings, as
    :func:`snap_to_lines` puts a line's members on their line: a circle of at least
    ``SNAP_MIN`` readings, each moved in from behind it or out by at most ``SNAP_SIGMAS`` σ,
    within [``min_range_m``, ``points.max_range_m``]; its σ becomes the circle's uncertainty
    there (its members' radial RMS over √n, along the beam) with half its own σ added (at
    most ``own_cap_m``). Why: docs/estimator.md, "Onto a round thing's circle"."""
    if at.size == 0:
        return points
    n_c = circles.shape[1]
    n = np.bincount(circle, minlength=n_c)
    x, y = points.x.reshape(-1)[at], points.y.reshape(-1)[at]
    cxm, cym = circles[0], circles[1]
    radial = np.hypot(x - cxm[circle], y - cym[circle])
    rm = np.bincount(circle, radial, n_c) / np.maximum(n, 1)
    use = n >= SNAP_MIN
    if not use[circle].any():
        return points
    resid = radial - rm[circle]
    rms = np.sqrt(np.bincount(circle, resid * resid, n_c) / np.maximum(n, 1))
    h = points.heading.reshape(-1)[at]
    ox, oy = points.origin_x.reshape(-1)[at], points.origin_y.reshape(-1)[at]
    rx, ry = cxm[circle] - ox, cym[circle] - oy
    ex, ey = np.cos(h), np.sin(h)
    along = rx * ex + ry * ey
    disc = along * along - (rx * rx + ry * ry - rm[circle] ** 2)
    t = along - np.sqrt(np.maximum(disc, 0.0))
    d = points.d.reshape(-1)[at]
    own = points.sigma_m.reshape(-1)[at]
    ok = (use[circle] & (disc > 0.0) & (along > 0.0) & (t - d <= SNAP_SIGMAS * own)
          & (t >= min_range_m) & (t <= points.max_range_m))
    if not ok.any():
        return points
    # the beam's cosine on the circle where it meets it: the fit's normal error along it
    cos = np.clip(((ox + t * ex - cxm[circle]) * -ex + (oy + t * ey - cym[circle]) * -ey)
                  / np.maximum(rm[circle], 1e-12), 1e-3, 1.0)
    fit = rms[circle] / np.sqrt(np.maximum(n[circle], 1)) / cos
    sigma = np.maximum(np.hypot(fit, np.minimum(SNAP_OWN * own, own_cap_m)), SIGMA_FLOOR_M)
    return placed_at(points, at[ok], t[ok], points.theta.reshape(-1)[at[ok]], sigma[ok])


def _round_wins(pr: Profile, pos: np.ndarray, lab: np.ndarray, group: np.ndarray, n: int,
                arc_mis: np.ndarray, arc_params: int, line_alpha: np.ndarray,
                line_cx: np.ndarray, line_cy: np.ndarray, cal: Calibration) -> np.ndarray:
    """Per group (n,): whether its readings misfit their arc (``arc_mis``, ``arc_params``
    parameters of its own) no more than its pieces by BIC: a line member on its line, each
    distinct line worth 3 (direction, offset and where it ends; the last 2), a reading on no
    line (``lab`` < 0) at ``ROUND_UNEXPLAINED`` (the lines leave it unexplained). A box's
    convex corner seen by one sensor is two lines within noise and a circle well outside it;
    an arc whose flank one line took too steep fits the readings that line left."""
    mem = lab >= 0
    lm, gm = lab[mem], group[mem]
    piece_cost = (np.bincount(gm, _pieces_misfit(pr, pos[mem], lm, line_alpha, line_cx,
                                                 line_cy, cal), n)
                  + ROUND_UNEXPLAINED * np.bincount(group[~mem], minlength=n))
    # distinct lines (a run's readings may alternate between two of them)
    width = int(lm.max(initial=0)) + 1
    n_pieces = np.bincount(np.unique(gm * width + lm) // width, minlength=n)
    log_n = np.log(np.maximum(np.bincount(group, minlength=n), 2))
    arc_cost = np.bincount(group, arc_mis, n)
    return ((arc_cost + arc_params * log_n <= piece_cost + (3.0 * n_pieces - 1.0) * log_n)
            | (n_pieces == 0))


def _on_circles(pr: Profile, pos: np.ndarray, group: np.ndarray, n: int,
                circles: np.ndarray, cal: Calibration):
    """Readings ``pr`` positions ``pos`` (groups ``group`` < ``n``) read on each of
    ``circles`` (3, C: centre x, y, radius); each group takes the circle it misfits least.
    Returns θ, d, σ (as :func:`arc_incidence` gives them), misfit and the circle taken, each
    per reading."""
    h = pr.heading[pos]
    ex, ey = np.cos(h), np.sin(h)
    t, th, meets = meet_circle(circles[:2, :, None], circles[2][:, None], pr.ox[pos],
                                pr.oy[pos], ex, ey)
    meets &= th <= cal.max_incidence_rad                      # (C, J)
    s = pr.s[pos]
    log_s = np.log(s)
    la, b = cal.log_ab(th)
    d = np.exp(la + b * log_s)
    _, b0 = cal._ab0
    noise = range_sigma(b0, pr.d0[pos], pr.sig_s[pos])
    z = (d - t) / noise
    mis = np.where(meets, np.minimum(z * z, ARC_MISS), ARC_MISS)
    cost = np.stack([np.bincount(group, m, n) for m in mis])  # (C, n)
    best = np.argmin(cost, axis=0)[group]
    j = np.arange(pos.size)
    th_b, d_b, mis_b = th[best, j], d[best, j], mis[best, j]
    lo = cal.distance(s, np.maximum(th_b - ARC_DOUBT_RAD, 0.0))
    hi = cal.distance(s, np.minimum(th_b + ARC_DOUBT_RAD, cal.max_incidence_rad))
    _, b_th = cal.log_ab(th_b)
    sig = np.hypot(range_sigma(b_th, d_b, pr.sig_s[pos]),
                   0.5 * np.abs(lo - hi))
    return th_b, d_b, sig, mis_b, best


def meet_circle(centre, radius: float, ox, oy, ex, ey):
    """Where beams (origins ``ox, oy``, unit directions ``ex, ey``: (J,)) meet circles
    (``centre``: x, y of shape (C, 1)): the distance t (C, J), the incidence there and
    whether they meet at all (ahead of the origin)."""
    rx, ry = centre[0] - ox, centre[1] - oy
    along = rx * ex + ry * ey
    disc = along * along - (rx * rx + ry * ry - radius * radius)
    t = along - np.sqrt(np.maximum(disc, 0.0))
    cos = np.clip(-((t * ex - rx) * ex + (t * ey - ry) * ey) / radius, 0.0, 1.0)
    return t, np.arccos(cos), (disc > 0.0) & (along > 0.0)


def members_on_arcs(points: Points, label: np.ndarray, vi: np.ndarray, pos: np.ndarray,
                    pr: Profile, cal: Calibration) -> tuple[Points, np.ndarray, np.ndarray]:
    """Members of lines a rule disowned (``pos``: ascending positions into the valid
    readings ``vi``; ``pr`` profiles every valid reading) read on a round thing's arc where
    one fits (:func:`arc_incidence`) and its run's θ = 0 end points bulge towards the
    sensor (:func:`_bulging`: a convex thing, not a concave wall), in sweeps of one sensor
    only (``rotating1``); numpy, shared by both estimators. Returns the points (those taken
    at the arc's θ, d and σ), ``label`` (those taken, −1) and which of ``pos`` were taken.
    Why, and why one sensor only: docs/estimator.md, "A disowned line on a pillar"."""
    taken = np.zeros(pos.size, dtype=bool)
    if points.valid.shape[1] != 1 or pos.size == 0:
        return points, label, taken
    th, dist, sig, good, _, _ = arc_incidence(pr, pos, cal)
    if not good.any():
        return points, label, taken
    # the runs arc_incidence fitted (one polyline, steps ARC_GAP_STEPS apart)
    chain, step = pr.chain[pos], pr.step[pos]
    cut = np.ones(pos.size, dtype=bool)
    cut[1:] = (chain[1:] != chain[:-1]) | (np.abs(step[1:] - step[:-1]) > ARC_GAP_STEPS)
    group = np.cumsum(cut) - 1
    h, d0, ox, oy = pr.heading[pos], pr.d0[pos], pr.ox[pos], pr.oy[pos]
    convex = _bulging(ox + d0 * np.cos(h), oy + d0 * np.sin(h), ox, oy, group,
                      int(group[-1]) + 1)[0]
    good &= convex[group]
    if not good.any():
        return points, label, taken
    at = vi[pos[good]]
    points = placed_at(points, at, dist[good], th[good], sig[good])
    label = label.copy()
    label.reshape(-1)[at] = -1
    taken[good] = True
    return points, label, taken


def local_incidence(points: Points, label: np.ndarray, index: np.ndarray, counts: np.ndarray,
                    steps: np.ndarray, cal: Calibration, profiler: Callable | None = None,
                    arcs: list | None = None) -> tuple[Points, np.ndarray]:
    """Readings on no line (``label`` −1, θ = 0), and the members of lines that are a round
    thing's, re-read at the incidence their own sensor's neighbouring steps give; numpy,
    shared by both estimators.

    ``index``: flat (S, N) indices of the live readings in scan order (each sensor's by
    step); ``steps`` (S,): each row's motor step. The valid readings of the same surface
    (polyline) within ``LOCAL_STEPS`` steps are fitted as u = u0 + v·tan θ in the reading's
    beam frame. A straight profile clearly not flat gives θ and a σ that includes the slope's
    standard error; a profile bent away from the beam (a post) keeps θ = 0 with the σ of its
    doubt; one that decides nothing, where θ = 0 may read more than ``UNKNOWN_M`` long, is
    INCIDENCE_UNKNOWN, unless the readings on no line alone give it a straight profile that
    places it surely (:func:`off_line_profiles`). The members of a steep line whose own
    profiles mostly bend away (a column's arc cut into short lines; ``ROUND_*``) leave it
    first and are read the same way (short far lines: :func:`doubt_far_lines`). Returns the
    points and ``label`` without those members; ``arcs`` (a list): the readings taken onto
    arcs and their circles appended to it, (flat indices, (3, n) centre x, y and radius), for
    :func:`onto_post_circles`. The why and the measured effects:
    docs/estimator.md ("Readings on no line", "Round things", "A short far line's
    direction"), docs/foldover.md ("Short far lines")."""
    flat_valid = points.valid.reshape(-1)
    vi = index[flat_valid[index]]               # valid readings in scan order
    if vi.size == 0:
        return points, label
    lab = label.reshape(-1)[vi]
    theta_now = points.theta.reshape(-1)[vi]
    off = (lab < 0) & (theta_now == 0.0)
    # only a line read steeply can be read too steeply: its members are asked too
    member = (lab >= 0).nonzero()[0]
    line = lab[member]
    total = np.bincount(line)
    steep = np.bincount(line, weights=theta_now[member], minlength=total.size)
    maybe = np.zeros(vi.size, dtype=bool)
    maybe[member] = (steep >= ROUND_MIN_THETA * total)[line]
    # where a part is read to its own range, a far line of few noisy readings may know its
    # direction only to 10-20°, and its members read at that θ lie 20-150 mm off: a line
    # whose direction is that unsure gives its members no θ (docs/estimator.md, "A far
    # line's direction"; elsewhere: doubt_far_lines)
    unsure = np.zeros(vi.size, dtype=bool)
    if member.size and read_to_own_range(cal, points.max_range_m):
        at = vi[member]
        sigma_perp = points.sigma_m.reshape(-1)[at] * np.cos(theta_now[member])
        se_dir = direction_se(points.x.reshape(-1)[at], points.y.reshape(-1)[at],
                              sigma_perp, line, total.size)
        unsure[member] = (se_dir > DIRECTION_SE_MAX)[line]
    maybe |= unsure
    ask = (off | maybe).nonzero()[0]
    if ask.size == 0:
        return points, label
    pr = (profiler or profiles_compiled)(points, vi, ask, counts, steps, cal)
    # round lines: their members bend away more often than not straight and steep
    asked = maybe[ask]
    line = lab[ask[asked]]
    bent = np.bincount(line, weights=pr.convex[asked], minlength=total.size)
    straight = np.bincount(line, weights=pr.ok[asked], minlength=total.size)
    round_line = (bent >= ROUND_SHARE * total) & (bent >= ROUND_OVER_OK * straight)
    taken = unsure[ask]
    taken[asked] |= round_line[line]
    if taken.any():    # back to θ = 0 with the σ of a reading on no line
        at = vi[ask[taken]]
        s0, d0 = pr.s[ask[taken]], pr.d0[ask[taken]]
        points = placed_at(points, at, d0, 0.0,
                           theta0_sigma(cal, s0, d0, pr.sig_s[ask[taken]]))
        label = label.copy()
        label.reshape(-1)[at] = -1
    mine = off[ask] | taken                     # the readings on no line now
    if not mine.any():
        return points, label
    off = ask[mine]
    s, d0, sig_s = pr.s, pr.d0, pr.sig_s
    ok, convex, sure, steep, theta, slope, se = (v[mine] for v in (
        pr.ok, pr.convex, pr.sure, pr.steep, pr.theta, pr.slope, pr.se))
    s_off = s[off]
    s_ok = s_off[ok]
    th, t, e = theta[ok], np.abs(slope[ok]), se[ok]
    # θ ± the slope's standard error: the range of d it leaves
    lo = np.arctan(np.maximum(t - e, 0.0))
    hi = np.minimum(np.arctan(t + e), cal.max_incidence_rad)
    # the curve read once for all (elementwise: the same numbers as one call each): at the
    # steepest θ allowed, at θ, and at θ ± its standard error
    d_steep, d_new, d_lo, d_hi = np.split(
        cal.distance(np.concatenate([s_off, s_ok, s_ok, s_ok]),
                     np.concatenate([steep, th, lo, hi])),
        np.cumsum([s_off.size, s_ok.size, s_ok.size]))
    # how much longer θ = 0 reads than the steepest θ the readings allow
    span = d0[off] - d_steep
    # a slope past the drop-out angle places a reading only where its lower bound does
    clamp = clamped_slopes(cal, s_ok, slope[ok], se[ok], pr.n[mine][ok], UNKNOWN_M)
    if clamp.any():
        ok = ok.copy()
        ok[ok.nonzero()[0][clamp]] = False
        th, t, e, lo, hi = (v[~clamp] for v in (th, t, e, lo, hi))
        s_ok, d_new, d_lo, d_hi = (v[~clamp] for v in (s_ok, d_new, d_lo, d_hi))
    # where θ = 0 may read more than UNKNOWN_M long, a bend noise could make (a steep far
    # wall's few readings bent 2.2 SE by noise were kept 106-166 mm long) is not enough
    convex = convex & (~(span > UNKNOWN_M) | sure)
    # a ring held still (fewer motor steps than a slope needs) has no neighbours to ask: its
    # readings are what it has (flagging them lost a radial ring nearly every reading)
    still = _fewer_distinct(steps, LOCAL_MIN)
    few = ~ok & ~convex & (not still) & (span > UNKNOWN_M)
    if few.any() and member.size:
        # a short face beside a line's face (a box's end past its corner) bends the profile
        # of its readings where their window takes in the line's members: asked again of
        # the readings on no line alone, a straight profile gives θ
        again = off_line_profiles(points, label, off[few], vi, counts, steps, cal, profiler)
        if again is not None:
            fix = few.nonzero()[0][again[0]]
            sure = placed_surely(cal, s_off[fix], *again[1:], sig_s[off[fix]])
            if sure.any():
                fix = fix[sure]
                ok, few = ok.copy(), few.copy()
                ok[fix], few[fix] = True, False
                theta, slope, se = theta.copy(), slope.copy(), se.copy()
                theta[fix], slope[fix], se[fix] = (v[sure] for v in again[1:])
                th, t, e = theta[ok], np.abs(slope[ok]), se[ok]
                lo = np.arctan(np.maximum(t - e, 0.0))
                hi = np.minimum(np.arctan(t + e), cal.max_incidence_rad)
                s_ok = s_off[ok]
                d_new, d_lo, d_hi = cal.distance(np.concatenate([s_ok, s_ok, s_ok]),
                                                 np.concatenate([th, lo, hi])).reshape(3, -1)
    # a convex thing's reading may have met its side steeply, a still ring's any surface:
    # θ = 0 with the σ of that doubt
    wide = (convex | still) & ~ok
    # a polyline holding a bent profile is a round thing's arc: its readings on no line
    # take θ from one circle through them where one fits (arc_incidence)
    arc = np.zeros(0, dtype=np.intp)
    if convex.any() and not still:
        on_arc = np.isin(pr.chain[off], np.unique(pr.chain[off[convex]]))
        th_a, d_a, sig_a, fit, mis_a, circle_a = arc_incidence(pr, off[on_arc], cal)
        arc = on_arc.nonzero()[0][fit]
        if arcs is not None and arc.size:
            arcs.append(_round_arcs(pr, off[arc], mis_a[fit], circle_a[:, fit], vi, cal))
        th_a, d_a, sig_a = th_a[fit], d_a[fit], sig_a[fit]
        on = np.zeros(off.size, dtype=bool)
        on[arc] = True
        rest = ~on[ok]          # the slopes' readings not on an arc
        th, d_new, d_lo, d_hi = th[rest], d_new[rest], d_lo[rest], d_hi[rest]
        ok, few, wide = ok & ~on, few & ~on, wide & ~on
    if not (ok.any() or few.any() or wide.any() or arc.size):
        return points, label
    if few.any():    # (few, wide and ok are readings apart)
        points = invalidated(points, vi[off[few]], Reason.INCIDENCE_UNKNOWN)
    out = {f: np.array(getattr(points, f)) for f in ("x", "y", "d", "theta", "sigma_m")}
    if wide.any():
        at = vi[off[wide]]
        doubt = 0.5 * span[wide]
        out["sigma_m"].reshape(-1)[at] = np.hypot(out["sigma_m"].reshape(-1)[at], doubt)
    at = vi[off[ok]]
    sigma, keep = own_slope_sigma(cal, th, d_new, d_lo, d_hi, sig_s[off[ok]])
    at, th, d_new, sigma = at[keep], th[keep], d_new[keep], sigma[keep]
    if arc.size:
        at = np.concatenate([at, vi[off[arc]]])
        th, d_new, sigma = (np.concatenate(v) for v in ((th, th_a), (d_new, d_a), (sigma, sig_a)))
    hh = points.heading.reshape(-1)[at]
    out["d"].reshape(-1)[at] = d_new
    out["theta"].reshape(-1)[at] = th
    out["sigma_m"].reshape(-1)[at] = sigma
    out["x"].reshape(-1)[at] = points.origin_x.reshape(-1)[at] + d_new * np.cos(hh)
    out["y"].reshape(-1)[at] = points.origin_y.reshape(-1)[at] + d_new * np.sin(hh)
    return points_with(points, **out), label


def _round_arcs(pr: Profile, pos: np.ndarray, mis: np.ndarray, circle: np.ndarray,
                vi: np.ndarray, cal: Calibration) -> tuple[np.ndarray, np.ndarray]:
    """The readings ``pos`` (into ``vi``) :func:`arc_incidence` took, with their misfits
    ``mis`` and circles ``circle`` (3, n), as :func:`onto_post_circles` is given them: (flat
    indices, one circle per run (3, runs)), NaN the circles of runs one line explains nearly
    as well (the arc's misfit above ``ROUND_BETTER`` of the line's, as :func:`round_runs`
    asks: a face, not a post)."""
    # (a run's readings are consecutive and share its circle)
    new = np.ones(pos.size, dtype=bool)
    new[1:] = (circle[:, 1:] != circle[:, :-1]).any(axis=0)
    group = np.cumsum(new) - 1
    n = int(group[-1]) + 1
    line = np.bincount(group, _one_line_misfit(pr, pos, group, n, cal), n)
    round_ = np.bincount(group, mis, n) <= ROUND_BETTER * line
    return vi[pos], np.where(round_, circle[:, new], np.nan)


def onto_post_circles(points: Points, label: np.ndarray, index: np.ndarray,
                      counts: np.ndarray, steps: np.ndarray, cal: Calibration, arcs: list
                      ) -> tuple[Points, np.ndarray]:
    """The circles :func:`local_incidence` fitted to posts' arcs (``arcs``: its list, and
    the readings :func:`round_runs` put on its circles with none, which keep them) asked
    by the sweep's other runs (valid readings of one sensor, steps at most
    ``ARC_GAP_STEPS`` apart, θ = 0 ranges within ``ROUND_JUMP_M``; at least
    ``ARC_MIN``), on a line or not: a sensor whose sweep ends on a post's flank sees no
    apex of its own, and its readings there were read at θ = 0 (long at the flank, σ wide),
    at a slope its few readings gave, or on a line across the flank (too steep, short). A
    run whose readings misfit their circle at most ``ARC_MISFIT`` on average takes it (each
    reading of own misfit at most ``ARC_ON``, at or past the least range) as
    :func:`round_runs`' other runs take its circles; numpy, shared by both estimators.
    Returns the points and ``label`` (those taken, −1). Why: docs/estimator.md, "A post's
    circle shared"."""
    if not arcs:
        return points, label
    on_arc = np.concatenate([a for a, _ in arcs])
    circles = np.concatenate([c for _, c in arcs], axis=1)
    circles = circles[:, np.isfinite(circles[2])]
    circles = circles[:, np.lexsort(circles[::-1])]      # (in np.unique's order)
    if circles.shape[1] == 0:
        return points, label
    flat_valid = points.valid.reshape(-1)
    vi = index[flat_valid[index]]
    vi = vi[~np.isin(vi, on_arc)]
    if vi.size < ARC_MIN:
        return points, label
    d0, _, run, n_run, size = _runs_at_zero(vi, points.valid.shape[1], steps, counts, cal)
    pos = (size[run] >= ARC_MIN).nonzero()[0]
    if pos.size == 0:
        return points, label
    # a run none of whose beams meets a circle misfits every one (ARC_MISS): not asked
    h = points.heading.reshape(-1)[vi[pos]]
    _, th, meets = meet_circle(circles[:2, :, None], circles[2][:, None],
                               points.origin_x.reshape(-1)[vi[pos]],
                               points.origin_y.reshape(-1)[vi[pos]], np.cos(h), np.sin(h))
    asked = np.bincount(run[pos], (meets & (th <= cal.max_incidence_rad)).any(axis=0),
                        n_run) > 0
    pos = pos[asked[run[pos]]]
    if pos.size == 0:
        return points, label
    grp = (np.cumsum(asked) - 1)[run[pos]]
    n_g = int(grp[-1]) + 1
    s_vi = np.asarray(counts, dtype=float).reshape(-1)[vi]
    lite = SimpleNamespace(ox=points.origin_x.reshape(-1)[vi],
                           oy=points.origin_y.reshape(-1)[vi],
                           heading=points.heading.reshape(-1)[vi], s=s_vi, d0=d0,
                           sig_s=cal.sigma_counts() / s_vi)
    th, d, sig, mis, _ = _on_circles(lite, pos, grp, n_g, circles, cal)
    fits = np.bincount(grp, mis, n_g) <= ARC_MISFIT * np.bincount(grp, minlength=n_g)
    # … and whose θ = 0 end points bulge towards the sensor: a box's face beside a corner
    # taken for an arc fits such a circle within its noise too, but lies flat
    h = lite.heading[pos]
    fits &= _bulging(lite.ox[pos] + d0[pos] * np.cos(h), lite.oy[pos] + d0[pos] * np.sin(h),
                     lite.ox[pos], lite.oy[pos], grp, n_g)[0]
    take = (fits[grp] & (mis <= ARC_ON) & np.isfinite(d) & (d >= cal.min_range_m)
            & np.isfinite(sig))
    if not take.any():
        return points, label
    at = vi[pos[take]]
    label = label.copy()
    label.reshape(-1)[at] = -1
    return placed_at(points, at, d[take], th[take], sig[take]), label


COLUMN_RUN_MIN = 3       # a sensor's run of at least this many readings …
COLUMN_LINK_M = 0.06     # … whose θ = 0 end points come this near another sensor's run's …
COLUMN_LINE_SHARE = 0.5  # … (its line members: on lines at least this share of whose members
#                          it holds) …
COLUMN_RADII_M = np.geomspace(0.03, 0.2, 14)  # … is tried with them as one circle of these radii
COLUMN_MIN = 12          # … where they hold this many readings (a circle: three parameters) …
COLUMN_MAX = 48          # … up to this many (more: walls'; each is tried as the apex: cost)
COLUMN_REACH = 0.95      # … read at θ = 0 within this share of the max range (median) …
COLUMN_NOISE_M = 0.025   # … with range noise this small (median): within more, a corner fits


def columns_across_sensors(points: Points, label: np.ndarray, index: np.ndarray,
                           counts: np.ndarray, steps: np.ndarray, cal: Calibration,
                           line_alpha: np.ndarray, line_cx: np.ndarray, line_cy: np.ndarray,
                           placed: np.ndarray) -> tuple[Points, np.ndarray]:
    """Several sensors' runs of one round thing read on ONE circle fitted to them all; numpy,
    shared by both estimators. Where no sensor's own run holds the arc's apex
    (:func:`arc_incidence`), the flanks each sensor saw were read on lines across them (too
    steep: short) or at θ = 0 (σ wide).

    Runs as :func:`_runs_at_zero` cuts them, of at least ``COLUMN_RUN_MIN`` readings, none
    of them ``placed`` (flat indices: on an arc or circle already). A run whose θ = 0 end
    points bulge towards its sensor (:func:`_bulging`) is linked to every other sensor's run
    whose end points come within ``COLUMN_LINK_M`` of its own. A group of two sensors or
    more and ``COLUMN_MIN`` to ``COLUMN_MAX`` readings, read at θ = 0 within
    ``COLUMN_REACH`` of the max range and ``COLUMN_NOISE_M`` of range noise (medians), none
    of its runs hollow and none of its readings a member of a line holding less than
    ``COLUMN_LINE_SHARE`` of its members there (a wall's), is tried as one circle: its
    nearest point on one reading's beam at its θ = 0 distance, radius of
    ``COLUMN_RADII_M`` (refined by ``ARC_REFINE``), scored as :func:`_arc_misfit` scores an
    arc. Kept where each run misfits it at most ``ARC_MISFIT`` on average and, by BIC, no
    more than the readings' pieces (:func:`_round_wins`); its readings of own misfit at
    most ``ARC_ON`` leave their lines (label −1) at its θ, their own distance there and σ
    as on an arc. Returns the points and ``label``. Why: docs/estimator.md, "A column
    across sensors"."""
    flat_valid = points.valid.reshape(-1)
    vi = index[flat_valid[index]]
    vi = vi[~np.isin(vi, placed)]
    n_sensors = points.valid.shape[1]
    if vi.size < 2 * COLUMN_RUN_MIN or n_sensors < 2:
        return points, label
    d0, _, run, n_run, size = _runs_at_zero(vi, n_sensors, steps, counts, cal)
    long_run = size >= COLUMN_RUN_MIN
    pos = long_run[run].nonzero()[0]
    if pos.size < 2 * COLUMN_RUN_MIN:
        return points, label
    at = vi[pos]
    h = points.heading.reshape(-1)[at]
    ex, ey = np.cos(h), np.sin(h)
    ox, oy = points.origin_x.reshape(-1)[at], points.origin_y.reshape(-1)[at]
    px, py = ox + d0[pos] * ex, oy + d0[pos] * ey
    grp = (np.cumsum(long_run) - 1)[run[pos]]
    n_g = int(grp[-1]) + 1
    bulge, toward = _bulging(px, py, ox, oy, grp, n_g)
    hollow = (np.bincount(grp, toward < -ROUND_BULGE_M, n_g)
              > ROUND_BEHIND * np.bincount(grp, minlength=n_g))
    seed = bulge & ~hollow
    if not seed.any():
        return points, label
    # a bulging run linked to the other sensors' runs its end points come near: runs whose
    # boxes do, then their points (a few pairs; every point against every other cost more
    # than the rest of the estimate on a T-room sweep)
    sensor = at % n_sensors
    first = np.searchsorted(grp, np.arange(n_g))
    box = [f.reduceat(v, first) for f, v in ((np.minimum, px), (np.maximum, px),
                                            (np.minimum, py), (np.maximum, py))]
    run_sensor = sensor[first]
    gap = np.maximum(np.maximum(box[0][:, None] - box[1][None, :],
                                box[0][None, :] - box[1][:, None]),
                     np.maximum(box[2][:, None] - box[3][None, :],
                                box[2][None, :] - box[3][:, None]))
    # (a run of more readings than a group may hold is a wall's: not linked)
    small = np.diff(np.append(first, grp.size)) <= COLUMN_MAX - COLUMN_RUN_MIN
    gi, gj = ((gap <= COLUMN_LINK_M) & (seed & small)[:, None] & small[None, :]
              & (run_sensor[:, None] != run_sensor[None, :])).nonzero()
    last = np.append(first[1:], grp.size)

    def near(a, b):
        """Whether runs a and b come within the link (each one's points in the other's box
        grown by it: the others cannot)."""
        pa, pb = slice(first[a], last[a]), slice(first[b], last[b])
        xa, ya, xb, yb = px[pa], py[pa], px[pb], py[pb]
        ia = ((xa >= box[0][b] - COLUMN_LINK_M) & (xa <= box[1][b] + COLUMN_LINK_M)
              & (ya >= box[2][b] - COLUMN_LINK_M) & (ya <= box[3][b] + COLUMN_LINK_M))
        ib = ((xb >= box[0][a] - COLUMN_LINK_M) & (xb <= box[1][a] + COLUMN_LINK_M)
              & (yb >= box[2][a] - COLUMN_LINK_M) & (yb <= box[3][a] + COLUMN_LINK_M))
        return bool(ia.any() and ib.any() and np.hypot(
            xa[ia, None] - xb[None, ib], ya[ia, None] - yb[None, ib]).min() <= COLUMN_LINK_M)
    close = np.array([near(a, b) for a, b in zip(gi, gj)], dtype=bool)
    gi, gj = gi[close], gj[close]
    if gi.size == 0:
        return points, label
    comp = linked_components(n_g, gi, gj)
    linked = np.zeros(n_g, dtype=bool)
    linked[gi] = linked[gj] = True
    lab = label.reshape(-1)[at]
    all_lab = label.reshape(-1)[vi]
    members = np.bincount(all_lab[all_lab >= 0], minlength=int(lab.max(initial=-1)) + 1)
    _, b0 = cal._ab0
    s = np.asarray(counts, dtype=float).reshape(-1)[at]
    sig_s = cal.sigma_counts() / s
    noise = range_sigma(b0, d0[pos], sig_s)
    log_s = np.log(s)
    lite = SimpleNamespace(ox=ox, oy=oy, heading=h, s=s, d0=d0[pos], sig_s=sig_s)
    step = math.log(COLUMN_RADII_M[1] / COLUMN_RADII_M[0])
    take_at, take_th, take_d, take_sig = [], [], [], []
    for c in np.unique(comp[linked]):
        runs = (comp == c).nonzero()[0]
        if hollow[runs].any():
            continue
        j = np.isin(grp, runs).nonzero()[0]
        if (not COLUMN_MIN <= j.size <= COLUMN_MAX
                or np.median(d0[pos][j]) > COLUMN_REACH * points.max_range_m
                or np.median(noise[j]) > COLUMN_NOISE_M):
            continue
        # a line most of whose members lie elsewhere is a wall's, not this thing's chord
        lines = np.unique(lab[j][lab[j] >= 0])
        if lines.size and (np.bincount(lab[j][lab[j] >= 0], minlength=members.size)[lines]
                           < COLUMN_LINE_SHARE * members[lines]).any():
            continue
        # every reading as the apex, every radius; then the best one's radius refined
        k_apex = np.repeat(j, COLUMN_RADII_M.size)
        k_r = np.tile(COLUMN_RADII_M, j.size)
        mis = _column_misfit(k_apex, k_r, j, px, py, ex, ey, ox, oy, log_s, noise, cal)[0]
        best = int(np.argmin(mis.sum(axis=1)))
        k_r = k_r[best] * np.exp(step * ARC_REFINE)
        mis, th, d = _column_misfit(np.full(k_r.size, k_apex[best]), k_r, j, px, py, ex, ey,
                                    ox, oy, log_s, noise, cal)
        best = int(np.argmin(mis.sum(axis=1)))
        m, th, d = mis[best], th[best], d[best]
        g = np.searchsorted(runs, grp[j])
        if (np.bincount(g, m, runs.size)
                > ARC_MISFIT * np.bincount(g, minlength=runs.size)).any():
            continue
        if not _round_wins(lite, j, lab[j], np.zeros(j.size, dtype=np.intp), 1, m, 3,
                           line_alpha, line_cx, line_cy, cal)[0]:
            continue
        on = (m <= ARC_ON) & np.isfinite(d) & (d >= cal.min_range_m)
        lo = cal.distance(s[j[on]], np.maximum(th[on] - ARC_DOUBT_RAD, 0.0))
        hi = cal.distance(s[j[on]], np.minimum(th[on] + ARC_DOUBT_RAD, cal.max_incidence_rad))
        _, b_th = cal.log_ab(th[on])
        take_at.append(at[j[on]])
        take_th.append(th[on])
        take_d.append(d[on])
        take_sig.append(np.hypot(range_sigma(b_th, d[on], sig_s[j[on]]), 0.5 * np.abs(lo - hi)))
    if not take_at:
        return points, label
    at = np.concatenate(take_at)
    if at.size == 0:
        return points, label
    label = label.copy()
    label.reshape(-1)[at] = -1
    return placed_at(points, at, np.concatenate(take_d), np.concatenate(take_th),
                     np.concatenate(take_sig)), label


def linked_components(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n,) each of ``n`` items' component: the smallest index it is linked to, through the
    pairs (``a[k]``, ``b[k]``) and their chains."""
    comp = np.arange(n)
    while True:      # hook each link's larger label onto its smaller, then follow labels
        low = np.minimum(comp[a], comp[b])
        nxt = comp.copy()
        for end in (a, b, comp[a], comp[b]):
            np.minimum.at(nxt, end, low)
        while not np.array_equal(nxt[nxt], nxt):
            nxt = nxt[nxt]
        if np.array_equal(nxt, comp):
            return comp
        comp = nxt


def _column_misfit(apex, radius, j, px, py, ex, ey, ox, oy, log_s, noise, cal):
    """Misfit, θ and d (K, J) of readings ``j`` on the circles (K,) whose nearest point is
    reading ``apex``'s θ = 0 end point (``px``, ``py``), of ``radius``: as
    :func:`_arc_misfit` scores an arc's."""
    cx = (px[apex] + radius * ex[apex])[:, None]
    cy = (py[apex] + radius * ey[apex])[:, None]
    t, th, meets = meet_circle((cx, cy), radius[:, None], ox[j], oy[j], ex[j], ey[j])
    meets &= th <= cal.max_incidence_rad
    la, b = cal.log_ab(th)
    d = np.exp(la + b * log_s[j])
    z = (d - t) / noise[j]
    return np.where(meets, np.minimum(z * z, ARC_MISS), ARC_MISS), th, d
