"""Smoothing and safety of the slave command: rate limits, a workspace box, hold-on-loss.

All limits are per control step: a speed limit ``v`` with step ``dt`` moves at most ``v * dt``.

* translation: the step toward the target is shortened along the straight line;
* rotation: slerp toward the target by at most ``max_angular_speed_rad_s * dt``;
* gap: moved toward the target by at most ``max_gap_speed_m_s * dt`` (the 2F-85 closes at
  20..150 mm/s);
* the workspace box clamps the target position before the rate limit (y up, world frame);
* ``LossGate`` tracks whether the inputs are usable; while they are not, the caller holds its last
  command, and on the first usable input after a loss it reports ``RESUME`` so the caller can
  re-calibrate the offset (eq. 1-2) and continue from where the slave is, without a jump.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

from .._validate import check_array, check_number
from ..se3 import quat_angle, quat_normalize, quat_slerp


def limit_translation(previous, target, max_step_m: float) -> np.ndarray:
    """Move from ``previous`` toward ``target`` [3] by at most ``max_step_m`` (straight line)."""
    p0 = check_array("previous", previous, (3,))
    p1 = check_array("target", target, (3,))
    step = check_number("max_step_m", max_step_m, 0.0, unit="m")
    d = p1 - p0
    n = float(np.linalg.norm(d))
    return p1 if n <= step else p0 + d * (step / n)


def limit_rotation(previous, target, max_step_rad: float) -> np.ndarray:
    """Rotate quaternion (x, y, z, w) ``previous`` toward ``target`` by at most ``max_step_rad``."""
    q0 = quat_normalize(check_array("previous", previous, (4,)))
    q1 = quat_normalize(check_array("target", target, (4,)))
    step = check_number("max_step_rad", max_step_rad, 0.0, unit="rad")
    ang = quat_angle(q0, q1)
    return q1 if ang <= step else quat_slerp(q0, q1, step / ang)


def limit_scalar(previous: float, target: float, max_step: float) -> float:
    """Move ``previous`` toward ``target`` by at most ``max_step``."""
    p0 = check_number("previous", previous)
    p1 = check_number("target", target)
    step = check_number("max_step", max_step, 0.0)
    return p0 + float(np.clip(p1 - p0, -step, step))


@dataclass(frozen=True)
class WorkspaceBox:
    """Axis-aligned box in the world frame (m, y up): ``lo`` < ``hi`` per axis."""

    lo: tuple[float, float, float] = (-0.5, 0.0, -0.5)
    hi: tuple[float, float, float] = (0.5, 1.0, 0.5)

    def __post_init__(self):
        lo = check_array("WorkspaceBox.lo", self.lo, (3,), unit="m")
        hi = check_array("WorkspaceBox.hi", self.hi, (3,), unit="m")
        if np.any(lo >= hi):
            raise ValueError(f"WorkspaceBox.lo must be < hi on every axis, got lo={lo.tolist()} hi={hi.tolist()}")
        object.__setattr__(self, "lo", tuple(lo.tolist()))
        object.__setattr__(self, "hi", tuple(hi.tolist()))

    def clamp(self, position) -> np.ndarray:
        p = check_array("position", position, (3,), unit="m")
        return np.clip(p, self.lo, self.hi)

    def contains(self, position) -> bool:
        p = check_array("position", position, (3,), unit="m")
        return bool(np.all(p >= self.lo) and np.all(p <= self.hi))


@dataclass(frozen=True)
class RateLimits:
    """Per-step limits of the slave command. dt: control period (s), default the env's 20 Hz."""

    max_speed_m_s: float = 0.5
    max_angular_speed_rad_s: float = 3.0
    max_gap_speed_m_s: float = 0.15
    dt: float = 0.05

    def __post_init__(self):
        check_number("RateLimits.max_speed_m_s", self.max_speed_m_s, 0.0, unit="m/s", lo_open=True)
        check_number("RateLimits.max_angular_speed_rad_s", self.max_angular_speed_rad_s, 0.0, unit="rad/s", lo_open=True)
        check_number("RateLimits.max_gap_speed_m_s", self.max_gap_speed_m_s, 0.0, unit="m/s", lo_open=True)
        check_number("RateLimits.dt", self.dt, 0.0, 10.0, unit="s", lo_open=True)


@dataclass
class Command:
    """A slave command: flange position [3] m, quaternion (x, y, z, w), jaw gap m."""

    position: np.ndarray
    quat_xyzw: np.ndarray
    gap_m: float

    def copy(self) -> "Command":
        return Command(self.position.copy(), self.quat_xyzw.copy(), float(self.gap_m))


@dataclass
class CommandFilter:
    """Workspace clamp then rate limit of a target command against the previous command."""

    limits: RateLimits = field(default_factory=RateLimits)
    workspace: WorkspaceBox = field(default_factory=WorkspaceBox)

    def step(self, previous: Command, target: Command) -> Command:
        l = self.limits
        pos = limit_translation(previous.position, self.workspace.clamp(target.position), l.max_speed_m_s * l.dt)
        quat = limit_rotation(previous.quat_xyzw, target.quat_xyzw, l.max_angular_speed_rad_s * l.dt)
        gap = limit_scalar(previous.gap_m, target.gap_m, l.max_gap_speed_m_s * l.dt)
        return Command(pos, quat, gap)


class GateEvent(enum.Enum):
    ACTIVE = "active"  # inputs usable, keep going
    HOLD = "hold"  # inputs lost: hold the last command
    RESUME = "resume"  # first usable input after a loss: re-calibrate, then go on


class LossGate:
    """Hold-on-loss state machine. ``resume_after``: consecutive usable inputs needed to resume
    (debounces a flickering tracker)."""

    def __init__(self, resume_after: int = 1):
        if isinstance(resume_after, bool) or not isinstance(resume_after, int) or resume_after < 1:
            raise ValueError(f"resume_after must be an int in [1, inf), got {resume_after!r}")
        self.resume_after = resume_after
        self.holding = False
        self._ok_run = 0

    def reset(self) -> None:
        self.holding = False
        self._ok_run = 0

    def update(self, ok: bool) -> GateEvent:
        if not ok:
            self.holding = True
            self._ok_run = 0
            return GateEvent.HOLD
        if not self.holding:
            return GateEvent.ACTIVE
        self._ok_run += 1
        if self._ok_run < self.resume_after:
            return GateEvent.HOLD
        self.holding = False
        self._ok_run = 0
        return GateEvent.RESUME
