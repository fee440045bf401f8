"""``EpisodeWriter``: the one place where recorded episodes become HDF5 files.

It holds the open episode of each world (an :class:`~.capture.EpisodeBuffer` with the replay data
and object it started with) and turns it into a file only when told: :meth:`EpisodeWriter.save`
writes it atomically (temp file + fsync + rename, ``atomic.write_episode``: a crash never leaves a
partial or corrupted file, and files written before stay intact), :meth:`EpisodeWriter.discard`
drops it. ``HDF5Recorder`` (one world), ``VectorHDF5Recorder`` (N worlds) and the teleop
collection app (through ``HDF5Recorder.save`` / ``discard``) all write through it.
"""

from __future__ import annotations

import json
import os
import pathlib

from ..envs.config import PickupConfig
from ..layout import ACTION_LAYOUTS, AGENT_POS, ENV_STATE
from .atomic import check_writable_directory, write_episode
from .capture import EpisodeBuffer
from .config_io import config_to_json, library_versions
from .schema import FORMAT, SCHEMA_VERSION, SUFFIX

#: ``end_reason`` values: the env ended the episode, or it was cut short to start another or to close.
END_REASONS = ("terminated", "truncated", "reset", "close")


def to_json(value, what: str) -> str:
    """``value`` as JSON (sorted keys); TypeError naming ``what`` if it cannot be."""
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


class _Open:
    """One world's episode in progress: its buffer, replay data (JSON-able dict) and object name."""

    def __init__(self, buffer: EpisodeBuffer, replay: dict, object_name: str):
        self.buffer, self.replay, self.object_name = buffer, replay, object_name


class EpisodeWriter:
    """Open episodes of worlds ``0 .. N-1`` and the files they become.

    Args:
        directory: where episode files go; created if missing; must be writable.
        config: the env's ``PickupConfig`` (stored as ``config_json``).
        env_id: stored as the ``env_id`` attribute.
        compression: h5py compression of the large datasets (None, "gzip", "lzf").
        name_template: file name with an ``{index}`` field; existing names are skipped.
        policy: what chooses the actions, stored as the ``policy`` attribute (None: not stored).

    Attributes:
        paths: files written so far, in order. ``episode_index``: the next file's index.
    """

    def __init__(self, directory: str | os.PathLike, config: PickupConfig, *, env_id: str,
                 compression: str | None = None, name_template: str = "episode_{index:06d}" + SUFFIX,
                 policy: str | None = None):
        check_recorder_options(name_template, compression)
        if policy is not None and (not isinstance(policy, str) or not policy):
            raise ValueError(f"policy must be a non-empty string naming what chooses the actions, or None; got {policy!r}")
        self.policy = policy
        self.directory = check_writable_directory(directory)
        self.config = config
        self.env_id = env_id
        self.compression = compression
        self.name_template = name_template
        self.paths: list[pathlib.Path] = []
        self.episode_index = 0
        self._next_name: dict[int, str] = {}  # world -> file name of its next saved episode
        self._open: dict[int, _Open] = {}
        self._versions = to_json(library_versions(), "versions")

    def set_next_name(self, name: str, w: int = 0) -> None:
        """Use file name ``name`` (in ``directory``) for world ``w``'s next saved episode instead of
        the template."""
        if not name.endswith(SUFFIX) or os.sep in name or name.startswith("."):
            raise ValueError(f"episode file name must be a plain name ending in {SUFFIX!r}, got {name!r}")
        self._next_name[w] = name

    def start(self, w: int, object_record: dict, obs0: dict, replay: dict, object_name: str) -> None:
        """Open world ``w``'s next episode: its ``object/`` group, first observation, replay data
        (``ReplaySpec.to_json_dict()`` plus ``max_episode_steps``) and object name. An episode of
        ``w`` with steps that was neither saved nor discarded is an error (RuntimeError)."""
        if self.steps(w):
            raise RuntimeError(f"world {w} has an open episode of {self.steps(w)} steps; save() or discard() it "
                               "before starting the next")
        to_json(replay, "replay data")
        self._open[w] = _Open(EpisodeBuffer(object_record, obs0, self.config.dt), replay, object_name)

    def append(self, w: int, row: tuple, action, obs: dict, reward: float, terminated: bool, truncated: bool,
               info: dict) -> None:
        """One step of world ``w``'s open episode (``capture.step_records`` row, the action, the
        observation after it, reward, flags and scalar info)."""
        if w not in self._open:
            raise RuntimeError(f"world {w} has no open episode; start() it first")
        self._open[w].buffer.append(row, action, obs, reward, terminated, truncated, info)

    def is_open(self, w: int) -> bool:
        return w in self._open

    def steps(self, w: int) -> int:
        """Steps recorded in world ``w``'s open episode (0 if none is open)."""
        return len(self._open[w].buffer) if w in self._open else 0

    def save(self, w: int, reason: str) -> pathlib.Path | None:
        """Write world ``w``'s open episode to a new file (``end_reason`` = ``reason``, one of
        ``END_REASONS``) and close it; returns the path, or None when it had no step (closed
        without a file). If the write fails, the episode stays open and nothing is published."""
        if reason not in END_REASONS:
            raise ValueError(f"reason must be one of {list(END_REASONS)}, got {reason!r}")
        if not self.steps(w):
            self._open.pop(w, None)
            return None
        episode = self._open[w]
        path = self._next_path(w)
        write_episode(path, *self._contents(episode, w, reason), self.compression)
        self._next_name.pop(w, None)  # used: a failed write keeps it for the next save
        del self._open[w]
        self.paths.append(path)
        self.episode_index += 1
        return path

    def discard(self, w: int) -> int:
        """Drop world ``w``'s open episode unwritten; returns its number of steps (0 if none)."""
        steps = self.steps(w)
        self._open.pop(w, None)
        return steps

    # -- internals ---------------------------------------------------------------------------
    def _next_path(self, w: int) -> pathlib.Path:
        if w in self._next_name:
            return self.directory / self._next_name[w]
        while (path := self.directory / self.name_template.format(index=self.episode_index)).exists():
            self.episode_index += 1
        return path

    def _contents(self, episode: _Open, w: int, reason: str) -> tuple[dict, dict, dict]:
        """(datasets, root attributes, column names) of the episode file (``schema.py`` layout)."""
        buf, cfg = episode.buffer, self.config
        arrays = buf.arrays()
        attrs = {
            "format": FORMAT, "schema_version": SCHEMA_VERSION, "env_id": self.env_id,
            "config_json": config_to_json(cfg), "replay_json": to_json(episode.replay, "replay data"),
            "versions_json": self._versions, "object_name": episode.object_name,
            "control_hz": float(cfg.control_hz), "dt": float(cfg.dt), "num_steps": len(buf),
            "episode_index": self.episode_index, "terminated": bool(buf.terminated[-1]),
            "truncated": bool(buf.truncated[-1]), "is_success": bool(arrays["steps/is_success"][-1]),
            "end_reason": reason, "world": w,
        }
        if self.policy is not None:
            attrs["policy"] = self.policy
        names = {"steps/action": list(ACTION_LAYOUTS[cfg.action_mode].names),
                 "observations/agent_pos": list(AGENT_POS.names),
                 "observations/environment_state": list(ENV_STATE.names)}
        names = {k: v for k, v in names.items() if k in arrays and arrays[k].shape[-1] == len(v)}
        return arrays, attrs, names
