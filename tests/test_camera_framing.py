"""Cameras for learning: the default frame holds the whole task, and RecordVideo writes a playable mp4."""

from __future__ import annotations

import itertools

import gymnasium as gym
import numpy as np
import pytest

import defgrasp_env  # noqa: F401
from defgrasp_env.render import Camera
from defgrasp_env.sim.meshing import OBJECT_SHAPES, make_object_mesh
from defgrasp_env.transforms import quat_to_matrix

MARGIN_PX = 2.0


def _inside(cam: Camera, points: np.ndarray) -> bool:
    uv, depth = cam.project(points)
    return bool(np.all(depth > 0) and np.all(uv >= MARGIN_PX) and np.all(uv[:, 0] <= cam.width - MARGIN_PX)
                and np.all(uv[:, 1] <= cam.height - MARGIN_PX))


@pytest.mark.parametrize("name", sorted(OBJECT_SHAPES))
@pytest.mark.parametrize("size", [(224, 224), (480, 480), (640, 480)])
def test_default_framing_holds_every_object_on_the_ground_and_at_the_goal(name, size):
    """Rest meshes at any yaw on the ground (with the env's 2 cm position noise), and lifted so that
    the feature point is at the goal, upright or hanging: every node projects inside the image."""
    cam = Camera(width=size[0], height=size[1])
    nodes = make_object_mesh(name).nodes
    for yaw, dx, dz in itertools.product(np.linspace(0, np.pi, 7), (-0.02, 0.02), (-0.02, 0.02)):
        q = np.array([0.0, np.sin(yaw / 2), 0.0, np.cos(yaw / 2)])
        ground = nodes @ quat_to_matrix(q).T + [dx, 0.0, dz]
        assert _inside(cam, ground), (name, yaw)
        held = ground - ground.mean(axis=0) + [0.0, 0.6, 0.0]
        assert _inside(cam, held), (name, yaw)
        # held at its middle and folded down over the pads (the rope: 0.52 .. 0.68 m)
        hanging = held.copy()
        hanging[:, 1] = 0.68 - np.hypot(held[:, 0] - held[:, 0].mean(), held[:, 2] - held[:, 2].mean())
        assert _inside(cam, hanging), (name, yaw)


@pytest.mark.parametrize("name", ["cuboid", "rope"])
def test_held_object_at_the_goal_is_inside_the_rendered_frame(name):
    """The expert lifts the object to the goal; all its nodes project inside the default 224 x 224
    frame (the rope, held at its middle, was cut at the top by the old framing), and the image
    there shows the object (its blue)."""
    from defgrasp_env.policies import RECOMMENDED_ENV_KWARGS, ScriptedPickupExpert

    env = gym.make("DeformablePickup-v0", object=name, youngs_modulus=1e5, render_mode="rgb_array",
                   **RECOMMENDED_ENV_KWARGS)
    expert = ScriptedPickupExpert.from_env(env)
    obs, _ = env.reset(seed=2)
    expert.reset()
    for _ in range(300):
        obs, _, terminated, truncated, info = env.step(expert(obs))
        if terminated or truncated:
            break
    assert info["is_success"], f"the expert should hold the {name} at the goal"
    scene = env.unwrapped.scene
    cam = env.unwrapped.config.camera
    nodes = scene.node_positions(0)
    assert np.linalg.norm(nodes.mean(axis=0) - [0, 0.6, 0]) < 0.05
    assert _inside(cam, nodes)
    img = env.render()
    uv, _ = cam.project(nodes)
    c0, r0 = np.floor(uv.min(axis=0)).astype(int)
    c1, r1 = np.ceil(uv.max(axis=0)).astype(int)
    if name == "cuboid":  # a 4 cm cube spans ~15 px at 224 px
        assert 8 <= r1 - r0 <= 30 and 8 <= c1 - c0 <= 30, (r0, r1, c0, c1)
    patch = img[r0:r1 + 1, c0:c1 + 1].astype(int)
    blue = (patch[..., 2] > patch[..., 0] + 40).mean()  # the object's colour is blue; sky and pads are not this blue
    assert blue > 0.1, blue
    env.close()


def test_record_video_writes_a_playable_mp4(tmp_path):
    pytest.importorskip("moviepy", reason="needs the [video] extra")
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    from gymnasium.wrappers import RecordVideo

    env = gym.make("DeformablePickup-v0", render_mode="rgb_array", camera=Camera(width=160, height=128))
    env = RecordVideo(env, str(tmp_path), episode_trigger=lambda i: True, name_prefix="pickup")
    env.reset(seed=0)
    for _ in range(12):
        env.step(env.action_space.sample() * 0 + np.array([0, -1, 0, 0, 0, 0, 1.0]))
    env.close()
    (mp4,) = sorted(tmp_path.glob("*.mp4"))
    reader = imageio_ffmpeg.read_frames(str(mp4))  # decoded by ffmpeg: the file is a playable video
    meta = next(reader)
    assert tuple(meta["size"]) == (160, 128)
    frames = [np.frombuffer(b, np.uint8).reshape(128, 160, 3) for b in reader]
    assert len(frames) == 13  # the reset frame and one per step
    assert np.abs(frames[0].astype(int) - frames[-1].astype(int)).max() > 30  # the gripper moved
