"""Pad edge contact: points along the edges of each pad box against the object's surface triangles.

Node-vs-box contact (``kernels.contact``) holds the object's nodes out of the pads, but not the
pads out of the object: a pad's box edge or corner pressed into a face of a coarse mesh sinks in
between the surface nodes (a 90-degree edge between node rows 8 mm apart: 4 mm), where the nodes'
own contacts then clamp the pad from its two faces. Here the 12 edges of every pad box are sampled
at ``EdgePoints.spacing`` (corners included, once each), and each such point q meets the object's
surface through one triangle per substep, lagged at the substep start like a node's contact face:

- **search** (``nearest_surface_triangles``, two passes, and ``lag_edge_points``): the triangle of
  the point's world nearest to q at the substep start (pad pose 0, nodes at ``x_start``), among
  those within ``SEARCH_MARGIN`` plus the point's and the triangle's motion over the substep (pad
  pose 0 -> 1, ``x_start`` -> the initial guess); ties go to the lowest triangle id, so the choice
  is deterministic. It keeps the barycentric weights w of the nearest point of that triangle and
  the triangle's outward unit normal n (world frame), both fixed for the substep.
- **contact** (``evaluate_edge_points``): depth g(x) = n . (sum_j w_j x_j - q1) with q1 the point
  at the pad's substep-end pose: how far the point lies behind the triangle's plane, the surface
  point carried by the nodes. Energy ``penalty_energy(k, g - g0)`` for g > g0 = ``SKIN_KNEES``
  penalty knees (0.5 mm: a pad pressed flat into a soft face leaves the rim of the dent a few
  tenths of a mm over its edges, and the rim must not load the pad's border: without a skin that
  made a cogging force with the node spacing's period, and a 0.25 mm skin raised the wrist force
  of a fast-swept stiff cuboid from 94 to 144 N, issue 10's notes). g is affine in the nodes, so
  within a substep this contact is a convex penalty of a fixed linear function: the Newton solve
  sees no switching (the edge-crossing formulation this replaces switched crossings on and off
  within a solve and did not converge on a swept E = 1e6 cuboid).
- forces: -f w_j n on node j (f = ``penalty_force``), +f n on the pad; Hessian: the block-diagonal
  majorant s w_j n n^T on node j of the Gauss-Newton term s (w w^T) x n n^T (Cauchy-Schwarz with
  sum w_j = 1), so the Newton direction stays a descent direction of the line search's energy.
  Frictionless: the pads' friction acts on the nodes that touch their faces.
- stiffness: the triangle's nodes' mean penalty stiffness (barycentric) times the point's share of
  its edge over the triangle's mean edge length, so a pad edge pressed along a face is about as
  stiff as a row of the face's nodes would be, whatever the sampling.

A point whose counted depth g - g0 exceeds ``SolverConfig.penetration_bound`` after the solve is
put back to 90 % of it by moving its triangle's three nodes along -n (``clamp_edge_points``) and the
world is flagged, as a node is (``contact.clamp_depth``).

Arrays (``solver_scratch.EdgeContactScratch``): triangles [T] vec3i global node ids and their world
[T]; points [Q] vec3 in their pad's frame (m), their pad index in the world [Q], their share of an
edge [Q] (m), ``point_first`` [P+1]; per world and point (index w * Q + q): the lagged triangle (-1:
none), weights, normal (world frame) and stiffness (N/m), and the search's best distance and triangle.
"""

import warp as wp

from .contact import penalty_energy, penalty_force, penalty_stiffness

#: Free depth of a pad edge point behind the surface, in penalty knees (2 x 0.25 mm = 0.5 mm).
SKIN_KNEES = 2.0
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
    """One (triangle, pad) pair per thread: the distance (m) from each of the pad's edge points at
    the substep start to the triangle at the substep start, in the pad's start frame. Pass
    ``choose`` = 0 keeps each point's smallest distance within its search radius (atomic
    minimum); pass 1 then keeps the lowest id of the triangles at that distance. A triangle whose
    bounding box (widened by the radius) misses the pad box is skipped whole."""
    tid = wp.tid()
    t = tid // pads_per_world
    k = tid % pads_per_world
    w = triangle_world[t]
    pad = w * pads_per_world + k
    ids = triangles[t]
    rot0 = pad_rot0[pad]
    pos0 = pad_pos0[pad]
    a = wp.quat_rotate_inv(rot0, x_start[ids[0]] - pos0)
    b = wp.quat_rotate_inv(rot0, x_start[ids[1]] - pos0)
    c = wp.quat_rotate_inv(rot0, x_start[ids[2]] - pos0)
    motion = wp.max(wp.length(x_guess[ids[0]] - x_start[ids[0]]),
                    wp.max(wp.length(x_guess[ids[1]] - x_start[ids[1]]), wp.length(x_guess[ids[2]] - x_start[ids[2]])))
    half = pad_half[pad]
    # the most any point of the pad box moves over the substep (translation + rotation)
    turn = wp.length(wp.quat_rotate_inv(rot0, wp.quat_rotate(pad_rot1[pad], half)) - half)
    radius = SEARCH_MARGIN + motion + wp.length(pad_pos1[pad] - pos0) + turn
    lo = wp.min(a, wp.min(b, c))
    hi = wp.max(a, wp.max(b, c))
    for j in range(3):
        if lo[j] > half[j] + radius or hi[j] < -half[j] - radius:
            return
    for q in range(point_first[k], point_first[k + 1]):
        p = wp.cw_mul(points[q], half)
        outside = int(0)
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
def lag_edge_points(
    x_start: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    points: wp.array(dtype=wp.vec3),
    point_pad: wp.array(dtype=int),
    point_share: wp.array(dtype=float),
    points_per_world: int,
    stiffness: wp.array(dtype=float),
    best_tri: wp.array(dtype=int),
    point_tri: wp.array(dtype=int),
    point_bary: wp.array(dtype=wp.vec3),
    point_normal: wp.array(dtype=wp.vec3),
    point_stiffness: wp.array(dtype=float),
):
    """For each (world, point): the triangle the search chose (-1: none), the barycentric weights
    of its point nearest to the edge point at the substep start, its outward unit normal (world
    frame) and the contact's stiffness (N/m), all held for the substep."""
    slot = wp.tid()
    w = slot // points_per_world
    q = slot % points_per_world
    t = best_tri[slot]
    if t == NO_TRIANGLE:
        point_tri[slot] = -1
        return
    pad = w * pads_per_world + point_pad[q]
    ids = triangles[t]
    xa = x_start[ids[0]]
    xb = x_start[ids[1]]
    xc = x_start[ids[2]]
    p = pad_pos0[pad] + wp.quat_rotate(pad_rot0[pad], wp.cw_mul(points[q], pad_half[pad]))
    bary = closest_point_barycentric(xa, xb, xc, p)
    cross = wp.cross(xb - xa, xc - xa)
    area2 = wp.length(cross)
    if area2 <= 0.0:  # a degenerate triangle has no normal: no contact through it
        point_tri[slot] = -1
        return
    mean_edge = (wp.length(xb - xa) + wp.length(xc - xb) + wp.length(xa - xc)) / 3.0
    k = bary[0] * stiffness[ids[0]] + bary[1] * stiffness[ids[1]] + bary[2] * stiffness[ids[2]]
    point_tri[slot] = t
    point_bary[slot] = bary
    point_normal[slot] = cross / area2
    point_stiffness[slot] = k * point_share[q] / mean_edge


@wp.func
def edge_point_depth(x: wp.array(dtype=wp.vec3), ids: wp.vec3i, bary: wp.vec3, n: wp.vec3, q1: wp.vec3):
    """Depth (m) of the pad point q1 behind the plane of its triangle through the lagged surface point."""
    surface = bary[0] * x[ids[0]] + bary[1] * x[ids[1]] + bary[2] * x[ids[2]]
    return wp.dot(n, surface - q1)


@wp.func
def edge_point_end(q: int, w: int, pads_per_world: int, points: wp.array(dtype=wp.vec3),
                   point_pad: wp.array(dtype=int), pad_pos1: wp.array(dtype=wp.vec3),
                   pad_rot1: wp.array(dtype=wp.quat), pad_half: wp.array(dtype=wp.vec3)):
    """The edge point at the pad's substep-end pose (world frame, m)."""
    pad = w * pads_per_world + point_pad[q]
    return pad_pos1[pad] + wp.quat_rotate(pad_rot1[pad], wp.cw_mul(points[q], pad_half[pad]))


@wp.kernel
def evaluate_edge_points(
    x: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    world_active: wp.array(dtype=int),
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
    point_stiffness: wp.array(dtype=float),
    knee: float,
    record_pads: int,
    # outputs, accumulated onto those of ``contact.evaluate_nodes``
    residual: wp.array(dtype=wp.vec3),
    diag_block: wp.array(dtype=wp.mat33),
    contact_hessian: wp.array(dtype=wp.mat33),
    contact_force: wp.array(dtype=wp.vec3),
    pad_normal_force: wp.array(dtype=float),
    pad_force: wp.array(dtype=wp.vec3),
    penetration: wp.array(dtype=float),
):
    """Add each edge point's penalty force (N) to the residual and contact force of its triangle's
    nodes and the block-diagonal majorant of its Hessian (N/m) to their diagonal and contact
    blocks; at the returned state (``record_pads``) also the pad's normal force (N), the force on
    the pad (N) and the point's depth behind the surface (m)."""
    slot = wp.tid()
    w = slot // points_per_world
    t = point_tri[slot]
    if t < 0 or world_active[w] == 0:
        return
    q = slot % points_per_world
    ids = triangles[t]
    bary = point_bary[slot]
    n = point_normal[slot]
    q1 = edge_point_end(q, w, pads_per_world, points, point_pad, pad_pos1, pad_rot1, pad_half)
    depth = edge_point_depth(x, ids, bary, n, q1)
    g = depth - SKIN_KNEES * knee
    if g <= 0.0:
        return
    k = point_stiffness[slot]
    f = penalty_force(k, g, knee)
    h = penalty_stiffness(k, g, knee) * wp.outer(n, n)
    for j in range(3):
        wp.atomic_add(residual, ids[j], -f * bary[j] * n)
        wp.atomic_add(contact_force, ids[j], -f * bary[j] * n)
        wp.atomic_add(diag_block, ids[j], bary[j] * h)
        wp.atomic_add(contact_hessian, ids[j], bary[j] * h)
    if record_pads != 0:
        pad = w * pads_per_world + point_pad[q]
        wp.atomic_max(penetration, w, depth)
        wp.atomic_add(pad_normal_force, pad, f)
        wp.atomic_add(pad_force, pad, f * n)


@wp.kernel
def edge_point_energy(
    x: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    world_active: wp.array(dtype=int),
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
    point_stiffness: wp.array(dtype=float),
    knee: float,
    energy: wp.array(dtype=wp.float64),
):
    """energy += the edge points' penalty energy (J) per world (``evaluate_edge_points``' potential)."""
    slot = wp.tid()
    w = slot // points_per_world
    t = point_tri[slot]
    if t < 0 or world_active[w] == 0:
        return
    q = slot % points_per_world
    q1 = edge_point_end(q, w, pads_per_world, points, point_pad, pad_pos1, pad_rot1, pad_half)
    g = edge_point_depth(x, triangles[t], point_bary[slot], point_normal[slot], q1) - SKIN_KNEES * knee
    if g > 0.0:
        wp.atomic_add(energy, w, wp.float64(penalty_energy(point_stiffness[slot], g, knee)))


@wp.kernel
def deepest_edge_point(
    x: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
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
    knee: float,
    depth_out: wp.array(dtype=float),
):
    """Deepest counted edge-point depth (m, beyond the free skin) per world of the iterate x (the
    edge part of ``contact.deepest_contact``: worlds deeper than the bound get extra iterations)."""
    slot = wp.tid()
    w = slot // points_per_world
    t = point_tri[slot]
    if t < 0:
        return
    q = slot % points_per_world
    q1 = edge_point_end(q, w, pads_per_world, points, point_pad, pad_pos1, pad_rot1, pad_half)
    g = edge_point_depth(x, triangles[t], point_bary[slot], point_normal[slot], q1) - SKIN_KNEES * knee
    if g > 0.0:
        wp.atomic_max(depth_out, w, g)


@wp.kernel
def clamp_edge_points(
    triangles: wp.array(dtype=wp.vec3i),
    solve: wp.array(dtype=int),
    free: wp.array(dtype=wp.vec3),
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
    knee: float,
    bound: float,
    target: float,
    x: wp.array(dtype=wp.vec3),
    clamped: wp.array(dtype=int),
):
    """Move the triangle of an edge point that the solve left deeper than ``bound`` (m, beyond the
    skin) along -n until the point is ``target`` deep (free axes only), and flag the world (the
    edge part of ``contact.clamp_depth``). Only worlds with ``solve`` set are touched."""
    slot = wp.tid()
    w = slot // points_per_world
    t = point_tri[slot]
    if t < 0 or solve[w] == 0:
        return
    q = slot % points_per_world
    ids = triangles[t]
    n = point_normal[slot]
    q1 = edge_point_end(q, w, pads_per_world, points, point_pad, pad_pos1, pad_rot1, pad_half)
    g = edge_point_depth(x, ids, point_bary[slot], n, q1) - SKIN_KNEES * knee
    if g > bound:
        for j in range(3):
            wp.atomic_add(x, ids[j], -(g - target) * wp.cw_mul(free[ids[j]], n))
        clamped[w] = 1
