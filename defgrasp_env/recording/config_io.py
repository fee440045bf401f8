"""Exact JSON round trip of the env configuration (frozen dataclasses, nested), and library versions."""

from __future__ import annotations

import dataclasses
import json
import platform
from typing import Any

from ..envs.config import PickupConfig


def _plain(value: Any) -> Any:
    """JSON-ready copy: dataclasses -> dicts, tuples -> lists, numpy scalars -> Python numbers."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):  # numpy scalar or array
        return _plain(value.tolist())
    return value


def config_to_json(config: PickupConfig) -> str:
    """The config as JSON; floats keep every bit (``repr`` round trip)."""
    return json.dumps(_plain(config), sort_keys=True)


def _tuples(value: Any) -> Any:
    return tuple(_tuples(v) for v in value) if isinstance(value, list) else value


def _build(cls: type, data: dict) -> Any:
    if not isinstance(data, dict):
        raise ValueError(f"config_json: {cls.__name__} must be a JSON object, got {type(data).__name__}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ValueError(f"config_json: unknown {cls.__name__} field(s) {unknown}; accepted {sorted(fields)}")
    kwargs = {}
    for name, value in data.items():
        f = fields[name]
        default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
        if dataclasses.is_dataclass(default):
            kwargs[name] = _build(type(default), value)
        else:
            kwargs[name] = _tuples(value)
    return cls(**kwargs)


#: PickupConfig fields whose default changed after files were recorded without them: a file that
#: lacks one was recorded with this value (``edge_contact`` was off by default until 2026-11-26),
#: which its replay must use to be exact.
RECORDED_BEFORE_DEFAULT = {"edge_contact": False}


def config_from_json(text: str) -> PickupConfig:
    """Inverse of :func:`config_to_json` (validated by the dataclasses themselves); a field of
    ``RECORDED_BEFORE_DEFAULT`` that the text lacks takes the value it was recorded with."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"config_json is not valid JSON: {exc}") from exc
    if isinstance(data, dict):
        data = {**RECORDED_BEFORE_DEFAULT, **data}
    return _build(PickupConfig, data)


def library_versions() -> dict[str, str]:
    """Versions of what decides the simulation's numbers (stored with every episode)."""
    import gymnasium
    import h5py
    import numpy
    import warp

    from .. import __version__

    return {"defgrasp": __version__, "python": platform.python_version(), "numpy": numpy.__version__,
            "warp": warp.config.version, "gymnasium": gymnasium.__version__, "h5py": h5py.__version__,
            "platform": platform.platform()}
