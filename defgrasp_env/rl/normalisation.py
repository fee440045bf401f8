"""Observation statistics held fixed while a Stable-Baselines3 run trains.

``VecNormalize`` updates its observation statistics (running mean and variance per observation
entry) at every training step. A policy fitted under some statistics reads its inputs through
them: where the states a run visits drift, so do the statistics, and the fixed network sees other
inputs for the same state. Measured (benchmarks/RESULTS.md, 2026-12-06): PPO from a policy cloned
from the scripted expert, 1.1 M steps, the running mean of the object's height fell from 0.299 m
to 0.207 m (more worlds with the object on the ground than in the expert's data), and the policy
then held every object 0.10 m below the goal: exactly where the clone's "at the goal" input now
lay ((0.6 - 0.299) / 0.222 std then, 0.207 + 1.356 x 0.211 = 0.493 m now; it held at 0.497 m).

``set_observation_statistics_frozen(venv, True)`` swaps each observation statistic of ``venv`` for
a ``FrozenRunningMeanStd`` with the same mean, variance and count, whose ``update`` does nothing;
the reward normalisation (``ret_rms``) goes on updating. ``False`` swaps them back. A saved
``vecnormalize.pkl`` keeps the frozen class, so a resumed or loaded run stays as it was saved.
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.running_mean_std import RunningMeanStd

__all__ = ["FrozenRunningMeanStd", "observation_statistics_frozen", "set_observation_statistics_frozen"]


class FrozenRunningMeanStd(RunningMeanStd):
    """SB3's ``RunningMeanStd`` whose statistics no longer change: ``update`` does nothing."""

    def update(self, arr: np.ndarray) -> None:
        return None

    def copy(self) -> FrozenRunningMeanStd:
        """A frozen copy (SB3's ``RunningMeanStd.copy`` would return an updating one)."""
        out = FrozenRunningMeanStd(shape=self.mean.shape)
        out.mean, out.var, out.count = self.mean.copy(), self.var.copy(), float(self.count)
        return out


def _swap(rms: RunningMeanStd, frozen: bool) -> RunningMeanStd:
    cls = FrozenRunningMeanStd if frozen else RunningMeanStd
    if type(rms) is cls:
        return rms
    out = cls(epsilon=1.0, shape=rms.mean.shape)
    out.mean, out.var, out.count = rms.mean.copy(), rms.var.copy(), rms.count
    return out


def set_observation_statistics_frozen(venv, frozen: bool) -> None:
    """Keep (``frozen``) or update (not) the observation statistics of SB3 ``VecNormalize`` ``venv``
    from now on, with their current values (see the module docstring)."""
    rms = getattr(venv, "obs_rms", None)
    if rms is None:
        raise TypeError(f"venv must be SB3's VecNormalize (observation statistics in .obs_rms), got {type(venv).__name__}")
    venv.obs_rms = {k: _swap(v, frozen) for k, v in rms.items()} if isinstance(rms, dict) else _swap(rms, frozen)


def observation_statistics_frozen(venv) -> bool:
    """Whether every observation statistic of SB3 ``VecNormalize`` ``venv`` is frozen."""
    rms = venv.obs_rms
    return all(isinstance(v, FrozenRunningMeanStd) for v in (rms.values() if isinstance(rms, dict) else [rms]))
