"""Registry of the named primitive objects and :func:`make_object_mesh`.

Default sizes are the paper's five objects, sized for a Robotiq 2F-85 (85 mm stroke, pads
22 mm wide x 37.5 mm tall) picking them top-down from the ground. Default resolutions keep
every default object at roughly 300-1500 tets for real-time CPU simulation.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from . import primitives as prim
from ._checks import checked_resolution, positive_length
from .tetmesh import TetMesh, finalize_mesh

__all__ = ["ObjectShape", "OBJECT_SHAPES", "make_object_mesh"]

Sizes = Mapping[str, Any]


@dataclass(frozen=True)
class ObjectShape:
    """A named primitive object.

    Attributes:
        name: registry key.
        description: shape, pose in the object frame and size parameters (metres).
        defaults: default size keyword arguments (metres; read-only mapping).
        default_resolution: default target mean tet edge length, metres.
        thickness: sizes -> smallest dimension the mesh must resolve (metres); a resolution
            above it would leave less than one tet layer and is rejected.
        build: (sizes, resolution) -> raw (nodes [N,3], tets [M,4]) in the object frame.
        check: sizes -> None; raises ValueError on inconsistent sizes (optional).
    """

    name: str
    description: str
    defaults: Mapping[str, Any]
    default_resolution: float
    thickness: Callable[[Sizes], float]
    build: Callable[[Sizes, float], tuple[np.ndarray, np.ndarray]]
    check: Callable[[Sizes], None] | None = None

    def resolve_sizes(self, **size_kwargs: Any) -> dict[str, Any]:
        """Merge ``size_kwargs`` over the defaults and validate them (metres)."""
        unknown = sorted(set(size_kwargs) - set(self.defaults))
        if unknown:
            raise TypeError(
                f"unknown size argument(s) {unknown} for object {self.name!r}; accepted: "
                f"{sorted(self.defaults)}"
            )
        sizes: dict[str, Any] = {}
        for key, default in self.defaults.items():
            value = size_kwargs.get(key, default)
            if isinstance(default, tuple):
                if not isinstance(value, (tuple, list, np.ndarray)) or len(value) != len(default):
                    raise TypeError(
                        f"{key} must be a sequence of {len(default)} lengths in metres, got {value!r}"
                    )
                sizes[key] = tuple(positive_length(f"{key}[{i}]", v) for i, v in enumerate(value))
            else:
                sizes[key] = positive_length(key, value)
        if self.check is not None:
            self.check(sizes)
        return sizes


# Fatter tori have a hole so small that the swept prisms at its rim degrade (< 10 deg).
TORUS_MAX_MINOR_RATIO = 0.8


def _check_torus(s: Sizes) -> None:
    limit = TORUS_MAX_MINOR_RATIO * s["major_radius"]
    if s["minor_radius"] > limit:
        raise ValueError(
            f"minor_radius must be in (0, {TORUS_MAX_MINOR_RATIO} * major_radius = {limit:g}] m "
            f"(the torus needs a hole), got {s['minor_radius']!r}"
        )


_SHAPES = (
    ObjectShape(
        name="cuboid",
        description="box of size=(sx, sy, sz) m, faces axis-aligned, bottom face on y = 0 "
        "(structured Kuhn grid, exact shape)",
        defaults=MappingProxyType({"size": (0.04, 0.04, 0.04)}),
        default_resolution=0.010,
        thickness=lambda s: min(s["size"]),
        build=lambda s, r: prim.cuboid_tets(s["size"], r),
    ),
    ObjectShape(
        name="sphere",
        description="ball of radius m resting on its pole (0, 0, 0); poles are nodes "
        "(isosurface stuffing)",
        defaults=MappingProxyType({"radius": 0.025}),
        default_resolution=0.009,
        thickness=lambda s: 2.0 * s["radius"],
        build=lambda s, r: prim.sphere_tets(s["radius"], r),
    ),
    ObjectShape(
        name="torus",
        description="torus lying flat (axis y) with major_radius and minor_radius (tube) m "
        "(swept disk)",
        defaults=MappingProxyType({"major_radius": 0.030, "minor_radius": 0.010}),
        default_resolution=0.009,
        thickness=lambda s: 2.0 * s["minor_radius"],
        build=lambda s, r: prim.torus_tets(s["major_radius"], s["minor_radius"], r),
        check=_check_torus,
    ),
    ObjectShape(
        name="cylinder",
        description="standing cylinder (axis y) of radius and height m, flat caps at y = 0 "
        "and y = height (swept disk)",
        defaults=MappingProxyType({"radius": 0.020, "height": 0.060}),
        default_resolution=0.009,
        thickness=lambda s: min(2.0 * s["radius"], s["height"]),
        build=lambda s, r: prim.cylinder_tets(s["radius"], s["height"], r),
    ),
    ObjectShape(
        name="rope",
        description="rope lying along x on the ground: cylinder of length and radius m with "
        "flat ends at x = +-length/2 (swept disk)",
        defaults=MappingProxyType({"length": 0.300, "radius": 0.008}),
        default_resolution=0.011,
        thickness=lambda s: 2.0 * s["radius"],
        build=lambda s, r: prim.rope_tets(s["length"], s["radius"], r),
    ),
)

OBJECT_SHAPES: Mapping[str, ObjectShape] = MappingProxyType({s.name: s for s in _SHAPES})
"""Registry: object name -> :class:`ObjectShape` (read-only)."""


def make_object_mesh(name: str, resolution: float | None = None, **size_kwargs: Any) -> TetMesh:
    """Tet mesh of a named primitive object in the object frame.

    Args:
        name: one of ``OBJECT_SHAPES`` ("cuboid", "sphere", "torus", "cylinder", "rope").
        resolution: target mean tet edge length, metres, in (0, thickness] where thickness is
            the object's smallest dimension (e.g. the rope's diameter); None uses the shape's
            ``default_resolution`` (capped at the thickness). Finer gives more tets, about
            volume / (0.12 res^3) for bulky shapes.
        **size_kwargs: size overrides in metres, see ``OBJECT_SHAPES[name].defaults``.
    Returns:
        A verified :class:`TetMesh` (metres, y up, resting on y = 0, centred at x = z = 0).
    Raises:
        TypeError: name is not a string, unknown size keyword, non-numeric value.
        ValueError: unknown name, non-positive size, resolution out of range, degenerate mesh.
    """
    if not isinstance(name, str):
        raise TypeError(f"name must be a str, one of {sorted(OBJECT_SHAPES)}, got {name!r}")
    if name not in OBJECT_SHAPES:
        raise ValueError(f"unknown object name {name!r}; accepted: {sorted(OBJECT_SHAPES)}")
    shape = OBJECT_SHAPES[name]
    sizes = shape.resolve_sizes(**size_kwargs)
    thickness = shape.thickness(sizes)
    if resolution is None:
        res = min(shape.default_resolution, thickness)
    else:
        res = checked_resolution(resolution, thickness, name, "its smallest dimension")
    nodes, tets = shape.build(sizes, res)
    return finalize_mesh(nodes, tets, what=f"{name} at resolution {res:g} m")

