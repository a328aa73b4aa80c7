"""Round twenty-four of hostile input: each test names the input that broke and asserts
what happens now."""

from __future__ import annotations

import pytest

from irring.cli import main


@pytest.mark.parametrize("argv, said", [
    (["run", "--seed", "3", "--out", "o", "--seed", "4"],
     "irring run: error: argument --seed: given twice ('3', then '4'); it takes one value, so "
     "give it once"),
    (["bench", "dynamics", "--seeds", "2", "5", "--seeds=3"],
     "irring bench dynamics: error: argument --seeds: given twice ('2 5', then '3'); list every "
     "value after one --seeds (--seeds 2 5 3)"),
])
def test_an_option_given_twice_with_other_values_is_refused(argv, said, tmp_path, monkeypatch,
                                                            capsys):
    # `--seeds 2 --seeds 3` ran seed 3 alone and `--seed 3 --seed 4` ran 4, without a word:
    # argparse keeps the last value
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert (stop.value.code, capsys.readouterr().err.splitlines()[-1]) == (2, said)
    assert list(tmp_path.iterdir()) == []


def test_an_option_given_twice_with_the_same_value_is_kept(capsys):
    # the same value twice loses nothing (`--seed 3 --seed 03`): kept, as are flags given twice
    from irring.cli import build_parser
    args = build_parser().parse_args(["run", "--seed", "3", "--json", "--seed", "03", "--json"])
    assert (args.seed, args.json) == (3, True)
    assert "_irring_given" not in vars(args)


def test_a_calibration_named_as_its_picture_is_refused(tmp_path, monkeypatch, capsys):
    # `calibrate --out c.png` wrote the YAML into c.png and the chart as c.png.png
    monkeypatch.chdir(tmp_path)
    assert main(["calibrate", "--out", "c ü.PNG", "--sweeps", "1"]) == 2
    assert capsys.readouterr().err == (
        "irring calibrate: error: --out c ü.PNG: a calibration is written as YAML, with its "
        "picture beside it; name the YAML file (--out c ü.yaml writes c ü.yaml and c ü.png)\n")
    assert list(tmp_path.iterdir()) == []
