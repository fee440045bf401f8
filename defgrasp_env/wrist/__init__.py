"""Invisible 6-DOF wrist robot: base at the world origin, flange = gripper frame G.

q = (slide_x, slide_y, slide_z [m], roll_z, pitch_x, yaw_y [rad]); flange p = q[:3],
R = Rz(roll) Rx(pitch) Ry(yaw). See ``spec`` (joint table, limits, reachable set), ``analytic``
(closed-form FK/IK, numpy) and ``kinematics`` (pytorch-kinematics FK and iterative IK).
"""

from .analytic import IKResult, fk_analytic, fk_matrix_analytic, ik_analytic, ik_joints
from .spec import FLANGE_LINK, JOINT_LOWER, JOINT_NAMES, JOINT_UPPER, WRIST_URDF_PATH, clamp_joints

__all__ = [
    "FLANGE_LINK", "IKResult", "JOINT_LOWER", "JOINT_NAMES", "JOINT_UPPER", "WRIST_URDF_PATH",
    "WristKinematics", "clamp_joints", "fk_analytic", "fk_matrix_analytic", "ik_analytic",
    "ik_joints",
]


def __getattr__(name: str):
    # WristKinematics pulls in torch through pytorch-kinematics (seconds to import): load on first use
    if name == "WristKinematics":
        from .kinematics import WristKinematics

        return WristKinematics
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
