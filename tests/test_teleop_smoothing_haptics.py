"""Rate limits, workspace clamp, hold-on-loss gate, and the haptic mapping."""

import math

import numpy as np
import pytest

from teleop.haptics import HapticsConfig, HapticsMapper, force_to_feedback
from teleop.retarget.smoothing import (
    Command, CommandFilter, GateEvent, LossGate, RateLimits, WorkspaceBox, limit_rotation, limit_scalar,
    limit_translation,
)
from teleop.se3 import quat_angle, rotvec_to_quat


def test_translation_limit():
    p = limit_translation([0, 0, 0], [3.0, 4.0, 0.0], 0.5)
    np.testing.assert_allclose(p, [0.3, 0.4, 0.0])
    np.testing.assert_allclose(limit_translation([0, 0, 0], [0.1, 0, 0], 0.5), [0.1, 0, 0])


def test_rotation_limit_along_the_geodesic():
    q0 = np.array([0, 0, 0, 1.0])
    q1 = rotvec_to_quat([0, 1.0, 0])
    q = limit_rotation(q0, q1, 0.25)
    assert quat_angle(q0, q) == pytest.approx(0.25)
    assert quat_angle(q, q1) == pytest.approx(0.75)
    np.testing.assert_allclose(q, rotvec_to_quat([0, 0.25, 0]), atol=1e-12)


def test_gap_limit():
    assert limit_scalar(0.08, 0.0, 0.0075) == pytest.approx(0.0725)
    assert limit_scalar(0.01, 0.012, 0.0075) == pytest.approx(0.012)


def test_filter_clamps_workspace_then_limits_rates():
    f = CommandFilter(RateLimits(max_speed_m_s=1.0, max_angular_speed_rad_s=2.0, max_gap_speed_m_s=0.1, dt=0.05),
                      WorkspaceBox((-0.1, 0.0, -0.1), (0.1, 0.5, 0.1)))
    prev = Command(np.array([0.09, 0.3, 0.0]), np.array([0, 0, 0, 1.0]), 0.0)
    out = f.step(prev, Command(np.array([5.0, 0.3, 0.0]), rotvec_to_quat([0, 0, 1.0]), 0.085))
    np.testing.assert_allclose(out.position, [0.1, 0.3, 0.0])  # clamped to the box (0.01 m < 0.05 m step)
    assert quat_angle([0, 0, 0, 1], out.quat_xyzw) == pytest.approx(0.1)
    assert out.gap_m == pytest.approx(0.005)


def test_workspace_box():
    box = WorkspaceBox()
    np.testing.assert_allclose(box.clamp([2, -1, 0.2]), [0.5, 0.0, 0.2])
    assert box.contains([0, 0.5, 0]) and not box.contains([0, 1.5, 0])


def test_loss_gate():
    g = LossGate(resume_after=2)
    assert g.update(True) is GateEvent.ACTIVE
    assert g.update(False) is GateEvent.HOLD
    assert g.update(True) is GateEvent.HOLD  # debounce
    assert g.update(True) is GateEvent.RESUME
    assert g.update(True) is GateEvent.ACTIVE


def test_force_feedback_mapping_values():
    assert force_to_feedback(0.0) == 0.0
    assert force_to_feedback(5.0) == pytest.approx(0.25)
    assert force_to_feedback(20.0) == 1.0
    assert force_to_feedback(35.0) == 1.0
    assert force_to_feedback(-2.0) == 0.0
    assert force_to_feedback(5.0, full_scale_n=10.0) == pytest.approx(0.5)


def test_haptics_mapper_fingers_and_onset_pulse():
    h = HapticsMapper(HapticsConfig(full_scale_n=20.0, contact_threshold_n=1.0, release_threshold_n=0.5,
                                    vibration_level=0.7, vibration_duration_s=0.1))
    c = h.step(0.0, 0.0)
    assert np.all(c.force_feedback == 0) and np.all(c.vibration == 0) and c.vibration_duration_s == 0
    c = h.step(4.0, 0.2)  # left tip touches: thumb feedback + pulse
    np.testing.assert_allclose(c.force_feedback, [0.2, 0.01, 0, 0, 0])
    np.testing.assert_allclose(c.vibration, [0.7, 0, 0, 0, 0])
    assert c.vibration_duration_s == pytest.approx(0.1)
    c = h.step(6.0, 2.0)  # thumb still in contact (no new pulse), index onset
    np.testing.assert_allclose(c.force_feedback, [0.3, 0.1, 0, 0, 0])
    np.testing.assert_allclose(c.vibration, [0, 0.7, 0, 0, 0])
    c = h.step(0.8, 2.0)  # thumb below contact but above release: hysteresis, no pulse
    assert np.all(c.vibration == 0)
    h.step(0.1, 2.0)  # thumb released
    c = h.step(1.5, 2.0)  # and touches again: pulse
    np.testing.assert_allclose(c.vibration, [0.7, 0, 0, 0, 0])


def test_haptics_from_info_and_finger_map():
    h = HapticsMapper(HapticsConfig(finger_map={"left": "index", "right": "middle"}))
    c = h.from_info({"left_tip_normal_force": np.float32(10.0), "right_tip_normal_force": np.array([30.0])})
    np.testing.assert_allclose(c.force_feedback, [0, 0.5, 1.0, 0, 0])
    with pytest.raises(ValueError, match=r"info lacks \['right_tip_normal_force'\]"):
        h.from_info({"left_tip_normal_force": 1.0})
    with pytest.raises(ValueError, match="left_tip_normal_force must be finite"):
        h.step(math.nan, 0.0)
