"""Deployment: model bundles, policy backends, the 50 Hz deployment step, its safety gate and the
joint-state reader.

Imports only the shared layer (config, observation, control, kinematics, transforms) and never
``fr5_rl.training``, perception, drivers or ROS: the ROS nodes and the training tools both build on it.
"""
