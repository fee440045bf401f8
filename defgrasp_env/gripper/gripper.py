"""``Gripper``: W 2F-85 grippers, each on an invisible 6-DOF wrist (batched numpy state).

The gripper owns the robot side of the pickup scene: the wrist joints, the jaw gap and its driver,
the grip-stiffness estimate, the pads' collision boxes and their poses, the lift that keeps the
pads above the ground, and the tip-force readout. It knows nothing about the FEM solver: per
physics substep the scene (which owns the substep loop) asks it for the pad box poses to move to
(:meth:`Gripper.plan_substep`, :meth:`Gripper.move`) and hands it the pad forces the solver measured
there (:meth:`Gripper.sense`).

Force limits: the jaw driver's grip-force limit runs in :meth:`Gripper.plan_substep` on the forces
of the previous :meth:`Gripper.sense`. The wrist's force limit (``wrist.force_limit``) needs the
solver: the scene may apply a planned substep several times with a fraction of the wrist's motion
and the jaw's closing (:meth:`Gripper.move`) and keeps the solve whose forces, handed to
:meth:`Gripper.sense`, are within the limits (the wrist force, and each pad's normal force within
the grip-force limit plus the wrist limit).

Frames and units: world frame (y up), m, rad, N; quaternions xyzw; joints
``q = (x, y, z, roll, pitch, yaw)`` of ``defgrasp_env.wrist``; pad index 0 = left (+x_G), 1 = right.
"""

from __future__ import annotations

import numpy as np

from ..transforms import quat_rotate, quat_to_matrix
from ..wrist import clamp_joints, fk_analytic, ik_joints
from ..wrist.force_limit import wrist_force
from .driver import GripperConfig, GripperDriver, update_grip_stiffness
from .linkage import GAP_MAX, GAP_MIN, pad_boxes, pad_centers, theta_from_gap

__all__ = ["GROUND_CLEARANCE", "Gripper", "pad_box_poses", "pad_reach", "PAD_BACKING", "PAD_BOX_HALF_EXTENTS", "START_FLANGE_HEIGHT"]

#: Extra thickness (m) of each pad's collision box behind its inner face, so that a fast-closing pad
#: can never push a node through itself; the inner face stays where the linkage puts it.
PAD_BACKING = 0.01
#: Start height of the flange above the ground (m) and pad clearance kept above the ground (m).
START_FLANGE_HEIGHT = 0.30
GROUND_CLEARANCE = 0.001
#: A world stopped at its force limit stays held while its planned push keeps within this cosine
#: (~26 degrees) of the push that was stopped (``Gripper.held_at_limit``).
HOLD_COSINE = 0.9
#: Half extents (m) of each pad's collision box (the pad plus its backing), in frame G.
PAD_BOX_HALF_EXTENTS = pad_boxes(gap=GAP_MAX)[1][0] + np.array([PAD_BACKING / 2, 0.0, 0.0])
_CORNER_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)


def _pad_box_centers(flange_pos: np.ndarray, flange_quat: np.ndarray, gap: np.ndarray):
    """Collision-box centres [W, 2, 3] (m, world) of the pads and the flange rotations [W, 3, 3]
    (the boxes' orientation) for flange poses [W, 3] m, [W, 4] xyzw and jaw gaps [W] m (clipped).
    The boxes mirror each other across the flange's y-z plane, so the right pad's lateral term is
    the left one's negated (exactly, as in the per-pad product)."""
    left = pad_centers(theta_from_gap(np.clip(gap, GAP_MIN, GAP_MAX)))[:, 0]   # [W, 3] in G, z = 0
    R = quat_to_matrix(flange_quat)                                            # [W, 3, 3]
    lateral = R[:, :, 0] * (left[:, 0] + PAD_BACKING / 2)[:, None]
    down = R[:, :, 1] * left[:, 1, None]
    across = R[:, :, 2] * left[:, 2, None]
    rotated = np.stack([(lateral + down) + across, (-lateral + down) + across], axis=1)
    return flange_pos[:, None, :] + rotated, R


def pad_box_poses(flange_pos: np.ndarray, flange_quat: np.ndarray, gap: np.ndarray):
    """Collision-box centres [W, 2, 3] (m) and orientations [W, 2, 4] (xyzw) of the pads (pad plus
    backing, half extents ``PAD_BOX_HALF_EXTENTS``) for flange poses [W, 3] m, [W, 4] xyzw (world)
    and jaw gaps [W] (m, clipped to the stroke)."""
    return _pad_box_centers(flange_pos, flange_quat, gap)[0], np.repeat(flange_quat[:, None, :], 2, axis=1)


def pad_reach() -> float:
    """Largest distance (m) of a pad-box corner from the flange over the jaw's stroke."""
    gaps = np.linspace(GAP_MIN, GAP_MAX, 9)
    flange = np.zeros((len(gaps), 3))
    centers, quats = pad_box_poses(flange, np.tile([0.0, 0.0, 0.0, 1.0], (len(gaps), 1)), gaps)
    corners = centers[:, :, None, :] + quat_rotate(quats[:, :, None, :], _CORNER_SIGNS * PAD_BOX_HALF_EXTENTS)
    return float(np.linalg.norm(corners, axis=-1).max())


def _read_only(a: np.ndarray) -> np.ndarray:
    view = a.view()
    view.flags.writeable = False
    return view


class Gripper:
    """W grippers on 6-DOF wrists. State (read-only views, float64, world frame):

    * ``q`` [W, 6]: wrist joints (m, m, m, rad, rad, rad);
    * ``gap`` [W]: jaw gap between the pad inner faces, m, in [GAP_MIN, GAP_MAX];
    * ``tip_force`` [W, 2]: normal force on the left and right pad inner face, N (last substep);
    * ``grip_stiffness`` [W]: the jaw driver's estimate of d(grip force)/d(closing), N/m (0: unknown);
    * ``pad_force`` [W, 2, 3]: total force (normal + friction) the object exerts on the left and
      right pad, N, world frame (last substep);
    * ``wrist_force`` [W]: magnitude of the net force of both pads on the object, N (last substep):
      the force the wrist carries, limited by ``wrist.force_limit``.

    One control period: :meth:`begin_step` (wrist targets), then per physics substep
    :meth:`plan_substep` (the jaw driver's move and the wrist's planned joints), :meth:`move` (apply
    them, possibly again with a fraction of the motion; returns the pad poses) and
    :meth:`sense` (pad forces). :meth:`substep` is plan + move of the whole motion.
    """

    pad_half_extents = PAD_BOX_HALF_EXTENTS

    def __init__(self, config: GripperConfig, num_worlds: int):
        self.driver = GripperDriver(config)
        self.num_worlds = num_worlds
        self._q = np.zeros((num_worlds, 6))
        self._gap = np.full(num_worlds, GAP_MAX)
        self._tip_force = np.zeros((num_worlds, 2))
        self._grip_stiffness = np.zeros(num_worlds)
        self._pad_force = np.zeros((num_worlds, 2, 3))
        self._q_start = self._q_move = None
        self._plan = None   # (joints before, gap after, joints after) of the planned substep
        #: [W, 3] per world, the planned substep push (flange slide, m, world) that the actuator
        #: force limit stopped when the world last tried to move; zeros where it moved (``record_limit``)
        self._stopped_push = np.zeros((num_worlds, 3))
        self._before = None  # (gap, grip force, target gap) at the start of the running substep

    # -- state -----------------------------------------------------------------------------
    @property
    def q(self) -> np.ndarray:
        return _read_only(self._q)

    @property
    def gap(self) -> np.ndarray:
        return _read_only(self._gap)

    @property
    def tip_force(self) -> np.ndarray:
        return _read_only(self._tip_force)

    @property
    def grip_stiffness(self) -> np.ndarray:
        return _read_only(self._grip_stiffness)

    @property
    def pad_force(self) -> np.ndarray:
        return _read_only(self._pad_force)

    @property
    def wrist_force(self) -> np.ndarray:
        return _read_only(wrist_force(self._pad_force))

    def pad_force_angles(self) -> np.ndarray:
        """[W, 2] rad, in [0, pi]: angle of the object's total force on each pad (``pad_force``)
        from the pad's opening direction (left +x_G, right -x_G): 0 where the object pushes the pad
        straight out along the closing axis (an antipodal grasp), atan(friction) at the edge of a
        Coulomb cone, over pi/2 where it pulls the pad inward; 0 where the force is zero."""
        _, quat = self.flange_pose()
        opening = quat_to_matrix(quat)[:, None, :, 0] * np.array([1.0, -1.0])[None, :, None]  # [W, 2, 3]
        along = np.sum(self._pad_force * opening, axis=-1)
        across = np.linalg.norm(self._pad_force - along[..., None] * opening, axis=-1)
        return np.arctan2(across, along)

    def reset(self, mask: np.ndarray, flange_xz: np.ndarray) -> None:
        """Worlds in ``mask`` [W]: flange at ``flange_xz`` [W, 2] (m, world x and z; rows outside the
        mask are ignored) and ``START_FLANGE_HEIGHT``, pointing down, jaw open, no force."""
        for w in np.flatnonzero(mask):
            self._q[w] = [flange_xz[w][0], START_FLANGE_HEIGHT, flange_xz[w][1], 0.0, 0.0, 0.0]
            self._gap[w] = GAP_MAX
            self._tip_force[w] = 0.0
            self._grip_stiffness[w] = 0.0
            self._pad_force[w] = 0.0
            self._stopped_push[w] = 0.0

    # -- kinematics ------------------------------------------------------------------------
    def flange_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Flange positions [W, 3] (m) and orientations [W, 4] (xyzw) in the world."""
        return fk_analytic(self._q)

    def pad_poses(self, q: np.ndarray | None = None, gap: np.ndarray | None = None):
        """Collision-box centres [W, 2, 3] (m) and orientations [W, 2, 4] (xyzw) of the pads for
        joints ``q`` [W, 6] and gap [W] (m; default: the current ones)."""
        q = self._q if q is None else q
        gap = self._gap if gap is None else gap
        return pad_box_poses(*fk_analytic(q), gap)

    def tcp_positions(self) -> np.ndarray:
        """Tool centre point (midpoint between the pad inner faces) [W, 3], m."""
        centers, _ = self.pad_poses()
        return centers.mean(axis=1)

    def lift_above_ground(self, q: np.ndarray, gap: np.ndarray):
        """Raise the flange so that no pad box corner is below ``GROUND_CLEARANCE``. Returns the
        joints [W, 6] and the pad poses (as :meth:`pad_poses`) for them.

        The lowest corner of a box with centre c, rotation R and half extents h is at height
        ``c_y - sum_j |R[1, j]| h_j``; both pads share R. (The terms are summed x, z, y: the order
        in which numpy's einsum summed them over the eight corners before, so the lift is the
        same to the bit.)"""
        pos, quat = fk_analytic(q)
        centers, R = _pad_box_centers(pos, quat, gap)
        quats = np.repeat(quat[:, None, :], 2, axis=1)
        r, h = np.abs(R[:, 1, :]), PAD_BOX_HALF_EXTENTS
        reach = (-(r[:, 0] * h[0]) - r[:, 2] * h[2]) - r[:, 1] * h[1]   # lowest corner below the centre
        lowest = np.minimum(centers[:, 0, 1], centers[:, 1, 1]) + reach
        lifted = q.copy()
        lifted[:, 1] += np.maximum(GROUND_CLEARANCE - lowest, 0.0)
        lifted = clamp_joints(lifted)
        centers[..., 1] += (lifted[:, 1] - q[:, 1])[:, None]  # joint 1 is the world-y slide
        return lifted, centers, quats

    # -- actuation (one control period) ---------------------------------------------------
    def begin_step(self, target_pos: np.ndarray, target_quat: np.ndarray) -> None:
        """Start a control period toward flange targets [W, 3] m, [W, 4] xyzw (joint limits
        enforced; the wrist turns the shortest way round)."""
        self._q_start = self._q.copy()
        q_move = clamp_joints(ik_joints(target_pos, target_quat)) - self._q_start
        q_move[:, 3:] = (q_move[:, 3:] + np.pi) % (2 * np.pi) - np.pi
        self._q_move = q_move

    def _wrist_joints(self, fraction: float) -> np.ndarray:
        """Joints [W, 6] a ``fraction`` of the way through the control period's wrist motion."""
        return clamp_joints(self._q_start + self._q_move * fraction)

    def plan_substep(self, k: int, count: int, h: float, target_gap: np.ndarray, active: np.ndarray) -> None:
        """Plan substep ``k`` of ``count`` (length ``h`` s): the jaw driver moves the gap toward
        ``target_gap`` [W] (m) on the forces of the last :meth:`sense` (speed and force limits,
        ``gripper.driver``) and the wrist is to move ``(k + 1) / count`` of the way. Worlds with
        ``active == False`` keep wrist and jaw. Nothing moves until :meth:`move`."""
        self._before = (self._gap, self._tip_force.mean(axis=1), target_gap)
        gap = self.driver.step(target_gap, self._gap, h, self._tip_force[:, 0], self._tip_force[:, 1],
                               self._grip_stiffness)
        q = np.where(active[:, None], self._wrist_joints((k + 1) / count), self._q)
        self._plan = (self._q, np.where(active, gap, self._gap), q)

    def move(self, fraction: np.ndarray | None = None):
        """Apply the planned substep: ``fraction`` [W] (in [0, 1]; default 1) of the wrist's planned
        substep motion and of the jaw's planned closing (a planned opening is applied whole: it only
        lowers the forces), with the wrist lifted so that the pads stay above the ground. May be
        called again (a retry from the same start, ``wrist.force_limit``) with another fraction.
        Returns the pad box centres [W, 2, 3] (m) and orientations [W, 2, 4] (xyzw) to move to."""
        q_before, gap, q = self._plan
        if fraction is not None:
            f = np.asarray(fraction, dtype=np.float64)
            q = np.where(f[:, None] < 1.0, q_before + (q - q_before) * f[:, None], q)
            gap_before = self._before[0]
            gap = np.where((f < 1.0) & (gap < gap_before), gap_before + (gap - gap_before) * f, gap)
        # an inactive world keeps q, already above the ground: the lift leaves it as it is
        self._q, pos, quat = self.lift_above_ground(q, gap)
        self._gap = gap
        return pos, quat

    def planned_push(self) -> np.ndarray:
        """[W, 3] (m, world): the planned substep's flange slide (joints 0-2), before any force limit."""
        q_before, _, q = self._plan
        return q[:, :3] - q_before[:, :3]

    def held_at_limit(self, load_before: np.ndarray) -> np.ndarray:
        """[W] bool: worlds whose actuators stay stopped this substep without trying their planned
        motion (``wrist.force_limit.limited_substep``'s ``held``), like a protective stop: at a
        limit at the substep start (``load_before`` [W] >= 1), their last try stopped by the limit,
        and the planned flange slide within ~26 degrees of that stopped one (cosine >=
        ``HOLD_COSINE``, any speed), whatever turn of the wrist is planned with it: the force limit
        scales the whole motion (slide, turn and the jaw's closing) by one fraction, and a world at
        its limit is stopped at fraction 0 when its try reads over, so a try that pushes on the same
        way with a turn ends stopped as the held world does, with two more solves (a learner's
        policy turns its wrist a little in every action; 1-3 degrees a control step measured while
        pressing a cube into the ground). A world whose load fell below its limit (the object gave
        way), whose slide turned away, or that only moves its jaw or only turns its wrist (no
        slide), tries to move."""
        stopped, push = self._stopped_push, self.planned_push()
        norms = np.linalg.norm(stopped, axis=1) * np.linalg.norm(push, axis=1)
        same_push = (norms > 0.0) & (np.einsum("wi,wi->w", stopped, push) >= HOLD_COSINE * norms)
        return same_push & (np.asarray(load_before) >= 1.0)

    def record_limit(self, scale: np.ndarray, held: np.ndarray) -> None:
        """After a substep's force limit: a world that tried to move (not ``held`` [W]) and was
        stopped (``scale`` [W] = 0) remembers the push it tried; one that moved forgets; a held one
        keeps the push that stopped it (so a command turning step by step releases it)."""
        tried_push = np.where((np.asarray(scale) == 0.0)[:, None], self.planned_push(), 0.0)
        self._stopped_push = np.where(np.asarray(held)[:, None], self._stopped_push, tried_push)

    def substep(self, k: int, count: int, h: float, target_gap: np.ndarray, active: np.ndarray):
        """:meth:`plan_substep` then :meth:`move` with the whole wrist motion; returns the pad poses."""
        self.plan_substep(k, count, h, target_gap, active)
        return self.move()

    def sense(self, pad_normal_force: np.ndarray, pad_force: np.ndarray | None = None) -> None:
        """The pad normal forces [W, 2] (N, left and right) and the object's total force on each pad
        [W, 2, 3] (N, world; default: unchanged) measured at the end of the substep: the readouts
        and the grip-stiffness estimate follow them."""
        gap_before, force_before, target_gap = self._before
        self._tip_force = np.array(pad_normal_force, dtype=np.float64).reshape(self.num_worlds, 2)
        if pad_force is not None:
            self._pad_force = np.array(pad_force, dtype=np.float64).reshape(self.num_worlds, 2, 3)
        self._grip_stiffness = update_grip_stiffness(self._grip_stiffness, gap_before, self._gap, force_before,
                                                     self._tip_force.mean(axis=1), target_gap)
