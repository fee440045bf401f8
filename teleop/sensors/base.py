"""Device interfaces: a 6-DOF pose tracker and a haptic glove, with their immutable samples.

Clock: every ``timestamp_s`` in this package is on the host's ``time.monotonic()`` clock (s) unless
a driver documents otherwise: for a network stream it is the time the datagram was received, for a
polled driver the time it was polled. Latencies (``HumanTeleopAgent.latency_s``) are differences on
that clock, so drivers and the agent must share it (all default to ``time.monotonic``).

Finger arrays are finger-major, thumb..pinky (``FINGERS``); joint angles are proximal -> distal.
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass

import numpy as np

from .._validate import check_array, check_number, readonly
from ..se3 import check_rigid

FINGERS = ("thumb", "index", "middle", "ring", "pinky")
N_FINGERS = 5
JOINTS_PER_FINGER = 4
#: bound on a glove joint angle (rad): anything beyond one turn is corrupt data
MAX_JOINT_ANGLE_RAD = 2.0 * math.pi
#: bound on a fingertip coordinate in the glove frame (m)
MAX_FINGERTIP_M = 1.0
#: longest vibration burst accepted by ``send_haptics`` (s)
MAX_VIBRATION_S = 10.0


@dataclass(frozen=True)
class TrackerSample:
    """One pose-tracker reading.

    pose: float64 [4, 4], the tracker's pose in the tracker system's own frame (OpenVR standing
        universe: right-handed, +y up, +x right, -z forward, metres). When ``valid`` is False it is
        the last valid pose (or identity if none) and must not be used to drive the robot.
    valid: the pose is tracked now (device connected, tracking OK, data fresh).
    timestamp_s: host monotonic time of the reading (s).
    """

    pose: np.ndarray
    valid: bool
    timestamp_s: float

    def __post_init__(self):
        object.__setattr__(self, "pose", readonly(check_rigid("TrackerSample.pose", self.pose)))
        if not isinstance(self.valid, (bool, np.bool_)):
            raise TypeError(f"TrackerSample.valid must be a bool, got {self.valid!r}")
        object.__setattr__(self, "valid", bool(self.valid))
        object.__setattr__(self, "timestamp_s", check_number("TrackerSample.timestamp_s", self.timestamp_s))


@dataclass(frozen=True)
class GloveSample:
    """One haptic-glove reading.

    joint_angles: float64 [5, 4] rad, per finger thumb..pinky, 4 joints proximal -> distal
        (SenseGlove DK1 sensor angles).
    fingertip_positions: float64 [5, 3] m, fingertips in the glove frame (+X toward the fingers,
        +Y pinky -> thumb on a right hand, +Z up from the palm), as computed by the glove SDK.
    connected: the glove is connected and the data is fresh. When False the arrays hold the last
        received values (zeros if none) and must not drive the robot.
    timestamp_s: host monotonic time of the reading (s).
    """

    joint_angles: np.ndarray
    fingertip_positions: np.ndarray
    connected: bool
    timestamp_s: float

    def __post_init__(self):
        a = check_array(
            "GloveSample.joint_angles", self.joint_angles, (N_FINGERS, JOINTS_PER_FINGER),
            lo=-MAX_JOINT_ANGLE_RAD, hi=MAX_JOINT_ANGLE_RAD, unit="rad",
        )
        p = check_array(
            "GloveSample.fingertip_positions", self.fingertip_positions, (N_FINGERS, 3),
            lo=-MAX_FINGERTIP_M, hi=MAX_FINGERTIP_M, unit="m",
        )
        if not isinstance(self.connected, (bool, np.bool_)):
            raise TypeError(f"GloveSample.connected must be a bool, got {self.connected!r}")
        object.__setattr__(self, "joint_angles", readonly(a))
        object.__setattr__(self, "fingertip_positions", readonly(p))
        object.__setattr__(self, "connected", bool(self.connected))
        object.__setattr__(self, "timestamp_s", check_number("GloveSample.timestamp_s", self.timestamp_s))


def check_haptics(force_feedback, vibration, vibration_duration_s) -> tuple[np.ndarray, np.ndarray, float]:
    """Validate a haptics command: two [5] arrays in 0..1 and a duration in [0, MAX_VIBRATION_S] s."""
    ff = check_array("force_feedback", force_feedback, (N_FINGERS,), lo=0.0, hi=1.0)
    vib = check_array("vibration", vibration, (N_FINGERS,), lo=0.0, hi=1.0)
    dur = check_number("vibration_duration_s", vibration_duration_s, 0.0, MAX_VIBRATION_S, unit="s")
    return ff, vib, dur


class _Device(abc.ABC):
    """Lifecycle shared by devices: connect/disconnect, ``is_connected``, context manager."""

    @abc.abstractmethod
    def connect(self) -> None:
        """Open the device (idempotent)."""

    @abc.abstractmethod
    def disconnect(self) -> None:
        """Release the device (idempotent)."""

    @property
    @abc.abstractmethod
    def is_connected(self) -> bool:
        """The driver is open. Whether data is live is each sample's ``valid``/``connected``."""

    def __enter__(self):
        self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.disconnect()


class PoseTracker(_Device):
    """A 6-DOF pose tracker (HTC VIVE tracker, a bridged pose stream, a replay)."""

    @abc.abstractmethod
    def read(self) -> TrackerSample:
        """Latest sample; never blocks. Raises RuntimeError if not connected."""


class HapticGlove(_Device):
    """A haptic glove with per-finger force feedback and vibration (SenseGlove DK1 and kin)."""

    @abc.abstractmethod
    def read(self) -> GloveSample:
        """Latest sample; never blocks. Raises RuntimeError if not connected."""

    @abc.abstractmethod
    def send_haptics(self, force_feedback, vibration, vibration_duration_s: float) -> bool:
        """Command the glove: force_feedback [5] and vibration [5] levels in 0..1 (thumb..pinky),
        vibration_duration_s in [0, 10] s. Commands latch until replaced (DK1 semantics). Returns
        True if the command was sent, False if there was no live glove to send it to. Invalid
        arguments raise ValueError/TypeError."""


def require_connected(device: _Device, what: str) -> None:
    """Raise RuntimeError naming the device if it is not connected."""
    if not device.is_connected:
        raise RuntimeError(f"{type(device).__name__}.{what}() needs connect() first")
