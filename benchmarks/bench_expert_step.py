"""Single-env step time of the scripted expert's episodes, with the solver's iteration counts.

    python benchmarks/bench_expert_step.py                       # 5 objects x E = 1e4, 1e7 Pa, seed 0
    python benchmarks/bench_expert_step.py --objects rope torus --moduli 1e4 --no-append

Per (object, E): one seeded episode of ``ScriptedPickupExpert`` in ``DeformablePickup-v0`` (CPU,
state observations; up to ``--max-steps`` control steps, ends early on success). Reported per
control step (``env.step`` wall time; the expert's own time is not included): median and p95 step
time and the rates they give (p95 rate = 1 / the 95th percentile of the step time), the same
percentiles of the process's CPU time per step (``time.process_time``: less disturbed than the wall
time by other processes on a shared machine; Warp's CPU kernels run on the calling thread), the
median and largest Newton and CG iterations per step (``info``, summed over the physics substeps and the wrist
force limit's re-solves), the launches from Python per step (kernel launches and graph replays),
the fraction of steps whose solve met the Newton tolerance (``info["sim_converged"]``) and whether
the episode succeeded.
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

import numpy as np  # noqa: E402
from machine import append_results, git_state, host  # noqa: E402

OBJECTS = ("cuboid", "sphere", "torus", "cylinder", "rope")


class LaunchCounter:
    """Counts the launches made from Python: single kernel launches (recorded ``Launch.launch``
    replays and direct ``wp.launch``) and graph replays (``wp.capture_launch``, one count each)."""

    def __init__(self):
        import warp as wp
        from warp import Launch

        self.count = 0
        counter = self
        replay, direct, graph = Launch.launch, wp.launch, wp.capture_launch

        def counted_replay(launch, *a, **kw):
            counter.count += 1
            return replay(launch, *a, **kw)

        def counted_direct(*a, **kw):
            if not kw.get("record_cmd", False):
                counter.count += 1
            return direct(*a, **kw)

        def counted_graph(*a, **kw):
            counter.count += 1
            return graph(*a, **kw)

        Launch.launch = counted_replay
        wp.launch = counted_direct
        wp.capture_launch = counted_graph


def run(obj: str, e: float, seed: int, max_steps: int, counter: LaunchCounter, edge_contact: bool = True) -> dict:
    import gymnasium as gym

    import defgrasp_env  # noqa: F401
    from defgrasp_env.policies import ScriptedPickupExpert

    env = gym.make("DeformablePickup-v0", object=obj, youngs_modulus=e, max_episode_steps=max_steps,
                   edge_contact=edge_contact)
    expert = ScriptedPickupExpert.from_env(env)
    obs, _ = env.reset(seed=seed)
    expert.reset()
    env.step(expert(obs))  # warm-up: kernels compiled and loaded
    obs, _ = env.reset(seed=seed)
    expert.reset()
    times, cpu, newton, cg, launches, converged, success = [], [], [], [], [], [], False
    while True:
        action = expert(obs)
        before = counter.count
        t0, c0 = time.perf_counter(), time.process_time()
        obs, _, terminated, truncated, info = env.step(action)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        launches.append(counter.count - before)
        newton.append(int(info["newton_iterations"]))
        cg.append(int(info["cg_iterations"]))
        converged.append(bool(info["sim_converged"]))
        success |= bool(info["is_success"])
        if terminated or truncated:
            break
    env.close()
    t, c = np.array(times), np.array(cpu)
    return {"object": obj, "E": e, "steps": len(t), "p50_ms": 1e3 * np.median(t),
            "p95_ms": 1e3 * np.percentile(t, 95), "cpu_p50_ms": 1e3 * np.median(c),
            "cpu_p95_ms": 1e3 * np.percentile(c, 95), "newton": (np.median(newton), max(newton)),
            "cg": (np.median(cg), max(cg)), "launches": (np.median(launches), max(launches)),
            "converged": float(np.mean(converged)), "success": success}


def table(rows: list[dict]) -> str:
    lines = ["| object | E (Pa) | steps | step p50 / p95 (ms) | rate p50 / p95 (Hz) | CPU time p50 / p95 (ms) "
             "| Newton it./step "
             "med / max | CG it./step med / max | launches/step med / max | converged | success |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(
            f"| {r['object']} | {r['E']:.0e} | {r['steps']} | {r['p50_ms']:.1f} / {r['p95_ms']:.1f} | "
            f"{1e3 / r['p50_ms']:.1f} / {1e3 / r['p95_ms']:.1f} | {r['cpu_p50_ms']:.1f} / {r['cpu_p95_ms']:.1f} | "
            f"{r['newton'][0]:.0f} / {r['newton'][1]} | "
            f"{r['cg'][0]:.0f} / {r['cg'][1]} | {r['launches'][0]:.0f} / {r['launches'][1]} | "
            f"{100 * r['converged']:.0f} % | {r['success']} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--objects", nargs="+", default=list(OBJECTS), choices=OBJECTS)
    p.add_argument("--moduli", nargs="+", type=float, default=[1e4, 1e7])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-steps", type=int, default=300)
    p.add_argument("--edge-contact", action=argparse.BooleanOptionalAction, default=True,
                   help="PickupConfig.edge_contact (on by default; --no-edge-contact: node-vs-box contact alone)")
    p.add_argument("--no-append", action="store_true")
    p.add_argument("--note", default="")
    args = p.parse_args(argv)
    counter = LaunchCounter()
    load0 = os.getloadavg()[0]
    rows = []
    for e in args.moduli:
        for obj in args.objects:
            rows.append(run(obj, e, args.seed, args.max_steps, counter, args.edge_contact))
            print(table(rows[-1:]).splitlines()[-1], flush=True)
    load1 = os.getloadavg()[0]
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    text = (f"\n## Expert episode step time (bench_expert_step.py), {stamp}\n\n"
            f"Machine: {host()}; load average {load0:.1f} at start, {load1:.1f} at end; code: {git_state()}"
            f"{'; ' + args.note if args.note else ''}.\n"
            f"Command: `python benchmarks/bench_expert_step.py {' '.join(argv or sys.argv[1:])}`; one env on "
            f"Warp CPU, seed {args.seed}, env.step wall time per control step (rate = 1 / step time).\n\n"
            + table(rows))
    print(text)
    if not args.no_append:
        append_results(text)


if __name__ == "__main__":
    main()
