"""Native vector env with one object versus mixed objects: reset cost and step rate on this machine.

    .venv/bin/python benchmarks/bench_vector_env.py [--worlds 16 64] [--steps 5] [--device cpu] [--no-append]

Per W and per ``object`` ("cuboid": one object; "random": a fresh object per world per episode):
``gym.make_vec(..., vectorization_mode="vector_entry_point")`` with defaults (E = 1e5 Pa, 20 Hz,
4 substeps), ``autoreset_mode=DISABLED``. Timed: the first ``reset(seed=0)`` (builds the scene),
a full ``reset()`` (continuing the RNGs: with "random" most worlds change object, so the flat
arrays are rebuilt), a partial reset of a quarter of the worlds (and whether it rebuilt), the step after it (a
rebuilt solver records its launches there), and, after 2 more warm-up steps, ``--steps`` steps with seeded uniform random actions (median, p95,
world-steps/s, and node-steps/s = world-steps/s x mean nodes per world, since the five objects
differ in size). ``--episode-steps N``: also the rate of ``--steps`` steps of an env whose episodes
end after N steps (``max_episode_steps``, next-step autoresets: W / N worlds reset a step, with
"random" most to another object: a learner's batch), after N warm-up steps. A slotted scene
(``PickupScene.slots``, the default on CUDA with several objects) changes objects in place; a
packed one rebuilds. Prints a table and appends it with the machine and load to benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
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
from gymnasium.vector import AutoresetMode  # noqa: E402

import defgrasp_env  # noqa: E402,F401
from machine import append_results, git_state, host  # noqa: E402


def _timed(fn) -> float:
    """Wall seconds of ``fn()``, its device work included (synchronised before and after)."""
    wp.synchronize()
    t0 = time.perf_counter()
    fn()
    wp.synchronize()
    return time.perf_counter() - t0


def run(worlds: int, obj: str, steps: int, device: str = "cpu", modulus=1e5) -> dict:
    env = gym.make_vec("DeformablePickup-v0", num_envs=worlds, vectorization_mode="vector_entry_point", object=obj,
                       autoreset_mode=AutoresetMode.DISABLED, device=device, youngs_modulus=modulus)
    build = _timed(lambda: env.reset(seed=0))
    full = _timed(lambda: env.reset())
    scene = env.unwrapped.scene
    before = scene.model
    mask = np.zeros(worlds, bool)
    mask[:: 4] = True
    partial = _timed(lambda: env.reset(options={"reset_mask": mask}))
    rebuilt = scene.model is not before
    space = env.action_space
    space.seed(0)
    first = _timed(lambda: env.step(space.sample()))  # records the solver launches of a rebuilt model
    for _ in range(2):
        env.step(space.sample())
    times = []
    for _ in range(steps):
        a = space.sample()
        times.append(_timed(lambda: env.step(a)))
    m = scene.model  # the objects' nodes (a slotted model's spare rows excluded)
    nodes = int(np.sum(getattr(m, "node_end", m.node_start[1:]) - m.node_start[:-1]))
    env.close()
    t = np.array(times)
    return {"W": worlds, "object": obj, "nodes": nodes, "build_ms": 1e3 * build, "full_ms": 1e3 * full,
            "partial_ms": 1e3 * partial, "rebuilt": rebuilt, "first_ms": 1e3 * first, "median_ms": 1e3 * float(np.median(t)),
            "p95_ms": 1e3 * float(np.percentile(t, 95)), "rate": worlds / float(np.median(t)),
            "load": os.getloadavg()[0]}


def autoreset_rate(worlds: int, obj: str, steps: int, device: str, episode_steps: int, modulus=1e5) -> dict:
    """World-steps/s of ``steps`` random-action steps with episodes of ``episode_steps`` steps
    (autoresets), after ``episode_steps`` warm-up steps that stagger the episodes (at warm-up step
    k the worlds w = k mod ``episode_steps`` are reset: from then on 1 / ``episode_steps`` of the
    worlds end an episode at every step, as terminations spread a learner's episodes); whether the
    scene is slotted and whether its model was rebuilt during the timed steps."""
    env = gym.make_vec("DeformablePickup-v0", num_envs=worlds, vectorization_mode="vector_entry_point", object=obj,
                       max_episode_steps=episode_steps, device=device, youngs_modulus=modulus)
    env.reset(seed=0)
    space = env.action_space
    space.seed(1)
    for k in range(episode_steps):
        env.reset(options={"reset_mask": np.arange(worlds) % episode_steps == k})
        env.step(space.sample())
    scene = env.unwrapped.scene
    model = scene.model
    times = []
    for _ in range(steps):
        a = space.sample()
        times.append(_timed(lambda: env.step(a)))
    out = {"auto_median_ms": 1e3 * float(np.median(times)), "auto_rate": worlds / float(np.median(times)),
           "slotted": getattr(scene, "slots", None) is not None, "auto_rebuilt": scene.model is not model}
    env.close()
    return out


def table(rows: list[dict]) -> str:
    lines = ["| W | object | nodes (all worlds) | first reset (build) ms | full reset ms | reset of W/4 ms "
             "(rebuilt?) | next step ms | step median ms | step p95 ms | world-steps/s | node-steps/s | "
             "with autoresets: step median ms | world-steps/s (slotted? rebuilt?) | load |",
             "|---" * 14 + "|"]
    for r in rows:
        auto = ("- | -" if "auto_rate" not in r else
                f"{r['auto_median_ms']:.0f} | {r['auto_rate']:.0f} ({'slotted' if r['slotted'] else 'packed'}, "
                f"{'rebuilt' if r['auto_rebuilt'] else 'not rebuilt'})")
        lines.append(f"| {r['W']} | {r['object']} | {r['nodes']} | {r['build_ms']:.0f} | {r['full_ms']:.0f} | "
                     f"{r['partial_ms']:.0f} ({'yes' if r['rebuilt'] else 'no'}) | {r['first_ms']:.0f} | "
                     f"{r['median_ms']:.0f} | {r['p95_ms']:.0f} | {r['rate']:.0f} | {r['rate'] * r['nodes'] / r['W']:.0f} | "
                     f"{auto} | {r['load']:.1f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--worlds", type=int, nargs="+", default=[16, 64])
    p.add_argument("--steps", type=int, default=5)
    p.add_argument("--device", default="cpu", help="the simulation's Warp device (cpu, cuda:0)")
    p.add_argument("--youngs-modulus", type=float, nargs="+", default=[1e5],
                   help="E (Pa); several: drawn per world per episode (materials change at resets)")
    p.add_argument("--episode-steps", type=int, default=0,
                   help="also time steps with episodes of this many steps (autoresets; 0: off)")
    p.add_argument("--no-append", action="store_true", help="do not append to benchmarks/RESULTS.md")
    args = p.parse_args(argv)
    wp.config.quiet = True
    modulus = args.youngs_modulus[0] if len(args.youngs_modulus) == 1 else tuple(args.youngs_modulus)
    rows = []
    for w in args.worlds:
        for obj in ("cuboid", "random"):
            rows.append(run(w, obj, args.steps, args.device, modulus))
            if args.episode_steps > 0:
                rows[-1].update(autoreset_rate(w, obj, args.steps, args.device, args.episode_steps, modulus))
    out = (f"\n## Vector env, one object vs mixed objects (bench_vector_env.py), "
           f"{datetime.datetime.now().isoformat(timespec='seconds')}\n\n"
           f"Machine: {host()}; Warp {args.device}; commit {git_state()}; E = {modulus} Pa; random actions, {args.steps} timed steps after 3 "
           f"warm-up ('next step': the first of those, after the reset of W/4); load average (1 min) after each row in the table.\n\n{table(rows)}\n")
    print(out)
    if not args.no_append:
        append_results(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
