"""Observations, reward terms, success and episode bookkeeping of the pickup task, batched over W."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from ..gripper import GAP_MAX
from .config import PickupConfig
from .scene import NUM_KEYPOINTS, PickupScene

AGENT_POS_NAMES = ("wrist_x", "wrist_y", "wrist_z", "wrist_qx", "wrist_qy", "wrist_qz", "wrist_qw",
                   "jaw_gap", "left_tip_normal_force", "right_tip_normal_force")
ENV_STATE_NAMES = (("feature_x", "feature_y", "feature_z", "feature_vx", "feature_vy", "feature_vz",
                    "goal_x", "goal_y", "goal_z")
                   + tuple(f"keypoint{k}_{a}" for k in range(NUM_KEYPOINTS) for a in "xyz"))
REWARD_TERMS = ("reach", "grasp", "lift", "success")
#: Both tip normal forces above this (N) count as a grasp.
GRASP_FORCE = 0.5
#: Deepest pad/ground penetration (m) beyond which the object counts as pierced.
PIERCE_DEPTH = 0.005


def observation_spaces(config: PickupConfig) -> spaces.Dict:
    """Observation space of one world."""
    inf = np.inf
    entries = {}
    if config.obs_type in ("state", "pixels_agent_pos"):
        entries["agent_pos"] = spaces.Box(-inf, inf, (len(AGENT_POS_NAMES),), np.float32)
    if config.obs_type == "state":
        entries["environment_state"] = spaces.Box(-inf, inf, (len(ENV_STATE_NAMES),), np.float32)
    if config.obs_type in ("pixels", "pixels_agent_pos"):
        cam = config.camera
        entries["pixels"] = spaces.Box(0, 255, (cam.height, cam.width, 3), np.uint8)
    return spaces.Dict(entries)


def action_space(config: PickupConfig) -> spaces.Box:
    """Action space of one world: delta mode [-1, 1]^7; absolute mode pos(3) m, quat xyzw(4), gap(1) m."""
    if config.action_mode == "delta":
        return spaces.Box(-1.0, 1.0, (7,), np.float32)
    low = np.array([-0.4, 0.0, -0.4, -1, -1, -1, -1, 0.0], np.float32)
    high = np.array([0.4, 1.0, 0.4, 1, 1, 1, 1, GAP_MAX], np.float32)
    return spaces.Box(low, high, (8,), np.float32)


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
        pos, quat = scene.flange_pose()
        return np.concatenate([pos, quat, scene.gap[:, None], scene.tip_force], axis=1).astype(np.float32)

    def environment_state(self, scene: PickupScene) -> np.ndarray:
        feat, vel = scene.feature_points()
        goal = np.broadcast_to(self.goal, feat.shape)
        keys = scene.keypoint_positions().reshape(scene.num_worlds, -1)
        return np.concatenate([feat, vel, goal, keys], axis=1).astype(np.float32)

    def evaluate(self, scene: PickupScene, stats, valid: np.ndarray) -> dict[str, np.ndarray]:
        """Reward terms [W] each, total reward, success/termination flags, after a step."""
        feat, _ = scene.feature_points()
        tcp = scene.tcp_positions()
        reach_dist = np.linalg.norm(tcp - feat, axis=1)
        goal_dist = np.linalg.norm(feat - self.goal, axis=1)
        grasped = np.all(scene.tip_force > GRASP_FORCE, axis=1)
        pierced = stats.penetration > PIERCE_DEPTH
        at_goal = (goal_dist < self.config.success_tolerance) & grasped & ~pierced & valid
        self.held = np.where(at_goal, self.held + 1, 0)
        self.elapsed += 1
        success = self.held >= max(self.hold_steps, 1)
        lift_progress = 1.0 - np.tanh(5.0 * goal_dist)
        terms = {
            "reach": (1.0 - np.tanh(10.0 * reach_dist)) * 0.5,
            "grasp": 0.5 * grasped,
            "lift": grasped * lift_progress * 2.0,
            "success": 10.0 * success,
        }
        reward = np.zeros(scene.num_worlds)
        for name in REWARD_TERMS:
            terms[name] = np.where(valid, terms[name], 0.0)
            reward = reward + terms[name]
        return {"reward": reward, "terms": terms, "is_success": success, "grasped": grasped,
                "pierced": pierced, "goal_distance": goal_dist}
