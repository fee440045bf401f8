"""Pad edge contact: points along the edges of each pad box against the object's surface triangles.

Node-vs-box contact (``kernels.contact``) holds the object's nodes out of the pads, but not the
pads out of the object: a pad's box edge or corner pressed into a face of a coarse mesh sinks in
between the surface nodes (a 90-degree edge between node rows 8 mm apart: 2.1 mm), where the
nodes' own contacts then clamp the pad from its two faces. Here the 12 edges of every pad box are sampled
at most ``pad_edge_points.EDGE_POINT_SPACING`` apart (corners once each), and each such point q
meets the object's surface through one triangle per substep, lagged like a node's contact face:

- **search** (``pad_edge_search.nearest_surface_triangles``, two passes, then ``lag_edge_points``): the triangle of
  the point's world nearest to q where the substep will take both (pad pose 1, nodes at the
  initial guess x_start + h v_start), among those within ``pad_edge_search.SEARCH_MARGIN`` plus the pad's and the
  triangle's motion over the substep and facing the pad's centre (n . (centre - q) > 0: the
  surface a pad edge touches faces the pad); ties go to the lowest triangle id. It keeps the
  barycentric weights w of the triangle's point nearest to q and its outward unit normal n.
  No contact where the object already wraps the pad there, i.e. the triangle's nodes touch this
  pad at the substep start on two different faces, or on a face the triangle does not face (n .
  face normal >= 0): the nodes' contacts hold the pad, and a coarse surface cannot fold around a
  90-degree edge (its chords cut the corner by millimetres); pushing them out of the pad's edge
  pushed those nodes into the pad, and the two fought until the solves blew up in the contact fuzz.
  No contact either for a point deeper than the skin behind its triangle's plane at the substep
  start that lies outside the object (beside a convex edge, behind a face's extended plane: the
  surface's winding number, ``surface_query.py``).
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
- initial guess (``edge_point_push``, ``push_triangles``): where the pad's motion takes a point
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
from .pad_edge_search import NO_TRIANGLE, closest_point_barycentric
from .surface_query import depth_inside_surface, winding_number

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
