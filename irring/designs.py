"""Named ring designs, all generated from the one MJCF template with different numbers."""

from __future__ import annotations

import math

from .scenario import Ring, Robot

PAPER_RING = Ring()  # the paper's: 12 sensors, R = 0.15 m, ±35 motor steps of 1.8°, gear 0.6

DESIGNS: dict[str, Ring] = {
    "rotating12": PAPER_RING,
    "radial12": Ring(min_step=0, max_step=0),
    "rotating1": Ring(sensors=1, radius_m=0.0, min_step=0, max_step=333,
                      joint_limit_rad=2 * math.pi),
}


def ring_for(robot: Robot) -> Ring:
    """The ring a robot uses: its explicit `ring:` if given, else the named design's."""
    if robot.ring is not None:
        return robot.ring
    try:
        return DESIGNS[robot.design]
    except KeyError:
        raise ValueError(f"design {robot.design!r} has no ring preset; known: "
                         f"{', '.join(DESIGNS)}") from None
