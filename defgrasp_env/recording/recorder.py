"""``HDF5Recorder``: a Gymnasium wrapper writing every episode of a DeformablePickup env to HDF5."""

from __future__ import annotations

import os
import pathlib

import gymnasium as gym

from ..envs.config import PickupConfig
from .capture import object_record, step_record
from .schema import SUFFIX
from .writer import EpisodeWriter, to_json


class HDF5Recorder(gym.Wrapper):
    """Record every step of every episode of a ``DeformablePickup-v0`` env, one HDF5 file per episode.

    The file layout is the paper's Table 1 plus actions, rewards, flags, observations and what replay
    needs (``defgrasp_env.recording.schema``, ``datasets/README.md``): the ``ReplaySpec`` that the
    env's ``reset`` returns in ``info["replay_spec"]``. An episode is written when it terminates or
    truncates; one cut short is written by :meth:`save` or dropped by :meth:`discard`, and
    ``reset()``/``close()`` do one of the two by themselves (``save_unfinished``). Files appear
    atomically (``EpisodeWriter``), so a crash never leaves a partial episode.

    Args:
        env: a ``DeformablePickup-v0`` env (``gym.make`` result or the bare env); W = 1.
        directory: where episode files go; created if missing; must be writable.
        record_frames: also store camera frames (``observations/pixels``) by calling ``render()``
            (needs ``render_mode="rgb_array"``); pixel observations are always stored.
        compression: h5py compression of the large datasets (None = fastest, "gzip", "lzf").
        name_template: file name with an ``{index}`` field; existing names are skipped.
        save_unfinished: what ``reset()``/``close()`` do with an episode cut short: save it
            (``end_reason`` "reset"/"close") or discard it.
        policy: what chooses the actions (``defgrasp-generate``'s ``--policy``, ``"teleop"``),
            stored in every file as the ``policy`` attribute; None: not stored.

    Attributes:
        paths: files written so far (in order). ``last_path``: the latest one or None.
    """

    def __init__(self, env: gym.Env, directory: str | os.PathLike, *, record_frames: bool = False,
                 compression: str | None = None, name_template: str = "episode_{index:06d}" + SUFFIX,
                 save_unfinished: bool = True, policy: str | None = None):
        super().__init__(env)
        uw = env.unwrapped
        if not isinstance(getattr(uw, "config", None), PickupConfig) or not hasattr(uw, "scene"):
            raise TypeError(f"HDF5Recorder needs a DeformablePickup env (with .config and .scene), "
                            f"got {type(uw).__name__}")
        pixels_in_obs = isinstance(env.observation_space, gym.spaces.Dict) and "pixels" in env.observation_space.spaces
        if record_frames and not pixels_in_obs and env.render_mode != "rgb_array":
            raise ValueError(f"record_frames=True needs render_mode='rgb_array', got {env.render_mode!r}")
        self.writer = EpisodeWriter(directory, uw.config, compression=compression, name_template=name_template,
                                    env_id=env.spec.id if env.spec is not None else type(uw).__name__, policy=policy)
        self.record_frames = record_frames and not pixels_in_obs
        self.save_unfinished = save_unfinished
        self._ended = False

    @property
    def directory(self) -> pathlib.Path:
        return self.writer.directory

    @property
    def paths(self) -> list[pathlib.Path]:
        return self.writer.paths

    @property
    def last_path(self) -> pathlib.Path | None:
        return self.paths[-1] if self.paths else None

    def set_next_name(self, name: str) -> None:
        """Use file name ``name`` (in ``directory``) for the next episode instead of the template."""
        self.writer.set_next_name(name)

    def save(self, reason: str = "reset") -> pathlib.Path | None:
        """Write the episode in progress now; ``reason`` (its ``end_reason``): "reset" (cut short to
        start another) or "close". Returns its path, or None when there is none with a step. The
        next ``step`` needs a ``reset``."""
        self._ended = True
        return self.writer.save(0, reason)

    def discard(self) -> int:
        """Drop the episode in progress unwritten; returns its number of steps (0: none). The next
        ``step`` needs a ``reset``."""
        self._ended = True
        return self.writer.discard(0)

    # -- gym API -----------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        to_json(options, "reset options")  # they go into the replay data: refuse them before anything changes
        self._finish_unfinished("reset")
        obs, info = self.env.reset(seed=seed, options=options)
        limit = self.env.spec.max_episode_steps if self.env.spec is not None else None
        spec = info["replay_spec"]
        self.writer.start(0, object_record(self.env.unwrapped.scene), self._obs_dict(obs),
                          {**spec.to_json_dict(), "max_episode_steps": limit}, spec.object_name)
        self._ended = False
        return obs, info

    def step(self, action):
        if self._ended:
            raise RuntimeError("HDF5Recorder: the episode has ended (terminated, truncated, saved or discarded); "
                               "call reset()")
        if not self.writer.is_open(0):
            raise RuntimeError("HDF5Recorder: call reset() before step()")
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.writer.append(0, step_record(self.env.unwrapped.scene), action, self._obs_dict(obs), reward,
                           terminated, truncated, info)
        if terminated or truncated:
            self.save("terminated" if terminated else "truncated")
        return obs, reward, terminated, truncated, info

    def close(self):
        try:
            self._finish_unfinished("close")
        finally:
            super().close()

    # -- internals ---------------------------------------------------------------------------
    def _obs_dict(self, obs) -> dict:
        out = dict(obs) if isinstance(obs, dict) else {"observation": obs}
        if self.record_frames:
            out["pixels"] = self.env.render()
        return out

    def _finish_unfinished(self, reason: str) -> None:
        if self.save_unfinished:
            self.writer.save(0, reason)
        else:
            self.writer.discard(0)
