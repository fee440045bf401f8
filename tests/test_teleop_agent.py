"""HumanTeleopAgent end to end: replayed and UDP-streamed devices, real retargeting and IK."""

import time

import numpy as np
import pytest

from teleop import HumanTeleopAgent, HumanTeleopConfig
from teleop.sensors import (
    GloveSample, ReplayGlove, ReplayTracker, TrackerSample, UdpGloveReceiver, UdpGloveSender, UdpTrackerReceiver,
    UdpTrackerSender,
)
from teleop.retarget import PinchGapMap, PinchRetargeter, RateLimits
from teleop.se3 import homogeneous, quat_angle, rot_y

S0_POS = np.array([0.0, 0.3, 0.0])
OBS = {"agent_pos": np.r_[S0_POS, [0, 0, 0, 1.0], 0.085, np.zeros(5)].astype(np.float32)}
M0 = homogeneous(None, [0.2, 1.0, -0.3])  # operator's hand in the OpenVR frame, held like the gripper


@pytest.fixture(scope="module")
def wrist_ik():
    from teleop.retarget.wrist_ik import WristIK

    return WristIK()


def glove(pinch_m, connected=True, t=0.0):
    tips = np.zeros((5, 3))
    tips[0] = [0.12, 0.03, -0.03]
    tips[1] = tips[0] + [pinch_m, 0, 0]
    return GloveSample(np.zeros((5, 4)), tips, connected, t)


def tracker(T, valid=True, t=0.0):
    return TrackerSample(T, valid, t)


def shifted(d):
    return homogeneous(None, M0[:3, 3] + np.asarray(d, float))


def make_agent(trackers, gloves, wrist_ik, **cfg):
    agent = HumanTeleopAgent(
        ReplayTracker([tracker(T, v, 0.05 * i) for i, (T, v) in enumerate(trackers)], realtime=False),
        ReplayGlove([glove(p, c, 0.05 * i) for i, (p, c) in enumerate(gloves)], realtime=False),
        HumanTeleopConfig(**cfg),
        wrist_ik=wrist_ik,
        pinch=PinchRetargeter(source="sdk", gap_map=PinchGapMap(0.01, 0.095)),
    )
    agent.connect()
    return agent


def test_first_step_maps_operator_to_current_gripper(wrist_ik):
    agent = make_agent([(M0, True)], [(0.095, True)], wrist_ik)
    a = agent.act(OBS)
    assert a.dtype == np.float32 and a.shape == (8,)
    np.testing.assert_allclose(a[:3], S0_POS, atol=1e-6)
    np.testing.assert_allclose(a[3:7], [0, 0, 0, 1], atol=1e-6)
    assert a[7] == pytest.approx(0.085, abs=1e-6)  # open hand = open gripper
    assert agent.is_calibrated and agent.status == "active"
    assert agent.get_action()["wrist.pos.y"] == pytest.approx(0.3, abs=1e-6)


def test_relative_motion_pinch_and_ik(wrist_ik):
    steps = [np.zeros(3), [0.01, 0.0, 0.0], [0.01, 0.02, 0.0], [0.01, 0.02, -0.015]]
    pinches = [0.095, 0.0525, 0.01, 0.01]
    agent = make_agent([(shifted(d), True) for d in steps], [(p, True) for p in pinches], wrist_ik,
                       limits=RateLimits(max_gap_speed_m_s=10.0))
    for d, p in zip(steps, pinches):
        a = agent.act(OBS)
        np.testing.assert_allclose(a[:3], S0_POS + d, atol=1e-6)
        expected_gap = max(0.085 * (p - 0.01) / 0.085, 0.0015112)  # linear map, then the linkage's minimum
        assert a[7] == pytest.approx(expected_gap, abs=1e-6)
    assert agent.last_ik.converged
    assert agent.driver_angle_rad == pytest.approx(0.8, abs=1e-6)  # fully closed


def test_rotation_follows_hand(wrist_ik):
    turned = homogeneous(rot_y(0.1), M0[:3, 3])
    agent = make_agent([(M0, True), (turned, True)], [(0.095, True)] * 2, wrist_ik)
    agent.act(OBS)
    a = agent.act(OBS)
    assert quat_angle(a[3:7].astype(float), [0, 0, 0, 1]) == pytest.approx(0.1, abs=1e-5)


def test_rate_limit_on_a_jump(wrist_ik):
    agent = make_agent([(M0, True)] + [(shifted([0.3, 0, 0]), True)] * 3, [(0.095, True)] * 4, wrist_ik)
    xs = [agent.act(OBS)[0] for _ in range(4)]
    np.testing.assert_allclose(np.diff(xs), [0.025, 0.025, 0.025], atol=1e-6)  # 0.5 m/s * 0.05 s


def test_hold_on_tracking_loss_and_resume_without_jump(wrist_ik):
    trackers = [
        (M0, True), (shifted([0.01, 0, 0]), True),
        (shifted([0.01, 0, 0]), False), (shifted([0.01, 0, 0]), False),  # lost
        (shifted([0.31, -0.2, 0.1]), True),  # back, the operator's hand has moved meanwhile
        (shifted([0.32, -0.2, 0.1]), True),
    ]
    agent = make_agent(trackers, [(0.095, True)] * 6, wrist_ik)
    a = [agent.act(OBS) for _ in range(2)]
    held = [agent.act(OBS) for _ in range(2)]
    assert agent.status == "hold"
    for h in held:
        np.testing.assert_array_equal(h, a[-1])
    resumed = agent.act(OBS)
    assert agent.status == "resume"
    np.testing.assert_allclose(resumed, a[-1], atol=1e-6)  # no jump
    nxt = agent.act(OBS)
    np.testing.assert_allclose(nxt[:3], resumed[:3] + [0.01, 0, 0], atol=1e-6)  # continues relative


def test_hold_on_glove_disconnect(wrist_ik):
    agent = make_agent([(M0, True), (shifted([0.01, 0, 0]), True), (shifted([0.02, 0, 0]), True)],
                       [(0.095, True), (0.095, False), (0.095, True)], wrist_ik)
    a0 = agent.act(OBS)
    np.testing.assert_array_equal(agent.act(OBS), a0)
    np.testing.assert_allclose(agent.act(OBS), a0, atol=1e-6)  # resume re-calibrates: no jump


def test_without_ik_and_fixed_offset():
    off = homogeneous(None, [-0.2, -0.7, 0.3])  # M0 -> S0 exactly
    agent = make_agent([(M0, True), (shifted([0, 0.01, 0]), True)], [(0.095, True)] * 2, None,
                       use_ik=False, offset=off)
    np.testing.assert_allclose(agent.act(OBS)[:3], S0_POS, atol=1e-7)
    np.testing.assert_allclose(agent.act(OBS)[:3], S0_POS + [0, 0.01, 0], atol=1e-7)
    assert agent.q is None


def test_reset_recalibrates_against_the_new_observation(wrist_ik):
    agent = make_agent([(M0, True), (shifted([0.05, 0, 0]), True)], [(0.095, True)] * 2, wrist_ik)
    agent.act(OBS)
    agent.reset()
    obs2 = {"agent_pos": np.r_[[0.1, 0.2, 0.1], [0, 0, 0, 1.0], 0.05]}
    np.testing.assert_allclose(agent.act(obs2)[:3], [0.1, 0.2, 0.1], atol=1e-6)


def test_udp_end_to_end_haptics_and_latency(wrist_ik):
    grx, trx = UdpGloveReceiver(port=0), UdpTrackerReceiver(port=0)
    agent = HumanTeleopAgent(trx, grx, wrist_ik=wrist_ik, pinch=PinchRetargeter(source="sdk", gap_map=PinchGapMap(0.01, 0.095)))
    agent.connect()
    gtx = UdpGloveSender(grx.address, bind_host="127.0.0.1")
    ttx = UdpTrackerSender(trx.address, bind_host="127.0.0.1")
    try:
        g = glove(0.095)
        gtx.send(g.joint_angles, g.fingertip_positions)
        ttx.send(M0)
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            a = agent.act(OBS)
            if agent.status == "active":
                break
            time.sleep(0.005)
        assert agent.status == "active"
        np.testing.assert_allclose(a[:3], S0_POS, atol=1e-6)
        agent.send_feedback({"left_tip_normal_force": 10.0, "right_tip_normal_force": 2.0})
        assert agent.latency_s is not None and 0.0 <= agent.latency_s < 0.5
        assert agent.latency_stats()["count"] == 1
        cmd = None
        while cmd is None and time.monotonic() < deadline:
            cmd = gtx.poll_haptics()
        np.testing.assert_allclose(cmd.force_feedback, [0.5, 0.1, 0, 0, 0], atol=1e-6)
        np.testing.assert_allclose(cmd.vibration, [0.6, 0.6, 0, 0, 0], atol=1e-6)  # onset on both tips
        assert cmd.vibration_duration_s == pytest.approx(0.08)
    finally:
        gtx.close()
        ttx.close()
        agent.disconnect()


def test_agent_requires_connect_and_valid_obs(wrist_ik):
    agent = HumanTeleopAgent(ReplayTracker([tracker(M0)]), ReplayGlove([glove(0.05)]), wrist_ik=wrist_ik)
    with pytest.raises(RuntimeError, match="connect"):
        agent.act(OBS)
    with pytest.raises(RuntimeError, match="connect"):
        agent.get_action()
    agent.connect()
    with pytest.raises(RuntimeError, match="no action yet"):
        agent.get_action()
    with pytest.raises(ValueError, match="'agent_pos'"):
        agent.act({"pixels": None})
    with pytest.raises(ValueError, match="at least 8 entries"):
        agent.act({"agent_pos": np.zeros(3)})
    with pytest.raises(ValueError, match="unit quaternion"):
        agent.act({"agent_pos": np.zeros(8)})
    with pytest.raises(TypeError, match="tracker must be a PoseTracker"):
        HumanTeleopAgent(object(), ReplayGlove([glove(0.05)]), wrist_ik=wrist_ik)
    assert set(agent.action_features) == {"wrist.pos.x", "wrist.pos.y", "wrist.pos.z", "wrist.quat.x",
                                          "wrist.quat.y", "wrist.quat.z", "wrist.quat.w", "jaw.gap"}
    assert set(agent.feedback_features) == {"left_tip_normal_force", "right_tip_normal_force"}


def test_default_finger_fk_pinch_calibration_through_the_agent(wrist_ik):
    """Eq. 4 with the default finger URDF: calibrate on a closed pinch and an open hand."""
    open_hand = np.zeros((5, 4))
    pinch = np.zeros((5, 4))
    pinch[0, 1:] = [1.04756402, 0.39022875, -0.96619183]  # thumb tip meets the index tip (solved offline)
    pinch[1, 1:] = [0.82336424, 0.86528122, 0.74594854]
    samples = [GloveSample(a, np.zeros((5, 3)), True, 0.05 * i) for i, a in enumerate([open_hand, pinch, pinch])]
    agent = HumanTeleopAgent(
        ReplayTracker([tracker(M0, True, 0.05 * i) for i in range(3)], realtime=False),
        ReplayGlove(samples, realtime=False),
        HumanTeleopConfig(limits=RateLimits(max_gap_speed_m_s=10.0)),
        wrist_ik=wrist_ik,
    )
    agent.connect()
    m = agent.calibrate_pinch(samples[1], samples[0])
    assert m.d_closed_m < 1e-5 and m.d_open_m > 0.1
    assert agent.act(OBS)[7] == pytest.approx(0.085, abs=1e-6)
    assert agent.act(OBS)[7] == pytest.approx(0.0015112, abs=1e-6)  # closed: the linkage's minimum gap
    assert agent.last_pinch.distance_m < 1e-5 and agent.last_pinch.driver_angle_rad == pytest.approx(0.8)
