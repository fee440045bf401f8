"""``benchmarks/bench_env_step.py --split``: the solver's share of each step is measured around every
solve and the solver is left as it was."""

from __future__ import annotations

import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_env_step import SolverClock, run_case  # noqa: E402

from defgrasp_env.sim import ImplicitSolver  # noqa: E402


def test_split_times_every_solve_and_restores_the_solver():
    advance = ImplicitSolver.advance
    row = run_case("cpu", 2, "random", "cuboid", 1e5, warmup=1, steps=3, split=True)
    assert ImplicitSolver.advance is advance
    # per step the solver's time is part of the step's, so its median is too (order statistics)
    assert 0.0 < row["solver_ms"] <= row["median_ms"]
    assert row["outside_ms"] > 0.0
    plain = run_case("cpu", 2, "random", "cuboid", 1e5, warmup=1, steps=1)
    assert np.isnan(plain["solver_ms"]) and np.isnan(plain["outside_ms"])


def test_solver_clock_counts_the_calls_it_wraps_and_unwraps_on_error():
    calls = []

    class Fake:
        pass

    advance = ImplicitSolver.advance

    def fake_advance(self, *args):
        calls.append(args)

    try:
        ImplicitSolver.advance = fake_advance
        try:
            with SolverClock("cpu") as clock:
                ImplicitSolver.advance(Fake(), 1, 2)
                ImplicitSolver.advance(Fake(), 3)
                raise RuntimeError("boom")
        except RuntimeError:
            pass
        assert calls == [(1, 2), (3,)] and clock.seconds > 0.0
        assert ImplicitSolver.advance is fake_advance  # put back although the block raised
    finally:
        ImplicitSolver.advance = advance
