"""rubber_rig: ROS 2 node suite for hardware-in-the-loop rubber-element test rigs.

The core (models, excitation, rig, recording, fitting) imports no rclpy; rubber_rig.nodes wires it to ROS 2.
"""
__version__ = '0.1.0'
