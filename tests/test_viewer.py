"""3D viewer parts without a browser: per-node stress, pad boxes from a recorded pose, colour bands,
port checks, render_mode="human" arguments."""

from __future__ import annotations

import socket

import numpy as np
import pytest

from defgrasp_env.viewer import StressScale, check_port_free, node_stress, pad_boxes_world


def test_node_stress_is_the_mean_over_incident_tets():
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    vm = np.array([10.0, 30.0])
    s = node_stress(tets, vm, 6)
    # nodes 0 and 4 are in one tet each, 1-3 in both, node 5 in none
    np.testing.assert_allclose(s, [10.0, 20.0, 20.0, 20.0, 30.0, 0.0])
    with pytest.raises(ValueError, match=r"tet_stress must have shape \(T,\) = \(2,\)"):
        node_stress(tets, vm[:1], 6)


def test_pad_boxes_from_a_recorded_pose_match_the_scene():
    """The playback draws pads from (flange pose, gap) as the file stores them: same boxes as the
    scene's own pad_poses at that state."""
    import gymnasium as gym

    import defgrasp_env  # noqa: F401

    env = gym.make("DeformablePickup-v0", object="sphere")
    env.reset(seed=4)
    rng = np.random.default_rng(0)
    for _ in range(6):
        env.step(rng.uniform(-1, 1, 7))
    scene = env.unwrapped.scene
    pos, quat = scene.gripper.flange_pose()
    centers, quats, half = pad_boxes_world(pos[0], quat[0], scene.gripper.gap[0])
    ref_c, ref_q = scene.gripper.pad_poses()
    np.testing.assert_allclose(centers, ref_c[0], atol=1e-12)
    np.testing.assert_allclose(quats, ref_q[0], atol=1e-12)
    assert np.all(half > 0)
    env.close()


def test_stress_scale_bands_and_sticky_range():
    sc = StressScale(bins=4, floor_pa=100.0)
    assert sc.colors.shape == (4, 3) and sc.colors.dtype == np.uint8
    np.testing.assert_array_equal(sc.band_of(np.array([0.0, 24.9, 25.0, 99.0, 1e9, np.nan])), [0, 0, 1, 3, 3, 0])
    sc.observe(np.array([50.0, 400.0, np.inf]))
    assert sc.upper_pa == 400.0  # grows, ignores inf
    sc.observe(10.0)
    assert sc.upper_pa == 400.0  # sticky within an episode
    assert "0.4" in sc.scale_bar_html()  # top label in kPa
    sc.reset()
    assert sc.upper_pa == 100.0
    for bad in (dict(bins=1), dict(colormap="jet"), dict(floor_pa=0.0)):
        with pytest.raises(ValueError):
            StressScale(**bad)


def test_port_clash_names_the_port_and_the_option():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        with pytest.raises(OSError, match=rf"port {port} .*already in use.*--my-port"):
            check_port_free("127.0.0.1", port, "--my-port")
    check_port_free("127.0.0.1", 0, "--my-port")
    with pytest.raises(ValueError, match="--my-port must be an int in"):
        check_port_free("127.0.0.1", 70000, "--my-port")


def test_human_render_mode_checks_its_port_at_make():
    pytest.importorskip("viser", reason="needs the [viewer] extra (viser)")
    import gymnasium as gym

    import defgrasp_env  # noqa: F401

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        with pytest.raises(OSError, match=rf"port {port}.*viewer_port"):
            gym.make("DeformablePickup-v0", render_mode="human", viewer_port=port)
    with pytest.raises(ValueError, match="render_mode must be None, 'rgb_array' or 'human'"):
        gym.make("DeformablePickup-v0", render_mode="window")


def test_vector_env_human_mode_draws_the_chosen_world():
    pytest.importorskip("viser", reason="needs the [viewer] extra (viser)")
    import gymnasium as gym

    import defgrasp_env  # noqa: F401

    venv = gym.make_vec("DeformablePickup-v0", num_envs=2, render_mode="human", viewer_world=1, viewer_port=0,
                        object="random", init_yaw_noise=0.0)
    try:
        venv.reset(seed=5)
        venv.step(np.zeros((2, 7)))
        viewer = venv.unwrapped._viewer.viewer
        scene = venv.unwrapped.scene
        assert scene.object_names == ("cylinder", "torus")  # object="random" with seed 5: two different objects
        np.testing.assert_array_equal(viewer.drawing.triangles, scene.mesh(1).surface)  # world 1's torus
        assert viewer.url.startswith("http://127.0.0.1:")
    finally:
        venv.close()
    with pytest.raises(ValueError, match=r"viewer_world must be an int in \[0, 1\], got 2"):
        gym.make_vec("DeformablePickup-v0", num_envs=2, render_mode="human", viewer_world=2, viewer_port=0)
