"""``benchmarks/bench_action_replay.py``: a recorded action sequence replays deterministically (the
same iterations and observation digest twice), its episode ends reset the env, and the shipped
sequence is what its docstring says it is."""

from __future__ import annotations

import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_action_replay import DEFAULT, replay  # noqa: E402


def test_the_shipped_sequence_is_the_operators_stiff_torus():
    data = np.load(DEFAULT)
    assert data["actions"].shape == (160, 8)
    assert (str(data["object"]), float(data["youngs_modulus"]), str(data["action_mode"])) == ("torus", 1e7, "absolute")


def test_a_replay_repeats_bit_for_bit(tmp_path):
    data = np.load(DEFAULT)
    short = tmp_path / "short.npz"
    np.savez(short, actions=data["actions"][:12], object="cuboid", youngs_modulus=1e5, seed=3, action_mode="absolute")
    first, second = replay(short), replay(short)
    assert first["steps"] == 12 and first["rows"].shape == (12, 4)
    assert (first["digest"], first["newton"], first["cg"]) == (second["digest"], second["newton"], second["cg"])
    assert first["newton"] >= 12  # at least one Newton iteration a step
    assert (first["rows"][:, 3] >= 4).all()  # every step solves its 4 substeps at least once
