"""Each world's whole line search in one launch: a block of threads per world tries its Newton
step at halving lengths until the incremental potential does not rise (``line_search.end_trial``),
with a block barrier (``block_sync.py``) between a trial's positions, its energy and its test.

Phase by phase, a trial is five launches over the rows of every world (``trial_positions``,
``energy.node_energy``, ``pad_edge_contact.edge_point_energy``, ``energy.tet_energy``,
``line_search.end_line_search_trial``) and two loop-control launches, and the batch tries as long as
its slowest world halves (a contact-heavy GPU batch: ~3.6 trials per Newton iteration, a full-width
``tet_energy`` each). Here each world's block tries only as often as the world needs, calling the
same row functions in the same order per world: bit-identical on the CPU (one thread per world).
"""

import warp as wp

from .block_sync import block_barrier
from .energy import node_energy_row, tet_energy_row
from .line_search import end_trial, trial_position
from .pad_edge_contact import edge_point_energy_slot


@wp.kernel
def line_search_world_blocks(
    threads: int,
    max_trials: int,
    node_start: wp.array(dtype=int),
    tet_start: wp.array(dtype=int),
    rel_tol: float,
    min_step: float,
    # the step and the trial
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
):
    """Line-search trials of world ``tid // threads`` (thread ``tid % threads`` of its block) until
    it accepts a step (``end_trial``; at most ``max_trials``); a world not searching returns at once."""
    tid = wp.tid()
    w = tid // threads
    lane = tid - w * threads
    if searching[w] == 0:
        return
    n0 = node_start[w]
    n1 = node_start[w + 1]
    t0 = tet_start[w]
    t1 = tet_start[w + 1]
    e0 = w * points_per_world
    e1 = e0 + points_per_world
    for _trial in range(max_trials):
        for i in range(n0 + lane, n1, threads):
            trial_position(i, x, dx, node_world, step_length, x_trial)
        block_barrier()
        for i in range(n0 + lane, n1, threads):
            node_energy_row(i, x_trial, x_start, v_start, mass, node_world, searching, external_force, gravity, dt,
                            pad_pos0, pad_rot0, pad_pos1, pad_rot1, pad_half, pads_per_world, lag_normal_force,
                            lag_normal, stiffness, knee, ground_mu, pad_mu, stick_velocity, trial_energy)
        for e in range(e0 + lane, e1, threads):
            edge_point_energy_slot(e, x_trial, x_start, triangles, searching, pad_pos0, pad_rot0, pad_pos1, pad_rot1,
                                   pad_half, pads_per_world, points, point_pad, points_per_world, point_tri,
                                   point_bary, point_normal, point_stiffness, point_allowed, point_friction, knee,
                                   pad_mu, slip_eps, trial_energy)
        for t in range(t0 + lane, t1, threads):
            tet_energy_row(t, x_trial, tets, rest_inv, rest_volume, tet_mu, tet_lambda, tet_world, searching,
                           tet_rotation, trial_energy)
        block_barrier()
        if lane == 0:
            end_trial(w, start_energy, rel_tol, min_step, trial_energy, step_length, searching)
        block_barrier()
        if searching[w] == 0:
            break
