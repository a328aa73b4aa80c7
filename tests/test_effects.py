"""The effects pipeline: each effect shows its parameters; effects that are off do not exist."""

from __future__ import annotations

import dataclasses
import math
import types

import numpy as np
import pytest

from irring.simulation import effects
from irring import gp2
from irring.core import Truth, hardware_duration_s
from irring.simulation.effects import Pipeline
from irring.scenario import (EFFECTS, BeamEffect, IncidenceEffect, NoiseEffect, OutliersEffect,
                             ReflectanceEffect, TimingEffect, load_scenario)

S, N = 71, 12
GP2D12 = gp2.sensor("gp2d12")
LSB_12 = 5.0 / 4096


@pytest.fixture(scope="module")
def base():
    return load_scenario("t_room")


def scene(base, effects_: dict, *, samples: int = 1, model: str = "gp2d12", bits: int = 12):
    """The t_room scene with these effects ({name: params dataclass or dict of its fields})."""
    fx = {k: EFFECTS[k](**v) if isinstance(v, dict) else v for k, v in effects_.items()}
    return dataclasses.replace(
        base, effects=types.MappingProxyType(fx),
        scan=dataclasses.replace(base.scan, samples=samples),
        sensor=dataclasses.replace(base.sensor, model=model, adc_bits=bits))


def truth(d, incidence=None, reflectance=None, direction=None, origin=None) -> Truth:
    d = np.asarray(d, dtype=float)
    shape = d.shape
    inc = np.zeros(shape) if incidence is None else np.broadcast_to(incidence, shape)
    refl = np.ones(shape) if reflectance is None else np.broadcast_to(reflectance, shape)
    hit = ~np.isnan(d)
    if direction is None:
        direction = np.zeros(shape + (3,))
        direction[..., 0] = 1.0
    if origin is None:
        origin = np.zeros(shape + (3,))
    return Truth(distance_m=d, incidence_rad=np.where(hit, inc, np.nan),
                 hit_point=origin + np.where(hit, d, np.nan)[..., None] * direction,
                 origin=origin, direction=direction, geom_id=np.where(hit, 0, -1),
                 reflectance=np.where(hit, refl, np.nan))


def spread(lo=0.12, hi=0.78, seed=0, shape=(S, N)) -> np.ndarray:
    return np.random.default_rng(seed).uniform(lo, hi, shape)


def ideal_counts(d, theta=0.0, model=GP2D12, bits=12):
    return gp2.counts_from_voltage(model.voltage(d, theta), bits, 5.0)


def draws(p: Pipeline, t: Truth, sweeps: int, seed: int = 7) -> np.ndarray:
    """Counts of `sweeps` sweeps of the same truth (≥ 10,000 readings for 12 sweeps)."""
    rng = np.random.default_rng(seed)
    return np.stack([p.run(t, rng) for _ in range(sweeps)])


# --------------------------------------------------------------------------- ideal curve


@pytest.mark.parametrize("model", ["gp2d12", "gp2y0a21", "gp2y0a02", "sonar", "laser"])
@pytest.mark.parametrize("bits", [10, 12])
def test_no_effects_counts_invert_to_the_true_distance(base, model, bits):
    m = gp2.sensor(model)
    p = Pipeline.from_scenario(scene(base, {}, model=model, bits=bits))
    assert p.stages == ()
    d = np.linspace(m.min_range_m, m.max_range_m, S * N).reshape(S, N)
    counts = p.run(truth(d), rng=None)  # no stage draws, so no generator is needed
    assert counts.dtype == np.float64 and counts.shape == (S, N)
    back = m.distance(gp2.voltage_from_counts(counts, bits, 5.0))
    assert np.max(np.abs(back - d)) < 1e-9


def test_no_return_reads_the_noise_floor(base):
    d = spread()
    d[::3, ::2] = np.nan
    counts = Pipeline.from_scenario(scene(base, {})).run(truth(d))
    floor = gp2.counts_from_voltage(GP2D12.no_return_v)
    assert np.all(counts[np.isnan(d)] == floor)
    assert np.all(counts[~np.isnan(d)] > floor)


# --------------------------------------------------------------------------- construction


def test_scene_without_an_effect_never_constructs_it(base, monkeypatch):
    all_on = {name: EFFECTS[name]() for name in effects.STAGE_ORDER}
    for off, cls in effects.STAGES.items():
        with monkeypatch.context() as mp:
            def refuse(self, *a, _name=off, **k):
                raise AssertionError(f"{_name} stage constructed although the scene is without it")
            mp.setattr(cls, "__init__", refuse)
            p = Pipeline.from_scenario(scene(base, {k: v for k, v in all_on.items() if k != off}))
        assert off not in p.names
        assert not any(isinstance(s, cls) for s in p.stages)
        assert len(p.stages) == len(effects.STAGE_ORDER) - 1


def test_empty_scene_builds_nothing_and_draws_nothing(base, monkeypatch):
    for cls in effects.STAGES.values():
        monkeypatch.setattr(cls, "__init__", lambda self, *a, **k: pytest.fail("constructed"))
    p = Pipeline.from_scenario(scene(base, {}))
    assert p.stages == () and p.names == ()
    rng = np.random.default_rng(3)
    before = rng.bit_generator.state
    p.run(truth(spread()), rng)
    assert rng.bit_generator.state == before


def test_deterministic_stages_draw_no_random_numbers(base):
    p = Pipeline.from_scenario(scene(base, {"incidence": {}, "foldover": {}, "quantization": {},
                                            "reflectance": {}}))
    rng = np.random.default_rng(3)
    before = rng.bit_generator.state
    p.run(truth(spread(), incidence=0.3, reflectance=0.5), rng)
    assert rng.bit_generator.state == before


def test_stages_run_in_physical_order_whatever_the_scene_lists(base):
    listed = ["quantization", "noise", "averaging", "foldover", "incidence", "outliers"]
    p = Pipeline.from_scenario(scene(base, {k: EFFECTS[k]() for k in listed}))
    assert p.names == ("incidence", "foldover", "averaging", "outliers", "noise", "quantization")
    assert p.names == tuple(n for n in effects.STAGE_ORDER if n in listed)


def test_motion_and_timing_are_not_signal_stages(base):
    p = Pipeline.from_scenario(scene(base, {"timing": TimingEffect(), "noise": NoiseEffect()}))
    assert p.names == ("noise",)


def test_outlier_rates_must_sum_to_at_most_one(base):
    bad = OutliersEffect(short_rate=0.5, random_rate=0.4, max_rate=0.2)
    with pytest.raises(ValueError, match="short_rate \\+ random_rate \\+ max_rate = 1.1 > 1"):
        Pipeline.from_scenario(scene(base, {"outliers": bad}))


# --------------------------------------------------------------------------- each effect


def test_noise_sigma_in_volts(base):
    sigma = 0.02
    p = Pipeline.from_scenario(scene(base, {"noise": NoiseEffect(sigma_v=sigma)}))
    d = spread()
    c = draws(p, truth(d), 12)
    err_v = (c - ideal_counts(d)).ravel() * LSB_12
    assert err_v.size >= 10_000
    assert np.std(err_v) == pytest.approx(sigma, rel=0.05)
    assert abs(np.mean(err_v)) < 4 * sigma / math.sqrt(err_v.size)
    assert c.dtype == np.float64


@pytest.mark.parametrize("bits", [10, 12])
def test_quantization_rounds_to_whole_counts(base, bits):
    p = Pipeline.from_scenario(scene(base, {"quantization": {}}, bits=bits))
    d = spread(shape=(1000, N))
    c = p.run(truth(d))
    assert np.issubdtype(c.dtype, np.integer)
    err = c - ideal_counts(d, bits=bits)
    assert np.all(np.abs(err) <= 0.5)
    assert np.std(err) == pytest.approx(1 / math.sqrt(12), rel=0.05)  # uniform over one step
    # one count is vref / 2^bits volts
    assert np.diff(np.unique(gp2.voltage_from_counts(c, bits)))[:5] == pytest.approx(5.0 / 2 ** bits)


def _binomial_ok(k: int, n: int, p: float) -> bool:
    return abs(k - n * p) <= 4.0 * math.sqrt(n * p * (1 - p))


@pytest.mark.parametrize("kind", ["short", "random", "max"])
def test_outlier_rates_within_binomial_bounds(base, kind):
    rate = 0.05
    params = OutliersEffect(**{"short_rate": 0.0, "random_rate": 0.0, "max_rate": 0.0,
                               f"{kind}_rate": rate})
    p = Pipeline.from_scenario(scene(base, {"outliers": params}))
    d = np.full((S, N), 0.55)
    c = draws(p, truth(d), 12)
    hit = c != ideal_counts(d)
    n = c.size
    assert _binomial_ok(int(hit.sum()), n, rate)
    read = GP2D12.distance(gp2.voltage_from_counts(c[hit]))
    if kind == "short":  # exponential, truncated to the true range
        assert np.all(read < 0.55)
        lam, z = params.short_lambda_per_m, 0.55
        mean = 1 / lam - z * math.exp(-lam * z) / (1 - math.exp(-lam * z))
        assert np.mean(read) == pytest.approx(mean, abs=4 * 0.16 / math.sqrt(hit.sum()))
    elif kind == "random":  # uniform over the sensor's range
        assert read.min() >= GP2D12.min_range_m - 1e-9 and read.max() <= GP2D12.max_range_m + 1e-9
        assert np.mean(read) == pytest.approx(0.45, abs=0.02)
    else:  # a failed reading: nothing in range
        assert np.all(c[hit] == gp2.counts_from_voltage(GP2D12.no_return_v))


def test_outlier_mixture_rates_together(base):
    params = OutliersEffect(short_rate=0.03, random_rate=0.02, max_rate=0.04)
    p = Pipeline.from_scenario(scene(base, {"outliers": params}))
    d = np.full((S, N), 0.55)
    c = draws(p, truth(d), 12)
    floor = gp2.counts_from_voltage(GP2D12.no_return_v)
    assert _binomial_ok(int(np.sum(c != ideal_counts(d))), c.size, 0.09)
    # the random ones can land past the true range; the max-range ones sit on the floor
    assert _binomial_ok(int(np.sum(c == floor)), c.size, 0.04)


def test_foldover_one_voltage_two_distances(base):
    p = Pipeline.from_scenario(scene(base, {"foldover": {}}))
    near = np.linspace(0.02, 0.085, S * N).reshape(S, N)
    _, far = GP2D12.distances(GP2D12.voltage_folded(near))
    assert np.all(far > GP2D12.peak_distance_m)
    c_near, c_far = p.run(truth(near)), p.run(truth(far))
    assert np.allclose(c_near, c_far, rtol=1e-12)
    # without the effect the near reading stays on the far branch (higher than the peak)
    plain = Pipeline.from_scenario(scene(base, {})).run(truth(near))
    assert np.all(plain > gp2.counts_from_voltage(GP2D12.peak_v()))


def test_incidence_curve_and_grazing_dropout(base):
    p = Pipeline.from_scenario(scene(base, {"incidence": {}}))
    d = spread(shape=(1000, N))
    theta = np.random.default_rng(1).uniform(0, math.radians(89), d.shape)
    c = p.run(truth(d, incidence=theta))
    floor = gp2.counts_from_voltage(GP2D12.no_return_v)
    past = theta > math.radians(70)  # the GP2 model's limit
    assert past.sum() > 1000 and (~past).sum() > 1000
    assert np.all(c[past] == floor)
    back = GP2D12.distance(gp2.voltage_from_counts(c[~past]), theta[~past])
    assert np.max(np.abs(back - d[~past])) < 1e-9
    # read with the θ = 0 curve, a 50° return from 0.6 m is 8–16 cm long (paper Fig. 8)
    c50 = p.run(truth(np.full((1, 1), 0.6), incidence=math.radians(50)))
    assert 0.08 <= GP2D12.distance(gp2.voltage_from_counts(c50)).item() - 0.6 <= 0.16


def test_incidence_limit_from_the_scene(base):
    p = Pipeline.from_scenario(scene(base, {"incidence": IncidenceEffect(math.radians(40))}))
    c = p.run(truth(np.full((1, 2), 0.4), incidence=np.radians([[39.0, 41.0]])))
    floor = gp2.counts_from_voltage(GP2D12.no_return_v)
    assert c[0, 0] != floor and c[0, 1] == floor


def test_reflectance_shortens_reach(base):
    p = Pipeline.from_scenario(scene(base, {"reflectance": ReflectanceEffect(min_signal=0.2)}))
    d = spread(0.12, 0.79, shape=(1000, N))
    c = p.run(truth(d, reflectance=0.1))
    reach = GP2D12.max_range_m * math.sqrt(0.1 / 0.2)  # 0.566 m
    floor = gp2.counts_from_voltage(GP2D12.no_return_v)
    assert np.all((c == floor) == (d > reach))
    # 18 % grey (0.2 of white) still reaches the full range, as the datasheet says
    assert np.all(p.run(truth(d, reflectance=0.2)) == ideal_counts(d))


def test_reflectance_makes_weak_returns_noisier(base):
    sigma = 0.01
    p = Pipeline.from_scenario(scene(base, {"reflectance": ReflectanceEffect(min_signal=0.1),
                                            "noise": NoiseEffect(sigma_v=sigma)}))
    # s = ρ (0.8 / d)² = 0.25 at d = 0.4 with ρ = 0.0625 → noise σ × 2
    d = np.full((S, N), 0.4)
    weak = draws(p, truth(d, reflectance=0.0625), 12)
    bright = draws(p, truth(d, reflectance=1.0), 12)
    assert np.std(weak * LSB_12) == pytest.approx(2 * sigma, rel=0.05)
    assert np.std(bright * LSB_12) == pytest.approx(sigma, rel=0.05)


def test_averaging_divides_noise_by_root_samples(base):
    sigma, k = 0.02, 16
    sc = scene(base, {"noise": NoiseEffect(sigma_v=sigma), "averaging": {}}, samples=k)
    p = Pipeline.from_scenario(sc)
    assert p.samples == k
    d = spread()
    c = draws(p, truth(d), 12)
    assert np.std((c - ideal_counts(d)) * LSB_12) == pytest.approx(sigma / math.sqrt(k), rel=0.05)
    # hardware time charges the samples taken: 71 steps × 16 × 38.3 ms
    assert hardware_duration_s(S, sc.scan.settle_s, p.samples) == pytest.approx(71 * 16 * 0.0383)
    # samples in the scan block without the averaging effect: one reading per step
    assert Pipeline.from_scenario(scene(base, {"noise": {}}, samples=k)).samples == 1


def test_averaging_of_quantised_samples_stays_integer(base):
    p = Pipeline.from_scenario(scene(base, {"noise": {}, "quantization": {}, "averaging": {}},
                                     samples=8))
    c = p.run(truth(spread()), np.random.default_rng(0))
    assert np.issubdtype(c.dtype, np.integer) and c.shape == (S, N)


# --------------------------------------------------------------------------- beam


class EdgeScene:
    """A fake ray caster: a near face at x = 0.3 for y > 0, a far wall at x = 0.6."""

    def __init__(self):
        self.calls = []

    def __call__(self, origin, direction):
        self.calls.append((origin.shape, direction.shape))
        t_near = (0.3 - origin[..., 0]) / direction[..., 0]
        y_near = origin[..., 1] + t_near * direction[..., 1]
        t_far = (0.6 - origin[..., 0]) / direction[..., 0]
        d = np.where(y_near > 0, t_near, t_far)
        return types.SimpleNamespace(
            distance_m=d, incidence_rad=np.arccos(np.abs(direction[..., 0])),
            hit_point=origin + d[..., None] * direction, geom_id=np.zeros(d.shape, int),
            reflectance=np.ones(d.shape))

    def truth(self, yaw: np.ndarray) -> Truth:
        direction = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=-1)
        origin = np.zeros(yaw.shape + (3,))
        origin[..., 2] = 0.1
        hits = self(origin, direction)
        self.calls.clear()
        return truth(hits.distance_m, incidence=hits.incidence_rad, direction=direction,
                     origin=origin)


def test_beam_mixes_readings_at_an_edge(base):
    cast = EdgeScene()
    beam = BeamEffect(aperture_rad=math.radians(6.0), rays=16, gaussian_width=0.5)
    p = Pipeline.from_scenario(scene(base, {"beam": beam}))
    yaw = np.linspace(math.radians(-6), math.radians(6), S)[:, None].repeat(N, 1)
    t = cast.truth(yaw)
    c = p.run(t, cast=cast)
    assert cast.calls == [((S, N, 16, 3), (S, N, 16, 3))]  # one batched cast
    read = GP2D12.distance(gp2.voltage_from_counts(c))[:, 0]
    single = t.distance_m[:, 0]
    assert np.all((single < 0.302) | (single > 0.598))  # one ray: a hard step
    # away from the edge the cone reads what the axis sees (off-axis rays are a bit longer)
    assert read[0] == pytest.approx(single[0], abs=0.002)
    assert read[-1] == pytest.approx(single[-1], abs=0.001)
    mixed = (read > 0.31) & (read < 0.59)
    assert mixed.sum() >= 3  # edges give readings between the two surfaces
    # and go from far to near in steps smaller than the single ray's jump
    assert np.max(np.abs(np.diff(read))) < 0.5 * np.max(np.abs(np.diff(single)))


def test_the_beam_weights_of_a_narrow_gaussian_are_weights_not_nan(base):
    """aperture 60°, 2 rays, gaussian_width 0.01 (each allowed): every weight underflowed to
    0 and w / w.sum() was NaN, so a run read 'no return' 3408 times of 3408 and mapped the
    room free (F1 0, exit 0, a RuntimeWarning). As σ → 0 the ray nearest the axis takes it
    all; wider cones keep the Gaussian's ratios (to an ulp: the exponent is shifted)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        st = effects.BeamStage(BeamEffect(aperture_rad=math.radians(60), rays=2,
                                          gaussian_width=0.01), effects.Setup(GP2D12))
    assert st.weights.tolist() == [1.0, 0.0]
    assert st.off_axis_rad[0] < st.off_axis_rad[1]
    wide = effects.BeamStage(BeamEffect(aperture_rad=math.radians(8), rays=5,
                                        gaussian_width=0.7), effects.Setup(GP2D12))
    w = np.exp(-0.5 * (wide.off_axis_rad / (0.7 * math.radians(4))) ** 2)
    np.testing.assert_allclose(wide.weights, w / w.sum(), rtol=1e-15, atol=0)


def test_beam_weights_are_gaussian_over_the_aperture(base):
    st = effects.BeamStage(BeamEffect(aperture_rad=math.radians(10), rays=32, gaussian_width=0.5),
                           effects.Setup(GP2D12))
    assert st.weights.sum() == pytest.approx(1.0)
    assert np.all(st.off_axis_rad <= math.radians(5) + 1e-12)
    order = np.argsort(st.off_axis_rad)
    assert np.all(np.diff(st.weights[order]) < 0)  # farther off axis, less weight
    sigma = 0.5 * math.radians(5)
    ratio = st.weights[order[-1]] / st.weights[order[0]]
    expect = math.exp(-0.5 * (st.off_axis_rad[order[-1]] / sigma) ** 2
                      + 0.5 * (st.off_axis_rad[order[0]] / sigma) ** 2)
    assert ratio == pytest.approx(expect)
    dirs = st.directions(np.array([[0.0, 1.0, 0.0]]))
    assert np.allclose(np.linalg.norm(dirs, axis=-1), 1.0)
    assert np.allclose(np.arccos(dirs[0] @ [0.0, 1.0, 0.0]), st.off_axis_rad)


def test_beam_without_a_caster_says_what_to_pass(base):
    p = Pipeline.from_scenario(scene(base, {"beam": {}}))
    with pytest.raises(ValueError, match="pass cast= to Pipeline.run"):
        p.run(truth(spread()))


# --------------------------------------------------------------------------- seeds


def test_same_seed_same_counts_other_seed_other_noise(base):
    all_on = {name: EFFECTS[name]() for name in effects.STAGE_ORDER}
    p = Pipeline.from_scenario(scene(base, all_on, samples=4))
    cast = EdgeScene()
    t = cast.truth(np.linspace(-0.1, 0.1, S)[:, None].repeat(N, 1))
    a = p.run(t, np.random.default_rng(42), cast=cast)
    b = p.run(t, np.random.default_rng(42), cast=cast)
    c = p.run(t, np.random.default_rng(43), cast=cast)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert np.issubdtype(a.dtype, np.integer) and a.shape == (S, N)


# --------------------------------------------------------------------------- benchmark


def test_bench_effects_reports_every_effect(capsys):
    import json

    from irring.cli import main

    status = main(["bench", "effects", "--rounds", "1", "--batch", "1", "--json"])
    r = json.loads(capsys.readouterr().out)
    assert status == (0 if r["off_within_budget"] else 6)   # a missed budget: 6, as in text
    assert [e["effect"] for e in r["effects"]] == list(effects.STAGE_ORDER)
    assert r["sweep_shape"] == [S, N] and r["off_budget_pct"] == 2.0


def test_the_stage_registry_runs_in_the_documented_order():
    # the order readings pass the stages; a new stage must take its place in STAGE_ORDER
    assert tuple(effects.STAGES) == effects.STAGE_ORDER


def test_bench_effects_shows_its_rounds_only_when_a_bar_is_wanted(capsys):
    from irring.scenario import load_scenario
    from irring.studies.effects import measure

    r = measure(load_scenario("t_room"), rounds=2, batch=1, progress=True)
    assert r["rounds"] == 2 and "bench effects:   0%" in capsys.readouterr().err
    measure(load_scenario("t_room"), rounds=2, batch=1, progress=False)
    assert capsys.readouterr().err == ""
