"""`irring replay RECORDING`: estimate and map recorded sweeps again."""

from __future__ import annotations

import argparse
from pathlib import Path

from .. import pipeline
from ..errors import UsageError
from ..outputs import REPLAY_SUFFIX, RUN_FILES, check_out, folder_name, folder_note, real_path
from ._common import add_mcap_option, describe, given, mcap_beside_outputs, out_path, spare_inputs
from .run import report

HELP = """\
Run recorded sweeps (a sweeps.npz from `irring run` or `irring drive`, simulated or from the
real ring) through the estimator and mapper again, on the grid they were first mapped on.
With the recorded calibration (`irring run` records the scene's; none: the datasheet curve,
or for an older simulated recording the recorded scene's) the map is identical to the
original run's; pass --calibration to see what another calibration makes of the same counts.
Scores are computed when the recording carries its scenario (simulated runs do);
one this irring cannot read (from another version) is named, and the map not scored.

Writes into --out the same files as `irring run`: map.png, map_building.gif, map.pgm +
map.yaml (ROS map_server), and sweeps.npz. Default: ./out/<run>-replay, where <run> is the
folder of a sweeps.npz (out/t_room/sweeps.npz → out/t_room-replay), else the file's own
name (lab.npz → out/lab-replay); a name of other than lower-case letters, digits and ._-
gets ~ and 8 hex digits of its SHA-256 (My Lab.npz → out/My_Lab~8c23cccc-replay), so two
runs never share a replay folder, nor a replay a run's.

examples:
  irring replay out/t_room/sweeps.npz
  irring replay out/t_room/sweeps.npz --calibration my_ring.yaml --out out/recal
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, HELP)
    p.add_argument("recording", type=given("a sweeps .npz recording", Path), metavar="RECORDING",
                   help="a sweeps .npz written by `irring run` or `irring drive`")
    p.add_argument("--calibration", type=given("a calibration file", Path), default=None,
                   metavar="FILE",
                   help="calibration YAML to use instead of the recorded one")
    p.add_argument("--out", type=out_path, default=None, metavar="DIR",
                   help="output folder (default: ./out/<run>-replay, <run> as above)")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("--no-animation", action="store_true", help="skip the GIF")
    add_mcap_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.out is not None:
        out = args.out
    else:
        stem = real_path(args.recording).parent.name if args.recording.stem == "sweeps" \
            else args.recording.stem
        out = Path("out") / f"{folder_name(stem, 'recording')}{REPLAY_SUFFIX}"
    spare_inputs({"--mcap": args.mcap}, {"RECORDING": args.recording,
                                         "--calibration": args.calibration})
    if real_path(out) == real_path(args.recording).parent:
        # the new set would replace the recording (and its calibration, with --calibration)
        # and remove the files of a run this one does not write: a drive's link.json
        raise UsageError(f"--out {out}: holds the recording being replayed ({args.recording}); "
                         "its outputs would replace it, so choose another folder (default: "
                         "out/<recording folder>-replay)")
    check_out(out, held=False, files=RUN_FILES)
    mcap_beside_outputs(args.mcap, out)
    frames = 0 if args.no_animation else pipeline.FRAMES_PER_SWEEP
    result = pipeline.replay(args.recording, calibration_file=args.calibration,
                             frames_per_sweep=frames)
    paths = pipeline.write_outputs(result, out, animation=not args.no_animation,
                                   mcap=args.mcap)
    report(result, paths, as_json=args.json)
    note = None if args.out is not None or args.json else folder_note(
        stem, out, "the replay of", REPLAY_SUFFIX)
    if note:
        print(f"  note      {note}")
    return 0
