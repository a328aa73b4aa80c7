"""A reading's θ only as far as its evidence bounds it.

A slope pinned at the drop-out angle is no θ (:func:`clamped_slopes`, called by
``local_incidence``); a line its counts contradict leaves its members no θ, but their own
profile may still bound it (:func:`kept_where_bounded`, called by ``counts_disown_lines``).
Numpy, shared by both estimators. Why and what they measured:
docs/estimator.md, "Bounded incidence".
"""
from __future__ import annotations

import numpy as np

from ..core import Points, Reason
from .calibration import range_sigma

CLAMP_SE = 2.0  # a clamped slope allows θ down to atan(|slope| − this many standard errors) …
CLAMP_TESTED = 4  # … where this many readings tested the profile's straightness (else to 0)
# a contradicted line's member is kept at θ = 0 only where that reads at most this long: at
# 100 mm (the undecided readings' bound) held-out grazing walls' 60-70° bin rose 9.8 -> 10.2 mm
KEPT_LONG_MAX_M = 0.05


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


def kept_where_bounded(points: Points, vi: np.ndarray, pos: np.ndarray, pr, cal):
    """(flat indices, d, σ) of the members ``vi[pos]`` of lines their counts contradict
    that leaving made INCIDENCE_UNKNOWN, to be placed again at θ = 0 where their own profile (``pr``, profiled over
    ``pos``) bounds θ (its ``steep``; a bent one, only the drop-out angle) and θ = 0 reads
    at most ``KEPT_LONG_MAX_M`` longer than that bound: σ their noise at θ = 0
    (:func:`~irring.estimation.calibration.range_sigma`) and half that span, as a reading on no line whose θ nothing decides
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
    keep = np.isfinite(span) & (span <= KEPT_LONG_MAX_M) & (d0 >= cal.min_range_m) & (
        d0 <= points.max_range_m)
    if not keep.any():
        return None
    at, d0, span = at[keep], d0[keep], span[keep]
    _, b0 = cal._ab0
    sigma = np.hypot(range_sigma(b0, d0, pr.sig_s[pos[lost][keep]]), 0.5 * span)
    return at, d0, sigma
