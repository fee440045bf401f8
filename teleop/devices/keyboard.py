"""Keyboard teleoperation without a glove: a pure key -> velocity map and ``KeyboardTeleop``.

The key source is anything that returns the set of keys held down now (a pynput listener, a pygame
loop, a GUI, a test); key names are lower-case strings. Default bindings (world frame, y up,
-z forward as in OpenVR):

    w / s   forward (-z) / back (+z)        a / d   left (-x) / right (+x)
    r / f   up (+y) / down (-y)             q / e   open / close the jaw
    i / k   pitch -/+ (about x)             j / l   yaw +/- (about y)
    u / o   roll +/- (about z)

Opposite keys cancel; unknown keys are ignored.
"""

from __future__ import annotations

from typing import Callable, Iterable, Mapping

import numpy as np

from .velocity import VelocityTeleop, VelocityTeleopConfig

#: key -> (kind, axis, sign); kind "lin" (m/s along a world axis), "ang" (rad/s about it), "gap"
DEFAULT_KEY_BINDINGS: Mapping[str, tuple[str, int, int]] = {
    "w": ("lin", 2, -1), "s": ("lin", 2, +1),
    "a": ("lin", 0, -1), "d": ("lin", 0, +1),
    "r": ("lin", 1, +1), "f": ("lin", 1, -1),
    "i": ("ang", 0, -1), "k": ("ang", 0, +1),
    "j": ("ang", 1, +1), "l": ("ang", 1, -1),
    "u": ("ang", 2, +1), "o": ("ang", 2, -1),
    "q": ("gap", 0, +1), "e": ("gap", 0, -1),
}


def _check_bindings(bindings: Mapping[str, tuple[str, int, int]]) -> None:
    for key, b in bindings.items():
        if not isinstance(key, str) or not key:
            raise ValueError(f"key binding names must be non-empty strings, got {key!r}")
        ok = isinstance(b, tuple) and len(b) == 3 and b[0] in ("lin", "ang", "gap") and b[1] in (0, 1, 2) and b[2] in (-1, 1)
        if not ok:
            raise ValueError(f"binding for {key!r} must be (kind in lin/ang/gap, axis in 0..2, sign in -1/+1), got {b!r}")


def key_velocity(
    keys: Iterable[str],
    *,
    linear_speed_m_s: float,
    angular_speed_rad_s: float,
    gap_speed_m_s: float,
    bindings: Mapping[str, tuple[str, int, int]] = DEFAULT_KEY_BINDINGS,
) -> tuple[np.ndarray, np.ndarray, float]:
    """(linear velocity [3] m/s, angular velocity [3] rad/s, gap rate m/s) for the held ``keys``."""
    if isinstance(keys, str):
        raise TypeError(f"keys must be a collection of key names, got the string {keys!r}")
    lin, ang, gap = np.zeros(3), np.zeros(3), 0.0
    for key in set(keys):
        if not isinstance(key, str):
            raise TypeError(f"key names must be strings, got {key!r}")
        b = bindings.get(key.lower())
        if b is None:
            continue
        kind, axis, sign = b
        if kind == "lin":
            lin[axis] += sign
        elif kind == "ang":
            ang[axis] += sign
        else:
            gap += sign
    return lin * linear_speed_m_s, ang * angular_speed_rad_s, gap * gap_speed_m_s


class KeyboardTeleop(VelocityTeleop):
    """TeleopDevice driven by held keys. ``key_source()`` returns the keys held down now."""

    def __init__(
        self,
        key_source: Callable[[], Iterable[str]],
        config: VelocityTeleopConfig | None = None,
        bindings: Mapping[str, tuple[str, int, int]] = DEFAULT_KEY_BINDINGS,
    ):
        if not callable(key_source):
            raise TypeError(f"key_source must be a callable returning the held keys, got {key_source!r}")
        _check_bindings(bindings)
        super().__init__(config)
        self._key_source = key_source
        self.bindings = dict(bindings)
        self._connected = False

    @property
    def is_connected(self) -> bool:
        return self._connected

    def connect(self, calibrate: bool = True) -> None:
        self._connected = True

    def disconnect(self) -> None:
        self._connected = False

    def read_velocity(self):
        c = self.config
        return key_velocity(
            self._key_source(), linear_speed_m_s=c.linear_speed_m_s, angular_speed_rad_s=c.angular_speed_rad_s,
            gap_speed_m_s=c.gap_speed_m_s, bindings=self.bindings,
        )
