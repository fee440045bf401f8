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
