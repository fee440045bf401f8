"""The PPO policies shipped in ``benchmarks/policies`` (``ppo_cuboid_scratch_goal_noise_e1e6``: one
run from scratch on goals drawn per episode; ``ppo_cuboid_scratch_hold_e1e6``: that policy trained
on with successes that do not end the episode and staggered worlds; benchmarks/RESULTS.md
2026-11-27) drive ``gym.make`` as plain policy objects (``PPOPolicy.from_run``) at the task's goal:
each picks the cuboid on seeds whose episodes its recorded CPU evaluation counted as successes, at
the same steps (the CPU is bit-deterministic on one kind of CPU; a world of the vector env that
recorded the evaluation repeats the single env's episode on these seeds, though not on every seed:
``test_demo``). A change of the simulation that alters these episodes fails here: re-evaluate the
policy (``benchmarks/eval_ppo.py``) and update the recorded evaluation. Last re-evaluated for the
solver's rigid-motion coarse space (2026-12-07, ``..._cpu_rigid_coarse.json``; the earlier JSONs
are the record of the earlier solver): scratch 50 -> 47 / 64, hold 60 -> 62 / 64 (the solver
before, re-evaluated on the same AMD EPYC: ``..._cpu_2026-12-07.json``); seed 1000000005 of the
scratch policy no longer picks, 1000000007 does."""

import json
import pathlib

import gymnasium as gym
import pytest

import defgrasp_env  # noqa: F401
from conftest import recording_cpu

ROOT = pathlib.Path(__file__).resolve().parents[1]
POLICIES = ROOT / "benchmarks" / "policies"
FIGURES = ROOT / "benchmarks" / "figures"
#: (policy folder, its recorded CPU evaluation)
SCRATCH = (POLICIES / "ppo_cuboid_scratch_goal_noise_e1e6", FIGURES / "ppo_cuboid_scratch_goal_noise_e1e6_h200_4p3m_eval64_15s_cpu_rigid_coarse.json")
HOLD = (POLICIES / "ppo_cuboid_scratch_hold_e1e6", FIGURES / "ppo_cuboid_hold_stagger_h200_1p1m_last_eval64_15s_cpu_rigid_coarse.json")


@pytest.mark.parametrize("shipped, seed", [(SCRATCH, 1000000040), (SCRATCH, 1000000056), (SCRATCH, 1000000007),
                                           (HOLD, 1000000000), (HOLD, 1000000002), (HOLD, 1000000005)])
def test_the_shipped_policy_picks_the_cuboid_as_evaluated(shipped, seed):
    from defgrasp_env.rl.ppo_policy import PPOPolicy

    if not recording_cpu():
        pytest.skip("the evaluation's episodes were recorded on an AMD EPYC: bit-identical there only "
                    "(conftest.recording_cpu)")
    run, evaluation = shipped
    recorded = {e["seed"]: e for e in json.loads(evaluation.read_text())["episodes"]}[seed]
    assert recorded["success"]
    policy = PPOPolicy.from_run(run)
    assert "goal_noise" in policy.settings and "goal" not in policy.env_kwargs  # trained on drawn goals, driven at the task's
    # the env's 15 s episodes, in which the evaluation ran (a run's own limit may be shorter), ending at a success
    env = gym.make("DeformablePickup-v0", **policy.make_env_kwargs(episode_seconds=15.0))
    assert env.spec.max_episode_steps == 300
    obs, info = env.reset(seed=seed)
    assert tuple(info["goal"]) == (0.0, 0.6, 0.0)
    policy.reset()
    for step in range(1, env.spec.max_episode_steps + 1):
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        if terminated or truncated:
            break
    assert info["is_success"] and terminated and not info["pierced"], (step, info["goal_distance"])
    assert step == recorded["success_step"]
