"""6-DOF wrist: URDF layout, FK (pytorch-kinematics vs manual), closed-form and iterative IK."""

import math

import numpy as np
import pytest

from defgrasp_env import transforms as tf
from defgrasp_env.wrist import (
    JOINT_LOWER,
    JOINT_NAMES,
    JOINT_UPPER,
    WristKinematics,
    fk_analytic,
    fk_matrix_analytic,
    ik_analytic,
)

POS_TOL_M = 1e-3      # the acceptance bounds of eq. 3 in the teleop issue: < 1 mm and < 0.01 rad
ROT_TOL_RAD = 1e-2


@pytest.fixture(scope="module")
def wrist():
    return WristKinematics()


def _translate(v):
    T = np.eye(4)
    T[:3, 3] = v
    return T


def _rotate(axis, angle):
    T = np.eye(4)
    T[:3, :3] = tf.quat_to_matrix(tf.axis_angle_to_quat(np.asarray(axis, float) * angle))
    return T


def _manual_fk(q):
    """Compose the URDF's elementary joint transforms one by one."""
    return (
        _translate([q[0], 0, 0]) @ _translate([0, q[1], 0]) @ _translate([0, 0, q[2]])
        @ _rotate([0, 0, 1], q[3]) @ _rotate([1, 0, 0], q[4]) @ _rotate([0, 1, 0], q[5])
    )


def _sample_q(rng, n, margin=0.02):
    """Joint vectors strictly inside the limits (away from the yaw wrap and the pitch lock)."""
    lo, hi = JOINT_LOWER + margin, JOINT_UPPER - margin
    return rng.uniform(lo, hi, size=(n, 6))


def test_limits_from_urdf(wrist):
    assert JOINT_NAMES == ("slide_x", "slide_y", "slide_z", "roll_z", "pitch_x", "yaw_y")
    h = math.pi / 2
    np.testing.assert_array_equal(JOINT_LOWER, [-0.4, 0.0, -0.4, -h, -h, -math.pi])
    np.testing.assert_array_equal(JOINT_UPPER, [0.4, 1.0, 0.4, h, h, math.pi])
    np.testing.assert_array_equal(wrist.lower, JOINT_LOWER)  # exact, not float32-rounded
    np.testing.assert_array_equal(wrist.upper, JOINT_UPPER)


def test_zero_pose_is_world_aligned_pointing_down(wrist):
    T = wrist.fk_matrix(np.zeros(6))
    np.testing.assert_allclose(T, np.eye(4), atol=1e-15)
    pos, quat = wrist.fk(np.zeros(6))
    np.testing.assert_allclose(pos, 0.0, atol=1e-15)
    np.testing.assert_allclose(quat, [0, 0, 0, 1], atol=1e-15)
    approach = T[:3, :3] @ np.array([0.0, -1.0, 0.0])
    np.testing.assert_allclose(approach, [0, -1, 0])


def test_fk_pytorch_kinematics_matches_manual_composition(wrist):
    rng = np.random.default_rng(0)
    q = rng.uniform(-3, 3, size=(64, 6))  # FK is defined everywhere, limits or not
    T = wrist.fk_matrix(q)
    T_manual = np.stack([_manual_fk(qi) for qi in q])
    np.testing.assert_allclose(T, T_manual, atol=1e-12)
    np.testing.assert_allclose(fk_matrix_analytic(q), T_manual, atol=1e-12)
    pos, quat = wrist.fk(q.reshape(8, 8, 6))
    assert pos.shape == (8, 8, 3) and quat.shape == (8, 8, 4)
    pos_a, quat_a = fk_analytic(q)
    np.testing.assert_allclose(pos.reshape(-1, 3), pos_a, atol=1e-12)
    assert np.all(tf.quat_angle_between(quat.reshape(-1, 4), quat_a) < 1e-9)


def test_reachable_orientations_never_point_up():
    rng = np.random.default_rng(1)
    R = fk_matrix_analytic(rng.uniform(JOINT_LOWER, JOINT_UPPER, size=(2000, 6)))[:, :3, :3]
    assert np.all(R[:, 1, 1] >= -1e-12)  # world-y component of the flange y axis


def test_ik_analytic_exact_on_reachable_targets():
    rng = np.random.default_rng(2)
    q = _sample_q(rng, 1000)
    pos, quat = fk_analytic(q)
    res = ik_analytic(pos, quat)
    assert res.converged.all()
    np.testing.assert_allclose(res.q, q, atol=1e-9)
    assert res.pos_err_m.max() < 1e-12 and res.rot_err_rad.max() < 1e-7


def test_ik_analytic_covers_the_lower_hemisphere_and_gimbal_lock():
    rng = np.random.default_rng(3)
    quat = tf.quat_normalize(rng.normal(size=(2000, 4)))
    up_y = tf.quat_to_matrix(quat)[:, 1, 1]
    res = ik_analytic(np.zeros((2000, 3)) + [0, 0.5, 0], quat)
    assert np.all(res.converged[up_y >= 0.0])
    assert not np.any(res.converged[up_y < -1e-3])
    assert np.all((res.q >= JOINT_LOWER) & (res.q <= JOINT_UPPER))
    # pitch = +-pi/2 (approach horizontal): roll and yaw are coupled, still solved exactly
    for pitch in (math.pi / 2, -math.pi / 2):
        q = np.array([0.1, 0.3, -0.1, 0.4, pitch, -0.7])
        res = ik_analytic(*fk_analytic(q))
        assert res.converged and res.rot_err_rad < 1e-7 and res.pos_err_m < 1e-12


def test_ik_iterative_matches_analytic_warm_start(wrist):
    rng = np.random.default_rng(4)
    q = _sample_q(rng, 200)
    pos, quat = fk_analytic(q)
    q_init = np.clip(q + rng.normal(0.0, 0.1, size=q.shape), JOINT_LOWER, JOINT_UPPER)
    res = wrist.ik(pos, quat, q_init)
    ref = wrist.ik_analytic(pos, quat)
    assert res.converged.all() and ref.converged.all()
    assert res.pos_err_m.max() < POS_TOL_M and res.rot_err_rad.max() < ROT_TOL_RAD
    pos_i, quat_i = wrist.fk(res.q)
    pos_a, quat_a = fk_analytic(ref.q)
    assert np.linalg.norm(pos_i - pos_a, axis=-1).max() < POS_TOL_M
    assert tf.quat_angle_between(quat_i, quat_a).max() < ROT_TOL_RAD
    np.testing.assert_allclose(res.q, ref.q, atol=ROT_TOL_RAD)  # unique solution inside the limits


def test_ik_iterative_cold_start_uses_restarts(wrist):
    rng = np.random.default_rng(5)
    q = _sample_q(rng, 100, margin=0.05)
    pos, quat = fk_analytic(q)
    res = wrist.ik(pos, quat, np.zeros(6))  # one warm start broadcast to all targets
    assert res.converged.all()
    assert res.pos_err_m.max() < POS_TOL_M and res.rot_err_rad.max() < ROT_TOL_RAD


def test_ik_batched_shapes(wrist):
    rng = np.random.default_rng(6)
    q = _sample_q(rng, 12).reshape(3, 4, 6)
    pos, quat = fk_analytic(q)
    res = wrist.ik(pos, quat, q)
    assert res.q.shape == (3, 4, 6)
    assert res.pos_err_m.shape == res.rot_err_rad.shape == res.converged.shape == (3, 4)
    single = wrist.ik(pos[0, 0], quat[0, 0], np.zeros(6))
    assert single.q.shape == (6,) and single.converged.shape == ()
    with pytest.raises(ValueError, match="q_init"):
        wrist.ik(pos, quat, np.zeros((5, 6)))


def test_ik_unreachable_targets_respect_limits(wrist):
    down = np.array([0.0, 0.0, 0.0, 1.0])
    up = tf.axis_angle_to_quat([math.pi, 0.0, 0.0])  # fingers pointing at the sky
    tilted_up = tf.axis_angle_to_quat([0.0, 0.0, 2.5])
    pos = np.array([[1.0, -0.5, 0.0], [0.0, 2.0, -0.9], [0.1, 0.5, 0.1], [0.0, 0.3, 0.0]])
    quat = np.stack([down, down, up, tilted_up])
    for res in (wrist.ik(pos, quat, np.zeros(6)), wrist.ik_analytic(pos, quat)):
        assert not res.converged.any()
        assert np.all((res.q >= JOINT_LOWER) & (res.q <= JOINT_UPPER))
        np.testing.assert_allclose(res.q[:, :3], np.clip(pos, JOINT_LOWER[:3], JOINT_UPPER[:3]), atol=1e-9)
        np.testing.assert_allclose(res.pos_err_m[:2], [math.hypot(0.6, 0.5), math.hypot(1.0, 0.5)], atol=1e-9)
        assert res.rot_err_rad[2] == pytest.approx(math.pi / 2, abs=1e-3)  # nearest: approach horizontal
        assert res.rot_err_rad[3] == pytest.approx(2.5 - math.pi / 2, abs=1e-3)  # roll clamped at pi/2


def test_ik_validation(wrist):
    with pytest.raises(ValueError, match="unit quaternion"):
        wrist.ik([0, 0.5, 0], [0, 0, 0, 2.0], np.zeros(6))
    with pytest.raises(ValueError, match=r"pos must have shape \[\.\.\., 3\]"):
        wrist.ik([0, 0.5], [0, 0, 0, 1.0], np.zeros(6))
    with pytest.raises(ValueError, match="q must be finite"):
        wrist.fk([0, 0, 0, 0, np.nan, 0])
    with pytest.raises(ValueError, match=r"q must have shape \[\.\.\., 6\]"):
        wrist.fk(np.zeros(5))
    with pytest.raises(ValueError, match=r"pos_tolerance must be in \(0, inf\) m"):
        WristKinematics(pos_tolerance=0.0)
    with pytest.raises(ValueError, match="urdf_path must be an existing URDF file"):
        WristKinematics("/nonexistent.urdf")
    with pytest.raises(ValueError, match="torch_threads must be None or an integer"):
        WristKinematics(torch_threads=0)


def test_torch_thread_setting_is_restored(wrist):
    import torch

    before = torch.get_num_threads()
    wrist.ik([0.0, 0.5, 0.0], [0, 0, 0, 1.0], np.zeros(6))
    wrist.fk(np.zeros(6))
    assert torch.get_num_threads() == before
