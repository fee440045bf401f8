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
4. **Force regulation** (when a grip stiffness k > 0, N/m, is known): the real gripper's motor
   current limit never lets the grip force exceed its setting, but a position-driven jaw that
   tests the force only between moves overshoots by k times the last move (a stiff object,
   E = 1e7, was held at ~95-120 N with the 20 N limit). With k known, the jaw instead moves to
   where the force is predicted to equal the limit: a closing move is shortened to
   (limit - force) / k, and above the limit the jaw opens by (force - limit) / k, both within the
   speed limit; a command that opens further wins. ``update_grip_stiffness`` estimates k from
   the forces before and after each move.

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
    "CONTACT_FORCE",
    "GRIP_FORCE_RANGE",
    "GripperConfig",
    "GripperDriver",
    "driver_step",
    "update_grip_stiffness",
]

CLOSING_SPEED_RANGE_MM_S = (20.0, 150.0)
"""2F-85 closing-speed setting range (mm/s), Robotiq manual."""
GRIP_FORCE_RANGE = (20.0, 235.0)
"""2F-85 grip-force setting range (N), Robotiq manual."""
CONTACT_FORCE = 0.05
"""Grip force (N) above which the pads count as touching the object, for the stiffness estimate."""
MAX_GRIP_STIFFNESS = 1e8
"""Upper bound (N/m) of a stiffness estimate (a noisy reading over a tiny move is clipped)."""


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
    config: GripperConfig, cmd_gap, gap, dt: float, force_left, force_right, grip_stiffness=0.0
) -> tuple[np.ndarray, np.ndarray]:
    """One actuation step for a batch of worlds; pure function of its arguments.

    Args:
        config: speed and force settings.
        cmd_gap: commanded gap (m), shape [W] or scalar; clipped to [GAP_MIN, GAP_MAX].
        gap: current gap (m), shape [W] or scalar; must lie in [GAP_MIN, GAP_MAX] (1e-9 m slack).
        dt: step duration (s), > 0.
        force_left, force_right: measured normal force (N, >= 0) on the left / right pad
            inner face, shape [W] or scalar.
        grip_stiffness: d(grip force)/d(closing) (N/m, >= 0) per world, 0 where unknown (rule 4
            applies where it is > 0); shape [W] or scalar.

    Returns:
        ``(new_gap, force_stopped)``: new gap (m) float64 and a bool mask of worlds whose closing
        move was cancelled, shortened or reversed by the force limit, both of the broadcast shape
        of the inputs.

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
    k = _array(grip_stiffness, "grip_stiffness")
    bad_gap = (cur < GAP_MIN - 1e-9) | (cur > GAP_MAX + 1e-9)
    if np.any(bad_gap):
        raise ValueError(f"gap must be in [{GAP_MIN:.9g}, {GAP_MAX:.9g}] m, got {cur[bad_gap].flat[0]:.9g}")
    for name, f, unit in (("force_left", f_l, "N"), ("force_right", f_r, "N"), ("grip_stiffness", k, "N/m")):
        if np.any(f < 0.0):
            raise ValueError(f"{name} must be in [0, inf) {unit}, got {f[f < 0.0].flat[0]:g}")
    try:
        cmd, cur, f_l, f_r, k = np.broadcast_arrays(cmd, cur, f_l, f_r, k)
    except ValueError as exc:
        raise ValueError(
            f"cmd_gap {cmd.shape}, gap {cur.shape}, force_left {f_l.shape}, force_right {f_r.shape} and "
            f"grip_stiffness {k.shape} must broadcast to one shape [W]"
        ) from exc

    cur = np.clip(cur, GAP_MIN, GAP_MAX)
    max_move = config.closing_speed * dt
    move = np.clip(np.clip(cmd, GAP_MIN, GAP_MAX) - cur, -max_move, max_move)
    grip_force = 0.5 * (f_l + f_r)
    known = k > 0.0
    # rule 4: the closing move allowed before the force reaches the limit (negative: open)
    allowed = (config.grip_force_limit - grip_force) / np.where(known, k, 1.0)
    regulated = np.clip(np.maximum(move, -allowed), -max_move, max_move)
    stopped = (move < 0.0) & np.where(known, regulated > move, grip_force >= config.grip_force_limit)
    new_move = np.where(known, regulated, np.where(stopped, 0.0, move))
    return np.clip(cur + new_move, GAP_MIN, GAP_MAX), stopped


def update_grip_stiffness(stiffness, gap_before, gap_after, force_before, force_after, cmd_gap) -> np.ndarray:
    """Estimate of d(grip force)/d(closing) (N/m) per world after a jaw move, for rule 4.

    Args (shape [W] or scalar): the current estimate (0 = unknown); the gap (m) before and after
    the move; the grip force (N, mean of the two pads) measured before and after it; the
    commanded gap (m).

    * touching before and after, the gap changed by >= 1 um and the force with it: the secant
      (force_after - force_before) / (gap_before - gap_after), clipped to MAX_GRIP_STIFFNESS;
    * first touch on a closing move: 2 force_after / closing, as if contact began halfway through
      the move (it began somewhere during it): if it began earlier the jaw backs off too little and
      the next secant is exact, if later it backs off too far and closes back by
      (limit - force) / k; kept if larger than the current estimate;
    * not touching and the command is to open or hold (a release): 0 again; a contact lost while
      the jaw backs off under a closing command keeps its estimate, so that the jaw closes back
      by (limit - force) / k instead of overshooting again at full speed;
    * a closing move that neither started nor ended touching: halved (below 1 N/m: 0), so a jaw
      that closes on nothing (the object slipped out) doubles its step each substep back to the
      speed limit;
    * otherwise unchanged.
    """
    k, g0, g1, f0, f1, cmd = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (
        stiffness, gap_before, gap_after, force_before, force_after, cmd_gap)))
    closing = g0 - g1
    touch0, touch1 = f0 >= CONTACT_FORCE, f1 >= CONTACT_FORCE
    moved = np.abs(closing) >= 1e-6
    secant = np.divide(f1 - f0, closing, out=np.zeros_like(k), where=moved)
    two_point = touch0 & touch1 & moved & (secant > 0.0)
    first_touch = ~touch0 & touch1 & (closing >= 1e-6)
    halfway = np.divide(2.0 * f1, closing, out=np.zeros_like(k), where=closing >= 1e-6)
    released = ~touch1 & (cmd >= g1)
    coasting = ~touch0 & ~touch1 & (closing >= 1e-6)
    out = np.where(two_point, secant, np.where(first_touch, np.maximum(k, halfway), np.where(coasting, 0.5 * k, k)))
    out = np.where(released | (out < 1.0), 0.0, out)
    return np.minimum(out, MAX_GRIP_STIFFNESS)


@dataclass(frozen=True)
class GripperDriver:
    """Stateless wrapper binding a :class:`GripperConfig` to :func:`driver_step`."""

    config: GripperConfig = GripperConfig()

    def __post_init__(self) -> None:
        if not isinstance(self.config, GripperConfig):
            raise TypeError(f"config must be a GripperConfig, got {type(self.config).__name__}")

    def step(self, cmd_gap, gap, dt: float, force_left, force_right, grip_stiffness=0.0) -> np.ndarray:
        """New gap (m) for each world; see :func:`driver_step` for shapes and rules."""
        return driver_step(self.config, cmd_gap, gap, dt, force_left, force_right, grip_stiffness)[0]
