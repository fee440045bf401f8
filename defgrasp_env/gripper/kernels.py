"""Warp kernels of the batched gripper (``Gripper``): one thread per world, float64, on the
simulation's device. They carry out the rules of ``driver`` (the jaw driver and the grip-stiffness
estimate), ``linkage`` (pad centres from the gap), ``wrist.analytic`` (the flange orientation) and
the lift above the ground, the hold at the force limit and its record (``Gripper.move``,
``held_at_limit``, ``sense``) for every world: a substep's gripper work is three launches (plan,
move, sense; reset apart), so that a control step's gripper work needs no numpy over the worlds and
no full-state transfer. The numpy functions stay the reference (tests compare the two on random
inputs).

Frames and units: world frame (y up), m, rad, N; quaternions xyzw; joints ``q = (x, y, z, roll,
pitch, yaw)`` as ``vec6d``; pad 0 = left (+x_G), 1 = right.
"""

from __future__ import annotations

import math
from typing import Any

import warp as wp

from ..wrist.spec import JOINT_LOWER, JOINT_UPPER
from .driver import CONTACT_FORCE, MAX_GRIP_STIFFNESS
from .linkage import (ARC_PHASE, ARC_RADIUS, FINGER_APPROACH, FINGER_LATERAL, GAP_MAX, GAP_MIN, GAP_OFFSET,
                      KNUCKLE_APPROACH, KNUCKLE_LATERAL, PAD_APPROACH, PAD_LATERAL, THETA_MAX, THETA_MIN)

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})

vec6d = wp.types.vector(length=6, dtype=wp.float64)

_F = wp.float64
_GAP_MIN = wp.constant(_F(GAP_MIN))
_GAP_MAX = wp.constant(_F(GAP_MAX))
_GAP_OFFSET = wp.constant(_F(GAP_OFFSET))
_ARC_RADIUS = wp.constant(_F(ARC_RADIUS))
_ARC_PHASE = wp.constant(_F(ARC_PHASE))
_THETA_MIN = wp.constant(_F(THETA_MIN))
_THETA_MAX = wp.constant(_F(THETA_MAX))
_FINGER_LATERAL = wp.constant(_F(FINGER_LATERAL))
_FINGER_APPROACH = wp.constant(_F(FINGER_APPROACH))
_KNUCKLE_PAD_LATERAL = wp.constant(_F(KNUCKLE_LATERAL + PAD_LATERAL))
_KNUCKLE_PAD_APPROACH = wp.constant(_F(KNUCKLE_APPROACH + PAD_APPROACH))
_CONTACT_FORCE = wp.constant(_F(CONTACT_FORCE))
_MAX_GRIP_STIFFNESS = wp.constant(_F(MAX_GRIP_STIFFNESS))
_PI = wp.constant(_F(math.pi))
_TWO_PI = wp.constant(_F(2.0 * math.pi))
_JOINT_LOWER = wp.constant(vec6d(*(float(v) for v in JOINT_LOWER)))
_JOINT_UPPER = wp.constant(vec6d(*(float(v) for v in JOINT_UPPER)))


@wp.func
def clamp_joints(q: vec6d):
    """Joints clipped to the URDF's limits (``wrist.spec.clamp_joints``)."""
    out = vec6d()
    for i in range(6):
        out[i] = wp.min(wp.max(q[i], _JOINT_LOWER[i]), _JOINT_UPPER[i])
    return out


@wp.func
def flange_quat(q: vec6d):
    """Flange orientation (x, y, z, w; w >= 0) Rz(q3) Rx(q4) Ry(q5), as ``wrist.analytic.fk_analytic``."""
    h = _F(0.5)
    cz = wp.cos(h * q[3])
    cx = wp.cos(h * q[4])
    cy = wp.cos(h * q[5])
    sz = wp.sin(h * q[3])
    sx = wp.sin(h * q[4])
    sy = wp.sin(h * q[5])
    p0 = cz * sx
    p1 = sz * sx
    p2 = cx * sz
    p3 = cz * cx
    out = wp.vec4d(cy * p0 - sy * p2, cy * p1 + sy * p3, cy * p2 + sy * p0, cy * p3 - sy * p1)
    if out[3] < _F(0.0):
        out = -out
    return out


@wp.func
def quat_matrix(q: wp.vec4d):
    """Rotation matrix of a unit quaternion (x, y, z, w), renormalised, as ``transforms.quat_to_matrix``."""
    u = q / wp.length(q)
    x = u[0]
    y = u[1]
    z = u[2]
    w = u[3]
    one = _F(1.0)
    two = _F(2.0)
    return wp.mat33d(one - two * (y * y + z * z), two * (x * y - w * z), two * (x * z + w * y),
                     two * (x * y + w * z), one - two * (x * x + z * z), two * (y * z - w * x),
                     two * (x * z - w * y), two * (y * z + w * x), one - two * (x * x + y * y))


@wp.func
def left_pad_center(gap: wp.float64):
    """Left pad centre (m, frame G; z = 0) for a jaw gap (clipped to the stroke): ``linkage.pad_centers``
    of ``linkage.theta_from_gap``."""
    g = wp.min(wp.max(gap, _GAP_MIN), _GAP_MAX)
    c = wp.min(wp.max((_F(0.5) * g - _GAP_OFFSET) / _ARC_RADIUS, _F(-1.0)), _F(1.0))
    t = wp.min(wp.max(wp.acos(c) - _ARC_PHASE, _THETA_MIN), _THETA_MAX)
    lateral = _KNUCKLE_PAD_LATERAL + _FINGER_LATERAL * wp.cos(t) - _FINGER_APPROACH * wp.sin(t)
    down = _KNUCKLE_PAD_APPROACH + _FINGER_LATERAL * wp.sin(t) + _FINGER_APPROACH * wp.cos(t)
    return wp.vec3d(lateral, -down, _F(0.0))


@wp.func
def _rot_z(a: wp.float64):
    c = wp.cos(a)
    s = wp.sin(a)
    return wp.mat33d(c, -s, _F(0.0), s, c, _F(0.0), _F(0.0), _F(0.0), _F(1.0))


@wp.func
def _rot_x(a: wp.float64):
    c = wp.cos(a)
    s = wp.sin(a)
    return wp.mat33d(_F(1.0), _F(0.0), _F(0.0), _F(0.0), c, -s, _F(0.0), s, c)


@wp.func
def ik_joints(pos: wp.vec3d, quat: wp.vec4d):
    """Wrist joints (clamped to the limits) for a flange target at ``pos`` (m) with orientation
    ``quat`` (xyzw, renormalised): ``wrist.analytic.ik_joints`` for one target (roll and pitch from
    the flange's y axis, 0 roll at the gimbal lock, the least-squares yaw of the rest)."""
    R = quat_matrix(quat)
    r0 = R[0, 1]
    r1 = R[1, 1]
    pitch = wp.asin(wp.min(wp.max(R[2, 1], _F(-1.0)), _F(1.0)))
    roll = _F(0.0)
    if wp.sqrt(r0 * r0 + r1 * r1) >= _F(1e-9):
        roll = wp.atan2(-r0, r1)
    roll = wp.min(wp.max(roll, _JOINT_LOWER[3]), _JOINT_UPPER[3])
    pitch = wp.min(wp.max(pitch, _JOINT_LOWER[4]), _JOINT_UPPER[4])
    M = wp.transpose(_rot_z(roll) * _rot_x(pitch)) * R
    yaw = wp.atan2(M[0, 2] - M[2, 0], M[0, 0] + M[2, 2])
    return clamp_joints(vec6d(pos[0], pos[1], pos[2], roll, pitch, yaw))


@wp.func
def wrap_angle(a: wp.float64):
    """``a`` (rad) wrapped to [-pi, pi): ``(a + pi) % (2 pi) - pi`` with numpy's floored remainder."""
    m = wp.mod(a + _PI, _TWO_PI)
    if m < _F(0.0):
        m = m + _TWO_PI
    return m - _PI


@wp.func
def pad_box_centers(flange_pos: wp.vec3d, R: wp.mat33d, gap: wp.float64, backing: wp.float64):
    """Collision-box centres (m, world) of the left and right pad for a flange at ``flange_pos`` (m)
    with rotation ``R`` and a jaw gap (m, clipped to the stroke), the boxes reaching ``backing`` m
    behind the pads' faces: ``gripper._pad_box_centers`` for one world."""
    left = left_pad_center(gap)
    lateral = wp.vec3d(R[0, 0], R[1, 0], R[2, 0]) * (left[0] + backing / _F(2.0))
    down = wp.vec3d(R[0, 1], R[1, 1], R[2, 1]) * left[1]
    across = wp.vec3d(R[0, 2], R[1, 2], R[2, 2]) * left[2]
    return flange_pos + ((lateral + down) + across), flange_pos + ((-lateral + down) + across)


@wp.func
def driver_gap(cmd: wp.float64, gap: wp.float64, max_move: wp.float64, force_left: wp.float64,
               force_right: wp.float64, stiffness: wp.float64, force_limit: wp.float64):
    """The jaw's new gap (m) after one driver step: ``driver.driver_step`` for one world (speed
    limit ``max_move`` m per step, force stop / regulation at ``force_limit`` N)."""
    cur = wp.min(wp.max(gap, _GAP_MIN), _GAP_MAX)
    target = wp.min(wp.max(cmd, _GAP_MIN), _GAP_MAX)
    move = wp.min(wp.max(target - cur, -max_move), max_move)
    grip = _F(0.5) * (force_left + force_right)
    new_move = move
    if stiffness > _F(0.0):
        allowed = (force_limit - grip) / stiffness
        new_move = wp.min(wp.max(wp.max(move, -allowed), -max_move), max_move)
    elif move < _F(0.0) and grip >= force_limit:
        new_move = _F(0.0)
    return wp.min(wp.max(cur + new_move, _GAP_MIN), _GAP_MAX)


@wp.func
def grip_stiffness_after(k: wp.float64, g0: wp.float64, g1: wp.float64, f0: wp.float64, f1: wp.float64,
                         cmd: wp.float64):
    """``driver.update_grip_stiffness`` for one world (N/m)."""
    closing = g0 - g1
    touch0 = f0 >= _CONTACT_FORCE
    touch1 = f1 >= _CONTACT_FORCE
    step = _F(1e-6)
    moved = wp.abs(closing) >= step
    secant = _F(0.0)
    if moved:
        secant = (f1 - f0) / closing
    halfway = _F(0.0)
    if closing >= step:
        halfway = _F(2.0) * f1 / closing
    out = k
    if touch0 and touch1 and moved and secant > _F(0.0):
        out = secant
    elif (not touch0) and touch1 and closing >= step:
        out = wp.max(k, halfway)
    elif (not touch0) and (not touch1) and closing >= step:
        out = _F(0.5) * k
    if ((not touch1) and cmd >= g1) or out < _F(1.0):
        out = _F(0.0)
    return wp.min(out, _MAX_GRIP_STIFFNESS)


@wp.func
def actuator_load(pad_left: wp.vec3d, pad_right: wp.vec3d, tip_left: wp.float64, tip_right: wp.float64,
                  wrist_limit: wp.float64, grip_limit: wp.float64):
    """``wrist.force_limit.actuator_load`` for one world: the larger of the wrist force over its limit
    and the larger pad normal force over ``grip_limit + wrist_limit``; 0 where the wrist limit is inf."""
    if not wp.isfinite(wrist_limit):
        return _F(0.0)
    wrist = wp.length(pad_left + pad_right)
    return wp.max(wrist / wrist_limit, wp.max(tip_left, tip_right) / (grip_limit + wrist_limit))


@wp.kernel
def begin_period(q: wp.array(dtype=vec6d), target_position: wp.array(dtype=wp.vec3d),
                 target_orientation: wp.array(dtype=wp.vec4d), q_start: wp.array(dtype=vec6d),
                 q_move: wp.array(dtype=vec6d)):
    """World w's control period toward its flange target: the joints at its start and the joint
    motion to the target's (``ik_joints``), the wrist's angles the shortest way round."""
    w = wp.tid()
    qs = q[w]
    q_start[w] = qs
    m = ik_joints(target_position[w], target_orientation[w]) - qs
    for i in range(3, 6):
        m[i] = wrap_angle(m[i])
    q_move[w] = m


@wp.kernel
def plan_substep(q: wp.array(dtype=vec6d), gap: wp.array(dtype=wp.float64), tip_force: wp.array(dtype=wp.vec2d),
                 pad_force: wp.array2d(dtype=wp.vec3d), grip_stiffness: wp.array(dtype=wp.float64),
                 stopped_push: wp.array(dtype=wp.vec3d), q_start: wp.array(dtype=vec6d),
                 q_move: wp.array(dtype=vec6d), target_gap: wp.array(dtype=wp.float64),
                 active: wp.array(dtype=wp.int32), period_fraction: wp.float64, max_move: wp.float64,
                 grip_limit: wp.float64, wrist_limit: wp.float64, hold_cosine: wp.float64,
                 q_before: wp.array(dtype=vec6d), q_plan: wp.array(dtype=vec6d), gap_before: wp.array(dtype=wp.float64),
                 gap_plan: wp.array(dtype=wp.float64), force_before: wp.array(dtype=wp.float64),
                 limits: wp.array(dtype=wp.vec2d), fraction: wp.array(dtype=wp.float64)):
    """Plan world w's substep: the jaw driver's gap on the last sensed forces, the wrist
    ``period_fraction`` of the way from ``q_start`` by ``q_move`` (joint limits kept), the state at
    the substep start kept for ``move`` and ``sense``; an inactive world keeps wrist and jaw.
    ``limits[w]`` = (actuator load at the start, 1 if the world stays held at its limit
    (``Gripper.held_at_limit``) else 0); ``fraction[w]``: the part of the plan a first try
    applies (``Gripper.move_as_planned``): 0 where held, else 1."""
    w = wp.tid()
    t = tip_force[w]
    g = gap[w]
    qw = q[w]
    q_before[w] = qw
    gap_before[w] = g
    force_before[w] = (t[0] + t[1]) / _F(2.0)
    new_gap = driver_gap(target_gap[w], g, max_move, t[0], t[1], grip_stiffness[w], grip_limit)
    planned = qw
    if active[w] != 0:
        planned = clamp_joints(q_start[w] + q_move[w] * period_fraction)
        g = new_gap
    q_plan[w] = planned
    gap_plan[w] = g
    load = actuator_load(pad_force[w, 0], pad_force[w, 1], t[0], t[1], wrist_limit, grip_limit)
    push = wp.vec3d(planned[0] - qw[0], planned[1] - qw[1], planned[2] - qw[2])
    stopped = stopped_push[w]
    norms = wp.length(stopped) * wp.length(push)
    held = _F(0.0)
    if norms > _F(0.0) and wp.dot(stopped, push) >= hold_cosine * norms and load >= _F(1.0):
        held = _F(1.0)
    limits[w] = wp.vec2d(load, held)
    fraction[w] = _F(1.0) - held


@wp.kernel
def move_pads(q_before: wp.array(dtype=vec6d), q_plan: wp.array(dtype=vec6d), gap_before: wp.array(dtype=wp.float64),
              gap_plan: wp.array(dtype=wp.float64), fraction: wp.array(dtype=wp.float64),
              back_off: wp.array(dtype=wp.vec3d), half_extents: wp.vec3d, backing: wp.float64, clearance: wp.float64,
              q: wp.array(dtype=vec6d), gap: wp.array(dtype=wp.float64), pad_center: wp.array2d(dtype=wp.vec3d),
              pad_quat: wp.array(dtype=wp.vec4d), target_positions: wp.array(dtype=wp.vec3),
              target_orientations: wp.array(dtype=wp.quat)):
    """Apply ``fraction[w]`` of world w's planned wrist motion and jaw closing (a planned opening
    whole; a negative fraction f backs the flange off by -f ``back_off[w]`` (m, world:
    ``aim_back_off``) from the substep start within the joint limits, orientation and jaw as they
    were), lift the flange so that no pad-box corner (half extents ``half_extents``, the pad's box
    reaching ``backing`` m behind its face) is below ``clearance``, and write the joints, gap and
    the pads' box poses: float64 (``pad_center`` [W, 2], ``pad_quat`` [W]) and float32 for the FEM
    (``target_positions`` / ``target_orientations`` [W*2], pad 0 then 1 per world)."""
    w = wp.tid()
    f = fraction[w]
    qb = q_before[w]
    qw = q_plan[w]
    g0 = gap_before[w]
    g = gap_plan[w]
    if f < _F(0.0):  # a back-off: the flange slides by -f back_off within the joint limits; orientation, jaw kept
        b = back_off[w] * (-f)
        qw = clamp_joints(vec6d(qb[0] + b[0], qb[1] + b[1], qb[2] + b[2], qb[3], qb[4], qb[5]))
        g = wp.max(g, g0)
    elif f < _F(1.0):
        qw = qb + (qw - qb) * f
        if g < g0:
            g = g0 + (g - g0) * f
    quat = flange_quat(qw)
    R = quat_matrix(quat)
    c0, c1 = pad_box_centers(wp.vec3d(qw[0], qw[1], qw[2]), R, g, backing)
    reach = (-(wp.abs(R[1, 0]) * half_extents[0]) - wp.abs(R[1, 2]) * half_extents[2]) - wp.abs(R[1, 1]) * half_extents[1]
    lowest = wp.min(c0[1], c1[1]) + reach
    lifted = qw
    lifted[1] = lifted[1] + wp.max(clearance - lowest, _F(0.0))
    lifted = clamp_joints(lifted)
    rise = lifted[1] - qw[1]
    c0 = wp.vec3d(c0[0], c0[1] + rise, c0[2])
    c1 = wp.vec3d(c1[0], c1[1] + rise, c1[2])
    q[w] = lifted
    gap[w] = g
    pad_center[w, 0] = c0
    pad_center[w, 1] = c1
    pad_quat[w] = quat
    rot = wp.quat(wp.float32(quat[0]), wp.float32(quat[1]), wp.float32(quat[2]), wp.float32(quat[3]))
    target_positions[2 * w] = wp.vec3(wp.float32(c0[0]), wp.float32(c0[1]), wp.float32(c0[2]))
    target_positions[2 * w + 1] = wp.vec3(wp.float32(c1[0]), wp.float32(c1[1]), wp.float32(c1[2]))
    target_orientations[2 * w] = rot
    target_orientations[2 * w + 1] = rot


@wp.kernel
def aim_back_off(pad_force: wp.array(dtype=wp.vec3), q_before: wp.array(dtype=vec6d), q_plan: wp.array(dtype=vec6d),
                 min_force: wp.float64, back_off: wp.array(dtype=wp.vec3d)):
    """World w's full back-off (``move_pads`` at fraction -1), from a solve's pad forces
    ``pad_force[2w], [2w+1]`` (N, world: the object's force on each pad): the flange slides along
    their sum (the wrist yields to the push, as a back-driven motor does) by the length of the
    substep's planned slide; none where the sum is at most ``min_force`` (N: a squeeze, whose
    direction the wrist cannot relieve) or no slide is planned."""
    w = wp.tid()
    a = pad_force[2 * w]
    b = pad_force[2 * w + 1]
    net = wp.vec3d(wp.float64(a[0]) + wp.float64(b[0]), wp.float64(a[1]) + wp.float64(b[1]),
                   wp.float64(a[2]) + wp.float64(b[2]))
    qb = q_before[w]
    qp = q_plan[w]
    slide = wp.length(wp.vec3d(qp[0] - qb[0], qp[1] - qb[1], qp[2] - qb[2]))
    size = wp.length(net)
    out = wp.vec3d()
    if size > min_force and slide > _F(0.0):
        out = net * (slide / size)
    back_off[w] = out


@wp.kernel
def sense_pads(normal_force: wp.array(dtype=Any), total_force: wp.array(dtype=Any), read_total: wp.int32,
               gap: wp.array(dtype=wp.float64), gap_before: wp.array(dtype=wp.float64),
               force_before: wp.array(dtype=wp.float64), target_gap: wp.array(dtype=wp.float64),
               q_before: wp.array(dtype=vec6d), q_plan: wp.array(dtype=vec6d), fraction: wp.array(dtype=wp.float64),
               limits: wp.array(dtype=wp.vec2d), record_limit: wp.int32,
               tip_force: wp.array(dtype=wp.vec2d), pad_force: wp.array2d(dtype=wp.vec3d),
               grip_stiffness: wp.array(dtype=wp.float64), stopped_push: wp.array(dtype=wp.vec3d)):
    """World w after its accepted solve: the pad normal forces ``normal_force[2w], [2w+1]`` (N) and,
    if ``read_total``, the object's total force on each pad ``total_force`` (N, world) become the
    gripper's readings; the grip-stiffness estimate follows them (``driver.update_grip_stiffness``);
    if ``record_limit``, the force limit's outcome is remembered
    (``Gripper.sense(record_limit=True)``: the substep's fraction 0 (or a back-off, below 0) in a
    world that tried to move keeps the planned push it tried, a held world keeps its push, a world
    that moved forgets)."""
    w = wp.tid()
    f0 = wp.float64(normal_force[2 * w])
    f1 = wp.float64(normal_force[2 * w + 1])
    tip_force[w] = wp.vec2d(f0, f1)
    if read_total != 0:
        a = total_force[2 * w]
        b = total_force[2 * w + 1]
        pad_force[w, 0] = wp.vec3d(wp.float64(a[0]), wp.float64(a[1]), wp.float64(a[2]))
        pad_force[w, 1] = wp.vec3d(wp.float64(b[0]), wp.float64(b[1]), wp.float64(b[2]))
    grip_stiffness[w] = grip_stiffness_after(grip_stiffness[w], gap_before[w], gap[w], force_before[w],
                                             (f0 + f1) / _F(2.0), target_gap[w])
    if record_limit != 0 and limits[w][1] == _F(0.0):
        push = wp.vec3d()
        if fraction[w] <= _F(0.0):
            qb = q_before[w]
            qp = q_plan[w]
            push = wp.vec3d(qp[0] - qb[0], qp[1] - qb[1], qp[2] - qb[2])
        stopped_push[w] = push


@wp.kernel
def reset_worlds(mask: wp.array(dtype=wp.int32), flange_xz: wp.array(dtype=wp.vec2d), height: wp.float64,
                 q: wp.array(dtype=vec6d), gap: wp.array(dtype=wp.float64), tip_force: wp.array(dtype=wp.vec2d),
                 pad_force: wp.array2d(dtype=wp.vec3d), grip_stiffness: wp.array(dtype=wp.float64),
                 stopped_push: wp.array(dtype=wp.vec3d)):
    """Worlds with ``mask[w] != 0``: flange at (x, ``height``, z) pointing down, jaw open, no force."""
    w = wp.tid()
    if mask[w] == 0:
        return
    xz = flange_xz[w]
    q[w] = vec6d(xz[0], height, xz[1], _F(0.0), _F(0.0), _F(0.0))
    gap[w] = _GAP_MAX
    tip_force[w] = wp.vec2d()
    pad_force[w, 0] = wp.vec3d()
    pad_force[w, 1] = wp.vec3d()
    grip_stiffness[w] = _F(0.0)
    stopped_push[w] = wp.vec3d()
