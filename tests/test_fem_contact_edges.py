"""FEM core, edge contact: a pad box edge must not pass between the surface nodes of a coarse stiff
object (``kernels/edge_contact.py``). With node-vs-box contact alone, a pad edge pressed into a face
between two node rows sinks in freely until the rows touch the edge's two faces (a 90-degree edge
between rows 8 mm apart: 4 mm), and the object then clamps the pad from both faces; that is how a
pad ended up embedded in the E = 1e7 cuboid in the contact fuzz's sideways sweep.

The check is independent of the solver's contact model: the object's surface is sampled densely
(a barycentric grid on every boundary triangle, ``surface_samples``) and no sample may lie deeper
than 1 mm (the penetration bound) inside the pad box.
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from defgrasp_env.sim.materials import Material
from defgrasp_env.sim.meshing import make_object_mesh
from defgrasp_env.sim.model import ContactParams, build_model
from defgrasp_env.sim.solver import ImplicitSolver, SolverConfig
from defgrasp_env.sim.state import Control, State
from defgrasp_env.transforms import quat_multiply, quat_rotate

# A pad collision box of the env's size (pad plus backing: 16.35 x 37.5 x 22 mm).
HALF = np.array([0.008175, 0.01875, 0.011])
BOUND = 1e-3  # m: SolverConfig.penetration_bound


def surface_samples(x: np.ndarray, tris: np.ndarray, n: int = 16) -> np.ndarray:
    """[S, 3] points of a barycentric grid with n intervals per side on every triangle (m)."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    w = np.stack([i[keep], j[keep], n - i[keep] - j[keep]], axis=1) / n  # [B, 3]
    return np.einsum("bk,tkd->tbd", w, x[tris]).reshape(-1, 3)


def box_depth(points: np.ndarray, center: np.ndarray, quat: np.ndarray) -> float:
    """Deepest nearest-face depth (m) of ``points`` inside the box (< 0: all outside)."""
    inv = np.asarray(quat, dtype=np.float64) * np.array([-1.0, -1.0, -1.0, 1.0])
    local = quat_rotate(inv[None], points - center)
    return float(np.min(HALF - np.abs(local), axis=1).max())


def axis_quat(axis, angle: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    return np.concatenate([np.sin(angle / 2) * axis, [np.cos(angle / 2)]])


def press(mesh, e: float, edges: bool, centre: np.ndarray, quat, travel: float) -> tuple[float, float]:
    """Drive a pad box (``HALF``, orientation ``quat``) from ``centre`` down by ``travel`` (m) at
    0.2 m/s in 5 ms steps into ``mesh`` (E = ``e``, resting on the ground), then hold it 10 steps;
    returns the deepest surface sample inside the pad over the run (m) and the object's upward
    force on the pad at the end (N)."""
    model = build_model([mesh], [Material(youngs_modulus=e)], pad_half_extents=[HALF],
                        contact=ContactParams(edge_contact=edges), device="cpu")
    state, control = State.from_model(model), Control.from_model(model)
    solver = ImplicitSolver(model, SolverConfig(substeps=1))
    state.pad_positions.assign(centre[None].astype(np.float32))
    state.pad_orientations.assign(np.asarray(quat)[None].astype(np.float32))
    control.pad_target_orientations.assign(np.asarray(quat)[None].astype(np.float32))
    h, speed = 0.005, 0.2
    tris = np.asarray(mesh.surface)
    moves = int(round(travel / (speed * h)))
    deepest = 0.0
    for k in range(moves + 10):  # drive down, then hold
        if k < moves:
            centre = centre - np.array([0.0, speed * h, 0.0])
        control.pad_target_positions.assign(centre[None].astype(np.float32))
        stats = solver.step(state, state, control, h)
        assert not stats.diverged.any()
        x = state.positions.numpy().astype(np.float64)
        deepest = max(deepest, box_depth(surface_samples(x, tris), centre, quat))
    return deepest, float(state.pad_force.numpy()[0, 1])


@pytest.mark.parametrize("size, resolution, e, quat, corner", [
    # edge along z (pad turned 45 deg about z), cuboid of the env (40 mm, 8 mm node rows), E = 1e7
    ((0.04, 0.04, 0.04), 0.010, 1e7, axis_quat((0, 0, 1), np.pi / 4), (-1, -1, 0)),
    # edge along x (pad turned 40 deg about x), a larger, coarser cuboid (10 mm rows), E = 1e6
    ((0.06, 0.05, 0.06), 0.012, 1e6, axis_quat((1, 0, 0), -0.7), (0, -1, -1)),
])
@pytest.mark.parametrize("edges", [True, False])
def test_pad_edge_pressed_between_surface_nodes_does_not_sink_in(size, resolution, e, quat, corner, edges):
    """A pad box with one edge pointing down, placed half way between two node rows of a stiff
    cuboid's top face, is driven 3.5 mm below the face at 0.2 m/s and held. With edge contact
    (``ContactParams.edge_contact``) the surface under the edge must push back: no surface point
    deeper than 1 mm in the pad, and the pad feels a force that holds it up. With node-vs-box
    contact alone (the default; the code before edge contact: 2.12 and 1.92 mm in the two cases)
    the edge sinks in deeper than 1.5 mm: the known gap this reproduces. The first case is the geometry of the contact fuzz's cuboid; the
    second (another size, row spacing, modulus and edge direction) was not used to tune anything."""
    mesh = make_object_mesh("cuboid", resolution=resolution, size=size)
    rows = np.unique(np.round(mesh.nodes[:, 0], 6) if corner[0] == 0 else np.round(mesh.nodes[:, 2], 6))
    top = float(mesh.nodes[:, 1].max())
    # the lowest box edge: local corner (the axis with 0 spans the edge) rotated into the world
    tip_local = np.asarray(corner, dtype=np.float64) * HALF
    tip_offset = quat_rotate(np.asarray(quat)[None], tip_local[None])[0]
    corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T * HALF
    assert np.isclose(tip_offset[1], quat_rotate(np.repeat(np.asarray(quat)[None], 8, 0), corners)[:, 1].min())
    between = 0.5 * (rows[len(rows) // 2 - 1] + rows[len(rows) // 2])  # half way between two rows
    target = np.array([between, top + 0.001, 0.0]) if corner[2] == 0 else np.array([0.0, top + 0.001, between])
    deepest, force = press(mesh, e, edges, target - tip_offset, quat, 0.001 + 0.0035)
    if not edges:  # node-vs-box contact alone (the default): the gap this test is about
        assert deepest > 1.5 * BOUND, deepest
        return
    assert deepest < BOUND, f"a surface point {deepest * 1e3:.2f} mm deep in the pad"
    # the held pad is pushed up: at least the force of 1 mm of surface pressed by a 22/37.5 mm
    # edge, well above the object's weight (~0.6 N) that node-vs-box contact alone reads
    assert force > 10.0, force


@pytest.mark.parametrize("edges", [True, False])
def test_pad_corner_pressed_into_a_sphere_between_its_nodes_does_not_sink_in(edges):
    """A pad box turned so that one corner points down (the pinch a learned policy found: the pads'
    corners pressed into a ball above its equator), placed over the centroid of the sphere's
    surface triangle nearest its top, i.e. between nodes, and driven 3 mm into it at 0.2 m/s, then
    held (50 mm sphere, E = 1e6: another shape, modulus and contact feature than the cases
    above). With edge contact no surface point lies deeper than 1 mm in the pad and the pad is
    pushed back; without it the corner sinks in between the nodes."""
    mesh = make_object_mesh("sphere")
    x0, tris = mesh.nodes.astype(np.float64), np.asarray(mesh.surface)
    centroids = x0[tris].mean(axis=1)
    normals = np.cross(x0[tris[:, 1]] - x0[tris[:, 0]], x0[tris[:, 2]] - x0[tris[:, 0]])
    up = normals[:, 1] / np.linalg.norm(normals, axis=1)
    top = centroids[np.argmax(up)]  # the flattest triangle at the top: its centroid is between nodes
    quat = quat_multiply(axis_quat((0, 0, 1), np.pi / 4), axis_quat((1, 0, 0), np.arctan(np.sqrt(0.5))))
    corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T * HALF
    world = quat_rotate(np.repeat(np.asarray(quat)[None], 8, 0), corners)
    tip_offset = world[np.argmin(world[:, 1])]
    deepest, force = press(mesh, 1e6, edges, top + np.array([0.0, 0.001, 0.0]) - tip_offset, quat, 0.004)
    if not edges:
        assert deepest > 1.5 * BOUND, deepest
        return
    assert deepest < BOUND, f"a surface point {deepest * 1e3:.2f} mm deep in the pad"
    assert force > 1.0, force
