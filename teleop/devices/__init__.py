"""Teleoperation devices: interfaces, drivers, UDP protocol, replay and recording.

Optional hardware packages (``openvr``, ``pyspacemouse``) are imported only on ``connect()``.
"""

from .base import FINGERS, GloveSample, HapticGlove, PoseTracker, TrackerSample
from .keyboard import DEFAULT_KEY_BINDINGS, KeyboardTeleop, key_velocity
from .openvr_tracker import OpenVRTracker, openvr_matrix_to_pose
from .recorder import RecordingGlove, RecordingTracker, StreamRecorder, load_stream
from .replay import ReplayGlove, ReplayTracker
from .spacemouse import SpaceMouseTeleop, spacemouse_velocity
from .udp_glove import DEFAULT_GLOVE_PORT, HapticsCommand, UdpGloveReceiver, UdpGloveSender
from .udp_tracker import DEFAULT_TRACKER_PORT, UdpTrackerReceiver, UdpTrackerSender
from .velocity import VelocityTeleop, VelocityTeleopConfig
from .wire import ProtocolError

__all__ = [
    "DEFAULT_GLOVE_PORT", "DEFAULT_KEY_BINDINGS", "DEFAULT_TRACKER_PORT", "FINGERS", "GloveSample",
    "HapticGlove", "HapticsCommand", "KeyboardTeleop", "OpenVRTracker", "PoseTracker", "ProtocolError",
    "RecordingGlove", "RecordingTracker", "ReplayGlove", "ReplayTracker", "SpaceMouseTeleop",
    "StreamRecorder", "TrackerSample", "UdpGloveReceiver", "UdpGloveSender", "UdpTrackerReceiver",
    "UdpTrackerSender", "VelocityTeleop", "VelocityTeleopConfig", "key_velocity", "load_stream",
    "openvr_matrix_to_pose", "spacemouse_velocity",
]
