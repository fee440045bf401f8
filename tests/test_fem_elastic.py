"""FEM core, elasticity: patch test (affine deformations) and rigid-motion invariance.

Truth: the fixed-corotated stress of a homogeneous deformation F = A, computed in float64 numpy
from its definition (P = 2 mu (F - R) + lam (J - 1) cof F, sigma = P F^T / J, R the polar
rotation of F), and the consistent nodal forces of a uniform stress, f_a = -sum_t V_t P grad N_a.
The forces and stresses are read from a solver step in which every node coordinate is prescribed
(Model fixed_axes all True, Control.prescribed_positions = the deformed positions), so the
state returned by the solver is evaluated exactly at that configuration.

Tolerances (the kernel works in float32, unit roundoff u = 6e-8): F is formed from float32
positions and a float32 D_m^-1, so each entry of F carries an absolute error of a few u times
|D_m^-1| |x| / h (about 10 u for these meshes, whose extent is a few cells). The stress depends on
F - R and J - 1, i.e. on the strain; its error relative to the stress is therefore about
10 u / strain + the float32 SVD error (~ 10 u). For the strains here (>= 0.05) that is <~ 2e-5:
the bounds below are 1e-4 relative (a margin of 5); a wrong formula (a missing factor, a transposed
cofactor, a wrong rotation) is off by O(1).
"""

from __future__ import annotations

import numpy as np
import pytest

from defgrasp_env.sim.materials import Material
from defgrasp_env.sim.meshing import make_object_mesh
from defgrasp_env.sim.model import build_model
from defgrasp_env.sim.solver import ImplicitSolver, SolverConfig
from defgrasp_env.sim.state import Control, State
from fem_meshes import box_mesh, jittered

MATERIAL = Material(density=1000.0, youngs_modulus=1e6, poisson_ratio=0.3)
STRESS_REL_TOL = 1e-4       # see module docstring: float32 F at strain >= 0.05


def rotation(axis, angle_rad) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle_rad) * k + (1 - np.cos(angle_rad)) * k @ k


def analytic_stress(f: np.ndarray, mu: float, lam: float):
    """First Piola P and Cauchy sigma of the fixed-corotated model at F (float64)."""
    u, _, vt = np.linalg.svd(f)
    r = u @ vt
    if np.linalg.det(r) < 0:      # never for the deformations used here (det F > 0)
        raise AssertionError("reflection in polar decomposition")
    j = np.linalg.det(f)
    cof = j * np.linalg.inv(f).T
    p = 2.0 * mu * (f - r) + lam * (j - 1.0) * cof
    return p, p @ f.T / j


def von_mises(sigma: np.ndarray) -> float:
    s = sigma - np.trace(sigma) / 3.0 * np.eye(3)
    return float(np.sqrt(1.5 * np.sum(s * s)))


def consistent_forces(mesh, p: np.ndarray) -> np.ndarray:
    """f_a = -sum_t V_t P grad N_a^t (float64) for a uniform first Piola stress P."""
    x = mesh.nodes[mesh.tets]
    dm = np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]], axis=2)
    b = np.linalg.inv(dm)                      # rows: grad N_1..3
    vol = np.linalg.det(dm) / 6.0
    grads = np.concatenate([-b.sum(axis=1, keepdims=True), b], axis=1)   # [T,4,3]
    per = -vol[:, None, None] * np.einsum("ij,tkj->tki", p, grads)
    forces = np.zeros_like(mesh.nodes)
    np.add.at(forces, mesh.tets.ravel(), per.reshape(-1, 3))
    return forces


def evaluate_at(mesh, material: Material, positions: np.ndarray):
    """Elastic force [N,3] and von Mises [T] of the solver's state with every node prescribed."""
    fixed = np.ones((len(mesh.nodes), 3), bool)
    model = build_model([mesh], [material], gravity=(0.0, 0.0, 0.0), fixed_axes=[fixed], device="cpu")
    state, control = State.from_model(model), Control.from_model(model)
    control.prescribed_positions.assign(positions.astype(np.float32))
    stats = ImplicitSolver(model, SolverConfig(substeps=1)).step(state, state, control, dt=1e-3)
    assert not stats.diverged.any()
    np.testing.assert_array_equal(state.positions.numpy(), positions.astype(np.float32))
    return state.elastic_force.numpy().astype(np.float64), state.von_mises.numpy().astype(np.float64)


def patch_meshes():
    box = box_mesh((0.05, 0.04, 0.03), (5, 4, 3))
    return {
        "jittered_box": jittered(box, amplitude=0.3 * 0.01, seed=1),   # irregular interior tets
        "sphere": make_object_mesh("sphere"),                          # unstructured stuffing mesh
    }


DEFORMATIONS = {
    # name: A (x = A X + b), with principal strains between 5 % and 20 %
    "stretch": np.diag([1.10, 0.95, 1.05]),
    "compress_shear_rotate": rotation((1, 2, 3), 0.7) @ np.array(
        [[0.90, 0.08, 0.00], [0.08, 1.05, -0.05], [0.00, -0.05, 0.93]]),
    "large_rotation_stretch": rotation((0, 1, 0), 2.5) @ np.diag([1.2, 1.0, 0.9]),
}


@pytest.mark.parametrize("mesh_name", ["jittered_box", "sphere"])
@pytest.mark.parametrize("deformation", sorted(DEFORMATIONS))
def test_patch_affine_deformation(mesh_name, deformation):
    mesh = patch_meshes()[mesh_name]
    a = DEFORMATIONS[deformation]
    b = np.array([0.01, 0.02, -0.005])
    positions = mesh.nodes @ a.T + b
    mu, lam = MATERIAL.lame
    p, sigma = analytic_stress(a, mu, lam)
    force, vm = evaluate_at(mesh, MATERIAL, positions)

    # every tet carries the analytic uniform von Mises stress
    vm_true = von_mises(sigma)
    stress_scale = np.linalg.norm(sigma, 2)
    assert np.max(np.abs(vm - vm_true)) <= STRESS_REL_TOL * stress_scale, (vm.min(), vm.max(), vm_true)

    # nodal forces: the consistent forces of the uniform stress (zero on interior nodes, the
    # surface traction on boundary nodes), compared relative to the largest nodal force
    expected = consistent_forces(mesh, p)
    scale = np.max(np.linalg.norm(expected, axis=1))
    err = np.max(np.linalg.norm(force - expected, axis=1))
    assert err <= STRESS_REL_TOL * scale, (err, scale)
    inner = np.setdiff1d(np.arange(len(mesh.nodes)), np.unique(mesh.surface))
    assert len(inner) > 0
    assert np.max(np.linalg.norm(force[inner], axis=1)) <= STRESS_REL_TOL * scale
    # the forces of the whole body are in equilibrium
    assert np.linalg.norm(force.sum(axis=0)) <= STRESS_REL_TOL * scale


@pytest.mark.parametrize("mesh_name", ["jittered_box", "sphere"])
def test_rigid_motion_is_stress_free(mesh_name):
    """x = Q X + b with Q a rotation: zero stress and zero elastic force.

    Bound: positions of magnitude <= 0.1 m are rounded to float32 (~6e-9 m), which over an
    edge of >= 3 mm is a spurious strain of ~2e-6 (F - Q entries), plus the float32 SVD
    (~1e-6). The stress from a strain e is at most (2 mu + 3 lam) e ~ 3 E e: so von Mises
    <= 3e-5 E is a margin of ~5 over that estimate, and a nodal force <= 3e-5 E h^2 with h the
    cell size. A solver that does not remove rotation (linear elasticity) gives stresses of
    order E (angle 2.5 rad) here.
    """
    mesh = patch_meshes()[mesh_name]
    q = rotation((0.3, -1.0, 0.5), 2.5)
    positions = mesh.nodes @ q.T + np.array([0.03, 0.05, -0.02])
    force, vm = evaluate_at(mesh, MATERIAL, positions)
    e = MATERIAL.youngs_modulus
    assert np.max(vm) <= 3e-5 * e, np.max(vm)
    h = 0.01    # cell size of both meshes (box 10 mm cells, sphere default resolution 9 mm)
    assert np.max(np.linalg.norm(force, axis=1)) <= 3e-5 * e * h * h, np.max(np.abs(force))


def test_fixed_axes_prescribe_positions_exactly():
    """The harness used above: prescribed nodes end exactly at their targets (no solve)."""
    mesh = box_mesh((0.02, 0.02, 0.02), (2, 2, 2))
    positions = mesh.nodes * 1.1
    force, vm = evaluate_at(mesh, MATERIAL, positions)
    assert np.all(np.isfinite(force)) and np.all(vm > 0)


@pytest.mark.parametrize("deformation", list(DEFORMATIONS))
def test_newton_pass_sums_the_strain_energy_of_the_line_search(deformation):
    """``evaluate_tets(add_energy=1)`` (the substep's first Newton pass, which also sums the line
    search's start energy) against ``tet_energy`` (the line search's own energy pass) and the
    analytic energy of a homogeneous deformation, V (mu |A - R|^2 + lam / 2 (J - 1)^2): equal to
    float32 rounding (per-tet terms in float32, summed in float64: 1e-5 relative to the analytic
    value at strains >= 0.05, 1e-6 between the two kernels, which share F and differ only in
    the polar rotation's last iterate)."""
    import warp as wp

    from defgrasp_env.sim.kernels import elastic as ke
    from defgrasp_env.sim.kernels import energy as kenergy

    mesh = patch_meshes()["jittered_box"]
    model = build_model([mesh], [MATERIAL], device="cpu")
    a = DEFORMATIONS[deformation]
    x = wp.array((mesh.nodes @ a.T).astype(np.float32), dtype=wp.vec3, device="cpu")
    t, n = model.num_tets, model.num_nodes
    rotation_in = wp.zeros(t, dtype=wp.quat, device="cpu")
    wp.launch(ke.seed_rotations, dim=t, inputs=[x, model.tets, model.tet_rest_inv, rotation_in], device="cpu")
    rotation_out = wp.clone(rotation_in)
    active = wp.ones(1, dtype=int, device="cpu")
    summed, alone = wp.zeros(1, dtype=wp.float64, device="cpu"), wp.zeros(1, dtype=wp.float64, device="cpu")
    z = lambda dtype, size: wp.zeros(size, dtype=dtype, device="cpu")  # noqa: E731
    wp.launch(ke.evaluate_tets, dim=t, inputs=[x, model.tets, model.tet_rest_inv, model.tet_rest_volume, model.tet_mu,
                                               model.tet_lambda, model.tet_world, active, rotation_out, z(wp.vec3, n),
                                               z(wp.mat33, n), z(wp.vec3, n), z(wp.mat33, t), z(float, t),
                                               z(wp.mat33, t), z(float, t), 0, 1, summed], device="cpu")
    wp.launch(kenergy.tet_energy, dim=t, inputs=[x, model.tets, model.tet_rest_inv, model.tet_rest_volume, model.tet_mu,
                                                 model.tet_lambda, model.tet_world, active, rotation_in, alone],
              device="cpu")
    mu, lam = MATERIAL.lame
    u, _, vt = np.linalg.svd(a)
    j = np.linalg.det(a)
    want = model.tet_rest_volume.numpy().astype(np.float64).sum() * (
        mu * np.sum((a - u @ vt) ** 2) + 0.5 * lam * (j - 1.0) ** 2)
    assert summed.numpy()[0] == pytest.approx(want, rel=1e-5)
    assert summed.numpy()[0] == pytest.approx(alone.numpy()[0], rel=1e-6)
