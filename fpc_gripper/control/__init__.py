"""Gripper geometry and closed-loop control laws (ROS-free)."""
