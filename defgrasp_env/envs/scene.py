"""The batched pickup scene: W worlds, each with one soft object, a 2F-85 gripper on a 6-DOF wrist,
the ground and the goal. It turns wrist/jaw targets into kinematic pad motion for the FEM solver and
reads back what the env observes. Shared by the single env (W = 1) and the native vector env.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from ..gripper import GAP_MAX, GAP_MIN, GripperDriver, pad_boxes, update_grip_stiffness
from ..sim.materials import Material
from ..sim.meshing import OBJECT_SHAPES, TetMesh, make_object_mesh, mesh_from_surface
from ..sim.model import ContactParams, build_model, set_world_material
from ..sim.pad_motion import corner_travel, substeps_for_travel
from ..sim.solver import ImplicitSolver, SolveStats
from ..sim.state import Control, State
from ..transforms import axis_angle_to_quat, quat_multiply, quat_normalize, quat_rotate, quat_to_matrix
from ..wrist import clamp_joints, fk_analytic, ik_analytic
from ..wrist.force_limit import limited_substep, wrist_force
from .config import PickupConfig

#: Extra thickness (m) of each pad's collision box behind its inner face, so that a fast-closing pad
#: can never push a node through itself; the inner face stays where the linkage puts it.
PAD_BACKING = 0.01
#: Number of object surface keypoints in the observation.
NUM_KEYPOINTS = 8
#: Start height of the flange above the ground (m) and pad clearance kept above the ground (m).
START_FLANGE_HEIGHT = 0.30
GROUND_CLEARANCE = 0.001
#: Half extents (m) of each pad's collision box (the pad plus its backing), and the signs of its 8 corners.
PAD_BOX_HALF_EXTENTS = pad_boxes(gap=GAP_MAX)[1][0] + np.array([PAD_BACKING / 2, 0.0, 0.0])
_CORNER_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)


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


@dataclass
class WorldSetup:
    """What a reset draws for one world."""

    object_name: str
    material: Material
    position: np.ndarray   # [3] m, object frame origin in the world
    quat: np.ndarray       # [4] xyzw


class PickupScene:
    """W worlds of the pickup task in one simulation (flat arrays, per-world offsets)."""

    def __init__(self, config: PickupConfig, setups: list[WorldSetup]):
        self.config = config
        self.num_worlds = len(setups)
        self.driver = GripperDriver(config.gripper)
        self.object_names = [s.object_name for s in setups]
        meshes = [object_mesh(s.object_name, config.object_resolution) for s in setups]
        contact = ContactParams(config.contact_stiffness, config.ground_friction, config.pad_friction)
        half = PAD_BOX_HALF_EXTENTS
        self.model = build_model(meshes, [s.material for s in setups],
                                 [(s.position, s.quat) for s in setups], pad_half_extents=[half, half],
                                 contact=contact, device=config.device)
        # one solver call per physics substep (see ``step``)
        self.solver = ImplicitSolver(self.model, dataclasses.replace(config.solver, substeps=1))
        self.state = State.from_model(self.model)
        self.control = Control.from_model(self.model)
        self.meshes = meshes
        self.keypoints = [keypoint_indices(m.nodes, m.surface) for m in meshes]
        w = self.num_worlds
        self.q = np.zeros((w, 6))
        self.gap = np.full(w, GAP_MAX)
        self.tip_force = np.zeros((w, 2))
        self.grip_stiffness = np.zeros(w)  # N/m, the jaw driver's estimate (0: not gripping)
        self.wrist_force = np.zeros(w)     # N, net force of the pads on the object (wrist force limit)
        self._substep_start = State.from_model(self.model)  # wrist force limit: re-solve a substep from here
        self.setups = list(setups)  # the setup each world was last reset to (initial pose, material)
        self.reset_worlds(np.ones(w, bool), setups)

    # -- resets ----------------------------------------------------------------------------
    def reset_worlds(self, mask: np.ndarray, setups: list[WorldSetup]) -> None:
        """Put the worlds in ``mask`` back to their initial state with the given setups (objects must
        match the built ones); other worlds are left untouched, bit for bit."""
        m = self.model
        x = self.state.positions.numpy()
        v = self.state.velocities.numpy()
        for w in np.flatnonzero(mask):
            s = setups[w]
            if s.object_name != self.object_names[w]:
                raise ValueError(f"world {w} holds {self.object_names[w]!r}; cannot reset it to {s.object_name!r}")
            sl = m.world_nodes(w)
            local = self.meshes[w].nodes
            x[sl] = (local @ quat_to_matrix(s.quat).T + s.position).astype(np.float32)
            v[sl] = 0.0
            if s.material != self.setups[w].material:
                set_world_material(m, w, s.material)
            self.setups[w] = s
            self.q[w] = [s.position[0], START_FLANGE_HEIGHT, s.position[2], 0.0, 0.0, 0.0]
            self.gap[w] = GAP_MAX
            self.tip_force[w] = 0.0
            self.grip_stiffness[w] = 0.0
            self.wrist_force[w] = 0.0
        self.state.positions.assign(x)
        self.state.velocities.assign(v)
        self._zero_outputs(mask)
        pos, quat = self.pad_poses()
        self.state.pad_positions.assign(pos.reshape(-1, 3).astype(np.float32))
        self.state.pad_orientations.assign(quat.reshape(-1, 4).astype(np.float32))

    def _zero_outputs(self, mask: np.ndarray) -> None:
        """Forces and stresses of freshly reset worlds: the object is at rest shape, untouched."""
        m, st = self.model, self.state
        node_mask = np.repeat(mask, np.diff(m.node_start))
        tet_mask = np.repeat(mask, np.diff(m.tet_start))
        pad_mask = np.repeat(mask, m.pads_per_world)
        for array, rows in ((st.elastic_force, node_mask), (st.contact_force, node_mask), (st.von_mises, tet_mask),
                            (st.mean_von_mises, mask), (st.pad_normal_force, pad_mask), (st.pad_force, pad_mask)):
            host = array.numpy()
            host[rows] = 0.0
            array.assign(host)

    @property
    def materials(self) -> list[Material]:
        """The material of each world (that of its last reset)."""
        return [s.material for s in self.setups]

    # -- kinematics ------------------------------------------------------------------------
    def flange_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Flange positions [W,3] (m) and orientations [W,4] (xyzw) in the world."""
        return fk_analytic(self.q)

    def pad_poses(self, q: np.ndarray | None = None, gap: np.ndarray | None = None):
        """Collision-box centres [W,2,3] (m) and orientations [W,2,4] of the pads for joints q and gap."""
        q = self.q if q is None else q
        gap = self.gap if gap is None else gap
        pos, quat = fk_analytic(q)
        centers = pad_boxes(gap=np.clip(gap, GAP_MIN, GAP_MAX))[0].copy()      # [W,2,3] in G
        centers[:, 0, 0] += PAD_BACKING / 2
        centers[:, 1, 0] -= PAD_BACKING / 2
        world = pos[:, None, :] + quat_rotate(quat[:, None, :], centers)
        return world, np.repeat(quat[:, None, :], 2, axis=1)

    def _lift_above_ground(self, q: np.ndarray, gap: np.ndarray):
        """Raise the flange so that no pad corner is below GROUND_CLEARANCE. Returns the joints and
        the pad poses (as ``pad_poses``) for them."""
        centers, quats = self.pad_poses(q, gap)
        corners = centers[:, :, None, :] + quat_rotate(quats[:, :, None, :], _CORNER_SIGNS * PAD_BOX_HALF_EXTENTS)
        lowest = corners[..., 1].reshape(len(q), -1).min(axis=1)
        lifted = q.copy()
        lifted[:, 1] += np.maximum(GROUND_CLEARANCE - lowest, 0.0)
        lifted = clamp_joints(lifted)
        centers[..., 1] += (lifted[:, 1] - q[:, 1])[:, None]  # joint 1 is the world-y slide
        return lifted, centers, quats

    def wrist_targets_from_delta(self, action: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Target flange pos [W,3], quat [W,4] and gap [W] for normalised delta actions [W,7]."""
        cfg = self.config
        pos, quat = self.flange_pose()
        target_pos = pos + action[:, :3] * cfg.max_linear_speed * cfg.dt
        dq = axis_angle_to_quat(action[:, 3:6] * cfg.max_angular_speed * cfg.dt)
        target_quat = quat_normalize(quat_multiply(dq, quat))
        target_gap = GAP_MAX + (GAP_MIN - GAP_MAX) * (action[:, 6] + 1.0) / 2.0
        return target_pos, target_quat, target_gap

    def rate_limited(self, target_pos, target_quat) -> tuple[np.ndarray, np.ndarray]:
        """Move the flange toward absolute targets no faster than the configured speeds."""
        cfg = self.config
        pos, quat = self.flange_pose()
        d = target_pos - pos
        dist = np.linalg.norm(d, axis=1, keepdims=True)
        step = np.minimum(1.0, cfg.max_linear_speed * cfg.dt / np.maximum(dist, 1e-12))
        rel = quat_multiply(target_quat, quat * np.array([-1, -1, -1, 1.0]))
        rel = np.where(rel[:, 3:4] < 0, -rel, rel)
        angle = 2 * np.arctan2(np.linalg.norm(rel[:, :3], axis=1), rel[:, 3])
        frac = np.minimum(1.0, cfg.max_angular_speed * cfg.dt / np.maximum(angle, 1e-12))
        axis = rel[:, :3] / np.maximum(np.linalg.norm(rel[:, :3], axis=1, keepdims=True), 1e-12)
        new_quat = quat_multiply(axis_angle_to_quat(axis * (angle * frac)[:, None]), quat)
        return pos + d * step, quat_normalize(new_quat)

    # -- stepping --------------------------------------------------------------------------
    def step(self, target_pos: np.ndarray, target_quat: np.ndarray, target_gap: np.ndarray,
             active: np.ndarray | None = None) -> SolveStats:
        """Move wrists and jaws toward the targets (limits enforced) and advance the FEM by one
        control period, in ``config.solver.substeps`` physics substeps. The jaw driver runs every
        substep on the pad forces of the previous one and a grip-stiffness estimate, and holds the
        grip force at the limit (``gripper.driver`` rules 3-4). Worlds with ``active == False``
        keep their wrist and jaw still."""
        cfg = self.config
        active = np.ones(self.num_worlds, bool) if active is None else active
        q_start = self.q.copy()
        q_move = clamp_joints(ik_analytic(target_pos, target_quat).q) - q_start
        q_move[:, 3:] = (q_move[:, 3:] + np.pi) % (2 * np.pi) - np.pi  # shortest way round
        # substeps adapted to the pad travel (sim.pad_motion), jaw included
        travel = corner_travel(*self.pad_poses(q_start), *self.pad_poses(q_start + q_move), PAD_BOX_HALF_EXTENTS)
        count = substeps_for_travel(travel + cfg.gripper.closing_speed * cfg.dt / 2, cfg.solver.substeps)
        h = cfg.dt / count
        reports = []
        for k in range(count):
            gap_before, force_before = self.gap, self.tip_force.mean(axis=1)
            gap = self.driver.step(target_gap, self.gap, h, self.tip_force[:, 0], self.tip_force[:, 1],
                                   self.grip_stiffness)
            q = np.where(active[:, None], clamp_joints(q_start + q_move * (k + 1) / count), self.q)
            # -- wrist force limit hook (wrist.force_limit): the substep is re-solved from its start
            # state with a fraction of the wrist motion while the pads' net force exceeds the limit
            q_prev, gap_prev = self.q, self.gap
            self._substep_start.copy_from(self.state)

            def solve(scale, q_prev=q_prev, q=q, gap=gap, gap_prev=gap_prev):
                self.state.copy_from(self._substep_start)
                # an inactive world keeps q, already above the ground: the lift leaves it as it is
                moved = np.where(scale[:, None] < 1.0, q_prev + (q - q_prev) * scale[:, None], q)
                self.q, pos, quat = self._lift_above_ground(moved, np.where(active, gap, gap_prev))
                self.control.pad_target_positions.assign(pos.reshape(-1, 3).astype(np.float32))
                self.control.pad_target_orientations.assign(quat.reshape(-1, 4).astype(np.float32))
                report = self.solver.step(self.state, self.state, self.control, h)
                return report, wrist_force(self.state.pad_force.numpy().reshape(-1, 2, 3))

            report, self.wrist_force, _ = limited_substep(solve, self.wrist_force, cfg.wrist_force_limit)
            reports.append(report)
            self.gap = np.where(active, gap, self.gap)
            self.tip_force = self.state.pad_normal_force.numpy().reshape(-1, 2).astype(np.float64)
            self.grip_stiffness = update_grip_stiffness(self.grip_stiffness, gap_before, self.gap, force_before,
                                                        self.tip_force.mean(axis=1), target_gap)
        stats = SolveStats.combine(reports)
        return stats

    # -- readouts --------------------------------------------------------------------------
    def node_positions(self, w: int) -> np.ndarray:
        return self.state.positions.numpy()[self.model.world_nodes(w)]

    def feature_points(self) -> tuple[np.ndarray, np.ndarray]:
        """Object feature point (mean node position, paper eq. 5) [W,3] m and its velocity [W,3] m/s."""
        x, v = self.state.positions.numpy(), self.state.velocities.numpy()
        starts = self.model.node_start
        counts = np.diff(starts)
        pos = np.add.reduceat(x.astype(np.float64), starts[:-1], axis=0) / counts[:, None]
        vel = np.add.reduceat(v.astype(np.float64), starts[:-1], axis=0) / counts[:, None]
        return pos, vel

    def keypoint_positions(self) -> np.ndarray:
        """[W, NUM_KEYPOINTS, 3] positions (m) of fixed surface nodes of each object."""
        x = self.state.positions.numpy()
        out = np.zeros((self.num_worlds, NUM_KEYPOINTS, 3))
        for w in range(self.num_worlds):
            idx = self.keypoints[w] + self.model.node_start[w]
            out[w, : len(idx)] = x[idx]
        return out

    def tcp_positions(self) -> np.ndarray:
        """Tool centre point (midpoint between the pad inner faces) [W,3], m."""
        centers, _ = self.pad_poses()
        return centers.mean(axis=1)

    def finite(self) -> np.ndarray:
        """[W] bool: the world's node positions and velocities are all finite."""
        x, v = self.state.positions.numpy(), self.state.velocities.numpy()
        bad = ~(np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1))
        return np.add.reduceat(bad.astype(int), self.model.node_start[:-1]) == 0
