"""Where the bundled models and scenarios live, for editable and plain installs alike.

A wheel carries them inside the package (``irring/_data``, see pyproject.toml); a source
checkout keeps them at the repository's top level.
"""

from __future__ import annotations

from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent


def _find(name: str) -> Path:
    for candidate in (_PACKAGE / "_data" / name, _PACKAGE.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"irring's bundled '{name}' folder is missing; reinstall irring "
                            f"(looked in {_PACKAGE / '_data'} and {_PACKAGE.parent})")


def models_dir() -> Path:
    return _find("models")


def scenarios_dir() -> Path:
    return _find("scenarios")
