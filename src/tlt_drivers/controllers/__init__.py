"""ros2_control-style controllers over a hardware interface's joints (pure logic + thin rclpy adapters)."""
