"""Sweeps saved to and loaded from a compressed ``.npz`` file, losslessly.

Everything a :class:`~irring.data.Sweep` holds survives the round trip bit for bit: the
arrays with their dtypes, the scalars, the :class:`~irring.scenario.Ring`, the optional
:class:`~irring.data.Truth` and per-reading poses. A JSON ``meta`` dict rides along (the
scenario text, seed, grid and calibration used), so ``irring replay`` can rebuild the same
map. The file holds no pickles (``allow_pickle=False``), so loading one is safe.

Layout (one zip member per array): ``meta`` (JSON text), ``format`` (version),
``sweep000/counts``, ``sweep000/truth/distance_m``, … and ``sweep000/scalars`` (JSON text
of the sweep's non-array fields, including the ring).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .data import Sweep, Truth
from .scenario import Ring

FORMAT = "irring-recording/1"


class RecordingError(ValueError):
    """A file that is not an irring recording, or a damaged one."""


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"cannot store {type(obj).__name__} in a recording's JSON")


def save_recording(path, sweeps: Sequence[Sweep], meta: dict | None = None) -> Path:
    """Write ``sweeps`` (and a JSON-serialisable ``meta``) to a compressed ``.npz``."""
    path = Path(path)
    if path.suffix != ".npz":
        path = path.with_suffix(".npz")
    arrays: dict[str, np.ndarray] = {
        "format": np.array(FORMAT),
        "meta": np.array(json.dumps(meta or {}, default=_json_default)),
    }
    for i, sweep in enumerate(sweeps):
        key = f"sweep{i:03d}"
        scalars: dict[str, Any] = {}
        for f in dataclasses.fields(sweep):
            value = getattr(sweep, f.name)
            if isinstance(value, np.ndarray):
                arrays[f"{key}/{f.name}"] = value
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


def load_recording(path) -> tuple[list[Sweep], dict]:
    """Read a recording: (sweeps, meta)."""
    path = Path(path)
    try:
        npz = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise RecordingError(f"{path}: no such recording") from None
    except (OSError, ValueError) as exc:
        raise RecordingError(f"{path}: not an irring recording (.npz): {exc}") from None
    with npz:
        if "format" not in npz.files:
            raise RecordingError(f"{path}: not an irring recording (no 'format' entry)")
        fmt = str(npz["format"])
        if fmt != FORMAT:
            raise RecordingError(f"{path}: recording format {fmt!r}; this irring reads {FORMAT!r}")
        meta = json.loads(str(npz["meta"]))
        # by number: from sweep1000 on, names no longer sort as text (sweep1000 < sweep101)
        keys = sorted({name.split("/", 1)[0] for name in npz.files if name.startswith("sweep")},
                      key=lambda k: int(k[len("sweep"):]))
        sweeps = [_load_sweep(npz, key, path) for key in keys]
    return sweeps, meta


def _load_sweep(npz, key: str, path: Path) -> Sweep:
    scalars = json.loads(str(npz[f"{key}/scalars"]))
    has_truth = scalars.pop("has_truth", False)
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(Sweep):
        name = f"{key}/{f.name}"
        if name in npz.files:
            kwargs[f.name] = npz[name]
        elif f.name == "ring":
            kwargs["ring"] = Ring(**scalars.pop("ring"))
        elif f.name == "truth":
            if has_truth:
                kwargs["truth"] = Truth(**{tf.name: npz[f"{key}/truth/{tf.name}"]
                                           for tf in dataclasses.fields(Truth)})
        elif f.name in scalars:
            value = scalars.pop(f.name)
            if f.name == "missing_steps":
                value = tuple(value)
            kwargs[f.name] = value
    try:
        return Sweep(**kwargs)
    except TypeError as exc:
        raise RecordingError(f"{path}: {key} is incomplete: {exc}") from None
