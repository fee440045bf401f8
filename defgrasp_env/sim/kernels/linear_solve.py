"""Per-world linear solves of the Newton systems: conjugate gradients preconditioned by block
Jacobi plus a coarse solve on the rigid motions of node aggregates (two-level additive,
``coarse_space.py``).

Every world runs its own CG (its own alpha, beta and stopping test) inside one set of flat arrays,
so a world's result never depends on the other worlds. Per-world flags switch finished worlds off.
One CG iteration is four or five launches: the pad edge points' ``edge_point_product``
(pad_edge_hessian.py, with edge contact), ``cg_node_product`` (the elastic Hessian's rows, assembled
by ``hessian_blocks.py`` once per Newton iteration, and the node terms), ``cg_update_solution``,
``cg_end_iteration`` (per world: coarse part, stopping test, beta) and ``cg_update_direction``.
"""

import warp as wp

from .coarse_space import add_rhs, aggregate_part, coarse_coefficients
from .hessian_blocks import hessian_row_product
from .world_rows import RowMap, mapped_row

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


@wp.func
def masked_block(block: wp.mat33, free: wp.vec3):
    """Block with fixed rows/columns replaced by identity rows/columns."""
    m = wp.diag(free)
    return m * block * m + wp.diag(wp.vec3(1.0) - free)


@wp.func
def begin_node_solve(
    i: int,
    residual: wp.array(dtype=wp.vec3),
    diag_block: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    precond: wp.array(dtype=wp.mat33),
    z: wp.array(dtype=wp.vec3),
    p: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    ap: wp.array(dtype=wp.vec3),
    rz: wp.array(dtype=float),
    residual_norm: wp.array(dtype=float),
):
    """Row ``i`` of ``begin_linear_solve``."""
    w = node_world[i]
    dx[i] = wp.vec3(0.0)
    ap[i] = wp.vec3(0.0)
    if world_active[w] == 0:
        p[i] = wp.vec3(0.0)
        return
    fr = free[i]
    r = wp.cw_mul(residual[i], fr)
    residual[i] = r
    pc = wp.inverse(masked_block(diag_block[i], fr))
    precond[i] = pc
    zi = wp.cw_mul(pc * r, fr)
    z[i] = zi
    p[i] = zi
    wp.atomic_add(rz, w, wp.dot(r, zi))
    wp.atomic_max(residual_norm, w, wp.max(wp.abs(r)))


@wp.kernel
def begin_linear_solve(
    residual: wp.array(dtype=wp.vec3),
    diag_block: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    precond: wp.array(dtype=wp.mat33),
    z: wp.array(dtype=wp.vec3),
    p: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    ap: wp.array(dtype=wp.vec3),
    rz: wp.array(dtype=float),
    residual_norm: wp.array(dtype=float),
):
    """Mask the residual, build the block-Jacobi preconditioner, start CG from dx = 0."""
    begin_node_solve(wp.tid(), residual, diag_block, free, node_world, world_active, precond, z, p, dx, ap, rz,
                     residual_norm)


@wp.func
def start_cg_world(
    w: int,
    newton_active: wp.array(dtype=int),
    newton_iterations: wp.array(dtype=int),
    patient: wp.array(dtype=int),
    last_update: wp.array(dtype=float),
    newton_tolerance: float,
    tolerance_near: float,
    tolerance_far: float,
    rz: wp.array(dtype=float),
    rz_stop: wp.array(dtype=float),
    cg_active: wp.array(dtype=int),
):
    """Row ``w`` of ``start_cg_worlds``."""
    update = float(0.0)
    if newton_iterations[w] > 0 and patient[w] == 0:
        update = last_update[w]
    eta = wp.clamp(tolerance_near * update / newton_tolerance, tolerance_near,
                   wp.max(tolerance_near, tolerance_far))
    rz_stop[w] = eta * eta * rz[w]
    active = 0
    if newton_active[w] != 0 and rz[w] > 0.0:
        active = 1
    cg_active[w] = active


@wp.kernel
def start_cg_worlds(
    newton_active: wp.array(dtype=int),
    newton_iterations: wp.array(dtype=int),
    patient: wp.array(dtype=int),
    last_update: wp.array(dtype=float),
    newton_tolerance: float,
    tolerance_near: float,
    tolerance_far: float,
    rz: wp.array(dtype=float),
    rz_stop: wp.array(dtype=float),
    cg_active: wp.array(dtype=int),
):
    """Start CG in the worlds still iterating Newton, with the r.z at which it stops: its start
    value times eta^2, eta = tolerance_near * (last Newton update / newton_tolerance) clamped to
    [tolerance_near, tolerance_far] (an inexact Newton method's forcing term: a world whose last
    update was far above the tolerance takes a rough step, one near it an accurate one, so that
    the convergence test and the contact forces of a converged solve rest on accurate steps).
    The last update is that of this substep (``newton_iterations`` [W]: its Newton iterations so
    far, cleared when a substep starts): a substep's first iteration solves to tolerance_near, so
    a substep's result depends on its input alone (not on the substeps or solves before it: a step
    of K substeps is bit-identical to K steps of one). A ``patient`` world (iterated on because
    its contact forces decide the actuator force limit: ``ImplicitSolver.advance``) solves every
    iteration to tolerance_near."""
    start_cg_world(wp.tid(), newton_active, newton_iterations, patient, last_update, newton_tolerance, tolerance_near,
                   tolerance_far, rz, rz_stop, cg_active)


@wp.func
def node_product_row(i: int, p: wp.array(dtype=wp.vec3), mass: wp.array(dtype=float),
                     contact_hessian: wp.array(dtype=wp.mat33), free: wp.array(dtype=wp.vec3), inv_dt2: float,
                     node_blocks: wp.array(dtype=wp.vec2i), block_node: wp.array(dtype=int),
                     hessian_values: wp.array(dtype=wp.mat33), ap: wp.array(dtype=wp.vec3)):
    """ap_i += (K p)_i + (m/dt^2 I + contact Hessian) p_i, masked, K the assembled elastic Hessian
    (``hessian_blocks.hessian_row_product``; ap holds the pad edge points' part); returns p_i . ap_i."""
    pi = p[i]
    elastic = hessian_row_product(i, p, node_blocks, block_node, hessian_values)
    api = wp.cw_mul(ap[i] + elastic + mass[i] * inv_dt2 * pi + contact_hessian[i] * pi, free[i])
    ap[i] = api
    return wp.dot(pi, api)


@wp.func
def node_product(i: int, p: wp.array(dtype=wp.vec3), mass: wp.array(dtype=float),
                 contact_hessian: wp.array(dtype=wp.mat33), free: wp.array(dtype=wp.vec3),
                 node_world: wp.array(dtype=int), cg_active: wp.array(dtype=int), inv_dt2: float,
                 node_blocks: wp.array(dtype=wp.vec2i), block_node: wp.array(dtype=int),
                 hessian_values: wp.array(dtype=wp.mat33), ap: wp.array(dtype=wp.vec3), p_ap: wp.array(dtype=float)):
    """``node_product_row`` of node ``i`` if its world iterates CG, and p_ap[w] += p_i . ap_i."""
    w = node_world[i]
    if cg_active[w] == 0:
        return
    wp.atomic_add(p_ap, w, node_product_row(i, p, mass, contact_hessian, free, inv_dt2, node_blocks, block_node,
                                            hessian_values, ap))


@wp.func
def node_products_serial(w: int, n0: int, n1: int, p: wp.array(dtype=wp.vec3), mass: wp.array(dtype=float),
                         contact_hessian: wp.array(dtype=wp.mat33), free: wp.array(dtype=wp.vec3), inv_dt2: float,
                         node_blocks: wp.array(dtype=wp.vec2i), block_node: wp.array(dtype=int),
                         hessian_values: wp.array(dtype=wp.mat33), ap: wp.array(dtype=wp.vec3),
                         p_ap: wp.array(dtype=float)):
    """``node_product`` of world ``w``'s nodes n0 .. n1 - 1 (iterating CG) by one thread: p . Ap summed
    in node order as there, in a register instead of through memory (the same bits; on a CPU core
    the sum's store-to-load chain no longer paces the rows)."""
    s = p_ap[w]
    for i in range(n0, n1):
        s += node_product_row(i, p, mass, contact_hessian, free, inv_dt2, node_blocks, block_node, hessian_values, ap)
    p_ap[w] = s


@wp.kernel
def cg_node_product(
    p: wp.array(dtype=wp.vec3),
    mass: wp.array(dtype=float),
    contact_hessian: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    cg_active: wp.array(dtype=int),
    inv_dt2: float,
    node_blocks: wp.array(dtype=wp.vec2i),
    block_node: wp.array(dtype=int),
    hessian_values: wp.array(dtype=wp.mat33),
    ap: wp.array(dtype=wp.vec3),
    p_ap: wp.array(dtype=float),
    rows: RowMap,
):
    """ap += (K + m/dt^2 I + contact Hessian) p (the pad edge points added their part); accumulate
    p . ap per world (the nodes of ``rows``)."""
    i = mapped_row(rows, wp.tid())
    if i < 0:
        return
    node_product(i, p, mass, contact_hessian, free, node_world, cg_active, inv_dt2, node_blocks, block_node,
                 hessian_values, ap, p_ap)


@wp.func
def cg_alpha(w: int, rz: wp.array(dtype=float), p_ap: wp.array(dtype=float)):
    """World ``w``'s CG step length r.z / p.Ap (0 where p.Ap is not positive)."""
    alpha = 0.0
    if p_ap[w] > 0.0:
        alpha = rz[w] / p_ap[w]
    return alpha


@wp.func
def update_solution_row(i: int, w: int, alpha: float, p: wp.array(dtype=wp.vec3), ap: wp.array(dtype=wp.vec3),
                        precond: wp.array(dtype=wp.mat33), free: wp.array(dtype=wp.vec3),
                        node_aggregate: wp.array(dtype=int), lever: wp.array(dtype=wp.vec3),
                        dx: wp.array(dtype=wp.vec3), r: wp.array(dtype=wp.vec3), z: wp.array(dtype=wp.vec3),
                        coarse_rhs: wp.array2d(dtype=float)):
    """dx_i += alpha p_i, r_i -= alpha ap_i, z_i = P r_i, T^T r gains node ``i``'s part; returns
    (the largest component of |alpha p_i|, r_i . z_i)."""
    step = alpha * p[i]
    dx[i] = dx[i] + step
    ri = r[i] - alpha * ap[i]
    r[i] = ri
    zi = wp.cw_mul(precond[i] * ri, free[i])
    z[i] = zi
    add_rhs(coarse_rhs, w, node_aggregate[i], lever[i], ri)
    return wp.max(wp.abs(step)), wp.dot(ri, zi)


@wp.func
def update_solution(i: int, p: wp.array(dtype=wp.vec3), ap: wp.array(dtype=wp.vec3),
                    precond: wp.array(dtype=wp.mat33), free: wp.array(dtype=wp.vec3),
                    node_world: wp.array(dtype=int), node_aggregate: wp.array(dtype=int),
                    lever: wp.array(dtype=wp.vec3),
                    cg_active: wp.array(dtype=int), rz: wp.array(dtype=float), p_ap: wp.array(dtype=float),
                    dx: wp.array(dtype=wp.vec3), r: wp.array(dtype=wp.vec3), z: wp.array(dtype=wp.vec3),
                    rz_new: wp.array(dtype=float), cg_update: wp.array(dtype=float),
                    coarse_rhs: wp.array2d(dtype=float)):
    """``update_solution_row`` of node ``i`` if its world iterates CG; the world's r.z and largest
    |alpha p| gain its part."""
    w = node_world[i]
    if cg_active[w] == 0:
        return
    moved, rz_i = update_solution_row(i, w, cg_alpha(w, rz, p_ap), p, ap, precond, free, node_aggregate, lever, dx, r,
                                      z, coarse_rhs)
    wp.atomic_max(cg_update, w, moved)
    wp.atomic_add(rz_new, w, rz_i)


@wp.func
def update_solutions_serial(w: int, n0: int, n1: int, p: wp.array(dtype=wp.vec3), ap: wp.array(dtype=wp.vec3),
                            precond: wp.array(dtype=wp.mat33), free: wp.array(dtype=wp.vec3),
                            node_aggregate: wp.array(dtype=int), lever: wp.array(dtype=wp.vec3),
                            rz: wp.array(dtype=float), p_ap: wp.array(dtype=float), dx: wp.array(dtype=wp.vec3),
                            r: wp.array(dtype=wp.vec3), z: wp.array(dtype=wp.vec3), rz_new: wp.array(dtype=float),
                            cg_update: wp.array(dtype=float), coarse_rhs: wp.array2d(dtype=float)):
    """``update_solution`` of world ``w``'s nodes n0 .. n1 - 1 (iterating CG) by one thread: alpha
    once, r.z summed in node order and the largest move kept in registers (the same bits)."""
    alpha = cg_alpha(w, rz, p_ap)
    rz_sum = rz_new[w]
    largest = cg_update[w]
    for i in range(n0, n1):
        moved, rz_i = update_solution_row(i, w, alpha, p, ap, precond, free, node_aggregate, lever, dx, r, z,
                                          coarse_rhs)
        largest = wp.max(largest, moved)
        rz_sum += rz_i
    rz_new[w] = rz_sum
    cg_update[w] = largest


@wp.kernel
def cg_update_solution(
    p: wp.array(dtype=wp.vec3),
    ap: wp.array(dtype=wp.vec3),
    precond: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    lever: wp.array(dtype=wp.vec3),
    cg_active: wp.array(dtype=int),
    rz: wp.array(dtype=float),
    p_ap: wp.array(dtype=float),
    dx: wp.array(dtype=wp.vec3),
    r: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
    rz_new: wp.array(dtype=float),
    cg_update: wp.array(dtype=float),
    coarse_rhs: wp.array2d(dtype=float),
    rows: RowMap,
):
    """dx += alpha p, r -= alpha A p, z = P r (block-Jacobi part); per world: r.z, the largest
    |alpha p| (m) and the coarse right-hand side T^T r (the nodes of ``rows``)."""
    i = mapped_row(rows, wp.tid())
    if i < 0:
        return
    update_solution(i, p, ap, precond, free, node_world, node_aggregate, lever, cg_active, rz, p_ap, dx, r, z,
                    rz_new, cg_update, coarse_rhs)


@wp.func
def end_iteration(w: int, rz_stop: wp.array(dtype=float), update_tol: float, max_iterations: int,
                  coarse_sizes: wp.array(dtype=int), coarse_inverse: wp.array3d(dtype=wp.float64),
                  coarse_rhs: wp.array2d(dtype=float), coarse_coef: wp.array2d(dtype=float),
                  rz: wp.array(dtype=float), rz_new: wp.array(dtype=float), p_ap: wp.array(dtype=float),
                  beta: wp.array(dtype=float), cg_iterations: wp.array(dtype=int),
                  cg_iterations_total: wp.array(dtype=int), cg_active: wp.array(dtype=int),
                  cg_update: wp.array(dtype=float)):
    """World ``w``'s coarse part of z (coef = E^-1 T^T r; r.z gains g . E^-1 g), beta, and its
    stopping test (``cg_end_iteration``)."""
    if cg_active[w] == 0:
        return
    finish_iteration(w, coarse_coefficients(w, coarse_sizes[w], coarse_inverse, coarse_rhs, coarse_coef), rz_stop,
                     update_tol, max_iterations, rz, rz_new, p_ap, beta, cg_iterations, cg_iterations_total,
                     cg_active, cg_update)


@wp.func
def finish_iteration(w: int, gain: float, rz_stop: wp.array(dtype=float), update_tol: float,
                     max_iterations: int, rz: wp.array(dtype=float), rz_new: wp.array(dtype=float),
                     p_ap: wp.array(dtype=float), beta: wp.array(dtype=float), cg_iterations: wp.array(dtype=int),
                     cg_iterations_total: wp.array(dtype=int), cg_active: wp.array(dtype=int),
                     cg_update: wp.array(dtype=float)):
    """``end_iteration`` after its coarse part (``gain`` = g . E^-1 g): r.z, beta, the
    stopping test, and the world's sums zeroed for the next iteration."""
    rz_next = rz_new[w] + gain
    it = cg_iterations[w] + 1
    cg_iterations[w] = it
    cg_iterations_total[w] = cg_iterations_total[w] + 1
    stalled = cg_update[w] <= update_tol and it >= 8  # CG can creep for a few iterations first
    if rz_next <= rz_stop[w] or stalled or it >= max_iterations or p_ap[w] <= 0.0:
        cg_active[w] = 0
    b = 0.0
    if rz[w] > 0.0:
        b = rz_next / rz[w]
    beta[w] = b
    cg_update[w] = 0.0
    rz[w] = rz_next
    rz_new[w] = 0.0
    p_ap[w] = 0.0


@wp.kernel
def cg_end_iteration(
    rz_stop: wp.array(dtype=float),
    update_tol: float,
    max_iterations: int,
    coarse_sizes: wp.array(dtype=int),
    coarse_inverse: wp.array3d(dtype=wp.float64),
    coarse_rhs: wp.array2d(dtype=float),
    coarse_coef: wp.array2d(dtype=float),
    rz: wp.array(dtype=float),
    rz_new: wp.array(dtype=float),
    p_ap: wp.array(dtype=float),
    beta: wp.array(dtype=float),
    cg_iterations: wp.array(dtype=int),
    cg_iterations_total: wp.array(dtype=int),
    cg_active: wp.array(dtype=int),
    cg_update: wp.array(dtype=float),
):
    """Per world: the coarse part of z (coef = E^-1 T^T r; r.z gains g . E^-1 g), beta, and the
    stopping test: stop on relative residual, on an iteration that moved no node by more than
    ``update_tol`` (m: the absolute test, as r.z cannot fall below float32 noise near a
    solution; applied from the 8th iteration on), on the iteration cap, or on a non-positive
    curvature."""
    end_iteration(wp.tid(), rz_stop, update_tol, max_iterations, coarse_sizes, coarse_inverse, coarse_rhs,
                  coarse_coef, rz, rz_new, p_ap, beta, cg_iterations, cg_iterations_total, cg_active, cg_update)


@wp.func
def update_direction(i: int, free: wp.array(dtype=wp.vec3), node_world: wp.array(dtype=int),
                     node_aggregate: wp.array(dtype=int), lever: wp.array(dtype=wp.vec3),
                     cg_active: wp.array(dtype=int),
                     coarse_coef: wp.array2d(dtype=float), beta: wp.array(dtype=float),
                     z: wp.array(dtype=wp.vec3), p: wp.array(dtype=wp.vec3), ap: wp.array(dtype=wp.vec3)):
    """z_i += (T coef)_i, p_i = z_i + beta p_i, ap_i = 0 (node ``i``, if its world still iterates)."""
    w = node_world[i]
    if cg_active[w] == 0:
        return
    zi = z[i] + aggregate_part(coarse_coef, w, node_aggregate[i], lever[i], free[i])
    z[i] = zi
    p[i] = zi + beta[w] * p[i]
    ap[i] = wp.vec3(0.0)


@wp.kernel
def cg_update_direction(
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    lever: wp.array(dtype=wp.vec3),
    cg_active: wp.array(dtype=int),
    coarse_coef: wp.array2d(dtype=float),
    beta: wp.array(dtype=float),
    z: wp.array(dtype=wp.vec3),
    p: wp.array(dtype=wp.vec3),
    ap: wp.array(dtype=wp.vec3),
    rows: RowMap,
):
    """z += T coef (the coarse part), p = z + beta p, ap = 0, in the worlds still iterating (the
    nodes of ``rows``)."""
    i = mapped_row(rows, wp.tid())
    if i < 0:
        return
    update_direction(i, free, node_world, node_aggregate, lever, cg_active, coarse_coef, beta, z, p, ap)
