"""Helpers shared by the single and the vector env: episode draws and their replay specs,
observations, info, camera."""

from __future__ import annotations

import numpy as np

from ..gripper import Gripper
from ..sim.materials import Material
from .config import PickupConfig
from .replay_spec import ReplaySpec
from .scene import PickupScene, WorldSetup
from .task import REWARD_TERMS, PickupTask


def draw_setup(config: PickupConfig, rng: np.random.Generator, object_name: str | None = None) -> WorldSetup:
    """Random episode start of one world: object (if not given), E, position and yaw noise, then
    Poisson ratio and density where the config gives tuples of them, then the goal where the
    config's ``goal_noise`` is not zero (drawn last, so that the other draws stay as they were)."""
    drawn = config.object_names[rng.integers(len(config.object_names))]  # always drawn: same stream either way
    name = object_name if object_name is not None else drawn
    e = config.moduli[rng.integers(len(config.moduli))]
    xz = rng.uniform(-config.init_position_noise, config.init_position_noise, size=2)
    yaw = rng.uniform(-config.init_yaw_noise, config.init_yaw_noise)
    quat = np.array([0.0, np.sin(yaw / 2), 0.0, np.cos(yaw / 2)])
    # drawn after the pose and only for a tuple, so that the draws of single values stay as they were
    nu = config.poisson_ratio[rng.integers(len(config.poisson_ratio))] \
        if isinstance(config.poisson_ratio, tuple) else config.poisson_ratio
    rho = config.density[rng.integers(len(config.density))] if isinstance(config.density, tuple) else config.density
    goal = np.asarray(config.goal, dtype=np.float64)
    noise = np.asarray(config.goal_noise, dtype=np.float64)
    if noise.any():
        goal = goal + rng.uniform(-noise, noise)
    return WorldSetup(name, Material(float(rho), float(e), float(nu)),
                      np.array([xz[0], 0.0, xz[1]]), quat, goal)


def draw_world(config: PickupConfig, rng: np.random.Generator, seed: int | None, object_name: str | None = None,
               options: dict | None = None) -> tuple[WorldSetup, ReplaySpec]:
    """One world's episode start drawn from ``rng`` (just seeded with ``seed``, or continuing when
    ``seed`` is None), and the spec that repeats it in a single env (no ``scene_origin`` yet):
    ``options`` are the single-env reset options giving the same draws."""
    rng_state = None if seed is not None else rng.bit_generator.state
    setup = draw_setup(config, rng, object_name)
    spec = ReplaySpec(None if seed is None else int(seed), rng_state, None if options is None else dict(options),
                      setup.object_name, setup.material, tuple(float(v) for v in setup.position),
                      tuple(float(v) for v in setup.quat), tuple(float(v) for v in setup.goal))
    return setup, spec


def observations(task: PickupTask, pixels=None) -> dict[str, np.ndarray]:
    """Batched observation dict [W, ...] of the task's last ``observe`` / ``evaluate``."""
    obs = task.observations()
    if pixels is not None:
        obs["pixels"] = pixels
    return obs


def step_infos(result: dict[str, np.ndarray], stats) -> dict[str, np.ndarray]:
    """Batched info arrays [W]: reward terms (``reward_<term>``), success, contact and solver data,
    from the task's step result (``PickupTask.result``) and the solver's report ``stats``."""
    info = {f"reward_{name}": result[f"reward_{name}"] for name in REWARD_TERMS}
    info.update({name: result[name] for name in (
        "is_success", "grasped", "grasp_quality", "pierced", "goal_distance", "left_tip_normal_force",
        "right_tip_normal_force", "jaw_gap", "mean_von_mises", "sim_diverged")})
    info.update(
        newton_iterations=stats.newton_iterations.copy(),
        cg_iterations=stats.cg_iterations.copy(),
        residual_force=stats.residual_force.astype(np.float64),
        penetration=stats.penetration.astype(np.float64),
        pad_embedding=result["pad_embedding"],
        wrist_force=result["wrist_force"],
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

    def render(self, scene: PickupScene, w: int, goal) -> np.ndarray:
        """HxWx3 uint8 image of world ``w`` with its goal ``goal`` [3] (m, world)."""
        from ..render.renderer import SceneRenderer

        name = scene.object_names[w]
        if w not in self._renderers or self._renderers[w][0] != name:
            mesh = scene.mesh(w)
            self._renderers[w] = (name, SceneRenderer(self.config.camera, mesh.surface, len(mesh.nodes), 2,
                                                      device=self.config.device))
        centers, quats = scene.gripper.pad_poses()
        half = np.repeat(Gripper.pad_half_extents[None], 2, axis=0)
        return self._renderers[w][1].render(scene.node_positions(w), centers[w], quats[w], half,
                                            goal=np.asarray(goal, np.float32))
