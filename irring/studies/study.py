"""Design studies: a grid of designs × scenarios × seeds × knobs from a YAML study file
(:func:`load_study`), every point run as ``irring run`` runs on any executor
(:func:`run_study`), one row per run appended to ``results.csv`` as it finishes (resumable),
then a summary per configuration and a chart. A bad study file raises :class:`StudyError`
(a ``ScenarioError``). Row order, resume and timing columns: docs/studies.md.
"""

from __future__ import annotations

import codecs
import contextlib
import csv
import dataclasses
import hashlib
import difflib
import itertools
import json
import math
import os
import re
import stat
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from .. import designs, gp2, safe_yaml
from ..core import (MAX_SEEDS, RESULT_ROW_BYTES, RESULT_ROW_TEXT_BYTES, SEED_MAX,
                    SENSOR_MODEL, Ring, bounds, key_unit, work_refusal)
from ..errors import OutputError, TooBig, brief, formula_start, printable
from ..maps.metrics import f1_score
from ..outputs import OutputSet, atomic_file, sole_writer, write_text_atomic
from ..pipeline import scenario_text
from ..resources import installed_version
from ..scenario import (ScenarioError, counted_seeds, listed, load_scenario,
                        not_a_scenario_file, scenario_file)
from . import accuracy
from .accuracy import mark_pareto
from .report import peak_memory_mb, write_csv
from .executor import stream

# knob → (type, lowest, highest, what it sets); the scenario's value when the study has none
KNOBS: Mapping[str, tuple[type, float, float, str]] = {
    "step_stride": (int, 1, 64, "scan.step_stride: motor steps between readings"),
    "samples": (int, 1, 64, "readings averaged per step (the averaging effect)"),
    "settle_ms": (float, 0.0, 5000.0, "scan.settle_s in ms: wait at each step before reading"),
}
TOP_KEYS = ("designs", "scenarios", "seeds", "knobs")
PARAMETRIC_KEYS = ("sensors", "radius_mm", "sweep_half_angle_deg", "step_deg")
PARAMETRIC_OPTIONAL = ("sensor", "name")
# a sensor step is a motor step times the paper's belt ratio (designs.parametric): the Ring's
# motor-step bounds in sensor degrees, 0.006 … 27° (step_deg 60 was let through to a
# "ring.motor_step_rad: 100 °" refusal naming a key no design file has)
STEP_DEG_RANGE = tuple(round(math.degrees(b) * designs.PAPER_RING.gear, 9)
                       for b in bounds(Ring, "motor_step_rad"))

KEY_COLUMNS = ("design", "scenario", "step_stride", "samples", "settle_ms", "seed")
DESIGN_COLUMNS = ("sensor", "sensors", "radius_mm", "sweep_half_angle_deg", "step_deg")
SCORE_COLUMNS = ("occupied_precision", "occupied_recall", "occupied_f1", "free_accuracy",
                 "coverage", "shadow", "range_rmse_m", "range_rmse_steep_m", "point_rmse_m",
                 "valid_share")
COST_COLUMNS = ("hardware_time_s", "hardware_time_total_s")
TIMING_COLUMNS = ("compute_ms", "estimate_ms", "map_ms", "sim_ms", "run_s", "worker_peak_mb")
META_COLUMNS = ("poses", "readings", "iterations_mean", "irring_version")
COLUMNS = (KEY_COLUMNS + DESIGN_COLUMNS + SCORE_COLUMNS + COST_COLUMNS + TIMING_COLUMNS
           + META_COLUMNS)
RESULTS = "results.csv"
_HEADER = (",".join(COLUMNS) + "\r\n").encode()   # as csv.writer writes it




class StudyError(ScenarioError):
    """A study file, or a results file, that cannot be used; one line naming the key."""


# --------------------------------------------------------------------------- the study file


@dataclass(frozen=True)
class DesignSpec:
    """One design of the grid: a named design, or a parametric ring."""

    label: str
    name: str | None = None            # a named design (designs.DESIGN_BY_NAME)
    params: tuple = ()                 # parametric: ((key, value), …) in PARAMETRIC_KEYS order
    sensor: str = SENSOR_MODEL
    design: Any = None                 # or a Design made in code (what compare() is given)

    def build(self):
        """The :class:`irring.designs.Design` (a named one, or ``designs.parametric``)."""
    
        if self.design is not None:
            return self.design
        if self.name is not None:
            return designs.get(self.name)
        p = dict(self.params)
        return designs.parametric(int(p["sensors"]), p["radius_mm"] / 1e3,
                                  math.radians(p["sweep_half_angle_deg"]),
                                  math.radians(p["step_deg"]), self.sensor, name=self.label)


@dataclass(frozen=True)
class Study:
    """A parsed study file. ``seeds``: explicit seeds, or None for ``seed_count`` seeds
    from each scenario's own (scenario.seed, +1, …)."""

    designs: tuple[DesignSpec, ...]
    scenarios: tuple[str, ...]
    seeds: tuple[int, ...] | None = None
    seed_count: int = 1
    knobs: tuple[tuple[str, tuple], ...] = ()
    source: str = ""


def _fail(source: str, path: str, msg: str) -> StudyError:
    where = f"{source}: " if source else ""
    return StudyError(f"{where}{path or '<top>'}: {msg}")


def _unknown(source: str, path: str, key: Any, allowed: Sequence[str]) -> StudyError:
    match = difflib.get_close_matches(str(key), list(allowed), n=1)
    hint = f" (did you mean `{match[0]}`?)" if match else ""
    return _fail(source, f"{path}.{key}" if path else str(key),
                 f"unknown key{hint}; allowed here: {', '.join(allowed)}")


def _list(source: str, path: str, raw: Any, what: str) -> list:
    if isinstance(raw, (str, int, float, Mapping)) and not isinstance(raw, bool):
        raw = [raw]
    if not isinstance(raw, list) or not raw:
        raise _fail(source, path, f"expected a non-empty list of {what}, got {raw!r}")
    return raw


def _number(source: str, path: str, raw: Any, tp: type, lo: float, hi: float) -> float | int:
    ok = isinstance(raw, (int, float)) and not isinstance(raw, bool)
    if ok and tp is int and isinstance(raw, float):
        ok = raw.is_integer()
    unit = key_unit(path)
    unit = f" {unit}" if unit else ""
    span = (f"{lo:g} … {hi:g}" if tp is float else f"{int(lo)} … {int(hi)}") + unit
    if not ok or not math.isfinite(raw):
        kind = "an integer" if tp is int else "a number"
        raise _fail(source, path, f"expected {kind} in {span}, got {brief(raw)}")
    if not lo <= raw <= hi:
        raise _fail(source, path, f"{brief(raw)}{unit} is out of range; allowed {span}")
    return tp(raw)


def design_spec(source: str, path: str, raw: Any) -> DesignSpec:
    """A design as a study file writes it (a name, or a parametric ring mapping), checked;
    raises :class:`StudyError` naming ``source`` and ``path``."""
    if isinstance(raw, str):
        if raw not in designs.DESIGN_BY_NAME:
            raise _fail(source, path, f"{raw!r} is not a named design; choose one of: "
                        f"{', '.join(designs.DESIGN_BY_NAME)}, or give a parametric ring "
                        f"{{{', '.join(PARAMETRIC_KEYS)}}}")
        return DesignSpec(raw, name=raw)
    if not isinstance(raw, Mapping):
        raise _fail(source, path, f"expected a design name or a mapping "
                    f"{{{', '.join(PARAMETRIC_KEYS)}}}, got {raw!r}")
    allowed = PARAMETRIC_KEYS + PARAMETRIC_OPTIONAL
    for key in raw:
        if key not in allowed:
            raise _unknown(source, path, key, allowed)
    for key in PARAMETRIC_KEYS:
        if key not in raw:
            raise _fail(source, f"{path}.{key}", "required key is missing")
    limits = {"sensors": (int, 1, 64), "radius_mm": (float, 0.0, 1000.0),
              "sweep_half_angle_deg": (float, 0.0, 180.0), "step_deg": (float, *STEP_DEG_RANGE)}
    params = tuple((k, _number(source, f"{path}.{k}", raw[k], *limits[k]))
                   for k in PARAMETRIC_KEYS)
    sensor = raw.get("sensor", SENSOR_MODEL)
    if not gp2.is_sensor_model(sensor):
        raise _fail(source, f"{path}.sensor", f"{sensor!r} is not allowed; choose one of: "
                    f"{', '.join(gp2.SENSORS)}")
    p = dict(params)
    label = raw.get("name") or (f"ring{p['sensors']}_r{p['radius_mm']:g}_"
                                f"a{p['sweep_half_angle_deg']:g}_s{p['step_deg']:g}"
                                + ("" if sensor == SENSOR_MODEL else f"_{sensor}"))
    if not isinstance(label, str) or not label.strip() or len(label) > 200:
        raise _fail(source, f"{path}.name", f"expected a text of 1 … 200 characters, got "
                                            f"{brief(label)}")
    if not label.isprintable():   # printed in the summary table, drawn in study.png
        raise _fail(source, f"{path}.name", f"{brief(label)}: control characters (terminal "
                                            "escapes, line breaks) are not allowed")
    if (why := formula_start(label)) is not None:
        raise _fail(source, f"{path}.name", why)
    spec = DesignSpec(str(label), params=params, sensor=sensor)
    try:
        spec.build()
    except ValueError as exc:  # the ring's own bounds check, in the loader's words
        raise _fail(source, path, str(exc)) from None
    return spec


def parse_study(raw: Any, source: str = "") -> Study:
    """Validate a parsed study document (see the module doc); raises :class:`StudyError`, or
    :class:`irring.errors.TooBig` for more runs than the work budget holds."""
    if not isinstance(raw, Mapping):
        raise _fail(source, "", "a study file must be a mapping with keys "
                    + ", ".join(TOP_KEYS))
    for key in raw:
        if key not in TOP_KEYS:
            raise _unknown(source, "", key, TOP_KEYS)
    for key in ("designs", "scenarios"):
        if key not in raw:
            raise _fail(source, key, "required key is missing")
    designs = tuple(design_spec(source, f"designs[{i}]", d)
                    for i, d in enumerate(_list(source, "designs", raw["designs"], "designs")))
    labels = [d.label for d in designs]
    for i, label in enumerate(labels):
        if label in labels[:i]:
            raise _fail(source, f"designs[{i}]", f"design {label!r} is listed twice")
    scenarios, seed_of, seen = [], {}, {}
    for i, s in enumerate(_list(source, "scenarios", raw["scenarios"], "scenario names or paths")):
        path = f"scenarios[{i}]"
        if not isinstance(s, str):
            raise _fail(source, path, f"expected a bundled scenario name or a YAML path, got {s!r}")
        if not s.strip():   # read as the study's folder: every *.yaml beside it ran unasked
            raise _fail(source, path, f"an empty name ({s!r}); name a bundled scenario, a YAML "
                                      "file or a folder of them (. is the study file's folder)")
        beside = Path(source).parent / s if source and not os.path.isabs(s) else None
        if beside is not None and beside.exists():   # a path relative to the study file
            if Path(s).exists() and scenario_file(s) != scenario_file(str(beside)):
                raise _fail(source, path, f"{s!r} names two files: {beside} beside the study "
                                          f"file and {s} in the working folder; write the "
                                          f"path of the one you mean (e.g. {beside})")
            if not Path(s).exists():
                s = str(beside)
        try:
            # a folder stands for its *.yaml, as in `irring bench rooms my_rooms/`
            named = listed(s)
            files = [f for f, _ in named]
            for f, in_folder in named:
                why = not_a_scenario_file(Path(f)) if in_folder else None
                if why:
                    raise ScenarioError(why)
                seed_of[f] = load_scenario(f)
        except ScenarioError as exc:
            raise _fail(source, path, str(exc)) from None
        for s in files:
            first = seen.setdefault(scenario_file(s), s)
            if s in scenarios or first != s:   # t_room and scenarios/t_room.yaml: one room
                raise _fail(source, path, f"scenario {s!r} is listed twice" + (
                    f" (as {first!r}, the same file); it would be run and counted in the "
                    f"means twice" if first != s else ""))
            scenarios.append(s)
    for i, d in enumerate(designs):   # before any run: a ring the rooms cannot hold
        for s in scenarios:
            try:
                accuracy.design_in(seed_of[s], d.build())
            except ScenarioError as exc:
                raise _fail(source, f"designs[{i}]", str(exc)) from None
    seeds, count = None, 1
    raw_seeds = raw.get("seeds", 1)
    if isinstance(raw_seeds, int) and not isinstance(raw_seeds, bool):
        count = _number(source, "seeds", raw_seeds, int, 1, MAX_SEEDS)
        for i, s in enumerate(scenarios):
            try:
                counted_seeds(seed_of[s], count)
            except ScenarioError as exc:
                raise _fail(source, "seeds", f"scenarios[{i}]: {exc}") from None
    else:
        seeds = tuple(_number(source, f"seeds[{i}]", s, int, 0, SEED_MAX)
                      for i, s in enumerate(_list(source, "seeds", raw_seeds, "seeds")))
        if len(set(seeds)) != len(seeds):
            raise _fail(source, "seeds", f"a seed is listed twice: {list(seeds)}")
    knobs_raw = raw.get("knobs") or {}
    if not isinstance(knobs_raw, Mapping):
        raise _fail(source, "knobs", f"expected a mapping of knob → list of values "
                    f"({', '.join(KNOBS)}), got {knobs_raw!r}")
    knobs = []
    for key, values in knobs_raw.items():
        if key not in KNOBS:
            raise _unknown(source, "knobs", key, tuple(KNOBS))
        tp, lo, hi, _ = KNOBS[key]
        vals = tuple(_number(source, f"knobs.{key}[{i}]", v, tp, lo, hi)
                     for i, v in enumerate(_list(source, f"knobs.{key}", values, "values")))
        if len(set(vals)) != len(vals):
            raise _fail(source, f"knobs.{key}", f"a value is listed twice: {list(vals)}")
        knobs.append((key, vals))
    settings = math.prod(len(v) for _, v in knobs)
    n_seeds = len(seeds) if seeds is not None else count
    runs = len(designs) * len(scenarios) * settings * n_seeds
    refusal = work_refusal(
        f"{len(designs)} designs × {len(scenarios)} scenarios × {settings} knob settings × "
        f"{n_seeds} seeds = {runs:,} runs, their results read back to summarise",
        runs * RESULT_ROW_BYTES, "a study", "use fewer seeds, knob values, designs or scenarios, "
        "or split it into several studies")
    if refusal:
        raise TooBig(f"{source}: {refusal}" if source else refusal)
    return Study(designs, tuple(scenarios), seeds, count, tuple(knobs), source)


def load_study(path: str | Path) -> Study:
    """Read and validate a study file; raises :class:`StudyError` naming the bad key."""
    try:
        raw = safe_yaml.load_file(path, "study file")
    except safe_yaml.InputError as exc:
        raise StudyError(str(exc)) from None
    return parse_study(raw, str(path))


# --------------------------------------------------------------------------- the grid


@dataclass(frozen=True)
class Point:
    """One run of the grid. ``key`` identifies it in results.csv (the KEY_COLUMNS as text)."""

    design: DesignSpec
    scenario: str
    step_stride: int
    samples: int
    settle_ms: float
    seed: int

    @property
    def key(self) -> tuple[str, ...]:
        return (self.design.label, self.scenario, str(self.step_stride), str(self.samples),
                repr(float(self.settle_ms)), str(self.seed))


def own_knobs(scenario) -> dict[str, float]:
    """The knob values a scenario runs with as written."""
    return {"step_stride": scenario.scan.step_stride, "samples": scenario.samples_per_step,
            "settle_ms": scenario.scan.settle_s * 1e3}


def point(design: DesignSpec, scenario, seed: int, *, loaded=None, **knobs) -> Point:
    """One grid point of ``scenario`` (a name, a path, or a Scenario: its file, or its name
    when it has none); knobs not given take the scenario's values. ``loaded``: the Scenario
    a name or path names, already loaded (else it is loaded here)."""
    sc = (loaded if loaded is not None else load_scenario(scenario)
          if isinstance(scenario, (str, Path)) else scenario)
    label = str(scenario) if isinstance(scenario, (str, Path)) else (sc.source or sc.name)
    k = {**own_knobs(sc), **knobs}
    return Point(design, label, int(k["step_stride"]), int(k["samples"]),
                 float(k["settle_ms"]), int(seed))


def grid(study: Study) -> list[Point]:
    """Every point in grid order: designs, then scenarios, then knob values (in the file's
    order, last fastest), then seeds. Knobs the study leaves out take the scenario's values."""
    names = [k for k, _ in study.knobs]
    combos = list(itertools.product(*[v for _, v in study.knobs]))
    out = []
    loaded = {s: load_scenario(s) for s in study.scenarios}   # once each, not once a point
    for d in study.designs:
        for s in study.scenarios:
            sc = loaded[s]
            seeds = study.seeds or counted_seeds(sc, study.seed_count)
            out += [point(d, s, seed, loaded=sc, **dict(zip(names, combo)))
                    for combo in combos for seed in seeds]
    return out


@dataclass(frozen=True)
class Task:
    """What a worker gets for one point: the scenario as YAML text (no files needed).
    ``scenario``: the Scenario itself instead, for a run in this process only."""

    point: Point
    scenario_yaml: str | None
    scenario_source: str
    scenario: Any = None


def tasks_for(points: Iterable[Point], scenarios: Mapping[str, Any] | None = None) -> list[Task]:
    """A task per point; its scenario loaded from ``point.scenario``, or taken from
    ``scenarios`` (label → Scenario). One made in code, without a file, travels as itself
    and can only run in this process."""
    scenarios = dict(scenarios or {})
    texts: dict[str, tuple] = {}
    out = []
    for p in points:
        if p.scenario not in texts:
            sc = scenarios.get(p.scenario) or load_scenario(p.scenario)
            text = scenario_text(sc)
            texts[p.scenario] = (text, sc.source, sc if text is None else None)
        out.append(Task(p, *texts[p.scenario]))
    return out




def design_columns(design) -> dict[str, Any]:
    """The :data:`DESIGN_COLUMNS` of a :class:`irring.designs.Design`."""
    ring = design.ring
    return dict(sensor=design.sensor.kind, sensors=ring.sensors, radius_mm=ring.radius_m * 1e3,
                sweep_half_angle_deg=math.degrees(max(abs(ring.min_step), abs(ring.max_step))
                                                  * ring.motor_step_rad * ring.gear),
                step_deg=math.degrees(ring.motor_step_rad * ring.gear))


def run_point(task: Task) -> dict:
    """One run of the grid (module level, so any executor can ship it): the row for
    results.csv, every column of :data:`COLUMNS`."""
    t0 = time.perf_counter()
    p = task.point
    design = p.design.build()
    # a knob at the scenario's own value is left alone, so `step_stride: [1]` is the
    # scenario as written, run for run
    base = task.scenario if task.scenario is not None else \
        accuracy.scenario_from_text(task.scenario_yaml, task.scenario_source)
    own = own_knobs(base)
    knobs = {k: (None if getattr(p, k) == own[k] else getattr(p, k)) for k in KNOBS}
    cfg = accuracy.Config("study", p.design.label, step_stride=knobs["step_stride"],
                          samples=knobs["samples"],
                          settle_s=None if knobs["settle_ms"] is None else knobs["settle_ms"] / 1e3,
                          design=design)
    r = accuracy.run_job(accuracy.Job(task.scenario_yaml, task.scenario_source, cfg, p.seed,
                                      base if task.scenario_yaml is None else None))
    row = dict(zip(KEY_COLUMNS, (p.design.label, p.scenario, p.step_stride, p.samples,
                                 float(p.settle_ms), p.seed)))
    row.update(design_columns(design))
    row.update({k: r.get(k) for k in SCORE_COLUMNS + COST_COLUMNS})
    row.update({k: r[k] for k in ("compute_ms", "estimate_ms", "map_ms", "sim_ms",
                                  "poses", "readings", "iterations_mean")})
    row["run_s"] = time.perf_counter() - t0
    row["worker_peak_mb"] = peak_memory_mb()
    row["irring_version"] = installed_version()
    return {k: row[k] for k in COLUMNS}


# --------------------------------------------------------------------------- results.csv


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v)   # round-trips exactly
    return str(v)


MAX_LINE_BYTES = 2**16   # of a results.csv line (a study writes ~500 bytes; csv's own field
#                          limit, 128 kB, ends in csv.Error)


def read_results(path: str | Path, *, repair: bool = False) -> list[dict[str, str]]:
    """The rows of a results.csv as text, read line by line. A last line cut short by a kill
    is dropped (and, with ``repair``, cut from the file). Raises :class:`StudyError` if the
    columns are not this version's or a line is damaged, :class:`TooBig` if the rows would
    take more memory than a study may use."""
    p = Path(path)
    lines = _Lines(p)
    try:
        # a device never ends (/dev/zero), a pipe blocks open() until a writer comes
        if not stat.S_ISREG(p.stat().st_mode):
            raise StudyError(f"{p}: not a regular file; a study's {RESULTS} is the file it "
                             "wrote: choose another --out")
        with open(p, "rb") as fh:
            rows = _read_rows(p, lines, lines.read(fh))
    except OSError as exc:
        raise StudyError(f"{p}: cannot read the study's results: "
                         f"{exc.strerror or exc}") from None
    if lines.cut is not None and repair:
        with open(p, "r+b") as fh:
            fh.truncate(lines.cut)
    return rows


class _Lines:
    """A results.csv's complete lines, decoded; counts the bytes read and where a last line
    without its newline (cut short by a kill) begins."""

    def __init__(self, path: Path):
        self.path = path
        self.bytes = 0
        self.cut: int | None = None

    def read(self, fh) -> Iterable[str]:
        """Each line with its newline (csv joins the lines of a quoted field)."""
        for number in itertools.count(1):
            raw = fh.readline(MAX_LINE_BYTES + 1)
            if not raw.endswith(b"\n"):
                if len(raw) > MAX_LINE_BYTES:
                    raise StudyError(f"{self.path}: line {number} is longer than "
                                     f"{MAX_LINE_BYTES:,} bytes (a study writes ~500); the file "
                                     "was edited or damaged")
                if number == 1 and raw and not _HEADER.startswith(
                        raw.removeprefix(codecs.BOM_UTF8)):
                    # a kill cuts only what a study wrote; a first line that is not the
                    # start of its header is someone else's file (a note, a picture)
                    raise StudyError(f"{self.path}: is not the {RESULTS} irring study writes "
                                     f"(it begins {brief(raw[:40])}, not with its columns); "
                                     "choose another --out, or move the file away to start "
                                     "afresh")
                self.cut = self.bytes if raw else None
                return
            start, self.bytes = self.bytes, self.bytes + len(raw)
            if number == 1:
                raw = raw.removeprefix(codecs.BOM_UTF8)   # a spreadsheet's "CSV UTF-8"
            try:
                yield raw.decode("utf-8")
            except UnicodeDecodeError as exc:   # saved by a spreadsheet in Latin-1 / cp1252
                raise StudyError(f"{self.path}: line {number}: not UTF-8 text (byte "
                                 f"{start + exc.start}); the file was edited or damaged; save "
                                 "it as UTF-8 CSV") from None


def _read_rows(p: Path, lines: _Lines, text: Iterable[str]) -> list[dict[str, str]]:
    reader = csv.reader(text)
    try:
        header = next(reader, None)   # None: no line at all; a blank first line is []
        if header is None:
            return []
        header = tuple(header)
        if header != COLUMNS:
            first = next((i for i, (h, c) in enumerate(zip(header, COLUMNS)) if h != c),
                         min(len(header), len(COLUMNS)))
            what = (f"column {first + 1} is {brief(header[first])}, expected "
                    f"{COLUMNS[first]!r}" if first < min(len(header), len(COLUMNS)) else
                    f"{len(header)} columns, expected {len(COLUMNS)}")
            raise StudyError(f"{p}: its columns are not the ones this irring writes ({what}); "
                             "choose another --out, or move the file away to start afresh")
        rows, lines_of = [], {}
        need, before = 0, lines.bytes
        for cells in reader:
            i = reader.line_num
            need += RESULT_ROW_BYTES + max(0, lines.bytes - before - RESULT_ROW_TEXT_BYTES)
            before = lines.bytes
            refusal = work_refusal(f"its runs read back to summarise ({len(rows) + 1:,} by "
                                   f"line {i})", need, "a study",
                                   "choose another --out, or split the file")
            if refusal:
                raise TooBig(f"{p}: {refusal}")
            if len(cells) != len(COLUMNS):
                raise StudyError(f"{p}: line {i} has {len(cells)} cells, expected "
                                 f"{len(COLUMNS)}; the file was edited or damaged")
            row = dict(zip(COLUMNS, cells))
            for col, cell in row.items():
                want = _cell_problem(col, cell)
                if want:
                    raise StudyError(f"{p}: line {i}, {col}: {brief(cell)} is not allowed; "
                                     f"{want}; the file was edited or damaged")
            f1 = _f1_problem(row)
            if f1:
                raise StudyError(f"{p}: line {i}, occupied_f1: {f1}; the file was edited or "
                                 "damaged")
            first = lines_of.setdefault(row_key(row), i)
            if first != i:   # summarised, it would count as one more run
                raise StudyError(f"{p}: line {i} repeats the run of line {first} "
                                 f"({row['design']}, {row['scenario']}, seed {row['seed']}); "
                                 "the file was edited or damaged")
            rows.append(row)
    except csv.Error as exc:
        raise StudyError(f"{p}: line {reader.line_num}: {exc}; the file was edited or "
                         "damaged") from None
    return rows


_TEXT_COLUMNS = ("design", "scenario", "sensor", "irring_version")
_WHOLE_COLUMNS = ("step_stride", "samples", "seed", "sensors", "poses", "readings")
_NAN_COLUMNS = ("worker_peak_mb",)   # NaN where the platform cannot measure it
_SHARE_COLUMNS = tuple(c for c in SCORE_COLUMNS if "rmse" not in c)   # 0 … 1


def _cell_problem(col: str, cell: str) -> str | None:
    """What a results.csv cell of ``col`` must be, if ``cell`` is not that (else None): the
    summary takes means of these, so a NaN, inf or text would end in it or in a crash."""
    if col in _TEXT_COLUMNS:
        return None
    if col in _WHOLE_COLUMNS:
        return None if re.fullmatch(r"-?[0-9]+", cell) else "a whole number"
    if cell == "" and col in SCORE_COLUMNS:
        return None   # n/a
    try:
        value = float(cell)
    except ValueError:
        value = None
    if col in _SHARE_COLUMNS:   # a share summarised as one: 7.5 made F1 4.245 ± 4.603
        return None if value is not None and 0 <= value <= 1 else "a number 0 … 1 or empty (n/a)"
    if value is not None and (math.isfinite(value) or (col in _NAN_COLUMNS and value != value)):
        return None if value >= 0 or value != value else "a number ≥ 0"
    return "a finite number" + (" or empty (n/a)" if col in SCORE_COLUMNS else "")


def _f1_problem(row: Mapping[str, str]) -> str | None:
    """Why a row's F1 is not the one its precision and recall give (the cells already
    checked), or None: an F1 edited to 0.5 beside precision 0.994 and recall 0.995 went
    into summary.csv. Spreadsheet digits (15 significant) pass."""
    p, r, f1 = (None if row[c] == "" else float(row[c])
                for c in ("occupied_precision", "occupied_recall", "occupied_f1"))
    want = f1_score(p, r)
    if (f1 is None) == (want is None) and (want is None or math.isclose(
            f1, want, rel_tol=1e-9, abs_tol=1e-12)):
        return None
    def cell(col: str) -> str:
        return printable(row[col], 30) or "empty"

    return (f"{cell('occupied_f1')} is not the F1 of the row's occupied_precision "
            f"{cell('occupied_precision')} and occupied_recall {cell('occupied_recall')}, "
            f"which is {'empty (n/a)' if want is None else f'{want:.6g}'}")


def _check_same_designs(path: Path, rows: Sequence[Mapping[str, str]],
                        points: Sequence[Point]) -> None:
    """:class:`StudyError` for a kept row whose design columns are not its point's: a design
    changed under its name would be summarised together with the runs of the old one."""
    by_key = {p.key: p for p in points}
    columns: dict[str, dict[str, Any]] = {}
    for line, row in enumerate(rows, start=2):
        p = by_key.get(row_key(row))
        if p is None:
            continue
        label = p.design.label
        if label not in columns:
            columns[label] = design_columns(p.design.build())
        for col, now in columns[label].items():
            same = (row[col] == now if isinstance(now, str)
                    else math.isclose(float(row[col]), now, rel_tol=1e-9, abs_tol=1e-12))
            if not same:
                raise StudyError(f"{path}: line {line}: {label} ({row['scenario']}, seed "
                                 f"{row['seed']}) was run with {col} {row[col]}; the study "
                                 f"file's {label} has {_cell(now)}: give the changed design "
                                 "another name, or choose another --out")


SCENARIOS = "scenarios.json"   # beside results.csv: what each scenario was when it ran


def scenario_digest(sc) -> str:
    """A scenario's fingerprint: SHA-256 of everything that shapes its runs (not its file's
    comments, layout, description or path)."""
    return hashlib.sha256(repr(dataclasses.replace(sc, source="", description=""))
                          .encode()).hexdigest()


def _check_same_scenarios(out: Path, rows: Sequence[Mapping[str, str]],
                          points: Sequence[Point]) -> None:
    """:class:`StudyError` for kept rows of a scenario file edited since they ran: resumed,
    the study ran none of them again and summarised the old room under the file's name.
    Then records every scenario's fingerprint in ``out``/scenarios.json."""
    path = out / SCENARIOS
    recorded: dict = {}
    if path.exists():
        try:
            raw = json.loads(path.read_text())
            recorded = raw["scenarios"]
            if not (isinstance(recorded, dict) and all(isinstance(v, str)
                                                       for v in recorded.values())):
                raise TypeError
        except (OSError, UnicodeDecodeError, ValueError, TypeError, KeyError) as exc:
            raise StudyError(f"{path}: not the record a study keeps of its scenarios "
                             f"({getattr(exc, 'strerror', None) or 'damaged or edited'}); "
                             "remove it (its scenarios are then taken as they are now) or "
                             "choose another --out") from None
    now = {label: scenario_digest(load_scenario(label))
           for label in dict.fromkeys(p.scenario for p in points)}
    kept: dict[str, int] = {}
    for row in rows:
        kept[row["scenario"]] = kept.get(row["scenario"], 0) + 1
    for label, digest in now.items():
        if kept.get(label) and recorded.get(label, digest) != digest:
            raise StudyError(f"{path.parent / RESULTS}: its {kept[label]} run(s) of {label} "
                             "were made before the file changed (another room, ring, effects "
                             "or knobs); resumed, they would be summarised as runs of it: "
                             "restore the file, save the changed one under another name, or choose "
                             "another --out")
    recorded.update(now)
    write_text_atomic(path, json.dumps({"format": 1, "scenarios": recorded}, indent=1) + "\n")


def row_key(row: Mapping[str, Any]) -> tuple[str, ...]:
    """A row's grid point as text (the same as :attr:`Point.key`)."""
    return (str(row["design"]), str(row["scenario"]), str(row["step_stride"]),
            str(row["samples"]), repr(float(row["settle_ms"])), str(row["seed"]))


def _write_sorted(path: Path, rows: list[dict[str, str]]) -> None:
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(COLUMNS)
            for r in rows:
                w.writerow([r[k] for k in COLUMNS])
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)   # a full disk: the rows in path stay as streamed


@contextlib.contextmanager
def _results_writes(path: Path, kept: Callable[[], int]):
    """Writes to results.csv: an OSError there (a full disk, a file-size limit) is an
    :class:`OutputError` naming the file and the runs it keeps for ``--resume``."""
    try:
        yield
    except OSError as exc:
        if isinstance(exc, OutputError):
            raise
        raise OutputError(f"{path}: cannot write the study's results: "
                          f"{exc.strerror or exc}; the {kept()} run(s) written before are kept "
                          "(free space, then rerun with --resume)") from exc


def _still_there(fh, path: Path) -> None:
    """:class:`OutputError` when ``path`` no longer names the results file ``fh`` appends to
    (--out removed, moved or replaced mid-study): the rows went on into a file no one could
    read, and the study ended, after all its runs, "cannot read the study's results"."""
    mine = os.fstat(fh.fileno())
    try:
        now = os.stat(path)
    except OSError:
        now = None
    if now is None or (now.st_ino, now.st_dev) != (mine.st_ino, mine.st_dev):
        raise OutputError(f"{path}: was removed, moved or replaced while the study wrote to it, "
                          "so its rows went where no one reads them; the study stopped: run it "
                          "again (with --resume where the file is whole) to run what is missing")


def _write_parquet(csv_path: Path) -> Path | None:
    """results.parquet beside results.csv, if pyarrow is installed (columns typed)."""
    try:
        import pyarrow.csv as pa_csv   # deferred: optional, not a dependency
        import pyarrow.parquet as pq
    except ImportError:
        return None
    out = csv_path.with_suffix(".parquet")
    with atomic_file(out) as tmp:
        pq.write_table(pa_csv.read_csv(csv_path), tmp)
    return out


# --------------------------------------------------------------------------- running


def run_study(study: Study | Sequence[Point], out_dir: str | Path, ex=None, *,
              resume: bool = False, progress: Callable[[dict], None] | None = None,
              on_start: Callable[[int, int], None] | None = None) -> dict:
    """Run every point not yet in ``out_dir/results.csv``, appending each row as it finishes,
    then rewrite the file in grid order and write the summary (:func:`write_summary`).

    ``ex``: a ``concurrent.futures`` executor (default: this process). An existing file with
    rows is an error unless ``resume``. ``on_start(done, todo)`` is told the counts before the
    first run; ``progress(row)`` after each. Returns ``{"rows": [...], "done_before": n,
    "ran": m, "paths": {...}}``; rows are text, in grid order.
    """
    points = grid(study) if isinstance(study, Study) else list(study)
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise StudyError(f"{out}: cannot write the study's results there: "
                         f"{exc.strerror or exc}") from None
    with sole_writer(out, f"a study's {RESULTS}"):   # exit 4 while another study runs there
        return _run_study(study, points, out, ex, resume, progress, on_start)


def _run_study(study, points: list, out: Path, ex, resume: bool, progress, on_start) -> dict:
    path = out / RESULTS
    if path.is_symlink():   # rows appended through it would land outside --out
        raise OutputError(f"{path}: a symbolic link (to {printable(os.readlink(path))}); a study "
                          f"appends to its own {RESULTS} in --out: remove the link or choose "
                          "another --out")
    existing = read_results(path, repair=resume) if path.exists() else []
    if existing and not resume:
        raise StudyError(f"{path}: already holds {len(existing)} run(s); pass --resume to run "
                         "only the missing ones, or choose another --out")
    _check_same_designs(path, existing, points)
    _check_same_scenarios(out, existing, points)
    done = {row_key(r) for r in existing}
    todo = [p for p in points if p.key not in done]
    refusal = work_refusal(    # the kept rows of points no longer in the study are read back too
        f"{len(existing):,} runs kept in {path} and {len(todo):,} to run, read back to "
        "summarise", (len(existing) + len(todo)) * RESULT_ROW_BYTES, "a study",
        "choose another --out")
    if refusal:
        raise TooBig(refusal)
    if on_start is not None:
        on_start(len(points) - len(todo), len(todo))
    if todo:   # an earlier run's summary beside rows it does not count looks finished
        _drop_summary(out)
    new_file = not existing
    kept = len(existing)
    with _results_writes(path, lambda: kept):
        fh = open(path, "w" if new_file else "a", newline="", encoding="utf-8")
    try:
        w = csv.writer(fh)
        if new_file:
            with _results_writes(path, lambda: kept):
                w.writerow(COLUMNS)
                fh.flush()
        for _, row in stream(run_point, tasks_for(todo), ex):
            with _results_writes(path, lambda: kept):   # not the runs' own OSErrors
                w.writerow([_cell(row[k]) for k in COLUMNS])
                fh.flush()   # a killed study keeps every finished row
                _still_there(fh, path)
            kept += 1
            if progress is not None:
                progress(row)
    finally:
        # every row was flushed; what close() could still fail on is a row whose flush
        # already failed (--resume drops its cut-off line)
        with contextlib.suppress(OSError):
            fh.close()
    rows = read_results(path)
    order = {p.key: i for i, p in enumerate(points)}
    # grid order; rows of points no longer in the study are kept, after the grid's
    rows.sort(key=lambda r: order.get(row_key(r), len(order)))
    with _results_writes(path, lambda: len(rows)):
        _write_sorted(path, rows)
    paths = {"results": str(path)}
    pq = _write_parquet(path)
    if pq is not None:
        paths["parquet"] = str(pq)
    in_grid = [r for r in rows if row_key(r) in order]
    source = getattr(study, "source", "")
    paths.update(write_summary(in_grid, out, [k for k, _ in getattr(study, "knobs", ())],
                               Path(source).name if source else ""))
    return {"rows": rows, "done_before": len(points) - len(todo), "ran": len(todo),
            "paths": paths}


# --------------------------------------------------------------------------- summary

SUMMARY_SCORES = ("occupied_f1", "occupied_precision", "occupied_recall", "free_accuracy",
                  "coverage", "shadow", "range_rmse_m", "point_rmse_m", "valid_share")


def _num(v: str) -> float | None:
    return float(v) if v not in ("", None) else None


def summarise(rows: Sequence[Mapping[str, str]], by: Sequence[str] = ("design",)) -> list[dict]:
    """One record per configuration (the values of ``by``; rows in grid order): ``runs``,
    per score the mean (``<score>``) and sample standard deviation (``<score>_std``) over the
    runs where it is defined, ``shadow_runs`` (how many: shadow is defined only in rooms
    with wall hidden behind an obstacle), ``hardware_time_s`` (mean), ``compute_ms``
    (median), and the Pareto flags of :func:`irring.studies.accuracy.mark_pareto`."""
    groups: dict[tuple, list[Mapping[str, str]]] = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in by), []).append(r)
    out = []
    for key, mine in groups.items():
        rec: dict[str, Any] = dict(zip(by, key))
        rec["runs"] = len(mine)
        rec["scenarios"] = sorted({r["scenario"] for r in mine})
        for k in SUMMARY_SCORES:
            vals = np.array([v for v in (_num(r[k]) for r in mine) if v is not None])
            rec[k] = float(vals.mean()) if vals.size else None
            rec[f"{k}_std"] = float(vals.std(ddof=1)) if vals.size > 1 else (
                0.0 if vals.size else None)
            if k == "shadow":
                rec["shadow_runs"] = int(vals.size)
        rec["hardware_time_s"] = float(np.mean([float(r["hardware_time_s"]) for r in mine]))
        rec["compute_ms"] = float(np.median([float(r["compute_ms"]) for r in mine]))
        rec["dynamics"] = False
        out.append(rec)
    mark_pareto(out)
    return out


def _label(rec: Mapping[str, Any], by: Sequence[str]) -> str:
    short = {"step_stride": "stride", "samples": "samples", "settle_ms": "settle"}
    parts = [str(rec["design"])] + [f"{short[k]} {rec[k]}" for k in by if k != "design"]
    return ", ".join(parts)


def _share(rec: Mapping[str, Any]) -> str:
    """" in k/n" when the shadow is defined in only k of a configuration's n runs."""
    k = rec.get("shadow_runs", rec["runs"])
    return f" in {k}/{rec['runs']}" if 0 < k < rec["runs"] else ""


def table(records: Sequence[Mapping[str, Any]], by: Sequence[str] = ("design",)) -> str:
    """Plain-text summary: per configuration the mean ± spread of the main scores; the
    shadow's mean is over the runs in rooms that hide wall behind an obstacle, and says
    over how many when that is not all of them (``in k/n``)."""
    head = ["configuration", "runs", "F1 occ", "coverage", "free acc", "shadow", "RMSE mm",
            "hardware", "compute", "front"]
    rows = [head]

    def pm(r, k, scale=1.0, digits=3):
        m, s = r[k], r[f"{k}_std"]
        return "—" if m is None else f"{m * scale:.{digits}f} ± {s * scale:.{digits}f}"

    for r in records:
        front = [m for m in ("f1", "cov", "rmse") if r.get(f"front_hw_{m}")]
        rows.append([_label(r, by), str(r["runs"]), pm(r, "occupied_f1"), pm(r, "coverage"),
                     pm(r, "free_accuracy"), pm(r, "shadow") + _share(r),
                     pm(r, "range_rmse_m", 1e3, 1),
                     f"{r['hardware_time_s']:.2f} s", f"{r['compute_ms']:.2f} ms",
                     ",".join(front) or "·"])
    widths = [max(len(row[i]) for row in rows) for i in range(len(head))]
    lines = ["  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in
                       enumerate(zip(row, widths))) for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _counted(n: int, what: str) -> str:
    return f"{n} {what}" + ("" if n == 1 else "s")


def study_title(name: str, rows: Sequence[Mapping[str, str]],
                knobs: Sequence[str] = ()) -> str:
    """study.png's title: ``name`` (the study file's), its runs and what they are made of,
    e.g. "study_ir_rings.yaml: 225 runs = 5 designs × 3 rooms × 3 step_stride values × 5
    seeds per room" (or "× 3 seeds (1–3)" when every room ran the same seeds)."""
    if not rows:
        return f"{name}: no runs"
    per_room: dict[str, set[int]] = {}
    for r in rows:
        per_room.setdefault(r["scenario"], set()).add(int(r["seed"]))
    counts = [len({r["design"] for r in rows}), len(per_room),
              *(len({r[k] for r in rows}) for k in knobs)]
    parts = [_counted(counts[0], "design"), _counted(counts[1], "room"),
             *(_counted(n, f"{k} value") for n, k in zip(counts[2:], knobs))]
    sets = list(per_room.values())
    sizes = sorted({len(x) for x in sets})
    if all(x == sets[0] for x in sets):
        seeds = sorted(sets[0])
        listed = (f"{seeds[0]}–{seeds[-1]}" if len(seeds) > 2 and
                  seeds == list(range(seeds[0], seeds[-1] + 1)) else ", ".join(map(str, seeds)))
        parts.append(f"{_counted(len(seeds), 'seed')} ({listed})")
    else:
        parts.append(f"{_counted(sizes[0], 'seed')} per room" if len(sizes) == 1 else
                     f"{sizes[0]}–{sizes[-1]} seeds per room")
    if len(sizes) == 1 and math.prod(counts) * sizes[0] == len(rows):
        return f"{name}: {_counted(len(rows), 'run')} = " + " × ".join(parts)
    return f"{name}: {_counted(len(rows), 'run')} of " + ", ".join(parts)


def _plain(text: str) -> str:
    """``text`` drawn as it is: a "$" in a file or design name is not mathtext (a design
    named ``a$\\frac$`` made the chart, and the study's summary, fail)."""
    return text.replace("$", r"\$")


def chart(records: Sequence[Mapping[str, Any]], path: str | Path,
          by: Sequence[str] = ("design",), title: str = ""):
    """Occupied F1 and coverage against hardware time per 360° view (log scale), one point
    per configuration with its spread over runs (±1 sd): colour the design, marker the knob
    values. The Pareto front is drawn as a staircase and its points ringed; ``title`` (see
    :func:`study_title`) above both, and in the PNG's Title. Drawn on ``render.figure`` (no
    pyplot): the caller's matplotlib backend is left alone. Returns the Figure."""
    # deferred: matplotlib, only for the chart
    from matplotlib.lines import Line2D

    from ..maps.render import figure, plain_log, stretch_towards_one

    knobs = [k for k in by if k != "design"]
    designs = list(dict.fromkeys(r["design"] for r in records))
    combos = list(dict.fromkeys(tuple(r[k] for k in knobs) for r in records))
    markers = "osD^v<>phX*"
    colour = {d: f"C{i % 10}" for i, d in enumerate(designs)}
    marker = {c: markers[i % len(markers)] for i, c in enumerate(combos)}
    fig = figure(12, 5.2)
    axes = fig.subplots(1, 2)
    for ax, (metric, key, score) in zip(axes, (("f1", "occupied_f1", "occupied F1"),
                                               ("cov", "coverage", "coverage"))):
        recs = [r for r in records if r[key] is not None]
        for r in recs:
            ax.errorbar(r["hardware_time_s"], r[key], yerr=r[f"{key}_std"],
                        fmt=marker[tuple(r[k] for k in knobs)], color=colour[r["design"]],
                        capsize=3, ms=6)
        front = sorted((r for r in recs if r.get(f"front_hw_{metric}")),
                       key=lambda r: r["hardware_time_s"])
        if front:
            xs = [r["hardware_time_s"] for r in front]
            ys = [r[key] for r in front]
            right = max(r["hardware_time_s"] for r in recs) * 1.5
            ax.step(xs + [right], ys + [ys[-1]], where="post", color="0.35", lw=1.2, ls="--",
                    zorder=0)
            ax.scatter(xs, ys, s=200, facecolors="none", edgecolors="k", lw=1.3, zorder=3)
        plain_log(ax)
        ax.set_xlabel("hardware time per 360° view (s, log scale)")
        ax.set_ylim(-0.02, 1.05)
        if key == "occupied_f1":   # rings at 0.995 and 0.998 were one dot on 0 … 1
            stretch_towards_one(ax)
            ax.set_ylabel(f"{score}, higher is better\n(mean ± 1 sd over runs; "
                          "scale stretched towards 1)")
        else:
            ax.set_ylabel(f"{score}, higher is better\n(mean ± 1 sd over runs)")
        ax.grid(alpha=0.3, which="both")
        ax.set_title(f"{score} against hardware time (dashed: Pareto front, ringed: on it)",
                     fontsize=9)
    by_colour = [Line2D([], [], color=colour[d], marker="o", ls="", label=_plain(d))
                 for d in designs]
    short = {"step_stride": "stride", "samples": "samples", "settle_ms": "settle ms"}
    by_marker = [Line2D([], [], color="k", marker=marker[c], ls="", mfc="none",
                        label=", ".join(f"{short[k]} {v}" for k, v in zip(knobs, c)))
                 for c in combos] if knobs else []
    by_marker.append(Line2D([], [], color="0.35", ls="--", label="Pareto front"))
    # under the panels, the designs in a row and the markers in the next, each wrapped
    # before it passes the figure's width (beside the panels the legend kept a sixth of
    # the width, mostly blank)
    y = 0.0
    for handles in (by_marker, by_colour):   # from the bottom up
        widest = max(len(h.get_label()) for h in handles)
        # at 8 pt a character is ~6 px at 100 dpi; the marker and gaps ~50 px
        cols = max(1, min(len(handles), int(fig.get_figwidth() * 100) // (6 * widest + 50)))
        fig.legend(handles=handles, loc="lower center", bbox_to_anchor=(0.5, y), ncols=cols,
                   fontsize=8, frameon=False)
        y += 0.045 * -(-len(handles) // cols)
    if title:
        fig.suptitle(_plain(title), fontsize=10)
    fig.tight_layout(rect=(0, y + 0.01, 1, 1))
    fig.savefig(path, dpi=100, metadata={"Title": title} if title else None)
    return fig


SUMMARY_CSV_KEYS = ("runs", "hardware_time_s", "compute_ms") + tuple(
    c for k in SUMMARY_SCORES for c in (k, f"{k}_std")) + (
    "shadow_runs", "front_hw_f1", "front_hw_cov", "front_hw_rmse")


SUMMARY_FILES = {"summary_csv": "summary.csv", "summary_json": "summary.json",
                 "chart": "study.png"}


def _drop_summary(out: Path) -> None:
    """Remove the summary files and results.parquet of an earlier run before rows are
    appended: made from results.csv again at the end, they would otherwise stay beside a
    half-run study (Ctrl-C, a kill) as if it had finished."""
    for name in (*SUMMARY_FILES.values(), Path(RESULTS).with_suffix(".parquet").name):
        path = out / name
        try:
            if path.is_file() or path.is_symlink():
                path.unlink()
        except OSError as exc:
            raise OutputError(f"{path}: the summary of an earlier run cannot be removed "
                              f"before new runs are added: {exc.strerror or exc}") from None


def write_summary(rows: Sequence[Mapping[str, str]], out_dir: str | Path,
                  knobs: Sequence[str] = (), name: str = "") -> dict[str, str]:
    """summary.csv and summary.json (one record per configuration: design and the knobs
    the study varies) and study.png (the chart, titled with ``name``, the study file's, or
    "the study in DIR") in ``out_dir``, all together (:class:`irring.outputs.OutputSet`;
    results.csv beside them is left alone)."""
    by = ("design",) + tuple(knobs)
    records = summarise(rows, by)
    target = OutputSet(out_dir, files=SUMMARY_FILES.values())
    with target as tmp:
        paths = {k: tmp / name for k, name in SUMMARY_FILES.items()}
        write_csv(paths["summary_csv"], records, by + SUMMARY_CSV_KEYS)
        paths["summary_json"].write_text(json.dumps({"by": list(by), "configurations": records},
                                                    indent=2))
        chart(records, paths["chart"], by,
              study_title(name or f"the study in {Path(out_dir).resolve().name}", rows, knobs))
    return {k: str(target.out / name) for k, name in SUMMARY_FILES.items()}


def summary_records(out_dir: str | Path) -> tuple[list[str], list[dict]]:
    """(by, records) from a written summary.json."""
    data = json.loads((Path(out_dir) / "summary.json").read_text())
    return data["by"], data["configurations"]

