"""Each world's substep end in one launch: a block of threads per solved world puts nodes left too
deep back within the penetration bound, sets the substep's velocities and, after an advance's last
substep, runs the outputs pass at the returned positions (pad loads, contact and elastic forces,
von Mises stress, the residual's norm, the mean stress) and copies the pad poses; then the new
velocities become the state's. A block barrier (``block_sync.py``) stands wherever a phase reads
what other threads wrote.

Phase by phase this is ``contact.clamp_depth``, ``substep.end_substep``, at the last substep the six
launches of the outputs pass (``substep.clear_outputs``, ``contact.evaluate_nodes``,
``pad_edge_contact.evaluate_edge_points``, ``elastic.evaluate_tets`` with ``outputs`` = 1,
``linear_solve.begin_linear_solve``, ``substep.mean_stress``), a clear of CG's ``rz`` and
``substep.copy_pad_poses``, then ``substep.copy_world_rows`` of the velocities: a lone world on a GPU
pays a launch's latency for each, in every substep (the scene advances the solver a substep at a
time; a control period's earlier substeps need only the contact part of the outputs:
``CONTACT_OUTPUTS``). ``finish_world_blocks`` calls the same row functions in the same order per world:
bit-identical on the CPU (one thread per world). A world not solved only has its ``rz`` cleared
after an outputs pass (the phase kernels also cleared its CG vectors, which nothing reads before its
next solve sets them again).
"""

import warp as wp

wp.set_module_options({"enable_backward": False})  # forward only, as ``world_evaluate``

from .block_sync import block_barrier
from .contact import clamp_depth_node, evaluate_node
from .elastic import evaluate_tet
from .linear_solve import begin_node_solve
from .pad_edge_contact import evaluate_edge_point
from .substep import end_substep_node, mean_stress_block

#: ``finish_world_blocks``'s ``outputs``: none (not an advance's last substep); the whole outputs pass;
#: or only the contact part (pad loads, contact forces, penetration: what a control period's earlier
#: substeps are read for, ``ImplicitSolver.advance(full_outputs=False)``): the elastic forces and the
#: residual's norm are then left at 0 (the nodes' pass clears them) and the von Mises stresses and
#: their mean as they were.
NO_OUTPUTS = wp.constant(0)
ALL_OUTPUTS = wp.constant(1)
CONTACT_OUTPUTS = wp.constant(2)


@wp.kernel
def finish_world_blocks(
    threads: int,
    node_start: wp.array(dtype=int),
    tet_start: wp.array(dtype=int),
    solve: wp.array(dtype=int),
    outputs: int,
    x: wp.array(dtype=wp.vec3),
    # contact.clamp_depth_node and substep.end_substep_node
    bound: float,
    target: float,
    clamped: wp.array(dtype=int),
    diverged: wp.array(dtype=int),
    inv_dt: float,
    v_new: wp.array(dtype=wp.vec3),
    # nodes (contact.evaluate_node)
    x_start: wp.array(dtype=wp.vec3),
    v_start: wp.array(dtype=wp.vec3),
    mass: wp.array(dtype=float),
    node_world: wp.array(dtype=int),
    external_force: wp.array(dtype=wp.vec3),
    gravity: wp.vec3,
    dt: float,
    pad_pos0: wp.array(dtype=wp.vec3),
    pad_rot0: wp.array(dtype=wp.quat),
    pad_pos1: wp.array(dtype=wp.vec3),
    pad_rot1: wp.array(dtype=wp.quat),
    pad_half: wp.array(dtype=wp.vec3),
    pads_per_world: int,
    lag_normal_force: wp.array(dtype=float),
    lag_normal: wp.array(dtype=wp.vec3),
    stiffness: wp.array(dtype=float),
    knee: float,
    ground_mu: float,
    pad_mu: float,
    stick_velocity: float,
    residual: wp.array(dtype=wp.vec3),
    diag_block: wp.array(dtype=wp.mat33),
    contact_hessian: wp.array(dtype=wp.mat33),
    contact_force: wp.array(dtype=wp.vec3),
    elastic_force: wp.array(dtype=wp.vec3),
    pad_normal_force: wp.array(dtype=float),
    pad_force: wp.array(dtype=wp.vec3),
    penetration: wp.array(dtype=float),
    # pad edge points (pad_edge_contact; points_per_world 0: none)
    triangles: wp.array(dtype=wp.vec3i),
    points: wp.array(dtype=wp.vec3),
    point_pad: wp.array(dtype=int),
    points_per_world: int,
    point_tri: wp.array(dtype=int),
    point_bary: wp.array(dtype=wp.vec3),
    point_normal: wp.array(dtype=wp.vec3),
    point_stiffness: wp.array(dtype=float),
    point_allowed: wp.array(dtype=float),
    point_friction: wp.array(dtype=float),
    slip_eps: float,
    triangle_first: wp.array(dtype=int),
    point_block: wp.array(dtype=wp.mat33),
    # tets (elastic.evaluate_tet)
    tets: wp.array(dtype=wp.vec4i),
    rest_inv: wp.array(dtype=wp.mat33),
    rest_volume: wp.array(dtype=float),
    tet_mu: wp.array(dtype=float),
    tet_lambda: wp.array(dtype=float),
    tet_world: wp.array(dtype=int),
    tet_rotation: wp.array(dtype=wp.quat),
    tet_cof: wp.array(dtype=wp.mat33),
    von_mises: wp.array(dtype=float),
    tet_r: wp.array(dtype=wp.mat33),
    tet_twist: wp.array(dtype=float),
    energy: wp.array(dtype=wp.float64),
    # the residual's mask and norm (linear_solve.begin_node_solve)
    free: wp.array(dtype=wp.vec3),
    precond: wp.array(dtype=wp.mat33),
    z: wp.array(dtype=wp.vec3),
    p: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    ap: wp.array(dtype=wp.vec3),
    rz: wp.array(dtype=float),
    residual_norm: wp.array(dtype=float),
    # the mean stress (substep.mean_stress)
    stress_first: wp.array(dtype=int),
    stress_end: wp.array(dtype=int),
    world_volume: wp.array(dtype=float),
    partial: wp.array(dtype=float),
    mean_von_mises: wp.array(dtype=float),
    # the pad poses' copy (substep.copy_pad_poses) after an outputs pass
    pad_target_pos: wp.array(dtype=wp.vec3),
    pad_target_rot: wp.array(dtype=wp.quat),
    state_pad_pos: wp.array(dtype=wp.vec3),
    state_pad_rot: wp.array(dtype=wp.quat),
):
    """The substep end of world ``tid // threads`` (thread ``tid % threads`` of its block) if it
    was solved (``solve``): ``x`` (m) kept within the penetration ``bound`` (m; moved back to
    ``target``), ``v_new`` = the substep's velocities (m/s; ``inv_dt``: 1 / the substep's length),
    then, where ``outputs`` is ``ALL_OUTPUTS``, the outputs pass (``v_start`` still the substep's
    start velocities; ``CONTACT_OUTPUTS``: its node and pad edge terms only) and, with either,
    ``rz[w]`` = 0 in every world and the pad poses (``pad_target_*`` into ``state_pad_*``); last,
    ``v_start`` = ``v_new``. ``node_start`` / ``tet_start`` [W+1]: each world's rows;
    ``stress_first`` / ``stress_end`` [W]: its object's tets for the mean stress (Pa,
    volume-weighted, into ``mean_von_mises``)."""
    tid = wp.tid()
    w = tid // threads
    lane = tid - w * threads
    if solve[w] == 0:
        if lane == 0 and outputs != NO_OUTPUTS:
            rz[w] = 0.0
        return
    n0 = node_start[w]
    n1 = node_start[w + 1]
    for i in range(n0 + lane, n1, threads):
        clamp_depth_node(i, node_world, solve, free, pad_pos1, pad_rot1, pad_half, pads_per_world, lag_normal, bound,
                         target, x, clamped)
        end_substep_node(i, x_start, node_world, solve, diverged, inv_dt, x, v_new)
    if outputs != NO_OUTPUTS:
        t0 = tet_start[w]
        t1 = tet_start[w + 1]
        if lane == 0:  # substep.clear_outputs
            for k in range(pads_per_world):
                pad_normal_force[w * pads_per_world + k] = 0.0
                pad_force[w * pads_per_world + k] = wp.vec3(0.0)
            residual_norm[w] = 0.0
        e0 = w * points_per_world
        e1 = e0 + points_per_world
        block_barrier()
        for i in range(n0 + lane, n1, threads):
            evaluate_node(i, x, x_start, v_start, mass, node_world, solve, external_force, gravity, dt, pad_pos0,
                          pad_rot0, pad_pos1, pad_rot1, pad_half, pads_per_world, lag_normal_force, lag_normal,
                          stiffness, knee, ground_mu, pad_mu, stick_velocity, 1, residual, diag_block, contact_hessian,
                          contact_force, elastic_force, pad_normal_force, pad_force, penetration)
        block_barrier()
        for e in range(e0 + lane, e1, threads):
            evaluate_edge_point(e, x, x_start, triangles, solve, pad_pos0, pad_rot0, pad_pos1, pad_rot1, pad_half,
                                pads_per_world, points, point_pad, points_per_world, point_tri, point_bary,
                                point_normal, point_stiffness, point_allowed, point_friction, knee, pad_mu, slip_eps,
                                triangle_first, 1, residual, diag_block, point_block, contact_force, pad_normal_force,
                                pad_force, penetration)
        if outputs == ALL_OUTPUTS:
            block_barrier()
            for t in range(t0 + lane, t1, threads):
                evaluate_tet(t, x, tets, rest_inv, rest_volume, tet_mu, tet_lambda, tet_world, solve, tet_rotation, 0,
                             tet_rotation, residual, diag_block, elastic_force, tet_cof, von_mises, tet_r, tet_twist, 1,
                             0, energy)
            block_barrier()
            for i in range(n0 + lane, n1, threads):
                begin_node_solve(i, residual, diag_block, free, node_world, solve, precond, z, p, dx, ap, rz,
                                 residual_norm)
            mean_stress_block(w, lane, threads, stress_first[w], stress_end[w], von_mises, rest_volume, world_volume,
                              partial, mean_von_mises)
        if lane == 0:
            rz[w] = 0.0
        for k in range(lane, pads_per_world, threads):
            pad = w * pads_per_world + k
            state_pad_pos[pad] = pad_target_pos[pad]
            state_pad_rot[pad] = pad_target_rot[pad]
    block_barrier()
    for i in range(n0 + lane, n1, threads):  # substep.copy_world_rows
        v_start[i] = v_new[i]
