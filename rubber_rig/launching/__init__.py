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

"""Starting the suite's nodes: :class:`.inprocess.InProcessLauncher` runs node classes inside one Python process
(one executor thread each), for ``rubber-rig bench``, ``rubber-rig hold`` and the tests. Not a node: it owns a ROS
context and threads, and waits on the wall clock for what real processes do (the nodes' own rules take their
time from the node's clock).
"""
