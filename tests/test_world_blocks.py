"""Each world's Newton iteration in three launches of a block per world, and its substep's start and
end in one each (``SolverConfig.world_block_threads``: ``kernels/world_evaluate.py``, ``world_cg.py``,
``world_newton_step.py``, ``world_start.py``, ``world_finish.py``) against the phase-by-phase
launches over all rows
(``world_block_threads=0``): the same row functions in the same order per world, so on the CPU
(one thread per world) every output must be equal bit for bit; on CUDA (blocks of threads with
barriers between the phases; float atomics in another order) within the tolerances of the other
CPU-vs-CUDA tests."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import defgrasp_env  # noqa: F401
from defgrasp_env.envs.config import PickupConfig
from defgrasp_env.sim.model import ContactParams
from defgrasp_env.sim.solver import (MANY_WORLDS, WORLD_BLOCK_THREADS, WORLD_BLOCK_THREADS_MANY, ImplicitSolver,
                                     SolverConfig, default_world_block_threads)
from contact_rollout import rollout_outputs
from defgrasp_env.sim.materials import Material
from defgrasp_env.sim.meshing import make_object_mesh
from defgrasp_env.sim.model import build_model
from defgrasp_env.sim.state import Control, State
from test_fem_batch import PAD_HALF, REPORT_FIELDS, STATE_ROWS, build, pad_targets, run


def _episode(world_block_threads: int, steps: int, device: str = "cpu"):
    """Three worlds, each with an object drawn per episode (different node and tet counts: the per
    world row ranges), E = 1e5: the expert, the expert with noise and a gripper pressing its object
    into the ground (force-limit retries and patient re-solves), edge contact on, autoresets;
    every output array, the final state and the CG iterations of every step."""
    solver = dataclasses.replace(PickupConfig().solver, world_block_threads=world_block_threads)
    env = gym.make_vec("DeformablePickup-v0", num_envs=3, vectorization_mode="vector_entry_point", object="random",
                       youngs_modulus=1e5, solver=solver, device=device, max_episode_steps=25)
    obs, reset_info = env.reset(seed=11)
    scene = env.unwrapped.scene
    assert scene.solver.world_block_threads == (min(world_block_threads, 1) if device == "cpu" else world_block_threads)
    out = {"reset/object": np.asarray(reset_info["object"]), **rollout_outputs(env, obs, steps, STATE_ROWS, seed=5)}
    env.close()
    return out


def test_world_blocks_give_the_bits_of_the_phase_launches_on_the_cpu():
    """40 steps of three worlds of different objects through an autoreset (episodes of 25 steps),
    with contact from every side: every observation, reward, info and state array equal."""
    steps = 40
    phases = _episode(0, steps)
    worlds = _episode(1, steps)
    assert phases.keys() == worlds.keys()
    differ = [k for k in phases if phases[k].dtype != worlds[k].dtype
              or not np.array_equal(phases[k], worlds[k], equal_nan=phases[k].dtype != object)]
    assert not differ, differ[:10]
    cg = sum(int(phases[f"{k}/info/cg_iterations"].sum()) for k in range(steps))
    assert cg > 1000  # CG ran (its iterations are counted by the world launch too: equal above)
    assert len(set(phases["reset/object"])) > 1, phases["reset/object"]


def test_cpu_world_blocks_keep_the_last_trials_rotations_for_the_next_evaluation():
    """On the CPU the line search's last trial keeps the tets' polar rotations it found
    (``scratch.trial_rotation``), and the next Newton evaluation at those positions uses them instead
    of computing them again (``rotations_at_x``; the phase launches above compute them, with the same
    bits). Independent check: after a step of a cube falling free (no clamp moves a node) the
    outputs pass evaluates the final positions from the same warm start, as the last trial did, and
    must find the same rotations bit for bit; the flag is set where the world line-searched."""
    env = gym.make("DeformablePickup-v0", object="cuboid", youngs_modulus=1e5, device="cpu")
    env.reset(seed=3)
    scene = env.unwrapped.scene
    scene.state.positions.assign(scene.state.positions.numpy() + np.array([0.0, 0.05, 0.0], np.float32))
    env.step(np.zeros(env.action_space.shape, np.float32))
    s = scene.solver.scratch
    assert scene.solver.world_block_threads == 1
    assert s.rotations_at_x.numpy()[0] == 1
    kept, found = s.trial_rotation.numpy(), s.tet_rotation.numpy()
    assert kept.any()
    np.testing.assert_array_equal(kept.view(np.int32), found.view(np.int32))
    env.close()


@pytest.mark.parametrize("config,edges", [(SolverConfig(), True),
                                          (SolverConfig(substeps=3, line_search_steps=0, check_every=0), True),
                                          (SolverConfig(newton_iterations=2, cg_iterations=5, patient_iterations=0), True),
                                          (SolverConfig(), False)],
                         ids=["default", "no_line_search", "short", "no_edge_contact"])
def test_world_block_solver_steps_match_bitwise_and_report_the_same_iterations(config, edges):
    """The FEM batch of ``test_fem_batch`` (three objects, E 1e4-1e6, squeezed, resting, falling):
    14 steps, the step as one graph and launched kernel by kernel, every state array and report
    field bit-identical with and without the world blocks; also without a line search, with
    iteration caps that stop Newton and CG unconverged, and without pad edge contact."""
    for graphs in (None, False):
        reference = _solver_steps(dataclasses.replace(config, world_block_threads=0), graphs, edges)
        worlds = _solver_steps(dataclasses.replace(config, world_block_threads=1), graphs, edges)
        for (got, got_report), (want, want_report) in zip(worlds, reference):
            for name in STATE_ROWS:
                np.testing.assert_array_equal(got[name], want[name], err_msg=name)
            for field in REPORT_FIELDS:
                np.testing.assert_array_equal(getattr(got_report, field), getattr(want_report, field), err_msg=field)
        assert sum(int(r.cg_iterations.sum()) for _, r in reference) > 0


def _solver_steps(config: SolverConfig, graphs, edges: bool = True):
    model, state, control = build((0, 1, 2), contact=ContactParams(edge_contact=edges))
    assert ImplicitSolver(model, config).scratch.edges.active == edges
    solver = ImplicitSolver(model, dataclasses.replace(config, graphs=graphs))
    history = []
    for k in range(1, 15):
        control.pad_target_positions.assign(np.concatenate([pad_targets(w, k) for w in (0, 1, 2)]))
        report = solver.step(state, state, control, 0.05)
        history.append(({name: getattr(state, name).numpy().copy() for name in STATE_ROWS}, report))
    return history


def test_world_block_threads_is_checked_and_its_default_depends_on_the_device():
    """Negative, non-integer, over 256 or (above 32) not a multiple of 32: refused, naming the
    value. None: ``WORLD_BLOCK_THREADS`` of the device kind (one thread per world on the CPU,
    whatever a positive value asks for; on CUDA fewer beyond ``MANY_WORLDS``); 0 turns it off and
    lets CG list its worlds again."""
    for bad in (-1, 1.5, True, 48, 288, 512, 1024):
        with pytest.raises(ValueError, match=f"world_block_threads.*{bad!r}"):
            SolverConfig(world_block_threads=bad)
    for good in (0, 1, 7, 32, 64, 256):
        SolverConfig(world_block_threads=good)
    model, _, _ = build((0, 1, 2))
    assert WORLD_BLOCK_THREADS["cpu"] == 1
    assert default_world_block_threads("cpu", 4096) == 1
    assert WORLD_BLOCK_THREADS["cuda"] == 256 and WORLD_BLOCK_THREADS_MANY == 128 and MANY_WORLDS == 2048
    assert ImplicitSolver(model, SolverConfig()).world_block_threads == 1
    assert ImplicitSolver(model, SolverConfig(world_block_threads=256)).world_block_threads == 1
    off = ImplicitSolver(model, SolverConfig(world_block_threads=0, listed_cg_worlds=2))
    assert off.world_block_threads == 0 and off._listed_cg


@pytest.mark.parametrize("threads", [8, 128])
def test_world_blocks_with_several_threads_a_world_agree_on_the_cpu(threads, monkeypatch):
    """The barriers at work without a GPU: with ``wp.config.enable_cpu_blocks`` a CPU block runs 8 or
    128 (a GPU's block at W > 2048: more threads than coarse unknowns) cooperative threads per world
    (Warp's fibers; ``block_sync`` is their sync), which sum in another order than one thread, and
    assemble and invert the coarse matrix in the block memory. Against the phase launches over 14
    steps of the FEM batch: positions within 1e-5 m (as CUDA against the phase launches; ~1e-6
    measured) and the CG iterations within 10 %. (Checked by hand: without the barrier before
    ``end_iteration`` in ``world_cg`` the positions are 0.12 m off at the first step and worlds
    diverge.)"""
    import warp as wp

    monkeypatch.setattr(wp.config, "enable_cpu_blocks", True)
    model, _, _ = build((0, 1, 2))
    assert ImplicitSolver(model, SolverConfig(world_block_threads=threads)).world_block_threads == threads
    reference = _solver_steps(SolverConfig(world_block_threads=0), None)
    worlds = _solver_steps(SolverConfig(world_block_threads=threads), None)
    for (got, got_report), (want, want_report) in zip(worlds, reference):
        assert not got_report.diverged.any()
        np.testing.assert_allclose(got["positions"], want["positions"], atol=1e-5)
    it0 = sum(int(r.cg_iterations.sum()) for _, r in reference)
    it1 = sum(int(r.cg_iterations.sum()) for _, r in worlds)
    assert abs(it1 - it0) <= 0.1 * it0, (it0, it1)


@pytest.mark.cuda
@pytest.mark.parametrize("threads", [32, 128])
def test_world_blocks_on_cuda_agree_with_the_phase_launches(threads):
    """On CUDA, blocks of 32 and 128 threads per world against the phase launches, W = 3, 14 steps:
    positions within 1e-5 m and the iteration counts within 10 % (as for the listed CG: float
    atomics sum in a run-dependent order); the CPU's result too."""
    _, reference, s0 = run((0, 1, 2), 14, SolverConfig(world_block_threads=0), device="cuda:0")
    _, worlds, s1 = run((0, 1, 2), 14, SolverConfig(world_block_threads=threads), device="cuda:0")
    _, cpu, _ = run((0, 1, 2), 14, SolverConfig(world_block_threads=0), device="cpu")
    assert not any(s.diverged.any() for s in s1)
    np.testing.assert_allclose(worlds[-1][0], reference[-1][0], atol=1e-5)
    for k in (0, 6):  # the first steps, before the falling cylinder's unconverged solves diverge
        np.testing.assert_allclose(worlds[k][0], cpu[k][0], atol=1e-5)
    it0 = sum(int(s.cg_iterations.sum()) for s in s0)
    it1 = sum(int(s.cg_iterations.sum()) for s in s1)
    assert abs(it1 - it0) <= 0.1 * it0, (it0, it1)


@pytest.mark.cuda
def test_world_blocks_on_cuda_through_contact_and_resets():
    """The three-world contact batch of the CPU test on CUDA with blocks of 64 threads: no NaN, no
    diverged world, the same objects, and the gripper's observations within 1 mm of the phase
    launches over the first 8 steps (before a grasp turns float rounding into other episodes)."""
    phases = _episode(0, 30, device="cuda:0")
    worlds = _episode(64, 30, device="cuda:0")
    assert list(worlds["reset/object"]) == list(phases["reset/object"])
    for k in range(30):
        for key in (f"{k}/obs/agent_pos", f"{k}/reward"):
            assert np.isfinite(worlds[key]).all(), key
        assert not worlds[f"{k}/info/sim_diverged"].any(), k
    for k in range(8):  # step 9 is world 2's first grasp: from there rounding makes other episodes
        np.testing.assert_allclose(worlds[f"{k}/obs/agent_pos"], phases[f"{k}/obs/agent_pos"], atol=1e-3)


def _rope_steps(config: SolverConfig, steps: int = 14, device: str = "cpu"):
    """A rope (8 coarse aggregates: 48 coarse unknowns) squeezed across its middle by the pads and
    lifted, beside a squeezed cube (8 aggregates too), E = 1e5: per step the state rows and the report."""
    rope, cube = make_object_mesh("rope"), make_object_mesh("cuboid")
    across = (0.0, float(np.sin(np.pi / 4)), 0.0, float(np.cos(np.pi / 4)))  # the rope along z, pads on +-x
    model = build_model([rope, cube], [Material(youngs_modulus=1e5)] * 2,
                        poses=[((0.0, 0.0, 0.0), across), ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))],
                        pad_half_extents=[PAD_HALF, PAD_HALF], device=device)
    state, control = State.from_model(model), Control.from_model(model)

    def targets(k):
        rows = []
        for reach, squeeze in ((0.008, 5e-5), (0.02, 4e-5)):
            x = reach + PAD_HALF[0] - squeeze * min(k, 8)
            lift = 0.002 * max(k - 8, 0)
            rows.append([[-x, 0.008 + lift, 0.0], [x, 0.008 + lift, 0.0]])
        return np.asarray(rows, np.float32).reshape(-1, 3)

    state.pad_positions.assign(targets(0))
    solver = ImplicitSolver(model, config)
    assert solver.scratch.coarse_sizes.numpy().tolist() == [48, 48]
    if device != "cpu":
        assert (solver.world_block_threads, solver.cg_block_threads) == (config.world_block_threads,
                                                                         config.cg_block_threads)
    history = []
    for k in range(1, steps + 1):
        control.pad_target_positions.assign(targets(k))
        report = solver.step(state, state, control, 0.05)
        history.append(({name: getattr(state, name).numpy().copy() for name in STATE_ROWS}, report))
    return history


def test_world_block_cg_applies_a_rope_coarse_solve_row_by_row_with_the_bits_of_one_thread():
    """The world-block CG applies the coarse solve (the rope's 48 unknowns) a row per thread
    (``coarse_space.coarse_row`` / ``coarse_gain``): on the CPU, every state row and report field equal
    to the phase launches' (which apply it on one thread, ``coarse_coefficients``) over 14 steps
    of a squeezed, lifted rope; with 8 cooperative threads a world (``wp.config.enable_cpu_blocks``,
    the rows then computed by different threads, the other sums in another order) within 1e-5 m
    and 10 % of the CG iterations. (Checked by hand: without the barrier after the rows the
    8-thread rope is 1e-3 m off after the first step.)"""
    import warp as wp

    reference = _rope_steps(SolverConfig(world_block_threads=0))
    rows = _rope_steps(SolverConfig(world_block_threads=1))
    for (got, got_report), (want, want_report) in zip(rows, reference):
        for name in STATE_ROWS:
            np.testing.assert_array_equal(got[name], want[name], err_msg=name)
        for field in REPORT_FIELDS:
            np.testing.assert_array_equal(getattr(got_report, field), getattr(want_report, field), err_msg=field)
    rope_cg = sum(int(r.cg_iterations[0]) for _, r in reference)
    squeeze = max(float(state["pad_normal_force"][:2].min()) for state, _ in reference)
    assert rope_cg > 100 and squeeze > 0.5, (rope_cg, squeeze)  # CG iterated on a rope both pads press
    wp.config.enable_cpu_blocks, before = True, wp.config.enable_cpu_blocks
    try:
        threads = _rope_steps(SolverConfig(world_block_threads=8))
    finally:
        wp.config.enable_cpu_blocks = before
    for (got, got_report), (want, _) in zip(threads, reference):
        assert not got_report.diverged.any()
        np.testing.assert_allclose(got["positions"], want["positions"], atol=1e-5)
    it = sum(int(r.cg_iterations.sum()) for _, r in threads)
    it0 = sum(int(r.cg_iterations.sum()) for _, r in reference)
    assert abs(it - it0) <= 0.1 * it0, (it0, it)


def test_cg_block_threads_is_checked_and_defaults_to_the_world_blocks():
    """``SolverConfig.cg_block_threads``: up to ``MAX_CG_BLOCK_THREADS`` (512: the CG kernel's
    registers), a multiple of 32 above 32, else refused naming the value; None follows
    ``world_block_threads``; the CPU runs one thread per world, and none where the blocks are off."""
    from defgrasp_env.sim.solver import MAX_CG_BLOCK_THREADS

    assert MAX_CG_BLOCK_THREADS == 512
    for bad in (0, -32, 1.5, True, 48, 544, 1024):
        with pytest.raises(ValueError, match=f"cg_block_threads.*{bad!r}"):
            SolverConfig(cg_block_threads=bad)
    for good in (1, 32, 256, 512):
        SolverConfig(cg_block_threads=good)
    model, _, _ = build((0, 1))
    assert ImplicitSolver(model, SolverConfig(cg_block_threads=512)).cg_block_threads == 1
    assert ImplicitSolver(model, SolverConfig(world_block_threads=0, cg_block_threads=512)).cg_block_threads == 0


@pytest.mark.cuda
@pytest.mark.parametrize("cg_threads", [256, 512])
def test_world_block_cg_of_more_threads_on_cuda_agrees_with_the_cpu(cg_threads):
    """On CUDA, the rope and cube of ``_rope_steps`` with blocks of 256 threads a world and CG in
    blocks of 256 or 512 (``cg_block_threads``; the rope's coarse rows a thread each) against the
    CPU's phase launches: positions within 1e-5 m at the first steps and the CG iterations within
    10 % (float atomics sum in a run-dependent order), none diverged."""
    reference = _rope_steps(SolverConfig(world_block_threads=0))
    got = _rope_steps(SolverConfig(world_block_threads=256, cg_block_threads=cg_threads), device="cuda:0")
    assert not any(r.diverged.any() for _, r in got)
    for k in (0, 4):
        np.testing.assert_allclose(got[k][0]["positions"], reference[k][0]["positions"], atol=1e-5)
    it0 = sum(int(r.cg_iterations.sum()) for _, r in reference)
    it1 = sum(int(r.cg_iterations.sum()) for _, r in got)
    assert abs(it1 - it0) <= 0.1 * it0, (it0, it1)
