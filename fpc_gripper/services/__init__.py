"""ROS-free services below the nodes: the model service, the input checks, log helpers."""
