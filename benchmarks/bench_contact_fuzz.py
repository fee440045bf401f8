"""Adversarial contact fuzz: what a learning agent does that the scripted expert never does.

    .venv/bin/python benchmarks/bench_contact_fuzz.py [--steps 10] [--objects cuboid] [--moduli 1e4] [--no-append]

Every object x E cell of ``DeformablePickup-v0`` runs, at the largest legal speeds
(``max_linear_speed`` 2 m/s, ``max_angular_speed`` 2 pi rad/s, jaw at its 150 mm/s), the
action sequences of ``SEQUENCES``: ``dive`` (straight down into the object and the ground while
closing), ``sweep`` (down beside the object, then full-speed sideways sweeps through it),
``rotate`` (pressing down while turning at full angular speed about a tilted axis) and ``random``
(uniform actions in the box, seeded). After every step the node positions are checked against the
pad collision boxes and the ground, independently of the solver's own report:

* ``deepest``: the deepest node inside a pad box (nearest-face depth) or below y = 0 after any
  physics substep, mm (``SubstepMonitor`` wraps the scene's solver to see every substep);
* ``crossed``: node paths through a pad (see ``SubstepMonitor``), summed over the substeps;
* ``flagged``: steps the env flagged ``sim_penetrated``; ``unflagged``: steps that ended a substep
  deeper than 1 mm without that flag (must be 0); ``diverged``: steps flagged diverged;
* ``clamped``: substeps (of ``steps`` x sequences x the env's substeps per step) whose accepted
  solve left a node deeper than the 1 mm bound, put back to 0.9 mm by the solver's clamp
  (``SolveStats.penetrated`` of that solve): how often the depth bound is met by clamping rather
  than by the contact itself;
* ``tip max``: the largest pad normal force, N, and ``wrist max``: the largest net force of the
  pads on the object, N, after any physics substep (the accepted solve's forces, which the env's
  ``left/right_tip_normal_force`` and ``wrist_force`` report for the last substep of a step);
  ``impact``: ``impact_margin``, N, what the limits do not bound (the object stopped by a stopped
  pad); ``ms/step``: mean wall time of a step.

Prints a table (one row per cell, worst over the sequences) and appends it to benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import defgrasp_env  # noqa: E402,F401
from defgrasp_env.envs.actions import max_flange_step  # noqa: E402
from defgrasp_env.envs.config import PickupConfig  # noqa: E402
from defgrasp_env.gripper import PAD_BOX_HALF_EXTENTS, GripperConfig, pad_reach  # noqa: E402
from defgrasp_env.sim.pad_motion import max_pad_travel  # noqa: E402
from defgrasp_env.sim.meshing import OBJECT_SHAPES  # noqa: E402
from defgrasp_env.transforms import quat_rotate  # noqa: E402
from defgrasp_env.wrist.force_limit import FORCE_TOLERANCE, tip_force_bound  # noqa: E402
from machine import append_results, git_state, host  # noqa: E402

MODULI = (1e4, 1e5, 1e6, 1e7)
PENETRATION_BOUND = 1e-3  # m: SolverConfig.penetration_bound, the depth the env flags (sim_penetrated)
SEQUENCES = ("dive", "sweep", "rotate", "random")


def action(sequence: str, k: int, rng: np.random.Generator) -> np.ndarray:
    """The k-th delta action [7] of an adversarial sequence (see the module docstring)."""
    if sequence == "dive":
        return np.array([0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    if sequence == "sweep":
        if k < 2:
            return np.array([0.25, -0.7, 0.0, 0.0, 0.0, 0.0, 1.0])
        side = 1.0 if (k // 3) % 2 else -1.0
        return np.array([side, -0.2, 0.5 * side, 0.0, 0.0, 0.0, 1.0])
    if sequence == "rotate":
        return np.array([0.0, -0.8, 0.0, 0.6, 0.3, 1.0, 1.0 if k > 1 else -1.0])
    return rng.uniform(-1.0, 1.0, 7)


def local_coordinates(x: np.ndarray, centers: np.ndarray, quats: np.ndarray) -> np.ndarray:
    """[P, N, 3] node positions [N, 3] in each pad's box frame (centres [P, 3], quats [P, 4])."""
    inv = quats * np.array([-1.0, -1.0, -1.0, 1.0])
    return np.stack([quat_rotate(inv[p][None], x - centers[p]) for p in range(len(centers))])


def crossed_box(a: np.ndarray, b: np.ndarray, half: np.ndarray) -> np.ndarray:
    """[...] bool: a node went from one side of a box to the opposite one: for some axis, it is
    beyond the box's face on one side at the start (``a``) and beyond the opposite face at the end
    (``b``), within the face's lateral extent both times ([..., 3] box frame, m)."""
    hit = np.zeros(a.shape[:-1], bool)
    for axis in range(3):
        lateral = [j for j in range(3) if j != axis]
        inside = np.all(np.abs(a[..., lateral]) < half[lateral], axis=-1) & \
            np.all(np.abs(b[..., lateral]) < half[lateral], axis=-1)
        hit |= inside & (a[..., axis] * b[..., axis] < 0) & (np.abs(a[..., axis]) >= half[axis]) & \
            (np.abs(b[..., axis]) >= half[axis])
    return hit


class SubstepMonitor:
    """Checks every solve of the scene's solver (each physics substep, the wrist limiter's
    re-solves included: every ``ImplicitSolver.advance``, which ``step`` calls too) against the pad
    boxes and the ground, from the solver's own input and output states (pad poses at the start
    and end of the substep):

    * depth: deepest node (m) inside a pad box (nearest-face depth) or below y = 0 at the end;
    * crossed: nodes that went through a pad in the substep (``crossed_box``: from beyond one face
      to beyond the opposite one, inside the faces' extent).

    A solve that starts from the same positions as the one before it is a re-solve of that
    substep (the wrist force limiter's): only the last solve of a substep, the one whose state
    the env goes on from, is counted (``commit`` after each env step)."""

    def __init__(self, scene):
        self.scene, self.depth, self.crossed, self.step_depth, self.clamped = scene, 0.0, 0, 0.0, 0
        self.substeps, self.tip, self.wrist = 0, 0.0, 0.0
        self._pending, self._start = None, None
        solver = scene.solver
        scene.period_graphs = False  # every solve through ``advance``, from the host (none inside a period's graph)
        advance = solver.advance
        half = PAD_BOX_HALF_EXTENTS

        def checked_advance(state_in, state_out, control, dt, *args, **kwargs):
            x0 = state_in.positions.numpy().copy()
            if self._start is None or not np.array_equal(x0, self._start):
                self.commit()
            self._start = x0
            c0 = state_in.pad_positions.numpy().astype(np.float64).copy()
            q0 = state_in.pad_orientations.numpy().astype(np.float64).copy()
            advance(state_in, state_out, control, dt, *args, **kwargs)
            x1 = state_out.positions.numpy()
            c1 = control.pad_target_positions.numpy().astype(np.float64)
            q1 = control.pad_target_orientations.numpy().astype(np.float64)
            l0, l1 = local_coordinates(x0, c0, q0), local_coordinates(x1, c1, q1)
            depth = max(float(np.min(half - np.abs(l1), axis=2).max()), float(-x1[:, 1].min()))
            tip = float(state_out.pad_normal_force.numpy().max())
            wrist = float(np.linalg.norm(state_out.pad_force.numpy().reshape(-1, 2, 3).sum(axis=1), axis=-1).max())
            clamped = int(solver.scratch.clamped.numpy().any())  # this solve's SolveStats.penetrated
            self._pending = (depth, int(crossed_box(l0, l1, half).sum()), clamped, tip, wrist)

        solver.advance = checked_advance

    def commit(self) -> None:
        if self._pending is not None:
            self.depth = max(self.depth, self._pending[0])
            self.step_depth = max(self.step_depth, self._pending[0])
            self.crossed += self._pending[1]
            self.clamped += self._pending[2]
            self.substeps += 1
            self.tip, self.wrist = max(self.tip, self._pending[3]), max(self.wrist, self._pending[4])
        self._pending, self._start = None, None


def impact_margin(env) -> float:
    """Force (N) the actuator limits cannot bound: an object thrown by the pads at their largest
    legal speed v (``max_pad_travel`` per control period) and stopped by a pad whose wrist and jaw
    stopped (``wrist.force_limit``: a stop, no yield) within one physics substep h, plus its weight:
    m v / h + m g (net force = momentum change / h in the backward-Euler step). The transient
    part of a contact, as ISO/TS 15066 separates it from the quasi-static one."""
    config, scene = env.unwrapped.config, env.unwrapped.scene
    mass = float(scene.model.node_mass.numpy().sum())
    v = max_pad_travel(*max_flange_step(config), pad_reach(), config.gripper.closing_speed * config.dt) / config.dt
    return mass * v / (config.dt / scene.substeps) + mass * 9.81


def run_cell(name: str, e: float, steps: int, seed: int = 0, sequences=SEQUENCES, **env_kwargs) -> dict:
    """The fuzz of one object x E cell (see the module docstring); ``env_kwargs`` override the env's
    settings (default: the largest legal speeds)."""
    kwargs = dict(max_linear_speed=2.0, max_angular_speed=2 * math.pi, init_yaw_noise=0.0) | env_kwargs
    env = gym.make("DeformablePickup-v0", object=name, youngs_modulus=e, **kwargs)
    out = dict(deepest=0.0, crossed=0, flagged=0, unflagged=0, diverged=0, clamped=0, substeps=0, tip=0.0, wrist=0.0,
               impact=0.0, times=[])
    monitor = None
    try:
        for sequence in sequences:
            rng = np.random.default_rng(seed)
            env.reset(seed=seed)
            scene = env.unwrapped.scene
            if monitor is None or monitor.scene is not scene:
                monitor = SubstepMonitor(scene)
            monitor.depth, monitor.crossed, monitor.clamped, monitor.substeps = 0.0, 0, 0, 0
            monitor.tip, monitor.wrist = 0.0, 0.0
            for k in range(steps):
                monitor.step_depth = 0.0
                t0 = time.perf_counter()
                _, _, terminated, truncated, info = env.step(action(sequence, k, rng).astype(np.float32))
                out["times"].append(time.perf_counter() - t0)
                monitor.commit()
                out["flagged"] += int(info["sim_penetrated"])
                out["unflagged"] += int(monitor.step_depth > PENETRATION_BOUND and not info["sim_penetrated"])
                out["diverged"] += int(info["sim_diverged"])
                if terminated or truncated:
                    break
            out["deepest"] = max(out["deepest"], monitor.depth)
            out["crossed"] += monitor.crossed
            out["clamped"] += monitor.clamped
            out["substeps"] += monitor.substeps
            out["tip"], out["wrist"] = max(out["tip"], monitor.tip), max(out["wrist"], monitor.wrist)
            out["impact"] = max(out["impact"], impact_margin(env))
    finally:
        env.close()
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--steps", type=int, default=10, help="steps per sequence (default 10)")
    p.add_argument("--objects", nargs="+", default=list(OBJECT_SHAPES), choices=list(OBJECT_SHAPES))
    p.add_argument("--moduli", nargs="+", type=float, default=list(MODULI))
    p.add_argument("--edge-contact", action=argparse.BooleanOptionalAction, default=True,
                   help="hold the pads' box edges and corners out of the object too (PickupConfig.edge_contact, "
                        "the default; --no-edge-contact: node-vs-box contact alone)")
    p.add_argument("--no-append", action="store_true")
    args = p.parse_args()
    rows = ["| object | E (Pa) | deepest (mm) | crossed | flagged | unflagged | diverged | clamped | tip max (N) "
            "| wrist max (N) | impact (N) | ms/step |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    print("\n".join(rows))
    worst, tip, wrist, clamped, substeps = 0.0, 0.0, 0.0, 0, 0
    for name in args.objects:
        for e in args.moduli:
            r = run_cell(name, e, args.steps, edge_contact=args.edge_contact)
            worst, tip, wrist = max(worst, r["deepest"]), max(tip, r["tip"]), max(wrist, r["wrist"])
            clamped, substeps = clamped + r["clamped"], substeps + r["substeps"]
            rows.append(f"| {name} | {e:.0e} | {r['deepest'] * 1e3:.3f} | {r['crossed']} | {r['flagged']} | "
                        f"{r['unflagged']} | "
                        f"{r['diverged']} | {r['clamped']} | {r['tip']:.1f} | {r['wrist']:.1f} | {r['impact']:.1f} | "
                        f"{1e3 * np.mean(r['times']):.0f} |")
            print(rows[-1], flush=True)
    limit, grip = PickupConfig().wrist_force_limit, GripperConfig().grip_force_limit
    rows.append(f"\nDeepest penetration over the fuzz: {worst * 1e3:.3f} mm; the clamp fired in {clamped} of "
                f"{substeps} substeps ({100 * clamped / max(substeps, 1):.1f} %); largest tip force {tip:.1f} N "
                f"(bound (grip + wrist limit) x (1 + {FORCE_TOLERANCE:g}) = "
                f"{tip_force_bound(grip, limit) * (1 + FORCE_TOLERANCE):.0f} N, + the cell's impact); largest wrist "
                f"force {wrist:.1f} N (limit x (1 + {FORCE_TOLERANCE:g}) = {limit * (1 + FORCE_TOLERANCE):.0f} N, "
                "+ the cell's impact)")
    print(rows[-1])
    text = (f"\n## bench_contact_fuzz ({datetime.date.today()}, {host()}, load {os.getloadavg()[0]:.1f}, "
            f"{git_state()})\n\n{args.steps} steps x sequences {', '.join(SEQUENCES)} per cell; "
            "max_linear_speed 2 m/s, max_angular_speed 2 pi rad/s"
            f", edge contact {'on' if args.edge_contact else 'off'}.\n\n" + "\n".join(rows) + "\n")
    if not args.no_append:
        append_results(text)


if __name__ == "__main__":
    main()
