"""Every kernel module of the package compiles for a GPU (sm_90 PTX by NVRTC, which the warp-lang wheel
carries: no GPU or driver needed). Most sessions have no GPU, and a CUDA-only code path (``__CUDA_ARCH__``
branches such as ``block_sync.compiled_for_cpu`` or ``block_memory``'s shared array, barriers, float64
atomics) is otherwise first compiled where a device is lent: this catches a kernel that no longer builds
for CUDA on the CPU machine. It does not run anything on a GPU."""

from __future__ import annotations

import importlib
import pathlib

import pytest
import warp as wp

ROOT = pathlib.Path(__file__).resolve().parents[1]
MODULES = sorted(".".join(p.relative_to(ROOT).with_suffix("").parts)
                 for p in (ROOT / "defgrasp_env").rglob("*.py") if "@wp.kernel" in p.read_text())


def test_the_kernel_modules_are_found():
    assert len(MODULES) >= 20 and "defgrasp_env.sim.kernels.world_evaluate" in MODULES


@pytest.mark.slow
@pytest.mark.parametrize("name", MODULES)
def test_kernel_module_compiles_for_cuda(name, tmp_path):
    wp.init()
    module = importlib.import_module(name)
    try:
        paths = wp.compile_aot_module(module.__name__, arch=90, use_ptx=True, module_dir=tmp_path)
    except RuntimeError as exc:
        if "nvrtc" in str(exc).lower() and "not" in str(exc).lower():
            pytest.skip(f"this Warp build cannot compile CUDA (NVRTC): {exc}")
        raise
    ptx = [p for p in map(pathlib.Path, paths) if p.suffix == ".ptx"]
    assert ptx and ptx[0].stat().st_size > 0, paths
