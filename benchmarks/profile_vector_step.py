"""Where the time of the native vector env's ``step`` goes on the CPU: solver versus host-side work.

    .venv/bin/python benchmarks/profile_vector_step.py [--worlds 64 256] [--steps 10] [--object cuboid]

Per W: the vector env (``gym.make_vec(..., vectorization_mode="vector_entry_point")``, defaults:
E = 1e5 Pa, 20 Hz, 4 substeps) is reset with seed 0 and stepped with seeded uniform random
actions; after 3 warm-up steps, ``--steps`` steps are timed (wall) and then the same number run
under cProfile. Printed: the step time (median, p95), the share inside ``ImplicitSolver.step``,
and the cumulative time of every function that ``env.step`` and ``PickupScene.step`` call, per
step (cProfile's own overhead inflates Python-heavy rows a little). Nothing is appended to
RESULTS.md: this is a diagnosis, not a benchmark of record.
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pathlib
import pstats
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

import defgrasp_env  # noqa: E402,F401


def callees(stats: pstats.Stats, caller_name: str, caller_file: str) -> list[tuple[str, float, int]]:
    """(function, cumulative s, calls) of everything ``caller_name`` (in a file ending with
    ``caller_file``) called, largest first."""
    rows = []
    for (file, line, name), (_cc, _nc, _tt, _ct, callers) in stats.stats.items():
        for (cfile, _cline, cname), (_ccc, cnc, _ctt, cct) in callers.items():
            if cname == caller_name and cfile.endswith(caller_file):
                rows.append((f"{pathlib.Path(file).name}:{line} {name}", cct, cnc))
    return sorted(rows, key=lambda r: -r[1])


def profile(worlds: int, steps: int, obj: str) -> None:
    env = gym.make_vec("DeformablePickup-v0", num_envs=worlds, vectorization_mode="vector_entry_point", object=obj)
    env.reset(seed=0)
    space = env.action_space
    space.seed(0)
    for _ in range(3):
        env.step(space.sample())
    times = []
    for _ in range(steps):
        a = space.sample()
        t0 = time.perf_counter()
        env.step(a)
        times.append(time.perf_counter() - t0)
    prof = cProfile.Profile()
    acts = [space.sample() for _ in range(steps)]
    prof.enable()
    for a in acts:
        env.step(a)
    prof.disable()
    env.close()
    stats = pstats.Stats(prof)
    total = sum(ct for (f, _l, n), (_cc, _nc, _tt, ct, _c) in stats.stats.items()
                if n == "step" and f.endswith("vector_env.py"))
    solver = sum(ct for (f, _l, n), (_cc, _nc, _tt, ct, _c) in stats.stats.items()
                 if n == "step" and f.endswith("sim/solver.py"))
    t = np.array(times)
    print(f"\n### W = {worlds}, {obj}: env.step median {np.median(t) * 1e3:.1f} ms, p95 "
          f"{np.percentile(t, 95) * 1e3:.1f} ms -> {worlds / np.median(t):.0f} world-steps/s; load "
          f"{os.getloadavg()[0]:.1f}")
    print(f"under cProfile: {total / steps * 1e3:.1f} ms/step, of which ImplicitSolver.step "
          f"{solver / steps * 1e3:.1f} ms ({100 * solver / total:.0f} %), outside it "
          f"{(total - solver) / steps * 1e3:.1f} ms/step")
    for caller, file in (("step", "vector_env.py"), ("step", "envs/scene.py")):
        print(f"\n{file} {caller} calls (ms per env step, share of env.step):")
        for name, ct, nc in callees(stats, caller, file)[:12]:
            print(f"  {ct / steps * 1e3:8.2f} ms {100 * ct / total:5.1f} %  {nc // steps:4d} calls/step  {name}")
    print("\nlargest own times (tottime, ms per env step):")
    for (file, line, name), (_cc, nc, tt, _ct, _c) in sorted(stats.stats.items(), key=lambda kv: -kv[1][2])[:15]:
        print(f"  {tt / steps * 1e3:8.2f} ms  {nc // steps:5d} calls/step  {pathlib.Path(file).name}:{line} {name}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--worlds", type=int, nargs="+", default=[64, 256])
    p.add_argument("--steps", type=int, default=10)
    p.add_argument("--object", default="cuboid")
    args = p.parse_args(argv)
    wp.config.quiet = True
    for w in args.worlds:
        profile(w, args.steps, args.object)
    return 0


if __name__ == "__main__":
    sys.exit(main())
