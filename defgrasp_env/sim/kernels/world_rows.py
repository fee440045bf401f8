"""Which rows (nodes, tets, pad edge slots) a CG-loop launch runs: all of them, or only those of a
short list of worlds (the worlds still iterating once few are left).

A batched CG iterates as long as its slowest world. Its kernels test a per-world flag on every row,
so once most worlds have stopped, a launch over all rows still costs a thread per row of every
world: on a GPU at W = 4096 ~10-15 us a launch (3 M tets) for the work of one world. The same
kernels launched over ``capacity x rows_per_world`` threads through a ``RowMap`` of the listed worlds
do that world's work for the cost of a small launch.

A ``RowMap`` with ``per_world == 0`` maps thread ``tid`` to row ``tid`` (a launch over all rows);
otherwise thread ``tid`` is row ``tid % per_world`` of listed world ``tid // per_world`` (the k-th
of ``worlds``, while ``k < count[0]``), if the world has that many rows. Each row is computed by the
same code either way, and a world's rows run in the same order, so on the CPU (one thread,
sequential launches) the results are bit-identical to a launch over all rows.

``list_worlds`` builds the list from a loop's per-world flags (``compact_begin``, then
``compact_worlds`` over the W worlds, then ``compact_gate``: ``cond`` = 1 where at most ``capacity``
worlds are flagged, the test of ``wp.capture_if``).
"""

from __future__ import annotations

import warp as wp


@wp.struct
class RowMap:
    per_world: int                    # 0: all rows; else the thread stride per listed world
    count: wp.array(dtype=wp.int32)   # [1] listed worlds
    worlds: wp.array(dtype=wp.int32)  # [capacity] the listed worlds
    start: wp.array(dtype=int)        # [W+1] first row of each world (and the row count last)


@wp.func
def mapped_row(rows: RowMap, tid: int) -> int:
    """The row thread ``tid`` runs, or -1 for none."""
    if rows.per_world == 0:
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
