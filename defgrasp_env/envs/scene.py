"""The batched pickup scene: W worlds, each with one soft object, a 2F-85 gripper on a 6-DOF wrist
(:class:`~defgrasp_env.gripper.Gripper`), the ground and the goal, in ONE FEM simulation. It steps
the gripper and the FEM together and reads back what the env observes. Shared by the single env
(W = 1) and the native vector env.

Physics substeps have one owner, :meth:`PickupScene.step`: a control period is
``substeps`` equal substeps (``config.solver.substeps``, more when the configured speeds let the
pads travel far in a period, ``sim.pad_motion``; never dependent on the actions), and
in each the gripper's jaw driver and wrist move on the pad forces of the one before, then the
solver takes ONE backward-Euler step (the solver is built with ``substeps=1``; its own substep loop
is not used, because the jaw driver and the actuators' force limit must see the forces of every
substep).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np
import warp as wp

from ..gripper import Gripper, pad_reach
from ..layout import NUM_KEYPOINTS
from ..sim.materials import Material
from ..sim.meshing import OBJECT_SHAPES, TetMesh, make_object_mesh, mesh_from_surface
from ..sim.launch_cache import LaunchCache
from ..sim.model import SPARE_POSITION, ContactParams
from ..sim.pad_motion import max_pad_travel, substeps_for_travel
from ..sim.solve_report import SolveReport
from ..sim.solver import ImplicitSolver, SolveStats
from ..sim.state import Control, State
from ..transforms import quat_to_matrix
from ..wrist.force_limit import FORCE_TOLERANCE, limited_substep, tip_force_bound
from .actions import max_flange_step
from .config import PickupConfig
from .limit_loads import SolveLoads
from .readouts import SceneReadouts, StepReadout
from .world_models import assemble_model, rewrite_worlds, set_materials, slot_sizes
from .period_graph import PeriodGraph
from .scene_kernels import (gather_rows, scatter_rows, solve_load_row, solve_loads, world_max, zero_float_rows_of_worlds,
                            zero_vec3_rows_of_worlds)

@functools.lru_cache(maxsize=16)
def object_mesh(name: str, resolution: float | None) -> TetMesh:
    """Cached tet mesh of a named object or a surface-mesh file (object frame, resting on y = 0)."""
    if name in OBJECT_SHAPES:
        return make_object_mesh(name, resolution)
    return mesh_from_surface(name, resolution if resolution is not None else 0.008)


def keypoint_indices(nodes: np.ndarray, surface: np.ndarray, count: int = NUM_KEYPOINTS) -> np.ndarray:
    """Deterministic farthest-point sample of ``count`` surface nodes (indices into ``nodes``)."""
    candidates = np.unique(surface)
    pts = nodes[candidates]
    chosen = [int(np.argmax(pts[:, 1] + 1e-3 * pts[:, 0]))]
    dist = np.linalg.norm(pts - pts[chosen[0]], axis=1)
    while len(chosen) < min(count, len(candidates)):
        nxt = int(np.argmax(dist))
        chosen.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(pts - pts[nxt], axis=1))
    return candidates[np.array(chosen)]


@functools.lru_cache(maxsize=16)
def object_keypoints(name: str, resolution: float | None) -> np.ndarray:
    """Cached ``keypoint_indices`` of ``object_mesh(name, resolution)`` (object-local node ids)."""
    mesh = object_mesh(name, resolution)
    return keypoint_indices(mesh.nodes, mesh.surface)


@dataclass(frozen=True)
class WorldSetup:
    """What a reset draws for one world: the object (a name of ``OBJECT_SHAPES`` or a mesh path),
    its material, its initial pose (object frame in the world), and the episode's goal."""

    object_name: str
    material: Material
    position: np.ndarray   # [3] m, object frame origin in the world
    quat: np.ndarray       # [4] xyzw
    goal: np.ndarray | None = None  # [3] m, world: the feature point's target (None: the config's ``goal``)


def _remap_index(old_start: np.ndarray, new_start: np.ndarray, keep: np.ndarray, device: str) -> wp.array:
    """int32 [rows of new layout]: the old row of each new row of a kept world, -1 elsewhere
    (``old_start`` / ``new_start`` [W+1]: first row of each world)."""
    counts = np.diff(new_start)
    world = np.repeat(np.arange(len(counts)), counts)
    local = np.arange(new_start[-1]) - new_start[world]
    index = np.where(keep[world], old_start[world] + local, -1)
    return wp.array(index.astype(np.int32), dtype=wp.int32, device=device)


class PickupScene:
    """W worlds of the pickup task in one simulation (flat arrays, per-world offsets).

    Public: ``config``, ``num_worlds``, ``gripper`` (the W grippers' state and kinematics),
    ``model`` / ``state`` (the FEM's static data and current full state, Newton style: read, do not
    write), ``solver`` (built with ``substeps=1``),
    ``substeps``, ``period_graphs`` and ``device_substeps`` (a control period as one graph),
    ``slots`` (each world's rows fit any of the config's objects, or None: packed), and the
    read-only accessors ``object_names``, ``setups``, ``materials``,
    ``mesh(w)`` and the readouts below (``readout()``: reduced on the device once per state).
    ``model``, ``state`` and ``solver`` are replaced when a reset changes a world's object in a
    packed scene (a slotted one keeps them): read them from the scene after each reset rather than
    holding on to them. ``slotted`` (constructor): None = slotted where the config names several
    objects, there are several worlds and the device is CUDA (a rebuild recaptures every graph
    there; a single env builds a new scene for another object anyway). Between resets ``state``
    is the same object after every ``step`` (zero-copy views of its arrays see each step); within a
    step two states alternate (a substep's solves read the current one, untouched, and write the
    other, which becomes current when a solve is accepted), and a step of an odd number of
    substeps ends with one copy back.
    """

    def __init__(self, config: PickupConfig, setups: list[WorldSetup], slotted: bool | None = None):
        self.config = config
        self.num_worlds = len(setups)
        if slotted is None:  # a rebuild recaptures every graph: on a GPU it costs more than spare rows do
            slotted = len(config.object_names) > 1 and self.num_worlds > 1 and wp.get_device(config.device).is_cuda
        #: the slot of every world (``world_models.SlotSizes``: each world's rows fit any of the
        #: config's objects, so that a reset changes a world's object in place), or None: packed
        #: rows, and a reset that changes an object rebuilds every array (``_rebuild``)
        self.slots = slot_sizes([object_mesh(name, config.object_resolution) for name in config.object_names]
                                ) if slotted else None
        #: physics substeps per control period, looped by ``step`` (the solver takes one per call):
        #: ``config.solver.substeps``, or more where the largest legal move of the pads in a period
        #: would exceed ``sim.pad_motion.MAX_PAD_TRAVEL`` per substep (a function of the config only)
        linear, angle = max_flange_step(config)
        travel = max_pad_travel(linear, angle, pad_reach(), config.gripper.closing_speed * config.dt)
        self.substeps = substeps_for_travel(travel, config.solver.substeps)
        self._gripper = Gripper(config.gripper, self.num_worlds, config.device, config.wrist_force_limit)
        #: run each control period as one graph where the solver captures graphs (``PeriodGraph``;
        #: the same results, bit for bit on the CPU); False: substep by substep from the host (a
        #: benchmark timing each solve on its own sets it)
        self.period_graphs = True
        self._build(setups)
        self._setups = list(setups)  # the setup each world was last reset to (initial pose, material)
        self.reset_worlds(np.ones(self.num_worlds, bool), setups)

    def _build(self, setups: list[WorldSetup]) -> None:
        """Model, solver, state and control of worlds holding ``setups``' objects and materials."""
        config = self.config
        self._object_names = tuple(s.object_name for s in setups)
        self._meshes = [object_mesh(s.object_name, config.object_resolution) for s in setups]
        contact = ContactParams(config.contact_stiffness, config.ground_friction, config.pad_friction,
                                edge_contact=config.edge_contact)
        half = Gripper.pad_half_extents
        self.model = assemble_model(self._meshes, [s.material for s in setups],
                                    [(s.position, s.quat) for s in setups], [half, half], contact, config.device,
                                    self.slots)
        self.solver = ImplicitSolver(self.model, dataclasses.replace(config.solver, substeps=1))
        self.state = State.from_model(self.model)
        self._home_state = self.state  # what ``state`` is between steps
        # the other state: a substep's solves (wrist-limit retries included) read ``state``, the
        # substep's untouched start, and write this one; the two swap when a solve is accepted
        self._next_state = State.from_model(self.model)
        self._control = Control.from_model(self.model)
        # the pads' targets are written by the gripper's kernels into its own arrays: the control reads those
        self._control.pad_target_positions, self._control.pad_target_orientations = self.gripper.pad_targets
        self._readouts = SceneReadouts(self.model, [self.state, self._next_state],
                                       [object_keypoints(s.object_name, config.object_resolution) for s in setups])
        self._report = SolveReport(self.num_worlds, self.model.device)  # the control step's solver report
        self._loads = wp.zeros(self.num_worlds, dtype=solve_load_row, device=self.model.device)  # ``solve_loads``
        #: [W] N/m: each world's stiffest node contact (``solve_loads``' bound on an unconverged
        #: solve's force error), set again where a reset changes objects or materials
        self._contact_stiffness = wp.zeros(self.num_worlds, dtype=wp.float32, device=self.model.device)
        self._set_contact_stiffness()
        #: substeps accepted inside a control period's graph since the scene was built (the others
        #: ran substep by substep on the host: the first period with a set of scalars, and all where
        #: the solver captures no graphs or ``period_graphs`` is off)
        self.device_substeps = 0
        self._launches = LaunchCache(self.model.device)  # per-solve launches, recorded once and replayed
        # a control period as one graph where the solver captures graphs (``period_graph``)
        self._period = PeriodGraph(self.solver, self.gripper, self._control, self._loads, self._launch_loads,
                                   self._accept_launches, self._launches)
        self._solves = 0  # solves run by ``_solve_substep`` (the wrist limit's accepted solve is its last)
        #: world-solves run since the scene was built: per solver call, the worlds it computed (all of
        #: them in a substep's first solve, those the force limit retries or re-solves patiently after)
        self.world_solves = 0
        #: [W] bool: the world's last solve of the current substep was patient (its result is what a
        #: re-solve from the same input and target would get: ``_patient_if_over`` skips it)
        self._patient_solved = np.zeros(self.num_worlds, dtype=bool)
        self._readout: StepReadout | None = None
        world = np.arange(self.num_worlds, dtype=np.int32)
        self._world_ids = wp.array(world, dtype=wp.int32, device=self.model.device)  # [W]: row w is world w
        self._pad_world = wp.array(np.repeat(world, self.model.pads_per_world), dtype=wp.int32,
                                   device=self.model.device)  # [W*P]: the world of each pad row

    # -- accessors ---------------------------------------------------------------------------
    @property
    def gripper(self) -> Gripper:
        """The W grippers (state, kinematics); the scene's control reads their pad targets, so the
        scene keeps this one gripper for its life (read-only attribute)."""
        return self._gripper

    @property
    def object_names(self) -> tuple[str, ...]:
        """The object each world holds now (a name of ``OBJECT_SHAPES`` or a mesh path)."""
        return self._object_names

    @property
    def setups(self) -> tuple[WorldSetup, ...]:
        """The setup each world was last reset to (object, material, initial pose)."""
        return tuple(self._setups)

    @property
    def materials(self) -> list[Material]:
        """The material of each world (that of its last reset)."""
        return [s.material for s in self._setups]

    def mesh(self, w: int) -> TetMesh:
        """Rest tet mesh of world ``w``'s object (object frame, m)."""
        return self._meshes[w]

    # -- resets ----------------------------------------------------------------------------
    def reset_worlds(self, mask: np.ndarray, setups: list[WorldSetup]) -> None:
        """Put the worlds in ``mask`` back to their initial state with the given setups; other
        worlds are left untouched, bit for bit (their full state and their gripper). A world whose
        object changes has its rows rewritten in place (``slots``: ``_rewrite``), or makes the scene
        rebuild its flat arrays (packed rows: ``_rebuild``)."""
        changed = [w for w in np.flatnonzero(mask) if setups[w].object_name != self._object_names[w]]
        if changed and self.slots is None:
            self._rebuild(mask, setups)
        elif changed:
            self._rewrite(changed, setups)
        m = self.model
        rows, values, materials = [], [], []
        flange_xz = np.zeros((self.num_worlds, 2))
        for w in np.flatnonzero(mask):
            s = setups[w]
            sl = m.world_nodes(w)
            local = self._meshes[w].nodes
            spare = int(m.node_start[w + 1]) - sl.stop  # a slot's spare rows go back to where they rest
            rows.append(np.arange(sl.start, sl.stop + spare, dtype=np.int32))
            values.append(np.concatenate([(local @ quat_to_matrix(s.quat).T + s.position).astype(np.float32),
                                          np.tile(np.float32(SPARE_POSITION), (spare, 1))]))
            if s.material != self._setups[w].material:
                materials.append(w)
            self._setups[w] = s
            flange_xz[w] = s.position[0], s.position[2]
        set_materials(m, materials, [self._meshes[w] for w in materials], [setups[w].material for w in materials],
                      [Gripper.pad_half_extents] * 2)
        self.gripper.reset(mask, flange_xz)
        self._readout = None
        if rows:  # only the reset worlds' rows travel (no full-state download)
            index = wp.array(np.concatenate(rows), dtype=wp.int32, device=m.device)
            x = wp.array(np.concatenate(values), dtype=wp.vec3, device=m.device)
            wp.launch(scatter_rows, dim=len(index), inputs=[x, index, self.state.positions], device=m.device)
        self._zero_outputs(mask)
        if changed or materials:  # a rebuild set it in ``_build``; a rewrite or new materials change it
            self._set_contact_stiffness()
        pos, quat = self.gripper.pad_poses()
        self.state.pad_positions.assign(pos.reshape(-1, 3).astype(np.float32))
        self.state.pad_orientations.assign(quat.reshape(-1, 4).astype(np.float32))

    def _set_contact_stiffness(self) -> None:
        """``_contact_stiffness`` from the model's node contact stiffness (one launch over the nodes)."""
        m = self.model
        self._contact_stiffness.zero_()
        wp.launch(world_max, dim=m.num_nodes, inputs=[m.node_contact_stiffness, m.node_world],
                  outputs=[self._contact_stiffness], device=m.device)

    def _rebuild(self, mask: np.ndarray, setups: list[WorldSetup]) -> None:
        """New flat arrays for the objects after the reset of ``mask`` (node and tet offsets change
        with the objects), with the full state of every world outside ``mask`` copied to its new
        offsets by a gather kernel on the device (the gripper's per-world state has no offsets and
        stays). The worlds in ``mask`` are then set by ``reset_worlds``."""
        old_model, old_state = self.model, self.state
        kept = [self._setups[w] if not mask[w] else setups[w] for w in range(self.num_worlds)]
        self._build(kept)
        for w in np.flatnonzero(mask):
            self._setups[w] = setups[w]  # built with its new material: no material update needed
        new = self.model
        node_index = _remap_index(old_model.node_start, new.node_start, ~mask, new.device)
        tet_index = _remap_index(old_model.tet_start, new.tet_start, ~mask, new.device)
        for name in ("positions", "velocities", "elastic_force", "contact_force", "von_mises"):
            index = tet_index if name == "von_mises" else node_index
            dst = getattr(self.state, name)
            wp.launch(gather_rows, dim=len(dst), inputs=[getattr(old_state, name), index, dst], device=new.device)
        for name in ("pad_positions", "pad_orientations", "mean_von_mises", "pad_normal_force", "pad_force"):
            wp.copy(getattr(self.state, name), getattr(old_state, name))  # [W] / [W*P]: same layout

    def _rewrite(self, worlds: list[int], setups: list[WorldSetup]) -> None:
        """Give ``worlds`` their setups' objects in place (a slotted model, ``slots``): their rows of
        the model (``world_models.rewrite_worlds``), of the solver's copies of it, of the control's
        prescribed positions and of the readouts; every array, and with them the recorded launches
        and captured graphs, stays. The worlds' states are then set by ``reset_worlds``."""
        config = self.config
        half = Gripper.pad_half_extents
        meshes = [object_mesh(setups[w].object_name, config.object_resolution) for w in worlds]
        rewrite_worlds(self.model, worlds, meshes, [setups[w].material for w in worlds],
                       [(setups[w].position, setups[w].quat) for w in worlds], [half, half])
        self.solver.scratch.rewrite_worlds(self.model, worlds)
        # the other state's rows of these worlds held the old objects' outputs, and the solver does
        # not write spare rows: no row of a rewritten world keeps them
        rewritten = np.zeros(self.num_worlds, bool)
        rewritten[worlds] = True
        self._zero_outputs(rewritten, self._next_state)
        wp.copy(self._control.prescribed_positions, self.model.rest_positions)  # Control.from_model's
        names = list(self._object_names)
        for w, mesh in zip(worlds, meshes):
            self._meshes[w] = mesh
            names[w] = setups[w].object_name
            self._setups[w] = setups[w]  # built with its new material: no material update needed
        self._object_names = tuple(names)
        self._readouts.set_objects(self.model, [object_keypoints(n, config.object_resolution) for n in names])

    def _zero_outputs(self, mask: np.ndarray, state: State | None = None) -> None:
        """Velocities, forces and stresses of freshly reset worlds (at rest shape, untouched): zeroed
        by kernels on the device, row by row of the worlds in ``mask`` (in ``state``, default the
        current one)."""
        m, st, d = self.model, state if state is not None else self.state, self.model.device
        world_mask = wp.array(mask.astype(np.int32), dtype=wp.int32, device=d)
        for array, row_world in ((st.velocities, m.node_world), (st.elastic_force, m.node_world),
                                 (st.contact_force, m.node_world), (st.pad_force, self._pad_world)):
            wp.launch(zero_vec3_rows_of_worlds, dim=len(array), inputs=[array, row_world, world_mask], device=d)
        for array, row_world in ((st.von_mises, m.tet_world), (st.mean_von_mises, self._world_ids),
                                 (st.pad_normal_force, self._pad_world)):
            wp.launch(zero_float_rows_of_worlds, dim=len(array), inputs=[array, row_world, world_mask], device=d)

    # -- stepping --------------------------------------------------------------------------
    def step(self, target_pos: np.ndarray, target_quat: np.ndarray, target_gap: np.ndarray,
             active: np.ndarray | None = None) -> SolveStats:
        """Move wrists and jaws toward the targets (flange pos [W, 3] m, quat [W, 4] xyzw, gap [W] m;
        limits enforced) and advance the FEM by one control period in ``substeps`` physics
        substeps: per substep the gripper plans jaw and wrist on the pad forces of the previous one
        (``Gripper.plan_substep``), the solver takes one step with the pads moved there
        (``Gripper.move``; retried with a fraction of the wrist's motion and the jaw's closing while
        the pads' net force exceeds ``config.wrist_force_limit`` or a pad's normal force the grip
        force limit plus it, ``wrist.force_limit``), and the gripper reads the new pad forces
        (``Gripper.sense``). Worlds with ``active == False`` keep their wrist and jaw
        still."""
        self.gripper.begin_step(target_pos, target_quat, target_gap, active)
        return self._advance_period()

    def step_to_gripper_targets(self, active: np.ndarray | None = None) -> SolveStats:
        """:meth:`step` toward the targets already in ``gripper.targets`` on the device (written by a
        kernel: the env's action decoding), with no transfer of them."""
        self.gripper.begin_step_to_targets(active)
        return self._advance_period()

    def _advance_period(self) -> SolveStats:
        """The control period's substeps after the gripper's ``begin_step``: as one graph on the
        device (``period_graph.PeriodGraph``: the same launches and decisions) where the solver
        captures graphs, else here, each substep's first try followed by the force limit's
        decisions on the host."""
        self._readout = None
        count = self.substeps
        h = self.config.dt / count
        run = self._period.run((self.state, self._next_state), count, h) if self.period_graphs else None
        if run is not None:
            self._solves += run.solves
            self.world_solves += run.world_solves
            self.device_substeps += run.accepted
            if run.accepted % 2:  # the graph's states alternate from the home state
                self.state, self._next_state = self._next_state, self.state
            if run.accepted < count:  # a solve left non-finite pad forces: the graph stopped there
                self._read_loads()
                raise RuntimeError("the period graph stopped on a solve whose loads read finite")
        else:
            for k in range(count):
                self.gripper.plan_substep(k, count, h)
                self._limit_and_accept(k, h, *self._solve_substep(None, h, last=k == count - 1))
        if self.state is not self._home_state:  # an odd number of substeps
            self._home_state.copy_from(self.state)
            self.state, self._next_state = self._home_state, self.state
        return self._report.download()

    def _limit_and_accept(self, k: int, h: float, number: int, loads: SolveLoads) -> None:
        """Substep ``k`` after its first try (solve ``number`` and its ``loads``): the force
        limit's retries and patient re-solves where a load is over a limit, then the accepted
        solve's state becomes current, its report is folded in and the gripper senses its pad
        forces."""
        solved = np.where(loads.held, 0.0, 1.0)  # the fraction [W] each world's last solve of this substep moved by

        def solve(fraction):
            # a retry re-solves only the worlds whose fraction changed: the others' last solve
            # (in the other state, untouched since) is what a new one would give
            nonlocal solved
            number, loads = self._solve_substep(fraction, h, worlds=fraction != solved, last=last)
            solved = np.array(fraction, dtype=np.float64)
            return self._patient_if_over(number, loads, fraction, h, last)

        last = k == self.substeps - 1
        first = self._patient_if_over(number, loads, solved, h, last)
        number, _, _ = limited_substep(solve, loads.start, held=loads.held, first=first,
                                       can_back_off=self._aim_back_off)
        if number != self._solves:
            raise RuntimeError(f"the actuator force limit accepted solve {number} of {self._solves}: only "
                               "the last solve's state, report and the gripper's move are kept")
        self.state, self._next_state = self._next_state, self.state
        self._accept_launches(k, self.state)

    def _aim_back_off(self, over: np.ndarray) -> np.ndarray:
        """[W] bool: the worlds whose wrist can back off (``Gripper.aim_back_off``, aimed in every
        world from the stopped solves in the other state), of the stopped ones still ``over`` the
        limit (``limited_substep``'s ``can_back_off``)."""
        self.gripper.aim_back_off(self._next_state.pad_force)
        return np.asarray(over, dtype=bool) & np.any(self.gripper.back_off != 0.0, axis=1)

    def _accept_launches(self, k: int, accepted: State) -> None:
        """Substep ``k``'s accepted solve (in ``accepted``): its report folded in, its pad forces
        sensed, its move's fraction the limit's scale (launches only)."""
        self._report.fold(self.solver.scratch, self.solver.config.penetration_bound, first=k == 0)
        self.gripper.sense(accepted.pad_normal_force, accepted.pad_force, record_limit=True)

    def _patient_if_over(self, number: int, loads: SolveLoads, fraction: np.ndarray, h: float, last: bool):
        """(solve number, load [W]) of a solve (of ``fraction`` [W] of the planned motion), re-solved
        patiently where ``SolveLoads.patient_re_solve`` asks (``limit_loads``: over the limit and
        the re-solve can change the decision or the kept forces) in the worlds whose solve is
        unconverged and was not patient already (``_patient_solved``)."""
        if (loads.load > 1.0 + FORCE_TOLERANCE).any():
            # not a world whose last solve was patient already: the flag ``unconverged`` stays set
            # after a patient solve (it tells of the regular iterations), and a re-solve from the
            # same input would repeat that solve, bit for bit on the CPU (a stopped world that still
            # reads over its limit was so re-solved after each of the substep's later retries)
            patient, target = loads.patient_re_solve(fraction, ~self._last_solve_converged() & ~self._patient_solved)
            if patient.any():
                number, loads = self._solve_substep(fraction, h, patient, worlds=patient, last=last,
                                                    patient_update=target)
        return number, loads.load

    def _solve_substep(self, fraction: np.ndarray | None, h: float, patient: np.ndarray | None = None,
                       worlds: np.ndarray | None = None, last: bool = True,
                       patient_update: np.ndarray | None = None) -> tuple[int, SolveLoads]:
        """One solve of the planned substep from its start (``state``, left untouched) into the
        other state, with ``fraction`` [W] of the actuators' motion (the force limit's retry,
        ``Gripper.move``; None: the plan's first try, ``Gripper.move_as_planned``), the ``patient``
        worlds [W] iterated until their update is at most ``patient_update`` [W] (m; default the
        Newton tolerance), of the ``worlds`` [W] bool (default all; the others keep their last
        solve: ``ImplicitSolver.advance``); ``last``: the period's last substep, whose solve writes
        every output (the earlier ones only the contact part the gripper and the force limit read:
        ``full_outputs``). Returns (the solve's number, its loads: ``_read_loads``); the report and
        the forces stay on the device."""
        if fraction is None:
            self.gripper.move_as_planned()  # writes the control's pad targets
        else:
            self.gripper.move(fraction)
        out = self._next_state
        self.solver.advance(self.state, out, self._control, h, patient, worlds, full_outputs=last,
                            patient_update=patient_update)
        solved = np.ones(self.num_worlds, dtype=bool) if worlds is None else np.asarray(worlds, dtype=bool)
        self._patient_solved[solved] = False if patient is None else np.asarray(patient, dtype=bool)[solved]
        self.world_solves += self.num_worlds if worlds is None else int(np.count_nonzero(worlds))
        self._launch_loads(out)
        loads = self._read_loads()
        self._solves += 1
        return self._solves, loads

    def _launch_loads(self, out: State) -> None:
        """``solve_loads`` of the solve in ``out`` into ``_loads`` (an unconverged solve's load
        raised by its possible force error: see there)."""
        wrist_limit, grip_limit = self.config.wrist_force_limit, self.config.gripper.grip_force_limit
        unit = min(wrist_limit, tip_force_bound(grip_limit, wrist_limit))
        tolerance = self.solver.config.newton_tolerance
        self._launches.launch(("loads", id(out), wrist_limit, grip_limit, tolerance), solve_loads, self.num_worlds,
                              [out.pad_normal_force, out.pad_force, self.gripper.plan_limits, wrist_limit, grip_limit,
                               self.solver.scratch.last_dx, tolerance, self._contact_stiffness, unit],
                              [self._loads], keep=(out,))

    def _read_loads(self) -> SolveLoads:
        """The last solve's loads from one download (``scene_kernels.solve_loads``); raises where
        its pad forces are not finite."""
        return SolveLoads.from_rows(self._loads.numpy().copy())  # CPU: numpy() views

    def _last_solve_converged(self) -> np.ndarray:
        """[W] bool: the last solve met the Newton tolerance in every substep and did not diverge
        (downloaded only when a world is over an actuator limit)."""
        s = self.solver.scratch
        return (s.unconverged.numpy() == 0) & (s.diverged.numpy() == 0)

    # -- readouts --------------------------------------------------------------------------
    def node_positions(self, w: int) -> np.ndarray:
        """Node positions [N_w, 3] (m, world) of world ``w``'s object (a copy)."""
        return self.state.positions.numpy()[self.model.world_nodes(w)].copy()

    def readout(self) -> StepReadout:
        """Feature point and velocity, keypoints, finiteness and pad embedding of every world at the current state
        (``readouts.StepReadout``): reduced on the simulation's device, once per state (cached until
        the next ``step`` or reset), so observations, reward and the divergence check share it."""
        if self._readout is None:
            self._readout = self._readouts.compute(self.state)
        return self._readout

    def device_readouts(self) -> SceneReadouts:
        """The readouts of the current state on the device (``SceneReadouts``' public arrays: feature
        point and velocity, keypoints, finiteness, pad embedding), launched now, not downloaded:
        for kernels that read them (``PickupTask``). Valid until the next step or reset."""
        self._readouts.launch(self.state)
        return self._readouts

    @property
    def solve_report(self) -> SolveReport:
        """The last control step's solver report on the device (``SolveReport.records`` [W]);
        ``step`` returns it downloaded."""
        return self._report

    def feature_points(self) -> tuple[np.ndarray, np.ndarray]:
        """Object feature point (mean node position, paper eq. 5) [W,3] m and its velocity [W,3] m/s."""
        r = self.readout()
        return r.feature_position, r.feature_velocity

    def keypoint_positions(self) -> np.ndarray:
        """[W, NUM_KEYPOINTS, 3] positions (m) of fixed surface nodes of each object."""
        return self.readout().keypoints

    def finite(self) -> np.ndarray:
        """[W] bool: the world's node positions and velocities are all finite."""
        return self.readout().finite

    def pad_embedding(self) -> np.ndarray:
        """[W] m: how deep the object's material lies inside a pad (its deepest tet centroid inside
        a pad box; ``StepReadout.pad_embedding``), 0 where none is."""
        return self.readout().pad_embedding
