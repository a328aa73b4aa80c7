"""How the compiled kernels (irring/*/_*.pyx) are built: with their source's SHA-256 in them.

pyproject.toml names :class:`BuildKernels` as its build_ext, so `pip install .` and
`pip install -e .` compile into every kernel the digest of the .pyx it was made from (the
kernel's ``PYX_SHA256``); ``irring.resources.kernel`` compares it with the .pyx beside the
kernel. `python -m irring.kernel_build` is a checkout's quick rebuild: in place, only the
kernels whose .pyx changed. setuptools loads this file on its own during a build (without
irring's dependencies): it imports nothing of irring, and setuptools only when asked.
"""

from __future__ import annotations

import functools
import os
import re
import sys
from pathlib import Path

DIGEST_ATTRIBUTE = "PYX_SHA256"   # a kernel's digest of its .pyx as built; "" if not recorded
DIGEST_MACRO = "IRRING_PYX_SHA256"   # the C macro the build defines it by


def source_digest(path: Path) -> str:
    """SHA-256 (hex) of a kernel's source file, as the build compiles it in."""
    # deferred: hashlib loads OpenSSL (~2 ms); only a kernel with its .pyx beside it needs it
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def __getattr__(name: str):
    # only a build asks for BuildKernels, so importing irring loads no setuptools
    if name == "BuildKernels":
        return _build_kernels_command()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@functools.lru_cache(maxsize=1)
def _build_kernels_command():
    # deferred: setuptools is there when irring is built, not always where it runs
    from setuptools.command.build_ext import build_ext

    class BuildKernels(build_ext):
        """setuptools' build_ext (Cython's, which the build requires) that compiles the
        SHA-256 of each kernel's .pyx into it as the C macro IRRING_PYX_SHA256."""

        def build_extension(self, ext):
            sources = [Path(s) for s in ext.sources if s.endswith(".pyx")]
            if sources:   # a second pass sees the generated .c and keeps the first digest
                ext.define_macros = [
                    *(m for m in ext.define_macros if m[0] != DIGEST_MACRO),
                    (DIGEST_MACRO, f'"{source_digest(sources[0])}"')]
            super().build_extension(ext)

    return BuildKernels


def missing_build_requirements(pyproject: Path) -> list[str]:
    """The requirements of pyproject.toml's ``[build-system] requires`` (``name>=version``)
    this interpreter lacks or has too old: pip builds in an environment of its own, an
    in-place build uses this one (a fresh venv has setuptools 65 and no Cython)."""
    # deferred: only a rebuild reads installed versions (importlib.metadata scans site-packages)
    from importlib import metadata

    block = re.search(r"^\[build-system\](.*?)^\[", pyproject.read_text() + "\n[", re.S | re.M)
    listed = re.search(r"^requires\s*=\s*\[(.*?)\]", block[1] if block else "", re.S | re.M)
    missing = []
    for name, least in re.findall(r'"([A-Za-z0-9_.-]+)\s*>=\s*([0-9.]+)"',
                                  listed[1] if listed else ""):
        try:
            have = metadata.version(name)
        except metadata.PackageNotFoundError:
            missing.append(f"{name}>={least}")
            continue
        if _release(have) < _release(least):
            missing.append(f"{name}>={least} (this environment has {have})")
    return missing


def _release(version: str) -> tuple[int, ...]:
    return tuple(int(part) for part in re.findall(r"\d+", version.split("+")[0])[:3])


def main() -> int:
    """`python -m irring.kernel_build`: rebuild in place the kernels whose .pyx changed (the
    quick rebuild of a checkout; pip's does the same with the rest of the install).
    Exit 2 (with one line saying what to do) outside a checkout or without the build's
    requirements in this environment."""
    root = Path(__file__).resolve().parent.parent
    if not (root / "pyproject.toml").is_file():
        print(f"python -m irring.kernel_build: error: {root} is not a checkout of irring (no "
              f"pyproject.toml); an installed irring is rebuilt by `pip install` itself",
              file=sys.stderr)
        return 2
    missing = missing_build_requirements(root / "pyproject.toml")
    if missing:
        print(f"python -m irring.kernel_build: error: an in-place build needs "
              f"{', '.join(missing)} in this environment; `pip install -e .` rebuilds the "
              f"kernels without them (pip builds in an environment of its own), or install "
              f"them first: pip install {' '.join(repr(m.split(' ')[0]) for m in missing)}",
              file=sys.stderr)
        return 2
    # deferred: setuptools is there when irring is built, not always where it runs
    from setuptools import setup

    os.chdir(root)   # setup() reads pyproject.toml (the kernels, BuildKernels) from here
    setup(script_args=["build_ext", "--inplace"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
