"""defgrasp teleoperation: sensors, TeleopDevices, retargeting (paper eq. 1-4), haptics and ``HumanTeleopAgent``.

    from teleop import HumanTeleopAgent, UdpGloveReceiver, OpenVRTracker
    agent = HumanTeleopAgent(OpenVRTracker(), UdpGloveReceiver())
    agent.connect(); obs, info = env.reset(); agent.reset()
    while running:
        obs, reward, terminated, truncated, info = env.step(agent.act(obs))
        agent.send_feedback(info)
"""

from .agent import HumanTeleopAgent, HumanTeleopConfig
from .devices import KeyboardTeleop, SpaceMouseTeleop
from .sensors import (
    GloveSample, HapticGlove, OpenVRTracker, PoseTracker, ReplayGlove, ReplayTracker, StreamRecorder, TrackerSample,
    UdpGloveReceiver, UdpGloveSender, UdpTrackerReceiver, UdpTrackerSender, load_stream,
)
from .haptics import HapticCommand, HapticsConfig, HapticsMapper, force_to_feedback
from .teleop_device import ACTION_NAMES, TeleopDevice, make_action

__all__ = [
    "ACTION_NAMES", "GloveSample", "HapticCommand", "HapticGlove", "HapticsConfig", "HapticsMapper",
    "HumanTeleopAgent", "HumanTeleopConfig", "KeyboardTeleop", "OpenVRTracker", "PoseTracker",
    "ReplayGlove", "ReplayTracker", "SpaceMouseTeleop", "StreamRecorder", "TeleopDevice", "TrackerSample",
    "UdpGloveReceiver", "UdpGloveSender", "UdpTrackerReceiver", "UdpTrackerSender", "force_to_feedback",
    "load_stream", "make_action",
]
