"""``VelocityTeleop``: a TeleopDevice that integrates velocity commands into absolute actions.

Base of ``KeyboardTeleop`` and ``SpaceMouseTeleop``. On the first ``act(obs)`` after ``reset()``
the target starts at the observed gripper state (``agent_pos``), so the gripper does not jump;
each ``act`` then integrates one step of ``dt``: position += v*dt (world, m), orientation =
exp(w*dt) * orientation (w in the world frame, rad/s), gap += gap_rate*dt clamped to [0, 0.085] m,
and the position is clamped to the workspace box.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass, field

import numpy as np

from .._validate import check_array, check_number
from ..retarget.smoothing import WorkspaceBox
from ..se3 import quat_multiply, quat_normalize, rotvec_to_quat
from ..teleop_device import MAX_GAP_M, TeleopDevice, make_action, parse_agent_state


@dataclass(frozen=True)
class VelocityTeleopConfig:
    """dt: control period (s); speeds at full deflection / key held."""

    dt: float = 0.05
    linear_speed_m_s: float = 0.1
    angular_speed_rad_s: float = 0.8
    gap_speed_m_s: float = 0.05
    workspace: WorkspaceBox = field(default_factory=WorkspaceBox)

    def __post_init__(self):
        check_number("dt", self.dt, 0.0, 10.0, unit="s", lo_open=True)
        check_number("linear_speed_m_s", self.linear_speed_m_s, 0.0, 10.0, unit="m/s", lo_open=True)
        check_number("angular_speed_rad_s", self.angular_speed_rad_s, 0.0, 100.0, unit="rad/s", lo_open=True)
        check_number("gap_speed_m_s", self.gap_speed_m_s, 0.0, 1.0, unit="m/s", lo_open=True)
        if not isinstance(self.workspace, WorkspaceBox):
            raise TypeError(f"workspace must be a WorkspaceBox, got {self.workspace!r}")


class VelocityTeleop(TeleopDevice):
    """Integrates ``read_velocity()`` (linear [3] m/s, angular [3] rad/s, gap rate m/s)."""

    def __init__(self, config: VelocityTeleopConfig | None = None):
        self.config = config or VelocityTeleopConfig()
        if not isinstance(self.config, VelocityTeleopConfig):
            raise TypeError(f"config must be a VelocityTeleopConfig, got {self.config!r}")
        self._target: tuple[np.ndarray, np.ndarray, float] | None = None
        self.last_action: np.ndarray | None = None

    @abc.abstractmethod
    def read_velocity(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(linear velocity [3] m/s world, angular velocity [3] rad/s world, gap rate m/s)."""

    def reset(self) -> None:
        self._target = None
        self.last_action = None

    def act(self, obs) -> np.ndarray:
        if not self.is_connected:
            raise RuntimeError(f"{type(self).__name__}.act() needs connect() first")
        if self._target is None:
            self._target = parse_agent_state(obs)
        pos, quat, gap = self._target
        v, w, gdot = self.read_velocity()
        v = check_array("linear velocity", v, (3,), unit="m/s")
        w = check_array("angular velocity", w, (3,), unit="rad/s")
        gdot = check_number("gap rate", gdot, unit="m/s")
        dt = self.config.dt
        pos = self.config.workspace.clamp(pos + v * dt)
        quat = quat_normalize(quat_multiply(rotvec_to_quat(w * dt), quat))
        gap = float(np.clip(gap + gdot * dt, 0.0, MAX_GAP_M))
        self._target = (pos, quat, gap)
        self.last_action = make_action(pos, quat, gap)
        return self.last_action
