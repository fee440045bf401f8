"""Description of the machine a benchmark ran on, for the lines the scripts append to RESULTS.md.

Imported by the scripts in this folder as ``machine`` (``python benchmarks/<script>.py`` puts this
folder first on ``sys.path``).
"""

from __future__ import annotations

import argparse
import os
import pathlib
import platform
import subprocess

_ROOT = pathlib.Path(__file__).resolve().parents[1]


def cpu_model(unknown: str | None = None) -> str:
    """CPU model name from /proc/cpuinfo, else ``platform.processor()``, else ``unknown``
    (``platform.machine()`` when None)."""
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or (platform.machine() if unknown is None else unknown)


def host(unknown: str | None = None, *, cores: str = "CPUs") -> str:
    """``"<CPU model>, <n> logical <cores>, <OS> <release>"``; ``unknown`` as for ``cpu_model``."""
    return f"{cpu_model(unknown)}, {os.cpu_count()} logical {cores}, {platform.system()} {platform.release()}"


def numeric_host() -> dict:
    """What a CPU episode's float results were found to depend on besides the code and the seed: the
    CPU (model name and a digest of its feature flags: Warp compiles CPU kernels for the host's
    features, torch and its BLAS pick kernels by them) and the versions of warp, torch and numpy.
    Hosts that differ here may differ in the last bits of a policy's actions or a solve, and a
    chaotic contact episode then takes other steps (benchmarks/RESULTS.md, 2026-12-08: two AMD EPYCs
    with different feature flags); equal values are what the tests take as the same host (not
    covered: Python, the C library, torch's thread count)."""
    import hashlib

    import numpy
    import torch
    import warp

    flags = ""
    try:
        flags = next((line.split(":", 1)[1] for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines()
                      if line.startswith("flags")), "")
    except OSError:
        pass
    digest = hashlib.sha1(" ".join(sorted(flags.split())).encode()).hexdigest()[:12]
    return {"cpu": cpu_model("unknown"), "cpu_flags": digest, "warp": warp.config.version, "torch": torch.__version__,
            "numpy": numpy.__version__}


def git_state() -> str:
    """Short commit of the checkout, plus any uncommitted or untracked files in the code folders."""
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=_ROOT, capture_output=True,
                             text=True, check=True).stdout.strip()
        code = ["defgrasp_env", "benchmarks", ":(exclude)benchmarks/RESULTS.md"]
        status = subprocess.run(["git", "status", "--porcelain", "--", *code], cwd=_ROOT,
                                capture_output=True, text=True, check=True).stdout.split("\n")
        dirty = [d[3:] for d in status if d.strip() and not d.startswith("??")]
        new = [d[3:] for d in status if d.startswith("??")]
        return (rev + (f" + uncommitted changes in {', '.join(dirty)}" if dirty else "")
                + (f" + untracked {', '.join(new)}" if new else ""))
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


RESULTS = _ROOT / "benchmarks" / "RESULTS.md"


def append_results(text: str, path: str | os.PathLike = RESULTS) -> None:
    """Append a benchmark's report to the results file (benchmarks/RESULTS.md by default)."""
    with open(path, "a", encoding="utf-8") as fh:
        fh.write(text)
    print(f"appended to {path}")


def env_profile_arguments(description: str, device: str, steps: int) -> argparse.ArgumentParser:
    """The arguments of the diagnoses that step the native vector env with random actions
    (``profile_kernels.py``, ``profile_phases.py``): its device, worlds, object and Young's modulus
    (Pa), the untimed warm-up steps and the measured steps."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--device", default=device)
    ap.add_argument("--worlds", type=int, default=1)
    ap.add_argument("--object", default="cuboid")
    ap.add_argument("--youngs-modulus", type=float, default=1e5)
    ap.add_argument("--warmup", type=int, default=10)
    ap.add_argument("--steps", type=int, default=steps)
    return ap
