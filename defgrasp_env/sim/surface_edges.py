"""Edges of the objects' boundary triangles, for the edge-edge pad contact (``kernels/edge_contact.py``)."""

from __future__ import annotations

import numpy as np

from .model import Model


def surface_edges(model: Model | None) -> tuple[np.ndarray, np.ndarray]:
    """Unique edges of every world's boundary triangles (``Model.surfaces``): global node ids
    [E, 2] int32 (lower id first, sorted per world) and the world of each edge [E] int32; none
    for ``None``."""
    edges, worlds = [], []
    for w, tris in enumerate(model.surfaces if model is not None else []):
        tris = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
        pairs = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
        unique = np.unique(pairs, axis=0) + int(model.node_start[w])
        edges.append(unique)
        worlds.append(np.full(len(unique), w))
    if not edges:
        return np.zeros((0, 2), np.int32), np.zeros(0, np.int32)
    return np.concatenate(edges).astype(np.int32), np.concatenate(worlds).astype(np.int32)
