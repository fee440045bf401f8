"""Scratch arrays of the implicit solver: everything a step writes besides the ``State``.

Made once per model. N nodes, T tets, W worlds, P pads per world; world frame, SI units.
"""

from __future__ import annotations

from dataclasses import dataclass

import warp as wp

from .model import Model
from .surface_edges import surface_edges


@dataclass
class SolverScratch:
    """Per-node, per-tet and per-world work arrays of ``ImplicitSolver`` (device arrays).

    Newton's iterate is the work state's ``positions``; each Newton iteration solves
    ``A dx = r`` (A = M/h^2 + contact Hessian + elastic Hessian) by CG preconditioned by block
    Jacobi plus a coarse solve on the translations of node aggregates (``kernels/coarse_space.py``),
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
    cofactor: wp.array          # [T] mat33: d(det F)/dF of each tet
    tet_rotation: wp.array      # [T] quat: polar rotation of each tet (warm start of the next solve)
    tet_r: wp.array             # [T] mat33: that rotation as a matrix
    tet_twist: wp.array         # [T] float: twist factor of the fixed-corotated Hessian
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
    rz0: wp.array               # float: r . z at the start of CG
    p_ap: wp.array              # float: p . A p
    dx_norm: wp.array           # float, m: largest component of the current Newton direction
    last_dx: wp.array           # float, m: that of the last Newton iteration (SolveStats.last_update)
    res_norm: wp.array          # float, N: largest residual component
    penetration: wp.array       # float, m: deepest contact at the returned state
    step_length: wp.array       # float: line-search step length
    cg_update: wp.array         # float, m: largest node move of the last CG iteration
    cg_beta: wp.array           # float: CG's beta of the current iteration
    coarse_scratch: wp.array    # float: p . A p of the coarse guess (unused)
    depth: wp.array             # float, m: deepest contact of the iterate (extra iterations)
    newton_active: wp.array     # int: world still iterating Newton
    cg_active: wp.array         # int: world still iterating CG
    newton_it: wp.array         # int: Newton iterations of the step (SolveStats)
    substep_newton_it: wp.array  # int: Newton iterations of the substep (the limit)
    cg_it: wp.array             # int: CG iterations of the current Newton iteration
    cg_total: wp.array          # int: CG iterations of the step (SolveStats)
    diverged: wp.array          # int: world blew up
    unconverged: wp.array       # int: a substep stopped at the iteration limit
    clamped: wp.array           # int: a substep's solve left a node deeper than the penetration bound
    solve_worlds: wp.array      # int: world computed by the current solve (1 in all unless advance(worlds=...))
    patient: wp.array           # int: world to iterate until newton_tolerance (ImplicitSolver.advance)
    searching: wp.array         # int: world still line-searching
    energy0: wp.array           # float64: incremental potential of the accepted iterate
    energy_trial: wp.array      # float64: that of the trial
    # coarse space: translations of K node aggregates per world (C = 3K unknowns, sim/aggregates.py;
    # K: the most aggregates of any world)
    coarse_size: int            # host: C
    node_aggregate: wp.array    # [N] int: world-local aggregate of each node
    coarse_matrix: wp.array     # [W, C, C] float64: T^T A T (assembled, then its Cholesky factor)
    coarse_lower_inv: wp.array  # [W, C, C] float64: inverse of the Cholesky factor
    coarse_inverse: wp.array    # [W, C, C] float64: (T^T A T)^-1 of the current Newton iteration
    coarse_rhs: wp.array        # [W, C] float: T^T r
    coarse_coef: wp.array       # [W, C] float: (T^T A T)^-1 T^T r
    coarse_guess: wp.array      # [N] vec3, m: T coef of the coarse initial guess
    # edge contact with the pads (kernels/edge_contact.py): E surface edges (0 unless
    # ContactParams.edge_contact)
    edge_nodes: wp.array        # [E] vec2i: global node ids of the objects' surface edges
    edge_world: wp.array        # [E] int: world of each surface edge
    edge_normal: wp.array       # [E*P] vec3: contact face (outward normal, pad frame) of each surface edge and pad

    @classmethod
    def from_model(cls, model: Model) -> "SolverScratch":
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
        size = 3 * (int(aggregate.max()) + 1)
        edges, edge_world = surface_edges(model) if model.contact.edge_contact else surface_edges(None)

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
            lag_normal_force=wp.zeros(slots, dtype=float, device=d), lag_normal=vec(slots),
            pad_pos0=vec(pads), pad_rot0=quat(pads), pad_pos1=vec(pads), pad_rot1=quat(pads),
            **{k: per_world(float) for k in floats}, **{k: per_world(int) for k in ints},
            energy0=per_world(wp.float64), energy_trial=per_world(wp.float64),
            coarse_size=size, node_aggregate=wp.array(aggregate, dtype=int, device=d),
            coarse_matrix=coarse(wp.float64, 3), coarse_lower_inv=coarse(wp.float64, 3),
            coarse_inverse=coarse(wp.float64, 3), coarse_rhs=coarse(float, 2), coarse_coef=coarse(float, 2),
            coarse_guess=vec(),
            edge_nodes=wp.array(edges, dtype=wp.vec2i, device=d), edge_world=wp.array(edge_world, dtype=int, device=d),
            edge_normal=vec(len(edges) * model.pads_per_world),
        )
        scratch.solve_worlds.fill_(1)
        scratch.step_length.fill_(1.0)  # begin_line_search resets it; with no line search it stays 1
        return scratch

    @property
    def pads(self) -> list:
        """Pad poses at the substep start and end, in the kernels' argument order."""
        return [self.pad_pos0, self.pad_rot0, self.pad_pos1, self.pad_rot1]
