"""A node's depth behind its lagged pad face is continuous where it slides past the face's edge.

``kernels.pad_faces.face_contact`` gives a node the depth behind the face it was pushed through at the
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

from defgrasp_env.sim.kernels.pad_faces import face_contact

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


def _node_contact(x: np.ndarray, x_start: np.ndarray, lag_force: float):
    """(energy as a function of positions [N, 3], the residual [N, 3] of ``contact.evaluate_nodes``)
    of N nodes of one world against one pad box at y = 0.05 m (identity pose, not moving), each node's
    lagged face the +x face with a lagged normal force ``lag_force`` (N, friction), mass 1 g,
    dt = 10 ms, no gravity: the residual is minus the energy's gradient (inertia, penalty, friction)."""
    from defgrasp_env.sim.kernels import contact as kc
    from defgrasp_env.sim.kernels import energy as ke

    n = len(x)
    dev = "cpu"
    arr = lambda a, dtype: wp.array(np.asarray(a), dtype=dtype, device=dev)  # noqa: E731
    pos = arr([[0.0, 0.05, 0.0]], wp.vec3)
    rot = arr([[0.0, 0.0, 0.0, 1.0]], wp.quat)
    lag_normal = np.zeros((n, 2, 3), np.float32)
    lag_normal[:, 0] = (0.0, 1.0, 0.0)
    lag_normal[:, 1] = (1.0, 0.0, 0.0)
    lag_fn = np.zeros((n, 2), np.float32)
    lag_fn[:, 1] = lag_force
    common = [arr(x_start.astype(np.float32), wp.vec3), arr(np.zeros((n, 3), np.float32), wp.vec3),
              arr(np.full(n, 1e-3, np.float32), float), arr(np.zeros(n, np.int32), int), arr([1], int),
              arr(np.zeros((n, 3), np.float32), wp.vec3), wp.vec3(0.0, 0.0, 0.0), 0.01, pos, rot, pos, rot,
              arr([HALF.astype(np.float32)], wp.vec3), 1, arr(lag_fn.reshape(-1), float),
              arr(lag_normal.reshape(-1, 3), wp.vec3), arr(np.full(n, 1e4, np.float32), float), 5e-4, 0.0, 0.5, 1e-3]

    def energy(xx):
        out = wp.zeros(1, dtype=wp.float64, device=dev)
        wp.launch(ke.node_energy, n, [arr(xx.astype(np.float32), wp.vec3), *common, out], device=dev)
        return float(out.numpy()[0])

    outs = [wp.zeros(n, dtype=wp.vec3, device=dev), wp.zeros(n, dtype=wp.mat33, device=dev),
            wp.zeros(n, dtype=wp.mat33, device=dev), wp.zeros(n, dtype=wp.vec3, device=dev),
            wp.zeros(n, dtype=wp.vec3, device=dev), wp.zeros(1, dtype=float, device=dev),
            wp.zeros(1, dtype=wp.vec3, device=dev), wp.zeros(1, dtype=float, device=dev)]
    wp.launch(kc.evaluate_nodes, n, [arr(x.astype(np.float32), wp.vec3), *common, 1, *outs], device=dev)
    return energy, outs[0].numpy().astype(np.float64)


def test_the_contact_force_is_minus_the_gradient_of_the_energy_at_a_faces_edge():
    """Nodes 2 mm behind the +x face at 0.4-3 mm from its +y edge (the side face nearest for the
    first ones), with and without a lagged friction force (2 N, nodes slid 0.3 mm along z since the
    substep start): ``evaluate_nodes``' residual equals minus the central difference of
    ``node_energy`` (step 1e-5 m, at least 0.4 mm from where the counted face changes; float32
    positions of ~5e-2 m round by ~4e-9 m, 0.04 % of the step: within 1 % of the force plus
    0.05 N). With the force along the lagged face's normal instead of the returned one this fails
    at the nodes nearest the edge."""
    side = np.array([0.0004, 0.001, 0.0015, 0.003, 0.006])
    x = np.stack([np.full_like(side, HALF[0] - 0.002), 0.05 + HALF[1] - side, np.zeros_like(side)], axis=1)
    for lag_force, slid in ((0.0, 0.0), (2.0, 3e-4)):
        x_start = x - np.array([0.0, 0.0, slid])
        energy, residual = _node_contact(x, x_start, lag_force)
        assert np.abs(residual[:3, 1]).min() > 1.0  # the edge's nodes pushed out along +y
        step = 1e-5
        for i in range(len(x)):
            for j in range(3):
                xp, xm = x.copy(), x.copy()
                xp[i, j] += step
                xm[i, j] -= step
                fd = -(energy(xp) - energy(xm)) / (2 * step)
                assert abs(fd - residual[i, j]) < 0.01 * np.abs(residual[i]).max() + 0.05, (lag_force, i, j, fd,
                                                                                           residual[i, j])


def test_a_point_past_the_opposite_face_keeps_the_full_depth_behind_its_face():
    """A pad's corner swept across a node (a stiff cylinder in the contact fuzz, 2026-12-07): the node
    ended 0.6 mm past the face opposite the one it entered through, 0.03 mm inside the side of the
    box, so its depth measured to that side was 0.03 mm and the solve let it through. Past the
    opposite face within the face's extent the depth is the full depth behind the face (the box's
    thickness plus how far past, pushing it back out where it came in), with the face's normal; beside
    the extent there is no contact, as in front of the face."""
    past = np.array([[-HALF[0] - 0.0006, HALF[1] - 0.00003, 0.0],   # the fuzz's node: near the +y side
                     [-HALF[0] - 0.002, 0.0, HALF[2] - 0.0001],     # near the +z side
                     [-HALF[0] - 0.0001, 0.0, 0.0]])                # just past, mid-face
    depth, normal = contacts(past, (1.0, 0.0, 0.0))
    np.testing.assert_allclose(depth, HALF[0] - past[:, 0], atol=2e-8)
    assert (normal == [1.0, 0.0, 0.0]).all()
    inside = past.copy()  # the same points 0.5 mm inside the opposite face: the side rule holds
    inside[:, 0] = -HALF[0] + 0.0005
    depth, normal = contacts(inside, (1.0, 0.0, 0.0))
    np.testing.assert_allclose(depth[:2], [0.00003, 0.0001], atol=2e-8)
    beside = past + [0.0, 0.001, 0.0]  # the first is then beside the extent
    assert contacts(beside[:1], (1.0, 0.0, 0.0))[0][0] <= 0.0
