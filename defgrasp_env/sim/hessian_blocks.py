"""``HessianBlocks``: the elastic Hessian assembled as 3 x 3 blocks per node row, for the products of CG.

CG multiplies the Newton matrix by a direction tens of times per Newton iteration. Tet by tet
(``elastic.stress_differential``: each tet's 12 x 12 Hessian applied to its four nodes' directions and
scattered back) a product costs ~200 flops and four scattered additions per tet. Assembled once per
Newton iteration (``kernels/hessian_blocks.py``), a product is a gather over each node's row: one
3 x 3 block per neighbouring node (the rope: 5,248 blocks for 1,536 tets, where the tets' 12 x 12
matrices hold 24,576), with no scattered writes. Measured on this project's 2-core Xeon (rope,
561 nodes, a pressed state): 55 us a product tet by tet, 21 us by rows, 200 us an assembly.
The diagonal blocks are not stored: a row's blocks sum to zero (each tet's do: its shape-function
gradients sum to zero), so (K p)_i = sum over j != i of K_ij (p_j - p_i), which, like the tet by
tet product (it differences the directions too), gives exactly zero for a rigid translation in
float32 (summed with K_ii p_i instead, a stiff object's translations would carry the rounding of
entries ~1e5 times the mass term: a stiff cube's Newton loop measured unconverged in 55 steps of a
teleop stream, 13 with the differences, 10 tet by tet).

The pattern (which blocks exist) depends on each world's tets only: built on the host per distinct
mesh (cached) and laid out per world. Row ``i`` holds the blocks ``node_blocks[i][0] ..
node_blocks[i][1]``, columns ascending (``block_node``: global node ids). Its incidences (the tets
naming node ``i``, in tet order, each with vertex ``a``) are ``incidence[node_incidences[i][0] ..
node_incidences[i][1]]`` as ``4 t + a``, with the positions of its blocks (a, b), b = 0..3, in
``incidence_blocks`` (-1 for b = a). A packed model's worlds follow each other; a slotted model
(``Model.block_slot``) gives each world ``block_slot`` block rows and 4 x its tet slot incidences,
so that ``rewrite_worlds`` changes a world's object in place. Spare nodes have empty rows; spare
tets name no incidence.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import warp as wp

from .kernels.world_rows import scatter_rows
from .model import Model


@dataclass(frozen=True)
class WorldBlocks:
    """One world's pattern in world-local numbering (host arrays): ``row`` [n+1] first block of each
    node row, ``node`` [B] its column node, ``incidence`` [4T] ``4 t + a`` sorted by node (then
    tet), ``incidence_row`` [n+1] first incidence of each node, ``incidence_blocks`` [4T, 4] the
    positions (in ``node``) of its blocks (a, 0..3), -1 for (a, a)."""

    row: np.ndarray
    node: np.ndarray
    incidence: np.ndarray
    incidence_row: np.ndarray
    incidence_blocks: np.ndarray

    @property
    def num_blocks(self) -> int:
        return len(self.node)


def world_blocks(tets: np.ndarray, num_nodes: int) -> WorldBlocks:
    """The pattern of one object (``tets`` [T, 4] world-local node ids, ``num_nodes`` its nodes)."""
    return _world_blocks(np.ascontiguousarray(tets, dtype=np.int64).tobytes(), int(num_nodes))


@functools.lru_cache(maxsize=64)
def _world_blocks(tet_bytes: bytes, n: int) -> WorldBlocks:
    tets = np.frombuffer(tet_bytes, dtype=np.int64).reshape(-1, 4)
    rows = np.repeat(tets, 4, axis=1)           # [T, 16]: a of pair (a, b) = k // 4
    cols = np.tile(tets, (1, 4))                # b = k % 4
    keys = rows * n + cols
    unique = np.unique(keys[rows != cols])      # row-major: by row, then column; no diagonal block
    row = np.zeros(n + 1, np.int64)
    row[1:] = np.cumsum(np.bincount(unique // n, minlength=n))
    position = np.where(rows != cols, np.searchsorted(unique, keys), -1)  # [T, 16]; (a, a): -1
    order = np.argsort(tets.ravel(), kind="stable")  # incidences 4 t + a by node, then tet
    incidence_row = np.zeros(n + 1, np.int64)
    incidence_row[1:] = np.cumsum(np.bincount(tets.ravel(), minlength=n))
    return WorldBlocks(row=row, node=(unique % n).astype(np.int64), incidence=order.astype(np.int64),
                       incidence_row=incidence_row, incidence_blocks=position.reshape(-1, 4)[order])


def block_count(tets: np.ndarray, num_nodes: int) -> int:
    """Hessian blocks of an object (twice its edges)."""
    return world_blocks(tets, num_nodes).num_blocks


def _world_tets(model: Model, w: int, tets: np.ndarray) -> tuple[np.ndarray, int]:
    """World ``w``'s object's tets (world-local ids) from the model's global ``tets`` rows of it."""
    start = int(model.node_start[w])
    return tets - start, int(model.node_end[w]) - start


def _check_slot(model: Model, parts: list[WorldBlocks]) -> None:
    """A slotted model's block slot holds every world's blocks (a packed model has none to fill)."""
    most = max(p.num_blocks for p in parts)
    if model.block_slot and most > model.block_slot:
        raise ValueError(f"a world's object has {most} Hessian blocks, more than the model's block slot "
                         f"{model.block_slot}")


def _spans(row: np.ndarray, base: int, rows: int) -> np.ndarray:
    """[rows, 2] int32 (first, one past last) of a world's node rows from its object's local starts
    ``row`` [n+1], offset by ``base``; the slot's spare rows past the object are empty."""
    spans = np.full((rows, 2), base + row[-1], np.int64)
    n = len(row) - 1
    spans[:n, 0], spans[:n, 1] = row[:-1] + base, row[1:] + base
    return spans.astype(np.int32)


@dataclass
class HessianBlocks:
    """The assembled elastic Hessian of every world (device arrays): N nodes, B block rows, T tets."""

    node_blocks: wp.array        # [N] vec2i: first and one-past-last block of each node row
    block_node: wp.array         # [B] int: global column node of each block
    node_incidences: wp.array    # [N] vec2i: first and one-past-last incidence of each node
    incidence: wp.array          # [4T] int: 4 t + a (tet t names the node as its vertex a)
    incidence_blocks: wp.array   # [4T] vec4i: the block (a, b) of the node's row, b = 0..3 (-1: b = a)
    values: wp.array             # [B] mat33, N/m: the blocks at the last Newton iterate
    block_start: np.ndarray      # [W+1] host: first block of each world (a slotted model: w x its block slot)

    @classmethod
    def from_model(cls, model: Model) -> "HessianBlocks":
        d, w = model.device, model.num_worlds
        tets = model.tets.numpy()
        parts = [world_blocks(*_world_tets(model, k, tets[model.world_tets(k)])) for k in range(w)]
        _check_slot(model, parts)
        slot = model.block_slot
        counts = np.full(w, slot) if slot else np.array([p.num_blocks for p in parts])
        block_start = np.concatenate([[0], np.cumsum(counts)])
        n, t = model.num_nodes, model.num_tets
        arrays = cls._host_rows(model, range(w), parts, block_start)
        blocks = int(block_start[-1])
        out = cls(node_blocks=wp.zeros(n, dtype=wp.vec2i, device=d), block_node=wp.zeros(blocks, dtype=int, device=d),
                  node_incidences=wp.zeros(n, dtype=wp.vec2i, device=d), incidence=wp.zeros(4 * t, dtype=int, device=d),
                  incidence_blocks=wp.zeros(4 * t, dtype=wp.vec4i, device=d),
                  values=wp.zeros(blocks, dtype=wp.mat33, device=d), block_start=block_start)
        out._write(arrays, d)
        return out

    def rewrite_worlds(self, model: Model, worlds) -> None:
        """The rows of ``worlds`` again, after their objects changed in place (a slotted model)."""
        worlds = [int(w) for w in worlds]
        if not worlds:
            return
        parts = []
        for w in worlds:
            sl = model.world_tets(w)
            parts.append(world_blocks(*_world_tets(model, w, model.tets[sl.start:sl.stop].numpy())))
        _check_slot(model, parts)
        self._write(self._host_rows(model, worlds, parts, self.block_start), model.device)

    @staticmethod
    def _host_rows(model: Model, worlds, parts: list[WorldBlocks], block_start: np.ndarray) -> dict:
        """Per array, (rows, values) of ``worlds`` (their whole slots: spare rows empty)."""
        out = {name: ([], []) for name in ("node_blocks", "block_node", "node_incidences", "incidence",
                                           "incidence_blocks")}

        def put(name, rows, values):
            out[name][0].append(np.asarray(rows, np.int64))
            out[name][1].append(values)

        for w, p in zip(worlds, parts):
            n0, n1 = int(model.node_start[w]), int(model.node_start[w + 1])
            t0 = int(model.tet_start[w])
            b0 = int(block_start[w])
            put("node_blocks", np.arange(n0, n1), _spans(p.row, b0, n1 - n0))
            put("block_node", np.arange(b0, b0 + p.num_blocks), (p.node + n0).astype(np.int32))
            put("node_incidences", np.arange(n0, n1), _spans(p.incidence_row, 4 * t0, n1 - n0))
            rows = np.arange(4 * t0, 4 * t0 + len(p.incidence))
            put("incidence", rows, (p.incidence + 4 * t0).astype(np.int32))
            blocks = np.where(p.incidence_blocks < 0, -1, p.incidence_blocks + b0)
            put("incidence_blocks", rows, blocks.astype(np.int32))
        return out

    def _write(self, arrays: dict, device) -> None:
        dtypes = {"node_blocks": wp.vec2i, "block_node": int, "node_incidences": wp.vec2i, "incidence": int,
                  "incidence_blocks": wp.vec4i}
        for name, (rows, values) in arrays.items():
            if not rows:
                continue
            index = wp.array(np.concatenate(rows).astype(np.int32), dtype=int, device=device)
            data = wp.array(np.ascontiguousarray(np.concatenate(values)), dtype=dtypes[name], device=device)
            wp.launch(scatter_rows, dim=len(index), inputs=[data, index, getattr(self, name)], device=device)
