"""Scratch arrays of the implicit solver: everything a step writes besides the ``State``.

Made once per model. N nodes, T tets, W worlds, P pads per world; world frame, SI units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from .hessian_blocks import HessianBlocks
from .kernels.block_memory import MAX_COARSE
from .kernels.coarse_space import AGGREGATE_UNKNOWNS
from .model import Model
from .kernels.world_rows import scatter_rows
from .pad_edge_points import pad_edge_points, surface_triangles, world_surface_triangles


@dataclass
class EdgeContactScratch:
    """Arrays of the pad edge contact (``kernels/pad_edge_contact.py``): T surface triangles, Q edge
    points per world (all its pads'), W worlds. Empty (T = Q = 0) unless ``ContactParams.edge_contact``."""

    triangles: wp.array         # [T] vec3i: global node ids of the objects' surface triangles (outward)
    triangle_world: wp.array    # [T] int: world of each triangle
    triangle_first: wp.array    # [W+1] int: first triangle of each world (a world's are contiguous)
    points: wp.array            # [Q] vec3: edge points in unit box coordinates (times the half extents: pad frame, m)
    point_pad: wp.array         # [Q] int: the point's pad within its world
    point_share: wp.array       # [Q] float, m: length of pad edge the point stands for
    point_first: wp.array       # [P+1] int: first point of each pad of a world
    best_dist: wp.array         # [W*Q] float, m: search: nearest triangle's distance
    best_tri: wp.array          # [W*Q] int: search: lowest id of the triangles at that distance
    point_tri: wp.array         # [W*Q] int: triangle the point meets this substep (-1: none)
    point_bary: wp.array        # [W*Q] vec3: barycentric weights of the triangle's surface point
    point_normal: wp.array      # [W*Q] vec3: the triangle's outward unit normal at the initial guess
    point_stiffness: wp.array   # [W*Q] float, N/m: penalty stiffness of the point's contact
    point_allowed: wp.array     # [W*Q] float, m: depth the point may keep this substep (start depth - a knee, or the skin)
    point_friction: wp.array    # [W*Q] float, N: the normal force the point's friction is lagged on this substep
    point_block: wp.array       # [W*Q] mat33, N/m: the point's Hessian (penalty + friction) at the last evaluation
    push: wp.array              # [T] float, m: initial guess: how far each triangle moves out of its points' way
    push_normal: wp.array       # [T] vec3: that triangle's outward unit normal

    @classmethod
    def from_model(cls, model: Model) -> "EdgeContactScratch":
        d, w, pads = model.device, model.num_worlds, model.pads_per_world
        on = model.contact.edge_contact and pads > 0
        tris, tri_world = surface_triangles(model) if on else (np.zeros((0, 3), np.int32), np.zeros(0, np.int32))
        half = model.pad_half_extents.numpy()[:pads] if on else np.zeros((0, 3))
        points, point_pad, share, first = pad_edge_points(half) if on else (
            np.zeros((0, 3), np.float32), np.zeros(0, np.int32), np.zeros(0, np.float32), np.zeros(1, np.int32))
        slots = w * len(points)
        if np.any(np.diff(tri_world) < 0):
            raise ValueError("surface_triangles must list each world's triangles together, in world order")
        tri_first = np.searchsorted(tri_world, np.arange(w + 1)).astype(np.int32)
        return cls(
            triangles=wp.array(tris, dtype=wp.vec3i, device=d), triangle_world=wp.array(tri_world, dtype=int, device=d),
            triangle_first=wp.array(tri_first, dtype=int, device=d),
            points=wp.array(points, dtype=wp.vec3, device=d), point_pad=wp.array(point_pad, dtype=int, device=d),
            point_share=wp.array(share, dtype=float, device=d), point_first=wp.array(first, dtype=int, device=d),
            best_dist=wp.zeros(slots, dtype=float, device=d), best_tri=wp.zeros(slots, dtype=int, device=d),
            point_tri=wp.full(slots, -1, dtype=int, device=d), point_bary=wp.zeros(slots, dtype=wp.vec3, device=d),
            point_normal=wp.zeros(slots, dtype=wp.vec3, device=d),
            point_stiffness=wp.zeros(slots, dtype=float, device=d), point_allowed=wp.zeros(slots, dtype=float, device=d),
            point_friction=wp.zeros(slots, dtype=float, device=d), point_block=wp.zeros(slots, dtype=wp.mat33, device=d),
            push=wp.zeros(len(tris), dtype=float, device=d), push_normal=wp.zeros(len(tris), dtype=wp.vec3, device=d))

    @property
    def points_per_world(self) -> int:
        return int(self.points.shape[0])

    @property
    def active(self) -> bool:
        """Whether there is any edge point (edge contact on, pads present)."""
        return self.points.shape[0] > 0 and self.triangles.shape[0] > 0


def world_coarse_sizes(model: Model, node_aggregate: np.ndarray) -> np.ndarray:
    """[W] int32: 6 x (the largest aggregate index of each world's nodes + 1), the unknowns of its
    coarse solve. A batch's coarse arrays are as wide as its most aggregates (8 for every object of
    more than a few nodes; a single tet's 4 nodes name pieces 0-6); the rows beyond a world's own
    are empty (no node, no right-hand side), so its solve over its own rows alone gives the same
    coefficients, bit for bit on the CPU, without the dense factor and products of the rows it
    does not use."""
    starts = np.asarray(model.node_start[:-1], dtype=np.int64)  # every world has nodes
    return (AGGREGATE_UNKNOWNS * (np.maximum.reduceat(np.asarray(node_aggregate), starts) + 1)).astype(np.int32)


def global_anchors(model: Model, rows: np.ndarray) -> np.ndarray:
    """[len(rows)] int32: the global node id of each node row's aggregate anchor (``Model.node_anchor``
    is world-local)."""
    world = np.searchsorted(model.node_start, rows, side="right") - 1
    return (model.node_anchor[rows] + model.node_start[world]).astype(np.int32)


@dataclass
class SolverScratch:
    """Per-node, per-tet and per-world work arrays of ``ImplicitSolver`` (device arrays).

    Newton's iterate is the work state's ``positions``; each Newton iteration solves
    ``A dx = r`` (A = M/h^2 + contact Hessian + elastic Hessian) by CG preconditioned by block
    Jacobi plus a coarse solve on the rigid motions of node aggregates (``kernels/coarse_space.py``),
    then line-searches along ``dx``.
    """

    # substep bookkeeping
    step_start: wp.array        # [N] vec3, m: positions at the start of the step (prescribed-axis lerp)
    x_start: wp.array           # [N] vec3, m: positions at the start of the substep
    v_new: wp.array             # [N] vec3, m/s: velocities at the end of the substep
    x_trial: wp.array           # [N] vec3, m: line-search trial positions
    # linear solve
    residual: wp.array          # [N] vec3, N: r = -grad E (then the CG residual)
    z: wp.array                 # [N] vec3: preconditioned residual
    p: wp.array                 # [N] vec3: CG direction
    ap: wp.array                # [N] vec3: A p
    dx: wp.array                # [N] vec3, m: Newton update
    diag_block: wp.array        # [N] mat33, N/m: diagonal blocks of A
    precond: wp.array           # [N] mat33, m/N: their inverses (masked by the free axes)
    contact_hessian: wp.array   # [N] mat33, N/m: contact part of the diagonal blocks
    cofactor: wp.array          # [T] mat33: d(det F)/dF of each tet at the last Newton iterate
    tet_rotation: wp.array      # [T] quat: polar rotation of each tet at the last evaluated positions (warm start)
    tet_r: wp.array             # [T] mat33: the rotation at the last Newton iterate as a matrix
    tet_twist: wp.array         # [T] float: twist factor of the fixed-corotated Hessian there
    trial_rotation: wp.array    # [T] quat: rotations the line search's last trial found (CPU world blocks; [1] on CUDA)
    tet_start: wp.array         # [W+1] int: first tet row of each world (a world's tets are contiguous)
    tet_end: wp.array           # [W] int: one past the last tet of each world's object (``Model.tet_end``)
    # contact, lagged at the substep start
    lag_normal_force: wp.array  # [N*(P+1)] float, N: normal force per node and contact (0: ground, 1+k: pad k)
    lag_normal: wp.array        # [N*(P+1)] vec3: normal of that contact (pad frame for pads: the contact face)
    pad_pos0: wp.array          # [W*P] vec3, m: pad centres at the substep start
    pad_rot0: wp.array          # [W*P] quat: pad orientations at the substep start
    pad_pos1: wp.array          # [W*P] vec3, m: pad centres at the substep end
    pad_rot1: wp.array          # [W*P] quat: pad orientations at the substep end
    # per-world reductions and flags [W]
    rz: wp.array                # float: r . z of CG
    rz_new: wp.array            # float
    rz_stop: wp.array           # float: r . z at which CG stops (its start value times the tolerance squared)
    p_ap: wp.array              # float: p . A p
    dx_norm: wp.array           # float, m: largest component of the current Newton direction
    last_dx: wp.array           # float, m: that of the last Newton iteration (SolveStats.last_update)
    res_norm: wp.array          # float, N: largest residual component
    penetration: wp.array       # float, m: deepest contact at the returned state (nodes; pad edges in the object)
    step_length: wp.array       # float: line-search step length
    cg_update: wp.array         # float, m: largest node move of the last CG iteration
    cg_beta: wp.array           # float: CG's beta of the current iteration
    coarse_scratch: wp.array    # float: p . A p of the coarse guess (unused)
    depth: wp.array             # float, m: deepest contact of the iterate (extra iterations)
    patient_update: wp.array    # float, m: the last update a patient world iterates down to (>= newton_tolerance)
    newton_active: wp.array     # int: world still iterating Newton
    cg_active: wp.array         # int: world still iterating CG
    newton_it: wp.array         # int: Newton iterations of the step (SolveStats)
    substep_newton_it: wp.array  # int: Newton iterations of the substep (the limit)
    cg_it: wp.array             # int: CG iterations of the current Newton iteration
    cg_total: wp.array          # int: CG iterations of the step (SolveStats)
    diverged: wp.array          # int: world blew up
    unconverged: wp.array       # int: a substep stopped at the iteration limit
    rotations_at_x: wp.array    # int: trial_rotation holds the rotations at the iterate (world blocks, CPU)
    clamped: wp.array           # int: a substep's solve left a node deeper than the penetration bound
    solve_worlds: wp.array      # int: world computed by the current solve (1 in all unless advance(worlds=...))
    patient: wp.array           # int: world to iterate until patient_update (ImplicitSolver.advance)
    searching: wp.array         # int: world still line-searching
    energy0: wp.array           # float64: incremental potential of the accepted iterate
    energy_trial: wp.array      # float64: that of the trial
    # coarse space: rigid motions of K node aggregates per world (C = 6K unknowns, sim/aggregates.py;
    # K: the most aggregates of any world)
    coarse_size: int            # host: C
    coarse_sizes: wp.array      # [W] int: 6 x the aggregates of each world's object (<= C): its coarse
    #                             solve's unknowns (the rest of its rows, empty aggregates, are left out)
    node_aggregate: wp.array    # [N] int: world-local aggregate of each node
    node_anchor: wp.array       # [N] int: global node its aggregate's rotations turn about
    coarse_lever: wp.array      # [N] vec3, m: x_i - x_anchor at the iterate of the last assembly
    coarse_matrix: wp.array     # [W, C, C] float64: T^T A T (assembled, then its Cholesky factor)
    coarse_lower_inv: wp.array  # [W, C, C] float64: inverse of the Cholesky factor
    coarse_inverse: wp.array    # [W, C, C] float64: (T^T A T)^-1 of the current Newton iteration
    coarse_rhs: wp.array        # [W, C] float: T^T r
    coarse_coef: wp.array       # [W, C] float: (T^T A T)^-1 T^T r
    coarse_terms: wp.array      # [W, C] float64: (T^T r)_i ((T^T A T)^-1 T^T r)_i (world-block CG's rows)
    coarse_guess: wp.array      # [N] vec3, m: T coef of the coarse initial guess
    edges: EdgeContactScratch   # pad edge contact (empty unless ContactParams.edge_contact)
    hessian: HessianBlocks      # the elastic Hessian assembled per node row (its pattern and values)
    stress_partial: wp.array    # [W*B] float, Pa: a world block's per-thread partial mean stresses (B threads)

    @classmethod
    def from_model(cls, model: Model, block_threads: int = 1) -> "SolverScratch":
        """Zeroed scratch for ``model``; ``block_threads``: threads of a world's block in the kernels
        that give each world one (``ImplicitSolver.world_block_threads``, at least 1)."""
        d, n, t, w = model.device, model.num_nodes, model.num_tets, model.num_worlds
        pads = max(w * model.pads_per_world, 1)
        slots = n * (model.pads_per_world + 1)

        def vec(count=n):
            return wp.zeros(count, dtype=wp.vec3, device=d)

        def mat(count=n):
            return wp.zeros(count, dtype=wp.mat33, device=d)

        def quat(count):
            return wp.zeros(count, dtype=wp.quat, device=d)

        def per_world(dtype):
            return wp.zeros(w, dtype=dtype, device=d)

        aggregate = model.node_aggregate
        size = AGGREGATE_UNKNOWNS * max(int(aggregate.max()) + 1, model.max_aggregates)
        if size > MAX_COARSE:
            raise ValueError(f"a world has at most {MAX_COARSE // AGGREGATE_UNKNOWNS} node aggregates (the coarse "
                             f"matrix in a GPU world block's shared memory, block_memory.MAX_COARSE; on every "
                             f"device, so that a model runs on any), got {size // AGGREGATE_UNKNOWNS}")

        def coarse(dtype, ndim):
            return wp.zeros((w,) + (size,) * (ndim - 1), dtype=dtype, device=d)

        names = [f.name for f in cls.__dataclass_fields__.values()]
        floats = names[names.index("rz"):names.index("newton_active")]
        ints = names[names.index("newton_active"):names.index("energy0")]
        scratch = cls(
            step_start=vec(), x_start=vec(), v_new=vec(), x_trial=vec(),
            residual=vec(), z=vec(), p=vec(), ap=vec(), dx=vec(),
            diag_block=mat(), precond=mat(), contact_hessian=mat(), cofactor=mat(t),
            tet_rotation=quat(t), tet_r=mat(t), tet_twist=wp.zeros(t, dtype=float, device=d),
            trial_rotation=quat(t if wp.get_device(d).is_cpu else 1),  # read and written by CPU kernels only
            lag_normal_force=wp.zeros(slots, dtype=float, device=d), lag_normal=vec(slots),
            pad_pos0=vec(pads), pad_rot0=quat(pads), pad_pos1=vec(pads), pad_rot1=quat(pads),
            **{k: per_world(float) for k in floats}, **{k: per_world(int) for k in ints},
            energy0=per_world(wp.float64), energy_trial=per_world(wp.float64),
            coarse_size=size, coarse_sizes=wp.array(world_coarse_sizes(model, aggregate), dtype=int, device=d),
            node_aggregate=wp.array(aggregate, dtype=int, device=d),
            node_anchor=wp.array(global_anchors(model, np.arange(n)), dtype=int, device=d), coarse_lever=vec(),
            coarse_matrix=coarse(wp.float64, 3), coarse_lower_inv=coarse(wp.float64, 3),
            coarse_inverse=coarse(wp.float64, 3), coarse_rhs=coarse(float, 2), coarse_coef=coarse(float, 2),
            coarse_terms=coarse(wp.float64, 2),
            coarse_guess=vec(), tet_start=wp.array(np.asarray(model.tet_start, dtype=np.int32), dtype=int, device=d),
            tet_end=wp.array(np.asarray(model.tet_end, dtype=np.int32), dtype=int, device=d),
            edges=EdgeContactScratch.from_model(model), hessian=HessianBlocks.from_model(model),
            stress_partial=wp.zeros(w * max(int(block_threads), 1), dtype=float, device=d),
        )
        scratch.solve_worlds.fill_(1)
        scratch.step_length.fill_(1.0)  # begin_line_search resets it; with no line search it stays 1
        return scratch

    def rewrite_worlds(self, model: Model, worlds) -> None:
        """The rows of ``worlds`` that this scratch copies from ``model`` (coarse aggregates and their
        anchors, surface triangles, the objects' last tets, the Hessian's pattern), written again after
        ``model``'s rows of them changed in place (a slotted model's object change,
        ``envs.world_models.rewrite_worlds``)."""
        worlds = [int(w) for w in worlds]
        if not worlds:
            return
        rows = np.concatenate([np.arange(model.node_start[w], model.node_start[w + 1]) for w in worlds])
        aggregates = model.node_aggregate[rows]
        if int(aggregates.max()) + 1 > self.coarse_size // AGGREGATE_UNKNOWNS:
            raise ValueError(f"the rewritten worlds name {int(aggregates.max()) + 1} coarse aggregates, more than the "
                             f"{self.coarse_size // AGGREGATE_UNKNOWNS} this scratch was made for")
        d = model.device
        self.tet_end.assign(np.asarray(model.tet_end, dtype=np.int32))
        self.coarse_sizes.assign(world_coarse_sizes(model, model.node_aggregate))
        index = wp.array(rows.astype(np.int32), dtype=int, device=d)
        for values, target in ((aggregates, self.node_aggregate), (global_anchors(model, rows), self.node_anchor)):
            wp.launch(scatter_rows, dim=len(rows), inputs=[wp.array(values, dtype=int, device=d), index],
                      outputs=[target], device=d)
        self.hessian.rewrite_worlds(model, worlds)
        e = self.edges
        if e.triangles.shape[0]:
            slot = model.triangle_slot
            tris = np.concatenate([world_surface_triangles(model, w) for w in worlds])
            rows = np.concatenate([np.arange(w * slot, (w + 1) * slot) for w in worlds])
            wp.launch(scatter_rows, dim=len(rows), inputs=[wp.array(tris, dtype=wp.vec3i, device=d),
                                                        wp.array(rows.astype(np.int32), dtype=int, device=d)],
                      outputs=[e.triangles], device=d)

    @property
    def pads(self) -> list:
        """Pad poses at the substep start and end, in the kernels' argument order."""
        return [self.pad_pos0, self.pad_rot0, self.pad_pos1, self.pad_rot1]
