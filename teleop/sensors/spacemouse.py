"""3Dconnexion SpaceMouse reader (optional ``pyspacemouse``, imported on ``connect()``).

A sensor only: :meth:`SpaceMouse.read` returns pyspacemouse's raw state (x, y, z, roll, pitch, yaw
in [-1, 1] and ``buttons``). ``teleop.devices.SpaceMouseTeleop`` turns it into teleop commands.
"""

from __future__ import annotations

import importlib
from typing import Any

INSTALL_HINT = "pip install pyspacemouse (and the hidapi system library)"


class SpaceMouse:
    """One SpaceMouse. device: pyspacemouse device name or None (the first one found)."""

    def __init__(self, device: str | None = None):
        if device is not None and not isinstance(device, str):
            raise TypeError(f"device must be a pyspacemouse device name (str) or None, got {device!r}")
        self.device = device
        self._mouse = None

    @property
    def is_connected(self) -> bool:
        return self._mouse is not None

    def connect(self) -> None:
        if self._mouse is not None:
            return
        try:
            sm = importlib.import_module("pyspacemouse")
        except ImportError as exc:
            raise ImportError(f"SpaceMouse needs the optional 'pyspacemouse' package: {INSTALL_HINT}") from exc
        mouse = sm.open(device=self.device) if self.device else sm.open()
        if not mouse:
            raise RuntimeError(f"pyspacemouse could not open a SpaceMouse (device={self.device!r}); is it plugged in and readable?")
        self._mouse = mouse if hasattr(mouse, "read") else sm

    def disconnect(self) -> None:
        if self._mouse is not None:
            self._mouse.close()
            self._mouse = None

    def read(self) -> Any:
        """The current raw state (attributes x, y, z, roll, pitch, yaw, buttons)."""
        if self._mouse is None:
            raise RuntimeError("SpaceMouse.read() needs connect() first")
        return self._mouse.read()
