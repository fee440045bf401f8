"""The vector env's ``reset(seed=...)`` argument, checked and expanded to one seed per world."""

from __future__ import annotations

import numbers


def _is_seed(value) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def world_seeds(seed, num_envs: int) -> list[int | None]:
    """One seed (or None: keep that world's RNG) per world.

    Args:
        seed: None (no reseeding), an int >= 0 (world ``i`` gets ``seed + i``), or a list/tuple of
            ``num_envs`` entries, each an int >= 0 or None.
    Raises:
        TypeError: ``seed`` or an entry of the wrong type (the value is named).
        ValueError: a negative seed or a list of the wrong length.
    """
    if seed is None:
        return [None] * num_envs
    if _is_seed(seed):
        if seed < 0:
            raise ValueError(f"seed must be an int >= 0, got {seed!r}")
        return [int(seed) + i for i in range(num_envs)]
    if not isinstance(seed, (list, tuple)):
        raise TypeError(f"seed must be None, an int >= 0 or a list of {num_envs} ints >= 0 (or None), "
                        f"got {seed!r} of type {type(seed).__name__}")
    if len(seed) != num_envs:
        raise ValueError(f"seed list must have {num_envs} entries (one per world), got {len(seed)}: {list(seed)!r}")
    for i, s in enumerate(seed):
        if s is not None and not _is_seed(s):
            raise TypeError(f"seed[{i}] must be an int >= 0 or None, got {s!r} of type {type(s).__name__}")
        if s is not None and s < 0:
            raise ValueError(f"seed[{i}] must be an int >= 0 or None, got {s!r}")
    return [None if s is None else int(s) for s in seed]
