"""The sonar cone stage: nearest specular echo inside the cone."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from irring import gp2, scenario
from irring.simulation import effects, rangers
from irring.core import Truth
from irring.scenario import load_scenario

DEG = math.pi / 180


@dataclass(frozen=True)
class RayHits:  # the fields the stage reads from sim.RayHits
    distance_m: np.ndarray
    incidence_rad: np.ndarray
    hit_point: np.ndarray
    geom_id: np.ndarray
    reflectance: np.ndarray


def wall_and_post(wall_x=1.0, post=(0.6, 0.25), post_r=0.02, max_range=6.45):
    """An analytic caster: a wall x = wall_x (normal −x) and a post (circle)."""

    def cast(origin, direction):
        o, u = origin[..., :2], direction[..., :2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t_wall = np.where(u[..., 0] > 0, (wall_x - o[..., 0]) / u[..., 0], np.inf)
        inc_wall = np.arccos(np.clip(u[..., 0], -1, 1))
        rel = np.asarray(post) - o
        along = np.einsum("...i,...i->...", rel, u)
        across = rel[..., 0] * u[..., 1] - rel[..., 1] * u[..., 0]
        p = np.abs(across) / post_r
        with np.errstate(invalid="ignore"):
            t_post = np.where((p <= 1) & (along > 0), along - post_r * np.sqrt(1 - p ** 2), np.inf)
        inc_post = np.arcsin(np.clip(p, 0, 1))
        post_first = t_post < t_wall
        t = np.where(post_first, t_post, t_wall)
        inc = np.where(post_first, inc_post, inc_wall)
        t = np.where(t <= max_range, t, np.nan)
        inc = np.where(np.isnan(t), np.nan, inc)
        shape = t.shape
        return RayHits(t, inc, np.full(shape + (3,), np.nan), np.zeros(shape, int),
                       np.where(np.isnan(t), np.nan, 1.0))

    return cast


def truth_for(headings_rad):
    h = np.asarray(headings_rad, dtype=float)[None, :]
    direction = np.stack([np.cos(h), np.sin(h), np.zeros_like(h)], axis=-1)
    origin = np.zeros(h.shape + (3,))
    nan = np.full(h.shape, np.nan)
    return Truth(nan, nan, np.full(h.shape + (3,), np.nan), origin, direction,
                 np.full(h.shape, -1), nan)


def sonar_pipeline(**cone):
    setup = effects.Setup(model=gp2.sensor("sonar"), adc_bits=16)
    return effects.Pipeline(setup, (rangers.SonarConeStage(rangers.SonarCone(**cone), setup),))


def read_m(counts):
    return gp2.sensor("sonar").distance(gp2.voltage_from_counts(counts, 16, 5.0))


def test_nearest_specular_echo():
    pipe = sonar_pipeline()
    # 0°: wall square on → 1 m. 10° off: the wall's normal is still in the ±15° cone → 1 m.
    # 40° off: the normal is outside the cone and the wall echoes away → no return.
    counts = pipe.run(truth_for([0, 10 * DEG, 40 * DEG]), cast=wall_and_post(post=(5, 5)))
    d = read_m(counts)[0]
    assert d[0] == pytest.approx(1.0, abs=1e-9)
    assert d[1] == pytest.approx(1.0, abs=1e-9)
    assert d[2] == pytest.approx(gp2.sensor("sonar").max_range_m)   # no-return reading


def test_a_post_inside_the_cone_is_heard_first_whatever_its_bearing():
    pipe = sonar_pipeline()
    post = (0.6, 0.6 * math.tan(12 * DEG))          # 12° off axis, nearer than the wall
    d = read_m(pipe.run(truth_for([0.0]), cast=wall_and_post(post=post)))[0, 0]
    assert d == pytest.approx(math.hypot(*post) - 0.02, abs=2e-3)
    # a pencil beam (one ray) misses the same post and reads the wall
    pencil = sonar_pipeline(rays=1)
    assert read_m(pencil.run(truth_for([0.0]), cast=wall_and_post(post=post)))[0, 0] == \
        pytest.approx(1.0)


def test_pipeline_for_adds_the_cone_only_for_sonar():
    sc = load_scenario("t_room_cylinder")
    assert "beam" not in rangers.pipeline_for(sc).names
    sonar = rangers.pipeline_for(scenario.apply_design(sc, "sonar12"))
    assert isinstance(sonar.stages[0], rangers.SonarConeStage)
    assert sonar.stages[0].offsets_rad[-1] == pytest.approx(15 * DEG)
    with pytest.raises(ValueError, match="pass cast="):
        sonar.run(truth_for([0.0]))
