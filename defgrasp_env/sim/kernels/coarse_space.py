"""Coarse space of the per-world linear solves: the rigid motions of node aggregates.

Block-Jacobi CG barely moves the smooth, long-wavelength modes of a Newton system A dx = r: the
rigid motions of a stiff object (their stiffness, the mass term m/h^2 and the contacts, is ~1e5
times below the elastic one) and the bending of a slender one (a rope: CG needs ~ its length in
elements of iterations to carry a correction from end to end). Every world's nodes are split into at
most K aggregates (``sim/aggregates.py``); T [3N x 6K] holds the six rigid motions of each aggregate
a: node i of a moves by T_i c_a = F_i (t_a + omega_a x l_i), a translation t_a and a small rotation
omega_a about the aggregate's anchor node (``Model.node_anchor``), with l_i = x_i - x_anchor at the
Newton iterate (``lever``, written by the assembly) and F_i the diagonal of its free axes. Unknown
6 a + k: the translation along axis k (k < 3) or the rotation about axis k - 3.
Per Newton iteration the coarse matrix E = T^T A T (6K x 6K, float64, its lower triangle: all that
the Cholesky factor reads) is assembled node row by node row: the node terms T_i^T (m/h^2 + contact
block) T_i, and the elastic Hessian's assembled rows (``hessian_blocks.py``: (K p)_i = sum over
j != i of K_ij (p_j - p_i)) as T_i^T K_ij T_j into E[a(i), a(j)] and -T_i^T K_ij T_i into
E[a(i), a(i)]; within one aggregate, with every axis free, the two together are T_i^T K_ij (T_j - T_i),
whose lower parts are exactly 0 in the translation rows and -[l_i]x K_ij [x_j - x_i]x in the
rotation-rotation block (its translation-rotation part, -K_ij [x_j - x_i]x, lies in the upper
triangle, which is not stored; summed over the object it is 0, as K annihilates translations).
The pad edge points add T_j^T (w_j w_k B) T_k (``pad_edge_hessian.py``). E is Cholesky-factored and
inverted per world.
It is used (a) before CG: dx0 = T E^-1 T^T r, residual r - A dx0, (b) inside CG: the two-level
additive preconditioner z = P r + T E^-1 T^T r (P block Jacobi; SPD, so CG stays CG), and (c) after
CG: dx += T E^-1 T^T r (the best A-norm correction in the coarse space). T^T r is each aggregate's
net force and its torque about the anchor.
A world whose E is not numerically positive definite gets E^-1 = 0 (block Jacobi alone) for that
Newton iteration.
"""

import warp as wp

from .block_sync import block_barrier

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})

#: Coarse unknowns per aggregate: three translations, three rotations.
AGGREGATE_UNKNOWNS = 6


@wp.func
def aggregate_part(coef: wp.array2d(dtype=float), w: int, a: int, lever: wp.vec3, free: wp.vec3):
    """(T coef)_i = F_i (t_a + omega_a x l_i) for a node of aggregate ``a`` of world ``w`` with lever
    ``lever`` (m) and free axes ``free``."""
    b = 6 * a
    t = wp.vec3(coef[w, b], coef[w, b + 1], coef[w, b + 2])
    omega = wp.vec3(coef[w, b + 3], coef[w, b + 4], coef[w, b + 5])
    return wp.cw_mul(free, t + wp.cross(omega, lever))


@wp.func
def add_rhs(rhs: wp.array2d(dtype=float), w: int, a: int, lever: wp.vec3, v: wp.vec3):
    """rhs_a += T_i^T v for a node of aggregate ``a`` with lever ``lever`` and ``v`` already masked
    by its free axes: the force v and its torque l_i x v."""
    b = 6 * a
    m = wp.cross(lever, v)
    wp.atomic_add(rhs, w, b, v[0])
    wp.atomic_add(rhs, w, b + 1, v[1])
    wp.atomic_add(rhs, w, b + 2, v[2])
    wp.atomic_add(rhs, w, b + 3, m[0])
    wp.atomic_add(rhs, w, b + 4, m[1])
    wp.atomic_add(rhs, w, b + 5, m[2])


@wp.func
def node_lever(i: int, x: wp.array(dtype=wp.vec3), anchor: wp.array(dtype=int)):
    """l_i = x_i - x of its aggregate's anchor node (m)."""
    return x[i] - x[anchor[i]]


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
def all_free(f: wp.vec3):
    """Whether a node's three axes are free (``f``: its free-axes mask)."""
    return f[0] + f[1] + f[2] == 3.0


@wp.func
def coarse_pair(fu: wp.vec3, lu: wp.vec3, block: wp.mat33d, fv: wp.vec3, lv: wp.vec3):
    """T_u^T X T_v for nodes u, v (free axes ``fu``/``fv``, levers ``lu``/``lv``) and a 3 x 3 block
    X: its four 3 x 3 parts (translation-translation, translation-rotation, rotation-translation,
    rotation-rotation), float64. T_u = [F_u, -F_u [l_u]x], so T_u^T = [F_u; [l_u]x F_u]."""
    xf = wp.diag(wp.vec3d(fu)) * block * wp.diag(wp.vec3d(fv))
    su = wp.skew(wp.vec3d(lu))
    sv = wp.skew(wp.vec3d(lv))
    return xf, -(xf * sv), su * xf, -(su * xf * sv)


@wp.func
def add_block(matrix: wp.array3d(dtype=wp.float64), w: int, a: int, b: int, tt: wp.mat33d, tr: wp.mat33d,
              rt: wp.mat33d, rr: wp.mat33d):
    """E[a, b] += [[tt, tr], [rt, rr]] (6 x 6), its entries in E's lower triangle only (a < b: none;
    the transposed block of E[b, a] holds them)."""
    if a < b:
        return
    ra = 6 * a
    cb = 6 * b
    for r in range(3):
        for c in range(3):
            if a > b or c <= r:
                wp.atomic_add(matrix, w, ra + r, cb + c, tt[r, c])
                wp.atomic_add(matrix, w, ra + 3 + r, cb + 3 + c, rr[r, c])
            if a > b:
                wp.atomic_add(matrix, w, ra + r, cb + 3 + c, tr[r, c])
            wp.atomic_add(matrix, w, ra + 3 + r, cb + c, rt[r, c])


@wp.func
def coarse_assemble_node(
    i: int,
    x: wp.array(dtype=wp.vec3),
    anchor: wp.array(dtype=int),
    mass: wp.array(dtype=float),
    contact_hessian: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    inv_dt2: float,
    node_blocks: wp.array(dtype=wp.vec2i),
    block_node: wp.array(dtype=int),
    hessian_values: wp.array(dtype=wp.mat33),
    r: wp.array(dtype=wp.vec3),
    lever: wp.array(dtype=wp.vec3),
    matrix: wp.array3d(dtype=wp.float64),
    rhs: wp.array2d(dtype=float),
):
    """Row ``i`` of ``coarse_assemble_nodes``."""
    w = node_world[i]
    if world_active[w] == 0:
        return
    a = node_aggregate[i]
    fi = free[i]
    li = node_lever(i, x, anchor)
    lever[i] = li
    d = mass[i] * inv_dt2 * wp.identity(n=3, dtype=float) + contact_hessian[i]
    tt, tr, rt, rr = coarse_pair(fi, li, wp.mat33d(d), fi, li)
    bend = wp.mat33d(0.0)  # sum of K_ij [x_j - x_i]x over the all-free neighbours in aggregate a
    own = wp.mat33d(0.0)   # sum of K_ij over the others: -T_i^T K_ij T_i
    others = int(0)
    free_row = all_free(fi)
    span = node_blocks[i]
    for k in range(span[0], span[1]):
        j = block_node[k]
        kij = wp.mat33d(hessian_values[k])
        aj = node_aggregate[j]
        fj = free[j]
        if aj == a and free_row and all_free(fj):
            bend += kij * wp.skew(wp.vec3d(x[j] - x[i]))
        else:
            own += kij
            others = 1
            ptt, ptr, prt, prr = coarse_pair(fi, li, kij, fj, node_lever(j, x, anchor))
            if aj == a:
                tt += ptt
                tr += ptr
                rt += prt
                rr += prr
            else:
                add_block(matrix, w, a, aj, ptt, ptr, prt, prr)
    if others != 0:  # most nodes have none: a rope's interior, any node of a free object's piece
        ott, otr, ort, orr = coarse_pair(fi, li, own, fi, li)
        tt -= ott
        tr -= otr
        rt -= ort
        rr -= orr
    add_block(matrix, w, a, a, tt, tr, rt, rr - wp.skew(wp.vec3d(li)) * bend)
    add_rhs(rhs, w, a, li, r[i])


@wp.kernel
def coarse_assemble_nodes(
    x: wp.array(dtype=wp.vec3),
    anchor: wp.array(dtype=int),
    mass: wp.array(dtype=float),
    contact_hessian: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    inv_dt2: float,
    node_blocks: wp.array(dtype=wp.vec2i),
    block_node: wp.array(dtype=int),
    hessian_values: wp.array(dtype=wp.mat33),
    r: wp.array(dtype=wp.vec3),
    lever: wp.array(dtype=wp.vec3),
    matrix: wp.array3d(dtype=wp.float64),
    rhs: wp.array2d(dtype=float),
):
    """E += T^T (M/h^2 + contact blocks + elastic Hessian) T (lower triangle; the elastic Hessian's
    rows assembled at this iterate, ``hessian_blocks.py``), rhs += T^T r (r already masked), and
    each node's lever l_i = x_i - x_anchor at the iterate ``x`` (what T applies until the next
    assembly)."""
    coarse_assemble_node(wp.tid(), x, anchor, mass, contact_hessian, free, node_world, node_aggregate, world_active,
                         inv_dt2, node_blocks, block_node, hessian_values, r, lever, matrix, rhs)


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
    L^-1 a column per thread, E^-1 an entry per thread, ``coef`` a row per thread (a rope's 24
    unknowns of the translation coarse space on one thread were a serial chain of ~7,800 float64
    multiply-adds; 48 now)."""
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
    lever: wp.array(dtype=wp.vec3),
    coef: wp.array2d(dtype=float),
    dx: wp.array(dtype=wp.vec3),
    guess: wp.array(dtype=wp.vec3),
):
    """Row ``i`` of ``coarse_guess``."""
    w = node_world[i]
    if world_active[w] == 0:
        return
    d = aggregate_part(coef, w, node_aggregate[i], lever[i], free[i])
    dx[i] = dx[i] + d
    guess[i] = d


@wp.kernel
def coarse_guess(
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    lever: wp.array(dtype=wp.vec3),
    coef: wp.array2d(dtype=float),
    dx: wp.array(dtype=wp.vec3),
    guess: wp.array(dtype=wp.vec3),
):
    """dx += T coef; guess = T coef (the direction whose A-product ``coarse_start_cg`` subtracts)."""
    coarse_guess_node(wp.tid(), free, node_world, node_aggregate, world_active, lever, coef, dx, guess)


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
    lever: wp.array(dtype=wp.vec3),
    rhs: wp.array2d(dtype=float),
):
    """Row ``i`` of ``coarse_reduce``."""
    w = node_world[i]
    if world_active[w] == 0:
        return
    add_rhs(rhs, w, node_aggregate[i], lever[i], r[i])


@wp.kernel
def coarse_reduce(
    r: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    lever: wp.array(dtype=wp.vec3),
    rhs: wp.array2d(dtype=float),
):
    """rhs += T^T r (r masked)."""
    coarse_reduce_node(wp.tid(), r, node_world, node_aggregate, world_active, lever, rhs)


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
    lever: wp.array(dtype=wp.vec3),
    coef: wp.array2d(dtype=float),
    dx: wp.array(dtype=wp.vec3),
):
    """Row ``i`` of ``coarse_correct``."""
    w = node_world[i]
    if world_active[w] == 0:
        return
    dx[i] = dx[i] + aggregate_part(coef, w, node_aggregate[i], lever[i], free[i])


@wp.kernel
def coarse_correct(
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    node_aggregate: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    lever: wp.array(dtype=wp.vec3),
    coef: wp.array2d(dtype=float),
    dx: wp.array(dtype=wp.vec3),
):
    """dx += T coef."""
    coarse_correct_node(wp.tid(), free, node_world, node_aggregate, world_active, lever, coef, dx)
