"""Wrist kinematics through pytorch-kinematics (float64, CPU), with numpy in and out.

``WristKinematics`` loads ``assets/wrist_6dof.urdf`` with ``build_serial_chain_from_urdf`` and
solves IK with ``PseudoInverseIK`` (damped least squares), warm-started from the caller's joint
values, one start per target, with the joints projected onto their limits after every step and a
final limit-enforcing refinement; targets the warm start does not solve are retried from a few fixed
seeded configurations. pytorch-kinematics is only used with 4x4 matrices here, so no
(w, x, y, z) quaternion crosses this boundary; quaternions in and out are (x, y, z, w).

The closed-form solution (``analytic.ik_analytic``) is exact and much faster; the iterative solver
is kept because it generalises to wrists without a closed form and serves as a cross-check.
"""

from __future__ import annotations

import contextlib
import pathlib

import numpy as np
import pytorch_kinematics as pk
import torch

from ..transforms import matrix_to_quat, pose_to_matrix
from .analytic import IKResult, _joints, ik_analytic, pose_errors
from .spec import FLANGE_LINK, JOINT_NAMES, WRIST_URDF_PATH, load_joint_limits

__all__ = ["WristKinematics"]


@contextlib.contextmanager
def _torch_threads(n: int | None):
    """Temporarily set torch's intra-op thread count (6x6 problems only lose from threading)."""
    if n is None:
        yield
        return
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _positive(value, name: str, unit: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number in (0, inf) {unit}, got {value!r}")
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be in (0, inf) {unit}, got {value}")
    return float(value)


class WristKinematics:
    """FK and IK of the invisible 6-DOF wrist (world frame, y up; flange = gripper frame G).

    Joint vector ``q [..., 6]`` = (slide_x, slide_y, slide_z in m; roll_z, pitch_x, yaw_y in rad);
    see ``defgrasp_env.wrist.spec`` for axes, limits and the reachable set.

    Args:
        urdf_path: wrist URDF (default: the packaged ``wrist_6dof.urdf``).
        pos_tolerance: IK position tolerance (m) used for ``converged``; default 1e-4.
        rot_tolerance: IK rotation tolerance (rad) used for ``converged``; default 1e-3.
        max_iterations: IK iteration cap per solve; default 30.
        restarts: number of fixed, seeded restart configurations (uniform within the limits) tried
            for the targets that the warm start does not solve (a local solver can stall on the
            pitch limit, the gimbal lock, from a far start); 0 disables; default 8.
        torch_threads: torch intra-op threads used during FK/IK calls (restored afterwards);
            default 1, which is 2-3x faster than several threads for these tiny matrices on a busy
            CPU; None leaves torch's global setting alone. Changing it is process-global while a
            call runs, so do not share torch across threads with a different setting.
    """

    def __init__(
        self,
        urdf_path: str | pathlib.Path = WRIST_URDF_PATH,
        *,
        pos_tolerance: float = 1e-4,
        rot_tolerance: float = 1e-3,
        max_iterations: int = 30,
        restarts: int = 8,
        torch_threads: int | None = 1,
    ) -> None:
        self.pos_tolerance = _positive(pos_tolerance, "pos_tolerance", "m")
        self.rot_tolerance = _positive(rot_tolerance, "rot_tolerance", "rad")
        for name, value, lo in (("max_iterations", max_iterations, 1), ("restarts", restarts, 0)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
                raise ValueError(f"{name} must be an integer in [{lo}, inf), got {value!r}")
        self.restarts = int(restarts)
        if torch_threads is not None and (
            isinstance(torch_threads, bool) or not isinstance(torch_threads, (int, np.integer)) or torch_threads < 1
        ):
            raise ValueError(f"torch_threads must be None or an integer in [1, inf), got {torch_threads!r}")
        self.torch_threads = None if torch_threads is None else int(torch_threads)
        path = pathlib.Path(urdf_path)
        if not path.is_file():
            raise ValueError(f"urdf_path must be an existing URDF file, got {str(path)!r}")
        self.chain = pk.build_serial_chain_from_urdf(path.read_bytes(), FLANGE_LINK).to(
            dtype=torch.float64, device="cpu"
        )
        names = tuple(self.chain.get_joint_parameter_names())
        if names != JOINT_NAMES:
            raise ValueError(f"{path}: joints must be {JOINT_NAMES}, got {names}")
        lower, upper = load_joint_limits(path)  # also checks the layout that ik_analytic assumes
        # pytorch-kinematics parses the limits through float32; restore the exact URDF values
        if not (np.allclose(self.chain.low.numpy(), lower, atol=1e-6) and np.allclose(self.chain.high.numpy(), upper, atol=1e-6)):
            raise ValueError(f"{path}: pytorch-kinematics joint limits disagree with the URDF")
        self.lower = np.array(lower, dtype=np.float64)
        """[6] lower joint limits (m, m, m, rad, rad, rad), exactly as in the URDF."""
        self.upper = np.array(upper, dtype=np.float64)
        """[6] upper joint limits (m, m, m, rad, rad, rad), exactly as in the URDF."""
        self.chain.low = torch.as_tensor(self.lower)
        self.chain.high = torch.as_tensor(self.upper)
        # Joint limits: every DLS step is projected onto the limits (clamp_to_limits), then
        # pytorch-kinematics' enforce_joint_limits wraps/clamps and refines twice more.
        options = dict(
            pos_tolerance=self.pos_tolerance,
            rot_tolerance=self.rot_tolerance,
            max_iterations=int(max_iterations),
            joint_limits=torch.stack([self.chain.low, self.chain.high], dim=1),
            early_stopping_any_converged=True,
            clamp_to_limits=True,
            enforce_joint_limits=True,
            num_limit_refinement_iterations=2,
        )
        # warm start: one start per problem, set per call as initial_config [n, 1, 6]
        self._solver = pk.PseudoInverseIK(self.chain, retry_configs=torch.zeros(1, 6, dtype=torch.float64), **options)
        self._restart_solver = None
        if self.restarts:
            seeds = np.random.default_rng(0).uniform(self.lower, self.upper, size=(self.restarts, 6))
            self._restart_solver = pk.PseudoInverseIK(
                self.chain, retry_configs=torch.as_tensor(seeds, dtype=torch.float64), **options
            )

    # ------------------------------------------------------------------------------------ FK

    _q = staticmethod(_joints)  # q as a finite float64 array [..., 6]

    def fk_matrix(self, q) -> np.ndarray:
        """Flange pose ``T_world_G [..., 4, 4]`` (m) for joints ``q [..., 6]`` (not clamped)."""
        a = self._q(q)
        flat = torch.as_tensor(a.reshape(-1, 6), dtype=torch.float64)
        with torch.no_grad(), _torch_threads(self.torch_threads):
            m = self.chain.forward_kinematics(flat).get_matrix()
        return m.numpy().reshape(a.shape[:-1] + (4, 4))

    def fk(self, q) -> tuple[np.ndarray, np.ndarray]:
        """Flange ``(position [..., 3] m, quaternion [..., 4] xyzw)`` in the world for ``q [..., 6]``."""
        T = self.fk_matrix(q)
        return T[..., :3, 3].copy(), matrix_to_quat(T[..., :3, :3])

    # ------------------------------------------------------------------------------------ IK

    def ik(self, target_pos, target_quat_xyzw, q_init) -> IKResult:
        """Iterative IK (pytorch-kinematics ``PseudoInverseIK``), batched over targets.

        Args:
            target_pos: [..., 3] flange position targets (m, world).
            target_quat_xyzw: [..., 4] flange orientation targets (x, y, z, w), broadcast with pos.
            q_init: [6] or [..., 6] warm start (e.g. the current joints); clamped to the limits.

        Returns:
            :class:`IKResult` ``(q [..., 6], pos_err_m [...], rot_err_rad [...], converged [...])``;
            ``q`` always lies within the joint limits; errors are recomputed by FK of ``q``.
            Unreachable targets come back clamped with ``converged = False``.
        """
        T = pose_to_matrix(target_pos, target_quat_xyzw)  # validates both
        batch = T.shape[:-2]
        q0 = self._q(q_init)
        try:
            q0 = np.broadcast_to(q0, batch + (6,))
        except ValueError as exc:
            raise ValueError(f"q_init {q0.shape} must broadcast to the target batch {batch + (6,)}") from exc
        n = int(np.prod(batch, dtype=np.int64))
        if n == 0:
            empty = np.zeros(batch)
            return IKResult(np.zeros(batch + (6,)), empty, empty.copy(), np.zeros(batch, dtype=bool))
        q0 = np.clip(q0.reshape(n, 6), self.lower, self.upper)
        T = T.reshape(n, 4, 4)
        pos_t, quat_t = T[:, :3, 3], matrix_to_quat(T[:, :3, :3])

        self._solver.initial_config = torch.as_tensor(q0).reshape(n, 1, 6)
        q = self._candidates(self._solver, T)[:, 0, :]
        pos_err, rot_err = pose_errors(q, pos_t, quat_t)
        ok = (pos_err < self.pos_tolerance) & (rot_err < self.rot_tolerance)

        if self._restart_solver is not None and not ok.all():
            bad = np.flatnonzero(~ok)
            cand = self._candidates(self._restart_solver, T[bad])  # [m, R, 6]
            c_pos, c_rot = pose_errors(cand, pos_t[bad, None], quat_t[bad, None])
            c_ok = (c_pos < self.pos_tolerance) & (c_rot < self.rot_tolerance)
            # converged candidates first, nearest to the warm start; else the smallest error
            score = np.where(c_ok, np.linalg.norm(cand - q0[bad, None], axis=-1), 1e6 + c_pos + c_rot)
            best = np.argmin(score, axis=1)
            pick = np.arange(len(bad))
            b_pos, b_rot = c_pos[pick, best], c_rot[pick, best]
            better = c_ok[pick, best] | (b_pos + b_rot < pos_err[bad] + rot_err[bad])
            rows = bad[better]
            q[rows] = cand[pick, best][better]
            pos_err[rows], rot_err[rows] = b_pos[better], b_rot[better]
            ok[rows] = c_ok[pick, best][better]

        return IKResult(q.reshape(batch + (6,)), pos_err.reshape(batch), rot_err.reshape(batch), ok.reshape(batch))

    def _candidates(self, solver: pk.PseudoInverseIK, T: np.ndarray) -> np.ndarray:
        """Run ``solver`` on targets ``T [m, 4, 4]``; return its solutions [m, retries, 6] clipped."""
        target = pk.Transform3d(matrix=torch.as_tensor(T), dtype=torch.float64)
        with torch.no_grad(), _torch_threads(self.torch_threads):
            sol = solver.solve(target)
        return np.clip(sol.solutions.numpy(), self.lower, self.upper)

    def ik_analytic(self, target_pos, target_quat_xyzw) -> IKResult:
        """Closed-form IK with this instance's tolerances; see ``analytic.ik_analytic``."""
        return ik_analytic(
            target_pos,
            target_quat_xyzw,
            pos_tolerance=self.pos_tolerance,
            rot_tolerance=self.rot_tolerance,
            lower=self.lower,
            upper=self.upper,
        )

    # ------------------------------------------------------------------------------------ misc

    def clamp(self, q) -> np.ndarray:
        """Clip ``q [..., 6]`` to the joint limits (float64 copy)."""
        return np.clip(self._q(q), self.lower, self.upper)

    def __repr__(self) -> str:
        lo, hi = np.round(self.lower, 4).tolist(), np.round(self.upper, 4).tolist()
        return f"WristKinematics(joints={JOINT_NAMES}, lower={lo}, upper={hi})"
