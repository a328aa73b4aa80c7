"""`irring calibrate`: write a calibration file (d_o, a(θ), b(θ)) for the estimator."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from .. import errors
from ..estimation.calibration import (CalibrationAborted, CalibrationError, GuidedCalibration,
                                      SimulatedRig)
from ..outputs import check_out
from ..scenario import load_scenario
from ._common import at_least, between, describe, seed

EPILOG = """\
what it does:
  A flat wall is put in front of one sensor at known distances and angles; the readings
  give the emitter offset d_o (paper Eq. 9) and the curve d = a(θ)·S^b(θ) (Eq. 10, S in
  ADC counts, θ the incidence angle) by least squares in log–log space.

  without --port  the simulated rig: the scenario's ring, sensor and effects in front of
                  one wall of a generated 4 m × 4 m room (MuJoCo ray casts); takes ~1 s.
  with --port     the real ring over a serial port (IRR protocol): you are asked to place
                  the wall for each of 28 placements (distances from the sensor's rotation
                  axis in mm, angles in degrees), the ring sweeps, and the file is written
                  at the end. Enter: read; s: skip the placement; q: quit.

  The file is YAML (distances in mm, angles in degrees); pass it to the estimator with
  `irring run --calibration FILE` or irring.estimation.calibration.Calibration.load(FILE).
  Without a calibration file `irring run` reads a simulated scene with the calibration of
  what the scene simulates, `irring drive` the real ring with the sensor's datasheet curve.

examples:
  irring calibrate                                  simulated rig, t_room's sensor and effects
  irring calibrate --scenario my_room.yaml --out my_cal.yaml
  irring calibrate --port /dev/ttyUSB0 --out ring.yaml
  irring emulate t_room &                           then
  irring calibrate --port ring.pty                 (checks the I/O only: the emulator shows
                                                    its scene, not your wall)
"""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Calibrate the ring for the estimator: the emitter offset d_o (paper "
             "Eq. 9) and the curve d = a(θ)·S^b(θ) (Eq. 10) from readings against a "
             "flat wall, on the simulated rig (default) or on the real ring (--port).",
             EPILOG)
    p.add_argument("--scenario", default="t_room", metavar="NAME_OR_PATH",
                   help="scenario whose ring, sensor model, ADC and effects are used "
                        "(default: t_room)")
    p.add_argument("--out", default="calibration.yaml", metavar="FILE",
                   help="calibration file to write (default: calibration.yaml)")
    p.add_argument("--port", metavar="PORT",
                   help="serial port or pyserial URL of the real ring; runs the guided "
                        "procedure instead of the simulated rig")
    p.add_argument("--baud", type=between(1, 10_000_000), default=115200,
                   help="serial speed with --port (default: 115200)")
    p.add_argument("--sensor", type=at_least(0), default=0,
                   help="which sensor faces the wall (default: 0)")
    p.add_argument("--sweeps", type=at_least(1), default=None, metavar="N",
                   help="sweeps per placement, averaged (≥ 1; default: 8 simulated, 4 real)")
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
    check_out(out.parent)
    scenario = load_scenario(args.scenario)

    def no_such_sensor(ring: str, sensors: int) -> int:
        print(f"irring calibrate: error: --sensor {args.sensor}: {ring} has sensors 0 … "
              f"{sensors - 1}", file=sys.stderr)
        return errors.USAGE

    try:
        if args.port is None:
            if args.sensor >= scenario.ring.sensors:
                return no_such_sensor(f"{scenario.name}'s ring", scenario.ring.sensors)
            rig = SimulatedRig(scenario, sensor=args.sensor, sweeps=args.sweeps or 8,
                               seed=args.seed)
            print(f"simulated rig: {scenario.name}'s ring and {scenario.sensor.model}, effects: "
                  f"{', '.join(k for k in scenario.effects if k != 'motion') or 'none'}; "
                  f"{len(rig.placements)} placements × {rig.sweeps} sweeps")
            cal = rig.calibrate()
        else:
            from ..hardware.serial_ring import SerialRing   # deferred: loads pyserial

            ring = SerialRing(args.port, baudrate=args.baud,
                              emitter_offset_m=scenario.ring.emitter_offset_m,
                              sensor_model=scenario.sensor.model, vref_v=scenario.sensor.vref_v,
                              max_range_m=scenario.sensor.max_range_m)
            try:
                with ring:  # the handshake sets ring.info (or raises)
                    if args.sensor >= ring.info.nsensors:   # before the first placement
                        return no_such_sensor(f"the ring on {args.port}", ring.info.nsensors)
                    guided = GuidedCalibration(
                        read_sweep=lambda: ring.sweep(resweep=1), prompt=input, show=print,
                        sensor_model=scenario.sensor.model, adc_bits=ring.info.adc_bits,
                        vref_v=scenario.sensor.vref_v, sensor=args.sensor,
                        sweeps=args.sweeps or 4,
                        emitter_offset_guess_m=scenario.ring.emitter_offset_m)
                    cal = guided.run()
            except errors.DeviceError as exc:
                print(f"irring calibrate: error: {exc}", file=sys.stderr)
                return errors.DEVICE
    except CalibrationAborted as exc:
        print(f"irring calibrate: {exc}; nothing written", file=sys.stderr)
        return 1
    except (CalibrationError, ValueError) as exc:
        print(f"irring calibrate: error: {errors.printable(str(exc))}", file=sys.stderr)
        return errors.INPUT
    except EOFError:
        print("irring calibrate: input ended; nothing written", file=sys.stderr)
        return 1
    path = cal.save(out)
    print(_summary(cal))
    print(f"wrote {path}")
    return 0
