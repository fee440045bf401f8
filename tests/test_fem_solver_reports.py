"""FEM core, solver reports: the Newton iteration limit holds per substep, ``converged`` means the
stated tolerance was met, and a state deeper than the penetration bound is flagged."""

from __future__ import annotations

import numpy as np

from defgrasp_env.sim.materials import Material
from defgrasp_env.sim.meshing import make_object_mesh
from defgrasp_env.sim.model import build_model
from defgrasp_env.sim.solver import ImplicitSolver, SolverConfig
from defgrasp_env.sim.state import Control, State


def dropped_cuboid():
    """A cuboid (E = 1e5) 2 mm above the ground: it falls and lands within a few steps."""
    model = build_model([make_object_mesh("cuboid")], [Material(youngs_modulus=1e5)],
                        poses=[((0.0, 0.002, 0.0), (0.0, 0.0, 0.0, 1.0))], device="cpu")
    return model, State.from_model(model), Control.from_model(model)


def test_newton_limit_is_per_substep():
    """With an unreachable tolerance every substep runs exactly ``newton_iterations``: one call of
    3 substeps reports 3 x the limit and is bit-identical to 3 calls of one substep (before the
    fix the 2nd and 3rd substeps got one iteration each)."""
    cfg = SolverConfig(substeps=3, newton_iterations=3, newton_tolerance=1e-15)
    model, state, control = dropped_cuboid()
    stats = ImplicitSolver(model, cfg).step(state, state, control, dt=0.03)
    assert stats.newton_iterations.tolist() == [9]
    model1, state1, control1 = dropped_cuboid()
    solver1 = ImplicitSolver(model1, SolverConfig(substeps=1, newton_iterations=3, newton_tolerance=1e-15))
    for _ in range(3):
        assert solver1.step(state1, state1, control1, dt=0.01).newton_iterations.tolist() == [3]
    np.testing.assert_array_equal(state.positions.numpy(), state1.positions.numpy())
    np.testing.assert_array_equal(state.velocities.numpy(), state1.velocities.numpy())


def test_converged_false_at_the_iteration_limit():
    """An unreachable tolerance stops at the limit: converged False (the world did not diverge);
    a reachable one with room to spare: converged True, in fewer iterations than the limit."""
    model, state, control = dropped_cuboid()
    stats = ImplicitSolver(model, SolverConfig(substeps=2, newton_iterations=2, newton_tolerance=1e-15)).step(
        state, state, control, dt=0.05)
    assert not stats.diverged.any() and not stats.converged.any()
    assert stats.newton_iterations.tolist() == [4]
    model, state, control = dropped_cuboid()
    stats = ImplicitSolver(model, SolverConfig(substeps=2, newton_iterations=30, newton_tolerance=1e-6)).step(
        state, state, control, dt=0.05)
    assert stats.converged.all() and stats.newton_iterations[0] < 60


def test_penetration_beyond_the_bound_is_flagged():
    """A cuboid resting on the ground sinks weight / stiffness into it (penalty): flagged against
    a bound below that depth, not against the default 1 mm."""
    reports = {}
    for bound in (1e-3, 1e-9):
        model, state, control = dropped_cuboid()
        solver = ImplicitSolver(model, SolverConfig(penetration_bound=bound))
        for _ in range(10):
            stats = solver.step(state, state, control, dt=0.05)
        reports[bound] = stats
    assert 1e-9 < reports[1e-3].penetration[0] < 1e-3
    assert not reports[1e-3].penetrated[0] and reports[1e-9].penetrated[0]


def test_public_sim_api():
    """``defgrasp_env.sim`` exports the Model/State/Control split, the solver and meshing: the
    docstring's example runs as written (a sphere falls under gravity, nothing else imported)."""
    import defgrasp_env.sim as sim

    for name in sim.__all__:
        assert getattr(sim, name) is not None
    model = sim.build_model([sim.make_object_mesh("sphere")], [sim.Material(youngs_modulus=1e5)],
                            poses=[((0.0, 0.01, 0.0), (0.0, 0.0, 0.0, 1.0))],
                            pad_half_extents=[(0.008, 0.019, 0.011)], device="cpu")
    state, control = sim.State.from_model(model), sim.Control.from_model(model)
    control.pad_target_positions.assign(np.array([[0.2, 0.1, 0.0]], np.float32))
    state.pad_positions.assign(np.array([[0.2, 0.1, 0.0]], np.float32))
    y0 = state.positions.numpy()[:, 1].mean()
    stats = sim.ImplicitSolver(model, sim.SolverConfig()).step(state, state, control, dt=0.02)
    assert isinstance(stats, sim.SolveStats) and not stats.diverged.any()
    assert state.positions.numpy()[:, 1].mean() < y0
