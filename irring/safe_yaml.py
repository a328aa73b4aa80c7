"""The one YAML reader for every file a user hands irring (scenarios, calibrations, sensor
curves, the scenario inside a recording, study files).

PyYAML's ``safe_load`` builds no objects, but it still lets the last of two equal keys win
silently, expands aliases (a 562-byte "billion laughs" file grows to gigabytes) and recurses
once per nesting level. :func:`load` refuses all three, and :func:`read_text` refuses what
is not a readable UTF-8 file of sane size, each with one line naming the file and the line.
Numbers read as written (``1e-3``); YAML 1.1's octal ``0750`` and base-60 ``1:30`` are refused.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from .errors import InputError, brief

MAX_DEPTH = 64             # nesting levels; irring's deepest schema uses 5
MAX_BYTES = 8 * 2**20      # a scenario with 100k outline corners is ~3 MB
MAX_DIGITS = 100           # of a whole number: more than any file's field takes (a float
#                            overflows at 309 digits; Python refuses to parse 4,300)

# YAML 1.2's exponent floats without a dot or without the exponent's sign (1e-3, 1.0e300),
# which YAML 1.1 reads as text
_EXPONENT_FLOAT = re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9_]+$")
_FLOAT_TAG = "tag:yaml.org,2002:float"


class YamlError(InputError):
    """A YAML text irring refuses to read; the message names the source and line."""


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader without aliases, duplicate keys or unbounded nesting."""

    def __init__(self, stream: str, source: str):
        super().__init__(stream)
        self.source = source
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


def load(text: str, source: str = "<string>") -> Any:
    """Parse one YAML document strictly: no aliases, no duplicate keys, at most
    :data:`MAX_DEPTH` levels. Raises :class:`YamlError` naming ``source`` and the line."""
    if not isinstance(text, str):
        raise YamlError(f"{source}: expected YAML text, got {type(text).__name__}")
    loader = None
    try:
        loader = _StrictLoader(text, source)   # (its reader refuses control characters)
        return loader.get_single_data()
    except YamlError:
        raise
    except yaml.reader.ReaderError as exc:
        raise YamlError(f"{source}: character {brief(exc.character)} at position "
                        f"{exc.position} is not allowed in YAML (control characters are "
                        "not)") from None
    except yaml.MarkedYAMLError as exc:
        where = f"line {exc.problem_mark.line + 1}: " if exc.problem_mark else ""
        raise YamlError(f"{source}: {where}not valid YAML: {brief(exc.problem or str(exc))[1:-1]}") from None
    except yaml.YAMLError as exc:
        raise YamlError(f"{source}: not valid YAML: {brief(str(exc))}") from None
    except RecursionError:
        raise YamlError(f"{source}: nested too deeply to read") from None
    finally:
        if loader is not None:
            loader.dispose()


def read_text(path: str | Path, what: str = "file", max_bytes: int = MAX_BYTES) -> str:
    """The UTF-8 text of a file a user named; :class:`InputError` (one line naming the path)
    for a missing file, a folder, an unreadable or oversized file or bytes that are not
    UTF-8."""
    path = Path(path)
    try:
        if path.is_dir():
            raise InputError(f"{path}: is a folder; expected a {what}")
        if not path.exists():
            raise InputError(f"{path}: no such {what}")
        size = path.stat().st_size
        if size > max_bytes:
            raise InputError(f"{path}: {size / 2**20:.1f} MB is too big for a {what} "
                             f"(at most {max_bytes / 2**20:g} MB)")
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
        line = data[:exc.start].count(b"\n") + 1
        raise InputError(f"{path}: line {line}: not UTF-8 text (byte {exc.start}); save the "
                         f"{what} as UTF-8") from None


def load_file(path: str | Path, what: str = "file") -> Any:
    """:func:`read_text` then :func:`load`."""
    return load(read_text(path, what), str(path))
