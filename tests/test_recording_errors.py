"""Bad input: truncated, foreign, missing, wrong-schema files and unwritable paths give clear errors
naming the file and the problem; nothing already written is touched."""

from __future__ import annotations

import hashlib
import os
import shutil

import h5py
import numpy as np
import pytest
from test_recording_helpers import make_recorder, record_episodes

from defgrasp_env.recording import EpisodeFileError, load_episode, validate_episode, validate_path
from defgrasp_env.recording.atomic import write_episode
from defgrasp_env.recording.cli import main as dataset_cli


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    return record_episodes(tmp_path_factory.mktemp("good"), seeds=(0,), steps=4)[0]


def _copy(good, tmp_path, name="ep.h5"):
    p = tmp_path / name
    shutil.copy(good, p)
    return p


def test_missing_truncated_and_foreign_files(good, tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.h5"):
        load_episode(tmp_path / "nope.h5")
    truncated = tmp_path / "truncated.h5"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(EpisodeFileError, match="truncated.h5"):
        load_episode(truncated)
    foreign = tmp_path / "foreign.h5"
    foreign.write_text("this is not HDF5")
    with pytest.raises(EpisodeFileError, match="foreign.h5: not an HDF5 file"):
        load_episode(foreign)
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = np.zeros(3)
    with pytest.raises(EpisodeFileError, match="other.h5: not a defgrasp episode"):
        load_episode(other)
    report = validate_path(tmp_path)
    assert not report.ok and len(report.files) == 3
    text = report.text()
    for name in ("truncated.h5", "foreign.h5", "other.h5"):
        assert f"INVALID  {tmp_path / name}" in text


@pytest.mark.parametrize("change, message", [
    (lambda f: f.__delitem__("steps/von_mises"), "steps/von_mises: required dataset is missing"),
    (lambda f: f["steps/node_positions"].__setitem__((1, 3, 0), np.nan), "steps/node_positions: 1 NaN/inf"),
    (lambda f: f["steps/jaw_length"].attrs.__setitem__("units", "mm"), "steps/jaw_length: units attribute 'mm'"),
    (lambda f: (f.__delitem__("steps/reward"), f.create_dataset("steps/reward", data=np.zeros(4, np.float32))),
     "steps/reward: dtype float32 != float64"),
    (lambda f: (f.__delitem__("steps/time"), f.create_dataset("steps/time", data=np.zeros(3))),
     "steps/time: dimension T is 3 here but 4 in the other datasets"),
    (lambda f: f["object/tetrahedra"].__setitem__((0, 0), 10_000), "object/tetrahedra: node indices span"),
    (lambda f: f.attrs.__setitem__("num_steps", 9), "num_steps = 9 but datasets have T = 4"),
    (lambda f: f.attrs.__delitem__("config_json"), "root attribute 'config_json' is missing"),
    (lambda f: f["steps/wrist_orientation"].__setitem__((0, 0), 2.0), "unit norm"),
])
def test_validate_names_the_problem(good, tmp_path, change, message, capsys):
    p = _copy(good, tmp_path)
    with h5py.File(p, "r+") as f:
        change(f)
    report = validate_episode(p)
    assert not report.ok and any(message in e for e in report.errors), report.errors
    assert dataset_cli(["validate", str(p)]) == 1
    assert message in capsys.readouterr().out


def test_wrong_schema_version_and_missing_dataset_on_load(good, tmp_path):
    p = _copy(good, tmp_path)
    with h5py.File(p, "r+") as f:
        f.attrs["schema_version"] = 99
    with pytest.raises(EpisodeFileError, match="ep.h5: unsupported schema_version 99"):
        load_episode(p)
    q = _copy(good, tmp_path, "q.h5")
    with h5py.File(q, "r+") as f:
        del f["object/density"]
    with pytest.raises(EpisodeFileError, match=r"q.h5: missing dataset\(s\) \['object/density'\]"):
        load_episode(q)


def test_unwritable_paths_are_refused_clearly(good, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(NotADirectoryError, match="file: recording directory is not a directory"):
        make_recorder(blocker)
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        try:
            with pytest.raises(PermissionError, match="ro: recording directory is not writable"):
                make_recorder(ro)
        finally:
            ro.chmod(0o700)


def test_existing_files_are_never_overwritten(good, tmp_path):
    p = _copy(good, tmp_path)
    digest = hashlib.sha256(p.read_bytes()).hexdigest()
    ep = load_episode(p)
    with pytest.raises(FileExistsError, match="ep.h5: episode file exists already"):
        write_episode(p, ep.data, dict(ep.attrs), ep.names)
    assert hashlib.sha256(p.read_bytes()).hexdigest() == digest
    assert sorted(x.name for x in tmp_path.iterdir()) == ["ep.h5"]   # no temp file left behind


def test_failed_write_leaves_no_file(tmp_path):
    with pytest.raises(TypeError):
        write_episode(tmp_path / "bad.h5", {"steps/x": np.array([object()])}, {"format": "defgrasp.episode"})
    assert list(tmp_path.iterdir()) == []


def test_cli_errors_exit_2_with_the_file_name(tmp_path, capsys):
    assert dataset_cli(["plot", str(tmp_path / "missing.h5")]) == 2
    assert "missing.h5: episode file not found" in capsys.readouterr().err
    assert dataset_cli(["to-lerobot", str(tmp_path / "none"), str(tmp_path / "dst")]) == 2
    assert "none: no such episode file or directory" in capsys.readouterr().err
    assert not (tmp_path / "dst").exists()
