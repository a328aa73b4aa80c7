"""Small leftovers of the last reviews: each test names what was wrong and asserts what
happens now."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import irring
from irring.cli import main


def _help(capsys, *argv) -> str:
    with pytest.raises(SystemExit):
        main([*argv, "--help"])
    return " ".join(capsys.readouterr().out.split())


def test_view_size_help_says_the_pixel_limit_its_refusal_uses(capsys):
    """`irring view --size`'s help said "picture size in pixels (default: 1280x960)", and
    nothing of the 16 … 8192 a side or the 20 million pixels past which it is refused."""
    from irring.cli.view import MAX_PIXELS, size_refusal

    text = _help(capsys, "view")
    assert ("--size WxH picture size in pixels, 16 … 8192 each and at most 20,000,000 in "
            "all (the 2 GB irring view may use; default: 1280x960)") in text
    assert MAX_PIXELS == 20_000_000
    assert size_refusal(5000, 4000) is None and size_refusal(5000, 4001) is not None


def test_compare_help_states_the_spread_as_its_table_does(capsys):
    """compare's --help said what "±" is in words of its own, beside the table footnote's
    (studies.compare.SPREAD): the two could drift apart. The help is built from it."""
    from irring.studies.compare import SPREAD

    assert f"per design (mean over scenarios × seeds; ± is {SPREAD}):" in _help(capsys,
                                                                             "compare")


def test_one_name_in_any_unicode_form_has_one_home():
    """Which names are one name (NFC) was decided in outputs.folder_name and again in
    scenario.check_distinct_names; both now ask outputs.name_key."""
    from irring import scenario
    from irring.outputs import folder_name, name_key

    source = Path(irring.__file__).parent
    homes = [f"{p.relative_to(source)}" for p in source.rglob("*.py")
             if 'normalize("NFC"' in p.read_text(encoding="utf-8")]
    assert homes == ["outputs.py"]
    nfc, nfd = "caf\u00e9", "cafe\u0301"
    assert name_key(nfd) == name_key(nfc) != name_key("Caf\u00e9")
    assert folder_name(nfd) == folder_name(nfc)
    room = "room: {outline_mm: [[0, 0], [900, 0], [900, 800], [0, 800]]}\n" \
           "robot: {poses: [{x_mm: 450, y_mm: 400}]}\n"
    a, b = (scenario.loads(f"name: {n}\n{room}", f"{i}.yaml") for i, n in enumerate((nfc, nfd)))
    with pytest.raises(scenario.ScenarioError, match=re.escape("(in another Unicode form)")):
        scenario.check_distinct_names([a, b])
