"""The digital twin as a ROS process: every device emulator bound to the MuJoCo model (docs/twin.md)."""
