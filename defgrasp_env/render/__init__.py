"""Headless renderer of the pickup scene: Warp ray casting, one thread per pixel, CPU or CUDA.

    from defgrasp_env.render import Camera, SceneRenderer
    r = SceneRenderer(Camera(), triangles, num_vertices=N, num_boxes=2, device="cpu")
    rgb = r.render(vertices, box_centers, box_quats, box_half_extents, goal=(0, 0.6, 0))

World frame y up, metres, quaternions (x, y, z, w); images uint8 [H, W, 3], row 0 at the top.
"""

from .camera import Camera
from .image_io import save_png
from .renderer import SceneRenderer
from .style import COLORMAPS, RenderStyle

__all__ = ["COLORMAPS", "Camera", "RenderStyle", "SceneRenderer", "save_png"]
