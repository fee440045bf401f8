"""Small structured meshes and set-up helpers for the FEM validation tests (test_fem_*.py).

The object meshes of the library come from ``defgrasp_env.sim.meshing``; the validation tests
also need meshes with an exact number of cells per axis (bars, beams) and a graded octant of a
ball (Hertz contact), which are built here with the plain Kuhn 6-tet split of a hexahedral grid.
Units: metres; the helpers never depend on the solver code they are used to test.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations

import numpy as np

# The 6 Kuhn tets of the unit cube: one per permutation of the axes, each a monotone lattice path
# from corner (0,0,0) to (1,1,1). They share the main diagonal, so neighbouring cells conform.
_KUHN_PATHS = [tuple(p) for p in permutations(range(3))]


@dataclass(frozen=True)
class SimpleMesh:
    """Tet mesh in the form ``build_model`` takes: nodes [N,3] float64 (m), tets [T,4] int32
    (positively oriented), surface [S,3] int32 (boundary triangles wound outward)."""

    nodes: np.ndarray
    tets: np.ndarray
    surface: np.ndarray


def boundary_faces(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Faces used by exactly one tet, wound so that their normal points out of the tet."""
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]])
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return faces[counts[inverse.ravel()] == 1].astype(np.int32)


def orient(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Tets reordered so that det[x1-x0, x2-x0, x3-x0] > 0."""
    tets = np.array(tets, dtype=np.int64)
    x = nodes[tets]
    det = np.linalg.det(np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]], axis=2))
    flip = det < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    return tets


def grid_mesh(xs: np.ndarray, ys: np.ndarray, zs: np.ndarray) -> SimpleMesh:
    """Kuhn-split tet mesh of the tensor grid xs x ys x zs (each strictly increasing, metres)."""
    xs, ys, zs = (np.asarray(a, dtype=np.float64) for a in (xs, ys, zs))
    shape = (len(xs), len(ys), len(zs))
    gx, gy, gz = np.meshgrid(xs, ys, zs, indexing="ij")
    nodes = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)
    index = np.arange(nodes.shape[0]).reshape(shape)
    ci, cj, ck = np.meshgrid(*(np.arange(n - 1) for n in shape), indexing="ij")
    ci, cj, ck = ci.ravel(), cj.ravel(), ck.ravel()
    tets = []
    for path in _KUHN_PATHS:
        corner = np.zeros((len(ci), 3), dtype=np.int64)
        verts = [index[ci, cj, ck]]
        for axis in path:
            corner[:, axis] += 1
            verts.append(index[ci + corner[:, 0], cj + corner[:, 1], ck + corner[:, 2]])
        tets.append(np.stack(verts, axis=1))
    tets = orient(nodes, np.concatenate(tets))
    return SimpleMesh(nodes, tets.astype(np.int32), boundary_faces(nodes, tets))


def box_mesh(size, cells, origin=(0.0, 0.0, 0.0)) -> SimpleMesh:
    """Box [origin, origin + size] (m) split into cells[0] x cells[1] x cells[2] Kuhn cells."""
    axes = [o + s * np.linspace(0.0, 1.0, c + 1) for o, s, c in zip(origin, size, cells)]
    return grid_mesh(*axes)


def jittered(mesh: SimpleMesh, amplitude: float, seed: int = 0) -> SimpleMesh:
    """The mesh with its interior nodes moved randomly by up to ``amplitude`` (m) per axis, so
    that its tets are irregular (boundary nodes stay, so the boundary keeps its shape)."""
    boundary = np.unique(mesh.surface)
    nodes = mesh.nodes.copy()
    rng = np.random.default_rng(seed)
    inner = np.setdiff1d(np.arange(len(nodes)), boundary)
    nodes[inner] += rng.uniform(-amplitude, amplitude, size=(len(inner), 3))
    return SimpleMesh(nodes, orient(nodes, mesh.tets).astype(np.int32), mesh.surface)


def graded_ball_octant(radius: float, cells: int, ratio: float) -> SimpleMesh:
    """Octant x, y, z >= 0 of a ball of ``radius`` (m), fine at the pole (radius, 0, 0).

    A cube grid [0,1]^3, graded geometrically (cell size shrinking by ``ratio`` in total towards
    x = 1 and towards y = 0 and z = 0), is mapped onto the octant by p -> radius p |p|_inf / |p|_2,
    which keeps the symmetry planes x = 0, y = 0, z = 0 in place and puts the face x = 1 on the
    sphere. Surface nodes lie exactly on the sphere.
    """
    def graded(n: int) -> np.ndarray:
        # cell sizes s_k = s_0 q^k, largest / smallest = ratio; nodes from 0 (fine end) to 1
        q = ratio ** (1.0 / max(n - 1, 1))
        sizes = q ** np.arange(n)
        return np.concatenate([[0.0], np.cumsum(sizes) / sizes.sum()])

    fine_at_zero = graded(cells)
    mesh = grid_mesh(1.0 - fine_at_zero[::-1], fine_at_zero, fine_at_zero)
    p = mesh.nodes
    norm2 = np.linalg.norm(p, axis=1)
    scale = np.where(norm2 > 0, np.max(np.abs(p), axis=1) / np.where(norm2 > 0, norm2, 1.0), 0.0)
    nodes = radius * p * scale[:, None]
    tets = orient(nodes, mesh.tets)
    return SimpleMesh(nodes, tets.astype(np.int32), boundary_faces(nodes, tets))


def face_load(mesh: SimpleMesh, axis: int, value: float, traction, tol: float = 1e-9) -> np.ndarray:
    """Consistent nodal forces [N,3] (N) of a uniform traction (Pa, [3]) on the boundary
    triangles lying in the plane X[axis] = value: each triangle gives area/3 to each node, exact
    for linear elements under a uniform traction."""
    forces = np.zeros((len(mesh.nodes), 3))
    tri = mesh.surface
    on = np.all(np.abs(mesh.nodes[tri][:, :, axis] - value) < tol, axis=1)
    x = mesh.nodes[tri[on]]
    area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)
    np.add.at(forces, tri[on].ravel(), np.repeat(area / 3.0, 3)[:, None] * np.asarray(traction, float))
    return forces
