"""The one-thread coarse factor (``coarse_factor.coarse_invert_serial``: the CPU's world blocks and
the phase kernel) computes ``SERIAL_LANES`` entries together on the CPU (``grouped``) so that a core
overlaps their dependent sums, and one at a time in CUDA kernels. Each entry must keep its own
order of operations, so both must give, bit for bit, what computing one entry at a time with the
entry functions gives (``cholesky_entry``, ``lower_inverse_entry``, ``inverse_entry`` in the
factor's order before the grouping, rebuilt here), and must invert E (an independent check:
E^-1 E = I in float64)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from defgrasp_env.sim.kernels.coarse_factor import (SERIAL_LANES, cholesky_entry, cholesky_pivot,
                                                     coarse_invert_serial, fix_coarse_diagonal, inverse_entry,
                                                     lower_inverse_entry)

wp.set_module_options({"enable_backward": False})

WIDTH = 48  # the arrays' width: 8 aggregates x 6 rigid motions


@wp.kernel
def _grouped(sizes: wp.array(dtype=int), matrix: wp.array3d(dtype=wp.float64),
             lower_inv: wp.array3d(dtype=wp.float64), inverse: wp.array3d(dtype=wp.float64)):
    w = wp.tid()
    coarse_invert_serial(w, sizes[w], matrix, lower_inv, inverse, 1)


@wp.kernel
def _entrywise(sizes: wp.array(dtype=int), matrix: wp.array3d(dtype=wp.float64),
               lower_inv: wp.array3d(dtype=wp.float64), inverse: wp.array3d(dtype=wp.float64)):
    w = wp.tid()
    coarse_invert_serial(w, sizes[w], matrix, lower_inv, inverse, 0)


@wp.kernel
def _one_entry_at_a_time(sizes: wp.array(dtype=int), matrix: wp.array3d(dtype=wp.float64),
                         lower_inv: wp.array3d(dtype=wp.float64), inverse: wp.array3d(dtype=wp.float64)):
    """The factor as it was before the grouping: column by column, one entry at a time."""
    w = wp.tid()
    size = sizes[w]
    for j in range(size):
        fix_coarse_diagonal(w, j, matrix)
    ok = int(1)
    for j in range(size):
        if ok == 1:
            ok = cholesky_pivot(w, j, matrix)
            if ok == 1:
                for i in range(j + 1, size):
                    cholesky_entry(w, i, j, matrix)
    for j in range(size):
        for i in range(size):
            lower_inv[w, i, j] = wp.float64(0.0)
        if ok == 1:
            lower_inv[w, j, j] = wp.float64(1.0) / matrix[w, j, j]
            for i in range(j + 1, size):
                lower_inverse_entry(w, i, j, matrix, lower_inv)
    for i in range(size):
        for j in range(i + 1):
            inverse_entry(w, i, j, size, lower_inv, inverse)


def _problems():
    """E's lower triangles [W, 48, 48] and sizes: SPD matrices of every size from 1 to 48 (every
    remainder of the groups), one with an empty aggregate (zero rows: its diagonal is fixed to 1),
    one indefinite (its factor fails part way down) and one badly conditioned (a rope-like chain
    with a 1e6 spread of scales)."""
    rng = np.random.default_rng(7)
    sizes = list(range(1, WIDTH + 1)) + [WIDTH] * 3
    m = np.zeros((len(sizes), WIDTH, WIDTH))
    for w, n in enumerate(sizes):
        a = rng.normal(size=(n, n))
        m[w, :n, :n] = a @ a.T + n * np.eye(n)
    m[-3, 6:12, :] = 0.0
    m[-3, :, 6:12] = 0.0
    m[-2, 20, 20] = -3.0 * m[-2, 20, 20]
    scale = np.logspace(0, 3, WIDTH)
    chain = 2 * np.eye(WIDTH) - np.eye(WIDTH, k=1) - np.eye(WIDTH, k=-1) + 1e-6 * np.eye(WIDTH)
    m[-1] = scale[:, None] * chain * scale[None, :]
    return np.tril(m), np.array(sizes, dtype=np.int32)


def _run(kernel, m, sizes):
    nan = np.full(m.shape, np.nan)  # L^-1 and E^-1 start as NaN: an entry the factor does not write shows
    arrays = [wp.array(m, dtype=wp.float64), wp.array(nan, dtype=wp.float64), wp.array(nan, dtype=wp.float64)]
    wp.launch(kernel, dim=len(m), inputs=[wp.array(sizes, dtype=int), *arrays], device="cpu")
    return arrays[2].numpy()


@pytest.mark.parametrize("kernel", [_grouped, _entrywise], ids=["grouped", "entrywise"])
def test_the_factor_keeps_the_bits_of_one_entry_at_a_time(kernel):
    assert SERIAL_LANES > 1  # else there is nothing to check
    m, sizes = _problems()
    grouped = _run(kernel, m, sizes)
    reference = _run(_one_entry_at_a_time, m, sizes)
    for w, n in enumerate(sizes):
        # float64 bits compared as integers (NaN-safe; a signed zero counts)
        np.testing.assert_array_equal(grouped[w, :n, :n].view(np.int64), reference[w, :n, :n].view(np.int64),
                                      err_msg=f"world {w} ({n} unknowns)")
    full = np.tril(m) + np.tril(m, -1).transpose(0, 2, 1)
    full[-3, 6:12, 6:12] = np.eye(6)  # the fixed diagonal of the empty aggregate
    for w in [0, 4, 23, 46, len(sizes) - 3]:
        n = sizes[w]
        np.testing.assert_allclose(grouped[w, :n, :n] @ full[w, :n, :n], np.eye(n), atol=1e-9)
    assert not grouped[-2].any()  # the indefinite world: E^-1 = 0 (block Jacobi alone)


@pytest.mark.parametrize("n", [SERIAL_LANES - 1, SERIAL_LANES, SERIAL_LANES + 1])
def test_a_group_boundary_size_inverts(n):
    """Sizes around one group: the remainder loops alone, one full group, a group and a remainder."""
    rng = np.random.default_rng(n)
    a = rng.normal(size=(n, n))
    e = a @ a.T + n * np.eye(n)
    m = np.zeros((1, WIDTH, WIDTH))
    m[0, :n, :n] = np.tril(e)
    inverse = _run(_grouped, m, np.array([n], dtype=np.int32))
    np.testing.assert_allclose(inverse[0, :n, :n], np.linalg.inv(e), rtol=1e-12, atol=1e-14)
