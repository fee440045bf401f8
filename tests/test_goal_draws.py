"""Goals drawn per episode (``PickupConfig.goal_noise``): validated, drawn last from each world's
RNG (zeros draw nothing, so every existing draw is unchanged), uniform in the configured box, in
the observation, the reset info, the replay spec and the episode file, equal between a vector
env's world and the single env on its seed, and used by the task: the scripted expert lifts each
world's object to that world's goal, and the success and reward are measured there."""

from __future__ import annotations

import gymnasium as gym
import h5py
import numpy as np
import pytest

from defgrasp_env import PickupConfig
from defgrasp_env.layout import ENV_STATE
from defgrasp_env.recording import HDF5Recorder, load_episode, replay_episode
from defgrasp_env.recording.reader import EpisodeFileError
from defgrasp_env.viewer.frame import EpisodeFrames

ENV_ID = "DeformablePickup-v0"
GOAL, NOISE = (0.02, 0.3, -0.01), (0.05, 0.2, 0.04)


def _vec(n: int, **kwargs):
    return gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", **kwargs)


@pytest.mark.parametrize("noise, words", [
    ((0.0, -0.1, 0.0), "goal_noise must be 3 finite numbers >= 0"),
    ((0.0, 0.1), "goal_noise must be 3 finite numbers >= 0"),
    ((0.0, float("nan"), 0.0), "goal_noise must be 3 finite numbers >= 0"),
    (0.1, "goal_noise must be 3 finite numbers >= 0"),
    ((0.0, 0.6, 0.0), "lowest goal height drawn, goal[1] - goal_noise[1] = 0.6 - 0.6 m"),
])
def test_bad_goal_noise_is_refused_naming_the_value(noise, words):
    with pytest.raises(ValueError, match=words.replace("[", r"\[").replace("]", r"\]")) as err:
        PickupConfig(goal_noise=noise)
    assert repr(noise) in str(err.value) or "0.6 - 0.6" in str(err.value)


def test_zero_noise_draws_nothing_and_noise_draws_last():
    """The default (zeros) leaves every draw as it was: the goal is the config's, the reset's
    observation equal to that of an explicit zero noise; with noise, the object, material and pose
    of the same seed are unchanged (the goal is drawn after them)."""
    plain, zeros, noisy = (gym.make(ENV_ID, **kw) for kw in ({}, {"goal_noise": (0.0, 0.0, 0.0)},
                                                              {"goal_noise": NOISE}))
    for seed in (0, 7):
        (o1, i1), (o2, i2), (o3, i3) = (e.reset(seed=seed) for e in (plain, zeros, noisy))
        np.testing.assert_array_equal(i1["goal"], PickupConfig().goal)
        for key in o1:
            np.testing.assert_array_equal(o1[key], o2[key])
        s1, s3 = i1["replay_spec"], i3["replay_spec"]
        assert (s1.object_name, s1.material, s1.position, s1.quat) == (s3.object_name, s3.material, s3.position, s3.quat)
        assert s1.goal == tuple(PickupConfig().goal) and s3.goal == tuple(i3["goal"]) != s1.goal
        np.testing.assert_array_equal(o1["agent_pos"], o3["agent_pos"])  # the same start, another goal


def test_drawn_goals_fill_the_box_and_reach_the_observation():
    """200 resets of one env (its RNG continuing): every goal inside goal +- goal_noise, the draws
    spread over the box (each axis's mean within 4 standard errors of the centre, its extremes
    within 10 % of the box's edges: a uniform sample of 200 misses them by ~0.5 %), and each
    reset's observation carries its goal (float32 of the info's float64)."""
    env = gym.make(ENV_ID, goal=GOAL, goal_noise=NOISE)
    env.reset(seed=123)
    goals = []
    for _ in range(200):
        obs, info = env.reset()
        goals.append(info["goal"])
        np.testing.assert_array_equal(ENV_STATE.get(obs["environment_state"], "goal"), info["goal"].astype(np.float32))
    goals, centre, half = np.array(goals), np.array(GOAL), np.array(NOISE)
    assert np.all(np.abs(goals - centre) <= half)
    assert np.all(np.abs(goals.mean(axis=0) - centre) < 4 * half / np.sqrt(3 * len(goals)))
    assert np.all(goals.min(axis=0) < centre - 0.9 * half) and np.all(goals.max(axis=0) > centre + 0.9 * half)


def test_vector_worlds_draw_the_single_envs_goals_through_autoresets():
    """World i of a vector env reset with seed s draws the goals of a single env reset with seed
    s + i, at the reset and at each autoreset (the single env's RNG continuing); the observation
    carries each world's own goal."""
    n, steps = 3, 2
    venv = _vec(n, goal=GOAL, goal_noise=NOISE, max_episode_steps=steps)
    obs, info = venv.reset(seed=40)
    drawn = [[g] for g in info["goal"]]
    for _ in range(2 * (steps + 1)):
        obs, *_, info = venv.step(np.zeros((n, 7), np.float32))
        if "_goal" in info:
            for w in np.flatnonzero(info["_goal"]):
                drawn[w].append(info["goal"][w])
        np.testing.assert_array_equal(ENV_STATE.get(obs["environment_state"], "goal"),
                                      venv.unwrapped.task.goals.astype(np.float32))
    single = gym.make(ENV_ID, goal=GOAL, goal_noise=NOISE)
    for w in range(n):
        assert len(drawn[w]) == 3
        want = [single.reset(seed=40 + w)[1]["goal"]] + [single.reset()[1]["goal"] for _ in range(len(drawn[w]) - 1)]
        np.testing.assert_array_equal(np.array(drawn[w]), np.array(want))
    assert len({tuple(g) for d in drawn for g in d}) == 3 * n


def test_the_expert_lifts_each_world_to_its_own_goal():
    """Two worlds with goals drawn 0.15-0.35 m high: the scripted expert (which reads the goal
    from the observation) succeeds in both; at each success the feature point lies within the
    success tolerance of its world's goal (measured here from the scene, not the env's flags),
    the info's goal distance is that distance, and the world with the lower goal succeeds first
    (each of its steps lifts less far)."""
    from defgrasp_env.policies import ScriptedPickupExpert

    venv = _vec(2, goal=(0.0, 0.25, 0.0), goal_noise=(0.0, 0.1, 0.0), max_episode_steps=200)
    obs, info = venv.reset(seed=5)
    goals = info["goal"].copy()
    assert abs(goals[0, 1] - goals[1, 1]) > 0.03, goals  # seed 5: two goals far enough apart to order
    expert = ScriptedPickupExpert.from_env(venv.unwrapped)
    success_step = [None, None]
    for k in range(200):
        action = expert(obs)
        obs, reward, terminated, truncated, info = venv.step(action)
        scene = venv.unwrapped.scene
        for w in range(2):
            if success_step[w] is None and info["is_success"][w]:
                success_step[w] = k
                feature = scene.node_positions(w).astype(np.float64).mean(axis=0)  # the feature point: mean node
                distance = np.linalg.norm(feature - goals[w])
                assert distance < PickupConfig().success_tolerance
                np.testing.assert_allclose(info["goal_distance"][w], distance, rtol=1e-9)  # summed in another order
                assert info["reward_success"][w] == 10.0
        if all(s is not None for s in success_step):
            break
        assert not truncated.any()
    assert None not in success_step, success_step
    low, high = np.argsort(goals[:, 1])
    assert success_step[low] < success_step[high], (goals, success_step)


def test_a_partial_reset_draws_goals_for_its_worlds_only():
    """``reset(options={"reset_mask": ...})``: the masked worlds draw new goals (reported with the
    mask), the others keep theirs, in the observation too."""
    from gymnasium.vector import AutoresetMode

    venv = _vec(3, goal=GOAL, goal_noise=NOISE, autoreset_mode=AutoresetMode.DISABLED)
    _, info = venv.reset(seed=60)
    before = info["goal"].copy()
    mask = np.array([True, False, True])
    obs, info = venv.reset(options={"reset_mask": mask})
    assert info["_goal"].tolist() == mask.tolist()
    now = venv.unwrapped.task.goals
    np.testing.assert_array_equal(now[1], before[1])
    np.testing.assert_array_equal(now[mask], info["goal"][mask])
    assert not np.any(now[mask] == before[mask])
    np.testing.assert_array_equal(ENV_STATE.get(obs["environment_state"], "goal"), now.astype(np.float32))


def test_recorded_episode_keeps_its_goal_and_replays_it(tmp_path):
    """The episode file stores the episode's goal (``task/goal``), the viewer's playback shows it,
    the replay spec repeats it in a fresh env, and a replay of a file whose goal was changed
    reports the goal (not a later difference of rewards)."""
    env = HDF5Recorder(gym.make(ENV_ID, goal=GOAL, goal_noise=NOISE, max_episode_steps=3), tmp_path)
    obs, info = env.reset(seed=9)
    for _ in range(3):
        env.step(np.zeros(7, np.float32))
    env.close()
    path, = sorted(tmp_path.glob("*.h5"))
    ep = load_episode(path)
    np.testing.assert_array_equal(ep["task/goal"], info["goal"])
    np.testing.assert_array_equal(EpisodeFrames(path).frame(0).goal, info["goal"])
    fresh = gym.make(ENV_ID, goal=GOAL, goal_noise=NOISE)
    obs2, info2 = info["replay_spec"].reset(fresh)
    np.testing.assert_array_equal(info2["goal"], info["goal"])
    np.testing.assert_array_equal(obs2["environment_state"], obs["environment_state"])
    assert replay_episode(path).bit_exact
    with h5py.File(path, "r+") as f:
        f["task/goal"][1] += 0.01
    with pytest.raises(EpisodeFileError, match="replayed reset gives the goal"):
        replay_episode(path)


def test_a_success_goes_on_without_termination_when_asked():
    """``terminate_on_success=False`` (for training): the expert's episode reaches the success at
    the step the default env terminates, is not terminated there, and the success and its bonus
    repeat while the object stays held at the goal, until the time limit truncates the episode;
    the steps up to the success are those of the default env (bit for bit on the CPU)."""
    from defgrasp_env.policies import ScriptedPickupExpert

    runs = {}
    for terminate in (True, False):
        env = gym.make(ENV_ID, goal=(0.0, 0.2, 0.0), terminate_on_success=terminate, max_episode_steps=120)
        obs, _ = env.reset(seed=2)
        expert = ScriptedPickupExpert.from_env(env.unwrapped)
        rows = []
        for _ in range(120):
            obs, reward, terminated, truncated, info = env.step(expert(obs))
            rows.append((reward, terminated, truncated, info["is_success"], info["reward_success"]))
            if terminated or truncated:
                break
        runs[terminate] = rows
    ended, going = runs[True], runs[False]
    first = len(ended) - 1
    assert ended[-1][1] and ended[-1][3]  # the default env terminates at its first success
    assert going[:first] == ended[:first] and going[first][3] and not going[first][1]
    assert going[first][0] == ended[first][0] and going[first][4] == 10.0
    after = going[first:]
    assert len(going) == 120 and after[-1][2] and not any(r[1] for r in going)  # truncated, never terminated
    held = [r for r in after if r[3]]
    assert len(held) > 0.8 * len(after) and all(r[4] == 10.0 for r in held)  # the expert holds it there
    assert all(r[4] == 0.0 for r in after if not r[3])
