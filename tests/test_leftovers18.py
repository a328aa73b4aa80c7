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


def _record(name: str, shadow):
    scores = {"occupied_f1": 0.9, "free_accuracy": 1.0, "coverage": 0.8, "shadow": shadow}
    return {"design": name, **scores, "hardware_time_s": 2.72, "compute_time_s": 0.004,
            "runs": 1, "scenarios": ["lab"], "poses": {"lab": 1},
            "by_scenario": {"lab": {**scores, "shadow_sd": 0.01}},
            "min_detectable_radius_m": [0.002]}


@pytest.mark.parametrize("shadow", [None, 0.6])
def test_the_shadow_panel_stands_its_designs_under_the_scores(tmp_path, figures, shadow):
    """With no room hiding a wall behind a post, compare.png's shadow panel had nothing to
    draw, yet kept its axes' 0 … 1 ticks and put the design names at x = 0 and 1 of an
    empty axis: a lone design's name in the panel's corner, two at its edges, under no
    bar. An empty panel has no ticks; a drawn one stands each design under the scores'."""
    from irring.studies import compare

    recs = [_record("rotating12", shadow), _record("radial12", shadow)]
    compare.chart({"designs": recs, "detection_distances_m": [0.35]}, tmp_path / "c.png")
    scores, shadows = figures[0].axes[:2]
    assert shadows.get_title() == ("Shadow: share of the wall hidden behind obstacles that "
                                   "the map shows")
    if shadow is None:
        assert list(shadows.get_xticks()) == [] and list(shadows.get_yticks()) == []
        assert shadows.get_ylabel() == ""
    else:
        assert [t.get_text() for t in shadows.get_xticklabels()] == ["rotating12", "radial12"]
        assert list(shadows.get_xticks()) == list(scores.get_xticks()) == [0, 1]
        assert shadows.get_xlim() == scores.get_xlim() == (-0.5, 1.5)
