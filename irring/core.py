"""The types every stage shares and the paper's constants, in numpy alone.

A source makes a :class:`Sweep` (arrays shaped ``(steps, sensors)``, SI units), the
estimator turns it into :class:`Points`, the mapper reads those; :class:`Ring`,
:class:`SensorSpec`, :class:`Room`, :class:`Cylinder`, :class:`Box` and :class:`Pose`
describe the ring and the scene. Imports numpy and no other irring module
(tests/test_imports.py); the numbers are the paper's (docs/paper.md).
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import math
import sys
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

# --------------------------------------------------------------------------- paper constants

MAX_RANGE_M = 0.624     # GP2D12 range the paper's experiments trust (Table I's D is 0.686 m)
DESIGN_RANGE_M = 0.686  # D of Eqs. 2-3 in Table I
ADC_BITS = 12           # MCP3202
VREF_V = 5.0
SENSOR_MODEL = "gp2d12"  # the paper's sensor, Sharp GP2D12 (models/sensors/gp2d12.yaml)
SEED_MAX = 2**63 - 1  # the largest seed a scenario or an option takes (numpy takes any int ≥ 0)
GP2_PERIOD_S = 0.0383   # GP2 measurement period (datasheet 38.3 ms ± 9.6 ms); one sample, one period
MIN_READING_PERIOD_S = 0.001  # no sensor a scenario or device may have reads faster

# --------------------------------------------------------------------------- work limits
# What one simulated run may ask for, checked before the work starts (irring.simulation.sim
# raises TooBig above them); a recording holds no more sweeps or steps than this either.
MAX_SWEEPS = 10_000
MAX_STEPS = 100_000                 # readings per sensor in one sweep
MAX_ADC_BITS = 24                   # a converter's bits a device, recording or calibration
                                    # file may state (a scenario's are fewer: Sensor.adc_bits)
MAX_SAMPLES = 64                    # readings a device averages per step (IRSCN, a recording)
NETWORK_URL_SCHEMES = ("socket", "rfc2217")  # pyserial URLs of a ring reached at HOST:PORT
VREF_RANGE_V = (0.1, 50.0)          # its reference voltage there (V; a scenario's: Sensor.vref_v)
MAX_DURATION_S = 1e7                # hardware time of one sweep (115 days; a recording's bound)
WORK_MEMORY_BYTES = 2 * 10**9       # what one command's work may hold: a run's readings and
                                    # belt physics together, a study's results read back
BYTES_PER_READING = 600             # a reading through simulation, estimate and map (measured,
                                    # few beams returning: 72 sensors × 20 001 steps peaked 0.94 GB)
ESTIMATE_BYTES_PER_READING = 2_700  # more for each reading of the sweep being estimated: the
# estimator's peak grows with the sweep's readings alone (measured: docs/speed.md, "Long sweeps")
MAX_ESTIMATED_READINGS = WORK_MEMORY_BYTES // (BYTES_PER_READING + ESTIMATE_BYTES_PER_READING)
#                                   one sweep's readings the estimator takes
BYTES_PER_PHYSICS_VALUE = 16        # a recorded qpos/qvel double, held twice while assembled
VIEW_BYTES_PER_PIXEL = 85           # an offscreen picture of `irring view`, beyond VIEW_BASE_BYTES
VIEW_BASE_BYTES = 300 * 10**6       # (peak RSS, 1280x960 to 4096x3072: OSMesa 83, EGL 63 bytes
                                    # a pixel over 0.25-0.3 GB; 4096x3072 1.28 and 1.03 GB)
RESULT_ROW_BYTES = 3_800            # a study's results.csv row read back to summarise
                                    # (measured: 100 000 rows, 377 MB)
RESULT_ROW_TEXT_BYTES = 500         # the line of such a row (a study writes 340-480 bytes); a
                                    # longer line's excess is held as well
MAX_RUNS = WORK_MEMORY_BYTES // RESULT_ROW_BYTES   # runs of one study (526,315)
MAX_SEEDS = 100_000                 # seeds of one configuration a study, compare or bench runs
# |value| of a position or size (m) in a scene or recording: 1e300 m is finite, but squaring
# it overflows and no map can place it
MAX_ABS_COORDINATE_M = 1e6
MAX_OUTLINE_CORNERS = 10_000        # corners of a room outline (checking that its walls never
                                    # cross takes ~1 s at this many; 100 000 took hours)
MAX_OBSTACLES = 10_000              # obstacles of a scene: each is checked against every pose
                                    # (a bool each) and rasterised for the score (20 000 took
                                    # 3 min to score; a file may list 245 000: 2.4 GB of checks)



def work_bytes(readings: int, largest_sweep: int) -> int:
    """Memory (bytes) estimating and mapping ``readings`` takes at most, ``largest_sweep`` of
    them in one sweep (estimated one sweep at a time); held within :data:`WORK_MEMORY_BYTES`."""
    return int(readings) * BYTES_PER_READING + int(largest_sweep) * ESTIMATE_BYTES_PER_READING


def gigabytes(n_bytes: float) -> str:
    """``n_bytes`` in GB as a refusal shows it: one decimal, three significant figures past
    a million GB (a 10³⁰-cell grid read "about 600000000000000016777216.0 GB")."""
    try:
        gb = n_bytes / 1e9
    except OverflowError:   # an int past a float's range (a drive at 1e-300 mm/s)
        return f"{count_text(int(n_bytes) // 10**9)} GB"
    return f"{gb:.1f} GB" if gb < 1e6 else f"{gb:.3g} GB"


def count_text(n: int) -> str:
    """Whole number ``n`` with thousands separators, past 10¹⁵ to three figures ("4.22e+300"):
    a drive at 1e-300 mm/s counted its sweeps in 400 characters."""
    if n < 10**15:
        return f"{n:,}"
    digits = len(str(n))
    return f"{n // 10 ** (digits - 3) / 100:.2f}e+{digits - 1}"


def work_refusal(work: str, need: int, who: str, advice: str) -> str | None:
    """None when ``need`` bytes fit :data:`WORK_MEMORY_BYTES`, else the one wording every
    refusal of too much work uses (raised as :class:`irring.errors.TooBig`, exit 5):
    '{work} (about N GB), more than the 2 GB {who} may use: {advice}'."""
    if need <= WORK_MEMORY_BYTES:
        return None
    return (f"{work} (about {gigabytes(need)}), more than the {WORK_MEMORY_BYTES / 1e9:g} GB "
            f"{who} may use: {advice}")


# --------------------------------------------------------------------------- field bounds
# A field's metadata holds its inclusive SI bounds or allowed choices; the scenario loader
# checks YAML against them and designs check rings made in code.


def num(default: Any = dataclasses.MISSING, lo: float | None = None, hi: float | None = None,
        doc: str = "") -> Any:
    """A numeric dataclass field with inclusive SI bounds."""
    return field(default=default, metadata={"lo": lo, "hi": hi, "choices": None, "doc": doc})


def choice(default: Any, choices: tuple, doc: str = "") -> Any:
    """A dataclass field that takes one of ``choices``."""
    return field(default=default, metadata={"lo": None, "hi": None, "choices": choices,
                                            "doc": doc})


# The one table of units in field names, longest suffix first: the SI suffix and its unit,
# and the other spelling a file may use (None: none), its unit and its factor to SI.
UNITS = (("_m_s", "m/s", "_mm_s", "mm/s", 1e-3),
         ("_per_m", "per m", None, None, None),
         ("_m", "m", "_mm", "mm", 1e-3),
         ("_rad", "rad", "_deg", "°", math.pi / 180.0),
         ("_s", "s", "_ms", "ms", 1e-3))
_SHOWN_SCALED = ("_m", "_rad", "_s")   # SI values a message shows in the file's unit


def _display(suf: str) -> tuple[float, str]:
    """(factor from SI, unit) of the file spelling of SI suffix ``suf``."""
    _, _, _, unit, to_si = next(row for row in UNITS if row[0] == suf)
    return 1.0 / to_si, unit


def unit_suffix(name: str) -> str | None:
    """The SI suffix of a field name (``_m``, ``_rad``, ``_s``, ``_m_s``, ``_per_m``)."""
    return next((si for si, *_ in UNITS if name.endswith(si)), None)


def si_name(yaml_name: str) -> str:
    """The SI field name of a YAML spelling (``radius_mm`` → ``radius_m``)."""
    for si, _, alt, _, _ in UNITS:
        if alt is not None and yaml_name.endswith(alt):
            return yaml_name[: -len(alt)] + si
    return yaml_name


def bounds(cls: type, name: str) -> tuple[Any, Any]:
    """The inclusive (lo, hi) SI bounds of field ``name`` of dataclass ``cls`` (None: open)."""
    meta = next(f for f in dataclasses.fields(cls) if f.name == name).metadata
    return meta.get("lo"), meta.get("hi")


def _fmt_range(name: str, lo: float | None, hi: float | None) -> str:
    suf = unit_suffix(name)
    scale, unit = 1.0, ""
    if suf in _SHOWN_SCALED:
        scale, unit = _display(suf)
    # a whole-number bound exactly: %g wrote the seed's 2⁶³ − 1 as 9.22337e+18
    parts = ["" if v is None else str(v) if isinstance(v, int) and scale == 1.0 else
             f"{v * scale:g}" for v in (lo, hi)]
    if lo is not None and hi is not None:
        return f"{parts[0]} … {parts[1]}{(' ' + unit) if unit else ''}"
    if lo is not None:
        return f"≥ {parts[0]}{unit}"
    return f"≤ {parts[1]}{unit}"


def _show(value: Any, si: str) -> str:
    suf = unit_suffix(si)
    if suf in _SHOWN_SCALED and isinstance(value, float):
        scale, unit = _display(suf)
        return f"{value * scale:g} {unit}"
    text = repr(value)   # bounded: the message must still say what is allowed
    return text if len(text) <= 60 else text[:59] + "…"


def key_unit(path: str) -> str | None:
    """The unit the last key of ``path`` names (``obstacles[0].radius_mm`` → "mm"), if any."""
    key = path.rsplit(".", 1)[-1].split("[", 1)[0]
    # a row's other spelling first: "_mm_s" also ends in "_s", "_ms" in "_s"
    spellings = ((suf, u) for si, si_unit, alt, alt_unit, _ in UNITS
                 for suf, u in ((alt, alt_unit), (si, si_unit)) if suf is not None)
    return next((u for suf, u in spellings if key.endswith(suf)), None)


def _number(x: float) -> str:
    """``x`` as %g, a subnormal as its shortest repr (%g shows 5e-324 as 4.94066e-324)."""
    return repr(float(x)) if 0 < abs(x) < sys.float_info.min else f"{x:g}"


def bounds_error(value: Any, meta: Any, path: str, written: float | None = None,
                 factor: float = 1.0) -> str | None:
    """Why ``value`` breaks the field metadata ``meta`` (None if it does not); ``path`` names
    the field (its last part, in YAML or SI spelling, sets the display unit). ``written``:
    the number as the file gave it, ``factor`` times it being ``value``; shown with the
    range in the unit its key names (5e-324 mm became 0 m and read "0 mm")."""
    choices = meta.get("choices")
    if choices is not None and value not in choices:
        allowed = ", ".join(str(c) for c in choices)
        return f"{value!r} is not allowed; choose one of: {allowed}"
    lo, hi = meta.get("lo"), meta.get("hi")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        unit = key_unit(path)
        if written is not None and unit is not None:
            lo_hi = [None if v is None else _number(v / factor) for v in (lo, hi)]
            span = (f"{lo_hi[0]} … {lo_hi[1]}" if None not in lo_hi else
                    f"≥ {lo_hi[0]}" if lo_hi[0] is not None else f"≤ {lo_hi[1]}")
            return f"{_number(written)} {unit} is out of range; allowed {span} {unit}"
        si = si_name(path.rsplit(".", 1)[-1].split("[", 1)[0])
        return f"{_show(value, si)} is out of range; allowed {_fmt_range(si, lo, hi)}"
    return None


# --------------------------------------------------------------------------- ring, sensor, scene


@dataclass(frozen=True)
class Ring:
    """A ring design: the paper's by default (12 sensors, R = 0.15 m, ±35 motor steps of
    1.8° through a 0.6 belt, d_o = 7 mm); other designs change these numbers."""

    sensors: int = num(12, lo=1, hi=72, doc="sensors on the ring")
    radius_m: float = num(0.15, lo=0.0, hi=1.0, doc="ring radius to the sensor hinge axes")
    motor_step_rad: float = num(math.radians(1.8), lo=math.radians(0.01), hi=math.radians(45.0))
    gear: float = num(0.6, lo=0.01, hi=10.0, doc="sensor turn per motor turn (belt ratio)")
    min_step: int = num(-35, lo=-100000, hi=100000)
    max_step: int = num(35, lo=-100000, hi=100000)
    emitter_offset_m: float = num(0.007, lo=0.0, hi=0.05,
                                  doc="lateral emitter offset d_o from the hinge axis")
    sensor_height_m: float = num(0.10, lo=0.01, hi=2.0)
    joint_limit_rad: float = num(math.radians(37.8), lo=0.0, hi=2 * math.pi,
                                 doc="each sensor hinge's range ±limit")


HOUSING_M = 0.02  # the sensors' housing reaches this far beyond the ring radius
# a point whose σ exceeds this is placed no better than uncertain: the mapper weighs it
# down by default (MapperParams.lone_sigma_m) and a fold-over sweep leaves it unplaced
UNCERTAIN_SIGMA_M = 0.03
# Geometry given in mm becomes metres by a float product (0.89 − 0.7 − 0.02 ≠ 0.17): checks
# of "at least this far" allow this much so a surface exactly at the limit passes.
GEOMETRY_TOL_M = 1e-9


@dataclass(frozen=True)
class SensorSpec:
    """What a sensor kind implies for a design. Lengths m, angles rad, times s.

    ``max_range_m``: readings beyond are no return. ``design_range_m``: D of Eqs. 2–3.
    ``noise_sigma_m``: 1-σ range noise the sensor implies, or None when the scene's own
    effects (volts, for GP2 curves) govern. ``beam_half_angle_rad``: cone half-angle (0: a
    pencil beam). ``reading_period_s``: time one reading costs. ``sequential``: sensors fire
    one after another (sonar crosstalk) instead of all at once. ``settles``: waits
    ``scan.settle_s`` per position (a laser's mirror never stops).
    """

    kind: str
    max_range_m: float
    design_range_m: float
    noise_sigma_m: float | None = None
    beam_half_angle_rad: float = 0.0
    reading_period_s: float = GP2_PERIOD_S
    sequential: bool = False
    adc_bits: int = ADC_BITS
    settles: bool = True
    description: str = ""

    @property
    def is_ir(self) -> bool:
        return self.kind.startswith("gp2")


@dataclass(frozen=True)
class Pose:
    x_m: float
    y_m: float
    yaw_rad: float = num(0.0, lo=-2 * math.pi, hi=2 * math.pi)


@dataclass(frozen=True)
class Cylinder:
    center_m: tuple[float, float]
    radius_m: float = num(lo=0.002, hi=2.0, doc="cylinder radius")
    reflectance: float = num(1.0, lo=0.05, hi=1.0, doc="relative IR reflectivity (white paper = 1)")


@dataclass(frozen=True)
class Box:
    center_m: tuple[float, float]
    size_m: tuple[float, float]
    yaw_rad: float = num(0.0, lo=-2 * math.pi, hi=2 * math.pi)
    reflectance: float = num(1.0, lo=0.05, hi=1.0)


@dataclass(frozen=True)
class Room:
    outline_m: tuple[tuple[float, float], ...]
    wall_height_m: float = num(0.30, lo=0.05, hi=3.0)
    wall_thickness_m: float = num(0.02, lo=0.002, hi=0.5)
    reflectance: float = num(1.0, lo=0.05, hi=1.0, doc="reflectivity of every wall")


# --------------------------------------------------------------------------- room geometry
# Vectorised over points: px, py broadcast together; an outline is the room's corners in order.


def segment_distance(px, py, ax, ay, bx, by) -> np.ndarray:
    """Distance (m) from points to the segment a–b."""
    dx, dy = bx - ax, by - ay
    t = np.clip(((px - ax) * dx + (py - ay) * dy) / (dx * dx + dy * dy), 0.0, 1.0)
    return np.hypot(px - (ax + t * dx), py - (ay + t * dy))


def inside_outline(px, py, outline) -> np.ndarray:
    """Points inside a closed outline (even-odd rule, one pass per edge)."""
    n = len(outline)
    if n > _FEW_WALLS:
        return _inside_many(px, py, outline)
    inside = np.zeros(np.broadcast(px, py).shape, bool)
    for i in range(n):
        (x1, y1), (x2, y2) = outline[i], outline[(i + 1) % n]
        if y1 == y2:
            continue
        crosses = (y1 > py) != (y2 > py)
        x_at = x1 + (py - y1) * (x2 - x1) / (y2 - y1)
        inside ^= crosses & (px < x_at)
    return inside


_FEW_WALLS = 32   # beyond this, each wall is asked only of the points level with it


def _inside_many(px, py, outline) -> np.ndarray:
    """inside_outline for an outline of many walls: each edge flips only the points whose y
    lies in [its lower y, its upper y), found in the points sorted by y (the same test)."""
    px, py = np.broadcast_arrays(np.asarray(px, dtype=float), np.asarray(py, dtype=float))
    x, y = px.ravel(), py.ravel()
    order = np.argsort(y, kind="stable")
    sorted_y = y[order]
    inside = np.zeros(x.shape, bool)
    n = len(outline)
    for i in range(n):
        (x1, y1), (x2, y2) = outline[i], outline[(i + 1) % n]
        if y1 == y2:
            continue
        idx = order[np.searchsorted(sorted_y, min(y1, y2), side="left"):
                    np.searchsorted(sorted_y, max(y1, y2), side="left")]
        x_at = x1 + (y[idx] - y1) * (x2 - x1) / (y2 - y1)
        inside[idx] ^= x[idx] < x_at
    return inside.reshape(px.shape)


def distance_to_outline(px, py, outline, within: float | None = None) -> np.ndarray:
    """Distance (m) from points to the nearest wall of a closed outline. ``within``: only
    distances up to it are wanted; the others are +inf, and each wall is measured only from
    the points in its box grown by ``within`` (an outline of thousands of walls on a grid)."""
    if within is not None:
        return _distance_within(px, py, outline, within)
    n = len(outline)
    nearest = segment_distance(px, py, *outline[-1], *outline[0])
    for i in range(n - 1):   # a running minimum: memory of one wall's distances, not n
        nearest = np.minimum(nearest, segment_distance(px, py, *outline[i], *outline[i + 1]))
    return nearest


def _distance_within(px, py, outline, within: float) -> np.ndarray:
    """distance_to_outline's values up to ``within`` (the same floats), +inf beyond."""
    px, py = np.broadcast_arrays(np.asarray(px, dtype=float), np.asarray(py, dtype=float))
    x, y = px.ravel(), py.ravel()
    order = np.argsort(x, kind="stable")
    sorted_x = x[order]
    nearest = np.full(x.shape, np.inf)
    n = len(outline)
    for i in range(n):
        (ax, ay), (bx, by) = outline[i - 1], outline[i]   # distance_to_outline's order
        lo = np.searchsorted(sorted_x, min(ax, bx) - within, side="left")
        hi = np.searchsorted(sorted_x, max(ax, bx) + within, side="right")
        idx = order[lo:hi]
        idx = idx[(y[idx] >= min(ay, by) - within) & (y[idx] <= max(ay, by) + within)]
        if idx.size:
            nearest[idx] = np.minimum(nearest[idx],
                                      segment_distance(x[idx], y[idx], ax, ay, bx, by))
    nearest[nearest > within] = np.inf
    return nearest.reshape(px.shape)


_CROSS_PAIRS = 4_000_000   # wall pairs :func:`first_crossing` holds at once (~100 MB)
OVERLAP_MIN_M = 1e-6   # walls sharing a stretch longer than this retrace each other (1 µm)


def _orient(u, v, w):   # > 0: w left of u→v (rows of points)
    return (v[:, 0] - u[:, 0]) * (w[:, 1] - u[:, 1]) - (v[:, 1] - u[:, 1]) * (w[:, 0] - u[:, 0])


def _meeting_walls(outline, *, neighbours: bool):
    """Blocks (starts, ends, i, j) of the wall pairs i < j, row-major, of a closed outline
    whose bounding boxes meet; ``neighbours``: also the walls that share a corner."""
    a = np.asarray(outline, dtype=float).reshape(-1, 2)
    n = len(a)
    b = np.roll(a, -1, axis=0)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    rows = max(1, _CROSS_PAIRS // max(n, 1))
    gap = 1 if neighbours else 2
    for i0 in range(0, n, rows):
        i = np.arange(i0, min(n, i0 + rows))[:, None]
        j = np.arange(n)[None, :]
        meet = ((lo[i, 0] <= hi[j, 0]) & (lo[j, 0] <= hi[i, 0]) & (lo[i, 1] <= hi[j, 1])
                & (lo[j, 1] <= hi[i, 1]) & (j >= i + gap))
        if not neighbours:
            meet &= ~((i == 0) & (j == n - 1))
        ii, jj = np.nonzero(meet)
        yield a, b, ii + i0, jj


def first_crossing(outline) -> tuple[int, int] | None:
    """The first pair of walls (i, j), i < j in row order, of a closed outline that cross
    properly (touching does not count), or None. Only pairs whose bounding boxes meet are
    judged, a block of walls against all at a time (numpy)."""
    for a, b, ii, jj in _meeting_walls(outline, neighbours=False):
        p, q, r, t = a[ii], b[ii], a[jj], b[jj]
        cross = ((_orient(r, t, p) * _orient(r, t, q) < 0)
                 & (_orient(p, q, r) * _orient(p, q, t) < 0))
        if cross.any():
            k = int(np.argmax(cross))
            return int(ii[k]), int(jj[k])
    return None


def first_overlap(outline) -> tuple[int, int, float] | None:
    """The first pair of walls (i, j), i < j in row order, of a closed outline that run along
    one line over a common stretch longer than :data:`OVERLAP_MIN_M` (a wall doubling back
    over its neighbour, or over any other wall), and that stretch's length (m); or None.
    Walls that only touch, or meet end to end along one line, do not overlap."""
    for a, b, ii, jj in _meeting_walls(outline, neighbours=True):
        p, q, r, t = a[ii], b[ii], a[jj], b[jj]
        length = np.hypot(*(q - p).T)
        on_line = ((np.abs(_orient(p, q, r)) <= GEOMETRY_TOL_M * length)
                   & (np.abs(_orient(p, q, t)) <= GEOMETRY_TOL_M * length))
        along_r = np.einsum("ij,ij->i", r - p, q - p) / length   # r, t measured along p→q
        along_t = np.einsum("ij,ij->i", t - p, q - p) / length
        shared = (np.minimum(length, np.maximum(along_r, along_t))
                  - np.maximum(0.0, np.minimum(along_r, along_t)))
        overlap = on_line & (shared > OVERLAP_MIN_M)
        if overlap.any():
            k = int(np.argmax(overlap))
            return int(ii[k]), int(jj[k]), float(shared[k])
    return None


def wall_extents(outline, thickness_m: float):
    """How the simulator builds each wall (simulation.model.wall_boxes): a box of
    ``thickness_m`` outward of the wall, lengthened by the thickness at each convex corner
    (closing the outside corner) and not at a reflex one. Rows per wall: (u, outward, ext_a,
    ext_b, length), u the unit vector from its corner to the next."""
    pts = np.asarray(outline, dtype=float).reshape(-1, 2)
    prev, b, nxt = np.roll(pts, 1, axis=0), np.roll(pts, -1, axis=0), np.roll(pts, -2, axis=0)
    ccw = float(np.sum(pts[:, 0] * b[:, 1] - b[:, 0] * pts[:, 1])) > 0
    d = b - pts
    length = np.hypot(d[:, 0], d[:, 1])
    u = d / length[:, None]
    outward = np.stack([u[:, 1], -u[:, 0]] if ccw else [-u[:, 1], u[:, 0]], axis=1)

    def convex(p, q, r):   # the corner at q turns toward the room
        cross = ((q[:, 0] - p[:, 0]) * (r[:, 1] - q[:, 1])
                 - (q[:, 1] - p[:, 1]) * (r[:, 0] - q[:, 0]))
        return (cross > 0) == ccw

    ext_a = np.where(convex(prev, pts, b), thickness_m, 0.0)
    ext_b = np.where(convex(pts, b, nxt), thickness_m, 0.0)
    return u, outward, ext_a, ext_b, length


def first_wall_intrusion(outline, thickness_m: float,
                         slack_m: float = OVERLAP_MIN_M) -> tuple[int, int] | None:
    """The first wall i (row order) whose box (:func:`wall_extents`) another wall j of the
    outline, not its neighbour, enters by more than ``slack_m`` short of its outer face,
    (i, j); or None.
    Wall j there has room on its far side: the simulated wall would stand in the room (two
    walls closer than the thickness outside the outline, a partition thinner than it)."""
    a = np.asarray(outline, dtype=float).reshape(-1, 2)
    n = len(a)
    b = np.roll(a, -1, axis=0)
    u, out, ext_a, ext_b, length = wall_extents(a, thickness_m)
    start = a - u * ext_a[:, None]
    span = length + ext_a + ext_b
    corners = np.stack([start, start + u * span[:, None], start + out * thickness_m,
                        start + u * span[:, None] + out * thickness_m])
    box_lo, box_hi = corners.min(axis=0), corners.max(axis=0)
    seg_lo, seg_hi = np.minimum(a, b), np.maximum(a, b)
    m = slack_m
    rows = max(1, _CROSS_PAIRS // max(n, 1))
    for i0 in range(0, n, rows):
        i = np.arange(i0, min(n, i0 + rows))[:, None]
        j = np.arange(n)[None, :]
        # not a wall's neighbours: at a sharp reflex corner (a V notch) the two boxes poke
        # past each other by a few mm near the corner, whatever their thickness
        apart = (j != i) & (j != (i + 1) % n) & (j != (i - 1) % n)
        meet = ((box_lo[i, 0] <= seg_hi[j, 0]) & (seg_lo[j, 0] <= box_hi[i, 0])
                & (box_lo[i, 1] <= seg_hi[j, 1]) & (seg_lo[j, 1] <= box_hi[i, 1]) & apart)
        ii, jj = np.nonzero(meet)
        ii = ii + i0
        # wall j in box i's frame: s along the box from its start, w outward from the wall
        p, q = a[jj] - start[ii], b[jj] - start[ii]
        s0, s1 = np.einsum("ij,ij->i", p, u[ii]), np.einsum("ij,ij->i", q, u[ii])
        w0, w1 = np.einsum("ij,ij->i", p, out[ii]), np.einsum("ij,ij->i", q, out[ii])
        enter, leave = np.zeros(len(ii)), np.ones(len(ii))
        for v0, v1, lo, hi in ((s0, s1, m, span[ii] - m),
                               (w0, w1, OVERLAP_MIN_M, thickness_m - m)):
            dv = v1 - v0
            with np.errstate(divide="ignore", invalid="ignore"):
                t_lo, t_hi = (lo - v0) / dv, (hi - v0) / dv
            moving = dv != 0
            enter = np.where(moving, np.maximum(enter, np.minimum(t_lo, t_hi)), enter)
            leave = np.where(moving, np.minimum(leave, np.maximum(t_lo, t_hi)), leave)
            still_out = ~moving & ((v0 <= lo) | (v0 >= hi))
            leave = np.where(still_out, -1.0, leave)
        hit = enter < leave
        if hit.any():
            k = int(np.argmax(hit))
            return int(ii[k]), int(jj[k])
    return None


def built_wall_thickness(outline, thickness_m: float) -> float:
    """How thick the simulator builds a room's walls: ``thickness_m``, or where two walls lie
    closer than that outside the outline (a partition drawn into it) the most that keeps every
    wall's box out of the room (within OVERLAP_MIN_M), so the partition is as thick as drawn.
    A sensor inside the room sees only the walls' inner faces, wherever they stand."""
    return _built_wall_thickness(tuple(tuple(map(float, p)) for p in outline), float(thickness_m))


@functools.lru_cache(maxsize=32)
def _built_wall_thickness(outline: tuple, thickness_m: float) -> float:
    if first_wall_intrusion(outline, thickness_m) is None:
        return thickness_m
    lo, hi = 0.0, thickness_m
    for _ in range(40):   # to ~1e-14 m of the thickness
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if first_wall_intrusion(outline, mid) is None else (lo, mid)
    return lo


def on_one_line(outline) -> bool:
    """Every corner of an outline within :data:`OVERLAP_MIN_M` of one line (it encloses no
    area)."""
    a = np.asarray(outline, dtype=float).reshape(-1, 2)
    far = a[int(np.argmax(np.hypot(*(a - a[0]).T)))]
    span = math.hypot(*(far - a[0]))
    if span == 0.0:
        return True
    off = np.abs((far[0] - a[0, 0]) * (a[:, 1] - a[0, 1])
                 - (far[1] - a[0, 1]) * (a[:, 0] - a[0, 0]))
    return bool(np.all(off <= OVERLAP_MIN_M * span))


def box_corners(box: Box) -> np.ndarray:
    """(4, 2) corners of a box, counter-clockwise."""
    c, s = math.cos(box.yaw_rad), math.sin(box.yaw_rad)
    hx, hy = box.size_m[0] / 2, box.size_m[1] / 2
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    return local @ np.array([[c, s], [-s, c]]) + np.asarray(box.center_m)


def _box_local(ob: Box, px, py):
    c, s = math.cos(ob.yaw_rad), math.sin(ob.yaw_rad)
    dx, dy = px - ob.center_m[0], py - ob.center_m[1]
    return c * dx + s * dy, -s * dx + c * dy


def inside_obstacle(ob: Cylinder | Box, px, py) -> np.ndarray:
    """Points inside (or on) an obstacle."""
    if isinstance(ob, Cylinder):
        return np.hypot(px - ob.center_m[0], py - ob.center_m[1]) <= ob.radius_m
    lx, ly = _box_local(ob, px, py)
    return (np.abs(lx) <= ob.size_m[0] / 2) & (np.abs(ly) <= ob.size_m[1] / 2)


def obstacle_bounds(ob: Cylinder | Box, pad_m: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) corners of a box around an obstacle's footprint, ``pad_m`` wider on each
    side than its rounding: no point outside it is :func:`inside_obstacle`."""
    if isinstance(ob, Cylinder):
        c = np.asarray(ob.center_m, dtype=float)
        return c - ob.radius_m - pad_m, c + ob.radius_m + pad_m
    corners = box_corners(ob)
    return corners.min(axis=0) - pad_m, corners.max(axis=0) + pad_m


def obstacle_distance(ob: Cylinder | Box, px, py) -> np.ndarray:
    """Signed distance (m) from points to an obstacle's surface (negative inside)."""
    if isinstance(ob, Cylinder):
        return np.hypot(px - ob.center_m[0], py - ob.center_m[1]) - ob.radius_m
    lx, ly = _box_local(ob, px, py)
    qx, qy = np.abs(lx) - ob.size_m[0] / 2, np.abs(ly) - ob.size_m[1] / 2
    return np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0)) + np.minimum(np.maximum(qx, qy), 0.0)


def first_wall_into(ob: Cylinder | Box, outline) -> int | None:
    """The first wall of a closed outline that comes into an obstacle (deeper than
    :data:`GEOMETRY_TOL_M`: a wall touching it does not), or None. With the obstacle's
    centre inside the room, None means the whole obstacle is inside."""
    hit = np.flatnonzero(walls_into(ob, outline))
    return int(hit[0]) if hit.size else None


def walls_into(ob: Cylinder | Box, outline) -> np.ndarray:
    """(n,) bool: which walls of a closed outline come into an obstacle (as
    :func:`first_wall_into`)."""
    a = np.asarray(outline, dtype=float).reshape(-1, 2)
    b = np.roll(a, -1, axis=0)
    if isinstance(ob, Cylinder):
        near = segment_distance(ob.center_m[0], ob.center_m[1], a[:, 0], a[:, 1], b[:, 0],
                                b[:, 1]) < ob.radius_m - GEOMETRY_TOL_M
    else:   # each wall clipped to the box shrunk by the tolerance, in the box's own frame
        (u0, v0), (u1, v1) = _box_local(ob, a[:, 0], a[:, 1]), _box_local(ob, b[:, 0], b[:, 1])
        enter, leave = np.zeros(len(a)), np.ones(len(a))
        near = np.ones(len(a), bool)
        for start, end, half in ((u0, u1, ob.size_m[0] / 2), (v0, v1, ob.size_m[1] / 2)):
            half -= GEOMETRY_TOL_M
            step = end - start
            still = step == 0.0
            near &= ~still | (np.abs(start) < half)
            with np.errstate(divide="ignore", invalid="ignore"):
                t1, t2 = (-half - start) / step, (half - start) / step
            enter = np.where(still, enter, np.maximum(enter, np.minimum(t1, t2)))
            leave = np.where(still, leave, np.minimum(leave, np.maximum(t1, t2)))
        near &= leave > enter
    return near


FOOTPRINT_SIDES = 360   # a cylinder's footprint as a polygon: its area within 0.01 %


def footprint(ob: Cylinder | Box) -> np.ndarray:
    """(K, 2) an obstacle's outline seen from above, counter-clockwise: a box's corners, a
    cylinder's as a regular polygon of FOOTPRINT_SIDES corners on its circle."""
    if isinstance(ob, Box):
        return box_corners(ob)
    a = np.linspace(0.0, 2.0 * math.pi, FOOTPRINT_SIDES, endpoint=False)
    return np.asarray(ob.center_m) + ob.radius_m * np.column_stack([np.cos(a), np.sin(a)])


def polygon_area(poly) -> float:
    """Area (m²) a closed polygon encloses, either orientation (shoelace)."""
    x, y = np.asarray(poly, dtype=float).reshape(-1, 2).T
    return abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))) / 2.0


def clip_to_convex(poly, window) -> np.ndarray:
    """The part of a closed polygon (any simple one, either orientation) inside a convex
    counter-clockwise ``window`` (Sutherland–Hodgman: a concave ``poly`` may come out with
    edges running back over one another, which enclose no area)."""
    out = np.asarray(poly, dtype=float).reshape(-1, 2)
    w = np.asarray(window, dtype=float).reshape(-1, 2)
    for p, q in zip(w, np.roll(w, -1, axis=0)):
        if not len(out):
            break
        side = (q[0] - p[0]) * (out[:, 1] - p[1]) - (q[1] - p[1]) * (out[:, 0] - p[0])
        nxt, side_nxt = np.roll(out, -1, axis=0), np.roll(side, -1)
        keep, cross = side >= 0, (side >= 0) != (side_nxt >= 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(cross, side / (side - side_nxt), 0.0)
        both = np.empty((2 * len(out), 2))
        both[0::2], both[1::2] = out, out + t[:, None] * (nxt - out)
        out = both[np.column_stack([keep, cross]).reshape(-1)]
    return out


def reach_outside(ob: Cylinder | Box, outline, spacing_m: float = 0.001) -> float:
    """How far (m) an obstacle reaches past a closed outline: the largest distance from the
    outline of a point of its footprint outside it (0 when none is), from points along the
    footprint's edges at most ``spacing_m`` apart (the farthest point outside is on them)."""
    a = footprint(ob)
    b = np.roll(a, -1, axis=0)
    n = np.maximum(1, np.ceil(np.hypot(*(b - a).T) / spacing_m).astype(int))
    t = np.concatenate([np.arange(k) / k for k in n])
    start = np.repeat(a, n, axis=0)
    pts = start + t[:, None] * (np.repeat(b, n, axis=0) - start)
    out = ~inside_outline(pts[:, 0], pts[:, 1], outline)
    if not out.any():
        return 0.0
    return float(np.max(distance_to_outline(pts[out, 0], pts[out, 1], outline)))


# --------------------------------------------------------------------------- sweeps and points


def hardware_duration_s(n_steps: int, settle_s: float, samples: int,
                        period_s: float = GP2_PERIOD_S) -> float:
    """Seconds the real ring spends on a sweep: steps × (settle + samples × period)."""
    return float(n_steps) * (settle_s + samples * period_s)


@dataclass(frozen=True)
class Truth:
    """Ground truth of a simulated sweep, per reading (absent for hardware)."""

    distance_m: np.ndarray   # (S, N) from the emitter; NaN: nothing within max range
    incidence_rad: np.ndarray  # (S, N) between ray and surface normal; NaN where no hit
    hit_point: np.ndarray    # (S, N, 3) world; NaN where no hit
    origin: np.ndarray       # (S, N, 3) emitter position, world
    direction: np.ndarray    # (S, N, 3) unit beam direction, world
    geom_id: np.ndarray      # (S, N) int, −1 where no hit
    reflectance: np.ndarray  # (S, N) of the surface hit; NaN where no hit


@dataclass(frozen=True)
class Sweep:
    """One sweep of the ring: ADC counts and where the sensors pointed.

    ``sensor_angles[s, k]`` is sensor k's angle (rad, CCW from above) off its radial
    direction at step ``steps[s]``. ``pose`` is the robot pose (x m, y m, yaw rad) of the
    sweep; ``reading_poses`` (S, N, 3) is set only when the robot moved during it.
    """

    steps: np.ndarray            # (S,) motor step indices
    sensor_angles: np.ndarray    # (S, N) rad
    counts: np.ndarray           # (S, N) ADC counts (float unless quantised)
    timestamps_s: np.ndarray     # (S,) when each step was read (device clock for hardware)
    duration_s: float            # hardware time of the sweep
    pose: np.ndarray             # (3,)
    ring: Ring
    sensor_model: str = SENSOR_MODEL
    adc_bits: int = ADC_BITS
    vref_v: float = VREF_V
    max_range_m: float = MAX_RANGE_M
    samples: int = 1
    settle_s: float = 0.0
    truth: Truth | None = None
    reading_poses: np.ndarray | None = None   # (S, N, 3) when the robot moves
    missing_steps: tuple[int, ...] = ()       # steps requested whose readings never arrived
    source: str = "sim"

    @property
    def shape(self) -> tuple[int, int]:
        return self.counts.shape


def score_text(value: float | None, scale: float = 1.0, digits: int = 3) -> str:
    """A score (or other figure) as people read it, in the printed summary, the map's title
    and the bench tables alike: ``value`` × ``scale`` to ``digits`` decimals (a score: 0.995,
    not 0.99), or n/a where it is undefined (None)."""
    return "n/a" if value is None else f"{value * scale:.{digits}f}"


def rows_in_step_order(steps: np.ndarray) -> np.ndarray:
    """(S,) the rows of a sweep (``steps`` (S,): each row's motor step) in step order, rows
    of one step as they lie."""
    return np.argsort(np.asarray(steps), kind="stable")


def in_turn_order(sweep: Sweep) -> Sweep:
    """``sweep`` with its rows in the order the ring turns through its steps: unchanged when
    its steps rise or fall, else a copy with every per-step row sorted by rising step (a
    source or a hand-made recording may list them in any order; the mapper takes a
    reading's neighbours from the rows beside it)."""
    steps = np.asarray(sweep.steps)
    gaps = np.diff(steps)
    if np.all(gaps > 0) or np.all(gaps < 0):
        return sweep
    order = rows_in_step_order(steps)
    truth = None if sweep.truth is None else Truth(
        **{f.name: np.asarray(getattr(sweep.truth, f.name))[order]
           for f in dataclasses.fields(Truth)})
    return dataclasses.replace(
        sweep, steps=steps[order], sensor_angles=np.asarray(sweep.sensor_angles)[order],
        counts=np.asarray(sweep.counts)[order],
        timestamps_s=np.asarray(sweep.timestamps_s)[order], truth=truth,
        reading_poses=None if sweep.reading_poses is None else
        np.asarray(sweep.reading_poses)[order])


def step_stride(steps) -> int:
    """The greatest common divisor of the gaps between distinct motor ``steps`` (any order,
    repeats allowed): the steps from one reading to the next; 1 with fewer than two."""
    s = np.asarray(steps, dtype=np.int64).reshape(-1)
    if s.size < 2 or abs(int(s[1]) - int(s[0])) == 1:   # (one step apart: the divisor is 1)
        return 1
    return max(int(np.gcd.reduce(np.abs(np.diff(s)))), 1)


def reading_stride(sweep: Sweep) -> int:
    """Motor steps from one of a sweep's readings to the ring's next (``scan.step_stride``):
    :func:`step_stride` of its steps and those listed missing (so a lost step leaves a wider
    gap, not a coarser stride)."""
    return step_stride(np.concatenate([np.asarray(sweep.steps, dtype=np.int64).reshape(-1),
                                       np.asarray(sweep.missing_steps, dtype=np.int64)]))


class Reason(enum.IntEnum):
    """Why a reading is invalid (OK when it is valid)."""

    OK = 0
    NO_RETURN = 1          # counts at or below the noise floor: nothing within range
    OUT_OF_RANGE = 2       # a distance outside the sensor's calibrated range
    FOLDOVER_AMBIGUOUS = 3  # counts above the curve's peak region: two distances possible
    SATURATED = 4          # ADC at full scale
    NOT_CONVERGED = 5      # iterative estimation did not settle
    MISSING = 6            # the reading never arrived (hardware)
    INCIDENCE_UNKNOWN = 7  # on no line, too few neighbours to tell θ: the θ = 0 distance
    #                        could be > 100 mm long (arcs.local_incidence), or σ past
    #                        60 mm (members.unplaced_alone)


@dataclass(frozen=True)
class Points:
    """Estimated end points of every reading of a sweep, in the world frame.

    All arrays (S, N). ``origin_*`` is the emitter, ``heading`` the world beam direction;
    for invalid readings x, y, d, theta are NaN and ``reason`` says why.
    """

    x: np.ndarray
    y: np.ndarray
    d: np.ndarray
    theta: np.ndarray
    origin_x: np.ndarray
    origin_y: np.ndarray
    heading: np.ndarray
    sigma_m: np.ndarray       # 1-σ range uncertainty of the reading
    iterations: np.ndarray    # int
    valid: np.ndarray         # bool
    reason: np.ndarray        # uint8 of Reason
    max_range_m: float = MAX_RANGE_M
    cone_half_angle_rad: float = 0.0  # > 0: each reading is an echo from anywhere in this cone
    # (S, N) or None: how far a NO_RETURN reading's beam is known free, where a surface of
    # the sweep explains the silence (it meets it past the drop-out angle); NaN or None: to
    # max_range_m
    reach_m: np.ndarray | None = None

    def reasons(self) -> dict[str, int]:
        """How many readings fell into each reason."""
        values, counts = np.unique(self.reason, return_counts=True)
        return {Reason(int(v)).name.lower(): int(c) for v, c in zip(values, counts)}


_POINTS_FIELDS = frozenset(f.name for f in dataclasses.fields(Points))


def points_with(points: Points, **changes) -> Points:
    """``dataclasses.replace(points, **changes)`` without running ``__init__`` again (the
    estimator makes a handful a sweep; replace costs several times more): the same fields
    and values (Points has no ``__post_init__`` to skip; tests/test_estimate.py holds it to
    replace). Raises TypeError naming a field Points does not have."""
    unknown = changes.keys() - _POINTS_FIELDS
    if unknown:
        raise TypeError(f"Points has no field {', '.join(sorted(unknown))}")
    out = object.__new__(Points)
    out.__dict__.update(points.__dict__)
    out.__dict__.update(changes)
    return out


def ring_angles(ring: Ring) -> np.ndarray:
    """(N,) radial direction of each sensor in the robot frame: sensor k at k·2π/N."""
    return np.arange(ring.sensors) * (2.0 * np.pi / ring.sensors)


def sensor_angles_for_steps(ring: Ring, steps: np.ndarray) -> np.ndarray:
    """(S, N) commanded sensor angles: step × motor step × belt ratio, the same for all."""
    angle = np.asarray(steps, dtype=float) * ring.motor_step_rad * ring.gear
    return np.repeat(angle[:, None], ring.sensors, axis=1)


def beam_geometry(ring: Ring, pose: np.ndarray, sensor_angles: np.ndarray,
                  emitter_offset_m: float, *, trig: bool = False) -> tuple[np.ndarray, ...]:
    """Emitter positions (S, N, 2) and world beam headings (S, N) for a sweep.

    Frames (the one convention, shared by the MJCF model and the estimator): sensor k's
    hinge sits at radius R along robot angle ρ_k = k·2π/N; its beam points along
    h = yaw + ρ_k + φ (φ = sensor angle, CCW positive); the emitter sits d_o to the right of
    the hinge, at hinge + d_o·(sin h, −cos h). Against a wall at perpendicular distance y
    from the hinge this gives the paper's Eq. 5, d = −d_o·tan φ + y / cos φ.
    ``pose`` is (3,) or, for a moving robot, (S, N, 3). ``trig``: also cos h and sin h
    (the estimator's beam directions).
    """
    pose = np.asarray(pose, dtype=float)
    x, y, yaw = pose[..., 0], pose[..., 1], pose[..., 2]
    rho = yaw + ring_angles(ring)
    heading = rho + sensor_angles
    hx = x + ring.radius_m * np.cos(rho)
    hy = y + ring.radius_m * np.sin(rho)
    cos_h, sin_h = np.cos(heading), np.sin(heading)
    origin = np.empty(np.broadcast_shapes(np.shape(hx), np.shape(heading)) + (2,))
    np.add(hx, emitter_offset_m * sin_h, out=origin[..., 0])
    np.subtract(hy, emitter_offset_m * cos_h, out=origin[..., 1])
    return (origin, heading, cos_h, sin_h) if trig else (origin, heading)


def as_pose(pose: Any) -> np.ndarray:
    """(3,) x m, y m, yaw rad from a scenario ``Pose`` or a sequence (x, y[, yaw]).

    Raises ValueError naming what was given when it is neither."""
    if hasattr(pose, "x_m"):
        return np.array([pose.x_m, pose.y_m, pose.yaw_rad], dtype=float)
    try:
        arr = np.asarray(pose, dtype=float).ravel()
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.size not in (2, 3) or not np.isfinite(arr).all():
        raise ValueError(f"a pose is (x m, y m[, yaw rad]) or a scenario Pose, got {pose!r}")
    return np.append(arr, 0.0) if arr.size == 2 else arr


def check_steps(steps: Any, lo: int, hi: int) -> np.ndarray:
    """``steps`` as int64 motor steps for one sweep: a non-empty 1-D sequence of whole
    numbers within ``lo`` … ``hi``, each once (a step read twice would be estimated and mapped
    twice, and a recording of it is refused). Raises ValueError naming what is wrong."""
    arr = np.asarray(steps)
    if arr.ndim != 1 or arr.size == 0 or not np.issubdtype(arr.dtype, np.integer):
        raise ValueError(f"steps must be a non-empty 1-D array of whole motor steps, got "
                         f"{_show(arr, '')}")
    if arr.min() < lo or arr.max() > hi:
        raise ValueError(f"steps must lie in the ring's range {lo} … {hi}; got "
                         f"{arr.min()} … {arr.max()}")
    values, counts = np.unique(arr, return_counts=True)
    if counts.max() > 1:
        raise ValueError(f"step {values[counts > 1][0]} is listed twice; a sweep reads each "
                         "step once")
    return arr.astype(np.int64)


@runtime_checkable
class RingSource(Protocol):
    """Anything that sweeps a ring: the simulator (``SimRing``), the real ring over a serial
    port (``SerialRing``), a fake in a test. ``pipeline.acquire`` drives any of them.

    ``sweep(pose, *, steps=None)`` takes one sweep with the robot at ``pose`` — (x m, y m,
    yaw rad) or a scenario ``Pose`` (a simulator also takes a scan-pose index) — over
    ``steps`` (motor steps in order; None: the source's full sweep) and returns a
    :class:`Sweep`; steps whose readings never arrived are listed in ``missing_steps``, never
    invented. A source that goes away mid-sweep raises :class:`SourceLost`. ``close()``
    releases it; as a context manager it opens on entry and closes on exit.
    """

    def sweep(self, pose: Any, *, steps: np.ndarray | None = None) -> Sweep: ...

    def close(self) -> None: ...

    def __enter__(self) -> Any: ...

    def __exit__(self, *exc: object) -> Any: ...


class SourceLost(RuntimeError):
    """The source went away mid-sweep; ``partial`` holds the :class:`Sweep` of what arrived
    (None if nothing did) and ``report`` the source's account of it, if it keeps one."""

    def __init__(self, message: str, partial: Sweep | None = None, report: Any = None):
        super().__init__(message)
        self.partial, self.report = partial, report
