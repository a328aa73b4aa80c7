"""SHA-256 of every field of every estimate over the bundled scenarios' simulated sweeps:
the check that a change leaves the estimates bit for bit as they were (docs/estimator.md
gives the totals it printed). Run it before and after a change:

    python tests/estimate_hashes.py fast      # estimate(): every field of each Estimate
    python tests/estimate_hashes.py numpy     # the numpy oracle's points and lines
    python tests/estimate_hashes.py detail    # the compiled estimate_detail's points and lines

It prints one hash per (scenario, seed) and a TOTAL line. The simulated sweeps (15 bundled
scenarios × seeds 0–2) are cached in the file $ESTIMATE_HASHES_CACHE, if set (delete it when
the simulation changes)."""

from __future__ import annotations

import dataclasses
import hashlib
import os
import pickle
import sys

import numpy as np

SEEDS = (0, 1, 2)
MODES = ("fast", "numpy", "detail")


def simulate(names=None, seeds=SEEDS) -> list:
    """[(scenario, seed, calibration, sweeps)] of every bundled scenario (or ``names``)."""
    from irring import pipeline, scenario
    data = []
    for name in sorted(scenario.bundled()) if names is None else names:
        sc = scenario.load_scenario(name)
        cal, _ = pipeline.scene_calibration(sc)
        for seed in seeds:
            acq, _ = pipeline.simulated(sc, seed=seed, progress=False)
            data.append((name, seed, cal, list(acq.sweeps)))
    return data


def _feed(h, obj) -> None:
    for f in dataclasses.fields(obj):
        a = getattr(obj, f.name)
        if isinstance(a, np.ndarray):
            b = np.ascontiguousarray(a).tobytes() + str(a.dtype).encode() + str(a.shape).encode()
        else:
            b = repr(a).encode()
        h.update(f.name.encode() + b)


def hashes(mode: str, data: list) -> tuple[dict, str]:
    """({(scenario, seed): 12 hex digits}, the total's 64) of ``data``'s estimates."""
    if mode == "fast":
        from irring.estimation.estimate import estimate as run
    elif mode == "numpy":
        from irring.estimation.estimate_numpy import estimate_detail as run
    elif mode == "detail":
        from irring.estimation.estimate import estimate_detail as run
    else:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    total, per = hashlib.sha256(), {}
    for name, seed, cal, sweeps in data:
        h = hashlib.sha256()
        for sw in sweeps:
            e = run(sw, cal)
            if mode == "fast":
                _feed(h, e)
            else:
                _feed(h, e.points)
                if e.lines is not None:
                    _feed(h, e.lines)
        per[(name, seed)] = h.hexdigest()[:12]
        total.update(h.digest())
    return per, total.hexdigest()


def main(argv: list[str]) -> int:
    if len(argv) != 1 or argv[0] not in MODES:
        print(__doc__, file=sys.stderr)
        return 2
    cache = os.environ.get("ESTIMATE_HASHES_CACHE")
    if cache and os.path.exists(cache):
        with open(cache, "rb") as f:
            data = pickle.load(f)
    else:
        data = simulate()
        if cache:
            with open(cache, "wb") as f:
                pickle.dump(data, f)
    per, total = hashes(argv[0], data)
    for key, value in per.items():
        print(key, value)
    print("TOTAL", argv[0], total, len(data), "runs", sum(len(d[3]) for d in data), "sweeps")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
