"""Main demo: the scripted expert picks each of the paper's five objects; prints what happened.

Run with ``python -m defgrasp_env.demo [--youngs-modulus 1e5] [--seed 0]``.
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--youngs-modulus", type=float, default=1e5, help="Pa (default 1e5)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--objects", nargs="*", default=None, help="default: all five")
    args = parser.parse_args(argv)

    import gymnasium as gym
    import warp as wp

    wp.config.quiet = True
    import defgrasp_env  # noqa: F401
    from defgrasp_env.policies import RECOMMENDED_ENV_KWARGS, ScriptedPickupExpert
    from defgrasp_env.sim.meshing import OBJECT_SHAPES

    objects = args.objects or list(OBJECT_SHAPES)
    print(f"{'object':9s} {'nodes':>6s} {'tets':>6s} {'success':>7s} {'steps':>5s} {'max tip N':>9s} "
          f"{'max lift m':>10s} {'mean vM kPa':>11s} {'penetr. mm':>10s} {'ms/step':>7s}")
    successes = 0
    for name in objects:
        env = gym.make("DeformablePickup-v0", object=name, youngs_modulus=args.youngs_modulus,
                       **RECOMMENDED_ENV_KWARGS)
        expert = ScriptedPickupExpert.from_env(env)
        obs, _ = env.reset(seed=args.seed)
        expert.reset()
        scene = env.unwrapped.scene
        tip, lift, stress, pen, steps = 0.0, 0.0, 0.0, 0.0, 0
        t0 = time.perf_counter()
        success = False
        while True:
            obs, _, terminated, truncated, info = env.step(expert(obs))
            steps += 1
            tip = max(tip, info["left_tip_normal_force"], info["right_tip_normal_force"])
            lift = max(lift, float(obs["environment_state"][1]))
            stress = max(stress, info["mean_von_mises"])
            pen = max(pen, info["penetration"])
            success = bool(info["is_success"])
            if terminated or truncated:
                break
        dt_ms = (time.perf_counter() - t0) / steps * 1e3
        successes += success
        print(f"{name:9s} {scene.model.num_nodes:6d} {scene.model.num_tets:6d} {str(success):>7s} {steps:5d} "
              f"{tip:9.2f} {lift:10.3f} {stress / 1e3:11.2f} {pen * 1e3:10.3f} {dt_ms:7.1f}")
        env.close()
    print(f"picked {successes}/{len(objects)} objects at E = {args.youngs_modulus:g} Pa (seed {args.seed})")
    return 0 if successes == len(objects) else 1


if __name__ == "__main__":
    raise SystemExit(main())
