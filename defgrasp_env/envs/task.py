"""Observations, reward terms, success and episode bookkeeping of the pickup task, batched over W."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from ..layout import ACTION_LAYOUTS, AGENT_POS, ENV_STATE, VectorLayout
from .config import PickupConfig
from .scene import PickupScene

REWARD_TERMS = ("reach", "grasp", "lift", "place", "success")
#: Both tip normal forces above this (N) count as a grasp.
GRASP_FORCE = 0.5
#: Deepest penetration (m) beyond which the object counts as pierced: of a node in a pad or the
#: ground, or of the object's material in a pad (``PickupScene.pad_embedding``: a pad sunk in
#: between surface nodes or pushed into the object).
PIERCE_DEPTH = 0.005
#: Distance scales (1/m) of the shaped reach and lift terms, ``1 - tanh(scale * distance)``: each
#: term must still rise over the whole distance a learner covers, the reach from the start pose
#: (~0.1-0.2 m) and the lift from the ground to the goal (0.58 m). With the earlier 10/m and 5/m the
#: lift term was flat below 0.3 m (0.01 on the ground, rising ~0.2 per m over the first 10 cm).
REACH_SCALE = 5.0
LIFT_SCALE = 2.0
#: Distance scale (1/m) of the place term ``1 - tanh(scale * |feature - goal|)``: a sharp maximum at
#: the goal on top of the broad lift term. With the lift term alone (4 per m at the goal) a PPO policy
#: learned to lift the cuboid through the goal at full speed to the wrist's upper limit and never
#: held it there for ``success_hold_seconds`` (2.9 M steps, benchmarks/RESULTS.md); ManiSkill's pick
#: tasks shape their place reward with 5/m over a goal 0.1-0.3 m away.
PLACE_SCALE = 10.0


def shaped_progress(distance: np.ndarray, scale: float) -> np.ndarray:
    """Dense progress in (0, 1]: ``1 - tanh(scale * distance)`` (distance m, scale 1/m), 1 at 0."""
    return 1.0 - np.tanh(scale * np.asarray(distance, np.float64))


def _box(layout: VectorLayout) -> spaces.Box:
    """float32 Box of a layout's bounds."""
    low, high = layout.bounds()
    return spaces.Box(low.astype(np.float32), high.astype(np.float32), (layout.size,), np.float32)


def observation_spaces(config: PickupConfig) -> spaces.Dict:
    """Observation space of one world (bounds from ``defgrasp_env.layout``)."""
    entries = {}
    if config.obs_type in ("state", "pixels_agent_pos"):
        entries["agent_pos"] = _box(AGENT_POS)
    if config.obs_type == "state":
        entries["environment_state"] = _box(ENV_STATE)
    if config.obs_type in ("pixels", "pixels_agent_pos"):
        cam = config.camera
        entries["pixels"] = spaces.Box(0, 255, (cam.height, cam.width, 3), np.uint8)
    return spaces.Dict(entries)


def action_space(config: PickupConfig) -> spaces.Box:
    """Action space of one world: ``DELTA_ACTION`` [-1, 1]^7 or ``ABSOLUTE_ACTION`` (pos(3) m, quat
    xyzw(4), gap(1) m), see ``defgrasp_env.layout``."""
    return _box(ACTION_LAYOUTS[config.action_mode])


class PickupTask:
    """Reward, success and termination logic over the worlds of a ``PickupScene``."""

    def __init__(self, config: PickupConfig, num_worlds: int):
        self.config = config
        self.goal = np.asarray(config.goal, dtype=np.float64)
        self.hold_steps = int(round(config.success_hold_seconds * config.control_hz))
        self.held = np.zeros(num_worlds, int)
        self.elapsed = np.zeros(num_worlds, int)

    def reset(self, mask: np.ndarray) -> None:
        self.held[mask] = 0
        self.elapsed[mask] = 0

    def agent_pos(self, scene: PickupScene) -> np.ndarray:
        gripper = scene.gripper
        pos, quat = gripper.flange_pose()
        return AGENT_POS.pack(wrist_position=pos, wrist_quat=quat, jaw_gap=gripper.gap[:, None],
                              tip_normal_force=gripper.tip_force).astype(np.float32)

    def environment_state(self, scene: PickupScene) -> np.ndarray:
        feat, vel = scene.feature_points()
        goal = np.broadcast_to(self.goal, feat.shape)
        keys = scene.keypoint_positions().reshape(scene.num_worlds, -1)
        return ENV_STATE.pack(feature_position=feat, feature_velocity=vel, goal=goal, keypoints=keys).astype(np.float32)

    def evaluate(self, scene: PickupScene, stats, valid: np.ndarray) -> dict[str, np.ndarray]:
        """Reward terms [W] each, total reward, success/termination flags, after a step."""
        feat, _ = scene.feature_points()
        tcp = scene.gripper.tcp_positions()
        reach_dist = np.linalg.norm(tcp - feat, axis=1)
        goal_dist = np.linalg.norm(feat - self.goal, axis=1)
        grasped = np.all(scene.gripper.tip_force > GRASP_FORCE, axis=1)
        embedding = scene.pad_embedding()
        pierced = (stats.penetration > PIERCE_DEPTH) | (embedding > PIERCE_DEPTH)
        at_goal = (goal_dist < self.config.success_tolerance) & grasped & ~pierced & valid
        self.held = np.where(at_goal, self.held + 1, 0)
        self.elapsed += 1
        success = self.held >= max(self.hold_steps, 1)
        lift_progress = shaped_progress(goal_dist, LIFT_SCALE)
        terms = {
            "reach": shaped_progress(reach_dist, REACH_SCALE) * 0.5,
            "grasp": 0.5 * grasped,
            "lift": grasped * lift_progress * 2.0,
            "place": grasped * shaped_progress(goal_dist, PLACE_SCALE),
            "success": 10.0 * success,
        }
        reward = np.zeros(scene.num_worlds)
        for name in REWARD_TERMS:
            terms[name] = np.where(valid, terms[name], 0.0)
            reward = reward + terms[name]
        return {"reward": reward, "terms": terms, "is_success": success, "grasped": grasped,
                "pierced": pierced, "goal_distance": goal_dist, "pad_embedding": embedding}
