"""tests/sameness.py masks what two runs of the same code make up (times, temporary paths)
and nothing else: `check main` on an unchanged tree showed bench dynamics' check_cost
seconds and calibrate's resume hint (a mkstemp file, the record's work folder) as changes."""

from __future__ import annotations

import json

import sameness


def _run(stdout: str, stderr: str = "") -> dict:
    return {"name": "x", "argv": ["x"], "exit": 0, "stdout": stdout, "stderr": stderr,
            "files": {}}


def test_check_cost_timings_are_masked_and_its_results_kept():
    cost = {"scene": "t_room_moving", "physics_steps": 5731, "check_change_rad": 1.5e-05,
            "halving_change_rad": 2.5e-06}
    a = {**cost, "physics_s": 0.534, "check_s": 0.324, "halving_s": 1.104,
         "check_ratio": 0.607, "halving_ratio": 2.069}
    b = {**cost, "physics_s": 0.308, "check_s": 0.223, "halving_s": 0.744,
         "check_ratio": 0.724, "halving_ratio": 2.413}
    wrap = lambda d: json.dumps({"check_cost": d})   # noqa: E731
    assert (sameness.normalise_record([_run(wrap(a))])
            == sameness.normalise_record([_run(wrap(b))]))
    moved = {**b, "check_change_rad": 3.0e-05}
    assert (sameness.normalise_record([_run(wrap(a))])
            != sameness.normalise_record([_run(wrap(moved))]))


def test_the_resume_hint_paths_are_masked_and_its_counts_kept():
    hint = ("irring calibrate: the {n} placements read (of 28) are kept in "
            "/tmp/irring-calibrate-{x}.yaml; resume with: irring calibrate --port "
            "/tmp/sameness-{w}/link --resume /tmp/irring-calibrate-{x}.yaml\n")
    a = hint.format(n=28, x="jl4ct68s", w="ul_oga7p")
    b = hint.format(n=28, x="w90ps_kw", w="hdko_asb")
    fewer = hint.format(n=27, x="w90ps_kw", w="hdko_asb")
    norm = lambda err: sameness.normalise_record([_run("", err)])   # noqa: E731
    assert norm(a) == norm(b)
    assert "--port <work>/link --resume <tmp>/irring-calibrate-<x>.yaml" in norm(a)
    assert norm(a) != norm(fewer)
