"""Eq. 4 of the paper: jaw gap (and 2F-85 driver angle) from the thumb-index pinch.

1. Finger forward kinematics: the glove's 20 joint angles through the finger-chain URDF
   (``hand_urdf``) loaded in pytorch-kinematics give P_thumb and P_index in the glove frame (m).
   (``source="sdk"`` uses the glove SDK's own fingertip positions instead.)
2. Pinch distance D = |P_thumb - P_index|.
3. Calibrated linear map from the operator's pinch range [D_closed, D_open] to the jaw gap
   [gap_closed, gap_open] (default [0, 0.085] m), clamped:
   gap = clip(gap_closed + (D - D_closed) / (D_open - D_closed) * (gap_open - gap_closed)).
   ``PinchGapMap.from_distances`` / ``PinchRetargeter.calibrate`` take two samples (pinch closed,
   hand open).
4. The 2F-85 geometric IK: gap -> driver angle (``gripper_ik``), and the gap it really makes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import check_array, check_choice, check_number
from ..sensors.base import FINGERS, JOINTS_PER_FINGER, GloveSample
from .hand_urdf import HandGeometry, hand_urdf, joint_name, tip_link

#: smallest accepted calibrated pinch span D_open - D_closed (m)
MIN_PINCH_SPAN_M = 0.005
THUMB, INDEX = FINGERS.index("thumb"), FINGERS.index("index")


class FingerKinematics:
    """Fingertip positions from glove joint angles via pytorch-kinematics (float64, CPU)."""

    def __init__(self, geometry: HandGeometry | None = None):
        import pytorch_kinematics as pk
        import torch

        self._torch = torch
        self.geometry = geometry or HandGeometry()
        self.urdf = hand_urdf(self.geometry)
        self.chain = pk.build_chain_from_urdf(self.urdf).to(dtype=torch.float64, device="cpu")
        names = list(self.chain.get_joint_parameter_names())
        # chain order -> (finger, joint) index in the flat [20] glove vector
        self._perm = np.array([names.index(joint_name(f, j)) for f in FINGERS for j in range(JOINTS_PER_FINGER)])
        self._inv = np.argsort(self._perm)
        self._tips = [tip_link(f) for f in FINGERS]

    def fingertip_positions(self, joint_angles) -> np.ndarray:
        """[5, 3] (or [B, 5, 3] for [B, 5, 4] input) fingertip positions in m, glove frame."""
        a = np.asarray(joint_angles, dtype=np.float64)
        batched = a.ndim == 3
        if a.shape[-2:] != (len(FINGERS), JOINTS_PER_FINGER) or a.ndim not in (2, 3):
            raise ValueError(f"joint_angles must have shape [5, 4] or [B, 5, 4], got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError("joint_angles must be finite")
        flat = a.reshape(-1, len(FINGERS) * JOINTS_PER_FINGER)
        th = np.empty_like(flat)
        th[:, self._perm] = flat
        with self._torch.no_grad():
            fk = self.chain.forward_kinematics(self._torch.as_tensor(th))
        tips = np.stack([fk[name].get_matrix()[:, :3, 3].numpy() for name in self._tips], axis=1)
        return tips if batched else tips[0]


def pinch_distance(p_thumb, p_index) -> float:
    """Euclidean distance D (m) between the thumb and index fingertips [3]."""
    return float(np.linalg.norm(check_array("p_thumb", p_thumb, (3,)) - check_array("p_index", p_index, (3,))))


@dataclass(frozen=True)
class PinchGapMap:
    """Linear, clamped map from pinch distance D (m) to jaw gap (m); see module doc."""

    d_closed_m: float = 0.015
    d_open_m: float = 0.10
    gap_closed_m: float = 0.0
    gap_open_m: float = 0.085

    def __post_init__(self):
        dc = check_number("d_closed_m", self.d_closed_m, 0.0, 0.5, unit="m")
        do = check_number("d_open_m", self.d_open_m, 0.0, 0.5, unit="m")
        if do - dc < MIN_PINCH_SPAN_M:
            raise ValueError(
                f"d_open_m - d_closed_m must be >= {MIN_PINCH_SPAN_M} m (open hand wider than the pinch), "
                f"got d_closed_m={dc}, d_open_m={do}"
            )
        gc = check_number("gap_closed_m", self.gap_closed_m, 0.0, 0.085, unit="m")
        go = check_number("gap_open_m", self.gap_open_m, 0.0, 0.085, unit="m")
        if go <= gc:
            raise ValueError(f"gap_open_m must be > gap_closed_m, got gap_closed_m={gc}, gap_open_m={go}")

    @classmethod
    def from_distances(cls, d_closed_m: float, d_open_m: float, **gaps) -> "PinchGapMap":
        """Calibrate from the pinch distance measured with the pinch closed and the hand open."""
        return cls(d_closed_m=d_closed_m, d_open_m=d_open_m, **gaps)

    def gap(self, distance_m: float) -> float:
        d = check_number("distance_m", distance_m, 0.0, unit="m")
        s = (d - self.d_closed_m) / (self.d_open_m - self.d_closed_m)
        return float(np.clip(self.gap_closed_m + s * (self.gap_open_m - self.gap_closed_m), self.gap_closed_m, self.gap_open_m))


@dataclass(frozen=True)
class PinchResult:
    distance_m: float  # D
    gap_m: float  # mapped, clamped gap
    driver_angle_rad: float  # 2F-85 finger_joint angle for that gap
    reachable_gap_m: float  # gap the linkage makes at that angle


class PinchRetargeter:
    """Glove sample -> PinchResult (eq. 4). source: "fk" (finger URDF FK) or "sdk"."""

    def __init__(self, kinematics: FingerKinematics | None = None, gap_map: PinchGapMap | None = None, *, source: str = "fk"):
        self.source = check_choice("source", source, ("fk", "sdk"))
        self.kinematics = kinematics if kinematics is not None or source == "sdk" else FingerKinematics()
        self.gap_map = gap_map or PinchGapMap()
        if not isinstance(self.gap_map, PinchGapMap):
            raise TypeError(f"gap_map must be a PinchGapMap, got {self.gap_map!r}")

    def distance(self, sample: GloveSample) -> float:
        if not isinstance(sample, GloveSample):
            raise TypeError(f"sample must be a GloveSample, got {type(sample).__name__}")
        tips = sample.fingertip_positions if self.source == "sdk" else self.kinematics.fingertip_positions(sample.joint_angles)
        return pinch_distance(tips[THUMB], tips[INDEX])

    def calibrate(self, closed: GloveSample, open_: GloveSample) -> PinchGapMap:
        """Set the map from a pinch-closed and a hand-open sample; returns the new map."""
        m = self.gap_map
        self.gap_map = PinchGapMap(self.distance(closed), self.distance(open_), m.gap_closed_m, m.gap_open_m)
        return self.gap_map

    def __call__(self, sample: GloveSample) -> PinchResult:
        from .gripper_ik import driver_angle_from_gap

        d = self.distance(sample)
        gap = self.gap_map.gap(d)
        theta, reach = driver_angle_from_gap(gap)
        return PinchResult(d, gap, theta, reach)
