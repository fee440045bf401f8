"""``EpisodeWriter``: the one writer of episode files, with explicit save and discard; a failed write
loses nothing and publishes nothing. ``HDF5Recorder.save`` / ``discard`` expose it to the
collection app."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import defgrasp_env  # noqa: F401
from defgrasp_env.recording import HDF5Recorder, load_episode, validate_path
from defgrasp_env.recording import writer as writer_module
from defgrasp_env.recording.capture import object_record, step_record
from defgrasp_env.recording.writer import EpisodeWriter

ENV_ID = "DeformablePickup-v0"


@pytest.fixture(scope="module")
def episode():
    """(config, object record, replay dict, object name, first obs, [step rows]) of 3 real steps."""
    env = gym.make(ENV_ID, max_episode_steps=50)
    obs0, info = env.reset(seed=5)
    scene = env.unwrapped.scene
    steps = []
    for k in range(3):
        action = np.zeros(7, np.float32)
        action[1] = -1.0
        obs, reward, terminated, truncated, step_info = env.step(action)
        steps.append((step_record(scene), action, obs, reward, terminated, truncated, step_info))
    spec = info["replay_spec"]
    out = (env.unwrapped.config, object_record(scene), {**spec.to_json_dict(), "max_episode_steps": 50},
           spec.object_name, obs0, steps)
    env.close()
    return out


def _fill(writer, w, episode, steps=3):
    config, obj, replay, name, obs0, rows = episode
    writer.start(w, obj, obs0, replay, name)
    for row in rows[:steps]:
        writer.append(w, *row)


def test_save_writes_a_valid_file_and_discard_writes_none(tmp_path, episode):
    writer = EpisodeWriter(tmp_path, episode[0], env_id=ENV_ID)
    _fill(writer, 0, episode)
    _fill(writer, 1, episode, steps=2)
    assert (writer.steps(0), writer.steps(1), writer.steps(2)) == (3, 2, 0)
    assert writer.discard(0) == 3 and not writer.is_open(0)
    path = writer.save(1, "close")
    assert writer.paths == [path] and list(tmp_path.iterdir()) == [path]
    assert validate_path(path).ok
    ep = load_episode(path)
    assert ep.attrs["world"] == 1 and ep.attrs["end_reason"] == "close" and ep.num_steps == 2
    assert ep.replay["seed"] == 5 and ep.attrs["object_name"] == "cuboid"
    np.testing.assert_array_equal(ep["steps/jaw_length"], [r[0][8] for r in episode[5][:2]])
    # nothing open: save is a no-op, discard drops nothing
    assert writer.save(1, "close") is None and writer.discard(1) == 0
    writer.start(2, episode[1], episode[4], episode[2], episode[3])  # zero steps ...
    assert writer.save(2, "reset") is None and writer.paths == [path]  # ... no file


def test_misuse_is_refused(tmp_path, episode):
    writer = EpisodeWriter(tmp_path, episode[0], env_id=ENV_ID)
    with pytest.raises(RuntimeError, match="world 0 has no open episode"):
        writer.append(0, *episode[5][0])
    _fill(writer, 0, episode, steps=1)
    with pytest.raises(RuntimeError, match=r"open episode of 1 steps; save\(\) or discard\(\) it"):
        _fill(writer, 0, episode)
    with pytest.raises(ValueError, match="reason must be one of"):
        writer.save(0, "because")
    with pytest.raises(TypeError, match="replay data must be JSON-serialisable"):
        writer.start(3, episode[1], episode[4], {"seed": object()}, "cuboid")
    with pytest.raises(ValueError, match="name_template"):
        EpisodeWriter(tmp_path, episode[0], env_id=ENV_ID, name_template="x.h5")


def test_a_failed_write_loses_nothing_and_publishes_nothing(tmp_path, episode, monkeypatch):
    writer = EpisodeWriter(tmp_path, episode[0], env_id=ENV_ID)
    _fill(writer, 0, episode)
    real = writer_module.write_episode

    def disk_full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(writer_module, "write_episode", disk_full)
    with pytest.raises(OSError, match="No space left"):
        writer.save(0, "terminated")
    assert writer.steps(0) == 3 and writer.paths == [] and list(tmp_path.iterdir()) == []
    monkeypatch.setattr(writer_module, "write_episode", real)
    path = writer.save(0, "terminated")  # the same episode, written once the disk has room
    assert load_episode(path).num_steps == 3 and writer.episode_index == 1


def test_recorder_save_and_discard(tmp_path):
    env = HDF5Recorder(gym.make(ENV_ID, max_episode_steps=50), tmp_path, save_unfinished=True)
    env.reset(seed=1)
    for _ in range(3):
        env.step(np.zeros(7, np.float32))
    path = env.save("reset")
    assert load_episode(path).attrs["end_reason"] == "reset" and load_episode(path).num_steps == 3
    with pytest.raises(RuntimeError, match="has ended"):
        env.step(np.zeros(7, np.float32))
    env.reset(seed=2)
    env.step(np.zeros(7, np.float32))
    env.step(np.zeros(7, np.float32))
    assert env.discard() == 2
    env.reset(seed=3)  # save_unfinished=True, but the discarded episode is gone: no file
    env.close()  # ... and an episode with no step writes none
    assert env.paths == [path]
