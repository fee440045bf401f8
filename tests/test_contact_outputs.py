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
from contact_rollout import ExpertNoisyPress
from defgrasp_env.sim.solver import ImplicitSolver
from defgrasp_env.sim.state import State
from test_fem_batch import STATE_ROWS, build, pad_targets


def _episode(steps: int, full_everywhere: bool, monkeypatch) -> dict:
    """Three worlds of objects drawn per episode, E = 1e5, the expert, the expert with noise and a
    gripper pressing into the ground (force-limit retries, patient re-solves), autoresets at 25
    steps: every observation, reward, info and final state array. ``full_everywhere``: every
    substep writes all outputs (the solver's ``full_outputs`` forced on)."""
    with monkeypatch.context() as patch:
        if full_everywhere:
            for name in ("advance", "launch_advance"):
                method = getattr(ImplicitSolver, name)

                def forced(*args, _method=method, **kwargs):
                    kwargs["full_outputs"] = True
                    return _method(*args, **kwargs)
                patch.setattr(ImplicitSolver, name, forced)
        env = gym.make_vec("DeformablePickup-v0", num_envs=3, vectorization_mode="vector_entry_point", object="random",
                           youngs_modulus=1e5, max_episode_steps=25)
        obs, _ = env.reset(seed=4)
        policy = ExpertNoisyPress(env, seed=2)
        out = {}
        for k in range(steps):
            obs, reward, terminated, truncated, info = env.step(policy.actions(obs))
            policy.episodes_ended(terminated, truncated)
            out.update({f"{k}/obs/{name}": np.asarray(v) for name, v in obs.items()})
            out[f"{k}/reward"] = np.asarray(reward)
            out.update({f"{k}/info/{name}": np.asarray(v) for name, v in info.items() if not isinstance(v, dict)})
        scene = env.unwrapped.scene
        for name in STATE_ROWS:
            out[f"state/{name}"] = getattr(scene.state, name).numpy().copy()
        out["world_solves"] = np.array(scene.world_solves)
        env.close()
    return out


def test_contact_outputs_between_substeps_change_nothing_the_env_returns(monkeypatch):
    """40 steps through autoresets, contact from every side, on the CPU: every array bit for bit
    equal to those of full outputs at every substep."""
    steps = 40
    default = _episode(steps, False, monkeypatch)
    full = _episode(steps, True, monkeypatch)
    assert default.keys() == full.keys()
    differ = [k for k in default if not np.array_equal(default[k], full[k], equal_nan=default[k].dtype != object)]
    assert not differ, differ[:10]
    assert max(float(default[f"{k}/info/wrist_force"].max()) for k in range(steps)) > 5.0  # pressed, held


@pytest.mark.parametrize("full", [True, False])
def test_full_outputs_decides_the_elastic_part_of_an_advance(full):
    """One advance of the FEM batch (squeezed objects) into a zeroed state: the contact part (pad
    normal forces, contact forces) is written either way; the elastic forces and the von Mises
    stresses only with ``full_outputs`` (otherwise left as they were: zero)."""
    model, state, control = build((0, 1, 2))
    control.pad_target_positions.assign(np.concatenate([pad_targets(w, 8) for w in (0, 1, 2)]))
    solver = ImplicitSolver(model)
    out = State.from_model(model)
    solver.advance(state, out, control, 0.05, full_outputs=full)
    assert np.abs(out.pad_normal_force.numpy()).max() > 0.1
    assert np.abs(out.contact_force.numpy()).max() > 0.0
    assert np.isfinite(out.positions.numpy()).all()
    assert (np.abs(out.von_mises.numpy()).max() > 0.0) == full
    assert (np.abs(out.elastic_force.numpy()).max() > 0.0) == full
    assert (np.abs(out.mean_von_mises.numpy()).max() > 0.0) == full
