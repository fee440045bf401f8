"""``ShardedVectorEnv``: several native vector envs stepped at once as one, a thread each.

One ``DeformablePickupVectorEnv`` is one batched simulation on one device, stepped by one host
thread: on a multi-core CPU it uses one core (Warp runs a CPU launch's threads one after another),
and it cannot use a second GPU. ``make_sharded_vec(num_envs, devices, **env_kwargs)`` splits the
worlds into one vector env (a shard) per entry of ``devices`` (``["cpu", "cpu"]``: two cores;
``["cuda:0", "cuda:1"]``: two GPUs) and ``ShardedVectorEnv`` steps them in a thread pool, one
thread per shard (Warp's launches release the GIL; the shards share no arrays), returning the
batch of all worlds: world ``i`` of the whole is world ``i - offset[k]`` of shard ``k``.

The whole behaves as one native vector env of all the worlds (the same spaces, autoreset mode,
``reset_mask`` option, info arrays with ``_key`` masks, ``final_obs`` / ``final_info``, seeds:
world ``i`` reset with seed ``s + i``), and on the CPU its worlds' episodes are bit-identical to
those of one vector env of all the worlds (a world's simulation does not depend on the other
worlds of its batch; tests/test_sharded_vector_env.py). An info key that some shards did not
report in a step (e.g. ``final_obs`` where no world of a shard ended) is filled there with zeros
(``None`` in object arrays) under a False mask. Graph captures, which Warp keeps process-wide, are
serialised against the shards' launches by ``sim.launch_lock.LAUNCH_LOCK``. Observations are numpy
arrays on the host (``torch_outputs`` is not supported: the shards' devices differ).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor, wait

import numpy as np
import warp as wp
from gymnasium.vector import VectorEnv
from gymnasium.vector.utils import batch_space

from ..sim.launch_lock import LAUNCH_LOCK
from .seeds import world_seeds

__all__ = ["ShardedVectorEnv", "make_sharded_vec", "shard_sizes"]


def shard_sizes(num_envs: int, shards: int) -> list[int]:
    """Worlds per shard: ``num_envs`` split into ``shards`` parts as even as possible, the larger
    first (ValueError unless 1 <= shards <= num_envs)."""
    if isinstance(shards, bool) or not isinstance(shards, int) or not 1 <= shards <= num_envs:
        raise ValueError(f"the number of shards must be an integer in [1, num_envs = {num_envs}], got {shards!r}")
    base, extra = divmod(num_envs, shards)
    return [base + (k < extra) for k in range(shards)]


def make_sharded_vec(num_envs: int, devices: Sequence[str], world_objects: Sequence[str] | None = None,
                     **env_kwargs) -> "ShardedVectorEnv":
    """``num_envs`` worlds of ``DeformablePickup-v0`` in one native vector env per entry of
    ``devices`` (the simulation device of each shard; a device may repeat: shards on one CPU
    use its cores), worlds split as ``shard_sizes``; ``world_objects`` (one name per world) is
    split with them; ``env_kwargs`` go to every shard's ``gym.make_vec`` (``autoreset_mode``,
    ``object``, ``youngs_modulus``, ``max_episode_steps``, ...; not ``device`` nor ``num_envs``)."""
    import gymnasium as gym

    devices = [devices] if isinstance(devices, str) else list(devices)
    for key in ("device", "num_envs", "vectorization_mode", "torch_outputs"):
        if key in env_kwargs:
            raise ValueError(f"make_sharded_vec sets {key!r} itself (devices: one shard each), got {key}="
                             f"{env_kwargs[key]!r}")
    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
        raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
    sizes = shard_sizes(num_envs, len(devices))
    if world_objects is not None and (isinstance(world_objects, str) or len(world_objects) != num_envs):
        raise ValueError(f"world_objects must name one object per world ({num_envs}), got {world_objects!r}")
    shards, start = [], 0
    try:
        for device, size in zip(devices, sizes):
            objects = None if world_objects is None else tuple(world_objects[start:start + size])
            shards.append(gym.make_vec("DeformablePickup-v0", num_envs=size, vectorization_mode="vector_entry_point",
                                       device=device, world_objects=objects, **env_kwargs))
            start += size
        return ShardedVectorEnv(shards)
    except Exception:
        for shard in shards:  # the ones built before the error
            shard.close()
        raise


class ShardedVectorEnv(VectorEnv):
    """The native vector envs ``shards`` as one vector env of all their worlds, each shard stepped
    in a thread of its own (see the module docstring). The shards must agree on spaces, autoreset
    mode and episode limit, and return numpy observations."""

    def __init__(self, shards: Sequence[VectorEnv]):
        shards = list(shards)
        if not shards:
            raise ValueError("ShardedVectorEnv needs at least one shard, got none")
        first = shards[0].unwrapped
        for k, shard in enumerate(shards):
            env = shard.unwrapped
            if getattr(env, "torch_outputs", False):
                raise ValueError(f"shard {k} returns torch tensors (torch_outputs=True): the shards must return numpy")
            for name in ("single_observation_space", "single_action_space", "autoreset_mode", "max_episode_steps"):
                if getattr(env, name) != getattr(first, name):
                    raise ValueError(f"shard {k}'s {name} ({getattr(env, name)!r}) differs from shard 0's "
                                     f"({getattr(first, name)!r})")
            mine, theirs = dataclasses.asdict(env.config), dataclasses.asdict(first.config)
            differ = sorted(key for key in mine if key != "device" and mine[key] != theirs[key])
            if differ:
                raise ValueError(f"shard {k}'s PickupConfig differs from shard 0's other than in its device: "
                                 + ", ".join(f"{key} {mine[key]!r} vs {theirs[key]!r}" for key in differ))
        self.shards = shards
        #: the shards' ``PickupConfig`` (shard 0's: the others differ at most in ``device``), read by
        #: what configures itself from an env (``ScriptedPickupExpert.from_env``, ``SB3VectorEnv``)
        self.config = first.config
        sizes = [s.num_envs for s in shards]
        #: [K + 1] world offsets: shard k holds worlds offsets[k] .. offsets[k + 1] - 1 of the whole
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self.num_envs = int(self.offsets[-1])
        self.single_observation_space = first.single_observation_space
        self.single_action_space = first.single_action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.autoreset_mode = first.autoreset_mode
        self.max_episode_steps = first.max_episode_steps
        self.torch_outputs = False
        self.metadata = dict(first.metadata)
        self.render_mode = first.render_mode
        self._pool = ThreadPoolExecutor(max_workers=len(shards), thread_name_prefix="defgrasp-shard")
        # Warp loads a module at its first launch (per device and block size), unguarded against a
        # second thread loading it at once: every module imported so far is loaded here on the
        # shards' devices, and the first reset and step run the shards one after another (the
        # solver's kernels load at its first step, in the block sizes it launches)
        wp.force_load(device=sorted({str(shard.unwrapped.config.device) for shard in shards}))
        self._first_reset = self._first_step = True

    # -- gym API ---------------------------------------------------------------------------
    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        seeds = world_seeds(seed, self.num_envs)
        mask = None if options is None else options.get("reset_mask")
        if mask is not None:
            mask = np.asarray(mask)
            if mask.shape != (self.num_envs,) or mask.dtype != bool:
                raise ValueError(f"reset_mask must be a bool array of shape ({self.num_envs},), "
                                 f"got {mask.dtype} {mask.shape}")

        def reset_shard(k):
            part = slice(self.offsets[k], self.offsets[k + 1])
            shard_options = None if options is None else {**options}
            if mask is not None:
                shard_options["reset_mask"] = mask[part]
            return self.shards[k].reset(seed=seeds[part], options=shard_options)

        results = self._run(reset_shard, sequential=self._first_reset)
        self._first_reset = False
        return _concat([obs for obs, _ in results]), _merge_infos([info for _, info in results], self._sizes())

    def step(self, actions):
        if hasattr(actions, "detach"):  # a torch tensor (on any device), as the native env takes
            actions = actions.detach().cpu().numpy()
        actions = np.asarray(actions)
        if actions.shape[:1] != (self.num_envs,):
            raise ValueError(f"actions must have {self.num_envs} rows (one per world), got shape {actions.shape}")
        results = self._run(lambda k: self.shards[k].step(actions[self.offsets[k]:self.offsets[k + 1]]),
                            sequential=self._first_step)
        self._first_step = False
        obs, reward, terminated, truncated, infos = zip(*results)
        return (_concat(obs), np.concatenate(reward), np.concatenate(terminated), np.concatenate(truncated),
                _merge_infos(list(infos), self._sizes()))

    def render(self):
        frames = self._run(lambda k: self.shards[k].render())
        return None if any(f is None for f in frames) else np.concatenate(frames)

    def close_extras(self, **kwargs):
        self._pool.shutdown(wait=True)  # no shard is stepping while it closes
        for shard in self.shards:
            shard.close()

    # -- internals -------------------------------------------------------------------------
    def _sizes(self) -> list[int]:
        return np.diff(self.offsets).tolist()

    def _run(self, call, sequential: bool = False) -> list:
        """``call(k)`` for every shard k, each in a thread of the pool holding the launch lock
        shared (one shard, or ``sequential``: one after another in the calling thread); results in
        shard order. Every shard's call has ended when this returns or raises (a shard's exception
        is raised after the others finished: none is left stepping)."""

        def locked(k):
            with LAUNCH_LOCK.shared():
                return call(k)

        if len(self.shards) == 1 or sequential:
            return [locked(k) for k in range(len(self.shards))]
        futures = [self._pool.submit(locked, k) for k in range(len(self.shards))]
        wait(futures)
        return [f.result() for f in futures]


def _concat(parts: list):
    """Batches of the shards joined along their first axis (dicts key by key)."""
    if isinstance(parts[0], dict):
        return {key: _concat([p[key] for p in parts]) for key in parts[0]}
    return np.concatenate(parts)


def _merge_infos(infos: list[dict], sizes: list[int]) -> dict:
    """The shards' vector infos (of ``sizes`` worlds each) as one: each key's arrays joined along
    the worlds; a key a shard lacks is filled there (zeros, None in object arrays, False masks;
    nested dicts alike)."""
    merged = {}
    for key in dict.fromkeys(k for info in infos for k in info):
        template = next(info[key] for info in infos if key in info)
        parts = [info[key] if key in info else _blank(template, n) for info, n in zip(infos, sizes)]
        merged[key] = _merge_infos(parts, sizes) if isinstance(template, dict) else np.concatenate(parts)
    return merged


def _blank(template, n: int):
    """An entry like ``template`` for ``n`` worlds that did not report it: zeros (False masks),
    None in object arrays; dicts key by key."""
    if isinstance(template, dict):
        return {key: _blank(value, n) for key, value in template.items()}
    template = np.asarray(template)
    if template.dtype == object:
        return np.full((n,) + template.shape[1:], None, dtype=object)
    return np.zeros((n,) + template.shape[1:], dtype=template.dtype)
