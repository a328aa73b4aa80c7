"""irring: a MuJoCo testbed for the rotating IR range-sensor ring of Park, Baek & Lee (2005)."""

from importlib.util import find_spec as _find_spec

# The estimator and mapper run compiled kernels (irring/*/_*.pyx) that pip builds at install;
# a source tree used without installing has only their sources.
_KERNELS = ("estimation._iterate", "estimation._lines", "maps._traverse")
_unbuilt = [k for k in _KERNELS if _find_spec(f"{__name__}.{k}") is None]
if _unbuilt:
    raise ImportError(
        f"irring's compiled kernels {', '.join(_unbuilt)} are not built: install irring with "
        f"`pip install .` (or `pip install -e .` in a checkout); pip compiles them with the "
        f"machine's C compiler (Debian: apt install build-essential python3-dev)")

from .data import Points, Reason, Sweep, Truth  # noqa: E402
from .scenario import Scenario, ScenarioError, load_scenario  # noqa: E402

__all__ = ["Points", "Reason", "Scenario", "ScenarioError", "Sweep", "Truth", "load_scenario",
           "SimRing"]


def __getattr__(name: str):
    # SimRing pulls in MuJoCo; import it only when asked for.
    if name == "SimRing":
        from .simulation.sim import SimRing

        return SimRing
    raise AttributeError(f"module 'irring' has no attribute {name!r}")
