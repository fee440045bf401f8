"""Retargeting of the operator's motion to the gripper (paper eq. 1-4) and command smoothing.

``offset`` (eq. 1-2) and ``smoothing`` are numpy only; ``pinch`` (eq. 4, pytorch-kinematics),
``wrist_ik`` (eq. 3, ``defgrasp_env.wrist``) and ``gripper_ik`` (``defgrasp_env.gripper``) load
their dependencies when used.
"""

from .hand_urdf import FingerGeometry, HandGeometry, hand_urdf
from .offset import OPENVR_TO_WORLD, OffsetRetargeter, compose_slave_pose
from .pinch import FingerKinematics, PinchGapMap, PinchResult, PinchRetargeter, pinch_distance
from .smoothing import (
    Command, CommandFilter, GateEvent, LossGate, RateLimits, WorkspaceBox, limit_rotation, limit_scalar,
    limit_translation,
)
from .wrist_ik import WristIK, WristIKResult

__all__ = [
    "Command", "CommandFilter", "FingerGeometry", "FingerKinematics", "GateEvent", "HandGeometry",
    "LossGate", "OPENVR_TO_WORLD", "OffsetRetargeter", "PinchGapMap", "PinchResult", "PinchRetargeter",
    "RateLimits", "WorkspaceBox", "WristIK", "WristIKResult", "compose_slave_pose", "hand_urdf",
    "limit_rotation", "limit_scalar", "limit_translation", "pinch_distance",
]
