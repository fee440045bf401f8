"""Haptic feedback: gripper tip normal forces (N) -> glove force-feedback and vibration levels.

Mapping (documented contract, every control step):

* force feedback of a finger = clip(F / full_scale_n, 0, 1), F the normal force on the gripper tip
  mapped to that finger (default: left tip -> thumb, right tip -> index; ``finger_map``), full
  scale 20 N by default (the 2F-85's lowest grip force). Fingers without a tip get 0.
* vibration pulse at contact onset: when F rises above ``contact_threshold_n`` (after having been
  below ``release_threshold_n``, a hysteresis that stops a force hovering at the threshold from
  buzzing), that finger gets ``vibration_level`` for ``vibration_duration_s``; otherwise 0.

``HapticsMapper.step(left_n, right_n) -> HapticCommand`` is pure apart from the contact state.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ._validate import check_number
from .sensors.base import FINGERS, MAX_VIBRATION_S, N_FINGERS

TIPS = ("left", "right")


def force_to_feedback(force_n: float, full_scale_n: float = 20.0) -> float:
    """clip(F / full_scale_n, 0, 1); F in N (negative forces count as no contact)."""
    f = check_number("force_n", force_n, unit="N")
    fs = check_number("full_scale_n", full_scale_n, 0.0, unit="N", lo_open=True)
    return float(np.clip(f / fs, 0.0, 1.0))


@dataclass(frozen=True)
class HapticsConfig:
    full_scale_n: float = 20.0
    contact_threshold_n: float = 0.5
    release_threshold_n: float = 0.25
    vibration_level: float = 0.6
    vibration_duration_s: float = 0.08
    finger_map: dict = field(default_factory=lambda: {"left": "thumb", "right": "index"})

    def __post_init__(self):
        check_number("full_scale_n", self.full_scale_n, 0.0, unit="N", lo_open=True)
        on = check_number("contact_threshold_n", self.contact_threshold_n, 0.0, unit="N", lo_open=True)
        off = check_number("release_threshold_n", self.release_threshold_n, 0.0, unit="N")
        if off > on:
            raise ValueError(f"release_threshold_n must be <= contact_threshold_n ({on} N), got {off}")
        check_number("vibration_level", self.vibration_level, 0.0, 1.0)
        check_number("vibration_duration_s", self.vibration_duration_s, 0.0, MAX_VIBRATION_S, unit="s")
        if not isinstance(self.finger_map, dict) or set(self.finger_map) != set(TIPS):
            raise ValueError(f"finger_map must map exactly {TIPS} to finger names, got {self.finger_map!r}")
        for tip, finger in self.finger_map.items():
            if finger not in FINGERS:
                raise ValueError(f"finger_map[{tip!r}] must be one of {FINGERS}, got {finger!r}")


@dataclass(frozen=True)
class HapticCommand:
    force_feedback: np.ndarray  # [5] 0..1, thumb..pinky
    vibration: np.ndarray  # [5] 0..1
    vibration_duration_s: float


class HapticsMapper:
    """Tip forces -> HapticCommand, with contact-onset detection (see module doc)."""

    def __init__(self, config: HapticsConfig | None = None):
        self.config = config or HapticsConfig()
        if not isinstance(self.config, HapticsConfig):
            raise TypeError(f"config must be a HapticsConfig, got {self.config!r}")
        self._index = {tip: FINGERS.index(self.config.finger_map[tip]) for tip in TIPS}
        self.in_contact = {tip: False for tip in TIPS}

    def reset(self) -> None:
        self.in_contact = {tip: False for tip in TIPS}

    def step(self, left_n: float, right_n: float) -> HapticCommand:
        c = self.config
        ff, vib = np.zeros(N_FINGERS), np.zeros(N_FINGERS)
        onset = False
        for tip, f in zip(TIPS, (left_n, right_n)):
            f = check_number(f"{tip}_tip_normal_force", f, unit="N")
            i = self._index[tip]
            ff[i] = max(ff[i], force_to_feedback(f, c.full_scale_n))
            if not self.in_contact[tip] and f > c.contact_threshold_n:
                self.in_contact[tip] = True
                vib[i] = c.vibration_level
                onset = True
            elif self.in_contact[tip] and f < c.release_threshold_n:
                self.in_contact[tip] = False
        return HapticCommand(ff, vib, c.vibration_duration_s if onset else 0.0)

    def from_info(self, info: dict) -> HapticCommand:
        """``step`` on an env info dict (``left_tip_normal_force``, ``right_tip_normal_force``)."""
        if not isinstance(info, dict):
            raise TypeError(f"info must be a dict, got {type(info).__name__}")
        missing = [k for k in ("left_tip_normal_force", "right_tip_normal_force") if k not in info]
        if missing:
            raise ValueError(f"info lacks {missing}; has keys {sorted(info)}")
        return self.step(_scalar(info["left_tip_normal_force"]), _scalar(info["right_tip_normal_force"]))


def _scalar(v) -> float:
    a = np.asarray(v, dtype=np.float64)
    if a.size != 1:
        raise ValueError(f"tip normal force must be a scalar (N), got shape {a.shape}")
    return float(a.reshape(()))
