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


def recording_cpu() -> bool:
    """Whether this host's CPU is of the kind the shipped policies' CPU evaluations were recorded on
    (an AMD EPYC): Warp compiles its CPU kernels with ``-march=native``, so their float results,
    and a chaotic contact episode's steps, are bit-identical on one kind of CPU, not across kinds
    (on a 2-core Intel Xeon, 2026-12-06, the same code took 1-106 more steps or missed 2 of 6)."""
    try:
        text = pathlib.Path("/proc/cpuinfo").read_text()
    except OSError:
        return False
    return "AMD EPYC" in text
