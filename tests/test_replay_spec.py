"""The replay spec the env emits (``info["replay_spec"]``): it repeats a world's reset in a single
env bit for bit, for single-env resets (seeded or continuing the RNG) and for vector-env worlds
(reset, partial reset and autoreset); recorders use it and read nothing private of the env."""

from __future__ import annotations

import ast
import json
import pathlib
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import defgrasp_env
from defgrasp_env.envs.pickup_env import DeformablePickupEnv
from defgrasp_env.envs.replay_spec import ReplaySpec
from defgrasp_env.envs.vector_env import DeformablePickupVectorEnv
from defgrasp_env.recording import HDF5Recorder, load_episode, replay_episode
from defgrasp_env.recording.vector_recorder import VectorHDF5Recorder

ENV_ID = "DeformablePickup-v0"
RECORDING = pathlib.Path(defgrasp_env.__file__).parent / "recording"


def _actions(n: int, steps: int, seed: int = 0) -> np.ndarray:
    """Down with the jaw closing: the pads reach the object within a few steps."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(-0.3, 0.3, size=(steps, n, 7)).astype(np.float32)
    a[..., 1] = -1.0
    a[..., 6] = 1.0
    return a


def _single_positions(spec: ReplaySpec, actions: np.ndarray, obj="cuboid") -> tuple[dict, list[np.ndarray]]:
    env = gym.make(ENV_ID, object=obj)
    obs, _ = spec.reset(env)
    scene = env.unwrapped.scene
    out = []
    for a in actions:
        env.step(a)
        out.append(scene.state.positions.numpy()[scene.model.world_nodes(0)].copy())
    env.close()
    return obs, out


def test_single_env_spec_describes_and_repeats_its_reset():
    env = gym.make(ENV_ID)
    _, info = env.reset(seed=3)
    spec = info["replay_spec"]
    setup = env.unwrapped.scene.setups[0]
    assert (spec.seed, spec.rng_state, spec.options, spec.scene_origin) == (3, None, None, None)
    assert spec.object_name == setup.object_name == "cuboid" and spec.material == setup.material
    assert spec.position == tuple(setup.position) and spec.quat == tuple(setup.quat)
    env.step(_actions(1, 1)[0, 0])
    obs, info = env.reset()  # continues the RNG: the spec holds its state and the scene's origin
    spec = info["replay_spec"]
    assert spec.seed is None and spec.rng_state["bit_generator"] == "PCG64"
    assert spec.scene_origin is not None and spec.scene_origin.seed == 3
    json.dumps(spec.to_json_dict())  # what a recorder stores
    actions = _actions(1, 4)[:, 0]
    x = []
    for a in actions:
        env.step(a)
        x.append(env.unwrapped.scene.node_positions(0))
    obs_replay, x_replay = _single_positions(spec, actions)
    for key in obs:
        np.testing.assert_array_equal(obs[key], obs_replay[key])
    for a, b in zip(x, x_replay):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("obj", ["cuboid", "random"])
def test_vector_world_replays_bit_exactly_in_a_single_env(obj):
    """World 1 of a 2-world vector env after an autoreset (NEXT_STEP) and after a partial reset
    without a seed (its RNG state): the spec each emits, applied to a fresh single env, gives the
    same first observation and the same node positions at every step, bit for bit (CPU)."""
    venv = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", max_episode_steps=2,
                        object=obj)
    _, info = venv.reset(seed=4)
    assert info["_replay_spec"].tolist() == [True, True]
    assert [s.seed for s in info["replay_spec"]] == [4, 5]  # the env's seed + i rule, nowhere else
    for a in _actions(2, 2, seed=1):
        _, _, _, truncated, info = venv.step(a)
    assert truncated.all() and not info.get("_replay_spec", np.zeros(2, bool)).any()
    actions = _actions(2, 3, seed=2)
    obs, _, _, _, info = venv.step(actions[0])  # NEXT_STEP: both worlds start over; the action is ignored
    assert info["_replay_spec"].tolist() == [True, True]
    spec = info["replay_spec"][1]
    assert spec.seed is None and spec.rng_state is not None and spec.options is None
    assert info["object"][1] == spec.object_name and info["youngs_modulus"][1] == spec.material.youngs_modulus
    # the world's build is its origin unless this reset drew another object (then it built it)
    assert spec.scene_origin is None or spec.scene_origin.seed == 5
    scene = venv.unwrapped.scene
    x = []
    for a in actions[1:]:
        venv.step(a)
        x.append(scene.state.positions.numpy()[scene.model.world_nodes(1)].copy())
    obs_single, x_single = _single_positions(spec, actions[1:, 1], obj)
    for key in obs:
        np.testing.assert_array_equal(obs[key][1], obs_single[key])
    for k, (a, b) in enumerate(zip(x, x_single)):
        assert np.array_equal(a, b), f"step {k}: max |dx| = {np.abs(a - b).max():.3e} m"
    venv.close()


def test_a_world_replays_bit_exactly_whatever_the_other_worlds_do():
    """The substep count depends on the config only: world 0 takes the largest legal move (every
    delta axis saturated), world 1 a gentle one; world 1 replayed alone in a single env gives the
    same node positions bit for bit (with a batch-wide count adapted to the actions, world 0's
    move gave world 1 more substeps than its replay: 1.4e-7 m apart at the first step)."""
    venv = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point")
    _, info = venv.reset(seed=11)
    spec = info["replay_spec"][1]
    actions = np.zeros((4, 2, 7), np.float32)
    actions[:, 0] = [-1.0, 1.0, -1.0, 1.0, -1.0, -1.0, 1.0]
    actions[:, 1, 1] = -0.5
    scene = venv.unwrapped.scene
    x = []
    for a in actions:
        venv.step(a)
        x.append(scene.state.positions.numpy()[scene.model.world_nodes(1)].copy())
    _, x_single = _single_positions(spec, actions[:, 1])
    for k, (a, b) in enumerate(zip(x, x_single)):
        assert np.array_equal(a, b), f"step {k}: max |dx| = {np.abs(a - b).max():.3e} m"
    venv.close()


def test_partial_reset_emits_specs_only_for_the_reset_worlds():
    venv = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point",
                        autoreset_mode=AutoresetMode.DISABLED)
    venv.reset(seed=[10, None, 12])
    _, info = venv.reset(options={"reset_mask": np.array([False, True, False])})
    assert info["_replay_spec"].tolist() == [False, True, False]
    assert info["replay_spec"][0] is None and info["replay_spec"][2] is None
    assert info["replay_spec"][1].seed is None and info["replay_spec"][1].scene_origin.seed is None
    assert info["replay_spec"][1].scene_origin.rng_state is not None  # the unseeded build is replayable too
    venv.close()


def _private_reads(path: pathlib.Path) -> list[str]:
    """``x._name`` where x is not ``self`` (reading another object's private attribute)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")
                and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"))):
            out.append(f"{path.name}: {ast.unparse(node)}")
    return out


def test_recorders_read_no_private_attribute_and_no_seed_rule():
    files = [RECORDING / n for n in ("recorder.py", "vector_recorder.py", "lerobot_recorder.py", "capture.py",
                                     "writer.py", "lerobot_export.py")]
    assert sum((_private_reads(f) for f in files), []) == []
    for f in files:
        assert "seed + " not in f.read_text(), f"{f.name} repeats the env's seed rule"


class _Guard:
    """Mixin: reading the env privates that recorders used to read, from recording code, fails."""

    GUARDED = ("_np_random", "_needs_reset", "_rngs")

    def __getattribute__(self, name):
        if name in _Guard.GUARDED:
            caller = sys._getframe(1).f_globals.get("__name__", "")
            if caller.startswith("defgrasp_env.recording"):
                raise AttributeError(f"{caller} read the env's private {name}")
        return object.__getattribute__(self, name)


class GuardedVectorEnv(_Guard, DeformablePickupVectorEnv):
    pass


class GuardedEnv(_Guard, DeformablePickupEnv):
    pass


def test_recorders_work_on_envs_that_hide_their_privates(tmp_path):
    venv = VectorHDF5Recorder(GuardedVectorEnv(num_envs=2, max_episode_steps=2), tmp_path / "vec")
    venv.reset()  # unseeded: the env's spec holds the RNG state
    for a in _actions(2, 4):
        venv.step(a)
    venv.close()
    assert len(venv.paths) == 4  # 2 truncated + 2 cut short by close
    env = HDF5Recorder(GuardedEnv(), tmp_path / "single")
    env.reset()
    for a in _actions(1, 2)[:, 0]:
        env.step(a)
    env.close()
    for path in venv.paths[:2] + env.paths:
        ep = load_episode(path)
        assert ep.replay["seed"] is None and ep.replay["rng_state"] is not None
    # replay needs the registered env id (the guarded classes are not registered): rewrite it
    import h5py

    for path in venv.paths[:1] + env.paths:
        with h5py.File(path, "r+") as f:
            f.attrs["env_id"] = ENV_ID
        assert replay_episode(path).bit_exact
