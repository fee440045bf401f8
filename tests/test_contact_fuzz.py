"""Adversarial contact through the env (``benchmarks/bench_contact_fuzz.py`` does the work): all 5
objects x the paper's 4 moduli, at the largest legal speeds (2 m/s, 2 pi rad/s, jaw 150 mm/s),
under dive / sideways-sweep / rotate-while-pressing / random action sequences.

Checked on every physics substep, independently of the solver (node positions against the pad
boxes and the ground): no node goes through a pad; no simulation diverges; a step that leaves a
node deeper than 1 mm is always flagged ``sim_penetrated`` (never silently returned); no node
ends a substep deeper than 1 mm (a solve that leaves one deeper is clamped back and flagged);
tip forces within grip limit + wrist limit and the wrist force within its limit, both + 10 %
(the limiter's tolerance) + the cell's ``impact_margin`` (the object's momentum stopped by a
stopped pad within a substep, and its weight; see test_actuator_force_bounds.py, which also
checks other parameters).
"""

from __future__ import annotations

import pathlib
import sys

import pytest

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_contact_fuzz import MODULI, run_cell  # noqa: E402

from defgrasp_env.gripper import GripperConfig  # noqa: E402
from defgrasp_env.sim.meshing import OBJECT_SHAPES  # noqa: E402
from defgrasp_env.wrist.force_limit import DEFAULT_WRIST_FORCE_LIMIT, FORCE_TOLERANCE, tip_force_bound  # noqa: E402

STEPS = 5


@pytest.mark.slow
@pytest.mark.parametrize("e", MODULI)
@pytest.mark.parametrize("name", list(OBJECT_SHAPES))
def test_adversarial_actions(name, e):
    r = run_cell(name, e, STEPS)
    assert r["crossed"] == 0
    assert r["diverged"] == 0
    assert r["unflagged"] == 0
    assert r["deepest"] < 1e-3, r["deepest"]
    grip = GripperConfig().grip_force_limit
    assert r["substeps"] > 0, r  # the monitor saw the solves
    assert r["tip"] <= tip_force_bound(grip, DEFAULT_WRIST_FORCE_LIMIT) * (1 + FORCE_TOLERANCE) + r["impact"], r
    assert r["wrist"] <= DEFAULT_WRIST_FORCE_LIMIT * (1 + FORCE_TOLERANCE) + r["impact"], r
