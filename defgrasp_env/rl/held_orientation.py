"""``HeldOrientationActions``: a Stable-Baselines3 VecEnv wrapper whose actions move the wrist
without turning it.

A top-down pick needs the flange's position and the jaw; its 3 rotation rates only let an
exploring policy tumble the gripper. The wrapper gives the learner a Box [-1, 1]^4: flange linear
velocity (3, x ``max_linear_speed`` m/s, world frame) and the jaw command (1), placed into the
env's ``DELTA_ACTION`` [7] with zero angular velocity, so the wrist keeps its start orientation
(pointing down). The same restriction as ManiSkill's ``pd_ee_delta_pos`` controller.

    venv = HeldOrientationActions(SB3VectorEnv(gym.make_vec("DeformablePickup-v0", num_envs=N,
                                                              autoreset_mode="SameStep")))
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnvWrapper

from ..layout import DELTA_ACTION

__all__ = ["HeldOrientationActions"]

_KEPT = ("linear_velocity", "jaw")


class HeldOrientationActions(VecEnvWrapper):
    """Actions [N, 4] (linear velocity 3, jaw 1, all in [-1, 1]) -> ``DELTA_ACTION`` [N, 7] with zero
    angular velocity, for a VecEnv with the env's delta action space."""

    def __init__(self, venv):
        inner = venv.action_space
        if not isinstance(inner, spaces.Box) or inner.shape != (DELTA_ACTION.size,):
            raise ValueError(f"the wrapped env must take DELTA_ACTION [{DELTA_ACTION.size}] actions "
                             f"(action_mode='delta'), got {inner}")
        self._columns = np.concatenate([np.arange(DELTA_ACTION.size)[DELTA_ACTION.slice(n)] for n in _KEPT])
        size = len(self._columns)
        super().__init__(venv, action_space=spaces.Box(-1.0, 1.0, (size,), np.float32))

    def full_actions(self, actions: np.ndarray) -> np.ndarray:
        """The env's ``DELTA_ACTION`` [N, 7] float32 for actions [N, 4] (angular velocity 0)."""
        a = np.asarray(actions, np.float32)
        if a.shape != (self.num_envs, len(self._columns)):
            raise ValueError(f"actions must have shape ({self.num_envs}, {len(self._columns)}), got {a.shape}")
        full = np.zeros((self.num_envs, DELTA_ACTION.size), np.float32)
        full[:, self._columns] = a
        return full

    def step_async(self, actions: np.ndarray) -> None:
        self.venv.step_async(self.full_actions(actions))

    def step_wait(self):
        return self.venv.step_wait()

    def reset(self):
        return self.venv.reset()
