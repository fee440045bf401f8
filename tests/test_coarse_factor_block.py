"""The coarse space's factor by a world's block of threads (``coarse_space.coarse_factor_block``, the
world-block evaluation's path for a slender object's coarse solve) against one thread's loops
(``coarse_factor_world``, the phase kernel's path): every entry of the Cholesky factor, L^-1, E^-1 and
the coefficients is computed by the same function in the same order of operations, so the two must
agree bit for bit whatever the number of threads, including where a pivot fails.

The threads run as Warp's CPU fibers (``wp.config.enable_cpu_blocks``): a block's threads run one
after another between barriers, so a missing barrier before a phase that reads another thread's
entries shows up as the NaN those entries start as (checked by hand: without the barrier after the
L^-1 columns, after the E^-1 entries or after the coefficient rows, 5, 8 and 32 threads differ; the
barrier after a pivot only matters where threads run at once, on a GPU: fibers run thread 0 first)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from defgrasp_env.sim.kernels.coarse_space import coarse_factor_block, coarse_factor_world

SIZE = 24  # the rope's 8 aggregates x 3 translations


@wp.kernel
def _factor_blocks(threads: int, sizes: wp.array(dtype=int), matrix: wp.array3d(dtype=wp.float64),
                   lower_inv: wp.array3d(dtype=wp.float64), inverse: wp.array3d(dtype=wp.float64),
                   rhs: wp.array2d(dtype=float), coef: wp.array2d(dtype=float), terms: wp.array2d(dtype=wp.float64),
                   factored: wp.array(dtype=int), rz: wp.array(dtype=float)):
    tid = wp.tid()
    w = tid // threads
    coarse_factor_block(w, tid - w * threads, threads, sizes, matrix, lower_inv, inverse, rhs, coef, terms, factored,
                        rz)


@wp.kernel
def _factor_worlds(active: wp.array(dtype=int), sizes: wp.array(dtype=int), matrix: wp.array3d(dtype=wp.float64),
                   lower_inv: wp.array3d(dtype=wp.float64), inverse: wp.array3d(dtype=wp.float64),
                   rhs: wp.array2d(dtype=float), coef: wp.array2d(dtype=float), rz: wp.array(dtype=float)):
    coarse_factor_world(wp.tid(), active, sizes, matrix, lower_inv, inverse, rhs, coef, rz)


def _problems(rng: np.random.Generator):
    """Four worlds' coarse matrices [4, 24, 24] float64, right-hand sides [4, 24] float32 and sizes:
    a well-conditioned SPD matrix (a mass term plus a chain's coupling, as a rope's), one whose
    first aggregate is empty (zero rows: diagonal fixed to 1), one indefinite (its pivot fails part
    way down) and a smaller one (12 unknowns in 24-wide arrays)."""
    def spd(n):
        a = rng.normal(size=(n, n))
        return a @ a.T + n * np.eye(n)

    m = np.zeros((4, SIZE, SIZE))
    m[0] = spd(SIZE)
    m[1] = spd(SIZE)
    m[1, :3, :] = 0.0
    m[1, :, :3] = 0.0
    m[2] = spd(SIZE)
    m[2, 10, 10] = -5.0 * m[2, 10, 10]
    m[3, :12, :12] = spd(12)
    rhs = rng.normal(size=(4, SIZE)).astype(np.float32)
    return m, rhs, np.array([SIZE, SIZE, SIZE, 12], dtype=np.int32)


def _arrays(m, rhs, device="cpu"):
    nan = np.full(m.shape, np.nan)  # entries a phase reads before another thread wrote them stay NaN
    return dict(matrix=wp.array(m, dtype=wp.float64, device=device),
                lower_inv=wp.array(nan, dtype=wp.float64, device=device),
                inverse=wp.array(nan, dtype=wp.float64, device=device), rhs=wp.array(rhs, dtype=float, device=device),
                coef=wp.array(np.full(rhs.shape, np.nan, np.float32), dtype=float, device=device),
                rz=wp.array(np.ones(len(m), np.float32), dtype=float, device=device))


def _factor(m, rhs, sizes, threads, device="cpu"):
    """``coarse_factor_block`` in blocks of ``threads``: its outputs as numpy, and ``factored``."""
    block = _arrays(m, rhs, device)
    factored = wp.array(np.full(len(m), 7, np.int32), dtype=int, device=device)
    terms = wp.zeros(rhs.shape, dtype=wp.float64, device=device)
    wp.launch(_factor_blocks, dim=len(m) * threads, block_dim=threads, device=device,
              inputs=[threads, wp.array(sizes, dtype=int, device=device), block["matrix"], block["lower_inv"],
                      block["inverse"], block["rhs"], block["coef"], terms, factored, block["rz"]])
    return {name: a.numpy() for name, a in block.items()}, factored.numpy()


@pytest.mark.parametrize("threads", [1, 5, 8, 32])
def test_a_block_factors_the_coarse_matrix_with_the_bits_of_one_thread(threads, monkeypatch):
    monkeypatch.setattr(wp.config, "enable_cpu_blocks", True)
    m, rhs, sizes = _problems(np.random.default_rng(3))
    serial = _arrays(m, rhs)
    wp.launch(_factor_worlds, dim=len(m), inputs=[wp.array(np.ones(len(m), np.int32), dtype=int),
                                                  wp.array(sizes, dtype=int), *serial.values()])
    block, factored = _factor(m, rhs, sizes, threads)
    for name in serial:
        np.testing.assert_array_equal(block[name], serial[name].numpy(), err_msg=name)
    assert factored.tolist() == [1, 1, 0, 1]
    inverse = serial["inverse"].numpy()
    m_fixed = m.copy()
    m_fixed[1, :3, :3] = np.eye(3)
    for w in (0, 1, 3):  # E^-1 E = I where the factor held; E^-1 = 0 (block Jacobi alone) where it failed
        n = sizes[w]
        np.testing.assert_allclose(inverse[w, :n, :n] @ m_fixed[w, :n, :n], np.eye(n), atol=1e-9)
    assert not inverse[2, :SIZE, :SIZE].any()
    coef = serial["coef"].numpy()
    np.testing.assert_allclose(coef[0], inverse[0] @ rhs[0].astype(np.float64), rtol=1e-5)
    assert not block["rhs"][:, :12].any() and not block["matrix"][:, :12, :12].any()


@pytest.mark.cuda
@pytest.mark.parametrize("threads", [32, 256])
def test_a_cuda_block_factors_the_coarse_matrix_as_one_cpu_thread(threads):
    """The same on a GPU, where the block's threads run at once (a missing barrier is a race there):
    within 1e-12 relative of the CPU's one thread (float64; the GPU compiler may fuse multiply-adds
    differently; the float32 coefficients within 1e-6), the failed factor's E^-1 exactly 0."""
    m, rhs, sizes = _problems(np.random.default_rng(3))
    serial = _arrays(m, rhs)
    wp.launch(_factor_worlds, dim=len(m), inputs=[wp.array(np.ones(len(m), np.int32), dtype=int),
                                                  wp.array(sizes, dtype=int), *serial.values()])
    for _ in range(3):  # races show up in some runs only
        block, factored = _factor(m, rhs, sizes, threads, device="cuda:0")
        assert factored.tolist() == [1, 1, 0, 1]
        for name in serial:  # coef is float32: one float32 rounding apart at most
            tol = 1e-6 if name == "coef" else 1e-12
            np.testing.assert_allclose(block[name], serial[name].numpy(), rtol=tol, atol=tol, err_msg=name)
        assert not block["inverse"][2, :SIZE, :SIZE].any()
