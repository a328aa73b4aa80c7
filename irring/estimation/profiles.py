"""Range profiles: what a reading's own sensor's neighbouring steps say of the surface it met
(slope, bend, θ; :func:`range_profiles` and its compiled :func:`profiles_compiled`), and
readings read at their own profile's θ where it places them surely (:func:`placed_surely`,
:func:`leave_doubted_line`). Used by the rules for readings on no line, doubted lines and
the fold-over. Why and what was measured: docs/estimator.md, "Readings on no line".
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..core import Points, Reason, points_with
from ..resources import kernel
from .calibration import SIGMA_FLOOR_M, Calibration, range_sigma
from .lines import (PINNED_RAD, LineOptions, invalidated, jump_slope, placed_at, polyline_ids,
                    theta0_sigma)


_lines = kernel("estimation._lines")
_INCIDENCE_UNKNOWN = int(Reason.INCIDENCE_UNKNOWN)


LOCAL_STEPS = 5        # a reading on no line looks this many steps either way …
LOCAL_MIN = 3          # … and needs this many readings of one surface (itself included) …
_LOCAL_SPREAD_M = 0.001  # … spread across its beam by at least this RMS …
_LOCAL_SLOPE_SE = 2.0   # … a range slope this many standard errors from flat …
_CHI2_95 = np.array([3.84, 5.99, 7.81, 9.49, 11.07])  # … and a straight profile: χ² within
#                                                    its 95 % point (1 … 5 degrees of freedom)
_CONVEX_BELOW_DROP_RAD = math.radians(5)  # a bend with θ this near the drop-out is the model's clamp
UNKNOWN_M = 0.10       # fewer readings, and θ = 0 may read this much long: INCIDENCE_UNKNOWN
_CONVEX_SURE_SE = 3.0   # … unless its profile bends away this many standard errors: a post
_BEND_MIN_SHARE = 1e-12  # a bend is read only where the curvature term keeps this share of
#                          Σ(v²)²: readings at three spots across the beam or more


@dataclass(frozen=True)
class Profile:
    """What a reading's own sensor's neighbouring steps say of the surface it met
    (:func:`range_profiles`); arrays over the asked readings, ``s``, ``d0`` and ``sig_s``
    over every valid reading."""
    s: np.ndarray         # counts of every valid reading in scan order
    d0: np.ndarray        # their θ = 0 distances
    sig_s: np.ndarray     # their relative count noise σ_S/S
    n: np.ndarray         # readings of the same surface in the window
    slope: np.ndarray     # range slope across the beam (tan θ, signed)
    se: np.ndarray        # its standard error
    theta: np.ndarray     # θ = atan|slope|, at most the drop-out angle
    ok: np.ndarray        # a straight profile clearly not flat: θ is its slope
    convex: np.ndarray    # bent away from the beam: a post, a leg, a column
    sure: np.ndarray      # bent away by _CONVEX_SURE_SE standard errors (not noise)
    concave: np.ndarray   # bent towards the beam: a concave corner
    steep: np.ndarray     # the steepest θ the readings allow
    chain: np.ndarray     # polyline id (at θ = 0) of every valid reading in scan order …
    heading: np.ndarray   # … its beam's heading …
    ox: np.ndarray        # … its emitter …
    oy: np.ndarray
    step: np.ndarray      # … and motor step


def _profile_inputs(points: Points, vi: np.ndarray, counts: np.ndarray, steps: np.ndarray,
                    cal: Calibration):
    """Per valid reading in scan order (``vi``): counts, heading, emitter, log counts,
    σ_S/S, θ = 0 distance, polyline id (at θ = 0) and motor step. numpy, the statement
    the kernel ``_lines.profile_inputs`` (which :func:`profiles_compiled` calls) is held to."""
    n_sensors = points.valid.shape[1]
    s = np.asarray(counts, dtype=float).reshape(-1)[vi]
    h = points.heading.reshape(-1)[vi]
    ox, oy = points.origin_x.reshape(-1)[vi], points.origin_y.reshape(-1)[vi]
    log_s = np.log(s)
    sig_s = cal.sigma_counts() / s              # σ_d = |b|·d·σ_S/S
    la0, b0 = cal._ab0
    d0 = np.exp(la0 + b0 * log_s)
    chain = polyline_ids(d0, range_sigma(b0, d0, sig_s), h,
                         vi % n_sensors, cal.max_incidence_rad, LineOptions.jump_sigmas)
    step = np.asarray(steps).reshape(-1)[vi // n_sensors]
    return s, h, ox, oy, log_s, sig_s, d0, chain, step


def profiles_compiled(points: Points, vi: np.ndarray, off: np.ndarray, counts: np.ndarray,
                      steps: np.ndarray, cal: Calibration, apart: np.ndarray | None = None
                      ) -> Profile:
    """:func:`range_profiles` in two compiled calls (``irring.estimation._lines.profile_inputs``
    and ``profiles``, held to it by tests/test_estimate_oracle.py)."""
    f = np.ascontiguousarray
    la0, b0 = cal._ab0
    s, h, ox, oy, log_s, sig_s, d0, chain, step = _lines.profile_inputs(
        f(counts, dtype=float).reshape(-1), f(points.heading, dtype=float).reshape(-1),
        f(points.origin_x, dtype=float).reshape(-1), f(points.origin_y, dtype=float).reshape(-1),
        np.asarray(steps).reshape(-1).astype(np.intp), f(vi, dtype=np.intp),
        points.valid.shape[1], cal.sigma_counts(), la0, b0, SIGMA_FLOOR_M,
        jump_slope(cal.max_incidence_rad), LineOptions.jump_sigmas)
    chain = _set_apart(chain, apart)
    n, slope, se, theta, steep, ok, convex, sure, concave = _lines.profiles(
        ox, oy, h, log_s, sig_s, chain, step,
        np.ascontiguousarray(off, dtype=np.intp), cal.theta_rad,
        cal._node_log_a, cal.b, cal.max_incidence_rad,
        _CONVEX_BELOW_DROP_RAD, LOCAL_STEPS, LOCAL_MIN, _LOCAL_SPREAD_M, _LOCAL_SLOPE_SE,
        _CHI2_95, SIGMA_FLOOR_M, _CONVEX_SURE_SE, _BEND_MIN_SHARE)
    return Profile(s=s, d0=d0, sig_s=sig_s, n=n, slope=slope, se=se, theta=theta,
                    ok=ok.view(bool), convex=convex.view(bool), sure=sure.view(bool),
                    concave=concave.view(bool), steep=steep, chain=chain, heading=h,
                    ox=ox, oy=oy, step=step)


def _set_apart(chain: np.ndarray, apart: np.ndarray | None) -> np.ndarray:
    """Polyline ids ``chain`` (scan order) with each reading where ``apart`` holds a polyline
    of its own, its neighbours either side cut from each other too."""
    if apart is None or not apart.any():
        return chain
    cut = np.ones(chain.size, dtype=bool)
    cut[1:] = (chain[1:] != chain[:-1]) | apart[1:] | apart[:-1]
    return np.cumsum(cut).astype(chain.dtype)


def range_profiles(points: Points, vi: np.ndarray, off: np.ndarray, counts: np.ndarray,
                   steps: np.ndarray, cal: Calibration, apart: np.ndarray | None = None
                   ) -> Profile:
    """The range profile of each reading ``vi[off]`` (``vi``: the valid readings' flat
    indices in scan order) from its sensor's valid readings of the same polyline within
    ``LOCAL_STEPS`` steps, read as a flat surface would be (:func:`local_incidence`);
    ``apart`` (over ``vi``, optional): readings that are a polyline of their own.
    numpy, the statement :func:`profiles_compiled` is held to."""
    s, h, ox, oy, log_s, sig_s, d0, chain, step = _profile_inputs(points, vi, counts, steps,
                                                                 cal)
    chain = _set_apart(chain, apart)
    # the window: same polyline, within LOCAL_STEPS steps
    j = off[:, None] + np.arange(-LOCAL_STEPS, LOCAL_STEPS + 1)[None, :]
    jc = np.clip(j, 0, vi.size - 1)
    w = ((j == jc) & (chain[jc] == chain[off][:, None])
         & (np.abs(step[jc] - step[off][:, None]) <= LOCAL_STEPS)).astype(float)
    n = w.sum(axis=1)
    ux, uy = np.cos(h[off])[:, None], np.sin(h[off])[:, None]
    rx, ry = ox[jc] - ox[off][:, None], oy[jc] - oy[off][:, None]
    cj, sj = np.cos(h[jc]), np.sin(h[jc])
    lsj = log_s[jc]
    turn = h[jc] - h[off][:, None]
    turn -= 2.0 * math.pi * np.round(turn / (2.0 * math.pi))
    signed = np.zeros(off.size)          # θ with the sign of the slope
    for _ in range(3):
        # on a flat surface a neighbour meets it at θ plus the angle the beam turned
        theta_j = np.minimum(np.abs(signed[:, None] + turn), cal.max_incidence_rad)
        la, b = cal.log_ab(theta_j)
        d = np.exp(la + b * lsj)
        x, y = rx + d * cj, ry + d * sj
        u, v = x * ux + y * uy, y * ux - x * uy
        nn = np.maximum(n, 1.0)
        mu, mv = (w * u).sum(axis=1) / nn, (w * v).sum(axis=1) / nn
        du, dv = (u - mu[:, None]) * w, (v - mv[:, None]) * w
        svv = np.maximum((dv * dv).sum(axis=1), 1e-12)
        slope = (du * dv).sum(axis=1) / svv
        signed = np.clip(np.arctan(slope), -cal.max_incidence_rad, cal.max_incidence_rad)
    theta = np.abs(signed)
    sig = range_sigma(b, d, sig_s[jc])
    se = np.sqrt(((sig * dv) ** 2).sum(axis=1)) / svv
    res = (du - slope[:, None] * dv) / sig
    chi2 = (res * res).sum(axis=1)
    # readings of one step repeated lie on one spot: they give no slope; nor do fewer than
    # LOCAL_MIN distinct steps (a step read repeatedly is one spot, however often)
    sj = np.where(w > 0, step[jc], np.iinfo(np.intp).min)
    first = ~np.tril(sj[:, :, None] == sj[:, None, :], -1).any(axis=2)   # no earlier equal
    n_steps = ((w > 0) & first).sum(axis=1)
    n = np.where((svv >= n * _LOCAL_SPREAD_M ** 2) & (n_steps >= LOCAL_MIN), n, 0.0)
    dof = np.clip(n - 2.0, 1.0, _CHI2_95.size).astype(np.intp)
    # bent: a curvature term (v², orthogonal to 1 and v) clearly off zero; a post's side
    # bends away from the beam (θ changes ~10× faster than the beam turns), a flat wall
    # is straight whatever its θ
    q = dv * dv
    q_norm = (q * q).sum(axis=1)
    q = (q - (q.sum(axis=1) / nn)[:, None] * w
         - ((q * dv).sum(axis=1) / svv)[:, None] * dv) * w
    sqq = (q * q).sum(axis=1)
    # at two spots (two readings, or a step repeated) the term is zero but for rounding and
    # its bend noise over noise, which numpy and the kernel round apart: no bend there
    curved = (n >= LOCAL_MIN) & (sqq > _BEND_MIN_SHARE * q_norm)
    sqq = np.maximum(sqq, 1e-30)
    bend = np.where(curved, (du * q).sum(axis=1) / sqq, 0.0)
    bend_se = np.where(curved, np.sqrt(((sig * q) ** 2).sum(axis=1)) / sqq, 0.0)
    straight = ((n >= LOCAL_MIN) & (chi2 <= _CHI2_95[dof - 1])
                & (np.abs(bend) <= _LOCAL_SLOPE_SE * bend_se))
    ok = straight & (np.abs(slope) > _LOCAL_SLOPE_SE * se)
    # undecided: too few readings (θ anywhere up to the drop-out), a bent profile or one
    # whose slope may be anything from flat to steep; kept at θ = 0 they may read long
    # (a post's centre has a flat slope: it stays); a profile bent towards the beam is a
    # concave corner, the reading on either wall: θ anywhere up to the drop-out
    concave = bend < -_LOCAL_SLOPE_SE * bend_se
    # the slope bounds θ only where the profile is straight (or a post's, bent away): a
    # window across a corner fails χ², and its slope's noise-only error bounded a reading
    # 39° steep at 47°, keeping it at θ = 0 105 mm long
    bounded = straight | (bend > _LOCAL_SLOPE_SE * bend_se)
    steep = np.where((n < LOCAL_MIN) | concave | ~bounded, cal.max_incidence_rad, np.minimum(
        np.arctan(np.abs(slope) + _LOCAL_SLOPE_SE * se), cal.max_incidence_rad))
    # a profile bent away from the beam is a convex thing (a post, a leg): kept at θ = 0,
    # as a post's readings are; flagging them lost thin legs' recall (0.96 -> 0.89)
    convex = ((n >= LOCAL_MIN) & (bend > _LOCAL_SLOPE_SE * bend_se)
              & (theta < cal.max_incidence_rad - _CONVEX_BELOW_DROP_RAD))
    return Profile(s=s, d0=d0, sig_s=sig_s, n=n, slope=slope, se=se, theta=theta, ok=ok,
                    convex=convex, sure=bend > _CONVEX_SURE_SE * bend_se, concave=concave,
                    steep=steep, chain=chain, heading=h, ox=ox, oy=oy, step=step)


class SharedProfiles:
    """A profiler (``profiler``'s signature) that also profiles the readings of ``extra``
    (flat (S·N,) mask) whenever it calls ``profiler`` and answers later calls from that call
    while the valid readings ``vi`` are the same: a reading's profile depends on ``vi`` and
    on no other asked reading (the shared profile_inputs and one kernel call saved a sweep).
    Readings set apart, or never asked, are asked of ``profiler`` alone."""

    def __init__(self, profiler: Callable, extra: np.ndarray | None):
        self.profiler, self.extra, self.vi, self.asked, self.pr = profiler, extra, None, None, None

    def __call__(self, points: Points, vi: np.ndarray, off: np.ndarray, counts: np.ndarray,
                 steps: np.ndarray, cal: Calibration, apart: np.ndarray | None = None
                 ) -> Profile:
        if apart is not None or self.extra is None:
            return self.profiler(points, vi, off, counts, steps, cal, apart=apart)
        if self.pr is not None and np.array_equal(vi, self.vi):
            row = np.searchsorted(self.asked, off)
            # (a first call that asked nothing leaves nothing to take from)
            have = self.asked.take(row, mode="clip") if self.asked.size else self.asked
            if not np.array_equal(have, off):
                return self.profiler(points, vi, off, counts, steps, cal)
            out = object.__new__(Profile)    # (dataclasses.replace costs several times more)
            out.__dict__.update(self.pr.__dict__)
            out.__dict__.update({f: getattr(self.pr, f).take(row) for f in _PROFILE_ROWS})
            return out
        # the first call, or a reading left since: the doubt's members asked with it
        asked = self.extra[vi]
        asked[off] = True
        self.vi, self.asked = vi, asked.nonzero()[0]
        self.pr = self.profiler(points, vi, self.asked, counts, steps, cal)
        return self(points, vi, off, counts, steps, cal)


_PROFILE_ROWS = ("n", "slope", "se", "theta", "ok", "convex", "sure", "concave", "steep")


def off_line_profiles(points: Points, label: np.ndarray, pos: np.ndarray, vi: np.ndarray,
                       counts: np.ndarray, steps: np.ndarray, cal: Calibration,
                       profiler: Callable | None):
    """The range profiles of the valid readings ``vi[pos]`` (on no line) from their sensor's
    valid readings on no line alone (``label`` −1; a line's member cuts the polyline):
    (which are straight and clearly sloped, their θ, slope, standard error) or None where
    none is."""
    pr = (profiler or profiles_compiled)(points, vi, pos, counts, steps, cal,
                                         apart=label.reshape(-1)[vi] >= 0)
    if not pr.ok.any():
        return None
    return pr.ok, pr.theta[pr.ok], pr.slope[pr.ok], pr.se[pr.ok]


AGAIN_SIGMA_M = UNKNOWN_M / 3  # a profile asked again places a reading only this surely …


def placed_surely(cal: Calibration, s: np.ndarray, theta: np.ndarray, slope: np.ndarray,
                   se: np.ndarray, sig_s: np.ndarray) -> np.ndarray:
    """Which readings (counts ``s``) a profile asked again may place at its ``theta``
    (``slope`` and its standard error ``se``; ``sig_s``: σ_S/S): σ at most
    ``AGAIN_SIGMA_M`` (θ = 0 would be off by 3σ or more), θ not pinned at the drop-out
    angle (a slope that steep is two surfaces', not one face's)."""
    _, sigma, placed = own_slope_read(cal, s, theta, slope, se, sig_s)
    return placed & (sigma <= AGAIN_SIGMA_M) & (theta < cal.max_incidence_rad - PINNED_RAD)


def own_slope_read(cal: Calibration, s: np.ndarray, theta: np.ndarray, slope: np.ndarray,
                   se: np.ndarray, sig_s: np.ndarray):
    """(d, σ, placed) of readings (counts ``s``, ``sig_s``: σ_S/S) read at their own
    profile's ``theta`` (``slope`` and its standard error ``se``): d at θ, σ and placed as
    :func:`own_slope_sigma` gives them from d at θ ± that error. numpy, the statement
    :func:`own_slope_read_compiled` is held to."""
    t = np.abs(slope)
    lo = np.arctan(np.maximum(t - se, 0.0))
    hi = np.minimum(np.arctan(t + se), cal.max_incidence_rad)
    d, d_lo, d_hi = cal.distance(np.concatenate([s, s, s]),
                                 np.concatenate([theta, lo, hi])).reshape(3, -1)
    return (d, *own_slope_sigma(cal, theta, d, d_lo, d_hi, sig_s))


def own_slope_read_compiled(cal: Calibration, s: np.ndarray, theta: np.ndarray,
                            slope: np.ndarray, se: np.ndarray, sig_s: np.ndarray):
    """:func:`own_slope_read` in one compiled call (``irring.estimation._lines.
    own_slope_reads``, held to it by tests/test_far_line_kernels.py)."""
    f = np.ascontiguousarray
    return _lines.own_slope_reads(
        f(s, dtype=float), f(theta, dtype=float), f(slope, dtype=float), f(se, dtype=float),
        f(sig_s, dtype=float), cal.theta_rad, cal._node_log_a, cal.b, cal.max_incidence_rad,
        cal.min_range_m, SIGMA_FLOOR_M)


def own_slope_sigma(cal: Calibration, theta: np.ndarray, d: np.ndarray, d_lo: np.ndarray,
                     d_hi: np.ndarray, sig_s: np.ndarray):
    """(σ, placed) of readings read at their own profile's θ (distance ``d``; ``d_lo``,
    ``d_hi`` at θ ± the slope's standard error; ``sig_s``: σ_S/S): the noise at θ plus half
    the spread of d over θ ± that error; placed: d and σ finite, d within the curve."""
    spread = 0.5 * np.abs(d_lo - d_hi)
    _, b_new = cal.log_ab(theta)
    sigma = np.hypot(range_sigma(b_new, d, sig_s), spread)
    return sigma, np.isfinite(d) & (d >= cal.min_range_m) & np.isfinite(sigma)


def leave_doubted_line(points: Points, label: np.ndarray, vi: np.ndarray, pos: np.ndarray,
                        pr: Profile, doubted: np.ndarray, cal: Calibration,
                        stay: np.ndarray | None = None) -> tuple[Points, np.ndarray]:
    """The members of doubted short far lines off their lines (``pos``: their places among
    the valid readings ``vi``; ``doubted``: which of the readings ``pr`` profiled they are):
    each at its own profile's θ where that is straight and clearly steep, else
    INCIDENCE_UNKNOWN (far, and nothing places it), unless no θ reads it beyond its noise
    (:func:`_theta_free`: then at θ = 0). ``stay`` (over ``pos``): members
    left on their line, as they were, where their own θ does not place them within the
    range."""
    placed = pr.ok[doubted].copy()  # only a straight, clearly steep profile places one
    if placed.any():
        theta = pr.theta[doubted][placed]
        d_new, sigma, fits = own_slope_read_compiled(
            cal, pr.s[pos[placed]], theta, pr.slope[doubted][placed], pr.se[doubted][placed],
            pr.sig_s[pos[placed]])
        if stay is not None:     # (a stayer is placed only within the range)
            fits &= ~stay[placed] | (d_new <= points.max_range_m)
        placed[placed] = fits
        if fits.any():
            points = placed_at(points, vi[pos[placed]], d_new[fits], theta[fits], sigma[fits])
    leave = np.ones(pos.size, dtype=bool) if stay is None else placed | ~stay
    # a reading no θ moves beyond its noise (an ideal sensor's) is placed by its counts alone
    rest = (leave & ~placed).nonzero()[0]
    if rest.size:
        at, sigma = _theta_free(cal, pr.s[pos[rest]], pr.d0[pos[rest]], pr.sig_s[pos[rest]],
                                points.max_range_m)
        if at.any():
            points = placed_at(points, vi[pos[rest[at]]], pr.d0[pos[rest[at]]], 0.0, sigma[at])
            placed[rest[at]] = True
    label = label.copy()
    label.reshape(-1)[vi[pos[leave]]] = -1
    gone = vi[pos[leave & ~placed]]
    if gone.size:
        points = invalidated(points, gone, Reason.INCIDENCE_UNKNOWN)
    return points, label


def unknown_theta_free(points: Points, counts: np.ndarray, cal: Calibration) -> Points:
    """``points`` with its INCIDENCE_UNKNOWN readings valid at θ = 0 with their θ = 0 σ where
    the calibration has no θ dependence (``cal.theta_free``: the ideal sensor's), within
    [min range, max range]: whichever rule left them unknown, what θ is cannot move them.
    ``counts`` (S, N): the counts they were read from (far branch: a calibration that folds
    is left alone, its branches are the fold-over's to decide). Why: docs/estimator.md,
    "Readings no θ moves"."""
    if not cal.theta_free or cal.folds:
        return points
    at = (points.reason.reshape(-1) == _INCIDENCE_UNKNOWN).nonzero()[0]
    if not at.size:
        return points
    s = np.asarray(counts, dtype=float).reshape(-1)[at]
    lit = s > 0.0
    at, s = at[lit], s[lit]
    d0 = cal.distance(s, 0.0)
    free, sigma = _theta_free(cal, s, d0, cal.sigma_counts() / s, points.max_range_m)
    if not free.any():
        return points
    at = at[free]
    points = placed_at(points, at, d0[free], 0.0, sigma[free])
    valid, reason = np.array(points.valid), np.array(points.reason)
    valid.reshape(-1)[at], reason.reshape(-1)[at] = True, Reason.OK
    return points_with(points, valid=valid, reason=reason)


THETA_FREE_SIGMAS = 3.0   # a θ-free reading stays within this many of its θ = 0 σ


def theta_free_in_noise(points: Points, counts: np.ndarray, cal: Calibration) -> Points:
    """``points`` with every valid reading placed more than ``THETA_FREE_SIGMAS`` θ = 0 σ
    from its θ = 0 distance read there, at θ = 0 with that σ, where the calibration has no
    θ dependence (``cal.theta_free``: the ideal sensor's) and does not fold: its counts
    alone measure its range, so no line, arc or neighbour moves it past its noise.
    ``counts`` (S, N): the counts it was read from. Why: docs/estimator.md, "A θ-free
    reading stays within its noise"."""
    if not cal.theta_free or cal.folds:
        return points
    at = np.asarray(points.valid).reshape(-1).nonzero()[0]
    s = np.asarray(counts, dtype=float).reshape(-1)[at]
    lit = s > 0.0
    at, s = at[lit], s[lit]
    if not at.size:
        return points
    d0 = cal.distance(s, 0.0)
    free, sigma = _theta_free(cal, s, d0, cal.sigma_counts() / s, points.max_range_m)
    with np.errstate(invalid="ignore"):
        off = free & ~(np.abs(np.asarray(points.d, float).reshape(-1)[at] - d0)
                       <= THETA_FREE_SIGMAS * sigma)
    if not off.any():
        return points
    return placed_at(points, at[off], d0[off], 0.0, sigma[off])


def _theta_free(cal: Calibration, s: np.ndarray, d0: np.ndarray, sig_s: np.ndarray,
                max_range_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(which, σ) of readings (counts ``s``, θ = 0 distance ``d0``, ``sig_s``: σ_S/S) that
    no incidence up to the drop-out angle reads more than their noise σ away from ``d0``
    (a calibration without θ dependence: the ideal sensor's), within [min range, max
    range]: what θ is does not matter to them, so nothing is unknown. σ: their θ = 0 σ."""
    thetas = np.append(cal.theta_rad[cal.theta_rad <= cal.max_incidence_rad],
                       cal.max_incidence_rad)
    spread = np.max(np.abs(cal.distance(s[:, None], thetas[None, :]) - d0[:, None]), axis=1,
                    initial=0.0)
    sigma = theta0_sigma(cal, s, d0, sig_s)
    return (np.isfinite(d0) & (d0 >= cal.min_range_m) & (d0 <= max_range_m)
            & (spread <= range_sigma(cal._ab0[1], d0, sig_s)) & np.isfinite(sigma)), sigma
