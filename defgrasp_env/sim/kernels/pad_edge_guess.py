"""Pad edge contact's initial guess (``pad_edge_contact.py`` has the whole contact): where the pad's
motion over a substep takes an edge point deeper than it may be, its triangle's nodes that touch no
pad are moved out by the largest such excess before Newton starts (after ``contact.keep_pad_depth``,
which does the same for nodes touching a pad face).
"""

import warp as wp

from .pad_edge_contact import edge_point_depth, edge_point_end

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


@wp.kernel
def clear_triangle_push(push: wp.array(dtype=float)):
    """Start the initial guess's fix: no triangle needs a push yet."""
    push[wp.tid()] = 0.0


@wp.func
def edge_point_push_slot(
    slot: int,
    x_start: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    solve: wp.array(dtype=int),
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    points: wp.array(dtype=wp.vec3),
    point_pad: wp.array(dtype=int),
    points_per_world: int,
    point_tri: wp.array(dtype=int),
    point_bary: wp.array(dtype=wp.vec3),
    point_normal: wp.array(dtype=wp.vec3),
    point_allowed: wp.array(dtype=float),
    x: wp.array(dtype=wp.vec3),
    push: wp.array(dtype=float),
    push_normal: wp.array(dtype=wp.vec3),
):
    """Initial Newton guess, pass 1 (after ``contact.keep_pad_depth``): how far (m) each triangle
    must move along -n so that none of its edge points ends the pad's motion deeper than it may be
    (``point_allowed``) or than it was at the substep start (nodes at ``x_start``, pad pose 0),
    whichever is deeper: the largest excess of its points (atomic maximum), and its normal (every
    point of a triangle holds the same one). A point pressed at the start keeps its depth, as a
    node touching a pad does (``keep_pad_depth``): pushed out to its kept depth, a held grasp's
    triangles were pushed out by their points' load depth in every substep and Newton needed four
    iterations to press them back. Slot ``slot`` of ``edge_point_push``."""
    w = slot // points_per_world
    t = point_tri[slot]
    if t < 0 or solve[w] == 0:
        return
    q = slot % points_per_world
    n = point_normal[slot]
    ids = triangles[t]
    bary = point_bary[slot]
    q1 = edge_point_end(q, w, pads_per_world, points, point_pad, pad_pos1, pad_rot1, pad_half)
    pad = w * pads_per_world + point_pad[q]
    q0 = pad_pos0[pad] + wp.quat_rotate(pad_rot0[pad], wp.cw_mul(points[q], pad_half[pad]))
    keep = wp.max(point_allowed[slot], edge_point_depth(x_start, ids, bary, n, q0))
    excess = edge_point_depth(x, ids, bary, n, q1) - keep
    if excess > 0.0:
        wp.atomic_max(push, t, excess)
        push_normal[t] = n


@wp.kernel
def edge_point_push(
    x_start: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    solve: wp.array(dtype=int),
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    points: wp.array(dtype=wp.vec3),
    point_pad: wp.array(dtype=int),
    points_per_world: int,
    point_tri: wp.array(dtype=int),
    point_bary: wp.array(dtype=wp.vec3),
    point_normal: wp.array(dtype=wp.vec3),
    point_allowed: wp.array(dtype=float),
    x: wp.array(dtype=wp.vec3),
    push: wp.array(dtype=float),
    push_normal: wp.array(dtype=wp.vec3),
):
    """``edge_point_push_slot`` for every (world, point) slot."""
    edge_point_push_slot(wp.tid(), x_start, triangles, solve, pad_pos0, pad_rot0, pad_pos1, pad_rot1, pad_half,
                         pads_per_world, points, point_pad, points_per_world, point_tri, point_bary, point_normal,
                         point_allowed, x, push, push_normal)


@wp.func
def push_triangle(
    t: int,
    triangles: wp.array(dtype=wp.vec3i),
    triangle_world: wp.array(dtype=int),
    solve: wp.array(dtype=int),
    free: wp.array(dtype=wp.vec3),
    lag_normal_force: wp.array(dtype=float),
    pads_per_world: int,
    push: wp.array(dtype=float),
    push_normal: wp.array(dtype=wp.vec3),
    x: wp.array(dtype=wp.vec3),
):
    """Initial Newton guess, pass 2: move each pushed triangle's nodes along -n by its push (free
    axes only), as nodes touching a pad face are put on it; a node that touches a pad or the ground
    at the substep start stays where ``contact.keep_pad_depth`` put it. Without this a pad corner
    driven at 2 m/s into a stiff cuboid starts Newton ~6 mm deep and the cubic penalty's force
    throws the object. A node shared by pushed triangles moves by the sum of their pushes (the
    same on every device: a guess only). Triangle ``t``'s row of ``push_triangles``."""
    d = push[t]
    if d <= 0.0 or solve[triangle_world[t]] == 0:
        return
    ids = triangles[t]
    slots = pads_per_world + 1
    for j in range(3):
        touching = int(0)
        for k in range(slots):
            if lag_normal_force[ids[j] * slots + k] > 0.0:
                touching = 1
        if touching == 0:
            wp.atomic_add(x, ids[j], -d * wp.cw_mul(free[ids[j]], push_normal[t]))


@wp.kernel
def push_triangles(
    triangles: wp.array(dtype=wp.vec3i),
    triangle_world: wp.array(dtype=int),
    solve: wp.array(dtype=int),
    free: wp.array(dtype=wp.vec3),
    lag_normal_force: wp.array(dtype=float),
    pads_per_world: int,
    push: wp.array(dtype=float),
    push_normal: wp.array(dtype=wp.vec3),
    x: wp.array(dtype=wp.vec3),
):
    """``push_triangle`` for every surface triangle."""
    push_triangle(wp.tid(), triangles, triangle_world, solve, free, lag_normal_force, pads_per_world, push,
                  push_normal, x)
