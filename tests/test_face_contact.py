"""A node's depth behind its lagged pad face is continuous where it slides past the face's edge.

``kernels.contact.face_contact`` gives a node the depth behind the face it was pushed through at the
substep start (``lag_normal``), however deep, never through the opposite face. Until 2026-12-07 that
depth counted only inside the face's lateral extent and jumped from nothing to the full depth at
its edge: a node swept around a pad's side and back in front of it met a wall of energy. In a
cylinder E = 3e6 swept at 2 m/s a 4 um step of a Newton iterate raised the incremental potential
from 1.1 to 360 J, the line search accepted its shortest step uphill in cycle after cycle, and a
stopped pad's solve did not converge in 4 + 60 iterations (kept at 966 N, the actuator bound is
270 N). Now the depth is the smaller of the face's depth and the distance to a side face of its
extent (with that side's normal), so it falls to 0 at the edge.

Independent truths: the depth is the distance to the nearest of those faces (a closed form), a
distance changes by at most the distance moved (Lipschitz 1: no jump; the old rule jumps by the
full depth), and the returned normal is minus the depth's gradient (central differences), which
the force and Hessian of ``contact.evaluate_node`` use with the energy of
``energy.node_energy_row``.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from defgrasp_env.sim.kernels.contact import face_contact

# A pad collision box of the env's size (pad plus backing: 16.35 x 37.5 x 22 mm).
HALF = np.array([0.008175, 0.01875, 0.011])


@wp.kernel
def _contacts(points: wp.array(dtype=wp.vec3), half: wp.vec3, n: wp.vec3, depth: wp.array(dtype=float),
              normal: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    d, m = face_contact(points[i], half, n)
    depth[i] = d
    normal[i] = m


def contacts(points: np.ndarray, n) -> tuple[np.ndarray, np.ndarray]:
    """(depth [N], normal [N, 3]) of ``face_contact`` at box-frame points [N, 3] for the face ``n``."""
    p = wp.array(np.asarray(points, np.float32), dtype=wp.vec3, device="cpu")
    depth = wp.zeros(len(points), dtype=float, device="cpu")
    normal = wp.zeros(len(points), dtype=wp.vec3, device="cpu")
    wp.launch(_contacts, len(points), [p, wp.vec3(*HALF), wp.vec3(*n), depth, normal], device="cpu")
    return depth.numpy().astype(np.float64), normal.numpy().astype(np.float64)


def test_depth_falls_to_zero_at_the_faces_edge():
    """A node 5 mm behind the +x face (outward normal +x) slid along y from beside the box to its
    middle: no contact beside it, then depth = its distance to the +y side (with the +y normal) up
    to 5 mm from the edge, then 5 mm with the +x normal; 0.01 mm steps change the depth by at most
    0.01 mm (float32 rounding of the points: 2e-8 m)."""
    x = HALF[0] - 0.005
    y = np.linspace(HALF[1] + 0.002, 0.0, 2076)
    points = np.stack([np.full_like(y, x), y, np.zeros_like(y)], axis=1)
    depth, normal = contacts(points, (1.0, 0.0, 0.0))
    side = HALF[1] - y
    expected = np.where(side <= 0.0, -1.0, np.minimum(0.005, side))
    inside = side > 1e-6
    np.testing.assert_allclose(depth[inside], expected[inside], atol=2e-8)
    assert (depth[side < -1e-6] <= 0.0).all()
    steps = np.abs(np.diff(np.maximum(depth, 0.0)))
    assert steps.max() <= np.abs(np.diff(y)).max() + 2e-8, steps.max()
    near_side = inside & (side < 0.005 - 1e-6)
    assert near_side.sum() > 100 and (normal[near_side] == [0.0, 1.0, 0.0]).all()
    assert (normal[inside & (side > 0.005 + 1e-6)] == [1.0, 0.0, 0.0]).all()


def test_no_point_is_pushed_through_the_opposite_face_and_a_deep_one_keeps_its_face():
    """Behind the -x face (outward normal -x, the box's thin axis), deeper than half the box:
    still pushed out through -x where that is nearer than the y and z sides, never through +x (its
    normal never points along +x)."""
    rng = np.random.default_rng(0)
    points = rng.uniform(-HALF, HALF, (2000, 3)) * 0.999
    depth, normal = contacts(points, (-1.0, 0.0, 0.0))
    assert (depth > 0.0).all() and not (normal[:, 0] > 0.0).any()
    face = HALF[0] + points[:, 0]
    sides = np.minimum(HALF[1] - np.abs(points[:, 1]), HALF[2] - np.abs(points[:, 2]))
    np.testing.assert_allclose(depth, np.minimum(face, sides), atol=2e-8)
    deep = (face > HALF[0]) & (face < sides)  # past the box's middle, nearer the -x face than the sides
    assert deep.sum() > 10 and (normal[deep] == [-1.0, 0.0, 0.0]).all()


def test_the_normal_is_minus_the_gradient_of_the_depth():
    """Central differences of the depth (float64 of float32 points, step 0.1 mm) at random points
    behind the +z face, away from the ridges where the nearest face changes: -grad depth equals
    the returned normal within 1e-3 (float32 rounding of points of ~1e-2 m over a 2e-4 m step)."""
    rng = np.random.default_rng(1)
    points = rng.uniform(-HALF, HALF, (400, 3)) * 0.95
    depth, normal = contacts(points, (0.0, 0.0, 1.0))
    step = 1e-4
    grad = np.zeros_like(points)
    for j in range(3):
        e = np.zeros(3)
        e[j] = step
        grad[:, j] = (contacts(points + e, (0.0, 0.0, 1.0))[0] - contacts(points - e, (0.0, 0.0, 1.0))[0]) / (2 * step)
    face = HALF[2] - points[:, 2]
    gaps = np.sort(np.stack([face, HALF[0] - np.abs(points[:, 0]), HALF[1] - np.abs(points[:, 1])], axis=1), axis=1)
    # the nearest face is the same at both difference points: off the ridges between faces and off
    # the planes x = 0, y = 0 between a side and its opposite side
    clear = (gaps[:, 1] - gaps[:, 0] > 2 * step) & (np.abs(points[:, :2]) > 2 * step).all(axis=1)
    sided = clear & (normal[:, 2] == 0.0)  # where a side is the nearest face
    assert clear.sum() > 300 and sided.sum() > 50, (clear.sum(), sided.sum())
    np.testing.assert_allclose(-grad[clear], normal[clear], atol=1e-3)
