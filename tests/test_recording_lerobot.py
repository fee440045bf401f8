"""to-lerobot through LeRobot's own API (loads with LeRobotDataset + DataLoader, values equal), and the
Fig. 5 plot."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from test_recording_helpers import record_episodes

from defgrasp_env.recording import load_episode, plot_episode, to_lerobot
from defgrasp_env.recording.cli import main as dataset_cli


@pytest.fixture(scope="module")
def episodes(tmp_path_factory):
    from defgrasp_env.render.camera import Camera

    d = tmp_path_factory.mktemp("episodes")
    record_episodes(d, seeds=(0, 1), steps=6, record_frames=True, render_mode="rgb_array",
                    camera=Camera(width=32, height=24))
    return d


def test_to_lerobot_loads_and_matches_hdf5(episodes, tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    assert dataset_cli(["to-lerobot", str(episodes), str(tmp_path / "lr")]) == 0
    ds = LeRobotDataset("defgrasp/lr", root=tmp_path / "lr")
    eps = [load_episode(p) for p in sorted(episodes.glob("*.h5"))]
    assert ds.meta.fps == 20 and ds.meta.total_episodes == 2 and len(ds) == sum(e.num_steps for e in eps)
    assert {"observation.state", "observation.environment_state", "action", "next.reward", "next.done",
            "observation.images.camera"} <= set(ds.features)
    loader = torch.utils.data.DataLoader(ds, batch_size=4, shuffle=False)
    rows = {k: [] for k in ("observation.state", "observation.environment_state", "action", "next.reward",
                            "next.done", "observation.images.camera")}
    tasks = []
    for batch in loader:
        for k in rows:
            rows[k].append(batch[k])
        tasks += batch["task"]
    got = {k: torch.cat(v).numpy() for k, v in rows.items()}
    want_state = np.concatenate([e["observations/agent_pos"][:-1] for e in eps])
    want_env = np.concatenate([e["observations/environment_state"][:-1] for e in eps])
    want_action = np.concatenate([e["steps/action"] for e in eps])
    want_reward = np.concatenate([e["steps/reward"] for e in eps])
    want_done = np.concatenate([e["steps/terminated"] | e["steps/truncated"] for e in eps])
    want_pixels = np.concatenate([e["observations/pixels"][:-1] for e in eps])
    np.testing.assert_allclose(got["observation.state"], want_state, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(got["observation.environment_state"], want_env, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(got["action"], want_action, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(got["next.reward"].reshape(-1), want_reward, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(got["next.done"].reshape(-1), want_done)
    images = np.round(got["observation.images.camera"].transpose(0, 2, 3, 1) * 255).astype(np.uint8)
    np.testing.assert_array_equal(images, want_pixels)
    assert set(tasks) == {"Pick up the cuboid (E = 1e+05 Pa) and lift it to [0, 0.6, 0] m"}


def test_to_lerobot_refuses_an_existing_destination(episodes, tmp_path):
    dst = tmp_path / "exists"
    dst.mkdir()
    (dst / "keep.txt").write_text("mine")
    with pytest.raises(FileExistsError, match="exists"):
        to_lerobot(episodes, dst)
    assert (dst / "keep.txt").read_text() == "mine"


def test_plot_writes_the_four_fig5_panels(episodes, tmp_path):
    import matplotlib.image

    ep = sorted(episodes.glob("*.h5"))[0]
    out = plot_episode(ep, tmp_path / "fig5.png")
    img = matplotlib.image.imread(out)
    assert img.shape[0] > 500 and img.shape[1] > 500
    assert dataset_cli(["plot", str(ep), "-o", str(tmp_path / "cli.png")]) == 0
    assert (tmp_path / "cli.png").stat().st_size > 10_000
    with pytest.raises(ValueError, match="png"):
        plot_episode(ep, tmp_path / "fig5.pdf")


def test_to_lerobot_state_fields_keep_those_columns_and_names(episodes, tmp_path):
    """``--state-fields`` writes ``observation.state`` as the chosen agent_pos columns of the files
    (the wrist orientation left out here), named by the layout; unknown fields are refused before
    anything is written."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from defgrasp_env.layout import AGENT_POS

    fields = ["wrist_position", "jaw_gap", "tip_normal_force"]
    assert dataset_cli(["to-lerobot", str(episodes), str(tmp_path / "lr"), "--state-fields", *fields]) == 0
    ds = LeRobotDataset("defgrasp/lr", root=tmp_path / "lr")
    assert ds.features["observation.state"]["shape"] == (6,)
    assert ds.features["observation.state"]["names"] == ["wrist_x", "wrist_y", "wrist_z", "jaw_gap",
                                                         "left_tip_normal_force", "right_tip_normal_force"]
    got = torch.cat([b["observation.state"] for b in torch.utils.data.DataLoader(ds, batch_size=8)]).numpy()
    full = np.concatenate([load_episode(p)["observations/agent_pos"][:-1] for p in sorted(episodes.glob("*.h5"))])
    keep = [AGENT_POS.names.index(n) for n in ds.features["observation.state"]["names"]]
    np.testing.assert_array_equal(got, full[:, keep].astype(np.float32))  # float32 columns, stored exactly
    with pytest.raises(ValueError, match="unknown: \\['wrist_yaw'\\]"):
        to_lerobot(episodes, tmp_path / "bad", state_fields=["wrist_position", "wrist_yaw"])
    assert not (tmp_path / "bad").exists()
