"""Record episodes straight into a LeRobot (v3.0) dataset during collection.

``LeRobotRecorder`` is a Gymnasium wrapper: every step becomes a LeRobot frame (the observation
before the action, the action, and the step's reward/done/success, the same frame layout as
``to_lerobot``), every ended episode is saved with ``save_episode``, and ``close`` finalizes the
dataset. An episode cut short by ``reset`` or ``close`` is saved too, so nothing recorded is lost.
"""

from __future__ import annotations

import os
import pathlib

import gymnasium as gym

from ..layout import AGENT_POS, ENV_STATE
from .lerobot_export import ROBOT_TYPE, FrameShape, lerobot_features, lerobot_frame, state_columns, task_text


class LeRobotRecorder(gym.Wrapper):
    """Wrap a single ``DeformablePickup-v0`` env (``obs_type`` "state", optionally with camera
    frames from ``render()`` when ``record_frames``) and write a LeRobot dataset at ``root``.
    ``state_fields``: the ``AGENT_POS`` fields ``observation.state`` keeps, as ``to_lerobot``'s
    (default all)."""

    def __init__(self, env: gym.Env, root: str | os.PathLike, repo_id: str | None = None,
                 task: str | None = None, record_frames: bool = False, use_videos: bool = False,
                 state_fields=None):
        super().__init__(env)
        from lerobot.datasets.lerobot_dataset import LeRobotDataset

        cfg = env.unwrapped.config
        if cfg.obs_type != "state":
            raise ValueError(f"LeRobotRecorder needs obs_type='state', got {cfg.obs_type!r}")
        if abs(cfg.control_hz - round(cfg.control_hz)) > 1e-9:
            raise ValueError(f"LeRobot needs an integer fps, the control rate is {cfg.control_hz} Hz")
        root = pathlib.Path(root)
        if root.exists():
            raise FileExistsError(f"{root}: LeRobot dataset folder exists already; choose a new one")
        if record_frames and env.render_mode != "rgb_array":
            raise ValueError("record_frames needs the env made with render_mode='rgb_array'")
        image = (cfg.camera.height, cfg.camera.width, 3) if record_frames else None
        self._columns = state_columns(state_fields)
        layout = FrameShape(int(round(cfg.control_hz)), len(self._columns), ENV_STATE.size, env.action_space.shape[0],
                            image)
        names = {"observations/agent_pos": [AGENT_POS.names[i] for i in self._columns],
                 "observations/environment_state": list(ENV_STATE.names)}
        self.dataset = LeRobotDataset.create(repo_id or f"defgrasp/{root.name}", layout.fps,
                                             lerobot_features(layout, names, use_videos), root=root,
                                             robot_type=ROBOT_TYPE, use_videos=use_videos, video_backend="pyav")
        self._given_task = task  # None: each episode's ``task_text`` (its object, E and goal)
        self.task = task
        self.record_frames = record_frames
        self._obs = None
        self._frame = None
        self._pending = 0
        self.episodes_saved = 0

    def reset(self, **kwargs):
        self._save_pending()
        obs, info = self.env.reset(**kwargs)
        self.task = self._given_task or task_text(info["object"], info["youngs_modulus"], info["goal"])
        self._obs = obs
        self._frame = self.env.render() if self.record_frames else None
        return obs, info

    def step(self, action):
        if self._obs is None:
            raise RuntimeError("call reset() before step()")
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.dataset.add_frame(lerobot_frame(self._obs["agent_pos"][self._columns], self._obs["environment_state"],
                                             action, reward,
                                             terminated or truncated, bool(info.get("is_success", False)),
                                             self.task, self._frame))
        self._pending += 1
        self._obs = obs
        self._frame = self.env.render() if self.record_frames else None
        if terminated or truncated:
            self._save_pending()
        return obs, reward, terminated, truncated, info

    def close(self):
        try:
            self._save_pending()
            self.dataset.finalize()
        finally:
            super().close()

    def _save_pending(self) -> None:
        if self._pending:
            self.dataset.save_episode()
            self.episodes_saved += 1
            self._pending = 0
