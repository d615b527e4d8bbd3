"""Model and ROS 2 drivers for a soft gripper of fluidic prestressed composite fingers."""
