"""Native vector env step time, with the FEM solver stubbed out (host work only) or real, for this
checkout and optionally another one side by side (before/after a change).

    .venv/bin/python benchmarks/bench_host_step.py --worlds 4096 --solver stub [--compare DIR] [--steps 10]
    .venv/bin/python benchmarks/bench_host_step.py --worlds 16 64 --solver real [--compare DIR]

Per checkout and W, a child process makes ``gym.make_vec("DeformablePickup-v0", num_envs=W,
vectorization_mode="vector_entry_point", youngs_modulus=1e5)`` (cuboid, 4 substeps), resets it with
seed 0, takes 3 warm-up steps and times ``--steps`` steps of seeded uniform random actions (the same
actions for every checkout). ``--solver stub`` replaces the solver call that the scene makes
(``ImplicitSolver.advance``, or ``ImplicitSolver.step`` in checkouts before it existed) by one that
leaves the state as it is and reports zero iterations: what remains is the env's host work and
its device round trips outside the solver. Checkouts run alternately (A B A B ...,
``--repeats`` rounds), so load changes hit both. Prints median and p95 ms per step and world-steps/s,
with the 1-minute load average after each run; ``--append`` appends the table to RESULTS.md.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]


def child(repo: str, worlds: int, steps: int, solver: str) -> dict:
    """Time the steps in this process with ``repo``'s defgrasp_env; returns the measurement."""
    sys.path.insert(0, repo)
    os.environ.setdefault("WARP_CACHE_PATH", str(pathlib.Path(repo) / ".cache" / "warp"))
    import gymnasium as gym
    import numpy as np
    import warp as wp

    wp.config.quiet = True
    import defgrasp_env
    from defgrasp_env.sim import solver as solver_module

    assert pathlib.Path(defgrasp_env.__file__).resolve().is_relative_to(pathlib.Path(repo).resolve())
    env = gym.make_vec("DeformablePickup-v0", num_envs=worlds, vectorization_mode="vector_entry_point",
                       youngs_modulus=1e5)
    env.reset(seed=0)
    if hasattr(env.unwrapped.scene, "period_graphs"):  # a stubbed or timed solve must go through ``advance``
        env.unwrapped.scene.period_graphs = False
    if solver == "stub":
        cls = solver_module.ImplicitSolver
        if hasattr(cls, "advance"):
            cls.advance = lambda self, *args, **kwargs: None
        else:
            def stub(self, state_in, state_out, control, dt):
                z = np.zeros(worlds)
                return solver_module.SolveStats(z.astype(np.int32), z.astype(np.int32), z.astype(np.float32),
                                                z.astype(np.float32), z.astype(np.float32), z.astype(bool),
                                                ~z.astype(bool), z.astype(bool))
            cls.step = stub
    rng = np.random.default_rng(0)
    actions = [rng.uniform(-1, 1, (worlds, 7)).astype(np.float32) for _ in range(steps + 3)]
    for a in actions[:3]:
        env.step(a)
    times = []
    for a in actions[3:]:
        t0 = time.perf_counter()
        env.step(a)
        times.append(time.perf_counter() - t0)
    t = np.array(times)
    return {"median_ms": 1e3 * float(np.median(t)), "p95_ms": 1e3 * float(np.percentile(t, 95)),
            "rate": worlds / float(np.median(t)), "load": os.getloadavg()[0]}


def git_commit(repo: str) -> str:
    out = subprocess.run(["git", "-C", repo, "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    dirty = subprocess.run(["git", "-C", repo, "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True).stdout.strip()
    return (out.stdout.strip() or "(no git)") + ("+dirty" if dirty else "")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--worlds", type=int, nargs="+", default=[4096])
    p.add_argument("--steps", type=int, default=10)
    p.add_argument("--solver", choices=("stub", "real"), default="stub")
    p.add_argument("--compare", help="another checkout of the repo (e.g. the commit before a change)")
    p.add_argument("--label", default="before", help="name of the --compare checkout in the table")
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--append", action="store_true", help="append the table to benchmarks/RESULTS.md")
    p.add_argument("--child", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child, args.worlds[0], args.steps, args.solver)))
        return 0
    repos = ([(args.label, args.compare)] if args.compare else []) + [("this", str(ROOT))]
    rows = []
    for w in args.worlds:
        for _ in range(args.repeats):
            for label, repo in repos:
                out = subprocess.run([sys.executable, __file__, "--child", repo, "--worlds", str(w), "--steps",
                                      str(args.steps), "--solver", args.solver], capture_output=True, text=True,
                                     cwd=repo, env={**os.environ, "PYTHONPATH": repo})
                if out.returncode:
                    raise RuntimeError(f"child for {repo} W={w} failed:\n{out.stderr[-3000:]}")
                r = json.loads(out.stdout.strip().splitlines()[-1])
                rows.append({"W": w, "label": label, "commit": git_commit(repo), **r})
                print(rows[-1], flush=True)
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from machine import append_results, host

    lines = [f"Machine: {host()}; Warp CPU; solver {args.solver}; cuboid, E = 1e5 Pa, 4 substeps, uniform random "
             f"actions; {args.steps} timed steps after 3 warm-up per run, runs alternated ({args.repeats} rounds).", "",
             "| W | checkout | commit | step median ms | step p95 ms | world-steps/s | load (1 min) |", "|---" * 7 + "|"]
    for r in rows:
        lines.append(f"| {r['W']} | {r['label']} | {r['commit']} | {r['median_ms']:.1f} | {r['p95_ms']:.1f} | "
                     f"{r['rate']:.0f} | {r['load']:.1f} |")
    out = "\n".join(lines)
    print(out)
    if args.append:
        append_results(out + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
