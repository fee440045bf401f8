"""Each world's substep start in one launch: a block of threads per world interpolates its pad poses,
saves its start positions and moves its nodes to the initial guess, lags its nodes' pad contacts,
searches its pad edge points' triangles and lags them, fixes the initial guess (nodes kept at their
pad depth, pushed edge triangles), seeds its tets' rotations and sets its Newton flags, with a block
barrier (``block_sync.py``) wherever a phase reads what other threads wrote.

Phase by phase this is thirteen launches (up to sixteen at a step's start) over the rows of every world
(``contact.interpolate_pads``, ``substep.begin_substep``, ``contact.lag_contacts``,
``pad_edge_search.clear_edge_search``, ``nearest_surface_triangles`` twice,
``pad_edge_lag.lag_edge_points``, ``contact.keep_pad_depth``, ``pad_edge_guess.clear_triangle_push``,
``edge_point_push``, ``push_triangles``, ``elastic.seed_rotations``, ``substep.begin_newton``, and at
a step's start ``substep.copy_world_rows`` twice and ``substep.clear_solve_report`` first): a lone
world on a GPU pays a launch's latency for each, in every substep. ``start_world_blocks`` calls the
same row functions in the same order per world (the push's clear moved before the search: nothing
reads it in between): bit-identical on the CPU (one thread per world). Like the phase kernels it
runs in every world, solved or not, moving only the nodes of the solved ones (``solve``).
"""

import warp as wp

wp.set_module_options({"enable_backward": False})  # forward only, as ``world_evaluate``

from .block_sync import block_barrier
from .contact import interpolate_pad, keep_pad_depth_node, lag_contact_node
from .elastic import seed_rotation_tet
from .pad_edge_guess import edge_point_push_slot, push_triangle
from .pad_edge_lag import lag_edge_point
from .pad_edge_search import NO_TRIANGLE, nearest_surface_triangle_pair
from .substep import begin_substep_node, clear_report_world


@wp.kernel
def start_world_blocks(
    threads: int,
    node_start: wp.array(dtype=int),
    tet_start: wp.array(dtype=int),
    solve: wp.array(dtype=int),
    # the step's start (substep.copy_world_rows, substep.clear_solve_report)
    copy_rows: int,
    in_positions: wp.array(dtype=wp.vec3),
    in_velocities: wp.array(dtype=wp.vec3),
    clear_report: int,
    newton_it: wp.array(dtype=int),
    cg_total: wp.array(dtype=int),
    diverged: wp.array(dtype=int),
    unconverged: wp.array(dtype=int),
    clamped: wp.array(dtype=int),
    penetration: wp.array(dtype=float),
    # pad poses (contact.interpolate_pad)
    step_pad_pos: wp.array(dtype=wp.vec3),
    step_pad_rot: wp.array(dtype=wp.quat),
    target_pad_pos: wp.array(dtype=wp.vec3),
    target_pad_rot: wp.array(dtype=wp.quat),
    s0: float,
    s1: float,
    # start and guess (substep.begin_substep_node)
    v: wp.array(dtype=wp.vec3),
    step_start: wp.array(dtype=wp.vec3),
    prescribed: wp.array(dtype=wp.vec3),
    dt: float,
    x_start: wp.array(dtype=wp.vec3),
    x: wp.array(dtype=wp.vec3),
    # nodes (contact.lag_contact_node, keep_pad_depth_node)
    node_world: wp.array(dtype=int),
    free: wp.array(dtype=wp.vec3),
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    stiffness: wp.array(dtype=float),
    knee: float,
    lag_normal_force: wp.array(dtype=float),
    lag_normal: wp.array(dtype=wp.vec3),
    # pad edge points (pad_edge_search, pad_edge_lag, pad_edge_guess; points_per_world 0: none)
    triangles: wp.array(dtype=wp.vec3i),
    triangle_world: wp.array(dtype=int),
    triangle_first: wp.array(dtype=int),
    points: wp.array(dtype=wp.vec3),
    point_first: wp.array(dtype=int),
    point_pad: wp.array(dtype=int),
    point_share: wp.array(dtype=float),
    points_per_world: int,
    best_dist: wp.array(dtype=float),
    best_tri: wp.array(dtype=int),
    point_tri: wp.array(dtype=int),
    point_bary: wp.array(dtype=wp.vec3),
    point_normal: wp.array(dtype=wp.vec3),
    point_stiffness: wp.array(dtype=float),
    point_allowed: wp.array(dtype=float),
    point_friction: wp.array(dtype=float),
    push: wp.array(dtype=float),
    push_normal: wp.array(dtype=wp.vec3),
    # tets (elastic.seed_rotation_tet)
    tets: wp.array(dtype=wp.vec4i),
    rest_inv: wp.array(dtype=wp.mat33),
    tet_rotation: wp.array(dtype=wp.quat),
    # Newton's flags (substep.begin_newton)
    newton_active: wp.array(dtype=int),
    substep_newton_it: wp.array(dtype=int),
    rotations_at_x: wp.array(dtype=int),
):
    """The start of the substep from fraction ``s0`` to ``s1`` of the step for world
    ``tid // threads`` (thread ``tid % threads`` of its block): if solved, at the step's start its rows
    of ``in_positions`` / ``in_velocities`` copied into ``x`` / ``v`` (``copy_rows``) and its report
    cleared (``clear_report``); its pad poses (``pad_pos0`` ...
    ``pad_rot1``) between the step's start (``step_pad_*``) and target (``target_pad_*``) poses,
    ``x_start`` = ``x`` (m) and ``x`` the initial guess x + ``dt`` v (prescribed axes: between
    ``step_start`` and ``prescribed``), the contacts lagged and the guess fixed. ``node_start`` /
    ``tet_start`` / ``triangle_first`` [W+1]: each world's rows."""
    tid = wp.tid()
    w = tid // threads
    lane = tid - w * threads
    n0 = node_start[w]
    n1 = node_start[w + 1]
    e0 = w * points_per_world
    e1 = e0 + points_per_world
    f0 = triangle_first[w]
    f1 = triangle_first[w + 1]
    if solve[w] != 0:
        if copy_rows != 0:
            for i in range(n0 + lane, n1, threads):
                x[i] = in_positions[i]
                v[i] = in_velocities[i]
        if clear_report != 0 and lane == 0:
            clear_report_world(w, newton_it, cg_total, diverged, unconverged, clamped, penetration)
    for k in range(lane, pads_per_world, threads):
        interpolate_pad(w * pads_per_world + k, step_pad_pos, step_pad_rot, target_pad_pos, target_pad_rot, s0, s1,
                        pad_pos0, pad_rot0, pad_pos1, pad_rot1)
    for i in range(n0 + lane, n1, threads):
        begin_substep_node(i, x, v, step_start, prescribed, free, node_world, solve, s1, dt, x_start)
    block_barrier()
    for i in range(n0 + lane, n1, threads):
        lag_contact_node(i, x_start, x, node_world, pad_pos0, pad_rot0, pad_pos1, pad_rot1, pad_half, pads_per_world,
                         stiffness, knee, lag_normal_force, lag_normal)
    if points_per_world > 0:
        for e in range(e0 + lane, e1, threads):
            best_dist[e] = 1.0e30  # pad_edge_search.clear_edge_search
            best_tri[e] = NO_TRIANGLE
        for t in range(f0 + lane, f1, threads):
            push[t] = 0.0  # pad_edge_guess.clear_triangle_push
        block_barrier()
        for choose in range(2):
            for pair in range(f0 * pads_per_world + lane, f1 * pads_per_world, threads):
                nearest_surface_triangle_pair(pair, x_start, x, triangles, triangle_world, pad_pos0, pad_rot0,
                                              pad_pos1, pad_rot1, pad_half, pads_per_world, points, point_first,
                                              points_per_world, choose, best_dist, best_tri)
            block_barrier()
        for e in range(e0 + lane, e1, threads):
            lag_edge_point(e, x_start, x, triangles, triangle_first, pad_pos0, pad_rot0, pad_pos1, pad_rot1, pad_half,
                           pads_per_world, points, point_pad, point_share, points_per_world, stiffness,
                           lag_normal_force, lag_normal, best_tri, point_tri, point_bary, point_normal,
                           point_stiffness, point_allowed, point_friction, knee)
    block_barrier()
    for i in range(n0 + lane, n1, threads):
        keep_pad_depth_node(i, x_start, node_world, solve, free, pad_pos0, pad_rot0, pad_pos1, pad_rot1, pad_half,
                            pads_per_world, lag_normal_force, lag_normal, x)
    if points_per_world > 0:
        block_barrier()
        for e in range(e0 + lane, e1, threads):
            edge_point_push_slot(e, x_start, triangles, solve, pad_pos0, pad_rot0, pad_pos1, pad_rot1, pad_half,
                                 pads_per_world, points, point_pad, points_per_world, point_tri, point_bary,
                                 point_normal, point_allowed, x, push, push_normal)
        block_barrier()
        for t in range(f0 + lane, f1, threads):
            push_triangle(t, triangles, triangle_world, solve, free, lag_normal_force, pads_per_world, push,
                          push_normal, x)
    block_barrier()
    for t in range(tet_start[w] + lane, tet_start[w + 1], threads):
        seed_rotation_tet(t, x, tets, rest_inv, tet_rotation)
    if lane == 0:  # substep.begin_newton
        newton_active[w] = solve[w]
        substep_newton_it[w] = 0
        rotations_at_x[w] = 0  # no line search of this substep yet (world_evaluate)
