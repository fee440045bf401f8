"""Reading episode files, with errors that name the file and the problem."""

from __future__ import annotations

import json
import os
import pathlib
from collections.abc import Iterable
from dataclasses import dataclass, field

import h5py
import numpy as np

from .schema import FIELDS, FORMAT, SCHEMA_VERSION, SUFFIX


class EpisodeFileError(ValueError):
    """An episode file is unreadable, foreign or does not follow the schema."""


def list_episodes(directory: str | os.PathLike) -> list[pathlib.Path]:
    """Episode files (``*.h5``) in ``directory``, sorted by name; hidden/temp files are skipped."""
    d = pathlib.Path(directory)
    if not d.is_dir():
        raise NotADirectoryError(f"{d}: not a directory of episode files")
    return sorted(p for p in d.iterdir() if p.suffix == SUFFIX and not p.name.startswith(".") and p.is_file())


def episode_paths(path: str | os.PathLike) -> list[pathlib.Path]:
    """``path`` itself if it is a file, else the episode files of the directory."""
    p = pathlib.Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such episode file or directory")
    return list_episodes(p) if p.is_dir() else [p]


def open_checked(path: str | os.PathLike) -> h5py.File:
    """Open an episode file read-only after checking it is HDF5 and a defgrasp episode."""
    p = pathlib.Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: episode file not found")
    if p.is_dir():
        raise IsADirectoryError(f"{p}: is a directory, expected an episode file ({SUFFIX})")
    try:
        is_hdf5 = h5py.is_hdf5(p)
    except OSError as exc:
        raise EpisodeFileError(f"{p}: cannot be read ({exc})") from exc
    if not is_hdf5:
        raise EpisodeFileError(f"{p}: not an HDF5 file (foreign format or truncated header)")
    try:
        f = h5py.File(p, "r")
    except OSError as exc:
        raise EpisodeFileError(f"{p}: corrupt or truncated HDF5 file ({exc})") from exc
    fmt = _attr(f.attrs.get("format"))
    if fmt != FORMAT:
        f.close()
        raise EpisodeFileError(f"{p}: not a defgrasp episode (root attribute 'format' is {fmt!r}, "
                               f"expected {FORMAT!r})")
    version = _attr(f.attrs.get("schema_version"))
    if not isinstance(version, int) or isinstance(version, bool) or not 1 <= version <= SCHEMA_VERSION:
        f.close()
        raise EpisodeFileError(f"{p}: unsupported schema_version {version!r} (this library reads 1..{SCHEMA_VERSION})")
    return f


def _attr(value):
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


@dataclass
class Episode:
    """One loaded episode: root attributes and datasets ("group/name" -> numpy array)."""

    path: pathlib.Path
    attrs: dict
    data: dict[str, np.ndarray]
    names: dict[str, list[str]] = field(default_factory=dict)

    def __getitem__(self, key: str) -> np.ndarray:
        try:
            return self.data[key]
        except KeyError:
            raise KeyError(f"{self.path}: no dataset {key!r} (has {sorted(self.data)})") from None

    def __contains__(self, key: str) -> bool:
        return key in self.data

    @property
    def num_steps(self) -> int:
        return int(self.attrs["num_steps"])

    @property
    def replay(self) -> dict:
        return json.loads(self.attrs["replay_json"])

    @property
    def config(self):
        from .config_io import config_from_json
        return config_from_json(self.attrs["config_json"])

    def feature_points(self) -> np.ndarray:
        """Object feature point P_feature (mean node position, paper eq. 5) per step [T,3], m."""
        return self["steps/node_positions"].astype(np.float64).mean(axis=1)


def load_episode(path: str | os.PathLike, keys: Iterable[str] | None = None, missing_ok: bool = False) -> Episode:
    """Load an episode file (all datasets, or only ``keys``, skipping absent ones if ``missing_ok``);
    raises ``EpisodeFileError`` naming the file and the problem for foreign, truncated or incomplete files."""
    p = pathlib.Path(path)
    with open_checked(p) as f:
        attrs = {k: _attr(v) for k, v in f.attrs.items()}
        present: list[str] = []
        f.visit(lambda name: present.append(name) if isinstance(f[name], h5py.Dataset) else None)
        missing = [k for k, fld in FIELDS.items() if fld.required and k not in present]
        if missing:
            raise EpisodeFileError(f"{p}: missing dataset(s) {missing}")
        wanted = present if keys is None else list(keys)
        data, names = {}, {}
        for k in wanted:
            if k not in f:
                if missing_ok:
                    continue
                raise EpisodeFileError(f"{p}: no dataset {k!r}")
            try:
                data[k] = f[k][()]
            except OSError as exc:
                raise EpisodeFileError(f"{p}: dataset {k!r} cannot be read ({exc})") from exc
            if "names" in f[k].attrs:
                names[k] = [_attr(n) for n in f[k].attrs["names"]]
    return Episode(p, attrs, data, names)
