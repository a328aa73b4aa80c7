"""The paper's design geometry: Eq. 1, Eq. 2, Eq. 3, and the Monte-Carlo overlap."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from irring import geometry as g

DEG = math.pi / 180


# --------------------------------------------------------------------------- paper numbers


def test_table_i_beta_and_area_match_the_paper():
    t = g.table_i()
    assert t["beta_deg"] == pytest.approx(19.56, abs=0.01)
    assert t["overlap_area_m2"] == pytest.approx(0.1376, abs=0.0005)
    assert round(t["overlap_area_m2"], 3) == 0.138  # the paper's printed value


def test_eq1_blind_spot_paper_example():
    # "r = 0.016 m with Δθ = 1.8° and d = 1 m"
    assert g.blind_spot_m(1.0, 1.8 * DEG) == pytest.approx(0.016, abs=0.0005)


def test_eq1_grows_linearly_with_distance_and_is_vectorised():
    d = np.array([0.25, 0.5, 1.0, 2.0])
    r = g.blind_spot_m(d, 1.08 * DEG)
    assert r.shape == d.shape
    np.testing.assert_allclose(r / d, r[0] / d[0], rtol=1e-12)


def test_eq1_edge_cases():
    assert g.blind_spot_m(1.0, 0.0) == 0.0               # a continuous fan misses nothing
    assert g.blind_spot_m(1.0, math.pi) == math.inf      # two opposite rays bound nothing


@given(d=st.floats(0.05, 10.0), step=st.floats(0.01 * DEG, 90 * DEG))
@settings(max_examples=200, deadline=None)
def test_eq1_circle_of_radius_r_touches_both_rays(d, step):
    """The circle of Eq. 1's radius, centred on the bisector at distance d + r from the apex
    (d is the distance to its near side), is tangent to both rays — the definition."""
    r = g.blind_spot_m(d, step)
    centre = d + r
    assert centre * math.sin(step / 2) == pytest.approx(r, rel=1e-9)


def test_eq2_no_overlap_when_alpha_is_small():
    # sensors that sweep less than half their spacing cannot overlap
    beta = g.overlap_angle_rad(0.15, 0.686, 30 * DEG, 10 * DEG)
    assert beta < 0
    assert g.overlap_area_m2(0.15, 0.686, 30 * DEG, 10 * DEG) == 0.0


def test_eq2_range_shorter_than_ring_gap_is_a_clear_error():
    with pytest.raises(ValueError, match="cannot overlap"):
        g.overlap_angle_rad(1.0, 0.1, 90 * DEG, 40 * DEG)


# --------------------------------------------------------------------------- Monte Carlo


def ideal_sectors(n: int, radius_m: float, alpha_rad: float) -> g.SweptSectors:
    rho = np.arange(n) * 2 * np.pi / n
    apex = np.c_[radius_m * np.cos(rho), radius_m * np.sin(rho)]
    return g.SweptSectors(apex, rho - alpha_rad, rho + alpha_rad)


def test_monte_carlo_of_ideal_sectors_agrees_with_eq3():
    mc, se = g.overlap_area_mc_m2(ideal_sectors(12, 0.15, 37.8 * DEG), 0.686,
                                  samples=200_000, seed=1)
    exact = g.overlap_area_m2(0.15, 0.686, 30 * DEG, 37.8 * DEG)
    assert se < 0.001
    assert mc == pytest.approx(exact, abs=4 * se + 1e-4)


@pytest.mark.parametrize("n,radius,alpha,rng", [(8, 0.2, 40, 0.8), (16, 0.1, 20, 0.5),
                                                (6, 0.25, 45, 1.2)])
def test_eq3_holds_for_other_rings(n, radius, alpha, rng):
    """Eq. 3 against counting points, for rings other than Table I's."""
    exact = g.overlap_area_m2(radius, rng, 2 * math.pi / n, alpha * DEG)
    mc, se = g.overlap_area_mc_m2(ideal_sectors(n, radius, alpha * DEG), rng,
                                  samples=100_000, seed=2)
    assert mc == pytest.approx(exact, abs=4 * se + 1e-4)


def test_monte_carlo_is_deterministic_under_a_seed_and_zero_for_radial_rings():
    s = ideal_sectors(12, 0.15, 37.8 * DEG)
    assert g.overlap_area_mc_m2(s, 0.686, samples=20_000, seed=5) == \
        g.overlap_area_mc_m2(s, 0.686, samples=20_000, seed=5)
    radial, _ = g.overlap_area_mc_m2(ideal_sectors(12, 0.15, 0.0), 0.686, samples=20_000)
    assert radial == 0.0
    assert g.overlap_area_mc_m2(ideal_sectors(1, 0.0, math.pi), 0.686) == (0.0, 0.0)
