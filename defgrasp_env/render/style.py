"""Colours, light and colormaps of the headless renderer (frozen, validated configuration).

All colours are linear RGB floats in [0, 1]; the image is written as round(255 * colour).
Directions are in the world frame (y up) and need not be unit length.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import _vec3

# Colormaps: 11 control points, sampled from matplotlib at 0, 0.1, ..., 1 and linearly
# interpolated in the kernel. One registry; add an entry to add a colormap.
COLORMAPS: dict[str, tuple[tuple[float, float, float], ...]] = {
    "viridis": (
        (0.2670, 0.0049, 0.3294), (0.2826, 0.1409, 0.4575), (0.2539, 0.2653, 0.5300),
        (0.2068, 0.3718, 0.5531), (0.1636, 0.4711, 0.5581), (0.1276, 0.5669, 0.5506),
        (0.1347, 0.6586, 0.5176), (0.2669, 0.7488, 0.4406), (0.4775, 0.8214, 0.3182),
        (0.7414, 0.8734, 0.1496), (0.9932, 0.9062, 0.1439),
    ),
    "turbo": (
        (0.1900, 0.0718, 0.2322), (0.2697, 0.3488, 0.7963), (0.2443, 0.6094, 0.9970),
        (0.0975, 0.8371, 0.8034), (0.2760, 0.9709, 0.5165), (0.6436, 0.9900, 0.2336),
        (0.8833, 0.8655, 0.2172), (0.9961, 0.6428, 0.1916), (0.9408, 0.3557, 0.0703),
        (0.7648, 0.1437, 0.0104), (0.4796, 0.0158, 0.0106),
    ),
}


def _color(name: str, value) -> tuple[float, float, float]:
    rgb = _vec3(name, value)
    if not all(0.0 <= c <= 1.0 for c in rgb):
        raise ValueError(f"{name} must have components in [0, 1], got {rgb}")
    return rgb


def _positive(name: str, value, unit: str) -> float:
    v = float(value)
    if not (np.isfinite(v) and v > 0.0):
        raise ValueError(f"{name} must be in (0, inf) {unit}, got {value}")
    return v


def _unit_interval(name: str, value) -> float:
    v = float(value)
    if not (0.0 <= v <= 1.0):
        raise ValueError(f"{name} must be in [0, 1], got {value}")
    return v


@dataclass(frozen=True)
class RenderStyle:
    """Appearance of the scene.

    Attributes:
        object_color: deformable object (blue-ish) when no per-vertex scalar is given.
        box_color: default colour of the oriented boxes (gripper pads, finger bodies).
        goal_color, goal_radius: goal marker sphere colour and radius (m, > 0).
        checker_light, checker_dark: the two ground colours; checker_size: square side (m, > 0).
        sky_horizon, sky_zenith: sky gradient colours at elevation 0 and 90 degrees.
        light_direction: direction from the scene *towards* the directional light (world frame).
        ambient, diffuse: Lambert weights, colour * (ambient + diffuse * max(0, n.l)), in [0, 1].
        shadows: cast one shadow ray per pixel (object and boxes occlude the light).
        fog_distance: ground fades to the horizon colour as 1 - exp(-t / fog_distance) (m, > 0).
        colormap: key of COLORMAPS used for per-vertex scalar colouring.
    """

    object_color: tuple[float, float, float] = (0.30, 0.50, 0.85)
    box_color: tuple[float, float, float] = (0.25, 0.25, 0.27)
    goal_color: tuple[float, float, float] = (0.90, 0.20, 0.20)
    goal_radius: float = 0.015
    checker_light: tuple[float, float, float] = (0.82, 0.82, 0.82)
    checker_dark: tuple[float, float, float] = (0.62, 0.62, 0.62)
    checker_size: float = 0.05
    sky_horizon: tuple[float, float, float] = (0.80, 0.87, 0.95)
    sky_zenith: tuple[float, float, float] = (0.40, 0.58, 0.85)
    light_direction: tuple[float, float, float] = (0.35, 1.0, 0.25)
    ambient: float = 0.35
    diffuse: float = 0.65
    shadows: bool = True
    fog_distance: float = 15.0
    colormap: str = "viridis"

    def __post_init__(self):
        for name in ("object_color", "box_color", "goal_color", "checker_light", "checker_dark",
                     "sky_horizon", "sky_zenith"):
            object.__setattr__(self, name, _color(name, getattr(self, name)))
        light = _vec3("light_direction", self.light_direction)
        if np.linalg.norm(light) < 1e-9:
            raise ValueError(f"light_direction must be a non-zero vector, got {light}")
        object.__setattr__(self, "light_direction", light)
        object.__setattr__(self, "goal_radius", _positive("goal_radius", self.goal_radius, "m"))
        object.__setattr__(self, "checker_size", _positive("checker_size", self.checker_size, "m"))
        object.__setattr__(self, "fog_distance", _positive("fog_distance", self.fog_distance, "m"))
        object.__setattr__(self, "ambient", _unit_interval("ambient", self.ambient))
        object.__setattr__(self, "diffuse", _unit_interval("diffuse", self.diffuse))
        if not isinstance(self.shadows, (bool, np.bool_)):
            raise TypeError(f"shadows must be a bool, got {self.shadows!r}")
        if self.colormap not in COLORMAPS:
            raise ValueError(f"colormap must be one of {sorted(COLORMAPS)}, got {self.colormap!r}")

    def light_unit(self) -> np.ndarray:
        """Unit vector towards the light, float64 [3], world frame."""
        light = np.asarray(self.light_direction, dtype=np.float64)
        return light / np.linalg.norm(light)
