"""Eq. 3 of the paper: wrist joint angles by inverse kinematics, and the reachable flange pose.

This is the only teleop module that touches ``defgrasp_env.wrist`` (``WristKinematics``: FK and
pytorch-kinematics ``PseudoInverseIK`` of the 6-DOF wrist URDF; pytorch-kinematics' (w, x, y, z)
quaternions never cross that boundary, it is driven with 4x4 matrices).

``WristIK.solve(target_pos, target_quat_xyzw, q_init)``:

1. IK warm-started from ``q_init`` (the current joints);
2. joint limits enforced: the solution is clamped to ``[lower, upper]``;
3. FK of the clamped joints gives the pose the wrist can actually reach; that is what the teleop
   sends as its action, so an unreachable target turns into the nearest reachable pose the solver
   found instead of a command the wrist cannot follow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import check_array
from ..se3 import quat_angle, quat_normalize


@dataclass(frozen=True)
class WristIKResult:
    """q [6] (m, m, m, rad, rad, rad) within the limits; position [3] m and quat_xyzw [4] = FK(q);
    pos_err_m / rot_err_rad between FK(q) and the target; converged: both under the solver's
    tolerances (1e-4 m, 1e-3 rad by default)."""

    q: np.ndarray
    position: np.ndarray
    quat_xyzw: np.ndarray
    pos_err_m: float
    rot_err_rad: float
    converged: bool


class WristIK:
    """Eq. 3 around a ``defgrasp_env.wrist.WristKinematics`` (built on first use if not given)."""

    def __init__(self, kinematics=None):
        if kinematics is None:
            from defgrasp_env.wrist import WristKinematics

            kinematics = WristKinematics()
        for attr in ("ik", "fk", "lower", "upper"):
            if not hasattr(kinematics, attr):
                raise TypeError(f"kinematics must provide ik/fk/lower/upper like WristKinematics, missing {attr!r}")
        self.kinematics = kinematics

    @property
    def lower(self) -> np.ndarray:
        return np.asarray(self.kinematics.lower, dtype=np.float64)

    @property
    def upper(self) -> np.ndarray:
        return np.asarray(self.kinematics.upper, dtype=np.float64)

    @property
    def home_q(self) -> np.ndarray:
        """A neutral start: zero joints projected onto the limits."""
        return np.clip(np.zeros(6), self.lower, self.upper)

    def fk(self, q) -> tuple[np.ndarray, np.ndarray]:
        """(position [3] m, quaternion (x, y, z, w)) of the flange for joints q [6]."""
        q = check_array("q", q, (6,))
        p, quat = self.kinematics.fk(q)
        return np.asarray(p, dtype=np.float64), quat_normalize(quat)

    def solve(self, target_pos, target_quat_xyzw, q_init=None) -> WristIKResult:
        """IK warm-started from ``q_init`` (default ``home_q``), clamped, then FK (module doc)."""
        p_t = check_array("target_pos", target_pos, (3,), unit="m")
        q_t = quat_normalize(check_array("target_quat_xyzw", target_quat_xyzw, (4,)))
        q0 = self.home_q if q_init is None else check_array("q_init", q_init, (6,))
        res = self.kinematics.ik(p_t, q_t, np.clip(q0, self.lower, self.upper))
        q = np.clip(np.asarray(res.q, dtype=np.float64).reshape(6), self.lower, self.upper)
        pos, quat = self.fk(q)
        pos_err = float(np.linalg.norm(pos - p_t))
        rot_err = quat_angle(quat, q_t)
        return WristIKResult(q, pos, quat, pos_err, rot_err, bool(np.all(res.converged)))
