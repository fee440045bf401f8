"""Fixed-corotated hyperelastic tetrahedra: forces, Hessian products, preconditioner blocks, stress.

Energy density psi(F) = mu |F - R|^2 + lam/2 (J - 1)^2 (Stomakhin et al. 2012), R the rotation of
the polar decomposition of F (from the SVD with signed singular values, so inverted tets are pushed
back). mu and lam are the Lamé parameters: the small-strain limit is linear elasticity.
First Piola stress P = 2 mu (F - R) + lam (J - 1) cof(F), cof(F) = dJ/dF.
The Hessian used by Newton is 2 mu (I - dR/dF)_+ + lam cof (x) cof. Its shear part acts on
dF in the singular frame of F = U diag(s) V^T, M = U^T dF V: the symmetric part of M is kept, the
skew part (rotation) of the pair (i, j) is scaled by clamp(1 - 2/(s_i + s_j), 0, 1) (the exact
eigenvalue, projected to be positive semi-definite, and 1 where s_i + s_j <= 0 for inverted tets).
Without the -dR/dF term (the projective-dynamics majorizer 2 mu I) infinitesimal rotations of
the elements would be as stiff as shear, and Newton converged only at a rate of about
1 / (L/a)^2 per iteration on bending of slender objects (a beam, a rope). The small
lam (J - 1) d2J/dF2 term (zero at rest) is dropped. The Hessian is positive semi-definite (plus
the positive mass term); the energy line search keeps every Newton step a descent step; the
gradient, hence the converged solution, is exact. The block-Jacobi preconditioner keeps the
majorizer's diagonal blocks 2 mu |b|^2 I + lam (cof b)(cof b)^T.
Node a of a tet enters F through b_a = row (a-1) of D_m^-1 (a = 1..3) and b_0 = -(b_1 + b_2 + b_3):
F = sum_a x_a (outer) b_a, and the gradient of the element energy w.r.t. x_a is V0 P b_a.
"""

import warp as wp


@wp.func
def column(m: wp.mat33, j: int):
    return wp.vec3(m[0, j], m[1, j], m[2, j])


@wp.func
def row(m: wp.mat33, i: int):
    return wp.vec3(m[i, 0], m[i, 1], m[i, 2])


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
def first_piola(f: wp.mat33, cof: wp.mat33, u: wp.mat33, v: wp.mat33, mu: float, lam: float):
    """P = 2 mu (F - R) + lam (J - 1) cof(F) with R = U V^T from the SVD of F (signed singular values)."""
    return 2.0 * mu * (f - u * wp.transpose(v)) + lam * (wp.determinant(f) - 1.0) * cof


@wp.func
def twist_factor(s: float):
    """Scale of the rotational (skew) part of dF for a pair of singular values of sum s."""
    if s <= 0.0:
        return 1.0
    return wp.clamp(1.0 - 2.0 / s, 0.0, 1.0)


@wp.func
def von_mises_of(f: wp.mat33, piola: wp.mat33):
    """Von Mises stress (Pa) of the Cauchy stress sigma = P F^T / J."""
    j = wp.max(wp.abs(wp.determinant(f)), 1.0e-6)
    sigma = piola * wp.transpose(f) / j
    mean = wp.trace(sigma) / 3.0
    s = sigma - mean * wp.identity(n=3, dtype=float)
    return wp.sqrt(1.5 * wp.ddot(s, s))


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
    # outputs
    residual: wp.array(dtype=wp.vec3),
    diag_block: wp.array(dtype=wp.mat33),
    elastic_force: wp.array(dtype=wp.vec3),
    tet_cof: wp.array(dtype=wp.mat33),
    von_mises: wp.array(dtype=float),
    tet_u: wp.array(dtype=wp.mat33),
    tet_v: wp.array(dtype=wp.mat33),
    tet_twist: wp.array(dtype=wp.vec3),
):
    """Add each tet's elastic force to ``residual`` and ``elastic_force`` and its Hessian diagonal
    blocks to ``diag_block``; store cof(F), the singular frames U, V of F and the twist factors
    (pairs (1,2), (0,2), (0,1)) for Hessian products, and the von Mises stress."""
    t = wp.tid()
    if world_active[tet_world[t]] == 0:
        return
    idx = tets[t]
    dm_inv = rest_inv[t]
    f = deformation_gradient(x[idx[0]], x[idx[1]], x[idx[2]], x[idx[3]], dm_inv)
    cof = cofactor(f)
    mu = tet_mu[t]
    lam = tet_lambda[t]
    su, sig, sv = wp.svd3(f)
    p = first_piola(f, cof, su, sv, mu, lam)
    v0 = rest_volume[t]
    tet_cof[t] = cof
    tet_u[t] = su
    tet_v[t] = sv
    tet_twist[t] = wp.vec3(twist_factor(sig[1] + sig[2]), twist_factor(sig[0] + sig[2]),
                           twist_factor(sig[0] + sig[1]))
    von_mises[t] = von_mises_of(f, p)
    b1 = row(dm_inv, 0)
    b2 = row(dm_inv, 1)
    b3 = row(dm_inv, 2)
    b0 = -(b1 + b2 + b3)
    for a in range(4):
        b = b0
        if a == 1:
            b = b1
        elif a == 2:
            b = b2
        elif a == 3:
            b = b3
        force = -v0 * (p * b)
        cb = cof * b
        block = v0 * (2.0 * mu * wp.dot(b, b) * wp.identity(n=3, dtype=float) + lam * wp.outer(cb, cb))
        wp.atomic_add(residual, idx[a], force)
        wp.atomic_add(elastic_force, idx[a], force)
        wp.atomic_add(diag_block, idx[a], block)


@wp.kernel
def hessian_product_tets(
    direction: wp.array(dtype=wp.vec3),
    tets: wp.array(dtype=wp.vec4i),
    rest_inv: wp.array(dtype=wp.mat33),
    rest_volume: wp.array(dtype=float),
    tet_mu: wp.array(dtype=float),
    tet_lambda: wp.array(dtype=float),
    tet_cof: wp.array(dtype=wp.mat33),
    tet_world: wp.array(dtype=int),
    world_active: wp.array(dtype=int),
    product: wp.array(dtype=wp.vec3),
    tet_u: wp.array(dtype=wp.mat33),
    tet_v: wp.array(dtype=wp.mat33),
    tet_twist: wp.array(dtype=wp.vec3),
):
    """product += K * direction (the elastic Hessian above), accumulated per node."""
    t = wp.tid()
    if world_active[tet_world[t]] == 0:
        return
    idx = tets[t]
    dm_inv = rest_inv[t]
    b1 = row(dm_inv, 0)
    b2 = row(dm_inv, 1)
    b3 = row(dm_inv, 2)
    b0 = -(b1 + b2 + b3)
    p0 = direction[idx[0]]
    df = wp.outer(direction[idx[1]] - p0, b1) + wp.outer(direction[idx[2]] - p0, b2) + wp.outer(
        direction[idx[3]] - p0, b3)
    cof = tet_cof[t]
    su = tet_u[t]
    sv = tet_v[t]
    c = tet_twist[t]
    m = wp.transpose(su) * df * sv
    # remove the fraction (1 - c) of the skew part of M = U^T dF V (the rotation, -dR/dF)
    a01 = (1.0 - c[2]) * 0.5 * (m[0, 1] - m[1, 0])
    a02 = (1.0 - c[1]) * 0.5 * (m[0, 2] - m[2, 0])
    a12 = (1.0 - c[0]) * 0.5 * (m[1, 2] - m[2, 1])
    rotation = wp.mat33(0.0, a01, a02, -a01, 0.0, a12, -a02, -a12, 0.0)
    df_shear = df - su * rotation * wp.transpose(sv)
    dp = rest_volume[t] * (2.0 * tet_mu[t] * df_shear + tet_lambda[t] * wp.ddot(cof, df) * cof)
    wp.atomic_add(product, idx[0], dp * b0)
    wp.atomic_add(product, idx[1], dp * b1)
    wp.atomic_add(product, idx[2], dp * b2)
    wp.atomic_add(product, idx[3], dp * b3)
