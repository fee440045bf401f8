"""Force limits of the actuators within a physics substep: the wrist and the jaw stop (or move a
fraction of their planned substep motion) when the forces the solve measures exceed their limits.

The wrist is a position-controlled robot arm. A collaborative arm stops (protective stop) when the
force it exerts on its surroundings exceeds its safety limit; the default 150 N is the default force
limit of Universal Robots' e-Series safety configuration and about the quasi-static contact limit of
ISO/TS 15066 for the hand and fingers (140 N). The wrist force is the *net* force of both pads on the
object, ``wrist_force = |f_left + f_right|`` (N, the force the wrist carries besides the gripper's
weight). The jaw's motor limits the grip (the squeeze, which cancels between the two pads); the jaw
driver (``gripper.driver``) regulates it between substeps, on the forces of the previous one.

Within a substep the forces are limited here: a pad's normal force can be at most the grip force
limit plus the wrist limit (the jaw squeezes with at most the one, the arm pushes with at most the
other; both add at most on one pad), and the wrist force at most the wrist limit. ``actuator_load``
is the largest ratio of a force to its limit (1 = at a limit). Per substep the actuators move by a
fraction ``scale`` in [-1, 1] of the substep's planned motion (the wrist's slide and turn, and the
jaw's closing): 1 when the load stays within ``1 + tolerance``; else the fraction found by
bracketing (Illinois regula falsi on the measured load, a few extra solves of that substep) that
brings the load to 1; and 0 (wrist and closing jaw stop) when the load was at 1 before the substep
or no fraction is found. So a jaw that closes fast on a stiff object pinned against the ground (or
the other pad), or a wrist that pushes a pad into one, stops within the substep, before the penalty
contact reads kN. Where the stopped actuators still read over the limit (the object pushes back: a
compressed stiff object, or its momentum against a pad that stopped), the wrist yields as a
back-driven motor does: it backs off along the force the object exerts on the pads (a negative
fraction f in [-``BACK_OFF``, 0]: -f planned slide lengths; orientation and jaw kept; none where the
pads only squeeze or no slide is planned: ``Gripper.aim_back_off``), by the least that brings the
load to the limit, bracketed the same way; where no back-off reads within the limit, the stop stands
(backing off along the reversed plan instead made a sphere, E = 1e6, pressed while turning read 4x
the limit). Before, a stopped pad could not yield: a stiff cylinder (E = 3e6) swept at the default
limits read 1.1-1.3 kN on one for four substeps, converged (with the tets' rotation seed of
``sim.kernels.elastic.frame_rotation``: the bounds rested on particular trajectories;
``benchmarks/RESULTS.md``). A world that stays at its limit under the same push (``held``:
``Gripper.held_at_limit``, e.g. a learner pressing the object into the ground for seconds) stays
stopped in one solve per substep (more where the stop still reads over and it backs off) instead of
trying its motion again (a solve over the limit, a patient re-solve and the stopped re-solve: 2.75-3
solves per substep, ~15x the time of a free step on the CPU, and on the GPU the batch's slowest
world), like a protective stop that holds until the load drops below the limit or the command turns
away (``Gripper.held_at_limit``: the same flange push within ~26 degrees, with or without a turn of
the wrist). Where the try would have been stopped anyway (a push into a stiff object) the result is
the same, bit for bit (tests/test_wrist_force_limit.py, also the rope); where a try's patient
re-solve would have read within the tolerance, the held wrist stays where it stopped instead of
creeping on in 10 % load steps (a first version that held on any push with a positive component
along the stopped one changed the recorded operator stream's rope episode so: it kept its grasp).
Pure functions on arrays (shapes [W] per world); the scene supplies ``solve``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

#: Default wrist force limit (N): UR e-Series default safety force limit; ISO/TS 15066 hand ~140 N.
DEFAULT_WRIST_FORCE_LIMIT = 150.0
#: Relative overshoot of a limit accepted without a re-solve, and the extra solves at most per search
#: (``limited_substep``'s retries with less motion, and again for a back-off; each + 1 final solve).
FORCE_TOLERANCE = 0.1
MAX_RETRIES = 6
#: The most a stopped wrist backs off in a substep when the object still pushes it over its limit,
#: in lengths of the substep's planned slide (``limited_substep``: fraction down to -BACK_OFF).
BACK_OFF = 1.0


def wrist_force(pad_force: np.ndarray) -> np.ndarray:
    """Magnitude (N) [W] of the net force the pads exert on the object, from the forces the object
    exerts on each pad ``pad_force`` [W, P, 3] (N, world frame)."""
    return np.linalg.norm(np.asarray(pad_force, dtype=np.float64).sum(axis=1), axis=-1)


def tip_force_bound(grip_force_limit: float, wrist_force_limit: float) -> float:
    """Largest normal force (N) one pad may exert: the jaw's grip-force limit plus the wrist's limit."""
    return grip_force_limit + wrist_force_limit


def actuator_load(wrist: np.ndarray, tip: np.ndarray, wrist_force_limit: float,
                  grip_force_limit: float) -> np.ndarray:
    """Load [W] (dimensionless, 1 = at a limit) of the actuators: the larger of ``wrist`` [W] (N, net
    pad force) over ``wrist_force_limit`` and the largest of ``tip`` [W, P] (N, pad normal forces)
    over ``tip_force_bound``; 0 where the wrist limit is ``inf`` (limits disabled)."""
    wrist = np.asarray(wrist, dtype=np.float64)
    tip = np.asarray(tip, dtype=np.float64).max(axis=-1)
    if not np.isfinite(wrist_force_limit):
        return np.zeros_like(wrist)
    return np.maximum(wrist / wrist_force_limit, tip / tip_force_bound(grip_force_limit, wrist_force_limit))


def next_scale(lo, hi, f_lo, f_hi, limit) -> np.ndarray:
    """Regula falsi: the motion fraction in (lo, hi) where the load, linear between (lo, f_lo) and
    (hi, f_hi), reaches ``limit``; kept 10 % of the bracket away from either end (forces are zero
    until touch, so the line is a poor model near the bracket ends)."""
    frac = (limit - f_lo) / np.maximum(f_hi - f_lo, 1e-12)
    return lo + (hi - lo) * np.clip(frac, 0.1, 0.9)


def limited_substep(solve: Callable[[np.ndarray], tuple[object, np.ndarray]], load_before: np.ndarray,
                    tolerance: float = FORCE_TOLERANCE, retries: int = MAX_RETRIES, held: np.ndarray | None = None,
                    first: tuple[object, np.ndarray] | None = None,
                    can_back_off: Callable[[np.ndarray], np.ndarray] | None = None):
    """Run one substep with the actuator load limited to 1 (+ ``tolerance``).

    Args:
        solve: ``solve(scale)`` runs the substep from the same start state with the actuators
            moved by the fraction ``scale`` [W] of their planned motion (negative: the wrist backed
            off by -scale of its back-off, ``Gripper.aim_back_off``); returns (result, load [W]),
            the load as ``actuator_load`` (1 = at a limit) and ``result`` anything the caller needs
            (solver report, forces).
        load_before: load [W] at the substep start.
        held: [W] bool (default none): worlds that start stopped (scale 0) without trying their
            planned motion (and back off where that still reads over): those at a limit whose
            actuators the limit stopped before on a motion in the same direction
            (``Gripper.held_at_limit``). Trying it would read over the limit and stop them again, at
            the cost of a solve and a patient re-solve per substep.
        first: (result, load) of the first try, ``solve(scale)`` with ``scale`` 0 where ``held`` and
            1 elsewhere, when the caller ran it already (default: run here).
        can_back_off: ``can_back_off(over)`` [W] bool: of the stopped worlds still ``over`` [W] bool
            the limit, those whose wrist has a way to back off (the scene aims the back-off from
            the stopped solve here: none where no slide is planned or the pads only squeeze);
            default: all.
    Returns:
        (result, load [W], scale [W]) of the accepted solve, which is always the last one run;
        ``scale`` in [-``BACK_OFF``, 1].
    """
    limit = 1.0
    load_before = np.asarray(load_before, dtype=np.float64)
    scale = np.ones_like(load_before) if held is None else np.where(held, 0.0, 1.0)
    result, load = solve(scale) if first is None else first
    over = (load > limit * (1.0 + tolerance)) & (scale > 0.0)  # a held world has no motion to take back
    if over.any():
        # stop at once where the actuators already pressed at the limit; else bracket [0, 1]
        searching = over & (load_before < limit)
        bracket = (np.zeros_like(scale), np.minimum(load_before, limit), scale.copy(), load.copy())
        scale = np.where(over, 0.0, scale)
        result, load = _bracket(solve, result, load, scale, bracket, searching, tolerance, retries)
    # stopped (or held) and still over: the object pushes back on the stopped pads (a compressed
    # stiff object, its momentum); the wrist yields, backing off by at most ``BACK_OFF``, the least
    # that brings the load to the limit (bracket [-BACK_OFF, 0], no load assumed at its far end);
    # where no back-off reads within the limit, the stop stands
    over = (load > limit * (1.0 + tolerance)) & (scale <= 0.0)
    if over.any() and can_back_off is not None:
        over &= np.asarray(can_back_off(over), dtype=bool)
    if over.any():
        bracket = (np.full_like(scale, -BACK_OFF), np.zeros_like(scale), scale.copy(), load.copy())
        result, load = _bracket(solve, result, load, scale, bracket, over, tolerance, retries)
    return result, load, scale


def _bracket(solve, result, load, scale: np.ndarray, bracket: tuple, searching: np.ndarray, tolerance: float,
             retries: int):
    """``limited_substep``'s search: Illinois regula falsi on the measured load, per searching world
    [W] bool, in its ``bracket`` (lo, f_lo, hi, f_hi) [W] each (lo reads at most the limit, hi over
    it), for the largest fraction that reads within 1 +- ``tolerance``; ``scale`` [W] (updated in
    place) is each world's accepted fraction: a searching world's last trial that read at most the
    limit (its start where none did: lo's load may be assumed, not measured). At most ``retries``
    solves, then a solve of the scales unless the last retry solved them already. Returns (result,
    load) of the last solve, which is the accepted one."""
    limit = 1.0
    lo, f_lo, hi, f_hi = (np.array(a, dtype=np.float64) for a in bracket)
    searching = searching.copy()
    side = np.zeros_like(scale)  # Illinois: halve the stale end's excess after two moves of one side
    trial = None
    for _ in range(retries):
        if not searching.any():
            break
        trial = np.where(searching, next_scale(lo, hi, f_lo, f_hi, limit), scale)
        result, load = solve(trial)
        low = searching & (load <= limit * (1.0 + tolerance))
        high = searching & ~low
        done = low & (load >= limit * (1.0 - tolerance))
        f_hi = np.where(low & (side < 0), limit + 0.5 * (f_hi - limit), f_hi)
        f_lo = np.where(high & (side > 0), limit - 0.5 * (limit - f_lo), f_lo)
        lo, f_lo = np.where(low, trial, lo), np.where(low, load, f_lo)
        hi, f_hi = np.where(high, trial, hi), np.where(high, load, f_hi)
        side = np.where(low, -1.0, np.where(high, 1.0, side))
        scale[:] = np.where(low, trial, scale)
        searching &= ~done
    # only once no world searches (or the retries ran out): ending the retries as soon as every
    # world's trial was accepted also ended a searching world's refinement (accepted under 1 -
    # tolerance) where no other world read over, so a world's course depended on the batch
    if trial is not None and np.array_equal(trial, scale):
        return result, load   # the last solve is the accepted one in every world
    return solve(scale.copy())
