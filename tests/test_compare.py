"""Design comparison: detection geometry from the built models, and simulated scenes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from irring import compare, designs, geometry

DEG = math.pi / 180


# --------------------------------------------------------------------------- detection


def test_rays_come_from_the_built_model():
    rays = compare.design_rays(designs.get("rotating12"))
    assert len(rays) == 71 * 12
    # sensor 0 at its first step: the emitter d_o right of the hinge at (0.15, 0), beam −37.8°
    h = -37.8 * DEG
    np.testing.assert_allclose(rays.direction[0], [math.cos(h), math.sin(h)], atol=1e-9)
    np.testing.assert_allclose(rays.origin[0], [0.15 + 0.007 * math.sin(h), -0.007 * math.cos(h)],
                               atol=1e-9)
    sonar = compare.design_rays(designs.get("sonar12"))
    assert len(sonar) == 12 * 121            # a fan every 0.25° across ±15°


def test_a_centred_scanner_matches_eq1():
    """The laser (one emitter at the centre, 0.5° steps) misses exactly Eq. 1's cylinder."""
    d = np.array([0.5, 1.0, 2.0])
    det = compare.detection(designs.get("laser"), d, bearings=60)
    eq1 = geometry.blind_spot_m(d, 0.5 * DEG)
    np.testing.assert_allclose(det.min_detectable_radius_m, eq1, rtol=0.03)
    assert np.all(det.max_missed_radius_m < det.min_detectable_radius_m)


def test_overlap_beats_a_single_scanner_and_radial_rings_miss_table_legs():
    d = (0.35, 0.55, 0.7)
    ring = compare.detection(designs.get("rotating12"), d, bearings=120)
    single = compare.detection(designs.get("rotating1"), d, bearings=60)
    radial = compare.detection(designs.get("radial12"), d, bearings=120)
    # overlapping sweeps of neighbours close the gaps a single 1.08° scanner leaves
    assert ring.min_detectable_radius_m[0] < 0.8 * single.min_detectable_radius_m[0]
    # past the GP2's 624 mm the centred scanner sees nothing; the ring still reaches
    assert math.isinf(single.min_detectable_radius_m[2])
    assert ring.min_detectable_radius_m[2] < 0.01
    # a 22 mm table leg hides between radial beams 30° apart
    assert np.all(radial.min_detectable_radius_m > 0.1)
