"""The elastic Hessian as 3 x 3 blocks per node row (``sim/hessian_blocks.py``): assembled once per
Newton iteration, then multiplied row by row in CG.

Tet t's Hessian (``elastic.stress_differential``: shear with the fraction k = (1 - c) / 2 of the
rotations removed, c the tet's twist factor, plus the volume term) couples its vertices a and b by

    K_ab = V0 [ 2 mu (1 - k) (b_a . b_b) I + 2 mu k (R b_b)(R b_a)^T + lam (cof b_a)(cof b_b)^T ],

b_a the shape-function gradients (rows of D_m^-1, b_0 = -(b_1 + b_2 + b_3)), R the tet's rotation
and cof its cofactor matrix at the iterate: K_ab d is the force change of vertex a when vertex b
moves by d (``stress_differential`` of dF = d b_b^T, times b_a), and K_ba = K_ab^T. Node i's row
sums K_ab over its incidences (tet t, vertex a) into the blocks of the columns b != a; a product is
then a gather, y_i = sum_{j != i} K_ij (p_j - p_i) (the diagonal block is minus the others' sum),
with no scattered writes. Each row is written by one thread, in the
same order on every device, so the assembly is deterministic on a GPU too.
"""

import warp as wp

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})

from .elastic import pick_vertex, row


@wp.func
def assemble_hessian_row(
    i: int,
    node_world: wp.array(dtype=int),
    active: wp.array(dtype=int),
    node_blocks: wp.array(dtype=wp.vec2i),
    node_incidences: wp.array(dtype=wp.vec2i),
    incidence: wp.array(dtype=int),
    incidence_blocks: wp.array(dtype=wp.vec4i),
    rest_inv: wp.array(dtype=wp.mat33),
    rest_volume: wp.array(dtype=float),
    tet_mu: wp.array(dtype=float),
    tet_lambda: wp.array(dtype=float),
    tet_cof: wp.array(dtype=wp.mat33),
    tet_r: wp.array(dtype=wp.mat33),
    tet_twist: wp.array(dtype=float),
    values: wp.array(dtype=wp.mat33),
):
    """Node ``i``'s row of the elastic Hessian into ``values`` (cleared first), from its tets'
    stored cofactor, rotation and twist factor (``elastic.evaluate_tet`` of this iterate)."""
    if active[node_world[i]] == 0:
        return
    span = node_blocks[i]
    for k in range(span[0], span[1]):
        values[k] = wp.mat33(0.0)
    inc = node_incidences[i]
    for q in range(inc[0], inc[1]):
        code = incidence[q]
        t = code // 4
        a = code - 4 * t
        dm_inv = rest_inv[t]
        b1 = row(dm_inv, 0)
        b2 = row(dm_inv, 1)
        b3 = row(dm_inv, 2)
        b0 = -(b1 + b2 + b3)
        r = tet_r[t]
        cof = tet_cof[t]
        twist_part = 0.5 * (1.0 - tet_twist[t])
        shear = 2.0 * rest_volume[t] * tet_mu[t]
        c_iso = shear * (1.0 - twist_part)
        c_rot = shear * twist_part
        c_vol = rest_volume[t] * tet_lambda[t]
        ba = pick_vertex(b0, b1, b2, b3, a)
        ga = r * ba
        ha = c_vol * (cof * ba)
        slots = incidence_blocks[q]
        for b in range(4):
            if b != a:
                bb = pick_vertex(b0, b1, b2, b3, b)
                values[slots[b]] += (c_iso * wp.dot(ba, bb)) * wp.identity(n=3, dtype=float) + wp.outer(
                    c_rot * (r * bb), ga) + wp.outer(ha, cof * bb)


@wp.func
def hessian_row_product(i: int, p: wp.array(dtype=wp.vec3), node_blocks: wp.array(dtype=wp.vec2i),
                        block_node: wp.array(dtype=int), values: wp.array(dtype=wp.mat33)):
    """(K p)_i: node ``i``'s row of the assembled elastic Hessian times ``p``, as the sum over its
    neighbours j of K_ij (p_j - p_i) (the row sums to zero: a rigid translation gives exactly 0).
    Four blocks a pass, their loads issued before their sums, added in the row's order: the same
    bits as a block at a time, and on a GPU a lone world's product waits on memory less (H100, a
    rope's CG iteration 108 -> 68 k cycles, its product 71 -> 37 k; the cuboid's unchanged:
    benchmarks/RESULTS.md, 2026-12-07)."""
    span = node_blocks[i]
    pi = p[i]
    s = wp.vec3(0.0)
    k = span[0]
    while k + 4 <= span[1]:
        j0 = block_node[k]
        j1 = block_node[k + 1]
        j2 = block_node[k + 2]
        j3 = block_node[k + 3]
        v0 = values[k]
        v1 = values[k + 1]
        v2 = values[k + 2]
        v3 = values[k + 3]
        d0 = p[j0] - pi
        d1 = p[j1] - pi
        d2 = p[j2] - pi
        d3 = p[j3] - pi
        s += v0 * d0
        s += v1 * d1
        s += v2 * d2
        s += v3 * d3
        k += 4
    while k < span[1]:
        s += values[k] * (p[block_node[k]] - pi)
        k += 1
    return s


@wp.kernel
def assemble_hessian_rows(
    node_world: wp.array(dtype=int),
    active: wp.array(dtype=int),
    node_blocks: wp.array(dtype=wp.vec2i),
    node_incidences: wp.array(dtype=wp.vec2i),
    incidence: wp.array(dtype=int),
    incidence_blocks: wp.array(dtype=wp.vec4i),
    rest_inv: wp.array(dtype=wp.mat33),
    rest_volume: wp.array(dtype=float),
    tet_mu: wp.array(dtype=float),
    tet_lambda: wp.array(dtype=float),
    tet_cof: wp.array(dtype=wp.mat33),
    tet_r: wp.array(dtype=wp.mat33),
    tet_twist: wp.array(dtype=float),
    values: wp.array(dtype=wp.mat33),
):
    """``assemble_hessian_row`` of every node of the ``active`` worlds."""
    assemble_hessian_row(wp.tid(), node_world, active, node_blocks, node_incidences, incidence, incidence_blocks,
                         rest_inv, rest_volume, tet_mu, tet_lambda, tet_cof, tet_r, tet_twist, values)
