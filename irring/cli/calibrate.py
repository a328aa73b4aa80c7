"""`irring calibrate`: write a calibration file (d_o, a(θ), b(θ)) for the estimator."""

from __future__ import annotations

import argparse
import math
import os
import shlex
import sys
import tempfile
from pathlib import Path

from .. import errors, gp2
from ..estimation import calibration_chart
from ..estimation.calibration import (CalibrationAborted, CalibrationError, GuidedCalibration,
                                      SimulatedRig, load_progress, save_progress)
from ..outputs import CHART_FILE, check_out, check_replaceable
from ..core import MAX_SWEEPS
from ..scenario import DEFAULT_SCENARIO, load_scenario
from ._common import (add_protocol_v1_option, at_least, between, describe, out_path, scenario_name,
                      seed, serial_port, spare_inputs, warn_protocol)

EPILOG = """\
what it does:
  A flat wall is put in front of one sensor at known distances and angles; the readings
  give the emitter offset d_o (paper Eq. 9) and the curve d = a(θ)·S^b(θ) (Eq. 10, S in
  ADC counts, θ the incidence angle) by least squares in log–log space.

  without --port  the simulated rig: the scenario's ring, sensor and effects in front of
                  one wall of a generated 4 m × 4 m room (MuJoCo ray casts); it takes a
                  few seconds (README, "Calibrate, then drive").
  with --port     the real ring over a serial port (IRR protocol): you are asked to place
                  the wall for each of 28 placements (distances from the sensor's rotation
                  axis in mm, angles in degrees), the ring sweeps, and the file is written
                  at the end. Enter: read; s: skip the placement; q: quit.

  stopping early  When the procedure stops before the file is written (q, Ctrl-C, the input
                  ending, the device failing, a fit that fails, --out not writable), the
                  placements already read are kept in a file in the temporary folder
                  ($TMPDIR, else /tmp), named on stderr with the command that resumes:
                  irring calibrate --port PORT --resume FILE asks only for the placements
                  the file does not hold (the printed command repeats --sensor, --scenario
                  and --out; a file of another sensor, model or ADC is refused).

  the ring        However the procedure ends, a sweep still running is stopped (IRSTP) and
                  the ring turned back to step 0 (IRGTO,0): its firmware takes where it
                  stands when it starts for step 0, and an Arduino restarts each time its
                  port is opened. A ring that does not confirm it is named in a warning.

  the picture     Beside the file, the same name with .png (calibration.png): the readings
                  (ADC counts and volts against the distance to the wall, coloured by the
                  incidence angle) with the fitted curve through them, how far the curve
                  reads each reading from the wall (mm), and the sensor's fold-over peak.
                  The picture of an earlier calibration there is removed as the file is
                  written: stopped while drawing, it leaves none rather than another's.

  The file is YAML (distances in mm, angles in degrees); pass it to the estimator with
  `irring run --calibration FILE` or irring.estimation.calibration.Calibration.load(FILE).
  Without a calibration file `irring run` reads a simulated scene with the calibration of
  what the scene simulates, `irring drive` the real ring with the sensor's datasheet curve.

examples:
  irring calibrate                                  simulated rig, t_room's sensor and effects
  irring calibrate --scenario my_room.yaml --out my_cal.yaml
  irring calibrate --port /dev/ttyUSB0 --out ring.yaml
  irring calibrate --port /dev/ttyUSB0 --out ring.yaml --resume /tmp/irring-calibrate-x.yaml
  irring emulate t_room &                           then
  irring calibrate --port ring.pty                 (checks the I/O only: the emulator shows
                                                    its scene, not your wall)
"""


# the options' defaults, stated once: the parser's, and the ones the command that resumes
# leaves out (_keep)
DEFAULTS = {"scenario": DEFAULT_SCENARIO, "out": "calibration.yaml", "baud": 115200,
            "sensor": 0, "sweeps": None}
SIMULATED_SWEEPS, REAL_SWEEPS = 8, 4   # --sweeps when not given (a resumed run: its file's)


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Calibrate the ring for the estimator: the emitter offset d_o (paper "
             "Eq. 9) and the curve d = a(θ)·S^b(θ) (Eq. 10) from readings against a "
             "flat wall, on the simulated rig (default) or on the real ring (--port).",
             EPILOG)
    p.add_argument("--scenario", default=DEFAULTS["scenario"], metavar="NAME_OR_PATH",
                   type=scenario_name,
                   help="scenario whose ring, sensor model, ADC and effects are used "
                        f"(default: {DEFAULTS['scenario']})")
    p.add_argument("--out", type=out_path, default=DEFAULTS["out"], metavar="FILE",
                   help=f"calibration file to write (default: {DEFAULTS['out']}); its "
                        "picture is written beside it, named with .png (calibration.png)")
    p.add_argument("--port", type=serial_port, metavar="PORT",
                   help="serial port or pyserial URL of the real ring; runs the guided "
                        "procedure instead of the simulated rig")
    p.add_argument("--baud", type=between(1, 10_000_000), default=None,
                   help=f"serial speed with --port (default: {DEFAULTS['baud']})")
    add_protocol_v1_option(p, "with --port: ")
    p.add_argument("--resume", type=Path, default=None, metavar="FILE",
                   help="with --port: the placements an earlier run read before it stopped "
                        "(the file it named); they are not measured again")
    p.add_argument("--sensor", type=at_least(0), default=DEFAULTS["sensor"], metavar="K",
                   help=f"which sensor faces the wall, ≥ 0: 0 … N−1 of the scenario's ring "
                        f"(default: {DEFAULTS['sensor']})")
    p.add_argument("--sweeps", type=at_least(1, MAX_SWEEPS), default=DEFAULTS["sweeps"],
                   metavar="N",
                   help=f"sweeps per placement, averaged (1 … {MAX_SWEEPS}, what a progress "
                        f"file holds; default: {SIMULATED_SWEEPS} simulated, {REAL_SWEEPS} real, "
                        "or as --resume's file)")
    p.add_argument("--seed", type=seed, default=None,
                   help="noise seed ≥ 0 of the simulated rig (default: the scenario's)")
    p.set_defaults(func=run)


def _summary(cal) -> str:
    return (f"d_o = {cal.emitter_offset_m * 1e3:.2f} mm, a(0) = {cal.a[0]:.5g}, "
            f"b(0) = {cal.b[0]:.4f}, θ table 0 … {math.degrees(cal.max_theta_rad):.0f}° "
            f"({cal.theta_rad.size} rows), noise {cal.noise_counts:.1f} counts")


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.is_dir():  # `--out DIR`: the file goes inside, not over the folder
        out = out / "calibration.yaml"
    elif out.suffix.lower() == ".png":   # `--out c.png` wrote YAML into c.png, the chart
        # into c.png.png
        yaml = out.with_suffix(".yaml")
        raise errors.UsageError(
            f"--out {errors.printable(str(out))}: a calibration is written as YAML, with its "
            f"picture beside it; name the YAML file (--out {errors.printable(str(yaml))} "
            f"writes {errors.printable(yaml.name)} and {picture_path(yaml).name})")
    if args.resume is not None and args.port is None:
        print("irring calibrate: error: --resume continues a guided calibration of the real "
              "ring; give its --port too", file=sys.stderr)
        return errors.USAGE
    if args.baud is not None and args.port is None:
        print("irring calibrate: error: --baud is the real ring's serial speed; give its "
              "--port too", file=sys.stderr)
        return errors.USAGE
    if args.accept_v1 and args.port is None:
        print("irring calibrate: error: --accept-protocol-v1 is for a real ring's old "
              "firmware; give its --port too", file=sys.stderr)
        return errors.USAGE
    check_out(out.parent)
    spare_inputs({"--out": out, "its picture": picture_path(out)},
                 {"--scenario": args.scenario, "--resume": args.resume})
    check_replaceable(out, "--out", "calibration file")   # before the rig, not after
    check_replaceable(picture_path(out), f"--out {out}'s picture", CHART_FILE)
    scenario = load_scenario(args.scenario)
    why = _cannot_calibrate(scenario, simulated=args.port is None)
    if why:
        print(f"irring calibrate: error: {scenario.source or scenario.name}: {why}",
              file=sys.stderr)
        return errors.INPUT
    if args.port is not None:
        return _guided(args, scenario, out)
    if args.sensor >= scenario.ring.sensors:
        return _no_such_sensor(args, f"{scenario.name}'s ring", scenario.ring.sensors)
    try:
        rig = SimulatedRig(scenario, sensor=args.sensor, sweeps=args.sweeps or SIMULATED_SWEEPS,
                           seed=args.seed)
        print(f"simulated rig: {scenario.name}'s ring and {scenario.sensor.model}, effects: "
              f"{', '.join(k for k in scenario.effects if k != 'motion') or 'none'}; "
              f"{len(rig.placements)} placements × {rig.sweeps} sweeps")
        fitted = rig.fit()
    except (CalibrationError, ValueError) as exc:
        print(f"irring calibrate: error: {errors.printable(str(exc))}", file=sys.stderr)
        return errors.INPUT
    path = _save(fitted.calibration, out)
    return _done(fitted, path, f"on the simulated rig ({scenario.name}'s ring)", args.sensor)


def _cannot_calibrate(scenario, simulated: bool) -> str | None:
    """Why the wall procedure cannot calibrate ``scenario``'s sensor (None: it can). It fits
    a GP2's falling curve and reads d_o from one sensor turned across a wall: a radial
    design ended in 'Σ tan²φ = 0 … sweep the sensor across angles', a laser in 'not a
    plausible d_o'."""
    if gp2.sensor(scenario.sensor.model).b[0] > 0:
        return (f"its sensor, {scenario.sensor.model}, reads distance linearly; irring "
                "calibrate fits a GP2's curve d = a(θ)·S^b(θ) (paper Eq. 10): use a scenario "
                "with a GP2 sensor (gp2d12, gp2y0a21, gp2y0a02)")
    ring = scenario.ring
    if simulated and ring.min_step == ring.max_step:
        return (f"its design, {scenario.robot.design}, does not turn its sensors (motor steps "
                f"{ring.min_step} … {ring.max_step}); the procedure reads d_o from a sensor "
                "turned across a wall (paper Eq. 9): use a turning design (rotating12, "
                "rotating1)")
    return None


def _no_such_sensor(args, ring: str, sensors: int) -> int:
    print(f"irring calibrate: error: --sensor {args.sensor}: {ring} has sensors 0 … "
          f"{sensors - 1}", file=sys.stderr)
    return errors.USAGE


def _guided(args: argparse.Namespace, scenario, out: Path) -> int:
    """The guided procedure on the real ring; what was read survives any way it stops."""
    from ..hardware.serial_ring import SerialRing   # deferred: loads pyserial

    progress = load_progress(args.resume) if args.resume is not None else None   # exit 1
    try:
        ring = SerialRing(args.port, baudrate=args.baud or DEFAULTS["baud"],
                          emitter_offset_m=scenario.ring.emitter_offset_m,
                          sensor_model=scenario.sensor.model, vref_v=scenario.sensor.vref_v,
                          max_range_m=scenario.sensor.max_range_m, accept_v1=args.accept_v1)
    except ValueError as exc:
        print(f"irring calibrate: error: {errors.printable(str(exc))}", file=sys.stderr)
        return errors.USAGE
    guided = None
    try:
        try:
            # Ctrl-C or `kill` stops the procedure, but the placements read are kept; the
            # handshake sets ring.info (or raises)
            with errors.sigterm_as_interrupt(), ring:
                warn_protocol(ring, print)
                if args.sensor >= ring.info.nsensors:   # before the first placement
                    return _no_such_sensor(args, f"the ring on {args.port}", ring.info.nsensors)
                guided = GuidedCalibration(
                    read_sweep=lambda: ring.sweep(resweep=1), prompt=input, show=print,
                    sensor_model=scenario.sensor.model, adc_bits=ring.info.adc_bits,
                    vref_v=scenario.sensor.vref_v, sensor=args.sensor, sweeps=args.sweeps or (
                        progress.sweeps if progress is not None else REAL_SWEEPS),
                    emitter_offset_guess_m=scenario.ring.emitter_offset_m)
                # before a wall is placed
                guided.check_steps(ring.info.max_step - ring.info.min_step + 1)
                if progress is not None:
                    why = progress.mismatch(guided)
                    if why:
                        print(f"irring calibrate: error: {args.resume}: cannot resume: {why}",
                              file=sys.stderr)
                        return errors.INPUT
                    guided.done.update((i, r) for i, (_, r) in progress.done.items())
                    guided.resumed = len(guided.done)
                    print(f"resuming from {args.resume}: {len(guided.done)} of "
                          f"{len(guided.placements)} placements read before")
                cal = guided.run()
        finally:   # the ring stopped and turned back to step 0, or why not
            if ring.park_failure:
                print(f"irring calibrate: warning: {errors.printable(ring.park_failure, 2000)}",
                      file=sys.stderr)
        path = _save(cal, out)
    except BaseException as exc:   # noqa: BLE001 - say why, keep what was read, then stop
        status = _say_why(exc, guided)
        if guided is not None:
            _keep(args, guided)
        if status is None:   # anything else (a full disk, a bug): main's one line
            raise
        return status
    return _done(guided.fitted, path, f"on the ring at {args.port}", args.sensor)


def picture_path(out: Path) -> Path:
    """The picture written beside the calibration file ``out``: its name with .png."""
    return out.with_name(out.name + ".png") if out.suffix.lower() == ".png" else \
        out.with_suffix(".png")


def _save(cal, out: Path) -> Path:
    """Write the calibration and remove the picture of the one it replaces, together. The
    new picture is drawn after that and may be cut short; then there is no picture, never
    one of another calibration beside the file. (check_replaceable let only a chart irring
    drew, or an empty file, stand there.)"""
    stopped: list[bool] = []
    with errors.interrupts_noted(lambda: stopped.append(True)):
        path = cal.save(out)
        picture_path(path).unlink(missing_ok=True)
    if stopped:
        raise KeyboardInterrupt
    return path


def _done(fitted, path: Path, where: str, sensor: int) -> int:
    """Say what was fitted; draw it beside the file (the file is written first: a picture
    that fails loses no calibration)."""
    cal = fitted.calibration
    print(_summary(cal))
    print(f"wrote {errors.printable(str(path))}")
    title = (f"Calibration of sensor {sensor} ({cal.sensor_model}) {where}: d_o = "
             f"{cal.emitter_offset_m * 1e3:.2f} mm, noise {cal.noise_counts:.1f} counts")
    try:
        png = calibration_chart.save_png(picture_path(path), fitted, errors.printable(title))
    except OSError as exc:   # a full disk said only "cal.png: No space left on device"
        why = exc.strerror or str(exc).rsplit(": ", 1)[-1]
        raise errors.OutputError(
            f"{errors.printable(str(picture_path(path)))}: cannot write the picture: {why}; "
            f"the calibration {errors.printable(str(path))} is written whole (it needs no "
            "picture)") from None
    print(f"wrote {errors.printable(str(png))} (the readings, the fitted curve and its errors)")
    return 0


def _say_why(exc: BaseException, guided) -> int | None:
    """Print why the procedure stopped and return the exit status (None: let main say)."""
    where = (f" at placement {guided.at} of {len(guided.placements)}"
             if guided is not None and guided.at else "")
    if isinstance(exc, CalibrationAborted):
        line, status = str(exc), errors.INPUT
    elif isinstance(exc, EOFError):
        line, status = f"input ended{where}", errors.INPUT
    elif isinstance(exc, KeyboardInterrupt):
        line, status = f"interrupted{where}", errors.INTERRUPTED
    elif isinstance(exc, (errors.DeviceError, CalibrationError, errors.TooBig)):
        line, status = f"error: {errors.printable(str(exc), 2000)}", exc.status
    else:
        return None
    print(f"irring calibrate: {line}", file=sys.stderr)
    return status


def _keep(args: argparse.Namespace, guided) -> None:
    """Save the placements read to a new file in the temporary folder and say how to
    resume: a person placed the wall for each of them."""
    n, total = len(guided.done), len(guided.placements)
    if not guided.done:
        print("irring calibrate: no placement was read, so nothing was kept", file=sys.stderr)
        return
    if n == guided.resumed:
        print(f"irring calibrate: nothing new was read; {args.resume} still holds the {n} "
              f"placements read before", file=sys.stderr)
        return
    try:
        fd, name = tempfile.mkstemp(prefix="irring-calibrate-", suffix=".yaml")
        os.close(fd)
        path = save_progress(name, guided)
    except Exception as exc:   # noqa: BLE001 - the error being reported matters more
        print(f"irring calibrate: the placements read could not be kept either "
              f"({errors.printable(str(exc))})", file=sys.stderr)
        return
    again = ["irring", "calibrate", "--port", args.port, "--resume", str(path)]
    for name in ("scenario", "sensor", "out", "sweeps", "baud"):
        value, default = getattr(args, name), DEFAULTS[name]
        # an option not given is None (--baud's parser default): `--baud None` is refused
        if value is not None and value != default and str(value) != default:
            again += [f"--{name}", str(value)]
    print(f"irring calibrate: the {n} placement{'s' if n != 1 else ''} read (of {total}) "
          f"{'are' if n != 1 else 'is'} kept in {path}; resume with: "
          f"{shlex.join(again)}", file=sys.stderr)
