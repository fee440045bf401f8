"""``env.step`` rate of the native vector env on any device, with random actions or the batched expert.

    python benchmarks/bench_env_step.py --device cuda:0 --worlds 1 512 4096
    python benchmarks/bench_env_step.py --device cuda:0 --worlds 512 --policy expert
    python benchmarks/bench_env_step.py --device cpu --worlds 1 16 --object random --no-append

Per W: ``gym.make_vec("DeformablePickup-v0", num_envs=W, vectorization_mode="vector_entry_point",
device=..., object=..., youngs_modulus=...)`` with the env defaults otherwise (20 Hz, NEXT_STEP
autoreset), ``reset(seed=0)``; then ``--warmup`` untimed steps and ``--steps`` timed ones, each
bracketed by ``wp.synchronize`` on the simulation's device (the wall time a learner waits for).
Actions: ``random`` = seeded uniform delta actions in [-1, 1]^7 (a fresh draw per step: an untrained
policy), ``expert`` = ``ScriptedPickupExpert`` batched over the W worlds (its time included).
Printed per row: median and p95 ms per step, world-steps/s (W / median), the physics substeps per
control step, the deepest solver-reported penetration (mm) and largest wrist force (N) over the timed
steps, and for ``expert`` the successes so far. The bare FEM core's rate for comparison comes from
``bench_fem.py`` (run it in the same session on the same machine). Appends a table with the machine to
benchmarks/RESULTS.md unless ``--no-append``.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import os
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

import defgrasp_env  # noqa: E402,F401
from defgrasp_env.envs.config import PickupConfig  # noqa: E402
from defgrasp_env.policies import ScriptedPickupExpert  # noqa: E402
from defgrasp_env.sim import SolverConfig  # noqa: E402
from machine import append_results, git_state, host  # noqa: E402


def solver_with_graphs(graphs: str) -> SolverConfig:
    """The env's default solver settings with ``graphs`` ("auto", "on", "off")."""
    return dataclasses.replace(PickupConfig().solver, graphs={"auto": None, "on": True, "off": False}[graphs])


def run_case(device: str, worlds: int, policy: str, obj: str, modulus: float, warmup: int, steps: int,
             graphs: str = "auto") -> dict:
    """Time ``steps`` env steps after ``warmup`` ones; returns one row of the table."""
    env = gym.make_vec("DeformablePickup-v0", num_envs=worlds, vectorization_mode="vector_entry_point",
                       device=device, object=obj, youngs_modulus=modulus, solver=solver_with_graphs(graphs))
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    expert = ScriptedPickupExpert.from_env(env) if policy == "expert" else None
    if expert is not None:
        expert.reset()
    times, depth, wrist, successes = [], 0.0, 0.0, 0
    for k in range(warmup + steps):
        wp.synchronize_device(device)
        t0 = time.perf_counter()
        action = expert(obs) if expert is not None else rng.uniform(-1, 1, (worlds, 7)).astype(np.float32)
        obs, _, terminated, _, info = env.step(action)
        wp.synchronize_device(device)
        successes += int(np.sum(terminated))
        if k >= warmup:
            times.append(time.perf_counter() - t0)
            depth = max(depth, float(np.max(info["penetration"])))
            wrist = max(wrist, float(np.max(info["wrist_force"])))
    substeps = env.unwrapped.scene.substeps
    env.close()
    t = np.array(times)
    return {"W": worlds, "policy": policy, "graphs": graphs, "object": obj, "E": modulus, "median_ms": 1e3 * float(np.median(t)),
            "p95_ms": 1e3 * float(np.percentile(t, 95)), "world_steps_per_s": worlds / float(np.median(t)),
            "substeps": substeps, "depth_mm": 1e3 * depth, "wrist_N": wrist, "successes": successes}


def table(rows: list[dict]) -> str:
    lines = ["| W | actions | step graphs | object | E (Pa) | substeps | median ms | p95 ms | world-steps/s | "
             "deepest mm | max wrist N | episodes won |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['W']} | {r['policy']} | {r['graphs']} | {r['object']} | {r['E']:.0e} | {r['substeps']} | "
                     f"{r['median_ms']:.1f} | {r['p95_ms']:.1f} | {r['world_steps_per_s']:,.0f} | "
                     f"{r['depth_mm']:.2f} | {r['wrist_N']:.0f} | {r['successes'] if r['policy'] == 'expert' else '-'} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--worlds", type=int, nargs="+", default=[1, 16])
    ap.add_argument("--policy", choices=["random", "expert"], default="random")
    ap.add_argument("--object", default="cuboid", help="an object name, 'random', or a mesh path")
    ap.add_argument("--youngs-modulus", type=float, default=1e5)
    ap.add_argument("--warmup", type=int, default=10)
    ap.add_argument("--steps", type=int, default=15)
    ap.add_argument("--graphs", choices=["auto", "on", "off", "both"], default="auto",
                    help="capture each solver step as one graph (SolverConfig.graphs); both: a row each, side by side")
    ap.add_argument("--no-append", action="store_true")
    args = ap.parse_args(argv)
    if min(args.worlds) < 1 or args.steps < 1 or args.warmup < 0:
        ap.error(f"--worlds and --steps must be >= 1 and --warmup >= 0, got {args.worlds}, {args.steps}, {args.warmup}")
    rows = []
    for w in args.worlds:
        for graphs in (["off", "on"] if args.graphs == "both" else [args.graphs]):
            rows.append(run_case(args.device, w, args.policy, args.object, args.youngs_modulus, args.warmup,
                                 args.steps, graphs))
            print(table(rows[-1:]).splitlines()[-1], flush=True)
    report = table(rows)
    print(report)
    if not args.no_append:
        load = os.getloadavg()[0]
        stamp = datetime.datetime.now().strftime("%Y-%m-%dT%H:%M:%S")
        append_results(f"\n## Env step rate (bench_env_step.py), {stamp}\n\nMachine: {host()}; device "
                       f"{args.device}; {git_state()}; load average (1 min) {load:.1f}; `python "
                       f"benchmarks/bench_env_step.py {' '.join(sys.argv[1:])}`; {args.warmup} warm-up and "
                       f"{args.steps} timed steps per row.\n\n{report}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
