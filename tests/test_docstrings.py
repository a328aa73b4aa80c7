"""Docstrings state a module's contract in a few lines (the long story lives in docs/) and
hold no measured timings, which go stale (they belong in the README and benchmark output)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import irring
from _parsed import parsed

PACKAGE = Path(irring.__file__).parent
MAX_MODULE_DOC_LINES = 9
# a duration with a unit, as a measurement is written; the GP2's datasheet period is a fact
TIMING = re.compile(r"\d(?:[\d.,–-]*\d)?\s?(?:ms|µs|us|s)\b(?![²/])")
NOT_MEASURED = ("38.3 ms",)


def _sources() -> dict[str, ast.Module]:
    return {str(p.relative_to(PACKAGE.parent)): parsed(p)
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


ROOT = PACKAGE.parent
# where a user reads a dotted irring.* name: the docs, the bundled files, the firmware
DOC_PLACES = ("README.md", "docs", "scenarios", "models", "firmware")
DOC_SUFFIXES = {".md", ".yaml", ".xml", ".txt", ".h", ".c", ".cpp", ".ino", ".py", ""}
DOTTED = re.compile(r"\birring(?:\.[A-Za-z_]\w*)+")
FILE_NAMES = re.compile(r"\.(xml|yaml|py|md|csv|json|png)$")   # irring.xml is a file


def _home_of(name: str) -> str | None:
    """Where ``name`` (irring.a.b.C.m) is defined, or None when it does not resolve."""
    import importlib
    import inspect

    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
            break
        except ImportError:
            continue
    module = obj.__name__
    for attr in parts[i:]:
        if not hasattr(obj, attr):
            return None
        obj = getattr(obj, attr)
        if inspect.isclass(obj) or inspect.isfunction(obj):
            module = obj.__module__ if attr == parts[i] else module
    return module


def _names_in(text: str) -> set[str]:
    return {m for m in DOTTED.findall(text) if not FILE_NAMES.search(m)}


def test_the_irring_names_users_read_are_where_the_code_is():
    """A dotted irring.* name in the docs, the bundled files, the firmware's notes or a
    calibration file's header resolves, through the module that defines it (not a
    re-export kept for old files): moved code leaves no stale path."""
    from irring.estimation.calibration import Calibration
    from irring.scenario import load_scenario

    places = {"calibration file header":
              Calibration.for_scene(load_scenario("t_room")).to_yaml()}
    for place in DOC_PLACES:
        path = ROOT / place
        for f in [path] if path.is_file() else sorted(path.rglob("*")):
            if f.is_file() and f.suffix in DOC_SUFFIXES:
                places[str(f.relative_to(ROOT))] = f.read_text(encoding="utf-8", errors="replace")
    stale = {}
    for place, text in places.items():
        for name in _names_in(text):
            home = _home_of(name)
            if home is None or not name.startswith(home):
                stale.setdefault(place, []).append(f"{name} (defined in {home})")
    assert "irring.estimation.calibration.Calibration.load" in _names_in(
        places["calibration file header"])
    assert stale == {}


def test_the_readme_layout_names_every_module():
    """The README's Layout is where a newcomer looks for a module: it left out
    estimation/bounds.py and `bench long`'s studies/long_sweeps.py. Every module of the
    package is named there (cli/: "one module per subcommand"), a benchmark's by its
    `irring bench` name where that is its module's; and docs/estimator.md's "Where the code
    is" names every rule module beside estimate.py."""
    block = (ROOT / "README.md").read_text().split("\n## Layout\n", 1)[1].split("```")[1]
    unnamed = []
    for f in sorted(PACKAGE.rglob("*")):
        rel = f.relative_to(PACKAGE)
        if f.suffix not in (".py", ".pyx") or f.name in ("__init__.py", "__main__.py") \
                or rel.parts[0] in ("cli", "_data"):
            continue
        names = [f.name] + ([f.stem] if rel.parts[0] == "studies" else [])
        if not any(re.search(rf"(?<![\w.]){re.escape(n)}(?![\w])", block) for n in names):
            unnamed.append(str(rel))
    assert unnamed == []
    table = (ROOT / "docs" / "estimator.md").read_text().split("\n## Where the code is\n")[1]
    table = table.split("\n## ")[0]
    rules = {f.name for f in (PACKAGE / "estimation").glob("*.py")} - {
        "__init__.py", "calibration.py", "calibration_chart.py", "estimate_numpy.py"}
    assert {r for r in rules if f"| `{r}` |" not in table} == set()
