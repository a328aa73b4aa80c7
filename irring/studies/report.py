"""The files a study writes (JSON, CSV tables, a chart, all together), the mean its
tables show, the load-average line every benchmark prints and a process's peak memory."""

from __future__ import annotations

import csv
import json
import os

try:
    import resource
except ImportError:  # pragma: no cover - not on POSIX
    resource = None

import numpy as np

from ..outputs import OutputSet


def mean_of(values) -> float | None:
    """Mean of the values that are not None (None when there are none)."""
    vals = [v for v in values if v is not None]
    return float(np.mean(vals)) if vals else None


def load_average() -> list[float]:
    """The machine's load average over 1, 5 and 15 minutes (``os.getloadavg``): a
    benchmark records it before and after, since a busy machine slows every timing."""
    return list(os.getloadavg())


def peak_memory_mb() -> float:
    """This process's peak resident memory (MB) since it started its program: Linux's
    ``VmHWM``, not ``ru_maxrss``, which a process started by a big one (a test session of
    1 GB) inherits through exec; ``ru_maxrss`` elsewhere, NaN without either."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0   # kB
    except (OSError, ValueError, IndexError):
        pass
    if resource is None:  # pragma: no cover - not on POSIX
        return float("nan")
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0   # KiB on Linux


def load_line(before, after, cpus: int | None = None) -> str:
    """The line a benchmark prints about how busy the machine was (``load_average()``
    before and after its work)."""
    cpus = os.cpu_count() if cpus is None else cpus
    return ("load average (1, 5, 15 min) before {} and after {}; with more than {} busy the "
            "figures are slower than the machine".format(
                " ".join(f"{v:.2f}" for v in before), " ".join(f"{v:.2f}" for v in after), cpus))


def write_csv(path, rows: list[dict], keys) -> None:
    """``rows`` as CSV with the columns ``keys`` (a missing or None value: an empty cell)."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for r in rows:
            w.writerow(["" if r.get(k) is None else r.get(k) for k in keys])


def study_files(name: str) -> tuple[str, ...]:
    """The files :func:`write_study` may write for the study ``name``."""
    return f"{name}.json", f"{name}.csv", "runs.csv", f"{name}.png"


def write_study(out_dir, name: str, result: dict, rows: list[dict], keys, draw) -> dict[str, str]:
    """A study's files in ``out_dir``, all together (:class:`irring.outputs.OutputSet`: a
    failed or interrupted write leaves the folder as it was): <name>.json (all of
    ``result``), <name>.csv (``rows`` with columns ``keys``), runs.csv (``result["runs"]``,
    if any) and <name>.png (``draw(result, path)``). Raises ``OutputError``."""
    target = OutputSet(out_dir, files=study_files(name))
    with target as tmp:
        paths = dict(zip(("json", "csv", "runs_csv", "chart"),
                         (tmp / f for f in study_files(name))))
        paths["json"].write_text(json.dumps(result, indent=2))
        write_csv(paths["csv"], rows, keys)
        if result["runs"]:
            write_csv(paths["runs_csv"], result["runs"], list(result["runs"][0]))
        else:
            del paths["runs_csv"]
        draw(result, paths["chart"])
    return {k: str(target.out / p.name) for k, p in paths.items()}
