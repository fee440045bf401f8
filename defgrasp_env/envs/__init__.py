"""Gymnasium environments of defgrasp."""

from .config import PickupConfig
from .pickup_env import DeformablePickupEnv
from .replay_spec import ReplaySpec

__all__ = ["DeformablePickupEnv", "PickupConfig", "ReplaySpec"]
