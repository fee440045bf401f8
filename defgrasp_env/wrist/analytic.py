"""Closed-form forward and inverse kinematics of the 6-DOF wrist (pure numpy, batched).

The three prismatic joints move the flange along the world axes and the three revolute axes all
pass through the flange origin, so position and orientation decouple:
``p = q[0:3]`` and ``R = Rz(q3) Rx(q4) Ry(q5)`` (see ``spec`` for the joint table).

Inverse orientation: with ``r = R[:, 1]`` (flange y axis in the world)
``r = (-sin q3 cos q4, cos q3 cos q4, sin q4)``, hence ``q4 = asin(r_z)``,
``q3 = atan2(-r_x, r_y)`` and ``q5`` from ``Ry(q5) = (Rz(q3) Rx(q4))^T R``. At the gimbal lock
(``cos q4 = 0``) ``q3`` is set to 0. For unreachable targets the joints are clamped to the limits
and ``q5`` is the yaw that minimises the remaining rotation error for the clamped ``q3, q4``;
the result reports the residual errors and ``converged = False``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..transforms import matrix_to_quat, quat_angle_between, quat_to_matrix
from .spec import JOINT_LOWER, JOINT_UPPER

__all__ = ["IKResult", "rot_x", "rot_y", "rot_z", "fk_matrix_analytic", "fk_analytic", "ik_analytic", "ik_joints", "pose_errors"]


class IKResult(NamedTuple):
    """Result of an inverse-kinematics solve over a batch of targets ``[...]``.

    Attributes:
        q: [..., 6] joint values within the limits (m, m, m, rad, rad, rad), float64.
        pos_err_m: [...] distance (m) between FK(q) flange position and the target.
        rot_err_rad: [...] geodesic angle (rad) between FK(q) flange orientation and the target.
        converged: [...] bool, ``pos_err_m < pos_tolerance & rot_err_rad < rot_tolerance``.
    """

    q: np.ndarray
    pos_err_m: np.ndarray
    rot_err_rad: np.ndarray
    converged: np.ndarray


def _elementary(angle, i: int, j: int) -> np.ndarray:
    """Rotation [..., 3, 3] by ``angle`` in the (i, j) coordinate plane (i -> j positive)."""
    a = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    k = 3 - i - j
    R[..., k, k] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., j, i] = s
    R[..., i, j] = -s
    return R


def rot_x(angle) -> np.ndarray:
    """Rotation matrices [..., 3, 3] about x by ``angle`` (rad, right-hand rule)."""
    return _elementary(angle, 1, 2)


def rot_y(angle) -> np.ndarray:
    """Rotation matrices [..., 3, 3] about y by ``angle`` (rad, right-hand rule)."""
    return _elementary(angle, 2, 0)


def rot_z(angle) -> np.ndarray:
    """Rotation matrices [..., 3, 3] about z by ``angle`` (rad, right-hand rule)."""
    return _elementary(angle, 0, 1)


def _joints(q) -> np.ndarray:
    a = np.asarray(q, dtype=np.float64)
    if a.ndim < 1 or a.shape[-1] != 6:
        raise ValueError(f"q must have shape [..., 6], got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("q must be finite")
    return a


def fk_matrix_analytic(q) -> np.ndarray:
    """World pose of the flange frame G, ``T_world_G [..., 4, 4]``, for joints ``q [..., 6]``.

    Joint values are used as given (not clamped), so callers can evaluate any configuration.
    """
    a = _joints(q)
    T = np.zeros(a.shape[:-1] + (4, 4))
    T[..., :3, :3] = rot_z(a[..., 3]) @ rot_x(a[..., 4]) @ rot_y(a[..., 5])
    T[..., :3, 3] = a[..., :3]
    T[..., 3, 3] = 1.0
    return T


def fk_analytic(q) -> tuple[np.ndarray, np.ndarray]:
    """Flange ``(position [..., 3] m, quaternion [..., 4] xyzw, w >= 0)`` in the world for ``q [..., 6]``.

    The orientation Rz(q3) Rx(q4) Ry(q5) as the product of the three axis quaternions, in closed form.
    """
    a = _joints(q)
    half = 0.5 * a[..., 3:]
    c, s = np.cos(half), np.sin(half)
    cz, cx, cy = c[..., 0], c[..., 1], c[..., 2]
    sz, sx, sy = s[..., 0], s[..., 1], s[..., 2]
    p0, p1, p2, p3 = cz * sx, sz * sx, cx * sz, cz * cx           # q_z * q_x
    quat = np.stack([cy * p0 - sy * p2, cy * p1 + sy * p3, cy * p2 + sy * p0, cy * p3 - sy * p1], axis=-1)
    return a[..., :3].copy(), np.where(quat[..., 3:4] < 0.0, -quat, quat)


def pose_errors(q, target_pos, target_quat) -> tuple[np.ndarray, np.ndarray]:
    """``(pos_err_m [...], rot_err_rad [...])`` of FK(q) w.r.t. targets (all broadcast)."""
    pos, quat = fk_analytic(q)
    return (
        np.linalg.norm(pos - np.asarray(target_pos, dtype=np.float64), axis=-1),
        quat_angle_between(quat, target_quat),
    )


def _ik_targets(target_pos, target_quat) -> tuple[np.ndarray, np.ndarray]:
    """Validated targets broadcast to one batch: positions [..., 3] m, rotation matrices [..., 3, 3]."""
    p = np.asarray(target_pos, dtype=np.float64)
    if p.ndim < 1 or p.shape[-1] != 3 or not np.all(np.isfinite(p)):
        raise ValueError(f"target_pos must be a finite array of shape [..., 3], got shape {p.shape}")
    R = quat_to_matrix(target_quat)  # validates the quaternion
    batch = np.broadcast_shapes(p.shape[:-1], R.shape[:-2])
    return np.broadcast_to(p, batch + (3,)), np.broadcast_to(R, batch + (3, 3))


def _ik_solve(p: np.ndarray, R: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Joints [..., 6] (clamped to ``lower``/``upper``) for flange positions p [..., 3] and rotations R [..., 3, 3]."""
    r = R[..., :, 1]  # flange y axis in the world
    pitch = np.arcsin(np.clip(r[..., 2], -1.0, 1.0))
    locked = np.hypot(r[..., 0], r[..., 1]) < 1e-9
    roll = np.where(locked, 0.0, np.arctan2(-r[..., 0], r[..., 1]))
    roll = np.clip(roll, lower[3], upper[3])
    pitch = np.clip(pitch, lower[4], upper[4])
    # remaining rotation about y; atan2 of the y-rotation part is the least-squares yaw
    M = np.swapaxes(rot_z(roll) @ rot_x(pitch), -1, -2) @ R
    yaw = np.arctan2(M[..., 0, 2] - M[..., 2, 0], M[..., 0, 0] + M[..., 2, 2])
    return np.clip(np.concatenate([p, roll[..., None], pitch[..., None], yaw[..., None]], axis=-1), lower, upper)


def ik_joints(target_pos, target_quat, *, lower=JOINT_LOWER, upper=JOINT_UPPER) -> np.ndarray:
    """``ik_analytic(...).q`` (the same values, float64 [..., 6]) without its residual errors: for
    callers that only move the wrist (a control step), at half the cost."""
    p, R = _ik_targets(target_pos, target_quat)
    return _ik_solve(p, R, np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64))


def ik_analytic(
    target_pos,
    target_quat,
    *,
    pos_tolerance: float = 1e-4,
    rot_tolerance: float = 1e-3,
    lower=JOINT_LOWER,
    upper=JOINT_UPPER,
) -> IKResult:
    """Exact IK for flange targets ``target_pos [..., 3]`` (m) and ``target_quat [..., 4]`` (xyzw).

    Leading dimensions broadcast. Reachable targets (position inside the prismatic limits, flange
    y axis with world-y component >= 0) are solved to machine precision; others are clamped to the
    joint limits and flagged ``converged = False`` with their residual errors. ``lower``/``upper``
    [6] default to the packaged URDF's limits (roll and pitch limits must lie within [-pi/2, pi/2]).
    """
    p, R = _ik_targets(target_pos, target_quat)
    q = _ik_solve(p, R, np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64))
    pos_err, rot_err = pose_errors(q, p, matrix_to_quat(R))
    return IKResult(q, pos_err, rot_err, (pos_err < pos_tolerance) & (rot_err < rot_tolerance))
