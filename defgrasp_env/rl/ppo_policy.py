"""``PPOPolicy``: a saved PPO run (``benchmarks/train_ppo.py``'s folder) with the scripted expert's interface.

    policy = PPOPolicy.from_run("datasets/output/ppo")
    obs, _ = env.reset(seed=0); policy.reset()
    action = policy(obs)            # float32 DELTA_ACTION [7] (or [N, 7] for a batch of observations)

The run folder holds the Stable-Baselines3 model (``ppo.zip``), the observation normalisation it
was trained with (``vecnormalize.pkl``, SB3's ``VecNormalize`` pickled without its env) and its
settings (``run.json``: the action set among ``rl.action_subset.ACTION_SETS``, the env options).
A call does what the training's wrappers did to an observation and an action: the observation
is normalised with the saved running statistics (frozen), the policy's mean action is taken
(``deterministic=True``, one world per forward pass as ``eval_ppo.py`` does, so an episode does not
depend on the batch size) and its components are placed into the env's ``DELTA_ACTION``, the
others zero (``ActionSubset``). Observations are the env's raw ones (``agent_pos`` [10],
``environment_state`` [33]), from ``gym.make`` or a vector env.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np

from ..envs.config import PickupConfig
from ..layout import AGENT_POS, DELTA_ACTION, ENV_STATE
from ..recording.config_io import RECORDED_BEFORE_DEFAULT
from .action_subset import ACTION_SETS, action_columns

__all__ = ["PPOPolicy", "RUN_ENV_OPTIONS", "run_env_options"]

#: The env options a run's ``run.json`` records (``train_ppo.py``'s env arguments).
RUN_ENV_OPTIONS = ("object", "youngs_modulus", "episode_seconds", "edge_contact")


def run_env_options(settings: dict, **overrides) -> dict:
    """The env options (``RUN_ENV_OPTIONS``) of a run's ``run.json`` ``settings`` as the run was
    trained with: an option left at its default is absent there (the default), and a run.json
    without ``edge_contact`` is a run trained before pad edge contact became the default (off), as
    recorded files are read (``recording.config_io``). ``overrides`` (None: the run's) replace
    them; the result is validated by ``PickupConfig``."""
    unknown = sorted(set(overrides) - set(RUN_ENV_OPTIONS))
    if unknown:
        raise ValueError(f"env overrides must be among {RUN_ENV_OPTIONS}, got {unknown}")
    given = RECORDED_BEFORE_DEFAULT | {k: settings[k] for k in RUN_ENV_OPTIONS if k in settings}
    config = PickupConfig(**(given | {k: v for k, v in overrides.items() if v is not None}))
    return {k: getattr(config, k) for k in RUN_ENV_OPTIONS}

#: The observation keys and sizes a run's policy reads.
_OBS_SIZES = {"agent_pos": AGENT_POS.size, "environment_state": ENV_STATE.size}


class PPOPolicy:
    """A trained SB3 PPO policy as ``policy(obs) -> action`` for ``DeformablePickup-v0`` (delta
    actions, state observations).

    ``settings``: the run's ``run.json`` (action set, env options); ``env_kwargs``: the options of
    the env the run was trained in, for ``gym.make("DeformablePickup-v0", **policy.env_kwargs)``
    (``run_env_options``, with the episode length as ``max_episode_steps``; a run trained on drawn
    goals, ``goal`` / ``goal_noise`` in its run.json, is driven at the task's goal, and one trained
    with ``terminate_on_success`` off is driven with the success ending the episode: those are not
    among ``RUN_ENV_OPTIONS``). ``normalizer``: SB3's ``VecNormalize`` of the run, used
    through ``normalize_obs`` alone, which never updates its statistics (a live training env's
    normaliser may be passed). The policy keeps
    no state between steps; ``reset`` exists for the expert's interface."""

    def __init__(self, model, normalizer, components, settings: dict | None = None):
        columns = action_columns(components)
        if model.action_space.shape != (len(components),):
            raise ValueError(f"the model's actions have shape {model.action_space.shape}, the action set "
                             f"{list(components)} has {len(components)} components")
        self.model = model
        self.normalizer = normalizer  # read only: ``normalize_obs`` never updates its statistics
        self.components = tuple(components)
        self._columns = columns
        self.settings = dict(settings or {})

    @classmethod
    def from_run(cls, folder: str | Path, device: str = "cpu") -> PPOPolicy:
        """Load ``folder`` (``ppo.zip``, ``vecnormalize.pkl``, ``run.json``, as ``train_ppo.py`` and its
        ``--out/best`` write them); ``device``: the torch device of the network."""
        from stable_baselines3 import PPO

        folder = Path(folder)
        missing = [name for name in ("ppo.zip", "vecnormalize.pkl", "run.json") if not (folder / name).is_file()]
        if missing:
            raise FileNotFoundError(f"{folder} is not a train_ppo.py run folder: missing {missing}")
        settings = json.loads((folder / "run.json").read_text())
        actions = settings.get("actions", "full")
        if actions not in ACTION_SETS:
            raise ValueError(f"{folder / 'run.json'}: actions must be one of {sorted(ACTION_SETS)}, got {actions!r}")
        with open(folder / "vecnormalize.pkl", "rb") as f:
            normalizer = pickle.load(f)
        return cls(PPO.load(folder / "ppo.zip", device=device), normalizer, ACTION_SETS[actions], settings)

    @property
    def env_kwargs(self) -> dict:
        """``gym.make`` keyword arguments of the run's env: ``make_env_kwargs()``."""
        return self.make_env_kwargs()

    def make_env_kwargs(self, **overrides) -> dict:
        """``gym.make`` keyword arguments of the run's env with ``overrides`` (keys of
        ``RUN_ENV_OPTIONS``; None keeps the run's): its options (``run_env_options``) and
        ``max_episode_steps`` from their episode length (``gym.make`` keeps the registered limit,
        so an ``episode_seconds`` override alone would not change it)."""
        options = run_env_options(self.settings, **overrides)
        return options | {"max_episode_steps": PickupConfig(**options).max_episode_steps}

    def reset(self, mask=None) -> None:
        """Start new episodes (all worlds or those in ``mask``): nothing to clear."""

    def __call__(self, obs) -> np.ndarray:
        if not isinstance(obs, dict):
            raise TypeError(f"obs must be the env's observation dict, got {type(obs).__name__}")
        missing = [k for k in _OBS_SIZES if k not in obs]
        if missing:
            raise ValueError(f"obs lacks {missing} (a PPO run reads {list(_OBS_SIZES)}: obs_type='state')")
        arrays = {k: np.asarray(obs[k], dtype=np.float32) for k in _OBS_SIZES}
        single = arrays["agent_pos"].ndim == 1
        batch = {k: (v[None] if single else v) for k, v in arrays.items()}
        n = len(batch["agent_pos"])
        for k, size in _OBS_SIZES.items():
            if batch[k].shape != (n, size):
                raise ValueError(f"obs[{k!r}] must have shape ({size},) or (N, {size}), got {arrays[k].shape}")
            bad = ~np.isfinite(batch[k])
            if bad.any():
                raise ValueError(f"obs[{k!r}] must be finite, got {batch[k][bad][:3].tolist()} at "
                                 f"{np.argwhere(bad)[:3].tolist()}")
        normalized = self.normalizer.normalize_obs(batch)
        chosen = np.concatenate([self.model.predict({k: v[i:i + 1] for k, v in normalized.items()},
                                                    deterministic=True)[0] for i in range(n)])
        full = np.zeros((n, DELTA_ACTION.size), np.float32)
        full[:, self._columns] = chosen
        return full[0] if single else full
