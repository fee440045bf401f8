"""Where a CUDA vector step's GPU time goes, kernel by kernel (a diagnosis, not a benchmark of record).

    python benchmarks/profile_kernels.py --device cuda:0 --worlds 1 [--object cuboid] [--steps 20]
        [--world-block-threads 0]

The native vector env (``bench_env_step.py``'s defaults: cuboid, E = 1e5 Pa, 20 Hz, 4 substeps,
seeded uniform random delta actions) is stepped twice from the same seed: first with every graph on
(the shipped path; wall ms per step, each step bracketed by ``wp.synchronize_device``), then with the
solver's graphs and the scene's period graphs off, under ``wp.timing_begin(wp.TIMING_KERNEL)``, so
that each kernel launch is timed on the GPU with CUDA events (``--world-block-threads 0``: the
solver's phase launches instead of its world blocks, so that each phase is a kernel of its own).
Printed: per kernel, launches per step, median us per launch and ms per step, largest first, and
the totals (kernel time and launches per step). With graphs on the same launches run as graph
nodes, so the launch count is what a step's graphs replay, and their sum of kernel times is a lower
bound of the graph-on step.
"""

from __future__ import annotations

import collections
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
from bench_env_step import solver_config  # noqa: E402
from machine import env_profile_arguments  # noqa: E402


def make(device: str, worlds: int, obj: str, modulus: float, graphs: bool, block_threads: int | None):
    env = gym.make_vec("DeformablePickup-v0", num_envs=worlds, vectorization_mode="vector_entry_point",
                       device=device, object=obj, youngs_modulus=modulus,
                       solver=solver_config("on" if graphs else "off", None, world_block_threads=block_threads))
    env.reset(seed=0)
    env.unwrapped.scene.period_graphs = graphs
    return env


def step_times(device: str, worlds: int, obj: str, modulus: float, warmup: int, steps: int,
               block_threads: int | None) -> np.ndarray:
    """Wall seconds of ``steps`` graph-on steps after ``warmup``."""
    env = make(device, worlds, obj, modulus, True, block_threads)
    rng = np.random.default_rng(0)
    times = []
    for k in range(warmup + steps):
        action = rng.uniform(-1, 1, (worlds, 7)).astype(np.float32)
        wp.synchronize_device(device)
        t0 = time.perf_counter()
        env.step(action)
        wp.synchronize_device(device)
        if k >= warmup:
            times.append(time.perf_counter() - t0)
    env.close()
    return np.array(times)


def kernel_times(device: str, worlds: int, obj: str, modulus: float, warmup: int, steps: int,
                 block_threads: int | None) -> list:
    """``wp.timing_end()``'s results over ``steps`` graph-off steps after ``warmup``."""
    env = make(device, worlds, obj, modulus, False, block_threads)
    rng = np.random.default_rng(0)
    for k in range(warmup + steps):
        action = rng.uniform(-1, 1, (worlds, 7)).astype(np.float32)
        if k == warmup:
            wp.synchronize_device(device)
            wp.timing_begin(cuda_filter=wp.TIMING_KERNEL)
        env.step(action)
    wp.synchronize_device(device)
    results = wp.timing_end()
    env.close()
    return results


def main(argv=None) -> int:
    ap = env_profile_arguments(__doc__.split("\n")[0], "cuda:0", steps=20)
    ap.add_argument("--top", type=int, default=40)
    ap.add_argument("--world-block-threads", type=int, default=None,
                    help="SolverConfig.world_block_threads (0: the phase launches; default: the solver's choice)")
    args = ap.parse_args(argv)
    if not wp.get_device(args.device).is_cuda:
        ap.error(f"--device must be a CUDA device (wp.timing_begin times CUDA kernels only), got {args.device!r}")
    wall = step_times(args.device, args.worlds, args.object, args.youngs_modulus, args.warmup, args.steps,
                      args.world_block_threads)
    print(f"W = {args.worlds}, {args.object}, E = {args.youngs_modulus:g}, graphs on: step median "
          f"{1e3 * np.median(wall):.3f} ms, p95 {1e3 * np.percentile(wall, 95):.3f} ms, "
          f"{args.worlds / np.median(wall):,.0f} world-steps/s")
    per_kernel = collections.defaultdict(list)
    for r in kernel_times(args.device, args.worlds, args.object, args.youngs_modulus, args.warmup, args.steps,
                          args.world_block_threads):
        per_kernel[r.name.split("_cuda_kernel_forward")[0]].append(1e3 * r.elapsed)
    rows = sorted(per_kernel.items(), key=lambda kv: -sum(kv[1]))
    total_us = sum(sum(v) for v in per_kernel.values())
    total_launches = sum(len(v) for v in per_kernel.values())
    print(f"graphs off: {total_launches / args.steps:.1f} kernel launches a step, "
          f"{total_us / args.steps / 1e3:.3f} ms of kernel time a step")
    print("| kernel | launches / step | us per launch, median | ms / step |")
    print("|---|---|---|---|")
    for name, us in rows[: args.top]:
        print(f"| `{name}` | {len(us) / args.steps:.1f} | {np.median(us):.1f} | {sum(us) / args.steps / 1e3:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
