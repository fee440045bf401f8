"""Regular background lattices split into tetrahedra (pure numpy, deterministic).

* :func:`bcc_lattice` - body-centred cubic (BCC) lattice: cube-corner nodes plus cube-centre
  nodes; each pair of face-adjacent cube centres spans 4 tets with the 4 edges of the shared
  square (12 tets per cube, all congruent, dihedral angles 60 and 90 deg). Long edges
  (corner-corner or centre-centre, length h) and short edges (corner-centre, length
  sqrt(3)/2 h) are told apart by :attr:`BCCLattice.num_corner`.
* :func:`kuhn_grid` - a box split into nx*ny*nz cells, each cut into the 6 Kuhn
  (Freudenthal) tets around its main diagonal; faces conform across cells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import permutations

import numpy as np

from ._checks import check_node_budget

__all__ = ["BCCLattice", "bcc_lattice", "kuhn_grid"]


@dataclass(frozen=True)
class BCCLattice:
    """Nodes of a BCC lattice; :meth:`tets` lists its tetrahedra.

    Attributes:
        nodes: [N,3] float64 positions, metres; the first ``num_corner`` are cube corners
            (C-order over the (cells+1) corner grid), the rest cube centres (C-order).
        num_corner: number of corner nodes.
        cells: (cx, cy, cz) number of cubes per axis.
        spacing: cube edge length h, metres.
    """

    nodes: np.ndarray
    num_corner: int
    cells: tuple[int, int, int]
    spacing: float

    def tets(self, keep: np.ndarray | None = None) -> np.ndarray:
        """[M,4] int64 lattice tets (orientation not normalised), in a fixed order.

        Args:
            keep: optional [N] bool node mask; only tets with at least one kept node are
                returned (saves memory when most of the lattice is outside the solid).
        """
        cells = self.cells
        cid = _grid_index((cells[0] + 1, cells[1] + 1, cells[2] + 1))
        zid = _grid_index(cells) + self.num_corner
        blocks = []
        for d in range(3):
            a, b = [x for x in range(3) if x != d]
            # cells c and c + e_d, both inside the grid
            sl_lo = [slice(None)] * 3
            sl_hi = [slice(None)] * 3
            sl_lo[d] = slice(0, cells[d] - 1)
            sl_hi[d] = slice(1, cells[d])
            c0 = zid[tuple(sl_lo)].ravel()
            c1 = zid[tuple(sl_hi)].ravel()
            # corners of the shared face: index i_d + 1 along d, {i, i+1} along a and b
            quad = []
            for oa, ob in ((0, 0), (1, 0), (1, 1), (0, 1)):
                sl = [slice(None)] * 3
                sl[d] = slice(1, cells[d])
                sl[a] = slice(oa, oa + cells[a])
                sl[b] = slice(ob, ob + cells[b])
                quad.append(cid[tuple(sl)].ravel())
            for e in range(4):
                block = np.stack([c0, c1, quad[e], quad[(e + 1) % 4]], axis=1)
                if keep is not None:
                    block = block[np.any(keep[block], axis=1)]
                blocks.append(block)
        return np.concatenate(blocks, axis=0)


def _grid_index(shape: tuple[int, int, int]) -> np.ndarray:
    return np.arange(shape[0] * shape[1] * shape[2], dtype=np.int64).reshape(shape)


def bcc_lattice(lo: np.ndarray, hi: np.ndarray, spacing: float, origin: np.ndarray) -> BCCLattice:
    """BCC lattice of cube size ``spacing`` covering the box [lo, hi] with one cube of margin.

    Args:
        lo, hi: [3] box corners, metres.
        spacing: cube edge length h > 0, metres.
        origin: [3] a point that is a corner node (e.g. a sphere centre, so that the lattice
            has nodes on the sphere's axes).
    Raises:
        ValueError: more than MAX_LATTICE_NODES nodes would be needed.
    """
    lo, hi, origin = (np.asarray(v, dtype=np.float64) for v in (lo, hi, origin))
    i0 = np.floor((lo - origin) / spacing).astype(np.int64) - 1
    i1 = np.ceil((hi - origin) / spacing).astype(np.int64) + 1
    cells = tuple(int(c) for c in (i1 - i0))
    n_corner = math.prod(c + 1 for c in cells)
    check_node_budget(n_corner + math.prod(cells), spacing)
    axes = [origin[d] + np.arange(i0[d], i1[d] + 1) * spacing for d in range(3)]
    corner = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    centre_axes = [origin[d] + (np.arange(i0[d], i1[d]) + 0.5) * spacing for d in range(3)]
    centre = np.stack(np.meshgrid(*centre_axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return BCCLattice(
        nodes=np.concatenate([corner, centre], axis=0),
        num_corner=n_corner,
        cells=cells,
        spacing=float(spacing),
    )


def kuhn_grid(size: tuple[float, float, float], cells: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Structured tet mesh of the box [-sx/2, sx/2] x [0, sy] x [-sz/2, sz/2].

    Args:
        size: (sx, sy, sz) box size, metres.
        cells: (nx, ny, nz) >= 1 cells per axis.
    Returns:
        nodes [(nx+1)(ny+1)(nz+1), 3] float64 metres (the faces lie exactly on x = +-sx/2,
        y = 0, y = sy, z = +-sz/2), tets [6*nx*ny*nz, 4] int64 (orientation not normalised).
    """
    n = [int(c) for c in cells]
    xs = [(2 * np.arange(n[0] + 1) - n[0]) / (2 * n[0]) * size[0],
          np.arange(n[1] + 1) / n[1] * size[1],
          (2 * np.arange(n[2] + 1) - n[2]) / (2 * n[2]) * size[2]]
    nodes = np.stack(np.meshgrid(*xs, indexing="ij"), axis=-1).reshape(-1, 3)
    gid = _grid_index((n[0] + 1, n[1] + 1, n[2] + 1))

    def corner(off: tuple[int, int, int]) -> np.ndarray:
        return gid[off[0]:off[0] + n[0], off[1]:off[1] + n[1], off[2]:off[2] + n[2]].ravel()

    blocks = []
    for perm in permutations(range(3)):
        path = [(0, 0, 0)]
        for axis in perm:
            step = list(path[-1])
            step[axis] = 1
            path.append(tuple(step))
        blocks.append(np.stack([corner(p) for p in path], axis=1))
    return nodes, np.concatenate(blocks, axis=0)
