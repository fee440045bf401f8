"""Tetrahedral meshing of the objects to pick up (pure numpy + trimesh; no GPL code).

Public API::

    from defgrasp_env.sim.meshing import (
        TetMesh, MeshQuality, OBJECT_SHAPES, make_object_mesh, mesh_from_surface)

    mesh = make_object_mesh("sphere")                      # default size and resolution
    mesh = make_object_mesh("cylinder", resolution=0.004, radius=0.015, height=0.05)
    mesh = mesh_from_surface("part.stl", resolution=0.005)  # any watertight surface, metres

Every mesh is in the OBJECT frame: metres, y up, resting on the ground (min y == 0), bounding
box centred at x = z = 0; tets positively oriented; ``surface`` = exactly the boundary faces,
wound outward. ``resolution`` is the target mean tet edge length in metres. Meshing is
deterministic: the same input gives bit-identical arrays.

Methods: cuboid - structured Kuhn grid; cylinder, rope, torus - swept ring-disk prisms;
sphere and user surfaces - isosurface stuffing on a BCC lattice (Labelle & Shewchuk 2007).
"""

from .from_surface import mesh_from_surface
from .quality import MeshQuality
from .shapes import OBJECT_SHAPES, ObjectShape, make_object_mesh
from .tetmesh import TetMesh

__all__ = [
    "TetMesh",
    "MeshQuality",
    "OBJECT_SHAPES",
    "ObjectShape",
    "make_object_mesh",
    "mesh_from_surface",
]
