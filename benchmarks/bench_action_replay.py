"""Single-env step time of a recorded action sequence, replayed lock-step (a deterministic repeat of
what a live run met), with the solver's work on the slowest steps.

    python benchmarks/bench_action_replay.py                    # the operator's stiff-torus strike
    python benchmarks/bench_action_replay.py --repeat 3 --no-append

The default sequence (``benchmarks/data/operator_torus_e1e7_paced_actions.npz``) is the 160
absolute actions the teleop bench's paced run (``bench_teleop.py``'s real-time part, the recorded
operator stream over loopback UDP) sent to the torus at E = 1e7 on 2026-12-08: a success at step 98,
then, in the episode after the reset, the operator's hand still descending drives a pad onto the
ring's rim at 0.3 m/s (step 137) and the ring jumps off the ground (steps 137-151: the steps that
cost that cell its 20 Hz). An ``.npz`` holds ``actions`` [K, A] and ``object``, ``youngs_modulus``
(Pa), ``seed``, ``action_mode``; the env is reset with that seed at the start and after every
episode end. Reported per run: mean, median, p95 and largest step time (``env.step`` wall time,
steps 3 on), the sum of the ten slowest steps, the Newton and CG iterations summed over the sequence
(``info``: accepted solves), and a digest of every observation (SHA-256 of their bytes: equal
digests from two codes mean bit-identical observations on this CPU); then the slowest steps'
iterations and world-solves (the force limit's retries and patient re-solves included).
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import os
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))

import numpy as np  # noqa: E402
from machine import append_results, git_state, host  # noqa: E402

DEFAULT = ROOT / "benchmarks" / "data" / "operator_torus_e1e7_paced_actions.npz"


def replay(path: pathlib.Path) -> dict:
    """One lock-step replay of the sequence in ``path``: per-step wall times and solver counts."""
    import gymnasium as gym

    import defgrasp_env  # noqa: F401

    data = np.load(path)
    seed = int(data["seed"])
    env = gym.make("DeformablePickup-v0", action_mode=str(data["action_mode"]), object=str(data["object"]),
                   youngs_modulus=float(data["youngs_modulus"]), device="cpu")
    scene_solves = lambda: env.unwrapped.scene.world_solves  # noqa: E731
    env.reset(seed=seed)
    rows, digest, ends = [], hashlib.sha256(), []
    for k, action in enumerate(data["actions"]):
        solves = scene_solves()
        t0 = time.perf_counter()
        obs, _, terminated, truncated, info = env.step(np.asarray(action, dtype=np.float32))
        rows.append((time.perf_counter() - t0, int(info["newton_iterations"]), int(info["cg_iterations"]),
                     scene_solves() - solves))
        for key in sorted(obs):
            digest.update(np.ascontiguousarray(obs[key]).tobytes())
        if terminated or truncated:
            ends.append((k, bool(info["is_success"])))
            env.reset(seed=seed)
    env.close()
    a = np.array(rows)
    t = a[3:, 0]
    return {"steps": len(rows), "ends": ends, "mean": t.mean(), "p50": np.median(t), "p95": np.percentile(t, 95),
            "max": t.max(), "slowest10": np.sort(t)[-10:].sum(), "newton": int(a[:, 1].sum()), "cg": int(a[:, 2].sum()),
            "digest": digest.hexdigest()[:16], "rows": a}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("actions", nargs="?", default=str(DEFAULT), help="an .npz of actions and env settings")
    p.add_argument("--repeat", type=int, default=1, help="replays (times vary, counts and digest must not)")
    p.add_argument("--slowest", type=int, default=8, help="slowest steps to list")
    p.add_argument("--no-append", action="store_true")
    p.add_argument("--results", default=str(ROOT / "benchmarks" / "RESULTS.md"))
    args = p.parse_args(argv)
    if args.repeat < 1:
        p.error(f"--repeat must be >= 1, got {args.repeat}")
    path = pathlib.Path(args.actions)
    load = os.getloadavg()[0]
    runs = [replay(path) for _ in range(args.repeat)]
    if len({(r["digest"], r["newton"], r["cg"]) for r in runs}) != 1:
        raise RuntimeError("the replays differ: the simulation is not deterministic on this machine")
    ms = lambda x: f"{1e3 * x:.1f}"  # noqa: E731
    lines = ["| run | mean / p50 / p95 / max step (ms) | ten slowest steps (ms) |", "|---|---|---|"]
    lines += [f"| {i + 1} | {ms(r['mean'])} / {ms(r['p50'])} / {ms(r['p95'])} / {ms(r['max'])} | {ms(r['slowest10'])} |"
              for i, r in enumerate(runs)]
    r = runs[0]
    slow = np.argsort(r["rows"][3:, 0])[::-1][:args.slowest] + 3
    listing = ", ".join(f"{k} ({ms(r['rows'][k, 0])} ms, {int(r['rows'][k, 1])} Newton, {int(r['rows'][k, 2])} CG, "
                        f"{int(r['rows'][k, 3])} world-solves)" for k in sorted(slow))
    out = (f"\n## Action replay (bench_action_replay.py), {datetime.datetime.now().isoformat(timespec='seconds')}\n\n"
           f"Machine: {host()}, load average {load:.1f} at start; env on Warp cpu; commit {git_state()}.\n"
           f"Sequence: {path.name} ({r['steps']} steps, episode ends {r['ends']}); Newton {r['newton']}, CG "
           f"{r['cg']} iterations; observation digest {r['digest']}.\n\n" + "\n".join(lines) +
           f"\n\nSlowest steps (run 1): {listing}.\n")
    print(out)
    if not args.no_append:
        append_results(out, args.results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
