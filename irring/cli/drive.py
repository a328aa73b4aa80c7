"""`irring drive --port PORT`: sweep the real ring, estimate and map like `irring run`."""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from .. import errors, pipeline
from ..core import MAX_SWEEPS, Pose, work_bytes, work_refusal
from ..errors import UsageError
from ..estimation.calibration import Calibration, CalibrationError, load_calibration
from ..hardware import DeviceError, SerialRing
from ..hardware.emulator import emulated_room, room_tag
from ..outputs import RUN_FILES, check_out
from ..recording import save_recording
from ..scenario import check_ring_placement, load_scenario
from ._common import (add_mcap_option, add_protocol_v1_option, at_least, between, describe, given,
                      mcap_beside_outputs, out_path, positive_seconds, scenario_name, serial_port,
                      spare_inputs, warn_protocol)
from .run import report

HELP = """\
Sweep the real ring (or `irring emulate`) over a serial port at one or more poses, then run
the readings through the same estimator and occupancy-grid mapper as `irring run`.

The ring must speak IRR protocol v2 (docs/protocol.md; a ring on v1 firmware is refused
with how to reflash it, or used with a warning under --accept-protocol-v1). The handshake
reads the protocol version, the sensor count,
ADC bits, motor step, belt ratio and step limits from the device; the ring radius and
emitter offset, which the device does not report, come from the paper (0.15 m, 7 mm), from
--calibration (its emitter offset d_o) or from --truth. Steps whose readings were lost on
the link are re-swept (--resweep) and, if still missing, left out and reported: no reading
is ever invented.

Writes into --out (default ./out/drive) the same files as `irring run` — map.png,
map_building.gif, map.pgm + map.yaml (ROS map_server), sweeps.npz (for `irring replay`) —
plus link.json (the protocol version and a per-sweep link report: missing steps, checksum
failures, seq gaps, timeouts).

Poses: with --truth the scenario's scan poses are used (and the map is scored against it,
from the poses swept); otherwise give each pose with --pose X_MM,Y_MM,YAW_DEG (default: one
pose at the origin).
Between poses drive waits for Enter when run at a terminal (--no-wait to skip); the emulator
moves its robot by itself at every full sweep. `irring emulate` names its room in its IRINF:
a --truth of another room is refused before any sweep (exit 2).

However it ends (done, an error, Ctrl-C, SIGTERM), drive stops a sweep still running (IRSTP)
and turns the ring back to step 0 (IRGTO,0): its firmware takes where the ring stands when it
starts for step 0, and an Arduino restarts each time its port is opened. A ring that does not
confirm it is named in a warning saying where it may stand (turn it radial by hand before
the next session); a drive cut short says where the ring stands in its last line.

Exit status: 0 all poses swept; 3 no device, or it stopped answering, disconnected, refused
a sweep, made no progress, or rebooted away from step 0, where it would take another step for
its step 0 (what arrived before is still mapped and written); 130 Ctrl-C, SIGTERM,
SIGHUP (the terminal closed) or the input ended at the prompt (the poses swept so far are
mapped and written); 2 bad arguments (or a --truth of another room than the emulator's);
1 a bad --truth or --calibration file.

examples:
  irring emulate t_room &                               # try it without hardware (ring.pty)
  irring drive --port ring.pty --truth t_room           # map + scores, same as `irring run`
  irring drive --port /dev/ttyUSB0 --calibration my_ring.yaml --pose 500,450,0 --pose 1210,450,0
  irring drive --port socket://ring.local:PORT --json   # a ring on the network
"""


def _pose(text: str) -> tuple[float, float, float]:
    try:
        parts = [float(v) for v in text.split(",")]
    except ValueError:
        parts = []
    if len(parts) not in (2, 3) or not all(math.isfinite(v) and abs(v) <= 1e6 for v in parts):
        raise argparse.ArgumentTypeError(f"{text!r}: expected X_MM,Y_MM[,YAW_DEG] as finite "
                                         f"numbers (|value| ≤ 1e6), e.g. 500,450,90")
    x, y, yaw = (parts + [0.0])[:3]
    return x / 1000.0, y / 1000.0, math.radians(yaw)


def register(p: argparse.ArgumentParser) -> None:
    describe(p, HELP)
    p.add_argument("--port", required=True, type=serial_port, metavar="PORT",
                   help="serial device or pyserial URL: /dev/ttyUSB0, COM3, a pty path, "
                        "socket://host:port, loop://")
    p.add_argument("--baud", type=between(1, 10_000_000), default=115200,
                   help="baud rate (default 115200)")
    add_protocol_v1_option(p)
    p.add_argument("--timeout", type=positive_seconds, default=1.0, metavar="S",
                   help="longest silence tolerated while an answer is due, on top of the "
                        "per-step time, in seconds (default 1.0); a silent device is given up "
                        "after about 4× this")
    p.add_argument("--calibration", type=given("a calibration file", Path), default=None,
                   metavar="FILE",
                   help="calibration YAML from `irring calibrate` (default: the sensor's "
                        "datasheet curve)")
    p.add_argument("--truth", default=None, metavar="SCENARIO", type=scenario_name,
                   help="scenario the ring is standing in (name or YAML): its poses, sensor "
                        "settings and room are used, and the map is scored against it")
    p.add_argument("--poses", type=between(1, MAX_SWEEPS), default=None, metavar="N",
                   help="number of poses to sweep (default: all of --truth's, or of --pose)")
    p.add_argument("--pose", type=_pose, action="append", default=None,
                   metavar="X_MM,Y_MM[,YAW_DEG]",
                   help="robot pose of the next sweep, repeatable (overrides --truth's; "
                        "the ring must fit --truth's room there, as a scan pose must)")
    p.add_argument("--samples", type=at_least(1, 64), default=None, metavar="N",
                   help="readings averaged per step by the device, 1 … 64 (default: --truth's "
                        "scan.samples with averaging, else 1)")
    p.add_argument("--settle-ms", type=at_least(0, 60_000), default=None, metavar="MS",
                   help="wait at each step before reading, 0 … 60000 ms (default: --truth's, "
                        "else 0)")
    p.add_argument("--resweep", type=between(0, 100), default=2, metavar="K",
                   help="rounds of re-sweeping only the missing steps (default 2; 0 = never)")
    p.add_argument("--out", type=out_path, default=Path("out") / "drive", metavar="DIR",
                   help="output folder (default: ./out/drive)")
    p.add_argument("--json", action="store_true",
                   help="print a JSON summary on stdout instead of the readable one")
    p.add_argument("--no-animation", action="store_true", help="skip the GIF")
    add_mcap_option(p)
    p.add_argument("--no-wait", action="store_true",
                   help="do not wait for Enter between poses")
    p.set_defaults(func=run)


def _differences(device, adc_bits: int, truth) -> list[str]:
    """What the device's IRINF says of its ring that ``truth``'s ring and sensor block do
    not (its emitter offset is --calibration's or the truth's, never the device's)."""
    t, name = truth.ring, truth.name
    out = []
    if device.sensors != t.sensors:
        out.append(f"{device.sensors} sensors ({name}'s: {t.sensors})")
    if (device.min_step, device.max_step) != (t.min_step, t.max_step):
        out.append(f"steps {device.min_step} … {device.max_step} ({name}'s: {t.min_step} … "
                   f"{t.max_step})")
    if device.motor_step_rad != t.motor_step_rad:
        out.append(f"a {math.degrees(device.motor_step_rad):g}° motor step ({name}'s: "
                   f"{math.degrees(t.motor_step_rad):g}°)")
    if device.gear != t.gear:
        out.append(f"gear {device.gear:g} ({name}'s: {t.gear:g})")
    if adc_bits != truth.sensor.adc_bits:
        out.append(f"a {adc_bits}-bit ADC ({name}'s: {truth.sensor.adc_bits}-bit)")
    return out


def _error(msg: str) -> int:
    print(f"irring drive: error: {errors.printable(msg, 2000)}", file=sys.stderr)
    return 2


def run(args: argparse.Namespace) -> int:
    spare_inputs({"--mcap": args.mcap}, {"--truth": args.truth,
                                         "--calibration": args.calibration})
    check_out(args.out, held=False, files=RUN_FILES)
    mcap_beside_outputs(args.mcap, args.out)
    truth = load_scenario(args.truth) if args.truth else None
    if truth is not None and truth.has("motion"):
        return _error(f"--truth {args.truth}: the scenario drives while scanning (`motion`), but "
                      "the IRR protocol reports no robot pose, so a moving scan cannot be mapped from the "
                      "link; map it with `irring run` instead")
    calibration, cal_text = load_calibration(args.calibration)   # a bad file: exit 1
    if truth is not None and calibration is not None and (
            calibration.sensor_model != truth.sensor.model
            or not math.isclose(calibration.vref_v, truth.sensor.vref_v, rel_tol=1e-9)):
        # the two files contradict each other on the ring's sensor (the ADC is the device's
        # to say, checked after the handshake); `irring run` refuses the same
        raise CalibrationError(
            f"{args.calibration}: the calibration is for a {calibration.sensor_model} at "
            f"{calibration.vref_v:g} V, but --truth {args.truth} says the ring reads a "
            f"{truth.sensor.model} at {truth.sensor.vref_v:g} V; use a calibration of that "
            f"sensor (irring calibrate), or a --truth whose sensor block names this one")

    # what the device does not report: the calibration's numbers over the truth scenario's
    # over SerialRing's defaults (the paper's ring and GP2D12)
    known: dict = {}
    if truth:
        known.update(template=truth.ring, sensor_model=truth.sensor.model,
                     vref_v=truth.sensor.vref_v, max_range_m=truth.sensor.max_range_m)
    if calibration:
        known.update(sensor_model=calibration.sensor_model, vref_v=calibration.vref_v,
                     emitter_offset_m=calibration.emitter_offset_m)

    poses = [tuple(p) for p in args.pose] if args.pose else (
        [(p.x_m, p.y_m, p.yaw_rad) for p in truth.robot.poses] if truth else [(0.0, 0.0, 0.0)])
    n = args.poses if args.poses is not None else len(poses)
    if n < 1:
        return _error("--poses must be at least 1")
    if n > MAX_SWEEPS:   # a recording holds at most this many: replay could not read it
        return _error(f"{n} poses: a drive sweeps at most {MAX_SWEEPS:,} (a recording's "
                      f"limit); map them in parts")
    if n > len(poses):
        if args.pose or truth:
            return _error(f"--poses {n} but only {len(poses)} pose(s) known; add --pose "
                          f"X_MM,Y_MM,YAW_DEG for each")
        poses = poses * n  # an unmoved robot swept n times
    if truth is not None and args.pose:   # scored against --truth's room: it must hold them
        for x, y, yaw in poses[:n]:
            placed = dataclasses.replace(truth, robot=dataclasses.replace(
                truth.robot, poses=(Pose(x, y, yaw),)))
            try:
                check_ring_placement(placed, lambda path, msg: UsageError(msg))
            except UsageError as exc:
                return _error(f"--pose {x * 1e3:g},{y * 1e3:g},{math.degrees(yaw):g} with "
                              f"--truth {args.truth}: {exc}")
    samples = args.samples
    if samples is None:
        samples = truth.samples_per_step if truth else 1
    settle_s = (args.settle_ms / 1000.0 if args.settle_ms is not None else
                truth.scan.settle_s if truth else 0.0)

    try:
        ring = SerialRing(args.port, baudrate=args.baud, timeout_s=args.timeout,
                          samples=samples, settle_s=settle_s, resweep=args.resweep,
                          accept_v1=args.accept_v1, **known)
    except ValueError as exc:
        return _error(str(exc))
    if truth is None:   # the map is laid out around the poses: refuse one too big unswept
        radius = ring.radius_m if ring.radius_m is not None else ring.template.radius_m
        pipeline.check_pose_spread([p[:2] for p in poses[:n]],
                                   radius + 2 * ring.max_range_m, "--pose")
    say = functools.partial(_tell, file=sys.stderr if args.json else sys.stdout)
    try:
        ring.open()
    except DeviceError as exc:
        _error(str(exc))
        return errors.DEVICE
    except KeyboardInterrupt:   # Ctrl-C, SIGTERM or SIGHUP in the handshake
        ring.close()   # the port only: close() turns nothing back before a handshake ends
        _tell(f"irring drive: interrupted during the handshake; nothing was read; "
              f"{_where(ring)}", file=sys.stderr)
        return errors.INTERRUPTED
    info = ring.info
    say(f"ring on {args.port}: {info.firmware}, {info.nsensors} sensors, {info.adc_bits}-bit "
        f"ADC, step {info.step_mdeg / 1000:g}° × {info.gear_num}/{info.gear_den}, steps "
        f"{info.min_step} … {info.max_step}; IRR protocol v{ring.protocol}")
    warn_protocol(ring, say)
    room = emulated_room(info.firmware)
    if truth is not None and room is not None and room != room_tag(truth.name):
        ring.close()   # another room's readings would be mapped and scored as --truth's
        _error(f"--truth {args.truth}: the emulator on {args.port} simulates {room}, not "
               f"{truth.name}; its readings would be scored against another room: run "
               f"`irring emulate {args.truth}` there, or leave --truth out")
        return errors.USAGE
    if calibration is not None and calibration.adc_bits != info.adc_bits:
        ring.close()   # a bad --calibration file for this ring: exit 1, as --help says
        _error(f"{args.calibration}: a calibration for a {calibration.adc_bits}-bit ADC; the "
               f"ring on {args.port} reports {info.adc_bits} bits: calibrate this ring "
               "(irring calibrate)")
        return errors.INPUT
    if calibration is None:   # the datasheet curve for the ring's ADC, as map_sweeps takes it
        try:
            nominal = Calibration.nominal(ring.sensor_model, ring.ring, info.adc_bits,
                                          ring.vref_v)
        except CalibrationError as exc:   # found after every pose was swept, as exit 1
            ring.close()
            _error(f"the ring on {args.port} reports a {info.adc_bits}-bit ADC, whose counts the "
                   f"{ring.sensor_model} datasheet curve reads as no distance within its range "
                   f"({exc}): calibrate this ring (irring calibrate) and drive it with "
                   f"--calibration FILE")
            return errors.DEVICE
        # a step skipped (README, "Calibrate, then drive"): said, or the map looks final
        say(f"note: no --calibration: the counts are read with the {ring.sensor_model} "
            f"datasheet curve and an emitter offset d_o of "
            f"{nominal.emitter_offset_m * 1000:g} mm; a real ring's own are measured by "
            f"`irring calibrate --port {errors.printable(args.port)} --out ring.yaml` (then "
            "--calibration ring.yaml)")
    differs = _differences(ring.ring, info.adc_bits, truth) if truth is not None else []
    if differs:
        say(f"warning: the ring on {args.port} differs from {truth.name}'s: "
            f"{', '.join(differs)}; using the ring's")
    stride = truth.scan.step_stride if truth else 1
    steps = np.arange(info.min_step, info.max_step + 1, stride)
    readings = n * len(steps) * info.nsensors
    refusal = work_refusal(f"{n:,} sweeps × {len(steps):,} steps × {info.nsensors} sensors "
                           f"(the ring's IRINF) = {readings:,} readings",
                           work_bytes(readings, len(steps) * info.nsensors), "a drive",
                           "give fewer --poses, or a firmware sweeping fewer steps")
    if refusal:   # refused before the ring turns: mapped at the end, it would run out of
        ring.close()   # memory after every sweep was read
        print(f"irring drive: error: {refusal}", file=sys.stderr)
        return errors.TOO_BIG
    if stride > 1:
        # IRSWP reads every step it passes, so every Nth step costs one IRSWP each; an
        # emulator only moves its robot on full-range sweeps and stays at one pose then
        say(f"note: {truth.name} reads every {stride}th step: one IRSWP per step (with "
            f"`irring emulate`, pick each pose with --pose)")

    def move(k: int, pose) -> None:
        if k and sys.stdin.isatty() and not args.no_wait:
            # for the person, as errors are: on stdout it went into a redirected --json
            # summary, unseen
            _tell(f"move the robot to pose {k + 1} of {n} ({pose[0] * 1e3:.0f} mm, "
                  f"{pose[1] * 1e3:.0f} mm, {math.degrees(pose[2]):.0f}°) and press Enter ",
                  end="", file=sys.stderr, flush=True)
            input()

    finished = []   # poses whose sweep came back whole or with steps missing

    def swept(k: int, sweep, report) -> None:
        finished.append(k)
        say(f"pose {k + 1}/{n}: {report.message}")

    try:
        # Ctrl-C, `kill` or the end of input (Ctrl-D at the prompt) stops the drive, but
        # what the ring already delivered is mapped and written, as after a lost link
        with errors.sigterm_as_interrupt():
            acq = pipeline.acquire(ring, poses[:n], steps=steps, progress=False, before=move,
                                   after=swept, interruptible=True)
    finally:
        ring.close()   # stops the ring if it still turns, and turns it back to step 0
        if ring.park_failure:
            _tell(f"irring drive: warning: {errors.printable(ring.park_failure, 2000)}",
                  file=sys.stderr)
    sweeps, failure = acq.sweeps, acq.error
    if failure is None and ring.close_interrupted:   # as the ring turned back: it is heeded
        failure = KeyboardInterrupt()
    stopped = isinstance(failure, (KeyboardInterrupt, EOFError))
    if stopped:
        at = len(finished)
        what = (f"input ended before pose {at + 1} of {n}" if isinstance(failure, EOFError)
                else "interrupted as the ring turned back to step 0" if at == n
                else f"interrupted during pose {at + 1} of {n}")
        kept = (f"{_kept(sweeps, len(finished), len(steps))} mapped and written" if sweeps
                else "no reading arrived, so nothing was mapped or written")
        _tell(f"irring drive: {what}; {kept}; {_where(ring)}", file=sys.stderr)
        if not sweeps:
            return errors.INTERRUPTED
    elif not sweeps:   # one line: why, and that there is nothing to map
        why = f"{errors.printable(str(failure), 2000)}; " if failure is not None else ""
        print(f"irring drive: error: {why}no reading arrived, so "
              "nothing was mapped or written", file=sys.stderr)
        return errors.DEVICE
    elif failure is not None:   # what arrived is mapped below
        _tell(f"irring drive: error: {errors.printable(str(failure), 2000)}", file=sys.stderr)

    try:
        paths, result, link = _map_and_write(args, sweeps, acq, ring, truth, calibration,
                                             cal_text, failure, stopped)
    except BaseException as exc:   # a full disk, a second Ctrl-C, a bug: the readings survive
        _keep_elsewhere(sweeps, truth, cal_text)
        if errors.interrupted(exc):
            _tell(f"irring drive: interrupted while mapping; {_where(ring)}", file=sys.stderr)
        raise
    report(result, paths, as_json=args.json,
           extra={"source": f"serial:{args.port}", "link": link})
    if not args.json:
        t = ring.stats
        missing = sum(len(s.missing_steps) for s in sweeps)
        print(f"  link      {t.scans} steps read, {missing} steps missing; "
              f"{t.checksum_failures} checksum failures, {t.malformed} malformed, "
              f"{t.seq_gaps} seq gaps, {t.timeouts} timeouts, {t.resweeps} re-sweeps")
    return 0 if failure is None else errors.INTERRUPTED if stopped else errors.DEVICE


def _kept(sweeps, whole: int, steps: int) -> str:
    """What a stopped drive maps: "the 2 poses swept are", or with the pose cut short
    "the 1 pose swept and 3 of 5 steps of pose 2 are" (a cut pose is not a pose swept)."""
    parts = [f"the {whole} pose{'s' if whole != 1 else ''} swept"] if whole else []
    cut = len(sweeps[whole].steps) if len(sweeps) > whole else 0   # steps of the cut pose
    if cut:
        parts.append(f"{cut} of {steps} steps of pose {whole + 1}")
    many = whole > 1 or len(parts) > 1 or cut > 1
    return f"{' and '.join(parts)} {'are' if many else 'is'}"


def _where(ring: SerialRing) -> str:
    """Where the ring stands once the session is closed, for a drive cut short."""
    if ring.park_failure:
        return "where the ring stands: see the warning above"
    if ring.stands_at == 0:
        return "the ring stands at step 0"
    if not ring.moved:
        return "the ring was not turned"
    return "where the ring stands is not known"


def _tell(*lines, file, **kw) -> None:
    """print(), but a line its reader did not take (`irring drive | head -1`) must not end
    the drive and lose what the ring delivered: the report after --out is written meets the
    same closed stream and ends the command (exit 4)."""
    try:
        print(*lines, file=file, **kw)
    except OSError:
        pass


def _map_and_write(args, sweeps, acq, ring, truth, calibration, cal_text, failure, stopped):
    """Estimate, map and score what arrived and write --out: (paths, result, link)."""
    frames = 0 if args.no_animation else pipeline.FRAMES_PER_SWEEP
    result = pipeline.map_sweeps(sweeps, scenario=truth, calibration=calibration,
                                 frames_per_sweep=frames, score=truth is not None)
    result.scenario_text = pipeline.scenario_text(truth) if truth is not None else None
    result.calibration_text = cal_text
    link = {"port": args.port, "firmware": ring.info.firmware, "protocol": ring.protocol,
            "totals": ring.stats.as_dict(),
            "sweeps": [r.as_dict() for r in acq.reports],
            "error": None if failure is None else "interrupted" if stopped else str(failure)}
    paths = pipeline.write_outputs(result, args.out, animation=not args.no_animation,
                                   mcap=args.mcap,
                                   extra_files={"link": ("link.json", json.dumps(link, indent=2))})
    return paths, result, link


def _keep_elsewhere(sweeps, truth, cal_text) -> None:
    """Save the sweeps to a new file in the temporary folder and say where: --out could not
    take them, and a drive's readings cannot be taken again for free."""
    try:
        fd, name = tempfile.mkstemp(prefix="irring-drive-", suffix=".npz")
        os.close(fd)
        meta = {"scenario_yaml": pipeline.scenario_text(truth) if truth is not None else None,
                "calibration_yaml": cal_text}
        path = save_recording(name, sweeps, meta)
    except Exception as exc:   # noqa: BLE001 - the error being reported matters more
        print(f"irring drive: the sweeps could not be kept either ({errors.printable(str(exc))})",
              file=sys.stderr)
        return
    n = len(sweeps)
    print(f"irring drive: the {n} sweep{'s' if n != 1 else ''} {'are' if n != 1 else 'is'} "
          f"kept in {path}: irring replay {path}", file=sys.stderr)
