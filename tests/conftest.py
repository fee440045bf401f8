"""Test configuration: caches go to the repo's ignored .cache folder, never to ~."""

import os
import pathlib

_CACHE = pathlib.Path(__file__).resolve().parents[1] / ".cache"
os.environ.setdefault("WARP_CACHE_PATH", str(_CACHE / "warp"))
os.environ.setdefault("HF_HOME", str(_CACHE / "hf"))
os.environ.setdefault("HF_LEROBOT_HOME", str(_CACHE / "lerobot"))
os.environ.setdefault("MPLCONFIGDIR", str(_CACHE / "mpl"))
os.environ.setdefault("MPLBACKEND", "Agg")
# Stable-Baselines3 makes a log folder at every learn() (tempdir/SB3-<time> unless this is set): one, ignored
os.environ.setdefault("SB3_LOGDIR", str(_CACHE / "sb3"))

import pytest  # noqa: E402


def _cuda_available() -> bool:
    import warp as wp

    wp.init()
    return wp.get_cuda_device_count() > 0


def pytest_collection_modifyitems(config, items):
    if _cuda_available():
        return
    skip = pytest.mark.skip(reason="needs a CUDA GPU (run on the device machine)")
    for item in items:
        if "cuda" in item.keywords:
            item.add_marker(skip)


def recorded_here(evaluation: dict) -> bool:
    """Whether this host repeats a recorded CPU evaluation (``benchmarks/eval_ppo.py``'s JSON) bit for
    bit: its ``host`` (``benchmarks/machine.numeric_host``: CPU model and feature flags, warp, torch
    and numpy versions) is this one's. Elsewhere a chaotic contact episode takes other steps (two AMD
    EPYCs with different feature flags, 2026-12-08: 6 of the 6 recorded steps differed)."""
    import sys

    benchmarks = str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks")
    if benchmarks not in sys.path:
        sys.path.insert(0, benchmarks)
    from machine import numeric_host

    return evaluation.get("host") == numeric_host()
