"""Live views of a collection session.

``SceneView3D`` (the default, ``--view 3d``): the 3D browser viewer of ``defgrasp_env.viewer``
(viser; the ``[viewer]`` extra): the deforming object coloured by stress, pads, wrist frame, goal,
tip-force arrows, and a status panel with the readouts (episode status, forces, gap, stress, success,
device state, and during review the result of the episode just finished, whose last frame stays on
screen). ``LiveView`` (``--view 2d`` and ``--view-png``) is the camera image and a readout table, with
no extra dependency (below).

Both have ``capture(env)`` (what to show of the env now), ``update(frame, readouts)``,
``new_episode()`` and ``close()``; the session calls only these.

``LiveView.update(frame, readouts)`` keeps the newest camera frame (``env.render()``, uint8
[H, W, 3]) and a dict of readouts (tip forces, jaw gap, mean stress, ...). Two optional sinks:

* a PNG file replaced atomically (temp file + ``os.replace``) at every update, for an image viewer
  that reloads it (``--view-png``);
* a small HTTP page (``http.server`` in a daemon thread, ``--view-port``): ``/`` shows the image
  and a readout table refreshed by a few lines of JavaScript, ``/frame.png`` the newest frame,
  ``/state.json`` the readouts. It binds 127.0.0.1 by default: a control room on another machine
  needs ``--view-host 0.0.0.0`` (there is no authentication).
"""

from __future__ import annotations

import http.server
import json
import logging
import math
import os
import pathlib
import threading

import numpy as np

from defgrasp_env.render.image_io import png_bytes as encode_png

log = logging.getLogger("teleop.app")


def png_bytes(image: np.ndarray, level: int = 1) -> bytes:
    """Encode an RGB uint8 [H, W, 3] image as PNG, fast (zlib ``level`` 1) for the live view."""
    return encode_png(image, level)


def _json_safe(v):
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, dict):
        return {str(k): _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_json_safe(x) for x in v]
    return None if v is None else str(v)


PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>defgrasp teleop</title>
<style>body{font-family:sans-serif;background:#222;color:#eee;margin:1em}
img{image-rendering:pixelated;width:448px;border:1px solid #555}
td{padding:2px 10px}td:first-child{color:#aaa}.row{display:flex;gap:2em}</style></head>
<body><h3>defgrasp teleop - live view</h3><div class="row"><img id="f" src="frame.png">
<table id="t"></table></div>
<p>Keys (in the app's terminal): &rarr; end episode, &larr; discard + re-record, s mark success, Esc stop.</p>
<script>
let last=-1;
async function tick(){
 try{const r=await fetch('state.json',{cache:'no-store'});const s=await r.json();
  const t=document.getElementById('t');t.innerHTML='';
  for(const [k,v] of Object.entries(s.readouts)){const row=t.insertRow();row.insertCell().textContent=k;
   row.insertCell().textContent=(typeof v==='number')?(Math.abs(v)>=1e4||(v!==0&&Math.abs(v)<1e-2)?v.toExponential(2):v.toFixed(3)):v;}
  if(s.frame!==last&&s.frame>=0){last=s.frame;document.getElementById('f').src='frame.png?n='+s.frame;}
 }catch(e){}
 setTimeout(tick,200);}
tick();
</script></body></html>
"""


class LiveView:
    """Newest frame + readouts, published to a PNG file and/or an HTTP page (module doc).

    png_path: file to keep replaced with the newest frame (None: no file).
    http_address: (host, port) to serve on (port 0 picks a free one; None: no server).
    port_flag: the option named when the port is taken.
    """

    def __init__(self, png_path=None, http_address: tuple[str, int] | None = None, port_flag: str = "--view-port"):
        self.port_flag = port_flag
        self.png_path = pathlib.Path(png_path) if png_path is not None else None
        self._lock = threading.Lock()
        self._frame: np.ndarray | None = None
        self._frame_id = -1
        self._png_cache: tuple[int, bytes] | None = None
        self._readouts: dict = {}
        self._server: http.server.ThreadingHTTPServer | None = None
        self._thread: threading.Thread | None = None
        if http_address is not None:
            self._start_server(http_address)

    # publishing --------------------------------------------------------------------------------------
    @staticmethod
    def capture(env) -> np.ndarray | None:
        """The env's camera image (``render_mode="rgb_array"``), else None."""
        return env.render() if env.render_mode == "rgb_array" else None

    def new_episode(self) -> None:
        """Nothing to restart (the image has no colour scale)."""

    def update(self, frame: np.ndarray | None, readouts: dict) -> None:
        """Publish a new frame (None keeps the previous one) and the readouts."""
        if not isinstance(readouts, dict):
            raise TypeError(f"readouts must be a dict, got {type(readouts).__name__}")
        with self._lock:
            if frame is not None:
                self._frame = np.array(frame, dtype=np.uint8, copy=True)
                self._frame_id += 1
            self._readouts = _json_safe(readouts)
            frame_now = self._frame if frame is not None else None
        if frame_now is not None and self.png_path is not None:
            self._write_png(frame_now)

    def _write_png(self, frame: np.ndarray) -> None:
        tmp = self.png_path.with_name(f".{self.png_path.name}.tmp-{os.getpid()}")
        try:
            self.png_path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_bytes(png_bytes(frame))
            os.replace(tmp, self.png_path)
        except OSError as exc:
            log.warning("live view: cannot write %s: %s", self.png_path, exc)
            tmp.unlink(missing_ok=True)

    def state(self) -> dict:
        """{"frame": frame counter (-1 before the first), "readouts": {...}} (JSON-safe)."""
        with self._lock:
            return {"frame": self._frame_id, "readouts": dict(self._readouts)}

    def frame_png(self) -> bytes | None:
        """The newest frame as PNG bytes (encoded once per frame), or None before the first."""
        with self._lock:
            if self._frame is None:
                return None
            if self._png_cache is None or self._png_cache[0] != self._frame_id:
                self._png_cache = (self._frame_id, png_bytes(self._frame))
            return self._png_cache[1]

    # HTTP --------------------------------------------------------------------------------------------
    @property
    def url(self) -> str | None:
        if self._server is None:
            return None
        host, port = self._server.server_address[:2]
        return f"http://{host}:{port}/"

    def _start_server(self, address: tuple[str, int]) -> None:
        view = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self):  # noqa: N802 (http.server API)
                path = self.path.split("?", 1)[0]
                if path in ("/", "/index.html"):
                    self._send(200, "text/html; charset=utf-8", PAGE.encode())
                elif path == "/state.json":
                    self._send(200, "application/json", json.dumps(view.state()).encode())
                elif path == "/frame.png":
                    data = view.frame_png()
                    if data is None:
                        self._send(404, "text/plain", b"no frame yet")
                    else:
                        self._send(200, "image/png", data)
                else:
                    self._send(404, "text/plain", b"not found")

            def _send(self, code: int, ctype: str, body: bytes) -> None:
                self.send_response(code)
                self.send_header("Content-Type", ctype)
                self.send_header("Content-Length", str(len(body)))
                self.send_header("Cache-Control", "no-store")
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, format, *args):  # quiet: the terminal shows the status line
                pass

        host, port = address
        try:
            self._server = http.server.ThreadingHTTPServer((host, int(port)), Handler)
        except OSError as exc:
            raise OSError(exc.errno, f"live view port {port} on {host} cannot be used ({exc.strerror}); "
                                     f"choose another with {self.port_flag} (0 picks a free one)") from None
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever, kwargs={"poll_interval": 0.2},
                                        name="teleop-view", daemon=True)
        self._thread.start()

    def close(self) -> None:
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class SceneView3D:
    """The 3D browser view of the session's env (module doc): ``defgrasp_env.viewer.LiveSceneViewer``
    on ``(host, port)``; the port is checked at construction (``OSError`` naming it and ``port_flag``)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, port_flag: str = "--view-port"):
        from defgrasp_env.viewer import LiveSceneViewer

        self._viewer = LiveSceneViewer(host=host, port=port, port_flag=port_flag, say=None, title="defgrasp teleop")
        self._viewer.open()

    @property
    def url(self) -> str | None:
        return self._viewer.url

    def capture(self, env):
        """(frame, surface) of world 0 of the env's scene now, or None before the first reset."""
        inner = env.unwrapped
        if inner.scene is None:
            return None
        return self._viewer.capture(inner.scene, 0, inner.task.goal(0),
                                    time_s=float(inner.task.elapsed[0]) * inner.config.dt)

    def new_episode(self) -> None:
        self._viewer.new_episode()

    def update(self, frame, readouts: dict) -> None:
        """Draw a captured frame (None keeps the one on screen) and show the readouts."""
        if not isinstance(readouts, dict):
            raise TypeError(f"readouts must be a dict, got {type(readouts).__name__}")
        if frame is None:
            self._viewer.set_status(readouts)
        else:
            self._viewer.show_frame(*frame, readouts)

    def close(self) -> None:
        self._viewer.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
