"""The 3D viewer's web server: a ``viser.ViserServer`` (three.js in the browser, served from Python,
no display and no extra binary) with a scene (``SceneDrawing``), a status panel and a scale bar.

Open the printed URL in a browser. On a remote machine, forward the port over SSH
(``ssh -L 8080:127.0.0.1:8080 host``) and open ``http://127.0.0.1:8080`` locally; the server binds
127.0.0.1 by default (``host="0.0.0.0"`` serves every interface, without authentication).
"""

from __future__ import annotations

import errno
import math
import socket

import numpy as np

from .colormap import StressScale
from .draw import SceneDrawing
from .frame import ViewerFrame

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8080
#: Where the browser's camera starts (m, world frame; vertical field of view in rad): the whole task,
#: the object on the ground to the goal at 0.6 m; orbit (drag), zoom (wheel) and pan (right drag)
#: from there to look closer.
INITIAL_CAMERA_POSITION = (0.48, 0.68, 0.82)
INITIAL_CAMERA_LOOK_AT = (0.0, 0.34, 0.0)
INITIAL_CAMERA_FOV = float(np.radians(45.0))


def _viser():
    try:
        import viser
    except ImportError as exc:
        raise ImportError("the 3D viewer needs viser: pip install 'defgrasp[viewer]'") from exc
    return viser


def check_port_free(host: str, port: int, flag: str = "port") -> None:
    """Raise ``OSError`` naming ``port`` and the option ``flag`` that changes it when ``host:port``
    cannot be bound (viser would silently move to the next port, and the URL the user forwarded over
    SSH would show nothing). Port 0 (any free port) always passes."""
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise ValueError(f"{flag} must be an int in [0, 65535], got {port!r}")
    if port == 0:
        return
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError as exc:
            why = "is already in use" if exc.errno == errno.EADDRINUSE else f"cannot be bound ({exc.strerror})"
            raise OSError(exc.errno, f"viewer port {port} on {host} {why}; choose another with {flag} "
                                     f"(0 picks a free one)") from None


def _fmt(value) -> str:
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if not math.isfinite(v):
            return "-"
        return f"{v:.3g}" if abs(v) >= 1e4 or (v != 0 and abs(v) < 1e-2) else f"{v:.3f}"
    return "-" if value is None else str(value)


def frame_readouts(frame: ViewerFrame) -> dict:
    """The status-panel values every frame has: time, tip forces, peak stress, feature height."""
    return {"time_s": frame.time_s, "left_tip_force_N": float(frame.tip_forces[0]),
            "right_tip_force_N": float(frame.tip_forces[1]),
            "max_von_mises_kPa": float(np.max(frame.node_stress)) / 1e3,
            "feature_height_m": float(frame.feature_point[1])}


class ViewerServer:
    """A running 3D viewer of one object (its surface ``triangles`` [M, 3]; None: set it later
    through ``drawing.set_surface``).

    host/port: bind address (port 0: any free port); ``port_flag`` names the option that sets the
    port in the error raised when it is taken. ``url`` is where to point the browser.
    ``show(frame, readouts)`` draws a ``ViewerFrame`` and fills the status panel with ``readouts``
    (name -> value); ``close()`` stops the server.
    """

    def __init__(self, triangles: np.ndarray | None = None, *, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 title: str = "defgrasp", port_flag: str = "port", scale: StressScale | None = None):
        viser = _viser()
        check_port_free(host, port, port_flag)
        self._server = viser.ViserServer(host=host, port=port, label=title, verbose=False)
        self.host = host
        try:
            cam = self._server.initial_camera
            cam.position = INITIAL_CAMERA_POSITION
            cam.look_at = INITIAL_CAMERA_LOOK_AT
            cam.up = (0.0, 1.0, 0.0)
            cam.fov = INITIAL_CAMERA_FOV
            self.drawing = SceneDrawing(self._server, triangles, scale)
            gui = self._server.gui
            self._scale_bar = gui.add_html(self.drawing.scale.scale_bar_html())
            self._status = gui.add_markdown("waiting for the first frame")
        except BaseException:
            self._server.stop()
            raise
        self._drawn_upper = self.drawing.scale.upper_pa

    @property
    def server(self):
        """The ``viser.ViserServer`` (to add GUI controls)."""
        return self._server

    @property
    def port(self) -> int:
        return int(self._server.get_port())

    @property
    def url(self) -> str:
        host = "127.0.0.1" if self.host in ("0.0.0.0", "") else self.host
        return f"http://{host}:{self.port}/"

    def show(self, frame: ViewerFrame, readouts: dict | None = None) -> None:
        """Draw ``frame``; the status panel shows ``frame_readouts(frame)`` updated by ``readouts``."""
        self.drawing.draw(frame)
        if self.drawing.scale.upper_pa != self._drawn_upper:
            self._drawn_upper = self.drawing.scale.upper_pa
            self._scale_bar.content = self.drawing.scale.scale_bar_html()
        self.set_status({**frame_readouts(frame), **(readouts or {})})

    def set_status(self, readouts: dict) -> None:
        """The status panel: one ``name: value`` line per readout (a ``headline`` key comes first, bold)."""
        lines = [f"**{readouts['headline']}**"] if "headline" in readouts else []
        lines += [f"{k}: `{_fmt(v)}`" for k, v in readouts.items() if k != "headline"]
        self._status.content = "  \n".join(lines)

    def reset_scale(self) -> None:
        """Start the stress range again from its floor (a new episode)."""
        self.drawing.scale.reset()

    def close(self) -> None:
        if self._server is not None:
            self._server.stop()
            self._server = None

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
