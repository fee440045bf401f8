"""Last step of eq. 4: the 2F-85's geometric IK, jaw gap -> driver angle, and back.

The only teleop module that touches ``defgrasp_env.gripper`` (closed-form linkage,
``theta_from_gap`` / ``gap_from_theta``, driver angle ``theta`` in [``THETA_MIN``, 0.8] rad, open to
closed). The linkage reaches gaps in ``[GAP_MIN, GAP_MAX]`` = [1.511, 85] mm; the env's absolute
action (``defgrasp_env.layout.ABSOLUTE_ACTION``) accepts [0, 0.085] m: a requested gap is clipped
to the linkage's range before the IK, so the returned gap is the one the gripper can actually make.
"""

from __future__ import annotations

from defgrasp_env.gripper import GAP_MAX, GAP_MIN, gap_from_theta, theta_from_gap
from defgrasp_env.layout import ABSOLUTE_ACTION

from .._validate import check_number

#: Widest gap (m) the absolute action accepts: the layout's, equal to the linkage's ``GAP_MAX``.
ACTION_GAP_MAX_M = float(ABSOLUTE_ACTION.field("gap").high)


def gap_limits() -> tuple[float, float]:
    """(min, max) gap in m reachable by the linkage and accepted by the action."""
    return float(GAP_MIN), float(min(GAP_MAX, ACTION_GAP_MAX_M))


def driver_angle_from_gap(gap_m: float) -> tuple[float, float]:
    """(driver angle theta rad, reachable gap m) for a requested gap in [0, ACTION_GAP_MAX_M] m."""
    g = check_number("gap_m", gap_m, 0.0, ACTION_GAP_MAX_M, unit="m")
    lo, hi = gap_limits()
    theta = float(theta_from_gap(min(max(g, lo), hi)))
    return theta, float(gap_from_theta(theta))
