"""Which rows (nodes, tets, pad edge slots) a CG-loop launch runs: all of them, or only those of a
short list of worlds (the worlds still iterating once few are left).

A batched CG iterates as long as its slowest world. Its kernels test a per-world flag on every row,
so once most worlds have stopped, a launch over all rows still costs a thread per row of every
world: on an H200 at W = 4096 (3 M tets) 26-69 us a tet-by-tet Hessian product launch for the work of
a few worlds, 7-12 us listed (benchmarks/RESULTS.md). The same
kernels launched over ``capacity x rows_per_world`` threads through a ``RowMap`` of the listed worlds
do that world's work for the cost of a small launch.

A ``RowMap`` with ``per_world == EVERY_ROW`` (-1) maps thread ``tid`` to row ``tid`` (a launch over
all rows); otherwise thread ``tid`` is row ``tid % per_world`` of listed world ``tid // per_world``
(the k-th of ``worlds``, while ``k < count[0]``), if the world has that many rows (a listed map with
``per_world == 0`` maps nothing: its launch has no threads). Each row is computed by the
same code either way, and a world's rows run in the same order, so on the CPU (one thread,
sequential launches) the results are bit-identical to a launch over all rows.

``WorldCompaction.record_list`` (``sim/world_compaction.py``) builds the list from a loop's
per-world flags: ``compact_begin``, then ``compact_worlds`` over the W worlds, then ``compact_gate``
(``cond`` = 1 where at most ``capacity`` worlds are flagged: the test of ``wp.capture_if``).

``scatter_rows`` writes given rows of any array (a slotted model's worlds rewritten in place, a
reset's node rows).
"""

from __future__ import annotations

from typing import Any

import warp as wp

# forward only: nothing differentiates these kernels, and their adjoints multiply the compile time
wp.set_module_options({"enable_backward": False})


#: ``RowMap.per_world`` of a map over every row (thread = row).
EVERY_ROW = -1


@wp.struct
class RowMap:
    per_world: int                    # EVERY_ROW: all rows; else the thread stride per listed world
    count: wp.array(dtype=wp.int32)   # [1] worlds flagged at the last listing
    worlds: wp.array(dtype=wp.int32)  # [capacity] the listed worlds
    start: wp.array(dtype=int)        # [W+1] first row of each world (and the row count last); unused by EVERY_ROW


@wp.func
def mapped_row(rows: RowMap, tid: int) -> int:
    """The row thread ``tid`` runs, or -1 for none."""
    if rows.per_world == EVERY_ROW:
        return tid
    k = tid // rows.per_world
    if k >= int(rows.count[0]):
        return -1
    w = int(rows.worlds[k])
    i = rows.start[w] + tid - k * rows.per_world
    if i >= rows.start[w + 1]:
        return -1
    return i


@wp.kernel
def compact_begin(count: wp.array(dtype=wp.int32)):
    """Empty the list."""
    count[0] = wp.int32(0)


@wp.kernel
def compact_worlds(flags: wp.array(dtype=int), capacity: int, count: wp.array(dtype=wp.int32),
                   worlds: wp.array(dtype=wp.int32)):
    """List the worlds whose flag is set (the first ``capacity`` of them; all are counted)."""
    w = wp.tid()
    if flags[w] != 0:
        k = wp.atomic_add(count, 0, wp.int32(1))
        if k < wp.int32(capacity):
            worlds[k] = wp.int32(w)


@wp.kernel
def compact_gate(count: wp.array(dtype=wp.int32), capacity: int, cond: wp.array(dtype=wp.int32)):
    """cond = 1 where every flagged world is listed."""
    go = wp.int32(0)
    if count[0] <= wp.int32(capacity):
        go = wp.int32(1)
    cond[0] = go


@wp.kernel
def scatter_rows(values: wp.array(dtype=Any), index: wp.array(dtype=wp.int32), dst: wp.array(dtype=Any)):
    """``dst[index[k]] = values[k]``."""
    k = wp.tid()
    dst[index[k]] = values[k]
