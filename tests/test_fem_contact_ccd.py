"""FEM core, intersection-free pad contact: a pad that moves further than its half thickness in a
substep must not push nodes out of its far side (continuous collision detection picks the face
each node meets, ``kernels.pad_faces.contact_face``), and no node may end deeper than 1 mm.
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from defgrasp_env.sim.kernels.pad_faces import contact_face
from defgrasp_env.sim.materials import Material
from defgrasp_env.sim.meshing import make_object_mesh
from defgrasp_env.sim.model import build_model
from defgrasp_env.sim.solver import ImplicitSolver, SolverConfig
from defgrasp_env.sim.state import Control, State

# A pad collision box of the env's size (pad plus backing: 16.35 x 37.5 x 22 mm).
HALF = np.array([0.008175, 0.01875, 0.011])


@wp.kernel
def _faces(a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3), half: wp.vec3, n: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    n[i] = contact_face(a[i], b[i], half)


def test_contact_face_rules():
    """Start outside, relative motion through the box: the face entered first (not the nearest one
    at the end, which is the far face); start inside: the nearest face; motion missing the box: the
    side of largest separation."""
    cases = [  # start, end (box frame, m), expected outward normal
        ((-0.02, 0.0, 0.0), (0.007, 0.0, 0.0), (-1, 0, 0)),      # swept past the centre: still the -x face
        ((0.0, 0.03, 0.0), (0.001, -0.015, 0.0), (0, 1, 0)),     # from above, through nearly all of it
        ((-0.02, 0.015, 0.0), (0.0, 0.025, 0.0), (-1, 0, 0)),    # corner region, enters through -x... and leaves
        ((0.007, 0.0, 0.0), (0.007, 0.0, 0.0), (1, 0, 0)),       # inside, 1.2 mm under the +x face
        ((0.0, 0.0, 0.05), (0.0, 0.0, 0.04), (0, 0, 1)),         # moving toward, not reaching: its side
    ]
    a = wp.array(np.array([c[0] for c in cases], np.float32), dtype=wp.vec3, device="cpu")
    b = wp.array(np.array([c[1] for c in cases], np.float32), dtype=wp.vec3, device="cpu")
    n = wp.zeros(len(cases), dtype=wp.vec3, device="cpu")
    wp.launch(_faces, len(cases), [a, b, wp.vec3(*HALF), n], device="cpu")
    np.testing.assert_array_equal(n.numpy(), np.array([c[2] for c in cases], np.float32))


def box_frame(x, center):
    return x - center  # the pad is axis-aligned in this test


@pytest.mark.parametrize("h", [0.0125, 0.005])
@pytest.mark.parametrize("name", ["sphere", "cuboid"])
def test_pad_at_2_m_s_into_a_stiff_object_does_not_tunnel(name, h):
    """A pad box moving at 2 m/s (the largest legal wrist speed) into an E = 1e7 object resting on
    the ground. h = 12.5 ms (the env's substep at 4 per 50 ms): 25 mm per substep, 1.5 x the
    box's own thickness; after every substep no node is on the far side of the pad (crossed: from
    in front of its -x face to behind its +x face, inside its y/z extent). Before CCD, 60+ nodes
    of the sphere ended behind the pad (nearest-face push-out), reading tens of kN.
    h = 5 ms: the env's adaptive substep at 2 m/s (``sim.pad_motion.MAX_PAD_TRAVEL`` = 10 mm per
    substep). At either substep the 4 + 8 Newton iterations do not always resolve the impact (the
    stiff cuboid's flat face at 25 mm per substep ended several mm deep, though never through):
    the depth clamp puts such nodes back to 0.9 mm and flags the step ``penetrated``; no node
    ends a substep deeper than 1 mm, and no node goes through."""
    mesh = make_object_mesh(name)
    radius, centre_y = float(mesh.nodes[:, 0].max()), 0.5 * float(mesh.nodes[:, 1].max())
    model = build_model([mesh], [Material(youngs_modulus=1e7)], pad_half_extents=[HALF], device="cpu")
    state, control = State.from_model(model), Control.from_model(model)
    solver = ImplicitSolver(model, SolverConfig(substeps=1))
    pad = np.array([radius + HALF[0] + 0.01, centre_y, 0.0])
    state.pad_positions.assign(pad[None].astype(np.float32))
    speed = 2.0
    for _ in range(round(0.125 / h)):
        start = box_frame(state.positions.numpy().astype(np.float64), pad)
        pad = pad - np.array([speed * h, 0.0, 0.0])
        control.pad_target_positions.assign(pad[None].astype(np.float32))
        stats = solver.step(state, state, control, h)
        x = state.positions.numpy().astype(np.float64)
        end = box_frame(x, pad)
        lateral = np.all(np.abs(start[:, 1:]) < HALF[1:], axis=1) & np.all(np.abs(end[:, 1:]) < HALF[1:], axis=1)
        crossed = lateral & (start[:, 0] <= -HALF[0]) & (end[:, 0] >= HALF[0])
        depth = max(float(np.min(HALF - np.abs(end), axis=1).max()), float(-x[:, 1].min()))
        assert not crossed.any(), f"{crossed.sum()} nodes went through the pad"
        assert not stats.diverged.any()
        assert depth < 1e-3, depth
        if depth > 0.9e-3:
            assert stats.penetrated[0]      # a clamped node is reported
