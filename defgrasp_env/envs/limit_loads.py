"""What the actuator force limit reads of a solve, on the host, and which worlds it re-solves
patiently (``PickupScene._patient_if_over``): one download of ``scene_kernels.solve_loads``' rows.

An unconverged solve's reading may be off by its force error (``solve_loads``: the world's
stiffest node contact x its last Newton update, in limit units), and the limit compares the
reading plus that error with 1. Over the limit, a world is re-solved patiently (more Newton
iterations from the same input) unless that cannot change the decision: a try that moved and
reads over even less twice its error is retried with less motion at once. A re-solve asks for the
decision, not convergence: a world that moved and reads under the limit (over only with its error)
iterates until its update is ``PATIENT_UPDATE_FRACTION`` of the one that settles the reading (a
stiff torus touching a pad at 0.1 N read 1.1-2.4 with its error and took 60 extra iterations a
substep to converge to 0.001); a world that did not move (stopped or held) keeps its solve
whatever it reads (or backs off from it, on its forces), so it iterates to the Newton tolerance
(skipping it let a stiff cylinder's stopped pad be accepted at 832 N). A back-off (a negative
fraction) moved: one read over is rejected, one read under is kept, as a try with less motion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..wrist.force_limit import FORCE_TOLERANCE

#: a patient re-solve of a world that moved and reads under the limit stops at this fraction of the
#: update under which its reading plus the force error stays under 1: a margin for the reading's
#: own change as the iterate converges
PATIENT_UPDATE_FRACTION = 0.5


@dataclass(frozen=True)
class SolveLoads:
    """What the actuator force limit reads of a solve, per world (host copies of ``solve_loads``).

    Attributes:
        start: [W] the actuator load at the substep start (1 = at a limit).
        held: [W] bool, held at its limit (no motion tried).
        load: [W] the solve's load as read plus ``error`` (what the limit compares with 1).
        error: [W] the load an unconverged solve may be off by (0 when converged).
        deciding: [W] m, the last update under which the reading plus its error stays under 1 (0
            where the reading is not under 1).
    """

    start: np.ndarray
    held: np.ndarray
    load: np.ndarray
    error: np.ndarray
    deciding: np.ndarray

    @classmethod
    def from_rows(cls, rows: np.ndarray) -> "SolveLoads":
        """From ``solve_loads``' rows [W, 6] (downloaded); raises where a world's pad forces are
        not finite (the gripper's kernels would carry them into the jaw and the force limit)."""
        bad = rows[:, 3] == 0.0
        if bad.any():
            raise FloatingPointError(f"the solver returned non-finite pad forces in worlds {np.flatnonzero(bad).tolist()}")
        return cls(start=rows[:, 0], held=rows[:, 1] > 0.0, load=rows[:, 2], error=rows[:, 4], deciding=rows[:, 5])

    def certainly_over(self, tolerance: float = FORCE_TOLERANCE) -> np.ndarray:
        """[W] bool: over 1 + ``tolerance`` even if the reading is off by its whole error the other
        way: a patient re-solve would read over too (False where the error is not finite: a
        diverged solve's)."""
        finite = np.isfinite(self.error)
        return finite & (self.load - 2.0 * np.where(finite, self.error, 0.0) > 1.0 + tolerance)

    def patient_re_solve(self, fraction: np.ndarray, allowed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(worlds [W] bool, their update targets [W] m) of the patient re-solve after this solve
        of the ``fraction`` [W] of the planned motion, among the ``allowed`` worlds [W] bool (the
        caller's: unconverged, and not already a patient solve of the same input): those over
        1 + ``FORCE_TOLERANCE`` except a world that moved and is :meth:`certainly_over`; the
        target is ``PATIENT_UPDATE_FRACTION`` x ``deciding`` where it moved, 0 (the Newton
        tolerance) where it did not."""
        moved = np.asarray(fraction) != 0.0
        over = self.load > 1.0 + FORCE_TOLERANCE
        patient = over & ~(self.certainly_over() & moved) & np.asarray(allowed, dtype=bool)
        return patient, np.where(moved, PATIENT_UPDATE_FRACTION * self.deciding, 0.0)
