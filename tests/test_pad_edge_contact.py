"""Pad edge contact's parts against independent references (``kernels/pad_edge_contact.py``,
``sim/pad_edge_points.py``): the nearest point of a triangle against dense sampling, the search's
triangle against a brute-force numpy search, the edge-point lattice against its definition, and the
contact force against central differences of its energy. The whole contact (a pad edge pressed
between surface nodes) is tested in ``test_fem_contact_edges.py``."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from defgrasp_env.sim.kernels import pad_edge_contact as kpe
from defgrasp_env.sim.kernels import pad_edge_guess as kpg
from defgrasp_env.sim.kernels import pad_edge_lag as kpl
from defgrasp_env.sim.kernels import pad_edge_hessian as kph
from defgrasp_env.sim.kernels import pad_edge_search as kps
from defgrasp_env.sim.materials import Material
from defgrasp_env.sim.meshing import make_object_mesh
from defgrasp_env.sim.model import ContactParams, build_model
from defgrasp_env.sim.pad_edge_points import EDGE_POINT_SPACING, pad_edge_points, surface_triangles
from defgrasp_env.sim.solver_scratch import EdgeContactScratch
from defgrasp_env.sim.world_compaction import every_row
from defgrasp_env.transforms import axis_angle_to_quat, quat_rotate
from geometry_reference import point_triangle_distances

HALF = np.array([0.008175, 0.01875, 0.011])  # the env's pad collision box (m)
KNEE = ContactParams().stiffening_depth
MU = ContactParams().pad_friction
EPS = 2e-5  # the friction's stick slip (m): 20 x the 1e-6 m finite-difference steps (the env's is ~1e-6 m)


@wp.kernel
def _closest(a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3), c: wp.array(dtype=wp.vec3),
             p: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = kps.closest_point_barycentric(a[i], b[i], c[i], p[i])


def test_closest_point_of_a_triangle_against_dense_sampling():
    """Random triangles and points (inside, beside every edge and vertex region): the kernel's
    nearest point is no farther than the nearest of ~5000 barycentric samples (to the samples'
    spacing), and its weights are a convex combination."""
    rng = np.random.default_rng(7)
    count = 300
    a, b, c = (rng.normal(0, 0.01, (count, 3)) for _ in range(3))
    p = rng.normal(0, 0.015, (count, 3))
    arrays = [wp.array(v.astype(np.float32), dtype=wp.vec3, device="cpu") for v in (a, b, c, p)]
    out = wp.zeros(count, dtype=wp.vec3, device="cpu")
    wp.launch(_closest, count, [*arrays, out], device="cpu")
    bary = out.numpy().astype(np.float64)
    assert np.all(bary >= -1e-6) and np.allclose(bary.sum(1), 1.0, atol=1e-5)
    n = 100
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    w = np.stack([i[keep], j[keep], n - i[keep] - j[keep]], 1) / n
    for k in range(count):
        tri = np.stack([a[k], b[k], c[k]])
        samples = w @ tri
        best = np.linalg.norm(samples - p[k], axis=1).min()
        got = np.linalg.norm(bary[k] @ tri - p[k])
        spacing = np.linalg.norm(tri - np.roll(tri, 1, 0), axis=1).max() / n
        assert got <= best + 1e-6, (k, got, best)
        assert got >= best - spacing - 1e-6, (k, got, best)


@pytest.mark.parametrize("half, spacing", [(HALF, EDGE_POINT_SPACING), ((0.01, 0.002, 0.005), 0.0033)])
def test_edge_points_lie_on_every_edge_at_most_spacing_apart_with_each_corner_once(half, spacing):
    points, pads, share, first = pad_edge_points(np.asarray([half, half]), spacing)
    assert first.tolist() == [0, len(points) // 2, len(points)] and pads.tolist() == [0] * first[1] + [1] * first[1]
    one = points[: first[1]].astype(np.float64)
    on_faces = np.isclose(np.abs(one), 1.0)
    assert np.all(on_faces.sum(1) >= 2)  # every point on a box edge
    corners = one[on_faces.sum(1) == 3]
    assert len(corners) == 8 and len(np.unique(corners, axis=0)) == 8
    assert len(np.unique(one, axis=0)) == len(one)  # no point twice
    for axis in range(3):  # neighbours along each of the 12 edges at most ``spacing`` apart
        others = [j for j in range(3) if j != axis]
        for sb in (-1, 1):
            for sc in (-1, 1):
                on = one[np.isclose(one[:, others[0]], sb) & np.isclose(one[:, others[1]], sc)]
                along = np.sort(on[:, axis]) * half[axis]
                assert np.isclose(along[0], -half[axis]) and np.isclose(along[-1], half[axis])
                assert np.diff(along).max() <= spacing + 1e-9
    # the edge length each point stands for sums to the 12 edges' length (corners counted on x)
    assert np.isclose(share[: first[1]].sum(), 8 * np.sum(half), rtol=0.15)


def _model(name="cuboid", e=1e6):
    mesh = make_object_mesh(name)
    return mesh, build_model([mesh, mesh], [Material(youngs_modulus=e)] * 2, pad_half_extents=[HALF, HALF],
                             contact=ContactParams(edge_contact=True), device="cpu")


def _search(model, edges, x, pos, rot, start=None, lag=None):
    """Run the search and lag kernels with the nodes still at x and the pads at (pos, rot) at the
    substep's end, at (start, rot) at its start (default: pos); ``lag``: the nodes' pad contacts
    (lag_normal_force [N*(P+1)], lag_normal [N*(P+1), 3]; default none)."""
    xw = wp.array(x.astype(np.float32), dtype=wp.vec3, device="cpu")
    pw = wp.array(pos.astype(np.float32), dtype=wp.vec3, device="cpu")
    qw = wp.array(rot.astype(np.float32), dtype=wp.quat, device="cpu")
    p0 = pw if start is None else wp.array(start.astype(np.float32), dtype=wp.vec3, device="cpu")
    pads = (p0, qw, pw, qw)
    slots = model.num_worlds * edges.points_per_world
    contacts = model.num_nodes * (model.pads_per_world + 1)
    force, normal = lag if lag is not None else (np.zeros(contacts, np.float32), np.zeros((contacts, 3), np.float32))
    lag_arrays = (wp.array(force, dtype=float, device="cpu"), wp.array(normal, dtype=wp.vec3, device="cpu"))
    args = (xw, xw, edges.triangles, edges.triangle_world, *pads, model.pad_half_extents, model.pads_per_world,
            edges.points, edges.point_first, edges.points_per_world)
    wp.launch(kps.clear_edge_search, slots, [edges.best_dist, edges.best_tri], device="cpu")
    for choose in (0, 1):
        wp.launch(kps.nearest_surface_triangles, edges.triangles.shape[0] * model.pads_per_world,
                  [*args, choose, edges.best_dist, edges.best_tri], device="cpu")
    wp.launch(kpl.lag_edge_points, slots, [xw, xw, edges.triangles, edges.triangle_first, *pads,
                                           model.pad_half_extents,
                                           model.pads_per_world, edges.points, edges.point_pad, edges.point_share,
                                           edges.points_per_world, model.node_contact_stiffness,
                                           *lag_arrays,
                                           edges.best_tri, edges.point_tri, edges.point_bary, edges.point_normal,
                                           edges.point_stiffness, edges.point_allowed, edges.point_friction, KNEE],
              device="cpu")
    return xw, pads


def _pad_points_world(edges, pos, rot, model):
    points = edges.points.numpy().astype(np.float64)
    pad_of = edges.point_pad.numpy()
    out = []
    for w in range(model.num_worlds):
        k = w * model.pads_per_world + pad_of
        out.append(pos[k] + quat_rotate(rot[k], points * HALF))
    return np.concatenate(out)


def test_search_finds_the_nearest_surface_triangle_of_the_points_own_world():
    """Two worlds of the cuboid (the second shifted so that its object overlaps no pad of world 0),
    pads placed across the objects' surfaces at random poses: every edge point within the search
    radius (2 mm, nothing moves) of a triangle that faces its pad's centre gets a triangle of its
    own world at the brute-force nearest distance among those (float32) and that triangle's
    outward normal, unless it lies outside the cube deeper than the skin behind that triangle's
    plane (``lag_edge_points`` drops it: beside a convex edge); points farther away get none."""
    _, model = _model()
    edges = EdgeContactScratch.from_model(model)
    tris, tri_world = surface_triangles(model)
    x = model.rest_positions.numpy().astype(np.float64)
    x[model.world_nodes(1)] += np.array([0.3, 0.0, 0.0])
    boxes = [(x[model.world_nodes(w)].min(0), x[model.world_nodes(w)].max(0)) for w in range(2)]
    rng = np.random.default_rng(11)
    checked = dropped = 0
    for trial in range(6):
        rot = rng.normal(size=(4, 4))
        rot /= np.linalg.norm(rot, axis=1, keepdims=True)
        # pad centres near the objects' top and side faces, half a pad inside
        pos = np.array([[0.0, 0.04, 0.0], [0.02, 0.02, 0.0], [0.3, 0.04, 0.01], [0.32, 0.02, 0.0]])
        pos += rng.normal(0, 0.004, pos.shape)
        _search(model, edges, x, pos, rot)
        q = _pad_points_world(edges, pos, rot, model)
        got = edges.point_tri.numpy()
        normals = edges.point_normal.numpy()
        per_world = edges.points_per_world
        for slot in range(len(q)):
            w = slot // per_world
            centre = pos[w * model.pads_per_world + edges.point_pad.numpy()[slot % per_world]]
            a, b, c = (x[tris[:, j]] for j in range(3))
            facing = np.cross(b - a, c - a) @ (centre - q[slot]) > 0
            mine = np.flatnonzero((tri_world == w) & facing)
            d = point_triangle_distances(q[slot], x[tris[mine]])
            best = d.min()
            if best > kps.SEARCH_MARGIN * 0.999:
                if best > kps.SEARCH_MARGIN * 1.001:
                    assert got[slot] == -1, (slot, best)
                continue
            outside = not np.all((q[slot] > boxes[w][0]) & (q[slot] < boxes[w][1]))
            t = got[slot]
            if t == -1:  # dropped: outside, deeper than the skin behind a triangle at the nearest distance
                tied = mine[d <= best + 2e-6]
                assert outside and max(_plane_depth(q[slot], x[tris[k]]) for k in tied) > 2 * KNEE, slot
                dropped += 1
                continue
            assert tri_world[t] == w, (slot, t)
            assert abs(point_triangle_distances(q[slot], x[tris[t]][None])[0] - best) < 2e-6, (slot, best)
            assert not (outside and _plane_depth(q[slot], x[tris[t]]) > 2 * KNEE + 1e-6), slot
            a, b, c = x[tris[t]]
            n = np.cross(b - a, c - a)
            assert np.allclose(normals[slot], n / np.linalg.norm(n), atol=1e-5)
            checked += 1
    assert checked > 200 and dropped > 0, (checked, dropped)


def _plane_depth(q, tri):
    """How far (m) q lies behind the plane of triangle tri [3, 3] (outward normal by the right-hand rule)."""
    a, b, c = tri
    n = np.cross(b - a, c - a)
    return float(n @ (a - q) / np.linalg.norm(n))


def _tilted_pad_pressed():
    """Two cuboid worlds (E = 1e6) and a pad of world 0 tilted so that its lowest corner ends the
    substep 1.2 mm below the top face, coming from 3 mm higher, searched: (model, edges, x rest
    positions, xw their Warp array, pad poses)."""
    _, model = _model(e=1e6)
    edges = EdgeContactScratch.from_model(model)
    x = model.rest_positions.numpy().astype(np.float64)
    top = x[:, 1].max()
    axis = np.array([1.0, 0.0, 0.3])
    rot = np.repeat(axis_angle_to_quat(0.5 * axis / np.linalg.norm(axis))[None], 4, 0)
    pos = np.array([[0.003, 0.0, 0.002], [0.3, 1.0, 0.0], [0.3, 1.0, 0.0], [0.3, 1.0, 0.0]])
    lowest = (quat_rotate(rot[:1], (np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T * HALF))[:, 1]
              .min())
    pos[0, 1] = top - lowest - 0.0012  # the lowest corner 1.2 mm below the face
    xw, pads = _search(model, edges, x, pos, rot, start=pos + np.array([0.0, 0.003, 0.0]))  # it came from above
    return model, edges, x, xw, pads


@pytest.mark.parametrize("slip", [None, 0.5, 3.0])
def test_edge_point_force_is_minus_the_gradient_of_its_energy(slip):
    """A pad pressed 1.2 mm into the cuboid's top face at a tilt over the substep (from 3 mm
    higher), so its edge points lie at depths past the skin and the cubic knee: the force the evaluate kernel adds to the nodes
    equals minus the central-difference gradient of the energy kernel (float64 sums; step 1e-6 m),
    and the force on the pad balances the nodes' forces. ``slip``: without friction, or with a
    lagged normal force of 2 N on every point and the nodes slid sideways by that many stick slips
    since the substep start (0.5: the smoothed law's sticking part; 3: sliding)."""
    model, edges, x, xw, pads = _tilted_pad_pressed()
    n = model.num_nodes
    active = wp.ones(model.num_worlds, dtype=int, device="cpu")
    slots = model.num_worlds * edges.points_per_world
    shift = 0.0 if slip is None else slip * EPS
    x_start = wp.array((x - shift * np.array([0.6, 0.0, 0.8])).astype(np.float32), dtype=wp.vec3, device="cpu")
    if slip is not None:
        edges.point_friction.assign(np.where(edges.point_tri.numpy() >= 0, 2.0, 0.0).astype(np.float32))
    args = (x_start, edges.triangles, active, *pads, model.pad_half_extents, model.pads_per_world, edges.points,
            edges.point_pad, edges.points_per_world, edges.point_tri, edges.point_bary, edges.point_normal,
            edges.point_stiffness, edges.point_allowed, edges.point_friction, KNEE, MU, EPS)

    def energy(xx):
        out = wp.zeros(model.num_worlds, dtype=wp.float64, device="cpu")
        wp.launch(kpe.edge_point_energy, slots,
                  [wp.array(xx.astype(np.float64).astype(np.float32), dtype=wp.vec3, device="cpu"), *args, out],
                  device="cpu")
        return float(out.numpy().sum())

    zeros = lambda dtype: wp.zeros(n, dtype=dtype, device="cpu")  # noqa: E731
    residual, diag, force = zeros(wp.vec3), zeros(wp.mat33), zeros(wp.vec3)
    hess = edges.point_block
    pad_fn = wp.zeros(4, dtype=float, device="cpu")
    pad_f = wp.zeros(4, dtype=wp.vec3, device="cpu")
    pen = wp.zeros(2, dtype=float, device="cpu")
    wp.launch(kpe.evaluate_edge_points, slots,
              [xw, *args, edges.triangle_first, 1, residual, diag, hess, force, pad_fn, pad_f, pen],
              device="cpu")
    f = residual.numpy().astype(np.float64)
    touched = np.flatnonzero(np.abs(f).sum(1) > 0)
    assert len(touched) >= 3 and pen.numpy()[0] > 2 * KNEE  # (depth beyond the skin: past the cubic knee)
    assert np.allclose(-f.sum(0), pad_f.numpy()[0], rtol=1e-4, atol=1e-4)
    eps = 1e-6
    for i in touched[:12]:
        for j in range(3):
            xp, xm = x.copy(), x.copy()
            xp[i, j] += eps
            xm[i, j] -= eps
            fd = -(energy(xp) - energy(xm)) / (2 * eps)
            assert abs(fd - f[i, j]) < 0.02 * np.abs(f[i]).max() + 1e-3, (i, j, fd, f[i, j])


def _expect_point_blocks(model, edges, x, x_start, pads):
    """Each pressed or rubbing edge point's Hessian block as ``evaluate_edge_points`` left it equals
    the block built here in float64 from the penalty law (``contact.penalty_stiffness``) and the
    smoothed Coulomb law (``contact.friction_coefficient``: f1(s)/s = 1/s beyond the stick slip,
    2/eps - s/eps^2 below), on the slip of the triangle's surface point against the pad (both pad
    poses share their rotation here: the slip is the surface point's motion less the pad's)."""
    tri, bary, normal = edges.point_tri.numpy(), edges.point_bary.numpy(), edges.point_normal.numpy()
    stiffness, allowed = edges.point_stiffness.numpy(), edges.point_allowed.numpy()
    lag, blocks = edges.point_friction.numpy(), edges.point_block.numpy()
    tris, points, point_pad = edges.triangles.numpy(), edges.points.numpy(), edges.point_pad.numpy()
    p0, q1, p1, half = pads[0].numpy(), pads[3].numpy(), pads[2].numpy(), model.pad_half_extents.numpy()
    q_count, checked = edges.points_per_world, 0
    for slot in np.flatnonzero(tri >= 0):
        w, q = divmod(int(slot), q_count)
        pad = w * model.pads_per_world + point_pad[q]
        n, wts, ids = normal[slot].astype(np.float64), bary[slot].astype(np.float64), tris[tri[slot]]
        end = p1[pad] + quat_rotate(q1[pad:pad + 1].astype(np.float64), (points[q] * half[pad])[None])[0]
        g = n @ (wts @ x[ids] - end) - allowed[slot]
        expected = np.zeros((3, 3))
        if g > 0:
            e = max(g - KNEE, 0.0)
            expected += stiffness[slot] * (1 + 3 * e * e / KNEE**2) * np.outer(n, n)
        if lag[slot] > 0:
            slip = wts @ (x[ids] - x_start[ids]) - (p1[pad] - p0[pad])
            st = np.linalg.norm(slip - (slip @ n) * n)
            f1_over_s = 1 / st if st >= EPS else 2 / EPS - st / EPS**2
            expected += MU * lag[slot] * f1_over_s * (np.eye(3) - np.outer(n, n))
        if np.any(expected):
            np.testing.assert_allclose(blocks[slot], expected, rtol=1e-3, atol=1e-4 * np.abs(expected).max())
            checked += 1
    assert checked >= 1


@pytest.mark.parametrize("friction", [False, True])
def test_edge_point_hessian_product_and_coarse_block_against_the_force_and_the_product(friction):
    """The pressed points of the tilted pad above (depths past the knee): (a) the Hessian product
    ``edge_point_product`` equals the central difference of minus the force along random
    directions (the depth is affine in the nodes, the penalty C1 beyond g = 0, so this is exact to
    float32 rounding of the 1e-6 m steps: 2 % of the product's largest entry); with friction (2 N
    lagged, sliding 3 stick slips sideways) along random normal directions, which leave the
    tangential slip and so the friction force as they are (the friction block is the usual lagged
    approximation c (I - n n^T), not the exact Jacobian of a sliding force); (b)
    ``coarse_assemble_edge_points`` gives T^T H T for node aggregates (T: the unit translations and
    rotations of each aggregate about an anchor node, some axes fixed), built column by column from
    the product, friction included (E's lower triangle: all that is assembled)."""
    model, edges, x, xw, pads = _tilted_pad_pressed()
    n, slots = model.num_nodes, model.num_worlds * edges.points_per_world
    active = wp.ones(model.num_worlds, dtype=int, device="cpu")
    shift = 3.0 * EPS if friction else 0.0
    x_start = wp.array((x - shift * np.array([0.6, 0.0, 0.8])).astype(np.float32), dtype=wp.vec3, device="cpu")
    if friction:
        edges.point_friction.assign(np.where(edges.point_tri.numpy() >= 0, 2.0, 0.0).astype(np.float32))
    args = (x_start, edges.triangles, active, *pads, model.pad_half_extents, model.pads_per_world, edges.points,
            edges.point_pad, edges.points_per_world, edges.point_tri, edges.point_bary, edges.point_normal,
            edges.point_stiffness, edges.point_allowed, edges.point_friction, KNEE, MU, EPS)

    def force(xx):
        out = wp.zeros(n, dtype=wp.vec3, device="cpu")
        wp.launch(kpe.evaluate_edge_points, slots,
                  [wp.array(xx.astype(np.float32), dtype=wp.vec3, device="cpu"), *args, edges.triangle_first, 0, out,
                   wp.zeros(n, dtype=wp.mat33, device="cpu"), edges.point_block, wp.zeros(n, dtype=wp.vec3, device="cpu"),
                   wp.zeros(4, dtype=float, device="cpu"), wp.zeros(4, dtype=wp.vec3, device="cpu"),
                   wp.zeros(2, dtype=float, device="cpu")], device="cpu")
        return out.numpy().astype(np.float64)

    def product(direction):
        out = wp.zeros(n, dtype=wp.vec3, device="cpu")
        wp.launch(kph.edge_point_product, slots,
                  [wp.array(direction.astype(np.float32), dtype=wp.vec3, device="cpu"), edges.triangles, active,
                   edges.points_per_world, edges.point_tri, edges.point_bary, edges.point_block, out,
                   every_row("cpu")], device="cpu")
        return out.numpy().astype(np.float64)

    f0 = force(x)  # sets point_hessian at x
    touched = np.abs(f0).sum(1) > 0
    assert touched.sum() >= 3 and (edges.point_block.numpy() > 0).sum() >= 1
    rng = np.random.default_rng(3)
    eps = 1e-6
    for _ in range(3):
        direction = np.where(touched[:, None], rng.normal(size=(n, 3)), 0.0)
        if friction:  # the top face's normal, +y
            direction[:, [0, 2]] = 0.0
        hp = product(direction)
        fd = -(force(x + eps * direction) - force(x - eps * direction)) / (2 * eps)
        force(x)  # back to the curvature at x
        assert np.abs(hp).max() > 0
        np.testing.assert_allclose(hp, fd, atol=0.02 * np.abs(hp).max())
    if friction:  # the blocks, from the documented laws: s n n^T (penalty) + mu f_n f1(s)/s (I - n n^T)
        _expect_point_blocks(model, edges, x, x - shift * np.array([0.6, 0.0, 0.8]), pads)
    # (b) coarse block: 3 aggregates by node id, anchors their first nodes, axis z fixed on every 5th node
    aggregate = anchor = np.arange(n) % 3
    free = np.ones((n, 3), np.float32)
    free[::5, 2] = 0.0
    matrix = wp.zeros((model.num_worlds, 18, 18), dtype=wp.float64, device="cpu")
    ints = [wp.array(a.astype(np.int32), dtype=int, device="cpu") for a in (aggregate, anchor)]
    wp.launch(kph.coarse_assemble_edge_points, slots,
              [edges.triangles, active, edges.points_per_world, edges.point_tri, edges.point_bary, edges.point_block,
               wp.array(free, dtype=wp.vec3, device="cpu"), ints[0], wp.array(x.astype(np.float32), dtype=wp.vec3,
                                                                                device="cpu"), ints[1], matrix],
              device="cpu")
    got, lever = matrix.numpy()[0], x.astype(np.float32).astype(np.float64)
    lever, columns = lever - lever[anchor], np.zeros((18, n, 3))
    for a, k in np.ndindex(3, 3):
        mine = (aggregate == a) & (model.node_world.numpy() == 0)
        columns[6 * a + k, mine] = free[mine] * np.eye(3)[k]
        columns[6 * a + 3 + k, mine] = free[mine] * np.cross(np.eye(3)[k], lever[mine])
    expected = np.einsum("inj,knj->ik", columns, np.stack([product(c) for c in columns]) * free[None])
    assert np.abs(np.tril(expected, -1)).max() > 0 and np.all(np.triu(got, 1) == 0.0)
    # scaled by the diagonal (rotation entries are ~lever^2 times the translations'): each entry to 1e-5
    scale = 1.0 / np.sqrt(np.where(np.diag(expected) > 0, np.diag(expected), 1.0))
    np.testing.assert_allclose(scale[:, None] * got * scale, scale[:, None] * np.tril(expected) * scale, rtol=1e-4,
                               atol=1e-5)


def _one_triangle_model():
    """A model of one cuboid world with one pad, its scratch, and the pad 1 mm above the top face
    at the substep start and 2.5 mm lower at its end (its bottom face's edges driven 1.5 mm into
    the face): (model, edges, x, start, end) with x the rest positions."""
    mesh = make_object_mesh("cuboid")
    model = build_model([mesh], [Material(youngs_modulus=1e6)], pad_half_extents=[HALF],
                        contact=ContactParams(edge_contact=True), device="cpu")
    x = model.rest_positions.numpy().astype(np.float64)
    top = x[:, 1].max()
    start = np.array([[0.001, top + HALF[1] + 0.001, 0.002]])
    return model, EdgeContactScratch.from_model(model), x, start, start - np.array([[0.0, 0.0025, 0.0]])


def _push(model, edges, x_start, pads, x):
    """``edge_point_push`` from nodes at ``x_start`` (substep start) and the guess ``x``: each triangle's push (m)."""
    wp.launch(kpg.clear_triangle_push, edges.triangles.shape[0], [edges.push], device="cpu")
    wp.launch(kpg.edge_point_push, model.num_worlds * edges.points_per_world,
              [wp.array(x_start.astype(np.float32), dtype=wp.vec3, device="cpu"), edges.triangles,
               wp.ones(1, dtype=int, device="cpu"), *pads, model.pad_half_extents, model.pads_per_world, edges.points,
               edges.point_pad, edges.points_per_world, edges.point_tri, edges.point_bary, edges.point_normal,
               edges.point_allowed, x, edges.push, edges.push_normal], device="cpu")
    return edges.push.numpy()


@pytest.mark.parametrize("start_depth", [0.0012, 0.0015])
def test_initial_guess_keeps_the_depth_a_point_had_at_the_substep_start(start_depth):
    """A pad edge already pressed into the face at the substep start (1.2 or 1.5 mm, past the 0.5 mm
    skin) and ending 1.5 mm deep: only the depth the pad's motion adds is pushed out (0.3 mm or
    none), as a node touching a pad keeps its start depth; pushing a held point out to its kept
    depth in every substep cost three extra Newton iterations per held grasp substep."""
    model, edges, x, start, end = _one_triangle_model()
    rot = np.array([[0.0, 0.0, 0.0, 1.0]])
    start = end + np.array([[0.0, 0.0015 - start_depth, 0.0]])
    xw, pads = _search(model, edges, x, end, rot, start=start)
    tri = edges.point_tri.numpy()
    hit = sorted(set(tri[tri >= 0].tolist()))
    assert hit, "no edge point met a triangle"
    allowed = edges.point_allowed.numpy()[tri >= 0]
    pressed = allowed > 2 * KNEE + 1e-6  # the bottom edges' points (those above the face keep the skin)
    assert pressed.sum() >= 8
    np.testing.assert_allclose(allowed[pressed], start_depth - KNEE, atol=2e-6)
    # the friction's lagged normal force: the penalty of the start depth beyond the kept one (a knee)
    stiffness = edges.point_stiffness.numpy()[tri >= 0]
    np.testing.assert_allclose(edges.point_friction.numpy()[tri >= 0][pressed], stiffness[pressed] * KNEE, rtol=0.02)
    assert np.all(edges.point_friction.numpy()[tri >= 0][~pressed] == 0.0)  # above the face at the start
    push = _push(model, edges, x, pads, xw)
    np.testing.assert_allclose(push[hit], 0.0015 - start_depth, atol=2e-6)


def test_initial_guess_moves_a_triangle_out_of_its_points_way_but_not_nodes_touching_a_pad():
    """``edge_point_push`` and ``push_triangles`` against the geometry worked by hand: the pad's
    bottom edges end 1.5 mm below the top face, 1 mm deeper than the 0.5 mm skin they may keep, so
    every triangle under them moves down by that excess; a node marked as touching the pad stays put."""
    model, edges, x, start, end = _one_triangle_model()
    rot = np.array([[0.0, 0.0, 0.0, 1.0]])
    xw, pads = _search(model, edges, x, end, rot, start=start)
    tri = edges.point_tri.numpy()
    hit = sorted(set(tri[tri >= 0].tolist()))
    assert hit, "no edge point met a triangle"
    tris = edges.triangles.numpy()
    touching = int(tris[hit[0]][0])
    lag_force = np.zeros(model.num_nodes * 2, np.float32)
    lag_force[touching * 2 + 1] = 1.0  # that node touches the pad (slot 1 + k, k = 0)
    lag = wp.array(lag_force, dtype=float, device="cpu")
    push = _push(model, edges, x, pads, xw)
    np.testing.assert_allclose(push[hit], 0.0015 - 2 * KNEE, atol=2e-6)  # 1.5 mm deep, 0.5 mm kept
    assert np.all(push[np.setdiff1d(np.arange(len(tris)), hit)] == 0.0)
    wp.launch(kpg.push_triangles, len(tris), [edges.triangles, edges.triangle_world, wp.ones(1, dtype=int, device="cpu"),
                                              model.free_axes, lag, model.pads_per_world, edges.push,
                                              edges.push_normal, xw], device="cpu")
    moved = xw.numpy().astype(np.float64) - x
    assert np.all(moved[touching] == 0.0)
    counts = np.zeros(model.num_nodes)
    for t in hit:
        counts[tris[t]] += 1
    counts[touching] = 0
    # each free node of a pushed top-face triangle moves down by the excess once per such triangle
    np.testing.assert_allclose(moved[:, 1], -counts * (0.0015 - 2 * KNEE), atol=1e-6)
    np.testing.assert_allclose(moved[:, [0, 2]], 0.0, atol=1e-7)


def test_no_edge_contact_where_the_object_wraps_the_pad():
    """``lag_edge_points`` drops a point whose triangle has nodes touching its pad on two different
    faces, or on a face the triangle does not face; one node on a face the triangle faces keeps it."""
    model, edges, x, start, end = _one_triangle_model()
    rot = np.array([[0.0, 0.0, 0.0, 1.0]])
    _search(model, edges, x, end, rot, start=start)
    base = edges.point_tri.numpy().copy()
    slot = int(np.flatnonzero(base >= 0)[0])
    a, b, _ = edges.triangles.numpy()[base[slot]]
    cases = {  # node: pad face normal (pad frame) it touches; the triangle's normal is +y
        "faced": ({a: (0.0, -1.0, 0.0)}, True),                       # the pad's bottom face, facing the top face
        "not faced": ({a: (0.0, 1.0, 0.0)}, False),                   # the pad's top face
        "two faces": ({a: (0.0, -1.0, 0.0), b: (1.0, 0.0, 0.0)}, False),
    }
    for name, (touch, kept) in cases.items():
        force = np.zeros(model.num_nodes * 2, np.float32)
        normal = np.zeros((model.num_nodes * 2, 3), np.float32)
        for node, face in touch.items():
            force[node * 2 + 1], normal[node * 2 + 1] = 1.0, face
        _search(model, edges, x, end, rot, start=start, lag=(force, normal))
        assert bool(edges.point_tri.numpy()[slot] >= 0) is kept, name


@pytest.mark.parametrize("where, offset, expected", [
    ("beside the cube, behind the top face's extended plane", (0.010, -0.008), 0.0),
    ("inside, nearest the top face", (-0.006, -0.003), 0.003),
    ("inside, nearest the side face", (-0.001, -0.003), 0.001),
])
def test_reported_penetration_is_how_deep_a_pressed_point_lies_inside_the_object(where, offset, expected):
    """One pressed edge point held against a top-face triangle at the cuboid's +x edge, its pad's
    corner placed (x offset from the +x face, y offset from the top face, m): the world's reported
    penetration is the point's distance to the nearest face beyond the skin where it lies inside the
    cube, and nothing where it lies beside it, although its plane depth reads 8 mm there (before
    2026-11-26 the plane depth was reported: a policy's pad beside a cube's edge read 7-12 mm and
    flagged the step pierced). The contact's force still follows the plane depth."""
    model, edges, x, _, _ = _one_triangle_model()
    t, top, side, z = _top_edge_triangle(edges, x)
    q = np.array([side + offset[0], top + offset[1], z])
    slot = 0  # the pad's first edge point: placed at q by the pad's position (no rotation)
    pen, pad_fn = _reported_penetration(model, edges, x, q - edges.points.numpy()[slot] * HALF, [slot], t)
    assert pad_fn > 0.0, where  # pressed: its plane depth is past the skin
    skin = kpe.SKIN_KNEES * KNEE
    assert pen == pytest.approx(max(expected - skin, 0.0), abs=2e-6), where


@pytest.mark.parametrize("edge", [1.0, -1.0])
def test_reported_penetration_is_the_same_whichever_point_runs_first(edge):
    """Two pressed edge points of one pad on the same top-face triangle at the cuboid's +x (or -x)
    edge, the pad's bottom 3 mm below the top face and straddling the edge: the bottom edge point
    over the cube (6 mm in from its side) lies 3 mm inside it, the one on the far side of the pad
    beside it, 3 mm behind the plane as well. The reading is the inside point's 3 mm less the skin
    with either point first in the launch (mirrored: the points swap roles), so the kernel's skip
    of points that cannot raise the reading does not depend on their order."""
    model, edges, x, _, _ = _one_triangle_model()
    t, top, side, z = _top_edge_triangle(edges, x, edge)
    points = edges.points.numpy()
    inner = -edge  # the pad's bottom edge point (unit x) over the cube
    slots = [int(np.flatnonzero(np.isclose(points[:, 0], u) & np.isclose(points[:, 1], -1.0)
                                & np.isclose(points[:, 2], 0.0, atol=0.2))[0]) for u in (inner, edge)]
    over = np.array([side - edge * 0.006, top - 0.003, z])  # where the inner point lies
    pen, pad_fn = _reported_penetration(model, edges, x, over - points[slots[0]] * HALF, slots, t)
    assert pad_fn > 0.0
    assert pen == pytest.approx(0.003 - kpe.SKIN_KNEES * KNEE, abs=2e-6)


def _reported_penetration(model, edges, x, pad_position, slots, t):
    """``evaluate_edge_points`` (recording) with the one pad at ``pad_position`` (no rotation) and
    the edge points ``slots`` held against triangle t (normal +y, barycentric centre, 1e4 N/m, kept
    depth the skin): (the world's reported penetration (m), the pad's normal force (N))."""
    pos = np.asarray(pad_position, np.float64)[None]
    rot = np.array([[0.0, 0.0, 0.0, 1.0]])
    pads = tuple(wp.array(v.astype(np.float32), dtype=dt, device="cpu")
                 for v, dt in ((pos, wp.vec3), (rot, wp.quat), (pos, wp.vec3), (rot, wp.quat)))
    count = edges.points_per_world
    tri = np.full(count, -1, np.int32)
    tri[slots] = t
    edges.point_tri.assign(tri)
    edges.point_bary.assign(np.full((count, 3), 1.0 / 3.0, np.float32))
    edges.point_normal.assign(np.tile(np.float32([0.0, 1.0, 0.0]), (count, 1)))
    edges.point_stiffness.assign(np.full(count, 1e4, np.float32))
    edges.point_allowed.assign(np.full(count, kpe.SKIN_KNEES * KNEE, np.float32))
    edges.point_friction.zero_()
    xw = wp.array(x.astype(np.float32), dtype=wp.vec3, device="cpu")
    n = model.num_nodes
    pad_fn = wp.zeros(1, dtype=float, device="cpu")
    pen = wp.zeros(1, dtype=float, device="cpu")
    zeros = lambda dtype: wp.zeros(n, dtype=dtype, device="cpu")  # noqa: E731
    wp.launch(kpe.evaluate_edge_points, count,
              [xw, xw, edges.triangles, wp.ones(1, dtype=int, device="cpu"), *pads, model.pad_half_extents,
               model.pads_per_world, edges.points, edges.point_pad, count, edges.point_tri, edges.point_bary,
               edges.point_normal, edges.point_stiffness, edges.point_allowed, edges.point_friction, KNEE, MU, EPS,
               edges.triangle_first, 1, zeros(wp.vec3), zeros(wp.mat33), edges.point_block, zeros(wp.vec3), pad_fn,
               wp.zeros(1, dtype=wp.vec3, device="cpu"), pen], device="cpu")
    return float(pen.numpy()[0]), float(pad_fn.numpy()[0])


def _top_edge_triangle(edges, x, edge=1.0):
    """A top-face triangle of the cuboid at its +x (``edge`` 1) or -x (-1) edge: (triangle id, top y,
    that side face's x, the triangle's mean z)."""
    tris = edges.triangles.numpy()
    top, side = x[:, 1].max(), (x[:, 0] * edge).max() * edge
    corners = x[tris]
    at_edge = np.flatnonzero(np.all(np.isclose(corners[:, :, 1], top), 1)
                             & np.isclose((corners[:, :, 0] * edge).max(1), side * edge))
    t = int(at_edge[0])
    return t, top, side, float(corners[t, :, 2].mean())


@pytest.mark.parametrize("where, offset, kept", [
    ("beside the cube, 8 mm behind the top face's extended plane", (0.010, -0.008), False),
    ("beside the cube, within the skin behind the plane", (0.010, -0.0003), True),
    ("in front of the top face", (-0.004, 0.001), True),
    ("inside, 3 mm under the top face", (-0.006, -0.003), True),
])
def test_a_point_found_deep_behind_its_plane_but_outside_the_object_gets_no_contact(where, offset, kept):
    """``lag_edge_points`` given a top-face triangle at the cuboid's +x edge for the pad's first
    edge point (as the search may give one whose motion window reaches it), the point placed (x
    offset from the +x face, y offset from the top face, m) at the substep start and end: a point
    deeper than the skin behind the plane is dropped where it lies outside the cube (it touches
    nothing: held, it pushed the face a knee's worth in every substep) and kept inside it; a point
    within the skin or in front of the face is kept wherever it is (a pad edge approaching)."""
    model, edges, x, _, _ = _one_triangle_model()
    t, top, side, z = _top_edge_triangle(edges, x)
    slot = 0
    pos = (np.array([side + offset[0], top + offset[1], z]) - edges.points.numpy()[slot] * HALF)[None]
    rot = np.array([[0.0, 0.0, 0.0, 1.0]])
    pads = tuple(wp.array(v.astype(np.float32), dtype=dt, device="cpu")
                 for v, dt in ((pos, wp.vec3), (rot, wp.quat), (pos, wp.vec3), (rot, wp.quat)))
    best = np.full(edges.points_per_world, kps.NO_TRIANGLE, np.int32)
    best[slot] = t
    edges.best_tri.assign(best)
    xw = wp.array(x.astype(np.float32), dtype=wp.vec3, device="cpu")
    contacts = model.num_nodes * (model.pads_per_world + 1)
    wp.launch(kpl.lag_edge_points, edges.points_per_world,
              [xw, xw, edges.triangles, edges.triangle_first, *pads, model.pad_half_extents, model.pads_per_world,
               edges.points, edges.point_pad, edges.point_share, edges.points_per_world, model.node_contact_stiffness,
               wp.zeros(contacts, dtype=float, device="cpu"), wp.zeros(contacts, dtype=wp.vec3, device="cpu"),
               edges.best_tri, edges.point_tri, edges.point_bary, edges.point_normal, edges.point_stiffness,
               edges.point_allowed, edges.point_friction, KNEE], device="cpu")
    assert bool(edges.point_tri.numpy()[slot] == t) is kept, where
