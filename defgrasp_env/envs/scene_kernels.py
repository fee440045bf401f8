"""Warp kernels of the pickup scene outside the FEM solver, on the simulation's device: the
state remap of a rebuild (worlds whose object changed at a reset), the per-world readouts of a
step (feature point, keypoints, finiteness, object material inside a pad), which reduce the full
state to small [W, ...] arrays,
the force limit's loads of a solve and the readouts, each packed for one download (the limit's
decisions on the device: ``limit_kernels``).
Kernels take arrays and scalars only; the launchers are in ``scene.py`` / ``readouts.py``."""

from __future__ import annotations

from typing import Any

import warp as wp

from ..gripper.kernels import actuator_load
from ..sim.kernels.pad_faces import box_penetration
from ..sim.kernels.elastic import spare_tet
from ..sim.kernels.world_rows import scatter_rows  # noqa: F401  (the scene's row writes)

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


@wp.kernel
def gather_rows(src: wp.array(dtype=Any), index: wp.array(dtype=wp.int32), dst: wp.array(dtype=Any)):
    """``dst[i] = src[index[i]]`` where ``index[i] >= 0``; rows with ``index[i] < 0`` are left as they are."""
    i = wp.tid()
    j = index[i]
    if j >= 0:
        dst[i] = src[j]


@wp.kernel
def world_readouts(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), node_start: wp.array(dtype=wp.int32),
                   node_end: wp.array(dtype=wp.int32), feature_position: wp.array(dtype=wp.vec3d),
                   feature_velocity: wp.array(dtype=wp.vec3d), finite: wp.array(dtype=wp.int32)):
    """One thread per world w over its object's nodes ``node_start[w]:node_end[w]`` (``Model``):
    the mean node position and velocity (float64, summed in node order, as ``numpy.add.reduceat``
    over float64 rows sums them) and whether every node position and velocity of the world is
    finite (1) or not (0)."""
    w = wp.tid()
    start = node_start[w]
    end = node_end[w]
    sx = wp.vec3d()
    sv = wp.vec3d()
    ok = int(1)
    for i in range(start, end):
        xi = x[i]
        vi = v[i]
        sx = sx + wp.vec3d(wp.float64(xi[0]), wp.float64(xi[1]), wp.float64(xi[2]))
        sv = sv + wp.vec3d(wp.float64(vi[0]), wp.float64(vi[1]), wp.float64(vi[2]))
        if not (wp.isfinite(xi) and wp.isfinite(vi)):
            ok = 0
    n = wp.float64(end - start)
    feature_position[w] = sx / n
    feature_velocity[w] = sv / n
    finite[w] = ok


@wp.kernel
def gather_keypoints(x: wp.array(dtype=wp.vec3), index: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.vec3)):
    """``out[k] = x[index[k]]``, zero where ``index[k] < 0`` (an object with fewer surface nodes
    than keypoints)."""
    k = wp.tid()
    j = index[k]
    if j >= 0:
        out[k] = x[j]
    else:
        out[k] = wp.vec3()


@wp.kernel
def zero_vec3_rows_of_worlds(a: wp.array(dtype=wp.vec3), row_world: wp.array(dtype=wp.int32),
                             mask: wp.array(dtype=wp.int32)):
    """``a[i] = 0`` where the world of row i (``row_world[i]``) has ``mask != 0``."""
    i = wp.tid()
    if mask[row_world[i]] != 0:
        a[i] = wp.vec3()


@wp.kernel
def zero_float_rows_of_worlds(a: wp.array(dtype=wp.float32), row_world: wp.array(dtype=wp.int32),
                              mask: wp.array(dtype=wp.int32)):
    """``a[i] = 0`` where the world of row i (``row_world[i]``) has ``mask != 0``."""
    i = wp.tid()
    if mask[row_world[i]] != 0:
        a[i] = 0.0


@wp.kernel
def world_max(values: wp.array(dtype=wp.float32), row_world: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.float32)):
    """``out[w]`` = max(itself, the largest of ``values``' rows of world w) (``out`` cleared before)."""
    i = wp.tid()
    wp.atomic_max(out, row_world[i], values[i])


#: a row of ``solve_loads``: (load at the substep start, held, the solve's load, finite, its force
#: error, the update deciding it), float64
solve_load_row = wp.types.vector(length=6, dtype=wp.float64)


@wp.kernel
def solve_loads(pad_normal_force: wp.array(dtype=wp.float32), pad_force: wp.array(dtype=wp.vec3),
                limits: wp.array(dtype=wp.vec2d), wrist_limit: wp.float64, grip_limit: wp.float64,
                last_update: wp.array(dtype=wp.float32), newton_tolerance: wp.float32,
                stiffness: wp.array(dtype=wp.float32), force_unit: wp.float64, loads: wp.array(dtype=solve_load_row)):
    """What the actuator force limit needs of world w after a solve (its two pads' normal forces
    ``pad_normal_force[2w], [2w+1]`` and total forces ``pad_force``, N), packed for one download:
    ``loads[w]`` = (the load at the substep start and 1 if held at the limit, ``limits[w]`` of
    ``Gripper.plan_substep``; the solve's actuator load, ``wrist.force_limit.actuator_load``, plus
    its force error; 1 if the pad forces are all finite, else 0; the force error; the last update (m)
    under which the load as read plus its force error stays under 1, 0 where it is not under 1).

    A solve whose last Newton update ``last_update[w]`` (m) is above ``newton_tolerance`` did not
    converge, and its pad forces are off by about a node's contact stiffness times that update or
    more (``stiffness[w]``: the world's stiffest node, N/m), also where its pads read no force at all
    (the iterate may not have reached a contact the solution has: a stiff cube pressed into the
    ground by pads at a 1 N limit read 0 N with an update of 12 mm, then kN): its load counts that
    much more (the force error, in units of ``force_unit``, N: the smaller of the limits' forces;
    inf: limits off, no margin), so that an unconverged solve that reads under the limit but may be
    over it is re-solved patiently (``PickupScene._patient_if_over``, down to a fraction of the
    deciding update) and the limit decides on converged forces; an unconverged solve of a soft
    object rarely counts (E = 1e4: ~3,000 N/m x 3e-4 m = 0.9 N), a stiff one's does from an update
    of ~0.2 mm (1e6 N/m over 150 N). (Measured: a stiff cube swept at 2 m/s, accepted at 164 N with
    a last update of 7 mm, read 1.5 kN solved on.)"""
    w = wp.tid()
    a = pad_force[2 * w]
    b = pad_force[2 * w + 1]
    n0 = pad_normal_force[2 * w]
    n1 = pad_normal_force[2 * w + 1]
    left = wp.vec3d(wp.float64(a[0]), wp.float64(a[1]), wp.float64(a[2]))
    right = wp.vec3d(wp.float64(b[0]), wp.float64(b[1]), wp.float64(b[2]))
    load = actuator_load(left, right, wp.float64(n0), wp.float64(n1), wrist_limit, grip_limit)
    dx = last_update[w]
    error = wp.float64(0.0)
    deciding = wp.float64(0.0)
    k = wp.float64(stiffness[w])
    if wp.isfinite(force_unit):
        if dx > newton_tolerance:
            error = k * wp.float64(dx) / force_unit
        if load < wp.float64(1.0) and k > wp.float64(0.0):
            deciding = (wp.float64(1.0) - load) * force_unit / k
    finite = wp.float64(0.0)
    if wp.isfinite(a) and wp.isfinite(b) and wp.isfinite(n0) and wp.isfinite(n1):
        finite = wp.float64(1.0)
    lim = limits[w]
    loads[w] = solve_load_row(lim[0], lim[1], load + error, finite, error, deciding)


@wp.kernel
def deepest_material_in_pads(x: wp.array(dtype=wp.vec3), tets: wp.array(dtype=wp.vec4i),
                             tet_world: wp.array(dtype=wp.int32), pad_positions: wp.array(dtype=wp.vec3),
                             pad_orientations: wp.array(dtype=wp.quat), pad_half: wp.array(dtype=wp.vec3),
                             pads_per_world: int, depth: wp.array(dtype=wp.float32)):
    """One thread per (tet, pad of its world): ``depth[w]`` = max(itself, how deep (m) the tet's
    centroid lies inside the pad box, from its nearest face). Node contact keeps the object's nodes
    out of the pads, not its interior: a pad that sinks in between surface nodes (a box edge or
    corner pressed into a coarse face, or a pad pushed through the object) holds material, and its
    centroids, inside it. ``depth`` must be cleared (zeros) before the launch."""
    tid = wp.tid()
    t = tid // pads_per_world
    w = tet_world[t]
    pad = w * pads_per_world + tid % pads_per_world
    n = tets[t]
    if spare_tet(n):  # parked 1 km above the task
        return
    c = 0.25 * (x[n[0]] + x[n[1]] + x[n[2]] + x[n[3]])
    local = wp.quat_rotate_inv(pad_orientations[pad], c - pad_positions[pad])
    d, normal = box_penetration(local, pad_half[pad])
    if d > 0.0:
        wp.atomic_max(depth, w, d)


@wp.kernel
def pack_readouts(feature_position: wp.array(dtype=wp.vec3d), feature_velocity: wp.array(dtype=wp.vec3d),
                  keypoints: wp.array(dtype=wp.vec3), finite: wp.array(dtype=wp.int32),
                  pad_embedding: wp.array(dtype=wp.float32), per_world: int, out: wp.array2d(dtype=wp.float64)):
    """Row w of ``out`` [W, 8 + 3 per_world] (float64): world w's feature point, its velocity, its
    ``per_world`` keypoints (float32 widened exactly), its finiteness flag (0 or 1) and its pad
    embedding (m): the readouts of a state packed for one download."""
    w = wp.tid()
    fp = feature_position[w]
    fv = feature_velocity[w]
    for i in range(3):
        out[w, i] = fp[i]
        out[w, 3 + i] = fv[i]
    for k in range(per_world):
        p = keypoints[w * per_world + k]
        for i in range(3):
            out[w, 6 + 3 * k + i] = wp.float64(p[i])
    out[w, 6 + 3 * per_world] = wp.float64(finite[w])
    out[w, 7 + 3 * per_world] = wp.float64(pad_embedding[w])
