"""The coarse matrix's inverse per world: E^-1 of ``coarse_space.py``'s E = T^T A T (float64, at most
``block_memory.MAX_COARSE`` unknowns), then coef = E^-1 T^T r.

Two algorithms, both giving E^-1 = 0 (block Jacobi alone for that Newton iteration) where E is not
numerically positive definite (a pivot <= 1e-12 of its diagonal), and a diagonal of 1 to an unknown
with no stiffness (an empty aggregate, an axis prescribed on all of its nodes):
- one thread (``coarse_factor_world``, the phase kernel ``coarse_factor``, and a world block of one
  thread, the CPU's): left-looking Cholesky E = L L^T in place in E's lower triangle, L^-1 row by
  row, E^-1 = L^-T L^-1, each entry a sum in a fixed order of operations (``cholesky_entry``,
  ``lower_inverse_entry``, ``inverse_entry``), ``SERIAL_LANES`` entries computed together;
- a block of several threads (``coarse_factor_block`` with ``threads`` > 1, a GPU's world blocks):
  Gauss-Jordan inversion in the block's shared memory (``block_memory.py``, where the world-block
  evaluation assembled E), pivots on the diagonal
  (E is SPD: its pivots are the Cholesky factor's squared diagonal, the Schur complements), each of
  the n steps a scale of the pivot row and a rank-1 update of the other rows spread over the threads
  with three barriers. The one-thread algorithm's dependent chains (a Cholesky entry a dot product of
  up to 47 products, L^-1's first column ~1,100 multiply-adds in a row) read E from global memory
  (on a GPU, hundreds of cycles a read); here each step's work is a few shared-memory operations
  per thread. Its rounding differs from the one thread's (agreement
  to ~1e-12 relative on a well-conditioned E; ``test_coarse_factor_block``).
"""

import warp as wp

from .block_memory import MAX_COARSE, shared_get, shared_set
from .block_sync import block_barrier, compiled_for_cpu
from .coarse_space import SERIAL_LANES, coarse_coefficient, coarse_coefficients, serial_lanes

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


@wp.func
def cholesky_pivot(w: int, j: int, matrix: wp.array3d(dtype=wp.float64)):
    """Column ``j``'s pivot of world ``w``'s in-place Cholesky factor (the columns before it done):
    1 and L_jj in ``matrix[w, j, j]``, or 0 (not numerically positive definite; left as it is)."""
    s = matrix[w, j, j]
    for k in range(j):
        s -= matrix[w, j, k] * matrix[w, j, k]
    if not (s > wp.float64(1.0e-12) * matrix[w, j, j]):
        return 0
    matrix[w, j, j] = wp.sqrt(s)
    return 1


@wp.func
def cholesky_entry(w: int, i: int, j: int, matrix: wp.array3d(dtype=wp.float64)):
    """L_ij (i > j) of world ``w``'s in-place Cholesky factor, after column ``j``'s pivot."""
    s = matrix[w, i, j]
    for k in range(j):
        s -= matrix[w, i, k] * matrix[w, j, k]
    matrix[w, i, j] = s / matrix[w, j, j]


@wp.func
def cholesky_column(w: int, j: int, size: int, matrix: wp.array3d(dtype=wp.float64), grouped: int):
    """Column ``j`` of world ``w``'s in-place Cholesky factor below its pivot: ``cholesky_entry`` of
    rows j + 1 .. size - 1, ``SERIAL_LANES`` rows at a time where ``grouped`` is 1."""
    d = matrix[w, j, j]
    i = j + 1
    while grouped == 1 and i + SERIAL_LANES <= size:
        s = serial_lanes()
        for q in range(SERIAL_LANES):
            s[q] = matrix[w, i + q, j]
        for k in range(j):
            b = matrix[w, j, k]
            for q in range(SERIAL_LANES):
                s[q] = s[q] - matrix[w, i + q, k] * b
        for q in range(SERIAL_LANES):
            matrix[w, i + q, j] = s[q] / d
        i += SERIAL_LANES
    while i < size:
        cholesky_entry(w, i, j, matrix)
        i += 1


@wp.func
def lower_inverse_entry(w: int, i: int, j: int, matrix: wp.array3d(dtype=wp.float64),
                        lower_inv: wp.array3d(dtype=wp.float64)):
    """(L^-1)_ij (i > j) by forward substitution, the rows above i of L^-1 done."""
    s = wp.float64(0.0)
    for k in range(j, i):
        s += matrix[w, i, k] * lower_inv[w, k, j]
    lower_inv[w, i, j] = -s / matrix[w, i, i]


@wp.func
def lower_inverse(w: int, size: int, matrix: wp.array3d(dtype=wp.float64), lower_inv: wp.array3d(dtype=wp.float64),
                  grouped: int):
    """L^-1 of world ``w``'s Cholesky factor (in ``matrix``'s lower triangle) into ``lower_inv``
    (zero above its diagonal), row by row, each row's entries ``SERIAL_LANES`` at a time where
    ``grouped`` is 1 (else one at a time, ``lower_inverse_entry``): entry
    (i, j)'s sum runs over k from j to i - 1 as ``lower_inverse_entry``'s; a group's sums all start
    at its first column, the terms before an entry's own column adding m x 0 (L^-1 is zero above its
    diagonal) to a sum still at +0, so each entry keeps its bits."""
    for i in range(size):
        for j in range(i + 1, size):
            lower_inv[w, i, j] = wp.float64(0.0)
    for i in range(size):
        d = matrix[w, i, i]
        lower_inv[w, i, i] = wp.float64(1.0) / d
        j = int(0)
        while grouped == 1 and j + SERIAL_LANES <= i:
            s = serial_lanes()
            for k in range(j, i):
                a = matrix[w, i, k]
                for q in range(SERIAL_LANES):
                    s[q] = s[q] + a * lower_inv[w, k, j + q]
            for q in range(SERIAL_LANES):
                lower_inv[w, i, j + q] = -s[q] / d
            j += SERIAL_LANES
        while j < i:
            lower_inverse_entry(w, i, j, matrix, lower_inv)
            j += 1


@wp.func
def inverse_entry(w: int, i: int, j: int, size: int, lower_inv: wp.array3d(dtype=wp.float64),
                  inverse: wp.array3d(dtype=wp.float64)):
    """E^-1_ij = E^-1_ji = (L^-T L^-1)_ij for j <= i."""
    s = wp.float64(0.0)
    for k in range(i, size):
        s += lower_inv[w, k, i] * lower_inv[w, k, j]
    inverse[w, i, j] = s
    inverse[w, j, i] = s


@wp.func
def inverse_row(w: int, i: int, size: int, lower_inv: wp.array3d(dtype=wp.float64),
                inverse: wp.array3d(dtype=wp.float64), grouped: int):
    """``inverse_entry`` of row ``i``'s entries j <= i, ``SERIAL_LANES`` at a time where ``grouped``
    is 1."""
    j = int(0)
    while grouped == 1 and j + SERIAL_LANES <= i + 1:
        s = serial_lanes()
        for k in range(i, size):
            a = lower_inv[w, k, i]
            for q in range(SERIAL_LANES):
                s[q] = s[q] + a * lower_inv[w, k, j + q]
        for q in range(SERIAL_LANES):
            inverse[w, i, j + q] = s[q]
            inverse[w, j + q, i] = s[q]
        j += SERIAL_LANES
    while j <= i:
        inverse_entry(w, i, j, size, lower_inv, inverse)
        j += 1


@wp.func
def fix_coarse_diagonal(w: int, j: int, matrix: wp.array3d(dtype=wp.float64)):
    """An unknown with no stiffness (an empty aggregate, an axis prescribed on all of its nodes)
    gets a diagonal of 1."""
    if matrix[w, j, j] <= wp.float64(0.0):
        matrix[w, j, j] = wp.float64(1.0)


@wp.func
def coarse_invert_serial(w: int, size: int, matrix: wp.array3d(dtype=wp.float64),
                         lower_inv: wp.array3d(dtype=wp.float64), inverse: wp.array3d(dtype=wp.float64),
                         grouped: int):
    """E^-1 of world ``w`` (``size`` unknowns, E's lower triangle in ``matrix``) into ``inverse`` by one
    thread's loops over the entry functions above (Cholesky in place, L^-1, L^-T L^-1); all zero
    where a pivot failed; clears ``matrix``. Each entry is a sum in a fixed order, a dependent
    chain of float64 multiply-adds (up to 48 long). ``grouped`` 1 computes ``SERIAL_LANES`` entries
    together: each entry keeps its order, hence its bits, while a CPU core overlaps their chains (a
    48 x 48 inverse 98 -> 41 us on a 2-core AMD EPYC: benchmarks/RESULTS.md, 2026-12-08, ninth
    session); the solver passes ``compiled_for_cpu()``, so CUDA kernels (where this path runs in the
    phase kernel ``coarse_factor`` and in world blocks of one thread) keep one entry at a time and
    their registers."""
    for j in range(size):
        fix_coarse_diagonal(w, j, matrix)
    ok = int(1)
    for j in range(size):  # Cholesky, in place in the lower triangle
        if ok == 1:
            ok = cholesky_pivot(w, j, matrix)
            if ok == 1:
                cholesky_column(w, j, size, matrix, grouped)
    if ok == 1:
        lower_inverse(w, size, matrix, lower_inv, grouped)
        for i in range(size):  # E^-1 = L^-T L^-1 (symmetric by construction)
            inverse_row(w, i, size, lower_inv, inverse, grouped)
    else:
        for i in range(size):
            for j in range(size):
                inverse[w, i, j] = wp.float64(0.0)
    for i in range(size):
        for j in range(size):
            matrix[w, i, j] = wp.float64(0.0)


@wp.func
def coarse_factor_world(
    w: int,
    world_active: wp.array(dtype=int),
    sizes: wp.array(dtype=int),
    matrix: wp.array3d(dtype=wp.float64),
    lower_inv: wp.array3d(dtype=wp.float64),
    inverse: wp.array3d(dtype=wp.float64),
    rhs: wp.array2d(dtype=float),
    coef: wp.array2d(dtype=float),
    rz: wp.array(dtype=float),
):
    """Row ``w`` of ``coarse_factor``."""
    if world_active[w] == 0:
        return
    size = sizes[w]
    coarse_invert_serial(w, size, matrix, lower_inv, inverse, compiled_for_cpu())
    coarse_coefficients(w, size, inverse, rhs, coef)
    rz[w] = 0.0


@wp.func
def coarse_invert_in_block(
    w: int,
    lane: int,
    threads: int,
    size: int,
    inverse: wp.array3d(dtype=wp.float64),
):
    """E^-1 of world ``w`` (``size`` unknowns; E's lower triangle in the block memory, row-major with
    row stride ``size``) into ``inverse`` by Gauss-Jordan in the block memory (thread ``lane`` of
    ``threads``; every thread must call it), symmetrized; all zero where a pivot is not positive
    (relative to E's diagonal, as ``cholesky_pivot``)."""
    col = MAX_COARSE * MAX_COARSE  # the pivot column's slots, then the diagonal's
    diag = col + MAX_COARSE
    for e in range(lane, size * size, threads):  # the upper triangle from the lower one; the diagonal fixed
        i = e // size
        j = e - i * size
        if i == j:
            v = shared_get(e)
            if v <= wp.float64(0.0):
                v = wp.float64(1.0)
            shared_set(e, v)
            shared_set(diag + i, v)
        elif i < j:
            shared_set(e, shared_get(j * size + i))
    block_barrier()
    ok = int(1)
    for k in range(size):
        for i in range(lane, size, threads):
            shared_set(col + i, shared_get(i * size + k))
        block_barrier()
        pivot = shared_get(col + k)
        if not (pivot > wp.float64(1.0e-12) * shared_get(diag + k)):
            ok = 0  # the same value in every thread: all leave the loop together
            break
        for j in range(lane, size, threads):
            if j == k:
                shared_set(k * size + j, wp.float64(1.0) / pivot)
            else:
                shared_set(k * size + j, shared_get(k * size + j) / pivot)
        block_barrier()
        for e in range(lane, size * size, threads):
            i = e // size
            if i != k:
                j = e - i * size
                v = shared_get(e)
                if j == k:
                    v = wp.float64(0.0)
                shared_set(e, v - shared_get(col + i) * shared_get(k * size + j))
        block_barrier()
    for e in range(lane, size * size, threads):
        i = e // size
        j = e - i * size
        v = wp.float64(0.0)
        if ok == 1:
            v = wp.float64(0.5) * (shared_get(e) + shared_get(j * size + i))
        inverse[w, i, j] = v
    block_barrier()


@wp.func
def coarse_factor_block(
    w: int,
    lane: int,
    threads: int,
    sizes: wp.array(dtype=int),
    matrix: wp.array3d(dtype=wp.float64),
    lower_inv: wp.array3d(dtype=wp.float64),
    inverse: wp.array3d(dtype=wp.float64),
    rhs: wp.array2d(dtype=float),
    coef: wp.array2d(dtype=float),
    rz: wp.array(dtype=float),
):
    """``coarse_factor_world`` of an iterating world ``w`` by the ``threads`` threads of its block
    (thread ``lane``; every thread must call it): E^-1 by ``coarse_invert_serial`` of E in
    ``matrix`` where the block has one thread (the CPU: the phase kernel's bits), else by
    ``coarse_invert_in_block`` of E in the block memory; then
    ``coef`` a row per thread, rhs and rz cleared."""
    size = sizes[w]
    if threads > 1:
        coarse_invert_in_block(w, lane, threads, size, inverse)
    else:
        coarse_invert_serial(w, size, matrix, lower_inv, inverse, compiled_for_cpu())
    for i in range(lane, size, threads):
        coarse_coefficient(w, i, size, inverse, rhs, coef)
    block_barrier()
    for i in range(lane, size, threads):
        rhs[w, i] = 0.0
    if lane == 0:
        rz[w] = 0.0


@wp.kernel
def coarse_factor(
    world_active: wp.array(dtype=int),
    sizes: wp.array(dtype=int),
    matrix: wp.array3d(dtype=wp.float64),
    lower_inv: wp.array3d(dtype=wp.float64),
    inverse: wp.array3d(dtype=wp.float64),
    rhs: wp.array2d(dtype=float),
    coef: wp.array2d(dtype=float),
    rz: wp.array(dtype=float),
):
    """Per world: E^-1 by Cholesky (E = L L^T, E^-1 = L^-T L^-1; unknowns with a zero diagonal, i.e.
    empty aggregates or axes prescribed on all of an aggregate's nodes, get 1), coef = E^-1 rhs;
    clears E, rhs and rz (recomputed by ``coarse_start_cg``)."""
    coarse_factor_world(wp.tid(), world_active, sizes, matrix, lower_inv, inverse, rhs, coef, rz)


