"""Check episode files against the schema (the checks of :mod:`.checks`, every dataset read) and
report every problem, one line each naming the file and the dataset."""

from __future__ import annotations

import json
import os
import pathlib
from dataclasses import dataclass, field

from .reader import EpisodeFileError, episode_paths, read_checked


@dataclass
class FileReport:
    """Findings for one file: errors make it invalid, warnings do not."""

    path: pathlib.Path
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    num_steps: int | None = None

    @property
    def ok(self) -> bool:
        return not self.errors


@dataclass
class ValidationReport:
    files: list[FileReport]

    @property
    def ok(self) -> bool:
        return bool(self.files) and all(f.ok for f in self.files)

    def text(self) -> str:
        """One line per valid file, per error and per warning, each naming the file."""
        lines = []
        for f in self.files:
            if f.ok:
                steps = f"{f.num_steps} steps" if f.num_steps is not None else "?"
                lines.append(f"OK       {f.path} ({steps})")
            lines += [f"INVALID  {f.path}: {e}" for e in f.errors]
            lines += [f"WARNING  {f.path}: {w}" for w in f.warnings]
        if not self.files:
            lines.append("no episode files found")
        bad = sum(not f.ok for f in self.files)
        lines.append(f"{len(self.files) - bad}/{len(self.files)} file(s) valid")
        return "\n".join(lines)


def _check_config(text: str, rep: FileReport) -> None:
    """``config_json`` must describe a valid ``PickupConfig``; a mesh file that does not exist on
    this machine is a warning (the file is fine, only replay needs the mesh)."""
    from .config_io import config_from_json

    try:
        config_from_json(text)
        return
    except (ValueError, TypeError) as exc:
        error = f"root attribute 'config_json': expected a valid PickupConfig ({exc})"
    data = json.loads(text)
    obj = data.get("object") if isinstance(data, dict) else None
    if isinstance(obj, str) and pathlib.Path(obj).suffix and not pathlib.Path(obj).exists():
        try:
            config_from_json(json.dumps({**data, "object": "cuboid"}))
        except (ValueError, TypeError):
            pass
        else:
            rep.warnings.append(f"root attribute 'config_json': object mesh {obj!r} not found here "
                                "(replay needs it)")
            return
    rep.errors.append(error)


def validate_episode(path: str | os.PathLike) -> FileReport:
    """Validate one episode file; never raises for a bad file (the report says what is wrong)."""
    rep = FileReport(pathlib.Path(path))
    try:
        found = read_checked(path)
    except (EpisodeFileError, OSError) as exc:
        rep.errors.append(str(exc).replace(f"{rep.path}: ", "", 1))
        return rep
    rep.errors += found.errors
    rep.warnings += found.warnings
    if isinstance(found.attrs.get("config_json"), str) and not any("'config_json'" in e for e in found.errors):
        _check_config(found.attrs["config_json"], rep)
    rep.num_steps = found.dims.get("T")
    return rep


def validate_path(*paths: str | os.PathLike) -> ValidationReport:
    """Validate episode files and every episode file of directories, in the order given."""
    files = []
    for path in paths:
        try:
            files += [validate_episode(p) for p in episode_paths(path)]
        except OSError as exc:  # missing path: reported like an invalid file, the others still checked
            files.append(FileReport(pathlib.Path(path), [str(exc).replace(f"{pathlib.Path(path)}: ", "", 1)]))
    return ValidationReport(files)
