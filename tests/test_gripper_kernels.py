"""``gripper.kernels`` (the batched gripper's Warp functions) against the numpy reference functions
they carry out (``driver.driver_step``, ``driver.update_grip_stiffness``, ``wrist.analytic.fk_analytic``,
``transforms.quat_to_matrix``, ``linkage.pad_centers`` / ``theta_from_gap``,
``wrist.force_limit.actuator_load``) on random inputs over every regime of their rules. Tolerance:
float64 rounding (rtol 1e-12; the compiled code may contract a product and a sum into one rounding
where numpy rounds twice); the rules' branches must agree exactly."""

import numpy as np
import pytest
import warp as wp

from defgrasp_env.gripper import GAP_MAX, GAP_MIN, GripperConfig, driver_step, pad_centers, theta_from_gap, update_grip_stiffness
from defgrasp_env.gripper import kernels as gk
from defgrasp_env.transforms import quat_to_matrix
from defgrasp_env.wrist import fk_analytic
from defgrasp_env.wrist.force_limit import actuator_load, wrist_force

F = wp.float64


@wp.kernel
def _driver(cmd: wp.array(dtype=F), gap: wp.array(dtype=F), fl: wp.array(dtype=F), fr: wp.array(dtype=F),
            k: wp.array(dtype=F), max_move: F, limit: F, out: wp.array(dtype=F)):
    i = wp.tid()
    out[i] = gk.driver_gap(cmd[i], gap[i], max_move, fl[i], fr[i], k[i], limit)


@wp.kernel
def _stiffness(k: wp.array(dtype=F), g0: wp.array(dtype=F), g1: wp.array(dtype=F), f0: wp.array(dtype=F),
               f1: wp.array(dtype=F), cmd: wp.array(dtype=F), out: wp.array(dtype=F)):
    i = wp.tid()
    out[i] = gk.grip_stiffness_after(k[i], g0[i], g1[i], f0[i], f1[i], cmd[i])


@wp.kernel
def _kinematics(q: wp.array(dtype=gk.vec6d), gap: wp.array(dtype=F), quat: wp.array(dtype=wp.vec4d),
                rot: wp.array(dtype=wp.mat33d), left: wp.array(dtype=wp.vec3d), clamped: wp.array(dtype=gk.vec6d)):
    i = wp.tid()
    quat[i] = gk.flange_quat(q[i])
    rot[i] = gk.quat_matrix(quat[i])
    left[i] = gk.left_pad_center(gap[i])
    clamped[i] = gk.clamp_joints(q[i])


@wp.kernel
def _load(pads: wp.array2d(dtype=wp.vec3d), tip: wp.array(dtype=wp.vec2d), wrist_limit: F, grip_limit: F,
          out: wp.array(dtype=F)):
    i = wp.tid()
    out[i] = gk.actuator_load(pads[i, 0], pads[i, 1], tip[i][0], tip[i][1], wrist_limit, grip_limit)


def _run(kernel, n, inputs, outputs):
    arrays = [wp.array(a, dtype=t, device="cpu") if isinstance(a, np.ndarray) else a for a, t in inputs]
    outs = [wp.zeros(n, dtype=t, device="cpu") for t in outputs]
    wp.launch(kernel, dim=n, inputs=arrays, outputs=outs, device="cpu")
    return [o.numpy() for o in outs]


def test_jaw_driver_matches_driver_step_in_every_regime():
    """Closing and opening, within and beyond the speed limit, stiffness unknown (force stop at the
    limit) and known (regulated: shortened, reversed above the limit), commands outside the stroke."""
    rng = np.random.default_rng(0)
    n = 20000
    config = GripperConfig(closing_speed_mm_s=120.0, grip_force_limit=35.0)
    dt = 0.0125
    gap = rng.uniform(GAP_MIN, GAP_MAX, n)
    cmd = np.where(rng.random(n) < 0.3, rng.uniform(-0.01, 0.1, n), gap + rng.normal(0.0, 0.004, n))
    forces = rng.choice([0.0, 10.0, 35.0, 60.0], (n, 2)) + rng.uniform(0.0, 5.0, (n, 2)) * (rng.random((n, 2)) < 0.5)
    k = np.where(rng.random(n) < 0.5, 0.0, 10.0 ** rng.uniform(2, 7, n))
    expected, stopped = driver_step(config, cmd, gap, dt, forces[:, 0], forces[:, 1], k)
    assert 0.05 < stopped.mean() < 0.6  # the force rules act in a good share of the draws
    (got,) = _run(_driver, n, [(cmd, F), (gap, F), (forces[:, 0].copy(), F), (forces[:, 1].copy(), F), (k, F),
                               (config.closing_speed * dt, None), (config.grip_force_limit, None)], [F])
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)


def test_grip_stiffness_matches_update_grip_stiffness_in_every_regime():
    """Secant while touching, first touch (kept if larger), coasting halved, release to 0, small
    estimates to 0, the clip at MAX_GRIP_STIFFNESS."""
    rng = np.random.default_rng(1)
    n = 20000
    k = np.where(rng.random(n) < 0.4, 0.0, 10.0 ** rng.uniform(-1, 9, n))
    g0 = rng.uniform(GAP_MIN, GAP_MAX, n)
    g1 = g0 - rng.choice([0.0, 5e-7, 1e-6, 1e-4, -1e-4, 2e-3], n)
    f0 = rng.choice([0.0, 0.04, 0.05, 3.0, 30.0], n)
    f1 = rng.choice([0.0, 0.04, 0.05, 3.0, 30.0, 1e6], n)
    cmd = np.where(rng.random(n) < 0.5, g1 + 0.01, g1 - 0.01)
    expected = update_grip_stiffness(k, g0, g1, f0, f1, cmd)
    assert len(np.unique(np.sign(expected - k))) == 3 and (expected == 0.0).mean() > 0.1
    (got,) = _run(_stiffness, n, [(k, F), (g0, F), (g1, F), (f0, F), (f1, F), (cmd, F)], [F])
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=0.0)
    np.testing.assert_array_equal(got == 0.0, expected == 0.0)


def test_flange_orientation_rotation_pad_centre_and_joint_clamp_match_numpy():
    """Random joints (gimbal-lock and axis-aligned angles, values beyond the limits) and gaps (beyond
    the stroke too: clipped)."""
    from defgrasp_env.wrist import clamp_joints

    rng = np.random.default_rng(2)
    n = 5000
    q = rng.uniform(-1.0, 1.0, (n, 6)) * [0.5, 0.5, 0.5, 2.0, 2.0, 4.0]
    q[:500, 3:] = rng.choice([0.0, np.pi / 2, -np.pi / 2, np.pi, 1e-12], (500, 3))
    gap = rng.uniform(GAP_MIN - 0.01, GAP_MAX + 0.01, n)
    quat, rot, left, clamped = _run(_kinematics, n, [(q, gk.vec6d), (gap, F)],
                                    [wp.vec4d, wp.mat33d, wp.vec3d, gk.vec6d])
    _, ref_quat = fk_analytic(q)
    np.testing.assert_allclose(quat, ref_quat, rtol=0, atol=1e-15)
    np.testing.assert_allclose(rot, quat_to_matrix(ref_quat), rtol=0, atol=1e-15)
    ref_left = pad_centers(theta_from_gap(np.clip(gap, GAP_MIN, GAP_MAX)))[:, 0]
    np.testing.assert_allclose(left, ref_left, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(clamped, clamp_joints(q))


@pytest.mark.parametrize("wrist_limit", [150.0, np.inf])
def test_actuator_load_matches_numpy(wrist_limit):
    rng = np.random.default_rng(3)
    n = 3000
    pads = rng.normal(0.0, 80.0, (n, 2, 3))
    tip = np.abs(rng.normal(0.0, 100.0, (n, 2)))
    (got,) = _run(_load, n, [(wp.array(pads, dtype=wp.vec3d, device="cpu"), None), (tip, wp.vec2d),
                             (wrist_limit, None), (20.0, None)], [F])
    expected = actuator_load(wrist_force(pads), tip, wrist_limit, 20.0)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=0.0)


@pytest.mark.cuda
def test_a_gripper_on_cuda_matches_one_on_the_cpu():
    """The same control periods (random wrist and jaw targets, forces sensed after each substep,
    force-limit fractions and records) on a CUDA gripper and a CPU one: joints, gaps, pad targets,
    stiffness estimates and hold decisions agree within float64 rounding (the GPU may contract
    products and sums into one rounding)."""
    from defgrasp_env.gripper import Gripper

    rng = np.random.default_rng(4)
    n = 64
    grippers = [Gripper(GripperConfig(), n, device, wrist_force_limit=150.0) for device in ("cpu", "cuda:0")]
    for g in grippers:
        g.reset(np.ones(n, bool), np.stack([np.linspace(-0.1, 0.1, n), np.zeros(n)], axis=1))
    held = 0
    for period in range(6):
        pos, quat = grippers[0].flange_pose()
        target = pos + rng.normal(0.0, 0.02, (n, 3)) - [0.0, 0.03, 0.0]
        gap = rng.uniform(GAP_MIN, GAP_MAX, n)
        active = rng.random(n) < 0.9
        tips = rng.uniform(0.0, 30.0, (4, n, 2))  # about the 20 N grip limit: the jaw closes and opens
        pads = rng.normal(0.0, 90.0, (4, n, 2, 3))
        fractions = np.where(rng.random((4, n)) < 0.3, rng.choice([0.0, 0.4], (4, n)), 1.0)
        for g in grippers:
            g.begin_step(target, quat, gap, active)
            for k in range(4):
                g.plan_substep(k, 4, 0.0125)
                g.move(fractions[k])
                g.sense(tips[k], pads[k], record_limit=True)
        cpu, gpu = grippers
        for name in ("q", "gap", "grip_stiffness", "tip_force", "pad_force"):
            np.testing.assert_allclose(getattr(gpu, name), getattr(cpu, name), rtol=1e-12, atol=1e-14, err_msg=name)
        for a, b in zip(gpu.pad_target_poses(), cpu.pad_target_poses()):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-14)
        np.testing.assert_array_equal(gpu.held_at_limit()[1], cpu.held_at_limit()[1])
        held += int(cpu.held_at_limit()[1].sum())
    assert held > 0 and np.ptp(cpu.gap) > 0.01


def test_a_back_off_slides_the_flange_along_the_net_pad_force_by_the_planned_slide():
    """``aim_back_off`` then ``move_pads`` at negative fractions against numpy: the flange moves
    from the substep start by -f x the planned slide's length along the sum of the pad forces
    (the object's push), its orientation stays at the start's and the jaw at its start gap (a
    planned closing is not applied; a planned opening is); pad forces whose sum is within
    ``min_force`` (a squeeze) or no planned slide give no back-off. A back-off past a joint limit
    stops at it, and the pads are where the returned joints put them (the same kernel moving
    those joints as planned, independently)."""
    from defgrasp_env.gripper.gripper import PAD_BACKING, PAD_BOX_HALF_EXTENTS, GROUND_CLEARANCE
    from defgrasp_env.wrist.spec import JOINT_LOWER, JOINT_UPPER

    rng = np.random.default_rng(5)
    n = 64
    q_before = np.concatenate([rng.uniform([-0.1, 0.25, -0.1], [0.1, 0.35, 0.1], (n, 3)),
                               rng.uniform(-0.5, 0.5, (n, 3))], axis=1)
    q_plan = q_before + np.concatenate([rng.normal(0.0, 0.01, (n, 3)), rng.normal(0.0, 0.05, (n, 3))], axis=1)
    q_plan[:4, :3] = q_before[:4, :3]                      # no slide planned (a turn only)
    forces = rng.normal(0.0, 50.0, (n, 2, 3))
    forces[4:8, 1] = -forces[4:8, 0] + rng.normal(0.0, 1.0, (4, 3))  # a squeeze: the net force within 10 N
    q_before[8:12, 0] = JOINT_UPPER[0] - 0.001                 # at the x limit, pushed on past it
    forces[8:12] = np.abs(forces[8:12]) * [1.0, 0.0, 0.0] + [40.0, 0.0, 0.0]
    min_force = 10.0
    gap_before = rng.uniform(GAP_MIN + 0.01, GAP_MAX - 0.01, n)
    gap_plan = gap_before + rng.uniform(-0.005, 0.005, n)
    fraction = -rng.uniform(0.05, 1.0, n)

    d = "cpu"
    arr = lambda a, t: wp.array(a, dtype=t, device=d)  # noqa: E731
    qb, qp = arr(q_before, gk.vec6d), arr(q_plan, gk.vec6d)
    back_off = wp.zeros(n, dtype=wp.vec3d, device=d)
    wp.launch(gk.aim_back_off, n, inputs=[arr(forces.reshape(2 * n, 3).astype(np.float32), wp.vec3), qb, qp,
                                          min_force], outputs=[back_off], device=d)

    def move(q_start, q_to, gap_start, gap_to, f, aim):
        outputs = [wp.zeros(n, dtype=gk.vec6d, device=d), wp.zeros(n, dtype=F, device=d),
                   wp.zeros((n, 2), dtype=wp.vec3d, device=d), wp.zeros(n, dtype=wp.vec4d, device=d),
                   wp.zeros(2 * n, dtype=wp.vec3, device=d), wp.zeros(2 * n, dtype=wp.quat, device=d)]
        wp.launch(gk.move_pads, n, inputs=[arr(q_start, gk.vec6d), arr(q_to, gk.vec6d), arr(gap_start, F),
                                           arr(gap_to, F), arr(f, F), aim, wp.vec3d(*PAD_BOX_HALF_EXTENTS),
                                           PAD_BACKING, GROUND_CLEARANCE], outputs=outputs, device=d)
        return [o.numpy() for o in outputs]

    q, gap, centers = move(q_before, q_plan, gap_before, gap_plan, fraction, back_off)[:3]
    still = move(q, q, gap, gap, np.ones(n), wp.zeros(n, dtype=wp.vec3d, device=d))
    np.testing.assert_array_equal(still[2], centers)  # the pads where the joints put them

    net = forces.astype(np.float32).astype(np.float64).sum(axis=1)
    slide = np.linalg.norm(q_plan[:, :3] - q_before[:, :3], axis=1)
    size = np.linalg.norm(net, axis=1)
    aim = (size > min_force) & (slide > 0.0)
    step = np.where(aim[:, None], net * (slide / np.where(aim, size, 1.0))[:, None], 0.0)
    expected = np.clip(q_before[:, :3] - fraction[:, None] * step, JOINT_LOWER[:3], JOINT_UPPER[:3])
    np.testing.assert_allclose(q[:, :3], expected, rtol=1e-12, atol=1e-12)
    assert (q[8:12, 0] == JOINT_UPPER[0]).all()                      # stopped at the limit
    np.testing.assert_array_equal(q[:, 3:], q_before[:, 3:])
    np.testing.assert_array_equal(gap, np.maximum(gap_plan, gap_before))
    np.testing.assert_array_equal(q[:8, :3], q_before[:8, :3])        # nothing to back off along
    assert not aim[:8].any() and aim[8:].all()
    assert (np.linalg.norm(q[8:, :3] - q_before[8:, :3], axis=1) > 0.0).all()
    # the back-off is along the push: the pads move the way the object pushes them
    assert (np.einsum("ij,ij->i", q[12:, :3] - q_before[12:, :3], net[12:]) > 0.0).all()
