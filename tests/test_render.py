"""Tests of the headless renderer (defgrasp_env.render) against hand-computed truths.

Test camera: at (0, 0.5, 2) m looking along -z (horizontal), fov_y 60 deg, 160 x 120 px, so
right = +x, up = +y, focal length f = 60 / tan(30 deg) = 103.92 px, and a world point (x, y, z)
lands at column 80 + f (x - 0) / (2 - z), row 60 - f (y - 0.5) / (2 - z). Flat shading
(ambient 1, diffuse 0, no shadows) makes every surface exactly its colour.
"""

import math

import numpy as np
import pytest
import warp as wp

from defgrasp_env.render import COLORMAPS, Camera, RenderStyle, SceneRenderer, save_png

W, H = 160, 120
F_PX = 60.0 / math.tan(math.radians(30.0))
CAM = Camera(position=(0.0, 0.5, 2.0), look_at=(0.0, 0.5, 0.0), fov_y_deg=60.0, width=W, height=H)
FLAT = RenderStyle(object_color=(1.0, 0.0, 0.0), box_color=(0.0, 1.0, 0.0), ambient=1.0, diffuse=0.0,
                   shadows=False)
NO_BOX = (np.zeros((0, 3)), np.zeros((0, 4)), np.zeros((0, 3)))
RED, GREEN = (255, 0, 0), (0, 255, 0)
IDENTITY = np.array([[0.0, 0.0, 0.0, 1.0]])


def hand_project(p):
    """(column, row) of a world point for CAM, by the formula in the module docstring."""
    x, y, z = p
    return 80.0 + F_PX * x / (2.0 - z), 60.0 - F_PX * (y - 0.5) / (2.0 - z)


def big_triangle(z=0.0):
    verts = np.array([[-0.3, 0.3, z], [0.4, 0.35, z], [0.0, 0.8, z]], dtype=np.float32)
    return verts, np.array([[0, 1, 2]], dtype=np.int32)


def is_color(img, rc, rgb):
    return tuple(int(c) for c in img[rc[0], rc[1]]) == rgb


def test_camera_validation_and_default():
    cam = Camera()
    assert (cam.width, cam.height) == (224, 224)
    uv, depth = cam.project([[0.0, 0.0, 0.0], [0.0, 0.6, 0.0]])  # object base and goal in view
    assert np.all(depth > 0) and np.all((uv >= 0) & (uv < 224))
    with pytest.raises(ValueError, match=r"width must be in \[16, 4096\] pixels, got 15"):
        Camera(width=15)
    with pytest.raises(TypeError, match="height must be an int"):
        Camera(height=100.0)
    with pytest.raises(ValueError, match=r"fov_y_deg must be in \(1, 179\) degrees, got 179"):
        Camera(fov_y_deg=179)
    with pytest.raises(ValueError, match="look_at must differ from position"):
        Camera(position=(1, 1, 1), look_at=(1, 1, 1))
    with pytest.raises(ValueError, match="must not be parallel"):
        Camera(position=(0, 1, 0), look_at=(0, 0, 0))
    with pytest.raises(ValueError, match="position must be finite"):
        Camera(position=(0, float("nan"), 1))


def test_camera_project_matches_hand_formula():
    p = (0.2, 0.6, 0.0)
    uv, depth = CAM.project(p)
    assert np.allclose(uv[0], hand_project(p)) and np.isclose(depth[0], 2.0)
    assert np.isclose(CAM.focal_px, F_PX)


def test_triangle_lands_where_pinhole_projection_says():
    verts, tris = big_triangle()
    r = SceneRenderer(CAM, tris, 3, 0, device="cpu", style=FLAT)
    img = r.render(verts, *NO_BOX)
    assert img.shape == (H, W, 3) and img.dtype == np.uint8
    # expected coverage: pixel centres inside the hand-projected triangle, away from its edges
    a, b, c = (np.array(hand_project(v)) for v in verts)
    cols, rows = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    pts = np.stack([cols, rows], -1)

    def signed_dist(p, q):  # distance of the pixel centres to the edge line p->q, in pixels
        e = q - p
        return ((pts[..., 0] - p[0]) * e[1] - (pts[..., 1] - p[1]) * e[0]) / np.linalg.norm(e)

    d = np.stack([signed_dist(a, b), signed_dist(b, c), signed_dist(c, a)])
    inside = np.all(d > 0.5, 0) | np.all(d < -0.5, 0)
    outside = np.any(d > 0.5, 0) & np.any(d < -0.5, 0)
    red = np.all(img == RED, -1)
    assert inside.sum() > 300
    assert red[inside].all()
    assert not red[outside].any()
    # the centroid of the red region is the projected centroid of the triangle (to 0.5 px)
    rr, cc = np.nonzero(red)
    centroid = (a + b + c) / 3.0
    assert abs(cc.mean() + 0.5 - centroid[0]) < 0.5 and abs(rr.mean() + 0.5 - centroid[1]) < 0.5


def test_moving_vertices_moves_the_object():
    """The BVH is refitted each frame: a 0.1 m shift in x moves the image by f * 0.1 / 2 px."""
    verts, tris = big_triangle()
    r = SceneRenderer(CAM, tris, 3, 0, device="cpu", style=FLAT)
    c0 = np.nonzero(np.all(r.render(verts, *NO_BOX) == RED, -1))[1].mean()
    c1 = np.nonzero(np.all(r.render(verts + [0.1, 0.0, 0.0], *NO_BOX) == RED, -1))[1].mean()
    assert abs((c1 - c0) - F_PX * 0.1 / 2.0) < 0.5


def test_box_occludes_object_behind_it_and_not_in_front():
    verts, tris = big_triangle()
    r = SceneRenderer(CAM, tris, 3, 1, device="cpu", style=FLAT)
    half = np.array([[0.05, 0.05, 0.05]])
    probe = (0.0, 0.5, 0.0)  # inside the triangle, at the box's (x, y)
    col, row = hand_project(probe)
    rc = (int(row), int(col))
    in_front = r.render(verts, np.array([[0.0, 0.5, 0.5]]), IDENTITY, half)
    assert is_color(in_front, rc, GREEN)
    behind = r.render(verts, np.array([[0.0, 0.5, -0.5]]), IDENTITY, half)
    assert is_color(behind, rc, RED)
    # a box rotated 45 deg about y shows its edge: its projected half width grows by sqrt(2)
    s = math.sin(math.pi / 8)
    rotated = r.render(verts, np.array([[0.0, 0.5, 0.5]]), np.array([[0.0, s, 0.0, math.cos(math.pi / 8)]]), half)
    green_cols = np.nonzero(np.all(rotated[rc[0]] == GREEN, -1))[0]
    # the silhouette corners are the side corners (x = +-0.05 sqrt(2), z = 0.5), 1.5 m deep:
    # f * 0.0707 / 1.5 px each side of the centre column
    expected = 2 * F_PX * 0.05 * math.sqrt(2) / 1.5
    assert abs(len(green_cols) - expected) <= 2


def test_ground_checker_below_horizon_and_sky_above():
    tris = np.array([[0, 1, 2]], dtype=np.int32)
    far = np.array([[50.0, 50.0, -50.0], [51.0, 50.0, -50.0], [50.0, 51.0, -50.0]])  # out of view
    st = RenderStyle(shadows=False)
    img = SceneRenderer(CAM, tris, 3, 0, device="cpu", style=st).render(far, *NO_BOX).astype(int)
    # horizon of a horizontal camera is the middle row: rows < 60 sky, rows >= 60 ground
    sky, ground = img[:50], img[75:]
    assert np.all(sky[..., 2] - sky[..., 0] > 20)  # bluish
    assert np.all(np.abs(ground[..., 2] - ground[..., 0]) < 12)  # grey (a little fog)
    # checker parity at two pixels of the bottom row, from the ray/ground intersection by hand
    row = H - 1
    sy = (1.0 - 2.0 * (row + 0.5) / H) * math.tan(math.radians(30))
    values = {}
    for col in range(0, W, 7):
        sx = (2.0 * (col + 0.5) / W - 1.0) * math.tan(math.radians(30)) * W / H
        t = 0.5 / -sy  # along (sx, sy, -1): y = 0.5 + t sy = 0
        x, z = t * sx, 2.0 - t
        cell = math.floor(x / st.checker_size) + math.floor(z / st.checker_size)
        frac_x, frac_z = (x / st.checker_size) % 1.0, (z / st.checker_size) % 1.0
        if min(frac_x, 1 - frac_x, frac_z, 1 - frac_z) > 0.15:  # clearly inside a square
            values.setdefault(cell % 2, []).append(img[row, col, 0])
    assert len(values[0]) > 2 and len(values[1]) > 2
    assert min(values[0]) > max(values[1]) + 10  # even cells light, odd cells dark (AA fade lowers contrast)


def test_shadow_under_floating_box():
    tris = np.array([[0, 1, 2]], dtype=np.int32)
    far = np.array([[50.0, 50.0, -50.0], [51.0, 50.0, -50.0], [50.0, 51.0, -50.0]])
    box = (np.array([[0.0, 0.2, 0.0]]), IDENTITY, np.array([[0.3, 0.01, 0.3]]))
    col, row = hand_project((0.0, 0.0, 0.2))  # ground under the slab, visible below it
    imgs = {}
    for shadows in (True, False):
        st = RenderStyle(light_direction=(0.0, 1.0, 0.0), shadows=shadows)
        imgs[shadows] = SceneRenderer(CAM, tris, 3, 1, device="cpu", style=st).render(far, *box).astype(float)
    ratio = imgs[True][int(row), int(col)].mean() / imgs[False][int(row), int(col)].mean()
    assert 0.3 < ratio < 0.5  # ambient / (ambient + diffuse) = 0.35, plus a little fog
    outside = hand_project((0.6, 0.0, 0.2))
    assert np.array_equal(imgs[True][int(outside[1]), int(outside[0])], imgs[False][int(outside[1]), int(outside[0])])


def test_vertex_scalar_is_interpolated_barycentrically():
    verts, tris = big_triangle()
    r = SceneRenderer(CAM, tris, 3, 0, device="cpu", style=FLAT)
    cmap = np.asarray(COLORMAPS[FLAT.colormap])
    knots = np.linspace(0.0, 1.0, len(cmap))
    for hot in range(3):
        scalar = np.zeros(3)
        scalar[hot] = 10.0
        img = r.render(verts, *NO_BOX, vertex_scalar=scalar, scalar_range=(0.0, 10.0))
        w = np.full(3, 0.1)
        w[hot] = 0.8  # point with barycentric weight 0.8 on the hot vertex: value 8 -> 0.8
        col, row = hand_project(w @ verts)
        expected = 255 * np.array([np.interp(0.8, knots, cmap[:, k]) for k in range(3)])
        assert np.abs(img[int(row), int(col)] - expected).max() <= 8, hot


def test_render_is_deterministic_and_returns_a_copy():
    from defgrasp_env.render.example import example_scene

    v, t, c, q, h, s, g = example_scene()
    r = SceneRenderer(Camera(), t, len(v), len(c), device="cpu")
    a = r.render(v, c, q, h, vertex_scalar=s, goal=g)
    b = r.render(v, c, q, h, vertex_scalar=s, goal=g)
    c2 = SceneRenderer(Camera(), t, len(v), len(c), device="cpu").render(v, c, q, h, vertex_scalar=s, goal=g)
    assert a.shape == (224, 224, 3) and a.dtype == np.uint8
    assert np.array_equal(a, b) and np.array_equal(a, c2)
    assert a is not b and not np.shares_memory(a, b)
    assert len(np.unique(a.reshape(-1, 3), axis=0)) > 50  # not a blank image


def test_warp_array_inputs_match_numpy_inputs():
    from defgrasp_env.render.example import example_scene

    v, t, c, q, h, s, g = example_scene()
    cam = Camera(width=64, height=48)
    r = SceneRenderer(cam, t, len(v), len(c), device="cpu")
    ref = r.render(v, c, q, h, vertex_scalar=s, goal=g)
    as_vec = r.render(wp.array(v, dtype=wp.vec3, device="cpu"), wp.array(c, dtype=wp.vec3, device="cpu"),
                      wp.array(q, dtype=wp.quat, device="cpu"), wp.array(h, dtype=wp.vec3, device="cpu"),
                      vertex_scalar=wp.array(s, dtype=wp.float32, device="cpu"), goal=g)
    as_2d = r.render(*(wp.array(x, dtype=wp.float32, device="cpu") for x in (v, c, q, h)),
                     vertex_scalar=s, goal=g)
    assert np.array_equal(ref, as_vec) and np.array_equal(ref, as_2d)


def test_non_square_image_shape():
    verts, tris = big_triangle()
    img = SceneRenderer(Camera(width=64, height=32), tris, 3, 0, device="cpu").render(verts, *NO_BOX)
    assert img.shape == (32, 64, 3) and img.dtype == np.uint8


def test_bad_inputs_are_rejected_with_clear_messages():
    tris = np.array([[0, 1, 2]] * 40, dtype=np.int32)
    r = SceneRenderer(CAM, tris, 120, 2, device="cpu")
    v = np.zeros((120, 3))
    boxes = (np.zeros((2, 3)), np.tile(IDENTITY, (2, 1)), np.full((2, 3), 0.01))
    with pytest.raises(ValueError, match=r"vertices must have shape \(N, 3\) = \(120, 3\), got \(119, 3\)"):
        r.render(np.zeros((119, 3)), *boxes)
    with pytest.raises(ValueError, match=r"box_quats must have shape \(K, 4\) = \(2, 4\), got \(2, 3\)"):
        r.render(v, boxes[0], np.zeros((2, 3)), boxes[2])
    with pytest.raises(ValueError, match="box_quats must be non-zero"):
        r.render(v, boxes[0], np.zeros((2, 4)), boxes[2])
    with pytest.raises(ValueError, match=r"box_half_extents must be in \(0, inf\) m"):
        r.render(v, boxes[0], boxes[1], -boxes[2])
    with pytest.raises(ValueError, match="vertices must be finite"):
        r.render(np.full((120, 3), np.nan), *boxes)
    with pytest.raises(ValueError, match=r"vertex_scalar must have shape \(N,\) = \(120,\), got \(3,\)"):
        r.render(v, *boxes, vertex_scalar=np.zeros(3))
    with pytest.raises(ValueError, match="scalar_range must be finite"):
        r.render(v, *boxes, vertex_scalar=np.zeros(120), scalar_range=(1.0, 1.0))
    with pytest.raises(ValueError, match="scalar_range was given without vertex_scalar"):
        r.render(v, *boxes, scalar_range=(0.0, 1.0))
    with pytest.raises(ValueError, match=r"goal must have shape \(3,\)"):
        r.render(v, *boxes, goal=(0.0, 0.6))
    with pytest.raises(TypeError, match="must be float32"):
        r.render(wp.zeros(120, dtype=wp.vec2, device="cpu"), *boxes)
    with pytest.raises(ValueError, match=r"triangles must index vertices in \[0, 2\], got indices in \[0, 3\]"):
        SceneRenderer(CAM, np.array([[0, 1, 3]]), 3, 0, device="cpu")
    with pytest.raises(ValueError, match=r"triangles must have shape \(M, 3\)"):
        SceneRenderer(CAM, np.array([0, 1, 2]), 3, 0, device="cpu")
    with pytest.raises(ValueError, match="num_boxes must be >= 0, got -1"):
        SceneRenderer(CAM, np.array([[0, 1, 2]]), 3, -1, device="cpu")
    with pytest.raises(ValueError, match=r"ambient must be in \[0, 1\], got 2"):
        RenderStyle(ambient=2)
    with pytest.raises(ValueError, match="colormap must be one of"):
        RenderStyle(colormap="jet")


def test_save_png_round_trip(tmp_path):
    from defgrasp_env.render.image_io import png_bytes

    img = (np.arange(16 * 20 * 3) % 256).astype(np.uint8).reshape(16, 20, 3)
    path = save_png(tmp_path / "a" / "x.png", img)
    (tmp_path / "raw.png").write_bytes(png_bytes(img))
    PIL = pytest.importorskip("PIL.Image")
    assert np.array_equal(np.asarray(PIL.open(path)), img)
    assert np.array_equal(np.asarray(PIL.open(tmp_path / "raw.png")), img)


@pytest.mark.cuda
def test_cuda_matches_cpu():
    from defgrasp_env.render.example import example_scene

    v, t, c, q, h, s, g = example_scene()
    imgs = [SceneRenderer(Camera(), t, len(v), len(c), device=dev).render(v, c, q, h, vertex_scalar=s, goal=g)
            for dev in ("cpu", "cuda:0")]
    differ = np.any(np.abs(imgs[0].astype(int) - imgs[1].astype(int)) > 2, -1)
    assert differ.mean() < 0.005  # float rounding may flip a few edge pixels
