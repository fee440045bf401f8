"""VectorHDF5Recorder: every world's episodes of the native vector env as episode files.

Truth: world w of the vector env equals a single env with the same draws (tested bitwise in
test_env.py), so every file must (1) pass the schema validator and (2) replay bit-exactly in a
fresh single env from its own config, reset data and actions (``replay_episode``: node positions
of every step compared exactly, rewards and flags too).
"""

from __future__ import annotations

import gymnasium as gym
import h5py
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import defgrasp_env  # noqa: F401
from defgrasp_env.policies import ScriptedPickupExpert
from defgrasp_env.recording import load_episode, replay_episode, validate_path
from defgrasp_env.recording.vector_recorder import VectorHDF5Recorder

ENV_ID = "DeformablePickup-v0"


def record(tmp_path, steps: int, **kwargs):
    venv = VectorHDF5Recorder(gym.make_vec(ENV_ID, **kwargs), tmp_path)
    expert = ScriptedPickupExpert.from_env(venv.unwrapped)
    obs, _ = venv.reset(seed=7)
    ended = np.zeros(venv.num_envs, int)
    for _ in range(steps):
        obs, _, terminated, truncated, _ = venv.step(expert(obs))
        ended += terminated | truncated
        expert.reset(terminated | truncated)  # those worlds start over at the next step
    venv.close()
    return venv, ended


@pytest.mark.parametrize("obj", ["cuboid", "random"])
def test_every_world_episode_is_a_valid_file_that_replays_bit_exactly(tmp_path, obj):
    """3 worlds, episodes cut at 45 steps (the expert has grasped and is lifting: contact, friction
    and stress are active), 100 steps: 2 finished episodes per world plus the unfinished third,
    written by close(). With object="random" each episode draws its object; replays name it."""
    venv, ended = record(tmp_path, 100, num_envs=3, object=obj, youngs_modulus=(1e5, 1e6), max_episode_steps=45)
    assert ended.tolist() == [2, 2, 2]
    assert len(venv.paths) == 9
    worlds = []
    for path in venv.paths:
        report = validate_path(path)
        assert report.ok, report.text()
        ep = load_episode(path)
        worlds.append(int(ep.attrs["world"]))
        result = replay_episode(ep)
        assert result.bit_exact, (path.name, result)
    assert sorted(worlds) == [0, 0, 0, 1, 1, 1, 2, 2, 2]
    with h5py.File(venv.paths[0]) as f:
        assert f.attrs["end_reason"] == "truncated"
        assert f["steps/node_positions"].shape[1:] == (load_episode(venv.paths[0])["object/rest_nodes"].shape)
    with h5py.File(venv.paths[-1]) as f:
        assert f.attrs["end_reason"] == "close"  # the third, unfinished episodes, written by close()


def test_disabled_autoreset_records_until_the_world_is_reset(tmp_path):
    """DISABLED: an ended world's further steps are not recorded; reset(options={"reset_mask"})
    starts its next episode, which also replays bit-exactly."""
    venv = VectorHDF5Recorder(gym.make_vec(ENV_ID, num_envs=2, autoreset_mode=AutoresetMode.DISABLED,
                                           max_episode_steps=5), tmp_path)
    venv.reset(seed=3)
    zero = np.zeros((2, 7), np.float32)
    for _ in range(8):  # both end (truncated) after 5 steps; 3 steps more are ignored
        venv.step(zero)
    assert len(venv.paths) == 2
    venv.reset(options={"reset_mask": np.array([True, False])})
    for _ in range(2):
        venv.step(zero)
    venv.close()  # world 0's unfinished second episode (2 steps)
    assert len(venv.paths) == 3
    eps = [load_episode(p) for p in venv.paths]
    assert [int(e.attrs["num_steps"]) for e in eps] == [5, 5, 2]
    assert eps[2].attrs["end_reason"] == "close"
    for ep in eps:
        assert replay_episode(ep).bit_exact


def test_refuses_same_step_autoreset_and_other_envs(tmp_path):
    with pytest.raises(ValueError, match="supports autoreset_mode NEXT_STEP or DISABLED, got SAME_STEP"):
        VectorHDF5Recorder(gym.make_vec(ENV_ID, num_envs=2, autoreset_mode=AutoresetMode.SAME_STEP), tmp_path)
    other = gym.make_vec("CartPole-v1", num_envs=2, vectorization_mode="sync")
    with pytest.raises(TypeError, match="needs the native DeformablePickup-v0 vector env, got SyncVectorEnv"):
        VectorHDF5Recorder(other, tmp_path)


def test_single_env_reset_option_object(tmp_path):
    """The reset option that replays of random-object worlds use: it picks the object and leaves
    the other draws as they were; an unknown object or option is refused."""
    env = gym.make(ENV_ID, object="random")
    _, info_a = env.reset(seed=11, options={"object": "torus"})
    setup_a = env.unwrapped.scene.setups[0]
    _, info_b = env.reset(seed=11, options={"object": "sphere"})
    setup_b = env.unwrapped.scene.setups[0]
    assert (info_a["object"], info_b["object"]) == ("torus", "sphere")
    assert np.array_equal(setup_a.position, setup_b.position) and setup_a.material == setup_b.material
    with pytest.raises(ValueError, match=r"reset option object must be one of \['cuboid'\], got 'torus'"):
        gym.make(ENV_ID).reset(options={"object": "torus"})
    with pytest.raises(ValueError, match=r"reset options must be a subset of \['object'\], got \['colour'\]"):
        gym.make(ENV_ID).reset(options={"colour": 1})
    with pytest.raises(ValueError, match=r"vector reset options must be a subset of \['reset_mask'\], got \['object'\]"):
        gym.make_vec(ENV_ID, num_envs=2).reset(options={"object": "cuboid"})
