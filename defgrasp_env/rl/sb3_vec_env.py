"""``SB3VectorEnv``: the native vector env of ``DeformablePickup-v0`` as a Stable-Baselines3 ``VecEnv``.

    from stable_baselines3 import PPO
    venv = SB3VectorEnv(gym.make_vec("DeformablePickup-v0", num_envs=16, autoreset_mode="SameStep"))
    PPO("MultiInputPolicy", VecNormalize(venv)).learn(100_000)

Stable-Baselines3 steps a ``VecEnv`` (N worlds, auto-reset inside ``step``, one info dict per world),
not a Gymnasium ``VectorEnv``. This adapter keeps the N worlds in ONE batched FEM simulation (no
per-world processes) and translates the protocol:

* observations: the env's Dict of numpy arrays [N, ...] (``MultiInputPolicy``), float32;
* ``step_wait`` returns rewards [N] float32, dones [N] (terminated or truncated) and a list of N
  info dicts with the env's per-world scalars (``is_success``, reward terms, ...), plus, for worlds
  whose episode ended, ``terminal_observation`` (their last observation; the returned observation is
  already the next episode's first) and ``TimeLimit.truncated`` (truncated and not terminated), as
  SB3 expects for bootstrapping;
* ``seed(s)`` seeds world i with ``s + i`` at the next ``reset()``;
* ``stagger_first_episodes=True`` cuts each world's first episode after a number of steps drawn
  uniformly from 1 .. the env's time limit (``first_episode_steps``, drawn at each ``reset()`` from
  a generator of its own that ``seed`` seeds), so that the worlds, which ``reset()`` starts
  together, run their episodes out of phase from then on (Isaac Lab / rsl_rl's random initial
  episode length). Without it, worlds whose episodes all run to the time limit (a success that does
  not terminate, ``PickupConfig.terminate_on_success=False``) stay in phase: every PPO rollout then
  holds one phase of the task (reaching, then grasping, then holding), and learning on the holding
  phase alone unlearnt the grasp (benchmarks/RESULTS.md). A cut episode ends as a truncation
  (``TimeLimit.truncated``); the world's next episode starts from its reset, drawn from the world's
  RNG as it would have been at the time limit. Every first episode's last info (cut or ended by
  itself before its cut) holds ``staggered_start=True``: such episodes are not a sample of the
  task's (a success before the cut is kept, a failure is cut), so learning curves leave them out
  (``train_ppo.py``'s does; SB3's own ``rollout/ep_*`` logs, through ``VecMonitor``, do not).

The wrapped env must use ``autoreset_mode="SameStep"`` (SB3's convention) and numpy outputs.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

__all__ = ["SB3VectorEnv"]

#: Second word of the seed of ``SB3VectorEnv``'s cut draws: a stream apart from the worlds' RNGs.
_STAGGER_STREAM = 0x57A6


class SB3VectorEnv(VecEnv):
    """Stable-Baselines3 view of a ``DeformablePickupVectorEnv`` (see the module docstring)."""

    def __init__(self, env, stagger_first_episodes: bool = False):
        venv = getattr(env, "unwrapped", env)
        if getattr(venv, "autoreset_mode", None) != AutoresetMode.SAME_STEP:
            raise ValueError(f"the vector env must use autoreset_mode='SameStep', got "
                             f"{getattr(venv, 'autoreset_mode', None)!r}")
        if getattr(venv, "torch_outputs", False):
            raise ValueError("the vector env must return numpy observations (torch_outputs=False)")
        self.env = env
        self._actions: np.ndarray | None = None
        self.stagger_first_episodes = bool(stagger_first_episodes)
        self._time_limit = int(venv.max_episode_steps)  # steps: the env truncates its episodes here
        self._steps_since_reset = 0  # vector steps since ``reset()``
        #: [N] steps after which ``reset()``'s first episodes are cut (the time limit: not cut); zeros unstaggered
        self.first_episode_steps = np.zeros(env.num_envs, np.int64)
        self._cut_at = np.zeros(env.num_envs, np.int64)  # [N] the same, 0 once the world's first episode ended
        self._stagger_rng = np.random.default_rng()  # the cuts' draws (``seed`` seeds it)
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)

    # -- VecEnv API --------------------------------------------------------------------------
    def reset(self):
        seeds = self._seeds if any(s is not None for s in self._seeds) else None
        if any(self._options):  # set by SB3's set_options: the native vector env takes one option dict
            raise ValueError(f"{type(self).__name__} has no per-world reset options, got {self._options}")
        obs, info = self.env.reset(seed=seeds)
        self._reset_seeds()
        self.reset_infos = self._split_info(info)
        self._steps_since_reset = 0
        if self.stagger_first_episodes:
            self.first_episode_steps = self._stagger_rng.integers(1, self._time_limit + 1, size=self.num_envs)
            self._cut_at = self.first_episode_steps.copy()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, np.float32)

    def step_wait(self):
        if self._actions is None:
            raise RuntimeError("step_async() must come before step_wait()")
        obs, reward, terminated, truncated, info = self.env.step(self._actions)
        self._actions = None
        done = np.asarray(terminated, bool) | np.asarray(truncated, bool)
        infos = self._split_info(info)
        if done.any():
            final_obs = info["final_obs"]
            final_info = self._split_info(info["final_info"])
            for i in np.flatnonzero(done):
                self.reset_infos[i] = infos[i]  # the new episode's reset info (its ReplaySpec)
                infos[i] = {**final_info[i], "terminal_observation": {k: v[i] for k, v in final_obs.items()},
                            "TimeLimit.truncated": bool(truncated[i] and not terminated[i])}
        self._steps_since_reset += 1
        first = done & (self._cut_at > 0)  # first episodes that ended by themselves: not cut
        for i in np.flatnonzero(first):
            infos[i]["staggered_start"] = True
        self._cut_at[done] = 0
        cut = self._cut_at == self._steps_since_reset
        if cut.any():
            obs = self._cut_episodes(cut, obs, infos)
            done = done | cut
        return obs, np.asarray(reward, np.float32), done, infos

    def seed(self, seed: int | None = None):
        self._seeds = [None if seed is None else seed + i for i in range(self.num_envs)]
        # the cuts' own stream: apart from every world's RNG (world 0's is seeded with ``seed`` itself)
        self._stagger_rng = np.random.default_rng(None if seed is None else [seed, _STAGGER_STREAM])
        return self._seeds

    def close(self) -> None:
        self.env.close()

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        value = getattr(self.env.unwrapped, attr_name) if attr_name != "render_mode" else self.env.render_mode
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        raise AttributeError(f"{type(self).__name__} does not set attributes of the worlds ({attr_name!r})")

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        raise AttributeError(f"{type(self).__name__}: the worlds share one simulation; no per-world "
                             f"{method_name!r}")

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self):
        return list(self.env.render())

    # -- internals -------------------------------------------------------------------------
    def _cut_episodes(self, cut: np.ndarray, obs: dict, infos: list[dict]) -> dict:
        """End the episodes of the worlds in ``cut`` [N] as truncations (``stagger_first_episodes``):
        their infos get the terminal observation and ``staggered_start``; the worlds are reset (the
        others untouched) and the returned observation holds their new episodes' first rows."""
        self._cut_at[cut] = 0
        for i in np.flatnonzero(cut):
            infos[i] = {**infos[i], "terminal_observation": {k: v[i].copy() for k, v in obs.items()},
                        "TimeLimit.truncated": True, "staggered_start": True}
        reset_obs, reset_info = self.env.reset(options={"reset_mask": cut})
        reset_infos = self._split_info(reset_info)
        for i in np.flatnonzero(cut):
            self.reset_infos[i] = reset_infos[i]
        return {k: np.where(cut.reshape((-1,) + (1,) * (v.ndim - 1)), reset_obs[k], v) for k, v in obs.items()}

    def _split_info(self, info: dict) -> list[dict]:
        """Gymnasium's batched info (arrays [N] with ``_key`` masks) -> N per-world dicts: Python
        scalars from 1-D numeric arrays, rows (arrays) or objects (e.g. a ReplaySpec) otherwise.
        Converted array by array (``tolist``), not item by item: at N = 2048 the per-item version
        cost ~70 ms a step, as much as the GPU env step it reported on."""
        out: list[dict] = [{} for _ in range(self.num_envs)]
        for key, value in info.items():
            if key.startswith("_") or key in ("final_obs", "final_info") or not isinstance(value, np.ndarray):
                continue
            items = value.tolist() if value.ndim == 1 and value.dtype != object else list(value)
            mask = info.get(f"_{key}")
            if mask is None or np.all(mask):
                for world_info, item in zip(out, items):
                    world_info[key] = item
            else:
                for i in np.flatnonzero(mask):
                    out[i][key] = items[i]
        return out
