"""Schema checks of an open episode file: the one set of rules every dataset tool reads through.

:func:`inspect_file` checks the root attributes and the dtype and shape of every dataset of the file
(metadata), reads every dataset once to check its values (NaN/inf, index ranges, unit quaternions,
time stamps) and keeps the datasets it is asked for. Problems come back as one-line strings that name the dataset
(or attribute) and what was expected; the caller adds the file name. ``load_episode`` raises on the
first problem, ``validate`` lists them all.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass, field

import h5py
import numpy as np

from .schema import FIELDS, INFO_GROUP, OPTIONAL_ROOT_ATTRS, ROOT_ATTRS, shape_text

QUAT_TOLERANCE = 1e-3
REPLAY_KEYS = ("seed", "rng_state", "options", "scene_origin")
#: Datasets whose values :func:`_check_values` checks beyond NaN/inf.
VALUE_CHECKED = ("object/triangles", "object/tetrahedra", "object/initial_quaternion", "steps/wrist_orientation",
                 "object/density", "object/youngs_modulus", "object/poisson_ratio", "steps/time",
                 "steps/terminated", "steps/truncated")


def attr_value(value):
    """An HDF5 attribute as a plain Python value (bytes -> str, numpy scalar -> number)."""
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


@dataclass
class Inspection:
    """What :func:`inspect_file` found: attributes, the datasets read, dims, errors and warnings."""

    attrs: dict
    data: dict[str, np.ndarray] = field(default_factory=dict)
    names: dict[str, list[str]] = field(default_factory=dict)
    dims: dict[str, int] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def _check_attrs(attrs: dict, out: Inspection) -> None:
    for name, (typ, _) in (ROOT_ATTRS | OPTIONAL_ROOT_ATTRS).items():
        if name not in attrs:
            if name in ROOT_ATTRS:
                out.errors.append(f"root attribute {name!r} is missing")
            continue
        v = attrs[name]
        ok = isinstance(v, typ) and not (typ is int and isinstance(v, bool))
        if typ is float:
            ok = isinstance(v, (int, float)) and not isinstance(v, bool) and bool(np.isfinite(v))
        named = typ is str and name in OPTIONAL_ROOT_ATTRS  # an optional text, when present, names something
        ok = ok and (bool(v) or not named)
        if not ok:
            what = f"non-empty {typ.__name__}" if named else typ.__name__
            out.errors.append(f"root attribute {name!r}: expected a {what}, got {v!r}")
    for name in ("config_json", "replay_json", "versions_json"):
        if not isinstance(attrs.get(name), str):
            continue
        try:
            value = json.loads(attrs[name])
        except json.JSONDecodeError as exc:
            out.errors.append(f"root attribute {name!r}: expected JSON ({exc})")
            continue
        if name == "replay_json" and not (isinstance(value, dict) and all(k in value for k in REPLAY_KEYS)):
            out.errors.append(f"root attribute 'replay_json': expected an object with keys {list(REPLAY_KEYS)}")


def _symbols(shape: tuple[str | int, ...], actual: tuple[int, ...]) -> list[tuple[str, int]]:
    """(dimension name, size it implies) for each symbolic entry of a schema shape."""
    out = []
    for d, s in zip(shape, actual):
        if isinstance(d, str):
            out.append((d[:-2], s - 1) if d.endswith("+1") else (d, s))
    return out


def _resolve_dims(shapes: dict[str, tuple[int, ...]], attrs: dict) -> dict[str, int]:
    """Each symbolic dimension takes the size most datasets agree on (T: the ``num_steps`` attribute
    counts as one more vote, so a lone dataset of another length is the one reported)."""
    votes: dict[str, dict[int, int]] = {}
    for key, shape in shapes.items():
        fld = FIELDS[key]
        if len(shape) == len(fld.shape):
            for name, size in _symbols(fld.shape, shape):
                votes.setdefault(name, {}).setdefault(size, 0)
                votes[name][size] += 1
    steps = attrs.get("num_steps")
    if isinstance(steps, int) and not isinstance(steps, bool):
        votes.setdefault("T", {}).setdefault(steps, 0)
        votes["T"][steps] += 1
    return {name: max(counts, key=lambda s: (counts[s], -s)) for name, counts in votes.items()}


def _shape_ok(spec: tuple[str | int, ...], shape: tuple[int, ...], dims: dict[str, int]) -> bool:
    if len(shape) != len(spec):
        return False
    fixed = all(d == s for d, s in zip(spec, shape) if isinstance(d, int))
    return fixed and all(dims.get(name) == size for name, size in _symbols(spec, shape))


def _expected(shape: tuple[str | int, ...], dims: dict[str, int]) -> str:
    sizes = []
    for d in shape:
        if isinstance(d, int):
            sizes.append(d)
        else:
            name = d[:-2] if d.endswith("+1") else d
            if name not in dims:
                return shape_text(shape)
            sizes.append(dims[name] + (1 if d.endswith("+1") else 0))
    concrete = "(" + ", ".join(str(s) for s in sizes) + ("," if len(sizes) == 1 else "") + ")"
    with_dims = ", ".join(f"{n} = {dims[n]}" for n in dict.fromkeys(
        (d[:-2] if d.endswith("+1") else d) for d in shape if isinstance(d, str)))
    return f"{shape_text(shape)} = {concrete}" + (f" ({with_dims})" if with_dims else "")


def _check_layout(f: h5py.File, present: list[str], out: Inspection) -> None:
    """dtype, rank and sizes of every dataset (metadata only); fills ``out.dims``."""
    for key, fld in FIELDS.items():
        if fld.required and key not in present:
            out.errors.append(f"{key}: required dataset is missing (expected {fld.dtype} {shape_text(fld.shape)})")
    shapes = {k: f[k].shape for k in present if k in FIELDS}
    out.dims = dims = _resolve_dims(shapes, out.attrs)
    for key, shape in shapes.items():
        fld = FIELDS[key]
        ds = f[key]
        if ds.dtype != np.dtype(fld.dtype):
            out.errors.append(f"{key}: dtype {ds.dtype}, expected {fld.dtype}")
        if not _shape_ok(fld.shape, shape, dims):
            out.errors.append(f"{key}: shape {shape}, expected {_expected(fld.shape, dims)}")
        units = attr_value(ds.attrs.get("units"))
        if units != fld.units:
            out.errors.append(f"{key}: units attribute {units!r}, expected {fld.units!r}")
    for key in present:
        if key.startswith(INFO_GROUP + "/"):
            shape = f[key].shape
            if len(shape) != 1 or ("T" in dims and shape[0] != dims["T"]):
                out.errors.append(f"{key}: shape {shape}, expected [T] = ({dims.get('T')},)")
        elif key not in FIELDS:
            out.warnings.append(f"{key}: dataset not in the schema (ignored)")


def _read(f: h5py.File, key: str, out: Inspection) -> np.ndarray | None:
    try:
        value = f[key][()]
    except OSError as exc:
        out.errors.append(f"{key}: data cannot be read ({exc})")
        return None
    if value.dtype.kind == "f":
        bad = ~np.isfinite(value)
        if bad.any():
            first = tuple(int(i) for i in np.argwhere(bad)[0])
            out.errors.append(f"{key}: {int(bad.sum())} NaN/inf value(s), first at index {first}; expected finite")
    return value


def _check_values(v: dict[str, np.ndarray], out: Inspection) -> None:
    dims, attrs = out.dims, out.attrs
    n3 = dims.get("N3")
    for key in ("object/triangles", "object/tetrahedra"):
        if key in v and n3 is not None and v[key].size and v[key].ndim == 2:
            lo, hi = int(v[key].min()), int(v[key].max())
            if lo < 0 or hi >= n3:
                out.errors.append(f"{key}: node indices span [{lo}, {hi}], expected [0, {n3 - 1}]")
    for key in ("object/initial_quaternion", "steps/wrist_orientation"):
        if key in v and v[key].size and v[key].shape[-1:] == (4,) and np.all(np.isfinite(v[key])):
            err = float(np.max(np.abs(np.linalg.norm(v[key], axis=-1) - 1.0)))
            if err > QUAT_TOLERANCE:
                out.errors.append(f"{key}: quaternions off unit norm by up to {err:.3g}, expected unit norm "
                                  f"(tolerance {QUAT_TOLERANCE:g})")
    for key, low, high in (("object/density", 0, np.inf), ("object/youngs_modulus", 0, np.inf),
                           ("object/poisson_ratio", -1e-12, 0.5)):
        if key in v and v[key].shape == () and not (low < float(v[key]) < high):
            out.errors.append(f"{key}: {float(v[key])!r}, expected a value in ({low}, {high})")
    t = v.get("steps/time")
    if t is not None and t.ndim == 1 and t.size:
        dt = attrs.get("dt")
        if np.any(np.diff(t) <= 0):
            out.errors.append("steps/time: expected strictly increasing times")
        elif isinstance(dt, float) and not np.allclose(t, np.arange(1, len(t) + 1) * dt, rtol=1e-9, atol=1e-12):
            out.errors.append(f"steps/time: expected (k+1) * dt with dt = {dt} s")
    if "T" in dims:
        if dims["T"] < 1:
            out.errors.append("steps: expected at least one step, got T = 0")
        steps = attrs.get("num_steps")
        if isinstance(steps, int) and steps != dims["T"]:
            out.errors.append(f"root attribute 'num_steps' = {steps}, but the datasets have T = {dims['T']}")
        for flag in ("terminated", "truncated"):
            key = f"steps/{flag}"
            if key in v and v[key].ndim == 1 and v[key].size and isinstance(attrs.get(flag), bool) \
                    and bool(v[key][-1]) != attrs[flag]:
                out.errors.append(f"root attribute {flag!r} = {attrs[flag]}, but {key}[-1] = {bool(v[key][-1])}")


def inspect_file(f: h5py.File, keys: Iterable[str] | None = None, missing_ok: bool = False) -> Inspection:
    """Check an open episode file and return its attributes and the datasets ``keys`` (default: all).

    The whole file is checked whatever is asked for (a file is valid or not for every tool): the
    dtype, shape and units of every dataset and the values of every dataset (read one at a time;
    only the requested ones are kept). A requested key that is absent is an error unless
    ``missing_ok``.
    """
    out = Inspection({k: attr_value(v) for k, v in f.attrs.items()})
    _check_attrs(out.attrs, out)
    present: list[str] = []
    f.visit(lambda name: present.append(name) if isinstance(f[name], h5py.Dataset) else None)
    _check_layout(f, present, out)
    wanted = set(present if keys is None else keys)
    checked = {}                         # the small datasets the value checks need, whether wanted or not
    for key in present:
        value = _read(f, key, out)
        if value is None:
            continue
        if key in wanted:
            out.data[key] = value
            if "names" in f[key].attrs:
                out.names[key] = [attr_value(n) for n in f[key].attrs["names"]]
        if key in VALUE_CHECKED:
            checked[key] = value
    for key in sorted(wanted - set(present)):
        if not missing_ok and (key not in FIELDS or not FIELDS[key].required):  # required: reported above
            out.errors.append(f"{key}: dataset is missing")
    _check_values(checked, out)
    return out
