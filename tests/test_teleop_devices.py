"""Keyboard / SpaceMouse mappings and integration, the OpenVR edge, device samples."""

import math
import sys

import numpy as np
import pytest

from teleop.devices import KeyboardTeleop, SpaceMouseTeleop, key_velocity, spacemouse_velocity
from teleop.sensors import GloveSample, OpenVRTracker, SpaceMouse, TrackerSample, openvr_matrix_to_pose
from teleop.devices.velocity import VelocityTeleopConfig
from teleop.retarget import WorkspaceBox
from teleop.se3 import quat_angle, rot_z

SPEEDS = dict(linear_speed_m_s=0.1, angular_speed_rad_s=0.8, gap_speed_m_s=0.05)
OBS = {"agent_pos": np.r_[[0.0, 0.3, 0.0], [0, 0, 0, 1.0], 0.04]}


def test_key_velocity_mapping():
    v, w, g = key_velocity({"w", "d", "r"}, **SPEEDS)
    np.testing.assert_allclose(v, [0.1, 0.1, -0.1])
    np.testing.assert_allclose(w, 0)
    assert g == 0
    v, w, g = key_velocity(["a", "d", "j", "E", "unknown"], **SPEEDS)  # opposite keys cancel, case-insensitive
    np.testing.assert_allclose(v, 0)
    np.testing.assert_allclose(w, [0, 0.8, 0])
    assert g == pytest.approx(-0.05)
    with pytest.raises(TypeError, match="collection of key names"):
        key_velocity("wasd", **SPEEDS)


def test_keyboard_teleop_integrates_from_observed_state():
    held = {"keys": set()}
    kb = KeyboardTeleop(lambda: held["keys"], VelocityTeleopConfig(dt=0.05))
    with kb:
        a = kb.act(OBS)
        np.testing.assert_allclose(a, OBS["agent_pos"][:8], atol=1e-7)  # no keys: stays, no jump
        held["keys"] = {"r", "q", "j"}
        for _ in range(10):
            a = kb.act(OBS)
        np.testing.assert_allclose(a[:3], [0.0, 0.3 + 10 * 0.05 * 0.1, 0.0], atol=1e-6)
        assert a[7] == pytest.approx(0.04 + 10 * 0.05 * 0.05, abs=1e-6)
        assert quat_angle(a[3:7].astype(float), [0, 0, 0, 1]) == pytest.approx(10 * 0.05 * 0.8, abs=1e-5)
        held["keys"] = {"q"}
        for _ in range(100):
            a = kb.act(OBS)
        assert a[7] == pytest.approx(0.085)  # gap clamped
        assert kb.get_action()["jaw.gap"] == pytest.approx(0.085)


def test_keyboard_workspace_clamp():
    kb = KeyboardTeleop(lambda: {"f"}, VelocityTeleopConfig(workspace=WorkspaceBox((-1, 0.29, -1), (1, 1, 1))))
    kb.connect()
    for _ in range(5):
        a = kb.act(OBS)
    assert a[1] == pytest.approx(0.29)


def test_spacemouse_mapping():
    class State:
        x, y, z, roll, pitch, yaw = 1.0, 0.5, 0.0, 0.0, 0.0, -1.0
        buttons = [1, 0]

    v, w, g = spacemouse_velocity(State(), deadzone=0.0, **SPEEDS)
    np.testing.assert_allclose(v, [0.1, 0.0, -0.05])  # device forward (+y) = world -z
    np.testing.assert_allclose(w, [0.0, -0.8, 0.0])
    assert g == pytest.approx(-0.05)  # button 0 closes
    State.x, State.y = 0.04, -0.55
    v, _, _ = spacemouse_velocity(State(), deadzone=0.1, **SPEEDS)
    np.testing.assert_allclose(v, [0.0, 0.0, 0.05])  # 0.04 in the deadzone; 0.55 -> 0.5 after rescale
    with pytest.raises(ValueError, match="axis_signs entries must be -1 or \\+1"):
        spacemouse_velocity(State(), axis_signs=(1, 1, 1, 1, 1, 0), **SPEEDS)


def test_spacemouse_missing_package_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyspacemouse", None)  # simulates an absent package
    with pytest.raises(ImportError, match="pip install pyspacemouse"):
        SpaceMouseTeleop().connect()


def test_spacemouse_teleop_reads_through_its_sensor(monkeypatch):
    """The TeleopDevice turns the SpaceMouse sensor's raw state into actions; the sensor (with a
    stand-in ``pyspacemouse`` module, no hardware here) only reads."""
    import types

    class State:
        x, y, z, roll, pitch, yaw = 0.0, 1.0, 0.0, 0.0, 0.0, 0.0   # full forward
        buttons = [0, 0]

    class Handle:
        closed = False

        def read(self):
            return State()

        def close(self):
            Handle.closed = True

    fake = types.ModuleType("pyspacemouse")
    fake.open = lambda device=None: Handle()
    monkeypatch.setitem(sys.modules, "pyspacemouse", fake)
    sensor = SpaceMouse()
    with pytest.raises(RuntimeError, match="connect"):
        sensor.read()
    teleop = SpaceMouseTeleop(deadzone=0.0)
    teleop.connect()
    assert teleop.is_connected and teleop.mouse.is_connected
    obs = {"agent_pos": np.array([0.0, 0.3, 0.0, 0.0, 0.0, 0.0, 1.0, 0.05, 0.0, 0.0], np.float32)}
    a = teleop.act(obs)
    dt, speed = teleop.config.dt, teleop.config.linear_speed_m_s
    np.testing.assert_allclose(a[:3], [0.0, 0.3, -speed * dt], atol=1e-7)   # device forward = world -z
    teleop.disconnect()
    assert Handle.closed and not teleop.is_connected


def test_openvr_missing_package_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "openvr", None)
    with pytest.raises(ImportError, match=r"pip install defgrasp\[vive\]"):
        OpenVRTracker().connect()


def test_openvr_3x4_to_4x4():
    R = rot_z(0.3)
    m34 = [[*R[0], 0.1], [*R[1], 1.2], [*R[2], -0.4]]  # HmdMatrix34_t indexes as m[row][col]
    T = openvr_matrix_to_pose(m34)
    np.testing.assert_allclose(T[:3, :3], R, atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], [0.1, 1.2, -0.4])
    np.testing.assert_array_equal(T[3], [0, 0, 0, 1])
    noisy = np.array(m34, dtype=np.float32).astype(float) * [[1.0001, 1, 1, 1], [1, 1, 1, 1], [1, 1, 1, 1]]
    Tn = openvr_matrix_to_pose(noisy)
    np.testing.assert_allclose(Tn[:3, :3].T @ Tn[:3, :3], np.eye(3), atol=1e-12)  # re-orthonormalised
    with pytest.raises(ValueError, match="not a rotation"):
        openvr_matrix_to_pose([[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]])
    with pytest.raises(ValueError, match="finite"):
        openvr_matrix_to_pose([[math.nan, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]])
    with pytest.raises(ValueError, match="3x4 matrix"):
        openvr_matrix_to_pose([[1, 0, 0]])


def test_samples_are_validated_and_immutable():
    s = TrackerSample(np.eye(4), True, 1.0)
    with pytest.raises(ValueError, match="read-only"):
        s.pose[0, 0] = 2.0
    with pytest.raises(ValueError, match="orthonormal"):
        TrackerSample(np.diag([2.0, 1, 1, 1]), True, 0.0)
    with pytest.raises(ValueError, match=r"GloveSample.joint_angles must have shape \(5, 4\)"):
        GloveSample(np.zeros((5, 3)), np.zeros((5, 3)), True, 0.0)
    with pytest.raises(ValueError, match=r"fingertip_positions entries must be in \[-1, 1\] m"):
        GloveSample(np.zeros((5, 4)), np.full((5, 3), 30.0), True, 0.0)
