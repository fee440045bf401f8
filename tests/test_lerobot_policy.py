"""``LeRobotPolicy``: a saved LeRobot policy as a plain-Python policy object (the expert's interface)."""

import gymnasium as gym
import numpy as np
import pytest

import defgrasp_env  # noqa: F401

pytest.importorskip("lerobot")

from defgrasp_env.lerobot_policy import LeRobotPolicy, save_untrained_act  # noqa: E402


@pytest.fixture(scope="module")
def policy(tmp_path_factory):
    return LeRobotPolicy.from_pretrained(save_untrained_act(tmp_path_factory.mktemp("act") / "m", seed=1))


def test_policy_drives_gym_make_to_the_end_of_an_episode(policy):
    env = gym.make("DeformablePickup-v0", object="cylinder", youngs_modulus=1e6, max_episode_steps=6)
    obs, _ = env.reset(seed=4)
    policy.reset()
    steps, done = 0, False
    while not done:
        action = policy(obs)
        assert action.shape == (7,) and action.dtype == np.float32 and np.all(np.abs(action) <= 1.0)
        obs, _, term, trunc, info = env.step(action)
        steps, done = steps + 1, term or trunc
    assert steps == 6 and trunc and not info["is_success"]


def test_batch_equals_single_observations(policy):
    env = gym.make("DeformablePickup-v0")
    obs = [env.reset(seed=s)[0] for s in (0, 1, 2)]
    batch = {k: np.stack([o[k] for o in obs]) for k in obs[0]}
    policy.reset()
    out = policy(batch)
    assert out.shape == (3, 7)
    for i, o in enumerate(obs):
        policy.reset()
        np.testing.assert_allclose(policy(o), out[i], atol=1e-6)


def test_reset_mask_and_bad_input(policy, tmp_path):
    env = gym.make("DeformablePickup-v0")
    obs, _ = env.reset(seed=0)
    batch = {k: np.stack([v, v]) for k, v in obs.items()}
    policy(batch)
    policy.reset(np.array([True, False]))  # n_action_steps == 1: no state kept, partial reset is fine
    with pytest.raises(ValueError, match="shape"):
        policy.reset(np.array([True, False, True]))
    with pytest.raises(ValueError, match="finite"):
        policy({**obs, "agent_pos": np.full(10, np.nan, np.float32)})
    with pytest.raises(TypeError):
        policy(np.zeros(43))
    with pytest.raises(FileNotFoundError):
        LeRobotPolicy.from_pretrained(tmp_path)


def test_a_policy_of_absolute_actions_returns_them_within_their_bounds(tmp_path):
    """An ACT whose action feature is ``ABSOLUTE_ACTION`` [8] (trained on ``--action-mode absolute``
    demonstrations) returns [8] actions clipped to that layout's bounds (a gap in [0, 85 mm], not
    [-1, 1]) and drives an ``action_mode="absolute"`` env."""
    from defgrasp_env.layout import ABSOLUTE_ACTION

    stats = {"action": {"mean": [0.0] * 7 + [1.0], "std": [1.0] * 7 + [0.1]}}  # raw gaps ~1 m: over the stroke
    stats |= {k: {"mean": [0.0] * n, "std": [1.0] * n}
              for k, n in (("observation.state", 10), ("observation.environment_state", 33))}
    policy = LeRobotPolicy.from_pretrained(save_untrained_act(tmp_path / "abs", seed=2, action_mode="absolute",
                                                              stats=stats))
    assert policy.action_layout is ABSOLUTE_ACTION
    env = gym.make("DeformablePickup-v0", object="sphere", youngs_modulus=1e6, action_mode="absolute",
                   max_episode_steps=3)
    obs, _ = env.reset(seed=0)
    policy.reset()
    low, high = env.action_space.low, env.action_space.high  # the layout's bounds, float32
    for _ in range(3):
        action = policy(obs)
        assert action.shape == (8,) and np.all(action >= low) and np.all(action <= high)
        assert action[7] == high[7]  # a raw ~1 m gap clipped to the 85 mm stroke
        assert env.action_space.contains(action)
        obs, _, term, trunc, _ = env.step(action)
    assert trunc


def test_a_policy_of_topdown_actions_drives_a_topdown_env(tmp_path):
    """An ACT whose action feature is ``TOPDOWN_ACTION`` [5] (``--action-mode topdown``
    demonstrations) is recognised by its size, returns [5] actions within that layout's bounds (a
    yaw in [-pi, pi] rad) and drives an ``action_mode="topdown"`` env."""
    from defgrasp_env.layout import TOPDOWN_ACTION

    stats = {"action": {"mean": [0.0] * 5, "std": [1.0, 1.0, 1.0, 10.0, 1.0]}}  # raw yaws over pi: clipped
    stats |= {k: {"mean": [0.0] * n, "std": [1.0] * n}
              for k, n in (("observation.state", 10), ("observation.environment_state", 33))}
    policy = LeRobotPolicy.from_pretrained(save_untrained_act(tmp_path / "td", seed=4, action_mode="topdown",
                                                              stats=stats))
    assert policy.action_layout is TOPDOWN_ACTION
    env = gym.make("DeformablePickup-v0", object="sphere", youngs_modulus=1e6, action_mode="topdown",
                   max_episode_steps=3)
    obs, _ = env.reset(seed=0)
    policy.reset()
    for _ in range(3):
        action = policy(obs)
        assert action.shape == (5,) and env.action_space.contains(action)
        obs, _, term, trunc, _ = env.step(action)
    assert trunc
