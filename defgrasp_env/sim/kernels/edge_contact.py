"""Edge contact: the object's surface edges against the faces of each pad box, where they cross the
face's boundary (a box edge).

Node-vs-box contact (``kernels.contact``) cannot see a pad box edge that passes between two surface
nodes: a 90-degree pad edge pressed into a face of a coarse stiff mesh sinks in between the nodes,
whose own contacts then clamp the pad from its two faces (in the contact fuzz's sideways sweep a
pad ended up embedded in an E = 1e7 cuboid that way, reading kN). Here each surface edge AB meets
each pad through one face per substep, chosen as a node's is (``contact.contact_face``: continuous
collision detection of the motion relative to the box) for the point of AB nearest the box centre
(in coordinates scaled by the half extents). Along AB the depth behind that face, g(t) = h_j -
n_j p_j(t) (j: the face's axis, n_j = +-1), is linear, so within the face's lateral extent
(|p_k| < h_k for the two other axes) it is largest at an end of that interval: at a node (the
node's own contact) or where AB crosses a lateral plane p_k = +-h_k inside the segment, a point of
the box edge where the face meets the side k. Those crossing points (at most two: where AB enters
and where it leaves the extent) are the contacts added here. Their depth g counts less the depth
of the interval's other end where that is a node of AB inside the extent (that node carries its
own contact: a crossing only adds what lies deeper than it), and less a free skin of 2 penalty
knees (0.5 mm, half the penetration bound): penalty_energy(g - g_node - g0), stiffness the mean of
the two nodes'. Without the subtraction and the skin, the uncompressed rim around a pad pressed
0.2 mm into a 1e5 Pa block loaded the pad's border and made a cogging force with the period of
the node spacing that lifted the held block 2 mm (tests/test_fem_contact.py, Coulomb hold), and
a 0.25 mm skin still raised the wrist force of a cuboid swept at 1.5 m/s from 94 to 144 N
(tests/test_actuator_force_bounds.py, held-out cuboid E = 3e6). A crossing point only counts
where face j is the nearest face of the point besides the side k it lies on (the faces of the
third axis, and the face across the box along k): deeper than those, the point is in the middle
of another face (a node's contact there), not at this box edge; and only where AB crosses the
plane at >= 17 degrees (``CROSSING_SIN``), since the gradient holds AB's slope.

Gradient (exact): with t* = (+-h_k - a_k) / u_k (u = b - a) and the slope r = u_j / u_k,
dg/da = -(1 - t*) v and dg/db = -t* v with v = n - n_j r e_k, and the subtracted node's depth has
gradient -n on that node; the force is f times minus the gradient of the counted depth,
f = ``penalty_force``. v is the common normal of AB and the box edge (frictionless). The
Gauss-Newton Hessian s (grad)(grad)^T couples A and B; the solver's Newton systems hold per-node
contact blocks, so it is replaced by a block-diagonal majorant: s (1 - t*) v v^T on A and s t* v v^T
on B (Cauchy-Schwarz, ((1-t) x + t y)^2 <= (1-t) x^2 + t y^2), or 2 s g_A g_A^T and 2 s g_B g_B^T
when a node's depth is subtracted; the Newton direction stays a descent direction of the line
search's energy. Frictionless: the faces' friction acts on the nodes.

Arrays: ``edge_nodes`` [E] vec2i global node ids of the surface edges, ``edge_world`` [E],
``edge_normal`` [E*P] vec3: the contact face (outward normal, box frame) of surface edge e with
pad p of its world (index e*P + p), lagged at the substep start.
"""

import warp as wp

from .contact import axis_normal, contact_face, penalty_energy, penalty_force, penalty_stiffness


#: Smallest sine of the angle between a surface edge and the lateral plane it crosses for the
#: crossing to count: bounds the slope |u_j / u_k| in the gradient (<= 1 / 0.3); an edge that
#: grazes the plane is met by its nodes or by the face of the plane.
CROSSING_SIN = 0.3
#: Free skin of a crossing point's depth, in penalty knees (2 x 0.25 mm: half the 1 mm penetration bound).
SKIN_KNEES = 2.0


@wp.func
def nearest_to_centre(a: wp.vec3, b: wp.vec3, half: wp.vec3):
    """Parameter t in [0, 1] of the point of segment AB (box frame) nearest the box centre in
    coordinates scaled by the half extents."""
    u = b - a
    num = float(0.0)
    den = float(0.0)
    for j in range(3):
        w = 1.0 / (half[j] * half[j])
        num += a[j] * u[j] * w
        den += u[j] * u[j] * w
    t = float(0.5)
    if den > 0.0:
        t = wp.clamp(-num / den, 0.0, 1.0)
    return t


@wp.func
def edge_crossing(a: wp.vec3, b: wp.vec3, half: wp.vec3, n: wp.vec3, side: int):
    """Where segment AB (box frame) enters (``side`` 0) or leaves (1) the lateral extent of the box
    face with outward normal ``n`` (a box axis) through a lateral plane p_k = +-h_k strictly inside
    the segment: its depth behind the face (m, > 0 inside), its parameter t on AB and
    v = n - n_j (u_j / u_k) e_k (the depth's gradient is -(1 - t) v on A, -t v on B), and whether
    there is such a crossing (0 where the extent starts or ends at a node of AB, or AB misses it);
    last, the depth (m, >= 0) behind the face of the interval's other end when that end is a node of
    AB inside the extent (B for side 0, A for side 1), else 0."""
    j = int(0)
    for q in range(3):
        if n[q] != 0.0:
            j = q
    u = b - a
    t_in = float(0.0)
    t_out = float(1.0)
    k_in = int(-1)
    k_out = int(-1)
    misses = int(0)
    for k in range(3):
        if k != j:
            if u[k] == 0.0:
                if wp.abs(a[k]) >= half[k]:
                    misses = 1
            else:
                t0 = (-half[k] - a[k]) / u[k]
                t1 = (half[k] - a[k]) / u[k]
                if t0 > t1:
                    tmp = t0
                    t0 = t1
                    t1 = tmp
                if t0 > t_in:
                    t_in = t0
                    k_in = k
                if t1 < t_out:
                    t_out = t1
                    k_out = k
    t = t_in
    k = k_in
    if side == 1:
        t = t_out
        k = k_out
    depth = float(0.0)
    rest = float(0.0)
    v = wp.vec3(0.0)
    valid = int(1)
    if misses == 1 or t_in >= t_out or k < 0:
        valid = 0
    elif wp.abs(u[k]) < CROSSING_SIN * wp.length(u):  # grazing the plane: ill-defined crossing
        valid = 0
    else:
        p = a + t * u
        depth = half[j] - n[j] * p[j]
        v = wp.vec3(n[0], n[1], n[2])
        v[k] = -n[j] * u[j] / u[k]
        # a box edge contact only where face j is the nearest face of p besides the side k it lies
        # on (the third axis' faces, the face opposite p across the box along k): deeper than
        # those, p is inside a face of another box edge, met there
        l = 3 - j - k
        if half[l] - wp.abs(p[l]) < depth or 2.0 * half[k] < depth:
            valid = 0
        if side == 0 and k_out < 0:
            rest = wp.max(half[j] - n[j] * b[j], 0.0)
        if side == 1 and k_in < 0:
            rest = wp.max(half[j] - n[j] * a[j], 0.0)
    return depth, t, v, valid, rest


@wp.kernel
def lag_edge_contacts(
    x_start: wp.array(dtype=wp.vec3),
    x_guess: wp.array(dtype=wp.vec3),
    edge_nodes: wp.array(dtype=wp.vec2i),
    edge_world: wp.array(dtype=int),
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    edge_normal: wp.array(dtype=wp.vec3),
):
    """Contact face of each (surface edge, pad) pair for the substep: ``contact.contact_face`` of
    the point of AB nearest the box centre at the substep start (start pad frame) and of the same
    point of AB at the initial guess (end pad frame)."""
    tid = wp.tid()
    e = tid // pads_per_world
    pad = edge_world[e] * pads_per_world + tid % pads_per_world
    ends = edge_nodes[e]
    half = pad_half[pad]
    a = wp.quat_rotate_inv(pad_rot0[pad], x_start[ends[0]] - pad_pos0[pad])
    b = wp.quat_rotate_inv(pad_rot0[pad], x_start[ends[1]] - pad_pos0[pad])
    best = float(1.0e30)
    face = wp.vec3(0.0)
    for f in range(6):
        n = axis_normal(f // 2, float(2 * (f % 2) - 1))
        for side in range(2):
            depth, t, v, valid, rest = edge_crossing(a, b, half, n, side)
            if valid != 0 and depth < best:
                best = depth
                face = n
    if best == 1.0e30:  # no crossing at the start: the face the pad's motion brings it to
        t = nearest_to_centre(a, b, half)
        ga = wp.quat_rotate_inv(pad_rot1[pad], x_guess[ends[0]] - pad_pos1[pad])
        gb = wp.quat_rotate_inv(pad_rot1[pad], x_guess[ends[1]] - pad_pos1[pad])
        face = contact_face(wp.lerp(a, b, t), wp.lerp(ga, gb, t), half)
    edge_normal[tid] = face


@wp.kernel
def evaluate_edges(
    x: wp.array(dtype=wp.vec3),
    edge_nodes: wp.array(dtype=wp.vec2i),
    edge_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    edge_normal: wp.array(dtype=wp.vec3),
    stiffness: wp.array(dtype=float),
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
    """Add the edge contacts' penalty forces (N) at the pad's substep end pose to the residual and
    contact force of the edge's two nodes, and the block-diagonal majorant of their Hessian (N/m)
    to the diagonal and contact blocks; at the returned state (``record_pads``) also the pad's
    normal force (N), the force on the pad (N) and the depth (m)."""
    tid = wp.tid()
    e = tid // pads_per_world
    w = edge_world[e]
    if world_active[w] == 0:
        return
    pad = w * pads_per_world + tid % pads_per_world
    ends = edge_nodes[e]
    rot = pad_rot1[pad]
    a = wp.quat_rotate_inv(rot, x[ends[0]] - pad_pos1[pad])
    b = wp.quat_rotate_inv(rot, x[ends[1]] - pad_pos1[pad])
    n = edge_normal[tid]
    k = 0.5 * (stiffness[ends[0]] + stiffness[ends[1]])
    nw = wp.quat_rotate(rot, n)
    for side in range(2):
        depth, t, v, valid, rest = edge_crossing(a, b, pad_half[pad], n, side)
        if valid != 0 and depth - rest > SKIN_KNEES * knee:
            f = penalty_force(k, depth - rest - SKIN_KNEES * knee, knee)
            s = penalty_stiffness(k, depth - rest - SKIN_KNEES * knee, knee)
            vw = wp.quat_rotate(rot, v)
            ga = (1.0 - t) * vw
            gb = t * vw
            ha = (1.0 - t) * s * wp.outer(vw, vw)
            hb = t * s * wp.outer(vw, vw)
            if rest > 0.0:  # the other end's own depth is subtracted: its gradient n joins in
                if side == 0:
                    gb = gb - nw
                else:
                    ga = ga - nw
                ha = 2.0 * s * wp.outer(ga, ga)
                hb = 2.0 * s * wp.outer(gb, gb)
            wp.atomic_add(residual, ends[0], f * ga)
            wp.atomic_add(residual, ends[1], f * gb)
            wp.atomic_add(contact_force, ends[0], f * ga)
            wp.atomic_add(contact_force, ends[1], f * gb)
            wp.atomic_add(diag_block, ends[0], ha)
            wp.atomic_add(diag_block, ends[1], hb)
            wp.atomic_add(contact_hessian, ends[0], ha)
            wp.atomic_add(contact_hessian, ends[1], hb)
            if record_pads != 0:
                wp.atomic_max(penetration, w, depth - rest)
                wp.atomic_add(pad_normal_force, pad, f * wp.dot(ga + gb, nw))
                wp.atomic_add(pad_force, pad, -f * (ga + gb))


@wp.kernel
def edge_energy(
    x: wp.array(dtype=wp.vec3),
    edge_nodes: wp.array(dtype=wp.vec2i),
    edge_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    edge_normal: wp.array(dtype=wp.vec3),
    stiffness: wp.array(dtype=float),
    knee: float,
    energy: wp.array(dtype=wp.float64),
):
    """energy += the edge contacts' penalty energy (J) per world (``evaluate_edges``' potential)."""
    tid = wp.tid()
    e = tid // pads_per_world
    w = edge_world[e]
    if world_active[w] == 0:
        return
    pad = w * pads_per_world + tid % pads_per_world
    ends = edge_nodes[e]
    rot = pad_rot1[pad]
    a = wp.quat_rotate_inv(rot, x[ends[0]] - pad_pos1[pad])
    b = wp.quat_rotate_inv(rot, x[ends[1]] - pad_pos1[pad])
    k = 0.5 * (stiffness[ends[0]] + stiffness[ends[1]])
    for side in range(2):
        depth, t, v, valid, rest = edge_crossing(a, b, pad_half[pad], edge_normal[tid], side)
        if valid != 0 and depth - rest > SKIN_KNEES * knee:
            wp.atomic_add(energy, w, wp.float64(penalty_energy(k, depth - rest - SKIN_KNEES * knee, knee)))


@wp.kernel
def deepest_edge_contact(
    x: wp.array(dtype=wp.vec3),
    edge_nodes: wp.array(dtype=wp.vec2i),
    edge_world: wp.array(dtype=int),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    edge_normal: wp.array(dtype=wp.vec3),
    knee: float,
    depth_out: wp.array(dtype=float),
):
    """Deepest edge contact (m, beyond the free ``knee``) per world of the iterate x (the edge part
    of ``contact.deepest_contact``: worlds still deeper than the bound get extra Newton iterations)."""
    tid = wp.tid()
    e = tid // pads_per_world
    w = edge_world[e]
    pad = w * pads_per_world + tid % pads_per_world
    ends = edge_nodes[e]
    rot = pad_rot1[pad]
    a = wp.quat_rotate_inv(rot, x[ends[0]] - pad_pos1[pad])
    b = wp.quat_rotate_inv(rot, x[ends[1]] - pad_pos1[pad])
    for side in range(2):
        depth, t, v, valid, rest = edge_crossing(a, b, pad_half[pad], edge_normal[tid], side)
        if valid != 0 and depth - rest > SKIN_KNEES * knee:
            wp.atomic_max(depth_out, w, depth - rest - SKIN_KNEES * knee)
