"""Crash-safe writing of one episode file: temp file + fsync + atomic ``os.replace`` + directory fsync.

A reader never sees a partial episode: the final name appears only once every byte of the file is on
disk, and an existing file is never opened for writing. A process killed at any moment leaves at most
a hidden ``.<name>.tmp-<pid>`` file, which readers ignore and :func:`remove_stale_temps` cleans up.
"""

from __future__ import annotations

import datetime
import os
import pathlib
import re
from collections.abc import Mapping

import h5py
import numpy as np

from .schema import FIELDS

_TEMP = re.compile(r"^\.(?P<name>.+)\.tmp-(?P<pid>\d+)$")


def temp_path(path: pathlib.Path) -> pathlib.Path:
    return path.with_name(f".{path.name}.tmp-{os.getpid()}")


def check_writable_directory(directory: str | os.PathLike) -> pathlib.Path:
    """Create ``directory`` if needed and prove it is writable; raise ``PermissionError``/
    ``NotADirectoryError`` naming it otherwise."""
    d = pathlib.Path(directory)
    if d.exists() and not d.is_dir():
        raise NotADirectoryError(f"{d}: recording directory is not a directory")
    try:
        d.mkdir(parents=True, exist_ok=True)
        probe = d / f".write-probe-{os.getpid()}"
        with open(probe, "wb"):
            pass
        probe.unlink()
    except OSError as exc:
        raise PermissionError(f"{d}: recording directory is not writable ({exc.strerror or exc})") from exc
    return d


def _fsync_directory(directory: pathlib.Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # e.g. Windows: directories cannot be opened; os.replace is still atomic there
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _dataset_attrs(path: str, names: Mapping[str, list[str]]) -> dict:
    field = FIELDS.get(path)
    if field is not None:
        attrs = {"units": field.units, "description": field.description}
    else:  # info/<key>
        attrs = {"units": "-", "description": f"info[{path.split('/', 1)[1]!r}] of each step"}
    if path in names:
        attrs["names"] = np.array(names[path], dtype=h5py.string_dtype())
    return attrs


def write_episode(path: str | os.PathLike, datasets: Mapping[str, np.ndarray], attrs: Mapping,
                  names: Mapping[str, list[str]] | None = None, compression: str | None = None,
                  overwrite: bool = False) -> pathlib.Path:
    """Write one episode atomically to ``path`` and return it.

    Args:
        datasets: "group/name" -> array (schema paths and ``info/<key>``).
        attrs: root attributes (str, int, float, bool).
        names: column names of "mixed" datasets, stored as their ``names`` attribute.
        compression: h5py compression of the large per-step datasets (None, "gzip", "lzf").
        overwrite: replace an existing file (atomically); default: refuse with ``FileExistsError``.
    """
    path = pathlib.Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path}: episode file exists already; it is left untouched")
    tmp = temp_path(path)
    try:
        with h5py.File(tmp, "w") as f:  # default libver: readable by old HDF5 libraries too
            for key, value in attrs.items():
                f.attrs[key] = value
            f.attrs["created_utc"] = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
            for key, value in datasets.items():
                big = value.ndim >= 2 and value.size > 4096
                ds = f.create_dataset(key, data=value, compression=compression if big else None)
                for a, v in _dataset_attrs(key, names or {}).items():
                    ds.attrs[a] = v
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        if overwrite:
            os.replace(tmp, path)
        else:
            _publish_no_clobber(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_directory(path.parent)
    return path


def _publish_no_clobber(tmp: pathlib.Path, path: pathlib.Path) -> None:
    """Give ``tmp`` the name ``path`` atomically, failing if ``path`` exists (hard link, then unlink)."""
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise FileExistsError(f"{path}: episode file appeared while writing; it is left untouched") from None
    except OSError:  # file system without hard links: check, then atomic replace
        if path.exists():
            raise FileExistsError(f"{path}: episode file exists already; it is left untouched") from None
        os.replace(tmp, path)
        return
    tmp.unlink()


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temps(directory: str | os.PathLike) -> list[pathlib.Path]:
    """Delete temp files left by writers that no longer run (killed mid-write); return them."""
    removed = []
    for p in pathlib.Path(directory).iterdir():
        m = _TEMP.match(p.name)
        if m and int(m["pid"]) != os.getpid() and not _pid_alive(int(m["pid"])):
            p.unlink(missing_ok=True)
            removed.append(p)
    return removed


def is_temp(path: pathlib.Path) -> bool:
    return bool(_TEMP.match(path.name))


__all__ = ["write_episode", "check_writable_directory", "remove_stale_temps", "is_temp"]
