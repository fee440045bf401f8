"""Each world's Newton evaluation in one launch: a block of threads per world evaluates the node,
pad edge point and tet terms at the iterate, starts its linear solve and its coarse solve, and
sets its CG's stopping value, with a block barrier (``block_sync.py``) wherever a phase reads
what other threads wrote.

Phase by phase this is eleven to fifteen launches over the rows of every world
(``contact.evaluate_nodes``, ``pad_edge_contact.evaluate_edge_points``, ``elastic.evaluate_tets``,
``linear_solve.begin_linear_solve``, the elastic Hessian's assembly (``hessian_blocks.py``), the
coarse space's assembly, factor and initial guess with its Hessian product,
``coarse_space.coarse_start_cg``, ``linear_solve.start_cg_worlds``); one
world on a GPU pays a launch's latency for each. ``evaluate_world_blocks`` calls the same row
functions in the same order per world: bit-identical on the CPU (one thread per world). With one thread a
world (the CPU) the coarse matrix (48 x 48 for 8 aggregates) is assembled in global memory and
inverted as the phase kernel does (the same bits); with several (a GPU) it is assembled in the
block's shared memory (``block_memory.py``) and inverted there by Gauss-Jordan
(``coarse_factor.coarse_factor_block``). A world not
iterating Newton only has its CG flag cleared (the phase kernels also cleared its CG vectors,
its CG stopping value and its line-search start energy, which nothing reads before its next solve
sets them again).
"""

import warp as wp

# forward only: these kernels are never differentiated, and the adjoint of their loops multiplies the
# CUDA compile time (world_evaluate: 205 s with it, on a 2-core Xeon)
wp.set_module_options({"enable_backward": False})

from .block_memory import shared_set
from .block_sync import block_barrier, compiled_for_cpu
from .coarse_factor import coarse_factor_block
from .coarse_space import coarse_assemble_node, coarse_guess_node, coarse_start_cg_node
from .contact import evaluate_node
from .elastic import evaluate_tet
from .hessian_blocks import assemble_hessian_row
from .linear_solve import begin_node_solve, node_product, start_cg_world
from .pad_edge_contact import evaluate_edge_point
from .pad_edge_hessian import coarse_assemble_edge_point, edge_point_slot_product


@wp.kernel
def evaluate_world_blocks(
    threads: int,
    node_start: wp.array(dtype=int),
    tet_start: wp.array(dtype=int),
    add_energy: int,
    energy: wp.array(dtype=wp.float64),
    active: wp.array(dtype=int),
    x: wp.array(dtype=wp.vec3),
    # nodes (contact.evaluate_node)
    x_start: wp.array(dtype=wp.vec3),
    v_start: wp.array(dtype=wp.vec3),
    mass: wp.array(dtype=float),
    node_world: wp.array(dtype=int),
    external_force: wp.array(dtype=wp.vec3),
    gravity: wp.vec3,
    dt: float,
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    lag_normal_force: wp.array(dtype=float),
    lag_normal: wp.array(dtype=wp.vec3),
    stiffness: wp.array(dtype=float),
    knee: float,
    ground_mu: float,
    pad_mu: float,
    stick_velocity: float,
    residual: wp.array(dtype=wp.vec3),
    diag_block: wp.array(dtype=wp.mat33),
    contact_hessian: wp.array(dtype=wp.mat33),
    contact_force: wp.array(dtype=wp.vec3),
    elastic_force: wp.array(dtype=wp.vec3),
    pad_normal_force: wp.array(dtype=float),
    pad_force: wp.array(dtype=wp.vec3),
    penetration: wp.array(dtype=float),
    # pad edge points (pad_edge_contact; points_per_world 0: none)
    triangles: wp.array(dtype=wp.vec3i),
    points: wp.array(dtype=wp.vec3),
    point_pad: wp.array(dtype=int),
    points_per_world: int,
    point_tri: wp.array(dtype=int),
    point_bary: wp.array(dtype=wp.vec3),
    point_normal: wp.array(dtype=wp.vec3),
    point_stiffness: wp.array(dtype=float),
    point_allowed: wp.array(dtype=float),
    point_friction: wp.array(dtype=float),
    slip_eps: float,
    triangle_first: wp.array(dtype=int),
    point_block: wp.array(dtype=wp.mat33),
    # tets (elastic.evaluate_tet)
    tets: wp.array(dtype=wp.vec4i),
    rest_inv: wp.array(dtype=wp.mat33),
    rest_volume: wp.array(dtype=float),
    tet_mu: wp.array(dtype=float),
    tet_lambda: wp.array(dtype=float),
    tet_world: wp.array(dtype=int),
    tet_rotation: wp.array(dtype=wp.quat),
    trial_rotation: wp.array(dtype=wp.quat),
    rotations_at_x: wp.array(dtype=int),
    tet_cof: wp.array(dtype=wp.mat33),
    von_mises: wp.array(dtype=float),
    tet_r: wp.array(dtype=wp.mat33),
    tet_twist: wp.array(dtype=float),
    # the assembled elastic Hessian (hessian_blocks.py)
    node_blocks: wp.array(dtype=wp.vec2i),
    block_node: wp.array(dtype=int),
    node_incidences: wp.array(dtype=wp.vec2i),
    incidence: wp.array(dtype=int),
    incidence_blocks: wp.array(dtype=wp.vec4i),
    hessian_values: wp.array(dtype=wp.mat33),
    # the linear solve (linear_solve.begin_node_solve) and its coarse space (coarse_space.py)
    free: wp.array(dtype=wp.vec3),
    precond: wp.array(dtype=wp.mat33),
    z: wp.array(dtype=wp.vec3),
    p: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    ap: wp.array(dtype=wp.vec3),
    rz: wp.array(dtype=float),
    residual_norm: wp.array(dtype=float),
    node_aggregate: wp.array(dtype=int),
    node_anchor: wp.array(dtype=int),
    coarse_lever: wp.array(dtype=wp.vec3),
    inv_dt2: float,
    coarse_sizes: wp.array(dtype=int),
    coarse_matrix: wp.array3d(dtype=wp.float64),
    coarse_rhs: wp.array2d(dtype=float),
    coarse_lower_inv: wp.array3d(dtype=wp.float64),
    coarse_inverse: wp.array3d(dtype=wp.float64),
    coarse_coef: wp.array2d(dtype=float),
    coarse_guess: wp.array(dtype=wp.vec3),
    coarse_p_ap: wp.array(dtype=float),
    # CG's start (linear_solve.start_cg_world)
    newton_iterations: wp.array(dtype=int),
    patient: wp.array(dtype=int),
    last_update: wp.array(dtype=float),
    newton_tolerance: float,
    tolerance_near: float,
    tolerance_far: float,
    rz_stop: wp.array(dtype=float),
    cg_active: wp.array(dtype=int),
):
    """The evaluation of world ``tid // threads`` (thread ``tid % threads`` of its block) for a
    Newton iteration, if it iterates (``active``); ``add_energy`` = 1 (a substep's first iteration):
    ``energy[w]`` is cleared and gains its tets' strain energy (``_evaluate``'s ``start_energy``)."""
    tid = wp.tid()
    w = tid // threads
    lane = tid - w * threads
    if active[w] == 0:
        if lane == 0:
            cg_active[w] = 0  # as start_cg_worlds: its CG does not run
        return
    n0 = node_start[w]
    n1 = node_start[w + 1]
    t0 = tet_start[w]
    t1 = tet_start[w + 1]
    e0 = w * points_per_world
    e1 = e0 + points_per_world
    if add_energy != 0 and lane == 0:
        energy[w] = wp.float64(0.0)
    for i in range(n0 + lane, n1, threads):
        evaluate_node(i, x, x_start, v_start, mass, node_world, active, external_force, gravity, dt, pad_pos0,
                      pad_rot0, pad_pos1, pad_rot1, pad_half, pads_per_world, lag_normal_force, lag_normal,
                      stiffness, knee, ground_mu, pad_mu, stick_velocity, 0, residual, diag_block, contact_hessian,
                      contact_force, elastic_force, pad_normal_force, pad_force, penetration)
    block_barrier()
    for e in range(e0 + lane, e1, threads):
        evaluate_edge_point(e, x, x_start, triangles, active, pad_pos0, pad_rot0, pad_pos1, pad_rot1, pad_half,
                            pads_per_world, points, point_pad, points_per_world, point_tri, point_bary, point_normal,
                            point_stiffness, point_allowed, point_friction, knee, pad_mu, slip_eps, triangle_first, 0,
                            residual, diag_block, point_block, contact_force, pad_normal_force, pad_force, penetration)
    # the CPU: whether the line search's last trial found the rotations at x (set by world_newton_step,
    # cleared by world_start at the substep's start)
    known = int(0)
    if compiled_for_cpu() == 1:
        known = rotations_at_x[w]
    for t in range(t0 + lane, t1, threads):
        evaluate_tet(t, x, tets, rest_inv, rest_volume, tet_mu, tet_lambda, tet_world, active, tet_rotation, known,
                     trial_rotation, residual, diag_block, elastic_force, tet_cof, von_mises, tet_r, tet_twist, 0,
                     add_energy, energy)
    block_barrier()
    for i in range(n0 + lane, n1, threads):
        begin_node_solve(i, residual, diag_block, free, node_world, active, precond, z, p, dx, ap, rz, residual_norm)
        assemble_hessian_row(i, node_world, active, node_blocks, node_incidences, incidence, incidence_blocks, rest_inv,
                             rest_volume, tet_mu, tet_lambda, tet_cof, tet_r, tet_twist, hessian_values)
    size = coarse_sizes[w]
    block_size = int(0)  # E in global memory (one thread: the phase kernels' bits), else in the block memory
    if threads > 1:
        block_size = size
        for e in range(lane, size * size, threads):
            shared_set(e, wp.float64(0.0))
    block_barrier()
    for i in range(n0 + lane, n1, threads):
        coarse_assemble_node(i, x, node_anchor, mass, contact_hessian, free, node_world, node_aggregate, active,
                             inv_dt2, node_blocks, block_node, hessian_values, residual, coarse_lever, coarse_matrix,
                             coarse_rhs, block_size)
    for e in range(e0 + lane, e1, threads):
        coarse_assemble_edge_point(e, triangles, active, points_per_world, point_tri, point_bary, point_block, free,
                                   node_aggregate, x, node_anchor, coarse_matrix, block_size)
    block_barrier()
    coarse_factor_block(w, lane, threads, coarse_sizes, coarse_matrix, coarse_lower_inv, coarse_inverse, coarse_rhs,
                        coarse_coef, rz)
    block_barrier()
    for i in range(n0 + lane, n1, threads):
        coarse_guess_node(i, free, node_world, node_aggregate, active, coarse_lever, coarse_coef, dx, coarse_guess)
    block_barrier()
    for e in range(e0 + lane, e1, threads):
        edge_point_slot_product(e, coarse_guess, triangles, active, points_per_world, point_tri, point_bary,
                                point_block, ap)
    block_barrier()
    for i in range(n0 + lane, n1, threads):
        node_product(i, coarse_guess, mass, contact_hessian, free, node_world, active, inv_dt2, node_blocks,
                     block_node, hessian_values, ap, coarse_p_ap)
    block_barrier()
    for i in range(n0 + lane, n1, threads):
        coarse_start_cg_node(i, precond, free, node_world, active, residual, ap, z, p, rz)
    block_barrier()
    if lane == 0:
        start_cg_world(w, active, newton_iterations, patient, last_update, newton_tolerance, tolerance_near,
                       tolerance_far, rz, rz_stop, cg_active)
