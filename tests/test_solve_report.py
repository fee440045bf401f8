"""Solver into a second state and the device-side report: ``ImplicitSolver.advance(state_in,
state_out)`` gives the bits of stepping in place and leaves ``state_in`` untouched, and
``SolveReport.fold`` over several solves equals ``SolveStats.combine`` of their host reports
(iterations summed, last update and residual, deepest penetration, any flag), divergence,
non-convergence and penetration included."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import warp as wp

from defgrasp_env.sim import SolveReport, SolveStats
from defgrasp_env.sim.materials import Material
from defgrasp_env.sim.meshing import make_object_mesh
from defgrasp_env.sim.model import build_model
from defgrasp_env.sim.solver import ImplicitSolver, SolverConfig
from defgrasp_env.sim.state import Control, State

PAD_HALF = np.array([0.004, 0.01875, 0.011])
DT = 0.05


def build(force_on_world1: float = 0.0):
    """A cuboid squeezed by its pads while falling 5 mm and a torus resting with its pads away;
    ``force_on_world1`` (N, along x) on one torus node (1e9: the world diverges)."""
    meshes = [make_object_mesh("cuboid"), make_object_mesh("torus")]
    model = build_model(meshes, [Material(youngs_modulus=1e5), Material(youngs_modulus=1e6)],
                        poses=[((0.0, 0.005, 0.0), (0, 0, 0, 1)), ((0.0, 0.0, 0.0), (0, 0, 0, 1))],
                        pad_half_extents=[PAD_HALF, PAD_HALF], device="cpu")
    state, control = State.from_model(model), Control.from_model(model)
    state.pad_positions.assign(pads(0))
    force = np.zeros((model.num_nodes, 3), np.float32)
    force[model.world_nodes(1).start + 3, 0] = force_on_world1
    control.external_force.assign(force)
    return model, state, control


def pads(step: int) -> np.ndarray:
    """Pad centres [4, 3] (m): world 0's pads close 1 mm per step from touching, world 1's stay away."""
    x0 = 0.02 + PAD_HALF[0] - 0.001 * step
    return np.array([[-x0, 0.02, 0.0], [x0, 0.02, 0.0], [-0.08, 0.02, 0.0], [0.08, 0.02, 0.0]], np.float32)


def arrays(state: State) -> dict[str, np.ndarray]:
    return {name: getattr(state, name).numpy().copy() for name in state.__dataclass_fields__}


def test_advance_into_another_state_equals_stepping_in_place():
    """Two states alternating (the scene's double buffer) give, step after step, every array of the
    in-place run bit for bit, and a solve never writes its input state."""
    model, state, control = build()
    solver = ImplicitSolver(model, SolverConfig(substeps=2))
    _, a, control_b = build()
    b = State.from_model(model)
    solver_b = ImplicitSolver(model, SolverConfig(substeps=2))
    for k in range(1, 6):
        control.pad_target_positions.assign(pads(k))
        control_b.pad_target_positions.assign(pads(k))
        solver.step(state, state, control, DT)
        before = arrays(a)
        solver_b.advance(a, b, control_b, DT)
        for name, value in arrays(a).items():
            np.testing.assert_array_equal(value, before[name], err_msg=f"state_in.{name} was written")
        for name, value in arrays(b).items():
            np.testing.assert_array_equal(value, arrays(state)[name], err_msg=f"{name} at step {k}")
        a, b = b, a
    assert np.abs(state.pad_normal_force.numpy()[:2]).max() > 0.0  # the pads did squeeze


@pytest.mark.parametrize("config, force", [
    (SolverConfig(substeps=2), 0.0),
    (SolverConfig(substeps=1, newton_iterations=1, newton_tolerance=1e-12, penetration_bound=1e-6), 0.0),
    (SolverConfig(substeps=2), 1e9),
])
def test_folded_report_equals_combine_of_the_solves(config, force):
    """Over 4 solves, the report folded on the device equals ``SolveStats.combine`` of the reports
    ``step`` returns, field by field and in dtype (cases: the default limits, world 1 converging;
    stopped at the Newton limit and deeper than a tiny penetration bound; world 1 diverging)."""
    model, state, control = build(force)
    solver = ImplicitSolver(model, config)
    reports = []
    _, state_b, control_b = build(force)
    solver_b = ImplicitSolver(model, config)
    folded = SolveReport(model.num_worlds, model.device)
    for k in range(1, 5):
        for c in (control, control_b):
            c.pad_target_positions.assign(pads(k))
        reports.append(solver.step(state, state, control, DT))
        solver_b.advance(state_b, state_b, control_b, DT)
        folded.fold(solver_b.scratch, config.penetration_bound, first=k == 1)
    expected, got = SolveStats.combine(reports), folded.download()
    for field in dataclasses.fields(SolveStats):
        e, g = getattr(expected, field.name), getattr(got, field.name)
        assert e.dtype == g.dtype, (field.name, e.dtype, g.dtype)
        np.testing.assert_array_equal(g, e, err_msg=field.name)
    if force:
        assert got.diverged.tolist() == [False, True]
    elif config.newton_iterations == 1:
        assert not got.converged.any() and got.penetrated[0]
    else:
        assert got.converged[1] and not got.diverged.any() and len(set(r.penetration[0] for r in reports)) > 1
    # a first fold restarts the report
    folded.fold(solver_b.scratch, config.penetration_bound, first=True)
    np.testing.assert_array_equal(folded.download().newton_iterations, reports[-1].newton_iterations)


def test_folded_penetration_keeps_a_nan_as_numpy_max_does():
    """A NaN penetration (a world whose state is not finite) stays NaN in the folded maximum."""
    model, state, control = build()
    solver = ImplicitSolver(model, SolverConfig(substeps=1))
    solver.step(state, state, control, DT)
    report = SolveReport(model.num_worlds, model.device)
    report.fold(solver.scratch, 1e-3, first=True)
    solver.scratch.penetration.assign(np.array([np.nan, 0.0], np.float32))
    report.fold(solver.scratch, 1e-3, first=False)
    solver.scratch.penetration.assign(np.array([0.0, 0.0], np.float32))
    report.fold(solver.scratch, 1e-3, first=False)
    pen = report.download().penetration
    assert np.isnan(pen[0]) and np.isfinite(pen[1])
    wp.synchronize()
