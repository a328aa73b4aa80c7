"""Docstrings state a module's contract in a few lines (the long story lives in docs/) and
hold no measured timings, which go stale (they belong in the README and benchmark output)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import irring

PACKAGE = Path(irring.__file__).parent
MAX_MODULE_DOC_LINES = 9
# a duration with a unit, as a measurement is written; the GP2's datasheet period is a fact
TIMING = re.compile(r"\d(?:[\d.,–-]*\d)?\s?(?:ms|µs|us|s)\b(?![²/])")
NOT_MEASURED = ("38.3 ms",)


def _sources() -> dict[str, ast.Module]:
    return {str(p.relative_to(PACKAGE.parent)): ast.parse(p.read_text())
            for p in sorted(PACKAGE.rglob("*.py")) if "_data" not in p.parts}


def test_module_docstrings_are_a_few_lines():
    lengths = {path: len((ast.get_docstring(tree, clean=False) or "").splitlines())
               for path, tree in _sources().items()}
    assert lengths["irring/core.py"] >= 3   # the parser reads them
    assert {p: n for p, n in lengths.items() if n > MAX_MODULE_DOC_LINES} == {}


def test_no_docstring_quotes_a_measured_time():
    found = []
    for path, tree in _sources().items():
        for node in ast.walk(tree):
            if isinstance(node, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef,
                                 ast.ClassDef)):
                doc = ast.get_docstring(node, clean=False) or ""
                for line in doc.splitlines():
                    if TIMING.search(line) and not any(f in line for f in NOT_MEASURED):
                        found.append(f"{path}: {line.strip()}")
    assert TIMING.search("takes ~0.1–0.5 s") and TIMING.search("0.044 ms per sweep")
    assert not TIMING.search("areas in m², 8 m/s")
    assert found == []
