"""Issue 13 item 4 on scenes written here: readings near the no-return level judged by the
noise the calibration knows, and the mapper weighing each end point by its σ."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from _synthetic import make_sweep
from irring.data import Reason
from irring.designs import PAPER_RING
from irring.estimation.estimate import RETURN_SIGMAS, Calibration, estimate
from irring.estimation.estimate_numpy import classify as classify_numpy


def _noise_only_sweep(cal: Calibration, offset_sigmas: float, seed: int):
    """A sweep whose every reading is the no-return level + offset + the calibration's
    own count noise (Gaussian, σ = cal.sigma_counts())."""
    sweep, _, _ = make_sweep(cal, walls=[((2.0, -1.0), (2.0, 1.0))], ring=PAPER_RING)
    rng = np.random.default_rng(seed)
    sigma = cal.sigma_counts()
    counts = cal.no_return_counts + (offset_sigmas + rng.standard_normal((40, *sweep.shape))) * sigma
    return [dataclasses.replace(sweep, counts=c) for c in counts], sigma


def test_no_return_noise_almost_never_passes_for_a_return():
    """40 sweeps (34 080 readings) of pure no-return noise at 15 mV: at most one in 10 000
    (the RETURN_SIGMAS tail, 1e-4) becomes a valid point; at the old 2σ it was 2.3 %."""
    cal = Calibration.nominal("gp2d12", PAPER_RING, noise_sigma_v=0.015)
    sweeps, _ = _noise_only_sweep(cal, 0.0, seed=4)
    reasons = np.concatenate([estimate(s, cal).reason.ravel() for s in sweeps])
    n = reasons.size
    assert n == 40 * 71 * 12
    assert np.count_nonzero(reasons == Reason.OK) <= 4          # expected 3.4
    # most are no return (≤ 2σ: 97.7 %), the rest too weak to tell (OUT_OF_RANGE)
    assert np.count_nonzero(reasons == Reason.NO_RETURN) / n > 0.97
    assert np.all(np.isin(reasons, [Reason.OK, Reason.NO_RETURN, Reason.OUT_OF_RANGE]))


def test_the_threshold_follows_the_calibrations_noise_and_oracle_agrees():
    """The same counts 3σ above the no-return level: out of range for a calibration that
    knows 15 mV of noise, valid returns for one that knows 2 mV (the ideal sensor's is 0.1)."""
    noisy = Calibration.nominal("gp2d12", PAPER_RING, noise_sigma_v=0.015)
    quiet = Calibration.nominal("gp2d12", PAPER_RING, noise_sigma_v=0.002)
    sweep, _, _ = make_sweep(noisy, walls=[((2.0, -1.0), (2.0, 1.0))], ring=PAPER_RING)
    level = noisy.no_return_counts + 3.0 * noisy.sigma_counts()
    assert 2.0 < 3.0 < RETURN_SIGMAS
    sweep = dataclasses.replace(sweep, counts=np.full(sweep.shape, level))
    for cal, want in ((noisy, Reason.OUT_OF_RANGE), (quiet, Reason.OK)):
        np.testing.assert_array_equal(classify_numpy(sweep.counts, sweep, cal),
                                      np.full(sweep.shape, 0 if want == Reason.OK else want))
    assert np.all(estimate(sweep, noisy).reason == Reason.OUT_OF_RANGE)
    # 3σ above the level at 2 mV is a return from ~0.7 m: the curve's calibrated far end
    assert math.isfinite(float(quiet.distance(level)))
