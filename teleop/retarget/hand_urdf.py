"""Finger chains of the glove as a URDF, generated from configurable link lengths.

Each finger is a serial chain of 4 revolute joints, as the SenseGlove DK1 reports 4 angles per
finger (proximal -> distal). Joint 0 sits at the finger base (``base_xyz``, ``base_rpy`` in the
glove frame: +X toward the fingers, +Y pinky -> thumb on a right hand, +Z up from the palm); joint
i >= 1 sits at the end of link i-1; link i runs ``link_lengths[i]`` m along its own +X; the
fingertip is the end of link 3. ``axes[i]`` is joint i's axis in its own frame. Default axes
(z, y, y, y): splay (abduction) then three flexions; a positive flexion about +y turns the link's
+X toward -Z, i.e. curls the finger toward the palm.

The default ``HandGeometry`` is an approximate adult right hand (phalanx lengths, finger bases)
meant for the human-hand angles; for raw DK1 exoskeleton sensor angles, replace it with the
exoskeleton's link lengths and offsets (SGCore ``SenseGloveInfo``). The pinch map is calibrated per
operator anyway (``PinchGapMap``), so geometry errors shift D but do not bias the gap endpoints.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validate import check_array
from ..sensors.base import FINGERS, JOINTS_PER_FINGER

ROOT_LINK = "glove"
Z, Y = (0.0, 0.0, 1.0), (0.0, 1.0, 0.0)


@dataclass(frozen=True)
class FingerGeometry:
    """One finger chain (see module doc). Lengths in m, angles in rad."""

    base_xyz: tuple[float, float, float]
    link_lengths: tuple[float, float, float, float]
    base_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axes: tuple = (Z, Y, Y, Y)

    def __post_init__(self):
        object.__setattr__(self, "base_xyz", tuple(check_array("base_xyz", self.base_xyz, (3,), lo=-1.0, hi=1.0, unit="m").tolist()))
        object.__setattr__(self, "base_rpy", tuple(check_array("base_rpy", self.base_rpy, (3,), lo=-2 * np.pi, hi=2 * np.pi, unit="rad").tolist()))
        L = check_array("link_lengths", self.link_lengths, (JOINTS_PER_FINGER,), lo=0.0, hi=0.5, unit="m")
        if L.sum() <= 0:
            raise ValueError(f"link_lengths must not all be zero, got {L.tolist()}")
        object.__setattr__(self, "link_lengths", tuple(L.tolist()))
        A = check_array("axes", self.axes, (JOINTS_PER_FINGER, 3))
        n = np.linalg.norm(A, axis=1)
        if np.any(n < 1e-9):
            raise ValueError(f"axes must be non-zero vectors, got {A.tolist()}")
        object.__setattr__(self, "axes", tuple(tuple(a) for a in (A / n[:, None]).tolist()))


def _default_fingers() -> tuple[FingerGeometry, ...]:
    return (
        FingerGeometry((0.020, 0.030, -0.025), (0.0, 0.045, 0.035, 0.030), base_rpy=(-0.8, 0.0, 0.8)),  # thumb
        FingerGeometry((0.090, 0.025, -0.015), (0.0, 0.045, 0.025, 0.020)),  # index
        FingerGeometry((0.090, 0.005, -0.015), (0.0, 0.050, 0.030, 0.022)),  # middle
        FingerGeometry((0.085, -0.015, -0.015), (0.0, 0.045, 0.028, 0.020)),  # ring
        FingerGeometry((0.075, -0.033, -0.015), (0.0, 0.035, 0.020, 0.018)),  # pinky
    )


@dataclass(frozen=True)
class HandGeometry:
    """Five finger chains, thumb..pinky (``FINGERS``)."""

    fingers: tuple[FingerGeometry, ...] = field(default_factory=_default_fingers)

    def __post_init__(self):
        if len(self.fingers) != len(FINGERS) or not all(isinstance(f, FingerGeometry) for f in self.fingers):
            raise ValueError(f"fingers must be {len(FINGERS)} FingerGeometry ({', '.join(FINGERS)}), got {self.fingers!r}")


def joint_name(finger: str, i: int) -> str:
    return f"{finger}_j{i}"


def tip_link(finger: str) -> str:
    return f"{finger}_tip"


def _fmt(v) -> str:
    return " ".join(repr(float(x)) for x in v)


def hand_urdf(geometry: HandGeometry | None = None, name: str = "glove_hand") -> str:
    """URDF text of the 5 finger chains under root link ``glove`` (joints ``<finger>_j0..3``,
    fingertip links ``<finger>_tip``). Joint limits are [-pi, pi]: the glove reports, we do not
    constrain."""
    g = geometry or HandGeometry()
    lines = ['<?xml version="1.0"?>', f'<robot name="{name}">', f'  <link name="{ROOT_LINK}"/>']
    for finger, fg in zip(FINGERS, g.fingers):
        parent = ROOT_LINK
        for i in range(JOINTS_PER_FINGER):
            child = f"{finger}_link{i}"
            xyz = fg.base_xyz if i == 0 else (fg.link_lengths[i - 1], 0.0, 0.0)
            rpy = fg.base_rpy if i == 0 else (0.0, 0.0, 0.0)
            lines += [
                f'  <link name="{child}"/>',
                f'  <joint name="{joint_name(finger, i)}" type="revolute">',
                f'    <parent link="{parent}"/><child link="{child}"/>',
                f'    <origin xyz="{_fmt(xyz)}" rpy="{_fmt(rpy)}"/><axis xyz="{_fmt(fg.axes[i])}"/>',
                f'    <limit lower="{-np.pi!r}" upper="{np.pi!r}" effort="1" velocity="10"/>',
                "  </joint>",
            ]
            parent = child
        lines += [
            f'  <link name="{tip_link(finger)}"/>',
            f'  <joint name="{finger}_tip_joint" type="fixed">',
            f'    <parent link="{parent}"/><child link="{tip_link(finger)}"/>',
            f'    <origin xyz="{_fmt((fg.link_lengths[-1], 0.0, 0.0))}" rpy="0 0 0"/>',
            "  </joint>",
        ]
    lines.append("</robot>")
    return "\n".join(lines) + "\n"
