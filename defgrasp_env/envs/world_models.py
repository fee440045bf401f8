"""Models of many worlds assembled from cached one-world models: a reset that changes objects
rebuilds the scene's flat arrays by concatenation (O(nodes) copies) instead of re-deriving every
world's rest shape, masses and stiffness (``build_model`` inverts each tet's rest matrix: ~4 ms
per world on this CPU). The result equals ``build_model`` of the same worlds bit for bit (each
world's data there depends on its own mesh, material and pose only).

With ``slots`` (``slot_sizes`` of every object the worlds may hold) the model is slotted
(``sim.model``): every world gets the same rows, its object the first ones, spare rows after, so
``rewrite_worlds`` changes the objects of some worlds in place (their rows of the model only, by
device scatters; no array is reallocated). What else copies model rows must follow (the solver's
scratch, a control's prescribed positions, readouts, states: ``PickupScene._rewrite``)."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import warp as wp

from ..sim.aggregates import bisect_nodes
from ..sim.hessian_blocks import block_count
from ..sim.materials import Material
from ..sim.meshing import TetMesh
from ..sim.model import SPARE_POSITION, ContactParams, Model, build_model, material_fields, set_world_materials
from ..transforms import quat_normalize, quat_to_matrix
from ..sim.kernels.world_rows import scatter_rows

_NODE_FIELDS = {"node_mass": wp.float32, "node_contact_stiffness": wp.float32, "free_axes": wp.vec3}
_TET_FIELDS = {"tet_rest_inv": wp.mat33, "tet_rest_volume": wp.float32, "tet_mu": wp.float32,
               "tet_lambda": wp.float32}


@dataclass(frozen=True)
class SlotSizes:
    """Rows per world of a slotted model: nodes (the most of any object plus one, so that every
    slot has a spare node for its spare tets and triangles to name), tets, surface triangles,
    coarse aggregates and elastic Hessian blocks (the most of any object)."""

    nodes: int
    tets: int
    triangles: int
    aggregates: int
    blocks: int


_REFERENCE = Material(1000.0, 1e5, 0.3)  # the geometry's rows do not depend on it


#: the material-independent rows of an object, cached per mesh (its tets, rest shape and volumes)
_GEOMETRY_FIELDS = ("free_axes", "tet_rest_inv", "tet_rest_volume")


@functools.lru_cache(maxsize=64)
def _geometry(mesh: TetMesh, pad_half_extents: tuple, contact: ContactParams) -> dict:
    """Host arrays of the one-world model of ``mesh`` (identity pose) that do not depend on its
    material (``build_model`` inverts each tet's rest matrix: ~4 ms per world on this CPU)."""
    m = build_model([mesh], [_REFERENCE], pad_half_extents=[list(h) for h in pad_half_extents], contact=contact,
                    device="cpu")
    out = {name: getattr(m, name).numpy() for name in _GEOMETRY_FIELDS}
    out.update(tets=m.tets.numpy(), world_volume=m.world_volume.numpy(), pad_half_extents=m.pad_half_extents.numpy(),
               gravity=m.gravity, surface=m.surfaces[0], nodes=np.asarray(mesh.nodes, dtype=np.float64),
               node_aggregate=m.node_aggregate, node_anchor=m.node_anchor)
    return out


@functools.lru_cache(maxsize=1024)
def _world_template(mesh: TetMesh, material: Material, pad_half_extents: tuple, contact: ContactParams) -> dict:
    """Host arrays of the one-world model of ``mesh`` with ``material`` (identity pose): the
    cached geometry and the material's rows (``sim.model.material_fields``, the arrays
    ``build_model`` makes, bit for bit)."""
    geometry = _geometry(mesh, pad_half_extents, contact)
    return {**geometry, **material_fields(geometry["tets"], geometry["tet_rest_volume"], len(geometry["nodes"]),
                                          material, contact)}


def set_materials(model: Model, worlds: Sequence[int], meshes: Sequence[TetMesh], materials: Sequence[Material],
                  pad_half_extents: Sequence[Sequence[float]]) -> None:
    """``sim.model.set_world_materials`` of ``worlds`` (holding ``meshes``) with their tets and rest
    volumes from the cached geometry: no transfer from the device, one scatter per array."""
    half = tuple(tuple(float(v) for v in h) for h in pad_half_extents)
    geometry = [_geometry(mesh, half, model.contact) for mesh in meshes]
    set_world_materials(model, worlds, materials, [g["tets"] for g in geometry],
                        [g["tet_rest_volume"] for g in geometry])


def slot_sizes(meshes: Sequence[TetMesh]) -> SlotSizes:
    """The slot of a model whose worlds may hold any of ``meshes`` (each object once)."""
    return SlotSizes(nodes=max(len(m.nodes) for m in meshes) + 1, tets=max(len(m.tets) for m in meshes),
                     triangles=max(len(m.surface) for m in meshes),
                     aggregates=max(int(bisect_nodes(np.asarray(m.nodes, dtype=np.float64)).max()) + 1
                                    for m in meshes),
                     blocks=max(block_count(np.asarray(m.tets), len(m.nodes)) for m in meshes))


def _rows(part: dict, pose: tuple, node_start: int, slots: SlotSizes | None) -> dict:
    """The rows one world fills (its object's, then its slot's spare ones): every node and tet
    field, rest positions at ``pose`` (float32), global tets and the aggregates."""
    n, t = len(part["nodes"]), len(part["tets"])
    x, q = pose
    rest = (part["nodes"] @ quat_to_matrix(quat_normalize(np.asarray(q, dtype=np.float64))).T
            + np.asarray(x, dtype=np.float64)).astype(np.float32)
    rows = {name: part[name] for name in (*_NODE_FIELDS, *_TET_FIELDS)}
    rows.update(rest_positions=rest, tets=(part["tets"] + node_start).astype(np.int32),
                node_aggregate=part["node_aggregate"], node_anchor=part["node_anchor"])
    if slots is None:
        return rows
    spare_nodes, spare_tets = slots.nodes - n, slots.tets - t
    aggregates = int(part["node_aggregate"].max()) + 1
    blocks = block_count(part["tets"], n)
    if (spare_nodes < 1 or spare_tets < 0 or slots.triangles < len(part["surface"]) or aggregates > slots.aggregates
            or blocks > slots.blocks):
        raise ValueError(f"an object of {n} nodes, {t} tets, {len(part['surface'])} surface triangles, {aggregates} "
                         f"coarse aggregates and {blocks} Hessian blocks does not fit the slot {slots}")
    spare = node_start + n  # the slot's first spare node: what its spare tets name

    def pad(a, count, value=0):
        return np.concatenate([a, np.full((count, *a.shape[1:]), value, dtype=a.dtype)])

    for name in _NODE_FIELDS:
        rows[name] = pad(rows[name], spare_nodes)
    for name in _TET_FIELDS:
        rows[name] = pad(rows[name], spare_tets)
    rows["rest_positions"] = np.concatenate([rest, np.tile(np.float32(SPARE_POSITION), (spare_nodes, 1))])
    rows["tets"] = pad(rows["tets"], spare_tets, spare)
    rows["node_aggregate"] = pad(rows["node_aggregate"], spare_nodes)
    rows["node_anchor"] = pad(rows["node_anchor"], spare_nodes)
    return rows


def assemble_model(meshes: Sequence[TetMesh], materials: Sequence[Material], poses: Sequence[tuple],
                   pad_half_extents: Sequence[Sequence[float]], contact: ContactParams, device: str,
                   slots: SlotSizes | None = None) -> Model:
    """The model ``build_model(meshes, materials, poses, pad_half_extents, contact, device=device)``
    returns (same arrays, bit for bit), from cached one-world models (meshes must be hashable: the
    scene's cached ``object_mesh`` instances); with ``slots``, that model slotted (``sim.model``):
    the same object rows, then spare rows."""
    half = tuple(tuple(float(v) for v in h) for h in pad_half_extents)
    parts = [_world_template(mesh, mat, half, contact) for mesh, mat in zip(meshes, materials)]
    counts = np.array([len(p["nodes"]) for p in parts])
    tet_counts = np.array([len(p["tets"]) for p in parts])
    node_rows = counts if slots is None else np.full(len(parts), slots.nodes)
    tet_rows = tet_counts if slots is None else np.full(len(parts), slots.tets)
    node_start = np.concatenate([[0], np.cumsum(node_rows)]).astype(np.int64)
    tet_start = np.concatenate([[0], np.cumsum(tet_rows)]).astype(np.int64)
    rows = [_rows(p, pose, s, slots) for p, pose, s in zip(parts, poses, node_start[:-1])]
    cat = np.concatenate
    world = np.arange(len(parts))

    def arr(name, dtype):
        return wp.array(np.ascontiguousarray(cat([r[name] for r in rows])), dtype=dtype, device=device)

    return Model(
        device=str(wp.get_device(device)), num_worlds=len(parts), pads_per_world=len(parts[0]["pad_half_extents"]),
        node_start=node_start, tet_start=tet_start, node_end=node_start[:-1] + counts,
        tet_end=tet_start[:-1] + tet_counts, surfaces=[p["surface"] for p in parts],
        node_aggregate=cat([r["node_aggregate"] for r in rows]), node_anchor=cat([r["node_anchor"] for r in rows]),
        rest_positions=arr("rest_positions", wp.vec3), tets=arr("tets", wp.vec4i),
        tet_world=wp.array(np.repeat(world, tet_rows).astype(np.int32), dtype=wp.int32, device=device),
        node_world=wp.array(np.repeat(world, node_rows).astype(np.int32), dtype=wp.int32, device=device),
        world_volume=wp.array(cat([p["world_volume"] for p in parts]), dtype=wp.float32, device=device),
        pad_half_extents=wp.array(cat([p["pad_half_extents"] for p in parts]), dtype=wp.vec3, device=device),
        gravity=parts[0]["gravity"], contact=contact,
        max_aggregates=0 if slots is None else slots.aggregates,
        triangle_slot=0 if slots is None else slots.triangles,
        block_slot=0 if slots is None else slots.blocks,
        **{name: arr(name, dtype) for name, dtype in {**_NODE_FIELDS, **_TET_FIELDS}.items()})


def _slots_of(model: Model) -> SlotSizes:
    if not model.triangle_slot:
        raise ValueError("the model is not slotted (assemble_model without slots)")
    return SlotSizes(nodes=int(model.node_start[1] - model.node_start[0]),
                     tets=int(model.tet_start[1] - model.tet_start[0]), triangles=model.triangle_slot,
                     aggregates=model.max_aggregates, blocks=model.block_slot)


def rewrite_worlds(model: Model, worlds: Sequence[int], meshes: Sequence[TetMesh], materials: Sequence[Material],
                   poses: Sequence[tuple], pad_half_extents: Sequence[Sequence[float]]) -> None:
    """Give the ``worlds`` of a slotted ``model`` the objects ``meshes`` (one per world listed) with
    ``materials`` at ``poses``, in place: their rows of every node and tet array, rest positions,
    volumes and aggregates, as ``assemble_model`` would build them (bit for bit), by one scatter
    per array; the other worlds' rows are not touched. Everything is checked before anything is
    written (distinct worlds in range, one mesh, material and pose each, each object fitting the
    slot)."""
    slots = _slots_of(model)
    worlds = [int(w) for w in worlds]
    if not len(meshes) == len(materials) == len(poses) == len(worlds):
        raise ValueError(f"need one mesh, material and pose per world: {len(worlds)} worlds, {len(meshes)} meshes, "
                         f"{len(materials)} materials, {len(poses)} poses")
    if len(set(worlds)) != len(worlds) or any(not 0 <= w < model.num_worlds for w in worlds):
        raise ValueError(f"worlds must be distinct, in [0, {model.num_worlds - 1}], got {worlds}")
    half = tuple(tuple(float(v) for v in h) for h in pad_half_extents)
    parts = [_world_template(mesh, mat, half, model.contact) for mesh, mat in zip(meshes, materials)]
    rows = [_rows(part, pose, int(model.node_start[w]), slots) for w, part, pose in zip(worlds, parts, poses)]
    node_index, tet_index = [], []
    for w, part, r in zip(worlds, parts, rows):  # all fit (``_rows`` raised otherwise): write
        start, tstart = int(model.node_start[w]), int(model.tet_start[w])
        node_index.append(np.arange(start, start + slots.nodes))
        tet_index.append(np.arange(tstart, tstart + slots.tets))
        model.node_end[w] = start + len(part["nodes"])
        model.tet_end[w] = tstart + len(part["tets"])
        model.surfaces[w] = part["surface"]
        model.node_aggregate[start:start + slots.nodes] = r["node_aggregate"]
        model.node_anchor[start:start + slots.nodes] = r["node_anchor"]
    if not rows:
        return
    d = model.device

    def scatter(index, name, dtype, target):
        values = wp.array(np.ascontiguousarray(np.concatenate([r[name] for r in rows])), dtype=dtype, device=d)
        wp.launch(scatter_rows, dim=len(index), inputs=[values, index, target], device=d)

    nodes = wp.array(np.concatenate(node_index).astype(np.int32), dtype=wp.int32, device=d)
    tets = wp.array(np.concatenate(tet_index).astype(np.int32), dtype=wp.int32, device=d)
    for name, dtype in _NODE_FIELDS.items():
        scatter(nodes, name, dtype, getattr(model, name))
    for name, dtype in _TET_FIELDS.items():
        scatter(tets, name, dtype, getattr(model, name))
    scatter(nodes, "rest_positions", wp.vec3, model.rest_positions)
    scatter(tets, "tets", wp.vec4i, model.tets)
    volumes = wp.array(np.concatenate([part["world_volume"] for part in parts]), dtype=wp.float32, device=d)
    index = wp.array(np.asarray(worlds, dtype=np.int32), dtype=wp.int32, device=d)
    wp.launch(scatter_rows, dim=len(index), inputs=[volumes, index, model.world_volume], device=d)
