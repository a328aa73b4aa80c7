"""Where a sensor turning a full turn is read from: its turn has no ends, so the estimator
starts it where the scene already breaks (docs/estimator.md, "A full turn's seam")."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..core import Points, Sweep, Truth, rows_in_step_order
from .calibration import RETURN_SIGMAS, Calibration
from .lines import Estimate


def closes_turn(h: np.ndarray) -> np.ndarray:
    """(N,) bool: which sensors turn a full turn, ``h`` (S, N) their headings (rad) in step
    order: the steps add up to 2π and the last heading lies within 1.5 of the widest step
    of the first."""
    turn = np.abs(np.mod(np.diff(h, axis=0) + math.pi, 2 * math.pi) - math.pi)
    back = np.abs(np.mod(h[0] - h[-1] + math.pi, 2 * math.pi) - math.pi)
    return (back <= 1.5 * turn.max(axis=0)) & (turn.sum(axis=0) + back > 1.9 * math.pi)


def turn_start(sweep: Sweep, cal: Calibration) -> np.ndarray | None:
    """(S,) the sweep's rows in the order its estimate reads them, or None to read them in
    step order: a sweep whose every sensor turns a full turn (and none of whose steps went
    missing) starts in the middle of its longest run of rows silent on every sensor (counts
    below the return level), else after its largest change in counts between neighbours."""
    steps = np.asarray(sweep.steps)
    counts = np.asarray(sweep.counts, dtype=float)
    angles = np.asarray(sweep.sensor_angles, dtype=float)
    # a malformed sweep is the estimator's to refuse, with its own message
    if (steps.size < 3 or counts.ndim != 2 or steps.shape != counts.shape[:1]
            or angles.shape != counts.shape or len(sweep.missing_steps)):
        return None
    order = rows_in_step_order(steps)
    if not closes_turn(angles[order]).all():
        return None
    c = counts[order]
    silent = (c < cal.no_return_counts + RETURN_SIGMAS * cal.sigma_counts()).all(axis=1)
    if silent.any() and not silent.all():
        lead = int(np.argmin(silent))                      # a row with a return leads
        s = np.roll(silent, -lead).astype(np.int8)
        edge = np.diff(np.concatenate([[0], s, [0]]))
        first, after = np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)
        k = int(np.argmax(after - first))
        start = (lead + (first[k] + after[k]) // 2) % steps.size
    else:
        jump = np.abs(c - np.roll(c, 1, axis=0)).sum(axis=1)  # row i against the one before
        start = int(np.argmax(jump))
    return None if start == 0 else np.roll(order, -start)


def started_at(sweep: Sweep, rows: np.ndarray) -> Sweep:
    """``sweep`` read in the order ``rows``, its steps relabelled in rising order (each
    reading keeps its sensor angle, so its beam; only which rows are neighbours in step
    order changes: the first and last rows)."""
    take = lambda a: None if a is None else np.asarray(a)[rows]   # noqa: E731
    truth = None if sweep.truth is None else Truth(
        **{f.name: take(getattr(sweep.truth, f.name)) for f in dataclasses.fields(Truth)})
    return dataclasses.replace(
        sweep, steps=np.sort(np.asarray(sweep.steps)), counts=take(sweep.counts),
        sensor_angles=take(sweep.sensor_angles), timestamps_s=take(sweep.timestamps_s),
        truth=truth, reading_poses=take(sweep.reading_poses))


def in_sweep_rows(est: Estimate, rows: np.ndarray) -> Estimate:
    """An estimate of ``started_at(sweep, rows)`` put back in ``sweep``'s rows."""
    n_rows = rows.size

    def back(a):
        if not isinstance(a, np.ndarray) or a.ndim == 0 or a.shape[0] != n_rows:
            return a
        out = np.empty_like(a)
        out[rows] = a
        return out

    points = Points(**{f.name: back(getattr(est.points, f.name)) if f.name not in (
        "max_range_m", "cone_half_angle_rad") else getattr(est.points, f.name)
        for f in dataclasses.fields(Points)})
    lines = est.lines
    if lines is not None:
        n = lines.label.shape[1]
        flat = lambda i: rows[np.asarray(i) // n] * n + np.asarray(i) % n   # noqa: E731
        lines = dataclasses.replace(lines, label=back(lines.label), start=flat(lines.start),
                                    end=flat(lines.end))
    return dataclasses.replace(est, points=points, lines=lines,
                               theta_history=tuple(back(t) for t in est.theta_history))
