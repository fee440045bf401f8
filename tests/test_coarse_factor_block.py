"""The coarse matrix's inverse by a world's block of threads (``coarse_factor.coarse_factor_block``,
the world-block evaluation's path) against one thread's loops (``coarse_factor_world``, the phase
kernel's path). With one thread a block runs the same entry functions in the same order, so the two
must agree bit for bit (the CPU's world blocks); with several (a GPU's) it inverts E, assembled in
the block's shared memory (loaded there by this file's kernel), by Gauss-Jordan there, which must
agree with the Cholesky path to rounding (1e-12 of the inverse's largest entry: float64 on
matrices of condition ~1e2), fail where a pivot fails, and give E^-1 E = I.

The threads run as Warp's CPU fibers (``wp.config.enable_cpu_blocks``): a block's threads run one
after another between barriers, so a missing barrier before a phase that reads another thread's
entries shows up as the NaN those entries start as in global memory (the inverse, the
coefficients), or, in shared memory, as a wrong entry (checked by hand: without the barrier after
the pivot row's scaling two of the three block sizes fail, without the one after the rank-1 update
all three; entries off by up to 1).
On CUDA the factor runs in ``test_world_blocks``' rope against the CPU (256 threads a world); a
standalone CUDA launch of this file's kernels failed to load its module on an H100 (2026-12-06,
cause not found) and is not kept."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from defgrasp_env.sim.kernels.block_memory import shared_set
from defgrasp_env.sim.kernels.block_sync import block_barrier
from defgrasp_env.sim.kernels.coarse_factor import coarse_factor_block, coarse_factor_world

# forward only, as the solver's kernel modules (the block barrier has no adjoint)
wp.set_module_options({"enable_backward": False})

SIZE = 48  # 8 aggregates x 6 rigid motions


@wp.kernel
def _factor_blocks(threads: int, sizes: wp.array(dtype=int), matrix: wp.array3d(dtype=wp.float64),
                   lower_inv: wp.array3d(dtype=wp.float64), inverse: wp.array3d(dtype=wp.float64),
                   rhs: wp.array2d(dtype=float), coef: wp.array2d(dtype=float), rz: wp.array(dtype=float)):
    tid = wp.tid()
    w = tid // threads
    lane = tid - w * threads
    size = sizes[w]
    if threads > 1:  # E's lower triangle into the block memory, where the world-block evaluation assembles it
        for e in range(lane, size * size, threads):
            i = e // size
            j = e - i * size
            v = wp.float64(0.0)
            if j <= i:
                v = matrix[w, i, j]
            shared_set(e, v)
        block_barrier()
    coarse_factor_block(w, lane, threads, sizes, matrix, lower_inv, inverse, rhs, coef, rz)


@wp.kernel
def _factor_worlds(active: wp.array(dtype=int), sizes: wp.array(dtype=int), matrix: wp.array3d(dtype=wp.float64),
                   lower_inv: wp.array3d(dtype=wp.float64), inverse: wp.array3d(dtype=wp.float64),
                   rhs: wp.array2d(dtype=float), coef: wp.array2d(dtype=float), rz: wp.array(dtype=float)):
    coarse_factor_world(wp.tid(), active, sizes, matrix, lower_inv, inverse, rhs, coef, rz)


def _problems(rng: np.random.Generator):
    """Four worlds' coarse matrices [4, 48, 48] float64, right-hand sides [4, 48] float32 and sizes:
    a well-conditioned SPD matrix (a mass term plus a chain's coupling, as a rope's), one whose
    first aggregate is empty (zero rows: diagonal fixed to 1), one indefinite (its pivot fails part
    way down) and a smaller one (24 unknowns in 48-wide arrays)."""
    def spd(n):
        a = rng.normal(size=(n, n))
        return a @ a.T + n * np.eye(n)

    m = np.zeros((4, SIZE, SIZE))
    m[0] = spd(SIZE)
    m[1] = spd(SIZE)
    m[1, :6, :] = 0.0
    m[1, :, :6] = 0.0
    m[2] = spd(SIZE)
    m[2, 10, 10] = -5.0 * m[2, 10, 10]
    m[3, :24, :24] = spd(24)
    rhs = rng.normal(size=(4, SIZE)).astype(np.float32)
    return m, rhs, np.array([SIZE, SIZE, SIZE, 24], dtype=np.int32)


def _arrays(m, rhs):
    nan = np.full(m.shape, np.nan)  # entries a phase reads before another thread wrote them stay NaN
    return dict(matrix=wp.array(m, dtype=wp.float64), lower_inv=wp.array(nan, dtype=wp.float64),
                inverse=wp.array(nan, dtype=wp.float64), rhs=wp.array(rhs, dtype=float),
                coef=wp.array(np.full(rhs.shape, np.nan, np.float32), dtype=float),
                rz=wp.array(np.ones(len(m), np.float32), dtype=float))


def _factor(m, rhs, sizes, threads):
    """``coarse_factor_block`` in blocks of ``threads`` (CPU fibers): its outputs as numpy."""
    block = _arrays(m, rhs)
    wp.launch(_factor_blocks, dim=len(m) * threads, block_dim=threads,
              inputs=[threads, wp.array(sizes, dtype=int), *block.values()])
    return {name: a.numpy() for name, a in block.items()}


@pytest.mark.parametrize("threads", [1, 5, 8, 32, 128, 256])
def test_a_block_inverts_the_coarse_matrix_as_one_thread_does(threads, monkeypatch):
    monkeypatch.setattr(wp.config, "enable_cpu_blocks", True)
    m, rhs, sizes = _problems(np.random.default_rng(3))
    serial = _arrays(m, rhs)
    wp.launch(_factor_worlds, dim=len(m), inputs=[wp.array(np.ones(len(m), np.int32), dtype=int),
                                                  wp.array(sizes, dtype=int), *serial.values()])
    block = _factor(m, rhs, sizes, threads)
    inverse = serial["inverse"].numpy()
    for name in serial:  # E and L^-1: the one thread's, which a block of several threads does not use
        if threads == 1 or name not in ("inverse", "coef", "lower_inv", "matrix"):
            np.testing.assert_array_equal(block[name], serial[name].numpy(), err_msg=name)
    scale = np.abs(np.nan_to_num(inverse)).max()
    np.testing.assert_allclose(block["inverse"], inverse, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(block["coef"], serial["coef"].numpy(), rtol=1e-6)
    held = [bool(block["inverse"][w, :n, :n].any()) for w, n in enumerate(sizes)]
    assert held == [True, True, False, True]  # the indefinite world's factor failed, the others held
    m_fixed = m.copy()
    m_fixed[1, :6, :6] = np.eye(6)
    for w in (0, 1, 3):  # E^-1 E = I where the factor held; E^-1 = 0 (block Jacobi alone) where it failed
        n = sizes[w]
        np.testing.assert_allclose(block["inverse"][w, :n, :n] @ m_fixed[w, :n, :n], np.eye(n), atol=1e-9)
    assert not block["inverse"][2, :SIZE, :SIZE].any()
    coef = block["coef"]
    np.testing.assert_allclose(coef[0], block["inverse"][0] @ rhs[0].astype(np.float64), rtol=1e-5)
    assert not block["rhs"][:, :24].any()
    if threads == 1:  # cleared for the next assembly; a block of several threads assembles in its block memory
        assert not block["matrix"][:, :24, :24].any()
