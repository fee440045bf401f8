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
and where it leaves the extent) are the contacts added here, with the node penalty's energy of
their depth g (``penalty_energy``, stiffness the mean of the two nodes'). A crossing point that
reaches an end of AB hands its depth over to that node's contact at the same depth (no jump in the
energy where the node and the edge meet the same face, as on a flat face pressed by a pad).

Gradient (exact): with t* = (+-h_k - a_k) / u_k (u = b - a) and the slope r = u_j / u_k,
dg/da = -(1 - t*) v and dg/db = -t* v with v = n - n_j r e_k; so the force on the nodes is
f (1 - t*) v and f t* v, f = ``penalty_force(g)``: its component along the face normal is f (the
pad's normal force) and v is the common normal of AB and the box edge (frictionless). The
Gauss-Newton Hessian s (grad g)(grad g)^T couples A and B; the solver's Newton systems hold
per-node contact blocks, so it is replaced by its block-diagonal majorant s (1 - t*) v v^T on A and
s t* v v^T on B (Cauchy-Schwarz: ((1-t) x + t y)^2 <= (1-t) x^2 + t y^2), which keeps the Newton
direction a descent direction of the line search's energy. Frictionless: the faces' friction acts
on the nodes.

Arrays: ``edge_nodes`` [E] vec2i global node ids of the surface edges, ``edge_world`` [E],
``edge_normal`` [E*P] vec3: the contact face (outward normal, box frame) of surface edge e with
pad p of its world (index e*P + p), lagged at the substep start.
"""

import warp as wp

from .contact import contact_face, penalty_energy, penalty_force, penalty_stiffness


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
    there is such a crossing (0 where the extent starts or ends at a node of AB, or AB misses it)."""
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
    v = wp.vec3(0.0)
    valid = int(1)
    if misses == 1 or t_in >= t_out or k < 0:
        valid = 0
    else:
        p = a + t * u
        depth = half[j] - n[j] * p[j]
        v = wp.vec3(n[0], n[1], n[2])
        v[k] = -n[j] * u[j] / u[k]
    return depth, t, v, valid


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
    t = nearest_to_centre(a, b, half)
    ga = wp.quat_rotate_inv(pad_rot1[pad], x_guess[ends[0]] - pad_pos1[pad])
    gb = wp.quat_rotate_inv(pad_rot1[pad], x_guess[ends[1]] - pad_pos1[pad])
    edge_normal[tid] = contact_face(wp.lerp(a, b, t), wp.lerp(ga, gb, t), half)


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
    for side in range(2):
        depth, t, v, valid = edge_crossing(a, b, pad_half[pad], n, side)
        if valid != 0 and depth > 0.0:
            f = penalty_force(k, depth, knee)
            s = penalty_stiffness(k, depth, knee)
            vw = wp.quat_rotate(rot, v)
            h = s * wp.outer(vw, vw)
            wp.atomic_add(residual, ends[0], (1.0 - t) * f * vw)
            wp.atomic_add(residual, ends[1], t * f * vw)
            wp.atomic_add(contact_force, ends[0], (1.0 - t) * f * vw)
            wp.atomic_add(contact_force, ends[1], t * f * vw)
            wp.atomic_add(diag_block, ends[0], (1.0 - t) * h)
            wp.atomic_add(diag_block, ends[1], t * h)
            wp.atomic_add(contact_hessian, ends[0], (1.0 - t) * h)
            wp.atomic_add(contact_hessian, ends[1], t * h)
            if record_pads != 0:
                wp.atomic_max(penetration, w, depth)
                wp.atomic_add(pad_normal_force, pad, f)
                wp.atomic_add(pad_force, pad, -f * vw)


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
        depth, t, v, valid = edge_crossing(a, b, pad_half[pad], edge_normal[tid], side)
        if valid != 0 and depth > 0.0:
            wp.atomic_add(energy, w, wp.float64(penalty_energy(k, depth, knee)))


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
    depth_out: wp.array(dtype=float),
):
    """Deepest edge contact (m) per world of the iterate x (the edge part of
    ``contact.deepest_contact``: worlds still deeper than the bound get extra Newton iterations)."""
    tid = wp.tid()
    e = tid // pads_per_world
    w = edge_world[e]
    pad = w * pads_per_world + tid % pads_per_world
    ends = edge_nodes[e]
    rot = pad_rot1[pad]
    a = wp.quat_rotate_inv(rot, x[ends[0]] - pad_pos1[pad])
    b = wp.quat_rotate_inv(rot, x[ends[1]] - pad_pos1[pad])
    for side in range(2):
        depth, t, v, valid = edge_crossing(a, b, pad_half[pad], edge_normal[tid], side)
        if valid != 0 and depth > 0.0:
            wp.atomic_max(depth_out, w, depth)
