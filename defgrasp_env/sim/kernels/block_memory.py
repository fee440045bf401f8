"""A float64 scratch in the shared memory of a thread block, for the world-block kernels' coarse
matrix (``coarse_space.coarse_assemble_node`` adds into it, ``coarse_factor.coarse_invert_in_block``
inverts it there): a world's 48 x 48 E in global memory cost a lone world on an H100 most of a
Newton iteration in latency (float64 atomics, then a factor's dependent loads), where shared memory
answers in a few cycles.

CUDA: a ``__shared__`` array of ``BLOCK_MEMORY_SLOTS`` (19.2 KB), one per thread block, shared by
every call in a kernel. CPU: one static array for the process (Warp's CPU JIT has no thread-local
storage); only blocks of several threads use it, which the CPU runs only under
``wp.config.enable_cpu_blocks`` (tests, one launch at a time, a block's threads as fibers that switch
at barriers only, so a plain add is atomic there); the solver's CPU world blocks have one thread and
use global memory. The phase kernels' coarse assembly (``coarse_space.coarse_assemble_nodes``,
``pad_edge_hessian.coarse_assemble_edge_points``) calls the same functions with the shared path off
at run time, so a CUDA launch of those kernels (``world_block_threads = 0``, not the default)
reserves the array without using it.
"""

import warp as wp

# forward only: nothing differentiates these functions
wp.set_module_options({"enable_backward": False})

#: The most coarse unknowns a world's block holds (8 aggregates x 6 rigid motions).
MAX_COARSE = 48
#: Float64 slots: the coarse matrix (MAX_COARSE^2), then a pivot column and a diagonal (MAX_COARSE each).
BLOCK_MEMORY_SLOTS = MAX_COARSE * MAX_COARSE + 2 * MAX_COARSE


@wp.func_native(f"""
#if defined(__CUDA_ARCH__)
__shared__ double defgrasp_block_memory[{BLOCK_MEMORY_SLOTS}];
if (op == 2) atomicAdd(&defgrasp_block_memory[index], value);
#else
static double defgrasp_block_memory[{BLOCK_MEMORY_SLOTS}];
if (op == 2) defgrasp_block_memory[index] += value;
#endif
if (op == 1) defgrasp_block_memory[index] = value;
return defgrasp_block_memory[index];
""")
def block_memory(index: int, value: wp.float64, op: int) -> wp.float64:
    """Slot ``index`` of the block's float64 scratch after ``op`` (0: none, 1: store ``value``, 2: add
    ``value`` atomically)."""
    ...


@wp.func
def shared_get(index: int):
    """Slot ``index`` of the block memory."""
    return block_memory(index, wp.float64(0.0), 0)


@wp.func
def shared_set(index: int, value: wp.float64):
    """Slot ``index`` of the block memory = ``value``."""
    block_memory(index, value, 1)


@wp.func
def shared_add(index: int, value: wp.float64):
    """Slot ``index`` of the block memory += ``value`` (atomic among the block's threads)."""
    block_memory(index, value, 2)
