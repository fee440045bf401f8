"""``SolveStats`` (the host report of a solve) and ``SolveReport`` (its device-side accumulator).

The solver leaves each solve's per-world counters and flags in its scratch arrays on the device.
``SolveReport.fold`` folds them into one packed record per world (``kernels.report``), so that a
caller running several solves per control step (substeps, wrist-limit retries) keeps only the
accepted ones and brings the step's report to the host with one download (``download``), instead
of one download per field per solve: on a GPU each download is a device synchronisation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from .kernels.report import SolveRecord, fold_solve_record
from .launch_cache import LaunchCache
from .solver_scratch import SolverScratch


@dataclass
class SolveStats:
    """Per-world convergence report of one ``step`` (numpy arrays of shape [W])."""

    newton_iterations: np.ndarray   # int: Newton iterations summed over substeps
    cg_iterations: np.ndarray       # int: CG iterations summed over Newton iterations and substeps
    last_update: np.ndarray         # float, m: largest node update of the last full Newton step
    residual_force: np.ndarray      # float, N: largest node force residual at the returned state
    penetration: np.ndarray         # float, m: deepest at the returned state: a node in the ground or a pad,
    #                                 a pad edge in the object
    diverged: np.ndarray            # bool: the world blew up (NaN, runaway update); its state was kept
    converged: np.ndarray           # bool: every substep's Newton loop met newton_tolerance, not diverged
    penetrated: np.ndarray          # bool: a substep's solve left a node deeper than
    #                                 SolverConfig.penetration_bound (put back to 0.9 x it: positions
    #                                 clamped, velocities follow), or the returned state is deeper

    @classmethod
    def combine(cls, reports: "list[SolveStats]") -> "SolveStats":
        """One report for consecutive steps: iterations summed, the last state's update and
        residual, the deepest penetration, and any step's divergence/non-convergence/penetration."""
        return cls(
            newton_iterations=np.sum([r.newton_iterations for r in reports], axis=0),
            cg_iterations=np.sum([r.cg_iterations for r in reports], axis=0),
            last_update=reports[-1].last_update,
            residual_force=reports[-1].residual_force,
            penetration=np.max([r.penetration for r in reports], axis=0),
            diverged=np.any([r.diverged for r in reports], axis=0),
            converged=np.all([r.converged for r in reports], axis=0),
            penetrated=np.any([r.penetrated for r in reports], axis=0),
        )


class SolveReport:
    """Device-side ``SolveStats`` of W worlds, folded over consecutive solves.

    ``fold(scratch, bound, first)`` after a solve adds that solve's report (``first``: starts a new
    report), as ``SolveStats.combine`` of the folded solves' reports would; ``download()`` brings
    it to the host in one transfer. ``records`` ([W] ``SolveRecord``) is the device array.
    """

    def __init__(self, num_worlds: int, device):
        self.num_worlds = num_worlds
        self.device = device
        self.records = wp.zeros(num_worlds, dtype=SolveRecord, device=device)
        self._launches = LaunchCache(device)

    def fold(self, scratch: SolverScratch, penetration_bound: float, first: bool) -> None:
        """Fold the last solve's report (left in ``scratch``) in; ``first``: overwrite instead."""
        s = scratch
        self._launches.launch((id(s), penetration_bound, first), fold_solve_record, self.num_worlds,
                              [s.newton_it, s.cg_total, s.last_dx, s.res_norm, s.penetration, s.diverged,
                               s.unconverged, s.clamped, penetration_bound, int(first)], [self.records], keep=(s,))

    def download(self) -> SolveStats:
        """The folded report on the host (one device-to-host copy): iteration counts int64, update,
        residual and penetration float32 (as the solver computes them), flags bool."""
        r = self.records.numpy()
        diverged = r["diverged"] != 0
        return SolveStats(
            newton_iterations=r["newton_iterations"].astype(np.int64),
            cg_iterations=r["cg_iterations"].astype(np.int64),
            last_update=r["last_update"].copy(),
            residual_force=r["residual_force"].copy(),
            penetration=r["penetration"].copy(),
            diverged=diverged,
            converged=~diverged & (r["unconverged"] == 0),
            penetrated=r["penetrated"] != 0,
        )
