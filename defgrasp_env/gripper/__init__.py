"""Robotiq 2F-85-like parallel-jaw gripper: closed-form linkage, pad geometry and actuation.

Frame G (the wrist flange): origin at the gripper mounting face, fingers along -y_G (approach),
closing axis x_G (left pad at +x_G, right pad at -x_G), z_G = x_G x y_G. See ``linkage`` for the
model, ``driver`` for the speed/force-limited actuation and ``gripper`` for :class:`Gripper`, the
batched gripper-on-a-wrist state that the pickup scene drives, stepped on the simulation's device by
the Warp kernels of ``kernels`` (the numpy functions here are their reference). All lengths in m, angles in rad.
"""

from .driver import (
    CLOSING_SPEED_RANGE_MM_S,
    CONTACT_FORCE,
    GRIP_FORCE_RANGE,
    GripperConfig,
    GripperDriver,
    driver_step,
    update_grip_stiffness,
)
from .gripper import (GROUND_CLEARANCE, PAD_BACKING, PAD_BOX_HALF_EXTENTS, START_FLANGE_HEIGHT, Gripper, GripperArrays,
                      GripperTargets, lift_above_ground, pad_box_poses, pad_reach)
from .linkage import (
    ARC_PHASE,
    ARC_RADIUS,
    GAP_MAX,
    GAP_MIN,
    GAP_OFFSET,
    PAD_HALF_EXTENTS,
    PAD_INWARD_NORMALS,
    PAD_NAMES,
    THETA_MAX,
    THETA_MIN,
    gap_from_theta,
    pad_arc_centers,
    pad_boxes,
    pad_centers,
    tcp_offset,
    theta_from_gap,
)

__all__ = [
    "ARC_PHASE", "ARC_RADIUS", "CLOSING_SPEED_RANGE_MM_S", "CONTACT_FORCE", "GAP_MAX", "GAP_MIN", "GAP_OFFSET",
    "GRIP_FORCE_RANGE", "GROUND_CLEARANCE", "Gripper", "GripperArrays", "GripperConfig", "GripperTargets", "lift_above_ground", "pad_box_poses", "pad_reach", "PAD_BACKING", "PAD_BOX_HALF_EXTENTS",
    "START_FLANGE_HEIGHT", "GripperDriver", "PAD_HALF_EXTENTS", "PAD_INWARD_NORMALS",
    "PAD_NAMES", "THETA_MAX", "THETA_MIN", "driver_step", "gap_from_theta", "pad_arc_centers",
    "pad_boxes", "pad_centers", "tcp_offset", "theta_from_gap", "update_grip_stiffness",
]
