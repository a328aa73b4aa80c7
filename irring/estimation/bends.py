"""Lines that bend: a curved wall's chords read on its circle (:func:`bowed_lines`, its compiled
pre-gate :func:`bowed_lines_compiled`), a far line over a corner read as two
(:func:`kinked_lines`), a line's members past a wall's shallow bend read on the turned wall
(:func:`bent_ends`, its compiled gate :func:`bent_ends_compiled`), a snapped line over a
many-sided wall's facets read as two (:func:`faceted_lines`, its compiled pre-gate
:func:`faceted_lines_compiled`), and the fold-over's neighbouring lines that are one concave
arc (:func:`onto_concave_arcs`). Why and what was measured: docs/estimator.md, "Curved
walls", "A line over a corner", "A shallow bend" and "A line over facets"; docs/foldover.md,
"Curved walls".
"""

from __future__ import annotations

import math

import numpy as np

from ..core import Points, Reason, points_with, rows_in_step_order
from ..resources import kernel
from .calibration import SIGMA_FLOOR_M, Calibration, range_sigma
from .arcs import ARC_MISFIT, ARC_MISS
from .lines import SNAP_MIN, SNAP_OWN, SNAP_SIGMAS, invalidated, placed_at, read_to_own_range


_lines = kernel("estimation._lines")


BOW_MIN = 10            # a line of at least this many valid members is asked for a bow …
BOW_PRE_F = 10.0        # … where its members as they lie bow by this F already (cheap) …
BOW_PRE_TOL = 1e-6      # (the compiled pre-gate's F, within this × (1 + Σw·n²/den) of numpy's)
BOW_ITERATIONS = 8      # … then read on a parabola by Table II's iteration (at most this
BOW_SETTLED_RAD = math.radians(0.2)  # many steps, settled to this) and kept where the
BOW_F = 25.0            # parabola beats the line by this F (1, n − 3), …
BOW_TURN_RAD = math.radians(3)   # … turns at least this much across the members …
BOW_RADIUS_M = (0.5, 4.0)        # … at a radius within these (tighter: round_runs')
BOW_POOL_M = 0.02       # a circle holds the bowed lines whose members lie this near it on average
BOW_CIRCLES = 3         # at most this many circles a sweep
BOW_JOIN_MIN = 5        # a line of at least this many valid members takes a circle …
BOW_MISFIT = ARC_MISFIT  # … that its members, read at the circle's θ, misfit this little
BOW_WORSE = 1.0         # … and at most this much more than their own line (σ²); the
BOW_REFITS = 1          # circles refitted to the lines they took this often at most
BOW_DOUBT_RAD = math.radians(3)  # a reading on a circle: σ includes d over θ ± this


def _bow_fit(g: np.ndarray, n_g: int, s: np.ndarray, nn: np.ndarray, w: np.ndarray
             ) -> np.ndarray:
    """Weighted least-squares parabola nn = a + b·s + c·s² per group: (n_g, 3)."""
    pw, r = np.empty((5, n_g)), np.empty((n_g, 3, 1))
    wk = w
    for k in range(5):
        pw[k] = np.bincount(g, wk, n_g)
        if k < 3:
            r[:, k, 0] = np.bincount(g, wk * nn, n_g)
        wk = wk * s
    m = pw[np.add.outer(np.arange(3), np.arange(3))].transpose(2, 0, 1)
    m[:, [0, 1, 2], [0, 1, 2]] += 1e-12
    try:
        return np.linalg.solve(m, r)[..., 0]
    except np.linalg.LinAlgError:   # a group whose members share one spot along the line
        return (np.linalg.pinv(m) @ r)[..., 0]


BOW_KINK_SHARE = 0.5   # two straight pieces leave this share of a parabola's misfit or less:
#                        a corner, not a curve (an arc's two chords fit no better than it) …
BOW_KINK_RAD = math.radians(20)   # … where the two pieces turn by this much


def _line_rss(W, S, Y, SS, SY, YY):
    """Weighted least-squares misfit of a line y = a + b·s from the sums of w, w·s, w·y,
    w·s², w·s·y and w·y² (arrays: one per candidate split)."""
    W = np.maximum(W, 1e-300)
    vs = SS - S * S / W
    cov = SY - S * Y / W
    return np.maximum(YY - Y * Y / W - cov * cov / np.maximum(vs, 1e-300), 0.0)


def _kinked(g: np.ndarray, n_g: int, s: np.ndarray, nn: np.ndarray, w: np.ndarray,
            chi_par: np.ndarray, ask: np.ndarray) -> np.ndarray:
    """(n_g,) bool: groups ``ask`` whose members (``s`` along, ``nn`` across, weights ``w``)
    two straight pieces split at one place along ``s`` (at least 3 members each) fit better
    than a parabola through them: at most ``BOW_KINK_SHARE`` of its weighted misfit
    ``chi_par``."""
    out = np.zeros(n_g, dtype=bool)
    for k in np.flatnonzero(ask):      # (a few bowed lines a sweep)
        on = g == k
        order = np.argsort(s[on], kind="stable")
        ss, yy, ww = s[on][order], nn[on][order], w[on][order]
        n = ss.size
        if n < 8:
            continue
        m = [np.cumsum(np.concatenate(([0.0], q))) for q in
             (ww, ww * ss, ww * yy, ww * ss * ss, ww * ss * yy, ww * yy * yy)]
        tot = [q[-1] for q in m]

        cut = np.arange(3, n - 2)
        lm = [q[cut] for q in m]
        rm = [t - q[cut] for t, q in zip(tot, m)]
        both = _line_rss(*lm) + _line_rss(*rm)
        at = int(np.argmin(both))
        if both[at] > BOW_KINK_SHARE * chi_par[k]:
            continue
        # ... turning at least BOW_KINK_RAD there (a polygonal arc's facets turn less)
        slope = [(q[4][at] - q[1][at] * q[2][at] / max(q[0][at], 1e-300))
                 / max(q[3][at] - q[1][at] ** 2 / max(q[0][at], 1e-300), 1e-300)
                 for q in (lm, rm)]
        out[k] = abs(math.atan(slope[0]) - math.atan(slope[1])) >= BOW_KINK_RAD
    return out


KINK_MIN = 20           # a line over a corner: a line of at least this many valid members …
KINK_SIDE = 4           # … each piece holds at least this many …
KINK_PRE_F = 10.0       # … two pieces beat the line by this F as its members lie (cheap) …
KINK_ITERATIONS = 8     # … then each piece is read by Table II's iteration (at most this
#                         many steps, settled to BOW_SETTLED_RAD) …
KINK_MISFIT = 1.0       # … where the line misfits its members by this χ² a member or more …
KINK_F = 10.0           # … the two pieces, so read, beat it by this F …
KINK_TURN_RAD = BOW_KINK_RAD   # … turn by this much …
KINK_MEET_M = 0.1       # … and meet within this of both pieces' members


def kinked_lines(points: Points, label: np.ndarray, counts: np.ndarray, cal: Calibration
                 ) -> tuple[Points, np.ndarray]:
    """Where a part is read to its own range: a line of ≥ ``KINK_MIN`` valid members over a
    corner (two walls, or a wall and a box face, fitted as one) split at its best place along
    it and each piece read by Table II's iteration, kept where the pieces beat the line
    (``KINK_PRE_F`` as the members lie, ``KINK_MISFIT``, ``KINK_F`` as re-read), turn by
    ``KINK_TURN_RAD``, meet within ``KINK_MEET_M`` of both and no member reaches the drop-out
    angle. Returns the points (a kept piece's members at their θ, σ their noise) and a label
    (S, N) giving one piece of each kept line a new number, for the snap (the grouping keeps
    ``label``). Numpy, shared by both estimators. Why and the rule in full:
    docs/estimator.md, "A line over a corner"."""
    if not read_to_own_range(cal, points.max_range_m):
        return points, label
    asked = _bow_asked(points, label, counts, cal)
    if asked is None:
        return points, label
    (idx, g, n_g, nm, ox, oy, ex, ey, s_c, sig_s, d_line, en, noise, w, ux, uy, cx, cy, s0,
     n0, _, _) = asked
    # every split of every line at once: prefix sums of the weighted moments in s order
    o = np.lexsort((s0, g))
    gs, ss, yy, ww = g[o], s0[o], n0[o], w[o]
    sums = [np.concatenate(([0.0], np.cumsum(q))) for q in
            (ww, ww * ss, ww * yy, ww * ss * ss, ww * ss * yy, ww * yy * yy)]
    start = np.searchsorted(gs, np.arange(n_g))
    end = start + nm.astype(np.intp)
    j = np.arange(gs.size)
    left = [q[j] - q[start[gs]] for q in sums]
    right = [q[end[gs]] - q[j] for q in sums]
    both = _line_rss(*left) + _line_rss(*right)
    pos = j - start[gs]
    both[(pos < KINK_SIDE) | (nm[gs] - pos < KINK_SIDE)] = np.inf
    one = _line_rss(*[q[end] - q[start] for q in sums])
    # (every line asked has BOW_MIN members: a split of KINK_SIDE a side; else the line)
    best = np.minimum(np.minimum.reduceat(both, start), one)
    f_pre = (one - best) / np.maximum(best / np.maximum(nm - 4, 1), 1e-12)
    # the line against its members: their distances against where their beams meet it
    den = ex * -uy + ey * ux
    t_line = (((cx[g] - ox) * -uy + (cy[g] - oy) * ux)
              / np.where(np.abs(den) > 1e-9, den, 1e-9))
    chi1 = np.bincount(g, ((d_line - t_line) / noise) ** 2, n_g)
    ask = (nm >= KINK_MIN) & (f_pre >= KINK_PRE_F) & (chi1 >= KINK_MISFIT * nm)
    if not ask.any():
        return points, label
    # the asked lines' members, each line cut at its best split: pieces 2c and 2c + 1
    first = np.minimum.reduceat(np.where(both == best[gs], j, gs.size), start)
    keep = ask[gs]
    mem, gk = o[keep], gs[keep]
    cand = (np.cumsum(ask) - 1)[gk]
    n_c = int(np.count_nonzero(ask))
    piece = 2 * cand + (j[keep] >= first[gk])
    n_p = 2 * n_c
    npc = np.bincount(piece, minlength=n_p).astype(float)
    mex, mey, mox, moy = ex[mem], ey[mem], ox[mem], oy[mem]
    log_s = np.log(s_c[mem])

    def tls(d):
        """Each piece's TLS line through its members at ``d``: centre, unit normal."""
        x, y = mox + d * mex, moy + d * mey
        px, py = np.bincount(piece, x, n_p) / npc, np.bincount(piece, y, n_p) / npc
        u, v = x - px[piece], y - py[piece]
        al = 0.5 * np.arctan2(2.0 * np.bincount(piece, u * v, n_p),
                              np.bincount(piece, u * u - v * v, n_p))
        return x, y, px, py, -np.sin(al), np.cos(al)

    # Table II's iteration, each piece its own line
    d, th = d_line[mem], None
    settled = np.zeros(n_c, dtype=bool)
    for _ in range(KINK_ITERATIONS):
        _, _, _, _, nx, ny = tls(d)
        th_new = np.arccos(np.clip(np.abs(mex * nx[piece] + mey * ny[piece]), 0.0, 1.0))
        if th is not None:
            settled = np.bincount(cand, np.abs(th_new - th) > BOW_SETTLED_RAD, n_c) == 0
        th = th_new
        la, b = cal.log_ab(th)
        d = np.exp(la + b * log_s)
        if settled.all():
            break
    sig = range_sigma(b, d, sig_s[mem])
    x, y, px, py, nx, ny = tls(d)
    den = mex * nx[piece] + mey * ny[piece]
    t = (((px[piece] - mox) * nx[piece] + (py[piece] - moy) * ny[piece])
         / np.where(np.abs(den) > 1e-9, den, 1e-9))
    chi2 = np.bincount(cand, ((d - t) / sig) ** 2, n_c)
    nmc = nm[ask]
    f = (chi1[ask] - chi2) / np.maximum(chi2 / np.maximum(nmc - 4, 1), 1e-12)
    # the two pieces' lines: how they turn and where they cross
    na, nb = np.arange(0, n_p, 2), np.arange(1, n_p, 2)
    sin = nx[na] * ny[nb] - ny[na] * nx[nb]
    ca, cb = nx[na] * px[na] + ny[na] * py[na], nx[nb] * px[nb] + ny[nb] * py[nb]
    s_ = np.where(np.abs(sin) > 1e-12, sin, 1e-12)
    kx, ky = (ca * ny[nb] - cb * ny[na]) / s_, (nx[na] * cb - nx[nb] * ca) / s_
    gap = np.full(n_p, np.inf)
    np.minimum.at(gap, piece, np.hypot(x - kx[cand], y - ky[cand]))
    past = np.bincount(cand, th >= cal.max_incidence_rad, n_c) > 0
    split_ok = (settled & ~past & (f >= KINK_F)
                & (np.arcsin(np.minimum(np.abs(sin), 1.0)) >= KINK_TURN_RAD)
                & (np.maximum(gap[na], gap[nb]) <= KINK_MEET_M))
    if not split_ok.any():
        return points, label
    take = split_ok[cand]
    at = idx[mem[take]]
    split = label.copy()
    second = take & (piece % 2 == 1)
    split.reshape(-1)[idx[mem[second]]] = label.max() + 1 + cand[second]
    return placed_at(points, at, d[take], th[take], sig[take]), split


BEND_MIN = 20           # a shallow bend: a line of at least this many valid members …
BEND_RUN_Z = 2.0        # … whose sensor's last members in step order its θ each reads this
BEND_Z = 4.0            # many noise σ nearer than the line, this many taken together (z summed
BEND_NEAR_M = 0.03      # over √n), and each this much (at close range a line's misfit passes
BEND_EXPLAINED_Z = 2.5  # 4σ), reaching past the end of the members it explains (this many σ)
BEND_RUN_MIN = 2        # … at least this many such at that end of the line …
BEND_FIT_CHI2 = 8.0     # … whose other members fit it within this mean z² …
BEND_PASSES = 2         # (the line fitted this often, each time without the members found)
BEND_MAX_RAD = math.radians(25)   # … are read on the wall turned by at most this much at the
BEND_GRID = 101         # line's end (this many turns tried, then refined)
BEND_DOUBT_RAD = math.radians(3)  # a reading past a bend: σ includes d over θ ± this


def _bend_members(points: Points, label: np.ndarray, steps: np.ndarray):
    """The members :func:`bent_ends` asks: None where no line has ``BEND_MIN`` valid
    members; else the flat indices ``idx`` of those lines' valid members, their line ``g``
    (0 … ``n_g`` − 1, in label order), ``n_g``, and each row's place in step order
    (``rank`` (S,))."""
    flat = label.reshape(-1)
    valid = points.valid.reshape(-1)
    idx = ((flat >= 0) & valid).nonzero()[0]
    if idx.size < BEND_MIN:
        return None
    lab = flat[idx]
    ask = np.bincount(lab) >= BEND_MIN
    if not ask.any():
        return None
    idx = idx[ask[lab]]
    g = (np.cumsum(ask) - 1)[flat[idx]]
    n_g = int(np.count_nonzero(ask))
    rank = np.empty(label.shape[0], dtype=np.intp)
    rank[rows_in_step_order(steps)] = np.arange(label.shape[0])
    return idx, g, n_g, rank


def _bend_gate(points: Points, shape: tuple, idx: np.ndarray, g: np.ndarray, n_g: int,
               counts: np.ndarray, rank: np.ndarray, cal: Calibration) -> bool:
    """Whether :func:`bent_ends` may find a run (cheap, no trigonometry over the members):
    some sensor's last (or first) member on a line, fitted to all its members, lies
    ``BEND_NEAR_M`` nearer than the line along its beam, and so does the member before it
    in that sensor's trace, or it alone lies ``BEND_Z`` σ nearer."""
    x, y = points.x.reshape(-1)[idx], points.y.reshape(-1)[idx]
    nm = np.bincount(g, minlength=n_g).astype(float)
    cx, cy = np.bincount(g, x, n_g) / nm, np.bincount(g, y, n_g) / nm
    u, v = x - cx[g], y - cy[g]
    al = 0.5 * np.arctan2(2.0 * np.bincount(g, u * v, n_g), np.bincount(g, u * u - v * v, n_g))
    nx, ny = -np.sin(al)[g], np.cos(al)[g]
    ox, oy = points.origin_x.reshape(-1)[idx], points.origin_y.reshape(-1)[idx]
    en = (x - ox) * nx + (y - oy) * ny     # d × the beam's cosine to the line's normal
    # how much nearer than the line along its beam: t − d = −(its offset from the line)/cos
    d = points.d.reshape(-1)[idx]
    short = -(u * nx + v * ny) * d / np.where(np.abs(en) > 1e-12, en, 1e-12)
    n_s, n_n = shape
    pos = rank[idx // n_n] * n_n + idx % n_n + n_n      # a row of padding either side
    line = np.full((n_s + 2) * n_n, -1, dtype=np.intp)
    line[pos] = g
    near = np.zeros((n_s + 2) * n_n, dtype=bool)
    near[pos] = short >= BEND_NEAR_M
    first, last = line[pos - n_n] != g, line[pos + n_n] != g
    end = near[pos] & (first | last)
    if not end.any():
        return False
    inner = np.where(last, pos - n_n, pos + n_n)
    if (end & near[inner] & (line[inner] == g)).any():
        return True
    e = end.nonzero()[0]
    s_c = np.asarray(counts, dtype=float).reshape(-1)[idx[e]]
    noise = range_sigma(cal.log_ab(points.theta.reshape(-1)[idx[e]])[1], d[e],
                        cal.sigma_counts() / s_c)
    return bool((short[e] >= BEND_Z * noise).any())


def bent_ends(points: Points, label: np.ndarray, counts: np.ndarray, steps: np.ndarray,
              cal: Calibration) -> tuple[Points, np.ndarray]:
    """``points`` and ``label`` (S, N) with the members past a wall's shallow bend read on the
    turned wall: on a line of ≥ ``BEND_MIN`` valid members, a sensor's run of members at the
    end of its trace on the line (``steps`` (S,) order) that the line's θ reads nearer than
    the line (each ``BEND_RUN_Z`` σ, the run ``BEND_Z`` σ over √n), reaching past the end of
    the members the line explains, are read on the line through that end turned by the
    least angle (within ``BEND_MAX_RAD``) their counts, at the incidence their beam meets it
    with, land on; they leave their line (label −1), and one no such wall explains is
    INCIDENCE_UNKNOWN. The line is fitted again without them and asked once more. Numpy
    (the fast estimator asks its gate of a kernel first: :func:`bent_ends_compiled`). Why:
    a bend of 4-20° makes no corner, and the line's θ, too steep past it, reads those
    members short (docs/estimator.md, "A shallow bend")."""
    asked = _bend_members(points, label, steps)
    if asked is None:
        return points, label
    idx, g, n_g, rank = asked
    if not _bend_gate(points, label.shape, idx, g, n_g, counts, rank, cal):
        return points, label
    ox, oy = points.origin_x.reshape(-1)[idx], points.origin_y.reshape(-1)[idx]
    h = points.heading.reshape(-1)[idx]
    ex, ey = np.cos(h), np.sin(h)
    d = points.d.reshape(-1)[idx]
    x, y = ox + d * ex, oy + d * ey
    s_c = np.asarray(counts, dtype=float).reshape(-1)[idx]
    sig_s = cal.sigma_counts() / s_c
    noise = range_sigma(cal.log_ab(points.theta.reshape(-1)[idx])[1], d, sig_s)
    n_sens = label.shape[1]
    r = rank[idx // n_sens]
    key = g * n_sens + idx % n_sens
    n_key = n_g * n_sens
    keep = np.ones(idx.size, dtype=bool)
    state = None
    # twice: the readings past a bend pull the line they joined toward them (its beams then
    # meet it short of where they would), so the line is fitted again without those found
    for _ in range(BEND_PASSES):
        w = keep.astype(float)
        nk = np.maximum(np.bincount(g, w, n_g), 1.0)
        cx, cy = np.bincount(g, w * x, n_g) / nk, np.bincount(g, w * y, n_g) / nk
        u, v = x - cx[g], y - cy[g]
        al = 0.5 * np.arctan2(2.0 * np.bincount(g, w * u * v, n_g),
                              np.bincount(g, w * (u * u - v * v), n_g))
        ux, uy = np.cos(al), np.sin(al)
        # where each beam meets its line, and how much nearer the reading lies (in its noise)
        den = ex * -uy[g] + ey * ux[g]
        t = ((cx[g] - ox) * -uy[g] + (cy[g] - oy) * ux[g]) / np.where(np.abs(den) > 1e-9,
                                                                        den, 1e-9)
        z = (t - d) / noise
        # a sensor's run of such at its trace's end, taken together: a bend of 5° met at
        # 60° reads its members 3-4σ short, each alone within the line's noise
        lean = (z >= BEND_RUN_Z) & (t - d >= BEND_NEAR_M)
        if not lean.any():
            break
        k_lo = np.full(n_key, np.iinfo(np.intp).max)
        k_hi = np.full(n_key, -1)
        np.minimum.at(k_lo, key[~lean], r[~lean])
        np.maximum.at(k_hi, key[~lean], r[~lean])
        at_hi, at_lo = lean & (r > k_hi[key]), lean & (r < k_lo[key])
        run = 2 * key + at_hi
        end = at_hi | at_lo
        zs = np.bincount(run[end], z[end], 2 * n_key)
        nz = np.bincount(run[end], minlength=2 * n_key)
        near = end & (zs[run] >= BEND_Z * np.sqrt(np.maximum(nz[run], 1)))
        if not near.any():
            break
        # past the end of the members the line explains: beyond their extent along it,
        # where its beam meets the line (a reading read short at grazing slides back along it)
        s = u * ux[g] + v * uy[g]
        s_t = (ox + t * ex - cx[g]) * ux[g] + (oy + t * ey - cy[g]) * uy[g]
        fit = np.abs(z) < BEND_EXPLAINED_Z
        s_lo = np.full(n_g, np.inf)
        s_hi = np.full(n_g, -np.inf)
        np.minimum.at(s_lo, g[fit], s[fit])
        np.maximum.at(s_hi, g[fit], s[fit])
        # a run reaching past that end is taken whole (its first readings, just past the
        # bend, lie among the other sensors' readings of the line's end)
        top = np.full(2 * n_key, -np.inf)
        bot = np.full(2 * n_key, np.inf)
        np.maximum.at(top, run[near], s_t[near])
        np.minimum.at(bot, run[near], s_t[near])
        past_hi = near & (top[run] > s_hi[g])
        past_lo = near & ~past_hi & (bot[run] < s_lo[g])
        # a bend's end holds at least BEND_RUN_MIN such readings (one alone: noise)
        side = 2 * g + past_hi
        many = np.bincount(side[past_hi | past_lo], minlength=2 * n_g) >= BEND_RUN_MIN
        # … on a line that fits the rest of its members (a line over a muddle of walls reads
        # its members anywhere: taking a few leaves the rest to a worse fit)
        rest = keep & ~(past_hi | past_lo)
        chi = (np.bincount(g[rest], z[rest] ** 2, n_g)
               / np.maximum(np.bincount(g[rest], minlength=n_g), 1))
        asked = (past_hi | past_lo) & many[side] & (chi[g] <= BEND_FIT_CHI2)
        if not asked.any():
            break
        near = asked
        state = (cx, cy, ux, uy, al, s, near, past_hi, asked)
        keep = ~asked
    if state is None:
        return points, label
    cx, cy, ux, uy, al, s, near, past_hi, asked = state
    a = asked.nonzero()[0]
    ga = g[a]
    # the bend: where the line's members that lie on it or behind it end on that side
    e_lo = np.full(n_g, np.inf)
    e_hi = np.full(n_g, -np.inf)
    np.minimum.at(e_lo, g[~near], s[~near])
    np.maximum.at(e_hi, g[~near], s[~near])
    end = np.where(past_hi[a], e_hi[ga], e_lo[ga])
    ax, ay = cx[ga] + end * ux[ga], cy[ga] + end * uy[ga]
    # every turn of the line's direction at once: the reading at the incidence its beam
    # meets that wall with, and how far off the wall through the end point it then lies
    turn = np.linspace(-BEND_MAX_RAD, BEND_MAX_RAD, BEND_GRID)
    phi = al[ga][:, None] + turn[None, :]
    nx, ny = -np.sin(phi), np.cos(phi)
    th = np.arccos(np.clip(np.abs(ex[a, None] * nx + ey[a, None] * ny), 0.0, 1.0))
    la, b = cal.log_ab(th)
    dd = np.exp(la + b * np.log(s_c[a])[:, None])
    r = (ox[a, None] + dd * ex[a, None] - ax[:, None]) * nx \
        + (oy[a, None] + dd * ey[a, None] - ay[:, None]) * ny
    ok = th < cal.max_incidence_rad
    # a root between two neighbouring turns, both readable: the least turn
    root = ok[:, :-1] & ok[:, 1:] & (np.sign(r[:, :-1]) != np.sign(r[:, 1:]))
    cost = np.where(root, np.abs(turn[:-1] + turn[1:]) * 0.5, np.inf)
    k = np.argmin(cost, axis=1)
    found = np.isfinite(cost[np.arange(a.size), k])
    rows = np.arange(a.size)
    r0, r1 = r[rows, k], r[rows, k + 1]
    f = r0 / np.where(r0 != r1, r0 - r1, 1.0)
    beta = turn[k] + f * (turn[1] - turn[0])
    ph = al[ga] + beta
    th_b = np.arccos(np.clip(np.abs(ex[a] * -np.sin(ph) + ey[a] * np.cos(ph)), 0.0, 1.0))
    lab_b, b_b = cal.log_ab(th_b)
    log_s = np.log(s_c[a])
    d_b = np.exp(lab_b + b_b * log_s)
    lo_t = np.maximum(th_b - BEND_DOUBT_RAD, 0.0)
    hi_t = np.minimum(th_b + BEND_DOUBT_RAD, cal.max_incidence_rad)
    la_lo, b_lo = cal.log_ab(lo_t)
    la_hi, b_hi = cal.log_ab(hi_t)
    spread = np.abs(np.exp(la_lo + b_lo * log_s) - np.exp(la_hi + b_hi * log_s))
    sig = range_sigma(b_b, d_b, sig_s[a]) + 0.5 * spread
    at = idx[a]
    label = label.copy()
    label.reshape(-1)[at] = -1
    points = placed_at(points, at[found], d_b[found], th_b[found], sig[found])
    if not found.all():
        points = invalidated(points, at[~found], Reason.INCIDENCE_UNKNOWN)
    return points, label


def _bend_gate_compiled(points: Points, label: np.ndarray, counts: np.ndarray,
                        steps: np.ndarray, cal: Calibration) -> bool:
    """:func:`_bend_gate` over the members :func:`_bend_members` asks (False where it asks
    none), in one compiled call (``irring.estimation._lines.bend_gate``): the same answer."""
    f = np.ascontiguousarray
    return _lines.bend_gate(
        f(label, dtype=np.intp).reshape(-1),
        f(points.valid, dtype=bool).reshape(-1).view(np.uint8), rows_in_step_order(steps),
        label.shape[1], f(points.x, dtype=float).reshape(-1),
        f(points.y, dtype=float).reshape(-1), f(points.origin_x, dtype=float).reshape(-1),
        f(points.origin_y, dtype=float).reshape(-1), f(points.d, dtype=float).reshape(-1),
        f(points.theta, dtype=float).reshape(-1), f(counts, dtype=float).reshape(-1),
        cal.sigma_counts(), SIGMA_FLOOR_M, f(cal.theta_rad, dtype=float),
        f(cal.b, dtype=float), BEND_MIN, BEND_NEAR_M, BEND_Z)


def bent_ends_compiled(points: Points, label: np.ndarray, counts: np.ndarray,
                       steps: np.ndarray, cal: Calibration) -> tuple[Points, np.ndarray]:
    """:func:`bent_ends`, whose gate is first asked of one compiled call
    (:func:`_bend_gate_compiled`, held to the numpy gate by tests/test_bent_ends.py): where
    it says no, so would numpy's and nothing moves (most sweeps); else :func:`bent_ends`
    itself."""
    if not _bend_gate_compiled(points, label, counts, steps, cal):
        return points, label
    return bent_ends(points, label, counts, steps, cal)


def _kasa_circle(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The least-squares (Kåsa) circle through points: centre x, y and radius."""
    mx, my = x.mean(), y.mean()
    u, v = x - mx, y - my
    w = u * u + v * v
    suu, svv, suv = (u * u).sum(), (v * v).sum(), (u * v).sum()
    suw, svw = (u * w).sum(), (v * w).sum()
    det = suu * svv - suv * suv
    det = det if abs(det) > 1e-18 else 1e-18
    a = 0.5 * (suw * svv - svw * suv) / det
    b = 0.5 * (svw * suu - suw * suv) / det
    return np.array([mx + a, my + b, math.sqrt(a * a + b * b + (suu + svv) / x.size)])


def _bow_circles(x: np.ndarray, y: np.ndarray, g: np.ndarray, n_g: int, good: np.ndarray,
                 strength: np.ndarray) -> np.ndarray:
    """Circles (3, C: centre x, y, radius) through the groups ``good`` (members ``x``, ``y``
    of group ``g``): one fitted to them all, refitted to those whose members lie on it within
    ``BOW_POOL_M`` on average until that holds, then the rest likewise (from the strongest
    (``strength``) where none lies on the circle of all), at most ``BOW_CIRCLES``."""
    nm = np.maximum(np.bincount(g, minlength=n_g), 1)
    left = good.copy()
    circles = []
    while left.any() and len(circles) < BOW_CIRCLES:
        agree = left & False
        for use in (left, np.arange(n_g) == np.flatnonzero(left)[np.argmax(strength[left])]):
            for _ in range(4):
                on = use[g]
                c = _kasa_circle(x[on], y[on])
                res = np.abs(np.hypot(x - c[0], y - c[1]) - c[2])
                agree = left & (np.bincount(g, res, n_g) / nm <= BOW_POOL_M)
                if not agree.any() or np.array_equal(agree, use):
                    break
                use = agree
            if agree.any():
                break
        if not agree.any():
            break
        circles.append(c)
        left &= ~agree
    return np.stack(circles, axis=1) if circles else np.zeros((3, 0))


def bowed_lines(points: Points, label: np.ndarray, counts: np.ndarray, cal: Calibration
                ) -> tuple[Points, np.ndarray]:
    """Line members on a curved wall (a polygonal arc, a round room's many sides) read at
    the incidence their beams meet its circle; numpy, shared by both estimators.

    A line of at least ``BOW_MIN`` valid members is one chord of such a wall: each member
    took the chord's θ, wrong by as much as the wall turns along it. Where its members bow
    (``BOW_PRE_F``), they are read on a parabola in the line's frame by Table II's
    iteration (fit, re-read each at the incidence its beam meets the curve, until θ
    settles); the line is bowed where the parabola then beats it by ``BOW_F`` (F test
    against the parabola's own scatter) and turns by ``BOW_TURN_RAD`` or more at a radius
    within ``BOW_RADIUS_M``. The bowed lines' members make up to ``BOW_CIRCLES`` circles
    (:func:`_bow_circles`), and every line of ``BOW_JOIN_MIN`` valid members or more takes
    the circle its members, read at the θ their beams meet it with, misfit least where that
    is within ``BOW_MISFIT`` on average (σ², each at most ``ARC_MISS``) and at most
    ``BOW_WORSE`` more than their own line (a short line read far along the same wall fits
    its chord as well: the circle's evidence is the long lines'; an ellipse's lines lie off a
    circle fitted elsewhere on it); each circle is refitted to the lines it took and asked
    again, ``BOW_REFITS`` times. A taken line's members whose beams miss the circle are
    INCIDENCE_UNKNOWN (their θ was the line's). The others leave their line (label −1) at
    that θ and are put where their beams meet the circle as :func:`snap_to_lines` puts a
    member on its line (in from behind always, out by at most ``SNAP_SIGMAS`` σ, within the
    range; σ the circle's there plus ``SNAP_OWN`` of their own: their noise and d over
    θ ± ``BOW_DOUBT_RAD``). Returns the points and ``label``. Why: docs/estimator.md,
    "Curved walls"."""
    asked = _bow_asked(points, label, counts, cal)
    if asked is None or not (pre := asked[-1] >= BOW_PRE_F).any():
        return points, label
    (idx, g, n_g, nm, ox, oy, ex, ey, s_c, sig_s, d_line, en, noise, w, ux, uy, cx, cy, s0,
     n0, chi0, _) = asked
    sel = pre[g]
    s0_k, n0_k, chi0_k = s0[sel], n0[sel], chi0[pre]   # (as they lie: the corner test's)
    idx, ox, oy, ex, ey, s_c, sig_s, d_line, en, noise, w, ux, uy = (
        a[sel] for a in (idx, ox, oy, ex, ey, s_c, sig_s, d_line, en, noise, w, ux, uy))
    cx, cy = cx[pre], cy[pre]
    g = (np.cumsum(pre) - 1)[g[sel]]
    n_g = int(np.count_nonzero(pre))
    nm = nm[pre]
    es = ex * ux + ey * uy
    so = (ox - cx[g]) * ux + (oy - cy[g]) * uy
    no = -(ox - cx[g]) * uy + (oy - cy[g]) * ux
    log_s = np.log(s_c)

    def meet(coef, t):
        """Where each beam meets its line's parabola (Newton from t), the incidence there
        and the curve's slope."""
        a, b, c = coef[g, 0], coef[g, 1], coef[g, 2]
        for _ in range(4):
            ss = so + t * es
            f = no + t * en - (a + (b + c * ss) * ss)
            fp = en - (b + 2.0 * c * ss) * es
            t = t - f / np.where(np.abs(fp) > 1e-9, fp, 1e-9)
        m = b + 2.0 * c * (so + t * es)
        cos = np.abs(en - m * es) / np.sqrt(1.0 + m * m)
        return t, np.arccos(np.clip(cos, 0.0, 1.0)), m

    # the line: its members against it (the held iterations' fixed point)
    t, _, _ = meet(np.zeros((n_g, 3)), d_line)
    z = (d_line - t) / noise
    chi_line = np.bincount(g, z * z, n_g)
    # the parabola: Table II's iteration with the curve in place of the line
    d, th = d_line, None
    settled = np.zeros(n_g, dtype=bool)
    for _ in range(BOW_ITERATIONS):
        coef = _bow_fit(g, n_g, so + d * es, no + d * en, w)
        _, th_new, _ = meet(coef, d)
        th_new = np.minimum(th_new, cal.max_incidence_rad)
        settled = (np.bincount(g, np.abs(th_new - th) > BOW_SETTLED_RAD, n_g) == 0
                   if th is not None else settled)
        th = th_new
        la, b = cal.log_ab(th)
        d = np.exp(la + b * log_s)
        if settled.all():
            break
    coef = _bow_fit(g, n_g, so + d * es, no + d * en, w)
    t, _, m = meet(coef, d)
    z = (d - t) / range_sigma(b, d, sig_s)
    chi_par = np.bincount(g, z * z, n_g)
    ang = np.arctan(m)
    lo, hi = np.full(n_g, np.inf), np.full(n_g, -np.inf)
    np.minimum.at(lo, g, ang)
    np.maximum.at(hi, g, ang)
    radius = 1.0 / np.maximum(np.abs(2.0 * coef[:, 2]), 1e-12)
    F = (chi_line - chi_par) / np.maximum(chi_par / np.maximum(nm - 3, 1), 1.0)
    good = (settled & (F >= BOW_F) & (hi - lo >= BOW_TURN_RAD) & (radius >= BOW_RADIUS_M[0])
            & (radius <= BOW_RADIUS_M[1])
            & (np.bincount(g, ~(np.isfinite(t) & (t > 0)), n_g) == 0))
    # a line over a corner bows too: two straight pieces that fit its members clearly
    # better than the parabola make it a corner, not a curve
    good &= ~_kinked(g, n_g, s0_k, n0_k, w, chi0_k, good)
    if not good.any():
        return points, label
    circ = _bow_circles(ox + d * ex, oy + d * ey, g, n_g, good, F)
    if circ.shape[1] == 0:
        return points, label
    return _onto_bow_circles(points, label, counts, cal, circ)


def bowed_lines_compiled(points: Points, label: np.ndarray, counts: np.ndarray,
                         cal: Calibration) -> tuple[Points, np.ndarray]:
    """:func:`bowed_lines`, whose pre-gate (:func:`_bow_asked`: do a line's members as they
    lie bow?) is first asked of one compiled call (``irring.estimation._lines.bow_pre_f``,
    held to it by tests/test_curved_walls.py): where its F, widened by ``BOW_PRE_TOL``,
    passes no line, neither would numpy's and nothing bows (most sweeps)."""
    f = np.ascontiguousarray
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        F, scale = _lines.bow_pre_f(
            f(label, dtype=np.intp).reshape(-1),
            f(points.valid, dtype=bool).reshape(-1).view(np.uint8),
            f(points.origin_x, dtype=float).reshape(-1),
            f(points.origin_y, dtype=float).reshape(-1),
            f(points.heading, dtype=float).reshape(-1), f(counts, dtype=float).reshape(-1),
            f(points.d, dtype=float).reshape(-1), f(points.theta, dtype=float).reshape(-1),
            cal.sigma_counts(), SIGMA_FLOOR_M, f(cal.theta_rad, dtype=float),
            f(cal._log_a, dtype=float), f(cal.b, dtype=float), BOW_MIN)
    if not (F + BOW_PRE_TOL * (1.0 + scale) >= BOW_PRE_F).any():
        return points, label
    return bowed_lines(points, label, counts, cal)


def _bow_asked(points: Points, label: np.ndarray, counts: np.ndarray, cal: Calibration):
    """:func:`bowed_lines`' pre-gate: None where no line has ``BOW_MIN`` valid members;
    else per member of those lines (flat index ``idx``, line ``g``) its beam, where it lies
    in its line's frame (the TLS line of its members: centre (cx, cy), direction (ux, uy);
    s0 along, n0 across) and its weight ``w``, and per line the χ² ``chi0`` of a weighted
    parabola through its members as they lie and the F (the last item) by which it beats
    that line."""
    flat = label.reshape(-1)
    valid = points.valid.reshape(-1)
    idx = ((flat >= 0) & valid).nonzero()[0]
    if idx.size < BOW_MIN:
        return None
    lab = flat[idx]
    ask = np.bincount(lab) >= BOW_MIN
    if not ask.any():
        return None
    sel = ask[lab]
    idx = idx[sel]
    g = (np.cumsum(ask) - 1)[lab[sel]]
    n_g = int(np.count_nonzero(ask))
    nm = np.bincount(g, minlength=n_g).astype(float)
    ox, oy = points.origin_x.reshape(-1)[idx], points.origin_y.reshape(-1)[idx]
    h = points.heading.reshape(-1)[idx]
    ex, ey = np.cos(h), np.sin(h)
    s_c = np.asarray(counts, dtype=float).reshape(-1)[idx]
    d_line = points.d.reshape(-1)[idx]
    x, y = ox + d_line * ex, oy + d_line * ey
    # each line's frame: its members' TLS line; s along it, n across
    cx, cy = np.bincount(g, x, n_g) / nm, np.bincount(g, y, n_g) / nm
    u, v = x - cx[g], y - cy[g]
    al = 0.5 * np.arctan2(2.0 * np.bincount(g, u * v, n_g), np.bincount(g, u * u - v * v, n_g))
    ux, uy = np.cos(al)[g], np.sin(al)[g]
    en = -ex * uy + ey * ux
    sig_s = cal.sigma_counts() / s_c
    noise = range_sigma(cal.log_ab(points.theta.reshape(-1)[idx])[1], d_line, sig_s)
    w = 1.0 / np.maximum(noise * np.abs(en), SIGMA_FLOOR_M) ** 2
    # asked further only where the members as they lie already bow (one fit)
    s0, n0 = u * ux + v * uy, -u * uy + v * ux
    c0 = _bow_fit(g, n_g, s0, n0, w)
    r0 = n0 - (c0[g, 0] + (c0[g, 1] + c0[g, 2] * s0) * s0)
    chi0 = np.bincount(g, w * r0 * r0, n_g)
    F = ((np.bincount(g, w * n0 * n0, n_g) - chi0)
         / np.maximum(chi0 / np.maximum(nm - 3, 1), 1.0))
    return (idx, g, n_g, nm, ox, oy, ex, ey, s_c, sig_s, d_line, en, noise, w, ux, uy, cx, cy,
            s0, n0, chi0, F)


def _onto_bow_circles(points: Points, label: np.ndarray, counts: np.ndarray,
                      cal: Calibration, circ: np.ndarray) -> tuple[Points, np.ndarray]:
    """:func:`bowed_lines`' second half: every line of ``BOW_JOIN_MIN`` valid members or more
    read on the circle ``circ`` (3, C) it fits best, where it fits, and put on it."""
    flat = label.reshape(-1)
    idx = ((flat >= 0) & points.valid.reshape(-1)).nonzero()[0]
    g = np.unique(flat[idx], return_inverse=True)[1]
    n_g = int(g.max()) + 1
    nm = np.bincount(g, minlength=n_g)
    ox, oy = points.origin_x.reshape(-1)[idx], points.origin_y.reshape(-1)[idx]
    h = points.heading.reshape(-1)[idx]
    ex, ey = np.cos(h), np.sin(h)
    s_c = np.asarray(counts, dtype=float).reshape(-1)[idx]
    sig_s = cal.sigma_counts() / s_c
    # each line's own misfit: its members against their TLS line where they lie
    d_now = points.d.reshape(-1)[idx]
    x, y = ox + d_now * ex, oy + d_now * ey
    nm_f = np.maximum(nm, 1)
    mx, my = np.bincount(g, x, n_g) / nm_f, np.bincount(g, y, n_g) / nm_f
    u, v = x - mx[g], y - my[g]
    al = 0.5 * np.arctan2(2.0 * np.bincount(g, u * v, n_g), np.bincount(g, u * u - v * v, n_g))
    nx, ny = -np.sin(al)[g], np.cos(al)[g]
    cos_b = ex * nx + ey * ny
    t_line = ((mx[g] - ox) * nx + (my[g] - oy) * ny) / np.where(np.abs(cos_b) > 1e-9, cos_b,
                                                                1e-9)
    _, b_now = cal.log_ab(points.theta.reshape(-1)[idx])
    z_line = (d_now - t_line) / range_sigma(b_now, d_now, sig_s)
    own = np.bincount(g, np.minimum(z_line * z_line, ARC_MISS), n_g) / nm_f
    log_s = np.log(s_c)
    cols = np.arange(n_g)
    fits = np.zeros(n_g, dtype=bool)
    for _ in range(BOW_REFITS + 1):
        # each beam on each circle: ahead of it, from inside (a room's wall) or outside (a bay)
        rx, ry = circ[0][:, None] - ox, circ[1][:, None] - oy          # (C, M)
        along = rx * ex + ry * ey
        r = circ[2][:, None]
        inside = rx * rx + ry * ry < r * r
        disc = along * along - (rx * rx + ry * ry - r * r)
        root = np.sqrt(np.maximum(disc, 0.0))
        t = np.where(inside, along + root, along - root)
        th = np.arccos(np.clip(np.abs((t * ex - rx) * ex + (t * ey - ry) * ey) / r, 0.0, 1.0))
        meets = (disc > 0.0) & (t > 0.0) & (th <= cal.max_incidence_rad)
        la, b = cal.log_ab(np.minimum(th, cal.max_incidence_rad))
        dd = np.exp(la + b * log_s)
        noise = range_sigma(b, dd, sig_s)
        z = (dd - t) / noise
        mis = np.where(meets, np.minimum(z * z, ARC_MISS), ARC_MISS)
        cost = np.stack([np.bincount(g, m_, n_g) for m_ in mis]) / nm_f   # (C, L)
        best = np.argmin(cost, axis=0)
        c_best = cost[best, cols]
        # … where it fits, and no worse than its own line (an ellipse's or an irregular
        # polygon's lines lie off a circle fitted elsewhere on it; a chord fits both alike)
        now = (c_best <= BOW_MISFIT) & (c_best <= own + BOW_WORSE) & (nm >= BOW_JOIN_MIN)
        if np.array_equal(now, fits):
            break
        fits = now
        # the circles refitted to the lines they took, read at their θ
        for k in range(circ.shape[1]):
            on = (fits & (best == k))[g] & meets[k]
            if np.count_nonzero(on) >= BOW_MIN:
                circ[:, k] = _kasa_circle((ox + dd[k] * ex)[on], (oy + dd[k] * ey)[on])
    taken = fits[g]
    if not taken.any():
        return points, label
    on_circle = taken & meets[best[g], np.arange(idx.size)]
    # a taken line's members whose beams miss its circle (past the drop-out angle) keep no
    # θ: theirs came from the line, now on the circle
    gone = idx[taken & ~on_circle]
    label = label.copy()
    label.reshape(-1)[idx[taken]] = -1
    if gone.size:
        points = invalidated(points, gone, Reason.INCIDENCE_UNKNOWN)
    j = on_circle.nonzero()[0]
    if j.size == 0:
        return points, label
    c = best[g[j]]
    at = idx[j]
    th_t, d_t, s_t = th[c, j], dd[c, j], s_c[j]
    lo_d = cal.distance(s_t, np.maximum(th_t - BOW_DOUBT_RAD, 0.0))
    hi_d = cal.distance(s_t, np.minimum(th_t + BOW_DOUBT_RAD, cal.max_incidence_rad))
    sig = np.hypot(noise[c, j], 0.5 * np.abs(lo_d - hi_d))
    points = placed_at(points, at, d_t, th_t, sig)
    # onto the circle: its uncertainty there from its readings' radial scatter
    t_c = t[c, j]
    radial = np.abs(np.hypot(ox[j] + d_t * ex[j] - circ[0][c], oy[j] + d_t * ey[j] - circ[1][c])
                    - circ[2][c])
    n_on = np.maximum(np.bincount(c, minlength=circ.shape[1]), 1)
    rms = np.sqrt(np.bincount(c, radial * radial, circ.shape[1]) / n_on)
    fit = rms[c] / np.sqrt(n_on[c]) / np.maximum(np.cos(th_t), 0.1)
    on = ((t_c - d_t <= SNAP_SIGMAS * sig) & (t_c >= cal.min_range_m)
          & (t_c <= points.max_range_m))
    if on.any():
        sig_on = np.maximum(np.hypot(fit, SNAP_OWN * sig), SIGMA_FLOOR_M)
        points = placed_at(points, at[on], t_c[on], th_t[on], sig_on[on])
    return points, label


CONCAVE_RADII_M = (0.25, 2.5)  # a curved wall's circle: radii from this to this …
CONCAVE_ITERATIONS = 8         # … its members read at its incidence and it refitted (at most)
CONCAVE_FIT_Z = 2.0            # … it fits them within this reduced χ² (their noise) …
CONCAVE_MIN_LINES = 3          # … and joins at least this many lines (two: a corner's walls) …
# … and, by BIC, better than its lines: a χ² lower by the log of its members per parameter
# saved (a circle 3 for 2 per line)


def _circle_fit(x: np.ndarray, y: np.ndarray, w: np.ndarray, start) -> tuple | None:
    """The circle (cx, cy, r) nearest points ``x``, ``y`` (m) with weights ``w`` (1/σ²
    across it): Gauss–Newton on the geometric distance from ``start`` (cx, cy, r); None
    where it does not settle."""
    cx, cy, r = (float(v) for v in start)
    for _ in range(30):
        dx, dy = x - cx, y - cy
        rho = np.maximum(np.hypot(dx, dy), 1e-9)
        jac = np.stack([-dx / rho, -dy / rho, -np.ones_like(rho)], axis=1)
        res = rho - r
        a = jac.T @ (jac * w[:, None])
        try:
            step = np.linalg.solve(a, -(jac.T @ (w * res)))
        except np.linalg.LinAlgError:
            return None
        cx, cy, r = cx + step[0], cy + step[1], r + step[2]
        if not np.all(np.isfinite((cx, cy, r))):
            return None
        if np.abs(step).max() < 1e-7:
            return cx, cy, r
    return None


def _beam_meets_circle(ox, oy, ux, uy, cx, cy, r):
    """(t, cos θ) where beams from inside a circle meet it going out: distance (m) and the
    cosine of the incidence (beam against the radius there)."""
    fx, fy = ox - cx, oy - cy
    b = fx * ux + fy * uy
    t = -b + np.sqrt(np.maximum(b * b - (fx * fx + fy * fy - r * r), 0.0))
    cos = np.abs(ux * (fx + t * ux) + uy * (fy + t * uy)) / r
    return t, np.clip(cos, 0.0, 1.0)


def _read_on_circle(group, ox, oy, ux, uy, s, cal, circle):
    """Self-consistent circle of readings ``group``: each read at the incidence where its
    beam meets the circle, the circle refitted to those end points, ``CONCAVE_ITERATIONS``
    times. Returns (circle, χ², θ) or None where it leaves the radii, the ring or the
    drop-out angle."""
    lo, hi = CONCAVE_RADII_M
    for _ in range(CONCAVE_ITERATIONS):
        cx, cy, r = circle
        if np.any(np.hypot(ox[group] - cx, oy[group] - cy) >= r):
            return None
        t, cos = _beam_meets_circle(ox[group], oy[group], ux[group], uy[group], cx, cy, r)
        theta = np.arccos(cos)
        if np.any(theta > cal.max_incidence_rad):
            return None
        d = np.asarray(cal.distance(s[group], theta), dtype=float)
        _, b = cal.log_ab(theta)
        sigma = range_sigma(b, d, cal.sigma_counts() / s[group]) * cos
        w = 1.0 / np.maximum(sigma, 1e-6) ** 2
        x, y = ox[group] + d * ux[group], oy[group] + d * uy[group]
        fit = _circle_fit(x, y, w, circle)
        if fit is None:
            return None
        settled = max(abs(a - b) for a, b in zip(fit, circle)) < 1e-6
        circle = fit
        if settled:
            break
    cx, cy, r = circle
    if not lo <= r <= hi or np.any(np.hypot(ox[group] - cx, oy[group] - cy) >= r):
        return None
    t, cos = _beam_meets_circle(ox[group], oy[group], ux[group], uy[group], cx, cy, r)
    theta = np.arccos(cos)
    if np.any(theta > cal.max_incidence_rad):
        return None
    chi2 = float(np.sum(w * (np.hypot(x - cx, y - cy) - r) ** 2))
    return circle, chi2, theta


def _line_chi2(group, ox, oy, ux, uy, s, cal, theta):
    """χ² of readings ``group`` about their own line, each read at its line's θ (TLS)."""
    d = np.asarray(cal.distance(s[group], theta[group]), dtype=float)
    _, b = cal.log_ab(theta[group])
    sigma = range_sigma(b, d, cal.sigma_counts() / s[group]) * np.cos(theta[group])
    w = 1.0 / np.maximum(sigma, 1e-6) ** 2
    x, y = ox[group] + d * ux[group], oy[group] + d * uy[group]
    mx, my = np.average(x, weights=w), np.average(y, weights=w)
    u, v = x - mx, y - my
    alpha = 0.5 * np.arctan2(2.0 * np.sum(w * u * v), np.sum(w * (u * u - v * v)))
    perp = -u * np.sin(alpha) + v * np.cos(alpha)
    return float(np.sum(w * perp * perp))


def onto_concave_arcs(p: Points, label: np.ndarray, counts: np.ndarray, cal: Calibration,
                      own_cap_m: float = math.inf) -> Points:
    """``p`` with the members of neighbouring lines (``label``, −1 none; lines of at least
    ``SNAP_MIN`` valid members) that one circle around the ring fits better put on it: a
    curved wall made of straight pieces (a round room, a bay), which lines fit each over
    several pieces, their θ 10–30° off the pieces' and their members 20–40 mm long (2–6σ).
    Lines are joined in the order of their bearing from the ring's centre while their
    members, each read at the incidence where its beam meets the circle
    (:func:`_read_on_circle`), fit it within ``CONCAVE_FIT_Z`` reduced χ² and, by BIC,
    better than the lines did; the circle encloses every emitter (a wall seen from inside,
    never a post) with a radius within ``CONCAVE_RADII_M``. Each member its own reading at the
    circle's incidence puts within ``SNAP_SIGMAS`` of it is then put where its beam meets the
    circle, at that incidence, its σ the circle's uncertainty there with half its own (at
    most ``own_cap_m``), as :func:`snap_to_lines` puts a line's. ``counts`` (S, N): the counts the lines were read
    from. numpy, shared by both estimators. docs/foldover.md, "Curved walls"."""
    member = p.valid & (label >= 0)
    if not member.any():
        return p
    n_lines = int(label[member].max()) + 1
    size = np.bincount(label[member], minlength=n_lines)
    lines = (size >= SNAP_MIN).nonzero()[0]
    if lines.size == 0:
        return p
    ox, oy = p.origin_x.reshape(-1), p.origin_y.reshape(-1)
    ux, uy = np.cos(p.heading).reshape(-1), np.sin(p.heading).reshape(-1)
    s = np.asarray(counts, dtype=float).reshape(-1)
    theta = np.asarray(p.theta, dtype=float).reshape(-1)
    lab = np.where(member, label, -1).reshape(-1)
    idx = [np.flatnonzero(lab == k) for k in lines]
    centre = np.array([np.mean(ox), np.mean(oy)])      # the ring's (its emitters' mean)
    bearing = np.array([math.atan2(np.mean(p.y.reshape(-1)[i]) - centre[1],
                                   np.mean(p.x.reshape(-1)[i]) - centre[0]) for i in idx])
    order = np.argsort(bearing)
    chi_line = np.array([_line_chi2(i, ox, oy, ux, uy, s, cal, theta) for i in idx])
    taken = []          # (lines, readings, circle, χ², θ) per circle kept
    k = 0
    while k < order.size:
        best = None
        for stop in range(k + CONCAVE_MIN_LINES, order.size + 1):
            trial = order[k:stop]
            group = np.concatenate([idx[j] for j in trial])
            # from the circle one line fewer took, else the circle about the ring's centre
            # through the lines' mean range
            start = best[2] if best is not None else (centre[0], centre[1], float(np.mean(
                np.hypot(p.x.reshape(-1)[group] - centre[0],
                         p.y.reshape(-1)[group] - centre[1]))))
            got = _read_on_circle(group, ox, oy, ux, uy, s, cal, start)
            if got is None or got[1] / max(group.size - 3, 1) > CONCAVE_FIT_Z:
                break
            circle, chi2, th = got
            n = group.size
            saved = 2 * trial.size - 3          # parameters the circle saves over the lines
            lines_chi = float(chi_line[trial].sum())
            # the noise scale the lines leave (a pooled reading's σ overstates its scatter)
            scale = max(lines_chi / max(n - 2 * trial.size, 1), 1e-6)
            if (chi2 - lines_chi) / scale > saved * math.log(n):
                break
            best = (trial, group, circle, chi2, th)
        if best is None:
            k += 1
            continue
        taken.append(best)
        k += best[0].size
    if not taken:
        return p
    x, y, d, th, sg = (np.array(v, dtype=float).reshape(-1)
                       for v in (p.x, p.y, p.d, p.theta, p.sigma_m))
    for trial, group, (cx, cy, r), chi2, theta_c in taken:
        t, cos = _beam_meets_circle(ox[group], oy[group], ux[group], uy[group], cx, cy, r)
        own = np.asarray(cal.distance(s[group], theta_c), dtype=float)
        _, b = cal.log_ab(theta_c)
        noise = range_sigma(b, own, cal.sigma_counts() / s[group])
        w = 1.0 / np.maximum(noise * cos, 1e-6) ** 2
        se = math.sqrt(max(chi2 / max(group.size - 3, 1), 1.0) * 3.0 / float(w.sum()))
        # as onto a line (snap_to_lines): a member its own reading puts within 3σ of it
        on = np.abs(own - t) <= SNAP_SIGMAS * noise
        g, t, cos, noise = group[on], t[on], cos[on], noise[on]
        d[g], th[g] = t, theta_c[on]
        x[g], y[g] = ox[g] + t * ux[g], oy[g] + t * uy[g]
        sg[g] = np.hypot(se / np.maximum(cos, 1e-3), np.minimum(SNAP_OWN * noise, own_cap_m))
    shape = p.valid.shape
    return points_with(p, x=x.reshape(shape), y=y.reshape(shape), d=d.reshape(shape),
                       theta=th.reshape(shape), sigma_m=sg.reshape(shape))


FACET_MIN = 12          # a snapped line of at least this many moved members is asked …
FACET_SIDE = 6          # … for its best split into two pieces of at least this many each …
FACET_F = 5.0           # … that beat the line by this F (2, n − 4) as the members lie …
FACET_CHI = 15.0        # … and by this χ² against the members' own σ (pooled far readings
# share their noise: their scatter is 0.06-0.3 σ², so F alone splits a straight wall there) …
FACET_TURN_RAD = math.radians(5)   # … and turn by this much (a straight wall's noise: less)
FACET_ITERATIONS = 4    # each piece then read by Table II's iteration, this many steps
FACET_PRE_TOL = 1e-6    # (the compiled pre-gate's F, gain and turn, within this × (1 + scale))


def faceted_lines(before: Points, label: np.ndarray, after: Points, cal: Calibration
                  ) -> Points:
    """A snapped line over a many-sided wall's facets read as two pieces; numpy, shared by
    both estimators, after the snap.

    ``before`` and ``after``: the points as :func:`snap_to_lines` took and returned them,
    ``label`` the lines it fitted. The members the snap moved, of a line of at least
    ``FACET_MIN`` of them, are split at their best place along the line (``FACET_SIDE`` a
    piece at least; weighted least squares in the line's frame, every line at once by
    prefix sums); where the pieces beat the line by ``FACET_F`` (against their scatter) and
    ``FACET_CHI`` (against their σ) as the members lie and turn by ``FACET_TURN_RAD`` or more,
    each piece is read by Table II's iteration
    (``FACET_ITERATIONS`` steps: fit, re-read each member at the incidence its beam meets
    the piece with) and its members are put where their beams meet it (at most
    ``SNAP_SIGMAS`` of their own σ from where they were read, within the range; θ and σ as
    the snap left them). A line over 2–4 facets of a round room, straight through their
    bends, puts its members up to 20–30 mm off them at 0.6 m: 3–5 cells of 5 mm. Why:
    docs/estimator.md, "A line over facets"."""
    asked = _facet_asked(before, label, after)
    if asked is None:
        return after
    (idx, g, ox, oy, ex, ey, d0, sig, cx, cy, ux, uy, order, gs, w, at, best, split, F, gain,
     turn) = asked
    good = (np.isfinite(split) & (F >= FACET_F) & (gain >= FACET_CHI)
            & (turn >= FACET_TURN_RAD))
    if not good.any():
        return after
    # the pieces (two a good line), each read by Table II's iteration
    keep = good[gs]
    piece = 2 * gs + (at >= best[gs])
    o = order[keep]
    piece = np.unique(piece[keep], return_inverse=True)[1]
    n_p = int(piece.max()) + 1
    gk = g[o]
    es = ex[o] * ux[o] + ey[o] * uy[o]
    en = -ex[o] * uy[o] + ey[o] * ux[o]
    so = (ox[o] - cx[gk]) * ux[o] + (oy[o] - cy[gk]) * uy[o]
    no = -(ox[o] - cx[gk]) * uy[o] + (oy[o] - cy[gk]) * ux[o]
    wk = w[keep]
    la0, b0 = cal.log_ab(before.theta.reshape(-1)[idx[o]])
    log_s = (np.log(d0[o]) - la0) / b0           # the reading as the estimator read it
    d = d0[o]
    for step in range(FACET_ITERATIONS + 1):
        ps, pr = so + d * es, no + d * en
        W, S, S2, R, SR = (np.bincount(piece, wk * q, n_p) for q in
                           (np.ones_like(ps), ps, ps * ps, pr, ps * pr))
        den = W * S2 - S * S
        with np.errstate(divide="ignore", invalid="ignore"):
            m_p = np.where(den > 1e-18, (W * SR - S * R) / den, 0.0)
            m, c = m_p[piece], ((R - m_p * S) / W)[piece]
        if step == FACET_ITERATIONS:
            break
        cos = np.abs(en - m * es) / np.sqrt(1.0 + m * m)
        la, b = cal.log_ab(np.minimum(np.arccos(np.clip(cos, 0.0, 1.0)),
                                      cal.max_incidence_rad))
        d = np.exp(la + b * log_s)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (c + m * so - no) / (en - m * es)
    flat_at = idx[o]
    # (a piece's noise-tilted end read 100 mm off on a straight wall: no member moves more
    # than the snap would move it out)
    ok = (np.isfinite(t) & (t >= cal.min_range_m) & (t <= before.max_range_m)
          & (np.abs(t - d0[o]) <= SNAP_SIGMAS * sig[o]))
    if not ok.any():
        return after
    flat_at, t = flat_at[ok], t[ok]
    out = {f: np.array(getattr(after, f)) for f in ("x", "y", "d")}
    out["d"].reshape(-1)[flat_at] = t
    out["x"].reshape(-1)[flat_at] = before.origin_x.reshape(-1)[flat_at] + t * np.cos(
        before.heading.reshape(-1)[flat_at])
    out["y"].reshape(-1)[flat_at] = before.origin_y.reshape(-1)[flat_at] + t * np.sin(
        before.heading.reshape(-1)[flat_at])
    return points_with(after, **out)


def faceted_lines_compiled(before: Points, label: np.ndarray, after: Points,
                           cal: Calibration) -> Points:
    """:func:`faceted_lines`, whose split search (:func:`_facet_asked`) is first asked of
    one compiled call (``irring.estimation._lines.facet_pre``, held to it by
    tests/test_faceted_lines.py): where its F, χ² gain and turn, each widened by
    ``FACET_PRE_TOL``, pass no line, neither would numpy's and nothing is split (most
    sweeps); else :func:`faceted_lines` itself."""
    f = np.ascontiguousarray
    may = _lines.facet_pre(
        f(label, dtype=np.intp).reshape(-1),
        f(before.valid, dtype=bool).reshape(-1).view(np.uint8),
        f(before.d, dtype=float).reshape(-1), f(after.d, dtype=float).reshape(-1),
        f(before.sigma_m, dtype=float).reshape(-1), f(after.sigma_m, dtype=float).reshape(-1),
        f(before.origin_x, dtype=float).reshape(-1), f(before.origin_y, dtype=float).reshape(-1),
        f(before.heading, dtype=float).reshape(-1), SIGMA_FLOOR_M, FACET_MIN, FACET_SIDE,
        FACET_F, FACET_CHI, FACET_TURN_RAD, FACET_PRE_TOL)[-1]
    if not may.any():
        return after
    return faceted_lines(before, label, after, cal)


def _facet_asked(before: Points, label: np.ndarray, after: Points):
    """:func:`faceted_lines`' split search, numpy (the statement the compiled pre-gate
    ``_lines.facet_pre`` is held to): None where no line has ``FACET_MIN`` members the snap
    moved; else per such member (flat index ``idx``, line ``g``) its beam, reading and σ,
    its line's centre and direction, the members' order along their lines (``order``,
    ``gs``: sorted by line then ``s``), their weights ``w`` and sorted places ``at``; and per
    line its best split (``best``, a sorted place: the first member of the right-hand
    piece), that split's χ² ``split``, the F and χ² ``gain`` by which it beats the line and
    how much its pieces ``turn`` (rad)."""
    flat = label.reshape(-1)
    d0_all, sig_all = before.d.reshape(-1), before.sigma_m.reshape(-1)
    with np.errstate(invalid="ignore"):
        moved = ((flat >= 0) & before.valid.reshape(-1)
                 & ((after.d.reshape(-1) != d0_all) | (after.sigma_m.reshape(-1) != sig_all)))
    idx = moved.nonzero()[0]
    if idx.size < FACET_MIN:
        return None
    ask = np.bincount(flat[idx]) >= FACET_MIN
    if not ask.any():
        return None
    idx = idx[ask[flat[idx]]]
    g = np.unique(flat[idx], return_inverse=True)[1]
    n_g = int(g.max()) + 1
    nm = np.bincount(g, minlength=n_g).astype(float)
    ox, oy = before.origin_x.reshape(-1)[idx], before.origin_y.reshape(-1)[idx]
    h = before.heading.reshape(-1)[idx]
    ex, ey = np.cos(h), np.sin(h)
    d0, sig = d0_all[idx], sig_all[idx]
    x, y = ox + d0 * ex, oy + d0 * ey
    cx, cy = np.bincount(g, x, n_g) / nm, np.bincount(g, y, n_g) / nm
    u, v = x - cx[g], y - cy[g]
    al = 0.5 * np.arctan2(2.0 * np.bincount(g, u * v, n_g), np.bincount(g, u * u - v * v, n_g))
    ux, uy = np.cos(al)[g], np.sin(al)[g]
    s, r = u * ux + v * uy, -u * uy + v * ux
    order = np.lexsort((s, g))
    gs, ss, rs = g[order], s[order], r[order]
    w = 1.0 / np.maximum(sig[order], SIGMA_FLOOR_M) ** 2
    cum = [np.concatenate(([0.0], np.cumsum(w * q))) for q in
           (np.ones_like(ss), ss, ss * ss, rs, ss * rs, rs * rs)]
    start = np.searchsorted(gs, np.arange(n_g))
    end = np.append(start[1:], gs.size)

    def fit(a, b):
        """Weighted least-squares line of sorted members a … b − 1: (χ², slope); NaN where
        they are fewer than two (the split search masks those)."""
        W, S, S2, R, SR, R2 = (q[b] - q[a] for q in cum)
        with np.errstate(divide="ignore", invalid="ignore"):
            sss, ssr = S2 - S * S / W, SR - S * R / W
            m = ssr / sss
            return np.maximum(R2 - R * R / W - ssr * m, 0.0), m

    # every sorted member as the first of a right-hand piece; the best per line
    at = np.arange(gs.size)
    lo, hi = start[gs], end[gs]
    can = (at - lo >= FACET_SIDE) & (hi - at >= FACET_SIDE)
    chi_l, m_l = fit(lo, at)
    chi_r, m_r = fit(at, hi)
    both = np.where(can, chi_l + chi_r, np.inf)
    best = np.lexsort((both, gs))[start]            # each line's least χ² split
    chi0 = fit(start, end)[0]
    split = both[best]
    with np.errstate(divide="ignore", invalid="ignore"):
        F = (chi0 - split) / 2.0 / np.maximum(split / np.maximum(nm - 4, 1), 1e-300)
        gain = chi0 - split
    turn = np.abs(np.arctan(m_r[best]) - np.arctan(m_l[best]))
    return (idx, g, ox, oy, ex, ey, d0, sig, cx, cy, ux, uy, order, gs, w, at, best, split, F,
            gain, turn)


REREAD_GRID_RAD = np.radians(np.arange(-30.0, 30.5, 1.0))   # a piece's direction: searched
REREAD_FINE_RAD = np.radians(np.arange(-1.0, 1.05, 0.1))    # … on this grid, then this one
REREAD_SURE_RAD = math.radians(5)  # a piece is placed where its χ² rises this far either
REREAD_SURE_CHI = 4.0   # … side of its direction by this much (2σ: its members orient it)
REREAD_ROUNDS = 2       # a piece split again this often at most (a line over 3–4 facets)
REREAD_SMALL_MIN = 6    # a line of at least this many members no such split fits is asked
REREAD_SMALL_SIDE = 3   # again for a piece of this many up to FACET_SIDE − 1 (a few members
REREAD_SMALL_CHI = 8.0  # of the next facet) and a gain of this much (FACET_F as before)


def _reread_table(ox, oy, ux, uy, s, cal, alpha):
    """Each member read at the incidence a line of direction ``alpha`` (K,) gives its beam:
    (K, n) offsets along the line's normal, weights (1/σ² across it; 0 past the drop-out
    angle), θ and distance."""
    a = np.asarray(alpha, dtype=float)[:, None]
    nx, ny = -np.sin(a), np.cos(a)
    cos = np.abs(ux * nx + uy * ny)
    theta = np.arccos(np.clip(cos, 0.0, 1.0))
    d = np.asarray(cal.distance(np.broadcast_to(s, theta.shape), theta), dtype=float)
    _, b = cal.log_ab(theta)
    sig = range_sigma(b, d, cal.sigma_counts() / s) * cos
    w = np.where(theta > cal.max_incidence_rad, 0.0, 1.0 / np.maximum(sig, 1e-6) ** 2)
    return (ox + d * ux) * nx + (oy + d * uy) * ny, w, theta, d


def _reread_split(r, w, lo, hi, side):
    """Best split of sorted members lo … hi − 1 into two pieces of ``side`` at least, every
    piece's direction its own (the grid row of least χ²): (χ² one line, χ² split, split
    index, row left, row right, whether both pieces' own members orient them
    (:func:`_determined`)), split index None where none fits."""
    rr, ww = r[:, lo:hi], w[:, lo:hi]
    zero = np.zeros((rr.shape[0], 1))
    cw, c1, c2 = (np.concatenate([zero, np.cumsum(q, axis=1)], axis=1)
                  for q in (ww, ww * rr, ww * rr * rr))
    cz = np.concatenate([zero, np.cumsum(ww == 0.0, axis=1)], axis=1)

    def chi(a, b):   # (K, m) χ² of pieces a … b − 1 (arrays of indices into the prefix sums)
        W, S, S2 = cw[:, b] - cw[:, a], c1[:, b] - c1[:, a], c2[:, b] - c2[:, a]
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.maximum(S2 - S * S / W, 0.0)
        return np.where((cz[:, b] - cz[:, a] > 0) | ~(W > 0), np.inf, out)

    n = hi - lo
    one = chi(np.array([0]), np.array([n]))[:, 0]
    k = np.arange(side, n - side + 1)
    if k.size == 0:
        return float(one.min()), math.inf, None, int(np.argmin(one)), 0, False
    left, right = chi(np.zeros_like(k), k), chi(k, np.full_like(k, n))
    tot = left.min(axis=0) + right.min(axis=0)
    j = int(np.argmin(tot))
    a, b = int(np.argmin(left[:, j])), int(np.argmin(right[:, j]))
    return (float(one.min()), float(tot[j]), lo + int(k[j]), a, b,
            min(_determined(left[:, j], a), _determined(right[:, j], b)) >= REREAD_SURE_CHI)


def _piece_chi(r, w):
    """(K,) offset and χ² of one piece's members (``r``, ``w`` (K, m): :func:`_reread_table`'s
    offsets and weights) at each of K directions; χ² inf where a member is past the drop-out
    angle."""
    with np.errstate(divide="ignore", invalid="ignore"):
        c = (w * r).sum(axis=1) / w.sum(axis=1)
        return c, np.where((w == 0).any(axis=1), np.inf, (w * (r - c[:, None]) ** 2).sum(axis=1))


def _determined(chi, at):
    """The least rise of a piece's χ² (over the direction grid) ``REREAD_SURE_RAD`` either
    side of its least, ``at``: how well its own members fix its direction (one sensor's
    trace alone does not: its range and incidence trade against each other)."""
    step = int(round(REREAD_SURE_RAD / (REREAD_GRID_RAD[1] - REREAD_GRID_RAD[0])))
    lo, hi = at - step, at + step
    rise = [chi[i] - chi[at] for i in (lo, hi) if 0 <= i < chi.size]
    return min(rise) if rise else 0.0


def _bends_round(left, right, alphas, ox, oy, ux, uy, s, cal, centre):
    """Whether two pieces (members ``left``, ``right``, each read at its direction of
    ``alphas``) bend round the ring as a wall seen from inside does (a round room's facets):
    each piece's members lie on the ring's side of the other piece's line."""
    pts = []
    for m, a in zip((left, right), alphas):
        d = _reread_table(ox[m], oy[m], ux[m], uy[m], s[m], cal, np.array([a]))[3][0]
        pts.append((ox[m] + d * ux[m], oy[m] + d * uy[m]))
    for (x0, y0), (x1, y1), a in ((pts[0], pts[1], alphas[0]), (pts[1], pts[0], alphas[1])):
        nx, ny = -math.sin(a), math.cos(a)
        c = float(np.mean(x0 * nx + y0 * ny))
        if (centre[0] * nx + centre[1] * ny - c) * (float(np.mean(x1 * nx + y1 * ny)) - c) <= 0:
            return False
    return True


def facets_reread(p: Points, label: np.ndarray, counts: np.ndarray, cal: Calibration
                  ) -> Points:
    """``p`` with the members of a line (``label``, −1 none; lines of at least
    ``REREAD_SMALL_MIN`` valid members) that two pieces, each with its members read at its
    own incidence, fit better put on those pieces: a line over two or three facets of a round room, whose
    members, read at the line's θ, fit it as well as its pieces (the members of a tilted
    facet read long at the line's shallower θ, which straightens the bend), so the split
    :func:`faceted_lines` asks of the members as they lie is not seen.

    Members are ordered along their line; every split of ``FACET_SIDE`` a piece at least is
    tried with each piece's direction searched over ``REREAD_GRID_RAD`` about the line's,
    each member read at the incidence its beam meets the piece with (its counts ``counts``
    (S, N)), the piece's offset their weighted mean. The best split is kept where it beats
    the line, read the same way, by ``FACET_F`` (against the pieces' scatter) and
    ``FACET_CHI`` (against the members' σ) and its pieces turn by ``FACET_TURN_RAD``; where
    none does (or the line has under ``FACET_MIN`` members, ``REREAD_SMALL_MIN`` at least),
    a split with a piece of ``REREAD_SMALL_SIDE`` to ``FACET_SIDE`` − 1 members and a gain of
    ``REREAD_SMALL_CHI`` is asked (a few members of the next facet at the line's end); each
    piece is then asked again
    (``REREAD_ROUNDS``). A piece whose χ² rises less than
    ``REREAD_SURE_CHI`` ``REREAD_SURE_RAD`` either side of its direction (one sensor's trace:
    range and incidence trade) leaves its members INCIDENCE_UNKNOWN; of the others, a member
    its own reading at the piece's θ puts within ``SNAP_SIGMAS`` of it is put where its beam
    meets it, at that θ (σ as it was). numpy, shared by both estimators (a fold-over's second pass).
    docs/foldover.md, "A line over facets, its members re-read"."""
    member = p.valid & (label >= 0)
    if not member.any():
        return p
    lab = np.where(member, label, -1).reshape(-1)
    size = np.bincount(lab[lab >= 0])
    lines = (size >= REREAD_SMALL_MIN).nonzero()[0]
    if lines.size == 0:
        return p
    ox, oy = p.origin_x.reshape(-1), p.origin_y.reshape(-1)
    ux, uy = np.cos(p.heading).reshape(-1), np.sin(p.heading).reshape(-1)
    s = np.asarray(counts, dtype=float).reshape(-1)
    x, y, d, th = (np.array(v, dtype=float).reshape(-1) for v in (p.x, p.y, p.d, p.theta))
    centre = (float(np.mean(ox)), float(np.mean(oy)))     # the ring's (its emitters' mean)
    moved, gone = False, []
    for k in lines:
        g = np.flatnonzero(lab == k)
        u, v = x[g] - x[g].mean(), y[g] - y[g].mean()
        alpha = 0.5 * math.atan2(2.0 * np.sum(u * v), np.sum(u * u - v * v))
        g = g[np.argsort(u * math.cos(alpha) + v * math.sin(alpha), kind="stable")]
        r, w, _, _ = _reread_table(ox[g], oy[g], ux[g], uy[g], s[g], cal,
                                   alpha + REREAD_GRID_RAD)

        def split(lo, hi, side, gain, small=False):
            """The split point of members lo … hi − 1 into pieces of ``side`` at least
            (``small``: one of them under FACET_SIDE) that beat the line by ``gain`` χ² (and
            FACET_F, FACET_TURN_RAD, bending round the ring where both are oriented); None
            where none does."""
            one, two, at, a, b, sure = _reread_split(r, w, lo, hi, side)
            n = hi - lo
            good = (at is not None and one - two >= gain
                    and (not small or min(at - lo, hi - at) < FACET_SIDE)
                    and (one - two) / 2.0 >= FACET_F * two / max(n - 4, 1)
                    and abs(REREAD_GRID_RAD[a] - REREAD_GRID_RAD[b]) >= FACET_TURN_RAD
                    and (not sure or _bends_round(g[lo:at], g[at:hi],
                                                  alpha + REREAD_GRID_RAD[[a, b]],
                                                  ox, oy, ux, uy, s, cal, centre)))
            return at if good else None

        pieces, todo = [], [(0, g.size, 0)]
        while todo:
            lo, hi, depth = todo.pop()
            at = None
            if depth < REREAD_ROUNDS:
                if depth > 0 or hi - lo >= FACET_MIN:
                    at = split(lo, hi, FACET_SIDE, FACET_CHI)
                if at is None:
                    # a few members of the next facet, or one sensor's trace on it, bend
                    # a short or weakly split line: their piece is asked for alone
                    at = split(lo, hi, REREAD_SMALL_SIDE, REREAD_SMALL_CHI, small=True)
            good = at is not None
            if good:
                todo += [(lo, at, depth + 1), (at, hi, depth + 1)]
            else:
                pieces.append((lo, hi, depth))
        if len(pieces) < 2:
            continue
        for lo, hi, _ in pieces:
            m = g[lo:hi]
            _, chi = _piece_chi(r[:, lo:hi], w[:, lo:hi])
            best = int(np.argmin(chi))
            if not _determined(chi, best) >= REREAD_SURE_CHI:
                # a piece its own members do not orient: the line's θ is not theirs either
                gone.append(m)
                continue
            a0 = alpha + REREAD_GRID_RAD[best]
            rr, ww, tt, dd = _reread_table(ox[m], oy[m], ux[m], uy[m], s[m], cal,
                                           a0 + REREAD_FINE_RAD)
            c, chi = _piece_chi(rr, ww)
            f = int(np.argmin(chi))
            if not np.isfinite(chi[f]):
                continue
            a1 = a0 + REREAD_FINE_RAD[f]
            nx, ny = -math.sin(a1), math.cos(a1)
            un = ux[m] * nx + uy[m] * ny
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (c[f] - (ox[m] * nx + oy[m] * ny)) / un
                _, bb = cal.log_ab(tt[f])
                noise = range_sigma(bb, dd[f], cal.sigma_counts() / s[m])
            on = (np.isfinite(t) & (t >= cal.min_range_m) & (t <= p.max_range_m)
                  & (np.abs(t - dd[f]) <= SNAP_SIGMAS * noise))
            m, t = m[on], t[on]
            d[m], th[m] = t, tt[f][on]
            x[m], y[m] = ox[m] + t * ux[m], oy[m] + t * uy[m]
            moved = True
    shape = p.valid.shape
    if moved:
        p = points_with(p, x=x.reshape(shape), y=y.reshape(shape), d=d.reshape(shape),
                        theta=th.reshape(shape))
    if gone:
        p = invalidated(p, np.concatenate(gone), Reason.INCIDENCE_UNKNOWN)
    return p
