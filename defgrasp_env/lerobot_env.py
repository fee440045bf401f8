"""LeRobot ``EnvConfig`` for ``DeformablePickup-v0``, registered as ``--env.type=defgrasp``.

Importing this module registers the config with LeRobot's env registry (``EnvConfig`` is a draccus
``ChoiceRegistry``). LeRobot's scripts find it without flags once the tiny plugin distribution
``plugins/lerobot_env_defgrasp`` is installed (``register_third_party_plugins()`` imports every
installed distribution named ``lerobot_env_*``), or with
``--env.discover_packages_path=defgrasp_env`` without it (LeRobot then imports
``defgrasp_env`` and its direct submodules, this one among them)::

    lerobot-eval --env.type=defgrasp --env.object=torus --env.youngs_modulus=1e4 \\
        --policy.path=outputs/train/act_defgrasp/checkpoints/last/pretrained_model \\
        --eval.n_episodes=5 --eval.batch_size=1

LeRobot builds ``gym.make(cfg.gym_id, **cfg.gym_kwargs)`` inside a ``SyncVectorEnv`` and reads
success from ``info["is_success"]``; observations reach the policy as
``agent_pos`` -> ``observation.state`` [10], ``environment_state`` -> ``observation.environment_state``
[33] and ``pixels`` -> ``observation.images.camera`` [3, H, W] (the names ``defgrasp-dataset
to-lerobot`` writes, so a policy trained on an exported dataset runs here unchanged).
"""

from __future__ import annotations

import pathlib
from dataclasses import dataclass, field

import numpy as np
from lerobot.configs import FeatureType, PipelineFeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.processor import (ObservationProcessorStep, PolicyProcessorPipeline, ProcessorStepRegistry,
                               RenameObservationsProcessorStep)
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGE, OBS_STATE

from . import ENV_ID
from .envs.config import OBS_TYPES, RANDOM_OBJECT, PickupConfig
from .sim.meshing import OBJECT_SHAPES
from .layout import ACTION_LAYOUTS, AGENT_POS, ENV_STATE
from .recording.lerobot_export import CAMERA_KEY, state_columns

__all__ = ["DefgraspEnvConfig", "SelectStateColumnsStep"]


@EnvConfig.register_subclass("defgrasp")
@dataclass
class DefgraspEnvConfig(EnvConfig):
    """``DeformablePickup-v0`` for ``lerobot-eval`` / ``lerobot-train --env.type=defgrasp``.

    ``fps`` is the env's control rate (Hz; actions are held for 1/fps s). ``object``: one of the
    five shapes, ``"random"`` or a mesh path; ``youngs_modulus`` (Pa); ``obs_type``: ``"state"``
    (``agent_pos`` + ``environment_state``), ``"pixels_agent_pos"`` or ``"pixels"``;
    ``episode_seconds`` sets LeRobot's rollout length (``max_episode_steps``); ``edge_contact``:
    the pads' box edges held out of the object (``PickupConfig.edge_contact``, on by default;
    ``--env.edge_contact=false`` evaluates a policy in the node-only contact of data recorded before
    2026-11-26); ``render_mode`` "rgb_array" gives the evaluation videos. ``action_mode``: the
    env's actions, ``"delta"`` (``DELTA_ACTION`` [7] in [-1, 1], the default), ``"absolute"``
    (``ABSOLUTE_ACTION`` [8]: target flange pose and gap) or ``"topdown"`` (``TOPDOWN_ACTION`` [5]:
    velocities, target yaw, jaw), for a policy trained on demonstrations recorded with
    ``defgrasp-generate --action-mode`` of that name. ``state_fields``: the ``AGENT_POS`` fields
    the policy's ``observation.state`` holds (default all [10]), for a policy trained on a dataset
    exported with ``defgrasp-dataset to-lerobot --state-fields`` (e.g.
    ``--env.state_fields='[wrist_position,jaw_gap,tip_normal_force]'``: no wrist orientation [6]).
    Only the state's size is visible to a check against the policy: give the fields its dataset
    was exported with (``meta/info.json`` names them under ``observation.state``).
    """

    task: str | None = ENV_ID
    fps: int = int(PickupConfig.control_hz)
    object: str = PickupConfig.object
    youngs_modulus: float = 1e5
    obs_type: str = "state"
    episode_seconds: float = PickupConfig.episode_seconds
    edge_contact: bool = PickupConfig.edge_contact
    action_mode: str = PickupConfig.action_mode
    render_mode: str = "rgb_array"
    device: str = "cpu"
    state_fields: list[str] | None = None
    features: dict[str, PolicyFeature] = field(default_factory=dict)
    features_map: dict[str, str] = field(default_factory=lambda: {
        ACTION: ACTION, "agent_pos": OBS_STATE, "environment_state": OBS_ENV_STATE, "pixels": CAMERA_KEY})

    def __post_init__(self):
        if self.obs_type not in OBS_TYPES:
            raise ValueError(f"obs_type must be one of {list(OBS_TYPES)}, got {self.obs_type!r}")
        # validate every env option now (clear errors at parse time, not inside the vector env)
        if self.object not in (*OBJECT_SHAPES, RANDOM_OBJECT) and not pathlib.Path(self.object).is_file():
            raise ValueError(f"object must be one of {sorted(OBJECT_SHAPES)}, {RANDOM_OBJECT!r} or a mesh file, "
                             f"got {self.object!r}")
        env_config = PickupConfig(**self._pickup_kwargs())
        camera = env_config.camera
        self.features = {ACTION: PolicyFeature(type=FeatureType.ACTION,
                                               shape=(ACTION_LAYOUTS[env_config.action_mode].size,))}
        columns = self.state_columns  # the names checked at parse time
        if self.state_fields is not None and self.obs_type == "pixels":
            raise ValueError("state_fields selects agent_pos fields; obs_type='pixels' has no agent_pos "
                             f"(got state_fields={self.state_fields})")
        if self.obs_type in ("state", "pixels_agent_pos"):
            self.features["agent_pos"] = PolicyFeature(type=FeatureType.STATE, shape=(len(columns),))
        if self.obs_type == "state":
            self.features["environment_state"] = PolicyFeature(type=FeatureType.ENV,
                                                               shape=(ENV_STATE.size,))
        if self.obs_type in ("pixels", "pixels_agent_pos"):
            self.features["pixels"] = PolicyFeature(type=FeatureType.VISUAL,
                                                    shape=(camera.height, camera.width, 3))

    @property
    def state_columns(self) -> np.ndarray:
        """Indices (int [n]) of the ``agent_pos`` entries ``observation.state`` keeps (``state_fields``)."""
        return state_columns(self.state_fields)

    def _pickup_kwargs(self) -> dict:
        return dict(object=self.object, youngs_modulus=float(self.youngs_modulus), obs_type=self.obs_type,
                    control_hz=float(self.fps), episode_seconds=float(self.episode_seconds),
                    edge_contact=self.edge_contact, action_mode=self.action_mode, device=self.device)

    @property
    def package_name(self) -> str:
        """Module whose import registers ``gym_id`` (LeRobot imports it if the id is missing)."""
        return "defgrasp_env"

    @property
    def gym_id(self) -> str:
        return self.task

    @property
    def gym_kwargs(self) -> dict:
        return {**self._pickup_kwargs(), "render_mode": self.render_mode,
                "max_episode_steps": round(self.episode_seconds * self.fps)}

    def get_env_processors(self):
        """LeRobot turns a single ``pixels`` array into ``observation.image``; rename it to the
        dataset's camera key. ``observation.state`` keeps the ``state_fields`` columns (all by
        default); the environment state passes through unchanged."""
        steps = [RenameObservationsProcessorStep(rename_map={OBS_IMAGE: CAMERA_KEY})]
        if len(self.state_columns) < AGENT_POS.size:
            steps.append(SelectStateColumnsStep(columns=self.state_columns.tolist()))
        return PolicyProcessorPipeline(steps=steps), PolicyProcessorPipeline(steps=[])


@ProcessorStepRegistry.register(name="defgrasp_select_state_columns")
@dataclass
class SelectStateColumnsStep(ObservationProcessorStep):
    """Keeps the entries ``columns`` (ints, in order) of ``observation.state`` [..., 10] along its
    last axis, as ``defgrasp-dataset to-lerobot --state-fields`` keeps them in a dataset."""

    columns: list[int] = field(default_factory=list)

    def __post_init__(self):
        cols = list(self.columns)
        if not cols or len(set(cols)) != len(cols) or not all(0 <= c < AGENT_POS.size for c in cols):
            raise ValueError(f"columns must be distinct indices in [0, {AGENT_POS.size}) of agent_pos, got {cols}")

    def observation(self, observation):
        if OBS_STATE in observation:
            state = observation[OBS_STATE]
            if state.shape[-1] != AGENT_POS.size:
                raise ValueError(f"{OBS_STATE} must have {AGENT_POS.size} entries (agent_pos) before the column "
                                 f"selection, got shape {tuple(state.shape)}")
            observation = {**observation, OBS_STATE: state[..., self.columns]}
        return observation

    def get_config(self) -> dict:
        return {"columns": list(self.columns)}

    def transform_features(self, features):
        obs = dict(features[PipelineFeatureType.OBSERVATION])
        if OBS_STATE in obs:
            obs[OBS_STATE] = PolicyFeature(type=obs[OBS_STATE].type, shape=(len(self.columns),))
        return {**features, PipelineFeatureType.OBSERVATION: obs}
