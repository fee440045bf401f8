"""``Gripper``: the batched gripper-on-a-wrist state the scene drives, tested without the FEM (forces
are handed in by hand), and the scene's single ownership of the physics substeps."""

import ast
import pathlib

import numpy as np
import pytest

import defgrasp_env
from defgrasp_env.envs.config import PickupConfig
from defgrasp_env.envs.scene import PickupScene, WorldSetup
from defgrasp_env.gripper import (GAP_MAX, GAP_MIN, GROUND_CLEARANCE, PAD_BOX_HALF_EXTENTS, START_FLANGE_HEIGHT,
                                  Gripper, GripperConfig, tcp_offset)
from defgrasp_env.sim.materials import Material

ROOT = pathlib.Path(defgrasp_env.__file__).resolve().parents[1]


def _gripper(n=3, **cfg):
    g = Gripper(GripperConfig(**cfg), n)
    g.reset(np.ones(n, bool), np.array([[0.01 * i, -0.02 * i] for i in range(n)]))
    return g


def _period(g, target_pos, target_quat, target_gap, forces, substeps=4, dt=0.05, active=None):
    """One control period driven by hand: ``forces`` [W, 2] N are 'measured' after every substep."""
    active = np.ones(g.num_worlds, bool) if active is None else active
    g.begin_step(target_pos, target_quat, target_gap, active)
    poses = []
    for k in range(substeps):
        poses.append(g.substep(k, substeps, dt / substeps))
        g.sense(forces)
    return poses


def test_reset_state_and_read_only_views():
    g = _gripper()
    pos, quat = g.flange_pose()
    np.testing.assert_allclose(pos, [[0.0, START_FLANGE_HEIGHT, 0.0], [0.01, 0.3, -0.02], [0.02, 0.3, -0.04]])
    np.testing.assert_allclose(quat, np.tile([0, 0, 0, 1.0], (3, 1)), atol=1e-15)  # pointing down
    assert np.all(g.gap == GAP_MAX) and not g.tip_force.any() and not g.grip_stiffness.any()
    for name in ("q", "gap", "tip_force", "grip_stiffness", "pad_force", "wrist_force"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(g, name)[...] = 0.0
    # the tcp hangs below the flange by the linkage's offset
    np.testing.assert_allclose(g.tcp_positions(), pos + tcp_offset(gap=GAP_MAX), atol=1e-12)


def test_jaw_closes_at_its_speed_and_stops_at_the_force_limit():
    g = _gripper(1, closing_speed_mm_s=100.0, grip_force_limit=20.0)
    pos, quat = g.flange_pose()
    _period(g, pos, quat, np.array([GAP_MIN]), np.zeros((1, 2)))
    assert g.gap[0] == pytest.approx(GAP_MAX - 0.1 * 0.05, abs=1e-12)  # 100 mm/s for 50 ms
    # 25 N (above the 20 N limit) measured from now on: the driver sees it one substep late, so the
    # jaw closes one more substep (1.25 mm), estimates k = 2 * 25 N / 1.25 mm at that first touch
    # (gripper.driver), and then opens by (25 - 20) / k in each of the 3 remaining substeps
    _period(g, pos, quat, np.array([GAP_MIN]), np.full((1, 2), 25.0))
    k = 2 * 25.0 / 0.00125
    assert g.gap[0] == pytest.approx(GAP_MAX - 0.005 - 0.00125 + 3 * 5.0 / k, abs=1e-12)
    assert g.grip_stiffness[0] == pytest.approx(k)
    np.testing.assert_array_equal(g.tip_force, [[25.0, 25.0]])


def test_wrist_reaches_its_target_and_pads_never_go_below_the_ground():
    g = _gripper(2)
    pos, quat = g.flange_pose()
    target = pos + [[0.05, -0.1, 0.0], [0.0, -1.0, 0.0]]  # world 1: far into the ground
    poses = _period(g, target, quat, g.gap.copy(), np.zeros((2, 2)))
    new_pos, _ = g.flange_pose()
    np.testing.assert_allclose(new_pos[0], target[0], atol=1e-9)
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * PAD_BOX_HALF_EXTENTS
    for centers, quats in poses:
        assert centers.shape == (2, 2, 3) and quats.shape == (2, 2, 4)
        lowest = (centers[:, :, None, :] + corners)[..., 1].min(axis=(1, 2))  # quats are identity here
        assert np.all(lowest >= GROUND_CLEARANCE - 1e-12)
    assert lowest[1] == pytest.approx(GROUND_CLEARANCE, abs=1e-12)  # lifted exactly to the clearance


def test_inactive_worlds_keep_wrist_and_jaw_bit_for_bit():
    g = _gripper(2)
    pos, quat = g.flange_pose()
    q0, gap0 = g.q.copy(), g.gap.copy()
    _period(g, pos + 0.05, quat, np.full(2, GAP_MIN), np.zeros((2, 2)), active=np.array([True, False]))
    assert np.array_equal(g.q[1], q0[1]) and g.gap[1] == gap0[1]
    assert not np.array_equal(g.q[0], q0[0]) and g.gap[0] < gap0[0]


def test_move_fraction_scales_the_wrist_and_the_closing_jaw_only():
    """``move(fraction)``: the wrist moves ``fraction`` of its planned substep motion, the jaw
    ``fraction`` of a planned closing (world 0) but all of a planned opening (world 1), and a retry
    from the same plan with fraction 1 gives the unscaled substep bit for bit."""
    g = _gripper(2)
    g.begin_step(*g.flange_pose(), np.full(2, GAP_MIN))
    g.substep(0, 1, 0.05)  # both close 7.5 mm
    g.sense(np.zeros((2, 2)))
    pos, quat = g.flange_pose()
    q0, gap0 = g.q.copy(), g.gap.copy()
    g.begin_step(pos + np.array([0.0, -0.02, 0.0]), quat, np.array([GAP_MIN, GAP_MAX]))
    g.plan_substep(0, 1, 0.05)
    g.move(np.ones(2))
    q_full, gap_full = g.q.copy(), g.gap.copy()
    assert gap_full[0] < gap0[0] and gap_full[1] > gap0[1]
    g.move(np.array([0.25, 0.25]))
    np.testing.assert_allclose(g.q, q0 + 0.25 * (q_full - q0), atol=1e-12)
    assert g.gap[0] == pytest.approx(gap0[0] + 0.25 * (gap_full[0] - gap0[0]), abs=1e-12)
    assert g.gap[1] == gap_full[1]
    g.move(np.ones(2))
    assert np.array_equal(g.q, q_full) and np.array_equal(g.gap, gap_full)


def test_scene_owns_the_substeps():
    cfg = PickupConfig()
    setup = WorldSetup("cuboid", Material(500.0, 1e5, 0.3), np.zeros(3), np.array([0, 0, 0, 1.0]))
    scene = PickupScene(cfg, [setup])
    assert scene.substeps == cfg.solver.substeps == 4 and scene.solver.config.substeps == 1
    calls = []
    advance = scene.solver.advance
    scene.solver.advance = lambda *a, **k: calls.append(a[3]) or advance(*a, **k)  # a[3]: dt
    scene.period_graphs = False  # every solve through ``advance``
    pos, quat = scene.gripper.flange_pose()
    scene.step(pos, quat, scene.gripper.gap.copy())
    assert calls == [cfg.dt / 4] * 4


def test_camera_task_and_recorders_use_public_scene_accessors():
    public = {"config", "num_worlds", "gripper", "model", "state", "solver", "substeps", "object_names", "setups",
              "materials", "mesh", "node_positions", "feature_points", "keypoint_positions", "finite", "pad_embedding", "step",
              "device_readouts", "solve_report", "step_to_gripper_targets",
              "reset_worlds"}
    files = [ROOT / "defgrasp_env/envs" / n for n in ("common.py", "task.py", "actions.py", "pickup_env.py",
                                                       "vector_env.py")]
    files += sorted((ROOT / "defgrasp_env/recording").glob("*.py"))
    used = set()
    for path in files:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Attribute) and isinstance(node.value, (ast.Name, ast.Attribute)):
                owner = node.value.id if isinstance(node.value, ast.Name) else node.value.attr
                if owner == "scene":
                    used.add((path.name, node.attr))
    assert {attr for _, attr in used} <= public, sorted(u for u in used if u[1] not in public)
    for attr in public - {"config", "num_worlds", "gripper", "model", "state", "solver", "substeps"}:
        assert hasattr(PickupScene, attr)


def test_lift_puts_the_lowest_pad_corner_at_the_clearance():
    """Against all 16 pad-box corners enumerated (independent of the closed form the lift uses),
    for random wrist poses (gimbal-lock and axis-aligned angles included) and gaps: no corner ends
    below GROUND_CLEARANCE, a lifted world's lowest corner is exactly at it (float64 rounding), an
    unlifted one is left as it was, and the returned pad poses are those of the returned joints."""
    from defgrasp_env.gripper.gripper import _CORNER_SIGNS, lift_above_ground
    from defgrasp_env.transforms import quat_rotate

    rng = np.random.default_rng(7)
    n = 4000
    q = np.zeros((n, 6))
    q[:, 0], q[:, 2] = rng.uniform(-0.3, 0.3, n), rng.uniform(-0.3, 0.3, n)
    q[:, 1] = rng.uniform(-0.05, 0.3, n)
    q[:, 3:] = rng.uniform(-1.5, 1.5, (n, 3))
    q[:400, 3:] = rng.choice([0.0, np.pi / 2, -np.pi / 2, 1e-12], (400, 3))
    gap = rng.uniform(GAP_MIN, GAP_MAX, n)
    g = _gripper(n)
    lifted, centers, quats = lift_above_ground(q, gap)
    corners = centers[:, :, None, :] + quat_rotate(quats[:, :, None, :], _CORNER_SIGNS * PAD_BOX_HALF_EXTENTS)
    lowest = corners[..., 1].reshape(n, -1).min(axis=1)
    raised = lifted[:, 1] > q[:, 1]
    assert 100 < raised.sum() < n - 100
    assert np.all(lowest >= GROUND_CLEARANCE - 1e-15)
    np.testing.assert_allclose(lowest[raised], GROUND_CLEARANCE, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(lifted[~raised], q[~raised])
    ref_centers, ref_quats = g.pad_poses(lifted, gap)
    np.testing.assert_allclose(centers, ref_centers, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(quats, ref_quats)


def test_wrist_limit_retries_solve_from_the_untouched_substep_start():
    """The wrist pressing a stiff cuboid down into the ground with a 1 N limit: the scene retries
    substeps; every solve reads the scene's current state, which no solve writes (the double
    buffer), and the state after each substep is the last solve's output."""
    cfg = PickupConfig(wrist_force_limit=1.0)
    setup = WorldSetup("cuboid", Material(500.0, 1e7, 0.3), np.zeros(3), np.array([0, 0, 0, 1.0]))
    scene = PickupScene(cfg, [setup])
    solves = []
    advance = scene.solver.advance

    def checked(state_in, state_out, control, dt, patient=None, worlds=None, **kwargs):
        assert state_in is scene.state and state_out is not state_in
        before = state_in.positions.numpy().copy()
        advance(state_in, state_out, control, dt, patient, worlds, **kwargs)
        np.testing.assert_array_equal(state_in.positions.numpy(), before)
        solves.append(state_out)

    scene.solver.advance = checked
    scene.period_graphs = False  # every solve through ``advance``, checked one by one
    pos, quat = scene.gripper.flange_pose()
    steps = 30
    for k in range(steps):  # down at 0.1 m/s from 0.3 m: the closed pads reach the cuboid's top at ~0.19 m
        pos[:, 1] -= 0.005
        substeps_before = len(solves)
        scene.step(pos, quat, np.full(1, GAP_MIN))
        assert scene.state is solves[-1] and len(solves) >= substeps_before + scene.substeps
    assert len(solves) > steps * scene.substeps  # the limit did retry
    assert scene.gripper.wrist_force[0] <= 1.0 * 1.1 + 5.0


@pytest.mark.parametrize("substeps", [5, 4])
def test_state_is_the_same_object_after_every_step(substeps):
    """Zero-copy views of ``scene.state`` see every step: the two alternating states end a step of
    an odd number of substeps with a copy back, so ``state`` is the same object after each step."""
    from defgrasp_env.sim.solver import SolverConfig

    cfg = PickupConfig(solver=SolverConfig(substeps=substeps))
    setup = WorldSetup("cuboid", Material(500.0, 1e5, 0.3), np.array([0.0, 0.01, 0.0]), np.array([0, 0, 0, 1.0]))
    scene = PickupScene(cfg, [setup])
    assert scene.substeps == substeps
    state, view = scene.state, scene.state.positions.numpy()  # on the CPU: a view of the array
    first = view.copy()
    pos, quat = scene.gripper.flange_pose()
    for _ in range(2):
        scene.step(pos, quat, scene.gripper.gap.copy())
        assert scene.state is state
    assert not np.array_equal(view, first)  # the object fell 1 cm: the view saw it
    np.testing.assert_array_equal(view, scene.state.positions.numpy())


def test_held_at_limit_only_for_the_same_push():
    """``held_at_limit``: after a try stopped by the force limit (down at 0.3 m/s, jaw closing), a
    world stays held under the same push (any speed, or within ~26 degrees, with a turn of the
    wrist or not: the limit stops a try's turn with its slide) at load >= 1; it tries to move when
    the command turns away (a slow lift, a stop with the jaw still closing, a push more than 26
    degrees off, a turn without a slide), when its load fell below the limit, and after a substep
    that moved.
    A held substep keeps the stopped push, so a command turning by small steps is released once it
    is 26 degrees off the push that was stopped."""
    down, quat = np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0])
    h, start = 0.0125, np.array([0.0, START_FLANGE_HEIGHT, 0.0])

    def plan(g, velocity, gap=0.0, turn=0.0):
        c, s = np.cos(turn / 2), np.sin(turn / 2)
        g.begin_step(np.tile(start + 0.05 * np.asarray(velocity), (g.num_worlds, 1)),
                     np.tile([0.0, s, 0.0, c] if turn else quat, (g.num_worlds, 1)), np.full(g.num_worlds, gap))
        g.plan_substep(0, 4, h)

    def held():
        return g.held_at_limit()[1]

    def sense(pads, moved=None):
        """Pad forces [1, 2, 3] sensed; ``moved``: the force limit's accepted fraction of the planned
        substep (recorded: ``sense(record_limit=True)``), None: no limit outcome recorded."""
        if moved is not None:
            g.move(np.full(1, moved))
        g.sense(np.zeros((1, 2)), pads, record_limit=moved is not None)

    g = Gripper(GripperConfig(), 1, wrist_force_limit=150.0)
    g.reset(np.ones(1, bool), np.zeros((1, 2)))
    at_limit = np.array([[[0.0, 150.0, 0.0], [0.0, 0.0, 0.0]]])  # the wrist force at its 150 N limit: load 1
    below = 0.99 * at_limit
    sense(at_limit)
    plan(g, 0.3 * down)
    assert g.held_at_limit()[0][0] == 1.0
    assert not held()[0]                            # nothing stopped yet: it tries
    sense(at_limit, moved=0.0)                      # the try was stopped
    cases = {"same push": (0.3 * down, 0.0, True), "slower": (0.05 * down, 0.0, True),
             "20 degrees off": (0.3 * np.array([np.sin(0.35), -np.cos(0.35), 0.0]), 0.0, True),
             "35 degrees off": (0.3 * np.array([np.sin(0.61), -np.cos(0.61), 0.0]), 0.0, False),
             "slow lift": (-0.05 * down, 0.0, False), "stop": (np.zeros(3), 0.0, False),
             "same push, turning wrist": (0.3 * down, 0.3, True), "turning wrist only": (np.zeros(3), 0.3, False)}
    for name, (velocity, turn, expected) in cases.items():
        plan(g, velocity, turn=turn)
        assert held()[0] == expected, name
    sense(below)
    plan(g, 0.3 * down)
    assert not held()[0]                            # the object gave way: try again
    sense(at_limit)
    # a held substep keeps the stopped push; a command turning 15 degrees at a time is released at 30
    for angle, expected in ((0.26, True), (0.52, False)):
        plan(g, 0.3 * np.array([np.sin(angle), -np.cos(angle), 0.0]))
        assert held()[0] == expected, angle
        sense(at_limit, moved=0.0)
    plan(g, 0.3 * down)                             # 30 degrees off the last stopped push: tried,
    sense(at_limit, moved=0.0)                      # and stopped: "down" is the stopped push again
    plan(g, 0.3 * down)
    assert held()[0]
    sense(below)
    plan(g, 0.3 * down)                             # below the limit: tried, and it moved:
    sense(at_limit, moved=1.0)                      # the stopped push is forgotten
    plan(g, 0.3 * down)
    assert not held()[0]


def test_non_finite_pad_forces_from_the_solver_are_refused():
    """A solve whose pad forces are not finite stops the step with an error naming the world, before
    the gripper's kernels would carry them into the jaw driver and the force limit."""
    setup = WorldSetup("cuboid", Material(500.0, 1e5, 0.3), np.zeros(3), np.array([0, 0, 0, 1.0]))
    scene = PickupScene(PickupConfig(), [setup, setup])
    advance = scene.solver.advance

    def poisoned(state_in, state_out, *args, **kwargs):
        advance(state_in, state_out, *args, **kwargs)
        forces = state_out.pad_normal_force.numpy()
        forces[3] = np.nan  # world 1's right pad
        state_out.pad_normal_force.assign(forces)

    scene.solver.advance = poisoned
    scene.period_graphs = False  # every solve through ``advance``
    pos, quat = scene.gripper.flange_pose()
    with pytest.raises(FloatingPointError, match=r"non-finite pad forces in worlds \[1\]"):
        scene.step(pos, quat, scene.gripper.gap.copy())


def test_begin_step_refuses_a_bad_jaw_target():
    """A non-finite or wrongly shaped jaw target is refused at the step's start, naming it (the
    kernels would clip NaN silently)."""
    g = _gripper(2)
    pos, quat = g.flange_pose()
    with pytest.raises(ValueError, match="target_gap must be finite"):
        g.begin_step(pos, quat, np.array([0.05, np.nan]))
    with pytest.raises(ValueError, match=r"target_gap must have shape \[2\]"):
        g.begin_step(pos, quat, np.full(3, 0.05))
