"""`irring emulate SCENARIO`: a ring device on a pseudo-terminal, backed by the simulator."""

from __future__ import annotations

import argparse
import errno
import ipaddress
import math
import signal
import socket
import sys
import time

from ..hardware import protocol
from ..hardware.emulator import Device, Faults, PtyEmulator, TcpEmulator, firmware_for
from ..scenario import load_scenario
from ._common import (add_pose_option, at_least, between, describe, host_port, number_in,
                      pose_index, scenario_name, seed)

STALL_S_MAX = 86_400   # a day: longer is a firmware that never recovers, the default

DEFAULT_LINK = "ring.pty"

EPILOG = """\
examples:
  irring emulate t_room                           # then: irring drive --port ring.pty
  irring emulate t_room --realtime                # GP2 timing and a 115200-baud UART
  irring emulate t_room --corrupt-rate 0.01 --drop-rate 0.05
  irring emulate t_room --bitflip-rate 0.001      # line noise: single bits flipped
  irring emulate t_room --stall-after 100 --disconnect-after 400
  irring emulate t_room --reverse-sweeps          # sweeps each IRSWP from its end back
  irring emulate t_room --motor-reversed          # a ring wired to turn the wrong way
  irring emulate t_room_cylinder --link ring2.pty # a second device beside the first
  irring emulate t_room --tcp 0                   # a free TCP port; it prints which, then:
                                                  #   irring drive --port socket://127.0.0.1:PORT
  irring emulate t_room --protocol 1              # an old board not yet reflashed

The device speaks IRR protocol v2 (docs/protocol.md) on /dev/pts/N; any serial program can open
the --link path (e.g. `python -m serial.tools.miniterm ring.pty`, then type $IRHLO*26D0).
Readings come from the scenario's simulated ring and effects with the scenario's seed, so a
fault-free full sweep equals `SimRing(scenario).sweep(pose)`. The robot starts at the
scenario's first pose (pose 1, as map.png numbers them); each further full-range sweep
moves it to the next pose, and each new session (a host's $IRHLO, sent when `irring drive`
or `calibrate` opens the port) starts it again at pose 1. Faults act on what the device
sends."""


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Run an emulated ring device that speaks the IRR serial protocol on a "
             "pseudo-terminal, with readings from the scenario's simulation and "
             "optional fault injection. Runs until Ctrl-C (or the injected "
             "disconnect).",
             EPILOG)
    p.add_argument("scenario", nargs="?", default="t_room", type=scenario_name,
                   help="bundled scenario name or YAML path (default: t_room)")
    p.add_argument("--link", metavar="PATH", default=None, type=_link_path,
                   help=f"symlink to the pty slave for the host to open (default: {DEFAULT_LINK} "
                        "in the current folder; removed when the emulator stops; a link "
                        "left by an emulator that was killed is replaced, one in use by a "
                        "running emulator or any other file refused)")
    p.add_argument("--tcp", metavar="[HOST:]PORT", default=None, type=host_port,
                   help="serve on TCP instead of a pty; the host opens socket://HOST:PORT "
                        "(HOST defaults to 127.0.0.1; PORT 0 picks a free one)")
    p.add_argument("--realtime", action="store_true",
                   help="take as long as the real ring: settle + samples × 38.3 ms per step "
                        "and a UART at --baud (default: as fast as possible, with a virtual "
                        "device clock that still advances by the hardware time)")
    p.add_argument("--baud", type=between(0, 10_000_000), default=None, metavar="BAUD",
                   help="pace output like a UART at BAUD bit/s, 10 bits per byte "
                        "(default: 115200 with --realtime, else unthrottled; 0 = unthrottled)")
    p.add_argument("--corrupt-rate", type=number_in(0, 1), default=0.0, metavar="P",
                   help="probability that each byte sent is corrupted, 0…1 (default 0; 0.01 "
                        "garbles about half of all 80-byte IRSCN sentences)")
    p.add_argument("--bitflip-rate", type=number_in(0, 1), default=0.0, metavar="P",
                   help="probability that each bit sent is flipped, 0…1, as line noise does "
                        "(default 0; 0.001 flips a bit in about half of all 80-byte IRSCN "
                        "sentences, most in one bit only: what a CRC is for)")
    p.add_argument("--drop-rate", type=number_in(0, 1), default=0.0, metavar="P",
                   help="probability that a sentence is never sent, 0…1 (default 0)")
    p.add_argument("--stall-after", type=at_least(0), default=None, metavar="N",
                   help="stop answering after N ≥ 0 sentences, a hung firmware (default: never)")
    p.add_argument("--stall-seconds", type=number_in(0, STALL_S_MAX), default=math.inf,
                   metavar="S", help=f"with --stall-after: recover after S seconds, ≥ 0 and "
                                     f"≤ {STALL_S_MAX:g} (default: never)")
    p.add_argument("--disconnect-after", type=at_least(0), default=None, metavar="N",
                   help="close the port after N ≥ 0 sentences, a pulled cable (default: never)")
    p.add_argument("--reverse-sweeps", action="store_true",
                   help="sweep every IRSWP from its last step back to its first, each IRSCN "
                        "naming its step: a firmware that ignores the asked direction")
    p.add_argument("--motor-reversed", action="store_true",
                   help="turn the motor the other way than the firmware counts (DIR wired "
                        "reversed): step s is read at step -s, which the link cannot show "
                        "(irring drive --truth scores the mirrored map)")
    p.add_argument("--seed", type=seed, default=None,
                   help="noise seed ≥ 0 of the readings (default: the scenario's seed)")
    p.add_argument("--fault-seed", type=seed, default=0, metavar="SEED",
                   help="seed ≥ 0 of the fault injection (default 0)")
    p.add_argument("--protocol", type=int, choices=protocol.PROTOCOL_VERSIONS,
                   default=protocol.PROTOCOL_VERSION, metavar="N",
                   help=f"IRR protocol version to speak: {protocol.PROTOCOL_VERSION} (default, "
                        "CRC-16) or 1 (an old board's 8-bit XOR checksum: irring drive "
                        "refuses it unless given --accept-protocol-v1)")
    add_pose_option(p, None, "stay at one pose instead of moving on after each full sweep")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(func=run)


def _link_path(text: str) -> str:
    """``--link``'s value: an empty one (``--link "$L"`` with L unset) was taken as the
    current folder ('--link : . exists and is not a symlink')."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"an empty path; name the link to make (default "
                                         f"{DEFAULT_LINK})")
    return text


def run(args: argparse.Namespace) -> int:
    from ..simulation.sim import SimRing   # deferred: loads MuJoCo, which --help does not need

    # an option that would do nothing is refused rather than ignored
    if args.tcp is not None and args.link is not None:
        print("irring emulate: error: --link and --tcp: the device is on a pty (--link PATH) "
              "or on TCP (--tcp PORT), not both", file=sys.stderr)
        return 2
    if args.stall_seconds != math.inf and args.stall_after is None:
        print(f"irring emulate: error: --stall-seconds {args.stall_seconds:g} recovers from a "
              "stall, so it needs --stall-after N (when to stall)", file=sys.stderr)
        return 2
    args.link = DEFAULT_LINK if args.link is None else args.link
    scenario = load_scenario(args.scenario)
    try:
        faults = Faults(corrupt_rate=args.corrupt_rate, bitflip_rate=args.bitflip_rate,
                        drop_rate=args.drop_rate,
                        stall_after=args.stall_after, stall_s=args.stall_seconds,
                        disconnect_after=args.disconnect_after,
                        reverse_sweeps=args.reverse_sweeps,
                        motor_reversed=args.motor_reversed, seed=args.fault_seed)
    except ValueError as exc:
        print(f"irring emulate: error: {exc}", file=sys.stderr)
        return 2
    fixed = None if args.pose is None else pose_index(args.pose, scenario)
    baud = args.baud if args.baud is not None else (115200 if args.realtime else 0)
    source = SimRing(scenario, seed=args.seed)
    try:
        device = Device(source, faults=faults, realtime=args.realtime, fixed_pose=fixed,
                        protocol=args.protocol, firmware=firmware_for(scenario.name))
    except ValueError as exc:   # --motor-reversed on an asymmetric ring; IRSCN too long
        print(f"irring emulate: error: {exc}", file=sys.stderr)
        return 2
    for warning in _announced_off(source.ring, device.info):   # emulated, yet not as given
        print(f"irring emulate: warning: {warning}", file=sys.stderr)
    if args.tcp is not None:
        host, port = args.tcp
        given = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"   # IPv6 in brackets
        try:
            emu = TcpEmulator(device, host=host, port=port, baud=baud)
            where = emu.open()
        except (ValueError, OSError, OverflowError) as exc:
            print(f"irring emulate: error: --tcp {given}: "
                  f"{getattr(exc, 'strerror', None) or exc}{_bind_hint(exc, host)}",
                  file=sys.stderr)
            return 2
        if not _loopback(host):   # once it listens: a name that fails needs no warning
            print(f"irring emulate: warning: {_exposed(given, host)}", file=sys.stderr)
    else:
        emu = PtyEmulator(device, link=args.link, baud=baud)
        try:
            where = f"{emu.open()}, link {args.link}"
        except OSError as exc:
            print(f"irring emulate: error: --link {args.link}: {exc.strerror or exc}",
                  file=sys.stderr)
            return 2
    if not args.quiet:
        info = device.info
        print(f"irring emulate: {scenario.name} ring ({info.nsensors} sensors, steps "
              f"{info.min_step} … {info.max_step}, seed {source.seed}) on {where}; "
              f"{'real time' if args.realtime else 'unthrottled'}"
              f"{f', {baud} baud' if baud else ''}. Ctrl-C stops.", flush=True)
    started = time.monotonic()
    previous = signal.signal(signal.SIGTERM, _interrupt)  # `kill` also removes the link
    try:
        emu.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        emu.stop()
    s = device.stats
    if not args.quiet:
        why = "disconnected as injected" if device.disconnected else "stopped"
        print(f"irring emulate: {why} after {time.monotonic() - started:.1f} s: {s.commands} "
              f"commands ({s.commands_rejected} rejected, {s.commands_dropped} dropped unanswered), "
              f"{s.sweeps} sweeps, "
              f"{s.sentences_produced} sentences ({s.sentences_dropped} dropped, "
              f"{s.sentences_corrupted} corrupted: {s.bytes_corrupted} bytes replaced, "
              f"{s.bits_flipped} bits flipped)", flush=True)
    return 0


ANNOUNCED_TOLERANCE = 1e-4   # 0.004° at the paper's 37.8°: below it, nothing said


def _announced_off(ring, info) -> list[str]:
    """The ring's turn a motor step where IRINF cannot carry it (whole millidegrees, a belt
    ratio of denominator ≤ 10 000) to 0.01 %: a host told only the IRINF would turn every
    reading's angle by that much too little or too far."""
    true = math.degrees(ring.motor_step_rad) * ring.gear
    sent = info.step_mdeg / 1000 * info.gear_num / info.gear_den
    off = sent / true - 1
    if abs(off) < ANNOUNCED_TOLERANCE:
        return []
    step = math.degrees(ring.motor_step_rad)
    return [f"the ring turns its sensors {true:.6g}° a motor step ({step:.6g}° × gear "
            f"{ring.gear:.6g}); IRINF, in whole millidegrees and a belt ratio of "
            f"denominator ≤ 10 000, says {sent:.6g}° ({info.step_mdeg / 1000:g}° × "
            f"{info.gear_num}/{info.gear_den}), {abs(off):.2%} {'more' if off > 0 else 'less'}: "
            f"`irring drive` without --truth turns every reading's angle that much off (with "
            f"--truth it takes the scenario's)"]


def _exposed(given: str, host: str) -> str:
    """The warning for a listener on an address other machines may reach."""
    loopback = "[::1]" if ":" in host else "127.0.0.1"   # the same family: it binds
    return (f"--tcp {given} serves the ring to every machine that can reach {host}, with no "
            f"authentication; use {loopback} to keep it on this machine")


def _bind_hint(exc: BaseException, host: str) -> str:
    """What --tcp allows, after the reason a listener could not open there ('' if none)."""
    local = "name an address of this machine (127.0.0.1, [::1]) or a name it resolves"
    code = getattr(exc, "errno", None)
    if isinstance(exc, socket.gaierror):
        return f"; {local}"
    if code == errno.EADDRINUSE:
        return "; another program listens there: pick another PORT, or 0 for a free one"
    if code == errno.EACCES:
        return "; ports below 1024 need privileges: pick PORT 1024 … 65535, or 0 for any"
    if code == errno.EINVAL and host.lower().startswith("fe80:") and "%" not in host:
        # the kernel cannot tell which interface's fe80::/10 is meant
        return (f"; a link-local address needs its interface ([{host}%eth0], as `ip addr` "
                f"names it), or {local}")
    if code in (errno.EADDRNOTAVAIL, errno.EINVAL):
        return ("; not an address of this machine: name one (127.0.0.1, [::1]) or a name it "
                "resolves")
    return ""


def _loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt
