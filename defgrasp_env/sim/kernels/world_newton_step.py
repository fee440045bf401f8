"""The rest of each world's Newton iteration after CG in one launch: the coarse correction, the
line search and the update, in a block of threads per world with block barriers
(``block_sync.py``) wherever a phase reads what other threads wrote.

Phase by phase this is ``coarse_post`` (``coarse_space.coarse_reduce``, ``coarse_solve``,
``coarse_correct``), in a substep's first iteration the nodes' and pad edge points' part of the
line search's start energy (``energy.node_energy``, ``pad_edge_contact.edge_point_energy``),
``line_search.begin_line_search``, per trial five launches over the rows of every world
(``trial_positions``, the node, edge point and tet energies, ``end_line_search_trial``) and two
loop-control launches while any world still halves (a contact-heavy GPU batch: ~3.6 trials per
Newton iteration, a full-width ``tet_energy`` each), then ``substep.apply_newton_step`` and
``end_newton_iteration``. Here each world tries only as often as it needs, calling the same row
functions in the same order per world: bit-identical on the CPU (one thread per world). A world not
iterating Newton returns at once (the phase kernels also reset its line-search state and trial
positions, which nothing reads while it does not iterate).
"""

import warp as wp

# forward only: these kernels are never differentiated, and the adjoint of their loops multiplies the
# CUDA compile time (world_evaluate: 205 s with it, on a 2-core Xeon)
wp.set_module_options({"enable_backward": False})

from .block_sync import block_barrier, compiled_for_cpu
from .coarse_space import coarse_correct_node, coarse_reduce_node, coarse_solve_world
from .energy import node_energy_row, tet_energy_row
from .line_search import begin_search_world, end_trial, trial_position
from .pad_edge_contact import edge_point_energy_slot
from .substep import apply_node_step, end_newton_world


@wp.kernel
def newton_step_world_blocks(
    threads: int,
    node_start: wp.array(dtype=int),
    tet_start: wp.array(dtype=int),
    newton_active: wp.array(dtype=int),
    # the coarse correction (coarse_space.py)
    residual: wp.array(dtype=wp.vec3),
    free: wp.array(dtype=wp.vec3),
    node_aggregate: wp.array(dtype=int),
    lever: wp.array(dtype=wp.vec3),
    coarse_sizes: wp.array(dtype=int),
    coarse_inverse: wp.array3d(dtype=wp.float64),
    coarse_rhs: wp.array2d(dtype=float),
    coarse_coef: wp.array2d(dtype=float),
    # the line search (line_search.py): 0 trials = none
    max_trials: int,
    start_energy_of_nodes: int,
    rel_tol: float,
    min_step: float,
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    step_length: wp.array(dtype=float),
    x_trial: wp.array(dtype=wp.vec3),
    searching: wp.array(dtype=int),
    start_energy: wp.array(dtype=wp.float64),
    trial_energy: wp.array(dtype=wp.float64),
    # nodes (energy.node_energy_row)
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
    # pad edge points (pad_edge_contact.edge_point_energy_slot; points_per_world 0: none)
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
    # tets (energy.tet_energy_row)
    tets: wp.array(dtype=wp.vec4i),
    rest_inv: wp.array(dtype=wp.mat33),
    rest_volume: wp.array(dtype=float),
    tet_mu: wp.array(dtype=float),
    tet_lambda: wp.array(dtype=float),
    tet_world: wp.array(dtype=int),
    tet_rotation: wp.array(dtype=wp.quat),
    trial_rotation: wp.array(dtype=wp.quat),
    rotations_at_x: wp.array(dtype=int),
    # the update (substep.apply_node_step, end_newton_world)
    max_step: float,
    dx_norm: wp.array(dtype=float),
    diverged: wp.array(dtype=int),
    newton_tolerance: float,
    newton_iterations: int,
    substep_iterations: wp.array(dtype=int),
    iterations: wp.array(dtype=int),
    rz: wp.array(dtype=float),
    residual_norm: wp.array(dtype=float),
    cg_iterations: wp.array(dtype=int),
    last_update: wp.array(dtype=float),
    unconverged: wp.array(dtype=int),
):
    """Coarse correction, line search and update of world ``tid // threads`` (thread
    ``tid % threads`` of its block), if it iterates Newton; ``start_energy_of_nodes`` = 1 (a
    substep's first iteration): first add its nodes' and edge points' energy at ``x`` to
    ``start_energy`` (its tets' part came from ``world_evaluate``)."""
    tid = wp.tid()
    w = tid // threads
    lane = tid - w * threads
    if newton_active[w] == 0:
        return
    n0 = node_start[w]
    n1 = node_start[w + 1]
    t0 = tet_start[w]
    t1 = tet_start[w + 1]
    e0 = w * points_per_world
    e1 = e0 + points_per_world
    for i in range(n0 + lane, n1, threads):
        coarse_reduce_node(i, residual, node_world, node_aggregate, newton_active, lever, coarse_rhs)
    block_barrier()
    if lane == 0:
        coarse_solve_world(w, newton_active, coarse_sizes, coarse_inverse, coarse_rhs, coarse_coef)
    block_barrier()
    for i in range(n0 + lane, n1, threads):
        coarse_correct_node(i, free, node_world, node_aggregate, newton_active, lever, coarse_coef, dx)
    keep = compiled_for_cpu()  # the CPU: the last trial's rotations, for the next evaluation at its positions
    if max_trials > 0:
        if start_energy_of_nodes != 0:
            for i in range(n0 + lane, n1, threads):
                node_energy_row(i, x, x_start, v_start, mass, node_world, newton_active, external_force, gravity, dt,
                                pad_pos0, pad_rot0, pad_pos1, pad_rot1, pad_half, pads_per_world, lag_normal_force,
                                lag_normal, stiffness, knee, ground_mu, pad_mu, stick_velocity, start_energy)
            for e in range(e0 + lane, e1, threads):
                edge_point_energy_slot(e, x, x_start, triangles, newton_active, pad_pos0, pad_rot0, pad_pos1,
                                       pad_rot1, pad_half, pads_per_world, points, point_pad, points_per_world,
                                       point_tri, point_bary, point_normal, point_stiffness, point_allowed,
                                       point_friction, knee, pad_mu, slip_eps, start_energy)
        if lane == 0:
            begin_search_world(w, newton_active, step_length, searching, trial_energy)
        block_barrier()
        for _trial in range(max_trials):
            for i in range(n0 + lane, n1, threads):
                trial_position(i, x, dx, node_world, step_length, x_trial)
            block_barrier()
            for i in range(n0 + lane, n1, threads):
                node_energy_row(i, x_trial, x_start, v_start, mass, node_world, searching, external_force, gravity,
                                dt, pad_pos0, pad_rot0, pad_pos1, pad_rot1, pad_half, pads_per_world,
                                lag_normal_force, lag_normal, stiffness, knee, ground_mu, pad_mu, stick_velocity,
                                trial_energy)
            for e in range(e0 + lane, e1, threads):
                edge_point_energy_slot(e, x_trial, x_start, triangles, searching, pad_pos0, pad_rot0, pad_pos1,
                                       pad_rot1, pad_half, pads_per_world, points, point_pad, points_per_world,
                                       point_tri, point_bary, point_normal, point_stiffness, point_allowed,
                                       point_friction, knee, pad_mu, slip_eps, trial_energy)
            for t in range(t0 + lane, t1, threads):
                tet_energy_row(t, x_trial, tets, rest_inv, rest_volume, tet_mu, tet_lambda, tet_world, searching,
                               tet_rotation, trial_energy, keep, trial_rotation)
            block_barrier()
            if lane == 0:
                end_trial(w, start_energy, rel_tol, min_step, trial_energy, step_length, searching)
            block_barrier()
            if searching[w] == 0:
                break
    block_barrier()
    for i in range(n0 + lane, n1, threads):
        apply_node_step(i, dx, node_world, newton_active, step_length, max_step, x, dx_norm, diverged)
    block_barrier()
    if lane == 0:
        # x is now the last trial's positions, bit for bit (apply_node_step adds the trial's step), where
        # the world line-searched to an accepted trial and did not diverge (a diverged world's nodes
        # stay where they were)
        known = int(0)
        if keep == 1 and max_trials > 0 and searching[w] == 0 and diverged[w] == 0:
            known = 1
        rotations_at_x[w] = known
        end_newton_world(w, dx_norm, newton_tolerance, newton_iterations, diverged, substep_iterations, iterations,
                         newton_active, rz, residual_norm, cg_iterations, last_update, unconverged)
