"""ROS 2 driver nodes: one process per hardware link (active_grippers, camera_mounts, top_grippers, ee)."""
