"""The elastic Hessian assembled per node row (``sim/hessian_blocks.py``, ``kernels/hessian_blocks.py``)
against the tet-by-tet product it replaces in CG: each tet's stress differential
(``elastic.stress_differential``, the Newton matrix's definition) applied to its four nodes'
directions and scattered back. Checked on deformed objects of a packed model of three worlds and
of a slotted model whose worlds changed objects in place; the pattern against an independent
count (one block per node and two per tet edge) and the rows' symmetry."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from defgrasp_env.envs.world_models import assemble_model, rewrite_worlds, slot_sizes
from defgrasp_env.sim.hessian_blocks import HessianBlocks, block_count
from defgrasp_env.sim.kernels import elastic as ke
from defgrasp_env.sim.kernels import hessian_blocks as khb
from defgrasp_env.sim.materials import Material
from defgrasp_env.sim.meshing import make_object_mesh
from defgrasp_env.sim.model import ContactParams, build_model
from defgrasp_env.sim.solver import ImplicitSolver, SolverConfig
from defgrasp_env.sim.state import Control, State

DT = 0.05


@wp.kernel
def tet_by_tet_product(p: wp.array(dtype=wp.vec3), tets: wp.array(dtype=wp.vec4i), rest_inv: wp.array(dtype=wp.mat33),
                       rest_volume: wp.array(dtype=float), tet_mu: wp.array(dtype=float),
                       tet_lambda: wp.array(dtype=float), tet_cof: wp.array(dtype=wp.mat33),
                       tet_r: wp.array(dtype=wp.mat33), tet_twist: wp.array(dtype=float), out: wp.array(dtype=wp.vec3)):
    t = wp.tid()
    idx = tets[t]
    if ke.spare_tet(idx):
        return
    dm = rest_inv[t]
    b1 = ke.row(dm, 0)
    b2 = ke.row(dm, 1)
    b3 = ke.row(dm, 2)
    b0 = -(b1 + b2 + b3)
    p0 = p[idx[0]]
    df = wp.outer(p[idx[1]] - p0, b1) + wp.outer(p[idx[2]] - p0, b2) + wp.outer(p[idx[3]] - p0, b3)
    dp = ke.stress_differential(df, tet_cof[t], tet_r[t], tet_twist[t], tet_mu[t], tet_lambda[t], rest_volume[t])
    wp.atomic_add(out, idx[0], dp * b0)
    wp.atomic_add(out, idx[1], dp * b1)
    wp.atomic_add(out, idx[2], dp * b2)
    wp.atomic_add(out, idx[3], dp * b3)


@wp.kernel
def row_product(p: wp.array(dtype=wp.vec3), node_blocks: wp.array(dtype=wp.vec2i), block_node: wp.array(dtype=int),
                values: wp.array(dtype=wp.mat33), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = khb.hessian_row_product(i, p, node_blocks, block_node, values)


@wp.kernel
def block_at_a_time(p: wp.array(dtype=wp.vec3), node_blocks: wp.array(dtype=wp.vec2i), block_node: wp.array(dtype=int),
                    values: wp.array(dtype=wp.mat33), out: wp.array(dtype=wp.vec3)):
    """The row product summed a block at a time (what ``hessian_row_product`` unrolls)."""
    i = wp.tid()
    span = node_blocks[i]
    s = wp.vec3(0.0)
    for k in range(span[0], span[1]):
        s += values[k] * (p[block_node[k]] - p[i])
    out[i] = s


def deform(model, state, rng) -> None:
    """Bend, stretch and squash every world's object (some tets compressed beyond 30 %, some
    twisted): a state far from rest, where the rotations and twist factors matter."""
    x = model.rest_positions.numpy().astype(np.float64)
    for w in range(model.num_worlds):
        sl = model.world_nodes(w)
        c = x[sl] - x[sl].mean(0)
        c[:, 1] += 0.02 * np.sin(c[:, 0] * 30.0) - 0.4 * c[:, 1] * (c[:, 0] > 0)
        c[:, 0] *= 1.1
        c += 2e-3 * rng.standard_normal(c.shape)
        x[sl] = c + x[sl].mean(0)
    state.positions.assign(x.astype(np.float32))


def one_iteration_solver(model):
    return ImplicitSolver(model, SolverConfig(substeps=1, newton_iterations=1))


def assembled_and_reference(model, rng, solver=None):
    """(rows' product, tet-by-tet product, the assembled blocks) of a random direction at a deformed
    state: the solver's own evaluation and assembly (one Newton iteration) fill the tets' data."""
    state, control = State.from_model(model), Control.from_model(model)
    deform(model, state, rng)
    solver = solver or one_iteration_solver(model)
    s, d, n = solver.scratch, model.device, model.num_nodes
    run, _ = solver._substep_launches(DT, state, state, control)
    for seq in run.start[0]:  # the substep's start (rotation seeds), then one evaluation with its assembly
        seq.launch()
    for seq in run.evaluate_first:
        seq.launch()
    twist = s.tet_twist.numpy()[: model.num_tets]
    assert twist.min() < 0.9, "the state should have tets whose rotations are partly removed"
    p = wp.array(rng.standard_normal((n, 3)).astype(np.float32), dtype=wp.vec3, device=d)
    got, ref = wp.zeros(n, dtype=wp.vec3, device=d), wp.zeros(n, dtype=wp.vec3, device=d)
    h = s.hessian
    wp.launch(row_product, n, inputs=[p, h.node_blocks, h.block_node, h.values, got], device=d)
    wp.launch(tet_by_tet_product, model.num_tets, inputs=[p, model.tets, model.tet_rest_inv, model.tet_rest_volume,
                                                           model.tet_mu, model.tet_lambda, s.cofactor, s.tet_r,
                                                           s.tet_twist, ref], device=d)
    return got.numpy(), ref.numpy(), h


def assert_products_agree(got, ref):
    # float32: each side sums ~10-60 terms per node in a different order; 1e-5 of the largest entry
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-5 * np.abs(ref).max())
    assert np.abs(ref).max() > 0


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=pytest.mark.cuda)])
def test_rows_equal_the_tet_by_tet_product_in_a_packed_model(device):
    """Rows against tets on a rope, a cuboid and a torus of different materials, a translation's
    product exactly zero, the unrolled product against a block at a time (the same bits on the
    CPU), and the blocks' symmetry; on CUDA too (one thread a row there as here)."""
    meshes = [make_object_mesh(name) for name in ("rope", "cuboid", "torus")]
    materials = [Material(youngs_modulus=e, poisson_ratio=nu) for e, nu in ((1e4, 0.45), (1e6, 0.3), (1e5, 0.49))]
    model = build_model(meshes, materials, poses=[((0.1 * w, 0.05, 0.0), (0.0, 0.0, 0.0, 1.0)) for w in range(3)],
                        device=device)
    got, ref, h = assembled_and_reference(model, np.random.default_rng(0))
    assert_products_agree(got, ref)
    n = model.num_nodes  # a rigid translation: exactly no force, as tet by tet (a stiff object's rigid motion)
    shift = wp.array(np.tile(np.float32([0.3, -1.7, 2.9]), (n, 1)), dtype=wp.vec3, device=device)
    zero = wp.zeros(n, dtype=wp.vec3, device=device)
    wp.launch(row_product, n, inputs=[shift, h.node_blocks, h.block_node, h.values, zero], device=device)
    assert not zero.numpy().any()
    once = wp.zeros(n, dtype=wp.vec3, device=device)  # unrolled by four: the same sums in the same order
    p = wp.array(np.random.default_rng(3).standard_normal((n, 3)).astype(np.float32), dtype=wp.vec3, device=device)
    lengths = np.diff(h.node_blocks.numpy(), axis=1).ravel()
    assert {0, 1, 2, 3} <= set(lengths % 4)  # rows with every remainder of the unrolled passes
    unrolled = wp.zeros(n, dtype=wp.vec3, device=device)
    wp.launch(block_at_a_time, n, inputs=[p, h.node_blocks, h.block_node, h.values, once], device=device)
    wp.launch(row_product, n, inputs=[p, h.node_blocks, h.block_node, h.values, unrolled], device=device)
    if device == "cpu":
        np.testing.assert_array_equal(unrolled.numpy(), once.numpy())
    else:  # a GPU compiler may contract the two loops' multiply-adds differently
        assert_products_agree(unrolled.numpy(), once.numpy())
    blocks = {}
    spans, cols, values = h.node_blocks.numpy(), h.block_node.numpy(), h.values.numpy()
    for i, (a, b) in enumerate(spans):
        assert list(cols[a:b]) == sorted(cols[a:b]) and i not in cols[a:b] and b > a
        blocks.update({(i, int(j)): values[k] for k, j in zip(range(a, b), cols[a:b])})
    for (i, j), v in blocks.items():  # K_ij = K_ji^T
        np.testing.assert_allclose(v, blocks[(j, i)].T, rtol=0, atol=1e-5 * np.abs(v).max() + 1e-12)


@pytest.mark.parametrize("name", ["rope", "cuboid", "sphere", "torus", "cylinder"])
def test_block_count_is_twice_the_edges(name):
    mesh = make_object_mesh(name)
    tets = np.asarray(mesh.tets)
    edges = {tuple(sorted((int(t[a]), int(t[b])))) for t in tets for a in range(4) for b in range(a + 1, 4)}
    assert block_count(tets, len(mesh.nodes)) == 2 * len(edges)


def test_rows_equal_the_tet_by_tet_product_after_objects_change_in_place():
    """A slotted model of three worlds whose objects are then rewritten (rope -> cuboid, cuboid ->
    rope): the scratch's pattern is rewritten with them (``HessianBlocks.rewrite_worlds``) and its
    rows still give the tet-by-tet product, spare rows zero."""
    names = ("rope", "cuboid", "torus")
    meshes = {n: make_object_mesh(n) for n in names}
    slots = slot_sizes(list(meshes.values()))
    assert slots.blocks == max(block_count(np.asarray(m.tets), len(m.nodes)) for m in meshes.values())
    poses = [((0.1 * w, 0.05, 0.0), (0.0, 0.0, 0.0, 1.0)) for w in range(3)]
    materials = [Material(youngs_modulus=1e5)] * 3
    model = assemble_model([meshes[n] for n in names], materials, poses, [], ContactParams(), "cpu", slots)
    rng = np.random.default_rng(1)
    solver = one_iteration_solver(model)
    got, ref, _ = assembled_and_reference(model, rng, solver)
    assert_products_agree(got, ref)
    rewrite_worlds(model, [0, 1], [meshes["cuboid"], meshes["rope"]], materials[:2], poses[:2], [])
    solver.scratch.rewrite_worlds(model, [0, 1])  # as PickupScene._rewrite does
    h, fresh = solver.scratch.hessian, HessianBlocks.from_model(model)
    for k in ("node_blocks", "node_incidences"):
        assert np.array_equal(getattr(h, k).numpy(), getattr(fresh, k).numpy()), k
    used = np.concatenate([np.arange(a, b) for a, b in fresh.node_blocks.numpy()])  # a slot's tail: the old object's
    assert np.array_equal(h.block_node.numpy()[used], fresh.block_node.numpy()[used])
    got, ref, _ = assembled_and_reference(model, rng, solver)
    assert_products_agree(got, ref)
    for w in range(3):
        spare = slice(int(model.node_end[w]), int(model.node_start[w + 1]))
        assert not got[spare].any()
        a, b = h.node_blocks.numpy()[spare].T
        assert (a == b).all()


def test_a_world_whose_blocks_exceed_the_slot_is_refused():
    """A slot sized for the cuboid cannot take the rope's Hessian blocks (the rope fits its node
    and tet rows here: the slot is widened for them), and nothing is written."""
    cuboid, rope = make_object_mesh("cuboid"), make_object_mesh("rope")
    slots = slot_sizes([cuboid, rope])
    narrow = type(slots)(nodes=slots.nodes, tets=slots.tets, triangles=slots.triangles,
                         aggregates=slots.aggregates, blocks=block_count(np.asarray(cuboid.tets), len(cuboid.nodes)))
    model = assemble_model([cuboid], [Material()], [((0.0, 0.05, 0.0), (0.0, 0.0, 0.0, 1.0))], [], ContactParams(),
                           "cpu", narrow)
    tets = model.tets.numpy().copy()
    with pytest.raises(ValueError, match="Hessian blocks"):
        rewrite_worlds(model, [0], [rope], [Material()], [((0.0, 0.05, 0.0), (0.0, 0.0, 0.0, 1.0))], [])
    assert np.array_equal(model.tets.numpy(), tets)


def test_a_model_whose_block_slot_is_too_small_is_refused():
    """``HessianBlocks`` checks the slot itself too (a model whose rows were written some other way
    than ``rewrite_worlds``, which checks first): with the name of the count and the slot."""
    import dataclasses

    rope = make_object_mesh("rope")
    slots = slot_sizes([rope])
    model = assemble_model([rope], [Material()], [((0.0, 0.05, 0.0), (0.0, 0.0, 0.0, 1.0))], [], ContactParams(),
                           "cpu", slots)
    narrow = dataclasses.replace(model, block_slot=slots.blocks - 1)
    with pytest.raises(ValueError, match=f"{slots.blocks} Hessian blocks, more than the model's block slot"):
        HessianBlocks.from_model(narrow)
    blocks = HessianBlocks.from_model(model)
    with pytest.raises(ValueError, match="more than the model's block slot"):
        blocks.rewrite_worlds(narrow, [0])

