"""Stress colours of the 3D viewer: a banded colormap and its scale bar.

The object's surface is split into ``bins`` colour bands (one viser mesh per band): each triangle
takes the colour of the band that holds the mean node stress of its three corners. The scale bar
shows the same bands with their stress limits, so what is on screen reads off the bar exactly.
Colormaps come from the headless renderer's registry (``defgrasp_env.render.style.COLORMAPS``).
"""

from __future__ import annotations

import numpy as np

from ..render.style import COLORMAPS


class StressScale:
    """Band colours and the stress range (Pa) they span.

    bins: number of colour bands (2..64); colormap: a key of ``COLORMAPS``; floor_pa: the smallest
    upper end of the range (Pa, > 0), so that an unloaded object is drawn in the lowest colour and
    not in noise. ``upper_pa`` is sticky: it grows to the largest stress seen (``observe``) and only
    goes back to the floor on ``reset`` (a new episode), so colours stay comparable over an episode.
    """

    def __init__(self, bins: int = 16, colormap: str = "turbo", floor_pa: float = 100.0):
        if isinstance(bins, bool) or not isinstance(bins, int) or not 2 <= bins <= 64:
            raise ValueError(f"bins must be an int in [2, 64], got {bins!r}")
        if colormap not in COLORMAPS:
            raise ValueError(f"colormap must be one of {sorted(COLORMAPS)}, got {colormap!r}")
        if not (np.isfinite(floor_pa) and floor_pa > 0):
            raise ValueError(f"floor_pa must be in (0, inf) Pa, got {floor_pa!r}")
        self.bins = bins
        self.colormap = colormap
        self.floor_pa = float(floor_pa)
        self.upper_pa = self.floor_pa
        control = np.asarray(COLORMAPS[colormap], dtype=np.float64)
        centers = (np.arange(bins) + 0.5) / bins
        pos = np.linspace(0.0, 1.0, len(control))
        rgb = np.stack([np.interp(centers, pos, control[:, c]) for c in range(3)], axis=1)
        self.colors = np.round(255 * rgb).astype(np.uint8)        # [bins, 3] RGB

    def reset(self) -> None:
        self.upper_pa = self.floor_pa

    def observe(self, stress_pa: np.ndarray | float) -> None:
        """Grow the range to hold ``stress_pa`` (Pa; NaN/inf are ignored)."""
        s = np.asarray(stress_pa, dtype=np.float64)
        s = s[np.isfinite(s)]
        if s.size:
            self.upper_pa = max(self.upper_pa, float(s.max()))

    def band_of(self, stress_pa: np.ndarray) -> np.ndarray:
        """Band index [same shape] in [0, bins) of each stress (Pa), clamped at both ends."""
        s = np.nan_to_num(np.asarray(stress_pa, dtype=np.float64), nan=0.0, posinf=self.upper_pa)
        return np.clip((s / self.upper_pa * self.bins).astype(np.int64), 0, self.bins - 1)

    def scale_bar_html(self) -> str:
        """An HTML scale bar: one coloured cell per band, labels at 0, the middle and the top (kPa)."""
        cells = "".join(f'<td style="background:rgb({r},{g},{b});height:14px;padding:0"></td>'
                        for r, g, b in self.colors)
        top = self.upper_pa / 1e3
        return ('<div style="font:12px sans-serif">von Mises stress (kPa)'
                f'<table style="width:100%;border-collapse:collapse;table-layout:fixed"><tr>{cells}</tr></table>'
                '<div style="display:flex;justify-content:space-between">'
                f'<span>0</span><span>{top / 2:.3g}</span><span>{top:.3g}</span></div></div>')
