"""Warp kernels of the pickup task (``PickupTask``): observations, reward terms, success and
episode bookkeeping of every world, one thread per world, float64, on the simulation's device.

A control step's outputs are one packed row per world (``OUTPUT_COLUMNS``, float64): the
observation vectors (``AGENT_POS`` then ``ENV_STATE``: the float64 state and the float32
keypoints, rounded to float32 when read as observations) and the
step's result (reward, its terms, flags, the info readings), written by ``observe_worlds`` and
``evaluate_worlds`` from the gripper's state, the scene's readouts and the solver's report, all
device arrays: the host downloads the row block once per step (numpy users) or reads it as a torch
tensor on the device. The numpy functions of ``envs.task`` (``grasp_quality``,
``feature_beyond_pad_faces``, ``shaped_progress``) and ``Gripper.pad_force_angles`` stay the
reference: tests compare the two.

Frames and units: world frame (y up), m, N, Pa; quaternions xyzw; pad 0 = left (+x_G), 1 = right.
"""

from __future__ import annotations

import warp as wp

from ..gripper import PAD_BACKING, PAD_BOX_HALF_EXTENTS
from ..gripper import kernels as gk
from ..layout import AGENT_POS, ENV_STATE, NUM_KEYPOINTS
from ..sim.kernels.report import SolveRecord

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})

_F = wp.float64

#: Columns of the step result that follow the observation columns in each world's output row, in order.
RESULT_COLUMNS = ("reward", "reward_reach", "reward_grasp", "reward_lift", "reward_place", "reward_success",
                  "reward_force", "is_success", "grasped", "grasp_quality", "pierced", "goal_distance", "pad_embedding",
                  "sim_diverged", "terminated", "truncated", "elapsed", "left_tip_normal_force",
                  "right_tip_normal_force", "jaw_gap", "wrist_force", "mean_von_mises")
#: One world's output row: ``AGENT_POS`` (10), ``ENV_STATE`` (33), then ``RESULT_COLUMNS``.
OBSERVATION_SIZE = AGENT_POS.size + ENV_STATE.size
OUTPUT_COLUMNS = (*AGENT_POS.names, *ENV_STATE.names, *RESULT_COLUMNS)


def column(name: str) -> int:
    """Index of the output column ``name`` (an entry of ``RESULT_COLUMNS``)."""
    return OBSERVATION_SIZE + RESULT_COLUMNS.index(name)


_REWARD = wp.constant(column("reward"))
_REACH = wp.constant(column("reward_reach"))
_GRASP = wp.constant(column("reward_grasp"))
_LIFT = wp.constant(column("reward_lift"))
_PLACE = wp.constant(column("reward_place"))
_SUCCESS_TERM = wp.constant(column("reward_success"))
_FORCE_TERM = wp.constant(column("reward_force"))
_IS_SUCCESS = wp.constant(column("is_success"))
_GRASPED = wp.constant(column("grasped"))
_QUALITY = wp.constant(column("grasp_quality"))
_PIERCED = wp.constant(column("pierced"))
_GOAL_DISTANCE = wp.constant(column("goal_distance"))
_EMBEDDING = wp.constant(column("pad_embedding"))
_DIVERGED = wp.constant(column("sim_diverged"))
_TERMINATED = wp.constant(column("terminated"))
_TRUNCATED = wp.constant(column("truncated"))
_ELAPSED = wp.constant(column("elapsed"))
_LEFT_TIP = wp.constant(column("left_tip_normal_force"))
_RIGHT_TIP = wp.constant(column("right_tip_normal_force"))
_JAW_GAP = wp.constant(column("jaw_gap"))
_WRIST_FORCE = wp.constant(column("wrist_force"))
_MEAN_VON_MISES = wp.constant(column("mean_von_mises"))
_ENV_STATE = wp.constant(AGENT_POS.size)
_KEYPOINTS = wp.constant(NUM_KEYPOINTS)
_HALF_WIDTH = wp.constant(_F(PAD_BOX_HALF_EXTENTS[2]))   # the pad box's half extent across the pads' width
_BACKING = wp.constant(_F(PAD_BACKING))


@wp.struct
class TaskParams:
    """The task's constants (``envs.task`` and the env's config) for the kernels."""

    success_tolerance: wp.float64  # m
    friction_cone: wp.float64      # cos(atan(pad_friction)): 1 for frictionless pads
    hold_steps: wp.int32           # control steps at the goal that make a success (0 counts as 1)
    max_episode_steps: wp.int32    # truncation after this many steps
    terminate_on_success: wp.int32 # 1: a success terminates the episode; 0: it goes on (PickupConfig)
    grasp_force: wp.float64        # N, both tip forces above it: grasped
    pierce_depth: wp.float32       # m, compared with the float32 readings as numpy compares them
    reach_scale: wp.float64        # 1/m
    lift_scale: wp.float64         # 1/m
    place_scale: wp.float64        # 1/m
    centre_scale: wp.float64       # 1/m
    force_free: wp.float64         # N, wrist force that costs nothing
    force_scale: wp.float64        # N, wrist force beyond force_free that costs the full penalty


@wp.func
def shaped_progress(distance: wp.float64, scale: wp.float64):
    """``envs.task.shaped_progress``: 1 - tanh(scale distance)."""
    return _F(1.0) - wp.tanh(scale * distance)


@wp.func
def widen(v: wp.vec3):
    return wp.vec3d(_F(v[0]), _F(v[1]), _F(v[2]))


@wp.func
def force_angle(force: wp.vec3d, opening: wp.vec3d):
    """Angle (rad, [0, pi]) of a pad's total force from the pad's opening direction (unit):
    ``Gripper.pad_force_angles`` for one pad."""
    along = wp.dot(force, opening)
    across = wp.length(force - along * opening)
    return wp.atan2(across, along)


@wp.func
def beyond_width(feature: wp.vec3d, center: wp.vec3d, R: wp.mat33d):
    """How far (m) the feature point lies beyond a pad face across the pads' width, 0 within it:
    ``envs.task.feature_beyond_pad_faces``'s second column for one pad."""
    local = wp.transpose(R) * (feature - center)
    return wp.max(wp.abs(local[2]) - _HALF_WIDTH, _F(0.0))


@wp.kernel
def observe_worlds(q: wp.array(dtype=gk.vec6d), gap: wp.array(dtype=wp.float64), tip_force: wp.array(dtype=wp.vec2d),
                   feature: wp.array(dtype=wp.vec3d), feature_velocity: wp.array(dtype=wp.vec3d),
                   keypoints: wp.array(dtype=wp.vec3), goals: wp.array(dtype=wp.vec3d), params: TaskParams,
                   out: wp.array2d(dtype=wp.float64)):
    """World w's observation columns of ``out``: ``AGENT_POS`` (flange position and orientation,
    jaw gap, tip forces) and ``ENV_STATE`` (feature point, its velocity, its goal ``goals[w]`` (m,
    world), the keypoints)."""
    w = wp.tid()
    qw = q[w]
    quat = gk.flange_quat(qw)
    t = tip_force[w]
    for i in range(3):
        out[w, i] = qw[i]
    for i in range(4):
        out[w, 3 + i] = quat[i]
    out[w, 7] = gap[w]
    out[w, 8] = t[0]
    out[w, 9] = t[1]
    fp = feature[w]
    fv = feature_velocity[w]
    goal = goals[w]
    for i in range(3):
        out[w, _ENV_STATE + i] = fp[i]
        out[w, _ENV_STATE + 3 + i] = fv[i]
        out[w, _ENV_STATE + 6 + i] = goal[i]
    for k in range(_KEYPOINTS):
        p = keypoints[w * _KEYPOINTS + k]
        for i in range(3):
            out[w, _ENV_STATE + 9 + 3 * k + i] = _F(p[i])


@wp.kernel
def evaluate_worlds(q: wp.array(dtype=gk.vec6d), gap: wp.array(dtype=wp.float64), tip_force: wp.array(dtype=wp.vec2d),
                    pad_force: wp.array2d(dtype=wp.vec3d), feature: wp.array(dtype=wp.vec3d),
                    finite: wp.array(dtype=wp.int32), pad_embedding: wp.array(dtype=wp.float32),
                    report: wp.array(dtype=SolveRecord), mean_von_mises: wp.array(dtype=wp.float32),
                    live: wp.array(dtype=wp.int32), goals: wp.array(dtype=wp.vec3d), params: TaskParams,
                    held: wp.array(dtype=wp.int32),
                    elapsed: wp.array(dtype=wp.int32), out: wp.array2d(dtype=wp.float64)):
    """World w after a control step: reward terms, grasp and its quality, piercing, success (the
    hold counter ``held``), the step count ``elapsed``, divergence, termination and truncation, and
    the info readings, into its result columns of ``out`` (``envs.task.PickupTask.evaluate``'s
    rules; ``live[w] == 0``: a world being reset, whose step counts for nothing; ``goals[w]``: its
    goal, m, world)."""
    w = wp.tid()
    qw = q[w]
    g = gap[w]
    t = tip_force[w]
    pos = wp.vec3d(qw[0], qw[1], qw[2])
    R = gk.quat_matrix(gk.flange_quat(qw))
    c0, c1 = gk.pad_box_centers(pos, R, g, _BACKING)
    fp = feature[w]
    rec = report[w]
    is_live = live[w] != 0
    diverged = (rec.diverged != 0 or finite[w] == 0) and is_live
    valid = is_live and not diverged
    reach_distance = wp.length((c0 + c1) / _F(2.0) - fp)
    goal_distance = wp.length(fp - goals[w])
    grasped = t[0] > params.grasp_force and t[1] > params.grasp_force
    # the grasp quality: the worse pad's friction-cone margin times the centring across the pads' width
    opening = wp.vec3d(R[0, 0], R[1, 0], R[2, 0])
    f0 = pad_force[w, 0]
    f1 = pad_force[w, 1]
    worst = wp.cos(wp.max(force_angle(f0, opening), force_angle(f1, -opening)))
    cone = params.friction_cone
    margin = _F(0.0)
    if cone >= _F(1.0):
        if worst >= _F(1.0):
            margin = _F(1.0)
    else:
        margin = wp.min(wp.max((worst - cone) / (_F(1.0) - cone), _F(0.0)), _F(1.0))
    beyond = wp.max(beyond_width(fp, c0, R), beyond_width(fp, c1, R))
    quality = margin * shaped_progress(beyond, params.centre_scale)
    held_well = _F(0.0)
    # numpy's max / clip carry a NaN into the quality where Warp's min / max drop it: check the inputs
    if grasped and wp.isfinite(quality) and wp.isfinite(f0) and wp.isfinite(f1) and wp.isfinite(fp):
        held_well = quality
    embedding = pad_embedding[w]
    pierced = rec.penetration > params.pierce_depth or embedding > params.pierce_depth
    at_goal = goal_distance < params.success_tolerance and grasped and (not pierced) and valid
    count = int(0)
    if at_goal:
        count = held[w] + 1
    held[w] = count
    steps = elapsed[w] + 1
    elapsed[w] = steps
    success = count >= wp.max(params.hold_steps, 1)
    reach = shaped_progress(reach_distance, params.reach_scale) * _F(0.5)
    grasp = _F(0.5) * held_well
    lift = held_well * shaped_progress(goal_distance, params.lift_scale) * _F(2.0)
    place = held_well * shaped_progress(goal_distance, params.place_scale)
    bonus = _F(0.0)
    if success:
        bonus = _F(10.0)
    wrist_force = wp.length(f0 + f1)
    # the pads pressing the object with more than the free force: -1 from force_free + force_scale on
    # (a non-finite force costs nothing, as numpy's reference says: the scene refuses such forces)
    force = _F(0.0)
    if wp.isfinite(wrist_force):
        force = -wp.min(wp.max((wrist_force - params.force_free) / params.force_scale, _F(0.0)), _F(1.0))
    if not valid:
        force = _F(0.0)
        reach = _F(0.0)
        grasp = _F(0.0)
        lift = _F(0.0)
        place = _F(0.0)
        bonus = _F(0.0)
    out[w, _REWARD] = ((((_F(0.0) + reach) + grasp) + lift + place) + bonus) + force
    out[w, _REACH] = reach
    out[w, _GRASP] = grasp
    out[w, _LIFT] = lift
    out[w, _PLACE] = place
    out[w, _SUCCESS_TERM] = bonus
    out[w, _FORCE_TERM] = force
    out[w, _IS_SUCCESS] = wp.where(success, _F(1.0), _F(0.0))
    out[w, _GRASPED] = wp.where(grasped, _F(1.0), _F(0.0))
    out[w, _QUALITY] = held_well
    out[w, _PIERCED] = wp.where(pierced, _F(1.0), _F(0.0))
    out[w, _GOAL_DISTANCE] = goal_distance
    out[w, _EMBEDDING] = _F(embedding)
    out[w, _DIVERGED] = wp.where(diverged, _F(1.0), _F(0.0))
    out[w, _TERMINATED] = wp.where(success and is_live and params.terminate_on_success != 0, _F(1.0), _F(0.0))
    out[w, _TRUNCATED] = wp.where((diverged or steps >= params.max_episode_steps) and is_live, _F(1.0), _F(0.0))
    out[w, _ELAPSED] = _F(steps)
    out[w, _LEFT_TIP] = t[0]
    out[w, _RIGHT_TIP] = t[1]
    out[w, _JAW_GAP] = g
    out[w, _WRIST_FORCE] = wrist_force
    out[w, _MEAN_VON_MISES] = _F(mean_von_mises[w])


@wp.kernel
def reset_counters(mask: wp.array(dtype=wp.int32), held: wp.array(dtype=wp.int32), elapsed: wp.array(dtype=wp.int32)):
    """Worlds with ``mask[w] != 0`` start a new episode: no step taken, not at the goal."""
    w = wp.tid()
    if mask[w] != 0:
        held[w] = 0
        elapsed[w] = 0
