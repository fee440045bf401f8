"""defgrasp: deformable-object pickup with complete FEM state.

``import defgrasp_env`` registers ``DeformablePickup-v0`` (single env and native vector env);
``make_sharded_vec`` splits a vector env's worlds over several devices or CPU cores.
"""

import gymnasium as gym

from .envs.config import PickupConfig
from .envs.sharded_vector_env import ShardedVectorEnv, make_sharded_vec

__version__ = "0.1.0"
ENV_ID = "DeformablePickup-v0"

if ENV_ID not in gym.registry:
    gym.register(
        id=ENV_ID,
        entry_point="defgrasp_env.envs.pickup_env:DeformablePickupEnv",
        vector_entry_point="defgrasp_env.envs.vector_env:DeformablePickupVectorEnv",
        max_episode_steps=PickupConfig().max_episode_steps,
    )

__all__ = ["ENV_ID", "PickupConfig", "ShardedVectorEnv", "__version__", "make_sharded_vec"]
