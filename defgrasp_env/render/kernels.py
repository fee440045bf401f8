"""Warp kernels of the headless ray-cast renderer: one thread per pixel (or per vertex).

Everything is in the world frame (y up, metres). Kernels take arrays and scalars only; the
launcher is :class:`defgrasp_env.render.renderer.SceneRenderer`. They contain no device-specific
code, so the same module runs on ``"cpu"`` and ``"cuda:N"``.
"""

from __future__ import annotations

import warp as wp

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})

HIT_NONE = wp.constant(0)
HIT_GROUND = wp.constant(1)
HIT_BOX = wp.constant(2)
HIT_MESH = wp.constant(3)
HIT_GOAL = wp.constant(4)
T_FAR = wp.constant(1.0e6)  # metres; "no hit" distance
SHADOW_EPS = wp.constant(1.0e-4)  # metres; shadow-ray origin offset along the normal


@wp.func
def ray_box(o: wp.vec3, d: wp.vec3, c: wp.vec3, q: wp.quat, h: wp.vec3, t_max: float) -> wp.vec4:
    """Closest entry of the ray o + t d (unit d, 0 < t < t_max) into the oriented box (centre c,
    rotation q xyzw body-to-world, normalised here, half extents h). Returns (t, n) with n the
    outward world normal of the entered face, or t = -1 on a miss (also when o is inside)."""
    # cheap reject with the bounding sphere (radius |h|): most rays miss every box
    oc = o - c
    b = wp.dot(oc, d)
    disc = b * b - (wp.dot(oc, oc) - wp.dot(h, h))
    if disc < 0.0:
        return wp.vec4(-1.0, 0.0, 0.0, 0.0)
    root = wp.sqrt(disc)
    if -b + root <= 0.0 or -b - root >= t_max:
        return wp.vec4(-1.0, 0.0, 0.0, 0.0)
    q = wp.normalize(q)
    ol = wp.quat_rotate_inv(q, oc)
    dl = wp.quat_rotate_inv(q, d)
    t_near = float(-1.0e30)
    t_far = float(1.0e30)
    axis = int(-1)
    miss = bool(False)
    for k in range(3):
        if wp.abs(dl[k]) < 1.0e-12:
            if wp.abs(ol[k]) > h[k]:
                miss = True
        else:
            t1 = (-h[k] - ol[k]) / dl[k]
            t2 = (h[k] - ol[k]) / dl[k]
            ta = wp.min(t1, t2)
            tb = wp.max(t1, t2)
            if ta > t_near:
                t_near = ta
                axis = k
            t_far = wp.min(t_far, tb)
    if miss or axis < 0 or t_near > t_far or t_near <= 0.0:
        return wp.vec4(-1.0, 0.0, 0.0, 0.0)
    nl = wp.vec3(0.0, 0.0, 0.0)
    nl[axis] = -wp.sign(dl[axis])
    n = wp.quat_rotate(q, nl)
    return wp.vec4(t_near, n[0], n[1], n[2])


@wp.func
def ray_sphere(o: wp.vec3, d: wp.vec3, c: wp.vec3, r: float) -> float:
    """Smallest t > 0 with |o + t d - c| = r for unit d, or -1 on a miss."""
    oc = o - c
    b = wp.dot(oc, d)
    disc = b * b - (wp.dot(oc, oc) - r * r)
    if disc < 0.0:
        return -1.0
    s = wp.sqrt(disc)
    t = -b - s
    if t <= 0.0:
        t = -b + s
    if t <= 0.0:
        return -1.0
    return t


@wp.func
def colormap_lookup(cmap: wp.array(dtype=wp.vec3), x: float) -> wp.vec3:
    """Linear interpolation in the control-point table cmap at x in [0, 1] (clamped)."""
    n = cmap.shape[0]
    s = wp.clamp(x, 0.0, 1.0) * float(n - 1)
    i = wp.min(int(wp.floor(s)), n - 2)
    f = s - float(i)
    return cmap[i] * (1.0 - f) + cmap[i + 1] * f


@wp.func
def occluded(mesh: wp.uint64, o: wp.vec3, d: wp.vec3, box_c: wp.array(dtype=wp.vec3),
             box_q: wp.array(dtype=wp.quat), box_h: wp.array(dtype=wp.vec3)) -> bool:
    """True if the ray o + t d (t > 0) hits the object mesh or any box."""
    if wp.mesh_query_ray_anyhit(mesh, o, d, T_FAR):
        return True
    for k in range(box_c.shape[0]):
        if ray_box(o, d, box_c[k], box_q[k], box_h[k], T_FAR)[0] > 0.0:
            return True
    return False


@wp.kernel
def vertex_normals_kernel(points: wp.array(dtype=wp.vec3), indices: wp.array(dtype=wp.int32),
                          adj_offsets: wp.array(dtype=wp.int32), adj_faces: wp.array(dtype=wp.int32),
                          normals: wp.array(dtype=wp.vec3)):
    """Area-weighted unit vertex normals [N] from the faces incident to each vertex (CSR
    adjacency adj_offsets [N+1], adj_faces); a fixed summation order keeps it deterministic."""
    v = wp.tid()
    n = wp.vec3(0.0, 0.0, 0.0)
    for a in range(adj_offsets[v], adj_offsets[v + 1]):
        f = adj_faces[a]
        p0 = points[indices[3 * f + 0]]
        p1 = points[indices[3 * f + 1]]
        p2 = points[indices[3 * f + 2]]
        n = n + wp.cross(p1 - p0, p2 - p0)
    length = wp.length(n)
    if length > 0.0:
        n = n / length
    normals[v] = n


@wp.kernel
def rows_to_vec3_kernel(src: wp.array2d(dtype=wp.float32), dst: wp.array(dtype=wp.vec3)):
    """Copy a float32 [P, 3] array into a vec3 [P] array."""
    i = wp.tid()
    dst[i] = wp.vec3(src[i, 0], src[i, 1], src[i, 2])


@wp.kernel
def rows_to_quat_kernel(src: wp.array2d(dtype=wp.float32), dst: wp.array(dtype=wp.quat)):
    """Copy a float32 [P, 4] array (x, y, z, w) into a quat [P] array."""
    i = wp.tid()
    dst[i] = wp.quat(src[i, 0], src[i, 1], src[i, 2], src[i, 3])


@wp.kernel
def render_kernel(
    mesh: wp.uint64,
    indices: wp.array(dtype=wp.int32),
    vnormals: wp.array(dtype=wp.vec3),
    vscalar: wp.array(dtype=wp.float32),
    use_scalar: int,
    scalar_lo: float,
    scalar_hi: float,
    cmap: wp.array(dtype=wp.vec3),
    box_c: wp.array(dtype=wp.vec3),
    box_q: wp.array(dtype=wp.quat),
    box_h: wp.array(dtype=wp.vec3),
    box_col: wp.array(dtype=wp.vec3),
    goal: wp.vec3,
    goal_radius: float,
    has_goal: int,
    cam_pos: wp.vec3,
    cam_right: wp.vec3,
    cam_up: wp.vec3,
    cam_fwd: wp.vec3,
    tan_half_fov_y: float,
    light: wp.vec3,
    ambient: float,
    diffuse: float,
    shadows: int,
    object_color: wp.vec3,
    goal_color: wp.vec3,
    checker_light: wp.vec3,
    checker_dark: wp.vec3,
    checker_size: float,
    sky_horizon: wp.vec3,
    sky_zenith: wp.vec3,
    fog_distance: float,
    image: wp.array3d(dtype=wp.uint8),
):
    """Ray-cast one pixel (row i from the top, column j from the left) into image [H, W, 3]."""
    i, j = wp.tid()
    height = image.shape[0]
    width = image.shape[1]
    sx = (2.0 * (float(j) + 0.5) / float(width) - 1.0) * tan_half_fov_y * float(width) / float(height)
    sy = (1.0 - 2.0 * (float(i) + 0.5) / float(height)) * tan_half_fov_y
    d = wp.normalize(cam_fwd + sx * cam_right + sy * cam_up)
    o = cam_pos

    best_t = float(T_FAR)
    kind = int(HIT_NONE)
    n = wp.vec3(0.0, 1.0, 0.0)
    color = wp.vec3(0.0, 0.0, 0.0)

    # ground plane y = 0 (seen from either side)
    if wp.abs(d[1]) > 1.0e-9:
        tg = -o[1] / d[1]
        if tg > 0.0 and tg < best_t:
            best_t = tg
            kind = HIT_GROUND
    # oriented boxes
    for k in range(box_c.shape[0]):
        hb = ray_box(o, d, box_c[k], box_q[k], box_h[k], best_t)
        if hb[0] > 0.0 and hb[0] < best_t:
            best_t = hb[0]
            kind = HIT_BOX
            n = wp.vec3(hb[1], hb[2], hb[3])
            color = box_col[k]
    # goal marker
    if has_goal != 0:
        ts = ray_sphere(o, d, goal, goal_radius)
        if ts > 0.0 and ts < best_t:
            best_t = ts
            kind = HIT_GOAL
            n = wp.normalize(o + ts * d - goal)
            color = goal_color
    # deformable object (closest hit nearer than everything above)
    q = wp.mesh_query_ray(mesh, o, d, best_t)
    if q.result:
        best_t = q.t
        kind = HIT_MESH
        w = 1.0 - q.u - q.v
        f = q.face
        i0 = indices[3 * f + 0]
        i1 = indices[3 * f + 1]
        i2 = indices[3 * f + 2]
        fn = wp.normalize(q.normal)
        if wp.dot(fn, d) > 0.0:
            fn = -fn
        n = q.u * vnormals[i0] + q.v * vnormals[i1] + w * vnormals[i2]
        if wp.length(n) < 1.0e-6:
            n = fn
        n = wp.normalize(n)
        if wp.dot(n, d) > 0.0:
            n = -n
        color = object_color
        if use_scalar != 0:
            s = q.u * vscalar[i0] + q.v * vscalar[i1] + w * vscalar[i2]
            color = colormap_lookup(cmap, (s - scalar_lo) / (scalar_hi - scalar_lo))

    p = o + best_t * d
    if kind == HIT_GROUND:
        n = wp.vec3(0.0, wp.sign(o[1]), 0.0)
        fx = wp.floor(p[0] / checker_size)
        fz = wp.floor(p[2] / checker_size)
        parity = (fx + fz) - 2.0 * wp.floor(0.5 * (fx + fz))
        color = checker_light * (1.0 - parity) + checker_dark * parity
        # fade the checker to its mean as a pixel's ground footprint (m, along the view) grows
        # from 1/4 to 3/4 of a square, where it would alias (anti-aliasing)
        footprint = best_t * 2.0 * tan_half_fov_y / float(height) / wp.max(wp.abs(d[1]), 1.0e-4)
        fade = wp.clamp(2.0 * footprint / checker_size - 0.5, 0.0, 1.0)
        color = color * (1.0 - fade) + 0.5 * (checker_light + checker_dark) * fade

    out = wp.vec3(0.0, 0.0, 0.0)
    if kind == HIT_NONE:
        e = wp.clamp(d[1], 0.0, 1.0)
        out = sky_horizon * (1.0 - e) + sky_zenith * e
    else:
        lam = wp.max(wp.dot(n, light), 0.0)
        if shadows != 0 and lam > 0.0 and kind != HIT_GOAL:
            if occluded(mesh, p + SHADOW_EPS * n, light, box_c, box_q, box_h):
                lam = 0.0
        out = color * (ambient + diffuse * lam)
        if kind == HIT_GROUND:
            fog = 1.0 - wp.exp(-best_t / fog_distance)
            out = out * (1.0 - fog) + sky_horizon * fog

    for c in range(3):
        image[i, j, c] = wp.uint8(int(wp.clamp(out[c] * 255.0 + 0.5, 0.0, 255.0)))
