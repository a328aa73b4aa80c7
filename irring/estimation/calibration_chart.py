"""The picture `irring calibrate` writes beside its file: the readings against the distance
to the wall with the fitted curve d = a(θ)·S^b(θ) through them, per incidence angle; how far
the curve reads each reading from where the wall was; the fold-over peak. What it shows:
docs/calibration.md, "The picture".
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .. import gp2
from ..outputs import CHART_FILE, CHART_SOFTWARE, atomic_file
from .calibration import Fitted

SIZE_IN = (11.0, 8.5)   # the figure (inches) …
DPI = 100               # … at this many pixels an inch: a 1100 × 850 PNG
CURVE_THETAS_DEG = (0.0, 15.0, 30.0, 45.0, 60.0, 75.0)   # curves drawn, up to the drop-out
CURVE_POINTS = 200


def chart_data(fitted: Fitted) -> dict:
    """What the picture plots, all from ``fitted`` (mm, counts, degrees): the readings (used
    by the fit or not) at the distance their beam travelled to the wall, the calibration's
    curve at a few incidence angles over its range, each used reading's error (the distance
    the calibration reads from it minus the true one) and the sensor's fold-over peak."""
    cal, r = fitted.calibration, fitted.readings
    ok = np.isfinite(r.counts)
    d_true = r.true_distance(cal.emitter_offset_m)
    theta = np.abs(r.beam_angle_rad)
    used = fitted.used   # a fit uses finite counts only (calibration.fit)
    model = gp2.sensor(cal.sensor_model)
    d = np.linspace(cal.min_range_m, cal.max_range_m, CURVE_POINTS)
    top = math.degrees(cal.max_incidence_rad)
    curves = [(t, d * 1e3, cal.counts(d, math.radians(t))) for t in CURVE_THETAS_DEG
              if t <= top + 1e-9]
    peak = None
    if model.folds:   # the datasheet's peak: the rig reads no wall that near
        peak_v = float(model.peak_v(0.0))
        peak = (model.peak_distance_m * 1e3, peak_v / gp2.lsb_v(cal.adc_bits, cal.vref_v))
    return {
        "distance_mm": d_true[used] * 1e3, "counts": r.counts[used],
        "theta_deg": np.degrees(theta[used]),
        "error_mm": (cal.distance(r.counts[used], theta[used]) - d_true[used]) * 1e3,
        "unused_distance_mm": d_true[ok & ~used] * 1e3, "unused_counts": r.counts[ok & ~used],
        "curves": curves, "peak": peak, "max_theta_deg": top,
        "range_mm": (cal.min_range_m * 1e3, cal.max_range_m * 1e3),
        "volts_per_count": gp2.lsb_v(cal.adc_bits, cal.vref_v),
    }


def save_png(path: str | Path, fitted: Fitted, title: str) -> Path:
    """Draw :func:`chart_data` of ``fitted`` to a PNG of ``SIZE_IN`` × ``DPI`` pixels at
    ``path`` (written whole or not at all)."""
    from matplotlib import colormaps
    from matplotlib.colors import Normalize

    from ..maps.render import figure   # deferred: matplotlib (no pyplot: the backend stays)

    c = chart_data(fitted)
    fig = figure(*SIZE_IN, dpi=DPI)
    fig.set_layout_engine("constrained")   # the colour bar spans both panels
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(2.2, 1.0))
    cmap, norm = colormaps["viridis"], Normalize(0.0, max(c["max_theta_deg"], 1.0))
    lo, hi = c["range_mm"]
    for ax in (top, bottom):
        ax.axvspan(0.0, lo, color="0.9", zorder=0)
        ax.grid(alpha=0.3)
    top.annotate("below the calibrated range", (lo / 2, 0.02), xycoords=("data", "axes fraction"),
                 ha="center", va="bottom", fontsize=8, rotation=90)
    if c["unused_counts"].size:
        top.plot(c["unused_distance_mm"], c["unused_counts"], "x", color="0.6", ms=3,
                 label="reading not fitted (outside the range, no return or at the ADC's end)")
    dots = top.scatter(c["distance_mm"], c["counts"], c=c["theta_deg"], cmap=cmap, norm=norm,
                       s=6, label="reading (average of the sweeps at one step)")
    shown = ", ".join(f"{t:.0f}" for t, _, _ in c["curves"])
    for t, d, n in c["curves"]:   # coloured as the readings at that θ (the colour bar)
        top.plot(d, n, color=cmap(norm(t)), lw=1.8,
                 label=f"fitted curve d = a(θ)·S^b(θ) at θ = {shown}°" if t == 0.0 else None)
    if c["peak"] is not None:
        pd, pn = c["peak"]
        top.axvline(pd, color="#d62728", ls=":", lw=1.2)
        top.plot([pd], [pn], "*", color="#d62728", ms=12,
                 label=f"fold-over peak (datasheet, square on), {pd:.0f} mm: nearer, the reading falls "
                       "again, so one reading means two distances")
    top.set_ylabel("sensor reading (ADC counts)")
    k = c["volts_per_count"]
    volts = top.secondary_yaxis("right", functions=(lambda n: n * k, lambda v: v / k))
    volts.set_ylabel("sensor output (V)")
    top.set_title("Readings against the distance to the wall, coloured by the angle the beam "
                  "meets it (θ)", fontsize=10)
    top.legend(fontsize=8, loc="upper right")
    fig.colorbar(dots, ax=[top, bottom], label="incidence angle θ (degrees)", pad=0.02)

    err = c["error_mm"]
    bottom.axhline(0.0, color="k", lw=0.8)
    bottom.scatter(c["distance_mm"], err, c=c["theta_deg"], cmap=cmap, norm=norm, s=6)
    rms = float(np.sqrt(np.mean(err ** 2))) if err.size else math.nan
    bottom.set_title(f"How far the fitted curve reads each reading from the wall: RMS "
                     f"{rms:.1f} mm over {err.size} readings (the sensor's noise included)",
                     fontsize=10)
    bottom.set_ylabel("distance error (mm)")
    bottom.set_xlabel("distance from the sensor to the wall along the beam (mm)")
    bottom.set_xlim(0.0, hi * 1.08)
    fig.suptitle(title, fontsize=11)
    with atomic_file(path, writes=CHART_FILE) as tmp:
        fig.savefig(tmp, dpi=DPI, format="png", metadata={"Software": CHART_SOFTWARE})
    return Path(path)
