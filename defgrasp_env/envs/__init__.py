"""Gymnasium environments of defgrasp."""

from .config import PickupConfig
from .pickup_env import DeformablePickupEnv

__all__ = ["DeformablePickupEnv", "PickupConfig"]
