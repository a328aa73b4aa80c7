"""Long sweeps (a device of 12 × 36,000 steps): the estimator's cost grows with a sweep's readings, not their
square, with the same results; a sweep past the work budget is refused before the work."""

from __future__ import annotations

import dataclasses
import json
import math
import tracemalloc

import numpy as np
import pytest

from _synthetic import stand_in_calibration
from irring.cli import main
from irring.core import ESTIMATE_BYTES_PER_READING, MAX_ESTIMATED_READINGS, Reason
from irring.errors import TooBig
from irring.estimation import arcs
from irring.estimation import estimate_numpy as oracle
from irring.estimation.estimate import check_work, estimate
from irring.estimation.far_lines import (POST_LINK_M, POST_RUN_MAX, POST_SENSORS, post_cells,
                                         post_groups_compiled)
from irring.studies.long_sweeps import circle_sweep


def _crowded_scene(seed: int):
    """Readings of 60 steps × 6 sensors, none on a line: half aimed at two spots 0.15 m
    apart (cells crowded with far more than POST_RUN_MAX of each sensor), a few at a post
    (3 to 5 of two or three sensors), one between the spots linking both, the rest
    anywhere; counts from the stand-in curve at each one's distance."""
    rng = np.random.default_rng(seed)
    cal = stand_in_calibration()
    s, n = 60, 6
    ring = rng.uniform(-math.pi, math.pi, (s, n))
    ox, oy = 0.15 * np.cos(ring), 0.15 * np.sin(ring)
    target = np.where(rng.random((s, n)) < 0.5, 0, 3)
    target[rng.random((s, n)) < 0.25] = 1
    posts = rng.choice(np.arange(s), int(rng.integers(3, 6)), replace=False)
    target[posts, rng.integers(0, int(rng.integers(2, 4)), posts.size)] = 2
    target[7, 5] = 4                                   # between the spots: links them
    spot = np.array([[0.42, 0.10], [0.42, 0.25], [-0.35, 0.20], [0.0, 0.0], [0.42, 0.175]])
    aim = spot[target] + rng.normal(0, 0.008, (s, n, 2))
    free = target == 3
    aim[free] = rng.uniform(-0.7, 0.7, (int(free.sum()), 2))
    heading = np.arctan2(aim[..., 1] - oy, aim[..., 0] - ox)
    dist = np.clip(np.hypot(aim[..., 0] - ox, aim[..., 1] - oy), 0.09, 0.75)
    counts = cal.counts(dist, 0.0)
    reason = np.where(rng.random((s, n)) < 0.5, Reason.OK, Reason.INCIDENCE_UNKNOWN
                      ).astype(np.uint8)
    points = dataclasses.make_dataclass("P", ["reason", "valid", "heading", "origin_x",
                                              "origin_y"])(
        reason, reason == Reason.OK, heading, ox, oy)
    return points, np.full((s, n), -1, dtype=np.intp), counts, cal


def _all_pairs_groups(px, py, col, n_sensors):
    """The far posts' qualifying groups as stated before the cells: every pair compared."""
    near = np.hypot(px[:, None] - px[None, :], py[:, None] - py[None, :]) < POST_LINK_M
    comp = np.arange(px.size)
    while True:
        low = np.where(near, comp[None, :], px.size).min(axis=1)
        if np.array_equal(low, comp):
            break
        comp = low
    groups = []
    for g in np.unique(comp):
        per = np.bincount(col[comp == g], minlength=n_sensors)
        if per.sum() >= 3 and np.count_nonzero(per) >= POST_SENSORS and per.max() <= POST_RUN_MAX:
            groups.append(tuple((comp == g).nonzero()[0]))
    return groups


def test_post_groups_by_cells_find_the_groups_every_pair_finds():
    """_lines.post_groups and its numpy statement, pairing candidates cell by cell (two
    crowded cells not compared), agree bit for bit, and their qualifying groups are
    exactly those comparing every pair gives, on 20 scenes whose cells are crowded, two
    crowded spots linked through one reading between them, and a post qualifying."""
    crowded = posts = 0
    for seed in range(20):
        args = _crowded_scene(seed)
        fast, slow = post_groups_compiled(*args), oracle.post_groups(*args)
        assert fast is not None and slow is not None, f"seed {seed}"
        for name, a, b in zip(("row", "col", "comp", "groups", "px", "py"), fast, slow):
            np.testing.assert_array_equal(a, b, err_msg=f"seed {seed}: {name}")
        row, col, comp, groups, px, py = fast
        found = [tuple((comp == g).nonzero()[0]) for g in groups]
        assert found == _all_pairs_groups(px, py, col, 6), f"seed {seed}"
        crowded += int(post_cells(px, py, POST_LINK_M, POST_RUN_MAX * 6)[2].sum())
        posts += len(found)
    assert crowded >= 40 and posts >= 20


def test_arc_fits_in_blocks_are_the_fits_at_once(monkeypatch):
    """arc_incidence scored ARC_BLOCK circle-readings at a time gives every output to the
    last bit as scored at once: a full-circle sweep (360 steps of 1°, every reading
    returning) whose twelve runs of 360 readings are tried as arcs (466,560 circle-
    readings), in blocks of 1,000, of the default, and at once."""
    calls = []
    fit = arcs.arc_incidence
    monkeypatch.setattr(arcs, "arc_incidence", lambda *a: calls.append(a) or fit(*a))
    estimate(*circle_sweep(360, 12, 1.0))
    assert [c[1].size for c in calls] == [4320]
    outs = []
    for block in (1_000, arcs.ARC_BLOCK, 10**9):
        monkeypatch.setattr(arcs, "ARC_BLOCK", block)
        outs.append(fit(*calls[0]))
    for out in outs[:2]:
        for a, b in zip(out, outs[2]):
            np.testing.assert_array_equal(a, b)
    theta, misfit = outs[2][0], outs[2][4]          # each reading read on its run's circle
    assert np.isfinite(theta).all() and np.count_nonzero(misfit < arcs.ARC_MISS) > 300


def test_arc_padding_grows_with_the_readings_not_their_square():
    """A long run beside many short ones: padded all to the longest, the places tried grow
    with short runs × the long run's length (1001 runs × 36,000 = 36 million for 44,000
    readings); the batches pad at most twice over, and an ordinary sweep's runs stay one
    batch padded to its longest run (its sums of misfits as before)."""
    for n_short in (1_000, 2_000, 4_000):
        size = np.array([36_000] + [8] * n_short)
        batches = arcs._arc_batches(size)
        assert sorted(np.concatenate([r for r, _ in batches]).tolist()) == list(range(size.size))
        assert all(int(size[r].max()) == w for r, w in batches)
        assert sum(r.size * w for r, w in batches) <= 2 * size.sum()
    assert [(r.tolist(), w) for r, w in arcs._arc_batches(np.array([71, 8, 12, 40]))] == [
        ([0, 1, 2, 3], 71)]


def test_the_estimators_peak_memory_stays_within_the_work_checks_model():
    """core.ESTIMATE_BYTES_PER_READING bounds what the compiled estimator holds on a long
    sweep round the full circle (4,500 steps of 0.08°, every reading returning, its runs
    tried as arcs: scored all at once, that alone held 0.65 GB): its peak traced memory
    per reading."""
    sweep, cal = circle_sweep(4500, 12, 0.08)
    estimate(sweep, cal)      # the calibration's tables, built once, not counted
    tracemalloc.start()
    try:
        estimate(sweep, cal)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak <= ESTIMATE_BYTES_PER_READING * sweep.counts.size


def test_a_sweep_past_the_work_budget_is_refused_before_estimating():
    """The estimator refuses a sweep of more than MAX_ESTIMATED_READINGS readings (one
    sweep's work within the 2 GB budget: 606,060) with what, how much and what is allowed,
    compiled and numpy alike; one of exactly that many passes the check."""
    assert MAX_ESTIMATED_READINGS == 606_060
    check_work((50_505, 12))
    sweep, cal = circle_sweep(50_506, 12)
    for run in (estimate, oracle.estimate_detail):
        with pytest.raises(TooBig) as e:
            run(sweep, cal)
        assert str(e.value) == (
            "a sweep of 50,506 steps × 12 sensors = 606,072 readings to estimate (about "
            "2.0 GB), more than the 2 GB the estimator may use: estimate at most 606,060 "
            "readings a sweep (fewer steps, or the sweep in parts)")


def test_bench_long_reports_each_sweep_per_reading(capsys):
    """`irring bench long --json`: a row per sweep asked, its steps and readings as asked,
    time and memory per reading its totals over its readings."""
    assert main(["bench", "long", "--kind", "circle", "--steps", "71", "150", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert [(w["steps"], w["readings"], w["estimator"]) for w in r["rows"]] == [
        (71, 852, "fast"), (150, 1800, "fast")]
    for w in r["rows"]:
        assert w["us_per_reading"] == pytest.approx(1e6 * w["cpu_s"] / w["readings"])
        assert w["bytes_per_reading"] == pytest.approx(w["peak_bytes"] / w["readings"])
        assert w["peak_bytes"] > 8 * w["readings"]        # at least the sweep's own counts
    assert r["model_bytes_per_reading"] == ESTIMATE_BYTES_PER_READING
