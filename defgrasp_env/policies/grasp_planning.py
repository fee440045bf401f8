"""Top-down parallel-jaw grasp planning from the observed object keypoints (pure numpy, batched).

Only what the env observes is used: the feature point (mean node position, [N, 3] m, world, y up)
and the 8 surface keypoints ([N, 8, 3] m, world). Nothing about the object's identity or mesh.

Rules (horizontal plane x-z; a closing axis d and -d are the same grasp):

* **Straddle** (the default): the pads close around the feature point. For every candidate
  closing direction the required half-opening is the largest keypoint distance from the feature
  point along it; the chosen direction is the narrowest one (ties within ``tie_tolerance`` go to
  the one closest to the current closing axis, so round objects need no wrist turn). The rope
  gets its closing axis across the rope, the cube across two faces.
* **Rim** (objects too wide for the open jaws, e.g. the torus, 80 mm across a hole, with the jaws
  opening 85 mm): the pads close across the rim where the current closing axis x_G, drawn from
  the feature point, meets it (on its +x_G side), so the wrist does not turn; the rim is taken
  as round (outer radius = the farthest keypoint's distance in every direction), its thickness
  as the object's height (a round tube), and the rim centre half a thickness inside the outer
  radius. (An earlier rule grasped at the farthest keypoint: for a round rim all keypoints are
  nearly equally far, so that choice jumped between them with tiny deformations and yaws, and
  no policy could learn it from demonstrations; the learned ACT policy grasped 0 of 12 tori.) Eight keypoints undersample round outlines (the
  torus's narrowest centred opening looks ~65 mm), so for compact objects (farthest keypoint
  closer than twice the narrowest half-opening) the farthest keypoint decides: opening needed
  ``2 r_max`` > ``JAW_GAP_MAX - 2 rim_margin`` (69 mm) means rim. Elongated objects (the rope) keep
  the narrow estimate.
* **Grasp height** of the tool centre point (pad centre): the feature point's height, raised so
  that the pad bottoms stay ``ground_clearance`` above the ground.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..gripper import PAD_HALF_EXTENTS
from ..layout import JAW_GAP_MAX

__all__ = ["GraspPlan", "plan_grasps", "closing_yaw", "PAD_HALF_LENGTH"]

#: Half length (m) of a pad along the approach axis: the tcp must stay this far above the ground.
PAD_HALF_LENGTH = float(PAD_HALF_EXTENTS[1])
_ANGLES = np.deg2rad(np.arange(0.0, 180.0, 1.0))
_DIRS = np.stack([np.cos(_ANGLES), np.sin(_ANGLES)], axis=1)  # [A, 2] (x, z)
#: Worlds per block of the [worlds, K, A] candidate evaluation: blocks stay in the CPU cache (at
#: N = 4096 one pass over all worlds at once is ~2x slower); rows are independent, so blocking does
#: not change a bit of the result.
_BLOCK = 64


@dataclass(frozen=True)
class GraspPlan:
    """Planned top-down grasps of N worlds (all arrays float64 / bool, world frame, m and rad).

    Attributes:
        point: [N, 3] target tool-centre point (pad-centre midpoint) at the grasp.
        yaw: [N] wrist yaw about world +y that puts the closing axis x_G on the chosen direction
            (x_G = (cos yaw, 0, -sin yaw)).
        width: [N] estimated object extent between the pads (m), from the keypoints.
        open_gap: [N] jaw gap to descend with (m).
        top: [N] highest keypoint (m), for the hover height.
        rim: [N] bool, True where the rim rule was used.
    """

    point: np.ndarray
    yaw: np.ndarray
    width: np.ndarray
    open_gap: np.ndarray
    top: np.ndarray
    rim: np.ndarray


def closing_yaw(direction_xz: np.ndarray) -> np.ndarray:
    """Yaw [N] (rad) whose closing axis x_G = (cos, 0, -sin) points along ``direction_xz`` [N, 2]."""
    return np.arctan2(-direction_xz[:, 1], direction_xz[:, 0])


def _wrap_half_turn(a: np.ndarray) -> np.ndarray:
    """Angle difference modulo pi into [-pi/2, pi/2) (closing axes are sign-symmetric)."""
    return (a + np.pi / 2) % np.pi - np.pi / 2


def _narrowest_directions(rel: np.ndarray, current_yaw: np.ndarray, tie_tolerance: float):
    """Per world, the narrowest centred half-opening ``best`` [N] (m) over the candidate closing
    directions and the index ``pick`` [N] into ``_DIRS`` of the direction chosen among those within
    ``tie_tolerance`` of it (closest to ``current_yaw`` [N] rad), for keypoints ``rel`` [N, K, 2]
    (x, z, m) relative to the feature point; evaluated in blocks of ``_BLOCK`` worlds."""
    n = len(rel)
    best, pick = np.empty(n), np.empty(n, dtype=np.intp)
    dir_yaw = closing_yaw(_DIRS)                                           # [A]
    for start in range(0, n, _BLOCK):
        rows = slice(start, start + _BLOCK)
        half = np.abs(rel[rows] @ _DIRS.T).max(axis=1)                    # [B, A] centred half-opening
        best[rows] = half.min(axis=1)
        # among the near-narrowest directions, the one closest to the current closing axis
        turn = np.abs(_wrap_half_turn(dir_yaw[None, :] - current_yaw[rows, None]))
        cost = np.where(half <= best[rows, None] + tie_tolerance, turn, np.inf)
        pick[rows] = np.argmin(cost, axis=1)
    return best, pick


def plan_grasps(feature: np.ndarray, keypoints: np.ndarray, current_yaw: np.ndarray, *,
                tie_tolerance: float = 0.003, rim_margin: float = 0.008, rim_clearance: float = 0.012,
                ground_clearance: float = 0.003) -> GraspPlan:
    """Grasp plans for N worlds from feature points [N, 3] and keypoints [N, K, 3] (m, world).

    ``current_yaw`` [N] (rad) breaks ties between equally narrow closing directions and is kept for
    rim grasps (the closing axis it gives decides where the rim is grasped). Objects whose
    narrowest centred opening exceeds ``JAW_GAP_MAX - 2 rim_margin`` are grasped at the rim, descending
    with a gap of the rim thickness + 2 ``rim_clearance``.
    """
    feature = np.asarray(feature, np.float64)
    keypoints = np.asarray(keypoints, np.float64)
    rel = keypoints[:, :, [0, 2]] - feature[:, None, [0, 2]]              # [N, K, 2]
    best, pick = _narrowest_directions(rel, np.asarray(current_yaw, np.float64), tie_tolerance)
    straddle_dir = _DIRS[pick]                                             # [N, 2]
    width = 2.0 * best

    top = keypoints[:, :, 1].max(axis=1)
    bottom = keypoints[:, :, 1].min(axis=1)
    r_max = np.linalg.norm(rel, axis=2).max(axis=1)                        # [N] farthest keypoint
    # 8 keypoints undersample round outlines (a torus looks ~65 mm wide, it is 80 mm): for compact
    # objects (farthest keypoint < 2x the narrowest half-opening) the farthest keypoint bounds the
    # opening the pads must clear; elongated ones (the rope) keep the narrow estimate
    compact = r_max < 2.0 * best
    clear_width = np.where(compact, 2.0 * np.maximum(r_max, best), width)
    rim = clear_width > JAW_GAP_MAX - 2.0 * rim_margin
    thickness = np.clip(top - bottom, 0.005, np.maximum(r_max, 0.005))
    current_yaw = np.asarray(current_yaw, np.float64)
    out_dir = np.stack([np.cos(current_yaw), -np.sin(current_yaw)], axis=1)  # +x_G, as closing_yaw

    direction = np.where(rim[:, None], out_dir, straddle_dir)
    centre_xz = np.where(rim[:, None], feature[:, [0, 2]] + out_dir * (r_max - thickness / 2)[:, None],
                         feature[:, [0, 2]])
    width = np.where(rim, thickness, width)
    open_gap = np.where(rim, np.minimum(thickness + 2.0 * rim_clearance, JAW_GAP_MAX), JAW_GAP_MAX)
    height = np.maximum(feature[:, 1], PAD_HALF_LENGTH + ground_clearance)
    if np.any(rim):
        rim_height = np.maximum(0.5 * (top + bottom), PAD_HALF_LENGTH + ground_clearance)
        height = np.where(rim, rim_height, height)
    # choose the sign of the closing axis (yaw modulo pi) nearest to the current yaw
    yaw = closing_yaw(direction)
    yaw = np.asarray(current_yaw, np.float64) + _wrap_half_turn(yaw - current_yaw)
    point = np.stack([centre_xz[:, 0], height, centre_xz[:, 1]], axis=1)
    return GraspPlan(point=point, yaw=yaw, width=width, open_gap=open_gap, top=top, rim=rim)
