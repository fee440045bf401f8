"""Pad edge contact's search (``pad_edge_contact.py`` has the whole contact): for each pad edge
point of each world, the surface triangle of its world nearest to it where the substep takes both,
facing the pad, in two passes of an atomic minimum (distance, then the lowest triangle id at that
distance), so the choice is deterministic on every device.
"""

import warp as wp

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})

#: Search radius (m) beyond the motion of the point and the triangle over a substep.
SEARCH_MARGIN = 2.0e-3
#: "No triangle found" for the search's atomic minimum of the triangle id.
NO_TRIANGLE = 2147483647


@wp.func
def closest_point_barycentric(a: wp.vec3, b: wp.vec3, c: wp.vec3, p: wp.vec3):
    """Barycentric weights (of a, b, c) of the point of triangle abc nearest to p (Ericson,
    Real-Time Collision Detection, 5.1.5: the Voronoi regions of the vertices, edges and face)."""
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = wp.dot(ab, ap)
    d2 = wp.dot(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        return wp.vec3(1.0, 0.0, 0.0)
    bp = p - b
    d3 = wp.dot(ab, bp)
    d4 = wp.dot(ac, bp)
    if d3 >= 0.0 and d4 <= d3:
        return wp.vec3(0.0, 1.0, 0.0)
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return wp.vec3(1.0 - v, v, 0.0)
    cp = p - c
    d5 = wp.dot(ab, cp)
    d6 = wp.dot(ac, cp)
    if d6 >= 0.0 and d5 <= d6:
        return wp.vec3(0.0, 0.0, 1.0)
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return wp.vec3(1.0 - w, 0.0, w)
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return wp.vec3(0.0, 1.0 - w, w)
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return wp.vec3(1.0 - v - w, v, w)


@wp.kernel
def clear_edge_search(best_dist: wp.array(dtype=float), best_tri: wp.array(dtype=int)):
    """Start the nearest-triangle search of every (world, point): nothing found yet."""
    i = wp.tid()
    best_dist[i] = 1.0e30
    best_tri[i] = NO_TRIANGLE


@wp.func
def nearest_surface_triangle_pair(
    tid: int,
    x_start: wp.array(dtype=wp.vec3),
    x_guess: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    triangle_world: wp.array(dtype=int),
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    points: wp.array(dtype=wp.vec3),
    point_first: wp.array(dtype=int),
    points_per_world: int,
    choose: int,
    best_dist: wp.array(dtype=float),
    best_tri: wp.array(dtype=int),
):
    """One (triangle, pad) pair per thread: the distance (m) from each of the pad's edge points at
    the substep's end pose to the triangle at the initial guess (x_start + h v_start), in the pad's
    end frame. Pass ``choose`` = 0 keeps each point's smallest distance within the search radius
    (atomic minimum; the radius: ``SEARCH_MARGIN`` plus the triangle's and the pad's motion over
    the substep); pass 1 then keeps the lowest id of the triangles at that distance. A
    triangle whose bounding box (widened by the radius) misses the pad box is skipped whole, and a
    triangle counts for a point only where it faces the pad's centre from it (outward normal n with
    n . (centre - q) > 0): the surface a pad edge touches faces the pad, and a point must not be
    pushed out through a face it never entered (a soft cuboid's bottom face, into the ground, for
    a pad edge pressed into its side just above the ground).

    Where the point and the triangle will be, not where they start: a pad moving up to 13 mm per
    substep (2 m/s, 2 pi rad/s) carries a point past the triangle nearest to it at the start, whose
    plane then reads millimetres of depth where the point passes beside the object. Pair ``tid``
    (triangle ``tid // pads_per_world``, pad ``tid % pads_per_world``) of ``nearest_surface_triangles``."""
    t = tid // pads_per_world
    k = tid % pads_per_world
    w = triangle_world[t]
    pad = w * pads_per_world + k
    ids = triangles[t]
    rot1 = pad_rot1[pad]
    pos1 = pad_pos1[pad]
    a = wp.quat_rotate_inv(rot1, x_guess[ids[0]] - pos1)
    b = wp.quat_rotate_inv(rot1, x_guess[ids[1]] - pos1)
    c = wp.quat_rotate_inv(rot1, x_guess[ids[2]] - pos1)
    motion = wp.max(wp.length(x_guess[ids[0]] - x_start[ids[0]]),
                    wp.max(wp.length(x_guess[ids[1]] - x_start[ids[1]]), wp.length(x_guess[ids[2]] - x_start[ids[2]])))
    half = pad_half[pad]
    # the most any point of the pad box moved over the substep (translation + rotation): a point
    # that the pad carried through the surface is that far from the triangle it crossed
    turn_quat = wp.mul(wp.quat_inverse(rot1), pad_rot0[pad])  # |sin(angle / 2)| is its vector part's length
    turn = 2.0 * wp.length(wp.vec3(turn_quat[0], turn_quat[1], turn_quat[2])) * wp.length(half)
    radius = SEARCH_MARGIN + motion + wp.length(pos1 - pad_pos0[pad]) + turn
    lo = wp.min(a, wp.min(b, c))
    hi = wp.max(a, wp.max(b, c))
    for j in range(3):
        if lo[j] > half[j] + radius or hi[j] < -half[j] - radius:
            return
    normal = wp.cross(b - a, c - a)  # outward (unnormalised), pad frame
    for q in range(point_first[k], point_first[k + 1]):
        p = wp.cw_mul(points[q], half)
        outside = int(0)
        if wp.dot(normal, p) >= 0.0:  # the triangle faces away from the pad's centre: not this pad's contact
            outside = 1
        for j in range(3):
            if p[j] < lo[j] - radius or p[j] > hi[j] + radius:
                outside = 1
        if outside == 0:
            bary = closest_point_barycentric(a, b, c, p)
            d = wp.length(bary[0] * a + bary[1] * b + bary[2] * c - p)
            if d < radius:
                slot = w * points_per_world + q
                if choose == 0:
                    wp.atomic_min(best_dist, slot, d)
                elif d == best_dist[slot]:
                    wp.atomic_min(best_tri, slot, t)


@wp.kernel
def nearest_surface_triangles(
    x_start: wp.array(dtype=wp.vec3),
    x_guess: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    triangle_world: wp.array(dtype=int),
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    points: wp.array(dtype=wp.vec3),
    point_first: wp.array(dtype=int),
    points_per_world: int,
    choose: int,
    best_dist: wp.array(dtype=float),
    best_tri: wp.array(dtype=int),
):
    """``nearest_surface_triangle_pair`` for every (triangle, pad) pair."""
    nearest_surface_triangle_pair(wp.tid(), x_start, x_guess, triangles, triangle_world, pad_pos0, pad_rot0, pad_pos1,
                                  pad_rot1, pad_half, pads_per_world, points, point_first, points_per_world, choose,
                                  best_dist, best_tri)
