"""Start a PPO policy from the scripted expert: noise-injected expert rollouts in the training env's
own Stable-Baselines3 stack, then the actor fitted to the expert's actions and the critic to the
rollouts' returns (behaviour cloning as a warm start for on-policy RL).

Why: PPO from scratch learned the cuboid (benchmarks/RESULTS.md) but, started from the cuboid
policy, not the torus (lifted by the rim, its feature point off the grasp) nor the 16 mm rope
(the jaw closing beside it); the scripted expert picks all five objects, and its actions on the
five are what a policy of the same action set can start from.

* ``collect_expert_steps(venv, components, steps, noise, rng)``: ``venv`` is the SB3 stack
  ``train_ppo.make_vec_env`` builds (``VecNormalize`` around ``VecMonitor`` around an optional
  ``ActionSubset`` around ``SB3VectorEnv``); the expert (``ScriptedPickupExpert.from_env`` of the
  native vector env) reads the unnormalised observations; the worlds execute its actions with
  Gaussian noise of std ``noise`` (clipped to [-1, 1]: the DART recipe, so that the data covers the
  states a policy's own errors lead to), the labels are its clean actions (the ``components`` of
  ``DELTA_ACTION`` the policy controls). The ``VecNormalize`` statistics are updated as in training
  (unless frozen: ``rl.normalisation``). Not DAgger: the expert's labels are those of its script,
  whose phases (approach, descend, close, lift) follow its own progress, so on a state another
  policy reached it may ask to open a jaw that holds the object (a clone driving on this CPU: 60 %
  of its held world-steps labelled "open"; a relabelled fit picked 0 / 40, benchmarks/RESULTS.md).
* ``discounted_returns(rewards, dones, gamma)``: per world, within episodes, not bootstrapped;
  ``complete_returns(dones, truncated, gamma)``: where those are the whole return (no truncation
  nor the data's end within the steps that set 99 % of it: 21 at the training discount 0.8).
* ``fit_policy(policy, normalizer, data, gamma, ...)``: Adam on the mean squared error of the
  policy's Gaussian mean against the labels plus ``value_weight`` times that of its value against
  the returns of the normalised rewards where complete (observations and rewards normalised by the
  final statistics), a random share of the worlds held out; sets the policy's ``log_std`` to ``log(noise)`` per
  component (the data's own spread; ``min_std`` at least, so that PPO still explores a component
  collected without noise). Returns the losses per epoch.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..layout import DELTA_ACTION
from ..policies.scripted_expert import ScriptedPickupExpert
from .action_subset import action_columns

__all__ = ["ExpertSteps", "collect_expert_steps", "complete_returns", "discounted_returns", "fit_policy"]


@dataclass
class ExpertSteps:
    """Expert steps of N worlds over T vector steps, as collected (unnormalised).

    Attributes:
        obs: observation dict, each key [T, N, ...] float32 (the env's units: m, N, xyzw).
        actions: [T, N, A] float32 clean expert actions of ``components`` (the labels), in [-1, 1].
        executed: [T, N, A] float32 actions the worlds stepped with (labels + clipped noise).
        rewards: [T, N] float64 env rewards of each step (unnormalised).
        dones: [T, N] bool: the world's episode ended at this step (terminated, truncated or cut).
        truncated: [T, N] bool: it ended by the time limit or a staggered start's cut
            (``TimeLimit.truncated``: its return goes on beyond the data, which SB3's PPO bootstraps).
        successes: [E] bool: some step of the episode read ``is_success``, for every episode that
            ended during the collection but the staggered first ones (where a success does not end
            the episode, its last step need not be one).
        dropped_max: max |action| over the collection of the expert's ``DELTA_ACTION`` components
            outside ``components`` (the policy cannot reproduce them; ~0 for a top-down expert).
        components: the ``DELTA_ACTION`` names of the A action columns.
        noise: [A] std of the executed actions' Gaussian noise, per action column.
    """

    obs: dict
    actions: np.ndarray
    executed: np.ndarray
    rewards: np.ndarray
    dones: np.ndarray
    truncated: np.ndarray
    successes: np.ndarray
    dropped_max: float
    components: tuple[str, ...]
    noise: np.ndarray

    @property
    def num_samples(self) -> int:
        return int(self.actions.shape[0] * self.actions.shape[1])


def _native_env(venv):
    """The native vector env under an SB3 stack ending in ``SB3VectorEnv``."""
    inner = venv.unwrapped
    env = getattr(inner, "env", None)
    if env is None:
        raise TypeError(f"the SB3 stack must end in SB3VectorEnv, got {type(inner).__name__}")
    return env


def collect_expert_steps(venv, components: Sequence[str], steps: int, noise: float | Sequence[float],
                         rng: np.random.Generator, expert_options: dict | None = None) -> ExpertSteps:
    """Run ``steps`` vector steps of the noise-injected scripted expert in ``venv`` (see the module
    docstring) from a fresh ``reset()``; ``components``: the ``DELTA_ACTION`` names ``venv``'s action
    space holds, in its order; ``noise``: the std of the actions' noise, one for all or one per
    component; ``expert_options``: ``ExpertConfig`` fields the expert is built with (e.g.
    ``delta_close_lead``)."""
    from stable_baselines3.common.vec_env import VecNormalize

    if not isinstance(venv, VecNormalize):
        raise TypeError(f"venv must be the VecNormalize of train_ppo.make_vec_env, got {type(venv).__name__}")
    columns = action_columns(components)
    if venv.action_space.shape != (len(components),):
        raise ValueError(f"venv's actions have shape {venv.action_space.shape}, components {list(components)} "
                         f"have {len(components)}")
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    std = np.broadcast_to(np.asarray(noise, np.float64), (len(components),)) if np.ndim(noise) == 0 \
        else np.asarray(noise, np.float64)
    if std.shape != (len(components),) or not np.all(np.isfinite(std) & (std >= 0.0)):
        raise ValueError(f"noise must be one finite std >= 0 or one per component ({len(components)}), got {noise}")
    dropped = np.setdiff1d(np.arange(DELTA_ACTION.size), columns)
    expert = ScriptedPickupExpert.from_env(_native_env(venv), **(expert_options or {}))
    n = venv.num_envs
    venv.reset()
    raw = venv.get_original_obs()
    expert.reset()
    obs = {k: np.empty((steps,) + v.shape, np.float32) for k, v in raw.items()}
    labels = np.empty((steps, n, len(columns)), np.float32)
    executed = np.empty_like(labels)
    rewards = np.empty((steps, n))
    dones = np.empty((steps, n), bool)
    truncated = np.empty((steps, n), bool)
    successes: list[bool] = []
    succeeded = np.zeros(n, bool)  # some step of the world's current episode read is_success
    dropped_max = 0.0
    for t in range(steps):
        full = expert(raw)
        if dropped.size:
            dropped_max = max(dropped_max, float(np.abs(full[:, dropped]).max()))
        for k, v in raw.items():
            obs[k][t] = v
        labels[t] = full[:, columns]
        executed[t] = np.clip(labels[t] + rng.normal(0.0, std, labels[t].shape), -1.0, 1.0) if std.any() else labels[t]
        _, _, done, infos = venv.step(executed[t])
        rewards[t] = venv.get_original_reward()
        dones[t] = done
        truncated[t] = [bool(info.get("TimeLimit.truncated", False)) for info in infos]
        succeeded |= [bool(info.get("is_success", False)) for info in infos]
        # a staggered first episode is no sample of the task's (a failure is cut, a success not)
        successes += [bool(succeeded[i]) for i in np.flatnonzero(done) if not infos[i].get("staggered_start", False)]
        if done.any():
            succeeded[done] = False
            expert.reset(done)
        raw = venv.get_original_obs()
    return ExpertSteps(obs, labels, executed, rewards, dones, truncated, np.array(successes, bool), dropped_max,
                       tuple(components), std.copy())


def discounted_returns(rewards: np.ndarray, dones: np.ndarray, gamma: float) -> np.ndarray:
    """[T, N] sum_k gamma^k r[t + k] within each world's episode (``dones[t]``: the episode ends after
    step t); the last episode of each world is cut at T without a bootstrap."""
    rewards, dones = np.asarray(rewards, np.float64), np.asarray(dones, bool)
    if rewards.shape != dones.shape or rewards.ndim != 2:
        raise ValueError(f"rewards and dones must both be [T, N], got {rewards.shape} and {dones.shape}")
    if not 0.0 <= gamma <= 1.0:
        raise ValueError(f"gamma must be in [0, 1], got {gamma}")
    out = np.empty_like(rewards)
    running = np.zeros(rewards.shape[1])
    for t in range(rewards.shape[0] - 1, -1, -1):
        running = rewards[t] + gamma * running * ~dones[t]
        out[t] = running
    return out


def complete_returns(dones: np.ndarray, truncated: np.ndarray, gamma: float, share: float = 0.99) -> np.ndarray:
    """[T, N] bool: the step's ``discounted_returns`` is ``share`` of its whole return or more: no
    truncation (``truncated``) and not the data's end within the next ``log(1 - share) / log(gamma)``
    steps of its episode (an episode that ends by itself, ``dones`` and not ``truncated``, is whole)."""
    dones, truncated = np.asarray(dones, bool), np.asarray(truncated, bool)
    if dones.shape != truncated.shape or dones.ndim != 2:
        raise ValueError(f"dones and truncated must both be [T, N], got {dones.shape} and {truncated.shape}")
    if not 0.0 < gamma < 1.0 or not 0.0 < share < 1.0:
        raise ValueError(f"gamma and share must be in (0, 1), got {gamma}, {share}")
    horizon = int(np.ceil(np.log(1.0 - share) / np.log(gamma)))
    cut_in = np.zeros(dones.shape[1])  # steps until the episode is cut (the data's end: after the last step)
    out = np.empty(dones.shape, bool)
    for t in range(dones.shape[0] - 1, -1, -1):
        if t < dones.shape[0] - 1:
            cut_in = np.where(dones[t], np.where(truncated[t], 0.0, np.inf), cut_in + 1.0)
        else:
            cut_in = np.where(dones[t] & ~truncated[t], np.inf, 0.0)
        out[t] = cut_in >= horizon
    return out


def fit_policy(policy, normalizer, data: ExpertSteps, gamma: float, epochs: int = 20, batch_size: int = 4096,
               learning_rate: float = 3e-4, value_weight: float = 0.5, holdout: float = 0.05,
               min_std: float = 0.05, rng: np.random.Generator | None = None) -> list[dict]:
    """Fit SB3 ``policy`` (an ``ActorCriticPolicy`` with a diagonal Gaussian) to ``data`` (see the
    module docstring); ``normalizer``: the ``VecNormalize`` whose statistics the run will use.
    ``holdout``: the share of the worlds (at least one of two or more) whose steps are held out.
    Returns one dict per epoch: ``action_mse`` / ``value_mse`` on the training and held-out
    samples (``holdout_*``; labels in [-1, 1], returns in normalised-reward units, over the steps
    whose return is complete: ``complete_returns``) and the held-out root mean squared error of each
    action component (``holdout_rms_<component>``, e.g. ``holdout_rms_jaw``: 0.024 is 1 mm of jaw gap)."""
    import torch

    if epochs < 1 or batch_size < 1 or not 0.0 <= holdout < 1.0 or not min_std > 0.0:
        raise ValueError(f"epochs and batch_size must be >= 1, holdout in [0, 1) and min_std > 0, got {epochs}, "
                         f"{batch_size}, {holdout}, {min_std}")
    if policy.action_space.shape != (data.actions.shape[-1],):
        raise ValueError(f"the policy's actions have shape {policy.action_space.shape}, the data's "
                         f"{data.actions.shape[-1:]}")
    rng = np.random.default_rng(0) if rng is None else rng
    flat = {k: v.reshape((-1,) + v.shape[2:]) for k, v in data.obs.items()}
    obs = normalizer.normalize_obs(flat)
    norm_rewards = normalizer.normalize_reward(data.rewards.reshape(-1)).reshape(data.rewards.shape)
    returns = discounted_returns(norm_rewards, data.dones, gamma).reshape(-1)
    whole = complete_returns(data.dones, data.truncated, gamma).reshape(-1)
    labels = data.actions.reshape(-1, data.actions.shape[-1])
    device = policy.device
    tensors = {k: torch.as_tensor(np.asarray(v, np.float32), device=device) for k, v in obs.items()}
    target_a = torch.as_tensor(labels, device=device)
    target_v = torch.as_tensor(returns, dtype=torch.float32, device=device)
    value_mask = torch.as_tensor(whole, dtype=torch.float32, device=device)
    # whole worlds held out: a world's consecutive steps are nearly alike
    worlds = data.actions.shape[1]
    held_count = max(1, int(round(holdout * worlds))) if holdout > 0.0 and worlds > 1 else 0
    held_worlds = rng.permutation(worlds)[:held_count]
    is_held = np.zeros(data.actions.shape[:2], bool)
    is_held[:, held_worlds] = True
    held, train = np.flatnonzero(is_held.reshape(-1)), np.flatnonzero(~is_held.reshape(-1))
    with torch.no_grad():
        policy.log_std.copy_(torch.as_tensor(np.log(np.maximum(data.noise, min_std)), dtype=policy.log_std.dtype))
    params = [p for name, p in policy.named_parameters() if name != "log_std"]
    optimiser = torch.optim.Adam(params, lr=learning_rate)

    def losses(idx):
        batch = {k: v[idx] for k, v in tensors.items()}
        mean = policy.get_distribution(batch).distribution.mean
        value = policy.predict_values(batch).squeeze(-1)
        mask = value_mask[idx]
        squared = (mean - target_a[idx]) ** 2
        return squared, (mask * (value - target_v[idx]) ** 2).sum() / mask.sum().clamp(min=1.0)

    history = []
    policy.set_training_mode(True)
    for _ in range(epochs):
        sums = np.zeros(2)
        rng.shuffle(train)
        for start in range(0, len(train), batch_size):
            idx = torch.as_tensor(train[start:start + batch_size], device=device)
            squared, v_loss = losses(idx)
            a_loss = squared.mean()
            optimiser.zero_grad()
            (a_loss + value_weight * v_loss).backward()
            optimiser.step()
            sums += len(idx) * np.array([a_loss.item(), v_loss.item()])
        row = {"action_mse": sums[0] / len(train), "value_mse": sums[1] / len(train)}
        if len(held):
            with torch.no_grad():
                squared, v_loss = losses(torch.as_tensor(held, device=device))
                rms = squared.mean(dim=0).sqrt().cpu().numpy()
            row |= {"holdout_action_mse": squared.mean().item(), "holdout_value_mse": v_loss.item()}
            row |= {f"holdout_rms_{name}": float(r) for name, r in zip(data.components, rms)}
        history.append(row)
    policy.set_training_mode(False)
    return history
