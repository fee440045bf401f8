"""Quaternion and rigid-pose helpers (vectorised numpy, float64, validated).

Conventions (see shared CONVENTIONS.md):

* Quaternions are stored **scalar-last** ``(x, y, z, w)``, Hamilton product, active rotation
  (``v' = q v q*``). Libraries that use ``(w, x, y, z)`` (pytorch-kinematics) are converted at their
  boundary with :func:`xyzw_to_wxyz` / :func:`wxyz_to_xyzw`.
* Rotation matrices ``R`` act on column vectors: ``v' = R @ v``; a pose ``T_A_B`` (4x4) maps
  coordinates in frame B to frame A.
* Every function accepts arbitrary leading batch dimensions ``[...]`` and returns new float64
  arrays. Quaternions returned by this module are unit and canonical (``w >= 0``).

Inputs are validated: wrong trailing shape raises ``ValueError``, non-finite values raise
``ValueError``, quaternions whose norm is off by more than ``QUAT_NORM_TOL`` raise ``ValueError``
(use :func:`quat_normalize` explicitly for unnormalised data), rotation matrices must be orthonormal
with det +1 within ``ROT_TOL``.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "QUAT_NORM_TOL",
    "ROT_TOL",
    "IDENTITY_QUAT",
    "xyzw_to_wxyz",
    "wxyz_to_xyzw",
    "quat_normalize",
    "unit_quat",
    "quat_conjugate",
    "quat_multiply",
    "quat_rotate",
    "quat_to_matrix",
    "matrix_to_quat",
    "pose_to_matrix",
    "matrix_to_pose",
    "pose_inverse",
    "axis_angle_to_quat",
    "quat_to_axis_angle",
    "quat_angle_between",
]

QUAT_NORM_TOL = 1e-3
"""Accepted deviation of a quaternion's norm from 1 (float32 data is fine); beyond it: ValueError."""

ROT_TOL = 1e-4
"""Accepted max-abs deviation of ``R.T @ R`` from identity and of ``det(R)`` from 1."""

IDENTITY_QUAT = np.array([0.0, 0.0, 0.0, 1.0])
"""Identity rotation, (x, y, z, w)."""


# ----------------------------------------------------------------------------- validation


def _as_array(x, last: tuple[int, ...], name: str) -> np.ndarray:
    """Return ``x`` as a finite float64 array whose trailing shape is ``last``."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a numeric array, got {type(x).__name__}") from exc
    if a.ndim < len(last) or a.shape[a.ndim - len(last):] != last:
        shape = "[..., " + ", ".join(str(n) for n in last) + "]"
        raise ValueError(f"{name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got non-finite values in an array of shape {a.shape}")
    return a


def unit_quat(q, name: str = "quat") -> np.ndarray:
    """Validate a quaternion array ``[..., 4]`` (finite, |norm - 1| <= ``QUAT_NORM_TOL``; ValueError
    naming ``name`` otherwise) and return it renormalised (float64)."""
    a = _as_array(q, (4,), name)
    norm = np.linalg.norm(a, axis=-1, keepdims=True)
    bad = np.abs(norm - 1.0) > QUAT_NORM_TOL
    if np.any(bad):
        worst = float(norm[bad].flat[0])
        raise ValueError(
            f"{name} must be a unit quaternion (|norm - 1| <= {QUAT_NORM_TOL}), got norm {worst:.6g}; "
            "use quat_normalize() for unnormalised data"
        )
    return a / norm


def _rotation(R, name: str = "rotation") -> np.ndarray:
    """Validate a rotation matrix array ``[..., 3, 3]``."""
    a = _as_array(R, (3, 3), name)
    ortho = np.abs(np.swapaxes(a, -1, -2) @ a - np.eye(3)).max(axis=(-1, -2)) if a.size else np.zeros(0)
    det = np.linalg.det(a) if a.size else np.zeros(0)
    if np.any(ortho > ROT_TOL) or np.any(np.abs(det - 1.0) > ROT_TOL):
        raise ValueError(
            f"{name} must be a proper rotation matrix (orthonormal within {ROT_TOL}, det = +1), "
            f"got max |R^T R - I| = {float(np.max(ortho)):.3g}, det in "
            f"[{float(np.min(det)):.6g}, {float(np.max(det)):.6g}]"
        )
    return a


def _canonical(q: np.ndarray) -> np.ndarray:
    """Normalise ``q [..., 4]`` and flip its sign so that ``w >= 0``."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0.0, -q, q)


# ----------------------------------------------------------------------------- quaternion basics


def xyzw_to_wxyz(q) -> np.ndarray:
    """Reorder scalar-last ``(x, y, z, w)`` [..., 4] to scalar-first ``(w, x, y, z)`` [..., 4]."""
    a = _as_array(q, (4,), "quat_xyzw")
    return np.concatenate([a[..., 3:4], a[..., :3]], axis=-1)


def wxyz_to_xyzw(q) -> np.ndarray:
    """Reorder scalar-first ``(w, x, y, z)`` [..., 4] to scalar-last ``(x, y, z, w)`` [..., 4]."""
    a = _as_array(q, (4,), "quat_wxyz")
    return np.concatenate([a[..., 1:], a[..., :1]], axis=-1)


def quat_normalize(q) -> np.ndarray:
    """Return ``q [..., 4]`` (x, y, z, w) scaled to unit norm with ``w >= 0``.

    Raises ``ValueError`` for a (near-)zero quaternion (norm < 1e-12).
    """
    a = _as_array(q, (4,), "quat")
    norm = np.linalg.norm(a, axis=-1, keepdims=True)
    if np.any(norm < 1e-12):
        raise ValueError("quat must have a non-zero norm to be normalised, got a zero quaternion")
    return _canonical(a / norm)


def quat_conjugate(q) -> np.ndarray:
    """Inverse rotation of unit ``q [..., 4]`` (x, y, z, w): ``(-x, -y, -z, w)``."""
    a = unit_quat(q)
    return np.concatenate([-a[..., :3], a[..., 3:]], axis=-1)


def _mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def quat_multiply(a, b) -> np.ndarray:
    """Hamilton product ``a * b`` of unit quaternions [..., 4] (x, y, z, w), broadcast.

    ``quat_to_matrix(a * b) == quat_to_matrix(a) @ quat_to_matrix(b)`` (apply b first, then a).
    The result is canonical (``w >= 0``).
    """
    return _canonical(_mul(unit_quat(a, "a"), unit_quat(b, "b")))


def quat_rotate(q, v) -> np.ndarray:
    """Rotate vectors ``v [..., 3]`` by unit quaternions ``q [..., 4]`` (broadcast) -> [..., 3]."""
    R = quat_to_matrix(q)
    vv = _as_array(v, (3,), "v")
    return np.einsum("...ij,...j->...i", R, vv)


# ----------------------------------------------------------------------------- matrices


def quat_to_matrix(q) -> np.ndarray:
    """Unit quaternion ``[..., 4]`` (x, y, z, w) -> rotation matrix ``[..., 3, 3]``."""
    x, y, z, w = np.moveaxis(unit_quat(q), -1, 0)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    R = np.stack(
        [
            1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
            2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
            2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
        ],
        axis=-1,
    )
    return R.reshape(R.shape[:-1] + (3, 3))


def matrix_to_quat(R) -> np.ndarray:
    """Rotation matrix ``[..., 3, 3]`` -> canonical unit quaternion ``[..., 4]`` (x, y, z, w), w >= 0.

    Shepperd's method: each element uses the numerically best of the four branches.
    """
    m = _rotation(R)
    m00, m01, m02 = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    m10, m11, m12 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    m20, m21, m22 = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    diag = np.stack([m00 + m11 + m22, m00 - m11 - m22, -m00 + m11 - m22, -m00 - m11 + m22], axis=-1)
    s = 2.0 * np.sqrt(np.maximum(1.0 + diag, 1e-12))  # s = 4 * (largest component)
    sw, sx, sy, sz = np.moveaxis(s, -1, 0)
    cand = np.stack(
        [
            np.stack([(m21 - m12) / sw, (m02 - m20) / sw, (m10 - m01) / sw, 0.25 * sw], axis=-1),
            np.stack([0.25 * sx, (m01 + m10) / sx, (m02 + m20) / sx, (m21 - m12) / sx], axis=-1),
            np.stack([(m01 + m10) / sy, 0.25 * sy, (m12 + m21) / sy, (m02 - m20) / sy], axis=-1),
            np.stack([(m02 + m20) / sz, (m12 + m21) / sz, 0.25 * sz, (m10 - m01) / sz], axis=-1),
        ],
        axis=-2,
    )  # [..., 4 branches, 4]
    best = np.argmax(diag, axis=-1)[..., None, None]
    q = np.take_along_axis(cand, np.broadcast_to(best, best.shape[:-2] + (1, 4)), axis=-2)[..., 0, :]
    return _canonical(q)


def pose_to_matrix(pos, quat) -> np.ndarray:
    """Position ``[..., 3]`` (m) + unit quaternion ``[..., 4]`` (x, y, z, w) -> 4x4 ``[..., 4, 4]``.

    Leading dimensions broadcast. The result maps child-frame coordinates to the parent frame.
    """
    p = _as_array(pos, (3,), "pos")
    R = quat_to_matrix(quat)
    batch = np.broadcast_shapes(p.shape[:-1], R.shape[:-2])
    T = np.zeros(batch + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = p
    T[..., 3, 3] = 1.0
    return T


def matrix_to_pose(T) -> tuple[np.ndarray, np.ndarray]:
    """4x4 rigid transform ``[..., 4, 4]`` -> (position ``[..., 3]`` m, quaternion ``[..., 4]`` xyzw).

    The last row must be ``[0, 0, 0, 1]`` and the rotation block a proper rotation.
    """
    a = _as_array(T, (4, 4), "T")
    if np.any(np.abs(a[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])) > ROT_TOL):
        raise ValueError("T must be a rigid transform with last row [0, 0, 0, 1]")
    return a[..., :3, 3].copy(), matrix_to_quat(a[..., :3, :3])


def pose_inverse(T) -> np.ndarray:
    """Inverse of rigid transforms ``[..., 4, 4]``: ``T_B_A`` from ``T_A_B``."""
    a = _as_array(T, (4, 4), "T")
    R = _rotation(a[..., :3, :3], "T[..., :3, :3]")
    Rt = np.swapaxes(R, -1, -2)
    out = np.zeros_like(a)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, a[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


# ----------------------------------------------------------------------------- axis-angle


def axis_angle_to_quat(axis_angle) -> np.ndarray:
    """Rotation vector ``[..., 3]`` (unit axis times angle in rad) -> quaternion ``[..., 4]`` (x, y, z, w).

    Exact for small angles (uses ``sinc``); the result is canonical (``w >= 0``).
    """
    v = _as_array(axis_angle, (3,), "axis_angle")
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(angle/2)/angle = 0.5 * sinc(angle / (2 pi)) with numpy's normalised sinc
    scale = 0.5 * np.sinc(half / np.pi)
    return _canonical(np.concatenate([v * scale, np.cos(half)], axis=-1))


def quat_to_axis_angle(q) -> np.ndarray:
    """Unit quaternion ``[..., 4]`` (x, y, z, w) -> rotation vector ``[..., 3]``, angle in [0, pi] rad."""
    a = _canonical(unit_quat(q))
    xyz, w = a[..., :3], a[..., 3:]
    s = np.linalg.norm(xyz, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, w)
    # angle / s -> 2 / w as s -> 0
    scale = np.where(s > 1e-12, angle / np.where(s > 1e-12, s, 1.0), 2.0 / np.maximum(w, 1e-12))
    return xyz * scale


def quat_angle_between(a, b) -> np.ndarray:
    """Geodesic angle ``[...]`` (rad, in [0, pi]) between unit quaternions ``a``, ``b`` [..., 4]."""
    qa, qb = unit_quat(a, "a"), unit_quat(b, "b")
    # q and -q are the same rotation: align the hemispheres first
    qb = np.where(np.sum(qa * qb, axis=-1, keepdims=True) < 0.0, -qb, qb)
    # a.b = cos(angle/2) and |a -+ b| = 2 sin/cos(angle/4): 4*atan2 is accurate near 0, acos is not
    return 4.0 * np.arctan2(np.linalg.norm(qa - qb, axis=-1), np.linalg.norm(qa + qb, axis=-1))
