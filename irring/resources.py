"""What the installation provides: the bundled models and scenarios, the compiled kernels.

A wheel carries models and scenarios inside the package (``irring/_data``, see
pyproject.toml); a source checkout keeps them at the repository's top level. A source tree
never installed lacks the compiled kernels: :class:`MissingKernel` stands in for one and
raises the ImportError that says how to build it when it is used.
"""

from __future__ import annotations

import functools
import importlib
from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent


def _find(name: str) -> Path:
    for candidate in (_PACKAGE / "_data" / name, _PACKAGE.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"irring's bundled '{name}' folder is missing; reinstall irring "
                            f"(looked in {_PACKAGE / '_data'} and {_PACKAGE.parent})")


@functools.lru_cache(maxsize=1)
def installed_version() -> str:
    """irring's installed version, or "unknown (not installed)" for a bare source tree."""
    # deferred: importlib.metadata is slow to import; only --version and a study's rows ask
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("irring")
    except PackageNotFoundError:
        return "unknown (not installed)"


def models_dir() -> Path:
    return _find("models")


def scenarios_dir() -> Path:
    return _find("scenarios")


class MissingKernel:
    """Stands in for a compiled kernel (irring/*/_*.pyx) that is not built; using it raises."""

    def __init__(self, name: str):
        self._name = name

    def __getattr__(self, attr: str):
        raise ImportError(
            f"irring's compiled kernel {self._name} is not built: install irring with "
            f"`pip install .` (or `pip install -e .` in a checkout); pip compiles it with the "
            f"machine's C compiler (Debian: apt install build-essential python3-dev)")


def kernel(name: str):
    """The compiled module ``irring.<name>`` (e.g. "maps._traverse"), or a MissingKernel
    that raises when used: a source tree never installed still imports."""
    try:
        return importlib.import_module(f"irring.{name}")
    except ImportError:
        return MissingKernel(name)
