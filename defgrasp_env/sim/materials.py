"""Object materials: density, Young's modulus and Poisson ratio, and their neo-Hookean parameters."""

from __future__ import annotations

import math
from dataclasses import dataclass

#: The paper's Young's moduli (Table 2), Pa.
PAPER_YOUNGS_MODULI = (1e4, 1e5, 1e6, 1e7)


def check_range(name: str, value: float, low: float, high: float, unit: str = "",
                low_open: bool = True, high_open: bool = True) -> float:
    """Return ``float(value)`` if it lies in the interval, else raise ``ValueError`` naming both."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"{name} must be a real number, got {value!r} ({type(value).__name__})")
    v = float(value)
    ok_low = v > low if low_open else v >= low
    ok_high = v < high if high_open else v <= high
    if not (math.isfinite(v) or (v == high == math.inf)) or not (ok_low and ok_high):
        interval = f"{'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
        raise ValueError(f"{name} must be in {interval}{' ' + unit if unit else ''}, got {value!r}")
    return v


@dataclass(frozen=True)
class Material:
    """Isotropic hyperelastic material of a soft object.

    Attributes:
        density: mass density, kg/m^3, in (0, inf).
        youngs_modulus: small-strain Young's modulus E, Pa, in (0, inf).
        poisson_ratio: small-strain Poisson ratio nu, in [0, 0.5).
    """

    density: float = 1000.0
    youngs_modulus: float = 1e5
    poisson_ratio: float = 0.3

    def __post_init__(self) -> None:
        object.__setattr__(self, "density", check_range("density", self.density, 0.0, math.inf, "kg/m^3"))
        object.__setattr__(self, "youngs_modulus",
                           check_range("youngs_modulus", self.youngs_modulus, 0.0, math.inf, "Pa"))
        object.__setattr__(self, "poisson_ratio",
                           check_range("poisson_ratio", self.poisson_ratio, 0.0, 0.5, low_open=False))

    @property
    def lame(self) -> tuple[float, float]:
        """Small-strain Lamé parameters (mu, lambda), Pa."""
        e, nu = self.youngs_modulus, self.poisson_ratio
        return e / (2.0 * (1.0 + nu)), e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
