"""The short list of worlds a batched CG still iterates, and the row maps of its launches
(``kernels/world_rows.py``).

Once at most ``capacity`` worlds of a batch still iterate CG (the slowest worlds of a batch: a
stiff first touch, a world re-solved alone by the force limit's retry), the CG loop's kernels are
launched over ``capacity x rows of the largest world`` threads instead of every row of every world:
the same rows computed by the same code in the same order (bit-identical on the CPU), at the
launch cost of a few worlds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from .kernels import world_rows as kwr
from .model import Model


def _row_map(per_world: int, count: wp.array, worlds: wp.array, start: np.ndarray, device) -> kwr.RowMap:
    rows = kwr.RowMap()
    rows.per_world = int(per_world)
    rows.count = count
    rows.worlds = worlds
    rows.start = wp.array(np.asarray(start, dtype=np.int32), dtype=int, device=device)
    return rows


def every_row(device) -> kwr.RowMap:
    """The map of a launch over every row (thread = row)."""
    return _row_map(kwr.EVERY_ROW, wp.zeros(1, dtype=wp.int32, device=device),
                    wp.zeros(1, dtype=wp.int32, device=device), np.zeros(1), device)


@dataclass
class WorldCompaction:
    """Device arrays of the list and the row maps (all rows, and the listed worlds' nodes, tets and
    pad edge slots) with their launch sizes.

    ``count`` [1] int32: worlds flagged at the last listing (``record_list``; all counted, at most
    ``capacity`` listed in ``worlds`` [capacity] int32); ``cond`` [1] int32: 1 where all of them are
    listed. ``every_row``: the map of a launch over every row (thread = row)."""

    capacity: int
    count: wp.array
    worlds: wp.array
    cond: wp.array
    every_row: kwr.RowMap
    nodes: kwr.RowMap
    tets: kwr.RowMap
    edge_slots: kwr.RowMap

    @classmethod
    def from_model(cls, model: Model, capacity: int, edge_points_per_world: int) -> "WorldCompaction":
        d, w = model.device, model.num_worlds
        count = wp.zeros(1, dtype=wp.int32, device=d)
        worlds = wp.zeros(max(capacity, 1), dtype=wp.int32, device=d)
        node_start, tet_start = np.asarray(model.node_start), np.asarray(model.tet_start)
        edge_start = np.arange(w + 1) * edge_points_per_world
        return cls(
            capacity=int(capacity), count=count, worlds=worlds, cond=wp.zeros(1, dtype=wp.int32, device=d),
            every_row=every_row(d),
            nodes=_row_map(np.diff(node_start).max(), count, worlds, node_start, d),
            tets=_row_map(np.diff(tet_start).max(), count, worlds, tet_start, d),
            edge_slots=_row_map(edge_points_per_world, count, worlds, edge_start, d))

    def dim(self, rows: kwr.RowMap) -> int:
        """Threads of a launch over the listed worlds' rows of ``rows``."""
        return self.capacity * rows.per_world

    def pays(self, model: Model) -> bool:
        """Whether listed launches are smaller than launches over every row: more worlds than
        ``capacity``, and ``capacity`` times the largest world's nodes (CG's rows: its products
        gather the assembled Hessian per node) fewer than all nodes (one large world among small
        ones could make a listed launch the larger)."""
        return 0 < self.capacity < model.num_worlds and self.dim(self.nodes) < model.num_nodes

    def record_list(self, flags: wp.array) -> list:
        """The recorded launches that list the worlds whose ``flags`` [W] are set and set ``cond``."""
        d, w = self.count.device, flags.shape[0]
        return [wp.launch(kwr.compact_begin, 1, inputs=[self.count], device=d, record_cmd=True),
                wp.launch(kwr.compact_worlds, w, inputs=[flags, self.capacity, self.count, self.worlds], device=d,
                          record_cmd=True),
                wp.launch(kwr.compact_gate, 1, inputs=[self.count, self.capacity, self.cond], device=d,
                          record_cmd=True)]
