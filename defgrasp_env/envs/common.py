"""Helpers shared by the single and the vector env: episode draws, action checks, observations, info."""

from __future__ import annotations

import numpy as np

from ..sim.materials import Material
from ..transforms import quat_normalize
from .config import PickupConfig
from .scene import PAD_BOX_HALF_EXTENTS, PickupScene, WorldSetup
from .task import REWARD_TERMS, PickupTask


def draw_setup(config: PickupConfig, rng: np.random.Generator, object_name: str | None = None) -> WorldSetup:
    """Random episode start of one world: object (if not given), E, position and yaw noise."""
    drawn = config.object_names[rng.integers(len(config.object_names))]  # always drawn: same stream either way
    name = object_name if object_name is not None else drawn
    e = config.moduli[rng.integers(len(config.moduli))]
    xz = rng.uniform(-config.init_position_noise, config.init_position_noise, size=2)
    yaw = rng.uniform(-config.init_yaw_noise, config.init_yaw_noise)
    quat = np.array([0.0, np.sin(yaw / 2), 0.0, np.cos(yaw / 2)])
    return WorldSetup(name, Material(config.density, float(e), config.poisson_ratio),
                      np.array([xz[0], 0.0, xz[1]]), quat)


def check_actions(actions, expected_shape: tuple[int, ...], space_low, space_high) -> np.ndarray:
    """Validate (shape, finiteness) and clip to the action space; returns float64 [W, A]."""
    a = np.asarray(actions, dtype=np.float64)
    if a.shape != expected_shape:
        raise ValueError(f"action must have shape {expected_shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"action must be finite, got {a.reshape(-1)[~np.isfinite(a.reshape(-1))][:3]} "
                         f"in {a.tolist()}")
    return np.clip(a, space_low, space_high)


def targets(scene: PickupScene, actions: np.ndarray, mode: str):
    """Flange position/orientation and jaw-gap targets [W,...] for batched actions [W, A]."""
    if mode == "delta":
        return scene.wrist_targets_from_delta(actions)
    quat = actions[:, 3:7]
    norm = np.linalg.norm(quat, axis=1)
    if np.any(norm < 1e-6):
        raise ValueError(f"absolute action quaternion must be non-zero, got {quat[norm < 1e-6][0].tolist()}")
    pos, q = scene.rate_limited(actions[:, :3], quat_normalize(quat))
    return pos, q, actions[:, 7]


def observations(config: PickupConfig, scene: PickupScene, task: PickupTask, pixels=None) -> dict[str, np.ndarray]:
    """Batched observation dict [W, ...]."""
    obs = {}
    if config.obs_type in ("state", "pixels_agent_pos"):
        obs["agent_pos"] = task.agent_pos(scene)
    if config.obs_type == "state":
        obs["environment_state"] = task.environment_state(scene)
    if pixels is not None:
        obs["pixels"] = pixels
    return obs


def step_infos(scene: PickupScene, result: dict, stats, diverged: np.ndarray) -> dict[str, np.ndarray]:
    """Batched info arrays [W]: reward terms (``reward_<term>``), success, contact and solver data."""
    info = {f"reward_{name}": result["terms"][name].astype(np.float64) for name in REWARD_TERMS}
    info.update(
        is_success=result["is_success"].copy(),
        grasped=result["grasped"].copy(),
        pierced=result["pierced"].copy(),
        goal_distance=result["goal_distance"].copy(),
        left_tip_normal_force=scene.tip_force[:, 0].copy(),
        right_tip_normal_force=scene.tip_force[:, 1].copy(),
        jaw_gap=scene.gap.copy(),
        mean_von_mises=scene.state.mean_von_mises.numpy().astype(np.float64),
        sim_diverged=diverged.copy(),
        newton_iterations=stats.newton_iterations.copy(),
        cg_iterations=stats.cg_iterations.copy(),
        residual_force=stats.residual_force.astype(np.float64),
        penetration=stats.penetration.astype(np.float64),
        wrist_force=scene.wrist_force.copy(),
        sim_converged=stats.converged.copy(),
        sim_penetrated=stats.penetrated.copy(),
    )
    return info


class SceneCamera:
    """Renders worlds of a ``PickupScene`` with the configured camera; one renderer (its object's
    surface and ray-cast structure) per world, rebuilt when the world's object changes."""

    def __init__(self, config: PickupConfig):
        self.config = config
        self._renderers: dict[int, tuple[str, object]] = {}

    def render(self, scene: PickupScene, w: int) -> np.ndarray:
        """HxWx3 uint8 image of world ``w``."""
        from ..render.renderer import SceneRenderer

        name = scene.object_names[w]
        if w not in self._renderers or self._renderers[w][0] != name:
            mesh = scene.meshes[w]
            self._renderers[w] = (name, SceneRenderer(self.config.camera, mesh.surface, len(mesh.nodes), 2,
                                                      device=self.config.device))
        centers, quats = scene.pad_poses()
        half = np.repeat(PAD_BOX_HALF_EXTENTS[None], 2, axis=0)
        return self._renderers[w][1].render(scene.node_positions(w), centers[w], quats[w], half,
                                            goal=np.asarray(self.config.goal, np.float32))
