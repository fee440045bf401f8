"""LeRobot env plugin for defgrasp: importing it registers ``--env.type=defgrasp``.

LeRobot's scripts call ``register_third_party_plugins()``, which imports every installed
distribution named ``lerobot_env_*`` by that name; the config itself lives in
``defgrasp_env.lerobot_env``.
"""

from defgrasp_env.lerobot_env import DefgraspEnvConfig

__all__ = ["DefgraspEnvConfig"]
