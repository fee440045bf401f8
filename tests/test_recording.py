"""HDF5Recorder: the Table 1 schema, values equal to the scene's, episode boundaries, schema doc."""

from __future__ import annotations

import json
import pathlib
import re

import gymnasium as gym
import h5py
import numpy as np
import pytest
from test_recording_helpers import STEPS, make_recorder, record_episodes, run_episode

from defgrasp_env.envs.config import PickupConfig
from defgrasp_env.recording import FIELDS, HDF5Recorder, load_episode, schema_markdown, validate_path
from defgrasp_env.recording.config_io import config_from_json, config_to_json
from defgrasp_env.recording.schema import ROOT_ATTRS

ROOT = pathlib.Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """One episode recorded while keeping what the env exposed at every step."""
    d = tmp_path_factory.mktemp("rec")
    env = make_recorder(d)
    seen = run_episode(env, seed=7)
    scene = env.unwrapped.scene
    truth = {"setup": scene.setups[0], "material": scene.materials[0], "tets": scene.model.tets.numpy(),
             "surface": scene.model.surfaces[0].copy()}
    env.close()
    return load_episode(env.paths[0]), seen, truth


def test_every_schema_dataset_has_declared_dtype_shape_and_units(recorded):
    ep, seen, _ = recorded
    t, n3 = len(seen), seen[0]["positions"].shape[0]
    dims = {"T": t, "T+1": t + 1, "N3": n3, "N2": len(ep["object/tetrahedra"]), "N1": len(ep["object/triangles"]),
            "A": 7, "O": 10, "S": 33}
    with h5py.File(ep.path) as f:
        for key, fld in FIELDS.items():
            if key not in f:
                assert not fld.required, key
                continue
            assert f[key].dtype == np.dtype(fld.dtype), key
            assert f[key].shape == tuple(dims[d] if isinstance(d, str) else d for d in fld.shape), key
            assert f[key].attrs["units"] == fld.units, key
            assert f[key].attrs["description"] == fld.description, key
        for name in ROOT_ATTRS:
            assert name in f.attrs, name


def test_table1_values_equal_what_the_env_exposed(recorded):
    ep, seen, truth = recorded
    setup, mat = truth["setup"], truth["material"]
    np.testing.assert_array_equal(ep["object/initial_position"], setup.position)
    np.testing.assert_array_equal(ep["object/initial_quaternion"], setup.quat)
    assert (ep["object/density"], ep["object/youngs_modulus"], ep["object/poisson_ratio"]) == \
           (mat.density, mat.youngs_modulus, mat.poisson_ratio)
    np.testing.assert_array_equal(ep["object/tetrahedra"], truth["tets"])
    np.testing.assert_array_equal(ep["object/triangles"], truth["surface"])
    for k, row in enumerate(seen):
        np.testing.assert_array_equal(ep["steps/node_positions"][k], row["positions"])
        agent = row["obs"]["agent_pos"]
        np.testing.assert_allclose(ep["steps/wrist_position"][k], agent[:3], rtol=0, atol=1e-6)
        np.testing.assert_allclose(ep["steps/wrist_orientation"][k], agent[3:7], rtol=0, atol=1e-6)
        info = row["info"]
        assert ep["steps/jaw_length"][k] == info["jaw_gap"]
        assert ep["steps/left_tip_normal_force"][k] == info["left_tip_normal_force"]
        assert ep["steps/right_tip_normal_force"][k] == info["right_tip_normal_force"]
        assert ep["steps/mean_von_mises"][k] == np.float32(info["mean_von_mises"])
        assert ep["steps/reward"][k] == row["reward"]
        np.testing.assert_array_equal(ep["observations/agent_pos"][k + 1], agent)
    np.testing.assert_allclose(ep["steps/time"], np.arange(1, len(seen) + 1) * 0.05)
    # force on node = elastic + contact; some contact exists (ground) and stresses are positive
    assert np.abs(ep["steps/contact_forces"]).max() > 0
    assert np.all(ep["steps/von_mises"] >= 0) and ep["steps/von_mises"].max() > 0
    np.testing.assert_allclose(ep["steps/mean_von_mises"], ep["info/mean_von_mises"], rtol=1e-6)


def test_attributes_describe_the_episode(recorded):
    ep, seen, _ = recorded
    a = ep.attrs
    assert a["env_id"] == "DeformablePickup-v0" and a["num_steps"] == len(seen) == STEPS
    assert a["truncated"] and not a["terminated"] and a["end_reason"] == "truncated"
    assert ep.replay["seed"] == 7 and ep.replay["max_episode_steps"] == STEPS
    assert ep.config == PickupConfig(object="cuboid", youngs_modulus=1e5)
    assert json.loads(a["versions_json"])["defgrasp"]
    assert ep.names["steps/action"] == ["vx", "vy", "vz", "wx", "wy", "wz", "jaw"]


def test_episode_boundaries_and_names(tmp_path):
    env = make_recorder(tmp_path)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(7, np.float32))
    run_episode(env, 0)                                  # truncated -> written at once
    assert len(env.paths) == 1 and env.paths[0].name == "episode_000000.h5"
    with pytest.raises(RuntimeError, match="ended"):
        env.step(np.zeros(7, np.float32))
    env.reset(seed=1)                                    # no step: nothing written
    env.reset(seed=2)
    env.step(np.zeros(7, np.float32))
    env.reset(seed=3)                                    # cut short by reset -> written
    env.step(np.zeros(7, np.float32))
    env.close()                                          # cut short by close -> written
    reasons = [load_episode(p).attrs["end_reason"] for p in env.paths]
    assert reasons == ["truncated", "reset", "close"]
    assert validate_path(tmp_path).ok
    env2 = make_recorder(tmp_path)                       # a new session never overwrites
    run_episode(env2, 0)
    env2.close()
    assert env2.paths[0].name == "episode_000003.h5"


def test_save_unfinished_false_and_custom_names(tmp_path):
    env = make_recorder(tmp_path, save_unfinished=False, name_template="run_{index:03d}.h5")
    env.set_next_name("chosen.h5")
    run_episode(env, 0)
    env.reset(seed=1)
    env.step(np.zeros(7, np.float32))
    env.close()
    assert [p.name for p in env.paths] == ["chosen.h5"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["chosen.h5"]


def test_frames_and_compression(tmp_path):
    from defgrasp_env.render.camera import Camera

    paths = record_episodes(tmp_path, seeds=(0,), steps=3, record_frames=True, compression="gzip",
                            render_mode="rgb_array", camera=Camera(width=32, height=24))
    ep = load_episode(paths[0])
    assert ep["observations/pixels"].shape == (4, 24, 32, 3) and ep["observations/pixels"].dtype == np.uint8
    assert ep["observations/pixels"].std() > 0
    with h5py.File(paths[0]) as f:
        assert f["observations/pixels"].compression == "gzip"
    assert validate_path(paths[0]).ok


def test_recorder_rejects_bad_arguments(tmp_path):
    base = gym.make("DeformablePickup-v0")
    with pytest.raises(ValueError, match="render_mode"):
        HDF5Recorder(base, tmp_path, record_frames=True)
    with pytest.raises(ValueError, match="name_template"):
        HDF5Recorder(base, tmp_path, name_template="x.h5")
    with pytest.raises(ValueError, match="compression"):
        HDF5Recorder(base, tmp_path, compression="zstd")
    with pytest.raises(TypeError, match="DeformablePickup"):
        HDF5Recorder(gym.make("CartPole-v1"), tmp_path)
    env = HDF5Recorder(base, tmp_path)
    with pytest.raises(ValueError, match="plain name"):
        env.set_next_name("../x.h5")
    with pytest.raises(TypeError, match="JSON"):
        env.reset(seed=0, options={"bad": object()})


def test_config_json_round_trip_is_exact():
    cfg = PickupConfig(object="torus", youngs_modulus=(1e4, 1e5), init_yaw_noise=0.1234567890123, control_hz=15.0)
    assert config_from_json(config_to_json(cfg)) == cfg
    with pytest.raises(ValueError, match="unknown"):
        config_from_json('{"nonsense": 1}')
    for edge in (True, False):  # both values round-trip, whatever the default
        assert config_from_json(config_to_json(PickupConfig(edge_contact=edge))).edge_contact is edge


def test_a_file_recorded_before_edge_contact_was_the_default_replays_without_it():
    """Files written while ``edge_contact`` did not exist or was off by default lack the key: they
    were simulated without it, so their config loads with it off (exact replay), not with today's default."""
    import json

    old = json.loads(config_to_json(PickupConfig(object="sphere")))
    del old["edge_contact"]
    assert PickupConfig().edge_contact is True
    assert config_from_json(json.dumps(old)) == PickupConfig(object="sphere", edge_contact=False)


def test_readme_schema_table_matches_the_code():
    readme = (ROOT / "datasets" / "README.md").read_text()
    m = re.search(r"<!-- schema:begin -->\n(.*?)<!-- schema:end -->", readme, re.S)
    assert m, "datasets/README.md needs the schema between <!-- schema:begin --> and <!-- schema:end -->"
    assert m.group(1) == schema_markdown(), "regenerate with: defgrasp-dataset schema"
    assert not (ROOT / "datasets" / "__init__.py").exists()
    assert (ROOT / "datasets" / "CARD.md").is_file()
