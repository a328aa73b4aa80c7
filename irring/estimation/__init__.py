"""Stage 2, estimation: calibration (calibrate) and the paper's iterative estimator (estimate),
its compiled kernels (_lines, _iterate) and their numpy oracle (estimate_numpy)."""
