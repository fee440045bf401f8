"""Per-step readouts of the pickup scene, reduced on the simulation's device: the full FEM state
(all nodes of all worlds) is read by Warp kernels (``scene_kernels``) into small per-world arrays,
and only those [W, ...] arrays reach the host, once per step, shared by observations, reward,
success and the divergence check."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from ..layout import NUM_KEYPOINTS
from ..sim.model import Model
from ..sim.state import State
from .scene_kernels import deepest_material_in_pads, gather_keypoints, pack_readouts, world_readouts


@dataclass(frozen=True)
class StepReadout:
    """What the env reads of a state, per world (host numpy; world frame, SI units).

    Attributes:
        feature_position: [W, 3] float64 m, the object's feature point (mean node position, eq. 5).
        feature_velocity: [W, 3] float64 m/s, its velocity (mean node velocity).
        keypoints: [W, NUM_KEYPOINTS, 3] float64 m, fixed surface nodes (zeros past an object's count).
        finite: [W] bool, every node position and velocity of the world is finite.
        pad_embedding: [W] float64 m, how deep the object's material lies inside a pad: the
            deepest tet centroid inside a pad box (``scene_kernels.deepest_material_in_pads``),
            0 where none is.
    """

    feature_position: np.ndarray
    feature_velocity: np.ndarray
    keypoints: np.ndarray
    finite: np.ndarray
    pad_embedding: np.ndarray


class SceneReadouts:
    """Device buffers and recorded launches of the readouts of one model's states.

    Public device arrays (valid after ``launch`` or ``compute``, overwritten by the next): ``feature_position``,
    ``feature_velocity`` ([W] vec3d), ``keypoints`` ([W*NUM_KEYPOINTS] vec3), ``finite`` ([W] int32),
    ``pad_embedding`` ([W] float32, m).

    Args:
        model: the simulation's model (its ``node_start`` offsets, tets, pads and device).
        states: the states the readouts may read (the scene's two alternating states; their arrays
            are bound to the launches recorded for each).
        keypoints: per world, the object-local node ids of its keypoints (<= NUM_KEYPOINTS each).
    """

    def __init__(self, model: Model, states: list[State], keypoints: list[np.ndarray]):
        d, w = model.device, model.num_worlds
        self.num_worlds = w
        self._device = d
        self._node_start = wp.array(model.node_start.astype(np.int32), dtype=wp.int32, device=d)
        self._node_end = wp.zeros(w, dtype=wp.int32, device=d)
        self._keypoint_index = wp.zeros(w * NUM_KEYPOINTS, dtype=wp.int32, device=d)
        self.set_objects(model, keypoints)
        self.feature_position = wp.zeros(w, dtype=wp.vec3d, device=d)
        self.feature_velocity = wp.zeros(w, dtype=wp.vec3d, device=d)
        self.keypoints = wp.zeros(w * NUM_KEYPOINTS, dtype=wp.vec3, device=d)
        self.finite = wp.zeros(w, dtype=wp.int32, device=d)
        self.pad_embedding = wp.zeros(w, dtype=wp.float32, device=d)
        self._packed = wp.zeros((w, 8 + 3 * NUM_KEYPOINTS), dtype=wp.float64, device=d)  # one download
        pack = wp.launch(pack_readouts, dim=w, inputs=[self.feature_position, self.feature_velocity, self.keypoints,
                                                        self.finite, self.pad_embedding, NUM_KEYPOINTS],
                         outputs=[self._packed], device=d, record_cmd=True)
        pads = model.pads_per_world
        embedding = [wp.launch(deepest_material_in_pads, dim=model.num_tets * pads,
                               inputs=[state.positions, model.tets, model.tet_world, state.pad_positions,
                                       state.pad_orientations, model.pad_half_extents, pads],
                               outputs=[self.pad_embedding], device=d, record_cmd=True) for state in states]
        # recorded once (a couple of microseconds of Python per launch, as the solver's launches)
        self._launches = [(state, (
            wp.launch(world_readouts, dim=w, inputs=[state.positions, state.velocities, self._node_start,
                                                     self._node_end],
                      outputs=[self.feature_position, self.feature_velocity, self.finite], device=d,
                      record_cmd=True),
            wp.launch(gather_keypoints, dim=w * NUM_KEYPOINTS, inputs=[state.positions, self._keypoint_index],
                      outputs=[self.keypoints], device=d, record_cmd=True), embed, pack))
            for state, embed in zip(states, embedding)]

    def set_objects(self, model: Model, keypoints: list[np.ndarray]) -> None:
        """The worlds' objects (their node rows ``Model.node_start`` .. ``node_end`` and ``keypoints``:
        per world, object-local node ids), again after a slotted model's objects changed in place."""
        index = np.full((self.num_worlds, NUM_KEYPOINTS), -1, np.int32)
        for i, local in enumerate(keypoints):
            index[i, : len(local)] = np.asarray(local) + model.node_start[i]
        self._keypoint_index.assign(index.ravel())
        self._node_end.assign(model.node_end.astype(np.int32))

    def launch(self, state: State) -> None:
        """Launch the readout kernels on ``state`` (one of the constructor's ``states``): the public
        device arrays then hold its readouts (no transfer)."""
        launches = next((cmds for s, cmds in self._launches if s is state), None)
        if launches is None:
            raise ValueError("state must be one of the states the readouts were built for")
        self.pad_embedding.zero_()  # the embedding launch takes maxima into it
        for cmd in launches[:-1]:
            cmd.launch()

    def compute(self, state: State) -> StepReadout:
        """:meth:`launch` on ``state``, then bring the [W, ...] results to the host, packed in one
        download."""
        w = self.num_worlds
        self.launch(state)
        next(cmds for s, cmds in self._launches if s is state)[-1].launch()  # the pack
        packed = self._packed.numpy()
        return StepReadout(packed[:, 0:3].copy(), packed[:, 3:6].copy(),
                           packed[:, 6:6 + 3 * NUM_KEYPOINTS].reshape(w, NUM_KEYPOINTS, 3).copy(),
                           packed[:, 6 + 3 * NUM_KEYPOINTS] != 0, packed[:, 7 + 3 * NUM_KEYPOINTS].copy())
