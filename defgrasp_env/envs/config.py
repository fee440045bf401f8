"""Validated configuration of the DeformablePickup task (frozen dataclass: no mutable defaults)."""

from __future__ import annotations

import functools
import math
import numbers
import pathlib
from collections.abc import Sequence
from dataclasses import dataclass, field

from ..gripper import GripperConfig
from ..layout import ACTION_LAYOUTS
from ..render.camera import Camera
from ..sim.materials import Material, check_range
from ..sim.meshing import OBJECT_SHAPES
from ..sim.meshing.from_surface import load_surface
from ..sim.model import ContactParams
from ..sim.solver import SolverConfig
from ..wrist.force_limit import DEFAULT_WRIST_FORCE_LIMIT

OBS_TYPES = ("state", "pixels_agent_pos", "pixels")
ACTION_MODES = tuple(ACTION_LAYOUTS)
RANDOM_OBJECT = "random"


def _check_choice(name: str, value, choices: Sequence[str]) -> str:
    if value not in choices:
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")
    return value


@functools.lru_cache(maxsize=32)
def _surface_problem(path: str, mtime_ns: int, size: int) -> str | None:
    """Why the surface file at ``path`` cannot be meshed (None: it can); cached per file version."""
    try:
        load_surface(path)
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types for unreadable files; all are reported
        return f"{type(exc).__name__}: {exc}"
    return None


def check_object(name: str) -> str:
    """``name`` if it is a registered shape, ``"random"``, or an existing watertight surface mesh
    file; else ``ValueError`` listing the valid names (a mesh path must exist) or naming the file."""
    if not isinstance(name, str):
        raise TypeError(f"object must be a str (one of {sorted(OBJECT_SHAPES)}, {RANDOM_OBJECT!r} or a mesh path), "
                        f"got {type(name).__name__}")
    if name in OBJECT_SHAPES or name == RANDOM_OBJECT:
        return name
    path = pathlib.Path(name)
    if not path.is_file():
        raise ValueError(f"object must be one of {sorted(OBJECT_SHAPES)}, {RANDOM_OBJECT!r}, or the path of an "
                         f"existing watertight surface mesh file (STL, OBJ, PLY, ...); got {name!r}, which is "
                         "neither a known name nor an existing file")
    stat = path.stat()
    problem = _surface_problem(str(path.resolve()), stat.st_mtime_ns, stat.st_size)
    if problem is not None:
        raise ValueError(f"object mesh file {name!r} cannot be used: {problem}")
    return name


@dataclass(frozen=True)
class PickupConfig:
    """Everything that defines a DeformablePickup task; see ``DeformablePickupEnv`` for the meaning.

    ``object`` is a name of ``OBJECT_SHAPES``, ``"random"`` (sampled per episode among the five), a
    path to a watertight surface mesh, or a tuple (a list is accepted) of names and mesh paths to
    sample from per episode, uniformly (each entry checked here: it must exist and load as a watertight
    surface, so a bad name or file fails at ``gym.make``, not at ``reset``). ``youngs_modulus`` is a value in Pa or a tuple of values
    to sample from per episode (e.g. the paper's (1e4, 1e5, 1e6, 1e7)); ``poisson_ratio`` and
    ``density`` (kg/m^3) likewise (a tuple is sampled per episode, after the pose; a single value
    draws nothing, so the draws of existing configurations are unchanged). ``goal_noise`` (m, >= 0
    per world axis) draws each episode's goal uniformly within ``goal`` +- ``goal_noise`` (last, and
    only where a component is > 0: zeros draw nothing); the lowest drawn goal must lie above the ground.
    The episode's goal is in the observation (``environment_state``) and the reset info (``goal``).
    """

    object: str | tuple[str, ...] = "cuboid"
    object_resolution: float | None = None
    youngs_modulus: float | tuple[float, ...] = 1e5
    poisson_ratio: float | tuple[float, ...] = 0.3
    density: float | tuple[float, ...] = 500.0
    ground_friction: float = 0.5
    pad_friction: float = 1.0
    contact_stiffness: float = 1e6
    #: ``ContactParams.edge_contact``: also hold the pads' box edges and corners out of the object
    #: between its surface nodes (on by default, as there; see its docstring)
    edge_contact: bool = True
    init_position_noise: float = 0.02
    init_yaw_noise: float = math.pi
    control_hz: float = 20.0
    episode_seconds: float = 15.0
    goal: tuple[float, float, float] = (0.0, 0.6, 0.0)
    goal_noise: tuple[float, float, float] = (0.0, 0.0, 0.0)
    success_tolerance: float = 0.05
    success_hold_seconds: float = 0.5
    #: False: a success does not end the episode (``info["is_success"]`` and the success term go on
    #: for every further step the object stays held at the goal, until truncation): for training,
    #: where a success that ends the episode is worth about as much as hovering near the goal
    #: (benchmarks/RESULTS.md, 2026-11-27; ManiSkill's ``ignore_terminations``). Evaluate with True.
    terminate_on_success: bool = True
    max_linear_speed: float = 0.3
    max_angular_speed: float = 1.5
    wrist_force_limit: float = DEFAULT_WRIST_FORCE_LIMIT
    obs_type: str = "state"
    action_mode: str = "delta"
    gripper: GripperConfig = field(default_factory=GripperConfig)
    solver: SolverConfig = field(default_factory=lambda: SolverConfig(substeps=4))
    camera: Camera = field(default_factory=Camera)
    device: str = "cpu"

    def __post_init__(self) -> None:
        if self.object_resolution is not None:
            check_range("object_resolution", self.object_resolution, 0.0, 0.1, "m", high_open=False)
        for name, unit in (("youngs_modulus", "Pa"), ("poisson_ratio", ""), ("density", "kg/m^3")):
            value = getattr(self, name)
            if isinstance(value, list):
                object.__setattr__(self, name, tuple(value))  # frozen: normalised once, here
            if getattr(self, name) == ():
                raise ValueError(f"{name} must be a value or a non-empty tuple of values {unit}, got ()")
        for e in self.moduli:
            for nu in self.poisson_ratios:
                for rho in self.densities:
                    Material(rho, e, nu)  # validates all three
        ContactParams(self.contact_stiffness, self.ground_friction, self.pad_friction, edge_contact=self.edge_contact)
        check_range("init_position_noise", self.init_position_noise, 0.0, 0.1, "m", low_open=False, high_open=False)
        check_range("init_yaw_noise", self.init_yaw_noise, 0.0, math.pi, "rad", low_open=False, high_open=False)
        check_range("control_hz", self.control_hz, 1.0, 200.0, "Hz", low_open=False, high_open=False)
        check_range("episode_seconds", self.episode_seconds, 0.0, 3600.0, "s")
        check_range("success_tolerance", self.success_tolerance, 0.0, 1.0, "m")
        check_range("success_hold_seconds", self.success_hold_seconds, 0.0, 60.0, "s", low_open=False)
        check_range("max_linear_speed", self.max_linear_speed, 0.0, 2.0, "m/s", high_open=False)
        check_range("wrist_force_limit", self.wrist_force_limit, 0.0, math.inf, "N", high_open=False)
        check_range("max_angular_speed", self.max_angular_speed, 0.0, 2 * math.pi, "rad/s", high_open=False)
        if len(self.goal) != 3 or not all(math.isfinite(float(g)) for g in self.goal):
            raise ValueError(f"goal must be 3 finite numbers in m, got {self.goal!r}")
        if isinstance(self.goal, list):
            object.__setattr__(self, "goal", tuple(self.goal))  # frozen: normalised once, here
        if isinstance(self.goal_noise, list):
            object.__setattr__(self, "goal_noise", tuple(self.goal_noise))
        if (not isinstance(self.goal_noise, tuple) or len(self.goal_noise) != 3
                or not all(isinstance(g, numbers.Real) and math.isfinite(g) and g >= 0.0 for g in self.goal_noise)):
            raise ValueError(f"goal_noise must be 3 finite numbers >= 0 in m (half-widths of the goal's draw), "
                             f"got {self.goal_noise!r}")
        if self.goal_noise[1] > 0.0 and float(self.goal[1]) - self.goal_noise[1] <= 0.0:
            raise ValueError(f"the lowest goal height drawn, goal[1] - goal_noise[1] = {self.goal[1]} - "
                             f"{self.goal_noise[1]} m, must be above the ground (> 0 m)")
        if not isinstance(self.terminate_on_success, bool):
            raise TypeError(f"terminate_on_success must be a bool, got {self.terminate_on_success!r}")
        _check_choice("obs_type", self.obs_type, OBS_TYPES)
        _check_choice("action_mode", self.action_mode, ACTION_MODES)
        for name, cls in (("gripper", GripperConfig), ("solver", SolverConfig), ("camera", Camera)):
            if not isinstance(getattr(self, name), cls):
                raise TypeError(f"{name} must be a {cls.__name__}, got {type(getattr(self, name)).__name__}")
        if isinstance(self.object, list):
            object.__setattr__(self, "object", tuple(self.object))  # frozen: normalised once, here
        if isinstance(self.object, tuple):
            if len(self.object) == 0 or RANDOM_OBJECT in self.object:
                raise ValueError(f"an object tuple must hold >= 1 names of {sorted(OBJECT_SHAPES)} or mesh paths "
                                 f"(not {RANDOM_OBJECT!r}), got {self.object!r}")
            for name in self.object:
                check_object(name)  # last: loads mesh files, after the cheap checks
        else:
            check_object(self.object)

    @property
    def dt(self) -> float:
        """Control period, s."""
        return 1.0 / self.control_hz

    @property
    def max_episode_steps(self) -> int:
        return int(round(self.episode_seconds * self.control_hz))

    @property
    def moduli(self) -> tuple[float, ...]:
        return self.youngs_modulus if isinstance(self.youngs_modulus, tuple) else (float(self.youngs_modulus),)

    @property
    def poisson_ratios(self) -> tuple[float, ...]:
        return self.poisson_ratio if isinstance(self.poisson_ratio, tuple) else (float(self.poisson_ratio),)

    @property
    def densities(self) -> tuple[float, ...]:
        return self.density if isinstance(self.density, tuple) else (float(self.density),)

    @property
    def object_names(self) -> tuple[str, ...]:
        """The objects an episode's object is drawn from (uniformly)."""
        if isinstance(self.object, tuple):
            return self.object
        return tuple(OBJECT_SHAPES) if self.object == RANDOM_OBJECT else (self.object,)

