"""Pinhole camera for the headless renderer.

World frame: right-handed, y up, metres (see CONVENTIONS.md). Image frame: row 0 is the top row,
column 0 the left column; pixel (row i, column j) covers the continuous image coordinates
[j, j+1) x [i, i+1) and its ray passes through the pixel centre (j + 0.5, i + 0.5).

Projection of a world point X (used by the renderer and by :meth:`Camera.project`)::

    forward = normalize(look_at - position)
    right   = normalize(cross(forward, up))
    up_cam  = cross(right, forward)
    d = X - position;  x = d.right;  y = d.up_cam;  z = d.forward   (z > 0: in front)
    f_px = (height / 2) / tan(fov_y / 2)                              (square pixels)
    column = width / 2 + f_px * x / z ;  row = height / 2 - f_px * y / z
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

_MIN_SIZE, _MAX_SIZE = 16, 4096


def _vec3(name: str, value) -> tuple[float, float, float]:
    """Validate a finite 3-vector and return it as a tuple of Python floats."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a sequence of 3 numbers, got {value!r}") from exc
    if arr.shape != (3,):
        raise ValueError(f"{name} must have shape (3,), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {tuple(arr.tolist())}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def _size(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an int, got {type(value).__name__} {value!r}")
    if not _MIN_SIZE <= int(value) <= _MAX_SIZE:
        raise ValueError(f"{name} must be in [{_MIN_SIZE}, {_MAX_SIZE}] pixels, got {value}")
    return int(value)


@dataclass(frozen=True)
class Camera:
    """Pinhole camera, immutable and validated.

    Attributes:
        position: camera centre, world frame, metres, 3 floats.
        look_at: point the optical axis passes through, world frame, metres; != position.
        up: approximate up direction (world frame, any length > 0, not parallel to the
            viewing direction); the image's vertical axis is its component orthogonal to it.
        fov_y_deg: vertical field of view in degrees, in (1, 179).
        width, height: image size in pixels, ints in [16, 4096].

    The default frames the whole pickup task: every object of the task (up to the 30 cm rope, any
    yaw, with the reset's position noise) on the ground, and held at the goal (0, 0.6, 0) m, upright
    or folded over the pads (the rope held at its middle: 0.52 to 0.68 m), lies inside the image
    at 224 x 224 (seen from the front-right, 30 degrees above the horizon, 1.2 m from
    (0, 0.34, 0), 41 degrees vertical field of view). The task's vertical extent sets the scale: a
    4 cm object spans ~15 px at 224 px and ~32 px at 480 px (``Camera(width=480, height=480)``
    keeps this framing: the field of view is vertical, so only the pixel count changes; a width
    below the height narrows the view). For video or to see deformation, render larger.
    """

    position: tuple[float, float, float] = (0.5196, 0.94, 0.9)
    look_at: tuple[float, float, float] = (0.0, 0.34, 0.0)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov_y_deg: float = 41.0
    width: int = 224
    height: int = 224

    def __post_init__(self):
        position = _vec3("position", self.position)
        look_at = _vec3("look_at", self.look_at)
        up = _vec3("up", self.up)
        object.__setattr__(self, "position", position)
        object.__setattr__(self, "look_at", look_at)
        object.__setattr__(self, "up", up)
        object.__setattr__(self, "width", _size("width", self.width))
        object.__setattr__(self, "height", _size("height", self.height))
        if isinstance(self.fov_y_deg, bool) or not isinstance(self.fov_y_deg, (int, float, np.number)):
            raise TypeError(f"fov_y_deg must be a number, got {type(self.fov_y_deg).__name__}")
        fov = float(self.fov_y_deg)
        if not (1.0 < fov < 179.0):
            raise ValueError(f"fov_y_deg must be in (1, 179) degrees, got {self.fov_y_deg}")
        object.__setattr__(self, "fov_y_deg", fov)

        view = np.subtract(look_at, position)
        dist = float(np.linalg.norm(view))
        if dist < 1e-9:
            raise ValueError(f"look_at must differ from position, both are {position}")
        up_norm = float(np.linalg.norm(up))
        if up_norm < 1e-12:
            raise ValueError(f"up must be a non-zero vector, got {up}")
        sin_angle = float(np.linalg.norm(np.cross(view / dist, np.asarray(up) / up_norm)))
        if sin_angle < 1e-6:
            raise ValueError(f"up {up} must not be parallel to the viewing direction {tuple(view / dist)}")

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Camera axes in the world frame: (right, up_cam, forward), unit float64 vectors [3].

        right points to increasing columns, up_cam to decreasing rows, forward along the view.
        """
        forward = np.subtract(self.look_at, self.position)
        forward = forward / np.linalg.norm(forward)
        right = np.cross(forward, self.up)
        right = right / np.linalg.norm(right)
        up_cam = np.cross(right, forward)
        return right, up_cam, forward

    @property
    def focal_px(self) -> float:
        """Focal length in pixels, (height / 2) / tan(fov_y / 2) (square pixels)."""
        return 0.5 * self.height / math.tan(math.radians(self.fov_y_deg) / 2.0)

    def project(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Project world points to continuous image coordinates.

        Args:
            points: world-frame positions in metres, shape (3,) or (P, 3).

        Returns:
            (uv, depth): uv float64 [P, 2] as (column, row) in pixels, with the pixel (i, j)
            covering [j, j+1) x [i, i+1); depth float64 [P] metres along the optical axis
            (<= 0 means behind the camera, where uv is meaningless).
        """
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"points must have shape (3,) or (P, 3), got {np.shape(points)}")
        right, up_cam, forward = self.basis()
        d = pts - np.asarray(self.position)
        x, y, z = d @ right, d @ up_cam, d @ forward
        with np.errstate(divide="ignore", invalid="ignore"):
            col = 0.5 * self.width + self.focal_px * x / z
            row = 0.5 * self.height - self.focal_px * y / z
        return np.stack([col, row], axis=1), z
