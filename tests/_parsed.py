"""irring's own sources, each parsed once a test process: the docstring and import rules
walk every module, and parsing the package takes seconds. No test edits a tree."""

from __future__ import annotations

import ast
import functools
from pathlib import Path


@functools.cache
def parsed(path: Path) -> ast.Module:
    """The syntax tree of the Python file at ``path`` (shared: read it, never change it)."""
    return ast.parse(path.read_text())
