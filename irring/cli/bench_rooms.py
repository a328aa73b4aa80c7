"""`irring bench rooms`: map scores on a room set, with the scene's effects and an ideal sensor."""

from __future__ import annotations

import argparse
import csv
import json
import sys

from .. import errors
from ..outputs import OutputSet, check_out
from ..studies.rooms import ROOMS, TARGETS, measure, print_clip_notes, resolve_rooms
from ..core import score_text
from ._common import MAP_COLUMNS, add_room_set_options, describe

EPILOG = f"""\
what it prints, per room, for the scene as written ("effects": the bundled rooms have
incidence, 15 mV noise and quantization) and for an ideal sensor ("ideal": the same scene
without any sensor-signal effect and with exact odometry; belt, timing and the drive are
kept):
  F1, prec, rec   occupied F1, precision, recall (1-cell tolerance, see `irring run --help`)
  free            free accuracy: share of the cells mapped free that are really free
  cov             coverage: share of the reachable free floor mapped free
  shadow          wall behind thin obstacles mapped (n/a: no wall hidden from every pose)
  pt mm           end-point RMS: estimated end point to the true hit point, over readings
                  both estimators call valid
  θ=0 mm          the same readings read as if square on (Eq. 10 with a(0), b(0))
  misses          targets missed by the scene's run: F1 ≥ {TARGETS['occupied_f1']:.2f}, precision ≥ {TARGETS['occupied_precision']:.2f}, free
                  accuracy ≥ {TARGETS['free_accuracy']:.2f}, set for the default effects (a scene with more, e.g. a
                  moving robot's odometry drift, names them: "(with motion, …)");
                  "ideal<" lists scores where the ideal sensor is worse
                  (both maps judged on the scene's truth: the wall its sensor returns from)
  n/a             nothing to score: no wall within reach (F1, precision, recall), no cell
                  mapped free (free); never counted as a miss or a loss

Figures are means over --seeds seeds (the first is the scenario's own seed + 0).
A room file that cannot be loaded or run is listed with its error and the others are scored;
the command then ends with that error's exit status (1 for a bad file). Rooms of one name
(from two folders) are shown with their files; rooms.csv's source column names each file.

exit status: 0 when every room was scored and holds its targets; {errors.TARGET_MISSED} when a room
misses a target set for its effects or the ideal sensor is worse somewhere (the table's
misses column says which); a misses entry marked "(with …)" is shown, not counted.

examples:
  irring bench rooms                          the room set (scenarios/) and the T-rooms
  irring bench rooms my_rooms/ other.yaml     rooms of your own: folders of *.yaml or files
  irring bench rooms --seeds 3 --json > rooms.json
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Run every room of a set through `irring run`'s path (simulate, estimate, "
             "map, score), once with the scene's effects and once with an ideal sensor, "
             "and print per room occupied F1, precision, recall, free accuracy, "
             "coverage, shadow and the end points' RMS error beside θ = 0's.",
             EPILOG)
    add_room_set_options(p, "the room set and the T-rooms", 1, "out/bench_rooms", "rooms.json and rooms.csv go")
    p.set_defaults(func=run)


COLUMNS = MAP_COLUMNS + (("coverage", "cov", 1, 3), ("shadow", "shadow", 1, 2),
                         ("point_rms_m", "pt mm", 1e3, 1),
                         ("point_rms_theta0_m", "θ=0 mm", 1e3, 1))


OUTPUT_FILES = ("rooms.json", "rooms.csv")


def run(args: argparse.Namespace) -> int:
    scenarios = resolve_rooms(args.rooms or ROOMS)
    out = check_out(args.out, held=False, files=OUTPUT_FILES)
    rows = measure(scenarios, args.seeds, debug=args.debug)
    failed = [r for r in rows if "error" in r]
    with OutputSet(out, files=OUTPUT_FILES) as tmp:
        (tmp / "rooms.json").write_text(json.dumps(rows, indent=2))
        with open(tmp / "rooms.csv", "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            keys = [c[0] for c in COLUMNS]
            w.writerow(["room", "source", "sensor", *keys, "error"])
            for r in rows:
                if "error" in r:
                    w.writerow([r["name"], r["source"], "", *("" for _ in keys), r["error"]])
                    continue
                for variant in ("effects", "ideal"):
                    w.writerow([r["name"], r["source"], variant,
                                *(r[variant][k] for k in keys), ""])
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        _print_table(rows, args.seeds, out)
    if failed:  # the table has the rest; the status says that not every room was scored
        first = failed[0]
        print(f"irring bench rooms: error: {len(failed)} of {len(rows)} room(s) not scored; "
              f"{first['error']}", file=sys.stderr)
        return first["status"]
    return errors.TARGET_MISSED if any(_misses_target(r) for r in rows) else errors.OK


def _misses_target(row: dict) -> bool:
    """A scored room below a target its effects were set for, or with the ideal sensor worse."""
    return bool(row["ideal_worse"]) or bool(row["misses"] and not row["beyond_target_effects"])


def _labels(rows: list[dict]) -> list[str]:
    """Each room's name, with its file where another room has the same name."""
    names = [r["name"] for r in rows]
    return [f"{r['name']} ({errors.printable(str(r['source']))})" if names.count(r["name"]) > 1
            else r["name"] for r in rows]


def _print_table(rows: list[dict], seeds: int, out) -> None:
    labels = _labels(rows)
    width = max(len(label) for label in labels)
    head = "".join(f"{label:>8}" for _, label, _, _ in COLUMNS)
    print(f"{'room':<{width}}  {'sensor':<8}{head}  misses")
    for r, label in zip(rows, labels):
        if "error" in r:
            print(f"{label:<{width}}  error: {r['error']}")
            continue
        for variant in ("effects", "ideal"):
            vals = "".join(f"{score_text(r[variant][k], s, d):>8}" for k, _, s, d in COLUMNS)
            note = ""
            if variant == "effects":
                note = ", ".join(f"{k} {v:.3f}" for k, v in r["misses"].items())
                if note and r["beyond_target_effects"]:   # the targets assume the defaults
                    note += " (with " + ", ".join(r["beyond_target_effects"]) + ")"
                if r["ideal_worse"]:
                    note += ("; " if note else "") + "ideal< " + ", ".join(r["ideal_worse"])
            name = label if variant == "effects" else ""
            print(f"{name:<{width}}  {variant:<8}{vals}  {note}")
        print_clip_notes(r)
    scored = [r for r in rows if "error" not in r]
    n_miss = sum(bool(r["misses"]) and not r["beyond_target_effects"] for r in scored)
    n_beyond = sum(bool(r["misses"]) and bool(r["beyond_target_effects"]) for r in scored)
    n_worse = sum(bool(r["ideal_worse"]) for r in scored)
    n_failed = len(rows) - len(scored)
    failed = f"{n_failed} not scored (error), " if n_failed else ""
    # as the exit status counts: a room with more than the default effects is shown, not counted
    beyond = (f", {n_beyond} below one with effects beyond the defaults (shown, not counted)"
              if n_beyond else "")
    print(f"{len(rows)} room{'' if len(rows) == 1 else 's'}, {seeds} seed(s) each: {failed}"
          f"{n_miss} miss a target{beyond}, "
          f"{n_worse} where the ideal sensor is worse somewhere; wrote {errors.printable(str(out))}/rooms.json, rooms.csv")
