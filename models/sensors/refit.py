"""Regenerate the sensor curve files in this folder from their source points.

Run from the repository root, with irring installed (pip install -e .):
    python models/sensors/refit.py
It fits d = a·V^b (paper Eq. 10) to each part's datasheet points by least squares on
log d = log a + b·log V (``irring.estimation.calibration.fit_curve``, the fit
``irring calibrate`` makes), then tabulates a(θ), b(θ) with the incidence model stated in
README.md, and rewrites <name>.yaml. irring itself only reads the YAML files; the test
tests/test_gp2.py checks that they still match their points.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from irring.estimation.calibration import fit_curve

HERE = Path(__file__).resolve().parent
THETA_DEG = list(range(0, 90, 5))  # 0 … 85°; beyond the last entry a, b are held constant

# Incidence model (README.md): a(θ) = a0·cos(θ)^A_EXP, b(θ) = b0·(1 + B_SLOPE·(1 − cos θ)).
# Chosen so that a θ = 50° return at 0.60 m read with the θ = 0 curve is ~11 cm long
# (paper Fig. 8: several cm, up to ~8–16 cm).
A_EXP = 0.30
B_SLOPE = -0.10

# The GP2D12 datasheet points (distance m → output V). The GP2Y0A21 is the same 10–80 cm
# class: its fixed fit is checked against these same points.
GP2D12_POINTS = dict(
    distance_m=[0.10, 0.12, 0.14, 0.16, 0.18, 0.20, 0.30, 0.35, 0.40, 0.45, 0.50, 0.60, 0.70,
                0.75, 0.80],
    voltage_v=[2.450, 2.125, 1.860, 1.660, 1.520, 1.380, 0.975, 0.850, 0.760, 0.680, 0.620,
               0.540, 0.480, 0.450, 0.420],
)

SPECS = {
    "gp2d12": dict(
        part="Sharp GP2D12",
        source="datasheet-derived points listed in docs/paper.md (mV → cm)",
        min_range_m=0.10, max_range_m=0.80, peak_distance_m=0.09, max_incidence_deg=70.0,
        **GP2D12_POINTS,
        notes="Peak (fold-over) at 9 cm: the datasheet curve tops out near 2.6–2.7 V at 8–9 cm; "
              "the fitted branch gives 2.71 V there.",
    ),
    "gp2y0a21": dict(
        part="Sharp GP2Y0A21YK(0F)",
        source="public power fit d[cm] = 27.728·V^-1.2045 (same 10–80 cm class as the GP2D12); "
               "residuals against the GP2D12 datasheet points",
        min_range_m=0.10, max_range_m=0.80, peak_distance_m=0.07, max_incidence_deg=70.0,
        fixed_fit=(0.27728, -1.2045),
        **GP2D12_POINTS,
        notes="Peak at 7 cm (datasheet: ~3.1 V at 6–7 cm; the fit gives 3.13 V at 7 cm).",
    ),
    "gp2y0a02": dict(
        part="Sharp GP2Y0A02YK0F",
        source="points from public simulator data listed in docs/paper.md (m → V); the 0.15 m point "
               "sits on the rounded peak and is kept out of the fit",
        min_range_m=0.20, max_range_m=1.50, peak_distance_m=0.15, max_incidence_deg=70.0,
        distance_m=[0.20, 0.30, 0.40, 0.50, 0.60, 0.80, 1.00, 1.20, 1.50],
        voltage_v=[2.51, 1.99, 1.52, 1.25, 1.04, 0.79, 0.69, 0.55, 0.45],
        notes="Peak at 15 cm (datasheet and the 2.75 V point at 0.15 m). The power-law branch "
              "overshoots there (3.5 V); readings that close are outside the part's range.",
    ),
    "sonar": dict(
        part="MaxBotix LV-MaxSonar-EZ class ultrasonic ranger (analog output)",
        source="datasheet scale factor Vcc/512 per inch: at 5 V, 9.766 mV/in, so "
               "d = 2.6010 m/V · V (b = +1, linear)",
        min_range_m=0.1524, max_range_m=6.45, peak_distance_m=0.0, max_incidence_deg=20.0,
        fixed_fit=(0.0254 * 512 / 5.0, 1.0), flat_incidence=True,
        notes="Hook for the `sonar12` design: linear output, no fold-over; smooth walls reflect "
              "specularly, so returns drop out past ~20° incidence (a(θ), b(θ) flat).",
    ),
    "laser": dict(
        part="SICK LMS200-like laser scanner, expressed as a linear analog output",
        source="design assumption: the scanner reports distance digitally; we write it as "
               "d = 2.0 m/V · V over 0–8 m (4 V at 8 m) so the same pipeline applies; use "
               "adc_bits 16 for ~0.12 mm steps",
        min_range_m=0.05, max_range_m=8.0, peak_distance_m=0.0, max_incidence_deg=85.0,
        fixed_fit=(2.0, 1.0), flat_incidence=True,
        notes="Hook for the `laser` design: linear, no fold-over, range independent of "
              "incidence until grazing (85°).",
    ),
}


def fit_power_law(distance_m, voltage_v) -> tuple[float, float]:
    """Least-squares a, b of d = a·V^b in log-log space (d in metres, V in volts): the
    calibration's Eq. 10 fit at θ = 0 alone, with volts for counts."""
    v = np.asarray(voltage_v, dtype=float)
    _, a, b = fit_curve(v, distance_m, np.zeros_like(v), [0.0])
    return float(a[0]), float(b[0])


def tables(a0: float, b0: float, flat: bool) -> tuple[list[float], list[float]]:
    c = np.cos(np.radians(THETA_DEG))
    if flat:
        return [a0] * len(c), [b0] * len(c)
    return list(a0 * c ** A_EXP), list(b0 * (1.0 + B_SLOPE * (1.0 - c)))


def _flow(values, fmt="{:.10g}") -> str:
    return "[" + ", ".join(fmt.format(v) for v in values) + "]"


def render(name: str, spec: dict) -> str:
    if "fixed_fit" in spec:
        a0, b0 = spec["fixed_fit"]
        how = "fixed (from the source above, not refitted)"
    else:
        a0, b0 = fit_power_law(spec["distance_m"], spec["voltage_v"])
        how = "least squares on log d = log a + b·log V"
    flat = spec.get("flat_incidence", False)
    ta, tb = tables(a0, b0, flat)
    lines = [
        f"# {spec['part']}: voltage curve for irring (generated by refit.py; see README.md).",
        f"# Source: {spec['source']}.",
        f"# {spec['notes']}",
        f"name: {name}",
        f"part: {spec['part']}",
        f"min_range_m: {spec['min_range_m']}",
        f"max_range_m: {spec['max_range_m']}",
        f"peak_distance_m: {spec['peak_distance_m']}",
        f"max_incidence_deg: {spec['max_incidence_deg']}",
    ]
    if "distance_m" in spec:
        d = np.asarray(spec["distance_m"])
        v = np.asarray(spec["voltage_v"])
        res = d - a0 * v ** b0
        lines += [
            "points:  # source data, distance (m) → output (V)",
            f"  distance_m: {_flow(d, '{:.4g}')}",
            f"  voltage_v: {_flow(v, '{:.4g}')}",
            f"fit:  # theta = 0: d[m] = a·V^b; {how}",
            f"  a: {a0:.10g}",
            f"  b: {b0:.10g}",
            f"  residual_m: {_flow(res, '{:+.4f}')}  # point − fit",
            f"  rms_residual_m: {float(np.sqrt(np.mean(res ** 2))):.4f}",
            f"  max_abs_residual_m: {float(np.max(np.abs(res))):.4f}",
        ]
    else:
        lines += [f"fit:  # d[m] = a·V^b; {how}", f"  a: {a0:.10g}", f"  b: {b0:.10g}"]
    model = ("flat: a, b do not depend on θ" if flat else
             f"a(θ) = a0·cos(θ)^{A_EXP}, b(θ) = b0·(1 {'+' if B_SLOPE >= 0 else '−'} "
             f"{abs(B_SLOPE)}·(1 − cos θ))")
    lines += [
        f"table:  # incidence θ (deg) → a (m·V^-b), b; {model}; linear in between, held past the end",
        f"  theta_deg: {_flow(THETA_DEG, '{:g}')}",
        f"  a: {_flow(ta)}",
        f"  b: {_flow(tb)}",
        "",
    ]
    return "\n".join(lines)


def main() -> None:
    for name, spec in SPECS.items():
        (HERE / f"{name}.yaml").write_text(render(name, spec))
        print(f"wrote {name}.yaml")


if __name__ == "__main__":
    main()
