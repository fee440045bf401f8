"""``VectorHDF5Recorder``: every episode of every world of the native vector env, one HDF5 file each."""

from __future__ import annotations

import os
import pathlib

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper

from ..envs.config import RANDOM_OBJECT
from ..envs.vector_env import DeformablePickupVectorEnv
from .atomic import check_writable_directory
from .capture import EpisodeBuffer, object_record, step_records
from .config_io import library_versions
from .recorder import _json, check_recorder_options, draw_seed, next_free_path, write_buffer
from .schema import SUFFIX


def _numpy(value) -> np.ndarray:
    """A numpy copy of an observation entry (numpy array or torch tensor on any device)."""
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    return np.asarray(value)


def _world_info(info: dict, w: int) -> dict:
    """World ``w``'s entries of a vector info dict (arrays [N] with ``_key`` masks) as scalars."""
    out = {}
    for key, value in info.items():
        if key.startswith("_"):
            continue
        mask = info.get(f"_{key}")
        if mask is not None and not mask[w]:
            continue
        item = np.asarray(value)[w]
        out[key] = item.item() if item.ndim == 0 else item
    return out


class VectorHDF5Recorder(VectorWrapper):
    """Record every episode of every world of a native ``DeformablePickup-v0`` vector env
    (``gym.make_vec(..., vectorization_mode="vector_entry_point")``), one HDF5 file per episode in
    the schema of :class:`~defgrasp_env.recording.HDF5Recorder` (attribute ``world``: the world).

    On the CPU each file replays bit-exactly in a single env (``defgrasp-dataset replay``): world w
    of the vector env equals a single env reset with the same draws, so the recorder stores the
    seed or RNG state that the single env needs for each of the world's resets, and the reset that
    built the world (``scene_origin``). On CUDA the float atomics sum in a varying order, so a
    replay differs in the last bits and, through contact and friction, by up to millimetres over an
    episode (measured on an H100: 2.8 mm after 45 steps of grasp and lift); the data stays valid. With ``object="random"`` a world keeps the object it was built
    with; its files name it in the reset options (``{"object": name}``) of the replay data.

    Autoreset modes: ``NEXT_STEP`` (an ended world's next step starts its next episode) and
    ``DISABLED`` (steps of an ended world are not recorded until ``reset(options={"reset_mask"})``
    resets it). ``SAME_STEP`` is refused: the env resets a world inside the step that ends its
    episode, before its final state could be read.

    Args:
        env: the native vector env (or a vector wrapper around it).
        directory: where episode files go; created if missing; must be writable.
        compression: h5py compression of the large datasets (None, "gzip", "lzf").
        name_template: file name with an ``{index}`` field; existing names are skipped.
        save_unfinished: write episodes cut short by reset()/close() (``end_reason`` says which).

    Attributes:
        paths: files written so far, in order of completion.
    """

    def __init__(self, env: VectorEnv, directory: str | os.PathLike, *, compression: str | None = None,
                 name_template: str = "episode_{index:06d}" + SUFFIX, save_unfinished: bool = True):
        super().__init__(env)
        uw = env.unwrapped
        if not isinstance(uw, DeformablePickupVectorEnv):
            raise TypeError(f"VectorHDF5Recorder needs the native DeformablePickup-v0 vector env, got {type(uw).__name__}")
        if uw.autoreset_mode == AutoresetMode.SAME_STEP:
            raise ValueError("VectorHDF5Recorder supports autoreset_mode NEXT_STEP or DISABLED, got SAME_STEP "
                             "(the env resets an ended world inside the step, before its final state can be recorded)")
        check_recorder_options(name_template, compression)
        self.directory = check_writable_directory(directory)
        self.compression = compression
        self.name_template = name_template
        self.save_unfinished = save_unfinished
        self.env_id = uw.spec.id if getattr(uw, "spec", None) is not None else "DeformablePickup-v0"
        self.paths: list[pathlib.Path] = []
        self.episode_index = 0
        n = uw.num_envs
        self._buffers: list[EpisodeBuffer | None] = [None] * n
        self._replays: list[dict | None] = [None] * n
        self._origins: list[dict | None] = [None] * n  # the reset that built each world
        self._versions = _json(library_versions(), "versions")

    # -- gym API -----------------------------------------------------------------------------
    def reset(self, *, seed=None, options: dict | None = None):
        uw = self.env.unwrapped
        n = uw.num_envs
        mask = np.ones(n, bool)
        if options is not None and "reset_mask" in options:
            mask = np.asarray(options["reset_mask"], dtype=bool).reshape(n)
        seeds = list(seed) if isinstance(seed, (list, tuple)) else [None if seed is None else seed + i for i in range(n)]
        if len(seeds) != n:  # checked before any unfinished episode is written out
            raise ValueError(f"seed list must have {n} entries, got {len(seeds)}")
        built = uw.scene is None
        if built:
            seeds = [draw_seed() if s is None else s for s in seeds]
        specs = {w: self._spec(w, seeds[w]) for w in np.flatnonzero(mask)}
        for w in specs:
            self._finish(w, "reset")
        obs, info = self.env.reset(seed=seeds, options=options)
        obs_np = {k: _numpy(v) for k, v in obs.items()}
        for w, spec in specs.items():
            if built:
                self._origins[w] = spec
            self._start(w, obs_np, spec, None if built else self._origins[w])
        return obs, info

    def step(self, actions):
        uw = self.env.unwrapped
        resetting = (uw._needs_reset.copy() if uw.autoreset_mode == AutoresetMode.NEXT_STEP
                     else np.zeros(uw.num_envs, bool))
        specs = {w: self._spec(w, None) for w in np.flatnonzero(resetting)}  # their episodes were written
        obs, reward, terminated, truncated, info = self.env.step(actions)
        acts, obs_np = _numpy(actions), {k: _numpy(v) for k, v in obs.items()}
        for w in specs:
            self._start(w, obs_np, specs[w], self._origins[w])
        # DISABLED mode: a world that ended and was not reset yet has no buffer
        recording = [w for w in range(uw.num_envs) if not resetting[w] and self._buffers[w] is not None]
        for w, row in zip(recording, step_records(uw.scene, recording)):
            self._buffers[w].append(row, acts[w], {k: v[w] for k, v in obs_np.items()}, float(reward[w]),
                                    bool(terminated[w]), bool(truncated[w]), _world_info(info, w))
            if terminated[w] or truncated[w]:
                self._write(w, "terminated" if terminated[w] else "truncated")
        return obs, reward, terminated, truncated, info

    def close(self, **kwargs):
        try:
            for w in range(len(self._buffers)):
                self._finish(w, "close")
        finally:
            super().close(**kwargs)

    # -- internals ---------------------------------------------------------------------------
    def _spec(self, w: int, seed) -> dict:
        """What a single env needs to repeat world w's next reset: its seed, else its RNG state,
        and the world's object if it is drawn per episode in a single env."""
        uw = self.env.unwrapped
        options = {"object": uw.scene.object_names[w]} if uw.config.object == RANDOM_OBJECT and uw.scene else None
        if seed is not None:
            return {"seed": int(seed), "rng_state": None, "options": options}
        return {"seed": None, "rng_state": uw._rngs[w].bit_generator.state, "options": options}

    def _start(self, w: int, obs_np: dict, spec: dict, scene_origin: dict | None) -> None:
        """Open world w's next episode; ``obs_np``: the batched observation as numpy arrays."""
        uw = self.env.unwrapped
        self._replays[w] = {**spec, "scene_origin": scene_origin, "max_episode_steps": uw.max_episode_steps}
        self._buffers[w] = EpisodeBuffer(object_record(uw.scene, w), {k: v[w] for k, v in obs_np.items()},
                                         uw.config.dt)

    def _finish(self, w: int, reason: str) -> None:
        if self._buffers[w] is not None and len(self._buffers[w]) and self.save_unfinished:
            self._write(w, reason)
        self._buffers[w] = None

    def _write(self, w: int, reason: str) -> pathlib.Path:
        uw = self.env.unwrapped
        buf, self._buffers[w] = self._buffers[w], None
        name = uw.scene.object_names[w]
        path, self.episode_index = next_free_path(self.directory, self.name_template, self.episode_index)
        write_buffer(path, buf, uw.config, env_id=self.env_id, object_name=name, replay=self._replays[w],
                     versions_json=self._versions, episode_index=self.episode_index, reason=reason,
                     compression=self.compression, extra_attrs={"world": w})
        self.paths.append(path)
        self.episode_index += 1
        return path
