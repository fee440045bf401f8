"""FEM core, linear solves: the node aggregates of the coarse space, the coarse matrix T^T A T
against its definition (A applied to the coarse columns by the CG's own Hessian-product kernel),
and the CPU graphs of the recorded launches (bit-identical to launching one by one)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import warp as wp

from defgrasp_env.sim.aggregates import bisect_nodes
from defgrasp_env.sim.kernels import linear_solve as klin
from defgrasp_env.sim.materials import Material
from defgrasp_env.sim.meshing import TetMesh, make_object_mesh
from defgrasp_env.sim.model import build_model
from defgrasp_env.sim.solver import ImplicitSolver, SolverConfig
from defgrasp_env.sim.state import Control, State
from defgrasp_env.sim.world_compaction import every_row

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


def test_a_models_aggregates_do_not_depend_on_its_pose():
    """The solver's aggregates (``Model.node_aggregate``) are cut in the object frame: a rope
    built at two poses (here float rounding of the posed nodes moves ties at the cuts) gets the same
    aggregates, and so do two worlds of one model and the env's cached-model assembly."""
    from defgrasp_env.envs.world_models import assemble_model
    from defgrasp_env.sim.model import ContactParams
    from defgrasp_env.transforms import quat_to_matrix

    rope = make_object_mesh("rope")
    poses = [((0.0, 0.01, 0.0), (0.0, 0.0, 0.0, 1.0)),
             ((0.013, 0.01, -0.02), (0.0, float(np.sin(0.61)), 0.0, float(np.cos(0.61))))]
    posed = bisect_nodes(np.asarray(rope.nodes) @ quat_to_matrix(np.asarray(poses[1][1])).T)
    reference = bisect_nodes(np.asarray(rope.nodes))
    assert not np.array_equal(posed, reference), "the test needs a pose whose posed cut differs"
    model = build_model([rope, rope], [Material()] * 2, poses=poses, device="cpu")
    n = len(rope.nodes)
    assert np.array_equal(model.node_aggregate[:n], reference) and np.array_equal(model.node_aggregate[n:], reference)
    assembled = assemble_model([rope, rope], [Material()] * 2, poses, [], ContactParams(), "cpu")
    assert np.array_equal(assembled.node_aggregate, model.node_aggregate)


def test_compact_objects_are_cut_into_eight_blocks():
    """A sphere, a cuboid and the torus are cut into 8 pieces of equal node counts (their rigid
    motions carry a stiff object's near-rigid deformation), each piece around its own part of the
    object: its nodes nearer their own piece's centre than any other piece's, on average."""
    for name in ("sphere", "cuboid", "torus"):
        x = np.asarray(make_object_mesh(name).nodes, dtype=np.float64)
        index = bisect_nodes(x, 8)
        counts = np.bincount(index, minlength=8)
        assert len(counts) == 8 and counts.max() - counts.min() <= 1, (name, counts)
        centres = np.stack([x[index == k].mean(axis=0) for k in range(8)])
        nearest = np.argmin(np.linalg.norm(x[:, None] - centres[None], axis=2), axis=1)
        assert np.mean(nearest == index) > 0.8, name


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
    Hessian-product kernel (the elastic Hessian's assembled rows + mass/contact nodes), to float32
    rounding: T's columns the translations and the rotations of each aggregate about its anchor
    node at the iterate, built here from the positions and ``Model.node_anchor``; with all axes
    free (the within-aggregate rows' translation parts cancel exactly) and with prescribed axes
    (T masked)."""
    model, solver, state, control = squeezed_rope(fixed)
    s, n, d = solver.scratch, model.num_nodes, model.device
    size = s.coarse_size
    assert size == 48
    run, _ = solver._substep_launches(DT, state, state, control)
    s.newton_active.fill_(1)
    s.coarse_matrix.zero_()
    s.coarse_rhs.zero_()
    for cmd in run.evaluate:   # assembles, factors (in place) and inverts: keep E^-1
        cmd.launch()
    inverse = s.coarse_inverse.numpy()[0]
    free = model.free_axes.numpy()
    agg = s.node_aggregate.numpy()
    x = state.positions.numpy().astype(np.float64)
    lever = x - x[model.node_anchor]
    np.testing.assert_allclose(s.coarse_lever.numpy(), lever, atol=1e-7)
    columns = np.zeros((size, n, 3))
    for a in range(size // 6):
        for k in range(3):
            axis = np.eye(3)[k]
            columns[6 * a + k, agg == a] = free[agg == a] * axis
            columns[6 * a + 3 + k, agg == a] = free[agg == a] * np.cross(axis, lever[agg == a])
    at = np.zeros_like(columns)
    for c in range(size):
        direction = wp.array(columns[c].astype(np.float32), dtype=wp.vec3, device=d)
        product = wp.zeros(n, dtype=wp.vec3, device=d)
        h = s.hessian
        wp.launch(klin.cg_node_product, n, inputs=[direction, model.node_mass, s.contact_hessian, model.free_axes,
                                                   model.node_world, s.solve_worlds, 1.0 / DT**2, h.node_blocks,
                                                   h.block_node, h.values, product,
                                                   wp.zeros(1, dtype=float, device=d), every_row(d)], device=d)
        at[c] = product.numpy()
    galerkin = np.einsum("inj,knj->ik", columns, at)
    used = np.diag(galerkin) > 0
    expected = np.linalg.inv(galerkin[np.ix_(used, used)])
    got = inverse[np.ix_(used, used)]
    assert np.allclose(got, got.T)
    np.testing.assert_allclose(got @ galerkin[np.ix_(used, used)], np.eye(used.sum()), atol=2e-3)
    np.testing.assert_allclose(got, expected, rtol=2e-3, atol=2e-3 * np.abs(expected).max())


def held_rope_steps(mode: str, steps: int = 6, config: SolverConfig = SolverConfig(substeps=2), patient=None):
    """A falling rope that lands, stepped with ``mode``: "step" (each ``advance`` one captured
    graph), "phases" (each phase one CPU graph) or "launches" (every launch from Python)."""
    model = build_model([make_object_mesh("rope")], [Material(youngs_modulus=1e4)],
                        poses=[((0.0, 0.004, 0.0), (0.0, 0.0, 0.0, 1.0))], device="cpu")
    state, control = State.from_model(model), Control.from_model(model)
    solver = ImplicitSolver(model, dataclasses.replace(config, graphs={"step": True, "fallback": None}.get(mode, False)))
    run, graphs = solver._substep_launches(DT / config.substeps, state, state, control)  # what ``step`` replays
    if mode == "launches":
        for phase in (run.evaluate, run.evaluate_first, run.cg, run.cg_world, run.step_world,
                      run.step_world_first, run.coarse_post, run.energy0, run.trial, run.apply,
                      *run.finish, *run.start):
            for seq in phase:
                seq.graph = None
    reports = [solver.step(state, state, control, dt=DT, patient=patient) for _ in range(steps)]
    assert (len(graphs) == 1) == solver.graphs, graphs   # captured once, then replayed
    return state, reports


@pytest.mark.parametrize("config", [SolverConfig(substeps=2), SolverConfig(substeps=1, check_every=0)],
                         ids=["check_every_4", "check_every_0"])
def test_cpu_graphs_are_bit_identical_to_single_launches(config):
    """The whole substep captured as one CPU graph (loops with device-side exit tests), the phases
    replayed as CPU graphs and the same launches one by one give the same bits (positions,
    velocities, iteration counts), step after step (a falling rope that lands), also with a
    patient world (extra Newton iterations) and without the early-exit checks."""
    results = {mode: held_rope_steps(mode, config=config, patient=np.ones(1, bool)) for mode in ("step", "phases", "launches")}
    cuboid = build_model([make_object_mesh("cuboid")], [Material()], device="cpu")
    state, control = State.from_model(cuboid), Control.from_model(cuboid)
    run, _ = ImplicitSolver(cuboid, SolverConfig(graphs=False))._substep_launches(DT, state, state, control)
    assert any(seq.graph is not None for seq in run.cg_world)  # the default: each world's CG in one launch
    s1, r1 = results["step"]
    for mode in ("phases", "launches"):
        s0, r0 = results[mode]
        np.testing.assert_array_equal(s1.positions.numpy(), s0.positions.numpy())
        np.testing.assert_array_equal(s1.velocities.numpy(), s0.velocities.numpy())
        assert [r.cg_iterations.tolist() for r in r1] == [r.cg_iterations.tolist() for r in r0]
        assert [r.newton_iterations.tolist() for r in r1] == [r.newton_iterations.tolist() for r in r0]
    assert sum(int(r.cg_iterations[0]) for r in r1) > 0


def _resting_rope(config: SolverConfig, steps: int):
    model = build_model([make_object_mesh("rope")], [Material(youngs_modulus=1e4)],
                        poses=[((0.0, 0.004, 0.0), (0.0, 0.0, 0.0, 1.0))], device="cpu")
    state, control = State.from_model(model), Control.from_model(model)
    solver = ImplicitSolver(model, config)
    assert solver.graphs, "this Warp captures no CPU graphs with capture_while"
    reports, cg_blocks = [], []
    for _ in range(steps):
        reports.append(solver.step(state, state, control, dt=DT))
        cg_blocks.append(int(solver.loops.count["cg"].numpy()[0]))   # in the step's last Newton iteration
    return solver, reports, cg_blocks


def test_device_loops_stop_early_and_take_the_extra_iterations():
    """The loop counters the captured graph keeps: with the exit tests a rope come to rest stops
    Newton before its cap (and CG before its last block); without them the regular loop runs all
    its passes; a patient world that cannot meet the tolerance gets exactly ``patient_iterations``
    extra Newton iterations per substep."""
    # CG phase by phase (world_block_threads=0): its loop counts CG blocks
    cfg = SolverConfig(substeps=1, newton_iterations=6, cg_iterations=40, check_every=4, world_block_threads=0)
    solver, reports, cg_blocks = _resting_rope(cfg, 12)
    assert int(reports[-1].newton_iterations[0]) < 6
    assert solver.loops.count["newton"].numpy()[0] < 6 and min(cg_blocks) < 10, cg_blocks
    assert solver.loops.count["extra"].numpy()[0] == 0   # an early stop skips the extra iterations
    solver, _, cg_blocks = _resting_rope(dataclasses.replace(cfg, check_every=0), 12)
    assert solver.loops.count["newton"].numpy()[0] == 6 and set(cg_blocks) == {1}
    strict = dataclasses.replace(cfg, newton_iterations=3, newton_tolerance=1e-12, patient_iterations=4,
                                 penetration_iterations=0)
    model = build_model([make_object_mesh("rope")] * 2, [Material(youngs_modulus=1e4)] * 2, device="cpu")
    state, control = State.from_model(model), Control.from_model(model)
    solver = ImplicitSolver(model, strict)
    stats = solver.step(state, state, control, dt=DT, patient=np.array([True, False]))
    assert stats.newton_iterations.tolist() == [3 + 4, 3], stats.newton_iterations
    assert solver.loops.count["extra"].numpy()[0] == 4


def test_deep_worlds_take_extra_iterations_with_and_without_exit_tests():
    """A cuboid started 3 mm below the ground, one regular Newton iteration: the world is still
    deeper than half the penetration bound, so it takes extra iterations (reported Newton
    iterations > 1); with the exit tests they stop once it is shallow enough, without them the
    loop runs its full count with the world inactive: the same bits either way."""
    results = []
    for check in (4, 0):
        model = build_model([make_object_mesh("cuboid")], [Material(youngs_modulus=1e5)],
                            poses=[((0.0, -0.003, 0.0), (0.0, 0.0, 0.0, 1.0))], device="cpu")
        state, control = State.from_model(model), Control.from_model(model)
        assert state.positions.numpy()[:, 1].min() < -0.002
        solver = ImplicitSolver(model, SolverConfig(substeps=1, newton_iterations=1, penetration_iterations=6,
                                                    check_every=check))
        stats = solver.step(state, state, control, dt=DT)
        results.append((state.positions.numpy(), int(stats.newton_iterations[0]), solver.loops.count["extra"].numpy()[0]))
    (x4, it4, extra4), (x0, it0, extra0) = results
    assert 1 < it4 == it0 <= 7 and 1 <= extra4 <= 6 and extra0 == 6, (it4, it0, extra4, extra0)
    np.testing.assert_array_equal(x4, x0)


def test_a_failed_capture_falls_back_to_launches(monkeypatch):
    """If capturing a step fails, graphs=None warns once and steps without graphs (the same bits
    as a solver made with graphs=False); graphs=True raises the capture's error."""
    import warp as wp

    class BrokenCapture:
        def __init__(self, *args, **kwargs):
            pass

        def __enter__(self):
            raise RuntimeError("capture not available here")

        def __exit__(self, *exc):
            return False

    reference, _ = held_rope_steps("phases", steps=2)
    monkeypatch.setattr(wp, "ScopedCapture", BrokenCapture)
    with pytest.warns(RuntimeWarning, match="capturing a solver step as a graph failed"):
        state, _ = held_rope_steps("fallback", steps=2)
    np.testing.assert_array_equal(state.positions.numpy(), reference.positions.numpy())
    with pytest.raises(RuntimeError, match="capture not available here"):
        held_rope_steps("step", steps=1)


def test_cg_stops_at_the_forcing_term_of_the_last_newton_update():
    """``start_cg_worlds``: CG stops at r.z = eta^2 times its start value, eta = cg_tolerance x
    (last Newton update of this substep / newton_tolerance) clamped to [cg_tolerance,
    cg_tolerance_far], computed here by hand; at a substep's first iteration (no update yet,
    whatever ``last_dx`` holds from before) and in a patient world eta is cg_tolerance; a far
    tolerance below the near one means the near one everywhere; worlds not iterating Newton, or
    with nothing to solve (r.z = 0), do not start CG."""
    tol, near = 1e-5, 1e-3
    last = np.array([0.0, 3e-5, 1e-4, 1e-3, 1.0, 5e-5, 1.0, 1.0], np.float32)
    iterations = np.array([1, 2, 1, 3, 1, 1, 0, 2], np.int32)
    patient = np.array([0, 0, 0, 0, 0, 0, 0, 1], np.int32)
    rz = np.array([2.0, 2.0, 2.0, 2.0, 2.0, 0.0, 2.0, 2.0], np.float32)
    active = np.array([1, 1, 1, 0, 1, 1, 1, 1], np.int32)
    used = np.where((iterations > 0) & (patient == 0), last.astype(np.float64), 0.0)
    for far in (1e-2, 1e-4):
        out_stop, out_active = wp.zeros(8, dtype=float, device="cpu"), wp.zeros(8, dtype=int, device="cpu")
        wp.launch(klin.start_cg_worlds, dim=8, device="cpu",
                  inputs=[wp.array(active, dtype=int, device="cpu"), wp.array(iterations, dtype=int, device="cpu"),
                          wp.array(patient, dtype=int, device="cpu"), wp.array(last, dtype=float, device="cpu"), tol,
                          near, far, wp.array(rz, dtype=float, device="cpu"), out_stop, out_active])
        eta = np.clip(near * used / tol, near, max(near, far))
        np.testing.assert_allclose(out_stop.numpy(), eta ** 2 * rz, rtol=1e-6)   # float32 products
        assert out_active.numpy().tolist() == [1, 1, 1, 0, 1, 0, 1, 1]
        if far > near:
            assert eta[[1, 2, 4]].tolist() == pytest.approx([3e-3, 1e-2, 1e-2]) and eta[6] == eta[7] == near
    assert eta.tolist() == [near] * 8   # far < near: the near tolerance everywhere


def _sunk_cuboid_step(config: SolverConfig, solver_steps: int = 1, patient: bool = False):
    """A cuboid (E = 1e4) started 3 mm below the ground: positions and reports after one step of
    ``config`` repeated ``solver_steps`` times from the same input (a fresh output each time)."""
    model = build_model([make_object_mesh("cuboid")], [Material(youngs_modulus=1e4)],
                        poses=[((0.0, -0.003, 0.0), (0.0, 0.0, 0.0, 1.0))], device="cpu")
    state, control = State.from_model(model), Control.from_model(model)
    solver = ImplicitSolver(model, config)
    out = []
    for _ in range(solver_steps):
        result = State.from_model(model)
        stats = solver.step(state, result, control, dt=DT, patient=np.ones(1, bool) if patient else None)
        out.append((result.positions.numpy(), stats))
    return out


def test_an_inexact_newton_step_converges_to_the_same_solution_with_fewer_cg_iterations():
    """One step to a tight Newton tolerance (1e-7 m): CG with the far tolerance 3e-2 (rough steps
    while the update is large) ends within 1e-6 m (10 x the tolerance: each solve's last update is
    below it, so both lie within about a tolerance of the solution) of CG solved to 1e-3 in every
    iteration, in fewer CG iterations, and in more than with 3e-2 in every iteration (the near
    tolerance is used where the update is small: the launch passes both)."""
    tight = SolverConfig(substeps=1, newton_iterations=40, newton_tolerance=1e-7, cg_iterations=200,
                         cg_tolerance=1e-3, cg_tolerance_far=1e-3)
    runs = {name: _sunk_cuboid_step(config)[0] for name, config in (
        ("tight", tight), ("adaptive", dataclasses.replace(tight, cg_tolerance_far=3e-2)),
        ("rough", dataclasses.replace(tight, cg_tolerance=3e-2, cg_tolerance_far=3e-2)))}
    assert all(stats.converged[0] for _, stats in runs.values()), runs
    assert np.abs(runs["tight"][0] - runs["adaptive"][0]).max() < 1e-6
    cg = {name: int(stats.cg_iterations[0]) for name, (_, stats) in runs.items()}
    assert cg["rough"] < cg["adaptive"] < cg["tight"], cg


def test_an_inexact_solve_depends_on_its_input_alone():
    """The forcing term reads only the substep's own Newton updates: an unconverged step (2 Newton
    iterations) taken twice from the same input gives the same bits, and so does a fresh solver
    (``test_fem_solver_reports.test_newton_limit_is_per_substep``: a step of 3 substeps is
    bit-identical to 3 steps of one);
    a patient world solves every CG to the near tolerance (the forces that decide the actuator
    limit): the same bits as with the far tolerance equal to the near one."""
    config = SolverConfig(substeps=1, newton_iterations=2, cg_tolerance_far=1e-2, penetration_iterations=0)
    (x1, s1), (x2, s2) = _sunk_cuboid_step(config, solver_steps=2)
    ((x3, s3),) = _sunk_cuboid_step(config)
    assert not s1.converged[0], "the test needs an unconverged solve (its last update above the tolerance)"
    for x, s in ((x2, s2), (x3, s3)):
        np.testing.assert_array_equal(x, x1)
        assert int(s.cg_iterations[0]) == int(s1.cg_iterations[0])
    patient = dataclasses.replace(config, patient_iterations=3)
    ((xp, sp),) = _sunk_cuboid_step(patient, patient=True)
    ((xq, sq),) = _sunk_cuboid_step(dataclasses.replace(patient, cg_tolerance_far=patient.cg_tolerance), patient=True)
    np.testing.assert_array_equal(xp, xq)
    assert int(sp.cg_iterations[0]) == int(sq.cg_iterations[0]) > 0


def test_each_world_solves_its_own_coarse_rows_with_the_same_bits():
    """A batch's coarse arrays are as wide as its most aggregates (8: 48 unknowns), and a world of
    fewer (a single tet: 4 nodes in pieces 0, 2, 4 and 6, so 42 unknowns, three empty pieces inside
    them) solves only its own rows (``SolverScratch.coarse_sizes``): the rows beyond are empty, so
    a tet and a cuboid dropped onto the ground (contact) step with the same bits as with every
    world solving all 48."""
    tet = TetMesh(nodes=0.03 * np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]),
                  tets=np.array([[0, 1, 2, 3]], np.int32),
                  surface=np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int32))

    def drop(full_width: bool):
        model = build_model([tet, make_object_mesh("cuboid")], [Material(youngs_modulus=1e5)] * 2,
                            poses=[((0.0, 0.01, 0.0), (0.0, 0.0, 0.0, 1.0)), ((0.2, 0.01, 0.0), (0.0, 0.0, 0.0, 1.0))],
                            device="cpu")
        state, control = State.from_model(model), Control.from_model(model)
        solver = ImplicitSolver(model, SolverConfig(substeps=2))
        assert solver.scratch.coarse_size == 48
        assert solver.scratch.coarse_sizes.numpy().tolist() == [42, 48]
        if full_width:
            solver.scratch.coarse_sizes.fill_(48)
        reports = [solver.step(state, state, control, dt=DT) for _ in range(8)]
        assert max(float(r.penetration[1]) for r in reports) > 0.0  # the cuboid reached the ground
        return state.positions.numpy(), [r.cg_iterations.tolist() for r in reports]

    own, own_cg = drop(False)
    full, full_cg = drop(True)
    np.testing.assert_array_equal(own, full)
    assert own_cg == full_cg and sum(c[0] for c in own_cg) > 0
