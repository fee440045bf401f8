"""``HumanTeleopAgent``: tracker + glove -> absolute actions, env info -> glove haptics.

Per ``act(obs)`` (one control step):

1. read the tracker and the glove (never blocks);
2. ``LossGate``: if the tracker is not tracking or the glove is not connected, return the last
   command unchanged (hold); on the first usable step after a loss, re-calibrate the offset so the
   current master pose maps to the last command: the slave continues from where it is, no jump;
3. eq. 1-2 (``OffsetRetargeter``): flange target = T_O^{O'} . T_master . T_wrist^{tracker}; the
   offset is calibrated on the first step after ``reset()`` against the observed gripper pose
   (``obs["agent_pos"]``) unless a fixed offset is configured;
4. eq. 4 (``PinchRetargeter``): jaw gap from the thumb-index distance;
5. workspace box + per-step rate limits against the previous command (``CommandFilter``);
6. eq. 3 (``WristIK``): IK warm-started from the previous joints, clamped to the limits, FK of the
   clamped joints = the reachable pose sent (``use_ik=False`` skips this and sends step 5's pose).

``send_feedback(info)`` maps ``left/right_tip_normal_force`` to force feedback and contact-onset
vibration (``HapticsMapper``) and sends it to the glove every step; ``latency_s`` is the time from
the oldest device sample used by the last active ``act`` to that haptic command (host monotonic
clock; devices and agent must share it, all default to ``time.monotonic``).
"""

from __future__ import annotations

import collections
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ._validate import check_array, check_choice
from .sensors.base import GloveSample, HapticGlove, PoseTracker, TrackerSample
from .haptics import HapticCommand, HapticsConfig, HapticsMapper
from .retarget.offset import CALIBRATION_MODES, OffsetRetargeter
from .retarget.pinch import PinchResult, PinchRetargeter
from .retarget.smoothing import Command, CommandFilter, GateEvent, LossGate, RateLimits, WorkspaceBox
from .se3 import check_rigid, matrix_to_quat, pose_to_matrix
from .teleop_device import MAX_GAP_M, TeleopDevice, make_action, parse_agent_state


@dataclass(frozen=True)
class HumanTeleopConfig:
    """offset: fixed T_O^{O'} (4x4) or None to calibrate on the first step; frame_rotation: 3x3
    OpenVR -> world (None = identity); tracker_to_flange: T_wrist^{tracker} (None = identity);
    resume_after: usable steps needed to leave a hold; latency_window: latencies kept."""

    limits: RateLimits = field(default_factory=RateLimits)
    workspace: WorkspaceBox = field(default_factory=WorkspaceBox)
    haptics: HapticsConfig = field(default_factory=HapticsConfig)
    calibration_mode: str = "full"
    offset: tuple | None = None
    frame_rotation: tuple | None = None
    tracker_to_flange: tuple | None = None
    use_ik: bool = True
    resume_after: int = 1
    latency_window: int = 1000

    def __post_init__(self):
        check_choice("calibration_mode", self.calibration_mode, CALIBRATION_MODES)
        for name, typ in (("limits", RateLimits), ("workspace", WorkspaceBox), ("haptics", HapticsConfig)):
            if not isinstance(getattr(self, name), typ):
                raise TypeError(f"{name} must be a {typ.__name__}, got {getattr(self, name)!r}")
        if self.offset is not None:
            object.__setattr__(self, "offset", tuple(map(tuple, check_rigid("offset", self.offset).tolist())))
        if self.tracker_to_flange is not None:
            object.__setattr__(self, "tracker_to_flange", tuple(map(tuple, check_rigid("tracker_to_flange", self.tracker_to_flange).tolist())))
        if self.frame_rotation is not None:
            object.__setattr__(self, "frame_rotation", tuple(map(tuple, check_array("frame_rotation", self.frame_rotation, (3, 3)).tolist())))
        if not isinstance(self.use_ik, bool):
            raise TypeError(f"use_ik must be a bool, got {self.use_ik!r}")
        if isinstance(self.latency_window, bool) or not isinstance(self.latency_window, int) or self.latency_window < 1:
            raise ValueError(f"latency_window must be an int in [1, inf), got {self.latency_window!r}")
        LossGate(self.resume_after)  # validates


class HumanTeleopAgent(TeleopDevice):
    """See module doc. tracker: PoseTracker; glove: HapticGlove; wrist_ik: a ``WristIK`` (built
    on first use when ``use_ik``); pinch: a ``PinchRetargeter`` (default: finger-URDF FK)."""

    def __init__(
        self,
        tracker: PoseTracker,
        glove: HapticGlove,
        config: HumanTeleopConfig | None = None,
        *,
        wrist_ik=None,
        pinch: PinchRetargeter | None = None,
        clock: Callable[[], float] = time.monotonic,
    ):
        if not isinstance(tracker, PoseTracker):
            raise TypeError(f"tracker must be a PoseTracker, got {type(tracker).__name__}")
        if not isinstance(glove, HapticGlove):
            raise TypeError(f"glove must be a HapticGlove, got {type(glove).__name__}")
        self.config = config or HumanTeleopConfig()
        if not isinstance(self.config, HumanTeleopConfig):
            raise TypeError(f"config must be a HumanTeleopConfig, got {self.config!r}")
        c = self.config
        self.tracker, self.glove, self._clock = tracker, glove, clock
        self.retargeter = OffsetRetargeter(
            offset=None if c.offset is None else np.array(c.offset), tracker_to_flange=None if c.tracker_to_flange is None else np.array(c.tracker_to_flange),
            frame_rotation=None if c.frame_rotation is None else np.array(c.frame_rotation), mode=c.calibration_mode,
        )
        self.pinch = pinch or PinchRetargeter()
        if c.use_ik and wrist_ik is None:
            from .retarget.wrist_ik import WristIK

            wrist_ik = WristIK()
        self.wrist_ik = wrist_ik
        self.filter = CommandFilter(c.limits, c.workspace)
        self.gate = LossGate(c.resume_after)
        self.haptics = HapticsMapper(c.haptics)
        self.latencies: collections.deque = collections.deque(maxlen=c.latency_window)
        self.reset()

    # TeleopDevice lifecycle -----------------------------------------------------------------------
    @property
    def is_connected(self) -> bool:
        return self.tracker.is_connected and self.glove.is_connected

    def connect(self, calibrate: bool = True) -> None:
        self.tracker.connect()
        self.glove.connect()

    def disconnect(self) -> None:
        self.tracker.disconnect()
        self.glove.disconnect()

    @property
    def is_calibrated(self) -> bool:
        return self.retargeter.calibrated and not self._calibrate_next

    def calibrate(self) -> None:
        """Re-calibrate the offset on the next ``act``: the operator's pose then maps to the
        gripper's current command (the pinch map is calibrated with ``calibrate_pinch``)."""
        self._calibrate_next = True

    def calibrate_pinch(self, closed: GloveSample, open_: GloveSample):
        """Pinch map from a pinch-closed and an open-hand glove sample (eq. 4 calibration)."""
        return self.pinch.calibrate(closed, open_)

    def reset(self) -> None:
        self._cmd: Command | None = None
        self._q: np.ndarray | None = None
        self._calibrate_next = self.config.offset is None
        self._input_t: float | None = None
        self.gate.reset()
        self.haptics.reset()
        self.last_action: np.ndarray | None = None
        self.status = "idle"
        self.last_tracker: TrackerSample | None = None
        self.last_glove: GloveSample | None = None
        self.last_pinch: PinchResult | None = None
        self.last_ik = None
        self.last_haptics: HapticCommand | None = None
        self.latency_s: float | None = None

    # control step -----------------------------------------------------------------------------------
    @property
    def q(self) -> np.ndarray | None:
        """Current wrist joints [6] (eq. 3 warm start), None before the first act or without IK."""
        return None if self._q is None else self._q.copy()

    def act(self, obs) -> np.ndarray:
        if not self.is_connected:
            raise RuntimeError("HumanTeleopAgent.act() needs connect() first")
        pos, quat, gap = parse_agent_state(obs)
        if self._cmd is None:
            self._cmd = Command(pos, quat, gap)
            if self.wrist_ik is not None:
                r = self.wrist_ik.solve(pos, quat, self.wrist_ik.home_q)
                self._q = r.q
        ts, gs = self.tracker.read(), self.glove.read()
        self.last_tracker, self.last_glove = ts, gs
        event = self.gate.update(ts.valid and gs.connected)
        if event is GateEvent.HOLD:
            self.status = "hold"
            self._input_t = None
            self.last_action = self._action(self._cmd)
            return self.last_action
        if event is GateEvent.RESUME or self._calibrate_next:
            self.retargeter.calibrate(ts.pose, pose_to_matrix(self._cmd.position, self._cmd.quat_xyzw))
            self._calibrate_next = False
        self.status = "resume" if event is GateEvent.RESUME else "active"
        T = self.retargeter.slave_pose(ts.pose)
        self.last_pinch = self.pinch(gs)
        target = Command(T[:3, 3], matrix_to_quat(T[:3, :3]), self.last_pinch.reachable_gap_m)
        cmd = self.filter.step(self._cmd, target)
        if self.wrist_ik is not None:
            r = self.wrist_ik.solve(cmd.position, cmd.quat_xyzw, self._q)
            self.last_ik, self._q = r, r.q
            cmd = Command(r.position, r.quat_xyzw, cmd.gap_m)
        self._cmd = cmd
        self._input_t = min(ts.timestamp_s, gs.timestamp_s)
        self.last_action = self._action(cmd)
        return self.last_action

    @property
    def driver_angle_rad(self) -> float | None:
        """2F-85 driver angle (rad) of the commanded gap (eq. 4's geometric IK), None before act."""
        if self._cmd is None:
            return None
        from .retarget.gripper_ik import driver_angle_from_gap

        return driver_angle_from_gap(float(np.clip(self._cmd.gap_m, 0.0, MAX_GAP_M)))[0]

    @staticmethod
    def _action(cmd: Command) -> np.ndarray:
        return make_action(cmd.position, cmd.quat_xyzw, float(np.clip(cmd.gap_m, 0.0, MAX_GAP_M)))

    # haptics -----------------------------------------------------------------------------------------
    def send_feedback(self, feedback: dict) -> None:
        """Map the env info's tip normal forces to glove haptics and send them (every step)."""
        if not self.is_connected:
            raise RuntimeError("HumanTeleopAgent.send_feedback() needs connect() first")
        cmd = self.haptics.from_info(feedback)
        self.last_haptics = cmd
        sent = self.glove.send_haptics(cmd.force_feedback, cmd.vibration, cmd.vibration_duration_s)
        if sent and self._input_t is not None:
            self.latency_s = self._clock() - self._input_t
            self.latencies.append(self.latency_s)
            self._input_t = None

    def latency_stats(self) -> dict[str, float]:
        """count, mean_s, p50_s, p95_s, max_s over the last ``latency_window`` latencies."""
        if not self.latencies:
            return {"count": 0}
        a = np.array(self.latencies)
        return {"count": int(a.size), "mean_s": float(a.mean()), "p50_s": float(np.percentile(a, 50)),
                "p95_s": float(np.percentile(a, 95)), "max_s": float(a.max())}
