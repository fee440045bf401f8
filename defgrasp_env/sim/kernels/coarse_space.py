"""Coarse space of the per-world linear solves: piecewise-constant translations of node aggregates.

Block-Jacobi CG barely moves the smooth, long-wavelength modes of a Newton system A dx = r: the
rigid translations of a stiff object (their stiffness m/h^2 is ~1e5 times below the elastic one)
and the bending of a slender one (a rope: CG needs ~ its length in elements of iterations to carry
a correction from end to end). Every world's nodes are split into at most K aggregates (``sim/aggregates.py``);
T [3N x 3K] holds the translations of each aggregate, column (a, k) = e_k on the nodes of aggregate
a, masked by the free axes. Per Newton iteration the coarse matrix E = T^T A T (3K x 3K, float64)
is assembled from the node terms (mass/h^2 + contact blocks) and the tets that straddle two or more
aggregates (a uniform translation does not strain a tet, so tets inside one aggregate add nothing,
exactly, when all their axes are free), Cholesky-factored and inverted per world.
It is used (a) before CG: dx0 = T E^-1 T^T r, residual r - A dx0, (b) inside CG: the two-level
additive preconditioner z = P r + T E^-1 T^T r (P block Jacobi; SPD, so CG stays CG), and (c) after
CG: dx += T E^-1 T^T r (the best A-norm correction in the coarse space).
A world whose E is not numerically positive definite gets E^-1 = 0 (block Jacobi alone) for that
Newton iteration.
"""

import warp as wp

from .block_sync import block_barrier
from .elastic import pick_vertex, row, spare_tet, stress_differential

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})

#: Coarse solves of at most this many unknowns (one aggregate: a compact object's) are factored and
#: applied by one thread of a world's block (``coarse_factor_world``, ``linear_solve.end_iteration``);
#: larger ones (a slender object's aggregates) by its threads (``coarse_factor_block``,
#: ``coarse_row``), with more barriers. The same bits either way on the CPU.
LANE_COARSE_SIZE = 3


@wp.func
def aggregate_part(coef: wp.array2d(dtype=float), w: int, a: int, free: wp.vec3):
    """(T c)_i for a node of aggregate ``a`` of world ``w`` with free axes ``free``."""
    return wp.cw_mul(free, wp.vec3(coef[w, 3 * a], coef[w, 3 * a + 1], coef[w, 3 * a + 2]))


@wp.func
def add_rhs(rhs: wp.array2d(dtype=float), w: int, a: int, v: wp.vec3):
    wp.atomic_add(rhs, w, 3 * a, v[0])
    wp.atomic_add(rhs, w, 3 * a + 1, v[1])
    wp.atomic_add(rhs, w, 3 * a + 2, v[2])


@wp.func
def coarse_coefficient(w: int, i: int, size: int, inverse: wp.array3d(dtype=wp.float64),
                       rhs: wp.array2d(dtype=float), coef: wp.array2d(dtype=float)):
    """coef_i = (E^-1 g)_i for g = rhs (T^T r); returns it in float64."""
    s = wp.float64(0.0)
    for j in range(size):
        s += inverse[w, i, j] * wp.float64(rhs[w, j])
    coef[w, i] = float(s)
    return s


@wp.func
def coarse_coefficients(w: int, size: int, inverse: wp.array3d(dtype=wp.float64),
                        rhs: wp.array2d(dtype=float), coef: wp.array2d(dtype=float)):
    """coef = E^-1 g for g = rhs (T^T r), then rhs = 0; returns g . E^-1 g."""
    g_c = wp.float64(0.0)
    for i in range(size):
        s = coarse_coefficient(w, i, size, inverse, rhs, coef)
        g_c += s * wp.float64(rhs[w, i])
    for i in range(size):
        rhs[w, i] = 0.0
    return float(g_c)


@wp.func
def coarse_row(w: int, i: int, size: int, inverse: wp.array3d(dtype=wp.float64), rhs: wp.array2d(dtype=float),
               coef: wp.array2d(dtype=float), terms: wp.array2d(dtype=wp.float64)):
    """Row ``i`` of ``coarse_coefficients``: coef_i = (E^-1 g)_i and its term g_i (E^-1 g)_i of
    g . E^-1 g (float64, summed in row order by ``coarse_gain``); rhs is left as it is. The same
    operations in the same order as there, so that rows computed by the threads of a block give
    the same bits as one thread's loop."""
    s = coarse_coefficient(w, i, size, inverse, rhs, coef)
    terms[w, i] = s * wp.float64(rhs[w, i])


@wp.func
def coarse_gain(w: int, size: int, rhs: wp.array2d(dtype=float), terms: wp.array2d(dtype=wp.float64)):
    """g . E^-1 g from the rows' ``coarse_row`` terms (summed in row order, as
    ``coarse_coefficients`` does), then rhs = 0."""
    g_c = wp.float64(0.0)
    for i in range(size):
        g_c += terms[w, i]
    for i in range(size):
        rhs[w, i] = 0.0
    return float(g_c)


@wp.func
def coarse_assemble_node(
    i: int,
    mass: wp.array(dtype=float),
    contact_hessian: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    inv_dt2: float,
    r: wp.array(dtype=wp.vec3),
    matrix: wp.array3d(dtype=wp.float64),
    rhs: wp.array2d(dtype=float),
):
    """Row ``i`` of ``coarse_assemble_nodes``."""
    w = node_world[i]
    if world_active[w] == 0:
        return
    a = node_aggregate[i]
    fr = wp.diag(free[i])
    block = fr * (mass[i] * inv_dt2 * wp.identity(n=3, dtype=float) + contact_hessian[i]) * fr
    for j in range(3):
        for k in range(3):
            wp.atomic_add(matrix, w, 3 * a + j, 3 * a + k, wp.float64(block[j, k]))
    add_rhs(rhs, w, a, r[i])


@wp.kernel
def coarse_assemble_nodes(
    mass: wp.array(dtype=float),
    contact_hessian: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    inv_dt2: float,
    r: wp.array(dtype=wp.vec3),
    matrix: wp.array3d(dtype=wp.float64),
    rhs: wp.array2d(dtype=float),
):
    """E += T^T (M/h^2 + contact blocks) T and rhs += T^T r (r already masked)."""
    coarse_assemble_node(wp.tid(), mass, contact_hessian, free, node_world, node_aggregate, world_active, inv_dt2, r,
                         matrix, rhs)


@wp.func
def vertices_in(a: int, a0: int, a1: int, a2: int, a3: int):
    """How many of a tet's four vertices (aggregates ``a0`` .. ``a3``) belong to aggregate ``a``."""
    return wp.where(a == a0, 1, 0) + wp.where(a == a1, 1, 0) + wp.where(a == a2, 1, 0) + wp.where(a == a3, 1, 0)


@wp.func
def most_shared_aggregate(a0: int, a1: int, a2: int, a3: int):
    """The aggregate that most of a tet's four vertices (aggregates ``a0`` .. ``a3``) belong to;
    the first vertex's among equals."""
    best = a0
    most = vertices_in(a0, a0, a1, a2, a3)
    n1 = vertices_in(a1, a0, a1, a2, a3)
    if n1 > most:
        best = a1
        most = n1
    n2 = vertices_in(a2, a0, a1, a2, a3)
    if n2 > most:
        best = a2
        most = n2
    if vertices_in(a3, a0, a1, a2, a3) > most:
        best = a3
    return best


@wp.func
def coarse_assemble_tet(
    t: int,
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
    """Row ``t`` of ``coarse_assemble_tets``."""
    w = tet_world[t]
    if world_active[w] == 0:
        return
    idx = tets[t]
    if spare_tet(idx):
        return
    a0 = node_aggregate[idx[0]]
    a1 = node_aggregate[idx[1]]
    a2 = node_aggregate[idx[2]]
    a3 = node_aggregate[idx[3]]
    all_free = free[idx[0]] + free[idx[1]] + free[idx[2]] + free[idx[3]]
    every_axis = all_free[0] + all_free[1] + all_free[2] == 12.0
    if a0 == a1 and a0 == a2 and a0 == a3 and every_axis:
        return
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
    # with every axis free, each column of the tet's Hessian sums to zero over its vertices (a uniform
    # translation strains nothing: b0 + b1 + b2 + b3 = 0), so E[a, c] = -sum over b != c of E[a, b]:
    # only the vertices outside the aggregate c that holds most of the tet's vertices are
    # differentiated, each column added to its own aggregate's block and taken from c's (a rope's
    # straddling tet: 1.3 vertices of 4 on average)
    c = -1
    if every_axis:
        c = most_shared_aggregate(a0, a1, a2, a3)
    for v in range(4):
        bv = pick_vertex(b0, b1, b2, b3, v)
        fv = free[idx[v]]
        av = node_aggregate[idx[v]]
        if av == c:
            continue
        for j in range(3):
            if fv[j] != 0.0:
                e = wp.vec3(0.0)
                e[j] = 1.0
                dp = stress_differential(wp.outer(e, bv), cof, r, twist, mu, lam, v0)
                for u in range(4):
                    bu = pick_vertex(b0, b1, b2, b3, u)
                    col = wp.cw_mul(free[idx[u]], dp * bu)
                    au = node_aggregate[idx[u]]
                    for k in range(3):
                        wp.atomic_add(matrix, w, 3 * au + k, 3 * av + j, wp.float64(col[k]))
                        if c >= 0:
                            wp.atomic_add(matrix, w, 3 * au + k, 3 * c + j, -wp.float64(col[k]))


@wp.kernel
def coarse_assemble_tets(
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
    """E += T^T K_t T for the tets t with nodes in two or more aggregates (or a prescribed axis):
    the tet's 12 unit-vector Hessian products (``stress_differential``), summed into the blocks of
    the aggregates of their nodes."""
    coarse_assemble_tet(wp.tid(), tets, rest_inv, rest_volume, tet_mu, tet_lambda, tet_cof, tet_r, tet_twist,
                        tet_world, world_active, free, node_aggregate, matrix)


@wp.func
def cholesky_pivot(w: int, j: int, matrix: wp.array3d(dtype=wp.float64)):
    """Column ``j``'s pivot of world ``w``'s in-place Cholesky factor (the columns before it done):
    1 and L_jj in ``matrix[w, j, j]``, or 0 (not numerically positive definite; left as it is)."""
    s = matrix[w, j, j]
    for k in range(j):
        s -= matrix[w, j, k] * matrix[w, j, k]
    if not (s > wp.float64(1.0e-12) * matrix[w, j, j]):
        return 0
    matrix[w, j, j] = wp.sqrt(s)
    return 1


@wp.func
def cholesky_entry(w: int, i: int, j: int, matrix: wp.array3d(dtype=wp.float64)):
    """L_ij (i > j) of world ``w``'s in-place Cholesky factor, after column ``j``'s pivot."""
    s = matrix[w, i, j]
    for k in range(j):
        s -= matrix[w, i, k] * matrix[w, j, k]
    matrix[w, i, j] = s / matrix[w, j, j]


@wp.func
def lower_inverse_column(w: int, j: int, size: int, ok: int, matrix: wp.array3d(dtype=wp.float64),
                         lower_inv: wp.array3d(dtype=wp.float64)):
    """Column ``j`` of L^-1 (forward substitution down the column; reads only this column of
    ``lower_inv``), all zero where the factor failed (``ok`` = 0)."""
    for i in range(size):
        lower_inv[w, i, j] = wp.float64(0.0)
    if ok == 1:
        lower_inv[w, j, j] = wp.float64(1.0) / matrix[w, j, j]
        for i in range(j + 1, size):
            s = wp.float64(0.0)
            for k in range(j, i):
                s += matrix[w, i, k] * lower_inv[w, k, j]
            lower_inv[w, i, j] = -s / matrix[w, i, i]


@wp.func
def inverse_entry(w: int, i: int, j: int, size: int, lower_inv: wp.array3d(dtype=wp.float64),
                  inverse: wp.array3d(dtype=wp.float64)):
    """E^-1_ij = E^-1_ji = (L^-T L^-1)_ij for j <= i."""
    s = wp.float64(0.0)
    for k in range(i, size):
        s += lower_inv[w, k, i] * lower_inv[w, k, j]
    inverse[w, i, j] = s
    inverse[w, j, i] = s


@wp.func
def fix_coarse_diagonal(w: int, j: int, matrix: wp.array3d(dtype=wp.float64)):
    """An unknown with no stiffness (an empty aggregate, an axis prescribed on all of its nodes)
    gets a diagonal of 1."""
    if matrix[w, j, j] <= wp.float64(0.0):
        matrix[w, j, j] = wp.float64(1.0)


@wp.func
def coarse_factor_world(
    w: int,
    world_active: wp.array(dtype=int),
    sizes: wp.array(dtype=int),
    matrix: wp.array3d(dtype=wp.float64),
    lower_inv: wp.array3d(dtype=wp.float64),
    inverse: wp.array3d(dtype=wp.float64),
    rhs: wp.array2d(dtype=float),
    coef: wp.array2d(dtype=float),
    rz: wp.array(dtype=float),
):
    """Row ``w`` of ``coarse_factor``: one thread's loops over the entry functions above
    (``coarse_factor_block`` runs the same entries on a block's threads)."""
    if world_active[w] == 0:
        return
    size = sizes[w]
    for j in range(size):
        fix_coarse_diagonal(w, j, matrix)
    ok = int(1)
    for j in range(size):  # Cholesky, in place in the lower triangle
        if ok == 1:
            ok = cholesky_pivot(w, j, matrix)
            if ok == 1:
                for i in range(j + 1, size):
                    cholesky_entry(w, i, j, matrix)
    for j in range(size):  # L^-1 (lower)
        lower_inverse_column(w, j, size, ok, matrix, lower_inv)
    for i in range(size):  # E^-1 = L^-T L^-1 (symmetric by construction)
        for j in range(i + 1):
            inverse_entry(w, i, j, size, lower_inv, inverse)
    for i in range(size):
        for j in range(size):
            matrix[w, i, j] = wp.float64(0.0)
    coarse_coefficients(w, size, inverse, rhs, coef)
    rz[w] = 0.0


@wp.func
def coarse_factor_block(
    w: int,
    lane: int,
    threads: int,
    sizes: wp.array(dtype=int),
    matrix: wp.array3d(dtype=wp.float64),
    lower_inv: wp.array3d(dtype=wp.float64),
    inverse: wp.array3d(dtype=wp.float64),
    rhs: wp.array2d(dtype=float),
    coef: wp.array2d(dtype=float),
    factored: wp.array(dtype=int),
    rz: wp.array(dtype=float),
):
    """``coarse_factor_world`` of an iterating world ``w`` by the ``threads`` threads of its block
    (thread ``lane``; every thread must call it): each entry of the factor, of L^-1 and of E^-1
    computed by the same function in the same order of operations as there, so the same bits.
    Per factor column, thread 0 takes the pivot and
    the threads the entries below it (``factored[w]``: 1 while every pivot so far was positive);
    L^-1 a column per thread, E^-1 an entry per thread, ``coef`` a row per thread. A slender
    object's 24 unknowns on one thread were a serial chain of ~7,800 float64 multiply-adds."""
    size = sizes[w]
    for j in range(lane, size, threads):
        fix_coarse_diagonal(w, j, matrix)
    if lane == 0:
        factored[w] = 1
    block_barrier()
    for j in range(size):  # Cholesky, in place in the lower triangle: a column per pass
        if lane == 0 and factored[w] == 1:
            factored[w] = cholesky_pivot(w, j, matrix)
        block_barrier()
        if factored[w] == 1:
            for i in range(j + 1 + lane, size, threads):
                cholesky_entry(w, i, j, matrix)
        block_barrier()
    ok = factored[w]
    for j in range(lane, size, threads):
        lower_inverse_column(w, j, size, ok, matrix, lower_inv)
    block_barrier()
    for e in range(lane, size * size, threads):
        i = e // size
        j = e - i * size
        if j <= i:
            inverse_entry(w, i, j, size, lower_inv, inverse)
    block_barrier()
    for e in range(lane, size * size, threads):
        matrix[w, e // size, e - (e // size) * size] = wp.float64(0.0)
    for i in range(lane, size, threads):
        coarse_coefficient(w, i, size, inverse, rhs, coef)
    block_barrier()
    for i in range(lane, size, threads):
        rhs[w, i] = 0.0
    if lane == 0:
        rz[w] = 0.0


@wp.kernel
def coarse_factor(
    world_active: wp.array(dtype=int),
    sizes: wp.array(dtype=int),
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
    coarse_factor_world(wp.tid(), world_active, sizes, matrix, lower_inv, inverse, rhs, coef, rz)


@wp.func
def coarse_guess_node(
    i: int,
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    coef: wp.array2d(dtype=float),
    dx: wp.array(dtype=wp.vec3),
    guess: wp.array(dtype=wp.vec3),
):
    """Row ``i`` of ``coarse_guess``."""
    w = node_world[i]
    if world_active[w] == 0:
        return
    d = aggregate_part(coef, w, node_aggregate[i], free[i])
    dx[i] = dx[i] + d
    guess[i] = d


@wp.kernel
def coarse_guess(
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    coef: wp.array2d(dtype=float),
    dx: wp.array(dtype=wp.vec3),
    guess: wp.array(dtype=wp.vec3),
):
    """dx += T coef; guess = T coef (the direction whose A-product ``coarse_start_cg`` subtracts)."""
    coarse_guess_node(wp.tid(), free, node_world, node_aggregate, world_active, coef, dx, guess)


@wp.func
def coarse_start_cg_node(
    i: int,
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
    """Row ``i`` of ``coarse_start_cg``."""
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
    coarse_start_cg_node(wp.tid(), precond, free, node_world, world_active, r, ap, z, p, rz)


@wp.func
def coarse_reduce_node(
    i: int,
    r: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    rhs: wp.array2d(dtype=float),
):
    """Row ``i`` of ``coarse_reduce``."""
    w = node_world[i]
    if world_active[w] == 0:
        return
    add_rhs(rhs, w, node_aggregate[i], r[i])


@wp.kernel
def coarse_reduce(
    r: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    rhs: wp.array2d(dtype=float),
):
    """rhs += T^T r (r masked)."""
    coarse_reduce_node(wp.tid(), r, node_world, node_aggregate, world_active, rhs)


@wp.func
def coarse_solve_world(
    w: int,
    world_active: wp.array(dtype=int),
    sizes: wp.array(dtype=int),
    inverse: wp.array3d(dtype=wp.float64),
    rhs: wp.array2d(dtype=float),
    coef: wp.array2d(dtype=float),
):
    """Row ``w`` of ``coarse_solve``."""
    if world_active[w] == 0:
        return
    coarse_coefficients(w, sizes[w], inverse, rhs, coef)


@wp.kernel
def coarse_solve(
    world_active: wp.array(dtype=int),
    sizes: wp.array(dtype=int),
    inverse: wp.array3d(dtype=wp.float64),
    rhs: wp.array2d(dtype=float),
    coef: wp.array2d(dtype=float),
):
    """coef = E^-1 rhs with the E^-1 of this Newton iteration; clears rhs."""
    coarse_solve_world(wp.tid(), world_active, sizes, inverse, rhs, coef)


@wp.func
def coarse_correct_node(
    i: int,
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    coef: wp.array2d(dtype=float),
    dx: wp.array(dtype=wp.vec3),
):
    """Row ``i`` of ``coarse_correct``."""
    w = node_world[i]
    if world_active[w] == 0:
        return
    dx[i] = dx[i] + aggregate_part(coef, w, node_aggregate[i], free[i])


@wp.kernel
def coarse_correct(
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    coef: wp.array2d(dtype=float),
    dx: wp.array(dtype=wp.vec3),
):
    """dx += T coef."""
    coarse_correct_node(wp.tid(), free, node_world, node_aggregate, world_active, coef, dx)
