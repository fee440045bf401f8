"""Tip and wrist force readings stay within the actuators' limits under adversarial actions.

A pad's normal force is bounded by what the actuators can exert: the jaw squeezes with at most its
grip-force limit G and the arm pushes with at most its wrist limit W, so one pad reads at most
G + W (``wrist.force_limit.tip_force_bound``), and the wrist force (net pad force) at most W. The
scene's limiter accepts a substep whose load is within ``FORCE_TOLERANCE`` (10 %) of a limit, so
the bounds asserted are (G + W)(1 + tol) and W(1 + tol), plus what no actuator limit bounds: the
wrist and jaw stop, and the wrist backs off only where the stop still reads over the limit, so an
object the pads threw and a stopped pad stops within one substep h adds its momentum change
m v / h to the net force, plus its weight
(``bench_contact_fuzz.impact_margin``, with v the largest legal pad speed: 85 N at 2 m/s and
2 pi rad/s with 21 substeps of 2.4 ms, for a 37 g cylinder; the transient part of a contact,
which ISO/TS 15066 bounds separately, at twice the quasi-static limit). Measured: a cuboid swept
at 2 m/s into a stopped pad added 14 N within a substep.

Reproduction (``test_torus_sweep_pinch``): the fuzz case that read 17.7 kN on one pad with a 122 N
wrist force (``bench_contact_fuzz.py``, torus E = 1e7, ``sweep``, 10 steps). The cause was not the
actuators' travel (with wrist and jaw stopped in the substep the solve still read 1.1 kN) but
Newton stopping at its 4-iteration limit on a stiff pad contact: the converged solve reads 24 N.
Over a limit, the scene now re-solves with ``SolverConfig.patient_iterations`` (60: 28 were not
enough for a sphere E = 1e5 swept at 2 m/s, which still read 1.2 kN) before it believes
the forces, and then moves wrist and jaw by the fraction that keeps them within the limits.

``test_bounds_held_out`` runs parameters the fix was not tuned on: other moduli (3e5, 3e6 Pa), a
1.5 m/s, pi rad/s wrist, other limits (G = 60 N, W = 80 N), dive, sweep and random sequences of
other seeds (5, 6).
"""

from __future__ import annotations

import copy
import math
import pathlib
import sys

import gymnasium as gym
import numpy as np
import pytest

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_contact_fuzz import action, run_cell  # noqa: E402

import defgrasp_env  # noqa: E402,F401
from defgrasp_env.envs.actions import targets  # noqa: E402
from defgrasp_env.gripper import GripperConfig  # noqa: E402
from defgrasp_env.sim.state import Control, State  # noqa: E402
from defgrasp_env.wrist.force_limit import DEFAULT_WRIST_FORCE_LIMIT, FORCE_TOLERANCE, tip_force_bound  # noqa: E402



def _within_default_limits(r: dict) -> None:
    """A fuzz cell's largest tip and wrist forces (``run_cell``) within the default limits' bounds
    (grip and wrist limit x (1 + tolerance), plus the cell's impact margin)."""
    grip = GripperConfig().grip_force_limit
    assert r["tip"] <= tip_force_bound(grip, DEFAULT_WRIST_FORCE_LIMIT) * (1 + FORCE_TOLERANCE) + r["impact"], r
    assert r["wrist"] <= DEFAULT_WRIST_FORCE_LIMIT * (1 + FORCE_TOLERANCE) + r["impact"], r


def test_torus_sweep_pinch():
    r = run_cell("torus", 1e7, 10, sequences=("sweep",))
    _within_default_limits(r)
    assert r["crossed"] == 0 and r["diverged"] == 0 and r["unflagged"] == 0


def test_cylinder_sweep_at_the_default_limits():
    """The contact fuzz's cylinder E = 3e6 swept at 2 m/s with the default limits (grip 20 N, wrist
    150 N; the fuzz's grid runs 1e4-1e7 by decades and ``test_bounds_held_out`` other limits, so
    neither saw it): from a839bf0 until the continuous face depth (``test_face_contact.py``) a
    substep's retries ended at a stopped pad whose re-solve stalled (last update 1.9 mm after 4 + 60
    Newton iterations: a node sliding past a pad face's edge met the full depth at once, and the
    line search's shortest step went uphill) and was kept at 966 N tip / 882 N wrist. Measured
    since: 261 N / 185 N (bounds 270 / 248 N with the impact margin). With the tets' rotation
    seeded without the SVD (float32 noise, another trajectory) a stopped pad read 1.1-1.3 kN,
    converged, for four substeps: the compressed cylinder pushed back on a pad that could only stop.
    Since a stopped wrist backs off (``wrist.force_limit``): 161 N / 161 N (2026-12-07)."""
    r = run_cell("cylinder", 3e6, 10, sequences=("sweep",))
    _within_default_limits(r)


@pytest.mark.slow
@pytest.mark.parametrize("name, e", [("cylinder", 3e6), ("sphere", 3e5), ("cuboid", 3e6), ("torus", 3e5)])
def test_bounds_held_out(name, e):
    grip, wrist_limit = 60.0, 80.0
    settings = dict(max_linear_speed=1.5, max_angular_speed=math.pi, wrist_force_limit=wrist_limit,
                    gripper=GripperConfig(grip_force_limit=grip))
    runs = [run_cell(name, e, 8, seed=5, sequences=("dive", "sweep", "random"), **settings),
            run_cell(name, e, 8, seed=6, sequences=("random",), **settings)]
    worst_tip, worst_wrist = max(r["tip"] for r in runs), max(r["wrist"] for r in runs)
    impact = max(r["impact"] for r in runs)
    assert not any(r["diverged"] or r["crossed"] or r["unflagged"] for r in runs), runs
    assert worst_tip <= tip_force_bound(grip, wrist_limit) * (1 + FORCE_TOLERANCE) + impact, (worst_tip, impact)
    assert worst_wrist <= wrist_limit * (1 + FORCE_TOLERANCE) + impact, (worst_wrist, impact)


@pytest.mark.parametrize("name", ["torus", "cuboid"])
def test_patient_re_solves_settle_the_limits_decision_not_convergence(monkeypatch, name):
    """Stiff objects (E = 1e7) swept and dived into at the largest legal speeds: the force limit
    re-solves an unconverged solve patiently only until its decision is settled (a try that reads
    over the limit even less its force error twice is retried with less motion at once; one that
    reads under, over only with its error, iterates to half the update that settles it:
    ``limit_loads.SolveLoads.patient_re_solve``). Independent truth: the actuator bounds (as
    ``test_torus_sweep_pinch``), and the same runs with the rule before 2026-12-07 (every solve
    over the limit re-solved to the Newton tolerance, emulated) keep them too, with more Newton
    iterations over all solves (retries and patient re-solves counted; asserted: at least 1/0.95 x): measured
    torus 2,315 -> 1,664, cuboid 10,794 -> 5,518 with the translations of one aggregate as the
    coarse space; with the rigid motions of 8 (2026-12-07), which converge a stiff object's solves
    in far fewer iterations, torus 1,844 -> 1,123, cuboid 1,657 -> 1,508."""
    from defgrasp_env.envs import limit_loads
    from defgrasp_env.sim.solver import ImplicitSolver

    advance, iterations = ImplicitSolver.advance, [0]

    def counted(self, state_in, state_out, control, dt, patient=None, worlds=None, **kwargs):
        advance(self, state_in, state_out, control, dt, patient, worlds, **kwargs)
        solved = np.ones(self.model.num_worlds, bool) if worlds is None else np.asarray(worlds, bool)
        iterations[0] += int(self.scratch.newton_it.numpy()[solved].sum())

    monkeypatch.setattr(ImplicitSolver, "advance", counted)

    def run():
        iterations[0] = 0
        r = run_cell(name, 1e7, 10, sequences=("sweep", "dive"))
        _within_default_limits(r)
        assert r["crossed"] == 0 and r["diverged"] == 0 and r["unflagged"] == 0, r
        return iterations[0]

    settled = run()
    monkeypatch.setattr(limit_loads, "PATIENT_UPDATE_FRACTION", 0.0)  # to the Newton tolerance
    monkeypatch.setattr(limit_loads.SolveLoads, "certainly_over", lambda self: np.zeros(len(self.load), bool))
    converged = run()
    assert settled <= 0.95 * converged, (settled, converged)


def test_patient_iterations_converge_one_world_and_leave_the_other_bit_identical():
    """Two identical worlds swept into a torus (E = 1e7) until the first substep of a step reads
    kN with its 4 regular Newton iterations, unconverged (searched over the sweep's first 30 steps:
    which step it is depends on the solver's path; step 6 with CG solved to 1e-3 in every Newton
    iteration, none of the first 10 with the inexact steps of ``cg_tolerance_far``): that substep solved
    with world 0 patient. World 1's result equals, bit for bit, the solve without patience; world 0
    meets the Newton tolerance and reads a pad force far below world 1's unconverged one. With node
    contact alone (``edge_contact=False``): with the pads' edges held out (the default) no substep
    of this sweep's first steps read kN unconverged, and the case needs one. Asked to stop at half
    the plain solve's update (``patient_update``; above the tolerance), world 0 stops under it with
    fewer iterations than to the tolerance (measured 2026-12-07: the plain solve's 4 iterations end
    at 2.0e-3 m, the next at 2.4e-4 m, the tolerance is met at the 7th); a NaN update is refused."""
    venv = gym.make_vec("DeformablePickup-v0", num_envs=2, object="torus", youngs_modulus=1e7,
                        max_linear_speed=2.0, max_angular_speed=2 * math.pi, init_yaw_noise=0.0,
                        init_position_noise=0.0, edge_contact=False)
    found = None
    try:
        venv.reset(seed=0)
        rng = np.random.default_rng(0)
        for k in range(30):
            a = np.tile(action("sweep", k, rng).astype(np.float32), (2, 1))
            scene = venv.unwrapped.scene
            probe = copy.deepcopy(scene.gripper)   # plans the step's first substep; the scene's stays as it is
            pos, quat, gap = targets(scene.gripper, venv.unwrapped.config, a)
            probe.begin_step(pos, quat, gap)
            h = venv.unwrapped.config.dt / scene.substeps
            probe.plan_substep(0, scene.substeps, h)
            control = Control.from_model(scene.model)
            probe.move()
            pad_pos, pad_quat = probe.pad_target_poses()
            control.pad_target_positions.assign(pad_pos.reshape(-1, 3).astype(np.float32))
            control.pad_target_orientations.assign(pad_quat.reshape(-1, 4).astype(np.float32))
            plain_state, patient_state = State.from_model(scene.model), State.from_model(scene.model)
            plain = scene.solver.step(scene.state, plain_state, control, h)
            tip_plain = plain_state.pad_normal_force.numpy().reshape(2, 2)
            if not plain.converged[0] and tip_plain[0].max() > 1000.0:
                patient = scene.solver.step(scene.state, patient_state, control, h, np.array([True, False]))
                partial_state = State.from_model(scene.model)
                middle = 0.5 * float(plain.last_update[0])  # half the plain update: above the tolerance
                partial = scene.solver.step(scene.state, partial_state, control, h, np.array([True, False]),
                                            patient_update=np.array([middle, 1.0]))
                x_partial = partial_state.positions.numpy().copy()
                with pytest.raises(ValueError, match="patient_update"):
                    scene.solver.step(scene.state, partial_state, control, h, np.array([True, False]),
                                      patient_update=np.array([np.nan, 1.0]))
                refused_flags = scene.solver.scratch.patient.numpy().copy()
                rows = scene.model.world_nodes(1)
                x_plain, x_patient = plain_state.positions.numpy(), patient_state.positions.numpy()
                tip_patient = patient_state.pad_normal_force.numpy().reshape(2, 2)
                found = k
                break
            venv.step(a)
    finally:
        venv.close()
    assert found is not None, "no sweep step read kN unconverged: the case at hand is gone"
    assert plain.last_update[0] > 1e-5
    np.testing.assert_array_equal(x_patient[rows], x_plain[rows])
    np.testing.assert_array_equal(tip_patient[1], tip_plain[1])
    assert patient.last_update[0] <= 1e-5 and patient.newton_iterations[0] > plain.newton_iterations[0]
    assert tip_patient[0].max() < 0.1 * tip_plain[0].max(), (tip_patient, tip_plain)
    # asked for a larger update (``patient_update``), world 0 stops once under it, before convergence
    assert 1e-5 < partial.last_update[0] <= np.float32(middle), (partial.last_update[0], middle)  # stored as float32
    assert plain.newton_iterations[0] < partial.newton_iterations[0] < patient.newton_iterations[0]
    np.testing.assert_array_equal(x_partial[rows], x_plain[rows])
    assert not refused_flags.any()  # the refused call left no world marked patient for later solves


def test_force_limit_retries_keep_vector_worlds_equal_to_single_envs():
    """Worlds of a vector env are independent under the actuator force limit: a torus (E = 1e7)
    swept, dived into and shaken at the largest legal speeds in three worlds gives, world by world
    and bit for bit, the observations, tip forces and solver reports of a single env driven by the
    same actions. The scene re-solves only the worlds a retry changes (``ImplicitSolver.advance``'s
    ``worlds``; asserted to have happened: a solve of some but not all worlds), so one world's
    retries cannot replace another world's patient (converged) solve with a plain one. (Re-solving
    every world could; this case passed with that code too: it guards the restricted solves.)"""
    sequences, steps, seed = ("sweep", "dive", "random"), 8, 3
    fast = dict(object="torus", youngs_modulus=1e7, max_linear_speed=2.0, max_angular_speed=2 * math.pi)

    def actions(i):
        rng = np.random.default_rng(i)
        return np.array([action(sequences[i], k, rng) for k in range(steps)], np.float32)

    def rollout(env, i_seed, acts, spy=None):
        obs, _ = env.reset(seed=i_seed)
        if spy is not None:
            scene = env.unwrapped.scene
            scene.period_graphs = False  # every solve through ``advance`` (the single env's periods run as graphs)
            advance = scene.solver.advance

            def counted(state_in, state_out, control, dt, patient=None, worlds=None, **kwargs):
                spy.append(None if worlds is None else np.asarray(worlds).copy())
                advance(state_in, state_out, control, dt, patient, worlds, **kwargs)

            scene.solver.advance = counted
        out = []
        for a in acts:
            obs, _, _, _, info = env.step(a)
            out.append((np.array(obs["agent_pos"]), np.array(obs["environment_state"]),
                        np.stack([info["left_tip_normal_force"], info["right_tip_normal_force"]], -1),
                        np.array(info["newton_iterations"]), np.array(info["sim_converged"])))
        env.close()
        return out

    masks = []
    venv = gym.make_vec("DeformablePickup-v0", num_envs=3, **fast)
    together = rollout(venv, seed, np.stack([actions(i) for i in range(3)], axis=1), masks)
    partial = [m for m in masks if m is not None and 0 < m.sum() < 3]
    assert partial, "no solve of some worlds only: the case at hand (a retry in some worlds) is gone"
    for i in range(3):
        alone = rollout(gym.make("DeformablePickup-v0", **fast), seed + i, actions(i))
        for k in range(steps):
            for got, want in zip(together[k], alone[k]):
                np.testing.assert_array_equal(got[i], want.reshape(got[i].shape), err_msg=f"world {i} step {k}")
