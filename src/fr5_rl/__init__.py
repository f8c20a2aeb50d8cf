"""fr5_rl: reinforcement learning for the FAIRINO FR5 arm, in PyBullet and on ROS 1.

Importing the package registers the gymnasium environments ``FR5Reach-v0`` and
``FR5Grasp-v0``.
"""
from gymnasium.envs.registration import register, registry

__version__ = "0.1.0"

for _env_id, _task in (("FR5Reach-v0", "reach"), ("FR5Grasp-v0", "grasp")):
    if _env_id not in registry:
        register(id=_env_id, entry_point="fr5_rl.envs:FR5Env", kwargs={"task": _task})
