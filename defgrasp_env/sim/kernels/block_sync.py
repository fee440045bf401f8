"""A barrier for the threads of one CUDA thread block, for kernels that give each world a block
(``world_evaluate.py``, ``world_cg.py``, ``world_newton_step.py``, ``substep.mean_stress``): all
the block's global-memory writes before it are seen by all its threads after it. A no-op on the CPU, where such a kernel runs one thread per
world (a launch's threads run one after another there).

Every thread of the block must reach every barrier: a kernel calls it outside row loops, and its
loops' bounds and exits read per-world values written before a barrier (the same for the whole
block)."""

import warp as wp


@wp.func_native("""
#if defined(__CUDA_ARCH__)
__syncthreads();
#endif
""")
def block_barrier(): ...
