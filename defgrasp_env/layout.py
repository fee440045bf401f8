"""The action and observation layout of ``DeformablePickup-v0``, defined once.

Every consumer imports it: the env (its spaces), the jaw decoding of the scene, the scripted expert,
teleoperation (absolute actions), the recorders (dataset column names) and the LeRobot export.
Nobody slices ``state[:, 9:33]`` or hard-codes ``[10]`` by hand.

A flat vector is a :class:`VectorLayout`: named :class:`Field` blocks in order, each with its
component names, unit and bounds (world frame, y up, SI units, quaternions xyzw):

``AGENT_POS`` [10] (observation ``agent_pos``)
    ``wrist_position`` (3, m) | ``wrist_quat`` (4, xyzw) | ``jaw_gap`` (1, m, in
    [``JAW_GAP_MIN``, ``JAW_GAP_MAX``]) | ``tip_normal_force`` (2, N, left and right pad, >= 0).
``ENV_STATE`` [33] (observation ``environment_state``, ``obs_type="state"``)
    ``feature_position`` (3, m: the mean node position, paper eq. 5) | ``feature_velocity``
    (3, m/s) | ``goal`` (3, m) | ``keypoints`` (``NUM_KEYPOINTS`` x 3 = 24, m: fixed surface nodes).
``DELTA_ACTION`` [7] (``action_mode="delta"``, every entry in [-1, 1])
    ``linear_velocity`` (3, x ``max_linear_speed`` m/s) | ``angular_velocity`` (3, axis-angle
    rate x ``max_angular_speed`` rad/s) | ``jaw`` (1: -1 fully open ... +1 fully closed,
    :func:`jaw_command_to_gap` / :func:`gap_to_jaw_command`).
``ABSOLUTE_ACTION`` [8] (``action_mode="absolute"``, used by teleoperation)
    ``position`` (3, m, target flange position) | ``orientation`` (4, xyzw) | ``gap`` (1, m, in
    [0, ``JAW_GAP_MAX``]; the jaw stops at ``JAW_GAP_MIN``).
``TOPDOWN_ACTION`` [5] (``action_mode="topdown"``, top-down grasping)
    ``linear_velocity`` (3, x ``max_linear_speed`` m/s, in [-1, 1], as ``DELTA_ACTION``) | ``yaw``
    (1, rad, in [-pi, pi]: the target orientation, flange pointing down turned by ``yaw`` about
    world +y; -pi and pi are the same target, which a learned regression near them would
    average) | ``jaw`` (1, in [-1, 1], as ``DELTA_ACTION``).

The jaw range is the modelled 2F-85's: ``JAW_GAP_MAX`` = 85 mm (its stroke) open, ``JAW_GAP_MIN``
= 1.5 mm closed (``defgrasp_env.gripper.linkage``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .gripper import GAP_MAX, GAP_MIN

__all__ = [
    "ABSOLUTE_ACTION", "ACTION_LAYOUTS", "AGENT_POS", "DELTA_ACTION", "ENV_STATE", "Field", "JAW_GAP_MAX",
    "JAW_GAP_MIN", "NUM_KEYPOINTS", "TOPDOWN_ACTION", "VectorLayout", "gap_to_jaw_command", "jaw_command_to_gap",
]

#: Jaw gap range (m) between the pad inner faces: closed ... open (the 2F-85's 85 mm stroke).
JAW_GAP_MIN = GAP_MIN
JAW_GAP_MAX = GAP_MAX
#: Number of object surface keypoints in ``environment_state``.
NUM_KEYPOINTS = 8

_INF = float("inf")


@dataclass(frozen=True)
class Field:
    """One named block of a flat vector.

    Attributes:
        name: the block's name (``"jaw_gap"``).
        components: one name per entry, as stored in dataset files (``("jaw_gap",)``).
        unit: unit of the entries (``"m"``, ``"N"``, ``"1"`` for unitless).
        low, high: bounds of every entry (a number, or one per component); +-inf when unbounded.
    """

    name: str
    components: tuple[str, ...]
    unit: str
    low: float | tuple[float, ...] = -_INF
    high: float | tuple[float, ...] = _INF

    @property
    def size(self) -> int:
        return len(self.components)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) float64 arrays of shape [size]."""
        return (np.broadcast_to(np.asarray(self.low, np.float64), (self.size,)).copy(),
                np.broadcast_to(np.asarray(self.high, np.float64), (self.size,)).copy())


@dataclass(frozen=True)
class VectorLayout:
    """Named fields of a flat float vector, in order; see the module docstring for the four layouts."""

    name: str
    fields: tuple[Field, ...]

    @property
    def size(self) -> int:
        """Length of the vector."""
        return sum(f.size for f in self.fields)

    @property
    def names(self) -> tuple[str, ...]:
        """One name per entry (the dataset column names)."""
        return tuple(c for f in self.fields for c in f.components)

    def field(self, name: str) -> Field:
        for f in self.fields:
            if f.name == name:
                return f
        raise KeyError(f"{self.name} has no field {name!r}; fields: {[f.name for f in self.fields]}")

    def slice(self, name: str) -> slice:
        """Slice of field ``name`` along the last axis."""
        start = 0
        for f in self.fields:
            if f.name == name:
                return slice(start, start + f.size)
            start += f.size
        raise KeyError(f"{self.name} has no field {name!r}; fields: {[f.name for f in self.fields]}")

    def get(self, vector, name: str) -> np.ndarray:
        """Field ``name`` of ``vector`` [..., size] (a view): shape [..., field size]."""
        v = np.asarray(vector)
        if v.shape[-1:] != (self.size,):
            raise ValueError(f"{self.name} must have {self.size} entries in its last axis, got shape {v.shape}")
        return v[..., self.slice(name)]

    def columns(self, field_names) -> np.ndarray:
        """Indices (int [n]) of the entries of the fields ``field_names`` (a non-empty sequence of
        distinct field names of this layout), in the layout's order whatever the order given:
        ``vector[..., layout.columns(names)]`` keeps those fields."""
        if isinstance(field_names, str):
            raise ValueError(f"{self.name} fields must be a list of field names, got the string {field_names!r}")
        names = list(field_names)
        known = [f.name for f in self.fields]
        unknown = [n for n in names if n not in known]
        if not names or unknown or len(set(names)) != len(names):
            raise ValueError(f"{self.name} fields must be a non-empty list of distinct names out of {known}, "
                             f"got {names}" + (f" (unknown: {unknown})" if unknown else ""))
        return np.concatenate([np.arange(self.size)[self.slice(f.name)] for f in self.fields if f.name in names])

    def pack(self, **values) -> np.ndarray:
        """float64 vector(s) [..., size] from one array per field (all fields, leading axes broadcast)."""
        missing = [f.name for f in self.fields if f.name not in values]
        unknown = sorted(set(values) - {f.name for f in self.fields})
        if missing or unknown:
            raise ValueError(f"{self.name}.pack needs exactly the fields {[f.name for f in self.fields]}; "
                             f"missing {missing}, unknown {unknown}")
        parts = [np.asarray(values[f.name], np.float64) for f in self.fields]
        lead = np.broadcast_shapes(*(p.shape[:-1] for p in parts))
        for f, p in zip(self.fields, parts):
            if p.shape[-1:] != (f.size,):
                raise ValueError(f"{self.name} field {f.name!r} must have {f.size} entries, got shape {p.shape}")
        return np.concatenate([np.broadcast_to(p, lead + p.shape[-1:]) for p in parts], axis=-1)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) float64 arrays [size] of the whole vector."""
        lows, highs = zip(*(f.bounds() for f in self.fields))
        return np.concatenate(lows), np.concatenate(highs)


def _xyz(prefix: str, axes: str = "xyz") -> tuple[str, ...]:
    return tuple(f"{prefix}{a}" for a in axes)


AGENT_POS = VectorLayout("agent_pos", (
    Field("wrist_position", _xyz("wrist_"), "m"),
    Field("wrist_quat", _xyz("wrist_q", "xyzw"), "1", -1.0, 1.0),
    Field("jaw_gap", ("jaw_gap",), "m", JAW_GAP_MIN, JAW_GAP_MAX),
    Field("tip_normal_force", ("left_tip_normal_force", "right_tip_normal_force"), "N", 0.0, _INF),
))
ENV_STATE = VectorLayout("environment_state", (
    Field("feature_position", _xyz("feature_"), "m"),
    Field("feature_velocity", _xyz("feature_v"), "m/s"),
    Field("goal", _xyz("goal_"), "m"),
    Field("keypoints", tuple(f"keypoint{k}_{a}" for k in range(NUM_KEYPOINTS) for a in "xyz"), "m"),
))
DELTA_ACTION = VectorLayout("delta action", (
    Field("linear_velocity", ("vx", "vy", "vz"), "max_linear_speed", -1.0, 1.0),
    Field("angular_velocity", ("wx", "wy", "wz"), "max_angular_speed", -1.0, 1.0),
    Field("jaw", ("jaw",), "1 (-1 open, +1 closed)", -1.0, 1.0),
))
ABSOLUTE_ACTION = VectorLayout("absolute action", (
    Field("position", ("x", "y", "z"), "m", (-0.4, 0.0, -0.4), (0.4, 1.0, 0.4)),
    Field("orientation", ("qx", "qy", "qz", "qw"), "1", -1.0, 1.0),
    Field("gap", ("gap",), "m", 0.0, JAW_GAP_MAX),
))
TOPDOWN_ACTION = VectorLayout("top-down action", (
    Field("linear_velocity", ("vx", "vy", "vz"), "max_linear_speed", -1.0, 1.0),
    Field("yaw", ("yaw",), "rad", -np.pi, np.pi),
    Field("jaw", ("jaw",), "1 (-1 open, +1 closed)", -1.0, 1.0),
))
#: The action layout of each ``action_mode``.
ACTION_LAYOUTS = {"delta": DELTA_ACTION, "absolute": ABSOLUTE_ACTION, "topdown": TOPDOWN_ACTION}


def jaw_command_to_gap(command):
    """Jaw gap (m) targeted by delta-mode jaw commands in [-1, 1]: -1 -> ``JAW_GAP_MAX`` (open),
    +1 -> ``JAW_GAP_MIN`` (closed), linear in between. Any shape; float64."""
    return JAW_GAP_MAX + (JAW_GAP_MIN - JAW_GAP_MAX) * (np.asarray(command, np.float64) + 1.0) / 2.0


def gap_to_jaw_command(gap):
    """Delta-mode jaw command in [-1, 1] whose target is ``gap`` (m, clipped to the jaw range);
    inverse of :func:`jaw_command_to_gap`. Any shape; float64."""
    g = np.clip(np.asarray(gap, np.float64), JAW_GAP_MIN, JAW_GAP_MAX)
    return 2.0 * (JAW_GAP_MAX - g) / (JAW_GAP_MAX - JAW_GAP_MIN) - 1.0
