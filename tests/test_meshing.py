"""Tests of defgrasp_env.sim.meshing against independent truths.

Every check recomputes what it verifies with code written here (analytic volumes, boundary
faces by counting, dihedral angles by an edge-projection formula, volumes by determinants and
by the divergence theorem), never with the library's own helpers.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import subprocess
import sys
import textwrap
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import trimesh

from defgrasp_env.sim.meshing import OBJECT_SHAPES, MeshQuality, TetMesh, make_object_mesh, mesh_from_surface
from defgrasp_env.sim.meshing.tetmesh import finalize_mesh

NAMES = ("cuboid", "sphere", "torus", "cylinder", "rope")
DEFAULT_SIZES = {
    "cuboid": {"size": (0.04, 0.04, 0.04)},
    "sphere": {"radius": 0.025},
    "torus": {"major_radius": 0.030, "minor_radius": 0.010},
    "cylinder": {"radius": 0.020, "height": 0.060},
    "rope": {"length": 0.300, "radius": 0.008},
}
FINE = 0.004  # m, the "finer" resolution used for convergence checks


def analytic_volume(name: str, s: dict) -> float:
    if name == "cuboid":
        return float(np.prod(s["size"]))
    if name == "sphere":
        return 4.0 / 3.0 * math.pi * s["radius"] ** 3
    if name == "torus":
        return 2.0 * math.pi**2 * s["major_radius"] * s["minor_radius"] ** 2
    if name == "cylinder":
        return math.pi * s["radius"] ** 2 * s["height"]
    return math.pi * s["radius"] ** 2 * s["length"]


def det_volumes(m: TetMesh) -> np.ndarray:
    x = m.nodes[m.tets]
    return np.linalg.det(np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]], axis=1)) / 6.0


def boundary_by_counting(tets: np.ndarray) -> set[tuple[int, ...]]:
    c = Counter()
    for t in tets.tolist():
        for f in ((t[0], t[1], t[2]), (t[0], t[1], t[3]), (t[0], t[2], t[3]), (t[1], t[2], t[3])):
            c[tuple(sorted(f))] += 1
    assert max(c.values()) <= 2
    return {f for f, n in c.items() if n == 1}


def min_dihedral_edge_formula(m: TetMesh) -> float:
    """Dihedral angle at edge (i, j): angle between the other two vertices projected on the
    plane normal to the edge."""
    x, worst = m.nodes[m.tets], 180.0
    for i, j, k, l in ((0, 1, 2, 3), (0, 2, 1, 3), (0, 3, 1, 2), (1, 2, 0, 3), (1, 3, 0, 2), (2, 3, 0, 1)):
        e = x[:, j] - x[:, i]
        e /= np.linalg.norm(e, axis=1, keepdims=True)
        u, w = x[:, k] - x[:, i], x[:, l] - x[:, i]
        u -= np.sum(u * e, axis=1, keepdims=True) * e
        w -= np.sum(w * e, axis=1, keepdims=True) * e
        cos = np.sum(u * w, axis=1) / np.linalg.norm(u, axis=1) / np.linalg.norm(w, axis=1)
        worst = min(worst, float(np.degrees(np.arccos(np.clip(cos, -1, 1))).min()))
    return worst


def surface_euler(surface: np.ndarray) -> tuple[int, Counter]:
    edges = Counter()
    for a, b, c in surface.tolist():
        for p, q in ((a, b), (b, c), (c, a)):
            edges[(min(p, q), max(p, q))] += 1
    verts = len(set(surface.ravel().tolist()))
    return verts - len(edges) + len(surface), edges


@pytest.fixture(scope="module")
def defaults() -> dict[str, TetMesh]:
    return {n: make_object_mesh(n) for n in NAMES}


@pytest.fixture(scope="module")
def fines() -> dict[str, TetMesh]:
    return {n: make_object_mesh(n, resolution=FINE) for n in NAMES}


@pytest.fixture(scope="module")
def finest() -> dict[str, TetMesh]:
    """1.5 mm meshes (~1.7-2.4e5 tets each; the sphere is the one for Hertz contact tests)."""
    return {n: make_object_mesh(n, resolution=0.0015) for n in NAMES}


def all_meshes(defaults, fines):
    return [(f"{n}-default", m) for n, m in defaults.items()] + [(f"{n}-fine", m) for n, m in fines.items()]


# ---------------------------------------------------------------- registry and defaults
def test_registry_is_one_read_only_mapping_of_frozen_specs():
    assert set(OBJECT_SHAPES) == set(NAMES)
    with pytest.raises(TypeError):
        OBJECT_SHAPES["blob"] = OBJECT_SHAPES["sphere"]  # type: ignore[index]
    spec = OBJECT_SHAPES["sphere"]
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.default_resolution = 1.0  # type: ignore[misc]
    for name in NAMES:
        assert dict(OBJECT_SHAPES[name].defaults) == DEFAULT_SIZES[name]


def test_default_objects_are_small_and_fit_the_gripper(defaults):
    for name, m in defaults.items():
        print(f"{name}: {m.num_nodes} nodes, {m.num_tets} tets, {m.num_surface_tris} tris")
        assert 300 <= m.num_tets <= 1600, name
        ext = m.nodes.max(axis=0) - m.nodes.min(axis=0)
        assert min(ext[0], ext[2]) <= 0.085, name  # fits the 85 mm stroke one way
        assert m.nodes.dtype == np.float64 and m.tets.dtype == np.int32 and m.surface.dtype == np.int32


# ---------------------------------------------------------------- geometry vs analytic truth
def test_volume_matches_analytic_and_converges(defaults, fines, finest):
    for name in NAMES:
        true = analytic_volume(name, DEFAULT_SIZES[name])
        err = [abs(det_volumes(m[name]).sum() / true - 1.0) for m in (defaults, fines, finest)]
        print(f"{name}: volume error " + ", ".join(f"{100 * e:.2f} %" for e in err)
              + " (default, 4 mm, 1.5 mm)")
        # nodes lie on the true surface and chords cut it: a few % at ~3 tets per radius,
        # falling as the chords shrink (circles have >= 16 segments, so the rope's cross-section
        # only refines below ~3 mm)
        assert err[0] < 0.04, name
        assert err[1] <= err[0] + 1e-12 and err[2] <= err[1] + 1e-12, name
        assert err[2] < 0.008, name
        if name != "cuboid":
            assert err[2] < 0.5 * err[0], name


def test_surface_nodes_lie_on_the_true_surface(defaults, fines):
    for m in (defaults, fines):
        p = m["sphere"].nodes[np.unique(m["sphere"].surface)]
        np.testing.assert_allclose(np.linalg.norm(p - [0, 0.025, 0], axis=1), 0.025, rtol=1e-12)
        p = m["torus"].nodes[np.unique(m["torus"].surface)]
        d = np.hypot(np.hypot(p[:, 0], p[:, 2]) - 0.03, p[:, 1] - 0.01)
        np.testing.assert_allclose(d, 0.01, rtol=1e-12)
        p = m["cylinder"].nodes[np.unique(m["cylinder"].surface)]
        cap = (p[:, 1] == 0.0) | (p[:, 1] == 0.06)
        np.testing.assert_allclose(np.hypot(p[~cap, 0], p[~cap, 2]), 0.02, rtol=1e-12)
        assert np.all(np.hypot(p[:, 0], p[:, 2]) <= 0.02 * (1 + 1e-12))
        p = m["rope"].nodes[np.unique(m["rope"].surface)]
        end = np.abs(p[:, 0]) == 0.15
        np.testing.assert_allclose(np.hypot(p[~end, 1] - 0.008, p[~end, 2]), 0.008, rtol=1e-12)
        p = m["cuboid"].nodes[np.unique(m["cuboid"].surface)]
        on_face = (np.abs(p[:, 0]) == 0.02) | (p[:, 1] == 0.0) | (p[:, 1] == 0.04) | (np.abs(p[:, 2]) == 0.02)
        assert np.all(on_face)


def test_flat_faces_are_exactly_flat_and_sphere_has_exact_poles(defaults, fines, finest):
    for m in (defaults["cylinder"], fines["cylinder"], defaults["cuboid"], fines["cuboid"]):
        tri_y = m.nodes[m.surface][:, :, 1]
        bottom = np.all(tri_y < 1e-9, axis=1)
        assert bottom.sum() >= 8 and np.all(tri_y[bottom] == 0.0)
        top = np.all(tri_y > tri_y.max() - 1e-9, axis=1)
        assert top.sum() >= 8 and np.all(tri_y[top] == tri_y.max())
    for m in (defaults["sphere"], fines["sphere"], finest["sphere"]):
        rows = {tuple(r) for r in m.nodes.tolist()}
        assert (0.0, 0.0, 0.0) in rows and (0.0, 0.05, 0.0) in rows


def test_resting_frame(defaults, fines):
    for label, m in all_meshes(defaults, fines):
        lo, hi = m.nodes.min(axis=0), m.nodes.max(axis=0)
        assert lo[1] == 0.0, label
        assert abs(lo[0] + hi[0]) < 1e-15 and abs(lo[2] + hi[2]) < 1e-15, label
    ext = {n: defaults[n].nodes.max(axis=0) for n in NAMES}
    np.testing.assert_allclose(ext["rope"], [0.15, 0.016, 0.008], rtol=1e-12)  # along x
    np.testing.assert_allclose(ext["cylinder"], [0.02, 0.06, 0.02], rtol=1e-12)  # axis y
    np.testing.assert_allclose(ext["torus"], [0.04, 0.02, 0.04], rtol=1e-12)  # flat


# ---------------------------------------------------------------- topology and orientation
def test_surface_is_exactly_the_outward_boundary(defaults, fines):
    for label, m in all_meshes(defaults, fines):
        faces = boundary_by_counting(m.tets)
        surf = [tuple(sorted(t)) for t in m.surface.tolist()]
        assert len(surf) == len(set(surf)) and set(surf) == faces, label
        # outward: the owning tet's fourth vertex lies behind the triangle
        owner = {}
        for t in m.tets.tolist():
            for skip in range(4):
                f = tuple(sorted(t[:skip] + t[skip + 1 :]))
                if f in faces:
                    owner[f] = t[skip]
        x = m.nodes[m.surface]
        n = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
        opp = m.nodes[[owner[f] for f in surf]]
        assert np.all(np.sum(n * (opp - x[:, 0]), axis=1) < 0.0), label


def test_surface_is_closed_manifold_with_right_euler_characteristic(defaults, fines):
    for label, m in all_meshes(defaults, fines):
        chi, edges = surface_euler(m.surface)
        assert set(edges.values()) == {2}, label
        directed = Counter((p, q) for a, b, c in m.surface.tolist() for p, q in ((a, b), (b, c), (c, a)))
        assert set(directed.values()) == {1}, label
        assert chi == (0 if label.startswith("torus") else 2), label


def test_tets_positive_and_divergence_theorem(defaults, fines):
    for label, m in all_meshes(defaults, fines):
        vol = det_volumes(m)
        assert np.all(vol > 0.0), label
        x = m.nodes[m.surface]
        v_surf = np.sum(x[:, 0] * np.cross(x[:, 1], x[:, 2])) / 6.0
        assert v_surf == pytest.approx(vol.sum(), rel=1e-10), label
        assert m.volume == pytest.approx(vol.sum(), rel=1e-12), label
        assert len(np.unique(m.tets)) == m.num_nodes, label  # no unreferenced node


def test_quality_bounds(defaults, fines):
    for label, m in all_meshes(defaults, fines):
        q = m.quality()
        assert isinstance(q, MeshQuality)
        indep = min_dihedral_edge_formula(m)
        print(f"{label}: min dihedral {indep:.2f} deg, min radius ratio {q.min_radius_ratio:.3f}")
        assert q.min_dihedral_deg == pytest.approx(indep, abs=1e-6), label
        assert indep > 5.0, label
        assert q.min_radius_ratio > 0.05 and q.min_volume > 0.0, label
        assert q.num_tets == m.num_tets and q.num_nodes == m.num_nodes
    regular = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)
    m = finalize_mesh(regular, np.array([[0, 1, 2, 3]]), "regular tet")
    q = m.quality()
    assert q.min_radius_ratio == pytest.approx(1.0) and q.min_dihedral_deg == pytest.approx(70.5288, abs=1e-3)


# ---------------------------------------------------------------- determinism, user meshes
def _digest(meshes) -> str:
    h = hashlib.sha256()
    for m in meshes:
        for a in (m.nodes, m.tets, m.surface):
            h.update(a.tobytes())
    return h.hexdigest()


def test_deterministic_within_a_process():
    for name in NAMES:
        x, y = make_object_mesh(name), make_object_mesh(name)
        for a, b in ((x.nodes, y.nodes), (x.tets, y.tets), (x.surface, y.surface)):
            assert a.tobytes() == b.tobytes(), name
    ico = trimesh.creation.icosphere(3, radius=0.02)
    x, y = mesh_from_surface(ico, 0.004), mesh_from_surface(ico.copy(), 0.004)
    assert _digest([x]) == _digest([y])


@pytest.mark.slow
def test_deterministic_across_processes(tmp_path):
    ico = trimesh.creation.icosphere(3, radius=0.02)
    path = tmp_path / "ico.stl"
    ico.export(path)
    here = _digest([make_object_mesh(n) for n in NAMES] + [mesh_from_surface(path, 0.004)])
    code = textwrap.dedent(f"""
        import hashlib
        from defgrasp_env.sim.meshing import make_object_mesh, mesh_from_surface
        ms = [make_object_mesh(n) for n in {NAMES!r}] + [mesh_from_surface({str(path)!r}, 0.004)]
        h = hashlib.sha256()
        for m in ms:
            for a in (m.nodes, m.tets, m.surface):
                h.update(a.tobytes())
        print(h.hexdigest())
    """)
    root = Path(__file__).resolve().parents[1]
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == here


@pytest.mark.parametrize("kind", ["icosphere", "box"])
def test_user_surface_from_stl(tmp_path, kind):
    if kind == "icosphere":
        src = trimesh.creation.icosphere(3, radius=0.025)
        res, tol = 0.004, 0.015
    else:
        src = trimesh.creation.box((0.04, 0.03, 0.05))
        res, tol = 0.004, 0.03  # sharp edges are bevelled at the resolution scale
    path = tmp_path / f"{kind}.stl"
    src.export(path)
    m = mesh_from_surface(str(path), res)
    assert abs(m.volume / src.volume - 1.0) < tol
    assert np.all(det_volumes(m) > 0.0)
    assert {tuple(sorted(t)) for t in m.surface.tolist()} == boundary_by_counting(m.tets)
    chi, edges = surface_euler(m.surface)
    assert chi == 2 and set(edges.values()) == {2}
    lo, hi = m.nodes.min(axis=0), m.nodes.max(axis=0)
    assert lo[1] == 0.0 and abs(lo[0] + hi[0]) < 1e-12 and abs(lo[2] + hi[2]) < 1e-12
    assert min_dihedral_edge_formula(m) > 5.0
    # every surface node lies on the input surface (input moved to the same resting frame)
    shifted = src.copy()
    (x0, y0, z0), (x1, _, z1) = src.bounds
    shifted.apply_translation(-np.array([0.5 * (x0 + x1), y0, 0.5 * (z0 + z1)]))
    _, dist, _ = trimesh.proximity.closest_point(shifted, m.nodes[np.unique(m.surface)])
    assert dist.max() < 1e-5  # trimesh's closest_point itself is only good to ~1e-6 m here
    # the same surface given as a Trimesh, and with inverted winding, gives the same mesh
    m2 = mesh_from_surface(trimesh.load(path), res)
    assert np.array_equal(m.nodes, m2.nodes) and np.array_equal(m.tets, m2.tets)
    inv = trimesh.load(path)
    inv.invert()
    assert mesh_from_surface(inv, res).volume == pytest.approx(m.volume, rel=1e-9)


def test_finest_meshes_valid(finest):
    for name, m in finest.items():
        assert m.num_tets > 100_000, name
        vol = det_volumes(m)
        assert np.all(vol > 0.0), name
        x = m.nodes[m.surface]
        v_surf = np.sum(x[:, 0] * np.cross(x[:, 1], x[:, 2])) / 6.0
        assert v_surf == pytest.approx(vol.sum(), rel=1e-10), name
        assert m.nodes.min(axis=0)[1] == 0.0, name
        q = m.quality()
        print(f"{name}-1.5mm: {m.num_tets} tets, min dihedral {q.min_dihedral_deg:.2f} deg")
        assert q.min_dihedral_deg > 5.0, name


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("call", "exc", "match"),
    [
        (lambda: make_object_mesh("cube"), ValueError, r"unknown object name 'cube'; accepted: \['cuboid'"),
        (lambda: make_object_mesh(3), TypeError, r"name must be a str"),
        (lambda: make_object_mesh("sphere", radius=-3.0), ValueError, r"radius must be in \(0, inf\) m, got -3.0"),
        (lambda: make_object_mesh("sphere", radius=0.0), ValueError, r"radius must be in \(0, inf\) m, got 0.0"),
        (lambda: make_object_mesh("sphere", radius=float("nan")), ValueError, r"radius must be in \(0, inf\) m"),
        (lambda: make_object_mesh("sphere", radius="big"), TypeError, r"radius must be a real number"),
        (lambda: make_object_mesh("sphere", radius=True), TypeError, r"radius must be a real number"),
        (lambda: make_object_mesh("sphere", diameter=0.05), TypeError, r"unknown size argument\(s\) \['diameter'\]"),
        (lambda: make_object_mesh("cuboid", size=(0.04, 0.04)), TypeError, r"size must be a sequence of 3"),
        (lambda: make_object_mesh("cuboid", size=(0.04, -0.01, 0.04)), ValueError, r"size\[1\] must be in \(0, inf\) m, got -0.01"),
        (lambda: make_object_mesh("torus", minor_radius=0.03), ValueError, r"minor_radius must be in \(0, 0.8 \* major_radius = 0.024\] m"),
        (lambda: make_object_mesh("cylinder", height=-1), ValueError, r"height must be in \(0, inf\) m, got -1"),
        (lambda: make_object_mesh("sphere", resolution=0.0), ValueError, r"resolution must be in \(0, 0.05\] m for sphere"),
        (lambda: make_object_mesh("sphere", resolution=-0.01), ValueError, r"resolution must be in \(0, 0.05\] m"),
        (lambda: make_object_mesh("rope", resolution=0.02), ValueError, r"resolution must be in \(0, 0.016\] m for rope .*got 0.02"),
        (lambda: make_object_mesh("sphere", resolution=1e-5), ValueError, r"resolution is too fine"),
        (lambda: make_object_mesh("cuboid", resolution="fine"), TypeError, r"resolution must be a real number"),
    ],
)
def test_bad_object_arguments_rejected(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


def test_bad_surfaces_rejected(tmp_path):
    holed = trimesh.creation.icosphere(2, radius=0.02)
    holed = trimesh.Trimesh(holed.vertices, holed.faces[1:], process=False)
    with pytest.raises(ValueError, match="must be watertight"):
        mesh_from_surface(holed, 0.005)
    path = tmp_path / "holed.stl"
    holed.export(path)
    with pytest.raises(ValueError, match="must be watertight"):
        mesh_from_surface(path, 0.005)
    with pytest.raises(ValueError, match="surface mesh is empty"):
        mesh_from_surface(trimesh.Trimesh(), 0.005)
    with pytest.raises(FileNotFoundError, match="surface mesh file not found"):
        mesh_from_surface(tmp_path / "missing.stl", 0.005)
    with pytest.raises(TypeError, match="source must be a file path"):
        mesh_from_surface(42, 0.005)  # type: ignore[arg-type]
    ball = trimesh.creation.icosphere(2, radius=0.02)
    with pytest.raises(ValueError, match=r"resolution must be in \(0, 0.04\] m for this surface"):
        mesh_from_surface(ball, 0.05)
    with pytest.raises(ValueError, match=r"resolution must be in \(0, 0.04\] m"):
        mesh_from_surface(ball, -1.0)


def test_degenerate_tets_rejected_naming_the_quality():
    flat = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=float)
    with pytest.raises(ValueError, match=r"degenerate tets \(min volume 0.000e\+00 m\^3"):
        finalize_mesh(flat, np.array([[0, 1, 2, 3]]), "flat tet")
    sliver = flat + np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0.01]])
    with pytest.raises(ValueError, match=r"near-degenerate tet: min dihedral angle \d+\.\d+ deg"):
        finalize_mesh(sliver, np.array([[0, 1, 2, 3]]), "sliver")


def test_tetmesh_is_immutable_and_checks_indices(defaults):
    m = defaults["cuboid"]
    with pytest.raises(ValueError):
        m.nodes[0, 0] = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.nodes = m.nodes  # type: ignore[misc]
    with pytest.raises(ValueError, match=r"tets indices must be in \[0, 3\]"):
        TetMesh(nodes=np.zeros((4, 3)), tets=np.array([[0, 1, 2, 4]]), surface=np.zeros((0, 3)))
    with pytest.raises(ValueError, match=r"nodes must have shape \[n, 3\]"):
        TetMesh(nodes=np.zeros((4, 2)), tets=np.zeros((0, 4)), surface=np.zeros((0, 3)))
