"""Implicit descriptions of solids consumed by the isosurface-stuffing mesher.

An :class:`Implicit` tells which points are inside, on or outside the solid and where a
segment from an inside point to an outside point crosses the surface. Positions are [n,3]
float64 metres in the frame the solid is described in (y up).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable

import numpy as np

__all__ = ["Implicit", "AnalyticImplicit", "sphere_implicit"]

_ROOT_ITERS = 60


class Implicit(ABC):
    """A solid for :func:`stuff_implicit`.

    Attributes:
        lo, hi: [3] axis-aligned bounding box of the solid, metres.
        origin: [3] point that the background lattice puts a node on (e.g. a centre of symmetry).
    """

    lo: np.ndarray
    hi: np.ndarray
    origin: np.ndarray

    @abstractmethod
    def classify(self, points: np.ndarray) -> np.ndarray:
        """[n] int8: +1 strictly inside, 0 on the surface, -1 outside."""

    @abstractmethod
    def crossings(self, inside: np.ndarray, outside: np.ndarray) -> np.ndarray:
        """[n,3] surface points on the segments inside[i] -> outside[i] (one crossing each)."""


class AnalyticImplicit(Implicit):
    """Solid given by a signed distance function (negative inside) and a projection.

    Args:
        sdf: maps [n,3] points (metres) to [n] signed distances (metres, < 0 inside).
        project: maps [n,3] points near the surface to their closest surface points.
        lo, hi: bounding box, metres.
        origin: lattice origin, metres.
    """

    def __init__(
        self,
        sdf: Callable[[np.ndarray], np.ndarray],
        project: Callable[[np.ndarray], np.ndarray],
        lo: np.ndarray,
        hi: np.ndarray,
        origin: np.ndarray,
    ) -> None:
        self._sdf = sdf
        self._project = project
        self.lo, self.hi, self.origin = (np.asarray(v, dtype=np.float64) for v in (lo, hi, origin))

    def classify(self, points: np.ndarray) -> np.ndarray:
        d = self._sdf(points)
        return (-np.sign(d)).astype(np.int8)

    def crossings(self, inside: np.ndarray, outside: np.ndarray) -> np.ndarray:
        """Illinois (modified regula falsi) root of the SDF along each segment."""
        a = np.zeros(len(inside))
        b = np.ones(len(inside))
        seg = outside - inside
        fa = self._sdf(inside)
        fb = self._sdf(outside)
        side = np.zeros(len(inside), dtype=np.int8)
        for _ in range(_ROOT_ITERS):
            denom = fb - fa
            t = np.where(denom != 0.0, (b * fa - a * fb) / np.where(denom != 0.0, denom, 1.0), 0.5 * (a + b))
            t = np.clip(t, a, b)
            ft = self._sdf(inside + t[:, None] * seg)
            neg = ft < 0.0
            # keep the bracket [a, b] with f(a) < 0 <= f(b); halve the stale end (Illinois)
            a_new = np.where(neg, t, a)
            b_new = np.where(neg, b, t)
            fa_new = np.where(neg, ft, np.where(side == -1, 0.5 * fa, fa))
            fb_new = np.where(neg, np.where(side == 1, 0.5 * fb, fb), ft)
            side = np.where(neg, 1, -1).astype(np.int8)
            done = (ft == 0.0) | (b_new - a_new <= 1e-15)
            a, b, fa, fb = a_new, b_new, fa_new, fb_new
            a = np.where(done, t, a)
            b = np.where(done, t, b)
            if np.all(b - a <= 1e-15):
                break
        t = 0.5 * (a + b)
        return self._project(inside + t[:, None] * seg)


def sphere_implicit(radius: float) -> AnalyticImplicit:
    """Ball of ``radius`` metres centred at the origin; the lattice origin is the centre, so
    lattice edges run along the axes and the poles (0, +-radius, 0) become mesh nodes."""

    def sdf(p: np.ndarray) -> np.ndarray:
        return np.sqrt(np.einsum("ij,ij->i", p, p)) - radius

    def project(p: np.ndarray) -> np.ndarray:
        r = np.sqrt(np.einsum("ij,ij->i", p, p))
        return p / np.where(r > 0.0, r, 1.0)[:, None] * radius

    ext = np.full(3, radius)
    return AnalyticImplicit(sdf, project, -ext, ext, np.zeros(3))
