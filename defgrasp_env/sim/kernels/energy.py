"""Incremental potential of a backward-Euler substep (the line search's objective, ``kernels.line_search``).

E(x) = sum_nodes [ m/(2 dt^2) |x - x_hat|^2 - (m g + f_ext) . (x - x_start) + penalty_energy(d) (ground, pads)
                   + mu f_n f0(|slip_t|) ]  +  sum_tets V0 psi(F),
the function whose stationary point the Newton solve seeks; f0 is the integral of the smoothed
Coulomb law (f0(s) = s^2/eps - s^3/(3 eps^2) + eps/3 below eps, s beyond). Sums go to float64.
"""

import warp as wp

from .contact import pad_slip, penalty_energy
from .pad_faces import face_penetration, start_face_normal
from .elastic import deformation_gradient, polar_rotation, spare_tet

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


@wp.func
def friction_potential(mu: float, normal_force: float, slip: wp.vec3, n: wp.vec3, eps: float):
    slip_t = slip - wp.dot(slip, n) * n
    s = wp.length(slip_t)
    f0 = s
    if s < eps:
        f0 = s * s / eps - s * s * s / (3.0 * eps * eps) + eps / 3.0
    return mu * normal_force * f0


@wp.func
def strain_energy_density(f: wp.mat33, rotation: wp.quat, mu: float, lam: float):
    """psi(F) (J/m^3) of the fixed-corotated model, ``rotation`` the polar rotation of F."""
    d = f - wp.quat_to_matrix(rotation)
    j = wp.determinant(f)
    return mu * wp.ddot(d, d) + 0.5 * lam * (j - 1.0) * (j - 1.0)


@wp.func
def node_energy_row(
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
    energy: wp.array(dtype=wp.float64),
):
    """energy[w] += node ``i``'s terms of the incremental potential (inertia, gravity and external
    force, ground and pad penalties, lagged friction), if its world is active."""
    w = node_world[i]
    if world_active[w] == 0:
        return
    xi = x[i]
    m = mass[i]
    eps = stick_velocity * dt
    slots = pads_per_world + 1
    d = xi - (x_start[i] + dt * v_start[i])
    e = 0.5 * m / (dt * dt) * wp.dot(d, d) - wp.dot(m * gravity + external_force[i], xi - x_start[i])
    depth = wp.max(-xi[1], 0.0)
    k_i = stiffness[i]
    e += penalty_energy(k_i, depth, knee)
    lag_fn = lag_normal_force[i * slots]
    if lag_fn > 0.0:
        e += friction_potential(ground_mu, lag_fn, xi - x_start[i], wp.vec3(0.0, 1.0, 0.0), eps)
    for k in range(pads_per_world):
        pad = w * pads_per_world + k
        rot1 = pad_rot1[pad]
        local = wp.quat_rotate_inv(rot1, xi - pad_pos1[pad])
        n_local = lag_normal[i * slots + 1 + k]
        depth = face_penetration(local, pad_half[pad], n_local)
        if depth > 0.0:
            e += penalty_energy(k_i, depth, knee)
        lag_fn = lag_normal_force[i * slots + 1 + k]
        if lag_fn > 0.0:
            slip = pad_slip(xi, x_start[i], pad_pos0[pad], pad_rot0[pad], pad_pos1[pad], rot1)
            n_lag = wp.quat_rotate(rot1, start_face_normal(x_start[i], pad_pos0[pad], pad_rot0[pad], pad_half[pad],
                                                           n_local))
            e += friction_potential(pad_mu, lag_fn, slip, n_lag, eps)
    wp.atomic_add(energy, w, wp.float64(e))


@wp.kernel
def node_energy(
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
    energy: wp.array(dtype=wp.float64),
):
    node_energy_row(wp.tid(), x, x_start, v_start, mass, node_world, world_active, external_force, gravity, dt, pad_pos0,
                    pad_rot0, pad_pos1, pad_rot1, pad_half, pads_per_world, lag_normal_force, lag_normal, stiffness, knee,
                    ground_mu, pad_mu, stick_velocity, energy)


@wp.func
def tet_energy_row(
    t: int,
    x: wp.array(dtype=wp.vec3),
    tets: wp.array(dtype=wp.vec4i),
    rest_inv: wp.array(dtype=wp.mat33),
    rest_volume: wp.array(dtype=float),
    tet_mu: wp.array(dtype=float),
    tet_lambda: wp.array(dtype=float),
    tet_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    tet_rotation: wp.array(dtype=wp.quat),
    energy: wp.array(dtype=wp.float64),
    keep: int,
    kept_rotation: wp.array(dtype=wp.quat),
):
    """energy += V0 psi(F) per world; ``tet_rotation`` (the rotations at the last evaluated
    positions) warm-starts the polar rotation of F, which ``keep`` = 1 stores in ``kept_rotation``
    (what the next evaluation at these positions would compute: ``elastic.evaluate_tet``'s
    ``rotation_known``)."""
    w = tet_world[t]
    if world_active[w] == 0:
        return
    idx = tets[t]
    if spare_tet(idx):
        return
    f = deformation_gradient(x[idx[0]], x[idx[1]], x[idx[2]], x[idx[3]], rest_inv[t])
    q = polar_rotation(f, tet_rotation[t])
    if keep != 0:
        kept_rotation[t] = q
    e = rest_volume[t] * strain_energy_density(f, q, tet_mu[t], tet_lambda[t])
    wp.atomic_add(energy, w, wp.float64(e))


@wp.kernel
def tet_energy(
    x: wp.array(dtype=wp.vec3),
    tets: wp.array(dtype=wp.vec4i),
    rest_inv: wp.array(dtype=wp.mat33),
    rest_volume: wp.array(dtype=float),
    tet_mu: wp.array(dtype=float),
    tet_lambda: wp.array(dtype=float),
    tet_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    tet_rotation: wp.array(dtype=wp.quat),
    energy: wp.array(dtype=wp.float64),
):
    """energy += V0 psi(F) per world; ``tet_rotation`` (the rotations at the last evaluated
    positions) warm-starts the polar rotation of F."""
    tet_energy_row(wp.tid(), x, tets, rest_inv, rest_volume, tet_mu, tet_lambda, tet_world, world_active, tet_rotation,
                   energy, 0, tet_rotation)
