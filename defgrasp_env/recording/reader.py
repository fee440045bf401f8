"""Reading episode files through the schema checks: every dataset tool (validate, plot, replay,
to-lerobot) reads here, and a malformed file gives one line naming the file, the dataset and what
was expected (:class:`EpisodeFileError`). Files are opened read-only: nothing is ever written."""

from __future__ import annotations

import json
import os
import pathlib
from collections.abc import Iterable
from dataclasses import dataclass, field

import h5py
import numpy as np

from .checks import Inspection, attr_value, inspect_file
from .schema import FORMAT, SCHEMA_VERSION, SUFFIX


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
    fmt = attr_value(f.attrs.get("format"))
    if fmt != FORMAT:
        f.close()
        raise EpisodeFileError(f"{p}: not a defgrasp episode (root attribute 'format' is {fmt!r}, "
                               f"expected {FORMAT!r})")
    version = attr_value(f.attrs.get("schema_version"))
    if not isinstance(version, int) or isinstance(version, bool) or not 1 <= version <= SCHEMA_VERSION:
        f.close()
        raise EpisodeFileError(f"{p}: unsupported schema_version {version!r} (this library reads 1..{SCHEMA_VERSION})")
    return f


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
        """The recorded ``PickupConfig``; ``EpisodeFileError`` naming the file if it is not valid
        here (e.g. its mesh file does not exist on this machine)."""
        from .config_io import config_from_json
        try:
            return config_from_json(self.attrs["config_json"])
        except (ValueError, TypeError) as exc:
            raise EpisodeFileError(f"{self.path}: root attribute 'config_json': {exc}") from exc

    def feature_points(self) -> np.ndarray:
        """Object feature point P_feature (mean node position, paper eq. 5) per step [T,3], m."""
        return self["steps/node_positions"].astype(np.float64).mean(axis=1)


def problem_line(path: pathlib.Path, problems: list[str]) -> str:
    """One line: the file, its first problem, and how many more ``validate`` would list."""
    more = f" (+{len(problems) - 1} more problem(s): defgrasp-dataset validate {path})" if len(problems) > 1 else ""
    return f"{path}: {problems[0]}{more}"


def read_checked(path: str | os.PathLike, keys: Iterable[str] | None = None,
                 missing_ok: bool = False) -> Inspection:
    """Open ``path`` read-only, check it against the schema and read ``keys`` (default: all).

    Raises ``EpisodeFileError`` (or ``FileNotFoundError``/``IsADirectoryError``) only when the file
    cannot be opened as a defgrasp episode; schema problems come back in ``Inspection.errors``.
    """
    with open_checked(path) as f:
        return inspect_file(f, keys, missing_ok)


def load_episode(path: str | os.PathLike, keys: Iterable[str] | None = None, missing_ok: bool = False) -> Episode:
    """Load an episode file (all datasets, or only ``keys``, skipping absent ones if ``missing_ok``).

    The whole file is checked first, whatever ``keys`` asks for (root attributes; dtype, shape,
    units and values of every dataset: see :mod:`.checks`); any problem raises ``EpisodeFileError``
    with one line naming the file, the dataset and what was expected.
    """
    p = pathlib.Path(path)
    found = read_checked(p, keys, missing_ok)
    if found.errors:
        raise EpisodeFileError(problem_line(p, found.errors))
    return Episode(p, found.attrs, found.data, found.names)
