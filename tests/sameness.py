"""Recorded check that a change alters no CLI output and no bundled map (issue 14).

Runs every command that prints results, with fixed seeds and small settings, and writes one
normalised record: text and ``--json`` output, exit status, the JSON/CSV files written (with
compute-time fields masked) and the SHA-256 of every map (``map.pgm``, ``map.yaml``, PNG,
GIF, ``sweeps.npz``) of every bundled scenario. Two records of the same code are identical;
``diff`` shows what a change moved.

    python tests/sameness.py check main            # record main and the working tree, diff
    python tests/sameness.py record out/same-a     # the code on this interpreter's path
    python tests/sameness.py diff out/same-a out/same-b

``check REF`` extracts REF with ``git archive`` and reuses this tree's compiled kernels when
REF's ``.pyx`` files are the same (otherwise it builds them, which needs Cython). Takes about
a minute on 2 cores. Not a pytest test: it needs a second version of the code to compare with.
"""

from __future__ import annotations

import argparse
import csv
import difflib
import hashlib
import io
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# Keys whose value is this machine's time or memory (JSON and CSV), never a result.
TIMING_KEY = re.compile(r"^(compute.*|ms|.*_ms(_.*)?|run_s|wall_s|worker_peak_mb|front_cpu_.*"
                        r"|machine|irring_version|sweeps_per_s|realtime_factor"
                        r"|ray_vs_raw_ratio|targets"
                        r"|physics_s|check_s|halving_s|check_ratio|halving_ratio)$")
#                         (the last five: bench dynamics' check_cost, seconds and their ratios)
# Paths a run makes up: its temporary work folder and the calibration progress file kept in
# $TMPDIR (calibrate's resume hint names both).
MADE_UP_PATHS = ((re.compile(r"\S*/sameness-[^/\s]+/"), "<work>/"),
                 (re.compile(r"\S*/irring-calibrate-[^/\s]*\.yaml"),
                  "<tmp>/irring-calibrate-<x>.yaml"))
KEEP_KEY = re.compile(r"^(settle_ms)$")   # a knob spelt like a timing
# Charts whose axes include compute time; their bytes differ from run to run.
TIMED_CHARTS = {"accuracy.png", "compare.png"}
HASHED = (".pgm", ".png", ".gif", ".npz", ".yaml")

STUDY = """designs: [rotating12, radial12]
scenarios: [t_room_cylinder]
seeds: [4]
knobs: {samples: [1, 2]}
"""

# (name, argv, files written to check); outputs go below the record's work folder.
COMMON = [
    ("run", ["run", "t_room_cylinder", "--seed", "3", "--out", "o/run"], "o/run"),
    ("run --json", ["run", "t_room_cylinder", "--seed", "3", "--out", "o/runj", "--json",
                    "--no-animation"], "o/runj"),
    ("replay", ["replay", "o/run/sweeps.npz", "--out", "o/rep", "--no-animation"], "o/rep"),
    ("replay --json", ["replay", "o/run/sweeps.npz", "--out", "o/repj", "--json",
                       "--no-animation"], None),
    ("calibrate", ["calibrate", "--out", "o/cal.yaml", "--sweeps", "2", "--seed", "7"],
     "o/cal.yaml"),
    ("calibrate t_room_cylinder", ["calibrate", "--scenario", "t_room_cylinder", "--out",
                                   "o/cal2.yaml", "--sweeps", "1"], "o/cal2.yaml"),
    ("run --calibration", ["run", "t_room", "--calibration", "o/cal.yaml", "--out", "o/runc",
                           "--json", "--no-animation"], "o/runc"),
    ("replay --calibration", ["replay", "o/run/sweeps.npz", "--calibration", "o/cal.yaml",
                              "--out", "o/repc", "--json", "--no-animation"], "o/repc"),
    ("geometry", ["geometry", "--design", "all", "--samples", "2000"], None),
    ("geometry --json", ["geometry", "--design", "all", "--samples", "2000", "--json"], None),
    ("compare", ["compare", "--scenario", "t_room_cylinder", "--design", "rotating12",
                 "--design", "sonar12", "--design", "laser", "--seeds", "1", "--bearings", "8",
                 "--distances-mm", "350,550", "--workers", "1", "--out", "o/cmp"], "o/cmp"),
    ("compare --json", ["compare", "--scenario", "t_room", "--design", "radial12",
                        "--design", "rotating1", "--seeds", "2", "--bearings", "8",
                        "--distances-mm", "450", "--workers", "1", "--out", "o/cmpj",
                        "--json"], None),
    ("bench rooms", ["bench", "rooms", "box_room", "t_room_cylinder", "--out", "o/rooms"],
     "o/rooms"),
    ("bench rooms --json", ["bench", "rooms", "angled_walls", "--seeds", "2", "--out",
                            "o/roomsj", "--json"], None),
    ("bench accuracy", ["bench", "accuracy", "--scenario", "t_room_cylinder", "--knob",
                        "samples", "--knob", "iterations", "--knob", "settle", "--seeds", "1",
                        "--workers", "1", "--out", "o/acc"], "o/acc"),
    ("bench accuracy --json", ["bench", "accuracy", "--scenario", "t_room", "--knob",
                               "resolution", "--knob", "design", "--seeds", "1", "--workers",
                               "1", "--out", "o/accj", "--json"], None),
    ("bench estimator --json", ["bench", "estimator", "--scenario", "t_room_cylinder",
                                "--sweeps", "2", "--json"], None),
    ("bench estimator --rig --json", ["bench", "estimator", "--scenario", "t_room_cylinder",
                                      "--sweeps", "1", "--rig", "--json"], None),
    ("bench dynamics --json", ["bench", "dynamics", "--sweeps", "4", "--no-motion", "--json"],
     None),
    ("bench speed --json", ["bench", "speed", "--rounds", "2", "--json"], None),
    ("study", ["study", "tiny.yaml", "--out", "o/study", "--workers", "1"], "o/study"),
    ("study --json", ["study", "tiny.yaml", "--out", "o/studyj", "--workers", "1", "--json"],
     None),
]


def _mask(obj):
    if isinstance(obj, dict):
        return {k: ("<time>" if TIMING_KEY.match(k) and not KEEP_KEY.match(k) else _mask(v))
                for k, v in obj.items()}
    if isinstance(obj, list):
        return [_mask(v) for v in obj]
    return obj


def _ruler_spans(line: str) -> list[tuple[int, int]] | None:
    if not line.strip() or set(line.strip()) - {"-", " "} or "  " not in line.strip():
        return None
    return [(m.start(), m.end()) for m in re.finditer(r"-+", line)]


def normalise_text(text: str) -> str:
    """Table columns headed compute (and the cpu part of a front column) masked; timing
    phrases masked; runs of spaces collapsed (masking changes column widths)."""
    lines = text.splitlines()
    out = list(lines)
    for i, line in enumerate(lines):
        spans = _ruler_spans(line)
        if not spans or i == 0:
            continue
        header = lines[i - 1]
        masked = [(a, b, header[a:b].strip()) for a, b in spans]
        masked = [(a, b, h) for a, b, h in masked if "compute" in h or h == "front"]
        for j in range(i + 1, len(lines)):
            row = out[j]
            gaps = [(spans[k][1], spans[k + 1][0]) for k in range(len(spans) - 1)]
            if not row.strip() or _ruler_spans(row) or any(row[a:b].strip() for a, b in gaps):
                break   # the table ended: a row is blank between its columns
            for a, b, h in masked:
                cell = row[a:b]
                if h == "front":   # keep the hardware-time fronts, drop the compute ones
                    kept = [t for t in cell.split() if not t.startswith("cpu:") and t != "·"]
                    cell = " ".join(kept) or "·"
                else:
                    cell = "<time>"
                row = row[:a] + cell + row[b:]
            out[j] = row
    text = "\n".join(out)
    text = re.sub(r"compute [\d.]+ s \([^)]*\)", "compute <time>", text)
    text = re.sub(r"ran (\d+) in [\d.]+ s, [\d.]+ runs/s", r"ran \1 in <time>", text)
    text = re.sub(r"(\d+) runs in [\d.]+ s", r"\1 runs in <time>", text)
    return "\n".join("<ruler>" if _ruler_spans(ln) else re.sub(r" {2,}", " ", ln).rstrip()
                     for ln in text.splitlines())


def normalise_stdout(text: str) -> str:
    try:
        return json.dumps(_mask(json.loads(text)), indent=1, sort_keys=True)
    except ValueError:
        return normalise_text(text)


def normalise_csv(text: str) -> str:
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        return ""
    head = rows[0]
    timed = {i for i, k in enumerate(head) if TIMING_KEY.match(k) and not KEEP_KEY.match(k)}
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    for r in rows:
        w.writerow(["<time>" if i in timed and r is not rows[0] else v for i, v in enumerate(r)])
    return buf.getvalue()


def collect_files(path: Path) -> dict[str, dict]:
    """What a command wrote: JSON/CSV text (normalised when compared), else a SHA-256."""
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    out = {}
    for f in files:
        if f.name.endswith((".json", ".csv")):
            out[f.name] = {"text": f.read_text()}
        else:
            out[f.name] = {"sha256": hashlib.sha256(f.read_bytes()).hexdigest()}
    return out


def describe_files(files: dict[str, dict]) -> list[str]:
    out = []
    for name, f in files.items():
        if name.endswith(".json"):
            out.append(f"--- {name}\n" + json.dumps(_mask(json.loads(f["text"])), indent=1,
                                                    sort_keys=True))
        elif name.endswith(".csv"):
            out.append(f"--- {name}\n" + normalise_csv(f["text"]))
        elif name in TIMED_CHARTS:
            out.append(f"--- {name}: chart with compute time, not compared")
        elif name.endswith(HASHED):
            out.append(f"--- {name} sha256 {f['sha256']}")
        else:
            out.append(f"--- {name}: not compared")
    return out


def _bundled(tree: Path) -> list[str]:
    return sorted(p.stem for p in (tree / "scenarios").glob("*.yaml"))


def _irring(tree: Path, work: Path, argv: list[str], stdin: str | None = None,
            timeout: float = 600) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(tree), "IRRING_DEBUG": "", "CI": "true"}
    return subprocess.run([sys.executable, "-m", "irring", *argv], cwd=work, env=env,
                          input=stdin, capture_output=True, text=True, timeout=timeout)


def _emulated_calibration(tree: Path, work: Path) -> subprocess.CompletedProcess:
    """``irring calibrate --port`` against ``irring emulate`` (every prompt answered Enter)."""
    link = work / "link"
    env = {**os.environ, "PYTHONPATH": str(tree), "CI": "true"}
    emu = subprocess.Popen([sys.executable, "-m", "irring", "emulate", "t_room", "--link",
                            str(link), "--seed", "5", "--quiet"], cwd=work, env=env,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        for _ in range(200):
            if link.exists():
                break
            subprocess.run(["sleep", "0.05"])
        return _irring(tree, work, ["calibrate", "--port", str(link), "--out",
                                    "o/cal_emu.yaml", "--sweeps", "1"], stdin="\n" * 100,
                       timeout=120)
    finally:
        emu.terminate()
        emu.wait(10)


def record(tree: Path, dest: Path) -> Path:
    """Run every command with the code in ``tree``; write what they printed and wrote to
    ``dest/record.json`` (raw: masking happens when records are compared) and the
    normalised text to ``dest/record.txt``."""
    dest.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="sameness-"))
    (work / "tiny.yaml").write_text(STUDY)
    runs = []
    commands = list(COMMON) + [
        (f"run {name} (bundled map)", ["run", name, "--out", f"o/maps/{name}", "--json",
                                       "--no-animation"], f"o/maps/{name}")
        for name in _bundled(tree)]
    try:
        for name, argv, written in commands:
            print(f"  {name}", file=sys.stderr, flush=True)
            runs.append(_run_record(name, argv, _irring(tree, work, argv), work, written))
        p = _emulated_calibration(tree, work)
        runs.append(_run_record("calibrate --port (emulator)", ["calibrate", "--port"], p,
                                work, "o/cal_emu.yaml"))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    (dest / "record.json").write_text(json.dumps({"tree": str(tree), "runs": runs}, indent=1))
    (dest / "record.txt").write_text(normalise_record(_load(dest)))
    return dest


def _load(dest: Path) -> list[dict]:
    """A record's runs, the source tree's path (bundled scenarios name it) as <tree>."""
    raw = json.loads((dest / "record.json").read_text())
    text = json.dumps(raw["runs"]).replace(raw["tree"], "<tree>")
    return json.loads(text)


def _run_record(name, argv, p, work, written) -> dict:
    return {"name": name, "argv": argv, "exit": p.returncode, "stdout": p.stdout,
            "stderr": p.stderr,
            "files": collect_files(work / written) if written and (work / written).exists()
            else {}}


def normalise_record(runs: list[dict]) -> str:
    sections = []
    for r in runs:
        body = [f"### {r['name']}: irring {' '.join(r['argv'])}", f"exit {r['exit']}",
                normalise_stdout(r["stdout"])]
        if r["stderr"].strip():   # a warning names the file and line it came from: code moves
            err = re.sub(r"\S*/irring/(\S+\.py):\d+:", r"irring/\1:<line>:", r["stderr"])
            for made_up, mask in MADE_UP_PATHS:
                err = made_up.sub(mask, err)
            body.append("stderr: " + normalise_text(_strip_progress(err)))
        body.extend(describe_files(r["files"]))
        sections.append("\n".join(body))
    return "\n".join(sections) + "\n"


def _strip_progress(text: str) -> str:
    # tqdm bars (they only appear on a terminal, but be safe) carry rates and ETAs
    return "\n".join(ln for ln in text.replace("\r", "\n").splitlines()
                     if not re.search(r"\d+/\d+ \[|it/s|s/it", ln))


def diff(a: Path, b: Path) -> int:
    """Print the differences of two records (masked as :func:`normalise_record` says);
    0 when they are the same."""
    la, lb = (normalise_record(_load(d)).splitlines() for d in (a, b))
    lines = list(difflib.unified_diff(la, lb, str(a), str(b), lineterm="", n=2))
    if lines:
        print("\n".join(lines))
        return 1
    print(f"same: {len(la)} lines, {sum(ln.startswith('### ') for ln in la)} commands")
    return 0


def extract(ref: str, into: Path) -> Path:
    """REF's tree in ``into``, its kernels built or copied from this tree's."""
    into.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", ref], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    same = all((into / p.relative_to(ROOT)).exists()
               and (into / p.relative_to(ROOT)).read_bytes() == p.read_bytes()
               for p in ROOT.glob("irring/**/*.pyx"))
    built = list(ROOT.glob("irring/**/*.so"))
    if same and built:
        for so in built:
            shutil.copy2(so, into / so.relative_to(ROOT))
    else:
        subprocess.run([sys.executable, "-c", "from setuptools import setup; setup()",
                        "build_ext", "--inplace", "-q"], cwd=into, check=True)
    return into


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record", help="record the outputs of the code in --tree")
    r.add_argument("dest", type=Path)
    r.add_argument("--tree", type=Path, default=ROOT, help="source tree (default: this one)")
    d = sub.add_parser("diff", help="compare two records")
    d.add_argument("a", type=Path)
    d.add_argument("b", type=Path)
    c = sub.add_parser("check", help="record REF and this tree, then diff")
    c.add_argument("ref")
    c.add_argument("--keep", type=Path, help="keep the records here")
    args = ap.parse_args(argv)
    if args.cmd == "record":
        print(record(args.tree.resolve(), args.dest))
        return 0
    if args.cmd == "diff":
        return diff(args.a, args.b)
    tmp = Path(tempfile.mkdtemp(prefix="sameness-check-"))
    try:
        keep = args.keep or tmp / "records"
        base = extract(args.ref, tmp / "ref")
        print(f"recording {args.ref}", file=sys.stderr)
        a = record(base, keep / "ref")
        print("recording the working tree", file=sys.stderr)
        b = record(ROOT, keep / "tree")
        return diff(a, b)
    finally:   # the records live in --keep when given, else in tmp
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
