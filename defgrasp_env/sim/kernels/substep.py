"""Substep and Newton-iteration bookkeeping of the implicit solver: the substep's start (initial
guess) and end (velocities), applying a Newton update, the per-world stopping tests, mean stress,
and the per-world copies and clears of a solve restricted to some worlds (``solve`` [W] int: 1 for
a world this solve computes; the others' rows are not written)."""

import warp as wp

from .block_sync import block_barrier

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


@wp.func
def begin_substep_node(
    i: int,
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    step_start: wp.array(dtype=wp.vec3),
    prescribed: wp.array(dtype=wp.vec3),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    solve: wp.array(dtype=int),
    s1: float,
    dt: float,
    x_start: wp.array(dtype=wp.vec3),
):
    """Save the substep's start positions and move x to the initial guess x + dt v; prescribed axes
    go to their target interpolated at fraction s1 of the step: node ``i``'s row of ``begin_substep``."""
    if solve[node_world[i]] == 0:
        return
    xi = x[i]
    x_start[i] = xi
    target = wp.lerp(step_start[i], prescribed[i], s1)
    fr = free[i]
    guess = xi + dt * v[i]
    x[i] = wp.cw_mul(fr, guess) + wp.cw_mul(wp.vec3(1.0) - fr, target)


@wp.kernel
def begin_substep(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    step_start: wp.array(dtype=wp.vec3),
    prescribed: wp.array(dtype=wp.vec3),
    free: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    solve: wp.array(dtype=int),
    s1: float,
    dt: float,
    x_start: wp.array(dtype=wp.vec3),
):
    """``begin_substep_node`` for every node."""
    begin_substep_node(wp.tid(), x, v, step_start, prescribed, free, node_world, solve, s1, dt, x_start)


@wp.kernel
def begin_newton(solve: wp.array(dtype=int), newton_active: wp.array(dtype=int),
                 substep_newton_it: wp.array(dtype=int)):
    """Before a substep's Newton iterations: each world iterates if it is solved, none has yet."""
    w = wp.tid()
    newton_active[w] = solve[w]
    substep_newton_it[w] = 0


@wp.func
def apply_node_step(
    i: int,
    dx: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    newton_active: wp.array(dtype=int),
    step_length: wp.array(dtype=float),
    max_step: float,
    x: wp.array(dtype=wp.vec3),
    dx_norm: wp.array(dtype=float),
    diverged: wp.array(dtype=int),
):
    """Row ``i`` of ``apply_newton_step``."""
    w = node_world[i]
    if newton_active[w] == 0:
        return
    d = step_length[w] * dx[i]
    size = wp.max(wp.abs(d))
    if not wp.isfinite(size) or size > max_step:
        diverged[w] = 1
        return
    x[i] = x[i] + d
    # convergence is judged on the full Newton direction: a step cut short by the line search
    # (e.g. a contact that the linearisation missed) must not pass for a converged one
    wp.atomic_max(dx_norm, w, wp.max(wp.abs(dx[i])))


@wp.kernel
def apply_newton_step(
    dx: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    newton_active: wp.array(dtype=int),
    step_length: wp.array(dtype=float),
    max_step: float,
    x: wp.array(dtype=wp.vec3),
    dx_norm: wp.array(dtype=float),
    diverged: wp.array(dtype=int),
):
    """x += step_length * dx; record the largest update per world; flag NaN/inf or an update longer
    than ``max_step`` (m)."""
    apply_node_step(wp.tid(), dx, node_world, newton_active, step_length, max_step, x, dx_norm, diverged)


@wp.func
def end_newton_world(
    w: int,
    dx_norm: wp.array(dtype=float),
    tol: float,
    max_iterations: int,
    diverged: wp.array(dtype=int),
    substep_iterations: wp.array(dtype=int),
    newton_iterations: wp.array(dtype=int),
    newton_active: wp.array(dtype=int),
    rz: wp.array(dtype=float),
    residual_norm: wp.array(dtype=float),
    cg_iterations: wp.array(dtype=int),
    last_dx_norm: wp.array(dtype=float),
    unconverged: wp.array(dtype=int),
):
    """Row ``w`` of ``end_newton_iteration``."""
    if newton_active[w] == 0:
        return
    it = substep_iterations[w] + 1
    substep_iterations[w] = it
    newton_iterations[w] = newton_iterations[w] + 1
    last_dx_norm[w] = dx_norm[w]
    if dx_norm[w] <= tol or diverged[w] != 0:
        newton_active[w] = 0
    elif it >= max_iterations:
        newton_active[w] = 0
        unconverged[w] = 1
    dx_norm[w] = 0.0
    rz[w] = 0.0
    residual_norm[w] = 0.0
    cg_iterations[w] = 0


@wp.kernel
def end_newton_iteration(
    dx_norm: wp.array(dtype=float),
    tol: float,
    max_iterations: int,
    diverged: wp.array(dtype=int),
    substep_iterations: wp.array(dtype=int),
    newton_iterations: wp.array(dtype=int),
    newton_active: wp.array(dtype=int),
    rz: wp.array(dtype=float),
    residual_norm: wp.array(dtype=float),
    cg_iterations: wp.array(dtype=int),
    last_dx_norm: wp.array(dtype=float),
    unconverged: wp.array(dtype=int),
):
    """Count the iteration (this substep's, for the limit, and the step's total) and stop a world
    on the update tolerance, at the per-substep limit (flagged ``unconverged``) or on divergence."""
    end_newton_world(wp.tid(), dx_norm, tol, max_iterations, diverged, substep_iterations, newton_iterations,
                     newton_active, rz, residual_norm, cg_iterations, last_dx_norm, unconverged)


@wp.func
def end_substep_node(
    i: int,
    x_start: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    solve: wp.array(dtype=int),
    diverged: wp.array(dtype=int),
    inv_dt: float,
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
):
    """Node ``i``'s row of ``end_substep``."""
    if solve[node_world[i]] == 0:
        return
    if diverged[node_world[i]] != 0:
        x[i] = x_start[i]
        v[i] = wp.vec3(0.0)
        return
    v[i] = (x[i] - x_start[i]) * inv_dt


@wp.kernel
def end_substep(
    x_start: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    solve: wp.array(dtype=int),
    diverged: wp.array(dtype=int),
    inv_dt: float,
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
):
    """v = (x - x_start) / dt; a diverged world is put back to its start positions at rest."""
    end_substep_node(wp.tid(), x_start, node_world, solve, diverged, inv_dt, x, v)


@wp.func
def mean_stress_block(w: int, lane: int, threads: int, first: int, end: int, von_mises: wp.array(dtype=float),
                      rest_volume: wp.array(dtype=float), world_volume: wp.array(dtype=float),
                      partial: wp.array(dtype=float), mean: wp.array(dtype=float)):
    """World ``w``'s ``mean_stress`` by thread ``lane`` of its block of ``threads`` (tets
    ``first:end``; every thread of the block must call it: it holds a barrier)."""
    total = float(0.0)
    volume = world_volume[w]
    for t in range(first + lane, end, threads):
        total = total + von_mises[t] * rest_volume[t] / volume
    partial[w * threads + lane] = total
    block_barrier()
    if lane == 0:
        mean_w = float(0.0)
        for k in range(threads):
            mean_w = mean_w + partial[w * threads + k]
        mean[w] = mean_w


@wp.kernel
def mean_stress(
    threads: int,
    von_mises: wp.array(dtype=float),
    rest_volume: wp.array(dtype=float),
    tet_start: wp.array(dtype=int),
    tet_end: wp.array(dtype=int),
    solve: wp.array(dtype=int),
    world_volume: wp.array(dtype=float),
    partial: wp.array(dtype=float),
    mean: wp.array(dtype=float),
):
    """A block of ``threads`` threads per solved world w (``block_sync.py``): ``mean[w]`` = the
    volume-weighted mean of its object's tets' (``tet_start[w]:tet_end[w]``) von Mises stress. Each
    thread sums every ``threads``-th tet in tet order into ``partial`` [W*threads], then thread 0
    adds the partial sums in thread order: deterministic on a GPU (no float atomics), and with one
    thread (the CPU) the sum in tet order of the CPU's atomic sum before."""
    tid = wp.tid()
    w = tid // threads
    if solve[w] == 0:
        return
    mean_stress_block(w, tid - w * threads, threads, tet_start[w], tet_end[w], von_mises, rest_volume, world_volume,
                      partial, mean)


@wp.kernel
def copy_world_rows(src: wp.array(dtype=wp.vec3), row_world: wp.array(dtype=int), solve: wp.array(dtype=int),
                    dst: wp.array(dtype=wp.vec3)):
    """dst[i] = src[i] for the rows i of the solved worlds (``row_world[i]``: the row's world)."""
    i = wp.tid()
    if solve[row_world[i]] != 0:
        dst[i] = src[i]


@wp.kernel
def copy_pad_poses(src_pos: wp.array(dtype=wp.vec3), src_rot: wp.array(dtype=wp.quat), pads_per_world: int,
                   solve: wp.array(dtype=int), dst_pos: wp.array(dtype=wp.vec3), dst_rot: wp.array(dtype=wp.quat)):
    """Pad poses [W*P] of the solved worlds: dst = src."""
    i = wp.tid()
    if solve[i // pads_per_world] != 0:
        dst_pos[i] = src_pos[i]
        dst_rot[i] = src_rot[i]


@wp.func
def clear_report_world(w: int, newton_it: wp.array(dtype=int), cg_total: wp.array(dtype=int),
                       diverged: wp.array(dtype=int), unconverged: wp.array(dtype=int), clamped: wp.array(dtype=int),
                       penetration: wp.array(dtype=float)):
    """Zero world ``w``'s report (counters, flags, penetration, m)."""
    newton_it[w] = 0
    cg_total[w] = 0
    diverged[w] = 0
    unconverged[w] = 0
    clamped[w] = 0
    penetration[w] = 0.0


@wp.kernel
def clear_solve_report(solve: wp.array(dtype=int), newton_it: wp.array(dtype=int), cg_total: wp.array(dtype=int),
                       diverged: wp.array(dtype=int), unconverged: wp.array(dtype=int), clamped: wp.array(dtype=int),
                       penetration: wp.array(dtype=float)):
    """Zero the per-world report of each solved world (``clear_report_world``)."""
    w = wp.tid()
    if solve[w] != 0:
        clear_report_world(w, newton_it, cg_total, diverged, unconverged, clamped, penetration)


@wp.kernel
def clear_values(values: wp.array(dtype=float)):
    """values[i] = 0 (CG's ``rz`` [W] after the outputs pass)."""
    values[wp.tid()] = 0.0


@wp.kernel
def clear_outputs(solve: wp.array(dtype=int), pads_per_world: int, pad_normal_force: wp.array(dtype=float),
                  pad_force: wp.array(dtype=wp.vec3), residual_norm: wp.array(dtype=float)):
    """Zero the accumulated outputs (pad loads [W*P] N, residual [W] N) of each solved world before
    they are evaluated."""
    w = wp.tid()
    if solve[w] == 0:
        return
    for k in range(pads_per_world):
        pad_normal_force[w * pads_per_world + k] = 0.0
        pad_force[w * pads_per_world + k] = wp.vec3(0.0)
    residual_norm[w] = 0.0
