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

"""The private parts of rclpy the nodes rely on, in one place, with the version they were checked on.

rclpy 7 (Jazzy) has no public API for these:

* ``RCLError`` (defined in ``rclpy._rclpy_pybind11``): what spinning raises when the context is shut down from
  outside while the executor builds its wait set (the public ``ExternalShutdownException`` covers the other
  moments); it is taken from ``rclpy.impl.implementation_singleton``, as rclpy's own modules take it;
* the parameter overrides of a node (``Node._parameter_overrides``): values from parameter files and the
  command line before they are declared, to accept an integer for a double and to find misspelt keys
  (``declare_parameter`` reads them without calling the public pre-set callbacks, and no public method lists
  them). The declared parameters come from the public ``Node.list_parameters`` instead of ``Node._parameters``;
* the current state of a lifecycle node (``LifecycleNode._state_machine.current_state``); the public way is
  the node's own ``get_state`` service, which a node cannot call on itself from its executor.

Checked against rclpy :data:`CHECKED_VERSION` (ROS 2 Jazzy; rclpy's own metadata, as the ros-jazzy-rclpy
7.1.6 / ros-rclpy 7.1.6 wheels install it). :func:`check_version` runs at import and warns, without failing,
when another major.minor version is installed; test/test_compat.py exercises each function against the
installed rclpy.
"""
from __future__ import annotations

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.lifecycle import LifecycleNode
from rclpy.node import Node

from rubber_rig.versions import CheckedVersion
from rubber_rig.versions import version_matches as _version_matches

PACKAGE = 'rclpy'
CHECKED_VERSION = '7.1.5'
RCLError = _rclpy.RCLError


VERSION = CheckedVersion(PACKAGE, CHECKED_VERSION, 'rubber_rig/nodes/rclpy_compat.py')
installed_version = VERSION.installed
check_version = VERSION.check


def version_matches(installed: str, checked: str = CHECKED_VERSION) -> bool:
    """True when ``installed`` has the major.minor of ``checked``."""
    return _version_matches(installed, checked)


check_version()


def parameter_overrides(node: Node) -> dict:
    """The node's parameter overrides (name -> rclpy Parameter), the live dict rclpy declares from."""
    return node._parameter_overrides


def lifecycle_state(node: LifecycleNode) -> str:
    """'unconfigured', 'inactive', 'active', 'finalized' or a transition state's label."""
    return node._state_machine.current_state[1]
