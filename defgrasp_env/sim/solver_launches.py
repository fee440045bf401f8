"""Recorded kernel launches of one implicit-solver substep, one builder per phase.

A substep of length h: ``start`` (at a step's first substep the input state's rows copied and the
report cleared; pad poses at the substep's start and end, save the start, initial guess, contact faces,
lagged friction, guess fixes, rotation seeds, Newton's flags), then Newton
iterations of ``evaluate`` (residual and diagonal blocks, CG start with the coarse correction),
``cg`` (a block of CG iterations, repeated; or ``cg_world``: each world's whole CG in one launch,
``SolverConfig.world_block_threads``), ``coarse_post``, the line search (``energy0`` once,
``begin_search``, ``trial`` repeated) and ``apply`` (or ``step_world``: each world's coarse correction,
line search and update in one launch); ``depth`` (the iterate's deepest contact) decides
the extra iterations (with the loop control of ``solver_loops``);
``finish`` (nodes left deeper than the penetration bound put back to it, velocities and, after the
last substep, the outputs: forces, stresses, residual, pad poses). With
``SolverConfig.world_block_threads`` ``start``, ``evaluate``, ``cg_world``, ``step_world`` and
``finish`` are one launch each (``kernels/world_*.py``: a block of threads per world), so a
substep's solver work is 5 + 3 per extra Newton iteration launches plus the loops' control.
Launches are recorded once per substep length and (state in, state out, control) set
(``wp.launch(record_cmd=True)``; ``ImplicitSolver`` keeps the 8 sets used last). Each phase is a list
holding one ``LaunchSequence`` of its launches: on the CPU a Warp graph (``wp.ScopedCapture``)
replayed by Warp's C++ loop (a replay costs ~15 us of Python instead of ~15-25 us per launch), else
the launches one by one (also where the solver captures the whole substep in one graph, which
cannot contain other CPU graphs). ``cg`` holds ``cg_block`` CG iterations (``SolverConfig.check_every``, or
all of ``cg_iterations`` when it is 0): CG iterations of a world that has stopped are no-ops.
"""

from __future__ import annotations

from dataclasses import dataclass

import warp as wp

from .kernels import coarse_factor as kcf
from .kernels import coarse_space as kcs
from .kernels import contact as kc
from .kernels import pad_edge_contact as kpe
from .kernels import pad_edge_guess as kpg
from .kernels import pad_edge_hessian as kph
from .kernels import pad_edge_lag as kpl
from .kernels import pad_edge_search as kps
from .kernels import elastic as ke
from .kernels import hessian_blocks as khb
from .kernels import energy as kenergy
from .kernels import line_search as kls
from .kernels import linear_solve as klin
from .kernels import substep as ksub
from .kernels import world_cg as kwcg
from .kernels import world_evaluate as kwev
from .kernels import world_finish as kwfin
from .kernels import world_newton_step as kwns
from .kernels import world_start as kwstart
from .launch_lock import scoped_capture
from .model import Model
from .solver_scratch import SolverScratch
from .state import Control, State
from .world_compaction import WorldCompaction


class LaunchSequence:
    """Recorded launches replayed in order by ``launch()``: as one captured graph on the CPU where
    Warp records CPU graphs (Warp 1.19 does), else one by one (CUDA; a Warp that cannot capture on the CPU). Both run the same
    kernels on the same arrays in the same order, so the results are bit-identical."""

    def __init__(self, commands: list, device, graph: bool = True):
        self.commands = list(commands)
        self.graph = None
        if graph and self.commands and wp.get_device(device).is_cpu:
            try:
                with scoped_capture(device=device) as capture:
                    for cmd in self.commands:
                        cmd.launch()
                self.graph = capture.graph
            except RuntimeError:  # this Warp cannot capture on the CPU: launch one by one
                self.graph = None

    def launch(self) -> None:
        if self.graph is not None:
            wp.capture_launch(self.graph)
        else:
            for cmd in self.commands:
                cmd.launch()


@dataclass
class SubstepLaunches:
    """Launches of each phase (lists are launched in order; see the module docstring)."""

    start: list         # [substeps] lists: (k = 0) input rows copied, report cleared; pad poses at fractions
                        # k/K and (k+1)/K, substep start, initial guess (prescribed axes at (k+1)/K), lag,
                        # Newton's flags (one launch of world blocks where ``world_block_threads``)
    evaluate: list      # a Newton iteration's evaluation (one launch of world blocks where ``world_block_threads``)
    evaluate_first: list  # the substep's first evaluation: also the tets' part of ``energy0``
    cg: list
    cg_world: list      # each world's whole CG in one launch (``kernels/world_cg.py``; [] where not used)
    cg_listed: list     # the same CG iterations over the listed worlds' rows (WorldCompaction; [] if unused)
    list_cg_worlds: list  # list the worlds still iterating CG (WorldCompaction.record_list; [] if unused)
    coarse_post: list
    energy0: list
    begin_search: object
    trial: list
    step_world: list    # coarse_post, line search and apply in one launch (``kernels/world_newton_step.py``; [] where not used)
    step_world_first: list  # the same in a substep's first Newton iteration (with the nodes' part of ``energy0``)
    apply: list
    depth: list         # launches: the iterate's deepest contact per world (extra iterations)
    finish: list        # [substeps] lists: clamp, end (velocities), at the last the outputs, CG's rz cleared
                        # and the pad poses copied, then the velocities' copy (one launch of world blocks)
    finish_contact: list  # the last substep's ``finish`` with the contact part of the outputs only
                          # (``ImplicitSolver.advance(full_outputs=False)``)
    cg_block: int       # CG iterations per launch of ``cg``


@dataclass
class _Context:
    model: Model
    scratch: SolverScratch
    work: State
    control: Control
    h: float
    substeps: int
    start_pads: tuple   # (positions, orientations) [W*P] of the pads at the step's start
    step_start: object  # [N] vec3: node positions at the step's start (prescribed-axis lerp)
    compaction: WorldCompaction
    block_threads: int  # threads of a world's block in the mean stress (``world_block_threads``, at least 1)
    copy_from: State | None  # the step's input state where it is not ``work`` (its rows copied at the start)

    def rec(self, kernel, dim, *inputs):
        return wp.launch(kernel, dim=dim, inputs=list(inputs), device=self.model.device, record_cmd=True)

    def blocks(self, kernel, threads: int, *inputs):
        """A recorded launch of a kernel that gives each world a block of ``threads`` threads."""
        return wp.launch(kernel, dim=self.model.num_worlds * threads, block_dim=threads, inputs=list(inputs),
                         device=self.model.device, record_cmd=True)


def _nodes(c: _Context, x, active, record_pads, energy=None) -> list:
    """Inertia, gravity and contact terms of every node at ``x`` (or their energy): the node
    terms, then the pad edge points' contacts (``kernels/pad_edge_contact.py``) added onto them."""
    m, s, work, ctl = c.model, c.scratch, c.work, c.control
    common = (m.node_mass, m.node_world, active, ctl.external_force, m.gravity, c.h, *s.pads, m.pad_half_extents,
              m.pads_per_world, s.lag_normal_force, s.lag_normal, m.node_contact_stiffness,
              m.contact.stiffening_depth, m.contact.ground_friction, m.contact.pad_friction,
              m.contact.stick_velocity)
    e = s.edges
    points = (x, s.x_start, e.triangles, active, *s.pads, m.pad_half_extents, m.pads_per_world, e.points,
              e.point_pad, e.points_per_world, e.point_tri, e.point_bary, e.point_normal, e.point_stiffness,
              e.point_allowed, e.point_friction, m.contact.stiffening_depth, m.contact.pad_friction,
              m.contact.stick_velocity * c.h)
    slots = m.num_worlds * e.points_per_world if e.active else 0
    if energy is not None:
        return [c.rec(kenergy.node_energy, m.num_nodes, x, s.x_start, work.velocities, *common, energy),
                *([c.rec(kpe.edge_point_energy, slots, *points, energy)] if slots else [])]
    return [c.rec(kc.evaluate_nodes, m.num_nodes, x, s.x_start, work.velocities, *common, record_pads, s.residual,
                  s.diag_block, s.contact_hessian, work.contact_force, work.elastic_force, work.pad_normal_force,
                  work.pad_force, s.penetration),
            *([c.rec(kpe.evaluate_edge_points, slots, *points, e.triangle_first, record_pads, s.residual, s.diag_block,
                     e.point_block, work.contact_force, work.pad_normal_force, work.pad_force, s.penetration)]
              if slots else [])]


def _edge_product(c: _Context, p, active, listed: bool = False) -> list:
    """ap += the edge points' Hessian blocks times ``p`` (none without edge contact); ``listed``:
    only the listed worlds' slots (``WorldCompaction``)."""
    m, s, e, wc = c.model, c.scratch, c.scratch.edges, c.compaction
    if not e.active:
        return []
    rows = wc.edge_slots if listed else wc.every_row
    dim = wc.dim(rows) if listed else m.num_worlds * e.points_per_world
    return [c.rec(kph.edge_point_product, dim, p, e.triangles, active, e.points_per_world, e.point_tri, e.point_bary,
                  e.point_block, s.ap, rows)]


def _edge_search(c: _Context, x) -> list:
    """The pad edge points' triangles for the substep (``kernels/pad_edge_search.py``, then the lag)."""
    m, s, e = c.model, c.scratch, c.scratch.edges
    if not e.active:
        return []
    slots, pairs = m.num_worlds * e.points_per_world, e.triangles.shape[0] * m.pads_per_world
    search = (s.x_start, x, e.triangles, e.triangle_world, *s.pads, m.pad_half_extents, m.pads_per_world, e.points,
              e.point_first, e.points_per_world)
    return [c.rec(kps.clear_edge_search, slots, e.best_dist, e.best_tri),
            c.rec(kps.nearest_surface_triangles, pairs, *search, 0, e.best_dist, e.best_tri),
            c.rec(kps.nearest_surface_triangles, pairs, *search, 1, e.best_dist, e.best_tri),
            c.rec(kpl.lag_edge_points, slots, s.x_start, x, e.triangles, e.triangle_first, *s.pads, m.pad_half_extents,
                  m.pads_per_world, e.points, e.point_pad, e.point_share, e.points_per_world,
                  m.node_contact_stiffness, s.lag_normal_force, s.lag_normal, e.best_tri, e.point_tri, e.point_bary,
                  e.point_normal,
                  e.point_stiffness, e.point_allowed, e.point_friction, m.contact.stiffening_depth)]


def _keep_edge_depth(c: _Context, x) -> list:
    """The initial guess's fix for the pad edge points (after the nodes'): two passes."""
    m, s, e = c.model, c.scratch, c.scratch.edges
    if not e.active:
        return []
    return [c.rec(kpg.clear_triangle_push, e.triangles.shape[0], e.push),
            c.rec(kpg.edge_point_push, m.num_worlds * e.points_per_world, s.x_start, e.triangles, s.solve_worlds,
                  *s.pads, m.pad_half_extents, m.pads_per_world, e.points, e.point_pad, e.points_per_world,
                  e.point_tri, e.point_bary, e.point_normal, e.point_allowed, x, e.push, e.push_normal),
            c.rec(kpg.push_triangles, e.triangles.shape[0], e.triangles, e.triangle_world, s.solve_worlds,
                  m.free_axes, s.lag_normal_force, m.pads_per_world, e.push, e.push_normal, x)]


def _tets(c: _Context, x, active, energy=None, outputs: int = 0, add_energy=None):
    """Elastic terms of every tet at ``x`` for a Newton iteration (``add_energy``: also summing
    their energy into that per-world array), or (``outputs`` = 1) for the outputs pass
    (``kernels/elastic.py``), or their energy alone (``energy``)."""
    m, s, work = c.model, c.scratch, c.work
    if energy is not None:
        return c.rec(kenergy.tet_energy, m.num_tets, x, m.tets, m.tet_rest_inv, m.tet_rest_volume, m.tet_mu,
                     m.tet_lambda, m.tet_world, active, s.tet_rotation, energy)
    return c.rec(ke.evaluate_tets, m.num_tets, x, m.tets, m.tet_rest_inv, m.tet_rest_volume, m.tet_mu, m.tet_lambda,
                 m.tet_world, active, s.tet_rotation, s.residual, s.diag_block, work.elastic_force, s.cofactor,
                 work.von_mises, s.tet_r, s.tet_twist, outputs, int(add_energy is not None),
                 s.energy0 if add_energy is None else add_energy)


def _begin_solve(c: _Context, active):
    m, s = c.model, c.scratch
    return c.rec(klin.begin_linear_solve, m.num_nodes, s.residual, s.diag_block, m.free_axes, m.node_world, active,
                 s.precond, s.z, s.p, s.dx, s.ap, s.rz, s.res_norm)


def _hessian_rows(c: _Context) -> tuple:
    """The assembled elastic Hessian's rows, as its products read them (``hessian_row_product``)."""
    h = c.scratch.hessian
    return h.node_blocks, h.block_node, h.values


def _hessian_pattern(c: _Context) -> tuple:
    """The assembly's inputs of the Hessian's pattern (``hessian_blocks.assemble_hessian_row``)."""
    h = c.scratch.hessian
    return h.node_blocks, h.node_incidences, h.incidence, h.incidence_blocks


def _assemble_hessian(c: _Context, active):
    """The elastic Hessian's rows at the iterate just evaluated (``_tets``)."""
    m, s = c.model, c.scratch
    return c.rec(khb.assemble_hessian_rows, m.num_nodes, m.node_world, active, *_hessian_pattern(c), m.tet_rest_inv,
                 m.tet_rest_volume, m.tet_mu, m.tet_lambda, s.cofactor, s.tet_r, s.tet_twist, s.hessian.values)


def _coarse_before(c: _Context, active) -> list:
    """Coarse solve before CG: assemble and invert T^T A T, start CG from dx = T (T^T A T)^-1 T^T r
    with the residual and CG vectors that follow (kernels/coarse_space.py)."""
    m, s, e, n = c.model, c.scratch, c.scratch.edges, c.model.num_nodes
    return [
        c.rec(kcs.coarse_assemble_nodes, n, c.work.positions, s.node_anchor, m.node_mass, s.contact_hessian,
              m.free_axes, m.node_world, s.node_aggregate, active, 1.0 / (c.h * c.h), *_hessian_rows(c), s.residual,
              s.coarse_lever, s.coarse_matrix, s.coarse_rhs),
        *([c.rec(kph.coarse_assemble_edge_points, m.num_worlds * e.points_per_world, e.triangles, active,
                 e.points_per_world, e.point_tri, e.point_bary, e.point_block, m.free_axes,
                 s.node_aggregate, c.work.positions, s.node_anchor, s.coarse_matrix)] if e.active else []),
        c.rec(kcf.coarse_factor, m.num_worlds, active, s.coarse_sizes, s.coarse_matrix, s.coarse_lower_inv,
              s.coarse_inverse, s.coarse_rhs, s.coarse_coef, s.rz),
        c.rec(kcs.coarse_guess, n, m.free_axes, m.node_world, s.node_aggregate, active, s.coarse_lever,
              s.coarse_coef, s.dx, s.coarse_guess),
        *_edge_product(c, s.coarse_guess, active),
        c.rec(klin.cg_node_product, n, s.coarse_guess, m.node_mass, s.contact_hessian, m.free_axes, m.node_world,
              active, 1.0 / (c.h * c.h), *_hessian_rows(c), s.ap, s.coarse_scratch, c.compaction.every_row),
        c.rec(kcs.coarse_start_cg, n, s.precond, m.free_axes, m.node_world, active, s.residual, s.ap, s.z, s.p,
              s.rz)]


def _coarse_after(c: _Context, active) -> list:
    """Coarse correction after CG: dx += T (T^T A T)^-1 T^T r with CG's final residual r."""
    m, s, n = c.model, c.scratch, c.model.num_nodes
    return [c.rec(kcs.coarse_reduce, n, s.residual, m.node_world, s.node_aggregate, active, s.coarse_lever,
                  s.coarse_rhs),
            c.rec(kcs.coarse_solve, m.num_worlds, active, s.coarse_sizes, s.coarse_inverse, s.coarse_rhs,
                  s.coarse_coef),
            c.rec(kcs.coarse_correct, n, m.free_axes, m.node_world, s.node_aggregate, active, s.coarse_lever,
                  s.coarse_coef, s.dx)]


def _pads(c: _Context, k: int) -> list:
    """Pad poses at fractions k/K and (k+1)/K of the step (none without pads)."""
    m, s, ctl, k_sub = c.model, c.scratch, c.control, c.substeps
    if not m.pads_per_world:
        return []
    return [c.rec(kc.interpolate_pads, m.num_worlds * m.pads_per_world, *c.start_pads, ctl.pad_target_positions,
                  ctl.pad_target_orientations, k / k_sub, (k + 1) / k_sub, *s.pads)]


def _begin(c: _Context, k: int):
    """Substep ``k``'s start positions and initial guess (prescribed axes at (k+1)/K)."""
    m, s, work = c.model, c.scratch, c.work
    return c.rec(ksub.begin_substep, m.num_nodes, work.positions, work.velocities, c.step_start,
                 c.control.prescribed_positions, m.free_axes, m.node_world, s.solve_worlds, (k + 1) / c.substeps,
                 c.h, s.x_start)


def _lag(c: _Context) -> list:
    m, s, x = c.model, c.scratch, c.work.positions
    return [c.rec(kc.lag_contacts, m.num_nodes, s.x_start, x, m.node_world, *s.pads, m.pad_half_extents,
                  m.pads_per_world, m.node_contact_stiffness, m.contact.stiffening_depth, s.lag_normal_force,
                  s.lag_normal),
            *_edge_search(c, x),
            c.rec(kc.keep_pad_depth, m.num_nodes, s.x_start, m.node_world, s.solve_worlds, m.free_axes, *s.pads,
                  m.pad_half_extents, m.pads_per_world, s.lag_normal_force, s.lag_normal, x),
            *_keep_edge_depth(c, x),
            c.rec(ke.seed_rotations, m.num_tets, x, m.tets, m.tet_rest_inv, s.tet_rotation)]


def _start(c: _Context, k: int) -> list:
    """The start of substep ``k``: at the step's start the input state's rows copied into ``work``
    (``copy_from``) and the report cleared, then pad poses (``_pads``), start and guess (``_begin``),
    lag (``_lag``), Newton's flags."""
    m, s = c.model, c.scratch
    step = []
    if k == 0 and c.copy_from is not None:
        step += [c.rec(ksub.copy_world_rows, m.num_nodes, getattr(c.copy_from, a), m.node_world, s.solve_worlds,
                       getattr(c.work, a)) for a in ("positions", "velocities")]
    if k == 0:
        step.append(c.rec(ksub.clear_solve_report, m.num_worlds, s.solve_worlds, s.newton_it, s.cg_total, s.diverged,
                          s.unconverged, s.clamped, s.penetration))
    return [*step, *_pads(c, k), _begin(c, k), *_lag(c),
            c.rec(ksub.begin_newton, m.num_worlds, s.solve_worlds, s.newton_active, s.substep_newton_it)]


def _start_world(c: _Context, threads: int, k: int) -> list:
    """``_start``'s launches as one: each world's start of substep ``k`` in a block of ``threads``
    threads (``kernels/world_start.py``)."""
    m, s, e, wc, ctl, work = c.model, c.scratch, c.scratch.edges, c.compaction, c.control, c.work
    copy_rows = k == 0 and c.copy_from is not None
    source = c.copy_from if copy_rows else work
    return [c.blocks(kwstart.start_world_blocks, threads,
                     threads, wc.nodes.start, wc.tets.start, s.solve_worlds,
                     int(copy_rows), source.positions, source.velocities, int(k == 0),
                     s.newton_it, s.cg_total, s.diverged, s.unconverged, s.clamped, s.penetration, *c.start_pads,
                     ctl.pad_target_positions, ctl.pad_target_orientations, k / c.substeps, (k + 1) / c.substeps,
                     work.velocities, c.step_start, ctl.prescribed_positions, c.h, s.x_start, work.positions,
                     m.node_world, m.free_axes, *s.pads, m.pad_half_extents, m.pads_per_world,
                     m.node_contact_stiffness, m.contact.stiffening_depth, s.lag_normal_force, s.lag_normal,
                     e.triangles, e.triangle_world, e.triangle_first, e.points, e.point_first, e.point_pad,
                     e.point_share, e.points_per_world if e.active else 0, e.best_dist, e.best_tri, e.point_tri,
                     e.point_bary, e.point_normal, e.point_stiffness, e.point_allowed, e.point_friction, e.push,
                     e.push_normal, m.tets, m.tet_rest_inv, s.tet_rotation, s.newton_active, s.substep_newton_it,
                     s.rotations_at_x)]


def _evaluate(c: _Context, config, start_energy: bool = False) -> list:
    """A Newton iteration's evaluation; ``start_energy``: the substep's first, which also sums the
    tets' part of the line search's start energy (``energy0``, cleared here; the nodes' part
    follows in ``energy0``'s launches)."""
    s, x = c.scratch, c.work.positions
    clear = [c.rec(kls.clear_world_energy, c.model.num_worlds, s.energy0)] if start_energy else []
    return [*clear, *_nodes(c, x, s.newton_active, 0),
            _tets(c, x, s.newton_active, add_energy=s.energy0 if start_energy else None), _begin_solve(c, s.newton_active),
            _assemble_hessian(c, s.newton_active),
            *_coarse_before(c, s.newton_active),
            c.rec(klin.start_cg_worlds, c.model.num_worlds, s.newton_active, s.substep_newton_it, s.patient, s.last_dx,
                  config.newton_tolerance, config.cg_tolerance, config.cg_tolerance_far, s.rz, s.rz_stop,
                  s.cg_active)]


def _world_node_terms(c: _Context) -> tuple:
    """The node terms' inputs of the world-block kernels (``contact.evaluate_node`` and
    ``energy.node_energy_row`` after their iterate and active flags)."""
    m, s, ctl = c.model, c.scratch, c.control
    return (s.x_start, c.work.velocities, m.node_mass, m.node_world, ctl.external_force, m.gravity, c.h, *s.pads,
            m.pad_half_extents, m.pads_per_world, s.lag_normal_force, s.lag_normal, m.node_contact_stiffness,
            m.contact.stiffening_depth, m.contact.ground_friction, m.contact.pad_friction, m.contact.stick_velocity)


def _world_edge_terms(c: _Context) -> tuple:
    """The pad edge points' inputs of the world-block kernels (points per world 0 without edge contact)."""
    m, e = c.model, c.scratch.edges
    return (e.triangles, e.points, e.point_pad, e.points_per_world if e.active else 0, e.point_tri, e.point_bary,
            e.point_normal, e.point_stiffness, e.point_allowed, e.point_friction, m.contact.stick_velocity * c.h)


def _world_tet_terms(c: _Context) -> tuple:
    """The tets' inputs of the world-block kernels up to their rotation seeds."""
    m = c.model
    return (m.tets, m.tet_rest_inv, m.tet_rest_volume, m.tet_mu, m.tet_lambda, m.tet_world, c.scratch.tet_rotation)


def _evaluate_world(c: _Context, config, threads: int, start_energy: bool = False) -> list:
    """``_evaluate``'s launches as one: each world's evaluation in a block of ``threads`` threads
    (``kernels/world_evaluate.py``)."""
    m, s, e, wc, work = c.model, c.scratch, c.scratch.edges, c.compaction, c.work
    return [c.blocks(kwev.evaluate_world_blocks, threads,
                     threads, wc.nodes.start, wc.tets.start, int(start_energy), s.energy0, s.newton_active,
                     work.positions, *_world_node_terms(c),
                     s.residual, s.diag_block, s.contact_hessian, work.contact_force, work.elastic_force,
                     work.pad_normal_force, work.pad_force, s.penetration,
                     *_world_edge_terms(c), e.triangle_first, e.point_block,
                     *_world_tet_terms(c), s.trial_rotation, s.rotations_at_x, s.cofactor, work.von_mises,
                     s.tet_r, s.tet_twist, s.hessian.node_blocks, s.hessian.block_node, s.hessian.node_incidences,
                     s.hessian.incidence, s.hessian.incidence_blocks, s.hessian.values,
                     m.free_axes, s.precond, s.z, s.p, s.dx, s.ap, s.rz, s.res_norm, s.node_aggregate,
                     s.node_anchor, s.coarse_lever, 1.0 / (c.h * c.h), s.coarse_sizes, s.coarse_matrix, s.coarse_rhs,
                     s.coarse_lower_inv, s.coarse_inverse, s.coarse_coef, s.coarse_guess,
                     s.coarse_scratch,
                     s.substep_newton_it, s.patient, s.last_dx, config.newton_tolerance, config.cg_tolerance,
                     config.cg_tolerance_far, s.rz_stop, s.cg_active)]


def _cg(c: _Context, config, listed: bool = False) -> list:
    """One CG iteration over every row, or (``listed``) over the rows of the listed worlds."""
    m, s, wc = c.model, c.scratch, c.compaction
    active = s.cg_active
    nodes = wc.nodes if listed else wc.every_row
    n = wc.dim(nodes) if listed else m.num_nodes
    return [
        *_edge_product(c, s.p, active, listed),
        c.rec(klin.cg_node_product, n, s.p, m.node_mass, s.contact_hessian, m.free_axes, m.node_world, active,
              1.0 / (c.h * c.h), *_hessian_rows(c), s.ap, s.p_ap, nodes),
        c.rec(klin.cg_update_solution, n, s.p, s.ap, s.precond, m.free_axes, m.node_world, s.node_aggregate,
              s.coarse_lever, active, s.rz, s.p_ap, s.dx, s.residual, s.z, s.rz_new, s.cg_update, s.coarse_rhs, nodes),
        c.rec(klin.cg_end_iteration, m.num_worlds, s.rz_stop,
              config.cg_update_fraction * config.newton_tolerance, config.cg_iterations, s.coarse_sizes,
              s.coarse_inverse, s.coarse_rhs, s.coarse_coef, s.rz, s.rz_new, s.p_ap, s.cg_beta, s.cg_it, s.cg_total,
              active, s.cg_update),
        c.rec(klin.cg_update_direction, n, m.free_axes, m.node_world, s.node_aggregate, s.coarse_lever, active,
              s.coarse_coef, s.cg_beta, s.z, s.p, s.ap, nodes)]


def _cg_world(c: _Context, config, threads: int) -> list:
    """Each world's whole CG (``kernels/world_cg.py``) in one launch of ``threads`` threads per world
    (CUDA thread blocks of that size)."""
    m, s, e, wc = c.model, c.scratch, c.scratch.edges, c.compaction
    return [c.blocks(kwcg.cg_world_blocks, threads,
                     threads, config.cg_iterations, wc.nodes.start, e.points_per_world if e.active else 0,
                     *_hessian_rows(c),
                     e.triangles, e.point_tri, e.point_bary, e.point_block,
                     m.node_mass, s.contact_hessian, m.free_axes, m.node_world, s.node_aggregate, s.coarse_lever,
                     s.precond,
                     1.0 / (c.h * c.h),
                     s.rz_stop, config.cg_update_fraction * config.newton_tolerance, s.coarse_sizes,
                     s.coarse_inverse, s.coarse_rhs, s.coarse_coef, s.coarse_terms, s.rz, s.rz_new, s.p_ap,
                     s.cg_beta, s.cg_it, s.cg_total, s.cg_active, s.cg_update,
                     s.p, s.ap, s.dx, s.residual, s.z)]


def _newton_step_world(c: _Context, config, threads: int, first: bool) -> list:
    """``coarse_post``, the line search (``first``: with the nodes' part of ``energy0``) and
    ``apply`` as one launch: each world's in a block of ``threads`` threads
    (``kernels/world_newton_step.py``)."""
    m, s = c.model, c.scratch
    return [c.blocks(kwns.newton_step_world_blocks, threads,
                     threads, c.compaction.nodes.start, c.compaction.tets.start, s.newton_active,
                     s.residual, m.free_axes, s.node_aggregate, s.coarse_lever, s.coarse_sizes, s.coarse_inverse,
                     s.coarse_rhs,
                     s.coarse_coef,
                     config.line_search_steps + 1 if config.line_search_steps > 0 else 0, int(first), 1e-6,
                     0.5 ** config.line_search_steps,
                     c.work.positions, s.dx, s.step_length, s.x_trial, s.searching, s.energy0, s.energy_trial,
                     *_world_node_terms(c), *_world_edge_terms(c), *_world_tet_terms(c), s.trial_rotation,
                     s.rotations_at_x,
                     config.max_node_step, s.dx_norm, s.diverged, config.newton_tolerance,
                     config.newton_iterations, s.substep_newton_it, s.newton_it, s.rz, s.res_norm, s.cg_it,
                     s.last_dx, s.unconverged)]


def _trial(c: _Context, config) -> list:
    m, s = c.model, c.scratch
    return [c.rec(kls.trial_positions, m.num_nodes, c.work.positions, s.dx, m.node_world, s.step_length, s.x_trial),
            *_nodes(c, s.x_trial, s.searching, 0, s.energy_trial),
            _tets(c, s.x_trial, s.searching, s.energy_trial),
            c.rec(kls.end_line_search_trial, m.num_worlds, s.energy0, 1e-6, 0.5 ** config.line_search_steps,
                  s.energy_trial, s.step_length, s.searching)]


def _apply(c: _Context, config) -> list:
    m, s = c.model, c.scratch
    return [c.rec(ksub.apply_newton_step, m.num_nodes, s.dx, m.node_world, s.newton_active, s.step_length,
                  config.max_node_step, c.work.positions, s.dx_norm, s.diverged),
            c.rec(ksub.end_newton_iteration, m.num_worlds, s.dx_norm, config.newton_tolerance,
                  config.newton_iterations, s.diverged, s.substep_newton_it, s.newton_it, s.newton_active, s.rz,
                  s.res_norm, s.cg_it, s.last_dx, s.unconverged)]


def _depth(c: _Context):
    m, s = c.model, c.scratch
    return [c.rec(kc.deepest_contact, m.num_nodes, c.work.positions, m.node_world, s.pad_pos1, s.pad_rot1,
                  m.pad_half_extents, m.pads_per_world, s.lag_normal, s.depth)]


def _outputs(c: _Context, outputs: int) -> list:
    """The outputs pass at the returned positions (``outputs``: ``kwfin.ALL_OUTPUTS``, or
    ``kwfin.CONTACT_OUTPUTS``: the node and pad edge terms only)."""
    m, s, work, x = c.model, c.scratch, c.work, c.work.positions
    cmds = [c.rec(ksub.clear_outputs, m.num_worlds, s.solve_worlds, m.pads_per_world, work.pad_normal_force,
                  work.pad_force, s.res_norm),
            *_nodes(c, x, s.solve_worlds, 1)]
    if outputs == kwfin.ALL_OUTPUTS:
        cmds += [_tets(c, x, s.solve_worlds, outputs=1), _begin_solve(c, s.solve_worlds),
                 c.blocks(ksub.mean_stress, c.block_threads, c.block_threads, work.von_mises, m.tet_rest_volume,
                          s.tet_start, s.tet_end, s.solve_worlds, m.world_volume, s.stress_partial,
                          work.mean_von_mises)]
    return cmds


def _finish(c: _Context, config, outputs: int) -> list:
    """A substep's end: nodes left too deep put back within the penetration bound, the velocities,
    after the last substep (``outputs`` not ``kwfin.NO_OUTPUTS``) the outputs pass (``_outputs``;
    then CG's ``rz`` cleared) and the pad poses into the output state, and the velocities into it."""
    m, s, work, ctl, x = c.model, c.scratch, c.work, c.control, c.work.positions
    cmds = [c.rec(kc.clamp_depth, m.num_nodes, m.node_world, s.solve_worlds, m.free_axes, s.pad_pos1, s.pad_rot1,
                  m.pad_half_extents, m.pads_per_world, s.lag_normal, config.penetration_bound,
                  0.9 * config.penetration_bound, x, s.clamped),
            c.rec(ksub.end_substep, m.num_nodes, s.x_start, m.node_world, s.solve_worlds, s.diverged, 1.0 / c.h, x,
                  s.v_new)]
    if outputs != kwfin.NO_OUTPUTS:
        cmds += [*_outputs(c, outputs), c.rec(ksub.clear_values, m.num_worlds, s.rz)]
        if m.pads_per_world:
            cmds.append(c.rec(ksub.copy_pad_poses, m.num_worlds * m.pads_per_world, ctl.pad_target_positions,
                              ctl.pad_target_orientations, m.pads_per_world, s.solve_worlds, work.pad_positions,
                              work.pad_orientations))
    return cmds + [c.rec(ksub.copy_world_rows, m.num_nodes, s.v_new, m.node_world, s.solve_worlds, work.velocities)]


def _finish_world(c: _Context, config, threads: int, outputs: int) -> list:
    """``_finish``'s launches as one: each solved world's substep end in a block of ``threads``
    threads (``kernels/world_finish.py``)."""
    m, s, e, wc, work, ctl = c.model, c.scratch, c.scratch.edges, c.compaction, c.work, c.control
    return [c.blocks(kwfin.finish_world_blocks, threads,
                     threads, wc.nodes.start, wc.tets.start, s.solve_worlds, outputs, work.positions,
                     config.penetration_bound, 0.9 * config.penetration_bound, s.clamped, s.diverged, 1.0 / c.h,
                     s.v_new, *_world_node_terms(c),
                     s.residual, s.diag_block, s.contact_hessian, work.contact_force, work.elastic_force,
                     work.pad_normal_force, work.pad_force, s.penetration,
                     *_world_edge_terms(c), e.triangle_first, e.point_block,
                     *_world_tet_terms(c), s.cofactor, work.von_mises, s.tet_r, s.tet_twist, s.energy0,
                     m.free_axes, s.precond, s.z, s.p, s.dx, s.ap, s.rz, s.res_norm,
                     s.tet_start, s.tet_end, m.world_volume, s.stress_partial, work.mean_von_mises,
                     ctl.pad_target_positions, ctl.pad_target_orientations, work.pad_positions,
                     work.pad_orientations)]


def record_substep_launches(model: Model, config, scratch: SolverScratch, work: State, control: Control,
                            h: float, start_pads: tuple, step_start: wp.array, compaction: WorldCompaction,
                            listed_cg: bool = False, phase_graphs: bool = True,
                            world_block_threads: int = 0, cg_block_threads: int | None = None,
                            copy_from: State | None = None) -> SubstepLaunches:
    """All launches of substeps of length ``h`` (s) for ``config.substeps`` substeps per step,
    iterating in ``work`` (the output state: positions and velocities hold the step's start when it
    begins) from the pad poses ``start_pads`` (positions, orientations) and the node positions
    ``step_start`` at the step's start, toward ``control``; ``copy_from``: the step's input state
    where it is not ``work`` (the solved worlds' positions and velocities are copied from it first).
    ``phase_graphs``: capture each phase as a CPU graph (False where the caller captures the whole
    substep). ``compaction``: the row maps; ``listed_cg``: also record the CG iterations over the
    listed worlds and the listing; ``world_block_threads`` > 0: each world's evaluation in one
    launch of that many threads per world (``evaluate``, ``evaluate_first``), and also its whole CG
    (``cg_world``, in blocks of ``cg_block_threads``, default ``world_block_threads``) and the rest
    of its Newton iteration (``step_world``, ``step_world_first``), its substep start (``start``)
    and end (``finish``)."""
    c = _Context(model, scratch, work, control, h, config.substeps, start_pads, step_start, compaction,
                 max(world_block_threads, 1), copy_from)
    if scratch.stress_partial.shape[0] < model.num_worlds * c.block_threads:
        raise ValueError(f"world_block_threads={world_block_threads} needs a scratch made with block_threads >= it "
                         f"(SolverScratch.from_model); its stress_partial holds {scratch.stress_partial.shape[0]} "
                         f"values for {model.num_worlds} worlds")
    s, x = scratch, work.positions
    block = config.check_every or config.cg_iterations

    def seq(commands: list) -> list:
        return [LaunchSequence(commands, model.device, phase_graphs)]

    def finish(outputs: int) -> list:
        if world_block_threads:
            return seq(_finish_world(c, config, world_block_threads, outputs))
        return seq(_finish(c, config, outputs))

    def evaluate(c: _Context, config, start_energy: bool = False) -> list:
        if world_block_threads:
            return _evaluate_world(c, config, world_block_threads, start_energy)
        return _evaluate(c, config, start_energy)

    return SubstepLaunches(
        start=[seq(_start_world(c, world_block_threads, k) if world_block_threads else _start(c, k))
               for k in range(c.substeps)],
        evaluate=seq(evaluate(c, config)),
        evaluate_first=seq(evaluate(c, config, start_energy=config.line_search_steps > 0)),
        cg=seq(_cg(c, config) * block),
        cg_world=seq(_cg_world(c, config, cg_block_threads or world_block_threads)) if world_block_threads else [],
        cg_listed=seq(_cg(c, config, listed=True) * block) if listed_cg else [],
        list_cg_worlds=seq(compaction.record_list(scratch.cg_active)) if listed_cg else [],
        coarse_post=seq(_coarse_after(c, s.newton_active)),
        energy0=seq(_nodes(c, x, s.newton_active, 0, s.energy0)),  # the tets' part: ``evaluate_first``
        begin_search=c.rec(kls.begin_line_search, model.num_worlds, s.newton_active, s.step_length, s.searching,
                           s.energy_trial),
        trial=seq(_trial(c, config)),
        step_world=seq(_newton_step_world(c, config, world_block_threads, False)) if world_block_threads else [],
        step_world_first=seq(_newton_step_world(c, config, world_block_threads, True)) if world_block_threads else [],
        apply=seq(_apply(c, config)), depth=_depth(c),
        finish=[finish(kwfin.ALL_OUTPUTS if k == c.substeps - 1 else kwfin.NO_OUTPUTS) for k in range(c.substeps)],
        finish_contact=finish(kwfin.CONTACT_OUTPUTS),
        cg_block=block,
    )
