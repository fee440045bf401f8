"""Main demo: the scripted expert picks each of the paper's five objects; prints what happened.

``--policy ppo``: the PPO policy learned in this env without demonstrations
(``benchmarks/policies/ppo_cuboid_scratch_hold_e1e6`` of a clone of the repository; cuboid,
E = 1e6 Pa) picks the cuboid instead, once per seed of ``--episodes`` seeds from ``--seed``.

Run with ``python -m defgrasp_env.demo [--youngs-modulus 1e5] [--seed 0] [--policy ppo]``.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import time

_CACHE = pathlib.Path.cwd() / ".cache"
os.environ.setdefault("WARP_CACHE_PATH", str(_CACHE / "warp"))
os.environ.setdefault("MPLCONFIGDIR", str(_CACHE / "mpl"))
os.environ.setdefault("HF_HOME", str(_CACHE / "hf"))

#: The PPO run ``--policy ppo`` drives: a folder of the repository (not installed with the package).
SHIPPED_PPO_RUN = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "policies" / "ppo_cuboid_scratch_hold_e1e6"

HEADER = (f"{'episode':13s} {'nodes':>6s} {'tets':>6s} {'success':>7s} {'steps':>5s} {'max tip N':>9s} "
          f"{'max lift m':>10s} {'mean vM kPa':>11s} {'penetr. mm':>10s} {'ms/step':>7s}")


def run_episode(env, policy, seed: int) -> dict:
    """One episode of ``policy`` (an expert-like callable with ``reset()``) in ``env`` from ``seed``:
    its success, steps, largest tip normal force (N), feature point height (m), mean von Mises
    stress (Pa), penetration (m), wall time per step (ms) and the object's node / tet counts."""
    obs, _ = env.reset(seed=seed)
    policy.reset()
    model = env.unwrapped.scene.model
    row = {"nodes": model.num_nodes, "tets": model.num_tets, "success": False, "steps": 0,
           "tip": 0.0, "lift": 0.0, "stress": 0.0, "penetration": 0.0}
    t0 = time.perf_counter()
    while True:
        obs, _, terminated, truncated, info = env.step(policy(obs))
        row["steps"] += 1
        row["tip"] = max(row["tip"], info["left_tip_normal_force"], info["right_tip_normal_force"])
        row["lift"] = max(row["lift"], float(obs["environment_state"][1]))
        row["stress"] = max(row["stress"], info["mean_von_mises"])
        row["penetration"] = max(row["penetration"], info["penetration"])
        row["success"] = bool(info["is_success"])
        if terminated or truncated:
            break
    row["ms_per_step"] = (time.perf_counter() - t0) / row["steps"] * 1e3
    return row


def format_row(label: str, row: dict) -> str:
    return (f"{label:13s} {row['nodes']:6d} {row['tets']:6d} {str(row['success']):>7s} {row['steps']:5d} "
            f"{row['tip']:9.2f} {row['lift']:10.3f} {row['stress'] / 1e3:11.2f} {row['penetration'] * 1e3:10.3f} "
            f"{row['ms_per_step']:7.1f}")


def expert_episodes(args):
    """(label, row) of the scripted expert on each object (``--objects``, default all five)."""
    import gymnasium as gym

    from defgrasp_env.policies import RECOMMENDED_ENV_KWARGS, ScriptedPickupExpert
    from defgrasp_env.sim.meshing import OBJECT_SHAPES

    modulus = 1e5 if args.youngs_modulus is None else args.youngs_modulus
    for name in args.objects or list(OBJECT_SHAPES):
        env = gym.make("DeformablePickup-v0", object=name, youngs_modulus=modulus, **RECOMMENDED_ENV_KWARGS)
        yield name, run_episode(env, ScriptedPickupExpert.from_env(env), args.seed)
        env.close()
    print(f"(scripted expert, E = {modulus:g} Pa, seed {args.seed})")


def ppo_episodes(args):
    """(label, row) of the shipped PPO policy on the cuboid, seeds ``--seed`` .. + ``--episodes`` - 1,
    in the env's 15 s episodes (the run trained in 12 s ones) at the run's E unless ``--youngs-modulus``."""
    import gymnasium as gym

    from defgrasp_env.rl.ppo_policy import PPOPolicy

    if not SHIPPED_PPO_RUN.is_dir():
        raise SystemExit(f"--policy ppo: the shipped PPO run {SHIPPED_PPO_RUN} is not here (it is in a clone of "
                         "the repository, not in an installed package)")
    if args.objects:
        raise SystemExit(f"--policy ppo drives the cuboid it was trained on; --objects {args.objects} is for the expert")
    policy = PPOPolicy.from_run(SHIPPED_PPO_RUN)
    kwargs = policy.make_env_kwargs(episode_seconds=15.0, youngs_modulus=args.youngs_modulus)
    env = gym.make("DeformablePickup-v0", **kwargs)
    for seed in range(args.seed, args.seed + args.episodes):
        yield f"cuboid s{seed}", run_episode(env, policy, seed)
    env.close()
    print(f"(PPO policy {SHIPPED_PPO_RUN.name}, E = {kwargs['youngs_modulus']:g} Pa)")


#: ``--policy``: the episodes each choice runs.
POLICIES = {"expert": expert_episodes, "ppo": ppo_episodes}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--youngs-modulus", type=float, default=None,
                        help="Pa (default: 1e5 for the expert, the run's 1e6 for --policy ppo)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--objects", nargs="*", default=None, help="the expert's objects (default: all five)")
    parser.add_argument("--policy", choices=sorted(POLICIES), default="expert",
                        help="expert: the scripted expert on each object; ppo: the PPO policy learned in this env "
                             "(benchmarks/policies) on the cuboid")
    parser.add_argument("--episodes", type=int, default=5, help="--policy ppo: episodes (seeds --seed ...)")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes must be >= 1, got {args.episodes}")

    import warp as wp

    wp.config.quiet = True
    import defgrasp_env  # noqa: F401

    print(HEADER)
    successes = episodes = 0
    for label, row in POLICIES[args.policy](args):
        print(format_row(label, row), flush=True)
        successes, episodes = successes + row["success"], episodes + 1
    print(f"picked {successes}/{episodes}")
    return 0 if successes == episodes else 1


if __name__ == "__main__":
    raise SystemExit(main())
