"""A barrier for the threads of one thread block, for kernels that give each world a block
(``world_evaluate.py``, ``world_cg.py``, ``world_newton_step.py``, ``substep.mean_stress``): all
the block's global-memory writes before it are seen by all its threads after it. Warp's
``WP_TILE_SYNC``: ``__syncthreads()`` on CUDA; on the CPU nothing with one thread per block (a
launch's threads run one after another there), and the fibers' sync where
``wp.config.enable_cpu_blocks`` runs several threads per block (how the tests exercise it there).

Every thread of the block must reach every barrier: a kernel calls it outside row loops, and its
loops' bounds and exits read per-world values written before a barrier (the same for the whole
block)."""

import warp as wp

#: Registers per thread at most (CUDA ``__maxnreg__``) of the world-block kernels. Uncapped, nvcc
#: gave ``evaluate_world_blocks`` 219 and ``newton_step_world_blocks`` 168 (``cg_world_blocks`` 96), so
#: one 256-thread block (one world) filled an SM's 64 K registers; at 128, two fit (spilling 200 and
#: 136 bytes a thread to local memory). Measured on an H200 (benchmarks/RESULTS.md, 2026-11-28):
#: W = 1 random 433 -> 509 steps/s, W = 512 with the expert 25.9 k -> 28.0 k world-steps/s
#: (90 steps), W = 4096 random unchanged (64.7 k); 96 and 64 were no better. Ignored on the CPU.
WORLD_BLOCK_MAX_REGISTERS = 128


@wp.func_native("""
WP_TILE_SYNC();
""")
def block_barrier(): ...
