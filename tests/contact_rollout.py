"""Actions of a three-world batch that drives the contact and the force limit from every side: the
scripted expert, the expert with noise, and a world closing over the object and pressing it into
the ground at full speed (its wrist at the force limit: first tries over the limit, retries,
patient re-solves). Shared by the tests that compare two ways of stepping the same batch."""

from __future__ import annotations

import numpy as np

from defgrasp_env.policies import ScriptedPickupExpert


class ExpertNoisyPress:
    """``actions(obs)`` [3, 7] float32 for a 3-world vector env (seeded noise); ``episodes_ended``
    restarts the expert's script in the worlds whose episode ended."""

    def __init__(self, env, seed: int = 0):
        self.expert = ScriptedPickupExpert.from_env(env)
        self.expert.reset()
        self.rng = np.random.default_rng(seed)

    def actions(self, obs) -> np.ndarray:
        action = self.expert(obs)
        action[1] = np.clip(action[1] + self.rng.normal(0.0, 0.5, action[1].shape), -1.0, 1.0)
        action[2, :3] = [0.0, -1.0, 0.0]
        action[2, -1] = 1.0
        return action.astype(np.float32)

    def episodes_ended(self, terminated, truncated) -> None:
        self.expert.reset(np.asarray(terminated) | np.asarray(truncated))


def rollout_outputs(env, obs, steps: int, state_rows, seed: int = 0) -> dict:
    """``steps`` steps of a 3-world vector env from its reset observation ``obs`` with
    ``ExpertNoisyPress(env, seed)`` (restarted where episodes end): every observation, reward and
    (array-valued) info entry per step, the final state's ``state_rows`` arrays and the scene's
    ``world_solves``, by name: what two ways of stepping the same batch must agree on."""
    policy = ExpertNoisyPress(env, seed=seed)
    out = {}
    for k in range(steps):
        obs, reward, terminated, truncated, info = env.step(policy.actions(obs))
        policy.episodes_ended(terminated, truncated)
        out.update({f"{k}/obs/{name}": np.asarray(v) for name, v in obs.items()})
        out[f"{k}/reward"] = np.asarray(reward)
        out.update({f"{k}/info/{name}": np.asarray(v) for name, v in info.items() if not isinstance(v, dict)})
    scene = env.unwrapped.scene
    for name in state_rows:
        out[f"state/{name}"] = getattr(scene.state, name).numpy().copy()
    out["world_solves"] = np.array(scene.world_solves)
    return out
