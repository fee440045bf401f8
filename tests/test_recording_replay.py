"""Replay: re-simulating from the recorded config, seed/RNG state and actions is bit-exact on CPU."""

from __future__ import annotations

import json
import shutil

import h5py
import numpy as np
from test_recording_helpers import make_recorder, run_episode

from defgrasp_env.recording import load_episode, replay_episode
from defgrasp_env.recording.cli import main as dataset_cli


def test_replay_is_bit_exact_for_every_episode_of_a_session(tmp_path):
    """Episode 1 is seeded, episode 2 continues the env's RNG (seed=None) with another E drawn, and
    both run in the scene built by episode 1: replays must still match bit for bit."""
    env = make_recorder(tmp_path, steps=8, youngs_modulus=(1e4, 1e5, 1e6))
    run_episode(env, seed=11, steps=8, action_seed=0)
    run_episode(env, seed=None, steps=8, action_seed=1)
    env.close()
    first, second = (load_episode(p) for p in env.paths)
    assert second.replay["seed"] is None and second.replay["rng_state"] is not None
    assert second.replay["scene_origin"]["seed"] == 11
    assert not np.array_equal(first["object/initial_quaternion"], second["object/initial_quaternion"])
    for ep in (first, second):
        result = replay_episode(ep.path)
        assert result.bit_exact, result.text()
        assert result.num_steps == result.replayed_steps == 8 and result.max_position_error == 0.0


def test_replay_reports_a_tampered_episode(tmp_path, capsys):
    env = make_recorder(tmp_path / "a", steps=6)
    run_episode(env, seed=3, steps=6)
    env.close()
    tampered = tmp_path / "tampered.h5"
    shutil.copy(env.paths[0], tampered)
    with h5py.File(tampered, "r+") as f:
        f["steps/node_positions"][2, 5, 1] += 1e-6
    result = replay_episode(tampered)
    assert not result.bit_exact and result.first_mismatch_step == 2 and 0 < result.max_position_error < 2e-6
    assert result.flags_match
    other = tmp_path / "other_action.h5"
    shutil.copy(env.paths[0], other)
    with h5py.File(other, "r+") as f:
        f["steps/action"][2, 1] += 0.5       # the gripper moves differently: rewards differ
    result = replay_episode(other)
    assert not result.bit_exact and not result.flags_match
    assert dataset_cli(["replay", str(env.paths[0])]) == 0
    assert "bit-exact" in capsys.readouterr().out
    assert dataset_cli(["replay", str(tampered)]) == 1
    out = capsys.readouterr().out
    assert "DIFFER from step 2" in out and "NOT exact" in out and "bit-exact" not in out


def test_a_partial_replay_is_never_bit_exact(tmp_path, capsys):
    """The recording says the episode may run 6 steps; a replay env limited to 3 ends early. Every
    replayed step matches, yet the replay is partial: not bit-exact, and the text says so."""
    env = make_recorder(tmp_path / "a", steps=6)
    run_episode(env, seed=4, steps=6)
    env.close()
    short = tmp_path / "short_limit.h5"
    shutil.copy(env.paths[0], short)
    with h5py.File(short, "r+") as f:
        replay = json.loads(f.attrs["replay_json"])
        replay["max_episode_steps"] = 3
        f.attrs["replay_json"] = json.dumps(replay)
    result = replay_episode(short)
    assert result.replayed_steps == 3 and result.num_steps == 6 and not result.complete
    assert result.first_mismatch_step is None and not result.bit_exact
    assert dataset_cli(["replay", str(short)]) == 1
    out = capsys.readouterr().out
    assert "PARTIAL replay: 3 of 6 steps replayed" in out and "bit-exact" not in out
