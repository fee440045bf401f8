"""Node aggregates of each world: the coarse space of the solver's linear solves.

The CG preconditioner of ``kernels/coarse_space.py`` adds a coarse solve on the piecewise-constant
translations of a few node aggregates per world. A slender object (a rope, a beam), where
block-Jacobi CG is slowest (a correction takes ~ its length in elements of iterations to cross it),
is cut into slices of equal node counts along its length: recursive bisection of the world's rest
nodes at the median along the principal axis of each piece, as long as the piece is at least
``ELONGATION`` times longer along that axis than along the next one. A compact object stays one
aggregate (its rigid translations; measured on the expert's episodes at E = 1e4 and 1e7: cutting
the sphere into 8 pieces cost 14-23 % more CG iterations, the torus 7-8 % fewer; cutting the rope
into 8 slices saved 11-37 %).
The cuts follow the principal axes of the object-frame nodes (``build_model``), so an object is cut
the same way whatever its pose (cutting posed nodes split nodes tied at a cut by float rounding of
the pose, so an episode depended on the pose of the reset that built the scene).
"""

from __future__ import annotations

import numpy as np

#: Aggregates per world at most (a power of two).
AGGREGATES = 8
#: A piece is cut in two while its extent along its principal axis is at least this many times its
#: extent along the second principal axis.
ELONGATION = 2.0


def bisect_nodes(x: np.ndarray, pieces: int = AGGREGATES, elongation: float = ELONGATION) -> np.ndarray:
    """Aggregate index in [0, pieces) of each of the nodes ``x`` [N, 3] (m): ``pieces`` must be a
    power of two; each piece with at least 2 nodes that is ``elongation`` times longer along its
    principal axis than along the second one is split at the median along the principal axis, up
    to ``pieces`` pieces (so indices may be unused; 0 only, for a compact object)."""
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
            axes = np.linalg.eigh(centred.T @ centred)[1]
            extent = np.ptp(centred @ axes[:, 1:], axis=0)   # along the second and the principal axis
            if extent[1] < elongation * extent[0]:
                split += [g, g[:0]]
                continue
            order = g[np.argsort(centred @ axes[:, -1], kind="stable")]
            split += [order[: len(g) // 2], order[len(g) // 2:]]
        groups = split
    index = np.empty(len(x), dtype=np.int32)
    for k, g in enumerate(groups):
        index[g] = k
    return index

