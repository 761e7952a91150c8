"""Dynamixel MX-106(2.0) chains over Protocol 2.0 with dynamixel-sdk (Active Grippers, camera mounts, EE)."""
