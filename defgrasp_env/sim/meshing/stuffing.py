"""Isosurface stuffing: tetrahedral meshing of an implicit solid on a BCC lattice.

Algorithm after Labelle & Shewchuk, "Isosurface Stuffing: Fast Tetrahedral Meshes with Good
Dihedral Angles" (SIGGRAPH 2007), written from the paper (no third-party code):

1. Classify BCC lattice nodes as inside (+), on (0) or outside (-) the solid.
2. Every lattice edge with a + and a - end gets a *cut point* where it crosses the surface.
3. Warping: a node closer to a cut point on one of its edges than alpha * edge length
   (alpha_long = 0.24999 on long edges, alpha_short = 0.41189 on short ones) is moved onto the
   nearest such cut point and becomes 0; cut points on its edges disappear. Nodes are
   processed in index order, so the result is deterministic.
4. Every lattice tet is replaced by its inside part, from a stencil per sign pattern. Quads
   that stencils share with a neighbour are split by the diagonal through their
   lowest-numbered vertex (cut points are numbered after lattice nodes), and prisms are cut
   into 3 tets by the same rule (Dompierre et al. 1999), so the result is conforming.

Units: metres. Output: nodes [N,3] float64, tets [M,4] int64 (orientation not normalised;
unreferenced nodes not removed - :func:`finalize_mesh` does both).
"""

from __future__ import annotations

import numpy as np

from .lattice import bcc_lattice
from .sdf import Implicit
from .surface import unique_rows

__all__ = ["stuff_implicit", "ALPHA_LONG", "ALPHA_SHORT"]

ALPHA_LONG = 0.24999
ALPHA_SHORT = 0.41189
_TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])


def _warp(nodes, sign, edges, cut_pts, is_long) -> None:
    """Snap violated lattice nodes onto their nearest cut point (in place, index order)."""
    length = np.linalg.norm(nodes[edges[:, 1]] - nodes[edges[:, 0]], axis=1)
    alpha = np.where(is_long, ALPHA_LONG, ALPHA_SHORT) * length
    ends = np.concatenate([edges[:, 0], edges[:, 1]])
    dist = np.concatenate(
        [np.linalg.norm(cut_pts - nodes[edges[:, 0]], axis=1),
         np.linalg.norm(cut_pts - nodes[edges[:, 1]], axis=1)]
    )
    eid = np.tile(np.arange(len(edges)), 2)
    viol = dist < np.tile(alpha, 2)
    ends, dist, eid = ends[viol], dist[viol], eid[viol]
    order = np.lexsort((eid, dist, ends))  # by node, then distance, then edge id
    ends, dist, eid = ends[order], dist[order], eid[order]
    if len(ends) == 0:
        return
    starts = np.flatnonzero(np.r_[True, ends[1:] != ends[:-1]])
    stops = np.r_[starts[1:], len(ends)]
    e0, e1 = edges[:, 0], edges[:, 1]
    for s, t in zip(starts.tolist(), stops.tolist()):
        v = int(ends[s])
        for k in range(s, t):  # candidates sorted by distance
            e = int(eid[k])
            if sign[e0[e]] * sign[e1[e]] < 0:  # cut point still alive
                nodes[v] = cut_pts[e]
                sign[v] = 0
                break


def _prism_tets(p: np.ndarray) -> np.ndarray:
    """Split prisms p [K,6] (triangles 0,1,2 and 3,4,5 with i <-> i+3; p[:,0] is the smallest
    vertex id of the prism) into 3 tets each, quads split through their smallest vertex."""
    d15 = np.minimum(p[:, 1], p[:, 5]) < np.minimum(p[:, 2], p[:, 4])
    a = np.where(d15[:, None], p[:, [0, 1, 2, 5]], p[:, [0, 1, 2, 4]])
    b = np.where(d15[:, None], p[:, [0, 1, 5, 4]], p[:, [0, 4, 2, 5]])
    c = p[:, [0, 4, 5, 3]]
    return np.concatenate([a, b, c], axis=0)


def _rotate_min_first(p: np.ndarray, rotations: list[list[int]]) -> np.ndarray:
    """Relabel each prism by the first rotation that puts its smallest id at position 0."""
    out = p.copy()
    for rot in rotations[::-1]:
        r = p[:, rot]
        hit = r[:, 0] == p.min(axis=1)
        out[hit] = r[hit]
    return out


def stuff_implicit(solid: Implicit, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Tet-mesh ``solid`` with a BCC lattice of cube size ``spacing`` (metres).

    Returns raw (nodes [N,3] float64, tets [M,4] int64); see the module docstring.
    """
    lat = bcc_lattice(solid.lo, solid.hi, spacing, solid.origin)
    nodes = lat.nodes.copy()
    nv = len(nodes)
    sign = solid.classify(nodes).astype(np.int8)
    tets = lat.tets(keep=sign >= 0)
    if len(tets) == 0:
        return nodes, np.zeros((0, 4), np.int64)
    edges = unique_rows(np.sort(tets[:, _TET_EDGES].reshape(-1, 2), axis=1))[0]
    edges = edges[sign[edges[:, 0]].astype(np.int16) * sign[edges[:, 1]] < 0]
    inside_first = sign[edges[:, 0]] > 0
    p_in = np.where(inside_first, edges[:, 0], edges[:, 1])
    p_out = np.where(inside_first, edges[:, 1], edges[:, 0])
    cut_pts = solid.crossings(nodes[p_in], nodes[p_out])
    is_long = (edges[:, 0] < lat.num_corner) == (edges[:, 1] < lat.num_corner)
    _warp(nodes, sign, edges, cut_pts, is_long)

    alive = sign[edges[:, 0]].astype(np.int16) * sign[edges[:, 1]] < 0
    edges, cut_pts = edges[alive], cut_pts[alive]
    keys = edges[:, 0] * nv + edges[:, 1]

    def cut(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        k = np.minimum(a, b) * nv + np.maximum(a, b)
        return nv + np.searchsorted(keys, k)

    s = sign[tets]
    order = np.argsort(-s, axis=1, kind="stable")
    v = np.take_along_axis(tets, order, axis=1)
    s = np.take_along_axis(s, order, axis=1)
    n_p = (s > 0).sum(axis=1)
    n_z = (s == 0).sum(axis=1)
    n_m = (s < 0).sum(axis=1)
    out = [v[(n_m == 0) & (n_p > 0)]]
    zero = v[n_z == 4]
    if len(zero):
        centroid = nodes[zero].mean(axis=1)
        out.append(zero[solid.classify(centroid) > 0])

    def pick(np_, nz_, nm_):
        return v[(n_p == np_) & (n_z == nz_) & (n_m == nm_)].T

    v0, v1, v2, v3 = pick(1, 0, 3)
    out.append(np.stack([v0, cut(v0, v1), cut(v0, v2), cut(v0, v3)], axis=1))
    v0, v1, v2, v3 = pick(1, 1, 2)
    out.append(np.stack([v0, v1, cut(v0, v2), cut(v0, v3)], axis=1))
    v0, v1, v2, v3 = pick(1, 2, 1)
    out.append(np.stack([v0, v1, v2, cut(v0, v3)], axis=1))
    v0, v1, v2, v3 = pick(2, 1, 1)  # pyramid: apex v2, quad v0 v1 c1 c0
    c0, c1 = cut(v0, v3), cut(v1, v3)
    lo0 = (v0 < v1)[:, None]
    out.append(np.where(lo0, np.stack([v2, v0, v1, c1], 1), np.stack([v2, v0, v1, c0], 1)))
    out.append(np.where(lo0, np.stack([v2, v0, c1, c0], 1), np.stack([v2, v1, c1, c0], 1)))
    v0, v1, v2, v3 = pick(3, 0, 1)  # prism v0 v1 v2 / c0 c1 c2
    prism = np.stack([v0, v1, v2, cut(v0, v3), cut(v1, v3), cut(v2, v3)], axis=1)
    prism = _rotate_min_first(prism, [[0, 1, 2, 3, 4, 5], [1, 2, 0, 4, 5, 3], [2, 0, 1, 5, 3, 4]])
    out.append(_prism_tets(prism))
    v0, v1, v2, v3 = pick(2, 0, 2)  # prism v0 c02 c03 / v1 c12 c13
    prism = np.stack([v0, cut(v0, v2), cut(v0, v3), v1, cut(v1, v2), cut(v1, v3)], axis=1)
    prism = _rotate_min_first(prism, [[0, 1, 2, 3, 4, 5], [3, 4, 5, 0, 1, 2]])
    out.append(_prism_tets(prism))
    return np.concatenate([nodes, cut_pts], axis=0), np.concatenate(out, axis=0)
