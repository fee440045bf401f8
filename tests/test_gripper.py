"""Robotiq 2F-85 model: linkage closed form, pad geometry, speed/force-limited driver, validation."""

import math

import numpy as np
import pytest

from defgrasp_env.gripper import (
    GAP_MAX,
    GAP_MIN,
    PAD_HALF_EXTENTS,
    THETA_MAX,
    THETA_MIN,
    GripperConfig,
    GripperDriver,
    driver_step,
    gap_from_theta,
    pad_arc_centers,
    pad_boxes,
    pad_centers,
    tcp_offset,
    theta_from_gap,
    update_grip_stiffness,
)
from defgrasp_env.gripper import linkage


def _rx(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rz(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _urdf_left_pad_centre(theta):
    """Left pad centre by chaining the URDF joints (base-link axes): independent of the closed form."""
    R = _rz(math.pi) @ _rx(theta)  # finger_joint: rpy (0, 0, pi), axis x
    p = np.array([0, -0.0306011, 0.054904])
    p = p + R @ np.array([0, 0.0315, -0.0041])  # left_outer_finger_joint (fixed)
    p = p + R @ np.array([0, 0.0061, 0.0471])  # left_inner_finger_joint, mimic -1
    R = R @ _rx(-theta)
    return p + R @ np.array([0, -0.0220203446692936, 0.03242]), R  # left_inner_finger_pad_joint


def test_closed_form_constants():
    assert math.isclose(linkage.GAP_OFFSET, 0.0054058, abs_tol=1e-7)
    assert math.isclose(linkage.ARC_RADIUS, math.hypot(0.0376, 0.0430), rel_tol=1e-15)
    assert math.isclose(linkage.ARC_PHASE, math.atan2(0.0430, 0.0376), rel_tol=1e-15)
    assert math.isclose(linkage.ARC_RADIUS, 0.057121, abs_tol=1e-6)
    assert math.isclose(linkage.ARC_PHASE, 0.8523, abs_tol=1e-4)


def test_known_values():
    # open = the 2F-85's 85 mm stroke, reached by limiting the driver angle (the URDF's theta = 0
    # would open the pads to 86.01 mm, wider than the gripper we model)
    assert GAP_MAX == 0.085
    assert gap_from_theta(THETA_MIN) == pytest.approx(0.085, abs=1e-15)
    assert 2 * (0.0054058 + 0.0376 * np.cos(0.0) - 0.0430 * np.sin(0.0)) == pytest.approx(0.0860, abs=1e-4)
    assert 0.0 < THETA_MIN < 0.02
    assert gap_from_theta(0.8) == pytest.approx(0.0015, abs=1e-4)
    assert GAP_MIN == pytest.approx(gap_from_theta(THETA_MAX), abs=1e-15)
    # the formula from REFERENCE.md
    t = np.linspace(THETA_MIN, 0.8, 9)
    np.testing.assert_allclose(gap_from_theta(t), 2 * (0.0054058 + 0.0376 * np.cos(t) - 0.0430 * np.sin(t)), atol=1e-7)


def test_gap_strictly_decreasing():
    g = gap_from_theta(np.linspace(THETA_MIN, 0.8, 10001))
    assert np.all(np.diff(g) < 0)


def test_round_trips():
    theta = np.linspace(THETA_MIN, 0.8, 4001)
    assert np.max(np.abs(theta_from_gap(gap_from_theta(theta)) - theta)) < 1e-6
    gap = np.linspace(GAP_MIN, GAP_MAX, 4001)
    assert np.max(np.abs(gap_from_theta(theta_from_gap(gap)) - gap)) < 1e-4  # 0.1 mm
    assert np.max(np.abs(gap_from_theta(theta_from_gap(gap)) - gap)) < 1e-12  # in fact exact


def test_pads_match_urdf_chain():
    for theta in np.linspace(THETA_MIN, 0.8, 17):
        p_b, R_b = _urdf_left_pad_centre(theta)
        np.testing.assert_allclose(R_b, _rz(math.pi), atol=1e-12)  # parallelogram: pad never rotates
        # base axes -> G: x_G = -y_b, y_G = -z_b, z_G = x_b
        p_g = np.array([-p_b[1], -p_b[2], p_b[0]])
        np.testing.assert_allclose(pad_centers(theta)[0], p_g, atol=1e-12)
        # inner faces are gap apart
        centers, half = pad_boxes(theta=theta)
        inner = (centers[0, 0] - half[0, 0]) - (centers[1, 0] + half[1, 0])
        assert inner == pytest.approx(gap_from_theta(theta), abs=1e-12)


def test_pad_geometry_and_arc():
    theta = np.linspace(THETA_MIN, 0.8, 50)
    c = pad_centers(theta)
    assert c.shape == (50, 2, 3)
    np.testing.assert_allclose(c[:, 1], c[:, 0] * [-1, 1, 1])  # mirrored in x
    np.testing.assert_allclose(c[..., 2], 0.0)
    assert np.all(c[:, 0, 0] > 0) and np.all(c[..., 1] < 0)  # left at +x, fingers along -y
    r = np.linalg.norm(c - pad_arc_centers(), axis=-1)
    np.testing.assert_allclose(r, linkage.ARC_RADIUS, atol=1e-12)
    centers, half = pad_boxes(gap=np.array([0.01, 0.05]))
    assert centers.shape == half.shape == (2, 2, 3)
    np.testing.assert_allclose(half[0, 0], PAD_HALF_EXTENTS)
    np.testing.assert_allclose(PAD_HALF_EXTENTS * 2, [0.00635, 0.0375, 0.022])
    np.testing.assert_allclose(centers[:, 0, 0] - half[:, 0, 0], [0.005, 0.025], atol=1e-12)


def test_tcp_offset():
    down = 0.054904 + 0.03242 + 0.0376 * np.sin(THETA_MIN) + 0.0430 * np.cos(THETA_MIN)
    np.testing.assert_allclose(tcp_offset(theta=THETA_MIN), [0, -down, 0], atol=1e-12)
    np.testing.assert_allclose(tcp_offset(gap=GAP_MAX), tcp_offset(theta=THETA_MIN), atol=1e-12)
    t = np.linspace(THETA_MIN, 0.8, 9)
    np.testing.assert_allclose(tcp_offset(theta=t), pad_centers(t).mean(axis=-2))
    np.testing.assert_allclose(tcp_offset(gap=GAP_MIN), tcp_offset(theta=0.8), atol=1e-12)
    with pytest.raises(TypeError, match="exactly one"):
        tcp_offset(gap=0.05, theta=0.1)
    with pytest.raises(TypeError, match="exactly one"):
        pad_boxes()


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: gap_from_theta(0.9), r"theta must be in \[0.0117021481, 0.8\] rad, got 0.9"),
        (lambda: gap_from_theta(0.0), r"theta must be in \[0.0117021481, 0.8\] rad, got 0"),
        (lambda: theta_from_gap(0.086), r"gap must be in \[0.00151123139, 0.085\] m, got 0.086"),
        (lambda: theta_from_gap(np.nan), "gap must be finite"),
    ],
)
def test_linkage_validation(call, match):
    with pytest.raises(ValueError, match=match):
        call()


# ----------------------------------------------------------------------------------- driver


def test_config_defaults_and_validation():
    cfg = GripperConfig()
    assert cfg.closing_speed_mm_s == 150.0 and cfg.grip_force_limit == 20.0
    assert cfg.closing_speed == pytest.approx(0.15)
    with pytest.raises(ValueError, match=r"^closing_speed_mm_s must be in \[20, 150\] mm/s, got 300$"):
        GripperConfig(closing_speed_mm_s=300)
    with pytest.raises(ValueError, match=r"^closing_speed_mm_s must be in \[20, 150\] mm/s, got 10$"):
        GripperConfig(closing_speed_mm_s=10)
    with pytest.raises(ValueError, match=r"^grip_force_limit must be in \[20, 235\] N, got 500$"):
        GripperConfig(grip_force_limit=500)
    with pytest.raises(ValueError, match="grip_force_limit must be in"):
        GripperConfig(grip_force_limit=float("nan"))
    with pytest.raises(TypeError, match="closing_speed_mm_s must be a real number"):
        GripperConfig(closing_speed_mm_s="fast")
    with pytest.raises(TypeError):
        GripperConfig(grip_force_limit=True)
    with pytest.raises(AttributeError):
        cfg.grip_force_limit = 50.0  # frozen


def test_driver_obeys_speed_limit_both_ways():
    cfg = GripperConfig(closing_speed_mm_s=100.0)
    W = 5
    gap = np.full(W, 0.05)
    cmd = np.array([0.0, 0.049, 0.05, 0.051, 1.0])  # out-of-range commands are clipped
    new = GripperDriver(cfg).step(cmd, gap, 0.05, np.zeros(W), np.zeros(W))
    np.testing.assert_allclose(new, [0.045, 0.049, 0.05, 0.051, 0.055], atol=1e-15)
    # long run converges to the clipped command without overshoot
    g = gap.copy()
    for _ in range(100):
        g_new = driver_step(cfg, cmd, g, 0.01, 0.0, 0.0)[0]
        assert np.all(np.abs(g_new - g) <= 0.1 * 0.01 + 1e-15)
        g = g_new
    np.testing.assert_allclose(g, np.clip(cmd, GAP_MIN, GAP_MAX), atol=1e-15)


def test_driver_stops_at_force_limit_and_still_opens():
    cfg = GripperConfig(closing_speed_mm_s=150.0, grip_force_limit=40.0)
    gap = np.full(4, 0.03)
    cmd = np.array([0.0, 0.0, 0.0, 0.08])
    f_l = np.array([10.0, 40.0, 70.0, 100.0])
    f_r = np.array([10.0, 40.0, 0.0, 100.0])  # mean force: 10, 40 (= limit), 35, 100
    new, stopped = driver_step(cfg, cmd, gap, 0.02, f_l, f_r)
    np.testing.assert_array_equal(stopped, [False, True, False, False])
    np.testing.assert_allclose(new, [0.027, 0.03, 0.027, 0.033], atol=1e-15)


def test_driver_closes_until_object_force_reaches_limit():
    """A linear-spring object of width 40 mm: closing stops at the gap where the force hits the limit."""
    cfg = GripperConfig(closing_speed_mm_s=20.0, grip_force_limit=50.0)
    k = 2500.0  # N/m, force on each pad per metre of gap below 40 mm
    g = np.array([0.08])
    for _ in range(1000):  # 0.1 mm per step
        f = k * np.maximum(0.04 - g, 0.0)
        g, stopped = driver_step(cfg, 0.0, g, 0.005, f, f)
    f = k * np.maximum(0.04 - g, 0.0)
    assert stopped[0]
    assert 50.0 <= f[0] <= 50.0 + k * 1e-4 + 1e-9  # overshoot at most one step
    assert g[0] == pytest.approx(0.04 - 50.0 / k, abs=1e-4)


def test_driver_scalar_and_broadcast():
    new = GripperDriver().step(0.0, 0.05, 0.05, 0.0, 0.0)
    assert new.shape == () and new == pytest.approx(0.05 - 0.0075)
    new = GripperDriver().step(np.zeros(3), 0.05, 0.05, 0.0, np.zeros(3))
    assert new.shape == (3,)


@pytest.mark.parametrize(
    "kwargs, exc, match",
    [
        (dict(dt=0.0), ValueError, r"dt must be in \(0, inf\) s, got 0"),
        (dict(dt=-1.0), ValueError, r"dt must be in \(0, inf\) s, got -1"),
        (dict(gap=0.2), ValueError, r"gap must be in \[0.00151123139, 0.085\] m, got 0.2"),
        (dict(force_left=-1.0), ValueError, r"force_left must be in \[0, inf\) N, got -1"),
        (dict(grip_stiffness=-5.0), ValueError, r"grip_stiffness must be in \[0, inf\) N/m, got -5"),
        (dict(cmd_gap=np.nan), ValueError, "cmd_gap must be finite"),
        (dict(cmd_gap=np.zeros(2), gap=np.full(3, 0.05)), ValueError, "must broadcast"),
        (dict(config=None), TypeError, "config must be a GripperConfig"),
    ],
)
def test_driver_validation(kwargs, exc, match):
    args = dict(config=GripperConfig(), cmd_gap=0.0, gap=0.05, dt=0.05, force_left=0.0, force_right=0.0)
    args.update(kwargs)
    with pytest.raises(exc, match=match):
        driver_step(**args)


# -- force regulation (driver rule 4) against spring objects -------------------------------------
def close_on_spring(force_of_gap, substeps: int, regulate: bool, cfg=GripperConfig(), h=0.0125):
    """Close fully (command 0) on an object whose grip force is ``force_of_gap(gap)`` (N), with
    the driver run every physics substep of ``h`` s as the env does. Returns the force after every
    substep."""
    g, k, f = np.array([0.08]), np.zeros(1), force_of_gap(np.array([0.08]))
    forces = []
    for _ in range(substeps):
        g_new = driver_step(cfg, 0.0, g, h, f, f, k if regulate else 0.0)[0]
        f_new = force_of_gap(g_new)
        if regulate:
            k = update_grip_stiffness(k, g, g_new, f, f_new, 0.0)
        g, f = g_new, f_new
        forces.append(f[0])
    return np.array(forces)


@pytest.mark.parametrize("stiffness", [2e3, 2e4, 2e5, 2e6])
def test_driver_holds_the_grip_force_at_the_limit_on_a_linear_spring(stiffness):
    """A 40 mm wide linear-spring object (k from a soft foam, 20 N at 10 mm squeeze, to the pad
    contact's stiffness) and the 2F-85's fastest closing (150 mm/s, 1.9 mm per 12.5 ms substep):
    with the stiffness estimate the force settles at the 20 N limit (within 0.5 %: the secant of a
    linear spring is exact), from the second substep after first touch on it never exceeds it by
    more than 1 % and once within 1 % it stays there, and the grip is never lost; without the
    estimate (rule 3 alone) the jaw stops after the move that crossed the limit, at up to
    k x 1.9 mm."""
    limit = GripperConfig().grip_force_limit
    spring = lambda g: stiffness * np.maximum(0.04 - g, 0.0)  # noqa: E731
    forces = close_on_spring(spring, 400, regulate=True)
    touch = int(np.argmax(forces > 0))
    assert forces[-1] == pytest.approx(limit, rel=5e-3)
    assert forces[touch:].min() > 0.0
    assert forces[touch + 2:].max() <= 1.01 * limit
    settled = int(np.argmax(np.abs(forces - limit) <= 0.01 * limit))
    np.testing.assert_allclose(forces[settled:], limit, rtol=0.01)
    unregulated = close_on_spring(spring, 400, regulate=False)
    assert unregulated[-1] >= limit
    if stiffness >= 2e5:  # the overshoot this rule removes: >= 1.9 mm x k - 20 N is possible
        assert unregulated[-1] > 2.0 * limit


def test_driver_regulates_a_stiffening_hertz_contact():
    """Grip force ~ c d^1.5 (Hertz, a sphere squeezed by flat pads), 20 N reached at 0.5 mm: the
    secant estimate lags the rising stiffness, yet the force settles within 2 % of the limit and
    the grip is never lost after first touch."""
    limit = GripperConfig().grip_force_limit
    c = limit / 0.0005 ** 1.5
    forces = close_on_spring(lambda g: c * np.maximum(0.04 - g, 0.0) ** 1.5, 400, regulate=True)
    touch = int(np.argmax(forces > 0))
    assert forces[-1] == pytest.approx(limit, rel=0.02)
    assert forces[touch:].min() > 0.0


def test_grip_stiffness_estimate_rules():
    """Secant of two touching readings; first touch gives 2 force / closing (contact taken to
    begin halfway through the move); a release (no touch, command open) resets to 0; contact lost
    while backing off under a closing command keeps the estimate; a tiny move keeps the old value;
    a closing move without touch halves it, and 1 N/m or less is 0."""
    k = update_grip_stiffness(
        [500.0, 0.0, 700.0, 700.0, 700.0, 700.0, 1.5],              # current estimates
        [0.040, 0.040, 0.040, 0.0400, 0.040, 0.040, 0.040],         # gap before (m)
        [0.039, 0.039, 0.041, 0.0410, 0.0400005, 0.039, 0.039],     # gap after
        [1.0, 0.0, 1.0, 1.0, 1.0, 0.0, 0.0],                        # force before (N)
        [3.0, 2.0, 0.0, 0.0, 1.5, 0.0, 0.0],                        # force after
        [0.0, 0.0, 0.085, 0.0, 0.0, 0.0, 0.0])                      # command
    np.testing.assert_allclose(k, [2000.0, 4000.0, 0.0, 700.0, 700.0, 350.0, 0.0])


def test_jaw_closes_back_to_full_speed_after_the_object_slips_out():
    """Gripping a stiff spring (k = 2e5 N/m) at the limit, then the object is gone (force 0) while
    the command stays closed: the jaw's step doubles each substep and is back at the speed limit
    (1.875 mm per 12.5 ms substep) within 6 substeps."""
    cfg, h = GripperConfig(), 0.0125
    g, k, f = np.array([0.0399]), np.array([2e5]), np.array([20.0])
    steps = []
    for _ in range(8):
        g_new = driver_step(cfg, 0.0, g, h, f, f, k)[0]
        k = update_grip_stiffness(k, g, g_new, f, 0.0, 0.0)
        steps.append(g[0] - g_new[0])
        g, f = g_new, np.zeros(1)
    assert steps[0] == 0.0  # at the limit: holds
    assert steps[6] == pytest.approx(cfg.closing_speed * h)
