"""irring: a MuJoCo testbed for the rotating IR range-sensor ring of Park, Baek & Lee (2005)."""

import importlib
import os
import signal
import sys


def interrupted_starting(signum, frame):
    """Ctrl-C while the `irring` command imports, before its main() takes Ctrl-C over: the
    one line main() would print (Python's own handler printed a traceback), exit 130."""
    os.write(2, b"irring: interrupted\n")
    os._exit(130)


# the command (its console script), not a program importing irring: until main() runs
if os.path.basename(sys.argv[0] if sys.argv else "") == "irring" and \
        signal.getsignal(signal.SIGINT) is signal.default_int_handler:
    signal.signal(signal.SIGINT, interrupted_starting)

from .core import Points, Reason, RingSource, Sweep, Truth  # noqa: E402 - after the handler

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
