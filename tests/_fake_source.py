"""A fake :class:`irring.core.RingSource` for tests: counts from a function, no MuJoCo.

The emulated firmware reads it by scan-pose index, ``pipeline.acquire`` by world pose; it
records every call so a test can say which sweeps were asked for, in which order.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from irring.core import Sweep, as_pose, hardware_duration_s, sensor_angles_for_steps
from irring.designs import PAPER_RING


class FakeSource:
    """``counts(pose, steps, k) -> (S, N)``: pose is what ``sweep`` got (an int index for
    the emulator), k how many sweeps that pose had before. ``lose_after``: raise
    ``SourceLost`` (with the first ``lose_after`` steps as its partial sweep) on that many
    calls from now on; ``missing``: steps each sweep leaves out (listed, not invented)."""

    def __init__(self, counts: Callable, *, ring=PAPER_RING, adc_bits: int = 12,
                 poses: int = 4, missing: tuple[int, ...] = ()):
        self.counts, self.ring, self.adc_bits, self.n_sweeps = counts, ring, adc_bits, poses
        self.missing = tuple(missing)
        self.calls: list[tuple] = []
        self.closed = 0
        self.lose_at: int | None = None   # the call number that loses the source
        self.lose_after = 0               # steps that arrive before it is lost

    def sweep(self, pose=0, *, steps=None) -> Sweep:
        from irring.core import SourceLost

        steps = np.arange(self.ring.min_step, self.ring.max_step + 1) if steps is None \
            else np.asarray(steps)
        key = int(pose) if isinstance(pose, (int, np.integer)) else tuple(as_pose(pose))
        k = sum(1 for c in self.calls if c[0] == key)
        self.calls.append((key, tuple(int(s) for s in steps)))
        keep = ~np.isin(steps, self.missing)
        lost = self.lose_at is not None and len(self.calls) == self.lose_at
        if lost:
            keep &= np.arange(len(steps)) < self.lose_after
        got = steps[keep]
        sweep = Sweep(steps=got, sensor_angles=sensor_angles_for_steps(self.ring, got),
                      counts=np.asarray(self.counts(key, steps, k))[keep],
                      timestamps_s=np.arange(1, len(got) + 1) * hardware_duration_s(1, 0.0, 1),
                      duration_s=hardware_duration_s(len(steps), 0.0, 1),
                      pose=np.zeros(3) if isinstance(key, int) else np.array(key),
                      ring=self.ring, adc_bits=self.adc_bits,
                      missing_steps=tuple(int(s) for s in steps[~keep]), source="fake")
        if lost:
            raise SourceLost("fake source lost", partial=sweep, report=f"lost at {len(got)}")
        return sweep

    def close(self) -> None:
        self.closed += 1

    def __enter__(self) -> FakeSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
