"""The ideal sensor must never map worse than the noisy one (issue 13): a reading no θ moves
stays within its noise (docs/estimator.md, "A θ-free reading stays within its noise")."""

from __future__ import annotations

import numpy as np

from irring import pipeline
from irring.core import Points
from irring.estimation.calibration import Calibration
from irring.estimation.lines import placed_at, theta0_sigma
from irring.estimation.profiles import THETA_FREE_SIGMAS, theta_free_in_noise
from irring.maps import metrics
from irring.scenario import loads
from irring.studies.rooms import ideal


def test_a_theta_free_reading_placed_past_its_noise_goes_back_to_its_counts():
    """A calibration without θ dependence (the ideal sensor's): readings read 40 mm and
    2·σ0 short of their counts' θ = 0 distance. The first go back to θ = 0 with their
    θ = 0 σ; the others (within THETA_FREE_SIGMAS σ0) stay. With incidence (θ dependence)
    nothing moves."""
    sc = loads(CLUTTER)
    flat, bent = Calibration.for_scene(ideal(sc)), Calibration.for_scene(sc)
    assert flat.theta_free and not flat.folds and not bent.theta_free
    d_true = np.array([[0.31, 0.47], [0.52, 0.23]])
    counts = flat.counts(d_true, 0.0)
    n = d_true.shape
    points = Points(x=d_true.copy(), y=np.zeros(n), d=d_true.copy(), theta=np.zeros(n),
                    origin_x=np.zeros(n), origin_y=np.zeros(n), heading=np.zeros(n),
                    sigma_m=np.full(n, 0.012), iterations=np.ones(n, int),
                    valid=np.ones(n, bool), reason=np.zeros(n, np.uint8), max_range_m=0.8)
    np.testing.assert_allclose(flat.distance(counts, 0.0), d_true, atol=1e-9)
    sigma0 = theta0_sigma(flat, counts.ravel(), d_true.ravel(),
                          flat.sigma_counts() / counts.ravel()).reshape(n)
    assert np.all(sigma0 < 0.004)
    # at its counts' distance a reading stays as it is, σ and all
    same = theta_free_in_noise(points, counts, flat)
    np.testing.assert_array_equal(same.d, points.d)
    np.testing.assert_array_equal(same.sigma_m, points.sigma_m)
    short = d_true - np.array([[0.040, 2 * sigma0[0, 1]], [2 * sigma0[1, 0], 0.040]])
    moved = placed_at(points, np.arange(4), short.ravel(), 0.0, np.full(4, 0.012))
    out = theta_free_in_noise(moved, counts, flat)
    far = np.array([[True, False], [False, True]])
    assert 2 < THETA_FREE_SIGMAS
    np.testing.assert_allclose(out.d[far], d_true[far], atol=1e-9)
    np.testing.assert_allclose(out.x[far], d_true[far], atol=1e-9)
    np.testing.assert_allclose(out.sigma_m[far], sigma0[far])
    np.testing.assert_array_equal(out.d[~far], short[~far])
    np.testing.assert_array_equal(out.sigma_m[~far], 0.012)
    same = theta_free_in_noise(moved, bent.counts(d_true, 0.0), bent)
    np.testing.assert_array_equal(same.d, moved.d)


# A room of our own (gen seed 373's g18a_031): a GP2D12 clutter room, 10 mm cells. From the
# second pose a post of radius 12 mm hides part of the right wall; the steps of sensor 10
# before it reach past the post to that wall.
CLUTTER = """\
name: clutter
seed: 20910
room:
  outline_mm: [[702.1, 4788.2], [3100.4, 4070.0], [3673.4, 5983.5], [1275.1, 6701.7]]
obstacles:
  - {type: box, center_mm: [2555.9, 5289.7], size_mm: [190.6, 249.5], yaw_deg: 47.18}
  - {type: box, center_mm: [2416.2, 5948.0], size_mm: [289.4, 65.7], yaw_deg: -0.00}
  - {type: cylinder, center_mm: [2912.4, 6026.4], radius_mm: 57.3}
  - {type: cylinder, center_mm: [1098.1, 5110.3], radius_mm: 41.6}
  - {type: cylinder, center_mm: [2340.7, 4763.2], radius_mm: 30.4}
  - {type: cylinder, center_mm: [2532.2, 5506.8], radius_mm: 46.0}
  - {type: box, center_mm: [1371.0, 6145.1], size_mm: [241.6, 294.7], yaw_deg: 12.36}
  - {type: cylinder, center_mm: [3061.1, 5609.8], radius_mm: 18.5}
  - {type: cylinder, center_mm: [2517.1, 5798.2], radius_mm: 50.3}
  - {type: cylinder, center_mm: [2462.3, 4869.5], radius_mm: 23.5}
  - {type: cylinder, center_mm: [3525.6, 5854.8], radius_mm: 22.2}
  - {type: cylinder, center_mm: [2866.9, 4601.8], radius_mm: 15.8}
  - {type: box, center_mm: [3218.2, 5386.7], size_mm: [263.1, 159.9], yaw_deg: -58.70}
  - {type: box, center_mm: [2237.1, 6272.5], size_mm: [163.0, 120.4], yaw_deg: 40.16}
  - {type: box, center_mm: [1547.3, 4681.3], size_mm: [200.6, 90.1], yaw_deg: 62.43}
  - {type: box, center_mm: [3229.3, 5877.2], size_mm: [299.9, 134.3], yaw_deg: -15.88}
  - {type: box, center_mm: [2101.4, 4931.5], size_mm: [271.5, 213.4], yaw_deg: -82.14}
  - {type: cylinder, center_mm: [3020.4, 4581.4], radius_mm: 12.0}
  - {type: cylinder, center_mm: [2735.2, 5073.6], radius_mm: 23.0}
  - {type: cylinder, center_mm: [1862.0, 5795.6], radius_mm: 55.8}
robot:
  design: rotating12
  poses:
    - {x_mm: 1503.2, y_mm: 5139.1, yaw_deg: -145.5}
    - {x_mm: 2505.3, y_mm: 4512.7, yaw_deg: 59.3}
    - {x_mm: 2143.4, y_mm: 5634.2, yaw_deg: -8.3}
sensor: {model: gp2d12, adc_bits: 12}
effects:
  incidence: {}
  noise: {sigma_v: 0.015}
  quantization: {}
map: {resolution_mm: 10}
"""


def test_the_ideal_sensor_reads_the_wall_behind_a_post_at_its_counts():
    """CLUTTER, seed 20910, second pose, sensor 10, steps 36–45: exact θ = 0 readings of the
    wall 576–616 mm away. The estimator put them on a line 30–44 mm short (σ 11–16 mm): the
    ideal map lost two wall cells behind the post (shadow 0.375 against the noisy 0.411) and
    marked free floor 40 mm in front of the wall (precision 0.9925). Now they are read at
    their counts, and no score of the ideal map is below the noisy one's."""
    sc = loads(CLUTTER)
    runs, scores = {}, {}
    for name, scene in (("noisy", sc), ("ideal", ideal(sc))):
        runs[name] = run = pipeline.run(scene, progress=False, score=False)
        scores[name] = metrics.score(run.grid, sc, metrics.ground_truth(sc, run.grid),
                                     mapped_by=scene)
    pts, sweep = runs["ideal"].points[1], runs["ideal"].sweeps[1]
    rows = slice(36, 46)
    hit = sweep.truth.hit_point[rows, 10]
    true_d = np.hypot(hit[:, 0] - pts.origin_x[rows, 10], hit[:, 1] - pts.origin_y[rows, 10])
    assert np.all(pts.valid[rows, 10])
    assert np.all((true_d > 0.57) & (true_d < 0.62))
    assert np.max(np.abs(pts.d[rows, 10] - true_d)) < 0.001
    for key in scores["noisy"]:
        if scores["noisy"][key] is not None:
            assert scores["ideal"][key] >= scores["noisy"][key], key
    assert scores["ideal"]["occupied_precision"] == 1.0
