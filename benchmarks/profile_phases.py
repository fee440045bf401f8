"""Where a world's time goes inside its world-block kernels, phase by phase (a diagnosis, not a benchmark of record).

    python benchmarks/profile_phases.py --device cuda:0 --object rope --youngs-modulus 1e4
    python benchmarks/profile_phases.py --device cpu --object torus --youngs-modulus 1e7 --json phases.json
    python benchmarks/profile_phases.py --device cpu --actions benchmarks/data/operator_torus_e1e7_paced_actions.npz \
        --window 137 142     # the phases of the operator's stiff-torus strike (bench_action_replay.py)

Each world's substep runs in a few launches with a thread block per world (``kernels/world_start.py``,
``world_evaluate.py``, ``world_cg.py``, ``world_newton_step.py``, ``world_finish.py``); inside a
launch its phases are separated by block barriers, so on a GPU a lone world's phase costs its
slowest thread's chain of memory round trips, which per-launch timers (``profile_kernels.py``)
cannot split. This script copies the package to a temporary folder and instruments the copy (the
shipped code is untouched): after every block barrier, and after one more at each kernel's end,
thread 0 of the block adds the ticks since its last stamp to that phase's sum and counts the run
(on CUDA ``clock64()``, SM cycles; on the CPU, where a block is one thread and a world's phases run
one after another, the x86 time-stamp counter, reference ticks rather than core cycles, or ARM's
virtual counter). The native vector env (random actions, ``bench_env_step.py``'s defaults) is
stepped ``--warmup`` times, the sums cleared, then ``--steps`` more steps; or (``--actions``) a
recorded sequence is replayed in a single env and the steps of ``--window`` summed. Printed per
kernel: the world-block launches a step (those that ran to the kernel's end: a world that does not iterate
returns at once), and per phase (named by the row functions it calls) its runs a launch and
thousands of ticks a run (CG's phases run once an iteration). A phase's time runs from the stamp
before it: where a branch skipped a barrier (a substep without full outputs, no pad edge points),
that code's time is in the next phase that ran. At W > 1 the sums are over every world's block.
"""

from __future__ import annotations

import json
import os
import pathlib
import re
import shutil
import sys
import tempfile

from machine import env_profile_arguments  # this folder: first on sys.path (python benchmarks/profile_phases.py)

ROOT = pathlib.Path(__file__).resolve().parents[1]
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))

#: the instrumented kernels (module of ``sim/kernels``, kernel) in the order printed
KERNELS = (("world_start", "start_world_blocks"), ("world_evaluate", "evaluate_world_blocks"),
           ("world_cg", "cg_world_blocks"), ("world_newton_step", "newton_step_world_blocks"),
           ("world_finish", "finish_world_blocks"))
#: per kernel: the cycles of its phases (up to PHASES), their runs (PHASES on), its launches that ran to
#: their end (SLOTS - 2) and its loop's passes (SLOTS - 1, CG's iterations)
SLOTS, PHASES = 32, 14

STAMP = '''

@wp.func_native("""
#if defined(__CUDA_ARCH__)
return (double)clock64();
#elif defined(__aarch64__)
unsigned long long ticks;
asm volatile("mrs %0, cntvct_el0" : "=r"(ticks));
return (double)ticks;
#elif defined(__x86_64__) || defined(__i386__)
return (double)__builtin_ia32_rdtsc();
#else
return 0.0;
#endif
""")
def phase_cycles() -> wp.float64: ...


@wp.func
def phase_stamp(sums: wp.array(dtype=wp.float64), k: int, runs: int, lane: int, last: wp.float64) -> wp.float64:
    """Thread 0 adds the cycles since ``last`` to ``sums[k]`` and counts the run in ``sums[runs]``;
    every thread gets the new stamp."""
    now = phase_cycles()
    if lane == 0:
        wp.atomic_add(sums, k, now - last)
        wp.atomic_add(sums, runs, wp.float64(1.0))
    return now
'''
_CALL = re.compile(r"(?<![.\w])([a-z_][a-z0-9_]*)\(")
_NOT_ROW_FUNCTIONS = {"range", "block_barrier", "int", "float", "compiled_for_cpu"}


def _instrument_kernel(source: str, kernel: str, base: int) -> tuple[str, list[str]]:
    """``source`` with ``kernel`` stamped after each block barrier and at its end (after one more
    barrier: every return and loop exit in these kernels is the same for a whole block); the
    phases' names (the row functions called since the barrier before)."""
    out, labels, called, where = [], [], [], None

    def stamp(indent: str) -> None:
        k = len(labels)
        out.append(f"{indent}phase_last = phase_stamp(phase_sums, {base + k}, {base + PHASES + k}, lane, phase_last)")
        labels.append(" + ".join(dict.fromkeys(called)) or "(barrier)")
        called.clear()

    def end_body() -> None:
        while out and not out[-1].strip():
            out.pop()
        out.append("    block_barrier()")
        stamp("    ")
        out.extend(["    if lane == 0:", f"        wp.atomic_add(phase_sums, {base + SLOTS - 2}, wp.float64(1.0))",
                    "", ""])

    for line in source.split("\n"):
        if where == "body" and line.startswith(("def ", "@wp.")):
            end_body()
            where = None
        if line.startswith(f"def {kernel}("):
            where = "signature"
        elif where == "signature" and line == "):":
            out.append("    phase_sums: wp.array(dtype=wp.float64),")
            where = "body"
        out.append(line)
        if where != "body":
            continue
        stripped = line.strip()
        if stripped == "lane = tid - w * threads":
            out.append("    phase_last = phase_cycles()")
        elif stripped.startswith("for _it in range("):
            indent = " " * (len(line) - len(line.lstrip()) + 4)
            out += [f"{indent}if lane == 0:",
                    f"{indent}    wp.atomic_add(phase_sums, {base + SLOTS - 1}, wp.float64(1.0))"]
        elif stripped == "block_barrier()":
            stamp(line[: len(line) - len(line.lstrip())])
        else:
            called.extend(name for name in _CALL.findall(stripped) if name not in _NOT_ROW_FUNCTIONS)
    if where == "body":
        end_body()
        out.pop()
    if len(labels) < 2 or len(labels) > PHASES:
        raise RuntimeError(f"profile_phases: {kernel} has {len(labels) - 1} block barriers; expected 1 to "
                           f"{PHASES - 1} (the world-block kernels changed: update this script)")
    return "\n".join(out), labels


def instrumented_copy(dst: pathlib.Path) -> dict[str, list[str]]:
    """``defgrasp_env`` copied under ``dst`` with the world-block kernels stamped and their launches
    given the phase sums (``sim/solver_launches.phase_sums(device)``); the phases' names by kernel."""
    package = dst / "defgrasp_env"
    shutil.copytree(ROOT / "defgrasp_env", package, ignore=shutil.ignore_patterns("__pycache__"))
    kernels = package / "sim" / "kernels"
    (kernels / "block_sync.py").write_text((kernels / "block_sync.py").read_text() + STAMP)
    labels = {}
    for i, (module, kernel) in enumerate(KERNELS):
        path = kernels / f"{module}.py"
        source = path.read_text().replace("from .block_sync import block_barrier",
                                          "from .block_sync import block_barrier, phase_cycles, phase_stamp")
        source, labels[kernel] = _instrument_kernel(source, kernel, i * SLOTS)
        path.write_text(source)
    launches = package / "sim" / "solver_launches.py"
    source = launches.read_text()
    for module, kernel in KERNELS:
        alias = re.search(rf"c\.blocks\((\w+)\.{kernel},", source)
        if alias is None:
            raise RuntimeError(f"profile_phases: no c.blocks(<module>.{kernel}, ...) launch in solver_launches.py")
        depth, i = 0, alias.start() + len("c.blocks")
        while True:  # the launch's closing parenthesis
            depth += {"(": 1, ")": -1}.get(source[i], 0)
            if depth == 0:
                break
            i += 1
        source = source[:i] + ", phase_sums(c.model.device)" + source[i:]
    source += ('\n\n_PHASE_SUMS: dict = {}\n\n\ndef phase_sums(device):\n'
               f'    """The phase sums [{len(KERNELS) * SLOTS}] float64 of ``device`` (profile_phases.py)."""\n'
               '    key = str(wp.get_device(device))\n'
               '    if key not in _PHASE_SUMS:\n'
               f'        _PHASE_SUMS[key] = wp.zeros({len(KERNELS) * SLOTS}, dtype=wp.float64, device=key)\n'
               '    return _PHASE_SUMS[key]\n')
    launches.write_text(source)
    return labels


def _read_sums(device: str, labels: dict[str, list[str]], out: dict) -> dict:
    """``out`` with each kernel's launches, loop passes and phases from the phase sums of ``device``."""
    from defgrasp_env.sim.solver_launches import phase_sums

    sums = phase_sums(device).numpy()
    out["kernels"] = {}
    for i, (_, kernel) in enumerate(KERNELS):
        base = i * SLOTS
        launches, iterations = float(sums[base + SLOTS - 2]), float(sums[base + SLOTS - 1])
        phases = []
        for k, name in enumerate(labels[kernel]):
            runs = float(sums[base + PHASES + k])
            phases.append({"name": name, "runs": runs, "kcycles_per_run": float(sums[base + k]) / max(runs, 1.0) / 1e3,
                           "kcycles_per_launch": float(sums[base + k]) / max(launches, 1.0) / 1e3})
        out["kernels"][kernel] = {"launches": launches, "iterations": iterations, "phases": phases}
    return out


def profile(device: str, worlds: int, obj: str, modulus: float, warmup: int, steps: int,
            labels: dict[str, list[str]]) -> dict:
    """Step the instrumented package's vector env and read its phase sums (import it first)."""
    import gymnasium as gym
    import numpy as np
    import warp as wp

    import defgrasp_env  # noqa: F401  (the instrumented copy: first on sys.path)
    from defgrasp_env.sim.solver_launches import phase_sums

    env = gym.make_vec("DeformablePickup-v0", num_envs=worlds, vectorization_mode="vector_entry_point",
                       device=device, object=obj, youngs_modulus=modulus)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    newton = cg = 0
    for k in range(warmup + steps):
        if k == warmup:
            wp.synchronize_device(device)
            phase_sums(device).zero_()
        _, _, _, _, info = env.step(rng.uniform(-1, 1, (worlds, 7)).astype(np.float32))
        if k >= warmup:
            newton += int(np.sum(info["newton_iterations"]))
            cg += int(np.sum(info["cg_iterations"]))
    wp.synchronize_device(device)
    env.close()
    return _read_sums(device, labels, {"device": device, "worlds": worlds, "object": obj, "youngs_modulus": modulus,
                                       "steps": steps, "reported_newton_iterations": newton,
                                       "reported_cg_iterations": cg})


def profile_replay(device: str, path: pathlib.Path, first: int, last: int, labels: dict[str, list[str]]) -> dict:
    """Replay a recorded action sequence (``bench_action_replay.py``'s ``.npz``) in the instrumented
    package's single env and read the phase sums of steps ``first`` .. ``last`` (import it first)."""
    import gymnasium as gym
    import numpy as np
    import warp as wp

    import defgrasp_env  # noqa: F401  (the instrumented copy: first on sys.path)
    from defgrasp_env.sim.solver_launches import phase_sums

    data = np.load(path)
    seed, actions = int(data["seed"]), data["actions"]
    if not 0 <= first <= last < len(actions):
        raise ValueError(f"--window must be two steps 0 <= first <= last < {len(actions)}, got {first} {last}")
    env = gym.make("DeformablePickup-v0", action_mode=str(data["action_mode"]), object=str(data["object"]),
                   youngs_modulus=float(data["youngs_modulus"]), device=device)
    env.reset(seed=seed)
    newton = cg = 0
    for k in range(last + 1):
        if k == first:
            wp.synchronize_device(device)
            phase_sums(device).zero_()
        _, _, terminated, truncated, info = env.step(np.asarray(actions[k], dtype=np.float32))
        if k >= first:
            newton += int(info["newton_iterations"])
            cg += int(info["cg_iterations"])
        if terminated or truncated:
            env.reset(seed=seed)
    wp.synchronize_device(device)
    env.close()
    return _read_sums(device, labels, {"device": device, "worlds": 1, "object": f"{data['object']} ({path.name}, "
                                       f"steps {first}-{last})", "youngs_modulus": float(data["youngs_modulus"]),
                                       "steps": last - first + 1, "reported_newton_iterations": newton,
                                       "reported_cg_iterations": cg})


def report(result: dict) -> str:
    lines = [f"{result['object']} E = {result['youngs_modulus']:g} Pa, W = {result['worlds']}, {result['device']}, "
             f"{result['steps']} steps; per world-block launch that ran to its end: each phase's runs and thousands "
             "of cycles a run (a phase runs from the stamp before: where a branch skipped a barrier, its time is in "
             "the next phase that ran)"]
    for kernel, k in result["kernels"].items():
        head = f"{kernel}: {k['launches'] / result['steps']:.1f} launches a step"
        if k["iterations"]:
            head += f", {k['iterations'] / max(k['launches'], 1.0):.1f} loop passes a launch"
        total = sum(p["kcycles_per_launch"] for p in k["phases"])
        lines.append(f"  {head}; {total:.1f} k cycles a launch")
        lines += [f"    {p['runs'] / max(k['launches'], 1.0):5.1f} x {p['kcycles_per_run']:9.2f}  {p['name']}"
                  for p in k["phases"]]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = env_profile_arguments(__doc__.split("\n")[0], "cuda:0", steps=30)
    ap.add_argument("--json", default=None, help="also write the numbers to this file")
    ap.add_argument("--actions", default=None, help="replay this recorded sequence (bench_action_replay.py's .npz) "
                                                    "in a single env instead of random actions")
    ap.add_argument("--window", type=int, nargs=2, default=None, metavar=("FIRST", "LAST"),
                    help="with --actions: the steps whose phases are summed (default: all)")
    args = ap.parse_args(argv)
    if args.worlds < 1 or args.steps < 1 or args.warmup < 0:
        ap.error(f"--worlds and --steps must be >= 1 and --warmup >= 0, got {args.worlds}, {args.steps}, {args.warmup}")
    if "defgrasp_env" in sys.modules:
        raise RuntimeError("profile_phases imports an instrumented copy of defgrasp_env: run it in a fresh process")
    with tempfile.TemporaryDirectory(prefix="defgrasp-phases-") as tmp:
        labels = instrumented_copy(pathlib.Path(tmp))
        sys.path.insert(0, tmp)
        if args.actions:
            import numpy as np

            path = pathlib.Path(args.actions)
            first, last = args.window or (0, len(np.load(path)["actions"]) - 1)
            result = profile_replay(args.device, path, first, last, labels)
        else:
            result = profile(args.device, args.worlds, args.object, args.youngs_modulus, args.warmup, args.steps,
                             labels)
    print(report(result))
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
