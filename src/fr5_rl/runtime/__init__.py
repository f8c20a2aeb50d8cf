"""Deployment-side code: model bundles, policy backends and the 50 Hz deployment step.

Imports only the shared layer (config, observation, control, kinematics, transforms) and never
``fr5_rl.training`` or ROS: the ROS nodes and the training tools both build on it.
"""
