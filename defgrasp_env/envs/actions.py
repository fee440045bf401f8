"""Action checking and decoding: batched actions [W, A] (``defgrasp_env.layout``) -> the flange
position [W, 3] m, orientation [W, 4] xyzw and jaw-gap [W] m targets of one control period."""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from ..gripper import Gripper
from ..layout import ABSOLUTE_ACTION, ACTION_LAYOUTS, DELTA_ACTION, TOPDOWN_ACTION, jaw_command_to_gap
from ..sim.launch_cache import LaunchCache
from ..transforms import axis_angle_to_quat, quat_multiply, quat_normalize
from .action_kernels import TARGET_KERNELS, ActionScales
from .config import PickupConfig


def check_actions(actions, expected_shape: tuple[int, ...], space_low, space_high) -> np.ndarray:
    """Validate (shape, finiteness) and clip to the action space; returns float64 [W, A]."""
    a = np.asarray(actions, dtype=np.float64)
    if a.shape != expected_shape:
        raise ValueError(f"action must have shape {expected_shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"action must be finite, got {a.reshape(-1)[~np.isfinite(a.reshape(-1))][:3]} "
                         f"in {a.tolist()}")
    return np.clip(a, space_low, space_high)


def delta_targets(gripper: Gripper, config: PickupConfig, action: np.ndarray):
    """Targets for normalised delta actions [W, 7] (``DELTA_ACTION``): the flange moves by the
    velocities times ``dt`` from where it is; the jaw command decodes to a gap."""
    pos, quat = gripper.flange_pose()
    target_pos = pos + DELTA_ACTION.get(action, "linear_velocity") * config.max_linear_speed * config.dt
    dq = axis_angle_to_quat(DELTA_ACTION.get(action, "angular_velocity") * config.max_angular_speed * config.dt)
    target_quat = quat_normalize(quat_multiply(dq, quat))
    return target_pos, target_quat, jaw_command_to_gap(DELTA_ACTION.get(action, "jaw")[:, 0])


def check_absolute_orientations(action: np.ndarray) -> None:
    """ValueError where an absolute action's [W, 8] target quaternion is (near) zero (norm < 1e-6)."""
    quat = ABSOLUTE_ACTION.get(action, "orientation")
    norm = np.linalg.norm(quat, axis=1)
    if np.any(norm < 1e-6):
        raise ValueError(f"absolute action quaternion must be non-zero, got {quat[norm < 1e-6][0].tolist()}")


def absolute_targets(gripper: Gripper, config: PickupConfig, action: np.ndarray):
    """Targets for absolute actions [W, 8] (``ABSOLUTE_ACTION``): the flange moves toward the
    target pose no faster than the configured speeds; the gap is the commanded one."""
    check_absolute_orientations(action)
    target_quat = quat_normalize(ABSOLUTE_ACTION.get(action, "orientation"))
    pos, quat = gripper.flange_pose()
    d = ABSOLUTE_ACTION.get(action, "position") - pos
    dist = np.linalg.norm(d, axis=1, keepdims=True)
    step = np.minimum(1.0, config.max_linear_speed * config.dt / np.maximum(dist, 1e-12))
    return pos + d * step, turn_toward(quat, target_quat, config), ABSOLUTE_ACTION.get(action, "gap")[:, 0]


def turn_toward(quat: np.ndarray, target_quat: np.ndarray, config: PickupConfig) -> np.ndarray:
    """Orientations [W, 4] (xyzw) one control period from ``quat`` toward ``target_quat`` (both
    [W, 4] xyzw, world; the target unit length): the shortest way, no faster than
    ``max_angular_speed``."""
    rel = quat_multiply(target_quat, quat * np.array([-1, -1, -1, 1.0]))
    rel = np.where(rel[:, 3:4] < 0, -rel, rel)
    angle = 2 * np.arctan2(np.linalg.norm(rel[:, :3], axis=1), rel[:, 3])
    frac = np.minimum(1.0, config.max_angular_speed * config.dt / np.maximum(angle, 1e-12))
    axis = rel[:, :3] / np.maximum(np.linalg.norm(rel[:, :3], axis=1, keepdims=True), 1e-12)
    new_quat = quat_multiply(axis_angle_to_quat(axis * (angle * frac)[:, None]), quat)
    return quat_normalize(new_quat)


def topdown_targets(gripper: Gripper, config: PickupConfig, action: np.ndarray):
    """Targets for top-down actions [W, 5] (``TOPDOWN_ACTION``): the flange moves by the velocities
    times ``dt`` from where it is (as a delta action) and turns toward the flange-down orientation of
    the ``yaw`` (rad) about world +y no faster than ``max_angular_speed`` (as an absolute action,
    which also turns roll and pitch back to pointing down); the jaw command decodes to a gap."""
    pos, quat = gripper.flange_pose()
    target_pos = pos + TOPDOWN_ACTION.get(action, "linear_velocity") * config.max_linear_speed * config.dt
    yaw = TOPDOWN_ACTION.get(action, "yaw")[:, 0]
    target_quat = axis_angle_to_quat(np.stack([np.zeros_like(yaw), yaw, np.zeros_like(yaw)], axis=1))
    gap = jaw_command_to_gap(TOPDOWN_ACTION.get(action, "jaw")[:, 0])
    return target_pos, turn_toward(quat, target_quat, config), gap


#: Largest flange translation and rotation of one control period, in units of
#: (``max_linear_speed`` dt, ``max_angular_speed`` dt), per ``action_mode``: a delta velocity moves
#: each axis by up to the speed limit (a norm of up to sqrt 3 of it); an absolute move and a turn
#: toward a target orientation are rate-limited in norm.
STEP_NORM_FACTOR = {"delta": (math.sqrt(3.0), math.sqrt(3.0)), "absolute": (1.0, 1.0),
                    "topdown": (math.sqrt(3.0), 1.0)}


def max_flange_step(config: PickupConfig) -> tuple[float, float]:
    """Largest flange translation (m) and rotation (rad) one control period of ``config`` can make."""
    linear, angular = STEP_NORM_FACTOR[config.action_mode]
    return linear * config.max_linear_speed * config.dt, angular * config.max_angular_speed * config.dt


#: The decoder of each ``action_mode``.
DECODERS = {"delta": delta_targets, "absolute": absolute_targets, "topdown": topdown_targets}


def targets(gripper: Gripper, config: PickupConfig, actions: np.ndarray):
    """Flange position [W, 3], orientation [W, 4] and jaw-gap [W] targets for checked actions [W, A]
    of ``config.action_mode``."""
    return DECODERS[config.action_mode](gripper, config, actions)


class DeviceActionDecoder:
    """Decodes checked actions [W, A] of ``config.action_mode`` into the gripper's targets
    (``Gripper.targets``) on the simulation's device (``action_kernels``: the rules of the numpy
    decoders above, which stay the reference): one upload of the actions, one kernel launch."""

    def __init__(self, config: PickupConfig, num_worlds: int):
        self.mode = config.action_mode
        self.kernel = TARGET_KERNELS[config.action_mode]
        self.scales = ActionScales()
        self.scales.linear_speed = float(config.max_linear_speed)
        self.scales.angular_speed = float(config.max_angular_speed)
        self.scales.dt = float(config.dt)
        self.actions = wp.zeros((num_worlds, ACTION_LAYOUTS[config.action_mode].size), dtype=wp.float64,
                                device=config.device)
        self._launches = LaunchCache(self.actions.device)
        self._gripper: Gripper | None = None  # the gripper the record is bound to

    def decode(self, gripper: Gripper, actions: np.ndarray) -> None:
        """Write ``gripper.targets`` for checked actions [W, A] (float64, ``check_actions``)."""
        if self.mode == "absolute":
            check_absolute_orientations(actions)
        self.actions.assign(actions)
        targets = gripper.targets
        if gripper is not self._gripper:  # a new scene's gripper: no record keeps the old one alive
            self._launches, self._gripper = LaunchCache(self.actions.device), gripper
        self._launches.launch("decode", self.kernel, len(actions), [self.actions, gripper.arrays.q, self.scales],
                              [targets.position, targets.orientation, targets.gap])
