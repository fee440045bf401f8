"""The actions' decoding and the wrist's inverse kinematics on the device (``envs.action_kernels``
through ``DeviceActionDecoder``; ``gripper.kernels.begin_period``) against the numpy reference
they carry out (``envs.actions``' decoders, ``wrist.analytic.ik_joints``, the shortest turn of
``Gripper.begin_step`` before it moved to the device), on random actions of every mode at random
wrist poses (turned, tilted, at the joint limits), zero and full-scale actions, targets beyond the
joint limits and at the gimbal lock. Tolerance: float64 rounding (rtol 1e-12, atol 1e-15: the
compiled sin / cos / atan2 may differ from numpy's in the last bit)."""

import numpy as np
import pytest

from defgrasp_env.envs.actions import DECODERS, DeviceActionDecoder, check_actions
from defgrasp_env.envs.config import PickupConfig
from defgrasp_env.gripper import Gripper, GripperConfig
from defgrasp_env.layout import ACTION_LAYOUTS
from defgrasp_env.transforms import axis_angle_to_quat, quat_multiply
from defgrasp_env.wrist import ik_joints
from defgrasp_env.wrist.spec import JOINT_LOWER, JOINT_UPPER

RTOL, ATOL = 1e-12, 1e-15


def _gripper_at(q: np.ndarray, device="cpu") -> Gripper:
    g = Gripper(GripperConfig(), len(q), device)
    g.arrays.q.assign(q)
    return g


def _random_joints(rng, n):
    q = rng.uniform(JOINT_LOWER, JOINT_UPPER, (n, 6))
    q[: n // 10] = JOINT_UPPER  # at the limits
    q[n // 10: n // 5, 3:] = 0.0  # pointing down
    return q


def _random_actions(rng, n, mode):
    low, high = ACTION_LAYOUTS[mode].bounds()
    a = rng.uniform(low, high, (n, len(low)))
    a[: n // 20] = 0.0
    a[n // 20: n // 10] = np.where(rng.random((n // 20, len(low))) < 0.5, low, high)  # full scale
    if mode == "absolute":
        a[:, 3:7] = rng.normal(size=(n, 4))  # any non-zero quaternion (normalised by the decoder)
    return check_actions(a, a.shape, low, high)


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=pytest.mark.cuda)])
@pytest.mark.parametrize("mode", sorted(DECODERS))
def test_device_decoding_matches_the_numpy_decoders(mode, device):
    n = 3000
    rng = np.random.default_rng(["absolute", "delta", "topdown"].index(mode))
    config = PickupConfig(action_mode=mode, device=device, max_linear_speed=1.7, max_angular_speed=4.0)
    q = _random_joints(rng, n)
    actions = _random_actions(rng, n, mode)
    want_pos, want_quat, want_gap = DECODERS[mode](_gripper_at(q), config, actions)
    g = _gripper_at(q, device)
    DeviceActionDecoder(config, n).decode(g, actions)
    np.testing.assert_allclose(g.targets.position.numpy(), want_pos, rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(g.targets.orientation.numpy(), want_quat, rtol=RTOL, atol=1e-14)
    np.testing.assert_allclose(g.targets.gap.numpy(), want_gap, rtol=RTOL, atol=ATOL)


def test_absolute_decoding_rejects_a_zero_quaternion_before_any_upload():
    config = PickupConfig(action_mode="absolute")
    g = _gripper_at(np.zeros((2, 6)))
    actions = np.array([[0, 0.3, 0, 0, 0, 0, 1, 0.05], [0, 0.3, 0, 0, 0, 0, 0, 0.05]], np.float64)
    with pytest.raises(ValueError, match="quaternion must be non-zero"):
        DeviceActionDecoder(config, 2).decode(g, actions)


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=pytest.mark.cuda)])
def test_begin_period_matches_numpy_ik_and_the_shortest_turn(device):
    """``begin_period``'s joint motion = ``ik_joints(target)`` - q with the angles wrapped to
    [-pi, pi) (the numpy ``begin_step``), for targets within and beyond the limits, pointing down,
    turned past pi from the start and at the gimbal lock (flange y axis along world z; there within
    asin's conditioning at 1, below)."""
    n = 4000
    rng = np.random.default_rng(11)
    q = _random_joints(rng, n)
    pos = rng.uniform(-0.6, 1.2, (n, 3))
    quat = rng.normal(size=(n, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    quat[:200] = axis_angle_to_quat(np.column_stack([np.zeros(200), rng.uniform(-6, 6, 200), np.zeros(200)]))
    # gimbal lock: the flange's y axis along world z, turned about it (its x, y parts ~1e-17)
    tilt = axis_angle_to_quat(np.tile([np.pi / 2, 0.0, 0.0], (100, 1)))
    quat[200:300] = quat_multiply(axis_angle_to_quat(np.column_stack([np.zeros((100, 2)), rng.uniform(-3, 3, 100)])), tilt)
    want = ik_joints(pos, quat) - q
    want[:, 3:] = (want[:, 3:] + np.pi) % (2 * np.pi) - np.pi
    g = _gripper_at(q, device)
    g.begin_step(pos, quat, np.full(n, 0.05))
    got = g._q_move.numpy()
    lock = np.zeros(n, bool)
    lock[200:300] = True
    np.testing.assert_allclose(got[~lock], want[~lock], rtol=RTOL, atol=1e-14)
    # at the gimbal lock the pitch is asin of an entry within an ulp of 1, where an ulp (1.1e-16)
    # moves asin by sqrt(2 x 1.1e-16) = 1.5e-8 rad (a GPU's matrix entry may differ by one)
    np.testing.assert_allclose(got[lock], want[lock], rtol=0, atol=5e-8)
    assert (np.abs(got[:, 3:]) <= np.pi).all() and (got[:200, 5] != 0).any()


def test_begin_step_checks_its_targets():
    g = _gripper_at(np.zeros((2, 6)))
    pos, quat = np.zeros((2, 3)), np.tile([0.0, 0.0, 0.0, 1.0], (2, 1))
    with pytest.raises(ValueError, match="target_pos must be finite"):
        g.begin_step(np.array([[0.0, np.nan, 0.0], [0, 0, 0]]), quat, np.full(2, 0.05))
    with pytest.raises(ValueError, match=r"target_quat must be a unit quaternion .* got norm 2"):
        g.begin_step(pos, 2 * quat, np.full(2, 0.05))
    with pytest.raises(ValueError, match=r"target_pos must have shape \[2, 3\]"):
        g.begin_step(np.zeros((3, 3)), quat, np.full(2, 0.05))
