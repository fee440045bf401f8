"""Implicit (backward Euler) FEM solver: a thin launcher over the kernels.

Each substep solves  M/h^2 (x - x_start - h v) = f_elastic(x) + f_contact(x) + M g + f_ext  for x by
Newton's method (projected elastic Hessian, exact contact normal Hessian, lagged friction), each
Newton system by block-Jacobi preconditioned CG with a coarse correction on the rigid translations
(kernels/linear_solve.py), a backtracking line search on the incremental potential
(kernels/energy.py, kernels/line_search.py), all per world. The scratch arrays are a
``SolverScratch``; the launches of each phase of a substep are recorded by ``solver_launches``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from .materials import check_range
from .model import Model
from .solver_launches import SubstepLaunches, record_substep_launches
from .solver_scratch import SolverScratch
from .state import Control, State


@dataclass(frozen=True)
class SolverConfig:
    """Iteration limits and tolerances of the implicit solver.

    Attributes:
        substeps: backward-Euler substeps per call of ``step``.
        newton_iterations: Newton iterations per substep at most.
        newton_tolerance: a world's Newton loop stops once the largest node update of its full Newton
            step (before the line search shortens it) is below this, m.
        cg_iterations: CG iterations per Newton iteration at most.
        cg_tolerance: CG stops once r.z falls below cg_tolerance^2 of its initial value.
        cg_update_fraction: CG also stops, from its 8th iteration on, after an iteration that moved no
            node by more than this fraction of ``newton_tolerance`` (r.z alone cannot fall below
            float32 noise near a solution).
        max_node_step: a Newton update longer than this (m) marks the world as diverged.
        line_search_steps: halvings of a Newton step at most while it raises the energy.
        penetration_bound: no node ends a substep deeper than this (m) inside a pad's collision box
            (behind its contact face) or below the ground: a solve that leaves one deeper has it put
            back to 90 % of this depth and is flagged (``SolveStats.penetrated``).
        penetration_iterations: extra Newton iterations at most per substep, after
            ``newton_iterations``, in the worlds whose iterate is still deeper than half of
            ``penetration_bound`` (a violent contact the regular iterations did not resolve).
        patient_iterations: extra Newton iterations at most per substep, after
            ``newton_iterations``, in the worlds a ``step`` call marks ``patient``, while their update
            is above ``newton_tolerance`` (a caller that needs the contact forces of a converged
            solve: an unconverged iterate of a stiff contact can read kN where the solution reads
            tens of N).
        check_every: on the host, test every this many CG iterations, and after every Newton
            iteration and line-search trial, whether all worlds are done (0 = never: run the full
            iteration counts, with no host round trip).
    """

    substeps: int = 2
    newton_iterations: int = 4
    newton_tolerance: float = 1e-5
    cg_iterations: int = 40
    cg_tolerance: float = 1e-3
    cg_update_fraction: float = 1e-3
    max_node_step: float = 0.5
    line_search_steps: int = 8
    check_every: int = 4
    penetration_bound: float = 1e-3
    penetration_iterations: int = 8
    patient_iterations: int = 60

    def __post_init__(self) -> None:
        for name, low in (("substeps", 1), ("newton_iterations", 1), ("cg_iterations", 1),
                          ("line_search_steps", 0), ("check_every", 0), ("penetration_iterations", 0),
                          ("patient_iterations", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
        check_range("newton_tolerance", self.newton_tolerance, 0.0, math.inf, "m")
        check_range("cg_tolerance", self.cg_tolerance, 0.0, 1.0)
        check_range("cg_update_fraction", self.cg_update_fraction, 0.0, 1.0, low_open=False, high_open=False)
        check_range("max_node_step", self.max_node_step, 0.0, math.inf, "m")
        check_range("penetration_bound", self.penetration_bound, 0.0, math.inf, "m")


@dataclass
class SolveStats:
    """Per-world convergence report of one ``step`` (numpy arrays of shape [W])."""

    newton_iterations: np.ndarray   # int: Newton iterations summed over substeps
    cg_iterations: np.ndarray       # int: CG iterations summed over Newton iterations and substeps
    last_update: np.ndarray         # float, m: largest node update of the last full Newton step
    residual_force: np.ndarray      # float, N: largest node force residual at the returned state
    penetration: np.ndarray         # float, m: deepest ground/pad penetration at the returned state
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


class ImplicitSolver:
    """Advances a ``State`` of a ``Model`` by ``dt`` under a ``Control``.

    Scratch arrays (``SolverScratch``) and the recorded kernel launches (``SubstepLaunches``) are
    made once per model (and per substep length), so a step costs a couple of microseconds of
    Python per launch. Usage::

        solver = ImplicitSolver(model, SolverConfig())
        stats = solver.step(state_in, state_out, control, dt=0.05)
    """

    def __init__(self, model: Model, config: SolverConfig = SolverConfig()):
        self.model = model
        self.config = config
        self.work = State.from_model(model)       # the solver's own copy of the state
        self.work_control = Control.from_model(model)
        self.scratch = SolverScratch.from_model(model)
        self._launches: dict[float, SubstepLaunches] = {}

    # -- public --------------------------------------------------------------------------------
    def step(self, state_in: State, state_out: State, control: Control, dt: float,
             patient: np.ndarray | None = None) -> SolveStats:
        """Advance ``state_in`` by ``dt`` seconds into ``state_out`` (they may be the same object).
        ``patient`` [W] bool (default none): worlds given up to ``config.patient_iterations`` extra
        Newton iterations per substep until they meet ``newton_tolerance``; every other world's
        result is the same, bit for bit, as without it (its ``converged`` flag stays False when the
        regular iterations did not converge, even if the extra ones did)."""
        check_range("dt", dt, 0.0, math.inf, "s")
        cfg, s, work = self.config, self.scratch, self.work
        patient_any = patient is not None and bool(np.any(patient))
        if patient_any:
            s.patient.assign(np.asarray(patient, dtype=np.int32).reshape(self.model.num_worlds))
        run = self._substep_launches(dt / cfg.substeps)
        for name in ("positions", "velocities", "pad_positions", "pad_orientations"):
            wp.copy(getattr(work, name), getattr(state_in, name))
        for name in self.work_control.__dataclass_fields__:
            wp.copy(getattr(self.work_control, name), getattr(control, name))
        wp.copy(s.step_start, state_in.positions)
        for a in (s.newton_it, s.cg_total, s.diverged, s.unconverged, s.clamped, s.penetration):
            a.zero_()
        for k in range(cfg.substeps):
            for cmd in run.pads[k]:
                cmd.launch()
            run.begin[k].launch()
            for cmd in run.lag:
                cmd.launch()
            self._newton(run, cfg.patient_iterations if patient_any else 0)
            run.clamp.launch()
            run.end.launch()
            if k == cfg.substeps - 1:
                self._evaluate_outputs(run)
            wp.copy(work.velocities, s.v_new)
        wp.copy(work.pad_positions, self.work_control.pad_target_positions)
        wp.copy(work.pad_orientations, self.work_control.pad_target_orientations)
        state_out.copy_from(work)
        if patient_any:
            s.patient.zero_()
        diverged = s.diverged.numpy().astype(bool)
        penetration = s.penetration.numpy().copy()
        return SolveStats(
            newton_iterations=s.newton_it.numpy().copy(),
            cg_iterations=s.cg_total.numpy().copy(),
            last_update=s.last_dx.numpy().copy(),
            residual_force=s.res_norm.numpy().copy(),
            penetration=penetration,
            diverged=diverged,
            converged=~diverged & (s.unconverged.numpy() == 0),
            penetrated=(penetration > cfg.penetration_bound) | (s.clamped.numpy() != 0),
        )

    # -- internals ---------------------------------------------------------------------------
    def _newton(self, run: SubstepLaunches, patient_iterations: int = 0) -> None:
        cfg, s = self.config, self.scratch
        wp.copy(s.newton_active, s.all_on)
        s.substep_newton_it.zero_()
        regular, deep = cfg.newton_iterations, cfg.penetration_iterations
        for it in range(regular + max(deep, patient_iterations)):
            if it >= regular:
                # extra iterations only in worlds still deeper than half the penetration bound ...
                if it < regular + deep:
                    for cmd in run.depth:
                        cmd.launch()
                else:
                    s.newton_active.zero_()
                # ... and in patient worlds not yet converged
                if it < regular + patient_iterations:
                    run.patient.launch()
                if cfg.check_every and not s.newton_active.numpy().any():
                    break
            for cmd in run.evaluate:
                cmd.launch()
            self._run_cg(run)
            for cmd in run.coarse_post:
                cmd.launch()
            self._line_search(run, first=it == 0)
            for cmd in run.apply:
                cmd.launch()
            if cfg.check_every and it < cfg.newton_iterations - 1 and not s.newton_active.numpy().any():
                break

    def _run_cg(self, run: SubstepLaunches) -> None:
        cfg, active = self.config, self.scratch.cg_active
        for it in range(cfg.cg_iterations):
            for cmd in run.cg:
                cmd.launch()
            if cfg.check_every and (it + 1) % cfg.check_every == 0 and not active.numpy().any():
                break

    def _line_search(self, run: SubstepLaunches, first: bool) -> None:
        """Per world, halve the Newton step until the incremental potential does not increase.
        The start energy is evaluated at the first Newton iteration of a substep; later ones start
        from the energy of the step accepted last (kept by ``end_line_search_trial``)."""
        cfg = self.config
        if cfg.line_search_steps == 0:
            return
        if first:
            self.scratch.energy0.zero_()
            for cmd in run.energy0:
                cmd.launch()
        run.begin_search.launch()
        for _ in range(cfg.line_search_steps + 1):
            for cmd in run.trial:
                cmd.launch()
            if cfg.check_every and not self.scratch.searching.numpy().any():
                break

    def _evaluate_outputs(self, run: SubstepLaunches) -> None:
        """Forces, stresses and pad loads at the returned positions, and the final residual
        (evaluated with the last substep's start velocities, so the inertia term is included)."""
        work, s = self.work, self.scratch
        for a in (work.pad_normal_force, work.pad_force, work.mean_von_mises, s.res_norm):
            a.zero_()
        for cmd in run.outputs:
            cmd.launch()
        s.rz.zero_()

    def _substep_launches(self, h: float) -> SubstepLaunches:
        """Recorded launches for substeps of length ``h`` (s)."""
        if h not in self._launches:
            self._launches[h] = record_substep_launches(self.model, self.config, self.scratch, self.work,
                                                        self.work_control, h)
        return self._launches[h]
