"""Crash safety: SIGKILL of a recording process at random moments never corrupts or loses a finished
episode, and never makes a partial one visible."""

from __future__ import annotations

import hashlib
import os
import pathlib
import random
import signal
import subprocess
import sys
import time

import pytest
from test_recording_helpers import record_episodes

from defgrasp_env.recording import list_episodes, validate_episode
from defgrasp_env.recording.atomic import is_temp, remove_stale_temps

ROOT = pathlib.Path(__file__).resolve().parents[1]

# Records short real episodes forever (the real recorder and env).
ENV_CHILD = """
import sys, numpy as np, gymnasium as gym, defgrasp_env
from defgrasp_env.recording import HDF5Recorder
env = HDF5Recorder(gym.make("DeformablePickup-v0", max_episode_steps=4), sys.argv[1])
print("READY", flush=True)
for seed in range(10_000):
    env.reset(seed=seed)
    done = False
    while not done:
        _, _, te, tr, _ = env.step(np.zeros(7, np.float32))
        done = te or tr
    print("SAVED", env.last_path, flush=True)
"""

# Rewrites a real episode under new names as fast as it can: most kill points land inside a write.
WRITER_CHILD = """
import sys, itertools, os
from defgrasp_env.recording import load_episode
from defgrasp_env.recording.atomic import write_episode
ep = load_episode(sys.argv[2])
print("READY", flush=True)
for i in itertools.count():
    path = f"{sys.argv[1]}/copy_{i:05d}.h5"
    if not os.path.exists(path):
        print("SAVED", write_episode(path, ep.data, dict(ep.attrs), ep.names, compression="gzip"), flush=True)
"""


def _digest(path: pathlib.Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _kill_at_random(code: str, args: list[str], delay: float) -> list[pathlib.Path]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-c", code, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True, env=env, cwd=ROOT)
    try:
        line = proc.stdout.readline()
        assert line.startswith("READY"), f"child did not start: {line!r}"
        time.sleep(delay)
        proc.send_signal(signal.SIGKILL)
        out, _ = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    return [pathlib.Path(line.split(" ", 1)[1]) for line in out.splitlines() if line.startswith("SAVED ")]


def _check_directory(d: pathlib.Path, reported: list[pathlib.Path], before: dict[pathlib.Path, str], what: str):
    visible = list_episodes(d)
    for p in visible:
        report = validate_episode(p)
        assert report.ok, f"{what}: visible file {p.name} is invalid: {report.errors}"
    for p in reported:
        assert p in visible, f"{what}: reported episode {p.name} is missing"
    for p, digest in before.items():
        assert p.exists() and _digest(p) == digest, f"{what}: finished episode {p.name} was changed"
    remove_stale_temps(d)
    assert not [p for p in d.iterdir() if is_temp(p)], f"{what}: stale temp files were not cleaned"


@pytest.mark.parametrize("seed, rounds, low, high", [
    (1234, 3, 0.05, 0.6),
    pytest.param(7, 6, 0.0, 1.0, marks=pytest.mark.slow, id="many"),
])
def test_sigkill_during_fast_writes_never_corrupts_or_loses_an_episode(tmp_path, seed, rounds, low, high):
    """The writer child is SIGKILLed ``rounds`` times after a random delay in [low, high] s."""
    template = record_episodes(tmp_path / "template", seeds=(0,), steps=6)[0]
    d = tmp_path / "out"
    d.mkdir()
    rng = random.Random(seed)
    for round_ in range(rounds):
        before = {p: _digest(p) for p in list_episodes(d)}
        delay = rng.uniform(low, high)
        reported = _kill_at_random(WRITER_CHILD, [str(d), str(template)], delay)
        _check_directory(d, reported, before, f"round {round_} (kill after {delay:.3f} s)")
    assert len(list_episodes(d)) >= 3


def test_sigkill_of_a_real_recording_session(tmp_path):
    rng = random.Random(99)
    for round_ in range(2):
        before = {p: _digest(p) for p in list_episodes(tmp_path)}
        delay = rng.uniform(0.3, 1.5)
        reported = _kill_at_random(ENV_CHILD, [str(tmp_path)], delay)
        _check_directory(tmp_path, reported, before, f"env round {round_} (kill after {delay:.3f} s)")


