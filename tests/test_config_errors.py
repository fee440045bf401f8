"""Early, clear errors: object names and mesh files are checked at gym.make (not at reset), and the
vector env's reset seed is type-checked, each error naming the bad value and what is accepted."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import trimesh

import defgrasp_env  # noqa: F401  (registers the env)
from defgrasp_env.envs.config import PickupConfig
from defgrasp_env.envs.seeds import world_seeds
from defgrasp_env.sim.meshing import OBJECT_SHAPES

ENV_ID = "DeformablePickup-v0"


@pytest.mark.parametrize("name", ["banana", "Cuboid", "cuboid ", "", "meshes/part.stl"])
def test_unknown_object_names_fail_at_make_listing_the_valid_names(name):
    with pytest.raises(ValueError) as err:
        gym.make(ENV_ID, object=name)
    text = str(err.value)
    assert repr(name) in text and all(repr(n) in text for n in OBJECT_SHAPES) and "'random'" in text
    assert "existing" in text and "file" in text


@pytest.mark.parametrize("value", [3, None, b"cuboid"])
def test_object_of_the_wrong_type(value):
    with pytest.raises(TypeError, match=f"object must be a str .*got {type(value).__name__}"):
        PickupConfig(object=value)


def test_every_registered_name_and_random_are_accepted():
    for name in (*OBJECT_SHAPES, "random"):
        assert PickupConfig(object=name).object == name


def _write(path, mesh):
    mesh.export(path)
    return str(path)


def test_a_watertight_mesh_file_is_accepted_and_meshes_at_reset(tmp_path):
    path = _write(tmp_path / "ball.stl", trimesh.creation.icosphere(2, radius=0.025))
    env = gym.make(ENV_ID, object=path, object_resolution=0.008)
    obs, _ = env.reset(seed=0)
    assert np.all(np.isfinite(obs["agent_pos"]))
    env.close()


def test_bad_mesh_files_fail_at_make_naming_the_file(tmp_path):
    box = trimesh.creation.box((0.04, 0.03, 0.05))
    holed = trimesh.Trimesh(box.vertices, box.faces[:-1], process=False)   # one triangle missing
    open_path = _write(tmp_path / "holed.stl", holed)
    with pytest.raises(ValueError) as err:
        gym.make(ENV_ID, object=open_path)
    assert f"object mesh file {open_path!r}" in str(err.value) and "watertight" in str(err.value)
    garbage = tmp_path / "garbage.obj"
    garbage.write_text("this is not a mesh\n")
    with pytest.raises(ValueError, match=f"object mesh file {str(garbage)!r} cannot be used"):
        gym.make(ENV_ID, object=str(garbage))
    with pytest.raises(ValueError, match="neither a known name nor an existing file"):
        gym.make(ENV_ID, object=str(tmp_path / "missing.stl"))
    with pytest.raises(ValueError, match="neither a known name nor an existing file"):
        gym.make(ENV_ID, object=str(tmp_path))                               # a folder is not a mesh file


def test_a_mesh_file_fixed_in_place_is_checked_again(tmp_path):
    """The check is cached per file version (path, mtime, size), not per path."""
    path = tmp_path / "part.stl"
    box = trimesh.creation.box((0.04, 0.03, 0.05))
    _write(path, trimesh.Trimesh(box.vertices, box.faces[:-1], process=False))
    with pytest.raises(ValueError, match="watertight"):
        PickupConfig(object=str(path))
    _write(path, box)
    assert PickupConfig(object=str(path)).object == str(path)


@pytest.mark.parametrize("seed, error, message", [
    ("abc", TypeError, "seed must be None, an int >= 0 or a list of 3 ints >= 0 (or None), got 'abc' of type str"),
    (1.5, TypeError, "got 1.5 of type float"),
    (True, TypeError, "got True of type bool"),
    (-1, ValueError, "seed must be an int >= 0, got -1"),
    ([1, 2], ValueError, "seed list must have 3 entries (one per world), got 2"),
    ([1, "x", 3], TypeError, "seed[1] must be an int >= 0 or None, got 'x' of type str"),
    ([1, -2, 3], ValueError, "seed[1] must be an int >= 0 or None, got -2"),
    (np.array([1, 2, 3]), TypeError, "of type ndarray"),
])
def test_vector_reset_seed_is_type_checked(seed, error, message):
    venv = gym.make_vec(ENV_ID, num_envs=3)
    with pytest.raises(error) as err:
        venv.reset(seed=seed)
    assert message in str(err.value)
    venv.close()


def test_world_seeds_expands_like_before():
    assert world_seeds(None, 2) == [None, None]
    assert world_seeds(7, 3) == [7, 8, 9]
    assert world_seeds(np.int64(7), 2) == [7, 8] and all(type(s) is int for s in world_seeds(np.int64(7), 2))
    assert world_seeds([4, None, 0], 3) == [4, None, 0]
    assert world_seeds((1, 2), 2) == [1, 2]


def test_vector_reset_with_valid_seeds_matches_single_envs():
    """A numpy integer seed now works and gives world i the seed + i of a single env."""
    venv = gym.make_vec(ENV_ID, num_envs=2)
    obs, _ = venv.reset(seed=np.int64(5))
    for i in range(2):
        single, _ = gym.make(ENV_ID).reset(seed=5 + i)
        np.testing.assert_array_equal(obs["agent_pos"][i], single["agent_pos"])
    venv.close()
