"""The paper's Fig. 5 panels for one episode, as a PNG (matplotlib, Agg backend).

a) height of the object feature point P_feature (mean node position, eq. 5) and of the gripper
   (wrist flange), with the gripper approach axis as arrows; b) normal force on the left and right
   tip, N; c) mean von Mises stress, kPa; d) distance between the gripper tips (jaw length D), mm.
"""

from __future__ import annotations

import os
import pathlib

import numpy as np

from ..transforms import quat_rotate
from .reader import load_episode

_KEYS = ("steps/time", "steps/node_positions", "steps/wrist_position", "steps/wrist_orientation",
         "steps/left_tip_normal_force", "steps/right_tip_normal_force", "steps/mean_von_mises",
         "steps/jaw_length")
ARROWS = 12


def plot_episode(episode: str | os.PathLike, out: str | os.PathLike | None = None, dpi: int = 120) -> pathlib.Path:
    """Draw the four Fig. 5 panels of ``episode`` into ``out`` (default: next to it, ``.png``)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    ep = load_episode(episode, _KEYS)
    out = pathlib.Path(out) if out is not None else ep.path.with_suffix(".png")
    if out.suffix.lower() != ".png":
        raise ValueError(f"{out}: plot output must be a .png file")
    if not out.parent.is_dir():
        raise FileNotFoundError(f"{out.parent}: output folder does not exist")
    t = ep["steps/time"]
    feature = ep.feature_points()
    wrist = ep["steps/wrist_position"]
    approach = quat_rotate(ep["steps/wrist_orientation"], np.array([0.0, -1.0, 0.0]))

    fig, axes = plt.subplots(4, 1, figsize=(7, 9), sharex=True, constrained_layout=True)
    ax = axes[0]
    ax.plot(t, feature[:, 1], label="object feature point")
    ax.plot(t, wrist[:, 1], label="gripper (wrist flange)")
    idx = np.unique(np.linspace(0, len(t) - 1, min(ARROWS, len(t))).astype(int))
    ax.quiver(t[idx], wrist[idx, 1], approach[idx, 0], approach[idx, 1], angles="uv", color="0.3",
              width=0.004, scale=25, label="gripper approach axis (x, y)")
    ax.set_ylabel("height [m]")
    ax.legend(loc="best", fontsize="small")
    ax.set_title(f"a) {ep.path.name}: heights and gripper orientation", fontsize="medium", loc="left")
    axes[1].plot(t, ep["steps/left_tip_normal_force"], label="left tip")
    axes[1].plot(t, ep["steps/right_tip_normal_force"], label="right tip")
    axes[1].set_ylabel("normal force [N]")
    axes[1].legend(loc="best", fontsize="small")
    axes[1].set_title("b) contact forces", fontsize="medium", loc="left")
    axes[2].plot(t, ep["steps/mean_von_mises"] / 1e3)
    axes[2].set_ylabel("mean von Mises [kPa]")
    axes[2].set_title("c) mean von Mises stress", fontsize="medium", loc="left")
    axes[3].plot(t, ep["steps/jaw_length"] * 1e3)
    axes[3].set_ylabel("jaw length D [mm]")
    axes[3].set_xlabel("time [s]")
    axes[3].set_title("d) distance between the gripper tips", fontsize="medium", loc="left")
    for a in axes:
        a.grid(True, alpha=0.3)
    fig.savefig(out, dpi=dpi)
    plt.close(fig)
    return out
