"""TeleopDevices without a glove: velocity commands (keyboard, SpaceMouse) integrated into absolute
actions (``act(obs) -> float32[8]``, the ``teleop.teleop_device.TeleopDevice`` contract). Their
inputs are sensors (``teleop.sensors``) or a key source. The glove + tracker TeleopDevice is
``teleop.HumanTeleopAgent``.
"""

from .keyboard import DEFAULT_KEY_BINDINGS, KeyboardTeleop, key_velocity
from .spacemouse import SpaceMouseTeleop, spacemouse_velocity
from .velocity import VelocityTeleop, VelocityTeleopConfig

__all__ = [
    "DEFAULT_KEY_BINDINGS", "KeyboardTeleop", "SpaceMouseTeleop", "VelocityTeleop", "VelocityTeleopConfig",
    "key_velocity", "spacemouse_velocity",
]
