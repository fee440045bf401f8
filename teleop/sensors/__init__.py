"""Sensors: readers of the operator's hardware and of recorded streams. They report samples
(tracker poses, glove joints and fingertips, SpaceMouse axes) and take haptic commands; they never
produce teleop actions (that is ``teleop.devices`` and ``HumanTeleopAgent``, which use them).

* ``base``: ``PoseTracker`` / ``HapticGlove`` interfaces, ``TrackerSample`` / ``GloveSample``;
* ``udp_glove``, ``udp_tracker`` (+ ``udp_common``, ``wire``): the UDP protocol
  (``GLOVE_PROTOCOL.md``), receivers and reference senders;
* ``openvr_tracker``: SteamVR trackers; ``spacemouse``: a 3Dconnexion SpaceMouse;
* ``recorder``: record a live stream to ``.jsonl``/``.npz``; ``replay``: play one back.

Optional hardware packages (``openvr``, ``pyspacemouse``) are imported only on ``connect()``.
"""

from .base import FINGERS, GloveSample, HapticGlove, PoseTracker, TrackerSample
from .openvr_tracker import OpenVRTracker, openvr_matrix_to_pose
from .recorder import RecordingGlove, RecordingTracker, StreamRecorder, load_stream
from .replay import ReplayGlove, ReplayTracker
from .spacemouse import SpaceMouse
from .udp_glove import DEFAULT_GLOVE_PORT, HapticsCommand, UdpGloveReceiver, UdpGloveSender
from .udp_tracker import DEFAULT_TRACKER_PORT, UdpTrackerReceiver, UdpTrackerSender
from .wire import ProtocolError

__all__ = [
    "DEFAULT_GLOVE_PORT", "DEFAULT_TRACKER_PORT", "FINGERS", "GloveSample", "HapticGlove", "HapticsCommand",
    "OpenVRTracker", "PoseTracker", "ProtocolError", "RecordingGlove", "RecordingTracker", "ReplayGlove",
    "ReplayTracker", "SpaceMouse", "StreamRecorder", "TrackerSample", "UdpGloveReceiver", "UdpGloveSender",
    "UdpTrackerReceiver", "UdpTrackerSender", "load_stream", "openvr_matrix_to_pose",
]
