"""The pickup task on the device (``envs.task_kernels`` through ``PickupTask``) against the numpy
reference of its rules (``envs.task``: ``grasp_quality``, ``feature_beyond_pad_faces``,
``shaped_progress``; ``Gripper.pad_force_angles``; ``gripper.pad_box_poses``; ``fk_analytic``),
written out below as the env computed them before the task moved to the device:
- on random states over every regime of the rules (grasped or not, forces inside and outside the
  friction cone and frictionless pads, feature points beside the pads and at the goal, piercing on
  either side of PIERCE_DEPTH, diverged, non-finite, reset worlds, hold counters reaching the
  success, step counts reaching the time limit, NaN forces);
- in the vector env along random episodes with autoresets (the kernels read the arrays the env's
  scene and gripper hold: the wiring).
Tolerance: float64 rounding (rtol 1e-12, atol 1e-15; the compiled tanh / atan2 may differ from
numpy's in the last bit); flags and counters exactly. Observations are exact (copies of float64
state, rounded to float32 once)."""

import gymnasium as gym
import numpy as np
import pytest
import warp as wp

from defgrasp_env.envs.config import PickupConfig
from defgrasp_env.envs.task import (FORCE_FREE, FORCE_SCALE, GRASP_FORCE, LIFT_SCALE, PIERCE_DEPTH, PLACE_SCALE, REACH_SCALE, REWARD_TERMS,
                                    PickupTask, feature_beyond_pad_faces, grasp_quality, shaped_progress)
from defgrasp_env.envs.task_kernels import OUTPUT_COLUMNS, RESULT_COLUMNS, column, evaluate_worlds, observe_worlds
from defgrasp_env.gripper import Gripper, GripperConfig, pad_box_poses
from defgrasp_env.gripper import kernels as gk
from defgrasp_env.layout import AGENT_POS, ENV_STATE, NUM_KEYPOINTS
from defgrasp_env.sim.kernels.report import SolveRecord
from defgrasp_env.transforms import quat_to_matrix
from defgrasp_env.wrist import fk_analytic

RTOL, ATOL = 1e-12, 1e-15
FLAGS = ("is_success", "grasped", "pierced", "sim_diverged", "terminated", "truncated")


def reference(q, gap, tip, pad_force, feature, finite, embedding, penetration, solver_diverged, live, held,
              elapsed, goals, config: PickupConfig, hold_steps: int, max_steps: int) -> dict:
    """The task's rules in numpy (the env's evaluation before it moved to the device); ``goals``
    [W, 3] m: each world's goal."""
    w = len(q)
    g = Gripper(GripperConfig(), w)
    g.arrays.q.assign(q)
    g.arrays.pad_force.assign(pad_force)
    angles = g.pad_force_angles()   # the reference of the pads' force angles (fresh gripper: no cached reads)
    pad_pos, pad_quat = pad_box_poses(*fk_analytic(q), gap)
    diverged = (solver_diverged | ~finite) & live
    valid = live & ~diverged
    reach_dist = np.linalg.norm(pad_pos.mean(axis=1) - feature, axis=1)
    goal_dist = np.linalg.norm(feature - goals, axis=1)
    grasped = np.all(tip > GRASP_FORCE, axis=1)
    with np.errstate(invalid="ignore"):
        quality = grasp_quality(angles, config.pad_friction, feature_beyond_pad_faces(feature, pad_pos, pad_quat))
    held_well = np.where(grasped & np.isfinite(quality), quality, 0.0)
    pierced = (penetration > PIERCE_DEPTH) | (embedding > PIERCE_DEPTH)
    at_goal = (goal_dist < config.success_tolerance) & grasped & ~pierced & valid
    held = np.where(at_goal, held + 1, 0)
    elapsed = elapsed + 1
    wrist_force = np.linalg.norm(pad_force.sum(axis=1), axis=1)
    success = held >= max(hold_steps, 1)
    terms = {"reach": shaped_progress(reach_dist, REACH_SCALE) * 0.5, "grasp": 0.5 * held_well,
             "lift": held_well * shaped_progress(goal_dist, LIFT_SCALE) * 2.0,
             "place": held_well * shaped_progress(goal_dist, PLACE_SCALE), "success": 10.0 * success,
             # a non-finite force (world 0's NaN pad force) costs nothing: the scene refuses such forces
             "force": np.where(np.isfinite(wrist_force), -np.clip((wrist_force - FORCE_FREE) / FORCE_SCALE, 0.0, 1.0), 0.0)}
    out = {"reward": np.zeros(w)}
    for name in REWARD_TERMS:
        out[f"reward_{name}"] = np.where(valid, terms[name], 0.0)
        out["reward"] = out["reward"] + out[f"reward_{name}"]
    out.update(is_success=success, grasped=grasped, grasp_quality=held_well, pierced=pierced,
               goal_distance=goal_dist, pad_embedding=embedding.astype(np.float64), sim_diverged=diverged,
               terminated=success & live & config.terminate_on_success, truncated=(diverged | (elapsed >= max_steps)) & live, elapsed=elapsed,
               left_tip_normal_force=tip[:, 0], right_tip_normal_force=tip[:, 1], jaw_gap=gap,
               wrist_force=wrist_force)
    return out, held


def _random_worlds(rng, w, goals):
    """Random states over the rules' regimes (see the module docstring)."""
    q = np.column_stack([rng.uniform(-0.2, 0.2, w), rng.uniform(0.02, 0.7, w), rng.uniform(-0.2, 0.2, w),
                         rng.uniform(-np.pi, np.pi, w), rng.uniform(-0.6, 0.6, w), rng.uniform(-0.6, 0.6, w)])
    gap = rng.uniform(0.0, 0.085, w)
    tip = rng.choice([0.0, 0.3, GRASP_FORCE, 0.6, 5.0, 40.0, 90.0, 200.0], size=(w, 2))
    pos, quat = fk_analytic(q)
    pad_pos, pad_quat = pad_box_poses(pos, quat, gap)
    R = quat_to_matrix(quat)
    opening = R[:, :, 0]
    # pad forces: along the opening direction (antipodal), tilted by random angles up to ~100 degrees, zero
    tilt = rng.choice([0.0, 0.2, 0.5, 0.8, 1.2, 1.8], size=(w, 2)) * rng.choice([0.0, 1.0], size=(w, 2), p=[0.1, 0.9])
    side = R[:, :, 2]
    forces = np.zeros((w, 2, 3))
    for p, sign in ((0, 1.0), (1, -1.0)):
        direction = sign * opening * np.cos(tilt[:, p])[:, None] + side * np.sin(tilt[:, p])[:, None]
        forces[:, p] = direction * tip[:, p:p + 1]
    # feature points: between the pads, beside them across their width, below them, at the goal
    tcp = pad_pos.mean(axis=1)
    choice = rng.integers(0, 4, w)
    feature = tcp + rng.normal(0.0, 0.003, (w, 3))
    feature[choice == 1] += side[choice == 1] * rng.uniform(0.005, 0.04, (np.sum(choice == 1), 1))
    feature[choice == 2] = goals[choice == 2] + rng.normal(0.0, 0.03, (np.sum(choice == 2), 3))
    feature[choice == 3] = rng.uniform(-0.3, 0.7, (np.sum(choice == 3), 3))
    finite = rng.random(w) > 0.05
    embedding = rng.choice([0.0, 0.004, PIERCE_DEPTH, 0.006], size=w).astype(np.float32)
    penetration = rng.choice([0.0, 0.002, PIERCE_DEPTH, 0.0051, np.nan], size=w).astype(np.float32)
    solver_diverged = rng.random(w) < 0.05
    live = rng.random(w) > 0.1
    return q, gap, tip, forces, feature, finite, embedding, penetration, solver_diverged, live


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=pytest.mark.cuda)])
@pytest.mark.parametrize("friction", [0.0, 0.8])
@pytest.mark.parametrize("terminate", [True, False])
def test_device_evaluation_matches_the_numpy_rules_on_random_worlds(friction, terminate, device):
    w, steps = 4000, 3
    config = PickupConfig(pad_friction=friction, goal=(0.0, 0.6, 0.0), device=device, terminate_on_success=terminate)
    task = PickupTask(config, w, max_episode_steps=5)
    rng = np.random.default_rng(7 if friction else 8)
    held = rng.integers(0, task.hold_steps + 1, w)  # some worlds one step from their success
    elapsed = rng.integers(0, 6, w)                  # some at the time limit
    task._held.assign(held.astype(np.int32))
    task._elapsed.assign(elapsed.astype(np.int32))
    seen = {name: 0 for name in FLAGS}
    # each world's own goal (a config's goal_noise draws them per episode): half at the config's
    goals = np.where(rng.random((w, 1)) < 0.5, np.asarray(config.goal), rng.uniform([-0.1, 0.05, -0.1], [0.1, 0.6, 0.1], (w, 3)))
    for _ in range(steps):
        q, gap, tip, forces, feature, finite, embedding, penetration, solver_diverged, live = _random_worlds(rng, w, goals)
        # world 0: grasped, one pad's force NaN, the other's inside the cone; world 1: grasped with
        # a NaN feature point (a diverged world): numpy's quality is NaN there, so neither holds well
        tip[:2] = 5.0
        forces[:2, 1] = -quat_to_matrix(fk_analytic(q[:2])[1])[:, :, 0] * 5.0
        forces[0, 0] = np.nan
        forces[1, 0] = quat_to_matrix(fk_analytic(q[1:2])[1])[:, :, 0] * 5.0
        feature[1], finite[1] = np.nan, False
        want, held = reference(q, gap, tip, forces, feature, finite, embedding, penetration, solver_diverged, live,
                               held, elapsed, goals, config, task.hold_steps, 5)
        elapsed = want["elapsed"]
        records = wp.zeros(w, dtype=SolveRecord, device="cpu")
        r = records.numpy()  # a view on the CPU
        r["penetration"], r["diverged"] = penetration, solver_diverged
        d = device
        records = wp.clone(records, device=d)
        args = [wp.array(q, dtype=gk.vec6d, device=d), wp.array(gap, dtype=wp.float64, device=d),
                wp.array(tip, dtype=wp.vec2d, device=d), wp.array(forces, dtype=wp.vec3d, device=d),
                wp.array(feature, dtype=wp.vec3d, device=d), wp.array(finite.astype(np.int32), dtype=wp.int32, device=d),
                wp.array(embedding, dtype=wp.float32, device=d), records, wp.zeros(w, dtype=wp.float32, device=d),
                wp.array(live.astype(np.int32), dtype=wp.int32, device=d), wp.array(goals, dtype=wp.vec3d, device=d),
                task.params, task._held, task._elapsed]
        wp.launch(evaluate_worlds, dim=w, inputs=args, outputs=[task.outputs], device=d)
        task._host = None
        got = task.result()
        for name, value in want.items():
            if name in FLAGS or name == "elapsed":
                np.testing.assert_array_equal(got[name], value, err_msg=name)
            else:
                np.testing.assert_allclose(got[name], value, rtol=RTOL, atol=ATOL, err_msg=name)
        np.testing.assert_array_equal(task._held.numpy(), held)
        assert got["grasp_quality"][0] == got["grasp_quality"][1] == 0.0  # NaN inputs: no hold quality
        assert not np.isnan(got["reward"][1:2]).any() and not got["sim_diverged"][1] ^ bool(live[1])
        seen = {name: seen[name] + int(want[name].sum()) for name in FLAGS}
    # the regimes were all visited: every flag both set and clear, holds of every quality
    if not terminate:  # successes go on: none terminates
        assert seen.pop("terminated") == 0 and seen["is_success"] > 0
    assert all(0 < count < steps * w for count in seen.values()), seen
    assert (want["grasp_quality"] > 0.5).any() and ((want["grasp_quality"] > 0) & (want["grasp_quality"] < 0.5)).any()
    # the force term free, partial and full: wrist forces below 50 N, between, and beyond 150 N
    force = want["reward_force"][live & ~want["sim_diverged"]]  # the valid worlds of the last step
    assert (force == 0).any() and ((force < 0) & (force > -1)).any() and (force == -1).any()


def test_device_observations_are_the_states_copies():
    """``observe_worlds``: the agent_pos and environment_state columns are the float64 state
    (flange pose by ``fk_analytic``), rounded to float32 once."""
    w = 50
    rng = np.random.default_rng(3)
    config = PickupConfig()
    task = PickupTask(config, w)
    q = np.column_stack([rng.uniform(-0.2, 0.2, (w, 3)), rng.uniform(-3, 3, (w, 3))])
    gap, tip = rng.uniform(0, 0.085, w), rng.uniform(0, 30, (w, 2))
    feature, velocity = rng.normal(size=(w, 3)), rng.normal(size=(w, 3))
    keypoints = rng.normal(size=(w * NUM_KEYPOINTS, 3)).astype(np.float32)
    goals = rng.uniform(0.05, 0.6, (w, 3))
    d = "cpu"
    wp.launch(observe_worlds, dim=w, inputs=[wp.array(q, dtype=gk.vec6d, device=d), wp.array(gap, dtype=wp.float64, device=d),
                                             wp.array(tip, dtype=wp.vec2d, device=d), wp.array(feature, dtype=wp.vec3d, device=d),
                                             wp.array(velocity, dtype=wp.vec3d, device=d),
                                             wp.array(keypoints, dtype=wp.vec3, device=d), wp.array(goals, dtype=wp.vec3d, device=d),
                                             task.params],
              outputs=[task.outputs], device=d)
    obs = task.observations()
    pos, quat = fk_analytic(q)
    want_agent = AGENT_POS.pack(wrist_position=pos, wrist_quat=quat, jaw_gap=gap[:, None], tip_normal_force=tip)
    want_env = ENV_STATE.pack(feature_position=feature, feature_velocity=velocity,
                              goal=goals, keypoints=keypoints.reshape(w, -1))
    np.testing.assert_allclose(obs["agent_pos"], want_agent.astype(np.float32), rtol=0, atol=np.float32(1e-7))
    np.testing.assert_array_equal(obs["environment_state"], want_env.astype(np.float32))
    # the orientation's float64 may differ from numpy's in the last bit (sin / cos): the rest is exact
    keep = np.r_[0:3, 7:10]
    np.testing.assert_array_equal(obs["agent_pos"][:, keep], want_agent[:, keep].astype(np.float32))
    assert OUTPUT_COLUMNS[:AGENT_POS.size + ENV_STATE.size] == (*AGENT_POS.names, *ENV_STATE.names)
    assert len(OUTPUT_COLUMNS) == AGENT_POS.size + ENV_STATE.size + len(RESULT_COLUMNS)
    assert len(set(RESULT_COLUMNS)) == len(RESULT_COLUMNS)  # (the info's gap and tip forces repeat agent_pos's)


def test_vector_env_outputs_follow_the_numpy_rules_along_episodes_with_autoresets():
    """Four worlds (two objects) with random actions, episodes of 6 steps (autoresets every
    seventh step): every step's reward, terms and flags against the numpy rules applied to the
    scene's host readouts, the gripper's numpy state and the step's solver report; each world's
    goal drawn per episode (``goal_noise``) as the reset info reports it."""
    n = 4
    venv = gym.make_vec("DeformablePickup-v0", num_envs=n, vectorization_mode="vector_entry_point",
                        object=("cuboid", "torus"), youngs_modulus=1e5, max_episode_steps=6,
                        goal=(0.0, 0.3, 0.0), goal_noise=(0.1, 0.25, 0.1))
    env = venv.unwrapped
    obs, reset_info = venv.reset(seed=11)
    goals = reset_info["goal"].copy()
    rng = np.random.default_rng(11)
    held, elapsed = np.zeros(n, int), np.zeros(n, int)
    resets_seen = 0
    done = np.zeros(n, bool)
    for k in range(16):
        live = ~done  # next-step autoreset: the worlds that ended last step are reset by this one
        action = rng.uniform(-1, 1, (n, 7)).astype(np.float32)
        action[:, 1] = -1.0  # down onto the objects: contact, forces
        obs, reward, terminated, truncated, info = venv.step(action)
        scene, report = env.scene, env.scene.solve_report.records.numpy()  # the step's solver report
        done = terminated | truncated
        if "_goal" in info:  # the worlds reset by this step drew new goals
            goals[info["_goal"]] = info["goal"][info["_goal"]]
            assert info["_goal"].tolist() == (~live).tolist()
        np.testing.assert_array_equal(ENV_STATE.get(obs["environment_state"], "goal"), goals.astype(np.float32))
        if not live.all():
            # the reset worlds' readouts are now those of their new episode: this step is not
            # compared; the others' counters advance (no world is at the goal with random actions)
            assert not np.any(info["is_success"])
            resets_seen += 1
            held[:], elapsed[~live] = 0, 0
            elapsed[live] += 1
            continue
        r = scene.readout()
        g = scene.gripper
        want, held = reference(g.q, g.gap, g.tip_force, g.pad_force, r.feature_position, r.finite, r.pad_embedding,
                               report["penetration"], report["diverged"] != 0, live, held, elapsed, goals, env.config,
                               env.task.hold_steps, 6)
        elapsed = want["elapsed"]
        np.testing.assert_allclose(reward, want["reward"], rtol=RTOL, atol=ATOL)
        for name in REWARD_TERMS:
            np.testing.assert_allclose(info[f"reward_{name}"], want[f"reward_{name}"], rtol=RTOL, atol=ATOL)
        np.testing.assert_array_equal(terminated, want["terminated"])
        np.testing.assert_array_equal(truncated, want["truncated"])
        for name in ("is_success", "grasped", "pierced", "sim_diverged"):
            np.testing.assert_array_equal(info[name], want[name], err_msg=name)
        for name in ("goal_distance", "grasp_quality", "wrist_force", "jaw_gap", "pad_embedding"):
            np.testing.assert_allclose(info[name], want[name], rtol=RTOL, atol=ATOL, err_msg=name)
        pos, quat = fk_analytic(g.q)
        np.testing.assert_array_equal(obs["agent_pos"][:, :3], pos.astype(np.float32))
        np.testing.assert_array_equal(obs["environment_state"][:, :3], r.feature_position.astype(np.float32))
        np.testing.assert_array_equal(info["mean_von_mises"], scene.state.mean_von_mises.numpy().astype(np.float64))
    assert resets_seen >= 2 and column("reward") == AGENT_POS.size + ENV_STATE.size
    assert len(np.unique(goals[:, 1])) == n  # the goals were drawn (no two alike)


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=pytest.mark.cuda)])
def test_torch_outputs_equal_the_numpy_outputs(device):
    """``torch_outputs=True``: observations, reward, terminated and truncated as torch tensors on
    the simulation's device equal the same step's outputs downloaded to numpy (the reward rounded
    to float32), and on the CPU (bit-deterministic) what a numpy env returns for the same seeds and
    actions; actions may be given as a torch tensor. (On CUDA two runs differ in float-atomic
    rounding, so only the one env's two readings are compared there.)"""
    torch = pytest.importorskip("torch")
    envs = [gym.make_vec("DeformablePickup-v0", num_envs=3, vectorization_mode="vector_entry_point", device=device,
                         torch_outputs=flag, max_episode_steps=3) for flag in (True, False)]
    (obs_t, _), (obs_np, _) = (e.reset(seed=5) for e in envs)
    rng = np.random.default_rng(5)
    ended = False
    for k in range(5):
        action = rng.uniform(-1, 1, (3, 7)).astype(np.float32)
        obs_t, reward, terminated, truncated, info = envs[0].step(torch.as_tensor(action, device=device))
        task = envs[0].unwrapped.task
        want = {**task.observations(), "reward": task.result()["reward"].astype(np.float32),
                "terminated": task.result()["terminated"], "truncated": task.result()["truncated"]}
        got = {**obs_t, "reward": reward, "terminated": terminated, "truncated": truncated}
        for key, value in got.items():
            assert isinstance(value, torch.Tensor) and value.device.type == torch.device(device).type, key
            np.testing.assert_array_equal(value.cpu().numpy(), want[key], err_msg=key)
        assert obs_t["agent_pos"].dtype == torch.float32 and terminated.dtype == torch.bool
        out_np = envs[1].step(action)
        if device == "cpu":
            for key in obs_t:
                np.testing.assert_array_equal(obs_t[key].numpy(), out_np[0][key])
            np.testing.assert_array_equal(reward.numpy(), out_np[1].astype(np.float32))
            np.testing.assert_array_equal(info["grasp_quality"], out_np[4]["grasp_quality"])
        ended |= bool(truncated.all())
    assert ended  # the episodes of 3 steps were truncated (and autoreset on the next step)


def test_torch_outputs_with_pixels():
    """``obs_type="pixels"`` with ``torch_outputs=True``: the pixels as a uint8 tensor on the
    simulation's device (no state observation to take the device from)."""
    torch = pytest.importorskip("torch")
    venv = gym.make_vec("DeformablePickup-v0", num_envs=2, vectorization_mode="vector_entry_point",
                        obs_type="pixels", torch_outputs=True)
    obs, _ = venv.reset(seed=0)
    obs, reward, *_ = venv.step(np.zeros((2, 7), np.float32))
    cam = venv.unwrapped.config.camera
    assert set(obs) == {"pixels"} and obs["pixels"].dtype == torch.uint8
    assert tuple(obs["pixels"].shape) == (2, cam.height, cam.width, 3) and reward.shape == (2,)


def test_a_rebuilt_scene_is_freed():
    """The task's and the action decoder's recorded launches are dropped when the scene they read is
    replaced (the single env builds a new scene for another object): the old scene's state is freed."""
    import gc
    import weakref

    env = gym.make("DeformablePickup-v0", object=("cuboid", "torus"))
    refs = []
    for name in ("cuboid", "torus", "cuboid"):
        env.reset(seed=0, options={"object": name})
        env.step(np.zeros(7, np.float32))
        refs.append(weakref.ref(env.unwrapped.scene.state.mean_von_mises))
    gc.collect()
    assert refs[0]() is None and refs[1]() is None and refs[2]() is not None


def test_max_episode_steps_changed_after_the_first_step_applies():
    venv = gym.make_vec("DeformablePickup-v0", num_envs=2, vectorization_mode="vector_entry_point", max_episode_steps=50)
    venv.reset(seed=0)
    venv.step(np.zeros((2, 7), np.float32))
    venv.unwrapped.max_episode_steps = 2
    truncated = venv.step(np.zeros((2, 7), np.float32))[3]
    assert truncated.all()
