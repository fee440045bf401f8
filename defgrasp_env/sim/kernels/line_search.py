"""Per-world backtracking line search on the incremental potential (``kernels.energy``): trial
positions, and the accept-or-halve test of each trial."""

import warp as wp

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


@wp.func
def trial_position(i: int, x: wp.array(dtype=wp.vec3), dx: wp.array(dtype=wp.vec3), node_world: wp.array(dtype=int),
                   step_length: wp.array(dtype=float), x_trial: wp.array(dtype=wp.vec3)):
    """x_trial_i = x_i + (its world's step length) dx_i."""
    x_trial[i] = x[i] + step_length[node_world[i]] * dx[i]


@wp.kernel
def trial_positions(
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    node_world: wp.array(dtype=int),
    step_length: wp.array(dtype=float),
    x_trial: wp.array(dtype=wp.vec3),
):
    trial_position(wp.tid(), x, dx, node_world, step_length, x_trial)


@wp.kernel
def clear_world_energy(energy: wp.array(dtype=wp.float64)):
    """``energy[w] = 0`` (a per-world sum about to be accumulated)."""
    energy[wp.tid()] = wp.float64(0.0)


@wp.func
def begin_search_world(
    w: int,
    newton_active: wp.array(dtype=int),
    step_length: wp.array(dtype=float),
    searching: wp.array(dtype=int),
    trial_energy: wp.array(dtype=wp.float64),
):
    """Row ``w`` of ``begin_line_search``."""
    step_length[w] = 1.0
    searching[w] = newton_active[w]
    trial_energy[w] = wp.float64(0.0)


@wp.kernel
def begin_line_search(
    newton_active: wp.array(dtype=int),
    step_length: wp.array(dtype=float),
    searching: wp.array(dtype=int),
    trial_energy: wp.array(dtype=wp.float64),
):
    begin_search_world(wp.tid(), newton_active, step_length, searching, trial_energy)


@wp.func
def end_trial(w: int, start_energy: wp.array(dtype=wp.float64), rel_tol: float, min_step: float,
              trial_energy: wp.array(dtype=wp.float64), step_length: wp.array(dtype=float),
              searching: wp.array(dtype=int)):
    """World ``w``'s accept-or-halve test (``end_line_search_trial``)."""
    if searching[w] == 0:
        return
    e0 = start_energy[w]
    tol = wp.float64(rel_tol) * wp.abs(e0) + wp.float64(1.0e-12)
    if trial_energy[w] <= e0 + tol or step_length[w] <= min_step:
        searching[w] = 0
        start_energy[w] = trial_energy[w]
    else:
        step_length[w] = 0.5 * step_length[w]
    trial_energy[w] = wp.float64(0.0)


@wp.kernel
def end_line_search_trial(
    start_energy: wp.array(dtype=wp.float64),
    rel_tol: float,
    min_step: float,
    trial_energy: wp.array(dtype=wp.float64),
    step_length: wp.array(dtype=float),
    searching: wp.array(dtype=int),
):
    """Accept the trial if it does not raise the energy (within float32 rounding of its terms),
    else halve the step; stop halving at ``min_step``. An accepted trial's energy becomes the
    start energy of the next Newton iteration (the step applied is the trial's, bit for bit)."""
    end_trial(wp.tid(), start_energy, rel_tol, min_step, trial_energy, step_length, searching)
