"""Recording straight to LeRobot during collection: the dataset loads with LeRobotDataset and a
torch DataLoader, and every frame equals what the env returned (float32 of the same values)."""

import gymnasium as gym
import numpy as np
import torch

import defgrasp_env  # noqa: F401
from defgrasp_env.recording import LeRobotRecorder


def test_direct_lerobot_recording_round_trip(tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    env = LeRobotRecorder(gym.make("DeformablePickup-v0", max_episode_steps=4), tmp_path / "lr")
    rng = np.random.default_rng(0)
    expected = []
    for episode in range(2):
        obs, _ = env.reset(seed=episode)
        done = False
        while not done:
            action = rng.uniform(-1, 1, 7).astype(np.float32)
            nxt, reward, term, trunc, _ = env.step(action)
            expected.append((obs["agent_pos"], obs["environment_state"], action, reward, term or trunc))
            obs, done = nxt, term or trunc
    obs, _ = env.reset(seed=9)  # a cut-short third episode is kept too
    action = np.zeros(7, np.float32)
    _, reward, term, trunc, _ = env.step(action)
    expected.append((obs["agent_pos"], obs["environment_state"], action, reward, term or trunc))
    env.close()

    ds = LeRobotDataset("defgrasp/lr", root=tmp_path / "lr")
    assert ds.meta.fps == 20 and ds.meta.total_episodes == 3 and len(ds) == len(expected) == 9
    rows = list(torch.utils.data.DataLoader(ds, batch_size=1, shuffle=False))
    for row, (state, env_state, action, reward, done) in zip(rows, expected):
        np.testing.assert_array_equal(row["observation.state"][0].numpy(), state)
        np.testing.assert_array_equal(row["observation.environment_state"][0].numpy(), env_state)
        np.testing.assert_array_equal(row["action"][0].numpy(), action)
        assert row["next.reward"][0].item() == np.float32(reward)
        assert bool(row["next.done"][0]) == done


def test_direct_recording_keeps_the_state_fields_asked_for(tmp_path):
    """``state_fields`` as in ``to-lerobot --state-fields``: ``observation.state`` holds the env's
    wrist position, gap and tip forces (no quaternion), named by the layout."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    env = LeRobotRecorder(gym.make("DeformablePickup-v0", max_episode_steps=3), tmp_path / "lr",
                          state_fields=["tip_normal_force", "wrist_position", "jaw_gap"])
    obs, _ = env.reset(seed=1)
    seen = []
    for _ in range(3):
        seen.append(obs["agent_pos"])
        obs, *_ = env.step(np.zeros(7, np.float32))
    env.close()
    ds = LeRobotDataset("defgrasp/lr", root=tmp_path / "lr")
    assert ds.features["observation.state"]["names"] == ["wrist_x", "wrist_y", "wrist_z", "jaw_gap",
                                                         "left_tip_normal_force", "right_tip_normal_force"]
    got = np.stack([row["observation.state"][0].numpy() for row in torch.utils.data.DataLoader(ds, batch_size=1)])
    np.testing.assert_array_equal(got, np.stack(seen)[:, [0, 1, 2, 7, 8, 9]])


def test_direct_recording_names_each_episodes_goal(tmp_path):
    """With goals drawn per episode (``goal_noise``) each episode's task text names its own goal,
    as ``to-lerobot`` names an episode file's (``task_text``)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from defgrasp_env.recording.lerobot_export import task_text

    env = LeRobotRecorder(gym.make("DeformablePickup-v0", max_episode_steps=2, goal=(0.0, 0.3, 0.0),
                                   goal_noise=(0.0, 0.2, 0.0)), tmp_path / "lr")
    want = []
    for seed in (3, 4):
        _, info = env.reset(seed=seed)
        want += [task_text("cuboid", 1e5, info["goal"])] * 2
        for _ in range(2):
            env.step(np.zeros(7, np.float32))
    env.close()
    ds = LeRobotDataset("defgrasp/lr", root=tmp_path / "lr")
    got = [row["task"][0] for row in torch.utils.data.DataLoader(ds, batch_size=1, shuffle=False)]
    assert got == want and want[0] != want[2] and want[0].startswith("Pick up the cuboid (E = 1e+05 Pa) and lift it to [0, 0.")
