"""Coarse space of the per-world linear solves: rigid motions (translations and infinitesimal
rotations) of node aggregates.

Block-Jacobi CG barely moves the smooth, long-wavelength modes of a Newton system A dx = r: the
rigid translations of a stiff object (their stiffness m/h^2 is ~1e5 times below the elastic one),
the bending of a slender one (a rope: CG needs ~ its length in elements of iterations to carry a
correction from end to end) and the swinging of the free parts of a held one (the hanging ends of a
gripped rope: its slowest modes were 99 % rigid motions of its aggregates, against 12-97 % for the
translations alone). Every world's nodes are split into at most K aggregates
(``sim/aggregates.py``); T [3N x 6K] holds the rigid motions of each aggregate: for a node i of
aggregate a, columns (a, k) = e_k (translations) and (a, 3 + k) = e_k x d_i (rotations about the
aggregate's origin node o_a, d_i = x_i - x_{o_a} at the current Newton iterate), masked by the free
axes. Per Newton iteration the coarse matrix E = T^T A T (6K x 6K, float64) is assembled from the
node terms (mass/h^2 + contact blocks) and the tets: a tet inside one aggregate with all axes free
adds only to the rotation block (a uniform translation does not strain it, exactly), through the
three products with dF = sum_v (e_k x d_v) (x) b_v; a tet that straddles aggregates (or has a
prescribed axis) adds the products of all the columns of its aggregates. E is Cholesky-factored and
inverted per world.
It is used (a) before CG: dx0 = T E^-1 T^T r, residual r - A dx0, (b) inside CG: the two-level
additive preconditioner z = P r + T E^-1 T^T r (P block Jacobi; SPD, so CG stays CG), and (c) after
CG: dx += T E^-1 T^T r (the best A-norm correction in the coarse space).
A world whose E is not numerically positive definite gets E^-1 = 0 (block Jacobi alone) for that
Newton iteration.
"""

import warp as wp

from .elastic import pick_vertex, row, stress_differential

#: Coarse unknowns per aggregate: 3 translations, 3 rotations.
AGGREGATE_DOFS = 6


@wp.func
def lever(x: wp.array(dtype=wp.vec3), origin: wp.array2d(dtype=int), w: int, a: int, i: int):
    """d_i = x_i - x_o (m): node i relative to the origin node of its aggregate ``a`` of world ``w``."""
    return x[i] - x[origin[w, a]]


@wp.func
def aggregate_part(coef: wp.array2d(dtype=float), w: int, a: int, free: wp.vec3, d: wp.vec3):
    """(T c)_i = free * (t_a + theta_a x d_i) for a node of aggregate ``a`` of world ``w``."""
    t = wp.vec3(coef[w, 6 * a], coef[w, 6 * a + 1], coef[w, 6 * a + 2])
    theta = wp.vec3(coef[w, 6 * a + 3], coef[w, 6 * a + 4], coef[w, 6 * a + 5])
    return wp.cw_mul(free, t + wp.cross(theta, d))


@wp.func
def add_rhs(rhs: wp.array2d(dtype=float), w: int, a: int, v: wp.vec3, d: wp.vec3):
    """rhs_a += T_i^T v for a node of aggregate ``a`` (``v`` masked by the free axes): v and d x v."""
    m = wp.cross(d, v)
    for k in range(3):
        wp.atomic_add(rhs, w, 6 * a + k, v[k])
        wp.atomic_add(rhs, w, 6 * a + 3 + k, m[k])


@wp.func
def coarse_coefficients(w: int, size: int, inverse: wp.array3d(dtype=wp.float64),
                        rhs: wp.array2d(dtype=float), coef: wp.array2d(dtype=float)):
    """coef = E^-1 g for g = rhs (T^T r), then rhs = 0; returns g . E^-1 g."""
    g_c = wp.float64(0.0)
    for i in range(size):
        s = wp.float64(0.0)
        for j in range(size):
            s += inverse[w, i, j] * wp.float64(rhs[w, j])
        coef[w, i] = float(s)
        g_c += s * wp.float64(rhs[w, i])
    for i in range(size):
        rhs[w, i] = 0.0
    return float(g_c)


@wp.func
def coarse_column(k: int, free: wp.vec3, d: wp.vec3):
    """Column k of T on a node (0-2: translation e_k, 3-5: rotation e_(k-3) x d), masked."""
    e = wp.vec3(0.0)
    if k < 3:
        e[k] = 1.0
        return wp.cw_mul(free, e)
    e[k - 3] = 1.0
    return wp.cw_mul(free, wp.cross(e, d))


@wp.kernel
def coarse_assemble_nodes(
    mass: wp.array(dtype=float),
    contact_hessian: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    x: wp.array(dtype=wp.vec3),
    origin: wp.array2d(dtype=int),
    inv_dt2: float,
    r: wp.array(dtype=wp.vec3),
    matrix: wp.array3d(dtype=wp.float64),
    rhs: wp.array2d(dtype=float),
):
    """E += T_i^T (M/h^2 + contact blocks) T_i and rhs += T_i^T r (r already masked); with
    T_i = [I | S], S = -skew(d_i) (rotation columns e_k x d_i), the block B masked on both sides."""
    i = wp.tid()
    w = node_world[i]
    if world_active[w] == 0:
        return
    a = node_aggregate[i]
    d = lever(x, origin, w, a, i)
    fr = wp.diag(free[i])
    block = fr * (mass[i] * inv_dt2 * wp.identity(n=3, dtype=float) + contact_hessian[i]) * fr
    skew_s = -wp.skew(d)
    bs = block * skew_s
    ss = wp.transpose(skew_s) * bs
    for j in range(3):
        for k in range(3):
            wp.atomic_add(matrix, w, 6 * a + j, 6 * a + k, wp.float64(block[j, k]))
            wp.atomic_add(matrix, w, 6 * a + j, 6 * a + 3 + k, wp.float64(bs[j, k]))
            wp.atomic_add(matrix, w, 6 * a + 3 + k, 6 * a + j, wp.float64(bs[j, k]))
            wp.atomic_add(matrix, w, 6 * a + 3 + j, 6 * a + 3 + k, wp.float64(ss[j, k]))
    add_rhs(rhs, w, a, r[i], d)


@wp.kernel
def coarse_assemble_tets(
    x: wp.array(dtype=wp.vec3),
    origin: wp.array2d(dtype=int),
    tets: wp.array(dtype=wp.vec4i),
    rest_inv: wp.array(dtype=wp.mat33),
    rest_volume: wp.array(dtype=float),
    tet_mu: wp.array(dtype=float),
    tet_lambda: wp.array(dtype=float),
    tet_cof: wp.array(dtype=wp.mat33),
    tet_r: wp.array(dtype=wp.mat33),
    tet_twist: wp.array(dtype=float),
    tet_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    free: wp.array(dtype=wp.vec3),
    node_aggregate: wp.array(dtype=int),
    matrix: wp.array3d(dtype=wp.float64),
):
    """E += T^T K_t T: per coarse column (a, k) of the aggregates of the tet's nodes, the Hessian
    product (``stress_differential``) with dF = sum over the tet's nodes v in aggregate a of
    (T column)_v (x) b_v, its node forces projected on the rows T_u^T. A tet inside one aggregate with
    all axes free: the three rotation columns into the rotation block only (its translation
    columns and rows are zero, exactly)."""
    t = wp.tid()
    w = tet_world[t]
    if world_active[w] == 0:
        return
    idx = tets[t]
    dm_inv = rest_inv[t]
    b1 = row(dm_inv, 0)
    b2 = row(dm_inv, 1)
    b3 = row(dm_inv, 2)
    b0 = -(b1 + b2 + b3)
    cof = tet_cof[t]
    r = tet_r[t]
    twist = tet_twist[t]
    mu = tet_mu[t]
    lam = tet_lambda[t]
    v0 = rest_volume[t]
    a0 = node_aggregate[idx[0]]
    all_free = free[idx[0]] + free[idx[1]] + free[idx[2]] + free[idx[3]]
    inside = (a0 == node_aggregate[idx[1]] and a0 == node_aggregate[idx[2]] and a0 == node_aggregate[idx[3]]
              and all_free[0] + all_free[1] + all_free[2] == 12.0)
    for v in range(4):
        av = node_aggregate[idx[v]]
        first = int(1)
        for u in range(v):
            if node_aggregate[idx[u]] == av:
                first = 0
        if first == 1:
            k_start = int(0)
            if inside:
                k_start = 3
            for k in range(k_start, 6):
                df = wp.mat33(0.0)
                for u in range(4):
                    if node_aggregate[idx[u]] == av:
                        col = coarse_column(k, free[idx[u]], lever(x, origin, w, av, idx[u]))
                        df += wp.outer(col, pick_vertex(b0, b1, b2, b3, u))
                dp = stress_differential(df, cof, r, twist, mu, lam, v0)
                for u in range(4):
                    au = node_aggregate[idx[u]]
                    f = wp.cw_mul(free[idx[u]], dp * pick_vertex(b0, b1, b2, b3, u))
                    m = wp.cross(lever(x, origin, w, au, idx[u]), f)
                    for j in range(3):
                        if not inside:
                            wp.atomic_add(matrix, w, 6 * au + j, 6 * av + k, wp.float64(f[j]))
                        wp.atomic_add(matrix, w, 6 * au + 3 + j, 6 * av + k, wp.float64(m[j]))


@wp.kernel
def coarse_factor(
    world_active: wp.array(dtype=int),
    size: int,
    matrix: wp.array3d(dtype=wp.float64),
    lower_inv: wp.array3d(dtype=wp.float64),
    inverse: wp.array3d(dtype=wp.float64),
    rhs: wp.array2d(dtype=float),
    coef: wp.array2d(dtype=float),
    rz: wp.array(dtype=float),
):
    """Per world: E^-1 by Cholesky (E = L L^T, E^-1 = L^-T L^-1; unknowns with a zero diagonal, i.e.
    empty aggregates or axes prescribed on all of an aggregate's nodes, get 1), coef = E^-1 rhs;
    clears E, rhs and rz (recomputed by ``coarse_start_cg``)."""
    w = wp.tid()
    if world_active[w] == 0:
        return
    ok = int(1)
    for j in range(size):
        if matrix[w, j, j] <= wp.float64(0.0):
            matrix[w, j, j] = wp.float64(1.0)
    for j in range(size):  # Cholesky, in place in the lower triangle
        if ok == 1:
            s = matrix[w, j, j]
            for k in range(j):
                s -= matrix[w, j, k] * matrix[w, j, k]
            if not (s > wp.float64(1.0e-12) * matrix[w, j, j]):
                ok = 0
            else:
                d = wp.sqrt(s)
                matrix[w, j, j] = d
                for i in range(j + 1, size):
                    s2 = matrix[w, i, j]
                    for k in range(j):
                        s2 -= matrix[w, i, k] * matrix[w, j, k]
                    matrix[w, i, j] = s2 / d
    for j in range(size):  # L^-1 (lower)
        for i in range(size):
            lower_inv[w, i, j] = wp.float64(0.0)
        if ok == 1:
            lower_inv[w, j, j] = wp.float64(1.0) / matrix[w, j, j]
            for i in range(j + 1, size):
                s = wp.float64(0.0)
                for k in range(j, i):
                    s += matrix[w, i, k] * lower_inv[w, k, j]
                lower_inv[w, i, j] = -s / matrix[w, i, i]
    for i in range(size):  # E^-1 = L^-T L^-1 (symmetric by construction)
        for j in range(i + 1):
            s = wp.float64(0.0)
            for k in range(i, size):
                s += lower_inv[w, k, i] * lower_inv[w, k, j]
            inverse[w, i, j] = s
            inverse[w, j, i] = s
    for i in range(size):
        for j in range(size):
            matrix[w, i, j] = wp.float64(0.0)
    coarse_coefficients(w, size, inverse, rhs, coef)
    rz[w] = 0.0


@wp.kernel
def coarse_guess(
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    x: wp.array(dtype=wp.vec3),
    origin: wp.array2d(dtype=int),
    world_active: wp.array(dtype=int),
    coef: wp.array2d(dtype=float),
    dx: wp.array(dtype=wp.vec3),
    guess: wp.array(dtype=wp.vec3),
):
    """dx += T coef; guess = T coef (the direction whose A-product ``coarse_start_cg`` subtracts)."""
    i = wp.tid()
    w = node_world[i]
    if world_active[w] == 0:
        return
    a = node_aggregate[i]
    d = aggregate_part(coef, w, a, free[i], lever(x, origin, w, a, i))
    dx[i] = dx[i] + d
    guess[i] = d


@wp.kernel
def coarse_start_cg(
    precond: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    r: wp.array(dtype=wp.vec3),
    ap: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
    p: wp.array(dtype=wp.vec3),
    rz: wp.array(dtype=float),
):
    """r -= A T coef (in ``ap``), then CG's z = p = P r, rz = r . z and ap = 0. T^T r = 0 after the
    coarse solve, so the coarse part of the first z vanishes (up to rounding) and is left out."""
    i = wp.tid()
    w = node_world[i]
    if world_active[w] == 0:
        return
    fr = free[i]
    ri = wp.cw_mul(r[i] - ap[i], fr)
    r[i] = ri
    zi = wp.cw_mul(precond[i] * ri, fr)
    z[i] = zi
    p[i] = zi
    ap[i] = wp.vec3(0.0)
    wp.atomic_add(rz, w, wp.dot(ri, zi))


@wp.kernel
def coarse_reduce(
    r: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    x: wp.array(dtype=wp.vec3),
    origin: wp.array2d(dtype=int),
    world_active: wp.array(dtype=int),
    rhs: wp.array2d(dtype=float),
):
    """rhs += T^T r (r masked)."""
    i = wp.tid()
    w = node_world[i]
    if world_active[w] == 0:
        return
    a = node_aggregate[i]
    add_rhs(rhs, w, a, r[i], lever(x, origin, w, a, i))


@wp.kernel
def coarse_solve(
    world_active: wp.array(dtype=int),
    size: int,
    inverse: wp.array3d(dtype=wp.float64),
    rhs: wp.array2d(dtype=float),
    coef: wp.array2d(dtype=float),
):
    """coef = E^-1 rhs with the E^-1 of this Newton iteration; clears rhs."""
    w = wp.tid()
    if world_active[w] == 0:
        return
    coarse_coefficients(w, size, inverse, rhs, coef)


@wp.kernel
def coarse_correct(
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    x: wp.array(dtype=wp.vec3),
    origin: wp.array2d(dtype=int),
    world_active: wp.array(dtype=int),
    coef: wp.array2d(dtype=float),
    dx: wp.array(dtype=wp.vec3),
):
    """dx += T coef."""
    i = wp.tid()
    w = node_world[i]
    if world_active[w] == 0:
        return
    a = node_aggregate[i]
    dx[i] = dx[i] + aggregate_part(coef, w, a, free[i], lever(x, origin, w, a, i))
