"""A control period's earlier substeps write only the contact part of the solver's outputs
(``ImplicitSolver.advance(full_outputs=False)``: pad loads, contact forces, penetration), its last
substep all of them: nothing the env returns may change, since only the pad loads are read between
substeps (the gripper's sensing and the actuator force limit) and a substep's start reseeds every
tet rotation from the positions."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import defgrasp_env  # noqa: F401
from contact_rollout import rollout_outputs
from defgrasp_env.sim.solve_report import SolveReport
from defgrasp_env.sim.solver import ImplicitSolver, SolverConfig
from defgrasp_env.sim.state import State
from test_fem_batch import STATE_ROWS, build, pad_targets


def _episode(steps: int, full_everywhere: bool, monkeypatch) -> tuple[dict, int]:
    """Three worlds of objects drawn per episode, E = 1e5, the expert, the expert with noise and a
    gripper pressing into the ground (force-limit retries, patient re-solves), autoresets at 25
    steps: every observation, reward, info and final state array, and how many solver calls asked
    for the contact outputs only. ``full_everywhere``: every substep writes all outputs (the
    solver's ``full_outputs`` forced on)."""
    contact_only = []
    with monkeypatch.context() as patch:
        for name in ("advance", "launch_advance"):
            method = getattr(ImplicitSolver, name)

            def spied(*args, _method=method, **kwargs):
                contact_only.append(kwargs.get("full_outputs", True) is False)
                if full_everywhere:
                    kwargs["full_outputs"] = True
                return _method(*args, **kwargs)
            patch.setattr(ImplicitSolver, name, spied)
        env = gym.make_vec("DeformablePickup-v0", num_envs=3, vectorization_mode="vector_entry_point", object="random",
                           youngs_modulus=1e5, max_episode_steps=25)
        obs, _ = env.reset(seed=4)
        out = rollout_outputs(env, obs, steps, STATE_ROWS, seed=2)
        env.close()
    return out, sum(contact_only)


def test_contact_outputs_between_substeps_change_nothing_the_env_returns(monkeypatch):
    """40 steps through autoresets, contact from every side, on the CPU: every array bit for bit
    equal to those of full outputs at every substep."""
    steps = 40
    default, asked = _episode(steps, False, monkeypatch)
    full, _ = _episode(steps, True, monkeypatch)
    assert asked > 0  # the scene asked for contact outputs only (substeps from the host and captured periods)
    assert default.keys() == full.keys()
    differ = [k for k in default if not np.array_equal(default[k], full[k], equal_nan=default[k].dtype != object)]
    assert not differ, differ[:10]
    assert max(float(default[f"{k}/info/wrist_force"].max()) for k in range(steps)) > 5.0  # pressed, held


@pytest.mark.parametrize("threads", [0, 1, 8], ids=["phase_launches", "world_blocks", "world_blocks_8_threads"])
def test_contact_outputs_are_those_of_a_full_outputs_pass(threads, monkeypatch):
    """One advance of the FEM batch (three objects squeezed by their pads) with and without
    ``full_outputs``, through the phase launches and the world blocks (one thread a world, and 8
    cooperative CPU threads: Warp's fibers): positions, velocities, pad poses, pad loads, contact
    forces and the report's penetration bit for bit equal; without, the elastic forces and the
    residual read 0 and the von Mises stresses and their mean keep what the output state held."""
    import warp as wp

    monkeypatch.setattr(wp.config, "enable_cpu_blocks", threads > 1)
    model, state, control = build((0, 1, 2))
    control.pad_target_positions.assign(np.concatenate([pad_targets(w, 8) for w in (0, 1, 2)]))
    outs = {}
    for full in (True, False):
        solver = ImplicitSolver(model, SolverConfig(world_block_threads=threads))
        assert solver.world_block_threads == threads
        out = State.from_model(model)
        out.von_mises.fill_(123.0)
        out.mean_von_mises.fill_(7.0)
        solver.advance(state, out, control, 0.05, full_outputs=full)
        report = SolveReport(model.num_worlds, model.device)
        report.fold(solver.scratch, solver.config.penetration_bound, first=True)
        outs[full] = ({name: getattr(out, name).numpy().copy() for name in STATE_ROWS}, report.download())
    (full, full_report), (contact, contact_report) = outs[True], outs[False]
    for name in ("positions", "velocities", "pad_positions", "pad_orientations", "pad_normal_force", "pad_force",
                 "contact_force"):
        np.testing.assert_array_equal(contact[name], full[name], err_msg=name)
    np.testing.assert_array_equal(contact_report.penetration, full_report.penetration)
    assert np.abs(full["pad_normal_force"]).max() > 0.1  # the pads press
    assert np.abs(full["elastic_force"]).max() > 0.0 and not contact["elastic_force"].any()
    assert (full_report.residual_force > 0.0).all() and not contact_report.residual_force.any()
    assert not (full["von_mises"] == 123.0).any() and (contact["von_mises"] == 123.0).all()
    assert not (full["mean_von_mises"] == 7.0).any() and (contact["mean_von_mises"] == 7.0).all()
