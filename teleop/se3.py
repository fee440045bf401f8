"""Rigid-transform helpers for the teleop package (numpy, float64, single poses).

Quaternion and pose basics come from ``defgrasp_env.transforms`` (scalar-last ``(x, y, z, w)``,
canonical ``w >= 0``); this module adds what teleop needs on top: slerp, elementary rotations,
re-orthonormalisation and a rigid-transform validator with clear messages. ``T_a_b`` (the pose of
b in a) maps coordinates in frame b to frame a.
"""

from __future__ import annotations

import numpy as np

from defgrasp_env.transforms import (  # noqa: F401  (re-exported)
    axis_angle_to_quat as rotvec_to_quat,
    matrix_to_pose,
    matrix_to_quat,
    pose_inverse as invert,
    pose_to_matrix,
    quat_angle_between,
    quat_multiply,
    quat_normalize,
    quat_to_matrix,
)
from defgrasp_env.wrist.analytic import rot_x, rot_y, rot_z  # noqa: F401  (re-exported)

from ._validate import check_array, check_number

__all__ = [
    "RIGID_TOL", "check_rigid", "homogeneous", "invert", "matrix_to_pose", "matrix_to_quat", "orthonormalize",
    "pose_to_matrix", "quat_angle", "quat_angle_between", "quat_multiply", "quat_normalize", "quat_slerp",
    "quat_to_matrix", "rot_x", "rot_y", "rot_z", "rotvec_to_quat",
]

#: tolerance on ||R^T R - I|| and |det R - 1| when a 4x4 is checked to be a rigid transform
RIGID_TOL = 1e-4


def quat_angle(a, b) -> float:
    """Angle in rad in [0, pi] of the rotation taking unit quaternion a to b."""
    return float(quat_angle_between(a, b))


def quat_slerp(a, b, t: float) -> np.ndarray:
    """Spherical interpolation from a (t=0) to b (t=1) along the shorter arc, (x, y, z, w)."""
    a = quat_normalize(a)
    b = quat_normalize(b)
    d = float(np.dot(a, b))
    if d < 0:
        b, d = -b, -d
    if d > 1.0 - 1e-12:
        return quat_normalize(a + t * (b - a))
    theta = np.arccos(min(1.0, d))
    return quat_normalize((np.sin((1 - t) * theta) * a + np.sin(t * theta) * b) / np.sin(theta))


def homogeneous(R=None, p=None) -> np.ndarray:
    """4x4 from a rotation (default identity) and a translation (default zero)."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if p is not None:
        T[:3, 3] = p
    return T


def orthonormalize(R) -> np.ndarray:
    """Nearest rotation matrix (SVD projection) of a nearly orthonormal 3x3."""
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=np.float64))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def check_rigid(name: str, T, tol: float = RIGID_TOL) -> np.ndarray:
    """Validate a 4x4 rigid transform (finite, orthonormal rotation, det +1, last row 0 0 0 1)."""
    T = check_array(name, T, (4, 4))
    check_number("tol", tol, 0.0, lo_open=True)
    R = T[:3, :3]
    ortho = float(np.max(np.abs(R.T @ R - np.eye(3))))
    det = float(np.linalg.det(R))
    if ortho > tol or abs(det - 1.0) > tol:
        raise ValueError(
            f"{name} rotation must be orthonormal with det +1 (tolerance {tol:g}), got max|R^T R - I| = "
            f"{ortho:.3g}, det = {det:.6g}"
        )
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=tol):
        raise ValueError(f"{name} last row must be [0, 0, 0, 1], got {T[3].tolist()}")
    return T
