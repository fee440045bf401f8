"""Worlds with different objects in the native vector env: ``object="random"`` (or a tuple of
names and mesh paths) draws a fresh object per world per episode; a reset that changes a world's
object rebuilds the flat arrays and leaves every other world bit-identical (full FEM state and
gripper, compared against a run where no reset happened, and still after more steps); the reset
info reports each world's object and E; a reset world's ReplaySpec replays bit-exactly in a
single env (CPU)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import trimesh
from gymnasium.vector import AutoresetMode

import defgrasp_env  # noqa: F401 - registers DeformablePickup-v0

ENV_ID = "DeformablePickup-v0"
STATE_NODE = ("positions", "velocities", "elastic_force", "contact_force")
STATE_WORLD = ("pad_positions", "pad_orientations", "pad_normal_force", "pad_force")


def _actions(n: int, steps: int, seed: int = 0) -> np.ndarray:
    """Down with the jaw closing: the pads reach the object within a few steps (contact active)."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(-0.3, 0.3, size=(steps, n, 7)).astype(np.float32)
    a[..., 1] = -1.0
    a[..., 6] = 1.0
    return a


def _single_object(seed: int, **kwargs) -> str:
    _, info = gym.make(ENV_ID, **kwargs).reset(seed=seed)
    return info["object"]


def _world_state(scene, w: int) -> dict[str, np.ndarray]:
    """Everything of world ``w`` that carries over a step: FEM state slices and the gripper."""
    st, m = scene.state, scene.model
    out = {k: getattr(st, k).numpy()[m.world_nodes(w)].copy() for k in STATE_NODE}
    out["von_mises"] = st.von_mises.numpy()[m.world_tets(w)].copy()
    out["mean_von_mises"] = st.mean_von_mises.numpy()[w:w + 1].copy()
    p = m.pads_per_world
    out.update({k: getattr(st, k).numpy()[w * p:(w + 1) * p].copy() for k in STATE_WORLD})
    g = scene.gripper
    out.update(q=g.q[w].copy(), gap=g.gap[w:w + 1].copy(), tip=g.tip_force[w].copy(),
               wrist=g.wrist_force[w:w + 1].copy())
    return out


def _assert_same(a: dict, b: dict, what: str) -> None:
    for k in a:
        assert a[k].tobytes() == b[k].tobytes(), f"{what}: {k} differs"


def test_random_object_is_drawn_per_world_per_episode_as_a_single_env_draws_it():
    venv = gym.make_vec(ENV_ID, num_envs=4, vectorization_mode="vector_entry_point", object="random",
                        youngs_modulus=(1e4, 1e5, 1e6))
    seen = set()
    for seed in (0, 40):
        _, info = venv.reset(seed=seed)
        scene = venv.unwrapped.scene
        assert info["_object"].all() and info["_youngs_modulus"].all()
        for w in range(4):
            single = gym.make(ENV_ID, object="random", youngs_modulus=(1e4, 1e5, 1e6))
            _, sinfo = single.reset(seed=seed + w)
            assert info["object"][w] == sinfo["object"] == scene.object_names[w]
            assert info["youngs_modulus"][w] == sinfo["youngs_modulus"] == scene.materials[w].youngs_modulus
            assert scene.model.node_start[w + 1] - scene.model.node_start[w] == len(scene.mesh(w).nodes)
            seen.add(scene.object_names[w])
    assert len(seen) >= 3  # 8 draws among 5 objects: the worlds do hold different objects
    venv.close()


def _changing_seed(current: str, **kwargs) -> int:
    """A seed whose single-env draw is another object than ``current``."""
    return next(s for s in range(100, 200) if _single_object(s, **kwargs) != current)


@pytest.mark.parametrize("obj", ["random", ("cuboid", "sphere", "torus")])
def test_reset_that_changes_an_object_leaves_other_worlds_bit_identical_and_replays(obj):
    kwargs = dict(object=obj, youngs_modulus=(1e5, 1e6))
    runs = []
    for _ in range(2):
        venv = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point",
                            autoreset_mode=AutoresetMode.DISABLED, **kwargs)
        venv.reset(seed=7)
        for a in _actions(3, 4):
            venv.step(a)
        runs.append(venv)
    reset_env, plain = runs
    scene = reset_env.unwrapped.scene
    old = scene.object_names[1]
    seed = _changing_seed(old, **kwargs)
    _, info = reset_env.reset(seed=[None, seed, None], options={"reset_mask": np.array([False, True, False])})
    assert info["_object"].tolist() == [False, True, False]
    assert scene.object_names[1] == info["object"][1] != old  # the object changed: the arrays were rebuilt
    assert info["youngs_modulus"][1] == scene.materials[1].youngs_modulus
    spec = info["replay_spec"][1]
    assert spec.seed == seed and spec.scene_origin is None  # this reset built the world's object
    pscene = plain.unwrapped.scene
    for w in (0, 2):
        _assert_same(_world_state(scene, w), _world_state(pscene, w), f"world {w} at the reset")
    later = _actions(3, 3, seed=5)
    x1 = []
    for a in later:
        reset_env.step(a)
        plain.step(a)
        x1.append(scene.state.positions.numpy()[scene.model.world_nodes(1)].copy())
    for w in (0, 2):  # the rebuilt solver steps the kept worlds exactly as the old one
        _assert_same(_world_state(scene, w), _world_state(pscene, w), f"world {w} after 3 more steps")
    single = gym.make(ENV_ID, **kwargs)
    spec.reset(single)
    sscene = single.unwrapped.scene
    for k, a in enumerate(later[:, 1]):
        single.step(a)
        assert np.array_equal(sscene.state.positions.numpy(), x1[k]), f"replay differs at step {k}"


def test_next_step_autoreset_redraws_objects_and_reports_them():
    venv = gym.make_vec(ENV_ID, num_envs=4, vectorization_mode="vector_entry_point", object="random",
                        max_episode_steps=1)
    venv.reset(seed=3)
    zero = np.zeros((4, 7), np.float32)
    names = []
    for _ in range(4):
        _, _, _, truncated, info = venv.step(zero)  # every other step is an autoreset of all worlds
        if "_object" in info:
            assert info["_object"].all() and list(info["object"]) == list(venv.unwrapped.scene.object_names)
            names.append(tuple(info["object"]))
    assert len(names) == 2 and names[0] != names[1]


def test_world_objects_fix_each_worlds_object_over_autoresets_without_rebuilding_and_replay():
    """``world_objects``: every episode of world i holds world_objects[i] (E and pose still drawn),
    autoresets keep the model (no rebuild), and each reset's ReplaySpec repeats it in a single env."""
    fixed = ("rope", "cuboid", "rope")
    kwargs = dict(object="random", youngs_modulus=(1e5, 1e6))
    venv = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point", max_episode_steps=2,
                        autoreset_mode=AutoresetMode.SAME_STEP, world_objects=list(fixed), **kwargs)
    _, info = venv.reset(seed=11)
    scene = venv.unwrapped.scene
    model = scene.model
    assert tuple(info["object"]) == fixed == scene.object_names
    specs, moduli = [list(info["replay_spec"])], {info["youngs_modulus"][0]}
    for a in _actions(3, 6, seed=2):
        _, _, _, truncated, info = venv.step(a)
        if truncated.any():
            assert truncated.all() and tuple(info["object"]) == fixed
            specs.append(list(info["replay_spec"]))
            moduli.add(info["youngs_modulus"][0])
    assert venv.unwrapped.scene is scene and scene.model is model  # no reset rebuilt the arrays
    assert len(specs) == 4 and moduli == {1e5, 1e6}  # E is still drawn per episode
    # a draw continues the world's RNG exactly as the single env's reset with the object option
    single = gym.make(ENV_ID, **kwargs)
    for episode in specs:
        for name, spec in zip(fixed, episode):
            assert spec.options == {"object": name}
            _, sinfo = spec.reset(single)
            s = single.unwrapped.scene.setups[0]
            assert sinfo["object"] == name and s.material == spec.material
            assert np.array_equal(s.position, spec.position) and np.array_equal(s.quat, spec.quat)
    # the same worlds of a run without world_objects draw other objects from the same seed
    free = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point", **kwargs)
    assert tuple(free.reset(seed=11)[1]["object"]) != fixed
    for env in (venv, single, free):
        env.close()


@pytest.mark.parametrize("objects, error", [
    (("cuboid", "sphere"), "one object per world \\(3\\), got 2"),
    (("cuboid", "sphere", "banana"), "world_objects\\[2\\] must be one of"),
    ("cuboid", "sequence of 3 object names"),
])
def test_bad_world_objects_rejected(objects, error):
    with pytest.raises((ValueError, TypeError), match=error):
        gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point", object="random",
                     world_objects=objects)


def test_world_objects_must_be_among_the_config_objects():
    with pytest.raises(ValueError, match="world_objects\\[0\\] must be one of the config's objects \\['cuboid'\\]"):
        gym.make_vec(ENV_ID, num_envs=1, vectorization_mode="vector_entry_point", world_objects=["sphere"])


def test_object_tuple_with_a_user_mesh(tmp_path):
    path = tmp_path / "ball.stl"
    trimesh.creation.icosphere(2, radius=0.025).export(path)
    venv = gym.make_vec(ENV_ID, num_envs=4, vectorization_mode="vector_entry_point",
                        object=["cuboid", str(path)])
    _, info = venv.reset(seed=0)
    assert set(info["object"]) <= {"cuboid", str(path)}
    obs, *_ = venv.step(np.zeros((4, 7), np.float32))
    assert np.isfinite(obs["environment_state"]).all()
    assert venv.unwrapped.config.object == ("cuboid", str(path))


@pytest.mark.parametrize("obj", [(), ("cuboid", "random"), ("cuboid", "banana")])
def test_bad_object_tuple_rejected(obj):
    with pytest.raises(ValueError, match="object"):
        gym.make(ENV_ID, object=obj)


def test_material_tuples_are_drawn_per_world_as_a_single_env_draws_them():
    kwargs = dict(object="random", youngs_modulus=(1e4, 1e6), poisson_ratio=(0.2, 0.45), density=(300.0, 900.0))
    venv = gym.make_vec(ENV_ID, num_envs=4, vectorization_mode="vector_entry_point", **kwargs)
    _, info = venv.reset(seed=5)
    a = _actions(4, 1, seed=3)[0]
    obs, *_ = venv.step(a)
    materials = set()
    for w in range(4):
        single = gym.make(ENV_ID, **kwargs)
        _, sinfo = single.reset(seed=5 + w)
        assert sinfo["replay_spec"].material == info["replay_spec"][w].material
        materials.add(sinfo["replay_spec"].material)
        sobs, *_ = single.step(a[w])
        for key in sobs:  # the model uses the drawn material: the step is the single env's, bit for bit
            assert np.array_equal(sobs[key], obs[key][w]), (w, key)
    assert len(materials) >= 2
    assert {m.poisson_ratio for m in materials} <= {0.2, 0.45} and {m.density for m in materials} <= {300.0, 900.0}


@pytest.mark.parametrize("kwargs", [dict(density=()), dict(poisson_ratio=(0.3, 0.5)), dict(density=(500.0, -1.0))])
def test_bad_material_tuples_rejected(kwargs):
    with pytest.raises(ValueError):
        gym.make(ENV_ID, **kwargs)
