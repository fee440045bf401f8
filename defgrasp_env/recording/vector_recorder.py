"""``VectorHDF5Recorder``: every episode of every world of the native vector env, one HDF5 file each."""

from __future__ import annotations

import os
import pathlib

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper

from ..envs.vector_env import DeformablePickupVectorEnv
from .capture import object_record, step_records
from .schema import SUFFIX
from .writer import EpisodeWriter


def _numpy(value) -> np.ndarray:
    """A numpy copy of an observation entry (numpy array or torch tensor on any device)."""
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    return np.asarray(value)


def _world_info(info: dict, w: int) -> dict:
    """World ``w``'s scalar entries of a vector info dict (arrays [N] with ``_key`` masks)."""
    out = {}
    for key, value in info.items():
        if key.startswith("_") or key == "replay_spec":
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
    of the vector env equals a single env reset with the same draws, and the env emits, for each
    world it (re)sets, the ``ReplaySpec`` a single env needs (``info["replay_spec"]`` of ``reset``
    and of autoresetting ``step``s: seed or RNG state, options, and the reset that built the world,
    ``scene_origin``); the recorder stores it and reads nothing private of the env. On CUDA the
    float atomics sum in a varying order, so a replay differs in the last bits and, through contact
    and friction, by up to millimetres over an episode (measured on an H100: 2.8 mm after 45 steps
    of grasp and lift); the data stays valid. With ``object="random"`` (or a tuple) a world draws a
    fresh object per episode, as a single env on the same seed or RNG state draws it.

    Autoreset modes: ``NEXT_STEP`` (an ended world's next step starts its next episode) and
    ``DISABLED`` (steps of an ended world are not recorded until ``reset(options={"reset_mask"})``
    resets it). ``SAME_STEP`` is refused: the env resets a world inside the step that ends its
    episode, before its final state could be read.

    Args:
        env: the native vector env (or a vector wrapper around it).
        directory: where episode files go; created if missing; must be writable.
        compression: h5py compression of the large datasets (None, "gzip", "lzf").
        name_template: file name with an ``{index}`` field; existing names are skipped.
        save_unfinished: what reset()/close() do with episodes cut short: save them (``end_reason``
            "reset"/"close") or discard them.
        policy: what chooses the actions, stored in every file as the ``policy`` attribute; None:
            not stored.

    Attributes:
        paths: files written so far, in order of completion. ``writer``: the ``EpisodeWriter``.
    """

    def __init__(self, env: VectorEnv, directory: str | os.PathLike, *, compression: str | None = None,
                 name_template: str = "episode_{index:06d}" + SUFFIX, save_unfinished: bool = True,
                 policy: str | None = None):
        super().__init__(env)
        uw = env.unwrapped
        if not isinstance(uw, DeformablePickupVectorEnv):
            raise TypeError(f"VectorHDF5Recorder needs the native DeformablePickup-v0 vector env, got {type(uw).__name__}")
        if uw.autoreset_mode == AutoresetMode.SAME_STEP:
            raise ValueError("VectorHDF5Recorder supports autoreset_mode NEXT_STEP or DISABLED, got SAME_STEP "
                             "(the env resets an ended world inside the step, before its final state can be recorded)")
        self.writer = EpisodeWriter(directory, uw.config, compression=compression, name_template=name_template,
                                    env_id=uw.spec.id if getattr(uw, "spec", None) is not None
                                    else "DeformablePickup-v0", policy=policy)
        self.save_unfinished = save_unfinished

    @property
    def directory(self) -> pathlib.Path:
        return self.writer.directory

    @property
    def paths(self) -> list[pathlib.Path]:
        return self.writer.paths

    def set_next_name(self, name: str, world: int) -> None:
        """Use file name ``name`` (in ``directory``) for world ``world``'s next saved episode
        instead of the template."""
        n = self.env.unwrapped.num_envs
        if isinstance(world, bool) or not isinstance(world, (int, np.integer)) or not 0 <= world < n:
            raise ValueError(f"world must be an int in [0, {n - 1}], got {world!r}")
        self.writer.set_next_name(name, int(world))

    # -- gym API -----------------------------------------------------------------------------
    def reset(self, *, seed=None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._start(info, {k: _numpy(v) for k, v in obs.items()}, "reset")
        return obs, info

    def step(self, actions):
        obs, reward, terminated, truncated, info = self.env.step(actions)
        acts, obs_np = _numpy(actions), {k: _numpy(v) for k, v in obs.items()}
        started = self._start(info, obs_np, "reset")  # autoreset (NEXT_STEP): their step is not theirs
        # DISABLED mode: a world that ended and was not reset yet has no open episode
        recording = [w for w in range(self.env.unwrapped.num_envs) if not started[w] and self.writer.is_open(w)]
        for w, row in zip(recording, step_records(self.env.unwrapped.scene, recording)):
            self.writer.append(w, row, acts[w], {k: v[w] for k, v in obs_np.items()}, float(reward[w]),
                               bool(terminated[w]), bool(truncated[w]), _world_info(info, w))
            if terminated[w] or truncated[w]:
                self.writer.save(w, "terminated" if terminated[w] else "truncated")
        return obs, reward, terminated, truncated, info

    def close(self, **kwargs):
        try:
            for w in range(self.env.unwrapped.num_envs):
                self._finish(w, "close")
        finally:
            super().close(**kwargs)

    # -- internals ---------------------------------------------------------------------------
    def _start(self, info: dict, obs_np: dict, reason: str) -> np.ndarray:
        """Open the next episode of every world the env (re)set (``info["_replay_spec"]``), after
        finishing its episode in progress; returns that mask [N]."""
        uw = self.env.unwrapped
        started = np.asarray(info.get("_replay_spec", np.zeros(uw.num_envs, bool)))
        for w in np.flatnonzero(started):
            spec = info["replay_spec"][w]
            self._finish(w, reason)
            self.writer.start(w, object_record(uw.scene, w), {k: v[w] for k, v in obs_np.items()},
                              {**spec.to_json_dict(), "max_episode_steps": uw.max_episode_steps}, spec.object_name)
        return started

    def _finish(self, w: int, reason: str) -> None:
        if self.save_unfinished:
            self.writer.save(w, reason)
        else:
            self.writer.discard(w)
