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
The pad edge points add T_j^T (w_j w_k B) T_k (``pad_edge_hessian.py``). E is inverted per world
(``coarse_factor.py``).
It is used (a) before CG: dx0 = T E^-1 T^T r, residual r - A dx0, (b) inside CG: the two-level
additive preconditioner z = P r + T E^-1 T^T r (P block Jacobi; SPD, so CG stays CG), and (c) after
CG: dx += T E^-1 T^T r (the best A-norm correction in the coarse space). T^T r is each aggregate's
net force and its torque about the anchor.
A world whose E is not numerically positive definite gets E^-1 = 0 (block Jacobi alone) for that
Newton iteration.
"""

import warp as wp

from .block_memory import shared_add

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


#: dependent float64 sums one thread computes side by side where a world's dense coarse products run on
#: one thread (the CPU: ``coarse_rows_serial``, ``coarse_factor.coarse_invert_serial``), each in its own order
SERIAL_LANES = 4
serial_lanes = wp.types.vector(length=SERIAL_LANES, dtype=wp.float64)


@wp.func
def coarse_rows_serial(w: int, size: int, inverse: wp.array3d(dtype=wp.float64), rhs: wp.array2d(dtype=float),
                       coef: wp.array2d(dtype=float), terms: wp.array2d(dtype=wp.float64)):
    """``coarse_row`` of every row by one thread (a world block of one thread: the CPU),
    ``SERIAL_LANES`` rows at a time: each row's sum in ``coarse_coefficient``'s order (the same
    bits), the rows' dependent chains of float64 multiply-adds overlapped by the core."""
    i = int(0)
    while i + SERIAL_LANES <= size:
        s = serial_lanes()
        for j in range(size):
            g = wp.float64(rhs[w, j])
            for q in range(SERIAL_LANES):
                s[q] = s[q] + inverse[w, i + q, j] * g
        for q in range(SERIAL_LANES):
            coef[w, i + q] = float(s[q])
            terms[w, i + q] = s[q] * wp.float64(rhs[w, i + q])
        i += SERIAL_LANES
    while i < size:
        coarse_row(w, i, size, inverse, rhs, coef, terms)
        i += 1


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
def add_entry(matrix: wp.array3d(dtype=wp.float64), w: int, row: int, col: int, block_size: int, v: wp.float64):
    """E[row, col] += v: world ``w``'s ``matrix``, or the block memory where ``block_size`` > 0 (E there
    row-major with row stride ``block_size``: a world block of several threads, ``world_evaluate``)."""
    if block_size > 0:
        shared_add(row * block_size + col, v)
    else:
        wp.atomic_add(matrix, w, row, col, v)


@wp.func
def add_block(matrix: wp.array3d(dtype=wp.float64), w: int, a: int, b: int, tt: wp.mat33d, tr: wp.mat33d,
              rt: wp.mat33d, rr: wp.mat33d, block_size: int):
    """E[a, b] += [[tt, tr], [rt, rr]] (6 x 6), its entries in E's lower triangle only (a < b: none;
    the transposed block of E[b, a] holds them), by ``add_entry``."""
    if a < b:
        return
    ra = 6 * a
    cb = 6 * b
    for r in range(3):
        for c in range(3):
            if a > b or c <= r:
                add_entry(matrix, w, ra + r, cb + c, block_size, tt[r, c])
                add_entry(matrix, w, ra + 3 + r, cb + 3 + c, block_size, rr[r, c])
            if a > b:
                add_entry(matrix, w, ra + r, cb + 3 + c, block_size, tr[r, c])
            add_entry(matrix, w, ra + 3 + r, cb + c, block_size, rt[r, c])


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
    block_size: int,
):
    """Row ``i`` of ``coarse_assemble_nodes``; E into the block memory where ``block_size`` > 0
    (``add_entry``)."""
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
                add_block(matrix, w, a, aj, ptt, ptr, prt, prr, block_size)
    if others != 0:  # most nodes have none: a rope's interior, any node of a free object's piece
        ott, otr, ort, orr = coarse_pair(fi, li, own, fi, li)
        tt -= ott
        tr -= otr
        rt -= ort
        rr -= orr
    add_block(matrix, w, a, a, tt, tr, rt, rr - wp.skew(wp.vec3d(li)) * bend, block_size)
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
                         inv_dt2, node_blocks, block_node, hessian_values, r, lever, matrix, rhs, 0)


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
