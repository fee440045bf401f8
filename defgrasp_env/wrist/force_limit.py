"""Force limit of the position-controlled wrist: it stops when the force its pads exert exceeds a limit.

The wrist is a position-controlled robot arm. A collaborative arm stops (protective stop) when the
force it exerts on its surroundings exceeds its safety limit; the default 150 N is the default force
limit of Universal Robots' e-Series safety configuration and about the quasi-static contact limit of
ISO/TS 15066 for the hand and fingers (140 N). The jaw driver limits the grip (the squeeze, which
cancels between the two pads); this limits the *net* force of both pads on the object,
``wrist_force = |f_left + f_right|`` (N, the force the wrist carries besides the gripper's weight).

Per physics substep the wrist moves by a fraction ``scale`` in [0, 1] of its planned joint motion:
1 when the resulting wrist force stays within ``limit * (1 + tolerance)``, else the fraction found
by bracketing (Illinois regula falsi on the measured force, a few extra solves of that substep)
that brings the force to the limit, and 0 (the wrist stops) when the force was at the limit before
the substep or no fraction is found. The jaw still closes under its own limit meanwhile.
Pure functions on arrays (shapes [W] per world); the scene supplies ``solve``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

#: Default wrist force limit (N): UR e-Series default safety force limit; ISO/TS 15066 hand ~140 N.
DEFAULT_WRIST_FORCE_LIMIT = 150.0
#: Relative overshoot of the limit accepted without a re-solve, and the extra solves at most.
FORCE_TOLERANCE = 0.1
MAX_RETRIES = 6


def wrist_force(pad_force: np.ndarray) -> np.ndarray:
    """Magnitude (N) [W] of the net force the pads exert on the object, from the forces the object
    exerts on each pad ``pad_force`` [W, P, 3] (N, world frame)."""
    return np.linalg.norm(np.asarray(pad_force, dtype=np.float64).sum(axis=1), axis=-1)


def next_scale(lo, hi, f_lo, f_hi, limit) -> np.ndarray:
    """Regula falsi: the motion fraction in (lo, hi) where the force, linear between (lo, f_lo) and
    (hi, f_hi), reaches ``limit``; kept 10 % of the bracket away from either end (forces are zero
    until touch, so the line is a poor model near the bracket ends)."""
    frac = (limit - f_lo) / np.maximum(f_hi - f_lo, 1e-9)
    return lo + (hi - lo) * np.clip(frac, 0.1, 0.9)


def limited_substep(solve: Callable[[np.ndarray], tuple[object, np.ndarray]], force_before: np.ndarray,
                    limit: float, tolerance: float = FORCE_TOLERANCE, retries: int = MAX_RETRIES):
    """Run one substep with the wrist force limited.

    Args:
        solve: ``solve(scale)`` runs the substep from the same start state with the wrist moved by
            the fraction ``scale`` [W] of its planned motion; returns (solver report, wrist force [W] N).
        force_before: wrist force [W] (N) at the substep start.
        limit: wrist force limit (N); ``inf`` disables the limit.
    Returns:
        (report, force [W], scale [W]) of the accepted solve.
    """
    force_before = np.asarray(force_before, dtype=np.float64)
    scale = np.ones_like(force_before)
    report, force = solve(scale)
    over = force > limit * (1.0 + tolerance)
    if not over.any():
        return report, force, scale
    # stop at once where the wrist already pressed at the limit; else bracket [0, 1]
    lo, f_lo = np.zeros_like(scale), np.minimum(force_before, limit)
    hi, f_hi = scale.copy(), force.copy()
    side = np.zeros_like(scale)  # Illinois: halve the stale end's excess after two moves of one side
    searching = over & (force_before < limit)
    scale = np.where(over, 0.0, 1.0)
    for _ in range(retries):
        if not searching.any():
            break
        trial = np.where(searching, next_scale(lo, hi, f_lo, f_hi, limit), scale)
        report, force = solve(trial)
        low = searching & (force <= limit * (1.0 + tolerance))
        high = searching & ~low
        done = low & (force >= limit * (1.0 - tolerance))
        f_hi = np.where(low & (side < 0), limit + 0.5 * (f_hi - limit), f_hi)
        f_lo = np.where(high & (side > 0), limit - 0.5 * (limit - f_lo), f_lo)
        lo, f_lo = np.where(low, trial, lo), np.where(low, force, f_lo)
        hi, f_hi = np.where(high, trial, hi), np.where(high, force, f_hi)
        side = np.where(low, -1.0, np.where(high, 1.0, side))
        scale = np.where(searching, lo, scale)
        searching &= ~done
        if np.array_equal(trial, scale):
            return report, force, scale   # the last solve is the accepted one in every world
    return (*solve(scale), scale)
