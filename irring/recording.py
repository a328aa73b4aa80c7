"""Sweeps saved to and loaded from a compressed ``.npz`` file, losslessly and without pickles
(loading one is safe), with a JSON ``meta`` (scenario text, seed, grid, calibration) from
which ``irring replay`` rebuilds the same map. The file layout: docs/recording.md.
"""

from __future__ import annotations

import dataclasses
import json
import math
import zipfile
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from . import core, gp2
from .core import (ADC_BITS, MAX_DURATION_S, MAX_RANGE_M, MAX_SAMPLES, MAX_STEPS, MAX_SWEEPS,
                   SEED_MAX, SENSOR_MODEL, VREF_V, Ring, Sweep, Truth, work_bytes, work_refusal)
from .errors import InputError, IrringError, TooBig, brief
from .maps.mapping import OFF_AT_INFINITY, MapperParams, check_grid_size
from .safe_yaml import MCAP_MAGIC, not_text
from .scenario import MapSpec, ScenarioError, load_dataclass

FORMAT = "irring-recording/1"
_RESOLUTION_M = core.bounds(MapSpec, "resolution_m")   # a recorded grid's cells: a scenario's


class RecordingError(InputError):
    """A file that is not an irring recording, or a damaged one."""


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"cannot store {type(obj).__name__} in a recording's JSON")


def _farthest(arr: np.ndarray) -> float:
    """max |x| of ``arr`` (0 if empty), taken in float64: in int64 |−2⁶³| is −2⁶³, and a
    float16 array cast the bound to inf with a RuntimeWarning."""
    return float(np.max(np.abs(arr.astype(np.float64)))) if arr.size else 0.0


def check_sweep(sweep: Sweep, name: str = "sweep") -> None:
    """ValueError naming ``name`` and the field for a :class:`Sweep` (from any source: a
    ``RingSource`` of your own, a sweep edited in code) that :func:`load_recording` would
    refuse: arrays of the wrong shape, NaN or inf, positions past ±1e6 m, a step twice or
    outside the ring, counts outside its ADC, scalars out of range. Mapped, such a sweep
    made NaN end points or invented readings, and its recording could not be replayed."""
    def fail(field_: str, msg: str) -> ValueError:
        return ValueError(f"{name}.{field_}: {msg}")

    counts = np.asarray(sweep.counts)
    if counts.ndim != 2 or counts.shape[1] != sweep.ring.sensors or counts.dtype.kind not in "iuf":
        raise fail("counts", f"expected numbers of shape (steps, {sweep.ring.sensors} sensors), "
                             f"got {counts.dtype} {counts.shape}")
    n_steps = counts.shape[0]
    shapes = {"steps": (n_steps,), "sensor_angles": counts.shape, "timestamps_s": (n_steps,),
              "pose": (3,), "reading_poses": counts.shape + (3,)}
    for field_, shape in shapes.items():
        value = getattr(sweep, field_)
        if value is None and field_ == "reading_poses":
            continue
        arr = np.asarray(value)
        if arr.shape != shape or arr.dtype.kind not in "iuf":
            raise fail(field_, f"expected numbers of shape {shape}, got {arr.dtype} {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise fail(field_, "holds NaN or infinite values")
        far = _farthest(arr) if field_.removeprefix("reading_") in ("pose", "sensor_angles") \
            else 0.0
        if far > MAX_ABS_COORDINATE:
            raise fail(field_, f"holds {far:g}; positions and angles lie "
                               f"within ±{MAX_ABS_COORDINATE:g} (m, rad)")
    if not np.all(np.isfinite(counts)):
        raise fail("counts", "holds NaN or infinite values")
    try:
        core.check_steps(sweep.steps, sweep.ring.min_step, sweep.ring.max_step)
        if sweep.missing_steps:
            core.check_steps(list(sweep.missing_steps), sweep.ring.min_step,
                             sweep.ring.max_step)
    except ValueError as exc:
        raise fail("steps", str(exc)) from None
    for field_, (ok, allowed, _) in _SCALARS.items():
        if not ok(getattr(sweep, field_)):
            raise fail(field_, f"{brief(getattr(sweep, field_))} is not allowed; {allowed}")
    top = 2 ** sweep.adc_bits - 1
    if counts.size and (counts.min() < 0 or counts.max() > top):
        raise fail("counts", f"readings {counts.min():g} … {counts.max():g} lie outside a "
                             f"{sweep.adc_bits}-bit ADC's 0 … {top}")
    if sweep.truth is not None:   # as the loader reads them (_TRUTH_ARRAYS)
        for key, dims in _TRUTH_ARRAYS.items():
            arr = np.asarray(getattr(sweep.truth, key))
            shape = counts.shape + ((3,) if dims == "SN3" else ())
            if arr.shape != shape or arr.dtype.kind not in ("iuf" if key == "geom_id" else "f"):
                raise fail(f"truth.{key}", f"expected numbers of shape {shape}, got "
                                            f"{arr.dtype} {arr.shape}")
            if key in ("origin", "direction") and not np.all(np.isfinite(arr)):
                raise fail(f"truth.{key}", "holds NaN or infinite values")


def _whole(value: Any, lo: int, hi: int) -> bool:
    return (isinstance(value, (int, np.integer)) and not isinstance(value, bool)
            and lo <= value <= hi)


# a sweep's scalars: (allowed?, what is allowed, default in a recording that leaves it out);
# one table for check_sweep and load_recording
_SCALARS: dict[str, tuple[Callable[[Any], bool], str, Any]] = {
    "sensor_model": (gp2.is_sensor_model, f"one of {', '.join(gp2.SENSORS)}", SENSOR_MODEL),
    "adc_bits": (lambda v: _whole(v, 1, core.MAX_ADC_BITS),
                 f"a whole number 1 … {core.MAX_ADC_BITS}", ADC_BITS),
    "vref_v": (lambda v: _finite(v, *core.VREF_RANGE_V),
               "{:g} … {:g} V".format(*core.VREF_RANGE_V), VREF_V),
    "max_range_m": (lambda v: _finite(v, 0.001, 100.0), "0.001 … 100 m", MAX_RANGE_M),
    "samples": (lambda v: _whole(v, 1, MAX_SAMPLES), f"a whole number 1 … {MAX_SAMPLES}", 1),
    "settle_s": (lambda v: _finite(v, 0.0, 60.0), "0 … 60 s", 0.0),
    "duration_s": (lambda v: _finite(v, 0.0, MAX_DURATION_S), f"0 … {MAX_DURATION_S:,.0f} s",
                   None),
}


def save_recording(path, sweeps: Sequence[Sweep], meta: dict | None = None) -> Path:
    """Write ``sweeps`` (and a JSON-serialisable ``meta``) to a compressed ``.npz``; a sweep
    :func:`check_sweep` refuses, no sweeps, or a folder as ``path`` raises ValueError before
    anything is written."""
    if not 1 <= len(sweeps) <= MAX_SWEEPS:   # what load_recording would refuse
        raise ValueError(f"a recording holds 1 … {MAX_SWEEPS} sweeps, got {len(sweeps)}")
    for i, sweep in enumerate(sweeps):
        check_sweep(sweep, f"sweeps[{i}]")
    meta_json = json.dumps(meta or {}, default=_json_default)
    _check_meta(json.loads(meta_json), ValueError)   # what load_recording would refuse
    path = Path(path)
    if path.is_dir():   # else written as the folder's name + .npz, beside it
        raise ValueError(f"{path}: is a folder; expected the path of a .npz file")
    if path.suffix != ".npz":
        path = path.with_suffix(".npz")
    arrays: dict[str, np.ndarray] = {
        "format": np.array(FORMAT),
        "meta": np.array(meta_json),
    }
    for i, sweep in enumerate(sweeps):
        key = f"sweep{i:03d}"
        scalars: dict[str, Any] = {}
        for f in dataclasses.fields(sweep):
            value = getattr(sweep, f.name)
            # a pose or counts given as a tuple or list (check_sweep takes them) went into the
            # scalars, and the recording could not be replayed ('pose: missing')
            if isinstance(value, np.ndarray) or (f.name in _SWEEP_ARRAYS and value is not None):
                arrays[f"{key}/{f.name}"] = np.asarray(value)
            elif f.name == "truth":
                if value is not None:
                    for tf in dataclasses.fields(value):
                        arrays[f"{key}/truth/{tf.name}"] = getattr(value, tf.name)
                scalars["has_truth"] = value is not None
            elif f.name == "ring":
                scalars["ring"] = dataclasses.asdict(value)
            else:
                scalars[f.name] = value
        # floats go through repr, which round-trips exactly
        arrays[f"{key}/scalars"] = np.array(json.dumps(scalars, default=_json_default))
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **arrays)
    return path



# Bounds checked before anything sized by the file is allocated.
MAX_FILE_BYTES = 2 * 2**30        # the .npz on disk
MAX_ARRAY_BYTES = 512 * 2**20     # one array, uncompressed
MAX_TEXT_CHARS = 8 * 2**20        # meta / scalars JSON, the embedded scenario

_SWEEP_ARRAYS = {  # name: (dimensions, kinds allowed, finite required)
    "steps": ("S", "iu", True), "sensor_angles": ("SN", "f", True), "counts": ("SN", "iuf", True),
    "timestamps_s": ("S", "iuf", True), "pose": ("3", "iuf", True),
    "reading_poses": ("SN3", "f", True),
}
# |value| bounds of positions (m) and angles (rad): a pose 1e300 m away is finite, but
# no map can place it (drawing its ring failed inside Pillow)
MAX_ABS_COORDINATE = core.MAX_ABS_COORDINATE_M
_BOUNDED = ("pose", "reading_poses", "sensor_angles")
_TRUTH_ARRAYS = {"distance_m": "SN", "incidence_rad": "SN", "hit_point": "SN3", "origin": "SN3",
                 "direction": "SN3", "geom_id": "SN", "reflectance": "SN"}


def _npy_header(zf: zipfile.ZipFile, info: zipfile.ZipInfo, fail) -> tuple[tuple, np.dtype]:
    """(shape, dtype) of a .npy member from its header alone; refuses pickled objects and
    arrays whose size does not match the member's."""
    with zf.open(info) as f:
        version = np.lib.format.read_magic(f)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
        else:
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
        header = f.tell()
    if dtype.hasobject or dtype.kind not in "biufcU":
        raise fail(f"{info.filename[:-4]}: holds {dtype} data; a recording holds numbers and text")
    nbytes = int(np.prod(shape, dtype=object)) * dtype.itemsize
    if nbytes > MAX_ARRAY_BYTES:
        raise fail(f"{info.filename[:-4]}: an array of shape {shape} ({nbytes / 2**20:.0f} MB) "
                   f"is larger than any recording holds (at most {MAX_ARRAY_BYTES // 2**20} MB)")
    if info.file_size != header + nbytes:
        raise fail(f"{info.filename[:-4]}: truncated or damaged ({info.file_size} bytes for an "
                   f"array of shape {shape})")
    return shape, dtype


_ZIP_END = b"PK\x05\x06"   # the zip's end-of-central-directory record: 22 bytes + comment
_ZIP_END_BYTES, _ZIP_COMMENT_MAX = 22, 0xFFFF


def _bytes_after_zip(path: Path) -> int:
    """How many bytes of ``path`` follow its zip's end record and comment (0 for a zip as
    written)."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        f.seek(max(0, size - _ZIP_END_BYTES - _ZIP_COMMENT_MAX))
        tail = f.read()
    at = tail.rfind(_ZIP_END)
    comment = int.from_bytes(tail[at + 20:at + 22], "little")
    return max(0, len(tail) - at - _ZIP_END_BYTES - comment) if at >= 0 else 0


def load_recording(path) -> tuple[list[Sweep], dict]:
    """Read a recording: (sweeps, meta). Raises :class:`RecordingError` (one line naming the
    file and the entry) for anything that is not a well-formed recording of this format:
    every array's shape and dtype is checked from the zip's headers before it is read, and
    every value against the schema (finite numbers, counts within the ADC's range, registry
    names) before it is used."""
    path = Path(path)

    def fail(msg: str) -> RecordingError:
        return RecordingError(f"{path}: {msg}")

    try:
        if path.is_dir():
            inside = path / "sweeps.npz"   # a run's --out
            raise fail("is a folder; expected a sweeps .npz recording" + (
                f" (this one holds one: irring replay {inside})" if inside.is_file() else ""))
        if not path.exists():
            raise fail("no such recording")
        if not path.is_file():   # a FIFO with no writer blocked here for good
            raise fail("is not a regular file (a pipe or a device); a recording is read from "
                       "a saved .npz file, in which it must seek: save it to a file first")
        if path.stat().st_size > MAX_FILE_BYTES:
            raise fail(f"{path.stat().st_size / 2**30:.1f} GB is larger than any recording")
        with open(path, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
            if head == MCAP_MAGIC:   # was "… damaged one: not a zip file"
                raise fail("an MCAP file (what --mcap writes for viewers such as Foxglove), "
                           "not a recording; replay the sweeps.npz written beside it")
            if not_text(head) and not head.startswith(b"PK"):   # a picture of the run's
                raise fail(f"{not_text(head)}; expected a sweeps .npz recording")
        with zipfile.ZipFile(path) as zf:
            infos = {i.filename: i for i in zf.infolist()}
            if len(infos) < len(zf.infolist()):   # zipfile reads the last of the same name
                seen: set[str] = set()
                twice = next(i.filename for i in zf.infolist()
                             if i.filename in seen or seen.add(i.filename))
                raise fail(f"{brief(twice[:-4])[1:-1]}: given twice in the zip; a recording "
                           "holds each entry once, and which one to read is not known")
            if "format.npy" not in infos:
                raise fail("not an irring recording (no 'format' entry)")
            # zipfile reads the last zip of a file: `cat a.npz b.npz` replayed b alone
            ahead = min(i.header_offset for i in infos.values())
            if ahead:
                raise fail(f"{ahead:,} bytes before the recording (two recordings joined into "
                           "one file?); replay each .npz on its own")
            after = _bytes_after_zip(path)
            if after:   # zipfile skips them too: `cat a.npz half-of-b.npz` replayed a alone
                raise fail(f"{after:,} bytes after the recording's end (another file, or part "
                           "of one, joined to it?); replay each .npz on its own")
            for name in infos:
                if not name.endswith(".npy"):
                    raise fail(f"{brief(name)}: unknown entry; a recording holds .npy arrays")
            headers = {name[:-4]: _npy_header(zf, info, fail) for name, info in infos.items()}
        _check_work(headers, path)
        with np.load(path, allow_pickle=False) as npz:
            return _read(npz, headers, fail)
    except IrringError:   # RecordingError, TooBig
        raise
    except Exception as exc:  # noqa: BLE001 - zipfile/zlib/numpy fail on damaged bytes in
        # many ways (BadZipFile, zlib.error, NotImplementedError for a flipped version or
        # flag, RuntimeError "encrypted", IndexError, EOFError, …): all mean a damaged file
        why = getattr(exc, "strerror", None) or f"{type(exc).__name__}: {exc}"
        raise fail(f"not an irring recording (.npz), or a damaged one: {brief(why)[1:-1]}") from None


def _check_work(headers: dict, path: Path) -> None:
    """:class:`TooBig` for sweeps too many readings to estimate and map within the work
    budget, told from the counts' headers before any array is read (a 1.2 MB file of one
    100,000 × 72 sweep filled 5.5 GB)."""
    shapes = [shape for name, (shape, _) in headers.items()
              if name.count("/") == 1 and name.endswith("/counts") and len(shape) == 2]
    if not shapes:
        return   # _read names what is missing
    readings = sum(s * n for s, n in shapes)
    steps, sensors = max(shapes, key=lambda sn: sn[0] * sn[1])
    refusal = work_refusal(f"{len(shapes)} sweeps, {readings:,} readings (the largest sweep "
                           f"{steps:,} steps × {sensors} sensors) to estimate and map",
                           work_bytes(readings, steps * sensors), "a replay",
                           "map fewer or shorter sweeps at a time")
    if refusal:
        raise TooBig(f"{path}: {refusal}")


def _text(npz, headers: dict, name: str, fail) -> str:
    shape, dtype = headers.get(name, (None, None))
    if shape != () or dtype.kind != "U" or dtype.itemsize // 4 > MAX_TEXT_CHARS:
        raise fail(f"{name}: expected one text entry of at most {MAX_TEXT_CHARS} characters")
    return str(npz[name])


def _json(npz, headers: dict, name: str, fail) -> dict:
    def once(pairs: list) -> dict:   # json keeps the last of a key given twice
        keys = [k for k, _ in pairs]
        for k in keys:
            if keys.count(k) > 1:
                raise fail(f"{name}: key {brief(k)} given twice")
        return dict(pairs)

    try:
        value = json.loads(_text(npz, headers, name, fail), object_pairs_hook=once)
    except RecordingError:
        raise
    except (ValueError, RecursionError):
        raise fail(f"{name}: not valid JSON") from None
    if not isinstance(value, dict):
        raise fail(f"{name}: expected a JSON object, got {brief(value)}")
    return value


def _read(npz, headers: dict, fail) -> tuple[list[Sweep], dict]:
    fmt = _text(npz, headers, "format", fail)
    if fmt != FORMAT:
        raise fail(f"recording format {brief(fmt)}; this irring reads {FORMAT!r}")
    meta = _json(npz, headers, "meta", fail)
    _check_meta(meta, fail)
    keys = set()
    for name in headers:
        head = name.split("/", 1)[0]
        if name in ("format", "meta"):
            continue
        if not (head.startswith("sweep") and head[5:].isdigit()):
            raise fail(f"{brief(name)}: unknown entry; a recording holds format, meta and "
                       f"sweepNNN/…")
        keys.add(head)
    numbers: dict[int, str] = {}
    for k in sorted(keys):
        other = numbers.setdefault(int(k[len("sweep"):]), k)
        if other != k:   # sweep1 and sweep001: one sweep number, two sweeps
            raise fail(f"{brief(other)[1:-1]} and {brief(k)[1:-1]} both number sweep "
                       f"{int(k[len('sweep'):])}; a recording numbers each sweep once")
    if not 1 <= len(keys) <= MAX_SWEEPS:
        raise fail(f"holds {len(keys)} sweeps; a recording holds 1 … {MAX_SWEEPS}")
    # by number: from sweep1000 on, names no longer sort as text (sweep1000 < sweep101)
    order = sorted(keys, key=lambda k: int(k[len("sweep"):]))
    absent = [n for n in range(max(numbers)) if n not in numbers]
    if absent:   # a sweep removed, or renumbered by another tool: replayed, it went unsaid
        raise fail(f"holds sweeps numbered {_spans(sorted(numbers))}: "
                   f"{_spans(absent)} {'is' if len(absent) == 1 else 'are'} missing; a "
                   f"recording numbers its sweeps sweep000, sweep001, … without a gap")
    sweeps = [_load_sweep(npz, headers, key, fail) for key in order]
    _check_grid_holds_poses(meta.get("grid"), sweeps, fail)
    return sweeps, meta


def _spans(numbers: list[int]) -> str:
    """[0, 1, 2, 7, 9, 10] → "0–2, 7, 9–10"."""
    runs: list[list[int]] = []
    for n in numbers:
        if runs and n == runs[-1][1] + 1:
            runs[-1][1] = n
        else:
            runs.append([n, n])
    return ", ".join(f"{a}" if a == b else f"{a}–{b}" for a, b in runs)


def _check_grid_holds_poses(grid: dict | None, sweeps: Sequence[Sweep], fail) -> None:
    """A recorded grid that holds none of the sweeps' poses belongs to other sweeps: mapped
    on it, every reading would land outside and the map come out empty without a word. (A
    drifting odometry may carry some believed poses off the grid they were mapped on; the
    run mapped what landed on it, and so does the replay.)"""
    if grid is None:
        return
    res = grid["resolution_m"]
    lo = np.asarray(grid["origin_xy_m"], dtype=float)
    hi = lo + res * np.asarray(grid["shape"][::-1], dtype=float)   # shape is rows, columns
    xy = np.array([np.asarray(sweep.pose, dtype=float)[:2] for sweep in sweeps])
    if not np.any(np.all((lo <= xy) & (xy <= hi), axis=1)):
        raise fail(f"meta.grid: sweep 1's pose ({xy[0, 0]:g}, {xy[0, 1]:g}) m lies outside "
                   f"the recorded grid (x {lo[0]:g} … {hi[0]:g} m, y {lo[1]:g} … "
                   f"{hi[1]:g} m), as do all the others; the grid and the sweeps do not "
                   "belong together")


def _finite(value: Any, lo: float, hi: float) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value) and lo <= value <= hi)


def _check_meta(meta: dict, fail) -> None:
    for key in ("scenario_yaml", "calibration_yaml", "scenario"):
        if meta.get(key) is not None and not isinstance(meta[key], str):
            raise fail(f"meta.{key}: expected text, got {brief(meta[key])}")
    seed = meta.get("seed")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)
                             or not 0 <= seed <= SEED_MAX):   # irring run --seed's bounds
        raise fail(f"meta.seed: expected a whole number 0 … {SEED_MAX}, got {brief(seed)}")
    grid = meta.get("grid")
    if grid is not None:
        ok = (isinstance(grid, dict) and set(grid) == {"origin_xy_m", "shape", "resolution_m"}
              and isinstance(grid["shape"], list) and len(grid["shape"]) == 2
              and all(isinstance(v, int) and not isinstance(v, bool) and v >= 1
                      for v in grid["shape"])
              and isinstance(grid["origin_xy_m"], list) and len(grid["origin_xy_m"]) == 2
              and all(_finite(v, -1e6, 1e6) for v in grid["origin_xy_m"])
              and _finite(grid["resolution_m"], *_RESOLUTION_M))
        if not ok:
            raise fail("meta.grid: expected origin_xy_m [x, y] (finite m), shape [rows, "
                       "columns] (whole numbers ≥ 1), resolution_m "
                       f"{_RESOLUTION_M[0]:g} … {_RESOLUTION_M[1]:g} (a scenario's map cells)")
        check_grid_size(*grid["shape"], grid["resolution_m"], f"{fail('').args[0]}meta.grid")
    mapper = meta.get("mapper")
    if mapper is not None:
        names = {f.name for f in dataclasses.fields(MapperParams)}
        if not isinstance(mapper, dict):
            raise fail(f"meta.mapper: expected a JSON object of mapper parameters, got "
                       f"{brief(mapper)}")
        for k, v in mapper.items():   # a parameter missing takes this irring's default
            if k not in names:
                raise fail(f"meta.mapper.{brief(k)[1:-1]}: a mapper parameter this irring does "
                           "not have (a recording from another irring version?); it maps with "
                           f"{', '.join(sorted(names))}")
            if not (_finite(v, -1e3, 1e3) or (k in OFF_AT_INFINITY and v == math.inf)):
                raise fail(f"meta.mapper.{k}: expected a finite number -1000 … 1000, got "
                           f"{brief(v)} (only {', '.join(OFF_AT_INFINITY)} may also be inf: "
                           "off)")
        try:
            MapperParams(**mapper)
        except ValueError as exc:
            raise fail(f"meta.mapper: {exc}") from None


def _array(npz, headers: dict, name: str, dims: str, kinds: str, sizes: dict, fail,
           finite: bool = True) -> np.ndarray:
    shape, dtype = headers[name]
    if dtype.kind not in kinds:
        want = {"i": "integers", "u": "integers", "f": "real numbers"}
        raise fail(f"{name}: holds {dtype}; expected "
                   f"{' or '.join(sorted({want[k] for k in kinds}))}")
    if len(shape) != len(dims):
        raise fail(f"{name}: shape {shape}; expected {len(dims)} dimension(s) ({dims})")
    for d, n in zip(dims, shape):
        expect = 3 if d == "3" else sizes.setdefault(d, n)
        if n != expect:
            raise fail(f"{name}: shape {shape} does not match the sweep's "
                       f"{sizes.get('S')} steps × {sizes.get('N')} sensors")
    arr = npz[name]
    if finite and arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        raise fail(f"{name}: holds NaN or infinite values")
    if name.rsplit("/", 1)[-1] in _BOUNDED:
        far = _farthest(arr)
        if far > MAX_ABS_COORDINATE:
            raise fail(f"{name}: holds {far:g}; positions and angles lie within "
                       f"±{MAX_ABS_COORDINATE:g} (m, rad)")
    return arr


def _check_steps(steps: np.ndarray, missing: list[int], ring: Ring, key: str, fail) -> None:
    """Steps listed once each and within the ring's range (a row also listed missing is one a
    source kept but marked missing): a step read twice was mapped twice, and no driver or
    simulator writes a step its ring does not have."""
    values, counts = np.unique(steps, return_counts=True)
    if np.any(counts > 1):
        raise fail(f"{key}/steps: step {values[counts > 1][0]} is listed twice; a sweep reads "
                   "each step once")
    for name, seq in ((f"{key}/steps", values), (f"{key}/scalars.missing_steps", missing)):
        outside = [int(s) for s in seq if not ring.min_step <= s <= ring.max_step]
        if outside:
            raise fail(f"{name}: step {outside[0]} lies outside the ring's steps "
                       f"{ring.min_step} … {ring.max_step}")


def _load_sweep(npz, headers: dict, key: str, fail) -> Sweep:
    scalars = _json(npz, headers, f"{key}/scalars", fail)
    known = {f.name for f in dataclasses.fields(Sweep)} | {"has_truth"}
    for name in scalars:
        if name not in known:
            raise fail(f"{key}/scalars: unknown field {brief(name)}")
    for name in headers:
        if name.startswith(key + "/") and name != f"{key}/scalars":
            rest = name[len(key) + 1:]
            if rest not in _SWEEP_ARRAYS and rest.removeprefix("truth/") not in _TRUTH_ARRAYS:
                raise fail(f"{brief(name)[1:-1]}: unknown entry")
    try:
        ring = load_dataclass(Ring, scalars.get("ring"), "ring", f"{fail('').args[0]}{key}")
    except ScenarioError as exc:
        raise RecordingError(str(exc)) from None
    # every recording lists them all; a default would invent geometry (a laser's radius 0
    # read as the paper's 0.15 m)
    ring_fields = [f.name for f in dataclasses.fields(Ring)]
    for name in ring_fields:
        if name not in (scalars.get("ring") or {}):
            raise fail(f"{key}/scalars.ring.{name}: missing; a recording lists every ring "
                       f"field ({', '.join(ring_fields)})")
    sizes = {"N": ring.sensors}
    kwargs: dict[str, Any] = {"ring": ring}
    for name, (dims, kinds, finite) in _SWEEP_ARRAYS.items():
        full = f"{key}/{name}"
        if full not in headers:
            if name == "reading_poses":
                continue
            raise fail(f"{full}: missing")
        kwargs[name] = _array(npz, headers, full, dims, kinds, sizes, fail, finite)
    if not 1 <= sizes["S"] <= MAX_STEPS:
        raise fail(f"{key}/steps: {sizes['S']} steps; a sweep has 1 … {MAX_STEPS}")

    def scalar(name: str, ok: Callable[[Any], bool], allowed: str, default: Any = None) -> Any:
        value = scalars.get(name, default)
        if not ok(value):
            raise fail(f"{key}/scalars.{name}: {brief(value)} is not allowed; {allowed}")
        return value

    def whole(lo: int, hi: int) -> Callable[[Any], bool]:
        return lambda v: isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi

    for name, (ok, allowed, default) in _SCALARS.items():
        kwargs[name] = scalar(name, ok, allowed, default)
    bits = kwargs["adc_bits"]
    kwargs["source"] = scalar("source", lambda v: isinstance(v, str) and len(v) <= 200,
                              "a short text", "sim")
    missing = scalar("missing_steps", lambda v: isinstance(v, list) and len(v) <= MAX_STEPS
                     and all(whole(-2**31, 2**31)(s) for s in v),
                     "a list of whole-number steps", [])
    kwargs["missing_steps"] = tuple(missing)
    _check_steps(kwargs["steps"], missing, ring, key, fail)
    counts = kwargs["counts"]
    if counts.size and (counts.min() < 0 or counts.max() > 2 ** bits - 1):
        raise fail(f"{key}/counts: readings {counts.min():g} … {counts.max():g} lie outside a "
                   f"{bits}-bit ADC's 0 … {2 ** bits - 1}")
    if scalar("has_truth", lambda v: isinstance(v, bool), "true or false", False):
        truth = {}
        for name, dims in _TRUTH_ARRAYS.items():
            full = f"{key}/truth/{name}"
            if full not in headers:
                raise fail(f"{full}: missing (has_truth is set)")
            truth[name] = _array(npz, headers, full, dims, "iuf" if name == "geom_id" else "f",
                                 sizes, fail, finite=name in ("origin", "direction"))
        kwargs["truth"] = Truth(**truth)
    try:
        return Sweep(**kwargs)
    except (TypeError, ValueError) as exc:
        raise fail(f"{key} is incomplete: {exc}") from None
