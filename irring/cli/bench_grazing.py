"""`irring bench grazing`: end-point error of walls met at grazing incidence, vs θ = 0."""

from __future__ import annotations

import argparse
import json
import sys

from .. import errors
from ..outputs import OutputSet, check_out
from ..studies.grazing import (BIN_DEG, GAIN_BAND_DEG, GAIN_TARGET, MAX_INCIDENCE_DEG,
                               RMS_TARGET_M, measure)
from ..studies.rooms import print_clip_notes, resolve_rooms
from ._common import add_room_set_options, describe

DEFAULT_ROOMS = ("grazing_corridor",)
_LO, _HI = GAIN_BAND_DEG

EPILOG = f"""\
what it prints: per room (each run as `irring run` runs it, with the scene's own effects),
over the readings both the estimator and θ = 0 call valid that hit a surface:
  n            readings compared
  RMS mm       end-point RMS: estimated end point to the true hit point
  θ=0 mm       the same readings read as if square on (Eq. 10 with a(0), b(0))
  {_LO}–{_HI}°       the same over readings whose true incidence lies in {_LO}–{_HI}°, and the gain
               (θ = 0's RMS over the estimator's)
then, pooled over all rooms and seeds, the same per {BIN_DEG}° bin of true incidence (with max
mm, the largest error) and over {_LO}–{_HI}°.
targets (pooled): every bin below {MAX_INCIDENCE_DEG}° has RMS ≤ {RMS_TARGET_M * 1e3:.0f} mm (an empty bin is no miss), and over
{_LO}–{_HI}° θ = 0's RMS is at least {GAIN_TARGET:g}× the estimator's (no reading there is a miss).

A room file that cannot be loaded or run is listed with its error and the others are pooled.
exit status: 0 when the targets hold; {errors.TARGET_MISSED} when one is missed (the last line says which);
that of the first room's error (1 for a bad file) when a room could not be run.

examples:
  irring bench grazing                          the bundled grazing room ({', '.join(DEFAULT_ROOMS)})
  irring bench grazing my_rooms/ --seeds 2      rooms of your own: folders of *.yaml or files
  irring bench grazing --json > grazing.json
"""

OUTPUT_FILES = ("grazing.json",)


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Run rooms whose walls are met at grazing incidence and print the end "
             f"points' RMS error per {BIN_DEG}° of true incidence beside θ = 0's, against "
             f"issue 13's targets: ≤ {RMS_TARGET_M * 1e3:.0f} mm up to {MAX_INCIDENCE_DEG}°, "
             f"≥ {GAIN_TARGET:g}× better than θ = 0 over {_LO}–{_HI}°.", EPILOG)
    add_room_set_options(p, ", ".join(DEFAULT_ROOMS), 2, "out/bench_grazing", "grazing.json goes")
    p.set_defaults(func=run)


def _mm(v, digits: int = 1) -> str:
    return "n/a" if v is None else f"{v * 1e3:.{digits}f}"


def _x(v) -> str:
    return "n/a" if v is None else f"{v:.1f}×"


def run(args: argparse.Namespace) -> int:
    scenarios = resolve_rooms(args.rooms or DEFAULT_ROOMS)
    out = check_out(args.out, held=False, files=OUTPUT_FILES)
    r = measure(scenarios, args.seeds, debug=args.debug)
    with OutputSet(out, files=OUTPUT_FILES) as tmp:
        (tmp / "grazing.json").write_text(json.dumps(r, indent=2))
    if args.json:
        print(json.dumps(r, indent=2))
    else:
        _print(r, args.seeds, out)
    failed = [row for row in r["rooms"] if "error" in row]
    if failed:
        print(f"irring bench grazing: error: {len(failed)} of {len(r['rooms'])} room(s) not "
              f"run; {failed[0]['error']}", file=sys.stderr)
        return failed[0]["status"]
    return errors.TARGET_MISSED if r["misses"] else errors.OK


def _print(r: dict, seeds: int, out) -> None:
    width = max([len(row["name"]) for row in r["rooms"]] + [6])
    band = f"{_LO}–{_HI}°"
    print(f"{'room':<{width}}  {'n':>6}{'RMS mm':>8}{'θ=0 mm':>8}   {band}: {'n':>5}"
          f"{'RMS mm':>8}{'θ=0 mm':>8}{'gain':>7}")
    for row in r["rooms"]:
        if "error" in row:
            print(f"{row['name']:<{width}}  error: {row['error']}")
            continue
        g = row["gain_band"]
        print(f"{row['name']:<{width}}  {row['n']:>6}{_mm(row['rms_m']):>8}"
              f"{_mm(row['rms_theta0_m']):>8}   {'':>{len(band) + 1}} {g['n']:>5}"
              f"{_mm(g['rms_m']):>8}{_mm(g['rms_theta0_m']):>8}{_x(g['gain']):>7}")
        print_clip_notes(row)
    print(f"pooled over {len(r['rooms'])} room(s), {seeds} seed(s) each: n {r['n']}, RMS "
          f"{_mm(r['rms_m'])} mm, θ = 0 {_mm(r['rms_theta0_m'])} mm")
    print(f"{'incidence':>10}{'n':>7}{'RMS mm':>8}{'θ=0 mm':>8}{'gain':>7}{'max mm':>8}  target")
    for b in r["bins"] + [r["gain_band"]]:
        pooled_band = (b["lo_deg"], b["hi_deg"]) == GAIN_BAND_DEG
        if pooled_band:
            target = f"gain ≥ {GAIN_TARGET:g}×"
        elif b["hi_deg"] <= MAX_INCIDENCE_DEG:
            target = f"RMS ≤ {RMS_TARGET_M * 1e3:.0f} mm"
        else:
            target = ""
        print(f"{b['lo_deg']:>4}–{b['hi_deg']:>2}°{b['n']:>8}{_mm(b['rms_m']):>8}"
              f"{_mm(b['rms_theta0_m']):>8}{_x(b['gain']):>7}{_mm(b['max_m'], 0):>8}  {target}".rstrip())
    verdict = "; ".join(r["misses"]) if r["misses"] else "every target met"
    print(f"{'MISSED: ' if r['misses'] else ''}{verdict}; wrote {errors.printable(str(out))}/grazing.json")
