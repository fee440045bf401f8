"""Throughput of the FEM core (ImplicitSolver) on the five default objects.

    python benchmarks/bench_fem.py                                   # CPU, one world
    python benchmarks/bench_fem.py --device cuda:0 --worlds 1 64 1024 4096
    python benchmarks/bench_fem.py --no-append --steps 20

Per object (default mesh, E = 1e6 Pa, default SolverConfig unless --newton/--cg/--substeps,
20 Hz control: dt = 0.05 s) and scenario:

* ``rest``: the object resting on the ground (after 10 warm-up steps of settling); it starts at
  its rest shape, so this is the easiest case for the solver;
* ``held``: two pads (8 x 37.5 x 22 mm) squeeze it by 0.5 mm per side, lift it 5 cm at 5 cm/s
  and hold it (the pickup of the env); the timed window is the lift and the hold;
* ``rest-dropped``: a realistic rest: the object starts 10 mm above the ground, falls and settles
  for 30 steps (1.5 s); the timed window is the object lying on the ground after that;
* ``held-static``: the dropped and settled object (as ``rest-dropped``) is gripped (the pads close
  from 20 mm away to a 0.5 mm squeeze per side in 10 steps), lifted 5 cm at 5 cm/s and held 10 steps;
  the timed window is the static hold after that.

"speed at start" is the largest node speed at the first timed step: how settled the object is.

Reported: tets, nodes, control steps/s of one world (CPU) or world-steps/s (W worlds of the
object in one model; wall time of a step bracketed by ``wp.synchronize``, median of the steps
after warm-up), and the median Newton and CG iterations per control step (summed over substeps).
The table is printed and appended to benchmarks/RESULTS.md with the machine.
"""

from __future__ import annotations

import argparse
import datetime
import os
import pathlib
import platform
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from defgrasp_env.sim.materials import Material  # noqa: E402
from defgrasp_env.sim.meshing import make_object_mesh  # noqa: E402
from defgrasp_env.sim.model import build_model  # noqa: E402
from defgrasp_env.sim.solver import ImplicitSolver, SolverConfig  # noqa: E402
from defgrasp_env.sim.state import Control, State  # noqa: E402
from machine import append_results, cpu_model, git_state  # noqa: E402

OBJECTS = ("cuboid", "sphere", "torus", "cylinder", "rope")
PAD_HALF = np.array([0.004, 0.01875, 0.011])
DT = 0.05
SQUEEZE = 5e-4            # m per side
LIFT_SPEED = 0.05         # m/s
ROPE_ACROSS = (0.0, np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4))   # rope turned to lie along z
DROP = 0.010              # m, start height of the dropped cases
SETTLE = 30               # control steps of fall and settling in the dropped cases
LIFT_STEPS = round(0.05 / (LIFT_SPEED * DT))   # 5 cm at 5 cm/s
SCENARIOS = ("rest", "held", "rest-dropped", "held-static")


def setup(name: str, worlds: int, device: str, config: SolverConfig, height: float = 0.0):
    """The object ``height`` m above its resting pose in W worlds; its half width along x and the
    pads' grip height, both of the object at rest on the ground."""
    mesh = make_object_mesh(name)
    quat = ROPE_ACROSS if name == "rope" else (0.0, 0.0, 0.0, 1.0)
    model = build_model([mesh] * worlds, [Material(youngs_modulus=1e6)] * worlds,
                        poses=[((0.0, height, 0.0), quat)] * worlds, pad_half_extents=[PAD_HALF, PAD_HALF],
                        device=device)
    x = model.rest_positions.numpy()[model.world_nodes(0)]
    half_width = float(x[:, 0].max())
    centre_y = float(min(0.5 * (x[:, 1].max() - height), PAD_HALF[1] + 0.002))
    state, control = State.from_model(model), Control.from_model(model)
    return model, state, control, ImplicitSolver(model, config), half_width, centre_y


def pads(worlds, half_width, centre_y, squeeze, lift, open_=0.0):
    x = half_width + PAD_HALF[0] - squeeze + open_
    one = np.array([[-x, centre_y + lift, 0.0], [x, centre_y + lift, 0.0]], np.float32)
    return np.tile(one, (worlds, 1))


def schedule(scenario: str, worlds: int, half_width: float, centre_y: float, steps: int):
    """The pads' start positions, their targets of every control step, and how many of the first
    steps are warm-up (untimed)."""
    def at(squeeze=0.0, lift=0.0, open_=0.0):
        return pads(worlds, half_width, centre_y, squeeze, lift, open_)

    if scenario in ("rest", "rest-dropped"):
        warmup = 10 if scenario == "rest" else SETTLE
        return at(open_=0.02), [at(open_=0.02)] * (warmup + steps), warmup
    if scenario == "held":
        targets = [at(SQUEEZE * min(k + 1, 5) / 5) for k in range(10)]
        return at(), targets + [at(SQUEEZE, min(LIFT_SPEED * DT * (k + 1), 0.05)) for k in range(steps)], 10
    targets = [at(open_=0.02)] * SETTLE                                      # held-static
    targets += [at(SQUEEZE * (k + 1) / 10, 0.0, 0.02 * (1 - (k + 1) / 10)) for k in range(10)]
    targets += [at(SQUEEZE, LIFT_SPEED * DT * (k + 1)) for k in range(LIFT_STEPS)]
    targets += [at(SQUEEZE, LIFT_SPEED * DT * LIFT_STEPS)] * (10 + steps)
    return at(open_=0.02), targets, len(targets) - steps


def run_case(name: str, scenario: str, worlds: int, device: str, config: SolverConfig, steps: int):
    height = DROP if scenario in ("rest-dropped", "held-static") else 0.0
    model, state, control, solver, half_width, centre_y = setup(name, worlds, device, config, height)
    start, targets, warmup = schedule(scenario, worlds, half_width, centre_y, steps)
    state.pad_positions.assign(start)
    times, newton, cg, diverged = [], [], [], False
    start_speed = 0.0
    for k, target in enumerate(targets):
        if k == warmup:
            start_speed = float(np.linalg.norm(state.velocities.numpy()[model.world_nodes(0)], axis=1).max())
        control.pad_target_positions.assign(target)
        wp.synchronize()
        t0 = time.perf_counter()
        stats = solver.step(state, state, control, DT)
        wp.synchronize()
        if k >= warmup:
            times.append(time.perf_counter() - t0)
            newton.append(np.median(stats.newton_iterations))
            cg.append(np.median(stats.cg_iterations))
        diverged |= bool(stats.diverged.any())
    step_time = float(np.median(times))
    lowest = float(state.positions.numpy()[model.world_nodes(0), 1].min())
    return {
        "object": name, "scenario": scenario, "worlds": worlds, "tets": model.num_tets // worlds,
        "nodes": model.num_nodes // worlds, "steps_per_s": 1.0 / step_time,
        "world_steps_per_s": worlds / step_time, "newton": float(np.median(newton)),
        "cg": float(np.median(cg)), "diverged": diverged, "lowest_mm": 1e3 * lowest,
        "start_speed_mm_s": 1e3 * start_speed,
    }


def machine(device: str) -> str:
    dev = wp.get_device(device)
    name = dev.name if dev.is_cuda else "CPU"
    return (f"{platform.platform()}, {cpu_model('unknown CPU')}, {os.cpu_count()} logical CPUs, Python "
            f"{platform.python_version()}, warp {wp.config.version}, device {device} ({name}); commit {git_state()}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--worlds", type=int, nargs="+", default=[1])
    parser.add_argument("--objects", nargs="+", default=list(OBJECTS), choices=OBJECTS)
    parser.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), choices=SCENARIOS)
    parser.add_argument("--steps", type=int, default=40, help="timed control steps per case")
    parser.add_argument("--substeps", type=int, default=None)
    parser.add_argument("--newton", type=int, default=None, help="newton_iterations (default: SolverConfig's)")
    parser.add_argument("--cg", type=int, default=None, help="cg_iterations (default: SolverConfig's)")
    parser.add_argument("--no-append", action="store_true", help="do not append to benchmarks/RESULTS.md")
    args = parser.parse_args(argv)
    wp.config.quiet = True
    wp.init()
    overrides = {k: v for k, v in (("substeps", args.substeps), ("newton_iterations", args.newton),
                                   ("cg_iterations", args.cg)) if v is not None}
    config = SolverConfig(**overrides)

    rows = []
    for worlds in args.worlds:
        for name in args.objects:
            for scenario in args.scenarios:
                rows.append(run_case(name, scenario, worlds, args.device, config, args.steps))
                r = rows[-1]
                print(f"  {name:8s} {scenario:4s} W={worlds:<5d} {r['world_steps_per_s']:10.1f} world-steps/s",
                      file=sys.stderr)

    header = ("| object | scenario | worlds | tets | nodes | control steps/s | world-steps/s | "
              "Newton it./step | CG it./step | speed at start (mm/s) | lowest node at end (mm) | diverged |")
    lines = [header, "|" + "---|" * 12]
    for r in rows:
        lines.append(f"| {r['object']} | {r['scenario']} | {r['worlds']} | {r['tets']} | {r['nodes']} | "
                     f"{r['steps_per_s']:.1f} | {r['world_steps_per_s']:.1f} | {r['newton']:.0f} | "
                     f"{r['cg']:.0f} | {r['start_speed_mm_s']:.2f} | {r['lowest_mm']:.1f} | "
                     f"{'yes' if r['diverged'] else 'no'} |")
    table = "\n".join(lines)
    stamp = datetime.datetime.now().isoformat(timespec="seconds")
    text = (f"\n## FEM core throughput (bench_fem.py), {stamp}\n\n"
            f"Machine: {machine(args.device)}\n"
            f"Config: E = 1e6 Pa, dt = {DT} s (20 Hz), {config}; median over {args.steps} timed steps "
            f"after the warm-up steps; 'held' = squeezed 0.5 mm/side by two pads and lifted at 5 cm/s; "
            f"'-dropped'/'-static': after a {DROP * 1e3:.0f} mm drop and {SETTLE} steps of settling (see the "
            f"script's docstring); lowest node at end > 0: off the ground.\n\n"
            f"{table}\n")
    print(text)
    if not args.no_append:
        append_results(text)


if __name__ == "__main__":
    main()
