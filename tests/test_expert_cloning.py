"""``rl.expert_cloning``: noise-injected expert rollouts in the training env's SB3 stack, returns,
and the behaviour-cloning fit; ``train_ppo.py --clone-expert-steps``."""

import json
import pathlib
import sys

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))

from defgrasp_env.layout import DELTA_ACTION  # noqa: E402
from defgrasp_env.policies.scripted_expert import ScriptedPickupExpert  # noqa: E402
from defgrasp_env.rl.action_subset import POSITION_YAW_JAW  # noqa: E402
from defgrasp_env.rl.expert_cloning import (ExpertSteps, collect_expert_steps, complete_returns,  # noqa: E402
                                            discounted_returns, fit_policy)


def _venv(n=3, seed=7, **kw):
    from train_ppo import make_vec_env

    return make_vec_env(n, seed, actions="position-yaw-jaw", gamma=0.8, youngs_modulus=1e6, **kw)


def test_discounted_returns_sum_each_episode_alone():
    """Against a direct sum over each episode's remaining steps (powers of gamma, no recursion)."""
    rng = np.random.default_rng(3)
    rewards = rng.normal(size=(23, 4))
    dones = rng.random((23, 4)) < 0.2
    gamma = 0.8
    got = discounted_returns(rewards, dones, gamma)
    for w in range(4):
        for t in range(23):
            end = next((k for k in range(t, 23) if dones[k, w]), 22)  # the episode's last step (or the data's)
            want = sum(gamma ** (k - t) * rewards[k, w] for k in range(t, end + 1))
            assert got[t, w] == pytest.approx(want, rel=1e-12, abs=1e-12)
    with pytest.raises(ValueError, match="gamma"):
        discounted_returns(rewards, dones, 1.5)
    with pytest.raises(ValueError, match=r"\[T, N\]"):
        discounted_returns(rewards[:, 0], dones[:, 0], gamma)


def test_complete_returns_mark_the_steps_no_cut_reaches_within_the_horizon():
    """Against a direct look-ahead: a step's return is complete unless its episode is truncated, or
    the data ends, within the 21 steps (gamma 0.8, 99 %) after it; an episode that ends by itself is
    whole."""
    rng = np.random.default_rng(8)
    dones = rng.random((90, 5)) < 0.04
    truncated = dones & (rng.random((90, 5)) < 0.5)
    got = complete_returns(dones, truncated, 0.8)
    horizon = 21  # ceil(log 0.01 / log 0.8) = ceil(20.6)
    for w in range(5):
        for t in range(90):
            end = next((k for k in range(t, 90) if dones[k, w]), None)
            cut = (end is None and 89 - t < horizon) or (end is not None and truncated[end, w] and end - t < horizon)
            assert got[t, w] == (not cut), (t, w)
    with pytest.raises(ValueError, match="gamma and share"):
        complete_returns(dones, truncated, 1.0)

def test_collected_labels_are_the_experts_actions_on_the_recorded_observations():
    """A fresh expert replayed on the recorded (unnormalised) observations, reset where the data's
    episodes ended, gives the labels bit for bit; the worlds stepped with the labels plus clipped
    noise of each component's std (none on the jaw); the objects' episodes cut by the staggered
    starts are in ``dones``; the wrist's other turns are ~0 for the top-down expert."""
    venv = _venv(n=3, object=("cuboid", "rope", "torus"), fixed_world_objects=True, episode_seconds=1.0,
                 stagger_episodes=True)
    steps, noise = 30, (0.3, 0.3, 0.3, 0.3, 0.0)
    data = collect_expert_steps(venv, POSITION_YAW_JAW, steps, noise, np.random.default_rng(1))
    assert data.actions.shape == data.executed.shape == (steps, 3, 5) and data.rewards.shape == (steps, 3)
    assert data.obs["agent_pos"].shape == (steps, 3, 10) and data.num_samples == 90
    assert data.dones[:19].any()  # staggered first episodes cut before the 20-step limit
    assert data.truncated[data.dones].all()  # every end here a time limit or a cut (nothing succeeds in 1 s)
    # the observation after an episode's end is the next episode's first: the flange back at the start
    # height (its x, z are drawn per episode) with the jaw open, where the ended episode's had moved
    start_height = data.obs["agent_pos"][0, 0, 1]
    ends = list(zip(*np.nonzero(data.dones[:-1])))
    assert ends
    for t, w in ends:
        first, last = data.obs["agent_pos"][t + 1, w], data.obs["agent_pos"][t, w]
        assert first[1] == pytest.approx(start_height, abs=1e-6) and first[7] == pytest.approx(0.085, abs=1e-6)
        assert abs(last[1] - start_height) > 1e-3 or abs(last[7] - 0.085) > 1e-4 or t < 2
    expert = ScriptedPickupExpert.from_env(venv.unwrapped.env)
    columns = [DELTA_ACTION.names.index(c) for c in POSITION_YAW_JAW]
    expert.reset()
    for t in range(steps):
        obs = {k: v[t] for k, v in data.obs.items()}
        np.testing.assert_array_equal(expert(obs)[:, columns], data.actions[t])
        if data.dones[t].any():
            expert.reset(data.dones[t])
    offset = (data.executed - data.actions)[..., :4]
    assert np.all(np.abs(data.executed) <= 1.0) and np.all(np.isfinite(data.rewards))
    np.testing.assert_array_equal(data.executed[..., 4], data.actions[..., 4])  # the jaw's std 0
    inside = np.abs(data.executed[..., :4]) < 1.0  # not clipped: the raw noise
    assert 0.2 < offset[inside].std() < 0.4 and abs(offset[inside].mean()) < 0.1  # 200+ draws of std 0.3
    np.testing.assert_array_equal(data.noise, noise)
    assert data.dropped_max < 0.05
    venv.close()


def test_noise_free_collection_executes_the_labels_and_the_fit_learns_a_known_mapping():
    """noise 0: executed == labels. The fit, on labels made a known smooth function of the
    observations (replacing the expert's), brings the held-out action error below a tenth of the
    labels' variance and sets the policy's log std to log(noise) (0.05 at least); its critic error
    (over the steps whose return is complete) falls too."""
    from train_ppo import new_ppo

    venv = _venv(n=4, object="cuboid", episode_seconds=3.0)  # 60 steps: the first 39 have complete returns
    options = {"delta_close_lead": 3, "grip_overtravel": 0.008}
    data = collect_expert_steps(venv, POSITION_YAW_JAW, 60, 0.0, np.random.default_rng(0), options)
    assert complete_returns(data.dones, data.truncated, 0.8).sum() == 39 * 4
    np.testing.assert_array_equal(data.executed, data.actions)
    # the labels are those of the expert built with the options (its closing jaw command 3 periods
    # ahead of the gap), not the default expert's on the same observations
    columns = [DELTA_ACTION.names.index(c) for c in POSITION_YAW_JAW]
    experts = [ScriptedPickupExpert.from_env(venv.unwrapped.env, **kw) for kw in (options, {})]
    replays = []
    for expert in experts:
        expert.reset()
        replays.append(np.stack([expert({k: v[t] for k, v in data.obs.items()})[:, columns] for t in range(60)]))
    np.testing.assert_array_equal(replays[0], data.actions)
    assert np.abs(replays[1] - data.actions)[..., 4].max() > 0.047  # 2 mm of jaw gap (0.048): 3 periods, not 1
    rng = np.random.default_rng(5)
    weights = rng.normal(size=(10, 5))
    pos = data.obs["agent_pos"].astype(np.float64)
    z = (pos - pos.reshape(-1, 10).mean(0)) / (pos.reshape(-1, 10).std(0) + 1e-6)
    known = ExpertSteps(data.obs, np.tanh(z @ weights * 0.5).astype(np.float32), data.executed, data.rewards,
                        data.dones, data.truncated, data.successes, 0.0, data.components,
                        np.array([0.25, 0.25, 0.25, 0.25, 0.0]))
    model = new_ppo(venv, n_steps=8, minibatches=1, n_epochs=1, learning_rate=3e-4, gamma=0.8, gae_lambda=0.9, seed=0)
    history = fit_policy(model.policy, venv, known, gamma=0.8, epochs=150, batch_size=32, learning_rate=1e-3,
                         holdout=0.25, rng=np.random.default_rng(2))  # one world of four held out
    variance = float(known.actions.var())
    assert history[-1]["holdout_action_mse"] < 0.1 * variance < history[0]["holdout_action_mse"]
    # the per-component held-out RMS: one per action component, their mean square the held-out MSE
    rms = np.array([history[-1][f"holdout_rms_{c}"] for c in POSITION_YAW_JAW])
    assert np.mean(rms ** 2) == pytest.approx(history[-1]["holdout_action_mse"], rel=1e-5)
    assert history[-1]["value_mse"] < 0.5 * history[0]["value_mse"]
    np.testing.assert_allclose(model.policy.log_std.detach().cpu().numpy(), np.log([0.25] * 4 + [0.05]), rtol=1e-6)
    venv.close()


def test_collect_and_fit_reject_bad_inputs():
    from train_ppo import ExpertClone

    venv = _venv(n=1, object="cuboid", episode_seconds=0.5)
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match=r"distinct names"):
        collect_expert_steps(venv, ("vx", "vx", "vz", "wy", "jaw"), 2, 0.1, rng)
    with pytest.raises(ValueError, match=r"components \['vx', 'vy', 'vz', 'jaw'\] have 4"):
        collect_expert_steps(venv, ("vx", "vy", "vz", "jaw"), 2, 0.1, rng)
    with pytest.raises(ValueError, match="steps must be >= 1, got 0"):
        collect_expert_steps(venv, POSITION_YAW_JAW, 0, 0.1, rng)
    with pytest.raises(ValueError, match=r"noise must be one finite std >= 0 or one per component \(5\), got -0.1"):
        collect_expert_steps(venv, POSITION_YAW_JAW, 2, -0.1, rng)
    with pytest.raises(ValueError, match="one per component"):
        collect_expert_steps(venv, POSITION_YAW_JAW, 2, (0.1, 0.1), rng)
    with pytest.raises(TypeError, match="VecNormalize"):
        collect_expert_steps(venv.venv, POSITION_YAW_JAW, 2, 0.1, rng)
    with pytest.raises(ValueError, match="clone steps and epochs"):
        ExpertClone(steps=10, noise=1.5)
    with pytest.raises(ValueError, match="delta_close_lead must be an integer >= 1"):
        ExpertClone(steps=10, close_lead=0)
    with pytest.raises(ValueError, match="grip_overtravel must be a finite number"):
        ExpertClone(steps=10, grip_overtravel=-0.001)
    venv.close()


def test_train_ppo_starts_from_the_clone_records_it_and_resumes_without_cloning_again(tmp_path):
    """``train(clone=...)``: the clone's record in the run's settings (the noisy expert's episodes
    counted as they ended); PPO then trains from the fitted policy; ``resume`` goes on without
    repeating the clone (its record kept); a clone with ``resume`` or ``init_from`` is refused."""
    from train_ppo import ExpertClone, save_run, train

    kw = dict(num_envs=2, n_steps=8, minibatches=1, episode_seconds=0.5, actions="position-yaw-jaw", object="cuboid",
              youngs_modulus=1e6, seed=3)
    model, curve = train(timesteps=16, clone=ExpertClone(steps=12, noise=0.2, epochs=2), **kw)
    record = curve.settings["clone_expert"]
    assert record["samples"] == 24 and record["expert_episodes"] == 2 and record["noise"] == 0.2  # 10-step episodes
    assert np.isclose(model.policy.log_std.detach().cpu().numpy(), np.log(0.2), atol=0.05).all()  # 2 PPO updates on
    assert model.num_timesteps == 16
    save_run(model, curve, tmp_path, "clone")
    assert json.loads((tmp_path / "run.json").read_text())["clone_expert"]["steps"] == 12
    resumed, curve2 = train(timesteps=32, resume=tmp_path, **kw)
    assert resumed.num_timesteps == 16 + 32 and curve2.settings["clone_expert"] == record
    for start in ("resume", "init_from"):
        with pytest.raises(ValueError, match=r"--clone-expert-steps\) starts a new run .*not with --resume or --init-from"):
            train(timesteps=8, clone=ExpertClone(steps=4), **{start: tmp_path}, **kw)
    with pytest.raises(ValueError, match="--policy-std sets a new run's start: not with --resume"):
        train(timesteps=8, resume=tmp_path, policy_std=0.3, **kw)


def test_policy_std_sets_a_new_runs_std_after_its_init_and_is_kept_by_a_resume(tmp_path):
    """``train(init_from=..., policy_std=0.4)``: every component's std starts at 0.4 (the source's
    are 0.2 and 0.05 here), the other weights are the source's; a resume keeps the record."""
    import torch
    from train_ppo import ExpertClone, save_run, train

    kw = dict(num_envs=2, n_steps=8, minibatches=1, episode_seconds=0.5, actions="position-yaw-jaw", object="cuboid",
              youngs_modulus=1e6, seed=3)
    source, curve = train(timesteps=0, clone=ExpertClone(steps=4, noise=(0.2, 0.2, 0.2, 0.2, 0.0), epochs=1), **kw)
    save_run(source, curve, tmp_path / "clone", "clone")
    np.testing.assert_allclose(source.policy.log_std.detach().numpy(), np.log([0.2] * 4 + [0.05]), rtol=1e-6)
    model, curve2 = train(timesteps=0, init_from=tmp_path / "clone", policy_std=0.4, **kw)
    np.testing.assert_allclose(model.policy.log_std.detach().numpy(), np.log(0.4), rtol=1e-6)
    torch.testing.assert_close(model.policy.action_net.weight, source.policy.action_net.weight)
    assert curve2.settings["policy_std"] == 0.4
    save_run(model, curve2, tmp_path / "ft", "ft")
    _, curve3 = train(timesteps=16, resume=tmp_path / "ft", init_from=tmp_path / "clone", **kw)
    assert curve3.settings["policy_std"] == 0.4
    with pytest.raises(ValueError, match=r"policy std must be in \(0, 10\), got 0.0"):
        train(timesteps=0, policy_std=0.0, **kw)


def test_collection_over_cpu_shards_equals_one_vector_env():
    """``train_ppo.py --device cpu,cpu``: the expert configures itself from a ``ShardedVectorEnv``
    (its ``config``) and the collected steps are those of one vector env, bit for bit."""
    kw = dict(object=("cuboid", "torus", "rope"), fixed_world_objects=True, episode_seconds=0.75)
    single = _venv(n=3, **kw)
    one = collect_expert_steps(single, POSITION_YAW_JAW, 20, 0.1, np.random.default_rng(4))
    single.close()
    sharded = _venv(n=3, shard_devices=["cpu", "cpu"], **kw)
    assert sharded.unwrapped.env.config.youngs_modulus == 1e6
    two = collect_expert_steps(sharded, POSITION_YAW_JAW, 20, 0.1, np.random.default_rng(4))
    for k in one.obs:
        np.testing.assert_array_equal(one.obs[k], two.obs[k])
    np.testing.assert_array_equal(one.actions, two.actions)
    np.testing.assert_array_equal(one.rewards, two.rewards)
    np.testing.assert_array_equal(one.dones, two.dones)
    sharded.close()


def test_frozen_observation_statistics_stay_while_rewards_are_still_normalised(tmp_path):
    """``rl.normalisation``: frozen, a VecNormalize's observation means, variances and counts stay
    bit for bit over steps while its return statistics move; thawed they move again; a saved and
    loaded VecNormalize stays frozen. ``train(freeze_obs_normalisation=True)`` from a saved run keeps
    that run's statistics through PPO's steps (without it they change), and records the option."""
    from stable_baselines3.common.vec_env import VecNormalize
    from train_ppo import ExpertClone, save_run, train

    from defgrasp_env.rl.normalisation import (FrozenRunningMeanStd, observation_statistics_frozen,
                                               set_observation_statistics_frozen)

    def stats(v):
        return {k: (r.mean.copy(), r.var.copy(), r.count) for k, r in v.obs_rms.items()}

    def same(a, b):
        return all(np.array_equal(a[k][0], b[k][0]) and np.array_equal(a[k][1], b[k][1]) and a[k][2] == b[k][2]
                   for k in a)

    venv = _venv(n=2, object="cuboid", episode_seconds=0.5)
    venv.reset()
    step = np.full((2, 5), 0.5, np.float32)
    venv.step(step)
    set_observation_statistics_frozen(venv, True)
    assert observation_statistics_frozen(venv)
    assert isinstance(venv.obs_rms["agent_pos"].copy(), FrozenRunningMeanStd)  # SB3's copy() would thaw it
    before, ret = stats(venv), venv.ret_rms.count
    for _ in range(3):
        venv.step(step)
    assert same(before, stats(venv)) and venv.ret_rms.count == ret + 3 * 2  # a count per world-step
    venv.save(str(tmp_path / "v.pkl"))
    loaded = VecNormalize.load(str(tmp_path / "v.pkl"), venv.venv)
    assert observation_statistics_frozen(loaded) and same(before, stats(loaded))
    set_observation_statistics_frozen(venv, False)
    assert not observation_statistics_frozen(venv) and same(before, stats(venv))  # thawed with its values
    venv.step(step)
    assert not same(before, stats(venv))
    with pytest.raises(TypeError, match="VecNormalize"):
        set_observation_statistics_frozen(venv.venv, True)
    venv.close()

    kw = dict(num_envs=2, n_steps=8, minibatches=1, episode_seconds=0.5, actions="position-yaw-jaw", object="cuboid",
              youngs_modulus=1e6, seed=3)
    source, curve = train(timesteps=0, clone=ExpertClone(steps=6, epochs=1), **kw)
    save_run(source, curve, tmp_path / "clone", "clone")
    start = stats(source.get_vec_normalize_env())
    frozen, curve2 = train(timesteps=16, init_from=tmp_path / "clone", freeze_obs_normalisation=True, **kw)
    assert same(start, stats(frozen.get_vec_normalize_env())) and curve2.settings["freeze_obs_normalisation"]
    moving, curve3 = train(timesteps=16, init_from=tmp_path / "clone", **kw)
    assert not same(start, stats(moving.get_vec_normalize_env())) and "freeze_obs_normalisation" not in curve3.settings
