"""Measured figures for the serial path (``python -m irring.studies.serial_link [--json]``):
the emulator on a real pty with SerialRing against it, unthrottled, paced like a UART and
in real time, and on a lossy link. Nothing here is asserted. What is measured:
docs/emulator.md.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

from ..scenario import load_scenario
from ..hardware import SerialRing
from ..hardware.emulator import Device, Faults, PtyEmulator
from ..simulation.sim import SimRing


@contextmanager
def _driver_on_pty(device: Device, *, timeout_s: float, baud: int = 0):
    """SerialRing (opened) on ``device`` served on a pty in a thread; both closed after."""
    with tempfile.TemporaryDirectory() as tmp:
        link = Path(tmp) / "tty"
        with PtyEmulator(device, link=link, baud=baud).start_thread(), \
                SerialRing(str(link), timeout_s=timeout_s) as ring:
            yield ring


def _sweep_times(scenario, *, baud: int, realtime: bool, repeats: int) -> dict:
    device = Device(SimRing(scenario), realtime=realtime)
    with _driver_on_pty(device, timeout_s=2.0, baud=baud) as ring:
        walls, durations = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            sweep = ring.sweep()
            walls.append(time.perf_counter() - t0)
            durations.append(sweep.duration_s)
    sent = device.stats.bytes_sent
    return {"baud": baud or None, "realtime": realtime, "repeats": repeats,
            "wall_s_median": statistics.median(walls), "wall_s_min": min(walls),
            "device_duration_s": statistics.median(durations),
            "bytes_per_sweep": sent / repeats}


class _Recorded(SimRing):
    """Remembers every row the device produced, to count invented readings."""

    def __init__(self, scenario):
        super().__init__(scenario)
        self.rows: set[tuple[int, bytes]] = set()

    def sweep(self, pose=0, *, steps=None):
        sweep = super().sweep(pose, steps=steps)
        self.rows.update((int(s), c.astype("int64").tobytes())
                         for s, c in zip(sweep.steps, sweep.counts))
        return sweep


def _lossy(scenario, *, sweeps: int, resweep: int, seed: int) -> dict:
    faults = Faults(corrupt_rate=0.01, drop_rate=0.05, seed=seed)
    source = _Recorded(scenario)
    invented = 0
    with _driver_on_pty(Device(source, faults=faults), timeout_s=0.2) as ring:
        received, walls = [], []
        for _ in range(sweeps):
            t0 = time.perf_counter()
            sweep = ring.sweep(resweep=resweep)
            walls.append(time.perf_counter() - t0)
            received.append(len(sweep.steps) / (len(sweep.steps) + len(sweep.missing_steps)))
            invented += sum((int(st), row.astype("int64").tobytes()) not in source.rows
                            for st, row in zip(sweep.steps, sweep.counts))
        stats = ring.stats.as_dict()
    return {"resweep": resweep, "sweeps": sweeps, "received_share_mean": statistics.mean(received),
            "received_share_min": min(received), "wall_s_median": statistics.median(walls),
            "invented_readings": invented, "link": stats}


def measure(scenario_name: str = "t_room", quick: bool = False) -> dict:
    sc = load_scenario(scenario_name)
    n = 3 if quick else 10
    return {
        "scenario": scenario_name,
        "unthrottled": _sweep_times(sc, baud=0, realtime=False, repeats=n),
        "uart_115200": _sweep_times(sc, baud=115200, realtime=False, repeats=max(2, n // 3)),
        "realtime_115200": _sweep_times(sc, baud=115200, realtime=True, repeats=1),
        "lossy_no_resweep": _lossy(sc, sweeps=n, resweep=0, seed=1),
        "lossy_resweep_2": _lossy(sc, sweeps=n, resweep=2, seed=1),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m irring.studies.serial_link",
                                 description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--quick", action="store_true", help="fewer repeats")
    args = ap.parse_args(argv)
    r = measure(quick=args.quick)
    if args.json:
        print(json.dumps(r, indent=2))
        return 0
    print(f"one full sweep of {r['scenario']} (71 steps × 12 sensors) over a pty:")
    for key, label in (("unthrottled", "unthrottled"), ("uart_115200", "115200 baud"),
                       ("realtime_115200", "real time + 115200 baud")):
        m = r[key]
        print(f"  {label:<24} host {m['wall_s_median'] * 1e3:8.1f} ms   device clock "
              f"{m['device_duration_s']:.3f} s   {m['bytes_per_sweep']:.0f} bytes")
    for key in ("lossy_no_resweep", "lossy_resweep_2"):
        m = r[key]
        link = m["link"]
        print(f"1 % corrupted bytes + 5 % dropped sentences, resweep={m['resweep']}: "
              f"{m['received_share_mean'] * 100:.1f} % of steps received (worst "
              f"{m['received_share_min'] * 100:.1f} %) over {m['sweeps']} sweeps, host "
              f"{m['wall_s_median'] * 1e3:.0f} ms per sweep; {link['checksum_failures']} "
              f"checksum failures, {link['malformed']} malformed, {link['lost_scans']} IRSCN "
              f"lost, {link['timeouts']} timeouts, {m['invented_readings']} rows not produced by "
              f"the device")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
