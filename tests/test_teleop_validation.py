"""Every bad argument is rejected with ValueError/TypeError naming the value and the accepted range."""

import math

import numpy as np
import pytest

from teleop import HapticsConfig, HumanTeleopConfig, make_action
from teleop.devices import KeyboardTeleop
from teleop.sensors import (
    OpenVRTracker, ReplayGlove, UdpGloveReceiver, UdpGloveSender, UdpTrackerReceiver, UdpTrackerSender,
)
from teleop.sensors.base import GloveSample, check_haptics
from teleop.devices.velocity import VelocityTeleopConfig
from teleop.haptics import force_to_feedback
from teleop.retarget import (
    FingerGeometry, HandGeometry, LossGate, OffsetRetargeter, PinchGapMap, PinchRetargeter, RateLimits,
    WorkspaceBox, limit_rotation, limit_translation,
)

GLOVE = GloveSample(np.zeros((5, 4)), np.zeros((5, 3)), True, 0.0)

CASES = [
    # (callable, exception, regex that must name the value and the range)
    (lambda: UdpGloveReceiver(port=70000), ValueError, r"port must be in \[0, 65535\], got 70000"),
    (lambda: UdpGloveReceiver(port=-1), ValueError, r"port must be in \[0, 65535\], got -1"),
    (lambda: UdpGloveReceiver(port="47001"), TypeError, r"port must be an int in \[0, 65535\], got '47001'"),
    (lambda: UdpGloveReceiver(timeout_s=0.0), ValueError, r"timeout_s must be in \(0, 60\] s, got 0.0"),
    (lambda: UdpGloveReceiver(max_delay_s=-1), ValueError, r"max_delay_s must be in \(0, 60\] s, got -1.0"),
    (lambda: UdpGloveReceiver(host=""), ValueError, r"host must be a non-empty host string .*got ''"),
    (lambda: UdpGloveReceiver(haptics_address="x"), ValueError, r"haptics_address must be a \(host, port\) tuple or None, got 'x'"),
    (lambda: UdpTrackerReceiver(timeout_s=math.inf), ValueError, r"timeout_s must be finite and in \(0, 60\] s, got inf"),
    (lambda: UdpGloveSender(("127.0.0.1", 0)), ValueError, r"destination port must be in \[1, 65535\], got 0"),
    (lambda: UdpGloveSender("127.0.0.1:47001"), ValueError, r"destination must be a \(host, port\) tuple, got '127.0.0.1:47001'"),
    (lambda: UdpTrackerSender(("127.0.0.1", 9), stream_id=-5), ValueError, r"stream_id must be an int in \[0, 4294967295\], got -5"),
    (lambda: check_haptics(np.full(5, 1.2), np.zeros(5), 0.1), ValueError, r"force_feedback entries must be in \[0, 1\], got \[1.2, "),
    (lambda: check_haptics(np.zeros(4), np.zeros(5), 0.1), ValueError, r"force_feedback must have shape \(5,\), got shape \(4,\)"),
    (lambda: check_haptics(np.zeros(5), np.full(5, -0.1), 0.1), ValueError, r"vibration entries must be in \[0, 1\], got \[-0.1"),
    (lambda: check_haptics(np.zeros(5), np.zeros(5), 11.0), ValueError, r"vibration_duration_s must be in \[0, 10\] s, got 11.0"),
    (lambda: force_to_feedback(5.0, full_scale_n=0.0), ValueError, r"full_scale_n must be in \(0, inf\) N, got 0.0"),
    (lambda: force_to_feedback(math.nan), ValueError, r"force_n must be finite and in \(-inf, inf\) N, got nan"),
    (lambda: HapticsConfig(full_scale_n=-3.0), ValueError, r"full_scale_n must be in \(0, inf\) N, got -3.0"),
    (lambda: HapticsConfig(vibration_level=2.0), ValueError, r"vibration_level must be in \[0, 1\], got 2.0"),
    (lambda: HapticsConfig(release_threshold_n=1.0), ValueError, r"release_threshold_n must be <= contact_threshold_n \(0.5 N\), got 1.0"),
    (lambda: HapticsConfig(finger_map={"left": "toe", "right": "index"}), ValueError, r"finger_map\['left'\] must be one of \('thumb', .*got 'toe'"),
    (lambda: RateLimits(max_speed_m_s=0.0), ValueError, r"max_speed_m_s must be in \(0, inf\) m/s, got 0.0"),
    (lambda: RateLimits(dt=-0.05), ValueError, r"dt must be in \(0, 10\] s, got -0.05"),
    (lambda: WorkspaceBox((0, 0, 0), (1, 0, 1)), ValueError, r"lo must be < hi on every axis, got lo=\[0.0, 0.0, 0.0\] hi=\[1.0, 0.0, 1.0\]"),
    (lambda: limit_translation([0, 0, 0], [1, 1, 1], -0.1), ValueError, r"max_step_m must be in \[0, inf\) m, got -0.1"),
    (lambda: limit_rotation([0, 0, 0, 1], [0, 0, 0, 1], math.nan), ValueError, r"max_step_rad must be finite and in \[0, inf\) rad, got nan"),
    (lambda: LossGate(0), ValueError, r"resume_after must be an int in \[1, inf\), got 0"),
    (lambda: PinchGapMap(0.05, 0.04), ValueError, r"d_open_m - d_closed_m must be >= 0.005 m .*got d_closed_m=0.05, d_open_m=0.04"),
    (lambda: PinchGapMap(-0.01, 0.04), ValueError, r"d_closed_m must be in \[0, 0.5\] m, got -0.01"),
    (lambda: PinchGapMap(gap_open_m=0.1), ValueError, r"gap_open_m must be in \[0, 0.085\] m, got 0.1"),
    (lambda: PinchGapMap().gap(-0.01), ValueError, r"distance_m must be in \[0, inf\) m, got -0.01"),
    (lambda: PinchRetargeter(source="camera"), ValueError, r"source must be one of \('fk', 'sdk'\), got 'camera'"),
    (lambda: FingerGeometry((0, 0, 0), (0.1, 0.1, 0.1, -0.1)), ValueError, r"link_lengths entries must be in \[0, 0.5\] m, got \[-0.1\]"),
    (lambda: FingerGeometry((0, 0, 0), (0.1, 0.1, 0.1, 0.1), axes=((0, 0, 0),) * 4), ValueError, r"axes must be non-zero vectors, got"),
    (lambda: HandGeometry(()), ValueError, r"fingers must be 5 FingerGeometry .*got \(\)"),
    (lambda: OffsetRetargeter(mode="magic"), ValueError, r"mode must be one of \('full', 'align_axes'\), got 'magic'"),
    (lambda: OffsetRetargeter(offset=np.diag([2.0, 1, 1, 1])), ValueError, r"offset rotation must be orthonormal with det \+1"),
    (lambda: OffsetRetargeter().calibrate(np.eye(3), np.eye(4)), ValueError, r"master_pose must have shape \(4, 4\), got shape \(3, 3\)"),
    (lambda: HumanTeleopConfig(calibration_mode="x"), ValueError, r"calibration_mode must be one of \('full', 'align_axes'\), got 'x'"),
    (lambda: HumanTeleopConfig(latency_window=0), ValueError, r"latency_window must be an int in \[1, inf\), got 0"),
    (lambda: HumanTeleopConfig(limits="fast"), TypeError, r"limits must be a RateLimits, got 'fast'"),
    (lambda: VelocityTeleopConfig(linear_speed_m_s=20.0), ValueError, r"linear_speed_m_s must be in \(0, 10\] m/s, got 20.0"),
    (lambda: KeyboardTeleop(lambda: (), bindings={"w": ("lin", 3, 1)}), ValueError, r"binding for 'w' must be .*got \('lin', 3, 1\)"),
    (lambda: KeyboardTeleop("wasd"), TypeError, r"key_source must be a callable returning the held keys, got 'wasd'"),
    (lambda: OpenVRTracker(serial=""), ValueError, r"serial must be a non-empty string or None, got ''"),
    (lambda: make_action([0, 0, 0], [0, 0, 0, 1], 0.09), ValueError, r"gap_m must be in \[0, 0.085\] m, got 0.09"),
    (lambda: make_action([0, 0, math.inf], [0, 0, 0, 1], 0.0), ValueError, r"position must be finite"),
    (lambda: GloveSample(np.zeros((5, 4)), np.zeros((5, 3)), "yes", 0.0), TypeError, r"GloveSample.connected must be a bool, got 'yes'"),
    (lambda: GloveSample(np.full((5, 4), 7.0), np.zeros((5, 3)), True, 0.0), ValueError, r"joint_angles entries must be in \[-6.28319, 6.28319\] rad, got \[7.0"),
]


@pytest.mark.parametrize("call, exc, pattern", CASES, ids=[c[2][:40] for c in CASES])
def test_bad_argument_rejected(call, exc, pattern):
    with pytest.raises(exc, match=pattern):
        call()


def test_bad_haptics_rejected_by_devices():
    rg = ReplayGlove([GLOVE])
    rg.connect()
    with pytest.raises(ValueError, match=r"vibration_duration_s must be in \[0, 10\] s, got -1.0"):
        rg.send_haptics(np.zeros(5), np.zeros(5), -1.0)
    rx = UdpGloveReceiver(port=0)
    with rx:
        with pytest.raises(ValueError, match=r"force_feedback entries must be in \[0, 1\]"):
            rx.send_haptics(np.full(5, 2.0), np.zeros(5), 0.0)


def test_bad_glove_data_rejected_by_sender():
    rx = UdpGloveReceiver(port=0)
    with rx, UdpGloveSender(rx.address, bind_host="127.0.0.1") as tx:
        with pytest.raises(ValueError, match=r"fingertip_positions entries must be in \[-1, 1\] m, got \[50.0"):
            tx.send(np.zeros((5, 4)), np.full((5, 3), 50.0))  # mm instead of m
        with pytest.raises(ValueError, match=r"timestamp_s must be finite"):
            tx.send(np.zeros((5, 4)), np.zeros((5, 3)), timestamp_s=math.nan)
