"""``transfer_policy``: start a Stable-Baselines3 policy of one action set from a policy trained
with another (``action_subset.ACTION_SETS``), e.g. a wrist-position + jaw policy into one that also
turns the wrist about the vertical.

Observations are the same for every action set, so every layer but the action head is copied as
it is; the head's rows (``action_net.weight`` [A, H], ``action_net.bias`` [A], ``log_std`` [A] of
SB3's ``ActorCriticPolicy`` with a diagonal Gaussian) are mapped by action component name.
"""

from __future__ import annotations

from .action_subset import ACTION_SETS

__all__ = ["transfer_policy"]

#: The action head's entries (one row per action component).
HEAD_KEYS = ("action_net.weight", "action_net.bias", "log_std")


def transfer_policy(source_state: dict, source_actions: str, target_state: dict, target_actions: str,
                    log_std_init: float) -> dict:
    """``target_state`` (a fresh policy's ``state_dict``) with the weights of ``source_state`` (a
    trained policy's of the same architecture): every layer but the action head as it is, and the
    head's rows by action component (``ACTION_SETS[source_actions]`` -> ``[target_actions]``): a
    component the source did not control starts with zero weights and bias (a zero mean: the
    env's still wrist, as under the source policy) and ``log_std_init``; one the target does not
    control is dropped. ValueError if the two policies' layers differ other than in the head's rows."""
    for name in (source_actions, target_actions):
        if name not in ACTION_SETS:
            raise ValueError(f"action set must be one of {sorted(ACTION_SETS)}, got {name!r}")
    old, new = ACTION_SETS[source_actions], ACTION_SETS[target_actions]
    if set(source_state) != set(target_state):
        raise ValueError(f"the trained policy has other layers (other network architecture): only it has "
                         f"{sorted(set(source_state) - set(target_state))}, only this one "
                         f"{sorted(set(target_state) - set(source_state))}")
    out = {}
    for key, value in target_state.items():
        src = source_state[key]
        same = src.shape[1:] == value.shape[1:] if key in HEAD_KEYS else src.shape == value.shape
        if not same:
            raise ValueError(f"the trained policy's {key!r} has shape {tuple(src.shape)}, this one's "
                             f"{tuple(value.shape)}: other observations or network architecture")
        if key in HEAD_KEYS:
            value = value.clone()
            value.fill_(log_std_init if key == "log_std" else 0.0)
            for row, name in enumerate(new):
                if name in old:
                    value[row] = src[old.index(name)]
        else:
            value = src.clone()
        out[key] = value
    return out
