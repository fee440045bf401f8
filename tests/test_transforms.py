"""Quaternion / pose helpers: round trips, agreement with scipy and pytorch-kinematics, validation."""

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from defgrasp_env import transforms as tf


def _random_quats(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def test_xyzw_wxyz_round_trip_and_order():
    q = np.array([0.1, 0.2, 0.3, 0.9])
    np.testing.assert_array_equal(tf.xyzw_to_wxyz(q), [0.9, 0.1, 0.2, 0.3])
    np.testing.assert_array_equal(tf.wxyz_to_xyzw(tf.xyzw_to_wxyz(q)), q)


def test_quat_to_matrix_matches_scipy_scalar_last(rng):
    q = _random_quats(rng, 200).reshape(10, 20, 4)
    R = tf.quat_to_matrix(q)
    assert R.shape == (10, 20, 3, 3)
    np.testing.assert_allclose(R, Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(R.shape), atol=1e-12)


def test_wxyz_boundary_matches_pytorch_kinematics(rng):
    from pytorch_kinematics.transforms import rotation_conversions as rc

    q = _random_quats(rng, 50)
    R_pk = rc.quaternion_to_matrix(torch.as_tensor(tf.xyzw_to_wxyz(q))).numpy()
    np.testing.assert_allclose(tf.quat_to_matrix(q), R_pk, atol=1e-12)
    q_pk = tf.wxyz_to_xyzw(rc.matrix_to_quaternion(torch.as_tensor(R_pk)).numpy())
    assert np.all(tf.quat_angle_between(q_pk, q) < 1e-7)


def test_matrix_to_quat_round_trip_all_branches(rng):
    q = _random_quats(rng, 500)
    # near-180 degree rotations about each axis exercise the x, y, z branches of Shepperd's method
    extra = tf.axis_angle_to_quat(np.array([[np.pi - 1e-9, 0, 0], [0, np.pi, 0], [0, 0, np.pi], [0, 0, 0]]))
    q = np.concatenate([q, extra])
    back = tf.matrix_to_quat(tf.quat_to_matrix(q))
    canonical = np.where(q[:, 3:] < 0, -q, q)
    assert np.all(back[:, 3] >= 0)
    assert np.all(tf.quat_angle_between(back, q) < 1e-7)
    np.testing.assert_allclose(tf.quat_to_matrix(back), tf.quat_to_matrix(canonical), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(back, axis=-1), 1.0, atol=1e-12)


def test_multiply_matches_matrix_product_and_conjugate_inverts(rng):
    a, b = _random_quats(rng, 100), _random_quats(rng, 100)
    np.testing.assert_allclose(
        tf.quat_to_matrix(tf.quat_multiply(a, b)), tf.quat_to_matrix(a) @ tf.quat_to_matrix(b), atol=1e-12
    )
    ident = tf.quat_multiply(a, tf.quat_conjugate(a))
    np.testing.assert_allclose(ident, np.broadcast_to(tf.IDENTITY_QUAT, ident.shape), atol=1e-12)
    v = rng.normal(size=(100, 3))
    np.testing.assert_allclose(tf.quat_rotate(a, v), np.einsum("nij,nj->ni", tf.quat_to_matrix(a), v), atol=1e-12)


def test_pose_matrix_round_trip_and_inverse(rng):
    q = _random_quats(rng, 64).reshape(8, 8, 4)
    p = rng.uniform(-1, 1, size=(8, 8, 3))
    T = tf.pose_to_matrix(p, q)
    assert T.shape == (8, 8, 4, 4)
    p2, q2 = tf.matrix_to_pose(T)
    np.testing.assert_allclose(p2, p, atol=1e-15)
    assert np.all(tf.quat_angle_between(q2, q) < 1e-7)
    np.testing.assert_allclose(tf.pose_inverse(T) @ T, np.broadcast_to(np.eye(4), T.shape), atol=1e-12)
    # a single orientation broadcasts over many positions
    assert tf.pose_to_matrix(p, tf.IDENTITY_QUAT).shape == (8, 8, 4, 4)


def test_axis_angle_round_trip_matches_scipy(rng):
    v = rng.normal(size=(300, 3))
    v *= (rng.uniform(0, np.pi, size=(300, 1)) / np.linalg.norm(v, axis=-1, keepdims=True))
    q = tf.axis_angle_to_quat(v)
    np.testing.assert_allclose(tf.quat_to_matrix(q), Rotation.from_rotvec(v).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(tf.quat_to_axis_angle(q), v, atol=1e-9)
    tiny = np.array([1e-12, -2e-12, 3e-13])
    np.testing.assert_allclose(tf.quat_to_axis_angle(tf.axis_angle_to_quat(tiny)), tiny, rtol=1e-6, atol=1e-20)
    np.testing.assert_allclose(tf.axis_angle_to_quat(np.zeros(3)), tf.IDENTITY_QUAT)


def test_angle_between_matches_scipy(rng):
    a, b = _random_quats(rng, 200), _random_quats(rng, 200)
    expected = (Rotation.from_quat(a).inv() * Rotation.from_quat(b)).magnitude()
    np.testing.assert_allclose(tf.quat_angle_between(a, b), expected, atol=1e-9)
    np.testing.assert_allclose(tf.quat_angle_between(a, -a), 0.0, atol=1e-12)  # double cover
    small = tf.axis_angle_to_quat([1e-9, 0, 0])
    np.testing.assert_allclose(tf.quat_angle_between(tf.IDENTITY_QUAT, small), 1e-9, rtol=1e-6)


def test_normalize():
    np.testing.assert_allclose(tf.quat_normalize([0, 0, 0, -2.0]), [0, 0, 0, 1.0])
    with pytest.raises(ValueError, match="non-zero norm"):
        tf.quat_normalize(np.zeros(4))


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: tf.quat_to_matrix([0, 0, 1]), r"quat must have shape \[\.\.\., 4\], got \(3,\)"),
        (lambda: tf.quat_to_matrix([0, 0, 0, 2.0]), "unit quaternion .* got norm 2"),
        (lambda: tf.quat_to_matrix([np.nan, 0, 0, 1]), "quat must be finite"),
        (lambda: tf.matrix_to_quat(np.diag([1.0, 1.0, -1.0])), "proper rotation matrix"),
        (lambda: tf.matrix_to_quat(2 * np.eye(3)), "proper rotation matrix"),
        (lambda: tf.pose_to_matrix([0, 0], [0, 0, 0, 1]), r"pos must have shape \[\.\.\., 3\]"),
        (lambda: tf.matrix_to_pose(np.zeros((4, 4))), "last row"),
        (lambda: tf.axis_angle_to_quat([0, np.inf, 0]), "axis_angle must be finite"),
    ],
)
def test_validation_errors(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_float32_unit_quaternions_accepted():
    q = np.array([0.3, -0.1, 0.2, 0.9], dtype=np.float32)
    q = (q / np.linalg.norm(q)).astype(np.float32)
    R = tf.quat_to_matrix(q)
    assert R.dtype == np.float64
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
