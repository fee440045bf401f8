"""LeRobot integration: the ``defgrasp`` EnvConfig through LeRobot's own ``make_env``, plugin
discovery, reset options, and a one-episode ``lerobot-eval`` run checked against a direct rollout."""

import json
import os
import pathlib
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

import defgrasp_env  # noqa: F401

pytest.importorskip("lerobot")

from lerobot.envs.factory import make_env, make_env_config  # noqa: E402
from lerobot.envs.utils import env_to_policy_features  # noqa: E402

from defgrasp_env.lerobot_env import DefgraspEnvConfig  # noqa: E402
from defgrasp_env.recording.lerobot_export import CAMERA_KEY  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _subprocess_env():
    return {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}


def test_config_features_match_the_env_and_the_dataset_export():
    cfg = make_env_config("defgrasp", object="torus", youngs_modulus=1e4)
    assert isinstance(cfg, DefgraspEnvConfig) and cfg.type == "defgrasp"
    env = gym.make(cfg.gym_id, **cfg.gym_kwargs)
    spaces = env.observation_space.spaces
    assert set(cfg.features) - {"action"} == set(spaces)
    for key, ft in cfg.features.items():
        shape = env.action_space.shape if key == "action" else spaces[key].shape
        assert tuple(ft.shape) == shape, key
    # the policy-side names are those `defgrasp-dataset to-lerobot` writes
    assert set(env_to_policy_features(cfg)) == {"action", "observation.state", "observation.environment_state"}
    pix = DefgraspEnvConfig(obs_type="pixels_agent_pos")
    assert set(env_to_policy_features(pix)) == {"action", "observation.state", CAMERA_KEY}
    assert env_to_policy_features(pix)[CAMERA_KEY].shape == (3, 224, 224)
    assert env.unwrapped.metadata["render_fps"] == cfg.fps == 20 and isinstance(cfg.fps, int)
    assert env.spec.max_episode_steps == 300


def test_config_rejects_bad_options_at_construction():
    with pytest.raises(ValueError, match="youngs_modulus"):
        DefgraspEnvConfig(youngs_modulus=-1.0)
    with pytest.raises(ValueError, match="obs_type"):
        DefgraspEnvConfig(obs_type="depth")
    with pytest.raises(ValueError, match="object"):
        DefgraspEnvConfig(object="banana")


def test_make_env_builds_and_steps_like_a_direct_env():
    """LeRobot's make_env -> SyncVectorEnv of gym.make: same observations and rewards as a plain env."""
    cfg = DefgraspEnvConfig(object="cuboid", youngs_modulus=1e6, episode_seconds=0.25)
    vec = make_env(cfg, n_envs=1)["defgrasp"][0]
    direct = gym.make("DeformablePickup-v0", object="cuboid", youngs_modulus=1e6)
    obs, info = vec.reset(seed=[7], options={"lerobot_new_rollout": True})
    ref, _ = direct.reset(seed=7)
    np.testing.assert_array_equal(obs["environment_state"][0], ref["environment_state"])
    assert vec.call("_max_episode_steps")[0] == 5
    action = np.array([[0.2, -0.5, 0.1, 0.0, 0.3, 0.0, 0.5]], np.float32)
    for t in range(5):
        obs, r, term, trunc, info = vec.step(action)
        ref, r_ref, *_ = direct.step(action[0])
        # SAME_STEP autoreset: the ending observation of world 0 goes to info["final_obs"][0]
        last = info["final_obs"][0]["agent_pos"] if t == 4 else obs["agent_pos"][0]
        np.testing.assert_array_equal(last, ref["agent_pos"])
        assert r[0] == pytest.approx(r_ref)
    assert trunc[0] and not term[0] and "is_success" in info["final_info"]
    # the contact model is a config field: today's default, or node contact alone for old data
    assert vec.call("config")[0].edge_contact is True
    nodes = make_env(DefgraspEnvConfig(object="cuboid", edge_contact=False), n_envs=1)["defgrasp"][0]
    assert nodes.call("config")[0].edge_contact is False
    nodes.reset(seed=[0])
    assert nodes.call("scene")[0].solver.scratch.edges.active is False
    frame = vec.call("render")[0]
    assert frame.shape == (224, 224, 3) and frame.dtype == np.uint8 and frame.std() > 0
    vec.close()


def test_state_fields_select_the_columns_the_policy_sees():
    """``state_fields`` (a dataset exported with ``--state-fields``): the config's ``agent_pos``
    feature has the chosen fields' size, and LeRobot's path (``make_env`` -> ``preprocess_observation``
    -> the config's env processor) hands the policy exactly those columns of the env's ``agent_pos``;
    a bad field name fails at construction."""
    from lerobot.envs.utils import preprocess_observation

    cfg = DefgraspEnvConfig(object="sphere", youngs_modulus=1e6, episode_seconds=0.25,
                            state_fields=["wrist_position", "jaw_gap", "tip_normal_force"])
    assert env_to_policy_features(cfg)["observation.state"].shape == (6,)
    vec = make_env(cfg, n_envs=1)["defgrasp"][0]
    obs, _ = vec.reset(seed=[3])
    obs, *_ = vec.step(np.array([[0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0]], np.float32))
    env_pre, _ = cfg.get_env_processors()
    state = env_pre(preprocess_observation(obs))["observation.state"].numpy()
    full = obs["agent_pos"]
    np.testing.assert_array_equal(state, full[:, [0, 1, 2, 7, 8, 9]])
    assert np.all(np.abs(full[:, 3:7]).sum(axis=1) > 0.5)  # the left-out quaternion was there
    vec.close()
    with pytest.raises(ValueError, match="unknown: \\['quat'\\]"):
        DefgraspEnvConfig(state_fields=["quat"])
    with pytest.raises(ValueError, match="obs_type='pixels' has no agent_pos"):
        DefgraspEnvConfig(obs_type="pixels", state_fields=["jaw_gap"])
    from defgrasp_env.lerobot_env import SelectStateColumnsStep
    for bad in ([], [0, 0], [10]):
        with pytest.raises(ValueError, match="distinct indices in \\[0, 10\\)"):
            SelectStateColumnsStep(columns=bad)


def test_reset_accepts_framework_options_and_rejects_typos():
    env = gym.make("DeformablePickup-v0")
    env.reset(seed=0, options={"lerobot_new_rollout": True, "object": "cuboid"})
    with pytest.raises(ValueError, match="objet"):
        env.reset(seed=0, options={"objet": "cuboid"})
    with pytest.raises(ValueError, match="new_rollout"):
        env.reset(seed=0, options={"new_rollout": True})  # not prefixed: a typo, not LeRobot's key


def test_plugin_is_discovered_without_flags():
    """register_third_party_plugins() (what every lerobot-* script calls) registers --env.type=defgrasp."""
    from importlib.metadata import PackageNotFoundError, distribution

    try:
        distribution("lerobot_env_defgrasp")
    except PackageNotFoundError:
        pytest.skip("plugin not installed: pip install -e plugins/lerobot_env_defgrasp")
    code = ("from lerobot.envs.configs import EnvConfig; assert 'defgrasp' not in EnvConfig.get_known_choices();"
            "from lerobot.utils.import_utils import register_third_party_plugins; register_third_party_plugins();"
            "print(EnvConfig.get_choice_class('defgrasp').__module__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                         env=_subprocess_env(), timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "defgrasp_env.lerobot_env"


@pytest.mark.slow
def test_lerobot_eval_one_episode_matches_a_direct_rollout(tmp_path):
    """`lerobot-eval` (LeRobot's CLI, in a subprocess, plugin found by --env.discover_packages_path) runs a
    tiny random-init ACT for one short episode; its reward sum equals the same policy driving
    gym.make through LeRobotPolicy on the same seed (ACT is deterministic at inference)."""
    from defgrasp_env.lerobot_policy import LeRobotPolicy, save_untrained_act

    ckpt = save_untrained_act(tmp_path / "act", seed=3)
    out = tmp_path / "eval"
    cmd = [sys.executable, "-m", "lerobot.scripts.lerobot_eval", "--env.type=defgrasp",
           "--env.discover_packages_path=defgrasp_env", "--env.object=sphere", "--env.youngs_modulus=1e5",
           "--env.episode_seconds=0.4", f"--policy.path={ckpt}", "--policy.device=cpu", "--eval.n_episodes=1",
           "--eval.batch_size=1", "--eval.use_async_envs=false", "--seed=11", f"--output_dir={out}"]
    res = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=_subprocess_env(), timeout=900)
    assert res.returncode == 0, res.stderr[-3000:]
    overall = json.loads((out / "eval_info.json").read_text())["overall"]
    assert overall["n_episodes"] == 1 and overall["pc_success"] == 0.0
    assert (out / "videos" / "defgrasp_0" / "eval_episode_0.mp4").stat().st_size > 0

    policy = LeRobotPolicy.from_pretrained(ckpt)
    env = gym.make("DeformablePickup-v0", object="sphere", youngs_modulus=1e5, max_episode_steps=8)
    obs, _ = env.reset(seed=11)
    policy.reset()
    total, done = 0.0, False
    while not done:
        obs, r, term, trunc, info = env.step(policy(obs))
        total += r
        done = term or trunc
    # float32 policy maths in two processes: equal to well below one step's reward
    assert overall["avg_sum_reward"] == pytest.approx(total, rel=1e-4, abs=1e-5)


def test_absolute_action_mode_config_builds_an_absolute_env():
    """``--env.action_mode=absolute``: the action feature is ``ABSOLUTE_ACTION`` [8] and LeRobot's
    ``make_env`` builds an env that takes it; a bad mode is refused at construction."""
    from defgrasp_env.layout import ABSOLUTE_ACTION

    cfg = make_env_config("defgrasp", object="sphere", youngs_modulus=1e6, action_mode="absolute", episode_seconds=0.1)
    assert cfg.features["action"].shape == (ABSOLUTE_ACTION.size,) and cfg.gym_kwargs["action_mode"] == "absolute"
    assert env_to_policy_features(cfg)["action"].shape == (ABSOLUTE_ACTION.size,)
    envs = make_env(cfg, n_envs=1)
    vec = next(iter(next(iter(envs.values())).values()))
    try:
        obs, _ = vec.reset(seed=[0])
        assert vec.single_action_space.shape == (ABSOLUTE_ACTION.size,)
        wrist = obs["agent_pos"][0, :3]
        action = ABSOLUTE_ACTION.pack(position=wrist[None] - [[0.0, 0.01, 0.0]], orientation=[[0.0, 0.0, 0.0, 1.0]],
                                      gap=[[0.05]]).astype(np.float32)
        obs, *_ = vec.step(action)
        np.testing.assert_allclose(obs["agent_pos"][0, 1], wrist[1] - 0.01, atol=1e-4)  # moved 1 cm down
        np.testing.assert_allclose(obs["agent_pos"][0, 7], 0.085 - 0.15 * 0.05, atol=1e-4)  # closing at 150 mm/s
    finally:
        vec.close()
    with pytest.raises(ValueError, match="action_mode"):
        DefgraspEnvConfig(action_mode="velocity")


def test_eval_lerobot_policy_script_keeps_every_episode(tmp_path):
    """``benchmarks/eval_lerobot_policy.py`` (the success table's script) runs lerobot-eval for one
    cell and writes ``episodes.json`` with that cell's episodes in order, equal to lerobot-eval's own
    ``eval_info.json``, and the cell's lerobot-eval command line; with 1 of the 20 cells it prints no
    table; a table-only call afterwards keeps the cell's command. The policy reads a state without
    the wrist orientation, so lerobot-eval parses ``--env.state_fields`` (it fails on the state's
    size otherwise)."""
    from defgrasp_env.lerobot_policy import save_untrained_act

    ckpt = save_untrained_act(tmp_path / "act", seed=5, state_fields=["wrist_position", "jaw_gap", "tip_normal_force"])
    out = tmp_path / "eval"
    lerobot_args = ["--env.episode_seconds=0.2", "--env.state_fields=[wrist_position,jaw_gap,tip_normal_force]"]
    cmd = [sys.executable, str(ROOT / "benchmarks" / "eval_lerobot_policy.py"), str(ckpt), "--episodes", "2",
           "--batch-size", "2", "--objects", "cuboid", "--moduli", "1e6", "--seed", "7", "--out", str(out),
           *lerobot_args]
    res = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=_subprocess_env(), timeout=900)
    assert res.returncode == 0, res.stderr[-3000:]
    assert "1 of 20 cells found: no table yet" in res.stdout
    kept = json.loads((out / "episodes.json").read_text())
    assert kept["seed"] == 7 and kept["lerobot_eval_args"] == lerobot_args
    assert kept["cells_run"] == ["cuboid_E1e+06"]
    metrics = json.loads((out / "cuboid_E1e+06" / "eval_info.json").read_text())["per_task"][0]["metrics"]
    assert list(kept["cells"]) == ["cuboid_E1e+06"]
    cell = kept["cells"]["cuboid_E1e+06"]
    assert cell["successes"] == metrics["successes"] == [False, False]
    assert cell["sum_rewards"] == metrics["sum_rewards"] and cell["max_rewards"] == metrics["max_rewards"]
    assert cell["folders"] == [str(out / "cuboid_E1e+06")]
    (command,) = cell["commands"]
    assert command[0] == "lerobot-eval" and "--seed=7" in command and command[-2:] == lerobot_args
    # a table-only call (no episodes) keeps each cell's own command and records no seed of its own
    res = subprocess.run(cmd[:3] + ["--episodes", "0", "--out", str(out)], capture_output=True, text=True, cwd=ROOT,
                         env=_subprocess_env(), timeout=900)
    assert res.returncode == 0, res.stderr[-3000:]
    kept = json.loads((out / "episodes.json").read_text())
    assert kept["seed"] is None and kept["lerobot_eval_args"] == [] and kept["cells_run"] == []
    assert kept["cells"]["cuboid_E1e+06"]["commands"] == [command]
