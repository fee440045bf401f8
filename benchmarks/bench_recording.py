"""Recording overhead of ``HDF5Recorder``: time per env step with and without recording.

    .venv/bin/python benchmarks/bench_recording.py [--object cuboid] [--steps 100] [--episodes 4]

Two measurements:
* end to end: the same episodes (same seeds and actions) run in lockstep on a plain env and on a
  recorded one, alternating step by step; env time = reset + step calls (the file write happens
  inside the last step of the recorded episode);
* direct: the recorder's own work (per-step capture, episode write) timed in isolation and
  divided by the plain step time, which is immune to the noise of a busy machine.
Prints a table and appends it, with the machine, to benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import datetime
import os
import pathlib
import platform
import statistics
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
for var, sub in {"WARP_CACHE_PATH": "warp", "HF_HOME": "hf", "HF_LEROBOT_HOME": "lerobot"}.items():
    os.environ.setdefault(var, str(ROOT / ".cache" / sub))

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import defgrasp_env  # noqa: E402,F401
from defgrasp_env.recording import HDF5Recorder  # noqa: E402
from defgrasp_env.recording.atomic import write_episode  # noqa: E402
from defgrasp_env.recording import load_episode  # noqa: E402
from defgrasp_env.recording.capture import EpisodeBuffer, object_record, step_record  # noqa: E402
from machine import append_results, git_state, host  # noqa: E402


def actions_for(steps: int, seed: int) -> np.ndarray:
    """Down, close, up: the object is touched and lifted, so contact and stress are active."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(-0.2, 0.2, (steps, 7)).astype(np.float32)
    a[:, 1] = np.where(np.arange(steps) < steps // 3, -1.0, 0.6)
    a[:, 6] = np.where(np.arange(steps) < steps // 4, -1.0, 1.0)
    return a


def run_lockstep(plain, recorded, seed: int, actions: np.ndarray) -> tuple[float, float]:
    """Env time (s) of one episode on each env: reset + every step (the recorder writes inside the
    last one); the two envs step alternately, so load from other processes hits both alike."""
    times = {id(plain): 0.0, id(recorded): 0.0}
    for env in (plain, recorded):
        t0 = time.perf_counter()
        env.reset(seed=seed)
        times[id(env)] += time.perf_counter() - t0
    for k, a in enumerate(actions):
        for env in ((plain, recorded) if k % 2 == 0 else (recorded, plain)):
            t0 = time.perf_counter()
            env.step(a)
            times[id(env)] += time.perf_counter() - t0
    return times[id(plain)], times[id(recorded)]


def machine() -> str:
    return f"{host()}, Python {platform.python_version()}"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--object", default="cuboid")
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--episodes", type=int, default=4)
    p.add_argument("--compression", choices=["gzip", "lzf"], default=None)
    p.add_argument("--no-append", action="store_true", help="do not append to benchmarks/RESULTS.md")
    args = p.parse_args(argv)

    kwargs = {"object": args.object, "max_episode_steps": args.steps}
    plain = gym.make("DeformablePickup-v0", **kwargs)
    with tempfile.TemporaryDirectory() as tmp:
        recorded = HDF5Recorder(gym.make("DeformablePickup-v0", **kwargs), tmp, compression=args.compression)
        run_lockstep(plain, recorded, 0, actions_for(3, 0))            # warm up kernels and caches
        recorded.discard()  # the warm-up episode is cut short: not written inside a timed reset
        t_plain, t_rec = [], []
        for ep in range(args.episodes):
            a, b = run_lockstep(plain, recorded, ep, actions_for(args.steps, ep))
            t_plain.append(a / args.steps)
            t_rec.append(b / args.steps)
        # direct: the recorder's own work for one episode of args.steps steps, timed in isolation
        scene = recorded.unwrapped.scene
        obs, _ = recorded.env.reset(seed=0)
        _, reward, term, trunc, info = recorded.env.step(actions_for(1, 0)[0])
        t0 = time.perf_counter()
        buf = EpisodeBuffer(object_record(scene), obs, 0.05)
        for a in actions_for(args.steps, 0):
            buf.append(step_record(scene), a, obs, reward, term, trunc, info)
        capture = (time.perf_counter() - t0) / args.steps
        attrs = dict(load_episode(recorded.paths[-1]).attrs)
        writes = []
        for i in range(3):
            t0 = time.perf_counter()
            write_episode(pathlib.Path(tmp) / f"w{i}.h5", buf.arrays(), attrs, compression=args.compression)
            writes.append(time.perf_counter() - t0)
        write = statistics.median(writes)
        ep = load_episode(recorded.paths[-1], ["steps/node_positions", "steps/von_mises"])
        nodes, tets = ep["steps/node_positions"].shape[1], ep["steps/von_mises"].shape[1]
        size_mb = recorded.paths[-1].stat().st_size / 1e6
        recorded.close()
    plain.close()

    step = sum(t_plain) / len(t_plain)
    rec = sum(t_rec) / len(t_rec)
    e2e = 100 * (rec - step) / step
    direct = 100 * (capture + write / args.steps) / step
    rows = [
        ("object / nodes / tets", f"{args.object} / {nodes} / {tets}"),
        ("steps per episode x episodes", f"{args.steps} x {args.episodes}"),
        ("compression", str(args.compression)),
        ("plain step time (mean)", f"{step * 1e3:.2f} ms"),
        ("recorded step time (mean)", f"{rec * 1e3:.2f} ms"),
        ("capture + buffer per step", f"{capture * 1e3:.3f} ms"),
        ("stack + write episode (%.2f MB)" % size_mb, f"{write * 1e3:.1f} ms = {write / args.steps * 1e3:.3f} ms/step"),
        ("overhead end to end", f"{e2e:+.1f} %"),
        ("overhead direct (capture + write/T)", f"{direct:.2f} %"),
        ("target", "<= 10 %: " + ("met" if direct <= 10 else "NOT met")),
    ]
    width = max(len(r[0]) for r in rows)
    table = "\n".join(f"| {k:<{width}} | {v} |" for k, v in rows)
    header = f"| {'quantity':<{width}} | value |\n|{'-' * (width + 2)}|---|"
    print(header + "\n" + table)
    if not args.no_append:
        stamp = datetime.datetime.now().isoformat(timespec="seconds")
        append_results(f"\n## Recording overhead (bench_recording.py), {stamp}\n\nMachine: {machine()}; commit "
                       f"{git_state()}\n(end-to-end numbers include the noise of other processes; the direct "
                       f"figure does not)\n\n{header}\n{table}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
