"""Round seventeen of hostile input: each test names the input that broke and asserts what
happens now."""

from __future__ import annotations

import numpy as np
import pytest


def test_a_calibration_file_cut_short_anywhere_is_refused_never_read_as_less(tmp_path):
    """A calibration file cut short (a copy that stopped, a disk that filled elsewhere)
    loaded whenever the cut fell in its θ table: with fewer rows, or with a number cut (b =
    -1 for -1.1754), and mapped unwarned (213 of this file's 1571 cuts). The table is
    written last and in one [...]: every cut is refused, or lost nothing (the last newline)."""
    from irring.errors import IrringError
    from irring.estimation.calibration import Calibration, load_calibration
    from irring.scenario import load_scenario

    path = Calibration.for_scene(load_scenario("t_room")).save(tmp_path / "cal.yaml")
    text = path.read_text()
    whole = load_calibration(text, is_text=True)[0]
    changed = []
    for cut in range(len(text)):
        try:
            cal = load_calibration(text[:cut], is_text=True)[0]
        except IrringError:
            continue
        if cal.to_yaml() != whole.to_yaml():   # every field, every row, to the digit
            changed.append(cut)
    assert changed == []
    cut = text[:text.index("b: ", text.index("theta_deg: 5.0")) + 5]   # 'b: -1'
    with pytest.raises(IrringError, match=r"^<recording's calibration>: line \d+: not valid "
                                          r"YAML: "):
        load_calibration(cut, is_text=True)
