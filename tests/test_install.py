"""What a user sees when irring's compiled kernels are missing (a source tree never installed)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import irring


def test_unbuilt_kernels_name_themselves_and_the_fix(tmp_path):
    # a copy of the package's Python sources only, imported with no site-packages (so no
    # editable install can supply the built kernels)
    shutil.copytree(Path(irring.__file__).parent, tmp_path / "irring",
                    ignore=shutil.ignore_patterns("*.so", "*.pyd", "__pycache__"))
    done = subprocess.run([sys.executable, "-S", "-c", "import irring"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode != 0
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("ImportError: irring's compiled kernels estimation._iterate, "
                           "estimation._lines, maps._traverse are not built")
    assert "pip install ." in last and "C compiler" in last
