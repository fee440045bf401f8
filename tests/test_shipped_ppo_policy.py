"""The PPO policy shipped in ``benchmarks/policies/ppo_cuboid_scratch_goal_noise_e1e6`` (one run
from scratch on goals drawn per episode, benchmarks/RESULTS.md 2026-11-27) drives ``gym.make`` as a
plain policy object (``PPOPolicy.from_run``) at the task's goal: it picks the cuboid on seeds
whose episodes the recorded CPU evaluation (``..._eval64_15s_cpu.json``) counted as successes, at
the same steps (the CPU is bit-deterministic, and a world of the vector env equals the single env
on its seed). A change of the simulation that alters these episodes fails here: re-evaluate the
policy (``benchmarks/eval_ppo.py``) and update the recorded evaluation."""

import json
import pathlib

import gymnasium as gym
import pytest

import defgrasp_env  # noqa: F401

ROOT = pathlib.Path(__file__).resolve().parents[1]
RUN = ROOT / "benchmarks" / "policies" / "ppo_cuboid_scratch_goal_noise_e1e6"
EVALUATION = ROOT / "benchmarks" / "figures" / "ppo_cuboid_scratch_goal_noise_e1e6_h200_4p3m_eval64_15s_cpu.json"


@pytest.mark.parametrize("seed", [1000000040, 1000000056, 1000000005])
def test_the_shipped_policy_picks_the_cuboid_as_evaluated(seed):
    from defgrasp_env.rl.ppo_policy import PPOPolicy

    recorded = {e["seed"]: e for e in json.loads(EVALUATION.read_text())["episodes"]}[seed]
    assert recorded["success"]
    policy = PPOPolicy.from_run(RUN)
    assert "goal_noise" in policy.settings and "goal" not in policy.env_kwargs  # trained on drawn goals, driven at the task's
    env = gym.make("DeformablePickup-v0", **policy.env_kwargs)
    obs, info = env.reset(seed=seed)
    assert tuple(info["goal"]) == (0.0, 0.6, 0.0)
    policy.reset()
    for step in range(1, env.spec.max_episode_steps + 1):
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        if terminated or truncated:
            break
    assert info["is_success"] and terminated and not info["pierced"], (step, info["goal_distance"])
    assert step == recorded["success_step"]
