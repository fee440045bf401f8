"""Shared helpers of the recording tests (no tests here): record short episodes quickly."""

from __future__ import annotations

import pathlib

import gymnasium as gym
import numpy as np

import defgrasp_env  # noqa: F401  (registers the env)
from defgrasp_env.recording import HDF5Recorder

STEPS = 10


def scripted_actions(seed: int, steps: int, size: int = 7) -> np.ndarray:
    """Down, close the jaw, then up: touches the object so that forces and stresses are non-trivial."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(-0.3, 0.3, size=(steps, size)).astype(np.float32)
    a[:, 1] = np.where(np.arange(steps) < steps // 2, -1.0, 0.5)
    a[:, 6] = np.where(np.arange(steps) < steps // 3, -1.0, 1.0)
    return a


def make_recorder(directory: pathlib.Path, steps: int = STEPS, **kwargs) -> HDF5Recorder:
    env_kwargs = {"object": "cuboid", "youngs_modulus": 1e5, "max_episode_steps": steps}
    rec_kwargs = {}
    for key in ("record_frames", "compression", "name_template", "save_unfinished"):
        if key in kwargs:
            rec_kwargs[key] = kwargs.pop(key)
    env_kwargs.update(kwargs)
    return HDF5Recorder(gym.make("DeformablePickup-v0", **env_kwargs), directory, **rec_kwargs)


def run_episode(env, seed, steps: int = STEPS, action_seed: int = 0):
    """Reset with ``seed`` and step scripted actions until the episode ends; returns the rows seen."""
    obs, _ = env.reset(seed=seed)
    seen = []
    for a in scripted_actions(action_seed, steps, env.action_space.shape[0]):
        obs, reward, terminated, truncated, info = env.step(a)
        scene = env.unwrapped.scene
        seen.append({"positions": scene.state.positions.numpy().copy(), "reward": reward, "info": info,
                     "obs": {k: np.array(v) for k, v in obs.items()}})
        if terminated or truncated:
            break
    return seen


def record_episodes(directory: pathlib.Path, seeds=(0, 1), steps: int = STEPS, **kwargs) -> list[pathlib.Path]:
    env = make_recorder(directory, steps, **kwargs)
    for i, seed in enumerate(seeds):
        run_episode(env, seed, steps, action_seed=i)
    env.close()
    return list(env.paths)
