"""Dataset generation rate: episodes per minute of ``defgrasp-generate``, serial and on a local Ray.

    .venv/bin/python benchmarks/bench_generate.py [--episodes 8] [--workers 1,2] [--policy ...]

The same jobs (default: cuboid, E = 1e5, the scripted expert, full episodes) are recorded into a
fresh folder by the serial run and by a local Ray with 1, 2, ... workers (one CPU each). The Ray
rate counts from task submission to the last file (worker process start, imports and Warp module
loads included, as in a real run); the cluster start is reported apart. Every run's files are
checked to hold the serial run's data. Prints a table and appends it to benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import datetime
import os
import pathlib
import platform
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
for var, sub in {"WARP_CACHE_PATH": "warp", "HF_HOME": "hf", "HF_LEROBOT_HOME": "lerobot"}.items():
    os.environ.setdefault(var, str(ROOT / ".cache" / sub))

import h5py  # noqa: E402
import numpy as np  # noqa: E402

from defgrasp_env.recording.distributed import run_jobs_ray  # noqa: E402
from defgrasp_env.recording.generate import DEFAULT_POLICY, plan_jobs, run_jobs  # noqa: E402
from machine import append_results, git_state, host  # noqa: E402


def _load() -> str:
    return "%.1f" % os.getloadavg()[0]


def _steps_and_data(d: pathlib.Path, names: list[str]) -> tuple[int, dict]:
    steps, data = 0, {}
    for n in names:
        with h5py.File(d / n, "r") as f:
            steps += int(f.attrs["num_steps"])
            data[n] = (f["steps/node_positions"][()], f["steps/action"][()])
    return steps, data


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--object", default="cuboid")
    p.add_argument("--modulus", type=float, default=1e5)
    p.add_argument("--episodes", type=int, default=8)
    p.add_argument("--workers", default="1,2", help="comma-separated local Ray worker counts")
    p.add_argument("--policy", default=DEFAULT_POLICY)
    p.add_argument("--max-steps", type=int, default=None)
    p.add_argument("--no-append", action="store_true", help="do not append to benchmarks/RESULTS.md")
    args = p.parse_args(argv)
    import ray

    jobs = plan_jobs([args.object], [args.modulus], args.episodes, 0)
    names = [j.name for j in jobs]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        ref = pathlib.Path(tmp) / "serial"
        run_jobs(ref, jobs[:1], args.policy, args.max_steps, progress=False)   # warm: Warp modules loaded
        (ref / names[0]).unlink()
        load0, t0 = _load(), time.perf_counter()
        run_jobs(ref, jobs, args.policy, args.max_steps, progress=False)
        wall = time.perf_counter() - t0
        steps, ref_data = _steps_and_data(ref, names)
        rows.append(("serial (one process)", "-", wall, steps, f"{load0} / {_load()}", "reference"))
        for n in [int(x) for x in args.workers.split(",") if x]:
            out = pathlib.Path(tmp) / f"ray{n}"
            load0, t0 = _load(), time.perf_counter()
            ray.init(num_cpus=n, include_dashboard=False, log_to_driver=False,
                     runtime_env={"env_vars": {"PYTHONPATH": str(ROOT)}})
            start = time.perf_counter() - t0
            try:
                t0 = time.perf_counter()
                run_jobs_ray(out, jobs, args.policy, args.max_steps, progress=False, workers=n)
                wall = time.perf_counter() - t0
            finally:
                ray.shutdown()
            steps, data = _steps_and_data(out, names)
            same = all(np.array_equal(data[k][0], ref_data[k][0]) and np.array_equal(data[k][1], ref_data[k][1])
                       for k in names)
            rows.append((f"Ray, {n} local worker{'s' * (n > 1)}", f"{start:.1f}", wall, steps, f"{load0} / {_load()}",
                         "bit-identical" if same else "DIFFERENT"))
    header = ("| run | cluster start (s) | wall (s) | episodes/min | env steps/s | load avg start / end "
              "| data vs serial |\n|---|---|---|---|---|---|---|")
    table = "\n".join(f"| {r[0]} | {r[1]} | {r[2]:.1f} | **{60 * args.episodes / r[2]:.1f}** | {r[3] / r[2]:.0f} "
                      f"| {r[4]} | {r[5]} |" for r in rows)
    print(header + "\n" + table)
    if not args.no_append:
        stamp = datetime.datetime.now().isoformat(timespec="seconds")
        append_results(
            f"\n## Dataset generation rate (bench_generate.py), {stamp}\n\nMachine: {host()}, Python "
            f"{platform.python_version()}; env on Warp CPU; commit {git_state()}.\n{args.episodes} episodes of "
            f"{args.object}, E = {args.modulus:g} Pa, policy {args.policy}, "
            f"{'full episodes' if args.max_steps is None else f'at most {args.max_steps} steps'}; files written "
            f"(no compression). Ray wall time from submission to the last file, worker start included; "
            f"the 1-minute load average includes other processes on the machine.\n\n{header}\n{table}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
