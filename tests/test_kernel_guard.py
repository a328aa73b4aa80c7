"""A compiled kernel built from another version of its .pyx (a checkout pulled, rebased or
edited since `pip install -e .`) stops with the rebuild command instead of running old code."""

from __future__ import annotations

import hashlib
import importlib
import os
import shutil
import subprocess
import sys
import types
from pathlib import Path

import pytest

import irring
from irring.errors import INTERNAL, KernelError, describe
from irring.kernel_build import DIGEST_ATTRIBUTE, source_digest
from irring.resources import UnusableKernel, kernel, stale_reason

PACKAGE = Path(irring.__file__).parent
SOURCES = sorted(PACKAGE.glob("*/_*.pyx"))
NAMES = [".".join(p.relative_to(PACKAGE).with_suffix("").parts) for p in SOURCES]


def test_this_tree_has_three_kernels_each_built_from_its_source():
    assert NAMES == ["estimation._iterate", "estimation._lines", "maps._traverse"]
    for name, source in zip(NAMES, SOURCES):
        module = importlib.import_module(f"irring.{name}")
        assert getattr(module, DIGEST_ATTRIBUTE) == source_digest(source), (
            f"{name} was built without its .pyx's digest (plain cythonize?): rebuild with "
            f"`pip install -e .` or `python -m irring.kernel_build`")
        assert stale_reason(name, module) is None
        assert kernel(name) is module


def source_digest_of(text: bytes) -> str:
    return hashlib.sha256(text).hexdigest()


def _fake_kernel(tmp_path: Path, pyx: bytes, recorded: str, pyx_newer: bool):
    """A kernel 'maps._walk' in a tmp checkout: its .so (an empty stand-in file), its .pyx,
    and a module object recording ``recorded``; the .pyx written after the .so or before."""
    folder = tmp_path / "irring" / "maps"
    folder.mkdir(parents=True)
    built, source = folder / "_walk.cpython-311-x86_64-linux-gnu.so", folder / "_walk.pyx"
    built.write_bytes(b"")
    source.write_bytes(pyx)
    so_time = 1_700_000_000
    os.utime(built, (so_time, so_time))
    os.utime(source, (so_time + (60 if pyx_newer else -60),) * 2)
    module = types.SimpleNamespace(__file__=str(built), **{DIGEST_ATTRIBUTE: recorded})
    return module, source


def test_a_changed_pyx_names_the_kernel_the_file_and_both_rebuilds(tmp_path):
    built_from = b"def walk(x):\n    return x\n"
    module, source = _fake_kernel(tmp_path, built_from + b"def walk_back(x):\n    return -x\n",
                                  recorded=source_digest_of(built_from), pyx_newer=True)
    reason = stale_reason("maps._walk", module)
    assert reason == (
        f"irring's compiled kernel maps._walk was built from another version of "
        f"irring/maps/_walk.pyx (it changed since: a pull, a rebase, a checkout or an edit); "
        f"rebuild the kernels in {tmp_path}: `pip install -e .`, or quicker "
        f"`python -m irring.kernel_build`")
    # …and a .pyx changed back to what was built is fine again, however new the file
    source.write_bytes(built_from)
    assert stale_reason("maps._walk", module) is None


@pytest.mark.parametrize("pyx_newer", [False, True])
def test_the_recorded_digest_decides_not_the_file_times(tmp_path, pyx_newer):
    text = b"cdef int k = 3\n"
    same, _ = _fake_kernel(tmp_path / "same", text, source_digest_of(text), pyx_newer)
    other, _ = _fake_kernel(tmp_path / "other", text, source_digest_of(b"cdef int k = 4\n"),
                            pyx_newer)
    assert stale_reason("maps._walk", same) is None          # a checkout touched, not changed
    assert "maps._walk was built from another version" in stale_reason("maps._walk", other)


def test_a_kernel_without_a_digest_is_judged_by_age_and_one_without_pyx_not_at_all(tmp_path):
    older, _ = _fake_kernel(tmp_path / "a", b"x = 1\n", recorded="", pyx_newer=False)
    newer, _ = _fake_kernel(tmp_path / "b", b"x = 1\n", recorded="", pyx_newer=True)
    assert stale_reason("maps._walk", older) is None    # plain `cythonize -i`, after the edit
    assert "irring/maps/_walk.pyx" in stale_reason("maps._walk", newer)
    wheel, source = _fake_kernel(tmp_path / "c", b"x = 1\n", recorded="0" * 64, pyx_newer=True)
    source.unlink()                                       # installed without sources
    assert stale_reason("maps._walk", wheel) is None


def test_an_unusable_kernel_raises_its_message_on_use_and_the_cli_prints_it_alone():
    stand_in = UnusableKernel("maps._walk", "irring's compiled kernel maps._walk was built …")
    with pytest.raises(KernelError) as caught:
        stand_in.walk
    assert isinstance(caught.value, ImportError)
    assert describe(caught.value) == (INTERNAL,
                                      "irring's compiled kernel maps._walk was built …")


def test_a_checkout_whose_pyx_changed_stops_at_first_use_with_the_rebuild(tmp_path):
    """End to end: a copy of this package whose _lines.pyx gained a line. Its estimator
    module still imports; estimating fails with the one-line error, not an AttributeError
    or an answer from the old code; the untouched kernels load (their .pyx touched only)."""
    tree = tmp_path / "checkout"
    shutil.copytree(PACKAGE, tree / "irring",
                    ignore=shutil.ignore_patterns("__pycache__", "*.c", "_data"))
    for folder in ("models", "scenarios"):
        (tree / folder).symlink_to(PACKAGE.parent / folder)
    lines = tree / "irring" / "estimation" / "_lines.pyx"
    lines.write_text(lines.read_text() + "\ncdef int NEW_KERNEL_CONSTANT = 1\n")
    (tree / "irring" / "maps" / "_traverse.pyx").touch()
    code = """
import irring
from irring.estimation import estimate
from irring.maps import mapping
assert irring.__file__.startswith(%r), irring.__file__
print(type(mapping._traverse).__name__)
try:
    estimate._lines.segment
except ImportError as exc:
    print(type(exc).__name__, exc)
""" % str(tree)
    env = {**os.environ, "PYTHONPATH": str(tree)}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=tmp_path, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        "module",
        f"KernelError irring's compiled kernel estimation._lines was built from another "
        f"version of irring/estimation/_lines.pyx (it changed since: a pull, a rebase, a "
        f"checkout or an edit); rebuild the kernels in {tree}: `pip install -e .`, or "
        f"quicker `python -m irring.kernel_build`"]
    run = subprocess.run([sys.executable, "-m", "irring.cli", "run", "--out", "out"],
                         capture_output=True, text=True, cwd=tmp_path, env=env, timeout=300)
    assert run.returncode == INTERNAL
    assert run.stderr.splitlines() == [
        "irring run: error: " + done.stdout.splitlines()[1].removeprefix("KernelError ")]


def test_an_in_place_rebuild_names_the_build_requirements_this_environment_lacks(
        tmp_path, monkeypatch, capsys):
    """`python -m irring.kernel_build` uses this interpreter's setuptools and Cython, where
    pip builds in an environment of its own: a fresh venv (setuptools 65, no Cython) got a
    60-line setuptools traceback about pyproject's licence field. Now one line says what to
    do, read from pyproject.toml's [build-system] requires."""
    from importlib import metadata

    from irring import kernel_build

    pyproject = tmp_path / "pyproject.toml"
    pyproject.write_text('[build-system]\nrequires = ["setuptools>=77.2", "cython>=3.0",\n'
                         '            "numpy>=1.9"]\n\n[project]\nrequires = ["x>=9"]\n')
    installed = {"setuptools": "65.5.0", "numpy": "1.26.4"}

    def version(name):
        if name not in installed:
            raise metadata.PackageNotFoundError(name)
        return installed[name]

    monkeypatch.setattr(metadata, "version", version)
    assert kernel_build.missing_build_requirements(pyproject) == [
        "setuptools>=77.2 (this environment has 65.5.0)", "cython>=3.0"]
    installed.update(setuptools="77.10.1", cython="3.0.0")
    assert kernel_build.missing_build_requirements(pyproject) == []
    # the checkout's own pyproject names both, and main() stops before setuptools runs
    del installed["cython"]
    assert kernel_build.missing_build_requirements(PACKAGE.parent / "pyproject.toml") == [
        "cython>=3.0"]
    assert kernel_build.main() == 2
    assert capsys.readouterr().err == (
        "python -m irring.kernel_build: error: an in-place build needs cython>=3.0 in this "
        "environment; `pip install -e .` rebuilds the kernels without them (pip builds in an "
        "environment of its own), or install them first: pip install 'cython>=3.0'\n")


def test_a_child_process_imports_this_irring_not_the_working_folders(tmp_path):
    """bench render and bench study time fresh processes: in a checkout beside a `pip install
    .`, `python -m`/`-c` imported the checkout (kernels not built) and the bench failed."""
    from irring.resources import python_here

    (tmp_path / "irring").mkdir()
    (tmp_path / "irring" / "__init__.py").write_text("raise ImportError('not this irring')\n")
    bare = subprocess.run([sys.executable, "-c", "import irring"], cwd=tmp_path,
                          capture_output=True, text=True)
    assert bare.returncode == 1 and "ImportError: not this irring" in bare.stderr
    child = subprocess.run(python_here("import irring, sys; print(irring.__file__, sys.argv[1:])")
                           + ["a", "b"], cwd=tmp_path, capture_output=True, text=True)
    assert child.returncode == 0, child.stderr
    assert child.stdout == f"{irring.__file__} ['a', 'b']\n"
