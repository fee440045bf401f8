"""Last step of eq. 4: the 2F-85's geometric IK, jaw gap -> driver angle, and back.

The only teleop module that touches ``defgrasp_env.gripper`` (closed-form linkage,
``theta_from_gap`` / ``gap_from_theta``, driver angle ``theta`` in [0, 0.8] rad, 0 = open). The
linkage reaches gaps in ``[GAP_MIN, GAP_MAX]`` = [1.511, 86.012] mm, the env's action accepts
[0, 0.085] m; a requested gap is clipped to the intersection before the IK, so the returned gap is
the one the gripper can actually make.
"""

from __future__ import annotations

from .._validate import check_number

ACTION_GAP_MAX_M = 0.085


def gap_limits() -> tuple[float, float]:
    """(min, max) gap in m reachable by the linkage and accepted by the action."""
    from defgrasp_env.gripper import GAP_MAX, GAP_MIN

    return float(GAP_MIN), float(min(GAP_MAX, ACTION_GAP_MAX_M))


def driver_angle_from_gap(gap_m: float) -> tuple[float, float]:
    """(driver angle theta rad, reachable gap m) for a requested gap in [0, 0.085] m."""
    from defgrasp_env.gripper import gap_from_theta, theta_from_gap

    g = check_number("gap_m", gap_m, 0.0, ACTION_GAP_MAX_M, unit="m")
    lo, hi = gap_limits()
    theta = float(theta_from_gap(min(max(g, lo), hi)))
    return theta, float(gap_from_theta(theta))
