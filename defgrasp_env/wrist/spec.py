"""Joint layout and limits of the invisible 6-DOF wrist, read from ``assets/wrist_6dof.urdf``.

The URDF is the single source of truth for the limits; this module parses it with the standard
library (no pytorch-kinematics) and checks that it has the structure the closed-form kinematics in
``analytic`` assumes.

Joint vector ``q [..., 6]`` (SI units: m for the first three, rad for the last three):

====  ===========  =========================================  ==================
idx   name         motion                                     limits
====  ===========  =========================================  ==================
0     ``slide_x``  flange x, along world x (m)                [-0.4, 0.4]
1     ``slide_y``  flange height, along world y (m)           [0.0, 1.0]
2     ``slide_z``  flange z, along world z (m)                [-0.4, 0.4]
3     ``roll_z``   rotation about world z (rad)               [-pi/2, pi/2]
4     ``pitch_x``  rotation about the rolled x axis (rad)     [-pi/2, pi/2]
5     ``yaw_y``    rotation about flange y = approach axis    [-pi, pi]
====  ===========  =========================================  ==================

Flange pose: ``p = q[0:3]``, ``R = Rz(q3) Rx(q4) Ry(q5)`` (intrinsic z-x-y). At ``q = 0`` the
flange frame G equals the world frame, so the fingers (-y_G) point down at the ground.

Why this order: the usual top-down grasp has pitch = roll = 0, where the three rotation axes
(z, x, y) are orthogonal; the only gimbal lock is at pitch = +-pi/2 (approach horizontal), which is
the joint limit. (Yaw about world y first and roll about the approach axis last would be coaxial,
i.e. locked, exactly at the top-down pose.) With roll and pitch in [-pi/2, pi/2] the approach
direction -y_G covers the closed lower hemisphere: **reachable orientations are those whose flange
y axis has a world-y component >= 0** (the fingers never point upward); yaw covers a full turn.
"""

from __future__ import annotations

import pathlib
import xml.etree.ElementTree as ET

import numpy as np

__all__ = [
    "WRIST_URDF_PATH",
    "ROOT_LINK",
    "FLANGE_LINK",
    "JOINT_NAMES",
    "JOINT_TYPES",
    "JOINT_AXES",
    "JOINT_LOWER",
    "JOINT_UPPER",
    "clamp_joints",
    "load_joint_limits",
]

WRIST_URDF_PATH = pathlib.Path(__file__).resolve().parents[1] / "assets" / "wrist_6dof.urdf"
ROOT_LINK = "world"
FLANGE_LINK = "flange"
JOINT_NAMES = ("slide_x", "slide_y", "slide_z", "roll_z", "pitch_x", "yaw_y")
JOINT_TYPES = ("prismatic",) * 3 + ("revolute",) * 3
JOINT_AXES = ((1, 0, 0), (0, 1, 0), (0, 0, 1), (0, 0, 1), (1, 0, 0), (0, 1, 0))


def load_joint_limits(path: pathlib.Path) -> tuple[np.ndarray, np.ndarray]:
    """Parse a wrist URDF and return (lower [6], upper [6]); ValueError if its layout differs."""
    root = ET.parse(path).getroot()
    joints = {j.get("name"): j for j in root.findall("joint")}
    chain = [j.get("name") for j in root.findall("joint")]
    if tuple(chain) != JOINT_NAMES:
        raise ValueError(f"{path}: joints must be {JOINT_NAMES} in order, got {tuple(chain)}")
    lower, upper = [], []
    parent = ROOT_LINK
    for name, jtype, axis in zip(JOINT_NAMES, JOINT_TYPES, JOINT_AXES):
        j = joints[name]
        origin = j.find("origin")
        xyz = [float(v) for v in (origin.get("xyz", "0 0 0").split() if origin is not None else [0, 0, 0])]
        rpy = [float(v) for v in (origin.get("rpy", "0 0 0").split() if origin is not None else [0, 0, 0])]
        ax = tuple(float(v) for v in j.find("axis").get("xyz").split())
        if j.get("type") != jtype or ax != axis or any(xyz) or any(rpy) or j.find("parent").get("link") != parent:
            raise ValueError(f"{path}: joint {name} must be {jtype} about {axis} at the flange origin")
        parent = j.find("child").get("link")
        lim = j.find("limit")
        lower.append(float(lim.get("lower")))
        upper.append(float(lim.get("upper")))
    if parent != FLANGE_LINK:
        raise ValueError(f"{path}: the last joint must end at link {FLANGE_LINK!r}, got {parent!r}")
    return np.array(lower), np.array(upper)


JOINT_LOWER, JOINT_UPPER = load_joint_limits(WRIST_URDF_PATH)
"""[6] joint limits (m, m, m, rad, rad, rad) from the URDF."""
JOINT_LOWER.setflags(write=False)
JOINT_UPPER.setflags(write=False)


def clamp_joints(q) -> np.ndarray:
    """Clip joint vectors ``q [..., 6]`` to ``[JOINT_LOWER, JOINT_UPPER]`` (float64 copy)."""
    a = np.asarray(q, dtype=np.float64)
    if a.shape[-1:] != (6,):
        raise ValueError(f"q must have shape [..., 6], got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("q must be finite")
    return np.clip(a, JOINT_LOWER, JOINT_UPPER)
