"""Warp kernels of the pickup scene outside the FEM solver, on the simulation's device: the
state remap of a rebuild (worlds whose object changed at a reset), the per-world readouts of a
step (feature point, keypoints, finiteness), which reduce the full state to small [W, ...] arrays,
and the pad loads of a solve packed for one download.
Kernels take arrays and scalars only; the launchers are in ``scene.py`` / ``readouts.py``."""

from __future__ import annotations

from typing import Any

import warp as wp


@wp.kernel
def gather_rows(src: wp.array(dtype=Any), index: wp.array(dtype=wp.int32), dst: wp.array(dtype=Any)):
    """``dst[i] = src[index[i]]`` where ``index[i] >= 0``; rows with ``index[i] < 0`` are left as they are."""
    i = wp.tid()
    j = index[i]
    if j >= 0:
        dst[i] = src[j]


@wp.kernel
def world_readouts(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), node_start: wp.array(dtype=wp.int32),
                   feature_position: wp.array(dtype=wp.vec3d), feature_velocity: wp.array(dtype=wp.vec3d),
                   finite: wp.array(dtype=wp.int32)):
    """One thread per world w: the mean node position and velocity (float64, summed in node order,
    as ``numpy.add.reduceat`` over float64 rows sums them) and whether every node position and
    velocity of the world is finite (1) or not (0)."""
    w = wp.tid()
    start = node_start[w]
    end = node_start[w + 1]
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
def scatter_rows(values: wp.array(dtype=Any), index: wp.array(dtype=wp.int32), dst: wp.array(dtype=Any)):
    """``dst[index[k]] = values[k]``."""
    k = wp.tid()
    dst[index[k]] = values[k]


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
def pack_pad_loads(pad_normal_force: wp.array(dtype=wp.float32), pad_force: wp.array(dtype=wp.vec3),
                   loads: wp.array(dtype=wp.vec4)):
    """``loads[p] = (pad_normal_force[p], pad_force[p])``: what the host needs of the pads after a
    solve, packed for one download."""
    p = wp.tid()
    f = pad_force[p]
    loads[p] = wp.vec4(pad_normal_force[p], f[0], f[1], f[2])
