"""Re-simulate a recorded episode from its config, reset seed/RNG state and actions.

On CPU the simulation is deterministic, so a replay reproduces the recorded node positions bit for
bit. The env builds its rest shape from the setup of the reset that created its scene, so the
recorder stores that reset too (``scene_origin``) and the replay performs it first.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np

from ..envs.replay_spec import reset_from_json
from .reader import Episode, EpisodeFileError, load_episode


@dataclass
class ReplayResult:
    """Outcome of a replay. ``bit_exact``: every recorded step was replayed and every node position,
    reward and flag matches exactly; a replay that ends before the recording is never bit-exact."""

    path: str
    num_steps: int                             # steps in the recording
    replayed_steps: int                        # steps the replay ran (fewer if the env ended first)
    bit_exact: bool
    max_position_error: float                  # m, over all replayed steps and nodes
    first_mismatch_step: int | None            # first step whose node positions differ
    flags_match: bool                          # rewards, terminated and truncated all equal
    warnings: list[str] = field(default_factory=list)

    @property
    def complete(self) -> bool:
        return self.replayed_steps == self.num_steps

    def text(self) -> str:
        if self.first_mismatch_step is not None:
            positions = (f"DIFFER from step {self.first_mismatch_step} "
                         f"(max node position error {self.max_position_error:.3e} m)")
        else:
            positions = "match bit for bit" if self.complete else "match bit for bit so far"
        head = "" if self.complete else "PARTIAL replay: "
        verdict = "bit-exact" if self.bit_exact else "NOT exact"
        lines = [f"{self.path}: {head}{self.replayed_steps} of {self.num_steps} steps replayed; node positions "
                 f"{positions}; rewards/flags {'match' if self.flags_match else 'DIFFER'}; {verdict}"]
        return "\n".join(lines + [f"  warning: {w}" for w in self.warnings])


def make_replay_env(episode: Episode, device: str | None = None, **kwargs) -> gym.Env:
    """A fresh env with the episode's config (and time limit), reset exactly as when recorded."""
    cfg = episode.config
    if device is not None:
        cfg = dataclasses.replace(cfg, device=device)
    replay = episode.replay
    limit = replay.get("max_episode_steps")
    env = gym.make(episode.attrs["env_id"], config=cfg, **({"max_episode_steps": limit} if limit else {}), **kwargs)
    origin = replay.get("scene_origin")
    if origin is not None and not origin.get("unknown"):  # "unknown": schema-1 files of older recorders
        reset_from_json(env, origin)
    reset_from_json(env, replay)
    return env


def replay_episode(path: str | os.PathLike | Episode, device: str | None = None) -> ReplayResult:
    """Replay an episode file and compare the node positions of every step with the recorded ones."""
    ep = path if isinstance(path, Episode) else load_episode(path)
    replay = ep.replay
    warnings = []
    origin = replay.get("scene_origin")
    if origin is not None and origin.get("unknown"):
        warnings.append("the env's scene was built by a reset before recording started; "
                        "the replay may differ in the last bits")
    import defgrasp_env  # noqa: F401  (registers the env id)

    env = make_replay_env(ep, device)
    try:
        setup = env.unwrapped.scene.setups[0]
        if not np.array_equal(setup.position, ep["object/initial_position"]):
            raise EpisodeFileError(f"{ep.path}: replayed reset gives initial position {setup.position.tolist()}, "
                                   f"recorded {ep['object/initial_position'].tolist()}")
        if "task/goal" in ep.data and not np.array_equal(setup.goal, ep["task/goal"]):
            raise EpisodeFileError(f"{ep.path}: replayed reset gives the goal {setup.goal.tolist()}, "
                                   f"recorded {ep['task/goal'].tolist()}")
        recorded = ep["steps/node_positions"]
        actions = ep["steps/action"]
        max_err, first, flags_ok, replayed = 0.0, None, True, 0
        for k, action in enumerate(actions):
            _, reward, terminated, truncated, _ = env.step(action)
            replayed = k + 1
            scene = env.unwrapped.scene
            x = scene.state.positions.numpy()[scene.model.world_nodes(0)]
            if not np.array_equal(x, recorded[k]):
                first = k if first is None else first
                max_err = max(max_err, float(np.nanmax(np.abs(x.astype(np.float64) - recorded[k]))))
            flags_ok &= bool(reward == ep["steps/reward"][k] and terminated == ep["steps/terminated"][k]
                             and truncated == ep["steps/truncated"][k])
            if (terminated or truncated) and k < len(actions) - 1:
                warnings.append(f"the replayed episode ended at step {k}, the recording has {len(actions)} steps")
                break
    finally:
        env.close()
    complete = replayed == len(actions)
    return ReplayResult(str(ep.path), len(actions), replayed, bool(complete and first is None and flags_ok),
                        max_err, first, bool(flags_ok), warnings)
