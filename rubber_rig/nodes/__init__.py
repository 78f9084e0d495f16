"""ROS 2 nodes of rubber_rig: thin rclpy wrappers around the ROS-free core.

Topic names are relative, so several rigs can run side by side under namespaces (``/rig1/samples``, ...).
"""
