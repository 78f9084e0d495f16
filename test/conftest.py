"""Shared pytest set-up: the ROS 2 middleware is real Fast DDS from the ros-jazzy-* wheels."""
import os

os.environ.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
# Keep test traffic on this machine and away from other ROS graphs on the network.
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
