"""Replay a recorded episode file in the 3D viewer with a timeline (``defgrasp-dataset view EPISODE``).

The GUI has a ``step`` slider (the timeline), a ``play`` checkbox and a ``speed`` factor; playing
advances the slider at the episode's control rate times the speed and loops at the end. The stress
colours use the episode's whole range (0 to its largest node stress), so every step reads off the
same scale bar.
"""

from __future__ import annotations

import threading

from .colormap import StressScale
from .frame import EpisodeFrames
from .server import DEFAULT_HOST, DEFAULT_PORT, ViewerServer


class EpisodePlayer:
    """An episode file in a ``ViewerServer`` with a timeline (module doc)."""

    def __init__(self, path, *, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, port_flag: str = "--port"):
        self.frames = EpisodeFrames(path)
        scale = StressScale()
        scale.observe(self.frames.stress_max)
        a = self.frames.attrs
        self.dt = float(a.get("dt", 0.05))
        self.viewer = ViewerServer(self.frames.triangles, host=host, port=port, title=f"defgrasp: {self.frames.path.name}",
                                   port_flag=port_flag, scale=scale)
        gui = self.viewer.server.gui
        last = self.frames.num_steps - 1
        self.slider = gui.add_slider("step", min=0, max=max(last, 1), step=1, initial_value=0, disabled=last == 0)
        self.playing = gui.add_checkbox("play", initial_value=False)
        self.speed = gui.add_number("speed", initial_value=1.0, min=0.05, max=20.0, step=0.05)
        self._lock = threading.Lock()
        self._summary = {"headline": f"replay: {a.get('object_name', '?')}", "file": self.frames.path.name,
                         "steps": self.frames.num_steps, "success": a.get("is_success"), "end": a.get("end_reason")}
        self.slider.on_update(lambda _event: self.show_step(int(self.slider.value)))
        self.show_step(0)

    @property
    def url(self) -> str:
        return self.viewer.url

    def show_step(self, t: int) -> None:
        """Draw step ``t`` (0-based) of the episode."""
        t = min(max(int(t), 0), self.frames.num_steps - 1)
        f = self.frames.frame(t)
        with self._lock:
            self.viewer.show(f, {**self._summary, "step": f"{t + 1}/{self.frames.num_steps}"})

    def run(self, stop: threading.Event | None = None) -> None:
        """Serve until ``stop`` is set (or Ctrl-C), advancing the timeline while ``play`` is on."""
        stop = stop or threading.Event()
        while not stop.is_set():
            if self.playing.value and self.frames.num_steps > 1:
                nxt = (int(self.slider.value) + 1) % self.frames.num_steps
                self.slider.value = nxt
                self.show_step(nxt)
                stop.wait(self.dt / max(float(self.speed.value), 1e-3))
            else:
                stop.wait(0.05)

    def close(self) -> None:
        self.viewer.close()


def view_episode(path, *, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, say=print) -> None:
    """Serve ``path`` in the viewer until Ctrl-C (prints the URL)."""
    player = EpisodePlayer(path, host=host, port=port)
    say(f"viewing {player.frames.path} ({player.frames.num_steps} steps) at {player.url}  (Ctrl-C to stop)")
    try:
        player.run()
    except KeyboardInterrupt:
        pass
    finally:
        player.close()
