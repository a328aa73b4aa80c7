"""A reading's θ only as far as its evidence bounds it.

A slope pinned at the drop-out angle is no θ (:func:`clamped_slopes`, called by
``local_incidence``); a line its counts contradict leaves its members no θ, but their own
profile may still bound it (:func:`kept_where_bounded`, called by ``counts_disown_lines``);
a line across a corner of two facets is snapped as two (:func:`split_facets`, called by
``final_estimate``). Numpy, shared by both estimators. Why and what they measured:
docs/estimator.md, "Bounded incidence".
"""
from __future__ import annotations

import numpy as np

from ..core import Points, Reason

CLAMP_SE = 2.0  # a clamped slope allows θ down to atan(|slope| − this many standard errors) …
CLAMP_TESTED = 4  # … where this many readings tested the profile's straightness (else to 0)


def clamped_slopes(cal, counts: np.ndarray, slope: np.ndarray, se: np.ndarray, n: np.ndarray,
                   unknown_m: float) -> np.ndarray:
    """Which readings (``counts``) whose own range profile is straight and sloped
    (``slope``, tan θ, its standard error ``se``, from ``n`` readings) may not take the θ it
    gives: where atan|slope| reaches the drop-out angle, the θ read is the clamp, not the
    surface's (a post's three readings, one surface's end and another's start), and the
    slope only bounds θ from below, at atan(|slope| − ``CLAMP_SE``·se), or at 0 where fewer
    than ``CLAMP_TESTED`` readings could show the profile bent; such a reading is placed
    only where that lower bound reads at most ``unknown_m`` longer than the clamp."""
    t = np.abs(slope)
    top = cal.max_incidence_rad
    pinned = np.arctan(t) >= top
    if not pinned.any():
        return pinned
    lo = np.where(n[pinned] >= CLAMP_TESTED,
                  np.arctan(np.maximum(t[pinned] - CLAMP_SE * se[pinned], 0.0)), 0.0)
    s = counts[pinned]
    d_lo, d_top = cal.distance(np.concatenate([s, s]),
                               np.concatenate([lo, np.full(s.size, top)])).reshape(2, -1)
    out = np.zeros(t.size, dtype=bool)
    out[pinned] = ~(d_lo - d_top <= unknown_m)
    return out


def kept_where_bounded(points: Points, vi: np.ndarray, pos: np.ndarray, pr, cal,
                       unknown_m: float, floor_m: float):
    """(flat indices, d, σ) of the members ``vi[pos]`` of lines their counts contradict
    that leaving made INCIDENCE_UNKNOWN, to be placed again at θ = 0 where their own profile (``pr``, profiled over
    ``pos``) bounds θ (its ``steep``; a bent one, only the drop-out angle) and θ = 0 reads
    at most ``unknown_m`` longer than that bound: σ their noise at θ = 0 (at least
    ``floor_m``) and half that span, as a reading on no line whose θ nothing decides
    (``local_incidence``). A line across facets
    square on (one sensor turning in a many-sided room) is contradicted, and its members,
    met at 0–30°, need no line to be placed within their noise."""
    at = vi[pos]
    lost = points.reason.reshape(-1)[at] == Reason.INCIDENCE_UNKNOWN
    if not lost.any():
        return None
    at, s = at[lost], pr.s[pos[lost]]
    # a bent profile (a convex corner's tip, a post) bounds θ by nothing but the drop-out
    steep = np.where(pr.convex[lost] | pr.concave[lost], cal.max_incidence_rad,
                     pr.steep[lost])
    d0, d_steep = cal.distance(np.concatenate([s, s]),
                               np.concatenate([np.zeros(s.size), steep])).reshape(2, -1)
    span = d0 - d_steep
    keep = np.isfinite(span) & (span <= unknown_m) & (d0 >= cal.min_range_m) & (
        d0 <= points.max_range_m)
    if not keep.any():
        return None
    at, d0, span = at[keep], d0[keep], span[keep]
    _, b0 = cal._ab0
    sigma = np.hypot(np.maximum(np.abs(b0) * d0 * pr.sig_s[pos[lost][keep]], floor_m),
                     0.5 * span)
    return at, d0, sigma


SPLIT_MIN = 15      # a line is split only into pieces of at least this many valid members …
SPLIT_F = 12.0      # … where two lines explain them better by this F (2 and n − 4 dof) …
SPLIT_TURN_MIN = np.radians(5)  # … whose directions differ by at least this (a corner) …
REREAD_TURN_MAX = np.radians(15)  # a piece turned more from its line keeps the line's θ
SPLIT_ROUNDS = 3    # … in at most this many rounds (a wall of several facets)


def _weighted_scatter(x, y, w, group, n):
    """Per group: summed weight, and the weighted TLS residual (weight × the scatter
    matrix's smaller eigenvalue) of the points, with its direction (rad)."""
    sw = np.bincount(group, w, n)
    safe = np.maximum(sw, 1e-300)
    mx, my = np.bincount(group, w * x, n) / safe, np.bincount(group, w * y, n) / safe
    u, v = x - mx[group], y - my[group]
    cxx = np.bincount(group, w * u * u, n)
    cyy = np.bincount(group, w * v * v, n)
    cxy = np.bincount(group, w * u * v, n)
    lam = 0.5 * (cxx + cyy) - np.hypot(0.5 * (cxx - cyy), cxy)
    return np.maximum(lam, 0.0), 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)


def _best_splits(x, y, w, line, n_lines):
    """For each line (members sorted along it): the weighted TLS χ² of one line, the least
    of two lines (a prefix and the rest, each ≥ ``SPLIT_MIN``), where that split lies (its
    second piece's first member among the lines' members in ``order``; −1 none), ``order``
    (the members of lines long enough to split, sorted by line and along it), the lines'
    member counts and the angle between the two pieces (rad)."""
    chi1, alpha = _weighted_scatter(x, y, w, line, n_lines)
    count = np.bincount(line, minlength=n_lines)
    best, at, turn = np.full(n_lines, np.inf), np.full(n_lines, -1), np.zeros(n_lines)
    long_enough = (count >= 2 * SPLIT_MIN)[line]
    if not long_enough.any():
        return chi1, best, at, np.zeros(0, np.intp), count, turn
    sub = long_enough.nonzero()[0]
    t = x[sub] * np.cos(alpha[line[sub]]) + y[sub] * np.sin(alpha[line[sub]])
    order = sub[np.lexsort((t, line[sub]))]
    xs, ys, ws, ls = x[order], y[order], w[order], line[order]
    # prefix sums of the weighted moments about each line's centroid (less cancellation)
    sw = np.bincount(ls, ws, n_lines)
    u = xs - (np.bincount(ls, ws * xs, n_lines) / np.maximum(sw, 1e-300))[ls]
    v = ys - (np.bincount(ls, ws * ys, n_lines) / np.maximum(sw, 1e-300))[ls]
    cum = np.cumsum(np.stack([ws, ws * u, ws * v, ws * u * u, ws * v * v, ws * u * v]), axis=1)
    first = np.searchsorted(ls, np.arange(n_lines))
    last = np.searchsorted(ls, np.arange(n_lines), side="right") - 1
    base = np.where(first > 0, cum[:, np.maximum(first - 1, 0)], 0.0)
    total = cum[:, np.maximum(last, 0)] - base
    pos = np.arange(ls.size) - first[ls] + 1      # members in the prefix
    idx = ((pos >= SPLIT_MIN) & (count[ls] - pos >= SPLIT_MIN)).nonzero()[0]
    if idx.size == 0:
        return chi1, best, at, order, count, turn
    li = ls[idx]
    left = cum[:, idx] - base[:, li]              # members up to and including idx
    right = total[:, li] - left

    def scatter(m):     # each prefix's or rest's weighted scatter (cxx, cyy, cxy)
        s = np.maximum(m[0], 1e-300)
        return m[3] - m[1] * m[1] / s, m[4] - m[2] * m[2] / s, m[5] - m[1] * m[2] / s

    def chi(c):
        return np.maximum(0.5 * (c[0] + c[1]) - np.hypot(0.5 * (c[0] - c[1]), c[2]), 0.0)

    cl, cr = scatter(left), scatter(right)
    chi2 = chi(cl) + chi(cr)
    starts = np.flatnonzero(np.concatenate(([True], li[1:] != li[:-1])))
    best[li[starts]] = np.minimum.reduceat(chi2, starts)
    hit = chi2 == best[li]
    # the split's second piece starts after the prefix; the pieces' directions' difference
    at[li[hit]] = idx[hit] + 1
    a_l = 0.5 * np.arctan2(2.0 * cl[2][hit], cl[0][hit] - cl[1][hit])
    a_r = 0.5 * np.arctan2(2.0 * cr[2][hit], cr[0][hit] - cr[1][hit])
    turn[li[hit]] = np.abs(np.angle(np.exp(2j * (a_l - a_r)))) / 2
    return chi1, best, at, order, count, turn


def split_facets(points: Points, label: np.ndarray) -> np.ndarray:
    """The lines to snap onto (:func:`snap_to_lines`): each line whose members two lines
    explain clearly better than one (F ≥ ``SPLIT_F`` on 2 and n − 4 degrees of freedom,
    each piece ≥ ``SPLIT_MIN`` valid members in order along the line, the members' σ
    across it as weights, the pieces turned ≥ ``SPLIT_TURN_MIN``: a corner) cut in two,
    in up to ``SPLIT_ROUNDS`` rounds, the second pieces numbered after the last line. θ
    stays the line's (docs/estimator.md, "Bounded incidence", says why). ``label`` (S, N)
    is not changed: the grouping's lines do not know the pieces."""
    flat = label.reshape(-1)
    at = ((flat >= 0) & points.valid.reshape(-1)).nonzero()[0]
    if at.size < 2 * SPLIT_MIN:
        return label
    new = flat.copy()
    n_lines = int(flat.max()) + 1
    x, y = points.x.reshape(-1)[at], points.y.reshape(-1)[at]
    w = 1.0 / np.maximum(points.sigma_m.reshape(-1)[at]
                         * np.cos(points.theta.reshape(-1)[at]), 1e-4) ** 2
    cuts = 0
    for _ in range(SPLIT_ROUNDS):
        line = new[at]
        chi1, chi2, start, order, count, turn = _best_splits(x, y, w, line, n_lines)
        tried = (start >= 0) & np.isfinite(chi2) & (turn >= SPLIT_TURN_MIN)
        f = np.zeros(n_lines)
        f[tried] = ((chi1[tried] - chi2[tried]) / 2.0
                    / np.maximum(chi2[tried] / np.maximum(count[tried] - 4, 1), 1e-12))
        cut = tried & (f >= SPLIT_F)
        if not cut.any():
            break
        # the members from each cut line's split on take a new line number
        ls = line[order]
        second = cut[ls] & (np.arange(ls.size) >= start[ls])
        ids = np.full(n_lines, -1)
        ids[cut] = n_lines + np.arange(np.count_nonzero(cut))
        new[at[order[second]]] = ids[ls[second]]
        n_lines += int(np.count_nonzero(cut))
        cuts += int(np.count_nonzero(cut))
    return new.reshape(label.shape) if cuts else label


def reread_pieces(points: Points, label: np.ndarray, pieces: np.ndarray, counts: np.ndarray,
                  cal):
    """(flat indices, d, θ) of the members of lines :func:`split_facets` cut (``pieces``
    its labels, ``label`` the lines as they were) re-read once at their piece's direction, where
    that turned at most ``REREAD_TURN_MAX`` from the line's: one step of Table II from the
    line's θ (docs/estimator.md, "Bounded incidence")."""
    flat, new = label.reshape(-1), pieces.reshape(-1)
    cut = np.unique(flat[(new != flat) & (new >= 0)])
    at = (np.isin(flat, cut) & points.valid.reshape(-1)).nonzero()[0]
    if at.size == 0:
        return None
    g, parent = new[at], flat[at]
    n = int(g.max()) + 1
    x, y = points.x.reshape(-1)[at], points.y.reshape(-1)[at]
    _, alpha = _weighted_scatter(x, y, np.ones(at.size), g, n)
    _, alpha0 = _weighted_scatter(x, y, np.ones(at.size), parent, int(parent.max()) + 1)
    heading = points.heading.reshape(-1)[at]
    th = np.arccos(np.clip(np.abs(np.sin(heading - alpha[g])), 0.0, 1.0))
    d = cal.distance(counts.reshape(-1)[at], th)
    # a piece turned far from its line (one sensor's few far readings) is not trusted for θ
    turn = np.abs(np.angle(np.exp(2j * (alpha[g] - alpha0[parent])))) / 2
    ok = np.isfinite(d) & (th < cal.max_incidence_rad) & (turn <= REREAD_TURN_MAX)
    return at[ok], d[ok], th[ok]
