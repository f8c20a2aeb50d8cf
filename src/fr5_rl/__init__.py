"""fr5_rl: reinforcement learning for the FAIRINO FR5 arm, in PyBullet and on ROS 1.

Importing the package registers the gymnasium environments ``FR5Reach-v0``, ``FR5Grasp-v0``
and ``FR5Place-v0``, and ``FR5PlaceGoal-v0`` (the place task with dict observations, for HER).
"""
from gymnasium.envs.registration import register, registry

__version__ = "0.1.0"

for _env_id, _task in (("FR5Reach-v0", "reach"), ("FR5Grasp-v0", "grasp"), ("FR5Place-v0", "place")):
    if _env_id not in registry:
        register(id=_env_id, entry_point="fr5_rl.envs:FR5Env", kwargs={"task": _task})
if "FR5PlaceGoal-v0" not in registry:
    register(id="FR5PlaceGoal-v0", entry_point="fr5_rl.goal_env:FR5PlaceGoalEnv")
