"""Penalty contact with the ground plane y = 0 and kinematic oriented boxes, with smoothed Coulomb friction.

Each node meets each box through one face per substep (``pad_faces``: chosen at the substep start by
continuous collision detection, the depth behind it continuous at its edges).

Normal: energy k/2 d^2 for penetration depth d, so the normal force is k d and its Hessian k n n^T,
stiffening cubically beyond a knee depth (``penalty_force``); k per node (``Model.node_contact_stiffness``).
Friction (normal force f_n and normal lagged at the substep start, IPC-style smoothing): for a tangential slip u_T over the step,
force = -mu f_n f1(|u_T|) u_T / |u_T| with f1(s) = 2 s/eps - s^2/eps^2 for s < eps and 1 beyond,
eps = stick_velocity * dt. Its Hessian is approximated by mu f_n f1(s)/s times the tangent projector
(positive semi-definite). Below eps the force grows linearly with slip: the contact sticks.
"""

import warp as wp

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})

from .pad_faces import contact_face, face_contact, face_penetration, start_face_normal  # noqa: E402


@wp.func
def friction_coefficient(s: float, eps: float):
    """f1(s) / s of the smoothed Coulomb law (1/m)."""
    if s < eps:
        return 2.0 / eps - s / (eps * eps)
    return 1.0 / s


@wp.func
def tangent_projector(n: wp.vec3):
    return wp.identity(n=3, dtype=float) - wp.outer(n, n)


@wp.func
def penalty_force(k: float, depth: float, knee: float):
    """Normal penalty force (N) of a depth (m) > 0: k d, plus k (d - knee)^3 / knee^2 beyond ``knee``."""
    f = k * depth
    if depth > knee:
        e = depth - knee
        f += k * e * e * e / (knee * knee)
    return f


@wp.func
def penalty_stiffness(k: float, depth: float, knee: float):
    """d(penalty_force)/d(depth), N/m."""
    s = k
    if depth > knee:
        e = depth - knee
        s += 3.0 * k * e * e / (knee * knee)
    return s


@wp.func
def penalty_energy(k: float, depth: float, knee: float):
    """Integral of penalty_force over the depth, J."""
    en = 0.5 * k * depth * depth
    if depth > knee:
        e = depth - knee
        en += 0.25 * k * e * e * e * e / (knee * knee)
    return en


@wp.func
def interpolate_pad(
    i: int,
    start_pos: wp.array(dtype=wp.vec3),
    start_rot: wp.array(dtype=wp.quat),
    end_pos: wp.array(dtype=wp.vec3),
    end_rot: wp.array(dtype=wp.quat),
    s0: float,
    s1: float,
    pos0: wp.array(dtype=wp.vec3),
    rot0: wp.array(dtype=wp.quat),
    pos1: wp.array(dtype=wp.vec3),
    rot1: wp.array(dtype=wp.quat),
):
    """Pad ``i``'s poses at fractions s0 and s1 of the step (linear position, slerp orientation)."""
    qa = wp.normalize(start_rot[i])
    qb = wp.normalize(end_rot[i])
    pos0[i] = wp.lerp(start_pos[i], end_pos[i], s0)
    pos1[i] = wp.lerp(start_pos[i], end_pos[i], s1)
    rot0[i] = wp.quat_slerp(qa, qb, s0)
    rot1[i] = wp.quat_slerp(qa, qb, s1)


@wp.kernel
def interpolate_pads(
    start_pos: wp.array(dtype=wp.vec3),
    start_rot: wp.array(dtype=wp.quat),
    end_pos: wp.array(dtype=wp.vec3),
    end_rot: wp.array(dtype=wp.quat),
    s0: float,
    s1: float,
    pos0: wp.array(dtype=wp.vec3),
    rot0: wp.array(dtype=wp.quat),
    pos1: wp.array(dtype=wp.vec3),
    rot1: wp.array(dtype=wp.quat),
):
    """Pad poses at fractions s0 and s1 of the step (linear position, slerp orientation)."""
    interpolate_pad(wp.tid(), start_pos, start_rot, end_pos, end_rot, s0, s1, pos0, rot0, pos1, rot1)


@wp.func
def lag_contact_node(
    i: int,
    x_start: wp.array(dtype=wp.vec3),
    x_guess: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    stiffness: wp.array(dtype=float),
    knee: float,
    lag_normal_force: wp.array(dtype=float),
    lag_normal: wp.array(dtype=wp.vec3),
):
    """Contact face of every node with every pad for the substep (``contact_face``: CCD of the
    node's motion relative to the pad), and the normal force (N) and normal at the substep start,
    which the friction law holds fixed during the substep's Newton solve (slot 0: ground; slot
    1 + k: pad k, normal in the pad's frame; the contact terms use that face all substep long):
    node ``i``'s row of ``lag_contacts``."""
    w = node_world[i]
    slots = pads_per_world + 1
    xi = x_start[i]
    k_i = stiffness[i]
    lag_normal_force[i * slots] = penalty_force(k_i, wp.max(-xi[1], 0.0), knee)
    lag_normal[i * slots] = wp.vec3(0.0, 1.0, 0.0)
    for k in range(pads_per_world):
        pad = w * pads_per_world + k
        local = wp.quat_rotate_inv(pad_rot0[pad], xi - pad_pos0[pad])
        guess = wp.quat_rotate_inv(pad_rot1[pad], x_guess[i] - pad_pos1[pad])
        n_local = contact_face(local, guess, pad_half[pad])
        depth = face_penetration(local, pad_half[pad], n_local)
        lag_normal_force[i * slots + 1 + k] = penalty_force(k_i, wp.max(depth, 0.0), knee)
        lag_normal[i * slots + 1 + k] = n_local


@wp.kernel
def lag_contacts(
    x_start: wp.array(dtype=wp.vec3),
    x_guess: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    stiffness: wp.array(dtype=float),
    knee: float,
    lag_normal_force: wp.array(dtype=float),
    lag_normal: wp.array(dtype=wp.vec3),
):
    """``lag_contact_node`` for every node."""
    lag_contact_node(wp.tid(), x_start, x_guess, node_world, pad_pos0, pad_rot0, pad_pos1, pad_rot1, pad_half,
                     pads_per_world, stiffness, knee, lag_normal_force, lag_normal)


@wp.func
def pad_slip(xi: wp.vec3, x_start: wp.vec3, pos0: wp.vec3, rot0: wp.quat, pos1: wp.vec3, rot1: wp.quat):
    """Slip (m) of a node at ``xi`` relative to the pad's material point that held it at the
    substep start (``x_start``, pad pose 0), carried to the pad's pose 1."""
    anchor_local = wp.quat_rotate_inv(rot0, x_start - pos0)
    return xi - (pos1 + wp.quat_rotate(rot1, anchor_local))


@wp.func
def friction_force(mu: float, normal_force: float, slip: wp.vec3, n: wp.vec3, eps: float):
    """Smoothed Coulomb force (N) for a slip (m) and normal n, and its Hessian (N/m)."""
    slip_t = slip - wp.dot(slip, n) * n
    c = mu * normal_force * friction_coefficient(wp.length(slip_t), eps)
    return -c * slip_t, c * tangent_projector(n)


@wp.func
def evaluate_node(
    i: int,
    x: wp.array(dtype=wp.vec3),
    x_start: wp.array(dtype=wp.vec3),
    v_start: wp.array(dtype=wp.vec3),
    mass: wp.array(dtype=float),
    node_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    external_force: wp.array(dtype=wp.vec3),
    gravity: wp.vec3,
    dt: float,
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    lag_normal_force: wp.array(dtype=float),
    lag_normal: wp.array(dtype=wp.vec3),
    stiffness: wp.array(dtype=float),
    knee: float,
    ground_mu: float,
    pad_mu: float,
    stick_velocity: float,
    record_pads: int,
    # outputs (written, not accumulated, except the pad totals)
    residual: wp.array(dtype=wp.vec3),
    diag_block: wp.array(dtype=wp.mat33),
    contact_hessian: wp.array(dtype=wp.mat33),
    contact_force: wp.array(dtype=wp.vec3),
    elastic_force: wp.array(dtype=wp.vec3),
    pad_normal_force: wp.array(dtype=float),
    pad_force: wp.array(dtype=wp.vec3),
    penetration: wp.array(dtype=float),
):
    """Row ``i`` of ``evaluate_nodes``."""
    w = node_world[i]
    if world_active[w] == 0:
        return
    m = mass[i]
    xi = x[i]
    inertia = m / (dt * dt)
    eps = stick_velocity * dt
    force = wp.vec3(0.0)
    hess = wp.mat33(0.0)
    slots = pads_per_world + 1
    # ground plane y = 0, normal +y
    n = wp.vec3(0.0, 1.0, 0.0)
    depth = -xi[1]
    k_i = stiffness[i]
    if depth > 0.0:
        force += penalty_force(k_i, depth, knee) * n
        hess += penalty_stiffness(k_i, depth, knee) * wp.outer(n, n)
        if record_pads != 0:  # only at the returned state, not at trial Newton iterates
            wp.atomic_max(penetration, w, depth)
    lag_fn = lag_normal_force[i * slots]
    if lag_fn > 0.0:
        f_fric, h_fric = friction_force(ground_mu, lag_fn, xi - x_start[i], n, eps)
        force += f_fric
        hess += h_fric
    for k in range(pads_per_world):
        pad = w * pads_per_world + k
        rot1 = pad_rot1[pad]
        local = wp.quat_rotate_inv(rot1, xi - pad_pos1[pad])
        n_local = lag_normal[i * slots + 1 + k]
        depth, n_face = face_contact(local, pad_half[pad], n_local)
        f_pad = wp.vec3(0.0)
        if depth > 0.0:
            n = wp.quat_rotate(rot1, n_face)
            f_n = penalty_force(k_i, depth, knee)
            f_pad = f_n * n
            hess += penalty_stiffness(k_i, depth, knee) * wp.outer(n, n)
            if record_pads != 0:
                wp.atomic_max(penetration, w, depth)
                wp.atomic_add(pad_normal_force, pad, f_n)
        lag_fn = lag_normal_force[i * slots + 1 + k]
        if lag_fn > 0.0:
            slip = pad_slip(xi, x_start[i], pad_pos0[pad], pad_rot0[pad], pad_pos1[pad], rot1)
            n_lag = wp.quat_rotate(rot1, start_face_normal(x_start[i], pad_pos0[pad], pad_rot0[pad], pad_half[pad],
                                                           n_local))
            f_fric, h_fric = friction_force(pad_mu, lag_fn, slip, n_lag, eps)
            f_pad += f_fric
            hess += h_fric
        force += f_pad
        if record_pads != 0:
            wp.atomic_add(pad_force, pad, -f_pad)
    x_hat = x_start[i] + dt * v_start[i]
    residual[i] = inertia * (x_hat - xi) + m * gravity + external_force[i] + force
    diag_block[i] = inertia * wp.identity(n=3, dtype=float) + hess
    contact_hessian[i] = hess
    contact_force[i] = force
    elastic_force[i] = wp.vec3(0.0)


@wp.kernel
def evaluate_nodes(
    x: wp.array(dtype=wp.vec3),
    x_start: wp.array(dtype=wp.vec3),
    v_start: wp.array(dtype=wp.vec3),
    mass: wp.array(dtype=float),
    node_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    external_force: wp.array(dtype=wp.vec3),
    gravity: wp.vec3,
    dt: float,
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    lag_normal_force: wp.array(dtype=float),
    lag_normal: wp.array(dtype=wp.vec3),
    stiffness: wp.array(dtype=float),
    knee: float,
    ground_mu: float,
    pad_mu: float,
    stick_velocity: float,
    record_pads: int,
    # outputs (written, not accumulated, except the pad totals)
    residual: wp.array(dtype=wp.vec3),
    diag_block: wp.array(dtype=wp.mat33),
    contact_hessian: wp.array(dtype=wp.mat33),
    contact_force: wp.array(dtype=wp.vec3),
    elastic_force: wp.array(dtype=wp.vec3),
    pad_normal_force: wp.array(dtype=float),
    pad_force: wp.array(dtype=wp.vec3),
    penetration: wp.array(dtype=float),
):
    """Inertia, gravity, external and contact terms of the backward-Euler residual of each node.

    residual = m/dt^2 (x_hat - x) + m g + f_ext + f_contact, x_hat = x_start + dt v_start;
    diag_block = m/dt^2 I + contact Hessian. The elastic terms are added afterwards by the tets.
    """
    evaluate_node(wp.tid(), x, x_start, v_start, mass, node_world, world_active, external_force, gravity, dt,
                  pad_pos0, pad_rot0, pad_pos1, pad_rot1, pad_half, pads_per_world, lag_normal_force, lag_normal,
                  stiffness, knee, ground_mu, pad_mu, stick_velocity, record_pads, residual, diag_block,
                  contact_hessian, contact_force, elastic_force, pad_normal_force, pad_force, penetration)


@wp.func
def keep_pad_depth_node(
    i: int,
    x_start: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    solve: wp.array(dtype=int),
    free: wp.array(dtype=wp.vec3),
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    lag_normal_force: wp.array(dtype=float),
    lag_normal: wp.array(dtype=wp.vec3),
    x: wp.array(dtype=wp.vec3),
):
    """Initial Newton guess of a node touching a pad at the substep start: the guess x (x_start +
    dt v_start) with its depth along the pad normal put back to the depth it had at the start, in
    the pad's moved frame; the tangential part (sliding or sticking) is kept. A node the moving pad
    (or its own motion) brings behind its contact face is put on that face, and a node that the
    guess takes below the ground on the ground: Newton starts from a state without deep contacts
    (a pad moving 10 mm per substep would start it with nodes 10 mm deep: a huge, stiff residual
    that 4 iterations do not resolve).

    The plain guess lets a node of a squeezed object that a turn or slide of the pad moves by
    micrometres start outside the pad; Newton sees no contact stiffness there, sends the node
    millimetres into the pad, and the line search shortens the whole world's step to ~1 %.
    Only the nodes of worlds with ``solve`` set are moved. Node ``i``'s row of ``keep_pad_depth``."""
    w = node_world[i]
    if solve[w] == 0:
        return
    slots = pads_per_world + 1
    fr = free[i]
    for k in range(pads_per_world):
        pad = w * pads_per_world + k
        n = lag_normal[i * slots + 1 + k]  # pad frame
        guess = wp.quat_rotate_inv(pad_rot1[pad], x[i] - pad_pos1[pad])
        moved = int(0)
        if lag_normal_force[i * slots + 1 + k] > 0.0:
            start = wp.quat_rotate_inv(pad_rot0[pad], x_start[i] - pad_pos0[pad])
            held = start_face_normal(x_start[i], pad_pos0[pad], pad_rot0[pad], pad_half[pad], n)
            guess = guess + wp.dot(start - guess, held) * held
            moved = 1
        else:
            depth, n_face = face_contact(guess, pad_half[pad], n)
            if depth > 0.0:
                guess = guess + depth * n_face
                moved = 1
        if moved == 1:
            kept = pad_pos1[pad] + wp.quat_rotate(pad_rot1[pad], guess)
            x[i] = wp.cw_mul(fr, kept) + wp.cw_mul(wp.vec3(1.0) - fr, x[i])
    xi = x[i]
    if xi[1] < 0.0 and x_start[i][1] >= 0.0 and fr[1] > 0.0:
        x[i] = wp.vec3(xi[0], 0.0, xi[2])


@wp.kernel
def keep_pad_depth(
    x_start: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    solve: wp.array(dtype=int),
    free: wp.array(dtype=wp.vec3),
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    lag_normal_force: wp.array(dtype=float),
    lag_normal: wp.array(dtype=wp.vec3),
    x: wp.array(dtype=wp.vec3),
):
    """``keep_pad_depth_node`` for every node."""
    keep_pad_depth_node(wp.tid(), x_start, node_world, solve, free, pad_pos0, pad_rot0, pad_pos1, pad_rot1, pad_half,
                        pads_per_world, lag_normal_force, lag_normal, x)


@wp.kernel
def deepest_contact(
    x: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    lag_normal: wp.array(dtype=wp.vec3),
    depth_out: wp.array(dtype=float),
):
    """Deepest penetration (m) per world of the iterate x: below the ground or behind a node's
    contact face of a pad (at the substep's end pose)."""
    i = wp.tid()
    w = node_world[i]
    xi = x[i]
    depth = -xi[1]
    slots = pads_per_world + 1
    for k in range(pads_per_world):
        pad = w * pads_per_world + k
        local = wp.quat_rotate_inv(pad_rot1[pad], xi - pad_pos1[pad])
        depth = wp.max(depth, face_penetration(local, pad_half[pad], lag_normal[i * slots + 1 + k]))
    if depth > 0.0:
        wp.atomic_max(depth_out, w, depth)


@wp.func
def clamp_depth_node(
    i: int,
    node_world: wp.array(dtype=int),
    solve: wp.array(dtype=int),
    free: wp.array(dtype=wp.vec3),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    lag_normal: wp.array(dtype=wp.vec3),
    bound: float,
    target: float,
    x: wp.array(dtype=wp.vec3),
    clamped: wp.array(dtype=int),
):
    """Put a node that the substep's solve left deeper than ``bound`` (m) behind its contact face of
    a pad, or below the ground, back to depth ``target`` (m, < bound: float32 rounding of the moved
    position stays within the bound) along that face's normal (free axes only),
    and flag its world: a solve that did not resolve a violent contact returns a state within the
    bound, reported (``SolveStats.penetrated``) rather than silently penetrated. Only the worlds
    with ``solve`` set are touched. Node ``i``'s row of ``clamp_depth``."""
    w = node_world[i]
    if solve[w] == 0:
        return
    fr = free[i]
    slots = pads_per_world + 1
    for k in range(pads_per_world):
        pad = w * pads_per_world + k
        rot = pad_rot1[pad]
        local = wp.quat_rotate_inv(rot, x[i] - pad_pos1[pad])
        n = lag_normal[i * slots + 1 + k]
        depth, n_face = face_contact(local, pad_half[pad], n)
        if depth > bound:
            moved = pad_pos1[pad] + wp.quat_rotate(rot, local + (depth - target) * n_face)
            x[i] = wp.cw_mul(fr, moved) + wp.cw_mul(wp.vec3(1.0) - fr, x[i])
            clamped[w] = 1
    xi = x[i]
    if xi[1] < -bound and fr[1] > 0.0:
        x[i] = wp.vec3(xi[0], -target, xi[2])
        clamped[w] = 1


@wp.kernel
def clamp_depth(
    node_world: wp.array(dtype=int),
    solve: wp.array(dtype=int),
    free: wp.array(dtype=wp.vec3),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    lag_normal: wp.array(dtype=wp.vec3),
    bound: float,
    target: float,
    x: wp.array(dtype=wp.vec3),
    clamped: wp.array(dtype=int),
):
    """``clamp_depth_node`` for every node."""
    clamp_depth_node(wp.tid(), node_world, solve, free, pad_pos1, pad_rot1, pad_half, pads_per_world, lag_normal,
                     bound, target, x, clamped)
