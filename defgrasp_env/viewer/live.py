"""Live 3D view of a running simulation: ``render_mode="human"`` of the envs and the teleop app.

``LiveSceneViewer.show(scene, world, ...)`` draws world ``world`` of a ``PickupScene`` (through its
public readouts, ``frame_from_scene``); the web server starts at the first call (the URL is printed
through ``say``) and follows a change of object (a new surface). Drawing one frame costs a few
milliseconds on the CPU (numpy + queueing websocket messages); the browser renders on its own.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from .frame import ViewerFrame, frame_from_scene
from .server import DEFAULT_HOST, DEFAULT_PORT, ViewerServer


class LiveSceneViewer:
    """A ``ViewerServer`` fed from a live scene (module doc).

    host/port: where to serve (port 0: any free port); port_flag: the option named when the port is
    taken; say: where the URL is announced (None: not announced); title: the page label.
    """

    def __init__(self, *, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, port_flag: str = "viewer_port",
                 say: Callable[[str], None] | None = print, title: str = "defgrasp"):
        self.host, self.port, self.port_flag, self.title = host, port, port_flag, title
        self._say = say
        self.viewer: ViewerServer | None = None
        self._surface_key = None

    def open(self) -> ViewerServer:
        """Start the server now (``show`` does it on its first call)."""
        if self.viewer is None:
            self.viewer = ViewerServer(None, host=self.host, port=self.port, title=self.title,
                                       port_flag=self.port_flag)
            if self._say is not None:
                self._say(f"3D viewer: {self.viewer.url}")
        return self.viewer

    @property
    def url(self) -> str | None:
        return None if self.viewer is None else self.viewer.url

    def capture(self, scene, world: int = 0, goal=(0.0, 0.6, 0.0), time_s: float = 0.0) -> tuple[ViewerFrame, np.ndarray]:
        """(frame, surface triangles) of a scene's world, to ``show_frame`` now or later."""
        return frame_from_scene(scene, world, goal, time_s), scene.mesh(world).surface

    def show_frame(self, frame: ViewerFrame, triangles: np.ndarray, readouts: dict | None = None) -> None:
        viewer = self.open()
        key = (id(triangles), len(triangles))
        if key != self._surface_key:
            viewer.drawing.set_surface(triangles)
        self._surface_key = key
        viewer.show(frame, readouts)

    def show(self, scene, world: int = 0, goal=(0.0, 0.6, 0.0), readouts: dict | None = None,
             time_s: float = 0.0) -> None:
        """Draw world ``world`` of ``scene`` now."""
        self.show_frame(*self.capture(scene, world, goal, time_s), readouts)

    def set_status(self, readouts: dict) -> None:
        if self.viewer is not None:
            self.viewer.set_status(readouts)

    def new_episode(self) -> None:
        """Restart the stress range (colours comparable within one episode)."""
        if self.viewer is not None:
            self.viewer.reset_scale()

    def close(self) -> None:
        if self.viewer is not None:
            self.viewer.close()
            self.viewer = None
            self._surface_key = None
