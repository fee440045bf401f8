"""Pad edge contact's lag (``pad_edge_contact.py`` has the whole contact): for each (world, pad edge
point), after the search (``pad_edge_search.py``), the triangle the substep holds it against, its
barycentric weights, outward normal, stiffness, the depth the point may keep and its friction's
lagged normal force; none where the object wraps the pad there or the point lies beside the object.
"""

import warp as wp

from .contact import penalty_force
from .pad_edge_contact import RECOVERY_KNEES, SKIN_KNEES, edge_point_depth, edge_point_end
from .pad_edge_search import NO_TRIANGLE, closest_point_barycentric
from .surface_query import winding_number

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


@wp.func
def lag_edge_point(
    slot: int,
    x_start: wp.array(dtype=wp.vec3),
    x_guess: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    triangle_first: wp.array(dtype=int),
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    points: wp.array(dtype=wp.vec3),
    point_pad: wp.array(dtype=int),
    point_share: wp.array(dtype=float),
    points_per_world: int,
    stiffness: wp.array(dtype=float),
    lag_normal_force: wp.array(dtype=float),
    lag_normal: wp.array(dtype=wp.vec3),
    best_tri: wp.array(dtype=int),
    point_tri: wp.array(dtype=int),
    point_bary: wp.array(dtype=wp.vec3),
    point_normal: wp.array(dtype=wp.vec3),
    point_stiffness: wp.array(dtype=float),
    point_allowed: wp.array(dtype=float),
    point_friction: wp.array(dtype=float),
    knee: float,
):
    """For each (world, point): the triangle the search chose (-1: none, or where the object wraps
    the point's pad there: see below; ``lag_normal_force``, ``lag_normal`` [N*(P+1)]: the nodes'
    pad contacts at the substep start, ``contact.lag_contacts``), the barycentric weights
    of its point nearest to the edge point (both where the search measured them: the guess, the
    pad's end pose), its outward unit normal (world frame) and the contact's stiffness (N/m),
    and the depth the point may keep (m): its depth at the substep start (nodes at ``x_start``,
    pad pose 0) less one penalty knee, or the free skin, whichever is larger; all held for the
    substep. A point deeper than the skin at the start (it met a triangle that a node touching the
    pad kept from it, or a solve stopped unconverged) is pushed out by at most a knee per substep,
    not at once (pushed out at once, a pad swept at 2 m/s into a soft cuboid read 1 kN). A point
    deeper than the skin at the start that lies outside the object there (the winding number of its
    world's surface, ``triangle_first`` [W+1]: ``surface_query.winding_number``, one pass over the
    world's triangles for every point deeper than the skin, so for every pressed point of a held
    grasp) gets no contact: it sits beside the object off a convex edge, behind the extended plane
    of a face it does not touch, which its kept depth would otherwise push a knee's worth every
    substep (a learner's pad hanging past a cube's edge, 7-12 mm behind the top face's plane). Also the
    normal force (N) its friction is lagged on: the penalty force of its start depth beyond the
    depth it may keep (a held point's load: its start depth is its kept depth plus its load depth;
    at most a knee's worth, so less than the load of a point deeper than that, pushed back out).
    Slot ``slot`` (world ``slot // points_per_world``) of ``lag_edge_points``."""
    w = slot // points_per_world
    q = slot % points_per_world
    t = best_tri[slot]
    if t == NO_TRIANGLE:
        point_tri[slot] = -1
        return
    k_pad = point_pad[q]
    pad = w * pads_per_world + k_pad
    ids = triangles[t]
    xa = x_guess[ids[0]]
    xb = x_guess[ids[1]]
    xc = x_guess[ids[2]]
    p = edge_point_end(q, w, pads_per_world, points, point_pad, pad_pos1, pad_rot1, pad_half)
    bary = closest_point_barycentric(xa, xb, xc, p)
    cross = wp.cross(xb - xa, xc - xa)
    area2 = wp.length(cross)
    if area2 <= 0.0:  # a degenerate triangle has no normal: no contact through it
        point_tri[slot] = -1
        return
    n = cross / area2
    # where the object wraps this pad (the triangle's nodes touch it on two faces, or on a face
    # that the triangle does not face) the nodes' contacts hold it, and pushing the triangle out
    # of the pad's edge would push those nodes into the pad
    slots = pads_per_world + 1
    face = wp.vec3(0.0)
    for j in range(3):
        c = ids[j] * slots + 1 + k_pad
        if lag_normal_force[c] > 0.0:
            f = wp.quat_rotate(pad_rot1[pad], lag_normal[c])
            if wp.dot(n, f) >= 0.0 or (wp.length(face) > 0.0 and wp.dot(face, f) < 0.5):
                point_tri[slot] = -1
                return
            face = f
    q0 = pad_pos0[pad] + wp.quat_rotate(pad_rot0[pad], wp.cw_mul(points[q], pad_half[pad]))
    start = edge_point_depth(x_start, ids, bary, n, q0)
    skin = SKIN_KNEES * knee
    if start > skin:
        # behind the triangle's plane beyond the skin at the start: in the object, or beside it (off
        # a convex edge, behind the extended plane of a face), where it touches nothing. Projecting
        # inside the triangle does not tell: at a convex edge the triangle's prism runs along the
        # next face, and a tilted or bulged face puts it outside (tried: 3 pierced readings and
        # other episodes in the 64 of the CPU evaluation)
        if winding_number(x_start, triangles, triangle_first[w], triangle_first[w + 1], q0) <= 0.5:
            point_tri[slot] = -1
            return
    mean_edge = (wp.length(xb - xa) + wp.length(xc - xb) + wp.length(xa - xc)) / 3.0
    k = bary[0] * stiffness[ids[0]] + bary[1] * stiffness[ids[1]] + bary[2] * stiffness[ids[2]]
    point_tri[slot] = t
    point_bary[slot] = bary
    point_normal[slot] = n
    point_stiffness[slot] = k * point_share[q] / mean_edge
    allowed = wp.max(start - RECOVERY_KNEES * knee, skin)
    point_allowed[slot] = allowed
    point_friction[slot] = 0.0
    if start > allowed:
        point_friction[slot] = penalty_force(point_stiffness[slot], start - allowed, knee)


@wp.kernel
def lag_edge_points(
    x_start: wp.array(dtype=wp.vec3),
    x_guess: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    triangle_first: wp.array(dtype=int),
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    points: wp.array(dtype=wp.vec3),
    point_pad: wp.array(dtype=int),
    point_share: wp.array(dtype=float),
    points_per_world: int,
    stiffness: wp.array(dtype=float),
    lag_normal_force: wp.array(dtype=float),
    lag_normal: wp.array(dtype=wp.vec3),
    best_tri: wp.array(dtype=int),
    point_tri: wp.array(dtype=int),
    point_bary: wp.array(dtype=wp.vec3),
    point_normal: wp.array(dtype=wp.vec3),
    point_stiffness: wp.array(dtype=float),
    point_allowed: wp.array(dtype=float),
    point_friction: wp.array(dtype=float),
    knee: float,
):
    """``lag_edge_point`` for every (world, point) slot."""
    lag_edge_point(wp.tid(), x_start, x_guess, triangles, triangle_first, pad_pos0, pad_rot0, pad_pos1, pad_rot1,
                   pad_half, pads_per_world, points, point_pad, point_share, points_per_world, stiffness,
                   lag_normal_force, lag_normal, best_tri, point_tri, point_bary, point_normal, point_stiffness,
                   point_allowed, point_friction, knee)
