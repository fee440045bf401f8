"""Argument validation helpers shared by the meshing modules (error style of CONVENTIONS.md)."""

from __future__ import annotations

import math
from numbers import Real

__all__ = ["positive_length", "checked_resolution", "check_node_budget", "MAX_LATTICE_NODES"]

# Guard against a resolution so fine that the meshing would exhaust memory.
MAX_LATTICE_NODES = 16_000_000


def positive_length(name: str, value: object, upper: float = math.inf) -> float:
    """Return ``value`` as a float in (0, upper] metres or raise TypeError/ValueError."""
    if isinstance(value, bool) or not isinstance(value, Real):
        raise TypeError(f"{name} must be a real number in metres, got {value!r} ({type(value).__name__})")
    v = float(value)
    if not (math.isfinite(v) and v > 0.0 and v <= upper):
        hi = "inf)" if math.isinf(upper) else f"{upper:g}]"
        raise ValueError(f"{name} must be in (0, {hi} m, got {value!r}")
    return v


def checked_resolution(resolution: object, limit: float, subject: str, across: str) -> float:
    """``resolution`` as a float in (0, limit] m (at least one tet layer across ``across`` of
    ``subject``), or raise TypeError/ValueError naming the accepted range."""
    try:
        return positive_length("resolution", resolution, upper=limit)
    except ValueError:
        raise ValueError(
            f"resolution must be in (0, {limit:g}] m for {subject} (at least one tet layer "
            f"across {across}), got {resolution!r}"
        ) from None


def check_node_budget(count: int, spacing: float) -> None:
    """Raise ValueError if a mesher would create more than MAX_LATTICE_NODES nodes.

    ``spacing`` (metres) is the lattice/grid spacing derived from the resolution."""
    if count > MAX_LATTICE_NODES:
        raise ValueError(
            f"resolution is too fine for this object: a grid spacing of {spacing:.3g} m would "
            f"need {count} nodes (at most {MAX_LATTICE_NODES})"
        )
