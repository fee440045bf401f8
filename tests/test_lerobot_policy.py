"""``LeRobotPolicy``: a saved LeRobot policy as a plain-Python policy object (the expert's interface)."""

import pathlib
import sys

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


@pytest.mark.parametrize("mode, size, clipped, mean, std", [
    # raw gaps ~1 m: over the 85 mm stroke
    ("absolute", 8, 7, [0.0] * 7 + [1.0], [1.0] * 7 + [0.1]),
    # raw yaws ~10 rad: over pi
    ("topdown", 5, 3, [0.0, 0.0, 0.0, 10.0, 0.0], [1.0, 1.0, 1.0, 0.1, 1.0]),
])
def test_a_policy_of_other_actions_returns_them_within_their_bounds(tmp_path, mode, size, clipped, mean, std):
    """An ACT whose action feature is ``ABSOLUTE_ACTION`` [8] or ``TOPDOWN_ACTION`` [5] (trained on
    ``--action-mode absolute`` / ``topdown`` demonstrations) is recognised by its size, returns its
    actions clipped to that layout's bounds (a gap in [0, 85 mm], a yaw in [-pi, pi] rad, not
    [-1, 1]) and drives an env of that ``action_mode``."""
    from defgrasp_env.layout import ACTION_LAYOUTS

    stats = {"action": {"mean": mean, "std": std}}
    stats |= {k: {"mean": [0.0] * n, "std": [1.0] * n}
              for k, n in (("observation.state", 10), ("observation.environment_state", 33))}
    policy = LeRobotPolicy.from_pretrained(save_untrained_act(tmp_path / mode, seed=2, action_mode=mode, stats=stats))
    assert policy.action_layout is ACTION_LAYOUTS[mode]
    env = gym.make("DeformablePickup-v0", object="sphere", youngs_modulus=1e6, action_mode=mode, max_episode_steps=3)
    obs, _ = env.reset(seed=0)
    policy.reset()
    low, high = env.action_space.low, env.action_space.high  # the layout's bounds, float32
    for _ in range(3):
        action = policy(obs)
        assert action.shape == (size,) and np.all(action >= low) and np.all(action <= high)
        assert action[clipped] == high[clipped]  # a raw value over the bound, clipped to it
        assert env.action_space.contains(action)
        obs, _, term, trunc, _ = env.step(action)
    assert trunc


def test_a_policy_without_the_wrist_orientation_ignores_it_and_reads_the_rest(tmp_path):
    """An ACT trained on ``observation.state`` = wrist position, gap and tip forces [6] (a dataset
    exported with ``--state-fields``): loaded with those fields, its action does not change when
    only the wrist quaternion of the observation changes, and does when the gap changes; loaded
    without them it is refused with the sizes named."""
    fields = ["wrist_position", "jaw_gap", "tip_normal_force"]
    ckpt = save_untrained_act(tmp_path / "nq", seed=4, state_fields=fields)
    with pytest.raises(ValueError, match=r"shape \(6,\).*give \(10,\)"):
        LeRobotPolicy.from_pretrained(ckpt)
    policy = LeRobotPolicy.from_pretrained(ckpt, state_fields=fields)
    obs, _ = gym.make("DeformablePickup-v0").reset(seed=0)
    turned = {**obs, "agent_pos": obs["agent_pos"].copy()}
    turned["agent_pos"][3:7] = [0.0, np.sin(0.6), 0.0, np.cos(0.6)]  # turned 1.2 rad about +y
    narrower = {**obs, "agent_pos": obs["agent_pos"].copy()}
    narrower["agent_pos"][7] -= 0.03
    base = policy(obs)
    np.testing.assert_array_equal(policy(turned), base)
    assert np.abs(policy(narrower) - base).max() > 0


def test_the_state_fields_come_from_the_training_dataset(tmp_path):
    """A checkpoint whose ``train_config.json`` names a dataset exported with ``--state-fields``
    loads with those fields without being told, and refuses other fields given by hand; without a
    findable dataset it falls back to the size check."""
    import json

    from test_recording_helpers import record_episodes

    from defgrasp_env.lerobot_policy import training_state_fields
    from defgrasp_env.recording import to_lerobot

    fields = ["wrist_position", "jaw_gap", "tip_normal_force"]
    record_episodes(tmp_path / "h5", seeds=(0,), steps=2)
    to_lerobot(tmp_path / "h5", tmp_path / "lr", state_fields=list(reversed(fields)))
    ckpt = save_untrained_act(tmp_path / "nq", seed=4, state_fields=fields)
    assert training_state_fields(ckpt) is None  # no train_config.json
    (ckpt / "train_config.json").write_text(json.dumps({"dataset": {"repo_id": "defgrasp/lr",
                                                                     "root": str(tmp_path / "lr")}}))
    assert training_state_fields(ckpt) == fields
    # the success-table script hands lerobot-eval the same fields unless told otherwise
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from eval_lerobot_policy import with_state_fields

    assert with_state_fields(str(ckpt), ["--env.episode_seconds=1"]) == [
        "--env.episode_seconds=1", "--env.state_fields=[wrist_position,jaw_gap,tip_normal_force]"]
    assert with_state_fields(str(ckpt), ["--env.state_fields=[jaw_gap]"]) == ["--env.state_fields=[jaw_gap]"]
    policy = LeRobotPolicy.from_pretrained(ckpt)
    obs, _ = gym.make("DeformablePickup-v0").reset(seed=0)
    np.testing.assert_array_equal(policy(obs), LeRobotPolicy.from_pretrained(ckpt, state_fields=fields)(obs))
    with pytest.raises(ValueError, match="differ from the fields its training dataset"):
        LeRobotPolicy.from_pretrained(ckpt, state_fields=["wrist_quat", "tip_normal_force"])
    (ckpt / "train_config.json").write_text(json.dumps({"dataset": {"repo_id": "defgrasp/lr",
                                                                     "root": str(tmp_path / "gone")}}))
    assert training_state_fields(ckpt) is None
    assert with_state_fields(str(ckpt), []) == []
    with pytest.raises(ValueError, match=r"shape \(6,\)"):
        LeRobotPolicy.from_pretrained(ckpt)
