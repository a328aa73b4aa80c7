"""What a failed `irring` command tells its user: one line and an exit status.

Every error a user can cause derives from :class:`IrringError`, whose ``status`` is the
command's exit status (the constants below); :func:`describe` turns it, or anything
unexpected, into one printable line and a status. Imports nothing of irring, so any module
can raise these.
"""

from __future__ import annotations

import contextlib
import errno
import os
import reprlib
import signal
import sys
import threading
from typing import Callable, Iterator

OK = 0             # done
INPUT = 1          # bad input: a scenario, recording, calibration or sensor-curve file
USAGE = 2          # bad usage: an option or argument (argparse's own status)
DEVICE = 3         # the device: no answer, disconnected, error replies, no progress
OUTPUT = 4         # an output could not be written (--out not a writable folder, disk full)
TOO_BIG = 5        # refused up front as too big for memory (the message says what it needs)
TARGET_MISSED = 6  # a benchmark's target missed (its figures printed as usual)
INTERNAL = 70      # an internal error (a bug: please report it with --debug's traceback),
                   # or a compiled kernel not built or built from another .pyx (KernelError)
INTERRUPTED = 130  # interrupted (Ctrl-C)

DEBUG_ENV = "IRRING_DEBUG"   # set to 1 for a traceback with every error
MAX_MESSAGE = 400            # characters of an error line


class IrringError(Exception):
    """An error the user can fix; ``status`` is the exit status it ends the command with."""

    status = INPUT


class InputError(IrringError, ValueError):
    """A file (or its contents) that irring cannot use."""


class UsageError(IrringError, ValueError):
    status = USAGE


class DeviceError(IrringError, RuntimeError):
    """The ring cannot be used as asked; the message says what to check."""

    status = DEVICE


class OutputError(IrringError, OSError):
    status = OUTPUT


class KernelError(IrringError, ImportError):
    """A compiled kernel that cannot be used (not built, or built from another version of
    its source); the message names it and the command that rebuilds it."""

    status = INTERNAL


class TooBig(IrringError, ValueError):
    """Work whose memory would exceed the budget, refused before allocating it."""

    status = TOO_BIG


def lengths_differ(what: str, **lengths: int) -> ValueError:
    """The error a compiled kernel raises for arrays that must share a length, naming each
    length: ``lengths_differ("readings", x=5, y=4)`` says "readings differ in length: x 5, y 4"."""
    return ValueError(f"{what} differ in length: "
                      + ", ".join(f"{name} {n}" for name, n in lengths.items()))


_repr = reprlib.Repr()
_repr.maxstring = _repr.maxother = 60
_repr.maxlist = _repr.maxtuple = _repr.maxdict = _repr.maxset = 6
_repr.maxlevel = 3


def brief(value: object) -> str:
    """A bounded, printable repr of a value from a file, for an error message."""
    return printable(_repr.repr(value))


# A spreadsheet opening a CSV takes a cell that begins with one of these for a formula and
# runs it (OWASP's "CSV injection"); a name irring writes into a CSV may not begin so.
FORMULA_STARTS = "=+-@"


def formula_start(name: str) -> str | None:
    """Why ``name`` (of a design or room, written to CSV files) may not be one, or None."""
    if name[:1] not in FORMULA_STARTS:
        return None
    return (f"{brief(name)} begins with {name[0]!r}, which a spreadsheet opening the CSV "
            f"files it is written to would run as a formula; begin it with none of "
            f"{' '.join(FORMULA_STARTS)}")


def printable(text: str, limit: int = MAX_MESSAGE) -> str:
    """``text`` on one line, control characters (terminal escapes) shown escaped, cut to
    ``limit`` characters."""
    text = str(text)
    if len(text) > 4 * limit:
        text = text[:4 * limit]
    out = []
    for ch in text:
        if ch in "\n\r\t":
            out.append(" ")
        elif ch.isprintable():
            out.append(ch)
        else:
            out.append(ch.encode("unicode_escape").decode("ascii"))
    line = " ".join("".join(out).split())
    return line if len(line) <= limit else line[:limit - 1] + "…"


def debug_requested() -> bool:
    return os.environ.get(DEBUG_ENV, "").strip() not in ("", "0", "false", "no")


def describe(exc: BaseException) -> tuple[int, str]:
    """(exit status, one-line message) for an exception that ended a command."""
    if isinstance(exc, IrringError):
        return exc.status, printable(str(exc) or type(exc).__name__)
    if isinstance(exc, MemoryError):
        return TOO_BIG, ("ran out of memory; the input asks for more than this machine has "
                         "(make the room, grid or number of poses smaller)")
    if isinstance(exc, RecursionError):
        return INPUT, "the input is nested too deeply to read"
    if isinstance(exc, RuntimeError) and "environment variable MUJOCO_GL" in str(exc):
        # raised by `import mujoco` (mujoco/gl_context.py) for a value it does not take
        value = os.environ.get("MUJOCO_GL", "")
        return USAGE, printable(f"MUJOCO_GL={value!r} is not a value MuJoCo takes; set "
                                f"MUJOCO_GL=egl or osmesa (pictures without a display), glfw "
                                f"(with a display), or unset it")
    if isinstance(exc, ImportError) and "PYOPENGL_PLATFORM environment variable" in str(exc):
        # raised by `import mujoco.osmesa` (or .egl) when the user's value names another
        backend = "egl" if "Cannot use EGL" in str(exc) else "osmesa"
        value = os.environ.get("PYOPENGL_PLATFORM", "")
        return USAGE, printable(f"PYOPENGL_PLATFORM={value!r} is not the OpenGL platform "
                                f"MuJoCo draws this picture with ({backend}); unset it, or set "
                                f"it (and MUJOCO_GL) to {backend}")
    serial = sys.modules.get("serial")  # not imported: then no pyserial error can be raised
    if serial is not None and isinstance(exc, serial.SerialException):
        return DEVICE, printable(str(exc) or type(exc).__name__)
    if isinstance(exc, OSError):
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        why = exc.strerror or str(exc)
        if exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EFBIG):
            return OUTPUT, printable(f"{where}{why}")
        return INPUT, printable(f"{where}{why}")
    return INTERNAL, printable(f"internal error ({type(exc).__name__}: {exc}); rerun with "
                               f"--debug (or {DEBUG_ENV}=1) for the traceback and please report it")


# SIGTERM: `kill`, timeout(1), a scheduler; SIGHUP: the terminal or SSH session closed,
# which killed a drive or a guided calibration outright and lost every pose swept
_STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP")
                      if hasattr(signal, name))


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """SIGTERM (`kill`) and SIGHUP (the terminal closed) end the block as Ctrl-C does
    (KeyboardInterrupt), so what the command does on Ctrl-C (stop a worker pool, write what
    a drive swept, keep a calibration's placements) happens too, instead of the process
    dying; only for a signal nobody else handles (not under nohup)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    mine = [s for s in _STOP_SIGNALS if signal.getsignal(s) is signal.SIG_DFL]

    def interrupt(signum, frame):
        if signum != signal.SIGTERM:
            _leave_terminal()
        raise KeyboardInterrupt

    for s in mine:
        signal.signal(s, interrupt)
    try:
        yield
    finally:
        for s in mine:
            signal.signal(s, signal.SIG_DFL)


@contextlib.contextmanager
def interrupts_noted(note: Callable[[], None]) -> Iterator[None]:
    """Ctrl-C, SIGTERM and SIGHUP call ``note()`` instead of raising KeyboardInterrupt in
    the block (their handlers' other work, leaving a hung-up terminal, is done), for a
    block that must not be cut short: in the main thread, for signals Python handles."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, *_STOP_SIGNALS)}
    previous = {s: h for s, h in previous.items() if callable(h)}

    def noted(signum, frame):
        note()
        try:
            previous[signum](signum, frame)
        except KeyboardInterrupt:
            pass

    for s in previous:
        signal.signal(s, noted)
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def interrupted(exc: BaseException) -> bool:
    """``exc`` is Ctrl-C (or a SIGTERM, SIGHUP raised as it), or an error it caused: one
    landing in a C extension's import (MuJoCo's) comes out as ImportError("initialization
    failed") with the KeyboardInterrupt in its context."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def _leave_terminal() -> None:
    """Point the standard streams that are a (hung-up) terminal at /dev/null: writing a
    message there fails (EIO) before the outputs are written, and input ends."""
    for fd in (0, 1, 2):
        try:
            if os.isatty(fd):
                null = os.open(os.devnull, os.O_RDWR)
                os.dup2(null, fd)
                os.close(null)
        except OSError:
            pass
