"""Observations, reward terms, success and episode bookkeeping of the pickup task, batched over W."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from ..gripper import PAD_BOX_HALF_EXTENTS
from ..layout import ACTION_LAYOUTS, AGENT_POS, ENV_STATE, VectorLayout
from ..transforms import quat_to_matrix
from .config import PickupConfig
from .scene import PickupScene

REWARD_TERMS = ("reach", "grasp", "lift", "place", "success")
#: Both tip normal forces above this (N) count as a grasp.
GRASP_FORCE = 0.5
#: Deepest penetration (m) beyond which the object counts as pierced: of a node in a pad or the
#: ground, of a pad's edge inside the object beyond the 0.5 mm skin (``SolveStats.penetration``),
#: or of the object's material in a pad (``PickupScene.pad_embedding``: a pad sunk in between
#: surface nodes or pushed into the object).
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


#: Distance scale (1/m) of the grasp quality's centring factor ``1 - tanh(scale * beyond)`` (beyond:
#: how far the object's feature point lies outside the pad faces across their width): 0.86 at 2 mm,
#: 0.60 at 6 mm, 0.12 at 20 mm. The scripted expert's holds of all five objects read 0 mm; PPO's
#: failed cuboid holds (pads pinching the cube's edge beside it, pressing down at the wrist's force
#: limit) 16-22 mm, its successes 6-8 mm (benchmarks/RESULTS.md, 2026-11-26).
CENTRE_SCALE = 70.0


def grasp_quality(pad_force_angles: np.ndarray, pad_friction: float, beyond_pad_faces: np.ndarray) -> np.ndarray:
    """[W] in [0, 1]: how sound a hold is, the product of two factors, 1 for the scripted expert's
    antipodal, centred holds:

    * the friction-cone margin of the worse pad, ``(cos(angle) - cos(cone)) / (1 - cos(cone))``
      clipped to [0, 1], cone = atan(``pad_friction``): 1 where both pads are pushed straight out
      along the closing axis, 0 where a pad's force lies on the cone (held by friction alone: it
      slips on any further load, as a wedge squeezed out between the pads does);
      ``pad_force_angles`` [W, 2] rad (``Gripper.pad_force_angles``). ManiSkill's ``is_grasping``
      gates its grasps on the same angle (at a fixed 85 degrees);
    * the centring ``1 - tanh(CENTRE_SCALE * beyond_pad_faces[:, 1])``: ``beyond_pad_faces`` [W, 2]
      m (``feature_beyond_pad_faces``: along the pads' length, across their width), 1 where the
      object's feature point lies within the pad faces' width: an object held beside its centre
      (pinched at an edge) reads less. Along the pads' length it is not counted: a soft object held
      near its top, or a torus held by its rim, hangs below the pads (the expert's soft torus: 10 mm).
    """
    cone = np.cos(np.arctan(pad_friction))
    worst = np.cos(np.max(pad_force_angles, axis=1))
    if cone >= 1.0:  # frictionless pads: only a force straight along the closing axis holds
        margin = (worst >= 1.0).astype(np.float64)
    else:
        margin = np.clip((worst - cone) / (1.0 - cone), 0.0, 1.0)
    return margin * shaped_progress(beyond_pad_faces[:, 1], CENTRE_SCALE)


def feature_beyond_pad_faces(feature: np.ndarray, pad_positions: np.ndarray, pad_quats: np.ndarray) -> np.ndarray:
    """[W, 2] m: how far each world's feature point ``feature`` [W, 3] (m, world) lies beyond the
    rectangle of the pad faces, along the pads' length (finger direction) and width, the larger of
    the pads; 0 where it lies between the faces. Pad box centres ``pad_positions`` [W, P, 3] m and
    orientations ``pad_quats`` [W, P, 4] xyzw (world; ``Gripper.pad_poses``). A hold whose feature
    point lies beyond the faces holds the object off its centre: a prism gripped across its width
    near its top (a sound grasp), or, with a jaw gap below the object's width there, on the pads'
    edges or corners (a sphere pinched above its equator, a cube across an edge). The scripted
    expert's holds read 0 across the width for all five objects (the torus's rim lies along the
    closing axis, which is not counted; a soft torus hangs ~10 mm below the pads' length)."""
    half = np.asarray(PAD_BOX_HALF_EXTENTS, np.float64)[1:]  # length, width (x: the closing axis)
    # the feature point in each pad's frame: R^T (feature - pad centre), [W, P, 3]
    rot = quat_to_matrix(np.asarray(pad_quats, np.float64))
    offset = np.asarray(feature, np.float64)[:, None, :] - np.asarray(pad_positions, np.float64)
    local = np.einsum("wpji,wpj->wpi", rot, offset)
    return np.maximum(np.abs(local[..., 1:]) - half, 0.0).max(axis=1)


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
    """Action space of one world: ``DELTA_ACTION`` [-1, 1]^7, ``ABSOLUTE_ACTION`` (pos(3) m, quat
    xyzw(4), gap(1) m) or ``TOPDOWN_ACTION`` (velocity(3) in [-1, 1], yaw(1) rad, jaw(1) in [-1, 1]),
    see ``defgrasp_env.layout``."""
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
        pad_pos, pad_quat = scene.gripper.pad_poses()
        tcp = pad_pos.mean(axis=1)  # ``Gripper.tcp_positions`` of the same poses
        reach_dist = np.linalg.norm(tcp - feat, axis=1)
        goal_dist = np.linalg.norm(feat - self.goal, axis=1)
        grasped = np.all(scene.gripper.tip_force > GRASP_FORCE, axis=1)
        quality = grasp_quality(scene.gripper.pad_force_angles(), self.config.pad_friction,
                                feature_beyond_pad_faces(feat, pad_pos, pad_quat))
        # the hold's quality, 0 where nothing is held (or a diverged world's forces are not finite)
        held_well = np.where(grasped & np.isfinite(quality), quality, 0.0)
        embedding = scene.pad_embedding()
        pierced = (stats.penetration > PIERCE_DEPTH) | (embedding > PIERCE_DEPTH)
        at_goal = (goal_dist < self.config.success_tolerance) & grasped & ~pierced & valid
        self.held = np.where(at_goal, self.held + 1, 0)
        self.elapsed += 1
        success = self.held >= max(self.hold_steps, 1)
        lift_progress = shaped_progress(goal_dist, LIFT_SCALE)
        terms = {
            "reach": shaped_progress(reach_dist, REACH_SCALE) * 0.5,
            "grasp": 0.5 * held_well,
            "lift": held_well * lift_progress * 2.0,
            "place": held_well * shaped_progress(goal_dist, PLACE_SCALE),
            "success": 10.0 * success,
        }
        reward = np.zeros(scene.num_worlds)
        for name in REWARD_TERMS:
            terms[name] = np.where(valid, terms[name], 0.0)
            reward = reward + terms[name]
        return {"reward": reward, "terms": terms, "is_success": success, "grasped": grasped, "grasp_quality": held_well,
                "pierced": pierced, "goal_distance": goal_dist, "pad_embedding": embedding}
