"""The `irring` command. Each subcommand lives in its own module under irring/cli/.

A module's ``register(parser)`` gives its parser the long help, the arguments and a
``func(args) -> int`` that does the work; it is imported only when that subcommand is
parsed or its help printed (``_common.LazyParser``), so `irring run` loads no other
subcommand's dependencies. Nothing below the cli imports it.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import os
import select
import signal
import sys
import traceback

from .. import errors, interrupted_starting
from ..resources import installed_version
from ._common import HelpFormatter, Parser, add_subcommands, glue_negative_values

# Subcommand modules → one-line help, in the order `irring --help` lists them.
COMMANDS = {
    "run": "map a scenario: simulate, estimate, map, score, draw",
    "replay": "estimate and map a recording (.npz) again",
    "view": "picture (or live viewer) of the MuJoCo scene with beams",
    "scenarios": "list the bundled scenarios, or check scenario files",
    "calibrate": "measure d_o and the sensor curve a(θ), b(θ); write a YAML file",
    "emulate": "a simulated ring device on a pseudo-terminal (try `drive` without hardware)",
    "drive": "sweep the real ring over a serial port, estimate and map",
    "geometry": "overlap angle/area (Eqs. 2–3, Monte Carlo) and blind spot (Eq. 1)",
    "compare": "compare ring designs on simulated scenes",
    "study": "run a grid of designs × scenarios × seeds × knobs (resumable)",
    "bench": "benchmarks: what accuracy costs in time, stage speeds",
}

DESCRIPTION = """\
irring: a MuJoCo testbed for the rotating infrared range-sensor ring of
Park, Baek & Lee (IEEE/ASME AIM 2005). Twelve Sharp GP2 sensors on a 0.15 m
ring turn ±37.8° together, so neighbouring beams overlap and the ring sees
past thin obstacles. Simulated and real (serial) sweeps go through the same
estimator and occupancy-grid mapper.

Start with `irring run` (the default scenario, t_room) and look at the map
it writes; `irring scenarios` lists the bundled scenarios."""


EPILOG = """\
exit status: 0 done; 1 bad input file (scenario, recording, calibration, study), or
calibrate --port stopped at its prompt (q, end of input), or view found no offscreen OpenGL
that works; 2 bad option, argument or MUJOCO_GL; 3 the device failed (no answer, disconnected, error replies, no progress); 4 an
output could not be written; 5 refused as too big for memory; 6 a benchmark's target missed
(bench speed --check, effects, rooms, foldover, grazing, link); 70 internal error (a bug, or a compiled kernel not
built or built from another .pyx: the message says how to rebuild); 130 interrupted
(or a worker process killed: out of memory, `kill`).
Errors are one line; --debug (anywhere on the line, or IRRING_DEBUG=1) adds the traceback.
Scan poses are numbered 1 … N everywhere (--pose K, map.png, progress)."""


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="irring", description=DESCRIPTION, epilog=EPILOG,
        formatter_class=HelpFormatter)
    parser.add_argument("--version", action=_Version,
                        help="show program's version number and exit")
    parser.add_argument("--debug", action="store_true",
                        help="print the traceback of an error (also: IRRING_DEBUG=1)")
    add_subcommands(parser, "command", "COMMAND", COMMANDS, lambda name: f"{__name__}.{name}")
    return parser


class _Version(argparse.Action):
    """argparse's "version" action, asking for the version only when --version is given."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help=None):
        super().__init__(option_strings, dest, nargs=0, default=default, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"irring {installed_version()}")
        parser.exit()


_SILENT = logging.NullHandler()


def main(argv: list[str] | None = None) -> int:
    """Run one `irring` command; every failure ends as one line on stderr and an exit
    status (irring.errors), with a traceback only under --debug or IRRING_DEBUG=1."""
    if signal.getsignal(signal.SIGINT) is interrupted_starting:
        signal.signal(signal.SIGINT, signal.default_int_handler)   # ours from here on
    argv = list(sys.argv[1:] if argv is None else argv)
    # the library's warnings (a ring not turned back, protocol v1) are the commands' to
    # print, once: unhandled, Python's last-resort handler printed each a second time
    logging.getLogger("irring").addHandler(_SILENT)
    debug = "--debug" in argv or errors.debug_requested()
    argv = glue_negative_values([a for a in argv if a != "--debug"])
    command = "irring"
    # the first word that is not an option names the subcommand (before parsing: a
    # subcommand's module may load MuJoCo when it is imported)
    word = next((a for a in argv if not a.startswith("-")), "")
    _hold_closed_streams()
    _escape_what_streams_cannot_encode()
    stdout, sys.stdout = sys.stdout, _NamedStream(sys.stdout, "standard output")
    try:
        # `kill` (SIGTERM) stops a command as Ctrl-C does: killed outright, it left its
        # half-written output folder or file (.irring-*) beside --out
        with _no_opengl(word != "view"), _no_mpl_backend(), errors.sigterm_as_interrupt():
            parser = build_parser()
            args = parser.parse_args(argv)
            if not getattr(args, "func", None):
                parser.print_help()
                return errors.USAGE
            # `irring bench rooms: error: …`, as the bench's own errors name it
            command = " ".join(["irring", args.command, *([args.bench] if getattr(
                args, "bench", None) else [])])
            args.debug = debug   # for commands that report an error and go on (bench rooms)
            return int(args.func(args) or 0)
    except SystemExit:
        raise
    except BaseException as exc:  # noqa: BLE001 - the one place every error becomes a line
        if debug:
            traceback.print_exc()
        if errors.interrupted(exc):
            print(f"{command}: interrupted", file=sys.stderr)
            return errors.INTERRUPTED
        status, message = errors.describe(exc)
        if isinstance(exc, BrokenPipeError) and _stdout_gone():
            # the reader left (`irring geometry | head`): an output not written, said by the
            # status alone, as other tools do; what stdout still buffers goes nowhere
            # instead of failing again at exit
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return errors.OUTPUT
        try:
            print(f"{command}: error: {message}", file=sys.stderr)
        except (OSError, ValueError):  # stderr itself is gone
            pass
        return status
    finally:
        sys.stdout = stdout


def _hold_closed_streams() -> None:
    """A standard stream closed when irring started (`irring … >&-`, a daemon's) is None in
    Python, and its descriptor is free: the next file opened takes it, and whatever writes
    to that descriptor lands in the file. /dev/null holds it instead: a closed standard
    input reads as ended (no terminal to wait at), writing to a closed standard output is an
    output error (exit 4), messages to a closed standard error go nowhere (the exit status
    still tells)."""
    closed = [(fd, name) for fd, name in ((0, "stdin"), (1, "stdout"), (2, "stderr"))
              if getattr(sys, name) is None]
    for fd, _ in closed:   # every descriptor first, before a stream below opens a file
        try:
            os.fstat(fd)
        except OSError:   # still free (if a file took it meanwhile, it stays that file's)
            null = os.open(os.devnull, os.O_RDWR)
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
    for fd, name in closed:
        setattr(sys, name, open(os.devnull) if fd == 0 else _Closed("standard output")
                if fd == 1 else open(os.devnull, "w"))


class _Closed(io.TextIOBase):
    """A standard stream that was closed: every write fails naming it."""

    def __init__(self, name: str):
        self.name = name

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        raise errors.OutputError(f"{self.name} is closed (as by >&-), so nothing can be "
                                 f"written to it")


class _NamedStream:
    """A text stream whose write errors name it: ``irring run --json > /dev/full`` said
    only 'No space left on device', after the outputs in --out were written whole."""

    def __init__(self, stream, name: str):
        self._stream, self._name = stream, name

    def _named(self, call, *args):
        try:
            return call(*args)
        except OSError as exc:
            if exc.filename is not None or exc.errno is None:
                raise
            raise OSError(exc.errno, exc.strerror, self._name) from exc   # EPIPE: BrokenPipeError

    def write(self, text: str) -> int:
        return self._named(self._stream.write, text)

    def flush(self) -> None:
        return self._named(self._stream.flush)

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def _stdout_gone() -> bool:
    """True when stdout is a pipe whose reader has closed it."""
    try:
        poll = select.poll()
        poll.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & select.POLLERR for _, events in poll.poll(0))
    except (AttributeError, OSError, ValueError):   # no poll(), no real stdout
        return False


def _escape_what_streams_cannot_encode() -> None:
    """A terminal or PYTHONIOENCODING that cannot show Φ, θ or — (ascii, latin-1) gets
    them as \\u escapes, as Python's stderr already does: every report has them, and
    each ended in exit 70 (UnicodeEncodeError) instead."""
    for stream in (sys.stdout, sys.stderr):
        try:
            "Φθ—×…".encode(stream.encoding)
        except (UnicodeEncodeError, LookupError, TypeError, AttributeError):
            try:
                stream.reconfigure(errors="backslashreplace")
            except (AttributeError, ValueError, OSError):   # not a text file of its own
                pass


@contextlib.contextmanager
def _no_mpl_backend():
    """irring draws its charts on its own Agg canvas (maps.render.figure) and opens no
    window, so MPLBACKEND has nothing to choose for it; a value matplotlib does not know
    made importing it fail, after the work, where a chart was to be drawn."""
    value = os.environ.pop("MPLBACKEND", None)
    try:
        yield
    finally:
        if value is not None:
            os.environ["MPLBACKEND"] = value


@contextlib.contextmanager
def _no_opengl(applies: bool):
    """Importing MuJoCo loads the OpenGL library MUJOCO_GL names (GLFW if unset); only
    `irring view` draws with it, so the others import it with none, whatever the user's
    MUJOCO_GL (an egl exported on a machine without EGL failed every run). The user's
    value is back when the command ends."""
    if not applies or "mujoco" in sys.modules:
        yield
        return
    users = os.environ.get("MUJOCO_GL")
    os.environ["MUJOCO_GL"] = "disable"
    try:
        yield
    finally:
        if users is None:
            os.environ.pop("MUJOCO_GL", None)
        else:
            os.environ["MUJOCO_GL"] = users


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
