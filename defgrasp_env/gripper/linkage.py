"""Robotiq 2F-85 finger linkage in closed form (pure numpy, vectorised).

Model
-----
Derived from the link offsets of the ros-industrial ``robotiq_arg2f_85_model_macro.xacro`` URDF.
Each finger is a parallelogram driven by ``finger_joint`` (angle ``theta`` in
``[THETA_MIN, THETA_MAX] = [0.011702, 0.8]`` rad, THETA_MIN = open): the pad translates without
rotating on a circle of radius ``ARC_RADIUS = hypot(0.0376, 0.0430)`` m. The URDF offsets used:

==========================  ===========================  =================================
offset                      lateral (closing axis) / m   along the approach axis / m
==========================  ===========================  =================================
base -> outer knuckle axis  ``KNUCKLE_LATERAL=0.0306011``  ``KNUCKLE_APPROACH=0.054904``
knuckle -> inner finger     ``0.0315 + 0.0061 = 0.0376``   ``-0.0041 + 0.0471 = 0.0430``
inner finger -> pad centre  ``-0.0220203446692936``        ``0.03242``
pad box (centred on frame)  thickness 0.00635              length 0.0375 (width 0.022)
==========================  ===========================  =================================

Gap between the pad inner faces::

    g(theta) = 2 * (GAP_OFFSET + 0.0376 cos(theta) - 0.0430 sin(theta))
             = 2 * (GAP_OFFSET + ARC_RADIUS * cos(theta + ARC_PHASE))
    GAP_OFFSET = 0.0306011 - 0.0220203446692936 - 0.00635 / 2 = 0.0054057553 m
    ARC_PHASE  = atan2(0.0430, 0.0376) = 0.8522957 rad,  ARC_RADIUS = 0.0571206 m

``g`` is strictly decreasing on [0, 0.8] (``theta + ARC_PHASE`` stays in (0, pi)), so the inverse
``theta(g) = acos((g / 2 - GAP_OFFSET) / ARC_RADIUS) - ARC_PHASE`` is exact.

Gap limits (decision)
---------------------
``GAP_MIN = g(0.8) = 1.511 mm`` (closed, the URDF's upper joint limit) to ``GAP_MAX = 85 mm``
(open): the 2F-85's datasheet stroke. The URDF's lower joint limit (theta = 0) would open the
pads to g(0) = 86.012 mm, 1 mm wider than the gripper we model, so the driver angle is limited to
``THETA_MIN = theta(85 mm) = 0.011702 rad``; gap <-> theta stays a bijection on
[THETA_MIN, THETA_MAX], and every part (env action space, jaw driver, expert, teleop, recorded
``jaw_length``) shares the 85 mm range through ``defgrasp_env.layout``. (MuJoCo Menagerie's
closed-loop model differs by up to 4 mm; we simulate this one.)

Gripper frame G (= the wrist flange, see ``defgrasp_env.wrist``)
-----------------------------------------------------------------
* origin: the flange, i.e. the gripper's mounting face (the URDF's ``robotiq_arg2f_base_link``);
* ``-y_G``: approach axis (the fingers point along -y_G; at zero wrist joints -y_G is world -y, down);
* ``x_G``: closing axis; the **left** pad (index 0, the URDF's ``left_inner_finger_pad``) is on
  the ``+x_G`` side, the **right** pad (index 1) on the ``-x_G`` side;
* ``z_G = x_G x y_G``: pad width direction.

In URDF base-link axes ``(x_b, y_b, z_b)``: ``x_G = -y_b``, ``y_G = -z_b``, ``z_G = x_b``.
Pad boxes (half extents in G): ``(0.003175, 0.01875, 0.011)`` m, axis-aligned in G for every theta
(the parallelogram keeps the pads parallel). Inner-face normals (pointing into the gap):
left ``-x_G``, right ``+x_G`` (``PAD_INWARD_NORMALS``).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "THETA_MIN", "THETA_MAX", "GAP_MIN", "GAP_MAX", "GAP_OFFSET", "ARC_RADIUS", "ARC_PHASE",
    "KNUCKLE_LATERAL", "KNUCKLE_APPROACH", "FINGER_LATERAL", "FINGER_APPROACH",
    "PAD_LATERAL", "PAD_APPROACH", "PAD_THICKNESS", "PAD_LENGTH", "PAD_WIDTH",
    "PAD_HALF_EXTENTS", "PAD_INWARD_NORMALS", "PAD_NAMES",
    "gap_from_theta", "theta_from_gap", "pad_centers", "pad_arc_centers", "pad_boxes", "tcp_offset",
]

# --- URDF offsets (m) -------------------------------------------------------------------------
KNUCKLE_LATERAL = 0.0306011  # base -> outer-knuckle axis, along the closing axis (outward)
KNUCKLE_APPROACH = 0.054904  # base -> outer-knuckle axis, along the approach axis
FINGER_LATERAL = 0.0315 + 0.0061  # knuckle axis -> inner-finger axis at theta = 0 (outward)
FINGER_APPROACH = -0.0041 + 0.0471  # knuckle axis -> inner-finger axis at theta = 0
PAD_LATERAL = -0.0220203446692936  # inner finger -> pad centre (negative = inward)
PAD_APPROACH = 0.03242  # inner finger -> pad centre, along the approach axis

# --- pad box (m), URDF <box size="0.022 0.00635 0.0375"/> ---------------------------------------
PAD_WIDTH = 0.022  # along z_G
PAD_THICKNESS = 0.00635  # along the closing axis x_G
PAD_LENGTH = 0.0375  # along the approach axis y_G
PAD_HALF_EXTENTS = np.array([PAD_THICKNESS, PAD_LENGTH, PAD_WIDTH]) / 2.0
"""Half extents [3] (m) of each pad box in frame G: (x_G, y_G, z_G)."""
PAD_NAMES = ("left", "right")
PAD_INWARD_NORMALS = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
"""[2, 3] unit normals of the pad inner faces in G, pointing into the gap (left, right)."""

# --- derived closed form -----------------------------------------------------------------------
GAP_OFFSET = KNUCKLE_LATERAL + PAD_LATERAL - PAD_THICKNESS / 2.0  # 0.0054057553 m
ARC_RADIUS = math.hypot(FINGER_LATERAL, FINGER_APPROACH)  # 0.0571206 m
ARC_PHASE = math.atan2(FINGER_APPROACH, FINGER_LATERAL)  # 0.8522957 rad

GAP_MAX = 0.085  # m, fully open: the 2F-85 stroke (see "Gap limits")
THETA_MIN = math.acos((0.5 * GAP_MAX - GAP_OFFSET) / ARC_RADIUS) - ARC_PHASE  # 0.0117021 rad
THETA_MAX = 0.8  # rad, fully closed (URDF finger_joint upper limit)
GAP_MIN = 2.0 * (GAP_OFFSET + ARC_RADIUS * math.cos(THETA_MAX + ARC_PHASE))  # 0.0015112 m

_EPS = 1e-9  # tolerance for range checks (rad or m); values within it are clipped


def _finite(x, name: str) -> np.ndarray:
    """``x`` as a float64 array; TypeError if not numeric, ValueError if any entry is not finite."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a number or numeric array, got {type(x).__name__}") from exc
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got {a[~np.isfinite(a)].flat[0]}")
    return a


def _checked(x, lo: float, hi: float, name: str, unit: str) -> np.ndarray:
    a = _finite(x, name)
    bad = (a < lo - _EPS) | (a > hi + _EPS)
    if np.any(bad):
        raise ValueError(f"{name} must be in [{lo:.9g}, {hi:.9g}] {unit}, got {a[bad].flat[0]:.9g}")
    return np.clip(a, lo, hi)


def gap_from_theta(theta) -> np.ndarray:
    """Gap between the pad inner faces (m) for driver angles ``theta`` (rad), any shape.

    ``theta`` must lie in ``[THETA_MIN, THETA_MAX] = [0.011702, 0.8]`` rad (ValueError otherwise).
    Returns float64 with the shape of ``theta``; strictly decreasing in ``theta``.
    """
    t = _checked(theta, THETA_MIN, THETA_MAX, "theta", "rad")
    return 2.0 * (GAP_OFFSET + FINGER_LATERAL * np.cos(t) - FINGER_APPROACH * np.sin(t))


def theta_from_gap(gap) -> np.ndarray:
    """Driver angle ``theta`` (rad) giving pad inner-face gap ``gap`` (m), any shape.

    ``gap`` must lie in ``[GAP_MIN, GAP_MAX]`` = [1.511, 85] mm (ValueError otherwise).
    Exact inverse of :func:`gap_from_theta`; the result is clipped to [THETA_MIN, THETA_MAX] rad.
    """
    g = _checked(gap, GAP_MIN, GAP_MAX, "gap", "m")
    c = np.clip((0.5 * g - GAP_OFFSET) / ARC_RADIUS, -1.0, 1.0)
    return np.clip(np.arccos(c) - ARC_PHASE, THETA_MIN, THETA_MAX)


def pad_centers(theta) -> np.ndarray:
    """Pad box centres in frame G (m), shape ``theta.shape + (2, 3)``: index 0 left (+x), 1 right.

    ``left = (+(KNUCKLE_LATERAL + PAD_LATERAL + ARC_RADIUS cos(theta + ARC_PHASE)),
    -(KNUCKLE_APPROACH + PAD_APPROACH + ARC_RADIUS sin(theta + ARC_PHASE)), 0)``; right mirrors x.
    The centres move on circles of radius ``ARC_RADIUS`` about :func:`pad_arc_centers`: closing
    moves them inward and first further out along the approach axis (max reach at
    ``theta = pi/2 - ARC_PHASE = 0.7185`` rad): 130.76 mm below the flange open, 144.44 mm at most,
    144.25 mm closed.
    """
    t = _checked(theta, THETA_MIN, THETA_MAX, "theta", "rad")
    lateral = KNUCKLE_LATERAL + PAD_LATERAL + FINGER_LATERAL * np.cos(t) - FINGER_APPROACH * np.sin(t)
    down = KNUCKLE_APPROACH + PAD_APPROACH + FINGER_LATERAL * np.sin(t) + FINGER_APPROACH * np.cos(t)
    out = np.zeros(t.shape + (2, 3))
    out[..., 0, 0] = lateral
    out[..., 1, 0] = -lateral
    out[..., :, 1] = -down[..., None]
    return out


def pad_arc_centers() -> np.ndarray:
    """[2, 3] centres (m, frame G) of the circles that the pad centres move on (left, right).

    This is the outer-knuckle axis shifted by the constant finger-to-pad offset (parallelogram).
    """
    lateral = KNUCKLE_LATERAL + PAD_LATERAL
    down = KNUCKLE_APPROACH + PAD_APPROACH
    return np.array([[lateral, -down, 0.0], [-lateral, -down, 0.0]])


def _theta_from(gap, theta) -> np.ndarray:
    if (gap is None) == (theta is None):
        raise TypeError("pass exactly one of gap= (m) or theta= (rad)")
    return theta_from_gap(gap) if theta is None else _checked(theta, THETA_MIN, THETA_MAX, "theta", "rad")


def pad_boxes(*, gap=None, theta=None) -> tuple[np.ndarray, np.ndarray]:
    """Oriented pad boxes in frame G for a gap (m) **or** a driver angle (rad), keyword-only.

    Returns ``(centers, half_extents)``, both ``shape + (2, 3)`` float64 (m), index 0 = left pad
    (+x_G), 1 = right pad (-x_G). The boxes are axis-aligned in G (rotation = identity in G); in the
    world their orientation is the flange's. Inner faces lie at ``x = +-gap / 2``.
    """
    t = _theta_from(gap, theta)
    centers = pad_centers(t)
    return centers, np.broadcast_to(PAD_HALF_EXTENTS, centers.shape).copy()


def tcp_offset(*, gap=None, theta=None) -> np.ndarray:
    """Flange -> tool centre point (midpoint of the two pad centres) in frame G (m), ``shape + (3,)``.

    Equals ``(0, -(KNUCKLE_APPROACH + PAD_APPROACH + ARC_RADIUS sin(theta + ARC_PHASE)), 0)``:
    0.130761 m below the flange when open, 0.144445 m at most (theta = 0.7185 rad), 0.144255 m closed.
    """
    t = _theta_from(gap, theta)
    return pad_centers(t).mean(axis=-2)
