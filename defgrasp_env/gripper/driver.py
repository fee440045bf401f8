"""Gripper actuation: speed-limited, force-limited jaw motion (pure numpy, batched over worlds).

The driver works on the **gap** between the pad inner faces (m, see ``linkage``), like the real
2F-85 whose position register maps to the stroke. Per world and per call:

1. The command is clipped to the linkage range ``[GAP_MIN, GAP_MAX]``.
2. The gap moves toward the command by at most ``closing_speed * dt`` (both directions; the
   2F-85's speed setting applies to opening too).
3. **Force stop (decision):** a closing move is cancelled (the jaw holds its gap) while the grip
   force ``(f_left + f_right) / 2`` is ``>= grip_force_limit``. The mean is what the single motor
   of the symmetric linkage feels: with the object squeezed between both pads it equals the grip
   force, and one pad pushing alone loads the motor at half its force. Opening is always allowed.

The force test uses the forces measured *before* the step, so call the driver at the physics rate
(or sub-step it): at 150 mm/s a 20 Hz control step moves the jaw by 7.5 mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .linkage import GAP_MAX, GAP_MIN, _finite as _array

__all__ = [
    "CLOSING_SPEED_RANGE_MM_S",
    "GRIP_FORCE_RANGE",
    "GripperConfig",
    "GripperDriver",
    "driver_step",
]

CLOSING_SPEED_RANGE_MM_S = (20.0, 150.0)
"""2F-85 closing-speed setting range (mm/s), Robotiq manual."""
GRIP_FORCE_RANGE = (20.0, 235.0)
"""2F-85 grip-force setting range (N), Robotiq manual."""


def _check_scalar(value, lo: float, hi: float, name: str, unit: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number in [{lo:g}, {hi:g}] {unit}, got {value!r}")
    v = float(value)
    if not (math.isfinite(v) and lo <= v <= hi):
        raise ValueError(f"{name} must be in [{lo:g}, {hi:g}] {unit}, got {value:g}")
    return v


@dataclass(frozen=True)
class GripperConfig:
    """Actuation settings of the 2F-85 model (validated, immutable).

    Attributes:
        closing_speed_mm_s: jaw gap speed limit in mm/s, in [20, 150] (the 2F-85 range);
            default 150 (the fastest setting, as for teleoperation).
        grip_force_limit: grip force (N) at which closing stops, in [20, 235] (the 2F-85 range);
            default 20 N, the gentlest real setting, chosen because the objects are soft
            (E down to 1e4 Pa): 20 N on a 22 x 37.5 mm pad is ~24 kPa, already above such
            moduli. Raise it for stiff or heavy objects.
    """

    closing_speed_mm_s: float = 150.0
    grip_force_limit: float = 20.0

    def __post_init__(self) -> None:
        object.__setattr__(
            self,
            "closing_speed_mm_s",
            _check_scalar(self.closing_speed_mm_s, *CLOSING_SPEED_RANGE_MM_S, "closing_speed_mm_s", "mm/s"),
        )
        object.__setattr__(
            self,
            "grip_force_limit",
            _check_scalar(self.grip_force_limit, *GRIP_FORCE_RANGE, "grip_force_limit", "N"),
        )

    @property
    def closing_speed(self) -> float:
        """Jaw gap speed limit in m/s."""
        return self.closing_speed_mm_s * 1e-3


def driver_step(
    config: GripperConfig, cmd_gap, gap, dt: float, force_left, force_right
) -> tuple[np.ndarray, np.ndarray]:
    """One actuation step for a batch of worlds; pure function of its arguments.

    Args:
        config: speed and force settings.
        cmd_gap: commanded gap (m), shape [W] or scalar; clipped to [GAP_MIN, GAP_MAX].
        gap: current gap (m), shape [W] or scalar; must lie in [GAP_MIN, GAP_MAX] (1e-9 m slack).
        dt: step duration (s), > 0.
        force_left, force_right: measured normal force (N, >= 0) on the left / right pad
            inner face, shape [W] or scalar.

    Returns:
        ``(new_gap, force_stopped)``: new gap (m) float64 and a bool mask of worlds whose closing
        move was cancelled by the force limit, both of the broadcast shape of the inputs.

    Raises:
        ValueError/TypeError for non-finite values, ``dt <= 0``, a gap outside the linkage range,
        negative forces or shapes that do not broadcast.
    """
    if not isinstance(config, GripperConfig):
        raise TypeError(f"config must be a GripperConfig, got {type(config).__name__}")
    if isinstance(dt, bool) or not isinstance(dt, (int, float, np.integer, np.floating)):
        raise TypeError(f"dt must be a real number in (0, inf) s, got {dt!r}")
    if not (math.isfinite(dt) and dt > 0.0):
        raise ValueError(f"dt must be in (0, inf) s, got {dt:g}")
    dt = float(dt)
    cmd = _array(cmd_gap, "cmd_gap")
    cur = _array(gap, "gap")
    f_l = _array(force_left, "force_left")
    f_r = _array(force_right, "force_right")
    bad_gap = (cur < GAP_MIN - 1e-9) | (cur > GAP_MAX + 1e-9)
    if np.any(bad_gap):
        raise ValueError(f"gap must be in [{GAP_MIN:.9g}, {GAP_MAX:.9g}] m, got {cur[bad_gap].flat[0]:.9g}")
    for name, f in (("force_left", f_l), ("force_right", f_r)):
        if np.any(f < 0.0):
            raise ValueError(f"{name} must be in [0, inf) N, got {f[f < 0.0].flat[0]:g}")
    try:
        cmd, cur, f_l, f_r = np.broadcast_arrays(cmd, cur, f_l, f_r)
    except ValueError as exc:
        raise ValueError(
            f"cmd_gap {cmd.shape}, gap {cur.shape}, force_left {f_l.shape} and force_right {f_r.shape} "
            "must broadcast to one shape [W]"
        ) from exc

    cur = np.clip(cur, GAP_MIN, GAP_MAX)
    max_move = config.closing_speed * dt
    move = np.clip(np.clip(cmd, GAP_MIN, GAP_MAX) - cur, -max_move, max_move)
    grip_force = 0.5 * (f_l + f_r)
    stopped = (move < 0.0) & (grip_force >= config.grip_force_limit)
    new_gap = np.clip(cur + np.where(stopped, 0.0, move), GAP_MIN, GAP_MAX)
    return new_gap, stopped


@dataclass(frozen=True)
class GripperDriver:
    """Stateless wrapper binding a :class:`GripperConfig` to :func:`driver_step`."""

    config: GripperConfig = GripperConfig()

    def __post_init__(self) -> None:
        if not isinstance(self.config, GripperConfig):
            raise TypeError(f"config must be a GripperConfig, got {type(self.config).__name__}")

    def step(self, cmd_gap, gap, dt: float, force_left, force_right) -> np.ndarray:
        """New gap (m) for each world; see :func:`driver_step` for shapes and rules."""
        return driver_step(self.config, cmd_gap, gap, dt, force_left, force_right)[0]

    def step_with_status(self, cmd_gap, gap, dt: float, force_left, force_right) -> tuple[np.ndarray, np.ndarray]:
        """``(new_gap, force_stopped)``; see :func:`driver_step`."""
        return driver_step(self.config, cmd_gap, gap, dt, force_left, force_right)
