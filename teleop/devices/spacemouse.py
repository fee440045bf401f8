"""3Dconnexion SpaceMouse teleoperation: the ``SpaceMouse`` sensor's state -> velocity commands.

pyspacemouse's state has x, y, z, roll, pitch, yaw in [-1, 1] and ``buttons``. Device axes: x right,
y forward (away from the user), z up. World (y up, -z forward): v = (x, z, -y), w = (pitch, yaw,
-roll), each times ``axis_signs`` (flip an entry if your unit moves the other way) after a
``deadzone``. Button 0 closes the jaw, button 1 opens it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validate import check_array, check_number
from ..sensors.spacemouse import SpaceMouse
from .velocity import VelocityTeleop, VelocityTeleopConfig


def spacemouse_velocity(
    state: Any,
    *,
    linear_speed_m_s: float,
    angular_speed_rad_s: float,
    gap_speed_m_s: float,
    deadzone: float = 0.05,
    axis_signs=(1, 1, 1, 1, 1, 1),
) -> tuple[np.ndarray, np.ndarray, float]:
    """(linear [3] m/s, angular [3] rad/s, gap rate m/s) in the world frame from a pyspacemouse
    state (attributes x, y, z, roll, pitch, yaw in [-1, 1] and ``buttons``)."""
    dz = check_number("deadzone", deadzone, 0.0, 1.0, hi_open=True)
    signs = check_array("axis_signs", axis_signs, (6,))
    if not np.all(np.abs(signs) == 1):
        raise ValueError(f"axis_signs entries must be -1 or +1, got {signs.tolist()}")
    try:
        raw = np.array([float(getattr(state, k)) for k in ("x", "y", "z", "roll", "pitch", "yaw")])
    except AttributeError as exc:
        raise TypeError(f"state must have x, y, z, roll, pitch, yaw, got {state!r}") from exc
    raw = check_array("spacemouse axes", np.clip(raw, -1.0, 1.0), (6,))
    raw = np.where(np.abs(raw) < dz, 0.0, (raw - np.sign(raw) * dz) / (1.0 - dz))
    x, y, z, roll, pitch, yaw = raw
    lin = np.array([x, z, -y]) * signs[:3] * linear_speed_m_s
    ang = np.array([pitch, yaw, -roll]) * signs[3:] * angular_speed_rad_s
    buttons = list(getattr(state, "buttons", []) or [])
    close = bool(buttons[0]) if len(buttons) > 0 else False
    open_ = bool(buttons[1]) if len(buttons) > 1 else False
    return lin, ang, (float(open_) - float(close)) * gap_speed_m_s


class SpaceMouseTeleop(VelocityTeleop):
    """TeleopDevice driven by a SpaceMouse. device: pyspacemouse device name or None (first)."""

    def __init__(self, config: VelocityTeleopConfig | None = None, *, device: str | None = None,
                 deadzone: float = 0.05, axis_signs=(1, 1, 1, 1, 1, 1)):
        super().__init__(config)
        self.device = device
        self.deadzone = check_number("deadzone", deadzone, 0.0, 1.0, hi_open=True)
        self.axis_signs = tuple(check_array("axis_signs", axis_signs, (6,)).tolist())
        self.mouse = SpaceMouse(device)

    @property
    def is_connected(self) -> bool:
        return self.mouse.is_connected

    def connect(self, calibrate: bool = True) -> None:
        self.mouse.connect()

    def disconnect(self) -> None:
        self.mouse.disconnect()

    def read_velocity(self):
        c = self.config
        return spacemouse_velocity(
            self.mouse.read(), linear_speed_m_s=c.linear_speed_m_s, angular_speed_rad_s=c.angular_speed_rad_s,
            gap_speed_m_s=c.gap_speed_m_s, deadzone=self.deadzone, axis_signs=self.axis_signs,
        )
