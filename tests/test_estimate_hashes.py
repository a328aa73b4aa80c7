"""tests/estimate_hashes.py, the bit-for-bit check docs/estimator.md's "estimates unchanged"
figures come from: its hash is the estimates', whatever process computes it, and one count
changed in one sweep changes that run's hash and the total, no other run's."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import estimate_hashes as eh

SCRIPT = Path(eh.__file__)


@pytest.fixture(scope="module")
def data():
    return eh.simulate(["t_room_cylinder", "t_room"], seeds=(0,))


def test_the_hash_is_the_estimates_in_any_process(data):
    per, total = eh.hashes("fast", data)
    code = (f"import sys; sys.path.insert(0, {str(SCRIPT.parent)!r})\n"
            "import estimate_hashes as eh\n"
            "print(eh.hashes('fast', eh.simulate(['t_room_cylinder', 't_room'], seeds=(0,)))[1])")
    other = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           check=True, env=dict(os.environ, PYTHONHASHSEED="7")).stdout.strip()
    assert other == total and len(per) == 2


def test_one_count_changed_changes_its_run_and_the_total(data):
    per, total = eh.hashes("numpy", data)
    (name, seed, cal, sweeps), rest = data[1], data[:1]
    counts = np.array(sweeps[2].counts)
    counts[30, 4] += 40   # one reading of one sensor at one step of pose 3
    changed = [*rest, (name, seed, cal, [*sweeps[:2],
                                         dataclasses.replace(sweeps[2], counts=counts),
                                         *sweeps[3:]])]
    per2, total2 = eh.hashes("numpy", changed)
    assert per2[("t_room_cylinder", 0)] == per[("t_room_cylinder", 0)]
    assert per2[("t_room", 0)] != per[("t_room", 0)] and total2 != total


def test_a_mode_it_does_not_know_is_refused():
    with pytest.raises(ValueError, match="mode must be one of fast, numpy, detail, got 'fats'"):
        eh.hashes("fats", [])
    done = subprocess.run([sys.executable, str(SCRIPT)], capture_output=True, text=True)
    assert done.returncode == 2 and "python tests/estimate_hashes.py fast" in done.stderr
