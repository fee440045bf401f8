"""``ActionSubset``: a Stable-Baselines3 VecEnv wrapper whose policy controls some of the env's
``DELTA_ACTION`` components; the others stay zero.

A top-down pick needs the flange's position, the jaw and, for objects that are not round, the
yaw (the turn about the vertical, to close across an object's faces or across a rope); the
other two rotation rates only let an exploring policy tumble the gripper. The named subsets:

* ``POSITION_JAW`` (4): flange linear velocity (x ``max_linear_speed`` m/s, world frame) and the
  jaw command: the wrist keeps its start orientation (pointing down), like ManiSkill's
  ``pd_ee_delta_pos`` controller;
* ``POSITION_YAW_JAW`` (5): also ``wy``, the angular velocity about the world's vertical y axis
  (x ``max_angular_speed`` rad/s): the wrist points down and turns about the vertical.

``ACTION_SETS`` names them (and "full"); ``policy_transfer.transfer_policy`` starts a policy of
one set from a trained policy of another.

    venv = ActionSubset(SB3VectorEnv(gym.make_vec("DeformablePickup-v0", num_envs=N,
                                                  autoreset_mode="SameStep")), POSITION_YAW_JAW)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnvWrapper

from ..layout import DELTA_ACTION

__all__ = ["ACTION_SETS", "ActionSubset", "POSITION_JAW", "POSITION_YAW_JAW", "action_columns"]

#: Wrist position and jaw (``DELTA_ACTION`` component names, in the policy's order).
POSITION_JAW = ("vx", "vy", "vz", "jaw")
#: Wrist position, its turn about the world's vertical axis, and the jaw.
POSITION_YAW_JAW = ("vx", "vy", "vz", "wy", "jaw")
#: The named action sets (``train_ppo.py --actions``): the components each policy controls, in order
#: ("full": all of ``DELTA_ACTION``, no wrapper needed). A saved run names its set; changing a set's
#: components would change what the saved policies' outputs mean.
ACTION_SETS = {"full": DELTA_ACTION.names, "position-jaw": POSITION_JAW, "position-yaw-jaw": POSITION_YAW_JAW}


def action_columns(components: Sequence[str]) -> np.ndarray:
    """[len(components)] int: the ``DELTA_ACTION`` column of each component name, in order;
    ValueError unless they are distinct names of ``DELTA_ACTION.names`` (one at least)."""
    names = DELTA_ACTION.names
    unknown = [c for c in components if c not in names]
    if unknown or len(set(components)) != len(components) or not components:
        raise ValueError(f"components must be distinct names of {list(names)}, got {list(components)}")
    return np.array([names.index(c) for c in components])


class ActionSubset(VecEnvWrapper):
    """Actions [N, len(components)] in [-1, 1] -> ``DELTA_ACTION`` [N, 7] with those components set
    (in the given order) and every other one zero, for a VecEnv with the env's delta action space.

    ``components``: names of ``DELTA_ACTION.names`` (``POSITION_JAW``, ``POSITION_YAW_JAW``)."""

    def __init__(self, venv, components: Sequence[str]):
        inner = venv.action_space
        if not isinstance(inner, spaces.Box) or inner.shape != (DELTA_ACTION.size,):
            raise ValueError(f"the wrapped env must take DELTA_ACTION [{DELTA_ACTION.size}] actions "
                             f"(action_mode='delta'), got {inner}")
        self._columns = action_columns(components)
        self.components = tuple(components)
        super().__init__(venv, action_space=spaces.Box(-1.0, 1.0, (len(self._columns),), np.float32))

    def full_actions(self, actions: np.ndarray) -> np.ndarray:
        """The env's ``DELTA_ACTION`` [N, 7] float32 for actions [N, len(components)]."""
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
