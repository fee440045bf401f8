"""Raw tet meshes of the primitive objects, in the object frame (metres, y up, resting on
y = 0, centred at x = z = 0). Each builder returns (nodes [N,3] float64, tets [M,4] int64);
:func:`finalize_mesh` orients, cleans and verifies them.

``resolution`` is the target MEAN tet edge length (metres). Each mesher converts it to its own
lattice spacing h by the mean edge length of its interior elements:
BCC lattice (sphere): h = 1.098 res (edges h and 0.866 h); Kuhn grid (cuboid):
h = res / 1.260 (edges h, 1.414 h, 1.732 h); swept prisms (cylinder, torus, rope):
h = res / 1.161 (edges h and 1.414 h).
"""

from __future__ import annotations

import math

import numpy as np

from ._checks import check_node_budget
from .lattice import kuhn_grid
from .sdf import sphere_implicit
from .stuffing import stuff_implicit
from .sweep import disk_mesh, ring_counts, sweep_prisms

__all__ = [
    "BCC_SPACING_PER_EDGE", "KUHN_SPACING_PER_EDGE", "SWEEP_SPACING_PER_EDGE",
    "MIN_CIRCLE_SEGMENTS", "cuboid_tets", "sphere_tets", "cylinder_tets", "torus_tets",
    "rope_tets",
]

BCC_SPACING_PER_EDGE = 6.0 / (2.0 + 2.0 * math.sqrt(3.0))
KUHN_SPACING_PER_EDGE = 6.0 / (3.0 + 2.0 * math.sqrt(2.0) + math.sqrt(3.0))
SWEEP_SPACING_PER_EDGE = 18.0 / (11.0 + 7.0 * math.sqrt(2.0))
# Circles are polygons of at least this many nodes (area deficit <= 2.6 %).
MIN_CIRCLE_SEGMENTS = 16


def cuboid_tets(size: tuple[float, float, float], resolution: float):
    """Box of ``size`` (sx, sy, sz) metres on a Kuhn grid; faces exactly planar, bottom at y = 0."""
    h = resolution * KUHN_SPACING_PER_EDGE
    cells = tuple(max(1, int(round(s / h))) for s in size)
    check_node_budget(math.prod(c + 1 for c in cells), h)
    return kuhn_grid(size, cells)


def sphere_tets(radius: float, resolution: float):
    """Ball of ``radius`` metres by isosurface stuffing on a BCC lattice with a node at the
    centre, so that the poles (0, 0, 0) and (0, 2 radius, 0) are nodes."""
    nodes, tets = stuff_implicit(sphere_implicit(radius), resolution * BCC_SPACING_PER_EDGE)
    nodes[:, 1] += radius  # centre at height radius; exact for the poles
    return nodes, tets


def _disk(radius: float, resolution: float, extent: float):
    h = resolution * SWEEP_SPACING_PER_EDGE
    counts = ring_counts(radius, h, MIN_CIRCLE_SEGMENTS)
    check_node_budget((1 + sum(counts)) * int(extent / h + 2), h)
    return disk_mesh(radius, counts), h


def cylinder_tets(radius: float, height: float, resolution: float):
    """Standing cylinder (axis y) of ``radius`` and ``height`` metres, y in [0, height]
    (caps exactly flat), circular side with nodes on the true circle."""
    (pts, tris), h = _disk(radius, resolution, height)
    layers = max(1, int(round(height / h)))
    ys = height * (np.arange(layers + 1) / layers)
    nodes = np.empty((layers + 1, len(pts), 3))
    nodes[:, :, 0] = pts[None, :, 0]
    nodes[:, :, 1] = ys[:, None]
    nodes[:, :, 2] = pts[None, :, 1]
    return nodes.reshape(-1, 3), sweep_prisms(tris, len(pts), layers, closed=False)


def rope_tets(length: float, radius: float, resolution: float):
    """Rope lying along x: a cylinder of ``radius`` with flat ends at x = +-length/2, axis at
    height ``radius`` (a line of nodes touches the ground)."""
    (pts, tris), h = _disk(radius, resolution, length)
    layers = max(1, int(round(length / h)))
    xs = length * (np.arange(layers + 1) / layers - 0.5)
    nodes = np.empty((layers + 1, len(pts), 3))
    nodes[:, :, 0] = xs[:, None]
    nodes[:, :, 1] = pts[None, :, 1] + radius
    nodes[:, :, 2] = pts[None, :, 0]
    return nodes.reshape(-1, 3), sweep_prisms(tris, len(pts), layers, closed=False)


def torus_tets(major_radius: float, minor_radius: float, resolution: float):
    """Torus lying flat (axis y): tube of ``minor_radius`` around the circle of
    ``major_radius`` in the plane y = minor_radius; the circles are polygons with nodes on the
    true surface."""
    (pts, tris), h = _disk(minor_radius, resolution, 2.0 * math.pi * major_radius)
    seg = max(MIN_CIRCLE_SEGMENTS, math.ceil(2.0 * math.pi * major_radius / h - 1e-9))
    seg = 4 * math.ceil(seg / 4)
    phi = 2.0 * math.pi * np.arange(seg) / seg
    rho = major_radius + pts[:, 0]
    nodes = np.empty((seg, len(pts), 3))
    nodes[:, :, 0] = np.cos(phi)[:, None] * rho[None, :]
    nodes[:, :, 1] = pts[None, :, 1] + minor_radius
    nodes[:, :, 2] = np.sin(phi)[:, None] * rho[None, :]
    return nodes.reshape(-1, 3), sweep_prisms(tris, len(pts), seg, closed=True)
