"""Env step rate with the scripted expert, and how steady the tip-force readings are.

    .venv/bin/python benchmarks/bench_env.py [--objects cuboid sphere] [--substeps 4 2] [--no-append]

One full seeded episode per object (``DeformablePickup-v0`` defaults: E = 1e5, 20 Hz) and per
number of physics substeps; each ``env.step`` but the first (module load, launch recording) is
timed (the policy is not). Grasp steps need several
times the Newton/CG work of free-space steps, so both the median and the mean rate are given.

Tip-force steadiness: over the steps where both pads read more than 0.5 N (the object is gripped),
the largest reading divided by the median reading of that pad; a spike from an unconverged
contact solve shows up as a ratio far above 1 (the expert squeezes to ~1.5 N per pad at E = 1e4, 4-9 N at 1e5, the 20 N jaw limit above).
Prints a table and appends it, with the machine, to benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import os
import pathlib
import platform
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import defgrasp_env  # noqa: E402,F401
from defgrasp_env.envs.config import PickupConfig  # noqa: E402
from defgrasp_env.policies import ScriptedPickupExpert  # noqa: E402
from defgrasp_env.sim.meshing import OBJECT_SHAPES  # noqa: E402
from machine import append_results, git_state, host  # noqa: E402

GRIPPED_N = 0.5


def run_episode(name: str, substeps: int, seed: int) -> dict:
    solver = dataclasses.replace(PickupConfig().solver, substeps=substeps)
    env = gym.make("DeformablePickup-v0", object=name, solver=solver)
    expert = ScriptedPickupExpert.from_env(env.unwrapped)
    obs, info = env.reset(seed=seed)
    times, tips = [], []
    try:
        for _ in range(env.spec.max_episode_steps):
            action = expert(obs)
            t0 = time.perf_counter()
            obs, _, terminated, truncated, info = env.step(action)
            times.append(time.perf_counter() - t0)
            tips.append(env.unwrapped.scene.gripper.tip_force[0].copy())
            if terminated or truncated:
                break
    finally:
        env.close()
    t, tips = np.array(times[1:]), np.array(tips)  # the first step loads the kernels and records the launches
    held = tips[(tips > GRIPPED_N).all(axis=1)]
    spike = float((held.max(axis=0) / np.median(held, axis=0)).max()) if len(held) else float("nan")
    return {"object": name, "substeps": substeps, "success": bool(info.get("is_success", False)),
            "steps": len(times), "median_ms": 1e3 * float(np.median(t)), "median_rate": 1.0 / float(np.median(t)),
            "mean_rate": len(t) / float(t.sum()), "held_steps": len(held), "spike": spike}


def table(rows: list[dict]) -> str:
    lines = ["| physics substeps | object | success | steps | median step (ms) | median steps/s | mean steps/s "
             "| gripped steps | max / median tip force |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['substeps']} | {r['object']} | {'yes' if r['success'] else 'no'} | {r['steps']} | "
                     f"{r['median_ms']:.1f} | {r['median_rate']:.0f} | {r['mean_rate']:.0f} | {r['held_steps']} | "
                     f"{r['spike']:.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--objects", nargs="+", default=list(OBJECT_SHAPES), choices=list(OBJECT_SHAPES))
    p.add_argument("--substeps", type=int, nargs="+", default=[PickupConfig().solver.substeps])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-append", action="store_true", help="do not append to benchmarks/RESULTS.md")
    args = p.parse_args(argv)
    load = os.getloadavg()[0]
    rows = [run_episode(name, k, args.seed) for k in args.substeps for name in args.objects]
    commit = git_state()
    out = (f"\n## Env step rate with the scripted expert (bench_env.py), {datetime.datetime.now().isoformat(timespec='seconds')}\n\n"
           f"Machine: {host()}, load average {load:.1f} at start; Python {platform.python_version()}; env on Warp CPU; "
           f"commit {commit}.\n`DeformablePickup-v0` defaults (E = 1e5, 20 Hz), seed {args.seed}, one "
           f"episode per row; each `env.step` but the first (module load, launch recording) timed (policy "
           f"excluded). Tip force: largest / median reading "
           f"of a pad over the steps where both pads read > {GRIPPED_N} N.\n\n{table(rows)}\n")
    print(out)
    if not args.no_append:
        append_results(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
