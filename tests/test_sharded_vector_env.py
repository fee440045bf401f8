"""``ShardedVectorEnv`` / ``make_sharded_vec``: worlds split over several native vector envs stepped
in threads, against one native vector env of all the worlds (the independent truth: a world's
simulation does not depend on its batch, bit for bit on the CPU), and ``LAUNCH_LOCK``'s rules."""

from __future__ import annotations

import threading
import time

import gymnasium as gym
import numpy as np
import pytest

import defgrasp_env  # noqa: F401
from defgrasp_env import make_sharded_vec
from defgrasp_env.envs.sharded_vector_env import ShardedVectorEnv, shard_sizes
from defgrasp_env.layout import DELTA_ACTION
from defgrasp_env.sim.launch_lock import LaunchLock

ENV = dict(object="random", youngs_modulus=(1e4, 1e6), autoreset_mode="SameStep", max_episode_steps=15)


def _actions(rng: np.random.Generator, n: int) -> np.ndarray:
    """Random delta actions pushing down at full speed near the object, the jaw random: contact,
    force-limit retries and episodes that end (15 steps) and redraw their objects (rebuilds on the CPU)."""
    a = rng.uniform(-1.0, 1.0, (n, DELTA_ACTION.size)).astype(np.float32)
    a[:, [0, 2]] *= 0.1  # over the object
    a[:, 1] = -1.0       # down at full speed, into it
    return a


def _assert_info_equal(got: dict, want: dict, where: str) -> None:
    """The same entries in ``got`` as in ``want``: arrays equal where their ``_key`` mask is set (all rows
    where there is none); nested dicts (``final_obs``, ``final_info``) under their own mask."""
    assert set(got) == set(want), (where, sorted(set(want) ^ set(got)))
    for key, value in want.items():
        rows = np.asarray(want.get(f"_{key}", np.ones(len(got[key]), bool)), bool) if not key.startswith("_") else None
        if isinstance(value, dict):
            for inner, v in value.items():
                np.testing.assert_array_equal(np.asarray(got[key][inner])[rows], np.asarray(v)[rows],
                                              err_msg=f"{where} {key}/{inner}")
        elif key.startswith("_"):
            np.testing.assert_array_equal(got[key], value, err_msg=f"{where} {key}")
        elif value.dtype == object:
            assert [repr(x) for x in got[key][rows]] == [repr(x) for x in value[rows]], (where, key)
        else:
            np.testing.assert_array_equal(got[key][rows], value[rows], err_msg=f"{where} {key}")


def _assert_result_equal(got: tuple, want: tuple, where: str) -> None:
    """A reset's (obs, info) or a step's (obs, reward, terminated, truncated, info): all equal."""
    for key in want[0]:
        np.testing.assert_array_equal(got[0][key], want[0][key], err_msg=f"{where} obs {key}")
    for g, w in zip(got[1:-1], want[1:-1]):
        np.testing.assert_array_equal(g, w, err_msg=f"{where} reward / flags")
    _assert_info_equal(got[-1], want[-1], where)


def test_sharded_worlds_are_bit_identical_to_one_vector_env_on_the_cpu():
    """Seven worlds over three CPU shards (3, 2, 2) stepped in threads against one vector env of
    seven: objects and E drawn per episode, contact pushes, same-step autoresets every 15 steps
    (packed worlds rebuilt, their launches recorded and graphs captured again inside the threads:
    ``LAUNCH_LOCK`` at work), a partial ``reset_mask`` reset: every observation, reward, flag and
    reported info entry equal over 30 steps. (Checked by hand: with ``scoped_capture`` not taking
    the lock, the threads' captures collide: "Graph capture already in progress" warnings, then a
    step fails with "CPU graph replay failed: no operations recorded".)"""
    n, rng = 7, np.random.default_rng(3)
    whole = gym.make_vec("DeformablePickup-v0", num_envs=n, vectorization_mode="vector_entry_point", **ENV)
    sharded = make_sharded_vec(n, ["cpu", "cpu", "cpu"], **ENV)
    assert [s.num_envs for s in sharded.shards] == [3, 2, 2] and sharded.offsets.tolist() == [0, 3, 5, 7]
    want, got = whole.reset(seed=11), sharded.reset(seed=11)
    _assert_result_equal(got, want, "reset")
    objects, ended, wrist = set(want[1]["object"]), 0, 0.0
    for step in range(30):
        if step == 20:
            mask = np.array([True, False, False, True, False, True, False])
            want, got = whole.reset(options={"reset_mask": mask}), sharded.reset(options={"reset_mask": mask})
            _assert_result_equal(got, want, "partial reset")
        actions = _actions(rng, n)
        want, got = whole.step(actions), sharded.step(actions)
        _assert_result_equal(got, want, f"step {step}")
        ended += int(np.sum(want[2] | want[3]))
        wrist = max(wrist, float(np.max(want[-1]["wrist_force"])))
        if "object" in want[-1]:
            objects.update(want[-1]["object"][want[-1]["_object"]])
    assert ended >= n and len(objects) >= 3 and wrist > 10.0, (ended, objects, wrist)
    whole.close()
    sharded.close()


def test_sharded_env_checks_its_input():
    """Bad shard counts, options it sets itself, unequal shards and wrong action rows or masks are
    refused before anything runs, naming the value."""
    assert shard_sizes(7, 3) == [3, 2, 2] and shard_sizes(4, 4) == [1, 1, 1, 1]
    for shards in (0, 5, True, 1.5):
        with pytest.raises(ValueError, match=f"shards.*{shards!r}"):
            shard_sizes(4, shards)
    with pytest.raises(ValueError, match="shards.*0"):
        make_sharded_vec(4, [])
    with pytest.raises(ValueError, match="'device'"):
        make_sharded_vec(4, ["cpu"], device="cpu")
    with pytest.raises(ValueError, match="world_objects.*4"):
        make_sharded_vec(4, ["cpu", "cpu"], object="random", world_objects=["cuboid"] * 3)
    with pytest.raises(ValueError, match="at least one shard"):
        ShardedVectorEnv([])
    a = gym.make_vec("DeformablePickup-v0", num_envs=1, vectorization_mode="vector_entry_point", max_episode_steps=5)
    b = gym.make_vec("DeformablePickup-v0", num_envs=1, vectorization_mode="vector_entry_point", max_episode_steps=6)
    with pytest.raises(ValueError, match="shard 1's max_episode_steps \\(6\\) differs"):
        ShardedVectorEnv([a, b])
    c = gym.make_vec("DeformablePickup-v0", num_envs=1, vectorization_mode="vector_entry_point", max_episode_steps=5,
                     youngs_modulus=1e6)
    with pytest.raises(ValueError, match="shard 1's PickupConfig differs from shard 0's other than in its device: youngs_modulus 1000000.0 vs"):
        ShardedVectorEnv([a, c])
    env = make_sharded_vec(3, ["cpu", "cpu"], object="cuboid", world_objects=["cuboid"] * 3)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="3 rows.*\\(2, 7\\)"):
        env.step(np.zeros((2, 7), np.float32))
    with pytest.raises(ValueError, match="reset_mask.*shape \\(3,\\)"):
        env.reset(options={"reset_mask": np.ones(2, bool)})
    env.close()


def test_launch_lock_keeps_captures_apart_from_launches():
    """A capture waits until every shared hold is let go, a shared hold waits for a waiting or
    running capture (no starvation), threads holding shared may capture (each lets go meanwhile:
    no deadlock, and no thread's launches run during another's capture), nested shared holds count
    once, and a capture inside the same thread's capture is refused."""
    lock, log = LaunchLock(), []
    inside, release = threading.Event(), threading.Event()

    def launcher():
        with lock.shared():
            with lock.shared():  # nested
                inside.set()
                release.wait(5.0)
                log.append("launch done")

    def capturer():
        with lock.capturing():
            log.append("capture")

    t1 = threading.Thread(target=launcher)
    t1.start()
    assert inside.wait(5.0)
    t2 = threading.Thread(target=capturer)
    t2.start()
    _wait_until(lambda: lock._waiting_writers == 1)
    assert log == []  # the capture waits for the launcher's step
    late = threading.Thread(target=lambda: (lock.shared().__enter__(), log.append("late launch")))
    late.start()
    time.sleep(0.2)  # time to get in, were it not held back
    assert log == []  # a new launcher waits behind the waiting capture
    release.set()
    for t in (t1, t2, late):
        t.join(5.0)
    assert log == ["launch done", "capture", "late launch"], log

    lock2, spans, active = LaunchLock(), [], [0]
    counter = threading.Lock()

    def step_that_captures(name):
        with lock2.shared():
            for _ in range(3):
                with counter:
                    active[0] += 1
                time.sleep(0.01)  # launching
                with counter:
                    active[0] -= 1
                with lock2.capturing():
                    with counter:
                        spans.append((name, active[0]))  # launches running during this capture
                    time.sleep(0.01)

    threads = [threading.Thread(target=step_that_captures, args=(k,)) for k in "abc"]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10.0)
    assert not any(t.is_alive() for t in threads) and len(spans) == 9, spans
    assert all(running == 0 for _, running in spans), spans  # no launch ran beside a capture
    with lock2.capturing(), pytest.raises(RuntimeError, match="already in progress"):
        with lock2.capturing():
            pass


def _wait_until(condition, timeout: float = 5.0) -> None:
    end = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.01)


def test_sb3_ppo_trains_on_a_sharded_vector_env():
    """Stable-Baselines3's PPO through ``SB3VectorEnv`` over two CPU shards (with staggered first
    episodes, which reset single worlds through ``reset_mask``): two rollouts and their updates."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from defgrasp_env.rl.sb3_vec_env import SB3VectorEnv

    env = make_sharded_vec(4, ["cpu", "cpu"], object=("cuboid", "sphere"), world_objects=["cuboid", "sphere"] * 2,
                           autoreset_mode="SameStep", max_episode_steps=6)
    venv = SB3VectorEnv(env, stagger_first_episodes=True)
    venv.seed(0)
    model = PPO("MultiInputPolicy", VecNormalize(venv), n_steps=4, batch_size=8, n_epochs=1, seed=0, device="cpu")
    model.learn(32)
    assert model.num_timesteps == 32
    venv.close()
