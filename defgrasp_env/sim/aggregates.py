"""Node aggregates of each world: the coarse space of the solver's linear solves.

The CG preconditioner of ``kernels/coarse_space.py`` adds a coarse solve on the rigid motions
(translations and small rotations about an anchor node, ``aggregate_anchors``) of a few node
aggregates per world. Every object is cut into 8 pieces of equal node counts by recursive
bisection of its rest nodes at the median along the principal axis of each piece: a slender
object (a rope) into 8 slices along its length, where block-Jacobi CG is slowest (a correction takes
~ its length in elements of iterations to cross it), a compact one into octant-like blocks, whose
rigid motions carry a stiff object's near-rigid deformation. Measured on the expert's episodes
(100 steps, E = 1e4 and 1e7, this project's 2-core AMD EPYC, 2026-12-07; CG iterations summed): with the
rigid motions of 8 pieces against the translations of one (compact) or of 8 slices (the rope)
before: stiff cuboid 7,594 -> 3,968, stiff torus 13,525 -> 6,976, soft torus 26,409 -> 19,531,
rope 31,457 -> 26,331 (E = 1e4) and 13,968 -> 12,140 (1e7); 4 pieces of a compact object saved
less (stiff torus 10,051), and its rigid motions as one piece less still (12,208).
The cuts follow the principal axes of the object-frame nodes (``build_model``), so an object is cut
the same way whatever its pose (cutting posed nodes split nodes tied at a cut by float rounding of
the pose, so an episode depended on the pose of the reset that built the scene).
"""

from __future__ import annotations

import numpy as np

#: Aggregates per world (a power of two).
AGGREGATES = 8


def bisect_nodes(x: np.ndarray, pieces: int = AGGREGATES) -> np.ndarray:
    """Aggregate index in [0, pieces) of each of the nodes ``x`` [N, 3] (m): ``pieces`` must be a
    power of two; each piece with at least 2 nodes is split at the median along its principal axis
    until there are ``pieces`` pieces (a mesh of fewer nodes leaves some indices unused)."""
    if pieces < 1 or pieces & (pieces - 1):
        raise ValueError(f"pieces must be a power of two >= 1, got {pieces}")
    x = np.asarray(x, dtype=np.float64)
    groups = [np.arange(len(x))]
    while len(groups) < pieces:
        split = []
        for g in groups:
            if len(g) < 2:
                split += [g, g[:0]]
                continue
            centred = x[g] - x[g].mean(axis=0)
            axis = np.linalg.eigh(centred.T @ centred)[1][:, -1]
            order = g[np.argsort(centred @ axis, kind="stable")]
            split += [order[: len(g) // 2], order[len(g) // 2:]]
        groups = split
    index = np.empty(len(x), dtype=np.int32)
    for k, g in enumerate(groups):
        index[g] = k
    return index


def aggregate_anchors(x: np.ndarray, index: np.ndarray) -> np.ndarray:
    """[N] int32: for each of the nodes ``x`` [N, 3] (m), the node of its aggregate (``index``, from
    ``bisect_nodes``) nearest that aggregate's mean position (the lowest index among equals): the
    point its aggregate's rotations turn about, so that the coarse space's levers (x_i - x_anchor)
    are at most an aggregate's size. From the object-frame nodes, so the same for every pose."""
    x = np.asarray(x, dtype=np.float64)
    index = np.asarray(index)
    anchor = np.empty(len(x), dtype=np.int32)
    for a in np.unique(index):
        nodes = np.flatnonzero(index == a)
        distance = np.linalg.norm(x[nodes] - x[nodes].mean(axis=0), axis=1)
        anchor[nodes] = nodes[int(np.argmin(distance))]
    return anchor
