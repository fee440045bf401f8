"""Implicit (backward Euler) FEM solver: a thin launcher over the kernels.

Each substep solves  M/h^2 (x - x_start - h v) = f_elastic(x) + f_contact(x) + M g + f_ext  for x by
Newton's method (projected elastic Hessian, exact contact normal Hessian, lagged friction), each
Newton system by block-Jacobi preconditioned CG with a coarse correction on the rigid translations
(kernels/newton.py), all per world.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from .kernels import contact as kc
from .kernels import elastic as ke
from .kernels import energy as kenergy
from .kernels import newton as kn
from .materials import check_range
from .model import Model
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
        penetration_bound: a returned state with a node deeper than this (m) inside a pad's
            collision box or below the ground is flagged (``SolveStats.penetrated``).
        penetration_iterations: extra Newton iterations at most per substep, after
            ``newton_iterations``, in the worlds whose iterate is still deeper than half of
            ``penetration_bound`` (a violent contact the regular iterations did not resolve).
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

    def __post_init__(self) -> None:
        for name, low in (("substeps", 1), ("newton_iterations", 1), ("cg_iterations", 1),
                          ("line_search_steps", 0), ("check_every", 0), ("penetration_iterations", 0)):
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
    penetrated: np.ndarray          # bool: penetration > SolverConfig.penetration_bound

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

    Scratch arrays and the recorded kernel launches are made once per model (and per substep
    length), so a step costs a couple of microseconds of Python per launch. Usage::

        solver = ImplicitSolver(model, SolverConfig())
        stats = solver.step(state_in, state_out, control, dt=0.05)
    """

    def __init__(self, model: Model, config: SolverConfig = SolverConfig()):
        self.model = model
        self.config = config
        d, n, w = model.device, model.num_nodes, model.num_worlds
        pads = max(w * model.pads_per_world, 1)

        def vec(count=n):
            return wp.zeros(count, dtype=wp.vec3, device=d)

        def mat(count=n):
            return wp.zeros(count, dtype=wp.mat33, device=d)

        self.work = State.from_model(model)       # the solver's own copy of the state
        self.work_control = Control.from_model(model)
        self._step_start, self._x_start, self._v_new, self._x_trial = vec(), vec(), vec(), vec()
        self._r, self._z, self._p, self._ap, self._dx = vec(), vec(), vec(), vec(), vec()
        self._diag, self._precond, self._contact_h, self._cof = mat(), mat(), mat(), mat(model.num_tets)
        self._tet_rotation = wp.zeros(model.num_tets, dtype=wp.quat, device=d)
        self._tet_r = mat(model.num_tets)
        self._tet_twist = wp.zeros(model.num_tets, dtype=float, device=d)
        slots = n * (model.pads_per_world + 1)
        self._lag_fn = wp.zeros(slots, dtype=float, device=d)
        self._lag_normal = vec(slots)
        self._pad = [vec(pads), wp.zeros(pads, dtype=wp.quat, device=d), vec(pads),
                     wp.zeros(pads, dtype=wp.quat, device=d)]
        self._wf = {k: wp.zeros(w, dtype=float, device=d) for k in (
            "rz", "rz_new", "rz0", "p_ap", "dx_norm", "last_dx", "res_norm", "penetration", "step", "cg_update",
        "depth")}
        self._wi = {k: wp.zeros(w, dtype=int, device=d) for k in (
            "newton_active", "cg_active", "newton_it", "substep_newton_it", "cg_it", "cg_total", "diverged",
            "unconverged", "all_on", "searching")}
        self._wi["all_on"].fill_(1)
        self._wf["step"].fill_(1.0)  # Newton step length: begin_line_search resets it, else it stays 1
        # coarse (rigid translation) correction: T_k = e_k masked by the free axes, A T_k, per-world 3x3
        free = model.free_axes.numpy()
        self._all_free = bool(free.all())
        self._coarse_t = [wp.array(free * np.eye(3, dtype=np.float32)[k], dtype=wp.vec3, device=d) for k in range(3)]
        self._coarse_at = [vec(), vec(), vec()]
        self._coarse_m, self._coarse_inv = mat(w), mat(w)
        self._coarse_rhs, self._coarse_coef = vec(w), vec(w)
        self._coarse_scratch = wp.zeros(w, dtype=float, device=d)
        self._energy0 = wp.zeros(w, dtype=wp.float64, device=d)
        self._energy_trial = wp.zeros(w, dtype=wp.float64, device=d)
        self._plans: dict[float, dict] = {}

    # -- public --------------------------------------------------------------------------------
    def step(self, state_in: State, state_out: State, control: Control, dt: float) -> SolveStats:
        """Advance ``state_in`` by ``dt`` seconds into ``state_out`` (they may be the same object)."""
        check_range("dt", dt, 0.0, math.inf, "s")
        cfg, wf, wi, work = self.config, self._wf, self._wi, self.work
        plan = self._plan(dt / cfg.substeps)
        for name in ("positions", "velocities", "pad_positions", "pad_orientations"):
            wp.copy(getattr(work, name), getattr(state_in, name))
        for name in self.work_control.__dataclass_fields__:
            wp.copy(getattr(self.work_control, name), getattr(control, name))
        wp.copy(self._step_start, state_in.positions)
        for a in (wi["newton_it"], wi["cg_total"], wi["diverged"], wi["unconverged"], wf["penetration"]):
            a.zero_()
        for k in range(cfg.substeps):
            for cmd in plan["pads"][k]:
                cmd.launch()
            plan["begin"][k].launch()
            for cmd in plan["lag"]:
                cmd.launch()
            self._newton(plan)
            plan["end"].launch()
            if k == cfg.substeps - 1:
                self._evaluate_outputs(plan)
            wp.copy(work.velocities, self._v_new)
        wp.copy(work.pad_positions, self.work_control.pad_target_positions)
        wp.copy(work.pad_orientations, self.work_control.pad_target_orientations)
        state_out.copy_from(work)
        diverged = wi["diverged"].numpy().astype(bool)
        penetration = wf["penetration"].numpy().copy()
        return SolveStats(
            newton_iterations=wi["newton_it"].numpy().copy(),
            cg_iterations=wi["cg_total"].numpy().copy(),
            last_update=wf["last_dx"].numpy().copy(),
            residual_force=wf["res_norm"].numpy().copy(),
            penetration=penetration,
            diverged=diverged,
            converged=~diverged & (wi["unconverged"].numpy() == 0),
            penetrated=penetration > cfg.penetration_bound,
        )

    # -- internals ---------------------------------------------------------------------------
    def _newton(self, plan: dict) -> None:
        cfg, wi = self.config, self._wi
        wp.copy(wi["newton_active"], wi["all_on"])
        wi["substep_newton_it"].zero_()
        for it in range(cfg.newton_iterations + cfg.penetration_iterations):
            if it >= cfg.newton_iterations:
                # extra iterations only in worlds still deeper than half the penetration bound
                for cmd in plan["depth"]:
                    cmd.launch()
                if cfg.check_every and not wi["newton_active"].numpy().any():
                    break
            for cmd in plan["evaluate"]:
                cmd.launch()
            self._run_cg(plan)
            for cmd in plan["coarse_post"]:
                cmd.launch()
            self._line_search(plan, first=it == 0)
            for cmd in plan["apply"]:
                cmd.launch()
            if cfg.check_every and it < cfg.newton_iterations - 1 and not wi["newton_active"].numpy().any():
                break

    def _run_cg(self, plan: dict) -> None:
        cfg, active = self.config, self._wi["cg_active"]
        for it in range(cfg.cg_iterations):
            for cmd in plan["cg"]:
                cmd.launch()
            if cfg.check_every and (it + 1) % cfg.check_every == 0 and not active.numpy().any():
                break

    def _line_search(self, plan: dict, first: bool) -> None:
        """Per world, halve the Newton step until the incremental potential does not increase.
        The start energy is evaluated at the first Newton iteration of a substep; later ones start
        from the energy of the step accepted last (kept by ``end_line_search_trial``)."""
        cfg = self.config
        if cfg.line_search_steps == 0:
            return
        if first:
            self._energy0.zero_()
            for cmd in plan["energy0"]:
                cmd.launch()
        plan["begin_search"].launch()
        for _ in range(cfg.line_search_steps + 1):
            for cmd in plan["trial"]:
                cmd.launch()
            if cfg.check_every and not self._wi["searching"].numpy().any():
                break

    def _evaluate_outputs(self, plan: dict) -> None:
        """Forces, stresses and pad loads at the returned positions, and the final residual
        (evaluated with the last substep's start velocities, so the inertia term is included)."""
        work, wf = self.work, self._wf
        for a in (work.pad_normal_force, work.pad_force, work.mean_von_mises, wf["res_norm"]):
            a.zero_()
        for cmd in plan["outputs"]:
            cmd.launch()
        wf["rz"].zero_()

    def _plan(self, h: float) -> dict:
        """Recorded launches for substeps of length ``h`` (s)."""
        if h in self._plans:
            return self._plans[h]
        m, c, cfg, work, ctl = self.model, self.model.contact, self.config, self.work, self.work_control
        wf, wi, dev = self._wf, self._wi, m.device
        n, t, w = m.num_nodes, m.num_tets, m.num_worlds

        def rec(kernel, dim, *inputs):
            return wp.launch(kernel, dim=dim, inputs=list(inputs), device=dev, record_cmd=True)

        def nodes(x, active, record_pads, energy=None):
            if energy is not None:
                return rec(kenergy.node_energy, n, x, self._x_start, work.velocities, m.node_mass, m.node_world,
                           active, ctl.external_force, m.gravity, h, *self._pad, m.pad_half_extents,
                           m.pads_per_world, self._lag_fn, self._lag_normal, m.node_contact_stiffness, c.stiffening_depth, c.ground_friction,
                           c.pad_friction, c.stick_velocity, energy)
            return rec(kc.evaluate_nodes, n, x, self._x_start, work.velocities, m.node_mass, m.node_world, active,
                       ctl.external_force, m.gravity, h, *self._pad, m.pad_half_extents, m.pads_per_world,
                       self._lag_fn, self._lag_normal, m.node_contact_stiffness, c.stiffening_depth, c.ground_friction, c.pad_friction,
                       c.stick_velocity, record_pads, self._r, self._diag, self._contact_h, work.contact_force,
                       work.elastic_force, work.pad_normal_force, work.pad_force, wf["penetration"])

        def tets(x, active, energy=None):
            if energy is not None:
                return rec(kenergy.tet_energy, t, x, m.tets, m.tet_rest_inv, m.tet_rest_volume, m.tet_mu,
                           m.tet_lambda, m.tet_world, active, self._tet_rotation, energy)
            return rec(ke.evaluate_tets, t, x, m.tets, m.tet_rest_inv, m.tet_rest_volume, m.tet_mu, m.tet_lambda,
                       m.tet_world, active, self._tet_rotation, self._r, self._diag, work.elastic_force, self._cof,
                       work.von_mises, self._tet_r, self._tet_twist)

        def begin_solve(active):
            return rec(kn.begin_linear_solve, n, self._r, self._diag, m.free_axes, m.node_world, active,
                       self._precond, self._z, self._p, self._dx, self._ap, wf["rz"], wf["res_norm"])

        def coarse(active, with_matrix):
            """Coarse solve on the rigid translations: before CG (with_matrix=1: builds T^T A T,
            starts CG from dx = T c) and after it (corrects dx with the CG residual)."""
            t_dirs, at = self._coarse_t, self._coarse_at
            cmds = []
            if with_matrix:
                cmds.append(rec(kn.coarse_clear, n, m.node_world, active, *at))
                for k in range(3):
                    if not self._all_free:  # a uniform translation does not strain a tet: K T_k = 0
                        cmds.append(rec(ke.hessian_product_tets, t, t_dirs[k], m.tets, m.tet_rest_inv, m.tet_rest_volume,
                                        m.tet_mu, m.tet_lambda, self._cof, m.tet_world, active, at[k],
                                        self._tet_r, self._tet_twist))
                    cmds.append(rec(kn.cg_node_product, n, t_dirs[k], m.node_mass, self._contact_h, m.free_axes,
                                    m.node_world, active, 1.0 / (h * h), at[k], self._coarse_scratch))
            cmds += [
                rec(kn.coarse_reduce, n, *at, self._r, m.free_axes, m.node_world, active, with_matrix,
                    self._coarse_m, self._coarse_rhs),
                rec(kn.coarse_solve, w, active, with_matrix, self._coarse_m, self._coarse_rhs, self._coarse_inv,
                    self._coarse_coef, wf["rz"] if with_matrix else self._coarse_scratch),
                rec(kn.coarse_apply, n, *at, self._precond, m.free_axes, m.node_world, active, self._coarse_coef,
                    with_matrix, self._dx, self._r, self._z, self._p, wf["rz"])]
            return cmds

        x, k_sub, pads = work.positions, cfg.substeps, max(w * m.pads_per_world, 1)
        newton_active, cg_active, searching = wi["newton_active"], wi["cg_active"], wi["searching"]
        plan = {
            "pads": [[rec(kc.interpolate_pads, pads, work.pad_positions, work.pad_orientations,
                          ctl.pad_target_positions, ctl.pad_target_orientations, k / k_sub, (k + 1) / k_sub,
                          *self._pad)] if m.pads_per_world else [] for k in range(k_sub)],
            "begin": [rec(kn.begin_substep, n, x, work.velocities, self._step_start, ctl.prescribed_positions,
                          m.free_axes, (k + 1) / k_sub, h, self._x_start) for k in range(k_sub)],
            "lag": [rec(kc.lag_contacts, n, self._x_start, x, m.node_world, *self._pad,
                        m.pad_half_extents, m.pads_per_world, m.node_contact_stiffness, c.stiffening_depth, self._lag_fn, self._lag_normal),
                    rec(kc.keep_pad_depth, n, self._x_start, m.node_world, m.free_axes, *self._pad, m.pad_half_extents,
                        m.pads_per_world,
                       self._lag_fn, self._lag_normal, x),
                    rec(ke.seed_rotations, t, x, m.tets, m.tet_rest_inv, self._tet_rotation)],
            "evaluate": [
                nodes(x, newton_active, 0), tets(x, newton_active), begin_solve(newton_active),
                *coarse(newton_active, 1),
                rec(kn.start_cg_worlds, w, newton_active, wf["rz"], wf["rz0"], cg_active)],
            "coarse_post": coarse(newton_active, 0),
            "cg": [
                rec(ke.hessian_product_tets, t, self._p, m.tets, m.tet_rest_inv, m.tet_rest_volume, m.tet_mu,
                    m.tet_lambda, self._cof, m.tet_world, cg_active, self._ap, self._tet_r, self._tet_twist),
                rec(kn.cg_node_product, n, self._p, m.node_mass, self._contact_h, m.free_axes, m.node_world,
                    cg_active, 1.0 / (h * h), self._ap, wf["p_ap"]),
                rec(kn.cg_update_solution, n, self._p, self._ap, self._precond, m.free_axes, m.node_world,
                    cg_active, wf["rz"], wf["p_ap"], self._dx, self._r, self._z, wf["rz_new"], wf["cg_update"]),
                rec(kn.cg_update_direction, n, self._z, m.node_world, cg_active, wf["rz"], wf["rz_new"],
                    self._p, self._ap),
                rec(kn.cg_end_iteration, w, wf["rz"], wf["rz_new"], wf["rz0"], wf["p_ap"], cfg.cg_tolerance ** 2,
                    cfg.cg_update_fraction * cfg.newton_tolerance, cfg.cg_iterations, wi["cg_it"], wi["cg_total"], cg_active,
                    wf["cg_update"])],
            "energy0": [nodes(x, newton_active, 0, self._energy0), tets(x, newton_active, self._energy0)],
            "begin_search": rec(kenergy.begin_line_search, w, newton_active, wf["step"], searching, self._energy_trial),
            "trial": [
                rec(kenergy.trial_positions, n, x, self._dx, m.node_world, wf["step"], self._x_trial),
                nodes(self._x_trial, searching, 0, self._energy_trial),
                tets(self._x_trial, searching, self._energy_trial),
                rec(kenergy.end_line_search_trial, w, self._energy0, 1e-6, 0.5 ** cfg.line_search_steps,
                    self._energy_trial, wf["step"], searching)],
            "apply": [
                rec(kn.apply_newton_step, n, self._dx, m.node_world, newton_active, wf["step"], cfg.max_node_step,
                    x, wf["dx_norm"], wi["diverged"]),
                rec(kn.end_newton_iteration, w, wf["dx_norm"], cfg.newton_tolerance, cfg.newton_iterations,
                    wi["diverged"], wi["substep_newton_it"], wi["newton_it"], newton_active, wf["rz"],
                    wf["res_norm"], wi["cg_it"], wf["last_dx"], wi["unconverged"])],
            "depth": [rec(kc.deepest_contact, n, x, m.node_world, self._pad[2], self._pad[3], m.pad_half_extents,
                          m.pads_per_world, self._lag_normal, wf["depth"]),
                      rec(kc.reactivate_deep_worlds, w, wf["depth"], 0.5 * cfg.penetration_bound, newton_active)],
            "end": rec(kn.end_substep, n, self._x_start, m.node_world, wi["diverged"], 1.0 / h, x, self._v_new),
            "outputs": [
                nodes(x, wi["all_on"], 1), tets(x, wi["all_on"]), begin_solve(wi["all_on"]),
                rec(kn.mean_stress, t, work.von_mises, m.tet_rest_volume, m.tet_world, m.world_volume,
                    work.mean_von_mises)],
        }
        self._plans[h] = plan
        return plan
