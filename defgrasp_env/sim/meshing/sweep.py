"""Structured tet meshes of solids swept from a disk: cylinders (straight sweep) and tori
(closed circular sweep). Pure numpy, deterministic.

The cross-section is a disk of concentric node rings (centre node + rings at radii k R / n);
its boundary ring lies exactly on the circle of radius R. Each triangle swept between two
consecutive stations is a prism cut into 3 tets; the quad faces are split by the diagonal
from the higher-numbered node of the lower station to the lower-numbered node of the upper
station, which depends only on the two cross-section node ids, so neighbouring prisms agree.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["disk_mesh", "sweep_prisms", "ring_counts"]


def ring_counts(radius: float, spacing: float, min_segments: int) -> list[int]:
    """Node counts of the rings 1..n of a disk of ``radius`` meshed at ``spacing`` (metres).

    n = max(1, round(radius / spacing)) rings; the boundary ring gets
    max(min_segments, 6 n, ceil(2 pi radius / spacing)) nodes rounded up to a multiple of 4
    (so that there are nodes at the bottom, top and sides); ring k gets about k/n of that.
    """
    n = max(1, int(round(radius / spacing)))
    m = max(min_segments, 6 * n, math.ceil(2.0 * math.pi * radius / spacing - 1e-9))
    m = 4 * math.ceil(m / 4)
    return [max(4, 4 * int(round(m * k / (4 * n)))) if k < n else m for k in range(1, n + 1)]


def disk_mesh(radius: float, counts: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Triangulated disk of ``radius`` metres centred at (0, 0).

    Args:
        radius: disk radius, metres.
        counts: nodes on rings 1..n (ring k has radius k * radius / n); every ring has a node at
            angle -pi/2 (the bottom) and is symmetric about the vertical axis.
    Returns:
        points [P,2] float64 metres (node 0 is the centre, the last ``counts[-1]`` nodes lie on
        the circle), tris [T,3] int64 counter-clockwise.
    """
    n = len(counts)
    pts = [np.zeros((1, 2))]
    first = [0]
    ang = []
    for k, m in enumerate(counts, start=1):
        th = -0.5 * math.pi + 2.0 * math.pi * np.arange(m) / m
        r = radius if k == n else radius * k / n
        pts.append(np.stack([r * np.cos(th), r * np.sin(th)], axis=1))
        first.append(first[-1] + (1 if k == 1 else counts[k - 2]))
        ang.append(np.arange(m) / m)  # angle as a fraction of a turn from the bottom
    tris = []
    # ring 1 fans around the centre
    m1 = counts[0]
    for i in range(m1):
        tris.append((0, first[1] + i, first[1] + (i + 1) % m1))
    # band between ring k-1 (inner) and ring k (outer): advance the side whose next node
    # comes first in angle (ties advance the inner ring)
    for k in range(2, n + 1):
        a_in, a_out = ang[k - 2], ang[k - 1]
        mi, mo = len(a_in), len(a_out)
        i = j = 0
        while i < mi or j < mo:
            next_in = a_in[i + 1] if i + 1 < mi else 1.0
            next_out = a_out[j + 1] if j + 1 < mo else 1.0
            vi, vo = first[k - 1] + i % mi, first[k] + j % mo
            if j < mo and (i >= mi or next_out < next_in - 1e-12):
                tris.append((vi, vo, first[k] + (j + 1) % mo))
                j += 1
            else:
                tris.append((vi, vo, first[k - 1] + (i + 1) % mi))
                i += 1
    return np.concatenate(pts, axis=0), np.asarray(tris, dtype=np.int64)


def sweep_prisms(tris: np.ndarray, num_points: int, num_layers: int, closed: bool) -> np.ndarray:
    """Tets of a disk triangulation swept through stations 0..S-1.

    Node id of cross-section point p at station s is s * num_points + p. With ``closed`` the
    last layer joins station num_layers - 1 back to station 0 (S = num_layers), otherwise
    S = num_layers + 1.

    Returns:
        [3 * T * num_layers, 4] int64 tets (orientation not normalised).
    """
    a, b, c = np.sort(tris, axis=1).T
    s = np.arange(num_layers, dtype=np.int64)[:, None]
    s1 = (s + 1) % num_layers if closed else s + 1
    lo, hi = s * num_points, s1 * num_points

    def tet(p, q, r, u):
        return np.stack([p, q, r, u], axis=-1).reshape(-1, 4)

    return np.concatenate([
        tet(lo + a, lo + b, lo + c, hi + a),
        tet(lo + b, lo + c, hi + a, hi + b),
        tet(lo + c, hi + a, hi + b, hi + c),
    ])
