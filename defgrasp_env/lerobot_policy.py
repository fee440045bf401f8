"""``LeRobotPolicy``: a trained LeRobot policy (ACT, diffusion, ...) with the scripted expert's interface.

    policy = LeRobotPolicy.from_pretrained("outputs/train/act/checkpoints/last/pretrained_model")
    obs, _ = env.reset(seed=0); policy.reset()
    action = policy(obs)            # float32 [7] (or [N, 7] for a batch of observations)

Observations go through the same path as in ``lerobot-eval``: LeRobot's ``preprocess_observation``
(``agent_pos`` -> ``observation.state``, ``environment_state`` -> ``observation.environment_state``,
``pixels`` -> ``observation.image``), the ``defgrasp`` env config's processor (camera key), then the
policy's own saved pre-processor (normalisation, device) and post-processor (un-normalisation).
"""

from __future__ import annotations

import pathlib

import numpy as np
import torch

from .layout import ACTION_LAYOUTS, AGENT_POS

__all__ = ["LeRobotPolicy", "training_state_fields"]


def training_state_fields(path: str | pathlib.Path) -> list[str] | None:
    """The ``AGENT_POS`` fields of ``observation.state`` in the dataset a ``pretrained_model``
    folder was trained on (``train_config.json``'s dataset root, else the LeRobot cache of its
    repo id; relative roots from the working directory, as ``lerobot-train`` read them), from the
    dataset's ``meta/info.json`` column names; None when the folder or the dataset does not say.
    ValueError if the columns are not whole ``AGENT_POS`` fields in the layout's order."""
    import json

    from lerobot.utils.constants import HF_LEROBOT_HOME

    config = pathlib.Path(path) / "train_config.json"
    if not config.is_file():
        return None
    dataset = json.loads(config.read_text()).get("dataset") or {}
    root = dataset.get("root") or (HF_LEROBOT_HOME / dataset["repo_id"] if dataset.get("repo_id") else None)
    info = pathlib.Path(root) / "meta" / "info.json" if root else None
    if info is None or not info.is_file():
        return None
    names = (json.loads(info.read_text()).get("features", {}).get("observation.state") or {}).get("names")
    if not names:
        return None
    fields = [f.name for f in AGENT_POS.fields if set(f.components) <= set(names)]
    if [c for name in fields for c in AGENT_POS.field(name).components] != list(names):
        raise ValueError(f"{info}: observation.state columns {names} are not whole agent_pos fields "
                         f"{[f.name for f in AGENT_POS.fields]} in order")
    return fields


class LeRobotPolicy:
    """A pretrained LeRobot policy as ``policy(obs) -> action`` for ``DeformablePickup-v0``.

    ``obs``: the env's observation dict, one observation (``agent_pos`` [10], ...) or a batch ([N, 10],
    ... as from ``gym.make_vec``). Returns float32 actions in the layout the policy was trained on
    (``action_layout``, by its action size): delta actions [7] or [N, 7] in [-1, 1], absolute
    actions [8] or [N, 8] (an env with ``action_mode="absolute"``) or top-down actions [5] or [N, 5]
    (``action_mode="topdown"``), clipped to the layout's bounds.
    ``reset()`` clears the policy's action queue at every episode start; ``reset(mask)`` for a vector
    env is accepted when the policy keeps no state between steps (``n_action_steps == 1`` without
    temporal ensembling) or all worlds restart together, otherwise it raises ``ValueError`` (LeRobot
    policies keep one action queue for the whole batch).
    """

    def __init__(self, policy, preprocessor, postprocessor, env_preprocessor=None):
        self.policy = policy.eval()
        self.preprocessor = preprocessor
        self.postprocessor = postprocessor
        self.env_preprocessor = env_preprocessor
        self.num_worlds = 0
        size = policy.config.output_features["action"].shape[0]
        layouts = {layout.size: layout for layout in ACTION_LAYOUTS.values()}
        if size not in layouts:
            raise ValueError(f"the policy's actions have {size} entries; the env takes "
                             f"{sorted(layouts)} (top-down, delta or absolute actions)")
        #: the action layout the policy outputs (``DELTA_ACTION``, ``ABSOLUTE_ACTION`` or ``TOPDOWN_ACTION``)
        self.action_layout = layouts[size]
        self._low, self._high = (b.astype(np.float32) for b in self.action_layout.bounds())  # the env's Box

    @classmethod
    def from_pretrained(cls, path: str | pathlib.Path, device: str = "cpu", state_fields=None) -> LeRobotPolicy:
        """Load a ``pretrained_model`` folder written by ``lerobot-train`` (config, weights and the
        saved pre/post-processors) onto ``device``. ``state_fields``: the ``AGENT_POS`` fields the
        policy's ``observation.state`` was trained on (``defgrasp-dataset to-lerobot
        --state-fields``); default: those its training dataset names (:func:`training_state_fields`)
        when it can be found, else all. Checked against the policy's state size, and against the
        training dataset's fields when both are known."""
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors
        from lerobot.utils.constants import OBS_STATE

        from .lerobot_env import DefgraspEnvConfig

        path = pathlib.Path(path)
        if not (path / "config.json").is_file():
            raise FileNotFoundError(f"{path} is not a LeRobot pretrained_model folder (no config.json)")
        config = PreTrainedConfig.from_pretrained(path)
        config.device = device
        policy = get_policy_class(config.type).from_pretrained(path, config=config)
        pre, post = make_pre_post_processors(config, pretrained_path=str(path),
                                             preprocessor_overrides={"device_processor": {"device": device}})
        trained_on = training_state_fields(path)
        if state_fields is not None and trained_on is not None and AGENT_POS.columns(state_fields).tolist() != \
                AGENT_POS.columns(trained_on).tolist():
            raise ValueError(f"{path}: state_fields {list(state_fields)} differ from the fields its training dataset's "
                             f"observation.state holds, {trained_on}")
        state_fields = trained_on if state_fields is None else state_fields
        env_config = DefgraspEnvConfig(state_fields=None if state_fields is None else list(state_fields))
        state = config.input_features.get(OBS_STATE)
        if state is not None and tuple(state.shape) != (len(env_config.state_columns),):
            raise ValueError(f"{path}: the policy's {OBS_STATE} has shape {tuple(state.shape)}, the state_fields "
                             f"{env_config.state_fields or 'all'} give ({len(env_config.state_columns)},); pass the "
                             "fields its dataset was exported with (to-lerobot --state-fields)")
        env_pre, _ = env_config.get_env_processors()
        return cls(policy, pre, post, env_pre)

    def reset(self, mask=None) -> None:
        """Start new episodes: all worlds, or the worlds where ``mask`` [N] is True."""
        if mask is not None:
            m = np.asarray(mask, bool).reshape(-1)
            if self.num_worlds and m.shape != (self.num_worlds,):
                raise ValueError(f"mask must have shape ({self.num_worlds},), got {m.shape}")
            cfg = self.policy.config
            stateless = getattr(cfg, "n_action_steps", 1) == 1 and getattr(cfg, "temporal_ensemble_coeff", None) is None
            if not m.any() or (not m.all() and stateless):
                return
            if not m.all():
                raise ValueError("this policy queues actions for the whole batch: reset all worlds together "
                                 "or use n_action_steps=1 without temporal ensembling")
        self.policy.reset()

    def __call__(self, obs) -> np.ndarray:
        from lerobot.envs.utils import preprocess_observation

        if not isinstance(obs, dict) or not obs:
            raise TypeError(f"obs must be the env's observation dict, got {type(obs).__name__}")
        arrays = {k: np.asarray(v) for k, v in obs.items()}
        ref, batch_ndim = next(((arrays[k], n) for k, n in (("agent_pos", 2), ("environment_state", 2), ("pixels", 4))
                                if k in arrays), (None, 0))
        if ref is None:
            raise ValueError(f"obs has none of agent_pos, environment_state, pixels: {sorted(arrays)}")
        single = ref.ndim == batch_ndim - 1
        batch = {k: (v[None] if single else v) for k, v in arrays.items()}
        for k, v in batch.items():
            if v.dtype != np.uint8 and not np.all(np.isfinite(v)):
                raise ValueError(f"observation {k!r} must be finite")
        self.num_worlds = len(next(iter(batch.values())))
        x = preprocess_observation(batch)
        x["task"] = [""] * self.num_worlds
        if self.env_preprocessor is not None:
            x = self.env_preprocessor(x)
        x = self.preprocessor(x)
        with torch.inference_mode():
            action = self.policy.select_action(x)
        action = self.postprocessor(action).to("cpu").numpy()
        action = np.clip(action, self._low, self._high).astype(np.float32)
        return action[0] if single else action


def save_untrained_act(path: str | pathlib.Path, *, seed: int = 0, dim_model: int = 32, chunk_size: int = 4,
                       stats: dict | None = None, action_mode: str = "delta", state_fields=None) -> pathlib.Path:
    """Write a randomly initialised, tiny ACT ``pretrained_model`` folder for the ``defgrasp`` env's
    state features (``observation.state`` [10], ``observation.environment_state`` [33], ``action``
    [7]), loadable by ``lerobot-eval --policy.path`` and ``LeRobotPolicy.from_pretrained``: for tests
    and smoke runs of the evaluation plumbing (it does not solve the task). ``stats``: per-feature
    ``{"mean": [...], "std": [...]}`` for the normaliser (default: mean 0, std 1). ``action_mode``:
    ``"absolute"`` gives an ``action`` [8] (the env's absolute actions), ``"topdown"`` one of [5],
    instead; ``state_fields`` an ``observation.state`` of those ``AGENT_POS`` fields only."""
    from lerobot.envs.utils import env_to_policy_features
    from lerobot.configs import FeatureType
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy
    from lerobot.policies.factory import make_pre_post_processors

    from .lerobot_env import DefgraspEnvConfig

    features = env_to_policy_features(DefgraspEnvConfig(action_mode=action_mode, state_fields=state_fields))
    config = ACTConfig(
        device="cpu", dim_model=dim_model, n_heads=2, dim_feedforward=2 * dim_model, n_encoder_layers=1,
        n_decoder_layers=1, n_vae_encoder_layers=1, chunk_size=chunk_size, n_action_steps=1,
        input_features={k: f for k, f in features.items() if f.type is not FeatureType.ACTION},
        output_features={k: f for k, f in features.items() if f.type is FeatureType.ACTION})
    torch.manual_seed(seed)
    policy = ACTPolicy(config)
    stats = stats or {k: {"mean": [0.0] * f.shape[0], "std": [1.0] * f.shape[0]} for k, f in features.items()}
    tensors = {k: {m: torch.as_tensor(v, dtype=torch.float32) for m, v in s.items()} for k, s in stats.items()}
    pre, post = make_pre_post_processors(config, dataset_stats=tensors)
    path = pathlib.Path(path)
    policy.save_pretrained(path)
    pre.save_pretrained(path)
    post.save_pretrained(path)
    return path
