"""Check episode files against the schema: presence, dtypes, shapes, units, NaN/inf, index ranges."""

from __future__ import annotations

import json
import os
import pathlib
from dataclasses import dataclass, field

import h5py
import numpy as np

from .reader import EpisodeFileError, _attr, episode_paths, open_checked
from .schema import FIELDS, INFO_GROUP, ROOT_ATTRS

QUAT_TOLERANCE = 1e-3
REPLAY_KEYS = ("seed", "rng_state", "options", "scene_origin")


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
        lines = []
        for f in self.files:
            status = "OK" if f.ok else "INVALID"
            steps = f"{f.num_steps} steps" if f.num_steps is not None else "?"
            lines.append(f"{status:8s} {f.path} ({steps}, {len(f.errors)} error(s), {len(f.warnings)} warning(s))")
            lines += [f"    error: {e}" for e in f.errors]
            lines += [f"    warning: {w}" for w in f.warnings]
        if not self.files:
            lines.append("no episode files found")
        bad = sum(not f.ok for f in self.files)
        lines.append(f"{len(self.files) - bad}/{len(self.files)} file(s) valid")
        return "\n".join(lines)


def _check_attrs(f: h5py.File, rep: FileReport) -> dict:
    attrs = {k: _attr(v) for k, v in f.attrs.items()}
    for name, (typ, _) in ROOT_ATTRS.items():
        if name not in attrs:
            rep.errors.append(f"root attribute {name!r} is missing")
            continue
        v = attrs[name]
        ok = isinstance(v, typ) and not (typ is int and isinstance(v, bool))
        if typ is float:
            ok = isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)
        if not ok:
            rep.errors.append(f"root attribute {name!r} must be {typ.__name__}, got {v!r}")
    for name in ("config_json", "replay_json", "versions_json"):
        if isinstance(attrs.get(name), str):
            try:
                value = json.loads(attrs[name])
            except json.JSONDecodeError as exc:
                rep.errors.append(f"root attribute {name!r} is not valid JSON ({exc})")
                continue
            if name == "replay_json" and not (isinstance(value, dict) and all(k in value for k in REPLAY_KEYS)):
                rep.errors.append(f"replay_json must be an object with keys {list(REPLAY_KEYS)}")
    if isinstance(attrs.get("config_json"), str):
        from .config_io import config_from_json
        try:
            config_from_json(attrs["config_json"])
        except (ValueError, TypeError) as exc:
            rep.errors.append(f"config_json does not describe a valid PickupConfig ({exc})")
    return attrs


def _resolve_dims(seen: list[tuple[str, str, int]], rep: FileReport) -> dict[str, int]:
    """Each symbolic dimension takes the size most datasets agree on; the others are reported."""
    votes: dict[str, dict[int, int]] = {}
    for _, name, size in seen:
        votes.setdefault(name, {}).setdefault(size, 0)
        votes[name][size] += 1
    dims = {name: max(counts, key=lambda s: (counts[s], -s)) for name, counts in votes.items()}
    for key, name, size in seen:
        if size != dims[name]:
            rep.errors.append(f"{key}: dimension {name} is {size} here but {dims[name]} in the other datasets")
    return dims


def _check_dataset(key: str, ds: h5py.Dataset, seen: list, rep: FileReport) -> np.ndarray | None:
    fld = FIELDS[key]
    if ds.dtype != np.dtype(fld.dtype):
        rep.errors.append(f"{key}: dtype {ds.dtype} != {fld.dtype}")
    if len(ds.shape) != len(fld.shape):
        rep.errors.append(f"{key}: shape {ds.shape} does not match {fld.shape}")
        return None
    for d, s in zip(fld.shape, ds.shape):
        if isinstance(d, int):
            if d != s:
                rep.errors.append(f"{key}: shape {ds.shape} does not match {fld.shape}")
        elif d.endswith("+1"):
            seen.append((key, d[:-2], s - 1))
        else:
            seen.append((key, d, s))
    units = _attr(ds.attrs.get("units"))
    if units != fld.units:
        rep.errors.append(f"{key}: units attribute {units!r} != {fld.units!r}")
    try:
        value = ds[()]
    except OSError as exc:
        rep.errors.append(f"{key}: data cannot be read ({exc})")
        return None
    if value.dtype.kind == "f":
        bad = ~np.isfinite(value)
        if bad.any():
            first = tuple(int(i) for i in np.argwhere(bad)[0])
            rep.errors.append(f"{key}: {int(bad.sum())} NaN/inf value(s), first at index {first}")
    return value


def _check_values(v: dict, dims: dict, attrs: dict, rep: FileReport) -> None:
    n3 = dims.get("N3")
    for key in ("object/triangles", "object/tetrahedra"):
        if v.get(key) is not None and n3 is not None and v[key].size:
            lo, hi = int(v[key].min()), int(v[key].max())
            if lo < 0 or hi >= n3:
                rep.errors.append(f"{key}: node indices span [{lo}, {hi}], must lie in [0, {n3 - 1}]")
    for key in ("object/initial_quaternion", "steps/wrist_orientation"):
        if v.get(key) is not None and v[key].size and np.all(np.isfinite(v[key])):
            err = float(np.max(np.abs(np.linalg.norm(v[key], axis=-1) - 1.0)))
            if err > QUAT_TOLERANCE:
                rep.errors.append(f"{key}: quaternions must have unit norm (off by up to {err:.3g})")
    for key, low, high in (("object/density", 0, np.inf), ("object/youngs_modulus", 0, np.inf),
                           ("object/poisson_ratio", -1e-12, 0.5)):
        if v.get(key) is not None and not (low < float(v[key]) < high):
            rep.errors.append(f"{key}: {float(v[key])!r} outside ({low}, {high})")
    t = v.get("steps/time")
    if t is not None and t.size:
        if np.any(np.diff(t) <= 0):
            rep.errors.append("steps/time must be strictly increasing")
        dt = attrs.get("dt")
        if isinstance(dt, float) and not np.allclose(t, np.arange(1, len(t) + 1) * dt, rtol=1e-9, atol=1e-12):
            rep.errors.append(f"steps/time must be (k+1) * dt with dt = {dt} s")
    if "T" in dims:
        if dims["T"] < 1:
            rep.errors.append("an episode must have at least one step")
        if isinstance(attrs.get("num_steps"), int) and attrs["num_steps"] != dims["T"]:
            rep.errors.append(f"root attribute num_steps = {attrs['num_steps']} but datasets have T = {dims['T']}")
        for flag in ("terminated", "truncated"):
            key = f"steps/{flag}"
            if v.get(key) is not None and v[key].size and isinstance(attrs.get(flag), bool) \
                    and bool(v[key][-1]) != attrs[flag]:
                rep.errors.append(f"root attribute {flag} = {attrs[flag]} but {key}[-1] = {bool(v[key][-1])}")


def validate_episode(path: str | os.PathLike) -> FileReport:
    """Validate one episode file; never raises for a bad file (the report says what is wrong)."""
    rep = FileReport(pathlib.Path(path))
    try:
        f = open_checked(path)
    except (EpisodeFileError, OSError) as exc:
        rep.errors.append(str(exc).replace(f"{rep.path}: ", "", 1))
        return rep
    with f:
        attrs = _check_attrs(f, rep)
        present: list[str] = []
        f.visit(lambda name: present.append(name) if isinstance(f[name], h5py.Dataset) else None)
        seen: list[tuple[str, str, int]] = []
        values: dict[str, np.ndarray | None] = {}
        for key, fld in FIELDS.items():
            if key in present:
                values[key] = _check_dataset(key, f[key], seen, rep)
            elif fld.required:
                rep.errors.append(f"{key}: required dataset is missing")
        dims = _resolve_dims(seen, rep)
        for key in present:
            if key.startswith(INFO_GROUP + "/"):
                shape = f[key].shape
                if len(shape) != 1 or ("T" in dims and shape[0] != dims["T"]):
                    rep.errors.append(f"{key}: shape {shape} must be (T,) = ({dims.get('T')},)")
                elif f[key].dtype.kind == "f" and not np.all(np.isfinite(f[key][()])):
                    rep.errors.append(f"{key}: contains NaN/inf")
            elif key not in FIELDS:
                rep.warnings.append(f"{key}: dataset not in the schema")
        _check_values(values, dims, attrs, rep)
        rep.num_steps = dims.get("T")
    return rep


def validate_path(path: str | os.PathLike) -> ValidationReport:
    """Validate an episode file or every episode file of a directory."""
    return ValidationReport([validate_episode(p) for p in episode_paths(path)])
