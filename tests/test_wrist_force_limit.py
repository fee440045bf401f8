"""Actuator force limits (``defgrasp_env.wrist.force_limit``): pure functions against a spring
contact whose force is known in closed form, and the env's wrist pressing a stiff object into the
ground."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import defgrasp_env  # noqa: F401
from defgrasp_env.wrist.force_limit import (DEFAULT_WRIST_FORCE_LIMIT, FORCE_TOLERANCE, actuator_load,
                                            limited_substep, tip_force_bound, wrist_force)


def spring_contact(gap, stiffness, travel, calls, preload=0.0, limit=150.0):
    """solve(scale): the wrist moves scale * travel (m) toward a spring (N/m) ``gap`` (m) away
    (or already pressing it with ``preload``, N, where gap = 0); returns (force N, load = force / limit)."""
    def solve(scale):
        calls.append(scale.copy())
        force = preload + stiffness * np.maximum(scale * travel - gap, 0.0)
        return force, force / limit
    return solve


def test_wrist_force_is_the_net_pad_force():
    """Equal and opposite pad forces (a pure squeeze) carry nothing; a push adds up."""
    pad_force = np.array([[[5.0, 1.0, 0.0], [-5.0, 1.0, 0.0]], [[0.0, 3.0, 4.0], [0.0, 0.0, 0.0]]])
    np.testing.assert_allclose(wrist_force(pad_force), [2.0, 5.0])


def test_free_motion_is_one_solve_at_full_scale():
    calls = []
    force, load, scale = limited_substep(spring_contact(np.array([0.01]), 1e5, np.array([0.005]), calls),
                                         np.zeros(1))
    assert len(calls) == 1 and scale.tolist() == [1.0] and force.tolist() == [0.0] and load.tolist() == [0.0]


def test_actuator_load_is_the_largest_force_over_its_limit():
    """Wrist force over the wrist limit, or a pad's normal force over grip + wrist limit, whichever
    is larger (hand-computed); no limit (inf) gives 0."""
    wrist = np.array([75.0, 10.0, 0.0])
    tip = np.array([[10.0, 10.0], [0.0, 340.0], [85.0, 85.0]])
    np.testing.assert_allclose(actuator_load(wrist, tip, 150.0, 20.0), [0.5, 2.0, 0.5])
    assert tip_force_bound(20.0, 150.0) == 170.0
    np.testing.assert_array_equal(actuator_load(wrist, tip, np.inf, 20.0), [0.0, 0.0, 0.0])


@pytest.mark.parametrize("stiffness", [1e3, 1e5, 1e7])
def test_stiff_contact_is_stopped_at_the_limit(stiffness):
    """Worlds of one batch: 0 moves freely, 1 hits a spring mid-move (force at full move far above
    the limit), 2 already pressed at the limit (stops at once). The accepted force is within the
    tolerance of the limit (1 by bracketing, independently of the stiffness), never above it."""
    limit, calls = 150.0, []
    gap = np.array([0.02, 0.004, 0.0])
    solve = spring_contact(gap, stiffness, np.array([0.01, 0.01, 0.01]), calls, np.array([0.0, 0.0, limit]))
    force, load, scale = limited_substep(solve, np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(load, force / limit)
    assert scale[0] == 1.0 and force[0] == 0.0
    assert force[1] <= limit * (1 + FORCE_TOLERANCE)
    if stiffness * 0.006 > limit * (1 + FORCE_TOLERANCE):   # the full move would exceed the limit
        assert force[1] >= limit * (1 - FORCE_TOLERANCE) or scale[1] * 0.01 <= gap[1]
        assert scale[1] < 1.0
    if stiffness * 0.01 > limit * FORCE_TOLERANCE:
        assert scale[2] == 0.0 and force[2] == limit
    else:  # a soft spring: the full move stays within the tolerance
        assert scale[2] == 1.0
    # the returned force is that of the last solve, whose scales are the returned ones
    np.testing.assert_array_equal(calls[-1], scale)


def test_a_worlds_search_does_not_depend_on_the_batch():
    """A world's bracketing is its own: world 0 (a spring whose first trial reads well under the
    limit) tries the same fractions and accepts the same scale alone as beside world 1, a stiffer,
    nearer spring whose first trial reads over the limit (the retries go on for it). Before, the
    retries' early end on "every world's trial accepted" ended world 0's search at its first trial
    alone but refined it on in the batch: another episode per batch size."""
    def run(gap, stiffness):
        calls = []
        solve = spring_contact(np.array(gap), np.array(stiffness), np.full(len(gap), 0.01), calls)
        force, load, scale = limited_substep(solve, np.zeros(len(gap)))
        return np.array(calls), load, scale

    def distinct(fractions):  # a world whose fraction is unchanged is not re-solved (the scene's solve)
        return fractions[np.r_[True, fractions[1:] != fractions[:-1]]]

    calls_alone, load_alone, scale_alone = run([0.004], [1e5])
    calls_batch, load_batch, scale_batch = run([0.004, 0.0005], [1e5, 1e6])
    assert len(calls_batch) > len(calls_alone)  # world 1 searched on after world 0's first trial
    assert scale_batch[0] == scale_alone[0] and load_batch[0] == load_alone[0]
    np.testing.assert_array_equal(distinct(calls_batch[:, 0]), calls_alone[:, 0])


def test_a_stopped_wrist_still_over_the_limit_backs_off_to_it():
    """Worlds stopped at the limit whose stop still reads over it (the object pushes back): world 0
    a spring that relaxes as the wrist backs off (force = preload + k x scale x travel, also for
    scale < 0) backs off to within the tolerance of the limit, by the least amount the bracketing
    finds (within 1 - tol .. 1 + tol, never past where the spring reads 0); world 1 the same but no
    way to back off (``can_back_off`` False: no slide planned, or the pads only squeeze) stays
    stopped; world 2 a preload that no back-off relieves keeps its stop, re-solved last at scale 0
    (the accepted solve is the last one run); world 3 held and over backs off too."""
    limit, k, travel = 150.0, 1e5, 0.01
    preload = np.array([300.0, 300.0, 300.0, 250.0])
    relaxes = np.array([True, True, False, True])
    calls = []

    def solve(scale):
        calls.append(scale.copy())
        force = np.where(relaxes, np.maximum(preload + k * travel * np.minimum(scale, 0.0), 0.0), preload)
        force = force + k * np.maximum(scale * travel, 0.0)  # any forward motion presses harder
        return force, force / limit

    held = np.array([False, False, False, True])
    force, load, scale = limited_substep(solve, np.ones(4), held=held,
                                         can_back_off=lambda over: over & np.array([True, False, True, True]))
    assert scale[0] < 0.0 and abs(load[0] - 1.0) <= FORCE_TOLERANCE
    assert scale[0] > -(preload[0] / (k * travel))            # it did not back off past the spring's relief
    assert scale[1] == 0.0 and force[1] == preload[1]         # cannot back off: the stop stands
    assert scale[2] == 0.0 and force[2] == preload[2]         # no back-off helps: the stop stands
    assert scale[3] < 0.0 and abs(load[3] - 1.0) <= FORCE_TOLERANCE
    np.testing.assert_array_equal(calls[-1], scale)          # the last solve is the accepted one
    assert len(calls) <= 1 + (1 + 6) + (1 + 6)                # first try, stop, back-off search


def test_env_wrist_pressing_down_is_limited():
    """The env's wrist drives the closed gripper (closed first, in the air, for 0.6 s) straight
    down at 2 m/s onto an E = 1e7 cuboid
    (which the ground holds): the wrist force in info stays within the limit + 10 % tolerance
    (+5 N for the object's weight and dynamics), and each tip force within grip-force limit +
    wrist limit (the two bounds add at most, one pad carrying all the push)."""
    env = gym.make("DeformablePickup-v0", object="cuboid", youngs_modulus=1e7, max_linear_speed=2.0)
    env.reset(seed=0)
    grip = env.unwrapped.config.gripper.grip_force_limit
    for _ in range(12):
        env.step(np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0], np.float32))
    worst_wrist, worst_tip = 0.0, 0.0
    for _ in range(6):
        _, _, _, _, info = env.step(np.array([0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0], np.float32))
        worst_wrist = max(worst_wrist, info["wrist_force"])
        worst_tip = max(worst_tip, info["left_tip_normal_force"], info["right_tip_normal_force"])
        assert info["penetration"] < 1e-3 and not info["sim_penetrated"]
    env.close()
    assert worst_wrist > 0.5 * DEFAULT_WRIST_FORCE_LIMIT      # it did press
    assert worst_wrist <= DEFAULT_WRIST_FORCE_LIMIT * (1 + FORCE_TOLERANCE) + 5.0
    assert worst_tip <= grip + DEFAULT_WRIST_FORCE_LIMIT * (1 + FORCE_TOLERANCE) + 5.0


def test_held_world_stays_stopped_in_one_solve():
    """A world the limit stopped before on the same push (``held``) is solved once, at scale 0, and
    accepted with the force it presses with; not held, the same world first tries its full move,
    reads over the limit and is stopped at 0 with the same force. A held world's neighbours in the
    batch bracket as before."""
    limit, travel = 150.0, np.array([0.01, 0.01])
    results = {}
    for held in (None, np.array([False, True])):
        calls = []
        solve = spring_contact(np.array([0.004, 0.0]), 1e5, travel, calls, np.array([0.0, limit]))
        force, load, scale = limited_substep(solve, np.array([0.0, 1.0]), held=held)
        results[held is None] = force, scale, np.array(calls)
    (force_try, scale_try, calls_try), (force_held, scale_held, calls_held) = results[True], results[False]
    assert scale_try[1] == scale_held[1] == 0.0 and force_try[1] == force_held[1] == limit
    assert calls_try[0, 1] == 1.0 and np.all(calls_held[:, 1] == 0.0)  # the held world never tried to move
    np.testing.assert_array_equal(scale_try[0], scale_held[0])            # its neighbour bracketed the same way
    assert force_held[0] <= limit * (1 + FORCE_TOLERANCE)


@pytest.mark.parametrize("name, modulus, sideways, turn", [("cuboid", 1e6, 0.7, 0.0), ("sphere", 1e7, 0.3, 0.0),
                                                          ("cuboid", 1e6, 0.7, 0.4), ("sphere", 3e6, 0.3, 0.3)])
def test_sustained_push_is_held_without_retries_and_released_at_once(monkeypatch, name, modulus, sideways, turn):
    """The closed gripper pushed down (and sideways) onto an object on the ground for 26 control
    steps, then lifted: what an RL policy does while learning, also turning its wrist about the
    vertical back and forth (``turn``: the yaw action, alternating each step, as a learner's noisy
    policy does). The wrist stops at its limit; each later substep of the same push is held
    (``Gripper.held_at_limit``, turn or not) in one solve instead of a full-motion try (with a
    patient re-solve where the try may be under the limit converged) and a stopped re-solve.
    Independent truth: the same episode with holding switched off (``HOLD_COSINE`` above 1: every
    substep tries its motion) gives bit-identical observations and wrist forces with >= 1.3x the
    solves (measured 1.5-1.8x; 1.8-1.9x while every try over the limit was re-solved patiently,
    before 2026-12-07; 1.35x for the stiff sphere, 1.67-1.86x for the others, with the solver's
    rigid-motion coarse space, whose patient re-solves converge sooner), turning or not: a world at its limit whose try reads over is
    stopped whole (slide, turn and jaw), as the held one is, and one the object still pushes over
    the limit backs off (along the object's push, not turning), as the held one does. While
    pressing, the turning wrist keeps its orientation, and the wrist force stays within the limit's
    tolerance (the sphere, E = 3e6, turning, read 172 N before stopped pads could back off,
    2026-12-07). The lift then moves the wrist up at the full 0.3 m/s from its first step.
    (Where a turn eases the load enough for the full try to read within the limit, holding does
    change an episode: a cylinder, E = 3e6, pushed with the yaw at 0.4 turned and read 168 N on a
    pad tried, 136 N held; the hold is a protective stop, released when the slide turns away or the
    load drops.)"""
    from defgrasp_env.gripper import gripper as gripper_module
    from defgrasp_env.layout import AGENT_POS, DELTA_ACTION, ENV_STATE

    def episode():
        env = gym.make("DeformablePickup-v0", object=name, youngs_modulus=modulus)
        obs, _ = env.reset(seed=1)
        scene = env.unwrapped.scene
        rows = []
        for t in range(36):
            offset = ENV_STATE.get(obs["environment_state"], "feature_position") - scene.gripper.tcp_positions()[0]
            toward = np.clip(offset / 0.015, -1.0, 1.0)
            push = [toward[0] + sideways, -1.0 if t > 5 else 0.0, toward[2]] if t < 32 else [0.0, 1.0, 0.0]
            spin = [0.0, turn * (-1.0) ** t if t < 32 else 0.0, 0.0]
            action = DELTA_ACTION.pack(linear_velocity=np.clip(push, -1.0, 1.0), angular_velocity=spin, jaw=[1.0])
            obs, _, _, _, info = env.step(action.astype(np.float32))
            rows.append((obs["agent_pos"].copy(), obs["environment_state"].copy(), info["wrist_force"]))
        env.close()
        return rows, scene.world_solves

    held_rows, held_solves = episode()
    monkeypatch.setattr(gripper_module, "HOLD_COSINE", 2.0)  # above any cosine: no world is held
    tried_rows, tried_solves = episode()
    for (pos_a, state_a, wrist_a), (pos_b, state_b, wrist_b) in zip(held_rows, tried_rows):
        np.testing.assert_array_equal(pos_a, pos_b)
        np.testing.assert_array_equal(state_a, state_b)
        assert wrist_a == wrist_b
    if turn:  # it turned before the press; while pressing at the limit its orientation stays
        quats = np.array([AGENT_POS.get(r[0], "wrist_quat") for r in held_rows])
        pressing = [t for t in range(1, 32) if held_rows[t - 1][2] >= DEFAULT_WRIST_FORCE_LIMIT]
        assert len(pressing) >= 10 and np.abs(quats[1] - quats[0]).max() > 1e-3
        assert max(np.abs(quats[t] - quats[t - 1]).max() for t in pressing[1:]) == 0.0
    assert max(r[2] for r in held_rows) > DEFAULT_WRIST_FORCE_LIMIT  # it pressed at the limit
    assert tried_solves >= 1.3 * held_solves, (held_solves, tried_solves)
    heights = [AGENT_POS.get(r[0], "wrist_position")[1] for r in held_rows[31:]]
    np.testing.assert_allclose(np.diff(heights), 0.3 * 0.05, rtol=1e-3)  # lifting at full speed at once
    worst, bound = max(r[2] for r in held_rows), DEFAULT_WRIST_FORCE_LIMIT * (1 + FORCE_TOLERANCE)
    assert worst <= bound, worst


def test_a_patient_solve_is_not_repeated_from_the_same_input(monkeypatch):
    """Eight worlds (objects drawn, E = 3e6), jaws closed, pushed down at 2 m/s with random slides
    and turns: within a substep the force limit re-solves patiently only worlds that the solve just
    before computed. A world whose last solve was patient already and still reads over its limit
    keeps that solve while its neighbours bracket on: a patient re-solve from the same input would
    repeat it (its ``unconverged`` flag tells of the regular iterations and stays set). Independent
    truth: the same episode with that world re-solved after every later retry (the code before
    2026-11-28, emulated by forgetting which worlds were solved patiently) gives bit-identical
    observations, rewards, infos and states with more world-solves; this seed has such worlds (9
    re-solves repeated with that rule; seed 4 had one until the continuous face depth of 2026-12-07
    made its solves converge; on an H200 at W = 2000, a five-object PPO batch had 120-140 a step)."""
    from defgrasp_env.envs import scene as scene_module
    from defgrasp_env.sim.solver import ImplicitSolver

    def episode():
        env = gym.make_vec("DeformablePickup-v0", num_envs=8, vectorization_mode="vector_entry_point",
                           object="random", youngs_modulus=3e6, max_linear_speed=2.0, max_episode_steps=60)
        env.reset(seed=1)
        scene = env.unwrapped.scene
        scene.period_graphs = False  # every solve through ImplicitSolver.advance (the same bits either way)
        calls = []
        advance = ImplicitSolver.advance

        def logged(self, state_in, state_out, control, dt, patient=None, worlds=None, **kwargs):
            solved = np.ones(scene.num_worlds, bool) if worlds is None else np.asarray(worlds, bool).copy()
            calls.append((solved, None if patient is None else np.asarray(patient, bool).copy()))
            return advance(self, state_in, state_out, control, dt, patient, worlds, **kwargs)

        monkeypatch.setattr(ImplicitSolver, "advance", logged)
        rng = np.random.default_rng(1)
        rows = []
        for t in range(13):
            action = np.zeros((8, 7), np.float32)
            action[:, 6] = 1.0  # close the jaw (10 steps in the air), then push down, sliding and turning
            if t >= 10:
                action[:, 1] = -1.0
                for column in (0, 2, 4):
                    action[:, column] = rng.uniform(-1.0, 1.0, 8)
            obs, reward, _, _, info = env.step(action)
            rows.append((obs, reward, {k: np.asarray(v) for k, v in info.items() if not isinstance(v, dict)}))
        monkeypatch.setattr(ImplicitSolver, "advance", advance)
        state = {name: getattr(scene.state, name).numpy().copy() for name in ("positions", "velocities")}
        env.close()
        # patient worlds that the solve before did not compute: re-solved from their last input
        repeated = sum(int(np.count_nonzero(patient & ~before)) for (before, _), (_, patient) in zip(calls, calls[1:])
                       if patient is not None)
        return rows, state, scene.world_solves, repeated

    rows, state, solves, repeated = episode()
    forget = scene_module.PickupScene._solve_substep

    def forgetting(self, *args, **kwargs):
        out = forget(self, *args, **kwargs)
        self._patient_solved[:] = False
        return out

    monkeypatch.setattr(scene_module.PickupScene, "_solve_substep", forgetting)
    rows_before, state_before, solves_before, repeated_before = episode()
    assert repeated == 0 and repeated_before >= 1, (repeated, repeated_before)
    assert solves_before == solves + repeated_before
    for (obs, reward, info), (obs_b, reward_b, info_b) in zip(rows, rows_before):
        for name in obs:
            np.testing.assert_array_equal(obs[name], obs_b[name])
        np.testing.assert_array_equal(reward, reward_b)
        for name in info:
            np.testing.assert_array_equal(info[name], info_b[name], err_msg=name)
    for name in state:
        np.testing.assert_array_equal(state[name], state_before[name])
    assert max(float(np.max(info["wrist_force"])) for _, _, info in rows) > DEFAULT_WRIST_FORCE_LIMIT
