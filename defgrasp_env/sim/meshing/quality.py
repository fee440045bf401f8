"""Per-tetrahedron geometry and quality measures (pure numpy).

All functions take ``nodes`` [N,3] float64 (metres, any frame) and ``tets`` [M,4] integer
indices and return per-tet arrays of length M. A tet (x0, x1, x2, x3) is *positively oriented*
when det[x1-x0, x2-x0, x3-x0] > 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "MeshQuality",
    "signed_volumes",
    "dihedral_angles_deg",
    "radius_ratios",
    "mesh_quality",
]

# Edge (i, j) of a tet is shared by the two faces opposite the other two vertices (k, l).
_EDGE_OPPOSITE = ((2, 3), (1, 3), (1, 2), (0, 3), (0, 2), (0, 1))  # for edges 01,02,03,12,13,23


@dataclass(frozen=True)
class MeshQuality:
    """Summary of a tet mesh's element quality.

    Attributes:
        min_dihedral_deg: smallest dihedral angle over all tets, degrees (regular tet: 70.53).
        mean_dihedral_deg: mean of all 6*M dihedral angles, degrees.
        max_dihedral_deg: largest dihedral angle, degrees (regular tet: 70.53).
        min_radius_ratio: smallest 3*r_in/r_circ (1 = regular tet, 0 = degenerate).
        mean_radius_ratio: mean 3*r_in/r_circ.
        min_volume: smallest signed tet volume, m^3 (> 0 for a valid mesh).
        num_nodes, num_tets, num_surface_tris: counts.
    """

    min_dihedral_deg: float
    mean_dihedral_deg: float
    max_dihedral_deg: float
    min_radius_ratio: float
    mean_radius_ratio: float
    min_volume: float
    num_nodes: int
    num_tets: int
    num_surface_tris: int


def signed_volumes(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volume of every tet, m^3: det[x1-x0, x2-x0, x3-x0] / 6. Shape [M]."""
    x0 = nodes[tets[:, 0]]
    a = nodes[tets[:, 1]] - x0
    b = nodes[tets[:, 2]] - x0
    c = nodes[tets[:, 3]] - x0
    return np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0


def _face_area_vectors(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Area vectors [M,4,3] of the faces opposite vertex 0..3, pointing outward for a
    positively oriented tet (magnitude = 2 * triangle area)."""
    x = nodes[tets]  # [M,4,3]
    out = np.empty_like(x)
    # outward faces of a positive tet: opp0=(1,2,3), opp1=(0,3,2), opp2=(0,1,3), opp3=(0,2,1)
    for k, (i, j, l) in enumerate(((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1))):
        out[:, k] = np.cross(x[:, j] - x[:, i], x[:, l] - x[:, i])
    return out


def dihedral_angles_deg(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """The 6 interior dihedral angles of every tet, degrees, shape [M,6] (edge order 01, 02,
    03, 12, 13, 23). A degenerate (zero-area face) tet gives 0 for the affected angles."""
    n = _face_area_vectors(nodes, tets)
    norm = np.linalg.norm(n, axis=2)
    safe = np.where(norm > 0.0, norm, 1.0)
    unit = n / safe[:, :, None]
    ang = np.empty((len(tets), 6))
    for e, (k, l) in enumerate(_EDGE_OPPOSITE):
        cos = np.einsum("ij,ij->i", unit[:, k], unit[:, l])
        ang[:, e] = np.pi - np.arccos(np.clip(cos, -1.0, 1.0))
        ang[(norm[:, k] == 0.0) | (norm[:, l] == 0.0), e] = 0.0
    return np.degrees(ang)


def radius_ratios(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Normalised radius ratio 3 * r_in / r_circ of every tet, shape [M]; 1 for a regular tet,
    0 for a degenerate one, negative for an inverted one."""
    x0 = nodes[tets[:, 0]]
    a = nodes[tets[:, 1]] - x0
    b = nodes[tets[:, 2]] - x0
    c = nodes[tets[:, 3]] - x0
    det = np.einsum("ij,ij->i", a, np.cross(b, c))  # 6 V
    areas = 0.5 * np.linalg.norm(_face_area_vectors(nodes, tets), axis=2).sum(axis=1)
    circ = (
        np.einsum("i,ij->ij", np.einsum("ij,ij->i", a, a), np.cross(b, c))
        + np.einsum("i,ij->ij", np.einsum("ij,ij->i", b, b), np.cross(c, a))
        + np.einsum("i,ij->ij", np.einsum("ij,ij->i", c, c), np.cross(a, b))
    )
    circ_len = np.linalg.norm(circ, axis=1)  # = 2 |det| r_circ
    # r_in = 3V / A = det / (2 A); r_circ = |circ| / (2 |det|)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = 3.0 * (det / (2.0 * areas)) * (2.0 * np.abs(det)) / circ_len
    return np.where(np.isfinite(ratio), ratio, 0.0)


def mesh_quality(nodes: np.ndarray, tets: np.ndarray, num_surface_tris: int) -> MeshQuality:
    """Summarise the quality of a tet mesh (see :class:`MeshQuality`)."""
    if len(tets) == 0:
        raise ValueError("mesh has no tetrahedra; cannot compute its quality")
    dih = dihedral_angles_deg(nodes, tets)
    rr = radius_ratios(nodes, tets)
    vol = signed_volumes(nodes, tets)
    return MeshQuality(
        min_dihedral_deg=float(dih.min()),
        mean_dihedral_deg=float(dih.mean()),
        max_dihedral_deg=float(dih.max()),
        min_radius_ratio=float(rr.min()),
        mean_radius_ratio=float(rr.mean()),
        min_volume=float(vol.min()),
        num_nodes=int(len(nodes)),
        num_tets=int(len(tets)),
        num_surface_tris=int(num_surface_tris),
    )
