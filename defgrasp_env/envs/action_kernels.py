"""Warp kernels that decode a control step's actions into the gripper's targets, one thread per
world, float64, on the simulation's device: per ``action_mode`` the rules of ``envs.actions``
(``delta_targets``, ``absolute_targets``, ``topdown_targets``, ``turn_toward``) with the
quaternion helpers of ``transforms`` (``axis_angle_to_quat`` with numpy's ``sinc``,
``quat_multiply``, ``quat_normalize``) carried out in the same order of operations. They write
``Gripper.targets`` (flange position m, orientation xyzw, jaw gap m); the numpy decoders stay the
reference (tests compare the two).

Actions arrive checked and clipped (``envs.actions.check_actions``) as float64 [W, A] of the
layout of ``action_mode`` (``defgrasp_env.layout``).
"""

from __future__ import annotations

import math

import warp as wp

from ..gripper import kernels as gk
from ..layout import JAW_GAP_MAX, JAW_GAP_MIN

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})

_F = wp.float64
_PI = wp.constant(_F(math.pi))
_GAP_MAX = wp.constant(_F(JAW_GAP_MAX))
_GAP_SPAN = wp.constant(_F(JAW_GAP_MIN - JAW_GAP_MAX))


@wp.struct
class ActionScales:
    """The config's speed limits and control period."""

    linear_speed: wp.float64   # m/s (``max_linear_speed``)
    angular_speed: wp.float64  # rad/s (``max_angular_speed``)
    dt: wp.float64             # s (one control period)


@wp.func
def canonical(q: wp.vec4d):
    """``transforms._canonical``: ``q`` over its norm, w >= 0."""
    u = q / wp.length(q)
    if u[3] < _F(0.0):
        u = -u
    return u


@wp.func
def hamilton(a: wp.vec4d, b: wp.vec4d):
    """``transforms._mul``: the Hamilton product a b (xyzw)."""
    return wp.vec4d(a[3] * b[0] + a[0] * b[3] + a[1] * b[2] - a[2] * b[1],
                    a[3] * b[1] - a[0] * b[2] + a[1] * b[3] + a[2] * b[0],
                    a[3] * b[2] + a[0] * b[1] - a[1] * b[0] + a[2] * b[3],
                    a[3] * b[3] - a[0] * b[0] - a[1] * b[1] - a[2] * b[2])


@wp.func
def quat_multiply(a: wp.vec4d, b: wp.vec4d):
    """``transforms.quat_multiply``: the canonical product of the two renormalised quaternions."""
    return canonical(hamilton(a / wp.length(a), b / wp.length(b)))


@wp.func
def quat_normalize(q: wp.vec4d):
    """``transforms.quat_normalize``."""
    return canonical(q / wp.length(q))


@wp.func
def axis_angle_quat(v: wp.vec3d):
    """``transforms.axis_angle_to_quat``: sin(angle / 2) / angle as numpy's ``0.5 sinc(half / pi)``."""
    angle = wp.length(v)
    half = _F(0.5) * angle
    x = half / _PI
    if x == _F(0.0):
        x = _F(1.0e-20)
    y = _PI * x
    scale = _F(0.5) * (wp.sin(y) / y)
    return canonical(wp.vec4d(v[0] * scale, v[1] * scale, v[2] * scale, wp.cos(half)))


@wp.func
def turn_toward(quat: wp.vec4d, target: wp.vec4d, scales: ActionScales):
    """``envs.actions.turn_toward``: one control period from ``quat`` toward ``target`` the
    shortest way, no faster than the angular speed."""
    rel = quat_multiply(target, wp.vec4d(-quat[0], -quat[1], -quat[2], quat[3]))
    if rel[3] < _F(0.0):
        rel = -rel
    xyz = wp.vec3d(rel[0], rel[1], rel[2])
    s = wp.length(xyz)
    angle = _F(2.0) * wp.atan2(s, rel[3])
    frac = wp.min(_F(1.0), scales.angular_speed * scales.dt / wp.max(angle, _F(1e-12)))
    axis = xyz / wp.max(s, _F(1e-12))
    return quat_normalize(quat_multiply(axis_angle_quat(axis * (angle * frac)), quat))


@wp.func
def jaw_gap(command: wp.float64):
    """``layout.jaw_command_to_gap``."""
    return _GAP_MAX + _GAP_SPAN * (command + _F(1.0)) / _F(2.0)


@wp.func
def moved(pos: wp.vec3d, action: wp.array2d(dtype=wp.float64), w: int, scales: ActionScales):
    """The flange position after the velocity action's first three entries for one period."""
    return wp.vec3d(pos[0] + action[w, 0] * scales.linear_speed * scales.dt,
                    pos[1] + action[w, 1] * scales.linear_speed * scales.dt,
                    pos[2] + action[w, 2] * scales.linear_speed * scales.dt)


@wp.kernel
def delta_targets(action: wp.array2d(dtype=wp.float64), q: wp.array(dtype=gk.vec6d), scales: ActionScales,
                  position: wp.array(dtype=wp.vec3d), orientation: wp.array(dtype=wp.vec4d),
                  gap: wp.array(dtype=wp.float64)):
    """``DELTA_ACTION`` [W, 7]: linear and angular velocities (in units of the speed limits) and
    the jaw command."""
    w = wp.tid()
    qw = q[w]
    a = scales.angular_speed
    rotation = wp.vec3d(action[w, 3] * a * scales.dt, action[w, 4] * a * scales.dt, action[w, 5] * a * scales.dt)
    position[w] = moved(wp.vec3d(qw[0], qw[1], qw[2]), action, w, scales)
    orientation[w] = quat_normalize(quat_multiply(axis_angle_quat(rotation), gk.flange_quat(qw)))
    gap[w] = jaw_gap(action[w, 6])


@wp.kernel
def absolute_targets(action: wp.array2d(dtype=wp.float64), q: wp.array(dtype=gk.vec6d), scales: ActionScales,
                     position: wp.array(dtype=wp.vec3d), orientation: wp.array(dtype=wp.vec4d),
                     gap: wp.array(dtype=wp.float64)):
    """``ABSOLUTE_ACTION`` [W, 8]: the target position (approached no faster than the linear
    speed), orientation (turned toward no faster than the angular speed; non-zero, checked on the
    host) and gap."""
    w = wp.tid()
    qw = q[w]
    pos = wp.vec3d(qw[0], qw[1], qw[2])
    d = wp.vec3d(action[w, 0], action[w, 1], action[w, 2]) - pos
    step = wp.min(_F(1.0), scales.linear_speed * scales.dt / wp.max(wp.length(d), _F(1e-12)))
    target = quat_normalize(wp.vec4d(action[w, 3], action[w, 4], action[w, 5], action[w, 6]))
    position[w] = pos + d * step
    orientation[w] = turn_toward(gk.flange_quat(qw), target, scales)
    gap[w] = action[w, 7]


@wp.kernel
def topdown_targets(action: wp.array2d(dtype=wp.float64), q: wp.array(dtype=gk.vec6d), scales: ActionScales,
                    position: wp.array(dtype=wp.vec3d), orientation: wp.array(dtype=wp.vec4d),
                    gap: wp.array(dtype=wp.float64)):
    """``TOPDOWN_ACTION`` [W, 5]: linear velocities, the target yaw about world +y (turned toward
    no faster than the angular speed, roll and pitch back to pointing down) and the jaw command."""
    w = wp.tid()
    qw = q[w]
    position[w] = moved(wp.vec3d(qw[0], qw[1], qw[2]), action, w, scales)
    target = axis_angle_quat(wp.vec3d(_F(0.0), action[w, 3], _F(0.0)))
    orientation[w] = turn_toward(gk.flange_quat(qw), target, scales)
    gap[w] = jaw_gap(action[w, 4])


#: The decoding kernel of each ``action_mode``.
TARGET_KERNELS = {"delta": delta_targets, "absolute": absolute_targets, "topdown": topdown_targets}
