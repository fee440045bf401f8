"""``ReplaySpec``: what a single ``DeformablePickup-v0`` env needs to repeat one world's reset.

The env emits one per reset world: ``info["replay_spec"]`` of the single env's ``reset``, and in
the vector env ``info["replay_spec"]`` (object array [N]) with the mask ``info["_replay_spec"]`` of
its ``reset`` and of every ``step`` that autoresets worlds. Recorders store it
(:meth:`ReplaySpec.to_json_dict`, the ``replay_json`` of an episode file) and never read the env's
RNGs or flags. :meth:`ReplaySpec.reset` repeats the reset in a single env: on the CPU the episode
then replays bit for bit, whether it was recorded in a single env or in world ``i`` of a vector
env.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from ..sim.materials import Material

_RESET_KEYS = ("seed", "rng_state", "options")


@dataclass(frozen=True)
class ReplaySpec:
    """One world's reset, as a single env repeats it.

    Attributes:
        seed: the reset's seed, or None when the reset continued an RNG (then ``rng_state``).
        rng_state: numpy ``bit_generator.state`` (JSON-able dict) the reset drew from, when
            ``seed`` is None; else None.
        options: the single-env reset options that give the same draws (``{"object": name}`` for a
            world of a vector env whose ``world_objects`` fix its object), or None.
        object_name: the world's object (a name of ``OBJECT_SHAPES`` or a mesh path).
        material: what the reset drew (density kg/m^3, Young's modulus Pa, Poisson ratio).
        position: initial object frame origin (m, world); ``quat``: its orientation (xyzw).
        goal: the episode's goal (m, world; drawn where the config's ``goal_noise`` is not zero).
        scene_origin: the reset that built the simulation this world lives in (its rest shape
            comes from it), to be repeated first; None when this reset built it.
    """

    seed: int | None
    rng_state: dict | None
    options: dict | None
    object_name: str
    material: Material
    position: tuple[float, float, float]
    quat: tuple[float, float, float, float]
    goal: tuple[float, float, float]
    scene_origin: ReplaySpec | None = None

    def to_json_dict(self) -> dict[str, Any]:
        """``{"seed", "rng_state", "options", "scene_origin"}`` (the origin as the same keys but its
        own origin), the replay data of an episode file (``schema.py``)."""
        origin = self.scene_origin
        return {**{k: getattr(self, k) for k in _RESET_KEYS},
                "scene_origin": None if origin is None else {k: getattr(origin, k) for k in _RESET_KEYS}}

    def reset(self, env: gym.Env):
        """Repeat this reset (after its ``scene_origin``) in the single env ``env``; returns what
        the env's last ``reset`` returned."""
        if self.scene_origin is not None:
            reset_from_json(env, self.scene_origin.to_json_dict())
        return reset_from_json(env, self.to_json_dict())


def reset_from_json(env: gym.Env, spec: dict):
    """``env.reset`` as a recorded reset dict (``ReplaySpec.to_json_dict``, an episode file's
    ``replay_json``) says: with its seed, or from its RNG state (keys missing: None)."""
    state = spec.get("rng_state")
    if spec.get("seed") is None and state is not None:
        bit_generator = getattr(np.random, state["bit_generator"])()
        bit_generator.state = state
        env.unwrapped.np_random = np.random.Generator(bit_generator)
        return env.reset(options=spec.get("options"))
    return env.reset(seed=spec.get("seed"), options=spec.get("options"))

