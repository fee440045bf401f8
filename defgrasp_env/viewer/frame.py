"""What the 3D viewer draws at one instant: a ``ViewerFrame``, built from a live scene or from a
recorded episode file, so that live views and playback draw exactly the same things.

World frame: y up, metres, quaternions (x, y, z, w) (CONVENTIONS.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..gripper import PAD_BOX_HALF_EXTENTS, pad_box_poses


@dataclass(frozen=True)
class ViewerFrame:
    """One world at one instant (world frame, SI units).

    vertices: object node positions [N, 3] (m); the surface ``triangles`` index them.
    node_stress: von Mises stress per node [N] (Pa), the mean over the tets that share the node.
    pad_centers, pad_quats, pad_half_extents: the two pad collision boxes [2, 3] (m), [2, 4] (xyzw),
        [2, 3] (m); index 0 = left pad.
    flange_position [3] (m), flange_quat [4] (xyzw): the wrist frame.
    tip_forces: left and right tip normal forces [2] (N), drawn as arrows along the pads' inner normals.
    feature_point: mean node position [3] (m) (paper eq. 5); goal [3] (m).
    time_s: simulation time of the episode (s); readouts: extra values for the status panel.
    """

    vertices: np.ndarray
    node_stress: np.ndarray
    pad_centers: np.ndarray
    pad_quats: np.ndarray
    pad_half_extents: np.ndarray
    flange_position: np.ndarray
    flange_quat: np.ndarray
    tip_forces: np.ndarray
    feature_point: np.ndarray
    goal: np.ndarray
    time_s: float = 0.0


def node_stress(tets: np.ndarray, tet_stress: np.ndarray, num_nodes: int) -> np.ndarray:
    """Per-node value [num_nodes] = mean of ``tet_stress`` [T] over the tets [T, 4] that use the node
    (0 for a node in no tet). Units are those of ``tet_stress`` (Pa for von Mises)."""
    tets = np.asarray(tets)
    values = np.asarray(tet_stress, dtype=np.float64)
    if tets.ndim != 2 or tets.shape[1] != 4:
        raise ValueError(f"tets must have shape (T, 4), got {tets.shape}")
    if values.shape != (len(tets),):
        raise ValueError(f"tet_stress must have shape (T,) = ({len(tets)},), got {values.shape}")
    idx = tets.reshape(-1)
    total = np.bincount(idx, weights=np.repeat(values, 4), minlength=num_nodes)
    count = np.bincount(idx, minlength=num_nodes)
    return total / np.maximum(count, 1)


def pad_boxes_world(flange_position, flange_quat, gap) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pads' collision boxes (as the simulation uses them: pad + backing) for a flange pose and a
    jaw gap: centres [2, 3] (m), orientations [2, 4] (xyzw), half extents [2, 3] (m)."""
    pos = np.asarray(flange_position, dtype=np.float64)[None]
    quat = np.asarray(flange_quat, dtype=np.float64)[None]
    centers, quats = pad_box_poses(pos, quat, np.array([float(gap)]))
    return centers[0], quats[0], np.repeat(PAD_BOX_HALF_EXTENTS[None], 2, axis=0)


def frame_from_scene(scene, world: int = 0, goal=(0.0, 0.6, 0.0), time_s: float = 0.0) -> ViewerFrame:
    """The frame of world ``world`` of a ``PickupScene`` (its public readouts only)."""
    nodes = scene.node_positions(world).astype(np.float64)
    tet_slice = scene.model.world_tets(world)
    tet_stress = scene.state.von_mises.numpy()[tet_slice]
    centers, quats = scene.gripper.pad_poses()
    pos, quat = scene.gripper.flange_pose()
    return ViewerFrame(
        vertices=nodes,
        node_stress=node_stress(scene.mesh(world).tets, tet_stress, len(nodes)),
        pad_centers=centers[world], pad_quats=quats[world],
        pad_half_extents=np.repeat(PAD_BOX_HALF_EXTENTS[None], 2, axis=0),
        flange_position=pos[world], flange_quat=quat[world],
        tip_forces=np.asarray(scene.gripper.tip_force[world], dtype=np.float64),
        feature_point=nodes.mean(axis=0),
        goal=np.asarray(goal, dtype=np.float64),
        time_s=float(time_s),
    )


class EpisodeFrames:
    """The frames of a recorded episode file (``defgrasp_env.recording`` schema), one per step.

    ``triangles`` [M, 3] (surface), ``num_steps``, ``frame(t)`` for t in [0, num_steps), ``stress_max``
    (Pa, the largest per-node stress of the episode), ``attrs`` (the file's root attributes).
    """

    KEYS = ("object/triangles", "object/tetrahedra", "steps/time", "steps/node_positions", "steps/von_mises",
            "steps/wrist_position", "steps/wrist_orientation", "steps/jaw_length",
            "steps/left_tip_normal_force", "steps/right_tip_normal_force")

    def __init__(self, path):
        from ..recording.reader import load_episode

        ep = load_episode(path, self.KEYS + ("task/goal",), missing_ok=True)  # the goal: files since it
        self.path = ep.path
        self.attrs = ep.attrs
        self.triangles = np.asarray(ep["object/triangles"], dtype=np.int64)
        self._tets = np.asarray(ep["object/tetrahedra"], dtype=np.int64)
        self._d = ep.data
        self.num_steps = int(len(ep["steps/time"]))
        if self.num_steps == 0:
            raise ValueError(f"{self.path}: episode has no steps to view")
        if "task/goal" in ep.data:  # the episode's own goal (files of before it fall back to the config's)
            self.goal = np.asarray(ep["task/goal"], dtype=np.float64)
        else:
            config = ep.config if "config_json" in ep.attrs else None
            self.goal = np.asarray(config.goal if config is not None else (0.0, 0.6, 0.0), dtype=np.float64)
        n = ep["steps/node_positions"].shape[1]
        self._stress = np.stack([node_stress(self._tets, s, n) for s in ep["steps/von_mises"]])
        self.stress_max = float(self._stress.max())

    def frame(self, t: int) -> ViewerFrame:
        if not 0 <= t < self.num_steps:
            raise IndexError(f"step must be in [0, {self.num_steps - 1}], got {t}")
        d = self._d
        nodes = d["steps/node_positions"][t].astype(np.float64)
        centers, quats, half = pad_boxes_world(d["steps/wrist_position"][t], d["steps/wrist_orientation"][t],
                                               d["steps/jaw_length"][t])
        return ViewerFrame(
            vertices=nodes, node_stress=self._stress[t], pad_centers=centers, pad_quats=quats,
            pad_half_extents=half, flange_position=d["steps/wrist_position"][t],
            flange_quat=d["steps/wrist_orientation"][t],
            tip_forces=np.array([d["steps/left_tip_normal_force"][t], d["steps/right_tip_normal_force"][t]]),
            feature_point=nodes.mean(axis=0), goal=self.goal, time_s=float(d["steps/time"][t]))
