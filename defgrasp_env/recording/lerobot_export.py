"""Convert episode files to a LeRobot (v3.0) dataset through LeRobot's own ``LeRobotDataset`` API.

Frame ``k`` of an episode = observation before action ``k`` (``observations/*[k]``), action ``k``,
and what step ``k`` returned (``next.reward``, ``next.done`` = terminated or truncated,
``next.success``). ``fps`` is the control rate. Images go in when the episodes hold camera frames.
:func:`lerobot_frame` builds that frame and :func:`lerobot_features` its feature dict, for this
export and for ``LeRobotRecorder`` alike.
"""

from __future__ import annotations

import os
import pathlib
import shutil
from dataclasses import dataclass, replace

import numpy as np

from ..layout import ACTION_LAYOUTS, AGENT_POS, ENV_STATE
from .reader import Episode, episode_paths, load_episode

ROBOT_TYPE = "robotiq_2f85_on_6dof_wrist"
CAMERA_KEY = "observation.images.camera"
_KEYS = ("observations/agent_pos", "observations/environment_state", "observations/pixels", "steps/action",
         "steps/reward", "steps/terminated", "steps/truncated", "steps/is_success", "object/youngs_modulus", "task/goal")


def task_text(object_name: str, youngs_modulus: float, goal) -> str:
    """The language task of an episode of ``object_name`` (a name or mesh path) at E
    ``youngs_modulus`` (Pa) with its goal ``goal`` [3] (m), e.g. 'Pick up the cuboid (E = 1e+05 Pa)
    and lift it to [0, 0.6, 0] m' (the export's and ``LeRobotRecorder``'s default)."""
    name = pathlib.Path(object_name).stem
    return (f"Pick up the {name} (E = {float(youngs_modulus):.0e} Pa) "
            f"and lift it to [{', '.join(f'{float(g):g}' for g in goal)}] m")


def default_task(ep: Episode) -> str:
    """The language task of an episode file (``task_text`` of its object, E and goal)."""
    import json

    goal = ep["task/goal"] if "task/goal" in ep.data else json.loads(ep.attrs["config_json"])["goal"]
    return task_text(ep.attrs["object_name"], ep["object/youngs_modulus"], goal)


@dataclass(frozen=True)
class FrameShape:
    """Sizes of a LeRobot frame: fps (Hz), agent_pos, environment_state and action lengths, and the
    camera image [H, W, 3] (None: no camera)."""

    fps: int
    state_dim: int
    env_dim: int
    action_dim: int
    image_shape: tuple[int, int, int] | None


def _frame_shape(episodes: list[Episode]) -> FrameShape:
    first = episodes[0]
    for key in ("observations/agent_pos", "observations/environment_state"):
        if key not in first:
            raise ValueError(f"{first.path}: has no {key!r} (recorded with obs_type other than 'state'?); "
                             "LeRobot export needs agent_pos and environment_state")
    hz = float(first.attrs["control_hz"])
    if abs(hz - round(hz)) > 1e-9:
        raise ValueError(f"{first.path}: LeRobot needs an integer fps, the control rate is {hz} Hz")
    pix = first.data.get("observations/pixels")
    layout = FrameShape(int(round(hz)), first["observations/agent_pos"].shape[1],
                     first["observations/environment_state"].shape[1], first["steps/action"].shape[1],
                     None if pix is None else tuple(pix.shape[1:]))
    for ep in episodes[1:]:
        pix = ep.data.get("observations/pixels")
        other = FrameShape(int(round(float(ep.attrs["control_hz"]))),
                        ep["observations/agent_pos"].shape[1] if "observations/agent_pos" in ep else -1,
                        ep["observations/environment_state"].shape[1] if "observations/environment_state" in ep else -1,
                        ep["steps/action"].shape[1], None if pix is None else tuple(pix.shape[1:]))
        if other != layout:
            raise ValueError(f"{ep.path}: layout {other} differs from {first.path}: {layout}; "
                             "convert episodes with equal rates, observation/action sizes and cameras together")
    return layout


def state_columns(state_fields=None) -> np.ndarray:
    """Indices (int [n]) of the ``agent_pos`` entries ``observation.state`` keeps: those of the
    ``AGENT_POS`` fields ``state_fields`` (in the layout's order), all of them when None."""
    return np.arange(AGENT_POS.size) if state_fields is None else AGENT_POS.columns(state_fields)


def _layout_names(key: str, n: int) -> list[str] | None:
    """Column names of dataset ``key`` with ``n`` columns from ``defgrasp_env.layout`` (None: no fit)."""
    layouts = {"observations/agent_pos": (AGENT_POS,), "observations/environment_state": (ENV_STATE,),
               "steps/action": tuple(ACTION_LAYOUTS.values())}
    return next((list(v.names) for v in layouts.get(key, ()) if v.size == n), None)


def lerobot_features(layout: FrameShape, names: dict, use_videos: bool) -> dict:
    """LeRobot feature dict of frames of ``layout``; ``names``: dataset key -> column names (from the
    episode files); where they are missing or do not fit, those of ``defgrasp_env.layout``, else
    generic names."""

    def vec(n, key):
        feature_names = names.get(key)
        if not feature_names or len(feature_names) != n:
            feature_names = _layout_names(key, n) or [f"{key.split('/')[-1]}_{i}" for i in range(n)]
        return {"dtype": "float32", "shape": (n,), "names": list(feature_names)}

    features = {
        "observation.state": vec(layout.state_dim, "observations/agent_pos"),
        "observation.environment_state": vec(layout.env_dim, "observations/environment_state"),
        "action": vec(layout.action_dim, "steps/action"),
        "next.reward": {"dtype": "float32", "shape": (1,), "names": None},
        "next.done": {"dtype": "bool", "shape": (1,), "names": None},
        "next.success": {"dtype": "bool", "shape": (1,), "names": None},
    }
    if layout.image_shape is not None:
        features[CAMERA_KEY] = {"dtype": "video" if use_videos else "image", "shape": layout.image_shape,
                                "names": ["height", "width", "channel"]}
    return features


def to_lerobot(src: str | os.PathLike, dst: str | os.PathLike, repo_id: str | None = None,
               task: str | None = None, use_videos: bool = False, progress: bool = False,
               state_fields=None):
    """Convert the episode file(s) at ``src`` (file or directory) into a new LeRobot dataset at ``dst``.

    Args:
        dst: dataset root; must not exist yet (nothing is overwritten); removed again if conversion fails.
        repo_id: LeRobot repo id (default ``defgrasp/<dst name>``).
        task: task string for every frame (default: :func:`default_task` per episode).
        use_videos: store images as MP4 (needs a working video encoder); default PNG images.
        state_fields: the ``AGENT_POS`` fields ``observation.state`` keeps (names, e.g.
            ``["wrist_position", "jaw_gap", "tip_normal_force"]``; kept in the layout's order);
            default all. A policy trained on such a dataset is evaluated with the same
            ``DefgraspEnvConfig.state_fields`` (``--env.state_fields``).

    Returns:
        The finalized ``LeRobotDataset``.
    """
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    paths = episode_paths(src)
    if not paths:
        raise FileNotFoundError(f"{src}: no episode files (*.h5) to convert")
    dst = pathlib.Path(dst)
    if dst.exists():
        raise FileExistsError(f"{dst}: LeRobot dataset folder exists already; choose a new one (nothing was changed)")
    episodes = [load_episode(p, _KEYS, missing_ok=True) for p in paths]
    layout = _frame_shape(episodes)
    names = dict(episodes[0].names)
    columns = None
    if state_fields is not None:
        columns = state_columns(state_fields)
        if layout.state_dim != AGENT_POS.size:
            raise ValueError(f"{episodes[0].path}: agent_pos has {layout.state_dim} columns, not AGENT_POS's "
                             f"{AGENT_POS.size}; state_fields selects AGENT_POS fields")
        layout = replace(layout, state_dim=len(columns))
        names["observations/agent_pos"] = [AGENT_POS.names[i] for i in columns]
    repo_id = repo_id or f"defgrasp/{dst.name}"
    features = lerobot_features(layout, names, use_videos)
    ds = LeRobotDataset.create(repo_id, layout.fps, features, root=dst, robot_type=ROBOT_TYPE,
                               use_videos=use_videos, video_backend="pyav")
    try:
        for ep in _progress(episodes, progress):
            _add_episode(ds, ep, task or default_task(ep), columns)
        ds.finalize()
    except BaseException:
        ds.finalize()
        shutil.rmtree(dst, ignore_errors=True)
        raise
    return ds


def _progress(items, enabled: bool):
    if not enabled:
        return items
    from tqdm import tqdm

    return tqdm(items, desc="to-lerobot", unit="episode")


def _add_episode(ds, ep: Episode, task: str, columns: np.ndarray | None) -> None:
    t = ep.num_steps
    state = ep["observations/agent_pos"].astype(np.float32)
    if columns is not None:
        state = state[:, columns]
    env_state = ep["observations/environment_state"].astype(np.float32)
    action = ep["steps/action"].astype(np.float32)
    reward = ep["steps/reward"].astype(np.float32)
    done = ep["steps/terminated"] | ep["steps/truncated"]
    success = ep["steps/is_success"]
    pixels = ep.data.get("observations/pixels")
    for k in range(t):
        ds.add_frame(lerobot_frame(state[k], env_state[k], action[k], reward[k], done[k], success[k], task,
                                   None if pixels is None else pixels[k]))
    ds.save_episode()


def lerobot_frame(agent_pos, environment_state, action, reward, done, success, task: str, image=None) -> dict:
    """One LeRobot frame: the observation before the action (``agent_pos`` [10], ``environment_state``
    [33], layouts of ``defgrasp_env.layout``), the action, and what the step returned (reward,
    done = terminated or truncated, success); ``image`` [H, W, 3] uint8 or None."""
    frame = {
        "observation.state": np.asarray(agent_pos, np.float32),
        "observation.environment_state": np.asarray(environment_state, np.float32),
        "action": np.asarray(action, np.float32),
        "next.reward": np.asarray(reward, np.float32).reshape(1),
        "next.done": np.asarray(done, bool).reshape(1),
        "next.success": np.asarray(success, bool).reshape(1),
        "task": task,
    }
    if image is not None:
        frame[CAMERA_KEY] = image
    return frame
