"""Boundary-surface extraction and topology checks for tet meshes (pure numpy).

Conventions: ``tets`` [M,4] int, positively oriented (det[x1-x0, x2-x0, x3-x0] > 0). The
outward faces of such a tet are (1,2,3), (0,3,2), (0,1,3), (0,2,1): their normal
(x1-x0) x (x2-x0) points away from the opposite vertex.
"""

from __future__ import annotations

import numpy as np

__all__ = ["unique_rows", "boundary_faces", "surface_edge_use", "check_closed_manifold"]

_OUTWARD_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


def unique_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unique rows of a non-negative int array [n,k] in lexicographic order.

    Returns (unique [u,k], inverse [n], counts [u]); like ``np.unique(rows, axis=0, ...)`` but
    much faster (rows packed into one int64 key when the values allow it)."""
    rows = np.asarray(rows, dtype=np.int64)
    if len(rows) == 0:
        return rows.reshape(0, rows.shape[1]), np.zeros(0, np.int64), np.zeros(0, np.int64)
    base = int(rows.max()) + 1
    if base ** rows.shape[1] < 2**62:
        key = np.zeros(len(rows), dtype=np.int64)
        for col in rows.T:
            key = key * base + col
        order = np.argsort(key, kind="stable")
        sk = key[order]
        start = np.r_[True, sk[1:] != sk[:-1]]
    else:
        order = np.lexsort(rows.T[::-1])
        sr = rows[order]
        start = np.r_[True, np.any(sr[1:] != sr[:-1], axis=1)]
    group = np.cumsum(start) - 1
    inverse = np.empty(len(rows), dtype=np.int64)
    inverse[order] = group
    counts = np.diff(np.r_[np.flatnonzero(start), len(rows)])
    return rows[order[start]], inverse, counts


def boundary_faces(tets: np.ndarray) -> np.ndarray:
    """Faces used by exactly one tet, wound outward, sorted deterministically.

    Args:
        tets: [M,4] int, positively oriented tets.
    Returns:
        [F,3] int32 outward-wound boundary triangles, in ascending order of their sorted
        vertex triples.
    Raises:
        ValueError: if a face is shared by more than two tets (non-conforming mesh).
    """
    faces = tets[:, _OUTWARD_FACES].reshape(-1, 3).astype(np.int64)
    key_faces = np.sort(faces, axis=1)
    _, inverse, counts = unique_rows(key_faces)
    if counts.size and counts.max() > 2:
        bad = int(np.count_nonzero(counts > 2))
        raise ValueError(
            f"tet mesh is non-conforming: {bad} faces are shared by more than 2 tets "
            "(each face must belong to 1 or 2 tets)"
        )
    once = counts[inverse] == 1
    surf = faces[once]
    order = np.argsort(inverse[once], kind="stable")  # ascending sorted vertex triple
    return surf[order].astype(np.int32)


def surface_edge_use(surface: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Undirected edges of a triangle surface and how many triangles use each.

    Returns:
        (edges [E,2] int64 with edges[:,0] < edges[:,1], counts [E] int64).
    """
    e = surface[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).astype(np.int64)
    uniq, _, counts = unique_rows(np.sort(e, axis=1))
    return uniq, counts


def check_closed_manifold(surface: np.ndarray) -> None:
    """Raise ValueError unless every surface edge is used by exactly 2 triangles with opposite
    directions (closed, consistently oriented, edge-manifold surface)."""
    if len(surface) == 0:
        raise ValueError("surface has no triangles")
    _, counts = surface_edge_use(surface)
    if np.any(counts != 2):
        bad = int(np.count_nonzero(counts != 2))
        raise ValueError(
            f"surface is not a closed edge-manifold: {bad} edges are used by a number of "
            "triangles other than 2 (the resolution may be too coarse for a thin feature)"
        )
    directed = surface[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).astype(np.int64)
    _, _, dcounts = unique_rows(directed)
    if np.any(dcounts != 1):
        raise ValueError("surface is not consistently oriented: a directed edge occurs twice")
