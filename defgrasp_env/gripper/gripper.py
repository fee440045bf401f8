"""``Gripper``: W 2F-85 grippers, each on an invisible 6-DOF wrist (batched state in Warp arrays
on the simulation's device, stepped by the kernels of ``gripper.kernels``).

The gripper owns the robot side of the pickup scene: the wrist joints, the jaw gap and its driver,
the grip-stiffness estimate, the pads' collision boxes and their poses, the lift that keeps the
pads above the ground, and the tip-force readout. It knows nothing about the FEM solver: per
physics substep the scene (which owns the substep loop) asks it for the pad box poses to move to
(:meth:`Gripper.plan_substep`, :meth:`Gripper.move`: written on the device into the arrays the FEM's
control reads) and hands it the pad forces the solver measured there (:meth:`Gripper.sense`: read
from the solver's state arrays on the device). A substep's gripper work is three kernel launches
and no transfer of the worlds' state; numpy copies of the state are made only when read.

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

import copy
import math
from typing import NamedTuple

import numpy as np
import warp as wp

from ..sim.launch_cache import LaunchCache
from ..transforms import quat_rotate, quat_to_matrix, unit_quat
from ..wrist import fk_analytic
from ..wrist.force_limit import FORCE_TOLERANCE, wrist_force
from . import kernels as gk
from .driver import GripperConfig, GripperDriver
from .linkage import GAP_MAX, GAP_MIN, _finite, pad_boxes, pad_centers, theta_from_gap

__all__ = ["GROUND_CLEARANCE", "Gripper", "GripperArrays", "GripperTargets", "lift_above_ground", "pad_box_poses", "pad_reach", "PAD_BACKING", "PAD_BOX_HALF_EXTENTS", "START_FLANGE_HEIGHT"]

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


def _move_pads_inputs(q_before, q_plan, gap_before, gap_plan, fraction, back_off) -> list:
    """The inputs of ``gripper.kernels.move_pads``: the substep's start and plan, the fraction of it
    to apply, the flange's full back-off, and the pad boxes' size, backing and ground clearance."""
    return [q_before, q_plan, gap_before, gap_plan, fraction, back_off, wp.vec3d(*PAD_BOX_HALF_EXTENTS), PAD_BACKING,
            GROUND_CLEARANCE]


def lift_above_ground(q: np.ndarray, gap: np.ndarray, device="cpu"):
    """Joints ``q`` [W, 6] with the flange raised so that no pad box corner is below
    ``GROUND_CLEARANCE`` (joint limits kept), and the pad box poses for them at jaw gaps ``gap`` [W]
    (m): (lifted joints [W, 6], centres [W, 2, 3] m, orientations [W, 2, 4] xyzw). The lowest
    corner of a box with centre c, rotation R and half extents h is at ``c_y - sum_j |R[1, j]| h_j``;
    both pads share R. The kernel of :meth:`Gripper.move`, run on ``device``."""
    d, n = wp.get_device(device), len(q)
    q_in = wp.array(np.asarray(q, dtype=np.float64), dtype=gk.vec6d, device=d)
    gap_in = wp.array(np.asarray(gap, dtype=np.float64), dtype=wp.float64, device=d)
    outputs = [wp.zeros_like(q_in), wp.zeros_like(gap_in), wp.zeros((n, 2), dtype=wp.vec3d, device=d),
               wp.zeros(n, dtype=wp.vec4d, device=d), wp.zeros(2 * n, dtype=wp.vec3, device=d),
               wp.zeros(2 * n, dtype=wp.quat, device=d)]
    whole = wp.ones(n, dtype=wp.float64, device=d)
    still = wp.zeros(n, dtype=wp.vec3d, device=d)
    wp.launch(gk.move_pads, dim=n, inputs=_move_pads_inputs(q_in, q_in, gap_in, gap_in, whole, still),
              outputs=outputs, device=d)
    quat = outputs[3].numpy()
    return outputs[0].numpy(), outputs[2].numpy(), np.repeat(quat[:, None, :], 2, axis=1)


class GripperArrays(NamedTuple):
    """The W grippers' state as Warp arrays on the simulation's device (float64, world frame), for
    kernels that read it (``Gripper.arrays``); valid for the gripper's life, overwritten by its
    kernels."""

    q: wp.array          # [W] vec6d: wrist joints (m, m, m, rad, rad, rad)
    gap: wp.array        # [W] float64: jaw gap, m
    tip_force: wp.array  # [W] vec2d: left and right pad normal force, N
    pad_force: wp.array  # [W, 2] vec3d: the object's total force on each pad, N


class GripperTargets(NamedTuple):
    """A control period's targets of the W grippers as Warp arrays on the simulation's device
    (float64, world frame; ``Gripper.targets``)."""

    position: wp.array     # [W] vec3d: flange position, m
    orientation: wp.array  # [W] vec4d: flange orientation, xyzw (unit; renormalised when read)
    gap: wp.array          # [W] float64: jaw gap, m (clipped to the stroke by the driver)


def _read_only(a: np.ndarray) -> np.ndarray:
    view = a.view()
    view.flags.writeable = False
    return view


class Gripper:
    """W grippers on 6-DOF wrists, their state in Warp arrays on ``device`` (the simulation's) and
    stepped there by ``gripper.kernels`` (one thread per world, float64). State, read as numpy
    (read-only; float64, world frame; on a GPU downloaded once after each change):

    * ``q`` [W, 6]: wrist joints (m, m, m, rad, rad, rad);
    * ``gap`` [W]: jaw gap between the pad inner faces, m, in [GAP_MIN, GAP_MAX];
    * ``tip_force`` [W, 2]: normal force on the left and right pad inner face, N (last substep);
    * ``grip_stiffness`` [W]: the jaw driver's estimate of d(grip force)/d(closing), N/m (0: unknown);
    * ``pad_force`` [W, 2, 3]: total force (normal + friction) the object exerts on the left and
      right pad, N, world frame (last substep);
    * ``wrist_force`` [W]: magnitude of the net force of both pads on the object, N (last substep):
      the force the wrist carries, limited by ``wrist.force_limit``.

    One control period: :meth:`begin_step` (wrist, jaw targets), then per physics substep
    :meth:`plan_substep` (the jaw driver's move and the wrist's planned joints), :meth:`move` (apply
    them, possibly again with a fraction of the motion; writes the pad poses ``pad_targets``) and
    :meth:`sense` (pad forces). :meth:`substep` is plan + move of the whole motion.
    ``pad_targets`` = (positions [W*2] vec3, orientations [W*2] quat, float32, pad 0 then 1 of
    each world) are the arrays the FEM's ``Control`` reads: the scene hands them to it.
    """

    pad_half_extents = PAD_BOX_HALF_EXTENTS

    def __init__(self, config: GripperConfig, num_worlds: int, device="cpu", wrist_force_limit: float = math.inf):
        self.driver = GripperDriver(config)
        #: N: the wrist's force limit (``wrist.force_limit``; inf = none), for :meth:`held_at_limit`'s load
        self.wrist_force_limit = float(wrist_force_limit)
        self.num_worlds = n = num_worlds
        self.device = d = wp.get_device(device)
        f64 = wp.float64
        self._q = wp.zeros(n, dtype=gk.vec6d, device=d)
        self._gap = wp.full(n, GAP_MAX, dtype=f64, device=d)
        self._tip_force = wp.zeros(n, dtype=wp.vec2d, device=d)
        self._grip_stiffness = wp.zeros(n, dtype=f64, device=d)
        self._pad_force = wp.zeros((n, 2), dtype=wp.vec3d, device=d)
        #: per world, the planned substep push (flange slide, m, world) that the actuator force limit
        #: stopped when the world last tried to move; zeros where it moved (``sense(record_limit=True)``)
        self._stopped_push = wp.zeros(n, dtype=wp.vec3d, device=d)
        # the control period: start joints, joint motion, jaw target, active worlds
        self._q_start = wp.zeros(n, dtype=gk.vec6d, device=d)
        self._q_move = wp.zeros(n, dtype=gk.vec6d, device=d)
        self._target_position = wp.zeros(n, dtype=wp.vec3d, device=d)
        self._target_orientation = wp.array(np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)), dtype=wp.vec4d, device=d)
        self._target_gap = wp.zeros(n, dtype=f64, device=d)
        self._active = wp.zeros(n, dtype=wp.int32, device=d)
        self._active_host = np.zeros(n, np.int32)  # what ``_active`` holds
        # the running substep: its start and plan, the fraction of it applied, (load, held) at its start
        self._q_before = wp.zeros(n, dtype=gk.vec6d, device=d)
        self._q_plan = wp.zeros(n, dtype=gk.vec6d, device=d)
        self._gap_before = wp.zeros(n, dtype=f64, device=d)
        self._gap_plan = wp.zeros(n, dtype=f64, device=d)
        self._force_before = wp.zeros(n, dtype=f64, device=d)
        self._fraction = wp.ones(n, dtype=f64, device=d)
        self._back_off = wp.zeros(n, dtype=wp.vec3d, device=d)  # m, world: the flange's full back-off
        self._limits = wp.zeros(n, dtype=wp.vec2d, device=d)
        self._pad_center = wp.zeros((n, 2), dtype=wp.vec3d, device=d)
        self._pad_quat = wp.array(np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)), dtype=wp.vec4d, device=d)
        quats = np.tile(np.array([0, 0, 0, 1], np.float32), (2 * n, 1))
        self.pad_targets = (wp.zeros(2 * n, dtype=wp.vec3, device=d), wp.array(quats, dtype=wp.quat, device=d))
        self._no_total = wp.zeros(0, dtype=wp.vec3d, device=d)
        self._host: dict[str, np.ndarray] = {}   # numpy copies of device arrays read since their last change
        self._launches = LaunchCache(d)  # the substep's launches, recorded once and replayed

    def __deepcopy__(self, memo) -> "Gripper":
        """An independent gripper with the same state (every Warp array cloned; a clone is shared
        through ``memo`` with anything else the same deep copy copies). Its ``pad_targets`` are
        its own: a scene's control keeps reading the original's."""
        other = object.__new__(Gripper)
        memo[id(self)] = other

        def clone(a: wp.array) -> wp.array:
            if id(a) not in memo:
                memo[id(a)] = wp.clone(a)
            return memo[id(a)]

        for name, value in self.__dict__.items():
            if isinstance(value, wp.array):
                value = clone(value)
            elif isinstance(value, tuple) and value and isinstance(value[0], wp.array):
                value = tuple(clone(a) for a in value)
            elif name == "_host":
                value = {}
            elif name == "_launches":  # its records name this gripper's arrays
                value = LaunchCache(self.device)
            elif name not in ("device", "driver"):  # those two are shared (immutable)
                value = copy.deepcopy(value, memo)
            other.__dict__[name] = value
        return other

    # -- state -----------------------------------------------------------------------------
    def _numpy(self, name: str) -> np.ndarray:
        """Read-only numpy copy of the Warp array ``name``, made once after each change (downloaded
        from a GPU; copied on the CPU, where ``numpy()`` would be a view that the next kernel
        overwrites under a caller who kept it)."""
        cached = self._host.get(name)
        if cached is None:
            array = getattr(self, name)
            values = array.numpy()
            cached = self._host[name] = _read_only(values.copy() if array.device.is_cpu else values)
        return cached

    def _changed(self) -> None:
        self._host.clear()

    def device_state_changed(self) -> None:
        """Tell the gripper that its device arrays changed outside its own calls (a replayed graph
        of its launches: ``PickupScene``'s control period): the host copies its readers return
        (``gap``, ``q``, ``tip_force``, ...) are read again."""
        self._changed()

    def _launch(self, key, kernel, inputs: list, outputs: list, keep: tuple = ()) -> None:
        """Launch ``kernel`` over the worlds, recorded under ``key`` and replayed (``LaunchCache``)."""
        self._launches.launch(key, kernel, self.num_worlds, inputs, outputs, keep)

    @property
    def arrays(self) -> GripperArrays:
        """The state's Warp arrays (read them in kernels; the gripper's kernels write them)."""
        return GripperArrays(self._q, self._gap, self._tip_force, self._pad_force)

    @property
    def targets(self) -> GripperTargets:
        """The control period's targets as Warp arrays on the device (written by :meth:`begin_step`,
        or by a kernel before :meth:`begin_step_to_targets`)."""
        return GripperTargets(self._target_position, self._target_orientation, self._target_gap)

    @property
    def plan_limits(self) -> wp.array:
        """[W] vec2d Warp array: :meth:`held_at_limit` on the device, (load, 1.0 if held else 0.0),
        written by :meth:`plan_substep`."""
        return self._limits

    @property
    def move_fraction(self) -> wp.array:
        """[W] float64 Warp array: the fraction of the planned substep motion that
        :meth:`move_as_planned` applies (written by :meth:`plan_substep` and :meth:`move`; a
        caller's kernel may write it in between: the force limit on the device)."""
        return self._fraction

    @property
    def q(self) -> np.ndarray:
        return self._numpy("_q")

    @property
    def gap(self) -> np.ndarray:
        return self._numpy("_gap")

    @property
    def tip_force(self) -> np.ndarray:
        return self._numpy("_tip_force")

    @property
    def grip_stiffness(self) -> np.ndarray:
        return self._numpy("_grip_stiffness")

    @property
    def pad_force(self) -> np.ndarray:
        return self._numpy("_pad_force")

    @property
    def wrist_force(self) -> np.ndarray:
        return _read_only(wrist_force(self.pad_force))

    def pad_force_angles(self) -> np.ndarray:
        """[W, 2] rad, in [0, pi]: angle of the object's total force on each pad (``pad_force``)
        from the pad's opening direction (left +x_G, right -x_G): 0 where the object pushes the pad
        straight out along the closing axis (an antipodal grasp), atan(friction) at the edge of a
        Coulomb cone, over pi/2 where it pulls the pad inward; 0 where the force is zero."""
        _, quat = self.flange_pose()
        opening = quat_to_matrix(quat)[:, None, :, 0] * np.array([1.0, -1.0])[None, :, None]  # [W, 2, 3]
        pad_force = self.pad_force
        along = np.sum(pad_force * opening, axis=-1)
        across = np.linalg.norm(pad_force - along[..., None] * opening, axis=-1)
        return np.arctan2(across, along)

    def reset(self, mask: np.ndarray, flange_xz: np.ndarray) -> None:
        """Worlds in ``mask`` [W]: flange at ``flange_xz`` [W, 2] (m, world x and z; rows outside the
        mask are ignored) and ``START_FLANGE_HEIGHT``, pointing down, jaw open, no force."""
        d = self.device
        wp.launch(gk.reset_worlds, dim=self.num_worlds,
                  inputs=[wp.array(np.asarray(mask, dtype=np.int32), dtype=wp.int32, device=d),
                          wp.array(np.asarray(flange_xz, dtype=np.float64), dtype=wp.vec2d, device=d),
                          START_FLANGE_HEIGHT],
                  outputs=[self._q, self._gap, self._tip_force, self._pad_force, self._grip_stiffness,
                           self._stopped_push], device=d)
        self._changed()

    # -- kinematics ------------------------------------------------------------------------
    def flange_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Flange positions [W, 3] (m) and orientations [W, 4] (xyzw) in the world."""
        return fk_analytic(self.q)

    def pad_poses(self, q: np.ndarray | None = None, gap: np.ndarray | None = None):
        """Collision-box centres [W, 2, 3] (m) and orientations [W, 2, 4] (xyzw) of the pads for
        joints ``q`` [W, 6] and gap [W] (m; default: the current ones)."""
        q = self.q if q is None else q
        gap = self.gap if gap is None else gap
        return pad_box_poses(*fk_analytic(q), gap)

    def tcp_positions(self) -> np.ndarray:
        """Tool centre point (midpoint between the pad inner faces) [W, 3], m."""
        centers, _ = self.pad_poses()
        return centers.mean(axis=1)

    def pad_target_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """The pad box poses the last :meth:`move` wrote (float64; before any move: centres at the
        origin, identity orientations; a reset does not write them): centres [W, 2, 3] (m) and
        orientations [W, 2, 4] (xyzw), with the flange lifted so that no pad box corner is below
        ``GROUND_CLEARANCE`` (the lowest corner of a box with centre c, rotation R and half extents
        h is at ``c_y - sum_j |R[1, j]| h_j``; both pads share R)."""
        quat = self._numpy("_pad_quat")
        return self._numpy("_pad_center").copy(), np.repeat(quat[:, None, :], 2, axis=1)

    # -- actuation (one control period) ---------------------------------------------------
    def begin_step(self, target_pos: np.ndarray, target_quat: np.ndarray, target_gap: np.ndarray,
                   active: np.ndarray | None = None) -> None:
        """Start a control period toward flange targets [W, 3] m, [W, 4] xyzw (joint limits
        enforced; the wrist turns the shortest way round) and the jaw gap ``target_gap`` [W] (m,
        finite; clipped to the stroke by the driver). Worlds with ``active == False`` [W] (default:
        all active) keep wrist and jaw this period."""
        n = self.num_worlds
        target_gap = _finite(target_gap, "target_gap")
        if target_gap.shape != (n,):
            raise ValueError(f"target_gap must have shape [{n}], got {target_gap.shape}")
        target_pos = _finite(target_pos, "target_pos")
        if target_pos.shape != (n, 3):
            raise ValueError(f"target_pos must have shape [{n}, 3], got {target_pos.shape}")
        unit_quat(target_quat, "target_quat")  # checked; the kernels renormalise it
        target_quat = np.asarray(target_quat, dtype=np.float64)
        if target_quat.shape != (n, 4):
            raise ValueError(f"target_quat must have shape [{n}, 4], got {target_quat.shape}")
        position, orientation, gap = self.targets
        position.assign(target_pos)
        orientation.assign(target_quat)
        gap.assign(target_gap)
        self.begin_step_to_targets(active)

    def begin_step_to_targets(self, active: np.ndarray | None = None) -> None:
        """:meth:`begin_step` toward the targets in :attr:`targets` as they are on the device (a
        kernel wrote them: the env's action decoding), with no transfer but ``active`` [W] bool's
        (default all; uploaded when it changes)."""
        active = np.ones(self.num_worlds, np.int32) if active is None else np.asarray(active, dtype=bool).astype(np.int32)
        if not np.array_equal(active, self._active_host):
            self._active.assign(active)
            self._active_host = active
        position, orientation, _ = self.targets
        self._launch("begin", gk.begin_period, [self._q, position, orientation], [self._q_start, self._q_move])

    def plan_substep(self, k: int, count: int, h: float) -> None:
        """Plan substep ``k`` of ``count`` (length ``h`` s): the jaw driver moves the gap toward
        the period's target (speed and force limits, ``gripper.driver``) on the forces of the last
        :meth:`sense` and the wrist is to move ``(k + 1) / count`` of the way. Inactive worlds keep
        wrist and jaw. Nothing moves until :meth:`move`. Also finds, per world, the actuator load
        at the substep start and whether the world stays held at its limit (:meth:`held_at_limit`),
        and sets the fraction of the plan a first try applies (:meth:`move_as_planned`: 0 where
        held, 1 elsewhere; a :meth:`move` with a fraction replaces it)."""
        config = self.driver.config
        key = ("plan", k, count, h, config.closing_speed, config.grip_force_limit, self.wrist_force_limit,
               HOLD_COSINE)  # every scalar argument: a record replays the values it was made with
        self._launch(key, gk.plan_substep,
                     [self._q, self._gap, self._tip_force, self._pad_force, self._grip_stiffness, self._stopped_push,
                      self._q_start, self._q_move, self._target_gap, self._active, (k + 1) / count,
                      config.closing_speed * h, config.grip_force_limit, self.wrist_force_limit, HOLD_COSINE],
                     [self._q_before, self._q_plan, self._gap_before, self._gap_plan, self._force_before, self._limits,
                      self._fraction])
        self._host.pop("_limits", None)

    def held_at_limit(self) -> tuple[np.ndarray, np.ndarray]:
        """(load [W], held [W] bool) at the start of the planned substep: the actuator load
        (``wrist.force_limit.actuator_load``: 1 = at a limit) of the last sensed forces, and the
        worlds whose actuators stay stopped this substep without trying their planned motion
        (``wrist.force_limit.limited_substep``'s ``held``), like a protective stop: at a
        limit at the substep start (load >= 1), their last try stopped by the limit,
        and the planned flange slide within ~26 degrees of that stopped one (cosine >=
        ``HOLD_COSINE``, any speed), whatever turn of the wrist is planned with it: the force limit
        scales the whole motion (slide, turn and the jaw's closing) by one fraction, and a world at
        its limit is stopped at fraction 0 when its try reads over, so a try that pushes on the same
        way with a turn ends stopped as the held world does, with two more solves (a learner's
        policy turns its wrist a little in every action; 1-3 degrees a control step measured while
        pressing a cube into the ground). A world whose load fell below its limit (the object gave
        way), whose slide turned away, or that only moves its jaw or only turns its wrist (no
        slide), tries to move."""
        limits = self._numpy("_limits")
        return limits[:, 0], limits[:, 1] > 0.0

    def move(self, fraction: np.ndarray | None = None) -> None:
        """Apply the planned substep: ``fraction`` [W] (in [-1, 1]; default 1; negative: the flange
        backed off, :meth:`aim_back_off`) of the wrist's planned substep motion and of the jaw's
        planned closing (a planned opening is applied whole: it only lowers the forces), with the
        wrist lifted so that the pads stay above the ground; writes the pad box poses to move to
        (``pad_targets``, :meth:`pad_target_poses`). May be called again (a retry from the same
        start, ``wrist.force_limit``) with another fraction."""
        if fraction is None or np.all(np.asarray(fraction) == 1.0):
            self._fraction.fill_(1.0)
        else:
            self._fraction.assign(np.asarray(fraction, dtype=np.float64).reshape(self.num_worlds))
        self._move_by_fraction()

    def aim_back_off(self, pad_force: wp.array) -> None:
        """The direction and length of this substep's back-off (a :meth:`move` with a negative
        fraction f slides the flange by -f times it, ``wrist.force_limit``), from a solve's pad
        forces ``pad_force`` [W*2] (vec3, N, world: the object's force on each pad, the stopped
        solve's): along their sum, the length of the planned slide; none where the sum is within
        the wrist limit's tolerance (``FORCE_TOLERANCE`` x the limit: a squeeze) or no slide is
        planned (``kernels.aim_back_off``)."""
        min_force = FORCE_TOLERANCE * self.wrist_force_limit
        self._launch(("aim back off", id(pad_force), min_force), gk.aim_back_off,
                     [pad_force, self._q_before, self._q_plan, min_force], [self._back_off], keep=(pad_force,))
        self._host.pop("_back_off", None)

    @property
    def back_off_aim(self) -> wp.array:
        """[W] vec3d Warp array: :meth:`aim_back_off`'s result on the device (m, world)."""
        return self._back_off

    @property
    def back_off(self) -> np.ndarray:
        """[W, 3] m (world): the flange's full back-off last aimed (:meth:`aim_back_off`; zeros
        where none), a host copy."""
        return self._numpy("_back_off")

    def move_as_planned(self) -> None:
        """:meth:`move` with the force limit's first try, set on the device by :meth:`plan_substep`
        (no transfer): fraction 0 in the worlds held at their limit (:meth:`held_at_limit`), 1
        (the whole planned motion) elsewhere. Call it after :meth:`plan_substep` and before any
        :meth:`move` with a fraction in that substep (which overwrites the fraction)."""
        self._move_by_fraction()

    def _move_by_fraction(self) -> None:
        """The move kernel with the fraction array as it is."""
        self._launch("move", gk.move_pads, _move_pads_inputs(self._q_before, self._q_plan, self._gap_before,
                                                              self._gap_plan, self._fraction, self._back_off),
                     [self._q, self._gap, self._pad_center, self._pad_quat, *self.pad_targets])
        self._changed()

    def substep(self, k: int, count: int, h: float):
        """:meth:`plan_substep` then :meth:`move` with the whole wrist motion; returns
        :meth:`pad_target_poses`."""
        self.plan_substep(k, count, h)
        self.move()
        return self.pad_target_poses()

    def sense(self, pad_normal_force, pad_force=None, record_limit: bool = False) -> None:
        """The pad normal forces (N, left and right) and the object's total force on each pad (N,
        world; default: unchanged) measured at the end of the substep, as Warp arrays [W*2]
        (float32 or float64; vec3 / vec3d) on the gripper's device or array-likes [W, 2] / [W, 2, 3]:
        the readouts and the grip-stiffness estimate follow them. ``record_limit``: the last
        :meth:`move` was the force limit's accepted one (its fraction the limit's scale): a world
        that tried to move (not held, :meth:`held_at_limit`) and was stopped (fraction 0) or backed
        off (a negative fraction) remembers the push it tried, one that moved forgets, a held one
        keeps the push that stopped it (so a command turning step by step releases it)."""
        n, d = self.num_worlds, self.device
        if not isinstance(pad_normal_force, wp.array):
            pad_normal_force = wp.array(np.asarray(pad_normal_force, dtype=np.float64).reshape(2 * n),
                                        dtype=wp.float64, device=d)
        if pad_force is not None and not isinstance(pad_force, wp.array):
            pad_force = wp.array(np.asarray(pad_force, dtype=np.float64).reshape(2 * n, 3), dtype=wp.vec3d, device=d)
        total = self._no_total if pad_force is None else pad_force
        self._launch(("sense", id(pad_normal_force), id(total), record_limit), gk.sense_pads,
                     [pad_normal_force, total, int(pad_force is not None), self._gap, self._gap_before,
                      self._force_before, self._target_gap, self._q_before, self._q_plan, self._fraction,
                      self._limits, int(record_limit)],
                     [self._tip_force, self._pad_force, self._grip_stiffness, self._stopped_push],
                     keep=(pad_normal_force, total))
        self._changed()
