"""Round twenty-one of hostile input: each test names the input that broke and asserts what
happens now."""

from __future__ import annotations

import warnings

import numpy as np

from irring import load_scenario
from irring.core import Reason
from irring.estimation.calibration import Calibration
from irring.estimation.silence import unconfirmed_near


def test_neighbouring_zero_counts_ask_no_near_reading_with_a_numpy_warning():
    # a sweep of 1 V noise reads 0 counts (an infinite distance) on neighbouring steps: their
    # inf - inf printed "RuntimeWarning: invalid value encountered in subtract" on stderr
    cal = Calibration.for_scene(load_scenario("t_room"))
    counts = np.array([[0.0, 3000.0], [0.0, 3005.0], [3100.0, 0.0], [700.0, 0.0]])
    reason = np.full(counts.shape, Reason.OK)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        alone = unconfirmed_near(counts, reason, np.array([-1, 0, 1, 2]), cal)
    assert alone.tolist() == [[False, False], [False, False], [True, False], [False, False]]
