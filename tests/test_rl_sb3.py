"""``SB3VectorEnv``: the native vector env under Stable-Baselines3's VecEnv protocol, and a PPO smoke run."""

import json
import pathlib

import gymnasium as gym
import numpy as np
import pytest

import defgrasp_env  # noqa: F401

pytest.importorskip("stable_baselines3")

from defgrasp_env.layout import AGENT_POS  # noqa: E402
from defgrasp_env.rl.sb3_vec_env import SB3VectorEnv  # noqa: E402


def _vec(n=2, steps=3, **kw):
    return gym.make_vec("DeformablePickup-v0", num_envs=n, autoreset_mode="SameStep", max_episode_steps=steps, **kw)


def test_protocol_matches_the_native_env_and_auto_resets():
    venv = SB3VectorEnv(_vec())
    ref = _vec()
    venv.seed(5)
    obs = venv.reset()
    ref_obs, _ = ref.reset(seed=5)
    for k in ref_obs:
        np.testing.assert_array_equal(obs[k], ref_obs[k])
    first = obs["environment_state"].copy()
    actions = np.tile(np.array([0.1, -0.3, 0.0, 0.0, 0.2, 0.0, 0.4], np.float32), (2, 1))
    for t in range(3):
        venv.step_async(actions)
        obs, reward, done, infos = venv.step_wait()
        ref_obs, ref_r, _, ref_trunc, ref_info = ref.step(actions)
        assert reward.dtype == np.float32 and reward.shape == (2,)
        np.testing.assert_allclose(reward, ref_r, rtol=1e-6)
        assert len(infos) == 2 and all("is_success" in i for i in infos)
    # the time limit ended both episodes: terminal obs = the native env's last obs, new episode started
    assert done.all() and all(i["TimeLimit.truncated"] for i in infos)
    for w in range(2):
        np.testing.assert_array_equal(infos[w]["terminal_observation"]["agent_pos"], ref_info["final_obs"]["agent_pos"][w])
    assert not np.allclose(obs["environment_state"], first)  # fresh noise draw for the new episodes
    np.testing.assert_array_equal(obs["agent_pos"], ref_obs["agent_pos"])


def test_staggered_first_episodes_are_cut_at_seeded_steps_and_leave_the_rest_of_the_run_as_it_was():
    """``stagger_first_episodes``: each world's first episode ends, as a truncation marked
    ``staggered_start``, at a step drawn from 1 .. the time limit (``first_episode_steps``,
    reproducible from the seed; a draw of the limit is the env's own truncation); until then every world steps
    bit-identically to an unstaggered adapter driven by the same actions, the cut world's terminal
    observation is the unstaggered world's observation of that step, and its next episode starts
    where the unstaggered world's second one does (the same reset draw from the world's RNG); the
    other worlds are untouched by the cut's partial reset. Later episodes run to the time limit."""
    n, limit = 6, 5
    staggered, plain = SB3VectorEnv(_vec(n, limit), stagger_first_episodes=True), SB3VectorEnv(_vec(n, limit))
    for venv in (staggered, plain):
        venv.seed(3)
    obs_s, obs_p = staggered.reset(), plain.reset()
    cut_at = staggered.first_episode_steps.copy()
    again = SB3VectorEnv(_vec(n, limit), stagger_first_episodes=True)
    again.seed(3)
    again.reset()
    np.testing.assert_array_equal(again.first_episode_steps, cut_at)  # seeded
    again.close()
    assert ((cut_at >= 1) & (cut_at <= limit)).all() and len(set(cut_at.tolist())) > 1
    assert (cut_at == limit).any() and (cut_at < limit).any()  # seed 3: both kinds of first episode end
    rng = np.random.default_rng(0)
    plain_second_start = {}  # world -> the unstaggered world's second episode's first agent_pos / environment_state
    ended = {}  # world -> (step, info) of its staggered first episode's end
    for step in range(1, 2 * limit + 1):
        actions = rng.uniform(-1, 1, (n, 7)).astype(np.float32)
        for venv in (staggered, plain):
            venv.step_async(actions)
        obs_s, _, done_s, infos_s = staggered.step_wait()
        obs_p, _, done_p, infos_p = plain.step_wait()
        for w in range(n):
            if step == limit:
                assert done_p[w]
                plain_second_start[w] = {k: v[w].copy() for k, v in obs_p.items()}
            if w in ended:  # its later episodes run to the time limit, unmarked
                assert done_s[w] == ((step - ended[w][0]) % limit == 0) and "staggered_start" not in infos_s[w]
                continue
            if step < cut_at[w]:  # still in its first episode, as the unstaggered world
                assert not done_s[w]
                for k in obs_s:
                    np.testing.assert_array_equal(obs_s[k][w], obs_p[k][w])
            else:
                assert step == cut_at[w] and done_s[w]
                info = infos_s[w]
                assert info["TimeLimit.truncated"] and info["staggered_start"]
                terminal = info["terminal_observation"]
                for k in terminal:
                    ref = infos_p[w]["terminal_observation"][k] if step == limit else obs_p[k][w]
                    np.testing.assert_array_equal(terminal[k], ref)
                ended[w] = (step, {k: v[w].copy() for k, v in obs_s.items()})
    assert sorted(ended) == list(range(n))
    for w, (step, first) in ended.items():
        for k in first:  # the new episode's first observation: the unstaggered world's second reset
            np.testing.assert_array_equal(first[k], plain_second_start[w][k])
    staggered.close(), plain.close()


def test_learning_curves_leave_staggered_first_episodes_out():
    """A staggered run's first episodes are not a sample of the task's (a success before the cut
    is kept, a failure cut): the curve counts neither their success nor their end, and starts the
    world's next episode at their end."""
    import sys
    from types import SimpleNamespace

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from train_ppo import LearningCurve

    curve = LearningCurve({}, 0, episode_steps=3)
    curve.model = SimpleNamespace(n_steps=3)
    # world 0: its staggered first episode succeeds and ends at step 1, its next one fails at step 3;
    # world 1: a success at step 3
    plan = [((True, False), ({"staggered_start": True, "is_success": True}, {})), ((False, False), ({}, {})),
            ((True, True), ({}, {"is_success": True}))]
    for dones, (i0, i1) in plan:
        curve.locals = {"dones": np.array(dones), "infos": [{"episode": {"r": 0.0}, **i0}, {"episode": {"r": 0.0}, **i1}]}
        curve._on_step()
    curve._on_rollout_end()
    assert curve.rows[0]["episodes"] == 2 and curve.rows[0]["success_rate"] == 0.5
    assert curve._ended == [(1, False, False), (0, True, False)]  # world 0's second episode began at step 1


def test_per_world_infos_hold_every_batched_info_entry():
    """Each world's info dict has, for every batched info array of the native env, that world's
    entry: a Python scalar (bool, int, float: SB3 and its loggers expect plain numbers)."""
    venv = SB3VectorEnv(_vec(n=3, steps=10))
    ref = _vec(n=3, steps=10)
    venv.seed(1)
    venv.reset()
    ref.reset(seed=1)
    a = np.random.default_rng(0).uniform(-1, 1, (3, 7)).astype(np.float32)
    venv.step_async(a)
    _, _, _, infos = venv.step_wait()
    _, _, _, _, ref_info = ref.step(a)
    keys = [k for k, v in ref_info.items() if isinstance(v, np.ndarray) and not k.startswith("_")]
    assert len(keys) >= 15
    for w in range(3):
        for k in keys:
            assert type(infos[w][k]) in (bool, int, float), (k, type(infos[w][k]))
            assert infos[w][k] == ref_info[k][w], k


def test_split_info_handles_masks_objects_and_rows():
    """Gymnasium's batched info format, every branch: a masked entry (worlds 0 and 2 only), an
    object array (a ReplaySpec-like entry per world), a 2-D array (a row per world, kept an array),
    numeric 1-D arrays (Python scalars), and entries SB3 must not see (masks, final obs/info)."""
    venv = SB3VectorEnv(_vec(n=3))
    specs = np.empty(3, dtype=object)
    specs[:] = [{"seed": 7}, None, {"seed": 9}]
    info = {"is_success": np.array([True, False, True]), "_is_success": np.ones(3, bool),
            "object": np.array(["cuboid", "", "rope"], dtype=object), "_object": np.array([True, False, True]),
            "replay_spec": specs, "_replay_spec": np.array([True, False, True]),
            "tip": np.arange(6.0).reshape(3, 2), "steps": np.array([1, 2, 3]),
            "final_obs": {"agent_pos": np.zeros((3, 10))}, "_final_obs": np.zeros(3, bool), "note": "not an array"}
    out = venv._split_info(info)
    assert out[1] == {"is_success": False, "tip": out[1]["tip"], "steps": 2}  # masked entries absent
    np.testing.assert_array_equal(out[1]["tip"], [2.0, 3.0])
    assert out[0]["object"] == "cuboid" and out[2]["object"] == "rope" and "object" not in out[1]
    assert out[0]["replay_spec"] == {"seed": 7} and out[2]["replay_spec"] is specs[2]
    assert type(out[0]["is_success"]) is bool and type(out[2]["steps"]) is int
    assert all(k not in w for w in out for k in ("_is_success", "final_obs", "_final_obs", "note"))
    venv.close()


def _quat_rel(q, q0):
    """xyzw quaternion q * conj(q0) (the rotation from q0 to q, world frame), rows [N, 4]."""
    x1, y1, z1, w1 = np.moveaxis(q, -1, 0)
    x2, y2, z2, w2 = np.moveaxis(q0 * np.array([-1, -1, -1, 1]), -1, 0)
    return np.stack([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2], -1)


# the DELTA_ACTION [7] (vx vy vz wx wy wz jaw) a subset's action a gives, written out by hand
@pytest.mark.parametrize("subset, full", [
    ("POSITION_JAW", lambda a, z: np.concatenate([a[:, :3], z, z, z, a[:, 3:]], axis=1)),
    ("POSITION_YAW_JAW", lambda a, z: np.concatenate([a[:, :3], z, a[:, 3:4], z, a[:, 4:]], axis=1)),
])
def test_action_subsets_step_the_env_as_the_full_action_with_the_other_components_zero(subset, full):
    """Actions through ``ActionSubset`` give the bits of the native env stepped with the full
    action written out by hand; without yaw the wrist's orientation never changes, with it the
    wrist turns about the vertical only (it keeps pointing down)."""
    from defgrasp_env.rl import action_subset

    components = getattr(action_subset, subset)
    venv = action_subset.ActionSubset(SB3VectorEnv(_vec(steps=10)), components)
    ref = _vec(steps=10)
    k = len(components)
    assert venv.action_space.shape == (k,)
    venv.seed(2)
    obs = venv.reset()
    ref_obs, _ = ref.reset(seed=2)
    quat0 = AGENT_POS.get(obs["agent_pos"], "wrist_quat").copy()
    rng = np.random.default_rng(0)
    zero = np.zeros((2, 1), np.float32)
    for _ in range(4):
        a = rng.uniform(-1, 1, (2, k)).astype(np.float32)
        venv.step_async(a)
        obs, reward, _, _ = venv.step_wait()
        ref_obs, ref_r, *_ = ref.step(full(a, zero))
        for key in ref_obs:
            np.testing.assert_array_equal(obs[key], ref_obs[key])
        np.testing.assert_array_equal(reward, ref_r.astype(np.float32))
    turn = _quat_rel(AGENT_POS.get(obs["agent_pos"], "wrist_quat"), quat0)
    np.testing.assert_allclose(turn[:, [0, 2]], 0.0, atol=1e-6)  # no tilt: about y at most
    yaw = 2 * np.arctan2(np.abs(turn[:, 1]), np.abs(turn[:, 3]))
    if "wy" in components:
        assert np.all(yaw > 0.01)  # 4 random yaw rates of up to 1.5 rad/s x 0.05 s
    else:
        np.testing.assert_allclose(yaw, 0.0, atol=1e-6)
    assert not np.allclose(AGENT_POS.get(obs["agent_pos"], "wrist_position"),
                           AGENT_POS.get(ref.reset(seed=2)[0]["agent_pos"], "wrist_position"))  # it moved
    with pytest.raises(ValueError, match=rf"shape \(2, {k}\)"):
        venv.step_async(np.zeros((2, 7), np.float32))


@pytest.mark.parametrize("components", [("vx", "spin"), ("vx", "vx"), ()])
def test_action_subset_rejects_bad_components(components):
    from defgrasp_env.rl.action_subset import ActionSubset

    with pytest.raises(ValueError, match="distinct names of"):
        ActionSubset(SB3VectorEnv(_vec(steps=10)), components)


def test_rejects_other_autoreset_modes():
    with pytest.raises(ValueError, match="SameStep"):
        SB3VectorEnv(gym.make_vec("DeformablePickup-v0", num_envs=1))


@pytest.mark.slow
def test_ppo_trains_on_the_vector_env(tmp_path, monkeypatch):
    """Two PPO iterations through VecMonitor + VecNormalize: the policy's parameters change, the
    curve records both rollouts, and the script's PNG/CSV are written."""
    import sys

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from train_ppo import BestPolicy, save_curve, save_run, train

    best = BestPolicy(tmp_path / "best", min_episodes=1)
    model, curve = train(num_envs=2, timesteps=32, n_steps=8, minibatches=2, episode_seconds=0.3,
                         actions="position-jaw", object="cuboid", best=best)
    assert model.num_timesteps == 32 and len(curve.rows) == 2
    cohorts = [r for r in curve.rows if r["cohort_episodes"] >= 1]
    assert cohorts, "the test needs a rollout with a cohort"
    kept = json.loads((tmp_path / "best" / "best.json").read_text())   # the callback offered every rollout
    assert kept["cohort_success_rate"] == max(r["cohort_success_rate"] for r in cohorts)
    assert sum(r["episodes"] for r in curve.rows) == 2 * (16 // 6)  # 6-step episodes, 2 worlds x 16 steps
    for r in curve.rows:  # step costs: 4 substeps a step, each at least one Newton iteration with CG in it
        assert 0 < r["step_ms_p50"] <= r["step_ms_p95"] < 1e3 * r["rollout_s"]
        assert r["slowest_newton"] >= 4 and r["slowest_cg"] >= r["slowest_newton"]
    params = [p.detach().clone() for p in model.policy.parameters()]
    model.learn(16, reset_num_timesteps=False)
    assert any(not np.allclose(a.numpy(), b.detach().numpy()) for a, b in zip(params, model.policy.parameters()))
    save_curve(curve.rows, tmp_path, "smoke")
    assert (tmp_path / "curve.png").stat().st_size > 1000 and (tmp_path / "curve.csv").is_file()

    # --resume: the saved model, normalisation statistics and curve go on
    save_run(model, curve, tmp_path, "smoke")
    with pytest.raises(ValueError, match=r"object: saved 'cuboid', given 'torus'"):
        train(num_envs=2, timesteps=16, n_steps=8, episode_seconds=0.3, actions="position-jaw", resume=tmp_path,
              object="torus")
    with pytest.raises(ValueError, match=r"edge_contact: saved True, given None"):  # the contact model too
        train(num_envs=2, timesteps=16, n_steps=8, episode_seconds=0.3, actions="position-jaw", resume=tmp_path,
              object="cuboid", edge_contact=False)
    seeds = []  # the seeds each SB3 reset of the env uses
    reset = SB3VectorEnv.reset
    monkeypatch.setattr(SB3VectorEnv, "reset", lambda self: (seeds.append(list(self._seeds)), reset(self))[1])
    count = model.get_vec_normalize_env().obs_rms["agent_pos"].count
    weights = [p.detach().clone() for p in model.policy.parameters()]
    resumed, curve2 = train(num_envs=2, timesteps=16, n_steps=8, episode_seconds=0.3, actions="position-jaw",
                            resume=tmp_path, object="cuboid")
    assert resumed.num_timesteps == model.num_timesteps + 16
    assert seeds[0] == [curve.rows[-1]["env_steps"] + i for i in range(2)]  # --seed 0 + steps so far: new episodes
    assert curve2.env_seed == curve.rows[-1]["env_steps"] and curve2.settings == curve.settings
    assert len(curve2.rows) == len(curve.rows) + 1  # the CSV round trip keeps every earlier row:
    for saved, loaded in zip(curve.rows, curve2.rows):
        assert saved.keys() == loaded.keys()
        np.testing.assert_allclose([float(v) for v in loaded.values()], [float(v) for v in saved.values()],
                                   rtol=1e-12, equal_nan=True)
    assert resumed.get_vec_normalize_env().obs_rms["agent_pos"].count > count  # the loaded statistics went on

    # --init-from: a new run (other options: 1 world) starts from the saved policy and statistics
    save_run(resumed, curve2, tmp_path, "smoke")
    saved = {k: v.detach().cpu().numpy().copy() for k, v in resumed.policy.state_dict().items()}
    fresh, _ = train(num_envs=1, timesteps=8, n_steps=8, episode_seconds=0.3, actions="position-jaw", seed=7,
                     object="cuboid")
    started, curve3 = train(num_envs=1, timesteps=8, n_steps=8, episode_seconds=0.3, actions="position-jaw", seed=7,
                            init_from=tmp_path, object="cuboid")
    assert curve3.settings["init_from"] == str(tmp_path) and len(curve3.rows) == 1
    def distance(model):
        return max(float(np.abs(v.detach().cpu().numpy() - saved[k]).max()) for k, v in model.policy.state_dict().items())
    assert distance(started) < 0.1 * distance(fresh)  # one small PPO update away from the saved weights
    assert started.get_vec_normalize_env().obs_rms["agent_pos"].count > resumed.get_vec_normalize_env().obs_rms["agent_pos"].count
    assert 0.0 <= curve3.rows[0]["at_goal_fraction"] <= curve3.rows[0]["grasped_fraction"]
    assert any(not np.allclose(a.numpy(), b.detach().cpu().numpy()) for a, b in zip(weights, resumed.policy.parameters()))


@pytest.mark.slow
def test_ppo_trains_on_staggered_worlds_whose_successes_do_not_terminate(tmp_path):
    """``train(stagger_episodes=True, terminate_on_success=False)`` (the hold recipe): the run
    records both options (a resume must repeat them), and its curve counts every episode that ended
    except the staggered first ones: world i's first episode ends at step c_i
    (``SB3VectorEnv.first_episode_steps``; a draw of 10 is the time limit itself), its next one
    c_i + 10 steps in."""
    import sys

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from train_ppo import save_run, train

    worlds, steps, limit = 4, 16, 10  # 0.5 s episodes at 20 Hz
    model, curve = train(num_envs=worlds, timesteps=worlds * steps, n_steps=8, minibatches=2, episode_seconds=0.5,
                         actions="position-jaw", object="cuboid", stagger_episodes=True, terminate_on_success=False,
                         seed=4)
    assert curve.settings["stagger_episodes"] is True and curve.settings["terminate_on_success"] is False
    adapter = model.get_env()
    while not isinstance(adapter, SB3VectorEnv):  # VecNormalize -> VecMonitor -> ActionSubset -> SB3VectorEnv
        adapter = adapter.venv
    cut = adapter.first_episode_steps
    assert (cut == limit).any() and (cut < limit).any()  # seed 4: both kinds of first episode end
    assert sum(r["episodes"] for r in curve.rows) == int(np.sum(cut + limit <= steps))
    # successes that do not terminate: the curve has the holding columns (no world-step is 5 s into a 0.5 s episode)
    assert curve.holding_steps == 100 and all(r["holding_world_steps"] == 0 for r in curve.rows)
    save_run(model, curve, tmp_path, "smoke")
    with pytest.raises(ValueError, match=r"stagger_episodes: saved True, given None"):
        train(num_envs=worlds, timesteps=8, n_steps=8, episode_seconds=0.5, actions="position-jaw", object="cuboid",
              terminate_on_success=False, seed=4, resume=tmp_path)


def test_best_policy_keeps_the_policy_of_the_best_cohort_rate(tmp_path):
    """``BestPolicy``: among rollouts with enough cohort episodes the best rate's policy (the weights
    the model had then, changed between offers here) is saved as a run folder (weights,
    normalisation, settings, best.json with the row); a resumed run's keeper takes only a better
    rate; a fresh run removes an earlier run's kept policy; bad sizes are refused."""
    import sys

    import torch
    from stable_baselines3 import PPO

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from train_ppo import TASK_GOAL_RANKING, BestPolicy, train

    model, curve = train(num_envs=1, timesteps=8, n_steps=8, episode_seconds=0.3, actions="position-jaw",
                         object="cuboid")
    folder = tmp_path / "best"
    best = BestPolicy(folder, min_episodes=100)
    first = next(iter(model.policy.parameters()))

    def row(rate, episodes, steps):
        return {"env_steps": steps, "wall_s": 1.0, "cohort_success_rate": rate, "cohort_episodes": episodes}

    offers = [(float("nan"), 0), (0.2, 300), (0.9, 99), (0.4, 300), (0.3, 300), (0.4, 500)]
    saved, weights = [], []
    for i, (rate, n) in enumerate(offers):
        with torch.no_grad():
            first.add_(1.0)   # another policy at every rollout
        weights.append(first.detach().cpu().numpy().copy())
        saved.append(best.offer(model, row(rate, n, 100 * i), curve.settings))
    assert saved == [False, True, False, True, False, False]
    assert json.loads((folder / "best.json").read_text()) == row(0.4, 300, 300)
    assert json.loads((folder / "run.json").read_text()) == json.loads(json.dumps(curve.settings))
    kept = PPO.load(folder / "ppo.zip").policy
    np.testing.assert_array_equal(next(iter(kept.parameters())).detach().cpu().numpy(), weights[3])
    assert (folder / "vecnormalize.pkl").stat().st_size > 0 and sorted(p.name for p in tmp_path.iterdir()) == ["best"]
    again = BestPolicy(folder, min_episodes=100, resumed=True)
    assert again.rate == 0.4 and not again.offer(model, row(0.35, 300, 700), curve.settings)
    assert again.offer(model, row(0.45, 300, 800), curve.settings) and again.rate == 0.45
    fresh = BestPolicy(folder, min_episodes=100)   # another run into the same --out
    assert fresh.rate == float("-inf") and not folder.exists()
    with pytest.raises(ValueError, match="min_episodes must be >= 1, got 0"):
        BestPolicy(folder, min_episodes=0)
    # a run on drawn goals ranks by its pooled rate at the task's goal, not the cohort over all goals
    ranked = BestPolicy(tmp_path / "ranked", 100, False, *TASK_GOAL_RANKING)
    goal_row = {**row(0.9, 300, 900), TASK_GOAL_RANKING[0]: 0.3, TASK_GOAL_RANKING[1]: 260}
    assert ranked.offer(model, goal_row, curve.settings) and ranked.rate == 0.3
    assert not ranked.offer(model, {**goal_row, "cohort_success_rate": 0.95, TASK_GOAL_RANKING[0]: 0.25},
                            curve.settings)
    assert json.loads((tmp_path / "ranked" / "best.json").read_text()) == goal_row
    assert BestPolicy(tmp_path / "ranked", 100, True, *TASK_GOAL_RANKING).rate == 0.3


def test_cohort_success_rate_is_unbiased_where_the_ended_rate_is_not():
    """All worlds start together; a success ends an episode after 3-5 steps, a failure at the
    10-step limit. The rate among the episodes that ended in a rollout reads ~1 in the first
    rollouts (only successes have ended yet); the cohort rate (episodes begun one time limit
    before the rollout) recovers the true success probability, and counts every episode once."""
    import sys
    from types import SimpleNamespace

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from train_ppo import LearningCurve

    rng = np.random.default_rng(3)
    p, worlds, limit, n_steps, rollouts = 0.3, 400, 10, 4, 40
    curve = LearningCurve({}, 0, episode_steps=limit)
    curve.model = SimpleNamespace(n_steps=n_steps)
    def draw():
        success = rng.random(worlds) < p
        return success, np.where(success, rng.integers(3, 6, worlds), limit)
    success, length = draw()
    age, begun = np.zeros(worlds, int), []  # begun: (start step, success) of every episode
    starts = np.zeros(worlds, int)
    for step in range(1, n_steps * rollouts + 1):
        age += 1
        done = age == length
        curve.locals = {"dones": done, "infos": [{"is_success": bool(s and d), "episode": {"r": 0.0}}
                                                 for s, d in zip(success, done)]}
        curve._on_step()
        new_success, new_length = draw()
        for w in np.flatnonzero(done):
            begun.append((starts[w], bool(success[w])))
            starts[w], age[w], success[w], length[w] = step, 0, new_success[w], new_length[w]
        if step % n_steps == 0:
            curve._on_rollout_end()
    assert curve.rows[0]["success_rate"] == 1.0 and curve.rows[1]["success_rate"] > 0.9  # only successes ended yet
    final = n_steps * rollouts - limit  # episodes begun before this have all ended and been counted
    counted = [s for start, s in begun if start < final]
    assert sum(r["cohort_episodes"] for r in curve.rows) == len(counted)
    pooled = sum(r["cohort_success_rate"] * r["cohort_episodes"] for r in curve.rows if r["cohort_episodes"])
    # ~7000 episodes: the binomial standard error of the pooled rate is ~0.006; 0.03 is 5 of it
    assert abs(pooled / len(counted) - p) < 0.03 and abs(np.mean(counted) - pooled / len(counted)) < 1e-12


def test_an_episode_counts_as_a_success_if_any_of_its_steps_succeeded():
    """Without termination on success an episode may succeed and end at its time limit after the
    object left the goal: the curve counts it as a success (and each episode once)."""
    import sys
    from types import SimpleNamespace

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from train_ppo import LearningCurve

    curve = LearningCurve({}, 0, episode_steps=4)
    curve.model = SimpleNamespace(n_steps=4)
    # world 0 succeeds at step 2 and ends at the limit without; world 1 never; both end at step 4
    flags = [(False, False), (True, False), (False, False), (False, False)]
    for k, (s0, s1) in enumerate(flags):
        done = np.array([k == 3, k == 3])
        curve.locals = {"dones": done, "infos": [{"is_success": s0, "episode": {"r": 0.0}},
                                                 {"is_success": s1, "episode": {"r": 0.0}}]}
        curve._on_step()
    curve._on_rollout_end()
    assert curve.rows[0]["episodes"] == 2 and curve.rows[0]["success_rate"] == 0.5


def test_holding_rate_counts_the_world_steps_old_enough_per_object():
    """``LearningCurve(holding_steps=3)``: per rollout, the world-steps at least 3 steps into their
    episode, the fraction of them with ``is_success``, overall and per object (each episode's object
    from its reset info, re-read when a world's episode ends), against a hand count. World 0
    (cuboid) holds from its 3rd step on; world 1 (rope) never holds and its episode ends at step 4
    (a staggered cut), its next one a sphere that holds from its 3rd step (step 7)."""
    import sys
    from types import SimpleNamespace

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from train_ppo import LearningCurve

    curve = LearningCurve({}, 0, episode_steps=100, holding_steps=3)
    reset_infos = [{"object": "cuboid"}, {"object": "rope"}]
    env = SimpleNamespace(reset_infos=reset_infos)
    curve.model = SimpleNamespace(n_steps=4, get_env=lambda: env)
    for step in range(1, 9):
        done = [False, step == 4]
        holding = [step >= 3, step >= 7]
        if step == 4:
            reset_infos[1] = {"object": "sphere"}  # the autoreset's new episode
        infos = [{"is_success": holding[0], "episode": {"r": 0.0}},
                 {"is_success": holding[1] and step != 4, "episode": {"r": 0.0}, "staggered_start": step == 4}]
        curve.locals = {"dones": np.array(done), "infos": infos}
        curve._on_step()
        if step % 4 == 0:
            curve._on_rollout_end()
    first, second = curve.rows
    # rollout 1 (steps 1-4): world 0 at ages 3, 4 (holding), world 1 at ages 3, 4 (not): 2 / 4
    assert first["holding_world_steps"] == 4 and first["holding_rate"] == 0.5
    assert first["holding_rate_cuboid"] == 1.0 and first["holding_rate_rope"] == 0.0 and "holding_rate_sphere" not in first
    # rollout 2 (steps 5-8): world 0 at ages 5-8 (holding), world 1's sphere at ages 3, 4 (steps 7, 8: holding)
    assert second["holding_world_steps"] == 6 and second["holding_rate"] == 1.0
    assert second["holding_rate_sphere"] == 1.0 and "holding_rate_rope" not in second
    # terminating successes: no holding columns
    plain = LearningCurve({}, 0, episode_steps=100)
    plain.model = SimpleNamespace(n_steps=1, get_env=lambda: env)
    plain.locals = {"dones": np.array([False, False]), "infos": [{"is_success": True}, {}]}
    plain._on_step()
    plain._on_rollout_end()
    assert not any(k.startswith("holding") for k in plain.rows[0])


def test_task_goal_cohort_counts_the_episodes_whose_goal_is_the_tasks():
    """With drawn goals (``task_goal`` set) the curve also reports the cohort's episodes whose goal
    (the reset info's, read from the env when each episode begins) lies within the success
    tolerance of the task's goal: half the episodes here, succeeding with probability 0.2 where the
    others succeed with 0.8; its pooled rate recovers 0.2 and it counts each such episode once."""
    import sys
    from types import SimpleNamespace

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from train_ppo import LearningCurve

    rng = np.random.default_rng(4)
    worlds, limit, n_steps, rollouts, task = 300, 8, 4, 40, (0.0, 0.6, 0.0)
    curve = LearningCurve({}, 0, episode_steps=limit, task_goal=task)
    reset_infos = [{} for _ in range(worlds)]
    env = SimpleNamespace(reset_infos=reset_infos)  # the innermost env (no ``venv``), as SB3VectorEnv updates it
    curve.model = SimpleNamespace(n_steps=n_steps, get_env=lambda: env)
    def draw(w):
        at_task = rng.random() < 0.5
        reset_infos[w] = {"goal": np.array(task) + (rng.uniform(-0.02, 0.02, 3) if at_task else [0.0, -0.4, 0.0])}
        success = rng.random() < (0.2 if at_task else 0.8)
        return at_task, success, int(rng.integers(2, 5)) if success else limit
    state = [draw(w) for w in range(worlds)]
    age, starts, begun = np.zeros(worlds, int), np.zeros(worlds, int), []
    for step in range(1, n_steps * rollouts + 1):
        age += 1
        done = np.array([age[w] == state[w][2] for w in range(worlds)])
        ended = {w: state[w] for w in np.flatnonzero(done)}
        for w in ended:  # the env resets the ended worlds inside the step: their reset info is the new episode's
            begun.append((starts[w], ended[w][0], ended[w][1]))
            starts[w], age[w], state[w] = step, 0, draw(w)
        curve.locals = {"dones": done, "infos": [{"is_success": bool(w in ended and ended[w][1]), "episode": {"r": 0.0}}
                                                 for w in range(worlds)]}
        curve._on_step()
        if step % n_steps == 0:
            curve._on_rollout_end()
    final = n_steps * rollouts - limit
    counted = [success for start, at_task, success in begun if start < final and at_task]
    rows = [r for r in curve.rows if r["task_goal_cohort_episodes"]]
    assert sum(r["task_goal_cohort_episodes"] for r in curve.rows) == len(counted)
    pooled = sum(r["task_goal_cohort_success_rate"] * r["task_goal_cohort_episodes"] for r in rows) / len(counted)
    # ~5,000 such episodes: the binomial standard error of 0.2 is ~0.006; 0.03 is 5 of it (the
    # cohort over all goals reads ~0.5)
    assert abs(pooled - 0.2) < 0.03 and abs(pooled - np.mean(counted)) < 1e-12
    assert all(r["task_goal_cohort_episodes"] <= r["cohort_episodes"] for r in curve.rows)
    # the ranking rate (TASK_GOAL_RANKING): the fewest latest cohorts that hold >= 256 such episodes
    counts = [r["task_goal_cohort_episodes"] for r in curve.rows]
    for i, r in enumerate(curve.rows):
        tail, successes = 0, 0
        for j in range(i, -1, -1):
            if tail >= 256:
                break
            tail += counts[j]
            successes += round(curve.rows[j]["task_goal_cohort_success_rate"] * counts[j]) if counts[j] else 0
        assert r["task_goal_pooled_episodes"] == tail
        if tail:
            assert r["task_goal_pooled_success_rate"] == successes / tail
    late = curve.rows[-1]
    # >= 256 episodes: a standard error of ~0.025 at 0.2; 0.1 is 4 of it
    assert late["task_goal_pooled_episodes"] >= 256 and abs(late["task_goal_pooled_success_rate"] - 0.2) < 0.1
    # a resumed curve rebuilds the pool from its rows: the next row pools the same history
    resumed = LearningCurve({}, 0, episode_steps=limit, task_goal=task, rows=curve.rows)
    assert resumed._task_columns([True] * 3) == curve._task_columns([True] * 3)


def test_eval_ppo_runs_one_episode_per_world_reproducibly(tmp_path):
    """``eval_ppo.evaluate`` on a saved (barely trained) run: one record per world, each ended at
    the time limit or by success, outcomes that add up, the run's env options unless overridden,
    and the same episodes again for the same seed (deterministic policy, frozen normalisation)."""
    import sys

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from eval_ppo import OUTCOMES, evaluate
    from train_ppo import save_run, train

    model, curve = train(num_envs=2, timesteps=16, n_steps=8, minibatches=2, episode_seconds=0.3,
                         actions="position-jaw", object="cuboid")
    save_run(model, curve, tmp_path, "smoke")
    first = evaluate(tmp_path, 3, seed=11)
    assert [e["seed"] for e in first["episodes"]] == [11, 12, 13] and first["env"]["youngs_modulus"] == 1e5  # the default
    for e in first["episodes"]:
        assert e["outcome"] in OUTCOMES and (e["steps"] == 6 or e["success"])
        assert e["success"] == (e["outcome"] == "success")
    assert sum(first["outcomes"].values()) == 3
    # the penetration records against the same episode in a single env (a world = the single env on its seed)
    from defgrasp_env.rl.ppo_policy import PPOPolicy

    policy = PPOPolicy.from_run(tmp_path)
    env = gym.make("DeformablePickup-v0", **policy.env_kwargs)
    obs, _ = env.reset(seed=12)
    flagged, deepest, pressed, newton = 0, 0.0, 0, []
    for _ in range(6):
        obs, _, terminated, truncated, info = env.step(policy(obs))
        flagged, deepest = flagged + bool(info["sim_penetrated"]), max(deepest, float(info["penetration"]))
        pressed += info["reward_force"] < 0.0
        newton.append(info["newton_iterations"])
        if terminated or truncated:
            break
    env.close()
    assert first["episodes"][1]["penetrated_steps"] == flagged
    assert first["episodes"][1]["pressed_steps"] == pressed
    assert first["episodes"][1]["newton_iterations_median"] == np.median(newton) and min(newton) > 0
    assert first["episodes"][1]["newton_iterations_max"] == max(newton)
    assert first["episodes"][1]["max_penetration"] == round(deepest, 6) and deepest > 0  # the cube rests in the ground's penalty
    assert evaluate(tmp_path, 3, seed=11)["episodes"] == first["episodes"]
    # spread over processes: the same episodes (a world's episode depends on its seed only)
    spread = evaluate(tmp_path, 3, seed=11, workers=2)
    assert spread["episodes"] == first["episodes"] and spread["outcomes"] == first["outcomes"]
    with pytest.raises(ValueError, match="workers"):
        evaluate(tmp_path, 3, workers=0)
    longer = evaluate(tmp_path, 1, seed=11, episode_seconds=0.5)  # eval_ppo --episode-seconds
    assert longer["env"]["episode_seconds"] == 0.5 and (longer["episodes"][0]["steps"] == 10 or longer["episodes"][0]["success"])
    softer = evaluate(tmp_path, 1, seed=11, youngs_modulus=1e4)  # an option the run left at its default
    assert softer["env"] == {"object": "cuboid", "youngs_modulus": 1e4, "episode_seconds": 0.3, "edge_contact": True}
    nodes = evaluate(tmp_path, 1, seed=11, edge_contact=False)  # node-vs-box contact alone (vector env, CPU)
    assert nodes["env"]["edge_contact"] is False and sum(nodes["outcomes"].values()) == 1
    # a run.json without the key is a run trained before edge contact was the default: without it
    settings = json.loads((tmp_path / "run.json").read_text())
    assert settings["edge_contact"] is True
    del settings["edge_contact"]
    (tmp_path / "run.json").write_text(json.dumps(settings))
    assert evaluate(tmp_path, 1, seed=11)["env"]["edge_contact"] is False
    with pytest.raises(ValueError, match="gamma"):
        evaluate(tmp_path, 1, gamma=0.5)

    # a run on several objects, one per world (started from the position-jaw run with the yaw added):
    # evaluated with world i holding the i-th object, and reported per object
    many = tmp_path / "many"
    model, curve = train(num_envs=2, timesteps=16, n_steps=8, minibatches=2, episode_seconds=0.3,
                         actions="position-yaw-jaw", object=("sphere", "rope"), fixed_world_objects=True,
                         init_from=tmp_path)
    assert model.action_space.shape == (5,) and curve.settings["fixed_world_objects"] is True
    save_run(model, curve, many, "smoke")
    both = evaluate(many, 3, seed=11)
    assert both["fixed_world_objects"] and [e["object"] for e in both["episodes"]] == ["sphere", "rope", "sphere"]
    # blocks of whole object cycles keep each seed's object: [sphere, rope] and [sphere]
    assert evaluate(many, 3, seed=11, workers=3)["episodes"] == both["episodes"]
    assert {k: sum(v.values()) for k, v in both["outcomes_by_object"].items()} == {"sphere": 2, "rope": 1}
    one = evaluate(many, 2, seed=11, object="rope")  # an object override: every world holds it
    assert not one["fixed_world_objects"] and [e["object"] for e in one["episodes"]] == ["rope", "rope"]


def test_transfer_policy_maps_the_action_head_by_component():
    """A position-jaw policy started into a position-yaw-jaw one: the same mean actions for the
    shared components on any observation, zero mean yaw (the wrist held still, as before) with the
    initial log std, and the value function unchanged; full -> position-jaw drops the rotations."""
    import sys

    import torch
    from stable_baselines3 import PPO

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from train_ppo import make_vec_env

    from defgrasp_env.rl.policy_transfer import transfer_policy

    def model(actions, seed):
        return PPO("MultiInputPolicy", make_vec_env(1, 0, actions=actions, episode_seconds=0.3), n_steps=8,
                   batch_size=8, policy_kwargs=dict(net_arch=[32, 32], log_std_init=-0.5), seed=seed)

    old, new, full = model("position-jaw", 1), model("position-yaw-jaw", 2), model("full", 3)
    with torch.no_grad():
        old.policy.log_std.copy_(torch.tensor([-1.0, -2.0, -3.0, -4.0]))
    new.policy.load_state_dict(transfer_policy(old.policy.state_dict(), "position-jaw",
                                               new.policy.state_dict(), "position-yaw-jaw", -0.5))
    rng = np.random.default_rng(0)
    obs = {k: torch.as_tensor(rng.normal(size=(5,) + space.shape), dtype=torch.float32)
           for k, space in old.observation_space.spaces.items()}
    with torch.no_grad():
        mean_old = old.policy.get_distribution(obs).distribution.mean.numpy()
        mean_new = new.policy.get_distribution(obs).distribution.mean.numpy()
        np.testing.assert_allclose(new.policy.predict_values(obs).numpy(), old.policy.predict_values(obs).numpy(),
                                   rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(mean_new[:, [0, 1, 2, 4]], mean_old, rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(mean_new[:, 3], 0.0)
    np.testing.assert_array_equal(new.policy.log_std.detach().numpy(), [-1.0, -2.0, -3.0, -0.5, -4.0])
    with torch.no_grad():
        full.policy.log_std.copy_(torch.arange(7.0))
    source = full.policy.state_dict()
    state = transfer_policy(source, "full", old.policy.state_dict(), "position-jaw", -0.5)
    np.testing.assert_array_equal(state["log_std"].numpy(), [0.0, 1.0, 2.0, 6.0])  # vx vy vz jaw
    for key in ("action_net.weight", "action_net.bias"):
        np.testing.assert_array_equal(state[key].numpy(), source[key].numpy()[[0, 1, 2, 6]])
    with pytest.raises(ValueError, match="other network architecture"):
        transfer_policy({}, "full", old.policy.state_dict(), "position-jaw", -0.5)
    with pytest.raises(ValueError, match="action set must be one of"):
        transfer_policy(source, "full", old.policy.state_dict(), "yaw-only", -0.5)
    for venv in (old.env, new.env, full.env):
        venv.close()


@pytest.mark.slow
def test_train_ppo_draws_the_modulus_per_episode_from_several_values(tmp_path):
    """``train_ppo.py --youngs-modulus 1e5 1e7``: run.json records both values, the run's policy
    (``PPOPolicy.from_run``) builds an env that draws one of them per episode (reset info), and a
    single value stays a number (the run.json of every earlier run)."""
    import sys

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from train_ppo import main

    from defgrasp_env.rl.ppo_policy import PPOPolicy

    common = ["--num-envs", "2", "--timesteps", "16", "--n-steps", "8", "--episode-seconds", "0.3",
              "--actions", "position-jaw", "--best-min-episodes", "0"]
    assert main(common + ["--youngs-modulus", "1e5", "1e7", "--out", str(tmp_path / "two")]) == 0
    assert json.loads((tmp_path / "two" / "run.json").read_text())["youngs_modulus"] == [1e5, 1e7]
    policy = PPOPolicy.from_run(tmp_path / "two")
    env = gym.make("DeformablePickup-v0", **policy.env_kwargs)
    drawn = {env.reset(seed=s)[1]["youngs_modulus"] for s in range(12)}
    assert drawn == {1e5, 1e7}  # 12 draws of two values: both (a miss has probability 2 / 4096)
    env.close()
    assert main(common + ["--youngs-modulus", "2e6", "--out", str(tmp_path / "one")]) == 0
    assert json.loads((tmp_path / "one" / "run.json").read_text())["youngs_modulus"] == 2e6


def test_fixed_world_objects_cycle_the_objects_over_the_worlds():
    import sys

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from train_ppo import make_vec_env, parse_object

    objects = parse_object("cuboid, sphere,rope")
    assert objects == ("cuboid", "sphere", "rope") and parse_object("random") == "random"
    venv = make_vec_env(4, 0, actions="position-yaw-jaw", fixed_world_objects=True, object=objects,
                        episode_seconds=0.3)
    venv.reset()
    inner = venv.venv.venv.venv.env.unwrapped  # VecNormalize > VecMonitor > ActionSubset > SB3VectorEnv
    assert inner.scene.object_names == ("cuboid", "sphere", "rope", "cuboid")
    assert venv.action_space.shape == (5,)
    venv.close()


def test_feature_beyond_pad_faces_against_placed_pads():
    """Pads placed by hand around a resting cube's feature point: between the faces -> 0; moved
    30 mm along a pad's length -> 30 mm less the pad's half length; turned 90 degrees about the
    pad's closing axis, the same offset reads along the width (the pad's own frame is used)."""
    import sys

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from eval_ppo import feature_beyond_pad_faces

    from defgrasp_env.gripper import Gripper
    from defgrasp_env.transforms import quat_multiply, quat_to_matrix

    env = gym.make("DeformablePickup-v0")
    env.reset(seed=0)
    scene = env.unwrapped.scene
    feature = scene.feature_points()[0][0]
    half = np.asarray(Gripper.pad_half_extents)
    quat = scene.state.pad_orientations.numpy().astype(np.float64)  # [2, 4] as the reset left them
    R = [quat_to_matrix(q) for q in quat]

    def place(offset_local, q=quat):
        pos = np.stack([feature - quat_to_matrix(q[p]) @ offset_local for p in range(2)])
        scene.state.pad_positions.assign(pos.astype(np.float32))
        scene.state.pad_orientations.assign(q.astype(np.float32))
        return feature_beyond_pad_faces(scene)[0]

    np.testing.assert_allclose(place(np.array([0.02, 0.0, 0.0])), [0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(place(np.array([0.02, 0.03, 0.0])), [0.03 - half[1], 0.0], atol=1e-6)
    np.testing.assert_allclose(place(np.array([0.02, 0.0, -0.025])), [0.0, 0.025 - half[2]], atol=1e-6)
    # the pads turned 90 degrees about their closing axis (x): a world offset that was along the
    # length now lies along the width
    turn = np.array([np.sin(np.pi / 4), 0.0, 0.0, np.cos(np.pi / 4)])
    turned = np.stack([quat_multiply(q, turn) for q in quat])
    world_offset = R[0] @ np.array([0.02, 0.03, 0.0])
    local = quat_to_matrix(turned[0]).T @ world_offset
    got = place(local, turned)
    np.testing.assert_allclose(got, [0.0, 0.03 - half[2]], atol=1e-6)
    env.close()


def test_resume_reads_a_setting_recorded_later_as_its_earlier_value(tmp_path):
    """A run saved before ``run.json`` recorded ``learning_rate`` (every run before 2026-11-26, all
    at 3e-4) resumes with 3e-4 and refuses another rate, naming it."""
    import json
    import sys

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from train_ppo import check_resume

    settings = {"num_envs": 2, "object": "cuboid", "device": "cpu"}
    (tmp_path / "run.json").write_text(json.dumps(settings))
    (tmp_path / "curve.csv").write_text("env_steps,wall_s\n32,1.5\n")
    assert check_resume(tmp_path, {**settings, "learning_rate": 3e-4}) == [{"env_steps": 32, "wall_s": 1.5}]
    with pytest.raises(ValueError, match=r"learning_rate: saved 0.0003, given 0.0001"):
        check_resume(tmp_path, {**settings, "learning_rate": 1e-4})


def test_ppo_policy_acts_as_the_training_wrappers_and_drives_gym_make(tmp_path):
    """``PPOPolicy`` on raw observations returns the very actions of SB3's own pipeline (the run's
    ``VecNormalize`` around the vector env, ``model.predict`` on its normalised observation, the
    action set's components placed by ``ActionSubset``), bit for bit, for one observation and for a
    batch; it drives ``gym.make`` to the end of an episode; bad folders and observations are refused."""
    import sys

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
    from train_ppo import load_normalisation, make_vec_env, save_run, train

    from defgrasp_env.rl.ppo_policy import PPOPolicy

    model, curve = train(num_envs=2, timesteps=32, n_steps=8, minibatches=2, episode_seconds=0.3,
                         actions="position-yaw-jaw", object="cuboid")
    save_run(model, curve, tmp_path, "smoke")
    policy = PPOPolicy.from_run(tmp_path)
    stats = {k: (rms.mean.copy(), rms.var.copy()) for k, rms in policy.normalizer.obs_rms.items()}
    assert policy.components == ("vx", "vy", "vz", "wy", "jaw") and policy.settings["actions"] == "position-yaw-jaw"

    # the reference: the wrappers the run was trained in, statistics frozen as eval_ppo.py does
    venv = load_normalisation(tmp_path, make_vec_env(2, 5, actions="position-yaw-jaw", gamma=0.8,
                                                     object="cuboid", episode_seconds=0.3))
    venv.training, venv.norm_reward = False, False
    subset = venv.venv.venv  # VecNormalize -> VecMonitor -> ActionSubset
    obs = venv.reset()
    moved = 0
    for _ in range(4):
        raw = venv.get_original_obs()
        chosen = np.concatenate([model.predict({k: v[i:i + 1] for k, v in obs.items()}, deterministic=True)[0]
                                 for i in range(2)])
        expected = subset.full_actions(chosen)
        got = policy({k: raw[k] for k in ("agent_pos", "environment_state")})
        assert got.dtype == np.float32 and got.shape == (2, 7)
        np.testing.assert_array_equal(got, expected)
        np.testing.assert_array_equal(policy({k: v[1] for k, v in raw.items()}), expected[1])  # one world
        assert np.all(got[:, [3, 5]] == 0.0)  # the turns the set leaves out
        moved += int(np.any(got != 0.0))
        obs, *_ = venv.step(chosen)
    assert moved == 4, "the test needs non-zero actions"

    # the run's env: its options as trained (E at its default, absent from run.json) and its 0.3 s
    # episodes as the time limit (6 steps at 20 Hz; gym.make would keep the registered 300)
    assert policy.env_kwargs == {"object": "cuboid", "youngs_modulus": 1e5, "episode_seconds": 0.3,
                                 "edge_contact": True, "max_episode_steps": 6}
    env = gym.make("DeformablePickup-v0", **policy.env_kwargs)
    obs, _ = env.reset(seed=3)
    policy.reset()
    for steps in range(1, 100):
        action = policy(obs)
        assert env.action_space.contains(action)
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    assert steps == 6 or terminated
    for k, rms in policy.normalizer.obs_rms.items():  # acting never updates the run's statistics
        assert np.array_equal(rms.mean, stats[k][0]) and np.array_equal(rms.var, stats[k][1])

    with pytest.raises(ValueError, match="environment_state"):
        policy({"agent_pos": obs["agent_pos"]})
    with pytest.raises(ValueError, match="shape"):
        policy({"agent_pos": obs["agent_pos"][:5], "environment_state": obs["environment_state"]})
    with pytest.raises(ValueError, match="finite"):
        policy({"agent_pos": np.full(10, np.nan, np.float32), "environment_state": obs["environment_state"]})
    with pytest.raises(TypeError, match="dict"):
        policy(obs["agent_pos"])
    (tmp_path / "vecnormalize.pkl").unlink()
    with pytest.raises(FileNotFoundError, match="vecnormalize.pkl"):
        PPOPolicy.from_run(tmp_path)
