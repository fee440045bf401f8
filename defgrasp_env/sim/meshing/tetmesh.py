"""The :class:`TetMesh` container and the common clean-up/verification step of every mesher.

Frame of a finished mesh (the OBJECT frame): metres, y up, the object resting on the ground
(min node y == 0) and its axis-aligned bounding box centred at x = z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .quality import MeshQuality, mesh_quality, radius_ratios, signed_volumes, dihedral_angles_deg
from .surface import boundary_faces, check_closed_manifold

__all__ = ["TetMesh", "finalize_mesh", "MIN_DIHEDRAL_DEG", "MIN_RADIUS_RATIO"]

# A finished mesh with a tet worse than either bound is rejected as near-degenerate.
MIN_DIHEDRAL_DEG = 3.0
MIN_RADIUS_RATIO = 0.02


def _readonly(a: np.ndarray, dtype, cols: int, name: str) -> np.ndarray:
    arr = np.array(a, dtype=dtype, copy=True)
    if arr.ndim != 2 or arr.shape[1] != cols:
        raise ValueError(f"{name} must have shape [n, {cols}], got {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class TetMesh:
    """An immutable linear tetrahedral mesh of one object.

    Attributes:
        nodes: [N3,3] float64 node positions, metres, object frame (y up; the object rests on
            the ground: min y == 0; bounding box centred at x = z = 0).
        tets: [N2,4] int32 node indices, every tet positively oriented
            (det[x1-x0, x2-x0, x3-x0] > 0).
        surface: [N1,3] int32 node indices of exactly the boundary faces of ``tets`` (faces
            used by one tet), wound so that (x1-x0) x (x2-x0) points out of the object.

    The arrays are read-only copies. Build meshes with :func:`make_object_mesh` or
    :func:`mesh_from_surface`; the constructor only checks shapes, dtypes and index ranges.
    """

    nodes: np.ndarray
    tets: np.ndarray
    surface: np.ndarray

    def __post_init__(self) -> None:
        nodes = _readonly(self.nodes, np.float64, 3, "nodes")
        tets = _readonly(self.tets, np.int32, 4, "tets")
        surface = _readonly(self.surface, np.int32, 3, "surface")
        if not np.all(np.isfinite(nodes)):
            raise ValueError("nodes must be finite, got NaN or inf")
        for name, idx in (("tets", tets), ("surface", surface)):
            if idx.size and (idx.min() < 0 or idx.max() >= len(nodes)):
                raise ValueError(
                    f"{name} indices must be in [0, {len(nodes) - 1}], got "
                    f"[{idx.min()}, {idx.max()}]"
                )
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "tets", tets)
        object.__setattr__(self, "surface", surface)

    @property
    def num_nodes(self) -> int:
        """Number of nodes N3."""
        return int(self.nodes.shape[0])

    @property
    def num_tets(self) -> int:
        """Number of tetrahedra N2."""
        return int(self.tets.shape[0])

    @property
    def num_surface_tris(self) -> int:
        """Number of boundary triangles N1."""
        return int(self.surface.shape[0])

    def tet_volumes(self) -> np.ndarray:
        """[N2] float64 signed volume of every tet, m^3 (all > 0)."""
        return signed_volumes(self.nodes, self.tets)

    @property
    def volume(self) -> float:
        """Total volume, m^3 (sum of tet volumes)."""
        return float(self.tet_volumes().sum())

    def quality(self) -> MeshQuality:
        """Element-quality summary: dihedral angles (deg), radius ratios, min volume (m^3)."""
        return mesh_quality(self.nodes, self.tets, self.num_surface_tris)


def _drop_unreferenced(nodes: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    used = np.zeros(len(nodes), dtype=bool)
    used[tets.ravel()] = True
    new_index = np.cumsum(used) - 1
    return nodes[used], new_index[tets]


def finalize_mesh(nodes: np.ndarray, tets: np.ndarray, what: str) -> TetMesh:
    """Clean, normalise and verify a raw tet mesh; return it as a :class:`TetMesh`.

    Steps: drop unreferenced nodes (keeping their order), orient every tet positively, move
    to the object frame (min y = 0, bounding box centred at x = z = 0), extract the boundary
    surface, and verify: closed edge-manifold surface, every tet positive with min dihedral
    angle >= MIN_DIHEDRAL_DEG and radius ratio >= MIN_RADIUS_RATIO.

    Args:
        nodes: [N,3] float64 positions, metres, y up.
        tets: [M,4] integer node indices, any orientation.
        what: description used in error messages (e.g. "sphere at resolution 0.008 m").
    Raises:
        ValueError: empty, non-manifold or degenerate mesh (the message names the quality).
    """
    tets = np.asarray(tets, dtype=np.int64)
    if len(tets) == 0:
        raise ValueError(
            f"meshing the {what} produced no tetrahedra: the resolution is too coarse for the "
            "object (less than one tet layer); use a finer resolution"
        )
    nodes, tets = _drop_unreferenced(np.asarray(nodes, dtype=np.float64), tets)
    vol = signed_volumes(nodes, tets)
    flip = vol < 0.0
    tets[flip] = tets[flip][:, [0, 1, 3, 2]]
    lo, hi = nodes.min(axis=0), nodes.max(axis=0)
    shift = np.array([0.5 * (lo[0] + hi[0]), lo[1], 0.5 * (lo[2] + hi[2])])
    nodes = nodes - shift
    surface = boundary_faces(tets)
    check_closed_manifold(surface)
    vol = signed_volumes(nodes, tets)
    if vol.min() <= 0.0:
        raise ValueError(
            f"meshing the {what} produced {int(np.count_nonzero(vol <= 0))} degenerate tets "
            f"(min volume {vol.min():.3e} m^3, must be > 0)"
        )
    min_dih = float(dihedral_angles_deg(nodes, tets).min())
    min_rr = float(radius_ratios(nodes, tets).min())
    if min_dih < MIN_DIHEDRAL_DEG or min_rr < MIN_RADIUS_RATIO:
        raise ValueError(
            f"meshing the {what} produced a near-degenerate tet: min dihedral angle "
            f"{min_dih:.2f} deg (must be >= {MIN_DIHEDRAL_DEG}), min radius ratio {min_rr:.4f} "
            f"(must be >= {MIN_RADIUS_RATIO}); try a finer resolution"
        )
    return TetMesh(nodes=nodes, tets=tets.astype(np.int32), surface=surface)
