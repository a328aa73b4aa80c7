"""Argument parsing shared by several subcommands (not a subcommand itself).

The ``type=`` callables here raise ``argparse.ArgumentTypeError`` on a bad value, so
argparse prints the usage line and ``irring COMMAND: error: argument --OPTION: …`` and
exits 2, like any other bad argument (exit 1 is left for runs that fail).
:class:`LazyParser` lets ``irring X`` import only subcommand X's module.
"""

from __future__ import annotations

import argparse
import difflib
import importlib.util
import math
import os
import re
import sys
import textwrap
import urllib.parse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..core import HOUSING_M, MAX_SEEDS, NETWORK_URL_SCHEMES, SEED_MAX
from ..errors import UsageError, brief
from ..outputs import MCAP_FILE, RUN_FILES, check_out, check_replaceable, real_path


def _is_number(word: str) -> bool:
    try:
        float(word)
        return True
    except ValueError:
        return False


class _StoreOnce(argparse._StoreAction):
    """argparse's store, refusing an option given twice with other values: argparse kept
    the last without a word, so `--seeds 2 --seeds 3` ran seed 3 alone and `--seed 3
    --seed 4` ran 4. The same value twice is harmless and kept."""

    def __call__(self, parser, namespace, values, option_string=None):
        given = namespace.__dict__.setdefault(_GIVEN, {})
        typed = " ".join(getattr(parser, "_typed", ()))
        if self.dest in given and given[self.dest][1] not in (values, typed):
            first = given[self.dest][0]
            if self.nargs in ("+", "*"):
                hint = f"list every value after one {option_string} ({option_string} " \
                       f"{first} {typed})"
            else:
                hint = "it takes one value, so give it once"
            raise argparse.ArgumentError(
                self, f"given twice ({brief(first)}, then {brief(typed)}); {hint}")
        given[self.dest] = (typed, values)
        super().__call__(parser, namespace, values, option_string)


_GIVEN = "_irring_given"   # the namespace's record of what _StoreOnce stored (removed after)


class Parser(argparse.ArgumentParser):
    """argparse's parser whose help, when it cannot be written, is an error: argparse drops
    the write's error, so `irring --help > /dev/full` printed nothing and exited 0; and
    whose options refuse a second, other value (:class:`_StoreOnce`)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.register("action", None, _StoreOnce)
        self.register("action", "store", _StoreOnce)

    def parse_known_args(self, args=None, namespace=None):
        namespace, extras = super().parse_known_args(args, namespace)
        namespace.__dict__.pop(_GIVEN, None)
        return namespace, extras

    def _get_values(self, action, arg_strings):
        self._typed = arg_strings   # the words as typed, for _StoreOnce's message
        return super()._get_values(action, arg_strings)

    def print_help(self, file=None) -> None:
        out = file or sys.stdout
        out.write(self.format_help())
        out.flush()


class LazyParser(Parser):
    """A subcommand's parser that imports its module and lets it ``register(self)`` (long
    help, arguments, ``func``) the first time it parses, or prints help or usage: building
    ``irring``'s parser then costs one line of help per subcommand, and ``irring run`` does
    not load what ``irring study`` or ``irring drive`` need (Dask, pyserial, …)."""

    module: str | None = None

    def _load(self) -> None:
        if self.module is not None:
            name, self.module = self.module, None
            importlib.import_module(name).register(self)

    def parse_known_args(self, args=None, namespace=None):
        self._load()
        namespace, extras = super().parse_known_args(args, namespace)
        if extras:   # else argparse reports them with `irring`'s usage, not this command's
            # an option among them is named alone: in `run --sed 4 t_room` the 4 took the
            # scenario's place, and "unrecognized arguments: --sed t_room" blamed t_room
            options = [w for w in extras if w.startswith("-") and not _is_number(w)]
            if options:
                self.error(f"unrecognized option{'s' * (len(options) > 1)}: "
                           f"{', '.join(w + self._near(w) for w in options)}")
            self.error(f"unrecognized arguments: {' '.join(extras)}")
        return namespace, extras

    def _near(self, word: str) -> str:
        """' (did you mean --seed?)' for a mistyped option ``word`` (--sed, --sed=4)."""
        names = [o[2:] for a in self._actions for o in a.option_strings if o.startswith("--")]
        if word.startswith("--"):   # compared without the "--" every option shares
            near = difflib.get_close_matches(word[2:].split("=")[0].lower(), names, n=1)
            if near:
                return f" (did you mean --{near[0]}?)"
        return ""

    def format_usage(self) -> str:
        self._load()
        return super().format_usage()

    def format_help(self) -> str:
        self._load()
        return super().format_help()


def add_subcommands(parser: argparse.ArgumentParser, dest: str, metavar: str,
                    commands: dict[str, str], module: Callable[[str], str]):
    """Subparsers ``commands`` (name → one-line help), each a :class:`LazyParser` filled in
    by module ``module(name)``; returns the subparsers action."""
    sub = parser.add_subparsers(dest=dest, metavar=metavar, parser_class=LazyParser)
    for name, help_line in commands.items():
        sub.add_parser(name, help=help_line).module = module(name)
    return sub


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Keeps the line breaks of a description and epilog (their indented tables and
    examples) but refills a paragraph of prose (lines that start at the margin) when one
    of its lines is wider than the terminal, as a description given on one line is."""

    def _fill_text(self, text, width, indent):
        lines, prose = [], []
        for line in [*text.splitlines(), ""]:
            if line[:1].strip():
                prose.append(line)
                continue
            if any(len(p) > width for p in prose):
                prose = textwrap.wrap(" ".join(prose), width, break_on_hyphens=False)
            lines += [*prose, line]
            prose = []
        return "\n".join(indent + line for line in lines[:-1])


def describe(p: argparse.ArgumentParser, description: str, epilog: str | None = None, *,
             raw: bool = True) -> None:
    """Set a subcommand's long help (its one-line help is where it is listed);
    ``raw``: print the texts with their own line breaks (a line of prose wider than the
    terminal is still wrapped, :class:`HelpFormatter`)."""
    p.description, p.epilog = description, epilog
    if raw:
        p.formatter_class = HelpFormatter


# a word argparse reads as a number, not an option: -5, -0.5 (its own test); and a word
# that begins as a negative number but is not one to argparse: -500,450 or -1e3
_PLAIN_NEGATIVE = re.compile(r"^-\d+$|^-\d*\.\d+$")
_NEGATIVE_START = re.compile(r"^-\.?\d")


def glue_negative_values(argv: list[str]) -> list[str]:
    """``--pose -500,450`` as ``--pose=-500,450``: argparse took ``-500,450`` (and ``-1e3``)
    for an option and said only "expected one argument". Only words argparse refused are
    glued to the option before them; ``--`` ends the options."""
    out: list[str] = []
    for i, word in enumerate(argv):
        if word == "--":
            return out + argv[i:]
        before = out[-1] if out else ""
        if (_NEGATIVE_START.match(word) and not _PLAIN_NEGATIVE.match(word)
                and before.startswith("--") and before != "--" and "=" not in before):
            out[-1] = f"{before}={word}"
        else:
            out.append(word)
    return out


def _integer(text: str, allowed: str) -> int:
    """``int(text)``, or the usage error saying what is ``allowed``."""
    try:
        return int(text)
    except ValueError:
        digits = text.strip().lstrip("+-").replace("_", "")
        if digits.isdigit():   # int() refuses more than 4,300 digits: still a number
            raise argparse.ArgumentTypeError(f"must be {allowed}, got a number of "
                                             f"{len(digits):,} digits") from None
        raise argparse.ArgumentTypeError(f"must be an integer {allowed}, got "
                                         f"{brief(text)}") from None


def at_least(low: int, high: int | None = None) -> Callable[[str], int]:
    """A ``type=`` for an integer option that must be ≥ ``low`` (and ≤ ``high`` if given)."""
    allowed = f"≥ {low}" if high is None else f"in {low} … {high}"

    def parse(text: str) -> int:
        value = _integer(text, allowed)
        if value < low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"must be {allowed}, got {brief(value)}")
        return value

    parse.__name__ = f"int {allowed}"
    return parse


MAX_DISTANCE_M = 100.0   # --distances-mm: far beyond any ring's reach, short of float overflow


def distances_mm(text: str) -> list[float]:
    """A ``type=`` for ``--distances-mm`` "250,500,1000" (mm) → metres: at least one
    number, all positive and at most :data:`MAX_DISTANCE_M`."""
    try:
        values = [float(v) * 1e-3 for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be positive distances in mm separated by commas, like 250,500,1000; "
            f"got {text!r}") from None
    if not values or not all(math.isfinite(v) and 0 < v <= MAX_DISTANCE_M for v in values):
        raise argparse.ArgumentTypeError(
            f"must be one or more positive distances in mm up to {MAX_DISTANCE_M * 1e3:g}, "
            f"like 250,500,1000; got {text!r}")
    return values


def check_distances_clear(distances_m, design_list) -> None:
    """:class:`UsageError` when a ``--distances-mm`` value (robot centre to the cylinder's
    near side) puts the cylinder within a design's ring and housing (radius + ``HOUSING_M``):
    such a cylinder is inside the robot and every bearing would read as a miss."""
    for design in design_list:
        reach_m = design.ring.radius_m + HOUSING_M
        inside = [d for d in distances_m if d <= reach_m]
        if inside:
            raise UsageError(
                f"--distances-mm {inside[0] * 1e3:g}: a cylinder that near is inside "
                f"{design.name}'s housing (ring radius {design.ring.radius_m * 1e3:g} mm + "
                f"{HOUSING_M * 1e3:g} mm); give distances in mm beyond {reach_m * 1e3:g}, "
                "like 250,350,450")


def add_pose_option(parser: argparse.ArgumentParser, default: int | None, what: str) -> None:
    """``--pose K``: a scan pose by number, 1 … N, as map.png and the progress lines number
    poses (everything a user types or reads counts poses from 1); :func:`pose_index` checks
    it against the scenario."""
    parser.add_argument("--pose", type=at_least(1), default=default, metavar="K",
                        help=f"{what}: scan pose K of the scenario, numbered 1 … N as on "
                             "map.png" + (f" (default: {default})" if default else ""))


def pose_index(number: int, scenario, option: str = "--pose") -> int:
    """The 0-based index of scan pose ``number`` (1 … N) of ``scenario``. Raises
    UsageError naming the option and the poses there are."""
    n = len(scenario.robot.poses)
    if not 1 <= number <= n:
        raise UsageError(f"{option} {number} is out of range: scenario {scenario.name!r} has "
                         f"{n} scan pose(s), 1 … {n}")
    return number - 1


def named_once(values, option: str, same: Callable = lambda value: value) -> None:
    """:class:`UsageError` when two of ``values`` of a repeatable ``option`` are the same
    (``same(value)`` equal: e.g. a scenario's file): run twice, it would weigh twice in the
    means and the summary count it as another one."""
    seen: dict = {}
    for value in values:
        key = same(value)
        if key in seen:
            given = "" if seen[key] == value else f" (as {seen[key]} and {value})"
            raise UsageError(f"{option} {value}: given twice{given}; it would be run and "
                             "counted in the means twice, so name each once")
        seen[key] = value


def given(what: str, kind: Callable[[str], Any] = str) -> Callable[[str], Any]:
    """A ``type=`` for a file or scenario a user names: an empty one (``irring run "$ROOM"``
    with ROOM unset) ran the default scenario into its folder, or read the current folder as
    ``.``, without a word."""
    def parse(text: str) -> Any:
        if not text.strip():
            raise argparse.ArgumentTypeError(f"an empty name; name {what}")
        return kind(text)

    parse.__name__ = what
    return parse


scenario_name = given("a bundled scenario (irring scenarios lists them) or a YAML file")
scenarios_or_folders = given("a bundled scenario (irring scenarios lists them) or a YAML "
                             "file, or a folder of them")


def out_path(text: str) -> Path:
    """``--out``'s value: an empty one (``--out "$DIR"`` with DIR unset) wrote into the
    current folder, or the default, without a word."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty path; name a folder or file (. is the "
                                         "current folder)")
    return Path(text)


def spare_inputs(outputs: dict, inputs: dict) -> None:
    """:class:`UsageError` when a file the command writes (``{option: path}``) is one it
    reads: ``irring run my.yaml --mcap my.yaml`` replaced the scenario with MCAP bytes."""
    for out_option, out in outputs.items():
        if out is None or not Path(out).is_file():
            continue
        for in_option, path in inputs.items():
            if path is not None and Path(path).is_file() and os.path.samefile(out, path):
                raise UsageError(f"{out_option} {out}: is the file {in_option} {path}, which "
                                 "this command reads; writing there would replace it, so name "
                                 "another file")


def mcap_beside_outputs(mcap: Path | None, out: Path) -> None:
    """:class:`UsageError` when ``--mcap`` names one of the files a run writes into ``out``:
    ``irring run t_room --out o --mcap o/sweeps.npz`` left MCAP bytes where the recording
    was (the MCAP is renamed in after the set; map.mcap is the one name kept for it);
    :class:`OutputError` when its folder cannot be written (checked before the work).
    :class:`UsageError` too when it names ``out`` or a folder holding it: ``--out o --mcap
    o`` wrote the whole set, then failed (exit 4) on the folder it had made."""
    if mcap is None:
        return
    mcap_at, out_at = real_path(mcap), real_path(out)
    if mcap_at == out_at or mcap_at in out_at.parents:
        raise UsageError(f"--mcap {mcap}: is the folder --out {out} or holds it, and this "
                         f"command writes its outputs there; name a file (such as "
                         f"{Path(out) / 'map.mcap'})")
    # before the work, as --out is: a read-only folder failed after the whole run
    check_out(mcap.parent, "--mcap")
    if mcap.name in RUN_FILES - {"map.mcap"} and real_path(mcap.absolute().parent) == out_at:
        raise UsageError(f"--mcap {mcap}: is the {mcap.name} this command writes into --out "
                         f"{out}; the MCAP would replace it, so name another file (such as "
                         f"{Path(out) / 'map.mcap'})")
    check_replaceable(mcap, "--mcap", MCAP_FILE)


def mcap_file(text: str) -> Path:
    """``--mcap``'s value, refused before any work when the mcap extra is not installed or
    it names a folder or a device (outputs.atomic_file would refuse it after the work)."""
    if importlib.util.find_spec("mcap_ros2") is None:
        raise argparse.ArgumentTypeError(
            f"writing {text} needs the mcap extra: pip install 'irring[mcap]'")
    if not text.strip():   # Path('') is '.', told as 'is a folder' under an empty name
        raise argparse.ArgumentTypeError("an empty path; name a file (such as map.mcap)")
    path = Path(text)
    try:
        if path.exists() and not path.is_file():
            raise argparse.ArgumentTypeError(f"{text}: is a folder or a device; name a file")
    except OSError as exc:   # a name too long: argparse would let it escape as exit 1
        raise argparse.ArgumentTypeError(f"{text}: {exc.strerror or exc}") from None
    return path


def add_protocol_v1_option(parser: argparse.ArgumentParser, when: str = "") -> None:
    """``--accept-protocol-v1``: speak v1 to an old ring (SerialRing's ``accept_v1``)."""
    parser.add_argument("--accept-protocol-v1", action="store_true", dest="accept_v1",
                        help=f"{when}use a ring whose firmware speaks IRR protocol v1 (an 8-bit XOR "
                             "checksum: two bit errors in one bit column pass as changed "
                             "readings) with a warning, instead of refusing it; better, "
                             "reflash it (firmware/README.md)")


def warn_protocol(ring, say) -> None:
    """Print the link's protocol warning (a v1 ring accepted), if any, through ``say``."""
    if ring.protocol_warning:
        say(f"warning: {ring.protocol_warning}")


def add_mcap_option(parser: argparse.ArgumentParser) -> None:
    """``--mcap FILE``: the run as MCAP for Foxglove / rosbag2 (irring/maps/mcap_export.py)."""
    parser.add_argument("--mcap", type=mcap_file, default=None, metavar="FILE",
                        help="also write the run as MCAP with ROS 2 messages (each sweep's "
                             "end points, the ring pose on /tf, the map, the true outline), "
                             "for Foxglove or rosbag2; needs pip install 'irring[mcap]'")


def add_executor_options(p: argparse.ArgumentParser) -> None:
    """``--workers N`` or ``--dask ADDRESS``: where a multi-run command runs its runs
    (``irring.studies.executor.executor(args.workers, args.dask)``)."""
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=at_least(1), default=None, metavar="N",
                       help="local worker processes (≥ 1; default: one per CPU; 1 = in this "
                            "process)")
    where.add_argument("--dask", metavar="ADDRESS", default=None,
                       help="run on the Dask cluster whose scheduler is at ADDRESS "
                            "(tcp://host:8786) instead; needs pip install 'irring[dask]'")


def between(low: int, high: int) -> Callable[[str], int]:
    """A ``type=`` for an integer option that must lie in ``low`` … ``high``."""

    def parse(text: str) -> int:
        value = _integer(text, f"{low} … {high}")
        if value < low:
            raise argparse.ArgumentTypeError(f"must be ≥ {low}, got {brief(value)}")
        if value > high:
            raise argparse.ArgumentTypeError(f"must be {low} … {high}, got {brief(value)}")
        return value

    parse.__name__ = f"int {low} … {high}"
    return parse


# a seed option takes what a scenario's seed: takes
seed = between(0, SEED_MAX)
# how many seeds an option may ask for: what a study file may (its runs' memory and time
# grow with them; 10^12 ran out of memory)
seed_count = at_least(1, MAX_SEEDS)


def number_in(low: float, high: float, *, low_open: bool = False) -> Callable[[str], float]:
    """A ``type=`` for a finite number in ``low`` … ``high`` (``low`` excluded when
    ``low_open``); NaN and infinities are refused."""
    lo_text = f"> {low:g}" if low_open else f"≥ {low:g}"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and (value > low if low_open else value >= low)
                and value <= high):
            raise argparse.ArgumentTypeError(f"must be a number {lo_text} and ≤ {high:g}, "
                                             f"got {text!r}")
        return value

    parse.__name__ = f"number {lo_text} … {high:g}"
    return parse


def positive_seconds(text: str) -> float:
    """A ``type=`` for a finite time in seconds > 0 (``--timeout``)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and 0 < value <= 3600):
        raise argparse.ArgumentTypeError(f"must be a number of seconds > 0 and ≤ 3600, "
                                         f"got {text!r}")
    return value


def serial_port(text: str) -> str:
    """A ``type=`` for ``--port``: a device path, or a pyserial URL; a network URL must name
    its host and port (``socket://`` alone failed inside pyserial with "'<=' not supported
    between instances of 'int' and 'NoneType'" and advice to check /dev/ttyUSB*)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty port; name a device (/dev/ttyUSB0, a pty) "
                                         "or a URL (socket://HOST:PORT)")
    scheme = text.partition("://")[0].lower() if "://" in text else ""
    if scheme in NETWORK_URL_SCHEMES:
        parts = urllib.parse.urlsplit(text)
        try:
            port = parts.port
        except ValueError:
            port = None
        if not parts.hostname or port is None or not 1 <= port <= 65535:
            raise argparse.ArgumentTypeError(f"expected {scheme}://HOST:PORT with PORT 1 … "
                                             f"65535, got {text!r}")
    return text


def host_port(text: str) -> tuple[str, int]:
    """A ``type=`` for ``[HOST:]PORT`` (PORT 0 … 65535; HOST defaults to 127.0.0.1)."""
    host, _, port = text.rpartition(":")
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not 0 <= number <= 65535:
        raise argparse.ArgumentTypeError(f"expected [HOST:]PORT with PORT 0 … 65535, "
                                         f"got {text!r}")
    return host.strip("[]") or "127.0.0.1", number


def add_room_set_options(p: argparse.ArgumentParser, default_rooms: str, seeds: int,
                         out: str, written: str) -> None:
    """The options of a bench over a set of rooms: ROOM…, --seeds, --out, --json.
    ``default_rooms`` names what runs without ROOM; ``written`` the files --out receives."""
    p.add_argument("rooms", nargs="*", metavar="ROOM",
                   type=scenarios_or_folders,
                   help="bundled scenario names, YAML files or folders of them "
                        f"(default: {default_rooms})")
    p.add_argument("--seeds", type=seed_count, default=seeds, metavar="N",
                   help=f"seeds per room: the scenario's seed, +1, … (1 … {MAX_SEEDS}; "
                        f"default: {seeds})")
    p.add_argument("--out", type=out_path, default=out, metavar="DIR",
                   help=f"where {written} (default: {out})")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


# A map's scores as the bench tables print them: (score key, column label, scale, digits).
MAP_COLUMNS = (("occupied_f1", "F1", 1, 3), ("occupied_precision", "prec", 1, 3),
               ("occupied_recall", "rec", 1, 3), ("free_accuracy", "free", 1, 3))


