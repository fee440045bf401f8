"""``TeleopDevice``: LeRobot's Teleoperator contract, plus ``act``/``reset`` for policy loops.

LeRobot (``lerobot.teleoperators.Teleoperator``) asks for ``action_features``, ``feedback_features``,
``is_connected``, ``connect(calibrate)``, ``is_calibrated``, ``calibrate()``, ``configure()``,
``get_action() -> dict``, ``send_feedback(dict)``, ``disconnect()``. We follow it by duck typing
rather than subclassing, because LeRobot's base creates calibration folders and needs a registered
draccus config. Every TeleopDevice also has ``act(obs) -> float32[8]`` and ``reset()``, so it runs
in the same loop as a learned policy:

    obs, info = env.reset(); teleop.reset()
    while True:
        action = teleop.act(obs)
        obs, reward, term, trunc, info = env.step(action)
        teleop.send_feedback(info)

Action ("absolute" mode of DeformablePickup-v0, ``defgrasp_env.layout.ABSOLUTE_ACTION``): float32
[8] = flange position [3] m (world, y up), flange orientation quaternion (x, y, z, w) [4], jaw gap
[1] m in [0, ``MAX_GAP_M``] (0.085 m, the 2F-85 stroke). ``ACTION_NAMES`` are LeRobot's flat keys
of those entries, in the layout's order.
"""

from __future__ import annotations

import abc
from typing import Any

import numpy as np

from defgrasp_env.layout import ABSOLUTE_ACTION, AGENT_POS, JAW_GAP_MAX

from ._validate import check_array, check_number
from .se3 import quat_normalize

ACTION_NAMES = (
    "wrist.pos.x", "wrist.pos.y", "wrist.pos.z",
    "wrist.quat.x", "wrist.quat.y", "wrist.quat.z", "wrist.quat.w",
    "jaw.gap",
)
ACTION_DIM = ABSOLUTE_ACTION.size
FEEDBACK_NAMES = AGENT_POS.field("tip_normal_force").components
#: Widest jaw gap (m) an action may ask for: the layout's (the 2F-85's 85 mm stroke).
MAX_GAP_M = float(JAW_GAP_MAX)
#: the leading entries of ``agent_pos`` that a teleop device reads: wrist pose and jaw gap
_AGENT_HEAD = slice(0, AGENT_POS.slice("jaw_gap").stop)
#: bound on any position coordinate accepted from an observation (m)
MAX_POSITION_M = 100.0


def make_action(position, quat_xyzw, gap_m: float) -> np.ndarray:
    """float32 [8] absolute action from a position [3] m, a quaternion (x, y, z, w), a gap m."""
    p = check_array("position", position, (3,), lo=-MAX_POSITION_M, hi=MAX_POSITION_M, unit="m")
    q = quat_normalize(check_array("quat_xyzw", quat_xyzw, (4,)))
    g = check_number("gap_m", gap_m, 0.0, MAX_GAP_M, unit="m")
    return ABSOLUTE_ACTION.pack(position=p, orientation=q, gap=[g]).astype(np.float32)


def action_to_dict(action) -> dict[str, float]:
    """LeRobot-style flat dict of an [8] action."""
    a = check_array("action", action, (ACTION_DIM,))
    return {k: float(v) for k, v in zip(ACTION_NAMES, a)}


def parse_agent_state(obs) -> tuple[np.ndarray, np.ndarray, float]:
    """(wrist position [3] m, quaternion (x, y, z, w), jaw gap m) from an observation dict with
    ``agent_pos`` (or the ``agent_pos`` array itself), in the layout ``defgrasp_env.layout.AGENT_POS``;
    only its leading wrist pose and jaw gap are read."""
    if isinstance(obs, dict):
        if "agent_pos" not in obs:
            raise ValueError(f"observation must have an 'agent_pos' entry, got keys {sorted(obs)}")
        obs = obs["agent_pos"]
    a = np.asarray(obs, dtype=np.float64).ravel()
    n = _AGENT_HEAD.stop
    if a.size < n:
        raise ValueError(f"agent_pos must have at least {n} entries ({', '.join(AGENT_POS.names[:n])}), got {a.size}")
    head = check_array(f"agent_pos[:{n}]", a[:n], (n,))
    q = head[AGENT_POS.slice("wrist_quat")]
    if abs(np.linalg.norm(q) - 1.0) > 1e-3:
        raise ValueError(f"agent_pos wrist_quat must be a unit quaternion (x, y, z, w), got {q.tolist()}")
    gap = float(np.clip(head[AGENT_POS.slice("jaw_gap")][0], 0.0, MAX_GAP_M))
    return head[AGENT_POS.slice("wrist_position")].copy(), quat_normalize(q), gap


class TeleopDevice(abc.ABC):
    """A source of absolute actions driven by a human (see module docstring)."""

    @property
    def action_features(self) -> dict[str, type]:
        return {k: float for k in ACTION_NAMES}

    @property
    def feedback_features(self) -> dict[str, type]:
        return {k: float for k in FEEDBACK_NAMES}

    @property
    @abc.abstractmethod
    def is_connected(self) -> bool: ...

    @abc.abstractmethod
    def connect(self, calibrate: bool = True) -> None: ...

    @abc.abstractmethod
    def disconnect(self) -> None: ...

    @property
    def is_calibrated(self) -> bool:
        return True

    def calibrate(self) -> None:
        """Nothing to calibrate by default."""

    def configure(self) -> None:
        """Nothing to configure by default."""

    @abc.abstractmethod
    def act(self, obs) -> np.ndarray:
        """float32 [8] absolute action for the observation ``obs`` (see module docstring)."""

    @abc.abstractmethod
    def reset(self) -> None:
        """Start a new episode: the next ``act`` starts from the observed gripper state."""

    def get_action(self) -> dict[str, float]:
        """The last action of ``act`` as a LeRobot flat dict (``act`` needs the observation)."""
        if not self.is_connected:
            raise RuntimeError(f"{type(self).__name__}.get_action() needs connect() first")
        last = getattr(self, "last_action", None)
        if last is None:
            raise RuntimeError(f"{type(self).__name__}.get_action(): no action yet, call act(obs) first")
        return action_to_dict(last)

    def send_feedback(self, feedback: dict[str, Any]) -> None:
        """Receive the env's info dict (``left_tip_normal_force``, ``right_tip_normal_force`` N).
        Devices without haptics ignore it."""

    def __enter__(self):
        self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.disconnect()
