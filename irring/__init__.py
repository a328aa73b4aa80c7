"""irring: a MuJoCo testbed for the rotating IR range-sensor ring of Park, Baek & Lee (2005)."""

from .data import Points, Reason, Sweep, Truth
from .scenario import Scenario, ScenarioError, load_scenario

__all__ = ["Points", "Reason", "Scenario", "ScenarioError", "Sweep", "Truth", "load_scenario",
           "SimRing"]


def __getattr__(name: str):
    # SimRing pulls in MuJoCo; import it only when asked for.
    if name == "SimRing":
        from .sim import SimRing

        return SimRing
    raise AttributeError(f"module 'irring' has no attribute {name!r}")
