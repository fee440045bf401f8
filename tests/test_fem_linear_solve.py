"""FEM core, linear solves: the node aggregates of the coarse space, the coarse matrix T^T A T
against its definition (A applied to the coarse columns by the CG's own Hessian-product kernels),
and the CPU graphs of the recorded launches (bit-identical to launching one by one)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from defgrasp_env.sim.aggregates import bisect_nodes
from defgrasp_env.sim.kernels import elastic as ke
from defgrasp_env.sim.kernels import linear_solve as klin
from defgrasp_env.sim.materials import Material
from defgrasp_env.sim.meshing import make_object_mesh
from defgrasp_env.sim.model import build_model
from defgrasp_env.sim.solver import ImplicitSolver, SolverConfig
from defgrasp_env.sim.state import Control, State

DT = 0.05


def slices_along(x: np.ndarray, index: np.ndarray, axis: np.ndarray) -> None:
    """The 8 aggregates are slices of equal node counts that do not overlap along ``axis``."""
    counts = np.bincount(index, minlength=8)
    assert counts.max() - counts.min() <= 1
    t = x @ axis
    spans = sorted((t[index == k].min(), t[index == k].max()) for k in range(8))
    for (_, hi), (lo, _) in zip(spans[:-1], spans[1:]):
        assert hi <= lo + 1e-9


def test_aggregates_are_equal_slices_along_a_rope_whatever_its_pose():
    """8 aggregates of a rope are 8 slices of equal node count along its length, also for the rope
    turned by an arbitrary rotation (principal axes, not coordinate axes)."""
    x = np.asarray(make_object_mesh("rope").nodes, dtype=np.float64)
    along = np.eye(3)[np.argmax(np.ptp(x, axis=0))]
    slices_along(x, bisect_nodes(x, 8), along)
    q, _ = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))
    turned = x @ q.T + [0.1, 0.2, 0.3]
    slices_along(turned, bisect_nodes(turned, 8), q @ along)


def test_compact_objects_are_one_aggregate():
    """A sphere, a cuboid (and the torus, flat but not slender) keep one aggregate: their rigid
    translations."""
    for name in ("sphere", "cuboid", "torus"):
        assert not bisect_nodes(make_object_mesh(name).nodes, 8).any()


def test_aggregates_of_a_tiny_mesh_and_bad_counts():
    """Fewer nodes than pieces: every node gets a valid index; a count that is not a power of two
    is refused with its value."""
    index = bisect_nodes(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), 8)
    assert index.min() >= 0 and index.max() < 8 and len(set(index.tolist())) == 3
    with pytest.raises(ValueError, match="power of two.*6"):
        bisect_nodes(np.eye(3), 6)


def squeezed_rope(fixed: bool):
    """A rope (E = 1e5) lying along x, stretched and bent a little, optionally with the x axis of
    its first nodes prescribed; its solver after one step (Hessian data at the returned state), the
    state and control it stepped."""
    mesh = make_object_mesh("rope")
    n = len(mesh.nodes)
    fixed_axes = None
    if fixed:
        fa = np.zeros((n, 3), bool)
        fa[np.argsort(np.asarray(mesh.nodes)[:, 0])[:20], 0] = True
        fixed_axes = [fa]
    model = build_model([mesh], [Material(youngs_modulus=1e5)], poses=[((0.0, 0.02, 0.0), (0.0, 0.0, 0.0, 1.0))],
                        fixed_axes=fixed_axes, device="cpu")
    state, control = State.from_model(model), Control.from_model(model)
    x = model.rest_positions.numpy().astype(np.float64)
    x[:, 1] += 0.01 * np.sin(x[:, 0] * 20.0)
    x[:, 0] *= 1.02
    state.positions.assign(x.astype(np.float32))
    solver = ImplicitSolver(model, SolverConfig(substeps=1, newton_iterations=1))
    solver.step(state, state, control, dt=DT)
    return model, solver, state, control


@pytest.mark.parametrize("fixed", [False, True])
def test_coarse_matrix_is_the_galerkin_product(fixed):
    """The assembled coarse matrix equals T^T (A T) with A T computed column by column by the CG's
    Hessian-product kernels (elastic tets + mass/contact nodes), to float32 rounding: with all axes
    free (inner tets skipped) and with prescribed axes (T masked, every tet assembled)."""
    model, solver, state, control = squeezed_rope(fixed)
    s, n, d = solver.scratch, model.num_nodes, model.device
    size = s.coarse_size
    assert size == 24
    run = solver._substep_launches(DT, state, state, control)
    s.newton_active.fill_(1)
    s.coarse_matrix.zero_()
    s.coarse_rhs.zero_()
    for cmd in run.evaluate:   # assembles, factors (in place) and inverts: keep E^-1
        cmd.launch()
    inverse = s.coarse_inverse.numpy()[0]
    free = model.free_axes.numpy()
    agg = s.node_aggregate.numpy()
    columns = np.zeros((size, n, 3))
    for a in range(size // 3):
        for k in range(3):
            columns[3 * a + k, agg == a, k] = free[agg == a, k]
    at = np.zeros_like(columns)
    for c in range(size):
        direction = wp.array(columns[c].astype(np.float32), dtype=wp.vec3, device=d)
        product = wp.zeros(n, dtype=wp.vec3, device=d)
        wp.launch(ke.hessian_product_tets, model.num_tets,
                  inputs=[direction, model.tets, model.tet_rest_inv, model.tet_rest_volume, model.tet_mu,
                          model.tet_lambda, s.cofactor, model.tet_world, s.all_on, product, s.tet_r, s.tet_twist],
                  device=d)
        wp.launch(klin.cg_node_product, n, inputs=[direction, model.node_mass, s.contact_hessian, model.free_axes,
                                                   model.node_world, s.all_on, 1.0 / DT**2, product,
                                                   wp.zeros(1, dtype=float, device=d)], device=d)
        at[c] = product.numpy()
    galerkin = np.einsum("inj,knj->ik", columns, at)
    used = np.diag(galerkin) > 0
    expected = np.linalg.inv(galerkin[np.ix_(used, used)])
    got = inverse[np.ix_(used, used)]
    assert np.allclose(got, got.T)
    np.testing.assert_allclose(got @ galerkin[np.ix_(used, used)], np.eye(used.sum()), atol=2e-3)
    np.testing.assert_allclose(got, expected, rtol=2e-3, atol=2e-3 * np.abs(expected).max())


def held_rope_steps(graphs: bool, steps: int = 6):
    model = build_model([make_object_mesh("rope")], [Material(youngs_modulus=1e4)],
                        poses=[((0.0, 0.004, 0.0), (0.0, 0.0, 0.0, 1.0))], device="cpu")
    state, control = State.from_model(model), Control.from_model(model)
    solver = ImplicitSolver(model, SolverConfig(substeps=2))
    run = solver._substep_launches(DT / 2, state, state, control)   # what ``step`` below replays
    if not graphs:
        for phase in (run.lag, run.evaluate, run.cg, run.coarse_post, run.energy0, run.trial, run.apply,
                      run.depth, run.outputs, *run.pads):
            for seq in phase:
                seq.graph = None
    reports = [solver.step(state, state, control, dt=DT) for _ in range(steps)]
    return state, reports


def test_cpu_graphs_are_bit_identical_to_single_launches():
    """The recorded phases replayed as CPU graphs give the same bits (positions, velocities,
    iteration counts) as the same launches one by one, step after step (a falling rope that lands)."""
    s1, r1 = held_rope_steps(True)
    s0, r0 = held_rope_steps(False)
    cuboid = build_model([make_object_mesh("cuboid")], [Material()], device="cpu")
    state, control = State.from_model(cuboid), Control.from_model(cuboid)
    assert any(seq.graph is not None for seq in ImplicitSolver(cuboid)._substep_launches(DT, state, state, control).cg)
    np.testing.assert_array_equal(s1.positions.numpy(), s0.positions.numpy())
    np.testing.assert_array_equal(s1.velocities.numpy(), s0.velocities.numpy())
    assert [r.cg_iterations.tolist() for r in r1] == [r.cg_iterations.tolist() for r in r0]
    assert sum(int(r.cg_iterations[0]) for r in r1) > 0
