"""The hostile-input corpus behind the README's table (issue 15): run it, count outcomes.

    python tests/hostile_corpus.py            # prints the markdown table (~2 min on 2 cores)
    python tests/hostile_corpus.py --list     # every input and its outcome
    python tests/hostile_corpus.py --kind=serial   # one kind (substring of its name)

Each input is handed to the `irring` command in a fresh process (so a hang is a hang: 60 s
limit) inside an empty folder, with --out pointing into it. Outcomes: *clear error* (exit
1-5, the last stderr line `irring …: error: …` or argparse's, no traceback), *handled*
(exit 0, the outputs complete), *traceback* (a Python traceback or exit 70), *hang*, and
*escaped* (a file written outside --out). tests/test_hostile.py asserts the same behaviour
per kind with hypothesis; this script is the census.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import threading
from collections import Counter, defaultdict
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import yaml

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
REPO = HERE.parent
PY = sys.executable
T_ROOM = (REPO / "scenarios" / "t_room.yaml").read_text()
LIMIT_S = 60


def scenario(**changes) -> str:
    raw = yaml.safe_load(T_ROOM)
    for key, value in changes.items():
        node = raw
        *parents, last = key.split(".")
        for k in parents:
            node = node.setdefault(k, {})
        node[last] = value
    return yaml.safe_dump(raw, allow_unicode=True)


BOMB = 'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n' + "".join(
    f"{c}: &{c} [{','.join(['*' + p] * 9)}]\n" for p, c in zip("abcdefgh", "bcdefghi"))

SCENARIOS = {
    "duplicate key": T_ROOM + "\nseed: 5\nseed: 6\n",
    "alias bomb (billion laughs)": BOMB,
    "anchors and aliases": "x: &r {outline_mm: [[0,0],[1,0],[1,1]]}\n" + T_ROOM.replace(
        "room:", "room_unused:", 1) + "room: *r\n",
    "10,000-deep list": "[" * 10_000 + "]" * 10_000,
    "10,000-deep mapping": "a: {" * 10_000 + "}" * 10_000,
    "non-UTF-8 bytes": "name: K\xfcche\n".encode("latin-1") + T_ROOM.encode(),
    "binary garbage": bytes(range(256)) * 4,
    "empty file": "",
    "comment only": "# nothing\n",
    "top-level list": "- 1\n- 2\n",
    "top-level number": "42\n",
    "python object tag": "!!python/object/apply:os.system ['echo hi']\n",
    "control character": "name: a\x01b\n",
    "NaN radius": scenario(**{"robot.ring": {"radius_mm": float("nan")}}),
    "infinite wall height": T_ROOM.replace("room:", "room:\n  wall_height_mm: .inf", 1),
    "huge integer seed": scenario(seed=2 ** 80),
    "negative seed": scenario(seed=-1),
    "bool as number": scenario(**{"scan.step_stride": True}),
    "string as number": scenario(**{"scan.step_stride": "two"}),
    "unknown key": scenario(colour="red"),
    "unknown effect": scenario(effects={"glitter": {}}),
    "effects: [{noise: {}}]": scenario(effects=[{"noise": {}}]),
    "effects: [{noise: {}, beam: {}}]": scenario(effects=[{"noise": {}, "beam": {}}]),
    "motion: {path: []}": scenario(effects={"motion": {"path": []}}),
    "scan.samples without averaging": scenario(**{"scan.samples": 4}),
    "two-corner room": scenario(**{"room.outline_mm": [[0, 0], [1000, 0]]}),
    "self-crossing room": scenario(**{"room.outline_mm": [[0, 0], [2000, 2000], [2000, 0],
                                                          [0, 2000]]}),
    "pose outside the room": scenario(**{"robot.poses": [{"x_mm": -500, "y_mm": 300}]}),
    "no poses": scenario(**{"robot.poses": []}),
    "100 m × 100 m room at 10 mm": scenario(**{
        "room.outline_mm": [[0, 0], [100_000, 0], [100_000, 100_000], [0, 100_000]]}),
    "resolution 0.001 mm": scenario(**{"map.resolution_mm": 0.001}),
    "name '/abs/path'": scenario(name="/tmp/irring-escape"),
    "name '..'": scenario(name=".."),
    "name ''": scenario(name=""),
    "name with escape codes": scenario(name="\x1b]0;pwned\x07\x1b[2J"),
    "name with path and spaces": scenario(name="../a b/../../c"),
    "name 10,000 characters": scenario(name="n" * 10_000),
    "a folder as the scenario": None,  # the folder itself (see make_case)
}


def _recording(tmp: Path) -> bytes:
    from test_hostile import _sweep

    from irring.recording import save_recording

    path = tmp / "good.npz"
    save_recording(path, [_sweep(np.random.default_rng(3))], {"seed": 3})
    return path.read_bytes()


def _rewrite(data: bytes, member: str, array) -> bytes:
    from test_hostile import _rewrite as rw

    return rw(data, member, array)


def _scalars(data: bytes, **changes) -> bytes:
    from test_hostile import _scalars as sc

    return sc(data, **changes)


def recordings(good: bytes) -> dict:
    meta = lambda m: _rewrite(good, "meta", np.array(json.dumps(m)))  # noqa: E731
    flipped = bytearray(good)
    flipped[len(flipped) // 3] ^= 0x55
    return {
        "truncated": good[: len(good) // 2],
        "bit-flipped": bytes(flipped),
        "empty file": b"",
        "not a zip": b"hello",
        "object array": _rewrite(good, "sweep000/counts", np.array([object()], dtype=object)),
        "missing counts": _rewrite(good, "sweep000/counts", np.zeros(0)),
        "sensors: 0": _scalars(good, ring={"sensors": 0}),
        "negative counts": _rewrite(good, "sweep000/counts", -np.ones((5, 4), int)),
        "boolean counts": _rewrite(good, "sweep000/counts", np.ones((5, 4), bool)),
        "complex counts": _rewrite(good, "sweep000/counts", np.ones((5, 4), complex)),
        "counts of the wrong shape": _rewrite(good, "sweep000/counts", np.ones((5, 3), int)),
        "NaN angles": _rewrite(good, "sweep000/sensor_angles", np.full((5, 4), np.nan)),
        "adc_bits 0": _scalars(good, adc_bits=0),
        "adc_bits 64": _scalars(good, adc_bits=64),
        "NaN max_range_m": _scalars(good, max_range_m=float("nan")),
        "unknown sensor_model": _scalars(good, sensor_model="gp2zz"),
        "grid 200000²": meta({"grid": {"origin_xy_m": [0, 0], "shape": [200000, 200000],
                                       "resolution_m": 0.01}}),
        "meta not JSON": _rewrite(good, "meta", np.array("{nope")),
        "meta 100,000-deep JSON": _rewrite(good, "meta", np.array("[" * 100_000)),
        "embedded scenario alias bomb": meta({"scenario_yaml": BOMB}),
        "embedded scenario duplicate key": meta({"scenario_yaml": T_ROOM + "seed: 1\nseed: 2\n"}),
        "embedded calibration bad": meta({"calibration_yaml": "irring_calibration: 1\n"}),
        "wrong format version": _rewrite(good, "format", np.array("irring-recording/99")),
        "valid (control)": good,
    }


def calibrations() -> dict:
    from irring.estimation.calibration import Calibration
    from irring.scenario import loads

    base = Calibration.for_scene(loads(T_ROOM, "t_room.yaml")).to_dict()

    def cal(**changes) -> str:
        raw = json.loads(json.dumps(base))
        raw.update(changes)
        return yaml.safe_dump(raw)

    rising = json.loads(json.dumps(base))
    for row in rising["curve"]:
        row["b"] = -row["b"]
    return {
        "vref_v 0": cal(vref_v=0), "vref_v NaN": cal(vref_v=float("nan")),
        "vref_v inf": cal(vref_v=float("inf")), "vref_v -5": cal(vref_v=-5),
        "unknown sensor_model": cal(sensor_model="anything"),
        "rising curve": yaml.safe_dump(rising),
        "alias bomb in source": BOMB.replace("a:", "source:", 1),
        "duplicate key": cal() + "vref_v: 3.3\n",
        "missing curve": cal(curve=None),
        "non-UTF-8": b"source: K\xfcche\n" + cal().encode(),
        "a folder": None,
        "valid (control)": cal(),
    }


OPTIONS = {
    "drive --timeout 0": ["drive", "--port", "loop://", "--timeout", "0"],
    "drive --timeout nan": ["drive", "--port", "loop://", "--timeout", "nan"],
    "drive --samples 65": ["drive", "--port", "loop://", "--samples", "65"],
    "drive --pose nan,nan": ["drive", "--port", "loop://", "--pose", "nan,nan"],
    "drive --baud -5": ["drive", "--port", "loop://", "--baud", "-5"],
    "drive --port nowhere": ["drive", "--port", "/dev/irring-none"],
    "emulate --baud -100": ["emulate", "--baud", "-100"],
    "emulate --tcp 127.0.0.1:99999": ["emulate", "--tcp", "127.0.0.1:99999"],
    "emulate --link a regular file": ["emulate", "--link", "REGULAR"],
    "run --out a file": ["run", "t_room", "--out", "REGULAR"],
    "run --out under a file": ["run", "t_room", "--out", "REGULAR/sub"],
    "run --seed abc": ["run", "--seed", "abc"],
    "calibrate --out a folder": ["calibrate", "--out", "DIR"],
    "replay no such file": ["replay", "nothing.npz"],
}


def devices() -> dict:
    import hostile_devices as hd

    return {
        "silent": hd.silent, "silent after IRINF": hd.silent_after_hello,
        "disconnects mid-sweep": hd.disconnect_on_sweep, "endless IRPOS": hd.flood_irpos,
        "repeated IRSCN": hd.repeat_irscn, "a sentence every 0.25 s":
            hd.sentence_every_quarter_second, "IRDON without steps": hd.done_without_steps,
        "wrong sensor count": hd.wrong_sensor_count, "IRERR 3": hd.error_reply(3),
        "IRERR 4": hd.error_reply(4), "IRERR 5": hd.error_reply(5),
        "4096 sensors": hd.announces(sensors=4096), "32-bit ADC": hd.announces(bits=32),
        "±2³¹ steps": hd.announces(lo=-2 ** 31 + 1, hi=2 ** 31 - 1),
        "trickle (1 byte/ms)": hd.trickle, "out of order": hd.out_of_order,
        "good (control)": hd.good,
    }


# --------------------------------------------------------------------------- running


def run_case(argv: list[str], cwd: Path, device=None) -> tuple[str, str]:
    """(outcome, last stderr line) of `irring *argv` in ``cwd``."""
    before = set(_tree(cwd))
    dev = None
    if device is not None:
        import hostile_devices as hd

        dev = hd.HostileDevice(device)
        argv = [a.replace("PORT", dev.link) for a in argv]
    env = {**os.environ, "CI": "true", "MPLBACKEND": "Agg"}
    try:
        done = subprocess.run([PY, "-m", "irring", *argv], cwd=cwd, capture_output=True,
                              text=True, timeout=LIMIT_S, env=env, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return "hang", ""
    finally:
        if dev is not None:
            dev.close()
    err = done.stderr.strip().splitlines()
    last = err[-1] if err else ""
    outs = ["out"] + [os.path.relpath(b, cwd) for a, b in zip(argv, argv[1:]) if a == "--out"]
    new = [p for p in set(_tree(cwd)) - before
           if not any(p == o or p.startswith(o + os.sep) for o in outs)]
    if new:
        return "escaped", f"wrote {sorted(new)[:3]}"
    if "Traceback" in done.stderr or done.returncode == 70:
        return "traceback", last
    if done.returncode == 0:
        return "handled", last
    if done.returncode in (1, 2, 3, 4, 5) and ("error" in last):
        return "clear error", last
    return f"exit {done.returncode}", last


def _tree(root: Path) -> list[str]:
    return [str(p.relative_to(root)) for p in root.rglob("*")]


def cases(tmp: Path) -> list[tuple[str, str, callable]]:
    out = []

    def case(kind, name, writer):
        out.append((kind, name, writer))

    for name, text in SCENARIOS.items():
        def w(d, text=text):
            if text is None:
                (d / "t_room").mkdir()
                return ["run", "t_room", "--out", "out/x", "--no-animation"]
            (d / "s.yaml").write_bytes(text if isinstance(text, bytes) else text.encode())
            return ["run", "s.yaml", "--no-animation", *(["--out", "out/x"]
                                                         if "name" not in name else [])]
        case("scenario file", name, w)
    good = _recording(tmp)
    for name, data in recordings(good).items():
        def w(d, data=data):
            (d / "r.npz").write_bytes(data)
            return ["replay", "r.npz", "--out", "out/x", "--no-animation"]
        case("recording (.npz)", name, w)
    for name, text in calibrations().items():
        def w(d, text=text):
            if text is None:
                (d / "c.yaml").mkdir()
            else:
                (d / "c.yaml").write_bytes(text if isinstance(text, bytes) else text.encode())
            (d / "r.npz").write_bytes(good)
            return ["replay", "r.npz", "--calibration", "c.yaml", "--out", "out/x",
                    "--no-animation"]
        case("calibration file", name, w)
    for name, argv in OPTIONS.items():
        def w(d, argv=argv):
            (d / "REGULAR").write_text("keep")
            (d / "DIR").mkdir()
            return [a if a not in ("REGULAR", "DIR") else str(d / a) for a in argv] + (
                ["--out", "out/x"] if argv[0] in ("drive",) else [])
        case("command-line option", name, w)
    for name, behaviour in devices().items():
        def w(d):
            return ["drive", "--port", "PORT", "--timeout", "0.2", "--no-wait",
                    "--no-animation", "--out", "out/x"]
        case("serial device", name, (w, behaviour))
    return out


def main(argv: list[str]) -> int:
    if any(a in ("-h", "--help") for a in argv):
        print(__doc__)
        return 0
    unknown = [a for a in argv if a != "--list" and not a.startswith("--kind=")]
    if unknown:     # before the ~2 min census, not after it
        print(f"hostile_corpus.py: unknown argument {unknown[0]!r}; allowed: --list, "
              "--kind=NAME, --help", file=sys.stderr)
        return 2
    results = []
    lock = threading.Lock()
    with tempfile.TemporaryDirectory() as top:
        top = Path(top)
        kinds = [a.split("=", 1)[1] for a in argv if a.startswith("--kind=")]
        todo = [c for c in cases(top) if not kinds or any(k in c[0] for k in kinds)]

        def one(i_case):
            i, (kind, name, w) = i_case
            d = top / f"case{i:03d}"
            d.mkdir()
            writer, device = (w if isinstance(w, tuple) else (w, None))
            outcome, last = run_case(writer(d), d, device)
            with lock:
                results.append((kind, name, outcome, last))
                print(f"[{len(results)}/{len(todo)}] {kind}: {name}: {outcome}", file=sys.stderr,
                      flush=True)

        with ThreadPoolExecutor(max_workers=2) as pool:
            list(pool.map(one, enumerate(todo)))
    by_kind: dict[str, Counter] = defaultdict(Counter)
    for kind, name, outcome, last in results:
        by_kind[kind][outcome] += 1
    if "--list" in argv:
        for kind, name, outcome, last in sorted(results):
            print(f"{kind:20} | {name:36} | {outcome:11} | {last[:110]}")
        print()
    cols = ["clear error", "handled", "traceback", "hang", "escaped"]
    print("| kind | inputs | " + " | ".join(cols) + " |")
    print("|---|---|" + "---|" * len(cols))
    total = Counter()
    for kind, counts in by_kind.items():
        total.update(counts)
        print(f"| {kind} | {sum(counts.values())} | "
              + " | ".join(str(counts.get(c, 0)) for c in cols) + " |")
    print(f"| **all** | {sum(total.values())} | "
          + " | ".join(str(total.get(c, 0)) for c in cols) + " |")
    other = {k: v for k, v in total.items() if k not in cols}
    if other:
        print("other outcomes:", dict(other))
    return 0 if not (total["traceback"] or total["hang"] or total["escaped"] or other) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
