"""The final pass's shared profile call (profiles.SharedProfiles): the same profiles as
a call of their own, one kernel call fewer a T-room sweep."""

from __future__ import annotations

import numpy as np
import pytest

from _synthetic import make_sweep, polygon, stand_in_calibration
from irring.estimation import _lines
from irring.estimation import estimate as est
from irring.estimation.estimate import estimate_detail
from irring.estimation.lines import scan_order
from irring.estimation.profiles import SharedProfiles, profiles_compiled, range_profiles

_FIELDS = ("s", "d0", "sig_s", "n", "slope", "se", "theta", "ok", "convex", "sure",
           "concave", "steep", "chain", "heading", "ox", "oy", "step")


def _same(a, b):
    for f in _FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), f


@pytest.mark.parametrize("profiler", [profiles_compiled, range_profiles])
def test_shared_profiles_are_a_call_of_their_own_while_the_valid_readings_stay(profiler):
    """Asked first for some readings with others extra, then for the extra ones: the
    profiler runs once and both answers are bit for bit a call of their own; once a
    reading is gone (another ``vi``) it asks the profiler afresh, the extra ones with it;
    a reading never asked, or readings set apart, are a call of their own."""
    cal = stand_in_calibration(strength=0.6, noise_counts=2.0)
    room = polygon([(-0.41, -0.37), (0.52, -0.29), (0.47, 0.44), (-0.33, 0.51)])
    sweep, _, _ = make_sweep(cal, walls=room, circles=[((0.21, -0.08), 0.06)],
                             noise_counts=2.0, seed=7, pose=(0.03, -0.02, 0.4), quantize=True)
    p = estimate_detail(sweep, cal).points
    steps = np.asarray(sweep.steps)
    index = scan_order(steps, p.valid.shape[1])
    vi = index[p.valid.reshape(-1)[index]]
    assert vi.size > 100
    calls = []

    def counting(*a, **k):
        calls.append(a[2].size)
        return profiler(*a, **k)

    extra = np.zeros(p.valid.size, dtype=bool)
    extra[vi[5::7]] = True
    shared = SharedProfiles(counting, extra)
    first = np.arange(0, vi.size, 3)
    later = (extra[vi]).nonzero()[0][2:]
    _same(shared(p, vi, first, sweep.counts, steps, cal),
          profiler(p, vi, first, sweep.counts, steps, cal))
    _same(shared(p, vi, later, sweep.counts, steps, cal),
          profiler(p, vi, later, sweep.counts, steps, cal))
    none = np.zeros(0, dtype=np.intp)
    _same(shared(p, vi.copy(), none, sweep.counts, steps, cal),
          profiler(p, vi, none, sweep.counts, steps, cal))
    assert calls == [np.union1d(first, extra[vi].nonzero()[0]).size]
    # a reading never asked: a call of its own
    unasked = np.setdiff1d(np.arange(vi.size), shared.asked)[:4]
    _same(shared(p, vi, unasked, sweep.counts, steps, cal),
          profiler(p, vi, unasked, sweep.counts, steps, cal))
    # a reading gone: other polylines and windows, a call of its own, the extra ones with it
    fewer = np.delete(vi, 11)
    _same(shared(p, fewer, later - 1, sweep.counts, steps, cal),
          profiler(p, fewer, later - 1, sweep.counts, steps, cal))
    assert calls[-1] == np.union1d(later - 1, extra[fewer].nonzero()[0]).size
    on_fewer = extra[fewer].nonzero()[0]
    _same(shared(p, fewer.copy(), on_fewer, sweep.counts, steps, cal),
          profiler(p, fewer, on_fewer, sweep.counts, steps, cal))
    apart = np.zeros(vi.size, dtype=bool)
    apart[::5] = True
    _same(shared(p, vi, first, sweep.counts, steps, cal, apart=apart),
          profiler(p, vi, first, sweep.counts, steps, cal, apart=apart))
    assert len(calls) == 4


@pytest.mark.parametrize("profiler", [profiles_compiled, range_profiles])
def test_a_first_call_that_asked_nothing_answers_a_later_one_by_a_call_of_its_own(profiler):
    """First asked for no reading with no extra ones (nothing shared), then for three: a
    call of its own (a corridor room crashed here, IndexError taking from nothing)."""
    cal = stand_in_calibration(strength=0.6, noise_counts=2.0)
    room = polygon([(-0.43, -0.36), (0.55, -0.31), (0.49, 0.42), (-0.35, 0.53)])
    sweep, _, _ = make_sweep(cal, walls=room, noise_counts=2.0, seed=5,
                             pose=(0.02, -0.04, 0.3), quantize=True)
    p = estimate_detail(sweep, cal).points
    steps = np.asarray(sweep.steps)
    index = scan_order(steps, p.valid.shape[1])
    vi = index[p.valid.reshape(-1)[index]]
    calls = []

    def counting(*a, **k):
        calls.append(a[2].size)
        return profiler(*a, **k)

    shared = SharedProfiles(counting, np.zeros(p.valid.size, dtype=bool))
    none = np.zeros(0, dtype=np.intp)
    _same(shared(p, vi, none, sweep.counts, steps, cal),
          profiler(p, vi, none, sweep.counts, steps, cal))
    some = np.array([1, 4, 9], dtype=np.intp)
    _same(shared(p, vi, some, sweep.counts, steps, cal),
          profiler(p, vi, some, sweep.counts, steps, cal))
    assert calls == [0, 3]


def test_the_t_rooms_final_pass_profiles_once_with_the_same_estimate(monkeypatch):
    """On the bundled T-room the short far lines' doubt takes its members' profiles from
    local_incidence's call: one kernel call fewer, and the estimate bit for bit the one
    each pass's own call gives."""
    from irring.scenario import load_scenario
    from irring.simulation.sim import SimRing
    from irring.estimation.calibration import Calibration

    sc = load_scenario("t_room")
    sweep, cal = SimRing(sc, seed=3).sweep(0), Calibration.for_scene(sc)
    kernel, calls = _lines.profiles, []

    def counting(*a, **k):
        calls.append(1)
        return kernel(*a, **k)

    monkeypatch.setattr(_lines, "profiles", counting)
    shared = estimate_detail(sweep, cal).points
    n_shared = len(calls)
    calls.clear()
    monkeypatch.setattr(est, "SharedProfiles", lambda profiler, extra: profiler)
    own = estimate_detail(sweep, cal).points
    assert n_shared == len(calls) - 1 >= 1
    for f in ("x", "y", "d", "theta", "sigma_m", "valid", "reason"):
        assert getattr(shared, f).tobytes() == getattr(own, f).tobytes(), f
