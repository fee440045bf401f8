"""defgrasp-generate on Ray (a local two-CPU cluster, real workers): the episode files equal a serial
run's, a worker killed mid-episode is retried by Ray, and an interrupted run resumes to the full set."""

from __future__ import annotations

import hashlib
import json
import os
import pathlib
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from defgrasp_env.recording import list_episodes, load_episode, replay_episode, validate_path
from defgrasp_env.recording.generate import main as generate_main
from defgrasp_env.recording.generate import plan_jobs

ray = pytest.importorskip("ray")

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _args(max_steps: int) -> list[str]:
    """2 moduli x 3 episodes: more jobs than workers, two env configurations per worker."""
    return ["--objects", "cuboid", "--moduli", "1e4,1e5", "--episodes", "3", "--max-steps", str(max_steps),
            "--no-progress"]


ARGS = _args(6)
NAMES = sorted(j.name for j in plan_jobs(["cuboid"], [1e4, 1e5], 3, 0))
# Recorder bookkeeping that depends on which episodes the same env recorded before (as in a resumed
# serial run): the episode's index in its recorder, its world in a vector env and (in replay_json) the
# reset that built the scene.
BOOKKEEPING = {"created_utc", "episode_index", "world"}


def _contents(path: pathlib.Path, ignore=()) -> tuple[dict, dict]:
    data, attrs = {}, {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda k, v: data.__setitem__(k, v[()]) if isinstance(v, h5py.Dataset) else None)
        for k, v in f.attrs.items():
            if k == "replay_json":
                v = {key: val for key, val in json.loads(v).items() if key != "scene_origin"}
            if k not in BOOKKEEPING and k not in ignore:
                attrs[k] = v
    return data, attrs


def assert_same_episodes(a: pathlib.Path, b: pathlib.Path, ignore=()) -> None:
    """Every dataset bit-identical (values and dtype), every attribute equal but the bookkeeping and
    the attributes ``ignore``."""
    assert sorted(p.name for p in list_episodes(a)) == sorted(p.name for p in list_episodes(b)) == NAMES
    for name in NAMES:
        (da, aa), (db, ab) = _contents(a / name, ignore), _contents(b / name, ignore)
        assert da.keys() == db.keys(), name
        for k in da:
            assert da[k].dtype == db[k].dtype and np.array_equal(da[k], db[k]), f"{name}: {k} differs"
        assert aa == ab, name


@pytest.fixture(scope="module")
def serial(tmp_path_factory) -> pathlib.Path:
    out = tmp_path_factory.mktemp("serial")
    assert generate_main([str(out), *ARGS, "--policy", "random"]) == 0
    return out


@pytest.fixture(scope="module")
def local_ray(tmp_path_factory):
    """A local Ray with 2 CPUs whose workers import this checkout and the tests' crash policy."""
    crash_dir = tmp_path_factory.mktemp("crash")
    saved = {k: os.environ.get(k) for k in ("PYTHONPATH", "DEFGRASP_CRASH_DIR")}
    os.environ["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(ROOT / "tests")])
    os.environ["DEFGRASP_CRASH_DIR"] = str(crash_dir)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield crash_dir
    ray.shutdown()
    for k, v in saved.items():
        os.environ.pop(k) if v is None else os.environ.__setitem__(k, v)


def _digests(d: pathlib.Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in list_episodes(d)}


def test_two_workers_match_serial_and_resume(serial, local_ray, tmp_path):
    assert generate_main([str(tmp_path), *ARGS, "--policy", "random", "--ray", "--workers", "2"]) == 0
    assert_same_episodes(serial, tmp_path)
    assert validate_path(tmp_path).ok
    result = replay_episode(tmp_path / NAMES[-1])  # a file recorded by a Ray worker replays bit-exactly
    assert result.bit_exact and result.num_steps == 6, result
    before = _digests(tmp_path)
    (tmp_path / NAMES[2]).unlink()                                         # as if never finished
    (tmp_path / f".{NAMES[4]}.tmp-999999999").write_bytes(b"partial")      # a killed writer's leftover
    assert generate_main([str(tmp_path), *ARGS, "--policy", "random", "--ray", "--workers", "2"]) == 0
    after = _digests(tmp_path)
    assert {k: v for k, v in after.items() if k != NAMES[2]} == {k: v for k, v in before.items() if k != NAMES[2]}
    assert sorted(p.name for p in tmp_path.iterdir()) == NAMES                # temp removed, nothing else
    assert_same_episodes(serial, tmp_path)


def test_ray_retries_a_worker_killed_mid_episode(serial, local_ray, tmp_path):
    assert generate_main([str(tmp_path), *ARGS, "--policy", "crash_policy:CrashOncePolicy", "--ray",
                          "--workers", "2"]) == 0
    assert (local_ray / "crashed").exists(), "no worker was killed: the test did not test a retry"
    # the retried episode equals the serial one (recorded by "random", which the crash policy acts as)
    assert_same_episodes(serial, tmp_path, ignore=("policy",))
    assert {load_episode(p).attrs["policy"] for p in list_episodes(tmp_path)} == {"crash_policy:CrashOncePolicy"}
    assert validate_path(tmp_path).ok


def test_worlds_per_task_match_serial(serial, local_ray, tmp_path):
    """--worlds 3 on Ray: one task per (object, E) records its 3 episodes as the worlds of one
    vector env; the files equal the serial run's (random actions: one action space per world)."""
    assert generate_main([str(tmp_path), *ARGS, "--policy", "random", "--ray", "--workers", "2", "--worlds", "3"]) == 0
    assert_same_episodes(serial, tmp_path)
    assert validate_path(tmp_path).ok
    result = replay_episode(tmp_path / NAMES[-1])  # world 2 of a task's vector env replays bit-exactly
    assert result.bit_exact and result.num_steps == 6, result


def test_a_failing_task_is_reported_cleanly(local_ray, tmp_path, capsys):
    assert generate_main([str(tmp_path), *ARGS, "--policy", "nope:thing", "--ray", "--workers", "2"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("defgrasp-generate: error: policy 'nope:thing' is not importable"), err
    assert list(tmp_path.iterdir()) == []


def test_bad_arguments_are_reported_before_ray_starts(tmp_path, capsys):
    with pytest.raises(SystemExit):
        generate_main([str(tmp_path), *ARGS, "--workers", "2"])            # --workers without --ray
    with pytest.raises(SystemExit):
        generate_main([str(tmp_path), *ARGS, "--ray", "--workers", "0"])
    assert generate_main([str(tmp_path), *ARGS, "--ray", "--device", "cuda:1"]) == 2
    assert "--device must be 'cpu' or 'cuda'" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def _ctrl_c_as_in_a_terminal() -> None:
    """In the child before exec: SIGINT delivered and not ignored, whatever the test process's state
    (in a full-suite run it is inherited ignored or blocked: the child then never saw Ctrl-C)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


@pytest.mark.slow
def test_interrupted_ray_run_resumes_to_the_full_set(tmp_path):
    """The CLI in its own process (it starts its own local Ray), interrupted by Ctrl-C after the
    first file: the finished files are valid and kept, and the same command completes the set.
    Episodes of 40 steps, so that the run is far from done when the first file appears."""
    cmd = [sys.executable, "-m", "defgrasp_env.recording.generate", str(tmp_path), *_args(40), "--policy", "random",
           "--ray", "--workers", "2"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_ctrl_c_as_in_a_terminal)
    try:
        deadline = time.monotonic() + 300
        while not list_episodes(tmp_path) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None, f"run ended before it could be interrupted: {proc.communicate()}"
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, (signal.getsignal(signal.SIGINT), signal.pthread_sigmask(signal.SIG_BLOCK, []),
                                    out, err)
    finished = list_episodes(tmp_path)
    assert 1 <= len(finished) < len(NAMES), finished
    assert validate_path(tmp_path).ok
    kept = _digests(tmp_path)
    assert subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, timeout=600).returncode == 0
    assert {k: v for k, v in _digests(tmp_path).items() if k in kept} == kept
    assert sorted(p.name for p in tmp_path.iterdir()) == NAMES
    assert validate_path(tmp_path).ok
    jobs = {j.name: j for j in plan_jobs(["cuboid"], [1e4, 1e5], 3, 0)}
    for name in NAMES:
        ep = load_episode(tmp_path / name)
        assert ep.replay["seed"] == jobs[name].seed and ep.num_steps == 40, name


def test_ray_tasks_record_in_the_absolute_action_mode(local_ray, tmp_path):
    """``--action-mode`` reaches the Ray tasks: the expert's episodes are recorded in absolute actions
    [8], and each equals the serial run's in that mode."""
    args = ["--objects", "sphere", "--moduli", "1e6", "--episodes", "2", "--max-steps", "3", "--no-progress",
            "--action-mode", "absolute"]
    assert generate_main([str(tmp_path / "ray"), *args, "--ray", "--workers", "2"]) == 0
    assert generate_main([str(tmp_path / "serial"), *args]) == 0
    for name in ("sphere_E1e6_000.h5", "sphere_E1e6_001.h5"):
        (a, _), (b, _) = _contents(tmp_path / "ray" / name), _contents(tmp_path / "serial" / name)
        assert a["steps/action"].shape == (3, 8) and np.array_equal(a["steps/action"], b["steps/action"])
        assert np.array_equal(a["steps/node_positions"], b["steps/node_positions"])
