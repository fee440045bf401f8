"""The 3D viewer in a real headless Chromium: live (render_mode="human") and playback
(``defgrasp-dataset view``). Screenshots are kept under ``tests/.artifacts/viewer`` (ignored) to look at.

What the screenshots must show, checked on pixels of the 3D area (the GUI panel and the browser's
notices are cropped away): the pads (dark neutral grey, only the pads are drawn so), the stress
colours (saturated pixels of several hues of the turbo colormap on the object), and a picture that
changes as the episode runs.
"""

from __future__ import annotations

import os
import pathlib
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from browser import require_chromium, screenshot

ROOT = pathlib.Path(__file__).resolve().parents[1]
ART = ROOT / "tests" / ".artifacts" / "viewer"


def scene_area(img: np.ndarray) -> np.ndarray:
    """The 3D view without the GUI panel (top right) and the browser notices (top left)."""
    h, w, _ = img.shape
    return img[int(0.25 * h):, : int(0.66 * w)]


def pad_pixels(img: np.ndarray) -> int:
    """Dark neutral grey pixels (the pads' colour (70, 70, 78) under the lights)."""
    a = scene_area(img).astype(int)
    return int(np.sum((a.max(axis=2) < 130) & (a.max(axis=2) - a.min(axis=2) < 25)))


def hue_bins(img: np.ndarray, min_pixels: int = 25) -> set[int]:
    """12 hue bins (30 degrees each) with at least ``min_pixels`` saturated, bright pixels."""
    a = scene_area(img).astype(float) / 255
    mx, mn = a.max(axis=2), a.min(axis=2)
    sat = (mx - mn) / np.maximum(mx, 1e-6)
    mask = (sat > 0.45) & (mx > 0.3)
    r, g, b = a[..., 0][mask], a[..., 1][mask], a[..., 2][mask]
    d = np.maximum(mx[mask] - mn[mask], 1e-6)
    hue = np.where(mx[mask] == r, ((g - b) / d) % 6, np.where(mx[mask] == g, (b - r) / d + 2, (r - g) / d + 4)) * 60
    counts = np.bincount((hue // 30).astype(int) % 12, minlength=12)
    return {int(i) for i in np.flatnonzero(counts >= min_pixels)}


@pytest.fixture(scope="module")
def chromium():
    return require_chromium()


def test_live_view_of_the_env_in_chromium(chromium):
    pytest.importorskip("viser", reason="needs the [viewer] extra (viser)")
    import gymnasium as gym

    import defgrasp_env  # noqa: F401
    from defgrasp_env.policies import RECOMMENDED_ENV_KWARGS, ScriptedPickupExpert

    ART.mkdir(parents=True, exist_ok=True)
    env = gym.make("DeformablePickup-v0", render_mode="human", viewer_port=0, object="cuboid", youngs_modulus=1e4,
                   init_yaw_noise=0.0, **RECOMMENDED_ENV_KWARGS)
    try:
        expert = ScriptedPickupExpert.from_env(env)
        obs, _ = env.reset(seed=1)
        expert.reset()
        url = env.unwrapped._viewer.url
        assert re.fullmatch(r"http://127\.0\.0\.1:\d+/", url)
        rest = screenshot(url, ART / "live_rest.png")
        squeezed_steps = 0
        for _ in range(200):
            obs, _, terminated, truncated, info = env.step(expert(obs))
            if min(info["left_tip_normal_force"], info["right_tip_normal_force"]) > 2.0:
                squeezed_steps += 1
            if squeezed_steps >= 6 or terminated or truncated:
                break
        assert squeezed_steps >= 6, "the expert should be squeezing the cuboid"
        grasp = screenshot(url, ART / "live_grasp.png")
    finally:
        env.close()
    # the pads are on screen in both; the squeezed object shows several stress colours
    assert pad_pixels(rest) > 300 and pad_pixels(grasp) > 300, (pad_pixels(rest), pad_pixels(grasp))
    assert len(hue_bins(grasp)) >= 3, hue_bins(grasp)
    # the picture changed as the episode ran (pads moved, object squeezed)
    changed = np.abs(rest.astype(int) - grasp.astype(int)).max(axis=2) > 40
    assert changed.mean() > 0.005, changed.mean()
