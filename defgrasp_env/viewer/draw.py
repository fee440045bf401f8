"""Draws ``ViewerFrame``s into a viser scene: the deforming object coloured by stress, the two pads,
the wrist frame, the goal, the tip-force arrows and the feature point.

Scene nodes (viser names): ``/object/band_k`` (one mesh per stress band), ``/pads/left``,
``/pads/right``, ``/wrist``, ``/goal``, ``/feature``, ``/tip_forces``, ``/ground``. viser takes
quaternions (w, x, y, z); frames carry (x, y, z, w) and are converted here.
"""

from __future__ import annotations

import numpy as np

from ..transforms import quat_rotate
from .colormap import StressScale
from .frame import ViewerFrame

#: Arrow length per newton of tip force (m/N) and the longest arrow drawn (m).
FORCE_ARROW_M_PER_N = 0.004
FORCE_ARROW_MAX_M = 0.12
PAD_COLOR = (70, 70, 78)
GOAL_COLOR = (230, 50, 50)
FEATURE_COLOR = (255, 255, 255)
FORCE_COLOR = (255, 140, 0)


def wxyz(quat_xyzw) -> np.ndarray:
    q = np.asarray(quat_xyzw, dtype=np.float64)
    return np.array([q[3], q[0], q[1], q[2]])


def force_arrows(frame: ViewerFrame) -> np.ndarray:
    """[2, 2, 3] start/end points (m) of the tip-force arrows: from each pad's centre along the force
    it puts on the object (left pad, at +x of the gripper frame, pushes along -x; right along +x),
    ``FORCE_ARROW_M_PER_N`` long per newton, at most ``FORCE_ARROW_MAX_M``."""
    x_axis = quat_rotate(np.asarray(frame.flange_quat, dtype=np.float64)[None], np.array([[1.0, 0.0, 0.0]]))[0]
    out = np.zeros((2, 2, 3))
    for i, sign in enumerate((-1.0, 1.0)):
        length = min(max(float(frame.tip_forces[i]), 0.0) * FORCE_ARROW_M_PER_N, FORCE_ARROW_MAX_M)
        out[i, 0] = frame.pad_centers[i]
        out[i, 1] = frame.pad_centers[i] + sign * length * x_axis
    return out


class SceneDrawing:
    """The viser scene nodes of one world; ``draw(frame)`` moves them to a new frame.

    server: a ``viser.ViserServer``; triangles: the object's surface [M, 3] (node indices; None: set
    later with ``set_surface``); scale: the ``StressScale`` that colours the surface (its range grows
    with ``draw``).
    """

    def __init__(self, server, triangles: np.ndarray | None = None, scale: StressScale | None = None):
        self.server = server
        self.scale = scale or StressScale()
        scene = server.scene
        scene.set_up_direction("+y")
        scene.add_grid("/ground", width=1.0, height=1.0, plane="xz", cell_size=0.05, section_size=0.25)
        self._bands: list = []
        self.triangles: np.ndarray | None = None
        if triangles is not None:
            self.set_surface(triangles)
        self._pads = [scene.add_box(f"/pads/{side}", color=PAD_COLOR, dimensions=(0.01, 0.01, 0.01))
                      for side in ("left", "right")]
        self._wrist = scene.add_frame("/wrist", axes_length=0.05, axes_radius=0.003)
        self._goal = scene.add_icosphere("/goal", radius=0.015, color=GOAL_COLOR, opacity=0.7)
        self._feature = scene.add_icosphere("/feature", radius=0.005, color=FEATURE_COLOR)
        self._arrows = scene.add_arrows("/tip_forces", np.zeros((2, 2, 3)), colors=FORCE_COLOR,
                                        shaft_radius=0.002, head_radius=0.005, head_length=0.01)

    def set_surface(self, triangles: np.ndarray) -> None:
        """Use another object surface [M, 3] from now on (a new object: its band meshes are rebuilt)."""
        tris = np.asarray(triangles)
        if tris.ndim != 2 or tris.shape[1] != 3 or len(tris) == 0 or not np.issubdtype(tris.dtype, np.integer):
            raise ValueError(f"triangles must be an int array of shape (M, 3) with M >= 1, got {tris.dtype} {tris.shape}")
        for handle in self._bands:
            handle.remove()
        self.triangles = tris.astype(np.uint32)
        dummy = np.zeros((int(self.triangles.max()) + 1, 3), np.float32)
        self._bands = [self.server.scene.add_mesh_simple(f"/object/band_{k:02d}", dummy, self.triangles[:1],
                                                         color=tuple(int(c) for c in color), side="double",
                                                         visible=False)
                       for k, color in enumerate(self.scale.colors)]
        self._last_bands: np.ndarray | None = None

    def draw(self, frame: ViewerFrame) -> None:
        """Move every node to ``frame`` (one atomic update of the scene)."""
        if self.triangles is None:
            raise RuntimeError("set_surface() before draw(): the object's surface is not known yet")
        self.scale.observe(frame.node_stress)
        face_stress = np.asarray(frame.node_stress, dtype=np.float64)[self.triangles.astype(np.int64)].mean(axis=1)
        bands = self.scale.band_of(face_stress)
        vertices = np.asarray(frame.vertices, dtype=np.float32)
        with self.server.atomic():
            for k, handle in enumerate(self._bands):
                in_band = bands == k
                if not in_band.any():
                    handle.visible = False
                    continue
                # each band carries only the vertices its faces use (what crosses the websocket per
                # frame is then about one copy of the surface, not one per band)
                used, local = np.unique(self.triangles[in_band], return_inverse=True)
                handle.vertices = vertices[used]
                if self._last_bands is None or not np.array_equal(in_band, self._last_bands == k):
                    handle.faces = local.reshape(-1, 3).astype(np.uint32)
                handle.visible = True
            self._last_bands = bands
            for i, pad in enumerate(self._pads):
                pad.dimensions = tuple(float(x) for x in 2.0 * np.asarray(frame.pad_half_extents[i]))
                pad.position = np.asarray(frame.pad_centers[i], dtype=np.float64)
                pad.wxyz = wxyz(frame.pad_quats[i])
            self._wrist.position = np.asarray(frame.flange_position, dtype=np.float64)
            self._wrist.wxyz = wxyz(frame.flange_quat)
            self._goal.position = np.asarray(frame.goal, dtype=np.float64)
            self._feature.position = np.asarray(frame.feature_point, dtype=np.float64)
            self._arrows.points = force_arrows(frame).astype(np.float32)
