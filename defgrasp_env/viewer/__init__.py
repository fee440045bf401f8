"""3D viewer in the browser (viser: a three.js scene served from Python; ``pip install 'defgrasp[viewer]'``).

* ``frame``: ``ViewerFrame`` (what is drawn), from a live scene (``frame_from_scene``) or an episode
  file (``EpisodeFrames``); per-node von Mises stress from per-tet values (``node_stress``);
* ``colormap``: banded stress colours and the scale bar (``StressScale``);
* ``draw``: ``SceneDrawing``, the viser scene nodes (object, pads, wrist frame, goal, tip-force
  arrows, feature point); ``server``: ``ViewerServer`` (bind address, port check, status panel);
* ``live``: ``LiveSceneViewer`` for ``render_mode="human"`` and the teleop app;
* ``playback``: ``EpisodePlayer`` / ``view_episode`` (``defgrasp-dataset view EPISODE.h5``).

Importing this package does not import viser; building a server does (ImportError naming the extra).
"""

from .colormap import StressScale
from .frame import EpisodeFrames, ViewerFrame, frame_from_scene, node_stress, pad_boxes_world
from .live import LiveSceneViewer
from .server import DEFAULT_HOST, DEFAULT_PORT, ViewerServer, check_port_free

__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "EpisodeFrames", "LiveSceneViewer", "StressScale", "ViewerFrame",
           "ViewerServer", "check_port_free", "frame_from_scene", "node_stress", "pad_boxes_world"]
