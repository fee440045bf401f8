"""Per-world solver report on the device: one record per world folded from the solver's scratch
after each solve, so that a caller stepping several solves (substeps, retries) downloads one
packed array per control step instead of one array per field per solve."""

import warp as wp

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


@wp.struct
class SolveRecord:
    """One world's ``SolveStats`` fields (the flags as int32 0/1)."""

    newton_iterations: wp.int32   # summed over the folded solves
    cg_iterations: wp.int32       # summed over the folded solves
    last_update: wp.float32       # m, of the last folded solve
    residual_force: wp.float32    # N, of the last folded solve
    penetration: wp.float32       # m, deepest over the folded solves (NaN propagates, as numpy.max)
    diverged: wp.int32            # any folded solve
    unconverged: wp.int32         # any folded solve stopped a substep at the Newton limit
    penetrated: wp.int32          # any folded solve: penetration > bound or a node clamped


@wp.kernel
def fold_solve_record(
    newton_iterations: wp.array(dtype=int),
    cg_iterations: wp.array(dtype=int),
    last_update: wp.array(dtype=float),
    residual_force: wp.array(dtype=float),
    penetration: wp.array(dtype=float),
    diverged: wp.array(dtype=int),
    unconverged: wp.array(dtype=int),
    clamped: wp.array(dtype=int),
    penetration_bound: float,
    first: int,
    record: wp.array(dtype=SolveRecord),
):
    """Fold world w's report of the last solve into ``record[w]`` (``first != 0``: overwrite it)."""
    w = wp.tid()
    pen = penetration[w]
    flag = int(0)
    if pen > penetration_bound or clamped[w] != 0:
        flag = 1
    r = SolveRecord()
    if first == 0:
        r = record[w]
    else:
        r.newton_iterations = 0
        r.cg_iterations = 0
        r.penetration = pen
        r.diverged = 0
        r.unconverged = 0
        r.penetrated = 0
    r.newton_iterations = r.newton_iterations + newton_iterations[w]
    r.cg_iterations = r.cg_iterations + cg_iterations[w]
    r.last_update = last_update[w]
    r.residual_force = residual_force[w]
    if wp.isnan(pen) or pen > r.penetration:
        r.penetration = pen
    r.diverged = wp.max(r.diverged, wp.where(diverged[w] != 0, 1, 0))
    r.unconverged = wp.max(r.unconverged, wp.where(unconverged[w] != 0, 1, 0))
    r.penetrated = wp.max(r.penetrated, flag)
    record[w] = r
