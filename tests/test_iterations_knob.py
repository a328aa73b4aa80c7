"""The accuracy study's "iterations" knob shows the estimate after k iterations (issue 13
item 7): capped readings still moving are kept at the θ they reached, not dropped."""

from __future__ import annotations

import numpy as np
import pytest

from irring import scenario as S
from irring.core import Reason
from irring.estimation.calibration import scene_calibration
from irring.estimation import estimate_numpy as oracle
from irring.estimation.estimate import estimate, estimate_detail
from irring.simulation.sim import SimRing
from irring.studies import accuracy


@pytest.fixture(scope="module")
def l_room_sweeps():
    sc = S.load_scenario("l_room")
    sim = SimRing(sc)
    return sc, [sim.sweep(k) for k in range(len(sc.robot.poses))], \
        scene_calibration(sc)[0]


def _err(sweep, p):
    hit = sweep.truth.hit_point
    m = p.valid & np.isfinite(hit[..., 0])
    return np.sqrt(np.mean((p.x[m] - hit[..., 0][m]) ** 2 + (p.y[m] - hit[..., 1][m]) ** 2))


def test_one_iteration_keeps_every_reading_and_beats_theta_zero(l_room_sweeps):
    _, sweeps, cal = l_room_sweeps
    for sw in sweeps:
        dropped = estimate(sw, cal, max_iterations=1)
        kept = estimate(sw, cal, max_iterations=1, keep_unconverged=True)
        flat = estimate(sw, cal, iterate=False)
        assert np.count_nonzero(dropped.reason == Reason.NOT_CONVERGED) > 50
        assert not np.any(kept.reason == Reason.NOT_CONVERGED)
        # kept: every reading the cap dropped is back (and only those)
        back = dropped.reason == Reason.NOT_CONVERGED
        np.testing.assert_array_equal(kept.valid, dropped.valid | back)
        assert np.all(np.isfinite(kept.x[kept.valid]) & np.isfinite(kept.sigma_m[kept.valid]))
        # one step of Table II already moves the end points towards the truth
        assert _err(sw, kept) < _err(sw, flat)


def test_keep_unconverged_kernels_agree_with_the_oracle(l_room_sweeps):
    _, sweeps, cal = l_room_sweeps
    for k in (1, 2):
        fast = estimate_detail(sweeps[0], cal, max_iterations=k, keep_unconverged=True).points
        slow = oracle.estimate_detail(sweeps[0], cal, max_iterations=k,
                                      keep_unconverged=True).points
        for f in ("valid", "reason", "iterations"):
            np.testing.assert_array_equal(getattr(fast, f), getattr(slow, f), err_msg=f)
        for f in ("x", "y", "d", "theta", "sigma_m"):
            np.testing.assert_allclose(getattr(fast, f), getattr(slow, f), rtol=0, atol=1e-9)


def test_the_iterations_knob_is_never_below_theta_zero():
    knob = [c for c in accuracy.configurations(["iterations"]) if c.knob == "iterations"]
    r = accuracy.measure(["l_room"], seeds=1, configs=[accuracy.Config()] + knob)
    by = {c["label"]: c for c in r["configs"]}
    flat = by["θ = 0 (no iterations)"]
    for label in ("1 iteration", "2 iterations", "5 iterations"):
        assert by[label]["occupied_f1"] > flat["occupied_f1"]
        assert by[label]["range_rmse_m"] < flat["range_rmse_m"]
