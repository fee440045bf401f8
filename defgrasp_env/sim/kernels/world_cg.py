"""Each world's whole CG in one launch: a block of threads per world runs its CG iterations to the
world's own stopping test, with a block barrier between the phases of an iteration.

The phase-by-phase CG of ``linear_solve.py`` launches four or five kernels per iteration over the
rows of every world (or of the listed worlds), and loops in blocks of ``check_every`` iterations
while any world iterates. Where a launch costs more than its work (one world on a GPU: ~4.5 us per
dependent launch; the slowest worlds of a batch, iterating alone), ``cg_world_blocks`` does a world's
iterations in one launch: block ``w`` (``threads`` threads: a CUDA thread block, launched with
``block_dim = threads``) strides over world ``w``'s pad edge slots and nodes, calling the same
row functions as the phase kernels (``pad_edge_hessian.edge_point_slot_product``,
``linear_solve.node_product`` with the assembled elastic Hessian's rows, ``update_solution``,
``finish_iteration`` after ``coarse_space.coarse_row`` / ``coarse_gain``, ``update_direction``),
with ``block_barrier`` between the phases (their sums and the world's alpha and beta are read after
it). A world computes its rows in the same order either
way, so with one thread per world (the CPU, which runs a launch's threads one after another) the
results are bit-identical to the phase-by-phase CG's; on a GPU the float atomics' order differs, as
it does between any two GPU runs. The coarse part of the preconditioner (z's T E^-1 T^T r) is a
dense product of the world's coarse inverse with T^T r (48 x 48 for 8 aggregates), computed a row per
thread (``coarse_space.coarse_row``, then ``coarse_gain`` on thread 0), or, by a block of one
thread (the CPU; ``block_sync.compiled_for_cpu``), ``coarse_space.SERIAL_LANES`` rows at a time
(``coarse_rows_serial``: the same bits); such a block also keeps the world's sums of its
rows (p . Ap, r . z, the largest move) in registers (``linear_solve.node_products_serial``,
``update_solutions_serial``).

The barrier (``block_sync.py``) is reached by every thread of a block: the iteration loop's bound
and its exit read the world's flag after a barrier, the same value for all of the block's threads,
and no barrier is inside a row loop; the launch has ``worlds x threads`` threads in blocks of
``threads``, so a block never holds two worlds (Warp's grid-stride loop, where the grid is smaller,
gives all threads of a block the same worlds in turn).
"""

import warp as wp

# forward only: these kernels are never differentiated, and the adjoint of their loops multiplies the
# CUDA compile time (world_evaluate: 205 s with it, on a 2-core Xeon)
wp.set_module_options({"enable_backward": False})

from .block_sync import block_barrier, compiled_for_cpu
from .coarse_space import coarse_gain, coarse_row, coarse_rows_serial
from .linear_solve import (finish_iteration, node_product, node_products_serial, update_direction,
                           update_solution, update_solutions_serial)
from .pad_edge_hessian import edge_point_slot_product



@wp.kernel
def cg_world_blocks(
    threads: int,
    max_iterations: int,
    node_start: wp.array(dtype=int),
    points_per_world: int,
    # the assembled elastic Hessian (hessian_blocks.hessian_row_product)
    node_blocks: wp.array(dtype=wp.vec2i),
    block_node: wp.array(dtype=int),
    hessian_values: wp.array(dtype=wp.mat33),
    # pad edge points (pad_edge_hessian.edge_point_slot_product; points_per_world 0: none)
    triangles: wp.array(dtype=wp.vec3i),
    point_tri: wp.array(dtype=int),
    point_bary: wp.array(dtype=wp.vec3),
    point_block: wp.array(dtype=wp.mat33),
    # nodes
    mass: wp.array(dtype=float),
    contact_hessian: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    lever: wp.array(dtype=wp.vec3),
    precond: wp.array(dtype=wp.mat33),
    inv_dt2: float,
    # per world
    rz_stop: wp.array(dtype=float),
    update_tol: float,
    coarse_sizes: wp.array(dtype=int),
    coarse_inverse: wp.array3d(dtype=wp.float64),
    coarse_rhs: wp.array2d(dtype=float),
    coarse_coef: wp.array2d(dtype=float),
    coarse_terms: wp.array2d(dtype=wp.float64),
    rz: wp.array(dtype=float),
    rz_new: wp.array(dtype=float),
    p_ap: wp.array(dtype=float),
    beta: wp.array(dtype=float),
    cg_iterations: wp.array(dtype=int),
    cg_iterations_total: wp.array(dtype=int),
    cg_active: wp.array(dtype=int),
    cg_update: wp.array(dtype=float),
    # CG vectors
    p: wp.array(dtype=wp.vec3),
    ap: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    r: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
):
    """CG iterations of world ``tid // threads`` (thread ``tid % threads`` of its block) until its
    stopping test (``linear_solve.finish_iteration``) or ``max_iterations``; a world not iterating CG
    returns at once."""
    tid = wp.tid()
    w = tid // threads
    lane = tid - w * threads
    if cg_active[w] == 0:
        return
    n0 = node_start[w]
    n1 = node_start[w + 1]
    e0 = w * points_per_world
    e1 = e0 + points_per_world
    for _it in range(max_iterations):
        for e in range(e0 + lane, e1, threads):
            edge_point_slot_product(e, p, triangles, cg_active, points_per_world, point_tri, point_bary, point_block,
                                    ap)
        block_barrier()
        serial = compiled_for_cpu() == 1 and threads == 1  # the world's sums in registers (the same bits)
        if serial:
            node_products_serial(w, n0, n1, p, mass, contact_hessian, free, inv_dt2, node_blocks, block_node,
                                 hessian_values, ap, p_ap)
        else:
            for i in range(n0 + lane, n1, threads):
                node_product(i, p, mass, contact_hessian, free, node_world, cg_active, inv_dt2, node_blocks,
                             block_node, hessian_values, ap, p_ap)
        block_barrier()
        if serial:
            update_solutions_serial(w, n0, n1, p, ap, precond, free, node_aggregate, lever, rz, p_ap, dx, r, z,
                                    rz_new, cg_update, coarse_rhs)
        else:
            for i in range(n0 + lane, n1, threads):
                update_solution(i, p, ap, precond, free, node_world, node_aggregate, lever, cg_active, rz, p_ap, dx,
                                r, z, rz_new, cg_update, coarse_rhs)
        block_barrier()
        size = coarse_sizes[w]
        if serial:
            coarse_rows_serial(w, size, coarse_inverse, coarse_rhs, coarse_coef, coarse_terms)
        else:
            for i in range(lane, size, threads):
                coarse_row(w, i, size, coarse_inverse, coarse_rhs, coarse_coef, coarse_terms)
        block_barrier()
        if lane == 0:
            finish_iteration(w, coarse_gain(w, size, coarse_rhs, coarse_terms), rz_stop, update_tol, max_iterations,
                             rz, rz_new, p_ap, beta, cg_iterations, cg_iterations_total, cg_active, cg_update)
        block_barrier()
        if cg_active[w] == 0:
            break
        for i in range(n0 + lane, n1, threads):
            update_direction(i, free, node_world, node_aggregate, lever, cg_active, coarse_coef, beta, z, p, ap)
        block_barrier()
