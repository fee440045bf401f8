"""The action/observation layout (``defgrasp_env.layout``) is the one contract between the env, the
scripted expert, teleoperation, the recorders and the LeRobot export; the jaw range is the 2F-85's
85 mm stroke everywhere."""

import ast
import pathlib

import gymnasium as gym
import numpy as np
import pytest

import defgrasp_env  # noqa: F401  (registers the env)
from defgrasp_env import gripper
from defgrasp_env.layout import (ABSOLUTE_ACTION, ACTION_LAYOUTS, AGENT_POS, DELTA_ACTION, ENV_STATE, JAW_GAP_MAX,
                                 JAW_GAP_MIN, NUM_KEYPOINTS, TOPDOWN_ACTION, gap_to_jaw_command,
                                 jaw_command_to_gap)

ROOT = pathlib.Path(defgrasp_env.__file__).resolve().parents[1]


def test_jaw_range_is_the_2f85_stroke():
    assert JAW_GAP_MAX == gripper.GAP_MAX == 0.085
    assert JAW_GAP_MIN == gripper.GAP_MIN == pytest.approx(0.0015112, abs=1e-7)
    assert gripper.gap_from_theta(gripper.THETA_MIN) == pytest.approx(0.085, abs=1e-15)
    with pytest.raises(ValueError, match="gap must be in"):
        gripper.theta_from_gap(0.0851)  # the URDF's 86 mm opening is out of range


def test_jaw_encode_decode_round_trip():
    assert jaw_command_to_gap(-1.0) == JAW_GAP_MAX
    assert jaw_command_to_gap(1.0) == pytest.approx(JAW_GAP_MIN, abs=1e-17)  # last-bit rounding
    assert gap_to_jaw_command(JAW_GAP_MAX) == -1.0 and gap_to_jaw_command(JAW_GAP_MIN) == 1.0
    gap = np.linspace(JAW_GAP_MIN, JAW_GAP_MAX, 1001)
    np.testing.assert_allclose(jaw_command_to_gap(gap_to_jaw_command(gap)), gap, rtol=0, atol=1e-17)
    cmd = np.linspace(-1, 1, 1001)
    np.testing.assert_allclose(gap_to_jaw_command(jaw_command_to_gap(cmd)), cmd, rtol=0, atol=1e-14)
    assert np.all(np.diff(jaw_command_to_gap(cmd)) < 0)  # +1 closes
    # out-of-range gaps are clipped to the jaw range, not extrapolated
    assert gap_to_jaw_command([0.2, -1.0]).tolist() == [-1.0, 1.0]


def test_layouts_are_contiguous_named_and_round_trip():
    assert (AGENT_POS.size, ENV_STATE.size, DELTA_ACTION.size, ABSOLUTE_ACTION.size, TOPDOWN_ACTION.size) == (
        10, 33, 7, 8, 5)
    # LeRobotPolicy and the LeRobot export tell the action layouts apart by their sizes
    assert len({layout.size for layout in ACTION_LAYOUTS.values()}) == len(ACTION_LAYOUTS)
    # every action mode has its decoder, step bound and expert packer
    from defgrasp_env.envs.actions import DECODERS, STEP_NORM_FACTOR
    from defgrasp_env.policies.scripted_expert import ACTION_PACKERS
    assert set(DECODERS) == set(STEP_NORM_FACTOR) == set(ACTION_PACKERS) == set(ACTION_LAYOUTS)
    assert ENV_STATE.field("keypoints").size == 3 * NUM_KEYPOINTS
    rng = np.random.default_rng(0)
    for layout in (AGENT_POS, ENV_STATE, *ACTION_LAYOUTS.values()):
        assert len(set(layout.names)) == layout.size
        stops = [layout.slice(f.name) for f in layout.fields]
        assert stops[0].start == 0 and stops[-1].stop == layout.size
        assert all(a.stop == b.start for a, b in zip(stops, stops[1:]))
        vec = rng.normal(size=(4, layout.size))
        parts = {f.name: layout.get(vec, f.name) for f in layout.fields}
        np.testing.assert_array_equal(layout.pack(**parts), vec)
        low, high = layout.bounds()
        assert low.shape == high.shape == (layout.size,) and np.all(low < high)
    with pytest.raises(ValueError, match="must have 10 entries"):
        AGENT_POS.get(np.zeros(9), "jaw_gap")
    with pytest.raises(ValueError, match="missing \\['goal'"):
        ENV_STATE.pack(feature_position=np.zeros(3), feature_velocity=np.zeros(3), keypoints=np.zeros(24))
    with pytest.raises(KeyError, match="no field 'gap'"):
        AGENT_POS.slice("gap")


@pytest.mark.parametrize("mode", ["delta", "absolute", "topdown"])
def test_env_spaces_and_observations_follow_the_layout(mode):
    env = gym.make("DeformablePickup-v0", action_mode=mode)
    layout = ACTION_LAYOUTS[mode]
    low, high = layout.bounds()
    np.testing.assert_array_equal(env.action_space.low, low.astype(np.float32))
    np.testing.assert_array_equal(env.action_space.high, high.astype(np.float32))
    assert env.observation_space["agent_pos"].shape == (AGENT_POS.size,)
    assert env.observation_space["environment_state"].shape == (ENV_STATE.size,)
    obs, _ = env.reset(seed=1)
    assert AGENT_POS.get(obs["agent_pos"], "jaw_gap")[0] == np.float32(JAW_GAP_MAX)  # starts open
    flange, quat = env.unwrapped.scene.gripper.flange_pose()
    np.testing.assert_allclose(AGENT_POS.get(obs["agent_pos"], "wrist_position"), flange[0], atol=1e-7)
    np.testing.assert_allclose(AGENT_POS.get(obs["agent_pos"], "wrist_quat"), quat[0], atol=1e-7)
    np.testing.assert_array_equal(ENV_STATE.get(obs["environment_state"], "goal"), np.float32([0, 0.6, 0]))
    # command the jaw wider than open, then closed: the gap stays in the 2F-85's range
    wide = layout.pack(**{f.name: np.zeros(f.size) for f in layout.fields})
    if mode in ("delta", "topdown"):  # zero velocities (and yaw 0: the start's)
        wide[layout.slice("jaw")] = -1.0
        close = wide.copy()
        close[layout.slice("jaw")] = 1.0
    else:
        wide[ABSOLUTE_ACTION.slice("position")] = flange[0]
        wide[ABSOLUTE_ACTION.slice("orientation")] = quat[0]
        wide[ABSOLUTE_ACTION.slice("gap")] = 1.0  # clipped to the box
        close = wide.copy()
        close[ABSOLUTE_ACTION.slice("gap")] = 0.0
    gaps = []
    for action in [wide] * 2 + [close] * 14:
        obs, _, _, _, info = env.step(action.astype(np.float32))
        gaps.append(info["jaw_gap"])
        assert AGENT_POS.get(obs["agent_pos"], "jaw_gap")[0] == np.float32(info["jaw_gap"])
    assert gaps[0] == gaps[1] == JAW_GAP_MAX
    assert gaps[-1] == pytest.approx(JAW_GAP_MIN, abs=1e-12)  # closed on nothing: 14 x 7.5 mm > 83.5 mm
    env.close()


def _numeric_slices(path: pathlib.Path) -> list[str]:
    """Subscripts of ``agent``/``state``/``obs``/``action`` variables by integer constants or slices."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) and node.value.id in (
                "agent", "state", "action", "actions", "head", "a"):
            index = ast.unparse(node.slice)
            if index != "0" and any(ch.isdigit() for ch in index):  # [0]: the first of a batch
                found.append(f"{path.name}: {ast.unparse(node)}")
    return found


def test_consumers_slice_by_layout_names_not_numbers():
    files = [ROOT / "defgrasp_env/policies/scripted_expert.py", ROOT / "defgrasp_env/envs/actions.py",
             ROOT / "teleop/teleop_device.py"]
    assert [f for f in files if not f.exists()] == []
    assert sum((_numeric_slices(f) for f in files), []) == []


def test_expert_actions_decode_into_the_jaw_range():
    from defgrasp_env.policies import ScriptedPickupExpert

    env = gym.make("DeformablePickup-v0")
    expert = ScriptedPickupExpert.from_env(env)
    obs, _ = env.reset(seed=2)
    for _ in range(30):
        action = expert(obs)
        assert action.shape == (DELTA_ACTION.size,) and env.action_space.contains(action)
        target = jaw_command_to_gap(DELTA_ACTION.get(action, "jaw")[0])
        assert JAW_GAP_MIN <= target <= JAW_GAP_MAX
        obs, *_ = env.step(action)
    # the expert's open command is the layout's open gap
    assert jaw_command_to_gap(gap_to_jaw_command(JAW_GAP_MAX)) == JAW_GAP_MAX
    env.close()


def test_teleop_uses_the_layout():
    from teleop import ACTION_NAMES, make_action
    from teleop.retarget.gripper_ik import ACTION_GAP_MAX_M, driver_angle_from_gap, gap_limits
    from teleop.teleop_device import ACTION_DIM, FEEDBACK_NAMES, MAX_GAP_M, parse_agent_state

    assert MAX_GAP_M == ACTION_GAP_MAX_M == gap_limits()[1] == JAW_GAP_MAX == ABSOLUTE_ACTION.bounds()[1][-1]
    assert len(ACTION_NAMES) == ACTION_DIM == ABSOLUTE_ACTION.size
    assert FEEDBACK_NAMES == AGENT_POS.field("tip_normal_force").components
    a = make_action([0.1, 0.2, 0.3], [0, 0, 0, 1], JAW_GAP_MAX)
    np.testing.assert_array_equal(ABSOLUTE_ACTION.get(a, "gap"), np.float32([0.085]))
    with pytest.raises(ValueError, match=r"gap_m must be in \[0, 0.085\] m"):
        make_action([0, 0, 0], [0, 0, 0, 1], 0.0851)
    theta, gap = driver_angle_from_gap(JAW_GAP_MAX)
    assert theta == pytest.approx(gripper.THETA_MIN, abs=1e-12) and gap == pytest.approx(JAW_GAP_MAX, abs=1e-15)
    agent = AGENT_POS.pack(wrist_position=[0.1, 0.2, 0.3], wrist_quat=[0, 0, 0, 1], jaw_gap=[0.04],
                           tip_normal_force=[1.0, 2.0])
    pos, quat, gap = parse_agent_state({"agent_pos": agent})
    assert pos.tolist() == [0.1, 0.2, 0.3] and quat.tolist() == [0, 0, 0, 1] and gap == 0.04


def test_recorders_and_lerobot_name_columns_by_the_layout():
    from defgrasp_env.recording.lerobot_export import FrameShape, lerobot_features, lerobot_frame

    names = {"observations/agent_pos": list(AGENT_POS.names), "observations/environment_state": list(ENV_STATE.names)}
    features = lerobot_features(FrameShape(20, AGENT_POS.size, ENV_STATE.size, DELTA_ACTION.size, None), names, False)
    assert features["observation.state"]["names"] == list(AGENT_POS.names)
    assert features["observation.environment_state"]["names"] == list(ENV_STATE.names)
    # files without column names get the layout's
    bare = lerobot_features(FrameShape(20, AGENT_POS.size, ENV_STATE.size, ABSOLUTE_ACTION.size, None), {}, False)
    assert bare["action"]["names"] == list(ABSOLUTE_ACTION.names)
    assert bare["observation.state"]["names"] == list(AGENT_POS.names)
    frame = lerobot_frame(np.arange(10.0), np.arange(33.0), np.zeros(7), 1.5, True, False, "pick")
    for key, feature in features.items():
        assert np.asarray(frame[key]).shape == feature["shape"], key
        assert np.asarray(frame[key]).dtype == np.dtype(feature["dtype"]), key


def test_columns_select_fields_in_layout_order_and_reject_bad_names():
    cols = AGENT_POS.columns(["tip_normal_force", "wrist_position", "jaw_gap"])  # any order given
    assert cols.tolist() == [0, 1, 2, 7, 8, 9]
    assert [AGENT_POS.names[i] for i in cols] == ["wrist_x", "wrist_y", "wrist_z", "jaw_gap",
                                                   "left_tip_normal_force", "right_tip_normal_force"]
    vec = AGENT_POS.pack(wrist_position=[1, 2, 3], wrist_quat=[4, 5, 6, 7], jaw_gap=[8], tip_normal_force=[9, 10])
    assert vec[cols].tolist() == [1, 2, 3, 8, 9, 10]
    for bad in (["wrist_yaw"], [], ["jaw_gap", "jaw_gap"]):
        with pytest.raises(ValueError, match="agent_pos fields must be a non-empty list of distinct names"):
            AGENT_POS.columns(bad)
    with pytest.raises(ValueError, match="got the string 'jaw_gap'"):
        AGENT_POS.columns("jaw_gap")
