"""Geometry of the pad edge contact (``kernels/pad_edge_contact.py``): the sample points along each
pad box's edges, and the objects' surface triangles."""

from __future__ import annotations

import math

import numpy as np

from .model import Model

#: Largest distance (m) between neighbouring sample points along a pad box edge: a fraction of the
#: objects' surface edges (3-12 mm), so an edge pressed into a face meets each triangle at several points.
EDGE_POINT_SPACING = 1.5e-3


def pad_edge_points(half_extents: np.ndarray, spacing: float = EDGE_POINT_SPACING
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sample points on the 12 edges of each of P pad boxes with half extents ``half_extents`` [P, 3]
    (m), at most ``spacing`` (m) apart along an edge, each box corner once.

    Returns the points [Q, 3] float32 in unit box coordinates (in [-1, 1]^3, two of them +-1: the
    point in the pad's frame is that times the half extents), the pad index of each point [Q]
    int32, the length of edge each point stands for [Q] float32 (m: its edge's sample spacing), and
    the first point of each pad [P + 1] int32 (pad k's points are ``first[k]:first[k + 1]``)."""
    half = np.asarray(half_extents, dtype=np.float64).reshape(-1, 3)
    points, pads, shares, first = [], [], [], [0]
    for k, h in enumerate(half):
        for axis in range(3):
            count = max(2, math.ceil(2.0 * h[axis] / spacing) + 1)
            along = np.linspace(-1.0, 1.0, count)
            if axis != 0:  # the corners are on the x edges
                along = along[1:-1]
            others = [j for j in range(3) if j != axis]
            for sb in (-1.0, 1.0):
                for sc in (-1.0, 1.0):
                    p = np.zeros((len(along), 3))
                    p[:, axis] = along
                    p[:, others[0]] = sb
                    p[:, others[1]] = sc
                    points.append(p)
                    pads.append(np.full(len(along), k))
                    shares.append(np.full(len(along), 2.0 * h[axis] / (count - 1)))
        first.append(sum(len(p) for p in points))
    return (np.concatenate(points).astype(np.float32), np.concatenate(pads).astype(np.int32),
            np.concatenate(shares).astype(np.float32), np.asarray(first, dtype=np.int32))


def world_surface_triangles(model: Model, w: int) -> np.ndarray:
    """World ``w``'s boundary triangles (``Model.surfaces``, outward by the right-hand rule) as
    global node ids [S, 3] int32; in a slotted model (``Model.triangle_slot``) padded to the slot
    with spare triangles naming the world's first spare node three times (zero area, zero solid
    angle, 1 km from the task: no point's nearest triangle)."""
    tris = np.asarray(model.surfaces[w], dtype=np.int64).reshape(-1, 3) + int(model.node_start[w])
    if model.triangle_slot:
        if len(tris) > model.triangle_slot:
            raise ValueError(f"world {w} has {len(tris)} surface triangles, more than its slot's {model.triangle_slot}")
        spare = np.full((model.triangle_slot - len(tris), 3), int(model.node_end[w]))
        tris = np.concatenate([tris, spare])
    return tris.astype(np.int32)


def surface_triangles(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """Every world's ``world_surface_triangles`` [T, 3] int32, and the world of each [T] int32."""
    tris = [world_surface_triangles(model, w) for w in range(model.num_worlds)]
    worlds = [np.full(len(t), w) for w, t in enumerate(tris)]
    if not tris:
        return np.zeros((0, 3), np.int32), np.zeros(0, np.int32)
    return np.concatenate(tris).astype(np.int32), np.concatenate(worlds).astype(np.int32)
