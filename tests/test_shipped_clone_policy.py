"""The five-object policy cloned from the scripted expert, shipped in ``benchmarks/policies``
(``ppo_five_expert_clone_e1e6``; ``train_ppo.py --clone-expert-steps``, benchmarks/RESULTS.md
2026-12-06), drives ``gym.make`` as a plain policy object at the task's goal: it picks the sphere
and the cylinder (50 / 50 each in its GPU evaluation, 8 / 8 each on this CPU) and the torus on a
seed its CPU evaluation counted as a success. Not compared step for step (the recorded episodes
are bit-identical on one kind of CPU only, tests/conftest.recording_cpu): success within the
env's 15 s and no pierced step."""

import json
import pathlib

import gymnasium as gym
import pytest

import defgrasp_env  # noqa: F401

ROOT = pathlib.Path(__file__).resolve().parents[1]
CLONE = ROOT / "benchmarks" / "policies" / "ppo_five_expert_clone_e1e6"


@pytest.mark.parametrize("obj, seed", [("sphere", 1000000001), ("cylinder", 1000000003), ("torus", 1000000007)])
def test_the_shipped_clone_picks_an_object_at_the_tasks_goal(obj, seed):
    from defgrasp_env.rl.ppo_policy import PPOPolicy

    policy = PPOPolicy.from_run(CLONE)
    assert policy.settings["clone_expert"]["samples"] == 600_000 and policy.settings["fixed_world_objects"]
    env = gym.make("DeformablePickup-v0", **policy.make_env_kwargs(object=obj, episode_seconds=15.0))
    obs, info = env.reset(seed=seed)
    assert tuple(info["goal"]) == (0.0, 0.6, 0.0) and info["object"] == obj
    policy.reset()
    pierced = 0
    for step in range(1, env.spec.max_episode_steps + 1):
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        pierced += bool(info["pierced"])
        if terminated or truncated:
            break
    assert info["is_success"] and terminated and pierced == 0, (step, info["goal_distance"])
    assert json.loads((CLONE / "run.json").read_text())["actions"] == "position-yaw-jaw"
