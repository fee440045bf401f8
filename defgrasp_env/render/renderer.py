"""Headless ray-cast renderer of the pickup scene (no display, no OpenGL), on Warp kernels.

Scene, all in the world frame (y up, metres): the deformable object as a triangle surface whose
vertices move every frame, K oriented boxes (gripper pads, finger bodies), the ground plane
y = 0 with a checkerboard, an optional goal marker sphere, and a sky gradient.
One thread per pixel; the same code runs on ``"cpu"`` and ``"cuda:N"``.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from . import kernels as K
from .camera import Camera, _vec3
from .style import COLORMAPS, RenderStyle


def _count(name: str, value, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an int, got {type(value).__name__} {value!r}")
    if int(value) < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    return int(value)


class SceneRenderer:
    """Render the pickup scene to an RGB image.

    The object's connectivity is fixed at construction; its vertex positions are given to every
    :meth:`render` call. The BVH of the object (a ``wp.Mesh``) is built at the first render from
    those vertices and refitted (topology kept, bounds updated) at every later render.

    Args:
        camera: the :class:`Camera` (image size and view).
        triangles: surface triangles, int [M, 3] (M >= 1), indices into the vertex array; the
            winding may be either way (surfaces are shaded two-sided).
        num_vertices: N, the number of object vertices passed to :meth:`render` (>= 3).
        num_boxes: K, the number of oriented boxes passed to :meth:`render` (>= 0).
        device: Warp device ("cpu", "cuda:0", a ``wp.Device``) or None for Warp's default.
        style: colours, light and colormap (:class:`RenderStyle`).
        box_colors: optional per-box RGB in [0, 1], float [K, 3]; default ``style.box_color``.
    """

    def __init__(self, camera: Camera, triangles: np.ndarray, num_vertices: int, num_boxes: int,
                 device=None, *, style: RenderStyle | None = None, box_colors=None):
        self.style = RenderStyle() if style is None else style
        if not isinstance(self.style, RenderStyle):
            raise TypeError(f"style must be a RenderStyle, got {type(style).__name__}")
        self.num_vertices = _count("num_vertices", num_vertices, 3)
        self.num_boxes = _count("num_boxes", num_boxes, 0)
        self.device = wp.get_device(device)
        tris = self._check_triangles(triangles, self.num_vertices)
        self.num_triangles = tris.shape[0]
        self.triangles = tris
        dev = self.device

        self._indices = wp.array(tris.reshape(-1), dtype=wp.int32, device=dev)
        # CSR vertex -> incident faces, in a fixed order (deterministic vertex normals)
        vert_of_corner = tris.reshape(-1)
        order = np.argsort(vert_of_corner, kind="stable")
        offsets = np.zeros(self.num_vertices + 1, dtype=np.int32)
        np.cumsum(np.bincount(vert_of_corner, minlength=self.num_vertices), out=offsets[1:])
        self._adj_offsets = wp.array(offsets, dtype=wp.int32, device=dev)
        self._adj_faces = wp.array((order // 3).astype(np.int32), dtype=wp.int32, device=dev)

        self._points = wp.zeros(self.num_vertices, dtype=wp.vec3, device=dev)
        self._normals = wp.zeros(self.num_vertices, dtype=wp.vec3, device=dev)
        self._scalar = wp.zeros(self.num_vertices, dtype=wp.float32, device=dev)
        self._mesh: wp.Mesh | None = None
        self._cmap = wp.array(np.asarray(COLORMAPS[self.style.colormap], dtype=np.float32),
                              dtype=wp.vec3, device=dev)

        nb = self.num_boxes
        self._box_c = wp.zeros(nb, dtype=wp.vec3, device=dev)
        self._box_q = wp.zeros(nb, dtype=wp.quat, device=dev)
        self._box_h = wp.zeros(nb, dtype=wp.vec3, device=dev)
        if box_colors is None:
            colors = np.tile(np.asarray(self.style.box_color, dtype=np.float32), (nb, 1))
        else:
            colors = np.asarray(box_colors, dtype=np.float32)
            if colors.shape != (nb, 3):
                raise ValueError(f"box_colors must have shape (K, 3) = ({nb}, 3), got {colors.shape}")
            if not np.all((colors >= 0.0) & (colors <= 1.0)):
                raise ValueError("box_colors must have components in [0, 1]")
        self._box_col = wp.array(colors.reshape(nb, 3), dtype=wp.vec3, device=dev)
        self._image = None
        self.set_camera(camera)

    # ------------------------------------------------------------------ configuration
    @staticmethod
    def _check_triangles(triangles, num_vertices: int) -> np.ndarray:
        tris = np.asarray(triangles)
        if tris.ndim != 2 or tris.shape[1] != 3 or tris.shape[0] < 1:
            raise ValueError(f"triangles must have shape (M, 3) with M >= 1, got {tris.shape}")
        if not np.issubdtype(tris.dtype, np.integer):
            raise TypeError(f"triangles must be an integer array, got dtype {tris.dtype}")
        lo, hi = int(tris.min()), int(tris.max())
        if lo < 0 or hi >= num_vertices:
            raise ValueError(f"triangles must index vertices in [0, {num_vertices - 1}], "
                             f"got indices in [{lo}, {hi}]")
        return np.ascontiguousarray(tris, dtype=np.int32)

    def set_camera(self, camera: Camera) -> None:
        """Use another camera from now on (the output size follows camera.width/height)."""
        if not isinstance(camera, Camera):
            raise TypeError(f"camera must be a Camera, got {type(camera).__name__}")
        self.camera = camera
        right, up_cam, forward = camera.basis()
        self._cam = (wp.vec3(*camera.position), wp.vec3(*right), wp.vec3(*up_cam), wp.vec3(*forward),
                     math.tan(math.radians(camera.fov_y_deg) / 2.0))
        shape = (camera.height, camera.width, 3)
        if self._image is None or self._image.shape != shape:
            self._image = wp.zeros(shape, dtype=wp.uint8, device=self.device)

    # ------------------------------------------------------------------ input conversion
    def _load(self, name: str, value, dst: wp.array, rows: str, width: int) -> np.ndarray | None:
        """Copy value (numpy-like [P, width] or a wp.array on this device) into dst [P].

        Returns the validated float array for numpy input (for further checks), None for wp.array.
        """
        count = dst.shape[0]
        expected = f"{name} must have shape ({rows}, {width}) = ({count}, {width})"
        if isinstance(value, wp.array):
            if value.device != self.device:
                raise ValueError(f"{name} is on device {value.device}, the renderer on {self.device}")
            vec_type = wp.vec3 if width == 3 else wp.quat
            if value.dtype == vec_type and value.ndim == 1:
                if value.shape[0] != count:
                    raise ValueError(f"{expected}, got ({value.shape[0]}, {width})")
                wp.copy(dst, value)
            elif value.dtype == wp.float32 and value.ndim == 2:
                if value.shape != (count, width):
                    raise ValueError(f"{expected}, got {value.shape}")
                kernel = K.rows_to_vec3_kernel if width == 3 else K.rows_to_quat_kernel
                wp.launch(kernel, dim=count, inputs=[value], outputs=[dst], device=self.device)
            else:
                raise TypeError(f"{name} as wp.array must be float32 ({rows}, {width}) or "
                                f"{vec_type.__name__} ({rows},), got dtype {value.dtype} shape {value.shape}")
            return None
        arr = np.asarray(value)
        if arr.shape != (count, width):
            raise ValueError(f"{expected}, got {arr.shape}")
        if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
            raise TypeError(f"{name} must be a real-valued array, got dtype {arr.dtype}")
        arr = arr.astype(np.float32)
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite, got NaN or inf")
        dst.assign(arr)
        return arr

    def _load_scalar(self, vertex_scalar, scalar_range) -> tuple[int, float, float]:
        if vertex_scalar is None:
            if scalar_range is not None:
                raise ValueError("scalar_range was given without vertex_scalar")
            return 0, 0.0, 1.0
        n = self.num_vertices
        if isinstance(vertex_scalar, wp.array):
            if vertex_scalar.device != self.device:
                raise ValueError(f"vertex_scalar is on device {vertex_scalar.device}, the renderer on {self.device}")
            if vertex_scalar.dtype != wp.float32 or vertex_scalar.shape != (n,):
                raise ValueError(f"vertex_scalar must be float32 with shape (N,) = ({n},), "
                                 f"got {vertex_scalar.dtype.__name__} {vertex_scalar.shape}")
            wp.copy(self._scalar, vertex_scalar)
            data = None
        else:
            data = np.asarray(vertex_scalar)
            if data.shape != (n,):
                raise ValueError(f"vertex_scalar must have shape (N,) = ({n},), got {data.shape}")
            data = data.astype(np.float32)
            if not np.all(np.isfinite(data)):
                raise ValueError("vertex_scalar must be finite, got NaN or inf")
            self._scalar.assign(data)
        if scalar_range is None:
            if data is None:
                data = self._scalar.numpy()
            lo, hi = float(data.min()), float(data.max())
            if not hi > lo:
                hi = lo + 1.0
        else:
            rng = np.asarray(scalar_range, dtype=np.float64)
            if rng.shape != (2,) or not np.all(np.isfinite(rng)) or not rng[1] > rng[0]:
                raise ValueError(f"scalar_range must be finite (lo, hi) with hi > lo, got {scalar_range!r}")
            lo, hi = float(rng[0]), float(rng[1])
        return 1, lo, hi

    # ------------------------------------------------------------------ render
    def render(self, vertices, box_centers, box_quats, box_half_extents, vertex_scalar=None,
               scalar_range=None, goal=None) -> np.ndarray:
        """Render one frame.

        Args (numpy-like, or wp.array on the renderer's device; world frame, metres):
            vertices: object vertex positions, float [N, 3] (or wp.vec3 [N]).
            box_centers: box centres, float [K, 3] (or wp.vec3 [K]).
            box_quats: box orientations body-to-world, quaternion (x, y, z, w), float [K, 4]
                (or wp.quat [K]); normalised before use, must be non-zero.
            box_half_extents: half side lengths along the box axes, float [K, 3] (> 0 for numpy).
            vertex_scalar: optional per-vertex scalar, float [N] (e.g. von Mises stress, Pa);
                colours the object through ``style.colormap``, interpolated barycentrically.
            scalar_range: (lo, hi) mapped to the colormap ends (clamped outside); default the
                min and max of vertex_scalar.
            goal: optional goal marker centre, float [3]; drawn as a sphere of ``style.goal_radius``.

        Returns:
            RGB image, uint8 [H, W, 3], row 0 at the top (a new array, not a view).
        """
        self._load("vertices", vertices, self._points, "N", 3)
        self._load("box_centers", box_centers, self._box_c, "K", 3)
        quats = self._load("box_quats", box_quats, self._box_q, "K", 4)
        if quats is not None and np.any(np.linalg.norm(quats, axis=1) < 1e-8):
            raise ValueError("box_quats must be non-zero quaternions (x, y, z, w)")
        half = self._load("box_half_extents", box_half_extents, self._box_h, "K", 3)
        if half is not None and np.any(half <= 0.0):
            raise ValueError(f"box_half_extents must be in (0, inf) m, got min {float(half.min())}")
        use_scalar, lo, hi = self._load_scalar(vertex_scalar, scalar_range)
        goal_pos = (0.0, 0.0, 0.0) if goal is None else _vec3("goal", goal)

        if self._mesh is None:
            self._mesh = wp.Mesh(points=self._points, indices=self._indices)
        else:
            self._mesh.refit()
        wp.launch(K.vertex_normals_kernel, dim=self.num_vertices,
                  inputs=[self._points, self._indices, self._adj_offsets, self._adj_faces],
                  outputs=[self._normals], device=self.device)

        st = self.style
        cam_pos, cam_right, cam_up, cam_fwd, tan_half = self._cam
        wp.launch(
            K.render_kernel,
            dim=(self.camera.height, self.camera.width),
            inputs=[
                self._mesh.id, self._indices, self._normals, self._scalar, use_scalar, lo, hi, self._cmap,
                self._box_c, self._box_q, self._box_h, self._box_col,
                wp.vec3(*goal_pos), st.goal_radius, 0 if goal is None else 1,
                cam_pos, cam_right, cam_up, cam_fwd, tan_half,
                wp.vec3(*st.light_unit()), st.ambient, st.diffuse, 1 if st.shadows else 0,
                wp.vec3(*st.object_color), wp.vec3(*st.goal_color),
                wp.vec3(*st.checker_light), wp.vec3(*st.checker_dark), st.checker_size,
                wp.vec3(*st.sky_horizon), wp.vec3(*st.sky_zenith), st.fog_distance,
            ],
            outputs=[self._image],
            device=self.device,
        )
        return np.array(self._image.numpy(), copy=True)
