"""``env.step`` rate of the native vector env on any device, with random actions or the batched expert.

    python benchmarks/bench_env_step.py --device cuda:0 --worlds 1 512 4096
    python benchmarks/bench_env_step.py --device cuda:0 --worlds 512 --policy expert
    python benchmarks/bench_env_step.py --device cpu --worlds 1 16 --object random --no-append
    python benchmarks/bench_env_step.py --device cpu --worlds 1 8 --policy press --youngs-modulus 1e6
    python benchmarks/bench_env_step.py --device cuda:0 --worlds 2048 --policy expert --noise 0.3 \
        --youngs-modulus 1e6 --warmup 0 --steps 100

Per W: ``gym.make_vec("DeformablePickup-v0", num_envs=W, vectorization_mode="vector_entry_point",
device=..., object=..., youngs_modulus=...)`` with the env defaults otherwise (20 Hz, NEXT_STEP
autoreset), ``reset(seed=0)``; then ``--warmup`` untimed steps and ``--steps`` timed ones, each
bracketed by ``wp.synchronize`` on the simulation's device (the wall time a learner waits for).
Actions: ``random`` = seeded uniform delta actions in [-1, 1]^7 (a fresh draw per step: an untrained
policy), ``expert`` = ``ScriptedPickupExpert`` batched over the W worlds (its time included);
``--noise STD`` adds seeded Gaussian noise of that std to the expert's actions (clipped to [-1, 1])
and zeroes their wrist rotation: the contact-heavy steps of an RL policy learning to grasp, whose
cost the actuator force limit's retries and the slowest world's iterations set; ``press`` = the
closed gripper pushed down onto the object at full speed and kept pushing (``press_actions``: a
learner pressing the object into the ground, the wrist at its force limit from the first touch).
``--listed-cg-worlds N [N ...]``: ``SolverConfig.listed_cg_worlds`` (CG's launches over the rows of
the worlds still iterating once at most N are left; 0 = over all rows; default: the solver's choice
for the device, "auto" in the table), a row each side by side.
``--world-block-threads N [N ...]``: ``SolverConfig.world_block_threads`` (each world's Newton
iteration in three launches with a block of N threads per world; 0 = the phase launches over all
rows; default: the solver's choice for the device, "auto" in the table), a row each, side by side.
``--cg-block-threads N [N ...]``: ``SolverConfig.cg_block_threads`` (threads per world of the world
blocks' CG launch alone, up to 512; default: those of the other world-block launches), a row each.
``--edge-contact on|off|both``: pad edge contact (``PickupConfig.edge_contact``, on by default;
both: a row each, side by side). ``--split``: also time the solver's share of each step: every
``ImplicitSolver.advance`` is bracketed by ``wp.synchronize_device`` (one more synchronisation per
solve, so the step itself is then slightly slower; and the scene steps substep by substep from the
host, ``PickupScene.period_graphs`` off: a solve inside a control period's graph cannot be timed on
its own) and the row gives the median ms per step inside
the solver and outside it (the policy's actions where ``expert`` or ``press`` computes them, the
gripper, force limits, readouts, observations, reward: the host side and its transfers). The last
column: the share of the timed substeps that ran inside a control period's graph (the others ran
substep by substep: from a first try over an actuator limit on, ``PickupScene``).
Printed per row: median, mean (what a learner waits for on average, slow steps included) and p95 ms
per step, world-steps/s (W / median), the physics substeps per
control step, the deepest solver-reported penetration (mm) and largest wrist force (N) over the timed
steps, world-solves per world-substep (1 = no force-limit retry or patient re-solve; the scene's
``world_solves``), Newton and CG iterations per step of the slowest world (median over steps) and of
the mean world, and for ``expert`` the successes so far. The bare FEM core's rate for comparison comes from
``bench_fem.py`` (run it in the same session on the same machine, with ``--substeps`` set to the
env's substeps per control period, 4 by default: its own default is ``SolverConfig``'s 2, which
halves the work per step). Appends a table with the machine to
benchmarks/RESULTS.md unless ``--no-append``.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
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

import defgrasp_env  # noqa: E402,F401
from defgrasp_env.envs.config import PickupConfig  # noqa: E402
from defgrasp_env.layout import DELTA_ACTION, ENV_STATE  # noqa: E402
from defgrasp_env.policies import ScriptedPickupExpert  # noqa: E402
from defgrasp_env.sim import ImplicitSolver, SolverConfig  # noqa: E402
from machine import append_results, git_state, host  # noqa: E402


def solver_config(graphs: str, listed_cg_worlds: int | None, world_block_threads: int | None = None,
                  cg_block_threads: int | None = None) -> SolverConfig:
    """The env's default solver settings with ``graphs`` ("auto", "on", "off"), ``listed_cg_worlds``,
    ``world_block_threads`` and ``cg_block_threads``."""
    return dataclasses.replace(PickupConfig().solver, graphs={"auto": None, "on": True, "off": False}[graphs],
                               listed_cg_worlds=listed_cg_worlds, world_block_threads=world_block_threads,
                               cg_block_threads=cg_block_threads)


def press_actions(obs: dict, scene) -> np.ndarray:
    """[W, 7] delta actions of a learner pressing the object into the ground: the gripper closes
    (jaw +1) over the object's feature point (x, z at up to full speed) and, once closed (gap
    < 5 mm), goes down at full speed onto the object and keeps pushing; wrist rotation 0. From the
    first touch the wrist stays at its force limit."""
    feature = ENV_STATE.get(obs["environment_state"], "feature_position")
    toward = np.clip((feature - scene.gripper.tcp_positions()) / 0.015, -1.0, 1.0)
    down = np.where(scene.gripper.gap < 0.005, -1.0, 0.0)
    velocity = np.stack([toward[:, 0], down, toward[:, 2]], axis=1)
    return DELTA_ACTION.pack(linear_velocity=velocity, angular_velocity=np.zeros((len(toward), 3)),
                             jaw=np.ones((len(toward), 1))).astype(np.float32)


class SolverClock:
    """Context manager timing every ``ImplicitSolver.advance`` (bracketed by ``wp.synchronize_device``
    on ``device``) while it is active; ``seconds`` accumulates (reset it between steps)."""

    def __init__(self, device: str):
        self.device = device
        self.seconds = 0.0

    def __enter__(self):
        self._advance = advance = ImplicitSolver.advance
        clock = self

        def timed(solver, *args, **kwargs):
            wp.synchronize_device(clock.device)
            t0 = time.perf_counter()
            result = advance(solver, *args, **kwargs)
            wp.synchronize_device(clock.device)
            clock.seconds += time.perf_counter() - t0
            return result

        ImplicitSolver.advance = timed
        return self

    def __exit__(self, *exc):
        ImplicitSolver.advance = self._advance
        return False


def run_case(device: str, worlds: int, policy: str, obj: str, modulus: float, warmup: int, steps: int,
             graphs: str = "auto", noise: float = 0.0, edge_contact: bool = True, split: bool = False,
             listed_cg_worlds: int | None = None, world_block_threads: int | None = None,
             cg_block_threads: int | None = None) -> dict:
    """Time ``steps`` env steps after ``warmup`` ones; returns one row of the table (with
    ``split``, the solver's share of each step too: ``SolverClock``)."""
    with SolverClock(device) if split else contextlib.nullcontext() as clock:
        return _run_case(device, worlds, policy, obj, modulus, warmup, steps, graphs, noise, edge_contact, clock,
                         listed_cg_worlds, world_block_threads, cg_block_threads)


def _run_case(device, worlds, policy, obj, modulus, warmup, steps, graphs, noise, edge_contact, clock,
              listed_cg_worlds, world_block_threads, cg_block_threads) -> dict:
    env = gym.make_vec("DeformablePickup-v0", num_envs=worlds, vectorization_mode="vector_entry_point",
                       device=device, object=obj, youngs_modulus=modulus,
                       solver=solver_config(graphs, listed_cg_worlds, world_block_threads, cg_block_threads),
                       edge_contact=edge_contact)
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    expert = ScriptedPickupExpert.from_env(env) if policy == "expert" else None
    if expert is not None:
        expert.reset()
    times, solver_times, depth, wrist, successes, newton, cg = [], [], 0.0, 0.0, 0, [], []
    rotation = DELTA_ACTION.slice("angular_velocity")
    scene = env.unwrapped.scene
    if clock is not None:  # a solve inside a control period's graph could not be timed on its own
        scene.period_graphs = False
    for k in range(warmup + steps):
        wp.synchronize_device(device)
        t0 = time.perf_counter()
        if policy == "press":
            action = press_actions(obs, scene)
        elif expert is None:
            action = rng.uniform(-1, 1, (worlds, 7)).astype(np.float32)
        else:
            action = expert(obs)
            if noise > 0.0:
                action = np.clip(action + rng.normal(0.0, noise, action.shape), -1.0, 1.0).astype(np.float32)
                action[:, rotation] = 0.0
        if k == warmup:
            solves_before, graphed_before = scene.world_solves, scene.device_substeps
        if clock is not None:
            clock.seconds = 0.0
        obs, _, terminated, _, info = env.step(action)
        wp.synchronize_device(device)
        successes += int(np.sum(terminated))
        if k >= warmup:
            times.append(time.perf_counter() - t0)
            solver_times.append(clock.seconds if clock is not None else np.nan)
            depth = max(depth, float(np.max(info["penetration"])))
            wrist = max(wrist, float(np.max(info["wrist_force"])))
            newton.append(info["newton_iterations"])
            cg.append(info["cg_iterations"])
    substeps = scene.substeps
    solves = (scene.world_solves - solves_before) / (worlds * substeps * steps)
    graphed = (scene.device_substeps - graphed_before) / (substeps * steps)
    env.close()
    t, solver_t, newton, cg = np.array(times), np.array(solver_times), np.array(newton), np.array(cg)
    return {"W": worlds, "policy": policy + (f" + noise {noise:g}" if noise > 0.0 else ""), "graphs": graphs,
            "edges": "on" if edge_contact else "off", "listed": "auto" if listed_cg_worlds is None else listed_cg_worlds,
            "world_blocks": "auto" if world_block_threads is None else world_block_threads,
            "cg_blocks": "auto" if cg_block_threads is None else cg_block_threads,
            "object": obj, "E": modulus, "median_ms": 1e3 * float(np.median(t)), "mean_ms": 1e3 * float(np.mean(t)),
            "p95_ms": 1e3 * float(np.percentile(t, 95)), "world_steps_per_s": worlds / float(np.median(t)),
            "solver_ms": 1e3 * float(np.median(solver_t)), "outside_ms": 1e3 * float(np.median(t - solver_t)),
            "substeps": substeps, "depth_mm": 1e3 * depth, "wrist_N": wrist, "successes": successes,
            "solves": solves, "graphed": graphed, "newton": (float(np.median(newton.max(axis=1))), float(newton.mean())),
            "cg": (float(np.median(cg.max(axis=1))), float(cg.mean()))}


def _ms(value: float) -> str:
    return "-" if np.isnan(value) else f"{value:.1f}"


def table(rows: list[dict]) -> str:
    lines = ["| W | actions | step graphs | edge contact | CG listed at <= worlds | threads per world block | threads per CG block | object | E (Pa) | substeps | median ms | mean ms | p95 ms | "
             "world-steps/s | deepest mm | max wrist N | world-solves per world-substep | Newton / step, slowest / "
             "mean | CG / step, slowest / mean | episodes won | solver ms (median) | outside the solver ms (median) | "
             "substeps in period graphs |",
             "|---" * 23 + "|"]
    for r in rows:
        won = r["successes"] if r["policy"].startswith("expert") else "-"
        lines.append(f"| {r['W']} | {r['policy']} | {r['graphs']} | {r['edges']} | {r['listed']} | {r['world_blocks']} | {r.get('cg_blocks', 'auto')} | {r['object']} | {r['E']:.0e} | {r['substeps']} | "
                     f"{r['median_ms']:.1f} | {r['mean_ms']:.1f} | {r['p95_ms']:.1f} | {r['world_steps_per_s']:,.0f} | "
                     f"{r['depth_mm']:.2f} | {r['wrist_N']:.0f} | {r['solves']:.3f} | {r['newton'][0]:.0f} / "
                     f"{r['newton'][1]:.1f} | {r['cg'][0]:.0f} / {r['cg'][1]:.0f} | {won} | {_ms(r['solver_ms'])} | "
                     f"{_ms(r['outside_ms'])} | {r['graphed']:.0%} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--worlds", type=int, nargs="+", default=[1, 16])
    ap.add_argument("--policy", choices=["random", "expert", "press"], default="random",
                    help="random actions, the batched scripted expert, or pressing the object into the ground")
    ap.add_argument("--object", default="cuboid", help="an object name, 'random', or a mesh path")
    ap.add_argument("--youngs-modulus", type=float, default=1e5)
    ap.add_argument("--warmup", type=int, default=10)
    ap.add_argument("--steps", type=int, default=15)
    ap.add_argument("--graphs", choices=["auto", "on", "off", "both"], default="auto",
                    help="capture each solver step as one graph (SolverConfig.graphs); both: a row each, side by side")
    ap.add_argument("--noise", type=float, default=0.0,
                    help="std of Gaussian noise on the expert's actions (wrist rotation zeroed); needs --policy expert")
    ap.add_argument("--edge-contact", choices=["on", "off", "both"], default="on",
                    help="pad edge contact (PickupConfig.edge_contact, on by default); both: a row each, side by side")
    ap.add_argument("--listed-cg-worlds", type=int, nargs="+", default=[None],
                    help="SolverConfig.listed_cg_worlds (0: CG always over all rows; default: the solver's choice "
                         "for the device); several: a row each, side by side")
    ap.add_argument("--world-block-threads", type=int, nargs="+", default=[None],
                    help="SolverConfig.world_block_threads (each world's Newton iteration in three launches, N "
                         "threads per world; 0: the phase launches; default: the solver's choice for the device); "
                         "several: a row each, side by side")
    ap.add_argument("--cg-block-threads", type=int, nargs="+", default=[None],
                    help="SolverConfig.cg_block_threads (threads per world of the world blocks' CG launch, up to "
                         "512; default: as the other world-block launches); several: a row each, side by side")
    ap.add_argument("--split", action="store_true",
                    help="also time the solver's share of each step (a synchronisation around every solve)")
    ap.add_argument("--no-append", action="store_true")
    args = ap.parse_args(argv)
    if args.noise < 0.0 or (args.noise > 0.0 and args.policy != "expert"):
        ap.error(f"--noise must be >= 0 and needs --policy expert, got {args.noise} with --policy {args.policy}")
    if min(args.worlds) < 1 or args.steps < 1 or args.warmup < 0:
        ap.error(f"--worlds and --steps must be >= 1 and --warmup >= 0, got {args.worlds}, {args.steps}, {args.warmup}")
    rows = []
    for w in args.worlds:
        for graphs in (["off", "on"] if args.graphs == "both" else [args.graphs]):
            for edges in (["off", "on"] if args.edge_contact == "both" else [args.edge_contact]):
                for listed in args.listed_cg_worlds:
                    for threads in args.world_block_threads:
                        for cg_threads in args.cg_block_threads:
                            rows.append(run_case(args.device, w, args.policy, args.object, args.youngs_modulus,
                                                 args.warmup, args.steps, graphs, args.noise, edges == "on",
                                                 args.split, listed, threads, cg_threads))
                            print(table(rows[-1:]).splitlines()[-1], flush=True)
    report = table(rows)
    print(report)
    if not args.no_append:
        load = os.getloadavg()[0]
        stamp = datetime.datetime.now().strftime("%Y-%m-%dT%H:%M:%S")
        append_results(f"\n## Env step rate (bench_env_step.py), {stamp}\n\nMachine: {host()}; device "
                       f"{args.device}; {git_state()}; load average (1 min) {load:.1f}; `python "
                       f"benchmarks/bench_env_step.py {' '.join(sys.argv[1:])}`; {args.warmup} warm-up and "
                       f"{args.steps} timed steps per row.\n\n{report}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
