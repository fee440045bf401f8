"""A real headless Chromium for the viewer tests (Debian package ``chromium``; no browser download).

``require_chromium()`` returns the executable; without one it skips the test with the reason, except
in CI (``CI=true``), where a missing browser FAILS the test (``.ci/run`` installs it).
``screenshot(url, path)`` loads the page with software WebGL (SwiftShader), lets it run for
``wait_ms`` of virtual time (the viser client connects over its websocket and draws the scene) and
writes a PNG; returns the image as uint8 [H, W, 3].
"""

from __future__ import annotations

import os
import pathlib
import shutil
import subprocess
import tempfile

import numpy as np
import pytest

CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def require_chromium() -> str:
    for name in CANDIDATES:
        path = shutil.which(name)
        if path:
            return path
    reason = f"no headless Chromium on PATH (looked for {', '.join(CANDIDATES)}); install it: apt-get install -y chromium"
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(f"CI=true but {reason}")
    pytest.skip(reason)


def screenshot(url: str, path: pathlib.Path, *, size=(900, 650), wait_ms: int = 10000, timeout_s: float = 180.0,
               ready=None, attempts: int = 5) -> np.ndarray:
    """``ready(image) -> bool``: the page has finished drawing (on a loaded machine the viser client can
    still be fading in when the virtual-time budget ends, or its WebGL context can fail to start and
    leave a white page); up to ``attempts`` shots, each in a fresh browser profile with a longer budget
    (at most 3x ``wait_ms``), and the last one is returned whatever it shows (the test's own checks
    then decide); a browser that crashed or hung counts as an attempt."""
    img, error = None, None
    for k in range(attempts):
        try:
            img = _screenshot_once(url, path, size=size, wait_ms=wait_ms * min(k + 1, 3), timeout_s=timeout_s)
        except (RuntimeError, subprocess.TimeoutExpired) as exc:  # a browser that crashed or hung: try again
            error = exc
            continue
        if ready is None or ready(img):
            break
    if img is None:
        raise RuntimeError(f"no screenshot of {url} in {attempts} attempts") from error
    return img


def _screenshot_once(url: str, path: pathlib.Path, *, size, wait_ms: int, timeout_s: float) -> np.ndarray:
    from PIL import Image

    exe = require_chromium()
    path = pathlib.Path(path)
    path.unlink(missing_ok=True)  # never read a previous attempt's picture
    path.parent.mkdir(parents=True, exist_ok=True)  # a test run alone has no artifact folder yet
    profile = pathlib.Path(tempfile.mkdtemp(prefix=f".chromium-profile-{path.stem}-", dir=path.parent))
    cmd = [exe, "--headless", "--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader",
           "--enable-unsafe-swiftshader", "--hide-scrollbars", "--no-first-run", f"--user-data-dir={profile}",
           f"--window-size={size[0]},{size[1]}", f"--virtual-time-budget={wait_ms}", f"--screenshot={path}", url]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
    finally:
        shutil.rmtree(profile, ignore_errors=True)
    if not path.exists():
        raise RuntimeError(f"chromium wrote no screenshot (exit {proc.returncode}): {proc.stderr[-2000:]}")
    return np.asarray(Image.open(path).convert("RGB"))
