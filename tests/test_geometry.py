"""The paper's design geometry: Eq. 1, Eq. 2, Eq. 3, and the Monte-Carlo overlap."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from irring.studies import geometry as g

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


# --------------------------------------------------------------------------- the built model

from irring import core, designs  # noqa: E402


@pytest.fixture(scope="module")
def paper_model():
    from irring.simulation import model

    return model.compile_ring(designs.PAPER_RING)


def test_monte_carlo_from_the_mjcf_frames_agrees_with_table_i(paper_model):
    sectors = g.swept_sectors(paper_model)
    mc, se = g.overlap_area_mc_m2(sectors, g.TABLE_I_D_M, samples=200_000, seed=3)
    analytic = g.table_i()["overlap_area_m2"]
    assert abs(mc - analytic) / analytic < 0.02
    assert se / analytic < 0.005          # the 2 % is not lost in sampling noise
    # the frames really are the paper's: hinges at R, sweep limits ±37.8° off radial
    rho = np.arange(12) * 30 * DEG
    np.testing.assert_allclose(np.hypot(*sectors.apex_xy.T), 0.15, atol=1e-9)
    np.testing.assert_allclose(np.cos(sectors.heading_min_rad - (rho - 37.8 * DEG)), 1, atol=1e-9)
    np.testing.assert_allclose(sectors.width_rad, 2 * 37.8 * DEG, atol=1e-9)


def test_model_frames_follow_the_beam_geometry_convention(paper_model):
    """Emitters and headings read from MuJoCo equal core.beam_geometry (the one frame
    convention the estimator uses)."""
    for step in (-35, 0, 17, 35):
        f = g.model_frames(paper_model, step)
        angles = core.sensor_angles_for_steps(designs.PAPER_RING, np.array([step]))
        xy, heading = core.beam_geometry(designs.PAPER_RING, np.zeros(3), angles,
                                         designs.PAPER_RING.emitter_offset_m)
        np.testing.assert_allclose(f.emitter_xyz[:, :2], xy[0], atol=1e-9)
        np.testing.assert_allclose(np.cos(f.heading_rad - heading[0]), 1, atol=1e-12)


def test_monte_carlo_sees_the_model_not_the_formula_inputs():
    """A model built with another radius gives another area: the MC measures the frames."""
    from irring.simulation import model

    other = model.compile_ring(designs.parametric(12, 0.30, 37.8 * DEG, 1.08 * DEG).ring)
    mc, _ = g.overlap_area_mc_m2(g.swept_sectors(other), g.TABLE_I_D_M, samples=50_000)
    assert mc == pytest.approx(g.overlap_area_m2(0.30, 0.686, 30 * DEG, 37.8 * DEG), rel=0.03)
    assert abs(mc - g.table_i()["overlap_area_m2"]) / g.table_i()["overlap_area_m2"] > 0.05


def test_design_report_for_every_named_design():
    for d in designs.DESIGN_LIST:
        r = g.design_report(d, distances_m=(0.5, 1.0), samples=20_000)
        assert set(r) >= {"beta_deg", "overlap_area_m2", "overlap_area_mc_m2", "blind_spot_m"}
        assert len(r["blind_spot_m"]) == 2
        if d.name != "rotating12":
            assert r["overlap_area_m2"] == 0.0 and r["overlap_area_mc_m2"] == 0.0
    paper = g.design_report(designs.get("rotating12"), samples=20_000)
    assert paper["beta_deg"] == pytest.approx(19.56, abs=0.01)
    # Eq. 1 with the ring's 1.08° step: 9.5 mm at 1 m
    assert paper["blind_spot_m"][-1] == pytest.approx(g.blind_spot_m(1.0, 1.08 * DEG))


def test_cli_geometry_json_has_the_contract_keys(capsys):
    import json

    from irring.cli import main

    assert main(["geometry", "--json", "--samples", "50000", "--distances-mm", "500,1000"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["beta_deg"] == pytest.approx(19.56, abs=0.01)
    assert out["overlap_area_m2"] == pytest.approx(0.1376, abs=0.0005)
    assert out["overlap_area_mc_m2"] == pytest.approx(0.1376, rel=0.02)
    assert out["distances_m"] == [0.5, 1.0] and len(out["blind_spot_m"]) == 2
    assert main(["geometry", "--design", "radial12", "--samples", "5000"]) == 0
    assert "0.0000 m²" in capsys.readouterr().out


def test_geometry_prints_the_sonar_rings_blind_spot_from_its_rays(capsys):
    import json

    from irring import designs
    from irring.cli import main

    assert main(["geometry", "--design", "sonar12", "--json", "--samples", "1000",
                 "--distances-mm", "500,1000"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["blind_spot_m"] == [0.0, 0.0]        # Eq. 1: the ±15° cones touch
    det = g.detection(designs.get("sonar12"), [0.5, 1.0])
    assert report["blind_spot_rays_m"] == det.min_detectable_radius_m.tolist()
    assert 0.09 < report["blind_spot_rays_m"][0] < 0.13   # yet posts of ~11 cm hide
    assert main(["geometry", "--design", "sonar12", "--samples", "1000",
                 "--distances-mm", "500"]) == 0
    text = capsys.readouterr().out
    assert "Eq. 1: 0.0 mm; rays: posts up to 112 mm hide" in text


def test_a_negative_overlap_angle_is_printed_as_the_gap_it_is(capsys):
    from irring.cli import main

    assert main(["geometry", "--design", "radial12", "--samples", "1000"]) == 0
    text = capsys.readouterr().out
    assert "none: neighbouring sweeps 18.24° apart (Eq. 2 gives -18.24°)" in text
    assert "rays:" not in text                          # a pencil beam: Eq. 1 is the answer


def test_the_monte_carlo_reports_each_pair_without_changing_the_area():
    """``on_pair`` (irring geometry's progress bar) hears of the 12 pairs of the paper's
    ring, none of a lone sensor's, and the area is that of a run nobody watches."""
    from irring import designs
    from irring.simulation import model as ring_model

    heard = []
    sectors = g.swept_sectors(ring_model.compile_ring(designs.get("rotating12").ring))
    watched = g.overlap_area_mc_m2(sectors, 0.686, samples=2000, seed=3,
                                   on_pair=lambda: heard.append(1))
    assert len(heard) == 12 == len(g.neighbour_pairs(12))
    assert watched == g.overlap_area_mc_m2(sectors, 0.686, samples=2000, seed=3)
    assert g.neighbour_pairs(1) == [] and g.neighbour_pairs(2) == [(0, 1)]
