"""Float64 numpy references of geometric queries for the kernel tests."""

import numpy as np


def point_triangle_distances(p, tri):
    """Distances from p [3] to triangles tri [T, 3, 3]: to the plane where p projects inside,
    else to the nearest of the three edges (float64, vectorised over the triangles)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    height = np.einsum("ij,ij->i", p - a, normal)
    proj = p - height[:, None] * normal
    inside = np.ones(len(tri), bool)
    for u, v in ((a, b), (b, c), (c, a)):  # the projection on the inner side of every edge
        inside &= np.einsum("ij,ij->i", np.cross(v - u, proj - u), normal) >= 0
    best = np.full(len(tri), np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        t = np.clip(np.einsum("ij,ij->i", p - u, v - u) / np.einsum("ij,ij->i", v - u, v - u), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(p - (u + t[:, None] * (v - u)), axis=1))
    return np.where(inside, np.abs(height), best)
