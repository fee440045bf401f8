"""Bad input: truncated, foreign, missing, wrong-schema files and unwritable paths give clear errors
naming the file and the problem; nothing already written is touched."""

from __future__ import annotations

import hashlib
import json
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
        assert f"INVALID  {tmp_path / name}: " in text


def _replace(f, key, data):
    attrs = dict(f[key].attrs)
    del f[key]
    f.create_dataset(key, data=data)
    f[key].attrs.update(attrs)


@pytest.mark.parametrize("change, message", [
    (lambda f: f.__delitem__("steps/von_mises"),
     "steps/von_mises: required dataset is missing (expected float32 [T, N2])"),
    (lambda f: f["steps/node_positions"].__setitem__((1, 3, 0), np.nan),
     "steps/node_positions: 1 NaN/inf value(s), first at index (1, 3, 0); expected finite"),
    (lambda f: f["steps/jaw_length"].attrs.__setitem__("units", "mm"),
     "steps/jaw_length: units attribute 'mm', expected 'm'"),
    (lambda f: _replace(f, "steps/reward", np.zeros(4, np.float32)), "steps/reward: dtype float32, expected float64"),
    (lambda f: _replace(f, "steps/time", np.arange(1, 4) * 0.05),
     "steps/time: shape (3,), expected [T] = (4,) (T = 4)"),
    (lambda f: _replace(f, "steps/node_positions", f["steps/node_positions"][..., :2]),
     "steps/node_positions: shape (4, {n3}, 2), expected [T, N3, 3] = (4, {n3}, 3) (T = 4, N3 = {n3})"),
    (lambda f: _replace(f, "steps/action", f["steps/action"][:3]),
     "steps/action: shape (3, 7), expected [T, A] = (4, 7) (T = 4, A = 7)"),
    (lambda f: f["object/tetrahedra"].__setitem__((0, 0), 10_000), "object/tetrahedra: node indices span"),
    (lambda f: f.attrs.__setitem__("num_steps", 9), "root attribute 'num_steps' = 9, but the datasets have T = 4"),
    (lambda f: f.attrs.__delitem__("config_json"), "root attribute 'config_json' is missing"),
    (lambda f: f["steps/wrist_orientation"].__setitem__((0, 0), 2.0), "steps/wrist_orientation: quaternions off unit norm"),
])
def test_validate_names_the_problem(good, tmp_path, change, message, capsys):
    p = _copy(good, tmp_path)
    with h5py.File(p, "r+") as f:
        n3 = f["object/rest_nodes"].shape[0]
        change(f)
    message = message.format(n3=n3)
    report = validate_episode(p)
    assert not report.ok and any(message in e for e in report.errors), report.errors
    assert dataset_cli(["validate", str(p)]) == 1
    assert f"INVALID  {p}: {message}" in capsys.readouterr().out
    with pytest.raises(EpisodeFileError) as exc:
        load_episode(p)
    assert str(exc.value).startswith(f"{p}: ") and "\n" not in str(exc.value)


MALFORMED = {  # name -> (change, the dataset the one-line error must name)
    "node_positions_2d": (lambda f: _replace(f, "steps/node_positions", f["steps/node_positions"][..., :2]),
                          "steps/node_positions"),
    "short_action": (lambda f: _replace(f, "steps/action", f["steps/action"][:-1]), "steps/action"),
    "missing_dataset": (lambda f: f.__delitem__("steps/jaw_length"), "steps/jaw_length"),
    "nan": (lambda f: f["steps/node_positions"].__setitem__((2, 0, 1), np.nan), "steps/node_positions"),
    "wrong_dtype": (lambda f: _replace(f, "steps/wrist_position", f["steps/wrist_position"][()].astype(np.float32)),
                    "steps/wrist_position"),
}


def _fingerprint(p):
    return hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_mtime_ns, p.stat().st_size


@pytest.fixture(scope="module")
def malformed(good, tmp_path_factory):
    d = tmp_path_factory.mktemp("malformed")
    out = {}
    for name, (change, dataset) in MALFORMED.items():
        p = _copy(good, d, f"{name}.h5")
        with h5py.File(p, "r+") as f:
            change(f)
        os.utime(p, ns=(1_000_000_000_000_000_000, 1_000_000_000_000_000_000))   # a mtime no tool would write
        out[name] = (p, dataset)
    return out


@pytest.mark.parametrize("tool", ["validate", "plot", "replay", "to-lerobot"])
@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_every_tool_rejects_a_malformed_file_in_one_line(malformed, tmp_path, capsys, tool, case):
    """Each dataset tool reads through the validating reader: one line naming the file, the dataset
    and what was expected, a non-zero exit, no output written, and the input byte-for-byte untouched."""
    p, dataset = malformed[case]
    before = _fingerprint(p)
    argv = {"validate": [str(p)], "plot": [str(p), "-o", str(tmp_path / "out.png")], "replay": [str(p)],
            "to-lerobot": [str(p), str(tmp_path / "lerobot")]}[tool]
    code = dataset_cli([tool, *argv])
    captured = capsys.readouterr()
    assert code != 0
    if tool == "validate":
        lines = [ln for ln in captured.out.splitlines() if ln.startswith("INVALID")]
    else:
        lines = captured.err.splitlines()
        assert captured.out == "" or "bit-exact" not in captured.out
    assert len(lines) == 1, captured
    assert str(p) in lines[0] and f"{dataset}: " in lines[0] and "expected" in lines[0], lines[0]
    assert "Traceback" not in captured.err
    assert _fingerprint(p) == before
    assert not (tmp_path / "out.png").exists() and not (tmp_path / "lerobot").exists()


def test_validate_takes_several_paths(good, malformed, tmp_path, capsys):
    folder = tmp_path / "folder"
    folder.mkdir()
    _copy(good, folder, "a.h5")
    bad = malformed["nan"][0]
    assert dataset_cli(["validate", str(good), str(folder), str(bad), str(tmp_path / "absent")]) == 1
    out = capsys.readouterr().out
    assert f"OK       {good} (4 steps)" in out and f"OK       {folder / 'a.h5'} (4 steps)" in out
    assert f"INVALID  {bad}: steps/node_positions" in out
    assert f"INVALID  {tmp_path / 'absent'}: no such episode file or directory" in out
    assert out.rstrip().endswith("2/4 file(s) valid")
    assert dataset_cli(["validate", str(good), str(folder)]) == 0
    assert capsys.readouterr().out.rstrip().endswith("2/2 file(s) valid")


def test_a_mesh_missing_on_this_machine_is_a_warning_not_an_error(good, tmp_path):
    """An episode of a mesh-file object is valid elsewhere; only replay needs the mesh itself."""
    p = _copy(good, tmp_path)
    with h5py.File(p, "r+") as f:
        config = json.loads(f.attrs["config_json"])
        f.attrs["config_json"] = json.dumps({**config, "object": "/nowhere/part.stl"})
    report = validate_episode(p)
    assert report.ok and any("object mesh '/nowhere/part.stl' not found here" in w for w in report.warnings)
    with pytest.raises(EpisodeFileError, match=r"ep.h5: root attribute 'config_json': .*part.stl"):
        load_episode(p).config
    q = _copy(good, tmp_path, "typo.h5")
    with h5py.File(q, "r+") as f:
        f.attrs["config_json"] = json.dumps({**config, "object": "cubiod"})
    assert any("'cubiod'" in e for e in validate_episode(q).errors)


def test_wrong_schema_version_and_missing_dataset_on_load(good, tmp_path):
    p = _copy(good, tmp_path)
    with h5py.File(p, "r+") as f:
        f.attrs["schema_version"] = 99
    with pytest.raises(EpisodeFileError, match="ep.h5: unsupported schema_version 99"):
        load_episode(p)
    q = _copy(good, tmp_path, "q.h5")
    with h5py.File(q, "r+") as f:
        del f["object/density"]
    with pytest.raises(EpisodeFileError, match=r"q.h5: object/density: required dataset is missing \(expected float64 scalar\)$"):
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
