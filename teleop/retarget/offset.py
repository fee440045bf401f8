"""Eq. 1-2 of the paper: the slave (flange) pose from the master (tracker) pose through a fixed
offset, T_slave^{O'} = T_O^{O'} . T_master^{O} . T_wrist^{tracker}.

Frames:

* O: the tracker system's origin (OpenVR standing universe: right-handed, +y up, +x right,
  -z forward, metres);
* O': the simulation world (right-handed, +y up, metres; CONVENTIONS.md). Both are y-up and
  right-handed, so the default frame map ``OPENVR_TO_WORLD`` is the identity: OpenVR +x -> world +x,
  +y -> +y, -z (the operator's forward) -> world -z. Pass ``frame_rotation`` to turn the operator
  to face another way (e.g. ``rot_y(pi)`` to make the operator's forward world +z);
* T_wrist^{tracker}: the flange pose in the tracker frame, identity by default as in the paper.

``calibrate(master, slave)`` solves the offset so that the current master pose maps exactly to
the current slave pose:

* mode "full" (default, eq. 2 verbatim): T_O^{O'} = T_slave . (T_master . T_wrist^{tracker})^-1.
  The offset's rotation is whatever turns the operator's current hand orientation into the
  gripper's, so translations of the hand are rotated by it too: hold the hand roughly like the
  gripper when calibrating;
* mode "align_axes": the offset's rotation stays ``frame_rotation`` (hand moving along OpenVR +x
  always moves the gripper along world +x) and the rotation part of T_wrist^{tracker} absorbs the
  difference between hand and gripper orientation; the offset's translation makes the poses meet.
  Hand rotations are then applied to the gripper about world axes.
"""

from __future__ import annotations

import numpy as np

from .._validate import check_array, check_choice
from ..se3 import check_rigid, invert

OPENVR_TO_WORLD = np.eye(3)
CALIBRATION_MODES = ("full", "align_axes")


def compose_slave_pose(offset, master_pose, tracker_to_flange=None) -> np.ndarray:
    """Eq. 2: T_slave = T_O^{O'} . T_master . T_wrist^{tracker} (all 4x4 rigid transforms)."""
    T_off = check_rigid("offset", offset)
    T_m = check_rigid("master_pose", master_pose)
    T_x = np.eye(4) if tracker_to_flange is None else check_rigid("tracker_to_flange", tracker_to_flange)
    return T_off @ T_m @ T_x


class OffsetRetargeter:
    """Holds T_O^{O'} (``offset``) and T_wrist^{tracker} (``tracker_to_flange``); see module doc.

    offset: 4x4 T_O^{O'}; default = pure rotation ``frame_rotation`` (no translation).
    frame_rotation: 3x3 rotation OpenVR -> world used by the default offset and by "align_axes".
    """

    def __init__(self, offset=None, tracker_to_flange=None, *, frame_rotation=None, mode: str = "full"):
        R = OPENVR_TO_WORLD if frame_rotation is None else check_array("frame_rotation", frame_rotation, (3, 3))
        F = np.eye(4)
        F[:3, :3] = R
        self.frame_rotation = check_rigid("frame_rotation (as a 4x4)", F)[:3, :3].copy()
        self.offset = F if offset is None else check_rigid("offset", offset)
        self.tracker_to_flange = np.eye(4) if tracker_to_flange is None else check_rigid("tracker_to_flange", tracker_to_flange)
        self.mode = check_choice("mode", mode, CALIBRATION_MODES)
        self.calibrated = offset is not None

    def slave_pose(self, master_pose) -> np.ndarray:
        """Eq. 2 for a master pose (4x4, tracker frame) -> flange pose (4x4, world)."""
        return compose_slave_pose(self.offset, master_pose, self.tracker_to_flange)

    def calibrate(self, master_pose, slave_pose) -> np.ndarray:
        """Make ``master_pose`` map to ``slave_pose`` now; returns the new offset."""
        T_m = check_rigid("master_pose", master_pose)
        T_s = check_rigid("slave_pose", slave_pose)
        if self.mode == "full":
            self.offset = T_s @ invert(T_m @ self.tracker_to_flange)
        else:
            R_off = self.frame_rotation
            X = self.tracker_to_flange.copy()
            # R_off R_m R_x = R_s  ->  R_x = R_m^T R_off^T R_s ; keep X's translation (tracker mount)
            X[:3, :3] = T_m[:3, :3].T @ R_off.T @ T_s[:3, :3]
            self.tracker_to_flange = X
            off = np.eye(4)
            off[:3, :3] = R_off
            off[:3, 3] = T_s[:3, 3] - R_off @ (T_m @ X)[:3, 3]
            self.offset = off
        self.calibrated = True
        return self.offset.copy()
