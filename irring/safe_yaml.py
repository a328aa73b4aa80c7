"""The one YAML reader for every file a user hands irring (scenarios, calibrations, sensor
curves, the scenario inside a recording, study files).

PyYAML's ``safe_load`` builds no objects, but it still lets the last of two equal keys win
silently, expands aliases (a 562-byte "billion laughs" file grows to gigabytes) and recurses
once per nesting level. :func:`load` refuses these and a file past its kind's
:data:`LIMITS`, :func:`read_text` what is not a readable UTF-8 file, each with one line
naming the file and the line. Numbers read as written (``1e-3``); YAML 1.1's octal ``0750``
and base-60 ``1:30`` are refused.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from .errors import InputError, brief

MAX_DEPTH = 64             # nesting levels; irring's deepest schema uses 5
MAX_BYTES = 8 * 2**20      # a scenario with 100k outline corners is ~3 MB
MAX_VALUES = 1_000_000     # scalars, lists and mappings of one file (a scenario of 10,000
#                            corners, 10,000 poses and 10,000 obstacles has ~190,000)
MAX_DIGITS = 100           # of a whole number: more than any file's field takes (a float
#                            overflows at 309 digits; Python refuses to parse 4,300)

# YAML 1.2's exponent floats without a dot or without the exponent's sign (1e-3, 1.0e300),
# which YAML 1.1 reads as text
_EXPONENT_FLOAT = re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9_]+$")
_FLOAT_TAG = "tag:yaml.org,2002:float"
_UNKNOWN_TAG = re.compile(r"could not determine a constructor for the tag '(.*)'", re.S)


# (bytes, values) a kind of file may have, checked before a value is built (building one
# costs far more than parsing it); the smaller kinds are far from their limits in use (a
# calibration `irring calibrate` writes is 2 kB, 130 values) and refuse a wrong or runaway
# file at once instead of after minutes
LIMITS = {
    "scenario file": (MAX_BYTES, MAX_VALUES),
    "calibration file": (2**20, 100_000),   # calibration.MAX_CURVE_ROWS rows as saved
    "calibration progress file": (MAX_BYTES, MAX_VALUES),
    "study file": (2**20, 100_000),
    "sensor curve file": (2**20, 100_000),
    "map_server YAML": (2**16, 1_000),
}


def limits(what: str) -> tuple[int, int]:
    """(bytes, values) a ``what`` (a key of :data:`LIMITS`) may have; any other kind gets
    the largest."""
    return LIMITS.get(what, (MAX_BYTES, MAX_VALUES))


class YamlError(InputError):
    """A YAML text irring refuses to read; the message names the source and line."""


# libyaml's parser (C, ~30× PyYAML's) feeds the Python composer, which does the checks;
# PyYAML's own reader, scanner and parser where PyYAML was built without libyaml
_PARSING = ((yaml.cyaml.CParser,) if yaml.__with_libyaml__ else
            (yaml.reader.Reader, yaml.scanner.Scanner, yaml.parser.Parser))


class _StrictLoader(yaml.composer.Composer, *_PARSING, yaml.constructor.SafeConstructor,
                    yaml.resolver.Resolver):
    """SafeLoader without aliases, duplicate keys, unbounded nesting or too many values."""

    def __init__(self, stream: str, source: str, what: str, max_values: int):
        if yaml.__with_libyaml__:
            yaml.cyaml.CParser.__init__(self, stream)
        else:
            yaml.reader.Reader.__init__(self, stream)
            yaml.scanner.Scanner.__init__(self)
            yaml.parser.Parser.__init__(self)
        yaml.composer.Composer.__init__(self)
        yaml.constructor.SafeConstructor.__init__(self)
        yaml.resolver.Resolver.__init__(self)
        self.source = source
        self.what = what
        self.max_values = max_values
        self.values = 0
        self.depth = 0

    def construct_object(self, node, deep=False):
        # a value PyYAML cannot build (a date 2026-13-45, `!!int x`) fails with a bare
        # ValueError: name the line and the value
        try:
            return super().construct_object(node, deep=deep)
        except YamlError:
            raise
        except (ValueError, OverflowError) as exc:
            raise self.fail(node.start_mark, f"{brief(node.value)} cannot be read as "
                                             f"{node.tag.rsplit(':', 1)[-1]}: {exc}") from None

    def construct_yaml_int(self, node):
        text = str(self.construct_scalar(node))
        digits = text.replace("_", "").lstrip("+-")
        if ":" in digits:
            raise self.fail(node.start_mark, f"{text} is a base-60 number in YAML 1.1 "
                                             f"({super().construct_yaml_int(node)}); write the "
                                             "number you mean, or quote it for text")
        if len(digits) > MAX_DIGITS:
            raise self.fail(node.start_mark, f"a whole number of {len(digits):,} digits; no "
                                             f"field takes one of more than {MAX_DIGITS}")
        value = super().construct_yaml_int(node)
        if (len(digits) > 1 and digits[0] == "0" and digits[1].isdigit()
                and value != int(text.replace("_", ""), 10)):
            raise self.fail(node.start_mark, f"{text} is an octal number in YAML 1.1 ({value}); "
                                             f"write it without the leading 0, or quote it for "
                                             "text")
        return value

    def construct_yaml_float(self, node):
        text = str(self.construct_scalar(node))
        if ":" in text:
            raise self.fail(node.start_mark, f"{text} is a base-60 number in YAML 1.1 "
                                             f"({super().construct_yaml_float(node)}); write the "
                                             "number you mean, or quote it for text")
        return super().construct_yaml_float(node)

    def fail(self, mark: Any, msg: str) -> YamlError:
        line = f"line {mark.line + 1}: " if mark is not None else ""
        return YamlError(f"{self.source}: {line}{msg}")

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise self.fail(event.start_mark, f"YAML aliases (*{brief(event.anchor)[1:-1]}) are "
                                              "not allowed; write the value out")
        self.values += 1
        if self.values > self.max_values:
            raise self.fail(self.peek_event().start_mark,
                            f"more than {self.max_values:,} values (numbers, keys, lists); "
                            f"too big for a {self.what}")
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise self.fail(self.peek_event().start_mark,
                            f"nested more than {MAX_DEPTH} levels deep")
        try:
            return super().compose_node(parent, index)
        finally:
            self.depth -= 1

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen: dict = {}
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=True)
                try:
                    first = seen.get(key)
                except TypeError:
                    raise self.fail(key_node.start_mark, "a mapping key must be a plain value, "
                                                         f"got {brief(key)}") from None
                if first is not None:
                    raise self.fail(key_node.start_mark,
                                    f"key {brief(key)} given twice (first on line {first + 1})")
                seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


_StrictLoader.add_constructor("tag:yaml.org,2002:int", _StrictLoader.construct_yaml_int)
_StrictLoader.add_constructor(_FLOAT_TAG, _StrictLoader.construct_yaml_float)
for _first in "-+.0123456789":
    _StrictLoader.add_implicit_resolver(_FLOAT_TAG, _EXPONENT_FLOAT, [_first])


def _tab_hint(text: str, mark) -> str:
    """A hint when a tab on the failing line, at or before the failing column, is the cause:
    libyaml's message does not name the character."""
    lines = text.splitlines()
    if mark is None or mark.line >= len(lines) or "\t" not in lines[mark.line][:mark.column + 1]:
        return ""
    return " (a tab: YAML indents with spaces, never tabs)"


def load(text: str, source: str = "<string>", what: str = "YAML file") -> Any:
    """Parse one YAML document strictly: no aliases, no duplicate keys, at most
    :data:`MAX_DEPTH` levels and the :func:`limits` of a ``what``. Raises
    :class:`YamlError` naming ``source`` and the line."""
    if not isinstance(text, str):
        raise YamlError(f"{source}: expected YAML text, got {type(text).__name__}")
    max_bytes, max_values = limits(what)
    if len(text) > max_bytes:      # text from a recording, not read by read_text
        raise YamlError(f"{source}: {len(text):,} characters is too big for a {what} (at "
                        f"most {max_bytes:,})")
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as exc:   # a lone surrogate, from a JSON escape in a recording
        raise YamlError(f"{source}: line {text.count(chr(10), 0, exc.start) + 1}: character "
                        f"U+{ord(text[exc.start]):04X} is not allowed in YAML (it is half of "
                        "a UTF-16 pair)") from None
    loader = None
    try:
        # (its reader refuses control characters)
        loader = _StrictLoader(text, source, what, max_values)
        data = loader.get_single_data()
        if isinstance(data, dict):
            kind = _other_kind(data, what)
            if kind:
                raise YamlError(f"{source}: {kind}; expected a {what}")
        return data
    except YamlError:
        raise
    except yaml.reader.ReaderError as exc:
        # libyaml counts the position in UTF-8 bytes, PyYAML in characters
        before = text.encode("utf-8")[:exc.position].decode(
            "utf-8", "replace") if yaml.__with_libyaml__ else text[:exc.position]
        code = exc.character if isinstance(exc.character, int) else ord(exc.character)
        raise YamlError(f"{source}: line {before.count(chr(10)) + 1}: character U+{code:04X} "
                        "is not allowed in YAML (control characters are not)") from None
    except yaml.MarkedYAMLError as exc:
        where = f"line {exc.problem_mark.line + 1}: " if exc.problem_mark else ""
        if "maximum nesting depth" in str(exc.problem):   # libyaml stops at 1,000 levels
            raise YamlError(f"{source}: {where}nested more than {MAX_DEPTH} levels deep") from None
        tag = _UNKNOWN_TAG.fullmatch(str(exc.problem))
        if tag:   # PyYAML's message, cut short, read 'could not determine a const...merge'
            raise YamlError(f"{source}: {where}" + (
                "YAML merge keys (<<) are not allowed; write the keys out"
                if tag[1] == "tag:yaml.org,2002:merge" else
                f"YAML tags ({brief(tag[1])[1:-1]}) are not allowed; write a plain value")
            ) from None
        raise YamlError(f"{source}: {where}not valid YAML: {brief(exc.problem or str(exc))[1:-1]}"
                        f"{_tab_hint(text, exc.problem_mark)}") from None
    except yaml.YAMLError as exc:
        raise YamlError(f"{source}: not valid YAML: {brief(str(exc))}") from None
    except RecursionError:
        raise YamlError(f"{source}: nested too deeply to read") from None
    finally:
        if loader is not None:
            loader.dispose()


MCAP_MAGIC = b"\x89MCAP0\r\n"   # the first bytes of every MCAP file (mcap.dev/spec)
# the files irring writes that are no text, by their first bytes
_NOT_YAML = ((b"PK\x03\x04", "a zip archive, as a recording (sweeps.npz) is: `irring replay` "
                             "reads those"),
             (b"\x89PNG", "a PNG picture"), (b"GIF8", "a GIF picture"),
             (b"P5\n", "a PGM picture (as map.pgm is)"),
             (MCAP_MAGIC, "an MCAP file (what --mcap writes, for viewers such as Foxglove)"))


def not_text(head: bytes) -> str | None:
    """What a file whose first bytes are ``head`` is, if irring wrote it and it is no text."""
    return next((kind for magic, kind in _NOT_YAML if head.startswith(magic)), None)


# irring's YAML files by the keys only each has: (what a caller names it, the keys, what it
# is for); the map_server map is maps.mapping's map.yaml beside map.pgm
_KINDS = (
    ("calibration file", {"irring_calibration"},
     "a calibration file (irring calibrate writes them; give it as --calibration)"),
    ("calibration progress file", {"irring_calibration_progress"},
     "a calibration progress file (give it to irring calibrate --port … --resume)"),
    ("scenario file", {"room", "robot"}, "a scenario file (irring run reads them)"),
    ("study file", {"designs", "scenarios"}, "a study file (irring study reads them)"),
    ("map_server YAML", {"image", "resolution", "origin", "occupied_thresh", "free_thresh"},
     "a ROS map_server map (the map.yaml irring writes beside map.pgm)"),
)


def input_kind(path: str | Path) -> tuple[str, str] | None:
    """(kind, what it is) of the irring input file at ``path`` (a recording, scenario,
    study, calibration or progress file), told from its first bytes and top-level keys;
    None for anything else (a picture, a map: outputs made again by a run)."""
    try:
        with open(path, "rb") as f:
            head = f.read(1 << 16)
    except OSError:
        return None
    if head.startswith(b"PK\x03\x04"):
        return "recording", not_text(head) or ""
    keys = set(re.findall(r"^([A-Za-z_]\w*)\s*:", head.decode("utf-8", "replace"), re.M))
    return next(((kind, told) for kind, need, told in _KINDS
                 if kind != "map_server YAML" and need <= keys), None)


def _other_kind(data: dict, what: str) -> str | None:
    """What ``data`` is when it has the keys of another kind of irring file than ``what``
    (one of the kinds; a plain "YAML file" is any)."""
    if what not in {kind for kind, _, _ in _KINDS} or any(
            kind == what and keys <= data.keys() for kind, keys, _ in _KINDS):
        return None
    return next((told for kind, keys, told in _KINDS if kind != what and keys <= data.keys()),
                None)


def read_text(path: str | Path, what: str = "file") -> str:
    """The UTF-8 text of a file a user named; :class:`InputError` (one line naming the path)
    for a missing file, a folder, an unreadable file, one over the :func:`limits` of a
    ``what``, or bytes that are not UTF-8."""
    path = Path(path)
    max_bytes = limits(what)[0]
    try:
        if path.is_dir():
            raise InputError(f"{path}: is a folder; expected a {what}")
        if not path.exists():
            raise InputError(f"{path}: no such {what}")
        size = path.stat().st_size
        if size > max_bytes:
            raise InputError(f"{path}: {size:,} bytes is too big for a {what} (at most "
                             f"{max_bytes / 2**20:g} MB, {max_bytes:,} bytes)")
        # a device or pipe reports size 0 and may never end (/dev/zero): read no more
        # than the limit allows
        with open(path, "rb") as f:
            data = f.read(max_bytes + 1)
        if len(data) > max_bytes:
            raise InputError(f"{path}: more than {max_bytes / 2**20:g} MB; too big for a {what} "
                             f"(is it a device or a stream that never ends?)")
    except OSError as exc:
        raise InputError(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        kind = not_text(data)
        if kind:   # irring's own outputs: "save it as UTF-8" is no advice for them
            raise InputError(f"{path}: {kind}; expected a {what}") from None
        line = data[:exc.start].count(b"\n") + 1
        raise InputError(f"{path}: line {line}: not UTF-8 text (byte {exc.start}); save the "
                         f"{what} as UTF-8") from None


def load_file(path: str | Path, what: str = "file") -> Any:
    """:func:`read_text` then :func:`load`."""
    return load(read_text(path, what), str(path), what)
