"""Argument validation shared by the teleop package.

Every public entry point validates at the boundary and raises ``ValueError`` (bad value) or
``TypeError`` (bad type) with the offending value and the accepted range, as CONVENTIONS.md asks:
``full_scale_n must be in (0, inf) N, got -3.0``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def check_number(
    name: str,
    value: Any,
    lo: float = -math.inf,
    hi: float = math.inf,
    *,
    unit: str = "",
    lo_open: bool = False,
    hi_open: bool = False,
) -> float:
    """Return ``value`` as a float after checking it is a finite real in the given interval.

    ``lo_open``/``hi_open`` make the bound exclusive. Infinite bounds are always open.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {value!r} ({type(value).__name__})")
    v = float(value)
    left = "(" if lo_open or math.isinf(lo) else "["
    right = ")" if hi_open or math.isinf(hi) else "]"
    suffix = f" {unit}" if unit else ""
    rng = f"{left}{lo:g}, {hi:g}{right}{suffix}"
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite and in {rng}, got {value!r}")
    if v < lo or v > hi or (lo_open and v == lo) or (hi_open and v == hi):
        raise ValueError(f"{name} must be in {rng}, got {v!r}")
    return v


def check_array(
    name: str,
    value: Any,
    shape: tuple[int, ...],
    *,
    lo: float = -math.inf,
    hi: float = math.inf,
    unit: str = "",
    dtype: type = np.float64,
) -> np.ndarray:
    """Return ``value`` as a finite array of exactly ``shape`` with entries in [lo, hi] (a copy)."""
    try:
        arr = np.array(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a numeric array of shape {shape}, got {value!r}") from exc
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    suffix = f" {unit}" if unit else ""
    if np.any(arr < lo) or np.any(arr > hi):
        bad = arr[(arr < lo) | (arr > hi)]
        raise ValueError(
            f"{name} entries must be in [{lo:g}, {hi:g}]{suffix}, got {bad.tolist()} in {arr.tolist()}"
        )
    return arr


def check_choice(name: str, value: Any, choices: tuple) -> Any:
    """Check that ``value`` is one of ``choices``."""
    if value not in choices:
        raise ValueError(f"{name} must be one of {choices}, got {value!r}")
    return value


def check_port(name: str, value: Any) -> int:
    """A UDP port: an int in [0, 65535] (0 = let the OS choose)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an int in [0, 65535], got {value!r}")
    if not 0 <= int(value) <= 65535:
        raise ValueError(f"{name} must be in [0, 65535], got {value!r}")
    return int(value)


def readonly(arr: np.ndarray) -> np.ndarray:
    """Mark an array read-only (samples are immutable values) and return it."""
    arr.setflags(write=False)
    return arr
