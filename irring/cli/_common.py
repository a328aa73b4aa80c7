"""Argument parsing shared by several subcommands (not a subcommand itself)."""

from __future__ import annotations


def distances_mm(text: str, command: str) -> list[float]:
    """``--distances-mm`` "250,500,1000" (mm) → metres; exits with ``irring COMMAND: error:``
    unless it holds at least one number and all are positive."""
    try:
        values = [float(v) * 1e-3 for v in text.split(",") if v.strip()]
    except ValueError:
        raise SystemExit(f"irring {command}: error: --distances-mm wants numbers like "
                         f"250,500,1000; got {text!r}") from None
    if not values or min(values) <= 0:
        raise SystemExit(f"irring {command}: error: --distances-mm needs positive distances")
    return values
