"""Per-step readouts of the env (feature point and velocity, keypoints, finiteness per world): the
Warp kernels on the simulation's device (``SceneReadouts.compute``, what ``PickupScene.readout``
runs once per state) versus the host numpy reductions
of the full state they replaced (feature points twice: reward and observation, as the env did).

    .venv/bin/python benchmarks/bench_readouts.py [--worlds 1 64 1024] [--repeats 20]

The scene is built and reset with seeded random objects (no solver step: the readouts' cost does
not depend on the state's values). Prints the median and p95 per call; nothing is appended (a
diagnosis beside bench_vector_env.py / profile_vector_step.py).
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from defgrasp_env.envs.common import draw_setup  # noqa: E402
from defgrasp_env.envs.readouts import SceneReadouts  # noqa: E402
from defgrasp_env.envs.config import PickupConfig  # noqa: E402
from defgrasp_env.envs.scene import PickupScene, keypoint_indices  # noqa: E402
from defgrasp_env.layout import NUM_KEYPOINTS  # noqa: E402


def host_readouts(scene, keypoints):
    """The numpy path the env used before: two feature-point reductions, a per-world keypoint loop,
    finiteness over every node (each a full-state download on a GPU)."""
    for _ in range(2):
        x, v = scene.state.positions.numpy(), scene.state.velocities.numpy()
        starts = scene.model.node_start
        counts = np.diff(starts)
        np.add.reduceat(x.astype(np.float64), starts[:-1], axis=0) / counts[:, None]
        np.add.reduceat(v.astype(np.float64), starts[:-1], axis=0) / counts[:, None]
    x = scene.state.positions.numpy()
    out = np.zeros((scene.num_worlds, NUM_KEYPOINTS, 3))
    for w in range(scene.num_worlds):
        idx = keypoints[w] + scene.model.node_start[w]
        out[w, : len(idx)] = x[idx]
    x, v = scene.state.positions.numpy(), scene.state.velocities.numpy()
    bad = ~(np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1))
    return np.add.reduceat(bad.astype(int), scene.model.node_start[:-1]) == 0


def _time(fn, repeats):
    t = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        t.append(time.perf_counter() - t0)
    return 1e3 * np.median(t), 1e3 * np.percentile(t, 95)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--worlds", type=int, nargs="+", default=[1, 64, 1024])
    p.add_argument("--repeats", type=int, default=20)
    args = p.parse_args(argv)
    wp.config.quiet = True
    config = PickupConfig(object="random")
    print("| W | nodes | host numpy median / p95 ms | device kernels median / p95 ms | load |")
    print("|---|---|---|---|---|")
    for w in args.worlds:
        rng = np.random.default_rng(0)
        scene = PickupScene(config, [draw_setup(config, rng) for _ in range(w)], slotted=False)  # the packed rows the baseline reduces
        keys = [keypoint_indices(scene.mesh(i).nodes, scene.mesh(i).surface) for i in range(w)]
        host = _time(lambda: host_readouts(scene, keys), args.repeats)
        readouts = SceneReadouts(scene.model, [scene.state], keys)
        dev = _time(lambda: readouts.compute(scene.state), args.repeats)
        print(f"| {w} | {scene.model.num_nodes} | {host[0]:.2f} / {host[1]:.2f} | {dev[0]:.2f} / {dev[1]:.2f} "
              f"| {os.getloadavg()[0]:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
