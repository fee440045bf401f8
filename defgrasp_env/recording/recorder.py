"""``HDF5Recorder``: a Gymnasium wrapper writing every episode of a DeformablePickup env to HDF5."""

from __future__ import annotations

import json
import os
import pathlib

import gymnasium as gym
import numpy as np

from ..envs.config import PickupConfig
from ..layout import ACTION_LAYOUTS, AGENT_POS, ENV_STATE
from .atomic import check_writable_directory, write_episode
from .capture import EpisodeBuffer, object_record, step_record
from .config_io import config_to_json, library_versions
from .schema import FORMAT, SCHEMA_VERSION, SUFFIX

#: Column names of ``steps/action`` per action mode (``defgrasp_env.layout``).
ACTION_NAMES = {mode: list(layout.names) for mode, layout in ACTION_LAYOUTS.items()}


def _json(value, what: str) -> str:
    try:
        return json.dumps(value, sort_keys=True)
    except TypeError as exc:
        raise TypeError(f"{what} must be JSON-serialisable to be recorded for replay, got {value!r}") from exc


def check_recorder_options(name_template: str, compression: str | None) -> None:
    """Validate a recorder's file-name template and h5py compression."""
    if "{index" not in name_template or not name_template.endswith(SUFFIX):
        raise ValueError(f"name_template must contain '{{index}}' and end with {SUFFIX!r}, got {name_template!r}")
    if compression not in (None, "gzip", "lzf"):
        raise ValueError(f"compression must be None, 'gzip' or 'lzf', got {compression!r}")


def draw_seed() -> int:
    """A fresh seed, drawn as gym would draw one, so that an unseeded first reset can be recorded."""
    return int(np.random.SeedSequence().generate_state(1)[0])


def next_free_path(directory: pathlib.Path, name_template: str, index: int) -> tuple[pathlib.Path, int]:
    """The first ``directory / name_template.format(index=i)`` with i >= index that does not exist, and i."""
    while (path := directory / name_template.format(index=index)).exists():
        index += 1
    return path, index


def write_buffer(path: pathlib.Path, buf: EpisodeBuffer, cfg: PickupConfig, *, env_id: str, object_name: str,
                 replay: dict, versions_json: str, episode_index: int, reason: str, compression: str | None,
                 extra_attrs: dict | None = None) -> pathlib.Path:
    """Write one recorded episode (schema.py layout, attributes included) atomically to ``path``."""
    arrays = buf.arrays()
    attrs = {
        "format": FORMAT, "schema_version": SCHEMA_VERSION, "env_id": env_id,
        "config_json": config_to_json(cfg), "replay_json": _json(replay, "replay data"),
        "versions_json": versions_json, "object_name": object_name,
        "control_hz": float(cfg.control_hz), "dt": float(cfg.dt), "num_steps": len(buf),
        "episode_index": episode_index, "terminated": bool(buf.terminated[-1]),
        "truncated": bool(buf.truncated[-1]), "is_success": bool(arrays["steps/is_success"][-1]),
        "end_reason": reason, **(extra_attrs or {}),
    }
    names = {"steps/action": ACTION_NAMES[cfg.action_mode],
             "observations/agent_pos": list(AGENT_POS.names),
             "observations/environment_state": list(ENV_STATE.names)}
    names = {k: v for k, v in names.items() if k in arrays and arrays[k].shape[-1] == len(v)}
    return write_episode(path, arrays, attrs, names, compression)


class HDF5Recorder(gym.Wrapper):
    """Record every step of every episode of a ``DeformablePickup-v0`` env, one HDF5 file per episode.

    The file layout is the paper's Table 1 plus actions, rewards, flags, observations and what replay
    needs (``defgrasp_env.recording.schema``, ``datasets/README.md``). An episode is written when it
    terminates or truncates, or (if ``save_unfinished``) when ``reset()``/``close()`` cuts it short;
    files appear atomically (temp file + fsync + rename), so a crash never leaves a partial episode.

    Args:
        env: a ``DeformablePickup-v0`` env (``gym.make`` result or the bare env); W = 1.
        directory: where episode files go; created if missing; must be writable.
        record_frames: also store camera frames (``observations/pixels``) by calling ``render()``
            (needs ``render_mode="rgb_array"``); pixel observations are always stored.
        compression: h5py compression of the large datasets (None = fastest, "gzip", "lzf").
        name_template: file name with an ``{index}`` field; existing names are skipped.
        save_unfinished: write episodes cut short by reset()/close() (``end_reason`` says which).

    Attributes:
        paths: files written so far (in order). ``last_path``: the latest one or None.
    """

    def __init__(self, env: gym.Env, directory: str | os.PathLike, *, record_frames: bool = False,
                 compression: str | None = None, name_template: str = "episode_{index:06d}" + SUFFIX,
                 save_unfinished: bool = True):
        super().__init__(env)
        uw = env.unwrapped
        if not isinstance(getattr(uw, "config", None), PickupConfig) or not hasattr(uw, "scene"):
            raise TypeError(f"HDF5Recorder needs a DeformablePickup env (with .config and .scene), "
                            f"got {type(uw).__name__}")
        check_recorder_options(name_template, compression)
        pixels_in_obs = isinstance(env.observation_space, gym.spaces.Dict) and "pixels" in env.observation_space.spaces
        if record_frames and not pixels_in_obs and env.render_mode != "rgb_array":
            raise ValueError(f"record_frames=True needs render_mode='rgb_array', got {env.render_mode!r}")
        self.directory = check_writable_directory(directory)
        self.record_frames = record_frames and not pixels_in_obs
        self.compression = compression
        self.name_template = name_template
        self.save_unfinished = save_unfinished
        self.env_id = env.spec.id if env.spec is not None else type(uw).__name__
        self.paths: list[pathlib.Path] = []
        self.episode_index = 0
        self._next_name: str | None = None
        self._buffer: EpisodeBuffer | None = None
        self._ended = False
        self._replay: dict | None = None
        self._scene_origin: dict | None = None
        self._versions = _json(library_versions(), "versions")

    @property
    def last_path(self) -> pathlib.Path | None:
        return self.paths[-1] if self.paths else None

    def set_next_name(self, name: str) -> None:
        """Use file name ``name`` (in ``directory``) for the next episode instead of the template."""
        if not name.endswith(SUFFIX) or os.sep in name or name.startswith("."):
            raise ValueError(f"episode file name must be a plain name ending in {SUFFIX!r}, got {name!r}")
        self._next_name = name

    # -- gym API -----------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self._finish_unfinished("reset")
        uw = self.env.unwrapped
        rng_state = None
        if seed is None:
            if uw._np_random is None:
                seed = draw_seed()
            else:
                rng_state = uw.np_random.bit_generator.state
        this = {"seed": seed, "rng_state": rng_state, "options": options}
        limit = self.env.spec.max_episode_steps if self.env.spec is not None else None
        _json(this, "reset seed/options")
        old_scene = uw.scene
        obs, info = self.env.reset(seed=seed, options=options)
        if uw.scene is not old_scene:
            self._scene_origin = this
        elif self._scene_origin is None:  # built by a reset before this wrapper: replay not bit-exact
            self._scene_origin = {"unknown": True}
        self._replay = {**this, "scene_origin": None if self._scene_origin is this else self._scene_origin,
                        "max_episode_steps": limit}
        self._buffer = EpisodeBuffer(object_record(uw.scene), self._obs_dict(obs), uw.config.dt)
        self._ended = False
        return obs, info

    def step(self, action):
        if self._ended:
            raise RuntimeError("HDF5Recorder: the episode has ended (terminated or truncated); call reset()")
        if self._buffer is None:
            raise RuntimeError("HDF5Recorder: call reset() before step()")
        obs, reward, terminated, truncated, info = self.env.step(action)
        row = step_record(self.env.unwrapped.scene)
        self._buffer.append(row, action, self._obs_dict(obs), reward, terminated, truncated, info)
        if terminated or truncated:
            self._ended = True
            self._write("terminated" if terminated else "truncated")
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
        if self._buffer is not None and not self._ended and len(self._buffer) and self.save_unfinished:
            self._write(reason)
        self._buffer = None

    def _next_path(self) -> pathlib.Path:
        if self._next_name is not None:
            name, self._next_name = self._next_name, None
            return self.directory / name
        path, self.episode_index = next_free_path(self.directory, self.name_template, self.episode_index)
        return path

    def _write(self, reason: str) -> pathlib.Path:
        buf, uw = self._buffer, self.env.unwrapped
        self._buffer = None
        path = write_buffer(self._next_path(), buf, uw.config, env_id=self.env_id, object_name=uw.scene.object_names[0],
                            replay=self._replay, versions_json=self._versions, episode_index=self.episode_index,
                            reason=reason, compression=self.compression, extra_attrs={"world": 0})
        self.paths.append(path)
        self.episode_index += 1
        return path
