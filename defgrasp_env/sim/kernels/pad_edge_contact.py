"""Pad edge contact: points along the edges of each pad box against the object's surface triangles.

Node-vs-box contact (``kernels.contact``) holds the object's nodes out of the pads, but not the
pads out of the object: a pad's box edge or corner pressed into a face of a coarse mesh sinks in
between the surface nodes (a 90-degree edge between node rows 8 mm apart: 2.1 mm), where the
nodes' own contacts then clamp the pad from its two faces. Here the 12 edges of every pad box are sampled
at most ``pad_edge_points.EDGE_POINT_SPACING`` apart (corners once each), and each such point q
meets the object's surface through one triangle per substep, lagged like a node's contact face:

- **search** (``pad_edge_search.nearest_surface_triangles``, two passes, then
  ``pad_edge_lag.lag_edge_points``): the triangle of the point's world nearest to q where the
  substep will take both (pad pose 1, nodes at the initial guess x_start + h v_start), among those
  within ``pad_edge_search.SEARCH_MARGIN`` plus the pad's and the triangle's motion over the substep
  and facing the pad's centre (n . (centre - q) > 0: the surface a pad edge touches faces the pad);
  ties go to the lowest triangle id. It keeps the barycentric weights w of the triangle's point
  nearest to q and its outward unit normal n. No contact where the object already wraps the pad
  there, i.e. the triangle's nodes touch this pad at the substep start on two different faces, or on
  a face the triangle does not face (n . face normal >= 0): the nodes' contacts hold the pad, and a
  coarse surface cannot fold around a 90-degree edge (its chords cut the corner by millimetres);
  pushing them out of the pad's edge pushed those nodes into the pad, and the two fought until the
  solves blew up in the contact fuzz. No contact either for a point deeper than the skin behind its
  triangle's plane at the substep start that lies outside the object (beside a convex edge, behind a
  face's extended plane: the surface's winding number, ``surface_query.py``).
- **contact** (``evaluate_edge_points``): depth g(x) = n . (sum_j w_j x_j - q1), q1 the point at the
  pad's substep-end pose: how far the point lies behind the plane of its triangle. Energy
  ``penalty_energy(k, g - g_a)`` for g > g_a, the depth the point may keep: the free skin of
  ``SKIN_KNEES`` penalty knees (0.5 mm: a pad pressed flat into a soft face leaves the rim of the
  dent a few tenths of a mm over its edges, which must not load the pad's border), or its depth at
  the substep start less one knee where that is deeper (a point found deep is pushed out a knee
  per substep, not thrown out at once). g is affine in the nodes, so within a substep this is a
  convex penalty of a fixed linear function: Newton sees no switching (the edge-crossing
  formulation this replaces switched crossings on and off within a solve and did not converge on
  a swept E = 1e6 cuboid).
- forces: -f w_j n on node j (f = ``penalty_force``), +f n on the pad (its normal force adds f).
- friction: the pads' smoothed Coulomb law (``contact.friction_force``) on the slip of the
  triangle's surface point against the pad's material point that held it at the substep start,
  lagged on the normal force of the point's start depth beyond the depth it may keep (at most a
  knee's worth: a held point's load exactly, less than its load for a point pushed back out); w_j
  of it on node j, its opposite on the pad. Without it a torus held by the pads' rims slipped (the
  expert's E = 1e7 torus episode took 244 steps instead of 79).
- Hessian: the point's 3x3 block B (s n n^T of the penalty, c (I - n n^T) of the friction) on the
  node pairs of its triangle, w_j w_k B: exact for the penalty, as the surface point is affine in
  the nodes (``pad_edge_hessian.py``: ``edge_point_product`` in CG, ``coarse_assemble_edge_points``
  in the coarse matrix; the diagonal blocks w_j^2 B in the block-Jacobi preconditioner). The per-node majorant
  w_j B used before made Newton converge linearly: a held soft grasp ran 4 iterations per substep.
- stiffness: the triangle's nodes' penalty stiffness (barycentric mean) times the point's share
  of its edge over the triangle's mean edge length, so a pad edge pressed along a face is about as
  stiff as a row of the face's nodes, whatever the sampling.
- initial guess (``pad_edge_guess.py``: ``edge_point_push``, ``push_triangles``): where the pad's motion takes a point
  deeper than g_a and than it was at the substep start, its triangle's nodes that touch no pad
  move out by the largest such excess of its points, as nodes touching a pad face are put on it
  (and a pressed point, like a node touching a pad, keeps its start depth).

The reported penetration (``SolveStats.penetration``) includes how far beyond the skin a pressed
point lies inside the object (its distance to the surface, where the surface's winding number says
it is inside: ``evaluate_edge_points``). Edge points do not take part in the extra Newton iterations or the
depth clamp of the nodes (``contact.deepest_contact``, ``clamp_depth``): a point beyond its kept
depth is pushed back by its penalty over the following substeps, a knee per substep at most.

Arrays (``solver_scratch.EdgeContactScratch``): triangles [T] vec3i global node ids and their world
[T]; points [Q] vec3 in unit box coordinates, their pad index in the world [Q], their share of an
edge [Q] (m), ``point_first`` [P+1]; per world and point (index w * Q + q): the lagged triangle (-1:
none), weights, normal (world frame), stiffness (N/m), kept depth (m), friction's normal force (N)
and Hessian block (N/m), and the search's best distance and triangle.
"""

import warp as wp

from .contact import friction_force, pad_slip, penalty_energy, penalty_force, penalty_stiffness
from .energy import friction_potential
from .surface_query import depth_inside_surface

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


#: Free depth of a pad edge point behind the surface, in penalty knees (2 x 0.25 mm = 0.5 mm).
SKIN_KNEES = 2.0
#: How much shallower (in penalty knees) than at the substep start a point deeper than the skin must end it.
RECOVERY_KNEES = 1.0


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


@wp.func
def edge_point_terms(slot: int, w: int, t: int, x: wp.array(dtype=wp.vec3), x_start: wp.array(dtype=wp.vec3),
                     triangles: wp.array(dtype=wp.vec3i), pad_pos0: wp.array(dtype=wp.vec3),
                     pad_rot0: wp.array(dtype=wp.quat), pad_pos1: wp.array(dtype=wp.vec3),
                     pad_rot1: wp.array(dtype=wp.quat), pad_half: wp.array(dtype=wp.vec3), pads_per_world: int,
                     points: wp.array(dtype=wp.vec3), point_pad: wp.array(dtype=int), points_per_world: int,
                     point_bary: wp.array(dtype=wp.vec3), point_normal: wp.array(dtype=wp.vec3),
                     point_allowed: wp.array(dtype=float)):
    """(depth beyond the kept depth g (m), depth behind the plane (m), slip (m)) of a point: the
    slip is that of its triangle's surface point relative to the pad's material point that held it
    at the substep start (``contact.pad_slip``)."""
    q = slot % points_per_world
    ids = triangles[t]
    bary = point_bary[slot]
    q1 = edge_point_end(q, w, pads_per_world, points, point_pad, pad_pos1, pad_rot1, pad_half)
    depth = edge_point_depth(x, ids, bary, point_normal[slot], q1)
    pad = w * pads_per_world + point_pad[q]
    surface = bary[0] * x[ids[0]] + bary[1] * x[ids[1]] + bary[2] * x[ids[2]]
    surface0 = bary[0] * x_start[ids[0]] + bary[1] * x_start[ids[1]] + bary[2] * x_start[ids[2]]
    slip = pad_slip(surface, surface0, pad_pos0[pad], pad_rot0[pad], pad_pos1[pad], pad_rot1[pad])
    return depth - point_allowed[slot], depth, slip


@wp.func
def evaluate_edge_point(
    slot: int,
    x: wp.array(dtype=wp.vec3),
    x_start: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    world_active: wp.array(dtype=int),
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
    point_stiffness: wp.array(dtype=float),
    point_allowed: wp.array(dtype=float),
    point_friction: wp.array(dtype=float),
    knee: float,
    mu: float,
    eps: float,
    triangle_first: wp.array(dtype=int),
    record_pads: int,
    # outputs, accumulated onto those of ``contact.evaluate_nodes`` (``point_block``: set)
    residual: wp.array(dtype=wp.vec3),
    diag_block: wp.array(dtype=wp.mat33),
    point_block: wp.array(dtype=wp.mat33),
    contact_force: wp.array(dtype=wp.vec3),
    pad_normal_force: wp.array(dtype=float),
    pad_force: wp.array(dtype=wp.vec3),
    penetration: wp.array(dtype=float),
):
    """Row ``slot`` of ``evaluate_edge_points``."""
    w = slot // points_per_world
    t = point_tri[slot]
    if t < 0 or world_active[w] == 0:
        return
    g, depth, slip = edge_point_terms(slot, w, t, x, x_start, triangles, pad_pos0, pad_rot0, pad_pos1, pad_rot1,
                                      pad_half, pads_per_world, points, point_pad, points_per_world, point_bary,
                                      point_normal, point_allowed)
    n = point_normal[slot]
    block = wp.mat33(0.0)
    force = wp.vec3(0.0)
    f = float(0.0)
    if g > 0.0:
        k = point_stiffness[slot]
        f = penalty_force(k, g, knee)
        force = -f * n
        block = penalty_stiffness(k, g, knee) * wp.outer(n, n)
    lag_fn = point_friction[slot]
    if lag_fn > 0.0:
        f_fric, h_fric = friction_force(mu, lag_fn, slip, n, eps)
        force += f_fric
        block += h_fric
    point_block[slot] = block
    if f == 0.0 and lag_fn <= 0.0:
        return
    ids = triangles[t]
    bary = point_bary[slot]
    for j in range(3):
        wp.atomic_add(residual, ids[j], bary[j] * force)
        wp.atomic_add(contact_force, ids[j], bary[j] * force)
        wp.atomic_add(diag_block, ids[j], (bary[j] * bary[j]) * block)
    if record_pads != 0:
        pad = w * pads_per_world + point_pad[slot % points_per_world]
        if f > 0.0:
            skin = SKIN_KNEES * knee
            if depth - skin > penetration[w]:
                q1 = edge_point_end(slot % points_per_world, w, pads_per_world, points, point_pad, pad_pos1, pad_rot1,
                                    pad_half)
                inside = depth_inside_surface(x, triangles, triangle_first[w], triangle_first[w + 1], q1)
                wp.atomic_max(penetration, w, wp.min(depth, inside) - skin)
            wp.atomic_add(pad_normal_force, pad, f)
        wp.atomic_add(pad_force, pad, -force)


@wp.kernel
def evaluate_edge_points(
    x: wp.array(dtype=wp.vec3),
    x_start: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    world_active: wp.array(dtype=int),
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
    point_stiffness: wp.array(dtype=float),
    point_allowed: wp.array(dtype=float),
    point_friction: wp.array(dtype=float),
    knee: float,
    mu: float,
    eps: float,
    triangle_first: wp.array(dtype=int),
    record_pads: int,
    # outputs, accumulated onto those of ``contact.evaluate_nodes`` (``point_block``: set)
    residual: wp.array(dtype=wp.vec3),
    diag_block: wp.array(dtype=wp.mat33),
    point_block: wp.array(dtype=wp.mat33),
    contact_force: wp.array(dtype=wp.vec3),
    pad_normal_force: wp.array(dtype=float),
    pad_force: wp.array(dtype=wp.vec3),
    penetration: wp.array(dtype=float),
):
    """Add each edge point's penalty and friction force (N, on its triangle's surface point) to the
    residual and contact force of the triangle's nodes (weights w_j), and the diagonal blocks of its
    Hessian (N/m) to their diagonal blocks (the block-Jacobi preconditioner's); keep the point's
    3x3 Hessian B (N/m: s n n^T of the penalty where pressed, c (I - n n^T) of the smoothed Coulomb
    law with the lagged normal force ``point_friction``, ``mu`` the pads' friction coefficient,
    ``eps`` its stick slip (m)) for the whole Hessian's products (node blocks w_j w_k B:
    ``pad_edge_hessian.py``); at the returned state (``record_pads``)
    also the pad's normal force (N), the force on the pad (N) and, into the world's ``penetration``
    (m, an atomic maximum), how far a pressed point lies inside the object beyond the skin: its
    distance to the nearest surface triangle of its world (``triangle_first`` [W+1]: the world's
    triangles; at most its plane depth) where the surface's winding number says it is inside
    (``surface_query.depth_inside_surface``), else nothing. The plane depth alone over-reported: a
    point beside a cube's edge, outside it, read 7-12 mm behind the extended plane of a face it was
    searched against. Only a point whose plane depth could raise the world's reading so far is
    tested (one pass over its world's triangles, a second for one inside), so the maximum is the
    same whatever the order the points run in."""
    evaluate_edge_point(wp.tid(), x, x_start, triangles, world_active, pad_pos0, pad_rot0, pad_pos1, pad_rot1,
                        pad_half, pads_per_world, points, point_pad, points_per_world, point_tri, point_bary,
                        point_normal, point_stiffness, point_allowed, point_friction, knee, mu, eps, triangle_first,
                        record_pads, residual, diag_block, point_block, contact_force, pad_normal_force, pad_force,
                        penetration)


@wp.func
def edge_point_energy_slot(
    slot: int,
    x: wp.array(dtype=wp.vec3),
    x_start: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    world_active: wp.array(dtype=int),
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
    point_stiffness: wp.array(dtype=float),
    point_allowed: wp.array(dtype=float),
    point_friction: wp.array(dtype=float),
    knee: float,
    mu: float,
    eps: float,
    energy: wp.array(dtype=wp.float64),
):
    """energy[w] += the penalty and friction potentials (J) of the edge point in ``slot``."""
    w = slot // points_per_world
    t = point_tri[slot]
    if t < 0 or world_active[w] == 0:
        return
    g, depth, slip = edge_point_terms(slot, w, t, x, x_start, triangles, pad_pos0, pad_rot0, pad_pos1, pad_rot1,
                                      pad_half, pads_per_world, points, point_pad, points_per_world, point_bary,
                                      point_normal, point_allowed)
    e = float(0.0)
    if g > 0.0:
        e = penalty_energy(point_stiffness[slot], g, knee)
    lag_fn = point_friction[slot]
    if lag_fn > 0.0:
        e += friction_potential(mu, lag_fn, slip, point_normal[slot], eps)
    if e != 0.0:
        wp.atomic_add(energy, w, wp.float64(e))


@wp.kernel
def edge_point_energy(
    x: wp.array(dtype=wp.vec3),
    x_start: wp.array(dtype=wp.vec3),
    triangles: wp.array(dtype=wp.vec3i),
    world_active: wp.array(dtype=int),
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
    point_stiffness: wp.array(dtype=float),
    point_allowed: wp.array(dtype=float),
    point_friction: wp.array(dtype=float),
    knee: float,
    mu: float,
    eps: float,
    energy: wp.array(dtype=wp.float64),
):
    """energy += the edge points' penalty and friction potentials (J) per world
    (``evaluate_edge_points``' potential)."""
    edge_point_energy_slot(wp.tid(), x, x_start, triangles, world_active, pad_pos0, pad_rot0, pad_pos1, pad_rot1,
                           pad_half, pads_per_world, points, point_pad, points_per_world, point_tri, point_bary,
                           point_normal, point_stiffness, point_allowed, point_friction, knee, mu, eps, energy)
