"""Example scene and timing of the renderer.

    python -m defgrasp_env.render.example [out.png] [--device cpu] [--bench]

Builds a ~500-triangle ellipsoid "soft block" (6 x 5 x 4 cm) gripped by two pads with finger
bodies, lifted by ``lift`` metres, coloured by a synthetic stress field (Pa), with the goal marker
at (0, 0.6, 0) m, and renders it with the default camera.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from .camera import Camera
from .image_io import save_png
from .renderer import SceneRenderer
from .style import RenderStyle


def ellipsoid_surface(radii=(0.03, 0.025, 0.02), n_lat: int = 12, n_lon: int = 24):
    """UV ellipsoid centred at the origin: vertices float32 [N, 3] (m), triangles int32 [M, 3]
    (outward winding); N = 2 + (n_lat - 1) n_lon, M = 2 n_lon (n_lat - 1)."""
    rx, ry, rz = radii
    verts = [(0.0, ry, 0.0)]
    for i in range(1, n_lat):
        th = np.pi * i / n_lat
        for j in range(n_lon):
            ph = 2.0 * np.pi * j / n_lon
            verts.append((rx * np.sin(th) * np.cos(ph), ry * np.cos(th), rz * np.sin(th) * np.sin(ph)))
    verts.append((0.0, -ry, 0.0))
    tris = []
    ring = lambda i, j: 1 + (i - 1) * n_lon + (j % n_lon)  # noqa: E731
    for j in range(n_lon):
        tris.append((0, ring(1, j + 1), ring(1, j)))
    for i in range(1, n_lat - 1):
        for j in range(n_lon):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1)
            tris += [(a, b, c), (b, d, c)]
    last = len(verts) - 1
    for j in range(n_lon):
        tris.append((last, ring(n_lat - 1, j), ring(n_lat - 1, j + 1)))
    return np.asarray(verts, dtype=np.float32), np.asarray(tris, dtype=np.int32)


def example_scene(lift: float = 0.08):
    """Vertices [N,3], triangles [M,3], box centres [4,3], quats xyzw [4,4], half extents [4,3],
    von Mises-like scalar [N] (Pa) and goal [3]: two pads squeezing the block along x plus two
    finger bodies above them, all lifted by ``lift`` m."""
    verts, tris = ellipsoid_surface()
    squeeze = 1.0 - 0.15 * np.exp(-(verts[:, 1] / 0.02) ** 2)  # pads pinch the middle
    verts = verts * np.stack([squeeze, np.ones_like(squeeze), np.ones_like(squeeze)], 1)
    verts[:, 1] += 0.025 + lift
    stress = 2.0e4 * np.exp(-((np.abs(verts[:, 0]) - 0.026) / 0.008) ** 2)
    cy = 0.025 + lift
    centers = np.array([[0.030, cy, 0.0], [-0.030, cy, 0.0],
                        [0.036, cy + 0.05, 0.0], [-0.036, cy + 0.05, 0.0]], dtype=np.float32)
    quats = np.tile(np.array([0.0, 0.0, 0.0, 1.0], dtype=np.float32), (4, 1))
    half = np.array([[0.003, 0.015, 0.015], [0.003, 0.015, 0.015],
                     [0.006, 0.04, 0.012], [0.006, 0.04, 0.012]], dtype=np.float32)
    return verts.astype(np.float32), tris, centers, quats, half, stress.astype(np.float32), (0.0, 0.6, 0.0)


def time_render(renderer: SceneRenderer, args, repeats: int = 30) -> tuple[float, float]:
    """(median, min) wall time of renderer.render(*args) in milliseconds, after one warm-up call."""
    renderer.render(*args[:4], vertex_scalar=args[4], goal=args[5])
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        renderer.render(*args[:4], vertex_scalar=args[4], goal=args[5])
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times)), 1e3 * float(np.min(times))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", nargs="?", default=".cache/render_example.png")
    parser.add_argument("--device", default=None)
    parser.add_argument("--bench", action="store_true", help="print render times at 224x224 and 480x640")
    a = parser.parse_args(argv)
    verts, tris, centers, quats, half, stress, goal = example_scene()
    cam = Camera(width=448, height=448)
    r = SceneRenderer(cam, tris, len(verts), len(centers), device=a.device)
    img = r.render(verts, centers, quats, half, vertex_scalar=stress, scalar_range=(0.0, 2.0e4), goal=goal)
    print("wrote", save_png(a.out, img), f"({len(tris)} triangles)")
    if a.bench:
        for h, w in ((224, 224), (480, 640)):
            for shadows in (True, False):
                rr = SceneRenderer(Camera(width=w, height=h), tris, len(verts), len(centers),
                                   device=a.device, style=RenderStyle(shadows=shadows))
                med, best = time_render(rr, (verts, centers, quats, half, stress, goal))
                print(f"{h}x{w} shadows={shadows}: median {med:.2f} ms, min {best:.2f} ms on {rr.device}")


if __name__ == "__main__":
    main()
