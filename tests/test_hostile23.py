"""Round twenty-three of hostile input: each test names the input that broke and asserts
what happens now."""

from __future__ import annotations

import math

import pytest

from irring.cli import build_parser, main
from irring.cli._common import glue_negative_values


def test_a_negative_coordinate_list_is_read_as_the_options_value(capsys):
    # `--pose -500,450` (a pose left of the origin) was told only "argument --pose: expected
    # one argument": argparse takes a word beginning with '-' for an option unless it is a
    # plain number such as -5
    argv = ["drive", "--port", "ring.pty", "--pose", "-500,-450,-90", "--pose", "1210,450"]
    args = build_parser().parse_args(glue_negative_values(argv))
    assert args.pose == [(-0.5, -0.45, math.radians(-90)), (1.21, 0.45, 0.0)]
    # a negative number is now refused by the option's own check, which says what is allowed
    with pytest.raises(SystemExit) as stop:
        main(["geometry", "--range-mm", "-1e3"])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert (stop.value.code, err) == (2, "irring geometry: error: argument --range-mm: must be "
                                         "a number > 0 and ≤ 100000, got '-1e3'")
    # plain negative numbers, values given with '=', and words after `--` are left as they were
    assert glue_negative_values(["view", "--step", "-5", "--pose=-1,2", "--", "--x", "-1,2"]) \
        == ["view", "--step", "-5", "--pose=-1,2", "--", "--x", "-1,2"]
