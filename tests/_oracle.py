"""The numpy estimator (the oracle) against the compiled one on simulated scenes."""

from __future__ import annotations

import numpy as np

from irring import pipeline
from irring.estimation import estimate as est
from irring.estimation import estimate_numpy as oracle
from irring.estimation.calibration import Calibration


def assert_oracle_agrees(scenes, atol_m: float = 1e-9) -> None:
    """Every sweep of every scene (its own seed and calibration): the same valid readings
    and reasons from both estimators, x, y, d and σ within ``atol_m``."""
    for scene in scenes:
        sim, _ = pipeline.simulated(scene, progress=False)
        cal = Calibration.for_scene(scene)
        for sweep in sim.sweeps:
            fast = est.estimate_detail(sweep, cal).points
            slow = oracle.estimate_detail(sweep, cal).points
            for f in ("valid", "reason"):
                np.testing.assert_array_equal(getattr(fast, f), getattr(slow, f), err_msg=f)
            for f in ("x", "y", "d", "sigma_m"):
                np.testing.assert_allclose(getattr(fast, f), getattr(slow, f), rtol=0,
                                           atol=atol_m, err_msg=f)
