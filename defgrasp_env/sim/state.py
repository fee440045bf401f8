"""State (time-varying arrays) and Control (inputs) of the batched FEM simulation."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from .model import Model


@dataclass
class State:
    """Per-step arrays. N nodes, T tets, W worlds, P pads per world; world frame, SI units.

    The force and stress arrays are evaluated at ``positions`` at the end of the step that wrote
    this state.
    """

    positions: wp.array         # [N] vec3, m
    velocities: wp.array        # [N] vec3, m/s
    pad_positions: wp.array     # [W*P] vec3, m: pad box centres
    pad_orientations: wp.array  # [W*P] quat (x, y, z, w): pad box orientations
    elastic_force: wp.array     # [N] vec3, N: internal elastic force on each node
    contact_force: wp.array     # [N] vec3, N: ground + pad contact force on each node (normal + friction)
    von_mises: wp.array         # [T] float, Pa: Cauchy von Mises stress of each tet
    mean_von_mises: wp.array    # [W] float, Pa: rest-volume-weighted mean of von_mises per world
    pad_normal_force: wp.array  # [W*P] float, N: normal force the object exerts on each pad
    pad_force: wp.array         # [W*P] vec3, N: total force (normal + friction) the object exerts on each pad

    @classmethod
    def from_model(cls, model: Model) -> "State":
        d, n, t = model.device, model.num_nodes, model.num_tets
        wp_count = model.num_worlds * model.pads_per_world
        quats = np.tile(np.array([0, 0, 0, 1], np.float32), (wp_count, 1))
        return cls(
            positions=wp.clone(model.rest_positions),
            velocities=wp.zeros(n, dtype=wp.vec3, device=d),
            pad_positions=wp.zeros(wp_count, dtype=wp.vec3, device=d),
            pad_orientations=wp.array(quats, dtype=wp.quat, device=d),
            elastic_force=wp.zeros(n, dtype=wp.vec3, device=d),
            contact_force=wp.zeros(n, dtype=wp.vec3, device=d),
            von_mises=wp.zeros(t, dtype=wp.float32, device=d),
            mean_von_mises=wp.zeros(model.num_worlds, dtype=wp.float32, device=d),
            pad_normal_force=wp.zeros(wp_count, dtype=wp.float32, device=d),
            pad_force=wp.zeros(wp_count, dtype=wp.vec3, device=d),
        )

    def copy_from(self, other: "State") -> None:
        for name in self.__dataclass_fields__:
            wp.copy(getattr(self, name), getattr(other, name))


@dataclass
class Control:
    """Inputs for one step. Poses are targets reached at the END of the step (linearly
    interpolated over substeps from the state's current pad poses).
    """

    pad_target_positions: wp.array     # [W*P] vec3, m
    pad_target_orientations: wp.array  # [W*P] quat (x, y, z, w)
    external_force: wp.array           # [N] vec3, N: extra force on each node (besides gravity)
    prescribed_positions: wp.array     # [N] vec3, m: end-of-step targets of the fixed axes (Model.free_axes == 0)

    @classmethod
    def from_model(cls, model: Model) -> "Control":
        d, n = model.device, model.num_nodes
        wp_count = model.num_worlds * model.pads_per_world
        quats = np.tile(np.array([0, 0, 0, 1], np.float32), (wp_count, 1))
        return cls(
            pad_target_positions=wp.zeros(wp_count, dtype=wp.vec3, device=d),
            pad_target_orientations=wp.array(quats, dtype=wp.quat, device=d),
            external_force=wp.zeros(n, dtype=wp.vec3, device=d),
            prescribed_positions=wp.clone(model.rest_positions),
        )
