"""Per-world linear solves of the Newton systems: block-Jacobi preconditioned conjugate gradients
with a coarse correction on the rigid translations.

Every world runs its own CG (its own alpha, beta and stopping test) inside one set of flat arrays,
so a world's result never depends on the other worlds. Per-world flags switch finished worlds off.
"""

import warp as wp


@wp.func
def masked_block(block: wp.mat33, free: wp.vec3):
    """Block with fixed rows/columns replaced by identity rows/columns."""
    m = wp.diag(free)
    return m * block * m + wp.diag(wp.vec3(1.0) - free)


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
    i = wp.tid()
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
def start_cg_worlds(
    newton_active: wp.array(dtype=int),
    rz: wp.array(dtype=float),
    rz_initial: wp.array(dtype=float),
    cg_active: wp.array(dtype=int),
):
    w = wp.tid()
    rz_initial[w] = rz[w]
    active = 0
    if newton_active[w] != 0 and rz[w] > 0.0:
        active = 1
    cg_active[w] = active


@wp.kernel
def cg_node_product(
    p: wp.array(dtype=wp.vec3),
    mass: wp.array(dtype=float),
    contact_hessian: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    cg_active: wp.array(dtype=int),
    inv_dt2: float,
    ap: wp.array(dtype=wp.vec3),
    p_ap: wp.array(dtype=float),
):
    """ap += (m/dt^2 I + contact Hessian) p (the tets added their part); accumulate p . ap per world."""
    i = wp.tid()
    w = node_world[i]
    if cg_active[w] == 0:
        return
    pi = p[i]
    api = wp.cw_mul(ap[i] + mass[i] * inv_dt2 * pi + contact_hessian[i] * pi, free[i])
    ap[i] = api
    wp.atomic_add(p_ap, w, wp.dot(pi, api))


@wp.kernel
def cg_update_solution(
    p: wp.array(dtype=wp.vec3),
    ap: wp.array(dtype=wp.vec3),
    precond: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    cg_active: wp.array(dtype=int),
    rz: wp.array(dtype=float),
    p_ap: wp.array(dtype=float),
    dx: wp.array(dtype=wp.vec3),
    r: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
    rz_new: wp.array(dtype=float),
    cg_update: wp.array(dtype=float),
):
    """dx += alpha p, r -= alpha A p, z = P r; per world: r.z and the largest |alpha p| (m)."""
    i = wp.tid()
    w = node_world[i]
    if cg_active[w] == 0:
        return
    alpha = 0.0
    if p_ap[w] > 0.0:
        alpha = rz[w] / p_ap[w]
    step = alpha * p[i]
    dx[i] = dx[i] + step
    wp.atomic_max(cg_update, w, wp.max(wp.abs(step)))
    ri = r[i] - alpha * ap[i]
    r[i] = ri
    zi = wp.cw_mul(precond[i] * ri, free[i])
    z[i] = zi
    wp.atomic_add(rz_new, w, wp.dot(ri, zi))


@wp.kernel
def cg_update_direction(
    z: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    cg_active: wp.array(dtype=int),
    rz: wp.array(dtype=float),
    rz_new: wp.array(dtype=float),
    p: wp.array(dtype=wp.vec3),
    ap: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    w = node_world[i]
    if cg_active[w] == 0:
        return
    beta = 0.0
    if rz[w] > 0.0:
        beta = rz_new[w] / rz[w]
    p[i] = z[i] + beta * p[i]
    ap[i] = wp.vec3(0.0)


@wp.kernel
def cg_end_iteration(
    rz: wp.array(dtype=float),
    rz_new: wp.array(dtype=float),
    rz_initial: wp.array(dtype=float),
    p_ap: wp.array(dtype=float),
    rel_tol_sq: float,
    update_tol: float,
    max_iterations: int,
    cg_iterations: wp.array(dtype=int),
    cg_iterations_total: wp.array(dtype=int),
    cg_active: wp.array(dtype=int),
    cg_update: wp.array(dtype=float),
):
    """Stop a world's CG on relative residual, on an iteration that moved no node by more than
    ``update_tol`` (m: the absolute test, as r.z cannot fall below float32 noise near a
    solution; applied from the 8th iteration on), on the iteration cap, or on a non-positive curvature."""
    w = wp.tid()
    if cg_active[w] == 0:
        return
    it = cg_iterations[w] + 1
    cg_iterations[w] = it
    cg_iterations_total[w] = cg_iterations_total[w] + 1
    stalled = cg_update[w] <= update_tol and it >= 8  # CG can creep for a few iterations first
    if rz_new[w] <= rel_tol_sq * rz_initial[w] or stalled or it >= max_iterations or p_ap[w] <= 0.0:
        cg_active[w] = 0
    cg_update[w] = 0.0
    rz[w] = rz_new[w]
    rz_new[w] = 0.0
    p_ap[w] = 0.0


# -- coarse (rigid translation) correction of the linear solve ------------------------------------
# Block-Jacobi CG barely moves the rigid translations of a stiff object (their stiffness m/dt^2 is
# ~1e5 times below the elastic one), so a falling object did not fall. Each Newton system is
# therefore also solved on the 3 translations T_k = e_k (masked by the free axes) per world
# (Galerkin: (T^T A T) c = T^T r) before CG (initial guess) and after it (correction).


@wp.kernel
def coarse_clear(
    node_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    at0: wp.array(dtype=wp.vec3),
    at1: wp.array(dtype=wp.vec3),
    at2: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    if world_active[node_world[i]] == 0:
        return
    at0[i] = wp.vec3(0.0)
    at1[i] = wp.vec3(0.0)
    at2[i] = wp.vec3(0.0)


@wp.kernel
def coarse_reduce(
    at0: wp.array(dtype=wp.vec3),
    at1: wp.array(dtype=wp.vec3),
    at2: wp.array(dtype=wp.vec3),
    r: wp.array(dtype=wp.vec3),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    with_matrix: int,
    coarse_matrix: wp.array(dtype=wp.mat33),
    coarse_rhs: wp.array(dtype=wp.vec3),
):
    """Per world: coarse_rhs += T^T r and (if with_matrix) coarse_matrix += T^T A T, where
    at_k = A T_k and (T_j . v)_i = free_i[j] v_i[j]."""
    i = wp.tid()
    w = node_world[i]
    if world_active[w] == 0:
        return
    fr = free[i]
    wp.atomic_add(coarse_rhs, w, wp.cw_mul(fr, r[i]))
    if with_matrix != 0:
        a0 = at0[i]
        a1 = at1[i]
        a2 = at2[i]
        m = wp.mat33(fr[0] * a0[0], fr[0] * a1[0], fr[0] * a2[0],
                     fr[1] * a0[1], fr[1] * a1[1], fr[1] * a2[1],
                     fr[2] * a0[2], fr[2] * a1[2], fr[2] * a2[2])
        wp.atomic_add(coarse_matrix, w, m)


@wp.kernel
def coarse_solve(
    world_active: wp.array(dtype=int),
    store_inverse: int,
    coarse_matrix: wp.array(dtype=wp.mat33),
    coarse_rhs: wp.array(dtype=wp.vec3),
    coarse_inverse: wp.array(dtype=wp.mat33),
    coarse_coef: wp.array(dtype=wp.vec3),
    rz: wp.array(dtype=float),
):
    """coef = (T^T A T)^-1 T^T r per world (axes fixed on every node get coef 0); clears the
    sums and rz (recomputed by coarse_apply)."""
    w = wp.tid()
    coarse_coef[w] = wp.vec3(0.0)
    if world_active[w] == 0:
        return
    if store_inverse != 0:
        m = coarse_matrix[w]
        for k in range(3):
            if m[k, k] <= 0.0:
                m[k, k] = 1.0
        inv = wp.mat33(0.0)
        det = wp.determinant(m)
        if wp.isfinite(det) and det > 0.0:
            inv = wp.inverse(m)
        coarse_inverse[w] = inv
    coarse_coef[w] = coarse_inverse[w] * coarse_rhs[w]
    coarse_matrix[w] = wp.mat33(0.0)
    coarse_rhs[w] = wp.vec3(0.0)
    rz[w] = 0.0


@wp.kernel
def coarse_apply(
    at0: wp.array(dtype=wp.vec3),
    at1: wp.array(dtype=wp.vec3),
    at2: wp.array(dtype=wp.vec3),
    precond: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    coarse_coef: wp.array(dtype=wp.vec3),
    update_residual: int,
    dx: wp.array(dtype=wp.vec3),
    r: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
    p: wp.array(dtype=wp.vec3),
    rz: wp.array(dtype=float),
):
    """dx += T coef; if update_residual, also r -= A T coef and restart CG's z = p = P r, rz."""
    i = wp.tid()
    w = node_world[i]
    if world_active[w] == 0:
        return
    c = coarse_coef[w]
    fr = free[i]
    dx[i] = dx[i] + wp.cw_mul(fr, c)
    if update_residual != 0:
        ri = wp.cw_mul(r[i] - (c[0] * at0[i] + c[1] * at1[i] + c[2] * at2[i]), fr)
        r[i] = ri
        zi = wp.cw_mul(precond[i] * ri, fr)
        z[i] = zi
        p[i] = zi
        wp.atomic_add(rz, w, wp.dot(ri, zi))
