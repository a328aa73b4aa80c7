"""The `irring` command as a user meets it: help for every command, the scenario list, and
clear errors for bad input."""

from __future__ import annotations

import pytest

from irring import scenario
from irring.cli import COMMANDS, main
from irring.cli.bench import BENCHES


def test_no_command_prints_help_and_fails(capsys):
    assert main([]) == 2
    out = capsys.readouterr().out
    for name in COMMANDS:
        assert name in out


@pytest.mark.parametrize("argv", [[name, "--help"] for name in COMMANDS] +
                         [["bench", name, "--help"] for name in BENCHES])
def test_every_command_explains_itself(argv, capsys):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: irring " + " ".join(argv[:-1]))
    assert len(out.splitlines()) >= 4  # more than a bare usage line


def test_scenarios_lists_every_bundled_scenario_and_marks_the_default(capsys):
    assert main(["scenarios"]) == 0
    lines = capsys.readouterr().out.splitlines()
    names = [line.split()[0] for line in lines]
    assert names == sorted(scenario.bundled())
    default = [line for line in lines if line.startswith(scenario.DEFAULT_SCENARIO + " ")]
    assert default and default[0].endswith("(default)")


def test_an_unknown_scenario_names_the_bundled_ones(capsys):
    assert main(["run", "t_rooom", "--out", "/nonexistent/never-written"]) == 2
    err = capsys.readouterr().err
    assert "t_rooom: no such file and no bundled scenario of that name" in err
    assert "t_room_cylinder" in err
