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


def test_bad_policy_is_reported(tmp_path, capsys):
    assert generate_main([str(tmp_path), "--objects", "cuboid", "--moduli", "1e5", "--policy", "nope:thing",
                          "--no-progress"]) == 2
    assert "policy 'nope:thing' is not importable" in capsys.readouterr().err
    assert list(tmp_path.glob("*.h5")) == []


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
