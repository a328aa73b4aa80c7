"""The estimator's oracle: the whole algorithm of :mod:`irring.estimation.estimate` in plain
numpy, the readable statement its compiled kernels are held to (tests/test_estimate_oracle.py).
An algorithm change goes here first; it is not for speed. The schedule: docs/estimator.md.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np

from ..core import Points, Reason, Sweep, beam_geometry
from .calibration import RANGE_SIGMAS, RETURN_SIGMAS, Calibration, range_sigma
from .estimate import (CORNER_WINDOW, MAX_GAIN, REGROUP_WINDOW, SIGMA_FLOOR_M, check_work,
                       final_estimate, full_turn, nominal_calibration, settled_within_noise)
from .arcs import linked_components, round_runs
from .bends import bent_ends, bowed_lines, faceted_lines
from .counts import CountsFits, counts_contradicted
from .far_lines import (POST_CELL_REACH, POST_LINK_M, POST_RUN_MAX, POST_SENSORS, post_cells,
                        short_far_lines)
from .foldover import resolve_foldover
from .lines import (PINNED_RAD, SNAP_MIN, SNAP_OWN, SNAP_SIGMAS, Estimate, LineOptions, Lines,
                    Pieces, fallback_spread, polyline_ids, scan_order)
from .members import alone_at_an_edge, past_members, silent_gaps
from .profiles import range_profiles
from .silence import (REACH_CLEAR_M, REACH_MIN_MEMBERS, beam_crossings, beside_a_return,
                      clip_at_corners, end_hide_angle, held_and_pooled, member_spans,
                      nearest_heard_rows, reach_cos_limit, unconfirmed_near)
from .traces import TraceSteps

_WINDOW = np.arange(-5, 6)   # corner refinement: readings tried either side of a corner


def _tls(n, t):
    """Total-least-squares lines from summed centred moments t = (Σx, Σy, Σx², Σy², Σxy)
    over n points (arrays): mean offset (mx, my), direction angle α ∈ (−π/2, π/2] (exact for
    vertical lines), λ_min, λ_max (variances across / along the line)."""
    inv = 1.0 / np.maximum(n, 1)
    mx = t[0] * inv
    my = t[1] * inv
    cxx = t[2] * inv
    cxx -= mx * mx
    np.maximum(cxx, 0.0, out=cxx)
    cyy = t[3] * inv
    cyy -= my * my
    np.maximum(cyy, 0.0, out=cyy)
    cxy2 = t[4] * inv
    cxy2 -= mx * my
    cxy2 *= 2.0
    dif = cxx - cyy
    root = np.hypot(dif, cxy2)
    root *= 0.5
    mean = cxx + cyy
    mean *= 0.5
    alpha = np.arctan2(cxy2, dif)
    alpha *= 0.5
    lmin = mean - root
    np.maximum(lmin, 0.0, out=lmin)
    mean += root
    return mx, my, alpha, lmin, mean


def _tls_angle(n, t):
    """(mx, my, α) of :func:`_tls` only."""
    mx = t[0] / n
    my = t[1] / n
    sxy = t[4] - t[0] * my
    dif = (t[2] - t[0] * mx) - (t[3] - t[1] * my)
    alpha = np.arctan2(sxy + sxy, dif)
    alpha *= 0.5
    return mx, my, alpha


def _rss(n, t):
    """Summed squared perpendicular residuals of each range's TLS line (for comparisons)."""
    sx, sy, sxx, syy, sxy = t
    inv = 1.0 / n
    cxx = sxx - sx * sx * inv
    cyy = syy - sy * sy * inv
    cxy = sxy - sx * sy * inv
    cxy += cxy
    out = cxx + cyy
    out -= np.hypot(cxx - cyy, cxy)
    return out


class _Moments:
    """Prefix sums of x, y, x², y², xy over an ordered point sequence: any contiguous range's
    TLS line in O(1). Coordinates are centred on (cx, cy) so small spreads keep their digits.
    (Residual sums from :func:`_rss` come out doubled; only their order matters.)"""

    __slots__ = ("cum", "cx", "cy")

    def __init__(self, px: np.ndarray, py: np.ndarray, cx: float, cy: float):
        self.cx, self.cy = cx, cy
        cum = np.zeros((5, px.size + 1))
        m = cum[:, 1:]
        np.subtract(px, cx, out=m[0])
        np.subtract(py, cy, out=m[1])
        np.multiply(m[0], m[0], out=m[2])
        np.multiply(m[1], m[1], out=m[3])
        np.multiply(m[0], m[1], out=m[4])
        m.cumsum(axis=1, out=m)
        self.cum = cum

    def sums(self, lo: np.ndarray, hi: np.ndarray):
        """(n, t) over the inclusive ranges [lo, hi]."""
        c = self.cum
        n = (hi - lo).astype(float)
        n += 1.0
        t = c.take(hi + 1, axis=1)
        t -= c.take(lo, axis=1)
        return n, t


def _owner(starts: np.ndarray, k: int) -> np.ndarray:
    """Piece of each of k points: the last piece starting at or before it (so a corner
    shared by two pieces goes to the right one). ``starts`` ascending, the first 0."""
    mark = np.zeros(k, dtype=np.intp)
    mark[starts[1:]] = 1
    return mark.cumsum()


def _lengths(first: np.ndarray, total: int) -> np.ndarray:
    """Lengths of the runs starting at ``first`` (ascending) in a sequence of ``total``."""
    n = np.empty(first.size)
    if first.size == 0:
        return n
    np.subtract(first[1:], first[:-1], out=n[:-1])
    n[-1] = total - first[-1]
    return n


def _split(px, py, inv_thr, starts, ends):
    """Iterative end-point fit on every piece at once: a piece splits at the reading farthest
    from its chord while that lies more than the threshold off. Pieces share their corner."""
    k = px.size
    while True:
        o = _owner(starts, k)
        ax, ay = px.take(starts), py.take(starts)
        dx = px.take(ends)
        dx -= ax
        dy = py.take(ends)
        dy -= ay
        chord = np.hypot(dx, dy)
        closed = chord < 1e-12
        any_closed = closed.any()
        if any_closed:  # a piece whose ends meet: distance from its end point instead
            closed &= ends - starts >= 2
            any_closed = closed.any()
            chord[closed] = 1.0
            dx[closed] = dy[closed] = 0.0
            np.maximum(chord, 1e-300, out=chord)
        dx /= chord
        dy /= chord
        c0 = dx * ay
        c0 -= dy * ax
        dist = dx.take(o) * py
        dist -= dy.take(o) * px
        dist -= c0.take(o)
        np.abs(dist, out=dist)
        if any_closed:
            far = closed.take(o)
            dist[far] = np.hypot(px[far] - ax.take(o[far]), py[far] - ay.take(o[far]))
        dist *= inv_thr
        dist[starts] = 0.0
        dist[ends] = 0.0
        best = np.maximum.reduceat(dist, starts)
        split = best > 1.0
        if not split.any():
            return starts, ends
        hit = ((dist == best.take(o)) & split.take(o)).nonzero()[0]
        ho = o.take(hit)
        first = np.ones(hit.size, dtype=bool)
        np.not_equal(ho[1:], ho[:-1], out=first[1:])
        at = hit[first]
        starts = np.concatenate([starts, at])
        starts.sort()
        ends = np.concatenate([ends, at])
        ends.sort()


def _refine_corners(mom: _Moments, starts, ends, rounds: int = 2):
    """Move each corner shared by two pieces to where the two TLS lines fit best.

    The end-point fit splits at the reading farthest from the chord, which for a corner near
    the end of a polyline, or seen at a slant, is a few readings off the true corner. Each
    shared corner is tried at up to 5 readings either side (keeping ≥ 2 readings per piece)
    and put where the summed squared perpendicular residuals of the two pieces are least;
    all corners at once, from prefix sums. Two corners moving towards each other must leave
    ≥ 2 readings between them, else both stay.
    """
    cum = mom.cum
    for _ in range(rounds):
        j = (starts[1:] == ends[:-1]).nonzero()[0]       # piece j and j + 1 share a corner
        if j.size == 0:
            break
        lo, v, hi = starts.take(j), ends.take(j), ends.take(j + 1)
        c = v[:, None] + _WINDOW
        bad = (c <= lo[:, None]) | (c >= hi[:, None])
        c[bad] = np.broadcast_to(v[:, None], c.shape)[bad]
        # prefix sums at each candidate: left piece [lo, c], right piece [c, hi]
        at_c1 = cum.take(c + 1, axis=1)                           # (5, P, w)
        left = at_c1 - cum.take(lo, axis=1)[:, :, None]
        right = cum.take(hi + 1, axis=1)[:, :, None] - cum.take(c, axis=1)
        cost = _rss((c - lo[:, None] + 1).astype(float), left)
        cost += _rss((hi[:, None] - c + 1).astype(float), right)
        cost[bad] = np.inf
        best = c[np.arange(j.size), cost.argmin(axis=1)]
        if (best == v).all():
            break
        new_ends, new_starts = ends.copy(), starts.copy()
        new_ends[j] = best
        new_starts[j + 1] = best
        short = (new_ends - new_starts < 1) & (ends - starts >= 1)
        if short.any():
            best = np.where(short.take(j) | short.take(j + 1), v, best)
            new_ends[j] = best
            new_starts[j + 1] = best
        starts, ends = new_starts, new_ends
    return starts, ends


def _merge(mom: _Moments, px, py, inv_thr, starts, ends):
    """Merge adjacent pieces (sharing a corner) whose joint TLS line fits every reading
    within its threshold; cheapest joins first, non-overlapping joins per round."""
    k = px.size
    for _ in range(starts.size):
        j = (starts[1:] == ends[:-1]).nonzero()[0]  # piece j with piece j+1
        if j.size == 0:
            break
        m = j.size
        mx, my, alpha = _tls_angle(*mom.sums(starts.take(j), ends.take(j + 1)))
        # the joint line of each candidate pair, plus a null line (residual 0) at index m
        line = np.zeros((3, m + 1))
        nx, ny, c0 = line
        np.sin(alpha, out=nx[:m])
        np.negative(nx[:m], out=nx[:m])
        np.cos(alpha, out=ny[:m])
        mx += mom.cx
        my += mom.cy
        np.multiply(nx[:m], mx, out=c0[:m])
        c0[:m] += ny[:m] * my
        pair_of = np.full(starts.size + 1, m)
        pair_of[j] = np.arange(m)
        o = _owner(starts, k)
        # each reading against the joint line of the pair where its piece is the left one,
        # then of the pair where it is the right one
        both = pair_of.take(np.stack([o, o - 1]))                          # (2, k)
        nl = line.take(both, axis=1)                                        # (3, 2, k)
        r = nl[0] * px
        r += nl[1] * py
        r -= nl[2]
        np.abs(r, out=r)
        r *= inv_thr
        w = np.maximum.reduceat(r, starts, axis=1)
        worst = np.maximum(w[0].take(j), w[1].take(j + 1))
        ok = worst <= 1.0
        if not ok.any():
            break
        # choose joins that are the cheapest among their neighbours (so none overlap)
        cost = worst
        cost[~ok] = np.inf
        adj = j[1:] == j[:-1] + 1
        pick = ok.copy()
        pick[1:] &= ~(adj & (cost[:-1] <= cost[1:]))
        pick[:-1] &= ~(adj & (cost[1:] < cost[:-1]))
        jj = j[pick]
        keep = np.ones(starts.size, dtype=bool)
        keep[jj + 1] = False
        ends = ends.copy()
        ends[jj] = ends[jj + 1]
        starts, ends = starts[keep], ends[keep]
    return starts, ends


def _segment(px, py, thr, sensor, opts: LineOptions, centre, prev: Pieces | None = None
             ) -> Pieces:
    """Split-and-merge over ordered points (one sensor's readings by step form polylines,
    broken where consecutive readings are more than ``gap_m`` apart), corners refined.

    With ``prev`` from the same polylines (a regroup once θ has straightened the points)
    its pieces are kept and only their corners are refined: splitting anew would mostly
    repeat them, and the pieces of the first grouping are the better start (measured on the
    T-room: regrouping by corner refinement alone gives the smaller range error)."""
    k = px.size
    brk = np.ones(k, dtype=bool)
    if k > 1:
        dx, dy = px[1:] - px[:-1], py[1:] - py[:-1]
        np.greater(dx * dx + dy * dy, opts.gap_m ** 2, out=brk[1:])
        brk[1:] |= sensor[1:] != sensor[:-1]
    mom = _Moments(px, py, *centre)
    if prev is not None and prev.brk.size == k and (prev.brk == brk).all():
        starts, ends = _refine_corners(mom, prev.starts, prev.ends)
    else:
        inv_thr = 1.0 / thr
        first = brk.nonzero()[0]
        last = np.empty_like(first)
        last[:-1] = first[1:] - 1
        last[-1] = k - 1
        starts, ends = _split(px, py, inv_thr, first, last)
        starts, ends = _merge(mom, px, py, inv_thr, starts, ends)
        if prev is not None and prev.brk.size == k:
            starts, ends = _keep_unchanged(prev, brk, starts, ends)
        starts, ends = _refine_corners(mom, starts, ends)
    return _piece_lines(mom, px, py, thr, starts, ends, brk, opts)


def _keep_unchanged(prev: Pieces, brk, starts, ends):
    """The pieces of polylines that are the same as in ``prev`` (same first and last point)
    from ``prev``, the fresh ``starts``/``ends`` elsewhere: a range jump found at a regroup
    re-splits only the polylines it cuts (split anew at half-settled θ, the others lost
    corners a held-out room's first grouping had found)."""
    k = brk.size
    first = brk.nonzero()[0]
    stop = np.append(first[1:], k)
    pfirst = prev.brk.nonzero()[0]
    pstop = np.append(pfirst[1:], k)
    at = np.minimum(np.searchsorted(pfirst, first), pfirst.size - 1)
    same = (pfirst.take(at) == first) & (pstop.take(at) == stop)
    line = np.cumsum(brk) - 1                     # polyline of each point
    keep_prev = same.take(line.take(prev.starts))
    keep_new = ~same.take(line.take(starts))
    s = np.concatenate([prev.starts[keep_prev], starts[keep_new]])
    e = np.concatenate([prev.ends[keep_prev], ends[keep_new]])
    order = np.argsort(s, kind="stable")
    return s.take(order), e.take(order)


def _piece_lines(mom: _Moments, px, py, thr, starts, ends, brk, opts: LineOptions) -> Pieces:
    """Each piece's TLS line, who owns the corners, and which lines are good enough."""
    mx, my, alpha, lmin, lmax = _tls(*mom.sums(starts, ends))
    cx, cy = mx + mom.cx, my + mom.cy
    nx, ny = -np.sin(alpha), np.cos(alpha)
    o = _owner(starts, px.size)
    # a corner shared with the previous piece joins the nearer line
    j = (starts[1:] == ends[:-1]).nonzero()[0]
    if j.size:
        at = starts.take(j + 1)
        x, y = px.take(at), py.take(at)
        r_own = np.abs((x - cx.take(j + 1)) * nx.take(j + 1) + (y - cy.take(j + 1)) * ny.take(j + 1))
        r_alt = np.abs((x - cx.take(j)) * nx.take(j) + (y - cy.take(j)) * ny.take(j))
        nearer = r_alt < r_own
        o[at[nearer]] = j[nearer]
    ext = np.abs((px.take(ends) - px.take(starts)) * ny + (py.take(ends) - py.take(starts)) * -nx)
    n_pts = np.bincount(o, minlength=starts.size)
    mean_sig = np.bincount(o, weights=thr, minlength=starts.size) / (
        opts.split_sigmas * np.maximum(n_pts, 1))
    usable = ((n_pts >= opts.min_points) & (ext >= opts.min_length_m) & (lmax > 0)
              & (np.sqrt(lmin) <= opts.max_rms_sigmas * np.maximum(mean_sig, 1e-6))
              & np.isfinite(alpha))
    alpha[alpha < 0] += math.pi
    return Pieces(starts=starts, ends=ends, brk=brk, owner=o, cx=cx, cy=cy, alpha=alpha,
                   lmin=lmin, lmax=lmax, n_points=n_pts, length_m=ext, usable=usable)


def classify(counts: np.ndarray, sweep: Sweep, cal: Calibration) -> np.ndarray:
    """Reasons decided by the counts alone (before any distance is computed). Assigned from
    the weakest claim up, so MISSING > SATURATED > FOLDOVER_AMBIGUOUS > NO_RETURN."""
    full, near, no_return, _, falling = cal._levels
    s = counts
    reason = np.zeros(s.shape, dtype=np.uint8)
    margin = cal.no_return_margin_counts
    if falling:
        reason[s <= no_return + cal.return_margin_counts] = Reason.OUT_OF_RANGE   # too weak
        reason[(s <= no_return + margin) | (s <= 0)] = Reason.NO_RETURN
        reason[s > near] = Reason.FOLDOVER_AMBIGUOUS
    else:  # a linear sensor (sonar/laser hooks): no fold-over, no return reads as max range
        reason[(s >= no_return - margin) | (s <= 0)] = Reason.NO_RETURN
    reason[s >= full - 0.5] = Reason.SATURATED
    reason[~np.isfinite(s)] = Reason.MISSING
    if sweep.missing_steps:
        rows = np.isin(np.asarray(sweep.steps), np.asarray(sweep.missing_steps))
        reason[rows, :] = Reason.MISSING
    # below the datasheet's range, a reading no neighbouring step confirms
    alone = unconfirmed_near(counts, reason, sweep.steps, cal)
    if alone is not None:
        reason[alone] = Reason.FOLDOVER_AMBIGUOUS
    return reason



def _incidence(hm: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Angle between beams (heading mod π) and the normals of lines at direction angle α
    (in [0, π)): with δ = h − α, cos θ = |sin δ|, so θ = |π/2 − |δ||."""
    return np.abs(_HALF_PI - np.abs(hm - alpha))


_HALF_PI = math.pi / 2
_INV_PI = 1.0 / math.pi


class _Sweep:
    """One sweep's live readings in scan order (sensor by sensor, by step), and the
    calibration's curve, for the loop: everything per reading that θ does not change."""

    def __init__(self, cal: Calibration, counts, origin, heading, live, steps, opts):
        n_sensors = counts.shape[1]
        scan = scan_order(steps, n_sensors)
        pos = live.reshape(-1).take(scan).nonzero()[0]      # places in the scan order
        self.index = sel = scan.take(pos)                     # flat (S, N) index of each
        self.k = sel.size
        self.sensor = sel % n_sensors
        # runs for the corner check break at a sensor change or a reading that is not live
        self.run_brk = np.ones(self.k, dtype=bool)
        if self.k > 1:
            self.run_brk[1:] = (self.sensor[1:] != self.sensor[:-1]) | (pos[1:] != pos[:-1] + 1)
        self.counts = counts.reshape(-1).take(sel)
        self.log_s = np.log(self.counts)
        self.ox = origin[..., 0].reshape(-1).take(sel)
        self.oy = origin[..., 1].reshape(-1).take(sel)
        self.h = h = heading.reshape(-1).take(sel)
        self.ux, self.uy = np.cos(h), np.sin(h)
        self.hm = h - math.pi * np.floor(h / math.pi)         # heading mod π
        self.centre = ((float(self.ox.sum()) / self.k, float(self.oy.sum()) / self.k) if self.k
                       else (0.0, 0.0))
        self.at = np.arange(self.k)
        self.cal = cal
        self.sig_s = cal.sigma_counts() / self.counts          # σ_d = |b|·d·σ_S/S
        self.inv_h, table, _ = cal._fine
        self.la_t, self.b_t = table[:, 0].copy(), table[:, 1].copy()
        self.opts = opts
        self.cap = cal.max_incidence_rad
        self.reject = self.cap + opts.incidence_margin_rad

    def ab(self, theta: np.ndarray):
        """log a(θ), b(θ) from the fine table (θ in [0, π/2])."""
        i = (theta * self.inv_h + 0.5).astype(np.intp)
        return self.la_t.take(i), self.b_t.take(i)

    def points(self, theta: np.ndarray):
        """d, x, y, σ of every live reading at incidence θ."""
        la, b = self.ab(theta)
        d = np.exp(la + b * self.log_s)
        sigma = range_sigma(b, d, self.sig_s)
        return d, self.ox + d * self.ux, self.oy + d * self.uy, sigma

    def thresholds(self, sigma: np.ndarray) -> np.ndarray:
        return np.maximum(self.opts.min_split_m, self.opts.split_sigmas * sigma)


class _Grouping:
    """The lines of the current iteration and which reading takes θ from which line."""

    def __init__(self, sw: _Sweep, pieces: Pieces, uidx: np.ndarray | None):
        self.sw = sw
        self.pieces = pieces
        self.uidx = uidx                 # compact index of each usable point (None: all)
        self.cx, self.cy = pieces.cx.copy(), pieces.cy.copy()
        self.alpha = pieces.alpha.copy()
        self.usable = pieces.usable.copy()
        self.first = pieces.starts if uidx is None else uidx.take(pieces.starts)
        self.last = pieces.ends if uidx is None else uidx.take(pieces.ends)
        self.n_lines = pieces.starts.size
        self.label = np.full(sw.k, -1, dtype=np.intp)   # line of each live reading
        self._tab = None

    # ---- membership

    def members(self, px, py, thr) -> None:
        """Each reading keeps its own usable line only if it sits on it (within the split
        threshold; the last readings past a corner often do not)."""
        own = self.pieces.owner
        a = self.alpha.take(own)
        if self.uidx is None:
            x, y, t = px, py, thr
        else:
            x, y, t = px.take(self.uidx), py.take(self.uidx), thr.take(self.uidx)
        r = np.abs((y - self.cy.take(own)) * np.cos(a) - (x - self.cx.take(own)) * np.sin(a))
        ok = (r <= t) & self.usable.take(own)
        lab = np.where(ok, own, -1)
        if self.uidx is None:
            self.label = lab
        else:
            self.label = np.full(self.sw.k, -1, dtype=np.intp)
            self.label[self.uidx] = lab

    def table(self, px, py):
        """The usable lines for re-reading: (indices, α, centroid x, y, direction x, y,
        extent along the line from its end readings ± adopt_margin_m, column of each line)."""
        if self._tab is None:
            use = self.usable.nonzero()[0]
            a, cx, cy = self.alpha.take(use), self.cx.take(use), self.cy.take(use)
            dx, dy = np.cos(a), np.sin(a)
            f, l = self.first.take(use), self.last.take(use)
            t0 = (px.take(f) - cx) * dx + (py.take(f) - cy) * dy
            t1 = (px.take(l) - cx) * dx + (py.take(l) - cy) * dy
            m = self.sw.opts.adopt_margin_m
            col = np.full(self.n_lines + 1, -1)
            col[use] = np.arange(use.size)
            self._tab = (use, a, cx, cy, dx, dy, np.minimum(t0, t1) - m, np.maximum(t0, t1) + m,
                         col)
        return self._tab

    def fit_to(self, idx, px, py, own=None):
        """Readings ``idx`` against every usable line, each re-read with that line's θ:
        (line indices (L,), |perpendicular residual| (U, L)). A line counts only if the
        reading lands within ``adopt_margin_m`` of its extent (its own line, ``own``, always
        counts) and the beam meets it no steeper than the rejection angle; else inf."""
        sw = self.sw
        use, a, cx, cy, dx, dy, lo, hi, col = self.table(px, py)
        th = _incidence(sw.hm.take(idx)[:, None], a)                      # (U, L)
        la, b = sw.ab(np.minimum(th, sw.cap))
        d = np.exp(la + b * sw.log_s.take(idx)[:, None])
        qx = d * sw.ux.take(idx)[:, None]
        qx += sw.ox.take(idx)[:, None] - cx
        qy = d * sw.uy.take(idx)[:, None]
        qy += sw.oy.take(idx)[:, None] - cy
        r = np.abs(qy * dx - qx * dy)
        t = qx * dx + qy * dy
        far = (t < lo) | (t > hi)
        if own is not None:
            far[np.arange(idx.size), col.take(own)] = False
        far |= th > sw.reject
        r[far] = np.inf
        return use, r

    def settle_corners(self, px, py, sigma, thr) -> None:
        """Readings at the ends of their run go to whichever line explains them best.

        Near a corner both walls' lines pass close to the first readings past it, and a
        reading read with the wrong wall's θ can land on that wall's extension (a
        self-consistent but wrong answer). Each reading within ``corner_window`` readings of
        either end of its run (same line, same sensor, consecutive in the scan) is re-read
        with every usable line's θ (see :meth:`fit_to`) and put on the line it then lies
        closest to, if that is clearly better than its own.
        """
        sw = self.sw
        k = sw.k
        if k == 0 or not self.usable.any():
            return
        seq = self.label
        at = sw.at
        new_run = sw.run_brk.copy()
        new_run[1:] |= seq[1:] != seq[:-1]
        run_start = np.maximum.accumulate(np.where(new_run, at, 0))
        end_run = np.ones(k, dtype=bool)
        end_run[:-1] = new_run[1:]
        run_end = np.minimum.accumulate(np.where(end_run, at, k - 1)[::-1])[::-1]
        edge = (np.minimum(at - run_start, run_end - at) < sw.opts.corner_window) & (seq >= 0)
        idx = edge.nonzero()[0]
        if idx.size == 0:
            return
        own = seq.take(idx)
        use, r = self.fit_to(idx, px, py, own=own)
        rows = np.arange(idx.size)
        best = r.argmin(axis=1)
        r_best = r[rows, best]
        r_own = r[rows, self._tab[8].take(own)]
        # switch only for a clear gain (noise alone must not shuffle readings between lines)
        ok = (r_best <= thr.take(idx)) & (r_best < r_own - sw.opts.corner_sigmas * sigma.take(idx))
        if ok.any():
            seq = seq.copy()
            seq[idx[ok]] = use.take(best[ok])
            self.label = seq

    def corners(self, px, py):
        """Every corner of two usable lines meeting at > 30°: pieces adjacent in a polyline,
        or lines whose intersection X lies within ``corner_reach_m`` of both lines' members
        (or ``corner_reach_share`` of X's distance from the ring's centre, if more).

        Returns None (no corner) or, per line and corner (ordered by line; entry e's mirror,
        the line across, is ``mirror[e]``): the line, the line across, X, Y, the line's
        direction, the side of X its bulk (centroid) is on (±1), the extent of the members
        of each usable column along its line (lo, hi; ±inf without members), and whether
        the corner is of adjacent pieces."""
        use, a, cx, cy, dx, dy, _, _, col = self.table(px, py)
        n = use.size
        if n < 2:
            return None
        lab = self.label
        mem = (lab >= 0).nonzero()[0]
        c = col.take(lab.take(mem))
        keep = c >= 0
        mem, c = mem[keep], c[keep]
        along = (px.take(mem) - cx.take(c)) * dx.take(c) + (py.take(mem) - cy.take(c)) * dy.take(c)
        lo = np.full(n, np.inf)
        hi = np.full(n, -np.inf)
        np.minimum.at(lo, c, along)
        np.maximum.at(hi, c, along)
        opts = self.sw.opts
        pc = self.pieces
        i, j = np.triu_indices(n, 1)
        den = dx[i] * dy[j] - dy[i] * dx[j]                 # sin of the angle between them
        ok = np.abs(den) > 0.5
        i, j, den = i[ok], j[ok], den[ok]
        ex, ey = cx[j] - cx[i], cy[j] - cy[i]
        s = (ex * dy[j] - ey * dx[j]) / den                   # X along line i from its centroid
        t = (ex * dy[i] - ey * dx[i]) / den                   # … and along line j
        X = cx.take(i) + s * dx.take(i)
        Y = cy.take(i) + s * dy.take(i)
        # a far corner's drop-out gap is wider: the reach grows with its distance
        reach = np.maximum(opts.corner_reach_m, opts.corner_reach_share
                           * np.hypot(X - self.sw.centre[0], Y - self.sw.centre[1]))
        li, lj = use.take(i), use.take(j)
        adjacent = (lj == li + 1) & (pc.starts.take(np.minimum(lj, pc.starts.size - 1))
                                     == pc.ends.take(li))
        near = ((s >= lo.take(i) - reach) & (s <= hi.take(i) + reach)
                & (t >= lo.take(j) - reach) & (t <= hi.take(j) + reach))
        keep = adjacent | near
        if not keep.any():
            return None
        i, j, s, t, adjacent = i[keep], j[keep], s[keep], t[keep], adjacent[keep]
        X, Y = X[keep], Y[keep]
        m = i.size
        # entries 2q (line i) and 2q + 1 (line j) of corner q, then ordered by line
        side = np.stack([i, j], axis=1).reshape(-1)
        order = np.argsort(use.take(side), kind="stable")
        rank = np.empty(2 * m, dtype=np.intp)
        rank[order] = np.arange(2 * m)
        mirror = rank.take(np.arange(2 * m) ^ 1).take(order)
        side = side.take(order)
        other = np.stack([j, i], axis=1).reshape(-1).take(order)
        bulk = np.sign(-np.stack([s, t], axis=1).reshape(-1)).take(order)
        return (use.take(side), use.take(other), np.repeat(X, 2).take(order),
                np.repeat(Y, 2).take(order), dx.take(side), dy.take(side), bulk, mirror, lo, hi,
                np.repeat(adjacent, 2).take(order))

    def corner_sides(self, d_now, px, py, sigma, thr) -> None:
        """A wall ends at its corner: readings on a line past a corner it makes with another
        line (past the intersection, away from the line's bulk) are not on it.

        Next to a corner a reading read with the wrong wall's θ lands on that wall's
        extension, self-consistently, and fits both lines about as well; where it lands
        tells them apart. Such a reading goes to the line across the corner if, read with
        that line's θ, it lies on it (within the split threshold and ``adopt_margin_m`` of
        its members' extent; at a far corner, of the corner too, if that brings it closer
        by more than the split threshold) and on its side of the corner; of several, one a
        neighbouring reading of its sensor is on, else the one it fits best. Past a corner
        of adjacent pieces it moves by itself. Past any other it moves with its run (the
        readings of its sensor next to it on its line going to the same line), only if the
        run's range, once moved, is continuous with the readings either side of it (a
        corner keeps the range continuous; a wall's readings behind an occlusion edge moved
        onto the near face would jump at the far end) and one of them is on the target
        line; a run within
        ``corner_past_m`` of the corner needs both, or each of its readings clearly
        (``corner_sigmas``·σ) closer to the target line than to its own. Corners:
        :meth:`corners`; ``d_now`` the readings' current distances (docs/estimator.md).
        """
        ent = self.corners(px, py)
        if ent is None:
            return
        line, other, X, Y, dx, dy, bulk, mirror, lo, hi, adjacent = ent
        sw = self.sw
        lab = self.label
        mem = (lab >= 0).nonzero()[0]
        # (member, entry) pairs of the member's line (entries are in line order: each
        # member's are a slice), the member past the corner
        lo_e = np.searchsorted(line, lab.take(mem), side="left")
        n_e = np.searchsorted(line, lab.take(mem), side="right") - lo_e
        pm = np.repeat(mem, n_e)
        pe = np.arange(pm.size) - np.repeat(np.cumsum(n_e) - n_e, n_e) + np.repeat(lo_e, n_e)
        beyond = ((px.take(pm) - X.take(pe)) * dx.take(pe)
                  + (py.take(pm) - Y.take(pe)) * dy.take(pe)) * bulk.take(pe)
        keep = beyond < 0
        pm, pe, beyond = pm[keep], pe[keep], beyond[keep]
        if pm.size == 0:
            return
        # read with the target's θ the reading must lie on the target line ...
        use, a, cx, cy, tdx, tdy, _, _, col = self._tab
        tc = col.take(other.take(pe))
        th = _incidence(sw.hm.take(pm), a.take(tc))
        la, b = sw.ab(np.minimum(th, sw.cap))
        d = np.exp(la + b * sw.log_s.take(pm))
        qx = d * sw.ux.take(pm)
        qx += sw.ox.take(pm) - cx.take(tc)
        qy = d * sw.uy.take(pm)
        qy += sw.oy.take(pm) - cy.take(tc)
        r = np.abs(qy * tdx.take(tc) - qx * tdy.take(tc))
        t = qx * tdx.take(tc) + qy * tdy.take(tc)
        # a far corner (its reach grown with its distance) hides the wall's end in the
        # drop-out gap: a reading that, read with the target's θ, comes closer by more than
        # the split threshold (its beam would have met that wall first) may lie on the
        # target up to the corner, not only up to its members
        m = sw.opts.adopt_margin_m
        tx = ((X.take(pe) - cx.take(tc)) * tdx.take(tc)
              + (Y.take(pe) - cy.take(tc)) * tdy.take(tc))
        far = (sw.opts.corner_reach_share * np.hypot(X.take(pe) - sw.centre[0],
                                                     Y.take(pe) - sw.centre[1])
               > sw.opts.corner_reach_m)
        tx = np.where(far & (d < d_now.take(pm) - thr.take(pm)), tx, lo.take(tc))
        ok = ((th <= sw.reject) & (r <= thr.take(pm))
              & (t >= np.minimum(lo.take(tc), tx) - m) & (t <= np.maximum(hi.take(tc), tx) + m))
        # ... on the target's side of the corner
        pt = mirror.take(pe)
        side = ((sw.ox.take(pm) + d * sw.ux.take(pm) - X.take(pt)) * dx.take(pt)
                + (sw.oy.take(pm) + d * sw.uy.take(pm) - Y.take(pt)) * dy.take(pt))
        ok &= side * bulk.take(pt) >= 0
        pm, pe, r, d, th, beyond = pm[ok], pe[ok], r[ok], d[ok], th[ok], beyond[ok]
        if pm.size == 0:
            return
        # one target per reading: of those a neighbouring reading of its sensor is on, the
        # one it fits best (the first of equals); else the one it fits best
        k = sw.k
        brk = sw.run_brk
        tg = other.take(pe)
        seen = ~brk.take(pm) & (lab.take(np.maximum(pm - 1, 0)) == tg)
        nx = pm + 1 < k
        nx[nx] = ~brk.take(pm[nx] + 1)
        seen |= nx & (lab.take(np.minimum(pm + 1, k - 1)) == tg)
        order = np.lexsort((np.arange(pm.size), r, ~seen, pm))
        first = np.ones(order.size, dtype=bool)
        first[1:] = pm.take(order[1:]) != pm.take(order[:-1])
        win = order[first]
        at = pm.take(win)
        cand = np.zeros(k, dtype=bool)
        cand[at] = True
        tgt = np.full(k, -1)
        tgt[at] = tg.take(win)
        d_new = d_now.copy()                  # the distances once every candidate moved
        d_new[at] = d.take(win)
        slope = np.zeros(k)
        slope[at] = np.tan(np.minimum(th.take(win), sw.cap))
        # within corner_past_m of the corner, and not clearly closer to the target line
        # than to its own (by corner_sigmas·σ, as settle_corners)
        oc = col.take(lab.take(at))
        r_own = np.abs((py.take(at) - cy.take(oc)) * tdx.take(oc)
                       - (px.take(at) - cx.take(oc)) * tdy.take(oc))
        near = np.zeros(k, dtype=bool)
        near[at] = ((beyond.take(win) >= -sw.opts.corner_past_m)
                    & ~(r.take(win) < r_own - sw.opts.corner_sigmas * sigma.take(at)))
        # past the corner of two pieces of one polyline: the trace is continuous there and
        # the target the piece beside it, so the reading moves by itself
        new = lab.copy()
        by_piece = adjacent.take(pe.take(win))
        new[at[by_piece]] = tgt.take(at[by_piece])
        cand[at[by_piece]] = False
        # runs: consecutive readings of a sensor on one line with one target
        same = np.zeros(k, dtype=bool)
        same[1:] = (cand[1:] & cand[:-1] & ~brk[1:] & (lab[1:] == lab[:-1])
                    & (tgt[1:] == tgt[:-1]))
        start = cand & ~same
        a = start.nonzero()[0]                                # first reading of each run
        if a.size == 0:
            self.label = new
            return
        last = cand.copy()
        last[:-1] &= ~same[1:]
        b = last.nonzero()[0]                                 # last reading of each run
        t = tgt.take(a)
        has_prev = ~brk.take(a)
        has_next = b + 1 < k
        has_next[has_next] = ~brk.take(b[has_next] + 1)
        prev, nxt = np.maximum(a - 1, 0), np.minimum(b + 1, k - 1)
        ok_prev = ~has_prev | self._same_surface(d_new, a, prev, slope.take(a), sigma)
        ok_next = ~has_next | self._same_surface(d_new, b, nxt, slope.take(b), sigma)
        on_prev, on_next = has_prev & (lab.take(prev) == t), has_next & (lab.take(nxt) == t)
        run = np.cumsum(start) - 1                            # run of each candidate
        n_near = np.bincount(run[cand & near], minlength=a.size)
        # a run next to the corner moves only between readings on the target line
        move = ok_prev & ok_next & (on_prev | on_next) & ((n_near == 0) | (on_prev & on_next))
        at = (cand & move.take(np.maximum(run, 0))).nonzero()[0]
        new[at] = tgt.take(at)
        self.label = new

    def _same_surface(self, d, i, j, slope, sigma):
        """Whether readings i and j (neighbours of one sensor) at distances ``d`` lie on one
        surface: ranges apart by at most max(d)·sin(turn)·``slope`` (d·tanθ per radian the
        beam turns) + jump_sigmas·(σ_i ⊕ σ_j)."""
        sw = self.sw
        di, dj = d.take(i), d.take(j)
        turn = np.abs(sw.ux.take(i) * sw.uy.take(j) - sw.uy.take(i) * sw.ux.take(j))
        allowed = np.maximum(di, dj) * turn * slope
        allowed += sw.opts.jump_sigmas * np.hypot(sigma.take(i), sigma.take(j))
        return np.abs(di - dj) <= allowed

    def drop_steep(self, usable) -> None:
        """A line the beam would meet past the drop-out angle cannot be what it saw.

        A reading whose line it meets steeper than the rejection angle leaves it. A line that
        most of its readings meet at or past the drop-out angle (less 2°) is not a surface: a
        radial streak (readings off a thin cylinder's edge, stretched along the beams by
        θ = 0) or a runaway (θ up → d down → the line turns radial → θ up, which a curve whose
        a(θ) falls with θ allows on a cylinder's face). A real wall that steep would return
        nothing. Such a line is dropped.
        """
        sw = self.sw
        label = self.label
        lab = np.maximum(label, 0)
        good = (label >= 0) & self.usable.take(lab)
        if usable is not None:
            good &= usable
        theta_line = _incidence(sw.hm, self.alpha.take(lab))
        pinned = good & (theta_line >= sw.cap - PINNED_RAD)
        if pinned.any():
            frac = (np.bincount(lab[pinned], minlength=self.n_lines)
                    / np.maximum(np.bincount(lab[good], minlength=self.n_lines), 1))
            streak = frac > 0.5
            if streak.any():
                self.usable &= ~streak
                self._tab = None
                good &= ~streak.take(lab)
        good &= theta_line <= sw.reject
        if not good.all():
            self.label = np.where(good, label, -1)

    def adopt(self, usable, px, py, thr) -> None:
        """Readings on no usable line join one if, read with that line's θ, they land on it.

        These are mostly readings next to a corner, which θ = 0 put off both walls, and the
        last few readings of a sweep past a corner (the neighbouring sensor sees that wall).
        Every orphan is tried against every usable line at once ((orphans, lines) arrays;
        both are few): it joins the nearest within the split threshold and near the line's
        extent.
        """
        orphan = self.label < 0
        if usable is not None:
            orphan &= usable
        sel = orphan.nonzero()[0]
        if sel.size == 0 or not self.usable.any():
            return
        use, r = self.fit_to(sel, px, py)
        r /= thr.take(sel)[:, None]
        best = r.argmin(axis=1)
        ok = r[np.arange(sel.size), best] <= 1.0
        if ok.any():
            self.label = self.label.copy()
            self.label[sel[ok]] = use.take(best[ok])

    def refit(self, usable, px, py) -> None:
        """The same members, lines refitted at their moved positions; a line left with
        fewer than two members keeps its fit but gives θ no more."""
        lab = self.label
        on = lab >= 0
        if usable is not None:
            on &= usable
        mem = on.nonzero()[0]
        self._tab = None
        if mem.size == 0:
            self.usable[:] = False
            return
        l = lab.take(mem)
        order = l.argsort(kind="stable")
        mem, l = mem.take(order), l.take(order)
        new = np.empty(l.size, dtype=bool)
        new[0] = True
        np.not_equal(l[1:], l[:-1], out=new[1:])
        first = new.nonzero()[0]
        lines = l.take(first)
        cx0, cy0 = self.sw.centre
        buf = np.empty((5, mem.size))
        np.subtract(px.take(mem), cx0, out=buf[0])
        np.subtract(py.take(mem), cy0, out=buf[1])
        np.multiply(buf[0], buf[0], out=buf[2])
        np.multiply(buf[1], buf[1], out=buf[3])
        np.multiply(buf[0], buf[1], out=buf[4])
        n = _lengths(first, mem.size)
        t = np.add.reduceat(buf, first, axis=1)
        mx, my, alpha = _tls_angle(n, t)
        # a line needs two members with some spread (all coincident: no direction)
        fitted = (n >= 2) & ((t[2] - t[0] * mx) + (t[3] - t[1] * my) > 0)
        keep = np.zeros(self.n_lines, dtype=bool)
        keep[lines[fitted]] = True
        lf = lines[fitted]
        self.cx = self.cx.copy()
        self.cy = self.cy.copy()
        self.alpha = self.alpha.copy()
        self.cx[lf] = mx[fitted] + cx0
        self.cy[lf] = my[fitted] + cy0
        alpha = alpha[fitted]
        alpha[alpha < 0] += math.pi
        self.alpha[lf] = alpha
        self.usable &= keep

    def theta_new(self):
        """(θ from each reading's line, capped (0 off any line), θ of the line uncapped)."""
        sw = self.sw
        on = self.label >= 0
        theta_line = np.where(on, _incidence(sw.hm, self.alpha.take(np.maximum(self.label, 0))),
                              0.0)
        return np.minimum(theta_line, sw.cap), theta_line


class _Held:
    """The iteration with held membership, in line order: each line's members' θ follow from
    one direction angle a (θ_i = |π/2 − |h_i − a||), so a step is: points at θ(a) → TLS
    angle G(a) of every line at once (np.add.reduceat over the members sorted by line) →
    new a. With ``secant`` the step is a safeguarded secant step on G(a) − a per line."""

    def __init__(self, sw: _Sweep, grouping: _Grouping, theta: np.ndarray, secant: bool):
        label = grouping.label
        mem = (label >= 0).nonzero()[0]
        lm = label.take(mem)
        order = np.argsort(lm, kind="stable")
        self.perm = perm = mem.take(order)
        lm = lm.take(order)
        self.km = km = perm.size
        new = np.ones(km, dtype=bool)
        np.not_equal(lm[1:], lm[:-1], out=new[1:])
        self.lstart = new.nonzero()[0]
        self.line = lm.take(self.lstart)                 # grouping line index of each slot
        self.slot = new.cumsum() - 1
        self.n = _lengths(self.lstart, km)
        lone = self.n < 2                                 # a lone member keeps its line's θ
        self.lone = lone if lone.any() else None
        cx0, cy0 = sw.centre
        self.hm = sw.hm.take(perm)
        self.log_s = sw.log_s.take(perm)
        self.ox, self.oy = sw.ox.take(perm) - cx0, sw.oy.take(perm) - cy0
        self.ux, self.uy = sw.ux.take(perm), sw.uy.take(perm)
        self.buf = np.empty((5, km))
        self.a = grouping.alpha.take(self.line)
        self.theta = theta.take(perm)
        self.sw = sw
        self.secant = secant
        self.a_prev = self.g_prev = None

    def fit(self):
        """Fit every line to its members' points at the current θ: returns (members' step
        θ_new − θ, θ of their lines uncapped)."""
        sw = self.sw
        la, b = sw.ab(self.theta)
        d = np.exp(la + b * self.log_s)
        buf = self.buf
        x, y = buf[0], buf[1]
        np.multiply(d, self.ux, out=x)
        x += self.ox
        np.multiply(d, self.uy, out=y)
        y += self.oy
        np.multiply(x, x, out=buf[2])
        np.multiply(y, y, out=buf[3])
        np.multiply(x, y, out=buf[4])
        _, _, g_out = _tls_angle(self.n, np.add.reduceat(buf, self.lstart, axis=1))
        g_out[g_out < 0.0] += math.pi
        if self.lone is not None:
            g_out[self.lone] = self.a[self.lone]
        self.g_out = g_out
        theta_line = _incidence(self.hm, g_out.take(self.slot))
        return np.minimum(theta_line, sw.cap) - self.theta, theta_line

    def advance(self) -> None:
        """The next a: the plain step a ← G(a), or (``secant``) a secant step towards the
        root of g(a) = G(a) − a from this and the previous iteration, its gain held to
        [1/64, 8]: below 1 it damps an oscillation (G' < 0), above 1 it speeds up a slow
        contraction (0 < G' < 1); where G' ≥ 1 (a runaway) the step stays plain."""
        g = self.g_out - self.a
        g -= math.pi * np.rint(g * _INV_PI)
        a = self.a
        if self.secant and self.a_prev is not None:
            da = a - self.a_prev
            da -= math.pi * np.rint(da * _INV_PI)
            dg = self.g_prev - g
            # gain −1/slope with slope = (g − g_prev)/da: only where the slope is negative
            ok = dg * da > 0.0
            gain = np.ones_like(g)
            gain[ok] = np.minimum(np.maximum(da[ok] / dg[ok], 1.0 / 64.0), MAX_GAIN)
            self.a_prev, self.g_prev = a, g
            a = a + gain * g
        else:
            self.a_prev, self.g_prev = a, g
            a = a + g
        a -= math.pi * np.floor(a * _INV_PI)
        self.a = a
        self.theta = np.minimum(_incidence(self.hm, a.take(self.slot)), self.sw.cap)


def estimate_detail(sweep: Sweep, calibration: Calibration | None = None, *,
                    max_iterations: int = 20, tolerance_rad: float = math.radians(0.1),
                    iterate: bool = True, lines: LineOptions = LineOptions(),
                    keep_history: bool = False, damping: bool = True,
                    hold: np.ndarray | None = None, snap: bool = True,
                    keep_unconverged: bool = False) -> Estimate:
    """:func:`_estimate_detail`; a full turn started where it breaks
    (:func:`irring.estimation.estimate.full_turn`) unless ``hold`` names rows already."""
    run = functools.partial(_estimate_detail, max_iterations=max_iterations,
                            tolerance_rad=tolerance_rad, iterate=iterate, lines=lines,
                            keep_history=keep_history, damping=damping, hold=hold, snap=snap,
                            keep_unconverged=keep_unconverged)
    if hold is not None:
        return run(sweep, calibration)
    return full_turn(run, sweep, calibration)


def _estimate_detail(sweep: Sweep, calibration: Calibration | None = None, *,
                     max_iterations: int = 20, tolerance_rad: float = math.radians(0.1),
                     iterate: bool = True, lines: LineOptions = LineOptions(),
                     keep_history: bool = False, damping: bool = True,
                     hold: np.ndarray | None = None, snap: bool = True,
                     keep_unconverged: bool = False) -> Estimate:
    """:func:`irring.estimation.estimate.estimate_detail` in numpy (always with the lines).

    ``damping=False`` switches the step control off: every step is the plain a ← G(a) of
    Table II (to show what the control is for). ``hold`` (S, N): readings kept out
    (FOLDOVER_AMBIGUOUS); None with a folding calibration: the fold-over is resolved first
    (:func:`irring.estimation.foldover.resolve_foldover`, numpy shared with the kernel path).
    ``snap``: line members' end points onto their lines
    (:func:`irring.estimation.lines.snap_to_lines`). ``keep_unconverged``: readings
    still moving at the cap valid at their last θ.
    """
    check_work(np.shape(sweep.counts))
    cal = calibration if calibration is not None else nominal_calibration(
        sweep.sensor_model, sweep.ring, sweep.adc_bits, sweep.vref_v)
    if hold is None and cal.folds and iterate:
        return resolve_foldover(lambda held, _detail, snap_: _estimate_detail(
            sweep, cal, max_iterations=max_iterations, tolerance_rad=tolerance_rad,
            iterate=iterate, lines=lines, keep_history=keep_history, damping=damping,
            hold=held, snap=snap_, keep_unconverged=keep_unconverged), sweep, cal, True,
            range_profiles, options=lines)
    if max_iterations < 1:
        raise ValueError(f"max_iterations must be ≥ 1, got {max_iterations}")
    counts = np.asarray(sweep.counts, dtype=float)
    if counts.ndim != 2:
        raise ValueError(f"sweep.counts must be (steps, sensors), got shape {counts.shape}")
    angles = np.asarray(sweep.sensor_angles, dtype=float)
    pose = sweep.reading_poses if sweep.reading_poses is not None else sweep.pose
    origin, heading = beam_geometry(sweep.ring, np.asarray(pose, dtype=float), angles,
                                    cal.emitter_offset_m)
    origin = np.broadcast_to(origin, counts.shape + (2,))
    heading = np.broadcast_to(heading, counts.shape)
    shape = counts.shape

    max_range = min(float(sweep.max_range_m), cal.max_range_m)
    counts, reason = held_and_pooled(counts, classify(counts, sweep, cal), hold,
                                     np.asarray(sweep.steps), cal, max_range)
    live = reason == Reason.OK
    sw = _Sweep(cal, counts, origin, heading, live, np.asarray(sweep.steps), lines)
    k = sw.k
    theta = np.zeros(k)
    last_moving = np.full(k, -1)        # last iteration in which each reading's θ moved
    history = [np.zeros(shape)] if keep_history else []
    grouping: _Grouping | None = None
    pieces: Pieces | None = None
    held: _Held | None = None
    on_line = np.zeros(k, dtype=bool)
    regroups = 0
    regroup_changed = True
    older = None          # the labels two groupings ago
    passes = []           # (iteration, θ, last_moving) at each membership pass
    mode = "regroup"
    it = 0
    settled = False
    while it < (max_iterations if iterate and k else 0):
        checked = False
        if mode != "inner":
            # a membership pass: regroup (split-and-merge anew), or check the members
            checked = True
            if held is not None:
                theta[held.perm] = held.theta
                # who stood still here met Table II's test; should this pass set them
                # moving again and the cap catch them, settled_within_noise judges them
                passes.append((it, theta.copy(), last_moving.copy()))
            d, px, py, sigma = sw.points(theta)
            thr = sw.thresholds(sigma)
            # readings far outside the range cannot help a line (but stay for the final check)
            usable = d <= 1.5 * max_range
            use_mask = None if bool(usable.all()) else usable
            before = None if grouping is None else grouping.label
            if mode == "regroup":
                uidx = None if use_mask is None else usable.nonzero()[0]
                # polylines break at a sensor change and at range jumps (occlusion edges)
                chains = polyline_ids(d, sigma, sw.h, sw.sensor, sw.reject, lines.jump_sigmas)
                parts = (px, py, thr, chains) if uidx is None else (
                    px.take(uidx), py.take(uidx), thr.take(uidx), chains.take(uidx))
                pieces = _segment(*parts, lines, sw.centre, pieces)
                grouping = _Grouping(sw, pieces, uidx)
                grouping.members(px, py, thr)
                grouping.settle_corners(px, py, sigma, thr)
                corners_checked = False    # the grouping's first check re-decides corners
                regroups += 1
            else:  # the same members, refitted where they now are
                grouping.refit(use_mask, px, py)
                if not corners_checked or it < CORNER_WINDOW:
                    grouping.corner_sides(d, px, py, sigma, thr)
                corners_checked = True
            grouping.drop_steep(use_mask)
            grouping.adopt(use_mask, px, py, thr)
            changed = before is None or not np.array_equal(before, grouping.label)
            # θ from the members' own lines (as the held iterations fit them), so an unchanged
            # grouping leaves θ where it was
            if mode == "regroup" or changed:
                grouping.refit(use_mask, px, py)
            elif settled:
                break          # the members stand and their lines did not move: done
            if mode == "regroup":
                # regroup again only while that changes who belongs where, and not back to
                # the grouping before (readings at a corner flipping between two lines)
                regroup_changed = changed and not (
                    older is not None and np.array_equal(older, grouping.label))
                older = before
            mode = "inner"
            if changed or held is None:  # a plain step from the new grouping
                theta_new, _ = grouping.theta_new()
                moving = np.abs(theta_new - theta) >= tolerance_rad
                theta = theta_new
                on_line = grouping.label >= 0
                last_moving[moving] = it
                it += 1
                if keep_history:
                    history.append(_scatter(theta, sw.index, shape, 0.0))
                if not moving.any():
                    break
                held = _Held(sw, grouping, theta, secant=damping)
                continue
            # unchanged: this iteration is an ordinary held step
        step, theta_line = held.fit()
        hot = theta_line >= sw.cap - PINNED_RAD
        if not checked and hot.any() and _needs_drop(held, hot, theta_line, sw):
            mode = "member"      # some member left its line: redo this iteration as a check
            continue
        moving = np.abs(step) >= tolerance_rad
        last_moving[held.perm[moving]] = it
        held.advance()
        it += 1
        settled = not moving.any()
        if keep_history:
            history.append(_scatter(theta, sw.index, shape, 0.0, held))
        if not moving.any():
            if regroups == 1 and regroups < lines.regroup_iterations:
                mode = "regroup"   # settled once: split-and-merge the straightened points again
            elif checked:
                break
            else:
                mode = "member"    # settled: a last look at who belongs where
        elif (regroup_changed and regroups < lines.regroup_iterations
              and (regroups == 1 or it < REGROUP_WINDOW)
              and float(np.max(np.abs(step))) < lines.regroup_until_rad):
            mode = "regroup"       # θ has settled coarsely: group the straightened points again
    n_its = it
    if held is not None:
        theta[held.perm] = held.theta
    if not keep_unconverged:
        settled_within_noise(passes, theta, last_moving, n_its, cal, sw.log_s)

    # final points with the exact curve
    s = sw.counts
    log_a, b = cal.log_ab(theta)
    d = np.exp(log_a + b * sw.log_s)
    sigma = range_sigma(b, d, sw.sig_s)
    px, py = sw.ox + d * sw.ux, sw.oy + d * sw.uy
    # a line member stays valid up to RANGE_SIGMAS of its (noise) σ past the max range: a
    # surface at the limit read long; final_estimate keeps it only on its line, in range
    limit = max_range + np.where(on_line, RANGE_SIGMAS * sigma, 0.0) if iterate else max_range
    if iterate:  # fallback readings (no line): θ = 0, σ widened by θ's unknown
        off = (~on_line).nonzero()[0]
        if off.size:
            sigma[off] = np.hypot(sigma.take(off), fallback_spread(cal, s.take(off),
                                                                     d.take(off)))

    iterations = np.minimum(last_moving + 2, n_its)
    moving_at_end = last_moving == n_its - 1 if n_its and not keep_unconverged \
        else np.zeros(k, dtype=bool)
    bad_range = (d > limit) | (d < cal.min_range_m) | ~np.isfinite(d)
    why = np.where(bad_range, np.uint8(Reason.OUT_OF_RANGE),
                   np.where(moving_at_end, np.uint8(Reason.NOT_CONVERGED), np.uint8(Reason.OK)))
    why = np.where(np.isfinite(px) & np.isfinite(py) & np.isfinite(sigma) | (why != Reason.OK),
                   why, np.uint8(Reason.OUT_OF_RANGE))
    reason.reshape(-1)[sw.index] = why
    valid = reason == Reason.OK
    it_out = np.full(shape, 1 if iterate else 0, dtype=np.int32)
    it_out.reshape(-1)[sw.index] = iterations
    nan = np.nan
    points = Points(
        x=_scatter(px, sw.index, shape, nan, mask=valid),
        y=_scatter(py, sw.index, shape, nan, mask=valid),
        d=_scatter(d, sw.index, shape, nan, mask=valid),
        theta=_scatter(theta, sw.index, shape, nan, mask=valid),
        origin_x=np.array(origin[..., 0]), origin_y=np.array(origin[..., 1]),
        heading=np.array(heading), sigma_m=_scatter(sigma, sw.index, shape, nan, mask=valid),
        iterations=it_out, valid=valid, reason=reason, max_range_m=max_range)
    return final_estimate(points, grouping, on_line, sw.index, cal, lines, snap, True, history,
                          counts, np.asarray(sweep.steps), reach=no_return_reach,
                          snapper=snap_to_lines, profiler=range_profiles,
                          voter=far_line_vote, shorter=short_far_lines,
                          post_grouper=post_groups, gapper=silent_gaps,
                          beside=beside_a_return, tracer=TraceSteps,
                          judge=counts_contradicted,
                          bower=bowed_lines, fitter=CountsFits, past_finder=past_members,
                          faceter=faceted_lines, rounder=round_runs, bender=bent_ends,
                          edger=alone_at_an_edge,
                          raw_counts=np.asarray(sweep.counts, dtype=float))


def snap_to_lines(points: Points, member: np.ndarray, min_range_m: float,
                  own_cap_m: float = math.inf, min_members: int = SNAP_MIN) -> Points:
    """End points of the readings on a line put where their beams meet it.

    ``member`` (S, N): the line each reading took θ from (−1: none). Each line is fitted
    (total least squares) to its valid members' final end points (members read a little
    past the max range included: see :func:`irring.estimation.silence.drop_beyond_range`);
    a member's end point moves along its beam to the line if it lies behind the line (the
    beam cannot have passed the surface its line says it met: noise put it there; a
    reading 49 mm past a wall its neighbours put at 470–483 mm drew cells outside a room)
    or short of it by no more than 3σ (something may stand in front of the wall). The line
    averages the noise of all its members, so a wall seen at 13 mm RMS per reading comes
    out a few mm thick; a reading the line does not explain keeps its own distance, and
    none leaves [``min_range_m``, ``points.max_range_m``]. A moved reading's σ is the
    line's uncertainty where its beam meets it, with half its own σ added in quadrature (at
    most ``own_cap_m``: where a part is read to its own range, its far end's noise is 30–55
    mm a reading and that half alone made a snapped point's σ twice its error; final_estimate
    passes :func:`irring.estimation.lines.far_sigma_cap`). Only lines of at least
    ``min_members`` (final_estimate passes :func:`irring.estimation.lines.snap_members`:
    ``SNAP_MIN`` at step_stride 1, fewer where fewer steps are read). The statement
    :func:`irring.estimation.lines.snap_to_lines` compiles."""
    on = (points.valid & (member >= 0)).reshape(-1).nonzero()[0]
    if on.size == 0:
        return points
    g = member.reshape(-1).take(on)              # line indices: small, so bincount directly
    x, y = points.x.reshape(-1).take(on), points.y.reshape(-1).take(on)
    n = np.bincount(g)
    keep = n >= min_members
    if not keep.any():
        return points
    nn = np.maximum(n, 1)
    mx, my = np.bincount(g, x) / nn, np.bincount(g, y) / nn
    u, v = x - mx.take(g), y - my.take(g)
    alpha = 0.5 * np.arctan2(2.0 * np.bincount(g, u * v), np.bincount(g, u * u)
                             - np.bincount(g, v * v))
    nx, ny = -np.sin(alpha), np.cos(alpha)
    along = u * np.cos(alpha).take(g) + v * np.sin(alpha).take(g)
    h = points.heading.reshape(-1).take(on)
    ch, sh = np.cos(h), np.sin(h)
    ngx, ngy = nx.take(g), ny.take(g)
    un = ch * ngx + sh * ngy
    ox, oy = points.origin_x.reshape(-1).take(on), points.origin_y.reshape(-1).take(on)
    # the line through the members' centroid: t along the beam to it (members offset by u, v)
    rel = u * ngx + v * ngy                      # each member's signed offset from its line
    d = points.d.reshape(-1).take(on)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = d - rel / un
    ok = (keep.take(g) & np.isfinite(t)
          & (t - d <= SNAP_SIGMAS * points.sigma_m.reshape(-1).take(on))
          & (t >= min_range_m) & (t <= points.max_range_m))
    if not ok.any():
        return points
    # σ of a point on the line: the fitted line's own uncertainty where the beam meets it
    # (its offset, rms²/n, and its angle, growing with the distance s from the centroid:
    # rms²·s²/(n·var_along)), along the beam
    var_perp = np.bincount(g, rel * rel) / nn
    var_along = np.maximum(np.bincount(g, along * along) / nn, 1e-12)
    perp2 = var_perp.take(g) / nn.take(g) * (1.0 + along * along / var_along.take(g))
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma_line = np.sqrt(perp2) / np.abs(un)
    at, t = on[ok], t[ok]
    out = {f: np.array(getattr(points, f)) for f in ("x", "y", "d", "sigma_m")}
    # plus half the reading's own σ: the line is a model, a wall's end or a slightly
    # wrong θ moves a member off it (with none, 4 % of T-room members lie beyond 3σ)
    own = points.sigma_m.reshape(-1)[at]
    out["sigma_m"].reshape(-1)[at] = np.maximum(
        np.hypot(sigma_line[ok], np.minimum(SNAP_OWN * own, own_cap_m)), SIGMA_FLOOR_M)
    out["d"].reshape(-1)[at] = t
    out["x"].reshape(-1)[at] = ox[ok] + t * ch[ok]
    out["y"].reshape(-1)[at] = oy[ok] + t * sh[ok]
    return replace(points, **out)


def return_gaps(points: Points) -> tuple[np.ndarray, np.ndarray]:
    """(up, down) (S·N,) rad: how far each reading's heading lies from the nearest reading of
    the same sensor column, earlier or later in the sweep, that was not silent (any reason
    but NO_RETURN), toward greater (``up``) and lesser (``down``) headings; NaN: none there.
    (Why: :func:`no_return_reach`, "Past a line's end".)"""
    reason = np.asarray(points.reason)
    steps = reason.shape[0]
    heard = (reason != Reason.NO_RETURN).reshape(steps, -1)
    h = np.asarray(points.heading, dtype=float).reshape(steps, -1)
    row, cols, nearest = nearest_heard_rows(heard)
    up = np.full(h.shape, np.nan)
    down = np.full(h.shape, np.nan)
    for other in nearest:
        has = (other >= 0) & (other < steps)
        diff = h[np.where(has, other, row), cols] - h
        diff = diff - 2.0 * math.pi * np.rint(diff / (2.0 * math.pi))      # to [−π, π]
        diff = np.where(has & (diff != 0.0), diff, np.nan)
        up = np.fmin(up, np.where(diff > 0, diff, np.nan))
        down = np.fmin(down, np.where(diff < 0, -diff, np.nan))
    return up.reshape(-1), down.reshape(-1)


def no_return_reach(points: Points, found: Lines | None, cal: Calibration,
                    options: LineOptions) -> np.ndarray | None:
    """How far each NO_RETURN beam is known free (S, N, m; NaN: to the max range; None: no
    silent beam meets a line that explains it), from the sweep's lines ``found``: the
    statement :func:`irring.estimation.silence.no_return_reach` compiles.

    A GP2 returns nothing from a surface met past its drop-out angle, so a silent beam only
    says "no surface I could have seen": one grazing a box's face passes into the box, and
    a few such beams at full length mapped the inside of boxes free (free accuracy 0.980 in
    a held-out kitchen). A silent beam that meets a usable line (≥ 5 valid members; its
    members' extent plus 0.25 m, not past a corner: ``clip_at_corners``) within its range
    at an incidence the sensor would drop out at (≥ the drop-out angle less
    ``options.incidence_margin_rad``) is explained by it: it is known free only to where
    it comes within 10 mm of that line. A line met at a smaller incidence is not what the
    beam saw (it would have returned), so it explains nothing.

    Past a line's end the surface may turn away past the drop-out (a reflex corner of the
    room, a box's face met end-on) and hide from every beam: a silent beam from O that
    crosses a usable line's supporting line beyond its members' end E, within range, is
    known free at most to t_E + δ·tan(θ + γ) and not before it crosses that line (t_E:
    along the beam to E's foot, δ: E's distance from the beam, γ: the angle at O between
    the beam and E, θ: the drop-out angle less the margin; no limit where θ + γ ≥ 90°).
    A straight face from E meets the beam at the angle ψ with tan ψ = (stop − t_E)/δ, and
    the sensor's beams between O→E and this one cross it up to γ less steeply: a face
    meeting the beam sooner would have returned one of them. Those that did return
    something may have seen it, so γ is at most the heading gap to the nearest of them
    (:func:`return_gaps`; docs/estimator.md, "Silent beams past a line's end")."""
    nr = (points.reason == Reason.NO_RETURN).reshape(-1).nonzero()[0]
    if nr.size == 0 or found is None or found.usable.size == 0:
        return None
    lab = found.label.reshape(-1)
    n_mem = np.bincount(lab[(lab >= 0) & points.valid.reshape(-1)],
                        minlength=found.usable.size)
    use = (found.usable & (n_mem >= REACH_MIN_MEMBERS)).nonzero()[0]
    if use.size == 0:
        return None
    c, e, nrm = found.centroid[use], found.direction[use], found.normal[use]
    *_, lo, hi = member_spans(points, found, use)
    lo_b, hi_b = clip_at_corners(c, e, lo, hi)
    h = points.heading.reshape(-1)[nr]
    un, t, ahead, along = beam_crossings(points.origin_x.reshape(-1)[nr],
                                         points.origin_y.reshape(-1)[nr], np.cos(h), np.sin(h),
                                         c, e, nrm)                          # (B, L)
    cos_inc = np.abs(un)
    ok = (ahead & (cos_inc <= reach_cos_limit(cal, options)) & (t <= points.max_range_m)
          & (along >= lo_b[None, :]) & (along <= hi_b[None, :]))
    # the beam stops where it comes within REACH_CLEAR_M of the line
    stop = np.maximum(np.where(ok, t - REACH_CLEAR_M / np.where(ok, cos_inc, 1.0),
                               np.inf).min(axis=1), 0.0)
    # … or where a face turned away at a line's end could have hidden from it
    theta = end_hide_angle(cal, options)
    ox, oy = points.origin_x.reshape(-1)[nr], points.origin_y.reshape(-1)[nr]
    ux, uy = np.cos(h), np.sin(h)
    up, down = (g[nr] for g in return_gaps(points))
    for end, beyond in ((hi, along > hi[None, :]), (lo, along < lo[None, :])):
        ex = c[None, :, 0] + end[None, :] * e[None, :, 0] - ox[:, None]         # O → E
        ey = c[None, :, 1] + end[None, :] * e[None, :, 1] - oy[:, None]
        t_end = ex * ux[:, None] + ey * uy[:, None]
        cross = ux[:, None] * ey - uy[:, None] * ex          # > 0: E at greater headings
        off = np.abs(cross)
        # γ: the angle to E, or to the nearest beam of the same sensor toward E that heard
        # something (the face may have returned it: only the silent ones in between count)
        gamma = np.arcsin(np.minimum(off / np.maximum(np.hypot(ex, ey), 1e-12), 1.0))
        heard = np.where(cross > 0, up[:, None], down[:, None])
        gamma = np.where(heard < gamma, heard, gamma)
        angle = theta + gamma
        hides = (ahead & beyond & (t <= points.max_range_m) & (t_end > 0)
                 & (angle < 0.5 * math.pi - 1e-6))
        hide = t_end + off * np.tan(np.where(hides, angle, 0.0))
        stop = np.minimum(stop, np.where(hides, np.maximum(t, hide), np.inf).min(axis=1))
    if not np.isfinite(stop).any():
        return None
    reach = np.full(points.valid.size, np.nan)
    reach[nr] = np.where(np.isfinite(stop), stop, np.nan)
    return reach.reshape(points.valid.shape)



def _needs_drop(held: _Held, hot, theta_line, sw: _Sweep) -> bool:
    """Whether a member now meets its line past the rejection angle, or most of a line's
    members sit at the drop-out angle (a streak or runaway, see _Grouping.drop_steep)."""
    if (theta_line > sw.reject).any():
        return True
    n_hot = np.bincount(held.slot[hot], minlength=held.n.size)
    return bool((n_hot > 0.5 * held.n).any())


def _scatter(values, index, shape, fill, held: _Held | None = None, mask=None):
    """Compact per-reading values back into an (S, N) array (``fill`` elsewhere)."""
    out = np.full(shape, fill)
    if held is not None:
        values = values.copy()
        values[held.perm] = held.theta
    out.reshape(-1)[index] = values
    if mask is not None:
        out[~mask] = fill
    return out


def far_line_vote(at: np.ndarray, sel: np.ndarray, lab: np.ndarray, theta_now: np.ndarray,
                  pr, d: np.ndarray, vi: np.ndarray, n_lines: int, cal: Calibration,
                  half: int, min_n: int, z_max: float, shift_m: float) -> np.ndarray:
    """Which short far lines their members vote off (``far_lines.doubt_far_lines``; docs/
    foldover.md, "Short far lines"): (n_lines,) bool. ``at`` (A,): the asked members'
    places among the valid readings ``vi`` (flat indices into ``d``, the distances),
    ``sel`` (A,) their places among the readings profiled (``pr``, a ``Profile``); ``lab``,
    ``theta_now`` (K,): each valid reading's line (−1 none) and θ.

    A member votes where its profile has ≥ ``min_n`` readings and a slope error, and its
    window (``half`` steps) holds its line's readings only, unless fewer than ``min_n`` of
    the line's members have such a window. A line with ≥ ``min_n`` votes is off where their
    summed z = (tan θ − |own slope|)/se exceeds ``z_max`` per vote and reading the voters at
    their own θ would move them ``shift_m`` on average. The compiled
    ``_lines.far_line_vote`` is held to this."""
    line = lab[at]
    n, se, slope = pr.n[sel], pr.se[sel], pr.slope[sel]
    use = (n >= min_n) & (se > 0)
    # a profile whose window holds another line's reading spans a corner and measures
    # neither wall: a line with enough members whose profiles see it alone is judged by them
    j = at[:, None] + np.arange(-half, half + 1)
    jc = np.clip(j, 0, lab.size - 1)
    window = ((j == jc) & (pr.chain[jc] == pr.chain[at][:, None])
              & (np.abs(pr.step[jc] - pr.step[at][:, None]) <= half))
    pure = use & ~(window & (lab[jc] != line[:, None])).any(axis=1)
    use &= pure | (np.bincount(line, weights=pure, minlength=n_lines) < min_n)[line]
    z = np.where(use, (np.tan(theta_now[at]) - np.abs(slope)) / np.where(use, se, 1.0), 0.0)
    n_use = np.bincount(line, weights=use, minlength=n_lines)
    z_sum = np.bincount(line, weights=z, minlength=n_lines)
    off_line = (n_use >= min_n) & (np.abs(z_sum) > z_max * np.maximum(n_use, 1))
    if off_line.any():   # … and whether their own θ would move them at all
        use &= off_line[line]
        shift = np.zeros(line.size)
        shift[use] = np.abs(d[vi[at[use]]] - cal.distance(pr.s[at[use]], pr.theta[sel][use]))
        off_line &= np.bincount(line, weights=shift, minlength=n_lines) >= shift_m * n_use
    return off_line


def post_groups(points: Points, label: np.ndarray, counts: np.ndarray, cal: Calibration):
    """The groups of readings that could be one far post (``far_lines.far_posts``; docs/
    estimator.md, "Far posts"): readings on no line (INCIDENCE_UNKNOWN, or valid with
    ``label`` (S, N) −1) with clear returns (``counts`` (S, N) at least RETURN_SIGMAS +
    RANGE_SIGMAS count σ above the no-return level), whose θ = 0 end points chain within
    ``POST_LINK_M``; a group holds ≥ 3 readings of ≥ ``POST_SENSORS`` sensors, ≤
    ``POST_RUN_MAX`` of each. Returns None where none does, else (row, col, comp, groups,
    px, py): the candidates (row-major), each one's group (its smallest member's index),
    the groups that qualify and the end points. The compiled ``_lines.post_groups`` is held
    to this. Pairs are sought cell by cell (:func:`_chained`), so the cost grows with the
    candidates, not their square."""
    shape = points.valid.shape
    row, col = ((points.reason == Reason.INCIDENCE_UNKNOWN)
                | (points.valid & (np.asarray(label).reshape(shape) < 0))).nonzero()
    s_c = np.asarray(counts, dtype=float).reshape(shape)[row, col]
    # clear returns only: near the no-return level noise alone makes some (as pooling says)
    clear = s_c >= cal.no_return_counts + (RETURN_SIGMAS + RANGE_SIGMAS) * cal.sigma_counts()
    row, col, s_c = row[clear], col[clear], s_c[clear]
    if row.size < 3 or np.unique(col).size < POST_SENSORS:
        return None
    la0, b0 = cal._ab0
    d0 = np.exp(la0 + b0 * np.log(s_c))                 # cal.distance(s_c, 0.0)
    heading = np.asarray(points.heading, dtype=float)[row, col]
    px = np.asarray(points.origin_x, dtype=float)[row, col] + d0 * np.cos(heading)
    py = np.asarray(points.origin_y, dtype=float)[row, col] + d0 * np.sin(heading)
    comp = _chained(px, py, POST_LINK_M, POST_RUN_MAX * shape[1])
    # per group: members, sensors and the most of one sensor
    pair, each = np.unique(comp * shape[1] + col, return_counts=True)
    group = pair // shape[1]
    total = np.bincount(group, each, row.size)
    sensors = np.bincount(group, minlength=row.size)
    top = np.zeros(row.size, dtype=each.dtype)
    np.maximum.at(top, group, each)
    groups = ((total >= 3) & (sensors >= POST_SENSORS) & (top <= POST_RUN_MAX)).nonzero()[0]
    if not groups.size:
        return None
    return row, col, comp, groups, px, py


def _chained(px: np.ndarray, py: np.ndarray, link_m: float, crowd: int,
             block: int = 1 << 20) -> np.ndarray:
    """Each point's group (its smallest member's index) where points ``px``, ``py`` within
    ``link_m`` of each other are linked, the pairs sought cell by cell (``post_cells``: a
    cell's points are all linked; two cells more than ``crowd`` points each are not compared,
    as a group that large fails the far posts' count either way), ``block`` pairs at a time."""
    order, start, crowded, key, width = post_cells(px, py, link_m, crowd)
    n_in = np.diff(start)
    a, b = [order.take(np.repeat(start[:-1], n_in))], [order]   # each with its cell's first
    cells = np.arange(key.size)
    for dx in range(POST_CELL_REACH + 1):
        for dy in range(-POST_CELL_REACH, POST_CELL_REACH + 1):
            if (dx == 0 and dy <= 0) or not key.size:
                continue
            want = key + dx * width + dy
            other = np.minimum(np.searchsorted(key, want), key.size - 1)
            both = ((key.take(other) == want) & ~(crowded.astype(bool)
                                                  & crowded.take(other).astype(bool)))
            ca, cb = cells[both], other[both]
            pairs = n_in[ca] * n_in[cb]
            cut = np.searchsorted(np.cumsum(pairs), np.arange(block, pairs.sum(), block))
            for part in np.split(np.arange(ca.size), cut):
                i, j = _cell_pairs(start, n_in, ca[part], cb[part])
                i, j = order.take(i), order.take(j)
                near = np.hypot(px[i] - px[j], py[i] - py[j]) < link_m
                a.append(i[near])
                b.append(j[near])
    return linked_components(px.size, np.concatenate(a), np.concatenate(b))


def _cell_pairs(start: np.ndarray, n_in: np.ndarray, ca: np.ndarray, cb: np.ndarray):
    """Every pair of places in cell order of cells ``ca`` and ``cb`` (each cell ``ca[p]``'s
    places with each of ``cb[p]``'s)."""
    na, nb = n_in[ca], n_in[cb]
    per = na * nb
    p = np.repeat(np.arange(ca.size), per)
    r = np.arange(per.sum()) - np.repeat(np.cumsum(per) - per, per)
    return start[ca][p] + r // nb[p], start[cb][p] + r % nb[p]
