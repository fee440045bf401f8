"""Slotted models (``envs.world_models``, ``PickupScene.slots``): every world's rows fit any of the
config's objects, so a reset changes a world's object in place instead of rebuilding the arrays.
The reference is the packed model, whose resets rebuild: the same episodes (objects redrawn at
autoresets) must give the same outputs bit for bit on the CPU, the spare rows adding exact zeros,
and a model rewritten in place must equal one assembled afresh for the same worlds."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import warp as wp

import defgrasp_env  # noqa: F401
from defgrasp_env.envs.config import PickupConfig
from defgrasp_env.envs.scene import PickupScene, WorldSetup, object_mesh
from defgrasp_env.envs.world_models import assemble_model, slot_sizes
from defgrasp_env.sim.materials import Material
from defgrasp_env.sim.model import SPARE_POSITION
from contact_rollout import ExpertNoisyPress

OBJECTS = ("cuboid", "torus", "rope")


def _run(slotted: bool, steps: int, device: str = "cpu"):
    """W = 3 worlds drawing from three objects, two moduli and two densities (episodes of 15 steps,
    so autoresets redraw objects and materials): the expert, the expert with noise, and a world closing over the object and
    pressing it into the ground. The scene is replaced after the first reset by a slotted or a
    packed one (``slotted``) of the same setups. Returns every output and the
    object names after each step."""
    env = gym.make_vec("DeformablePickup-v0", num_envs=3, vectorization_mode="vector_entry_point", object=OBJECTS,
                       youngs_modulus=(1e5, 1e6), density=(500.0, 1200.0), max_episode_steps=15, device=device)
    obs, _ = env.reset(seed=11)
    venv = env.unwrapped
    venv.scene = PickupScene(venv.config, list(venv.scene.setups), slotted=slotted)
    scene = venv.scene
    assert (scene.slots is not None) == slotted
    model = scene.model
    policy = ExpertNoisyPress(env)
    out, names = {}, []
    for k in range(steps):
        obs, reward, terminated, truncated, info = env.step(policy.actions(obs))
        policy.episodes_ended(terminated, truncated)
        names.append(venv.scene.object_names)
        out.update({f"{k}/obs/{name}": np.asarray(v) for name, v in obs.items()})
        out[f"{k}/reward"] = np.asarray(reward)
        out.update({f"{k}/info/{name}": np.asarray(v) for name, v in info.items()
                    if np.asarray(v).dtype != object})
        s, m = venv.scene.state, venv.scene.model
        for w in range(3):
            for name in ("positions", "velocities", "elastic_force", "contact_force"):
                out[f"{k}/state/{w}/{name}"] = getattr(s, name).numpy()[m.world_nodes(w)].copy()
            out[f"{k}/state/{w}/von_mises"] = s.von_mises.numpy()[m.world_tets(w)].copy()
        for name in ("mean_von_mises", "pad_normal_force", "pad_force"):
            out[f"{k}/state/{name}"] = getattr(s, name).numpy().copy()
    if slotted:
        assert venv.scene.model is model  # the objects changed in place: never rebuilt
    env.close()
    return out, names, venv


def test_slotted_episodes_give_the_bits_of_packed_ones_through_object_changes():
    """Every observation, reward, info entry and state row of the objects equal to the packed
    model's (which rebuilds at each object change), over 45 steps whose autoresets change objects
    (asserted), with contact (the expert's grasps and the pressing world's force limit)."""
    steps = 45
    slotted, names, _ = _run(True, steps)
    packed, packed_names, _ = _run(False, steps)
    assert names == packed_names
    assert len({n for step in names for n in step}) == 3 and len(set(names)) >= 3  # objects changed
    moduli = {float(packed[k][w]) for k in packed if k.endswith("/info/youngs_modulus") for w in range(3)
              if packed[k.replace("youngs_modulus", "_youngs_modulus")][w]}
    assert moduli == {1e5, 1e6}  # materials were drawn at the resets
    assert slotted.keys() == packed.keys()
    differ = [k for k in packed if not np.array_equal(slotted[k], packed[k], equal_nan=True)
              or slotted[k].dtype != packed[k].dtype]
    assert not differ, differ[:10]


def _arrays(obj) -> dict:
    return {name: value.numpy() for name, value in vars(obj).items() if isinstance(value, wp.array)}


def test_a_model_rewritten_in_place_equals_one_assembled_afresh():
    """After resets that change objects, the slotted scene's model (every device array and the host
    offsets, surfaces and aggregates), the solver's copies of it (the Hessian's pattern included) and the control's prescribed
    positions equal those of a slotted model assembled from the worlds' current setups; the spare
    rows rest at SPARE_POSITION, fixed, massless, with zero-volume tets."""
    config = PickupConfig(object=OBJECTS)

    def setup(name, i, modulus):
        return WorldSetup(name, Material(500.0 + 100 * i, modulus, 0.3), np.array([0.02 * i, 0.0, -0.01 * i]),
                          np.array([0.0, np.sin(0.1 * i), 0.0, np.cos(0.1 * i)]))

    first = [setup(n, i, 1e5) for i, n in enumerate(("rope", "cuboid", "torus", "cuboid"))]
    scene = PickupScene(config, first, slotted=True)
    model, scratch = scene.model, scene.solver.scratch
    later = [setup(n, i + 4, 1e6) for i, n in enumerate(("cuboid", "rope", "torus", "torus"))]
    scene.reset_worlds(np.array([True, True, False, True]), later)
    scene.reset_worlds(np.array([False, False, True, False]), [None, None, setup("rope", 9, 1e4), None])
    assert scene.model is model and scene.object_names == ("cuboid", "rope", "rope", "torus")
    setups = scene.setups
    fresh = assemble_model([scene.mesh(w) for w in range(4)], [s.material for s in setups],
                           [(s.position, s.quat) for s in setups], [scene.gripper.pad_half_extents] * 2,
                           model.contact, "cpu", scene.slots)
    for name, value in _arrays(fresh).items():
        assert np.array_equal(getattr(model, name).numpy(), value), name
    for name in ("node_start", "tet_start", "node_end", "tet_end", "node_aggregate", "node_anchor"):
        assert np.array_equal(getattr(model, name), getattr(fresh, name)), name
    assert all(np.array_equal(a, b) for a, b in zip(model.surfaces, fresh.surfaces))
    fresh_solver = PickupScene(config, list(setups), slotted=True).solver.scratch
    assert np.array_equal(scratch.node_aggregate.numpy(), fresh_solver.node_aggregate.numpy())
    assert np.array_equal(scratch.node_anchor.numpy(), fresh_solver.node_anchor.numpy())
    assert np.array_equal(scratch.coarse_sizes.numpy(), fresh_solver.coarse_sizes.numpy())
    assert np.array_equal(scratch.tet_end.numpy(), fresh_solver.tet_end.numpy())
    assert np.array_equal(scratch.edges.triangles.numpy(), fresh_solver.edges.triangles.numpy())
    assert scratch.coarse_size == fresh_solver.coarse_size == 6 * scene.slots.aggregates
    assert np.array_equal(scene.solver.scratch.edges.triangle_first.numpy(), fresh_solver.edges.triangle_first.numpy())
    for name in ("node_blocks", "node_incidences"):  # the Hessian's pattern
        assert np.array_equal(getattr(scratch.hessian, name).numpy(), getattr(fresh_solver.hessian, name).numpy()), name
    used = np.concatenate([np.arange(a, b) for a, b in fresh_solver.hessian.node_blocks.numpy()])
    assert np.array_equal(scratch.hessian.block_node.numpy()[used], fresh_solver.hessian.block_node.numpy()[used])
    for w in range(4):  # the incidences the object's nodes name (rows past them: the old object's, never read)
        used = slice(4 * int(model.tet_start[w]), 4 * int(model.tet_end[w]))
        for name in ("incidence", "incidence_blocks"):
            assert np.array_equal(getattr(scratch.hessian, name).numpy()[used],
                                  getattr(fresh_solver.hessian, name).numpy()[used]), name
    for w in range(4):
        spare = slice(int(model.node_end[w]), int(model.node_start[w + 1]))
        assert spare.stop - spare.start >= 1
        np.testing.assert_array_equal(model.rest_positions.numpy()[spare], np.float32(SPARE_POSITION)[None].repeat(
            spare.stop - spare.start, 0))
        np.testing.assert_array_equal(scene.state.positions.numpy()[spare], model.rest_positions.numpy()[spare])
        assert not model.free_axes.numpy()[spare].any() and not model.node_mass.numpy()[spare].any()
        tets = slice(int(model.tet_end[w]), int(model.tet_start[w + 1]))
        assert not model.tet_rest_volume.numpy()[tets].any() and not model.tet_mu.numpy()[tets].any()
        assert (model.tets.numpy()[tets] == spare.start).all()
    pos, quat = scene.gripper.flange_pose()
    scene.step(pos, quat, scene.gripper.gap.copy())  # spare rows stay where the control prescribes them
    for w in range(4):
        spare = slice(int(model.node_end[w]), int(model.node_start[w + 1]))
        np.testing.assert_array_equal(scene.state.positions.numpy()[spare], model.rest_positions.numpy()[spare])
        assert not scene.state.velocities.numpy()[spare].any()


def test_an_object_larger_than_the_slot_is_refused():
    config = PickupConfig(object=("cuboid", "sphere"))
    setup = WorldSetup("rope", Material(500.0, 1e5, 0.3), np.zeros(3), np.array([0, 0, 0, 1.0]))
    with pytest.raises(ValueError, match="does not fit the slot"):
        PickupScene(config, [setup], slotted=True)


def test_slots_are_asked_for_or_left_out():
    """A CPU scene stays packed by default (spare rows would cost its solver time; a rebuild is
    cheap there; the CUDA default is checked by the CUDA test below); one object needs no slots;
    asked for, the slot fits every object of the config."""
    setup = WorldSetup("cuboid", Material(500.0, 1e5, 0.3), np.zeros(3), np.array([0, 0, 0, 1.0]))
    assert PickupScene(PickupConfig(object=OBJECTS), [setup]).slots is None
    sizes = slot_sizes([object_mesh(o, None) for o in OBJECTS])
    assert PickupScene(PickupConfig(object=OBJECTS), [setup], slotted=True).slots == sizes
    assert PickupScene(PickupConfig(), [setup]).slots is None


@pytest.mark.cuda
def test_random_objects_on_cuda_change_in_place_and_agree_with_packed():
    """On CUDA ``object="random"`` is slotted by default: autoresets change objects without a
    rebuild, and the first steps agree with a packed run within the float atomics' rounding."""
    if not wp.is_cuda_available():
        pytest.skip("no CUDA device")
    env = gym.make_vec("DeformablePickup-v0", num_envs=8, vectorization_mode="vector_entry_point", object="random",
                       max_episode_steps=3, device="cuda:0")
    env.reset(seed=2)
    scene = env.unwrapped.scene
    model, names = scene.model, set()
    assert scene.slots is not None
    for _ in range(12):
        _, reward, *_ = env.step(np.zeros((8, 7), np.float32))
        names.add(scene.object_names)
        assert np.isfinite(reward).all()
    assert scene.model is model and len(names) > 2
    slotted, _, _ = _run(True, 4, "cuda:0")
    packed, _, _ = _run(False, 4, "cuda:0")
    for w in range(3):
        np.testing.assert_allclose(slotted[f"3/state/{w}/positions"], packed[f"3/state/{w}/positions"], atol=1e-5)


def test_materials_set_in_place_equal_a_model_built_with_them():
    """``set_world_materials`` (one scatter per array for several worlds) and ``set_world_material``
    (one world, its tets and volumes read back) give the arrays ``build_model`` makes with the new
    materials, bit for bit; the other worlds' rows are untouched."""
    from defgrasp_env.sim.model import build_model, set_world_material, set_world_materials

    meshes = [object_mesh(n, None) for n in ("cuboid", "torus", "sphere")]
    a = [Material(400.0, 1e4, 0.3), Material(900.0, 2e5, 0.45), Material(1200.0, 3e6, 0.2)]
    b = [Material(1500.0, 7e6, 0.35), a[1], Material(300.0, 5e4, 0.49)]
    model = build_model(meshes, a)
    expected = build_model(meshes, b)
    volumes = [model.tet_rest_volume.numpy()[model.world_tets(w)] for w in range(3)]
    set_world_materials(model, [0], [b[0]], [np.asarray(meshes[0].tets)], volumes[:1])
    set_world_material(model, 2, b[2])
    for name in ("node_mass", "node_contact_stiffness", "tet_mu", "tet_lambda"):
        assert np.array_equal(getattr(model, name).numpy(), getattr(expected, name).numpy()), name
    with pytest.raises(ValueError, match=r"world must be in \[0, 2\], got 3"):
        set_world_materials(model, [3], [b[0]], [np.asarray(meshes[0].tets)], volumes[:1])


def test_a_bad_rewrite_is_refused_before_anything_changes():
    """Worlds out of range or repeated, missing meshes or poses, and an object whose coarse
    aggregates exceed the slot's are refused, naming the problem, with the model untouched."""
    from defgrasp_env.envs.world_models import rewrite_worlds
    from defgrasp_env.sim.model import set_world_materials

    config = PickupConfig(object=("cuboid", "sphere"))
    setup = WorldSetup("cuboid", Material(500.0, 1e5, 0.3), np.zeros(3), np.array([0, 0, 0, 1.0]))
    scene = PickupScene(config, [setup, setup], slotted=True)
    model = scene.model
    before = {name: a.copy() for name, a in _arrays(model).items()}
    ends = model.node_end.copy()
    sphere, rope = object_mesh("sphere", None), object_mesh("rope", None)
    pose = (np.zeros(3), np.array([0, 0, 0, 1.0]))
    half = [scene.gripper.pad_half_extents] * 2
    cases = [([0, 0], [sphere, sphere], r"worlds must be distinct"), ([2], [sphere], r"in \[0, 1\], got \[2\]"),
             ([0, 1], [sphere], "need one mesh, material and pose per world"), ([0], [rope], "does not fit the slot")]
    for worlds, meshes, message in cases:
        with pytest.raises(ValueError, match=message):
            rewrite_worlds(model, worlds, meshes, [setup.material] * len(meshes), [pose] * len(meshes), half)
    with pytest.raises(ValueError, match="need one material, tets and volumes per world"):
        set_world_materials(model, [0, 1], [setup.material], [np.zeros((0, 4))], [np.zeros(0)])
    with pytest.raises(ValueError, match=r"world 0 has \d+ tets, got 3 tets"):
        set_world_materials(model, [0], [setup.material], [np.zeros((3, 4), int)], [np.zeros(3)])
    assert all(np.array_equal(getattr(model, name).numpy(), a) for name, a in before.items())
    assert np.array_equal(model.node_end, ends)
