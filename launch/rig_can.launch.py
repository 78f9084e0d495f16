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

"""Hardware rig on a CAN bus: rig_driver (python-can interface/channel/bitrate), excitation, element_model, recorder.

    ros2 launch rubber_rig rig_can.launch.py can_interface:=socketcan can_channel:=can0
    ros2 launch rubber_rig rig_can.launch.py can_interface:=pcan can_channel:=PCAN_USBBUS1 can_bitrate:=1000000

Parameters come from config/rig_can.yaml; the bus can be chosen on the command line. The excitation waits
for a RunProgram goal (nothing moves on hardware until an operator sends one) unless ``program`` is given.
The rig_driver is a lifecycle node and config/rig_can.yaml sets ``autostart: false``: bring it up with
``ros2 lifecycle set /rig_driver configure`` then ``... activate`` once the rig is ready.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node
from launch_ros.parameter_descriptions import ParameterValue

from launch import LaunchDescription

# element_model and the recorder restart safely: a respawned model starts afresh on the next samples, a
# respawned recorder opens a new file (the killed one keeps what it wrote; `rubber-rig recover` closes it).
# rig_driver (the safety authority: an operator looks at why it died) and the excitation (with `program` set it
# would start the program again) are not respawned.
RESPAWN_DELAY = 2.0   # [s]


def generate_launch_description():
    config = os.path.join(get_package_share_directory('rubber_rig'), 'config', 'rig_can.yaml')
    namespace = LaunchConfiguration('namespace')
    driver_overrides = {
        'backend': LaunchConfiguration('can_interface'),
        'can.channel': LaunchConfiguration('can_channel'),
        'can.bitrate': ParameterValue(LaunchConfiguration('can_bitrate'), value_type=int),
    }
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='', description='namespace of this rig'),
        DeclareLaunchArgument('can_interface', default_value='socketcan', description='python-can interface'),
        DeclareLaunchArgument('can_channel', default_value='can0', description='python-can channel'),
        DeclareLaunchArgument('can_bitrate', default_value='1000000', description='CAN bitrate [bit/s]'),
        DeclareLaunchArgument('program', default_value='', description='test program to run at start (empty: '
                              'wait for a RunProgram goal)'),
        LifecycleNode(package='rubber_rig', executable='rig_driver', name='rig_driver', namespace=namespace,
                      parameters=[config, driver_overrides], output='screen'),
        Node(package='rubber_rig', executable='excitation', name='excitation', namespace=namespace,
             parameters=[config, {'program': LaunchConfiguration('program')}], output='screen'),
        Node(package='rubber_rig', executable='element_model', name='element_model', namespace=namespace,
             parameters=[config], output='screen', respawn=True, respawn_delay=RESPAWN_DELAY),
        Node(package='rubber_rig', executable='recorder', name='recorder', namespace=namespace,
             parameters=[config], output='screen', respawn=True, respawn_delay=RESPAWN_DELAY),
    ])
