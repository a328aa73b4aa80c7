"""What the installation provides: the bundled models and scenarios, the compiled kernels.

A wheel carries models and scenarios inside the package (``irring/_data``, see
pyproject.toml); a source checkout keeps them at the repository's top level. A kernel that
cannot be used — not built (a source tree never installed), or built from another version of
its .pyx than the one beside it (a checkout pulled or edited since `pip install -e .`) — is
replaced by an :class:`UnusableKernel` whose first use raises the KernelError that names it
and the rebuild (the build records each .pyx's SHA-256 in its kernel: irring/kernel_build.py).
"""

from __future__ import annotations

import functools
import importlib
import sys
from pathlib import Path

from .errors import KernelError
from .kernel_build import DIGEST_ATTRIBUTE, source_digest

_PACKAGE = Path(__file__).resolve().parent


def _find(name: str) -> Path:
    for candidate in (_PACKAGE / "_data" / name, _PACKAGE.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"irring's bundled '{name}' folder is missing; reinstall irring "
                            f"(looked in {_PACKAGE / '_data'} and {_PACKAGE.parent})")


def python_here(code: str) -> list[str]:
    """The command line ``[python, "-c", code]`` of a child process that imports the irring
    this process imported. ``-c`` and ``-m`` put the working folder first on ``sys.path``: in
    a checkout beside a ``pip install .`` the child would import the checkout, whose kernels
    are not built; here the folder irring came from takes the working folder's place."""
    return [sys.executable, "-c", f"import sys; sys.path[0] = {str(_PACKAGE.parent)!r}\n{code}"]


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


class UnusableKernel:
    """Stands in for a compiled kernel (irring/*/_*.pyx) that cannot be used; any use raises
    KernelError with ``message`` (what is wrong and the command that fixes it)."""

    def __init__(self, name: str, message: str):
        self._name, self._message = name, message

    def __getattr__(self, attr: str):
        raise KernelError(self._message)


@functools.lru_cache(maxsize=None)   # imported by several modules: compared once
def kernel(name: str):
    """The compiled module ``irring.<name>`` (e.g. "maps._traverse"), or an UnusableKernel
    that raises when used: a kernel not built, or one whose .pyx beside it (a checkout)
    changed since it was built. An installed wheel has no .pyx, so nothing is compared."""
    try:
        module = importlib.import_module(f"irring.{name}")
    except ImportError:
        return UnusableKernel(name, (
            f"irring's compiled kernel {name} is not built: install irring with "
            f"`pip install .` (or `pip install -e .` in a checkout); pip compiles it with the "
            f"machine's C compiler (Debian: apt install build-essential python3-dev)"))
    stale = stale_reason(name, module)
    return UnusableKernel(name, stale) if stale else module


def stale_reason(name: str, module) -> str | None:
    """Why ``module`` was not built from the .pyx now beside it (the message for the user),
    or None: the same source, or no .pyx there (an installed wheel: one failed stat)."""
    built = Path(module.__file__)
    source = built.parent / (name.rsplit(".", 1)[-1] + ".pyx")
    if not source.is_file():
        return None
    recorded = getattr(module, DIGEST_ATTRIBUTE, "")
    if recorded:
        if source_digest(source) == recorded:
            return None
    elif source.stat().st_mtime <= built.stat().st_mtime:
        # built without a digest (plain `cythonize -i`, or before digests were recorded):
        # a .pyx no newer than the kernel is taken as its source
        return None
    root = built.parents[name.count(".") + 1]
    return (f"irring's compiled kernel {name} was built from another version of "
            f"{source.relative_to(root).as_posix()} (it changed since: a pull, a rebase, "
            f"a checkout or an edit); rebuild the kernels in {root}: `pip install -e .`, "
            f"or quicker `python -m irring.kernel_build`")
