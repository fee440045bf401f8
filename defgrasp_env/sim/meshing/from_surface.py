"""Tet meshes of user-supplied watertight surface meshes (loaded by trimesh).

The surface is taken to be in metres with y up; the result is moved into the object frame
(resting on y = 0, bounding box centred at x = z = 0). Meshing is isosurface stuffing on a BCC
lattice (see :mod:`.stuffing`): inside/outside from trimesh ray tests (embree when installed),
surface crossings of lattice edges from ray casts refined in float64 against the hit triangle's
plane. Smooth surfaces are reproduced up to chords of about the resolution; sharp edges and
corners are bevelled at the scale of the resolution.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import trimesh

from ._checks import checked_resolution
from .primitives import BCC_SPACING_PER_EDGE
from .sdf import Implicit
from .stuffing import stuff_implicit
from .tetmesh import TetMesh, finalize_mesh

__all__ = ["mesh_from_surface", "load_surface", "TrimeshImplicit"]


class TrimeshImplicit(Implicit):
    """The solid bounded by a watertight, outward-wound ``trimesh.Trimesh`` (metres)."""

    def __init__(self, mesh: trimesh.Trimesh) -> None:
        self.mesh = mesh
        self.lo = np.asarray(mesh.bounds[0], dtype=np.float64)
        self.hi = np.asarray(mesh.bounds[1], dtype=np.float64)
        self.origin = 0.5 * (self.lo + self.hi)
        self._tri = np.asarray(mesh.triangles, dtype=np.float64)

    def classify(self, points: np.ndarray) -> np.ndarray:
        if len(points) == 0:
            return np.zeros(0, dtype=np.int8)
        return np.where(self.mesh.contains(points), 1, -1).astype(np.int8)

    def crossings(self, inside: np.ndarray, outside: np.ndarray) -> np.ndarray:
        if len(inside) == 0:
            return np.zeros((0, 3))
        seg = outside - inside
        seed = np.asarray(self.mesh.ray.intersects_first(ray_origins=inside, ray_directions=seg))
        miss = seed < 0
        if np.any(miss):  # grazing ray: start from the triangle closest to the midpoint
            _, _, near = trimesh.proximity.closest_point(self.mesh, inside[miss] + 0.5 * seg[miss])
            seed[miss] = near
        t, ok = self._refine(inside, seg, seed)
        if not np.all(ok):
            # no triangle around the seed is crossed within the segment: take the surface
            # point closest to the midpoint, projected onto the segment
            bad = ~ok
            closest, _, _ = trimesh.proximity.closest_point(self.mesh, inside[bad] + 0.5 * seg[bad])
            sb = seg[bad]
            t[bad] = np.einsum("ij,ij->i", closest - inside[bad], sb) / np.einsum("ij,ij->i", sb, sb)
        t = np.clip(t, 0.0, 1.0)
        return inside + t[:, None] * seg

    def _refine(self, origin: np.ndarray, seg: np.ndarray, seed: np.ndarray):
        """Exact float64 segment/triangle intersection against the seed triangle and every
        triangle sharing a vertex with it (the float32 ray tracer may report a neighbour).
        Returns (t [n], ok [n]); picks the triangle whose barycentric coordinates are most
        inside (ties: first candidate)."""
        vf = np.asarray(self.mesh.vertex_faces)
        cand = vf[np.asarray(self.mesh.faces)[seed]].reshape(len(seed), -1)  # [n, K], -1 pad
        valid = cand >= 0
        c = np.where(valid, cand, 0)
        v0 = self._tri[c, 0]
        e1 = self._tri[c, 1] - v0
        e2 = self._tri[c, 2] - v0
        d = np.broadcast_to(seg[:, None, :], e1.shape)
        p = np.cross(d, e2)
        det = np.einsum("nki,nki->nk", e1, p)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = origin[:, None, :] - v0
            u = np.einsum("nki,nki->nk", s, p) * inv
            q = np.cross(s, e1)
            v = np.einsum("nki,nki->nk", d, q) * inv
            t = np.einsum("nki,nki->nk", e2, q) * inv
            score = np.minimum(np.minimum(u, v), 1.0 - u - v)
        good = valid & np.isfinite(t) & (det != 0.0) & (t >= -1e-9) & (t <= 1.0 + 1e-9)
        score = np.where(good & np.isfinite(score), score, -np.inf)
        best = np.argmax(score, axis=1)
        rows = np.arange(len(seed))
        return t[rows, best], score[rows, best] > -1e-9


def load_surface(source: str | os.PathLike | trimesh.Trimesh) -> trimesh.Trimesh:
    """The checked surface :func:`mesh_from_surface` meshes: loaded, non-empty, finite, watertight,
    consistently wound, outward (inverted if needed). Raises as :func:`mesh_from_surface` does."""
    if isinstance(source, trimesh.Trimesh):
        mesh = trimesh.Trimesh(
            vertices=np.array(source.vertices, dtype=np.float64),
            faces=np.array(source.faces, dtype=np.int64),
            process=True,
        )
    elif isinstance(source, (str, os.PathLike)):
        path = Path(source)
        if not path.is_file():
            raise FileNotFoundError(f"surface mesh file not found: {str(path)!r}")
        loaded = trimesh.load(path, force="mesh", process=True)
        if not isinstance(loaded, trimesh.Trimesh):
            raise ValueError(f"{str(path)!r} does not contain a triangle mesh (got {type(loaded).__name__})")
        mesh = loaded
    else:
        raise TypeError(
            "source must be a file path (str or os.PathLike) or a trimesh.Trimesh, got "
            f"{type(source).__name__}"
        )
    if len(mesh.faces) == 0 or len(mesh.vertices) == 0:
        raise ValueError("surface mesh is empty: it must have at least 4 triangles, got 0")
    if not np.all(np.isfinite(mesh.vertices)):
        raise ValueError("surface mesh vertices must be finite, got NaN or inf")
    if not mesh.is_watertight:
        raise ValueError(
            "surface mesh must be watertight (every edge shared by exactly 2 triangles); "
            f"got {len(mesh.faces)} triangles that do not close a volume"
        )
    if not mesh.is_winding_consistent:
        raise ValueError("surface mesh must have consistently wound triangles")
    if mesh.volume < 0.0:
        mesh.invert()
    if not mesh.volume > 0.0:
        raise ValueError(f"surface mesh must enclose a volume in (0, inf) m^3, got {mesh.volume!r}")
    return mesh


def mesh_from_surface(source: str | os.PathLike | trimesh.Trimesh, resolution: float) -> TetMesh:
    """Tet mesh of the solid bounded by a watertight surface mesh.

    Args:
        source: path of any file trimesh loads (STL, OBJ, PLY, OFF, GLB, ...) or a
            ``trimesh.Trimesh``; coordinates in metres, y up.
        resolution: target mean tet edge length, metres, in (0, smallest bounding-box extent].
    Returns:
        A verified :class:`TetMesh` in the object frame (resting on y = 0, centred at x = z = 0).
    Raises:
        TypeError: wrong source type or non-numeric resolution.
        FileNotFoundError: missing file.
        ValueError: empty / non-watertight surface, resolution out of range, non-manifold or
            degenerate result.
    """
    mesh = load_surface(source)
    extent = float(np.min(mesh.extents))
    res = checked_resolution(resolution, extent, "this surface", "its smallest bounding-box extent")
    nodes, tets = stuff_implicit(TrimeshImplicit(mesh), res * BCC_SPACING_PER_EDGE)
    return finalize_mesh(nodes, tets, what=f"surface mesh at resolution {res:g} m")
