"""Retargeting (paper eq. 1-4) against hand-computed geometry and independent kinematics."""

import math

import numpy as np
import pytest

from teleop.sensors import GloveSample
from teleop.retarget import (
    FingerGeometry, FingerKinematics, HandGeometry, OffsetRetargeter, PinchGapMap, PinchRetargeter,
    compose_slave_pose, hand_urdf, pinch_distance,
)
from teleop.se3 import homogeneous, pose_to_matrix, rot_x, rot_y, rot_z, rotvec_to_quat

RNG = np.random.default_rng(7)
Y = (0.0, 1.0, 0.0)


def random_pose(scale=1.0):
    return pose_to_matrix(RNG.uniform(-scale, scale, 3), rotvec_to_quat(RNG.normal(size=3)))


# ----------------------------------------------------------------------------------- eq. 1-2

def test_offset_composition_hand_computed():
    off = homogeneous(rot_z(math.pi / 2), [1.0, 2.0, 3.0])
    master = homogeneous(rot_x(math.pi / 2), [0.1, 0.0, 0.0])
    tracker_to_flange = homogeneous(None, [0.0, 0.0, 0.05])
    # by hand: R = Rz90 Rx90 = [[0,0,1],[1,0,0],[0,1,0]];
    # p = Rz90 (p_m + Rx90 p_x) + t = Rz90 (0.1, -0.05, 0) + (1,2,3) = (1.05, 2.1, 3)
    expected = np.array([[0, 0, 1, 1.05], [1, 0, 0, 2.1], [0, 1, 0, 3.0], [0, 0, 0, 1]])
    np.testing.assert_allclose(compose_slave_pose(off, master, tracker_to_flange), expected, atol=1e-12)
    r = OffsetRetargeter(off, tracker_to_flange)
    np.testing.assert_allclose(r.slave_pose(master), expected, atol=1e-12)


def test_default_offset_is_openvr_to_world_identity():
    r = OffsetRetargeter()
    m = random_pose()
    np.testing.assert_allclose(r.slave_pose(m), m, atol=1e-12)
    assert not r.calibrated


@pytest.mark.parametrize("mode", ["full", "align_axes"])
def test_calibration_maps_current_master_to_current_slave(mode):
    r = OffsetRetargeter(tracker_to_flange=homogeneous(None, [0.0, -0.03, 0.02]), mode=mode)
    for _ in range(5):
        m, s = random_pose(2.0), random_pose(0.5)
        r.calibrate(m, s)
        np.testing.assert_allclose(r.slave_pose(m), s, atol=1e-12)
        assert r.calibrated


def test_full_calibration_relative_motion():
    """Hand held like the gripper: hand translation d (OpenVR) moves the gripper by d (world)."""
    R = rot_y(0.4) @ rot_x(-0.2)
    m0, s0 = homogeneous(R, [0.3, 1.1, -0.4]), homogeneous(R, [0.0, 0.2, 0.0])
    r = OffsetRetargeter()
    r.calibrate(m0, s0)
    d = np.array([0.05, -0.02, 0.01])
    m1 = m0.copy()
    m1[:3, 3] += d
    np.testing.assert_allclose(r.slave_pose(m1)[:3, 3], s0[:3, 3] + d, atol=1e-12)


def test_align_axes_calibration_keeps_world_axes():
    """Hand at any orientation: translations and world-frame rotations carry over one to one."""
    m0 = homogeneous(rot_z(1.0) @ rot_x(0.7), [0.3, 1.1, -0.4])
    s0 = homogeneous(rot_y(-0.3), [0.0, 0.2, 0.0])
    r = OffsetRetargeter(mode="align_axes")
    r.calibrate(m0, s0)
    d = np.array([0.05, -0.02, 0.01])
    Rw = rot_y(0.25)  # operator turns the hand 0.25 rad about world up
    m1 = homogeneous(Rw @ m0[:3, :3], m0[:3, 3] + d)
    s1 = r.slave_pose(m1)
    np.testing.assert_allclose(s1[:3, 3], s0[:3, 3] + d, atol=1e-12)
    np.testing.assert_allclose(s1[:3, :3], Rw @ s0[:3, :3], atol=1e-12)


def test_frame_rotation_maps_openvr_forward():
    r = OffsetRetargeter(frame_rotation=rot_y(math.pi))  # operator's forward (-z) -> world +z
    p = r.slave_pose(homogeneous(None, [0.0, 0.0, -1.0]))[:3, 3]
    np.testing.assert_allclose(p, [0.0, 0.0, 1.0], atol=1e-12)


# ----------------------------------------------------------------------------------- eq. 4

def planar_hand():
    """Thumb and index both planar (all joints about y), bases 3 cm apart along y."""
    idx = FingerGeometry((0.10, 0.02, 0.0), (0.03, 0.04, 0.025, 0.02), axes=(Y, Y, Y, Y))
    thb = FingerGeometry((0.05, 0.05, 0.0), (0.02, 0.03, 0.03, 0.02), axes=(Y, Y, Y, Y))
    other = FingerGeometry((0.1, -0.02, 0.0), (0.0, 0.04, 0.02, 0.02))
    return HandGeometry((thb, idx, other, other, other))


def planar_tip(base, lengths, angles):
    """Hand geometry: rotating +x by phi about +y gives (cos phi, 0, -sin phi)."""
    p = np.array(base, dtype=float)
    phi = 0.0
    for L, a in zip(lengths, angles):
        phi += a
        p += L * np.array([math.cos(phi), 0.0, -math.sin(phi)])
    return p


def test_finger_fk_matches_planar_geometry():
    geo = planar_hand()
    fk = FingerKinematics(geo)
    for _ in range(5):
        a = RNG.uniform(-0.3, 1.4, (5, 4))
        tips = fk.fingertip_positions(a)
        for f in (0, 1):
            g = geo.fingers[f]
            np.testing.assert_allclose(tips[f], planar_tip(g.base_xyz, g.link_lengths, a[f]), atol=1e-6)
        expected_d = np.linalg.norm(planar_tip(geo.fingers[0].base_xyz, geo.fingers[0].link_lengths, a[0])
                                    - planar_tip(geo.fingers[1].base_xyz, geo.fingers[1].link_lengths, a[1]))
        sample = GloveSample(a, np.zeros((5, 3)), True, 0.0)
        assert PinchRetargeter(fk).distance(sample) == pytest.approx(expected_d, abs=1e-6)


def test_finger_fk_abduction_then_flexion():
    """Default axes (z, y, y, y): splay b then a flat finger: tip on the rotated x axis."""
    g = FingerGeometry((0.1, 0.0, 0.0), (0.0, 0.05, 0.03, 0.02))
    geo = HandGeometry((g,) * 5)
    b = 0.3
    a = np.zeros((5, 4))
    a[1, 0] = b
    tip = FingerKinematics(geo).fingertip_positions(a)[1]
    np.testing.assert_allclose(tip, [0.1 + 0.1 * math.cos(b), 0.1 * math.sin(b), 0.0], atol=1e-6)


def test_finger_fk_batched():
    fk = FingerKinematics()
    a = RNG.uniform(-0.5, 1.0, (4, 5, 4))
    batch = fk.fingertip_positions(a)
    assert batch.shape == (4, 5, 3)
    np.testing.assert_allclose(batch[2], fk.fingertip_positions(a[2]), atol=1e-12)


def test_hand_urdf_has_four_joints_per_finger():
    text = hand_urdf()
    assert text.count('type="revolute"') == 20 and text.count('type="fixed"') == 5


def test_gap_map_endpoints_and_clamp():
    m = PinchGapMap(0.02, 0.10)
    assert m.gap(0.02) == pytest.approx(0.0)
    assert m.gap(0.10) == pytest.approx(0.085)
    assert m.gap(0.06) == pytest.approx(0.0425)
    assert m.gap(0.0) == 0.0 and m.gap(0.5) == pytest.approx(0.085)


def test_pinch_calibration_from_two_samples():
    def sample(d):
        tips = np.zeros((5, 3))
        tips[0] = [0.1, 0.03, -0.02]
        tips[1] = tips[0] + np.array([d, 0.0, 0.0])
        return GloveSample(np.zeros((5, 4)), tips, True, 0.0)

    p = PinchRetargeter(source="sdk")
    m = p.calibrate(sample(0.012), sample(0.09))
    assert (m.d_closed_m, m.d_open_m) == pytest.approx((0.012, 0.09))
    assert p(sample(0.012)).gap_m == pytest.approx(0.0)
    assert p(sample(0.09)).gap_m == pytest.approx(0.085)
    assert p(sample(0.2)).gap_m == pytest.approx(0.085)
    with pytest.raises(ValueError, match="d_open_m - d_closed_m must be >= 0.005 m"):
        p.calibrate(sample(0.05), sample(0.052))


def test_pinch_driver_angle_matches_2f85_formula():
    """REFERENCE.md: g(theta) = 2 (0.0054058 + 0.0376 cos theta - 0.0430 sin theta)."""
    p = PinchRetargeter(source="sdk", gap_map=PinchGapMap(0.0, 0.085))
    for d in (0.0, 0.01, 0.04, 0.085):
        tips = np.zeros((5, 3))
        tips[1, 0] = d
        r = p(GloveSample(np.zeros((5, 4)), tips, True, 0.0))
        g = 2 * (0.0054058 + 0.0376 * math.cos(r.driver_angle_rad) - 0.0430 * math.sin(r.driver_angle_rad))
        assert r.reachable_gap_m == pytest.approx(g, abs=1e-6)
        assert 0.0 <= r.driver_angle_rad <= 0.8
        assert r.reachable_gap_m == pytest.approx(max(r.gap_m, 0.0015112), abs=1e-6)  # linkage min gap
    assert pinch_distance([0, 0, 0], [0.03, 0.04, 0]) == pytest.approx(0.05)


# ----------------------------------------------------------------------------------- eq. 3

@pytest.fixture(scope="module")
def wrist_ik():
    from teleop.retarget.wrist_ik import WristIK

    return WristIK()


def test_ik_accuracy_on_reachable_targets(wrist_ik):
    from defgrasp_env.wrist import fk_matrix_analytic  # closed form, independent of pytorch-kinematics

    lo, hi = wrist_ik.lower, wrist_ik.upper
    for _ in range(20):
        q_true = RNG.uniform(lo * 0.9, hi * 0.9)
        T = fk_matrix_analytic(q_true)
        q_cur = np.clip(q_true + RNG.normal(scale=0.1, size=6), lo, hi)  # warm start: current joints
        r = wrist_ik.solve(T[:3, 3], pose_to_matrix_quat(T), q_cur)
        T_got = fk_matrix_analytic(r.q)
        assert np.linalg.norm(T_got[:3, 3] - T[:3, 3]) < 1e-3
        assert rot_angle(T_got[:3, :3], T[:3, :3]) < 0.01
        assert np.all(r.q >= lo) and np.all(r.q <= hi)
        np.testing.assert_allclose(r.position, T_got[:3, 3], atol=1e-9)


def test_ik_unreachable_target_gives_reachable_pose(wrist_ik):
    from defgrasp_env.wrist import fk_matrix_analytic

    # 2 m to the side (slide_x limit 0.4 m) and fingers pointing up (not reachable)
    r = wrist_ik.solve([2.0, 0.5, 0.0], rotvec_to_quat([math.pi, 0.0, 0.0]), wrist_ik.home_q)
    assert not r.converged
    assert np.all(r.q >= wrist_ik.lower) and np.all(r.q <= wrist_ik.upper)
    T = fk_matrix_analytic(r.q)
    np.testing.assert_allclose(r.position, T[:3, 3], atol=1e-9)  # the action is FK of clamped joints
    assert r.position[0] == pytest.approx(wrist_ik.upper[0])


def pose_to_matrix_quat(T):
    from teleop.se3 import matrix_to_quat

    return matrix_to_quat(T[:3, :3])


def rot_angle(Ra, Rb):
    c = (np.trace(Ra.T @ Rb) - 1) / 2
    return math.acos(max(-1.0, min(1.0, c)))
