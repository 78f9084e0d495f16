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

"""ament_python package rubber_rig (also installable with pip for the no-ROS path of the README)."""
import re
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

package_name = 'rubber_rig'
# package.xml is the one place the version is written (colcon and bloom read it there)
version = re.search(r'<version>\s*([^<\s]+)\s*</version>',
                    (Path(__file__).resolve().parent / 'package.xml').read_text(encoding='utf-8')).group(1)

setup(
    name=package_name,
    version=version,
    packages=find_packages(exclude=['test', 'test.*']),
    package_data={package_name: ['**/*.yaml', '**/*.dbc', '**/*.json']},
    include_package_data=True,
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml', 'LICENSE', 'CHANGELOG.rst', 'REFERENCES.md']),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.json') + glob('config/*.xml')),
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='rubber_rig developers',
    maintainer_email='rubber-rig@example.org',
    description='ROS 2 node suite for hardware-in-the-loop rubber-element test rigs',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'rubber-rig = rubber_rig.cli.main:main',
            'rig_driver = rubber_rig.nodes.rig_driver_node:main',
            'excitation = rubber_rig.nodes.excitation_node:main',
            'element_model = rubber_rig.nodes.element_model_node:main',
            'recorder = rubber_rig.nodes.recorder_node:main',
            'foxglove_view = rubber_rig.nodes.foxglove_view_node:main',
        ],
    },
)
