"""A barrier for the threads of one thread block, for kernels that give each world a block
(``world_start.py``, ``world_evaluate.py``, ``world_cg.py``, ``world_newton_step.py``,
``world_finish.py``, ``substep.mean_stress``, ``coarse_factor.coarse_factor_block``): all
the block's global-memory writes before it are seen by all its threads after it. Warp's
``WP_TILE_SYNC``: ``__syncthreads()`` on CUDA; on the CPU nothing with one thread per block (a
launch's threads run one after another there), and the fibers' sync where
``wp.config.enable_cpu_blocks`` runs several threads per block (how the tests exercise it there).

Every thread of the block must reach every barrier: a kernel calls it outside row loops, and its
loops' bounds and exits read per-world values written before a barrier (the same for the whole
block)."""

import warp as wp


@wp.func_native("""
WP_TILE_SYNC();
""")
def block_barrier(): ...


@wp.func_native("""
#if defined(__CUDA_ARCH__)
return 0;
#else
return 1;
#endif
""")
def compiled_for_cpu() -> int:
    """1 in a kernel compiled for the CPU, 0 for CUDA: a constant of the target, so a branch on it
    leaves no code (and no registers) in the other target's kernel."""
    ...
