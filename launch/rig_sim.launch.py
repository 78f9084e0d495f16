# Copyright 2026 rubber_rig developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Simulated rig: rig_driver (backend sim, paced to the wall clock), excitation, element_model and recorder.

    ros2 launch rubber_rig rig_sim.launch.py
    ros2 launch rubber_rig rig_sim.launch.py namespace:=rig1 program:=dynamic_stiffness_grid

Same node classes and the same parameter file (config/rig_sim.yaml) as ``rubber-rig bench``, which starts
them in one process when there is no ROS install. The rig_driver is a lifecycle node; with ``autostart: true``
(the default in the config) it configures and activates itself, otherwise use ``ros2 lifecycle set``.
For the live view, start foxglove_bridge alongside and import config/foxglove_layout.json in Foxglove.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node

from launch import LaunchDescription

# element_model and the recorder restart safely: a respawned model starts afresh on the next samples, a
# respawned recorder opens a new file (the killed one keeps what it wrote; `rubber-rig recover` closes it).
# rig_driver (the safety authority: an operator looks at why it died) and the excitation (with `program` set it
# would start the program again) are not respawned.
RESPAWN_DELAY = 2.0   # [s]


def generate_launch_description():
    config = os.path.join(get_package_share_directory('rubber_rig'), 'config', 'rig_sim.yaml')
    namespace = LaunchConfiguration('namespace')
    program = LaunchConfiguration('program')
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='', description='namespace of this rig'),
        DeclareLaunchArgument('program', default_value='dynamic_stiffness_grid',
                              description='test program (shipped name or YAML path) the excitation runs at start; '
                                          'empty: wait for a RunProgram goal'),
        LifecycleNode(package='rubber_rig', executable='rig_driver', name='rig_driver', namespace=namespace,
                      parameters=[config], output='screen'),
        Node(package='rubber_rig', executable='excitation', name='excitation', namespace=namespace,
             parameters=[config, {'program': program}], output='screen'),
        Node(package='rubber_rig', executable='element_model', name='element_model', namespace=namespace,
             parameters=[config], output='screen', respawn=True, respawn_delay=RESPAWN_DELAY),
        Node(package='rubber_rig', executable='recorder', name='recorder', namespace=namespace,
             parameters=[config], output='screen', respawn=True, respawn_delay=RESPAWN_DELAY),
    ])
