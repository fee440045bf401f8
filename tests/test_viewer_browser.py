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
import threading
import time

import numpy as np
import pytest

from browser import require_chromium, screenshot

ROOT = pathlib.Path(__file__).resolve().parents[1]
ART = ROOT / "tests" / ".artifacts" / "viewer"


def scene_area(img: np.ndarray) -> np.ndarray:
    """The screenshot with the GUI panel (top right) and the browser's notice (top left) painted white."""
    h, w, _ = img.shape
    out = img.copy()
    out[: int(0.40 * h), int(0.60 * w):] = 255
    out[: int(0.26 * h), : int(0.38 * w)] = 255
    return out


def pad_pixels(img: np.ndarray) -> int:
    """Dark neutral grey pixels (the pads' colour (70, 70, 78) under the lights)."""
    a = scene_area(img).astype(int)
    return int(np.sum((a.max(axis=2) < 130) & (a.max(axis=2) - a.min(axis=2) < 25)))


def test_pixel_checks_tell_the_pads_and_the_stress_colours_apart():
    """The screenshot checks on drawn patches: pad grey counts as pads, not as colours; the turbo
    bands count as several hues; the white page as nothing."""
    from defgrasp_env.viewer import StressScale

    img = np.full((400, 400, 3), 255, np.uint8)
    assert pad_pixels(img) == 0 and hue_bins(img) == set()
    img[300:340, 20:60] = (70, 70, 78)
    assert pad_pixels(img) == 1600 and hue_bins(img) == set()
    for k, c in enumerate(StressScale().colors):
        img[350:390, 100 + 15 * k:115 + 15 * k] = c
    assert len(hue_bins(img)) >= 5


def hue_bins(img: np.ndarray, min_pixels: int = 10) -> set[int]:
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


def drawn(img: np.ndarray) -> bool:
    """The page has finished fading in: the pads are drawn in their full dark grey."""
    return pad_pixels(img) > 100


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
        rest = screenshot(url, ART / "live_rest.png", ready=drawn)
        squeezed_steps = 0
        for _ in range(200):
            obs, _, terminated, truncated, info = env.step(expert(obs))
            if info["grasped"]:  # both tip normal forces above the task's grasp threshold
                squeezed_steps += 1
            if squeezed_steps >= 6 or terminated or truncated:
                break
        assert squeezed_steps >= 6, "the expert should be squeezing the cuboid"
        grasp = screenshot(url, ART / "live_grasp.png", ready=drawn)
    finally:
        env.close()
    # the pads are on screen in both; the squeezed object shows several stress colours
    assert pad_pixels(rest) > 100 and pad_pixels(grasp) > 100, (pad_pixels(rest), pad_pixels(grasp))
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
        first = screenshot(player.url, ART / "playback_first.png", ready=drawn)
        player.slider.value = last
        player.show_step(last)
        end = screenshot(player.url, ART / "playback_last.png", ready=drawn)
    finally:
        player.close()
    assert pad_pixels(first) > 100 and pad_pixels(end) > 100
    assert len(hue_bins(end)) >= 3, hue_bins(end)
    assert (np.abs(first.astype(int) - end.astype(int)).max(axis=2) > 40).mean() > 0.005


def test_dataset_view_command_serves_the_episode(chromium, episode_file, tmp_path):
    """``defgrasp-dataset view EPISODE --port 0`` prints the URL, serves the episode, stops on Ctrl-C."""
    pytest.importorskip("viser", reason="needs the [viewer] extra (viser)")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    # as a user's terminal would: Ctrl-C raises KeyboardInterrupt. A test run started in the
    # background (nohup, `cmd &`, some CI runners) hands its children SIGINT ignored, and Python
    # then leaves it ignored, so the child restores the default handler before running the CLI.
    run_cli = ("import runpy, signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
               "sys.argv = ['defgrasp-dataset', *sys.argv[1:]]; "
               "runpy.run_module('defgrasp_env.recording.cli', run_name='__main__')")
    proc = subprocess.Popen([sys.executable, "-c", run_cli, "view", str(episode_file), "--port", "0"],
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
        # keep reading its output: a full pipe would block the viewer in a write (and past Ctrl-C)
        threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True).start()
        img = screenshot(url, ART / "dataset_view.png", ready=drawn)
        assert pad_pixels(img) > 100
        proc.send_signal(signal.SIGINT)
        try:
            code = proc.wait(timeout=120)   # it stops on Ctrl-C (slowly on a loaded box)
        except subprocess.TimeoutExpired:
            code = None
        assert code == 0, f"exit code {code} after Ctrl-C; its output:\n" + "".join(lines)[-3000:]
    finally:
        if proc.poll() is None:
            proc.kill()


def test_dataset_view_errors_are_clear(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, "-m", "defgrasp_env.recording.cli", "view", str(tmp_path / "none.h5")],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "none.h5" in r.stderr and "not found" in r.stderr


def test_teleop_app_3d_view_in_chromium(chromium, tmp_path):
    """The collection app with a recorded operator (replay devices, paced): the 3D page while the
    operator works, and during the review (the finished episode's lifted object and its result)."""
    pytest.importorskip("viser", reason="needs the [viewer] extra (viser)")
    import json
    import threading

    from teleop.app.devices import DeviceContext, build_controller
    from teleop.app.keys import NullKeySource
    from teleop.app.session import CollectionSession, SessionConfig, SimClock, make_env_stack
    from teleop.app.view import SceneView3D

    data = ROOT / "tests" / "data"
    meta = json.loads((data / "human_pick_cuboid.json").read_text())
    ART.mkdir(parents=True, exist_ok=True)
    env, rec, marks = make_env_stack({**meta["env_kwargs"]}, out_dir=tmp_path / "eps")
    clock = SimClock()
    ctrl = build_controller(f"replay:{data / 'human_pick_cuboid_tracker.jsonl'}",
                            f"replay:{data / 'human_pick_cuboid_glove.jsonl'}",
                            ctx=DeviceContext(episode_clock=clock), ik="analytic")
    view = SceneView3D("127.0.0.1", 0)
    session = CollectionSession(env, ctrl, NullKeySource(), recorder=rec, marks=marks, view=view, sim_clock=clock,
                                config=SessionConfig(num_episodes=1, reset_time_s=600.0, seed=meta["seed"],
                                                     fixed_seed=True, realtime=True),
                                say=lambda m: None, status=lambda line: None, handle_sigint=False)
    # the operator's episode (5 s paced) waits at its 12th step until the page has been shot: on a
    # loaded box the screenshot can take longer than the whole episode
    shot_taken, steps_taken, step = threading.Event(), [0], env.step

    def step_after_the_shot(action):
        steps_taken[0] += 1
        if steps_taken[0] == 12:
            shot_taken.wait(timeout=600)
        return step(action)

    env.step = step_after_the_shot
    errors = []
    worker = threading.Thread(target=lambda: errors.append(None) if session.run() else None, daemon=True)
    try:
        worker.start()
        t0 = time.monotonic()
        while session.report.steps < 10 and time.monotonic() - t0 < 120:
            time.sleep(0.1)
        working = screenshot(view.url, ART / "teleop_recording.png", ready=drawn)
        assert session.control.phase.value != "review", "the episode ended before the page was shot"
        shot_taken.set()
        while session.control.phase.value != "review" and time.monotonic() - t0 < 600:
            time.sleep(0.2)
        assert session.control.phase.value == "review"

        def changed(img):  # the review frame is published just after the phase turns to review
            return drawn(img) and (np.abs(working.astype(int) - img.astype(int)).max(axis=2) > 40).mean() > 0.005

        review = screenshot(view.url, ART / "teleop_review.png", ready=changed)
    finally:
        shot_taken.set()
        session.request_stop()
        worker.join(timeout=60)
    assert not worker.is_alive() and errors == [None]
    assert len(session.report.saved) == 1
    assert pad_pixels(working) > 100 and pad_pixels(review) > 100
    assert len(hue_bins(review)) >= 3, hue_bins(review)
    assert (np.abs(working.astype(int) - review.astype(int)).max(axis=2) > 40).mean() > 0.005
