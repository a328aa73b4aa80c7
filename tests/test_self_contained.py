"""Nothing in the repository points outside it: no review or report files, helpers' names,
developers' scripts or tool folders, or paths on the developers' machine. A test's
docstring says what it checks; a doc says what was measured and how to measure it again
with what the repository ships."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

OUTSIDE = [
    (re.compile(r"FINDINGS\d*|NEWUSER\d*|REVIEW\d+|BUILDER\d+"), "a review or report file"),
    (re.compile(r"\b(?:newuser|fixes|attack|review|polish|builder)\d+\b", re.I),
     "a helper's name"),
    (re.compile(r"\b(?:hashall|ruletime|esttime)\b|\btrace\.py\b"), "a developer's script"),
    (re.compile(r"\b[\w.]+-tools/|\bof [\w.]+-tools\b"), "a developer's tool folder"),
    (re.compile(r"/work/"), "a path on the developers' machine"),
    (re.compile(r"/tmp/"), "a temporary path"),
]
# legitimate: what a program prints or is fed, shown as an example
ALLOWED = {
    ("README.md", "/tmp/irring-calibrate-"),
    ("docs/calibration.md", "/tmp/irring-calibrate-"),
    ("irring/cli/calibrate.py", "/tmp/irring-calibrate-"),
    ("tests/test_sameness_masks.py", "/tmp/irring-calibrate-"),
    ("tests/test_sameness_masks.py", "/tmp/sameness-"),
    ("tests/hostile_corpus.py", "/tmp/irring-escape"),
}
HERE = Path(__file__).resolve().relative_to(ROOT).as_posix()


def _tracked() -> list[str]:
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True,
                             check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the tracked files are not known")
    return [f for f in out.decode().split("\0") if f and f != HERE]


def _texts():
    for name in _tracked():
        try:
            yield name, (ROOT / name).read_text(encoding="utf-8")
        except (UnicodeDecodeError, FileNotFoundError, IsADirectoryError):
            continue   # a picture, a binary, a file deleted in the work tree


def test_no_file_points_outside_the_repository():
    found = []
    for name, text in _texts():
        for n, line in enumerate(text.splitlines(), 1):
            for pattern, what in OUTSIDE:
                m = pattern.search(line)
                if m and not any(f == name and s in line for f, s in ALLOWED):
                    found.append(f"{name}:{n}: {what}: {m.group(0)!r}")
    assert not found, "\n".join(found)


def test_every_script_a_doc_names_is_in_the_repository():
    """A doc that names `something.py` names a file the repository holds."""
    names = {Path(f).name for f in _tracked()}
    found = []
    for name, text in _texts():
        if not name.endswith(".md"):
            continue
        for n, line in enumerate(text.splitlines(), 1):
            for m in re.finditer(r"\b[A-Za-z_]\w*\.py\b", line):
                if m.group(0) not in names:
                    found.append(f"{name}:{n}: {m.group(0)}")
    assert not found, "\n".join(found)
