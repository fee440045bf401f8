"""Model: the static data of a batched FEM simulation of W worlds (Newton's Model/State/Control split).

Every world holds one soft object (its own tetrahedral mesh and material) and ``pads_per_world``
kinematic boxes (the gripper pads). Nodes and tets of all worlds live in flat arrays; world ``w``
owns the rows ``node_start[w]:node_start[w+1]`` and ``tet_start[w]:tet_start[w+1]``, its object the
first of them: nodes ``node_start[w]:node_end[w]`` (``world_nodes``), tets ``tet_start[w]:tet_end[w]``
(``world_tets``). In a packed model (``build_model``) the two coincide. In a slotted model
(``envs.world_models.assemble_model`` with slot sizes) every world has the same number of rows, so
that a world's object can change in place; the rows past its object are spare: spare nodes are
parked at ``SPARE_POSITION``, fixed, massless and without contact stiffness; spare tets name the
world's first spare node four times with zero rest matrix, volume and Lamé parameters. They add
exact zeros to every sum of the solver, so a world's results do not depend on its slot.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import warp as wp

from ..transforms import quat_normalize, quat_to_matrix
from .aggregates import aggregate_anchors, bisect_nodes
from .kernels.world_rows import scatter_rows
from .materials import Material, check_range

#: Where the spare node rows of a slotted model rest (m, world frame): far above the task, out of
#: reach of the pads and the ground.
SPARE_POSITION = (0.0, 1000.0, 0.0)


@dataclass(frozen=True)
class ContactParams:
    """Penalty contact and Coulomb friction parameters shared by all worlds.

    The normal penalty stiffness of node i is ``k_i = min(stiffness, modulus_scale * E * h_i)``
    (``Model.node_contact_stiffness``) with E the world's Young's modulus and h_i = V_i^(1/3) the
    node's size (V_i: its lumped volume, a quarter of each adjacent tet's): ``modulus_scale`` times
    stiffer than the material around the node, so the penalty's own compliance is ~1 % of the
    contact's and the contact stays well conditioned for the linear solver at every E (a fixed
    1e6 N/m on an E = 1e4 object is ~1e5 times stiffer than the material: the solves did not
    converge and soft contacts read 5-15x the Hertz force). Beyond ``stiffening_depth`` the
    force grows cubically, k d + k (d - d_k)^3 / d_k^2, so that a depth of 4 d_k (1 mm by default)
    takes 7.75 k d_k... 31 k d_k: a soft object's low stiffness does not let a hard press sink in.

    Attributes:
        stiffness: upper bound of the normal penalty stiffness per node, N/m (the stiffness of stiff
            objects: 1e6 N/m keeps a node pushed with 100 N within 0.1 mm).
        ground_friction: Coulomb coefficient between object and ground, [0, inf).
        pad_friction: Coulomb coefficient between object and pads, [0, inf).
        stick_velocity: slip speed below which friction is treated as sticking, m/s (the smoothing
            width of the friction law: an object held with a margin creeps at most at this speed).
        modulus_scale: penalty stiffness of a node per Young's modulus and node size (dimensionless).
        stiffening_depth: depth (m) beyond which the penalty force grows cubically.
        edge_contact: also hold the pads' box edges and corners out of the object's surface
            (``sim/kernels/pad_edge_contact.py``: points every <= 1.5 mm along each pad box edge
            against the surface triangle nearest to each where the substep takes them, with
            the pads' friction, the first 0.5 mm free), so a pad edge cannot sink in between
            surface nodes. On by default; off gives node-vs-box contact alone (a pad edge or corner
            sinks up to ~2 mm between a coarse mesh's nodes; the expert's steps take 0.8-1.5x as
            long with it on, README).
    """

    stiffness: float = 1e6
    ground_friction: float = 0.5
    pad_friction: float = 1.0
    stick_velocity: float = 1e-4
    modulus_scale: float = 100.0
    stiffening_depth: float = 2.5e-4
    edge_contact: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.edge_contact, bool):
            raise TypeError(f"edge_contact must be a bool, got {self.edge_contact!r}")
        check_range("contact stiffness", self.stiffness, 0.0, math.inf, "N/m")
        check_range("ground_friction", self.ground_friction, 0.0, math.inf, low_open=False)
        check_range("pad_friction", self.pad_friction, 0.0, math.inf, low_open=False)
        check_range("stick_velocity", self.stick_velocity, 0.0, math.inf, "m/s")
        check_range("modulus_scale", self.modulus_scale, 0.0, math.inf)
        check_range("stiffening_depth", self.stiffening_depth, 0.0, math.inf, "m")


@dataclass
class Model:
    """Static arrays of the simulation (device arrays unless noted).

    Shapes: N nodes, T tets, W worlds, P pads per world. Frames: world, y up, metres.
    """

    device: str
    num_worlds: int
    pads_per_world: int
    node_start: np.ndarray        # [W+1] int64 host: first node row of each world
    tet_start: np.ndarray         # [W+1] int64 host: first tet row of each world
    node_end: np.ndarray          # [W] int64 host: one past the last node of each world's object
    tet_end: np.ndarray           # [W] int64 host: one past the last tet of each world's object
    surfaces: list[np.ndarray]    # W x [S_w,3] int32 host: boundary triangles, world-local node ids
    node_aggregate: np.ndarray    # [N] int32 host: world-local coarse aggregate of each node (``aggregates.py``,
                                  # cut in the object frame: the same for every pose)
    node_anchor: np.ndarray       # [N] int32 host: world-local node its aggregate's rotations turn about
                                  # (``aggregates.aggregate_anchors``; a slot's spare nodes: 0)
    rest_positions: wp.array      # [N] vec3, m: node positions at the initial pose
    tets: wp.array                # [T] vec4i: global node indices, positively oriented
    tet_rest_inv: wp.array        # [T] mat33: inverse of the rest edge matrix D_m (object frame), 1/m
    tet_rest_volume: wp.array     # [T] float, m^3
    tet_mu: wp.array              # [T] float, Pa: Lamé mu (shear modulus)
    tet_lambda: wp.array          # [T] float, Pa: Lamé lambda
    tet_world: wp.array           # [T] int32
    node_mass: wp.array           # [N] float, kg (lumped)
    node_contact_stiffness: wp.array  # [N] float, N/m: normal penalty stiffness (see ContactParams)
    node_world: wp.array          # [N] int32
    free_axes: wp.array           # [N] vec3: 1 = axis free, 0 = axis prescribed (Dirichlet)
    world_volume: wp.array        # [W] float, m^3: rest volume of each object
    pad_half_extents: wp.array    # [W*P] vec3, m: half sizes of the pad boxes in their own frame
    gravity: wp.vec3              # m/s^2
    contact: ContactParams
    #: coarse aggregates per world the solver allocates at least (a slotted model: the most of any
    #: object it may hold; 0: the most of the worlds' ``node_aggregate``)
    max_aggregates: int = 0
    #: surface triangle rows per world (a slotted model; 0: each world's own surface, packed)
    triangle_slot: int = 0
    #: elastic Hessian blocks per world the solver allocates (a slotted model: the most of any object
    #: it may hold, ``hessian_blocks.block_count``; 0: each world's own, packed)
    block_slot: int = 0

    @property
    def num_nodes(self) -> int:
        return int(self.node_start[-1])

    @property
    def num_tets(self) -> int:
        return int(self.tet_start[-1])

    def world_nodes(self, w: int) -> slice:
        """The rows of world ``w``'s object's nodes (its spare rows excluded)."""
        return slice(int(self.node_start[w]), int(self.node_end[w]))

    def world_tets(self, w: int) -> slice:
        """The rows of world ``w``'s object's tets (its spare rows excluded)."""
        return slice(int(self.tet_start[w]), int(self.tet_end[w]))


def _check_mesh(w: int, nodes: np.ndarray, tets: np.ndarray) -> None:
    if nodes.ndim != 2 or nodes.shape[1] != 3 or len(nodes) < 4:
        raise ValueError(f"world {w}: mesh nodes must have shape (N>=4, 3), got {nodes.shape}")
    if not np.all(np.isfinite(nodes)):
        raise ValueError(f"world {w}: mesh nodes contain NaN or inf")
    if tets.ndim != 2 or tets.shape[1] != 4 or len(tets) < 1:
        raise ValueError(f"world {w}: mesh tets must have shape (T>=1, 4), got {tets.shape}")
    if tets.min() < 0 or tets.max() >= len(nodes):
        raise ValueError(f"world {w}: tet node indices must be in [0, {len(nodes) - 1}], "
                         f"got [{tets.min()}, {tets.max()}]")


def build_model(
    meshes: Sequence,
    materials: Sequence[Material],
    poses: Sequence[tuple[Sequence[float], Sequence[float]]] | None = None,
    pad_half_extents: Sequence[Sequence[float]] = (),
    contact: ContactParams = ContactParams(),
    gravity: Sequence[float] = (0.0, -9.81, 0.0),
    fixed_axes: Sequence[np.ndarray] | None = None,
    device: str | None = None,
) -> Model:
    """Build a batched model with one object per world.

    Args:
        meshes: W meshes with ``nodes`` [N_w,3] (m, object frame), ``tets`` [T_w,4], ``surface`` [S_w,3].
        materials: W materials (one per world).
        poses: W initial poses (position [3] m, quaternion xyzw [4]) of the object frame in the world;
            default identity (object resting on the ground at the origin).
        pad_half_extents: P half extents [3] (m) of the kinematic pad boxes, the same in every world.
        contact: contact and friction parameters.
        gravity: gravity vector, m/s^2 (default -9.81 along y).
        fixed_axes: optional W boolean arrays [N_w,3]: True where a node coordinate is prescribed.
        device: Warp device ("cpu", "cuda:0"); default Warp's default device.
    """
    if len(meshes) == 0:
        raise ValueError("build_model needs at least one world, got 0 meshes")
    if len(materials) != len(meshes):
        raise ValueError(f"need one material per mesh: {len(meshes)} meshes, {len(materials)} materials")
    poses = poses if poses is not None else [((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))] * len(meshes)
    if len(poses) != len(meshes):
        raise ValueError(f"need one pose per mesh: {len(meshes)} meshes, {len(poses)} poses")
    device = str(wp.get_device(device))

    positions, tets, rest_inv, volumes, mus, lams, tet_world = [], [], [], [], [], [], []
    masses, node_world, free, world_volume, node_stiffness, aggregates, anchors = [], [], [], [], [], [], []
    node_start, tet_start = [0], [0]
    for w, (mesh, material, (pos, quat)) in enumerate(zip(meshes, materials, poses)):
        nodes = np.asarray(mesh.nodes, dtype=np.float64)
        t = np.asarray(mesh.tets, dtype=np.int64)
        _check_mesh(w, nodes, t)
        x = nodes @ quat_to_matrix(quat_normalize(np.asarray(quat, dtype=np.float64))).T + np.asarray(pos, dtype=np.float64)
        # rest shape from the object-frame nodes, so the model does not depend on the initial pose
        dm = np.stack([nodes[t[:, 1]] - nodes[t[:, 0]], nodes[t[:, 2]] - nodes[t[:, 0]],
                       nodes[t[:, 3]] - nodes[t[:, 0]]], axis=2)
        det = np.linalg.det(dm)
        scale = np.max(np.ptp(x, axis=0)) ** 3
        if np.any(det <= 1e-12 * scale):
            bad = int(np.argmin(det))
            raise ValueError(f"world {w}: tet {bad} is inverted or degenerate (6*volume = {det[bad]:.3e} m^3); "
                             "tets must be positively oriented with non-zero volume")
        vol = det / 6.0
        fields = material_fields(t, vol, len(x), material, contact)
        positions.append(x)
        aggregates.append(bisect_nodes(nodes))
        anchors.append(aggregate_anchors(nodes, aggregates[-1]))
        tets.append(t + node_start[-1])
        rest_inv.append(np.linalg.inv(dm))
        volumes.append(vol)
        mus.append(fields["tet_mu"])
        lams.append(fields["tet_lambda"])
        tet_world.append(np.full(len(t), w))
        masses.append(fields["node_mass"])
        node_stiffness.append(fields["node_contact_stiffness"])
        node_world.append(np.full(len(x), w))
        fa = np.zeros((len(x), 3), bool) if fixed_axes is None else np.asarray(fixed_axes[w], bool)
        if fa.shape != (len(x), 3):
            raise ValueError(f"world {w}: fixed_axes must have shape {(len(x), 3)}, got {fa.shape}")
        free.append(1.0 - fa)
        world_volume.append(vol.sum())
        node_start.append(node_start[-1] + len(x))
        tet_start.append(tet_start[-1] + len(t))

    half = np.asarray(pad_half_extents, dtype=np.float64).reshape(-1, 3)
    if np.any(half <= 0) or not np.all(np.isfinite(half)):
        raise ValueError(f"pad_half_extents must be finite and > 0 m, got {half.tolist()}")
    pads = len(half)
    half_all = np.tile(half, (len(meshes), 1)) if pads else np.zeros((0, 3))
    g = np.asarray(gravity, dtype=np.float64)
    if g.shape != (3,) or not np.all(np.isfinite(g)):
        raise ValueError(f"gravity must be a finite 3-vector in m/s^2, got {gravity!r}")

    def arr(a, dtype):
        return wp.array(np.ascontiguousarray(a), dtype=dtype, device=device)

    cat = np.concatenate
    return Model(
        device=device,
        num_worlds=len(meshes),
        pads_per_world=pads,
        node_start=np.asarray(node_start, dtype=np.int64),
        tet_start=np.asarray(tet_start, dtype=np.int64),
        node_end=np.asarray(node_start[1:], dtype=np.int64),
        tet_end=np.asarray(tet_start[1:], dtype=np.int64),
        surfaces=[np.asarray(mesh.surface, dtype=np.int32) for mesh in meshes],
        node_aggregate=cat(aggregates).astype(np.int32),
        node_anchor=cat(anchors).astype(np.int32),
        rest_positions=arr(cat(positions).astype(np.float32), wp.vec3),
        tets=arr(cat(tets).astype(np.int32), wp.vec4i),
        tet_rest_inv=arr(cat(rest_inv).astype(np.float32), wp.mat33),
        tet_rest_volume=arr(cat(volumes).astype(np.float32), wp.float32),
        tet_mu=arr(cat(mus).astype(np.float32), wp.float32),
        tet_lambda=arr(cat(lams).astype(np.float32), wp.float32),
        tet_world=arr(cat(tet_world).astype(np.int32), wp.int32),
        node_mass=arr(cat(masses).astype(np.float32), wp.float32),
        node_contact_stiffness=arr(cat(node_stiffness).astype(np.float32), wp.float32),
        node_world=arr(cat(node_world).astype(np.int32), wp.int32),
        free_axes=arr(cat(free).astype(np.float32), wp.vec3),
        world_volume=arr(np.asarray(world_volume, dtype=np.float32), wp.float32),
        pad_half_extents=arr(half_all.astype(np.float32), wp.vec3),
        gravity=wp.vec3(*g.astype(np.float32)),
        contact=contact,
    )


def lumped_masses(tets: np.ndarray, volumes: np.ndarray, density: float, num_nodes: int) -> np.ndarray:
    """Node masses (kg) [num_nodes]: a quarter of each tet's mass (tets [T, 4] local indices,
    volumes [T] m^3) to each of its nodes. The volumes are rounded to float32 first, as the model
    stores them, so that a material set later (``set_world_material``) gives the same bits."""
    m = np.zeros(num_nodes)
    vol = np.asarray(volumes, dtype=np.float32).astype(np.float64)
    np.add.at(m, np.asarray(tets).ravel(), np.repeat(density * vol / 4.0, 4))
    return m


def contact_stiffness(tets: np.ndarray, volumes: np.ndarray, youngs_modulus: float, num_nodes: int,
                      contact: ContactParams) -> np.ndarray:
    """Normal penalty stiffness (N/m) [num_nodes] of each node: min(contact.stiffness,
    contact.modulus_scale * E * V_i^(1/3)), V_i the node's lumped volume (tets [T, 4] local
    indices, volumes [T] m^3, rounded to float32 as the model stores them)."""
    v = np.zeros(num_nodes)
    vol = np.asarray(volumes, dtype=np.float32).astype(np.float64)
    np.add.at(v, np.asarray(tets).ravel(), np.repeat(vol / 4.0, 4))
    return np.minimum(contact.stiffness, contact.modulus_scale * youngs_modulus * np.cbrt(v))


def material_fields(tets: np.ndarray, volumes: np.ndarray, num_nodes: int, material: Material,
                    contact: ContactParams) -> dict[str, np.ndarray]:
    """The material-dependent rows of one object (float32, as the model stores them): its nodes'
    ``node_mass`` and ``node_contact_stiffness`` [num_nodes], its tets' ``tet_mu`` and
    ``tet_lambda`` [T] (tets [T, 4] local indices, volumes [T] m^3; the arrays ``build_model``
    makes, bit for bit)."""
    mu, lam = material.lame
    return {"node_mass": lumped_masses(tets, volumes, material.density, num_nodes).astype(np.float32),
            "node_contact_stiffness": contact_stiffness(tets, volumes, material.youngs_modulus, num_nodes,
                                                        contact).astype(np.float32),
            "tet_mu": np.full(len(tets), mu).astype(np.float32), "tet_lambda": np.full(len(tets), lam).astype(np.float32)}


def set_world_materials(model: Model, worlds, materials, tets, volumes) -> None:
    """Replace the materials of ``worlds`` in place (Lamé parameters, masses, contact stiffness),
    e.g. on an env reset: one upload and one scatter per array for all of them. ``tets`` and
    ``volumes``: per world, its object's tets [T_w, 4] (world-local node ids) and rest volumes
    [T_w] (m^3, as the model stores them), host copies."""
    worlds = [int(w) for w in worlds]
    if not len(materials) == len(tets) == len(volumes) == len(worlds):
        raise ValueError(f"need one material, tets and volumes per world: {len(worlds)} worlds, {len(materials)} "
                         f"materials, {len(tets)} tets, {len(volumes)} volumes")
    for w, t, v in zip(worlds, tets, volumes):
        if not 0 <= w < model.num_worlds:
            raise ValueError(f"world must be in [0, {model.num_worlds - 1}], got {w}")
        sl = model.world_tets(w)
        if len(t) != sl.stop - sl.start or len(v) != len(t):
            raise ValueError(f"world {w} has {sl.stop - sl.start} tets, got {len(t)} tets and {len(v)} volumes")
    if not worlds:
        return
    fields, node_rows, tet_rows = [], [], []
    for w, material, t, v in zip(worlds, materials, tets, volumes):
        nl, tl = model.world_nodes(w), model.world_tets(w)
        fields.append(material_fields(t, v, nl.stop - nl.start, material, model.contact))
        node_rows.append(np.arange(nl.start, nl.stop))
        tet_rows.append(np.arange(tl.start, tl.stop))
    d = model.device
    for rows, names in ((node_rows, ("node_mass", "node_contact_stiffness")), (tet_rows, ("tet_mu", "tet_lambda"))):
        index = wp.array(np.concatenate(rows).astype(np.int32), dtype=wp.int32, device=d)
        for name in names:
            values = wp.array(np.concatenate([f[name] for f in fields]), dtype=wp.float32, device=d)
            wp.launch(scatter_rows, dim=len(index), inputs=[values, index, getattr(model, name)], device=d)


def set_world_material(model: Model, world: int, material: Material) -> None:
    """Replace the material of one world in place (``set_world_materials`` with its tets and rest
    volumes read from the model)."""
    if not 0 <= world < model.num_worlds:
        raise ValueError(f"world must be in [0, {model.num_worlds - 1}], got {world}")
    sl, nl = model.world_tets(world), model.world_nodes(world)
    set_world_materials(model, [world], [material], [model.tets[sl].numpy() - nl.start],
                        [model.tet_rest_volume[sl].numpy()])
