"""irring: a MuJoCo testbed for the rotating IR range-sensor ring of Park, Baek & Lee (2005)."""

import importlib

from .core import Points, Reason, RingSource, Sweep, Truth

__all__ = ["Points", "Reason", "RingSource", "Scenario", "ScenarioError", "Sweep", "Truth",
           "load_scenario", "SimRing"]

# Loaded when first asked for: the scenario names need pyyaml and SimRing MuJoCo, which the
# core types and the serial protocol (irring.hardware.protocol) do without.
_LAZY = {"Scenario": "scenario", "ScenarioError": "scenario", "load_scenario": "scenario",
         "SimRing": "simulation.sim"}


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module 'irring' has no attribute {name!r}")
