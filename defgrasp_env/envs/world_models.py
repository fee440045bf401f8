"""Models of many worlds assembled from cached one-world models: a reset that changes objects
rebuilds the scene's flat arrays by concatenation (O(nodes) copies) instead of re-deriving every
world's rest shape, masses and stiffness (``build_model`` inverts each tet's rest matrix: ~4 ms
per world on this CPU). The result equals ``build_model`` of the same worlds bit for bit (each
world's data there depends on its own mesh, material and pose only)."""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np
import warp as wp

from ..sim.materials import Material
from ..sim.meshing import TetMesh
from ..sim.model import ContactParams, Model, build_model
from ..transforms import quat_normalize, quat_to_matrix

_NODE_FIELDS = {"node_mass": wp.float32, "node_contact_stiffness": wp.float32, "free_axes": wp.vec3}
_TET_FIELDS = {"tet_rest_inv": wp.mat33, "tet_rest_volume": wp.float32, "tet_mu": wp.float32,
               "tet_lambda": wp.float32}


@functools.lru_cache(maxsize=256)
def _world_template(mesh: TetMesh, material: Material, pad_half_extents: tuple, contact: ContactParams) -> dict:
    """Host arrays of the one-world model of ``mesh`` with ``material`` (identity pose)."""
    m = build_model([mesh], [material], pad_half_extents=[list(h) for h in pad_half_extents], contact=contact,
                    device="cpu")
    out = {name: getattr(m, name).numpy() for name in (*_NODE_FIELDS, *_TET_FIELDS)}
    out.update(tets=m.tets.numpy(), world_volume=m.world_volume.numpy(), pad_half_extents=m.pad_half_extents.numpy(),
               gravity=m.gravity, surface=m.surfaces[0], nodes=np.asarray(mesh.nodes, dtype=np.float64),
               node_aggregate=m.node_aggregate)
    return out


def assemble_model(meshes: Sequence[TetMesh], materials: Sequence[Material], poses: Sequence[tuple],
                   pad_half_extents: Sequence[Sequence[float]], contact: ContactParams, device: str) -> Model:
    """The model ``build_model(meshes, materials, poses, pad_half_extents, contact, device=device)``
    returns (same arrays, bit for bit), from cached one-world models (meshes must be hashable: the
    scene's cached ``object_mesh`` instances)."""
    half = tuple(tuple(float(v) for v in h) for h in pad_half_extents)
    parts = [_world_template(mesh, mat, half, contact) for mesh, mat in zip(meshes, materials)]
    counts = np.array([len(p["nodes"]) for p in parts])
    tet_counts = np.array([len(p["tets"]) for p in parts])
    node_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    tet_start = np.concatenate([[0], np.cumsum(tet_counts)]).astype(np.int64)
    rest = [p["nodes"] @ quat_to_matrix(quat_normalize(np.asarray(q, dtype=np.float64))).T + np.asarray(x, dtype=np.float64)
            for p, (x, q) in zip(parts, poses)]
    cat = np.concatenate
    world = np.arange(len(parts))

    def arr(a, dtype):
        return wp.array(np.ascontiguousarray(a), dtype=dtype, device=device)

    fields = {name: arr(cat([p[name] for p in parts]), dtype) for name, dtype in {**_NODE_FIELDS, **_TET_FIELDS}.items()}
    return Model(
        device=str(wp.get_device(device)), num_worlds=len(parts), pads_per_world=len(parts[0]["pad_half_extents"]),
        node_start=node_start, tet_start=tet_start, surfaces=[p["surface"] for p in parts],
        node_aggregate=cat([p["node_aggregate"] for p in parts]),
        rest_positions=arr(cat(rest).astype(np.float32), wp.vec3),
        tets=arr(cat([p["tets"] + s for p, s in zip(parts, node_start[:-1])]).astype(np.int32), wp.vec4i),
        tet_world=arr(np.repeat(world, tet_counts).astype(np.int32), wp.int32),
        node_world=arr(np.repeat(world, counts).astype(np.int32), wp.int32),
        world_volume=arr(cat([p["world_volume"] for p in parts]), wp.float32),
        pad_half_extents=arr(cat([p["pad_half_extents"] for p in parts]), wp.vec3),
        gravity=parts[0]["gravity"], contact=contact, **fields)
