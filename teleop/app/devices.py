"""Device choice of the collection app: ``--tracker`` / ``--glove`` specs -> one ``TeleopDevice``.

Specs are ``name`` or ``name:argument`` looked up in two registries (no if/elif factories):

* trackers (``TRACKERS``): ``udp`` (``UdpTrackerReceiver``, a bridge streams poses), ``openvr``
  (``OpenVRTracker``, SteamVR; ``openvr:SERIAL`` picks a tracker), ``replay:PATH`` (a recorded
  ``.jsonl``/``.npz`` stream), ``keyboard`` (no tracker: ``KeyboardTeleop`` drives the flange);
* gloves (``GLOVES``): ``udp`` (``UdpGloveReceiver``, SenseGlove bridge), ``replay:PATH``,
  ``none`` (no glove: with a pose tracker the jaw follows keys q = open / e = close,
  ``KeyJawGlove``; with the keyboard or a SpaceMouse the jaw is theirs anyway).

``--spacemouse`` replaces the tracker by ``SpaceMouseTeleop``. A pose tracker + glove become a
``HumanTeleopAgent`` whose wrist IK (eq. 3) is ``IK_SOLVERS[ik]``: ``analytic`` (closed form of the
3-prismatic + 3-revolute wrist, exact and ~100x faster) or ``iterative`` (pytorch-kinematics
``PseudoInverseIK``, the agent's default).

Replay devices run on the session's episode clock (simulation time, restarting at every episode),
so a recorded stream stays in step with the simulation however fast the loop runs; their latency
readings are then meaningless and ``Controller.live_latency`` is False.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from ..agent import HumanTeleopAgent, HumanTeleopConfig
from ..sensors.base import GloveSample, HapticGlove, PoseTracker, require_connected
from ..devices.keyboard import DEFAULT_KEY_BINDINGS, KeyboardTeleop
from ..sensors.openvr_tracker import OpenVRTracker
from ..sensors.replay import ReplayGlove, ReplayTracker
from ..devices.spacemouse import SpaceMouseTeleop
from ..sensors.udp_glove import DEFAULT_GLOVE_PORT, UdpGloveReceiver
from ..sensors.udp_tracker import DEFAULT_TRACKER_PORT, UdpTrackerReceiver
from ..devices.velocity import VelocityTeleopConfig
from ..retarget.pinch import PinchGapMap, PinchRetargeter
from ..retarget.smoothing import RateLimits
from ..teleop_device import TeleopDevice

#: Keyboard flange bindings of the app: ``s`` is the success key, so "back" (+z) moves to ``x``.
APP_KEYBOARD_BINDINGS = {**{k: v for k, v in DEFAULT_KEY_BINDINGS.items() if k != "s"}, "x": ("lin", 2, +1)}


@dataclass(frozen=True)
class DeviceSpec:
    """A parsed ``name[:argument]`` device spec."""

    name: str
    argument: str | None = None


@dataclass
class DeviceContext:
    """What device builders may need. episode_clock: simulation time of the episode (s)."""

    held_keys: Callable[[], set[str]] = set
    episode_clock: Callable[[], float] = time.monotonic
    host: str = "127.0.0.1"
    tracker_port: int = DEFAULT_TRACKER_PORT
    glove_port: int = DEFAULT_GLOVE_PORT
    dt: float = 0.05


@dataclass
class Controller:
    """The app's input: a TeleopDevice plus how it was made."""

    device: TeleopDevice
    description: str
    live_latency: bool
    parts: dict = field(default_factory=dict)

    def has_data(self) -> bool:
        """True when the devices send usable data now: the pose tracker is tracking and the glove
        (if any) connected. Devices without a stream (keyboard, SpaceMouse) always have data. Reads
        the devices (they must be connected); reading does not consume samples."""
        tracker, glove = self.parts.get("tracker"), self.parts.get("glove")
        if tracker is None:
            return True
        return bool(tracker.read().valid) and (glove is None or bool(glove.read().connected))


class KeyJawGlove(HapticGlove):
    """Stand-in glove when there is none: the pinch distance follows held keys (``open_key``
    widens, ``close_key`` narrows at the rate that moves the jaw at ``gap_speed_m_s``) and is
    reported as SDK fingertips (use a ``PinchRetargeter(source="sdk")`` with the same map).
    Haptics go nowhere (``send_haptics`` returns False)."""

    def __init__(self, held_keys: Callable[[], set[str]], gap_map: PinchGapMap | None = None, *,
                 gap_speed_m_s: float = 0.05, open_key: str = "q", close_key: str = "e",
                 clock: Callable[[], float] = time.monotonic):
        self.gap_map = gap_map or PinchGapMap()
        self._held, self._clock = held_keys, clock
        self.open_key, self.close_key = open_key, close_key
        span = self.gap_map.d_open_m - self.gap_map.d_closed_m
        self._rate = gap_speed_m_s * span / (self.gap_map.gap_open_m - self.gap_map.gap_closed_m)
        self.distance_m = self.gap_map.d_open_m
        self._t: float | None = None
        self._connected = False

    def connect(self) -> None:
        self._connected = True
        self._t = None

    def disconnect(self) -> None:
        self._connected = False

    @property
    def is_connected(self) -> bool:
        return self._connected

    def read(self) -> GloveSample:
        require_connected(self, "read")
        now = self._clock()
        if self._t is not None:
            keys = self._held()
            direction = (self.open_key in keys) - (self.close_key in keys)
            m = self.gap_map
            self.distance_m = float(np.clip(self.distance_m + direction * self._rate * (now - self._t), m.d_closed_m, m.d_open_m))
        self._t = now
        tips = np.zeros((5, 3))
        tips[0] = [0.10, 0.03, -0.03]
        tips[1] = tips[0] + [self.distance_m, 0.0, 0.0]
        return GloveSample(np.zeros((5, 4)), tips, True, now)

    def send_haptics(self, force_feedback, vibration, vibration_duration_s: float) -> bool:
        return False


class AnalyticWristKinematics:
    """``WristIK`` backend with the closed-form IK of ``defgrasp_env.wrist.analytic`` (the warm
    start is not needed: the solution within the limits is unique)."""

    def __init__(self):
        from defgrasp_env.wrist import JOINT_LOWER, JOINT_UPPER

        self.lower = np.asarray(JOINT_LOWER, dtype=np.float64)
        self.upper = np.asarray(JOINT_UPPER, dtype=np.float64)

    def fk(self, q):
        from defgrasp_env.wrist import fk_analytic

        return fk_analytic(q)

    def ik(self, target_pos, target_quat_xyzw, q_init):
        from defgrasp_env.wrist import ik_analytic

        return ik_analytic(target_pos, target_quat_xyzw, lower=self.lower, upper=self.upper)


def _wrist_ik(kinematics_factory):
    def build():
        from ..retarget.wrist_ik import WristIK

        return WristIK(kinematics_factory() if kinematics_factory else None)

    return build


#: name -> factory of a ``WristIK`` (eq. 3)
IK_SOLVERS: Mapping[str, Callable[[], object]] = {
    "analytic": _wrist_ik(AnalyticWristKinematics),
    "iterative": _wrist_ik(None),
}


def _need(spec: DeviceSpec, what: str) -> str:
    if not spec.argument:
        raise ValueError(f"{what} {spec.name!r} needs an argument: {spec.name}:PATH")
    return spec.argument


def _no_arg(spec: DeviceSpec, what: str) -> None:
    if spec.argument is not None:
        raise ValueError(f"{what} {spec.name!r} takes no argument, got {spec.name}:{spec.argument}")


def _udp_tracker(spec, ctx):
    _no_arg(spec, "tracker")
    return UdpTrackerReceiver(ctx.host, ctx.tracker_port)


def _openvr_tracker(spec, ctx):
    return OpenVRTracker(spec.argument or None)


def _replay_tracker(spec, ctx):
    return ReplayTracker(_need(spec, "tracker"), realtime=True, clock=ctx.episode_clock)


def _udp_glove(spec, ctx):
    _no_arg(spec, "glove")
    return UdpGloveReceiver(ctx.host, ctx.glove_port)


def _replay_glove(spec, ctx):
    return ReplayGlove(_need(spec, "glove"), realtime=True, clock=ctx.episode_clock)


def _no_glove(spec, ctx):
    _no_arg(spec, "glove")
    return None


#: tracker name -> builder(spec, ctx) of a PoseTracker, or None for "no pose tracker" (keyboard)
TRACKERS: Mapping[str, Callable] = {
    "udp": _udp_tracker,
    "openvr": _openvr_tracker,
    "replay": _replay_tracker,
    "keyboard": lambda spec, ctx: _no_arg(spec, "tracker"),
}
#: glove name -> builder(spec, ctx) of a HapticGlove, or None (no glove)
GLOVES: Mapping[str, Callable] = {"udp": _udp_glove, "replay": _replay_glove, "none": _no_glove}


def parse_device_spec(text: str, registry: Mapping[str, Callable], what: str) -> DeviceSpec:
    """``name`` or ``name:argument`` with ``name`` in ``registry``; ValueError listing the names."""
    if not isinstance(text, str) or not text:
        raise ValueError(f"{what} must be one of {sorted(registry)} (name or name:ARG), got {text!r}")
    name, sep, arg = text.partition(":")
    if name not in registry:
        raise ValueError(f"{what} must be one of {sorted(registry)} (name or name:ARG), got {text!r}")
    return DeviceSpec(name, arg if sep else None)


def build_controller(tracker: str | None = "udp", glove: str | None = None, *, spacemouse: bool = False,
                     ctx: DeviceContext | None = None, agent_config: HumanTeleopConfig | None = None,
                     ik: str = "analytic") -> Controller:
    """The app's ``TeleopDevice`` for the given specs (module doc). ``glove`` None means ``udp``
    with a pose tracker and ``none`` with the keyboard / SpaceMouse."""
    ctx = ctx or DeviceContext()
    if ik not in IK_SOLVERS:
        raise ValueError(f"ik must be one of {sorted(IK_SOLVERS)}, got {ik!r}")
    velocity_cfg = VelocityTeleopConfig(dt=ctx.dt)
    if spacemouse:
        if tracker not in (None, "keyboard") or glove not in (None, "none"):
            raise ValueError(f"--spacemouse replaces the tracker and the glove; got tracker={tracker!r}, glove={glove!r}")
        return Controller(SpaceMouseTeleop(velocity_cfg), "SpaceMouse (jaw: buttons 0 close / 1 open)", False)
    t_spec = parse_device_spec(tracker or "udp", TRACKERS, "tracker")
    pose_tracker: PoseTracker | None = TRACKERS[t_spec.name](t_spec, ctx)
    if pose_tracker is None:  # keyboard
        if glove not in (None, "none"):
            raise ValueError(f"--tracker keyboard drives the jaw with q/e; it takes no glove, got --glove {glove}")
        return Controller(KeyboardTeleop(ctx.held_keys, velocity_cfg, bindings=APP_KEYBOARD_BINDINGS),
                          "keyboard (w/x/a/d/r/f move, i/k j/l u/o turn, q/e jaw)", False)
    g_spec = parse_device_spec(glove or "udp", GLOVES, "glove")
    hand: HapticGlove | None = GLOVES[g_spec.name](g_spec, ctx)
    pinch = None
    if hand is None:
        gap_map = PinchGapMap()
        hand = KeyJawGlove(ctx.held_keys, gap_map, clock=ctx.episode_clock if t_spec.name == "replay" else time.monotonic)
        pinch = PinchRetargeter(source="sdk", gap_map=gap_map)
    replay = t_spec.name == "replay" or g_spec.name == "replay"
    agent = HumanTeleopAgent(pose_tracker, hand, agent_config or HumanTeleopConfig(limits=RateLimits(dt=ctx.dt)), wrist_ik=IK_SOLVERS[ik](),
                             pinch=pinch, clock=ctx.episode_clock if replay else time.monotonic)
    text = f"tracker {tracker or 'udp'} + glove {glove or 'udp'}" + (" (jaw: q open / e close)" if g_spec.name == "none" else "")
    return Controller(agent, f"{text}, {ik} wrist IK", not replay, {"tracker": pose_tracker, "glove": hand})
