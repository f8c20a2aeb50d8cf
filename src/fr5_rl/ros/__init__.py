"""ROS 1 nodes of fr5_rl: simulator, policy, static transforms. Entry points in scripts/."""
