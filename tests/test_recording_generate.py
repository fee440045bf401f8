"""defgrasp-generate: objects x E, resumable (finished files are skipped, seeds depend on names only),
summary table; console scripts registered."""

from __future__ import annotations

import hashlib
import importlib
import pathlib
import tomllib

import numpy as np

from defgrasp_env.recording import load_episode, validate_path
from defgrasp_env.recording.generate import main as generate_main
from defgrasp_env.recording.generate import plan_jobs

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_generate_resumes_and_summarises(tmp_path, capsys):
    def args(episodes):
        return [str(tmp_path), "--objects", "cuboid", "--moduli", "1e4,1e5", "--episodes", str(episodes),
                "--max-steps", "3", "--policy", "random", "--no-progress"]

    assert generate_main(args(1)) == 0
    names = sorted(p.name for p in tmp_path.glob("*.h5"))
    assert names == ["cuboid_E1e4_000.h5", "cuboid_E1e5_000.h5"]
    first = tmp_path / "cuboid_E1e4_000.h5"
    digest = hashlib.sha256(first.read_bytes()).hexdigest()
    (tmp_path / "cuboid_E1e5_000.h5").unlink()                   # as if interrupted before it
    (tmp_path / ".cuboid_E1e5_001.h5.tmp-999999999").write_bytes(b"partial")   # killed writer's leftover
    assert generate_main(args(2)) == 0
    out = capsys.readouterr().out
    assert hashlib.sha256(first.read_bytes()).hexdigest() == digest        # skipped, untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "cuboid_E1e4_000.h5", "cuboid_E1e4_001.h5", "cuboid_E1e5_000.h5", "cuboid_E1e5_001.h5"]
    assert validate_path(tmp_path).ok
    assert "cuboid" in out and "1e+04" in out and "all" in out and "success" in out
    jobs = {j.name: j for j in plan_jobs(["cuboid"], [1e4, 1e5], 2, 0)}
    for name, job in jobs.items():
        ep = load_episode(tmp_path / name)
        assert ep.replay["seed"] == job.seed and ep["object/youngs_modulus"] == job.youngs_modulus


def test_resuming_a_dataset_recorded_without_edge_contact_is_refused(tmp_path, capsys):
    """A folder whose episodes were recorded with node contact alone (the default before pad edge
    contact: their config lacks the key) is not resumed with today's default, which would mix two
    contact models in one dataset: exit 2 naming the file, nothing written, the file untouched."""
    import json

    import h5py

    args = [str(tmp_path), "--objects", "cuboid", "--moduli", "1e4", "--episodes", "2", "--max-steps", "2",
            "--policy", "random", "--no-progress"]
    assert generate_main(args[:6] + ["1"] + args[7:]) == 0
    first = tmp_path / "cuboid_E1e4_000.h5"
    with h5py.File(first, "r+") as f:  # as written before the key existed
        config = json.loads(f.attrs["config_json"])
        del config["edge_contact"]
        f.attrs["config_json"] = json.dumps(config, sort_keys=True)
    digest = hashlib.sha256(first.read_bytes()).hexdigest()
    capsys.readouterr()
    assert generate_main(args) == 2
    err = capsys.readouterr().err
    assert "cuboid_E1e4_000.h5 was recorded with edge_contact=False" in err and "new folder" in err
    assert sorted(p.name for p in tmp_path.glob("*.h5")) == ["cuboid_E1e4_000.h5"]
    assert hashlib.sha256(first.read_bytes()).hexdigest() == digest


def test_files_name_their_policy_and_resuming_with_another_is_refused(tmp_path, capsys):
    """Every file keeps the ``--policy`` that chose its actions (attribute ``policy``, the default
    expert's spec when none is given); resuming the folder with another policy exits 2 naming both
    and writes nothing, and a folder of files from before the attribute resumes as before."""
    import h5py

    from defgrasp_env.recording.generate import DEFAULT_POLICY

    args = [str(tmp_path), "--objects", "cuboid", "--moduli", "1e4", "--episodes", "1", "--max-steps", "2",
            "--no-progress"]
    assert generate_main(args) == 0
    first = tmp_path / "cuboid_E1e4_000.h5"
    assert load_episode(first).attrs["policy"] == DEFAULT_POLICY
    assert validate_path(first).ok
    capsys.readouterr()
    more = args[:6] + ["2"] + args[7:]
    assert generate_main(more + ["--policy", "random"]) == 2
    err = capsys.readouterr().err
    assert f"recorded by the policy {DEFAULT_POLICY!r}, this run's is 'random'" in err and "--policy" in err
    assert sorted(p.name for p in tmp_path.glob("*.h5")) == ["cuboid_E1e4_000.h5"]
    with h5py.File(first, "r+") as f:  # as written before the attribute existed
        del f.attrs["policy"]
    assert validate_path(first).ok
    assert generate_main(more + ["--policy", "random"]) == 0
    assert load_episode(tmp_path / "cuboid_E1e4_001.h5").attrs["policy"] == "random"
    # the attribute-less first file does not hide the second one's policy from a third run
    capsys.readouterr()
    assert generate_main(args[:6] + ["3"] + args[7:]) == 2
    assert "cuboid_E1e4_001.h5 was recorded by the policy 'random'" in capsys.readouterr().err
    with h5py.File(first, "r+") as f:  # a present policy must name one
        f.attrs["policy"] = ""
    assert "'policy': expected a non-empty str, got ''" in validate_path(first).text()


def test_bad_policy_is_reported(tmp_path, capsys):
    assert generate_main([str(tmp_path), "--objects", "cuboid", "--moduli", "1e5", "--policy", "nope:thing",
                          "--no-progress"]) == 2
    assert "policy 'nope:thing' is not importable" in capsys.readouterr().err
    assert list(tmp_path.glob("*.h5")) == []


def test_bad_objects_and_moduli_are_refused_before_anything_runs(tmp_path, capsys):
    """An unknown object, a missing mesh file or a non-positive modulus stops defgrasp-generate at
    its arguments (exit 2, the bad value and the valid names in the message), before any episode
    runs or the output folder is made."""
    import pytest

    out = tmp_path / "out"
    for bad, words in ((["--objects", "cuboid,banana"], ["'banana'", "cuboid", "torus"]),
                       (["--objects", str(tmp_path / "missing.stl")], ["missing.stl", "existing"]),
                       (["--objects", "cuboid", "--moduli", "1e5,-3"], ["youngs_modulus", "-3"]),
                       (["--objects", ","], ["--objects"])):
        with pytest.raises(SystemExit) as exc:
            generate_main([str(out), "--max-steps", "2", "--no-progress", *bad])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert all(w in err for w in words), (bad, err)
    assert not out.exists()


def test_console_scripts_are_registered():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    for name in ("defgrasp-dataset", "defgrasp-generate"):
        module, attr = scripts[name].split(":")
        assert callable(getattr(importlib.import_module(module), attr))


def test_generate_uses_the_scripted_expert_by_default(tmp_path, capsys):
    assert generate_main([str(tmp_path), "--objects", "cuboid", "--moduli", "1e5", "--max-steps", "4",
                          "--no-progress"]) == 0
    ep = load_episode(tmp_path / "cuboid_E1e5_000.h5")
    assert ep.num_steps == 4 and np.all(np.abs(ep["steps/action"]) <= 1.0)
    assert "cuboid" in capsys.readouterr().out


def _datasets(path: pathlib.Path) -> dict:
    import h5py

    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda k, v: out.__setitem__(k, v[()]) if isinstance(v, h5py.Dataset) else None)
    return out


def test_worlds_record_the_serial_runs_data(tmp_path):
    """``--worlds 3``: the 3 episodes of each (object, E) recorded together as the worlds of one
    vector env hold, dataset for dataset and bit for bit, what one env recording them one after the
    other holds (a world steps as a single env on its seed, and an episode does not depend on the
    episodes the env recorded before it: the rope's solver aggregates are cut in the object frame),
    with the scripted expert and with random actions (a random action space per world); a second
    run with --worlds 2 resumes a deleted file."""
    for policy in ("defgrasp_env.policies:ScriptedPickupExpert", "random"):
        args = ["--objects", "rope,cuboid", "--moduli", "1e4", "--episodes", "3", "--max-steps", "12",
                "--policy", policy, "--no-progress"]
        serial, together = tmp_path / f"serial-{policy[-6:]}", tmp_path / f"worlds-{policy[-6:]}"
        assert generate_main([str(serial), *args]) == 0
        assert generate_main([str(together), *args, "--worlds", "3"]) == 0
        names = sorted(p.name for p in serial.glob("*.h5"))
        assert names == sorted(p.name for p in together.glob("*.h5")) and len(names) == 6
        for name in names:
            a, b = _datasets(serial / name), _datasets(together / name)
            assert a.keys() == b.keys(), name
            for k in a:
                assert a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k]), f"{policy} {name}: {k} differs"
            assert load_episode(together / name).attrs["policy"] == policy
        assert validate_path(together).ok
    (together / names[1]).unlink()
    assert generate_main([str(together), *args, "--worlds", "2"]) == 0
    assert np.array_equal(_datasets(together / names[1])["steps/action"], _datasets(serial / names[1])["steps/action"])


def test_worlds_argument_errors(tmp_path, capsys):
    import pytest

    base = [str(tmp_path), "--objects", "cuboid", "--moduli", "1e4", "--max-steps", "2", "--no-progress"]
    for bad in (["--worlds", "0"], ["--worlds", "2", "--frames"]):
        with pytest.raises(SystemExit):
            generate_main([*base, *bad])
    err = capsys.readouterr().err
    assert "--worlds" in err and "--frames records one episode at a time" in err
    assert list(tmp_path.iterdir()) == []


def test_worlds_that_end_at_different_steps(tmp_path):
    """The expert lifts 3 cuboids in episodes of different lengths: recorded together (--worlds 3),
    each world's file ends where its episode ended and holds the serial run's data bit for bit
    (a world that ended is stepped on, unrecorded, and the policy sees its final observation). E =
    1e5: 84, 82 and 83 steps (at 1e6 all three took 83 since the continuous face depth of
    2026-12-07)."""
    args = ["--objects", "cuboid", "--moduli", "1e5", "--episodes", "3", "--max-steps", "140", "--no-progress"]
    assert generate_main([str(tmp_path / "serial"), *args]) == 0
    assert generate_main([str(tmp_path / "worlds"), *args, "--worlds", "3"]) == 0
    lengths = set()
    for path in sorted((tmp_path / "serial").glob("*.h5")):
        a, b = _datasets(path), _datasets(tmp_path / "worlds" / path.name)
        assert a.keys() == b.keys()
        for k in a:
            assert np.array_equal(a[k], b[k]), f"{path.name}: {k} differs"
        ep = load_episode(path)
        assert ep.attrs["is_success"], path.name
        lengths.add(ep.num_steps)
    assert len(lengths) > 1, f"the episodes all took {lengths} steps: the test needs different lengths"


def test_absolute_action_mode_records_the_expert_in_absolute_actions_and_refuses_mixing(tmp_path, capsys):
    """``--action-mode absolute``: the episodes' actions are ``ABSOLUTE_ACTION`` [8] (the scripted
    expert acts in the env's mode: target flange position within one period's travel of the wrist,
    a unit top-down quaternion, a gap in the stroke), the file replays to the same states, and
    resuming that folder in delta actions is refused (one action layout per dataset)."""
    from defgrasp_env.envs.config import PickupConfig
    from defgrasp_env.layout import ABSOLUTE_ACTION, AGENT_POS
    from defgrasp_env.recording import replay_episode

    args = [str(tmp_path), "--objects", "sphere", "--moduli", "1e6", "--episodes", "1", "--max-steps", "8",
            "--no-progress"]
    assert generate_main(args + ["--action-mode", "absolute"]) == 0
    path = tmp_path / "sphere_E1e6_000.h5"
    ep = load_episode(path)
    actions = ep["steps/action"]
    assert actions.shape == (8, ABSOLUTE_ACTION.size)
    wrist = AGENT_POS.get(ep["observations/agent_pos"][:-1], "wrist_position")
    step = np.linalg.norm(ABSOLUTE_ACTION.get(actions, "position") - wrist, axis=1)
    config = PickupConfig()
    # the expert's velocity is limited in norm: one period's move at most max_linear_speed x dt (+ the
    # float32 rounding of the recorded wrist position and action, ~1e-8 m)
    assert np.all(step <= config.max_linear_speed * config.dt + 1e-6) and step.max() > 0.01
    quat = ABSOLUTE_ACTION.get(actions, "orientation")
    np.testing.assert_allclose(np.linalg.norm(quat, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(quat[:, [0, 2]], 0.0, atol=1e-7)  # a turn about the vertical only
    gap = ABSOLUTE_ACTION.get(actions, "gap")
    assert np.all((gap >= 0) & (gap <= np.float32(0.085)))  # the stroke (float32 actions)
    assert validate_path(tmp_path).ok
    replay = replay_episode(path)
    assert replay.max_position_error == 0.0

    capsys.readouterr()
    assert generate_main(args[:6] + ["2"] + args[7:]) == 2  # delta actions into the absolute folder
    err = capsys.readouterr().err
    assert "action_mode='absolute'" in err and "--action-mode absolute" in err
    other = ["--objects", "cuboid"] + args[3:]  # another object's files: still one dataset
    assert generate_main([args[0]] + other) == 2 and "action_mode='absolute'" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.glob("*.h5")) == ["sphere_E1e6_000.h5"]


def test_topdown_action_mode_records_the_expert_in_topdown_actions(tmp_path):
    """``--action-mode topdown``: the episodes' actions are ``TOPDOWN_ACTION`` [5] with its column
    names (velocities and jaw in [-1, 1], the planned yaw in rad, held while the wrist turns), the
    file validates and replays bit for bit, and its LeRobot export names the action columns so."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from defgrasp_env.layout import AGENT_POS, TOPDOWN_ACTION
    from defgrasp_env.recording import replay_episode
    from defgrasp_env.recording.lerobot_export import to_lerobot

    out = tmp_path / "eps"
    args = [str(out), "--objects", "rope", "--moduli", "1e6", "--episodes", "1", "--max-steps", "12",
            "--no-progress", "--action-mode", "topdown"]
    assert generate_main(args) == 0
    path = out / "rope_E1e6_000.h5"
    ep = load_episode(path)
    actions = ep["steps/action"]
    assert actions.shape == (12, TOPDOWN_ACTION.size)
    low, high = TOPDOWN_ACTION.bounds()
    assert np.all(actions >= low.astype(np.float32)) and np.all(actions <= high.astype(np.float32))
    yaw = TOPDOWN_ACTION.get(actions, "yaw")[:, 0]
    assert np.ptp(yaw) == 0.0 and abs(yaw[0]) > 0.1  # the rope's planned turn, one target throughout
    quat = AGENT_POS.get(ep["observations/agent_pos"], "wrist_quat")
    wrist_yaw = 2 * np.arctan2(quat[:, 1], quat[:, 3])
    assert abs(wrist_yaw[-1] - yaw[0]) < abs(wrist_yaw[0] - yaw[0])  # turning toward it
    assert validate_path(out).ok
    assert replay_episode(path).max_position_error == 0.0
    dst = tmp_path / "lr"
    to_lerobot(out, dst, repo_id="test/topdown")
    ds = LeRobotDataset("test/topdown", root=dst)
    assert ds.features["action"]["names"] == list(TOPDOWN_ACTION.names) and ds[0]["action"].shape == (5,)
