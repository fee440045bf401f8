"""FEM core, edge contact: a pad box edge or corner must not pass between the surface nodes of a
coarse object (``kernels/pad_edge_contact.py``). With node-vs-box contact alone, a pad edge pressed
into a face between two node rows sinks in freely until the rows touch the edge's two faces (a
90-degree edge between rows 8 mm apart could sink 4 mm; measured 2.1 mm), and the object then
clamps the pad from both faces; that is how a pad ended up embedded in the E = 1e7 cuboid in the
contact fuzz's sideways sweep.

The check is independent of the solver's contact model: the object's surface is sampled densely
(a barycentric grid on every boundary triangle, ``surface_samples``) and no sample may lie deeper
than 1 mm (the penetration bound) inside the pad box.
"""

from __future__ import annotations

import numpy as np
import pytest

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


def drive(meshes, moduli, centres, quats, travel: float, edges: bool = True, device: str = "cpu",
          config: SolverConfig = SolverConfig(substeps=1)):
    """Drive one pad box (``HALF``) per world, world w's from ``centres[w]`` with orientation
    ``quats[w]``, down by ``travel`` (m) at 0.2 m/s in 5 ms steps into ``meshes[w]`` (E =
    ``moduli[w]``, resting on the ground), then hold it 10 steps; returns the node positions after
    every step [steps][N, 3] and the upward force of each object on its pad at the end [W] (N)."""
    model = build_model(list(meshes), [Material(youngs_modulus=e) for e in moduli], pad_half_extents=[HALF],
                        contact=ContactParams(edge_contact=edges), device=device)
    state, control = State.from_model(model), Control.from_model(model)
    solver = ImplicitSolver(model, config)
    centres = np.asarray(centres, dtype=np.float64)
    quats = np.asarray(quats, dtype=np.float32)
    state.pad_positions.assign(centres.astype(np.float32))
    state.pad_orientations.assign(quats)
    control.pad_target_orientations.assign(quats)
    h, speed = 0.005, 0.2
    moves = int(round(travel / (speed * h)))
    history = []
    for k in range(moves + 10):  # drive down, then hold
        if k < moves:
            centres = centres - np.array([0.0, speed * h, 0.0])
        control.pad_target_positions.assign(centres.astype(np.float32))
        assert not solver.step(state, state, control, h).diverged.any()
        history.append(state.positions.numpy().astype(np.float64))
    return history, state.pad_force.numpy().astype(np.float64)[:, 1]


def press(mesh, e: float, edges: bool, centre: np.ndarray, quat, travel: float) -> tuple[float, float]:
    """``drive`` one world; returns the deepest surface sample inside the pad over the run (m) and
    the object's upward force on the pad at the end (N)."""
    history, force = drive([mesh], [e], [centre], [quat], travel, edges)
    h, speed = 0.005, 0.2
    tris = np.asarray(mesh.surface)
    centres = [centre - np.array([0.0, speed * h * min(k + 1, round(travel / (speed * h))), 0.0])
               for k in range(len(history))]
    return max(box_depth(surface_samples(x, tris), c, quat) for x, c in zip(history, centres)), float(force[0])


#: The two pad-edge cases: cuboid size, mesh resolution, E, pad orientation and the pad's lowest
#: edge (the local corner whose 0 axis spans it).
EDGE_CASES = [
    # edge along z (pad turned 45 deg about z), cuboid of the env (40 mm, 8 mm node rows), E = 1e7
    ((0.04, 0.04, 0.04), 0.010, 1e7, axis_quat((0, 0, 1), np.pi / 4), (-1, -1, 0)),
    # edge along x (pad turned 40 deg about x), a larger, coarser cuboid (10 mm rows), E = 1e6
    ((0.06, 0.05, 0.06), 0.012, 1e6, axis_quat((1, 0, 0), -0.7), (0, -1, -1)),
]


def edge_case_start(size, resolution, quat, corner):
    """The cuboid mesh of an edge case and the pad centre that puts its lowest edge 1 mm above the
    top face, half way between two node rows."""
    mesh = make_object_mesh("cuboid", resolution=resolution, size=size)
    rows = np.unique(np.round(mesh.nodes[:, 0], 6) if corner[0] == 0 else np.round(mesh.nodes[:, 2], 6))
    top = float(mesh.nodes[:, 1].max())
    tip_offset = quat_rotate(np.asarray(quat)[None], (np.asarray(corner, dtype=np.float64) * HALF)[None])[0]
    corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T * HALF
    assert np.isclose(tip_offset[1], quat_rotate(np.repeat(np.asarray(quat)[None], 8, 0), corners)[:, 1].min())
    between = 0.5 * (rows[len(rows) // 2 - 1] + rows[len(rows) // 2])  # half way between two rows
    target = np.array([between, top + 0.001, 0.0]) if corner[2] == 0 else np.array([0.0, top + 0.001, between])
    return mesh, target - tip_offset


@pytest.mark.parametrize("size, resolution, e, quat, corner", EDGE_CASES)
@pytest.mark.parametrize("edges", [True, False])
def test_pad_edge_pressed_between_surface_nodes_does_not_sink_in(size, resolution, e, quat, corner, edges):
    """A pad box with one edge pointing down, placed half way between two node rows of a stiff
    cuboid's top face, is driven 3.5 mm below the face at 0.2 m/s and held. With edge contact
    (``ContactParams.edge_contact``) the surface under the edge must push back: no surface point
    deeper than 1 mm in the pad, and the pad feels a force that holds it up. With node-vs-box
    contact alone (``edge_contact=False``: 2.12 and 1.92 mm in the two cases) the edge sinks in deeper than
    1.5 mm: the gap edge contact closes. The first case is the geometry of the contact fuzz's
    cuboid; the second (another size, row spacing, modulus and edge direction) was not used to
    tune anything."""
    mesh, centre = edge_case_start(size, resolution, quat, corner)
    deepest, force = press(mesh, e, edges, centre, quat, 0.001 + 0.0035)
    if not edges:  # node-vs-box contact alone: the gap this test is about
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


def _both_edge_cases(device="cpu", config=SolverConfig(substeps=1), worlds=(0, 1)):
    starts = [edge_case_start(*(EDGE_CASES[w][i] for i in (0, 1, 3, 4))) for w in worlds]
    return drive([m for m, _ in starts], [EDGE_CASES[w][2] for w in worlds], [c for _, c in starts],
                 [EDGE_CASES[w][3] for w in worlds], 0.0045, device=device, config=config)


def test_edge_contact_worlds_are_independent_bitwise_on_cpu():
    """The two edge cases in one model (two worlds, edge contact engaged: the pads are pushed
    back with > 10 N) give bit-identical positions and pad forces to each simulated alone: the
    edge points' search and sums stay within their world."""
    together, force = _both_edge_cases()
    assert np.all(force > 10.0), force
    start = 0
    for w in (0, 1):
        alone, force_alone = _both_edge_cases(worlds=(w,))
        n = alone[0].shape[0]
        for x, xa in zip(together, alone):
            np.testing.assert_array_equal(x[start:start + n], xa)
        assert force[w] == force_alone[0]
        start += n


@pytest.mark.cuda
def test_edge_contact_cpu_and_cuda_agree():
    """The two edge cases (two worlds) on CPU and CUDA: positions within 2e-5 m and pad forces within
    2 % + 10 mN at the end (as test_fem_batch's agreement test: float32 atomics sum in another
    order on the GPU; converged solves keep the two close; the edge points' atomic minimum picks
    the same triangle on both unless two are equally near)."""
    config = SolverConfig(substeps=1, newton_iterations=16, newton_tolerance=1e-7, cg_iterations=200,
                          cg_tolerance=1e-5)
    cpu, f_cpu = _both_edge_cases(config=config)
    gpu, f_gpu = _both_edge_cases(device="cuda:0", config=config)
    np.testing.assert_allclose(gpu[-1], cpu[-1], atol=2e-5)
    np.testing.assert_allclose(f_gpu, f_cpu, rtol=0.02, atol=1e-2)
