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


@pytest.fixture(scope="module")
def episode_file(tmp_path_factory):
    """A recorded expert episode (soft cuboid, until it has been squeezed for a while)."""
    import gymnasium as gym

    import defgrasp_env  # noqa: F401
    from defgrasp_env.policies import RECOMMENDED_ENV_KWARGS, ScriptedPickupExpert
    from defgrasp_env.recording import HDF5Recorder

    out = tmp_path_factory.mktemp("episodes")
    env = HDF5Recorder(gym.make("DeformablePickup-v0", object="cuboid", youngs_modulus=1e4, init_yaw_noise=0.0,
                                **RECOMMENDED_ENV_KWARGS), out)
    expert = ScriptedPickupExpert.from_env(env)
    obs, _ = env.reset(seed=1)
    expert.reset()
    squeezed = 0
    for _ in range(200):
        obs, _, terminated, truncated, info = env.step(expert(obs))
        squeezed += min(info["left_tip_normal_force"], info["right_tip_normal_force"]) > 2.0
        if squeezed >= 8 or terminated or truncated:
            break
    env.close()
    (path,) = sorted(out.glob("*.h5"))
    return path


def test_playback_timeline_in_chromium(chromium, episode_file):
    pytest.importorskip("viser", reason="needs the [viewer] extra (viser)")
    from defgrasp_env.viewer.playback import EpisodePlayer

    ART.mkdir(parents=True, exist_ok=True)
    player = EpisodePlayer(episode_file, port=0)
    try:
        last = player.frames.num_steps - 1
        assert int(player.slider.value) == 0 and player.slider.max == last
        first = screenshot(player.url, ART / "playback_first.png")
        player.slider.value = last
        player.show_step(last)
        end = screenshot(player.url, ART / "playback_last.png")
    finally:
        player.close()
    assert pad_pixels(first) > 300 and pad_pixels(end) > 300
    assert len(hue_bins(end)) >= 3, hue_bins(end)
    assert (np.abs(first.astype(int) - end.astype(int)).max(axis=2) > 40).mean() > 0.005


def test_dataset_view_command_serves_the_episode(chromium, episode_file, tmp_path):
    """``defgrasp-dataset view EPISODE --port 0`` prints the URL, serves the episode, stops on Ctrl-C."""
    pytest.importorskip("viser", reason="needs the [viewer] extra (viser)")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "defgrasp_env.recording.cli", "view", str(episode_file), "--port", "0"],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        url, lines, t0 = None, [], time.monotonic()
        while url is None and time.monotonic() - t0 < 120:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            m = re.search(r"viewing .* at (http://127\.0\.0\.1:\d+/)", line)
            url = m.group(1) if m else None
        assert url, "".join(lines)
        img = screenshot(url, ART / "dataset_view.png")
        assert pad_pixels(img) > 300
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=30) == 0
    finally:
        if proc.poll() is None:
            proc.kill()


def test_dataset_view_errors_are_clear(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, "-m", "defgrasp_env.recording.cli", "view", str(tmp_path / "none.h5")],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "none.h5" in r.stderr and "not found" in r.stderr
