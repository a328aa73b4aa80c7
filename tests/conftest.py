"""Shared fixtures: bundled scenarios (loaded once) and their raw YAML for mutating, and the
figures a chart draws."""

from __future__ import annotations

import copy
import os
import shutil
import signal
import tempfile
from pathlib import Path

import pytest
import yaml
from hypothesis import settings

# No per-example deadline anywhere: on a loaded machine hypothesis's 200 ms failed examples
# whose code was fine (a timing check that flakes; speed is benchmarked, not tested). CI
# (CI=true, .ci/run) also draws the same examples every run: a red CI must mean a
# regression, not a new draw; elsewhere hypothesis explores
settings.register_profile("dev", deadline=None)
settings.register_profile("ci", derandomize=True, deadline=None)
settings.load_profile("ci" if os.environ.get("CI", "").lower() in ("1", "true", "yes")
                      else "dev")

# A suite started in the background of a script (`cmd &`) or under nohup inherits SIGINT or
# SIGHUP ignored, and the tests of Ctrl-C and of a hung-up terminal (test_hostile) then saw
# neither; they need both as a terminal delivers them, here and in the commands they start
signal.signal(signal.SIGINT, signal.default_int_handler)
signal.signal(signal.SIGHUP, signal.SIG_DFL)

from irring import scenario as scenario_lib


@pytest.fixture(scope="session")
def t_room() -> scenario_lib.Scenario:
    """The paper's inverted-T room, four poses (bundled ``t_room``)."""
    return scenario_lib.load_scenario("t_room")


@pytest.fixture(scope="session")
def three_cylinders() -> scenario_lib.Scenario:
    """The T-room with two small and one large cylinder (bundled)."""
    return scenario_lib.load_scenario("t_room_three_cylinders")


@pytest.fixture(scope="session")
def _t_room_yaml() -> dict:
    return yaml.safe_load(scenario_lib.resolve("t_room").read_text())


@pytest.fixture
def t_room_raw(_t_room_yaml) -> dict:
    """A fresh, mutable copy of ``t_room.yaml`` as parsed YAML (change it, then ``parse``)."""
    return copy.deepcopy(_t_room_yaml)


@pytest.fixture(scope="session")
def t_room_recording(tmp_path_factory, t_room) -> dict:
    """`irring run t_room`'s sweeps.npz, entry by entry, read-only (a test edits a copy)."""
    import numpy as np

    from irring import pipeline

    out = tmp_path_factory.mktemp("run")
    pipeline.write_outputs(pipeline.run(t_room), out, animation=False)
    with np.load(out / "sweeps.npz") as z:
        entries = {k: z[k] for k in z.keys()}
    for v in entries.values():
        v.flags.writeable = False
    return entries


@pytest.fixture
def figures(monkeypatch) -> list:
    """Every figure ``irring.maps.render.figure`` makes during the test, in order (a chart's
    lines and texts, read after it is saved)."""
    from irring.maps import render

    made: list = []
    real = render.figure
    monkeypatch.setattr(render, "figure", lambda *a, **k: made.append(real(*a, **k)) or made[-1])
    return made


@pytest.fixture
def short_tmp():
    """A temporary folder of a short path (tempfile's): an error line naming it twice stays
    within errors.MAX_MESSAGE whatever pytest's folder is (an xdist worker's adds popen-gw0/,
    and the study's line was cut)."""
    folder = Path(tempfile.mkdtemp(prefix="irring-"))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)
