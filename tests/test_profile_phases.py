"""``benchmarks/profile_phases.py``: the world-block kernels' phases stamped in a copy of the package,
checked against the solver's own report (each Newton iteration one evaluation launch, CG's
iterations), with the shipped package left as it was."""

from __future__ import annotations

import json
import os
import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from profile_phases import KERNELS, _instrument_kernel  # noqa: E402


def test_phases_match_the_solvers_report(tmp_path):
    """A lone cuboid, 2 steps after 1 (random actions, no contact yet: one solve a substep): the
    evaluation's launches are the reported Newton iterations and CG's loop passes the reported CG
    iterations; every kernel runs once a solve (4 substeps a step), every phase's cycles are >= 0
    and each kernel's sum > 0 (the CPU's cycle counter), the phases are named by their row
    functions; the repository's package is not touched."""
    sim = ROOT / "defgrasp_env" / "sim"
    touched = [sim / "solver_launches.py", sim / "kernels" / "block_sync.py",
               *(sim / "kernels" / f"{module}.py" for module, _ in KERNELS)]
    before = [path.read_text() for path in touched]
    out = tmp_path / "phases.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    run = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "profile_phases.py"), "--device", "cpu",
                          "--warmup", "1", "--steps", "2", "--json", str(out)], env=env, cwd=tmp_path,
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    r = json.loads(out.read_text())
    k = r["kernels"]
    assert k["evaluate_world_blocks"]["launches"] == r["reported_newton_iterations"] > 0
    cg = k["cg_world_blocks"]
    assert cg["iterations"] == r["reported_cg_iterations"] > 0
    assert [p["runs"] for p in cg["phases"][:3]] == [cg["iterations"]] * 3  # once an iteration
    assert [k[name]["launches"] for _, name in KERNELS[:1] + KERNELS[-1:]] == [8.0, 8.0]
    for name, kernel in k.items():
        assert kernel["phases"][-1]["runs"] == kernel["launches"], name  # the end stamp: once a launch
        cycles = [p["kcycles_per_run"] for p in kernel["phases"]]
        assert min(cycles) >= 0.0 and sum(cycles) > 0.0, name
    names = " ".join(p["name"] for p in k["evaluate_world_blocks"]["phases"])
    assert "assemble_hessian_row" in names and "evaluate_tet" in names
    # the CPU's one-thread block sums a world's rows in registers (linear_solve.node_products_serial)
    assert cg["phases"][1]["name"] == "node_products_serial + node_product"
    assert [path.read_text() for path in touched] == before


def test_a_kernel_the_script_does_not_know_is_refused():
    source = "def other_world_blocks(\n    threads: int,\n):\n    tid = wp.tid()\n    lane = tid - w * threads\n"
    with pytest.raises(RuntimeError, match="other_world_blocks has 0 block barriers; expected 1 to 13"):
        _instrument_kernel(source, "other_world_blocks", 0)


def test_a_recorded_sequence_can_be_profiled(tmp_path):
    """``--actions`` replays a recorded sequence (``bench_action_replay.py``'s) in a single env and
    sums the phases of ``--window``: each Newton iteration one evaluation launch, as the report says."""
    out = tmp_path / "phases.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    run = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "profile_phases.py"), "--device", "cpu",
                          "--actions", str(ROOT / "benchmarks" / "data" / "operator_torus_e1e7_paced_actions.npz"),
                          "--window", "1", "2", "--json", str(out)], env=env, cwd=tmp_path, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    r = json.loads(out.read_text())
    assert r["steps"] == 2 and r["object"].startswith("torus")
    assert r["kernels"]["evaluate_world_blocks"]["launches"] == r["reported_newton_iterations"] > 0
