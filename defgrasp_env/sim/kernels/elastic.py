"""Fixed-corotated hyperelastic tetrahedra: forces, the Hessian's stress differential, preconditioner
blocks, stress.

Energy density psi(F) = mu |F - R|^2 + lam/2 (J - 1)^2 (Stomakhin et al. 2012), R the rotation of
the polar decomposition of F (from the SVD with signed singular values, so inverted tets are pushed
back). mu and lam are the Lamé parameters: the small-strain limit is linear elasticity.
First Piola stress P = 2 mu (F - R) + lam (J - 1) cof(F), cof(F) = dJ/dF.
The Hessian used by Newton is 2 mu (I - dR/dF)_+ + lam cof (x) cof. Its shear part acts on dF
through M = R^T dF: the symmetric part of M is kept, the skew part (an infinitesimal rotation) is
scaled by c = clamp(1 - 3 / tr(S), 0, 1), S = R^T F (1 where tr(S) <= 0, for inverted tets).
The exact eigenvalue of the rotation pair (i, j) in the singular frame is 2 mu (1 - 2 / (s_i + s_j));
c uses the mean pair sum 2 tr(S) / 3 for all three pairs, so products need R only, not the SVD
frames. Without the -dR/dF term (the projective-dynamics majorizer 2 mu I) infinitesimal rotations
of the elements would be as stiff as shear, and Newton converged only at a rate of about
1 / (L/a)^2 per iteration on bending of slender objects (a beam, a rope). R comes from a
warm-started Newton iteration on the rotation (``polar_rotation``), seeded by the SVD once per
substep. The small
lam (J - 1) d2J/dF2 term (zero at rest) is dropped. The Hessian is positive semi-definite (plus
the positive mass term); the energy line search keeps every Newton step a descent step; the
gradient, hence the converged solution, is exact. The block-Jacobi preconditioner keeps the
majorizer's diagonal blocks 2 mu |b|^2 I + lam (cof b)(cof b)^T.
Node a of a tet enters F through b_a = row (a-1) of D_m^-1 (a = 1..3) and b_0 = -(b_1 + b_2 + b_3):
F = sum_a x_a (outer) b_a, and the gradient of the element energy w.r.t. x_a is V0 P b_a.
"""

import warp as wp

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


@wp.func
def column(m: wp.mat33, j: int):
    return wp.vec3(m[0, j], m[1, j], m[2, j])


@wp.func
def row(m: wp.mat33, i: int):
    return wp.vec3(m[i, 0], m[i, 1], m[i, 2])


@wp.func
def spare_tet(idx: wp.vec4i):
    """Whether a tet is a spare row of a slotted model (``sim.model``: one node named four times;
    an object's tets are never degenerate): it adds exact zeros, so the tet kernels skip it."""
    return idx[0] == idx[1]


@wp.func
def pick_vertex(b0: wp.vec3, b1: wp.vec3, b2: wp.vec3, b3: wp.vec3, v: int):
    """The one of a tet's four shape-function gradients ``b0..b3`` (1/m) that belongs to vertex ``v``."""
    if v == 1:
        return b1
    if v == 2:
        return b2
    if v == 3:
        return b3
    return b0


@wp.func
def cofactor(f: wp.mat33):
    """dJ/dF: columns (f1 x f2, f2 x f0, f0 x f1) for the columns f0, f1, f2 of F."""
    f0 = column(f, 0)
    f1 = column(f, 1)
    f2 = column(f, 2)
    return wp.matrix_from_cols(wp.cross(f1, f2), wp.cross(f2, f0), wp.cross(f0, f1))


@wp.func
def deformation_gradient(x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, x3: wp.vec3, rest_inv: wp.mat33):
    return wp.matrix_from_cols(x1 - x0, x2 - x0, x3 - x0) * rest_inv


@wp.func
def first_piola(f: wp.mat33, cof: wp.mat33, r: wp.mat33, mu: float, lam: float):
    """P = 2 mu (F - R) + lam (J - 1) cof(F), R the rotation of the polar decomposition of F."""
    return 2.0 * mu * (f - r) + lam * (wp.determinant(f) - 1.0) * cof


@wp.func
def svd_rotation(f: wp.mat33):
    """R = U V^T from the SVD of F with signed singular values (det R = +1, also for det F < 0)."""
    u, sigma, v = wp.svd3(f)
    return wp.quat_from_matrix(u * wp.transpose(v))


@wp.func
def newton_polar(f: wp.mat33, guess: wp.quat):
    """Newton's method for the rotation R that maximises tr(R^T F), from ``guess``. With A = R^T F,
    the gradient of tr(R^T F) over a body rotation d (R <- R exp(d)) is
    g = (A21 - A12, A02 - A20, A10 - A01) and its Hessian -(tr(A) I - sym(A)), so
    d = (tr(A) I - sym(A))^-1 g. That matrix is positive definite exactly near the maximum (its
    eigenvalues are the pair sums of the signed singular values of F), so it also tells whether
    a stationary point is the maximum. Returns the rotation and whether it converged: |d| < 1e-7
    rad, or < 1e-5 rad after 6 steps (float32 noise of an ill-conditioned F; the convergence
    is quadratic, so from a good guess it takes 1-3 steps)."""
    q = guess
    state = int(0)  # 0 iterating, 1 converged, -1 not near the maximum
    angle = float(1.0)
    for _ in range(6):
        if state == 0:
            a = wp.transpose(wp.quat_to_matrix(q)) * f
            g = wp.vec3(a[2, 1] - a[1, 2], a[0, 2] - a[2, 0], a[1, 0] - a[0, 1])
            h = wp.trace(a) * wp.identity(n=3, dtype=float) - 0.5 * (a + wp.transpose(a))
            if h[0, 0] <= 0.0 or h[0, 0] * h[1, 1] - h[0, 1] * h[1, 0] <= 0.0 or wp.determinant(h) <= 0.0:
                state = -1
            else:
                d = wp.inverse(h) * g
                angle = wp.length(d)
                if angle > 0.0:
                    q = wp.normalize(q * wp.quat_from_axis_angle(d / angle, angle))
                if angle < 1.0e-7:
                    state = 1
    return q, state == 1 or (state == 0 and angle < 1.0e-5)


@wp.func
def polar_rotation(f: wp.mat33, guess: wp.quat):
    """Rotation of the polar decomposition F = R S (the R in SO(3) that maximises tr(R^T F)):
    ``newton_polar`` from ``guess``, else from the float32 SVD's rotation (which alone is off by
    up to 5e-4 for some F), else that rotation."""
    q, ok = newton_polar(f, guess)
    if not ok:
        seed = svd_rotation(f)
        q, ok = newton_polar(f, seed)
        if not ok:
            q = seed
    return q


@wp.func
def twist_factor(trace_s: float):
    """Kept fraction of the rotational (skew) part of R^T dF, from tr(S) = tr(R^T F)."""
    if trace_s <= 0.0:
        return 1.0
    return wp.clamp(1.0 - 3.0 / trace_s, 0.0, 1.0)


@wp.func
def von_mises_of(f: wp.mat33, piola: wp.mat33):
    """Von Mises stress (Pa) of the Cauchy stress sigma = P F^T / J."""
    j = wp.max(wp.abs(wp.determinant(f)), 1.0e-6)
    sigma = piola * wp.transpose(f) / j
    mean = wp.trace(sigma) / 3.0
    s = sigma - mean * wp.identity(n=3, dtype=float)
    return wp.sqrt(1.5 * wp.ddot(s, s))


@wp.func
def evaluate_tet(
    t: int,
    x: wp.array(dtype=wp.vec3),
    tets: wp.array(dtype=wp.vec4i),
    rest_inv: wp.array(dtype=wp.mat33),
    rest_volume: wp.array(dtype=float),
    tet_mu: wp.array(dtype=float),
    tet_lambda: wp.array(dtype=float),
    tet_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    # in: warm start; out: the rotation at x
    tet_rotation: wp.array(dtype=wp.quat),
    # 1: the rotation at x is known (``known_rotation``: the line search's last trial computed it from
    # the same warm start at the same positions, ``energy.tet_energy_row``), so it is not computed again
    rotation_known: int,
    known_rotation: wp.array(dtype=wp.quat),
    # outputs
    residual: wp.array(dtype=wp.vec3),
    diag_block: wp.array(dtype=wp.mat33),
    elastic_force: wp.array(dtype=wp.vec3),
    tet_cof: wp.array(dtype=wp.mat33),
    von_mises: wp.array(dtype=float),
    tet_r: wp.array(dtype=wp.mat33),
    tet_twist: wp.array(dtype=float),
    outputs: int,
    add_energy: int,
    energy: wp.array(dtype=wp.float64),
):
    """Row ``t`` of ``evaluate_tets``."""
    if world_active[tet_world[t]] == 0:
        return
    idx = tets[t]
    if spare_tet(idx):
        return
    dm_inv = rest_inv[t]
    f = deformation_gradient(x[idx[0]], x[idx[1]], x[idx[2]], x[idx[3]], dm_inv)
    cof = cofactor(f)
    mu = tet_mu[t]
    lam = tet_lambda[t]
    q = wp.quat()
    if rotation_known != 0:
        q = known_rotation[t]
    else:
        q = polar_rotation(f, tet_rotation[t])
    r = wp.quat_to_matrix(q)
    p = first_piola(f, cof, r, mu, lam)
    v0 = rest_volume[t]
    tet_rotation[t] = q
    if add_energy != 0:
        d = f - r
        j = wp.determinant(f)
        wp.atomic_add(energy, tet_world[t], wp.float64(v0 * (mu * wp.ddot(d, d) + 0.5 * lam * (j - 1.0) * (j - 1.0))))
    if outputs == 0:
        tet_cof[t] = cof
        tet_r[t] = r
        tet_twist[t] = twist_factor(wp.trace(wp.transpose(r) * f))
    else:
        von_mises[t] = von_mises_of(f, p)
    b1 = row(dm_inv, 0)
    b2 = row(dm_inv, 1)
    b3 = row(dm_inv, 2)
    b0 = -(b1 + b2 + b3)
    for a in range(4):
        b = pick_vertex(b0, b1, b2, b3, a)
        force = -v0 * (p * b)
        wp.atomic_add(residual, idx[a], force)
        if outputs == 0:
            cb = cof * b
            block = v0 * (2.0 * mu * wp.dot(b, b) * wp.identity(n=3, dtype=float) + lam * wp.outer(cb, cb))
            wp.atomic_add(diag_block, idx[a], block)
        else:
            wp.atomic_add(elastic_force, idx[a], force)


@wp.kernel
def evaluate_tets(
    x: wp.array(dtype=wp.vec3),
    tets: wp.array(dtype=wp.vec4i),
    rest_inv: wp.array(dtype=wp.mat33),
    rest_volume: wp.array(dtype=float),
    tet_mu: wp.array(dtype=float),
    tet_lambda: wp.array(dtype=float),
    tet_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    # in: warm start; out: the rotation at x
    tet_rotation: wp.array(dtype=wp.quat),
    # outputs
    residual: wp.array(dtype=wp.vec3),
    diag_block: wp.array(dtype=wp.mat33),
    elastic_force: wp.array(dtype=wp.vec3),
    tet_cof: wp.array(dtype=wp.mat33),
    von_mises: wp.array(dtype=float),
    tet_r: wp.array(dtype=wp.mat33),
    tet_twist: wp.array(dtype=float),
    outputs: int,
    add_energy: int,
    energy: wp.array(dtype=wp.float64),
):
    """Add each tet's elastic force to ``residual`` and store the polar rotation of F (the next warm
    start); then, in a Newton iteration (``outputs`` = 0), add its Hessian diagonal blocks to
    ``diag_block`` and store cof(F), R as a matrix and the twist factor for the Hessian's assembly
    (``hessian_blocks.py``), or, in the outputs pass after a solve (``outputs`` = 1), add the force
    to ``elastic_force`` and store the von Mises stress: each pass writes only what is read after it (the same values as
    both passes writing everything). ``add_energy`` = 1: also add V0 psi(F) (``energy.tet_energy``'s
    term, with the rotation just found) to ``energy[world]`` (the line search's start energy, from
    the F and R this pass computes anyway)."""
    evaluate_tet(wp.tid(), x, tets, rest_inv, rest_volume, tet_mu, tet_lambda, tet_world, world_active, tet_rotation,
                 0, tet_rotation, residual, diag_block, elastic_force, tet_cof, von_mises, tet_r, tet_twist, outputs,
                 add_energy, energy)


@wp.func
def stress_differential(df: wp.mat33, cof: wp.mat33, r: wp.mat33, twist: float, mu: float, lam: float,
                        volume: float):
    """V0 dP of the Hessian above for a change ``df`` of F (its product with b_a is the force change
    of node a); ``cof``, ``r``, ``twist``: the tet's stored cof(F), R and twist factor."""
    m = wp.transpose(r) * df
    # remove the fraction (1 - c) of the skew part of M = R^T dF (the rotation, -dR/dF)
    df_shear = df - (0.5 * (1.0 - twist)) * (r * (m - wp.transpose(m)))
    return volume * (2.0 * mu * df_shear + lam * wp.ddot(cof, df) * cof)


@wp.func
def frame_rotation(f: wp.mat33):
    """A rotation near F's polar rotation, for a few flops: F's first two columns made orthonormal
    (Gram-Schmidt) and completed by their cross product; the identity where they are (nearly)
    parallel or zero. Off the polar rotation by the shear's angle (degrees at the strains here)."""
    c0 = column(f, 0)
    c1 = column(f, 1)
    l0 = wp.length(c0)
    if l0 <= 1.0e-12:
        return wp.quat_identity()
    e0 = c0 / l0
    u1 = c1 - wp.dot(c1, e0) * e0
    l1 = wp.length(u1)
    if l1 <= 1.0e-6 * wp.length(c1) or l1 <= 1.0e-12:
        return wp.quat_identity()
    e1 = u1 / l1
    return wp.quat_from_matrix(wp.matrix_from_cols(e0, e1, wp.cross(e0, e1)))


@wp.func
def seed_rotation_tet(
    t: int,
    x: wp.array(dtype=wp.vec3),
    tets: wp.array(dtype=wp.vec4i),
    rest_inv: wp.array(dtype=wp.mat33),
    tet_rotation: wp.array(dtype=wp.quat),
):
    """Tet ``t``'s row of ``seed_rotations``."""
    idx = tets[t]
    if spare_tet(idx):
        return
    f = deformation_gradient(x[idx[0]], x[idx[1]], x[idx[2]], x[idx[3]], rest_inv[t])
    tet_rotation[t] = polar_rotation(f, frame_rotation(f))


@wp.kernel
def seed_rotations(
    x: wp.array(dtype=wp.vec3),
    tets: wp.array(dtype=wp.vec4i),
    rest_inv: wp.array(dtype=wp.mat33),
    tet_rotation: wp.array(dtype=wp.quat),
):
    """Polar rotation of every tet (``polar_rotation``: Newton from ``frame_rotation``, the SVD only
    where that fails): the warm start of ``polar_rotation`` for a substep, so that results depend on
    the state only, not on the solver's history. Seeded by the SVD alone before (2026-12-07): on a
    2-core Xeon 0.37 us a tet with Warp's ``svd3``, 0.22-0.26 us this way (benchmarks/RESULTS.md)."""
    seed_rotation_tet(wp.tid(), x, tets, rest_inv, tet_rotation)
