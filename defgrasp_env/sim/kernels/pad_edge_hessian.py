"""The pad edge points' Hessian in CG and in the coarse space (``pad_edge_contact.py`` evaluates
the points and keeps each point's 3x3 block B): products ``ap += H p`` with the whole Hessian of a
point's terms, H = (w w^T) x B over its triangle's nodes (weights w), and its blocks in the coarse
matrix T^T H T."""

import warp as wp

from .coarse_space import add_block, coarse_pair, node_lever
from .world_rows import RowMap, mapped_row

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


@wp.func
def edge_point_slot_product(
    slot: int,
    p: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    cg_active: wp.array(dtype=int),
    points_per_world: int,
    point_tri: wp.array(dtype=int),
    point_bary: wp.array(dtype=wp.vec3),
    point_block: wp.array(dtype=wp.mat33),
    ap: wp.array(dtype=wp.vec3),
):
    """ap += H p for the edge point in ``slot`` (``edge_point_product``)."""
    t = point_tri[slot]
    if t < 0 or cg_active[slot // points_per_world] == 0:
        return
    block = point_block[slot]
    if wp.ddot(block, block) == 0.0:  # neither pressed nor rubbing
        return
    ids = triangles[t]
    bary = point_bary[slot]
    along = block * (bary[0] * p[ids[0]] + bary[1] * p[ids[1]] + bary[2] * p[ids[2]])
    for j in range(3):
        wp.atomic_add(ap, ids[j], bary[j] * along)


@wp.kernel
def edge_point_product(
    p: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    cg_active: wp.array(dtype=int),
    points_per_world: int,
    point_tri: wp.array(dtype=int),
    point_bary: wp.array(dtype=wp.vec3),
    point_block: wp.array(dtype=wp.mat33),
    ap: wp.array(dtype=wp.vec3),
    rows: RowMap,
):
    """ap += H p for the edge points' Hessians H = (w w^T) x B (node j, k: w_j w_k B; B from
    ``evaluate_edge_points``: the surface point is affine in the triangle's nodes, so this is the
    whole Hessian of its terms), before ``linear_solve.cg_node_product`` masks ap and adds the
    node terms; for the slots of ``rows`` (``world_rows.py``)."""
    slot = mapped_row(rows, wp.tid())
    if slot < 0:
        return
    edge_point_slot_product(slot, p, triangles, cg_active, points_per_world, point_tri, point_bary, point_block, ap)


@wp.func
def coarse_assemble_edge_point(
    slot: int,
    triangles: wp.array(dtype=wp.vec3i),
    world_active: wp.array(dtype=int),
    points_per_world: int,
    point_tri: wp.array(dtype=int),
    point_bary: wp.array(dtype=wp.vec3),
    point_block: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_aggregate: wp.array(dtype=int),
    x: wp.array(dtype=wp.vec3),
    anchor: wp.array(dtype=int),
    matrix: wp.array3d(dtype=wp.float64),
    block_size: int,
):
    """Row ``slot`` of ``coarse_assemble_edge_points``; E into the block memory where ``block_size`` > 0
    (``coarse_space.add_entry``)."""
    w = slot // points_per_world
    t = point_tri[slot]
    if t < 0 or world_active[w] == 0:
        return
    block = point_block[slot]
    if wp.ddot(block, block) == 0.0:  # neither pressed nor rubbing
        return
    ids = triangles[t]
    bary = point_bary[slot]
    for j in range(3):
        nj = ids[j]
        lj = node_lever(nj, x, anchor)
        for k in range(3):
            nk = ids[k]
            part = wp.mat33d((bary[j] * bary[k]) * block)
            tt, tr, rt, rr = coarse_pair(free[nj], lj, part, free[nk], node_lever(nk, x, anchor))
            add_block(matrix, w, node_aggregate[nj], node_aggregate[nk], tt, tr, rt, rr, block_size)


@wp.kernel
def coarse_assemble_edge_points(
    triangles: wp.array(dtype=wp.vec3i),
    world_active: wp.array(dtype=int),
    points_per_world: int,
    point_tri: wp.array(dtype=int),
    point_bary: wp.array(dtype=wp.vec3),
    point_block: wp.array(dtype=wp.mat33),
    free: wp.array(dtype=wp.vec3),
    node_aggregate: wp.array(dtype=int),
    x: wp.array(dtype=wp.vec3),
    anchor: wp.array(dtype=int),
    matrix: wp.array3d(dtype=wp.float64),
):
    """E += T^T H T for the edge points' Hessians (``edge_point_product``): block
    T_j^T (w_j w_k B) T_k between the aggregates of nodes j and k (``coarse_space.coarse_pair``: the
    rigid motions of their aggregates, levers at the iterate ``x``; E's lower triangle)."""
    coarse_assemble_edge_point(wp.tid(), triangles, world_active, points_per_world, point_tri, point_bary,
                               point_block, free, node_aggregate, x, anchor, matrix, 0)
