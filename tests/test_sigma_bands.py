"""A reading's σ against its range error, per distance band (docs/estimator.md, "A reading's
σ against its error"; `irring bench sigma`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from irring import pipeline
from irring.estimation import estimate as fast
from irring.estimation import silence as est_silence
from irring.scenario import loads
from irring.studies import sigma

from test_far_end import CRATES_A02


def test_band_table_counts_and_ratios_exactly():
    true = np.array([0.10, 0.35, 0.36, 0.70, 0.95, 1.40])
    err = np.array([0.002, -0.010, 0.030, 0.000, 0.008, -0.020])
    sig = np.array([0.001, 0.010, 0.010, 0.005, 0.004, 0.010])
    rows = sigma.band_table(true, err, sig, 1.5, bands=3)
    assert [r["n"] for r in rows] == [3, 2, 1]
    assert rows[0]["z_rms"] == pytest.approx(math.sqrt((4 + 1 + 9) / 3))
    assert rows[0]["beyond_2sigma"] == pytest.approx(1 / 3)   # 3σ is past 2σ, 2σ itself not
    assert rows[1]["err_rms_m"] == pytest.approx(math.sqrt(0.008 ** 2 / 2))
    assert rows[2]["sigma_median_m"] == 0.010 and rows[2]["z_rms"] == pytest.approx(2.0)
    empty = sigma.band_table(true, err, sig, 0.05, bands=2)
    assert empty[0]["n"] == 0 and empty[0]["z_rms"] is None


def test_on_simulated_walls_no_band_understates_its_error():
    """Seed 0 of each wall room: err/σ RMS per fifth of the range stays under Z_HIGH in every
    band of every sensor; near the sensor σ overstates the error 2-4× (GP2Y0A21 0.32-0.48 m:
    err/σ 0.24), the far fifth comes closest (0.67-0.95)."""
    rows = sigma.measure(sigma.wall_rooms(), 1)
    assert [r["sensor"] for r in rows] == ["gp2d12", "gp2y0a21", "gp2y0a02"]
    for r in rows:
        z = [b["z_rms"] for b in r["bands"] if b["n"]]
        assert len(z) == 3 and max(z) < sigma.Z_HIGH, (r["name"], z)
        assert z[-1] == max(z) and z[-1] > 0.6
    assert min(b["z_rms"] for r in rows for b in r["bands"] if b["n"]) < 0.3


def test_faces_ending_at_the_far_end_understate_less_without_straddling_pools(monkeypatch):
    """CRATES_A02, seeds 4307-4309, true distance 1.20-1.35 m (the GP2Y0A02's 80-90 % of its
    1500 mm): err/σ RMS 2.00 and 17.9 % beyond 2σ while pools straddled a face's end (2.16
    and 21.6 % before the short far lines' doubt ran on every part); 1.68 and 15.7 % since
    POOL_SIDE_SIGMAS. Still above 1: those faces' lines hold a selection of their readings
    (docs/estimator.md). (The pools' halves alone: dim returns put on those faces' lines
    raise that band to 1.83, their members' σ short of their lines' error.)"""
    monkeypatch.setattr(fast, "dim_returns_on_lines", lambda points, *a, **k: points)
    scene = loads(CRATES_A02)

    def band():
        parts = [sigma.reading_z(pipeline.run(scene, seed=s, progress=False, score=False))
                 for s in (4307, 4308, 4309)]
        td, err, sig = (np.concatenate(a) for a in zip(*parts))
        return sigma.band_table(td, err, sig, 1.5, bands=10)[8]

    after = band()
    monkeypatch.setattr(est_silence, "POOL_SIDE_SIGMAS", -math.inf)
    before = band()
    assert before["z_rms"] > 1.98 and before["beyond_2sigma"] > 0.175
    assert 1.25 < after["z_rms"] < before["z_rms"] - 0.3 and after["beyond_2sigma"] < 0.17
