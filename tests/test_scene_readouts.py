"""The per-step readouts reduced by Warp kernels on the simulation's device (feature point and
velocity, keypoints, finiteness per world) against the numpy reductions of the full state they
replace (the independent truth), on mixed objects, after contact steps, and with a NaN planted in
one world."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import warp as wp

import defgrasp_env  # noqa: F401 - registers DeformablePickup-v0
from defgrasp_env.envs.readouts import SceneReadouts
from defgrasp_env.envs.scene import keypoint_indices
from defgrasp_env.layout import ENV_STATE, NUM_KEYPOINTS


def _numpy_readouts(scene):
    """The readouts as the env computed them on the host before they moved to the device."""
    x, v = scene.state.positions.numpy(), scene.state.velocities.numpy()
    starts = scene.model.node_start
    counts = np.diff(starts)
    pos = np.add.reduceat(x.astype(np.float64), starts[:-1], axis=0) / counts[:, None]
    vel = np.add.reduceat(v.astype(np.float64), starts[:-1], axis=0) / counts[:, None]
    keys = np.zeros((scene.num_worlds, NUM_KEYPOINTS, 3))
    for w in range(scene.num_worlds):
        mesh = scene.mesh(w)
        idx = keypoint_indices(mesh.nodes, mesh.surface) + starts[w]
        keys[w, : len(idx)] = x[idx]
    bad = ~(np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1))
    finite = np.add.reduceat(bad.astype(int), starts[:-1]) == 0
    return pos, vel, keys, finite


def test_device_readouts_equal_the_numpy_reductions_on_mixed_objects():
    venv = gym.make_vec("DeformablePickup-v0", num_envs=5, vectorization_mode="vector_entry_point", object="random")
    venv.reset(seed=2)
    rng = np.random.default_rng(0)
    scene = venv.unwrapped.scene
    for _ in range(3):
        a = rng.uniform(-0.5, 0.5, (5, 7)).astype(np.float32)
        a[:, 1], a[:, 6] = -1.0, 1.0
        obs, *_ = venv.step(a)
        pos, vel, keys, finite = _numpy_readouts(scene)
        r = scene.readout()
        # float64 sums in node order, as numpy's reduceat over rows: equal bits (a reordered sum
        # would differ by ~1e-16 relative; 1e-12 m would still be far below any physical scale)
        np.testing.assert_array_equal(r.feature_position, pos)
        np.testing.assert_array_equal(r.feature_velocity, vel)
        np.testing.assert_array_equal(r.keypoints, keys)
        assert r.finite.tolist() == finite.tolist() == [True] * 5
        env_state = obs["environment_state"]
        np.testing.assert_array_equal(ENV_STATE.get(env_state, "feature_position"), pos.astype(np.float32))
        np.testing.assert_array_equal(ENV_STATE.get(env_state, "keypoints"), keys.reshape(5, -1).astype(np.float32))


def test_finite_flags_only_the_world_with_a_nan():
    venv = gym.make_vec("DeformablePickup-v0", num_envs=3, vectorization_mode="vector_entry_point", object="random")
    venv.reset(seed=0)
    scene = venv.unwrapped.scene
    for field, value in (("positions", np.nan), ("velocities", np.inf)):
        state = type(scene.state)(**{k: wp.clone(getattr(scene.state, k)) for k in scene.state.__dataclass_fields__})
        readouts = SceneReadouts(scene.model, [state], [keypoint_indices(scene.mesh(w).nodes, scene.mesh(w).surface)
                                                      for w in range(3)])
        host = getattr(state, field).numpy()
        last = scene.model.node_start[2] - 1  # the last node of world 1
        host[last, 2] = value
        getattr(state, field).assign(host)
        r = readouts.compute(state)
        assert r.finite.tolist() == [True, False, True], field


def test_assembled_model_equals_build_model_bit_for_bit():
    """The scene's model from cached one-world models equals ``build_model`` of the same worlds."""
    from defgrasp_env.envs.common import draw_setup
    from defgrasp_env.envs.config import PickupConfig
    from defgrasp_env.envs.scene import object_mesh
    from defgrasp_env.envs.world_models import assemble_model
    from defgrasp_env.gripper import Gripper
    from defgrasp_env.sim.model import ContactParams, build_model

    config = PickupConfig(object="random", youngs_modulus=(1e4, 1e6), density=(300.0, 800.0))
    rng = np.random.default_rng(1)
    setups = [draw_setup(config, rng) for _ in range(7)]
    args = ([object_mesh(s.object_name, None) for s in setups], [s.material for s in setups],
            [(s.position, s.quat) for s in setups])
    half = [Gripper.pad_half_extents] * 2
    contact = ContactParams(2e6, 0.4, 0.9)
    a = assemble_model(*args, half, contact, "cpu")
    b = build_model(*args, pad_half_extents=half, contact=contact, device="cpu")
    for name in b.__dataclass_fields__:
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(y, wp.array):
            assert x.dtype == y.dtype and x.numpy().tobytes() == y.numpy().tobytes(), name
        elif name == "surfaces":
            assert all(np.array_equal(s, t) for s, t in zip(x, y))
        elif isinstance(y, np.ndarray):
            assert x.dtype == y.dtype and np.array_equal(x, y), name
        else:
            assert x == y, name


def _numpy_pad_embedding(scene, pad_pos, pad_quat):
    """Deepest tet centroid inside a pad box per world (m, 0 where none), in numpy: the pad poses
    [W*P, 3] / [W*P, 4] (xyzw) as given to the state, the box test written out per axis."""
    from defgrasp_env.transforms import quat_to_matrix

    x = scene.state.positions.numpy().astype(np.float64)
    tets, tet_world = scene.model.tets.numpy(), scene.model.tet_world.numpy()
    half = scene.model.pad_half_extents.numpy().astype(np.float64)
    pads = scene.model.pads_per_world
    centroid = x[tets].mean(axis=1)
    out = np.zeros(scene.num_worlds)
    for pad in range(len(pad_pos)):
        mine = tet_world == pad // pads
        local = (centroid[mine] - pad_pos[pad]) @ quat_to_matrix(pad_quat[pad])  # R^T (c - p), row-wise
        depth = np.min(half[pad] - np.abs(local), axis=1)
        if depth.size and depth.max() > 0:
            out[pad // pads] = max(out[pad // pads], depth.max())
    return out


def test_pad_embedding_reads_material_inside_a_pad_and_nothing_outside():
    """The readout's pad embedding against the numpy computation of the same definition: zero for
    the expert-free reset scene (pads above the objects), the analytic depth where a pad box is
    placed around an object's interior (tilted, in one world of three), and zero again in the
    other worlds; the env's ``pierced`` flag follows it beyond PIERCE_DEPTH."""
    from defgrasp_env.envs.task import PIERCE_DEPTH

    venv = gym.make_vec("DeformablePickup-v0", num_envs=3, vectorization_mode="vector_entry_point",
                        object=("cuboid", "sphere"), youngs_modulus=1e6)  # solid: material at the centre
    venv.reset(seed=1)
    scene = venv.unwrapped.scene
    assert np.all(scene.readout().pad_embedding == 0.0)
    original_pos, original_quat = scene.state.pad_positions.numpy().copy(), scene.state.pad_orientations.numpy().copy()
    pos, quat = original_pos.astype(np.float64), original_quat.astype(np.float64)
    feature = scene.readout().feature_position
    pos[2] = feature[1]  # world 1's first pad around its object's centre, turned 30 degrees about y
    quat[2] = [0.0, np.sin(np.pi / 12), 0.0, np.cos(np.pi / 12)]
    scene.state.pad_positions.assign(pos.astype(np.float32))
    scene.state.pad_orientations.assign(quat.astype(np.float32))
    scene._readout = None  # the readout caches per state: the poses changed under it
    got = scene.readout().pad_embedding
    want = _numpy_pad_embedding(scene, pos.astype(np.float32).astype(np.float64), quat.astype(np.float32))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)  # float32 kernel vs float64: ~1e-8 m apart
    assert got[0] == got[2] == 0.0
    half = scene.model.pad_half_extents.numpy()[2]
    assert PIERCE_DEPTH < got[1] <= half.min()  # the pad's 16 mm thickness full of material
    assert np.all(scene.solve_report.records.numpy()["penetration"] == 0.0)  # no step yet: no node deep
    task = venv.unwrapped.task
    task.evaluate(scene)
    assert task.result()["pierced"].tolist() == [False, True, False]
    scene.state.pad_positions.assign(original_pos)  # the pads back above the objects: zero again,
    scene.state.pad_orientations.assign(original_quat)  # not the maximum of the last readout
    scene._readout = None
    assert np.all(scene.readout().pad_embedding == 0.0)
    task.evaluate(scene)
    assert not task.result()["pierced"].any()
