"""The coarse space's factor by a world's block of threads (``coarse_space.coarse_factor_block``, the
world-block evaluation's path for a slender object's coarse solve) against one thread's loops
(``coarse_factor_world``, the phase kernel's path): every entry of the Cholesky factor, L^-1, E^-1 and
the coefficients is computed by the same function in the same order of operations, so the two must
agree bit for bit whatever the number of threads, including where a pivot fails.

The threads run as Warp's CPU fibers (``wp.config.enable_cpu_blocks``): a block's threads run one
after another between barriers, so a missing barrier before a phase that reads another thread's
entries shows up as the NaN those entries start as (checked by hand: without the barrier after the
L^-1 columns, after the E^-1 entries or after the coefficient rows, 5, 8 and 32 threads differ; the
barrier after a pivot only matters where threads run at once, on a GPU: fibers run thread 0 first).
On CUDA the factor runs in ``test_world_blocks``' rope against the CPU (256 threads a world); a
standalone CUDA launch of this file's kernels failed to load its module on an H100 (2026-12-06,
cause not found) and is not kept."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from defgrasp_env.sim.kernels.coarse_space import coarse_factor_block, coarse_factor_world

# forward only, as the solver's kernel modules (the block barrier has no adjoint)
wp.set_module_options({"enable_backward": False})

SIZE = 48  # 8 aggregates x 6 rigid motions


@wp.kernel
def _factor_blocks(threads: int, sizes: wp.array(dtype=int), matrix: wp.array3d(dtype=wp.float64),
                   lower_inv: wp.array3d(dtype=wp.float64), inverse: wp.array3d(dtype=wp.float64),
                   rhs: wp.array2d(dtype=float), coef: wp.array2d(dtype=float), factored: wp.array(dtype=int),
                   rz: wp.array(dtype=float)):
    tid = wp.tid()
    w = tid // threads
    coarse_factor_block(w, tid - w * threads, threads, sizes, matrix, lower_inv, inverse, rhs, coef, factored, rz)


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
    """``coarse_factor_block`` in blocks of ``threads`` (CPU fibers): its outputs as numpy, and
    ``factored``."""
    block = _arrays(m, rhs)
    factored = wp.array(np.full(len(m), 7, np.int32), dtype=int)
    wp.launch(_factor_blocks, dim=len(m) * threads, block_dim=threads,
              inputs=[threads, wp.array(sizes, dtype=int), block["matrix"], block["lower_inv"], block["inverse"],
                      block["rhs"], block["coef"], factored, block["rz"]])
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
    m_fixed[1, :6, :6] = np.eye(6)
    for w in (0, 1, 3):  # E^-1 E = I where the factor held; E^-1 = 0 (block Jacobi alone) where it failed
        n = sizes[w]
        np.testing.assert_allclose(inverse[w, :n, :n] @ m_fixed[w, :n, :n], np.eye(n), atol=1e-9)
    assert not inverse[2, :SIZE, :SIZE].any()
    coef = serial["coef"].numpy()
    np.testing.assert_allclose(coef[0], inverse[0] @ rhs[0].astype(np.float64), rtol=1e-5)
    assert not block["rhs"][:, :24].any() and not block["matrix"][:, :24, :24].any()

